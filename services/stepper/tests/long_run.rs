//! The hour-long run (issue 13): `config/scenes/hard/long-run.toml`, whose header states the
//! criterion, for 432,000 steps at 120 Hz, twice. Resting and supported blocks cost nothing
//! (R14 skips them until something stirs them), so an hour of simulated time takes seconds.

mod support;

use std::collections::hash_map::DefaultHasher;
use std::hash::Hasher;
use std::path::Path;
use std::time::Instant;

use glam::{DQuat, DVec3};

use common::config::Scene;
use common::BlockMode;
use stepper::{BareFingersHand, World};

/// One hour at 120 Hz.
const STEPS: u64 = 432_000;
/// The hand's keys repeat every 8 s.
const PERIOD_STEPS: u64 = 8 * 120;

/// What one run measured.
struct Run {
    /// A hash of every step's block poses (their bits) and modes.
    hash: u64,
    last: Vec<(DVec3, DQuat)>,
    throws: usize,
    pushes: usize,
    seconds: f64,
}

fn run(scene: &Scene) -> Result<Run, String> {
    let hand = BareFingersHand::from_scene(scene).ok_or("the scene has a bare-fingers hand")?;
    let mut w = World::new(scene).map_err(|e| e.to_string())?;
    let dt = 1.0 / scene.world.step_hz;
    // t modulo the period, exactly (integer steps).
    let hand_at = |n: u64| {
        let mut h = hand.sample((n % PERIOD_STEPS) as f64 * dt);
        h.stamp.seq = n;
        h
    };
    let names: Vec<String> = w.block_names().map(str::to_string).collect();
    let touched = |i: usize| names[i] == "A" || names[i] == "B";
    w.set_previous_hand(Some(&hand_at(0)));
    let start = Instant::now();
    let mut hasher = DefaultHasher::new();
    let mut after_first: Vec<(DVec3, DQuat)> = Vec::new();
    let mut prev: Vec<(DVec3, BlockMode)> = Vec::new();
    let (mut throws, mut pushes) = (0, 0);
    for n in 1..=STEPS {
        w.step(Some(&hand_at(n)));
        for e in w.events() {
            match e.kind {
                stepper::EventKind::Release => throws += 1,
                stepper::EventKind::Push => pushes += 1,
                _ => {}
            }
        }
        for i in 0..w.block_count() {
            let b = w.block(i).ok_or("block")?;
            let (p, q) = (b.position, b.rotation);
            if !p.is_finite() || !q.is_finite() {
                return Err(format!("{} is not finite at step {n}", names[i]));
            }
            if (q.length() - 1.0).abs() > 1e-12 {
                return Err(format!("{}: |q| = {} at step {n}", names[i], q.length()));
            }
            for v in [p.x, p.y, p.z, q.x, q.y, q.z, q.w] {
                hasher.write_u64(v.to_bits());
            }
            hasher.write_u32(b.mode as u32);
            if n == 1 {
                after_first.push((p, q));
            } else if !touched(i) && after_first[i] != (p, q) {
                return Err(format!("{} moved at step {n}: {p} {q}", names[i]));
            }
            let resting = |m: BlockMode| matches!(m, BlockMode::Resting | BlockMode::Supported);
            if n > 1 && resting(b.mode) && resting(prev[i].1) && p.y > prev[i].0.y {
                return Err(format!(
                    "{} at rest rose from {} to {} at step {n}",
                    names[i], prev[i].0.y, p.y
                ));
            }
            if n == 1 {
                prev.push((p, b.mode));
            } else {
                prev[i] = (p, b.mode);
            }
        }
    }
    let seconds = start.elapsed().as_secs_f64();
    let last = (0..w.block_count())
        .map(|i| {
            let b = w.block(i).unwrap();
            (b.position, b.rotation)
        })
        .collect();
    Ok(Run {
        hash: hasher.finish(),
        last,
        throws,
        pushes,
        seconds,
    })
}

#[test]
fn an_hour_of_throws_and_pushes_stays_stable_and_deterministic() {
    let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/scenes/hard/long-run.toml");
    let scene = Scene::load(&file).unwrap_or_else(|e| panic!("{e}"));
    let a = run(&scene).unwrap_or_else(|e| panic!("long run: {e}"));
    let b = run(&scene).unwrap_or_else(|e| panic!("long run (second): {e}"));
    assert_eq!(a.hash, b.hash, "two runs differ");
    assert_eq!(a.last, b.last);
    // The hand kept working for the whole hour: a throw and two pushes every 8 s.
    let periods = (STEPS / PERIOD_STEPS) as usize;
    assert!(
        a.throws >= periods,
        "{} throws in {periods} periods",
        a.throws
    );
    assert!(
        a.pushes >= 2 * periods,
        "{} pushes in {periods} periods",
        a.pushes
    );
    // A comes back to where it was thrown from; B stays within reach.
    let (pa, pb) = (a.last[0].0, a.last[1].0);
    assert!(pa.x.abs() < 1e-9 && pa.z.abs() < 1e-9, "A drifted to {pa}");
    assert!(
        (pb.x - 0.6).abs() < 0.02 && pb.z.abs() < 1e-9,
        "B drifted to {pb}"
    );
    println!(
        "long run: {STEPS} steps, {} throws, {} pushes, {:.2} s and {:.2} s wall",
        a.throws, a.pushes, a.seconds, b.seconds
    );
}
