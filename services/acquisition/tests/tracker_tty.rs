//! The FASTRAK driver end to end through a real tty, against the emulated tracker.

use std::time::{Duration, Instant};

use acquisition::devices::fastrak::tracker_axes;
use acquisition::devices::serial::Backoff;
use acquisition::devices::{
    DeviceError, Format, Orientation, ReadOutcome, Tracker, TrackerConfig, TrackerMode, Units,
};
use acquisition::emulator::tracker::{self, TrackerBehaviour, CIRCLE_CENTRE_CM, CIRCLE_RADIUS_CM};
use acquisition::emulator::Fault;
use common::{Pose, TrackerSample};
use glam::{DQuat, DVec3};

fn config(port: &std::path::Path) -> TrackerConfig {
    let mut cfg = TrackerConfig::new(port);
    // Generous: a loaded test machine must not make a healthy stream look silent. Tests of
    // silence shorten it.
    cfg.link.silence_timeout = Duration::from_millis(1500);
    cfg.link.backoff = Backoff::new(Duration::from_millis(50), Duration::from_millis(200));
    cfg
}

fn collect(
    t: &mut Tracker,
    want: usize,
    limit: Duration,
) -> (Vec<TrackerSample>, Vec<DeviceError>) {
    let end = Instant::now() + limit;
    let mut samples = Vec::new();
    let mut errors = Vec::new();
    let mut s = TrackerSample::default();
    while samples.len() < want && Instant::now() < end {
        match t.read(&mut s) {
            Ok(ReadOutcome::Sample) => samples.push(s),
            Ok(ReadOutcome::Pending) => {}
            Err(e) => errors.push(e),
        }
    }
    (samples, errors)
}

/// The emulated receiver moves on a circle (tracker frame, cm) and turns about the tracker's
/// z (down) axis: in the world, a circle about the mapped centre, in a horizontal plane, and
/// a rotation about the vertical.
fn assert_on_circle(samples: &[TrackerSample], to_world: &Pose, tol_m: f64) {
    let w_q = DQuat::from_array(to_world.rotation);
    let centre = DVec3::from_array(to_world.position)
        + w_q * (tracker_axes() * (DVec3::from_array(CIRCLE_CENTRE_CM) * 0.01));
    let up = w_q * DVec3::Y;
    for s in samples {
        assert!(s.wrist.is_finite());
        let p = DVec3::from_array(s.wrist.position);
        let d = p - centre;
        assert!(d.dot(up).abs() < tol_m, "{p} off the circle's plane");
        assert!(
            (d.length() - CIRCLE_RADIUS_CM * 0.01).abs() < tol_m,
            "{p} is {} from the centre",
            d.length()
        );
        let q = DQuat::from_array(s.wrist.rotation);
        assert!((q.length() - 1.0).abs() < 1e-9);
        // A turn about the vertical only: the world-up axis stays up.
        assert!((q * w_q.conjugate() * up - up).length() < 1e-3, "{q}");
    }
}

#[test]
fn binary_centimetres_quaternions_continuous() {
    let emu = tracker::spawn(TrackerBehaviour::new()).unwrap();
    let mut t = Tracker::open(config(emu.path())).unwrap();
    let (samples, errors) = collect(&mut t, 40, Duration::from_secs(5));
    assert!(errors.is_empty(), "{errors:?}");
    assert_eq!(samples.len(), 40);
    assert_on_circle(&samples, &Pose::IDENTITY, 1e-4);
    assert!(samples.iter().all(|s| s.station == 1));
    assert!(samples
        .windows(2)
        .all(|w| w[1].stamp.source_time_ns > w[0].stamp.source_time_ns));
    drop(t);
    let report = emu.stop().unwrap();
    let sent = String::from_utf8_lossy(&report.received).into_owned();
    assert!(
        sent.starts_with("cfuO1,2,11,1\rO2,2,11,1\rO3,2,11,1\rO4,2,11,1\rPC"),
        "{sent:?}"
    );
    assert!(sent.ends_with('c'), "{sent:?}");
}

#[test]
fn ascii_inches_euler_with_a_placed_transmitter() {
    let emu = tracker::spawn(TrackerBehaviour::new()).unwrap();
    let mut cfg = config(emu.path());
    cfg.format = Format::Ascii;
    cfg.units = Units::Inches;
    cfg.orientation = Orientation::Euler;
    // The transmitter 1 m up, turned a quarter about the vertical.
    let q = DQuat::from_rotation_y(std::f64::consts::FRAC_PI_2);
    cfg.to_world = Pose {
        position: [0.2, 1.0, -0.3],
        rotation: q.to_array(),
    };
    let to_world = cfg.to_world;
    let mut t = Tracker::open(cfg).unwrap();
    let (samples, errors) = collect(&mut t, 30, Duration::from_secs(5));
    assert!(errors.is_empty(), "{errors:?}");
    assert_eq!(samples.len(), 30);
    // ASCII keeps 0.01 inch: a quarter millimetre.
    assert_on_circle(&samples, &to_world, 1e-3);
}

#[test]
fn polled_tracker() {
    let emu = tracker::spawn(TrackerBehaviour::new()).unwrap();
    let mut cfg = config(emu.path());
    cfg.mode = TrackerMode::Polled { rate_hz: 200.0 };
    let mut t = Tracker::open(cfg).unwrap();
    let (samples, errors) = collect(&mut t, 20, Duration::from_secs(5));
    assert!(errors.is_empty(), "{errors:?}");
    assert_on_circle(&samples, &Pose::IDENTITY, 1e-4);
    drop(t);
    let report = emu.stop().unwrap();
    let polls = report.received.iter().filter(|b| **b == b'P').count();
    assert!(polls >= 20, "{polls}");
    assert!(!report.received.contains(&b'C'));
}

#[test]
fn the_configured_station_is_picked_from_several() {
    let mut b = TrackerBehaviour::new();
    b.stations = [true, true, false, true];
    let emu = tracker::spawn(b).unwrap();
    let mut cfg = config(emu.path());
    cfg.station = 2;
    let mut t = Tracker::open(cfg).unwrap();
    let (samples, errors) = collect(&mut t, 20, Duration::from_secs(5));
    assert!(errors.is_empty(), "{errors:?}");
    assert!(samples.iter().all(|s| s.station == 2));
    assert!(t.stats().other_station_records >= 20, "{:?}", t.stats());
}

#[test]
fn a_missing_station_names_the_ones_that_report() {
    let mut b = TrackerBehaviour::new();
    b.stations = [true, false, false, true];
    let emu = tracker::spawn(b).unwrap();
    let mut cfg = config(emu.path());
    cfg.station = 3;
    cfg.link.answer_timeout = Duration::from_millis(200);
    let Err(e) = Tracker::open(cfg) else {
        panic!("opened a station with no receiver")
    };
    let msg = e.to_string();
    assert!(msg.contains("did not report station 3"), "{msg}");
    assert!(msg.contains("stations reporting: 1, 4"), "{msg}");
}

#[test]
fn noise_and_cut_records_resynchronise_in_both_formats() {
    for format in [Format::Binary, Format::Ascii] {
        let mut b = TrackerBehaviour::new();
        // Record numbers count the answer to the driver's `P` (record 0) too.
        b.faults = vec![
            (5, Fault::Garbage(b"\xff\x0001 junk\r\n0".to_vec())),
            (10, Fault::Truncate(20)),
            (15, Fault::Garbage(vec![b'0'; 40])),
            (20, Fault::Truncate(3)),
            (25, Fault::Garbage((0..=255u8).collect())),
        ];
        let emu = tracker::spawn(b).unwrap();
        let mut cfg = config(emu.path());
        cfg.format = format;
        let mut t = Tracker::open(cfg).unwrap();
        let (samples, errors) = collect(&mut t, 35, Duration::from_secs(5));
        assert!(errors.is_empty(), "{format:?}: {errors:?}");
        assert_eq!(samples.len(), 35);
        assert_on_circle(&samples, &Pose::IDENTITY, 1e-3);
        let stats = t.stats();
        assert!(stats.garbage_bytes > 0, "{format:?}: {stats:?}");
    }
}

#[test]
fn a_tracker_that_goes_silent_is_reported_and_reconnected() {
    let mut b = TrackerBehaviour::new();
    b.faults = vec![(20, Fault::Silence(Duration::from_millis(600)))];
    let emu = tracker::spawn(b).unwrap();
    let mut cfg = config(emu.path());
    cfg.link.silence_timeout = Duration::from_millis(250);
    // Shorter than the silence, so the first reconnection attempt meets a mute tracker.
    cfg.link.answer_timeout = Duration::from_millis(200);
    let mut t = Tracker::open(cfg).unwrap();
    let (first, _) = collect(&mut t, 15, Duration::from_secs(5));
    assert_eq!(first.len(), 15);
    let (after, errors) = collect(&mut t, 20, Duration::from_secs(8));
    assert_eq!(after.len(), 20, "{errors:?}");
    assert!(
        errors
            .iter()
            .any(|e| matches!(e, DeviceError::Silent { .. })),
        "{errors:?}"
    );
    // While silent, reconnection attempts fail with "did not answer".
    assert!(
        errors
            .iter()
            .any(|e| e.to_string().contains("did not answer `P`")),
        "{errors:?}"
    );
    assert!(t.stats().reconnects >= 1);
    assert_on_circle(&after, &Pose::IDENTITY, 1e-4);
}

#[test]
fn an_unplugged_tracker_comes_back_in_the_same_settings() {
    let mut b = TrackerBehaviour::new();
    b.faults = vec![(10, Fault::Unplug(Duration::from_millis(300)))];
    let emu = tracker::spawn(b).unwrap();
    let mut cfg = config(emu.path());
    cfg.format = Format::Binary;
    cfg.units = Units::Inches;
    let mut t = Tracker::open(cfg).unwrap();
    let (_, _) = collect(&mut t, 5, Duration::from_secs(5));
    let (after, errors) = collect(&mut t, 20, Duration::from_secs(8));
    assert_eq!(after.len(), 20, "{errors:?}");
    assert!(!errors.is_empty());
    // The replugged tracker powered up in ASCII inches; the driver set it up again.
    assert_on_circle(&after, &Pose::IDENTITY, 1e-4);
}
