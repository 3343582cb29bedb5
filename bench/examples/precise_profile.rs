//! Steps one of `bench stepper`'s fields (or a scene file) under the precise model, for a
//! profiler and for checking that a change to the precise wrapper left its results alone:
//! `cargo run --release -p handblocks-bench --example precise_profile -- falling 1024 3
//! [sleep] [noccd] [substeps=N] [iterations=N] [steps=N]`; the situation is `falling`, `resting`,
//! `hand` or a scene file (`config/scenes/hard/pyramid-15.toml`: its own hand is left out unless
//! it gives bare `fingers`).
//!
//! Prints the time per step (mean and p50 over every run's steps), the wrapper's share of it
//! (the step less rapier's pipeline call, [`stepper::PreciseWorld::pipeline_ns`]), and an
//! FNV-1a hash over every block's pose bits, mode and every
//! event after every step of the first run: two builds that print the same hash stepped the
//! scene identically, bit for bit, modes and events included (`sleep` puts the bodies to sleep,
//! which is what the mode derivation's skipping of sleeping bodies needs checking on).

use std::path::Path;
use std::time::Instant;

use common::config::scene::ModelKind;
use common::config::Scene;
use handblocks_bench::stepper::{field, Situation};
use stepper::{BareFingersHand, Model};

fn fnv(hash: &mut u64, bytes: &[u8]) {
    for &byte in bytes {
        *hash = (*hash ^ byte as u64).wrapping_mul(0x100_0000_01b3);
    }
}

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let which = args.first().map(String::as_str).unwrap_or("falling");
    let parse = |k: usize, default: usize| -> Result<usize, String> {
        args.get(k)
            .filter(|s| !s.contains('=') && s.parse::<usize>().is_ok())
            .map_or(Ok(default), |s| {
                s.parse().map_err(|e| format!("{s:?}: {e}"))
            })
    };
    let (n, runs) = (parse(1, 1024)?, parse(2, 3)?.max(1));
    let mut scene = match which {
        "falling" => field(n, Situation::Falling, ModelKind::Precise),
        "resting" => field(n, Situation::Resting, ModelKind::Precise),
        "hand" => field(n, Situation::Hand, ModelKind::Precise),
        file => Scene::load(Path::new(file)).map_err(|e| e.to_string())?,
    };
    scene.world.model = ModelKind::Precise;
    let mut steps_per_run: u64 = 60;
    for a in &args {
        let value = |key: &str| -> Result<Option<u32>, String> {
            a.strip_prefix(key)
                .map(|v| v.parse::<u32>().map_err(|e| format!("{a:?}: {e}")))
                .transpose()
        };
        match a.as_str() {
            "sleep" => scene.world.precise.sleep = true,
            "noccd" => scene.world.precise.ccd = false,
            _ => {
                if let Some(v) = value("substeps=")? {
                    scene.world.precise.substeps = v.max(1);
                }
                if let Some(v) = value("iterations=")? {
                    scene.world.precise.solver_iterations = v.max(1);
                }
                if let Some(v) = value("steps=")? {
                    steps_per_run = u64::from(v.max(1));
                }
            }
        }
    }
    let hand = BareFingersHand::from_scene(&scene);
    let dt = 1.0 / scene.world.step_hz;
    let sample = |k: u64| hand.as_ref().map(|h| h.sample(k as f64 * dt));
    let mut hash = 0xcbf2_9ce4_8422_2325u64;
    let mut events = 0usize;
    let mut total = 0.0;
    let mut pipeline_ns = 0u64;
    let mut times = Vec::new();
    for run in 0..runs {
        let mut model = Model::new(&scene).map_err(|e| e.to_string())?;
        model.set_previous_hand(sample(0).as_ref());
        for k in 1..=steps_per_run {
            let h = sample(k);
            let t0 = Instant::now();
            model.step(h.as_ref());
            let dt = t0.elapsed().as_secs_f64();
            total += dt;
            times.push(dt);
            if run > 0 {
                continue;
            }
            for i in 0..model.block_count() {
                let Some(b) = model.block(i) else { continue };
                for v in b
                    .position
                    .to_array()
                    .into_iter()
                    .chain(b.rotation.to_array())
                {
                    fnv(&mut hash, &v.to_bits().to_le_bytes());
                }
                fnv(&mut hash, &(b.mode as u32).to_le_bytes());
            }
            for e in model.events() {
                events += 1;
                fnv(&mut hash, format!("{e:?}").as_bytes());
            }
        }
        if let Model::Precise(w) = &model {
            pipeline_ns += w.pipeline_ns();
        }
    }
    times.sort_by(f64::total_cmp);
    let p50 = times.get(times.len() / 2).copied().unwrap_or(f64::NAN);
    let steps = steps_per_run * runs as u64;
    let wrapper = total - pipeline_ns as f64 * 1e-9;
    println!(
        "{which} x{}: {:.1} us per step (mean over {steps} steps, {runs} runs), p50 {:.1} us; wrapper {:.1} us per step, {:.1} % of the step; {events} events; poses, modes and events {hash:016x}",
        scene.blocks.len(),
        total / steps as f64 * 1e6,
        p50 * 1e6,
        wrapper / steps as f64 * 1e6,
        100.0 * wrapper / total,
    );
    Ok(())
}
