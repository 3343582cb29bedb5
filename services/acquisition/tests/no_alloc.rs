//! The read path allocates nothing per sample: after open and a few warm-up samples, reading
//! through a real tty (parse, calibrate or transform, stamp) makes no heap allocation on the
//! reading thread. Counted with a global allocator that tallies per thread.

use std::time::{Duration, Instant};

use acquisition::devices::{
    Format, Glove, GloveConfig, GloveMode, Orientation, ReadOutcome, Tracker, TrackerConfig,
    TrackerMode, Units,
};
use acquisition::emulator::glove::{self, GloveBehaviour};
use acquisition::emulator::tracker::{self, TrackerBehaviour};
use common::{GloveSample, TrackerSample};

#[global_allocator]
static GLOBAL: counting_alloc::Counting = counting_alloc::Counting;

/// Reads `n` samples and returns the allocations made meanwhile on this thread.
fn count<S>(n: usize, mut read: impl FnMut(&mut S) -> Option<bool>, sample: &mut S) -> u64 {
    let end = Instant::now() + Duration::from_secs(10);
    let before = counting_alloc::allocations();
    let mut got = 0;
    while got < n && Instant::now() < end {
        match read(sample) {
            Some(true) => got += 1,
            Some(false) => {}
            None => panic!("device error during the count"),
        }
    }
    let made = counting_alloc::allocations() - before;
    assert_eq!(got, n, "too few samples");
    made
}

#[test]
fn glove_reads_allocate_nothing() {
    for mode in [GloveMode::Streamed, GloveMode::Polled { rate_hz: 500.0 }] {
        let emu = glove::spawn(GloveBehaviour::new(22)).unwrap();
        let mut cfg = GloveConfig::new(emu.path());
        cfg.mode = mode;
        cfg.link.silence_timeout = Duration::from_secs(2);
        let mut g = Glove::open(cfg).unwrap();
        let mut s = GloveSample::default();
        let mut read = |s: &mut GloveSample| match g.read(s) {
            Ok(o) => Some(o == ReadOutcome::Sample),
            Err(_) => None,
        };
        count(5, &mut read, &mut s);
        assert_eq!(count(40, &mut read, &mut s), 0, "{mode:?}");
    }
}

#[test]
fn tracker_reads_allocate_nothing() {
    let cases = [
        (
            Format::Binary,
            Orientation::Quaternion,
            TrackerMode::Continuous,
        ),
        (Format::Ascii, Orientation::Euler, TrackerMode::Continuous),
        (
            Format::Ascii,
            Orientation::Quaternion,
            TrackerMode::Polled { rate_hz: 500.0 },
        ),
    ];
    for (format, orientation, mode) in cases {
        let mut b = TrackerBehaviour::new();
        b.stations = [true, true, false, false];
        let emu = tracker::spawn(b).unwrap();
        let mut cfg = TrackerConfig::new(emu.path());
        cfg.format = format;
        cfg.orientation = orientation;
        cfg.mode = mode;
        cfg.units = Units::Inches;
        cfg.link.silence_timeout = Duration::from_secs(2);
        let mut t = Tracker::open(cfg).unwrap();
        let mut s = TrackerSample::default();
        let mut read = |s: &mut TrackerSample| match t.read(s) {
            Ok(o) => Some(o == ReadOutcome::Sample),
            Err(_) => None,
        };
        count(5, &mut read, &mut s);
        assert_eq!(count(30, &mut read, &mut s), 0, "{format:?} {mode:?}");
    }
}
