//! Why a launch could not run (as opposed to running and violating the budget): one variant
//! per thing that can stop it, so a caller can tell a wrong session file from a busy bus id
//! or a process that would not start, and `Display` gives the sentence a person reads, naming
//! the option, file or key to change.

use std::fmt;
use std::io;
use std::path::PathBuf;
use std::process::ExitStatus;
use std::time::Duration;

use common::bus::BusError;
use common::config::ConfigError;
use common::Stage;

/// Why a launch could not run.
#[derive(Debug)]
pub enum LaunchError {
    /// The session file, its scene or a `--set` override is wrong (device settings included).
    Session(ConfigError),
    /// A replay session's trace cannot be opened.
    TraceUnreadable {
        session: PathBuf,
        trace: PathBuf,
        reason: io::Error,
    },
    /// `renderer.mode = "window"` with neither $DISPLAY nor $WAYLAND_DISPLAY set.
    NoDisplay { session: PathBuf },
    /// `--frames-dir` for a session whose renderer is off.
    NoFramesToWrite { session: PathBuf },
    /// The recording exists and `--force` was not given; `from_option`: `--record` named it,
    /// not the session's `recorder.file`.
    RecordingExists {
        session: PathBuf,
        file: PathBuf,
        from_option: bool,
    },
    /// An output the user names (`what`: "--report", "--frames-dir") is taken (a file, or a
    /// link, which a session never writes through) and `--force` was not given.
    OutputExists {
        what: &'static str,
        path: PathBuf,
        link: bool,
    },
    /// An output (`what`: "the recording", "--report", "the preview") names a folder.
    OutputIsFolder { what: &'static str, path: PathBuf },
    /// An output that is a folder (`--frames-dir`) names something that is not one.
    OutputIsNotFolder { what: &'static str, path: PathBuf },
    /// The folder for an output cannot be created.
    OutputFolder {
        what: &'static str,
        dir: PathBuf,
        path: PathBuf,
        reason: io::Error,
    },
    /// An output cannot be written.
    OutputUnwritable {
        what: &'static str,
        path: PathBuf,
        reason: io::Error,
    },
    /// The session's bus could not be configured, opened or read.
    Bus(BusError),
    /// `--bus-id` names the bus of a session whose processes are alive.
    BusIdInUse { id: String },
    /// Files of an earlier session with this `--bus-id` are left and cannot be removed.
    LeftoverFiles {
        id: String,
        prefix: String,
        reason: io::Error,
    },
    /// A service process could not be started.
    Spawn {
        stage: Stage,
        exe: PathBuf,
        reason: io::Error,
    },
    /// A process exited before every process was attached.
    ExitedDuringStartup {
        stage: Stage,
        status: Option<ExitStatus>,
    },
    /// The processes did not attach in time; `missing` says what was still missing.
    AttachTimeout { waited: Duration, missing: String },
    /// The session's iceoryx2 files could not be removed at the end.
    Cleanup { prefix: String, reason: io::Error },
    /// The report's folder cannot be created.
    ReportFolder { dir: PathBuf, reason: io::Error },
    /// The report could not be encoded as JSON.
    ReportJson(serde_json::Error),
    /// The report file cannot be written.
    ReportWrite { path: PathBuf, reason: io::Error },
}

/// How a process ended, for messages: its exit status, or that it had to be killed.
pub(crate) fn describe_exit(status: Option<ExitStatus>) -> String {
    match status {
        Some(s) => s.to_string(),
        None => "still running; killed".into(),
    }
}

impl fmt::Display for LaunchError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LaunchError::Session(e) => write!(f, "{e}"),
            LaunchError::TraceUnreadable {
                session,
                trace,
                reason,
            } => write!(
                f,
                "{}: [source] file = {}: cannot read it: {reason} (a recording of ours, .mcap, \
                 or a CARL trace; relative paths start at the session file's folder; \
                 README.md, \"CARL traces\", says where to get them)",
                session.display(),
                trace.display()
            ),
            LaunchError::NoDisplay { session } => write!(
                f,
                "{}: `renderer.mode`: \"window\" needs a display, and neither $DISPLAY nor \
                 $WAYLAND_DISPLAY is set; run it on a desktop, or without a window: \
                 --set renderer.mode=headless (frames and an animated preview, no display needed)",
                session.display()
            ),
            LaunchError::NoFramesToWrite { session } => write!(
                f,
                "--frames-dir: this session draws no frames ({}: [renderer] mode = \"off\"); \
                 add --set renderer.mode=headless, or drop --frames-dir",
                session.display()
            ),
            LaunchError::RecordingExists {
                session,
                file,
                from_option,
            } => {
                if *from_option {
                    write!(f, "--record")?;
                } else {
                    write!(f, "{}: `recorder.file`", session.display())?;
                }
                let link = if common::output::is_link(file) {
                    " (a symbolic link: a session never writes through one)"
                } else {
                    ""
                };
                write!(
                    f,
                    ": {} exists{link}; pass --force to replace it, or record to another file",
                    file.display()
                )
            }
            LaunchError::OutputExists { what, path, link } => {
                let link = if *link {
                    " (a symbolic link: a session never writes through one)"
                } else {
                    ""
                };
                write!(
                    f,
                    "{what}: {} exists{link}; pass --force to replace it, or give another path",
                    path.display()
                )
            }
            LaunchError::OutputIsFolder { what, path } => write!(
                f,
                "{what}: {} is a folder; give a file name",
                path.display()
            ),
            LaunchError::OutputIsNotFolder { what, path } => write!(
                f,
                "{what}: {} exists and is not a folder; give a folder (made when missing), e.g. \
                 out/frames",
                path.display()
            ),
            LaunchError::OutputFolder {
                what,
                dir,
                path,
                reason,
            } => write!(
                f,
                "{what}: cannot create the folder {} for {}: {reason}",
                dir.display(),
                path.display()
            ),
            LaunchError::OutputUnwritable { what, path, reason } => {
                write!(f, "{what}: cannot write {}: {reason}", path.display())
            }
            LaunchError::Bus(e) => write!(f, "{e}"),
            LaunchError::BusIdInUse { id } => write!(
                f,
                "--bus-id {id}: that bus id is already in use by a running session (its \
                 processes are alive); give another id, or none for a fresh one"
            ),
            LaunchError::LeftoverFiles { id, prefix, reason } => write!(
                f,
                "--bus-id {id}: files of an earlier session with that id are left ({prefix}) \
                 and cannot be removed: {reason}"
            ),
            LaunchError::Spawn { stage, exe, reason } => write!(
                f,
                "cannot start the {} process ({}): {reason}",
                stage.name(),
                exe.display()
            ),
            LaunchError::ExitedDuringStartup { stage, status } => write!(
                f,
                "the {} process exited during start-up ({})",
                stage.name(),
                describe_exit(*status)
            ),
            LaunchError::AttachTimeout { waited, missing } => write!(
                f,
                "the processes did not attach within {} s; still missing: {missing}",
                waited.as_secs()
            ),
            LaunchError::Cleanup { prefix, reason } => write!(
                f,
                "cannot remove the session's iceoryx2 files ({prefix}): {reason}"
            ),
            LaunchError::ReportFolder { dir, reason } => {
                write!(f, "cannot create {}: {reason}", dir.display())
            }
            LaunchError::ReportJson(e) => write!(f, "{e}"),
            LaunchError::ReportWrite { path, reason } => {
                write!(f, "cannot write the report {}: {reason}", path.display())
            }
        }
    }
}

/// The message already holds the underlying error's own (a person reads one line), so no
/// `source` is given: a reporter walking the chain would print it twice.
impl std::error::Error for LaunchError {}

impl From<ConfigError> for LaunchError {
    fn from(e: ConfigError) -> Self {
        LaunchError::Session(e)
    }
}

impl From<BusError> for LaunchError {
    fn from(e: BusError) -> Self {
        LaunchError::Bus(e)
    }
}
