//! What goes wrong with a recording, writing or reading it: one error type for the file,
//! naming it in every variant and, for damage, the byte offset where reading stopped.

use std::fmt;
use std::path::PathBuf;

/// What went wrong with a recording; every variant names the file, and damage its byte offset.
#[derive(Debug)]
pub enum RecordingError {
    /// The file could not be created, read or written.
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    /// The file does not start with MCAP's magic bytes.
    NotMcap { path: PathBuf },
    /// The MCAP library refused a write.
    Write { path: PathBuf, error: String },
    /// The file is damaged at `offset`; what comes before it was read.
    Damaged {
        path: PathBuf,
        offset: u64,
        what: String,
    },
}

impl fmt::Display for RecordingError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RecordingError::Io { path, error } => write!(f, "{}: {error}", path.display()),
            RecordingError::NotMcap { path } => write!(
                f,
                "{}: not an MCAP recording (wrong magic at offset 0; expected \\x89MCAP0\\r\\n)",
                path.display()
            ),
            RecordingError::Write { path, error } => {
                write!(f, "{}: cannot write the recording: {error}", path.display())
            }
            RecordingError::Damaged { path, offset, what } => {
                write!(
                    f,
                    "{}: damaged at byte offset {offset}: {what}",
                    path.display()
                )
            }
        }
    }
}

impl std::error::Error for RecordingError {}
