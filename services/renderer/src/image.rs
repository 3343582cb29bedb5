//! Frames as images: tightly packed RGBA, split into eyes or joined with a gap between them.
//! Its own module, below everything that makes or writes images (the renderer reads frames
//! back into it, the PNG, frame and preview writers take it).

use crate::camera::Eye;

/// Background-coloured pixels between the two eyes of a side-by-side image (at full size).
pub const EYE_GAP: u32 = 16;
/// The gap's colour.
pub const GAP_RGB: [u8; 3] = [24, 24, 28];

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

    /// A side-by-side image with [`EYE_GAP`] dark pixels between its two eyes
    /// (so that the eyes read as two views, not one image with a seam), into `out`.
    pub fn with_eye_gap_into(&self, out: &mut Image) {
        let w = (self.width / 2) as usize;
        let gap = EYE_GAP as usize;
        out.width = self.width + EYE_GAP;
        out.height = self.height;
        out.rgba.clear();
        for y in 0..self.height as usize {
            let row = &self.rgba[y * self.width as usize * 4..(y + 1) * self.width as usize * 4];
            out.rgba.extend_from_slice(&row[..w * 4]);
            for _ in 0..gap {
                out.rgba.extend_from_slice(&GAP_RGB);
                out.rgba.push(255);
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
