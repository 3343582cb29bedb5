//! `handblocks simulate`: run a world for N steps from a hand source, deterministically, and
//! render the result as docs/design.md states (text, or JSON with `--json`).
//!
//! The scene's `[hand]` drives the hand, sampled once per step: the n-th step (1-based) gets
//! the hand at t = n * dt and takes the hand at t = (n - 1) * dt as its previous one, so after
//! k steps the world and the hand are both at t = k * dt. Keys with `fingers` need no hand
//! model: [`BareFingersHand`] interpolates them. Keys with `grip`/`angles` go through the hand
//! model, which the caller supplies as a [`HandSource`].

use std::fmt::Write as _;

use glam::{DQuat, DVec3};

use common::config::scene::{HandPoseSpec, HandScript};
use common::config::Scene;
use common::{BlockMode, HandSample, Pose, Stamp, MAX_FINGERS, MAX_FINGER_POINTS};

use crate::model::Model;
use crate::timeline::{HandFrames, Timeline};
use crate::world::{EventKind, WorldError};

/// Where `simulate` gets the hand of each step.
pub trait HandSource {
    /// The hand at `step` (0 = before the first step) and time `t = step * dt`; None when
    /// there is no hand.
    fn hand_at(&mut self, step: u64, t: f64) -> Option<HandSample>;
}

impl<F: FnMut(u64, f64) -> Option<HandSample>> HandSource for F {
    fn hand_at(&mut self, step: u64, t: f64) -> Option<HandSample> {
        self(step, t)
    }
}

/// One key of a bare check-point hand, in the wrist frame.
#[derive(Debug, Clone)]
struct BareKey {
    t: f64,
    wrist: DVec3,
    rot: DQuat,
    points: [[DVec3; MAX_FINGER_POINTS]; MAX_FINGERS],
}

/// The scripted hand of a scene whose keys give `fingers`: no hand model, no palm, finger
/// radius 0. Between keys: the wrist position linearly, its rotation by slerp, and every check
/// point linearly in the wrist's frame, then into the world. Before the first key and after the
/// last the hand holds still.
#[derive(Debug, Clone)]
pub struct BareFingersHand {
    keys: Vec<BareKey>,
    finger_count: u32,
    point_count: [u32; MAX_FINGERS],
}

impl BareFingersHand {
    /// None unless every key of the script gives `fingers`.
    pub fn from_script(script: &HandScript) -> Option<BareFingersHand> {
        let mut keys = Vec::with_capacity(script.keys.len());
        let mut finger_count = 0;
        let mut point_count = [0u32; MAX_FINGERS];
        for k in &script.keys {
            let HandPoseSpec::Fingers(fingers) = &k.pose else {
                return None;
            };
            let mut points = [[DVec3::ZERO; MAX_FINGER_POINTS]; MAX_FINGERS];
            finger_count = fingers.len().min(MAX_FINGERS) as u32;
            for (f, finger) in fingers.iter().take(MAX_FINGERS).enumerate() {
                point_count[f] = finger.len().min(MAX_FINGER_POINTS) as u32;
                for (j, p) in finger.iter().take(MAX_FINGER_POINTS).enumerate() {
                    points[f][j] = DVec3::from_array(*p);
                }
            }
            keys.push(BareKey {
                t: k.t,
                wrist: DVec3::from_array(k.wrist),
                rot: DQuat::from_array(k.wrist_rotation).normalize(),
                points,
            });
        }
        if keys.is_empty() {
            return None;
        }
        Some(BareFingersHand {
            keys,
            finger_count,
            point_count,
        })
    }

    /// The scene's bare check-point hand, if its `[hand]` uses `fingers`.
    pub fn from_scene(scene: &Scene) -> Option<BareFingersHand> {
        scene.hand.as_ref().and_then(BareFingersHand::from_script)
    }

    /// The scene's bare check-point left hand, if its `[left_hand]` uses `fingers` (taken as
    /// given, in the left wrist's frame: nothing is mirrored).
    pub fn left_of_scene(scene: &Scene) -> Option<BareFingersHand> {
        scene
            .left_hand
            .as_ref()
            .and_then(BareFingersHand::from_script)
    }

    /// The hand at time t.
    pub fn sample(&self, t: f64) -> HandSample {
        let n = self.keys.len();
        let (a, b, s) = if t <= self.keys[0].t {
            (0, 0, 0.0)
        } else if t >= self.keys[n - 1].t {
            (n - 1, n - 1, 0.0)
        } else {
            let j = self.keys.partition_point(|k| k.t <= t);
            let (k0, k1) = (&self.keys[j - 1], &self.keys[j]);
            (j - 1, j, (t - k0.t) / (k1.t - k0.t))
        };
        let (ka, kb) = (&self.keys[a], &self.keys[b]);
        let wrist = ka.wrist.lerp(kb.wrist, s);
        let rot = if a == b {
            ka.rot
        } else {
            ka.rot.slerp(kb.rot, s).normalize()
        };
        let mut h = HandSample {
            stamp: Stamp::default(),
            wrist: Pose {
                position: wrist.to_array(),
                rotation: rot.to_array(),
            },
            tracked: 1,
            finger_count: self.finger_count,
            finger_point_count: self.point_count,
            palm_vertex_count: 0,
            ..HandSample::default()
        };
        for f in 0..self.finger_count as usize {
            for j in 0..self.point_count[f] as usize {
                let local = ka.points[f][j].lerp(kb.points[f][j], s);
                h.finger_points[f][j] = (wrist + rot * local).to_array();
            }
        }
        h
    }

    /// The time of the last key (the hand holds still after it).
    pub fn end_time(&self) -> f64 {
        self.keys.last().map_or(0.0, |k| k.t)
    }
}

impl HandSource for BareFingersHand {
    fn hand_at(&mut self, step: u64, t: f64) -> Option<HandSample> {
        let mut h = self.sample(t);
        h.stamp.seq = step;
        Some(h)
    }
}

/// One block's final state in a report.
#[derive(Debug, Clone, PartialEq)]
pub struct BlockReport {
    pub name: String,
    pub position: [f64; 3],
    pub rotation: [f64; 4],
    pub mode: BlockMode,
}

/// One event in a report.
#[derive(Debug, Clone, PartialEq)]
pub struct EventReport {
    pub step: u64,
    pub kind: EventKind,
    pub block: String,
    /// The hand a grasp, release or push is by, in a two-hand world (`"hand"` in the JSON).
    pub hand: Option<common::HandSide>,
    /// Whose hand, in a shared world ([`common::HandSample::participant`]; `"participant"` in
    /// the JSON, which names it only when it is not 0).
    pub participant: u32,
}

/// The side of the hand in slot `slot` of a two-hand world ([`crate::HAND_SLOTS`]): slot 0 is
/// the right, slot 1 the left (and so on for each participant of a shared world: even slots
/// are right hands).
pub fn slot_side(slot: usize) -> common::HandSide {
    if slot.is_multiple_of(2) {
        common::HandSide::Right
    } else {
        common::HandSide::Left
    }
}

/// The slot of `side` in a two-hand world ([`slot_side`]).
pub fn side_slot(side: common::HandSide) -> usize {
    match side {
        common::HandSide::Right => 0,
        common::HandSide::Left => 1,
    }
}

/// What `simulate` returns.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    pub frames: u64,
    pub blocks: Vec<BlockReport>,
    pub events: Vec<EventReport>,
    /// Times the hand's source clock jumped by more than `timeline::MAX_CATCH_UP_NS` between
    /// two samples (each brought one step, not a catch-up): 0 for a sound trace.
    pub clock_jumps: u64,
    /// Hand samples refused where they entered (`hand::unusable_because`): the hand held its
    /// last good pose over them. 0 for a sound trace.
    pub refused_hands: u64,
    /// The first refused sample: its seq and why.
    pub first_refused: Option<(u64, &'static str)>,
    /// Under `[world] hands = "tracked"`: what T1-T3 did (None under the paper's rules, whose
    /// reports stay as they were).
    pub tracked: Option<crate::tracked::TrackedCounts>,
}

/// Steps `simulate` takes when the command line gives no `--frames`: the scripted hand's
/// duration plus three seconds to settle (at least three seconds), at the scene's step rate.
pub fn default_frames(scene: &Scene) -> u64 {
    let hand_end = [&scene.hand, &scene.left_hand]
        .into_iter()
        .flatten()
        .map(|h| h.end_time())
        .fold(0.0, f64::max);
    ((hand_end + 3.0) * scene.world.step_hz).ceil() as u64
}

/// A progress hook's answer: stop the run here.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stop;

/// Called after every step of a run with the steps taken so far and the world after it (a
/// caller that checks for Ctrl-C, shows progress, or keeps the blocks' path); [`Stop`] ends
/// the run there.
pub type Progress<'a> = dyn FnMut(u64, &Model) -> Result<(), Stop> + 'a;

/// Why a run with a progress hook gave no report.
#[derive(Debug)]
pub enum RunError {
    World(WorldError),
    /// Its hook said [`Stop`] after this many steps.
    Stopped {
        steps: u64,
    },
}

impl From<WorldError> for RunError {
    fn from(e: WorldError) -> RunError {
        RunError::World(e)
    }
}

/// The world error of a run whose hook never stops.
fn never_stopped(e: RunError) -> WorldError {
    match e {
        RunError::World(e) => e,
        RunError::Stopped { .. } => unreachable!("a hook that never stops stopped a run"),
    }
}

/// Runs the scene's world for `frames` steps with the hand from `hand` (None: no hand; a scene
/// whose hand uses `fingers` can pass a [`BareFingersHand`]), under the model the scene's
/// `[world] model` names. Deterministic.
pub fn simulate(
    scene: &Scene,
    frames: u64,
    hand: Option<&mut dyn HandSource>,
) -> Result<Report, WorldError> {
    simulate_with(scene, frames, hand, &mut |_, _| Ok(())).map_err(never_stopped)
}

/// [`simulate`], calling `progress` after every step.
pub fn simulate_with(
    scene: &Scene,
    frames: u64,
    hand: Option<&mut dyn HandSource>,
    progress: &mut Progress<'_>,
) -> Result<Report, RunError> {
    simulate_hands_with(scene, frames, [hand, None], progress)
}

/// [`simulate_with`] of two hands by slot (docs/model.md "Two hands": slot 0 the right, slot 1
/// the left), each sampled once per step as one hand is: a scene's `[hand]` and `[left_hand]`.
/// With no left hand it is [`simulate_with`] bit for bit; with one, events name their hands.
pub fn simulate_hands_with(
    scene: &Scene,
    frames: u64,
    mut hands: [Option<&mut dyn HandSource>; 2],
    progress: &mut Progress<'_>,
) -> Result<Report, RunError> {
    let mut world = Model::new(scene)?;
    let two_handed = hands[1].is_some();
    if world.kind() == common::config::scene::ModelKind::Precise && two_handed {
        return Err(RunError::World(two_hands_refused(scene)));
    }
    let dt = 1.0 / scene.world.step_hz;
    let mut events = Vec::new();
    for (slot, hand) in hands.iter_mut().enumerate() {
        if let Some(h) = hand.as_deref_mut() {
            let first = h.hand_at(0, 0.0);
            world.set_previous_hand_of(slot, first.as_ref());
        }
    }
    for n in 1..=frames {
        let t = n as f64 * dt;
        let mut sample = |slot: usize| {
            hands[slot].as_deref_mut().and_then(|h| {
                h.hand_at(n, t).map(|mut h| {
                    h.side = slot_side(slot).code();
                    h
                })
            })
        };
        let (right, left) = (sample(0), sample(1));
        world.step_hands([right.as_ref(), left.as_ref()]);
        collect_events(&world, scene, &mut events, two_handed);
        progress(n, &world).map_err(|Stop| RunError::Stopped { steps: n })?;
    }
    Ok(report(&world, scene, frames, events))
}

/// The precise model's refusal of a second hand.
fn two_hands_refused(scene: &Scene) -> WorldError {
    WorldError {
        file: scene.file.clone(),
        block: None,
        problem: "two hands are the paper model's (docs/model.md \"Two hands\"): the precise \
                  model takes one; give one hand (--hands left or right) or `world.model` = \
                  \"paper\""
            .into(),
    }
}

/// Runs the scene's world on a sequence of hand samples with their own source times, exactly
/// as the stepper process does (docs/model.md conventions: as many steps as bring world time up to
/// each sample, the hand interpolated between samples); then, with the last hand held, up to
/// `frames` steps in all (None: 2 s more). With `frames` below what the trace brings, the world
/// stops there. This is how a recorded trace is tried against a scene in one process.
pub fn simulate_samples(
    scene: &Scene,
    hands: &[HandSample],
    frames: Option<u64>,
) -> Result<Report, WorldError> {
    simulate_samples_with(scene, hands, frames, &mut |_, _| Ok(())).map_err(never_stopped)
}

/// [`simulate_samples`], calling `progress` after every step. The samples are a stream of
/// hands as the stepper process receives them, each marked with its side
/// ([`HandSample::side`]): a one-hand source's are all the right's (side 0); a two-hand
/// source's right and left of each frame make one frame ([`HandFrames`]), and the world is
/// two-handed from the first left hand on.
pub fn simulate_samples_with(
    scene: &Scene,
    hands: &[HandSample],
    frames: Option<u64>,
    progress: &mut Progress<'_>,
) -> Result<Report, RunError> {
    simulate_stream(scene, hands.iter().copied(), frames, progress)
}

pub use crate::timeline::HandFrame;

/// [`simulate_samples_with`] for frames of two hands by slot (slot 0 the right, slot 1 the
/// left, whatever the samples' own `side`), each hand interpolated on its own between frames
/// ([`Timeline::advance_hands`]).
pub fn simulate_frames_with(
    scene: &Scene,
    hand_frames: &[HandFrame],
    frames: Option<u64>,
    progress: &mut Progress<'_>,
) -> Result<Report, RunError> {
    let stream = hand_frames.iter().flat_map(|frame| {
        frame.iter().enumerate().filter_map(|(slot, hand)| {
            hand.map(|mut h| {
                h.side = slot_side(slot).code();
                h
            })
        })
    });
    simulate_stream(scene, stream, frames, progress)
}

/// The hands of `stream` made into frames and taken exactly as the stepper process takes
/// them ([`HandFrames`]; a hand the world cannot use is refused and counted: it holds its last
/// good sample beside a good one, and a frame with no usable hand brings no steps), then the
/// last hands held for 2 s (or up to `frames` steps in all).
fn simulate_stream(
    scene: &Scene,
    stream: impl Iterator<Item = HandSample> + Clone,
    frames: Option<u64>,
    progress: &mut Progress<'_>,
) -> Result<Report, RunError> {
    let mut world = Model::new(scene)?;
    let two_handed = stream
        .clone()
        .any(|h| common::HandSide::from_code(h.side) == common::HandSide::Left);
    if world.kind() == common::config::scene::ModelKind::Precise && two_handed {
        return Err(RunError::World(two_hands_refused(scene)));
    }
    let mut events = Vec::new();
    let mut timeline = Timeline::new(scene.world.step_hz);
    let mut assembled = HandFrames::new();
    let limit = frames.unwrap_or(u64::MAX);
    let stopped = std::cell::Cell::new(None);
    let mut take = |frame: &HandFrame| {
        if !timeline.started() {
            for (slot, hand) in frame.iter().enumerate() {
                if hand.is_some() || slot == 0 {
                    world.set_previous_hand_of(slot, hand.as_ref());
                }
            }
        }
        timeline.advance_hands(frame.each_ref().map(Option::as_ref), |h| {
            if world.steps() < limit && stopped.get().is_none() {
                world.step_hands(h);
                collect_events(&world, scene, &mut events, two_handed);
                if progress(world.steps(), &world).is_err() {
                    stopped.set(Some(world.steps()));
                }
            }
        });
    };
    for hand in stream {
        assembled.push(&hand, &mut take);
        if let Some(steps) = stopped.get() {
            return Err(RunError::Stopped { steps });
        }
    }
    assembled.flush(&mut take);
    if let Some(steps) = stopped.get() {
        return Err(RunError::Stopped { steps });
    }
    let last = *assembled.last_good();
    let end = frames.unwrap_or(world.steps() + (2.0 * scene.world.step_hz) as u64);
    while world.steps() < end {
        world.step_hands(last.each_ref().map(Option::as_ref));
        collect_events(&world, scene, &mut events, two_handed);
        let n = world.steps();
        progress(n, &world).map_err(|Stop| RunError::Stopped { steps: n })?;
    }
    let steps = world.steps();
    let mut out = report(&world, scene, steps, events);
    out.clock_jumps = timeline.jumps();
    out.refused_hands = assembled.refused_hands;
    out.first_refused = assembled.first_refused;
    Ok(out)
}

/// The step's events, one for each hand an event names in a two-hand world (right first).
fn collect_events(world: &Model, scene: &Scene, events: &mut Vec<EventReport>, two: bool) {
    for e in world.events() {
        push_event(e, scene, two, events);
    }
}

fn push_event(e: &crate::world::Event, scene: &Scene, two: bool, out: &mut Vec<EventReport>) {
    let block = scene
        .blocks
        .get(e.block)
        .map_or_else(|| format!("block {}", e.block), |b| b.name.clone());
    let named = (0..crate::HAND_SLOTS).filter(|k| e.hands & (1 << k) != 0);
    if two && e.hands != 0 {
        for slot in named {
            out.push(EventReport {
                step: e.step,
                kind: e.kind,
                block: block.clone(),
                hand: Some(slot_side(slot)),
                participant: (slot / 2) as u32,
            });
        }
    } else {
        out.push(EventReport {
            step: e.step,
            kind: e.kind,
            block,
            hand: None,
            participant: 0,
        });
    }
}

/// What a live session's world came to (the stepper process writes it when it stops): the
/// report `simulate` prints, from the world and the events it saw.
pub fn outcome(world: &Model, scene: &Scene, events: &[crate::world::Event]) -> Report {
    let mut reports = Vec::with_capacity(events.len());
    let two = events.iter().any(|e| e.hands != 0);
    for e in events {
        push_event(e, scene, two, &mut reports);
    }
    let events = reports;
    report(world, scene, world.steps(), events)
}

fn report(world: &Model, scene: &Scene, frames: u64, events: Vec<EventReport>) -> Report {
    let blocks = (0..world.block_count())
        .filter_map(|i| world.block(i).map(|b| (i, b)))
        .map(|(i, b)| BlockReport {
            name: scene.blocks[i].name.clone(),
            position: b.position.to_array(),
            rotation: b.rotation.to_array(),
            mode: b.mode,
        })
        .collect();
    Report {
        frames,
        blocks,
        events,
        clock_jumps: 0,
        refused_hands: 0,
        first_refused: None,
        tracked: (scene.world.hands == common::config::scene::HandRules::Tracked)
            .then(|| world.tracked_counts()),
    }
}

/// A JSON string literal.
fn json_str(s: &str) -> String {
    let mut o = String::with_capacity(s.len() + 2);
    o.push('"');
    for c in s.chars() {
        match c {
            '"' => o.push_str("\\\""),
            '\\' => o.push_str("\\\\"),
            c if (c as u32) < 0x20 => {
                let _ = write!(o, "\\u{:04x}", c as u32);
            }
            c => o.push(c),
        }
    }
    o.push('"');
    o
}

/// A JSON number: Rust's shortest round-trip form (deterministic; finite by construction).
fn json_num(v: f64) -> String {
    if v.is_finite() {
        format!("{v:?}")
    } else {
        "null".into()
    }
}

fn json_list(v: &[f64]) -> String {
    let items: Vec<String> = v.iter().map(|x| json_num(*x)).collect();
    format!("[{}]", items.join(", "))
}

impl Report {
    /// docs/design.md's `--json`: `{"frames": N, "blocks": [{"name", "position", "rotation",
    /// "mode"}], "events": [{"step", "kind", "block"}]}`.
    pub fn to_json(&self) -> String {
        let mut o = String::new();
        let _ = write!(o, "{{\"frames\": {}, \"blocks\": [", self.frames);
        for (i, b) in self.blocks.iter().enumerate() {
            if i > 0 {
                o.push_str(", ");
            }
            let _ = write!(
                o,
                "{{\"name\": {}, \"position\": {}, \"rotation\": {}, \"mode\": {}}}",
                json_str(&b.name),
                json_list(&b.position),
                json_list(&b.rotation),
                json_str(b.mode.name())
            );
        }
        o.push_str("], \"events\": [");
        for (i, e) in self.events.iter().enumerate() {
            if i > 0 {
                o.push_str(", ");
            }
            let _ = write!(
                o,
                "{{\"step\": {}, \"kind\": {}, \"block\": {}",
                e.step,
                json_str(e.kind.name()),
                json_str(&e.block)
            );
            if let Some(hand) = e.hand {
                let _ = write!(o, ", \"hand\": {}", json_str(hand.name()));
            }
            if e.participant != 0 {
                let _ = write!(o, ", \"participant\": {}", e.participant);
            }
            o.push('}');
        }
        o.push(']');
        if self.clock_jumps > 0 {
            let _ = write!(o, ", \"clock_jumps\": {}", self.clock_jumps);
        }
        if self.refused_hands > 0 {
            let _ = write!(o, ", \"refused_hands\": {}", self.refused_hands);
        }
        if let Some(t) = &self.tracked {
            let _ = write!(
                o,
                ", \"hands\": \"tracked\", \"tracked\": {{\"grip_held_steps\": {}, \"gaps_held\": {}, \
                 \"gap_releases\": {}, \"fitted_throws\": {}}}",
                t.grip_held_steps, t.gaps_held, t.gap_releases, t.fitted_throws
            );
        }
        o.push_str("}\n");
        o
    }

    /// The readable summary: each block's final mode and pose, then the events.
    pub fn to_text(&self) -> String {
        let mut o = String::new();
        let _ = writeln!(o, "after {} steps:", self.frames);
        // Names are at most MAX_BLOCK_NAME_CHARS (and a lattice suffix); the cap keeps the
        // column within what a format width can be whatever made the report.
        let w = self
            .blocks
            .iter()
            .map(|b| b.name.len())
            .max()
            .unwrap_or(0)
            .min(256);
        for b in &self.blocks {
            let [x, y, z] = b.position;
            let q = DQuat::from_array(b.rotation);
            let (axis, angle) = q.to_axis_angle();
            let _ = writeln!(
                o,
                "  {:w$}  {:9}  G = ({x:.6}, {y:.6}, {z:.6}) m  rotation {:.3} deg about ({:.3}, {:.3}, {:.3})",
                b.name,
                b.mode.name(),
                angle.to_degrees(),
                axis.x,
                axis.y,
                axis.z,
            );
        }
        if self.clock_jumps > 0 {
            let _ = writeln!(
                o,
                "the hand's clock jumped {} time(s) by more than {} s between two samples: \
                 world time went on one step at each (a damaged or edited trace?)",
                self.clock_jumps,
                crate::timeline::MAX_CATCH_UP_NS / 1_000_000_000
            );
        }
        if self.refused_hands > 0 {
            let _ = write!(
                o,
                "{} hand sample(s) refused where they entered: the hand held its last good pose",
                self.refused_hands
            );
            match self.first_refused {
                Some((seq, why)) => {
                    let _ = writeln!(o, " (the first, seq {seq}: {why})");
                }
                None => o.push('\n'),
            }
        }
        if let Some(t) = &self.tracked {
            let _ = writeln!(
                o,
                "hands: tracked (docs/model.md T1-T3): {} step(s) held by the grip (T1: R3 alone let go), {} \
                 tracking gap(s) held, {} grasp(s) let go after a long gap, {} fitted throw(s)",
                t.grip_held_steps, t.gaps_held, t.gap_releases, t.fitted_throws
            );
        }
        if self.events.is_empty() {
            o.push_str("events: none\n");
        } else {
            let _ = writeln!(o, "events ({}):", self.events.len());
            // Runs of the same event of the same block on consecutive steps are folded.
            let mut i = 0;
            while i < self.events.len() {
                let e = &self.events[i];
                let mut j = i + 1;
                while j < self.events.len()
                    && self.events[j].kind == e.kind
                    && self.events[j].block == e.block
                    && self.events[j].hand == e.hand
                    && self.events[j].participant == e.participant
                    && self.events[j].step == self.events[j - 1].step + 1
                {
                    j += 1;
                }
                let by = match (e.hand, e.participant) {
                    (None, _) => String::new(),
                    (Some(h), 0) => format!(" ({} hand)", h.name()),
                    (Some(h), p) => format!(" (participant {p}'s {} hand)", h.name()),
                };
                if j - i > 1 {
                    let _ = writeln!(
                        o,
                        "  steps {}-{}  {:8} {}{by}",
                        e.step,
                        self.events[j - 1].step,
                        e.kind.name(),
                        e.block
                    );
                } else {
                    let _ = writeln!(
                        o,
                        "  step {:6}  {:8} {}{by}",
                        e.step,
                        e.kind.name(),
                        e.block
                    );
                }
                i = j;
            }
        }
        o
    }
}
