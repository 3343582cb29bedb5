//! numpy arrays from the samples: each topic's fields as Python names and shapes them
//! ([`leaves`], from the topic table's field list), read in place from a live sample
//! (`session.rs`) or copied into columns, one row per sample, from a recording's
//! (`recording.rs`): one copy, into memory numpy then owns.
//!
//! Python's names follow from the field list by one rule, so a topic added to the table
//! reaches Python with no code here: each number or array of numbers (a *leaf*) is named as its
//! field, and a leaf of a message nested once at the sample's top level takes that field's
//! name as a prefix (the tracker's `wrist` gives `wrist_position`, `wrist_rotation`); inside an
//! array of messages or a slice topic's elements the leaves keep their own names, the array
//! becoming their first axis (a joints sample's `joints` give `position (26, 3)`, a world's
//! blocks `position (blocks, 3)` and `mode`). The stamp is the sample's attributes (`seq`,
//! `time_ns`, ...), not a field; padding is no field.

use std::sync::OnceLock;

use numpy::{Element, PyArray1, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use common::topic::{Base, Meaning, Message, SampleView, Scalar, Schema, Topic};
use common::Stamp;

/// Fields the Python API does not show, by name: a block's `held_by` (which hands grasp it),
/// added with two hands after `World`'s columns and a world sample's fields were fixed; its
/// holder is the world's `grasped_block` from Python.
const NOT_SHOWN: [&str; 1] = ["held_by"];

/// One number or array of numbers of a sample, as Python names and shapes it.
#[derive(Debug, Clone)]
pub struct Leaf {
    pub name: String,
    pub scalar: Scalar,
    pub meaning: Meaning,
    /// Where it lies: in each element of a slice topic (a world's blocks), else in the sample
    /// (a slice topic's header).
    pub per_element: bool,
    /// The byte offset of its first number, in the sample or in one element.
    pub offset: usize,
    /// Its shape within the sample (or element), and the byte step of each axis.
    pub shape: Vec<usize>,
    pub strides: Vec<usize>,
}

impl Leaf {
    /// Numbers it holds in one sample (or element).
    fn count(&self) -> usize {
        self.shape.iter().product()
    }

    /// The byte offset of each of its numbers, in row-major order, from `base`.
    fn offsets(&self, base: usize, mut each: impl FnMut(usize)) {
        fn walk(shape: &[usize], strides: &[usize], at: usize, each: &mut impl FnMut(usize)) {
            match (shape.split_first(), strides.split_first()) {
                (Some((&n, shape)), Some((&step, strides))) => {
                    for i in 0..n {
                        walk(shape, strides, at + i * step, each);
                    }
                }
                _ => each(at),
            }
        }
        walk(&self.shape, &self.strides, base + self.offset, &mut each);
    }
}

/// The leaves of `topic`'s samples, in the field list's order (the header's, then the
/// elements'), made once per topic.
pub fn leaves(topic: Topic) -> &'static [Leaf] {
    static LEAVES: OnceLock<Vec<Vec<Leaf>>> = OnceLock::new();
    let all = LEAVES.get_or_init(|| {
        Topic::ALL
            .iter()
            .map(|t| {
                let schema = t.schema();
                let mut out = Vec::new();
                let top = Place {
                    per_element: false,
                    offset: 0,
                    prefix: String::new(),
                    shape: Vec::new(),
                    strides: Vec::new(),
                    top: true,
                };
                collect(schema, &top, &mut out);
                if let Some(e) = schema.elements {
                    let each = Place {
                        per_element: true,
                        top: false,
                        ..top
                    };
                    collect(e.schema, &each, &mut out);
                }
                out
            })
            .collect()
    });
    all.get(topic as usize).map_or(&[], Vec::as_slice)
}

/// Where the fields being collected lie: in the sample or an element, from which byte, under
/// which prefix and array axes, and whether at the sample's top level.
#[derive(Clone)]
struct Place {
    per_element: bool,
    offset: usize,
    prefix: String,
    shape: Vec<usize>,
    strides: Vec<usize>,
    top: bool,
}

fn collect(schema: &Schema, at: &Place, out: &mut Vec<Leaf>) {
    for f in schema.fields {
        if f.meaning == Meaning::Reserved || NOT_SHOWN.contains(&f.name) {
            continue;
        }
        // The field's own axes, row-major over its values (or messages) of `each` bytes.
        let each = f.size / f.count().max(1);
        let mut shape = at.shape.clone();
        let mut strides = at.strides.clone();
        shape.extend_from_slice(f.dims);
        for k in 0..f.dims.len() {
            strides.push(each * f.dims[k + 1..].iter().product::<usize>());
        }
        match f.base {
            Base::Scalar(scalar) => out.push(Leaf {
                name: format!("{}{}", at.prefix, f.name),
                scalar,
                meaning: f.meaning,
                per_element: at.per_element,
                offset: at.offset + f.offset,
                shape,
                strides,
            }),
            // The stamp: the sample's attributes.
            Base::Message(m) if at.top && m == <Stamp as Message>::SCHEMA => {}
            Base::Message(m) => {
                let single = f.dims.is_empty() && at.top;
                let inner = Place {
                    per_element: at.per_element,
                    offset: at.offset + f.offset,
                    prefix: if single {
                        format!("{}{}_", at.prefix, f.name)
                    } else {
                        at.prefix.clone()
                    },
                    shape,
                    strides,
                    top: single,
                };
                collect(m, &inner, out);
            }
        }
    }
}

/// `data` as a numpy array of `shape` (C order; `data.len()` is the shape's product).
pub fn array<'py, T: Element>(
    py: Python<'py>,
    data: Vec<T>,
    shape: &[usize],
) -> PyResult<Bound<'py, PyAny>> {
    let flat = PyArray1::from_vec(py, data);
    Ok(flat.reshape(shape.to_vec())?.into_any())
}

/// One leaf's numbers over many samples, in its numpy type (a flag's as bools).
enum Column {
    F64(Vec<f64>),
    U64(Vec<u64>),
    I64(Vec<i64>),
    U32(Vec<u32>),
    I32(Vec<i32>),
    U8(Vec<u8>),
    Bool(Vec<bool>),
}

impl Column {
    fn new(leaf: &Leaf, n: usize) -> Column {
        match (leaf.scalar, leaf.meaning) {
            (_, Meaning::Flag) => Column::Bool(Vec::with_capacity(n)),
            (Scalar::Float64, _) => Column::F64(Vec::with_capacity(n)),
            (Scalar::Uint64, _) => Column::U64(Vec::with_capacity(n)),
            (Scalar::Int64, _) => Column::I64(Vec::with_capacity(n)),
            (Scalar::Uint32, _) => Column::U32(Vec::with_capacity(n)),
            (Scalar::Int32, _) => Column::I32(Vec::with_capacity(n)),
            (Scalar::Uint8, _) => Column::U8(Vec::with_capacity(n)),
        }
    }

    /// The number at `bytes` (as many as the leaf's type takes; missing ones read as 0).
    fn push(&mut self, bytes: &[u8]) {
        let mut b = [0u8; 8];
        let n = bytes.len().min(8);
        b[..n].copy_from_slice(&bytes[..n]);
        let w = [b[0], b[1], b[2], b[3]];
        match self {
            Column::F64(v) => v.push(f64::from_le_bytes(b)),
            Column::U64(v) => v.push(u64::from_le_bytes(b)),
            Column::I64(v) => v.push(i64::from_le_bytes(b)),
            Column::U32(v) => v.push(u32::from_le_bytes(w)),
            Column::I32(v) => v.push(i32::from_le_bytes(w)),
            Column::U8(v) => v.push(b[0]),
            Column::Bool(v) => v.push(b.iter().any(|x| *x != 0)),
        }
    }

    /// What stands for a number a sample does not have (an element past its last): NaN, 0,
    /// false.
    fn pad(&mut self) {
        match self {
            Column::F64(v) => v.push(f64::NAN),
            Column::U64(v) => v.push(0),
            Column::I64(v) => v.push(0),
            Column::U32(v) => v.push(0),
            Column::I32(v) => v.push(0),
            Column::U8(v) => v.push(0),
            Column::Bool(v) => v.push(false),
        }
    }

    fn into_array<'py>(self, py: Python<'py>, shape: &[usize]) -> PyResult<Bound<'py, PyAny>> {
        match self {
            Column::F64(v) => array(py, v, shape),
            Column::U64(v) => array(py, v, shape),
            Column::I64(v) => array(py, v, shape),
            Column::U32(v) => array(py, v, shape),
            Column::I32(v) => array(py, v, shape),
            Column::U8(v) => array(py, v, shape),
            Column::Bool(v) => array(py, v, shape),
        }
    }
}

/// `topic`'s samples as columns into `out`, one row per sample: the stamps, then each leaf
/// ([`leaves`]). A slice topic's element leaves are `(samples, elements, ...)`, as wide as the
/// sample with the most elements (the others padded: NaN, 0, false); the header's count of
/// them ([`Meaning::Length`]) is that width, so it is no column.
pub fn columns(topic: Topic, samples: &[SampleView<'_>], out: &Bound<'_, PyDict>) -> PyResult<()> {
    let py = out.py();
    let n = samples.len();
    let mut stamps = StampColumns::with_capacity(n);
    for s in samples {
        stamps.push(&s.stamp());
    }
    stamps.into_dict(out)?;
    let width = samples.iter().map(SampleView::len).max().unwrap_or(0);
    let element_size = topic.element_size().unwrap_or(0);
    for leaf in leaves(topic) {
        if leaf.meaning == Meaning::Length {
            continue;
        }
        let mut shape = vec![n];
        if leaf.per_element {
            shape.push(width);
        }
        shape.extend_from_slice(&leaf.shape);
        let mut column = Column::new(leaf, shape.iter().product());
        for s in samples {
            let (bytes, elements) = if leaf.per_element {
                (s.elements(), width)
            } else {
                (s.sample(), 1)
            };
            for e in 0..elements {
                if leaf.per_element && e >= s.len() {
                    (0..leaf.count()).for_each(|_| column.pad());
                    continue;
                }
                let size = leaf.scalar.size();
                leaf.offsets(e * element_size, |at| {
                    column.push(bytes.get(at..at + size).unwrap_or(&[]));
                });
            }
        }
        out.set_item(&leaf.name, column.into_array(py, &shape)?)?;
    }
    Ok(())
}

/// The stamp of every sample, as four columns: `seq`, `time_ns` (the source's own time),
/// `origin_ns` and `publish_ns` (CLOCK_MONOTONIC of the machine that ran the session).
#[derive(Default)]
pub struct StampColumns {
    seq: Vec<u64>,
    time_ns: Vec<u64>,
    origin_ns: Vec<u64>,
    publish_ns: Vec<u64>,
}

impl StampColumns {
    pub fn with_capacity(n: usize) -> StampColumns {
        StampColumns {
            seq: Vec::with_capacity(n),
            time_ns: Vec::with_capacity(n),
            origin_ns: Vec::with_capacity(n),
            publish_ns: Vec::with_capacity(n),
        }
    }

    pub fn push(&mut self, s: &Stamp) {
        self.seq.push(s.seq);
        self.time_ns.push(s.source_time_ns);
        self.origin_ns.push(s.origin_ns);
        self.publish_ns.push(s.publish_ns);
    }

    /// Puts the four columns into `out`.
    pub fn into_dict(self, out: &Bound<'_, PyDict>) -> PyResult<()> {
        let py = out.py();
        let n = self.seq.len();
        out.set_item("seq", array(py, self.seq, &[n])?)?;
        out.set_item("time_ns", array(py, self.time_ns, &[n])?)?;
        out.set_item("origin_ns", array(py, self.origin_ns, &[n])?)?;
        out.set_item("publish_ns", array(py, self.publish_ns, &[n])?)?;
        Ok(())
    }
}
