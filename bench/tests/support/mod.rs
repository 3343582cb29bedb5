//! Helpers for `tests/r14.rs`: those of the stepper's own `services/stepper/tests/support/`
//! that it uses (it moved here with the hard-case harness, whose `overlaps` it reads).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use common::config::Scene;
use stepper::{BareFingersHand, HandSource};

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
    let path: PathBuf = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../config/scenes")
        .join(format!("{name}.toml"));
    Scene::load(&path).unwrap_or_else(|e| panic!("{e}"))
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
