//! The schemas: each sample type as a ROS 2 message definition (`ros2msg`) that lists every
//! field with its byte offset and size, so that Foxglove and the ROS 2 tools decode the
//! recorded bytes without knowing handblocks, and anyone can read them without a CDR library.

use std::fmt::Write as _;
use std::mem::{offset_of, size_of};

use common::samples::{
    BlockMode, BlockState, FrameSample, GloveSample, HandSample, JointsSample, Pose, TrackerSample,
    WorldHeader,
};
use common::stamp::Stamp;
use common::topic::Topic;

use crate::codec::{sample_type, slice_elements_offset};

/// Schema encoding: ROS 2 message definitions, as [`layout`] writes them.
pub const SCHEMA_ENCODING: &str = "ros2msg";

/// One field of a sample layout: where it is and what it holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Field {
    pub name: &'static str,
    /// The ROS 2 field type: `float64[75]`, or a nested message such as `handblocks/Pose`.
    /// Multi-dimensional arrays are flattened (row-major, as in memory).
    pub ty: &'static str,
    pub offset: usize,
    pub size: usize,
}

fn field_size<T, F>(_: fn(&T) -> &F) -> usize {
    size_of::<F>()
}

macro_rules! fields {
    ($t:ty { $($f:ident : $ty:literal),* $(,)? }) => {
        vec![$(Field {
            name: stringify!($f).trim_start_matches('_'),
            ty: $ty,
            offset: offset_of!($t, $f),
            size: field_size::<$t, _>(|s| &s.$f),
        }),*]
    };
}

/// The fields of a struct the samples are built from, in memory order.
pub fn fields(struct_name: &str) -> Option<Vec<Field>> {
    Some(match struct_name {
        "handblocks/Stamp" => fields!(Stamp {
            seq: "uint64",
            source_time_ns: "uint64",
            origin_ns: "uint64",
            publish_ns: "uint64",
        }),
        "handblocks/Pose" => fields!(Pose {
            position: "float64[3]",
            rotation: "float64[4]",
        }),
        "handblocks/BlockState" => fields!(BlockState {
            pose: "handblocks/Pose",
            mode: "uint32",
            held_by: "uint32",
        }),
        "handblocks/msg/GloveSample" => fields!(GloveSample {
            stamp: "handblocks/Stamp",
            sensor_count: "uint32",
            side: "uint32",
            angles: "float64[22]",
        }),
        "handblocks/msg/TrackerSample" => fields!(TrackerSample {
            stamp: "handblocks/Stamp",
            station: "uint32",
            side: "uint32",
            wrist: "handblocks/Pose",
        }),
        "handblocks/msg/JointsSample" => fields!(JointsSample {
            stamp: "handblocks/Stamp",
            tracked: "uint32",
            side: "uint32",
            wrist: "handblocks/Pose",
            joints: "handblocks/Pose[26]",
        }),
        "handblocks/msg/HandSample" => fields!(HandSample {
            stamp: "handblocks/Stamp",
            wrist: "handblocks/Pose",
            tracked: "uint32",
            finger_count: "uint32",
            finger_point_count: "uint32[5]",
            palm_vertex_count: "uint32",
            finger_points: "float64[75]",
            finger_radius: "float64[5]",
            palm_vertices: "float64[48]",
            side: "uint32",
            _reserved: "uint32",
        }),
        // The header; `layout` adds the `blocks` sequence that follows it.
        "handblocks/msg/WorldSample" => fields!(WorldHeader {
            stamp: "handblocks/Stamp",
            step: "uint64",
            hand_seq: "uint64",
            block_count: "uint32",
            grasped_block: "int32",
            finger_count: "uint32",
            finger_point_count: "uint32[5]",
            finger_points: "float64[75]",
        }),
        "handblocks/msg/FrameSample" => fields!(FrameSample {
            stamp: "handblocks/Stamp",
            world_seq: "uint64",
            render_ns: "uint64",
            origin_to_photon_ns: "uint64",
            skipped_worlds: "uint64",
        }),
        _ => return None,
    })
}

/// The schema of a topic: a ROS 2 message definition of its sample type, then (after the
/// `====` separators of the format) each nested message it uses. Each field's comment gives its
/// byte offset and size within the sample, so the bytes can be read without a CDR library too.
pub fn layout(topic: Topic) -> String {
    let (name, size) = sample_type(topic);
    let mut out = String::new();
    let mut pending = vec![(name, size)];
    let mut done: Vec<&str> = Vec::new();
    while let Some((name, size)) = pending.pop() {
        if done.contains(&name) {
            continue;
        }
        let Some(fs) = fields(name) else { continue };
        if done.is_empty() {
            let what = match topic.element_size() {
                None => format!("{size} bytes"),
                Some(_) => format!("a {size}-byte header and a sequence of blocks"),
            };
            let _ = writeln!(
                out,
                "# {name}: {what} after the 4-byte CDR header (little-endian; each field at a \
                 multiple of its size, so the CDR bytes are the C layout). Metres, world frame, y \
                 up; rotations as unit quaternions [x, y, z, w]; times in nanoseconds."
            );
        } else {
            let _ = writeln!(out, "{}", "=".repeat(80));
            let _ = writeln!(out, "MSG: {name}");
            let _ = writeln!(out, "# {size} bytes");
        }
        done.push(name);
        for f in &fs {
            let _ = writeln!(
                out,
                "{} {}  # @{}, {} bytes",
                f.ty, f.name, f.offset, f.size
            );
            // The mode as an enum: ROS 2 constants of the field's type, which Foxglove and
            // the ROS 2 tools show by name beside the value.
            if name == "handblocks/BlockState" && f.name == "mode" {
                for mode in BlockMode::ALL {
                    let _ = writeln!(
                        out,
                        "uint32 MODE_{}={}  # mode: {}",
                        mode.name().to_ascii_uppercase(),
                        mode as u32,
                        mode.name()
                    );
                }
            }
            let base = f.ty.split('[').next().unwrap_or(f.ty);
            let nested = match base {
                "handblocks/Stamp" => Some(size_of::<Stamp>()),
                "handblocks/Pose" => Some(size_of::<Pose>()),
                "handblocks/BlockState" => Some(size_of::<BlockState>()),
                _ => None,
            };
            if let Some(s) = nested {
                pending.insert(0, (base, s));
            }
        }
        // A slice topic's elements follow its header as a CDR sequence.
        if done.len() == 1 && topic.element_size().is_some() {
            let _ = writeln!(
                out,
                "handblocks/BlockState[] blocks  # count: uint32 @{size}; blocks @{}, {} bytes each",
                slice_elements_offset(topic),
                size_of::<BlockState>()
            );
            pending.insert(0, ("handblocks/BlockState", size_of::<BlockState>()));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::RECORDED_TOPICS;

    /// Every layout lists every byte of its struct once, in order: no field forgotten, no gap.
    #[test]
    fn layouts_cover_every_byte() {
        for (name, size) in [
            ("handblocks/Stamp", size_of::<Stamp>()),
            ("handblocks/Pose", size_of::<Pose>()),
            ("handblocks/BlockState", size_of::<BlockState>()),
        ]
        .into_iter()
        .chain(RECORDED_TOPICS.into_iter().map(sample_type))
        {
            let fs = fields(name).unwrap();
            let mut at = 0;
            for f in &fs {
                assert_eq!(
                    f.offset, at,
                    "{name}.{} starts where the last ended",
                    f.name
                );
                // CDR aligns each primitive to its own size: so does our layout.
                let element = match f.ty.split('[').next().unwrap() {
                    "uint64"
                    | "float64"
                    | "handblocks/Stamp"
                    | "handblocks/Pose"
                    | "handblocks/BlockState" => 8,
                    "uint32" | "int32" => 4,
                    other => panic!("{name}.{}: unexpected type {other}", f.name),
                };
                assert_eq!(f.offset % element, 0, "{name}.{} is CDR-aligned", f.name);
                at += f.size;
            }
            assert_eq!(at, size, "{name}: the fields cover all {size} bytes");
        }
        let text = layout(Topic::World);
        assert!(
            text.contains(
                "handblocks/BlockState[] blocks  # count: uint32 @680; blocks @688, 64 bytes each"
            ),
            "{text}"
        );
        assert!(text.contains("MSG: handblocks/BlockState"));
        assert!(text.contains("MSG: handblocks/Pose"));
        assert!(text.contains("MSG: handblocks/Stamp"));
        assert!(text.contains("uint32 held_by"));
    }
}
