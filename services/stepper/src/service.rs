//! The stepper process: runs the block world on the hand's timeline and publishes one `world`
//! sample per `hand` sample.
//!
//! Time (docs/model.md, "Conventions") is the library's [`Timeline`], the one `simulate` replays
//! a trace with: steps follow the hand's source time, never a wall clock, so the same hand
//! samples always give bit-identical worlds, live or replayed. This module is only the process
//! shell around it: the bus, the latency report and the outcome files.

use std::time::Duration;

use crate::model::Model;
use crate::timeline::Timeline;
use common::bus::Bus;
use common::bus::{WaitStrategy, Waiter};
use common::config::Session;
use common::latency::Reporter;
use common::{monotonic_ns, shutdown, topics, HandSample, Stage, Stamp};

const IDLE_WAIT: Duration = Duration::from_millis(50);
/// Events kept for the session's outcome (grasps, releases, landings: a few per second); past
/// this many the later ones are counted, not kept, so keeping one never allocates.
const OUTCOME_EVENTS: usize = 4096;

/// Runs until asked to stop, then drains what its input still holds.
pub fn run(session: &Session, bus: &Bus) -> Result<(), Box<dyn std::error::Error>> {
    run_with_outcome(session, bus, None)
}

/// [`run`], and when it stops, writes the world's outcome (what `simulate` prints: each
/// block's final pose and mode, the events) as `outcome.txt` and `outcome.json` into
/// `outcome_dir` (the launcher prints it after the session).
pub fn run_with_outcome(
    session: &Session,
    bus: &Bus,
    outcome_dir: Option<&std::path::Path>,
) -> Result<(), Box<dyn std::error::Error>> {
    let mut world = Model::new(&session.scene)?;
    let mut events: Vec<crate::world::Event> = Vec::with_capacity(OUTCOME_EVENTS);
    let mut events_not_kept = 0u64;
    let hand_in = bus.inlet::<topics::Hand>()?;
    let mut world_out = bus.slice_outlet::<topics::World>()?;
    if world.block_count() > world_out.capacity() {
        return Err(format!(
            "the scene has {} blocks but this session's world samples hold {} (every process \
             of a session sizes its bus from the same scene)",
            world.block_count(),
            world_out.capacity()
        )
        .into());
    }
    let mut reporter = Reporter::new(Stage::Stepper, bus.outlet::<topics::Latency>()?);
    let mut timeline = Timeline::new(session.scene.world.step_hz);
    let mut clock_jumps_told = 0;
    let mut waiter = Waiter::new(session.wait);
    loop {
        let stopping = shutdown::requested();
        if !stopping {
            waiter.wait(&[&hand_in], IDLE_WAIT)?;
        }
        let mut first = true;
        while let Some(s) = hand_in.receive()? {
            let received = monotonic_ns();
            if std::mem::take(&mut first) {
                // When it was sent, not when we woke: a late wake-up would shift the next
                // predicted arrival late by as much.
                waiter.arrived(s.stamp.publish_ns);
            }
            reporter.recorder.hop(&s.stamp, received);
            let hand: &HandSample = s.payload();
            // A hand the model cannot use (NaN, bad counts) brings no steps: the world holds.
            if crate::hand::is_usable(hand) {
                if !timeline.started() {
                    // The first hand is the previous one of the first step (P- of R1, R2).
                    world.set_previous_hand(Some(hand));
                }
                timeline.advance(hand, |h| {
                    world.step(h);
                    for e in world.events() {
                        if events.len() < OUTCOME_EVENTS {
                            events.push(*e);
                        } else {
                            events_not_kept += 1;
                        }
                    }
                });
                if timeline.jumps() != clock_jumps_told {
                    // Rare (a clock reset, a damaged trace): said when it happens.
                    clock_jumps_told = timeline.jumps();
                    eprintln!(
                        "handblocks stepper: the hand's source clock jumped to {} ns at seq {} \
                         (more than {} s from the sample before): world time went on one step",
                        hand.stamp.source_time_ns,
                        hand.stamp.seq,
                        crate::timeline::MAX_CATCH_UP_NS / 1_000_000_000
                    );
                }
            }
            // Written straight into the sample's shared memory: no copy of the world.
            let sent = world_out.publish_with(
                world.block_count(),
                |header| {
                    world.write_header(header);
                    header.stamp = Stamp::derived(0, &hand.stamp);
                    header.hand_seq = hand.stamp.seq;
                },
                |i| world.block_state(i),
            )?;
            reporter.recorder.output(received, &sent);
        }
        let counters = [hand_in.counter(), world_out.counter()];
        if stopping {
            if waiter.strategy() == WaitStrategy::Adaptive {
                eprintln!(
                    "handblocks stepper: adaptive wait: {} of {} arrivals found in the poll window",
                    waiter.in_window, waiter.arrivals
                );
            }
            if let Some(dir) = outcome_dir {
                write_outcome(
                    dir,
                    &world,
                    session,
                    &events,
                    events_not_kept,
                    timeline.jumps(),
                );
            }
            return Ok(reporter.finish(&counters)?);
        }
        reporter.maybe_report(&counters)?;
    }
}

fn write_outcome(
    dir: &std::path::Path,
    world: &Model,
    session: &Session,
    events: &[crate::world::Event],
    not_kept: u64,
    clock_jumps: u64,
) {
    let mut report = crate::simulate::outcome(world, &session.scene, events);
    report.clock_jumps = clock_jumps;
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
