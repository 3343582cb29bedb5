//! The animated PNG (what every web browser plays): writing it, and reading back its frames'
//! count, size and length.

use std::path::Path;

use super::PreviewInfo;
use crate::error::RenderError;

/// The frame count, size and length of an (animated) PNG file (its animation's frames; a
/// separate default image is not one of them).
pub fn describe(path: &Path) -> Option<PreviewInfo> {
    let file = std::fs::File::open(path).ok()?;
    let dec = ::png::Decoder::new(std::io::BufReader::new(file));
    let reader = dec.read_info().ok()?;
    let info = reader.info();
    Some(PreviewInfo {
        frames: info.animation_control.map_or(1, |a| a.num_frames),
        width: info.width,
        height: info.height,
        duration_ms: apng_duration_ms(&std::fs::read(path).ok()?),
    })
}

/// The delays of an APNG's frames (its `fcTL` chunks) added, milliseconds; 0 for a still PNG.
fn apng_duration_ms(bytes: &[u8]) -> u32 {
    let mut at = 8; // the signature
    let mut ms = 0.0;
    while let Some(head) = bytes.get(at..at + 8) {
        let len = u32::from_be_bytes([head[0], head[1], head[2], head[3]]) as usize;
        if &head[4..8] == b"fcTL" {
            if let Some(d) = bytes.get(at + 8..at + 8 + len).filter(|d| d.len() >= 24) {
                let num = u16::from_be_bytes([d[20], d[21]]);
                let den = match u16::from_be_bytes([d[22], d[23]]) {
                    0 => 100,
                    den => den,
                };
                ms += 1000.0 * f64::from(num) / f64::from(den);
            }
        }
        at = at.saturating_add(12).saturating_add(len);
    }
    ms.round() as u32
}

/// Writes the animated PNG: the poster first, as its default image, then each frame with its
/// own delay.
pub(crate) fn write_apng(
    path: &Path,
    w: u32,
    h: u32,
    frames: &[Vec<u8>],
    poster: usize,
    delays_ms: &[u32],
) -> Result<(), RenderError> {
    let encode = |file: &mut std::fs::File| -> Result<(), ::png::EncodingError> {
        let mut enc = ::png::Encoder::new(std::io::BufWriter::new(file), w, h);
        enc.set_color(::png::ColorType::Rgb);
        enc.set_depth(::png::BitDepth::Eight);
        enc.set_source_srgb(::png::SrgbRenderingIntent::Perceptual);
        enc.set_compression(::png::Compression::Balanced);
        enc.set_animated(frames.len() as u32, 0)?;
        // The poster first, as the default image that is no frame of the animation: what a
        // viewer that does not animate PNGs shows.
        enc.set_sep_def_img(true)?;
        let ms = |k: usize| {
            delays_ms
                .get(k)
                .map_or(100, |d| (*d).min(u32::from(u16::MAX)) as u16)
        };
        enc.set_frame_delay(ms(0), 1000)?;
        let mut wr = enc.write_header()?;
        wr.write_image_data(&frames[poster.min(frames.len() - 1)])?;
        for (k, f) in frames.iter().enumerate() {
            // Each frame's own delay goes into its fcTL, written with its data.
            wr.set_frame_delay(ms(k), 1000)?;
            wr.write_image_data(f)?;
        }
        wr.finish()
    };
    common::output::replace(path, |file| encode(file).map_err(std::io::Error::other))
        .map_err(|e| RenderError::Io(format!("writing {}: {e}", path.display())))
}
