//! The renderer process loop.

use std::time::Duration;

use common::bus::Bus;
use common::config::session::RenderMode;
use common::config::Session;
use common::latency::{Metric, Reporter};
use common::{monotonic_ns, shutdown, FrameSample, HandSample, Stage, Stamp, Topic, WorldSample};

/// Runs until asked to stop.
pub fn run(session: &Session, bus: &Bus) -> Result<(), Box<dyn std::error::Error>> {
    let world_in = bus.inlet::<WorldSample>(Topic::World)?;
    let hand_in = bus.inlet::<HandSample>(Topic::Hand)?;
    let mut frame_out = bus.outlet::<FrameSample>(Topic::Frame)?;
    let mut reporter = Reporter::new(Stage::Renderer, bus.outlet(Topic::Latency)?);
    let drawing = session.renderer.mode != RenderMode::Off;

    let period_ns = (1e9 / session.budget.frame_hz) as u64;
    let mut next_frame = monotonic_ns() + period_ns;
    let mut newest: Option<Stamp> = None; // the newest world's stamp
    let mut superseded = 0u64;
    let mut hand = HandSample::default();
    loop {
        let stopping = shutdown::requested();
        let now = monotonic_ns();
        if !stopping && now < next_frame {
            world_in.wait(Duration::from_nanos(next_frame - now))?;
        }
        while let Some(s) = world_in.receive()? {
            let received = monotonic_ns();
            reporter.recorder.hop(&s.stamp, received);
            if newest.is_some() {
                superseded += 1;
            }
            newest = Some(s.stamp);
        }
        while let Some(s) = hand_in.receive()? {
            reporter.recorder.hop(&s.stamp, monotonic_ns());
            hand = *s.payload();
        }
        let now = monotonic_ns();
        if now >= next_frame || stopping {
            // Pace on absolute deadlines; after a long stall, start afresh instead of bursting.
            next_frame = if now > next_frame + period_ns {
                now + period_ns
            } else {
                next_frame + period_ns
            };
            if let Some(stamp) = newest.take() {
                let started = monotonic_ns();
                if drawing {
                    draw(&hand);
                }
                let done = monotonic_ns();
                let frame = FrameSample {
                    stamp: Stamp::derived(0, &stamp),
                    world_seq: stamp.seq,
                    render_ns: done - started,
                    origin_to_photon_ns: done.saturating_sub(stamp.origin_ns),
                    skipped_worlds: std::mem::take(&mut superseded),
                };
                reporter
                    .recorder
                    .record(Metric::Photon, frame.origin_to_photon_ns);
                let sent = frame_out.publish(&frame)?;
                // The renderer's own work is the frame, not the wait for its deadline.
                reporter
                    .recorder
                    .record(Metric::Process, sent.publish_ns.saturating_sub(started));
                reporter.recorder.record(
                    Metric::Origin,
                    sent.publish_ns.saturating_sub(sent.origin_ns),
                );
            }
        }
        let counters = [world_in.counter(), hand_in.counter(), frame_out.counter()];
        if stopping {
            return Ok(reporter.finish(&counters)?);
        }
        reporter.maybe_report(&counters)?;
    }
}

/// Drawing is issue 6 (wgpu); until then a frame costs only its bookkeeping.
fn draw(_hand: &HandSample) {}
