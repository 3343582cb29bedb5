//! Session and scene files (docs/design.md, "Sessions" and "Effects").
//!
//! Every error names the file, the key (as a dotted path, e.g. `block[2].size`) and what is
//! allowed, so a user can fix the file without reading code. Unknown keys are errors: a typo
//! must not silently fall back to a default.

pub mod devices;
pub mod hand;
mod reader;
pub mod scene;
pub mod session;

use std::fmt;
use std::path::PathBuf;

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
