//! The preview follows the action (issue 43): a synthetic session (no GPU needed: the plan is
//! what the renderer draws) where the hand idles for 3 s, closes in on a cube, grasps it,
//! lifts it and throws it, and idles again for 4.5 s; a second cube stands far off, untouched.
//! The preview keeps the grasp, the throw and the landing, with little before and after, the
//! throw over several frames; the hand and the cube are inside every frame, the cube larger
//! than a whole-scene view draws it, and the untouched cube is not what the view is fitted to.

use std::path::PathBuf;

use common::config::scene::{BlockSpec, Effects, Scene, ShapeSpec, WorldSettings};
use common::{BlockMode, BlockState, HandSample, Pose, WorldSample};
use glam::DVec3;
use renderer::camera::stereo;
use renderer::preview::{PreviewPlan, PreviewWriter, LEAD_S, MAX_FRAMES, MAX_LEAD_S, TAIL_S};
use renderer::CameraSettings;

const W: u32 = 640;
const H: u32 = 480;
const STEP_HZ: f64 = 120.0;
const SIDE: f64 = 0.06;
/// When the hand grasps, releases, and the thrown cube lands (seconds).
const GRASP: f64 = 4.0;
const RELEASE: f64 = 5.0;
const END: f64 = 9.5;

fn cube(name: &str, at: [f64; 3]) -> BlockSpec {
    BlockSpec {
        name: name.into(),
        shape: ShapeSpec::Box {
            size: [SIDE, SIDE, SIDE],
        },
        position: at,
        rotation: [0.0, 0.0, 0.0, 1.0],
        velocity: [0.0; 3],
    }
}

fn scene() -> Scene {
    Scene {
        file: PathBuf::from("preview-test.toml"),
        world: WorldSettings::default(),
        effects: Effects::default(),
        blocks: vec![
            cube("red", [0.0, SIDE / 2.0, 0.0]),
            cube("blue", [0.9, SIDE / 2.0, -0.7]),
        ],
        hand: None,
        left_hand: None,
    }
}

fn lerp(a: DVec3, b: DVec3, s: f64) -> DVec3 {
    a + (b - a) * s.clamp(0.0, 1.0)
}

/// Where the wrist is at `t`: idle, closing in above the cube, lifting it, then still.
fn wrist(t: f64) -> DVec3 {
    let idle = DVec3::new(0.35, 0.25, 0.25);
    let above = DVec3::new(0.0, 0.09, 0.0);
    let lifted = DVec3::new(0.0, 0.4, -0.2);
    if t < 3.0 {
        idle
    } else if t < GRASP {
        lerp(idle, above, t - 3.0)
    } else {
        lerp(above, lifted, (t - GRASP) / (RELEASE - GRASP))
    }
}

/// The hand at `t`: one finger of three points and a palm of four vertices around the wrist.
fn hand(t: f64) -> HandSample {
    let c = wrist(t);
    let mut h = HandSample {
        finger_count: 1,
        palm_vertex_count: 4,
        tracked: 1,
        ..Default::default()
    };
    h.finger_point_count[0] = 3;
    for (k, p) in h.finger_points[0][..3].iter_mut().enumerate() {
        *p = (c + DVec3::new(0.0, -0.02 * k as f64, -0.04 - 0.03 * k as f64)).to_array();
    }
    for (k, p) in h.palm_vertices[..4].iter_mut().enumerate() {
        let (x, z) = ([-0.04, 0.04][k % 2], [0.0, -0.05][k / 2]);
        *p = (c + DVec3::new(x, 0.0, z)).to_array();
    }
    h
}

/// The thrown cube's flight after the release: the hand's last velocity, then gravity, until
/// it lands (its time and where).
fn flight(t: f64) -> (DVec3, bool) {
    let start = wrist(RELEASE) - DVec3::Y * 0.05;
    let v = (wrist(RELEASE) - wrist(GRASP)) / (RELEASE - GRASP) + DVec3::new(0.0, 0.6, -0.8);
    let s = t - RELEASE;
    let p = start + v * s - DVec3::Y * (0.5 * 9.81 * s * s);
    if p.y <= SIDE / 2.0 {
        (DVec3::new(p.x, SIDE / 2.0, p.z), true)
    } else {
        (p, false)
    }
}

fn landing() -> f64 {
    (0..)
        .map(|k| RELEASE + k as f64 / STEP_HZ)
        .find(|&t| flight(t).1)
        .unwrap_or(END)
}

/// The world at step `step`: the red cube at rest, in the hand, flying or landed; blue still.
fn world(step: u64, land: (f64, DVec3)) -> WorldSample {
    let t = step as f64 / STEP_HZ;
    let mut w = WorldSample::with_blocks(2);
    w.header.step = step;
    let (red, mode) = if t < GRASP {
        (DVec3::new(0.0, SIDE / 2.0, 0.0), BlockMode::Resting)
    } else if t < RELEASE {
        w.header.grasped_block = 0;
        (wrist(t) - DVec3::Y * 0.05, BlockMode::Grasped)
    } else if t < land.0 {
        (flight(t).0, BlockMode::Free)
    } else {
        (land.1, BlockMode::Resting)
    };
    let pose = |p: DVec3| Pose {
        position: p.to_array(),
        rotation: [0.0, 0.0, 0.0, 1.0],
    };
    w.blocks[0] = BlockState {
        pose: pose(red),
        mode: mode as u32,
        held_by: 0,
    };
    w.blocks[1] = BlockState {
        pose: pose(DVec3::new(0.9, SIDE / 2.0, -0.7)),
        mode: BlockMode::Resting as u32,
        held_by: 0,
    };
    if w.header.grasped_block < 0 {
        w.header.grasped_block = -1;
    }
    w
}

/// The session, drawn at 60 frames a second (every other step), into a preview's plan.
fn plan_of_session() -> (PreviewPlan, f64) {
    let dir = std::env::temp_dir().join(format!("hb-preview-test-{}", std::process::id()));
    let mut p = PreviewWriter::start(dir.join("p.png"), &scene()).unwrap();
    let land_t = landing();
    let land = (land_t, flight(land_t).0);
    let mut step = 0;
    while (step as f64) / STEP_HZ <= END {
        let t = step as f64 / STEP_HZ;
        p.after_frame(world(step, land).view(), &hand(t), None);
        step += 2;
    }
    let plan = p.plan(W, H, &CameraSettings::default()).unwrap();
    p.finish(None);
    let _ = std::fs::remove_dir_all(dir);
    (plan, land_t)
}

fn inside(plan: &PreviewPlan, camera: &CameraSettings, p: DVec3) -> bool {
    let [eye, _] = stereo(camera, W, H);
    eye.project_px(p, W, H)
        .is_some_and(|(x, y)| plan.crop.contains(x, y))
}

/// The cube's height in the picture, pixels, seen by `camera`, at `p`.
fn cube_px(camera: &CameraSettings, p: DVec3) -> f64 {
    let [eye, _] = stereo(camera, W, H);
    let top = eye.project_px(p + DVec3::Y * SIDE / 2.0, W, H).unwrap();
    let bottom = eye.project_px(p - DVec3::Y * SIDE / 2.0, W, H).unwrap();
    (bottom.1 - top.1).abs()
}

#[test]
fn the_preview_is_cut_to_the_action_and_holds_the_hand_in_every_frame() {
    let (plan, land_t) = plan_of_session();
    let f = &plan.frames;
    let loop_s: f64 = f.iter().map(|x| f64::from(x.delay_ms) / 1000.0).sum();
    eprintln!(
        "{} frames, {:.2}-{:.2} s of {:.2}-{:.2} s, action {:?}, loop {loop_s:.2} s, landing {land_t:.2} s",
        f.len(),
        f[0].time_s,
        f[f.len() - 1].time_s,
        plan.session_s.0,
        plan.session_s.1,
        plan.action_s
    );
    // In time: from a little before the hand closes in to a little after the landing.
    let (first, last) = plan.action_s.expect("the grasp and the throw are action");
    assert!((first - GRASP).abs() < 0.06, "{first}");
    assert!((last - land_t).abs() < 0.06, "{last} vs {land_t}");
    assert!(f.len() <= MAX_FRAMES, "{}", f.len());
    assert!(
        f[0].time_s >= GRASP - MAX_LEAD_S - 0.06 && f[0].time_s <= GRASP - LEAD_S + 0.06,
        "starts at {}",
        f[0].time_s
    );
    assert!(
        f[f.len() - 1].time_s <= land_t + TAIL_S + 0.06 && f[f.len() - 1].time_s >= land_t,
        "ends at {}",
        f[f.len() - 1].time_s
    );
    // No long idle loop: the 9.5 s session plays in about the time its action took.
    let action = land_t + TAIL_S - (GRASP - MAX_LEAD_S);
    assert!(
        loop_s <= action + 0.1 && loop_s >= 1.5,
        "loop {loop_s:.2} s"
    );
    // The throw over several frames, at the kept worlds' pace.
    let flying = f
        .iter()
        .filter(|x| x.time_s > RELEASE && x.time_s < land_t)
        .count();
    assert!(flying >= 4, "the throw shows in {flying} frames");
    assert!(f
        .windows(2)
        .filter(|w| w[0].time_s >= GRASP - 0.3 && w[1].time_s <= land_t + 0.3)
        .all(|w| w[1].time_s - w[0].time_s < 0.06));
    // In space: the hand and the cube it moves are inside every frame.
    let land = flight(land_t).0;
    let mut sizes = Vec::new();
    for x in f {
        let step = (x.time_s * STEP_HZ).round() as u64;
        let w = world(step, (land_t, land));
        let h = hand(x.time_s);
        let points = h.finger_points[0][..3]
            .iter()
            .chain(&h.palm_vertices[..4])
            .map(|p| DVec3::from_array(*p));
        for p in points {
            assert!(
                inside(&plan, &x.camera, p),
                "the hand's {p} is out of the frame at {:.2} s",
                x.time_s
            );
        }
        let red = DVec3::from_array(w.blocks[0].pose.position);
        assert!(
            inside(&plan, &x.camera, red),
            "the cube is out of the frame at {:.2} s",
            x.time_s
        );
        sizes.push(cube_px(&x.camera, red));
    }
    // Tighter than a view of the whole scene: the cube is larger, and the untouched cube is
    // outside some frames.
    sizes.sort_by(f64::total_cmp);
    let whole = renderer::camera::frame_spheres(
        &[
            (DVec3::new(0.0, 0.03, 0.0), 0.05),
            (DVec3::new(0.9, 0.03, -0.7), 0.05),
            (land, 0.05),
            (wrist(0.0), 0.05),
            (wrist(RELEASE), 0.05),
        ],
        &CameraSettings::default(),
        W,
        W * 9 / 16,
    )
    .unwrap();
    let whole_px = cube_px(&whole, DVec3::new(0.0, 0.03, 0.0));
    eprintln!(
        "the cube: {:.0}-{:.0} px high, median {:.0} (whole scene in view: {whole_px:.0} px)",
        sizes[0],
        sizes[sizes.len() - 1],
        sizes[sizes.len() / 2]
    );
    assert!(sizes[sizes.len() / 2] > 1.5 * whole_px, "{sizes:?}");
    assert!(sizes[0] > 20.0, "{sizes:?}");
    let blue = DVec3::new(0.9, SIDE / 2.0, -0.7);
    assert!(f.iter().any(|x| !inside(&plan, &x.camera, blue)));
    // 16:9, the eye's full width.
    assert_eq!(plan.crop.width(), f64::from(W));
    assert!((plan.crop.width() / plan.crop.height() - 16.0 / 9.0).abs() < 1e-9);
}

/// A session where nothing moves is shown whole (at most MAX_FRAMES frames of it).
#[test]
fn a_session_without_action_is_shown_whole() {
    let dir = std::env::temp_dir().join(format!("hb-preview-idle-{}", std::process::id()));
    let mut p = PreviewWriter::start(dir.join("p.png"), &scene()).unwrap();
    let land = (f64::INFINITY, DVec3::ZERO);
    for step in (0..(12.0 * STEP_HZ) as u64).step_by(2) {
        let mut w = world(0, land);
        w.header.step = step;
        p.after_frame(w.view(), &hand(0.0), None);
    }
    let plan = p.plan(W, H, &CameraSettings::default()).unwrap();
    p.finish(None);
    let _ = std::fs::remove_dir_all(dir);
    assert_eq!(plan.action_s, None);
    assert!(plan.frames.len() <= MAX_FRAMES && plan.frames.len() >= 40);
    assert_eq!(plan.frames[0].time_s, 0.0);
    assert!(plan.frames[plan.frames.len() - 1].time_s > 11.5);
}
