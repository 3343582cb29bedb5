//! The GIF beside the animated PNG (what every image viewer and chat plays): one palette for
//! the whole animation, each frame after the first only what changed; and reading back its
//! frames' count, size and length.

use std::path::Path;

use common::BlockMode;

use super::PreviewInfo;
use crate::draw_list::mode_color_srgb;
use crate::error::RenderError;
use crate::image::GAP_RGB;
use crate::overlay::WHITE;
use crate::preview::PreviewScene;

/// The frame count, size and length of a GIF file (every frame decoded).
pub fn describe_gif(path: &Path) -> Option<PreviewInfo> {
    let file = std::fs::File::open(path).ok()?;
    let mut opts = ::gif::DecodeOptions::new();
    opts.set_color_output(::gif::ColorOutput::Indexed);
    let mut dec = opts.read_info(std::io::BufReader::new(file)).ok()?;
    let (width, height) = (u32::from(dec.width()), u32::from(dec.height()));
    let (mut frames, mut duration_ms) = (0, 0);
    while let Some(frame) = dec.read_next_frame().ok()? {
        frames += 1;
        duration_ms += u32::from(frame.delay) * 10;
    }
    Some(PreviewInfo {
        frames,
        width,
        height,
        duration_ms,
    })
}

/// The GIF's transparent palette index: a pixel of a frame after the first that shows what
/// the frame before showed.
const TRANSPARENT: u8 = 255;

/// The frame that turns `before` into `after` (palette indices, `w` x `h`, the frame before
/// kept): the smallest rectangle that holds every pixel that changed, the others in it
/// transparent where they are nearly all of it, so that a still background costs little.
fn changes(before: &[u8], after: &[u8], w: u32, h: u32) -> ::gif::Frame<'static> {
    let (w, h) = (w as usize, h as usize);
    let (mut x0, mut y0, mut x1, mut y1) = (w, h, 0, 0);
    for y in 0..h {
        for x in 0..w {
            if before[y * w + x] != after[y * w + x] {
                (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x + 1), y1.max(y + 1));
            }
        }
    }
    if x0 >= x1 {
        // Nothing changed: one transparent pixel.
        (x0, y0, x1, y1) = (0, 0, 1, 1);
    }
    let area = (x1 - x0) * (y1 - y0);
    let changed = (y0..y1)
        .flat_map(|y| (x0..x1).map(move |x| y * w + x))
        .filter(|&i| before[i] != after[i])
        .count();
    // Transparency pays where nearly all of the rectangle stays (a still camera); where much
    // of it changes (the camera moved: a fifth of the pixels, scattered) it only breaks the
    // runs the compression feeds on, and the frame is the rectangle as it is.
    let sparse = changed * 10 < area;
    let mut pixels = Vec::with_capacity(area);
    for y in y0..y1 {
        for x in x0..x1 {
            let (b, a) = (before[y * w + x], after[y * w + x]);
            pixels.push(if sparse && a == b { TRANSPARENT } else { a });
        }
    }
    let mut frame = ::gif::Frame::from_indexed_pixels(
        (x1 - x0) as u16,
        (y1 - y0) as u16,
        pixels,
        sparse.then_some(TRANSPARENT),
    );
    frame.left = x0 as u16;
    frame.top = y0 as u16;
    frame
}

/// Colours the GIF's palette always holds exactly: the overlay's text, the blocks' own
/// colours and the outlines' (the rest of the palette is learned from the frames).
fn fixed_colors(look: &PreviewScene) -> Vec<[u8; 3]> {
    let mut c = vec![WHITE, GAP_RGB];
    c.extend(BlockMode::ALL.iter().map(|m| mode_color_srgb(*m)));
    for b in look.colors.iter().take(16) {
        if !c.contains(b) {
            c.push(*b);
        }
    }
    c
}

/// Writes the GIF: one palette for the whole animation (NeuQuant, trained on a sample of its
/// frames, plus [`fixed_colors`]), each pixel mapped through a 15-bit table of the nearest
/// palette entry, so that encoding costs a table look-up per pixel; each frame after the first
/// holds only what changed ([`changes`]).
pub(crate) fn write_gif(
    path: &Path,
    w: u32,
    h: u32,
    frames: &[Vec<u8>],
    delays_ms: &[u32],
    look: &PreviewScene,
) -> Result<(), RenderError> {
    let fixed = fixed_colors(look);
    // The last entry stays free: the transparent index of the frames after the first.
    let learned = 255 - fixed.len();
    let mut sample: Vec<u8> = Vec::new();
    let step = frames.len().div_ceil(8).max(1);
    for f in frames.iter().step_by(step) {
        for p in f.chunks_exact(3).step_by(3) {
            sample.extend_from_slice(&[p[0], p[1], p[2], 255]);
        }
    }
    let nq = color_quant::NeuQuant::new(10, learned, &sample);
    let mut palette: Vec<[u8; 3]> = nq
        .color_map_rgb()
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    palette.extend(fixed);
    palette.push([0, 0, 0]);
    let table: Vec<u8> = (0..1u32 << 15)
        .map(|k| {
            let q = [(k >> 10) & 31, (k >> 5) & 31, k & 31].map(|v| (v << 3 | 4) as i32);
            palette
                .iter()
                .enumerate()
                .take(TRANSPARENT as usize)
                .min_by_key(|(_, p)| (0..3).map(|c| (i32::from(p[c]) - q[c]).pow(2)).sum::<i32>())
                .map_or(0, |(i, _)| i as u8)
        })
        .collect();
    let exact: Vec<([u8; 3], u8)> = palette
        .iter()
        .enumerate()
        .take(TRANSPARENT as usize)
        .skip(learned)
        .map(|(i, p)| (*p, i as u8))
        .collect();
    let flat: Vec<u8> = palette.iter().flatten().copied().collect();
    let encode = |file: &mut std::fs::File| -> Result<(), ::gif::EncodingError> {
        let mut enc =
            ::gif::Encoder::new(std::io::BufWriter::new(file), w as u16, h as u16, &flat)?;
        enc.set_repeat(::gif::Repeat::Infinite)?;
        let mut shown: Vec<u8> = Vec::new();
        for (k, f) in frames.iter().enumerate() {
            let idx: Vec<u8> = f
                .chunks_exact(3)
                .map(|p| {
                    let rgb = [p[0], p[1], p[2]];
                    // The text's and outlines' colours exactly, the rest through the table.
                    exact.iter().find(|(c, _)| *c == rgb).map_or_else(
                        || {
                            let k = (usize::from(p[0]) >> 3) << 10
                                | (usize::from(p[1]) >> 3) << 5
                                | usize::from(p[2]) >> 3;
                            table[k]
                        },
                        |(_, i)| *i,
                    )
                })
                .collect();
            let mut frame = if shown.is_empty() {
                ::gif::Frame::from_indexed_pixels(w as u16, h as u16, idx.clone(), None)
            } else {
                changes(&shown, &idx, w, h)
            };
            shown = idx;
            frame.dispose = ::gif::DisposalMethod::Keep;
            frame.delay = delays_ms
                .get(k)
                .map_or(10, |d| (d / 10).min(u32::from(u16::MAX)) as u16);
            enc.write_frame(&frame)?;
        }
        Ok(())
    };
    common::output::replace(path, |file| encode(file).map_err(std::io::Error::other))
        .map_err(|e| RenderError::Io(format!("writing {}: {e}", path.display())))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::preview::fixtures::{look, scratch};

    /// Each GIF frame after the first stores only what changed; played, each shows the whole
    /// picture as composed.
    #[test]
    fn the_gif_shows_every_frame_whole_though_it_stores_only_changes() {
        let (w, h) = (64u32, 36u32);
        // Two small squares at opposite corners move a pixel a frame (a still camera: the
        // changes are transparent holes' worth of the rectangle); then everything changes
        // (the camera moved).
        let frames: Vec<Vec<u8>> = (0..5)
            .map(|k| {
                let base = if k == 4 {
                    [120u8, 100, 90]
                } else {
                    [90u8, 100, 110]
                };
                let mut rgb = base.repeat((w * h) as usize);
                for (x0, y0) in [(2 + k, 2), (56 - k, 28)] {
                    for y in y0..y0 + 4 {
                        for x in x0..x0 + 4 {
                            let i = ((y * w + x) * 3) as usize;
                            rgb[i..i + 3].copy_from_slice(&WHITE);
                        }
                    }
                }
                rgb
            })
            .collect();
        let path = scratch("changes").with_extension("gif");
        write_gif(&path, w, h, &frames, &[50; 5], &look(1)).unwrap();
        let mut opts = ::gif::DecodeOptions::new();
        opts.set_color_output(::gif::ColorOutput::RGBA);
        let file = std::fs::File::open(&path).unwrap();
        let mut dec = opts.read_info(std::io::BufReader::new(file)).unwrap();
        let mut canvas = vec![0u8; (w * h * 4) as usize];
        let mut k = 0;
        while let Some(f) = dec.read_next_frame().unwrap() {
            // The first and the last whole; those between with their unchanged pixels
            // transparent.
            assert_eq!(f.transparent.is_some(), (1..4).contains(&k), "frame {k}");
            for (i, p) in f.buffer.chunks_exact(4).enumerate() {
                let (x, y) = (
                    usize::from(f.left) + i % usize::from(f.width),
                    usize::from(f.top) + i / usize::from(f.width),
                );
                if p[3] > 0 {
                    let o = (y * w as usize + x) * 4;
                    canvas[o..o + 4].copy_from_slice(p);
                }
            }
            for (i, want) in frames[k].chunks_exact(3).enumerate() {
                let got = &canvas[i * 4..i * 4 + 3];
                assert!(
                    (0..3).all(|c| got[c].abs_diff(want[c]) <= 8),
                    "frame {k} pixel {i}: {got:?} for {want:?}"
                );
            }
            k += 1;
        }
        assert_eq!(k, 5);
        std::fs::remove_file(path).unwrap();
    }
}
