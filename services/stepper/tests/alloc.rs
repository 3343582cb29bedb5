//! "Keep one step allocation-free after warm-up": counts heap allocations made by
//! `World::step` over whole scenes (grasp, throw, carry, support, tipping, casts, R14), on the
//! stepping thread only (`counting-alloc`).

mod support;

use common::config::scene::HandRules;
use stepper::{BareFingersHand, HandSource, World};
use support::*;

#[global_allocator]
static GLOBAL: counting_alloc::Counting = counting_alloc::Counting;

#[test]
fn a_step_does_not_allocate_after_warm_up() {
    for name in [
        "grasp-throw-fingers",
        "stack-paper",
        "wedge-tetra",
        "carry",
        "push",
        "tip",
        "drop",
        "balance",
        // R14 supported stacking: judging, tipping with a load, landing, a hand in a stack.
        "hard/harmonic-4-101",
        "hard/push-into-stack",
        "hard/pyramid-15",
    ] {
        for hands in [HandRules::Paper, HandRules::Tracked] {
            let mut s = scene_file(name);
            // docs/model.md T1-T3: the margin's contacts, the held path, the fitted throw.
            s.world.hands = hands;
            steps_without_allocating(name, &s);
        }
    }
}

fn steps_without_allocating(name: &str, s: &common::config::Scene) {
    {
        let mut world = World::new(s).unwrap();
        let mut hand = BareFingersHand::from_scene(s);
        let dt = 1.0 / s.world.step_hz;
        let hands: Vec<Option<common::HandSample>> = (0..=600u64)
            .map(|n| hand.as_mut().and_then(|h| h.hand_at(n, n as f64 * dt)))
            .collect();
        world.set_previous_hand(hands[0].as_ref());
        for h in &hands[1..4] {
            world.step(h.as_ref());
        }
        let before = counting_alloc::allocations();
        for h in &hands[4..] {
            world.step(h.as_ref());
        }
        let made = counting_alloc::allocations() - before;
        assert_eq!(
            made, 0,
            "{name} ({:?} hands): {made} allocations in 597 steps",
            s.world.hands
        );
    }
}

/// Issue 14's scale: a 4096-block world (R14 supported stacking, half the cubes resting, half
/// falling onto the floor between them, some landing on others) steps without allocating.
#[test]
fn a_step_of_a_4096_block_world_does_not_allocate() {
    let mut text = String::from("[effects]\nstacking = \"supported\"\n");
    for i in 0..4096usize {
        let (x, z) = ((i % 64) as f64 * 0.05, (i / 64) as f64 * 0.05);
        // Even cubes rest; odd ones fall from 6 to 21 cm, the first of each row onto the
        // cube resting beside it (half a pitch over), the others onto the floor.
        let (x, y) = if i % 2 == 0 {
            (x, 0.02)
        } else if i % 64 == 1 {
            (x - 0.05, 0.06 + 0.15 * (i % 7) as f64 / 6.0)
        } else {
            (x, 0.06 + 0.15 * (i % 7) as f64 / 6.0)
        };
        text += &format!("[[block]]\nsize = [0.04, 0.04, 0.04]\nposition = [{x}, {y}, {z}]\n");
    }
    let s = scene(&text);
    let mut world = World::new(&s).unwrap();
    for _ in 0..4 {
        world.step(None);
    }
    let ((), made) = counting_alloc::count(|| {
        for _ in 0..36 {
            world.step(None);
        }
    });
    assert_eq!(made, 0, "4096 blocks: {made} allocations in 36 steps");
}
