//! The precise model (rapier3d) through the real binary: `simulate --model precise` prints
//! the same bytes on every run, and a live session runs on it (scene `model = "precise"`).

use std::process::Command;

mod support;
use support::{both, launch_session, repo, Scratch, EXE};

fn simulate_precise(scene: &str) -> std::process::Output {
    Command::new(EXE)
        .current_dir(repo())
        .args(["simulate", "--model", "precise", "--json", scene])
        .output()
        .expect("run handblocks")
}

/// The hand-model grasp-throw (keyframes -> glove + tracker -> hand model -> kinematic
/// capsules and palm), twice: identical output, and the hand grasped and released the block.
#[test]
fn simulate_model_precise_prints_identical_bytes_across_runs() {
    let a = simulate_precise("config/scenes/grasp-throw.toml");
    let b = simulate_precise("config/scenes/grasp-throw.toml");
    assert!(a.status.success(), "{}", both(&a));
    assert_eq!(a.stdout, b.stdout, "two runs differ");
    let text = String::from_utf8_lossy(&a.stdout);
    assert!(
        text.contains("\"kind\": \"grasp\"") && text.contains("\"kind\": \"release\""),
        "{text}"
    );
}

/// A session whose scene says `model = "precise"`: the stepper process runs the reference
/// on the hand's timeline, and the session ends cleanly with its report.
#[test]
fn a_live_session_runs_on_the_precise_model() {
    let dir = Scratch::new("precise-live");
    let original = std::fs::read_to_string(repo().join("config/scenes/grasp-throw.toml")).unwrap();
    let scene = dir.path("scene.toml");
    std::fs::write(&scene, format!("[world]\nmodel = \"precise\"\n{original}")).unwrap();
    let session = dir.path("session.toml");
    std::fs::write(
        &session,
        format!(
            "scene = {:?}\nhand_model = {:?}\n[source]\nkind = \"scripted\"\nrate_hz = 120\n[renderer]\nmode = \"off\"\n",
            scene.to_string_lossy(),
            repo().join("config/hand.toml").to_string_lossy()
        ),
    )
    .unwrap();
    let report = dir.path("report.json");
    let id = format!("itprecise{}", std::process::id());
    let out = launch_session(&session, &id, 2.0, Some(&report));
    assert!(out.status.success(), "{}", both(&out));
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let received = r["topics"]["world"]["published"].as_u64().unwrap_or(0);
    assert!(received > 100, "{r}");
}
