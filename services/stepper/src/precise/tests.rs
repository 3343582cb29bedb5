//! Checks that need the precise world's insides: the mode derivation (skipping the bodies that
//! slept through a step, reading the contacts in one pass over the pairs) leaves every mode,
//! contact count and event as judging every block by its own contact query does.

use std::path::{Path, PathBuf};

use common::config::scene::{
    BlockSpec, Effects, HandKey, HandPoseSpec, HandScript, ModelKind, ShapeSpec, WorldSettings,
};
use common::config::Scene;
use common::HandSample;

use super::PreciseWorld;
use crate::simulate::{default_frames, BareFingersHand};

fn config_scene(name: &str) -> Scene {
    let file = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../config/scenes")
        .join(name);
    Scene::load(&file).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// Three cubes face to face on the floor and a bare fingertip that waits far off for 1.5 s
/// (every cube falls asleep), pushes the first one into the others, stands still against it
/// for 1.5 s (asleep again, touching a still kinematic finger), and leaves; `gaps` are the
/// steps given no hand at all (its colliders switched off while it touches a sleeping cube).
fn push_after_sleep() -> Scene {
    let cube = |name: &str, x: f64| BlockSpec {
        name: name.into(),
        shape: ShapeSpec::Box { size: [0.1; 3] },
        position: [x, 0.05, 0.0],
        rotation: [0.0, 0.0, 0.0, 1.0],
        velocity: [0.0; 3],
    };
    let key = |t: f64, x: f64, y: f64| HandKey {
        t,
        wrist: [x, y, 0.0],
        wrist_rotation: [0.0, 0.0, 0.0, 1.0],
        pose: HandPoseSpec::Fingers(vec![vec![[0.0; 3]]]),
    };
    Scene {
        file: PathBuf::from("<precise tests: push after sleep>"),
        world: WorldSettings {
            model: ModelKind::Precise,
            ..WorldSettings::default()
        },
        effects: Effects::default(),
        blocks: vec![cube("a", 0.0), cube("b", 0.1), cube("c", 0.2)],
        hand: Some(HandScript {
            keys: vec![
                key(0.0, -0.5, 0.05),
                key(1.5, -0.5, 0.05),
                key(2.0, -0.0498, 0.05),
                key(2.3, -0.0452, 0.05),
                key(3.8, -0.0452, 0.05),
                key(4.3, -0.3, 0.4),
            ],
        }),
        left_hand: None,
    }
}

/// A cube held by the bare fingers of grasp-throw-fingers.toml with a smaller one standing on
/// it: carried while the grasp lasts.
fn grasp_with_a_rider() -> Scene {
    let mut s = config_scene("grasp-throw-fingers.toml");
    let base = s.blocks[0].clone();
    let (ShapeSpec::Box { size }, [x, y, z]) = (&base.shape, base.position) else {
        panic!("grasp-throw-fingers.toml: a box first");
    };
    s.blocks.push(BlockSpec {
        name: "rider".into(),
        shape: ShapeSpec::Box { size: [0.02; 3] },
        position: [x, y + size[1] / 2.0 + 0.01, z],
        ..base
    });
    s.file = PathBuf::from("<precise tests: grasp with a rider>");
    s
}

/// Steps `scene` under the precise model (sleeping as `sleep` says), twice side by side: once
/// as the model runs, once judging every block by its own contact query every step. Returns
/// how many block judgements the first one skipped.
fn skipped_judgements(scene: &Scene, sleep: bool, gaps: &[std::ops::Range<u64>]) -> usize {
    let mut scene = scene.clone();
    scene.world.model = ModelKind::Precise;
    scene.world.precise.sleep = sleep;
    let name = scene.file.display().to_string();
    let hand = BareFingersHand::from_scene(&scene);
    let dt = 1.0 / scene.world.step_hz;
    let sample = |k: u64| -> Option<HandSample> {
        if gaps.iter().any(|g| g.contains(&k)) {
            return None;
        }
        hand.as_ref().map(|h| h.sample(k as f64 * dt))
    };
    let mut fast = PreciseWorld::new(&scene).unwrap_or_else(|e| panic!("{name}: {e}"));
    let mut all = PreciseWorld::new(&scene).unwrap_or_else(|e| panic!("{name}: {e}"));
    all.judge_all = true;
    fast.set_previous_hand(sample(0).as_ref());
    all.set_previous_hand(sample(0).as_ref());
    let n = fast.block_count();
    let mut skipped = 0;
    for k in 1..=default_frames(&scene) + 240 {
        let h = sample(k);
        fast.step(h.as_ref());
        all.step(h.as_ref());
        assert_eq!(fast.events(), all.events(), "{name}: events of step {k}");
        for i in 0..n {
            let (a, b) = (&fast.blocks[i], &all.blocks[i]);
            assert_eq!(
                (a.mode, a.touching, a.floor_contacts),
                (b.mode, b.touching, b.floor_contacts),
                "{name}: block {i} after step {k}"
            );
            // The bodies themselves never differ: the derivation only reads them.
            assert_eq!(
                fast.block(i).map(|v| (v.position, v.rotation)),
                all.block(i).map(|v| (v.position, v.rotation)),
                "{name}: block {i}'s pose after step {k}"
            );
        }
        skipped += n - fast.judge.len();
    }
    skipped
}

#[test]
fn skipping_sleeping_bodies_keeps_every_mode_and_event() {
    let mut skipped = Vec::new();
    let custom = push_after_sleep();
    // The hand gone for a few steps while it stands against a sleeping cube, and again later.
    let gaps = [420..426, 445..448];
    skipped.push((
        "push after sleep".to_string(),
        skipped_judgements(&custom, true, &gaps),
    ));
    for name in [
        "push.toml",
        "carry.toml",
        "tip.toml",
        "drop.toml",
        "balance.toml",
        "stack-paper.toml",
        "wedge-tetra.toml",
        "grasp-throw-fingers.toml",
        "hard/push-into-stack.toml",
        "hard/drop-onto-tower.toml",
        "hard/pyramid-knocked.toml",
        "hard/staggered.toml",
    ] {
        skipped.push((
            name.to_string(),
            skipped_judgements(&config_scene(name), true, &[]),
        ));
    }
    // The check means something only where bodies did sleep.
    for (name, s) in &skipped {
        assert!(*s > 0, "{name}: no body ever slept ({skipped:?})");
    }
}

#[test]
fn one_pass_over_the_pairs_counts_what_each_block_s_own_query_counts() {
    let rider = grasp_with_a_rider();
    assert_eq!(skipped_judgements(&rider, false, &[]), 0);
    // The rider was carried: the case where the first block touched matters.
    let mut w = PreciseWorld::new(&rider).expect("the rider scene");
    let hand = BareFingersHand::from_scene(&rider).expect("bare fingers");
    let dt = 1.0 / rider.world.step_hz;
    w.set_previous_hand(Some(&hand.sample(0.0)));
    let mut carried = false;
    for k in 1..=default_frames(&rider) {
        w.step(Some(&hand.sample(k as f64 * dt)));
        carried |= w.blocks[1].mode == common::BlockMode::Carried;
    }
    assert!(carried, "the rider was never carried");
    for name in [
        "push.toml",
        "carry.toml",
        "drop.toml",
        "stack-paper.toml",
        "grasp-throw-fingers.toml",
        "hard/push-into-stack.toml",
        "hard/bullet-200-wall.toml",
        "hard/staggered.toml",
    ] {
        assert_eq!(skipped_judgements(&config_scene(name), false, &[]), 0);
    }
    // Sleeping on, most blocks awake at first: the pass, then the blocks' own queries.
    assert!(skipped_judgements(&rider, true, &[]) > 0);
}
