//! The WebXR page's hand frames on the wire (issue 31): what a headset's browser sends each XR
//! frame, and the one mapping of its joints to the joints the pipeline takes.
//!
//! **Why binary, and this layout.** A frame goes out 60 to 90 times a second from a headset's
//! JavaScript, which reads each joint with `XRFrame.getJointPose` (its position, orientation
//! and radius as the runtime gives them, with no matrix in between) into a typed array: a
//! little-endian frame of fixed-size parts is a `DataView` write away there and a
//! bounds-checked read here, with nothing to parse. Every length is implied by the header, so
//! a message is either exactly right or refused.
//!
//! ```text
//! offset  size  field
//!      0     4  magic "HBX1" (the format's version is its last byte)
//!      4     1  kind: 1 = hands
//!      5     1  hands present: bit 0 left, bit 1 right (0: no hand tracked this frame)
//!      6     2  reserved, 0
//!      8     4  seq (u32): the page's frame counter, +1 per frame sent
//!     12     4  reserved, 0
//!     16     8  frame time (f64, ms): XRFrame.predictedDisplayTime, the page's clock
//!     24   800  per hand present, left first: 25 joints of 8 f32 each, in WebXR's order
//!               (wrist, thumb-metacarpal ... pinky-finger-tip): position x y z (m),
//!               orientation x y z w (unit quaternion), radius (m); reference space
//!               `local-floor` (y up, metres), which is handblocks' own convention
//! ```
//!
//! **What is refused**, each with a named [`WireError`] (the socket is outside input): a wrong
//! length, magic, kind or reserved field; a hand mask beyond the two hands; a joint that
//! fails the check every source of joints makes ([`common::Pose::joint_fault`]: a non-finite
//! number, a position farther than [`MAX_POSITION_M`] from the origin, an orientation that is
//! no rotation; within it, an orientation is passed on as sent, each f32 exactly, as a CARL
//! trace's are, and the hand model normalises what it uses); a radius outside 0 to
//! [`MAX_RADIUS_M`]. Order, replays and floods are the session's to judge (by `seq` and time),
//! not the decoder's.
//!
//! **The other messages** of the page's socket share the first eight bytes (magic, kind, three
//! zero bytes) and a u32 at 8; each has a fixed length ([`page`]): the page's frame statistics
//! (kind 2) and its answer to a clock ping (kind 4) come in; the world (kind 3) and the ping
//! (kind 5) go out. Two go out as text (JSON, [`page::Text`]): the scene, first, and `ready`
//! once the page's clock is known. [`page`] declares them all; the page's script
//! (services/webxr/page/app.js) is checked against it by tests/webxr_browser.rs, which passes
//! every message through the page's own decoders and encoders in Chromium. The emulated
//! headset's playback file, WebXR's joints again, is [`playback`].
//!
//! **Joints.** WebXR's hand has 25 joints; OpenXR's (`XR_EXT_hand_tracking`, which CARL traces
//! and the `joints` topic carry) has the same 25 after a `palm` joint. [`to_joints`] derives the
//! palm as OpenXR defines it: at the middle of the middle finger's metacarpal (halfway from its
//! metacarpal joint to its proximal phalanx joint), oriented as that metacarpal. From there the
//! hand takes the very path a CARL replay does (kinematics' joints model). [`from_joints`] is
//! its inverse, for what plays a recorded hand as a headset's (the emulated headset, tests).

use common::samples::{JointFault, JointsSample, Pose, OPENXR_JOINTS};

/// The message's first four bytes.
pub const MAGIC: [u8; 4] = *b"HBX1";
/// `kind` of a hands frame.
pub const KIND_HANDS: u8 = 1;
/// WebXR's joints per hand.
pub const WEBXR_JOINTS: usize = 25;
/// f32 values per joint: position (3), orientation (4), radius (1).
pub const VALUES_PER_JOINT: usize = 8;
/// Bytes before the hands.
pub const HEADER_BYTES: usize = 24;
/// Bytes of one hand.
pub const HAND_BYTES: usize = WEBXR_JOINTS * VALUES_PER_JOINT * 4;
/// The longest message: both hands.
pub const MAX_MESSAGE_BYTES: usize = HEADER_BYTES + 2 * HAND_BYTES;
/// The farthest a joint may be from the origin, metres: the bound every source of joints
/// holds to.
pub use common::samples::MAX_JOINT_DISTANCE_M as MAX_POSITION_M;
/// The largest joint radius, metres (a joint is a centimetre or two).
pub const MAX_RADIUS_M: f32 = 0.1;

/// WebXR's joint indices the palm is derived from.
const MIDDLE_METACARPAL: usize = 10;
const MIDDLE_PROXIMAL: usize = 11;

/// Which hand.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Handedness {
    Left = 0,
    Right = 1,
}

/// One hand's joints as decoded: poses in metres (y up), radii in metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HandJoints {
    pub poses: [Pose; WEBXR_JOINTS],
    pub radii: [f64; WEBXR_JOINTS],
}

impl Default for HandJoints {
    fn default() -> Self {
        HandJoints {
            poses: [Pose::IDENTITY; WEBXR_JOINTS],
            radii: [0.0; WEBXR_JOINTS],
        }
    }
}

/// A decoded hands frame. Decoding writes into one kept across messages: nothing is allocated.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct HandsFrame {
    pub seq: u32,
    /// `XRFrame.predictedDisplayTime`, milliseconds on the page's clock.
    pub frame_time_ms: f64,
    /// Which hands this frame holds (`hands[Handedness as usize]`).
    pub present: [bool; 2],
    pub hands: [HandJoints; 2],
}

impl HandsFrame {
    /// The hand `which`, when this frame holds it.
    pub fn hand(&self, which: Handedness) -> Option<&HandJoints> {
        self.present[which as usize].then(|| &self.hands[which as usize])
    }
}

/// Why a message was refused.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum WireError {
    /// Not `HBX1`: not this format, or another version of it.
    Magic([u8; 4]),
    /// A kind this format does not define.
    Kind(u8),
    /// A reserved field is not 0.
    Reserved,
    /// The hand mask has bits beyond the two hands.
    Hands(u8),
    /// The length the header implies is not the message's.
    Length { expected: usize, got: usize },
    /// The frame time is not a finite, non-negative number.
    FrameTime(f64),
    /// A field of a statistics or clock message is not a finite number in its range.
    Value { field: &'static str, value: f64 },
    /// A joint value is NaN or infinite.
    NonFinite { hand: Handedness, joint: usize },
    /// A joint farther than [`MAX_POSITION_M`] from the origin.
    Position {
        hand: Handedness,
        joint: usize,
        metres: f64,
    },
    /// An orientation whose norm is far from 1: no rotation.
    Orientation {
        hand: Handedness,
        joint: usize,
        norm: f64,
    },
    /// A radius outside 0 to [`MAX_RADIUS_M`].
    Radius {
        hand: Handedness,
        joint: usize,
        metres: f32,
    },
}

impl WireError {
    /// A short name for counting refusals by kind in a report.
    pub fn kind(&self) -> &'static str {
        match self {
            WireError::Magic(_) => "magic",
            WireError::Kind(_) => "kind",
            WireError::Reserved => "reserved",
            WireError::Hands(_) => "hands",
            WireError::Length { .. } => "length",
            WireError::FrameTime(_) => "frame_time",
            WireError::Value { .. } => "value",
            WireError::NonFinite { .. } => "non_finite",
            WireError::Position { .. } => "position",
            WireError::Orientation { .. } => "orientation",
            WireError::Radius { .. } => "radius",
        }
    }
}

impl std::fmt::Display for WireError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            WireError::Magic(m) => write!(f, "not a hands frame of this format (magic {m:02x?})"),
            WireError::Kind(k) => write!(f, "unknown message kind {k}"),
            WireError::Reserved => f.write_str("a reserved field is not 0"),
            WireError::Hands(m) => write!(f, "hand mask {m:#04x}: allowed 0 (none), 1 (left), 2 (right), 3"),
            WireError::Length { expected, got } => {
                write!(f, "{got} bytes where the header implies {expected}")
            }
            WireError::FrameTime(t) => write!(f, "frame time {t} ms is not a finite time"),
            WireError::Value { field, value } => write!(f, "{field} = {value} is out of range"),
            WireError::NonFinite { hand, joint } => {
                write!(f, "{hand:?} hand, joint {joint}: not a finite number")
            }
            WireError::Position {
                hand,
                joint,
                metres,
            } => write!(
                f,
                "{hand:?} hand, joint {joint}: {metres} m from the origin (at most {MAX_POSITION_M})"
            ),
            WireError::Orientation { hand, joint, norm } => write!(
                f,
                "{hand:?} hand, joint {joint}: orientation of norm {norm} is no rotation"
            ),
            WireError::Radius {
                hand,
                joint,
                metres,
            } => write!(
                f,
                "{hand:?} hand, joint {joint}: radius {metres} m (allowed 0 to {MAX_RADIUS_M})"
            ),
        }
    }
}

impl std::error::Error for WireError {}

fn f32_at(bytes: &[u8], at: usize) -> f32 {
    let mut b = [0u8; 4];
    b.copy_from_slice(&bytes[at..at + 4]);
    f32::from_le_bytes(b)
}

pub mod page;
pub mod playback;

/// Decodes `bytes` into `out` (left as it was when refused). Allocates nothing.
pub fn decode_into(bytes: &[u8], out: &mut HandsFrame) -> Result<(), WireError> {
    if bytes.len() < HEADER_BYTES {
        return Err(WireError::Length {
            expected: HEADER_BYTES,
            got: bytes.len(),
        });
    }
    let magic = [bytes[0], bytes[1], bytes[2], bytes[3]];
    if magic != MAGIC {
        return Err(WireError::Magic(magic));
    }
    if bytes[4] != KIND_HANDS {
        return Err(WireError::Kind(bytes[4]));
    }
    let mask = bytes[5];
    if mask > 3 {
        return Err(WireError::Hands(mask));
    }
    if bytes[6..8] != [0, 0] || bytes[12..16] != [0, 0, 0, 0] {
        return Err(WireError::Reserved);
    }
    let expected = HEADER_BYTES + HAND_BYTES * mask.count_ones() as usize;
    if bytes.len() != expected {
        return Err(WireError::Length {
            expected,
            got: bytes.len(),
        });
    }
    let seq = u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]);
    let mut t = [0u8; 8];
    t.copy_from_slice(&bytes[16..24]);
    let frame_time_ms = f64::from_le_bytes(t);
    if !(frame_time_ms.is_finite() && frame_time_ms >= 0.0) {
        return Err(WireError::FrameTime(frame_time_ms));
    }
    // Check everything first, then write: a refused message leaves `out` as it was.
    let mut at = HEADER_BYTES;
    let mut decoded = [HandJoints::default(); 2];
    let mut present = [false; 2];
    for hand in [Handedness::Left, Handedness::Right] {
        if mask & (1 << hand as u8) == 0 {
            continue;
        }
        present[hand as usize] = true;
        let joints = &mut decoded[hand as usize];
        for joint in 0..WEBXR_JOINTS {
            let v: [f32; VALUES_PER_JOINT] = std::array::from_fn(|k| f32_at(bytes, at + 4 * k));
            at += 4 * VALUES_PER_JOINT;
            let pose = Pose {
                position: [v[0], v[1], v[2]].map(f64::from),
                rotation: [v[3], v[4], v[5], v[6]].map(f64::from),
            };
            match pose.joint_fault() {
                None => {}
                Some(JointFault::NonFinite) => return Err(WireError::NonFinite { hand, joint }),
                Some(JointFault::TooFar { metres }) => {
                    return Err(WireError::Position {
                        hand,
                        joint,
                        metres,
                    })
                }
                Some(JointFault::NoRotation { norm }) => {
                    return Err(WireError::Orientation { hand, joint, norm })
                }
            }
            if !v[7].is_finite() {
                return Err(WireError::NonFinite { hand, joint });
            }
            if !(0.0..=MAX_RADIUS_M).contains(&v[7]) {
                return Err(WireError::Radius {
                    hand,
                    joint,
                    metres: v[7],
                });
            }
            joints.poses[joint] = pose;
            joints.radii[joint] = f64::from(v[7]);
        }
    }
    *out = HandsFrame {
        seq,
        frame_time_ms,
        present,
        hands: decoded,
    };
    Ok(())
}

/// Encodes `frame` as the page does (for tests, and the emulated headset's checks): the hands
/// `present` names, into `out` (cleared first).
pub fn encode(frame: &HandsFrame, out: &mut Vec<u8>) {
    out.clear();
    out.extend_from_slice(&MAGIC);
    out.push(KIND_HANDS);
    out.push(u8::from(frame.present[0]) | (u8::from(frame.present[1]) << 1));
    out.extend_from_slice(&[0, 0]);
    out.extend_from_slice(&frame.seq.to_le_bytes());
    out.extend_from_slice(&[0, 0, 0, 0]);
    out.extend_from_slice(&frame.frame_time_ms.to_le_bytes());
    for h in 0..2 {
        if !frame.present[h] {
            continue;
        }
        let hand = &frame.hands[h];
        for j in 0..WEBXR_JOINTS {
            let p = &hand.poses[j];
            let values = [
                p.position[0],
                p.position[1],
                p.position[2],
                p.rotation[0],
                p.rotation[1],
                p.rotation[2],
                p.rotation[3],
                hand.radii[j],
            ];
            for v in values {
                out.extend_from_slice(&(v as f32).to_le_bytes());
            }
        }
    }
}

/// A WebXR hand as the `joints` topic carries it (OpenXR's 26 joints, the palm derived, the
/// wrist also as `wrist`), tracked; the stamp is the caller's.
pub fn to_joints(hand: &HandJoints, out: &mut JointsSample) {
    const _: () = assert!(OPENXR_JOINTS == WEBXR_JOINTS + 1);
    let meta = hand.poses[MIDDLE_METACARPAL];
    let proximal = hand.poses[MIDDLE_PROXIMAL];
    let palm = Pose {
        position: std::array::from_fn(|k| (meta.position[k] + proximal.position[k]) / 2.0),
        rotation: meta.rotation,
    };
    out.joints[0] = palm;
    out.joints[1..].copy_from_slice(&hand.poses);
    out.wrist = hand.poses[0];
    out.tracked = 1;
}

/// The inverse of [`to_joints`]: a `joints` sample's hand as WebXR's 25 joints, the sample's
/// `wrist` first, then OpenXR's joints after its palm and wrist (the palm is derived, so it is
/// dropped). The wrist comes from `wrist`, not from OpenXR's wrist joint, because CARL's traces
/// hold identity poses in their palm and wrist joints and the wrist's pose beside them.
pub fn from_joints(joints: &JointsSample) -> [Pose; WEBXR_JOINTS] {
    std::array::from_fn(|k| match k {
        0 => joints.wrist,
        _ => joints.joints[k + 1],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame() -> HandsFrame {
        let mut f = HandsFrame {
            seq: 7,
            frame_time_ms: 1234.5,
            present: [false, true],
            ..Default::default()
        };
        for j in 0..WEBXR_JOINTS {
            f.hands[1].poses[j].position = [0.01 * j as f64, 1.0, -0.3];
            f.hands[1].radii[j] = 0.01;
        }
        f
    }

    #[test]
    fn a_frame_round_trips_and_its_length_is_implied_by_its_header() {
        let mut bytes = Vec::new();
        encode(&frame(), &mut bytes);
        assert_eq!(bytes.len(), HEADER_BYTES + HAND_BYTES);
        let mut back = HandsFrame::default();
        decode_into(&bytes, &mut back).unwrap();
        assert_eq!(back.seq, 7);
        assert_eq!(back.frame_time_ms, 1234.5);
        assert!(back.hand(Handedness::Left).is_none());
        let right = back.hand(Handedness::Right).unwrap();
        for j in 0..WEBXR_JOINTS {
            let want = frame().hands[1].poses[j].position;
            for (got, want) in right.poses[j].position.iter().zip(want) {
                assert!((got - want).abs() < 1e-6);
            }
        }
        let mut long = bytes.clone();
        long.push(0);
        assert_eq!(
            decode_into(&long, &mut back),
            Err(WireError::Length {
                expected: bytes.len(),
                got: bytes.len() + 1
            })
        );
    }

    #[test]
    fn each_kind_of_bad_message_is_refused_by_name_and_leaves_the_last_frame() {
        let mut good = Vec::new();
        encode(&frame(), &mut good);
        let mut out = HandsFrame::default();
        decode_into(&good, &mut out).unwrap();
        let kept = out;
        let joint_value = |j: usize, k: usize| HEADER_BYTES + (j * VALUES_PER_JOINT + k) * 4;
        type Spoil = Box<dyn Fn(&mut Vec<u8>)>;
        let cases: Vec<(Spoil, &str)> = vec![
            (Box::new(|b| b[0] = b'X'), "magic"),
            (Box::new(|b| b[4] = 9), "kind"),
            (Box::new(|b| b[5] = 0), "length"),
            (Box::new(|b| b[5] = 4), "hands"),
            (Box::new(|b| b[5] = 3), "length"),
            (Box::new(|b| b[6] = 1), "reserved"),
            (Box::new(|b| b.truncate(10)), "length"),
            (
                Box::new(|b| b[16..24].copy_from_slice(&f64::NAN.to_le_bytes())),
                "frame_time",
            ),
            (
                Box::new(move |b| {
                    b[joint_value(3, 1)..][..4].copy_from_slice(&f32::NAN.to_le_bytes())
                }),
                "non_finite",
            ),
            (
                Box::new(move |b| {
                    b[joint_value(3, 0)..][..4].copy_from_slice(&1e6f32.to_le_bytes())
                }),
                "position",
            ),
            (
                Box::new(move |b| {
                    b[joint_value(3, 6)..][..4].copy_from_slice(&0.0f32.to_le_bytes())
                }),
                "orientation",
            ),
            (
                Box::new(move |b| {
                    b[joint_value(3, 7)..][..4].copy_from_slice(&(-0.01f32).to_le_bytes())
                }),
                "radius",
            ),
        ];
        for (spoil, kind) in cases {
            let mut bad = good.clone();
            spoil(&mut bad);
            let e = decode_into(&bad, &mut out).unwrap_err();
            assert_eq!(e.kind(), kind, "{e}");
            assert_eq!(out, kept, "{kind}: the last good frame is kept");
        }
    }

    #[test]
    fn the_palm_is_midway_along_the_middle_metacarpal_and_the_rest_follow_in_order() {
        let f = frame();
        let mut j = JointsSample::default();
        to_joints(&f.hands[1], &mut j);
        let meta = f.hands[1].poses[MIDDLE_METACARPAL].position;
        let prox = f.hands[1].poses[MIDDLE_PROXIMAL].position;
        assert_eq!(j.joints[0].position[0], (meta[0] + prox[0]) / 2.0);
        assert_eq!(
            j.joints[1], f.hands[1].poses[0],
            "OpenXR's wrist is WebXR's first"
        );
        assert_eq!(j.joints[25], f.hands[1].poses[24], "the pinky tip last");
        assert_eq!(j.wrist, f.hands[1].poses[0]);
        assert_eq!(j.tracked, 1);
    }

    #[test]
    fn from_joints_undoes_to_joints_and_to_joints_undoes_it_on_a_sample_it_made() {
        let mut hand = frame().hands[1];
        for (j, p) in hand.poses.iter_mut().enumerate() {
            let a = 0.05 * j as f64;
            p.rotation = [a.sin(), 0.0, 0.0, a.cos()];
        }
        let mut joints = JointsSample::default();
        to_joints(&hand, &mut joints);
        assert_eq!(from_joints(&joints), hand.poses);
        let mut again = JointsSample::default();
        to_joints(
            &HandJoints {
                poses: from_joints(&joints),
                radii: hand.radii,
            },
            &mut again,
        );
        assert_eq!(again, joints);
        // A CARL sample: the wrist beside an identity wrist joint; the page's first is it.
        joints.joints[1] = Pose::IDENTITY;
        assert_eq!(from_joints(&joints)[0], hand.poses[0]);
    }

    proptest::proptest! {
        /// Any bytes: refused or decoded, never a panic; a decoded frame is finite and in range.
        #[test]
        fn any_bytes_decode_or_are_refused(bytes in proptest::collection::vec(proptest::num::u8::ANY, 0..1700)) {
            let mut out = HandsFrame::default();
            if decode_into(&bytes, &mut out).is_ok() {
                for h in out.hands.iter() {
                    for p in h.poses.iter() {
                        proptest::prop_assert!(p.is_finite());
                    }
                }
            }
        }
    }
}
