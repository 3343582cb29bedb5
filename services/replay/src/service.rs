//! The replay process: publishes a recorded hand on `joints`, in place of acquisition.
//!
//! Each sample keeps its recorded source time (so the stepper's world is the same however fast
//! it is replayed) and is stamped with a new origin when it enters the pipeline (so latency
//! stays meaningful). At `speed` s > 0 the recorded timing is played s times faster; at
//! speed 0 samples go out as fast as the pipeline consumes them without loss: the replay keeps
//! at most [`IN_FLIGHT`] samples ahead of the newest world state.

use std::time::Duration;

use common::bus::Bus;
use common::config::session::Source;
use common::config::Session;
use common::latency::Reporter;
use common::stamp::sleep_until_ns;
use common::{monotonic_ns, shutdown, JointsSample, Stage, Topic, WorldSample};

use crate::carl::CarlTrace;

/// Samples the replay may be ahead of the stepper at speed 0 (well under every buffer).
pub const IN_FLIGHT: u64 = 32;

/// Runs until asked to stop; after the trace's end the hand holds still (nothing more is sent).
pub fn run(session: &Session, bus: &Bus) -> Result<(), Box<dyn std::error::Error>> {
    let Source::Replay {
        file,
        speed,
        offset,
    } = &session.source
    else {
        return Err(format!(
            "{}: the replay process needs [source] kind = \"replay\"",
            session.file.display()
        )
        .into());
    };
    let trace = CarlTrace::load(file)?;
    if let Some(d) = &trace.damage {
        eprintln!(
            "handblocks replay: warning: {d}; replaying the {} samples before it",
            trace.samples.len()
        );
    }
    let mut samples = Vec::new();
    trace.joints(*offset, &mut samples);

    let mut joints_out = bus.outlet::<JointsSample>(Topic::Joints)?;
    let world_in = bus.inlet::<WorldSample>(Topic::World)?;
    let mut reporter = Reporter::new(Stage::Replay, bus.outlet(Topic::Latency)?);
    let mut answered: Option<u64> = None; // the newest hand seq a world state answered
    let start = monotonic_ns();
    for (k, sample) in samples.iter().enumerate() {
        if *speed > 0.0 {
            sleep_until_ns(start + (sample.stamp.source_time_ns as f64 / speed) as u64);
        } else {
            while answered.map_or(0, |a| a + 1) + IN_FLIGHT <= k as u64 && !shutdown::requested() {
                world_in.wait(Duration::from_millis(20))?;
                while let Some(w) = world_in.receive()? {
                    answered = Some(w.hand_seq);
                }
            }
        }
        if shutdown::requested() {
            break;
        }
        let mut s = *sample;
        s.stamp.origin_ns = monotonic_ns();
        let sent = joints_out.publish(&s)?;
        reporter.recorder.source_output(&sent);
        // Keep up with the world's answers (speed 0 paces on them).
        while let Some(w) = world_in.receive()? {
            answered = Some(w.hand_seq);
        }
        reporter.maybe_report(&[joints_out.counter()])?;
    }
    while !shutdown::requested() {
        std::thread::sleep(Duration::from_millis(20));
        while world_in.receive()?.is_some() {}
        reporter.maybe_report(&[joints_out.counter()])?;
    }
    reporter.finish(&[joints_out.counter()])?;
    Ok(())
}
