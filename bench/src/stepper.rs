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
//!   log-log), and the paper model's time as a ratio to the precise model's. The timed runs go
//!   round the sizes (run 1 of each, then run 2, ...), so the machine's slow spells fall on
//!   every size alike.
//! * **Contenders**: the paper model; the precise one at its `[precise]` defaults (the
//!   reference of `bench accuracy`: 8 substeps, sleeping off, because sleeping would freeze a
//!   block tipping slowly); and the precise one at the cheapest setting that keeps a settled
//!   field still (`precise-cheap`: sleeping on, one solver iteration, the fewest substeps that
//!   pass [`cheapest_still`], found in the same run, not chosen by hand).
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
use stepper::{BareFingersHand, Model};

use crate::plot::{Figure, Legend, Panel, Series};

/// `handblocks bench stepper`'s options.
pub struct StepperBench {
    pub out_dir: PathBuf,
    /// Sizes up to 64 blocks, 2 timed runs (5 otherwise), 5 ablation runs a side (9).
    pub quick: bool,
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
    }
}

/// Times `steps` steps of `scene`, each on its own, after `settle` untimed ones; with
/// `count_active`, also the mean count of blocks not resting (else 0). The count is a pass
/// over every block between two steps: a timed run leaves it out, so that the bench's own
/// bookkeeping does not sweep the step's data out of the caches before each timed step (at
/// 4096 blocks that pass reads ~0.8 MB, more than this machine's L2); it is the same in every
/// run (the model is deterministic), so the untimed warm-up counts it.
fn run_steps(
    scene: &Scene,
    settle: u64,
    steps: u64,
    count_active: bool,
) -> Result<(Vec<f64>, f64), String> {
    let mut model = Model::new(scene).map_err(|e| format!("{}: {e}", scene.file.display()))?;
    let hand = BareFingersHand::from_scene(scene);
    let dt = 1.0 / scene.world.step_hz;
    let sample = |k: u64| -> Option<HandSample> { hand.as_ref().map(|h| h.sample(k as f64 * dt)) };
    model.set_previous_hand(sample(0).as_ref());
    for k in 1..=settle {
        model.step(sample(k).as_ref());
    }
    let mut times = Vec::with_capacity(steps as usize);
    let mut active = 0usize;
    for k in settle + 1..=settle + steps {
        let h = sample(k);
        let t0 = Instant::now();
        model.step(h.as_ref());
        times.push(t0.elapsed().as_secs_f64() * 1e6);
        if count_active {
            active += (0..model.block_count())
                .filter(|&i| model.block(i).is_some_and(|b| b.mode != BlockMode::Resting))
                .count();
        }
    }
    Ok((times, active as f64 / steps.max(1) as f64))
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

/// Substeps tried for the cheap precise setting, fewest first.
const CHEAP_SUBSTEPS: [u32; 4] = [1, 2, 4, 8];
/// "Still": no cube of the settled field moves more than this over its second second.
pub const STILL_M: f64 = 1e-5;

/// The precise model's cheapest setting that keeps a settled field still: sleeping on, one
/// solver iteration, and the fewest substeps with which no cube of the 64-cube resting field,
/// after a first second to settle, moves more than [`STILL_M`] over the next second. Returns
/// the setting and what was found ([`Cheap`]: each tried setting's largest move, and the
/// chosen one's sag, the largest drop in the first second: its contacts' give).
pub fn cheapest_still() -> Result<(PreciseSettings, Cheap), String> {
    let mut tried = Vec::new();
    for substeps in CHEAP_SUBSTEPS {
        let p = PreciseSettings {
            substeps,
            solver_iterations: 1,
            sleep: true,
            ..PreciseSettings::default()
        };
        let mut scene = field(64, Situation::Resting, ModelKind::Precise);
        scene.world.precise = p;
        let mut model = Model::new(&scene).map_err(|e| format!("{}: {e}", scene.file.display()))?;
        let start: Vec<f64> = (0..model.block_count())
            .filter_map(|i| model.block(i).map(|b| b.position.y))
            .collect();
        let settle = scene.world.step_hz.round() as u64;
        for _ in 0..settle {
            model.step(None);
        }
        let settled: Vec<_> = (0..model.block_count())
            .filter_map(|i| model.block(i).map(|b| b.position))
            .collect();
        let sag = settled
            .iter()
            .zip(&start)
            .map(|(p, y0)| y0 - p.y)
            .fold(0.0, f64::max);
        for _ in 0..settle {
            model.step(None);
        }
        let moved = (0..model.block_count())
            .filter_map(|i| model.block(i).map(|b| (b.position - settled[i]).length()))
            .fold(0.0, f64::max);
        tried.push((substeps, moved));
        if moved <= STILL_M {
            let cheap = Cheap {
                substeps,
                tried,
                sag_m: sag,
            };
            return Ok((p, cheap));
        }
    }
    Err(format!(
        "no setting tried keeps a settled field still ({tried:?}: substeps, largest move in m)"
    ))
}

/// The scaling rows of one contender in one situation, one per size. Each size is warmed up
/// once, then the timed runs go round the sizes (run 1 of every size, then run 2, ...), so a
/// slow minute of this shared machine falls on every size alike rather than on the one being
/// timed then (timing the sizes one after the other, a slow spell during the 4096 field's runs
/// alone moved the fitted exponent by several hundredths).
fn scaling_rows(
    c: Contender,
    situation: Situation,
    sizes: &[usize],
    runs: usize,
) -> Result<Vec<ScalingRow>, String> {
    let (settle, steps) = (situation.settle(), situation.steps());
    let mut scenes = Vec::with_capacity(sizes.len());
    let mut active = Vec::with_capacity(sizes.len());
    for &n in sizes {
        let mut scene = field(n, situation, c.model);
        c.apply(&mut scene);
        // The warm-up, and the count of active blocks (the same in every run).
        let (_, a) = run_steps(&scene, settle, steps, true)?;
        active.push(a);
        scenes.push(scene);
    }
    let mut all: Vec<Vec<f64>> = vec![Vec::new(); sizes.len()];
    for _ in 0..runs {
        for (k, scene) in scenes.iter().enumerate() {
            all[k].extend(run_steps(scene, settle, steps, false)?.0);
        }
    }
    Ok(sizes
        .iter()
        .zip(all.iter_mut())
        .zip(active)
        .map(|((&n, times), active)| {
            times.sort_by(f64::total_cmp);
            ScalingRow {
                model: c.name,
                situation,
                blocks: n,
                active,
                us_per_step_p50: percentile(times, 0.5),
                us_per_step_p99: percentile(times, 0.99),
            }
        })
        .collect())
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
    let (t, _) = run_steps(scene, settle, steps, false)?;
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

/// The precise model's cheap setting, as found in this run.
pub struct Cheap {
    pub substeps: u32,
    /// (substeps, largest move of a settled cube over a second, m) per setting tried.
    pub tried: Vec<(u32, f64)>,
    /// The chosen setting's sag in its first second, m.
    pub sag_m: f64,
}

/// What one run of the benchmark measured.
pub struct Report {
    pub cheap: Cheap,
    pub scaling: Vec<ScalingRow>,
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
        "stepper: the precise model's cheapest setting that keeps a settled field still: {} substeps, 1 iteration, sleeping on (tried {}; sag {:.2} mm)",
        cheap.substeps,
        found
            .tried
            .iter()
            .map(|(s, m)| format!("{s} substeps: {m:.1e} m"))
            .collect::<Vec<_>>()
            .join(", "),
        found.sag_m * 1e3
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
    let mut scaling = Vec::new();
    let jobs: Vec<(Contender, Situation)> = contenders
        .iter()
        .flat_map(|&m| Situation::ALL.iter().map(move |&s| (m, s)))
        .collect();
    for (k, &(m, s)) in jobs.iter().enumerate() {
        for r in scaling_rows(m, s, &measured, runs)? {
            eprintln!(
                "stepper: scaling [{}/{}] {} {} x{}: p50 {:.1} us, p99 {:.1} us, {:.1} active ({:.0} s so far)",
                k + 1,
                jobs.len(),
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
    std::fs::write(&md_path, markdown(&report, b.quick))
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

fn num(v: f64) -> Value {
    if v.is_finite() {
        json!(v)
    } else {
        Value::Null
    }
}

fn to_json(r: &Report) -> Value {
    let scaling: Vec<Value> = r
        .scaling
        .iter()
        .map(|s| {
            json!({"model": s.model, "situation": s.situation.name(), "blocks": s.blocks,
                   "active": num(s.active), "us_per_step_p50": num(s.us_per_step_p50),
                   "us_per_step_p99": num(s.us_per_step_p99)})
        })
        .collect();
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
    let cheap = json!({"substeps": r.cheap.substeps, "solver_iterations": 1, "sleep": true,
        "still_m": STILL_M, "sag_m": num(r.cheap.sag_m),
        "tried": r.cheap.tried.iter().map(|(s, m)| json!({"substeps": s, "moved_m": num(*m)})).collect::<Vec<_>>()});
    json!({"scaling": scaling, "exponents": exponents, "not_run": not_run,
           "precise_cheap": cheap,
           "ablation": ablation, "clock_reading_us": num(r.clock_us),
           "seconds": num(r.seconds)})
}

/// The contenders' names, in table order.
const NAMES: [&str; 3] = ["paper", "precise", "precise-cheap"];

/// The scaling table: one line per (situation, N), the contenders side by side.
pub fn scaling_table(r: &Report) -> String {
    let mut s = String::from(
        "| situation | blocks | paper: active, p50 / p99 (us) | paper us per active block | precise: active, p50 / p99 | precise-cheap: active, p50 / p99 | precise / paper | precise-cheap / paper |\n|---|---|---|---|---|---|---|---|\n",
    );
    for sit in Situation::ALL {
        let mut sizes: Vec<usize> = r
            .scaling
            .iter()
            .filter(|x| x.situation == sit)
            .map(|x| x.blocks)
            .collect();
        sizes.sort_unstable();
        sizes.dedup();
        for n in sizes {
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
            let ratio = |q: Option<&ScalingRow>| match (p, q) {
                (Some(p), Some(q)) if p.us_per_step_p50 > 0.0 => {
                    format!("{:.0}x", q.us_per_step_p50 / p.us_per_step_p50)
                }
                _ => "-".into(),
            };
            s += &format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} |\n",
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
                ratio(q),
                ratio(c)
            );
        }
    }
    for (n, why) in &r.not_run {
        s += &format!("| all | {n} | not run: {why} | | | | | |\n");
    }
    s += &format!(
        "\nprecise-cheap: {} substeps, 1 solver iteration, sleeping on: the fewest substeps (of {:?}) with which no cube of a settled 64-cube field moves over {STILL_M:.0e} m in its second second (tried: {}; its sag in the first second {:.2} mm).\n",
        r.cheap.substeps,
        CHEAP_SUBSTEPS,
        r.cheap
            .tried
            .iter()
            .map(|(s, m)| format!("{s}: {m:.1e} m"))
            .collect::<Vec<_>>()
            .join(", "),
        r.cheap.sag_m * 1e3
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

fn markdown(r: &Report, quick: bool) -> String {
    let mut s = String::from("# handblocks bench stepper\n\n");
    s += &format!(
        "Both models in one run ({:.0} s{}); the precise one at its `[precise]` defaults (the reference: sleeping off) and at its cheapest setting that keeps a settled field still (`precise-cheap`). Scaling: fields of N 4 cm cubes on an 8 cm grid; `falling`: a rain from 0.6-1.2 m, its first 0.5 s (all in the air, then the lowest landing), `resting`: the settled field (timed after 1 s untimed), `hand`: one check point sweeping the middle row; every step timed on its own, p50/p99 over the timed runs; active: blocks not resting, mean per step.\n\n",
        r.seconds,
        if quick { ", --quick: 16 and 64 blocks, 2 timed runs" } else { ", 5 timed runs after a warm-up, going round the sizes" }
    );
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
            x_label: "blocks (log)".into(),
            y_label: "us per step (log)".into(),
            log_x: true,
            log_y: true,
            series,
            marked: Vec::new(),
            legend: Legend::AboveData,
        }],
        columns: 1,
        panel_width: 900,
        panel_height: 560,
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
            })
            .collect();
        let e = exponent(&rows, "paper", Situation::Falling).unwrap();
        assert!((e - 1.5).abs() < 1e-9, "{e}");
        assert!(exponent(&rows, "precise", Situation::Falling).is_none());
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
