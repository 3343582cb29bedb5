//! A simple hand model (the paper's Fig. 1(a)): fingers as chains of cylinders with check
//! points at the knuckle, the joints and the tip, and the palm as a box-like polyhedron.
//!
//! Frame of the hand (the wrist's local frame): the wrist at the origin, fingers extended along
//! -z, the palm facing -y (down), the thumb on the -x side (a right hand). Flexing a finger
//! curls it toward the palm (-y, then back toward +z). The thumb swings from beside the hand
//! (thumb rotation 0) to under the palm, opposed to the fingers (thumb rotation 1 rad), and
//! its MCP and IP joints bend it forward, toward the fingers.

use common::config::hand::{FingerSpec, HandModelSpec};
use common::glove::{angle, GloveJoint};
use common::{GloveSample, HandSample, HandSide, JointsSample, Pose, MAX_FINGERS, OPENXR_JOINTS};
use glam::{DQuat, DVec3};

/// The hand model: bone lengths, finger radii and palm shape, from a hand model file
/// (`config/hand.toml`) or the built-in adult hand.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct HandModel {
    pub spec: HandModelSpec,
}

impl HandModel {
    pub fn new(spec: HandModelSpec) -> Self {
        HandModel { spec }
    }
}

/// The direction of a finger bone after a cumulative flexion `phi` (0: straight along -z).
fn flexed(phi: f64) -> DVec3 {
    DVec3::new(0.0, -phi.sin(), -phi.cos())
}

impl HandModel {
    /// Check points of the thumb in the hand frame: MCP, IP, tip.
    fn thumb(&self, rotation: f64, mcp: f64, ip: f64) -> [DVec3; 3] {
        let open = DVec3::new(-0.8, 0.0, -0.6);
        let opposed =
            |flex: f64| DVec3::new(0.0, -(0.9 - flex).cos(), -(0.9 - flex).sin()).normalize();
        let s = rotation.clamp(0.0, 1.0);
        let dir = |flex: f64| open.lerp(opposed(flex), s).normalize_or(open);
        let base = DVec3::from_array(self.spec.thumb_base);
        let [l0, l1, l2] = self.spec.thumb_bones;
        let mcp_point = base + dir(0.0) * l0;
        let ip_point = mcp_point + dir(mcp) * l1;
        let tip = ip_point + dir(mcp + ip) * l2;
        [mcp_point, ip_point, tip]
    }

    /// Check points of finger `spec` in the hand frame: knuckle, PIP, DIP, tip.
    fn finger(spec: &FingerSpec, mcp: f64, pip: f64, dip: f64) -> [DVec3; 4] {
        let knuckle = DVec3::from_array(spec.knuckle);
        let [l0, l1, l2] = spec.bones;
        let pip_point = knuckle + flexed(mcp) * l0;
        let dip_point = pip_point + flexed(mcp + pip) * l1;
        let tip = dip_point + flexed(mcp + pip + dip) * l2;
        [knuckle, pip_point, dip_point, tip]
    }

    /// The 26 OpenXR joints (XR_EXT_hand_tracking order, world frame) of a glove reading and a
    /// wrist pose. Each joint's orientation is the bone that starts there (OpenXR: -z along the
    /// bone toward the tip, +y the back of the hand); a tip takes its distal bone's.
    pub fn glove_joints(&self, glove: &GloveSample, wrist: &Pose, out: &mut [Pose; OPENXR_JOINTS]) {
        self.glove_joints_of(HandSide::Right, glove, wrist, out);
    }

    /// [`HandModel::glove_joints`] of the hand `side`. The model is a right hand; the left is
    /// its mirror image in the wrist's x (the thumb on the wrist's +x side), so that a left
    /// wrist pose mirrored from a right one gives the mirrored hand. Each joint's orientation
    /// is mirrored too (a rotation R becomes M R M, M = diag(-1, 1, 1)): a proper rotation
    /// that keeps -z along the bone and +y on the back of the hand, as OpenXR's left hand has.
    pub fn glove_joints_of(
        &self,
        side: HandSide,
        glove: &GloveSample,
        wrist: &Pose,
        out: &mut [Pose; OPENXR_JOINTS],
    ) {
        let a = |j: GloveJoint| angle(glove, j).filter(|v| v.is_finite()).unwrap_or(0.0);
        // An 18-sensor glove has no DIP sensor: the DIP follows the PIP (about 2/3).
        let dip = |d: GloveJoint, p: GloveJoint| angle(glove, d).unwrap_or(a(p) * 2.0 / 3.0);
        let position = DVec3::from_array(wrist.position);
        let rotation = DQuat::from_array(wrist.rotation).normalize();
        let left = side == HandSide::Left;
        let pose = |p: DVec3, bone: DQuat| {
            let (p, bone) = if left {
                (
                    DVec3::new(-p.x, p.y, p.z),
                    DQuat::from_xyzw(bone.x, -bone.y, -bone.z, bone.w),
                )
            } else {
                (p, bone)
            };
            Pose {
                position: (position + rotation * p).to_array(),
                rotation: (rotation * bone).normalize().to_array(),
            }
        };
        let along = |d: DVec3| DQuat::from_rotation_arc(DVec3::NEG_Z, d.normalize());

        let knuckle_z = self
            .spec
            .fingers
            .iter()
            .map(|f| f.knuckle[2])
            .fold(0.0, f64::min);
        out[0] = pose(DVec3::new(0.0, 0.0, knuckle_z / 2.0), DQuat::IDENTITY);
        out[1] = pose(DVec3::ZERO, DQuat::IDENTITY);

        let thumb = self.thumb(
            a(GloveJoint::ThumbRotation),
            a(GloveJoint::ThumbMcp),
            a(GloveJoint::ThumbIp),
        );
        let base = DVec3::from_array(self.spec.thumb_base);
        let chain = [base, thumb[0], thumb[1], thumb[2]];
        for k in 0..4 {
            let bone = if k < 3 {
                chain[k + 1] - chain[k]
            } else {
                chain[3] - chain[2]
            };
            out[2 + k] = pose(chain[k], along(bone));
        }

        let joints = [
            (
                GloveJoint::IndexMcp,
                GloveJoint::IndexPip,
                GloveJoint::IndexDip,
            ),
            (
                GloveJoint::MiddleMcp,
                GloveJoint::MiddlePip,
                GloveJoint::MiddleDip,
            ),
            (
                GloveJoint::RingMcp,
                GloveJoint::RingPip,
                GloveJoint::RingDip,
            ),
            (
                GloveJoint::LittleMcp,
                GloveJoint::LittlePip,
                GloveJoint::LittleDip,
            ),
        ];
        for (f, (spec, (m, p, d))) in self.spec.fingers.iter().zip(joints).enumerate() {
            let first = 6 + 5 * f;
            let (mcp, pip) = (a(m), a(p));
            let dip = dip(d, p);
            let points = Self::finger(spec, mcp, pip, dip);
            // The metacarpal joint: the bone's base, near the wrist.
            let metacarpal = DVec3::new(spec.knuckle[0] * 0.5, 0.0, spec.knuckle[2] * 0.2);
            out[first] = pose(metacarpal, along(points[0] - metacarpal));
            let flex = [mcp, mcp + pip, mcp + pip + dip, mcp + pip + dip];
            for k in 0..4 {
                out[first + 1 + k] = pose(points[k], DQuat::from_rotation_x(-flex[k]));
            }
        }
    }

    /// The hand of a glove reading and a wrist pose, in the world frame: the glove's OpenXR
    /// joints ([`HandModel::glove_joints`]) made into a hand exactly as a hand tracker's are
    /// ([`HandModel::from_joints`]). `out.stamp` is left for the caller.
    pub fn solve(&self, glove: &GloveSample, wrist: &Pose, out: &mut HandSample) {
        self.solve_side(HandSide::Right, glove, wrist, out);
    }

    /// [`HandModel::solve`] of the hand `side` ([`HandModel::glove_joints_of`]), marked with
    /// it (`out.side`).
    pub fn solve_side(
        &self,
        side: HandSide,
        glove: &GloveSample,
        wrist: &Pose,
        out: &mut HandSample,
    ) {
        let mut joints = JointsSample {
            tracked: 1,
            side: side.code(),
            ..Default::default()
        };
        out.side = side.code();
        self.glove_joints_of(side, glove, wrist, &mut joints.joints);
        joints.wrist = joints.joints[1];
        if !self.from_joints(&joints, out) {
            // Only a non-finite wrist gets here: keep the previous hand, marked lost.
            out.tracked = 0;
        }
    }
}

/// OpenXR joints (XR_EXT_hand_tracking order) used as check points, knuckle to tip: the thumb's
/// proximal (MCP), distal (IP) and tip, then for each finger its proximal (the knuckle),
/// intermediate, distal and tip. Metacarpal joints lie inside the palm and are not check points.
pub const OPENXR_CHECK_POINTS: [&[usize]; 5] = [
    &[3, 4, 5],
    &[7, 8, 9, 10],
    &[12, 13, 14, 15],
    &[17, 18, 19, 20],
    &[22, 23, 24, 25],
];

impl HandModel {
    /// The hand of a hand tracker's joints, in the world frame: check points at the tracked
    /// joints, radii from the model, and the palm as a box spanning the wrist and the knuckles,
    /// oriented by the wrist pose (OpenXR's wrist frame is ours: fingers along -z, back of the
    /// hand +y). The wrist pose comes from `joints.wrist` (some trackers, e.g. the CARL
    /// recordings, leave the palm and wrist joints as identity). Returns false, leaving `out`
    /// untouched, when a pose needed is not finite.
    pub fn from_joints(&self, joints: &JointsSample, out: &mut HandSample) -> bool {
        let needed = OPENXR_CHECK_POINTS.iter().flat_map(|f| f.iter());
        if !joints.wrist.is_finite() || needed.clone().any(|&j| !joints.joints[j].is_finite()) {
            return false;
        }
        let rotation = DQuat::from_array(joints.wrist.rotation);
        // A zero (or NaN-free but degenerate) quaternion carries no orientation.
        if rotation.length() <= 0.5 {
            return false;
        }
        let rotation = rotation.normalize();
        let wrist = DVec3::from_array(joints.wrist.position);
        out.wrist = Pose {
            position: wrist.to_array(),
            rotation: rotation.to_array(),
        };
        out.tracked = joints.tracked;
        out.finger_count = MAX_FINGERS as u32;
        let radii = [
            self.spec.thumb_radius,
            self.spec.fingers[0].radius,
            self.spec.fingers[1].radius,
            self.spec.fingers[2].radius,
            self.spec.fingers[3].radius,
        ];
        for (f, indices) in OPENXR_CHECK_POINTS.iter().enumerate() {
            out.finger_point_count[f] = indices.len() as u32;
            for (slot, &j) in out.finger_points[f].iter_mut().zip(indices.iter()) {
                *slot = joints.joints[j].position;
            }
            out.finger_radius[f] = radii[f];
        }
        // The palm: from the wrist to the farthest knuckle along the hand's forward axis.
        let forward = rotation * DVec3::NEG_Z;
        let reach = [7, 12, 17, 22]
            .iter()
            .map(|&j| (DVec3::from_array(joints.joints[j].position) - wrist).dot(forward))
            .fold(0.0, f64::max);
        let (w, t) = (self.spec.palm_half_width, self.spec.palm_half_thickness);
        let mut i = 0;
        for x in [-w, w] {
            for y in [-t, t] {
                for z in [0.0, -reach] {
                    out.palm_vertices[i] = (wrist + rotation * DVec3::new(x, y, z)).to_array();
                    i += 1;
                }
            }
        }
        out.palm_vertex_count = 8;
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn glove(f: impl Fn(GloveJoint) -> f64) -> GloveSample {
        let mut g = GloveSample::default();
        for (i, j) in common::glove::SENSORS_22.iter().enumerate() {
            g.angles[i] = f(*j);
        }
        g
    }

    fn close(a: [f64; 3], b: [f64; 3]) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-12)
    }

    #[test]
    fn the_left_hand_is_the_right_mirrored_in_the_wrist_x() {
        let m = HandModel::default();
        let fist = glove(|j| match j {
            GloveJoint::ThumbRotation => 0.8,
            GloveJoint::IndexMcp | GloveJoint::MiddleMcp => 1.2,
            GloveJoint::IndexPip | GloveJoint::MiddlePip => 1.3,
            _ => 0.4,
        });
        // A right wrist turned about y and its mirror in the plane x = 0 (x negated, the turn
        // about y reversed): the left hand is the right hand mirrored, point for point.
        let turn = 0.7;
        let right_wrist = Pose {
            position: [0.2, 0.1, -0.3],
            rotation: DQuat::from_rotation_y(turn).to_array(),
        };
        let left_wrist = Pose {
            position: [-0.2, 0.1, -0.3],
            rotation: DQuat::from_rotation_y(-turn).to_array(),
        };
        let (mut r, mut l) = (HandSample::default(), HandSample::default());
        m.solve_side(HandSide::Right, &fist, &right_wrist, &mut r);
        m.solve_side(HandSide::Left, &fist, &left_wrist, &mut l);
        assert_eq!((r.side, l.side), (0, 1));
        let mirrored = |p: [f64; 3]| [-p[0], p[1], p[2]];
        for f in 0..5 {
            for (a, b) in r.finger(f).iter().zip(l.finger(f)) {
                let d = DVec3::from_array(mirrored(*a)) - DVec3::from_array(*b);
                assert!(d.length() < 1e-12, "finger {f}: {a:?} vs {b:?}");
            }
        }
        // In its own wrist frame, the left thumb is on +x.
        let mut at_origin = HandSample::default();
        m.solve_side(HandSide::Left, &fist, &Pose::IDENTITY, &mut at_origin);
        assert!(at_origin.finger(0)[2][0] > 0.0);
        // And the left joints' orientations are proper rotations that keep -z along the bone.
        let mut joints = [Pose::IDENTITY; OPENXR_JOINTS];
        m.glove_joints_of(HandSide::Left, &fist, &left_wrist, &mut joints);
        let (tip, dip) = (joints[10].position, joints[9].position);
        let along = DVec3::from_array(tip) - DVec3::from_array(dip);
        let minus_z = DQuat::from_array(joints[9].rotation) * DVec3::NEG_Z;
        assert!(along.normalize().dot(minus_z) > 1.0 - 1e-9);
    }

    #[test]
    fn flat_hand_has_straight_fingers_along_minus_z() {
        let m = HandModel::default();
        let mut h = HandSample::default();
        m.solve(&glove(|_| 0.0), &Pose::IDENTITY, &mut h);
        // Index: knuckle at (-0.028, 0, -0.09), tip 0.09 further along -z.
        assert!(close(h.finger(1)[0], [-0.028, 0.0, -0.090]));
        assert!(close(h.finger(1)[3], [-0.028, 0.0, -0.180]));
        assert_eq!(h.finger_count, 5);
        assert_eq!(h.palm().len(), 8);
    }

    #[test]
    fn a_right_angle_mcp_bend_points_the_finger_down() {
        let m = HandModel::default();
        let mut h = HandSample::default();
        m.solve(
            &glove(|j| {
                if j == GloveJoint::IndexMcp {
                    std::f64::consts::FRAC_PI_2
                } else {
                    0.0
                }
            }),
            &Pose::IDENTITY,
            &mut h,
        );
        // Every bone after the knuckle hangs straight down: the tip is 0.09 below the knuckle.
        assert!(close(h.finger(1)[3], [-0.028, -0.090, -0.090]));
        // The middle finger did not move.
        assert!(close(h.finger(2)[3], [-0.009, 0.0, -0.195]));
    }

    #[test]
    fn a_fist_curls_tips_back_under_the_palm() {
        let m = HandModel::default();
        let mut h = HandSample::default();
        m.solve(
            &glove(|j| match j {
                GloveJoint::IndexMcp => std::f64::consts::FRAC_PI_2,
                GloveJoint::IndexPip => std::f64::consts::FRAC_PI_2,
                _ => 0.0,
            }),
            &Pose::IDENTITY,
            &mut h,
        );
        // MCP 90 deg then PIP 90 deg: the middle bone points back (+z), and the DIP (0 here)
        // keeps that direction: tip = knuckle + (0,-0.045,0) + (0,0,+0.045).
        assert!(close(h.finger(1)[3], [-0.028, -0.045, -0.045]));
    }

    #[test]
    fn the_wrist_pose_moves_and_turns_the_whole_hand() {
        let m = HandModel::default();
        let mut h = HandSample::default();
        let q = DQuat::from_rotation_y(std::f64::consts::PI);
        let wrist = Pose {
            position: [1.0, 2.0, 3.0],
            rotation: q.to_array(),
        };
        m.solve(&glove(|_| 0.0), &wrist, &mut h);
        // Turned half around y, -z becomes +z and -x becomes +x.
        let tip = h.finger(1)[3];
        assert!(close(tip, [1.028, 2.0, 3.18]), "{tip:?}");
    }

    #[test]
    fn an_eighteen_sensor_glove_bends_dip_with_pip() {
        let m = HandModel::default();
        let mut g = GloveSample {
            sensor_count: 18,
            ..Default::default()
        };
        g.angles[5] = 0.9; // index PIP in the 18-sensor order
        let mut h = HandSample::default();
        m.solve(&g, &Pose::IDENTITY, &mut h);
        let f = h.finger(1);
        let last = DVec3::from_array(f[3]) - DVec3::from_array(f[2]);
        // Distal direction = flexed(0.9 + 0.6).
        assert!((last.normalize() - flexed(1.5)).length() < 1e-12);
    }

    #[test]
    fn joints_become_check_points_knuckle_to_tip_and_a_palm() {
        let m = HandModel::default();
        let mut j = JointsSample {
            tracked: 1,
            ..Default::default()
        };
        j.wrist.position = [0.0, 1.0, 0.0];
        for (k, joint) in j.joints.iter_mut().enumerate() {
            // Each joint 1 cm further along -z, so the order is visible.
            joint.position = [0.0, 1.0, -0.01 * k as f64];
        }
        let mut h = HandSample::default();
        assert!(m.from_joints(&j, &mut h));
        assert_eq!(
            h.finger(0),
            &[[0.0, 1.0, -0.03], [0.0, 1.0, -0.04], [0.0, 1.0, -0.05]]
        );
        assert_eq!(h.finger(1)[0], [0.0, 1.0, -0.07]);
        assert_eq!(h.finger(4)[3], [0.0, 1.0, -0.25]);
        // The palm reaches the farthest knuckle (joint 22, 0.22 m ahead of the wrist).
        let min_z = h.palm().iter().map(|p| p[2]).fold(0.0, f64::min);
        assert!((min_z + 0.22).abs() < 1e-12, "{min_z}");
        assert_eq!(h.tracked, 1);
    }

    #[test]
    fn a_joint_with_nan_leaves_the_hand_untouched() {
        let m = HandModel::default();
        let mut j = JointsSample {
            tracked: 1,
            ..Default::default()
        };
        j.joints[9].position[1] = f64::NAN;
        let mut h = HandSample {
            finger_count: 42,
            ..Default::default()
        };
        assert!(!m.from_joints(&j, &mut h));
        assert_eq!(h.finger_count, 42);
    }

    fn joints_of(g: &GloveSample, wrist: &Pose) -> [Pose; OPENXR_JOINTS] {
        let mut j = [Pose::IDENTITY; OPENXR_JOINTS];
        HandModel::default().glove_joints(g, wrist, &mut j);
        j
    }

    fn bone_direction(p: &Pose) -> DVec3 {
        DQuat::from_array(p.rotation) * DVec3::NEG_Z
    }

    #[test]
    fn a_flat_glove_gives_openxr_joints_along_minus_z_with_the_back_of_the_hand_up() {
        let j = joints_of(&glove(|_| 0.0), &Pose::IDENTITY);
        // Index: metacarpal (6), proximal = knuckle (7), intermediate (8), distal (9), tip (10).
        assert!(close(j[7].position, [-0.028, 0.0, -0.090]));
        assert!(close(j[8].position, [-0.028, 0.0, -0.135]));
        assert!(close(j[9].position, [-0.028, 0.0, -0.160]));
        assert!(close(j[10].position, [-0.028, 0.0, -0.180]));
        // Little tip: knuckle (0.028, 0, -0.08) + 0.075 along -z.
        assert!(close(j[25].position, [0.028, 0.0, -0.155]));
        for (k, joint) in j.iter().enumerate().take(11).skip(7) {
            assert!(
                (bone_direction(joint) - DVec3::NEG_Z).length() < 1e-12,
                "joint {k}"
            );
            let up = DQuat::from_array(j[k].rotation) * DVec3::Y;
            assert!(
                (up - DVec3::Y).length() < 1e-12,
                "joint {k}: back of the hand is not +y"
            );
        }
        assert!(close(j[1].position, [0.0; 3]), "joint 1 is the wrist");
    }

    #[test]
    fn a_single_mcp_bend_turns_every_later_index_bone_down() {
        let bend = std::f64::consts::FRAC_PI_2;
        let j = joints_of(
            &glove(|g| if g == GloveJoint::IndexMcp { bend } else { 0.0 }),
            &Pose::IDENTITY,
        );
        assert!(
            close(j[7].position, [-0.028, 0.0, -0.090]),
            "the knuckle does not move"
        );
        assert!(close(j[8].position, [-0.028, -0.045, -0.090]));
        assert!(close(j[10].position, [-0.028, -0.090, -0.090]));
        for (k, joint) in j.iter().enumerate().take(11).skip(7) {
            assert!(
                (bone_direction(joint) - DVec3::NEG_Y).length() < 1e-12,
                "joint {k}"
            );
        }
        // The middle finger's joints are untouched.
        assert!((bone_direction(&j[13]) - DVec3::NEG_Z).length() < 1e-12);
    }

    #[test]
    fn a_fist_points_the_fingertips_back_toward_the_wrist() {
        let j = joints_of(
            &glove(|g| match g {
                GloveJoint::IndexMcp | GloveJoint::IndexPip => std::f64::consts::FRAC_PI_2,
                _ => 0.0,
            }),
            &Pose::IDENTITY,
        );
        // MCP 90 + PIP 90: the middle and distal bones point back along +z.
        assert!((bone_direction(&j[8]) - DVec3::Z).length() < 1e-12);
        assert!((bone_direction(&j[10]) - DVec3::Z).length() < 1e-12);
        assert!(close(j[10].position, [-0.028, -0.045, -0.045]));
    }

    #[test]
    fn the_glove_path_and_the_joints_path_give_the_same_hand() {
        let m = HandModel::default();
        let g = glove(|j| match j {
            GloveJoint::ThumbRotation => 0.7,
            GloveJoint::MiddlePip => 0.9,
            _ => 0.3,
        });
        let wrist = Pose {
            position: [0.1, 0.3, -0.2],
            rotation: DQuat::from_rotation_y(0.4).to_array(),
        };
        let mut from_glove = HandSample::default();
        m.solve(&g, &wrist, &mut from_glove);
        let mut joints = JointsSample {
            tracked: 1,
            wrist,
            ..Default::default()
        };
        m.glove_joints(&g, &wrist, &mut joints.joints);
        let mut from_joints = HandSample::default();
        assert!(m.from_joints(&joints, &mut from_joints));
        assert_eq!(from_glove, from_joints);
    }
}
