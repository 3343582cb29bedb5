//! `handblocks.Source`: a Python program as the session's source (`[source] kind =
//! "external"`). The launcher starts the program from `[source] command` with the session's
//! bus id in `HANDBLOCKS_BUS`; the program publishes OpenXR hand joints with their time, and
//! this module makes each one a `joints` sample exactly as a replay or a headset does: stamped
//! (`seq`, the program's `time_ns` as source time, `origin_ns` = now, `publish_ns`), checked
//! (each joint as every source's are, [`common::Pose::joint_fault`]: finite, within
//! [`MAX_JOINT_DISTANCE_M`] of the origin, quaternions of norm 0.5 to 2; time increasing, at
//! most [`MAX_RATE_HZ`] a second), counted (published and refused, in the
//! session's report under the device `external`, the refusals by kind in `refused`), and
//! reported on `latency` like any stage, so the launcher judges it.
//!
//! The stage loop of a process the launcher starts ([`common::node::run`]) is inverted here:
//! Python calls [`NativeSource::publish`] when it has a hand, and every call (and every look at
//! `running`) sends the periodic latency report when it is due. `close` (or the end of the
//! `with` block) sends the final report; the session then ends, as it does when a replay has
//! played its trace.

use std::time::Duration;

use numpy::{PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use common::bus::{Bus, Outlet, RunningSession};
use common::latency::Reporter;
use common::samples::{
    first_joint_fault, DeviceCounters, JointFault, JointsSample, Pose, MAX_JOINT_DISTANCE_M,
    OPENXR_JOINTS,
};
use common::{shutdown, topics, Stage, Stamp};

use crate::SourceError;

/// The joint OpenXR names the wrist: its pose is the sample's `wrist`.
const WRIST: usize = 1;
/// How often `session_running` looks at the session's card (a directory walk).
const LOOK_EVERY_NS: u64 = 250_000_000;

/// How long a closing source waits for its launcher to read its final report.
const RELEASE_WAIT: Duration = Duration::from_secs(5);

/// How long a source its launcher did not start keeps its ports after its final report.
const UNLAUNCHED_LINGER: Duration = Duration::from_millis(200);

/// Why a sample was refused; the index counts it.
const REASONS: [&str; 5] = ["not finite", "too far", "rotation norm", "order", "rate"];
/// [`REASONS`]' index of a sample over [`MAX_RATE_HZ`].
const RATE: usize = 4;

/// The most hands a second a source may publish: a tracker's rate with room to spare (a
/// headset's hand tracking runs at 30 to 120 Hz; the webxr stage takes a page's frames up to
/// the same 240 a second). Faster, the pipeline behind it cannot keep up: 20,000 hands
/// published at 123,000 a second made the session drop a third of its worlds (issue 40).
/// Hands beyond it are refused and counted (`rate`), as a page's are (`flood`).
pub const MAX_RATE_HZ: f64 = 240.0;
/// How many hands may come at once after a pause (a quarter of a second's worth): a program
/// that stalled briefly and sends what it held is not refused, a burst that would overrun
/// the readers' buffers is.
pub const MAX_BURST: f64 = MAX_RATE_HZ / 4.0;

/// The rate limit: a bucket of [`MAX_BURST`] hands, refilled at [`MAX_RATE_HZ`] (on
/// CLOCK_MONOTONIC: the program's own `time_ns` says nothing about how fast it sends).
#[derive(Debug, Clone, Copy)]
struct RateLimit {
    tokens: f64,
    at_ns: u64,
}

impl RateLimit {
    fn new(now_ns: u64) -> RateLimit {
        RateLimit {
            tokens: MAX_BURST,
            at_ns: now_ns,
        }
    }

    /// Whether a hand may go out at `now_ns`; takes its token when it may.
    fn take(&mut self, now_ns: u64) -> bool {
        let elapsed_s = now_ns.saturating_sub(self.at_ns) as f64 * 1e-9;
        self.tokens = (self.tokens + elapsed_s * MAX_RATE_HZ).min(MAX_BURST);
        self.at_ns = now_ns;
        if self.tokens < 1.0 {
            return false;
        }
        self.tokens -= 1.0;
        true
    }
}

/// Joint `j` by name (26: the wrist given apart).
fn joint(j: usize) -> String {
    match common::samples::OPENXR_JOINT_NAMES.get(j) {
        Some(name) => format!("joint {j} ({name})"),
        None => "the wrist".to_string(),
    }
}

#[pyclass(module = "handblocks._native", unsendable, name = "NativeSource")]
pub struct NativeSource {
    running: RunningSession,
    joints_out: Option<Outlet<topics::Joints>>,
    reporter: Option<Reporter>,
    _bus: Bus,
    sample: JointsSample,
    /// The last published time of each hand (right, left): each must increase.
    last_time_ns: [Option<u64>; 2],
    published: u64,
    refused: [u64; REASONS.len()],
    first_refused: Option<String>,
    rate: RateLimit,
    /// The session's folder, where the final report leaves the refusals by kind (the
    /// launcher's report names them: `devices.external.refused`).
    session_folder: std::path::PathBuf,
    session_gone: bool,
    last_look_ns: u64,
    closed: bool,
    /// Started by the session's launcher (which releases it through its standard input).
    launched: bool,
}

impl NativeSource {
    fn counters(&self) -> common::node::Counters {
        self.joints_out
            .as_ref()
            .map(|o| common::node::Counters::of([o.counter()]))
            .unwrap_or_else(|| common::node::Counters::of([]))
    }

    fn devices(&self) -> [DeviceCounters; 2] {
        [
            DeviceCounters {
                device: common::samples::DeviceKind::External as u32,
                samples: self.published,
                rejected_records: self.refused.iter().sum(),
                ..DeviceCounters::default()
            },
            DeviceCounters::default(),
        ]
    }

    fn report_if_due(&mut self) -> PyResult<()> {
        let counters = self.counters();
        let devices = self.devices();
        if let Some(r) = self.reporter.as_mut() {
            r.set_devices(devices);
            r.maybe_report(counters.as_slice())
                .map_err(|e| SourceError::new_err(e.to_string()))?;
        }
        Ok(())
    }

    fn refuse(&mut self, reason: usize, what: String) -> Option<String> {
        self.refused[reason] += 1;
        let first = self.refused[reason] == 1;
        self.first_refused.get_or_insert_with(|| what.clone());
        first.then_some(what)
    }

    /// Why these joints are refused, if they are: (reason index, what).
    fn check(
        &self,
        slot: usize,
        time_ns: u64,
        position: &[f64],
        rotation: &[f64],
    ) -> Option<(usize, String)> {
        // On the stack: nothing is allocated per sample.
        let mut poses = [Pose::IDENTITY; OPENXR_JOINTS + 1];
        for (pose, (p, q)) in poses
            .iter_mut()
            .zip(position.chunks_exact(3).zip(rotation.chunks_exact(4)))
        {
            pose.position.copy_from_slice(p);
            pose.rotation.copy_from_slice(q);
        }
        let checked = (position.len() / 3).min(poses.len());
        if let Some((j, fault)) = first_joint_fault(&poses[..checked]) {
            return Some(match fault {
                JointFault::NonFinite => (
                    0,
                    format!("{}: a position or rotation is not finite", joint(j)),
                ),
                JointFault::TooFar { metres } => (
                    1,
                    format!(
                        "{}: {metres} m from the origin (at most {MAX_JOINT_DISTANCE_M}; \
                         positions are metres)",
                        joint(j)
                    ),
                ),
                JointFault::NoRotation { norm } => (
                    2,
                    format!(
                        "{}: a rotation of norm {norm} (a quaternion [x, y, z, w] of norm 0.5 \
                         to 2)",
                        joint(j)
                    ),
                ),
            });
        }
        if let Some(last) = self.last_time_ns[slot] {
            if time_ns <= last {
                return Some((
                    3,
                    format!("time_ns {time_ns} is not after the last sample's {last}"),
                ));
            }
        }
        None
    }
}

#[pymethods]
impl NativeSource {
    /// Opens the session's bus as its `external` stage: the session `bus_id` names, else
    /// `$HANDBLOCKS_BUS` (set by the launcher that started this program).
    #[new]
    #[pyo3(signature = (bus_id=None))]
    fn new(bus_id: Option<String>) -> PyResult<NativeSource> {
        let launched = std::env::var("HANDBLOCKS_STAGE").is_ok_and(|s| s == "external");
        let id = bus_id.or_else(|| std::env::var("HANDBLOCKS_BUS").ok());
        let running = RunningSession::find(id.as_deref()).map_err(|why| {
            SourceError::new_err(format!(
                "{why}. An external source is started by its session: `handblocks launch` a \
                 session whose [source] has kind = \"external\" and command = [\"python3\", \
                 \"this_program.py\"]"
            ))
        })?;
        // One source per session, of the kind it was launched with: joints published into a
        // replay's or a headset's session would make a second hand fight the first.
        if running.source != "external" && running.source != "?" {
            return Err(SourceError::new_err(format!(
                "session {} is fed by its {} source; an external source drives only a session \
                 whose [source] has kind = \"external\"",
                running.bus.id, running.source
            )));
        }
        if launched {
            // The launcher asks its processes to stop with SIGTERM, and releases them (or says
            // it is gone) by closing their standard input: `running` turns False on either.
            shutdown::install_term_handler();
            shutdown::watch_parent_pipe();
        }
        let err = |e: common::bus::BusError| SourceError::new_err(e.to_string());
        let bus = Bus::for_stage(&running.bus, Stage::External).map_err(err)?;
        let publishers = bus
            .create_services()
            .map_err(err)?
            .publishers(common::Topic::Joints);
        if publishers > 0 {
            return Err(SourceError::new_err(format!(
                "session {} already has its source (a joints publisher is attached); a session \
                 has one",
                running.bus.id
            )));
        }
        let joints_out = bus.outlet::<topics::Joints>().map_err(err)?;
        let reporter = Reporter::new(Stage::External, bus.outlet().map_err(err)?);
        let session_folder = bus.session_folder().to_path_buf();
        Ok(NativeSource {
            running,
            joints_out: Some(joints_out),
            reporter: Some(reporter),
            _bus: bus,
            sample: JointsSample {
                stamp: Stamp::default(),
                tracked: 0,
                side: 0,
                wrist: Pose::IDENTITY,
                joints: [Pose::IDENTITY; OPENXR_JOINTS],
            },
            last_time_ns: [None, None],
            published: 0,
            refused: [0; REASONS.len()],
            first_refused: None,
            rate: RateLimit::new(common::monotonic_ns()),
            session_folder,
            session_gone: false,
            last_look_ns: 0,
            closed: false,
            launched,
        })
    }

    #[getter]
    fn bus_id(&self) -> String {
        self.running.bus.id.clone()
    }

    /// False once the session asks its source to stop (Ctrl-C at the launcher, its
    /// `--duration`, a failed process) or has ended; also sends the latency report when due.
    #[getter]
    fn running(&mut self) -> PyResult<bool> {
        if self.closed {
            return Ok(false);
        }
        self.report_if_due()?;
        let now = common::monotonic_ns();
        if now.saturating_sub(self.last_look_ns) >= LOOK_EVERY_NS {
            self.last_look_ns = now;
            self.session_gone = !self.running.is_running();
        }
        Ok(!shutdown::requested() && !self.session_gone)
    }

    /// Publishes one hand: `position` (26, 3) metres and `rotation` (26, 4) quaternions
    /// `[x, y, z, w]` of OpenXR's joints, at `time_ns` in the program's own timeline (it must
    /// increase). Returns the sample's seq, or None when the joints were refused; a refusal
    /// is counted, and the first of each kind is returned as a warning's text in
    /// `last_refusal`.
    /// `hand`: "right" (or a one-hand tracker's only hand) or "left": a tracker of two hands
    /// publishes each frame's right, then its left, with the same `time_ns`.
    #[pyo3(signature = (time_ns, position, rotation, tracked=true, wrist_position=None, wrist_rotation=None, hand="right"))]
    #[allow(clippy::too_many_arguments)]
    fn publish(
        &mut self,
        time_ns: u64,
        position: PyReadonlyArray2<'_, f64>,
        rotation: PyReadonlyArray2<'_, f64>,
        tracked: bool,
        wrist_position: Option<PyReadonlyArray1<'_, f64>>,
        wrist_rotation: Option<PyReadonlyArray1<'_, f64>>,
        hand: &str,
    ) -> PyResult<(Option<u64>, Option<String>)> {
        let Some(side) = common::HandSide::parse(hand) else {
            return Err(PyValueError::new_err(format!(
                "hand={hand:?}: \"right\" (a one-hand tracker's only hand, whichever it is) or \
                 \"left\" (the second hand of a tracker of two)"
            )));
        };
        let slot = usize::from(side == common::HandSide::Left);
        if self.closed {
            return Err(SourceError::new_err(
                "this source is closed; a session has one source, which ends it when it closes",
            ));
        }
        if position.shape() != [OPENXR_JOINTS, 3] || rotation.shape() != [OPENXR_JOINTS, 4] {
            return Err(PyValueError::new_err(format!(
                "position must be (26, 3) and rotation (26, 4) (OpenXR's joints, handblocks.\
                 JOINT_NAMES), not {:?} and {:?}",
                position.shape(),
                rotation.shape()
            )));
        }
        // On the stack, the wrist's room after the joints: nothing is allocated per sample.
        let mut p = [0.0f64; (OPENXR_JOINTS + 1) * 3];
        let mut q = [0.0f64; (OPENXR_JOINTS + 1) * 4];
        for (d, v) in p.iter_mut().zip(position.as_array().iter()) {
            *d = *v;
        }
        for (d, v) in q.iter_mut().zip(rotation.as_array().iter()) {
            *d = *v;
        }
        // The wrist: OpenXR's joint 1, unless given apart (CARL's traces hold identity poses
        // in joints 0 and 1 and the wrist beside them). Checked with the joints, as joint 26.
        let wrist_given = match (&wrist_position, &wrist_rotation) {
            (Some(wp), Some(wr)) if wp.shape() == [3] && wr.shape() == [4] => {
                let w = OPENXR_JOINTS;
                for (d, v) in p[w * 3..].iter_mut().zip(wp.as_array().iter()) {
                    *d = *v;
                }
                for (d, v) in q[w * 4..].iter_mut().zip(wr.as_array().iter()) {
                    *d = *v;
                }
                true
            }
            (None, None) => false,
            _ => {
                return Err(PyValueError::new_err(
                    "give both wrist_position (3,) and wrist_rotation (4,), or neither (the \
                     wrist is then joint 1, OpenXR's wrist)",
                ))
            }
        };
        let checked = OPENXR_JOINTS + wrist_given as usize;
        let (p, q) = (&p[..checked * 3], &q[..checked * 4]);
        let mut warning = None;
        let verdict = self.check(slot, time_ns, p, q).or_else(|| {
            (!self.rate.take(common::monotonic_ns())).then(|| {
                (
                    RATE,
                    format!(
                        "more than {MAX_RATE_HZ} hands a second (at most {MAX_BURST} at once): \
                         publish at the tracker's own rate (Source.wait sleeps between hands)"
                    ),
                )
            })
        });
        let seq = match verdict {
            Some((reason, what)) => {
                warning = self.refuse(reason, what);
                None
            }
            None => {
                for (j, pose) in self.sample.joints.iter_mut().enumerate() {
                    pose.position.copy_from_slice(&p[j * 3..j * 3 + 3]);
                    pose.rotation.copy_from_slice(&q[j * 4..j * 4 + 4]);
                }
                self.sample.wrist = if wrist_given {
                    let w = OPENXR_JOINTS;
                    let mut pose = Pose::IDENTITY;
                    pose.position.copy_from_slice(&p[w * 3..w * 3 + 3]);
                    pose.rotation.copy_from_slice(&q[w * 4..w * 4 + 4]);
                    pose
                } else {
                    self.sample.joints[WRIST]
                };
                self.sample.tracked = tracked as u32;
                self.sample.side = side.code();
                self.sample.stamp = Stamp {
                    source_time_ns: time_ns,
                    origin_ns: common::monotonic_ns(),
                    ..Stamp::default()
                };
                let out = self
                    .joints_out
                    .as_mut()
                    .ok_or_else(|| SourceError::new_err("the source is closed"))?;
                let sent = out
                    .publish(&self.sample)
                    .map_err(|e| SourceError::new_err(e.to_string()))?;
                if let Some(r) = self.reporter.as_mut() {
                    r.recorder.source_output(&sent);
                }
                self.last_time_ns[slot] = Some(time_ns);
                self.published += 1;
                Some(sent.seq)
            }
        };
        self.report_if_due()?;
        Ok((seq, warning))
    }

    /// Published and refused (by reason) so far.
    fn counts<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        d.set_item("published", self.published)?;
        let refused = PyDict::new(py);
        for (name, n) in REASONS.iter().zip(self.refused) {
            refused.set_item(*name, n)?;
        }
        d.set_item("refused", refused)?;
        d.set_item("first_refused", self.first_refused.clone())?;
        Ok(d)
    }

    /// Sends the final report and waits (at most a few seconds, the GIL released) until the
    /// launcher has read it; the session then ends. Idempotent.
    fn close(&mut self, py: Python<'_>) -> PyResult<()> {
        if self.closed {
            return Ok(());
        }
        self.final_report()?;
        // The ports must live until the launcher has read the report (iceoryx2 drops what a
        // departed publisher had not delivered): the launcher that started this program says
        // so by releasing it; another program gives it a moment.
        let launched = self.launched;
        py.detach(|| {
            if launched {
                shutdown::wait_for_release(RELEASE_WAIT);
            } else {
                std::thread::sleep(UNLAUNCHED_LINGER);
            }
        });
        self.joints_out = None;
        Ok(())
    }
}

impl NativeSource {
    /// Sends the final report, once.
    fn final_report(&mut self) -> PyResult<()> {
        self.closed = true;
        let counters = self.counters();
        let devices = self.devices();
        let Some(mut reporter) = self.reporter.take() else {
            return Ok(());
        };
        reporter.set_devices(devices);
        self.write_refusals();
        reporter
            .report(counters.as_slice(), true)
            .map_err(|e| SourceError::new_err(e.to_string()))
    }

    /// Leaves the refusals by kind in the session's folder, where the launcher reads them
    /// into its report (`refused.external.json`; `rejected_records` carries only their
    /// total). Written before the final report, which the launcher waits for. Best effort: the
    /// counts also go to the program (`counts()`).
    fn write_refusals(&self) {
        // A JSON object of our own fixed names (letters and `_`): nothing to escape.
        let kinds: Vec<String> = REASONS
            .iter()
            .zip(self.refused)
            .filter(|(_, n)| *n > 0)
            .map(|(k, n)| format!("\"{}\": {n}", k.replace(' ', "_")))
            .collect();
        let file = self.session_folder.join("refused.external.json");
        let _ = std::fs::write(file, format!("{{{}}}\n", kinds.join(", ")));
    }
}

/// A program that ends without closing its source (no `with`, no `close()`) still ends its
/// session cleanly: the final report goes out when the source is dropped, and a launched
/// program waits for the launcher to read it. Whether the program succeeded is its exit
/// status's to say, which the launcher judges.
impl Drop for NativeSource {
    fn drop(&mut self) {
        if self.closed {
            return;
        }
        if self.final_report().is_ok() {
            if self.launched {
                shutdown::wait_for_release(RELEASE_WAIT);
            } else {
                std::thread::sleep(UNLAUNCHED_LINGER);
            }
        }
    }
}
