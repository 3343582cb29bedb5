//! "Keep one step allocation-free after warm-up": counts heap allocations made by
//! `World::step` over whole scenes (grasp, throw, carry, support, tipping, casts, R14).

mod support;

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use stepper::{BareFingersHand, HandSource, World};
use support::*;

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

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
        let s = scene_file(name);
        let mut world = World::new(&s).unwrap();
        let mut hand = BareFingersHand::from_scene(&s);
        let dt = 1.0 / s.world.step_hz;
        let hands: Vec<Option<common::HandSample>> = (0..=600u64)
            .map(|n| hand.as_mut().and_then(|h| h.hand_at(n, n as f64 * dt)))
            .collect();
        world.set_previous_hand(hands[0].as_ref());
        for h in &hands[1..4] {
            world.step(h.as_ref());
        }
        let before = ALLOCATIONS.load(Ordering::Relaxed);
        for h in &hands[4..] {
            world.step(h.as_ref());
        }
        let made = ALLOCATIONS.load(Ordering::Relaxed) - before;
        assert_eq!(made, 0, "{name}: {made} allocations in 597 steps");
    }
}
