//! A bad network on one machine: a userspace UDP proxy that delays every datagram and drops a
//! share of them, each way, seeded (this machine's kernel has no netem, and a test may not need
//! root). A shared world's participant connects to the proxy instead of the host; zenoh's TLS
//! link is QUIC over UDP, so the proxy's loss is real packet loss that QUIC recovers from by
//! retransmission, as on a lossy Wi-Fi link, and its delay is one-way latency (a round trip
//! crosses it twice).
//!
//! [`UdpProxy::pause`] drops everything for a while (a stalled link: a participant's Wi-Fi
//! gone for two seconds), and [`UdpProxy::stats`] counts what crossed and what was dropped.

use std::collections::{BinaryHeap, HashMap};
use std::net::{SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// What a proxy does to each datagram, each way.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Impairment {
    /// Added one-way delay.
    pub delay: Duration,
    /// The share of datagrams dropped, 0 to 1.
    pub loss: f64,
}

impl Impairment {
    pub const NONE: Impairment = Impairment {
        delay: Duration::ZERO,
        loss: 0.0,
    };
}

/// Datagrams that crossed and that were dropped, both ways together.
#[derive(Debug, Default)]
pub struct ProxyStats {
    pub forwarded: AtomicU64,
    pub dropped: AtomicU64,
    pub paused_drops: AtomicU64,
    pub bytes: AtomicU64,
}

/// A datagram waiting for its time.
struct Due {
    at: Instant,
    order: u64,
    to: Target,
    data: Vec<u8>,
}

#[derive(Clone)]
enum Target {
    /// To the server, from the client's own back socket.
    Server(Arc<UdpSocket>),
    /// Back to a client, from the front socket.
    Client(SocketAddr),
}

impl PartialEq for Due {
    fn eq(&self, other: &Self) -> bool {
        (self.at, self.order) == (other.at, other.order)
    }
}
impl Eq for Due {}
impl PartialOrd for Due {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Due {
    /// The earliest first out of a max-heap.
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        (other.at, other.order).cmp(&(self.at, self.order))
    }
}

/// The proxy's shared state: the impairment (changeable while it runs), the pause, the queue.
struct Shared {
    impairment: Mutex<Impairment>,
    paused_until: Mutex<Option<Instant>>,
    queue: Mutex<BinaryHeap<Due>>,
    rng: Mutex<u64>,
    order: AtomicU64,
    stop: AtomicBool,
    stats: ProxyStats,
}

impl Shared {
    /// Queues `data` for `to` after the delay, unless it is lost or the link is paused.
    fn pass(&self, data: &[u8], to: Target) {
        let now = Instant::now();
        if self
            .paused_until
            .lock()
            .map(|p| p.is_some_and(|until| now < until))
            .unwrap_or(false)
        {
            self.stats.paused_drops.fetch_add(1, Ordering::Relaxed);
            return;
        }
        let imp = self
            .impairment
            .lock()
            .map(|i| *i)
            .unwrap_or(Impairment::NONE);
        if imp.loss > 0.0 && self.uniform() < imp.loss {
            self.stats.dropped.fetch_add(1, Ordering::Relaxed);
            return;
        }
        let due = Due {
            at: now + imp.delay,
            order: self.order.fetch_add(1, Ordering::Relaxed),
            to,
            data: data.to_vec(),
        };
        if let Ok(mut q) = self.queue.lock() {
            q.push(due);
        }
    }

    /// xorshift64*: a uniform number in [0, 1), the same sequence for the same seed.
    fn uniform(&self) -> f64 {
        let Ok(mut s) = self.rng.lock() else {
            return 1.0;
        };
        *s ^= *s >> 12;
        *s ^= *s << 25;
        *s ^= *s >> 27;
        let x = s.wrapping_mul(0x2545_f491_4f6c_dd1d);
        (x >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// A running proxy: clients send to `127.0.0.1:port`, it forwards to the target.
pub struct UdpProxy {
    pub port: u16,
    shared: Arc<Shared>,
    threads: Vec<JoinHandle<()>>,
}

impl UdpProxy {
    /// Starts a proxy on a free loopback port forwarding to `target`, impaired by `impairment`
    /// each way, its losses drawn from `seed`.
    pub fn start(target: SocketAddr, impairment: Impairment, seed: u64) -> std::io::Result<Self> {
        let front = Arc::new(UdpSocket::bind("127.0.0.1:0")?);
        front.set_read_timeout(Some(Duration::from_millis(20)))?;
        let port = front.local_addr()?.port();
        let shared = Arc::new(Shared {
            impairment: Mutex::new(impairment),
            paused_until: Mutex::new(None),
            queue: Mutex::new(BinaryHeap::new()),
            rng: Mutex::new(seed.max(1)),
            order: AtomicU64::new(0),
            stop: AtomicBool::new(false),
            stats: ProxyStats::default(),
        });
        let mut threads = Vec::new();
        // Sends what is due, every 200 us.
        {
            let (shared, front) = (shared.clone(), front.clone());
            threads.push(std::thread::spawn(move || {
                while !shared.stop.load(Ordering::Relaxed) {
                    let now = Instant::now();
                    loop {
                        let next = shared.queue.lock().ok().and_then(|mut q| {
                            if q.peek().is_some_and(|d| d.at <= now) {
                                q.pop()
                            } else {
                                None
                            }
                        });
                        let Some(d) = next else { break };
                        let sent = match &d.to {
                            Target::Server(back) => back.send(&d.data),
                            Target::Client(addr) => front.send_to(&d.data, addr),
                        };
                        if sent.is_ok() {
                            shared.stats.forwarded.fetch_add(1, Ordering::Relaxed);
                            shared
                                .stats
                                .bytes
                                .fetch_add(d.data.len() as u64, Ordering::Relaxed);
                        }
                    }
                    std::thread::sleep(Duration::from_micros(200));
                }
            }));
        }
        // Takes in from clients; each client gets its own back socket (and a reader of it).
        {
            let (shared, front) = (shared.clone(), front.clone());
            threads.push(std::thread::spawn(move || {
                let mut backs: HashMap<SocketAddr, Arc<UdpSocket>> = HashMap::new();
                let mut readers = Vec::new();
                let mut buf = vec![0u8; 65536];
                while !shared.stop.load(Ordering::Relaxed) {
                    let Ok((n, from)) = front.recv_from(&mut buf) else {
                        continue;
                    };
                    let back = match backs.get(&from) {
                        Some(b) => b.clone(),
                        None => {
                            let Ok(b) = UdpSocket::bind("127.0.0.1:0")
                                .and_then(|b| b.connect(target).map(|()| b))
                                .and_then(|b| {
                                    b.set_read_timeout(Some(Duration::from_millis(20)))
                                        .map(|()| b)
                                })
                            else {
                                continue;
                            };
                            let b = Arc::new(b);
                            backs.insert(from, b.clone());
                            let (shared, reader) = (shared.clone(), b.clone());
                            readers.push(std::thread::spawn(move || {
                                let mut buf = vec![0u8; 65536];
                                while !shared.stop.load(Ordering::Relaxed) {
                                    if let Ok(n) = reader.recv(&mut buf) {
                                        shared.pass(&buf[..n], Target::Client(from));
                                    }
                                }
                            }));
                            b
                        }
                    };
                    shared.pass(&buf[..n], Target::Server(back));
                }
                for r in readers {
                    let _ = r.join();
                }
            }));
        }
        Ok(UdpProxy {
            port,
            shared,
            threads,
        })
    }

    /// Drops every datagram, both ways, for `how_long` from now (a stalled link).
    pub fn pause(&self, how_long: Duration) {
        if let Ok(mut p) = self.shared.paused_until.lock() {
            *p = Some(Instant::now() + how_long);
        }
    }

    /// Changes the impairment from now on.
    pub fn set(&self, impairment: Impairment) {
        if let Ok(mut i) = self.shared.impairment.lock() {
            *i = impairment;
        }
    }

    pub fn stats(&self) -> &ProxyStats {
        &self.shared.stats
    }
}

impl Drop for UdpProxy {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn datagrams_cross_late_by_the_delay_and_the_loss_is_about_its_share() {
        let server = UdpSocket::bind("127.0.0.1:0").unwrap();
        server
            .set_read_timeout(Some(Duration::from_millis(500)))
            .unwrap();
        let target = server.local_addr().unwrap();
        let delay = Duration::from_millis(30);
        let proxy = UdpProxy::start(target, Impairment { delay, loss: 0.0 }, 7).unwrap();
        let client = UdpSocket::bind("127.0.0.1:0").unwrap();
        client
            .set_read_timeout(Some(Duration::from_millis(500)))
            .unwrap();
        let to = SocketAddr::from(([127, 0, 0, 1], proxy.port));
        let sent = Instant::now();
        client.send_to(b"ping", to).unwrap();
        let mut buf = [0u8; 16];
        let (n, back) = server.recv_from(&mut buf).unwrap();
        assert_eq!(&buf[..n], b"ping");
        assert!(sent.elapsed() >= delay, "{:?}", sent.elapsed());
        server.send_to(b"pong", back).unwrap();
        let n = client.recv(&mut buf).unwrap();
        assert_eq!(&buf[..n], b"pong");
        assert!(sent.elapsed() >= 2 * delay, "a round trip crosses twice");
        // 5 % loss over 2000 datagrams: about 100 lost, of those the proxy took in. Sent in
        // small bursts: a loaded machine's socket buffer may overflow under one burst of 2000,
        // and what the kernel drops before the proxy is not the proxy's loss.
        proxy.set(Impairment {
            delay: Duration::ZERO,
            loss: 0.05,
        });
        let forwarded_before = proxy.stats().forwarded.load(Ordering::Relaxed);
        for k in 0..2000 {
            client.send_to(b"x", to).unwrap();
            if k % 50 == 49 {
                std::thread::sleep(Duration::from_millis(1));
            }
        }
        std::thread::sleep(Duration::from_millis(200));
        let dropped = proxy.stats().dropped.load(Ordering::Relaxed);
        let taken_in = dropped + proxy.stats().forwarded.load(Ordering::Relaxed) - forwarded_before;
        assert!(taken_in >= 1000, "the proxy took in {taken_in} of 2000");
        let share = dropped as f64 / taken_in as f64;
        assert!(
            (0.025..0.10).contains(&share),
            "{dropped} of {taken_in} dropped"
        );
        // A pause drops everything.
        proxy.pause(Duration::from_millis(200));
        client.send_to(b"y", to).unwrap();
        std::thread::sleep(Duration::from_millis(20));
        assert!(proxy.stats().paused_drops.load(Ordering::Relaxed) >= 1);
    }
}
