//! A devices session on the emulators, end to end through real ttys: both drivers read on
//! their own threads, as the acquisition process runs them, while the glove's cable is pulled
//! and the tracker goes quiet and spits noise. The session goes on: both streams continue
//! after each fault, every sample is finite and in order, and the errors say what happened.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use acquisition::devices::serial::Backoff;
use acquisition::devices::{
    DeviceEvent, DeviceReaders, Format, Glove, GloveConfig, ReadOutcome, Tracker, TrackerConfig,
    Units,
};
use acquisition::emulator::glove::GloveBehaviour;
use acquisition::emulator::tracker::TrackerBehaviour;
use acquisition::emulator::{glove, tracker, Fault};
use common::{monotonic_ns, GloveSample, Pose, TrackerSample};

fn backoff() -> Backoff {
    Backoff::new(Duration::from_millis(50), Duration::from_millis(200))
}

#[test]
fn a_devices_session_survives_an_unplugged_glove_and_a_silent_tracker() {
    let mut gb = GloveBehaviour::new(22);
    gb.faults = vec![
        (30, Fault::Garbage(b"\x00noise".to_vec())),
        (60, Fault::Unplug(Duration::from_millis(300))),
    ];
    let mut tb = TrackerBehaviour::new();
    tb.stations = [true, true, false, false];
    tb.faults = vec![
        (40, Fault::Garbage(b"01 \r\n\xff".to_vec())),
        (90, Fault::Silence(Duration::from_millis(500))),
    ];
    let glove_emu = glove::spawn(gb).unwrap();
    let tracker_emu = tracker::spawn(tb).unwrap();

    // One epoch for both devices, as the acquisition process gives them.
    let epoch = monotonic_ns();
    let mut gc = GloveConfig::new(glove_emu.path());
    gc.sensors = Some(22);
    gc.calibration = Some(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/devices/glove-22.cal"),
    );
    gc.link.silence_timeout = Duration::from_millis(300);
    gc.link.backoff = backoff();
    gc.epoch_ns = epoch;
    let mut tc = TrackerConfig::new(tracker_emu.path());
    tc.format = Format::Binary;
    tc.units = Units::Inches;
    tc.to_world = Pose {
        position: [0.0, 1.2, 0.0],
        rotation: [0.0, 0.0, 0.0, 1.0],
    };
    tc.link.silence_timeout = Duration::from_millis(300);
    tc.link.backoff = backoff();
    tc.epoch_ns = epoch;

    // As the acquisition process runs them: each driver on its own reader thread, one
    // consumer (which would publish `glove` and `tracker`).
    let g = Glove::open(gc).unwrap();
    let t = Tracker::open(tc).unwrap();
    let readers = DeviceReaders::spawn(Some(g), Some(t)).unwrap();

    // Run until both devices have been through their faults and delivered well after them,
    // or a generous limit.
    let start = Instant::now();
    let mut gloves: Vec<(GloveSample, Instant)> = Vec::new();
    let mut trackers: Vec<(TrackerSample, Instant)> = Vec::new();
    let mut errors = Vec::new();
    while start.elapsed() < Duration::from_secs(10) {
        match readers.recv_timeout(Duration::from_millis(100)) {
            Some(DeviceEvent::Glove(s)) => gloves.push((s, Instant::now())),
            Some(DeviceEvent::Tracker(s)) => trackers.push((s, Instant::now())),
            Some(DeviceEvent::Error(e)) => errors.push((e, Instant::now())),
            None => {}
        }
        let glove_back = errors
            .iter()
            .rfind(|(e, _)| e.port() == Some(glove_emu.path()))
            .is_some_and(|(_, at)| gloves.iter().filter(|(_, t)| t > at).count() >= 30);
        let tracker_back = errors
            .iter()
            .rfind(|(e, _)| e.port() == Some(tracker_emu.path()))
            .is_some_and(|(_, at)| trackers.iter().filter(|(_, t)| t > at).count() >= 30);
        if glove_back && tracker_back {
            break;
        }
    }
    let stats = readers.stop();
    let (glove_stats, tracker_stats) = (stats.glove, stats.tracker);
    assert_eq!(stats.dropped, 0);
    let glove_report = glove_emu.stop().unwrap();
    let tracker_report = tracker_emu.stop().unwrap();

    let messages: Vec<String> = errors.iter().map(|(e, _)| e.to_string()).collect();
    // The glove: pulled, reported as a failed link, reconnected.
    assert_eq!(glove_report.unplugs, 1);
    assert!(glove_stats.reconnects >= 1, "{glove_stats:?} {messages:#?}");
    assert!(
        messages.iter().any(|m| m.starts_with("the glove link on")),
        "{messages:#?}"
    );
    // The tracker: went quiet, reported silent, reconnected; noise skipped.
    assert!(
        tracker_stats.reconnects >= 1,
        "{tracker_stats:?} {messages:#?}"
    );
    assert!(tracker_stats.garbage_bytes > 0);
    assert!(tracker_stats.other_station_records > 0);
    assert!(
        messages
            .iter()
            .any(|m| m.starts_with("the tracker on") && m.contains("stopped answering")),
        "{messages:#?}"
    );
    assert!(tracker_report.records > 100);

    // Both streams: finite, in order, on one timeline, and alive after their faults.
    assert!(
        gloves.len() > 60 && trackers.len() > 60,
        "{} glove and {} tracker samples",
        gloves.len(),
        trackers.len()
    );
    for w in gloves.windows(2) {
        assert_eq!(w[1].0.stamp.seq, w[0].0.stamp.seq + 1);
        assert!(w[1].0.stamp.source_time_ns > w[0].0.stamp.source_time_ns);
    }
    for w in trackers.windows(2) {
        assert_eq!(w[1].0.stamp.seq, w[0].0.stamp.seq + 1);
        assert!(w[1].0.stamp.source_time_ns > w[0].0.stamp.source_time_ns);
    }
    assert!(gloves
        .iter()
        .all(|(s, _)| s.sensor_count == 22 && s.angles.iter().all(|a| a.is_finite())));
    assert!(trackers
        .iter()
        .all(|(s, _)| s.wrist.is_finite() && s.station == 1));
    // The transmitter is 1.2 m up and the receiver 20 cm below it.
    assert!(trackers
        .iter()
        .all(|(s, _)| (s.wrist.position[1] - 1.0).abs() < 1e-3));
}

#[test]
fn the_emulator_program_entry_serves_a_link_until_stopped() {
    let dir = std::env::temp_dir().join(format!("handblocks-run-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let link = dir.join("glove");
    let stop = Arc::new(AtomicBool::new(false));
    let server = {
        let (link, stop) = (link.clone(), stop.clone());
        std::thread::spawn(move || {
            glove::run(&link, GloveBehaviour::new(18), &|| {
                stop.load(Ordering::Relaxed)
            })
        })
    };
    let deadline = Instant::now() + Duration::from_secs(5);
    while std::fs::symlink_metadata(&link).is_err() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(5));
    }
    let mut g = Glove::open(GloveConfig::new(&link)).unwrap();
    let mut s = GloveSample::default();
    let mut n = 0;
    while n < 5 && Instant::now() < deadline {
        if let Ok(ReadOutcome::Sample) = g.read(&mut s) {
            n += 1;
        }
    }
    assert_eq!(n, 5);
    assert_eq!(s.sensor_count, 18);
    drop(g);
    stop.store(true, Ordering::Relaxed);
    let report = server.join().unwrap().unwrap();
    assert!(report.records >= 5);
    // The link is gone with the emulator.
    assert!(std::fs::symlink_metadata(&link).is_err());
    let _ = std::fs::remove_dir_all(&dir);
}
