//! Property tests over random scenes and hand motions: no NaN, unit quaternions, no vertex below
//! the floor by more than contact_eps after any step, and bit-identical results on a second run.

use std::path::PathBuf;

use glam::{DQuat, DVec3};
use proptest::prelude::*;

use common::config::scene::{
    BlockSpec, Effects, FloorEffect, HandEffect, HandKey, HandPoseSpec, HandScript, ShapeSpec,
    Stacking, WorldSettings,
};
use common::config::Scene;
use common::BlockMode;
use stepper::geometry::Polyhedron;
use stepper::{BareFingersHand, HandSource, World};

fn shape() -> impl Strategy<Value = ShapeSpec> {
    let size = prop::array::uniform3(0.02f64..0.2);
    prop_oneof![
        size.clone().prop_map(|size| ShapeSpec::Box { size }),
        size.clone().prop_map(|size| ShapeSpec::Wedge { size }),
        size.prop_map(|size| ShapeSpec::Tetra { size }),
        prop::collection::vec(prop::array::uniform3(-0.08f64..0.08), 4..12)
            .prop_map(|vertices| ShapeSpec::Hull { vertices }),
    ]
}

fn rotation() -> impl Strategy<Value = [f64; 4]> {
    (
        prop::array::uniform3(-1.0f64..1.0),
        0.0f64..std::f64::consts::TAU,
    )
        .prop_map(|(a, angle)| {
            let axis = DVec3::from_array(a).try_normalize().unwrap_or(DVec3::Y);
            DQuat::from_axis_angle(axis, angle).to_array()
        })
}

/// Blocks on a grid 0.5 m apart (so none starts inside another), at a random height above
/// the floor (or just on it), with a random velocity.
fn blocks() -> impl Strategy<Value = Vec<BlockSpec>> {
    prop::collection::vec(
        (
            shape(),
            rotation(),
            0.0f64..0.6,
            prop::array::uniform3(-2.0f64..2.0),
            prop::bool::ANY,
        ),
        1..6,
    )
    .prop_map(|v| {
        v.into_iter()
            .enumerate()
            .filter_map(|(i, (shape, rotation, height, velocity, on_floor))| {
                let poly = Polyhedron::from_spec(&shape).ok()?;
                let q = DQuat::from_array(rotation);
                let low = poly
                    .vertices
                    .iter()
                    .map(|p| (q * *p).y)
                    .fold(f64::INFINITY, f64::min);
                let y = -low + if on_floor { 0.0 } else { height };
                let x = (i % 3) as f64 * 0.5 - 0.5;
                let z = (i / 3) as f64 * 0.5;
                Some(BlockSpec {
                    name: format!("b{i}"),
                    shape,
                    position: [x, y, z],
                    rotation,
                    velocity: if on_floor { [0.0; 3] } else { velocity },
                })
            })
            .collect()
    })
}

/// A bare check-point hand with 1-3 fingers of 1-3 points, sweeping through the block area.
fn hand() -> impl Strategy<Value = Option<HandScript>> {
    let finger = prop::collection::vec(prop::array::uniform3(-0.1f64..0.1), 1..4);
    (
        1usize..4,
        prop::collection::vec(
            (
                prop::array::uniform3(-0.8f64..0.8),
                rotation(),
                prop::collection::vec(finger, 3),
            ),
            2..5,
        ),
        prop::bool::weighted(0.85),
    )
        .prop_map(|(nf, keys, present)| {
            if !present {
                return None;
            }
            // Every key has the same finger layout as the first.
            let layout: Vec<usize> = keys[0].2.iter().take(nf).map(|f| f.len()).collect();
            let keys = keys
                .into_iter()
                .enumerate()
                .map(|(k, (wrist, rot, fingers))| HandKey {
                    t: k as f64 * 0.4,
                    wrist: [wrist[0], wrist[1].abs() * 0.4 + 0.02, wrist[2] * 0.5 + 0.2],
                    wrist_rotation: rot,
                    pose: HandPoseSpec::Fingers(
                        layout
                            .iter()
                            .enumerate()
                            .map(|(f, &n)| {
                                (0..n).map(|j| fingers[f][j % fingers[f].len()]).collect()
                            })
                            .collect(),
                    ),
                })
                .collect();
            Some(HandScript { keys })
        })
}

/// Two fingers that close on whatever is at x = -0.5, z = 0 near the floor (block 0's place),
/// then carry it along random wrist positions and rotations, and open: grasps, carries and
/// throws under random shapes and poses.
fn pinch() -> impl Strategy<Value = Option<HandScript>> {
    (
        prop::collection::vec((prop::array::uniform3(-0.5f64..0.5), rotation()), 1..4),
        0.01f64..0.2,
        -0.04f64..0.04,
    )
        .prop_map(|(moves, open_time, dy)| {
            let fingers = |x: f64| {
                HandPoseSpec::Fingers(vec![
                    vec![[-x, 0.05, 0.0], [-x, dy, 0.0]],
                    vec![[x, 0.05, 0.0], [x, dy, 0.0]],
                ])
            };
            let at = |t: f64, w: [f64; 3], r: [f64; 4], x: f64| HandKey {
                t,
                wrist: w,
                wrist_rotation: r,
                pose: fingers(x),
            };
            let id = [0.0, 0.0, 0.0, 1.0];
            let mut keys = vec![
                at(0.0, [-0.5, 0.05, 0.0], id, 0.25),
                at(0.5, [-0.5, 0.05, 0.0], id, 0.25),
                at(0.8, [-0.5, 0.05, 0.0], id, 0.0),
            ];
            let mut t = 0.8;
            for (w, r) in &moves {
                t += 0.25;
                keys.push(at(t, [-0.5 + w[0], 0.3 + w[1], w[2]], *r, 0.0));
            }
            let last = keys
                .last()
                .map(|k| (k.wrist, k.wrist_rotation))
                .unwrap_or(([0.0; 3], id));
            keys.push(at(t + open_time, last.0, last.1, 0.25));
            Some(HandScript { keys })
        })
}

fn scene() -> impl Strategy<Value = Scene> {
    let hand = prop_oneof![hand(), pinch()];
    let effects = (
        prop::bool::weighted(0.8),
        prop::bool::weighted(0.8),
        prop::bool::ANY,
        prop::sample::select(vec![
            FloorEffect::Tipping,
            FloorEffect::Tipping,
            FloorEffect::Rest,
        ]),
        prop::sample::select(vec![HandEffect::Grasp, HandEffect::Grasp, HandEffect::Push]),
    );
    (blocks(), hand, effects).prop_map(
        |(blocks, hand, (gravity, inertia, carry, floor, hand_effect))| Scene {
            file: PathBuf::from("proptest.toml"),
            world: WorldSettings::default(),
            effects: Effects {
                gravity: gravity || hand.is_none(),
                inertia,
                carry,
                floor,
                hand: hand_effect,
                ..Effects::default()
            },
            blocks,
            hand,
            left_hand: None,
        },
    )
}

/// Runs the scene, checking the invariants after every step; returns every pose.
fn run_checked(s: &Scene, steps: u64) -> Result<Vec<(DVec3, DQuat)>, TestCaseError> {
    let mut world = World::new(s).map_err(|e| TestCaseError::fail(e.to_string()))?;
    let mut hand = s.hand.as_ref().and_then(BareFingersHand::from_script);
    let dt = 1.0 / s.world.step_hz;
    if let Some(h) = hand.as_mut() {
        world.set_previous_hand(h.hand_at(0, 0.0).as_ref());
    }
    let mut poses = Vec::new();
    let mut last: Vec<(DVec3, DQuat, BlockMode)> = Vec::new();
    for n in 1..=steps {
        let h = hand.as_mut().and_then(|h| h.hand_at(n, n as f64 * dt));
        world.step(h.as_ref());
        for i in 0..world.block_count() {
            let b = world.block(i).unwrap();
            prop_assert!(
                b.position.is_finite() && b.rotation.is_finite(),
                "NaN at step {n}: {b:?}"
            );
            prop_assert!(
                (b.rotation.length() - 1.0).abs() < 1e-6,
                "step {n}: |q| = {}",
                b.rotation.length()
            );
            if s.effects.floor != FloorEffect::None {
                let low = world
                    .block_vertices(i)
                    .fold(f64::INFINITY, |m, v| m.min(v.y));
                prop_assert!(
                    low >= -s.world.contact_eps,
                    "step {n}: block {i} has a vertex {low} below the floor ({:?})",
                    b.mode
                );
            }
            // A block resting before and after a step did not move at all.
            if let Some(&(p, q, m)) = last.get(i) {
                if m == BlockMode::Resting && b.mode == BlockMode::Resting {
                    prop_assert!(
                        p == b.position && q == b.rotation,
                        "step {n}: resting block {i} moved"
                    );
                }
            }
            poses.push((b.position, b.rotation));
        }
        last.clear();
        last.extend((0..world.block_count()).map(|i| {
            let b = world.block(i).unwrap();
            (b.position, b.rotation, b.mode)
        }));
    }
    Ok(poses)
}

/// R14: stacks of 2-4 random shapes, each dropped 1 mm onto the one below (its lowest vertex
/// 1 mm above the other's highest) with a random offset, two such stacks, and a random hand.
fn stacks() -> impl Strategy<Value = Scene> {
    let block = (shape(), rotation(), -0.05f64..0.05, -0.05f64..0.05);
    (
        prop::collection::vec(prop::collection::vec(block, 2..5), 2),
        prop_oneof![hand(), pinch()],
    )
        .prop_map(|(stacks, hand)| {
            let mut blocks = Vec::new();
            for (s, stack) in stacks.into_iter().enumerate() {
                let mut top = 0.0f64;
                for (shape, rotation, dx, dz) in stack {
                    let Ok(poly) = Polyhedron::from_spec(&shape) else {
                        continue;
                    };
                    let q = DQuat::from_array(rotation);
                    let ys = poly.vertices.iter().map(|p| (q * *p).y);
                    let (low, high) = ys.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), y| {
                        (l.min(y), h.max(y))
                    });
                    let y = top - low + if top > 0.0 { 0.001 } else { 0.0 };
                    top = y + high;
                    blocks.push(BlockSpec {
                        name: format!("b{}", blocks.len()),
                        shape,
                        position: [-0.5 + dx + s as f64 * 0.8, y, dz],
                        rotation,
                        velocity: [0.0; 3],
                    });
                }
            }
            Scene {
                file: PathBuf::from("proptest-stacks.toml"),
                world: WorldSettings::default(),
                effects: Effects {
                    stacking: Stacking::Supported,
                    ..Effects::default()
                },
                blocks,
                hand,
                left_hand: None,
            }
        })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 128, ..ProptestConfig::default() })]

    #[test]
    fn r14_random_stacks_keep_the_invariants_and_repeat_exactly(s in stacks()) {
        let a = run_checked(&s, 240)?;
        let b = run_checked(&s, 240)?;
        prop_assert!(a == b, "a second run differs");
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn random_scenes_keep_the_invariants_and_repeat_exactly(s in scene()) {
        let a = run_checked(&s, 240)?;
        let b = run_checked(&s, 240)?;
        prop_assert!(a == b, "a second run differs");
    }
}
