//! The preview's two files: the animated PNG ([`apng`]) and the GIF beside it ([`gif`]), and
//! what a written one holds.

mod apng;
mod gif;

use std::path::{Path, PathBuf};

pub use apng::describe;
pub(super) use apng::write_apng;
pub use gif::describe_gif;
pub(super) use gif::write_gif;

/// What [`describe`] and [`describe_gif`] find in a preview file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PreviewInfo {
    pub frames: u32,
    pub width: u32,
    pub height: u32,
    /// The loop's length, milliseconds (the frames' delays added).
    pub duration_ms: u32,
}

/// Where the GIF goes beside the animated PNG `apng`: the same stem, `.gif`.
pub fn gif_path(apng: &Path) -> PathBuf {
    apng.with_extension("gif")
}
