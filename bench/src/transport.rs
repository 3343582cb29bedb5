//! `handblocks bench latency transport`: one hop between two processes, publish -> receive,
//! over the transports a user would weigh against each other, at payloads from 64 B to 4 MiB,
//! at 120 Hz and flat out.
//!
//! * `iceoryx2`: a zero-copy publish-subscribe service of byte slices, the reader woken by an
//!   event service and sleeping in `ppoll` on its listener (what the pipeline does);
//! * `iceoryx2-doorbell`: the same service, the reader woken by a doorbell
//!   (`common::bus::Doorbell`: a futex word the writer rings after each send), as the
//!   pipeline's kinematics and stepper are (issue 46);
//! * `iceoryx2-semaphore`: the same service, the reader woken by an event service of
//!   `common::bus::semaphore::SemaphoreIpc` (iceoryx2's semaphore event: a futex in shared
//!   memory, no socket) and sleeping on its listener (issue 46);
//! * `iceoryx2-poll`: the same service, the reader spinning on `receive` (no wake-up);
//! * `futex`: the floor of a woken hop: a ring of 8 payloads in shared memory written in
//!   place, the published count a futex word the reader sleeps on (`FUTEX_WAIT`) and the
//!   writer wakes (`FUTEX_WAKE`); no library at all;
//! * `eventfd`: the same ring, the reader sleeping in `ppoll` on an eventfd the writer
//!   inherited and writes (the cheapest wake-up that is a descriptor, so it joins a wait on
//!   other descriptors);
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
    Iceoryx2Doorbell,
    Iceoryx2Semaphore,
    Iceoryx2Poll,
    Futex,
    Eventfd,
    Uds,
    Tcp,
    Zenoh,
}

impl Transport {
    pub const ALL: [Transport; 9] = [
        Transport::Iceoryx2,
        Transport::Iceoryx2Doorbell,
        Transport::Iceoryx2Semaphore,
        Transport::Iceoryx2Poll,
        Transport::Futex,
        Transport::Eventfd,
        Transport::Uds,
        Transport::Tcp,
        Transport::Zenoh,
    ];

    /// The name in the JSON, the tables and `--transport`.
    pub fn name(self) -> &'static str {
        match self {
            Transport::Iceoryx2 => "iceoryx2",
            Transport::Iceoryx2Doorbell => "iceoryx2-doorbell",
            Transport::Iceoryx2Semaphore => "iceoryx2-semaphore",
            Transport::Iceoryx2Poll => "iceoryx2-poll",
            Transport::Futex => "futex",
            Transport::Eventfd => "eventfd",
            Transport::Uds => "uds",
            Transport::Tcp => "tcp",
            Transport::Zenoh => "zenoh",
        }
    }

    pub fn from_name(name: &str) -> Option<Transport> {
        Transport::ALL.into_iter().find(|t| t.name() == name)
    }

    fn is_iceoryx2(self) -> bool {
        matches!(
            self,
            Transport::Iceoryx2
                | Transport::Iceoryx2Doorbell
                | Transport::Iceoryx2Semaphore
                | Transport::Iceoryx2Poll
        )
    }

    /// A bare wake-up, no library: the floor the others are measured against.
    pub fn is_bare(self) -> bool {
        matches!(self, Transport::Futex | Transport::Eventfd)
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
    /// Every run's latencies together.
    pub histogram: Histogram<u64>,
    /// Samples delivered per second over the run (the median run's, after [`Row::merge`]).
    pub throughput_hz: f64,
    /// Each run's p50 and p99, us (one per run; [`Row::p50`] and [`Row::p99`] are their medians).
    pub runs: Vec<(f64, f64)>,
    throughputs: Vec<f64>,
}

/// The median of `v` (the mean of the middle two for an even count); NaN for none.
fn median(v: Vec<f64>) -> f64 {
    crate::accuracy::median(&v)
}

impl Row {
    /// Adds another run of the same transport, payload and rate.
    fn merge(&mut self, other: Row) {
        let _ = self.histogram.add(&other.histogram);
        self.sent += other.sent;
        self.runs.extend(other.runs);
        self.throughputs.extend(other.throughputs);
        self.throughput_hz = median(self.throughputs.clone());
    }

    /// The median of the runs' p50, us.
    pub fn p50(&self) -> f64 {
        median(self.runs.iter().map(|r| r.0).collect())
    }

    /// The median of the runs' p99, us.
    pub fn p99(&self) -> f64 {
        median(self.runs.iter().map(|r| r.1).collect())
    }

    /// The runs' lowest and highest p50 and p99, us: the spread beside the medians.
    fn spread(&self) -> ((f64, f64), (f64, f64)) {
        let lo_hi = |f: fn(&(f64, f64)) -> f64| {
            self.runs
                .iter()
                .map(f)
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                    (lo.min(v), hi.max(v))
                })
        };
        (lo_hi(|r| r.0), lo_hi(|r| r.1))
    }

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

    /// Its JSON: p50 and p99 the medians of the runs' (each run's beside them); p90, p99.9
    /// and max of every run's latencies together. The row of the wake-up the pipeline's
    /// stages use carries `"pipeline": true`.
    pub fn json(&self) -> Value {
        let s = Summary::of(&self.histogram);
        let round1 = |v: f64| (v * 10.0).round() / 10.0;
        let mut v = json!({
            "transport": self.transport.name(),
            "payload_bytes": self.payload_bytes,
            "rate_hz": self.rate_hz,
            "p50_us": round1(self.p50()), "p90_us": s.p90, "p99_us": round1(self.p99()), "p999_us": s.p999,
            "p50_runs_us": self.runs.iter().map(|r| r.0).collect::<Vec<_>>(),
            "p99_runs_us": self.runs.iter().map(|r| r.1).collect::<Vec<_>>(),
            "max_us": s.max, "count": s.count, "sent": self.sent,
            "throughput_hz": (self.throughput_hz * 10.0).round() / 10.0,
            "throughput_mib_s": (self.throughput_hz * self.payload_bytes as f64 / 1048576.0 * 10.0).round() / 10.0,
        });
        if self.transport == PIPELINE_WAKE {
            v["pipeline"] = json!(true);
        }
        v
    }
}

/// Options of `handblocks bench latency transport`.
pub struct TransportBench {
    /// This executable (the writer runs as its `bench-transport-peer`).
    pub exe: PathBuf,
    pub out_dir: PathBuf,
    /// 1 s paced runs and short flat-out runs (well under a minute on 2 cores).
    pub quick: bool,
    /// Whole sweeps, one after another (every transport once per payload and rate in each):
    /// a p50 or p99 published is the median of the runs', with their spread.
    pub runs: u64,
    /// The transports measured (empty: every one).
    pub only: Vec<Transport>,
}

/// The hop the pipeline's stages on its path (kinematics, the stepper) make: iceoryx2's
/// publish-subscribe, woken by the stage's doorbell (`[pipeline] wake = "doorbell"`, the
/// default). The stages that sleep on other descriptors too use `iceoryx2`'s event.
pub const PIPELINE_WAKE: Transport = Transport::Iceoryx2Doorbell;

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
        Transport::Futex | Transport::Eventfd => {
            let (path, eventfd) = ring_endpoint(&a.endpoint)?;
            let ring = Ring::open(Path::new(path), a.bytes)?;
            let start = monotonic_ns();
            for k in 0..a.count {
                pace(start, k, a.rate_hz);
                // Written in place, as into a loaned iceoryx2 sample.
                stamp(ring.slot(k), k);
                ring.publish(k + 1);
                match eventfd {
                    Some(fd) => {
                        let one = 1u64.to_ne_bytes();
                        // SAFETY: 8 bytes from the stack to the inherited eventfd.
                        unsafe { libc::write(fd, one.as_ptr().cast(), 8) };
                    }
                    None => ring.wake(),
                }
            }
            // Stay until the reader has everything (it reads our memory).
            common::shutdown::watch_parent_pipe();
            common::shutdown::wait_for_release(Duration::from_secs(10));
        }
        Transport::Iceoryx2Doorbell => {
            let config = BusConfig::for_session(&a.endpoint)?;
            let (_node, pubsub, _) = services(&config, a.bytes)?;
            let doorbell = common::bus::Doorbell::open(&doorbell_path(&a.endpoint))?;
            write_iceoryx2(a, &pubsub, || {
                doorbell.ring();
                Ok(())
            })?;
        }
        Transport::Iceoryx2Semaphore => {
            let config = BusConfig::for_session(&a.endpoint)?;
            let (_node, pubsub, _) = services(&config, a.bytes)?;
            let (_doorbell_node, event) = semaphore_event(&config, a.bytes)?;
            let notifier = event
                .notifier_builder()
                .create()
                .map_err(|e| format!("{e:?}"))?;
            write_iceoryx2(a, &pubsub, || {
                notifier
                    .notify()
                    .map(drop)
                    .map_err(|e| format!("{e:?}").into())
            })?;
        }
        Transport::Iceoryx2 | Transport::Iceoryx2Poll => {
            let config = BusConfig::for_session(&a.endpoint)?;
            let (_node, pubsub, event) = services(&config, a.bytes)?;
            let notifier = event
                .notifier_builder()
                .create()
                .map_err(|e| format!("{e:?}"))?;
            write_iceoryx2(a, &pubsub, || {
                if a.transport == Transport::Iceoryx2Poll {
                    return Ok(());
                }
                notifier
                    .notify()
                    .map(drop)
                    .map_err(|e| format!("{e:?}").into())
            })?;
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

/// The iceoryx2 rows' writer: each payload written once, in place in the loaned sample (as
/// `stamp` writes a socket's buffer), sent, then `wake` (the row's wake-up: its event, its
/// doorbell, none); then it stays until the reader has everything (it reads our memory).
fn write_iceoryx2(
    a: &PeerArgs,
    pubsub: &ByteService,
    wake: impl Fn() -> Result<(), Box<dyn std::error::Error>>,
) -> Result<(), Box<dyn std::error::Error>> {
    let publisher = pubsub
        .publisher_builder()
        .initial_max_slice_len(a.bytes)
        .max_loaned_samples(2)
        .create()
        .map_err(|e| format!("{e:?}"))?;
    let start = monotonic_ns();
    for k in 0..a.count {
        pace(start, k, a.rate_hz);
        let sample = publisher
            .loan_slice_uninit(a.bytes)
            .map_err(|e| format!("{e:?}"))?;
        let mut sample = sample.write_from_fn(|i| (i as u64 ^ k) as u8);
        let payload = sample.payload_mut();
        payload[8..16].copy_from_slice(&k.to_le_bytes());
        payload[..8].copy_from_slice(&monotonic_ns().to_le_bytes());
        sample.send().map_err(|e| format!("{e:?}"))?;
        wake()?;
    }
    common::shutdown::watch_parent_pipe();
    common::shutdown::wait_for_release(Duration::from_secs(10));
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

type SemaphoreEventService =
    iceoryx2::service::port_factory::event::PortFactory<common::bus::semaphore::SemaphoreIpc>;

/// The event service of the `iceoryx2-semaphore` rows: the same name and bus as
/// [`services`]' pub-sub service, on a node of the semaphore service type.
fn semaphore_event(
    config: &BusConfig,
    bytes: usize,
) -> Result<
    (
        Node<common::bus::semaphore::SemaphoreIpc>,
        SemaphoreEventService,
    ),
    Box<dyn std::error::Error>,
> {
    let node = NodeBuilder::new()
        .config(&config.iceoryx()?)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<common::bus::semaphore::SemaphoreIpc>()
        .map_err(|e| format!("{e:?}"))?;
    let name = ServiceName::new(&format!("transport-{bytes}")).map_err(|e| format!("{e:?}"))?;
    let event = node
        .service_builder(&name)
        .event()
        .open_or_create()
        .map_err(|e| format!("{e:?}"))?;
    Ok((node, event))
}

/// The `iceoryx2-doorbell` rows' doorbell: a file in /dev/shm named for the run.
fn doorbell_path(endpoint: &str) -> PathBuf {
    PathBuf::from(format!("/dev/shm/{endpoint}-doorbell"))
}

/// The `futex` and `eventfd` rows' endpoint: the ring's file, and after a `|` the eventfd the
/// writer inherited (eventfd only).
fn ring_endpoint(endpoint: &str) -> Result<(&str, Option<i32>), Box<dyn std::error::Error>> {
    match endpoint.split_once('|') {
        Some((path, fd)) => Ok((path, Some(fd.parse()?))),
        None => Ok((endpoint, None)),
    }
}

/// Slots of a [`Ring`]: as deep as the iceoryx2 rows' subscriber buffer.
const RING_SLOTS: u64 = 8;
/// Bytes before the ring's slots: the futex word (u32, at 0) and the published count (u64, at 8).
const RING_HEAD: usize = 64;

/// The bare rows' shared memory: [`RING_SLOTS`] payloads in a file in /dev/shm mapped by
/// both processes, and the count of payloads published, whose low 32 bits are the futex
/// word. The writer writes payload `k` in place in slot `k % 8`, then publishes `k + 1`.
struct Ring {
    base: *mut u8,
    len: usize,
    bytes: usize,
}

impl Ring {
    fn map(file: &std::fs::File, len: usize) -> Result<*mut u8, Box<dyn std::error::Error>> {
        use std::os::fd::AsRawFd;
        // SAFETY: a shared mapping of `len` bytes of an open file of that length.
        let p = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                len,
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_SHARED,
                file.as_raw_fd(),
                0,
            )
        };
        if p == libc::MAP_FAILED {
            return Err(format!("mmap: {}", std::io::Error::last_os_error()).into());
        }
        Ok(p.cast())
    }

    fn create(path: &Path, bytes: usize) -> Result<Ring, Box<dyn std::error::Error>> {
        let len = RING_HEAD + RING_SLOTS as usize * bytes;
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create_new(true)
            .open(path)
            .map_err(|e| format!("{}: {e}", path.display()))?;
        file.set_len(len as u64)?;
        Ok(Ring {
            base: Ring::map(&file, len)?,
            len,
            bytes,
        })
    }

    fn open(path: &Path, bytes: usize) -> Result<Ring, Box<dyn std::error::Error>> {
        let len = RING_HEAD + RING_SLOTS as usize * bytes;
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(path)
            .map_err(|e| format!("{}: {e}", path.display()))?;
        Ok(Ring {
            base: Ring::map(&file, len)?,
            len,
            bytes,
        })
    }

    fn word(&self) -> &std::sync::atomic::AtomicU32 {
        // SAFETY: the first 4 bytes of the mapping, aligned (page-aligned base).
        unsafe { &*self.base.cast::<std::sync::atomic::AtomicU32>() }
    }

    fn count(&self) -> &std::sync::atomic::AtomicU64 {
        // SAFETY: bytes 8..16 of the mapping, aligned.
        unsafe { &*self.base.add(8).cast::<std::sync::atomic::AtomicU64>() }
    }

    #[allow(clippy::mut_from_ref)]
    fn slot(&self, k: u64) -> &mut [u8] {
        let at = RING_HEAD + (k % RING_SLOTS) as usize * self.bytes;
        // SAFETY: inside the mapping; one writer process writes a slot while the reader may
        // read it only after it was published (a reader 8 behind checks the number it reads).
        unsafe { std::slice::from_raw_parts_mut(self.base.add(at), self.bytes) }
    }

    fn publish(&self, count: u64) {
        use std::sync::atomic::Ordering;
        self.count().store(count, Ordering::Release);
        self.word().store(count as u32, Ordering::Release);
    }

    fn published(&self) -> u64 {
        self.count().load(std::sync::atomic::Ordering::Acquire)
    }

    /// Wakes the reader sleeping on the word.
    fn wake(&self) {
        // SAFETY: FUTEX_WAKE on the mapped word (shared: another process sleeps on it).
        unsafe {
            libc::syscall(
                libc::SYS_futex,
                self.word().as_ptr(),
                libc::FUTEX_WAKE,
                1,
                std::ptr::null::<libc::timespec>(),
            )
        };
    }

    /// Sleeps while the word still reads `seen` (as far as `timeout`).
    fn sleep(&self, seen: u64, timeout: Duration) {
        let ts = libc::timespec {
            tv_sec: timeout.as_secs() as libc::time_t,
            tv_nsec: timeout.subsec_nanos() as libc::c_long,
        };
        // SAFETY: FUTEX_WAIT on the mapped word with a relative timeout on the stack.
        unsafe {
            libc::syscall(
                libc::SYS_futex,
                self.word().as_ptr(),
                libc::FUTEX_WAIT,
                seen as u32,
                &ts as *const libc::timespec,
            )
        };
    }
}

impl Drop for Ring {
    fn drop(&mut self) {
        // SAFETY: the mapping this ring made.
        unsafe { libc::munmap(self.base.cast(), self.len) };
    }
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
/// `bench latency pipeline` measures its bare hops with it (`endpoint` a name of its own).
pub fn measure(exe: &Path, a: &PeerArgs) -> Result<Row, Box<dyn std::error::Error>> {
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
        Transport::Futex | Transport::Eventfd => {
            let path = PathBuf::from(format!("/dev/shm/{}", a.endpoint));
            let ring = Ring::create(&path, a.bytes)?;
            let result = (|| -> Result<(), Box<dyn std::error::Error>> {
                let eventfd = if a.transport == Transport::Eventfd {
                    // SAFETY: a new descriptor, without CLOEXEC so that the writer inherits it.
                    let fd = unsafe { libc::eventfd(0, 0) };
                    if fd < 0 {
                        return Err(format!("eventfd: {}", std::io::Error::last_os_error()).into());
                    }
                    Some(fd)
                } else {
                    None
                };
                let endpoint = match eventfd {
                    Some(fd) => format!("{}|{fd}", path.display()),
                    None => path.display().to_string(),
                };
                let mut child = spawn_peer(
                    exe,
                    &PeerArgs {
                        endpoint,
                        ..a.clone()
                    },
                )?;
                let outcome = (|| -> Result<(), Box<dyn std::error::Error>> {
                    let mut read = 0u64;
                    while read < a.count {
                        if Instant::now() > deadline {
                            return Err(late().into());
                        }
                        let published = ring.published();
                        if published == read {
                            match eventfd {
                                Some(fd) => {
                                    wait_readable(fd, Duration::from_millis(50));
                                    let mut b = [0u8; 8];
                                    // SAFETY: 8 bytes into the stack; clears the count.
                                    unsafe { libc::read(fd, b.as_mut_ptr().cast(), 8) };
                                }
                                None => ring.sleep(published, Duration::from_millis(50)),
                            }
                            continue;
                        }
                        // A reader more than the ring behind lost the oldest, as iceoryx2's.
                        for k in read.max(published.saturating_sub(RING_SLOTS))..published {
                            let slot = ring.slot(k);
                            let t0 = read_u64(slot, 0);
                            if read_u64(slot, 8) == k {
                                record(t0);
                                first.get_or_insert_with(Instant::now);
                            }
                        }
                        read = published;
                    }
                    Ok(())
                })();
                drop(child.stdin.take());
                let _ = child.wait();
                if let Some(fd) = eventfd {
                    // SAFETY: ours, no longer used (the writer had its own copy).
                    unsafe { libc::close(fd) };
                }
                outcome
            })();
            let _ = std::fs::remove_file(&path);
            result?;
        }
        Transport::Iceoryx2Doorbell => {
            let config = BusConfig::for_session(&a.endpoint)?;
            let bell = doorbell_path(&a.endpoint);
            let result = (|| -> Result<(), Box<dyn std::error::Error>> {
                let (_node, pubsub, _) = services(&config, a.bytes)?;
                let doorbell = common::bus::Doorbell::open(&bell)?;
                let subscriber = pubsub
                    .subscriber_builder()
                    .buffer_size(8)
                    .create()
                    .map_err(|e| format!("{e:?}"))?;
                let mut child = spawn_peer(exe, a)?;
                let mut last = false;
                while !last {
                    if Instant::now() > deadline {
                        return Err(late().into());
                    }
                    doorbell.wait_unless(
                        || subscriber.has_samples().unwrap_or(true),
                        Duration::from_millis(50),
                    );
                    while let Some(s) = subscriber.receive().map_err(|e| format!("{e:?}"))? {
                        record(read_u64(s.payload(), 0));
                        first.get_or_insert_with(Instant::now);
                        last |= read_u64(s.payload(), 8) + 1 == a.count;
                    }
                }
                drop(child.stdin.take());
                let _ = child.wait();
                Ok(())
            })();
            let _ = std::fs::remove_file(&bell);
            let _ = config.remove_resources();
            result?;
        }
        Transport::Iceoryx2Semaphore => {
            let config = BusConfig::for_session(&a.endpoint)?;
            let result = (|| -> Result<(), Box<dyn std::error::Error>> {
                let (_node, pubsub, _) = services(&config, a.bytes)?;
                let (_doorbell_node, event) = semaphore_event(&config, a.bytes)?;
                let subscriber = pubsub
                    .subscriber_builder()
                    .buffer_size(8)
                    .create()
                    .map_err(|e| format!("{e:?}"))?;
                let listener = event
                    .listener_builder()
                    .create()
                    .map_err(|e| format!("{e:?}"))?;
                let mut child = spawn_peer(exe, a)?;
                let mut last = false;
                while !last {
                    if Instant::now() > deadline {
                        return Err(late().into());
                    }
                    listener
                        .timed_wait(|_| {}, Duration::from_millis(50))
                        .map_err(|e| format!("{e:?}"))?;
                    while let Some(s) = subscriber.receive().map_err(|e| format!("{e:?}"))? {
                        record(read_u64(s.payload(), 0));
                        first.get_or_insert_with(Instant::now);
                        last |= read_u64(s.payload(), 8) + 1 == a.count;
                    }
                }
                drop(child.stdin.take());
                let _ = child.wait();
                Ok(())
            })();
            let _ = config.remove_resources();
            result?;
        }
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
        runs: vec![{
            let s = Summary::of(&hist);
            (s.p50, s.p99)
        }],
        histogram: hist,
        throughput_hz,
        throughputs: vec![throughput_hz],
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
    let total = b.transports().len() * PAYLOADS.len() * rates.len() * b.runs.max(1) as usize;
    let scratch = std::env::temp_dir().join(format!("hb-transport-{}", std::process::id()));
    std::fs::create_dir_all(&scratch)?;
    let quiet = page::Quietness::start();
    let measured = measure_all(b, &rates, total, &scratch);
    // The sockets' folder goes whatever happened.
    let _ = std::fs::remove_dir_all(&scratch);
    write_outputs(&measured?, b, &quiet)
}

fn measure_all(
    b: &TransportBench,
    rates: &[f64],
    total: usize,
    scratch: &Path,
) -> Result<Vec<Row>, Box<dyn std::error::Error>> {
    let mut rows: Vec<Row> = Vec::new();
    let mut done = 0usize;
    let t0 = Instant::now();
    for run in 0..b.runs.max(1) {
        for &rate in rates {
            for &bytes in &PAYLOADS {
                for t in b.transports() {
                    let endpoint = if t.is_iceoryx2() || t.is_bare() {
                        format!("tr{}_{}", std::process::id(), done)
                    } else {
                        scratch
                            .join(format!("s{}", done))
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
                    done += 1;
                    eprintln!(
                    "bench latency transport: [{done}/{total}] run {} {:<18} {:>8} B {:>6}: p50 {:.1} us, p99 {:.1} us ({:.0} s so far)",
                    run + 1,
                    t.name(),
                    bytes,
                    row.rate_name(),
                    s.p50,
                    s.p99,
                    t0.elapsed().as_secs_f64()
                );
                    match rows
                        .iter_mut()
                        .find(|r| r.transport == t && r.payload_bytes == bytes && r.rate_hz == rate)
                    {
                        Some(kept) => kept.merge(row),
                        None => rows.push(row),
                    }
                }
            }
        }
    }
    Ok(rows)
}

impl TransportBench {
    /// The transports this run measures, in [`Transport::ALL`]'s order.
    fn transports(&self) -> Vec<Transport> {
        Transport::ALL
            .into_iter()
            .filter(|t| self.only.is_empty() || self.only.contains(t))
            .collect()
    }
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

fn write_outputs(
    rows: &[Row],
    b: &TransportBench,
    quiet: &page::Quietness,
) -> Result<Value, Box<dyn std::error::Error>> {
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
        "runs": b.runs.max(1),
        "how_quiet": quiet.line(),
        "transport": rows.iter().map(Row::json).collect::<Vec<_>>(),
        "uds_over_iceoryx2": ratios,
        "zenoh_over_iceoryx2": bridged,
    });
    std::fs::write(
        b.out_dir.join("transport.json"),
        serde_json::to_string_pretty(&value)? + "\n",
    )?;
    crate::latency::merge_into_latency_json(&b.out_dir, "transport", value["transport"].clone())?;
    let provenance = Provenance::of_this_run(b.quick, &b.out_dir).with_quietness(quiet);
    std::fs::write(
        b.out_dir.join("transport.md"),
        markdown(rows, b, &provenance),
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
                out.push((bytes, rate, o.p50() / i.p50(), o.p99() / i.p99()));
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

fn markdown(rows: &[Row], b: &TransportBench, provenance: &Provenance) -> String {
    let what = format!(
        "One hop between two processes, publish -> receive: from the writer's clock when the \
         payload is complete to the reader's clock when it is the reader's to read \
         (`CLOCK_MONOTONIC`, one clock for both), over the transports a user would weigh \
         against each other, at payloads of 64 B to 4 MiB, paced at 120 Hz and flat out \
         ({}; {} whole sweeps, one after another: each p50 and p99 is the median of the \
         runs', with the lowest and highest run beside it). \
         `iceoryx2`: zero-copy shared memory, the reader woken by iceoryx2's event (a Unix \
         datagram beside a bit set) and sleeping in `ppoll` (what the pipeline did \
         before issue 46, and still of the stages that sleep on other descriptors too); \
         `iceoryx2-doorbell`: the same, woken by a doorbell, a futex word the writer rings \
         (`common::bus::Doorbell`: what kinematics and the stepper do, marked \
         `\"pipeline\": true` in the JSON); `iceoryx2-semaphore`: the same, woken by iceoryx2's \
         semaphore event (`common::bus::semaphore::SemaphoreIpc`; its timed wait is iceoryx2's \
         adaptive wait: it polls the semaphore, yielding, then sleeping in steps, so it is no \
         futex sleep); `iceoryx2-poll`: the reader spinning on `receive`; `futex` and \
         `eventfd`: the floor of a woken hop, no library: a ring of payloads in shared memory \
         written in place, the reader asleep in `FUTEX_WAIT` on the published count, or in \
         `ppoll` on an eventfd the writer writes; `uds`: a Unix stream socket; `tcp`: \
         loopback, `TCP_NODELAY`; `zenoh`: the bridge's hop across machines, here over \
         loopback (TCP, express, dropping when the link is full). Flat out, the writer sends \
         back to back: a socket blocks the writer (the queueing counts), shared memory \
         overwrites the oldest unread sample 8 behind (the pipeline's setting), so it may \
         deliver fewer than were sent.\n\n\
         How to read it: lower is better; the ratio tables divide a transport's percentile \
         by iceoryx2's (woken by its event) at the same payload and rate, measured in this \
         run on this machine, so 3.00x means three times as long. Paced at 120 Hz, \
         the reader's CPU is idle between samples: a woken hop then includes this machine's \
         wake from idle, which no transport can avoid and which flat-out runs do not pay. The \
         figure draws each payload's latency by percentile (p50 to the tail, HdrHistogram's \
         log axis) at 120 Hz, every run together; every histogram is also an `.hgrm` file \
         under `hgrm/`.",
        if b.quick {
            "quick run: 1 s paced, up to 500 samples flat out"
        } else {
            "5 s paced, up to 5000 samples (1 GiB) flat out"
        },
        b.runs.max(1)
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
    let rate_name = |rate: f64| if rate > 0.0 { "120 Hz" } else { "flat out" };
    // The goal of issue 46: the pipeline's woken hop at or below a Unix socket's.
    md.push_str(&format!(
        "## The pipeline's wake-up ({}) against a Unix socket, and the floor\n\n\
         At or below the socket is the goal, p50 and p99, at every payload at 120 Hz. The \
         floor is the fastest bare wake-up measured (futex or eventfd) at that payload.\n\n\
         | payload | rate | pipeline p50 / uds p50 | pipeline p99 / uds p99 | goal | floor p50 / p99 (us) |\n|---|---|---|---|---|---|\n",
        PIPELINE_WAKE.name()
    ));
    for &bytes in &PAYLOADS {
        for rate in [PACED_HZ, 0.0] {
            let (Some(p), Some(u)) = (
                find(rows, PIPELINE_WAKE, bytes, rate),
                find(rows, Transport::Uds, bytes, rate),
            ) else {
                continue;
            };
            let (r50, r99) = (p.p50() / u.p50(), p.p99() / u.p99());
            let floor = [Transport::Futex, Transport::Eventfd]
                .into_iter()
                .filter_map(|t| find(rows, t, bytes, rate))
                .min_by(|a, b| a.p99().total_cmp(&b.p99()))
                .map_or("-".to_string(), |f| {
                    format!("{} {:.1} / {:.1}", f.transport.name(), f.p50(), f.p99())
                });
            md.push_str(&format!(
                "| {} | {} | {r50:.2}x | {r99:.2}x | {} | {floor} |\n",
                size_name(bytes),
                rate_name(rate),
                if rate == 0.0 {
                    "-"
                } else if r50 <= 1.0 && r99 <= 1.0 {
                    "met"
                } else {
                    "not met"
                },
            ));
        }
    }
    md.push('\n');
    for (t, title) in [
        (Transport::Uds, "The Unix socket's latency as a multiple of iceoryx2's (same run)"),
        (
            Transport::Iceoryx2Doorbell,
            "iceoryx2 woken by a doorbell (the pipeline's) as a multiple of its own event (same run)",
        ),
        (
            Transport::Iceoryx2Semaphore,
            "iceoryx2 with its semaphore event as a multiple of its datagram event (same run)",
        ),
        (
            Transport::Futex,
            "The bare futex wake-up as a multiple of iceoryx2's (same run)",
        ),
        (
            Transport::Eventfd,
            "The bare eventfd wake-up as a multiple of iceoryx2's (same run)",
        ),
        (
            Transport::Zenoh,
            "The bridged hop (zenoh, loopback) as a multiple of the local one (iceoryx2, woken; same run)",
        ),
    ] {
        let ratios = over_iceoryx2(rows, t);
        if ratios.is_empty() {
            continue;
        }
        md.push_str(&format!(
            "## {title}\n\n| payload | rate | p50 | p99 |\n|---|---|---|---|\n"
        ));
        for (bytes, rate, p50, p99) in ratios {
            md.push_str(&format!(
                "| {} | {} | {p50:.2}x | {p99:.2}x |\n",
                size_name(bytes),
                rate_name(rate),
            ));
        }
        md.push('\n');
    }
    md.push_str("## Every hop\n\n");
    md.push_str(
        "p50 and p99: the median of the runs' (the lowest and highest run in brackets); p90, \
         p99.9 and max of every run's latencies together.\n\n",
    );
    md.push_str("| transport | payload | rate | p50 (us) | p90 | p99 | p99.9 | max | delivered / sent | throughput (/s) |\n|---|---|---|---|---|---|---|---|---|---|\n");
    for r in rows {
        let s = Summary::of(&r.histogram);
        let ((p50_lo, p50_hi), (p99_lo, p99_hi)) = r.spread();
        md.push_str(&format!(
            "| {}{} | {} | {} | {:.1} ({p50_lo:.1}-{p50_hi:.1}) | {:.1} | {:.1} ({p99_lo:.1}-{p99_hi:.1}) | {:.1} | {:.1} | {} / {} | {:.0} |\n",
            r.transport.name(),
            if r.transport == PIPELINE_WAKE { " (pipeline)" } else { "" },
            size_name(r.payload_bytes),
            if r.rate_hz > 0.0 {
                format!("{:.0} Hz", r.rate_hz)
            } else {
                "flat out".into()
            },
            r.p50(),
            s.p90,
            r.p99(),
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
    #[test]
    fn runs_merge_into_one_row_whose_percentiles_are_the_medians_of_the_runs() {
        let row = |p50: f64, p99: f64, throughput: f64| {
            let mut histogram = new_histogram();
            histogram.record((p50 * 1000.0) as u64).unwrap();
            Row {
                transport: Transport::Futex,
                payload_bytes: 64,
                rate_hz: PACED_HZ,
                sent: 10,
                histogram,
                throughput_hz: throughput,
                runs: vec![(p50, p99)],
                throughputs: vec![throughput],
            }
        };
        let mut r = row(40.0, 200.0, 120.0);
        r.merge(row(45.0, 900.0, 119.0));
        r.merge(row(42.0, 250.0, 118.0));
        assert_eq!((r.p50(), r.p99()), (42.0, 250.0), "the middle run of three");
        assert_eq!(r.spread(), ((40.0, 45.0), (200.0, 900.0)));
        assert_eq!(
            (r.sent, r.histogram.len()),
            (30, 3),
            "every run's samples together"
        );
        assert_eq!(r.throughput_hz, 119.0);
        assert_eq!(median(vec![1.0, 3.0]), 2.0);
        assert!(median(vec![]).is_nan());
        let v = r.json();
        assert_eq!(v["p50_runs_us"], json!([40.0, 45.0, 42.0]));
        assert!(
            v.get("pipeline").is_none(),
            "futex is not the pipeline's wake-up"
        );
    }

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
