//! From a FASTRAK record to the wrist's pose in the world.
//!
//! The FASTRAK reports in its transmitter's frame: x forward, y right, z down (right-handed),
//! orientation as the receiver's rotation from that frame. The project's frame is right-handed
//! with y up; the fixed mapping used here takes the transmitter's forward to -z, right to +x and
//! down to -y:
//!
//! ```text
//! project (x, y, z) = (tracker y, -tracker z, -tracker x)
//! ```
//!
//! and rotations are conjugated by the same mapping, so a receiver aligned with the
//! transmitter gives the identity rotation. Then `to_world` (the transmitter's pose in the
//! world, in those project axes) places the result, and `wrist_offset` (the wrist's pose in the
//! receiver's frame, project axes: where on the hand the receiver is strapped) moves it from
//! the receiver to the wrist. Positions are converted from inches (2.54 cm) or centimetres to
//! metres.

use common::Pose;
use glam::{DMat3, DQuat, DVec3};

use super::Units;

/// One decoded record, in the tracker's own frame and units.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TrackerRecord {
    pub station: u8,
    /// The record's error character (b' ' when all is well).
    pub error: u8,
    pub position: [f64; 3],
    pub has_position: bool,
    /// Azimuth, elevation, roll in degrees.
    pub euler: [f64; 3],
    pub has_euler: bool,
    /// w, x, y, z as the FASTRAK sends them (q0 scalar).
    pub quaternion: [f64; 4],
    pub has_quaternion: bool,
}

impl TrackerRecord {
    /// The receiver's rotation in the tracker frame (unit), from the quaternion or the Euler
    /// angles (azimuth about z, then elevation about y, then roll about x).
    pub fn rotation(&self) -> DQuat {
        if self.has_quaternion {
            let [w, x, y, z] = self.quaternion;
            DQuat::from_xyzw(x, y, z, w).normalize()
        } else if self.has_euler {
            let [az, el, roll] = self.euler;
            DQuat::from_rotation_z(az.to_radians())
                * DQuat::from_rotation_y(el.to_radians())
                * DQuat::from_rotation_x(roll.to_radians())
        } else {
            DQuat::IDENTITY
        }
    }
}

/// The fixed axis mapping tracker (x forward, y right, z down) -> project (y up, forward -z).
pub fn tracker_axes() -> DQuat {
    DQuat::from_mat3(&DMat3::from_cols(
        DVec3::new(0.0, 0.0, -1.0), // tracker x (forward)
        DVec3::new(1.0, 0.0, 0.0),  // tracker y (right)
        DVec3::new(0.0, -1.0, 0.0), // tracker z (down)
    ))
}

/// A record's receiver pose as the wrist's pose in the world (metres, unit quaternion), or
/// None if the result is not finite.
pub fn record_to_world(
    rec: &TrackerRecord,
    units: Units,
    axes: DQuat,
    to_world: &Pose,
    wrist_offset: &Pose,
) -> Option<Pose> {
    let s = units.metres_per_unit();
    let p_t = DVec3::from_array(rec.position) * s;
    let p = axes * p_t;
    let q = axes * rec.rotation() * axes.conjugate();
    let w_q = DQuat::from_array(to_world.rotation);
    let w_p = DVec3::from_array(to_world.position);
    let sensor_p = w_p + w_q * p;
    let sensor_q = w_q * q;
    let o_q = DQuat::from_array(wrist_offset.rotation);
    let o_p = DVec3::from_array(wrist_offset.position);
    let wrist_p = sensor_p + sensor_q * o_p;
    let wrist_q = (sensor_q * o_q).normalize();
    let pose = Pose {
        position: wrist_p.to_array(),
        rotation: wrist_q.to_array(),
    };
    pose.is_finite().then_some(pose)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_mapping_takes_forward_to_minus_z_and_down_to_minus_y() {
        let axes = tracker_axes();
        let rec = |pos: [f64; 3], q: DQuat| TrackerRecord {
            station: 1,
            error: b' ',
            position: pos,
            has_position: true,
            quaternion: [q.w, q.x, q.y, q.z],
            has_quaternion: true,
            ..Default::default()
        };
        let id = Pose::IDENTITY;
        let p = record_to_world(
            &rec([100.0, 0.0, 0.0], DQuat::IDENTITY),
            Units::Centimetres,
            axes,
            &id,
            &id,
        )
        .unwrap();
        assert!((DVec3::from_array(p.position) - DVec3::new(0.0, 0.0, -1.0)).length() < 1e-12);
        let p = record_to_world(
            &rec([0.0, 10.0, 10.0], DQuat::IDENTITY),
            Units::Inches,
            axes,
            &id,
            &id,
        )
        .unwrap();
        assert!((DVec3::from_array(p.position) - DVec3::new(0.254, -0.254, 0.0)).length() < 1e-12);
        // Aligned receiver: identity. A yaw (azimuth) about the tracker's down axis becomes a
        // rotation about the world's -y: positive azimuth turns forward (-z) towards right (+x).
        assert!(DQuat::from_array(p.rotation).angle_between(DQuat::IDENTITY) < 1e-12);
        let yaw = DQuat::from_rotation_z(0.5);
        let p = record_to_world(&rec([0.0; 3], yaw), Units::Inches, axes, &id, &id).unwrap();
        let fwd = DQuat::from_array(p.rotation) * DVec3::new(0.0, 0.0, -1.0);
        assert!(fwd.x > 0.4 && fwd.y.abs() < 1e-12, "{fwd}");
        // to_world lifts the transmitter 1 m; the wrist offset moves along the receiver.
        let to_world = Pose {
            position: [0.0, 1.0, 0.0],
            rotation: [0.0, 0.0, 0.0, 1.0],
        };
        let offset = Pose {
            position: [0.0, 0.0, 0.1],
            rotation: [0.0, 0.0, 0.0, 1.0],
        };
        let p = record_to_world(
            &rec([0.0; 3], DQuat::IDENTITY),
            Units::Inches,
            axes,
            &to_world,
            &offset,
        )
        .unwrap();
        assert!((DVec3::from_array(p.position) - DVec3::new(0.0, 1.0, 0.1)).length() < 1e-12);
    }

    #[test]
    fn euler_and_quaternion_agree() {
        let axis_angles = [(10.0, 20.0, 30.0), (-170.0, 45.0, -90.0)];
        for (az, el, roll) in axis_angles {
            let q = DQuat::from_euler(
                glam::EulerRot::ZYX,
                f64::to_radians(az),
                f64::to_radians(el),
                f64::to_radians(roll),
            );
            let a = TrackerRecord {
                euler: [az, el, roll],
                has_euler: true,
                ..Default::default()
            }
            .rotation();
            assert!(a.angle_between(q) < 1e-9);
        }
    }
}
