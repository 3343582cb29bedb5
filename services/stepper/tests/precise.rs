//! Both models against exact answers (static tipping near the critical angle, free fall, a
//! projectile's landing), the precise model's hand scenes, its determinism and its `[precise]`
//! table's validation. Tolerances are each model's measured error with a margin (the accuracy
//! benchmark reports the errors themselves): the paper model is exact statics (R9) with the
//! semi-implicit fall of R7; the precise one is rapier3d at its default reference setting.

mod support;

use glam::{DQuat, DVec3};

use common::config::Scene;
use stepper::{simulate, BareFingersHand, EventKind, HandSource, Model, Report};
use support::*;

const G: f64 = 9.81;

fn with_model(text: &str, model: &str) -> Scene {
    scene(&format!("[world]\nmodel = \"{model}\"\n{text}"))
}

/// A box w (x) by h (y) on its -x bottom edge at the origin, turned `tilt` about +z: G is
/// beyond the edge (it topples onto its -x face) iff tan(tilt) > w / h.
fn tilted_box(w: f64, h: f64, tilt: f64) -> String {
    let q = DQuat::from_rotation_z(tilt);
    let g = q * DVec3::new(w / 2.0, h / 2.0, 0.0);
    format!(
        "[[block]]\nname = \"box\"\nsize = [{w}, {h}, 0.1]\nposition = [{}, {}, 0.0]\nrotation = [{}, {}, {}, {}]\n",
        g.x, g.y, q.x, q.y, q.z, q.w
    )
}

/// The largest distance of a box vertex from where it is in the exact final pose.
fn pose_error(r: &Report, w: f64, h: f64, toppled: bool) -> f64 {
    let (eg, eq) = if toppled {
        (
            DVec3::new(-h / 2.0, w / 2.0, 0.0),
            DQuat::from_rotation_z(std::f64::consts::FRAC_PI_2),
        )
    } else {
        (DVec3::new(w / 2.0, h / 2.0, 0.0), DQuat::IDENTITY)
    };
    let g = DVec3::from_array(r.blocks[0].position);
    let q = DQuat::from_array(r.blocks[0].rotation);
    let mut worst: f64 = 0.0;
    for sx in [-1.0, 1.0] {
        for sy in [-1.0, 1.0] {
            for sz in [-1.0, 1.0] {
                let v = DVec3::new(sx * w / 2.0, sy * h / 2.0, sz * 0.05);
                worst = worst.max(((g + q * v) - (eg + eq * v)).length());
            }
        }
    }
    worst
}

fn tipping_cases(model: &str, pose_tolerance: f64) {
    for (w, h) in [(0.05f64, 0.1f64), (0.1, 0.1), (0.1, 0.05)] {
        let critical = (w / h).atan();
        for off in [-15.0f64, -5.0, -2.0, 2.0, 5.0, 15.0] {
            let s = with_model(&tilted_box(w, h, critical + off.to_radians()), model);
            let r = simulate(&s, 240, None).unwrap();
            let q = DQuat::from_array(r.blocks[0].rotation);
            let tilt = (q * DVec3::Y).y.clamp(-1.0, 1.0).acos();
            let toppled = tilt > std::f64::consts::FRAC_PI_4;
            assert_eq!(
                toppled,
                off > 0.0,
                "{model}: {w} x {h} at critical {off:+} deg: final tilt {:.2} deg",
                tilt.to_degrees()
            );
            let e = pose_error(&r, w, h, off > 0.0);
            assert!(
                e < pose_tolerance,
                "{model}: {w} x {h} at critical {off:+} deg: final pose {:.3} mm off",
                e * 1e3
            );
        }
    }
}

/// R9 is exact statics: every decision right, and the block ends exactly on a face.
#[test]
fn r9_paper_tipping_near_the_critical_angle_decides_exactly_for_three_aspect_ratios() {
    tipping_cases("paper", 1e-6);
}

/// The reference decides the same. Its final pose is off by 0.1 to 10 mm (largest vertex
/// distance, `bench accuracy`): the landing impact skids and yaws the block a little, and
/// finer settings do not remove it (it is sensitive to the last bit of the start pose), so
/// the tolerance here is a centimetre: the benchmark shows the figure itself.
#[test]
fn precise_tipping_near_the_critical_angle_decides_right_and_ends_near_the_exact_pose() {
    tipping_cases("precise", 0.01);
}

/// The first step after which the cube's (edge `size`) lowest vertex is within 1 mm of the
/// floor, and G then.
fn landing_step(s: &Scene, frames: u64, half: f64) -> (u64, DVec3) {
    let mut m = Model::new(s).unwrap();
    for _ in 0..frames {
        m.step(None);
        let b = m.block(0).unwrap();
        let mut low = f64::INFINITY;
        for sx in [-half, half] {
            for sy in [-half, half] {
                for sz in [-half, half] {
                    low = low.min((b.position + b.rotation * DVec3::new(sx, sy, sz)).y);
                }
            }
        }
        if low <= 1e-3 {
            return (m.steps(), b.position);
        }
    }
    panic!("never landed in {frames} steps");
}

/// Free fall from 1 m: t = sqrt(2 h / g) = 0.4515 s. R7's per-step fall d = v + g dt^2 is
/// semi-implicit Euler: it runs dt / 2 ahead of the exact fall; rapier's substeps run
/// (dt / substeps) / 2 ahead. Both land within one step (plus that lead) of the exact time.
#[test]
fn free_fall_lands_at_the_exact_time_within_a_step_in_both_models() {
    let exact = (2.0 * 1.0 / G).sqrt();
    for model in ["paper", "precise"] {
        let s = with_model(
            "[[block]]\nname = \"cube\"\nposition = [0.0, 1.05, 0.0]\n",
            model,
        );
        let dt = 1.0 / s.world.step_hz;
        let (k, _) = landing_step(&s, 240, 0.05);
        let t = k as f64 * dt;
        assert!(
            t >= exact - dt && t <= exact + dt,
            "{model}: landed after step {k} (t = {t:.4} s), exact {exact:.4} s"
        );
    }
}

/// A 5 cm cube thrown at 2 m/s, 45 degrees, its lowest face 0.3 m up: it lands
/// R = v cos a (v sin a + sqrt(v^2 sin^2 a + 2 g h0)) / g = 0.6087 m further on. Both models
/// place G there within what one step of flight covers (1.41 m/s x 1/120 s = 12 mm).
#[test]
fn projectile_lands_at_the_exact_range_in_both_models() {
    let (v, a, h0) = (2.0f64, 45f64.to_radians(), 0.3);
    let range = v * a.cos() * (v * a.sin() + ((v * a.sin()).powi(2) + 2.0 * G * h0).sqrt()) / G;
    for model in ["paper", "precise"] {
        let s = with_model(
            &format!(
                "[[block]]\nname = \"cube\"\nsize = [0.05, 0.05, 0.05]\nposition = [0.0, 0.325, 0.0]\nvelocity = [{}, {}, 0.0]\n",
                v * a.cos(),
                v * a.sin()
            ),
            model,
        );
        let (_, g) = landing_step(&s, 240, 0.025);
        assert!(
            (g.x - range).abs() < 0.013,
            "{model}: landed at x = {:.4} m, exact {range:.4} m",
            g.x
        );
    }
}

fn precise_file(name: &str) -> Scene {
    let mut s = scene_file(name);
    s.world.model = common::config::scene::ModelKind::Precise;
    s
}

/// The bare-finger grasp-throw under the precise model: thumb and fingers close on the cube
/// from opposite sides, so the contact normals are 180 deg apart (> grasp_angle): grasped;
/// then the fingers open in the swing (release) and the block flies on forward (+z).
#[test]
fn precise_grasp_throw_is_grasped_between_opposing_fingers_and_thrown_forward() {
    let s = precise_file("grasp-throw-fingers");
    let r = run(&s, 400);
    let kinds: Vec<EventKind> = r.events.iter().map(|e| e.kind).collect();
    let grasp = kinds.iter().position(|k| *k == EventKind::Grasp);
    let release = kinds.iter().rposition(|k| *k == EventKind::Release);
    assert!(
        matches!((grasp, release), (Some(g), Some(r)) if g < r),
        "{:?}",
        r.events
    );
    let z = r.blocks[0].position[2];
    assert!(z > 0.3, "thrown forward: z = {z}");
}

/// One fingertip pushes the cube (config/scenes/push.toml) under the precise model: a push
/// contact (one finger: never a grasp), and the cube moves. Pushed at G's height with perfect
/// friction it tips over its far edge rather than slide (the force that tips it, m g w / 2h,
/// is below the one that slides it, mu m g), so where it ends is not asserted here.
#[test]
fn precise_push_is_a_push_contact_and_moves_the_block() {
    let s = precise_file("push");
    let r = run(&s, 200);
    assert!(
        r.events.iter().any(|e| e.kind == EventKind::Push),
        "{:?}",
        r.events
    );
    assert!(!r.events.iter().any(|e| e.kind == EventKind::Grasp));
    let moved = DVec3::from_array(r.blocks[0].position) - DVec3::new(0.0, 0.05, 0.0);
    assert!(moved.length() > 0.01, "{:?}", r.blocks[0]);
}

/// Determinism: the same scene twice gives the same report, bit for bit (rapier runs single
/// threaded; nothing reads a clock).
#[test]
fn precise_simulate_is_bit_identical_across_runs() {
    let s = precise_file("grasp-throw-fingers");
    assert_eq!(run(&s, 300).to_json(), run(&s, 300).to_json());
}

/// A precise world fills the same world sample as the paper one: poses, modes, step.
#[test]
fn precise_world_sample_carries_poses_and_modes() {
    let s = precise_file("tip");
    let mut m = Model::new(&s).unwrap();
    for _ in 0..240 {
        m.step(None);
    }
    let mut out = common::WorldSample::default();
    m.write_sample(&mut out);
    assert_eq!(out.step, 240);
    assert_eq!(out.block_count, 2);
    assert_eq!(out.grasped_block, -1);
    assert_eq!(out.blocks[0].mode(), common::BlockMode::Resting);
    assert!((out.blocks[0].pose.position[1] - 0.05).abs() < 1e-3);
}

/// The precise model computes in the anchored frame (docs/model.md R9 Precision, the paper
/// model's rule) and gives everything back in the scene's: push.toml moved 99 km along x has
/// its anchor at the shift; its world sample carries the hand's check points exactly as they
/// were given, and the cube (`block(i)` the same pose) where the run at the origin has it
/// plus the shift, within 1e-4 m (its hand's samples are rounded at 99 km: 4.4e-5 m measured,
/// bench/tests/far_from_origin.rs; 85 mm before the precise model had an anchor). At the
/// origin the anchor is zero, and nothing is translated.
#[test]
fn precise_world_far_from_the_origin_computes_at_its_anchor_and_publishes_the_scene_frame() {
    let s = precise_file("push");
    let shift = DVec3::new(99_000.0, 0.0, 0.0);
    let mut far = s.clone();
    for b in &mut far.blocks {
        b.position = (DVec3::from_array(b.position) + shift).to_array();
    }
    for k in far.hand.iter_mut().flat_map(|h| h.keys.iter_mut()) {
        k.wrist = (DVec3::from_array(k.wrist) + shift).to_array();
    }
    let anchor = |m: &Model| match m {
        Model::Precise(w) => w.anchor(),
        Model::Paper(w) => w.anchor(),
    };
    let (mut m0, mut m) = (Model::new(&s).unwrap(), Model::new(&far).unwrap());
    assert_eq!(anchor(&m0), DVec3::ZERO);
    assert_eq!(anchor(&m), shift);
    let (mut hand0, mut hand) = (
        BareFingersHand::from_scene(&s).unwrap(),
        BareFingersHand::from_scene(&far).unwrap(),
    );
    m0.set_previous_hand(hand0.hand_at(0, 0.0).as_ref());
    m.set_previous_hand(hand.hand_at(0, 0.0).as_ref());
    let mut out = common::WorldSample::default();
    let mut pushed = false;
    for n in 1..=240 {
        let t = n as f64 / s.world.step_hz;
        m0.step(hand0.hand_at(n, t).as_ref());
        let h = hand.hand_at(n, t).unwrap();
        m.step(Some(&h));
        pushed |= m.events().iter().any(|e| e.kind == EventKind::Push);
        m.write_sample(&mut out);
        assert_eq!(out.finger_count, h.finger_count);
        for f in 0..h.finger_count as usize {
            let k = h.finger_point_count[f] as usize;
            assert_eq!(
                out.finger_points[f][..k],
                h.finger_points[f][..k],
                "step {n}"
            );
        }
        let (b0, b) = (m0.block(0).unwrap(), m.block(0).unwrap());
        assert_eq!(
            b.position.to_array(),
            out.blocks[0].pose.position,
            "step {n}"
        );
        assert!(
            (b.position - shift - b0.position).length() < 1e-4,
            "step {n}: the cube at {} moved back, {} at the origin",
            b.position - shift,
            b0.position
        );
    }
    assert!(pushed, "the finger never reached the cube");
}

fn load_err(text: &str) -> common::config::ConfigError {
    let dir = std::env::temp_dir().join(format!("stepper-precise-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("bad.toml");
    std::fs::write(&file, text).unwrap();
    let e = Scene::load(&file).unwrap_err();
    let _ = std::fs::remove_dir_all(&dir);
    e
}

/// Bad `[precise]` values name the file, the key and the allowed range.
#[test]
fn bad_precise_values_are_refused_with_file_key_and_range() {
    for (text, key, says) in [
        (
            "[precise]\nsubsteps = 0\n",
            "precise.substeps",
            "allowed: 1 to 256",
        ),
        (
            "[precise]\nsolver_iterations = 1000\n",
            "precise.solver_iterations",
            "allowed: 1 to 64",
        ),
        (
            "[precise]\ncontact_hz = 0.5\n",
            "precise.contact_hz",
            "allowed: 1 to",
        ),
        (
            "[precise]\nfriction = -1\n",
            "precise.friction",
            "allowed: 0 to 100",
        ),
        ("[precise]\nccd = 1\n", "precise.ccd", "true or false"),
        (
            "[precise]\nallowed_penetration = 1.0\n",
            "precise.allowed_penetration",
            "allowed: 0.0000001 to 0.1",
        ),
        ("[precise]\nsubstep = 4\n", "precise.substep", "unknown key"),
    ] {
        let e = load_err(text);
        let msg = e.to_string();
        assert_eq!(e.key, key, "{msg}");
        assert!(msg.contains("bad.toml"), "{msg}");
        assert!(msg.contains(says), "{text}: {msg}");
    }
}
