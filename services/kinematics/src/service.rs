//! The kinematics process: one `hand` sample per `tracker` sample, with the newest glove
//! reading at the tracker's source time ([`crate::GloveHistory`]; docs/design.md, "Stamps and
//! latency"), keeping the older of the two origins; or one `hand` per `joints` sample from a
//! hand tracker. The samples become hands in [`HandStream`], as in `simulate --hand`.

use std::time::Duration;

use common::bus::{Bus, WaitStrategy, Waiter};
use common::config::Session;
use common::latency::Reporter;
use common::{monotonic_ns, shutdown, topics, Stage};

use crate::model::HandModel;
use crate::pairing::HandStream;

/// How long to sleep without a sample before re-checking for a stop request.
const IDLE_WAIT: Duration = Duration::from_millis(50);

/// Runs until asked to stop, then drains what its inputs still hold.
pub fn run(session: &Session, bus: &Bus) -> Result<(), Box<dyn std::error::Error>> {
    let model = HandModel::new(session.hand_model.clone());
    let glove_in = bus.inlet::<topics::Glove>()?;
    let tracker_in = bus.inlet::<topics::Tracker>()?;
    let joints_in = bus.inlet::<topics::Joints>()?;
    let mut hand_out = bus.outlet::<topics::Hand>()?;
    let mut reporter = Reporter::new(Stage::Kinematics, bus.outlet::<topics::Latency>()?);

    let mut hands = HandStream::new(model);
    let mut waiter = Waiter::for_stage(session.wait);
    loop {
        let stopping = shutdown::requested();
        if !stopping {
            waiter.wait(&[&tracker_in, &joints_in], IDLE_WAIT)?;
        }
        let mut first = true;
        loop {
            let tracker = tracker_in.receive()?;
            let received = monotonic_ns();
            if let Some(t) = &tracker {
                if std::mem::take(&mut first) {
                    // When it was sent, not when we woke (see the stepper's).
                    waiter.arrived(t.stamp.publish_ns);
                }
            }
            // A glove is sent before the tracker of the same instant: read the gloves after
            // taking each tracker (and once more when none is left), so that one published
            // just before it is never missed.
            while let Some(g) = glove_in.receive()? {
                reporter.recorder.hop(&g.stamp, received);
                hands.glove(g.payload());
            }
            let Some(s) = tracker else {
                break;
            };
            reporter.recorder.hop(&s.stamp, received);
            let Some(hand) = hands.tracker(s.payload()) else {
                continue;
            };
            let sent = hand_out.publish(hand)?;
            reporter.recorder.output(received, &sent);
        }
        // A hand tracker's joints: one hand per joints sample.
        while let Some(s) = joints_in.receive()? {
            let received = monotonic_ns();
            if std::mem::take(&mut first) {
                waiter.arrived(s.stamp.publish_ns);
            }
            reporter.recorder.hop(&s.stamp, received);
            let sent = hand_out.publish(hands.joints(s.payload()))?;
            reporter.recorder.output(received, &sent);
        }
        let counters = [
            glove_in.counter(),
            tracker_in.counter(),
            joints_in.counter(),
            hand_out.counter(),
        ];
        if stopping {
            if waiter.strategy() == WaitStrategy::Adaptive {
                eprintln!("{}", waiter.finish("kinematics"));
            }
            return Ok(reporter.finish(&counters)?);
        }
        reporter.maybe_report(&counters)?;
    }
}
