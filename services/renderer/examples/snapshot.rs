//! Renders a demonstration world (blocks in several modes, a hand grasping one) and writes it
//! as PNG, to show what the renderer draws.
//!
//! `cargo run -p renderer --release --example snapshot -- OUT.png [side-by-side|anaglyph|separate] [WIDTH HEIGHT] [--window SECONDS]`
//!
//! With `--window SECONDS` it also shows the frame in a window for that long (needs a display).

use std::path::PathBuf;

use common::config::scene::{BlockSpec, Effects, Scene, ShapeSpec, WorldSettings};
use common::{BlockMode, BlockState, HandSample, Pose, WorldSample};
use renderer::image::Image;
use renderer::output::write_frame;
use renderer::{OutputMode, RenderSettings, Renderer};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let out = PathBuf::from(args.first().map(String::as_str).unwrap_or("snapshot.png"));
    let output = args
        .get(1)
        .map(|s| OutputMode::from_name(s).ok_or(format!("unknown output mode {s}")))
        .transpose()?
        .unwrap_or_default();
    let width = args.get(2).map(|s| s.parse()).transpose()?.unwrap_or(320);
    let height = args.get(3).map(|s| s.parse()).transpose()?.unwrap_or(240);
    let settings = RenderSettings {
        width,
        height,
        output,
        ..RenderSettings::default()
    };
    let (scene, world, hand) = demo();
    let window_s: Option<f64> = args
        .iter()
        .position(|a| a == "--window")
        .and_then(|i| args.get(i + 1))
        .map(|s| s.parse())
        .transpose()?;
    let mut r = match window_s {
        Some(seconds) => {
            let (mut r, mut window) = Renderer::new_window(&settings, &scene)?;
            let until = std::time::Instant::now() + std::time::Duration::from_secs_f64(seconds);
            while std::time::Instant::now() < until
                && window.pump(&mut r) == renderer::window::WindowStatus::Open
            {
                r.render(world.view(), &hand)?;
                std::thread::sleep(std::time::Duration::from_millis(30));
            }
            r
        }
        None => Renderer::new_headless(&settings, &scene)?,
    };
    r.render(world.view(), &hand)?;
    let img = r.read_back()?;
    let dir = out.parent().map(PathBuf::from).unwrap_or_default();
    let paths = write_frame(&dir, 0, output, &img, &mut Image::default())?;
    // write_frame names frames; rename to what was asked for.
    match output {
        OutputMode::Separate => {
            let stem = out.with_extension("");
            for (p, eye) in paths.iter().zip(["left", "right"]) {
                std::fs::rename(p, format!("{}_{eye}.png", stem.display()))?;
            }
        }
        _ => std::fs::rename(&paths[0], &out)?,
    }
    println!("{} on {}", out.display(), r.adapter_name());
    Ok(())
}

fn block(name: &str, shape: ShapeSpec) -> BlockSpec {
    BlockSpec {
        name: name.into(),
        shape,
        position: [0.0; 3],
        rotation: [0.0, 0.0, 0.0, 1.0],
        velocity: [0.0; 3],
    }
}

/// Six blocks, each in its own colour (named for it) and one per common mode (shown by its
/// outline), and an open hand's fingers around the grasped one.
fn demo() -> (Scene, WorldSample, HandSample) {
    let s = 0.06;
    let scene = Scene {
        file: PathBuf::from("demo"),
        world: WorldSettings::default(),
        effects: Effects::default(),
        blocks: vec![
            block("red", ShapeSpec::Box { size: [s, s, s] }),
            block(
                "blue",
                ShapeSpec::Wedge {
                    size: [0.1, 0.06, 0.06],
                },
            ),
            block(
                "purple",
                ShapeSpec::Box {
                    size: [0.08, 0.04, 0.06],
                },
            ),
            block("orange", ShapeSpec::Box { size: [s, s, s] }),
            block(
                "cyan",
                ShapeSpec::Tetra {
                    size: [0.08, 0.08, 0.08],
                },
            ),
            block(
                "pink",
                ShapeSpec::Box {
                    size: [0.05, 0.05, 0.05],
                },
            ),
        ],
        hand: None,
        left_hand: None,
    };
    let half = std::f64::consts::FRAC_1_SQRT_2;
    let tilt = (0.2f64).sin_cos();
    let poses: [([f64; 3], [f64; 4], BlockMode); 6] = [
        (
            [-0.25, 0.03, 0.05],
            [0.0, 0.38, 0.0, 0.925],
            BlockMode::Resting,
        ),
        (
            [-0.12, 0.035, -0.2],
            [0.0, 0.0, tilt.0, tilt.1],
            BlockMode::Tipping,
        ),
        ([0.22, 0.02, 0.1], [0.0, 0.0, 0.0, 1.0], BlockMode::Pushed),
        ([0.02, 0.2, 0.0], [0.0, 0.2, 0.0, 0.98], BlockMode::Grasped),
        (
            [0.25, 0.06, -0.15],
            [0.0, half, 0.0, half],
            BlockMode::Carried,
        ),
        ([-0.05, 0.32, -0.25], [0.3, 0.2, 0.0, 0.93], BlockMode::Free),
    ];
    let mut world = WorldSample::with_blocks(poses.len());
    world.grasped_block = 3;
    for (b, (p, q, m)) in world.blocks.iter_mut().zip(poses) {
        let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        *b = BlockState {
            pose: Pose {
                position: p,
                rotation: q.map(|v| v / n),
            },
            mode: m as u32,
            held_by: 0,
        };
    }
    // Four fingers curling down over the block's near face (towards the viewer), the thumb
    // on its far face, the palm above it.
    let mut hand = HandSample {
        tracked: 1,
        finger_count: 5,
        finger_point_count: [4; 5],
        finger_radius: [0.010, 0.009, 0.009, 0.0085, 0.0075],
        palm_vertex_count: 8,
        ..Default::default()
    };
    let (gx, gy, gz) = (0.02, 0.2, 0.0);
    hand.finger_points[0] = [
        [gx - 0.05, gy + 0.06, gz - 0.02],
        [gx - 0.045, gy + 0.03, gz - 0.04],
        [gx - 0.02, gy + 0.01, gz - 0.045],
        [gx, gy, gz - 0.04],
        [0.0; 3],
    ];
    for f in 1..5 {
        let x = gx - 0.03 + 0.02 * (f - 1) as f64;
        hand.finger_points[f] = [
            [x, gy + 0.07, gz + 0.0],
            [x, gy + 0.06, gz + 0.03],
            [x, gy + 0.03, gz + 0.045],
            [x, gy + 0.005, gz + 0.04],
            [0.0; 3],
        ];
    }
    let mut k = 0;
    for dx in [-0.045, 0.045] {
        for dy in [0.07, 0.095] {
            for dz in [-0.09, 0.0] {
                hand.palm_vertices[k] = [gx + dx, gy + dy, gz + dz];
                k += 1;
            }
        }
    }
    (scene, world, hand)
}
