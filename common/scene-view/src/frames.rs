//! The hand as a tree of coordinate frames: a `foxglove.FrameTransforms` on [`TF_CHANNEL`],
//! so that Foxglove's 3D panel shows the wrist's and every joint's axes (and any panel can
//! follow one of them), beside `/scene`'s drawing.
//!
//! **The tree.** `world` (the z-up frame every `/scene` entity is in, [`crate::FRAME_ID`]) ->
//! the hand's root frame at the wrist ([`crate::HAND_ID`] `hand`, or [`crate::LEFT_HAND_ID`]
//! `hand-left` for a two-hand session's left hand) -> each finger's check points, knuckle to
//! tip, each the child of the one before: the kinematics' joint chain (`hand` samples'
//! `finger_points`). A joint's frame is named `ROOT/FINGER_JOINT`: the thumb's three points
//! `thumb_mcp`, `thumb_ip`, `thumb_tip`; a finger's four `index_mcp`, `index_pip`, `index_dip`,
//! `index_tip` (then `middle`, `ring`, `little`); a finger of another number of points (a
//! scene's bare `fingers`) numbers them from 0 (`index_0`, ...).
//!
//! **Orientation.** The wrist frame is the hand sample's wrist pose (fingers along its -z, the
//! back of the hand +y, as the kinematics and OpenXR have it). A joint's frame turns the
//! wrist's frame by the shortest arc that brings its -z onto the bone that starts at the joint
//! (a tip takes its last bone's; a bone of no length its parent's), so its -z points along
//! the finger, as OpenXR's joint poses do. Only the root is converted to z-up
//! ([`crate::z_up`]): the transforms below it are relative to their parents, which the change
//! of frame leaves as they are.
//!
//! **Cost.** The message is laid out once per hand shape (its fingers and their point counts)
//! and then rewritten in place: after the first hand nothing is allocated.

use std::fmt::Write as _;

use common::samples::{HandSample, MAX_FINGERS};
use foxglove::schemas::{FrameTransform, FrameTransforms, Quaternion, Timestamp, Vector3};
use foxglove::Encode as _;
use glam::{DQuat, DVec3};

use crate::{z_up, z_up_rotation, FRAME_ID, HAND_ID, LEFT_HAND_ID};

/// The channel (topic) of the hand's frames, live and recorded.
pub const TF_CHANNEL: &str = "/tf";

/// The fingers' names, in the kinematics' order (`HandSample::finger_points`).
pub const FINGER_NAMES: [&str; MAX_FINGERS] = ["thumb", "index", "middle", "ring", "little"];
/// The thumb's check points' names, when it has the kinematics' three.
pub const THUMB_JOINTS: [&str; 3] = ["mcp", "ip", "tip"];
/// A finger's check points' names, when it has the kinematics' four.
pub const FINGER_JOINTS: [&str; 4] = ["mcp", "pip", "dip", "tip"];

/// The root frame of the hand of `side` (`HandSample::side`: 1 the left, else the right).
pub fn hand_frame(side: usize) -> &'static str {
    if side == 1 {
        LEFT_HAND_ID
    } else {
        HAND_ID
    }
}

/// The frame of point `k` of finger `f` of a chain of `n` points, under the hand frame `root`.
pub fn joint_frame(root: &str, f: usize, k: usize, n: usize) -> String {
    let finger = FINGER_NAMES.get(f).copied().unwrap_or("finger");
    let named = match (f, n) {
        (0, 3) => THUMB_JOINTS.get(k),
        (1.., 4) => FINGER_JOINTS.get(k),
        _ => None,
    };
    let mut id = String::with_capacity(root.len() + finger.len() + 6);
    id.push_str(root);
    id.push('/');
    id.push_str(finger);
    id.push('_');
    match named {
        Some(j) => id.push_str(j),
        None => {
            let _ = write!(id, "{k}");
        }
    }
    id
}

/// The points each finger of `hand` has (0 past `finger_count`): the shape its transforms
/// are laid out for.
fn shape(hand: &HandSample) -> [usize; MAX_FINGERS] {
    let fingers = (hand.finger_count as usize).min(MAX_FINGERS);
    std::array::from_fn(|f| if f < fingers { hand.finger(f).len() } else { 0 })
}

/// A unit quaternion of `q`, or the identity when it carries no orientation (zero, or not
/// finite: a sample from outside may hold anything).
fn unit(q: [f64; 4]) -> DQuat {
    let q = DQuat::from_array(q);
    if q.is_finite() && q.length() > 0.5 {
        q.normalize()
    } else {
        DQuat::IDENTITY
    }
}

fn transform(parent: &str, child: String) -> FrameTransform {
    FrameTransform {
        timestamp: None,
        parent_frame_id: parent.into(),
        child_frame_id: child,
        translation: Some(Vector3::default()),
        rotation: Some(Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }),
    }
}

fn set(t: &mut FrameTransform, position: [f64; 3], rotation: [f64; 4]) {
    let [x, y, z] = position;
    t.translation = Some(Vector3 { x, y, z });
    let [x, y, z, w] = rotation;
    t.rotation = Some(Quaternion { x, y, z, w });
}

/// The hands' frames as one `FrameTransforms`: the right hand's (or a one-hand session's
/// only hand's) transforms first, then the left's once there is one.
#[derive(Default)]
pub struct HandFrames {
    message: FrameTransforms,
    /// Per side (0 the right, 1 the left): the shape its transforms were laid out for, None
    /// before its first hand.
    shapes: [Option<[usize; MAX_FINGERS]>; 2],
    /// Per side: its newest hand, to fill its transforms again when the message is laid out
    /// anew for the other side's.
    hands: [Option<HandSample>; 2],
}

impl HandFrames {
    /// The message as it stands: empty before the first hand.
    pub fn message(&self) -> &FrameTransforms {
        &self.message
    }

    /// True before the first hand: there is nothing to send.
    pub fn is_empty(&self) -> bool {
        self.message.transforms.is_empty()
    }

    /// Transforms of side `side` and where they start in the message.
    fn range(&self, side: usize) -> (usize, usize) {
        let len = |s: &Option<[usize; MAX_FINGERS]>| s.map_or(0, |s| 1 + s.iter().sum::<usize>());
        let start = if side == 1 { len(&self.shapes[0]) } else { 0 };
        (start, len(&self.shapes[side]))
    }

    /// Lays the message out again for the shapes now known (names allocated here only).
    fn lay_out(&mut self) {
        self.message.transforms.clear();
        for side in 0..2 {
            let Some(shape) = self.shapes[side] else {
                continue;
            };
            let root = hand_frame(side);
            self.message
                .transforms
                .push(transform(FRAME_ID, root.to_string()));
            for (f, &n) in shape.iter().enumerate() {
                for k in 0..n {
                    let parent = if k == 0 {
                        root.to_string()
                    } else {
                        joint_frame(root, f, k - 1, n)
                    };
                    self.message
                        .transforms
                        .push(transform(&parent, joint_frame(root, f, k, n)));
                }
            }
        }
    }

    /// The transforms of `hand` (its side's), rewritten in place.
    pub fn set_hand(&mut self, hand: &HandSample) {
        let side = usize::from(hand.side == 1);
        self.hands[side] = Some(*hand);
        let shape = shape(hand);
        if self.shapes[side] != Some(shape) {
            self.shapes[side] = Some(shape);
            self.lay_out();
            // The other side's transforms were laid out anew too.
            if let Some(other) = self.hands[1 - side] {
                self.fill(1 - side, &other);
            }
        }
        self.fill(side, hand);
    }

    /// Side `side`'s transforms from `hand`.
    fn fill(&mut self, side: usize, hand: &HandSample) {
        let Some(shape) = self.shapes[side] else {
            return;
        };
        let (start, len) = self.range(side);
        let Some(out) = self.message.transforms.get_mut(start..start + len) else {
            return;
        };
        let wrist = DVec3::from_array(hand.wrist.position);
        let wrist_rotation = unit(hand.wrist.rotation);
        set(
            &mut out[0],
            z_up(wrist.to_array()),
            z_up_rotation(wrist_rotation.to_array()),
        );
        let mut at = 1;
        for (f, &n) in shape.iter().enumerate() {
            let points = hand.finger(f);
            // The parent's pose in the world (y-up): the wrist, then each joint in turn.
            let (mut parent_at, mut parent_rotation) = (wrist, wrist_rotation);
            for k in 0..n {
                let p = DVec3::from_array(points[k]);
                // The bone that starts here; a tip takes the bone that ends at it.
                let bone = match (points.get(k + 1), k.checked_sub(1)) {
                    (Some(next), _) => DVec3::from_array(*next) - p,
                    (None, Some(before)) => p - DVec3::from_array(points[before]),
                    (None, None) => DVec3::ZERO,
                };
                let rotation = match (wrist_rotation.inverse() * bone).try_normalize() {
                    Some(along) => {
                        (wrist_rotation * DQuat::from_rotation_arc(DVec3::NEG_Z, along)).normalize()
                    }
                    None => parent_rotation,
                };
                let inverse = parent_rotation.inverse();
                set(
                    &mut out[at],
                    (inverse * (p - parent_at)).to_array(),
                    (inverse * rotation).normalize().to_array(),
                );
                (parent_at, parent_rotation) = (p, rotation);
                at += 1;
            }
        }
    }

    /// Stamps every transform with `unix_ns` (nanoseconds since the Unix epoch: the log time
    /// of the message that carries them, so the 3D panel looks them up at the time of the
    /// scene beside them).
    pub fn stamp(&mut self, unix_ns: u64) {
        let timestamp = u32::try_from(unix_ns / 1_000_000_000)
            .ok()
            .and_then(|sec| Timestamp::new_checked(sec, (unix_ns % 1_000_000_000) as u32));
        for t in &mut self.message.transforms {
            t.timestamp = timestamp;
        }
    }

    /// The message, protobuf-encoded into `out` (cleared first; its capacity is kept).
    pub fn encode_into(&self, out: &mut Vec<u8>) {
        out.clear();
        // A Vec grows as needed: encoding into one cannot run out of room.
        let _ = self.message.encode(out);
    }

    /// The schema of the channel: (name, encoding, data), as an MCAP schema record wants them.
    pub fn schema() -> (String, String, Vec<u8>) {
        match FrameTransforms::get_schema() {
            Some(s) => (s.name, s.encoding, s.data.into_owned()),
            None => (
                "foxglove.FrameTransforms".into(),
                "protobuf".into(),
                Vec::new(),
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use common::samples::HandSide;

    /// A hand of the kinematics' shape: a thumb of 3 points and four fingers of 4, curled.
    fn kinematic_hand(side: HandSide, wrist: common::Pose) -> HandSample {
        let mut h = HandSample {
            wrist,
            finger_count: 5,
            side: side.code(),
            ..Default::default()
        };
        let w = DVec3::from_array(wrist.position);
        let r = DQuat::from_array(wrist.rotation);
        for f in 0..5 {
            let n = if f == 0 { 3 } else { 4 };
            h.finger_point_count[f] = n as u32;
            for k in 0..n {
                // In the hand frame: along -z, bending toward -y.
                let local = DVec3::new(
                    -0.03 + 0.015 * f as f64,
                    -0.01 * (k * k) as f64,
                    -0.09 - 0.025 * k as f64,
                );
                h.finger_points[f][k] = (w + r * local).to_array();
            }
        }
        h
    }

    /// Each frame's world pose (z-up), composed down the tree from `world`.
    fn world_poses(m: &FrameTransforms) -> Vec<(String, DVec3, DQuat)> {
        let mut out: Vec<(String, DVec3, DQuat)> = Vec::new();
        for t in &m.transforms {
            let (pp, pr) = if t.parent_frame_id == FRAME_ID {
                (DVec3::ZERO, DQuat::IDENTITY)
            } else {
                let p = out
                    .iter()
                    .find(|(id, _, _)| *id == t.parent_frame_id)
                    .expect("a parent before its child");
                (p.1, p.2)
            };
            let tr = t.translation.as_ref().expect("a translation");
            let q = t.rotation.as_ref().expect("a rotation");
            let local = DVec3::new(tr.x, tr.y, tr.z);
            let lq = DQuat::from_xyzw(q.x, q.y, q.z, q.w);
            out.push((t.child_frame_id.clone(), pp + pr * local, pr * lq));
        }
        out
    }

    /// The tree's frames land on the sample's points (z-up), every joint's -z runs along its
    /// bone, and the names follow the kinematics' chain.
    #[test]
    fn frames_compose_to_the_hands_points_z_up() {
        let wrist = common::Pose {
            position: [0.1, 0.3, -0.2],
            rotation: DQuat::from_euler(glam::EulerRot::YXZ, 0.7, -0.4, 0.2).to_array(),
        };
        let hand = kinematic_hand(HandSide::Right, wrist);
        let mut frames = HandFrames::default();
        assert!(frames.is_empty());
        frames.set_hand(&hand);
        let m = frames.message();
        assert_eq!(m.transforms.len(), 1 + 3 + 4 * 4);
        assert_eq!(m.transforms[0].parent_frame_id, "world");
        assert_eq!(m.transforms[0].child_frame_id, "hand");
        assert_eq!(m.transforms[1].parent_frame_id, "hand");
        assert_eq!(m.transforms[1].child_frame_id, "hand/thumb_mcp");
        assert_eq!(m.transforms[3].child_frame_id, "hand/thumb_tip");
        assert_eq!(m.transforms[3].parent_frame_id, "hand/thumb_ip");
        assert_eq!(m.transforms[4].child_frame_id, "hand/index_mcp");
        assert_eq!(m.transforms[4].parent_frame_id, "hand");
        assert_eq!(m.transforms[19].child_frame_id, "hand/little_tip");
        assert_eq!(m.transforms[19].parent_frame_id, "hand/little_dip");
        let poses = world_poses(m);
        let find = |id: &str| poses.iter().find(|p| p.0 == id).expect(id).clone();
        let (_, wp, wq) = find("hand");
        assert!((wp - DVec3::from_array(z_up(wrist.position))).length() < 1e-12);
        let expect = DQuat::from_array(z_up_rotation(wrist.rotation));
        assert!(wq.dot(expect).abs() > 1.0 - 1e-12);
        for f in 0..5 {
            let n = hand.finger_point_count[f] as usize;
            for k in 0..n {
                let (_, p, q) = find(&joint_frame("hand", f, k, n));
                let want = DVec3::from_array(z_up(hand.finger_points[f][k]));
                assert!((p - want).length() < 1e-12, "finger {f} point {k}");
                let at = |j: usize| DVec3::from_array(z_up(hand.finger_points[f][j]));
                // The bone that starts at the joint; the tip's, the one that ends there.
                let bone = if k + 1 < n {
                    at(k + 1) - at(k)
                } else {
                    at(k) - at(k - 1)
                };
                assert!((q * DVec3::NEG_Z - bone.normalize()).length() < 1e-9);
            }
        }
    }

    /// A left hand's frames follow the right's under `hand-left`; a new hand of the same
    /// shape rewrites the message in place; stamps reach every transform.
    #[test]
    fn the_left_hand_has_its_own_tree_after_the_right() {
        let mut frames = HandFrames::default();
        let right = kinematic_hand(HandSide::Right, common::Pose::IDENTITY);
        let left_at = common::Pose {
            position: [-0.4, 0.2, 0.0],
            ..common::Pose::IDENTITY
        };
        frames.set_hand(&kinematic_hand(HandSide::Left, left_at));
        assert_eq!(frames.message().transforms[0].child_frame_id, "hand-left");
        frames.set_hand(&right);
        let m = frames.message();
        assert_eq!(m.transforms.len(), 40);
        assert_eq!(m.transforms[0].child_frame_id, "hand");
        assert_eq!(m.transforms[20].child_frame_id, "hand-left");
        assert_eq!(m.transforms[20].parent_frame_id, "world");
        assert_eq!(m.transforms[21].child_frame_id, "hand-left/thumb_mcp");
        let x = m.transforms[20].translation.as_ref().map(|t| t.x);
        assert_eq!(x, Some(-0.4));
        let names: *const u8 = m.transforms[5].child_frame_id.as_ptr();
        frames.set_hand(&right);
        assert_eq!(
            frames.message().transforms[5].child_frame_id.as_ptr(),
            names
        );
        frames.stamp(1_700_000_000_123_456_789);
        for t in &frames.message().transforms {
            let ts = t.timestamp.expect("stamped");
            assert_eq!((ts.sec(), ts.nsec()), (1_700_000_000, 123_456_789));
        }
        let mut bytes = Vec::new();
        frames.encode_into(&mut bytes);
        assert!(!bytes.is_empty());
        assert_eq!(HandFrames::schema().0, "foxglove.FrameTransforms");
    }

    /// A bare check-point hand (other counts) numbers its points; a lost hand with no fingers
    /// is its wrist frame alone; a zero quaternion reads as the identity.
    #[test]
    fn other_shapes_are_numbered_and_a_bare_wrist_stands_alone() {
        let mut h = HandSample {
            finger_count: 2,
            wrist: common::Pose {
                position: [0.0, 0.2, 0.0],
                rotation: [0.0; 4],
            },
            ..Default::default()
        };
        h.finger_point_count[..2].copy_from_slice(&[2, 5]);
        h.finger_points[0][..2].copy_from_slice(&[[0.0, 0.2, -0.1], [0.0, 0.2, -0.1]]);
        let mut frames = HandFrames::default();
        frames.set_hand(&h);
        let ids: Vec<&str> = frames
            .message()
            .transforms
            .iter()
            .map(|t| t.child_frame_id.as_str())
            .collect();
        assert_eq!(
            ids,
            [
                "hand",
                "hand/thumb_0",
                "hand/thumb_1",
                "hand/index_0",
                "hand/index_1",
                "hand/index_2",
                "hand/index_3",
                "hand/index_4"
            ]
        );
        for t in &frames.message().transforms {
            let q = t.rotation.as_ref().expect("a rotation");
            let v = [q.x, q.y, q.z, q.w];
            assert!(v.iter().all(|c| c.is_finite()), "{v:?}");
        }
        h.finger_count = 0;
        frames.set_hand(&h);
        assert_eq!(frames.message().transforms.len(), 1);
    }
}
