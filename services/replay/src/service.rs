//! The replay process: publishes a recorded hand in place of acquisition, on the topics the
//! recording's source used (`glove` + `tracker` for one of our recordings of a glove session,
//! `joints` for a hand tracker or a CARL trace), or, for a shared world host's recording (no
//! source samples, every participant's hands), on `hand`, straight to the stepper.
//!
//! Each sample keeps its recorded source time (so the stepper's world is the same however fast
//! it is replayed) and is stamped with a new origin when it enters the pipeline (so latency
//! stays meaningful). At `speed` s > 0 the recorded timing is played s times faster; at
//! speed 0 samples go out as fast as the pipeline consumes them without loss: the replay keeps
//! at most [`IN_FLIGHT`] hand-making samples ahead of the newest world state.

use std::time::Duration;

use common::bus::{Bus, BusError, Inlet, Outlet, WaitStrategy, Waiter};
use common::config::session::Source;
use common::config::Session;
use common::node::{self, Counters, Pass, Task};
use common::stamp::sleep_until_ns;
use common::{monotonic_ns, shutdown, topics, Stage, Stamp, Topic};

use crate::trace::{HandTrace, SourceSample};

/// Hand-making samples the replay may be ahead of the stepper at speed 0 (well under every
/// buffer).
pub const IN_FLIGHT: u64 = 32;

/// Why the replay process stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    #[error("{0}")]
    Bus(#[from] BusError),
    /// The session's source is not a replay.
    #[error("{}: the replay process needs [source] kind = \"replay\"", session.display())]
    NotAReplay { session: std::path::PathBuf },
    /// The trace could not be read (the message names the file).
    #[error("{0}")]
    Trace(String),
}

/// Plays the trace, sends its final report and returns: the launcher then ends the session
/// (as `ros2 bag play` ends). With `loop = true` it plays the trace again and again, its
/// source times going on (each round starts one mean sample period after the last ended), until
/// asked to stop.
pub fn run(session: &Session, bus: &Bus) -> Result<(), ReplayError> {
    let Source::Replay {
        file,
        speed,
        offset,
        looped,
        topics,
        hands,
    } = &session.source
    else {
        return Err(ReplayError::NotAReplay {
            session: session.file.clone(),
        });
    };
    let mut trace = HandTrace::load_hands(file, *offset, *hands).map_err(ReplayError::Trace)?;
    if !topics.is_empty() {
        // `[source] topics`: only these are played (their seqs count only them).
        trace.samples.retain(|s| topics.contains(&s.topic()));
    }
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

    let glove_out = bus.outlet::<topics::Glove>()?;
    let tracker_out = bus.outlet::<topics::Tracker>()?;
    let joints_out = bus.outlet::<topics::Joints>()?;
    let hand_out = bus.outlet::<topics::Hand>()?;
    let world_in = bus.inlet::<topics::World>()?;
    let t0 = trace.first_source_time_ns();
    let span = trace
        .samples
        .last()
        .map_or(0, |s| s.source_time_ns().saturating_sub(t0));
    // Restarted ([supervise]), a replay at speed > 0 goes on on its first incarnation's
    // timeline: the samples due while it was down are skipped (never sent: its seq goes on
    // without them).
    let (start, resumed) = bus.session_epoch_ns("replay");
    let resume_after = if resumed && *speed > 0.0 {
        monotonic_ns().saturating_sub(start)
    } else {
        0
    };
    let mut replay = Replay {
        trace: &trace,
        speed: *speed,
        rounds: if *looped && !trace.samples.is_empty() {
            u64::MAX
        } else {
            1
        },
        // One round after another: the next starts a mean sample period after this one's end.
        round_ns: span + span / (trace.samples.len().max(2) as u64 - 1),
        t0,
        start,
        resume_after,
        skipped: [0; Topic::ALL.len()],
        skipping: resume_after > 0,
        next: (0, 0),
        due: None,
        answered: None,
        hands_sent: 0,
        glove_out,
        tracker_out,
        joints_out,
        hand_out,
        world_in,
    };
    // A source: it sleeps on its own deadlines, not by the session's wait strategy.
    node::run(Stage::Replay, bus, WaitStrategy::Event, &mut replay)
}

/// The replay stage: the trace, where it is in it, and its ports.
struct Replay<'t> {
    trace: &'t HandTrace,
    speed: f64,
    rounds: u64,
    round_ns: u64,
    t0: u64,
    /// The session's epoch for the replay, and (restarted) how far into it the dead one got.
    start: u64,
    resume_after: u64,
    skipped: [u64; Topic::ALL.len()],
    skipping: bool,
    /// The next sample: its round and index.
    next: (u64, usize),
    /// The sample the last wait was for, with its round's shift of source time.
    due: Option<(u64, &'t SourceSample)>,
    /// The newest hand seq a world state answered, and the hand-making samples sent.
    answered: Option<u64>,
    hands_sent: u64,
    glove_out: Outlet<topics::Glove>,
    tracker_out: Outlet<topics::Tracker>,
    joints_out: Outlet<topics::Joints>,
    /// A shared world host's recording: its hands, straight to the stepper.
    hand_out: Outlet<topics::Hand>,
    world_in: Inlet<topics::World>,
}

impl<'t> Replay<'t> {
    /// The next sample of the rounds, with its round's shift; None when all are played.
    fn take_next(&mut self) -> Option<(u64, &'t SourceSample)> {
        let (round, i) = self.next;
        if round >= self.rounds {
            return None;
        }
        let sample = self.trace.samples.get(i)?;
        self.next = if i + 1 < self.trace.samples.len() {
            (round, i + 1)
        } else {
            (round + 1, 0)
        };
        Some((round.saturating_mul(self.round_ns), sample))
    }

    /// Keeps up with the world's answers (speed 0 paces on them).
    fn read_answers(&mut self) -> Result<(), BusError> {
        while let Some(w) = self.world_in.receive()? {
            self.answered = Some(w.user_header().hand_seq);
        }
        Ok(())
    }
}

impl Task for Replay<'_> {
    type Error = ReplayError;

    /// Until the next sample is due: its time scaled by the speed, or at speed 0 until the
    /// world has answered all but [`IN_FLIGHT`] of the hands sent.
    fn wait(&mut self, _: &mut Waiter, _: Duration) -> Result<(), ReplayError> {
        while let Some((shift, sample)) = self.take_next() {
            if self.speed > 0.0 {
                let after = (sample.source_time_ns() + shift - self.t0) as f64 / self.speed;
                if (after as u64) < self.resume_after {
                    // Due before the restart: sent by the dead replay, or lost while none ran
                    // (each topic's seq counts its samples in order, sent or not).
                    self.skipped[sample.topic() as usize] += 1;
                    continue;
                }
                if std::mem::take(&mut self.skipping) {
                    self.glove_out.skip_to(self.skipped[Topic::Glove as usize]);
                    self.tracker_out
                        .skip_to(self.skipped[Topic::Tracker as usize]);
                    self.joints_out
                        .skip_to(self.skipped[Topic::Joints as usize]);
                    self.hand_out.skip_to(self.skipped[Topic::Hand as usize]);
                }
                sleep_until_ns(self.start + after as u64);
            } else if sample.makes_a_hand() {
                while self.answered.map_or(0, |a| a + 1) + IN_FLIGHT <= self.hands_sent
                    && !shutdown::requested()
                {
                    self.world_in.wait(Duration::from_millis(20))?;
                    self.read_answers()?;
                }
            }
            self.due = Some((shift, sample));
            return Ok(());
        }
        Ok(())
    }

    fn work(&mut self, pass: &mut Pass<'_>) -> Result<(), ReplayError> {
        // The trace is played: the final report tells the launcher.
        let Some((shift, sample)) = self.due.take() else {
            pass.end();
            return Ok(());
        };
        if pass.stopping || shutdown::requested() {
            return Ok(());
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
                self.glove_out.publish(&g)?
            }
            SourceSample::Tracker(mut t) => {
                t.stamp = restamp(&t.stamp);
                self.tracker_out.publish(&t)?
            }
            SourceSample::Joints(mut j) => {
                j.stamp = restamp(&j.stamp);
                self.joints_out.publish(&j)?
            }
            SourceSample::Hand(mut h) => {
                h.stamp = restamp(&h.stamp);
                self.hand_out.publish(&h)?
            }
        };
        if sample.makes_a_hand() {
            pass.recorder.source_output(&sent);
            self.hands_sent += 1;
        }
        self.read_answers()?;
        Ok(())
    }

    fn counters(&self) -> Counters {
        Counters::of([
            self.glove_out.counter(),
            self.tracker_out.counter(),
            self.joints_out.counter(),
            self.hand_out.counter(),
        ])
    }
}
