//! The zenoh side of the bridge: one peer session on the link's endpoint, a publisher per topic
//! sent, a subscriber per topic taken in, and the clock exchange (see [`crate::clock`]).
//!
//! Keys: topic `world` travels on `KEY/world`; the sending side answers clock queries on
//! `KEY/clock/TOPIC` for each topic it sends, so a receiver asks the very process that stamps
//! what it receives (two viewers on one link never answer each other).
//!
//! Backpressure never reaches the pipeline: the bridge reads the bus like any reader (a slow
//! bridge loses its own samples, never the stepper's time), its publishers drop rather than
//! block when the link's queue is full (`CongestionControl::Drop`), and the receiving side's
//! callback hands samples to the bridge's loop through a bounded queue that drops, counted,
//! when the loop falls behind. What was lost shows as gaps in the seqs the receiver publishes.

use std::os::fd::RawFd;
use std::sync::atomic::{AtomicBool, AtomicI64, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use common::bus::Wake;
use common::config::session::{LinkRole, RemoteLink};
use common::{monotonic_ns, Topic};
use zenoh::bytes::ZBytes;
use zenoh::pubsub::{Publisher, Subscriber};
use zenoh::qos::{CongestionControl, Priority};
use zenoh::query::Queryable;
use zenoh::Wait;

use crate::clock::{ClockOffset, Exchange};

/// Samples taken in and not yet published on the bus: two seconds of a 1 kHz source per topic.
const INCOMING_QUEUE: usize = 4096;

/// Why the link could not be opened.
#[derive(Debug)]
pub enum LinkError {
    /// zenoh refused the configuration or could not open the session (a busy port, say).
    Open { endpoint: String, reason: String },
    /// A publisher, subscriber or queryable could not be declared.
    Declare { key: String, reason: String },
    /// The wake-up descriptor could not be made.
    EventFd(std::io::Error),
}

impl std::fmt::Display for LinkError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LinkError::Open { endpoint, reason } => write!(
                f,
                "cannot open the zenoh link on {endpoint}: {reason} (is the port in use, or \
                 the host not this machine's? [remote] endpoint / role name it)"
            ),
            LinkError::Declare { key, reason } => {
                write!(f, "cannot declare zenoh key {key}: {reason}")
            }
            LinkError::EventFd(e) => write!(f, "cannot make the bridge's wake-up descriptor: {e}"),
        }
    }
}

impl std::error::Error for LinkError {}

/// One sample taken in, as it arrived.
pub struct Incoming {
    pub topic: Topic,
    /// When zenoh handed it to us (our clock).
    pub arrived_ns: u64,
    pub bytes: ZBytes,
}

/// The clock estimate, shared between the exchange thread and the bridge's loop.
#[derive(Default)]
pub struct SharedClock {
    known: AtomicBool,
    offset_ns: AtomicI64,
    uncertainty_ns: AtomicU64,
    exchanges: AtomicU64,
}

impl SharedClock {
    /// Their clock minus ours, once known.
    pub fn offset_ns(&self) -> Option<i64> {
        self.known
            .load(Ordering::Acquire)
            .then(|| self.offset_ns.load(Ordering::Relaxed))
    }

    pub fn uncertainty_ns(&self) -> u64 {
        self.uncertainty_ns.load(Ordering::Relaxed)
    }

    pub fn exchanges(&self) -> u64 {
        self.exchanges.load(Ordering::Relaxed)
    }
}

/// The open link.
pub struct Link {
    session: zenoh::Session,
    publishers: Vec<(Topic, Publisher<'static>)>,
    _subscribers: Vec<Subscriber<()>>,
    _clock_answers: Vec<Queryable<()>>,
    pub incoming: crossbeam_channel::Receiver<Incoming>,
    /// Written by the subscribers' callback after each sample queued: the loop sleeps on it.
    wake: Arc<Wake>,
    /// Samples the queue had no room for.
    pub queue_full: Arc<AtomicU64>,
    pub clock: Arc<SharedClock>,
    stop_clock: Arc<AtomicBool>,
    clock_thread: Option<std::thread::JoinHandle<()>>,
    pub endpoint: String,
}

/// zenoh's configuration for one side of a link: a peer, on TCP, that listens on or connects
/// to `endpoint` (`tcp/HOST:PORT`; a connecting side retries every 100-500 ms until the other
/// answers, so the halves start in either order), and finds no one by multicast (a session
/// talks to whom its file names). The latency bench's zenoh rows use it too.
pub fn peer_config(endpoint: &str, role: LinkRole) -> Result<zenoh::Config, String> {
    let mut c = zenoh::Config::default();
    let set = |c: &mut zenoh::Config, k: &str, v: &str| {
        c.insert_json5(k, v).map_err(|e| format!("{k} = {v}: {e}"))
    };
    set(&mut c, "mode", "\"peer\"")?;
    set(&mut c, "scouting/multicast/enabled", "false")?;
    let endpoint = serde_json::to_string(&[endpoint]).map_err(|e| e.to_string())?;
    match role {
        LinkRole::Listen => {
            set(&mut c, "listen/endpoints", &endpoint)?;
        }
        LinkRole::Connect => {
            set(&mut c, "listen/endpoints", "[]")?;
            set(&mut c, "connect/endpoints", &endpoint)?;
            set(&mut c, "connect/timeout_ms", "-1")?;
            set(&mut c, "connect/exit_on_failure", "false")?;
            set(
                &mut c,
                "connect/retry",
                "{ period_init_ms: 100, period_max_ms: 500, period_increase_factor: 2 }",
            )?;
        }
    }
    Ok(c)
}

/// A publisher on `key` as the bridge sends: dropping rather than blocking when the link is
/// full (backpressure never reaches the pipeline), high priority, and express (not batched:
/// a world state goes out as soon as it is put). The latency bench's zenoh writer uses it too.
pub fn declare_sender(
    session: &zenoh::Session,
    key: String,
) -> Result<Publisher<'static>, zenoh::Error> {
    session
        .declare_publisher(key)
        .congestion_control(CongestionControl::Drop)
        .priority(Priority::InteractiveHigh)
        .express(true)
        .wait()
}

impl Link {
    pub fn open(link: &RemoteLink) -> Result<Link, LinkError> {
        let open_err = |reason: String| LinkError::Open {
            endpoint: link.endpoint.clone(),
            reason,
        };
        let session = zenoh::open(peer_config(&link.endpoint, link.role).map_err(open_err)?)
            .wait()
            .map_err(|e| open_err(e.to_string()))?;
        let declare_err = |key: &str, e: zenoh::Error| LinkError::Declare {
            key: key.to_string(),
            reason: e.to_string(),
        };
        let mut publishers = Vec::new();
        let mut clock_answers = Vec::new();
        for &topic in &link.publish {
            let key = format!("{}/{}", link.key, topic.name());
            let p = declare_sender(&session, key.clone()).map_err(|e| declare_err(&key, e))?;
            publishers.push((topic, p));
            let clock_key = format!("{}/clock/{}", link.key, topic.name());
            let q = session
                .declare_queryable(clock_key.clone())
                .callback(|query| {
                    let now = monotonic_ns().to_le_bytes();
                    let _ = query.reply(query.key_expr().clone(), &now[..]).wait();
                })
                .wait()
                .map_err(|e| declare_err(&clock_key, e))?;
            clock_answers.push(q);
        }
        let wake = Arc::new(Wake::new().map_err(LinkError::EventFd)?);
        let queue_full = Arc::new(AtomicU64::new(0));
        let (tx, incoming) = crossbeam_channel::bounded(INCOMING_QUEUE);
        let mut subscribers = Vec::new();
        for &topic in &link.subscribe {
            let key = format!("{}/{}", link.key, topic.name());
            let tx = tx.clone();
            let wake = wake.clone();
            let full = queue_full.clone();
            let s = session
                .declare_subscriber(key.clone())
                .callback(move |sample| {
                    let item = Incoming {
                        topic,
                        arrived_ns: monotonic_ns(),
                        bytes: sample.payload().clone(),
                    };
                    match tx.try_send(item) {
                        Ok(()) => wake.wake(),
                        Err(_) => {
                            full.fetch_add(1, Ordering::Relaxed);
                        }
                    }
                })
                .wait()
                .map_err(|e| declare_err(&key, e))?;
            subscribers.push(s);
        }
        let clock = Arc::new(SharedClock::default());
        let stop_clock = Arc::new(AtomicBool::new(false));
        let clock_thread = link.subscribe.first().map(|first| {
            let key = format!("{}/clock/{}", link.key, first.name());
            let (session, clock, stop) = (session.clone(), clock.clone(), stop_clock.clone());
            std::thread::spawn(move || exchange_clocks(&session, &key, &clock, &stop))
        });
        Ok(Link {
            session,
            publishers,
            _subscribers: subscribers,
            _clock_answers: clock_answers,
            incoming,
            wake,
            queue_full,
            clock,
            stop_clock,
            clock_thread,
            endpoint: link.endpoint.clone(),
        })
    }

    /// The descriptor the loop sleeps on besides its inlets (readable: samples queued).
    pub fn wake_fd(&self) -> RawFd {
        self.wake.fd()
    }

    /// Consumes the wake-ups (the queue itself is drained by the caller).
    pub fn clear_wake(&self) {
        self.wake.clear();
    }

    /// Sends `message` on `topic`'s key; false when the topic is not sent on this link.
    /// Never blocks: a full link drops (zenoh's congestion control).
    pub fn put(&self, topic: Topic, message: &[u8]) -> Result<bool, String> {
        let Some((_, p)) = self.publishers.iter().find(|(t, _)| *t == topic) else {
            return Ok(false);
        };
        p.put(message).wait().map_err(|e| e.to_string())?;
        Ok(true)
    }

    /// How many peers this side is connected to now.
    pub fn peers(&self) -> usize {
        self.session.info().peers_zid().wait().count()
    }

    /// Stops the clock exchange and closes the session.
    pub fn close(mut self) {
        self.stop_clock.store(true, Ordering::Release);
        if let Some(t) = self.clock_thread.take() {
            let _ = t.join();
        }
        let _ = self.session.close().wait();
    }
}

/// Asks the sender's clock every 50 ms until an answer came, then every second, and keeps the
/// estimate in `shared` (see [`crate::clock`]).
fn exchange_clocks(session: &zenoh::Session, key: &str, shared: &SharedClock, stop: &AtomicBool) {
    let mut estimate = ClockOffset::default();
    while !stop.load(Ordering::Acquire) {
        let sent_ns = monotonic_ns();
        if let Ok(replies) = session.get(key).timeout(Duration::from_millis(500)).wait() {
            while let Ok(reply) = replies.recv() {
                let received_ns = monotonic_ns();
                let Ok(sample) = reply.result() else { continue };
                let bytes = sample.payload().to_bytes();
                let Ok(their) = <[u8; 8]>::try_from(&bytes[..]) else {
                    continue;
                };
                estimate.add(Exchange {
                    sent_ns,
                    their_ns: u64::from_le_bytes(their),
                    received_ns,
                });
                if let (Some(offset), Some(u)) = (estimate.offset_ns(), estimate.uncertainty_ns()) {
                    shared.offset_ns.store(offset, Ordering::Relaxed);
                    shared.uncertainty_ns.store(u, Ordering::Relaxed);
                    shared
                        .exchanges
                        .store(estimate.exchanges(), Ordering::Relaxed);
                    shared.known.store(true, Ordering::Release);
                }
                break;
            }
        }
        // The first exchanges in a burst (the best of a few is much better than one), then
        // one a second to follow the clocks' drift.
        let pause = if estimate.exchanges() < 8 { 50 } else { 1000 };
        let until = monotonic_ns() + pause * 1_000_000;
        while monotonic_ns() < until && !stop.load(Ordering::Acquire) {
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}
