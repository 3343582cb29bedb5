//! `handblocks bench accuracy`: what accuracy costs in time, for the paper model and the
//! precise reference (rapier3d), measured on the same scenes in the same run.
//!
//! Each scene class has a stated reference: an exact answer where physics gives one (static
//! tipping: topple or not and the final pose; a drop's fall time; a throw's landing point; a
//! box released past its edge: its fall time from the pendulum equation phi'' = p^2 sin phi;
//! stacks: stand or fall, and no sink), and for the hand scenes (push, grasp-throw) the
//! precise model at its finest setting, after checking that halving its substep moves the
//! answer by less than 10%. Each model runs at several settings (the paper model at five step
//! rates, the precise one over step rate x substeps x solver iterations); every setting of
//! every scene is timed (median of five runs after a warm-up) and its error measured against
//! the reference. Neither model is tuned here: each runs at its own settings, and the errors
//! are what they are.
//!
//! Outputs: `accuracy.json` (`{"rows": [...], "pareto": [...]}`), `accuracy.md` (the summary
//! and the tables) and `accuracy.png` (per class, log time per step against log error, one
//! line per model, the Pareto front ringed).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::{DQuat, DVec3};
use serde_json::{json, Value};

use common::config::scene::{BlockSpec, ModelKind, ShapeSpec, WorldSettings};
use common::config::Scene;
use stepper::geometry::Polyhedron;
use stepper::{BareFingersHand, HandSource, Model};

use crate::plot::{pareto_front, Figure, Legend, Panel, Series};

/// Options of `handblocks bench accuracy`.
pub struct AccuracyBench {
    pub out_dir: PathBuf,
    /// A reduced sweep (fewer scenes and settings) that runs in under a minute.
    pub quick: bool,
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
            } => format!("{hz} Hz x{substeps} sub x{iterations} it"),
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
                ..
            } => {
                scene.world.model = ModelKind::Precise;
                scene.world.precise.substeps = substeps;
                scene.world.precise.solver_iterations = iterations;
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

/// One class's unit and how its scenes' errors combine into the class's figure.
struct ClassInfo {
    class: &'static str,
    unit: &'static str,
    what: &'static str,
}

const CLASSES: [ClassInfo; 9] = [
    ClassInfo {
        class: "tipping-decision",
        unit: "% wrong",
        what: "static tipping near the critical angle: topple or not (exact: tan(tilt) > w/h)",
    },
    ClassInfo {
        class: "tipping-pose",
        unit: "mm",
        what: "static tipping: final pose, largest vertex distance from the exact pose (pivoting without sliding)",
    },
    ClassInfo {
        class: "drop",
        unit: "ms",
        what: "drop: time to reach the floor (exact: sqrt(2h/g))",
    },
    ClassInfo {
        class: "throw",
        unit: "mm",
        what: "throw: landing point of G (exact projectile range)",
    },
    ClassInfo {
        class: "tipping-dynamics",
        unit: "ms",
        what: "tipping dynamics: time for a box released past its edge to fall to 89 deg (exact: phi'' = p^2 sin phi)",
    },
    ClassInfo {
        class: "stack-decision",
        unit: "% wrong",
        what: "stacks: stands or falls (exact statics: every interface carries its load's G inside its contact)",
    },
    ClassInfo {
        class: "stack-sink",
        unit: "mm",
        what: "aligned towers (3 and 6 cubes): how far the top block sinks below its exact height (exact: 0)",
    },
    ClassInfo {
        class: "push",
        unit: "mm",
        what: "push with a fingertip: final G against the precise model's finest setting",
    },
    ClassInfo {
        class: "grasp-throw",
        unit: "mm",
        what: "grasp, lift, throw, land: final G against the precise model's finest setting",
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
    for (class, file, text, seconds, landing) in [
        ("push", "push (fingertip 2 cm high)", PUSH_LOW, 1.5, false),
        (
            "grasp-throw",
            "config/scenes/grasp-throw-fingers.toml",
            include_str!("../../config/scenes/grasp-throw-fingers.toml"),
            2.0,
            true,
        ),
    ] {
        if let Some(s) = load_text("hand-scene.toml", text) {
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

/// A warm-up run, then `timed` runs; the median time per step and the last run's trace
/// (every run gives the same poses: the models are deterministic).
fn run_timed(case: &Case, setting: Setting, timed: usize) -> Result<Trace, String> {
    run_once(case, setting)?;
    let mut times = Vec::with_capacity(timed);
    let mut last = None;
    for _ in 0..timed {
        let t = run_once(case, setting)?;
        times.push(t.us_per_step);
        last = Some(t);
    }
    times.sort_by(f64::total_cmp);
    let mut t = last.ok_or("no timed run")?;
    t.us_per_step = times[times.len() / 2];
    Ok(t)
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

/// The landing of block 0: the first step its lowest vertex is within 1 mm of the floor,
/// placed within the step by the speed of the step before (so a model is not charged a whole
/// step for where in its step the floor was crossed). Returns (time in steps, G's horizontal
/// distance at that time).
fn landing(trace: &Trace, verts: &[DVec3]) -> Option<(f64, f64)> {
    let ys: Vec<f64> = (0..=trace.steps())
        .map(|k| lowest(verts, trace.at(k, 0)))
        .collect();
    let k = ys.iter().position(|y| *y <= 1e-3)?;
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

/// Where block 0 first touches the floor after having been lifted 5 cm clear of it: G at
/// that step, moved on within the step as in [`landing`].
fn landing_after_lift(trace: &Trace, verts: &[DVec3]) -> Option<DVec3> {
    let ys: Vec<f64> = (0..=trace.steps())
        .map(|k| lowest(verts, trace.at(k, 0)))
        .collect();
    let lifted = ys.iter().position(|y| *y > 0.05)?;
    let k = lifted + ys[lifted..].iter().position(|y| *y <= 1e-3)?;
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

/// One row of the report.
#[derive(Debug, Clone)]
pub struct Row {
    pub class: String,
    pub scene: String,
    pub model: String,
    pub setting: String,
    pub error: f64,
    pub unit: String,
    pub us_per_step: f64,
    pub us_per_sim_s: f64,
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
    let mut precise = Vec::new();
    for &hz in rates {
        for &substeps in subs {
            for &iterations in its {
                precise.push(Setting::Precise {
                    hz,
                    substeps,
                    iterations,
                });
            }
        }
    }
    (paper, precise)
}

/// The reference setting for the hand scenes, and the one with half its substep.
fn reference_settings(quick: bool) -> (Setting, Setting) {
    let (hz, sub) = if quick { (240.0, 8) } else { (480.0, 16) };
    (
        Setting::Precise {
            hz,
            substeps: sub,
            iterations: 4,
        },
        Setting::Precise {
            hz,
            substeps: sub / 2,
            iterations: 4,
        },
    )
}

/// Runs the benchmark and writes its three files; returns the rows.
pub fn run(b: &AccuracyBench) -> Result<Vec<Row>, Box<dyn std::error::Error>> {
    std::fs::create_dir_all(&b.out_dir)
        .map_err(|e| format!("{}: cannot create: {e}", b.out_dir.display()))?;
    let timed = 5;
    let cases = cases(b.quick);
    let (paper, precise) = settings(b.quick);
    let (reference, half) = reference_settings(b.quick);
    let started = Instant::now();
    let mut notes = Vec::new();

    // The hand scenes' references, and the check that they have converged.
    let mut references: Vec<Option<DVec3>> = vec![None; cases.len()];
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
        let coarse = run_once(c, half)?;
        let start = fine.at(0, 0).0;
        let (Some(end), Some(other)) = (answer(&fine), answer(&coarse)) else {
            notes.push(format!(
                "{}: the reference run never lands the block; no reference",
                c.class
            ));
            continue;
        };
        let change = (other - end).length() / (end - start).length().max(1e-9);
        let ok = change < 0.10;
        let line = format!(
            "{}: reference = precise at {}; halving its substep ({}) moves the final G by {:.1} mm, {:.1}% of its travel ({})",
            c.class,
            reference.label(),
            half.label(),
            (other - end).length() * 1e3,
            change * 100.0,
            if ok { "converged: < 10%" } else { "NOT converged: >= 10%, the reference is uncertain" }
        );
        eprintln!("accuracy: {line}");
        notes.push(line);
        references[i] = Some(end);
    }

    let mut rows = Vec::new();
    let r14: Vec<Setting> = paper
        .iter()
        .map(|s| Setting::PaperR14 { hz: s.hz() })
        .collect();
    let all: Vec<Setting> = paper.iter().chain(&r14).chain(&precise).copied().collect();
    let mut r14_missing = false;
    for (si, setting) in all.iter().enumerate() {
        let t0 = Instant::now();
        let mut ran = 0;
        for (ci, c) in cases.iter().enumerate() {
            if matches!(setting, Setting::PaperR14 { .. }) && (c.class != "stack" || r14_missing) {
                continue;
            }
            // The reference's error against itself is 0 by definition: not a measurement.
            if matches!(c.judge, Judge::AgainstReference { .. }) && *setting == reference {
                continue;
            }
            let trace = match run_timed(c, *setting, timed) {
                Ok(t) => t,
                Err(e) if matches!(setting, Setting::PaperR14 { .. }) => {
                    // A build without R14 refuses the option: say so once, skip the line.
                    r14_missing = true;
                    notes.push(format!("paper-R14 not measured: {e}"));
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
            let dt = 1.0 / setting.hz();
            for (class, error) in judge(c, &trace, dt, references[ci]).errors {
                rows.push(Row {
                    class: class.into(),
                    scene: c.name.clone(),
                    model: setting.model().into(),
                    setting: setting.label(),
                    error,
                    unit: class_info(class).unit.into(),
                    us_per_step: trace.us_per_step,
                    us_per_sim_s: trace.us_per_step * setting.hz(),
                });
            }
        }
        eprintln!(
            "accuracy: [{}/{}] {} {}: {} scenes in {:.1} s ({:.0} s so far)",
            si + 1,
            all.len(),
            setting.model(),
            setting.label(),
            ran,
            t0.elapsed().as_secs_f64(),
            started.elapsed().as_secs_f64()
        );
    }
    let summary = summarise(&rows);
    let pareto = pareto_of(&summary);
    write_json(&b.out_dir.join("accuracy.json"), &rows, &summary, &pareto)?;
    let md = markdown(&rows, &summary, &pareto, &notes, b.quick, reference);
    std::fs::write(b.out_dir.join("accuracy.md"), &md)
        .map_err(|e| format!("{}: {e}", b.out_dir.join("accuracy.md").display()))?;
    let png = b.out_dir.join("accuracy.png");
    let text = figure(&summary, &pareto).write_png(&png)?;
    if !text {
        eprintln!(
            "accuracy: no TrueType font found (install fonts-dejavu-core or set HB_PLOT_FONT): {} has no labels",
            png.display()
        );
    }
    println!("{}", summary_table(&summary));
    println!(
        "accuracy: {} rows in {:.0} s; wrote {}, accuracy.md, accuracy.png",
        rows.len(),
        started.elapsed().as_secs_f64(),
        b.out_dir.join("accuracy.json").display()
    );
    Ok(rows)
}

/// A class's figure for one model setting: the worst error over the class's scenes (for
/// decisions: the share wrong) and the mean time per step.
#[derive(Debug, Clone)]
pub struct Point {
    pub class: String,
    pub model: String,
    pub setting: String,
    pub error: f64,
    pub us_per_step: f64,
    pub us_per_sim_s: f64,
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
            let error = if info.unit == "% wrong" {
                rs.iter().map(|r| r.error).sum::<f64>() / n
            } else {
                rs.iter().map(|r| r.error).fold(0.0, f64::max)
            };
            out.push(Point {
                class: info.class.into(),
                model,
                setting,
                error,
                us_per_step: rs.iter().map(|r| r.us_per_step).sum::<f64>() / n,
                us_per_sim_s: rs.iter().map(|r| r.us_per_sim_s).sum::<f64>() / n,
            });
        }
    }
    out
}

/// Per class, the settings (of either model) that no other beats in both time and error.
fn pareto_of(points: &[Point]) -> Vec<Point> {
    let mut out = Vec::new();
    for info in &CLASSES {
        let ps: Vec<&Point> = points
            .iter()
            .filter(|p| p.class == info.class && p.error.is_finite())
            .collect();
        let xy: Vec<(f64, f64)> = ps.iter().map(|p| (p.us_per_step, p.error)).collect();
        for i in pareto_front(&xy) {
            out.push(ps[i].clone());
        }
    }
    out
}

fn num(v: f64) -> Value {
    if v.is_finite() {
        json!(v)
    } else {
        Value::Null
    }
}

fn write_json(
    path: &Path,
    rows: &[Row],
    _summary: &[Point],
    pareto: &[Point],
) -> Result<(), Box<dyn std::error::Error>> {
    let rows: Vec<Value> = rows
        .iter()
        .map(|r| {
            json!({"class": r.class, "scene": r.scene, "model": r.model, "setting": r.setting,
                   "error": num(r.error), "unit": r.unit, "us_per_step": num(r.us_per_step),
                   "us_per_sim_s": num(r.us_per_sim_s)})
        })
        .collect();
    let pareto: Vec<Value> = pareto
        .iter()
        .map(|p| {
            json!({"class": p.class, "model": p.model, "setting": p.setting,
                   "error": num(p.error), "unit": class_info(&p.class).unit,
                   "us_per_step": num(p.us_per_step), "us_per_sim_s": num(p.us_per_sim_s)})
        })
        .collect();
    let doc = json!({"rows": rows, "pareto": pareto});
    std::fs::write(path, serde_json::to_string_pretty(&doc)? + "\n")
        .map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(())
}

fn fmt_err(v: f64) -> String {
    if !v.is_finite() {
        "n/a".into()
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

/// Per class and model: the best error, and the cheapest setting reaching it.
fn best(points: &[Point], class: &str, model: &str) -> Option<Point> {
    let mut ps: Vec<&Point> = points
        .iter()
        .filter(|p| p.class == class && p.model == model && p.error.is_finite())
        .collect();
    ps.sort_by(|a, b| {
        a.error
            .total_cmp(&b.error)
            .then(a.us_per_step.total_cmp(&b.us_per_step))
    });
    ps.first().map(|p| (*p).clone())
}

/// The summary: per class, each model's best error and its cost, and the time ratio.
pub fn summary_table(points: &[Point]) -> String {
    let mut o = String::new();
    o.push_str("| class | unit | paper: best error | at | us/step | precise: best error | at | us/step | time ratio precise/paper |\n");
    o.push_str("|---|---|---|---|---|---|---|---|---|\n");
    for info in &CLASSES {
        let p = best(points, info.class, "paper");
        let q = best(points, info.class, "precise");
        let cell = |x: &Option<Point>| match x {
            Some(p) => format!(
                "{} | {} | {:.1}",
                fmt_err(p.error),
                p.setting,
                p.us_per_step
            ),
            None => "- | - | -".into(),
        };
        let ratio = match (&p, &q) {
            (Some(p), Some(q)) if p.us_per_step > 0.0 => {
                format!("{:.0}x", q.us_per_step / p.us_per_step)
            }
            _ => "-".into(),
        };
        let _ = writeln!(
            o,
            "| {} | {} | {} | {} | {} |",
            info.class,
            info.unit,
            cell(&p),
            cell(&q),
            ratio
        );
        // The paper model with R14 where it was measured (stacks), in the paper's columns.
        if let Some(r) = best(points, info.class, "paper-R14") {
            let ratio = match &q {
                Some(q) if r.us_per_step > 0.0 => format!("{:.0}x", q.us_per_step / r.us_per_step),
                _ => "-".into(),
            };
            let _ = writeln!(
                o,
                "| {} (paper with R14) | {} | {} | {} | {} |",
                info.class,
                info.unit,
                cell(&Some(r)),
                cell(&q),
                ratio
            );
        }
    }
    o
}

fn markdown(
    rows: &[Row],
    summary: &[Point],
    pareto: &[Point],
    notes: &[String],
    quick: bool,
    reference: Setting,
) -> String {
    let mut o = String::new();
    o.push_str("# What accuracy costs in time\n\n");
    let _ = writeln!(
        o,
        "`handblocks bench accuracy{}`: the paper model and the precise model (rapier3d) on the same scenes, \
         each at its own settings; time per step is the median of 5 runs after a warm-up, on this machine, in this run.\n",
        if quick { " --quick" } else { "" }
    );
    o.push_str(
        "## Summary (per class: each model's best error, the cheapest setting reaching it)\n\n",
    );
    o.push_str(&summary_table(summary));
    o.push_str("\n## Classes and references\n\n");
    for info in &CLASSES {
        let _ = writeln!(o, "- **{}** ({}): {}", info.class, info.unit, info.what);
    }
    let _ = writeln!(
        o,
        "\nThe hand scenes' reference is the precise model at {} (it has no row of its own in \
         those classes). Errors are per class the worst over its scenes (decisions: the share \
         wrong); time is the mean over the class's scenes.",
        reference.label()
    );
    for n in notes {
        let _ = writeln!(o, "- {n}");
    }
    o.push_str("\n## Every setting, per class\n\n");
    o.push_str("| class | model | setting | error | unit | us/step | us per simulated s | Pareto |\n|---|---|---|---|---|---|---|---|\n");
    for p in summary {
        let on = pareto
            .iter()
            .any(|q| q.class == p.class && q.model == p.model && q.setting == p.setting);
        let _ = writeln!(
            o,
            "| {} | {} | {} | {} | {} | {:.1} | {:.0} | {} |",
            p.class,
            p.model,
            p.setting,
            fmt_err(p.error),
            class_info(&p.class).unit,
            p.us_per_step,
            p.us_per_sim_s,
            if on { "yes" } else { "" }
        );
    }
    o.push_str("\n## Every scene (accuracy.json has these rows)\n\n");
    o.push_str("| class | scene | model | setting | error | unit | us/step |\n|---|---|---|---|---|---|---|\n");
    for r in rows {
        let _ = writeln!(
            o,
            "| {} | {} | {} | {} | {} | {} | {:.1} |",
            r.class,
            r.scene,
            r.model,
            r.setting,
            fmt_err(r.error),
            r.unit,
            r.us_per_step
        );
    }
    o
}

/// Errors of 0 cannot sit on a log axis: they are drawn at this floor (stated in the title).
fn floor_of(unit: &str) -> f64 {
    match unit {
        "% wrong" => 1.0,
        _ => 1e-3,
    }
}

fn figure(summary: &[Point], pareto: &[Point]) -> Figure {
    let mut panels = Vec::new();
    for info in &CLASSES {
        let floor = floor_of(info.unit);
        let mut series = Vec::new();
        // This order gives each model the same colour in every panel (the palette goes by
        // position): paper blue, precise red, paper-R14 (stack panels only) green.
        for model in ["paper", "precise", "paper-R14"] {
            let mut pts: Vec<(f64, f64)> = summary
                .iter()
                .filter(|p| p.class == info.class && p.model == model && p.error.is_finite())
                .map(|p| (p.us_per_step, p.error.max(floor)))
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
            .map(|p| (p.us_per_step, p.error.max(floor)))
            .collect();
        panels.push(Panel {
            title: format!("{} (0 drawn at {})", info.class, floor),
            x_label: "us per step (log)".into(),
            y_label: format!("error, {} (log)", info.unit),
            log_x: true,
            log_y: true,
            series,
            marked,
            legend: Legend::UpperRight,
        });
    }
    Figure {
        panels,
        columns: 3,
        panel_width: 420,
        panel_height: 300,
    }
}

#[cfg(test)]
mod tests {
    use super::exact::*;

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
