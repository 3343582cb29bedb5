//! Steps one of `bench stepper`'s fields over and over, for a profiler (`perf record`,
//! `valgrind --tool=callgrind`): `cargo run --release -p handblocks-bench --example
//! stepper_profile -- falling 1024 20` (situation, blocks, runs; `idle` and `idle-no-hand`:
//! the ablation's idle field with its hand on and off, whatever the blocks).

use std::time::Instant;

use common::config::scene::HandEffect;
use common::config::scene::ModelKind;
use handblocks_bench::stepper::{field, idle_field, Situation};
use stepper::{BareFingersHand, Model};

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let which = args.first().map(String::as_str).unwrap_or("falling");
    let situation = match which {
        "falling" => Situation::Falling,
        "resting" | "idle" | "idle-no-hand" => Situation::Resting,
        "hand" => Situation::Hand,
        other => {
            return Err(format!(
                "situation {other:?}: falling, resting, hand, idle (the ablation's idle field) \
                 or idle-no-hand (the same with hand = \"none\")"
            ))
        }
    };
    let parse = |k: usize, default: usize| -> Result<usize, String> {
        args.get(k).map_or(Ok(default), |s| {
            s.parse().map_err(|e| format!("{s:?}: {e}"))
        })
    };
    let (n, runs) = (parse(1, 1024)?, parse(2, 20)?);
    let scene = match which {
        "idle" => idle_field(ModelKind::Paper),
        "idle-no-hand" => {
            let mut s = idle_field(ModelKind::Paper);
            s.effects.hand = HandEffect::None;
            s
        }
        _ => field(n, situation, ModelKind::Paper),
    };
    let hand = BareFingersHand::from_scene(&scene);
    let dt = 1.0 / scene.world.step_hz;
    let mut total = 0.0;
    let mut steps = 0u64;
    // FNV-1a over every block's pose bits after every step of the first run: two builds that
    // print the same hash stepped the field identically, bit for bit.
    let mut hash = 0xcbf2_9ce4_8422_2325u64;
    for _ in 0..runs {
        let mut model = Model::new(&scene).map_err(|e| e.to_string())?;
        let sample = |k: u64| hand.as_ref().map(|h| h.sample(k as f64 * dt));
        model.set_previous_hand(sample(0).as_ref());
        let t0 = Instant::now();
        for k in 1..=60 {
            model.step(sample(k).as_ref());
        }
        total += t0.elapsed().as_secs_f64();
        if steps == 0 {
            // Replayed untimed for the hash.
            let mut model = Model::new(&scene).map_err(|e| e.to_string())?;
            model.set_previous_hand(sample(0).as_ref());
            for k in 1..=60 {
                model.step(sample(k).as_ref());
                for i in 0..model.block_count() {
                    let Some(b) = model.block(i) else { continue };
                    for v in b
                        .position
                        .to_array()
                        .into_iter()
                        .chain(b.rotation.to_array())
                    {
                        for byte in v.to_bits().to_le_bytes() {
                            hash = (hash ^ byte as u64).wrapping_mul(0x100_0000_01b3);
                        }
                    }
                }
            }
        }
        steps += 60;
    }
    println!(
        "{} x{n}: {:.1} us per step (mean over {steps} steps); poses {hash:016x}",
        which,
        total / steps as f64 * 1e6
    );
    Ok(())
}
