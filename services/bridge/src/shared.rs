//! A shared world's link (`[shared]`, issue 45): several people, each with their own source of
//! hands on their own machine, in one block world.
//!
//! **One authoritative world.** The host's stepper steps the only world; its bridge (this
//! module, [`Host`]) is that session's source: it takes every participant's hands over zenoh
//! and, on the host's own clock at the scene's step rate, publishes one frame of them on the
//! host's bus (each hand marked with its participant's number, `HandSample::participant`),
//! then sends every world the stepper makes to every participant. A participant's bridge
//! ([`Join`]) sends its session's hands and publishes the host's worlds on its own bus, bit for
//! bit, for its renderer and recorder. Why not replicated steppers in lockstep: the world is
//! bit-deterministic, so lockstep would also agree, but each step would wait for the slowest
//! participant's input (a 2 s stall stops everyone), and a late joiner would need the world's
//! whole state, which the paper model keeps in many stages; the host's world sample *is* the
//! state a participant shows. What it costs is measured, not assumed: a participant's hand ->
//! world is its link's round trip plus the host's wait for the next tick (the report's
//! `shared.hand_to_world_us`), and the host sends each participant every world (bytes per
//! second in `bridge.json`).
//!
//! **Keys** (prefix `KEY`, `[shared] key`): `KEY/join` (a query: token and name in, the
//! participant's number and a secret out), `KEY/hand/SECRET` (a participant's hands; the
//! secret is known only to the host and that participant, so nobody else can put hands under
//! its number), `KEY/world/SECRET` (the host's worlds, with an attachment naming, per participant,
//! the seq of its newest hand the world's frame held: the participant's own hand -> world
//! latency on its own clock, no clock estimate needed), `KEY/peer/SECRET` (the other
//! participants' hands, [`crate::peer_wire`], for the participant's `peer_hand` topic).
//!
//! **Never waiting on anyone.** The host's frames go out on its clock whatever arrives: a
//! participant whose hands stop coming has them sent as lost (`tracked = 0`, holding what they
//! hold, T2) after `hold_ms`, and after `drop_after_s` is named and dropped: its hands are sent
//! empty (no check points, so they let go, as a lost hand does) until it sends again.
//!
//! **Refused and counted by name** (`bridge.json`, `shared.refused`): a join with a wrong
//! token or into a full world; hands under a key no participant was given; hands that are not
//! hand samples, or name another participant's number, or a side neither right nor left;
//! hands the world cannot use (NaN, out of range); a seq not after the last (a duplicate or
//! reordered sample); a source time ahead of the host's clock by more than a second since the
//! participant's first hand (a future stamp); more than `FLOOD_PER_S` hands a second.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use common::bus::{wait_each, AnyInlet, Bus, BusError, Inlet, Outlet, WaitStrategy, Waiter, Wake};
use common::config::session::LinkRole;
use common::config::shared::{SharedLink, SharedRole};
use common::config::Session;
use common::latency::{Metric, Reporter};
use common::node::{self, Counters, Pass, Task};
use common::{
    monotonic_ns, topics, HandSample, HandSide, PeerHandSample, Stage, Stamp, Topic, HAND_SLOTS,
    MAX_PARTICIPANTS,
};
use zenoh::Wait;

use crate::identity::Identity;
use crate::link::{declare_sender, peer_config};
use crate::service::BridgeError;

/// Hands a participant may send a second (both hands of a 120 Hz source are 240): past it the
/// rest of that second's are refused as a flood.
pub const FLOOD_PER_S: u32 = 1000;
/// How far a participant's source time may run ahead of the host's clock since its first hand.
const FUTURE_SLACK_NS: u64 = 1_000_000_000;
/// Hands and worlds taken off the link and not yet handled: two seconds of four participants'
/// two 120 Hz hands.
const QUEUE: usize = 4096;
/// The longest a world's send waits on a stalled participant's link before dropping it for
/// that participant, microseconds (see [`run`]).
pub const WORLD_SEND_WAIT_US: u64 = 1000;
/// How often a participant asks to join until the host answers.
const JOIN_RETRY: Duration = Duration::from_millis(500);
/// A participant's own hands kept to read its hand -> world latency off the world's
/// attachment (seconds of them at 120 Hz).
const SENT_RING: usize = 1024;
/// How often a participant is sent each other participant's hand, at most (a hand a second):
/// drawn, never stepped, so half a 60 Hz display's rate is enough to see where another
/// person's hand is, and it costs a participant's link about 17 KB a second per other hand
/// ([`crate::peer_wire`]) beside its worlds and its own hands.
pub const PEER_HZ: u64 = 30;

/// The most hands a participant keeps in flight (unanswered), whatever the window.
const IN_FLIGHT_MAX: usize = SENT_RING / 2;

/// Newest-only sending over a reliable link (issue 45): the samples sent and not yet answered,
/// oldest first, and the quickest turn seen (sent -> answered). While the oldest unanswered is
/// older than the window (three of the quickest turns and 100 ms), the link is behind: a
/// reliable, congestion-controlled stream at a long round trip with loss carries less than the
/// stream offered, and what is sent only queues. Then the next sample waits (a newer one
/// supersedes it); a sample unanswered for four windows (at least 1 s) is given up on, so that
/// no lost answer closes the window for good.
#[derive(Debug)]
struct SendWindow {
    in_flight: std::collections::VecDeque<(u64, u64)>,
    min_turn_ns: u64,
}

impl Default for SendWindow {
    fn default() -> Self {
        SendWindow {
            in_flight: std::collections::VecDeque::with_capacity(IN_FLIGHT_MAX),
            min_turn_ns: u64::MAX,
        }
    }
}

impl SendWindow {
    /// The window: how long the oldest unanswered may wait before the link counts as behind.
    fn window_ns(&self) -> u64 {
        if self.min_turn_ns == u64::MAX {
            return u64::MAX;
        }
        self.min_turn_ns
            .saturating_mul(3)
            .saturating_add(100_000_000)
    }

    /// Whether the link is behind at `now` (after giving up on the long unanswered).
    fn behind(&mut self, now: u64) -> bool {
        let window = self.window_ns();
        let give_up = window.saturating_mul(4).max(1_000_000_000);
        while self
            .in_flight
            .front()
            .is_some_and(|&(_, sent)| now.saturating_sub(sent) > give_up)
        {
            self.in_flight.pop_front();
        }
        self.in_flight
            .front()
            .is_some_and(|&(_, sent)| now.saturating_sub(sent) > window)
            || self.in_flight.len() >= IN_FLIGHT_MAX
    }

    fn sent(&mut self, seq: u64, now: u64) {
        if self.in_flight.len() < IN_FLIGHT_MAX {
            self.in_flight.push_back((seq, now));
        }
    }

    /// Seq `answered` (and all before it) came, answered at `now`.
    fn answered(&mut self, answered: u64, now: u64) {
        while let Some(&(seq, sent)) = self.in_flight.front() {
            if seq > answered {
                break;
            }
            if seq == answered {
                self.min_turn_ns = self.min_turn_ns.min(now.saturating_sub(sent));
            }
            self.in_flight.pop_front();
        }
    }

    /// The window in ms, once a turn was seen.
    fn window_ms(&self) -> Option<f64> {
        (self.min_turn_ns != u64::MAX).then(|| self.window_ns() as f64 / 1e6)
    }
}

/// Why a shared link's process stopped.
#[derive(Debug, thiserror::Error)]
pub enum SharedError {
    #[error("cannot open the shared world's zenoh link on {endpoint}: {reason}")]
    Open { endpoint: String, reason: String },
    #[error("the host of the shared world refused to let this session join: {0}")]
    Refused(String),
    #[error("cannot make the shared link's wake-up descriptor: {0}")]
    Wake(std::io::Error),
    #[error("cannot make the shared world's token: {0}")]
    Token(std::io::Error),
}

/// Runs this session's side of a shared world.
pub fn run(session: &Session, bus: &Bus, link: &SharedLink) -> Result<(), BridgeError> {
    let identity = Identity::load(&link.security, &link.endpoint)
        .map_err(|e| BridgeError::Link(crate::link::LinkError::Identity(e)))?;
    let role = if link.is_host() {
        LinkRole::Listen
    } else {
        LinkRole::Connect
    };
    let open_err = |reason: String| {
        BridgeError::Shared(SharedError::Open {
            endpoint: link.endpoint.clone(),
            reason,
        })
    };
    let mut config = peer_config(&link.endpoint, role, identity.as_ref()).map_err(open_err)?;
    if link.is_host() {
        // A world put waits this long for room on a participant's queue before it drops the
        // world for that participant (the bridge's default, 20 ms, is for one viewer): a
        // stalled participant then costs the host's loop at most WORLD_SEND_WAIT_US per world,
        // MAX_PARTICIPANTS of them under a tick, and never the others their worlds.
        config
            .insert_json5(
                "transport/link/tx/queue/congestion_control/drop/wait_before_drop",
                &WORLD_SEND_WAIT_US.to_string(),
            )
            .map_err(|e| open_err(e.to_string()))?;
    }
    let zenoh = zenoh::open(config)
        .wait()
        .map_err(|e| open_err(e.to_string()))?;
    let protection = match &identity {
        Some(id) => id.describe(),
        None => {
            "plain TCP (allow_plain = true): in clear; only the token keeps others out".to_string()
        }
    };
    eprintln!("handblocks bridge: the shared world's link: {protection}");
    let summary_file = bus.session_folder().join("bridge.json");
    match &link.role {
        SharedRole::Host {
            drop_after_s,
            hold_ms,
        } => {
            let token = match &link.token {
                Some(t) => t.clone(),
                None => random_token().map_err(|e| BridgeError::Shared(SharedError::Token(e)))?,
            };
            let mut host = Host::open(
                session,
                bus,
                zenoh,
                link,
                token,
                protection,
                (*drop_after_s * 1e9) as u64,
                hold_ms * 1_000_000,
                summary_file,
            )?;
            Ok(node::run(
                Stage::Bridge,
                bus,
                WaitStrategy::Event,
                &mut host,
            )?)
        }
        SharedRole::Join { name } => {
            let mut join = Join::open(session, bus, zenoh, link, name, protection, summary_file)?;
            node::run(Stage::Bridge, bus, WaitStrategy::Event, &mut join)?;
            match join.refused.take() {
                Some(why) => Err(why),
                None => Ok(()),
            }
        }
    }
}

/// A new token: 24 characters of `A-Za-z0-9-_` (144 bits) from the system's random source.
fn random_token() -> std::io::Result<String> {
    use std::io::Read;
    let mut bytes = [0u8; 18];
    std::fs::File::open("/dev/urandom")?.read_exact(&mut bytes)?;
    use base64::Engine as _;
    Ok(base64::engine::general_purpose::URL_SAFE_NO_PAD.encode(bytes))
}

/// A participant's secret key segment: 32 hex digits.
fn secret_text(secret: u128) -> String {
    format!("{secret:032x}")
}

/// A secret as [`secret_text`] writes it (32 hex digits), else None.
fn parse_secret(text: &str) -> Option<u128> {
    (text.len() == 32)
        .then(|| u128::from_str_radix(text, 16).ok())
        .flatten()
}

fn random_secret() -> std::io::Result<u128> {
    use std::io::Read;
    let mut bytes = [0u8; 16];
    std::fs::File::open("/dev/urandom")?.read_exact(&mut bytes)?;
    Ok(u128::from_le_bytes(bytes))
}

/// Compares two tokens in time that does not depend on where they differ.
fn same_token(given: &str, token: &str) -> bool {
    given.len() == token.len()
        && given
            .bytes()
            .zip(token.bytes())
            .fold(0u8, |acc, (a, b)| acc | (a ^ b))
            == 0
}

/// The address a participant on another machine reaches a host listening on `endpoint` by:
/// the endpoint itself, or, for one on every interface (`0.0.0.0`, `[::]`), this machine's
/// address on its default route (none: loopback).
fn join_address(endpoint: &str) -> String {
    let host = common::config::remote::endpoint_host(endpoint);
    if host != "0.0.0.0" && host != "::" {
        return endpoint.to_string();
    }
    let local = std::net::UdpSocket::bind("0.0.0.0:0")
        .and_then(|s| s.connect("192.0.2.1:9").map(|()| s))
        .and_then(|s| s.local_addr())
        .map(|a| a.ip().to_string())
        .unwrap_or_else(|_| "127.0.0.1".into());
    let (scheme, rest) = endpoint.split_once('/').unwrap_or(("tls", endpoint));
    let port = rest.rsplit_once(':').map_or("7460", |(_, p)| p);
    format!("{scheme}/{local}:{port}")
}

// ---------------------------------------------------------------------------------------------
// The host.

/// A join the queryable granted, for the loop.
struct Joined {
    participant: usize,
    name: String,
    secret: u128,
}

/// Who may join, shared by the join queryable (another thread, rare) and the loop.
struct Roster {
    token: String,
    /// By participant number: its name.
    names: Vec<String>,
    refused_wrong_token: u64,
    refused_full: u64,
    joined: crossbeam_channel::Sender<Joined>,
}

/// A participant's answer to its worlds: the secret of the key it came under, the newest world
/// seq it took in, when it arrived.
struct AckIn {
    secret: Option<u128>,
    seq: Option<u64>,
    arrived_ns: u64,
}

/// A participant that says it leaves: its secret and the last seq it sent.
struct Leaving {
    secret: u128,
    last_seq: Option<u64>,
}

/// One hand taken off the link: the secret of the key it came under, its bytes, when.
struct HandIn {
    secret: Option<u128>,
    arrived_ns: u64,
    bytes: zenoh::bytes::ZBytes,
}

/// What the host knows of one participant.
#[derive(Default)]
struct Participant {
    name: String,
    secret: u128,
    /// Each side's newest hand (0 the right, 1 the left), when it arrived, and its seq.
    latest: [Option<(HandSample, u64)>; 2],
    /// The newest seq taken (a participant's hands, both sides, count one seq), and the source
    /// time and host time of its first.
    last_seq: Option<u64>,
    first: Option<(u64, u64)>,
    taken: u64,
    /// Seqs skipped (hands the link lost), and hands refused, by name.
    lost: u64,
    refused: BTreeMap<&'static str, u64>,
    flood_window_ns: u64,
    flood_count: u32,
    /// Joined this many times (a rejoin after a drop keeps the number).
    joins: u64,
    /// Dropped (silent for `drop_after_s`) and not back yet; and how often.
    dropped: bool,
    drops: u64,
    /// When the host last heard from it.
    last_heard_ns: u64,
    /// Bytes of its hands taken.
    bytes_in: u64,
    /// Each side's seq the last frame sent (a hand sent again is held, not new).
    framed: [Option<u64>; 2],
    /// It said it leaves (its session ended): its hands let go at once, and the hands it sent
    /// that never came are counted lost.
    left: bool,
    /// Its worlds go under its own key (`KEY/world/SECRET`), each when its link keeps up.
    world_sender: Option<zenoh::pubsub::Publisher<'static>>,
    /// The worlds it was sent and has not answered (`KEY/ack/SECRET`), and their sends' times.
    world_window: SendWindow,
    worlds_sent: u64,
    /// Worlds not sent to it because its link was behind (the next world, the whole state,
    /// catches it up).
    worlds_held_back: u64,
    world_bytes_sent: u64,
    /// The other participants' hands go to it under `KEY/peer/SECRET`, each slot's when it
    /// changed since the last sent to it ([`FramedHand::version`]), with its worlds.
    peer_sender: Option<zenoh::pubsub::Publisher<'static>>,
    peer_versions: [u64; HAND_SLOTS],
    /// When each slot's hand was last sent to it (at most [`PEER_HZ`] a second each).
    peer_sent_ns: [u64; HAND_SLOTS],
    peer_hands_sent: u64,
    peer_bytes_sent: u64,
}

/// A hand slot as the host's last frame published it, encoded once for every participant
/// ([`crate::peer_wire`]; empty: no one's hand yet), and how often it changed (a new hand, or
/// one held as lost, or let go): a participant is sent another's hand when its version moved.
#[derive(Default)]
struct FramedHand {
    encoded: Vec<u8>,
    version: u64,
    /// What the version was made of: the hand's seq, `tracked`, and its finger count.
    key: (u64, u32, u32),
}

impl Participant {
    fn refuse(&mut self, why: &'static str) {
        *self.refused.entry(why).or_default() += 1;
    }
}

/// The host's side: the participants' hands in, ordered frames out on the bus, worlds out.
struct Host<'s> {
    session: &'s Session,
    zenoh: zenoh::Session,
    roster: Arc<Mutex<Roster>>,
    joined: crossbeam_channel::Receiver<Joined>,
    leaving: crossbeam_channel::Receiver<Leaving>,
    hands: crossbeam_channel::Receiver<HandIn>,
    queue_full: Arc<AtomicU64>,
    wake: Arc<Wake>,
    _join_queryable: zenoh::query::Queryable<()>,
    _leave_queryable: zenoh::query::Queryable<()>,
    _hand_subscriber: zenoh::pubsub::Subscriber<()>,
    acks: crossbeam_channel::Receiver<AckIn>,
    _ack_subscriber: zenoh::pubsub::Subscriber<()>,
    world_in: AnyInlet,
    hand_out: Outlet<topics::Hand>,
    participants: Vec<Participant>,
    /// Hands under a key no participant was given.
    unknown_key: u64,
    period_ns: u64,
    next_tick_ns: u64,
    frames: u64,
    hold_ns: u64,
    drop_ns: u64,
    message: Vec<u8>,
    attachment: [u8; 8 * MAX_PARTICIPANTS],
    /// Per participant, the seq of its newest hand the last frame held (the attachment).
    frame_seqs: [u64; MAX_PARTICIPANTS],
    /// Each hand slot as the last frame published it, for the other participants.
    framed_hands: [FramedHand; HAND_SLOTS],
    started_ns: u64,
    endpoint: String,
    key: String,
    protection: String,
    summary_file: PathBuf,
}

impl<'s> Host<'s> {
    #[allow(clippy::too_many_arguments)]
    fn open(
        session: &'s Session,
        bus: &Bus,
        zenoh: zenoh::Session,
        link: &SharedLink,
        token: String,
        protection: String,
        drop_ns: u64,
        hold_ns: u64,
        summary_file: PathBuf,
    ) -> Result<Host<'s>, BridgeError> {
        let declare_err = |key: &str, e: zenoh::Error| {
            BridgeError::Link(crate::link::LinkError::Declare {
                key: key.to_string(),
                reason: e.to_string(),
            })
        };
        let (joined_tx, joined) = crossbeam_channel::bounded(4 * MAX_PARTICIPANTS);
        let roster = Arc::new(Mutex::new(Roster {
            token: token.clone(),
            names: Vec::new(),
            refused_wrong_token: 0,
            refused_full: 0,
            joined: joined_tx,
        }));
        let wake = Arc::new(Wake::new().map_err(|e| BridgeError::Shared(SharedError::Wake(e)))?);
        let join_key = format!("{}/join", link.key);
        let answering = roster.clone();
        let join_wake = wake.clone();
        let join_queryable = zenoh
            .declare_queryable(join_key.clone())
            .callback(move |query| {
                let asked = query
                    .payload()
                    .map(|p| p.to_bytes().into_owned())
                    .unwrap_or_default();
                let answer = answer_join(&answering, &asked);
                join_wake.wake();
                let _ = query.reply(query.key_expr().clone(), answer).wait();
            })
            .wait()
            .map_err(|e| declare_err(&join_key, e))?;
        let (leave_tx, leaving) = crossbeam_channel::bounded(4 * MAX_PARTICIPANTS);
        let leave_key = format!("{}/leave", link.key);
        let leave_wake = wake.clone();
        let leave_queryable = zenoh
            .declare_queryable(leave_key.clone())
            .callback(move |query| {
                let said: serde_json::Value = query
                    .payload()
                    .and_then(|p| serde_json::from_slice(&p.to_bytes()).ok())
                    .unwrap_or_default();
                let secret = said["secret"].as_str().and_then(parse_secret);
                if let Some(secret) = secret {
                    let _ = leave_tx.try_send(Leaving {
                        secret,
                        last_seq: said["last_seq"].as_u64(),
                    });
                    leave_wake.wake();
                }
                let _ = query.reply(query.key_expr().clone(), "bye").wait();
            })
            .wait()
            .map_err(|e| declare_err(&leave_key, e))?;
        let (hand_tx, hands) = crossbeam_channel::bounded(QUEUE);
        let queue_full = Arc::new(AtomicU64::new(0));
        let hand_key = format!("{}/hand/*", link.key);
        let (full, hand_wake) = (queue_full.clone(), wake.clone());
        let prefix_len = link.key.len() + "/hand/".len();
        let hand_subscriber = zenoh
            .declare_subscriber(hand_key.clone())
            .callback(move |sample| {
                let secret = sample
                    .key_expr()
                    .as_str()
                    .get(prefix_len..)
                    .and_then(parse_secret);
                let item = HandIn {
                    secret,
                    arrived_ns: monotonic_ns(),
                    bytes: sample.payload().clone(),
                };
                match hand_tx.try_send(item) {
                    Ok(()) => hand_wake.wake(),
                    Err(_) => {
                        full.fetch_add(1, Ordering::Relaxed);
                    }
                }
            })
            .wait()
            .map_err(|e| declare_err(&hand_key, e))?;
        let (ack_tx, acks) = crossbeam_channel::bounded(QUEUE);
        let ack_key = format!("{}/ack/*", link.key);
        let ack_wake = wake.clone();
        let ack_prefix_len = link.key.len() + "/ack/".len();
        let ack_subscriber = zenoh
            .declare_subscriber(ack_key.clone())
            .callback(move |sample| {
                let secret = sample
                    .key_expr()
                    .as_str()
                    .get(ack_prefix_len..)
                    .and_then(parse_secret);
                let bytes = sample.payload().to_bytes();
                let seq = <[u8; 8]>::try_from(&bytes[..]).ok().map(u64::from_le_bytes);
                let item = AckIn {
                    secret,
                    seq,
                    arrived_ns: monotonic_ns(),
                };
                if ack_tx.try_send(item).is_ok() {
                    ack_wake.wake();
                }
            })
            .wait()
            .map_err(|e| declare_err(&ack_key, e))?;
        let period_ns = (1e9 / session.scene.world.step_hz).round().max(1.0) as u64;
        let join = join_address(&link.endpoint);
        eprintln!(
            "handblocks bridge: hosting a shared world on {} (key {}); each participant joins \
             with its own hands (any --set source... of theirs):\n  handblocks launch \
             shared-join --set shared.host={join} --set shared.token={token}",
            link.endpoint, link.key
        );
        Ok(Host {
            session,
            zenoh,
            roster,
            joined,
            leaving,
            hands,
            queue_full,
            wake,
            _join_queryable: join_queryable,
            _leave_queryable: leave_queryable,
            _hand_subscriber: hand_subscriber,
            acks,
            _ack_subscriber: ack_subscriber,
            world_in: bus.any_inlet(Topic::World)?,
            hand_out: bus.outlet::<topics::Hand>()?,
            participants: Vec::new(),
            unknown_key: 0,
            period_ns,
            next_tick_ns: 0,
            frames: 0,
            hold_ns,
            drop_ns,
            message: Vec::new(),
            attachment: [0; 8 * MAX_PARTICIPANTS],
            frame_seqs: [0; MAX_PARTICIPANTS],
            framed_hands: std::array::from_fn(|_| FramedHand::default()),
            started_ns: monotonic_ns(),
            endpoint: link.endpoint.clone(),
            key: link.key.clone(),
            protection,
            summary_file,
        })
    }

    /// Takes the joins the queryable granted.
    fn take_joins(&mut self) {
        while let Ok(j) = self.joined.try_recv() {
            if self.participants.len() <= j.participant {
                self.participants
                    .resize_with(j.participant + 1, Participant::default);
            }
            let p = &mut self.participants[j.participant];
            p.name = j.name;
            p.secret = j.secret;
            p.joins += 1;
            p.last_seq = None;
            p.left = false;
            p.framed = [None; 2];
            self.frame_seqs[j.participant] = 0;
            p.first = None;
            p.last_heard_ns = monotonic_ns();
            p.world_window = SendWindow::default();
            let world_key = format!("{}/world/{}", self.key, secret_text(p.secret));
            p.world_sender = match declare_sender(&self.zenoh, world_key.clone()) {
                Ok(sender) => Some(sender),
                Err(e) => {
                    eprintln!(
                        "handblocks bridge: cannot send {}'s worlds ({world_key}): {e}",
                        p.name
                    );
                    None
                }
            };
            let peer_key = format!("{}/peer/{}", self.key, secret_text(p.secret));
            p.peer_sender = match declare_sender(&self.zenoh, peer_key.clone()) {
                Ok(sender) => Some(sender),
                Err(e) => {
                    eprintln!(
                        "handblocks bridge: cannot send {} the others' hands ({peer_key}): {e}",
                        p.name
                    );
                    None
                }
            };
            // Everything it has not been sent yet: every slot's hand goes with its first world.
            p.peer_versions = [0; HAND_SLOTS];
            p.peer_sent_ns = [0; HAND_SLOTS];
            eprintln!(
                "handblocks bridge: {} joined the shared world as participant {}",
                p.name, j.participant
            );
        }
    }

    /// Takes the participants that said they leave: their hands let go from the next frame,
    /// and what they sent that never came is counted lost (a later arrival is taken back).
    fn take_leaves(&mut self) {
        while let Ok(l) = self.leaving.try_recv() {
            let Some(k) = self
                .participants
                .iter()
                .position(|p| p.secret == l.secret && p.joins > 0)
            else {
                self.unknown_key += 1;
                continue;
            };
            let p = &mut self.participants[k];
            if !p.left {
                p.left = true;
                if let Some(last_sent) = l.last_seq {
                    match p.last_seq {
                        Some(last) => p.lost += last_sent.saturating_sub(last),
                        None => p.lost += 1,
                    }
                }
                eprintln!(
                    "handblocks bridge: participant {k} ({}) left the shared world; its hands \
                     let go",
                    p.name
                );
            }
        }
    }

    /// Checks and keeps each hand the link brought (the newest of each side is what the next
    /// frame sends).
    fn take_hands(&mut self) {
        while let Ok(item) = self.hands.try_recv() {
            let Some(k) = item.secret.and_then(|s| {
                self.participants
                    .iter()
                    .position(|p| p.secret == s && p.joins > 0)
            }) else {
                self.unknown_key += 1;
                continue;
            };
            let bytes = item.bytes.to_bytes();
            let p = &mut self.participants[k];
            p.bytes_in += bytes.len() as u64;
            let now = item.arrived_ns;
            let (hand, side) = match check_hand(p, k, &bytes, now) {
                Ok(taken) => taken,
                Err(why) => {
                    p.refuse(why);
                    continue;
                }
            };
            let seq = hand.stamp.seq;
            if let Some(last) = p.last_seq {
                let gap = seq - last - 1;
                if p.left {
                    // Counted lost when it left (its last seq then); it came after all.
                    p.lost = p.lost.saturating_sub(gap + 1);
                }
                p.lost += gap;
            }
            p.last_seq = Some(seq);
            p.latest[side] = Some((hand, now));
            p.last_heard_ns = now;
            p.taken += 1;
            if p.dropped {
                p.dropped = false;
                eprintln!(
                    "handblocks bridge: participant {k} ({}) is back: its hands drive again",
                    p.name
                );
            }
        }
    }

    /// Takes the participants' answers to their worlds: each opens its world window again.
    fn take_acks(&mut self) {
        while let Ok(a) = self.acks.try_recv() {
            let (Some(secret), Some(seq)) = (a.secret, a.seq) else {
                continue;
            };
            if let Some(p) = self.participants.iter_mut().find(|p| p.secret == secret) {
                p.world_window.answered(seq, a.arrived_ns);
            }
        }
    }

    /// Sends every world the stepper made to each participant, with the frame's seqs, while
    /// its link keeps up ([`SendWindow`]); one whose link is behind gets a later world (the
    /// whole state) once it answered the ones in flight.
    fn send_worlds(&mut self) -> Result<(), BusError> {
        while let Some(s) = self.world_in.receive()? {
            let view = s.view();
            let seq = view.stamp().seq;
            recording::encode_view(&view, &mut self.message);
            for (k, seq) in self.frame_seqs.iter().enumerate() {
                self.attachment[8 * k..8 * k + 8].copy_from_slice(&seq.to_le_bytes());
            }
            let now = monotonic_ns();
            for (k, p) in self.participants.iter_mut().enumerate() {
                let Some(sender) = &p.world_sender else {
                    continue;
                };
                if p.left {
                    continue;
                }
                if p.world_window.behind(now) {
                    p.worlds_held_back += 1;
                    continue;
                }
                if sender
                    .put(self.message.as_slice())
                    .attachment(&self.attachment[..])
                    .wait()
                    .is_ok()
                {
                    p.world_window.sent(seq, now);
                    p.worlds_sent += 1;
                    p.world_bytes_sent += self.message.len() as u64;
                    send_peers(p, k, &self.framed_hands, now);
                }
            }
        }
        Ok(())
    }

    /// One frame at tick `tick_ns`: each participant's newest hands, participant 0's right
    /// always (the stepper's frame waits for slot 0), held as lost after `hold_ns`, empty
    /// after `drop_ns`.
    fn send_frame(&mut self, tick_ns: u64, pass: &mut Pass<'_>) -> Result<(), BusError> {
        if self.participants.iter().all(|p| p.taken == 0) {
            return Ok(());
        }
        for k in 0..self.participants.len() {
            let silent_ns = tick_ns.saturating_sub(self.participants[k].last_heard_ns);
            if silent_ns > self.drop_ns
                && !self.participants[k].dropped
                && self.participants[k].taken > 0
            {
                let p = &mut self.participants[k];
                p.dropped = true;
                p.drops += 1;
                eprintln!(
                    "handblocks bridge: participant {k} ({}) sent nothing for {:.1} s: \
                     dropped; its hands let go (it may send again, or join again)",
                    p.name,
                    silent_ns as f64 / 1e9
                );
            }
            for side in 0..2 {
                let p = &self.participants[k];
                let Some((newest, arrived_ns)) = p.latest[side] else {
                    if k == 0 && side == 0 {
                        // Slot 0 in every frame: an empty right hand of participant 0.
                        let empty = HandSample {
                            stamp: Stamp::at_origin(0, tick_ns),
                            ..HandSample::default()
                        };
                        self.publish_hand(empty, 0, 0, tick_ns, tick_ns, pass)?;
                    }
                    continue;
                };
                let mut hand = newest;
                let age = tick_ns.saturating_sub(arrived_ns);
                // A hand that came since the last frame counts from its arrival; one held
                // (nothing new came) is this frame's own, from the tick.
                let fresh = p.framed[side] != Some(newest.stamp.seq);
                let origin = if fresh { arrived_ns } else { tick_ns };
                if p.dropped || p.left {
                    hand.finger_count = 0;
                    hand.palm_vertex_count = 0;
                    hand.tracked = 0;
                } else if age > self.hold_ns {
                    hand.tracked = 0;
                }
                self.participants[k].framed[side] = Some(newest.stamp.seq);
                self.frame_seqs[k] = self.frame_seqs[k].max(newest.stamp.seq);
                self.publish_hand(hand, k, side, tick_ns, origin, pass)?;
            }
        }
        self.frames += 1;
        Ok(())
    }

    fn publish_hand(
        &mut self,
        mut hand: HandSample,
        participant: usize,
        side: usize,
        tick_ns: u64,
        arrived_ns: u64,
        pass: &mut Pass<'_>,
    ) -> Result<(), BusError> {
        hand.participant = participant as u32;
        hand.side = side as u32;
        hand.stamp.source_time_ns = tick_ns;
        // The host's own latency counts from the hand's arrival here; a participant's hand ->
        // world, from its own origin, is measured on its side.
        hand.stamp.origin_ns = arrived_ns;
        let sent = self.hand_out.publish(&hand)?;
        // A slot's placeholder (participant 0's empty right hand before it sent any) is no
        // one's hand to show.
        if let Some(slot) = hand
            .slot()
            .filter(|_| self.participants[participant].taken > 0)
        {
            let framed = &mut self.framed_hands[slot];
            // A hand held from frame to frame differs only in its stamp, which the peer form
            // leaves out: encoded again only when it changed.
            let key = (hand.stamp.seq, hand.tracked, hand.finger_count);
            if framed.encoded.is_empty() || framed.key != key {
                framed.version += 1;
                framed.key = key;
                crate::peer_wire::encode(&hand, &mut framed.encoded);
            }
        }
        // The host waits for its first participant: its silence counts from its first frame
        // (before the first origin is recorded, which marks the first output).
        pass.recorder.delivered_after_waiting(sent.publish_ns);
        let ns = sent.publish_ns.saturating_sub(sent.origin_ns);
        pass.recorder.record(Metric::Process, ns);
        pass.recorder.record(Metric::Origin, ns);
        Ok(())
    }

    fn summary(&self) -> serde_json::Value {
        use serde_json::json;
        let roster = self
            .roster
            .lock()
            .map(|r| (r.refused_wrong_token, r.refused_full));
        let (wrong_token, full) = roster.unwrap_or((0, 0));
        let seconds = (monotonic_ns().saturating_sub(self.started_ns) as f64 / 1e9).max(1e-9);
        let mut refused = BTreeMap::new();
        if wrong_token > 0 {
            refused.insert("a join with a wrong token".to_string(), wrong_token);
        }
        if full > 0 {
            refused.insert("a join into a full world".to_string(), full);
        }
        if self.unknown_key > 0 {
            refused.insert(
                "hands under a key no participant was given (not joined, or another session's)"
                    .to_string(),
                self.unknown_key,
            );
        }
        let participants: Vec<_> = self
            .participants
            .iter()
            .enumerate()
            .map(|(k, p)| {
                for (why, n) in &p.refused {
                    *refused.entry(format!("{}: {why}", p.name)).or_default() += n;
                }
                json!({
                    "participant": k,
                    "name": p.name,
                    "joins": p.joins,
                    "hands_taken": p.taken,
                    "hands_lost": p.lost,
                    "refused": p.refused,
                    "left": p.left,
                    "dropped": p.dropped,
                    "drops": p.drops,
                    "bytes_in_per_s": p.bytes_in as f64 / seconds,
                    "worlds_sent": p.worlds_sent,
                    "worlds_held_back": p.worlds_held_back,
                    "world_window_ms": p.world_window.window_ms(),
                    "world_bytes_out_per_s": p.world_bytes_sent as f64 / seconds,
                    "peer_hands_sent": p.peer_hands_sent,
                    "peer_bytes_out_per_s": p.peer_bytes_sent as f64 / seconds,
                })
            })
            .collect();
        json!({
            "shared": {
                "role": "host",
                "endpoint": self.endpoint,
                "key": self.key,
                "protection": self.protection,
                "design": "one authoritative world: the host orders every participant's hands \
                           on its clock at the scene's step rate and sends each its worlds",
                "step_hz": self.session.scene.world.step_hz,
                "frames": self.frames,
                "participants": participants,
                "worlds_sent": self.participants.iter().map(|p| p.worlds_sent).sum::<u64>(),
                "world_bytes_out_per_s_per_participant": self
                    .participants
                    .iter()
                    .map(|p| p.world_bytes_sent as f64 / seconds)
                    .sum::<f64>()
                    / self.participants.len().max(1) as f64,
                "queue_full": self.queue_full.load(Ordering::Relaxed),
                "refused": refused,
            }
        })
    }
}

/// Participant `p`'s (number `k`) hand in `bytes`, arrived at `now` on the host's clock, with
/// its side (0 the right, 1 the left); or why it is refused, by name (counted in the report):
/// not a hand sample; past [`FLOOD_PER_S`] this second; another participant's number; a side
/// neither right nor left; not usable by the world (NaN, out of range); a seq not after the
/// last taken (a duplicate or reordered one); a source time ahead of the host's clock by more
/// than [`FUTURE_SLACK_NS`] since its first hand. Nobody else's hands are touched.
fn check_hand(
    p: &mut Participant,
    k: usize,
    bytes: &[u8],
    now: u64,
) -> Result<(HandSample, usize), &'static str> {
    let hand: HandSample =
        recording::decode_sample(Topic::Hand, bytes).map_err(|_| "not a hand sample")?;
    if now.saturating_sub(p.flood_window_ns) >= 1_000_000_000 {
        p.flood_window_ns = now;
        p.flood_count = 0;
    }
    p.flood_count += 1;
    if p.flood_count > FLOOD_PER_S {
        return Err("a flood (more hands a second than FLOOD_PER_S)");
    }
    if hand.participant as usize != k {
        return Err("another participant's number");
    }
    if hand.side > 1 {
        return Err("a side neither right nor left");
    }
    if hand.unusable_because().is_some() {
        return Err("a hand the world cannot use (not finite, or out of range)");
    }
    if p.last_seq.is_some_and(|last| hand.stamp.seq <= last) {
        return Err("a seq not after the last (duplicate or reordered)");
    }
    let (first_source, first_host) = *p.first.get_or_insert((hand.stamp.source_time_ns, now));
    let ahead = hand
        .stamp
        .source_time_ns
        .saturating_sub(first_source)
        .saturating_sub(now.saturating_sub(first_host));
    if ahead > FUTURE_SLACK_NS {
        return Err("a source time ahead of the host's clock (a future stamp)");
    }
    let side = usize::from(HandSide::from_code(hand.side) == HandSide::Left);
    Ok((hand, side))
}

/// Sends participant `p` (number `k`) the other participants' hands whose slots changed since
/// it was last sent them (the frame's hands, as its world's frame held them), each at most
/// [`PEER_HZ`] a second; one message a hand ([`crate::peer_wire`]).
fn send_peers(p: &mut Participant, k: usize, framed: &[FramedHand; HAND_SLOTS], now: u64) {
    let Some(sender) = &p.peer_sender else {
        return;
    };
    for (slot, f) in framed.iter().enumerate() {
        if f.encoded.is_empty() {
            continue;
        }
        let since_ns = now.saturating_sub(p.peer_sent_ns[slot]);
        if slot / 2 == k || p.peer_versions[slot] == f.version || since_ns < 1_000_000_000 / PEER_HZ
        {
            continue;
        }
        if sender.put(f.encoded.as_slice()).wait().is_ok() {
            p.peer_versions[slot] = f.version;
            p.peer_sent_ns[slot] = now;
            p.peer_hands_sent += 1;
            p.peer_bytes_sent += f.encoded.len() as u64;
        }
    }
}

/// The join queryable's answer to `asked` (`{"token": ..., "name": ...}`): the participant's
/// number and secret, or why not.
fn answer_join(roster: &Mutex<Roster>, asked: &[u8]) -> Vec<u8> {
    use serde_json::json;
    let refusal = |why: &str| json!({ "refused": why }).to_string().into_bytes();
    let Ok(asked) = serde_json::from_slice::<serde_json::Value>(asked) else {
        return refusal("the join was not JSON with a token and a name");
    };
    let (Some(token), Some(name)) = (asked["token"].as_str(), asked["name"].as_str()) else {
        return refusal("the join holds no token or no name");
    };
    let Ok(mut r) = roster.lock() else {
        return refusal("the host is stopping");
    };
    if !same_token(token, &r.token) {
        r.refused_wrong_token += 1;
        return refusal("a wrong token (the host printed the command that joins it)");
    }
    let name: String = name
        .chars()
        .filter(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
        .take(32)
        .collect();
    // A name seen before takes its number back (a participant that dropped and joins again).
    let participant = match r.names.iter().position(|n| *n == name) {
        Some(k) => k,
        None if r.names.len() < MAX_PARTICIPANTS => {
            r.names.push(name.clone());
            r.names.len() - 1
        }
        None => {
            r.refused_full += 1;
            return refusal(&format!(
                "the world is full ({MAX_PARTICIPANTS} participants; handblocks holds up to \
                 MAX_PARTICIPANTS people's hands)"
            ));
        }
    };
    let Ok(secret) = random_secret() else {
        return refusal("the host could not make a secret");
    };
    if r.joined
        .try_send(Joined {
            participant,
            name,
            secret,
        })
        .is_err()
    {
        return refusal("the host is busy taking other joins; try again");
    }
    json!({ "participant": participant, "secret": secret_text(secret) })
        .to_string()
        .into_bytes()
}

impl Task for Host<'_> {
    type Error = BusError;

    fn wait(&mut self, _: &mut Waiter, _: Duration) -> Result<(), BusError> {
        let now = monotonic_ns();
        let timeout = Duration::from_nanos(self.next_tick_ns.saturating_sub(now).max(1_000))
            .min(node::IDLE_WAIT);
        let inlets = std::iter::once(&self.world_in as &dyn common::bus::Wakeable);
        wait_each(inlets, Some(self.wake.fd()), timeout)
    }

    fn work(&mut self, pass: &mut Pass<'_>) -> Result<(), BusError> {
        self.wake.clear();
        self.take_joins();
        self.take_hands();
        self.take_leaves();
        self.take_acks();
        let now = monotonic_ns();
        if self.next_tick_ns == 0 {
            self.next_tick_ns = now;
        }
        if now >= self.next_tick_ns {
            // One frame per tick due; a host that fell behind by more than one tick skips to
            // now (the world's time follows the host's clock, never a backlog).
            let tick = self.next_tick_ns;
            self.send_frame(tick, pass)?;
            self.next_tick_ns = tick + self.period_ns;
            if now >= self.next_tick_ns + self.period_ns {
                self.next_tick_ns = now + self.period_ns;
            }
        }
        self.send_worlds()
    }

    fn counters(&self) -> Counters {
        [self.world_in.counter(), self.hand_out.counter()]
            .into_iter()
            .collect()
    }

    fn stop(&mut self, _: &mut Reporter) -> Result<(), BusError> {
        write_summary(&self.summary_file, self.summary());
        crate::link::close_bounded(self.zenoh.clone());
        Ok(())
    }
}

fn write_summary(file: &std::path::Path, summary: serde_json::Value) {
    if let Err(e) = std::fs::write(file, summary.to_string()) {
        eprintln!("handblocks bridge: cannot write {}: {e}", file.display());
    }
}

// ---------------------------------------------------------------------------------------------
// A participant.

/// One world taken off the link, and the attachment's seq of this participant's newest hand.
struct WorldIn {
    arrived_ns: u64,
    acked_seq: Option<u64>,
    bytes: zenoh::bytes::ZBytes,
}

/// A participant's side: its hands out, the host's worlds in.
struct Join {
    zenoh: zenoh::Session,
    /// The host's answer to the join, asked on its own thread; None once it came.
    asking: Option<crossbeam_channel::Receiver<Result<(usize, String), BridgeError>>>,
    /// Why the host refused this participant (the session stops, and says so).
    refused: Option<BridgeError>,
    participant: usize,
    name: String,
    hand_in: Inlet<topics::Hand>,
    /// Declared once joined (its key holds the secret the host gave).
    hand_sender: Option<zenoh::pubsub::Publisher<'static>>,
    worlds: crossbeam_channel::Receiver<WorldIn>,
    world_out: Outlet<topics::World>,
    elements: usize,
    wake: Arc<Wake>,
    queue_full: Arc<AtomicU64>,
    message: Vec<u8>,
    /// (seq, origin_ns) of the hands sent, by seq modulo the ring.
    sent: Box<[(u64, u64); SENT_RING]>,
    /// Hands this machine made before its first hand went to the host (before the join's
    /// answer, or superseded by a newer one before the first send): not sent (stale), and
    /// not seen by the host, whose gap count starts at the first hand it takes.
    hands_before_join: u64,
    /// The newest hand not sent yet (the link was behind).
    pending: Option<HandSample>,
    /// Hands superseded in `pending` since the last send.
    superseded: u64,
    /// Hands superseded before a newer one went (the host counts them lost: their seqs lie
    /// between two it took).
    held_back: u64,
    /// The hands sent and not yet answered by a world.
    hand_window: SendWindow,
    /// The newest world seq taken in and not yet answered to the host (`KEY/ack/SECRET`).
    world_to_ack: Option<u64>,
    ack_sender: Option<zenoh::pubsub::Publisher<'static>>,
    world_key: String,
    world_subscriber: Option<zenoh::pubsub::Subscriber<()>>,
    /// What the world subscriber's callback needs, kept for its declaration at the join.
    world_tx: crossbeam_channel::Sender<WorldIn>,
    /// The other participants' hands the host sends (`KEY/peer/SECRET`), published on this
    /// bus's `peer_hand` for the renderer and recorder.
    peer_subscriber: Option<zenoh::pubsub::Subscriber<()>>,
    peer_tx: crossbeam_channel::Sender<zenoh::bytes::ZBytes>,
    peers: crossbeam_channel::Receiver<zenoh::bytes::ZBytes>,
    peer_out: Outlet<topics::PeerHand>,
    peer_hands_taken: u64,
    /// Peer hands refused, by why (a host that sent garbage, or this participant's own).
    peer_hands_refused: BTreeMap<&'static str, u64>,
    hands_sent: u64,
    last_seq_sent: Option<u64>,
    secret: String,
    hand_bytes_sent: u64,
    worlds_taken: u64,
    worlds_malformed: u64,
    last_world_seq: Option<u64>,
    worlds_lost: u64,
    hand_to_world: hdrhistogram::Histogram<u64>,
    first_world_ns: Option<u64>,
    joined_ns: u64,
    started_ns: u64,
    endpoint: String,
    key: String,
    protection: String,
    summary_file: PathBuf,
}

impl Join {
    fn open(
        session: &Session,
        bus: &Bus,
        zenoh: zenoh::Session,
        link: &SharedLink,
        name: &str,
        protection: String,
        summary_file: PathBuf,
    ) -> Result<Join, BridgeError> {
        let wake = Arc::new(Wake::new().map_err(|e| BridgeError::Shared(SharedError::Wake(e)))?);
        let queue_full = Arc::new(AtomicU64::new(0));
        // The worlds come under this participant's own key, subscribed to at the join.
        let (world_tx, worlds) = crossbeam_channel::bounded(QUEUE);
        let Some(token) = link.token.clone() else {
            return Err(BridgeError::Shared(SharedError::Refused(
                "this session names no token: give the one the host printed, --set \
                 shared.token=TOKEN (handblocks launch shared-host prints the whole command)"
                    .into(),
            )));
        };
        // The bus ports first: the session's processes attach within the launcher's bound
        // however long the host takes to answer (a slow or lossy link, a host not up yet).
        let hand_in = bus.inlet::<topics::Hand>()?;
        let world_out = bus.slice_outlet::<topics::World>()?;
        let peer_out = bus.outlet::<topics::PeerHand>()?;
        let (peer_tx, peers) = crossbeam_channel::bounded(QUEUE);
        let started_ns = monotonic_ns();
        // The join on its own thread: the stage runs (and reports, and stops when asked) however
        // long the host takes to answer.
        let (answer_tx, asking) = crossbeam_channel::bounded(1);
        {
            let (zenoh, key, name, endpoint, wake) = (
                zenoh.clone(),
                link.key.clone(),
                name.to_string(),
                link.endpoint.clone(),
                wake.clone(),
            );
            std::thread::Builder::new()
                .name("shared-join".into())
                .spawn(move || {
                    let _ = answer_tx.send(join(&zenoh, &key, &token, &name, &endpoint));
                    wake.wake();
                })
                .map_err(|e| BridgeError::Shared(SharedError::Wake(e)))?;
        }
        Ok(Join {
            zenoh,
            asking: Some(asking),
            refused: None,
            participant: usize::MAX,
            name: name.to_string(),
            hand_in,
            hands_before_join: 0,
            pending: None,
            superseded: 0,
            held_back: 0,
            hand_window: SendWindow::default(),
            world_to_ack: None,
            ack_sender: None,
            world_key: String::new(),
            world_subscriber: None,
            world_tx,
            peer_subscriber: None,
            peer_tx,
            peers,
            peer_out,
            peer_hands_taken: 0,
            peer_hands_refused: BTreeMap::new(),
            hand_sender: None,
            worlds,
            world_out,
            elements: session.scene.blocks.len(),
            wake,
            queue_full,
            message: Vec::new(),
            sent: Box::new([(u64::MAX, 0); SENT_RING]),
            hands_sent: 0,
            last_seq_sent: None,
            secret: String::new(),
            hand_bytes_sent: 0,
            worlds_taken: 0,
            worlds_malformed: 0,
            last_world_seq: None,
            worlds_lost: 0,
            hand_to_world: hdrhistogram::Histogram::new_with_bounds(1, 60_000_000_000, 3)
                .expect("constant bounds are valid"),
            first_world_ns: None,
            joined_ns: started_ns,
            started_ns,
            endpoint: link.endpoint.clone(),
            key: link.key.clone(),
            protection,
            summary_file,
        })
    }

    /// Takes the host's answer to the join when it came: the participant's number and the
    /// key its hands go under. Until then hands are let go (stale by the time the host
    /// answers), counted. A refusal stops the session, and `run` says why.
    fn take_answer(&mut self) -> Result<(), BusError> {
        let Some(asking) = &self.asking else {
            return Ok(());
        };
        let answer = match asking.try_recv() {
            Ok(answer) => answer,
            Err(crossbeam_channel::TryRecvError::Empty) => {
                while self.hand_in.receive()?.is_some() {
                    self.hands_before_join += 1;
                }
                return Ok(());
            }
            Err(crossbeam_channel::TryRecvError::Disconnected) => Err(BridgeError::Shared(
                SharedError::Refused("the join ended without an answer".into()),
            )),
        };
        self.asking = None;
        while self.hand_in.receive()?.is_some() {
            self.hands_before_join += 1;
        }
        let declare_err = |key: String, e: zenoh::Error| {
            BridgeError::Link(crate::link::LinkError::Declare {
                key,
                reason: e.to_string(),
            })
        };
        let declared = answer.and_then(|(participant, secret)| {
            let hand_key = format!("{}/hand/{secret}", self.key);
            let sender = declare_sender(&self.zenoh, hand_key.clone())
                .map_err(|e| declare_err(hand_key, e))?;
            let ack_key = format!("{}/ack/{secret}", self.key);
            let acks = declare_sender(&self.zenoh, ack_key.clone())
                .map_err(|e| declare_err(ack_key, e))?;
            let world_key = format!("{}/world/{secret}", self.key);
            let (world_tx, full, world_wake) = (
                self.world_tx.clone(),
                self.queue_full.clone(),
                self.wake.clone(),
            );
            let subscriber = self
                .zenoh
                .declare_subscriber(world_key.clone())
                .callback(move |sample| {
                    // The seq of this participant's newest hand the world's frame held.
                    let acked_seq = sample.attachment().and_then(|a| {
                        let a = a.to_bytes();
                        a.get(8 * participant..8 * participant + 8)
                            .and_then(|b| b.try_into().ok())
                            .map(u64::from_le_bytes)
                    });
                    let item = WorldIn {
                        arrived_ns: monotonic_ns(),
                        acked_seq,
                        bytes: sample.payload().clone(),
                    };
                    match world_tx.try_send(item) {
                        Ok(()) => world_wake.wake(),
                        Err(_) => {
                            full.fetch_add(1, Ordering::Relaxed);
                        }
                    }
                })
                .wait()
                .map_err(|e| declare_err(world_key.clone(), e))?;
            let peer_key = format!("{}/peer/{secret}", self.key);
            let (peer_tx, full, peer_wake) = (
                self.peer_tx.clone(),
                self.queue_full.clone(),
                self.wake.clone(),
            );
            let peers = self
                .zenoh
                .declare_subscriber(peer_key.clone())
                .callback(
                    move |sample| match peer_tx.try_send(sample.payload().clone()) {
                        Ok(()) => peer_wake.wake(),
                        Err(_) => {
                            full.fetch_add(1, Ordering::Relaxed);
                        }
                    },
                )
                .wait()
                .map_err(|e| declare_err(peer_key, e))?;
            Ok((
                participant,
                secret,
                sender,
                acks,
                (subscriber, peers),
                world_key,
            ))
        });
        match declared {
            Ok((participant, secret, sender, acks, (subscriber, peers), world_key)) => {
                self.peer_subscriber = Some(peers);
                self.participant = participant;
                self.secret = secret;
                self.hand_sender = Some(sender);
                self.ack_sender = Some(acks);
                self.world_subscriber = Some(subscriber);
                self.world_key = world_key;
                self.joined_ns = monotonic_ns();
                eprintln!(
                    "handblocks bridge: joined the shared world on {} as participant \
                     {participant} ({}) after {:.2} s",
                    self.endpoint,
                    self.name,
                    (self.joined_ns - self.started_ns) as f64 / 1e9
                );
            }
            Err(e) => {
                self.refused = Some(e);
                common::shutdown::request();
            }
        }
        Ok(())
    }

    fn send_hands(&mut self, pass: &mut Pass<'_>) -> Result<(), BusError> {
        if self.hand_sender.is_none() {
            return Ok(());
        }
        while let Some(s) = self.hand_in.receive()? {
            let received = monotonic_ns();
            let mut hand: HandSample = *s.payload();
            hand.participant = self.participant as u32;
            pass.recorder.hop(&hand.stamp, received);
            // Newest only: a hand not yet sent is superseded by this one.
            if self.pending.replace(hand).is_some() {
                self.superseded += 1;
            }
        }
        self.send_pending(monotonic_ns());
        Ok(())
    }

    /// Sends the newest hand unless the link is behind ([`SendWindow`]).
    fn send_pending(&mut self, now: u64) {
        let behind = self.hand_window.behind(now);
        let (Some(hand_sender), false) = (&self.hand_sender, behind) else {
            return;
        };
        let Some(hand) = self.pending.take() else {
            return;
        };
        recording::encode_sample(&hand, &mut self.message);
        if hand_sender.put(self.message.as_slice()).wait().is_ok() {
            self.hands_sent += 1;
            let superseded = std::mem::take(&mut self.superseded);
            if self.last_seq_sent.is_some() {
                self.held_back += superseded;
            } else {
                // Before the first hand the host took: no gap it can see.
                self.hands_before_join += superseded;
            }
            self.last_seq_sent = Some(hand.stamp.seq);
            self.hand_bytes_sent += self.message.len() as u64;
            self.sent[(hand.stamp.seq % SENT_RING as u64) as usize] =
                (hand.stamp.seq, hand.stamp.origin_ns);
            self.hand_window.sent(hand.stamp.seq, now);
        } else {
            // Not sent: kept for the next try, unless a newer hand comes first.
            self.pending = Some(hand);
        }
    }

    /// Publishes the other participants' hands the host sent on this bus's `peer_hand`, each
    /// checked as the host checks a hand (it is outside input here too); this participant's
    /// own is refused (the host never sends it: its own hands are on `hand`).
    fn take_peers(&mut self) -> Result<(), BusError> {
        while let Ok(bytes) = self.peers.try_recv() {
            let bytes = bytes.to_bytes();
            let hand = match crate::peer_wire::decode(&bytes) {
                Ok(h) => h,
                Err(_) => {
                    *self
                        .peer_hands_refused
                        .entry("not a peer hand")
                        .or_default() += 1;
                    continue;
                }
            };
            let why = if hand.participant as usize == self.participant {
                Some("this participant's own number")
            } else if hand.slot().is_none() || hand.side > 1 {
                Some("a participant or side out of range")
            } else {
                hand.unusable_because()
            };
            if let Some(why) = why {
                *self.peer_hands_refused.entry(why).or_default() += 1;
                continue;
            }
            let peer = PeerHandSample {
                stamp: Stamp::at_origin(0, monotonic_ns()),
                own_participant: self.participant as u32,
                _reserved: 0,
                hand,
            };
            self.peer_out.publish(&peer)?;
            self.peer_hands_taken += 1;
        }
        Ok(())
    }

    fn take_worlds(&mut self, pass: &mut Pass<'_>) {
        while let Ok(item) = self.worlds.try_recv() {
            let bytes = item.bytes.to_bytes();
            let decoded: Result<(common::WorldHeader, &[u8]), _> =
                recording::decode_slice(Topic::World, &bytes);
            let Ok((header, body)) = decoded else {
                self.worlds_malformed += 1;
                continue;
            };
            let size = std::mem::size_of::<common::BlockState>();
            let n = body.len() / size;
            if n != self.elements {
                self.worlds_malformed += 1;
                continue;
            }
            // The world's age on this machine: from this participant's own hand that its frame
            // held (the attachment), else from its arrival.
            let own_origin = item.acked_seq.and_then(|seq| {
                let (kept, origin) = self.sent[(seq % SENT_RING as u64) as usize];
                (kept == seq).then_some(origin)
            });
            if let Some(origin) = own_origin {
                let _ = self
                    .hand_to_world
                    .record(item.arrived_ns.saturating_sub(origin).max(1));
            }
            // The hands this world answers are no longer in flight; the quickest turn so far
            // sets the send window.
            if let Some(acked) = item.acked_seq {
                self.hand_window.answered(acked, item.arrived_ns);
            }
            let seq = header.stamp.seq;
            if let Some(last) = self.last_world_seq {
                if seq > last + 1 {
                    self.worlds_lost += seq - last - 1;
                }
            }
            self.last_world_seq = Some(seq);
            self.world_to_ack = Some(self.world_to_ack.map_or(seq, |a| a.max(seq)));
            let published = self.world_out.publish_with_as(
                seq,
                n,
                |h| {
                    *h = header;
                    h.stamp.origin_ns = own_origin.unwrap_or(item.arrived_ns);
                },
                // SAFETY: `body` holds exactly `n` elements (checked above); a block state is
                // plain old data (any bit pattern valid), read unaligned.
                |i| unsafe {
                    std::ptr::read_unaligned(body[i * size..].as_ptr() as *const common::BlockState)
                },
            );
            if let Ok(stamp) = published {
                pass.recorder.output(item.arrived_ns, &stamp);
                self.worlds_taken += 1;
                if self.hand_sender.is_some() {
                    self.first_world_ns.get_or_insert(item.arrived_ns);
                }
            }
        }
    }

    fn summary(&self) -> serde_json::Value {
        use serde_json::json;
        let seconds = (monotonic_ns().saturating_sub(self.joined_ns) as f64 / 1e9).max(1e-9);
        let h = &self.hand_to_world;
        let us = |q: f64| (!h.is_empty()).then(|| h.value_at_quantile(q) as f64 / 1e3);
        json!({
            "shared": {
                "role": "join",
                "endpoint": self.endpoint,
                "key": self.key,
                "protection": self.protection,
                "participant": (self.participant < MAX_PARTICIPANTS).then_some(self.participant),
                "name": self.name,
                "join_s": self
                    .hand_sender
                    .is_some()
                    .then(|| (self.joined_ns - self.started_ns) as f64 / 1e9),
                "first_world_after_join_s": self
                    .first_world_ns
                    .map(|t| t.saturating_sub(self.joined_ns) as f64 / 1e9),
                "hands_sent": self.hands_sent,
                "hands_before_join": self.hands_before_join,
                "hands_held_back": self.held_back,
                "hands_held_back_at_the_end": self.superseded + u64::from(self.pending.is_some()),
                "send_window_ms": self.hand_window.window_ms(),
                "hand_bytes_out_per_s": self.hand_bytes_sent as f64 / seconds,
                "worlds_taken_in": self.worlds_taken,
                "worlds_lost": self.worlds_lost,
                "worlds_malformed": self.worlds_malformed,
                "peer_hands_taken": self.peer_hands_taken,
                "peer_hands_refused": self.peer_hands_refused,
                "queue_full": self.queue_full.load(Ordering::Relaxed),
                "hand_to_world_us": {
                    "count": h.len(),
                    "p50": us(0.5),
                    "p99": us(0.99),
                    "max": us(1.0),
                    "what": "this participant's hand (its origin, on its clock) to the host's \
                             world whose frame held it, taken in here",
                },
            }
        })
    }
}

/// Asks the host at `KEY/join` until it answers (the host may start later), or the process is
/// asked to stop; returns the participant's number and its secret key segment.
fn join(
    zenoh: &zenoh::Session,
    key: &str,
    token: &str,
    name: &str,
    endpoint: &str,
) -> Result<(usize, String), BridgeError> {
    let asked = serde_json::json!({ "token": token, "name": name }).to_string();
    let join_key = format!("{key}/join");
    let mut told = false;
    while !common::shutdown::requested() {
        let replies = zenoh
            .get(join_key.as_str())
            .payload(asked.as_str())
            .timeout(Duration::from_secs(2))
            .wait();
        if let Ok(replies) = replies {
            while let Ok(reply) = replies.recv() {
                let Ok(sample) = reply.result() else { continue };
                let answer: serde_json::Value =
                    serde_json::from_slice(&sample.payload().to_bytes()).unwrap_or_default();
                if let Some(why) = answer["refused"].as_str() {
                    return Err(BridgeError::Shared(SharedError::Refused(why.to_string())));
                }
                if let (Some(k), Some(secret)) =
                    (answer["participant"].as_u64(), answer["secret"].as_str())
                {
                    if (k as usize) < MAX_PARTICIPANTS
                        && secret.len() == 32
                        && secret.chars().all(|c| c.is_ascii_hexdigit())
                    {
                        return Ok((k as usize, secret.to_string()));
                    }
                }
            }
        }
        if !told {
            eprintln!(
                "handblocks bridge: waiting for the shared world's host on {endpoint} \
                 (asking every {} ms)",
                JOIN_RETRY.as_millis()
            );
            told = true;
        }
        std::thread::sleep(JOIN_RETRY);
    }
    Err(BridgeError::Shared(SharedError::Refused(
        "stopped before the host answered".into(),
    )))
}

impl Task for Join {
    type Error = BusError;

    fn wait(&mut self, _: &mut Waiter, timeout: Duration) -> Result<(), BusError> {
        let inlets = std::iter::once(&self.hand_in as &dyn common::bus::Wakeable);
        wait_each(inlets, Some(self.wake.fd()), timeout.min(node::IDLE_WAIT))
    }

    fn work(&mut self, pass: &mut Pass<'_>) -> Result<(), BusError> {
        self.wake.clear();
        self.take_answer()?;
        self.send_hands(pass)?;
        self.take_worlds(pass);
        self.take_peers()?;
        // The worlds' acks may have opened the window for a hand held back.
        self.send_pending(monotonic_ns());
        // The newest world taken in, answered: the host sends the next ones while this
        // participant's link keeps up.
        if let (Some(seq), Some(acks)) = (self.world_to_ack.take(), &self.ack_sender) {
            let _ = acks.put(&seq.to_le_bytes()[..]).wait();
        }
        Ok(())
    }

    fn counters(&self) -> Counters {
        [
            self.hand_in.counter(),
            self.world_out.counter(),
            self.peer_out.counter(),
        ]
        .into_iter()
        .collect()
    }

    fn stop(&mut self, _: &mut Reporter) -> Result<(), BusError> {
        // Say goodbye (bounded): the host lets this participant's hands go at once, and counts
        // what it sent that never came.
        let said = serde_json::json!({ "secret": self.secret, "last_seq": self.last_seq_sent });
        let joined = self.hand_sender.is_some();
        if let Some(replies) = joined
            .then(|| {
                self.zenoh
                    .get(format!("{}/leave", self.key))
                    .payload(said.to_string())
                    .timeout(Duration::from_secs(1))
                    .wait()
                    .ok()
            })
            .flatten()
        {
            let _ = replies.recv_timeout(Duration::from_secs(1));
        }
        write_summary(&self.summary_file, self.summary());
        crate::link::close_bounded(self.zenoh.clone());
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bytes(hand: &HandSample) -> Vec<u8> {
        let mut out = Vec::new();
        recording::encode_sample(hand, &mut out);
        out
    }

    fn hand(participant: u32, seq: u64, source_time_ns: u64) -> HandSample {
        HandSample {
            participant,
            stamp: Stamp {
                seq,
                source_time_ns,
                ..Stamp::default()
            },
            ..HandSample::default()
        }
    }

    /// Issue 45, bad input: each kind of bad hand is refused by its own name, and the
    /// participant's good hands around it are still taken.
    #[test]
    fn a_participants_bad_hands_are_refused_by_name_and_its_good_ones_taken() {
        let mut p = Participant::default();
        let k = 1;
        let take = |p: &mut Participant, h: &HandSample, now: u64| {
            let taken = check_hand(p, k, &bytes(h), now);
            if let Ok((h, _)) = taken {
                p.last_seq = Some(h.stamp.seq);
            }
            taken.map(|(h, side)| (h.stamp.seq, side))
        };
        let s = 1_000_000_000;
        assert_eq!(take(&mut p, &hand(1, 1, 0), s), Ok((1, 0)));
        let mut nan = hand(1, 2, 10_000_000);
        nan.wrist.position[1] = f64::NAN;
        assert_eq!(
            take(&mut p, &nan, s + 10_000_000),
            Err("a hand the world cannot use (not finite, or out of range)")
        );
        assert_eq!(
            take(&mut p, &hand(1, 1, 10_000_000), s + 10_000_000),
            Err("a seq not after the last (duplicate or reordered)")
        );
        assert_eq!(
            take(&mut p, &hand(0, 3, 10_000_000), s + 10_000_000),
            Err("another participant's number")
        );
        let mut sideways = hand(1, 3, 10_000_000);
        sideways.side = 7;
        assert_eq!(
            take(&mut p, &sideways, s + 10_000_000),
            Err("a side neither right nor left")
        );
        // 5 s of source time 20 ms after the first: a future stamp.
        assert_eq!(
            take(&mut p, &hand(1, 3, 5_000_000_000), s + 20_000_000),
            Err("a source time ahead of the host's clock (a future stamp)")
        );
        assert_eq!(
            check_hand(&mut p, k, b"\x00\x01garbage", s + 20_000_000).map(|_| ()),
            Err("not a hand sample")
        );
        // A good one after all that; a left hand is side 1.
        let mut left = hand(1, 4, 30_000_000);
        left.side = 1;
        assert_eq!(take(&mut p, &left, s + 30_000_000), Ok((4, 1)));
        // A flood: past FLOOD_PER_S hands in one second the rest are refused.
        let mut refused = 0;
        for i in 0..u64::from(FLOOD_PER_S) + 50 {
            let t = 40_000_000 + i * 100_000;
            if take(&mut p, &hand(1, 5 + i, t), s + t)
                == Err("a flood (more hands a second than FLOOD_PER_S)")
            {
                refused += 1;
            }
        }
        assert!(refused >= 50, "{refused} refused as a flood");
    }
}
