//! The CDR walker: a message's fields in order, read by its topic's field list (the schema
//! the recording carries, [`crate::layout`]), told to a [`MessageVisitor`]. One walk serves
//! every reader that shows a sample field by field, whatever its topic: `handblocks echo`
//! (text) and `handblocks inspect --samples` (JSON) are two visitors of it.
//!
//! A message shorter than its schema loses the fields it does not hold (and a slice topic the
//! elements it does not hold); nothing is read past its end. Padding (`reserved`) is skipped.

use std::fmt;

use common::topic::{Field, Meaning, Scalar, Schema, Topic};

use crate::codec::{slice_elements_offset, CDR_LE_HEADER};

/// What holds nested messages: a field of them, or a slice topic's elements.
#[derive(Debug, Clone, Copy)]
pub enum Group<'a> {
    /// A field of one message (its `dims` empty) or an array of them.
    Field(&'a Field),
    /// A slice topic's elements, by the name its schema gives them (`blocks`): `count` as the
    /// message says (those it holds are visited).
    Elements { name: &'static str, count: usize },
}

impl Group<'_> {
    /// The name the group has in its message.
    pub fn name(&self) -> &'static str {
        match self {
            Group::Field(f) => f.name,
            Group::Elements { name, .. } => name,
        }
    }

    /// True when the group holds a list (an array field, or elements) rather than one message.
    pub fn is_list(&self) -> bool {
        match self {
            Group::Field(f) => !f.dims.is_empty(),
            Group::Elements { .. } => true,
        }
    }
}

/// What a walk meets, in the message's order. Nested messages come as `begin` (the group),
/// then per message `item` .. its fields .. `end_item`, then `end`.
pub trait MessageVisitor {
    /// A field of numbers: its values in memory order (an array's, flattened).
    fn values(&mut self, field: &Field, values: Values<'_>);
    /// A group of nested messages begins.
    fn begin(&mut self, _group: Group<'_>) {}
    /// Message `index` of the group begins.
    fn item(&mut self, _group: Group<'_>, _index: usize) {}
    /// The message `item` began ends.
    fn end_item(&mut self, _group: Group<'_>) {}
    /// The group ends.
    fn end(&mut self, _group: Group<'_>) {}
}

/// One number of a field.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Value {
    F64(f64),
    U64(u64),
    I64(i64),
    U32(u32),
    I32(i32),
    U8(u8),
}

impl Value {
    /// An integer's value (an enumeration's index); None for a float.
    pub fn as_index(self) -> Option<u64> {
        match self {
            Value::U64(v) => Some(v),
            Value::U32(v) => Some(v.into()),
            Value::U8(v) => Some(v.into()),
            Value::I64(v) => u64::try_from(v).ok(),
            Value::I32(v) => u64::try_from(v).ok(),
            Value::F64(_) => None,
        }
    }
}

/// As Rust prints each number (floats in their shortest round-trip form).
impl fmt::Display for Value {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Value::F64(v) => write!(f, "{v}"),
            Value::U64(v) => write!(f, "{v}"),
            Value::I64(v) => write!(f, "{v}"),
            Value::U32(v) => write!(f, "{v}"),
            Value::I32(v) => write!(f, "{v}"),
            Value::U8(v) => write!(f, "{v}"),
        }
    }
}

/// The numbers of one field, read little-endian from its bytes.
#[derive(Debug, Clone)]
pub struct Values<'a> {
    scalar: Scalar,
    chunks: std::slice::ChunksExact<'a, u8>,
}

impl<'a> Values<'a> {
    fn new(scalar: Scalar, bytes: &'a [u8]) -> Values<'a> {
        Values {
            scalar,
            chunks: bytes.chunks_exact(scalar.size()),
        }
    }
}

impl Iterator for Values<'_> {
    type Item = Value;

    fn next(&mut self) -> Option<Value> {
        let c = self.chunks.next()?;
        let mut b = [0u8; 8];
        b[..c.len()].copy_from_slice(c);
        let w = [b[0], b[1], b[2], b[3]];
        Some(match self.scalar {
            Scalar::Float64 => Value::F64(f64::from_le_bytes(b)),
            Scalar::Uint64 => Value::U64(u64::from_le_bytes(b)),
            Scalar::Int64 => Value::I64(i64::from_le_bytes(b)),
            Scalar::Uint32 => Value::U32(u32::from_le_bytes(w)),
            Scalar::Int32 => Value::I32(i32::from_le_bytes(w)),
            Scalar::Uint8 => Value::U8(b[0]),
        })
    }
}

/// Walks `message` (a recording's or the bridge's: the CDR header, then the sample's bytes)
/// as a sample of `topic`: its fields, then a slice topic's elements.
pub fn walk(topic: Topic, message: &[u8], visitor: &mut impl MessageVisitor) {
    let body = message.get(CDR_LE_HEADER.len()..).unwrap_or(&[]);
    let schema = topic.schema();
    walk_struct(schema, body, visitor);
    if let Some(elements) = schema.elements {
        let size = schema.size;
        let count = body
            .get(size..size + 4)
            .map_or(0, |b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize);
        let at = slice_elements_offset(topic);
        let each = elements.schema.size;
        let group = Group::Elements {
            name: elements.name,
            count,
        };
        visitor.begin(group);
        for i in 0..count {
            let Some(bytes) = body.get(at + i * each..at + (i + 1) * each) else {
                break;
            };
            visitor.item(group, i);
            walk_struct(elements.schema, bytes, visitor);
            visitor.end_item(group);
        }
        visitor.end(group);
    }
}

/// The fields of one message of `schema` in `bytes`.
fn walk_struct(schema: &Schema, bytes: &[u8], visitor: &mut impl MessageVisitor) {
    for f in schema
        .fields
        .iter()
        .filter(|f| f.meaning != Meaning::Reserved)
    {
        let Some(field) = bytes.get(f.offset..f.offset + f.size) else {
            continue;
        };
        let Some(nested) = f.message() else {
            if let common::topic::Base::Scalar(scalar) = f.base {
                visitor.values(f, Values::new(scalar, field));
            }
            continue;
        };
        let count = f.count();
        let each = f.size / count.max(1);
        let group = Group::Field(f);
        visitor.begin(group);
        for i in 0..count {
            visitor.item(group, i);
            walk_struct(nested, &field[i * each..(i + 1) * each], visitor);
            visitor.end_item(group);
        }
        visitor.end(group);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use common::{BlockState, WorldHeader};

    /// Records the walk as lines.
    #[derive(Default)]
    struct Trace(Vec<String>);

    impl MessageVisitor for Trace {
        fn values(&mut self, field: &Field, values: Values<'_>) {
            let v: Vec<String> = values.map(|v| v.to_string()).collect();
            self.0.push(format!("{}={}", field.name, v.join(",")));
        }
        fn begin(&mut self, group: Group<'_>) {
            self.0.push(format!("begin {}", group.name()));
        }
        fn item(&mut self, group: Group<'_>, index: usize) {
            self.0.push(format!("item {}[{index}]", group.name()));
        }
        fn end(&mut self, group: Group<'_>) {
            self.0.push(format!("end {}", group.name()));
        }
    }

    #[test]
    fn a_world_is_walked_field_by_field_then_block_by_block() {
        let header = WorldHeader {
            step: 3,
            block_count: 2,
            ..WorldHeader::default()
        };
        let block = BlockState {
            mode: 4,
            ..BlockState::default()
        };
        let mut message = Vec::new();
        crate::encode_slice(Topic::World, &header, &[block, block], &mut message);
        let mut trace = Trace::default();
        walk(Topic::World, &message, &mut trace);
        let t = trace.0;
        assert_eq!(t[0], "begin stamp");
        assert!(t.contains(&"step=3".to_string()), "{t:?}");
        assert!(t.contains(&"block_count=2".to_string()), "{t:?}");
        let blocks = t.iter().position(|l| l == "begin blocks").unwrap();
        assert_eq!(t[blocks + 1], "item blocks[0]");
        assert_eq!(t.iter().filter(|l| *l == "mode=4").count(), 2);
        assert_eq!(t.last().map(String::as_str), Some("end blocks"));
        // Cut short: what it holds, nothing past its end.
        let mut cut = Trace::default();
        walk(Topic::World, &message[..40], &mut cut);
        assert_eq!(cut.0.len(), 9, "{:?}", cut.0);
        assert_eq!(cut.0[7..], ["begin blocks", "end blocks"]);
    }
}
