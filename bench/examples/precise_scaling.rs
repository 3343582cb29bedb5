//! The precise model's scaling alone, as `bench stepper` measures it but without the paper
//! model, the cheap setting or the ablation: `cargo run --release -p handblocks-bench --example
//! precise_scaling -- falling 3 [16,64,256,1024,4096]` (situation, timed runs per size, sizes).
//! Each size is warmed up once, then the timed runs go round the sizes; every step is timed on
//! its own. Prints per size the p50 time per step, the time per block, the wrapper's p50 and its
//! share of the step (the step less rapier's pipeline call), and the fitted exponent of p50
//! against N (least squares on log-log, `bench stepper`'s fit, written out here so that the
//! example also builds against a tree from before the wrapper was measured).

use std::time::Instant;

use common::config::scene::ModelKind;
use common::config::Scene;
use handblocks_bench::stepper::{field, Situation};
use stepper::{BareFingersHand, Model};

/// One run: (step time, wrapper time) per timed step, in us.
fn run(scene: &Scene, settle: u64, steps: u64) -> Result<Vec<(f64, f64)>, String> {
    let mut model = Model::new(scene).map_err(|e| e.to_string())?;
    let hand = BareFingersHand::from_scene(scene);
    let dt = 1.0 / scene.world.step_hz;
    let sample = |k: u64| hand.as_ref().map(|h| h.sample(k as f64 * dt));
    model.set_previous_hand(sample(0).as_ref());
    for k in 1..=settle {
        model.step(sample(k).as_ref());
    }
    let pipeline = |m: &Model| match m {
        Model::Precise(w) => w.pipeline_ns(),
        _ => 0,
    };
    let mut out = Vec::with_capacity(steps as usize);
    for k in settle + 1..=settle + steps {
        let h = sample(k);
        let p0 = pipeline(&model);
        let t0 = Instant::now();
        model.step(h.as_ref());
        let us = t0.elapsed().as_secs_f64() * 1e6;
        out.push((us, us - (pipeline(&model) - p0) as f64 * 1e-3));
    }
    Ok(out)
}

fn p50(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (situation, settle, steps) = match args.first().map(String::as_str).unwrap_or("falling") {
        "falling" => (Situation::Falling, 0, 60),
        "resting" => (Situation::Resting, 120, 60),
        "hand" => (Situation::Hand, 0, 132),
        other => return Err(format!("situation {other:?}: falling, resting or hand")),
    };
    let runs: usize = args
        .get(1)
        .map_or(Ok(3), |s| s.parse().map_err(|e| format!("{s:?}: {e}")))?;
    let sizes: Vec<usize> = args
        .get(2)
        .map_or("16,64,256,1024,4096", String::as_str)
        .split(',')
        .map(|s| s.parse().map_err(|e| format!("{s:?}: {e}")))
        .collect::<Result<_, String>>()?;
    let scenes: Vec<Scene> = sizes
        .iter()
        .map(|&n| field(n, situation, ModelKind::Precise))
        .collect();
    for s in &scenes {
        run(s, settle, steps)?;
    }
    let mut all: Vec<Vec<(f64, f64)>> = vec![Vec::new(); sizes.len()];
    for _ in 0..runs {
        for (k, s) in scenes.iter().enumerate() {
            all[k].extend(run(s, settle, steps)?);
        }
    }
    let mut points = Vec::new();
    for (&n, t) in sizes.iter().zip(&all) {
        let total: f64 = t.iter().map(|x| x.0).sum();
        let wrapper: f64 = t.iter().map(|x| x.1).sum();
        let step = p50(t.iter().map(|x| x.0).collect());
        println!(
            "{} x{n}: p50 {step:.1} us per step, {:.3} us per block; wrapper p50 {:.1} us, {:.1} % of the step",
            situation.name(),
            step / n as f64,
            p50(t.iter().map(|x| x.1).collect()),
            100.0 * wrapper / total
        );
        points.push(((n as f64).ln(), step.ln()));
    }
    let m = points.len() as f64;
    let (mx, my) = (
        points.iter().map(|p| p.0).sum::<f64>() / m,
        points.iter().map(|p| p.1).sum::<f64>() / m,
    );
    let sxy: f64 = points.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = points.iter().map(|p| (p.0 - mx).powi(2)).sum();
    println!("fitted exponent of p50 against N: {:.3}", sxy / sxx);
    Ok(())
}
