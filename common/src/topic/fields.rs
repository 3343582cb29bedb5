//! Each sample's field list: every field of every sample type (and of the types nested in
//! them) with its name, its type as a recording's schema spells it (`float64[75]`,
//! `handblocks/Pose[26]`), its byte offset and size, and its shape. The topic table names the
//! fields of each row (`fields: [...]`) and of the types nested in them; everything else is
//! taken from the Rust types (offsets, sizes, array shapes, the schema's type names), and a
//! compile-time check refuses a list that misses a field or a byte of padding.
//!
//! What reads a sample by its fields, whatever its topic, reads them here: the recording's
//! schema (`recording::layout`), the CDR walker that prints a sample (`recording::walk`:
//! `handblocks echo` and `inspect --samples`) and Python's arrays. So a topic added to the
//! table prints, records and reaches Python with no code of its own.

use std::mem::size_of;

/// A number type of the schema, as ROS 2 message definitions name it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scalar {
    Float64,
    Uint64,
    Int64,
    Uint32,
    Int32,
    Uint8,
}

impl Scalar {
    /// The ROS 2 name (`float64`).
    pub const fn name(self) -> &'static str {
        match self {
            Scalar::Float64 => "float64",
            Scalar::Uint64 => "uint64",
            Scalar::Int64 => "int64",
            Scalar::Uint32 => "uint32",
            Scalar::Int32 => "int32",
            Scalar::Uint8 => "uint8",
        }
    }

    /// Bytes of one value (CDR aligns each value to its size).
    pub const fn size(self) -> usize {
        match self {
            Scalar::Float64 | Scalar::Uint64 | Scalar::Int64 => 8,
            Scalar::Uint32 | Scalar::Int32 => 4,
            Scalar::Uint8 => 1,
        }
    }
}

/// What one value of a field is: a number, or a nested message (a [`Schema`] of its own).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Base {
    Scalar(Scalar),
    Message(&'static Schema),
}

/// What a field's numbers mean beyond their type: what readers that show a field (not only
/// carry its bytes) need to know about it, declared in the table beside the field's name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Meaning {
    /// A quantity or an index: shown as it is.
    Number,
    /// A `uint32` that is 0 or 1 (`tracked`): Python shows it as a bool.
    Flag,
    /// An enumeration: value `v` is named `names[v]` (a block's `mode`); the schema lists the
    /// names as constants, `echo` prints the name beside the value.
    Names(&'static [&'static str]),
    /// The number of elements of the slice that follows a slice topic's header
    /// (`block_count`): a reader of many samples has it as its arrays' width.
    Length,
    /// Padding that makes the C layout the CDR one (a Rust field named `_reserved`): in the
    /// schema, so that every byte is named, but no reader shows it.
    Reserved,
}

/// One field of a sample (or of a type nested in one): where it is and what it holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Field {
    /// The Rust field's name without a leading `_` (`_reserved` is `reserved`).
    pub name: &'static str,
    /// The ROS 2 field type: `float64[75]`, or a nested message such as `handblocks/Pose`.
    /// Multi-dimensional arrays are flattened (row-major, as in memory); [`Field::dims`] keeps
    /// their shape.
    pub ty: &'static str,
    pub offset: usize,
    pub size: usize,
    /// One value's type.
    pub base: Base,
    /// The array's shape, outermost first (`[5, 5, 3]` for `[[[f64; 3]; 5]; 5]`); empty for
    /// one value.
    pub dims: &'static [usize],
    pub meaning: Meaning,
}

impl Field {
    /// The values (or nested messages) the field holds: the product of its dims.
    pub const fn count(&self) -> usize {
        product(self.dims)
    }

    /// The nested message's schema, for a field of messages.
    pub const fn message(&self) -> Option<&'static Schema> {
        match self.base {
            Base::Message(s) => Some(s),
            Base::Scalar(_) => None,
        }
    }

    /// A field made from a Rust field: `ident` its name, `offset` its `offset_of!`, and
    /// `_of` a function that reads it, which names its type `F` without spelling it out.
    pub const fn of<T, F: FieldValue>(
        ident: &'static str,
        offset: usize,
        meaning: Meaning,
        _of: fn(&T) -> &F,
    ) -> Field {
        let bytes = ident.as_bytes();
        let (name, meaning) = if !bytes.is_empty() && bytes[0] == b'_' {
            // SAFETY: an identifier is ASCII; dropping its first byte leaves valid UTF-8.
            let rest = unsafe { std::str::from_utf8_unchecked(bytes.split_at(1).1) };
            (rest, Meaning::Reserved)
        } else {
            (ident, meaning)
        };
        Field {
            name,
            ty: F::TYPE_NAME,
            offset,
            size: size_of::<F>(),
            base: F::BASE,
            dims: F::DIMS_SLICE,
            meaning,
        }
    }
}

/// The fields of one message type: a sample type (`handblocks/msg/GloveSample`) or a type
/// nested in them (`handblocks/Pose`).
#[derive(Debug, PartialEq, Eq)]
pub struct Schema {
    /// The schema name a recording gives it.
    pub name: &'static str,
    /// Its bytes (of a slice topic's schema, its header's).
    pub size: usize,
    /// In memory order, covering every byte.
    pub fields: &'static [Field],
    /// A slice topic's schema: the elements after its header.
    pub elements: Option<Elements>,
}

/// The elements of a slice topic, by name (`blocks`) and type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Elements {
    pub name: &'static str,
    pub schema: &'static Schema,
}

impl Schema {
    /// The alignment CDR gives the type: its widest number's.
    pub const fn align(&self) -> usize {
        let mut align = 1;
        let mut i = 0;
        while i < self.fields.len() {
            let a = field_align(&self.fields[i]);
            if a > align {
                align = a;
            }
            i += 1;
        }
        align
    }

    /// True when the fields lie one after the other from byte 0 to the end, each at a multiple
    /// of its alignment: the C layout is then the CDR one, and no byte is padding the schema
    /// does not name (every byte of a sample is initialised, so it may be read as bytes).
    pub const fn covers_every_byte(&self) -> bool {
        let mut at = 0;
        let mut i = 0;
        while i < self.fields.len() {
            let f = &self.fields[i];
            if f.offset != at || !f.offset.is_multiple_of(field_align(f)) {
                return false;
            }
            at += f.size;
            i += 1;
        }
        at == self.size
    }

    /// This schema or one nested in it (at any depth, its elements' included) named `name`.
    pub fn find(&'static self, name: &str) -> Option<&'static Schema> {
        if self.name == name {
            return Some(self);
        }
        self.fields
            .iter()
            .filter_map(|f| f.message())
            .chain(self.elements.map(|e| e.schema))
            .find_map(|s| s.find(name))
    }
}

const fn field_align(f: &Field) -> usize {
    match f.base {
        Base::Scalar(s) => s.size(),
        Base::Message(m) => m.align(),
    }
}

const fn product(dims: &[usize]) -> usize {
    let mut p = 1;
    let mut i = 0;
    while i < dims.len() {
        p *= dims[i];
        i += 1;
    }
    p
}

/// The deepest array a field may be (`[[[f64; 3]; 5]; 5]`).
const MAX_RANK: usize = 3;

/// A type a field may have: a number, a message of the table, or an array of them. Its
/// associated constants are what [`Field::of`] reads.
pub trait FieldValue {
    /// One value's type.
    const BASE: Base;
    /// One value's type name (`float64`, `handblocks/Pose`).
    const BASE_NAME: &'static str;
    /// The array's shape (the first [`FieldValue::RANK`] entries).
    const DIMS: [usize; MAX_RANK];
    const RANK: usize;
    /// The schema's type: the base name, and `[n]` (all values, flattened) for an array.
    const TYPE_NAME: &'static str;
    /// [`FieldValue::DIMS`] cut to the rank.
    const DIMS_SLICE: &'static [usize];
}

macro_rules! scalar_value {
    ($($t:ty => $s:ident),* $(,)?) => {
        $(
            impl FieldValue for $t {
                const BASE: Base = Base::Scalar(Scalar::$s);
                const BASE_NAME: &'static str = Scalar::$s.name();
                const DIMS: [usize; MAX_RANK] = [0; MAX_RANK];
                const RANK: usize = 0;
                const TYPE_NAME: &'static str = Scalar::$s.name();
                const DIMS_SLICE: &'static [usize] = &[];
            }
        )*
    };
}

scalar_value!(f64 => Float64, u64 => Uint64, i64 => Int64, u32 => Uint32, i32 => Int32, u8 => Uint8);

impl<T: FieldValue, const N: usize> FieldValue for [T; N] {
    const BASE: Base = T::BASE;
    const BASE_NAME: &'static str = T::BASE_NAME;
    const DIMS: [usize; MAX_RANK] = {
        assert!(T::RANK < MAX_RANK, "a field of more than three dimensions");
        let mut d = [0; MAX_RANK];
        d[0] = N;
        let mut i = 0;
        while i < T::RANK {
            d[i + 1] = T::DIMS[i];
            i += 1;
        }
        d
    };
    const RANK: usize = T::RANK + 1;
    const TYPE_NAME: &'static str = {
        let name: &'static TypeName = &TypeName::array(T::BASE_NAME, N * product(T::DIMS_SLICE));
        name.as_str()
    };
    const DIMS_SLICE: &'static [usize] = {
        let dims: &'static [usize; MAX_RANK] = &Self::DIMS;
        dims.split_at(Self::RANK).0
    };
}

/// A message type of the table (a sample type, or a type nested in one): its field list.
pub trait Message {
    const SCHEMA: &'static Schema;
}

/// An array's schema type name, `base[count]`, written at compile time.
struct TypeName {
    bytes: [u8; 64],
    len: usize,
}

impl TypeName {
    const fn array(base: &str, count: usize) -> TypeName {
        let mut t = TypeName {
            bytes: [0; 64],
            len: 0,
        };
        t = t.push(base.as_bytes());
        t = t.push(b"[");
        let mut digits = [0u8; 20];
        let (mut n, mut k) = (count, 0);
        loop {
            digits[k] = b'0' + (n % 10) as u8;
            k += 1;
            n /= 10;
            if n == 0 {
                break;
            }
        }
        while k > 0 {
            k -= 1;
            t = t.push(&[digits[k]]);
        }
        t.push(b"]")
    }

    const fn push(mut self, s: &[u8]) -> TypeName {
        let mut i = 0;
        while i < s.len() {
            self.bytes[self.len] = s[i];
            self.len += 1;
            i += 1;
        }
        self
    }

    const fn as_str(&'static self) -> &'static str {
        // SAFETY: made of a type name (UTF-8), ASCII brackets and ASCII digits.
        unsafe { std::str::from_utf8_unchecked(self.bytes.split_at(self.len).0) }
    }
}

/// Declares nested message types of the table: a schema name and the fields in memory order,
/// each optionally with its [`Meaning`] (`mode (names MODES)`, `tracked (flag)`,
/// `block_count (length)`).
macro_rules! message_types {
    ($($t:ident: $name:literal [$($field:ident $(($($meaning:tt)*))?),* $(,)?]),* $(,)?) => {
        $(
            message_type!($t, $name, None, [$($field $(($($meaning)*))?),*]);
        )*
    };
}

/// The [`Message`] and [`FieldValue`] impls of one type, and the check that its field list
/// covers it.
macro_rules! message_type {
    ($t:ty, $name:expr, $elements:expr, [$($field:ident $(($($meaning:tt)*))?),*]) => {
        impl $crate::topic::fields::Message for $t {
            const SCHEMA: &'static $crate::topic::fields::Schema = &$crate::topic::fields::Schema {
                name: $name,
                size: ::std::mem::size_of::<$t>(),
                fields: &[$(
                    $crate::topic::fields::Field::of::<$t, _>(
                        stringify!($field),
                        ::std::mem::offset_of!($t, $field),
                        meaning!($($($meaning)*)?),
                        |s| &s.$field,
                    )
                ),*],
                elements: $elements,
            };
        }
        impl $crate::topic::fields::FieldValue for $t {
            const BASE: $crate::topic::fields::Base = $crate::topic::fields::Base::Message(
                <$t as $crate::topic::fields::Message>::SCHEMA,
            );
            const BASE_NAME: &'static str = $name;
            const DIMS: [usize; 3] = [0; 3];
            const RANK: usize = 0;
            const TYPE_NAME: &'static str = $name;
            const DIMS_SLICE: &'static [usize] = &[];
        }
        const _: () = assert!(
            <$t as $crate::topic::fields::Message>::SCHEMA.covers_every_byte(),
            concat!(
                "the field list of ", stringify!($t), " in the topic table (common/src/topic.rs) \
                 must name every field of the struct, in memory order, each at a multiple of its \
                 size (no implicit padding)"
            )
        );
    };
}

/// A field's [`Meaning`] from the table's annotation.
macro_rules! meaning {
    () => {
        $crate::topic::fields::Meaning::Number
    };
    (flag) => {
        $crate::topic::fields::Meaning::Flag
    };
    (length) => {
        $crate::topic::fields::Meaning::Length
    };
    (names $names:expr) => {
        $crate::topic::fields::Meaning::Names(&$names)
    };
}

pub(crate) use {meaning, message_type, message_types};

#[cfg(test)]
mod tests {
    use super::*;

    #[repr(C)]
    struct Probe {
        a: f64,
        b: [[f64; 3]; 5],
        c: [u32; 2],
        _reserved: u64,
    }

    #[test]
    fn a_field_is_named_typed_and_shaped_from_its_rust_type() {
        let b = Field::of::<Probe, _>("b", 8, Meaning::Number, |s| &s.b);
        assert_eq!(b.ty, "float64[15]");
        assert_eq!(b.dims, &[5, 3]);
        assert_eq!((b.size, b.count()), (120, 15));
        let c = Field::of::<Probe, _>("c", 128, Meaning::Number, |s| &s.c);
        assert_eq!((c.ty, c.base), ("uint32[2]", Base::Scalar(Scalar::Uint32)));
        let r = Field::of::<Probe, _>("_reserved", 136, Meaning::Number, |s| &s._reserved);
        assert_eq!(
            (r.name, r.ty, r.meaning),
            ("reserved", "uint64", Meaning::Reserved)
        );
        let a = Field::of::<Probe, _>("a", 0, Meaning::Flag, |s| &s.a);
        assert_eq!(
            (a.ty, a.dims, a.meaning),
            ("float64", &[][..], Meaning::Flag)
        );
        let fields = [a, b, c, r];
        let probe = Schema {
            name: "probe",
            size: size_of::<Probe>(),
            fields: Box::leak(Box::new(fields)),
            elements: None,
        };
        assert!(probe.covers_every_byte());
        let gap = Schema {
            fields: Box::leak(Box::new([a, c, r])),
            ..probe
        };
        assert!(!gap.covers_every_byte());
    }
}
