//! The schemas: each sample type as a ROS 2 message definition (`ros2msg`) that lists every
//! field with its byte offset and size, so that Foxglove and the ROS 2 tools decode the
//! recorded bytes without knowing handblocks, and anyone can read them without a CDR library.

use std::fmt::Write as _;

use common::topic::{Meaning, Schema, Topic};

use crate::codec::slice_elements_offset;

pub use common::topic::Field;

/// Schema encoding: ROS 2 message definitions, as [`layout`] writes them.
pub const SCHEMA_ENCODING: &str = "ros2msg";

/// The fields of a struct the samples are built from, in memory order, by its schema name
/// (`handblocks/msg/HandSample`, or a nested `handblocks/Pose`): the topic table's field
/// lists ([`Topic::schema`]).
pub fn fields(struct_name: &str) -> Option<Vec<Field>> {
    schema(struct_name).map(|s| s.fields.to_vec())
}

/// The schema named `struct_name`: a topic's sample type or a type nested in one.
pub fn schema(struct_name: &str) -> Option<&'static Schema> {
    Topic::ALL.iter().find_map(|t| t.schema().find(struct_name))
}

/// The schema of a topic: a ROS 2 message definition of its sample type, then (after the
/// `====` separators of the format) each nested message it uses. Each field's comment gives its
/// byte offset and size within the sample, so the bytes can be read without a CDR library too.
pub fn layout(topic: Topic) -> String {
    let top = topic.schema();
    let mut out = String::new();
    let mut pending = vec![top];
    let mut done: Vec<&str> = Vec::new();
    while let Some(schema) = pending.pop() {
        let (name, size) = (schema.name, schema.size);
        if done.contains(&name) {
            continue;
        }
        if done.is_empty() {
            let what = match top.elements {
                None => format!("{size} bytes"),
                Some(e) => format!("a {size}-byte header and a sequence of {}", e.name),
            };
            let _ = writeln!(
                out,
                "# {name}: {what} after the 4-byte CDR header (little-endian; each field at a \
                 multiple of its size, so the CDR bytes are the C layout). Metres, world frame, y \
                 up; rotations as unit quaternions [x, y, z, w]; times in nanoseconds."
            );
        } else {
            let _ = writeln!(out, "{}", "=".repeat(80));
            let _ = writeln!(out, "MSG: {}", ros_type(name));
            let _ = writeln!(out, "# {size} bytes");
        }
        done.push(name);
        for f in schema.fields {
            let _ = writeln!(
                out,
                "{} {}  # @{}, {} bytes",
                ros_type(f.ty),
                f.name,
                f.offset,
                f.size
            );
            // An enumeration's names: ROS 2 constants of the field's type, which Foxglove
            // and the ROS 2 tools show by name beside the value.
            if let Meaning::Names(names) = f.meaning {
                let base = f.ty.split('[').next().unwrap_or(f.ty);
                for (value, each) in names.iter().enumerate() {
                    let _ = writeln!(
                        out,
                        "{base} {}_{}={value}  # {}: {each}",
                        f.name.to_ascii_uppercase(),
                        each.to_ascii_uppercase(),
                        f.name
                    );
                }
            }
            if let Some(nested) = f.message() {
                pending.insert(0, nested);
            }
        }
        // A slice topic's elements follow its header as a CDR sequence.
        if let (1, Some(e)) = (done.len(), schema.elements) {
            let _ = writeln!(
                out,
                "{}[] {}  # count: uint32 @{size}; {} @{}, {} bytes each",
                e.schema.name,
                e.name,
                e.name,
                slice_elements_offset(topic),
                e.schema.size
            );
            pending.insert(0, e.schema);
        }
    }
    out
}

/// A nested message's type as a ROS 2 field names it: `pkg/Name`. A sample type nested in
/// another (a `peer_hand` holds a `handblocks/msg/HandSample`) loses its `msg/`, which the ROS 2
/// parsers refuse in a field's type (a topic's own schema keeps its name).
fn ros_type(ty: &str) -> std::borrow::Cow<'_, str> {
    if ty.contains("/msg/") {
        ty.replacen("/msg/", "/", 1).into()
    } else {
        ty.into()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::sample_type;
    use crate::RECORDED_TOPICS;
    use common::samples::{BlockState, Pose};
    use common::stamp::Stamp;
    use std::mem::size_of;

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
                    | "handblocks/BlockState"
                    | "handblocks/msg/HandSample" => 8,
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
        // A sample nested in another (another participant's hand): its definition follows.
        let text = layout(Topic::PeerHand);
        assert!(text.contains("handblocks/HandSample hand"), "{text}");
        assert!(text.contains("MSG: handblocks/HandSample"), "{text}");
    }
}
