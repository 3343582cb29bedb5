//! R14 supported stacking [extension]: stacks hold exactly when statics says they do
//! (docs/model.md R14 "Consequences to test"; docs/accuracy-cost.md "What it is judged against":
//! a stack stands iff at every interface the centre of gravity of everything above lies in that
//! interface's contact area; the harmonic stack's top overhangs 1/2 H_n block lengths). Each stack is also run in
//! paper mode (R11), which keeps every one of them where it is.

#[path = "../../services/stepper/tests/support/mod.rs"]
mod support;

use glam::DVec3;

use common::BlockMode;
use support::*;

/// Cube edge.
const L: f64 = 0.1;

/// A scene of 0.1 m cubes stacked exactly touching: cube k at x = `xs[k]` with its bottom face
/// at y = k L (cube 0 on the floor), turned `yaw[k]` degrees about y (0 when absent).
fn stack(stacking: &str, xs: &[f64], yaw: &[f64]) -> common::config::Scene {
    let mut t = format!("[effects]\nstacking = \"{stacking}\"\n");
    for (k, x) in xs.iter().enumerate() {
        let a = yaw.get(k).copied().unwrap_or(0.0).to_radians() / 2.0;
        t.push_str(&format!(
            "[[block]]\nname = \"c{k}\"\nposition = [{x}, {}, 0.0]\nrotation = [0.0, {}, 0.0, {}]\n",
            L / 2.0 + L * k as f64,
            a.sin(),
            a.cos()
        ));
    }
    scene(&t)
}

/// Every block's pose at every step after the first (the first step lands them: R8's first
/// impact) is bit-for-bit that of step 1.
fn never_moves(s: &common::config::Scene, steps: u64) -> Result<(), String> {
    let (poses, _, _) = trace(s, steps);
    for (k, p) in poses.iter().enumerate().skip(1) {
        if *p != poses[1] {
            return Err(format!("moved at step {k}: {:?} vs {:?}", p, poses[1]));
        }
    }
    // Nothing moved on step 1 either: the blocks were spawned exactly touching.
    if poses[1] != poses[0] {
        return Err(format!("moved on step 1: {:?} vs {:?}", poses[1], poses[0]));
    }
    Ok(())
}

/// The harmonic stack of n cubes on a base cube, scaled by `s`: cube k from the top
/// (k = 1..n) is offset s L / (2k) from the one below it, so that the top overhangs the base's
/// edge by s 1/2 H_n block lengths and at s = 1 every interface carries its load's G_L exactly
/// on its edge.
fn harmonic(n: usize, s: f64) -> Vec<f64> {
    let mut xs = vec![0.0; n + 1];
    for (i, x) in xs.iter_mut().enumerate().skip(1) {
        // Block i from the bottom of the stack is k = n + 1 - i from the top.
        *x = (n + 1 - i..=n).map(|m| s * L / (2.0 * m as f64)).sum();
    }
    xs
}

#[test]
fn r14_an_aligned_tower_never_moves() {
    let xs = vec![0.0; 20];
    let s = stack("supported", &xs, &[]);
    never_moves(&s, 600).unwrap();
    let (_, _, w) = trace(&s, 10);
    assert_eq!(w.block(0).unwrap().mode, BlockMode::Resting);
    for i in 1..20 {
        assert_eq!(w.block(i).unwrap().mode, BlockMode::Supported, "cube {i}");
    }
    never_moves(&stack("paper", &xs, &[]), 600).unwrap();
}

/// Three cubes, each 0.3 L beyond the one below: the top's G is 0.6 L from the bottom's centre,
/// beyond its edge (0.5 L), but every interface carries its load: the top on the middle at
/// 0.3 L, the top two on the bottom at 0.45 L, all three on the floor at 0.3 L.
#[test]
fn r14_a_staggered_stack_with_its_top_beyond_the_bottom_stays_exactly_still() {
    let xs = [0.0, 0.3 * L, 0.6 * L];
    let s = stack("supported", &xs, &[]);
    never_moves(&s, 600).unwrap();
    never_moves(&stack("paper", &xs, &[]), 600).unwrap();
}

/// Two 0.3 m slabs (base on the floor, A on it), cube B on A 0.02 m inside A's right edge, cube
/// C on B 0.045 m beyond B: C on B holds (0.045 < 0.05), B inside its own support, but B and C
/// on A put G_L at x = 0.1525, beyond A's edge at 0.15. So the stack topples from the A-B
/// interface up: base and A never move (A's load with B and C is at most x = 0.124 even when
/// they have turned over, and while B tips over A's edge its weight rests on that edge), B and
/// C come down beyond A and lie still.
#[test]
fn r14_a_combined_load_beyond_a_lower_interface_topples_from_there_up() {
    let text = |stacking: &str| {
        format!(
            "[effects]\nstacking = \"{stacking}\"\n\
             [[block]]\nname = \"base\"\nsize = [0.3, 0.1, 0.1]\nposition = [0.0, 0.05, 0.0]\n\
             [[block]]\nname = \"A\"\nsize = [0.3, 0.1, 0.1]\nposition = [0.0, 0.15, 0.0]\n\
             [[block]]\nname = \"B\"\nposition = [0.13, 0.25, 0.0]\n\
             [[block]]\nname = \"C\"\nposition = [0.175, 0.35, 0.0]\n"
        )
    };
    let s = scene(&text("supported"));
    let (poses, events, w) = trace(&s, 1500);
    for p in &poses {
        assert_eq!(p[0], poses[0][0], "the base never moves");
        assert_eq!(p[1], poses[0][1], "A never moves");
    }
    let first_topple = events
        .iter()
        .find(|e| e.kind == stepper::EventKind::Topple)
        .expect("a topple");
    assert_eq!(first_topple.block, 2, "B topples first: {first_topple:?}");
    // B and C came down beyond A's edge and lie still: C on the floor, B leaning on A's side
    // and C (perfect friction holds it there).
    for (i, below) in [(2, 0.25), (3, 0.1)] {
        let b = w.block(i).unwrap();
        assert!(b.position.is_finite() && (b.rotation.length() - 1.0).abs() < 1e-12);
        assert!(b.position.y < below, "block {i} came down: {}", b.position);
        assert!(b.position.x > 0.15, "block {i} fell beyond A's edge");
        assert!(
            poses[1400..].iter().all(|p| p[i] == poses[1400][i]),
            "block {i} lies still"
        );
    }
    never_moves(&scene(&text("paper")), 600).unwrap();
}

/// docs/accuracy-cost.md: harmonic stacks of n = 2, 3, 4 cubes on a base overhang 1/2 H_n block
/// lengths (0.75, 0.917, 1.042): at 99% of it they stand exactly still, at 101% they fall (the
/// lowest interface over the base edge is exceeded: everything above the base topples as one)
/// and the base never moves. Paper mode keeps both.
#[test]
fn r14_harmonic_stacks_stand_at_99_percent_and_fall_at_101() {
    for n in [2, 3, 4] {
        let xs = harmonic(n, 0.99);
        let h_n: f64 = (1..=n).map(|m| 1.0 / m as f64).sum();
        assert!((xs[n] - 0.99 * L * h_n / 2.0).abs() < 1e-15);
        never_moves(&stack("supported", &xs, &[]), 400).unwrap_or_else(|e| panic!("n = {n}: {e}"));
        never_moves(&stack("paper", &xs, &[]), 400).unwrap_or_else(|e| panic!("n = {n}: {e}"));

        let xs = harmonic(n, 1.01);
        let (poses, _, w) = trace(&stack("supported", &xs, &[]), 3000);
        // The statics verdict: everything above the base topples over its edge as one; the
        // base never moves (while they tip over its edge, and lean on it, their weight rests
        // on that edge).
        assert!(poses.iter().all(|p| p[0] == poses[0][0]), "n = {n}: base");
        for i in 1..=n {
            let b = w.block(i).unwrap();
            assert!(
                b.position.y < L / 2.0 + L * i as f64 && b.position.x > 0.05,
                "n = {n}: block {i} came down beyond the base: {}",
                b.position
            );
        }
        never_moves(&stack("paper", &xs, &[]), 400).unwrap_or_else(|e| panic!("n = {n}: {e}"));
    }
}

/// A cube turned 45 deg on another: no vertex of either lies on the other's face, so only the
/// edge crossings of the contact manifold give the octagon they share. It is supported, exactly
/// still, also shifted 0.03 m (its G still over the octagon).
#[test]
fn r14_a_cube_turned_45_degrees_on_another_is_supported() {
    for x in [0.0, 0.03] {
        let s = stack("supported", &[0.0, x], &[0.0, 45.0]);
        never_moves(&s, 300).unwrap();
        let (_, _, w) = trace(&s, 5);
        assert_eq!(w.block(1).unwrap().mode, BlockMode::Supported);
    }
}

/// A block beside a stack is no supporter (side contact): a cube dropped so that it slides down
/// the side of a tower (touching it) falls to the floor instead of hanging where it touched.
#[test]
fn r14_r12_a_block_sliding_down_the_side_of_another_does_not_hang() {
    let s = scene(
        "[effects]\nstacking = \"supported\"\n\
         [[block]]\nname = \"post\"\nsize = [0.1, 0.6, 0.1]\nposition = [0.0, 0.3, 0.0]\n\
         [[block]]\nname = \"slider\"\nposition = [0.1, 0.5, 0.0]\n",
    );
    let (_, _, w) = trace(&s, 300);
    let b = w.block(1).unwrap();
    assert_eq!(b.mode, BlockMode::Resting);
    assert!(
        (b.position - DVec3::new(0.1, 0.05, 0.0)).length() < 1e-9,
        "{}",
        b.position
    );
}

/// Every scene of config/scenes also runs under R14: no two blocks ever overlap by more than
/// contact_eps, and everything lies still at the end (stack-paper's overhanging "top" now falls:
/// its G is beyond the base's edge).
#[test]
fn r14_every_scene_runs_under_supported_stacking() {
    use handblocks_bench::hard_cases::overlaps;
    use stepper::geometry::Polyhedron;
    for name in [
        "drop",
        "tip",
        "balance",
        "push",
        "grasp-throw-fingers",
        "carry",
        "stack-paper",
        "wedge-tetra",
    ] {
        let mut s = scene_file(name);
        s.effects.stacking = common::config::scene::Stacking::Supported;
        let polys: Vec<Polyhedron> = s
            .blocks
            .iter()
            .map(|b| Polyhedron::from_spec(&b.shape).unwrap())
            .collect();
        let (poses, _, w) = trace(&s, 900);
        let (mut va, mut vb) = (Vec::new(), Vec::new());
        for (k, p) in poses.iter().enumerate() {
            assert!(
                p.iter().all(|(g, q)| g.is_finite() && q.is_finite()),
                "{name}: a pose is not finite at step {k}"
            );
            if let Some((d, i, j)) = overlaps(&polys, p, &mut va, &mut vb).deepest_pair {
                assert!(
                    d <= 1e-4,
                    "{name}: blocks {i} and {j} overlap by {d} at step {k}"
                );
            }
        }
        assert!(
            poses[800..].iter().all(|p| *p == poses[800]),
            "{name}: still moving at the end"
        );
        if name == "stack-paper" {
            assert_eq!(w.block(1).unwrap().mode, BlockMode::Resting, "top fell");
            assert!(w.block(1).unwrap().position.y < 0.06);
        }
    }
}

/// R14 with the hand (R5, R10): lifting the bottom cube of a two-cube stack carries the top one
/// (it overlaps the rising cube), and when the hand holds still the top rests on the grasped
/// cube (a held block supports, it is never part of a load). Lifting the top cube leaves the
/// bottom one exactly where it was.
#[test]
fn r14_r10_a_lifted_stack_rides_on_the_grasped_block() {
    let fingers = |x: f64| {
        format!(
            "[[[{}, 0.0, 0.0], [{}, -0.03, 0.0]], [[{}, 0.0, 0.0], [{}, -0.03, 0.0]]]",
            -x, -x, x, x
        )
    };
    let text = |grip_y: f64| {
        format!(
            "[effects]\nstacking = \"supported\"\n\
             [[block]]\nname = \"bottom\"\nsize = [0.06, 0.06, 0.06]\nposition = [0.0, 0.03, 0.0]\n\
             [[block]]\nname = \"top\"\nsize = [0.06, 0.06, 0.06]\nposition = [0.0, 0.09, 0.0]\n\
             [hand]\n\
             [[hand.key]]\nt = 0.0\nwrist = [0.0, {y0}, 0.0]\nfingers = {open}\n\
             [[hand.key]]\nt = 0.3\nwrist = [0.0, {y0}, 0.0]\nfingers = {closed}\n\
             [[hand.key]]\nt = 0.6\nwrist = [0.0, {y1}, 0.0]\nfingers = {closed}\n",
            y0 = grip_y + 0.015,
            y1 = grip_y + 0.115,
            open = fingers(0.05),
            closed = fingers(0.0295),
        )
    };
    let (poses, _, w) = trace(&scene(&text(0.03)), 200);
    assert_eq!(w.block(0).unwrap().mode, BlockMode::Grasped);
    assert_eq!(w.block(1).unwrap().mode, BlockMode::Supported);
    assert!(
        (poses[200][0].0.y - 0.13).abs() < 1e-9,
        "{}",
        poses[200][0].0
    );
    assert!(
        (poses[200][1].0.y - 0.19).abs() < 1e-9,
        "{}",
        poses[200][1].0
    );
    assert!(
        poses[100..].iter().all(|p| p[1] == poses[100][1]),
        "the top rests on the held cube"
    );
    let (poses, _, w) = trace(&scene(&text(0.09)), 200);
    assert_eq!(w.block(1).unwrap().mode, BlockMode::Grasped);
    assert!((poses[200][1].0.y - 0.19).abs() < 1e-9);
    assert!(
        poses.iter().all(|p| p[0] == poses[0][0]),
        "the bottom never moves"
    );
}
