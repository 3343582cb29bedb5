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
use common::config::remote::LinkSecurity;
use common::config::session::{LinkRole, RemoteLink};
use common::{monotonic_ns, Topic};
use zenoh::bytes::ZBytes;
use zenoh::pubsub::{Publisher, Subscriber};
use zenoh::qos::{CongestionControl, Priority};
use zenoh::query::Queryable;
use zenoh::Wait;

use crate::clock::{ClockOffset, Exchange};
use crate::identity::{Identity, IdentityError};

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
    /// This side's keys, or the trusted peer's certificate (a `tls/` link).
    Identity(IdentityError),
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
            LinkError::Identity(e) => write!(f, "cannot open the zenoh link: {e}"),
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
    /// Clock answers whose signature is not the trusted authority's (an impostor on a `tls/`
    /// link's other end): never taken, so nothing is published.
    unsigned_answers: AtomicU64,
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

    /// Clock answers refused: not signed by the trusted peer's authority.
    pub fn unsigned_answers(&self) -> u64 {
        self.unsigned_answers.load(Ordering::Relaxed)
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
    /// What the terminal says of the link's protection.
    pub protection: String,
}

/// zenoh's configuration for one side of a link: a peer that listens on or connects to
/// `endpoint` (`tls/HOST:PORT` or `tcp/HOST:PORT`; a connecting side retries every 100-500 ms
/// until the other answers, so the halves start in either order), and finds no one by
/// multicast or gossip (a session talks to whom its file names: issue 40, a stranger gossiped
/// in as a peer's peer). With an [`Identity`], TLS 1.3 with both sides' certificates: this
/// side presents its issued chain and accepts only certificates the peer's authority issued
/// (a listener's check of a connecting side uses that authority alone; a connecting side
/// checks the listener's name too). The latency bench's zenoh rows use it too, plain.
/// The zenoh endpoint of a session's `tls/HOST:PORT`: `quic/HOST:PORT`, TLS 1.3 with both sides'
/// certificates as zenoh's `tls/` link, on UDP. zenoh 1.10's `tls/` link reads and writes one
/// rustls stream from two tasks through an `UnsafeCell` (zenoh #2557; rustls supports no
/// such use): under traffic both ways (a viewer sending frames back) a bridge aborted in
/// rustls with a garbage allocation. Its QUIC link keeps rustls inside quinn, which does not
/// share it. `tcp/` (plain) is taken as it is.
/// The longest the link waits for its zenoh session to close when the bridge stops.
const CLOSE_TIMEOUT_MS: u64 = 500;

pub fn zenoh_endpoint(endpoint: &str) -> String {
    match endpoint.strip_prefix("tls/") {
        Some(rest) => format!("quic/{rest}"),
        None => endpoint.to_string(),
    }
}

pub fn peer_config(
    endpoint: &str,
    role: LinkRole,
    identity: Option<&Identity>,
) -> Result<zenoh::Config, String> {
    let mut c = zenoh::Config::default();
    let set = |c: &mut zenoh::Config, k: &str, v: &str| {
        c.insert_json5(k, v).map_err(|e| format!("{k}: {e}"))
    };
    set(&mut c, "mode", "\"peer\"")?;
    set(&mut c, "scouting/multicast/enabled", "false")?;
    set(&mut c, "scouting/gossip/enabled", "false")?;
    // A droppable put waits up to 20 ms for room before it is dropped (zenoh's default is
    // 1 ms): a link that stalls briefly (a loaded machine, a TLS record being sealed) loses
    // nothing, and the wait is the bridge's own (it reads the bus like any reader, with a
    // second of samples buffered), never the pipeline's.
    set(
        &mut c,
        "transport/link/tx/queue/congestion_control/drop/wait_before_drop",
        "20000",
    )?;
    if let Some(id) = identity {
        let b64 = |pem: &[u8]| {
            use base64::Engine as _;
            serde_json::to_string(&base64::engine::general_purpose::STANDARD.encode(pem))
                .map_err(|e| e.to_string())
        };
        let tls = "transport/link/tls";
        set(
            &mut c,
            &format!("{tls}/root_ca_certificate_base64"),
            &b64(&id.peer_pem)?,
        )?;
        for side in ["listen", "connect"] {
            set(
                &mut c,
                &format!("{tls}/{side}_private_key_base64"),
                &b64(&id.key_pem)?,
            )?;
            set(
                &mut c,
                &format!("{tls}/{side}_certificate_base64"),
                &b64(&id.chain_pem)?,
            )?;
        }
        set(&mut c, &format!("{tls}/enable_mtls"), "true")?;
        set(&mut c, &format!("{tls}/verify_name_on_connect"), "true")?;
    }
    let endpoint = serde_json::to_string(&[zenoh_endpoint(endpoint)]).map_err(|e| e.to_string())?;
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

/// What a sender signs in answer to a receiver's clock query: a fixed label, the query's key,
/// the receiver's nonce and the sender's clock reading (so an answer is good for one query of
/// one link only).
fn clock_statement(key: &str, nonce: &[u8], their_ns: u64) -> Vec<u8> {
    let mut m = Vec::with_capacity(32 + key.len() + nonce.len());
    m.extend_from_slice(b"handblocks link clock\0");
    m.extend_from_slice(key.as_bytes());
    m.push(0);
    m.extend_from_slice(nonce);
    m.extend_from_slice(&their_ns.to_le_bytes());
    m
}

/// Bytes of a receiver's nonce in a clock query.
const NONCE_BYTES: usize = 16;

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
    /// Opens `link` as its session file says: on a `tls/` endpoint with this side's keys and
    /// the trusted peer's authority ([`Identity::load`]).
    pub fn open(link: &RemoteLink) -> Result<Link, LinkError> {
        let identity =
            Identity::load(&link.security, &link.endpoint).map_err(LinkError::Identity)?;
        Link::open_with(link, identity)
    }

    /// Opens `link` with the keys given (None: plain): a test plays an impostor with keys no
    /// session file would give.
    pub fn open_with(link: &RemoteLink, identity: Option<Identity>) -> Result<Link, LinkError> {
        let open_err = |reason: String| LinkError::Open {
            endpoint: link.endpoint.clone(),
            reason,
        };
        let identity = identity.map(Arc::new);
        let protection = match (&identity, &link.security) {
            (Some(id), _) => id.describe(),
            (None, LinkSecurity::Plain) => {
                let host = common::config::remote::endpoint_host(&link.endpoint);
                if common::config::remote::is_loopback_host(host) {
                    "plain TCP (allow_plain = true): in clear, any peer on this machine may join"
                        .to_string()
                } else {
                    format!(
                        "WARNING: plain TCP (allow_plain = true) on {host}: every sample \
                         crosses the network in clear, and any peer that reaches the port may \
                         read or inject them; use a tls/ endpoint"
                    )
                }
            }
            (None, LinkSecurity::Tls { .. }) => String::new(),
        };
        let session = zenoh::open(
            peer_config(&link.endpoint, link.role, identity.as_deref()).map_err(open_err)?,
        )
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
            let signer = identity.clone();
            let answer_key = clock_key.clone();
            let q = session
                .declare_queryable(clock_key.clone())
                .callback(move |query| {
                    let now = monotonic_ns();
                    let mut answer = now.to_le_bytes().to_vec();
                    // A receiver that sent a nonce gets it signed with this side's authority.
                    if let (Some(id), Some(nonce)) = (&signer, query.payload()) {
                        let nonce = nonce.to_bytes();
                        if nonce.len() == NONCE_BYTES {
                            match id
                                .authority
                                .sign(&clock_statement(&answer_key, &nonce, now))
                            {
                                Ok(sig) => answer.extend_from_slice(&sig),
                                Err(_) => return,
                            }
                        }
                    }
                    let _ = query.reply(query.key_expr().clone(), answer).wait();
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
            let trusted = identity.as_ref().map(|id| id.peer_pem.clone());
            std::thread::spawn(move || {
                exchange_clocks(&session, &key, trusted.as_deref(), &clock, &stop)
            })
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
            protection,
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

    /// True when every topic this side sends has a subscriber on the other side (a viewer
    /// attached; zenoh's matching status of each publisher).
    pub fn every_topic_taken(&self) -> bool {
        !self.publishers.is_empty()
            && self
                .publishers
                .iter()
                .all(|(_, p)| p.matching_status().wait().is_ok_and(|m| m.matching()))
    }

    /// Waits until [`Link::every_topic_taken`], at most `limit`, or until the process is asked
    /// to stop; returns how long it waited when a viewer attached, None when none did.
    pub fn wait_for_viewer(&self, limit: Duration) -> Option<Duration> {
        let started = std::time::Instant::now();
        while started.elapsed() < limit && !common::shutdown::requested() {
            if self.every_topic_taken() {
                return Some(started.elapsed());
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        None
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
        close_bounded(self.session);
    }
}

/// Closes a zenoh session, waiting at most [`CLOSE_TIMEOUT_MS`]: a QUIC link's close waits on
/// its peer (6.5 s for one that had gone: a viewer stopped first), and the bridge's final
/// report waits on this. The process ends right after; what the close had not done, the end
/// of the process does.
pub fn close_bounded(session: zenoh::Session) {
    let (done, closed) = crossbeam_channel::bounded::<()>(1);
    let closing = std::thread::Builder::new()
        .name("link-close".into())
        .spawn(move || {
            let _ = session.close().wait();
            let _ = done.send(());
        });
    if closing.is_ok() {
        let _ = closed.recv_timeout(Duration::from_millis(CLOSE_TIMEOUT_MS));
    }
}

/// Asks the sender's clock every 50 ms until an answer came, then every second, and keeps the
/// estimate in `shared` (see [`crate::clock`]). On a `tls/` link (`trusted`: the peer's
/// authority certificate) each query carries a fresh nonce and an answer counts only when the
/// authority signed it: until one did, the clock stays unknown and nothing taken in is
/// published.
fn exchange_clocks(
    session: &zenoh::Session,
    key: &str,
    trusted: Option<&[u8]>,
    shared: &SharedClock,
    stop: &AtomicBool,
) {
    let mut estimate = ClockOffset::default();
    let mut nonce = [0u8; NONCE_BYTES];
    while !stop.load(Ordering::Acquire) {
        let sent_ns = monotonic_ns();
        let mut get = session.get(key).timeout(Duration::from_millis(500));
        if trusted.is_some() {
            fill_random(&mut nonce);
            get = get.payload(nonce.to_vec());
        }
        if let Ok(replies) = get.wait() {
            while let Ok(reply) = replies.recv() {
                let received_ns = monotonic_ns();
                let Ok(sample) = reply.result() else { continue };
                let bytes = sample.payload().to_bytes();
                let Some((their, signature)) = bytes.split_first_chunk::<8>() else {
                    continue;
                };
                let their_ns = u64::from_le_bytes(*their);
                if let Some(pem) = trusted {
                    let statement = clock_statement(key, &nonce, their_ns);
                    if !keyfile::verify(pem, &statement, signature) {
                        shared.unsigned_answers.fetch_add(1, Ordering::Relaxed);
                        continue;
                    }
                }
                estimate.add(Exchange {
                    sent_ns,
                    their_ns,
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

/// Fills `buf` from the kernel's random source (getrandom(2)).
fn fill_random(buf: &mut [u8]) {
    let mut at = 0;
    while at < buf.len() {
        // SAFETY: writes at most the rest of `buf`, which is ours.
        let n = unsafe {
            libc::getrandom(
                buf[at..].as_mut_ptr() as *mut libc::c_void,
                buf.len() - at,
                0,
            )
        };
        if n <= 0 {
            // getrandom fails only before the pool is ready or on a bad buffer: try again.
            std::thread::sleep(Duration::from_millis(1));
            continue;
        }
        at += n as usize;
    }
}
