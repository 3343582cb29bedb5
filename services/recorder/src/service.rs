//! The recorder process: sleeps on every topic's event, writes each sample as it comes into
//! the session's MCAP recording, and reports per topic what it received and the gaps in
//! sequence numbers (the launcher puts them in the session report).
//!
//! A chunk of the recording is handed to the operating system as soon as it closes (every
//! 1 MiB or 0.5 s), so a crash of any process, this one included, loses at most the open chunk.

use std::time::Duration;

use common::bus::{wait_any, Bus, Inlet, Stamped};
use common::config::Session;
use common::latency::Reporter;
use common::{
    monotonic_ns, shutdown, FrameSample, GloveSample, HandSample, JointsSample, Stage, Topic,
    TrackerSample, WorldSample,
};

use recording::RecordingWriter;

const IDLE_WAIT: Duration = Duration::from_millis(50);

fn drain<T: Stamped>(
    inlet: &Inlet<T>,
    log: &mut Option<RecordingWriter>,
    reporter: &mut Reporter,
) -> Result<(), Box<dyn std::error::Error>> {
    while let Some(s) = inlet.receive()? {
        let received = monotonic_ns();
        reporter.recorder.hop(s.stamp(), received);
        if let Some(log) = log {
            log.write(inlet.topic(), s.payload())?;
        }
        let done = monotonic_ns();
        reporter
            .recorder
            .record(common::latency::Metric::Process, done - received);
        reporter.recorder.record(
            common::latency::Metric::Origin,
            done.saturating_sub(s.stamp().origin_ns),
        );
    }
    Ok(())
}

/// Runs until asked to stop, then drains every input.
pub fn run(session: &Session, bus: &Bus) -> Result<(), Box<dyn std::error::Error>> {
    let mut log = match &session.recorder.file {
        Some(path) => {
            // The recording names the session it came from (`handblocks inspect` shows it).
            let name = |p: &std::path::Path| {
                std::fs::canonicalize(p)
                    .unwrap_or_else(|_| p.to_path_buf())
                    .display()
                    .to_string()
            };
            let about = [
                ("session", name(&session.file)),
                ("scene", name(&session.scene_file)),
                ("source", session.source.kind().to_string()),
            ];
            Some(
                RecordingWriter::create_with(path, &about)
                    .map_err(|e| format!("cannot record: {e}"))?,
            )
        }
        None => None,
    };
    let glove = bus.inlet::<GloveSample>(Topic::Glove)?;
    let tracker = bus.inlet::<TrackerSample>(Topic::Tracker)?;
    let joints = bus.inlet::<JointsSample>(Topic::Joints)?;
    let hand = bus.inlet::<HandSample>(Topic::Hand)?;
    let world = bus.inlet::<WorldSample>(Topic::World)?;
    let frame = bus.inlet::<FrameSample>(Topic::Frame)?;
    let mut reporter = Reporter::new(Stage::Recorder, bus.outlet(Topic::Latency)?);

    loop {
        let stopping = shutdown::requested();
        if !stopping {
            wait_any(
                &[&glove, &tracker, &joints, &hand, &world, &frame],
                IDLE_WAIT,
            )?;
        }
        drain(&glove, &mut log, &mut reporter)?;
        drain(&tracker, &mut log, &mut reporter)?;
        drain(&joints, &mut log, &mut reporter)?;
        drain(&hand, &mut log, &mut reporter)?;
        drain(&world, &mut log, &mut reporter)?;
        drain(&frame, &mut log, &mut reporter)?;
        let counters = [
            glove.counter(),
            tracker.counter(),
            joints.counter(),
            hand.counter(),
            world.counter(),
            frame.counter(),
        ];
        if stopping {
            if let Some(log) = log.take() {
                log.finish()?;
            }
            return Ok(reporter.finish(&counters)?);
        }
        reporter.maybe_report(&counters)?;
    }
}
