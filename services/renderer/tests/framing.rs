//! The camera frames the scene: with no `eye` or `target` in the session, the default session's
//! blocks, the hand's reach and the block the hand throws, where it lands, are all in view, and
//! the cube is drawn larger than the fixed default camera drew it.

use std::path::PathBuf;

use common::config::Scene;
use glam::DVec3;
use renderer::camera::{frame_scene, stereo};
use renderer::CameraSettings;

const W: u32 = 640;
const H: u32 = 480;

fn scene(name: &str) -> Scene {
    let file = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../config/scenes")
        .join(name);
    Scene::load(&file).unwrap()
}

/// The cube's height on screen (px) and whether every point is inside both eyes' images.
fn view(camera: &CameraSettings, points: &[DVec3]) -> (f64, bool) {
    let eyes = stereo(camera, W, H);
    let inside = eyes.iter().all(|e| {
        points.iter().all(|p| {
            e.project_px(*p, W, H)
                .is_some_and(|(x, y)| (0.0..W as f64).contains(&x) && (0.0..H as f64).contains(&y))
        })
    });
    let top = eyes[0]
        .project_px(DVec3::new(0.0, 0.06, 0.0), W, H)
        .unwrap();
    let bottom = eyes[0].project_px(DVec3::new(0.0, 0.0, 0.0), W, H).unwrap();
    ((bottom.1 - top.1).abs(), inside)
}

#[test]
fn the_default_scene_its_hand_and_the_thrown_block_stay_in_frame() {
    let s = scene("grasp-throw.toml");
    let default = CameraSettings::default();
    let (eye, target) = frame_scene(&s, &default, W, H);
    let framed = CameraSettings {
        eye,
        target,
        ..default
    };
    // The cube at the start, the hand's highest point, the release, and the landing (the
    // block rests 0.855 m away along -z: `simulate config/scenes/grasp-throw.toml`).
    let points = [
        DVec3::new(0.0, 0.03, 0.0),
        DVec3::new(0.02, 0.6, -0.4),
        DVec3::new(0.02, 0.475, -0.295),
        DVec3::new(0.0, 0.03, -0.855),
    ];
    let (cube_px, inside) = view(&framed, &points);
    println!("framed: cube {cube_px:.1} px, eye {eye:?}, target {target:?}");
    assert!(inside, "not all in view from {eye:?} towards {target:?}");
    let (default_px, default_inside) = view(&default, &points);
    assert!(
        !default_inside,
        "the fixed camera lost the throw, as the issue said"
    );
    assert!(
        cube_px > default_px * 0.9 && cube_px > 25.0,
        "the cube is {cube_px:.1} px high (the fixed camera: {default_px:.1} px)"
    );
}

#[test]
fn a_scene_without_a_hand_is_framed_on_its_blocks() {
    let s = scene("stack-paper.toml");
    let (eye, target) = frame_scene(&s, &CameraSettings::default(), W, H);
    let framed = CameraSettings {
        eye,
        target,
        ..CameraSettings::default()
    };
    let eyes = stereo(&framed, W, H);
    for b in &s.blocks {
        let p = DVec3::from_array(b.position);
        let (x, y) = eyes[0].project_px(p, W, H).unwrap();
        assert!(
            (0.0..W as f64).contains(&x) && (0.0..H as f64).contains(&y),
            "{}",
            b.name
        );
    }
}
