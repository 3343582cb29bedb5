//! The `world` sample a stepper publishes is the world as it stands after every step: the
//! block entries the world keeps side by side for publishing (rewritten for the active blocks
//! only) and the header's grasped block (found among the active blocks only) agree, every
//! step of every scene of config/scenes and config/scenes/hard, with a full pass over the
//! blocks.

use std::path::Path;

use common::config::scene::ModelKind;
use common::config::Scene;
use common::{BlockMode, WorldHeader};
use stepper::{default_frames, BareFingersHand, World};

fn scenes() -> Vec<Scene> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/scenes");
    let mut files = Vec::new();
    for dir in [root.clone(), root.join("hard")] {
        for e in std::fs::read_dir(&dir).unwrap() {
            let p = e.unwrap().path();
            if p.extension().is_some_and(|x| x == "toml") {
                files.push(p);
            }
        }
    }
    files.sort();
    files
        .iter()
        .filter_map(|f| Scene::load(f).ok())
        .filter(|s| s.world.model == ModelKind::Paper)
        .collect()
}

#[test]
fn the_published_entries_and_grasped_block_are_the_worlds_every_step() {
    let mut checked = 0;
    let mut grasped_seen = false;
    for scene in scenes() {
        let Ok(mut world) = World::new(&scene) else {
            continue;
        };
        let hand = BareFingersHand::from_scene(&scene);
        let dt = 1.0 / scene.world.step_hz;
        let name = scene.file.display().to_string();
        for k in 1..=default_frames(&scene).min(900) {
            let h = hand.as_ref().map(|h| h.sample(k as f64 * dt));
            world.step(h.as_ref());
            let mut header = WorldHeader::default();
            world.write_header(&mut header);
            let first_grasped = (0..world.block_count())
                .find(|&i| world.block(i).is_some_and(|b| b.mode == BlockMode::Grasped))
                .map_or(-1, |i| i as i32);
            assert_eq!(header.grasped_block, first_grasped, "{name} step {k}");
            grasped_seen |= first_grasped >= 0;
            for i in 0..world.block_count() {
                let (b, s) = (world.block(i).unwrap(), world.block_state(i));
                assert_eq!(
                    s.pose.position,
                    b.position.to_array(),
                    "{name} step {k} block {i}"
                );
                assert_eq!(
                    s.pose.rotation,
                    b.rotation.to_array(),
                    "{name} step {k} block {i}"
                );
                assert_eq!(s.mode, b.mode as u32, "{name} step {k} block {i}");
            }
            checked += 1;
        }
    }
    assert!(checked > 10_000, "{checked} steps checked");
    assert!(
        grasped_seen,
        "no scene grasped a block: the header check meant nothing"
    );
}
