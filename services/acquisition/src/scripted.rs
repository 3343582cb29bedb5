//! The scripted hand: a scene's `[hand]` keyframes, linearly interpolated (the wrist rotation by
//! slerp), sampled as a glove and a tracker would report them.
//!
//! Grip keys become glove angles by scaling a fist ([`fist_angles`]), so a scripted session
//! exercises the same kinematics as a real glove. After the last key the hand holds still.

use common::config::scene::{HandPoseSpec, HandScript};
use common::config::Scene;
use common::glove::{GloveJoint, SENSORS_22};
use common::{GloveSample, HandSide, Pose, Stamp, TrackerSample, MAX_GLOVE_SENSORS};
use glam::{DQuat, DVec3};

/// The hand a script asks for at one moment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HandTarget {
    pub wrist: Pose,
    /// Glove angles in radians, in the order of a glove of `sensor_count` sensors.
    pub angles: [f64; MAX_GLOVE_SENSORS],
    pub sensor_count: u32,
}

/// Why a scene's hand cannot be scripted as a glove and tracker.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ScriptError {
    /// The keys give bare check points, which no glove can report.
    #[error(
        "the scene's [hand] keys give bare `fingers` check points, which no glove can report; \
         run such a scene with `handblocks simulate`, or give the keys `grip` or `angles`"
    )]
    BareFingers,
}

/// Glove angles of a closed fist, 22-sensor order: grip g gives g times these.
pub fn fist_angles() -> [f64; MAX_GLOVE_SENSORS] {
    let mut a = [0.0; MAX_GLOVE_SENSORS];
    for (i, joint) in SENSORS_22.iter().enumerate() {
        a[i] = match joint {
            GloveJoint::ThumbRotation => 1.0,
            GloveJoint::ThumbMcp => 0.5,
            GloveJoint::ThumbIp => 0.6,
            GloveJoint::IndexMcp
            | GloveJoint::MiddleMcp
            | GloveJoint::RingMcp
            | GloveJoint::LittleMcp => 1.5,
            GloveJoint::IndexPip
            | GloveJoint::MiddlePip
            | GloveJoint::RingPip
            | GloveJoint::LittlePip => 1.7,
            GloveJoint::IndexDip
            | GloveJoint::MiddleDip
            | GloveJoint::RingDip
            | GloveJoint::LittleDip => 1.1,
            _ => 0.0,
        };
    }
    a
}

/// Keyframes ready to sample.
#[derive(Debug, Clone)]
pub struct ScriptedHand {
    keys: Vec<(f64, Pose, [f64; MAX_GLOVE_SENSORS])>,
    sensor_count: u32,
    /// The hand the samples are marked with: a scene's `[hand]` is the right, its
    /// `[left_hand]` the left.
    side: HandSide,
}

impl ScriptedHand {
    pub fn new(script: &HandScript) -> Result<ScriptedHand, ScriptError> {
        let fist = fist_angles();
        let mut sensor_count = 22;
        let keys = script
            .keys
            .iter()
            .map(|k| {
                let angles = match &k.pose {
                    HandPoseSpec::Grip(g) => fist.map(|a| a * g),
                    HandPoseSpec::Angles(a) => {
                        sensor_count = a.len() as u32;
                        let mut out = [0.0; MAX_GLOVE_SENSORS];
                        out[..a.len()].copy_from_slice(a);
                        out
                    }
                    HandPoseSpec::Fingers(_) => return Err(ScriptError::BareFingers),
                };
                let wrist = Pose {
                    position: k.wrist,
                    rotation: k.wrist_rotation,
                };
                Ok((k.t, wrist, angles))
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(ScriptedHand {
            keys,
            sensor_count,
            side: HandSide::Right,
        })
    }

    /// The same script played as the hand `side` (its samples marked with it).
    pub fn with_side(self, side: HandSide) -> ScriptedHand {
        ScriptedHand { side, ..self }
    }

    /// The scene's scripted hands: its `[hand]` (the right) and its `[left_hand]`, if any.
    pub fn of_scene(scene: &Scene) -> Result<Vec<ScriptedHand>, ScriptError> {
        let mut hands = Vec::with_capacity(2);
        if let Some(right) = &scene.hand {
            hands.push(ScriptedHand::new(right)?);
        }
        if let Some(left) = &scene.left_hand {
            hands.push(ScriptedHand::new(left)?.with_side(HandSide::Left));
        }
        Ok(hands)
    }

    /// The time of the last key, after which the hand holds still.
    pub fn duration(&self) -> f64 {
        self.keys.last().map_or(0.0, |k| k.0)
    }

    /// The hand at `t` seconds.
    pub fn at(&self, t: f64) -> HandTarget {
        let target = |pose: Pose, angles| HandTarget {
            wrist: pose,
            angles,
            sensor_count: self.sensor_count,
        };
        let Some(first) = self.keys.first() else {
            return target(Pose::IDENTITY, [0.0; MAX_GLOVE_SENSORS]);
        };
        // Before the first key and after the last, hold.
        let i = self.keys.partition_point(|k| k.0 <= t);
        if i == 0 {
            return target(first.1, first.2);
        }
        if i == self.keys.len() {
            let last = &self.keys[i - 1];
            return target(last.1, last.2);
        }
        let (a, b) = (&self.keys[i - 1], &self.keys[i]);
        let s = (t - a.0) / (b.0 - a.0);
        let pa = DVec3::from_array(a.1.position);
        let pb = DVec3::from_array(b.1.position);
        let qa = DQuat::from_array(a.1.rotation);
        let qb = DQuat::from_array(b.1.rotation);
        let wrist = Pose {
            position: pa.lerp(pb, s).to_array(),
            rotation: qa.slerp(qb, s).normalize().to_array(),
        };
        let mut angles = [0.0; MAX_GLOVE_SENSORS];
        for (k, out) in angles.iter_mut().enumerate() {
            *out = a.2[k] + (b.2[k] - a.2[k]) * s;
        }
        target(wrist, angles)
    }

    /// The glove and tracker samples of the hand at `t` (stamps left for the caller).
    pub fn samples_at(&self, t: f64, stamp: Stamp) -> (GloveSample, TrackerSample) {
        let h = self.at(t);
        let glove = GloveSample {
            stamp,
            sensor_count: h.sensor_count,
            side: self.side.code(),
            angles: h.angles,
        };
        let tracker = TrackerSample {
            stamp,
            // One tracker station per hand, as a two-receiver tracker numbers them.
            station: 1 + self.side.code(),
            side: self.side.code(),
            wrist: h.wrist,
        };
        (glove, tracker)
    }
}

/// The source time of sample `k` of a source at `rate_hz`, in ns, rounded up, so that the
/// stepper, which takes floor(t * step_hz) steps, takes exactly k steps at sample k when the
/// rates are equal.
pub fn source_time_ns(k: u64, rate_hz: f64) -> u64 {
    let exact = k as f64 * 1e9 / rate_hz;
    exact.ceil() as u64
}

#[cfg(test)]
mod tests {
    use super::*;
    use common::config::scene::HandKey;

    fn key(t: f64, x: f64, grip: f64) -> HandKey {
        HandKey {
            t,
            wrist: [x, 0.3, 0.0],
            wrist_rotation: [0.0, 0.0, 0.0, 1.0],
            pose: HandPoseSpec::Grip(grip),
        }
    }

    #[test]
    fn keys_interpolate_linearly_and_hold_after_the_last() {
        let h = ScriptedHand::new(&HandScript {
            keys: vec![key(0.0, 0.0, 0.0), key(1.0, 1.0, 1.0)],
        })
        .unwrap();
        let mid = h.at(0.25);
        assert!((mid.wrist.position[0] - 0.25).abs() < 1e-12);
        assert!((mid.angles[4] - 0.25 * fist_angles()[4]).abs() < 1e-12);
        assert_eq!(h.at(5.0), h.at(1.0));
        assert_eq!(h.at(-1.0), h.at(0.0));
    }

    #[test]
    fn wrist_rotation_is_slerped() {
        let mut a = key(0.0, 0.0, 0.0);
        let mut b = key(1.0, 0.0, 0.0);
        a.wrist_rotation = [0.0, 0.0, 0.0, 1.0];
        let q = DQuat::from_rotation_y(std::f64::consts::FRAC_PI_2);
        b.wrist_rotation = q.to_array();
        let h = ScriptedHand::new(&HandScript { keys: vec![a, b] }).unwrap();
        let mid = DQuat::from_array(h.at(0.5).wrist.rotation);
        assert!(mid.angle_between(DQuat::from_rotation_y(std::f64::consts::FRAC_PI_4)) < 1e-12);
    }

    #[test]
    fn source_times_give_whole_steps() {
        for k in 0..10_000u64 {
            let t = source_time_ns(k, 120.0);
            assert_eq!((t as f64 * 120.0 / 1e9).floor() as u64, k);
        }
    }

    #[test]
    fn bare_fingers_cannot_be_a_glove() {
        let k = HandKey {
            t: 0.0,
            wrist: [0.0; 3],
            wrist_rotation: [0.0, 0.0, 0.0, 1.0],
            pose: HandPoseSpec::Fingers(vec![vec![[0.0; 3]]]),
        };
        assert_eq!(
            ScriptedHand::new(&HandScript { keys: vec![k] }).unwrap_err(),
            ScriptError::BareFingers
        );
    }
}
