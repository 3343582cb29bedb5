//! `handblocks._native`: the Rust half of the Python package `handblocks` (python/handblocks
//! is the other). It is built from the project's own crates, so a sample's layout in Python
//! is the one the processes use and can never drift from it:
//!
//! * [`recording`]: one of our MCAP recordings, or a CARL trace, read into numpy arrays;
//! * [`simulate`]: the block world as a function, `handblocks simulate --json` bit for bit;
//! * [`session`]: a running session's topics, read zero-copy from its shared memory;
//! * [`source`]: the `external` source, a Python program that publishes hand joints.
//!
//! Errors are Python exceptions of one family ([`HandblocksError`]), each carrying the same
//! message the command line prints for the same input.

use pyo3::create_exception;
use pyo3::prelude::*;

mod arrays;
mod recording;
mod session;
mod simulate;
mod source;

create_exception!(
    _native,
    HandblocksError,
    pyo3::exceptions::PyException,
    "Every error handblocks raises."
);
create_exception!(
    _native,
    RecordingError,
    HandblocksError,
    "A recording or trace that cannot be read (the message is `handblocks inspect`'s)."
);
create_exception!(
    _native,
    SceneError,
    HandblocksError,
    "A scene refused: the message names the file (or <dict>), the key and what is allowed."
);
create_exception!(
    _native,
    SimulateError,
    HandblocksError,
    "A simulation that could not run: its trace or its hand script."
);
create_exception!(
    _native,
    SessionError,
    HandblocksError,
    "No such session runs, or its bus cannot be opened or read."
);
create_exception!(
    _native,
    SourceError,
    HandblocksError,
    "The external source cannot publish: no session to publish into, or its bus failed."
);

/// A topic a session publishes and a recording holds, by its name (`world` or `/world`); a
/// ValueError listing them for any other.
pub(crate) fn recorded_topic(name: &str) -> PyResult<common::Topic> {
    use common::Topic;
    Topic::from_channel(name)
        .filter(|t| t.is_recorded())
        .ok_or_else(|| {
            pyo3::exceptions::PyValueError::new_err(format!(
                "{name:?} is not a topic; one of: {}",
                Topic::RECORDED.map(|t| t.name()).join(", ")
            ))
        })
}

/// CLOCK_MONOTONIC in nanoseconds: the clock of every stamp's `origin_ns` and `publish_ns`, so
/// `monotonic_ns() - sample.origin_ns` is a sample's age, as the session's report counts it.
#[pyfunction]
fn monotonic_ns() -> u64 {
    common::monotonic_ns()
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    // The package's version is the workspace's: `handblocks.__version__`.
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    // The checkout this package was built from: the console command `handblocks` runs the
    // program that checkout built (`handblocks._cli`), where nothing else names one.
    m.add(
        "BUILT_FROM",
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .parent()
            .map_or_else(String::new, |p| p.display().to_string()),
    )?;
    m.add("HandblocksError", py.get_type::<HandblocksError>())?;
    m.add("RecordingError", py.get_type::<RecordingError>())?;
    m.add("SceneError", py.get_type::<SceneError>())?;
    m.add("SimulateError", py.get_type::<SimulateError>())?;
    m.add("SessionError", py.get_type::<SessionError>())?;
    m.add("SourceError", py.get_type::<SourceError>())?;
    m.add(
        "MODE_NAMES",
        common::BlockMode::ALL
            .iter()
            .map(|m| m.name())
            .collect::<Vec<_>>(),
    )?;
    m.add("JOINT_NAMES", common::samples::OPENXR_JOINT_NAMES.to_vec())?;
    m.add(
        "TOPICS",
        common::Topic::RECORDED
            .iter()
            .map(|t| t.name())
            .collect::<Vec<_>>(),
    )?;
    m.add("TRACKING_HOLD_NS", common::TRACKING_HOLD_NS)?;
    m.add("MAX_FRAMES", simulate::MAX_FRAMES)?;
    m.add_function(wrap_pyfunction!(monotonic_ns, m)?)?;
    m.add_class::<recording::NativeRecording>()?;
    m.add_function(wrap_pyfunction!(simulate::simulate, m)?)?;
    m.add_class::<session::NativeSession>()?;
    m.add_class::<session::Subscription>()?;
    m.add_class::<session::LiveSample>()?;
    m.add_class::<source::NativeSource>()?;
    Ok(())
}
