//! Issue 27, "Precision far from the origin": the paper model does what it does wherever the
//! scene is. Every hard case and every scene of `config/scenes/` without a hand, moved along x
//! only, z only and both, by 1 km and 99 km (and the far-from-origin scene by 10,000 km, beyond
//! what the scene loader accepts), gives the events and modes of the run at the origin, and
//! every block's pose, every step, within 1e-6 m and 1e-6 rad of it; the three hard cases that
//! turn on the last bits of their start keep their verdict and stay within measured bounds.
//!
//! Issue 42: the precise model (rapier3d-f64) computes in the same anchored frame, and every
//! scene without a hand under it, moved by 1 km, 99 km and 10,000 km, does what it does at the
//! origin within 1e-8 m and rad (one scene, measured, within its own bound); so does
//! `push.toml`, the scene that ended 85 mm away before, within its measured bound.
//!
//! Each axis is its own test: a shift along x and z by equal amounts once hid a 0.2 mm
//! difference that a shift along one axis showed (before the world computed in its own frame,
//! `World::anchor`). Times, release build on a 2-vCPU machine, each test alone: the three
//! `every_hard_case_*` 3.7 to 5.3 s (3000-step cases, three runs a shift), the three precise
//! ones 0.4 s, the others under 0.1 s; the whole file 15 s on two test threads.

use std::path::Path;

use glam::{DQuat, DVec3};

use common::config::scene::ModelKind;
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

/// A run whose outcome turns on the last bits of its start: the scene moved far holds its
/// positions rounded to that distance (7e-12 m at 99 km), and so does the scene at the origin
/// perturbed by as much; a scripted hand's samples are rounded there too. Without a hand the
/// model is translation invariant (the far run is the origin run of the rounded scene, which is
/// asserted); what differs from the scene as written is that rounding, amplified by the run.
/// What the run keeps is asserted: a hard case's verdict, its modes at the end where they
/// held, its events where they held, and its differences from the origin run within
/// [`LAST_BITS_MARGIN`] times the figures measured here (the largest over every shift of these
/// tests).
struct LastBits {
    /// The hard case's name, or the scene's file name.
    name: &'static str,
    why: &'static str,
    /// The largest difference of a block's pose from the origin run's at any step (m, rad).
    worst: (f64, f64),
    /// The largest at the last step (m).
    end: f64,
    /// The events (kind and block, in order) are the origin run's, each at most this many
    /// steps from it (0: the same events); None: they differ (a pushed cube comes to rest in
    /// other steps, with other events), and are not compared.
    steps_apart: Option<u64>,
    /// Whether the modes at the end are the origin run's.
    same_modes: bool,
}

/// The bounds asserted on a [`LastBits`] run: this many times each figure measured. A change
/// of the model that moves one of these outcomes 3 times as far as the rounding does is
/// caught; the rounding itself, which differs with the shift, stays inside it.
const LAST_BITS_MARGIN: f64 = 3.0;

impl LastBits {
    /// `far` (moved back by its shift) against `base` (a run at the origin): Ok gives the
    /// figures, Err what broke its bounds.
    fn within_bounds(&self, base: &Outcome, far: &Outcome) -> Result<String, String> {
        let (worst_m, worst_rad, end_m) = differences(base, far);
        let bound = |measured: f64| measured * LAST_BITS_MARGIN;
        let mut figures = format!(
            "{worst_m:.2e} m, {worst_rad:.2e} rad at worst, {end_m:.2e} m at the end (bounds \
             {:.1e} m, {:.1e} rad, {:.1e} m)",
            bound(self.worst.0),
            bound(self.worst.1),
            bound(self.end)
        );
        if !(worst_m <= bound(self.worst.0)
            && worst_rad <= bound(self.worst.1)
            && end_m <= bound(self.end))
        {
            return Err(format!("{figures}: beyond the bounds"));
        }
        if self.same_modes && base.modes != far.modes {
            return Err(format!(
                "modes at the end differ: {:?} against {:?}",
                base.modes, far.modes
            ));
        }
        if let Some(apart) = self.steps_apart {
            let key = |o: &Outcome| -> Vec<(EventKind, usize)> {
                o.events.iter().map(|e| (e.kind, e.block)).collect()
            };
            if key(base) != key(far) {
                return Err(format!(
                    "events differ: {:?} against {:?}",
                    base.events, far.events
                ));
            }
            let most = (apart as f64 * LAST_BITS_MARGIN) as u64;
            let farthest = base
                .events
                .iter()
                .zip(&far.events)
                .map(|(a, b)| a.step.abs_diff(b.step))
                .max()
                .unwrap_or(0);
            if farthest > most {
                return Err(format!(
                    "{figures}: events up to {farthest} steps apart (bound {most})"
                ));
            }
            figures += &format!(", the same events at most {farthest} steps apart (bound {most})");
        }
        Ok(figures)
    }
}

/// The largest differences of `far`'s poses from `base`'s (each moved back by its shift): at
/// any step (m, rad), and at the last step (m).
fn differences(base: &Outcome, far: &Outcome) -> (f64, f64, f64) {
    let (mut worst, mut worst_angle, mut end) = (0.0f64, 0.0f64, 0.0f64);
    let last = base.poses.len().min(far.poses.len());
    for (step, (a, b)) in base.poses.iter().zip(&far.poses).enumerate() {
        for (pa, pb) in a.iter().zip(b) {
            let d = ((pb.0 - far.shift) - (pa.0 - base.shift)).length();
            // NaN counts as the largest difference.
            let d = if d.is_nan() { f64::INFINITY } else { d };
            worst = worst.max(d);
            worst_angle = worst_angle.max(angle_between(pa.1, pb.1));
            if step + 1 == last {
                end = end.max(d);
            }
        }
    }
    (worst, worst_angle, end)
}

/// `o` with its poses moved back by its shift, as the run at the origin would hold them: a
/// case's criterion reads positions in the scene's frame (drop-onto-tower's cube ends beside
/// the tower at x < -0.1).
fn moved_back(mut o: Outcome) -> Outcome {
    let shift = o.shift;
    for p in o.poses.iter_mut().flatten() {
        p.0 -= shift;
    }
    o.shift = DVec3::ZERO;
    o
}

/// The case's own verdict (`hard_cases::judge`: its criterion) and its stands/falls decision
/// (`hard_cases::figures`), of `far` moved back, are the origin run's.
fn same_verdict(
    case: &hard_cases::Case,
    variant: Variant,
    origin: &Outcome,
    far: Outcome,
) -> Result<(), String> {
    let far = moved_back(far);
    let (at_origin, moved) = (
        hard_cases::judge(case, variant, origin),
        hard_cases::judge(case, variant, &far),
    );
    if at_origin.is_ok() != moved.is_ok() {
        return Err(format!(
            "verdict at the origin {at_origin:?}, moved {moved:?}"
        ));
    }
    let (at_origin, moved) = (
        hard_cases::figures(case, origin).decision,
        hard_cases::figures(case, &far).decision,
    );
    if at_origin != moved {
        return Err(format!(
            "stands/falls (expected, got) at the origin {at_origin:?}, moved {moved:?}"
        ));
    }
    Ok(())
}

/// The hard cases that turn on their last bits under the paper model as written (R1-R14:
/// under R11 only, `Variant::Paper`, harmonic-4-101 stays where it is and is held to 1e-6 m
/// as every other case), measured with
/// `cargo test --release -p handblocks-bench --test far_from_origin -- --nocapture` (which
/// prints each run's figures beside its bounds) on 2026-12-05.
const TURN_ON_THEIR_LAST_BITS: &[LastBits] = &[
    LastBits {
        name: "drop-onto-tower",
        why: "the dropped cube slides down the tower's side at touching distance: moving its \
              start by 1e-13 m moves its topple by steps, and where it is at a step by up to \
              13 cm; it ends where it ends at the origin",
        worst: (0.133, 0.0759),
        end: 2.42e-11,
        steps_apart: Some(6),
        same_modes: true,
    },
    LastBits {
        name: "harmonic-4-101",
        why: "3000 steps of a four-cube overhang toppling: 7e-12 m at the start grows to 3e-4 m, \
              with the same events in the same steps",
        worst: (3.38e-4, 1.12e-3),
        end: 3.24e-4,
        steps_apart: Some(0),
        same_modes: true,
    },
    LastBits {
        name: "push-into-stack",
        why: "a scripted hand pushes a cube into a stack: the hand's samples are rounded at that \
              distance too (wrist plus finger offset, in the scene's frame), and when and where \
              the pushed cubes come to rest turns on it (3 cm)",
        worst: (3.34e-2, 1.05e-2),
        end: 3.34e-2,
        steps_apart: None,
        same_modes: false,
    },
];

/// Every hard case moved by each of `shifts`. Against the run at the origin of the scene as
/// the moved one holds it (its positions rounded at that distance): the same events and modes
/// and every pose within 1e-9 m and rad (translation invariance; a case with a scripted hand
/// within 1e-6, with events at most a step apart: the hand's samples are rounded at that
/// distance too). Against the run at the origin of the scene as written: the same events and
/// modes and every pose within 1e-6 m and rad; a case that turns on its last bits
/// ([`TURN_ON_THEIR_LAST_BITS`]) keeps its verdict and stays within its bounds instead (and a
/// hand's, against the rounded scene's run too).
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
                .find(|c| c.name == case.name && variant == Variant::PaperR14);
            for &shift in shifts {
                let far = hard_cases::run_shifted(case, shift, variant);
                let rounded = hard_cases::run_scene(
                    rounded_as_at(&scene, shift),
                    case.steps,
                    case.glitch,
                    DVec3::ZERO,
                );
                let what = format!("{} ({}) moved by {shift}", case.name, variant.label());
                let invariant = match (has_hand, sensitive) {
                    (true, Some(s)) => s.within_bounds(&rounded, &far).map(|_| ()),
                    (true, None) => compare_hand_case(&rounded, &far).map(|_| ()),
                    (false, _) => compare(&rounded, &far, 1e-9).map(|_| ()),
                };
                if let Err(e) = invariant {
                    failures.push(format!("{what}: not translation invariant: {e}"));
                    continue;
                }
                match sensitive {
                    Some(s) => match s.within_bounds(&origin, &far).and_then(|figures| {
                        same_verdict(case, variant, &origin, far).map(|()| figures)
                    }) {
                        Ok(figures) => println!("{what}: {figures}, verdict kept ({})", s.why),
                        Err(e) => failures.push(format!("{what} ({}): {e}", s.why)),
                    },
                    None => match compare(&origin, &far, TOL) {
                        Ok((d, a)) => worst = (worst.0.max(d), worst.1.max(a)),
                        Err(e) => failures.push(format!("{what}: {e}")),
                    },
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

// ---- The precise model (issue 42) ---------------------------------------------------------

/// The precise model's tolerance against the origin run, in metres and radians: the scenes
/// without a hand under it, moved by up to 10,000 km, came within 1.6e-9 m and 2e-14 rad of it
/// (1.6e-11 m at 99 km, 1.3e-13 m at 1 km), the rounding of their positions at that distance
/// and nothing more. Before the precise model computed in the anchored frame, rapier worked
/// with positions of that size: balance.toml moved 1 km along z ended 4e-5 m away, drop,
/// tip and wedge-tetra at 10,000 km 2e-8 to 5e-7 m; a 1e-6 m tolerance would not have caught
/// the last three.
const PRECISE_TOL: f64 = 1e-8;

/// What a far run may differ from the origin run of its own rounded scene (same events and
/// modes, poses within this many metres and radians): its poses leave the world's frame plus
/// the anchor and are rounded there, half a unit in the last place of the shift per
/// coordinate (measured: at most 0.5 epsilon times the distance, both axes together).
fn rounding_at(shift: DVec3) -> f64 {
    2.0 * f64::EPSILON * shift.abs().max_element()
}

/// `scene` under the precise model.
fn precise(mut scene: Scene) -> Scene {
    scene.world.model = ModelKind::Precise;
    scene
}

fn file_name(scene: &Scene) -> String {
    scene
        .file
        .file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned())
}

/// Scenes without a hand whose outcome under the precise model turns on the last bits of their
/// start, measured as [`TURN_ON_THEIR_LAST_BITS`] (on 2026-12-05, every shift of the precise
/// tests; the angle's bound holds nothing: a tumbling tetrahedron may end any way up).
const PRECISE_TURN_ON_THEIR_LAST_BITS: &[LastBits] = &[LastBits {
    name: "stack-paper.toml",
    why: "cubes and a tetrahedron dropped onto cubes: rapier's contact solve amplifies the \
          start's rounding (1e-13 m at 1 km) to where a falling block lands, up to 8 cm \
          (as it did before the anchor)",
    worst: (7.72e-2, 2.24),
    end: 7.60e-2,
    steps_apart: None,
    same_modes: true,
}];

/// Every scene without a hand under the precise model, moved by each of `shifts`, 360 steps.
/// Against the origin run of the scene as the moved one holds it: the same events and modes
/// and every pose within the shift's own rounding ([`rounding_at`]: the anchored frame makes
/// the engine compute the same numbers). Against the origin run of the scene as written: the
/// same events and modes and every pose within [`PRECISE_TOL`], but for the scenes that turn
/// on their last bits ([`PRECISE_TURN_ON_THEIR_LAST_BITS`]), within their measured bounds.
fn every_scene_without_a_hand_under_the_precise_model_moved_by(shifts: &[DVec3]) {
    let mut failures = Vec::new();
    let mut worst = (0.0f64, 0.0f64);
    for scene in handless_scenes().into_iter().map(precise) {
        let name = file_name(&scene);
        let origin = hard_cases::run_scene(scene.clone(), 360, Glitch::None, DVec3::ZERO);
        assert!(origin.refused.is_none(), "{name}: {:?}", origin.refused);
        let sensitive = PRECISE_TURN_ON_THEIR_LAST_BITS
            .iter()
            .find(|c| c.name == name);
        for &shift in shifts {
            let mut moved = scene.clone();
            hard_cases::shift_scene(&mut moved, shift);
            let far = hard_cases::run_scene(moved, 360, Glitch::None, shift);
            let rounded =
                hard_cases::run_scene(rounded_as_at(&scene, shift), 360, Glitch::None, DVec3::ZERO);
            let what = format!("{name} (precise) moved by {shift}");
            if let Err(e) = compare(&rounded, &far, rounding_at(shift)) {
                failures.push(format!("{what}: not translation invariant: {e}"));
                continue;
            }
            match sensitive {
                Some(s) => match s.within_bounds(&origin, &far) {
                    Ok(figures) => println!("{what}: {figures} ({})", s.why),
                    Err(e) => failures.push(format!("{what} ({}): {e}", s.why)),
                },
                None => match compare(&origin, &far, PRECISE_TOL) {
                    Ok((d, a)) => worst = (worst.0.max(d), worst.1.max(a)),
                    Err(e) => failures.push(format!("{what}: {e}")),
                },
            }
        }
    }
    println!(
        "every scene without a hand (precise) moved by {shifts:?}: worst {:.1e} m, {:.1e} rad \
         from the origin run",
        worst.0, worst.1
    );
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn every_scene_without_a_hand_under_the_precise_model_moved_along_x_only_does_what_it_does_at_the_origin(
) {
    every_scene_without_a_hand_under_the_precise_model_moved_by(&[
        along_x(KM),
        along_x(99.0 * KM),
        along_x(10_000.0 * KM),
    ]);
}

#[test]
fn every_scene_without_a_hand_under_the_precise_model_moved_along_z_only_does_what_it_does_at_the_origin(
) {
    every_scene_without_a_hand_under_the_precise_model_moved_by(&[
        along_z(KM),
        along_z(99.0 * KM),
        along_z(10_000.0 * KM),
    ]);
}

#[test]
fn every_scene_without_a_hand_under_the_precise_model_moved_along_x_and_z_does_what_it_does_at_the_origin(
) {
    every_scene_without_a_hand_under_the_precise_model_moved_by(&[
        along_both(KM),
        along_both(99.0 * KM),
        along_both(10_000.0 * KM),
    ]);
}

/// push.toml under the precise model, the run issue 42 measured: moved 99 km along x it ended
/// 85 mm from the run at the origin before the precise model computed in the anchored frame.
/// Its hand's samples are still rounded at that distance (the wrist plus each finger's offset,
/// in the scene's frame: 1.5e-11 m at 99 km), and the push turns on them: measured, 4.4e-5 m
/// and 5.1e-4 rad at worst, 1.3e-5 m at the end, the same events at most a step apart (1 km:
/// 2.6e-6 m). At 10,000 km (hand samples rounded to 1.9e-9 m) the push ends 0.24 m away with
/// other events, as it did before the anchor: that distance is not asserted.
const PUSH: LastBits = LastBits {
    name: "push.toml",
    why: "the hand's samples rounded at that distance",
    worst: (4.42e-5, 5.14e-4),
    end: 1.28e-5,
    steps_apart: Some(1),
    same_modes: true,
};

/// [`PUSH`] moved by 1 km and 99 km along x, z and both.
#[test]
fn the_push_scene_under_the_precise_model_moved_1_and_99_km_stays_within_its_bounds_of_the_origin_run(
) {
    let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/scenes/push.toml");
    let scene = precise(Scene::load(&file).unwrap_or_else(|e| panic!("{e}")));
    let origin = hard_cases::run_scene(scene.clone(), 360, Glitch::None, DVec3::ZERO);
    assert!(origin.refused.is_none(), "{:?}", origin.refused);
    let mut failures = Vec::new();
    for shift in [KM, 99.0 * KM]
        .into_iter()
        .flat_map(|d| [along_x(d), along_z(d), along_both(d)])
    {
        let mut moved = scene.clone();
        hard_cases::shift_scene(&mut moved, shift);
        let far = hard_cases::run_scene(moved, 360, Glitch::None, shift);
        match PUSH.within_bounds(&origin, &far) {
            Ok(figures) => println!("{} (precise) moved by {shift}: {figures}", PUSH.name),
            Err(e) => failures.push(format!(
                "{} moved by {shift} ({}): {e}",
                PUSH.name, PUSH.why
            )),
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
