//! Session and scene files (docs/design.md, "Sessions" and "Effects").
//!
//! Every error names the file, the key (as a dotted path, e.g. `block[2].size`) and what is
//! allowed, so a user can fix the file without reading code. Unknown keys are errors: a typo
//! must not silently fall back to a default.

pub mod catalog;
pub mod colors;
pub mod devices;
pub mod graph;
pub mod hand;
mod key_docs;
mod reader;
pub mod remote;
pub mod scene;
pub mod session;
pub mod shared;

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

    /// This error, saying "(given with --set)" when its key is one of `overrides` or inside
    /// one: the user then looks at the command line, not the file.
    pub fn given_with_set(mut self, overrides: &[session::Override]) -> Self {
        if overrides
            .iter()
            .any(|o| self.key == o.key || self.key.starts_with(&format!("{}.", o.key)))
        {
            self.problem.push_str(" (given with --set)");
        }
        self
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

/// What a path names, in words for a message: "a regular file", "a FIFO (named pipe)", ...
pub fn file_kind_name(meta: &std::fs::Metadata) -> &'static str {
    use std::os::unix::fs::FileTypeExt as _;
    let t = meta.file_type();
    if t.is_file() {
        "a regular file"
    } else if t.is_dir() {
        "a folder"
    } else if t.is_fifo() {
        "a FIFO (named pipe)"
    } else if t.is_char_device() {
        "a character device"
    } else if t.is_block_device() {
        "a block device"
    } else if t.is_socket() {
        "a socket"
    } else if t.is_symlink() {
        "a symbolic link"
    } else {
        "not a regular file"
    }
}

/// Opens a file named by outside input for reading, refusing anything but a regular file
/// *before* a read could block: it is opened with `O_NONBLOCK` (opening a FIFO with no writer
/// then returns at once instead of waiting forever for one), its type is taken from the open
/// descriptor (no window between a check and the open), and only a regular file is kept, in
/// blocking mode again. The error is the problem without the file's name, for the caller's
/// message ("it is a FIFO (named pipe), not a regular file").
pub fn open_regular(file: &Path) -> Result<std::fs::File, String> {
    use std::os::fd::AsRawFd as _;
    use std::os::unix::fs::OpenOptionsExt as _;
    let f = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK | libc::O_CLOEXEC)
        .open(file)
        .map_err(|e| {
            // A socket cannot be opened at all (ENXIO): say what it is, not the errno.
            match std::fs::metadata(file) {
                Ok(meta) if !meta.is_file() => format!(
                    "it is {}, not a regular file: give the path of a file",
                    file_kind_name(&meta)
                ),
                _ => e.to_string(),
            }
        })?;
    let meta = f.metadata().map_err(|e| e.to_string())?;
    if !meta.is_file() {
        return Err(format!(
            "it is {}, not a regular file: give the path of a file",
            file_kind_name(&meta)
        ));
    }
    // SAFETY: fcntl on a descriptor this function owns; only O_NONBLOCK is cleared.
    unsafe {
        let flags = libc::fcntl(f.as_raw_fd(), libc::F_GETFL);
        if flags >= 0 {
            libc::fcntl(f.as_raw_fd(), libc::F_SETFL, flags & !libc::O_NONBLOCK);
        }
    }
    Ok(f)
}

/// Reads a file named by outside input, at most `max_bytes` of it: only a regular file (a
/// device such as `/dev/zero`, a pipe or a terminal would never end, or block: refused by
/// [`open_regular`] before anything is read), and only while it holds no more than
/// `max_bytes` (a `/proc` file says it is empty and can be any length). The error is the
/// problem without the file's name, for the caller's message.
pub fn read_bounded(file: &Path, max_bytes: u64) -> Result<Vec<u8>, String> {
    let f = open_regular(file)?;
    let meta = f.metadata().map_err(|e| e.to_string())?;
    if meta.len() > max_bytes {
        return Err(format!(
            "it holds {} bytes; at most {max_bytes} are read",
            meta.len()
        ));
    }
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

/// The number of one-character edits (insert, delete, replace) from `a` to `b`: how a
/// misspelt name finds the one meant (an unknown key's "did you mean", a scene's name).
pub fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut prev = row[0];
        row[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let cur = row[j + 1];
            row[j + 1] = if ca == *cb {
                prev
            } else {
                1 + prev.min(cur).min(row[j])
            };
            prev = cur;
        }
    }
    row[b.len()]
}

/// Whether `asked` is near enough `name` to be a misspelling of it: at most a third of its
/// characters wrong, and at least 2 allowed.
pub fn near_enough(asked: &str, name: &str) -> bool {
    edit_distance(asked, name) <= (asked.chars().count() / 3).max(2)
}
