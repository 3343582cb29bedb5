//! The page's socket besides the hands frame: what else the page sends (its frame statistics,
//! its answer to a clock ping) and what it is sent (the scene and `ready` as text, the world,
//! the ping). Every binary message starts with [`MAGIC`] and a kind byte, then three zero bytes
//! and a u32; each kind has one length.
//!
//! ```text
//! kind 2, stats (page -> us), 32 bytes: u32 seq of the hands frame reported; f64 its frame
//!         callback's JavaScript time (ms); f64 the newest round trip (ms) measured since the
//!         last stats, from a hands frame sent to the world that answers it drawn (-1: none)
//! kind 4, pong (page -> us), 32 bytes: u32 the ping's seq; f64 the ping's server time (ms,
//!         echoed); f64 the page's clock (ms, performance.now()) when the ping arrived
//! kind 5, ping (us -> page), 24 bytes: u32 seq; f64 the server's time (ms)
//! kind 6, peers (us -> page), 16 + per hand 8 + 12 points bytes: u32 hands (0 to
//!         [`MAX_PEER_HANDS`]); u32 0; per hand u32 its participant, u16 its side (0 the right
//!         or only hand, 1 the left), u16 its points (0 to [`PEER_HAND_POINTS`]), then each
//!         point 3 f32: the other participants' hands in a shared world, as their finger
//!         points (the world's frame), the newest of each; a hand no longer in it is left out
//! kind 3, world (us -> page), 32 + 32 blocks + 12 points bytes: u32 the hands frame's seq this
//!         world answers (u32::MAX: none of this page's); u32 blocks; f64 world time (s); i32
//!         the grasped block (-1: none; the first grasped); u32 finger points; per block 7 f32
//!         (position x y z, orientation x y z w), u16 its mode (`BlockMode`), u16 the hands
//!         that hold it (`BlockState::held_by`: bit 0 the right hand or a one-hand session's
//!         only hand, bit 1 the left; 0 when not grasped); per finger point 3 f32
//! ```
//! Statistics are bounded: a JavaScript time of 0 to 10 s, a round trip of -1 (none) or 0 to
//! 60 s; clock times finite and non-negative.
//!
//! **Text** ([`Text`], JSON objects told apart by their `op`): the [`Scene`], sent first on
//! every socket (the blocks' hulls, names and colours, the floor, the session's hands and
//! offset), and [`Ready`], once the page's clock is known (the page sends hands only after
//! it). Their keys go out in the order their fields are declared, which is the order the
//! first server wrote them in, so the bytes did not change when they became types.

use common::{WorldView, MAX_FINGERS, MAX_FINGER_POINTS};
use serde::{Deserialize, Serialize};

use crate::{WireError, MAGIC};

/// `kind` of the page's frame statistics.
pub const KIND_STATS: u8 = 2;
/// `kind` of a world state sent to the page.
pub const KIND_WORLD: u8 = 3;
/// `kind` of the page's answer to a ping.
pub const KIND_PONG: u8 = 4;
/// `kind` of a clock ping sent to the page.
pub const KIND_PING: u8 = 5;
/// `kind` of the other participants' hands sent to the page.
pub const KIND_PEERS: u8 = 6;
/// Bytes of a peers message before its hands.
pub const PEERS_HEADER_BYTES: usize = 16;
/// Bytes of one hand's head in a peers message (before its points).
pub const PEER_HAND_HEAD_BYTES: usize = 8;
/// The most hands one peers message holds: two for each other participant.
pub const MAX_PEER_HANDS: usize = 2 * (common::MAX_PARTICIPANTS - 1);
/// The most points one hand of a peers message holds (every finger's check points).
pub const PEER_HAND_POINTS: usize = MAX_FINGERS * MAX_FINGER_POINTS;
/// Bytes of a stats or pong message.
pub const STATS_BYTES: usize = 32;
/// Bytes of a ping.
pub const PING_BYTES: usize = 24;
/// Bytes of a world message before its blocks.
pub const WORLD_HEADER_BYTES: usize = 32;
/// Bytes of one block in a world message.
pub const WORLD_BLOCK_BYTES: usize = 32;
/// Bytes of one finger point in a world message.
pub const WORLD_POINT_BYTES: usize = 12;
/// `page_seq` of a world that answers none of the page's frames.
pub const NO_FRAME: u32 = u32::MAX;

/// One frame's statistics from the page.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameStats {
    pub seq: u32,
    pub js_ms: f64,
    /// None when no world answered a frame since the last statistics.
    pub round_trip_ms: Option<f64>,
}

/// A clock ping.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ping {
    pub seq: u32,
    /// The server's CLOCK_MONOTONIC when it sent the ping, ms (the pong echoes it).
    pub server_ms: f64,
}

/// The page's answer to a ping.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pong {
    pub seq: u32,
    pub server_ms: f64,
    pub page_ms: f64,
}

/// The kind byte of a message of this format (checked magic), or why not.
pub fn kind_of(bytes: &[u8]) -> Result<u8, WireError> {
    if bytes.len() < 8 {
        return Err(WireError::Length {
            expected: 8,
            got: bytes.len(),
        });
    }
    let magic = [bytes[0], bytes[1], bytes[2], bytes[3]];
    if magic != MAGIC {
        return Err(WireError::Magic(magic));
    }
    Ok(bytes[4])
}

fn fixed(bytes: &[u8], kind: u8, len: usize) -> Result<(), WireError> {
    let k = kind_of(bytes)?;
    if k != kind {
        return Err(WireError::Kind(k));
    }
    if bytes.len() != len {
        return Err(WireError::Length {
            expected: len,
            got: bytes.len(),
        });
    }
    if bytes[5..8] != [0, 0, 0] || bytes[12..16] != [0, 0, 0, 0] {
        return Err(WireError::Reserved);
    }
    Ok(())
}

fn u32_at(bytes: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]])
}

fn f64_at(bytes: &[u8], at: usize) -> f64 {
    let mut b = [0u8; 8];
    b.copy_from_slice(&bytes[at..at + 8]);
    f64::from_le_bytes(b)
}

fn within(
    field: &'static str,
    value: f64,
    range: std::ops::RangeInclusive<f64>,
) -> Result<f64, WireError> {
    if value.is_finite() && range.contains(&value) {
        Ok(value)
    } else {
        Err(WireError::Value { field, value })
    }
}

/// Decodes the page's frame statistics (kind 2).
pub fn decode_stats(bytes: &[u8]) -> Result<FrameStats, WireError> {
    fixed(bytes, KIND_STATS, STATS_BYTES)?;
    let js_ms = within("js_ms", f64_at(bytes, 16), 0.0..=10_000.0)?;
    let rt = f64_at(bytes, 24);
    let round_trip_ms = if rt == -1.0 {
        None
    } else {
        Some(within("round_trip_ms", rt, 0.0..=60_000.0)?)
    };
    Ok(FrameStats {
        seq: u32_at(bytes, 8),
        js_ms,
        round_trip_ms,
    })
}

/// Decodes a ping (kind 5).
pub fn decode_ping(bytes: &[u8]) -> Result<Ping, WireError> {
    fixed(bytes, KIND_PING, PING_BYTES)?;
    Ok(Ping {
        seq: u32_at(bytes, 8),
        server_ms: within("server_ms", f64_at(bytes, 16), 0.0..=f64::MAX)?,
    })
}

/// Decodes the page's answer to a ping (kind 4).
pub fn decode_pong(bytes: &[u8]) -> Result<Pong, WireError> {
    fixed(bytes, KIND_PONG, STATS_BYTES)?;
    Ok(Pong {
        seq: u32_at(bytes, 8),
        server_ms: within("server_ms", f64_at(bytes, 16), 0.0..=f64::MAX)?,
        page_ms: within("page_ms", f64_at(bytes, 24), 0.0..=f64::MAX)?,
    })
}

fn head(out: &mut Vec<u8>, kind: u8, word: u32, word2: u32) {
    out.clear();
    out.extend_from_slice(&MAGIC);
    out.extend_from_slice(&[kind, 0, 0, 0]);
    out.extend_from_slice(&word.to_le_bytes());
    out.extend_from_slice(&word2.to_le_bytes());
}

/// A ping (kind 5) into `out` (cleared first).
pub fn encode_ping(seq: u32, server_ms: f64, out: &mut Vec<u8>) {
    head(out, KIND_PING, seq, 0);
    out.extend_from_slice(&server_ms.to_le_bytes());
}

/// The page's stats (kind 2) as the page writes them (for tests and the fuzz seeds).
pub fn encode_stats(stats: &FrameStats, out: &mut Vec<u8>) {
    head(out, KIND_STATS, stats.seq, 0);
    out.extend_from_slice(&stats.js_ms.to_le_bytes());
    out.extend_from_slice(&stats.round_trip_ms.unwrap_or(-1.0).to_le_bytes());
}

/// The page's pong (kind 4) as the page writes it (for tests and the fuzz seeds).
pub fn encode_pong(pong: &Pong, out: &mut Vec<u8>) {
    head(out, KIND_PONG, pong.seq, 0);
    out.extend_from_slice(&pong.server_ms.to_le_bytes());
    out.extend_from_slice(&pong.page_ms.to_le_bytes());
}

/// A world message (kind 3) of `world` into `out` (cleared first, then grown once to its
/// size: a kept buffer of the scene's size is written without allocating): its blocks'
/// positions, orientations, modes and the hands that hold them, the grasped block, and the
/// finger points as drawn.
pub fn encode_world(page_seq: u32, world_time_s: f64, world: &WorldView<'_>, out: &mut Vec<u8>) {
    let blocks = world.blocks();
    let fingers = (world.finger_count as usize).min(MAX_FINGERS);
    let points_of = |f: usize| (world.finger_point_count[f] as usize).min(MAX_FINGER_POINTS);
    let points: usize = (0..fingers).map(points_of).sum();
    head(out, KIND_WORLD, page_seq, blocks.len() as u32);
    out.extend_from_slice(&world_time_s.to_le_bytes());
    out.extend_from_slice(&world.grasped_block.to_le_bytes());
    out.extend_from_slice(&(points as u32).to_le_bytes());
    for b in blocks {
        for v in b.pose.position.into_iter().chain(b.pose.rotation) {
            out.extend_from_slice(&(v as f32).to_le_bytes());
        }
        out.extend_from_slice(&(b.mode.min(u32::from(u16::MAX)) as u16).to_le_bytes());
        out.extend_from_slice(&((b.held_by & 0xFFFF) as u16).to_le_bytes());
    }
    for f in 0..fingers {
        for p in &world.finger_points[f][..points_of(f)] {
            for v in p {
                out.extend_from_slice(&(*v as f32).to_le_bytes());
            }
        }
    }
}

/// A world message (kind 3) as the page reads it: what [`encode_world`] wrote, each number
/// as it travelled.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct World {
    /// The seq of the page's hands frame this world answers ([`NO_FRAME`]: none of its own).
    pub page_seq: u32,
    /// The world's time, seconds (its step count times its step).
    pub time_s: f64,
    /// The grasped block (-1: none; with two grasped, the first).
    pub grasped: i32,
    pub blocks: Vec<WorldBlock>,
    /// Every finger's points as drawn, one finger after another.
    pub finger_points: Vec<[f32; 3]>,
}

/// One block of a [`World`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WorldBlock {
    pub position: [f32; 3],
    /// A unit quaternion `[x, y, z, w]`.
    pub rotation: [f32; 4],
    /// `common::BlockMode`.
    pub mode: u16,
    /// `BlockState::held_by`: bit 0 the right hand (or a one-hand session's only hand), bit 1
    /// the left.
    pub held_by: u16,
}

fn f32_at(bytes: &[u8], at: usize) -> f32 {
    let mut b = [0u8; 4];
    b.copy_from_slice(&bytes[at..at + 4]);
    f32::from_le_bytes(b)
}

fn u16_at(bytes: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([bytes[at], bytes[at + 1]])
}

/// Decodes a world message (kind 3): its length must be the one its counts imply.
pub fn decode_world(bytes: &[u8]) -> Result<World, WireError> {
    let k = kind_of(bytes)?;
    if k != KIND_WORLD {
        return Err(WireError::Kind(k));
    }
    if bytes.len() < WORLD_HEADER_BYTES {
        return Err(WireError::Length {
            expected: WORLD_HEADER_BYTES,
            got: bytes.len(),
        });
    }
    if bytes[5..8] != [0, 0, 0] {
        return Err(WireError::Reserved);
    }
    let blocks = u32_at(bytes, 12) as usize;
    let points = u32_at(bytes, 28) as usize;
    let expected = blocks
        .checked_mul(WORLD_BLOCK_BYTES)
        .zip(points.checked_mul(WORLD_POINT_BYTES))
        .and_then(|(b, p)| (WORLD_HEADER_BYTES + b).checked_add(p));
    if expected != Some(bytes.len()) {
        return Err(WireError::Length {
            expected: expected.unwrap_or(usize::MAX),
            got: bytes.len(),
        });
    }
    let block = |i: usize| {
        let at = WORLD_HEADER_BYTES + i * WORLD_BLOCK_BYTES;
        WorldBlock {
            position: std::array::from_fn(|k| f32_at(bytes, at + 4 * k)),
            rotation: std::array::from_fn(|k| f32_at(bytes, at + 12 + 4 * k)),
            mode: u16_at(bytes, at + 28),
            held_by: u16_at(bytes, at + 30),
        }
    };
    let first_point = WORLD_HEADER_BYTES + blocks * WORLD_BLOCK_BYTES;
    let point = |i: usize| {
        let at = first_point + i * WORLD_POINT_BYTES;
        std::array::from_fn(|k| f32_at(bytes, at + 4 * k))
    };
    Ok(World {
        page_seq: u32_at(bytes, 8),
        time_s: f64_at(bytes, 16),
        grasped: u32_at(bytes, 24) as i32,
        blocks: (0..blocks).map(block).collect(),
        finger_points: (0..points).map(point).collect(),
    })
}

/// Another participant's hand as a peers message (kind 6) carries it and the page reads it:
/// its finger points in the world's frame, one finger after another.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PeerHand {
    /// The host's number for its participant.
    pub participant: u32,
    /// 0 the right (or a one-hand session's only) hand, 1 the left.
    pub side: u16,
    pub points: Vec<[f32; 3]>,
}

/// A peers message (kind 6) of `hands` into `out` (cleared first): at most
/// [`MAX_PEER_HANDS`] hands of at most [`PEER_HAND_POINTS`] points each (those beyond are
/// left out). `hands` gives each hand's participant, side and points.
pub fn encode_peers<'a>(
    hands: impl Iterator<Item = (u32, u16, &'a [[f32; 3]])> + Clone,
    out: &mut Vec<u8>,
) {
    let count = hands.clone().take(MAX_PEER_HANDS).count();
    head(out, KIND_PEERS, count as u32, 0);
    for (participant, side, points) in hands.take(MAX_PEER_HANDS) {
        let points = &points[..points.len().min(PEER_HAND_POINTS)];
        out.extend_from_slice(&participant.to_le_bytes());
        out.extend_from_slice(&side.to_le_bytes());
        out.extend_from_slice(&(points.len() as u16).to_le_bytes());
        for v in points.iter().flatten() {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
}

/// Decodes a peers message (kind 6): every count in its range and the length the counts
/// imply. The points are passed as they travelled (NaN included: the page draws what is
/// finite, and the bridge refused a NaN hand before it came here).
pub fn decode_peers(bytes: &[u8]) -> Result<Vec<PeerHand>, WireError> {
    let k = kind_of(bytes)?;
    if k != KIND_PEERS {
        return Err(WireError::Kind(k));
    }
    if bytes.len() < PEERS_HEADER_BYTES {
        return Err(WireError::Length {
            expected: PEERS_HEADER_BYTES,
            got: bytes.len(),
        });
    }
    if bytes[5..8] != [0, 0, 0] || bytes[12..16] != [0, 0, 0, 0] {
        return Err(WireError::Reserved);
    }
    let count = u32_at(bytes, 8) as usize;
    if count > MAX_PEER_HANDS {
        return Err(WireError::Value {
            field: "peer hands",
            value: count as f64,
        });
    }
    let mut hands = Vec::with_capacity(count);
    let mut at = PEERS_HEADER_BYTES;
    for _ in 0..count {
        if bytes.len() < at + PEER_HAND_HEAD_BYTES {
            return Err(WireError::Length {
                expected: at + PEER_HAND_HEAD_BYTES,
                got: bytes.len(),
            });
        }
        let participant = u32_at(bytes, at);
        let side = u16_at(bytes, at + 4);
        let points = u16_at(bytes, at + 6) as usize;
        if participant as usize >= common::MAX_PARTICIPANTS {
            return Err(WireError::Value {
                field: "participant",
                value: f64::from(participant),
            });
        }
        if side > 1 {
            return Err(WireError::Value {
                field: "side",
                value: f64::from(side),
            });
        }
        if points > PEER_HAND_POINTS {
            return Err(WireError::Value {
                field: "peer hand points",
                value: points as f64,
            });
        }
        at += PEER_HAND_HEAD_BYTES;
        let end = at + points * WORLD_POINT_BYTES;
        if bytes.len() < end {
            return Err(WireError::Length {
                expected: end,
                got: bytes.len(),
            });
        }
        let point = |i: usize| std::array::from_fn(|k| f32_at(bytes, at + 12 * i + 4 * k));
        hands.push(PeerHand {
            participant,
            side,
            points: (0..points).map(point).collect(),
        });
        at = end;
    }
    if at != bytes.len() {
        return Err(WireError::Length {
            expected: at,
            got: bytes.len(),
        });
    }
    Ok(hands)
}

/// The hands a session takes from the page, as the scene names them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Hands {
    Right,
    Left,
    Both,
}

impl From<common::HandsUsed> for Hands {
    fn from(hands: common::HandsUsed) -> Hands {
        match hands {
            common::HandsUsed::One(common::HandSide::Right) => Hands::Right,
            common::HandsUsed::One(common::HandSide::Left) => Hands::Left,
            common::HandsUsed::Both => Hands::Both,
        }
    }
}

/// The `op` of a [`Scene`]: a field of its own, so that it goes out where the first server
/// put it (keys in alphabetical order), not first as a serde tag would.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum SceneOp {
    #[default]
    #[serde(rename = "scene")]
    Scene,
}

/// The `op` of a [`Ready`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum ReadyOp {
    #[default]
    #[serde(rename = "ready")]
    Ready,
}

/// The scene as the page draws it, sent first on every socket.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Scene {
    pub blocks: Vec<SceneBlock>,
    /// The floor's height, metres (the world's y).
    pub floor_y: f64,
    /// The hands the session takes: the page draws the world's hand slots with them.
    pub hand: Hands,
    /// What the session adds to the tracked hand's positions (metres): the page moves the
    /// world back by as much in the headset, so the blocks lie where the hand is.
    pub offset: [f64; 3],
    pub op: SceneOp,
    /// The session's file, for the page to show.
    pub session: String,
    pub step_hz: f64,
}

/// One block of a [`Scene`]: its hull in its own frame (about its centre of gravity, as the
/// world's poses place it), its name and colour.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneBlock {
    /// Linear RGB, 0 to 1 (the scene's f32 colours, each as the f64 it is).
    pub color: [f64; 3],
    /// Three per triangle, into `vertices`.
    pub indices: Vec<u32>,
    pub name: String,
    /// x y z per vertex, metres.
    pub vertices: Vec<f64>,
}

/// The page's clock is known: it may send hands. The offset and round trip are the ping's
/// with the shortest round trip so far, for the page to show.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Ready {
    pub op: ReadyOp,
    /// Add to the page's clock (ms) for this machine's CLOCK_MONOTONIC (ms).
    pub offset_ms: f64,
    pub round_trip_ms: f64,
}

/// A text message to the page.
#[derive(Debug, Clone, PartialEq)]
pub enum Text {
    Scene(Scene),
    Ready(Ready),
}

/// Why a text message was refused.
#[derive(Debug, thiserror::Error)]
pub enum TextError {
    #[error("not a message of the page's: {0}")]
    Json(#[from] serde_json::Error),
    #[error("unknown op {0:?} (allowed: scene, ready)")]
    Op(String),
}

/// Its JSON: a structure of numbers and strings, which always serialises.
fn json<T: Serialize>(message: &T) -> String {
    serde_json::to_string(message).expect("a message of numbers and strings serialises")
}

impl Scene {
    /// The scene's JSON, as the page is sent it.
    pub fn encode(&self) -> String {
        json(self)
    }
}

impl Ready {
    pub fn new(offset_ms: f64, round_trip_ms: f64) -> Ready {
        Ready {
            op: ReadyOp::Ready,
            offset_ms,
            round_trip_ms,
        }
    }

    /// `ready`'s JSON, as the page is sent it.
    pub fn encode(&self) -> String {
        json(self)
    }
}

/// Decodes a text message by its `op`.
pub fn decode_text(text: &str) -> Result<Text, TextError> {
    #[derive(Deserialize)]
    struct Op {
        op: String,
    }
    let Op { op } = serde_json::from_str(text)?;
    match op.as_str() {
        "scene" => Ok(Text::Scene(serde_json::from_str(text)?)),
        "ready" => Ok(Text::Ready(serde_json::from_str(text)?)),
        _ => Err(TextError::Op(op)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stats_and_pongs_round_trip_and_bad_values_are_refused_by_name() {
        let mut b = Vec::new();
        let s = FrameStats {
            seq: 9,
            js_ms: 1.5,
            round_trip_ms: Some(40.0),
        };
        encode_stats(&s, &mut b);
        assert_eq!(decode_stats(&b), Ok(s));
        let none = FrameStats {
            round_trip_ms: None,
            ..s
        };
        encode_stats(&none, &mut b);
        assert_eq!(decode_stats(&b), Ok(none));
        encode_stats(
            &FrameStats {
                js_ms: f64::NAN,
                ..s
            },
            &mut b,
        );
        assert_eq!(decode_stats(&b).unwrap_err().kind(), "value");
        let p = Pong {
            seq: 3,
            server_ms: 10.0,
            page_ms: 2.0,
        };
        encode_pong(&p, &mut b);
        assert_eq!(decode_pong(&b), Ok(p));
        assert_eq!(decode_stats(&b).unwrap_err().kind(), "kind");
        let mut ping = Vec::new();
        encode_ping(3, 10.0, &mut ping);
        assert_eq!(
            decode_ping(&ping),
            Ok(Ping {
                seq: 3,
                server_ms: 10.0
            })
        );
        assert_eq!(decode_ping(&b).unwrap_err().kind(), "kind");
        b.push(0);
        assert_eq!(decode_pong(&b).unwrap_err().kind(), "length");
        b.pop();
        b[6] = 1;
        assert_eq!(decode_pong(&b).unwrap_err().kind(), "reserved");
        assert_eq!(
            kind_of(b"HBX"),
            Err(WireError::Length {
                expected: 8,
                got: 3
            })
        );
    }

    #[test]
    fn a_peers_message_round_trips_and_every_bad_count_or_length_is_refused() {
        let right: Vec<[f32; 3]> = (0..19).map(|i| [i as f32, 1.5, -0.25]).collect();
        let left = vec![[0.5f32, 1.0, 2.0]; 3];
        let hands = [(2u32, 0u16, &right[..]), (3, 1, &left[..])];
        let mut b = Vec::new();
        encode_peers(hands.iter().copied(), &mut b);
        assert_eq!(
            b.len(),
            PEERS_HEADER_BYTES + 2 * PEER_HAND_HEAD_BYTES + 22 * 12
        );
        let back = decode_peers(&b).unwrap();
        assert_eq!(back.len(), 2);
        assert_eq!((back[0].participant, back[0].side), (2, 0));
        assert_eq!(back[0].points, right);
        assert_eq!(
            (back[1].participant, back[1].side, &back[1].points),
            (3, 1, &left)
        );
        // None: a message of no hands (everyone else left).
        let mut none = Vec::new();
        encode_peers(std::iter::empty(), &mut none);
        assert_eq!(decode_peers(&none).unwrap(), vec![]);
        // Every truncation, and a byte more, is refused by its length.
        for len in 0..b.len() {
            assert!(decode_peers(&b[..len]).is_err(), "{len} bytes taken");
        }
        let mut long = b.clone();
        long.push(0);
        assert_eq!(decode_peers(&long).unwrap_err().kind(), "length");
        // Counts out of range, each by name.
        let mut bad = b.clone();
        bad[8] = MAX_PEER_HANDS as u8 + 1;
        assert_eq!(
            decode_peers(&bad),
            Err(WireError::Value {
                field: "peer hands",
                value: (MAX_PEER_HANDS + 1) as f64
            })
        );
        let mut bad = b.clone();
        bad[PEERS_HEADER_BYTES] = common::MAX_PARTICIPANTS as u8;
        assert!(matches!(
            decode_peers(&bad),
            Err(WireError::Value {
                field: "participant",
                ..
            })
        ));
        let mut bad = b.clone();
        bad[PEERS_HEADER_BYTES + 4] = 2;
        assert!(matches!(
            decode_peers(&bad),
            Err(WireError::Value { field: "side", .. })
        ));
        let mut bad = b.clone();
        bad[PEERS_HEADER_BYTES + 6] = PEER_HAND_POINTS as u8 + 1;
        assert!(matches!(
            decode_peers(&bad),
            Err(WireError::Value {
                field: "peer hand points",
                ..
            })
        ));
        let mut bad = b.clone();
        bad[13] = 1;
        assert_eq!(decode_peers(&bad), Err(WireError::Reserved));
        // More hands than a message holds, or points than a hand holds, are left out.
        let many: Vec<[f32; 3]> = vec![[0.0; 3]; PEER_HAND_POINTS + 4];
        let lots = [(1u32, 0u16, &many[..]); MAX_PEER_HANDS + 2];
        encode_peers(lots.iter().copied(), &mut b);
        let back = decode_peers(&b).unwrap();
        assert_eq!(back.len(), MAX_PEER_HANDS);
        assert!(back.iter().all(|h| h.points.len() == PEER_HAND_POINTS));
        assert_eq!(decode_world(&b).unwrap_err().kind(), "kind");
    }

    #[test]
    fn a_world_message_is_sized_by_its_header() {
        let mut b = Vec::new();
        let mut blocks = [common::BlockState {
            pose: common::Pose {
                position: [1.0, 2.0, 3.0],
                rotation: [0.0, 0.0, 0.0, 1.0],
            },
            mode: 4,
            held_by: 0,
        }; 2];
        blocks[1].mode = common::BlockMode::Grasped as u32;
        blocks[1].held_by = 0b10;
        let mut header = common::WorldHeader {
            block_count: 2,
            grasped_block: 1,
            finger_count: 1,
            ..Default::default()
        };
        header.finger_point_count[0] = 3;
        let world = WorldView {
            header: &header,
            blocks: &blocks,
        };
        encode_world(7, 1.25, &world, &mut b);
        assert_eq!(
            b.len(),
            WORLD_HEADER_BYTES + 2 * WORLD_BLOCK_BYTES + 3 * WORLD_POINT_BYTES
        );
        assert_eq!(kind_of(&b), Ok(KIND_WORLD));
        assert_eq!(u32_at(&b, 8), 7);
        assert_eq!(u32_at(&b, 12), 2);
        assert_eq!(f64_at(&b, 16), 1.25);
        // Each block's mode and holders after its pose: the second held by the left hand.
        let block = |i: usize, at: usize| WORLD_HEADER_BYTES + i * WORLD_BLOCK_BYTES + at;
        assert_eq!(
            f32::from_le_bytes(b[block(0, 0)..block(0, 4)].try_into().unwrap()),
            1.0
        );
        assert_eq!(b[block(0, 28)..block(0, 32)], [4, 0, 0, 0]);
        let grasped = common::BlockMode::Grasped as u8;
        assert_eq!(b[block(1, 28)..block(1, 32)], [grasped, 0, 2, 0]);
        let cap = b.capacity();
        encode_world(8, 1.5, &world, &mut b);
        assert_eq!(b.capacity(), cap, "a kept buffer is not grown again");
        let back = decode_world(&b).unwrap();
        assert_eq!((back.page_seq, back.time_s, back.grasped), (8, 1.5, 1));
        assert_eq!(back.blocks.len(), 2);
        assert_eq!(back.blocks[1].position, [1.0, 2.0, 3.0]);
        assert_eq!(back.blocks[1].rotation, [0.0, 0.0, 0.0, 1.0]);
        assert_eq!(
            (back.blocks[1].mode, back.blocks[1].held_by),
            (grasped.into(), 2)
        );
        assert_eq!(back.finger_points.len(), 3);
        b.pop();
        assert_eq!(decode_world(&b).unwrap_err().kind(), "length");
        b[12..16].copy_from_slice(&u32::MAX.to_le_bytes());
        assert_eq!(decode_world(&b).unwrap_err().kind(), "length");
    }

    fn scene() -> Scene {
        Scene {
            blocks: vec![SceneBlock {
                color: [0.8f32, 0.2, 0.1].map(f64::from),
                indices: vec![0, 1, 2],
                name: "cube".into(),
                vertices: vec![0.0, 0.5, -0.25, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0],
            }],
            floor_y: 0.0,
            hand: Hands::Both,
            offset: [0.0, -0.92, 0.0],
            op: SceneOp::Scene,
            session: "config/sessions/webxr.toml".into(),
            step_hz: 120.0,
        }
    }

    #[test]
    fn the_text_messages_go_out_as_the_first_server_wrote_them_and_read_back() {
        // The scene was a `json!` value (keys sorted; its f32 colours as f64), `ready` a
        // `format!` (op first).
        let s = scene();
        let colour: [f32; 3] = [0.8, 0.2, 0.1];
        let was = serde_json::json!({
            "op": "scene",
            "session": s.session,
            "hand": "both",
            "floor_y": 0.0,
            "step_hz": s.step_hz,
            "offset": s.offset,
            "blocks": [{
                "name": "cube",
                "color": colour,
                "vertices": s.blocks[0].vertices,
                "indices": s.blocks[0].indices,
            }],
        })
        .to_string();
        assert_eq!(s.encode(), was);
        let r = Ready::new(4000.125, 1.5);
        assert_eq!(
            r.encode(),
            r#"{"op":"ready","offset_ms":4000.125,"round_trip_ms":1.5}"#
        );
        assert_eq!(decode_text(&s.encode()).unwrap(), Text::Scene(s));
        assert_eq!(decode_text(&r.encode()).unwrap(), Text::Ready(r));
        assert!(matches!(
            decode_text(r#"{"op":"error","message":"x"}"#),
            Err(TextError::Op(op)) if op == "error"
        ));
        assert!(matches!(
            decode_text(r#"{"op":"ready"}"#),
            Err(TextError::Json(_))
        ));
        assert!(matches!(decode_text("[]"), Err(TextError::Json(_))));
    }
}
