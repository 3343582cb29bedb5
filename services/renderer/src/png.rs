//! PNG files of frames (the `png` crate: deflate only, no image-processing stack).

use std::io::BufWriter;
use std::path::Path;

use crate::error::RenderError;
use crate::image::Image;

/// Writes `img` as an 8-bit sRGB RGBA PNG, a new private file (`common::output::create_new`:
/// an existing file or a link at `path` is refused, never written through; the launcher's
/// `--force` removed an earlier session's frames).
pub fn write_png(path: &Path, img: &Image) -> Result<(), RenderError> {
    let io =
        |e: &dyn std::fmt::Display| RenderError::Io(format!("writing {}: {e}", path.display()));
    let file = common::output::create_new(path).map_err(|e| io(&e))?;
    let mut enc = ::png::Encoder::new(BufWriter::new(file), img.width, img.height);
    enc.set_color(::png::ColorType::Rgba);
    enc.set_depth(::png::BitDepth::Eight);
    enc.set_source_srgb(::png::SrgbRenderingIntent::Perceptual);
    // Fast compression: frames are written while the session runs.
    enc.set_compression(::png::Compression::Fast);
    let mut w = enc.write_header().map_err(|e| io(&e))?;
    w.write_image_data(&img.rgba).map_err(|e| io(&e))?;
    w.finish().map_err(|e| io(&e))
}

/// Reads an 8-bit RGBA or RGB PNG (tests and tools read frames back with it).
pub fn read_png(path: &Path) -> Result<Image, RenderError> {
    let io =
        |e: &dyn std::fmt::Display| RenderError::Io(format!("reading {}: {e}", path.display()));
    let file = std::fs::File::open(path).map_err(|e| io(&e))?;
    let mut dec = ::png::Decoder::new(std::io::BufReader::new(file));
    dec.set_transformations(::png::Transformations::EXPAND);
    let mut reader = dec.read_info().map_err(|e| io(&e))?;
    let size = reader
        .output_buffer_size()
        .ok_or_else(|| io(&"image too large"))?;
    let mut buf = vec![0; size];
    let info = reader.next_frame(&mut buf).map_err(|e| io(&e))?;
    buf.truncate(info.buffer_size());
    let rgba = match info.color_type {
        ::png::ColorType::Rgba => buf,
        ::png::ColorType::Rgb => buf
            .chunks(3)
            .flat_map(|c| [c[0], c[1], c[2], 255])
            .collect(),
        other => return Err(io(&format!("unsupported colour type {other:?}"))),
    };
    Ok(Image {
        width: info.width,
        height: info.height,
        rgba,
    })
}
