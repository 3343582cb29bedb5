//! `handblocks bench stepper`: what one step costs as the world grows, under both models in the
//! same run, and what each effect of `[effects]` costs when it is on and when it is off.
//!
//! * **Scaling**: fields of N cubes (4 cm, on an 8 cm grid, so that only what a situation makes
//!   touch touches) in three situations: `falling` (a rain: every cube dropped from 0.6 to
//!   1.2 m, timed over its first 0.5 s: all falling, then the lowest landing), `resting` (the
//!   settled field, timed after a second of settling) and `hand` (one bare check point sweeps
//!   along the middle row at cube height, pushing the few it meets). Every step is timed on its
//!   own; p50 and p99 over the timed runs, the mean count of blocks not resting ("active"),
//!   the time per active block, the fitted exponent of time against N (least squares on
//!   log-log), and the precise contenders' time as a ratio to the paper model's, taken round by
//!   round (median [min, max] over the rounds). The timed runs are interleaved: a round goes
//!   round the sizes and, within a size, round the contenders (paper, precise, precise-cheap,
//!   then the next size, ...), so the machine's slow spells fall on every model and size alike,
//!   and the two runs a ratio compares are seconds apart.
//! * **Contenders**: the paper model; the precise one at its `[precise]` defaults (the
//!   reference of `bench accuracy`: 8 substeps, sleeping off, because sleeping would freeze a
//!   block tipping slowly); and the precise one at the cheapest setting that keeps a settled
//!   field still (`precise-cheap`: the least solver work, over substeps, solver iterations,
//!   sleeping and CCD, with which a settled pyramid of cubes, block on block, stands and
//!   neither moves nor turns: [`cheapest_still`], found in the same run, not chosen by hand).
//! * **The wrapper's share**: a precise step is rapier's `PhysicsPipeline::step` plus our
//!   wrapper around it (the hand's colliders, the choice of bullets, the modes and events);
//!   the world times the pipeline call itself ([`stepper::PreciseWorld::pipeline_ns`]), so
//!   each precise row also gives the wrapper's time per step (p50) and its share of the whole
//!   step (its time over all timed steps over theirs): the precise model is charged for rapier,
//!   and what is ours shows.
//! * **Ablation**: per effect, on and off, 9 runs each (`--quick`: 5), interleaved (on, off,
//!   on, off, ...); the median, min and max of each side's time per step, and of the
//!   differences of the pairs of runs (run k on - run k off: back to back, so that a slow
//!   moment of the machine falls on both). An effect's cost is within noise when the pairs'
//!   differences are not all of one sign, beyond what one reading of the clock costs
//!   (measured in the run: a difference below it is below what the timing resolves); by
//!   chance, all 9 fall on one side 0.4 % of the time. `noise_us`: half the pairs' max - min,
//!   at least that reading. Two cases per effect: `work`, a scene of
//!   `config/scenes/` the effect acts in (on - off is the effect's work; the two sides do
//!   different things), and `idle`, the idle field (64 resting cubes, a hand 5 m away), timed
//!   after a settling second (its first step is work: the first impacts, every block judged
//!   once), where the effect has nothing to do and turning it off changes no pose (a test
//!   checks it), so on - off is what its pass costs just by being in the step. An effect that is off is left
//!   out of the step's pass list (`Passes`): off runs none of its code, and an idle pass that
//!   costs more than noise is work the broad phase should have skipped.
//!
//! Sizes over the scene limit (`common::MAX_SCENE_BLOCKS`) would be listed as not run, with
//! the reason, rather than left out silently, and the limit itself measured in their place.
//! Every size here also runs in a live session (the world topic is sized from the scene:
//! `config/sessions/field-1024.toml` is the 1024-block one).
//!
//! Writes `stepper.json`, `stepper.md` and `stepper.png` (time per step against N, log-log)
//! under `--out`.

use std::path::{Path, PathBuf};
use std::time::Instant;

use common::config::scene::{
    BlockSpec, Effects, FloorEffect, HandEffect, HandKey, HandPoseSpec, HandScript, ModelKind,
    PreciseSettings, ShapeSpec, Stacking, WorldSettings,
};
use common::config::Scene;
use common::{BlockMode, HandSample, MAX_SCENE_BLOCKS};
use serde_json::{json, Value};

use crate::page::num;
use stepper::{BareFingersHand, Model};

use crate::page::{self, Provenance};
use crate::plot::{Axis, Figure, Join, Panel, Series};

/// `handblocks bench stepper`'s options.
pub struct StepperBench {
    pub out_dir: PathBuf,
    /// Sizes up to 64 blocks, 2 timed runs (5 otherwise), 5 ablation runs a side (9).
    pub quick: bool,
    /// Whole runs of the scaling part (each every size, situation and round from the start):
    /// a published ratio is the median of the runs' medians, with the run-to-run spread.
    pub runs: usize,
}

/// The sizes the scaling part asks for.
pub const SIZES: [usize; 5] = [16, 64, 256, 1024, 4096];
const QUICK_SIZES: usize = 2;

/// A scaling situation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Situation {
    Falling,
    Resting,
    Hand,
}

impl Situation {
    pub const ALL: [Situation; 3] = [Situation::Falling, Situation::Resting, Situation::Hand];

    pub fn name(self) -> &'static str {
        match self {
            Situation::Falling => "falling",
            Situation::Resting => "resting",
            Situation::Hand => "hand",
        }
    }

    /// Untimed steps before the timed ones: the settled field is timed settled (1 s: a
    /// precise model that sleeps has put it to sleep by then; the paper model rests it at
    /// once); the others from their start.
    fn settle(self) -> u64 {
        match self {
            Situation::Resting => 120,
            _ => 0,
        }
    }

    /// Steps a run times (at 120 Hz): the rain's first 0.5 s (every cube in the air until the
    /// lowest land from 0.35 s on: p50 is a step of falling, p99 one of landing), the sweep's
    /// 1 s and a little more.
    fn steps(self) -> u64 {
        match self {
            Situation::Falling => 60,
            Situation::Resting => 60,
            Situation::Hand => 132,
        }
    }
}

/// One (model, situation, N) of the scaling part.
#[derive(Debug, Clone)]
pub struct ScalingRow {
    pub model: &'static str,
    pub situation: Situation,
    pub blocks: usize,
    /// Mean number of blocks not resting after a step.
    pub active: f64,
    pub us_per_step_p50: f64,
    pub us_per_step_p99: f64,
    /// The precise model's wrapper: its time per step (p50, us) and its share of the step
    /// (its time over all timed steps over theirs); NaN for the paper model.
    pub wrapper_us_p50: f64,
    pub wrapper_share: f64,
    /// The p50 of each timed round (us), in round order: the ratio of two contenders is taken
    /// round by round ([`round_ratios`]).
    pub round_p50: Vec<f64>,
}

/// One effect's on/off pair.
#[derive(Debug, Clone)]
pub struct AblationRow {
    pub model: &'static str,
    /// e.g. `gravity`, `floor: tipping -> rest`.
    pub effect: String,
    /// `work`: a scene the effect acts in; `idle`: the idle field, where it has nothing to do
    /// (turning it off changes no pose), so `on - off` is what the pass costs by being there.
    pub case: &'static str,
    /// The scene both sides run.
    pub scene: String,
    pub on: Spread,
    pub off: Spread,
    /// `on - off` of each pair of runs (run k of on against run k of off, back to back).
    pub diff: Spread,
    /// Half the paired differences' max - min, at least what one reading of the clock costs.
    pub noise_us: f64,
    /// What one reading of the clock costs here (us).
    pub clock_us: f64,
}

/// Median, min and max of a side's time per step over its runs (microseconds).
#[derive(Debug, Clone, Copy)]
pub struct Spread {
    pub median: f64,
    pub min: f64,
    pub max: f64,
}

impl Spread {
    fn of(mut v: Vec<f64>) -> Spread {
        if v.is_empty() {
            return Spread {
                median: f64::NAN,
                min: f64::NAN,
                max: f64::NAN,
            };
        }
        v.sort_by(f64::total_cmp);
        Spread {
            median: v[v.len() / 2],
            min: v[0],
            max: v[v.len() - 1],
        }
    }
}

impl AblationRow {
    /// Whether on and off are indistinguishable here: the paired runs' differences do not all
    /// lie on one side of zero (beyond what the clock resolves). Pairs, not each side's spread:
    /// a slow spell of the machine falls on both runs of a pair, and the two sides' medians
    /// of separate runs differed by more than half a side's spread on the precise model's
    /// tipping -> rest idle row, where both sides run the same code (rapier has no "rest").
    /// A difference of one sign in all 9 pairs happens by chance 0.4 % of the time.
    pub fn within_noise(&self) -> bool {
        self.diff.min - self.clock_us <= 0.0 && self.diff.max + self.clock_us >= 0.0
    }
}

const CUBE: f64 = 0.04;
const PITCH: f64 = 0.08;

fn cube(name: String, x: f64, y: f64, z: f64) -> BlockSpec {
    BlockSpec {
        name,
        shape: ShapeSpec::Box { size: [CUBE; 3] },
        position: [x, y, z],
        rotation: [0.0, 0.0, 0.0, 1.0],
        velocity: [0.0; 3],
    }
}

/// A scene of `n` cubes on a square grid centred on the origin, in `situation`.
pub fn field(n: usize, situation: Situation, model: ModelKind) -> Scene {
    let side = (n as f64).sqrt().ceil() as usize;
    let half = (side as f64 - 1.0) * PITCH / 2.0;
    let blocks = (0..n)
        .map(|i| {
            let (row, col) = (i / side, i % side);
            let (x, z) = (col as f64 * PITCH - half, row as f64 * PITCH - half);
            // The rain: heights spread over 0.6-1.2 m by a fixed scramble of the index, so
            // landings spread over the run's end.
            let y = match situation {
                Situation::Falling => 0.6 + 0.6 * ((i * 7919) % 97) as f64 / 96.0,
                _ => CUBE / 2.0,
            };
            cube(format!("b{i}"), x, y, z)
        })
        .collect();
    let hand = (situation == Situation::Hand).then(|| {
        // One check point along the middle row (z of row side/2), at the cubes' mid-height,
        // 2 cm off their centre line, from beyond one end to beyond the other in 1 s.
        let z = (side / 2) as f64 * PITCH - half + 0.01;
        let key = |t: f64, x: f64| HandKey {
            t,
            wrist: [x, CUBE / 2.0, z],
            wrist_rotation: [0.0, 0.0, 0.0, 1.0],
            pose: HandPoseSpec::Fingers(vec![vec![[0.0; 3]]]),
        };
        HandScript {
            keys: vec![key(0.0, -half - PITCH), key(1.0, half + PITCH)],
        }
    });
    Scene {
        file: PathBuf::from(format!("<bench stepper: {} x{n}>", situation.name())),
        world: WorldSettings {
            model,
            ..WorldSettings::default()
        },
        effects: Effects {
            hand: HandEffect::Push,
            ..Effects::default()
        },
        blocks,
        hand,
        left_hand: None,
    }
}

/// What [`run_steps`] measured: each timed step's time (us), for the precise model each timed
/// step's wrapper time (us: the step less rapier's pipeline call; empty for the paper model),
/// and the mean count of blocks not resting.
struct Timed {
    times: Vec<f64>,
    wrapper: Vec<f64>,
    active: f64,
}

/// Nanoseconds a precise world has spent in rapier's pipeline so far (None: the paper model).
fn pipeline_ns(model: &Model) -> Option<u64> {
    match model {
        Model::Precise(w) => Some(w.pipeline_ns()),
        _ => None,
    }
}

/// Times `steps` steps of `scene`, each on its own, after `settle` untimed ones; with
/// `count_active`, also the mean count of blocks not resting (else 0). The count is a pass
/// over every block between two steps: a timed run leaves it out, so that the bench's own
/// bookkeeping does not sweep the step's data out of the caches before each timed step (at
/// 4096 blocks that pass reads ~0.8 MB, more than this machine's L2); it is the same in every
/// run (the model is deterministic), so the untimed warm-up counts it. Under the precise model
/// the wrapper's time is the step's less what the world's own clock put on rapier's pipeline
/// call inside it (two readings of a counter around the timed call, outside it).
fn run_steps(scene: &Scene, settle: u64, steps: u64, count_active: bool) -> Result<Timed, String> {
    let mut model = Model::new(scene).map_err(|e| format!("{}: {e}", scene.file.display()))?;
    let hand = BareFingersHand::from_scene(scene);
    let dt = 1.0 / scene.world.step_hz;
    let sample = |k: u64| -> Option<HandSample> { hand.as_ref().map(|h| h.sample(k as f64 * dt)) };
    model.set_previous_hand(sample(0).as_ref());
    for k in 1..=settle {
        model.step(sample(k).as_ref());
    }
    let mut times = Vec::with_capacity(steps as usize);
    let mut wrapper = Vec::with_capacity(steps as usize);
    let mut active = 0usize;
    for k in settle + 1..=settle + steps {
        let h = sample(k);
        let before = pipeline_ns(&model);
        let t0 = Instant::now();
        model.step(h.as_ref());
        let us = t0.elapsed().as_secs_f64() * 1e6;
        times.push(us);
        if let (Some(a), Some(b)) = (before, pipeline_ns(&model)) {
            wrapper.push(us - b.saturating_sub(a) as f64 * 1e-3);
        }
        if count_active {
            active += (0..model.block_count())
                .filter(|&i| model.block(i).is_some_and(|b| b.mode != BlockMode::Resting))
                .count();
        }
    }
    Ok(Timed {
        times,
        wrapper,
        active: active as f64 / steps.max(1) as f64,
    })
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let k = ((sorted.len() as f64 - 1.0) * p).round() as usize;
    sorted[k.min(sorted.len() - 1)]
}

fn model_name(m: ModelKind) -> &'static str {
    match m {
        ModelKind::Paper => "paper",
        ModelKind::Precise => "precise",
    }
}

/// A model at one setting: the paper model, the precise one at its `[precise]` defaults (the
/// reference, sleeping off), or the precise one at the cheapest setting that keeps a settled
/// field still ([`cheapest_still`]).
#[derive(Debug, Clone, Copy)]
pub struct Contender {
    pub name: &'static str,
    pub model: ModelKind,
    pub precise: Option<PreciseSettings>,
}

impl Contender {
    pub const PAPER: Contender = Contender {
        name: "paper",
        model: ModelKind::Paper,
        precise: None,
    };
    pub const PRECISE: Contender = Contender {
        name: "precise",
        model: ModelKind::Precise,
        precise: None,
    };

    fn apply(&self, scene: &mut Scene) {
        scene.world.model = self.model;
        if let Some(p) = self.precise {
            scene.world.precise = p;
        }
    }
}

/// Substeps, solver iterations per substep, sleeping and CCD tried for the cheap precise
/// setting (every combination: 48).
const CHEAP_SUBSTEPS: [u32; 4] = [1, 2, 4, 8];
const CHEAP_ITERATIONS: [u32; 3] = [1, 2, 4];
const CHEAP_SLEEP: [bool; 2] = [true, false];
const CHEAP_CCD: [bool; 2] = [false, true];
/// "Still": no cube of the settled field moves more than this over its second second...
pub const STILL_M: f64 = 1e-5;
/// ... nor turns more than this (rad): a turn that moves a 4 cm cube's corner by `STILL_M`.
pub const STILL_RAD: f64 = STILL_M / (CUBE * 0.866_025_403_784_438_6);
/// "Stands": over its first second no cube drifts more than a quarter of its size from where it
/// was built nor turns more than 5 degrees (a pyramid that falls apart moves its cubes by
/// their size; a soft contact's sag is millimetres).
pub const STAND_M: f64 = CUBE / 4.0;
pub const STAND_RAD: f64 = 5.0 * std::f64::consts::PI / 180.0;
/// Rows of the judged pyramid: 8 cubes at its base, 36 in all.
const PYRAMID_ROWS: usize = 8;

/// The field the cheap setting is judged on: a pyramid of 4 cm cubes, 8 at its base, each row
/// one fewer and shifted half a cube, every cube face to face with its neighbours in the row
/// and on the two below it (block on block, and on the floor): what a settled field of stacked
/// blocks asks of the solver, where a field of cubes apart from each other asks only the
/// floor (and answered 1 substep whatever the solver did between blocks).
pub fn pyramid_field() -> Scene {
    let mut blocks = Vec::new();
    for row in 0..PYRAMID_ROWS {
        let count = PYRAMID_ROWS - row;
        let x0 = -(count as f64 - 1.0) * CUBE / 2.0;
        for k in 0..count {
            blocks.push(cube(
                format!("p{row}_{k}"),
                x0 + k as f64 * CUBE,
                CUBE / 2.0 + row as f64 * CUBE,
                0.0,
            ));
        }
    }
    Scene {
        file: PathBuf::from(format!(
            "<bench stepper: pyramid of {} cubes>",
            blocks.len()
        )),
        world: WorldSettings {
            model: ModelKind::Precise,
            ..WorldSettings::default()
        },
        effects: Effects::default(),
        blocks,
        hand: None,
        left_hand: None,
    }
}

/// One setting tried for the cheap precise setting, and what it did on the pyramid.
#[derive(Debug, Clone, Copy)]
pub struct CheapTry {
    pub substeps: u32,
    pub solver_iterations: u32,
    pub sleep: bool,
    pub ccd: bool,
    /// Over the first second: the largest drift of a cube from where it was built (m), its
    /// largest turn (rad), and the largest drop (the contacts' give, m).
    pub drift_m: f64,
    pub drift_rad: f64,
    pub sag_m: f64,
    /// Over the second second: the largest move of a cube (m) and its largest turn (rad).
    pub moved_m: f64,
    pub turned_rad: f64,
    /// Mean time per step over the two seconds (us), for the record: the choice does not read
    /// it (see [`cheapest_still`]).
    pub us_per_step: f64,
}

impl CheapTry {
    /// A setting not tried yet: its figures are NaN until [`try_cheap`] measures them.
    fn untried(substeps: u32, solver_iterations: u32, sleep: bool, ccd: bool) -> CheapTry {
        CheapTry {
            substeps,
            solver_iterations,
            sleep,
            ccd,
            drift_m: f64::NAN,
            drift_rad: f64::NAN,
            sag_m: f64::NAN,
            moved_m: f64::NAN,
            turned_rad: f64::NAN,
            us_per_step: f64::NAN,
        }
    }
}

impl CheapTry {
    /// The pyramid stood through its first second and was still through its second.
    pub fn still(&self) -> bool {
        self.drift_m <= STAND_M
            && self.drift_rad <= STAND_RAD
            && self.moved_m <= STILL_M
            && self.turned_rad <= STILL_RAD
    }

    /// The solver's work per step, as rapier's step scales with it: substeps times iterations.
    fn work(&self) -> u32 {
        self.substeps * self.solver_iterations
    }

    /// The order of cheapness: the least solver work; then fewer substeps (a substep also
    /// integrates and refreshes the contacts, an iteration only solves); then sleeping (a
    /// sleeping body costs nothing) and no CCD (no bullets to choose, no sweeps), which never
    /// add work.
    fn cost_key(&self) -> (u32, u32, bool, bool) {
        (self.work(), self.substeps, !self.sleep, self.ccd)
    }

    fn settings(&self) -> PreciseSettings {
        PreciseSettings {
            substeps: self.substeps,
            solver_iterations: self.solver_iterations,
            sleep: self.sleep,
            ccd: self.ccd,
            ..PreciseSettings::default()
        }
    }
}

/// Runs the pyramid two seconds under `t`'s setting and fills in what it did.
fn try_cheap(mut t: CheapTry) -> Result<CheapTry, String> {
    let mut scene = pyramid_field();
    scene.world.precise = t.settings();
    let mut model = Model::new(&scene).map_err(|e| format!("{}: {e}", scene.file.display()))?;
    let poses = |m: &Model| -> Vec<(glam::DVec3, glam::DQuat)> {
        (0..m.block_count())
            .filter_map(|i| m.block(i).map(|b| (b.position, b.rotation)))
            .collect()
    };
    let start = poses(&model);
    let second = scene.world.step_hz.round() as u64;
    let t0 = Instant::now();
    for _ in 0..second {
        model.step(None);
    }
    let settled = poses(&model);
    for _ in 0..second {
        model.step(None);
    }
    t.us_per_step = t0.elapsed().as_secs_f64() * 1e6 / (2 * second) as f64;
    let end = poses(&model);
    let worst = |a: &[(glam::DVec3, glam::DQuat)], b: &[(glam::DVec3, glam::DQuat)]| {
        a.iter().zip(b).fold((0.0f64, 0.0f64), |(m, r), (p, q)| {
            (m.max((q.0 - p.0).length()), r.max(q.1.angle_between(p.1)))
        })
    };
    // A cube lost from the model (a count that differs) fails every test below.
    let lost = if start.len() == scene.blocks.len() && end.len() == start.len() {
        0.0
    } else {
        f64::INFINITY
    };
    (t.drift_m, t.drift_rad) = worst(&start, &settled);
    (t.moved_m, t.turned_rad) = worst(&settled, &end);
    t.drift_m += lost;
    t.moved_m += lost;
    t.sag_m = start
        .iter()
        .zip(&settled)
        .map(|(a, b)| a.0.y - b.0.y)
        .fold(0.0, f64::max);
    Ok(t)
}

/// The precise model's cheapest setting that keeps a settled field still: every combination
/// of substeps, solver iterations, sleeping and CCD ([`CHEAP_SUBSTEPS`] ...) runs the 36-cube
/// pyramid ([`pyramid_field`]) for two seconds; a setting keeps it still when it stood through
/// the first second ([`STAND_M`], [`STAND_RAD`]) and no cube moved more than [`STILL_M`] nor
/// turned more than [`STILL_RAD`] over the second. Of those, the cheapest by the solver work
/// it asks for ([`CheapTry::cost_key`]), not by the clock: on this shared machine two runs'
/// timings differ by more than neighbouring settings' costs, and a settled field that sleeps
/// costs next to nothing whatever its substeps, so a timed choice would pick by noise (each
/// setting's time is reported beside it). Bounded: 48 runs of 240 steps of 36 cubes, a few
/// seconds. Returns the setting and every setting's record ([`Cheap`]).
pub fn cheapest_still() -> Result<(PreciseSettings, Cheap), String> {
    let mut tried = Vec::new();
    for substeps in CHEAP_SUBSTEPS {
        for solver_iterations in CHEAP_ITERATIONS {
            for sleep in CHEAP_SLEEP {
                for ccd in CHEAP_CCD {
                    tried.push(try_cheap(CheapTry::untried(
                        substeps,
                        solver_iterations,
                        sleep,
                        ccd,
                    ))?);
                }
            }
        }
    }
    let best = tried
        .iter()
        .filter(|t| t.still())
        .min_by_key(|t| t.cost_key())
        .copied();
    match best {
        Some(chosen) => Ok((chosen.settings(), Cheap { chosen, tried })),
        None => Err(format!(
            "no setting tried keeps a settled pyramid still: {}",
            tried
                .iter()
                .map(CheapTry::describe)
                .collect::<Vec<_>>()
                .join("; ")
        )),
    }
}

impl CheapTry {
    /// e.g. `2 x 1, sleep on, ccd off: moved 3.1e-7 m, turned 2.0e-6 rad (drift 1.2 mm)`.
    pub fn describe(&self) -> String {
        format!(
            "{} x {}, sleep {}, ccd {}: moved {:.1e} m, turned {:.1e} rad (first second: drift {:.2} mm, {:.2} deg)",
            self.substeps,
            self.solver_iterations,
            if self.sleep { "on" } else { "off" },
            if self.ccd { "on" } else { "off" },
            self.moved_m,
            self.turned_rad,
            self.drift_m * 1e3,
            self.drift_rad.to_degrees()
        )
    }
}

/// The scaling rows of every contender in one situation, one per (contender, size). Each
/// (size, contender) is warmed up once; then each round goes round the sizes and, within a
/// size, round the contenders (paper, precise, precise-cheap, then the next size, ...), so that
/// a slow minute of this shared machine falls on every model and every size alike rather than
/// on the one being timed then (timing the models one after the other, the machine's speed
/// drifted by a third between them; timing the sizes one after the other, a slow spell during
/// the 4096 field's runs alone moved the fitted exponent by several hundredths). Each row keeps
/// its p50 of each round, so that the ratio of two contenders is known per round, from runs
/// seconds apart.
fn scaling_rows(
    contenders: &[Contender],
    situation: Situation,
    sizes: &[usize],
    runs: usize,
) -> Result<Vec<ScalingRow>, String> {
    let (settle, steps) = (situation.settle(), situation.steps());
    // Indexed [size][contender].
    let mut scenes = Vec::with_capacity(sizes.len() * contenders.len());
    let mut active = Vec::with_capacity(sizes.len() * contenders.len());
    for &n in sizes {
        for c in contenders {
            let mut scene = field(n, situation, c.model);
            c.apply(&mut scene);
            // The warm-up, and the count of active blocks (the same in every run).
            active.push(run_steps(&scene, settle, steps, true)?.active);
            scenes.push(scene);
        }
    }
    let mut all: Vec<Vec<f64>> = vec![Vec::new(); scenes.len()];
    let mut wrapper: Vec<Vec<f64>> = vec![Vec::new(); scenes.len()];
    let mut rounds: Vec<Vec<f64>> = vec![Vec::with_capacity(runs); scenes.len()];
    for _ in 0..runs {
        for (k, scene) in scenes.iter().enumerate() {
            let mut t = run_steps(scene, settle, steps, false)?;
            all[k].extend_from_slice(&t.times);
            wrapper[k].extend(t.wrapper);
            t.times.sort_by(f64::total_cmp);
            rounds[k].push(percentile(&t.times, 0.5));
        }
    }
    let mut rows = Vec::with_capacity(scenes.len());
    for (k, ((times, wrapper), round_p50)) in all
        .iter_mut()
        .zip(wrapper.iter_mut())
        .zip(rounds)
        .enumerate()
    {
        let (n, c) = (
            sizes[k / contenders.len()],
            contenders[k % contenders.len()],
        );
        let total: f64 = times.iter().sum();
        let share = if wrapper.is_empty() || total <= 0.0 {
            f64::NAN
        } else {
            wrapper.iter().sum::<f64>() / total
        };
        times.sort_by(f64::total_cmp);
        wrapper.sort_by(f64::total_cmp);
        rows.push(ScalingRow {
            model: c.name,
            situation,
            blocks: n,
            active: active[k],
            us_per_step_p50: percentile(times, 0.5),
            us_per_step_p99: percentile(times, 0.99),
            wrapper_us_p50: percentile(wrapper, 0.5),
            wrapper_share: share,
            round_p50,
        });
    }
    Ok(rows)
}

/// `model`'s p50 over the paper model's, round by round (the two timed seconds apart in each
/// round), for one (situation, N): the ratios, in round order, and their median [min, max].
pub fn round_ratios(
    rows: &[ScalingRow],
    model: &str,
    situation: Situation,
    blocks: usize,
) -> Option<(Vec<f64>, Spread)> {
    let get = |m: &str| {
        rows.iter()
            .find(|r| r.model == m && r.situation == situation && r.blocks == blocks)
    };
    let (p, q) = (get("paper")?, get(model)?);
    let ratios: Vec<f64> = p
        .round_p50
        .iter()
        .zip(&q.round_p50)
        .filter(|(p, _)| **p > 0.0)
        .map(|(p, q)| q / p)
        .collect();
    (!ratios.is_empty()).then(|| (ratios.clone(), Spread::of(ratios)))
}

/// `model`'s ratio to the paper model for one (situation, N) over the whole runs: each run's
/// median over its rounds ([`round_ratios`]), and their median [min, max over the runs].
pub fn ratio_across_runs(
    r: &Report,
    model: &str,
    situation: Situation,
    blocks: usize,
) -> Option<(Vec<f64>, Spread)> {
    let per_run: Vec<f64> = r
        .scaling_runs
        .iter()
        .filter_map(|rows| round_ratios(rows, model, situation, blocks).map(|(_, s)| s.median))
        .collect();
    (!per_run.is_empty()).then(|| (per_run.clone(), Spread::of(per_run)))
}

/// The least-squares slope of ln(p50) on ln(N) over the rows of one (model, situation).
pub fn exponent(rows: &[ScalingRow], model: &str, situation: Situation) -> Option<f64> {
    let pts: Vec<(f64, f64)> = rows
        .iter()
        .filter(|r| r.model == model && r.situation == situation && r.us_per_step_p50 > 0.0)
        .map(|r| ((r.blocks as f64).ln(), r.us_per_step_p50.ln()))
        .collect();
    if pts.len() < 2 {
        return None;
    }
    let n = pts.len() as f64;
    let (mx, my) = (
        pts.iter().map(|p| p.0).sum::<f64>() / n,
        pts.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    (sxx > 0.0).then(|| sxy / sxx)
}

/// A scene file of `config/scenes/`, read by the real loader.
fn config_scene(name: &str) -> Result<Scene, String> {
    let file = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../config/scenes")
        .join(name);
    Scene::load(&file).map_err(|e| e.to_string())
}

/// An ablation pair: the effect's label, the scene, and how to set each side.
struct Pair {
    effect: &'static str,
    scene: &'static str,
    on: fn(&mut Effects),
    off: fn(&mut Effects),
    /// What the idle field needs so that this effect has nothing to do there either way;
    /// `None`: the effect has no idle case. The floor's (rest -> none) has none: resting is the
    /// floor's verdict, so without a floor the idle field's cubes never rest, stay in the
    /// step's active set and are looked at every step; the two sides do different work (the
    /// `work` row shows what the floor costs).
    idle: Option<fn(&mut Effects)>,
}

fn nothing(_: &mut Effects) {}

/// A row of [`PAIRS`].
const fn pair(
    effect: &'static str,
    scene: &'static str,
    on: fn(&mut Effects),
    off: fn(&mut Effects),
    idle: Option<fn(&mut Effects)>,
) -> Pair {
    Pair {
        effect,
        scene,
        on,
        off,
        idle,
    }
}

#[rustfmt::skip]
const PAIRS: &[Pair] = &[
    pair("gravity", "drop.toml", |e| e.gravity = true, |e| e.gravity = false, Some(nothing)),
    pair("inertia", "grasp-throw-fingers.toml", |e| e.inertia = true, |e| e.inertia = false, Some(nothing)),
    pair("floor: tipping -> rest", "tip.toml", |e| e.floor = FloorEffect::Tipping, |e| e.floor = FloorEffect::Rest, Some(nothing)),
    pair("floor: rest -> none", "tip.toml", |e| e.floor = FloorEffect::Rest, |e| e.floor = FloorEffect::None, None),
    pair("hand: grasp -> push", "grasp-throw-fingers.toml", |e| e.hand = HandEffect::Grasp, |e| e.hand = HandEffect::Push, Some(nothing)),
    pair("hand: push -> none", "push.toml", |e| e.hand = HandEffect::Push, |e| e.hand = HandEffect::None, Some(nothing)),
    pair("carry", "carry.toml", |e| e.carry = true, |e| e.carry = false, Some(nothing)),
    pair("stacking: supported -> paper", "hard/staggered.toml", |e| e.stacking = Stacking::Supported, |e| e.stacking = Stacking::Paper, Some(nothing)),
];

/// Mean us per step of one whole run of `scene` (its hand's keys plus 1 s) after `settle`
/// untimed steps.
fn mean_us(scene: &Scene, settle: u64) -> Result<f64, String> {
    let steps = stepper::default_frames(scene);
    let t = run_steps(scene, settle, steps, false)?.times;
    Ok(t.iter().sum::<f64>() / t.len().max(1) as f64)
}

/// The idle field: 64 cubes resting on the floor apart from each other, and one bare check
/// point 5 m away moving slowly: gravity, inertia, floor, hand, carry and stacking all have
/// nothing to do, so none of them changes a pose, on or off.
pub fn idle_field(model: ModelKind) -> Scene {
    let mut scene = field(64, Situation::Resting, model);
    let key = |t: f64, x: f64| HandKey {
        t,
        wrist: [x, 0.5, 0.0],
        wrist_rotation: [0.0, 0.0, 0.0, 1.0],
        pose: HandPoseSpec::Fingers(vec![vec![[0.0; 3]], vec![[0.0, 0.0, 0.02]]]),
    };
    scene.hand = Some(HandScript {
        keys: vec![key(0.0, 5.0), key(1.0, 5.1)],
    });
    scene.file = PathBuf::from("<bench stepper: idle field x64>");
    scene
}

/// Runs a side of each ablation row (`--quick`: 5).
const ABLATION_RUNS: usize = 9;

/// Untimed steps before the idle field's timed ones (1 s at 120 Hz).
const IDLE_SETTLE_STEPS: u64 = 120;

/// What reading the clock costs here (us): the smallest of many back-to-back readings'
/// differences. Every step is timed between two readings, so a difference between two
/// settings below this is below what the timing resolves: the floor of `noise_us`.
pub fn clock_reading_us() -> f64 {
    let mut best = f64::INFINITY;
    for _ in 0..10_000 {
        let t0 = Instant::now();
        best = best.min(t0.elapsed().as_secs_f64() * 1e6);
    }
    best
}

fn ablation_row(
    pair: &Pair,
    model: ModelKind,
    runs: usize,
    idle: bool,
    clock_us: f64,
) -> Result<AblationRow, String> {
    let mut base = if idle {
        idle_field(model)
    } else {
        config_scene(pair.scene)?
    };
    base.world.model = model;
    if let (true, Some(setup)) = (idle, pair.idle) {
        setup(&mut base.effects);
    }
    // The idle field is timed settled, as the resting situation is: its first step is work
    // for several effects (the floor's first impacts, R9 and R14 judging every block once),
    // and idle means after it.
    let settle = if idle { IDLE_SETTLE_STEPS } else { 0 };
    let (mut on, mut off) = (base.clone(), base);
    (pair.on)(&mut on.effects);
    (pair.off)(&mut off.effects);
    mean_us(&on, settle)?;
    mean_us(&off, settle)?;
    let (mut a, mut b) = (Vec::with_capacity(runs), Vec::with_capacity(runs));
    for _ in 0..runs {
        a.push(mean_us(&on, settle)?);
        b.push(mean_us(&off, settle)?);
    }
    let diff = Spread::of(a.iter().zip(&b).map(|(x, y)| x - y).collect());
    let (on, off) = (Spread::of(a), Spread::of(b));
    Ok(AblationRow {
        model: model_name(model),
        effect: pair.effect.to_string(),
        case: if idle { "idle" } else { "work" },
        scene: if idle {
            "idle field (64 resting cubes, a hand 5 m away)".to_string()
        } else {
            pair.scene.to_string()
        },
        noise_us: (0.5 * (diff.max - diff.min)).max(clock_us),
        clock_us,
        on,
        off,
        diff,
    })
}

/// The precise model's cheap setting, as found in this run: the chosen setting's record and
/// every setting's, in the order tried.
pub struct Cheap {
    pub chosen: CheapTry,
    pub tried: Vec<CheapTry>,
}

/// What one run of the benchmark measured.
pub struct Report {
    pub cheap: Cheap,
    /// The last whole run's scaling rows (the tables' p50s and p99s).
    pub scaling: Vec<ScalingRow>,
    /// Every whole run's scaling rows, in run order (the published ratios: [`ratio_across_runs`]).
    pub scaling_runs: Vec<Vec<ScalingRow>>,
    /// Sizes asked for that the world cannot hold yet: (N, why).
    pub not_run: Vec<(usize, String)>,
    pub ablation: Vec<AblationRow>,
    /// What one reading of the clock costs here (us): the floor of every row's noise.
    pub clock_us: f64,
    pub seconds: f64,
}

pub fn run(b: &StepperBench) -> Result<Report, Box<dyn std::error::Error>> {
    std::fs::create_dir_all(&b.out_dir)
        .map_err(|e| format!("{}: cannot create: {e}", b.out_dir.display()))?;
    let started = Instant::now();
    let sizes: Vec<usize> = SIZES
        .iter()
        .copied()
        .take(if b.quick { QUICK_SIZES } else { SIZES.len() })
        .collect();
    let not_run: Vec<(usize, String)> = sizes
        .iter()
        .filter(|&&n| n > MAX_SCENE_BLOCKS)
        .map(|&n| {
            (
                n,
                format!(
                    "over the scene limit of {MAX_SCENE_BLOCKS} blocks (common::MAX_SCENE_BLOCKS)"
                ),
            )
        })
        .collect();
    // Until the world holds them all, the largest world it holds is measured too, so that the
    // fit has three sizes.
    let mut measured: Vec<usize> = sizes
        .iter()
        .copied()
        .filter(|&n| n <= MAX_SCENE_BLOCKS)
        .collect();
    if !not_run.is_empty() && !measured.contains(&MAX_SCENE_BLOCKS) {
        measured.push(MAX_SCENE_BLOCKS);
    }
    let runs = if b.quick { 2 } else { 5 };
    let models = [ModelKind::Paper, ModelKind::Precise];
    let (cheap, found) = cheapest_still()?;
    eprintln!(
        "stepper: the precise model's cheapest setting that keeps a settled pyramid still: {} ({} of {} settings keep it still; {:.0} s so far)",
        found.chosen.describe(),
        found.tried.iter().filter(|t| t.still()).count(),
        found.tried.len(),
        started.elapsed().as_secs_f64()
    );
    let contenders = [
        Contender::PAPER,
        Contender::PRECISE,
        Contender {
            name: "precise-cheap",
            model: ModelKind::Precise,
            precise: Some(cheap),
        },
    ];
    let whole_runs = b.runs.max(1);
    let mut scaling_runs = Vec::with_capacity(whole_runs);
    for w in 0..whole_runs {
        eprintln!("stepper: scaling, whole run {} of {whole_runs}", w + 1);
        let mut scaling = Vec::new();
        for (k, &s) in Situation::ALL.iter().enumerate() {
            for r in scaling_rows(&contenders, s, &measured, runs)? {
                eprintln!(
                "stepper: scaling [{}/{}] {} {} x{}: p50 {:.1} us, p99 {:.1} us, {:.1} active ({:.0} s so far)",
                k + 1,
                Situation::ALL.len(),
                r.model,
                s.name(),
                r.blocks,
                r.us_per_step_p50,
                r.us_per_step_p99,
                r.active,
                started.elapsed().as_secs_f64()
            );
                scaling.push(r);
            }
        }
        scaling_runs.push(scaling);
    }
    let scaling = scaling_runs.last().cloned().unwrap_or_default();
    for (n, why) in &not_run {
        eprintln!("stepper: scaling x{n}: not run: {why}");
    }
    let ab_runs = if b.quick { 5 } else { ABLATION_RUNS };
    let mut ablation = Vec::new();
    let cases: Vec<(bool, &Pair)> = [false, true]
        .iter()
        .flat_map(|&i| PAIRS.iter().map(move |p| (i, p)))
        .filter(|(idle, p)| !idle || p.idle.is_some())
        .collect();
    let total = cases.len() * models.len();
    let clock_us = clock_reading_us();
    for (k, (idle, pair, &m)) in cases
        .iter()
        .flat_map(|&(i, p)| models.iter().map(move |m| (i, p, m)))
        .enumerate()
    {
        let r = ablation_row(pair, m, ab_runs, idle, clock_us)?;
        eprintln!(
            "stepper: ablation [{}/{}] {} {} ({}): on {:.2} us, off {:.2} us, noise {:.2} us ({:.0} s so far)",
            k + 1,
            total,
            r.model,
            r.effect,
            r.case,
            r.on.median,
            r.off.median,
            r.noise_us,
            started.elapsed().as_secs_f64()
        );
        ablation.push(r);
    }
    let report = Report {
        cheap: found,
        scaling,
        scaling_runs,
        not_run,
        ablation,
        clock_us,
        seconds: started.elapsed().as_secs_f64(),
    };
    let json_path = b.out_dir.join("stepper.json");
    std::fs::write(
        &json_path,
        serde_json::to_string_pretty(&to_json(&report))? + "\n",
    )
    .map_err(|e| format!("{}: {e}", json_path.display()))?;
    let md_path = b.out_dir.join("stepper.md");
    let provenance = Provenance::of_this_run(b.quick, &b.out_dir);
    std::fs::write(&md_path, markdown(&report, &provenance))
        .map_err(|e| format!("{}: {e}", md_path.display()))?;
    let png = b.out_dir.join("stepper.png");
    if !figure(&report.scaling).write_png(&png)? {
        eprintln!(
            "stepper: no TrueType font found (install fonts-dejavu-core or set HB_PLOT_FONT): {} has no labels",
            png.display()
        );
    }
    println!("{}\n\n{}", scaling_table(&report), ablation_table(&report));
    println!(
        "stepper: {} scaling rows, {} ablation rows in {:.0} s; wrote {}, stepper.md, stepper.png",
        report.scaling.len(),
        report.ablation.len(),
        report.seconds,
        json_path.display()
    );
    Ok(report)
}

fn to_json(r: &Report) -> Value {
    let scaling: Vec<Value> = r
        .scaling
        .iter()
        .map(|s| {
            json!({"model": s.model, "situation": s.situation.name(), "blocks": s.blocks,
                   "active": num(s.active), "us_per_step_p50": num(s.us_per_step_p50),
                   "us_per_step_p99": num(s.us_per_step_p99),
                   "wrapper_us_p50": num(s.wrapper_us_p50),
                   "wrapper_share": num(s.wrapper_share),
                   "round_p50_us": s.round_p50.iter().map(|&v| num(v)).collect::<Vec<_>>()})
        })
        .collect();
    let mut ratios = Vec::new();
    for sit in Situation::ALL {
        for n in sizes_of(&r.scaling, sit) {
            for m in &NAMES[1..] {
                if let Some((per_round, s)) = round_ratios(&r.scaling, m, sit, n) {
                    let across = ratio_across_runs(r, m, sit, n).map(|(per_run, a)| {
                        json!({"runs": per_run.len(),
                               "per_run_median": per_run.iter().map(|&v| num(v)).collect::<Vec<_>>(),
                               "median": num(a.median), "min": num(a.min), "max": num(a.max)})
                    });
                    ratios.push(json!({"model": m, "over": "paper", "situation": sit.name(),
                        "blocks": n, "across_runs": across,
                        "last_run": {"per_round": per_round.iter().map(|&v| num(v)).collect::<Vec<_>>(),
                                     "median": num(s.median), "min": num(s.min), "max": num(s.max)}}));
                }
            }
        }
    }
    let mut exponents = Vec::new();
    for m in NAMES {
        for s in Situation::ALL {
            exponents.push(json!({"model": m, "situation": s.name(),
                                  "exponent": exponent(&r.scaling, m, s).map(num)}));
        }
    }
    let ablation: Vec<Value> = r
        .ablation
        .iter()
        .map(|a| {
            json!({"model": a.model, "effect": a.effect, "case": a.case, "scene": a.scene,
                   "on_us": num(a.on.median), "off_us": num(a.off.median),
                   "noise_us": num(a.noise_us),
                   "diff_median_us": num(a.diff.median), "diff_min_us": num(a.diff.min),
                   "diff_max_us": num(a.diff.max),
                   "on_min_us": num(a.on.min), "on_max_us": num(a.on.max),
                   "off_min_us": num(a.off.min), "off_max_us": num(a.off.max),
                   "within_noise": a.within_noise()})
        })
        .collect();
    let not_run: Vec<Value> = r
        .not_run
        .iter()
        .map(|(n, why)| json!({"blocks": n, "why": why}))
        .collect();
    let row = |t: &CheapTry| {
        json!({"substeps": t.substeps, "solver_iterations": t.solver_iterations,
               "sleep": t.sleep, "ccd": t.ccd, "still": t.still(),
               "drift_m": num(t.drift_m), "drift_rad": num(t.drift_rad), "sag_m": num(t.sag_m),
               "moved_m": num(t.moved_m), "turned_rad": num(t.turned_rad),
               "us_per_step": num(t.us_per_step)})
    };
    let c = &r.cheap.chosen;
    let cheap = json!({"substeps": c.substeps, "solver_iterations": c.solver_iterations,
        "sleep": c.sleep, "ccd": c.ccd, "sag_m": num(c.sag_m),
        "field": format!("pyramid of {} cubes ({} at its base), 1 s to settle, judged over the next", pyramid_field().blocks.len(), PYRAMID_ROWS),
        "still_m": STILL_M, "still_rad": STILL_RAD, "stand_m": STAND_M, "stand_rad": STAND_RAD,
        "tried": r.cheap.tried.iter().map(row).collect::<Vec<_>>()});
    json!({"scaling": scaling, "ratios_to_paper": ratios, "exponents": exponents, "not_run": not_run,
           "precise_cheap": cheap,
           "ablation": ablation, "clock_reading_us": num(r.clock_us),
           "seconds": num(r.seconds)})
}

/// The contenders' names, in table order.
const NAMES: [&str; 3] = ["paper", "precise", "precise-cheap"];

/// The sizes measured in a situation, ascending.
fn sizes_of(rows: &[ScalingRow], situation: Situation) -> Vec<usize> {
    let mut sizes: Vec<usize> = rows
        .iter()
        .filter(|x| x.situation == situation)
        .map(|x| x.blocks)
        .collect();
    sizes.sort_unstable();
    sizes.dedup();
    sizes
}

/// A ratio as the tables print it: whole numbers from 10 up, one decimal below.
fn times(x: f64) -> String {
    if x >= 10.0 {
        format!("{x:.0}x")
    } else {
        format!("{x:.1}x")
    }
}

/// The scaling table: one line per (situation, N), the contenders side by side.
pub fn scaling_table(r: &Report) -> String {
    let mut s = String::from(
        "| situation | blocks | paper: active, p50 / p99 (us) | paper us per active block | precise: active, p50 / p99 | precise-cheap: active, p50 / p99 | precise / paper: median of the whole runs [min, max over runs] | precise-cheap / paper: the same | precise: wrapper p50 (us), share | precise-cheap: wrapper p50, share |\n|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for sit in Situation::ALL {
        for n in sizes_of(&r.scaling, sit) {
            let get = |m: &str| {
                r.scaling
                    .iter()
                    .find(|x| x.model == m && x.situation == sit && x.blocks == n)
            };
            let (p, q, c) = (get("paper"), get("precise"), get("precise-cheap"));
            let cell = |x: Option<&ScalingRow>| {
                x.map_or("-".to_string(), |x| {
                    format!(
                        "{:.1}, {:.1} / {:.1}",
                        x.active, x.us_per_step_p50, x.us_per_step_p99
                    )
                })
            };
            let ratio = |m: &str| {
                ratio_across_runs(r, m, sit, n).map_or("-".to_string(), |(_, s)| {
                    format!("{} [{}, {}]", times(s.median), times(s.min), times(s.max))
                })
            };
            let wrapper = |x: Option<&ScalingRow>| {
                x.filter(|x| x.wrapper_share.is_finite())
                    .map_or("-".to_string(), |x| {
                        format!("{:.1}, {:.1} %", x.wrapper_us_p50, 100.0 * x.wrapper_share)
                    })
            };
            s += &format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
                sit.name(),
                n,
                cell(p),
                p.map_or("-".into(), |x| if x.active > 0.0 {
                    format!("{:.2}", x.us_per_step_p50 / x.active)
                } else {
                    "(none active)".into()
                }),
                cell(q),
                cell(c),
                ratio("precise"),
                ratio("precise-cheap"),
                wrapper(q),
                wrapper(c)
            );
        }
    }
    for (n, why) in &r.not_run {
        s += &format!("| all | {n} | not run: {why} | | | | | | | |\n");
    }
    let c = &r.cheap.chosen;
    s += &format!(
        "\nprecise-cheap: {} substeps x {} solver iteration(s) per substep, sleeping {}, CCD {}: the least solver work (substeps x iterations, then fewer substeps, sleeping, no CCD) of {} settings (substeps {:?} x iterations {:?} x sleeping on/off x CCD on/off) with which a pyramid of {} cubes, block on block, stands through its first second (no cube drifts over {:.0} mm nor turns over {:.0} deg) and no cube moves over {STILL_M:.0e} m nor turns over {STILL_RAD:.1e} rad in its second (its sag {:.2} mm, {:.1} us per step). {} of the {} keep it still; the fewest substeps that do: {}.\n",
        c.substeps,
        c.solver_iterations,
        if c.sleep { "on" } else { "off" },
        if c.ccd { "on" } else { "off" },
        r.cheap.tried.len(),
        CHEAP_SUBSTEPS,
        CHEAP_ITERATIONS,
        pyramid_field().blocks.len(),
        STAND_M * 1e3,
        STAND_RAD.to_degrees(),
        c.sag_m * 1e3,
        c.us_per_step,
        r.cheap.tried.iter().filter(|t| t.still()).count(),
        r.cheap.tried.len(),
        r.cheap
            .tried
            .iter()
            .filter(|t| t.still())
            .map(|t| t.substeps)
            .min()
            .map_or("-".to_string(), |s| s.to_string()),
    );
    s += "\nfitted exponent of p50 against N (least squares, log-log):";
    for m in NAMES {
        for sit in Situation::ALL {
            s += &format!(
                " {m} {}: {};",
                sit.name(),
                exponent(&r.scaling, m, sit).map_or("-".into(), |e| format!("{e:.2}"))
            );
        }
    }
    s.trim_end_matches(';').to_string()
}

/// The ablation table.
pub fn ablation_table(r: &Report) -> String {
    let mut s = String::from(
        "| model | effect (on -> off) | case | scene | on: median [min, max] (us/step) | off: median [min, max] | on - off, paired: median [min, max] | noise | within noise |\n|---|---|---|---|---|---|---|---|---|\n",
    );
    for a in &r.ablation {
        s += &format!(
            "| {} | {} | {} | {} | {:.2} [{:.2}, {:.2}] | {:.2} [{:.2}, {:.2}] | {:+.2} [{:+.2}, {:+.2}] | {:.2} | {} |\n",
            a.model,
            a.effect,
            a.case,
            a.scene,
            a.on.median,
            a.on.min,
            a.on.max,
            a.off.median,
            a.off.min,
            a.off.max,
            a.diff.median,
            a.diff.min,
            a.diff.max,
            a.noise_us,
            if a.within_noise() { "yes" } else { "no" }
        );
    }
    s.trim_end().to_string()
}

fn markdown(r: &Report, provenance: &Provenance) -> String {
    let quick = provenance.quick;
    let what = format!(
        "What a step costs as the world grows, under both models in one run ({:.0} s{}): the \
         paper model and the precise one (rapier3d, the peer), the precise one at its `[precise]` defaults (the reference: sleeping off) and at its cheapest setting that keeps a settled field still (`precise-cheap`). Scaling: fields of N 4 cm cubes on an 8 cm grid; `falling`: a rain from 0.6-1.2 m, its first 0.5 s (all in the air, then the lowest landing), `resting`: the settled field (timed after 1 s untimed), `hand`: one check point sweeping the middle row; every step timed on its own, p50/p99 over the timed rounds; a ratio to the paper model is taken round by round (each round's p50 over the paper model's p50 of the same round, timed seconds apart), its median over a run's rounds; the scaling part is run {} whole times from the start and the table's ratio is the median of the runs' medians [min, max over the runs] (the run-to-run spread; the p50s and p99s are the last run's); active: blocks not resting, mean per step; wrapper: a precise step less rapier's own `PhysicsPipeline::step` call (timed inside the world), p50 and its share of all the timed steps' time.\n\n\
         How to read it: lower is better; a ratio divides the precise model's time per step by \
         the paper model's in the same round: 16x means the precise step costs 16 times the \
         paper one. The figure draws \
         time per step (p50) against the number of blocks, both log, one line per model and \
         situation: a slope of 1 is linear in N.",
        r.seconds,
        if quick {
            "; quick run: 16 and 64 blocks, 2 timed rounds"
        } else {
            ", 5 timed rounds after a warm-up; a round goes round the sizes and, within a size, round the contenders (paper, precise, precise-cheap)"
        },
        r.scaling_runs.len()
    );
    let mut s = page::head(
        "Benchmark: a step's cost against the world's size, and each effect's",
        &what,
        provenance,
    );
    s += &page::figure(
        "time per step (p50) against blocks, log-log, one line per model and situation",
        "stepper.png",
    );
    s += "## Scaling\n\n";
    s += &scaling_table(r);
    s += &format!(
        "\n\n## Ablation\n\nEach effect on and off on the same scene, {runs} interleaved runs a side after a warm-up (on, off, on, off, ...), mean us per step of the whole run; on - off: the difference of each pair of runs (back to back, so a slow spell of the machine falls on both), median [min, max]; within noise: the pairs' differences are not all of one sign, beyond what one reading of the clock costs here ({clock:.3} us: a difference below it is below what the timing resolves; by chance, all {runs} of one sign happens {chance:.1} % of the time); noise: half the pairs' max - min, at least that reading. `work`: a scene of `config/scenes/` the effect acts in (on - off is the effect's work, and the two sides do different things); `idle`: the idle field (64 resting cubes, a two-point hand 5 m away), timed after 1 s of settling untimed, where the effect has nothing to do and turning it off changes no pose, so on - off is what its pass costs by being in the step at all (the floor's rest -> none has no idle case: without a floor nothing rests, so the idle field's cubes stay in the step's active set). An effect that is off is not in the step's pass list (`Passes`): off runs none of its code.\n\n",
        clock = r.clock_us,
        runs = if quick { 5 } else { ABLATION_RUNS },
        chance = 100.0 * 0.5f64.powi(if quick { 5 } else { ABLATION_RUNS } as i32 - 1),
    );
    s += &ablation_table(r);
    s += "\n";
    s
}

/// Time per step (p50) against N, log-log: one line per (model, situation).
fn figure(rows: &[ScalingRow]) -> Figure {
    let mut sizes: Vec<f64> = rows.iter().map(|r| r.blocks as f64).collect();
    sizes.sort_by(f64::total_cmp);
    sizes.dedup();
    let mut series = Vec::new();
    for m in NAMES {
        for sit in Situation::ALL {
            let points: Vec<(f64, f64)> = rows
                .iter()
                .filter(|r| r.model == m && r.situation == sit)
                .map(|r| (r.blocks as f64, r.us_per_step_p50.max(1e-3)))
                .collect();
            if !points.is_empty() {
                series.push(Series {
                    label: format!("{m} {}", sit.name()),
                    points,
                });
            }
        }
    }
    Figure {
        panels: vec![Panel {
            title: "time per step (p50) against blocks".into(),
            x: Axis::log("blocks").with_ticks_at(sizes),
            y: Axis::log("us per step"),
            series,
            marked: Vec::new(),
            join: Join::Settings,
        }],
        columns: 1,
        panel_width: 760,
        panel_height: 520,
        column_weights: Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fields_are_valid_scenes_of_n_cubes_in_each_situation() {
        for s in Situation::ALL {
            for n in [1, 16, 64] {
                let scene = field(n, s, ModelKind::Paper);
                assert_eq!(scene.blocks.len(), n);
                Model::new(&scene).unwrap_or_else(|e| panic!("{} x{n}: {e}", s.name()));
            }
        }
    }

    #[test]
    fn the_cheap_search_tells_a_pyramid_that_falls_from_one_that_stands_still() {
        let pyramid = pyramid_field();
        assert_eq!(pyramid.blocks.len(), 36);
        Model::new(&pyramid).unwrap_or_else(|e| panic!("the pyramid: {e}"));
        let t = |substeps, solver_iterations, sleep, ccd| {
            try_cheap(CheapTry::untried(substeps, solver_iterations, sleep, ccd)).unwrap()
        };
        // One substep, awake: it comes apart (a cube moves by centimetres in the second second).
        let loose = t(1, 1, false, false);
        assert!(
            !loose.still() && loose.moved_m > 1e-2,
            "{}",
            loose.describe()
        );
        // The reference setting: it stands, still, sagging less than a millimetre.
        let reference = t(8, 2, false, true);
        assert!(
            reference.still() && reference.sag_m < 1e-3,
            "{}",
            reference.describe()
        );
    }

    #[test]
    fn the_exponent_of_a_power_law_is_its_power() {
        let rows: Vec<ScalingRow> = [16usize, 64, 256]
            .iter()
            .map(|&n| ScalingRow {
                model: "paper",
                situation: Situation::Falling,
                blocks: n,
                active: n as f64,
                us_per_step_p50: 0.5 * (n as f64).powf(1.5),
                us_per_step_p99: 0.0,
                wrapper_us_p50: f64::NAN,
                wrapper_share: f64::NAN,
                round_p50: Vec::new(),
            })
            .collect();
        let e = exponent(&rows, "paper", Situation::Falling).unwrap();
        assert!((e - 1.5).abs() < 1e-9, "{e}");
        assert!(exponent(&rows, "precise", Situation::Falling).is_none());
    }

    #[test]
    fn ratios_are_taken_round_by_round() {
        let row = |model, round_p50: Vec<f64>| ScalingRow {
            model,
            situation: Situation::Falling,
            blocks: 64,
            active: 64.0,
            us_per_step_p50: 0.0,
            us_per_step_p99: 0.0,
            wrapper_us_p50: f64::NAN,
            wrapper_share: f64::NAN,
            round_p50,
        };
        // A slow round slows both models: per round the ratio stays 10, pooled it would not.
        let rows = [
            row("paper", vec![1.0, 3.0, 1.0]),
            row("precise", vec![10.0, 30.0, 10.0]),
        ];
        let (per_round, s) = round_ratios(&rows, "precise", Situation::Falling, 64).unwrap();
        assert_eq!(per_round, vec![10.0, 10.0, 10.0]);
        assert_eq!((s.median, s.min, s.max), (10.0, 10.0, 10.0));
        assert!(round_ratios(&rows, "precise-cheap", Situation::Falling, 64).is_none());
        assert!(round_ratios(&rows, "precise", Situation::Resting, 64).is_none());
    }

    #[test]
    fn every_ablation_scene_loads_and_both_sides_differ() {
        for p in PAIRS {
            let scene = config_scene(p.scene).unwrap();
            let (mut on, mut off) = (scene.effects, scene.effects);
            (p.on)(&mut on);
            (p.off)(&mut off);
            assert_ne!(on, off, "{}", p.effect);
        }
    }

    fn final_poses(scene: &Scene, steps: u64) -> Vec<[u64; 7]> {
        let mut model = Model::new(scene).unwrap();
        let hand = BareFingersHand::from_scene(scene);
        let dt = 1.0 / scene.world.step_hz;
        for k in 1..=steps {
            let h = hand.as_ref().map(|h| h.sample(k as f64 * dt));
            model.step(h.as_ref());
        }
        (0..model.block_count())
            .map(|i| {
                let b = model.block(i).unwrap();
                let (p, q) = (b.position.to_array(), b.rotation.to_array());
                [p[0], p[1], p[2], q[0], q[1], q[2], q[3]].map(f64::to_bits)
            })
            .collect()
    }

    #[test]
    fn in_the_idle_field_no_effect_changes_a_pose_on_or_off() {
        for p in PAIRS {
            let (mut on, mut off) = (idle_field(ModelKind::Paper), idle_field(ModelKind::Paper));
            let Some(setup) = p.idle else { continue };
            setup(&mut on.effects);
            setup(&mut off.effects);
            (p.on)(&mut on.effects);
            (p.off)(&mut off.effects);
            let start = final_poses(&on, 0);
            assert_eq!(final_poses(&on, 120), start, "{} on", p.effect);
            assert_eq!(final_poses(&off, 120), start, "{} off", p.effect);
        }
    }
}
