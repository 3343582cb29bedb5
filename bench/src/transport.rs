//! `handblocks bench latency transport`: one hop between two processes, publish -> receive,
//! over the transports a user would weigh against each other, at payloads from 64 B to 4 MiB,
//! at 120 Hz and flat out.
//!
//! * `iceoryx2`: a zero-copy publish-subscribe service of byte slices, the reader woken by an
//!   event service and sleeping in `ppoll` on its listener (what the pipeline does);
//! * `iceoryx2-poll`: the same service, the reader spinning on `receive` (no wake-up);
//! * `uds`: a Unix domain stream socket, the reader blocking in `read` (copies in and out of
//!   the kernel);
//! * `tcp`: TCP over loopback, `TCP_NODELAY`, the same framing;
//! * `zenoh`: the bridge's hop across machines (issue 17), here over loopback: a zenoh peer
//!   publishing as the bridge does (TCP, express, `CongestionControl::Drop`, so a reader that
//!   falls behind loses samples rather than slowing the writer) to a subscriber woken by zenoh's
//!   own threads.
//!
//! The writer is a second process (this executable's hidden `bench-transport-peer`). For each
//! sample it writes the payload (a pattern: a producer writes its data once, into the loaned
//! shared memory or into its send buffer), stamps its first 8 bytes with `CLOCK_MONOTONIC`
//! (one clock for every process of the machine: the moment the data is complete), and sends. The reader takes
//! the clock again when the whole payload is its to read: a received iceoryx2 sample, or the
//! last byte read from the socket. Flat out, the writer sends back to back: a socket blocks the
//! writer when the reader falls behind (the figures include the queueing), while iceoryx2, set
//! as the pipeline sets it (safe overflow, 8 samples deep), overwrites the oldest unread sample,
//! so its rows count what was delivered of what was sent; throughput is what was delivered per
//! second.
//!
//! Writes `transport.json`, `transport.md`, `transport.png` (latency by percentile on
//! HdrHistogram's log "nines" axis, a panel per payload) and one `.hgrm` file per histogram in
//! HdrHistogram's percentile-distribution format (`hgrm::percentile_distribution`).

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::bus::BusConfig;
use common::config::session::LinkRole;
use common::latency::{new_histogram, Summary};
use common::monotonic_ns;
use hdrhistogram::Histogram;
use iceoryx2::prelude::*;
use serde_json::{json, Value};

use crate::hgrm::percentile_distribution;
use crate::page::{self, Provenance};
use crate::plot::{Axis, Figure, Join, Panel, Series};

/// The payloads measured, bytes.
pub const PAYLOADS: [usize; 5] = [64, 1024, 64 << 10, 1 << 20, 4 << 20];
/// The paced rate, samples per second.
pub const PACED_HZ: f64 = 120.0;

/// One way of moving bytes from one process to another.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transport {
    Iceoryx2,
    Iceoryx2Poll,
    Uds,
    Tcp,
    Zenoh,
}

impl Transport {
    pub const ALL: [Transport; 5] = [
        Transport::Iceoryx2,
        Transport::Iceoryx2Poll,
        Transport::Uds,
        Transport::Tcp,
        Transport::Zenoh,
    ];

    /// The name in the JSON, the tables and `--transport`.
    pub fn name(self) -> &'static str {
        match self {
            Transport::Iceoryx2 => "iceoryx2",
            Transport::Iceoryx2Poll => "iceoryx2-poll",
            Transport::Uds => "uds",
            Transport::Tcp => "tcp",
            Transport::Zenoh => "zenoh",
        }
    }

    pub fn from_name(name: &str) -> Option<Transport> {
        Transport::ALL.into_iter().find(|t| t.name() == name)
    }

    fn is_iceoryx2(self) -> bool {
        matches!(self, Transport::Iceoryx2 | Transport::Iceoryx2Poll)
    }
}

/// What the writer process is told: where to send, what, how often, how many.
#[derive(Debug, Clone, PartialEq)]
pub struct PeerArgs {
    pub transport: Transport,
    /// A bus id (iceoryx2), a socket path (uds) or `127.0.0.1:PORT` (tcp, zenoh).
    pub endpoint: String,
    pub bytes: usize,
    /// Samples per second; 0 = flat out.
    pub rate_hz: f64,
    pub count: u64,
}

/// One measured hop: a transport at a payload and rate.
pub struct Row {
    pub transport: Transport,
    pub payload_bytes: usize,
    /// 0 = flat out.
    pub rate_hz: f64,
    /// Samples the writer sent (`count` in the JSON is those delivered).
    pub sent: u64,
    pub histogram: Histogram<u64>,
    /// Samples delivered per second over the run.
    pub throughput_hz: f64,
}

impl Row {
    fn rate_name(&self) -> String {
        if self.rate_hz > 0.0 {
            format!("{:.0}hz", self.rate_hz)
        } else {
            "flat".to_string()
        }
    }

    /// `transport-iceoryx2-65536-120hz`: the row's `.hgrm` file stem.
    pub fn stem(&self) -> String {
        format!(
            "transport-{}-{}-{}",
            self.transport.name(),
            self.payload_bytes,
            self.rate_name()
        )
    }

    pub fn json(&self) -> Value {
        let s = Summary::of(&self.histogram);
        json!({
            "transport": self.transport.name(),
            "payload_bytes": self.payload_bytes,
            "rate_hz": self.rate_hz,
            "p50_us": s.p50, "p90_us": s.p90, "p99_us": s.p99, "p999_us": s.p999,
            "max_us": s.max, "count": s.count, "sent": self.sent,
            "throughput_hz": (self.throughput_hz * 10.0).round() / 10.0,
            "throughput_mib_s": (self.throughput_hz * self.payload_bytes as f64 / 1048576.0 * 10.0).round() / 10.0,
        })
    }
}

/// Options of `handblocks bench latency transport`.
pub struct TransportBench {
    /// This executable (the writer runs as its `bench-transport-peer`).
    pub exe: PathBuf,
    pub out_dir: PathBuf,
    /// 1 s paced runs and short flat-out runs (well under a minute on 2 cores).
    pub quick: bool,
}

// ---------------------------------------------------------------------------------------------
// The writer (a process of its own)

/// The smallest payload: the stamp (bytes 0..8) and the sample's number (8..16).
pub const MIN_PAYLOAD: usize = 16;

/// Writes sample `k`: a pattern (the cost of producing the data, the same for every
/// transport), its number, and last the stamp: the moment the data is complete.
fn stamp(buf: &mut [u8], k: u64) {
    for (i, b) in buf.iter_mut().enumerate().skip(MIN_PAYLOAD) {
        *b = (i as u64 ^ k) as u8;
    }
    buf[8..16].copy_from_slice(&k.to_le_bytes());
    buf[..8].copy_from_slice(&monotonic_ns().to_le_bytes());
}

fn read_u64(buf: &[u8], at: usize) -> u64 {
    let mut b = [0u8; 8];
    b.copy_from_slice(&buf[at..at + 8]);
    u64::from_le_bytes(b)
}

fn pace(start: u64, k: u64, rate_hz: f64) {
    if rate_hz > 0.0 {
        common::stamp::sleep_until_ns(start + (k as f64 * 1e9 / rate_hz) as u64);
    }
}

/// The writing half: connects to the reader's endpoint and sends `count` payloads.
pub fn peer(a: &PeerArgs) -> Result<(), Box<dyn std::error::Error>> {
    if a.bytes < MIN_PAYLOAD {
        return Err(format!(
            "--bytes {}: at least {MIN_PAYLOAD} (the stamp and the number)",
            a.bytes
        )
        .into());
    }
    match a.transport {
        Transport::Iceoryx2 | Transport::Iceoryx2Poll => {
            let config = BusConfig::for_session(&a.endpoint)?;
            let (_node, pubsub, event) = services(&config, a.bytes)?;
            let publisher = pubsub
                .publisher_builder()
                .initial_max_slice_len(a.bytes)
                .max_loaned_samples(2)
                .create()
                .map_err(|e| format!("{e:?}"))?;
            let notifier = event
                .notifier_builder()
                .create()
                .map_err(|e| format!("{e:?}"))?;
            let start = monotonic_ns();
            for k in 0..a.count {
                pace(start, k, a.rate_hz);
                let sample = publisher
                    .loan_slice_uninit(a.bytes)
                    .map_err(|e| format!("{e:?}"))?;
                // Written once, in place, as `stamp` writes a socket's buffer.
                let mut sample = sample.write_from_fn(|i| (i as u64 ^ k) as u8);
                let payload = sample.payload_mut();
                payload[8..16].copy_from_slice(&k.to_le_bytes());
                payload[..8].copy_from_slice(&monotonic_ns().to_le_bytes());
                sample.send().map_err(|e| format!("{e:?}"))?;
                if a.transport == Transport::Iceoryx2 {
                    notifier.notify().map_err(|e| format!("{e:?}"))?;
                }
            }
            // Stay until the reader has everything (it reads our memory).
            common::shutdown::watch_parent_pipe();
            common::shutdown::wait_for_release(Duration::from_secs(10));
        }
        Transport::Zenoh => {
            use zenoh::Wait;
            let session = zenoh::open(bridge::link::peer_config(
                &format!("tcp/{}", a.endpoint),
                LinkRole::Connect,
                None,
            )?)
            .wait()
            .map_err(|e| e.to_string())?;
            let publisher = bridge::link::declare_sender(&session, ZENOH_KEY.to_string())
                .map_err(|e| e.to_string())?;
            // Not before the reader's subscription is known here: what went out before would
            // be lost to nobody, not to the link.
            let until = Instant::now() + Duration::from_secs(20);
            while !publisher
                .matching_status()
                .wait()
                .map_err(|e| e.to_string())?
                .matching()
            {
                if Instant::now() > until {
                    return Err("zenoh: the reader never subscribed".into());
                }
                std::thread::sleep(Duration::from_millis(5));
            }
            let mut buf = vec![0u8; a.bytes];
            let start = monotonic_ns();
            for k in 0..a.count {
                pace(start, k, a.rate_hz);
                stamp(&mut buf, k);
                publisher.put(&buf[..]).wait().map_err(|e| e.to_string())?;
            }
            // Stay until the reader has everything (zenoh sends from its own threads).
            common::shutdown::watch_parent_pipe();
            common::shutdown::wait_for_release(Duration::from_secs(10));
            let _ = session.close().wait();
        }
        Transport::Uds | Transport::Tcp => {
            let mut stream: Box<dyn Write> = if a.transport == Transport::Uds {
                Box::new(UnixStream::connect(&a.endpoint)?)
            } else {
                let s = TcpStream::connect(&a.endpoint)?;
                s.set_nodelay(true)?;
                Box::new(s)
            };
            let mut buf = vec![0u8; a.bytes];
            let start = monotonic_ns();
            for k in 0..a.count {
                pace(start, k, a.rate_hz);
                stamp(&mut buf, k);
                stream.write_all(&buf)?;
            }
            stream.flush()?;
        }
    }
    Ok(())
}

/// The key of the zenoh runs (each reader listens on a port of its own, and finds no one by
/// multicast, so runs never hear each other). Both sides are set up as the bridge's are
/// (`bridge::link::peer_config`, `declare_sender`).
const ZENOH_KEY: &str = "handblocks/bench/transport";

type ByteService =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, [u8], ()>;
type EventService = iceoryx2::service::port_factory::event::PortFactory<ipc::Service>;

/// This process's node on `config`'s bus, the byte-slice service and its event service, sized for one reader and one writer (so
/// iceoryx2's data segment, which it zeroes when the writer attaches, stays small at 4 MiB);
/// a reader 8 samples behind loses the oldest, as in the pipeline.
fn services(
    config: &BusConfig,
    bytes: usize,
) -> Result<(Node<ipc::Service>, ByteService, EventService), Box<dyn std::error::Error>> {
    let node = NodeBuilder::new()
        .config(&config.iceoryx()?)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(|e| format!("{e:?}"))?;
    let name = ServiceName::new(&format!("transport-{bytes}")).map_err(|e| format!("{e:?}"))?;
    let pubsub = node
        .service_builder(&name)
        .publish_subscribe::<[u8]>()
        .max_publishers(1)
        .max_subscribers(1)
        .subscriber_max_buffer_size(8)
        .subscriber_max_borrowed_samples(2)
        .history_size(0)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| format!("{e:?}"))?;
    let event = node
        .service_builder(&name)
        .event()
        .open_or_create()
        .map_err(|e| format!("{e:?}"))?;
    Ok((node, pubsub, event))
}

// ---------------------------------------------------------------------------------------------
// The reader (this process)

fn spawn_peer(exe: &Path, a: &PeerArgs) -> Result<Child, Box<dyn std::error::Error>> {
    Ok(Command::new(exe)
        .args([
            "bench-transport-peer",
            "--transport",
            a.transport.name(),
            "--endpoint",
            &a.endpoint,
            "--bytes",
            &a.bytes.to_string(),
            "--rate",
            &a.rate_hz.to_string(),
            "--count",
            &a.count.to_string(),
        ])
        .stdin(Stdio::piped())
        .spawn()?)
}

/// Sleeps until `fd` is readable or `timeout` passes (the pipeline's wait: `ppoll`).
fn wait_readable(fd: i32, timeout: Duration) {
    let mut fds = [libc::pollfd {
        fd,
        events: libc::POLLIN,
        revents: 0,
    }];
    let ts = libc::timespec {
        tv_sec: timeout.as_secs() as libc::time_t,
        tv_nsec: timeout.subsec_nanos() as libc::c_long,
    };
    // SAFETY: one valid pollfd on the stack; `ts` outlives the call.
    unsafe { libc::ppoll(fds.as_mut_ptr(), 1, &ts, std::ptr::null()) };
}

/// One hop measured: starts the writer, reads `count` payloads, returns their latencies.
fn measure(exe: &Path, a: &PeerArgs) -> Result<Row, Box<dyn std::error::Error>> {
    let mut hist = new_histogram();
    let deadline = Instant::now()
        + Duration::from_secs_f64(if a.rate_hz > 0.0 {
            a.count as f64 / a.rate_hz + 20.0
        } else {
            60.0
        });
    let late = || {
        format!(
            "{} {} B: the writer stopped early",
            a.transport.name(),
            a.bytes
        )
    };
    let mut record = |t0: u64| {
        hist.saturating_record(monotonic_ns().saturating_sub(t0).max(1));
    };
    let started = Instant::now();
    let mut first: Option<Instant> = None;
    match a.transport {
        Transport::Iceoryx2 | Transport::Iceoryx2Poll => {
            let config = BusConfig::for_session(&a.endpoint)?;
            let result = (|| -> Result<(), Box<dyn std::error::Error>> {
                let (_node, pubsub, event) = services(&config, a.bytes)?;
                let subscriber = pubsub
                    .subscriber_builder()
                    .buffer_size(8)
                    .create()
                    .map_err(|e| format!("{e:?}"))?;
                let listener = event
                    .listener_builder()
                    .create()
                    .map_err(|e| format!("{e:?}"))?;
                // SAFETY: the descriptor stays owned by the listener, which outlives its use.
                let fd = unsafe { listener.file_descriptor().native_handle() };
                let mut child = spawn_peer(exe, a)?;
                // Until the last sample arrives (some may be overwritten unread, flat out).
                let mut last = false;
                while !last {
                    if Instant::now() > deadline {
                        return Err(late().into());
                    }
                    if a.transport == Transport::Iceoryx2 {
                        wait_readable(fd, Duration::from_millis(50));
                        let _ = listener.try_wait(|_| {});
                    }
                    while let Some(s) = subscriber.receive().map_err(|e| format!("{e:?}"))? {
                        record(read_u64(s.payload(), 0));
                        first.get_or_insert_with(Instant::now);
                        last |= read_u64(s.payload(), 8) + 1 == a.count;
                    }
                    if a.transport == Transport::Iceoryx2Poll {
                        std::hint::spin_loop();
                    }
                }
                drop(child.stdin.take());
                let _ = child.wait();
                Ok(())
            })();
            let _ = config.remove_resources();
            result?;
        }
        Transport::Zenoh => {
            use zenoh::Wait;
            let port = TcpListener::bind("127.0.0.1:0")?.local_addr()?.port();
            let args = PeerArgs {
                endpoint: format!("127.0.0.1:{port}"),
                ..a.clone()
            };
            let session = zenoh::open(bridge::link::peer_config(
                &format!("tcp/{}", args.endpoint),
                LinkRole::Listen,
                None,
            )?)
            .wait()
            .map_err(|e| e.to_string())?;
            let subscriber = session
                .declare_subscriber(ZENOH_KEY)
                .wait()
                .map_err(|e| e.to_string())?;
            let mut child = spawn_peer(exe, &args)?;
            // Until the last sample, or (flat out, where the link may drop it) a second with
            // nothing after the writer began.
            let mut last_arrival = Instant::now();
            loop {
                if Instant::now() > deadline {
                    let _ = child.kill();
                    return Err(late().into());
                }
                match subscriber.recv_timeout(Duration::from_millis(100)) {
                    Ok(Some(sample)) => {
                        let bytes = sample.payload().to_bytes();
                        record(read_u64(&bytes, 0));
                        first.get_or_insert_with(Instant::now);
                        last_arrival = Instant::now();
                        if read_u64(&bytes, 8) + 1 == a.count {
                            break;
                        }
                    }
                    Ok(None) => {
                        if first.is_some() && last_arrival.elapsed() > Duration::from_secs(1) {
                            break;
                        }
                    }
                    Err(e) => return Err(format!("zenoh: {e}").into()),
                }
            }
            drop(child.stdin.take());
            let _ = child.wait();
            let _ = session.close().wait();
        }
        Transport::Uds | Transport::Tcp => {
            let mut buf = vec![0u8; a.bytes];
            let mut child: Child;
            let mut stream: Box<dyn Read> = if a.transport == Transport::Uds {
                let listener = UnixListener::bind(&a.endpoint)?;
                child = spawn_peer(exe, a)?;
                let (s, _) = listener.accept()?;
                let _ = std::fs::remove_file(&a.endpoint);
                Box::new(s)
            } else {
                let listener = TcpListener::bind("127.0.0.1:0")?;
                let args = PeerArgs {
                    endpoint: listener.local_addr()?.to_string(),
                    ..a.clone()
                };
                child = spawn_peer(exe, &args)?;
                let (s, _) = listener.accept()?;
                s.set_nodelay(true)?;
                Box::new(s)
            };
            for _ in 0..a.count {
                if Instant::now() > deadline {
                    return Err(late().into());
                }
                stream
                    .read_exact(&mut buf)
                    .map_err(|e| format!("{}: {e}", late()))?;
                record(read_u64(&buf, 0));
                first.get_or_insert_with(Instant::now);
            }
            let _ = child.wait();
        }
    }
    let span = first.map_or(started.elapsed(), |f| f.elapsed());
    let delivered = hist.len();
    let throughput_hz = if span.as_secs_f64() > 0.0 && delivered > 1 {
        (delivered - 1) as f64 / span.as_secs_f64()
    } else {
        0.0
    };
    Ok(Row {
        transport: a.transport,
        payload_bytes: a.bytes,
        rate_hz: a.rate_hz,
        sent: a.count,
        histogram: hist,
        throughput_hz,
    })
}

/// Samples of one run: a paced run lasts 1 s (quick) or 5 s; a flat-out one moves at most
/// 256 MiB (quick) or 1 GiB, and at least 50 samples.
fn count_for(bytes: usize, rate_hz: f64, quick: bool) -> u64 {
    if rate_hz > 0.0 {
        (rate_hz * if quick { 1.0 } else { 5.0 }) as u64
    } else {
        let (n, bytes_at_most): (u64, u64) = if quick {
            (500, 1 << 28)
        } else {
            (5000, 1 << 30)
        };
        n.min((bytes_at_most / bytes as u64).max(50))
    }
}

/// Runs every transport at every payload, paced and flat out; writes the outputs.
pub fn run(b: &TransportBench) -> Result<Value, Box<dyn std::error::Error>> {
    let rates = [PACED_HZ, 0.0];
    let total = Transport::ALL.len() * PAYLOADS.len() * rates.len();
    let scratch = std::env::temp_dir().join(format!("hb-transport-{}", std::process::id()));
    std::fs::create_dir_all(&scratch)?;
    let measured = measure_all(b, &rates, total, &scratch);
    // The sockets' folder goes whatever happened.
    let _ = std::fs::remove_dir_all(&scratch);
    write_outputs(&measured?, b)
}

fn measure_all(
    b: &TransportBench,
    rates: &[f64],
    total: usize,
    scratch: &Path,
) -> Result<Vec<Row>, Box<dyn std::error::Error>> {
    let mut rows: Vec<Row> = Vec::with_capacity(total);
    let t0 = Instant::now();
    for &rate in rates {
        for &bytes in &PAYLOADS {
            for t in Transport::ALL {
                let endpoint = if t.is_iceoryx2() {
                    format!("tr{}_{}", std::process::id(), rows.len())
                } else {
                    scratch
                        .join(format!("s{}", rows.len()))
                        .to_string_lossy()
                        .into_owned()
                };
                let a = PeerArgs {
                    transport: t,
                    endpoint,
                    bytes,
                    rate_hz: rate,
                    count: count_for(bytes, rate, b.quick),
                };
                let row = measure(&b.exe, &a)?;
                let s = Summary::of(&row.histogram);
                eprintln!(
                    "bench latency transport: [{}/{total}] {:<13} {:>8} B {:>6}: p50 {:.1} us, p99 {:.1} us ({:.0} s so far)",
                    rows.len() + 1,
                    t.name(),
                    bytes,
                    row.rate_name(),
                    s.p50,
                    s.p99,
                    t0.elapsed().as_secs_f64()
                );
                rows.push(row);
            }
        }
    }
    Ok(rows)
}

fn find(rows: &[Row], t: Transport, bytes: usize, rate: f64) -> Option<&Row> {
    rows.iter()
        .find(|r| r.transport == t && r.payload_bytes == bytes && r.rate_hz == rate)
}

fn size_name(bytes: usize) -> String {
    match bytes {
        b if b >= 1 << 20 => format!("{} MiB", b >> 20),
        b if b >= 1 << 10 => format!("{} KiB", b >> 10),
        b => format!("{b} B"),
    }
}

fn write_outputs(rows: &[Row], b: &TransportBench) -> Result<Value, Box<dyn std::error::Error>> {
    std::fs::create_dir_all(&b.out_dir)?;
    let hgrm_dir = b.out_dir.join("hgrm");
    std::fs::create_dir_all(&hgrm_dir)?;
    for r in rows {
        std::fs::write(
            hgrm_dir.join(format!("{}.hgrm", r.stem())),
            percentile_distribution(&r.histogram, 1000.0),
        )?;
    }
    // iceoryx2 (woken) against the Unix socket, per payload: the case for shared memory; and
    // the bridged hop (zenoh) against it: what leaving the machine costs.
    let ratios_json = |t: Transport, p50_key: &str, p99_key: &str| -> Vec<Value> {
        over_iceoryx2(rows, t)
            .into_iter()
            .map(|(bytes, rate, p50, p99)| {
                json!({"payload_bytes": bytes, "rate_hz": rate, p50_key: round2(p50), p99_key: round2(p99)})
            })
            .collect()
    };
    let ratios = ratios_json(
        Transport::Uds,
        "uds_p50_over_iceoryx2_p50",
        "uds_p99_over_iceoryx2_p99",
    );
    let bridged = ratios_json(
        Transport::Zenoh,
        "zenoh_p50_over_iceoryx2_p50",
        "zenoh_p99_over_iceoryx2_p99",
    );
    let value = json!({
        "quick": b.quick,
        "transport": rows.iter().map(Row::json).collect::<Vec<_>>(),
        "uds_over_iceoryx2": ratios,
        "zenoh_over_iceoryx2": bridged,
    });
    std::fs::write(
        b.out_dir.join("transport.json"),
        serde_json::to_string_pretty(&value)? + "\n",
    )?;
    crate::latency::merge_into_latency_json(&b.out_dir, "transport", value["transport"].clone())?;
    let provenance = Provenance::of_this_run(b.quick, &b.out_dir);
    std::fs::write(
        b.out_dir.join("transport.md"),
        markdown(rows, b.quick, &provenance),
    )?;
    let png = b.out_dir.join("transport.png");
    let drawn = figure(rows).write_png(&png)?;
    eprintln!(
        "bench latency transport: wrote {}, transport.md{}, and {} .hgrm files in {}",
        b.out_dir.join("transport.json").display(),
        if drawn { ", transport.png" } else { "" },
        rows.len(),
        hgrm_dir.display()
    );
    Ok(value)
}

/// `t`'s p50 and p99 as multiples of the woken iceoryx2 hop's, per payload and rate, for the
/// rows measured in this run.
fn over_iceoryx2(rows: &[Row], t: Transport) -> Vec<(usize, f64, f64, f64)> {
    let mut out = Vec::new();
    for &bytes in &PAYLOADS {
        for rate in [PACED_HZ, 0.0] {
            if let (Some(i), Some(o)) = (
                find(rows, Transport::Iceoryx2, bytes, rate),
                find(rows, t, bytes, rate),
            ) {
                let (si, so) = (Summary::of(&i.histogram), Summary::of(&o.histogram));
                out.push((bytes, rate, so.p50 / si.p50, so.p99 / si.p99));
            }
        }
    }
    out
}

fn round2(v: f64) -> f64 {
    if v.is_finite() {
        (v * 100.0).round() / 100.0
    } else {
        f64::NAN
    }
}

fn markdown(rows: &[Row], quick: bool, provenance: &Provenance) -> String {
    let what = format!(
        "One hop between two processes, publish -> receive: from the writer's clock when the \
         payload is complete to the reader's clock when it is the reader's to read \
         (`CLOCK_MONOTONIC`, one clock for both), over the transports a user would weigh \
         against each other, at payloads of 64 B to 4 MiB, paced at 120 Hz and flat out \
         ({}). `iceoryx2`: zero-copy shared memory, the reader woken by an event and sleeping \
         in `ppoll` (what the pipeline does); `iceoryx2-poll`: the same, the reader spinning \
         on `receive`; `uds`: a Unix stream socket; `tcp`: loopback, `TCP_NODELAY`; `zenoh`: \
         the bridge's hop across machines, here over loopback (TCP, express, dropping when \
         the link is full). Flat out, the writer sends back to back: a socket blocks the \
         writer (the queueing counts), iceoryx2 overwrites the oldest unread sample 8 behind \
         (the pipeline's setting), so it may deliver fewer than were sent.\n\n\
         How to read it: lower is better; the two ratio tables divide a transport's \
         percentile by iceoryx2's (woken) at the same payload and rate, measured in this run \
         on this machine, so 3.00x means three times as long as the shared-memory hop. The \
         figure draws each payload's latency by percentile (p50 to the tail, HdrHistogram's \
         log axis) at 120 Hz; every histogram is also an `.hgrm` file under `hgrm/`.",
        if quick {
            "quick run: 1 s paced, up to 500 samples flat out"
        } else {
            "5 s paced, up to 5000 samples (1 GiB) flat out"
        }
    );
    let mut md = page::head(
        "Benchmark: one hop between two processes, by transport",
        &what,
        provenance,
    );
    md.push_str(&page::figure(
        "latency by percentile per payload at 120 Hz, one line per transport",
        "transport.png",
    ));
    for (t, title) in [
        (Transport::Uds, "The Unix socket's latency as a multiple of iceoryx2's (same run)"),
        (
            Transport::Zenoh,
            "The bridged hop (zenoh, loopback) as a multiple of the local one (iceoryx2, woken; same run)",
        ),
    ] {
        md.push_str(&format!(
            "## {title}\n\n| payload | rate | p50 | p99 |\n|---|---|---|---|\n"
        ));
        for (bytes, rate, p50, p99) in over_iceoryx2(rows, t) {
            md.push_str(&format!(
                "| {} | {} | {p50:.2}x | {p99:.2}x |\n",
                size_name(bytes),
                if rate > 0.0 { "120 Hz" } else { "flat out" },
            ));
        }
        md.push('\n');
    }
    md.push_str("## Every hop\n\n");
    md.push_str("| transport | payload | rate | p50 (us) | p90 | p99 | p99.9 | max | delivered / sent | throughput (/s) |\n|---|---|---|---|---|---|---|---|---|---|\n");
    for r in rows {
        let s = Summary::of(&r.histogram);
        md.push_str(&format!(
            "| {} | {} | {} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {} / {} | {:.0} |\n",
            r.transport.name(),
            size_name(r.payload_bytes),
            if r.rate_hz > 0.0 {
                format!("{:.0} Hz", r.rate_hz)
            } else {
                "flat out".into()
            },
            s.p50,
            s.p90,
            s.p99,
            s.p999,
            s.max,
            s.count,
            r.sent,
            r.throughput_hz
        ));
    }
    md
}

/// Latency by percentile on HdrHistogram's axis (1 / (1 - percentile), labelled in nines),
/// one panel per payload at 120 Hz, a line per transport.
fn figure(rows: &[Row]) -> Figure {
    let panels = PAYLOADS
        .iter()
        .map(|&bytes| Panel {
            title: format!("{} at 120 Hz", size_name(bytes)),
            x: Axis::nines(),
            y: Axis::log("latency (us)"),
            series: Transport::ALL
                .iter()
                .filter_map(|&t| find(rows, t, bytes, PACED_HZ))
                .map(|r| Series::nines(r.transport.name(), &r.histogram))
                .collect(),
            marked: Vec::new(),
            join: Join::Curve,
        })
        .collect();
    Figure {
        panels,
        columns: 3,
        panel_width: 440,
        panel_height: 340,
        column_weights: Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transports_have_names_that_round_trip() {
        for t in Transport::ALL {
            assert_eq!(Transport::from_name(t.name()), Some(t));
        }
        assert_eq!(Transport::from_name("pigeon"), None);
    }

    #[test]
    fn flat_out_runs_move_at_most_a_gibibyte() {
        assert_eq!(count_for(64, 0.0, false), 5000);
        assert_eq!(count_for(4 << 20, 0.0, false), 256);
        assert_eq!(count_for(4 << 20, 0.0, true), 64);
        assert_eq!(count_for(64, PACED_HZ, true), 120);
    }
}
