//! Time of `Renderer::render` (draw both eyes, wait for the GPU) alone, per frame content.
//! `cargo run -p renderer --release --example frame_cost -- [WIDTH HEIGHT] [FRAMES] [GAP_MS] [BLOCKS]`
//! (GAP_MS: idle time between frames, as a paced loop has; BLOCKS: 8 by default, laid out on a
//! square grid 8 cm apart like config/scenes/field-1024.toml). The blocks rest; each size is
//! timed drawn whole every frame (the static layer off), from the static layer's image, and
//! from it with one block pushed a little every frame (its layer unchanged), and with one of
//! the layer's blocks moving every frame (a redraw of the layer each frame: the worst case).

use std::path::PathBuf;

use common::config::scene::{BlockSpec, Effects, Scene, ShapeSpec, WorldSettings};
use common::{BlockMode, HandSample, WorldSample};
use renderer::{RenderSettings, Renderer};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<u32> = std::env::args()
        .skip(1)
        .map(|s| s.parse::<u32>())
        .collect::<Result<_, _>>()?;
    let (w, h) = (
        a.first().copied().unwrap_or(640),
        a.get(1).copied().unwrap_or(480),
    );
    let frames = a.get(2).copied().unwrap_or(200);
    let gap = std::time::Duration::from_millis(a.get(3).copied().unwrap_or(0) as u64);
    let blocks = a.get(4).copied().unwrap_or(8) as usize;
    let side = (blocks as f64).sqrt().ceil() as usize;
    let scene = Scene {
        file: PathBuf::from("cost"),
        world: WorldSettings::default(),
        effects: Effects::default(),
        blocks: (0..blocks)
            .map(|i| BlockSpec {
                name: format!("b{i}"),
                shape: ShapeSpec::Box { size: [0.06; 3] },
                position: [0.0; 3],
                rotation: [0.0, 0.0, 0.0, 1.0],
                velocity: [0.0; 3],
            })
            .collect(),
        hand: None,
        left_hand: None,
    };
    let mut world = WorldSample::with_blocks(blocks);
    for (i, b) in world.blocks[..blocks].iter_mut().enumerate() {
        let (col, row) = ((i % side) as f64, (i / side) as f64);
        let half = (side as f64 - 1.0) / 2.0;
        b.pose.position = [0.08 * (col - half), 0.03, 0.08 * (row - half)];
        b.pose.rotation = [0.0, 0.0, 0.0, 1.0];
        b.mode = BlockMode::Resting as u32;
    }
    let empty = WorldSample::default();
    let hand = HandSample::default();
    for shadows in [true, false] {
        let settings = RenderSettings {
            width: w,
            height: h,
            shadows,
            ..RenderSettings::default()
        };
        let mut r = Renderer::new_headless(&settings, &scene)?;
        let whole = format!("{blocks} blocks, drawn whole");
        let layered = format!("{blocks} blocks at rest, static layer");
        let one_live = format!("{blocks} blocks, 1 pushed, static layer");
        let redrawn = format!("{blocks} blocks, 1 of the layer moved a frame");
        let cases: [(&str, &WorldSample, bool, Option<BlockMode>); 5] = [
            ("floor only", &empty, false, None),
            (&whole, &world, false, None),
            (&layered, &world, true, None),
            (&one_live, &world, true, Some(BlockMode::Pushed)),
            (&redrawn, &world, true, Some(BlockMode::Resting)),
        ];
        for (name, wld, layer, moving) in cases {
            r.set_static_layer(layer);
            let mut wld = wld.clone();
            let mut t = Vec::new();
            for i in 0..frames + 10 {
                std::thread::sleep(gap);
                if let (Some(mode), Some(b)) = (moving, wld.blocks.first_mut()) {
                    b.mode = mode as u32;
                    b.pose.position[1] = 0.03 + 0.001 * (i % 2) as f64;
                }
                let f = r.render(wld.view(), &hand)?;
                if i >= 10 {
                    t.push((f.done_ns - f.started_ns) as f64 / 1e6);
                }
            }
            t.sort_by(f64::total_cmp);
            println!(
                "{w} x {h} per eye, shadows {shadows}, {name}: p50 {:.2} ms, p99 {:.2} ms",
                t[t.len() / 2],
                t[(t.len() - 1) * 99 / 100]
            );
        }
    }
    Ok(())
}
