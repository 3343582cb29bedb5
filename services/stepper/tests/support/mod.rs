//! Helpers shared by the integration tests (the stepper's, and the bench's `tests/r14.rs`,
//! which includes this file).
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use common::config::Scene;
use stepper::{simulate, BareFingersHand, HandSource, Report};

/// Loads a scene from TOML text through the real loader (a temporary file).
pub fn scene(text: &str) -> Scene {
    static N: AtomicU64 = AtomicU64::new(0);
    let dir = std::env::temp_dir().join(format!("stepper-tests-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join(format!("scene{}.toml", N.fetch_add(1, Ordering::Relaxed)));
    std::fs::write(&file, text).unwrap();
    let s = Scene::load(&file).unwrap_or_else(|e| panic!("{e}"));
    let _ = std::fs::remove_file(&file);
    s
}

/// The repository's scene file `config/scenes/NAME.toml`.
pub fn scene_file(name: &str) -> Scene {
    // The workspace root above this crate (these helpers serve the stepper's tests and the
    // bench's, which include this file).
    let root = Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .find(|a| a.join("config/scenes").is_dir())
        .expect("config/scenes above the crate");
    let path: PathBuf = root.join("config/scenes").join(format!("{name}.toml"));
    Scene::load(&path).unwrap_or_else(|e| panic!("{e}"))
}

/// Runs a scene with its bare check-point hand (if any) for `frames` steps.
pub fn run(scene: &Scene, frames: u64) -> Report {
    let mut hand = BareFingersHand::from_scene(scene);
    simulate(
        scene,
        frames,
        hand.as_mut().map(|h| h as &mut dyn HandSource),
    )
    .unwrap_or_else(|e| panic!("{e}"))
}

/// A bare check-point hand sample: fingers in the world frame, wrist at `wrist` (identity
/// rotation), no palm, radius 0.
pub fn hand(fingers: &[&[[f64; 3]]], wrist: [f64; 3]) -> common::HandSample {
    let mut h = common::HandSample {
        tracked: 1,
        finger_count: fingers.len() as u32,
        ..Default::default()
    };
    h.wrist.position = wrist;
    for (f, pts) in fingers.iter().enumerate() {
        h.finger_point_count[f] = pts.len() as u32;
        for (k, p) in pts.iter().enumerate() {
            h.finger_points[f][k] = *p;
        }
    }
    h
}

/// Every step's block poses (index 0: the initial state).
pub type Poses = Vec<Vec<(glam::DVec3, glam::DQuat)>>;

/// Runs a scene with its bare hand and returns every step's block poses (after each step;
/// index 0 is the initial state) and the world.
pub fn trace(scene: &Scene, frames: u64) -> (Poses, Vec<stepper::Event>, stepper::World) {
    let mut hand = BareFingersHand::from_scene(scene);
    let mut w = stepper::World::new(scene).unwrap_or_else(|e| panic!("{e}"));
    let dt = 1.0 / scene.world.step_hz;
    let snap = |w: &stepper::World| {
        (0..w.block_count())
            .map(|i| {
                let b = w.block(i).unwrap();
                (b.position, b.rotation)
            })
            .collect::<Vec<_>>()
    };
    let mut out = vec![snap(&w)];
    let mut events = Vec::new();
    if let Some(h) = hand.as_mut() {
        w.set_previous_hand(h.hand_at(0, 0.0).as_ref());
    }
    for n in 1..=frames {
        let s = hand.as_mut().and_then(|h| h.hand_at(n, n as f64 * dt));
        w.step(s.as_ref());
        events.extend_from_slice(w.events());
        out.push(snap(&w));
    }
    (out, events, w)
}
