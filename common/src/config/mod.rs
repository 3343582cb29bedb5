//! Session and scene files (docs/design.md, "Sessions" and "Effects").
//!
//! Every error names the file, the key (as a dotted path, e.g. `block[2].size`) and what is
//! allowed, so a user can fix the file without reading code. Unknown keys are errors: a typo
//! must not silently fall back to a default.

pub mod colors;
pub mod devices;
pub mod graph;
pub mod hand;
mod reader;
pub mod remote;
pub mod scene;
pub mod session;

use std::fmt;
use std::io::Read as _;
use std::path::{Path, PathBuf};

pub use graph::Graph;
pub use scene::Scene;
pub use session::Session;

/// What is wrong with a configuration file.
#[derive(Debug, Clone, PartialEq)]
pub struct ConfigError {
    pub file: PathBuf,
    /// The dotted key path, empty for the file as a whole.
    pub key: String,
    pub problem: String,
}

impl ConfigError {
    pub fn new(
        file: impl Into<PathBuf>,
        key: impl Into<String>,
        problem: impl Into<String>,
    ) -> Self {
        ConfigError {
            file: file.into(),
            key: key.into(),
            problem: problem.into(),
        }
    }
}

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.key.is_empty() {
            write!(f, "{}: {}", self.file.display(), self.problem)
        } else {
            write!(
                f,
                "{}: `{}`: {}",
                self.file.display(),
                self.key,
                self.problem
            )
        }
    }
}

impl std::error::Error for ConfigError {}

/// The largest configuration file (scene, session, hand model) read: a scene of 4096 blocks
/// with every hull vertex written out is a few MiB.
pub const MAX_CONFIG_BYTES: u64 = 64 << 20;

/// Reads a file named by outside input, at most `max_bytes` of it: only a regular file (a
/// device such as `/dev/zero`, a pipe or a terminal would never end, or block), and only
/// while it holds no more than `max_bytes` (a `/proc` file says it is empty and can be any
/// length). The error is the problem without the file's name, for the caller's message.
pub fn read_bounded(file: &Path, max_bytes: u64) -> Result<Vec<u8>, String> {
    let meta = std::fs::metadata(file).map_err(|e| e.to_string())?;
    if !meta.is_file() {
        let kind = if meta.is_dir() {
            "a folder"
        } else {
            "a device, a pipe or a socket"
        };
        return Err(format!("it is {kind}, not a regular file"));
    }
    if meta.len() > max_bytes {
        return Err(format!(
            "it holds {} bytes; at most {max_bytes} are read",
            meta.len()
        ));
    }
    let f = std::fs::File::open(file).map_err(|e| e.to_string())?;
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    f.take(max_bytes + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| e.to_string())?;
    if bytes.len() as u64 > max_bytes {
        return Err(format!(
            "it holds more than {max_bytes} bytes; at most {max_bytes} are read"
        ));
    }
    Ok(bytes)
}

/// [`read_bounded`] as UTF-8 text; a byte that is not UTF-8 is named by its offset.
pub fn read_bounded_text(file: &Path, max_bytes: u64) -> Result<String, String> {
    String::from_utf8(read_bounded(file, max_bytes)?).map_err(|e| {
        format!(
            "not UTF-8 text: the byte at offset {} is not valid UTF-8",
            e.utf8_error().valid_up_to()
        )
    })
}
