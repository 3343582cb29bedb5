//! The animated preview a session without a display leaves behind: an animated PNG (APNG,
//! which every web browser plays) of the view, downscaled to at most [`MAX_WIDTH`] x
//! [`MAX_HEIGHT`], at [`PREVIEW_HZ`] frames per second.
//!
//! The render loop only reads a frame back every 1 / PREVIEW_HZ seconds and hands it over in a
//! recycled image; downscaling, keeping and encoding happen on the preview's own thread, and
//! when that thread is busy the frame is skipped rather than the loop waiting. At most
//! [`MAX_FRAMES`] frames are kept: when the store is full, every other frame is dropped and
//! the rate halves, so a long session becomes a time-lapse of the whole of it.

use std::path::{Path, PathBuf};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender, TryRecvError};
use std::thread::JoinHandle;

use crate::error::RenderError;
use crate::image::{Image, EYE_GAP, GAP_RGB};
use crate::renderer::Renderer;
use crate::settings::OutputMode;

/// Frames per second of the preview at first.
pub const PREVIEW_HZ: f64 = 5.0;
/// The preview's largest size, pixels.
pub const MAX_WIDTH: u32 = 660;
pub const MAX_HEIGHT: u32 = 360;
/// Frames kept (of MAX_WIDTH x MAX_HEIGHT RGB: at most 43 MB).
pub const MAX_FRAMES: usize = 60;

/// What [`describe`] finds in an animated PNG.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PreviewInfo {
    pub frames: u32,
    pub width: u32,
    pub height: u32,
}

/// The frame count and size of an (animated) PNG file.
pub fn describe(path: &Path) -> Option<PreviewInfo> {
    let file = std::fs::File::open(path).ok()?;
    let dec = ::png::Decoder::new(std::io::BufReader::new(file));
    let reader = dec.read_info().ok()?;
    let info = reader.info();
    Some(PreviewInfo {
        frames: info.animation_control.map_or(1, |a| a.num_frames),
        width: info.width,
        height: info.height,
    })
}

/// `frame` (tightly packed RGBA, as read back) downscaled by the whole factor `k` (box filter)
/// into RGB `out`, with a gap between the eyes when `gap` (side-by-side).
pub fn downscale_into(frame: &Image, k: u32, side_by_side: bool, out: &mut Image) {
    let k = k.max(1);
    let (eyes, eye_w) = if side_by_side {
        (2, frame.width / 2)
    } else {
        (1, frame.width)
    };
    let ow = eye_w / k;
    let oh = frame.height / k;
    let gap = if side_by_side { EYE_GAP / k } else { 0 };
    out.width = ow * eyes + gap * (eyes - 1);
    out.height = oh;
    out.rgba.clear();
    out.rgba.reserve((out.width * out.height * 3) as usize);
    let n = k * k;
    for y in 0..oh {
        for e in 0..eyes {
            if e == 1 {
                for _ in 0..gap {
                    out.rgba.extend_from_slice(&GAP_RGB);
                }
            }
            for x in 0..ow {
                let mut sum = [0u32; 3];
                for dy in 0..k {
                    let row = ((y * k + dy) * frame.width) as usize;
                    for dx in 0..k {
                        let i = (row + (e * eye_w + x * k + dx) as usize) * 4;
                        for (c, s) in sum.iter_mut().enumerate() {
                            *s += u32::from(frame.rgba[i + c]);
                        }
                    }
                }
                for s in sum {
                    out.rgba.push((s / n) as u8);
                }
            }
        }
    }
}

/// The whole factor that brings a `width` x `height` frame within the preview's size.
pub fn scale_for(width: u32, height: u32) -> u32 {
    width
        .div_ceil(MAX_WIDTH)
        .max(height.div_ceil(MAX_HEIGHT))
        .max(1)
}

/// The preview being made: the render loop offers frames, its thread keeps and encodes them.
pub struct PreviewWriter {
    to_writer: Option<SyncSender<Image>>,
    free: Receiver<Image>,
    thread: Option<JoinHandle<Result<(), RenderError>>>,
    period_ns: u64,
    next_ns: u64,
    path: PathBuf,
}

impl PreviewWriter {
    /// Starts the preview's thread; the file is written when [`Self::finish`] is called.
    pub fn start(path: PathBuf, mode: OutputMode) -> Result<PreviewWriter, RenderError> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir)
                .map_err(|e| RenderError::Io(format!("preview folder {}: {e}", dir.display())))?;
        }
        let (to_writer, from_loop) = sync_channel::<Image>(1);
        let (to_free, free) = sync_channel::<Image>(2);
        for _ in 0..2 {
            let _ = to_free.try_send(Image::default());
        }
        let target = path.clone();
        let side_by_side = mode == OutputMode::SideBySide;
        let thread = std::thread::Builder::new()
            .name("preview".into())
            .spawn(move || {
                let mut store = FrameStore::default();
                while let Ok(img) = from_loop.recv() {
                    store.offer(&img, side_by_side);
                    let _ = to_free.try_send(img);
                }
                store.write(&target)
            })
            .map_err(|e| RenderError::Io(format!("starting the preview writer: {e}")))?;
        Ok(PreviewWriter {
            to_writer: Some(to_writer),
            free,
            thread: Some(thread),
            period_ns: (1e9 / PREVIEW_HZ) as u64,
            next_ns: 0,
            path,
        })
    }

    /// Called after each frame drawn at `now_ns`: reads it back and hands it over when a
    /// preview frame is due and the thread has a free image.
    pub fn after_frame(&mut self, r: &mut Renderer, now_ns: u64) -> Result<(), RenderError> {
        if now_ns < self.next_ns {
            return Ok(());
        }
        self.next_ns = now_ns + self.period_ns;
        let mut img = match self.free.try_recv() {
            Ok(img) => img,
            Err(TryRecvError::Empty) | Err(TryRecvError::Disconnected) => return Ok(()),
        };
        r.read_back_into(&mut img)?;
        if let Some(tx) = &self.to_writer {
            let _ = tx.try_send(img);
        }
        Ok(())
    }

    /// Writes the preview file and stops the thread.
    pub fn finish(mut self) {
        self.to_writer = None;
        if let Some(t) = self.thread.take() {
            match t.join() {
                Ok(Ok(())) => {}
                Ok(Err(e)) => eprintln!("renderer: preview {}: {e}", self.path.display()),
                Err(_) => eprintln!("renderer: the preview writer failed"),
            }
        }
    }
}

/// The kept frames, RGB, all one size.
#[derive(Default)]
struct FrameStore {
    frames: Vec<Vec<u8>>,
    width: u32,
    height: u32,
    /// Keep every `keep_every`-th offered frame (doubles each time the store fills).
    keep_every: u32,
    offered: u64,
    scratch: Image,
}

impl FrameStore {
    fn offer(&mut self, frame: &Image, side_by_side: bool) {
        if self.keep_every == 0 {
            self.keep_every = 1;
        }
        let n = self.offered;
        self.offered += 1;
        if !n.is_multiple_of(u64::from(self.keep_every)) {
            return;
        }
        let k = scale_for(frame.width, frame.height);
        downscale_into(frame, k, side_by_side, &mut self.scratch);
        if self.frames.is_empty() {
            self.width = self.scratch.width;
            self.height = self.scratch.height;
        } else if (self.scratch.width, self.scratch.height) != (self.width, self.height) {
            return;
        }
        if self.frames.len() == MAX_FRAMES {
            // Full: keep every other frame, at half the rate from now on.
            let mut i = 0;
            self.frames.retain(|_| {
                i += 1;
                i % 2 == 1
            });
            self.keep_every *= 2;
            if !n.is_multiple_of(u64::from(self.keep_every)) {
                return;
            }
        }
        self.frames.push(self.scratch.rgba.clone());
    }

    /// Writes the animated PNG whole beside `path` and renames it over `path`
    /// (`common::output::replace`): the preview is the session's own output at a fixed path,
    /// replaced each run; a link there is replaced, never written through; private (0600).
    fn write(&self, path: &Path) -> Result<(), RenderError> {
        let io =
            |e: &dyn std::fmt::Display| RenderError::Io(format!("writing {}: {e}", path.display()));
        if self.frames.is_empty() {
            return Err(io(&"no frame was drawn"));
        }
        let encode = |file: &mut std::fs::File| -> Result<(), ::png::EncodingError> {
            let mut enc =
                ::png::Encoder::new(std::io::BufWriter::new(file), self.width, self.height);
            enc.set_color(::png::ColorType::Rgb);
            enc.set_depth(::png::BitDepth::Eight);
            enc.set_source_srgb(::png::SrgbRenderingIntent::Perceptual);
            enc.set_compression(::png::Compression::Balanced);
            enc.set_animated(self.frames.len() as u32, 0)?;
            // Each kept frame stands for keep_every preview periods.
            let delay_ms = (1000.0 / PREVIEW_HZ) as u32 * self.keep_every.max(1);
            enc.set_frame_delay(delay_ms.min(u32::from(u16::MAX)) as u16, 1000)?;
            let mut w = enc.write_header()?;
            for f in &self.frames {
                w.write_image_data(f)?;
            }
            w.finish()
        };
        common::output::replace(path, |file| encode(file).map_err(std::io::Error::other))
            .map_err(|e| io(&e))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(w: u32, h: u32, rgba: [u8; 4]) -> Image {
        Image {
            width: w,
            height: h,
            rgba: rgba.repeat((w * h) as usize),
        }
    }

    #[test]
    fn side_by_side_eyes_get_a_gap_and_the_size_stays_modest() {
        let f = frame(1280, 480, [200, 100, 50, 255]);
        let k = scale_for(f.width, f.height);
        assert_eq!(k, 2);
        let mut out = Image::default();
        downscale_into(&f, k, true, &mut out);
        assert_eq!((out.width, out.height), (640 + EYE_GAP / 2, 240));
        assert_eq!(out.rgba.len(), (out.width * out.height * 3) as usize);
        // Left eye, gap, right eye along the first row.
        assert_eq!(&out.rgba[0..3], &[200, 100, 50]);
        let gap = (320 * 3) as usize;
        assert_eq!(&out.rgba[gap..gap + 3], &GAP_RGB);
        let right = ((320 + EYE_GAP / 2) * 3) as usize;
        assert_eq!(&out.rgba[right..right + 3], &[200, 100, 50]);
    }

    #[test]
    fn a_long_session_becomes_a_time_lapse_within_the_frame_limit() {
        let mut store = FrameStore::default();
        let f = frame(64, 48, [1, 2, 3, 255]);
        for _ in 0..500 {
            store.offer(&f, false);
        }
        assert!(store.frames.len() <= MAX_FRAMES, "{}", store.frames.len());
        assert!(store.frames.len() > MAX_FRAMES / 4);
        assert!(store.keep_every >= 8);
        let path = std::env::temp_dir().join(format!("hb-preview-{}.png", std::process::id()));
        store.write(&path).unwrap();
        let info = describe(&path).unwrap();
        assert_eq!(info.frames as usize, store.frames.len());
        assert_eq!((info.width, info.height), (64, 48));
        std::fs::remove_file(path).unwrap();
    }
}
