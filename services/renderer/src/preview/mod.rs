//! The animated preview a session without a display leaves behind: an animated PNG (APNG,
//! which every web browser plays) and a GIF beside it (same stem; what every image viewer and
//! chat plays), at most [`OUT_WIDTH`] x [`OUT_HEIGHT`].
//!
//! What it shows, so that it reads at a glance:
//! - one eye (the left), not both side by side: twice the size for the same width, and in the
//!   blocks' own colours whatever the output mode (an anaglyph's would be tinted);
//! - **the action, in time**: the render loop keeps the world [`KEEP_HZ`] times a second of
//!   world time (a copy into a recycled slot; nothing is read back during the session, at most
//!   [`MAX_STATES`] worlds). When the session ends, [`PreviewWriter::plan`] finds the action
//!   (a block moving, a block in the hand, a grasp, a release, a push) and keeps the worlds
//!   from [`LEAD_S`] before its first moment (earlier while the hand already closes in on the
//!   blocks it will move, up to [`MAX_LEAD_S`]) to [`TAIL_S`] after its last (the last block
//!   come to rest; a lead or a tail where the hand is under the floor, as a trace's resting
//!   hand is, only `HIDDEN_S` of it): at most [`MAX_FRAMES`] frames, every kept world near the
//!   action (a throw over several frames, at its own pace) and fewer in calm stretches, which
//!   play faster;
//! - **the action, in space**: each frame has its own camera, looking along one direction
//!   for the whole preview (the session camera's unless another is clearly better,
//!   `camera::frame_spheres`), moved and zoomed to hold that moment's hand and the blocks the
//!   hand touches or moves (not every block, nor the floor under them), the view at least
//!   [`MIN_VIEW_M`] wide; its aim is smoothed over time and its distance never less than any
//!   moment's within [`HOLD_S`] needs, so the hand and those blocks are inside every frame and
//!   the view glides rather than jumps. Each kept world is drawn again with its camera
//!   (`Renderer::render_preview`) at the eye's full resolution, and the frame is cut at a
//!   16:9 band of the eye's image. Deterministic (the same motion gives the same preview),
//!   free while the session runs, and it holds what the session did (a replayed hand no camera
//!   chosen beforehand could know). The session's camera and the live window stay as
//!   configured;
//! - an overlay ([`crate::overlay`]): time, each block's name (in its colour) and mode (in its
//!   outline's colour), the latest event;
//! - the APNG's default image (what a viewer that does not animate shows) is a poster: a frame
//!   from the middle of the grasp, or else of the most motion; it is not part of the animation.
//!
//! A session where nothing moves shows all of it, at most [`MAX_FRAMES`] frames of it, framed
//! on the hand and every block. Cropping, writing text and encoding happen on the preview's own
//! thread.
//!
//! Files by concept: `events` (what happened between the worlds drawn), `store` (the worlds
//! kept), `action` (the action in time: the frames shown and how long), `framing` (the action
//! in space: the crop and each frame's camera), `frames` (the drawn frames on the preview's
//! thread: stored, cropped, written over), `resample` (the pixels scaled), `encode` (the
//! animated PNG and the GIF). This module is the public API and the orchestration: the writer
//! the render loop calls, and the plan.

mod action;
mod encode;
mod events;
mod frames;
mod framing;
mod resample;
mod store;

use std::path::PathBuf;
use std::sync::mpsc::{sync_channel, Receiver, SyncSender};
use std::thread::JoinHandle;

use common::config::Scene;
use common::{BlockMode, HandSample, WorldView};

use crate::camera::{block_radius, CameraSettings};
use crate::draw_list::block_colors;
use crate::error::RenderError;
use crate::image::Image;
use crate::renderer::Renderer;

pub use encode::{describe, describe_gif, gif_path, PreviewInfo};
pub use events::{Event, EventKind, EventTracker};
pub use framing::Rect;

use events::drawn_mode;
use frames::FrameStore;
use store::{KeptState, StateStore};

/// Worlds the render loop keeps per second of world time.
pub const KEEP_HZ: f64 = 20.0;
/// Worlds kept at most (about 25 MB for 1024 blocks): when full, every other one goes and the
/// rate halves, so a long session keeps the whole of it, more sparsely.
pub const MAX_STATES: usize = 200;
/// Frames of the preview at most.
pub const MAX_FRAMES: usize = 60;
/// The preview's size (16:9, one eye). A smaller rendered image gives a smaller preview
/// (see [`MAX_ZOOM`]).
pub const OUT_WIDTH: u32 = 640;
pub const OUT_HEIGHT: u32 = 360;
/// The largest preview any session writes (what the tests hold it to).
pub const MAX_WIDTH: u32 = 660;
pub const MAX_HEIGHT: u32 = 360;
/// The preview magnifies the rendered pixels at most this much (more would only blur).
pub const MAX_ZOOM: f64 = 2.0;
/// Seconds shown before the first moment of action, and at most before it while the hand
/// closes in (within `NEAR_M` of a block it will move).
pub const LEAD_S: f64 = 0.5;
pub const MAX_LEAD_S: f64 = 1.5;
/// Seconds shown after the last moment of action (the block at rest).
pub const TAIL_S: f64 = 0.5;
/// The narrowest view at the aim, metres: the hand alone does not fill the picture.
pub const MIN_VIEW_M: f64 = 0.55;
/// The camera's aim is averaged over this time (the Gaussian's sigma, seconds); its distance
/// is at least any frame's within [`HOLD_S`] needs, then averaged over as long.
const SMOOTH_S: f64 = 0.2;
pub const HOLD_S: f64 = 0.3;

/// What a preview frame shows besides its pixels.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FrameFacts {
    /// Session time, seconds.
    pub time_s: f64,
    /// Each block's mode as drawn, scene order.
    pub modes: Vec<BlockMode>,
    pub event: Option<Event>,
}

/// What the preview knows of the scene: the blocks' names, colours (sRGB bytes) and sizes,
/// and the world's step rate (its clock).
#[derive(Debug, Clone, PartialEq)]
pub struct PreviewScene {
    pub names: Vec<String>,
    pub colors: Vec<[u8; 3]>,
    pub radii: Vec<f64>,
    pub step_hz: f64,
}

impl PreviewScene {
    pub fn of(scene: &Scene) -> PreviewScene {
        PreviewScene {
            names: scene.blocks.iter().map(|b| b.name.clone()).collect(),
            colors: block_colors(scene)
                .iter()
                .map(|c| c.map(|v| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8))
                .collect(),
            radii: scene
                .blocks
                .iter()
                .map(|b| block_radius(&b.shape))
                .collect(),
            step_hz: scene.world.step_hz,
        }
    }
}

/// A preview frame on its way to the thread: the eye's pixels and the frame's facts, both
/// recycled, how long it shows and the part of the eye's image the preview keeps.
#[derive(Default)]
struct PreviewFrame {
    image: Image,
    facts: FrameFacts,
    delay_ms: u32,
    crop: Option<Rect>,
}

/// One frame of the preview as planned: the time of the kept world it draws, the camera that
/// draws it, and how long it shows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlannedFrame {
    /// Session time of the world it draws, seconds.
    pub time_s: f64,
    /// The mono camera it is drawn with (the eye's full image; the preview keeps `crop`).
    pub camera: CameraSettings,
    /// How long it shows, milliseconds (a multiple of 10, GIF's unit).
    pub delay_ms: u32,
    /// The kept world's index.
    state: usize,
}

/// What the preview will show: its frames and the part of the eye's image it keeps.
#[derive(Debug, Clone, PartialEq)]
pub struct PreviewPlan {
    pub frames: Vec<PlannedFrame>,
    /// The part of every frame the preview keeps, eye pixels: a 16:9 band of the eye's image
    /// (the whole image when that is no wider), the action below its top `OVERLAY_ROOM`.
    pub crop: Rect,
    /// Session time of the first and the last world kept, seconds.
    pub session_s: (f64, f64),
    /// The first and the last moment of action (a block moving or in the hand, a grasp, a
    /// release, a push), seconds; None when nothing happened.
    pub action_s: Option<(f64, f64)>,
}

/// The frames a preview of `states` shows, for an eye of `width` x `height` whose session
/// camera is `session`; None when no world was kept. See the module's comment: in time
/// ([`action`], steps 1-4), then in space ([`framing`], step 5).
fn plan_states(
    states: &[KeptState],
    radii: &[f64],
    session: &CameraSettings,
    (width, height): (u32, u32),
) -> Option<PreviewPlan> {
    let shown = action::shown(states, radii)?;
    let (crop, cameras) = framing::cameras(states, &shown, radii, session, (width, height));
    let m = shown.chosen.len();
    Some(PreviewPlan {
        frames: (0..m)
            .map(|k| PlannedFrame {
                time_s: shown.times[k],
                camera: cameras[k],
                delay_ms: shown.delays[k],
                state: shown.chosen[k],
            })
            .collect(),
        crop,
        session_s: shown.session_s,
        action_s: shown.action_s,
    })
}

/// The preview being made: the render loop keeps the world [`KEEP_HZ`] times a second of world
/// time; when the session ends, [`Self::plan`] picks the frames and their cameras, each is
/// drawn, and the preview's thread crops, writes text and encodes.
pub struct PreviewWriter {
    to_writer: Option<SyncSender<PreviewFrame>>,
    free: Receiver<PreviewFrame>,
    thread: Option<JoinHandle<Result<(), RenderError>>>,
    /// World time of the next world to keep, seconds.
    next_keep_s: f64,
    path: PathBuf,
    radii: Vec<f64>,
    step_hz: f64,
    events: EventTracker,
    states: StateStore,
}

impl PreviewWriter {
    /// Starts the preview's thread; the files (`path`, and [`gif_path`] of it) are written
    /// when [`Self::finish`] is called.
    pub fn start(path: PathBuf, scene: &Scene) -> Result<PreviewWriter, RenderError> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir)
                .map_err(|e| RenderError::Io(format!("preview folder {}: {e}", dir.display())))?;
        }
        let look = PreviewScene::of(scene);
        let (radii, step_hz) = (look.radii.clone(), look.step_hz);
        let blocks = look.names.len();
        let (to_writer, from_loop) = sync_channel::<PreviewFrame>(1);
        let (to_free, free) = sync_channel::<PreviewFrame>(2);
        for _ in 0..2 {
            let _ = to_free.try_send(PreviewFrame::default());
        }
        let target = path.clone();
        let thread = std::thread::Builder::new()
            .name("preview".into())
            .spawn(move || {
                let mut store = FrameStore::default();
                while let Ok(f) = from_loop.recv() {
                    store.offer(&f.image, &f.facts, f.delay_ms);
                    store.crop = f.crop;
                    let _ = to_free.try_send(f);
                }
                store.write(&target, &gif_path(&target), &look)
            })
            .map_err(|e| RenderError::Io(format!("starting the preview writer: {e}")))?;
        Ok(PreviewWriter {
            to_writer: Some(to_writer),
            free,
            thread: Some(thread),
            next_keep_s: f64::NEG_INFINITY,
            path,
            radii,
            step_hz,
            events: EventTracker::new(blocks),
            states: StateStore::default(),
        })
    }

    /// Called after each frame drawn (of `world` and `hand`, and a two-hand session's `left`
    /// hand): follows the events, and keeps the world when one is due by world time (a copy
    /// into a recycled state: nothing is read back from the GPU during the session).
    pub fn after_frame(
        &mut self,
        world: WorldView<'_>,
        hand: &HandSample,
        left: Option<&HandSample>,
    ) {
        let time_s = world.step as f64 / self.step_hz;
        self.events.observe(world, time_s);
        if time_s < self.next_keep_s || !time_s.is_finite() {
            return;
        }
        self.next_keep_s = ((time_s * KEEP_HZ).floor() + 1.0) / KEEP_HZ;
        if !self.states.wants_next() {
            return;
        }
        let mut s = self.states.slot();
        s.header = *world.header;
        s.blocks.clear();
        s.blocks.extend_from_slice(world.blocks());
        s.hand = *hand;
        s.left = left.copied();
        s.hand_events = self.events.hand_events;
        s.facts.time_s = time_s;
        s.facts.modes.clear();
        s.facts.modes.extend(
            world
                .blocks()
                .iter()
                .enumerate()
                .map(|(i, b)| drawn_mode(world, i, b.mode())),
        );
        s.facts.event = self.events.latest;
        self.states.kept.push(s);
    }

    /// What the preview of the worlds kept so far shows, for an eye of `width` x `height`
    /// whose session camera is `session`: the frames (the worlds near the action), each one's
    /// camera and delay, and the crop. None before any world was kept.
    pub fn plan(&self, width: u32, height: u32, session: &CameraSettings) -> Option<PreviewPlan> {
        plan_states(&self.states.kept, &self.radii, session, (width, height))
    }

    /// Draws the planned frames, each with its camera, hands them to the thread, which writes
    /// the preview files, and stops it. Without a renderer, or when drawing fails, no preview
    /// is written.
    pub fn finish(mut self, r: Option<&mut Renderer>) {
        if let Some(r) = r {
            if let Err(e) = self.draw_kept(r) {
                eprintln!("renderer: preview {}: {e}", self.path.display());
            }
        }
        self.to_writer = None;
        if let Some(t) = self.thread.take() {
            match t.join() {
                Ok(Ok(())) => {}
                Ok(Err(e)) => eprintln!("renderer: preview {}: {e}", self.path.display()),
                Err(_) => eprintln!("renderer: the preview writer failed"),
            }
        }
    }

    fn draw_kept(&mut self, r: &mut Renderer) -> Result<(), RenderError> {
        let (w, h) = (r.settings().width, r.settings().height);
        let session = r.settings().camera;
        let Some(plan) = self.plan(w, h, &session) else {
            return Ok(());
        };
        for p in &plan.frames {
            let Ok(mut f) = self.free.recv() else {
                break; // the thread is gone: its error is reported by finish
            };
            let s = &self.states.kept[p.state];
            r.render_preview(s.view(), &s.hand, s.left.as_ref(), &p.camera)?;
            r.read_back_left_eye_into(&mut f.image)?;
            f.facts.clone_from(&s.facts);
            f.delay_ms = p.delay_ms;
            f.crop = Some(plan.crop);
            if let Some(tx) = &self.to_writer {
                if tx.send(f).is_err() {
                    break;
                }
            }
        }
        Ok(())
    }
}

/// What the tests of the preview's parts draw and write with.
#[cfg(test)]
mod fixtures {
    use std::path::PathBuf;

    use common::BlockMode;

    use super::{FrameFacts, PreviewScene};
    use crate::image::Image;

    pub(super) fn frame(w: u32, h: u32, rgba: [u8; 4]) -> Image {
        Image {
            width: w,
            height: h,
            rgba: rgba.repeat((w * h) as usize),
        }
    }

    pub(super) fn look(n: usize) -> PreviewScene {
        PreviewScene {
            names: (0..n).map(|i| format!("b{i}")).collect(),
            colors: vec![[200, 30, 20]; n],
            radii: vec![0.05; n],
            step_hz: 120.0,
        }
    }

    pub(super) fn facts(t: f64) -> FrameFacts {
        FrameFacts {
            time_s: t,
            modes: vec![BlockMode::Resting],
            event: None,
        }
    }

    pub(super) fn scratch(name: &str) -> PathBuf {
        std::env::temp_dir().join(format!("hb-preview-{name}-{}.png", std::process::id()))
    }
}
