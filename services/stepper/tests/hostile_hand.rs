//! Issue 28: a hand sample from outside (a trace, a recording, a device, a remote peer) with a
//! huge but finite coordinate is refused where it enters the world, never a hang: every step
//! with such a sample ends, and the world counts what it refused; the hand holds its last good
//! pose over it.

use std::sync::mpsc;
use std::time::Duration;

use common::config::scene::ModelKind;
use common::config::Scene;
use common::HandSample;
use stepper::{BareFingersHand, HandSource, Model, World};

fn scene(name: &str) -> Scene {
    let file = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../config/scenes")
        .join(name);
    Scene::load(&file).unwrap_or_else(|e| panic!("{e}"))
}

/// Steps `name`'s scene 240 steps with its scripted hand, one coordinate of sample 60 set to
/// `value`, on a thread; Err when the steps do not end within 20 s.
fn run_with(name: &'static str, value: f64, which: usize) -> Result<u64, String> {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let s = scene(name);
        let mut w = World::new(&s).unwrap();
        let mut hand = BareFingersHand::from_scene(&s).unwrap();
        let dt = 1.0 / s.world.step_hz;
        for n in 1..=240u64 {
            let mut h = hand.hand_at(n, n as f64 * dt);
            if n == 60 {
                if let Some(h) = h.as_mut() {
                    match which {
                        0 => h.finger_points[0][0][0] = value,
                        1 => h.finger_points[0][0][1] = value,
                        _ => h.wrist.position[2] = -value,
                    }
                }
            }
            w.step(h.as_ref());
        }
        let _ = tx.send(w.rejected_hand_samples());
    });
    rx.recv_timeout(Duration::from_secs(20))
        .map_err(|_| format!("{name}: a coordinate of {value:e} hung the stepper"))
}

#[test]
fn a_huge_coordinate_in_a_hand_sample_is_refused_not_a_hang() {
    for name in ["push.toml", "grasp-throw-fingers.toml"] {
        for value in [5e14, 1e20, 1e300, f64::MAX] {
            for which in 0..3 {
                let rejected = run_with(name, value, which).unwrap();
                assert_eq!(rejected, 1, "{name}: {value:e} at {which}");
            }
        }
        // In range: nothing refused.
        assert_eq!(run_with(name, 0.5, 0).unwrap(), 0);
    }
}

/// Steps `name`'s scene under `model` with its scripted hand, sample `at` replaced by
/// `replace` of the step's own sample and the one before it; the final poses (bits), modes and
/// every step's events.
fn outcome_with(
    name: &str,
    model: ModelKind,
    at: u64,
    replace: impl Fn(&HandSample, &HandSample) -> HandSample,
) -> (Vec<[u64; 7]>, Vec<String>, u64) {
    let mut s = scene(name);
    s.world.model = model;
    let mut w = Model::new(&s).unwrap();
    let mut hand = BareFingersHand::from_scene(&s).unwrap();
    let dt = 1.0 / s.world.step_hz;
    let mut before = hand.hand_at(0, 0.0).unwrap();
    w.set_previous_hand(Some(&before));
    let mut events = Vec::new();
    for n in 1..=360u64 {
        let mut h = hand.hand_at(n, n as f64 * dt).unwrap();
        if n == at {
            h = replace(&h, &before);
        }
        w.step(Some(&h));
        before = h;
        events.extend(w.events().iter().map(|e| format!("{e:?}")));
    }
    let poses = (0..w.block_count())
        .filter_map(|i| w.block(i))
        .map(|b| {
            let (p, q) = (b.position.to_array(), b.rotation.to_array());
            [p[0], p[1], p[2], q[0], q[1], q[2], q[3]].map(f64::to_bits)
        })
        .collect();
    (poses, events, w.rejected_hand_samples())
}

/// The hand holds its last good pose over a refused sample: the world steps exactly as if the
/// sample before had come again (same bits, same events), under both models, at steps where
/// the hand pushes, closes on the block, carries it and lets go. A refused sample does not
/// drop a grasp nor let the hand vanish for a step.
#[test]
fn a_refused_sample_holds_the_last_good_pose() {
    type Glitch = (&'static str, fn(&mut HandSample));
    let glitches: [Glitch; 3] = [
        ("a check point at 1e20 m", |h| {
            h.finger_points[0][0][0] = 1e20
        }),
        ("a NaN wrist", |h| h.wrist.position[1] = f64::NAN),
        ("a negative finger radius", |h| h.finger_radius[0] = -0.01),
    ];
    for name in ["push.toml", "grasp-throw-fingers.toml"] {
        for model in [ModelKind::Paper, ModelKind::Precise] {
            for at in [30, 60, 90, 150, 210] {
                let held = outcome_with(name, model, at, |_, before| *before);
                assert_eq!(held.2, 0);
                for (what, glitch) in glitches {
                    let refused = outcome_with(name, model, at, |h, _| {
                        let mut h = *h;
                        glitch(&mut h);
                        h
                    });
                    let case = format!("{name} {model:?}, {what} at step {at}");
                    assert_eq!(refused.2, 1, "{case}: refused");
                    assert_eq!(refused.1, held.1, "{case}: events");
                    assert_eq!(refused.0, held.0, "{case}: final poses");
                }
            }
        }
    }
}
