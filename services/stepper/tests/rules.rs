//! One test (or a few) per docs/model.md rule, with expectations worked out by hand in the comments.

mod support;

use glam::{DQuat, DVec2, DVec3};

use common::BlockMode;
use stepper::body::VertexSet;
use stepper::floor::{stability, R9Params, Stability};
use stepper::{push_one_point, EventKind, World};
use support::*;

const TIGHT: f64 = 1e-12;

fn close(a: DVec3, b: DVec3, tol: f64) -> bool {
    (a - b).length() <= tol
}

// ---------------------------------------------------------------------------------------------
// R4: the paper's Fig. 5.

/// Fig. 5 with numbers: G = 0, C = (-0.05, 0, 0) on the -x face, the check point ends at
/// B = C + (0.01, 0, 0.02). u = (1, 0, 0), so T = (0.01, 0, 0) and R = (0, 0, 0.02);
/// theta = atan(0.02 / 0.05) = atan(0.4); X = (C - G) x R = (0, 0.001, 0) -> +y.
#[test]
fn r4_fig5_t_r_theta_and_axis() {
    let c = DVec3::new(-0.05, 0.0, 0.0);
    let b = c + DVec3::new(0.01, 0.0, 0.02);
    let p = push_one_point(c, b, DVec3::ZERO, 1e-6, 1e-4).unwrap();
    assert!(close(p.t, DVec3::new(0.01, 0.0, 0.0), TIGHT), "{:?}", p.t);
    assert!(close(p.r, DVec3::new(0.0, 0.0, 0.02), TIGHT), "{:?}", p.r);
    assert!((p.theta - 0.4f64.atan()).abs() < TIGHT);
    assert!(close(p.axis.unwrap(), DVec3::Y, TIGHT));
    // An oblique one: G = 0, C = (-0.03, -0.04, 0) (|CG| = 0.05, u = (0.6, 0.8, 0)),
    // B - C = (0.01, 0, 0): T = 0.006 u = (0.0036, 0.0048, 0), R = (0.0064, -0.0048, 0),
    // |R| = 0.008, theta = atan(0.16), X = (C - G) x R = (0, 0, 0.000448) -> +z.
    let c = DVec3::new(-0.03, -0.04, 0.0);
    let p = push_one_point(c, c + DVec3::new(0.01, 0.0, 0.0), DVec3::ZERO, 1e-6, 1e-4).unwrap();
    assert!(
        close(p.t, DVec3::new(0.0036, 0.0048, 0.0), TIGHT),
        "{:?}",
        p.t
    );
    assert!(
        close(p.r, DVec3::new(0.0064, -0.0048, 0.0), TIGHT),
        "{:?}",
        p.r
    );
    assert!((p.theta - 0.16f64.atan()).abs() < TIGHT);
    assert!(close(p.axis.unwrap(), DVec3::Z, TIGHT));
}

/// R4 below contact_eps: |R| < contact_eps skips the rotation; leaving does nothing.
#[test]
fn r4_small_r_skips_rotation_and_leaving_finger_does_nothing() {
    let c = DVec3::new(-0.05, 0.0, 0.0);
    let p = push_one_point(
        c,
        c + DVec3::new(0.01, 0.0, 0.00005),
        DVec3::ZERO,
        1e-6,
        1e-4,
    )
    .unwrap();
    assert!(p.axis.is_none());
    assert!(push_one_point(c, c + DVec3::new(-0.01, 0.0, 0.02), DVec3::ZERO, 1e-6, 1e-4).is_none());
    assert!(push_one_point(c, c + DVec3::new(0.0, 0.0, 0.02), DVec3::ZERO, 1e-6, 1e-4).is_none());
}

/// R1 + R4 end to end: a fingertip's locus A = (-0.06, 0.05, -0.02) -> B = (-0.04, 0.05, 0.02)
/// enters the cube (G = (0, 0.05, 0)) through the -x face at its centre C = (-0.05, 0.05, 0):
/// the Fig. 5 numbers above. After the step G = (0.01, 0.05, 0) and the block has turned
/// atan(0.4) about +y; the body point that was at C moved by T plus a displacement along R
/// (0.05 sin(theta) along +z). R9 then finds it resting (Gm = g_step, G' below G).
#[test]
fn r4_fig5_end_to_end_through_r1_and_the_contact_point_moves_along_r() {
    let s =
        scene("[[block]]\nname = \"cube\"\nsize = [0.1, 0.1, 0.1]\nposition = [0.0, 0.05, 0.0]\n");
    let mut w = World::new(&s).unwrap();
    w.step(None); // lands on the floor (first impact), rests
    assert_eq!(w.block(0).unwrap().mode, BlockMode::Resting);
    let a = hand(&[&[[-0.06, 0.05, -0.02]]], [0.0; 3]);
    let b = hand(&[&[[-0.04, 0.05, 0.02]]], [0.0; 3]);
    w.set_previous_hand(Some(&a));
    w.step(Some(&b));
    let v = w.block(0).unwrap();
    assert_eq!(v.mode, BlockMode::Pushed);
    assert!(
        close(v.position, DVec3::new(0.01, 0.05, 0.0), 1e-12),
        "{:?}",
        v.position
    );
    let (axis, angle) = v.rotation.to_axis_angle();
    assert!((angle - 0.4f64.atan()).abs() < 1e-12, "{angle}");
    assert!(close(axis, DVec3::Y, 1e-12));
    let c_body = DVec3::new(-0.05, 0.0, 0.0);
    let c_now = v.position + v.rotation * c_body;
    let moved_beyond_t = c_now - (DVec3::new(-0.05, 0.05, 0.0) + DVec3::new(0.01, 0.0, 0.0));
    let theta = 0.4f64.atan();
    assert!(
        (moved_beyond_t.z - 0.05 * theta.sin()).abs() < 1e-12,
        "{moved_beyond_t}"
    );
    assert!(moved_beyond_t.z > 0.0);
    // Perfect friction after a push: v = 0 on the floor.
    assert_eq!(v.v, DVec3::ZERO);
}

// ---------------------------------------------------------------------------------------------
// R9: the three cases, with known pivot and direction. G = origin, floor at y = -0.04
// (gy = 0.04), Gm = (0, -0.001, 0) straight down, so G' is straight below G.
// With C = (0.03, -0.04, 0): |CG| = 0.05, u = (0.6, -0.8, 0), T = 0.0008 u, R = (-0.00048,
// -0.00036, 0), |R| = 0.0006, theta = atan(0.012), axis +z (G moves along R: toward -x, down).

const GY: f64 = 0.04;
const P9: R9Params = R9Params {
    hull_eps: 1e-6,
    angle_eps: 1e-9,
};

fn verdict(contacts: &[DVec3], gm: DVec3) -> Stability {
    // The contact vertices, plus two high vertices that never limit the rotation.
    let mut rel: Vec<DVec3> = contacts.to_vec();
    rel.push(DVec3::new(-0.05, 0.05, 0.0));
    rel.push(DVec3::new(0.05, 0.05, 0.0));
    let mut set = VertexSet::EMPTY;
    for i in 0..contacts.len() {
        set.insert(i);
    }
    let (mut a, mut b) = (Vec::<DVec2>::new(), Vec::<DVec2>::new());
    stability(&rel, GY, &set, gm, P9, &mut a, &mut b)
}

fn expect_tip(s: Stability, pivot: DVec3, axis: DVec3, theta: f64) {
    match s {
        Stability::Tipping {
            pivot: p,
            axis: a,
            theta: t,
        } => {
            assert!(close(p, pivot, TIGHT), "pivot {p} != {pivot}");
            assert!(close(a, axis, TIGHT), "axis {a} != {axis}");
            assert!((t - theta).abs() < TIGHT, "theta {t} != {theta}");
        }
        Stability::Resting => panic!("expected tipping about {pivot}"),
    }
}

const DOWN: DVec3 = DVec3::new(0.0, -0.001, 0.0);

#[test]
fn r9_case1_one_vertex_pivot_and_direction() {
    let c = DVec3::new(0.03, -0.04, 0.0);
    expect_tip(verdict(&[c], DOWN), c, DVec3::Z, 0.012f64.atan());
    // Mirror: C on the -x side tips the other way.
    let c = DVec3::new(-0.03, -0.04, 0.0);
    expect_tip(verdict(&[c], DOWN), c, -DVec3::Z, 0.012f64.atan());
}

#[test]
fn r9_case2_two_vertices_rotate_about_their_line() {
    let v1 = DVec3::new(0.03, -0.04, -0.05);
    let v2 = DVec3::new(0.03, -0.04, 0.05);
    // C = foot of the perpendicular from G onto V1V2 = (0.03, -0.04, 0).
    expect_tip(
        verdict(&[v1, v2], DOWN),
        DVec3::new(0.03, -0.04, 0.0),
        DVec3::Z,
        0.012f64.atan(),
    );
    // Equation 5: a component of Gm along V1V2 is removed (same result).
    expect_tip(
        verdict(&[v1, v2], DVec3::new(0.0, -0.001, 0.0007)),
        DVec3::new(0.03, -0.04, 0.0),
        DVec3::Z,
        0.012f64.atan(),
    );
}

#[test]
fn r9_case2_g_prime_outside_the_strip_uses_the_nearer_vertex() {
    // G' (z = 0) is not between the perpendicular lines z = 0.01 and z = 0.05: C = V1 (nearer
    // to G), case 1. u = V1/|V1| with |V1| = sqrt(0.0026); computed independently below.
    let v1 = DVec3::new(0.03, -0.04, 0.01);
    let v2 = DVec3::new(0.03, -0.04, 0.05);
    let u = v1 / v1.length();
    let r = DOWN - u * DOWN.dot(u);
    let axis = (-v1).cross(r).normalize();
    expect_tip(
        verdict(&[v1, v2], DOWN),
        v1,
        axis,
        (r.length() / v1.length()).atan(),
    );
}

#[test]
fn r9_case3_nearest_hull_edge_then_case2() {
    // Contact square x in [0.03, 0.07], z in [-0.05, 0.05]; G' = (0, 0) is outside; the
    // nearest hull edge is x = 0.03: case 2 with C = (0.03, -0.04, 0).
    let sq = [
        DVec3::new(0.03, -0.04, -0.05),
        DVec3::new(0.07, -0.04, -0.05),
        DVec3::new(0.07, -0.04, 0.05),
        DVec3::new(0.03, -0.04, 0.05),
    ];
    expect_tip(
        verdict(&sq, DOWN),
        DVec3::new(0.03, -0.04, 0.0),
        DVec3::Z,
        0.012f64.atan(),
    );
}

#[test]
fn r9_g_prime_inside_or_on_the_boundary_rests_just_outside_tips() {
    let sq = |x0: f64| {
        [
            DVec3::new(x0, -0.04, -0.05),
            DVec3::new(x0 + 0.04, -0.04, -0.05),
            DVec3::new(x0 + 0.04, -0.04, 0.05),
            DVec3::new(x0, -0.04, 0.05),
        ]
    };
    assert_eq!(verdict(&sq(-0.02), DOWN), Stability::Resting);
    assert_eq!(verdict(&sq(0.0), DOWN), Stability::Resting); // exactly on the boundary
    assert_eq!(verdict(&sq(0.0000009), DOWN), Stability::Resting); // within hull_eps
    assert!(matches!(
        verdict(&sq(0.000002), DOWN),
        Stability::Tipping { .. }
    ));
    // G' follows Gm: slanted motion moves G' by t * Gm (t = gy / -Gm.y = 40).
    let slanted = DVec3::new(0.0004, -0.001, 0.0); // G' = (0.016, 0)
    assert_eq!(verdict(&sq(0.01), slanted), Stability::Resting);
    assert!(matches!(
        verdict(&sq(0.017), slanted),
        Stability::Tipping { .. }
    ));
}

/// R9 limit: the tip scene's cube turns back 30 degrees and lands exactly on a face: four
/// vertices on the floor, its rotation a whole face-down one, and it then never moves again.
#[test]
fn r9_limit_lands_exactly_on_a_face_no_rocking_no_creeping() {
    let s = scene_file("tip");
    let (poses, events, w) = trace(&s, 400);
    let v = w.block(0).unwrap();
    assert_eq!(v.mode, BlockMode::Resting);
    assert_eq!(v.floor_contacts, 4);
    assert!((v.position.y - 0.05).abs() < 1e-12, "{}", v.position.y);
    assert!(v.rotation.angle_between(DQuat::IDENTITY) < 1e-9);
    // The pivot edge stayed put: the lowest corner was at x = -0.05 cos30 + 0.05 sin30... i.e.
    // G ends 0.05 to the +x side of that corner.
    let corner_x = (DVec3::new(-0.05, -0.05, 0.0)).x * (30f64.to_radians().cos())
        + 0.05 * 30f64.to_radians().sin();
    assert!(
        (v.position.x - (corner_x + 0.05)).abs() < 1e-12,
        "{} {}",
        v.position.x,
        corner_x
    );
    // No rocking, no creeping: once resting, the pose never changes again.
    let rest = events
        .iter()
        .find(|e| e.kind == EventKind::Rest && e.block == 0 && e.step > 1)
        .unwrap()
        .step as usize;
    for p in &poses[rest..] {
        assert_eq!(p[0], poses[rest][0]);
    }
    // Nothing gains energy: G never rises while it tips (the floor's R8 lift is only rounding).
    for k in 1..rest {
        assert!(poses[k][0].0.y <= poses[k - 1][0].0.y + 1e-12, "step {k}");
    }
    // The post falls over 75 degrees onto its broad side.
    let post = w.block(1).unwrap();
    assert_eq!(post.mode, BlockMode::Resting);
    assert!(
        (post.position.y - 0.02).abs() < 1e-12,
        "{}",
        post.position.y
    );
}

/// "G' exactly on the hull boundary: stays": the balance scene's cube on an edge and
/// tetrahedron on a vertex never move; tilted by 1e-4 rad more they tip.
#[test]
fn r9_balance_on_the_boundary_stays_and_a_hair_beyond_tips() {
    let s = scene_file("balance");
    let (poses, _, w) = trace(&s, 600);
    #[allow(clippy::needless_range_loop)]
    for i in 0..2 {
        assert_eq!(w.block(i).unwrap().mode, BlockMode::Resting);
        // Step 1 may lift it by rounding (R8, ~1e-17 m); after that it never moves.
        assert!(close(poses[1][i].0, poses[0][i].0, 1e-15));
        assert_eq!(poses[600][i], poses[1][i], "block {i} moved");
    }
    let mut s2 = s.clone();
    // 45 deg + 1e-4 rad about z: G is 0.0707 * 1e-4 = 7 um beyond the edge (> hull_eps).
    let q = DQuat::from_rotation_z(std::f64::consts::FRAC_PI_4 + 1e-4);
    s2.blocks[0].rotation = q.to_array();
    let (_, _, w2) = trace(&s2, 600);
    let v = w2.block(0).unwrap();
    assert_eq!(v.mode, BlockMode::Resting);
    assert!(
        (v.position.y - 0.05).abs() < 1e-9,
        "it fell onto a face: {}",
        v.position.y
    );
}

// ---------------------------------------------------------------------------------------------
// R3: the grasp threshold, just below and just above.

/// An isosceles prism (base on the floor, two faces sloping at phi from the horizontal) has
/// side-face normals (-sin phi, cos phi, 0) and (sin phi, cos phi, 0): 2 phi apart. Two
/// fingertips press into the face centres along the normals. With phi = 60 deg +- 0.01 deg
/// the largest angle is 120.02 or 119.98 deg against grasp_angle = 120: grasped, or pushed.
fn prism_pinch(phi_deg: f64) -> BlockMode {
    let phi = phi_deg.to_radians();
    let (w, d) = (0.05, 0.05);
    let h = w * phi.tan();
    let verts = format!(
        "[[{}, 0, {}], [{}, 0, {}], [{}, 0, {}], [{}, 0, {}], [0, {h}, {}], [0, {h}, {}]]",
        -w, -d, w, -d, w, d, -w, d, -d, d
    );
    let s = scene(&format!(
        "[effects]\ngravity = false\n[[block]]\nname = \"prism\"\nshape = \"hull\"\nvertices = {verts}\nposition = [0.0, {}, 0.0]\n",
        h / 3.0 + 0.2
    ));
    let mut world = World::new(&s).unwrap();
    let g = DVec3::new(0.0, h / 3.0 + 0.2, 0.0);
    let base = g - DVec3::new(0.0, h / 3.0, 0.0);
    let n1 = DVec3::new(-phi.sin(), phi.cos(), 0.0);
    let n2 = DVec3::new(phi.sin(), phi.cos(), 0.0);
    let c1 = base + DVec3::new(-w / 2.0, h / 2.0, 0.0);
    let c2 = base + DVec3::new(w / 2.0, h / 2.0, 0.0);
    let a = hand(
        &[
            &[(c1 + n1 * 0.01).to_array()],
            &[(c2 + n2 * 0.01).to_array()],
        ],
        [0.0; 3],
    );
    let b = hand(
        &[
            &[(c1 - n1 * 0.001).to_array()],
            &[(c2 - n2 * 0.001).to_array()],
        ],
        [0.0; 3],
    );
    world.set_previous_hand(Some(&a));
    world.step(Some(&b));
    world.block(0).unwrap().mode
}

#[test]
fn r3_grasp_threshold_just_above_grasps_just_below_pushes() {
    assert_eq!(prism_pinch(60.01), BlockMode::Grasped);
    assert_eq!(prism_pinch(59.99), BlockMode::Pushed);
}

// ---------------------------------------------------------------------------------------------
// R2: a finger segment sweeping over edges.

/// A horizontal finger (-0.2, 1.06, 0) -> (0.2, 1.06, 0) moves down 2 cm over a floating cube
/// (G = (0, 1, 0), gravity off, no floor). Neither check point touches the cube; the swept
/// quad crosses the two top edges along z at C = (+-0.05, 0.05, 0) (relative to G). Their
/// pseudo-normals (+-1, 1, 0)/sqrt(2) are 90 deg apart (< 120): R6. For each, B - C =
/// (0, -0.01, 0), u = -C/|C|, T = ((B - C) . u) u = (-+0.005, -0.005, 0): mean (0, -0.005, 0).
#[test]
fn r2_swept_segment_crosses_two_edges_and_r6_translates_by_the_mean_t() {
    let s = scene(
        "[effects]\ngravity = false\nfloor = \"none\"\n[[block]]\nname = \"cube\"\nposition = [0.0, 1.0, 0.0]\n",
    );
    let mut w = World::new(&s).unwrap();
    let a = hand(&[&[[-0.2, 1.06, 0.0], [0.2, 1.06, 0.0]]], [0.0; 3]);
    let b = hand(&[&[[-0.2, 1.04, 0.0], [0.2, 1.04, 0.0]]], [0.0; 3]);
    w.set_previous_hand(Some(&a));
    w.step(Some(&b));
    let v = w.block(0).unwrap();
    assert_eq!(v.mode, BlockMode::Pushed);
    assert!(
        close(v.position, DVec3::new(0.0, 0.995, 0.0), 1e-12),
        "{}",
        v.position
    );
    assert_eq!(v.rotation, DQuat::IDENTITY);
    // Knocked in mid-air, it flies on with that displacement (gravity off: forever).
    w.step(None);
    let v2 = w.block(0).unwrap();
    assert!(
        close(v2.position, DVec3::new(0.0, 0.99, 0.0), 1e-12),
        "{}",
        v2.position
    );
}

/// R2's start-of-step case: a finger segment already lying through the block (both check
/// points outside) is a contact at the nearest block edge, so a finger lying across a block
/// cannot pass through it. Here the segment crosses the cube along x at y = 1.04 (1 cm under
/// the top face) and moves down 2 cm: the nearest edges are the two top edges along z, at
/// C = (+-0.05, 0.05, 0) relative to G; B (the finger's point there, now) = (+-0.05, 0.02, 0),
/// so B - C = (0, -0.03, 0) (the 1 cm it was already inside counts, as for R1's point inside),
/// u = (-+1, -1, 0)/sqrt(2), T = (-+0.015, -0.015, 0); pseudo-normals 90 deg apart: R6, the
/// mean T = (0, -0.015, 0).
#[test]
fn r2_segment_already_through_the_block_is_a_contact() {
    let s = scene(
        "[effects]\ngravity = false\nfloor = \"none\"\n[[block]]\nname = \"cube\"\nposition = [0.0, 1.0, 0.0]\n",
    );
    let mut w = World::new(&s).unwrap();
    let a = hand(&[&[[-0.2, 1.04, 0.0], [0.2, 1.04, 0.0]]], [0.0; 3]);
    let b = hand(&[&[[-0.2, 1.02, 0.0], [0.2, 1.02, 0.0]]], [0.0; 3]);
    w.set_previous_hand(Some(&a));
    w.step(Some(&b));
    let v = w.block(0).unwrap();
    assert_eq!(v.mode, BlockMode::Pushed, "{v:?}");
    assert!(
        close(v.position, DVec3::new(0.0, 0.985, 0.0), 1e-12),
        "{}",
        v.position
    );
    assert_eq!(v.rotation, DQuat::IDENTITY);
}

// ---------------------------------------------------------------------------------------------
// R5, R7, R13: grasp, carry, throw, and the closed form of the flight.

#[test]
fn r5_r13_r7_grasp_lift_throw_follows_the_closed_form() {
    let s = scene_file("grasp-throw-fingers");
    let (poses, events, w) = trace(&s, 400);
    let find = |k: EventKind| events.iter().find(|e| e.kind == k).map(|e| e.step as usize);
    let grasp = find(EventKind::Grasp).expect("grasped");
    let release = find(EventKind::Release).expect("released");
    assert!(grasp < release);
    // While grasped the block moved rigidly with the wrist: lifted 0.2 m by t = 0.9 s.
    let at_09 = poses[108][0].0;
    assert!((at_09.y - (0.03 + 0.2)).abs() < 1e-9, "{at_09}");
    // R13: in the release step the grasp ends and the block becomes free with v = the
    // displacement of its last grasped step; it flies from the next step on ("Order of one
    // step" 5), so R7 gives, k steps after the release step, p = p0 + k v + g_step k (k + 1) / 2
    // with p0 = its pose in the release step.
    let p0 = poses[release][0].0;
    assert_eq!(
        p0,
        poses[release - 1][0].0,
        "the release step itself does not move it"
    );
    let v = poses[release - 1][0].0 - poses[release - 2][0].0;
    let g = DVec3::new(0.0, -9.81 / (120.0 * 120.0), 0.0);
    let land = events
        .iter()
        .find(|e| e.kind == EventKind::Impact && e.step as usize > release)
        .unwrap()
        .step as usize;
    assert!(land - release > 20, "a real flight: {}", land - release);
    for k in 1..(land - release) {
        let kf = k as f64;
        let expect = p0 + v * kf + g * (kf * (kf + 1.0) / 2.0);
        let got = poses[release + k][0].0;
        assert!(
            (got - expect).length() <= 1e-9 * expect.length(),
            "k = {k}: {got} vs {expect}"
        );
        assert_eq!(
            poses[release + k][0].1,
            poses[release][0].1,
            "no rotation in flight"
        );
    }
    // It lands and rests, face down, ~0.84 m further on.
    let b = w.block(0).unwrap();
    assert_eq!(b.mode, BlockMode::Resting);
    assert!((b.position.y - 0.03).abs() < 1e-9);
    assert!(b.position.z > 0.6, "{}", b.position.z);
}

/// R5: check points that end inside the grasped block are published on its surface.
#[test]
fn r5_relocated_finger_points_are_on_the_surface() {
    let s = scene_file("grasp-throw-fingers");
    let (_, _, w) = trace(&s, 100); // t = 0.83 s: held, being lifted
    let mut sample = common::WorldSample::default();
    w.write_sample(&mut sample);
    assert_eq!(sample.grasped_block, 0);
    let b = w.block(0).unwrap();
    assert_eq!(sample.finger_count, 3);
    for f in 0..3 {
        let tip = DVec3::from_array(sample.finger_points[f][1]);
        let local = b.rotation.conjugate() * (tip - b.position);
        assert!((local.x.abs() - 0.03).abs() < 1e-12, "finger {f}: {local}");
    }
}

/// R7 closed form for a block given an initial velocity: p_k = p_0 + k v + g_step k(k+1)/2.
#[test]
fn r7_free_flight_closed_form() {
    let s = scene(
        "[[block]]\nname = \"b\"\nposition = [1.0, 50.0, -2.0]\nvelocity = [3.0, 4.0, -1.5]\n",
    );
    let (poses, _, _) = trace(&s, 240);
    let dt = 1.0 / 120.0;
    let v = DVec3::new(3.0, 4.0, -1.5) * dt;
    let g = DVec3::new(0.0, -9.81 * dt * dt, 0.0);
    let p0 = DVec3::new(1.0, 50.0, -2.0);
    for k in [1usize, 2, 10, 100, 240] {
        let kf = k as f64;
        let expect = p0 + v * kf + g * (kf * (kf + 1.0) / 2.0);
        assert!((poses[k][0].0 - expect).length() <= 1e-9 * expect.length());
    }
}

// ---------------------------------------------------------------------------------------------
// R8: impact and no rebound.

#[test]
fn r8_a_falling_block_lands_without_rebound_or_slide() {
    let s =
        scene("[[block]]\nname = \"b\"\nposition = [0.0, 1.0, 0.0]\nvelocity = [0.3, 0.0, 0.0]\n");
    let (poses, events, w) = trace(&s, 200);
    let land = events
        .iter()
        .find(|e| e.kind == EventKind::Impact)
        .unwrap()
        .step as usize;
    assert!(
        (poses[land][0].0.y - 0.05).abs() < 1e-12,
        "landed exactly on the floor"
    );
    for p in &poses[land..] {
        assert_eq!(p[0], poses[land][0], "no rebound, no slide");
    }
    assert_eq!(w.block(0).unwrap().mode, BlockMode::Resting);
}

// ---------------------------------------------------------------------------------------------
// R10, R11, R12.

#[test]
fn r10_transitive_carry_translates_each_block_once_by_the_same_translation() {
    let s = scene_file("carry");
    let (poses, events, w) = trace(&s, 200);
    #[allow(clippy::needless_range_loop)]
    for i in 0..3 {
        let d = poses[200][i].0 - poses[0][i].0;
        assert!(
            close(d, DVec3::new(0.04, 0.0, 0.0), 1e-12),
            "block {i}: {d}"
        );
        assert_eq!(
            poses[200][i].1,
            DQuat::IDENTITY,
            "carried blocks do not rotate"
        );
        assert_eq!(w.block(i).unwrap().mode, BlockMode::Resting);
    }
    assert!(events
        .iter()
        .any(|e| e.kind == EventKind::Carry && e.block == 2));
}

/// R10 while grasping: lifting a block lifts the block standing on it (the grasped block
/// moves into it); lifting the top block off a stack leaves the bottom one (touching is not
/// overlapping).
#[test]
fn r10_lifting_a_block_carries_what_stands_on_it_but_not_what_it_stands_on() {
    let fingers = |x: f64| {
        format!(
            "[[[{}, 0.0, 0.0], [{}, -0.06, 0.0]], [[{}, 0.0, 0.0], [{}, -0.06, 0.0]]]",
            -x, -x, x, x
        )
    };
    let text = |grip_y: f64| {
        format!(
            r#"
[[block]]
name = "bottom"
size = [0.06, 0.06, 0.06]
position = [0.0, 0.03, 0.0]
[[block]]
name = "top"
size = [0.06, 0.06, 0.06]
position = [0.0, 0.09, 0.0]
[hand]
[[hand.key]]
t = 0.0
wrist = [0.0, {y0}, 0.0]
fingers = {open}
[[hand.key]]
t = 0.3
wrist = [0.0, {y0}, 0.0]
fingers = {closed}
[[hand.key]]
t = 0.6
wrist = [0.0, {y1}, 0.0]
fingers = {closed}
"#,
            y0 = grip_y + 0.06,
            y1 = grip_y + 0.16,
            open = fingers(0.05),
            closed = fingers(0.0295),
        )
    };
    // Grasp the bottom block (finger tips at its G's height): both rise by 0.1.
    let (poses, _, w) = trace(&scene(&text(0.03)), 100);
    assert_eq!(w.block(0).unwrap().mode, BlockMode::Grasped);
    assert!(
        (poses[100][0].0.y - 0.13).abs() < 1e-9,
        "{}",
        poses[100][0].0
    );
    assert!(
        (poses[100][1].0.y - 0.19).abs() < 1e-9,
        "{}",
        poses[100][1].0
    );
    // Grasp the top block: only it rises; the bottom one stays on the floor.
    let (poses, _, w) = trace(&scene(&text(0.09)), 100);
    assert_eq!(w.block(1).unwrap().mode, BlockMode::Grasped);
    assert!((poses[100][1].0.y - 0.19).abs() < 1e-9);
    assert_eq!(poses[100][0], poses[0][0]);
}

#[test]
fn r11_a_block_on_another_stays_even_when_unstable() {
    let s = scene_file("stack-paper");
    let (_, _, w) = trace(&s, 300);
    let top = w.block(1).unwrap();
    assert_eq!(top.mode, BlockMode::Supported);
    // G 1.5 cm beyond base's edge, yet it stays where it first touched: on base's top face.
    assert!(
        close(top.position, DVec3::new(0.065, 0.15, 0.0), 1e-9),
        "{}",
        top.position
    );
    for (i, y) in [(3, 0.14), (4, 0.21), (5, 0.255)] {
        let b = w.block(i).unwrap();
        assert_eq!(b.mode, BlockMode::Supported);
        assert!(
            (b.position.y - y).abs() < 1e-9,
            "block {i}: {}",
            b.position.y
        );
    }
}

/// R11 ends when the supporter moves away: a fingertip pushes the base out from under the top
/// block (no overlap, so no carry); the top block stays while it still touches, then falls.
#[test]
fn r11_support_ends_when_the_block_below_moves_away() {
    let s = scene(
        r#"
[[block]]
name = "base"
position = [0.0, 0.05, 0.0]
[[block]]
name = "top"
size = [0.06, 0.06, 0.06]
position = [0.0, 0.13, 0.0]
[hand]
[[hand.key]]
t = 0.0
wrist = [-0.1, 0.05, 0.0]
fingers = [[[0.0, 0.0, 0.0]]]
[[hand.key]]
t = 1.0
wrist = [0.15, 0.05, 0.0]
fingers = [[[0.0, 0.0, 0.0]]]
"#,
    );
    let (_, _, w) = trace(&s, 300);
    let top = w.block(1).unwrap();
    assert_eq!(top.mode, BlockMode::Resting);
    assert!(
        (top.position.y - 0.03).abs() < 1e-9,
        "fell to the floor: {}",
        top.position
    );
    assert!(top.position.x.abs() < 1e-12, "fell straight down");
}

#[test]
fn r12_a_block_at_200_m_per_s_does_not_pass_through_a_1_cm_plate() {
    let s = scene(
        r#"
[[block]]
name = "bullet"
size = [0.05, 0.05, 0.05]
position = [0.0, 0.5, 0.0]
velocity = [200.0, 0.0, 0.0]
[[block]]
name = "plate"
size = [0.01, 1.0, 1.0]
position = [1.0, 0.5, 0.0]
"#,
    );
    let (poses, _, w) = trace(&s, 20);
    // 200 m/s is 1.67 m a step: without R12 it would be past the plate in one step.
    let x = poses[20][0].0.x;
    assert!(x + 0.025 <= 0.995 + 1e-9, "{x}");
    assert!(x + 0.025 >= 0.995 - 1e-6, "stopped at first contact: {x}");
    assert_eq!(w.block(0).unwrap().mode, BlockMode::Supported);
    // Falling at 200 m/s onto a 1 cm plate lying on the floor.
    let s = scene(
        r#"
[[block]]
name = "bullet"
size = [0.05, 0.05, 0.05]
position = [0.0, 5.0, 0.0]
velocity = [0.0, -200.0, 0.0]
[[block]]
name = "plate"
size = [1.0, 0.01, 1.0]
position = [0.0, 0.005, 0.0]
"#,
    );
    let (poses, _, _) = trace(&s, 20);
    let y = poses[20][0].0.y;
    assert!((y - 0.035).abs() < 1e-6, "{y}");
}

// ---------------------------------------------------------------------------------------------
// Robustness.

#[test]
fn a_hand_with_nan_is_refused_and_the_hand_holds_its_grasp() {
    let s = scene_file("grasp-throw-fingers");
    let mut hand = stepper::BareFingersHand::from_scene(&s).unwrap();
    let mut w = World::new(&s).unwrap();
    use stepper::HandSource;
    w.set_previous_hand(hand.hand_at(0, 0.0).as_ref());
    for n in 1..=80u64 {
        let h = hand.hand_at(n, n as f64 / 120.0);
        w.step(h.as_ref());
    }
    assert_eq!(w.block(0).unwrap().mode, BlockMode::Grasped);
    let mut bad = hand.hand_at(81, 81.0 / 120.0).unwrap();
    bad.finger_points[0][1][0] = f64::NAN;
    w.step(Some(&bad));
    let v = w.block(0).unwrap();
    assert!(v.position.is_finite() && v.rotation.is_finite());
    // Refused, counted, and the hand held its last good pose: the grasp goes on.
    assert_eq!(w.rejected_hand_samples(), 1);
    assert!(w.events().iter().all(|e| e.kind != EventKind::Release));
    assert_eq!(v.mode, BlockMode::Grasped);
}

#[test]
fn far_from_the_origin_the_tip_scene_behaves_the_same() {
    let s = scene_file("tip");
    let mut far = s.clone();
    let off = DVec3::new(1000.0, 0.0, -1000.0);
    for b in &mut far.blocks {
        b.position = (DVec3::from_array(b.position) + off).to_array();
    }
    let (p, _, _) = trace(&s, 200);
    let (q, _, _) = trace(&far, 200);
    for i in 0..2 {
        assert!(
            close(q[200][i].0 - off, p[200][i].0, 1e-9),
            "{} vs {}",
            q[200][i].0 - off,
            p[200][i].0
        );
        assert!(q[200][i].1.angle_between(p[200][i].1) < 1e-9);
    }
}

/// R9 consequence: a block thrown so that it lands on an edge tips over in the direction of
/// flight and settles face down; dropped straight onto the edge (G' on the edge) it stays.
#[test]
fn r9_thrown_onto_an_edge_tips_in_the_direction_of_flight() {
    for (vx, expect_x_sign) in [(1.0, 1.0), (-1.0, -1.0), (0.0, 0.0)] {
        let s = scene(&format!(
            "[[block]]\nname = \"c\"\nposition = [0.0, 0.5, 0.0]\nrotation = [0.0, 0.0, 0.3826834323650898, 0.9238795325112867]\nvelocity = [{vx}, 0.0, 0.0]\n"
        ));
        let (_, events, w) = trace(&s, 300);
        let b = w.block(0).unwrap();
        assert_eq!(b.mode, BlockMode::Resting);
        let land = events
            .iter()
            .find(|e| e.kind == EventKind::Impact)
            .unwrap()
            .step as f64;
        // Where it landed on its edge: x = vx * land * dt; it then tips beyond that edge.
        let edge_x = vx * land / 120.0;
        if expect_x_sign == 0.0 {
            assert!(
                (b.position.y - 0.05 * 2f64.sqrt()).abs() < 1e-12,
                "stays on its edge"
            );
        } else {
            assert!((b.position.y - 0.05).abs() < 1e-12, "face down");
            assert!(
                (b.position.x - edge_x) * expect_x_sign > 0.0,
                "{} vs edge {edge_x}",
                b.position.x
            );
        }
    }
}

/// R13 [extension]: throw_window = 3 throws with the mean displacement of the last three
/// grasped steps.
#[test]
fn r13_throw_window_averages_the_last_grasped_steps() {
    let mut s = scene_file("grasp-throw-fingers");
    s.world.throw_window = 3;
    // The wrist speeds up while the fingers open, so the last grasped steps differ.
    s.hand.as_mut().unwrap().keys[5].wrist = [0.0, 0.56, 0.42];
    let (poses, events, _) = trace(&s, 200);
    let release = events
        .iter()
        .find(|e| e.kind == EventKind::Release)
        .unwrap()
        .step as usize;
    let p = |k: usize| poses[k][0].0;
    let mean = (p(release - 1) - p(release - 4)) / 3.0;
    let g = DVec3::new(0.0, -9.81 / (120.0 * 120.0), 0.0);
    let last = p(release - 1) - p(release - 2);
    assert!((last - mean).length() > 1e-4, "the window matters here");
    let flew = p(release + 1) - p(release);
    assert!(close(flew, mean + g, 1e-12), "{flew} vs {}", mean + g);
}

/// Hard cases (notes/physics.md): a 20-cube tower stands exactly still (R11 holds every cube
/// above the first, which rests), and a cube falling edge-first onto another cube's edge stops
/// at first contact (R12) without overlapping it.
#[test]
fn r11_r12_tall_stack_stays_exactly_still_and_edge_on_edge_stops_at_contact() {
    let mut text = String::new();
    for i in 0..20 {
        text.push_str(&format!(
            "[[block]]\nname = \"c{i}\"\nposition = [0.0, {}, 0.0]\n",
            0.05 + 0.1 * i as f64
        ));
    }
    let s = scene(&text);
    let (poses, _, w) = trace(&s, 1000);
    assert_eq!(w.block(0).unwrap().mode, BlockMode::Resting);
    for i in 1..20 {
        assert_eq!(w.block(i).unwrap().mode, BlockMode::Supported, "cube {i}");
    }
    assert!(poses[1..].iter().all(|p| *p == poses[1]), "nothing moves");

    // Edge on edge: the lower cube turned 45 deg about z, the upper 45 deg about x.
    let s = scene(
        r#"
[[block]]
name = "low"
position = [0.0, 0.07071067811865475, 0.0]
rotation = [0.0, 0.0, 0.3826834323650898, 0.9238795325112867]
[[block]]
name = "high"
position = [0.0, 0.6, 0.0]
rotation = [0.3826834323650898, 0.0, 0.0, 0.9238795325112867]
"#,
    );
    let (_, _, w) = trace(&s, 200);
    let high = w.block(1).unwrap();
    assert_eq!(high.mode, BlockMode::Supported);
    // Top edge of "low" at y = 0.1414; bottom edge of "high" 0.0707 below its G.
    let expect = 2.0 * 0.07071067811865475 + 0.07071067811865475;
    assert!(
        (high.position.y - expect).abs() < 1e-6,
        "{} vs {expect}",
        high.position.y
    );
    assert!(high.position.y >= expect - 1e-9, "no overlap");
}
