//! Two-hand throws and slingshots (docs/model.md "Two hands"): the scripted throws of
//! [`super::throws`] with the cube held by both hands, one world per throw taking both.
//!
//! **The hands.** Both have the throw's wrist. The right is [`Throw::hand`] (a pinch across
//! the wrist frame's x faces, picking the cube up); the left pinches across its y faces
//! ([`Throw::hand_of`]: fingertips pressing on them), joining the grasp during the lift with a
//! closing as long as the right's. Two kinds: **together** (both open at t_r) and **left first**
//! (the left opens at t_r - [`LEFT_FIRST_S`], in the wind-up or the hold before it, while the
//! right holds through to t_r). Each hand is degraded on its own ([`throws::degrade_hand`]:
//! the right draws exactly as the one-hand bench's hand, the left with its own salt, so its
//! noise, gaps and latency jitter are its own), both at the same level and on the same time
//! grid; frame k is [right sample k, left sample k], stepped through
//! `Timeline::advance_hands` and `World::step_hands` (the first frame is both hands' previous
//! hand).
//!
//! **Scored.** The final release (every holder let go: the cube leaves `grasped`) as the
//! one-hand bench scores a release ([`throws::judge`], [`throws::errors`]); a false drop is a
//! full release before t_r minus one sample interval (a hand leaving a grasp the other keeps
//! is no drop). A **slingshot**: a release event (a hand leaving a two-hand grasp, or the
//! final release) after which the cube's speed over the next 3 steps (the mean of |dG| / dt)
//! is more than twice the speed the hands moved at: the larger of the script's true G speed
//! over the span of time the world's hands at the event may stand for (the level's latency
//! +10 %, one sample interval and its longest gap before the event), the faster given hand's
//! G speed over those same 3 steps, and a floor of [`SPEED_FLOOR`].

use std::fmt::Write as _;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

use common::config::scene::HandRules;
use common::config::Scene;
use common::{BlockMode, HandSample};
use glam::{DQuat, DVec3};
use serde_json::{json, Value};
use stepper::timeline::Timeline;
use stepper::{EventKind, World};

use super::throws::{self, Hold, Level, Side, Throw, G_LOCAL};
use super::{fmt, pct_json, Pct, SEED};

/// The left lets go this long before t_r in a "left first" throw (s).
pub const LEFT_FIRST_S: f64 = 0.2;
/// Two-hand throws per (level, kind) at most.
pub const MAX_THROWS: usize = 300;
/// The levels measured with two hands (those of them a run chose).
pub const LEVELS: [&str; 3] = ["ideal", "quest", "worst"];
/// The hands' speed is taken as at least this (m/s): a hand at rest does not make noise a
/// slingshot.
pub const SPEED_FLOOR: f64 = 0.2;
/// A release is a slingshot when the cube leaves faster than this many times the hands.
pub const SLINGSHOT_RATIO: f64 = 2.0;
/// The steps after a release over which the cube's speed is taken.
pub const AFTER_STEPS: usize = 3;
/// Salt of the left hand's degradation draw.
const LEFT_SALT: u64 = 0x1ef7;
const RIGHT: u8 = 0b01;
const LEFT: u8 = 0b10;

/// How the two hands let go.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// Both open at t_r.
    Together,
    /// The left opens at t_r - [`LEFT_FIRST_S`], the right at t_r.
    LeftFirst,
}

impl Kind {
    pub const ALL: [Kind; 2] = [Kind::Together, Kind::LeftFirst];

    pub fn name(self) -> &'static str {
        match self {
            Kind::Together => "together",
            Kind::LeftFirst => "left first",
        }
    }

    /// When the left hand opens.
    pub fn left_opens(self, throw: &Throw) -> f64 {
        match self {
            Kind::Together => throw.t_r,
            Kind::LeftFirst => throw.t_r - LEFT_FIRST_S,
        }
    }
}

/// One grasp or release event of the cube in a two-hand world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TwoEvent {
    pub step: u64,
    pub kind: EventKind,
    /// The hands it is by (bit 0 right, bit 1 left).
    pub hands: u8,
    /// The cube's mode and holders after the step.
    pub mode: BlockMode,
    pub held_by: u8,
    /// The cube's mode before the step.
    pub mode_before: BlockMode,
    /// The cube's velocity (v / dt) after the step.
    pub velocity: DVec3,
}

impl TwoEvent {
    /// A release of every holder: the cube is no longer grasped.
    pub fn is_full_release(&self) -> bool {
        self.kind == EventKind::Release && self.mode != BlockMode::Grasped
    }

    /// A hand leaving a grasp that goes on.
    pub fn is_partial_release(&self) -> bool {
        self.kind == EventKind::Release && self.mode == BlockMode::Grasped
    }

    /// A grasp of a cube no hand held.
    pub fn is_first_grasp(&self) -> bool {
        self.kind == EventKind::Grasp && self.mode_before != BlockMode::Grasped
    }
}

/// What one two-hand world did with one throw's frames.
#[derive(Debug, Clone, Default)]
pub struct TwoRun {
    pub dt: f64,
    pub events: Vec<TwoEvent>,
    /// Per step (index step - 1): the cube's G after it, and each given hand's G (the wrist
    /// with the script's grip offset; None: no hand).
    pub block: Vec<DVec3>,
    pub hand_g: Vec<[Option<DVec3>; 2]>,
    /// Whether both hands held the cube at once in some step.
    pub both_held: bool,
}

fn g_of(h: &HandSample) -> DVec3 {
    DVec3::from_array(h.wrist.position) + DQuat::from_array(h.wrist.rotation) * G_LOCAL
}

/// Runs a world of `scene` on frames [right[k], left[k]]: the first frame is both hands'
/// previous hand, each frame brings the steps up to its time with each hand interpolated on
/// its own.
pub fn run_two(scene: &Scene, right: &[HandSample], left: &[HandSample]) -> Result<TwoRun, String> {
    let mut world =
        World::new(scene).map_err(|e| format!("{}: {}", e.file.display(), e.problem))?;
    let mut timeline = Timeline::new(scene.world.step_hz);
    let mut run = TwoRun {
        dt: 1.0 / scene.world.step_hz,
        ..TwoRun::default()
    };
    for (r, l) in right.iter().zip(left) {
        if !timeline.started() {
            world.set_previous_hand_of(0, Some(r));
            world.set_previous_hand_of(1, Some(l));
        }
        timeline.advance_hands([Some(r), Some(l)], |hands| {
            let before = world.block(0).map_or(BlockMode::Resting, |b| b.mode);
            world.step_hands(hands);
            let view = world.block(0);
            let (mode, velocity) = view.map_or((BlockMode::Resting, DVec3::ZERO), |b| {
                (b.mode, b.v / run.dt)
            });
            let held_by = if view.is_some() {
                world.block_state(0).held_by as u8
            } else {
                0
            };
            run.both_held |= held_by == RIGHT | LEFT;
            run.block.push(view.map_or(DVec3::ZERO, |b| b.position));
            run.hand_g.push(hands.map(|h| h.map(g_of)));
            for e in world.events() {
                if e.block != 0 || !matches!(e.kind, EventKind::Grasp | EventKind::Release) {
                    continue;
                }
                run.events.push(TwoEvent {
                    step: e.step,
                    kind: e.kind,
                    hands: e.hands,
                    mode,
                    held_by,
                    mode_before: before,
                    velocity,
                });
            }
        });
    }
    Ok(run)
}

impl TwoRun {
    /// The cube's first grasps and full releases as (time, grab or let go), and the index in
    /// `events` of each.
    pub fn holds(&self) -> (Vec<(f64, Hold)>, Vec<usize>) {
        let mut holds = Vec::new();
        let mut index = Vec::new();
        for (i, e) in self.events.iter().enumerate() {
            let h = if e.is_first_grasp() {
                Hold::Grab
            } else if e.is_full_release() {
                Hold::Let
            } else {
                continue;
            };
            holds.push((e.step as f64 * self.dt, h));
            index.push(i);
        }
        (holds, index)
    }

    /// Mean |dG| / dt of the cube and of the faster given hand over the [`AFTER_STEPS`] steps
    /// after step `step` (None: the run ends before).
    pub fn speeds_after(&self, step: u64) -> Option<(f64, f64)> {
        let e = usize::try_from(step).ok()?.checked_sub(1)?;
        if e + AFTER_STEPS >= self.block.len() {
            return None;
        }
        let n = AFTER_STEPS as f64;
        let cube = (1..=AFTER_STEPS)
            .map(|j| (self.block[e + j] - self.block[e + j - 1]).length())
            .sum::<f64>()
            / n
            / self.dt;
        let hand = (0..2)
            .map(|slot| {
                (1..=AFTER_STEPS)
                    .map(
                        |j| match (self.hand_g[e + j][slot], self.hand_g[e + j - 1][slot]) {
                            (Some(a), Some(b)) => (a - b).length(),
                            _ => 0.0,
                        },
                    )
                    .sum::<f64>()
                    / n
                    / self.dt
            })
            .fold(0.0, f64::max);
        Some((cube, hand))
    }
}

/// How one two-hand throw went.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct TwoOutcome {
    pub grasped: bool,
    pub both_held: bool,
    pub false_drops: u32,
    /// The final release's velocity (None: never let go).
    pub velocity: Option<DVec3>,
    pub lost: bool,
    /// Release events checked, and those that slingshot.
    pub releases: u32,
    pub slingshots: u32,
    /// A hand let go of the two-hand grasp (for "left first": the left) and the other kept
    /// the cube, with no drop, to the final release.
    pub kept_by_the_other: bool,
}

/// The true speed of the hands behind the world's hands at time `t`: the script's G speed,
/// its largest over the span the level's hands at `t` may stand for.
fn true_speed(throw: &Throw, level: &Level, t: f64) -> f64 {
    let gap = level.gaps.map_or(0.0, |g| g.max_s.max(g.min_s));
    let span = level.latency * 1.1 + 1.0 / level.rate_hz.max(1.0) + gap;
    let n = (span / 0.002).ceil().max(1.0) as usize;
    (0..=n)
        .map(|i| throw.g_speed((t - span * i as f64 / n as f64).max(0.0)))
        .fold(0.0, f64::max)
}

/// Scores one two-hand run of `throw`.
pub fn score(run: &TwoRun, throw: &Throw, level: &Level, kind: Kind) -> TwoOutcome {
    let interval = 1.0 / level.rate_hz.max(1.0);
    let (holds, index) = run.holds();
    let (o, pick) = throws::judge(&holds, throw.t_r, interval);
    let mut out = TwoOutcome {
        grasped: o.grasped,
        both_held: run.both_held,
        false_drops: o.false_drops,
        velocity: pick.map(|p| run.events[index[p]].velocity),
        lost: o.lost,
        ..TwoOutcome::default()
    };
    for e in run.events.iter().filter(|e| e.kind == EventKind::Release) {
        let Some((cube, hand)) = run.speeds_after(e.step) else {
            continue;
        };
        out.releases += 1;
        let t = e.step as f64 * run.dt;
        let hands = true_speed(throw, level, t).max(hand).max(SPEED_FLOOR);
        if cube > SLINGSHOT_RATIO * hands {
            out.slingshots += 1;
        }
    }
    let early = throw.t_r - interval;
    out.kept_by_the_other = run.events.iter().enumerate().any(|(i, e)| {
        let leaving = match kind {
            Kind::LeftFirst => e.hands == LEFT && e.held_by == RIGHT,
            Kind::Together => e.hands != 0 && e.held_by != 0,
        };
        leaving
            && e.is_partial_release()
            && run.events[i + 1..]
                .iter()
                .find(|x| x.is_full_release())
                .is_some_and(|x| x.step as f64 * run.dt >= early)
    });
    out
}

/// One (level, kind, rules) of the two-hand table.
#[derive(Debug, Clone)]
pub struct TwoRow {
    pub level: String,
    pub kind: Kind,
    pub rules: HandRules,
    pub throws: u32,
    /// Throws whose cube both hands held at once.
    pub both_held: u32,
    pub missed_grasps: u32,
    pub unreleased: u32,
    /// Throws with a final release velocity.
    pub scored: u32,
    pub speed_error_pct: Pct,
    pub direction_error_deg: Pct,
    pub false_drops: u32,
    /// Release events checked for slingshots, and the slingshots.
    pub releases: u32,
    pub slingshots: u32,
    pub kept_by_the_other: u32,
}

#[derive(Debug, Default)]
struct Tally {
    throws: u32,
    both_held: u32,
    missed: u32,
    unreleased: u32,
    false_drops: u32,
    releases: u32,
    slingshots: u32,
    kept: u32,
    speed: Vec<f64>,
    dir: Vec<f64>,
}

impl Tally {
    fn add(&mut self, o: &TwoOutcome, throw: &Throw) {
        self.throws += 1;
        self.both_held += u32::from(o.both_held);
        self.false_drops += o.false_drops;
        self.releases += o.releases;
        self.slingshots += o.slingshots;
        self.kept += u32::from(o.kept_by_the_other);
        if !o.grasped {
            self.missed += 1;
            return;
        }
        match o.velocity {
            None => self.unreleased += 1,
            Some(v) => {
                let (speed, dir) = throws::errors(v, throw.velocity());
                self.speed.push(speed);
                self.dir.push(dir);
            }
        }
    }

    fn row(&self, level: &str, kind: Kind, rules: HandRules) -> TwoRow {
        TwoRow {
            level: level.to_string(),
            kind,
            rules,
            throws: self.throws,
            both_held: self.both_held,
            missed_grasps: self.missed,
            unreleased: self.unreleased,
            scored: self.speed.len() as u32,
            speed_error_pct: Pct::of(&self.speed),
            direction_error_deg: Pct::of(&self.dir),
            false_drops: self.false_drops,
            releases: self.releases,
            slingshots: self.slingshots,
            kept_by_the_other: self.kept,
        }
    }
}

/// The rules measured, in the table's order.
pub const RULES: [HandRules; 2] = [HandRules::Tracked, HandRules::Paper];

/// Both hands' samples of `throw` at `level` for `kind`.
pub fn frames(
    throw: &Throw,
    level: &Level,
    level_index: usize,
    kind: Kind,
) -> (Vec<HandSample>, Vec<HandSample>) {
    let right = throws::degrade_hand(throw, level, level_index, SEED, None, |t| {
        throw.hand_of(Side::Right, t, throw.t_r)
    });
    let open = kind.left_opens(throw);
    let left = throws::degrade_hand(throw, level, level_index, SEED, Some(LEFT_SALT), |t| {
        throw.hand_of(Side::Left, t, open)
    });
    (right, left)
}

/// `count` two-hand throws of `kind` at `level`, under each of [`RULES`]: a row per rules.
pub fn one_kind(
    level: &Level,
    level_index: usize,
    kind: Kind,
    count: usize,
) -> Result<Vec<TwoRow>, String> {
    let scenes: Vec<Scene> = RULES.iter().map(|r| throws::scene(*r)).collect();
    let mut tallies: Vec<Tally> = RULES.iter().map(|_| Tally::default()).collect();
    for i in 0..count {
        let throw = Throw::new(SEED, i);
        let (right, left) = frames(&throw, level, level_index, kind);
        for (scene, tally) in scenes.iter().zip(&mut tallies) {
            let run = run_two(scene, &right, &left)?;
            tally.add(&score(&run, &throw, level, kind), &throw);
        }
    }
    Ok(RULES
        .iter()
        .zip(&tallies)
        .map(|(r, t)| t.row(level.name, kind, *r))
        .collect())
}

/// One (level, kind)'s rows, or why it could not run.
type KindResult = Result<Vec<TwoRow>, String>;

/// The two-hand part: [`LEVELS`] among `levels` (by index into [`throws::levels`]), each
/// [`Kind`], min(`count`, [`MAX_THROWS`]) throws, on up to `workers` threads; `progress` gets a
/// line per (level, kind) done.
pub fn measure(
    levels: &[(usize, Level)],
    count: usize,
    workers: usize,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<Vec<TwoRow>, String> {
    let count = count.clamp(1, MAX_THROWS);
    let jobs: Vec<(usize, &Level, Kind)> = LEVELS
        .iter()
        .filter_map(|name| levels.iter().find(|(_, l)| l.name == *name))
        .flat_map(|(i, l)| Kind::ALL.map(|k| (*i, l, k)))
        .collect();
    let next = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<KindResult>>> = Mutex::new(vec![None; jobs.len()]);
    let started = Instant::now();
    std::thread::scope(|s| {
        for _ in 0..workers.clamp(1, jobs.len().max(1)) {
            s.spawn(|| loop {
                let k = next.fetch_add(1, Ordering::SeqCst);
                let Some(&(index, level, kind)) = jobs.get(k) else {
                    break;
                };
                let t0 = Instant::now();
                let r = one_kind(level, index, kind, count);
                let n = done.fetch_add(1, Ordering::SeqCst) + 1;
                let line = match &r {
                    Ok(rows) => {
                        let figs: Vec<String> = rows
                            .iter()
                            .map(|r| {
                                format!(
                                    "{} p90 {} % {} deg, {} drops, {} slingshots",
                                    r.rules.name(),
                                    fmt(r.speed_error_pct.p90, 1),
                                    fmt(r.direction_error_deg.p90, 1),
                                    r.false_drops,
                                    r.slingshots
                                )
                            })
                            .collect();
                        format!(
                            "[{n}/{}] {} {}: {count} throws, {} ({:.1} s, {:.0} s so far)",
                            jobs.len(),
                            level.name,
                            kind.name(),
                            figs.join(", "),
                            t0.elapsed().as_secs_f64(),
                            started.elapsed().as_secs_f64()
                        )
                    }
                    Err(e) => format!(
                        "[{n}/{}] {} {}: failed: {e}",
                        jobs.len(),
                        level.name,
                        kind.name()
                    ),
                };
                progress(&line);
                if let Ok(mut all) = results.lock() {
                    all[k] = Some(r);
                }
            });
        }
    });
    let all = results
        .into_inner()
        .map_err(|_| "a worker thread panicked".to_string())?;
    let mut rows = Vec::new();
    for r in all {
        rows.extend(r.ok_or("a two-hand level was not run")??);
    }
    Ok(rows)
}

/// `hands.json`'s row of the two-hand table.
pub fn row_json(r: &TwoRow) -> Value {
    json!({
        "level": r.level,
        "kind": r.kind.name(),
        "rules": r.rules.name(),
        "throws": r.throws,
        "both_held": r.both_held,
        "missed_grasps": r.missed_grasps,
        "unreleased": r.unreleased,
        "scored": r.scored,
        "speed_error_pct": pct_json(&r.speed_error_pct),
        "direction_error_deg": pct_json(&r.direction_error_deg),
        "false_drops": r.false_drops,
        "releases": r.releases,
        "slingshots": r.slingshots,
        "kept_by_the_other": r.kept_by_the_other,
    })
}

/// The "0 slingshots" goal's verdict and figures (None: no two-hand row ran).
pub fn slingshot_goal(rows: &[TwoRow]) -> Option<(bool, String)> {
    if rows.is_empty() {
        return None;
    }
    let slingshots: u32 = rows.iter().map(|r| r.slingshots).sum();
    let releases: u32 = rows.iter().map(|r| r.releases).sum();
    let throws: u32 = rows.iter().map(|r| r.throws).sum();
    let mut levels: Vec<&str> = Vec::new();
    for r in rows {
        if !levels.contains(&r.level.as_str()) {
            levels.push(&r.level);
        }
    }
    Some((
        slingshots == 0,
        format!(
            "{slingshots} slingshots in {releases} two-hand release events ({throws} runs: {}; together and left first; tracked and paper)",
            levels.join(", ")
        ),
    ))
}

/// `hands.md`'s two-hand section.
pub fn markdown(rows: &[TwoRow]) -> String {
    let mut s = String::from("## Two hands: throws and slingshots\n\n");
    if rows.is_empty() {
        s.push_str("Not measured: none of the levels ideal, quest, worst ran.\n\n");
        return s;
    }
    let _ = writeln!(
        s,
        "The same scripted throws with the cube held by both hands of one world \
(docs/model.md \"Two hands\"): the right picks the cube up as above (a pinch across the wrist \
frame's x faces); the left, on the same wrist, joins during the lift (at {:.2}-{:.2} s, the cube \
5 cm up or more: its open fingers slide in along the wrist's z, then close in 120 ms as the \
right's do) with its fingertips on the y faces (thumb on +y, index and middle on -y, each \
finger square to its face, tips 4 mm inside). **together**: both open at t_r; **left first**: the \
left opens {:.0} ms before t_r (in the wind-up, or the hold before it) and the right holds on \
to t_r. Each hand is degraded on its own at the level (its own noise, gaps and latency \
jitter; the right draws as the one-hand throws' hand), frames pair the two hands' samples \
of one time, and a `stepper::World` takes them through `Timeline::advance_hands` and \
`World::step_hands`. The speed and direction errors are the final release's (every holder let \
go) against G's velocity at t_r; a false drop is a full release before t_r minus one sample \
interval (a hand leaving a grasp the other keeps is none). A **slingshot** is a release event \
(partial or final) after which the cube's mean speed over the next {AFTER_STEPS} steps is \
over {SLINGSHOT_RATIO} times the hands': the larger of the script's true G speed over the \
time the world's hands at the event may stand for (the level's latency +10 %, one sample \
interval and its longest gap), the faster given hand's speed over those steps, and \
{SPEED_FLOOR} m/s. *kept by the other*: runs in which a hand let go of the two-hand grasp \
(left first: the left) and the other kept the cube, undropped, to the final release \
(expected: every left-first run). *both held*: runs whose cube both hands held at once.\n",
        throws::LEFT_CLOSE_START,
        throws::LEFT_CLOSE_END,
        LEFT_FIRST_S * 1e3
    );
    s.push_str(
        "| level | kind | rules | speed err p50 / p90 (%) | direction err p50 / p90 (deg) | false drops | slingshots / release events | kept by the other | both held | scored / throws | missed grasps | never released |\n|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for r in rows {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} / {} | {} / {} | {} | {} / {} | {} | {} | {} / {} | {} | {} |",
            r.level,
            r.kind.name(),
            r.rules.name(),
            fmt(r.speed_error_pct.p50, 1),
            fmt(r.speed_error_pct.p90, 1),
            fmt(r.direction_error_deg.p50, 1),
            fmt(r.direction_error_deg.p90, 1),
            r.false_drops,
            r.slingshots,
            r.releases,
            r.kept_by_the_other,
            r.both_held,
            r.scored,
            r.throws,
            r.missed_grasps,
            r.unreleased
        );
    }
    s.push('\n');
    s
}

/// The JSON of a list of rows (for `hands.json`).
pub fn rows_json(rows: &[TwoRow]) -> Value {
    Value::Array(rows.iter().map(row_json).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ideal() -> (usize, Level) {
        let all = throws::levels();
        let i = all.iter().position(|l| l.name == "ideal").expect("ideal");
        (i, all[i].clone())
    }

    #[test]
    fn two_hand_ideal_throws_neither_slingshot_nor_drop() {
        let (index, level) = ideal();
        for kind in Kind::ALL {
            for rules in RULES {
                let scene = throws::scene(rules);
                for i in 0..6 {
                    let throw = Throw::new(SEED, i);
                    let (right, left) = frames(&throw, &level, index, kind);
                    let run = run_two(&scene, &right, &left).expect("world");
                    let o = score(&run, &throw, &level, kind);
                    let what = format!(
                        "{} {} throw {i}: {:?}",
                        kind.name(),
                        rules.name(),
                        run.events
                    );
                    assert!(o.grasped && o.both_held, "{what}");
                    assert_eq!(o.false_drops, 0, "{what}");
                    assert_eq!(o.slingshots, 0, "{what}");
                    assert!(o.releases >= 1, "{what}");
                    let v = o.velocity.expect("released");
                    let (speed, dir) = throws::errors(v, throw.velocity());
                    assert!(speed < 15.0 && dir < 15.0, "{what}: {speed} % {dir} deg");
                    if kind == Kind::LeftFirst {
                        assert!(o.kept_by_the_other, "{what}");
                    }
                }
            }
        }
    }

    #[test]
    fn the_left_hand_joins_clear_of_the_cube_and_above_the_floor() {
        for i in 0..10 {
            let th = Throw::new(SEED, i);
            let mut t = 0.0;
            while t < th.t_r {
                let h = th.hand_of(Side::Left, t, th.t_r);
                let (g, rot) = th.pose(t);
                for f in 0..3 {
                    for (j, p) in h.finger_points[f][..3].iter().enumerate() {
                        let p = DVec3::from_array(*p);
                        // In the cube's frame (the cube where the script holds it: at G).
                        let local = rot.inverse() * (p - g);
                        let half = throws::CUBE / 2.0;
                        let inside = local.abs().max_element() < half;
                        // Before it closes, no left point is in the cube; from the slide on,
                        // no fingertip is below the floor.
                        if t < throws::LEFT_CLOSE_START {
                            assert!(!inside, "throw {i} at {t}: {local}");
                        }
                        if t >= throws::LEFT_SLIDE_START && j == 2 {
                            assert!(p.y > 0.0, "throw {i} at {t}: {p}");
                        }
                    }
                }
                t += 0.001;
            }
            // Held, the fingertips are GRIP_DEPTH inside the y faces, moving with G.
            let t = th.t_r - 0.01;
            let h = th.hand_of(Side::Left, t, th.t_r);
            let (g, rot) = th.pose(t);
            let depth = throws::CUBE / 2.0 - throws::GRIP_DEPTH;
            for (f, sign) in [(0, 1.0), (1, -1.0), (2, -1.0)] {
                let local = rot.inverse() * (DVec3::from_array(h.finger_points[f][2]) - g);
                assert!((local.y - sign * depth).abs() < 1e-9, "{f}: {local}");
                assert!(local.x.abs() < 1e-9, "{f}: {local}");
            }
        }
    }

    #[test]
    fn the_right_hand_is_the_one_hand_throws_hand() {
        let (index, level) = ideal();
        let th = Throw::new(SEED, 3);
        let (right, _) = frames(&th, &level, index, Kind::LeftFirst);
        let one = throws::degrade(&th, &level, index, SEED);
        assert_eq!(right.len(), one.len());
        assert!(right
            .iter()
            .zip(&one)
            .all(|(a, b)| a.finger_points == b.finger_points && a.wrist == b.wrist));
    }
}
