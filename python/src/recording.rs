//! `handblocks.Recording`: one of our MCAP recordings (every topic) or a CARL trace (its
//! joints) read into numpy arrays, one row per sample, with the samples' stamps as columns.
//! The columns are made from each topic's field list (`crate::arrays::columns`), whatever
//! the topic.
//!
//! The file is read by the project's own readers (`recording::Recording`, `replay::CarlTrace`),
//! so a damaged file reads exactly as `handblocks inspect` and a replay read it: what comes
//! before the damage, with the damage named. The counts [`NativeRecording::topics`] gives are
//! `inspect --json`'s.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use pyo3::prelude::*;
use pyo3::types::PyDict;

use common::samples::JointsSample;
use common::topic::SampleView;
use common::Topic;
use recording::Recording;
use replay::CarlTrace;

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
        match &self.data {
            Data::Mcap(r) => {
                let samples: Vec<SampleView<'_>> = r.views(topic).collect();
                crate::arrays::columns(topic, &samples, &out)?;
            }
            // A CARL trace holds joints only: every other topic has no rows.
            Data::Carl { joints, .. } => {
                let messages: Vec<Vec<u8>> = match topic {
                    Topic::Joints => joints
                        .iter()
                        .map(|j| {
                            let mut m = Vec::new();
                            recording::encode_sample(j, &mut m);
                            m
                        })
                        .collect(),
                    _ => Vec::new(),
                };
                let samples: Vec<SampleView<'_>> = messages
                    .iter()
                    .filter_map(|m| {
                        SampleView::new(topic, m.get(recording::CDR_LE_HEADER.len()..)?, &[])
                    })
                    .collect();
                crate::arrays::columns(topic, &samples, &out)?;
            }
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
