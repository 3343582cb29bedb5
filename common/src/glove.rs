//! What each angle of a [`crate::GloveSample`] means: the CyberGlove's sensor order.
//!
//! The 18-sensor glove reports, in order: thumb rotation, thumb MCP, thumb IP, thumb-index
//! abduction, index MCP, index PIP, middle MCP, middle PIP, middle-index abduction, ring MCP,
//! ring PIP, ring-middle abduction, little MCP, little PIP, little-ring abduction, palm arch,
//! wrist pitch, wrist yaw. The 22-sensor glove adds a DIP sensor after each finger's PIP.

/// One glove sensor, named for the joint it measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GloveJoint {
    ThumbRotation,
    ThumbMcp,
    ThumbIp,
    ThumbIndexAbduction,
    IndexMcp,
    IndexPip,
    IndexDip,
    MiddleMcp,
    MiddlePip,
    MiddleDip,
    MiddleIndexAbduction,
    RingMcp,
    RingPip,
    RingDip,
    RingMiddleAbduction,
    LittleMcp,
    LittlePip,
    LittleDip,
    LittleRingAbduction,
    PalmArch,
    WristPitch,
    WristYaw,
}

use GloveJoint::*;

/// The 22-sensor order.
pub const SENSORS_22: [GloveJoint; 22] = [
    ThumbRotation,
    ThumbMcp,
    ThumbIp,
    ThumbIndexAbduction,
    IndexMcp,
    IndexPip,
    IndexDip,
    MiddleMcp,
    MiddlePip,
    MiddleDip,
    MiddleIndexAbduction,
    RingMcp,
    RingPip,
    RingDip,
    RingMiddleAbduction,
    LittleMcp,
    LittlePip,
    LittleDip,
    LittleRingAbduction,
    PalmArch,
    WristPitch,
    WristYaw,
];

/// The 18-sensor order (no DIP sensors).
pub const SENSORS_18: [GloveJoint; 18] = [
    ThumbRotation,
    ThumbMcp,
    ThumbIp,
    ThumbIndexAbduction,
    IndexMcp,
    IndexPip,
    MiddleMcp,
    MiddlePip,
    MiddleIndexAbduction,
    RingMcp,
    RingPip,
    RingMiddleAbduction,
    LittleMcp,
    LittlePip,
    LittleRingAbduction,
    PalmArch,
    WristPitch,
    WristYaw,
];

/// The sensor order of a glove with `sensor_count` sensors (18 or 22).
pub fn sensor_order(sensor_count: u32) -> Option<&'static [GloveJoint]> {
    match sensor_count {
        18 => Some(&SENSORS_18),
        22 => Some(&SENSORS_22),
        _ => None,
    }
}

/// The angle of `joint` in a glove sample's `angles`, or None if this glove has no such sensor
/// (the DIP joints of an 18-sensor glove).
pub fn angle(sample: &crate::GloveSample, joint: GloveJoint) -> Option<f64> {
    let order = sensor_order(sample.sensor_count)?;
    order
        .iter()
        .position(|j| *j == joint)
        .map(|i| sample.angles[i])
}
