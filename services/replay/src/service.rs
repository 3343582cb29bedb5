//! The replay process: publishes a recorded hand in place of acquisition, on the topics the
//! recording's source used (`glove` + `tracker` for one of our recordings of a glove session,
//! `joints` for a hand tracker or a CARL trace).
//!
//! Each sample keeps its recorded source time (so the stepper's world is the same however fast
//! it is replayed) and is stamped with a new origin when it enters the pipeline (so latency
//! stays meaningful). At `speed` s > 0 the recorded timing is played s times faster; at
//! speed 0 samples go out as fast as the pipeline consumes them without loss: the replay keeps
//! at most [`IN_FLIGHT`] hand-making samples ahead of the newest world state.

use std::time::Duration;

use common::bus::Bus;
use common::config::session::Source;
use common::config::Session;
use common::latency::Reporter;
use common::stamp::sleep_until_ns;
use common::{monotonic_ns, shutdown, topics, Stage, Stamp, Topic};

use crate::trace::{HandTrace, SourceSample};

/// Hand-making samples the replay may be ahead of the stepper at speed 0 (well under every
/// buffer).
pub const IN_FLIGHT: u64 = 32;

/// Plays the trace, sends its final report and returns: the launcher then ends the session
/// (as `ros2 bag play` ends). With `loop = true` it plays the trace again and again, its
/// source times going on (each round starts one mean sample period after the last ended), until
/// asked to stop.
pub fn run(session: &Session, bus: &Bus) -> Result<(), Box<dyn std::error::Error>> {
    let Source::Replay {
        file,
        speed,
        offset,
        looped,
    } = &session.source
    else {
        return Err(format!(
            "{}: the replay process needs [source] kind = \"replay\"",
            session.file.display()
        )
        .into());
    };
    let trace = HandTrace::load(file, *offset)?;
    for w in &trace.warnings {
        eprintln!("handblocks replay: warning: {w}");
    }
    if !trace.warnings.is_empty() {
        eprintln!(
            "handblocks replay: replaying the {} good samples of {}",
            trace.samples.len(),
            file.display()
        );
    }

    let mut glove_out = bus.outlet::<topics::Glove>()?;
    let mut tracker_out = bus.outlet::<topics::Tracker>()?;
    let mut joints_out = bus.outlet::<topics::Joints>()?;
    let world_in = bus.inlet::<topics::World>()?;
    let mut reporter = Reporter::new(Stage::Replay, bus.outlet::<topics::Latency>()?);
    let mut answered: Option<u64> = None; // the newest hand seq a world state answered
    let mut hands_sent: u64 = 0;
    let t0 = trace.first_source_time_ns();
    let span = trace
        .samples
        .last()
        .map_or(0, |s| s.source_time_ns().saturating_sub(t0));
    // One round after another: the next starts a mean sample period after this one's end.
    let round_ns = span + span / (trace.samples.len().max(2) as u64 - 1);
    // Restarted ([supervise]), a replay at speed > 0 goes on on its first incarnation's
    // timeline: the samples due while it was down are skipped (never sent: its seq goes on
    // without them).
    let (start, resumed) = bus.session_epoch_ns("replay");
    let resume_after = if resumed && *speed > 0.0 {
        monotonic_ns().saturating_sub(start)
    } else {
        0
    };
    let mut skipped = [0u64; Topic::ALL.len()];
    let mut skipping = resume_after > 0;
    let rounds = if *looped && !trace.samples.is_empty() {
        u64::MAX
    } else {
        1
    };
    let samples = (0..rounds)
        .take_while(|_| !shutdown::requested())
        .flat_map(|round| {
            trace
                .samples
                .iter()
                .map(move |s| (round.saturating_mul(round_ns), s))
        });
    for (shift, sample) in samples {
        if *speed > 0.0 {
            let after = (sample.source_time_ns() + shift - t0) as f64 / speed;
            if (after as u64) < resume_after {
                // Due before the restart: sent by the dead replay, or lost while none ran
                // (each topic's seq counts its samples in order, sent or not).
                skipped[sample.topic() as usize] += 1;
                continue;
            }
            if std::mem::take(&mut skipping) {
                glove_out.skip_to(skipped[Topic::Glove as usize]);
                tracker_out.skip_to(skipped[Topic::Tracker as usize]);
                joints_out.skip_to(skipped[Topic::Joints as usize]);
            }
            sleep_until_ns(start + after as u64);
        } else if sample.makes_a_hand() {
            while answered.map_or(0, |a| a + 1) + IN_FLIGHT <= hands_sent && !shutdown::requested()
            {
                world_in.wait(Duration::from_millis(20))?;
                while let Some(w) = world_in.receive()? {
                    answered = Some(w.user_header().hand_seq);
                }
            }
        }
        if shutdown::requested() {
            break;
        }
        let origin = monotonic_ns();
        let restamp = |s: &Stamp| Stamp {
            origin_ns: origin,
            source_time_ns: s.source_time_ns + shift,
            ..*s
        };
        let sent = match *sample {
            SourceSample::Glove(mut g) => {
                g.stamp = restamp(&g.stamp);
                glove_out.publish(&g)?
            }
            SourceSample::Tracker(mut t) => {
                t.stamp = restamp(&t.stamp);
                tracker_out.publish(&t)?
            }
            SourceSample::Joints(mut j) => {
                j.stamp = restamp(&j.stamp);
                joints_out.publish(&j)?
            }
        };
        if sample.makes_a_hand() {
            reporter.recorder.source_output(&sent);
            hands_sent += 1;
        }
        // Keep up with the world's answers (speed 0 paces on them).
        while let Some(w) = world_in.receive()? {
            answered = Some(w.user_header().hand_seq);
        }
        reporter.maybe_report(&[
            glove_out.counter(),
            tracker_out.counter(),
            joints_out.counter(),
        ])?;
    }
    // The trace is played (or the session stops): the final report tells the launcher.
    reporter.finish(&[
        glove_out.counter(),
        tracker_out.counter(),
        joints_out.counter(),
    ])?;
    Ok(())
}
