//! The emulated headset's playback file: what `handblocks emulate headset` writes and its
//! browser driver (services/webxr/driver/headset.js) plays, one sample per XR frame, through
//! the page's WebXR calls. Its joints are the page's: WebXR's 25 in WebXR's order
//! ([`crate::from_joints`] of a recorded hand), so the driver hands the page exactly what a
//! headset would, and can check the page's hands frames against them bit for bit.
//!
//! ```text
//! u32 samples, then per sample one record per hand played (one, or two: the right, then the
//! left), each RECORD_BYTES:
//!   f64 time (ms from the first sample; both records of a sample hold the same)
//!   u8  tracked (1, or 0: the hand is not seen in that frame), 3 zero bytes
//!   25 joints of 7 f32: position x y z (m), orientation x y z w
//! ```
//! All little-endian.

use common::Pose;

use crate::WEBXR_JOINTS;

/// f32 values per joint: position (3) and orientation (4); the runtime gives the radius.
pub const VALUES_PER_JOINT: usize = 7;
/// Bytes of one hand's record.
pub const RECORD_BYTES: usize = 8 + 4 + WEBXR_JOINTS * VALUES_PER_JOINT * 4;

/// One hand of one sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Record {
    /// Milliseconds from the first sample: the page's frame time while it plays.
    pub time_ms: f64,
    pub tracked: bool,
    /// WebXR's joints, in its order.
    pub poses: [Pose; WEBXR_JOINTS],
}

/// The file of `samples` (each its records, one per hand played, all of the same count)
/// into `out` (cleared first).
pub fn encode<'a>(samples: impl ExactSizeIterator<Item = &'a [Record]>, out: &mut Vec<u8>) {
    out.clear();
    out.extend_from_slice(&(samples.len() as u32).to_le_bytes());
    for records in samples {
        for r in records {
            out.extend_from_slice(&r.time_ms.to_le_bytes());
            out.extend_from_slice(&[u8::from(r.tracked), 0, 0, 0]);
            for p in &r.poses {
                for v in p.position.iter().chain(&p.rotation) {
                    out.extend_from_slice(&(*v as f32).to_le_bytes());
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_lie_where_the_driver_reads_them() {
        let mut poses = [Pose::IDENTITY; WEBXR_JOINTS];
        poses[24].position = [0.25, 1.5, -0.5];
        let right = Record {
            time_ms: 11.5,
            tracked: true,
            poses,
        };
        let left = Record {
            tracked: false,
            ..right
        };
        let samples = [[right, left], [right, right]];
        let mut out = Vec::new();
        encode(samples.iter().map(|s| &s[..]), &mut out);
        assert_eq!(RECORD_BYTES, 712, "headset.js's RECORD");
        assert_eq!(out.len(), 4 + 2 * 2 * RECORD_BYTES);
        assert_eq!(out[..4], 2u32.to_le_bytes());
        let record = |i: usize| 4 + i * RECORD_BYTES;
        assert_eq!(out[record(0)..record(0) + 8], 11.5f64.to_le_bytes());
        assert_eq!(out[record(0) + 8..record(0) + 12], [1, 0, 0, 0]);
        assert_eq!(out[record(1) + 8], 0, "the second hand untracked");
        let tip_x = record(0) + 12 + (24 * VALUES_PER_JOINT) * 4;
        assert_eq!(out[tip_x..tip_x + 4], 0.25f32.to_le_bytes());
        let tip_w = tip_x + 6 * 4;
        assert_eq!(out[tip_w..tip_w + 4], 1.0f32.to_le_bytes());
    }
}
