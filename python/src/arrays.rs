//! numpy arrays from the columns Rust collects: one copy, into memory numpy then owns.

use numpy::{Element, PyArray1, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use common::Stamp;

/// `data` as a numpy array of `shape` (C order; `data.len()` is the shape's product).
pub fn array<'py, T: Element>(
    py: Python<'py>,
    data: Vec<T>,
    shape: &[usize],
) -> PyResult<Bound<'py, PyAny>> {
    let flat = PyArray1::from_vec(py, data);
    Ok(flat.reshape(shape.to_vec())?.into_any())
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
