//! `handblocks.Session`: a running session seen from Python, as `handblocks echo` sees it. Its
//! launcher's card says how to open its bus; a subscription is one more reader of one topic,
//! and each sample it yields is the publisher's shared memory itself, viewed by numpy arrays
//! (read-only) for as long as the sample (or any array viewing it) is alive.
//!
//! A live session's publishers overwrite a reader's oldest unread sample rather than wait for
//! it, so a slow Python loop costs the pipeline nothing (it loses samples, counted as gaps); a
//! lossless session (a speed-0 replay) would wait for every reader, so it is refused.
//!
//! A subscription is the bus's run-time inlet (`AnyInlet`), whatever the topic, and a
//! sample's fields are its topic's field list as Python names them (`crate::arrays::leaves`),
//! so a topic added to the table is read here with no code of its own.

use std::rc::Rc;
use std::time::{Duration, Instant};

use numpy::{Element, PyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use common::bus::{AnyInlet, AnySample, Bus, BusError, RunningSession};
use common::topic::{Meaning, Scalar};
use common::{Stamp, Topic};

use crate::arrays::{leaves, Leaf};
use crate::SessionError;

fn bus_err(e: BusError) -> PyErr {
    SessionError::new_err(e.to_string())
}

/// This program's node on a session's bus, shared by the session and its subscriptions. When
/// the last of them goes the node goes, and if the session has ended meanwhile, what the node
/// left of it is removed ([`RunningSession::tidy_after_reader`]): a program that held its
/// `Session` past the session's end leaves nothing in /dev/shm.
struct Attached {
    /// None only while being dropped.
    bus: Option<Bus>,
    running: RunningSession,
}

impl std::ops::Deref for Attached {
    type Target = Bus;
    fn deref(&self) -> &Bus {
        self.bus
            .as_ref()
            .expect("the bus is taken only when the last holder drops it")
    }
}

impl Drop for Attached {
    fn drop(&mut self) {
        drop(self.bus.take());
        self.running.tidy_after_reader();
    }
}

/// A running session (the Python class `handblocks.Session` wraps it).
#[pyclass(module = "handblocks._native", unsendable, name = "NativeSession")]
pub struct NativeSession {
    running: RunningSession,
    bus: Rc<Attached>,
}

#[pymethods]
impl NativeSession {
    /// The session `bus_id` names, or the only one running.
    #[new]
    #[pyo3(signature = (bus_id=None))]
    fn new(bus_id: Option<&str>) -> PyResult<NativeSession> {
        let running = RunningSession::find(bus_id).map_err(SessionError::new_err)?;
        // iceoryx2 would warn, raw, about the files the launcher removes at the session's
        // end; the subscription says the session ended (it yields None) instead.
        RunningSession::quiet_bus_log();
        let bus = Bus::open(&running.bus, "python").map_err(bus_err)?;
        Ok(NativeSession {
            bus: Rc::new(Attached {
                bus: Some(bus),
                running: running.clone(),
            }),
            running,
        })
    }

    #[getter]
    fn id(&self) -> String {
        self.running.bus.id.clone()
    }

    #[getter]
    fn session_file(&self) -> String {
        self.running.session_file.clone()
    }

    /// Its source's kind: `scripted`, `devices`, `replay`, `remote`, `webxr`, `external`.
    #[getter]
    fn source(&self) -> String {
        self.running.source.clone()
    }

    #[getter]
    fn lossless(&self) -> bool {
        self.running.bus.lossless
    }

    #[getter]
    fn world_blocks(&self) -> usize {
        self.running.bus.world_blocks
    }

    #[getter]
    fn started_unix_s(&self) -> u64 {
        self.running.started_unix_s
    }

    /// True while the session's launcher runs.
    fn is_running(&self) -> bool {
        self.running.is_running()
    }

    /// The processes attached to its bus: (name, pid).
    fn processes(&self) -> Vec<(String, u32)> {
        self.running.processes()
    }

    /// Per topic: how many publishers and subscribers are attached now.
    fn topics<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.still_running()?;
        let services = self.bus.create_services().map_err(bus_err)?;
        let out = PyDict::new(py);
        for t in Topic::RECORDED {
            let d = PyDict::new(py);
            d.set_item("publishers", services.publishers(t))?;
            d.set_item("subscribers", services.subscribers(t))?;
            out.set_item(t.name(), d)?;
        }
        Ok(out)
    }

    /// A reader of `topic`.
    fn subscribe(&self, topic: &str) -> PyResult<Subscription> {
        let t = crate::recorded_topic(topic)?;
        self.still_running()?;
        if self.running.bus.lossless {
            return Err(SessionError::new_err(format!(
                "session {} is a lossless replay (speed 0): its publishers wait for every \
                 reader, so a reader here would slow it; replay at a speed above 0 to read it",
                self.running.bus.id
            )));
        }
        let inlet = self.bus.any_inlet(t).map_err(bus_err)?;
        Ok(Subscription {
            _bus: Rc::clone(&self.bus),
            running: self.running.clone(),
            inlet,
            last_check: Instant::now(),
            ended: false,
        })
    }
}

impl NativeSession {
    /// Refuses to open a port on a session that has ended: opening one would make its
    /// services again, in files nobody removes.
    fn still_running(&self) -> PyResult<()> {
        if self.running.is_running() {
            Ok(())
        } else {
            Err(SessionError::new_err(format!(
                "session {} has ended (`handblocks sessions` lists those that run)",
                self.running.bus.id
            )))
        }
    }
}

/// How often a waiting subscription looks whether the session still runs and whether Python
/// has a signal (Ctrl-C) to deliver (it sleeps with the interpreter's lock released).
const LOOK_EVERY: Duration = Duration::from_millis(100);

/// One reader of one topic (the Python class `handblocks.Subscription` wraps it).
#[pyclass(module = "handblocks._native", unsendable)]
pub struct Subscription {
    running: RunningSession,
    inlet: AnyInlet,
    last_check: Instant,
    ended: bool,
    /// The node the inlet belongs to: declared last, so dropped after the inlet (the node's
    /// last holder then removes what is left of an ended session).
    _bus: Rc<Attached>,
}

#[pymethods]
impl Subscription {
    /// The next sample, waiting at most `timeout` seconds (None: until the session ends);
    /// None when none came in time or the session ended.
    #[pyo3(signature = (timeout=None))]
    fn receive(&mut self, py: Python<'_>, timeout: Option<f64>) -> PyResult<Option<LiveSample>> {
        let deadline = match timeout {
            Some(t) if !(t.is_finite() && t >= 0.0) => {
                return Err(pyo3::exceptions::PyValueError::new_err(format!(
                    "timeout={t}: seconds, at least 0, or None to wait until the session ends"
                )))
            }
            Some(t) => Some(Instant::now() + Duration::from_secs_f64(t.min(1e9))),
            None => None,
        };
        loop {
            match self.inlet.receive() {
                Ok(Some(held)) => {
                    return Ok(Some(LiveSample {
                        held,
                        received_ns: common::monotonic_ns(),
                    }))
                }
                Ok(None) => {}
                Err(e) => {
                    return Err(SessionError::new_err(format!(
                        "{e} (a reader may hold only so many samples at once: copy what you \
                         keep, `sample.copy()`, and let the samples go)"
                    )))
                }
            }
            if self.ended {
                return Ok(None);
            }
            let now = Instant::now();
            if now.duration_since(self.last_check) >= LOOK_EVERY {
                self.last_check = now;
                py.check_signals()?;
                if !self.running.is_running() {
                    // Take what the session published before it ended, then stop.
                    self.ended = true;
                    continue;
                }
            }
            let wait = match deadline {
                Some(d) if now >= d => return Ok(None),
                Some(d) => (d - now).min(LOOK_EVERY),
                None => LOOK_EVERY,
            };
            // Asleep with the interpreter's lock released: the program's other threads (a
            // GUI, a plot) run meanwhile.
            // (A Python program's bus is no stage's, so its inlets always have a descriptor;
            // without one it would look again every millisecond.)
            match common::bus::wake_fd(&self.inlet) {
                Some(fd) => py
                    .detach(|| common::bus::wait_fd(fd, wait))
                    .map_err(bus_err)?,
                None => py.detach(|| std::thread::sleep(wait.min(Duration::from_millis(1)))),
            }
            common::bus::take_wake_ups(&self.inlet);
        }
    }

    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__(&mut self, py: Python<'_>) -> PyResult<Option<LiveSample>> {
        self.receive(py, None)
    }

    /// Samples received, and samples missed (gaps in their seqs: the publisher overwrote
    /// them before this reader took them).
    fn counts(&self) -> (u64, u64) {
        let c = self.inlet.counter();
        (c.count, c.gaps)
    }
}

/// One sample as it lies in shared memory: its stamp as attributes, its fields as read-only
/// numpy views of that memory (`fields()`, or by name: `sample.position`).
#[pyclass(module = "handblocks._native", unsendable)]
pub struct LiveSample {
    /// Held in the publisher's shared memory.
    held: AnySample,
    /// CLOCK_MONOTONIC when this reader took it.
    #[pyo3(get)]
    received_ns: u64,
}

impl LiveSample {
    fn stamp(&self) -> &Stamp {
        self.held.stamp()
    }
}

/// A read-only numpy view of `shape` elements of `T` from `ptr`, with `strides` in elements,
/// that keeps `owner` (the sample) alive.
///
/// # Safety
/// `ptr` with `shape` and `strides` must stay within memory `owner` keeps alive and unchanged
/// while it is alive: a held iceoryx2 sample, which its publisher does not reuse until it is
/// released.
unsafe fn view<'py, T: Element>(
    owner: &Bound<'py, LiveSample>,
    ptr: *const T,
    shape: &[usize],
    strides: &[usize],
) -> PyResult<Bound<'py, PyAny>> {
    use numpy::ndarray::{ArrayViewD, IxDyn, ShapeBuilder};
    let v = ArrayViewD::from_shape_ptr(IxDyn(shape).strides(IxDyn(strides)), ptr);
    let array = PyArrayDyn::borrow_from_array(&v, owner.clone().into_any());
    // Read-only: the memory is the publisher's. (The flag itself, as rust-numpy's
    // `make_nonwriteable` sets it, without its borrow bookkeeping on every sample.)
    (*numpy::npyffi::_PyArray_GET_ITEM_DATA(array.as_array_ptr())).flags &=
        !numpy::npyffi::NPY_ARRAY_WRITEABLE;
    Ok(array.into_any())
}

#[pymethods]
impl LiveSample {
    #[getter]
    fn topic(&self) -> &'static str {
        self.held.topic().name()
    }

    #[getter]
    fn seq(&self) -> u64 {
        self.stamp().seq
    }

    /// The source's own time of the sample (a world: of the hand it stepped to).
    #[getter]
    fn time_ns(&self) -> u64 {
        self.stamp().source_time_ns
    }

    #[getter]
    fn origin_ns(&self) -> u64 {
        self.stamp().origin_ns
    }

    #[getter]
    fn publish_ns(&self) -> u64 {
        self.stamp().publish_ns
    }

    /// A field by name (`sample.position`): one of [`LiveSample::fields`], made alone.
    fn __getattr__<'py>(slf: &Bound<'py, Self>, name: &str) -> PyResult<Bound<'py, PyAny>> {
        field(slf, name)?.ok_or_else(|| {
            let this = slf.borrow();
            pyo3::exceptions::PyAttributeError::new_err(format!(
                "a {} sample has no field {name:?}; its fields: seq, time_ns, origin_ns, \
                 publish_ns, received_ns, {}",
                this.topic(),
                this.field_names().join(", ")
            ))
        })
    }

    /// The stamp and every field, copied out of shared memory (arrays the caller owns), so
    /// the sample itself can go back to its publisher.
    fn copy<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyDict>> {
        let fields = Self::fields(slf)?;
        let out = PyDict::new(slf.py());
        let this = slf.borrow();
        out.set_item("seq", this.seq())?;
        out.set_item("time_ns", this.time_ns())?;
        out.set_item("origin_ns", this.origin_ns())?;
        out.set_item("publish_ns", this.publish_ns())?;
        out.set_item("received_ns", this.received_ns)?;
        for (k, v) in fields.iter() {
            let owned = if v.hasattr("copy")? {
                v.call_method0("copy")?
            } else {
                v
            };
            out.set_item(k, owned)?;
        }
        Ok(out)
    }

    fn __repr__(&self) -> String {
        format!(
            "<handblocks {} sample seq {} time_ns {}>",
            self.topic(),
            self.seq(),
            self.time_ns()
        )
    }

    /// The sample's fields by name: scalars as Python numbers, arrays as read-only numpy
    /// views of the shared memory (valid while this sample or a view of it is alive).
    fn fields<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyDict>> {
        let out = PyDict::new(slf.py());
        let topic = slf.borrow().held.topic();
        for leaf in leaves(topic) {
            out.set_item(&leaf.name, value(slf, leaf)?)?;
        }
        Ok(out)
    }
}

impl LiveSample {
    /// The fields of this sample's topic, as [`field`] makes them.
    fn field_names(&self) -> Vec<&'static str> {
        leaves(self.held.topic())
            .iter()
            .map(|l| l.name.as_str())
            .collect()
    }
}

/// One field of the sample `slf` holds, by name (None: the topic has no such field): a scalar
/// as a Python number, an array as a read-only view of the shared memory. Only the field asked
/// for is made, so `sample.position` costs one view.
fn field<'py>(slf: &Bound<'py, LiveSample>, name: &str) -> PyResult<Option<Bound<'py, PyAny>>> {
    let topic = slf.borrow().held.topic();
    match leaves(topic).iter().find(|l| l.name == name) {
        Some(leaf) => value(slf, leaf).map(Some),
        None => Ok(None),
    }
}

/// The value of `leaf` in the sample `slf` holds: one number as a Python number (a flag as a
/// bool), an array as a read-only numpy view of the shared memory (a slice topic's element
/// leaves with the elements as their first axis).
fn value<'py>(slf: &Bound<'py, LiveSample>, leaf: &Leaf) -> PyResult<Bound<'py, PyAny>> {
    let py = slf.py();
    let this = slf.borrow();
    let sample = this.held.view();
    let (bytes, mut shape, mut strides) = if leaf.per_element {
        let each = sample.topic().element_size().unwrap_or(0);
        (sample.elements(), vec![sample.len()], vec![each])
    } else {
        (sample.sample(), Vec::new(), Vec::new())
    };
    shape.extend_from_slice(&leaf.shape);
    strides.extend_from_slice(&leaf.strides);
    let size = leaf.scalar.size();
    if shape.is_empty() {
        let mut b = [0u8; 8];
        let n = size.min(8);
        if let Some(v) = bytes.get(leaf.offset..leaf.offset + n) {
            b[..n].copy_from_slice(v);
        }
        let w = [b[0], b[1], b[2], b[3]];
        return Ok(match (leaf.scalar, leaf.meaning) {
            (_, Meaning::Flag) => pyo3::types::PyBool::new(py, b.iter().any(|x| *x != 0))
                .to_owned()
                .into_any(),
            (Scalar::Float64, _) => f64::from_le_bytes(b).into_pyobject(py)?.into_any(),
            (Scalar::Uint64, _) => u64::from_le_bytes(b).into_pyobject(py)?.into_any(),
            (Scalar::Int64, _) => i64::from_le_bytes(b).into_pyobject(py)?.into_any(),
            (Scalar::Uint32, _) => u32::from_le_bytes(w).into_pyobject(py)?.into_any(),
            (Scalar::Int32, _) => i32::from_le_bytes(w).into_pyobject(py)?.into_any(),
            (Scalar::Uint8, _) => b[0].into_pyobject(py)?.into_any(),
        });
    }
    // The last byte the view reaches must lie within the sample's memory.
    let reach = leaf.offset
        + shape
            .iter()
            .zip(&strides)
            .map(|(n, step)| n.saturating_sub(1) * step)
            .sum::<usize>()
        + size;
    let empty = shape.contains(&0);
    if !empty && reach > bytes.len() {
        return Err(SessionError::new_err(format!(
            "the {} field {} lies past its sample's {} bytes",
            sample.topic().name(),
            leaf.name,
            bytes.len()
        )));
    }
    // In elements of the leaf's type: every field lies at a multiple of its size.
    let steps: Vec<usize> = strides.iter().map(|s| s / size).collect();
    let base = bytes.as_ptr().wrapping_add(leaf.offset);
    // SAFETY: `base` with `shape` and `steps` stays within the sample's bytes (checked above;
    // an empty view reads nothing), which `slf` holds in shared memory for as long as the
    // view, which keeps `slf` alive, lives; every field is aligned to its type's size in a
    // sample the bus aligned for its type.
    unsafe {
        match leaf.scalar {
            Scalar::Float64 => view(slf, base as *const f64, &shape, &steps),
            Scalar::Uint64 => view(slf, base as *const u64, &shape, &steps),
            Scalar::Int64 => view(slf, base as *const i64, &shape, &steps),
            Scalar::Uint32 => view(slf, base as *const u32, &shape, &steps),
            Scalar::Int32 => view(slf, base as *const i32, &shape, &steps),
            Scalar::Uint8 => view(slf, base, &shape, &steps),
        }
    }
}
