//! The preview's frames on its own thread: stored shrunk as they are drawn, then cropped,
//! scaled and written over (the overlay), the poster picked, and handed to the encoders.

use std::path::Path;

use common::BlockMode;

use super::encode::{write_apng, write_gif};
use super::framing::Rect;
use super::resample::{resample, shrink_rgba};
use super::{FrameFacts, PreviewScene, MAX_FRAMES, MAX_ZOOM, OUT_HEIGHT, OUT_WIDTH};
use crate::error::RenderError;
use crate::image::Image;
use crate::overlay::{self, Canvas};

/// Kept frames are stored shrunk (a whole factor) to at most this size: 60 frames of it are
/// 124 MB at most, 55 MB for the default 640 x 480 eye.
const STORE_MAX_WIDTH: u32 = 960;
const STORE_MAX_HEIGHT: u32 = 720;

/// A kept frame: RGB at the store's size, its facts and how long it shows.
struct Kept {
    rgb: Vec<u8>,
    facts: FrameFacts,
    delay_ms: u32,
}

/// The preview's frames as drawn, all one size (at most [`MAX_FRAMES`]), and the part of them
/// the preview keeps.
#[derive(Default)]
pub(super) struct FrameStore {
    frames: Vec<Kept>,
    /// The stored frames' size, and the whole factor they were shrunk by.
    width: u32,
    height: u32,
    shrink: u32,
    /// The part kept, eye pixels (None: all of it).
    pub(super) crop: Option<Rect>,
}

impl FrameStore {
    pub(super) fn offer(&mut self, frame: &Image, facts: &FrameFacts, delay_ms: u32) {
        if self.frames.is_empty() {
            self.shrink = frame
                .width
                .div_ceil(STORE_MAX_WIDTH)
                .max(frame.height.div_ceil(STORE_MAX_HEIGHT))
                .max(1);
            self.width = frame.width / self.shrink;
            self.height = frame.height / self.shrink;
        }
        let size = (frame.width / self.shrink, frame.height / self.shrink);
        if size != (self.width, self.height) || self.frames.len() >= MAX_FRAMES {
            return;
        }
        self.frames.push(Kept {
            rgb: shrink_rgba(frame, self.shrink),
            facts: facts.clone(),
            delay_ms,
        });
    }

    /// The rectangle of the stored frames the preview shows: the plan's crop, within them.
    fn crop(&self) -> Rect {
        let (iw, ih) = (f64::from(self.width), f64::from(self.height));
        let c = self
            .crop
            .map(|c| c.scaled(1.0 / f64::from(self.shrink.max(1))))
            .map(|c| Rect {
                x0: c.x0.max(0.0),
                y0: c.y0.max(0.0),
                x1: c.x1.min(iw),
                y1: c.y1.min(ih),
            })
            .filter(|c| c.width() >= 1.0 && c.height() >= 1.0);
        c.unwrap_or(Rect {
            x0: 0.0,
            y0: 0.0,
            x1: iw,
            y1: ih,
        })
    }

    /// The preview's size for a crop: as large as OUT_WIDTH x OUT_HEIGHT holds at its aspect,
    /// or less where that would magnify more than MAX_ZOOM.
    fn out_size(crop: &Rect) -> (u32, u32) {
        let aspect = crop.width() / crop.height();
        let (w, h) = out_size_for(aspect);
        let zoom = (f64::from(w) / crop.width()).min(MAX_ZOOM) / (f64::from(w) / crop.width());
        let w = (f64::from(w) * zoom).round().max(16.0) as u32;
        let h = (f64::from(h) * zoom).round().max(9.0) as u32;
        (w, h)
    }

    /// The preview's frames (cropped, scaled, with the overlay), their size, and the poster's
    /// index.
    fn compose(&self, look: &PreviewScene) -> (u32, u32, Vec<Vec<u8>>, usize) {
        let crop = self.crop();
        let (ow, oh) = Self::out_size(&crop);
        let mut out = Vec::with_capacity(self.frames.len());
        for k in &self.frames {
            let mut rgb = vec![0u8; (ow * oh * 3) as usize];
            resample(&k.rgb, self.width, self.height, &crop, &mut rgb, ow, oh);
            let event = k.facts.event.map(|e| e.text(&look.names));
            let lines = overlay::lines(
                k.facts.time_s,
                &look.names,
                &look.colors,
                &k.facts.modes,
                event.as_deref(),
            );
            overlay::draw(
                &mut Canvas {
                    rgb: &mut rgb,
                    width: ow,
                    height: oh,
                },
                &lines,
            );
            out.push(rgb);
        }
        (ow, oh, out, self.poster())
    }

    /// The frame a viewer that does not animate shows: the middle of the grasp (the block in
    /// the hand), else of the frames where the most blocks move, else the middle one.
    fn poster(&self) -> usize {
        let held: Vec<usize> = (0..self.frames.len())
            .filter(|&i| {
                self.frames[i]
                    .facts
                    .modes
                    .iter()
                    .any(|m| matches!(m, BlockMode::Grasped | BlockMode::Carried))
            })
            .collect();
        if let Some(&i) = held.get(held.len() / 2) {
            return i;
        }
        let busy = |i: usize| {
            self.frames[i]
                .facts
                .modes
                .iter()
                .filter(|m| **m != BlockMode::Resting)
                .count()
        };
        let most = (0..self.frames.len()).map(busy).max().unwrap_or(0);
        if most > 0 {
            let busiest: Vec<usize> = (0..self.frames.len())
                .filter(|&i| busy(i) == most)
                .collect();
            return busiest[busiest.len() / 2];
        }
        self.frames.len() / 2
    }

    /// Writes the animated PNG and the GIF, each whole beside its path and renamed over it
    /// (`common::output::replace`): the preview is the session's own output at a fixed path,
    /// replaced each run; a link there is replaced, never written through; private (0600).
    pub(super) fn write(
        &self,
        apng: &Path,
        gif_file: &Path,
        look: &PreviewScene,
    ) -> Result<(), RenderError> {
        if self.frames.is_empty() {
            return Err(RenderError::Io(format!(
                "writing {}: no frame was drawn",
                apng.display()
            )));
        }
        let (w, h, frames, poster) = self.compose(look);
        let delays: Vec<u32> = self
            .frames
            .iter()
            .map(|k| k.delay_ms.clamp(10, 60_000))
            .collect();
        write_apng(apng, w, h, &frames, poster, &delays)?;
        write_gif(gif_file, w, h, &frames, &delays, look)
    }
}

/// The largest size of this aspect within OUT_WIDTH x OUT_HEIGHT.
fn out_size_for(aspect: f64) -> (u32, u32) {
    let w = f64::from(OUT_WIDTH).min(f64::from(OUT_HEIGHT) * aspect);
    (w.round() as u32, (w / aspect).round() as u32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::preview::fixtures::{facts, frame, look, scratch};
    use crate::preview::{
        describe, describe_gif, gif_path, Event, EventKind, MAX_HEIGHT, MAX_WIDTH,
    };

    /// Both files hold the same frames, at the same size, each shown as long as planned; no
    /// more than MAX_FRAMES of them.
    #[test]
    fn both_files_hold_the_frames_with_their_own_delays_within_the_frame_limit() {
        let mut store = FrameStore::default();
        let f = frame(320, 240, [90, 120, 150, 255]);
        for i in 0..(MAX_FRAMES + 5) {
            let delay = if i < 10 { 50 } else { 150 };
            store.offer(&f, &facts(i as f64 * 0.05), delay);
        }
        assert_eq!(store.frames.len(), MAX_FRAMES);
        let path = scratch("delays");
        let gif_file = gif_path(&path);
        store.write(&path, &gif_file, &look(1)).unwrap();
        let info = describe(&path).unwrap();
        assert_eq!(info.frames as usize, MAX_FRAMES);
        assert_eq!(info.duration_ms, 10 * 50 + (MAX_FRAMES as u32 - 10) * 150);
        assert!(
            info.width <= MAX_WIDTH && info.height <= MAX_HEIGHT,
            "{info:?}"
        );
        // The GIF decodes, with the same frames at the same size, as long.
        assert_eq!(describe_gif(&gif_file).unwrap(), info);
        std::fs::remove_file(path).unwrap();
        std::fs::remove_file(gif_file).unwrap();
    }

    /// The plan's crop of the eye's image is what the frames show, at 16:9.
    #[test]
    fn the_frames_show_the_crop_at_16_to_9() {
        let mut store = FrameStore {
            crop: Some(Rect {
                x0: 0.0,
                y0: 42.0,
                x1: 640.0,
                y1: 402.0,
            }),
            ..FrameStore::default()
        };
        store.offer(&frame(640, 480, [0, 0, 0, 255]), &facts(0.0), 50);
        let c = store.crop();
        assert_eq!((c.x0, c.y0, c.x1, c.y1), (0.0, 42.0, 640.0, 402.0));
        assert_eq!(FrameStore::out_size(&c), (OUT_WIDTH, OUT_HEIGHT));
    }

    #[test]
    fn the_overlay_marks_every_frame_and_the_poster_is_a_held_frame() {
        let mut store = FrameStore::default();
        let f = frame(640, 480, [128, 128, 128, 255]);
        for i in 0..10 {
            let mut x = facts(i as f64 * 0.2);
            if (4..7).contains(&i) {
                x.modes[0] = BlockMode::Grasped;
                x.event = Some(Event {
                    kind: EventKind::Grasp,
                    block: 0,
                    time_s: 0.8,
                });
            }
            store.offer(&f, &x, 50);
        }
        assert_eq!(store.poster(), 5);
        let (w, h, frames, _) = store.compose(&look(1));
        // No crop: the whole eye, at its 4:3.
        assert_eq!((w, h), (480, 360));
        for (k, rgb) in frames.iter().enumerate() {
            // The overlay's box, top-left, differs from the plain grey; the opposite corner
            // does not.
            let changed = |x0: u32, y0: u32| {
                (y0..y0 + 30)
                    .flat_map(|y| (x0..x0 + 60).map(move |x| (x, y)))
                    .filter(|&(x, y)| {
                        let i = ((y * w + x) * 3) as usize;
                        rgb[i..i + 3] != [128, 128, 128]
                    })
                    .count()
            };
            assert!(changed(0, 0) > 900, "frame {k}: {}", changed(0, 0));
            assert_eq!(changed(w - 60, h - 30), 0, "frame {k}");
        }
    }
}
