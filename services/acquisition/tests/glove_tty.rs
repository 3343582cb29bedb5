//! The CyberGlove driver end to end through a real tty: the emulated glove on a pseudo-terminal,
//! the driver opening its slave path exactly as it opens `/dev/ttyUSB0`.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use acquisition::devices::{Calibration, DeviceError, Glove, GloveConfig, GloveMode, ReadOutcome};
use acquisition::emulator::glove::{self, is_flexion, GloveBehaviour};
use acquisition::emulator::{tracker, Fault};
use common::glove::sensor_order;
use common::GloveSample;

fn cal_file(n: u32) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(format!("../../config/devices/glove-{n}.cal"))
}

fn config(port: &std::path::Path) -> GloveConfig {
    let mut cfg = GloveConfig::new(port);
    // Generous: a loaded test machine must not make a healthy stream look silent. Tests of
    // silence shorten it.
    cfg.link.silence_timeout = Duration::from_millis(1500);
    cfg.link.backoff = acquisition::devices::serial::Backoff::new(
        Duration::from_millis(50),
        Duration::from_millis(200),
    );
    cfg
}

/// Reads until `want` samples or `limit`, collecting samples and errors.
fn collect(
    glove: &mut Glove,
    want: usize,
    limit: Duration,
) -> (Vec<GloveSample>, Vec<DeviceError>) {
    let end = Instant::now() + limit;
    let mut samples = Vec::new();
    let mut errors = Vec::new();
    let mut s = GloveSample::default();
    while samples.len() < want && Instant::now() < end {
        match glove.read(&mut s) {
            Ok(ReadOutcome::Sample) => samples.push(s),
            Ok(ReadOutcome::Pending) => {}
            Err(e) => errors.push(e),
        }
    }
    (samples, errors)
}

/// Every sample the emulator sends has all flexion sensors at one grip value and the rest at
/// 128: a sample that is not so was mixed from two records or shifted.
fn assert_consistent(samples: &[GloveSample], cal: &Calibration) {
    let n = cal.sensor_count();
    let order = sensor_order(n).unwrap();
    for s in samples {
        assert_eq!(s.sensor_count, n);
        assert!(s.angles.iter().all(|a| a.is_finite()));
        let grip_sensor = order.iter().position(|j| is_flexion(*j)).unwrap();
        let raw = cal.raw_for(grip_sensor, s.angles[grip_sensor]);
        for (i, j) in order.iter().enumerate() {
            let want = if is_flexion(*j) { raw } else { 128 };
            assert_eq!(cal.raw_for(i, s.angles[i]), want, "sensor {i} of {s:?}");
        }
    }
}

#[test]
fn streamed_22_sensor_glove_with_calibration() {
    let emu = glove::spawn(GloveBehaviour::new(22)).unwrap();
    let mut cfg = config(emu.path());
    cfg.sensors = Some(22);
    cfg.calibration = Some(cal_file(22));
    let mut g = Glove::open(cfg).unwrap();
    let (samples, errors) = collect(&mut g, 40, Duration::from_secs(5));
    assert!(errors.is_empty(), "{errors:?}");
    assert_eq!(samples.len(), 40);
    let cal = Calibration::load(&cal_file(22)).unwrap();
    assert_consistent(&samples, &cal);
    // Streamed at 100 Hz with nothing lost: the grip moves by one count per record.
    let grips: Vec<u8> = samples
        .iter()
        .map(|s| cal.raw_for(1, s.angles[1]))
        .collect();
    assert!(
        grips.windows(2).all(|w| w[0].abs_diff(w[1]) <= 1),
        "{grips:?}"
    );
    assert!(samples
        .windows(2)
        .all(|w| w[1].stamp.seq == w[0].stamp.seq + 1));
    assert!(samples
        .windows(2)
        .all(|w| w[1].stamp.source_time_ns > w[0].stamp.source_time_ns));
    drop(g);
    let report = emu.stop().unwrap();
    // The handshake: stop any stream, ask the size, start streaming; and stop on close.
    assert!(
        report.received.starts_with(&[0x03, b'?', b'S', b'S']),
        "{:?}",
        report.received
    );
    assert_eq!(report.received.last(), Some(&0x03));
}

#[test]
fn polled_18_sensor_glove_follows_the_glove_size() {
    let emu = glove::spawn(GloveBehaviour::new(18)).unwrap();
    let mut cfg = config(emu.path());
    cfg.mode = GloveMode::Polled { rate_hz: 200.0 };
    // No size and no calibration: the driver takes the size from `?S`.
    let mut g = Glove::open(cfg).unwrap();
    assert_eq!(g.sensor_count(), 18);
    let (samples, errors) = collect(&mut g, 20, Duration::from_secs(5));
    assert!(errors.is_empty(), "{errors:?}");
    assert_consistent(&samples, &Calibration::nominal(18).unwrap());
    drop(g);
    let report = emu.stop().unwrap();
    let polls = report.received.iter().filter(|b| **b == b'G').count();
    assert!(polls >= 20, "{polls} polls");
}

#[test]
fn noise_cut_and_damaged_records_are_skipped() {
    let mut b = GloveBehaviour::new(22);
    b.faults = vec![
        (5, Fault::Garbage(b"\x00\xffG\x01\x02noise S".to_vec())),
        (10, Fault::Truncate(9)),
        (15, Fault::Corrupt(23)), // the terminator
        (20, Fault::Garbage(vec![b'S'; 30])),
        (25, Fault::Truncate(1)),
    ];
    let emu = glove::spawn(b).unwrap();
    let mut g = Glove::open(config(emu.path())).unwrap();
    let (samples, errors) = collect(&mut g, 35, Duration::from_secs(5));
    assert!(errors.is_empty(), "{errors:?}");
    assert_eq!(samples.len(), 35);
    assert_consistent(&samples, &Calibration::nominal(22).unwrap());
    let stats = g.stats();
    assert!(
        stats.garbage_bytes > 0 && stats.rejected_records > 0,
        "{stats:?}"
    );
}

#[test]
fn a_glove_that_goes_silent_is_reported_and_reconnected() {
    let mut b = GloveBehaviour::new(22);
    b.faults = vec![(20, Fault::Silence(Duration::from_millis(600)))];
    let emu = glove::spawn(b).unwrap();
    let mut cfg = config(emu.path());
    cfg.link.silence_timeout = Duration::from_millis(250);
    let mut g = Glove::open(cfg).unwrap();
    let (first, errors) = collect(&mut g, 20, Duration::from_secs(5));
    assert_eq!(first.len(), 20);
    assert!(errors.is_empty());
    // Then silence: an error that says so, reconnection attempts, and samples again.
    let (after, errors) = collect(&mut g, 20, Duration::from_secs(8));
    assert_eq!(after.len(), 20, "{errors:?}");
    let silent = errors
        .iter()
        .find(|e| matches!(e, DeviceError::Silent { .. }))
        .unwrap_or_else(|| panic!("no silence reported: {errors:?}"));
    let msg = silent.to_string();
    assert!(
        msg.contains("stopped answering") && msg.contains(&emu.path().display().to_string()),
        "{msg}"
    );
    assert!(g.stats().reconnects >= 1);
    assert_consistent(&after, &Calibration::nominal(22).unwrap());
}

#[test]
fn an_unplugged_glove_comes_back() {
    let mut b = GloveBehaviour::new(18);
    b.faults = vec![(10, Fault::Unplug(Duration::from_millis(400)))];
    let emu = glove::spawn(b).unwrap();
    let mut g = Glove::open(config(emu.path())).unwrap();
    let (first, _) = collect(&mut g, 10, Duration::from_secs(5));
    assert_eq!(first.len(), 10);
    let (after, errors) = collect(&mut g, 10, Duration::from_secs(8));
    assert_eq!(after.len(), 10, "{errors:?}");
    // While unplugged the port does not exist: reopening fails and says which port.
    assert!(
        errors
            .iter()
            .any(|e| matches!(e, DeviceError::Reconnecting { cause, .. }
            if matches!(**cause, DeviceError::Open { .. }))),
        "{errors:?}"
    );
    assert!(g.stats().reconnects >= 1);
    let report = emu.stop().unwrap();
    assert_eq!(report.unplugs, 1);
}

#[test]
fn a_glove_of_the_wrong_size_is_refused_with_the_fix() {
    let emu = glove::spawn(GloveBehaviour::new(18)).unwrap();
    let mut cfg = config(emu.path());
    cfg.sensors = Some(22);
    cfg.calibration = Some(cal_file(22));
    let Err(e) = Glove::open(cfg) else {
        panic!("opened an 18-sensor glove as 22")
    };
    let msg = e.to_string();
    assert!(
        msg.contains("answered 18 sensors but the config says 22"),
        "{msg}"
    );
    assert!(msg.contains("glove-22.cal has 22 entries"), "{msg}");
    assert!(msg.contains("set sensors = 18"), "{msg}");
}

#[test]
fn a_glove_whose_records_do_not_match_its_answer_is_reported_silent() {
    // It says 22 but sends 18 bytes a record: no record ever parses.
    let mut b = GloveBehaviour::new(18);
    b.reported_sensors = 22;
    let emu = glove::spawn(b).unwrap();
    let mut cfg = config(emu.path());
    cfg.link.silence_timeout = Duration::from_millis(250);
    let mut g = Glove::open(cfg).unwrap();
    let (samples, errors) = collect(&mut g, 1, Duration::from_secs(1));
    assert!(samples.is_empty());
    let msg = errors.first().map(|e| e.to_string()).unwrap_or_default();
    assert!(
        msg.contains("stopped answering") && msg.contains("baud rate"),
        "{msg}"
    );
}

#[test]
fn a_port_with_no_glove_on_it_says_so() {
    // A FASTRAK where the glove should be: nothing answers `?S`.
    let emu = tracker::spawn(Default::default()).unwrap();
    let mut cfg = config(emu.path());
    cfg.link.answer_timeout = Duration::from_millis(200);
    let Err(e) = Glove::open(cfg) else {
        panic!("a tracker answered as a glove")
    };
    let msg = e.to_string();
    assert!(msg.contains("did not answer `?S`"), "{msg}");
}

#[test]
fn a_glove_switched_on_later_is_picked_up_by_read() {
    let emu = glove::spawn(GloveBehaviour::new(22)).unwrap();
    // `new` does not touch the port, so it works before the device exists...
    let missing = emu.path().with_file_name("not-yet");
    let mut g = Glove::new(config(&missing)).unwrap();
    let (samples, errors) = collect(&mut g, 1, Duration::from_millis(200));
    assert!(samples.is_empty());
    assert!(
        matches!(errors.first(), Some(DeviceError::Reconnecting { .. })),
        "{errors:?}"
    );
    // ...and `read` connects once it does.
    std::os::unix::fs::symlink(std::fs::read_link(emu.path()).unwrap(), &missing).unwrap();
    let (samples, _) = collect(&mut g, 5, Duration::from_secs(5));
    assert_eq!(samples.len(), 5);
    drop(g);
    let _ = std::fs::remove_file(&missing);
}

#[test]
fn a_glove_detached_from_its_interface_unit_is_named_as_such() {
    let mut b = GloveBehaviour::new(22);
    b.glove_detached = true;
    let emu = glove::spawn(b).unwrap();
    let mut cfg = config(emu.path());
    cfg.mode = GloveMode::Polled { rate_hz: 100.0 };
    cfg.link.silence_timeout = Duration::from_millis(250);
    let mut g = Glove::open(cfg).unwrap();
    let (samples, errors) = collect(&mut g, 1, Duration::from_millis(500));
    assert!(samples.is_empty());
    let msg = errors.first().map(|e| e.to_string()).unwrap_or_default();
    assert!(
        msg.contains("stopped answering")
            && msg.contains("no glove is plugged into the interface unit"),
        "{msg}"
    );
    assert!(g.stats().device_errors > 0);
}
