//! Another participant's hand as the host sends it to a participant (`KEY/peer/SECRET`):
//! compact, because it shares the participant's link with its worlds and its own hands. A
//! `hand` sample is about 1.2 KB, every array at full size in `f64`; this is the used part
//! only, in `f32`, about 550 bytes for a whole hand. It is drawn, never stepped (the host's
//! world holds what the hand did), so `f32` (a tenth of a micrometre at a metre) loses nothing
//! anyone sees.
//!
//! Layout (little-endian): `VERSION`, participant, side, tracked, finger count, palm vertex
//! count (one byte each); a point count per finger (one byte each); the wrist's position (3
//! `f32`) and rotation (4 `f32`); per finger its radius and its points (3 `f32` each); the
//! palm's vertices (3 `f32` each). Nothing else, nothing after.

use common::{HandSample, Pose, MAX_FINGERS, MAX_FINGER_POINTS, MAX_PALM_VERTICES};

/// The layout's version (its first byte).
pub const VERSION: u8 = 1;

/// Why bytes are not a peer hand.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum PeerWireError {
    #[error("not a version {VERSION} peer hand (first byte {0})")]
    Version(u8),
    #[error("{what} is {value}, more than a hand holds ({max})")]
    Count {
        what: &'static str,
        value: u8,
        max: usize,
    },
    #[error("{len} bytes, where its counts say {expected}")]
    Length { len: usize, expected: usize },
}

/// Writes `hand` into `out` (cleared first). Counts beyond the arrays are clamped (a hand the
/// host took was checked).
pub fn encode(hand: &HandSample, out: &mut Vec<u8>) {
    out.clear();
    let fingers = (hand.finger_count as usize).min(MAX_FINGERS);
    let palm = (hand.palm_vertex_count as usize).min(MAX_PALM_VERTICES);
    out.extend_from_slice(&[
        VERSION,
        hand.participant.min(255) as u8,
        hand.side.min(255) as u8,
        u8::from(hand.tracked != 0),
        fingers as u8,
        palm as u8,
    ]);
    for f in 0..fingers {
        out.push(hand.finger_point_count[f].min(MAX_FINGER_POINTS as u32) as u8);
    }
    let mut put = |v: f64| out.extend_from_slice(&(v as f32).to_le_bytes());
    hand.wrist.position.iter().for_each(|&v| put(v));
    hand.wrist.rotation.iter().for_each(|&v| put(v));
    for f in 0..fingers {
        put(hand.finger_radius[f]);
        for p in hand.finger(f) {
            p.iter().for_each(|&v| put(v));
        }
    }
    for v in &hand.palm_vertices[..palm] {
        v.iter().for_each(|&c| put(c));
    }
}

/// Reads a peer hand; its values still need [`HandSample::unusable_because`] (this checks the
/// counts and the length only).
pub fn decode(bytes: &[u8]) -> Result<HandSample, PeerWireError> {
    let head = bytes.get(..6).ok_or(PeerWireError::Length {
        len: bytes.len(),
        expected: 6,
    })?;
    if head[0] != VERSION {
        return Err(PeerWireError::Version(head[0]));
    }
    let (fingers, palm) = (head[4], head[5]);
    let count = |what, value: u8, max: usize| {
        if usize::from(value) > max {
            Err(PeerWireError::Count { what, value, max })
        } else {
            Ok(usize::from(value))
        }
    };
    let fingers = count("finger_count", fingers, MAX_FINGERS)?;
    let palm = count("palm_vertex_count", palm, MAX_PALM_VERTICES)?;
    let point_counts = bytes.get(6..6 + fingers).ok_or(PeerWireError::Length {
        len: bytes.len(),
        expected: 6 + fingers,
    })?;
    let mut points = [0usize; MAX_FINGERS];
    for (f, &n) in point_counts.iter().enumerate() {
        points[f] = count("finger_point_count", n, MAX_FINGER_POINTS)?;
    }
    let floats = 7 + fingers + 3 * points.iter().sum::<usize>() + 3 * palm;
    let expected = 6 + fingers + 4 * floats;
    if bytes.len() != expected {
        return Err(PeerWireError::Length {
            len: bytes.len(),
            expected,
        });
    }
    let mut at = 6 + fingers;
    let mut next = || {
        let v = f32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]]);
        at += 4;
        f64::from(v)
    };
    let mut hand = HandSample {
        participant: u32::from(head[1]),
        side: u32::from(head[2]),
        tracked: u32::from(head[3]),
        finger_count: fingers as u32,
        palm_vertex_count: palm as u32,
        wrist: Pose {
            position: [next(), next(), next()],
            rotation: [next(), next(), next(), next()],
        },
        ..HandSample::default()
    };
    for (f, &n) in points.iter().enumerate().take(fingers) {
        hand.finger_point_count[f] = n as u32;
        hand.finger_radius[f] = next();
        for p in &mut hand.finger_points[f][..n] {
            *p = [next(), next(), next()];
        }
    }
    for v in &mut hand.palm_vertices[..palm] {
        *v = [next(), next(), next()];
    }
    Ok(hand)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn whole_hand() -> HandSample {
        let mut h = HandSample {
            participant: 2,
            side: 1,
            tracked: 1,
            finger_count: MAX_FINGERS as u32,
            palm_vertex_count: MAX_PALM_VERTICES as u32,
            wrist: Pose {
                position: [0.1, 1.2, -0.3],
                rotation: [0.0, 0.0, 0.6, 0.8],
            },
            ..HandSample::default()
        };
        for f in 0..MAX_FINGERS {
            h.finger_point_count[f] = MAX_FINGER_POINTS as u32;
            h.finger_radius[f] = 0.008 + f as f64 * 0.001;
            for k in 0..MAX_FINGER_POINTS {
                h.finger_points[f][k] = [f as f64 * 0.02, 1.0 + k as f64 * 0.01, 0.25];
            }
        }
        for (i, v) in h.palm_vertices.iter_mut().enumerate() {
            *v = [i as f64 * 0.01, 1.0, -0.02];
        }
        h
    }

    #[test]
    fn a_whole_hand_goes_in_under_half_a_hand_sample_and_comes_back_to_f32() {
        let h = whole_hand();
        let mut out = Vec::new();
        encode(&h, &mut out);
        assert!(
            out.len() * 2 < std::mem::size_of::<HandSample>(),
            "{} bytes",
            out.len()
        );
        let back = decode(&out).expect("decodes");
        assert_eq!(
            (back.participant, back.side, back.tracked),
            (h.participant, h.side, 1)
        );
        assert_eq!(back.finger_point_count, h.finger_point_count);
        for f in 0..MAX_FINGERS {
            for (a, b) in back.finger(f).iter().zip(h.finger(f)) {
                for c in 0..3 {
                    assert!((a[c] - b[c]).abs() < 1e-6);
                }
            }
        }
        assert!((back.wrist.rotation[3] - 0.8).abs() < 1e-6);
        assert!(back.unusable_because().is_none());
    }

    #[test]
    fn bad_bytes_are_named_never_read_past() {
        let mut out = Vec::new();
        encode(&whole_hand(), &mut out);
        for len in 0..out.len() {
            assert!(decode(&out[..len]).is_err(), "{len} bytes decoded");
        }
        let mut longer = out.clone();
        longer.push(0);
        assert!(matches!(decode(&longer), Err(PeerWireError::Length { .. })));
        let mut wrong = out.clone();
        wrong[0] = 9;
        assert_eq!(decode(&wrong), Err(PeerWireError::Version(9)));
        let mut too_many = out.clone();
        too_many[4] = 6;
        assert!(matches!(
            decode(&too_many),
            Err(PeerWireError::Count {
                what: "finger_count",
                ..
            })
        ));
        let mut too_many_points = out;
        too_many_points[6] = 200;
        assert!(matches!(
            decode(&too_many_points),
            Err(PeerWireError::Count {
                what: "finger_point_count",
                ..
            })
        ));
    }

    #[test]
    fn nan_comes_through_to_be_refused_by_the_hand_check() {
        let mut h = whole_hand();
        h.finger_points[0][0][1] = f64::NAN;
        let mut out = Vec::new();
        encode(&h, &mut out);
        let back = decode(&out).expect("the layout is right");
        assert!(back.unusable_because().is_some());
    }
}
