//! The kinematics process: one `hand` sample per `tracker` sample, with the newest glove
//! reading at the tracker's source time ([`crate::GloveHistory`]; docs/design.md, "Stamps and
//! latency"), keeping the older of the two origins; or one `hand` per `joints` sample from a
//! hand tracker. The samples become hands in [`HandStream`], as in `simulate --hand`. The loop
//! around it is the stage loop ([`common::node`]).

use std::time::Duration;

use common::bus::{Bus, BusError, Inlet, Outlet, Waiter};
use common::config::Session;
use common::node::{self, Counters, Pass, Task};
use common::{topics, Stage};

use crate::model::HandModel;
use crate::pairing::HandStream;

/// The kinematics stage: its ports and the hands it makes.
struct Kinematics {
    glove_in: Inlet<topics::Glove>,
    tracker_in: Inlet<topics::Tracker>,
    joints_in: Inlet<topics::Joints>,
    hand_out: Outlet<topics::Hand>,
    hands: HandStream,
}

impl Task for Kinematics {
    type Error = BusError;

    fn wait(&mut self, waiter: &mut Waiter, timeout: Duration) -> Result<(), BusError> {
        waiter.wait(&[&self.tracker_in, &self.joints_in], timeout)
    }

    fn work(&mut self, pass: &mut Pass<'_>) -> Result<(), BusError> {
        loop {
            let tracker = self.tracker_in.receive()?;
            let received = match &tracker {
                Some(t) => pass.arrived(&t.stamp),
                None => common::monotonic_ns(),
            };
            // A glove is sent before the tracker of the same instant: read the gloves after
            // taking each tracker (and once more when none is left), so that one published
            // just before it is never missed.
            while let Some(g) = self.glove_in.receive()? {
                pass.recorder.hop(&g.stamp, received);
                self.hands.glove(g.payload());
            }
            let Some(s) = tracker else {
                break;
            };
            let Some(hand) = self.hands.tracker(s.payload()) else {
                continue;
            };
            let sent = self.hand_out.publish(hand)?;
            pass.recorder.output(received, &sent);
        }
        // A hand tracker's joints: one hand per joints sample.
        while let Some(s) = self.joints_in.receive()? {
            let received = pass.arrived(&s.stamp);
            let sent = self.hand_out.publish(self.hands.joints(s.payload()))?;
            pass.recorder.output(received, &sent);
        }
        Ok(())
    }

    fn counters(&self) -> Counters {
        Counters::of([
            self.glove_in.counter(),
            self.tracker_in.counter(),
            self.joints_in.counter(),
            self.hand_out.counter(),
        ])
    }
}

/// Runs until asked to stop, then drains what its inputs still hold.
pub fn run(session: &Session, bus: &Bus) -> Result<(), BusError> {
    let mut kinematics = Kinematics {
        glove_in: bus.inlet()?,
        tracker_in: bus.inlet()?,
        joints_in: bus.inlet()?,
        hand_out: bus.outlet()?,
        hands: HandStream::new(HandModel::new(session.hand_model.clone())),
    };
    node::run(Stage::Kinematics, bus, session.wait, &mut kinematics)
}
