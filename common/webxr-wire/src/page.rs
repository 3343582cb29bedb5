//! The page's socket besides the hands frame: what else the page sends (its frame statistics,
//! its answer to a clock ping) and what it is sent (the world, the ping). Every message starts
//! with [`MAGIC`] and a kind byte, then three zero bytes and a u32; each kind has one length.
//!
//! ```text
//! kind 2, stats (page -> us), 32 bytes: u32 seq of the hands frame reported; f64 its frame
//!         callback's JavaScript time (ms); f64 the newest round trip (ms) measured since the
//!         last stats, from a hands frame sent to the world that answers it drawn (-1: none)
//! kind 4, pong (page -> us), 32 bytes: u32 the ping's seq; f64 the ping's server time (ms,
//!         echoed); f64 the page's clock (ms, performance.now()) when the ping arrived
//! kind 5, ping (us -> page), 24 bytes: u32 seq; f64 the server's time (ms)
//! kind 3, world (us -> page), 32 + 32 blocks + 12 points bytes: u32 the hands frame's seq this
//!         world answers (u32::MAX: none of this page's); u32 blocks; f64 world time (s); i32
//!         the grasped block (-1: none; the first grasped); u32 finger points; per block 7 f32
//!         (position x y z, orientation x y z w), u16 its mode (`BlockMode`), u16 the hands
//!         that hold it (`BlockState::held_by`: bit 0 the right hand or a one-hand session's
//!         only hand, bit 1 the left; 0 when not grasped); per finger point 3 f32
//! ```
//! Statistics are bounded: a JavaScript time of 0 to 10 s, a round trip of -1 (none) or 0 to
//! 60 s; clock times finite and non-negative.

use common::{WorldView, MAX_FINGERS, MAX_FINGER_POINTS};

use crate::{WireError, MAGIC};

/// `kind` of the page's frame statistics.
pub const KIND_STATS: u8 = 2;
/// `kind` of a world state sent to the page.
pub const KIND_WORLD: u8 = 3;
/// `kind` of the page's answer to a ping.
pub const KIND_PONG: u8 = 4;
/// `kind` of a clock ping sent to the page.
pub const KIND_PING: u8 = 5;
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
    }
}
