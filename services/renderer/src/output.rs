//! Frames as images, and how each output mode writes them: side by side (one 2W x H file),
//! anaglyph (one W x H file, composed on the GPU), separate (two W x H files, left and right).

use std::path::{Path, PathBuf};

use crate::camera::Eye;
use crate::png::write_png;
use crate::renderer::RenderError;
use crate::settings::OutputMode;

/// Tightly packed 8-bit sRGB RGBA rows, top row first.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub rgba: Vec<u8>,
}

impl Image {
    /// The pixel at (x, y) as [r, g, b, a].
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 4] {
        let i = ((y * self.width + x) * 4) as usize;
        [
            self.rgba[i],
            self.rgba[i + 1],
            self.rgba[i + 2],
            self.rgba[i + 3],
        ]
    }

    /// One eye's half of a side-by-side image, written into `out` (its allocation is reused).
    pub fn eye_into(&self, eye: Eye, out: &mut Image) {
        let w = self.width / 2;
        let x0 = match eye {
            Eye::Left => 0,
            Eye::Right => w,
        } as usize;
        out.width = w;
        out.height = self.height;
        out.rgba.clear();
        for y in 0..self.height as usize {
            let row = y * self.width as usize;
            out.rgba
                .extend_from_slice(&self.rgba[(row + x0) * 4..(row + x0 + w as usize) * 4]);
        }
    }

    /// A side-by-side image with [`crate::preview::EYE_GAP`] dark pixels between its two eyes
    /// (so that the eyes read as two views, not one image with a seam), into `out`.
    pub fn with_eye_gap_into(&self, out: &mut Image) {
        let w = (self.width / 2) as usize;
        let gap = crate::preview::EYE_GAP as usize;
        out.width = self.width + crate::preview::EYE_GAP;
        out.height = self.height;
        out.rgba.clear();
        for y in 0..self.height as usize {
            let row = &self.rgba[y * self.width as usize * 4..(y + 1) * self.width as usize * 4];
            out.rgba.extend_from_slice(&row[..w * 4]);
            for _ in 0..gap {
                out.rgba.extend_from_slice(&[24, 24, 28, 255]);
            }
            out.rgba.extend_from_slice(&row[w * 4..]);
        }
    }

    /// [`Self::eye_into`] into a new image.
    pub fn eye(&self, eye: Eye) -> Image {
        let mut out = Image::default();
        self.eye_into(eye, &mut out);
        out
    }
}

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
