//! The real-trace half of `handblocks bench hands`: real people's hands (the CARL recordings,
//! Quest hand tracking) closing on a cube that the block world places where they close, run
//! under each hand rule set (`[world] hands = "paper" | "tracked"`), counting what the world
//! made of each grip: grasps, drops, flickers and lifts.
//!
//! Per `*.carl` file of the folder (sorted by name; a file that cannot be read is skipped with
//! a progress line naming the error) and per hand, left then right, that the file tracks:
//!
//! 1. **Hands.** The hand's joints become hand samples exactly as `handblocks simulate --hand
//!    FILE` makes them: [`replay::CarlTrace::joints`] (source time from the first sample, the
//!    offset added to every pose), then [`kinematics::HandStream::joints`] with the built-in
//!    hand model (a sample the model cannot use holds the last hand, marked lost; a hand lost
//!    for longer than `common::TRACKING_HOLD_NS` lets go). (`simulate` goes through
//!    `replay::HandTrace`, which reads the right hand only and also re-times jumps of the
//!    source's clock of more than `common::stamp::MAX_SOURCE_GAP_NS`; a CARL file whose clock
//!    never jumps, as every shared recording, gives the same samples either way.)
//! 2. **Closures** ([`find_closures`], [`CLOSURE_RULE`]): where the hand closes its grip.
//! 3. **The cube** ([`place_cube`], [`CUBE_RULE`]), at the hand's first closure; the whole trace
//!    is moved vertically so that the cube rests on the floor.
//! 4. **The world**, once per rule set: the cube alone, the scene's defaults otherwise
//!    (120 Hz, `[effects]` all on), stepped along the hand's own timeline
//!    ([`stepper::timeline::Timeline`]) exactly as `stepper::simulate_samples` steps it (a
//!    sample the world refuses takes no steps), then 2 s more with the last hand held.
//! 5. **Counts** ([`TraceRow`]): from the world's events for the cube and its pose, step by
//!    step ([`COUNT_RULE`]).
//!
//! A hand with no tracked sample, or that never closes by the rule, gives no row (a progress
//! line says so); every other gives one row per rule set.

use std::path::{Path, PathBuf};

use common::config::scene::{BlockSpec, Effects, HandRules, ShapeSpec, WorldSettings};
use common::config::Scene;
use common::{BlockMode, HandSample, HandSide};
use glam::{DQuat, DVec3};
use replay::CarlTrace;
use stepper::timeline::Timeline;
use stepper::{EventKind, Model};

/// The closure rule, as the report states it.
pub const CLOSURE_RULE: &str = "The grip aperture of a hand sample is the distance from the \
    thumb tip to the nearer of the index and middle tips (that finger is the opposing one). A \
    closure is a tracked sample, not the first or last of its run of tracked samples, whose \
    aperture is the least of its run within 0.25 s either side (the first of equals), that lies \
    both at least 3 cm below and at most 0.6 times the largest aperture of the 1 s before it (the \
    open value, taken since the previous closure: the grip must open again between two \
    closures), and that leaves room for something between the tips: above the sum of the two \
    fingers' radii (the hand model's: 1.9 cm for thumb and index), below which the fingertips \
    touch and the hand holds nothing. 3 cm is several times a tracker's jitter; 0.6 tells a \
    grip, which closes most of the way, from a spread hand relaxing or twitching, which closes \
    by a fraction (a cube bigger than about half the open hand is not found).";

/// The cube rule, as the report states it.
pub const CUBE_RULE: &str = "At the hand's first closure the cube's centre is midway between \
    the thumb tip and the opposing tip; it rests on a face, turned about the vertical only (a \
    cube turned to the grip's exact axis would stand on an edge and topple before the hand \
    came). Its grip axis is the vertical when the thumb-to-finger line is within 45 degrees of \
    vertical, else that line's horizontal direction (the cube's x axis). Its edge is the tips' \
    separation along that axis plus 2 x 4 mm, so each tip ends 4 mm inside its face. The whole \
    trace, hand and cube, is then moved vertically so that the cube's bottom face lies on the \
    floor (y = 0); the hand may pass below the floor elsewhere in the trace (the floor does not \
    act on the hand). The hand is replayed as recorded, however fast it moves at the closure: \
    a hand that closes in passing sweeps on through the cube (the rows give the wrist's speed \
    there).";

/// The counting rule, as the report states it.
pub const COUNT_RULE: &str = "grasps: the world's Grasp events for the cube. drops: its Release \
    events at a step whose grip aperture (of the hand that step took; of the last hand with \
    fingers when it had none, a hand lost too long) is still below the closure's open \
    threshold, midway between the closure's aperture and its open value: the world let go of a \
    hand still closed. flickers: Releases followed by a Grasp of the cube within 200 ms. \
    lifted: the cube's centre rose at least 3 cm above where it lay, at a step where it was \
    grasped.";

/// A closure's aperture must lie this far below the open value before it (m): several times
/// a hand tracker's jitter (2-11 mm sd), so that no tremor of a still hand counts.
pub const CLOSE_DROP_M: f64 = 0.03;
/// A closure's aperture is at most this fraction of the open value before it.
pub const CLOSE_RATIO: f64 = 0.6;
/// The open value is the largest aperture of this long before the closure (s).
pub const OPEN_LOOKBACK_S: f64 = 1.0;
/// A closure is the least aperture of its run within this long either side (s).
pub const MINIMUM_WINDOW_S: f64 = 0.25;
/// Each tip ends this far inside its face of the cube (m).
pub const TIP_DEPTH_M: f64 = 0.004;
/// A grasped cube that rose this far (m) was lifted.
pub const LIFT_M: f64 = 0.03;
/// A Release followed by a Grasp within this long (s) is a flicker.
pub const FLICKER_S: f64 = 0.2;
/// Steps after the trace's last sample, with its hand held (s), as `simulate` takes.
pub const SETTLE_S: f64 = 2.0;

/// One (file, hand, rule set): what the world made of the hand's grip on the cube.
#[derive(Debug, Clone, serde::Serialize)]
pub struct TraceRow {
    /// The file's name (no folder).
    pub file: String,
    /// `"left"` or `"right"`.
    pub hand: String,
    /// `"paper"` or `"tracked"`.
    pub rules: String,
    /// The recording's other hand in the same world too (docs/model.md "Two hands"): the
    /// counts are still this hand's cube's, now with the other hand beside it.
    pub with_other_hand: bool,
    pub grasps: u32,
    /// Releases while the hand was still closed ([`COUNT_RULE`]).
    pub drops: u32,
    /// Releases followed by a Grasp within [`FLICKER_S`].
    pub flickers: u32,
    /// The grasped cube rose at least [`LIFT_M`].
    pub lifted: bool,
    /// Every Release event of the cube.
    pub releases: u32,
    /// How long the cube was grasped in all (s).
    pub grasped_s: f64,
    /// The most the cube's centre rose above where it lay while grasped (m; 0 if never).
    pub max_rise_m: f64,
    /// The most the wrist rose above its height at the closure, from the closure on (m): what
    /// the cube could have risen had it gone with the hand.
    pub wrist_rise_m: f64,
    /// The wrist's speed at the closure (m/s, from the samples either side): a hand that
    /// closes in passing (a swipe, a gesture in the air) is not one that stops to hold.
    pub wrist_speed_m_s: f64,
    /// Its vertical part (m/s): a hand closing on its way down drives the grasped cube, which
    /// lies on the floor, into it (R5 moves a grasped block with the wrist, R8 lifts it back
    /// out), and its fingers go on through the cube and the floor.
    pub wrist_vy_m_s: f64,
    /// Closures of this hand in the file ([`CLOSURE_RULE`]); the cube is at the first.
    pub closures: u32,
    /// The first closure's time from the trace's first sample (s).
    pub closure_s: f64,
    /// Its grip aperture (m) and the open value before it (m).
    pub aperture_m: f64,
    pub open_m: f64,
    /// The opposing finger: `"index"` or `"middle"`.
    pub finger: String,
    /// The cube's edge (m) and the axis it is gripped along: `"horizontal"` or `"vertical"`.
    pub cube_m: f64,
    pub grip_axis: String,
    /// How far the trace was moved up to put the cube on the floor (m; negative: down).
    pub shift_y_m: f64,
    /// The hand's samples in the file, and the share of them tracked.
    pub samples: u32,
    pub tracked_fraction: f64,
    /// Steps the world took (the trace, then [`SETTLE_S`]).
    pub steps: u64,
}

/// A grip: the aperture, the thumb tip and the opposing tip (world, m), which finger opposes
/// (1 index, 2 middle), and the two fingers' radii summed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Grip {
    pub aperture: f64,
    pub thumb: [f64; 3],
    pub finger_tip: [f64; 3],
    pub finger: usize,
    pub radii: f64,
}

/// The grip of a hand sample: None for a hand without thumb, index and middle (a hand lost
/// for too long has no fingers).
pub fn grip(hand: &HandSample) -> Option<Grip> {
    if hand.finger_count < 3 {
        return None;
    }
    let thumb = *hand.finger(0).last()?;
    let mut best: Option<Grip> = None;
    for f in [1, 2] {
        let tip = *hand.finger(f).last()?;
        let aperture = DVec3::from_array(thumb).distance(DVec3::from_array(tip));
        if !aperture.is_finite() {
            return None;
        }
        if best.is_none_or(|b| aperture < b.aperture) {
            best = Some(Grip {
                aperture,
                thumb,
                finger_tip: tip,
                finger: f,
                radii: hand.finger_radius[0] + hand.finger_radius[f],
            });
        }
    }
    best
}

/// One closure ([`CLOSURE_RULE`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Closure {
    /// The sample's index in the hand samples given.
    pub index: usize,
    /// Seconds from the first sample given.
    pub time_s: f64,
    pub grip: Grip,
    /// The largest aperture of the [`OPEN_LOOKBACK_S`] before (since the previous closure).
    pub open: f64,
    /// The wrist's position at the closure.
    pub wrist: [f64; 3],
}

impl Closure {
    /// Midway between the closure's aperture and its open value: a hand below it is still
    /// closed.
    pub fn open_threshold(&self) -> f64 {
        (self.grip.aperture + self.open) / 2.0
    }
}

/// The closures of a hand's samples, in order ([`CLOSURE_RULE`]). Samples count as tracked
/// when `tracked` is set and they have a grip; their times are their stamps' source times,
/// which must not go back (a CARL reader's and a hand stream's never do).
pub fn find_closures(hands: &[HandSample]) -> Vec<Closure> {
    let times: Vec<f64> = hands
        .iter()
        .map(|h| h.stamp.source_time_ns as f64 / 1e9)
        .collect();
    let t0 = times.first().copied().unwrap_or(0.0);
    let grips: Vec<Option<Grip>> = hands
        .iter()
        .map(|h| if h.tracked != 0 { grip(h) } else { None })
        .collect();
    let a = |i: usize| grips[i].map_or(f64::INFINITY, |g| g.aperture);
    let mut out = Vec::new();
    let mut k = 0;
    while k < hands.len() {
        if grips[k].is_none() {
            k += 1;
            continue;
        }
        // A run of tracked samples: [start, end). Each look around a sample stops at the
        // window's edge (times are in order), so a long recording costs its length.
        let start = k;
        let mut end = k;
        while end < hands.len() && grips[end].is_some() {
            end += 1;
        }
        let mut since = start;
        for i in start + 1..end.saturating_sub(1) {
            let Some(g) = grips[i] else { continue };
            let t = times[i];
            // The least of the window (the first of equals).
            let mut least = true;
            let mut j = i;
            while least && j > start {
                j -= 1;
                if t - times[j] > MINIMUM_WINDOW_S {
                    break;
                }
                least = a(j) > g.aperture;
            }
            let mut j = i + 1;
            while least && j < end && times[j] - t <= MINIMUM_WINDOW_S {
                least = a(j) >= g.aperture;
                j += 1;
            }
            if !least {
                continue;
            }
            // The open value: the widest of the lookback, since the previous closure.
            let mut open = f64::NEG_INFINITY;
            let mut j = i;
            while j > since {
                j -= 1;
                if t - times[j] > OPEN_LOOKBACK_S {
                    break;
                }
                open = open.max(a(j));
            }
            if open - g.aperture >= CLOSE_DROP_M
                && g.aperture <= CLOSE_RATIO * open
                && g.aperture > g.radii
            {
                out.push(Closure {
                    index: i,
                    time_s: t - t0,
                    grip: g,
                    open,
                    wrist: hands[i].wrist.position,
                });
                since = i + 1;
            }
        }
        k = end;
    }
    out
}

/// Where the cube goes ([`CUBE_RULE`]), before the trace is moved to the floor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CubePlacement {
    pub centre: [f64; 3],
    /// A turn about +y only.
    pub rotation: [f64; 4],
    pub edge: f64,
    /// True when the grip axis is the vertical.
    pub vertical: bool,
}

impl CubePlacement {
    /// What moves the trace so that the cube's bottom face lies on y = 0 (m).
    pub fn shift_y(&self) -> f64 {
        self.edge / 2.0 - self.centre[1]
    }
}

/// The cube of a closure ([`CUBE_RULE`]).
pub fn place_cube(closure: &Closure) -> CubePlacement {
    let thumb = DVec3::from_array(closure.grip.thumb);
    let tip = DVec3::from_array(closure.grip.finger_tip);
    let line = tip - thumb;
    let centre = (thumb + tip) / 2.0;
    let horizontal = DVec3::new(line.x, 0.0, line.z);
    let vertical = line.y.abs() >= horizontal.length();
    let (rotation, separation) = if vertical {
        (DQuat::IDENTITY, line.y.abs())
    } else {
        // The cube's x axis along the line's horizontal direction: x -> (cos a, 0, -sin a)
        // under a turn a about +y.
        let angle = (-horizontal.z).atan2(horizontal.x);
        (DQuat::from_rotation_y(angle), horizontal.length())
    };
    CubePlacement {
        centre: centre.to_array(),
        rotation: rotation.to_array(),
        edge: separation + 2.0 * TIP_DEPTH_M,
        vertical,
    }
}

/// A hand of a CARL trace as `handblocks simulate --hand` makes its hand samples (see the
/// module's doc), with every pose moved by `offset` (m).
pub fn hand_samples(trace: &CarlTrace, offset: [f64; 3]) -> Vec<HandSample> {
    let mut joints = Vec::new();
    trace.joints(offset, &mut joints);
    let mut stream = kinematics::HandStream::new(kinematics::HandModel::default());
    joints.iter().map(|j| *stream.joints(j)).collect()
}

/// The cube's scene under `rules`.
pub fn scene(name: &str, cube: &CubePlacement, rules: HandRules) -> Scene {
    Scene {
        file: PathBuf::from(format!("<bench hands: {name}, {}>", rules.name())),
        world: WorldSettings {
            hands: rules,
            ..WorldSettings::default()
        },
        effects: Effects::default(),
        blocks: vec![BlockSpec {
            name: "cube".into(),
            shape: ShapeSpec::Box {
                size: [cube.edge; 3],
            },
            position: [cube.centre[0], cube.edge / 2.0, cube.centre[2]],
            rotation: cube.rotation,
            velocity: [0.0; 3],
        }],
        hand: None,
        left_hand: None,
    }
}

/// What one run counted ([`COUNT_RULE`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Counts {
    pub grasps: u32,
    pub releases: u32,
    pub drops: u32,
    pub flickers: u32,
    /// Steps that ended with the cube grasped.
    pub grasped_steps: u64,
    pub max_rise_m: f64,
    pub steps: u64,
}

/// What [`run`] and [`run_with_other`] count after each step ([`COUNT_RULE`]): the cube's grasps,
/// releases, drops (released while this hand's aperture was under the threshold), flickers,
/// grasped steps and rise.
struct Tally {
    start_y: f64,
    flicker_steps: u64,
    last_release: Option<u64>,
    last_aperture: f64,
    threshold: f64,
}

impl Tally {
    fn new(scene: &Scene, threshold: f64) -> Tally {
        Tally {
            start_y: scene.blocks.first().map_or(0.0, |b| b.position[1]),
            flicker_steps: (FLICKER_S * scene.world.step_hz).round() as u64,
            last_release: None,
            last_aperture: f64::INFINITY,
            threshold,
        }
    }

    fn observe(&mut self, world: &Model, hand: Option<&HandSample>, counts: &mut Counts) {
        if let Some(g) = hand.and_then(grip) {
            self.last_aperture = g.aperture;
        }
        for e in world.events().iter().filter(|e| e.block == 0) {
            match e.kind {
                EventKind::Grasp => {
                    counts.grasps += 1;
                    if self
                        .last_release
                        .is_some_and(|r| e.step - r <= self.flicker_steps)
                    {
                        counts.flickers += 1;
                    }
                    self.last_release = None;
                }
                EventKind::Release => {
                    counts.releases += 1;
                    if self.last_aperture < self.threshold {
                        counts.drops += 1;
                    }
                    self.last_release = Some(e.step);
                }
                _ => {}
            }
        }
        if let Some(b) = world.block(0) {
            if b.mode == BlockMode::Grasped {
                counts.grasped_steps += 1;
                counts.max_rise_m = counts.max_rise_m.max(b.position.y - self.start_y);
            }
        }
    }
}

/// Runs `scene` (its block 0 is the cube) on `hands` along their timeline, then
/// [`SETTLE_S`] with the last usable hand held, counting by [`COUNT_RULE`] with `threshold` as
/// the closure's open threshold.
pub fn run(scene: &Scene, hands: &[HandSample], threshold: f64) -> Result<Counts, String> {
    let mut world = Model::new(scene).map_err(|e| e.to_string())?;
    let mut counts = Counts::default();
    let mut tally = Tally::new(scene, threshold);
    let mut observe = |world: &Model, hand: Option<&HandSample>, counts: &mut Counts| {
        tally.observe(world, hand, counts)
    };
    let mut timeline = Timeline::new(scene.world.step_hz);
    let mut last_usable: Option<&HandSample> = None;
    for hand in hands {
        if !stepper::hand::is_usable(hand) {
            // Refused where it enters, as `simulate_samples` refuses it: no steps of its own.
            continue;
        }
        if !timeline.started() {
            world.set_previous_hand(Some(hand));
        }
        timeline.advance(hand, |h| {
            world.step(h);
            observe(&world, h, &mut counts);
        });
        last_usable = Some(hand);
    }
    let end = world.steps() + (SETTLE_S * scene.world.step_hz) as u64;
    while world.steps() < end {
        world.step(last_usable);
        observe(&world, last_usable, &mut counts);
    }
    counts.steps = world.steps();
    Ok(counts)
}

/// [`run`] with the recording's other hand in the same world (`other`, sample for sample with
/// `hands`; `side` is the side of `hands`): the frames of a two-hand source, made into frames as
/// the stepper makes them (`stepper::timeline::HandFrames`), each hand in its slot. The
/// counts are of block 0, and the aperture (for drops) is this hand's.
pub fn run_with_other(
    scene: &Scene,
    hands: &[HandSample],
    other: &[HandSample],
    side: HandSide,
    threshold: f64,
) -> Result<Counts, String> {
    use stepper::timeline::{HandFrame, HandFrames};
    let mut world = Model::new(scene).map_err(|e| e.to_string())?;
    let slot = stepper::side_slot(side);
    let mut counts = Counts::default();
    let mut tally = Tally::new(scene, threshold);
    let mut observe = |world: &Model, hand: Option<&HandSample>, counts: &mut Counts| {
        tally.observe(world, hand, counts)
    };
    let mut timeline = Timeline::new(scene.world.step_hz);
    let mut frames = HandFrames::new();
    let mut take = |frame: &HandFrame| {
        if !timeline.started() {
            for (k, h) in frame.iter().enumerate() {
                world.set_previous_hand_of(k, h.as_ref());
            }
        }
        timeline.advance_hands([frame[0].as_ref(), frame[1].as_ref()], |h| {
            world.step_hands(h);
            observe(&world, h[slot], &mut counts);
        });
    };
    for (this, that) in hands.iter().zip(other) {
        // The right first, then the left, as a two-hand source sends them.
        let (mut right, mut left) = if slot == 0 {
            (*this, *that)
        } else {
            (*that, *this)
        };
        right.side = HandSide::Right.code();
        left.side = HandSide::Left.code();
        frames.push(&right, &mut take);
        frames.push(&left, &mut take);
    }
    frames.flush(&mut take);
    let last = *frames.last_good();
    let end = world.steps() + (SETTLE_S * scene.world.step_hz) as u64;
    while world.steps() < end {
        world.step_hands([last[0].as_ref(), last[1].as_ref()]);
        observe(&world, last[slot].as_ref(), &mut counts);
    }
    counts.steps = world.steps();
    Ok(counts)
}

/// Every `*.carl` file of `dir`, sorted by name.
fn carl_files(dir: &Path) -> Result<Vec<PathBuf>, String> {
    let entries =
        std::fs::read_dir(dir).map_err(|e| format!("{}: cannot list: {e}", dir.display()))?;
    let mut files = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| format!("{}: cannot list: {e}", dir.display()))?;
        let path = entry.path();
        if path.extension().is_some_and(|x| x == "carl") && path.is_file() {
            files.push(path);
        }
    }
    files.sort();
    Ok(files)
}

/// Every `*.carl` file of `dir` (sorted), each hand that is tracked and closes, each rule set:
/// one row each (see the module's doc). A file that cannot be read is skipped with a progress
/// line; only a folder that cannot be listed is an error.
pub fn measure(dir: &Path, progress: &mut dyn FnMut(&str)) -> Result<Vec<TraceRow>, String> {
    let mut rows = Vec::new();
    for file in carl_files(dir)? {
        let name = file.file_name().map_or_else(
            || file.display().to_string(),
            |n| n.to_string_lossy().into(),
        );
        let counts = match CarlTrace::tracked_counts(&file) {
            Ok(c) => c,
            Err(e) => {
                progress(&format!("skipped {name}: {e}"));
                continue;
            }
        };
        for (side, tracked) in counts {
            let label = format!("{name} {}", side.name());
            if tracked == 0 {
                progress(&format!("{label}: not tracked in any sample"));
                continue;
            }
            match measure_hand(&file, &name, side, tracked, progress) {
                Ok(r) => rows.extend(r),
                Err(e) => progress(&format!("skipped {label}: {e}")),
            }
        }
    }
    Ok(rows)
}

/// The rows of one hand of one file (none when it never closes).
fn measure_hand(
    file: &Path,
    name: &str,
    side: HandSide,
    tracked: usize,
    progress: &mut dyn FnMut(&str),
) -> Result<Vec<TraceRow>, String> {
    let label = format!("{name} {}", side.name());
    let trace = CarlTrace::load_hand(file, side).map_err(|e| e.to_string())?;
    if let Some(d) = &trace.damage {
        progress(&format!(
            "{label}: using the {} good samples; {d}",
            trace.samples.len()
        ));
    }
    let hands = hand_samples(&trace, [0.0; 3]);
    let closures = find_closures(&hands);
    let Some(first) = closures.first() else {
        progress(&format!(
            "{label}: {tracked} of {} samples tracked; no closure (no row)",
            trace.samples.len()
        ));
        return Ok(Vec::new());
    };
    let cube = place_cube(first);
    let shift = cube.shift_y();
    let hands = hand_samples(&trace, [0.0, shift, 0.0]);
    let wrist_rise_m = hands
        .iter()
        .skip(first.index)
        .filter(|h| h.tracked != 0)
        .map(|h| h.wrist.position[1] - (first.wrist[1] + shift))
        .fold(0.0, f64::max);
    let wrist_velocity = {
        // A closure is never the first or last sample of its run: both neighbours exist.
        let before = first.index.checked_sub(1).and_then(|i| hands.get(i));
        match (before, hands.get(first.index + 1)) {
            (Some(a), Some(b)) if b.stamp.source_time_ns > a.stamp.source_time_ns => {
                let dt = (b.stamp.source_time_ns - a.stamp.source_time_ns) as f64 / 1e9;
                (DVec3::from_array(b.wrist.position) - DVec3::from_array(a.wrist.position)) / dt
            }
            _ => DVec3::ZERO,
        }
    };
    let finger = if first.grip.finger == 1 {
        "index"
    } else {
        "middle"
    };
    progress(&format!(
        "{label}: {tracked} of {} samples tracked; {} closure(s), the first at {:.2} s \
         ({finger}, {:.1} cm from {:.1} cm open; wrist at {:.2} m/s, {:+.2} m/s vertically); cube \
         {:.1} cm, gripped {}, trace moved {:+.3} m",
        trace.samples.len(),
        closures.len(),
        first.time_s,
        first.grip.aperture * 100.0,
        first.open * 100.0,
        wrist_velocity.length(),
        wrist_velocity.y,
        cube.edge * 100.0,
        if cube.vertical {
            "vertically"
        } else {
            "horizontally"
        },
        shift
    ));
    // The recording's other hand, moved as this one, when it is tracked at all: the same cube
    // with both hands in the world (docs/model.md "Two hands").
    let other_side = match side {
        HandSide::Right => HandSide::Left,
        HandSide::Left => HandSide::Right,
    };
    let other = CarlTrace::load_hand(file, other_side)
        .ok()
        .filter(|t| t.tracked_samples() > 0 && t.samples.len() == trace.samples.len())
        .map(|t| hand_samples(&t, [0.0, shift, 0.0]));
    let runs = [HandRules::Paper, HandRules::Tracked]
        .into_iter()
        .map(|r| (r, None))
        .chain(
            other
                .iter()
                .flat_map(|o| [HandRules::Paper, HandRules::Tracked].map(|r| (r, Some(o)))),
        );
    let mut rows = Vec::new();
    for (rules, other) in runs {
        let scene = scene(&label, &cube, rules);
        let c = match other {
            None => run(&scene, &hands, first.open_threshold()),
            Some(o) => run_with_other(&scene, &hands, o, side, first.open_threshold()),
        }
        .map_err(|e| format!("{} rules: {e}", rules.name()))?;
        let lifted = c.max_rise_m >= LIFT_M;
        progress(&format!(
            "{label} {}{}: {} grasp(s) ({:.2} s grasped), {} release(s), {} drop(s), {} flicker(s), \
             {}",
            rules.name(),
            if other.is_some() {
                ", with the other hand"
            } else {
                ""
            },
            c.grasps,
            c.grasped_steps as f64 / scene.world.step_hz,
            c.releases,
            c.drops,
            c.flickers,
            if lifted {
                format!("lifted {:.1} cm", c.max_rise_m * 100.0)
            } else {
                "not lifted".to_string()
            }
        ));
        rows.push(TraceRow {
            file: name.to_string(),
            hand: side.name().to_string(),
            rules: rules.name().to_string(),
            with_other_hand: other.is_some(),
            grasps: c.grasps,
            drops: c.drops,
            flickers: c.flickers,
            lifted,
            releases: c.releases,
            grasped_s: c.grasped_steps as f64 / scene.world.step_hz,
            max_rise_m: c.max_rise_m,
            wrist_rise_m,
            wrist_speed_m_s: wrist_velocity.length(),
            wrist_vy_m_s: wrist_velocity.y,
            closures: closures.len() as u32,
            closure_s: first.time_s,
            aperture_m: first.grip.aperture,
            open_m: first.open,
            finger: finger.to_string(),
            cube_m: cube.edge,
            grip_axis: if cube.vertical {
                "vertical"
            } else {
                "horizontal"
            }
            .to_string(),
            shift_y_m: shift,
            samples: trace.samples.len() as u32,
            tracked_fraction: tracked as f64 / trace.samples.len().max(1) as f64,
            steps: c.steps,
        });
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shared CARL recordings, or None (with a message) where this checkout has none.
    fn shared_carl() -> Option<PathBuf> {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/carl");
        if dir.is_dir() {
            Some(dir)
        } else {
            eprintln!("skipped: no {} in this checkout", dir.display());
            None
        }
    }

    /// A hand of bare tips: the thumb at the origin's side, index and middle `aperture` and
    /// `aperture + 2 cm` away along +x, at time `t`, with the hand model's radii.
    fn hand(t: f64, aperture: f64) -> HandSample {
        let mut h = HandSample {
            tracked: 1,
            finger_count: 5,
            ..HandSample::default()
        };
        h.stamp.source_time_ns = (t * 1e9).round() as u64;
        h.wrist.position = [0.0, 1.0, 0.1];
        h.finger_point_count = [3, 4, 4, 4, 4];
        let spec = common::config::hand::HandModelSpec::default();
        h.finger_radius = [
            spec.thumb_radius,
            spec.fingers[0].radius,
            spec.fingers[1].radius,
            spec.fingers[2].radius,
            spec.fingers[3].radius,
        ];
        for f in 0..5 {
            for p in 0..4 {
                h.finger_points[f][p] = [0.0, 1.0, -0.01 * p as f64];
            }
        }
        h.finger_points[0][2] = [0.0, 1.0, 0.0];
        h.finger_points[1][3] = [aperture, 1.0, 0.0];
        h.finger_points[2][3] = [aperture + 0.02, 1.0, 0.0];
        h
    }

    /// Open (8 cm) for 0.5 s, closing to 3 cm over 0.3 s, held 0.4 s, opening over 0.3 s,
    /// open 0.5 s: at 90 Hz, with a deterministic +-1 mm tremor.
    fn open_close_open() -> Vec<HandSample> {
        let n = (2.0 * 90.0) as usize;
        (0..n)
            .map(|k| {
                let t = k as f64 / 90.0;
                let a = if t < 0.5 {
                    0.08
                } else if t < 0.8 {
                    0.08 - 0.05 * (t - 0.5) / 0.3
                } else if t < 1.2 {
                    0.03
                } else if t < 1.5 {
                    0.03 + 0.05 * (t - 1.2) / 0.3
                } else {
                    0.08
                };
                let tremor = 0.001 * ((k * 7919 % 13) as f64 / 6.0 - 1.0);
                hand(t, a + tremor)
            })
            .collect()
    }

    #[test]
    fn an_open_close_open_hand_has_exactly_one_closure() {
        let hands = open_close_open();
        let c = find_closures(&hands);
        assert_eq!(c.len(), 1, "{c:?}");
        let c = c[0];
        assert!((0.8..1.2).contains(&c.time_s), "{}", c.time_s);
        assert!((c.grip.aperture - 0.03).abs() <= 0.0011, "{c:?}");
        assert!(c.open >= 0.079, "{c:?}");
        assert_eq!(c.grip.finger, 1);
        // Twice, with the hand lost in between: one closure in each run.
        let mut twice = hands.clone();
        for (k, h) in hands.iter().enumerate() {
            let mut h = *h;
            h.stamp.source_time_ns += 2_000_000_000 + 100_000_000;
            if k == 0 {
                let mut lost = h;
                lost.tracked = 0;
                lost.stamp.source_time_ns -= 50_000_000;
                twice.push(lost);
            }
            twice.push(h);
        }
        let c = find_closures(&twice);
        assert_eq!(c.len(), 2, "{c:?}");
        assert!(c[1].index > hands.len());
    }

    #[test]
    fn a_still_hand_a_small_squeeze_and_a_pinch_on_nothing_are_no_closures() {
        let still: Vec<_> = (0..180).map(|k| hand(k as f64 / 90.0, 0.06)).collect();
        assert!(find_closures(&still).is_empty());
        // 2.5 cm of closing: less than CLOSE_DROP_M.
        let squeeze: Vec<_> = open_close_open()
            .iter()
            .map(|h| {
                let a = h.finger_points[1][3][0];
                hand(
                    h.stamp.source_time_ns as f64 / 1e9,
                    0.055 + (a - 0.08) / 2.0,
                )
            })
            .collect();
        assert!(find_closures(&squeeze).is_empty());
        // A spread hand twitching: 12 cm to 8.5 cm (3.5 cm, but only 30% of its opening).
        let twitch: Vec<_> = open_close_open()
            .iter()
            .map(|h| {
                let a = h.finger_points[1][3][0];
                hand(h.stamp.source_time_ns as f64 / 1e9, 0.12 + (a - 0.08) * 0.7)
            })
            .collect();
        assert!(find_closures(&twitch).is_empty());
        // Closing to 1.5 cm: the tips (radii 1.0 and 0.9 cm) touch; nothing is held.
        let pinch: Vec<_> = open_close_open()
            .iter()
            .map(|h| {
                let a = h.finger_points[1][3][0];
                hand(h.stamp.source_time_ns as f64 / 1e9, 0.015 + (a - 0.03))
            })
            .collect();
        assert!(find_closures(&pinch).is_empty());
        // Untracked samples are not a hand.
        let lost: Vec<_> = open_close_open()
            .into_iter()
            .map(|mut h| {
                h.tracked = 0;
                h
            })
            .collect();
        assert!(find_closures(&lost).is_empty());
    }

    #[test]
    fn the_cube_puts_each_tip_its_depth_inside_opposite_faces() {
        for (thumb, tip, vertical) in [
            ([0.0, 1.0, 0.0], [0.03, 1.01, 0.02], false),
            ([0.1, 1.2, -0.3], [0.09, 1.17, -0.3], true),
        ] {
            let closure = Closure {
                index: 0,
                time_s: 0.0,
                grip: Grip {
                    aperture: DVec3::from_array(thumb).distance(DVec3::from_array(tip)),
                    thumb,
                    finger_tip: tip,
                    finger: 1,
                    radii: 0.019,
                },
                open: 0.08,
                wrist: [0.0; 3],
            };
            let cube = place_cube(&closure);
            assert_eq!(cube.vertical, vertical);
            let rot = DQuat::from_array(cube.rotation);
            // Turned about the vertical only: it rests on a face.
            assert!((rot * DVec3::Y - DVec3::Y).length() < 1e-12);
            let centre = DVec3::from_array(cube.centre);
            let local = |p: [f64; 3]| rot.inverse() * (DVec3::from_array(p) - centre);
            let (a, b) = (local(thumb), local(tip));
            let axis = if vertical { 1 } else { 0 };
            let half = cube.edge / 2.0;
            for p in [a, b] {
                let depth = half - p.to_array()[axis].abs();
                assert!((depth - TIP_DEPTH_M).abs() < 1e-12, "{depth}");
                // Within the face, not beside it.
                assert!(p.abs().max_element() <= half + 1e-12, "{p}");
            }
            assert!(
                a.to_array()[axis] * b.to_array()[axis] < 0.0,
                "opposite faces"
            );
            // Moved by shift_y, the cube's bottom is on the floor.
            assert!((centre.y + cube.shift_y() - half).abs() < 1e-12);
        }
    }

    #[test]
    fn a_file_that_is_not_carl_is_skipped_with_a_line() {
        let dir = std::env::temp_dir().join(format!("bench-hands-traces-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("a.carl"), b"MCAP\x01\0\0\0 not a carl file").unwrap();
        std::fs::write(dir.join("b.carl"), b"CARL").unwrap();
        std::fs::write(dir.join("notes.txt"), b"not looked at").unwrap();
        let mut lines = Vec::new();
        let rows = measure(&dir, &mut |l| lines.push(l.to_string())).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        assert!(rows.is_empty());
        assert_eq!(lines.len(), 2, "{lines:?}");
        assert!(lines[0].starts_with("skipped a.carl: "), "{lines:?}");
        assert!(lines[0].contains("not a CARL file"), "{lines:?}");
        assert!(lines[1].starts_with("skipped b.carl: "), "{lines:?}");
        assert!(lines[1].contains("at byte 4"), "{lines:?}");
        assert!(measure(Path::new("/no/such/folder"), &mut |_| {}).is_err());
    }

    /// The hands are those `handblocks simulate --hand` makes (it reads the right hand through
    /// `replay::HandTrace`), and a run steps the world as `stepper::simulate_samples` does:
    /// the same steps, the same grasps and releases.
    #[test]
    fn the_hands_and_the_run_are_simulates() {
        let Some(dir) = shared_carl() else { return };
        let file = dir.join("example_push_0.carl");
        let offset = [0.0, -1.2, 0.0];
        let trace = replay::HandTrace::load(&file, offset).unwrap();
        let mut stream = kinematics::HandStream::new(kinematics::HandModel::default());
        let theirs: Vec<HandSample> = trace
            .samples
            .iter()
            .map(|s| match s {
                replay::SourceSample::Joints(j) => *stream.joints(j),
                other => panic!("a CARL trace gave {other:?}"),
            })
            .collect();
        let carl = CarlTrace::load_hand(&file, HandSide::Right).unwrap();
        let ours = hand_samples(&carl, offset);
        assert!(ours == theirs);

        let hands = hand_samples(&carl, [0.0; 3]);
        let first = find_closures(&hands)[0];
        let cube = place_cube(&first);
        let hands = hand_samples(&carl, [0.0, cube.shift_y(), 0.0]);
        for rules in [HandRules::Paper, HandRules::Tracked] {
            let scene = scene("push right", &cube, rules);
            let counts = run(&scene, &hands, first.open_threshold()).unwrap();
            let report = stepper::simulate_samples(&scene, &hands, None).unwrap();
            let of = |k: EventKind| report.events.iter().filter(|e| e.kind == k).count() as u32;
            assert_eq!(counts.steps, report.frames);
            assert_eq!(counts.grasps, of(EventKind::Grasp));
            assert_eq!(counts.releases, of(EventKind::Release));
            assert!(counts.grasps > 0);
        }
    }

    /// Every shared recording: both rule sets for each hand that closes, none for the others.
    #[test]
    fn every_shared_recording_gives_rows_for_each_closing_hand_under_both_rule_sets() {
        let Some(dir) = shared_carl() else { return };
        let mut lines = Vec::new();
        let rows = measure(&dir, &mut |l| lines.push(l.to_string())).unwrap();
        for l in &lines {
            println!("{l}");
        }
        println!("file hand rules grasps releases drops flickers lifted grasped_s rise wrist_rise");
        for r in &rows {
            println!(
                "{} {} {} {} {} {} {} {} {:.2} {:.3} {:.3}",
                r.file,
                r.hand,
                r.rules,
                r.grasps,
                r.releases,
                r.drops,
                r.flickers,
                r.lifted,
                r.grasped_s,
                r.max_rise_m,
                r.wrist_rise_m
            );
        }
        let mut closing = 0;
        for file in carl_files(&dir).unwrap() {
            let name = file.file_name().unwrap().to_string_lossy().to_string();
            for side in HandSide::BOTH {
                let trace = CarlTrace::load_hand(&file, side).unwrap();
                let closes = !find_closures(&hand_samples(&trace, [0.0; 3])).is_empty();
                let of: Vec<&TraceRow> = rows
                    .iter()
                    .filter(|r| r.file == name && r.hand == side.name())
                    .collect();
                if closes {
                    closing += 1;
                    let rules: Vec<(&str, bool)> = of
                        .iter()
                        .map(|r| (r.rules.as_str(), r.with_other_hand))
                        .collect();
                    // Alone under both rules; then with the other hand, where it is tracked.
                    let other = match side {
                        HandSide::Right => HandSide::Left,
                        HandSide::Left => HandSide::Right,
                    };
                    let other_tracked = CarlTrace::load_hand(&file, other)
                        .unwrap()
                        .tracked_samples()
                        > 0;
                    let mut want = vec![("paper", false), ("tracked", false)];
                    if other_tracked {
                        want.extend([("paper", true), ("tracked", true)]);
                    }
                    assert_eq!(rules, want, "{name} {}", side.name());
                    for r in of {
                        assert!(r.closures >= 1 && r.cube_m > 2.0 * TIP_DEPTH_M);
                        assert!(r.drops <= r.releases && r.flickers <= r.releases);
                        assert!(r.lifted == (r.max_rise_m >= LIFT_M));
                        assert!(r.tracked_fraction > 0.0 && r.tracked_fraction <= 1.0);
                    }
                } else {
                    assert!(of.is_empty(), "{name} {}", side.name());
                }
            }
        }
        assert!(closing > 0, "no hand of the shared recordings closes");
        assert!(serde_json::to_string(&rows)
            .unwrap()
            .contains("\"rules\":\"tracked\""));
    }
}
