//! `handblocks.Recording`: one of our MCAP recordings (every topic) or a CARL trace (its
//! joints) read into numpy arrays, one row per sample, with the samples' stamps as columns.
//!
//! The file is read by the project's own readers (`recording::Recording`, `replay::CarlTrace`),
//! so a damaged file reads exactly as `handblocks inspect` and a replay read it: what comes
//! before the damage, with the damage named. The counts [`NativeRecording::topics`] gives are
//! `inspect --json`'s.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use pyo3::prelude::*;
use pyo3::types::PyDict;

use common::samples::{
    FrameSample, GloveSample, HandSample, JointsSample, Pose, TrackerSample, MAX_FINGERS,
    MAX_FINGER_POINTS, MAX_GLOVE_SENSORS, MAX_PALM_VERTICES, OPENXR_JOINTS,
};
use common::Topic;
use recording::Recording;
use replay::CarlTrace;

use crate::arrays::{array, StampColumns};
use crate::RecordingError;

/// What was read: a recording of ours, or a CARL trace's joints.
enum Data {
    Mcap(Box<Recording>),
    Carl {
        joints: Vec<JointsSample>,
        damage: Option<String>,
        seconds: f64,
    },
}

/// A recording read into memory (the Python class `handblocks.Recording` wraps it).
#[pyclass(module = "handblocks._native", frozen, name = "NativeRecording")]
pub struct NativeRecording {
    path: PathBuf,
    data: Data,
}

/// Refused with `inspect`'s message.
fn refused(e: impl std::fmt::Display) -> PyErr {
    RecordingError::new_err(e.to_string())
}

#[pymethods]
impl NativeRecording {
    /// Reads `path`: an MCAP file of ours (by its first bytes), else a CARL trace.
    #[new]
    fn new(py: Python<'_>, path: PathBuf) -> PyResult<NativeRecording> {
        let data = py.detach(|| read(&path))?;
        Ok(NativeRecording { path, data })
    }

    #[getter]
    fn path(&self) -> String {
        self.path.display().to_string()
    }

    /// `"mcap"` or `"carl"`.
    #[getter]
    fn kind(&self) -> &'static str {
        match self.data {
            Data::Mcap(_) => "mcap",
            Data::Carl { .. } => "carl",
        }
    }

    /// True when the file was whole: an MCAP file closed with its summary and footer, a CARL
    /// file read to its last byte.
    #[getter]
    fn complete(&self) -> bool {
        match &self.data {
            Data::Mcap(r) => r.complete && r.damage.is_none(),
            Data::Carl { damage, .. } => damage.is_none(),
        }
    }

    /// Where and why reading stopped early, as `inspect` says it; None for a whole file.
    #[getter]
    fn damage(&self) -> Option<String> {
        match &self.data {
            Data::Mcap(r) => r.damage.as_ref().map(|d| d.to_string()),
            Data::Carl { damage, .. } => damage.clone(),
        }
    }

    /// The `handblocks` metadata record: `session`, `scene`, `source`, `blocks` (the blocks'
    /// names, one a line) when a session recorded the file; empty for a CARL trace.
    #[getter]
    fn metadata(&self) -> BTreeMap<String, String> {
        match &self.data {
            Data::Mcap(r) => r.metadata.clone(),
            Data::Carl { .. } => BTreeMap::new(),
        }
    }

    /// The files a restarted recorder went on in (`NAME.1.mcap`, ...), which exist beside
    /// this one; each is a recording of its own.
    #[getter]
    fn segments(&self) -> Vec<String> {
        (1..)
            .map(|k| common::config::session::recording_segment(&self.path, k))
            .take_while(|p| std::fs::symlink_metadata(p).is_ok())
            .map(|p| p.display().to_string())
            .collect()
    }

    /// Per topic: `messages`, `gaps`, `seconds`, `rate_hz`, `schema`, `bytes` and
    /// `bytes_per_element`, as `handblocks inspect --json` lists them.
    fn topics<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let out = PyDict::new(py);
        match &self.data {
            Data::Mcap(r) => {
                for t in r.summary().topics {
                    let d = PyDict::new(py);
                    d.set_item("messages", t.messages)?;
                    d.set_item("gaps", t.gaps)?;
                    d.set_item("seconds", t.seconds)?;
                    d.set_item("rate_hz", t.rate_hz)?;
                    d.set_item("schema", t.schema)?;
                    d.set_item("bytes", t.sample_bytes)?;
                    d.set_item("bytes_per_element", t.element_bytes)?;
                    out.set_item(t.topic.name(), d)?;
                }
            }
            Data::Carl {
                joints, seconds, ..
            } => {
                let d = PyDict::new(py);
                d.set_item("messages", joints.len())?;
                d.set_item("gaps", 0)?;
                d.set_item("seconds", *seconds)?;
                let rate = if *seconds > 0.0 {
                    (joints.len().saturating_sub(1)) as f64 / seconds
                } else {
                    0.0
                };
                d.set_item("rate_hz", rate)?;
                d.set_item("schema", "CARL (OpenXR joints, right hand)")?;
                d.set_item("bytes", std::mem::size_of::<JointsSample>())?;
                d.set_item("bytes_per_element", py.None())?;
                out.set_item(Topic::Joints.name(), d)?;
            }
        }
        Ok(out)
    }

    /// One topic's samples as columns (a dict of numpy arrays, one row per sample): the
    /// stamps, then the topic's own fields. A topic the file does not hold gives 0 rows.
    fn arrays<'py>(&self, py: Python<'py>, topic: &str) -> PyResult<Bound<'py, PyDict>> {
        let topic = crate::recorded_topic(topic)?;
        let out = PyDict::new(py);
        match (&self.data, topic) {
            (Data::Mcap(r), Topic::World) => world(r, &out)?,
            (Data::Mcap(r), Topic::Hand) => {
                hand(&r.samples(Topic::Hand).collect::<Vec<_>>(), &out)?
            }
            (Data::Mcap(r), Topic::Joints) => {
                joints(&r.samples(Topic::Joints).collect::<Vec<_>>(), &out)?
            }
            (Data::Mcap(r), Topic::Glove) => {
                glove(&r.samples(Topic::Glove).collect::<Vec<_>>(), &out)?
            }
            (Data::Mcap(r), Topic::Tracker) => {
                tracker(&r.samples(Topic::Tracker).collect::<Vec<_>>(), &out)?
            }
            (Data::Mcap(r), Topic::Frame) => {
                frame(&r.samples(Topic::Frame).collect::<Vec<_>>(), &out)?
            }
            (Data::Carl { joints: j, .. }, Topic::Joints) => joints(j, &out)?,
            (Data::Carl { .. }, Topic::World) => world_rows(Vec::new(), 0, &out)?,
            (Data::Carl { .. }, Topic::Hand) => hand(&[], &out)?,
            (Data::Carl { .. }, Topic::Glove) => glove(&[], &out)?,
            (Data::Carl { .. }, Topic::Tracker) => tracker(&[], &out)?,
            (Data::Carl { .. }, _) => frame(&[], &out)?,
            (Data::Mcap(_), Topic::Latency) => {}
        }
        Ok(out)
    }
}

/// Reads the file, as `inspect` (MCAP) or a replay (CARL) reads it.
fn read(path: &Path) -> PyResult<Data> {
    let head = {
        use std::io::Read;
        let mut head = [0u8; 8];
        // Only a regular file, refused before a read could block: a FIFO with no writer
        // would hang here for ever, deaf to Ctrl-C (issue 40).
        let n = common::config::open_regular(path)
            .and_then(|mut f| f.read(&mut head).map_err(|e| e.to_string()))
            .map_err(|e| refused(format!("{}: cannot read it: {e}", path.display())))?;
        head[..n].to_vec()
    };
    if Recording::is_mcap(&head) {
        return Recording::open(path)
            .map(|r| Data::Mcap(Box::new(r)))
            .map_err(refused);
    }
    let carl = CarlTrace::load(path).map_err(|e| {
        refused(format!(
            "{e} (a recording is one of our MCAP files or a CARL trace)"
        ))
    })?;
    let mut joints = Vec::new();
    carl.joints([0.0; 3], &mut joints);
    for (seq, j) in joints.iter_mut().enumerate() {
        j.stamp.seq = seq as u64;
    }
    Ok(Data::Carl {
        joints,
        damage: carl.damage.as_ref().map(|d| d.to_string()),
        seconds: carl.duration(),
    })
}

/// The fingers' check points of a world (as stepped) or a hand: `finger_count (n,)`,
/// `finger_point_count (n, 5)`, `finger_points (n, 5, 5, 3)`.
struct FingerColumns {
    count: Vec<u32>,
    point_count: Vec<u32>,
    points: Vec<f64>,
}

impl FingerColumns {
    fn with_capacity(n: usize) -> FingerColumns {
        FingerColumns {
            count: Vec::with_capacity(n),
            point_count: Vec::with_capacity(n * MAX_FINGERS),
            points: Vec::with_capacity(n * MAX_FINGERS * MAX_FINGER_POINTS * 3),
        }
    }

    fn push(
        &mut self,
        count: u32,
        point_count: &[u32; MAX_FINGERS],
        points: &[[[f64; 3]; MAX_FINGER_POINTS]; MAX_FINGERS],
    ) {
        self.count.push(count);
        self.point_count.extend_from_slice(point_count);
        self.points
            .extend(points.iter().flatten().flatten().copied());
    }

    fn into_dict(self, out: &Bound<'_, PyDict>) -> PyResult<()> {
        let py = out.py();
        let n = self.count.len();
        out.set_item("finger_count", array(py, self.count, &[n])?)?;
        out.set_item(
            "finger_point_count",
            array(py, self.point_count, &[n, MAX_FINGERS])?,
        )?;
        out.set_item(
            "finger_points",
            array(py, self.points, &[n, MAX_FINGERS, MAX_FINGER_POINTS, 3])?,
        )?;
        Ok(())
    }
}

fn push_pose(p: &Pose, position: &mut Vec<f64>, rotation: &mut Vec<f64>) {
    position.extend_from_slice(&p.position);
    rotation.extend_from_slice(&p.rotation);
}

fn world(r: &Recording, out: &Bound<'_, PyDict>) -> PyResult<()> {
    let worlds: Vec<common::WorldSample> = r.worlds().collect();
    let blocks = worlds.iter().map(|w| w.blocks.len()).max().unwrap_or(0);
    world_rows(worlds, blocks, out)
}

/// The world's columns; a sample with fewer blocks than `blocks` (a recording edited by
/// hand) is padded with NaN poses and mode 0.
fn world_rows(
    worlds: Vec<common::WorldSample>,
    blocks: usize,
    out: &Bound<'_, PyDict>,
) -> PyResult<()> {
    let py = out.py();
    let n = worlds.len();
    let mut stamps = StampColumns::with_capacity(n);
    let (mut step, mut hand_seq, mut grasped) = (
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
    );
    let mut position = Vec::with_capacity(n * blocks * 3);
    let mut rotation = Vec::with_capacity(n * blocks * 4);
    let mut mode = Vec::with_capacity(n * blocks);
    let mut fingers = FingerColumns::with_capacity(n);
    for w in &worlds {
        let h = &w.header;
        stamps.push(&h.stamp);
        step.push(h.step);
        hand_seq.push(h.hand_seq);
        grasped.push(h.grasped_block);
        for b in 0..blocks {
            match w.blocks.get(b) {
                Some(s) => {
                    push_pose(&s.pose, &mut position, &mut rotation);
                    mode.push(s.mode);
                }
                None => {
                    position.extend_from_slice(&[f64::NAN; 3]);
                    rotation.extend_from_slice(&[f64::NAN; 4]);
                    mode.push(0);
                }
            }
        }
        fingers.push(h.finger_count, &h.finger_point_count, &h.finger_points);
    }
    stamps.into_dict(out)?;
    out.set_item("step", array(py, step, &[n])?)?;
    out.set_item("hand_seq", array(py, hand_seq, &[n])?)?;
    out.set_item("grasped_block", array(py, grasped, &[n])?)?;
    out.set_item("position", array(py, position, &[n, blocks, 3])?)?;
    out.set_item("rotation", array(py, rotation, &[n, blocks, 4])?)?;
    out.set_item("mode", array(py, mode, &[n, blocks])?)?;
    fingers.into_dict(out)
}

fn hand(samples: &[HandSample], out: &Bound<'_, PyDict>) -> PyResult<()> {
    let py = out.py();
    let n = samples.len();
    let mut stamps = StampColumns::with_capacity(n);
    let (mut wp, mut wr) = (Vec::with_capacity(n * 3), Vec::with_capacity(n * 4));
    let mut tracked = Vec::with_capacity(n);
    let mut side = Vec::with_capacity(n);
    let mut fingers = FingerColumns::with_capacity(n);
    let mut finger_radius = Vec::with_capacity(n * MAX_FINGERS);
    let mut palm_count = Vec::with_capacity(n);
    let mut palm = Vec::with_capacity(n * MAX_PALM_VERTICES * 3);
    for h in samples {
        stamps.push(&h.stamp);
        push_pose(&h.wrist, &mut wp, &mut wr);
        tracked.push(h.tracked != 0);
        side.push(h.side);
        fingers.push(h.finger_count, &h.finger_point_count, &h.finger_points);
        finger_radius.extend_from_slice(&h.finger_radius);
        palm_count.push(h.palm_vertex_count);
        for v in &h.palm_vertices {
            palm.extend_from_slice(v);
        }
    }
    stamps.into_dict(out)?;
    out.set_item("tracked", array(py, tracked, &[n])?)?;
    out.set_item("side", array(py, side, &[n])?)?;
    out.set_item("wrist_position", array(py, wp, &[n, 3])?)?;
    out.set_item("wrist_rotation", array(py, wr, &[n, 4])?)?;
    fingers.into_dict(out)?;
    out.set_item(
        "finger_radius",
        array(py, finger_radius, &[n, MAX_FINGERS])?,
    )?;
    out.set_item("palm_vertex_count", array(py, palm_count, &[n])?)?;
    out.set_item(
        "palm_vertices",
        array(py, palm, &[n, MAX_PALM_VERTICES, 3])?,
    )?;
    Ok(())
}

fn joints(samples: &[JointsSample], out: &Bound<'_, PyDict>) -> PyResult<()> {
    let py = out.py();
    let n = samples.len();
    let mut stamps = StampColumns::with_capacity(n);
    let (mut wp, mut wr) = (Vec::with_capacity(n * 3), Vec::with_capacity(n * 4));
    let (mut jp, mut jr) = (
        Vec::with_capacity(n * OPENXR_JOINTS * 3),
        Vec::with_capacity(n * OPENXR_JOINTS * 4),
    );
    let mut tracked = Vec::with_capacity(n);
    let mut side = Vec::with_capacity(n);
    for j in samples {
        stamps.push(&j.stamp);
        tracked.push(j.tracked != 0);
        side.push(j.side);
        push_pose(&j.wrist, &mut wp, &mut wr);
        for p in &j.joints {
            push_pose(p, &mut jp, &mut jr);
        }
    }
    stamps.into_dict(out)?;
    out.set_item("tracked", array(py, tracked, &[n])?)?;
    out.set_item("side", array(py, side, &[n])?)?;
    out.set_item("wrist_position", array(py, wp, &[n, 3])?)?;
    out.set_item("wrist_rotation", array(py, wr, &[n, 4])?)?;
    out.set_item("position", array(py, jp, &[n, OPENXR_JOINTS, 3])?)?;
    out.set_item("rotation", array(py, jr, &[n, OPENXR_JOINTS, 4])?)?;
    Ok(())
}

fn glove(samples: &[GloveSample], out: &Bound<'_, PyDict>) -> PyResult<()> {
    let py = out.py();
    let n = samples.len();
    let mut stamps = StampColumns::with_capacity(n);
    let mut count = Vec::with_capacity(n);
    let mut side = Vec::with_capacity(n);
    let mut angles = Vec::with_capacity(n * MAX_GLOVE_SENSORS);
    for g in samples {
        stamps.push(&g.stamp);
        count.push(g.sensor_count);
        side.push(g.side);
        angles.extend_from_slice(&g.angles);
    }
    stamps.into_dict(out)?;
    out.set_item("sensor_count", array(py, count, &[n])?)?;
    out.set_item("side", array(py, side, &[n])?)?;
    out.set_item("angles", array(py, angles, &[n, MAX_GLOVE_SENSORS])?)?;
    Ok(())
}

fn tracker(samples: &[TrackerSample], out: &Bound<'_, PyDict>) -> PyResult<()> {
    let py = out.py();
    let n = samples.len();
    let mut stamps = StampColumns::with_capacity(n);
    let mut station = Vec::with_capacity(n);
    let mut side = Vec::with_capacity(n);
    let (mut wp, mut wr) = (Vec::with_capacity(n * 3), Vec::with_capacity(n * 4));
    for t in samples {
        stamps.push(&t.stamp);
        station.push(t.station);
        side.push(t.side);
        push_pose(&t.wrist, &mut wp, &mut wr);
    }
    stamps.into_dict(out)?;
    out.set_item("station", array(py, station, &[n])?)?;
    out.set_item("side", array(py, side, &[n])?)?;
    out.set_item("wrist_position", array(py, wp, &[n, 3])?)?;
    out.set_item("wrist_rotation", array(py, wr, &[n, 4])?)?;
    Ok(())
}

fn frame(samples: &[FrameSample], out: &Bound<'_, PyDict>) -> PyResult<()> {
    let py = out.py();
    let n = samples.len();
    let mut stamps = StampColumns::with_capacity(n);
    let (mut world_seq, mut render_ns, mut photon_ns, mut skipped) = (
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
    );
    for f in samples {
        stamps.push(&f.stamp);
        world_seq.push(f.world_seq);
        render_ns.push(f.render_ns);
        photon_ns.push(f.origin_to_photon_ns);
        skipped.push(f.skipped_worlds);
    }
    stamps.into_dict(out)?;
    out.set_item("world_seq", array(py, world_seq, &[n])?)?;
    out.set_item("render_ns", array(py, render_ns, &[n])?)?;
    out.set_item("origin_to_photon_ns", array(py, photon_ns, &[n])?)?;
    out.set_item("skipped_worlds", array(py, skipped, &[n])?)?;
    Ok(())
}
