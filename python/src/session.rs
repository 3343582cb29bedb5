//! `handblocks.Session`: a running session seen from Python, as `handblocks echo` sees it. Its
//! launcher's card says how to open its bus; a subscription is one more reader of one topic,
//! and each sample it yields is the publisher's shared memory itself, viewed by numpy arrays
//! (read-only) for as long as the sample (or any array viewing it) is alive.
//!
//! A live session's publishers overwrite a reader's oldest unread sample rather than wait for
//! it, so a slow Python loop costs the pipeline nothing (it loses samples, counted as gaps); a
//! lossless session (a speed-0 replay) would wait for every reader, so it is refused.

use std::rc::Rc;
use std::time::{Duration, Instant};

use numpy::{Element, PyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use common::bus::{Bus, BusError, Inlet, Received, RunningSession, Wakeable};
use common::samples::{
    BlockState, Pose, MAX_FINGERS, MAX_FINGER_POINTS, MAX_GLOVE_SENSORS, MAX_PALM_VERTICES,
    OPENXR_JOINTS,
};
use common::{topics, Stamp, Topic};

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
        let bus = &self.bus;
        let inlet = match t {
            Topic::Glove => AnyInlet::Glove(bus.inlet().map_err(bus_err)?),
            Topic::Tracker => AnyInlet::Tracker(bus.inlet().map_err(bus_err)?),
            Topic::Joints => AnyInlet::Joints(bus.inlet().map_err(bus_err)?),
            Topic::Hand => AnyInlet::Hand(bus.inlet().map_err(bus_err)?),
            Topic::World => AnyInlet::World(bus.inlet().map_err(bus_err)?),
            _ => AnyInlet::Frame(bus.inlet().map_err(bus_err)?),
        };
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

enum AnyInlet {
    Glove(Inlet<topics::Glove>),
    Tracker(Inlet<topics::Tracker>),
    Joints(Inlet<topics::Joints>),
    Hand(Inlet<topics::Hand>),
    World(Inlet<topics::World>),
    Frame(Inlet<topics::Frame>),
}

impl AnyInlet {
    fn wakeable(&self) -> &dyn Wakeable {
        match self {
            AnyInlet::Glove(i) => i,
            AnyInlet::Tracker(i) => i,
            AnyInlet::Joints(i) => i,
            AnyInlet::Hand(i) => i,
            AnyInlet::World(i) => i,
            AnyInlet::Frame(i) => i,
        }
    }

    fn receive(&self) -> Result<Option<Held>, BusError> {
        Ok(match self {
            AnyInlet::Glove(i) => i.receive()?.map(Held::Glove),
            AnyInlet::Tracker(i) => i.receive()?.map(Held::Tracker),
            AnyInlet::Joints(i) => i.receive()?.map(Held::Joints),
            AnyInlet::Hand(i) => i.receive()?.map(Held::Hand),
            AnyInlet::World(i) => i.receive()?.map(Held::World),
            AnyInlet::Frame(i) => i.receive()?.map(Held::Frame),
        })
    }

    fn counter(&self) -> common::TopicCounter {
        match self {
            AnyInlet::Glove(i) => i.counter(),
            AnyInlet::Tracker(i) => i.counter(),
            AnyInlet::Joints(i) => i.counter(),
            AnyInlet::Hand(i) => i.counter(),
            AnyInlet::World(i) => i.counter(),
            AnyInlet::Frame(i) => i.counter(),
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
            let fd = common::bus::wake_fd(self.inlet.wakeable());
            py.detach(|| common::bus::wait_fd(fd, wait))
                .map_err(bus_err)?;
            common::bus::take_wake_ups(self.inlet.wakeable());
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

/// A sample held in the publisher's shared memory.
enum Held {
    Glove(Received<topics::Glove>),
    Tracker(Received<topics::Tracker>),
    Joints(Received<topics::Joints>),
    Hand(Received<topics::Hand>),
    World(Received<topics::World>),
    Frame(Received<topics::Frame>),
}

/// One sample as it lies in shared memory: its stamp as attributes, its fields as read-only
/// numpy views of that memory (`fields()`, or by name: `sample.position`).
#[pyclass(module = "handblocks._native", unsendable)]
pub struct LiveSample {
    held: Held,
    /// CLOCK_MONOTONIC when this reader took it.
    #[pyo3(get)]
    received_ns: u64,
}

impl LiveSample {
    fn stamp(&self) -> &Stamp {
        use common::bus::Stamped as _;
        match &self.held {
            Held::Glove(s) => s.payload().stamp(),
            Held::Tracker(s) => s.payload().stamp(),
            Held::Joints(s) => s.payload().stamp(),
            Held::Hand(s) => s.payload().stamp(),
            Held::World(s) => s.user_header().stamp(),
            Held::Frame(s) => s.payload().stamp(),
        }
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

const F64S_PER_POSE: usize = std::mem::size_of::<Pose>() / 8;

#[pymethods]
impl LiveSample {
    #[getter]
    fn topic(&self) -> &'static str {
        match &self.held {
            Held::Glove(_) => "glove",
            Held::Tracker(_) => "tracker",
            Held::Joints(_) => "joints",
            Held::Hand(_) => "hand",
            Held::World(_) => "world",
            Held::Frame(_) => "frame",
        }
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
        for name in slf.borrow().field_names() {
            if let Some(v) = field(slf, name)? {
                out.set_item(*name, v)?;
            }
        }
        Ok(out)
    }
}

impl LiveSample {
    /// The fields of this sample's topic, as [`field`] makes them.
    fn field_names(&self) -> &'static [&'static str] {
        match &self.held {
            Held::World(_) => &[
                "step",
                "hand_seq",
                "grasped_block",
                "block_count",
                "finger_count",
                "position",
                "rotation",
                "mode",
                "finger_point_count",
                "finger_points",
            ],
            Held::Hand(_) => &[
                "tracked",
                "side",
                "finger_count",
                "palm_vertex_count",
                "wrist_position",
                "wrist_rotation",
                "finger_point_count",
                "finger_points",
                "finger_radius",
                "palm_vertices",
            ],
            Held::Joints(_) => &[
                "tracked",
                "side",
                "wrist_position",
                "wrist_rotation",
                "position",
                "rotation",
            ],
            Held::Glove(_) => &["sensor_count", "side", "angles"],
            Held::Tracker(_) => &["station", "side", "wrist_position", "wrist_rotation"],
            Held::Frame(_) => &[
                "world_seq",
                "render_ns",
                "origin_to_photon_ns",
                "skipped_worlds",
            ],
        }
    }
}

/// One field of the sample `slf` holds, by name (None: the topic has no such field): a scalar
/// as a Python number, an array as a read-only view of the shared memory. Only the field asked
/// for is made, so `sample.position` costs one view.
fn field<'py>(slf: &Bound<'py, LiveSample>, name: &str) -> PyResult<Option<Bound<'py, PyAny>>> {
    let py = slf.py();
    let this = slf.borrow();
    let num = |v: u64| Ok(Some(v.into_pyobject(py)?.into_any()));
    let int = |v: i64| Ok(Some(v.into_pyobject(py)?.into_any()));
    let flag = |v: u32| {
        Ok(Some(
            pyo3::types::PyBool::new(py, v != 0).to_owned().into_any(),
        ))
    };
    // SAFETY (every `view` below): each pointer, shape and stride lies within the sample
    // `slf` holds, which the view keeps alive.
    unsafe {
        let pose = |p: &Pose, rotation: bool| {
            if rotation {
                view(slf, p.rotation.as_ptr(), &[4], &[1])
            } else {
                view(slf, p.position.as_ptr(), &[3], &[1])
            }
        };
        let fingers = |points: &[[[f64; 3]; MAX_FINGER_POINTS]; MAX_FINGERS]| {
            view(
                slf,
                points.as_ptr() as *const f64,
                &[MAX_FINGERS, MAX_FINGER_POINTS, 3],
                &[MAX_FINGER_POINTS * 3, 3, 1],
            )
        };
        match &this.held {
            Held::World(s) => {
                let h = s.user_header();
                let blocks: &[BlockState] = s.payload();
                let per_block = std::mem::size_of::<BlockState>() / 8;
                let base = blocks.as_ptr() as *const f64;
                let n = blocks.len();
                match name {
                    "step" => num(h.step),
                    "hand_seq" => num(h.hand_seq),
                    "grasped_block" => int(h.grasped_block.into()),
                    "block_count" => num(h.block_count.into()),
                    "finger_count" => num(h.finger_count.into()),
                    "position" => view(slf, base, &[n, 3], &[per_block, 1]).map(Some),
                    "rotation" => view(slf, base.add(3), &[n, 4], &[per_block, 1]).map(Some),
                    "mode" => view(
                        slf,
                        base.add(F64S_PER_POSE) as *const u32,
                        &[n],
                        &[per_block * 2],
                    )
                    .map(Some),
                    "finger_point_count" => {
                        view(slf, h.finger_point_count.as_ptr(), &[MAX_FINGERS], &[1]).map(Some)
                    }
                    "finger_points" => fingers(&h.finger_points).map(Some),
                    _ => Ok(None),
                }
            }
            Held::Hand(s) => {
                let h = s.payload();
                match name {
                    "tracked" => flag(h.tracked),
                    "side" => num(h.side.into()),
                    "finger_count" => num(h.finger_count.into()),
                    "palm_vertex_count" => num(h.palm_vertex_count.into()),
                    "wrist_position" => pose(&h.wrist, false).map(Some),
                    "wrist_rotation" => pose(&h.wrist, true).map(Some),
                    "finger_point_count" => {
                        view(slf, h.finger_point_count.as_ptr(), &[MAX_FINGERS], &[1]).map(Some)
                    }
                    "finger_points" => fingers(&h.finger_points).map(Some),
                    "finger_radius" => {
                        view(slf, h.finger_radius.as_ptr(), &[MAX_FINGERS], &[1]).map(Some)
                    }
                    "palm_vertices" => view(
                        slf,
                        h.palm_vertices.as_ptr() as *const f64,
                        &[MAX_PALM_VERTICES, 3],
                        &[3, 1],
                    )
                    .map(Some),
                    _ => Ok(None),
                }
            }
            Held::Joints(s) => {
                let j = s.payload();
                let base = j.joints.as_ptr() as *const f64;
                match name {
                    "tracked" => flag(j.tracked),
                    "side" => num(j.side.into()),
                    "wrist_position" => pose(&j.wrist, false).map(Some),
                    "wrist_rotation" => pose(&j.wrist, true).map(Some),
                    "position" => {
                        view(slf, base, &[OPENXR_JOINTS, 3], &[F64S_PER_POSE, 1]).map(Some)
                    }
                    "rotation" => {
                        view(slf, base.add(3), &[OPENXR_JOINTS, 4], &[F64S_PER_POSE, 1]).map(Some)
                    }
                    _ => Ok(None),
                }
            }
            Held::Glove(s) => {
                let g = s.payload();
                match name {
                    "sensor_count" => num(g.sensor_count.into()),
                    "side" => num(g.side.into()),
                    "angles" => view(slf, g.angles.as_ptr(), &[MAX_GLOVE_SENSORS], &[1]).map(Some),
                    _ => Ok(None),
                }
            }
            Held::Tracker(s) => {
                let t = s.payload();
                match name {
                    "station" => num(t.station.into()),
                    "side" => num(t.side.into()),
                    "wrist_position" => pose(&t.wrist, false).map(Some),
                    "wrist_rotation" => pose(&t.wrist, true).map(Some),
                    _ => Ok(None),
                }
            }
            Held::Frame(s) => {
                let f = s.payload();
                match name {
                    "world_seq" => num(f.world_seq),
                    "render_ns" => num(f.render_ns),
                    "origin_to_photon_ns" => num(f.origin_to_photon_ns),
                    "skipped_worlds" => num(f.skipped_worlds),
                    _ => Ok(None),
                }
            }
        }
    }
}
