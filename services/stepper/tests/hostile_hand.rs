//! Issue 28: a hand sample from outside (a trace, a recording, a device, a remote peer) with a
//! huge but finite coordinate is refused where it enters the world, never a hang: every step
//! with such a sample ends, and the world counts what it refused.

use std::sync::mpsc;
use std::time::Duration;

use common::config::Scene;
use stepper::{BareFingersHand, HandSource, World};

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
