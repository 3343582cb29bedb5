//! `handblocks bench accuracy`: what accuracy costs in time, for the paper model and the
//! precise reference (rapier3d), measured on the same scenes in the same run.
//!
//! Each scene class has a stated reference: an exact answer where physics gives one (static
//! tipping: topple or not and the final pose; a drop's fall time; a throw's landing point; a
//! box released past its edge: its fall time from the pendulum equation phi'' = p^2 sin phi;
//! stacks: stand or fall, and no sink). The hand scenes (push, grasp-throw) have none: they are
//! judged against the precise model at its finest setting, so their figure is *agreement with
//! the precise model*, not accuracy, and only where that setting passes its convergence check
//! (halving its substep moves the answer by less than 10% of the block's travel). A class whose
//! reference fails the check has no error at all (NaN, printed "-"), never 0, and no verdict.
//! In those scenes both models get the same fingers: the paper model's are points, so the
//! precise model's capsules are made as thin as rapier handles ([`FINGER_RADIUS`]).
//!
//! Each model runs at several settings (the paper model at five step rates, the precise one
//! over step rate x substeps x solver iterations x sleeping off and on). Settings differ in step rate, so every
//! comparison of cost (the Pareto front, the cheapest setting reaching the best error, the
//! ratios) is in time per *simulated second* (time per step x step rate); the time per step
//! stays a column. Each scene times its settings interleaved: a warm-up round, then
//! [`ROUNDS`] rounds, each timing every setting once in turn (the order rotated a setting per
//! round; a short run repeated within a reading), so that a slow spell of this shared machine
//! falls on both models alike; a ratio between models is taken within each
//! round and reported as median [min, max] over the rounds. Neither model is tuned here: each
//! runs at its own settings, and the errors are what they are.
//!
//! Outputs: `accuracy.json` (`{"rows", "summary", "pareto", "verdicts", "references", ...}`),
//! `accuracy.md` (the summary and the tables) and `accuracy.png` (per class, log time per
//! simulated second against log error, one line per model, the Pareto front ringed).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::{DQuat, DVec3};
use serde_json::{json, Value};

use crate::page::num;

use common::config::scene::{BlockSpec, ModelKind, ShapeSpec, WorldSettings};
use common::config::Scene;
use stepper::geometry::Polyhedron;
use stepper::{BareFingersHand, HandSource, Model};

use crate::page::{self, Provenance};
use crate::plot::{pareto_front, Axis, Figure, Join, Panel, Series};

/// Options of `handblocks bench accuracy`.
pub struct AccuracyBench {
    pub out_dir: PathBuf,
    /// A reduced sweep (fewer scenes and settings) that runs in under a minute.
    pub quick: bool,
    /// Whole runs (every scene, setting and round, from the start): the published ratios are
    /// the median over them, with their run-to-run spread. At least 1; 3 by default.
    pub runs: usize,
}

/// The whole runs a published figure takes the median of, by default.
pub const DEFAULT_RUNS: usize = 3;

/// One whole run's results.
struct Whole {
    rows: Vec<Row>,
    summary: Vec<Point>,
    pareto: Vec<Point>,
    verdicts: Vec<Verdict>,
    checks: Vec<ReferenceCheck>,
    notes: Vec<String>,
    reference: Setting,
}

/// One verdict's figures across whole runs: each run's median over its rounds.
#[derive(Debug, Clone, Default)]
pub struct AcrossRuns {
    pub best_against_best: Vec<f64>,
    pub at_paper_best: Vec<f64>,
    pub at_precise_best: Vec<f64>,
    /// The settings each run chose (they can differ where two settings cost about the same).
    pub paper_settings: Vec<String>,
    pub precise_settings: Vec<String>,
}

/// Per verdict of the last run (class, paper model), its figures in every run.
fn across_runs(wholes: &[Whole]) -> Vec<AcrossRuns> {
    let Some(last) = wholes.last() else {
        return Vec::new();
    };
    last.verdicts
        .iter()
        .map(|v| {
            let mut a = AcrossRuns::default();
            for w in wholes {
                let Some(u) = w
                    .verdicts
                    .iter()
                    .find(|u| u.class == v.class && u.paper_model == v.paper_model)
                else {
                    continue;
                };
                let med = |r: &[f64]| spread(r).map_or(f64::NAN, |s| s.median);
                a.best_against_best.push(med(&u.ratios));
                a.at_paper_best.push(med(&u.ratios_at_paper_best));
                a.at_precise_best.push(med(&u.ratios_at_precise_best));
                for (list, p) in [
                    (&mut a.paper_settings, &u.paper),
                    (&mut a.precise_settings, &u.precise),
                ] {
                    if let Some(p) = p {
                        if !list.contains(&p.setting) {
                            list.push(p.setting.clone());
                        }
                    }
                }
            }
            a
        })
        .collect()
}

/// The published table: per class, each ratio as the median of the runs' medians, [min, max]
/// over the runs.
pub fn across_runs_table(verdicts: &[Verdict], across: &[AcrossRuns], runs: usize) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "| class | judged against | best against best: precise/paper per simulated s, median of {runs} runs [min, max over runs] | at matched error, the paper's best as target | at matched error, the precise best as target | settings chosen (paper; precise) |"
    );
    o.push_str("|---|---|---|---|---|---|\n");
    for (v, a) in verdicts.iter().zip(across) {
        let name = if v.paper_model == "paper-R14" {
            format!("{} (paper with R14)", v.class)
        } else {
            v.class.to_string()
        };
        let cell = |r: &[f64]| match spread(r) {
            _ if matches!(
                v.against,
                Against::NoConvergedReference | Against::ReferenceTooCoarse
            ) =>
            {
                "no verdict".to_string()
            }
            None => "none reaches it".to_string(),
            s => fmt_spread(s, fmt_ratio, "x"),
        };
        let _ = writeln!(
            o,
            "| {name} | {} | {} | {} | {} | {}; {} |",
            v.against.label(),
            cell(&a.best_against_best),
            cell(&a.at_paper_best),
            cell(&a.at_precise_best),
            if a.paper_settings.is_empty() {
                "-".to_string()
            } else {
                a.paper_settings.join(" / ")
            },
            if a.precise_settings.is_empty() {
                "-".to_string()
            } else {
                a.precise_settings.join(" / ")
            },
        );
    }
    o
}

/// One model at one setting.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Setting {
    Paper {
        hz: f64,
    },
    /// The paper model with R14's supported stacking (`stacking = "supported"`), run on the
    /// stack scenes only (elsewhere it is the paper model), when this build has R14.
    PaperR14 {
        hz: f64,
    },
    Precise {
        hz: f64,
        substeps: u32,
        iterations: u32,
        /// rapier's sleeping (`[precise] sleep`): a body at rest is put to sleep and costs
        /// nothing until something wakes it.
        sleep: bool,
    },
}

impl Setting {
    pub fn model(&self) -> &'static str {
        match self {
            Setting::Paper { .. } => "paper",
            Setting::PaperR14 { .. } => "paper-R14",
            Setting::Precise { .. } => "precise",
        }
    }

    pub fn label(&self) -> String {
        match self {
            Setting::Paper { hz } | Setting::PaperR14 { hz } => format!("{hz} Hz"),
            Setting::Precise {
                hz,
                substeps,
                iterations,
                sleep,
            } => format!(
                "{hz} Hz x{substeps} sub x{iterations} it{}",
                if *sleep { " sleep" } else { "" }
            ),
        }
    }

    fn hz(&self) -> f64 {
        match self {
            Setting::Paper { hz } | Setting::PaperR14 { hz } | Setting::Precise { hz, .. } => *hz,
        }
    }

    fn apply(&self, scene: &mut Scene) {
        scene.world.step_hz = self.hz();
        match *self {
            Setting::Paper { .. } => scene.world.model = ModelKind::Paper,
            Setting::PaperR14 { .. } => {
                scene.world.model = ModelKind::Paper;
                scene.effects.stacking = common::config::scene::Stacking::Supported;
            }
            Setting::Precise {
                substeps,
                iterations,
                sleep,
                ..
            } => {
                scene.world.model = ModelKind::Precise;
                scene.world.precise.substeps = substeps;
                scene.world.precise.solver_iterations = iterations;
                scene.world.precise.sleep = sleep;
            }
        }
    }
}

/// What a scene's run is judged by.
#[derive(Debug, Clone, Copy)]
enum Judge {
    /// Static tipping: the block ends toppled (rotated 90 deg about z about its pivot) or back
    /// upright; `topples` is the exact decision.
    Tipping { w: f64, h: f64, topples: bool },
    /// Time at which the lowest vertex reaches the floor, against `t` (s).
    FallTime { t: f64 },
    /// Horizontal distance of G at the landing, against `range` (m).
    Landing { range: f64 },
    /// Time at which the tilt reaches `tilt` (rad), against `t`.
    TiltTime { tilt: f64, t: f64 },
    /// Stands (no block moves more than 2 cm) or falls.
    Stack { stands: bool, aligned: bool },
    /// Block 0's final G (or, with `landing`, where it first lands after being lifted)
    /// against the reference model's.
    AgainstReference { landing: bool },
}

/// One scene of a class.
#[derive(Clone)]
struct Case {
    class: &'static str,
    name: String,
    scene: Scene,
    seconds: f64,
    judge: Judge,
    /// The scene's bare check-point hand.
    hand: bool,
}

/// One class's unit and what it is judged against.
struct ClassInfo {
    class: &'static str,
    unit: &'static str,
    what: &'static str,
    /// Whether the reference is an exact answer; if not, it is the precise model itself
    /// (the hand scenes), and the error is agreement with that model.
    exact: bool,
}

const CLASSES: [ClassInfo; 9] = [
    ClassInfo {
        class: "tipping-decision",
        unit: "% wrong",
        what: "static tipping near the critical angle: topple or not (exact: tan(tilt) > w/h)",
        exact: true,
    },
    ClassInfo {
        class: "tipping-pose",
        unit: "mm",
        what: "static tipping: final pose, largest vertex distance from the exact pose (pivoting without sliding)",
        exact: true,
    },
    ClassInfo {
        class: "drop",
        unit: "ms",
        what: "drop: time to reach the floor (exact: sqrt(2h/g))",
        exact: true,
    },
    ClassInfo {
        class: "throw",
        unit: "mm",
        what: "throw: landing point of G (exact projectile range)",
        exact: true,
    },
    ClassInfo {
        class: "tipping-dynamics",
        unit: "ms",
        what: "tipping dynamics: time for a box released past its edge to fall to 89 deg (exact: phi'' = p^2 sin phi)",
        exact: true,
    },
    ClassInfo {
        class: "stack-decision",
        unit: "% wrong",
        what: "stacks: stands or falls (exact statics: every interface carries its load's G inside its contact)",
        exact: true,
    },
    ClassInfo {
        class: "stack-sink",
        unit: "mm",
        what: "aligned towers (3 and 6 cubes): how far the top block sinks below its exact height (exact: 0)",
        exact: true,
    },
    ClassInfo {
        class: "push",
        unit: "mm",
        what: "push with a fingertip: agreement with the precise model, final G against its finest setting (no reference independent of both models exists)",
        exact: false,
    },
    ClassInfo {
        class: "grasp-throw",
        unit: "mm",
        what: "grasp, lift, throw: agreement with the precise model, where the block first lands against its finest setting (no reference independent of both models exists)",
        exact: false,
    },
];

fn class_info(class: &str) -> &'static ClassInfo {
    CLASSES
        .iter()
        .find(|c| c.class == class)
        .unwrap_or(&CLASSES[0])
}

/// The exact answers.
pub mod exact {
    /// Free fall from rest through `h` metres.
    pub fn fall_time(h: f64, g: f64) -> f64 {
        (2.0 * h / g).sqrt()
    }

    /// Horizontal range of a projectile launched at speed `v`, angle `a` (rad) above the
    /// horizontal, from `h0` above the floor.
    pub fn projectile_range(v: f64, a: f64, h0: f64, g: f64) -> f64 {
        let (s, c) = a.sin_cos();
        v * c * (v * s + (v * v * s * s + 2.0 * g * h0).sqrt()) / g
    }

    /// Time for a box (w x h, uniform, pivoting about a fixed edge without sliding) to turn
    /// from `phi0` to `phi1`, phi being the angle of pivot -> G from the vertical:
    /// phi'' = p^2 sin(phi), p^2 = 3 g / (4 R), R the half diagonal; energy gives
    /// phi'^2 = 2 p^2 (cos phi0 - cos phi). With phi = phi0 + u^2 the integrand
    /// 2u / phi'(u) is smooth at the start (the 1/sqrt singularity is gone), and
    /// cos phi0 - cos phi = 2 sin(phi0 + u^2/2) sin(u^2/2) has no cancellation; composite
    /// Gauss-Legendre (5 points) on 4000 panels is exact to far below a microsecond.
    pub fn tipping_time(w: f64, h: f64, g: f64, phi0: f64, phi1: f64) -> f64 {
        let r = 0.5 * (w * w + h * h).sqrt();
        let p2 = 3.0 * g / (4.0 * r);
        let f = |u: f64| -> f64 {
            let s = 2.0 * (phi0 + 0.5 * u * u).sin() * (0.5 * u * u).sin();
            if u == 0.0 {
                2.0 / (2.0 * p2 * phi0.sin()).sqrt()
            } else {
                2.0 * u / (2.0 * p2 * s).sqrt()
            }
        };
        let umax = (phi1 - phi0).sqrt();
        let n = 4000;
        let hstep = umax / n as f64;
        const X: [f64; 5] = [
            0.0,
            -0.538_469_310_105_683,
            0.538_469_310_105_683,
            -0.906_179_845_938_664,
            0.906_179_845_938_664,
        ];
        const W: [f64; 5] = [
            0.568_888_888_888_889,
            0.478_628_670_499_366,
            0.478_628_670_499_366,
            0.236_926_885_056_189,
            0.236_926_885_056_189,
        ];
        let mut sum = 0.0;
        for k in 0..n {
            let mid = (k as f64 + 0.5) * hstep;
            for (x, wt) in X.iter().zip(W) {
                sum += wt * f(mid + 0.5 * hstep * x);
            }
        }
        sum * 0.5 * hstep
    }

    /// The harmonic stack's offsets: block i from the top (0-based) overhangs the one below
    /// it by L / (2 (i + 1)); `n` blocks on a floor have n - 1 interfaces.
    pub fn harmonic_offsets(n: usize, length: f64) -> Vec<f64> {
        (0..n.saturating_sub(1))
            .map(|i| length / (2.0 * (i + 1) as f64))
            .collect()
    }
}

const G: f64 = 9.81;

fn block(
    name: &str,
    size: [f64; 3],
    position: DVec3,
    rotation: DQuat,
    velocity: DVec3,
) -> BlockSpec {
    BlockSpec {
        name: name.into(),
        shape: ShapeSpec::Box { size },
        position: position.to_array(),
        rotation: rotation.to_array(),
        velocity: velocity.to_array(),
    }
}

fn scene_of(name: &str, blocks: Vec<BlockSpec>) -> Scene {
    Scene {
        file: PathBuf::from(format!("<bench accuracy: {name}>")),
        world: WorldSettings {
            gravity: G,
            ..WorldSettings::default()
        },
        effects: Default::default(),
        blocks,
        hand: None,
        left_hand: None,
    }
}

/// A box w (x) by h (y) standing on its -x bottom edge at the origin, turned `tilt` about +z.
/// G beyond the edge (tilt > atan(w/h)) topples onto the -x face.
fn tilted_box(w: f64, h: f64, tilt: f64) -> BlockSpec {
    let rot = DQuat::from_rotation_z(tilt);
    let g = rot * DVec3::new(w / 2.0, h / 2.0, 0.0);
    block("box", [w, h, 0.1], g, rot, DVec3::ZERO)
}

fn cases(quick: bool) -> Vec<Case> {
    let mut v = Vec::new();
    // Static tipping: three aspect ratios, critical angle +-2, 5, 15 deg.
    let ratios: &[(f64, f64)] = if quick {
        &[(0.05, 0.1), (0.1, 0.05)]
    } else {
        &[(0.05, 0.1), (0.1, 0.1), (0.1, 0.05)]
    };
    for &(w, h) in ratios {
        let crit = (w / h).atan();
        for off in [-15.0f64, -5.0, -2.0, 2.0, 5.0, 15.0] {
            let tilt = crit + off.to_radians();
            let name = format!("{:.0}x{:.0} mm at critical {off:+} deg", w * 1e3, h * 1e3);
            let s = scene_of(&name, vec![tilted_box(w, h, tilt)]);
            v.push(Case {
                class: "tipping",
                name,
                scene: s,
                seconds: 2.0,
                judge: Judge::Tipping {
                    w,
                    h,
                    topples: off > 0.0,
                },
                hand: false,
            });
        }
    }
    // Drop: a 10 cm cube from rest, its lowest face h above the floor.
    let drops: &[f64] = if quick {
        &[0.2, 1.0]
    } else {
        &[0.05, 0.2, 0.5, 1.0]
    };
    for &h in drops {
        let name = format!("10 cm cube from {h} m");
        let s = scene_of(
            &name,
            vec![block(
                "cube",
                [0.1; 3],
                DVec3::new(0.0, h + 0.05, 0.0),
                DQuat::IDENTITY,
                DVec3::ZERO,
            )],
        );
        v.push(Case {
            class: "drop",
            name,
            scene: s,
            seconds: exact::fall_time(h, G) + 0.2,
            judge: Judge::FallTime {
                t: exact::fall_time(h, G),
            },
            hand: false,
        });
    }
    // Throw: a 5 cm cube launched from 0.3 m (its lowest face).
    let throws: &[(f64, f64)] = if quick {
        &[(2.0, 45.0)]
    } else {
        &[(2.0, 30.0), (2.0, 60.0), (4.0, 45.0)]
    };
    for &(speed, deg) in throws {
        let a = deg.to_radians();
        let name = format!("5 cm cube at {speed} m/s, {deg} deg, from 0.3 m");
        let vel = DVec3::new(speed * a.cos(), speed * a.sin(), 0.0);
        let s = scene_of(
            &name,
            vec![block(
                "cube",
                [0.05; 3],
                DVec3::new(0.0, 0.325, 0.0),
                DQuat::IDENTITY,
                vel,
            )],
        );
        let t = (speed * a.sin() + ((speed * a.sin()).powi(2) + 2.0 * G * 0.3).sqrt()) / G;
        v.push(Case {
            class: "throw",
            name,
            scene: s,
            seconds: t + 0.1,
            judge: Judge::Landing {
                range: exact::projectile_range(speed, a, 0.3, G),
            },
            hand: false,
        });
    }
    // Tipping dynamics: released past the edge by delta; the fall to 89 deg of tilt.
    let tips: &[(f64, f64, f64)] = if quick {
        &[(1.0, 1.0, 1.0)]
    } else {
        &[
            (1.0, 1.0, 1.0),
            (1.0, 1.0, 5.0),
            (0.1, 0.1, 2.0),
            (0.05, 0.1, 2.0),
        ]
    };
    for &(w, h, delta) in tips {
        let crit = (w / h).atan();
        let tilt0 = crit + delta.to_radians();
        let end = 89f64.to_radians();
        let t = exact::tipping_time(w, h, G, delta.to_radians(), end - crit);
        let name = format!("{w} x {h} m box {delta} deg past its edge");
        v.push(Case {
            class: "tipping-dynamics",
            name: name.clone(),
            scene: scene_of(&name, vec![tilted_box(w, h, tilt0)]),
            seconds: t + 0.3,
            judge: Judge::TiltTime { tilt: end, t },
            hand: false,
        });
    }
    // Stacks of 10 cm cubes, placed 0.5 mm apart so that each settles onto the one below.
    // Placed exactly touching, rapier resolves the coincident faces at distance 0 with
    // sideways normals and topples even an aligned tower (a known hard case for engines):
    // a reference must not be judged on that, and the gap costs the paper model nothing
    // (R12 stops the short fall at first contact).
    const GAP: f64 = 0.0005;
    let tower = |n: usize| -> Vec<BlockSpec> {
        (0..n)
            .map(|i| {
                block(
                    &format!("b{i}"),
                    [0.1; 3],
                    DVec3::new(0.0, 0.05 + (0.1 + GAP) * i as f64, 0.0),
                    DQuat::IDENTITY,
                    DVec3::ZERO,
                )
            })
            .collect()
    };
    let harmonic = |n: usize, scale: f64| -> Vec<BlockSpec> {
        // Offsets from the top down; the bottom block sits on the floor at x = 0.
        let offs = exact::harmonic_offsets(n, 0.1);
        let mut x = vec![0.0; n];
        // x[i] for block i from the bottom: x[i] = x[i-1] + offset of (block i over i-1).
        for i in 1..n {
            let from_top = n - 1 - i;
            x[i] = x[i - 1] + scale * offs[from_top];
        }
        (0..n)
            .map(|i| {
                block(
                    &format!("b{i}"),
                    [0.1; 3],
                    DVec3::new(x[i], 0.05 + (0.1 + GAP) * i as f64, 0.0),
                    DQuat::IDENTITY,
                    DVec3::ZERO,
                )
            })
            .collect()
    };
    let mut stacks: Vec<(String, Vec<BlockSpec>, bool, bool)> = vec![
        ("tower of 3".into(), tower(3), true, true),
        (
            "harmonic stack of 4 at 99%".into(),
            harmonic(4, 0.99),
            true,
            false,
        ),
        (
            "harmonic stack of 4 at 101%".into(),
            harmonic(4, 1.01),
            false,
            false,
        ),
    ];
    if !quick {
        stacks.insert(1, ("tower of 6".into(), tower(6), true, true));
    }
    for (name, blocks, stands, aligned) in stacks {
        v.push(Case {
            class: "stack",
            name: name.clone(),
            scene: scene_of(&name, blocks),
            seconds: 2.0,
            judge: Judge::Stack { stands, aligned },
            hand: false,
        });
    }
    // Hand scenes. The push is config/scenes/push.toml's with the fingertip 2 cm above the
    // floor instead of at G's height: pushed at G's height a block with perfect friction
    // tips over its far edge (the push force needed to tip it, m g w / 2h, is below the one
    // needed to slide it, mu m g), and whether it rolls on or falls back is decided by
    // fractions of a millimetre: no setting of any model converges there. Low down it slides
    // and turns, as R4 says. The grasp-throw is the shipped scene; it is judged by where the
    // thrown block first lands (the tumbling after is as chaotic).
    for (class, file, text, seconds, landing, contact_hz) in [
        (
            "push",
            "push (fingertip 2 cm high)",
            PUSH_LOW,
            1.5,
            false,
            None,
        ),
        (
            "grasp-throw",
            "config/scenes/grasp-throw-fingers.toml",
            include_str!("../../config/scenes/grasp-throw-fingers.toml"),
            2.0,
            true,
            Some(GRASP_CONTACT_HZ),
        ),
    ] {
        if let Some(mut s) = load_text("hand-scene.toml", text) {
            s.world.precise.bare_finger_radius = FINGER_RADIUS;
            if contact_hz.is_some() {
                s.world.precise.contact_hz = contact_hz;
            }
            v.push(Case {
                class,
                name: file.into(),
                scene: s,
                seconds,
                judge: Judge::AgainstReference { landing },
                hand: true,
            });
        }
    }
    v
}

/// The precise model's finger radius in the hand scenes, m. The paper model's bare fingers
/// are points (radius 0), but a rapier collider needs a radius; at the scenes' default 2 mm
/// part of the paper model's "error" was the finger's thickness (a pushing fingertip's surface
/// 2 mm ahead of the paper's point, a grasp squeezing 2.5 mm into the block instead of the
/// scripted 0.5 mm). So the bench gives the precise model the thinnest capsule it handles,
/// which leaves the two models' fingers at most this far apart.
const FINGER_RADIUS: f64 = 1e-4;

/// The precise model's contact stiffness in the grasp-throw scene, Hz. The grasp holds the
/// block by squeezing it between kinematic fingers scripted 0.5 mm inside its faces, so the
/// grip is the contact spring's force. At the default stiffness (0.125 / substep dt) every
/// halving of the substep doubles the spring's frequency: it changes the grip, not only the
/// resolution, and the landing point scattered by 10 to 40 cm between neighbouring settings
/// (above ~500 Hz of contact stiffness), so the reference never converged. With the spring
/// fixed at 100 or 200 Hz the landing stays within ~1 mm from 240 Hz x 4 to 960 Hz x 32
/// substeps (halving the substep moves it by 0.0-0.5% of its 0.83 m travel); 500 Hz converged
/// only at 960 Hz, 1000 Hz nowhere (the `reference_sweep` test prints these figures).
const GRASP_CONTACT_HZ: f64 = 200.0;

const PUSH_LOW: &str = r#"
[[block]]
name = "cube"
shape = "box"
size = [0.1, 0.1, 0.1]
position = [0.0, 0.05, 0.0]

[hand]
[[hand.key]]
t = 0.0
wrist = [-0.1, 0.02, 0.03]
fingers = [[[0.0, 0.0, 0.0]]]
[[hand.key]]
t = 0.6
wrist = [-0.02, 0.02, 0.03]
fingers = [[[0.0, 0.0, 0.0]]]
[[hand.key]]
t = 0.7
wrist = [-0.06, 0.02, 0.03]
fingers = [[[0.0, 0.0, 0.0]]]
"#;

/// A scene from its text, through the real loader (a temporary file).
fn load_text(name: &str, text: &str) -> Option<Scene> {
    let dir = std::env::temp_dir().join(format!("hb-accuracy-{}", std::process::id()));
    std::fs::create_dir_all(&dir).ok()?;
    let file = dir.join(name);
    std::fs::write(&file, text).ok()?;
    let s = Scene::load(&file).ok();
    let _ = std::fs::remove_file(&file);
    let _ = std::fs::remove_dir(&dir);
    s
}

/// One run's poses: every block after every step (index 0: the start).
struct Trace {
    blocks: usize,
    poses: Vec<(DVec3, DQuat)>,
    us_per_step: f64,
}

impl Trace {
    fn at(&self, step: usize, block: usize) -> (DVec3, DQuat) {
        self.poses[step * self.blocks + block]
    }
    fn steps(&self) -> usize {
        self.poses.len() / self.blocks.max(1) - 1
    }
}

fn run_once(case: &Case, setting: Setting) -> Result<Trace, String> {
    let mut scene = case.scene.clone();
    setting.apply(&mut scene);
    let dt = 1.0 / scene.world.step_hz;
    let frames = (case.seconds * scene.world.step_hz).ceil() as u64;
    let mut model = Model::new(&scene).map_err(|e| e.to_string())?;
    let mut hand = if case.hand {
        BareFingersHand::from_scene(&scene)
    } else {
        None
    };
    let n = model.block_count();
    let mut poses = Vec::with_capacity((frames as usize + 1) * n);
    let record = |m: &Model, poses: &mut Vec<(DVec3, DQuat)>| {
        for i in 0..n {
            if let Some(b) = m.block(i) {
                poses.push((b.position, b.rotation));
            }
        }
    };
    record(&model, &mut poses);
    if let Some(h) = hand.as_mut() {
        let first = h.hand_at(0, 0.0);
        model.set_previous_hand(first.as_ref());
    }
    let start = Instant::now();
    for k in 1..=frames {
        let sample = hand.as_mut().and_then(|h| h.hand_at(k, k as f64 * dt));
        model.step(sample.as_ref());
        record(&model, &mut poses);
    }
    let us = start.elapsed().as_secs_f64() * 1e6 / frames.max(1) as f64;
    Ok(Trace {
        blocks: n,
        poses,
        us_per_step: us,
    })
}

fn vertices(case: &Case, block: usize) -> Vec<DVec3> {
    case.scene
        .blocks
        .get(block)
        .and_then(|b| Polyhedron::from_spec(&b.shape).ok())
        .map(|p| p.vertices)
        .unwrap_or_default()
}

fn lowest(verts: &[DVec3], pose: (DVec3, DQuat)) -> f64 {
    verts
        .iter()
        .map(|v| (pose.0 + pose.1 * *v).y)
        .fold(f64::INFINITY, f64::min)
}

/// The first step at which `f` (a per-step value, rising) crosses `target`, interpolated
/// linearly between that step and the one before: a time in steps.
fn crossing(values: &[f64], target: f64) -> Option<f64> {
    let k = values.iter().position(|v| *v >= target)?;
    if k == 0 {
        return Some(0.0);
    }
    let (a, b) = (values[k - 1], values[k]);
    let f = if b > a { (target - a) / (b - a) } else { 1.0 };
    Some((k - 1) as f64 + f.clamp(0.0, 1.0))
}

/// The first step from `from` at which a block whose lowest vertex is at `ys` (one per step
/// end) has touched the floor: its lowest vertex within 1 mm of it, or the bottom of a hop (a
/// step lower than both its neighbours: in flight the height is concave, so a low point between
/// two higher ones is a contact within that step, and a cube that lands and hops may never end
/// a step within 1 mm of the floor). None: it never touched.
fn touchdown(ys: &[f64], from: usize) -> Option<usize> {
    (from..ys.len()).find(|&k| {
        ys[k] <= 1e-3 || (k > from && k + 1 < ys.len() && ys[k - 1] > ys[k] && ys[k + 1] > ys[k])
    })
}

/// The landing of block 0: the first step its lowest vertex is within 1 mm of the floor or
/// hops off it ([`touchdown`]),
/// placed within the step by the speed of the step before (so a model is not charged a whole
/// step for where in its step the floor was crossed). Returns (time in steps, G's horizontal
/// distance at that time).
fn landing(trace: &Trace, verts: &[DVec3]) -> Option<(f64, f64)> {
    let ys: Vec<f64> = (0..=trace.steps())
        .map(|k| lowest(verts, trace.at(k, 0)))
        .collect();
    let k = touchdown(&ys, 0)?;
    let horizontal = |k: usize| {
        let p = trace.at(k, 0).0;
        (p.x * p.x + p.z * p.z).sqrt()
    };
    if k == 0 {
        return Some((0.0, horizontal(0)));
    }
    let drop = if k >= 2 {
        ys[k - 2] - ys[k - 1]
    } else {
        ys[k - 1] - ys[k]
    };
    let f = if drop > 0.0 {
        (ys[k - 1] / drop).clamp(0.0, 1.0)
    } else {
        1.0
    };
    let x_prev = horizontal(k - 1);
    let dx = if k >= 2 {
        x_prev - horizontal(k - 2)
    } else {
        horizontal(k) - x_prev
    };
    Some(((k - 1) as f64 + f, x_prev + f * dx))
}

/// Where block 0 first touches the floor ([`touchdown`]) after having been lifted 5 cm clear
/// of it: G at that step, moved on within the step as in [`landing`].
fn landing_after_lift(trace: &Trace, verts: &[DVec3]) -> Option<DVec3> {
    let ys: Vec<f64> = (0..=trace.steps())
        .map(|k| lowest(verts, trace.at(k, 0)))
        .collect();
    let lifted = ys.iter().position(|y| *y > 0.05)?;
    let k = touchdown(&ys, lifted)?;
    if k < 2 {
        return Some(trace.at(k, 0).0);
    }
    let drop = ys[k - 2] - ys[k - 1];
    let f = if drop > 0.0 {
        (ys[k - 1] / drop).clamp(0.0, 1.0)
    } else {
        1.0
    };
    let (p1, p2) = (trace.at(k - 1, 0).0, trace.at(k - 2, 0).0);
    Some(p1 + f * (p1 - p2))
}

/// A scene's measured answers: the value judged, and the decision where there is one.
struct Measured {
    /// Class-unit error per sub-class (e.g. tipping gives a decision and a pose).
    errors: Vec<(&'static str, f64)>,
}

fn judge(case: &Case, trace: &Trace, dt: f64, reference: Option<DVec3>) -> Measured {
    let last = trace.steps();
    let verts = vertices(case, 0);
    let mut errors = Vec::new();
    match case.judge {
        Judge::Tipping { w, h, topples } => {
            let (g, q) = trace.at(last, 0);
            let up = q * DVec3::Y;
            let tilt = up.y.clamp(-1.0, 1.0).acos();
            let toppled = tilt > std::f64::consts::FRAC_PI_4;
            errors.push((
                "tipping-decision",
                if toppled == topples { 0.0 } else { 100.0 },
            ));
            let (eg, eq) = if topples {
                (
                    DVec3::new(-h / 2.0, w / 2.0, 0.0),
                    DQuat::from_rotation_z(std::f64::consts::FRAC_PI_2),
                )
            } else {
                (DVec3::new(w / 2.0, h / 2.0, 0.0), DQuat::IDENTITY)
            };
            let worst = verts
                .iter()
                .map(|v| ((g + q * *v) - (eg + eq * *v)).length())
                .fold(0.0, f64::max);
            errors.push(("tipping-pose", worst * 1e3));
        }
        Judge::FallTime { t } => {
            let e = landing(trace, &verts)
                .map(|(steps, _)| (steps * dt - t).abs() * 1e3)
                .unwrap_or(f64::INFINITY);
            errors.push(("drop", e));
        }
        Judge::Landing { range } => {
            let e = landing(trace, &verts)
                .map(|(_, x)| (x - range).abs() * 1e3)
                .unwrap_or(f64::INFINITY);
            errors.push(("throw", e));
        }
        Judge::TiltTime { tilt, t } => {
            let tilts: Vec<f64> = (0..=last)
                .map(|k| (trace.at(k, 0).1 * DVec3::Y).y.clamp(-1.0, 1.0).acos())
                .collect();
            let e = crossing(&tilts, tilt)
                .map(|steps| (steps * dt - t).abs() * 1e3)
                .unwrap_or(f64::INFINITY);
            errors.push(("tipping-dynamics", e));
        }
        Judge::Stack { stands, aligned } => {
            // Moved: horizontally, or down by more than the settling gaps.
            let moved = (0..trace.blocks)
                .map(|i| {
                    let d = trace.at(last, i).0 - trace.at(0, i).0;
                    f64::hypot(d.x, d.z).max(-d.y - 0.001 * i as f64)
                })
                .fold(0.0, f64::max);
            let stood = moved < 0.02;
            errors.push(("stack-decision", if stood == stands { 0.0 } else { 100.0 }));
            if aligned {
                // Sink (aligned towers only: a staggered stack that falls has no sink): below the exact resting height of the top block (cubes of 10 cm).
                let top = trace.blocks - 1;
                let exact_y = 0.05 + 0.1 * top as f64;
                let sink = exact_y - trace.at(last, top).0.y;
                errors.push(("stack-sink", sink.max(0.0) * 1e3));
            }
        }
        Judge::AgainstReference { landing } => {
            let answer = if landing {
                landing_after_lift(trace, &verts)
            } else {
                Some(trace.at(last, 0).0)
            };
            let e = match (reference, answer) {
                (Some(r), Some(a)) => (a - r).length() * 1e3,
                (Some(_), None) => f64::INFINITY,
                _ => f64::NAN,
            };
            errors.push((case.class, e));
        }
    }
    Measured { errors }
}

/// One row of the report: one scene under one setting.
#[derive(Debug, Clone)]
pub struct Row {
    pub class: String,
    pub scene: String,
    pub model: String,
    pub setting: String,
    /// The error in the class's unit. NaN where the scene has no converged reference: an
    /// unmeasured error must never read as 0, the best score there is. Infinite where the
    /// judged event never happened (a block that never lands).
    pub error: f64,
    pub unit: String,
    /// Median over the timed rounds of the time per step, us.
    pub us_per_step: f64,
    /// Median over the timed rounds of the time per simulated second (time per step x step
    /// rate), us: the time axis of every comparison, since settings differ in step rate (a
    /// 480 Hz step covers an eighth of the simulated time of a 60 Hz step).
    pub us_per_sim_s: f64,
    /// Each timed round's time per simulated second, in round order: round k of every setting
    /// of a scene ran in the same pass ([`time_interleaved`]).
    pub rounds_us_per_sim_s: Vec<f64>,
}

fn settings(quick: bool) -> (Vec<Setting>, Vec<Setting>) {
    let paper = [30.0, 60.0, 120.0, 240.0, 480.0]
        .into_iter()
        .map(|hz| Setting::Paper { hz })
        .collect();
    let (rates, subs, its): (&[f64], &[u32], &[u32]) = if quick {
        (&[60.0, 240.0], &[1, 4], &[2])
    } else {
        (&[60.0, 120.0, 240.0, 480.0], &[1, 2, 4, 8, 16], &[1, 4])
    };
    // Sleeping off and on: a scene that ends at rest should not charge rapier for a body
    // lying still (the paper model skips it), nor should sleeping be assumed harmless (it can
    // freeze a block tipping slowly).
    let mut precise = Vec::new();
    for &hz in rates {
        for &substeps in subs {
            for &iterations in its {
                for sleep in [false, true] {
                    precise.push(Setting::Precise {
                        hz,
                        substeps,
                        iterations,
                        sleep,
                    });
                }
            }
        }
    }
    (paper, precise)
}

/// Whether `a` is `b` but for sleeping.
fn same_but_sleep(a: Setting, b: Setting) -> bool {
    let awake = |s: Setting| match s {
        Setting::Precise {
            hz,
            substeps,
            iterations,
            ..
        } => Setting::Precise {
            hz,
            substeps,
            iterations,
            sleep: false,
        },
        other => other,
    };
    awake(a) == awake(b)
}

/// The reference setting for the hand scenes: the finest scored rate and substeps, and twice
/// the scored settings' most solver iterations (8: with 4, as the scored settings' finest, the
/// push's reference moved 1.94 mm when its iterations halved, more than a third of the paper
/// model's 5.7 mm, so the class could not be judged; with 8 its change is 1.5 mm).
fn reference_setting(quick: bool) -> Setting {
    let (hz, sub) = if quick { (240.0, 8) } else { (480.0, 16) };
    Setting::Precise {
        hz,
        substeps: sub,
        iterations: 8,
        sleep: false,
    }
}

/// The reference with each of the knobs the scored settings vary one notch coarser: half the
/// step rate, half the substeps, half the solver iterations, sleeping on. How far the judged
/// answer moves under the worst of them is the reference's own uncertainty (its *change*).
fn reference_variants(reference: Setting) -> Vec<(&'static str, Setting)> {
    let Setting::Precise {
        hz,
        substeps,
        iterations,
        sleep,
    } = reference
    else {
        return Vec::new();
    };
    let at = |hz: f64, substeps: u32, iterations: u32, sleep: bool| Setting::Precise {
        hz,
        substeps,
        iterations,
        sleep,
    };
    vec![
        ("half the rate", at(hz / 2.0, substeps, iterations, sleep)),
        (
            "half the substeps",
            at(hz, (substeps / 2).max(1), iterations, sleep),
        ),
        (
            "half the iterations",
            at(hz, substeps, (iterations / 2).max(1), sleep),
        ),
        ("sleeping on", at(hz, substeps, iterations, true)),
    ]
}

/// Timed rounds per scene, after a warm-up round. Each round times every setting once, in
/// turn; with five, one outlying round cannot move the median.
const ROUNDS: usize = 5;

/// One setting's measurement on one scene: the warm-up run's poses (the models are
/// deterministic: every run gives the same ones) and each timed round's time per step.
struct Timed {
    trace: Trace,
    rounds_us_per_step: Vec<f64>,
}

/// Runs every setting on `case` once to warm up, then `rounds` rounds, each timing every
/// setting once in the order given (round k of all settings, then round k + 1). Interleaved so
/// that a slow spell of this shared machine (another process, a clock change) falls on every
/// setting of a round alike, not on whichever model happened to be timed at the time. A
/// setting that fails keeps its error and is left out of the later rounds.
fn time_interleaved(
    case: &Case,
    settings: &[Setting],
    rounds: usize,
) -> Vec<Result<Timed, String>> {
    let mut out: Vec<Result<Timed, String>> = settings
        .iter()
        .map(|s| {
            run_once(case, *s).map(|trace| Timed {
                trace,
                rounds_us_per_step: Vec::with_capacity(rounds),
            })
        })
        .collect();
    // Round r starts at setting r (mod n), so that no setting is always timed first (the first
    // of a round ran 3.7x slower per step than its neighbour on the same falling cube, issue 42).
    let n = settings.len();
    for round in 0..rounds {
        for k in 0..n {
            let i = (k + round) % n;
            if out[i].is_err() {
                continue;
            }
            match reading(case, settings[i]) {
                Ok(us) => {
                    if let Ok(timed) = &mut out[i] {
                        timed.rounds_us_per_step.push(us);
                    }
                }
                Err(e) => out[i] = Err(e),
            }
        }
    }
    out
}

/// A run shorter than this is repeated within one reading (a paper model run is a few
/// microseconds: one run is mostly the timer and the cache).
const MIN_READING_NS: u128 = 2_000_000;
/// The most runs one reading repeats.
const MAX_READING_RUNS: usize = 200;

/// One timed reading of `setting`: its time per step, the median over as many runs as fill
/// [`MIN_READING_NS`] (at least one, at most [`MAX_READING_RUNS`]).
fn reading(case: &Case, setting: Setting) -> Result<f64, String> {
    let started = std::time::Instant::now();
    let mut per_step = Vec::new();
    while per_step.is_empty()
        || (started.elapsed().as_nanos() < MIN_READING_NS && per_step.len() < MAX_READING_RUNS)
    {
        per_step.push(run_once(case, setting)?.us_per_step);
    }
    Ok(median(&per_step))
}

/// The median of the finite values; NaN when there are none (not 0: a time never measured
/// is not a free one).
pub(crate) fn median(values: &[f64]) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Median, smallest and largest of per-round values.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spread {
    pub median: f64,
    pub min: f64,
    pub max: f64,
}

/// The spread of the finite values; None when there are none.
fn spread(values: &[f64]) -> Option<Spread> {
    let finite: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if finite.is_empty() {
        return None;
    }
    Some(Spread {
        median: median(&finite),
        min: finite.iter().copied().fold(f64::INFINITY, f64::min),
        max: finite.iter().copied().fold(f64::NEG_INFINITY, f64::max),
    })
}

/// A hand scene's reference and its uncertainty, measured in the run: the precise model at
/// its finest setting against each of [`reference_variants`].
#[derive(Debug, Clone)]
pub struct ReferenceCheck {
    pub class: &'static str,
    pub scene: String,
    pub setting: String,
    /// Per variant: what was coarsened, the setting, and how far the judged answer moved, m
    /// (NaN: that run never landed).
    pub changes: Vec<(&'static str, String, f64)>,
    /// The largest of `changes` (NaN if any is): the reference's change.
    pub change_m: f64,
    /// The block's travel in the reference run (start to the judged answer), m.
    pub travel_m: f64,
}

/// A class is judged only where its reference's change is under this share of the smallest
/// error it judges (the paper model's best): otherwise the reference cannot tell the errors
/// it would rank apart.
const JUDGED_BELOW_SHARE: f64 = 1.0 / 3.0;

/// Runs the benchmark and writes its three files; returns the rows.
pub fn run(b: &AccuracyBench) -> Result<Vec<Row>, Box<dyn std::error::Error>> {
    std::fs::create_dir_all(&b.out_dir)
        .map_err(|e| format!("{}: cannot create: {e}", b.out_dir.display()))?;
    let started = Instant::now();
    let runs = b.runs.max(1);
    let mut wholes = Vec::with_capacity(runs);
    for k in 0..runs {
        eprintln!("accuracy: whole run {} of {runs}", k + 1);
        wholes.push(whole_run(b)?);
    }
    let across = across_runs(&wholes);
    let Some(w) = wholes.pop() else {
        return Err("no run".into());
    };
    write_json(&b.out_dir.join("accuracy.json"), &w, &across, runs)?;
    let provenance = Provenance::of_this_run(b.quick, &b.out_dir);
    let md = markdown(&w, &across, runs, &provenance);
    std::fs::write(b.out_dir.join("accuracy.md"), &md)
        .map_err(|e| format!("{}: {e}", b.out_dir.join("accuracy.md").display()))?;
    let png = b.out_dir.join("accuracy.png");
    let text = figure(&w.summary, &w.pareto).write_png(&png)?;
    if !text {
        eprintln!(
            "accuracy: no TrueType font found (install fonts-dejavu-core or set HB_PLOT_FONT): {} has no labels",
            png.display()
        );
    }
    println!("{}", across_runs_table(&w.verdicts, &across, runs));
    println!(
        "accuracy: {runs} whole runs of {} rows in {:.0} s; wrote {}, accuracy.md, accuracy.png",
        w.rows.len(),
        started.elapsed().as_secs_f64(),
        b.out_dir.join("accuracy.json").display()
    );
    Ok(w.rows)
}

/// One whole run: every scene's references, then every setting on every scene in interleaved
/// rounds, summarised and judged.
fn whole_run(b: &AccuracyBench) -> Result<Whole, Box<dyn std::error::Error>> {
    let cases = cases(b.quick);
    let (paper, precise) = settings(b.quick);
    let reference = reference_setting(b.quick);
    let variants = reference_variants(reference);
    let started = Instant::now();
    let mut notes = Vec::new();

    // The hand scenes' references, each with its change: how far its judged answer moves when
    // each knob the scored settings vary goes one notch coarser. A class is judged only where
    // that change is under a third of the smallest error it judges (see `verdicts`).
    let mut references: Vec<Option<DVec3>> = vec![None; cases.len()];
    let mut checks: Vec<ReferenceCheck> = Vec::new();
    for (i, c) in cases.iter().enumerate() {
        let Judge::AgainstReference { landing } = c.judge else {
            continue;
        };
        let verts = vertices(c, 0);
        let answer = |t: &Trace| {
            if landing {
                landing_after_lift(t, &verts)
            } else {
                Some(t.at(t.steps(), 0).0)
            }
        };
        let fine = run_once(c, reference)?;
        let start = fine.at(0, 0).0;
        let end = answer(&fine);
        let mut changes = Vec::with_capacity(variants.len());
        for (what, setting) in &variants {
            let other = run_once(c, *setting)?;
            let change = match (end, answer(&other)) {
                (Some(e), Some(o)) => (o - e).length(),
                _ => f64::NAN,
            };
            changes.push((*what, setting.label(), change));
        }
        let change = if changes.iter().any(|(_, _, c)| c.is_nan()) {
            f64::NAN
        } else {
            changes.iter().map(|(_, _, c)| *c).fold(0.0, f64::max)
        };
        let travel = end.map_or(f64::NAN, |e| (e - start).length());
        let line = format!(
            "{} / {}: reference = precise at {}, the judged G {} mm from the start; its change \
             (the largest move of that G with one knob one notch coarser) {} mm: {}",
            c.class,
            c.name,
            reference.label(),
            fmt_err(travel * 1e3),
            fmt_err(change * 1e3),
            changes
                .iter()
                .map(|(what, label, m)| format!("{what} ({label}) {} mm", fmt_err(m * 1e3)))
                .collect::<Vec<_>>()
                .join(", ")
        );
        eprintln!("accuracy: {line}");
        notes.push(line);
        checks.push(ReferenceCheck {
            class: c.class,
            scene: c.name.clone(),
            setting: reference.label(),
            changes,
            change_m: change,
            travel_m: travel,
        });
        if change.is_finite() {
            references[i] = end;
        }
    }
    let changes = class_changes(&checks);

    let mut rows = Vec::new();
    let r14: Vec<Setting> = paper
        .iter()
        .map(|s| Setting::PaperR14 { hz: s.hz() })
        .collect();
    let all: Vec<Setting> = paper.iter().chain(&r14).chain(&precise).copied().collect();
    let mut r14_missing = false;
    for (ci, c) in cases.iter().enumerate() {
        let t0 = Instant::now();
        let mut these: Vec<Setting> = Vec::with_capacity(all.len());
        for s in &all {
            if matches!(s, Setting::PaperR14 { .. }) && (c.class != "stack" || r14_missing) {
                continue;
            }
            // The reference's agreement with itself is 0 by definition: not a measurement. So
            // is its twin with sleeping on, which runs the same steps while anything moves (a
            // fresh run scored it 0 and called it the precise model's best).
            if matches!(c.judge, Judge::AgainstReference { .. }) && same_but_sleep(*s, reference) {
                continue;
            }
            these.push(*s);
        }
        let results = time_interleaved(c, &these, ROUNDS);
        let mut ran = 0;
        for (setting, result) in these.iter().zip(results) {
            let timed = match result {
                Ok(t) => t,
                Err(e) if matches!(setting, Setting::PaperR14 { .. }) => {
                    // A build without R14 refuses the option: say so once, skip the line.
                    if !r14_missing {
                        notes.push(format!("paper-R14 not measured: {e}"));
                    }
                    r14_missing = true;
                    continue;
                }
                Err(e) => {
                    notes.push(format!(
                        "{} under {} {}: {e}",
                        c.name,
                        setting.model(),
                        setting.label()
                    ));
                    continue;
                }
            };
            ran += 1;
            let hz = setting.hz();
            let rounds_us_per_sim_s: Vec<f64> =
                timed.rounds_us_per_step.iter().map(|us| us * hz).collect();
            let us_per_step = median(&timed.rounds_us_per_step);
            for (class, error) in judge(c, &timed.trace, 1.0 / hz, references[ci]).errors {
                rows.push(Row {
                    class: class.into(),
                    scene: c.name.clone(),
                    model: setting.model().into(),
                    setting: setting.label(),
                    error,
                    unit: class_info(class).unit.into(),
                    us_per_step,
                    us_per_sim_s: us_per_step * hz,
                    rounds_us_per_sim_s: rounds_us_per_sim_s.clone(),
                });
            }
        }
        eprintln!(
            "accuracy: [{}/{}] {} / {}: {} settings x {} rounds in {:.1} s ({:.0} s so far)",
            ci + 1,
            cases.len(),
            c.class,
            c.name,
            ran,
            ROUNDS,
            t0.elapsed().as_secs_f64(),
            started.elapsed().as_secs_f64()
        );
    }
    let mut summary = summarise(&rows);
    for p in &mut summary {
        p.reference_change = change_of(&changes, &p.class);
    }
    let pareto = pareto_of(&summary);
    let verdicts = verdicts(&summary, &changes);
    Ok(Whole {
        rows,
        summary,
        pareto,
        verdicts,
        checks,
        notes,
        reference,
    })
}

/// A class's figure for one model setting: the worst error over the class's scenes (for
/// decisions: the share wrong) and the mean time over them.
#[derive(Debug, Clone)]
pub struct Point {
    pub class: String,
    pub model: String,
    pub setting: String,
    /// NaN when any of the class's scenes has no reference (see [`class_error`]).
    pub error: f64,
    /// The mean over the class's scenes of their median time per step (a column only).
    pub us_per_step: f64,
    /// The median of `rounds_us_per_sim_s`: the time axis of every comparison.
    pub us_per_sim_s: f64,
    /// Round k: the mean over the class's scenes of round k's time per simulated second.
    pub rounds_us_per_sim_s: Vec<f64>,
    /// The class's reference change in the class's unit (NaN for an exact answer): an error
    /// at or below it cannot be told from the reference's own uncertainty ("<= change").
    pub reference_change: f64,
}

impl Point {
    /// Whether the error is within the reference's change (never for an exact answer).
    pub fn within_change(&self) -> bool {
        self.reference_change.is_finite() && self.error <= self.reference_change
    }
    /// The error as a ranking sees it: an error within the reference's change is the change
    /// (the reference cannot rank errors below it).
    fn ranked_error(&self) -> f64 {
        if self.within_change() {
            self.reference_change
        } else {
            self.error
        }
    }
}

/// Per class against a reference, its change in the class's unit (mm): the largest over the
/// class's scenes (NaN where any scene's reference never landed).
fn class_changes(checks: &[ReferenceCheck]) -> Vec<(&'static str, f64)> {
    let mut out: Vec<(&'static str, f64)> = Vec::new();
    for k in checks {
        let mm = k.change_m * 1e3;
        match out.iter_mut().find(|(c, _)| *c == k.class) {
            Some((_, v)) => {
                *v = if v.is_nan() || mm.is_nan() {
                    f64::NAN
                } else {
                    v.max(mm)
                }
            }
            None => out.push((k.class, mm)),
        }
    }
    out
}

/// A class's reference change (NaN: the class has an exact answer, or no reference landed).
fn change_of(changes: &[(&'static str, f64)], class: &str) -> f64 {
    changes
        .iter()
        .find(|(c, _)| *c == class)
        .map_or(f64::NAN, |(_, v)| *v)
}

/// A class's error from its scenes' errors: for decisions the share wrong (the mean), else
/// the worst. NaN (a scene with no reference) or no scene at all makes the class's error NaN:
/// folding from 0 with `f64::max` would drop the NaN and score an unmeasured class 0, the
/// best error there is.
fn class_error(unit: &str, errors: &[f64]) -> f64 {
    if errors.is_empty() || errors.iter().any(|e| e.is_nan()) {
        return f64::NAN;
    }
    if unit == "% wrong" {
        errors.iter().sum::<f64>() / errors.len() as f64
    } else {
        errors.iter().copied().fold(f64::NEG_INFINITY, f64::max)
    }
}

fn summarise(rows: &[Row]) -> Vec<Point> {
    let mut out: Vec<Point> = Vec::new();
    for info in &CLASSES {
        let mut keys: Vec<(String, String)> = Vec::new();
        for r in rows.iter().filter(|r| r.class == info.class) {
            let k = (r.model.clone(), r.setting.clone());
            if !keys.contains(&k) {
                keys.push(k);
            }
        }
        for (model, setting) in keys {
            let rs: Vec<&Row> = rows
                .iter()
                .filter(|r| r.class == info.class && r.model == model && r.setting == setting)
                .collect();
            let n = rs.len() as f64;
            let errors: Vec<f64> = rs.iter().map(|r| r.error).collect();
            let rounds = rs
                .iter()
                .map(|r| r.rounds_us_per_sim_s.len())
                .min()
                .unwrap_or(0);
            let per_round: Vec<f64> = (0..rounds)
                .map(|k| rs.iter().map(|r| r.rounds_us_per_sim_s[k]).sum::<f64>() / n)
                .collect();
            // The median of the same per-round values whose spread is reported (the mean of
            // the scenes' medians could fall outside that spread); without rounds, the mean.
            let us_per_sim_s = if per_round.is_empty() {
                rs.iter().map(|r| r.us_per_sim_s).sum::<f64>() / n
            } else {
                median(&per_round)
            };
            out.push(Point {
                class: info.class.into(),
                model,
                setting,
                error: class_error(info.unit, &errors),
                us_per_step: rs.iter().map(|r| r.us_per_step).sum::<f64>() / n,
                us_per_sim_s,
                rounds_us_per_sim_s: per_round,
                reference_change: f64::NAN,
            });
        }
    }
    out
}

/// Per class, the settings (of either model) that no other setting of the class beats in
/// both time per simulated second and error. Per step would favour high step rates, whose
/// steps are cheap but many: a 480 Hz setting at 1 us per step costs 480 us per simulated
/// second, more than a 30 Hz one at 10 us per step.
fn pareto_of(points: &[Point]) -> Vec<Point> {
    let mut out = Vec::new();
    for info in &CLASSES {
        let ps: Vec<&Point> = points
            .iter()
            .filter(|p| p.class == info.class && p.error.is_finite())
            .collect();
        // Errors within the reference's change are the change: the front does not rank what
        // the reference cannot tell apart.
        let xy: Vec<(f64, f64)> = ps
            .iter()
            .map(|p| (p.us_per_sim_s, p.ranked_error()))
            .collect();
        for i in pareto_front(&xy) {
            out.push(ps[i].clone());
        }
    }
    out
}

/// What a class was judged against in this run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Against {
    /// An exact answer.
    Exact,
    /// The precise model at its finest setting, its change under a third of the smallest
    /// error judged: agreement, not accuracy.
    PreciseModel,
    /// The precise model's reference did not land under one of its variants: no change, so
    /// nothing is judged.
    NoConvergedReference,
    /// The reference's change is not under a third of the smallest error judged (the paper
    /// model's best): the errors are shown, but no verdict and no ratio.
    ReferenceTooCoarse,
}

impl Against {
    fn label(self) -> &'static str {
        match self {
            Against::Exact => "exact answer",
            Against::PreciseModel => "agreement with the precise model",
            Against::NoConvergedReference => "no converged reference",
            Against::ReferenceTooCoarse => "reference too coarse to judge",
        }
    }

    fn key(self) -> &'static str {
        match self {
            Against::Exact => "exact",
            Against::PreciseModel => "precise-model",
            Against::NoConvergedReference => "none",
            Against::ReferenceTooCoarse => "reference-too-coarse",
        }
    }
}

/// One line of the summary: per class the paper model's (or paper-R14's) best point and the
/// precise model's, each the cheapest setting per simulated second reaching that model's best
/// error, and the time ratio precise/paper per simulated second in each round.
#[derive(Debug, Clone)]
pub struct Verdict {
    pub class: &'static str,
    /// "paper" or "paper-R14".
    pub paper_model: &'static str,
    pub against: Against,
    /// The reference's change in the class's unit (NaN: an exact answer).
    pub reference_change: f64,
    /// The smallest error the verdict rests on: the paper model's best (NaN: none).
    pub smallest_error_judged: f64,
    /// None where the class has no converged reference (no verdict) or no finite error.
    pub paper: Option<Point>,
    pub precise: Option<Point>,
    /// Round k: the precise point's time per simulated second over the paper point's (best
    /// against best: each model at its own best error, not at equal accuracy).
    pub ratios: Vec<f64>,
    /// At matched error, the paper model's best as the target: the cheapest precise setting at
    /// least as accurate (None: none is), and round k's time ratio of it over the paper's best.
    pub precise_at_paper_best: Option<Point>,
    pub ratios_at_paper_best: Vec<f64>,
    /// At matched error, the precise model's best as the target: the cheapest paper setting at
    /// least as accurate (None: none is), and round k's time ratio of the precise best over it.
    pub paper_at_precise_best: Option<Point>,
    pub ratios_at_precise_best: Vec<f64>,
}

impl Verdict {
    pub fn ratio(&self) -> Option<Spread> {
        spread(&self.ratios)
    }
}

/// The cheapest setting per simulated second of `model` in `class` whose error is at most
/// `target` (ties in time go to the more accurate).
fn cheapest_reaching(points: &[Point], class: &str, model: &str, target: f64) -> Option<Point> {
    let mut ps: Vec<&Point> = points
        .iter()
        .filter(|p| p.class == class && p.model == model && p.error.is_finite())
        .filter(|p| p.error <= target)
        .collect();
    ps.sort_by(|a, b| {
        a.us_per_sim_s
            .total_cmp(&b.us_per_sim_s)
            .then(a.error.total_cmp(&b.error))
    });
    ps.first().map(|p| (*p).clone())
}

/// Round by round, `q`'s time per simulated second over `p`'s.
fn ratio_rounds(p: &Point, q: &Point) -> Vec<f64> {
    p.rounds_us_per_sim_s
        .iter()
        .zip(&q.rounds_us_per_sim_s)
        .filter(|(a, _)| **a > 0.0)
        .map(|(a, b)| b / a)
        .collect()
}

fn verdicts(points: &[Point], changes: &[(&'static str, f64)]) -> Vec<Verdict> {
    let mut out = Vec::new();
    for info in &CLASSES {
        let change = change_of(changes, info.class);
        let no_verdict = |against: Against, paper: Option<Point>, precise: Option<Point>| Verdict {
            class: info.class,
            paper_model: "paper",
            against,
            reference_change: change,
            smallest_error_judged: paper.as_ref().map_or(f64::NAN, |p| p.error),
            paper,
            precise,
            ratios: Vec::new(),
            precise_at_paper_best: None,
            ratios_at_paper_best: Vec::new(),
            paper_at_precise_best: None,
            ratios_at_precise_best: Vec::new(),
        };
        if !info.exact && change.is_nan() {
            out.push(no_verdict(Against::NoConvergedReference, None, None));
            continue;
        }
        let q = best(points, info.class, "precise");
        for paper_model in ["paper", "paper-R14"] {
            let p = best(points, info.class, paper_model);
            // paper-R14 only where it was measured (the stacks).
            if paper_model == "paper-R14" && p.is_none() {
                continue;
            }
            let against = if info.exact {
                Against::Exact
            } else if p
                .as_ref()
                .is_some_and(|p| change < JUDGED_BELOW_SHARE * p.error)
            {
                Against::PreciseModel
            } else {
                Against::ReferenceTooCoarse
            };
            if against == Against::ReferenceTooCoarse {
                out.push(no_verdict(against, p, q.clone()));
                continue;
            }
            let ratios = match (&p, &q) {
                (Some(p), Some(q)) => ratio_rounds(p, q),
                _ => Vec::new(),
            };
            // Matched error: each model's cheapest setting reaching the other's best (the
            // precise best, where it is within the reference's change, is the change).
            let precise_at_paper_best = p
                .as_ref()
                .and_then(|p| cheapest_reaching(points, info.class, "precise", p.error));
            let ratios_at_paper_best = match (&p, &precise_at_paper_best) {
                (Some(p), Some(q)) => ratio_rounds(p, q),
                _ => Vec::new(),
            };
            let paper_at_precise_best = q
                .as_ref()
                .and_then(|q| cheapest_reaching(points, info.class, paper_model, q.ranked_error()));
            let ratios_at_precise_best = match (&paper_at_precise_best, &q) {
                (Some(p), Some(q)) => ratio_rounds(p, q),
                _ => Vec::new(),
            };
            out.push(Verdict {
                class: info.class,
                paper_model,
                against,
                reference_change: change,
                smallest_error_judged: p.as_ref().map_or(f64::NAN, |p| p.error),
                paper: p,
                precise: q.clone(),
                ratios,
                precise_at_paper_best,
                ratios_at_paper_best,
                paper_at_precise_best,
                ratios_at_precise_best,
            });
        }
    }
    out
}

/// Per class and model: the best error, and the cheapest setting per simulated second
/// reaching it (ties in error go to the cheaper per simulated second). An error within the
/// reference's change ties with the change: the best is then the cheapest setting inside
/// that band. NaN and infinite errors are never best: None when the model has no finite
/// error in the class.
fn best(points: &[Point], class: &str, model: &str) -> Option<Point> {
    let mut ps: Vec<&Point> = points
        .iter()
        .filter(|p| p.class == class && p.model == model && p.error.is_finite())
        .collect();
    ps.sort_by(|a, b| {
        a.ranked_error()
            .total_cmp(&b.ranked_error())
            .then(a.us_per_sim_s.total_cmp(&b.us_per_sim_s))
    });
    ps.first().map(|p| (*p).clone())
}

fn nums(v: &[f64]) -> Value {
    Value::Array(v.iter().map(|x| num(*x)).collect())
}

fn spread_json(s: Option<Spread>) -> Value {
    match s {
        Some(s) => json!({"median": num(s.median), "min": num(s.min), "max": num(s.max)}),
        None => Value::Null,
    }
}

/// An error in JSON: a number, or a word where it is not one (null would hide why).
fn error_json(v: f64) -> Value {
    if v.is_nan() {
        json!("no reference")
    } else if v.is_infinite() {
        json!("never")
    } else {
        json!(v)
    }
}

fn point_json(p: &Point) -> Value {
    json!({"class": p.class, "model": p.model, "setting": p.setting,
           "error": error_json(p.error), "unit": class_info(&p.class).unit,
           "reference_change": num(p.reference_change),
           "within_reference_change": p.within_change(),
           "us_per_step": num(p.us_per_step), "us_per_sim_s": num(p.us_per_sim_s),
           "rounds_us_per_sim_s": nums(&p.rounds_us_per_sim_s),
           "us_per_sim_s_spread": spread_json(spread(&p.rounds_us_per_sim_s))})
}

fn write_json(
    path: &Path,
    w: &Whole,
    across: &[AcrossRuns],
    runs: usize,
) -> Result<(), Box<dyn std::error::Error>> {
    let (rows, summary, pareto, verdicts, checks) =
        (&w.rows, &w.summary, &w.pareto, &w.verdicts, &w.checks);
    let rows: Vec<Value> = rows
        .iter()
        .map(|r| {
            json!({"class": r.class, "scene": r.scene, "model": r.model, "setting": r.setting,
                   "error": error_json(r.error), "unit": r.unit, "us_per_step": num(r.us_per_step),
                   "us_per_sim_s": num(r.us_per_sim_s),
                   "rounds_us_per_sim_s": nums(&r.rounds_us_per_sim_s)})
        })
        .collect();
    let summary: Vec<Value> = summary.iter().map(point_json).collect();
    let pareto: Vec<Value> = pareto.iter().map(point_json).collect();
    let verdicts: Vec<Value> = verdicts
        .iter()
        .zip(across.iter().map(Some).chain(std::iter::repeat(None)))
        .map(|(v, a)| {
            let over_runs =
                |r: &[f64]| json!({"spread": spread_json(spread(r)), "per_run": nums(r)});
            let across_runs = a.map(|a| {
                json!({
                "runs": runs,
                "ratio_best_against_best": over_runs(&a.best_against_best),
                "ratio_at_paper_best": over_runs(&a.at_paper_best),
                "ratio_at_precise_best": over_runs(&a.at_precise_best),
                "paper_settings": a.paper_settings,
                "precise_settings": a.precise_settings})
            });
            json!({"class": v.class, "paper_model": v.paper_model,
                   "across_runs": across_runs,
                   "against": v.against.key(), "against_label": v.against.label(),
                   "reference_change": num(v.reference_change),
                   "smallest_error_judged": num(v.smallest_error_judged),
                   "paper": v.paper.as_ref().map(point_json),
                   "precise": v.precise.as_ref().map(point_json),
                   "ratio_precise_over_paper_per_sim_s": spread_json(v.ratio()),
                   "ratio_best_against_best": spread_json(v.ratio()),
                   "ratio_rounds": nums(&v.ratios),
                   "ratio_at_matched_error": {
                       "at_paper_best": {
                           "precise": v.precise_at_paper_best.as_ref().map(point_json),
                           "ratio": spread_json(spread(&v.ratios_at_paper_best)),
                           "ratio_rounds": nums(&v.ratios_at_paper_best)},
                       "at_precise_best": {
                           "paper": v.paper_at_precise_best.as_ref().map(point_json),
                           "ratio": spread_json(spread(&v.ratios_at_precise_best)),
                           "ratio_rounds": nums(&v.ratios_at_precise_best)}}})
        })
        .collect();
    let references: Vec<Value> = checks
        .iter()
        .map(|k| {
            json!({"class": k.class, "scene": k.scene, "setting": k.setting,
                   "changes": k.changes.iter().map(|(what, setting, m)| json!({"coarser": what, "setting": setting, "change_m": num(*m)})).collect::<Vec<_>>(),
                   "change_m": num(k.change_m), "travel_m": num(k.travel_m)})
        })
        .collect();
    let doc = json!({"time_axis": "us per simulated second (us per step x step rate)",
                     "runs": runs,
                     "published": "verdicts[].across_runs: each ratio the median of the whole runs' medians, with min and max over the runs; everything else is the last run's",
                     "rounds": ROUNDS, "finger_radius_m": FINGER_RADIUS,
                     "grasp_throw_contact_hz": GRASP_CONTACT_HZ,
                     "rows": rows, "summary": summary, "pareto": pareto,
                     "verdicts": verdicts, "references": references});
    std::fs::write(path, serde_json::to_string_pretty(&doc)? + "\n")
        .map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(())
}

/// An error for the tables: "-" where there is none (no reference: never "0"), "never"
/// where the judged event did not happen.
fn fmt_err(v: f64) -> String {
    if v.is_nan() {
        "-".into()
    } else if v.is_infinite() {
        "never".into()
    } else if v == 0.0 {
        "0".into()
    } else if v >= 100.0 {
        format!("{v:.0}")
    } else if v >= 1.0 {
        format!("{v:.2}")
    } else {
        format!("{v:.3}")
    }
}

/// A point's error for the tables: "<= change" where it is within its reference's change.
fn fmt_point_err(p: &Point) -> String {
    if p.within_change() {
        format!("<= {}", fmt_err(p.reference_change))
    } else {
        fmt_err(p.error)
    }
}

fn fmt_ratio(v: f64) -> String {
    if !v.is_finite() {
        "-".into()
    } else if v >= 10.0 {
        format!("{v:.0}")
    } else if v >= 1.0 {
        format!("{v:.1}")
    } else {
        format!("{v:.2}")
    }
}

fn fmt_spread(s: Option<Spread>, f: fn(f64) -> String, suffix: &str) -> String {
    match s {
        Some(s) => format!("{}{suffix} [{}, {}]", f(s.median), f(s.min), f(s.max)),
        None => "-".into(),
    }
}

fn fmt_us(v: f64) -> String {
    if !v.is_finite() {
        "-".into()
    } else if v >= 100.0 {
        format!("{v:.0}")
    } else {
        format!("{v:.1}")
    }
}

/// The summary: per class, what it is judged against, each model's best error and its cost
/// (per step, and per simulated second, which the choice and the ratio use), and the time
/// ratio precise/paper per simulated second, median [min, max] over the rounds.
pub fn summary_table(verdicts: &[Verdict]) -> String {
    let mut o = String::new();
    o.push_str("| class | judged against | unit | paper: best error | at | us/step | us/sim s | precise: best error | at | us/step | us/sim s | time per sim s, precise/paper, best against best: median [min, max] over rounds | at matched error (the paper's best): the cheapest precise setting as accurate, and the ratio |\n");
    o.push_str("|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for v in verdicts {
        let info = class_info(v.class);
        let name = if v.paper_model == "paper-R14" {
            format!("{} (paper with R14)", v.class)
        } else {
            v.class.to_string()
        };
        if v.against == Against::NoConvergedReference {
            let _ = writeln!(
                o,
                "| {name} | {} | {} | no converged reference | - | - | - | no converged reference | - | - | - | - | - |",
                v.against.label(),
                info.unit
            );
            continue;
        }
        let against = if v.reference_change.is_finite() {
            format!(
                "{} (its change {} {}, {} a third of the smallest error judged, {})",
                v.against.label(),
                fmt_err(v.reference_change),
                info.unit,
                if v.against == Against::ReferenceTooCoarse {
                    "not under"
                } else {
                    "under"
                },
                fmt_err(v.smallest_error_judged)
            )
        } else {
            v.against.label().to_string()
        };
        let cell = |x: &Option<Point>| match x {
            Some(p) => format!(
                "{} | {} | {} | {}",
                fmt_point_err(p),
                p.setting,
                fmt_us(p.us_per_step),
                fmt_us(p.us_per_sim_s)
            ),
            None => "- | - | - | -".into(),
        };
        let matched = match &v.precise_at_paper_best {
            Some(q) => format!(
                "{} ({} {}): {}",
                q.setting,
                fmt_point_err(q),
                info.unit,
                fmt_spread(spread(&v.ratios_at_paper_best), fmt_ratio, "x")
            ),
            None if v.against == Against::ReferenceTooCoarse => "no verdict".into(),
            None if v.paper.is_some() => "no precise setting as accurate".into(),
            None => "-".into(),
        };
        let _ = writeln!(
            o,
            "| {name} | {} | {} | {} | {} | {} | {} |",
            against,
            info.unit,
            cell(&v.paper),
            cell(&v.precise),
            fmt_spread(v.ratio(), fmt_ratio, "x"),
            matched
        );
    }
    o
}

fn markdown(w: &Whole, across: &[AcrossRuns], runs: usize, provenance: &Provenance) -> String {
    let (rows, summary, pareto, verdicts, notes, reference) = (
        &w.rows,
        &w.summary,
        &w.pareto,
        &w.verdicts,
        &w.notes,
        w.reference,
    );
    let quick = provenance.quick;
    let what = format!(
        "What accuracy costs in time{}: the paper model and the precise model (rapier3d, \
         the peer) on the same scenes, each at its own settings (the step rate; for the precise \
         model also substeps, solver iterations and sleeping), each scene judged against its \
         exact answer (or, for the hand scenes, against the precise model at its finest \
         setting). Each scene times its settings interleaved: a warm-up round, then {ROUNDS} \
         rounds each timing every setting once in turn, each round starting one setting later \
         (no setting is always first); a reading repeats a run shorter than 2 ms until it fills \
         2 ms and takes the median; a time is the median over the rounds, on this machine, in \
         this run. The published ratios (the first table) are the median over {runs} whole \
         runs of each run's median, with their run-to-run spread [min, max over the runs]; the \
         tables after it are the last run's. Settings differ in step rate, so costs are compared per \
         simulated second (us per step x step rate).\n\n\
         How to read it: lower is better on both axes. The summary gives per class each \
         model's best error and the cheapest setting reaching it; its last column divides the \
         precise model's time per simulated second at that setting by the paper model's at \
         its own, within each round (median [min, max] over the rounds): 18x means the precise \
         model pays 18 times what the paper model pays for its best. In the figure each point \
         is a setting, the ringed ones the Pareto front (no other setting is both cheaper and \
         more accurate), and a hollow point an error of 0 (at most the first \
         tick where that tick reads ≤).",
        if quick {
            " (quick run: a reduced sweep of settings and scenes)"
        } else {
            ""
        }
    );
    let mut o = page::head(
        "Benchmark: what accuracy costs in time, paper model against precise",
        &what,
        provenance,
    );
    o.push_str(&page::figure(
        "per class, error against time per simulated second, one colour per model, the Pareto front ringed",
        "accuracy.png",
    ));
    let _ = writeln!(
        o,
        "## The ratios, over {runs} whole runs (the published figures)\n\n\
         Each whole run measures everything again from the start; a cell is the median of the \
         runs' medians (each over its rounds), [min, max] over the runs. *Best against best*: \
         each model at its own best error (not equal accuracy). *At matched error*: the \
         cheapest setting of one model that reaches the other's best (docs/accuracy-cost.md).\n"
    );
    o.push_str(&across_runs_table(verdicts, across, runs));
    o.push_str(
        "\n## Summary of the last run (per class: each model's best error, the cheapest setting per simulated second reaching it)\n\n",
    );
    o.push_str(&summary_table(verdicts));
    o.push_str("\n## Classes and references\n\n");
    for info in &CLASSES {
        let _ = writeln!(o, "- **{}** ({}): {}", info.class, info.unit, info.what);
    }
    let _ = writeln!(
        o,
        "\nThe hand scenes have no reference independent of both models: they are judged against the \
         precise model at {} (it has no row of its own in those classes), so their error is agreement \
         with the precise model. Each reference carries its uncertainty, measured in this run: its \
         *change*, the largest move of its judged answer when one knob the scored settings vary \
         goes one notch coarser (half the rate, half the substeps, half the iterations, sleeping \
         on; the lines below give each). An error at or below the change reads \"<= change\" (the \
         reference cannot rank it), and the precise model's best is the cheapest setting inside \
         that band; a class is judged (a verdict and its ratios) only where the change is under \
         a third of the smallest error judged, the paper model's best; a reference that never \
         landed under a variant has no change, no error (\"-\") and no verdict. Both models' \
         fingers are the same there: points for the paper model, {} mm capsules for the precise \
         one. In the grasp-throw the precise model's contact spring is fixed at {} Hz instead \
         of its default 0.125 / substep dt, which stiffens with every halving of the substep \
         and so would change the squeezing grasp's grip rather than only its resolution. Errors are per class the worst over its scenes (decisions: the share wrong); \
         time is the mean over the class's scenes.",
        reference.label(),
        FINGER_RADIUS * 1e3,
        GRASP_CONTACT_HZ
    );
    for n in notes {
        let _ = writeln!(o, "- {n}");
    }
    o.push_str("\n## Every setting, per class\n\n");
    o.push_str("| class | model | setting | error | unit | us/step | us per simulated s: median [min, max] over rounds | Pareto (per simulated s) |\n|---|---|---|---|---|---|---|---|\n");
    for p in summary {
        let on = pareto
            .iter()
            .any(|q| q.class == p.class && q.model == p.model && q.setting == p.setting);
        let _ = writeln!(
            o,
            "| {} | {} | {} | {} | {} | {} | {} | {} |",
            p.class,
            p.model,
            p.setting,
            fmt_point_err(p),
            class_info(&p.class).unit,
            fmt_us(p.us_per_step),
            fmt_spread(spread(&p.rounds_us_per_sim_s), fmt_us, ""),
            if on { "yes" } else { "" }
        );
    }
    // Every scene under every setting is thousands of rows (half a megabyte of table in a
    // full run): the page would drown its summary, so they stay in the JSON.
    let _ = writeln!(
        o,
        "\n## Every scene\n\nThe {} rows of every scene under every setting (class, scene, \
         model, setting, error, unit, us per step, us per simulated second, and each round's \
         time) are in `accuracy.json`, written beside this page by the same command.",
        rows.len()
    );
    o
}

/// Errors of 0 cannot sit on a log axis: they are drawn hollow at this floor, whose tick reads
/// "0" (see [`Axis::floor`]); it lies below every error the benchmark reports as non-zero.
fn floor_of(unit: &str) -> f64 {
    match unit {
        "% wrong" => 1.0,
        _ => 1e-3,
    }
}

/// Per class, error against time per simulated second, both log, one colour per model, a
/// point per setting, the Pareto front ringed and joined; a zero error hollow on the "0" tick.
fn figure(summary: &[Point], pareto: &[Point]) -> Figure {
    let mut panels = Vec::new();
    for info in &CLASSES {
        let floor = floor_of(info.unit);
        let mut series = Vec::new();
        for model in ["paper", "precise", "paper-R14"] {
            let mut pts: Vec<(f64, f64)> = summary
                .iter()
                .filter(|p| p.class == info.class && p.model == model && p.error.is_finite())
                .map(|p| (p.us_per_sim_s, p.error))
                .collect();
            if pts.is_empty() {
                continue;
            }
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            series.push(Series {
                label: model.into(),
                points: pts,
            });
        }
        if series.is_empty() {
            continue;
        }
        let marked = pareto
            .iter()
            .filter(|p| p.class == info.class)
            .map(|p| (p.us_per_sim_s, p.error))
            .collect();
        let (title, y) = if info.exact {
            (
                format!("{}: error against the exact answer", info.class),
                format!("error ({})", info.unit),
            )
        } else {
            (
                format!("{}: distance from the precise reference", info.class),
                format!("distance ({})", info.unit),
            )
        };
        panels.push(Panel {
            title,
            x: Axis::log("us per simulated second"),
            y: Axis::log(&y).with_floor(floor),
            series,
            marked,
            // Points only: the precise model's settings (rate x substeps x iterations x sleep)
            // are no one sequence, and a line through them in order of cost zigzags over the
            // panel; the front's line is the trade-off to read.
            join: Join::No,
        });
    }
    Figure {
        panels,
        columns: 3,
        panel_width: 440,
        panel_height: 320,
        column_weights: Vec::new(),
    }
}

#[cfg(test)]
mod tests {

    /// Issue 42: a cube that lands and hops, never ending a step within 1 mm of the floor, has
    /// landed at the bottom of its hop; one still in flight has not.
    #[test]
    fn a_landing_is_found_inside_the_step_of_a_hop() {
        // Falling 4 cm a step, the low point 3 mm up between two higher steps, then a hop.
        let ys = [0.2, 0.16, 0.12, 0.08, 0.04, 0.003, 0.02, 0.03, 0.02, 0.004];
        assert_eq!(touchdown(&ys, 0), Some(5));
        // The same, ending a step on the floor: that step.
        let on = [0.2, 0.12, 0.04, 0.0005, 0.0005];
        assert_eq!(touchdown(&on, 0), Some(3));
        // A throw rising then falling, still in the air: never.
        let flight = [0.1, 0.15, 0.18, 0.19, 0.18, 0.15, 0.1];
        assert_eq!(touchdown(&flight, 0), None);
        // After a lift: the start is not a landing.
        let lift = [0.0005, 0.02, 0.06, 0.09, 0.05, 0.01, 0.012, 0.03];
        assert_eq!(touchdown(&lift, 3), Some(5));
    }
    use super::exact::*;
    use super::*;

    fn point(
        class: &str,
        model: &str,
        setting: &str,
        error: f64,
        us_per_step: f64,
        hz: f64,
    ) -> Point {
        Point {
            class: class.into(),
            model: model.into(),
            setting: setting.into(),
            error,
            us_per_step,
            us_per_sim_s: us_per_step * hz,
            rounds_us_per_sim_s: vec![us_per_step * hz; 3],
            reference_change: f64::NAN,
        }
    }

    #[test]
    fn the_pareto_front_is_per_simulated_second_a_cheap_480_hz_step_dominated_by_30_hz_is_off_it() {
        let ps = vec![
            // 30 us per simulated second, error 5.
            point("drop", "paper", "30 Hz", 5.0, 1.0, 30.0),
            // The cheapest step, but 240 us per simulated second and a worse error.
            point("drop", "paper", "480 Hz", 6.0, 0.5, 480.0),
            point("drop", "precise", "60 Hz x1 sub x1 it", 1.0, 20.0, 60.0),
        ];
        // Per step the 480 Hz point would be on the front: the test means something.
        assert!(pareto_front(&[(1.0, 5.0), (0.5, 6.0), (20.0, 1.0)]).contains(&1));
        let front: Vec<String> = pareto_of(&ps).into_iter().map(|p| p.setting).collect();
        assert_eq!(front, vec!["30 Hz", "60 Hz x1 sub x1 it"]);
        // No point on the front is dominated per simulated second by another of its class.
        for f in pareto_of(&ps) {
            assert!(!ps.iter().any(|q| q.us_per_sim_s <= f.us_per_sim_s
                && q.error <= f.error
                && (q.us_per_sim_s < f.us_per_sim_s || q.error < f.error)));
        }
    }

    #[test]
    fn the_cheapest_setting_reaching_the_best_error_is_cheapest_per_simulated_second() {
        let ps = vec![
            point("tipping-decision", "paper", "480 Hz", 0.0, 0.1, 480.0),
            point("tipping-decision", "paper", "30 Hz", 0.0, 1.0, 30.0),
        ];
        let b = best(&ps, "tipping-decision", "paper").map(|p| p.setting);
        assert_eq!(b.as_deref(), Some("30 Hz"));
    }

    #[test]
    fn ratios_are_taken_within_each_round_and_reported_as_median_min_max() {
        let mut p = point("drop", "paper", "30 Hz", 1.0, 1.0, 30.0);
        p.rounds_us_per_sim_s = vec![10.0, 20.0, 10.0];
        let mut q = point("drop", "precise", "60 Hz x1 sub x1 it", 1.0, 1.0, 60.0);
        q.rounds_us_per_sim_s = vec![100.0, 100.0, 300.0];
        let r = ratio_rounds(&p, &q);
        assert_eq!(r, vec![10.0, 5.0, 30.0]);
        assert_eq!(
            spread(&r),
            Some(Spread {
                median: 10.0,
                min: 5.0,
                max: 30.0
            })
        );
        assert_eq!(fmt_spread(spread(&r), fmt_ratio, "x"), "10x [5.0, 30]");
        assert_eq!(spread(&[]), None);
    }

    #[test]
    fn a_missing_reference_never_becomes_0() {
        // The judge: no reference, NaN.
        let case = Case {
            class: "push",
            name: "t".into(),
            scene: scene_of("t", vec![]),
            seconds: 1.0,
            judge: Judge::AgainstReference { landing: false },
            hand: false,
        };
        let trace = Trace {
            blocks: 1,
            poses: vec![(DVec3::ZERO, DQuat::IDENTITY), (DVec3::X, DQuat::IDENTITY)],
            us_per_step: 1.0,
        };
        let e = judge(&case, &trace, 0.01, None).errors;
        assert_eq!(e.len(), 1);
        assert!(e[0].1.is_nan(), "{e:?}");
        // A class: one NaN scene makes it NaN, whatever the others say; no scene at all too.
        assert!(class_error("mm", &[0.0, f64::NAN, 3.0]).is_nan());
        assert!(class_error("% wrong", &[0.0, f64::NAN]).is_nan());
        assert!(class_error("mm", &[]).is_nan());
        assert_eq!(class_error("mm", &[1.0, 3.0]), 3.0);
        let row = |error: f64| Row {
            class: "push".into(),
            scene: "s".into(),
            model: "paper".into(),
            setting: "60 Hz".into(),
            error,
            unit: "mm".into(),
            us_per_step: 1.0,
            us_per_sim_s: 60.0,
            rounds_us_per_sim_s: vec![60.0; 3],
        };
        let summary = summarise(&[row(f64::NAN)]);
        assert_eq!(summary.len(), 1);
        assert!(summary[0].error.is_nan());
        // Never best, never on the front, printed "-", and "no reference" in JSON.
        assert!(best(&summary, "push", "paper").is_none());
        assert!(pareto_of(&summary).is_empty());
        assert_eq!(fmt_err(f64::NAN), "-");
        assert_eq!(error_json(f64::NAN), json!("no reference"));
        // A class whose reference failed its check: no errors, no ratio, said so.
        let v = verdicts(&summary, &[("push", f64::NAN)]);
        let push: Vec<&Verdict> = v.iter().filter(|v| v.class == "push").collect();
        assert_eq!(push.len(), 1);
        assert_eq!(push[0].against, Against::NoConvergedReference);
        assert!(push[0].paper.is_none() && push[0].ratio().is_none());
        let table = summary_table(&v);
        let line = table
            .lines()
            .find(|l| l.starts_with("| push "))
            .unwrap_or_default();
        assert!(line.contains("no converged reference"), "{line}");
        assert!(!line.contains("| 0 |"), "{line}");
        // Nor in the figure (no panel) or the markdown's tables ("-").
        assert!(figure(&summary, &[]).panels.is_empty());
        let whole = Whole {
            rows: vec![row(f64::NAN)],
            summary: summary.clone(),
            pareto: Vec::new(),
            verdicts: v.clone(),
            checks: Vec::new(),
            notes: Vec::new(),
            reference: Setting::Paper { hz: 60.0 },
        };
        let across = across_runs(std::slice::from_ref(&whole));
        let md = markdown(
            &whole,
            &across,
            1,
            &Provenance {
                command: "handblocks bench accuracy --quick".into(),
                date_utc: "2024-01-01 00:00 UTC".into(),
                commit: "abc1234".into(),
                machine: "a CPU, 2 CPUs available to the run".into(),
                quick: true,
                quietness: None,
            },
        );
        assert!(md.contains("| push | paper | 60 Hz | - | mm |"), "{md}");
        assert!(md.contains("The 1 rows of every scene"), "{md}");
        // The published table says how many whole runs its medians are over.
        assert!(md.contains("median of 1 runs [min, max over runs]"), "{md}");
        // With a change under a third of the paper's best error, the same class is labelled
        // agreement, not accuracy.
        let v = verdicts(&summarise(&[row(2.0)]), &[("push", 0.5)]);
        let push = v.iter().find(|v| v.class == "push").map(|v| v.against);
        assert_eq!(push, Some(Against::PreciseModel));
        // Not under a third: errors shown, no verdict.
        let v = verdicts(&summarise(&[row(2.0)]), &[("push", 0.7)]);
        let push = v.iter().find(|v| v.class == "push");
        assert_eq!(push.map(|v| v.against), Some(Against::ReferenceTooCoarse));
        assert!(push.is_some_and(|v| v.ratio().is_none() && v.paper.is_some()));
    }

    /// Item 3 of issue 42: an error within the reference's change is "<= change", ties with
    /// the change, and the precise best is the cheapest setting inside that band.
    #[test]
    fn errors_within_the_references_change_read_as_the_change_and_the_cheapest_wins() {
        let point = |model: &str, setting: &str, error: f64, us: f64| Point {
            class: "push".into(),
            model: model.into(),
            setting: setting.into(),
            error,
            us_per_step: us / 60.0,
            us_per_sim_s: us,
            rounds_us_per_sim_s: vec![us; 3],
            reference_change: 0.5,
        };
        let points = vec![
            point("paper", "60 Hz", 3.0, 10.0),
            point("precise", "fine", 0.1, 1000.0),
            point("precise", "cheap", 0.4, 100.0),
            point("precise", "coarse", 2.0, 50.0),
        ];
        assert_eq!(fmt_point_err(&points[1]), "<= 0.500");
        assert_eq!(fmt_point_err(&points[3]), "2.00");
        let q = best(&points, "push", "precise").map(|p| p.setting);
        assert_eq!(q.as_deref(), Some("cheap"));
        let v = verdicts(&points, &[("push", 0.5)]);
        let push = v.iter().find(|v| v.class == "push").unwrap();
        assert_eq!(push.against, Against::PreciseModel);
        assert_eq!(
            push.precise_at_paper_best
                .as_ref()
                .map(|p| p.setting.as_str()),
            Some("coarse")
        );
        // 0.1 and 0.4 are one point on the front: the cheaper.
        let front: Vec<String> = pareto_of(&points).into_iter().map(|p| p.setting).collect();
        assert!(front.contains(&"cheap".to_string()) && !front.contains(&"fine".to_string()));
    }

    /// Not a check: a sweep of the precise model's settings on a hand scene, printing the
    /// judged answer (and G when lifted and at the release) at each, to look for a reference
    /// that converges when its substep halves. HB_SWEEP_CLASS (default grasp-throw) picks the
    /// class, HB_SWEEP_VARIANT a substring of the variants' names.
    /// `cargo test --release -p handblocks-bench -- --ignored --nocapture reference_sweep`
    #[test]
    #[ignore]
    fn reference_sweep() {
        let class = std::env::var("HB_SWEEP_CLASS").unwrap_or_else(|_| "grasp-throw".into());
        let only = std::env::var("HB_SWEEP_VARIANT").unwrap_or_default();
        type Variant = (&'static str, fn(&mut Scene));
        let variants: [Variant; 11] = [
            ("bench", |_| {}),
            ("contact 0.125 / substep (default)", |s| {
                s.world.precise.contact_hz = None
            }),
            ("r 2 mm", |s| s.world.precise.bare_finger_radius = 0.002),
            ("r 1 mm", |s| s.world.precise.bare_finger_radius = 0.001),
            ("damping 10", |s| s.world.precise.contact_damping = 10.0),
            ("no ccd", |s| s.world.precise.ccd = false),
            ("penetration 1 mm", |s| {
                s.world.precise.allowed_penetration = 1e-3
            }),
            ("contact 100 Hz", |s| {
                s.world.precise.contact_hz = Some(100.0)
            }),
            ("contact 500 Hz", |s| {
                s.world.precise.contact_hz = Some(500.0)
            }),
            ("contact 1000 Hz", |s| {
                s.world.precise.contact_hz = Some(1000.0)
            }),
            ("friction 1", |s| s.world.precise.friction = 1.0),
        ];
        let grid: [(f64, &[u32]); 3] = [
            (240.0, &[4, 8, 16, 32]),
            (480.0, &[4, 8, 16, 32]),
            (960.0, &[8, 16, 32]),
        ];
        for c in cases(false).into_iter().filter(|c| c.class == class) {
            let verts = vertices(&c, 0);
            let landing = matches!(c.judge, Judge::AgainstReference { landing: true });
            for (name, apply) in variants.iter().filter(|v| v.0.contains(&only)) {
                let mut c = c.clone();
                apply(&mut c.scene);
                for (hz, subs) in grid {
                    let mut prev: Option<DVec3> = None;
                    for &sub in subs {
                        let s = Setting::Precise {
                            hz,
                            substeps: sub,
                            iterations: 4,
                            sleep: false,
                        };
                        let Ok(t) = run_once(&c, s) else {
                            println!("{class} {name} {}: failed", s.label());
                            continue;
                        };
                        let a = if landing {
                            landing_after_lift(&t, &verts)
                        } else {
                            Some(t.at(t.steps(), 0).0)
                        };
                        let at = |sec: f64| t.at(((sec * hz) as usize).min(t.steps()), 0).0;
                        let start = t.at(0, 0).0;
                        let fmt = |p: DVec3| {
                            format!("({:.1}, {:.1}, {:.1})", p.x * 1e3, p.y * 1e3, p.z * 1e3)
                        };
                        let change = match (a, prev) {
                            (Some(a), Some(p)) => format!(
                                "{:.1} mm = {:.1}% of travel",
                                (a - p).length() * 1e3,
                                100.0 * (a - p).length() / (a - start).length().max(1e-9)
                            ),
                            _ => "-".into(),
                        };
                        println!(
                            "{class} | {name} | {} | G at 0.9 s {} | at 1.14 s {} | answer {} | vs half substep: {change} | {:.0} us/step",
                            s.label(),
                            fmt(at(0.9)),
                            fmt(at(1.14)),
                            a.map(fmt).unwrap_or_else(|| "never lands".into()),
                            t.us_per_step
                        );
                        prev = a;
                    }
                }
            }
        }
    }

    #[test]
    fn interleaved_timing_gives_every_setting_every_round() {
        let case = Case {
            class: "drop",
            name: "t".into(),
            scene: scene_of(
                "t",
                vec![block(
                    "cube",
                    [0.1; 3],
                    DVec3::new(0.0, 0.15, 0.0),
                    DQuat::IDENTITY,
                    DVec3::ZERO,
                )],
            ),
            seconds: 0.25,
            judge: Judge::FallTime { t: 0.14 },
            hand: false,
        };
        let settings = [
            Setting::Paper { hz: 60.0 },
            Setting::Precise {
                hz: 60.0,
                substeps: 1,
                iterations: 1,
                sleep: false,
            },
        ];
        let out = time_interleaved(&case, &settings, 3);
        assert_eq!(out.len(), 2);
        for r in &out {
            let t = r
                .as_ref()
                .map_err(|e| e.clone())
                .unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(t.rounds_us_per_step.len(), 3);
            assert_eq!(t.trace.steps(), 15);
        }
    }

    #[test]
    fn the_tipping_time_of_a_metre_cube_one_degree_past_its_edge_is_1_399_s() {
        let t = tipping_time(1.0, 1.0, 9.81, 1f64.to_radians(), 45f64.to_radians());
        assert!((t - 1.399).abs() < 0.001, "{t}");
    }

    #[test]
    fn the_tipping_time_agrees_with_a_fine_numerical_integration() {
        // RK4 at 1 us on phi'' = p^2 sin phi.
        let (w, h, g) = (0.1, 0.05, 9.81);
        let r = 0.5 * f64::hypot(w, h);
        let p2 = 3.0 * g / (4.0 * r);
        let (phi0, phi1) = (2f64.to_radians(), 30f64.to_radians());
        let (mut phi, mut om, mut t) = (phi0, 0.0f64, 0.0);
        let dt = 1e-6;
        while phi < phi1 {
            let f = |p: f64| p2 * p.sin();
            let (k1p, k1o) = (om, f(phi));
            let (k2p, k2o) = (om + 0.5 * dt * k1o, f(phi + 0.5 * dt * k1p));
            let (k3p, k3o) = (om + 0.5 * dt * k2o, f(phi + 0.5 * dt * k2p));
            let (k4p, k4o) = (om + dt * k3o, f(phi + dt * k3p));
            phi += dt / 6.0 * (k1p + 2.0 * k2p + 2.0 * k3p + k4p);
            om += dt / 6.0 * (k1o + 2.0 * k2o + 2.0 * k3o + k4o);
            t += dt;
        }
        let exact = tipping_time(w, h, g, phi0, phi1);
        assert!((t - exact).abs() < 2e-6, "{t} vs {exact}");
    }

    #[test]
    fn projectile_and_fall_closed_forms() {
        assert!((fall_time(1.0, 9.81) - 0.451_523_6).abs() < 1e-6);
        // From the floor at 45 deg: v^2 / g.
        assert!((projectile_range(3.0, 45f64.to_radians(), 0.0, 9.81) - 9.0 / 9.81).abs() < 1e-12);
        let o = harmonic_offsets(4, 0.1);
        assert!((o.iter().sum::<f64>() - 0.1 * (1.0 + 0.5 + 1.0 / 3.0) / 2.0).abs() < 1e-12);
    }
}
