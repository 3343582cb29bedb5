//! The scenes in config/scenes behave as their comments say.

mod support;

use common::BlockMode;
use glam::DVec3;
use support::*;

/// Every block of the report is resting.
fn all_resting(r: &stepper::Report) {
    for b in &r.blocks {
        assert_eq!(b.mode, BlockMode::Resting, "{}\n{}", b.name, r.to_text());
    }
}

#[test]
fn drop_blocks_fall_and_rest() {
    let s = scene_file("drop");
    let r = run(&s, 360);
    all_resting(&r);
    // Each rests on its lowest face: G at half the height (a wedge's and a tetra's G at 1/3 and
    // 1/4 of theirs), not rotated.
    let heights = [0.05, 0.025, 0.08 / 3.0, 0.025, 0.04];
    for (b, h) in r.blocks.iter().zip(heights) {
        assert!(
            (b.position[1] - h).abs() < 1e-12,
            "{}: {:?}",
            b.name,
            b.position
        );
        assert_eq!(b.rotation, [0.0, 0.0, 0.0, 1.0]);
    }
}

#[test]
fn wedge_tetra_and_hull_blocks_tip_onto_a_face() {
    let s = scene_file("wedge-tetra");
    let (_, events, w) = trace(&s, 600);
    for i in 0..w.block_count() {
        let b = w.block(i).unwrap();
        assert_eq!(b.mode, BlockMode::Resting, "block {i}");
        assert!(b.floor_contacts >= 3, "block {i} rests on a face: {b:?}");
        assert!(
            events
                .iter()
                .any(|e| e.block == i && e.kind == stepper::EventKind::Topple),
            "block {i} tipped"
        );
        let low = w.block_vertices(i).fold(f64::INFINITY, |m, v| m.min(v.y));
        assert!(low.abs() < 1e-9, "block {i}: lowest vertex {low}");
    }
}

#[test]
fn every_scene_is_deterministic_and_simulates() {
    for name in [
        "drop",
        "tip",
        "balance",
        "push",
        "carry",
        "stack-paper",
        "grasp-throw-fingers",
        "wedge-tetra",
    ] {
        let s = scene_file(name);
        let a = run(&s, 500);
        let b = run(&s, 500);
        assert_eq!(a.to_json(), b.to_json(), "{name}");
        assert_eq!(a.to_text(), b.to_text(), "{name}");
    }
}

#[test]
fn the_grip_scene_loads_and_builds_a_world() {
    // Its hand goes through the hand model (the binary wires it); here: no hand.
    let s = scene_file("grasp-throw");
    assert!(s.hand.is_some());
    let r = stepper::simulate(&s, 240, None).unwrap();
    assert_eq!(r.blocks[0].mode, BlockMode::Resting);
}

#[test]
fn push_moves_and_turns_the_cube() {
    let s = scene_file("push");
    let (_, _, w) = trace(&s, 240);
    let b = w.block(0).unwrap();
    assert_eq!(b.mode, BlockMode::Resting);
    let (axis, angle) = b.rotation.to_axis_angle();
    assert!((axis - DVec3::Y).length() < 1e-9, "turned about +y: {axis}");
    assert!(angle > 0.1, "{angle}");
    assert!(b.position.x > 0.01 && b.position.z < 0.0, "{}", b.position);
    assert!((b.position.y - 0.05).abs() < 1e-12);
}

#[test]
fn print_scene_summaries() {
    for name in [
        "drop",
        "tip",
        "balance",
        "push",
        "carry",
        "stack-paper",
        "wedge-tetra",
        "grasp-throw-fingers",
    ] {
        let s = scene_file(name);
        let r = run(&s, 600);
        print!("{name}: {}", r.to_text());
    }
}
