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

use std::path::{Path, PathBuf};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender};
use std::thread::JoinHandle;

use common::config::Scene;
use common::{BlockMode, BlockState, HandSample, WorldHeader, WorldView};
use glam::DVec3;

use crate::camera::{
    block_radius, centre_along, distance_along, frame_spheres, CameraSettings, Viewer,
};
use crate::draw_list::{block_colors, mode_color_srgb};
use crate::error::RenderError;
use crate::image::{Image, GAP_RGB};
use crate::overlay::{self, Canvas, WHITE};
use crate::renderer::Renderer;

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
/// Kept frames are stored shrunk (a whole factor) to at most this size: 60 frames of it are
/// 124 MB at most, 55 MB for the default 640 x 480 eye.
const STORE_MAX_WIDTH: u32 = 960;
const STORE_MAX_HEIGHT: u32 = 720;
/// The preview magnifies the rendered pixels at most this much (more would only blur).
pub const MAX_ZOOM: f64 = 2.0;
/// The preview's aspect.
const ASPECT: f64 = 16.0 / 9.0;
/// The top of each frame kept free of the action (a fraction of its height), for the
/// overlay's box.
const OVERLAY_ROOM: f64 = 0.1;
/// Seconds shown before the first moment of action, and at most before it while the hand
/// closes in (within `NEAR_M` of a block it will move).
pub const LEAD_S: f64 = 0.5;
pub const MAX_LEAD_S: f64 = 1.5;
/// Seconds shown after the last moment of action (the block at rest).
pub const TAIL_S: f64 = 0.5;
/// The shortest stretch shown, seconds (a lone event gets this much around it).
const MIN_WINDOW_S: f64 = 1.0;
/// A block that moved at least this far between two kept worlds moved (metres).
const MOTION_M: f64 = 0.002;
/// The hand closes in on a block within this distance of its bounding sphere (metres).
const NEAR_M: f64 = 0.2;
/// The hand touches a block within this distance of its bounding sphere (metres).
const TOUCH_M: f64 = 0.02;
/// Worlds within this time of a moment of action are all shown; the rest, calm, one in
/// `1 / CALM_WEIGHT`.
const BUSY_S: f64 = 0.3;
const CALM_WEIGHT: f64 = 1.0 / 3.0;
/// A frame is shown at most this long (a calm stretch's sparse frames play faster).
const MAX_DELAY_S: f64 = 0.15;
/// The narrowest view at the aim, metres: the hand alone does not fill the picture.
pub const MIN_VIEW_M: f64 = 0.55;
/// The camera's aim is averaged over this time (the Gaussian's sigma, seconds); its distance
/// is at least any frame's within [`HOLD_S`] needs, then averaged over as long.
const SMOOTH_S: f64 = 0.2;
pub const HOLD_S: f64 = 0.3;
/// A hand shows when one of its points is this far above the floor (metres); a lead or a
/// tail where it does not is cut to this long (seconds).
const SHOWS_ABOVE_M: f64 = 0.01;
const HIDDEN_S: f64 = 0.2;
/// The radius the framing gives a finger point or a palm vertex (metres).
const POINT_RADIUS_M: f64 = 0.01;

/// What [`describe`] and [`describe_gif`] find in a preview file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PreviewInfo {
    pub frames: u32,
    pub width: u32,
    pub height: u32,
    /// The loop's length, milliseconds (the frames' delays added).
    pub duration_ms: u32,
}

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

/// The frame count, size and length of a GIF file (every frame decoded).
pub fn describe_gif(path: &Path) -> Option<PreviewInfo> {
    let file = std::fs::File::open(path).ok()?;
    let mut opts = gif::DecodeOptions::new();
    opts.set_color_output(gif::ColorOutput::Indexed);
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
    pub fn point(x: f64, y: f64) -> Rect {
        Rect {
            x0: x,
            y0: y,
            x1: x,
            y1: y,
        }
    }

    pub fn union(self, o: Rect) -> Rect {
        Rect {
            x0: self.x0.min(o.x0),
            y0: self.y0.min(o.y0),
            x1: self.x1.max(o.x1),
            y1: self.y1.max(o.y1),
        }
    }

    /// Whether the point `x, y` lies inside (edges included).
    pub fn contains(&self, x: f64, y: f64) -> bool {
        (self.x0..=self.x1).contains(&x) && (self.y0..=self.y1).contains(&y)
    }

    pub fn width(&self) -> f64 {
        self.x1 - self.x0
    }

    pub fn height(&self) -> f64 {
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
    /// Events of the hand so far: grasps, releases, blocks becoming pushed or carried (what
    /// the preview's cut in time looks for, with the blocks' motion).
    pub hand_events: u64,
}

impl EventTracker {
    pub fn new(blocks: usize) -> EventTracker {
        EventTracker {
            modes: vec![BlockMode::Resting; blocks],
            grasped: -1,
            seen: false,
            latest: None,
            hand_events: 0,
        }
    }

    /// Compares `world` with the one observed before it.
    pub fn observe(&mut self, world: WorldView<'_>, time_s: f64) {
        for (i, b) in world.blocks().iter().enumerate().take(self.modes.len()) {
            let m = drawn_mode(world, i, b.mode());
            let was = std::mem::replace(&mut self.modes[i], m);
            let by_grasp = [m, was].contains(&BlockMode::Grasped);
            if self.seen && m != was && !by_grasp {
                if matches!(m, BlockMode::Pushed | BlockMode::Carried) {
                    self.hand_events += 1;
                }
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
            self.hand_events += 1;
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

/// A world as the preview keeps it until the session ends: the header, the blocks, the hand
/// it answers (and a two-hand session's newest left hand), the hand's events so far and the
/// facts of the moment.
struct KeptState {
    header: WorldHeader,
    blocks: Vec<BlockState>,
    hand: HandSample,
    left: Option<HandSample>,
    hand_events: u64,
    facts: FrameFacts,
}

/// The worlds kept for the preview, at most [`MAX_STATES`]: when full, every other one goes
/// and the rate halves (the whole session, more sparsely). Dropped states are reused, so the
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
        if self.kept.len() == MAX_STATES {
            // Keep the 1st, 3rd, ...; the 2nd, 4th, ... become spares (from the back, so that
            // the indices still to visit do not move).
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
            hand_events: 0,
            facts: FrameFacts::default(),
        }
    }

    fn view(&self) -> WorldView<'_> {
        WorldView {
            header: &self.header,
            blocks: &self.blocks,
        }
    }

    /// The points of the hands as drawn (finger points, palm; and a two-hand session's left
    /// hand, as tracked), finite ones only.
    fn hand_points(&self) -> impl Iterator<Item = DVec3> + '_ {
        let right = drawn_finger_points(&self.header, &self.hand)
            .chain(self.hand.palm().iter().map(|p| DVec3::from_array(*p)));
        let left = self
            .left
            .iter()
            .flat_map(|l| tracked_points(l).chain(l.palm().iter().map(|p| DVec3::from_array(*p))));
        right.chain(left).filter(|p| p.is_finite())
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

/// A block is in the hand in these modes (the world says so as it happens).
fn in_hand(m: BlockMode) -> bool {
    matches!(
        m,
        BlockMode::Grasped | BlockMode::Carried | BlockMode::Pushed
    )
}

/// Block `k`'s centre in `s`.
fn centre_of(s: &KeptState, k: usize) -> DVec3 {
    DVec3::from_array(s.blocks[k].pose.position)
}

/// Whether block `k` moved more than [`MOTION_M`] from `a` to `b`.
fn block_moved(a: &KeptState, b: &KeptState, k: usize) -> bool {
    centre_of(a, k).distance(centre_of(b, k)) > MOTION_M
}

/// The frames a preview of `states` shows, for an eye of `width` x `height` whose session
/// camera is `session`; None when no world was kept. See the module's comment.
fn plan_states(
    states: &[KeptState],
    radii: &[f64],
    session: &CameraSettings,
    (width, height): (u32, u32),
) -> Option<PreviewPlan> {
    let n = states.len();
    let session_s = (states.first()?.facts.time_s, states.last()?.facts.time_s);
    let t = |i: usize| states[i].facts.time_s;
    let blocks = states.iter().map(|s| s.blocks.len()).min().unwrap_or(0);
    let radius = |k: usize| radii.get(k).copied().unwrap_or(0.05);

    // 1. The moments of action, and the blocks that moved or were in the hand.
    let mut moved = vec![false; blocks];
    let mut action = vec![false; n];
    for i in 0..n {
        let s = &states[i];
        for (k, m) in moved.iter_mut().enumerate() {
            let held = s.facts.modes.get(k).is_some_and(|m| in_hand(*m));
            if held || (i > 0 && block_moved(&states[i - 1], s, k)) {
                *m = true;
                action[i] = true;
            }
        }
        action[i] |= i > 0 && s.hand_events != states[i - 1].hand_events;
    }
    let busy: Vec<usize> = (0..n).filter(|&i| action[i]).collect();
    let action_s = busy.first().zip(busy.last()).map(|(&a, &b)| (t(a), t(b)));

    // 2. The stretch shown: from LEAD_S before the first moment (earlier while the hand closes
    //    in on a block that moves, up to MAX_LEAD_S) to TAIL_S after the last.
    let near = |s: &KeptState, k: usize, p: DVec3, within: f64| {
        centre_of(s, k).distance(p) < radius(k) + within
    };
    // A hand below the floor (a trace's resting hand) does not show: a lead or a tail of
    // that is cut to HIDDEN_S (in a session with a hand that shows at all).
    let shows = |s: &KeptState| s.hand_points().any(|p| p.y > SHOWS_ABOVE_M);
    let has_hand = states.iter().any(shows);
    let (lo, hi) = match (busy.first(), busy.last()) {
        (Some(&a), Some(&b)) => {
            let closing_in = |s: &KeptState| {
                s.hand_points()
                    .any(|p| (0..blocks).any(|k| moved[k] && near(s, k, p, NEAR_M)))
            };
            let hidden = |i: usize, from: f64| {
                has_hand && (t(i) - from).abs() > HIDDEN_S && !shows(&states[i])
            };
            let mut lo = a;
            while lo > 0
                && !hidden(lo - 1, t(a))
                && (t(lo - 1) >= t(a) - LEAD_S
                    || (t(lo - 1) >= t(a) - MAX_LEAD_S && closing_in(&states[lo - 1])))
            {
                lo -= 1;
            }
            let mut hi = b;
            while hi + 1 < n && !hidden(hi + 1, t(b)) && t(hi + 1) <= t(b) + TAIL_S + 1e-9 {
                hi += 1;
            }
            // A lone moment gets MIN_WINDOW_S around it.
            let short = MIN_WINDOW_S - (t(hi) - t(lo));
            if short > 0.0 {
                let (start, end) = (t(lo) - 0.5 * short, t(hi) + 0.5 * short);
                lo = (0..n).find(|&i| t(i) >= start - 1e-9).unwrap_or(0);
                hi = (0..n).rev().find(|&i| t(i) <= end + 1e-9).unwrap_or(n - 1);
            }
            (lo, hi.max(lo))
        }
        _ => (0, n - 1),
    };

    // 3. The blocks framed: those that moved or were in the hand, and those the hand touches
    //    in the stretch shown; every block when there are none.
    let mut framed = moved;
    for s in &states[lo..=hi] {
        for p in s.hand_points() {
            for (k, f) in framed.iter_mut().enumerate() {
                *f = *f || near(s, k, p, TOUCH_M);
            }
        }
    }
    if !framed.contains(&true) {
        framed.iter_mut().for_each(|f| *f = true);
    }

    // 4. The frames: every kept world near a moment of action, one in 1 / CALM_WEIGHT of the
    //    rest, all of it thinned evenly when that is more than MAX_FRAMES.
    let weight = |i: usize| {
        if busy.is_empty() || busy.iter().any(|&j| (t(i) - t(j)).abs() <= BUSY_S) {
            1.0
        } else {
            CALM_WEIGHT
        }
    };
    let total: f64 = (lo..=hi).map(weight).sum();
    let step = (total / MAX_FRAMES as f64).max(1.0);
    let mut chosen: Vec<usize> = Vec::new();
    let (mut acc, mut next) = (0.0, 0.0);
    for i in lo..=hi {
        if acc + 1e-9 >= next {
            chosen.push(i);
            next += step;
        }
        acc += weight(i);
    }
    if chosen.last() != Some(&hi) {
        chosen.push(hi);
    }
    if chosen.len() > MAX_FRAMES {
        let m = chosen.len();
        chosen = (0..MAX_FRAMES)
            .map(|k| chosen[k * (m - 1) / (MAX_FRAMES - 1)])
            .collect();
    }
    let m = chosen.len();
    let times: Vec<f64> = chosen.iter().map(|&i| t(i)).collect();
    // Each frame shows until the next one's time (the last one as long as a kept world),
    // from 20 ms to MAX_DELAY_S, averaged over its neighbours: the worlds kept are those
    // the render loop drew, at uneven times, and the motion should play evenly.
    let gaps: Vec<f64> = (0..m)
        .map(|k| {
            let gap = times.get(k + 1).map_or(1.0 / KEEP_HZ, |n| n - times[k]);
            gap.clamp(0.02, MAX_DELAY_S)
        })
        .collect();
    let delays: Vec<u32> = (0..m)
        .map(|k| {
            let around = &gaps[k.saturating_sub(2)..(k + 3).min(m)];
            let mean = around.iter().sum::<f64>() / around.len() as f64;
            (mean * 100.0).round() as u32 * 10
        })
        .collect();

    // 5. The cameras: one direction for all, each frame's aim and distance its own.
    let band = (f64::from(width) / ASPECT).min(f64::from(height));
    let fit = (width, ((band * (1.0 - OVERLAY_ROOM)).round() as u32).max(1));
    let y0 = ((f64::from(height) - band) * 0.5 - band * OVERLAY_ROOM * 0.5).max(0.0);
    let crop = Rect {
        x0: 0.0,
        y0,
        x1: f64::from(width),
        y1: y0 + band,
    };
    let sets: Vec<Vec<(DVec3, f64)>> = chosen
        .iter()
        .map(|&i| {
            let s = &states[i];
            // A hand below the floor (a trace's resting hand) is framed where it would show.
            let mut v: Vec<(DVec3, f64)> = s
                .hand_points()
                .map(|p| (DVec3::new(p.x, p.y.max(0.0), p.z), POINT_RADIUS_M))
                .collect();
            v.extend(
                (0..blocks)
                    .filter(|&k| framed[k])
                    .map(|k| (centre_of(s, k), radius(k))),
            );
            v
        })
        .collect();
    let all: Vec<(DVec3, f64)> = sets.iter().flatten().copied().collect();
    let mono = CameraSettings {
        ipd_m: 0.0,
        ..*session
    };
    let cameras: Vec<CameraSettings> = match frame_spheres(&all, session, fit.0, fit.1) {
        None => vec![mono; m],
        Some(c) => {
            let forward = Viewer::new(&c).forward;
            let whole = DVec3::from_array(c.target);
            let aims: Vec<DVec3> = sets
                .iter()
                .map(|s| centre_along(s, forward).unwrap_or(whole))
                .collect();
            let gauss = |dt: f64, sigma: f64| (-0.5 * (dt / sigma).powi(2)).exp();
            let aims: Vec<DVec3> = (0..m)
                .map(|k| {
                    let (mut sum, mut weights) = (DVec3::ZERO, 0.0);
                    for j in 0..m {
                        let g = gauss(times[j] - times[k], SMOOTH_S);
                        sum += aims[j] * g;
                        weights += g;
                    }
                    sum / weights
                })
                .collect();
            let need: Vec<f64> = (0..m)
                .map(|k| distance_along(&sets[k], aims[k], forward, session, fit, MIN_VIEW_M))
                .collect();
            let times = &times;
            let within =
                move |k: usize| (0..m).filter(move |&j| (times[j] - times[k]).abs() <= HOLD_S);
            // At least what any frame within HOLD_S needs, so an average over as long is at
            // least what this frame needs.
            let held: Vec<f64> = (0..m)
                .map(|k| within(k).map(|j| need[j]).fold(0.0, f64::max))
                .collect();
            (0..m)
                .map(|k| {
                    let (mut sum, mut weights) = (0.0, 0.0);
                    for j in within(k) {
                        let g = gauss(times[j] - times[k], 0.5 * HOLD_S);
                        sum += held[j] * g;
                        weights += g;
                    }
                    let d = (sum / weights).max(need[k]);
                    CameraSettings {
                        eye: (aims[k] - forward * d).to_array(),
                        target: aims[k].to_array(),
                        ..mono
                    }
                })
                .collect()
        }
    };
    Some(PreviewPlan {
        frames: (0..m)
            .map(|k| PlannedFrame {
                time_s: times[k],
                camera: cameras[k],
                delay_ms: delays[k],
                state: chosen[k],
            })
            .collect(),
        crop,
        session_s,
        action_s,
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

/// A kept frame: RGB at the store's size, its facts and how long it shows.
struct Kept {
    rgb: Vec<u8>,
    facts: FrameFacts,
    delay_ms: u32,
}

/// The preview's frames as drawn, all one size (at most [`MAX_FRAMES`]), and the part of them
/// the preview keeps.
#[derive(Default)]
struct FrameStore {
    frames: Vec<Kept>,
    /// The stored frames' size, and the whole factor they were shrunk by.
    width: u32,
    height: u32,
    shrink: u32,
    /// The part kept, eye pixels (None: all of it).
    crop: Option<Rect>,
}

impl FrameStore {
    fn offer(&mut self, frame: &Image, facts: &FrameFacts, delay_ms: u32) {
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
    fn write(&self, apng: &Path, gif_file: &Path, look: &PreviewScene) -> Result<(), RenderError> {
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

/// The GIF's transparent palette index: a pixel of a frame after the first that shows what
/// the frame before showed.
const TRANSPARENT: u8 = 255;

/// The frame that turns `before` into `after` (palette indices, `w` x `h`, the frame before
/// kept): the smallest rectangle that holds every pixel that changed, the others in it
/// transparent where they are nearly all of it, so that a still background costs little.
fn changes(before: &[u8], after: &[u8], w: u32, h: u32) -> gif::Frame<'static> {
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
    let mut frame = gif::Frame::from_indexed_pixels(
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
fn write_gif(
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
    let encode = |file: &mut std::fs::File| -> Result<(), gif::EncodingError> {
        let mut enc = gif::Encoder::new(std::io::BufWriter::new(file), w as u16, h as u16, &flat)?;
        enc.set_repeat(gif::Repeat::Infinite)?;
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
                gif::Frame::from_indexed_pixels(w as u16, h as u16, idx.clone(), None)
            } else {
                changes(&shown, &idx, w, h)
            };
            shown = idx;
            frame.dispose = gif::DisposalMethod::Keep;
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

    fn facts(t: f64) -> FrameFacts {
        FrameFacts {
            time_s: t,
            modes: vec![BlockMode::Resting],
            event: None,
        }
    }

    fn scratch(name: &str) -> PathBuf {
        std::env::temp_dir().join(format!("hb-preview-{name}-{}.png", std::process::id()))
    }

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
        let mut opts = gif::DecodeOptions::new();
        opts.set_color_output(gif::ColorOutput::RGBA);
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

    #[test]
    fn the_render_loop_keeps_at_most_max_states_worlds_reusing_dropped_ones() {
        let mut store = StateStore::default();
        let mut fresh = 0;
        for i in 0..5000 {
            if store.wants_next() {
                if store.spare.is_empty() {
                    fresh += 1;
                }
                let mut s = store.slot();
                s.facts.time_s = i as f64;
                store.kept.push(s);
            }
            assert!(store.kept.len() <= MAX_STATES);
        }
        assert!(store.kept.len() > MAX_STATES / 2, "{}", store.kept.len());
        assert!(fresh <= MAX_STATES + 1, "{fresh} states made");
        // In time order, evenly spaced from the start.
        let t: Vec<f64> = store.kept.iter().map(|s| s.facts.time_s).collect();
        assert_eq!(t[0], 0.0);
        let step = t[1] - t[0];
        assert!(t.windows(2).all(|w| w[1] - w[0] == step), "{t:?}");
        assert_eq!(step, f64::from(store.keep_every));
    }

    /// A two-hand session's left hand is part of what the preview frames; without one, the
    /// points are the right hand's alone.
    #[test]
    fn the_left_hand_is_framed_too() {
        let w = common::WorldSample::with_blocks(1);
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
        let mut state = KeptState::placeholder();
        state.header = w.header;
        state.blocks = w.blocks.clone();
        state.hand = right;
        let one: Vec<DVec3> = state.hand_points().collect();
        assert_eq!(one, [DVec3::new(0.0, 0.2, 0.0), DVec3::new(0.0, 0.2, 0.04)]);
        state.left = Some(left);
        let two: Vec<DVec3> = state.hand_points().collect();
        assert_eq!(two[..2], one[..]);
        assert_eq!(
            two[2..],
            [DVec3::new(-0.3, 0.25, 0.0), DVec3::new(-0.32, 0.25, 0.0)]
        );
    }

    #[test]
    fn events_are_grasps_releases_and_mode_changes() {
        let mut w = common::WorldSample::with_blocks(2);
        let mut t = EventTracker::new(2);
        t.observe(w.view(), 0.0);
        assert_eq!(t.latest, None);
        // A block settling is an event, not the hand's.
        w.blocks[0].mode = BlockMode::Free as u32;
        t.observe(w.view(), 0.5);
        assert_eq!(t.hand_events, 0);
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
        w.blocks[0].mode = BlockMode::Pushed as u32;
        t.observe(w.view(), 3.0);
        // The grasp, the release and the push.
        assert_eq!(t.hand_events, 3);
    }
}
