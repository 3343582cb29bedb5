//! The hard-case suite (issue 13): the cases physics engines are judged by (notes/physics.md,
//! notes/accuracy.md), each a scene file under `config/scenes/hard/` whose header comment states
//! its criterion, and here a function that measures it. One `#[test]` per case.
//!
//! The table [`CASES`] is model-independent: a case is a scene file, a number of steps, what the
//! harness does to the scene or the hand (a shift far from the origin, a glitch in one sample)
//! and a criterion over the [`Outcome`]. [`run_case`] runs it under a [`Model`]; today only the
//! paper model (R1-R14) exists, the precise model (rapier3d, issue 11) adds a variant and the
//! cases that apply to it.

mod support;

use std::path::{Path, PathBuf};

use glam::{DQuat, DVec3};

use common::config::Scene;
use common::BlockMode;
use stepper::geometry::{rotate_vertices, sat_depth, Polyhedron};
use stepper::{BareFingersHand, Event, EventKind, HandSource, World};

/// The models a case can run under.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Model {
    /// MODEL.md R1-R14 (`stepper::World`).
    Paper,
}

/// What the harness does to one hand sample.
#[derive(Debug, Clone, Copy)]
enum Glitch {
    None,
    /// Sample k gets a NaN (a device glitch).
    Nan(u64),
    /// Sample k is moved 1 m along +x (a tracker glitch); the next is the script's again.
    Jump(u64),
}

/// One hard case.
struct Case {
    name: &'static str,
    /// Under config/scenes/hard/.
    file: &'static str,
    steps: u64,
    /// Added to every block position (far from the origin).
    shift: DVec3,
    glitch: Glitch,
    /// Measure the largest overlap of any two blocks in every step (small scenes only).
    overlaps: bool,
    check: fn(&Outcome) -> Result<String, String>,
}

/// What a run measured.
struct Outcome {
    /// Why the world refused the scene, when it did.
    refused: Option<String>,
    /// Block poses after every step (index 0: the initial state).
    poses: Vec<Vec<(DVec3, DQuat)>>,
    events: Vec<Event>,
    modes: Vec<BlockMode>,
    /// The largest SAT overlap of two blocks over all steps (with `overlaps`): step and blocks.
    max_overlap: f64,
    worst_overlap: (u64, usize, usize),
    /// Steps in which a block was grasped, and the deepest a drawn finger point lay inside it.
    grasped_steps: u64,
    finger_depth: f64,
    /// The same case at the origin (for shifted cases).
    origin: Option<Box<Outcome>>,
    shift: DVec3,
}

fn hard_file(file: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../config/scenes/hard")
        .join(file)
}

fn load(case: &Case) -> Scene {
    let mut s = Scene::load(&hard_file(case.file)).unwrap_or_else(|e| panic!("{e}"));
    for b in &mut s.blocks {
        b.position = (DVec3::from_array(b.position) + case.shift).to_array();
    }
    s
}

/// Runs a case's scene under `model` and measures it.
fn run(case: &Case, shift: DVec3, model: Model) -> Outcome {
    let c = Case { shift, ..*case };
    let scene = load(&c);
    match model {
        Model::Paper => run_paper(&c, &scene),
    }
}

fn run_paper(case: &Case, scene: &Scene) -> Outcome {
    let mut out = Outcome {
        refused: None,
        poses: Vec::new(),
        events: Vec::new(),
        modes: Vec::new(),
        max_overlap: f64::NEG_INFINITY,
        worst_overlap: (0, 0, 0),
        grasped_steps: 0,
        finger_depth: f64::NEG_INFINITY,
        origin: None,
        shift: case.shift,
    };
    let mut w = match World::new(scene) {
        Ok(w) => w,
        Err(e) => {
            out.refused = Some(e.to_string());
            return out;
        }
    };
    let polys: Vec<Polyhedron> = scene
        .blocks
        .iter()
        .map(|b| Polyhedron::from_spec(&b.shape).unwrap())
        .collect();
    let snap = |w: &World| -> Vec<(DVec3, DQuat)> {
        (0..w.block_count())
            .map(|i| {
                let b = w.block(i).unwrap();
                (b.position, b.rotation)
            })
            .collect()
    };
    let dt = 1.0 / scene.world.step_hz;
    let mut hand = BareFingersHand::from_scene(scene);
    if let Some(h) = hand.as_mut() {
        w.set_previous_hand(h.hand_at(0, 0.0).as_ref());
    }
    out.poses.push(snap(&w));
    let (mut va, mut vb) = (Vec::new(), Vec::new());
    let mut sample = common::WorldSample::default();
    for n in 1..=case.steps {
        let mut s = hand.as_mut().and_then(|h| h.hand_at(n, n as f64 * dt));
        if let Some(h) = s.as_mut() {
            match case.glitch {
                Glitch::Nan(k) if k == n => h.finger_points[0][0][0] = f64::NAN,
                Glitch::Jump(k) if k == n => {
                    h.wrist.position[0] += 1.0;
                    for f in 0..h.finger_count as usize {
                        for p in 0..h.finger_point_count[f] as usize {
                            h.finger_points[f][p][0] += 1.0;
                        }
                    }
                }
                _ => {}
            }
        }
        w.step(s.as_ref());
        out.events.extend_from_slice(w.events());
        let p = snap(&w);
        if case.overlaps {
            for i in 0..p.len() {
                for j in i + 1..p.len() {
                    if (p[j].0 - p[i].0).length() > polys[i].radius + polys[j].radius {
                        continue;
                    }
                    rotate_vertices(&polys[i], p[i].1, &mut va);
                    rotate_vertices(&polys[j], p[j].1, &mut vb);
                    let d = sat_depth(
                        &polys[i],
                        p[i].1,
                        &va,
                        &polys[j],
                        p[j].1,
                        &vb,
                        p[j].0 - p[i].0,
                    );
                    if d > out.max_overlap {
                        out.max_overlap = d;
                        out.worst_overlap = (n, i, j);
                    }
                }
            }
        }
        w.write_sample(&mut sample);
        if sample.grasped_block >= 0 {
            out.grasped_steps += 1;
            let g = sample.grasped_block as usize;
            let (pos, rot) = p[g];
            for f in 0..sample.finger_count as usize {
                for k in 0..sample.finger_point_count[f] as usize {
                    let local =
                        rot.conjugate() * (DVec3::from_array(sample.finger_points[f][k]) - pos);
                    let (d, _) = polys[g].max_face_distance(local);
                    out.finger_depth = out.finger_depth.max(-d);
                }
            }
        }
        out.poses.push(p);
    }
    out.modes = (0..w.block_count())
        .map(|i| w.block(i).unwrap().mode)
        .collect();
    out
}

/// Checks every case must pass: no NaN, unit quaternions (within 1e-12), in every step.
fn sane(o: &Outcome) -> Result<(), String> {
    for (k, p) in o.poses.iter().enumerate() {
        for (i, (x, q)) in p.iter().enumerate() {
            if !x.is_finite() || !q.is_finite() {
                return Err(format!("block {i} not finite at step {k}"));
            }
            if (q.length() - 1.0).abs() > 1e-12 {
                return Err(format!("block {i}: |q| = {} at step {k}", q.length()));
            }
        }
    }
    Ok(())
}

// ---- criteria helpers ----------------------------------------------------------------------

fn last(o: &Outcome) -> &Vec<(DVec3, DQuat)> {
    o.poses.last().unwrap()
}

/// No block ever moves, bit for bit, from the initial state.
fn never_moves(o: &Outcome) -> Result<String, String> {
    for (k, p) in o.poses.iter().enumerate() {
        if *p != o.poses[0] {
            let i = (0..p.len()).find(|&i| p[i] != o.poses[0][i]).unwrap();
            return Err(format!("block {i} moved at step {k}: {:?}", p[i]));
        }
    }
    Ok(format!(
        "0 drift (bit for bit) over {} steps",
        o.poses.len() - 1
    ))
}

/// Block i never moves from the initial state over steps `..end`.
fn block_still(o: &Outcome, i: usize, end: usize) -> Result<(), String> {
    match o.poses[..end.min(o.poses.len())]
        .iter()
        .position(|p| p[i] != o.poses[0][i])
    {
        Some(k) => Err(format!("block {i} moved at step {k}")),
        None => Ok(()),
    }
}

/// Everything lies still, bit for bit, over the last `n` steps.
fn still_at_end(o: &Outcome, n: usize) -> Result<(), String> {
    let from = o.poses.len() - n;
    match o.poses[from..].iter().position(|p| *p != o.poses[from]) {
        Some(k) => Err(format!("still moving at step {}", from + k)),
        None => Ok(()),
    }
}

fn mode(o: &Outcome, i: usize, m: BlockMode) -> Result<(), String> {
    if o.modes[i] == m {
        Ok(())
    } else {
        Err(format!("block {i} is {:?}, expected {m:?}", o.modes[i]))
    }
}

/// The tilt of a rotation away from upright (radians).
fn tilt(q: DQuat) -> f64 {
    (q * DVec3::Y).angle_between(DVec3::Y)
}

fn near(what: &str, got: f64, want: f64, tol: f64) -> Result<(), String> {
    if (got - want).abs() <= tol {
        Ok(())
    } else {
        Err(format!("{what} = {got}, expected {want} within {tol}"))
    }
}

fn stack_stands(o: &Outcome) -> Result<String, String> {
    let r = never_moves(o)?;
    mode(o, 0, BlockMode::Resting)?;
    for i in 1..o.modes.len() {
        mode(o, i, BlockMode::Supported)?;
    }
    Ok(r)
}

fn pyramid_stands(o: &Outcome) -> Result<String, String> {
    let r = never_moves(o)?;
    for i in 0..o.modes.len() {
        mode(
            o,
            i,
            if i < 15 {
                BlockMode::Resting
            } else {
                BlockMode::Supported
            },
        )?;
    }
    Ok(r)
}

fn pyramid_knocked(o: &Outcome) -> Result<String, String> {
    if o.max_overlap > EPS {
        return Err(format!("overlap {}", o.max_overlap));
    }
    let pushed = 14;
    if last(o)[pushed].0.z < 0.1 {
        return Err(format!(
            "the bottom-right cube was not pushed out: {}",
            last(o)[pushed].0
        ));
    }
    for i in (0..o.modes.len()).filter(|&i| i != pushed) {
        block_still(o, i, o.poses.len())?;
    }
    Ok(format!(
        "largest overlap {:.1e} m; 119 cubes never moved",
        o.max_overlap.max(0.0)
    ))
}

fn drop_onto_tower(o: &Outcome) -> Result<String, String> {
    if o.max_overlap > EPS {
        return Err(format!(
            "overlap {} (step, blocks) {:?}",
            o.max_overlap, o.worst_overlap
        ));
    }
    for i in 0..5 {
        block_still(o, i, o.poses.len())?;
    }
    mode(o, 5, BlockMode::Supported)?;
    near("staying cube G y", last(o)[5].0.y, 0.55, 1e-9)?;
    mode(o, 6, BlockMode::Resting)?;
    let fell = last(o)[6].0;
    near("falling cube G y", fell.y, 0.05, 1e-9)?;
    if fell.x > -0.1 + 1e-9 {
        return Err(format!("the falling cube is not beside the tower: {fell}"));
    }
    still_at_end(o, 60)?;
    Ok(format!(
        "tower still; one stays on top, the other slid down its side to the floor at x = {:.4}",
        fell.x
    ))
}

fn upper_stays(o: &Outcome) -> Result<String, String> {
    let r = never_moves(o)?;
    mode(o, 1, BlockMode::Supported)?;
    Ok(r)
}

// ---- the cases -----------------------------------------------------------------------------

const EPS: f64 = 1e-4;
const HULL_EPS: f64 = 1e-6;

fn harmonic_101(o: &Outcome) -> Result<String, String> {
    block_still(o, 0, o.poses.len())?;
    let down = o
        .events
        .iter()
        .find(|e| e.kind == EventKind::Impact && e.block != 0)
        .ok_or("the stack never reached the floor")?
        .step;
    for i in 1..5 {
        let (x0, x) = (o.poses[0][i].0, last(o)[i].0);
        if !(x.y < x0.y && x.x > 0.05) {
            return Err(format!("block {i} did not come down beyond the edge: {x}"));
        }
    }
    still_at_end(o, 60)?;
    Ok(format!(
        "toppled, first on the floor at step {down}; base never moved"
    ))
}

fn plate_1_5_20(o: &Outcome) -> Result<String, String> {
    mode(o, 0, BlockMode::Resting)?;
    let (x, q) = last(o)[0];
    near("G y", x.y, 0.005, 1e-9)?;
    near("tilt", tilt(q), 0.0, 1e-9)?;
    Ok(format!("face down, G y - 0.005 = {:.1e} m", x.y - 0.005))
}

fn plate_1000_1(o: &Outcome) -> Result<String, String> {
    mode(o, 0, BlockMode::Resting)?;
    let (x, q) = last(o)[0];
    near("plate G y", x.y, 0.0005, 1e-9)?;
    near("plate tilt", tilt(q), 0.0, 1e-9)?;
    let cube = last(o)[1].0;
    near("cube G y", cube.y, 0.051, 1e-6)?;
    let low = o
        .poses
        .iter()
        .map(|p| p[1].0.y)
        .fold(f64::INFINITY, f64::min);
    if low < 0.051 - 1e-9 {
        return Err(format!("the cube went down to {low}"));
    }
    still_at_end(o, 60)?;
    Ok(format!(
        "plate flat; cube on it at +{:.1e} m",
        cube.y - 0.051
    ))
}

fn parallel_faces(o: &Outcome) -> Result<String, String> {
    let gaps: Vec<f64> = o.poses.iter().map(|p| p[1].0.y - 0.15).collect();
    let min = gaps.iter().copied().fold(f64::INFINITY, f64::min);
    if min < -1e-12 {
        return Err(format!("overlap {min}"));
    }
    let gap = *gaps.last().unwrap();
    if gap > EPS {
        return Err(format!("not touching: gap {gap}"));
    }
    let landed = gaps.iter().position(|g| *g <= EPS).unwrap();
    if o.poses[landed..].iter().any(|p| p[1] != o.poses[landed][1]) {
        return Err("moved after landing".into());
    }
    mode(o, 1, BlockMode::Supported)?;
    Ok(format!("gap {gap:.1e} m, still from step {landed}"))
}

fn edge_on_edge(o: &Outcome) -> Result<String, String> {
    let want = 3.0 * 0.05 * 2f64.sqrt();
    let y = last(o)[1].0.y;
    near("G y", y, want, 1e-6)?;
    let low = o
        .poses
        .iter()
        .map(|p| p[1].0.y)
        .fold(f64::INFINITY, f64::min);
    if low < want - 1e-9 {
        return Err(format!("went down to {low} (overlap)"));
    }
    still_at_end(o, 60)?;
    Ok(format!("stopped at {:+.1e} m of first contact", y - want))
}

fn g_past_edge(o: &Outcome) -> Result<String, String> {
    block_still(o, 0, o.poses.len())?;
    let x = last(o)[1].0;
    if x.y >= 0.1 {
        return Err(format!("did not fall: {x}"));
    }
    Ok(format!("tipped and fell, ends at y = {:.4}", x.y))
}

fn fall_step(o: &Outcome) -> Result<String, String> {
    let y = last(o)[1].0.y;
    near("grain G y", y, 0.015, 1e-6)?;
    let low = o
        .poses
        .iter()
        .map(|p| p[1].0.y)
        .fold(f64::INFINITY, f64::min);
    if low < 0.015 - 1e-9 {
        return Err(format!("went down to {low}"));
    }
    mode(o, 1, BlockMode::Supported)?;
    still_at_end(o, 60)?;
    Ok(format!("stopped on it at {:+.1e} m", y - 0.015))
}

fn bullet_wall(o: &Outcome) -> Result<String, String> {
    let front = o
        .poses
        .iter()
        .map(|p| p[0].0.x + 0.025)
        .fold(f64::NEG_INFINITY, f64::max);
    if front > 0.995 + 1e-9 {
        return Err(format!("passed the wall's face: front at {front}"));
    }
    if front < 0.995 - 1e-6 {
        return Err(format!("stopped short: front at {front}"));
    }
    block_still(o, 1, o.poses.len())?;
    mode(o, 0, BlockMode::Resting)?;
    near("bullet G y", last(o)[0].0.y, 0.025, 1e-9)?;
    Ok(format!(
        "front stops {:.1e} m before the face; ends on the floor",
        0.995 - front
    ))
}

fn bullet_moving(o: &Outcome) -> Result<String, String> {
    if o.max_overlap > HULL_EPS {
        return Err(format!("overlap {}", o.max_overlap));
    }
    mode(o, 0, BlockMode::Resting)?;
    mode(o, 1, BlockMode::Resting)?;
    near("bullet G y", last(o)[0].0.y, 0.025, 1e-9)?;
    near("target G y", last(o)[1].0.y, 0.05, 1e-9)?;
    Ok(format!(
        "largest overlap {:.1e} m; both on the floor",
        o.max_overlap.max(0.0)
    ))
}

fn far(o: &Outcome) -> Result<String, String> {
    let origin = o.origin.as_ref().ok_or("no origin run")?;
    let mut worst: f64 = 0.0;
    let mut worst_angle: f64 = 0.0;
    for (a, b) in last(o).iter().zip(last(origin)) {
        worst = worst.max(((a.0 - o.shift) - b.0).length());
        worst_angle = worst_angle.max(a.1.angle_between(b.1));
    }
    if worst > 1e-6 || worst_angle > 1e-6 {
        return Err(format!(
            "differs from the origin run by {worst} m, {worst_angle} rad"
        ));
    }
    // The scene does something: the tipper and the overhanging cube came down.
    if last(origin)[1].0.y > 0.2 || last(origin)[3].0.y > 0.1 {
        return Err("the scene did not topple".into());
    }
    Ok(format!(
        "{worst:.1e} m, {worst_angle:.1e} rad from the origin run"
    ))
}

fn overlapping_spawn(o: &Outcome) -> Result<String, String> {
    let e = o.refused.as_ref().ok_or("the scene was accepted")?;
    if !(e.contains("overlapping-spawn.toml")
        && e.contains("\"a\"")
        && e.contains("\"b\"")
        && e.contains("overlap"))
    {
        return Err(format!("unclear error: {e}"));
    }
    Ok(format!("refused: {e}").replace(env!("CARGO_MANIFEST_DIR"), ""))
}

fn push_into_wall(o: &Outcome) -> Result<String, String> {
    if o.max_overlap > HULL_EPS {
        return Err(format!("overlap {}", o.max_overlap));
    }
    let moved = last(o)[1].0.x - 0.11;
    if !(0.08..=0.11).contains(&moved) {
        return Err(format!("the wall moved {moved}"));
    }
    still_at_end(o, 60)?;
    Ok(format!(
        "largest overlap {:.1e} m; wall carried {moved:.4} m",
        o.max_overlap.max(0.0)
    ))
}

fn push_into_stack(o: &Outcome) -> Result<String, String> {
    if o.max_overlap > EPS {
        return Err(format!(
            "overlap {} (step, blocks) {:?}",
            o.max_overlap, o.worst_overlap
        ));
    }
    still_at_end(o, 120)?;
    for i in [2, 3] {
        if last(o)[i].0.y > o.poses[0][i].0.y - 0.05 {
            return Err(format!("cube {i} did not come down: {}", last(o)[i].0));
        }
    }
    Ok(format!(
        "largest overlap {:.1e} m; the upper cubes came down and rest",
        o.max_overlap.max(0.0)
    ))
}

fn grasp_deep(o: &Outcome) -> Result<String, String> {
    if o.grasped_steps == 0 {
        return Err("never grasped".into());
    }
    if o.finger_depth > 1e-9 {
        return Err(format!("a drawn finger point {} m inside", o.finger_depth));
    }
    mode(o, 0, BlockMode::Resting)?;
    near("G y", last(o)[0].0.y, 0.03, 1e-9)?;
    Ok(format!(
        "grasped {} steps, drawn fingers at most {:.1e} m inside; rests",
        o.grasped_steps,
        o.finger_depth.max(0.0)
    ))
}

fn trace_nan(o: &Outcome) -> Result<String, String> {
    if !o
        .events
        .iter()
        .any(|e| e.step == 80 && e.kind == EventKind::Release)
    {
        return Err("the NaN sample did not end the grasp".into());
    }
    mode(o, 0, BlockMode::Resting)?;
    near("G y", last(o)[0].0.y, 0.03, 1e-9)?;
    Ok("grasp ends at the NaN sample; no NaN; rests".into())
}

fn trace_jump(o: &Outcome) -> Result<String, String> {
    if o.max_overlap > EPS {
        return Err(format!("overlap {}", o.max_overlap));
    }
    for (i, (x, _)) in last(o).iter().enumerate() {
        mode(o, i, BlockMode::Resting)?;
        if x.length() > 2.0 {
            return Err(format!("block {i} flew to {x}"));
        }
    }
    still_at_end(o, 60)?;
    let far = last(o)
        .iter()
        .zip(&o.poses[0])
        .map(|(a, b)| (a.0 - b.0).length())
        .fold(0.0, f64::max);
    Ok(format!(
        "largest overlap {:.1e} m; moved at most {far:.3} m; all rest",
        o.max_overlap.max(0.0)
    ))
}

fn heavy_on_light(o: &Outcome) -> Result<String, String> {
    upper_stays(o).map(|r| format!("{r} (no mass in the paper model)"))
}

macro_rules! case {
    ($name:literal, $steps:expr, $check:expr) => {
        case!($name, $steps, $check, DVec3::ZERO, Glitch::None, false)
    };
    ($name:literal, $steps:expr, $check:expr, $shift:expr, $glitch:expr, $overlaps:expr) => {
        Case {
            name: $name,
            file: concat!($name, ".toml"),
            steps: $steps,
            shift: $shift,
            glitch: $glitch,
            overlaps: $overlaps,
            check: $check,
        }
    };
}

const KM: f64 = 1000.0;

/// The suite: (case, scene file, steps, criterion). The scene's header states the criterion.
const CASES: &[Case] = &[
    case!("tower-10", 600, stack_stands),
    case!("tower-20", 600, stack_stands),
    case!("tower-40", 600, stack_stands),
    case!("staggered", 600, never_moves),
    case!("harmonic-4-99", 600, never_moves),
    case!("harmonic-4-101", 3000, harmonic_101),
    case!("pyramid-15", 240, pyramid_stands),
    case!(
        "pyramid-knocked",
        480,
        pyramid_knocked,
        DVec3::ZERO,
        Glitch::None,
        true
    ),
    case!(
        "drop-onto-tower",
        600,
        drop_onto_tower,
        DVec3::ZERO,
        Glitch::None,
        true
    ),
    case!("plate-1-5-20", 360, plate_1_5_20),
    case!("plate-1000-1", 600, plate_1000_1),
    case!("parallel-faces", 300, parallel_faces),
    case!("edge-on-edge", 300, edge_on_edge),
    case!("vertex-on-face", 600, upper_stays),
    case!("g-on-edge", 600, upper_stays),
    case!("g-on-edge-plus-1e-9", 600, upper_stays),
    case!("g-on-edge-minus-1e-9", 600, upper_stays),
    case!("g-past-edge-1e-5", 3000, g_past_edge),
    case!("fall-step-longer-than-block", 240, fall_step),
    case!("bullet-200-wall", 240, bullet_wall),
    case!(
        "bullet-200-moving-block",
        240,
        bullet_moving,
        DVec3::ZERO,
        Glitch::None,
        true
    ),
    Case {
        name: "far-1km",
        ..case!(
            "far-from-origin",
            360,
            far,
            DVec3::new(KM, 0.0, KM),
            Glitch::None,
            false
        )
    },
    Case {
        name: "far-100km",
        ..case!(
            "far-from-origin",
            360,
            far,
            DVec3::new(100.0 * KM, 0.0, 100.0 * KM),
            Glitch::None,
            false
        )
    },
    Case {
        name: "far-10000km",
        ..case!(
            "far-from-origin",
            360,
            far,
            DVec3::new(10_000.0 * KM, 0.0, 10_000.0 * KM),
            Glitch::None,
            false
        )
    },
    case!("overlapping-spawn", 10, overlapping_spawn),
    case!(
        "push-into-wall",
        240,
        push_into_wall,
        DVec3::ZERO,
        Glitch::None,
        true
    ),
    case!(
        "push-into-stack",
        960,
        push_into_stack,
        DVec3::ZERO,
        Glitch::None,
        true
    ),
    case!("grasp-deep", 360, grasp_deep),
    case!(
        "trace-nan",
        360,
        trace_nan,
        DVec3::ZERO,
        Glitch::Nan(80),
        false
    ),
    case!(
        "trace-jump",
        240,
        trace_jump,
        DVec3::ZERO,
        Glitch::Jump(40),
        true
    ),
    case!("heavy-on-light", 600, heavy_on_light),
];

/// Runs one case under `model`; panics with the measured failure.
fn run_case(name: &str, model: Model) {
    let case = CASES
        .iter()
        .find(|c| c.name == name)
        .unwrap_or_else(|| panic!("no case {name}"));
    let mut o = run(case, case.shift, model);
    if case.shift != DVec3::ZERO {
        o.origin = Some(Box::new(run(case, DVec3::ZERO, model)));
    }
    let result = sane(&o).and_then(|()| (case.check)(&o));
    match result {
        Ok(figure) => println!("| {name} | {model:?} | {figure} |"),
        Err(e) => panic!("hard case {name} ({model:?}, {}): {e}", case.file),
    }
}

macro_rules! tests {
    ($($test:ident => $name:literal),* $(,)?) => {
        /// One test per case, under the paper model.
        mod paper {
            $(
                #[test]
                fn $test() {
                    super::run_case($name, super::Model::Paper);
                }
            )*
        }

        /// Every case of the table has its test.
        #[test]
        fn every_case_is_tested_and_has_a_scene_with_a_criterion() {
            let tested = [$($name),*];
            assert!(CASES.len() >= 25);
            for c in CASES {
                assert!(tested.contains(&c.name), "{} has no test", c.name);
                let text = std::fs::read_to_string(hard_file(c.file)).unwrap();
                assert!(text.starts_with("# Hard case") && text.contains("Criterion"), "{}", c.file);
            }
        }
    };
}

tests! {
    tower_10 => "tower-10",
    tower_20 => "tower-20",
    tower_40 => "tower-40",
    staggered => "staggered",
    harmonic_4_99 => "harmonic-4-99",
    harmonic_4_101 => "harmonic-4-101",
    pyramid_15 => "pyramid-15",
    a_cube_dropped_beyond_a_towers_edge_slides_down_its_side => "drop-onto-tower",
    pyramid_with_a_bottom_cube_pushed_out => "pyramid-knocked",
    plate_1_5_20_lands_flat => "plate-1-5-20",
    plate_1000_1_lands_flat_and_carries_a_cube => "plate-1000-1",
    parallel_faces => "parallel-faces",
    edge_on_edge => "edge-on-edge",
    vertex_on_face => "vertex-on-face",
    g_exactly_on_the_edge => "g-on-edge",
    g_1e_9_beyond_the_edge => "g-on-edge-plus-1e-9",
    g_1e_9_inside_the_edge => "g-on-edge-minus-1e-9",
    g_1e_5_beyond_the_edge_tips => "g-past-edge-1e-5",
    fall_step_longer_than_the_block => "fall-step-longer-than-block",
    bullet_200_m_per_s_against_a_1_cm_wall => "bullet-200-wall",
    bullet_200_m_per_s_against_a_moving_block => "bullet-200-moving-block",
    far_1_km => "far-1km",
    far_100_km => "far-100km",
    far_10000_km => "far-10000km",
    overlapping_spawn_is_refused => "overlapping-spawn",
    hand_pushes_a_block_into_a_wall => "push-into-wall",
    hand_pushes_a_block_into_a_stack => "push-into-stack",
    grasp_with_fingers_deep_inside => "grasp-deep",
    trace_with_a_nan_sample => "trace-nan",
    trace_with_a_1_m_jump => "trace-jump",
    heavy_on_light => "heavy-on-light",
}
