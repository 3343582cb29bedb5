//! How each output mode writes a frame: side by side (one 2W x H file), anaglyph (one W x H
//! file, composed on the GPU), separate (two W x H files, left and right).

use std::path::{Path, PathBuf};

use crate::camera::Eye;
use crate::error::RenderError;
use crate::image::Image;
use crate::png::write_png;
use crate::settings::OutputMode;

/// Where frame `n` goes: `frame_NNNNNN.png`, or `frame_NNNNNN_left.png` and `_right.png`.
pub fn frame_paths(dir: &Path, n: u64, mode: OutputMode) -> Vec<PathBuf> {
    match mode {
        OutputMode::Separate => vec![
            dir.join(format!("frame_{n:06}_left.png")),
            dir.join(format!("frame_{n:06}_right.png")),
        ],
        _ => vec![dir.join(format!("frame_{n:06}.png"))],
    }
}

/// Writes a read-back frame (see `Renderer::read_back_into`) as the output mode's files.
/// `scratch` holds a split eye in separate mode, the frame with its eye gap in side-by-side.
pub fn write_frame(
    dir: &Path,
    n: u64,
    mode: OutputMode,
    frame: &Image,
    scratch: &mut Image,
) -> Result<Vec<PathBuf>, RenderError> {
    let paths = frame_paths(dir, n, mode);
    match mode {
        OutputMode::Separate => {
            for (eye, path) in Eye::BOTH.iter().zip(&paths) {
                frame.eye_into(*eye, scratch);
                write_png(path, scratch)?;
            }
        }
        OutputMode::SideBySide => {
            frame.with_eye_gap_into(scratch);
            write_png(&paths[0], scratch)?;
        }
        OutputMode::Anaglyph => write_png(&paths[0], frame)?,
    }
    Ok(paths)
}
