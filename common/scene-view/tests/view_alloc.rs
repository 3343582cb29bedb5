//! The view is rewritten in place: after the first updates, drawing a world and a hand,
//! rewriting the hand's frames, stamping them and encoding the scene and the frames allocate
//! nothing (the live view and the recorder do this up to 60 times a second). Counted with a
//! global allocator that tallies per thread.

use common::samples::{BlockState, HandSample, HandSide};
use common::Pose;
use scene_view::SceneView;

#[global_allocator]
static GLOBAL: counting_alloc::Counting = counting_alloc::Counting;

fn scene() -> common::config::Scene {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/scenes");
    common::config::Scene::load(&dir.join("carry.toml")).expect("the scene loads")
}

/// A hand of the kinematics' shape at `x`, its fingers curled by `curl`, on `side`.
fn hand(x: f64, curl: f64, side: HandSide) -> HandSample {
    let mut h = HandSample {
        wrist: Pose {
            position: [x, 0.2, 0.0],
            rotation: [0.0, (curl / 2.0).sin(), 0.0, (curl / 2.0).cos()],
        },
        tracked: 1,
        finger_count: 5,
        palm_vertex_count: 8,
        side: side.code(),
        ..Default::default()
    };
    for f in 0..5 {
        let n = if f == 0 { 3 } else { 4 };
        h.finger_point_count[f] = n as u32;
        h.finger_radius[f] = 0.008;
        for k in 0..n {
            h.finger_points[f][k] = [
                x - 0.03 + 0.015 * f as f64,
                0.2 - curl * 0.01 * (k * k) as f64,
                -0.09 - 0.025 * k as f64,
            ];
        }
    }
    let mut i = 0;
    for dx in [-0.04, 0.04] {
        for dy in [-0.01, 0.01] {
            for dz in [0.0, -0.09] {
                h.palm_vertices[i] = [x + dx, 0.2 + dy, dz];
                i += 1;
            }
        }
    }
    h
}

#[test]
fn drawing_and_sending_the_scene_and_the_frames_allocates_nothing() {
    let scene = scene();
    let blocks = scene.blocks.len();
    let mut view = SceneView::new(&scene).expect("a view");
    let (mut scene_bytes, mut tf_bytes) = (Vec::new(), Vec::new());
    let mut step = |view: &mut SceneView, k: u64| {
        let t = k as f64 * 0.01;
        view.set_hand(&hand(t.sin() * 0.1, 0.5 + 0.4 * t.cos(), HandSide::Right));
        view.set_hand(&hand(-0.4 + t.cos() * 0.1, 0.5, HandSide::Left));
        view.set_world(blocks, |i| BlockState {
            pose: Pose {
                position: [i as f64 * 0.1, 0.03 + t, 0.0],
                ..Pose::IDENTITY
            },
            ..Default::default()
        });
        view.encode_into(&mut scene_bytes);
        view.frames_mut().stamp(1_700_000_000_000_000_000 + k);
        view.frames().encode_into(&mut tf_bytes);
    };
    for k in 0..1000 {
        // Warm-up over the motion measured below: the lists and buffers grow to their size
        // (an encoding grows by a few bytes when a value that was exactly 0 is not).
        step(&mut view, k);
    }
    assert_eq!(
        view.frames().message().transforms.len(),
        40,
        "two hands' trees"
    );
    let ((), made) = counting_alloc::count(|| {
        for k in 0..1000 {
            step(&mut view, k);
        }
    });
    assert_eq!(made, 0, "{made} allocations in 1000 updates");
    assert!(!scene_bytes.is_empty() && !tf_bytes.is_empty());
}
