//! Window mode: with a display (e.g. under Xvfb) it opens a window, draws and presents frames
//! and can still read them back; without one it fails with an error that says what is missing
//! and how to render anyway, never a panic. CI has no display, so it checks the second; run
//! `xvfb-run cargo test -p renderer --release --test window` to check the first.

use std::path::PathBuf;

use common::config::scene::{BlockSpec, Effects, Scene, ShapeSpec, WorldSettings};
use common::{BlockMode, HandSample, WorldSample};
use renderer::window::WindowStatus;
use renderer::{OutputMode, RenderSettings, Renderer};

#[test]
fn window_mode_draws_with_a_display_and_explains_itself_without_one() {
    let scene = Scene {
        file: PathBuf::from("test.toml"),
        world: WorldSettings::default(),
        effects: Effects::default(),
        blocks: vec![BlockSpec {
            name: "red".into(),
            shape: ShapeSpec::Box { size: [0.06; 3] },
            position: [0.0, 0.03, 0.0],
            rotation: [0.0, 0.0, 0.0, 1.0],
            velocity: [0.0; 3],
        }],
        hand: None,
        left_hand: None,
    };
    let settings = RenderSettings {
        width: 160,
        height: 120,
        output: OutputMode::Anaglyph,
        ..RenderSettings::default()
    };
    let has_display = std::env::var("DISPLAY").is_ok_and(|d| !d.is_empty());
    match Renderer::new_window(&settings, &scene) {
        Ok((mut r, mut window)) => {
            assert!(has_display);
            let mut w = WorldSample::with_blocks(1);
            w.blocks[0].pose.position = [0.0, 0.03, 0.0];
            w.blocks[0].pose.rotation = [0.0, 0.0, 0.0, 1.0];
            w.blocks[0].mode = BlockMode::Grasped as u32;
            for _ in 0..20 {
                assert_eq!(window.pump(&mut r), WindowStatus::Open);
                r.render(w.view(), &HandSample::default()).unwrap();
            }
            let img = r.read_back().unwrap();
            assert_eq!((img.width, img.height), (160, 120));
            println!("window mode: 20 frames presented on {}", r.adapter_name());
        }
        Err(e) => {
            let e = e.to_string();
            println!("window mode: {e}");
            assert!(!has_display, "a display is set but: {e}");
            assert!(e.contains("DISPLAY"), "{e}");
            assert!(e.contains("mode = \"headless\""), "{e}");
        }
    }
}
