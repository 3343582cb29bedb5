//! The animated preview a session without a display leaves behind: an animated PNG (APNG,
//! which every web browser plays) and a GIF beside it (same stem; what every image viewer and
//! chat plays), at most [`OUT_WIDTH`] x [`OUT_HEIGHT`], at [`PREVIEW_HZ`] frames per second.
//!
//! What it shows, so that it reads at a glance:
//! - one eye (the left), not both side by side: twice the size for the same width, and in the
//!   blocks' own colours whatever the output mode (an anaglyph's would be tinted);
//! - framed on the action, with its own camera: the render loop keeps the world every
//!   1 / PREVIEW_HZ seconds (a copy into a recycled slot; nothing is read back during the
//!   session); when the session ends, a mono camera is fitted to all that those worlds hold
//!   (`camera::frame_spheres`: blocks, the floor under them, the hands), each is drawn again
//!   with it (`Renderer::render_preview`), and every frame is cut at one rectangle, the union
//!   of what each frame's blocks and hand cover, with a margin, at 4:3 to 16:9, zoomed at most
//!   [`MAX_ZOOM`] times. Deterministic, free while the session runs, and it holds what the
//!   session did (a lifted block, a throw's landing, a replayed hand no camera chosen
//!   beforehand could know). The session's camera and the live window stay as configured;
//! - an overlay ([`crate::overlay`]): time, each block's name (in its colour) and mode (in its
//!   outline's colour), the latest event;
//! - the APNG's default image (what a viewer that does not animate shows) is a poster: a frame
//!   from the middle of the grasp, or else of the most motion; it is not part of the animation.
//!
//! At most [`MAX_FRAMES`] worlds are kept: when the store is full, every other one goes and
//! the rate halves, so a long session becomes a time-lapse of it. Cropping, writing text and
//! encoding happen on the preview's own thread.

use std::path::{Path, PathBuf};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender};
use std::thread::JoinHandle;

use common::config::Scene;
use common::{BlockMode, BlockState, HandSample, WorldHeader, WorldView};
use glam::DVec3;

use crate::camera::{block_radius, frame_spheres, CameraSettings, EyeView};
use crate::draw_list::{block_colors, mode_color_srgb};
use crate::error::RenderError;
use crate::image::{Image, GAP_RGB};
use crate::overlay::{self, Canvas, WHITE};
use crate::renderer::Renderer;

/// Frames per second of the preview at first.
pub const PREVIEW_HZ: f64 = 5.0;
/// The preview's size (16:9, one eye). A smaller rendered image gives a smaller preview
/// (see [`MAX_ZOOM`]).
pub const OUT_WIDTH: u32 = 640;
pub const OUT_HEIGHT: u32 = 360;
/// The largest preview any session writes (what the tests hold it to).
pub const MAX_WIDTH: u32 = 660;
pub const MAX_HEIGHT: u32 = 360;
/// Frames kept.
pub const MAX_FRAMES: usize = 60;
/// Kept frames are stored shrunk (a whole factor) to at most this size: 60 frames of it are
/// 124 MB at most, 55 MB for the default 640 x 480 eye.
const STORE_MAX_WIDTH: u32 = 960;
const STORE_MAX_HEIGHT: u32 = 720;
/// The preview magnifies the rendered pixels at most this much (more would only blur).
pub const MAX_ZOOM: f64 = 2.0;
/// The preview's aspect follows the action's, from 4:3 (the default eye's) to 16:9.
const MIN_ASPECT: f64 = 4.0 / 3.0;
const MAX_ASPECT: f64 = 16.0 / 9.0;
/// Space kept around the action, as a fraction of its size, on each side.
const MARGIN: f64 = 0.05;
/// The crop's top gets this much more room (a fraction of the preview's height) for the
/// overlay's box over the sky rather than over the action.
const OVERLAY_ROOM: f64 = 0.06;

/// What [`describe`] and [`describe_gif`] find in a preview file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PreviewInfo {
    pub frames: u32,
    pub width: u32,
    pub height: u32,
}

/// The frame count and size of an (animated) PNG file (its animation's frames; a separate
/// default image is not one of them).
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

/// The frame count and size of a GIF file (every frame decoded).
pub fn describe_gif(path: &Path) -> Option<PreviewInfo> {
    let file = std::fs::File::open(path).ok()?;
    let mut opts = gif::DecodeOptions::new();
    opts.set_color_output(gif::ColorOutput::Indexed);
    let mut dec = opts.read_info(std::io::BufReader::new(file)).ok()?;
    let (width, height) = (u32::from(dec.width()), u32::from(dec.height()));
    let mut frames = 0;
    while let Some(_frame) = dec.read_next_frame().ok()? {
        frames += 1;
    }
    Some(PreviewInfo {
        frames,
        width,
        height,
    })
}

/// Where the GIF goes beside the animated PNG `apng`: the same stem, `.gif`.
pub fn gif_path(apng: &Path) -> PathBuf {
    apng.with_extension("gif")
}

/// A rectangle of an image, pixels (x to the right, y down).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rect {
    pub x0: f64,
    pub y0: f64,
    pub x1: f64,
    pub y1: f64,
}

impl Rect {
    fn point(x: f64, y: f64) -> Rect {
        Rect {
            x0: x,
            y0: y,
            x1: x,
            y1: y,
        }
    }

    fn union(self, o: Rect) -> Rect {
        Rect {
            x0: self.x0.min(o.x0),
            y0: self.y0.min(o.y0),
            x1: self.x1.max(o.x1),
            y1: self.y1.max(o.y1),
        }
    }

    fn width(&self) -> f64 {
        self.x1 - self.x0
    }

    fn height(&self) -> f64 {
        self.y1 - self.y0
    }

    fn scaled(self, k: f64) -> Rect {
        Rect {
            x0: self.x0 * k,
            y0: self.y0 * k,
            x1: self.x1 * k,
            y1: self.y1 * k,
        }
    }
}

/// Something the render loop saw happen, from the world samples it draws (the stepper's own
/// events do not reach the renderer: grasps and releases are the world's grasped block
/// changing, the rest a block's mode changing).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Event {
    pub kind: EventKind,
    /// The block's scene index.
    pub block: u32,
    /// Session time, seconds (the world's steps over its rate).
    pub time_s: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EventKind {
    Grasp,
    Release,
    /// The block's mode became this (other than by a grasp or a release).
    Became(BlockMode),
}

impl Event {
    /// `grasp red 1.05 s`, `release red 1.94 s`, `red resting 2.80 s`.
    pub fn text(&self, names: &[String]) -> String {
        let name = names.get(self.block as usize).map_or("?", String::as_str);
        match self.kind {
            EventKind::Grasp => format!("grasp {name} {:.2} s", self.time_s),
            EventKind::Release => format!("release {name} {:.2} s", self.time_s),
            EventKind::Became(m) => format!("{name} {} {:.2} s", m.name(), self.time_s),
        }
    }
}

/// Finds events between the world samples drawn; allocates only when made.
#[derive(Debug, Default)]
pub struct EventTracker {
    modes: Vec<BlockMode>,
    grasped: i32,
    seen: bool,
    /// The latest event so far.
    pub latest: Option<Event>,
}

impl EventTracker {
    pub fn new(blocks: usize) -> EventTracker {
        EventTracker {
            modes: vec![BlockMode::Resting; blocks],
            grasped: -1,
            seen: false,
            latest: None,
        }
    }

    /// Compares `world` with the one observed before it.
    pub fn observe(&mut self, world: WorldView<'_>, time_s: f64) {
        for (i, b) in world.blocks().iter().enumerate().take(self.modes.len()) {
            let m = drawn_mode(world, i, b.mode());
            let was = std::mem::replace(&mut self.modes[i], m);
            let by_grasp = [m, was].contains(&BlockMode::Grasped);
            if self.seen && m != was && !by_grasp {
                self.latest = Some(Event {
                    kind: EventKind::Became(m),
                    block: i as u32,
                    time_s,
                });
            }
        }
        let g = world.grasped_block;
        if self.seen && g != self.grasped {
            let (kind, block) = if g >= 0 {
                (EventKind::Grasp, g)
            } else {
                (EventKind::Release, self.grasped)
            };
            self.latest = Some(Event {
                kind,
                block: block as u32,
                time_s,
            });
        }
        self.grasped = g;
        self.seen = true;
    }
}

/// A block's mode as drawn: the grasped block shows as grasped.
fn drawn_mode(world: WorldView<'_>, i: usize, mode: BlockMode) -> BlockMode {
    if world.grasped_block == i as i32 {
        BlockMode::Grasped
    } else {
        mode
    }
}

/// What a preview frame shows besides its pixels.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FrameFacts {
    /// Session time, seconds.
    pub time_s: f64,
    /// Each block's mode as drawn, scene order.
    pub modes: Vec<BlockMode>,
    pub event: Option<Event>,
    /// Where the blocks and the hand are in the eye's image (None: nothing in front of it).
    pub action: Option<Rect>,
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

/// Where `world`'s blocks (each one's bounding sphere's box, and the floor under it) and the
/// hand (finger points, palm; and a two-hand session's `left` hand's, as tracked) land in an
/// eye's `width` x `height` image; None when nothing is in front of the eye. Allocates
/// nothing.
pub fn action_rect(
    eye: &EyeView,
    width: u32,
    height: u32,
    world: WorldView<'_>,
    hand: &HandSample,
    left: Option<&HandSample>,
    radii: &[f64],
) -> Option<Rect> {
    let mut r: Option<Rect> = None;
    let mut add = |p: DVec3| {
        if let Some((x, y)) = p
            .is_finite()
            .then(|| eye.project_px(p, width, height))
            .flatten()
        {
            let q = Rect::point(x, y);
            r = Some(r.map_or(q, |r| r.union(q)));
        }
    };
    for (i, b) in world.blocks().iter().enumerate() {
        let c = DVec3::from_array(b.pose.position);
        let s = radii.get(i).copied().unwrap_or(0.05);
        for k in 0..8 {
            let corner = DVec3::new(
                if k & 1 == 0 { -s } else { s },
                if k & 2 == 0 { -s } else { s },
                if k & 4 == 0 { -s } else { s },
            );
            add(c + corner);
        }
        add(DVec3::new(c.x, 0.0, c.z));
    }
    for p in drawn_finger_points(&world, hand) {
        add(p);
    }
    for p in hand.palm() {
        add(DVec3::from_array(*p));
    }
    if let Some(left) = left {
        for p in tracked_points(left).chain(left.palm().iter().map(|p| DVec3::from_array(*p))) {
            add(p);
        }
    }
    r
}

/// A preview frame on its way to the thread: the eye's pixels and the frame's facts, both
/// recycled, and how many preview periods it stands for.
#[derive(Default)]
struct PreviewFrame {
    image: Image,
    facts: FrameFacts,
    periods: u32,
}

/// A world as the preview keeps it until the session ends: the header, the blocks, the hand
/// it answers (and a two-hand session's newest left hand), and the facts of the moment.
struct KeptState {
    header: WorldHeader,
    blocks: Vec<BlockState>,
    hand: HandSample,
    left: Option<HandSample>,
    facts: FrameFacts,
}

/// The worlds kept for the preview, at most [`MAX_FRAMES`]: when full, every other one goes
/// and the rate halves (a time-lapse of the whole session). Dropped states are reused, so the
/// render loop allocates only while the store first fills.
#[derive(Default)]
struct StateStore {
    kept: Vec<KeptState>,
    spare: Vec<KeptState>,
    keep_every: u32,
    offered: u64,
}

impl StateStore {
    /// Whether the next offered state is kept (and counts it).
    fn wants_next(&mut self) -> bool {
        if self.keep_every == 0 {
            self.keep_every = 1;
        }
        let n = self.offered;
        self.offered += 1;
        if !n.is_multiple_of(u64::from(self.keep_every)) {
            return false;
        }
        if self.kept.len() == MAX_FRAMES {
            // Keep the 1st, 3rd, ...; the 2nd, 4th, ... become spares (from the back, so that
            // the indices still to visit do not move; 60 states: nothing to speed up).
            for i in (0..self.kept.len()).rev().filter(|i| i % 2 == 1) {
                let s = self.kept.remove(i);
                self.spare.push(s);
            }
            self.keep_every *= 2;
            return n.is_multiple_of(u64::from(self.keep_every));
        }
        true
    }

    /// A state to fill: a spare one, or a new one.
    fn slot(&mut self) -> KeptState {
        self.spare.pop().unwrap_or_else(KeptState::placeholder)
    }
}

impl KeptState {
    fn placeholder() -> KeptState {
        KeptState {
            header: WorldHeader::default(),
            blocks: Vec::new(),
            hand: HandSample::default(),
            left: None,
            facts: FrameFacts::default(),
        }
    }

    fn view(&self) -> WorldView<'_> {
        WorldView {
            header: &self.header,
            blocks: &self.blocks,
        }
    }
}

/// The finger points a frame draws: the world's (the fingers as the stepper placed them, out
/// of the blocks) when it carries them, else the hand's.
fn drawn_finger_points<'a>(
    world: &'a common::WorldHeader,
    hand: &'a HandSample,
) -> impl Iterator<Item = DVec3> + 'a {
    let (count, counts, points) = crate::draw_list::drawn_fingers(world, hand);
    points
        .iter()
        .zip(counts)
        .take(count as usize)
        .flat_map(|(finger, n)| finger.iter().take(*n as usize))
        .map(|p| DVec3::from_array(*p))
}

/// A hand's own check points, as tracked (a two-hand session's left hand: the world's drawn
/// points are the right hand's).
fn tracked_points(hand: &HandSample) -> impl Iterator<Item = DVec3> + '_ {
    (0..(hand.finger_count as usize).min(common::MAX_FINGERS))
        .flat_map(|f| hand.finger(f).iter())
        .map(|p| DVec3::from_array(*p))
}

/// The spheres that matter in a kept world: each block's bounding sphere and a point on the
/// floor under it, the finger points and the palm (of both hands in a two-hand session).
fn spheres_of(state: &KeptState, radii: &[f64], out: &mut Vec<(DVec3, f64)>) {
    let world = state.view();
    for (i, b) in world.blocks().iter().enumerate() {
        let c = DVec3::from_array(b.pose.position);
        out.push((c, radii.get(i).copied().unwrap_or(0.05)));
        out.push((DVec3::new(c.x, 0.0, c.z), 0.0));
    }
    let hand = &state.hand;
    for p in drawn_finger_points(&world, hand) {
        out.push((p, 0.01));
    }
    for p in hand.palm() {
        out.push((DVec3::from_array(*p), 0.0));
    }
    if let Some(left) = &state.left {
        out.extend(tracked_points(left).map(|p| (p, 0.01)));
        out.extend(left.palm().iter().map(|p| (DVec3::from_array(*p), 0.0)));
    }
}

/// The preview being made: the render loop keeps a world every 1 / PREVIEW_HZ seconds; when
/// the session ends, a camera is fitted to all that they hold, each is drawn with it, and the
/// preview's thread crops, writes text and encodes.
pub struct PreviewWriter {
    to_writer: Option<SyncSender<PreviewFrame>>,
    free: Receiver<PreviewFrame>,
    thread: Option<JoinHandle<Result<(), RenderError>>>,
    period_ns: u64,
    next_ns: u64,
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
                    store.offer(&f.image, &f.facts);
                    store.periods = f.periods;
                    let _ = to_free.try_send(f);
                }
                store.write(&target, &gif_path(&target), &look)
            })
            .map_err(|e| RenderError::Io(format!("starting the preview writer: {e}")))?;
        Ok(PreviewWriter {
            to_writer: Some(to_writer),
            free,
            thread: Some(thread),
            period_ns: (1e9 / PREVIEW_HZ) as u64,
            next_ns: 0,
            path,
            radii,
            step_hz,
            events: EventTracker::new(blocks),
            states: StateStore::default(),
        })
    }

    /// Called after each frame drawn at `now_ns` (of `world` and `hand`, and a two-hand
    /// session's `left` hand): follows the events, and keeps the world when a preview frame is
    /// due (a copy into a recycled state: nothing is read back from the GPU during the
    /// session).
    pub fn after_frame(
        &mut self,
        now_ns: u64,
        world: WorldView<'_>,
        hand: &HandSample,
        left: Option<&HandSample>,
    ) {
        let time_s = world.step as f64 / self.step_hz;
        self.events.observe(world, time_s);
        if now_ns < self.next_ns {
            return;
        }
        self.next_ns = now_ns + self.period_ns;
        if !self.states.wants_next() {
            return;
        }
        let mut s = self.states.slot();
        s.header = *world.header;
        s.blocks.clear();
        s.blocks.extend_from_slice(world.blocks());
        s.hand = *hand;
        s.left = left.copied();
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
        s.facts.action = None;
        self.states.kept.push(s);
    }

    /// Draws the kept worlds with a camera that frames all of them (the session camera's
    /// direction, mono), hands them to the thread, which writes the preview files, and stops
    /// it. Without a renderer, or when drawing fails, no preview is written.
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
        let mut spheres = Vec::new();
        for s in &self.states.kept {
            spheres_of(s, &self.radii, &mut spheres);
        }
        let (w, h) = (r.settings().width, r.settings().height);
        let session = r.settings().camera;
        // Fitted at the preview's widest aspect (16:9) within the eye's image: the crop cuts
        // the band it fills.
        let band = (f64::from(w) / MAX_ASPECT).min(f64::from(h)) as u32;
        let camera = frame_spheres(&spheres, &session, w, band).unwrap_or(CameraSettings {
            ipd_m: 0.0,
            ..session
        });
        let periods = self.states.keep_every.max(1);
        for s in &self.states.kept {
            let Ok(mut f) = self.free.recv() else {
                break; // the thread is gone: its error is reported by finish
            };
            let left = s.left.as_ref();
            let eye = r.render_preview(s.view(), &s.hand, left, &camera)?;
            r.read_back_left_eye_into(&mut f.image)?;
            f.facts.clone_from(&s.facts);
            f.facts.action = action_rect(&eye, w, h, s.view(), &s.hand, left, &self.radii);
            f.periods = periods;
            if let Some(tx) = &self.to_writer {
                if tx.send(f).is_err() {
                    break;
                }
            }
        }
        Ok(())
    }
}

/// A kept frame: RGB at the store's size, and its facts.
struct Kept {
    rgb: Vec<u8>,
    facts: FrameFacts,
}

/// The kept frames, all one size, and where the action was in all offered frames.
#[derive(Default)]
struct FrameStore {
    frames: Vec<Kept>,
    /// The stored frames' size, and the whole factor they were shrunk by.
    width: u32,
    height: u32,
    shrink: u32,
    /// Keep every `keep_every`-th offered frame (doubles each time the store fills).
    keep_every: u32,
    offered: u64,
    /// The union of every offered frame's action, in stored pixels.
    action: Option<Rect>,
    /// Preview periods each offered frame stands for (the render loop's time-lapse).
    periods: u32,
}

impl FrameStore {
    fn offer(&mut self, frame: &Image, facts: &FrameFacts) {
        if self.keep_every == 0 {
            self.keep_every = 1;
        }
        if self.frames.is_empty() && self.offered == 0 {
            self.shrink = frame
                .width
                .div_ceil(STORE_MAX_WIDTH)
                .max(frame.height.div_ceil(STORE_MAX_HEIGHT))
                .max(1);
            self.width = frame.width / self.shrink;
            self.height = frame.height / self.shrink;
        }
        if (frame.width / self.shrink, frame.height / self.shrink) != (self.width, self.height) {
            return;
        }
        let n = self.offered;
        self.offered += 1;
        // Every offered frame's action counts, kept or not: the crop holds the whole session.
        if let Some(a) = facts.action {
            let a = a.scaled(1.0 / f64::from(self.shrink));
            self.action = Some(self.action.map_or(a, |r| r.union(a)));
        }
        if !n.is_multiple_of(u64::from(self.keep_every)) {
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
        self.frames.push(Kept {
            rgb: shrink_rgba(frame, self.shrink),
            facts: facts.clone(),
        });
    }

    /// The rectangle of the stored frames the preview shows: the action with its margin (and
    /// room above it for the overlay), widened or heightened to an aspect between 4:3 and
    /// 16:9, magnified at most MAX_ZOOM times, within the frame (a margin that does not fit is
    /// cut rather than padded).
    fn crop(&self) -> Rect {
        let (iw, ih) = (f64::from(self.width), f64::from(self.height));
        let whole = Rect {
            x0: 0.0,
            y0: 0.0,
            x1: iw,
            y1: ih,
        };
        let a = self
            .action
            .map(|a| Rect {
                x0: a.x0.max(0.0),
                y0: a.y0.max(0.0),
                x1: a.x1.min(iw),
                y1: a.y1.min(ih),
            })
            .filter(|a| a.width() > 0.0 && a.height() > 0.0)
            .unwrap_or(whole);
        let mut w = a.width() * (1.0 + 2.0 * MARGIN);
        let mut h = a.height() * (1.0 + 2.0 * MARGIN + OVERLAY_ROOM);
        let aspect = (w / h).clamp(MIN_ASPECT, MAX_ASPECT);
        w = w.max(h * aspect);
        h = w / aspect;
        // No more magnification than MAX_ZOOM at the preview's size.
        let (ow, _) = out_size_for(aspect);
        let least = (f64::from(ow) / MAX_ZOOM).min(iw).min(ih * aspect);
        if w < least {
            w = least;
            h = w / aspect;
        }
        let fit = (iw / w).min(ih / h).min(1.0);
        w *= fit;
        h *= fit;
        let cx = (a.x0 + a.x1) * 0.5;
        // Centred below the overlay's room.
        let cy = (a.y0 + a.y1) * 0.5 - a.height() * OVERLAY_ROOM * 0.5;
        let x0 = (cx - w * 0.5).clamp(0.0, (iw - w).max(0.0));
        let y0 = (cy - h * 0.5).clamp(0.0, (ih - h).max(0.0));
        Rect {
            x0,
            y0,
            x1: x0 + w,
            y1: y0 + h,
        }
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
    fn write(&self, apng: &Path, gif_file: &Path, look: &PreviewScene) -> Result<(), RenderError> {
        if self.frames.is_empty() {
            return Err(RenderError::Io(format!(
                "writing {}: no frame was drawn",
                apng.display()
            )));
        }
        let (w, h, frames, poster) = self.compose(look);
        // Each kept frame stands for keep_every offered ones, each for `periods` periods.
        let periods = self.keep_every.max(1) * self.periods.max(1);
        let delay_ms = ((1000.0 / PREVIEW_HZ) as u32 * periods).min(60_000);
        write_apng(apng, w, h, &frames, poster, delay_ms)?;
        write_gif(gif_file, w, h, &frames, delay_ms, look)
    }
}

/// The largest size of this aspect within OUT_WIDTH x OUT_HEIGHT.
fn out_size_for(aspect: f64) -> (u32, u32) {
    let w = f64::from(OUT_WIDTH).min(f64::from(OUT_HEIGHT) * aspect);
    (w.round() as u32, (w / aspect).round() as u32)
}

/// `frame` (RGBA) shrunk by the whole factor `k` (box filter), as RGB.
fn shrink_rgba(frame: &Image, k: u32) -> Vec<u8> {
    let (ow, oh) = (frame.width / k, frame.height / k);
    let mut out = Vec::with_capacity((ow * oh * 3) as usize);
    let n = k * k;
    for y in 0..oh {
        for x in 0..ow {
            let mut sum = [0u32; 3];
            for dy in 0..k {
                let row = ((y * k + dy) * frame.width) as usize;
                for dx in 0..k {
                    let i = (row + (x * k + dx) as usize) * 4;
                    for (c, s) in sum.iter_mut().enumerate() {
                        *s += u32::from(frame.rgba[i + c]);
                    }
                }
            }
            out.extend(sum.map(|s| (s / n) as u8));
        }
    }
    out
}

/// One bilinear tap along an axis: the two source pixels and the second one's weight; None
/// outside the image.
type Tap = Option<(u32, u32, f32)>;

/// The taps of `n` output pixels along an axis of `size` source pixels, `taps` per output
/// pixel, for the source span `from .. from + n * step`.
fn axis_taps(from: f64, step: f64, n: u32, taps: u32, size: u32, out: &mut Vec<Tap>) {
    out.clear();
    for o in 0..n {
        for t in 0..taps {
            let x = from + (f64::from(o) + (f64::from(t) + 0.5) / f64::from(taps)) * step;
            if x < 0.0 || x > f64::from(size) {
                out.push(None);
                continue;
            }
            // Pixel centres at half integers.
            let f = (x - 0.5).clamp(0.0, f64::from(size - 1));
            let a = f.floor() as u32;
            let b = (a + 1).min(size - 1);
            out.push(Some((a, b, (f - f64::from(a)) as f32)));
        }
    }
}

/// `crop` of the RGB image `src` (`sw` x `sh`) scaled into `out` (`ow` x `oh`): bilinear,
/// with as many taps per pixel as it shrinks; outside the image, the gap colour. The taps are
/// worked out once per column and row, not per pixel.
fn resample(src: &[u8], sw: u32, sh: u32, crop: &Rect, out: &mut [u8], ow: u32, oh: u32) {
    if sw == 0 || sh == 0 {
        return;
    }
    let sx = crop.width() / f64::from(ow);
    let sy = crop.height() / f64::from(oh);
    let (tx, ty) = (sx.ceil().max(1.0) as u32, sy.ceil().max(1.0) as u32);
    let (mut xs, mut ys) = (Vec::new(), Vec::new());
    axis_taps(crop.x0, sx, ow, tx, sw, &mut xs);
    axis_taps(crop.y0, sy, oh, ty, sh, &mut ys);
    let norm = 1.0 / (tx * ty) as f32;
    let gap = GAP_RGB.map(f32::from);
    let px = |x: u32, y: u32| {
        let i = ((y * sw + x) * 3) as usize;
        [
            f32::from(src[i]),
            f32::from(src[i + 1]),
            f32::from(src[i + 2]),
        ]
    };
    for y in 0..oh as usize {
        for x in 0..ow as usize {
            let mut sum = [0.0f32; 3];
            for yt in &ys[y * ty as usize..(y + 1) * ty as usize] {
                for xt in &xs[x * tx as usize..(x + 1) * tx as usize] {
                    let v = match (yt, xt) {
                        (Some((y0, y1, ay)), Some((x0, x1, ax))) => {
                            let (p00, p10) = (px(*x0, *y0), px(*x1, *y0));
                            let (p01, p11) = (px(*x0, *y1), px(*x1, *y1));
                            std::array::from_fn(|c| {
                                let top = p00[c] + (p10[c] - p00[c]) * ax;
                                let bottom = p01[c] + (p11[c] - p01[c]) * ax;
                                top + (bottom - top) * ay
                            })
                        }
                        _ => gap,
                    };
                    for c in 0..3 {
                        sum[c] += v[c];
                    }
                }
            }
            let o = (y * ow as usize + x) * 3;
            for c in 0..3 {
                out[o + c] = (sum[c] * norm).round().clamp(0.0, 255.0) as u8;
            }
        }
    }
}

fn write_apng(
    path: &Path,
    w: u32,
    h: u32,
    frames: &[Vec<u8>],
    poster: usize,
    delay_ms: u32,
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
        enc.set_frame_delay(delay_ms.min(u32::from(u16::MAX)) as u16, 1000)?;
        let mut wr = enc.write_header()?;
        wr.write_image_data(&frames[poster.min(frames.len() - 1)])?;
        for f in frames {
            wr.write_image_data(f)?;
        }
        wr.finish()
    };
    common::output::replace(path, |file| encode(file).map_err(std::io::Error::other))
        .map_err(|e| RenderError::Io(format!("writing {}: {e}", path.display())))
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
/// palette entry, so that encoding costs a table look-up per pixel.
fn write_gif(
    path: &Path,
    w: u32,
    h: u32,
    frames: &[Vec<u8>],
    delay_ms: u32,
    look: &PreviewScene,
) -> Result<(), RenderError> {
    let fixed = fixed_colors(look);
    let learned = 256 - fixed.len();
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
    let table: Vec<u8> = (0..1u32 << 15)
        .map(|k| {
            let q = [(k >> 10) & 31, (k >> 5) & 31, k & 31].map(|v| (v << 3 | 4) as i32);
            palette
                .iter()
                .enumerate()
                .min_by_key(|(_, p)| (0..3).map(|c| (i32::from(p[c]) - q[c]).pow(2)).sum::<i32>())
                .map_or(0, |(i, _)| i as u8)
        })
        .collect();
    let exact: Vec<([u8; 3], u8)> = palette
        .iter()
        .enumerate()
        .skip(learned)
        .map(|(i, p)| (*p, i as u8))
        .collect();
    let flat: Vec<u8> = palette.iter().flatten().copied().collect();
    let delay_cs = (delay_ms / 10).min(u32::from(u16::MAX)) as u16;
    let encode = |file: &mut std::fs::File| -> Result<(), gif::EncodingError> {
        let mut enc = gif::Encoder::new(std::io::BufWriter::new(file), w as u16, h as u16, &flat)?;
        enc.set_repeat(gif::Repeat::Infinite)?;
        for f in frames {
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
            let mut frame = gif::Frame::from_indexed_pixels(w as u16, h as u16, idx, None);
            frame.delay = delay_cs;
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

    fn frame(w: u32, h: u32, rgba: [u8; 4]) -> Image {
        Image {
            width: w,
            height: h,
            rgba: rgba.repeat((w * h) as usize),
        }
    }

    fn look(n: usize) -> PreviewScene {
        PreviewScene {
            names: (0..n).map(|i| format!("b{i}")).collect(),
            colors: vec![[200, 30, 20]; n],
            radii: vec![0.05; n],
            step_hz: 120.0,
        }
    }

    fn facts(t: f64, action: Option<Rect>) -> FrameFacts {
        FrameFacts {
            time_s: t,
            modes: vec![BlockMode::Resting],
            event: None,
            action,
        }
    }

    fn scratch(name: &str) -> PathBuf {
        std::env::temp_dir().join(format!("hb-preview-{name}-{}.png", std::process::id()))
    }

    #[test]
    fn a_long_session_becomes_a_time_lapse_within_the_frame_limit_in_both_files() {
        let mut store = FrameStore::default();
        let f = frame(320, 240, [90, 120, 150, 255]);
        for i in 0..500 {
            store.offer(&f, &facts(i as f64 * 0.2, None));
        }
        assert!(store.frames.len() <= MAX_FRAMES, "{}", store.frames.len());
        assert!(store.frames.len() > MAX_FRAMES / 4);
        assert!(store.keep_every >= 8);
        let path = scratch("lapse");
        let gif_file = gif_path(&path);
        store.write(&path, &gif_file, &look(1)).unwrap();
        let info = describe(&path).unwrap();
        assert_eq!(info.frames as usize, store.frames.len());
        assert!(
            info.width <= MAX_WIDTH && info.height <= MAX_HEIGHT,
            "{info:?}"
        );
        // The GIF decodes, with the same frames at the same size.
        let g = describe_gif(&gif_file).unwrap();
        assert_eq!(g, info);
        std::fs::remove_file(path).unwrap();
        std::fs::remove_file(gif_file).unwrap();
    }

    /// The crop holds every offered frame's action (with its margin), kept or not, and is at
    /// the preview's aspect.
    #[test]
    fn the_crop_holds_all_the_action_of_the_session() {
        let mut store = FrameStore::default();
        let f = frame(640, 480, [0, 0, 0, 255]);
        let spots = [
            Rect::point(300.0, 300.0).union(Rect::point(340.0, 340.0)),
            Rect::point(350.0, 120.0).union(Rect::point(380.0, 150.0)), // lifted
            Rect::point(500.0, 330.0).union(Rect::point(520.0, 350.0)), // landed
        ];
        for (i, s) in spots.iter().enumerate() {
            store.offer(&f, &facts(i as f64, Some(*s)));
        }
        let c = store.crop();
        for s in spots {
            assert!(
                c.x0 <= s.x0 && c.y0 <= s.y0 && c.x1 >= s.x1 && c.y1 >= s.y1,
                "{s:?} outside {c:?}"
            );
        }
        let aspect = c.width() / c.height();
        assert!(
            (MIN_ASPECT - 1e-9..=MAX_ASPECT + 1e-9).contains(&aspect),
            "{aspect}"
        );
        // Tighter than the whole frame: the action fills it.
        assert!(c.width() < 640.0 * 0.8, "{c:?}");
        assert!(
            c.x0 >= 0.0 && c.y0 >= 0.0 && c.x1 <= 640.0 && c.y1 <= 480.0,
            "{c:?}"
        );
    }

    #[test]
    fn the_overlay_marks_every_frame_and_the_poster_is_a_held_frame() {
        let mut store = FrameStore::default();
        let f = frame(640, 480, [128, 128, 128, 255]);
        for i in 0..10 {
            let mut x = facts(i as f64 * 0.2, None);
            if (4..7).contains(&i) {
                x.modes[0] = BlockMode::Grasped;
                x.event = Some(Event {
                    kind: EventKind::Grasp,
                    block: 0,
                    time_s: 0.8,
                });
            }
            store.offer(&f, &x);
        }
        assert_eq!(store.poster(), 5);
        let (w, h, frames, _) = store.compose(&look(1));
        // Nothing moved: the whole eye, at its 4:3.
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

    #[test]
    fn the_render_loop_keeps_at_most_max_frames_worlds_reusing_dropped_ones() {
        let mut store = StateStore::default();
        let mut fresh = 0;
        for i in 0..1000 {
            if store.wants_next() {
                if store.spare.is_empty() {
                    fresh += 1;
                }
                let mut s = store.slot();
                s.facts.time_s = i as f64;
                store.kept.push(s);
            }
            assert!(store.kept.len() <= MAX_FRAMES);
        }
        assert!(store.kept.len() > MAX_FRAMES / 2, "{}", store.kept.len());
        assert!(fresh <= MAX_FRAMES + 1, "{fresh} states made");
        // In time order, evenly spaced from the start.
        let t: Vec<f64> = store.kept.iter().map(|s| s.facts.time_s).collect();
        assert_eq!(t[0], 0.0);
        let step = t[1] - t[0];
        assert!(t.windows(2).all(|w| w[1] - w[0] == step), "{t:?}");
        assert_eq!(step, f64::from(store.keep_every));
    }

    /// A two-hand session's left hand is part of what the preview frames and crops; without
    /// one, both are as for one hand.
    #[test]
    fn the_left_hand_is_framed_and_cropped_too() {
        let mut w = common::WorldSample::with_blocks(1);
        w.blocks[0].pose.rotation = [0.0, 0.0, 0.0, 1.0];
        let mut right = HandSample {
            finger_count: 1,
            ..Default::default()
        };
        right.finger_point_count[0] = 2;
        right.finger_points[0][..2].copy_from_slice(&[[0.0, 0.2, 0.0], [0.0, 0.2, 0.04]]);
        let mut left = HandSample {
            finger_count: 1,
            palm_vertex_count: 1,
            side: common::HandSide::Left.code(),
            ..Default::default()
        };
        left.finger_point_count[0] = 1;
        left.finger_points[0][0] = [-0.3, 0.25, 0.0];
        left.palm_vertices[0] = [-0.32, 0.25, 0.0];
        let radii = [0.05];
        let mut state = KeptState::placeholder();
        state.header = w.header;
        state.blocks = w.blocks.clone();
        state.hand = right;
        let mut one = Vec::new();
        spheres_of(&state, &radii, &mut one);
        state.left = Some(left);
        let mut two = Vec::new();
        spheres_of(&state, &radii, &mut two);
        assert_eq!(two[..one.len()], one[..]);
        assert_eq!(
            two[one.len()..],
            [
                (DVec3::new(-0.3, 0.25, 0.0), 0.01),
                (DVec3::new(-0.32, 0.25, 0.0), 0.0)
            ]
        );
        let [eye, _] = crate::camera::stereo(&CameraSettings::default(), 640, 480);
        let without = action_rect(&eye, 640, 480, w.view(), &right, None, &radii).unwrap();
        let with = action_rect(&eye, 640, 480, w.view(), &right, Some(&left), &radii).unwrap();
        let (x, y) = eye
            .project_px(DVec3::new(-0.32, 0.25, 0.0), 640, 480)
            .unwrap();
        assert!(without.x0 > x, "{without:?} already holds {x}");
        assert!(with.x0 <= x && with.y0 <= y, "{with:?} {x} {y}");
    }

    #[test]
    fn events_are_grasps_releases_and_mode_changes() {
        let mut w = common::WorldSample::with_blocks(2);
        let mut t = EventTracker::new(2);
        t.observe(w.view(), 0.0);
        assert_eq!(t.latest, None);
        w.header.grasped_block = 1;
        t.observe(w.view(), 1.0);
        assert_eq!(
            t.latest.map(|e| (e.kind, e.block)),
            Some((EventKind::Grasp, 1))
        );
        w.header.grasped_block = -1;
        w.blocks[1].mode = BlockMode::Free as u32;
        t.observe(w.view(), 2.0);
        assert_eq!(
            t.latest.map(|e| (e.kind, e.block)),
            Some((EventKind::Release, 1))
        );
        w.blocks[1].mode = BlockMode::Resting as u32;
        t.observe(w.view(), 2.5);
        let e = t.latest.unwrap();
        assert_eq!(e.kind, EventKind::Became(BlockMode::Resting));
        let names = vec!["red".to_string(), "blue".to_string()];
        assert_eq!(e.text(&names), "blue resting 2.50 s");
    }
}
