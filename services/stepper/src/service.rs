//! The stepper process: runs the block world on the hand's timeline and publishes one `world`
//! sample per `hand` sample (with two hands, per frame: after its left, the frame's last).
//!
//! Time (docs/model.md, "Conventions") is the library's [`Timeline`], the one `simulate` replays
//! a trace with: steps follow the hand's source time, never a wall clock, so the same hand
//! samples always give bit-identical worlds, live or replayed. This module is only the process
//! shell around it: the bus, the latency report and the outcome files.
//!
//! Restarted by the launcher (issue 16, `[supervise]`), the stepper resumes exactly: the world
//! is a pure function of the scene and the hand samples taken, so a supervised stepper keeps
//! every hand it takes in the session's folder ([`HandLog`]), and a restarted one takes them
//! all again before its first live hand.
//!
//! Why not a snapshot of the world: the world is fully determined by the hands taken, so
//! taking them again is exact by construction, for both models, with no state of any stage
//! (contact sets, grasp histories, R14's sleeping sets, rapier's solver) to export and keep in
//! step with the model's code. The cost is the log's size (1144 bytes a sample, ~0.5 GB per
//! hour at 120 Hz) and a restart's time, which grows with the session and the scene's step
//! cost (grasp-throw, one block: 527 hands in 2.5 ms, so about 2 s after an hour at 120 Hz). Its world is then bit for bit the one the dead
//! stepper had (no block jumps), whatever the model (paper or precise) and whatever state its
//! stages keep; only the hands that arrived while no stepper ran are missing, and the
//! timeline steps across them as across any gap in a source.

use std::time::Duration;

use crate::hand_log::HandLog;
use crate::model::Model;
use crate::timeline::{HandFrame, HandFrames, Timeline};
use crate::world::WorldError;
use common::bus::{Bus, BusError, Inlet, Outlet, Waiter};
use common::config::Session;
use common::latency::Reporter;
use common::node::{self, Counters, Pass, Task};
use common::{monotonic_ns, topics, HandSample, Stage, Stamp};

/// Events kept for the session's outcome (grasps, releases, landings: a few per second); past
/// this many the later ones are counted, not kept, so keeping one never allocates.
const OUTCOME_EVENTS: usize = 4096;

/// Why the stepper process stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum StepperError {
    #[error("{0}")]
    Bus(#[from] BusError),
    /// The session's scene is not a world ([`Model::new`]).
    #[error("{0}")]
    Scene(#[source] WorldError),
    /// The scene has more blocks than the session's world samples hold.
    #[error(
        "the scene has {blocks} blocks but this session's world samples hold {capacity} \
         (every process of a session sizes its bus from the same scene)"
    )]
    WorldTooLarge { blocks: usize, capacity: usize },
    /// A supervised stepper's hand log could not be opened or written.
    #[error("{0}")]
    HandLog(String),
}

/// Runs until asked to stop, then drains what its input still holds.
pub fn run(session: &Session, bus: &Bus) -> Result<(), StepperError> {
    run_with_outcome(session, bus, None)
}

/// [`run`], and when it stops, writes the world's outcome (what `simulate` prints: each
/// block's final pose and mode, the events) as `outcome.txt` and `outcome.json` into
/// `outcome_dir` (the launcher prints it after the session).
pub fn run_with_outcome(
    session: &Session,
    bus: &Bus,
    outcome_dir: Option<&std::path::Path>,
) -> Result<(), StepperError> {
    let mut stepping = Stepping {
        world: Model::new(&session.scene).map_err(StepperError::Scene)?,
        timeline: Timeline::new(session.scene.world.step_hz),
        frames: HandFrames::new(),
        events: Vec::with_capacity(OUTCOME_EVENTS),
        events_not_kept: 0,
        clock_jumps_told: 0,
        refusals_told: 0,
    };
    let hand_in = bus.inlet::<topics::Hand>()?;
    let world_out = bus.slice_outlet::<topics::World>()?;
    if stepping.world.block_count() > world_out.capacity() {
        return Err(StepperError::WorldTooLarge {
            blocks: stepping.world.block_count(),
            capacity: world_out.capacity(),
        });
    }
    // Supervised: every hand taken is kept; restarted: the dead stepper's hands first.
    let log = if bus.is_supervised() {
        let path = bus.session_folder().join("stepper.hands");
        let (log, taken) = HandLog::open(&path).map_err(StepperError::HandLog)?;
        if bus.restart() > 0 {
            let started = monotonic_ns();
            for hand in &taken {
                stepping.take(hand, false);
            }
            eprintln!(
                "handblocks stepper: restart {}: resumed the world from the {} hand samples \
                 taken before (step {}, last hand seq {}) in {:.1} ms",
                bus.restart(),
                taken.len(),
                stepping.world.steps(),
                taken.last().map_or(-1, |h| h.stamp.seq as i64),
                (monotonic_ns() - started) as f64 / 1e6
            );
        }
        Some(log)
    } else {
        None
    };
    let mut stage = StepperStage {
        frame_origin_ns: None,
        hand_in,
        world_out,
        log,
        stepping,
        session,
        outcome_dir,
    };
    node::run(Stage::Stepper, bus, session.wait, &mut stage)
}

/// The stepper stage: its ports, its hand log and the world.
struct StepperStage<'s> {
    /// The oldest origin among the hands of the frame being gathered (two hands).
    frame_origin_ns: Option<u64>,
    hand_in: Inlet<topics::Hand>,
    world_out: Outlet<topics::World>,
    log: Option<HandLog>,
    stepping: Stepping,
    session: &'s Session,
    outcome_dir: Option<&'s std::path::Path>,
}

impl Task for StepperStage<'_> {
    type Error = StepperError;

    fn wait(&mut self, waiter: &mut Waiter, timeout: Duration) -> Result<(), StepperError> {
        Ok(waiter.wait(&[&self.hand_in], timeout)?)
    }

    fn work(&mut self, pass: &mut Pass<'_>) -> Result<(), StepperError> {
        while let Some(s) = self.hand_in.receive()? {
            let received = pass.arrived(&s.stamp);
            let hand: &HandSample = s.payload();
            if let Some(log) = &mut self.log {
                // Kept before it is taken: a world state this stepper may have published is
                // always one its restart rebuilds.
                log.append(hand)
                    .map_err(|e| StepperError::HandLog(e.to_string()))?;
            }
            self.stepping.take(hand, true);
            // The oldest origin of the frame this world answers (two hands: its right's).
            let origin_ns = self
                .frame_origin_ns
                .map_or(hand.stamp.origin_ns, |o| o.min(hand.stamp.origin_ns));
            if self.stepping.frames.waiting() {
                // The frame's right came and its left not yet: the world answers the frame
                // once it is whole (a world now would be the last frame's, stamped as this).
                self.frame_origin_ns = Some(origin_ns);
                continue;
            }
            self.frame_origin_ns = None;
            let world = &self.stepping.world;
            // Written straight into the sample's shared memory: no copy of the world.
            let sent = self.world_out.publish_with(
                world.block_count(),
                |header| {
                    world.write_header(header);
                    header.stamp = Stamp {
                        origin_ns,
                        ..Stamp::derived(0, &hand.stamp)
                    };
                    header.hand_seq = hand.stamp.seq;
                },
                |i| world.block_state(i),
            )?;
            pass.recorder.output(received, &sent);
        }
        Ok(())
    }

    fn counters(&self) -> Counters {
        Counters::of([self.hand_in.counter(), self.world_out.counter()])
    }

    fn stop(&mut self, _: &mut Reporter) -> Result<(), StepperError> {
        // A frame the source left incomplete (it stopped between a frame's two hands).
        self.stepping.flush();
        let stepping = &self.stepping;
        if stepping.frames.refused_hands > 0 {
            eprintln!(
                "handblocks stepper: {} hand samples refused (a value not finite, or out \
                 of range): the hand held its last good pose",
                stepping.frames.refused_hands
            );
        }
        if let Some(dir) = self.outcome_dir {
            write_outcome(
                dir,
                &stepping.world,
                self.session,
                &stepping.events,
                stepping.events_not_kept,
                stepping.timeline.jumps(),
                (stepping.frames.refused_hands, stepping.frames.first_refused),
            );
        }
        Ok(())
    }
}

/// The world on the hand's timeline, and what the session's outcome keeps of it.
struct Stepping {
    world: Model,
    timeline: Timeline,
    /// The hands taken, made into frames of both hands ([`HandFrames`]: a two-hand source's
    /// right and left of one time are one frame); its counts are the refused hands.
    frames: HandFrames,
    events: Vec<crate::world::Event>,
    events_not_kept: u64,
    clock_jumps_told: u64,
    refusals_told: u64,
}

impl Stepping {
    /// Takes one hand sample: the steps its frame brings, once the frame is complete (none for
    /// a hand the model cannot use, NaN or bad counts: it holds its last good pose). `tell`:
    /// say a jump of the source's clock or a refusal (a restart taking the dead stepper's hands
    /// again does not say them twice).
    fn take(&mut self, hand: &HandSample, tell: bool) {
        let Stepping {
            world,
            timeline,
            frames,
            events,
            events_not_kept,
            ..
        } = self;
        frames.push(hand, |frame| {
            Self::step(world, timeline, events, events_not_kept, frame)
        });
        if frames.refused_hands > self.refusals_told {
            if tell && self.refusals_told == 0 {
                if let Some((seq, why)) = frames.first_refused {
                    eprintln!(
                        "handblocks stepper: hand sample seq {seq} refused: {why} (the hand \
                         holds its last good pose; later refusals are counted)"
                    );
                }
            }
            self.refusals_told = frames.refused_hands;
        }
        if timeline.jumps() != self.clock_jumps_told {
            // Rare (a clock reset, a damaged trace): said when it happens.
            self.clock_jumps_told = timeline.jumps();
            if tell {
                eprintln!(
                    "handblocks stepper: the hand's source clock jumped to {} ns at seq {} \
                     (more than {} s from the sample before): world time went on one step",
                    hand.stamp.source_time_ns,
                    hand.stamp.seq,
                    crate::timeline::MAX_CATCH_UP_NS / 1_000_000_000
                );
            }
        }
    }

    /// Takes the frame being gathered, complete or not.
    fn flush(&mut self) {
        let Stepping {
            world,
            timeline,
            frames,
            events,
            events_not_kept,
            ..
        } = self;
        frames.flush(|frame| Self::step(world, timeline, events, events_not_kept, frame));
    }

    /// The steps one frame of hands brings.
    fn step(
        world: &mut Model,
        timeline: &mut Timeline,
        events: &mut Vec<crate::world::Event>,
        events_not_kept: &mut u64,
        frame: &HandFrame,
    ) {
        if !timeline.started() {
            // The first hands are the previous ones of the first step (P- of R1, R2).
            for (slot, hand) in frame.iter().enumerate() {
                if hand.is_some() || slot == 0 {
                    world.set_previous_hand_of(slot, hand.as_ref());
                }
            }
        }
        timeline.advance_hands(frame.each_ref().map(Option::as_ref), |h| {
            world.step_hands(h);
            for e in world.events() {
                if events.len() < OUTCOME_EVENTS {
                    events.push(*e);
                } else {
                    *events_not_kept += 1;
                }
            }
        });
    }
}

fn write_outcome(
    dir: &std::path::Path,
    world: &Model,
    session: &Session,
    events: &[crate::world::Event],
    not_kept: u64,
    clock_jumps: u64,
    (refused_hands, first_refused): (u64, Option<(u64, &'static str)>),
) {
    let mut report = crate::simulate::outcome(world, &session.scene, events);
    report.clock_jumps = clock_jumps;
    report.refused_hands = refused_hands;
    report.first_refused = first_refused;
    let mut text = report.to_text();
    if not_kept > 0 {
        text.push_str(&format!("  ... and {not_kept} later events, not kept\n"));
    }
    for (name, body) in [("outcome.txt", text), ("outcome.json", report.to_json())] {
        if let Err(e) = std::fs::write(dir.join(name), body) {
            eprintln!(
                "handblocks stepper: cannot write the outcome {}: {e}",
                dir.join(name).display()
            );
        }
    }
}
