//! Helpers shared by the integration tests.
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
    let path: PathBuf = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../config/scenes")
        .join(format!("{name}.toml"));
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
