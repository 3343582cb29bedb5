//! The null source (`[source] kind = "null"`): a flat right hand held still, a glove and a
//! tracker sample at each of `[source] rate_hz`'s deadlines, until the session stops.
//!
//! It is for tests and for measurements that want a session's whole pipeline running with a
//! hand that never moves (what the stages cost when nothing happens), without a scene's script
//! or a trace. It is also the smallest whole source: adding it took its row in the stage table
//! (`common/src/stage.rs`), its stage among the glove and tracker topics' publishers in the
//! topic table, its `[source] kind`, and this crate, named once in `handblocks service`.

use std::time::Duration;

use common::bus::{Bus, BusError, Outlet, WaitStrategy, Waiter};
use common::config::session::Source;
use common::config::Session;
use common::node::{self, Counters, Launch, Pass, Task};
use common::stamp::sleep_until_ns;
use common::{monotonic_ns, shutdown, topics, GloveSample, Pose, Stage, Stamp, TrackerSample};

/// Where the still hand's wrist is, metres, in the world frame (y up): half a metre above the
/// origin, over the middle of most scenes' floor and clear of their blocks.
pub const WRIST: Pose = Pose {
    position: [0.0, 0.5, 0.0],
    rotation: [0.0, 0.0, 0.0, 1.0],
};

/// Why the null source stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum NullError {
    #[error(transparent)]
    Bus(#[from] BusError),
    /// The session's source is another kind (the message names the session file).
    #[error("{file}: source kind \"{kind}\" is not run by the null source")]
    NotThisSource { file: String, kind: &'static str },
}

/// The null stage's process, as `handblocks service null` runs it.
pub struct Process;

impl node::Process for Process {
    const STAGE: Stage = Stage::Null;
    type Error = NullError;
    fn run(session: &Session, bus: &Bus, _launch: &Launch) -> Result<(), NullError> {
        let Source::Null { rate_hz } = session.source else {
            return Err(NullError::NotThisSource {
                file: session.file.display().to_string(),
                kind: session.source.kind(),
            });
        };
        let mut still = Still::open(bus, rate_hz)?;
        // A source: it sleeps until its deadlines, not by the session's wait strategy.
        Ok(node::run(
            Stage::Null,
            bus,
            WaitStrategy::Event,
            &mut still,
        )?)
    }
}

/// The source time of deadline `k` at `rate_hz`, ns: its source's own timeline, as a device's.
pub fn source_time_ns(k: u64, rate_hz: f64) -> u64 {
    (k as f64 * 1e9 / rate_hz).ceil() as u64
}

/// The still hand's stage: one glove and one tracker sample per deadline, on absolute
/// deadlines so that the rate does not drift with the time each pass takes.
struct Still {
    glove: Outlet<topics::Glove>,
    tracker: Outlet<topics::Tracker>,
    rate_hz: f64,
    start_ns: u64,
    period_ns: f64,
    /// The next sample's index on the deadline grid (its seq).
    k: u64,
}

impl Still {
    fn open(bus: &Bus, rate_hz: f64) -> Result<Still, BusError> {
        let mut glove = bus.outlet::<topics::Glove>()?;
        let mut tracker = bus.outlet::<topics::Tracker>()?;
        // A restarted source goes on on its first start's deadline grid, at the first deadline
        // still ahead; the deadlines missed while it was down are seqs never sent.
        let (start_ns, resumed) = bus.session_epoch_ns(Stage::Null.name());
        let period_ns = 1e9 / rate_hz;
        let k = if resumed {
            (monotonic_ns().saturating_sub(start_ns) as f64 / period_ns).ceil() as u64
        } else {
            0
        };
        glove.skip_to(k);
        tracker.skip_to(k);
        Ok(Still {
            glove,
            tracker,
            rate_hz,
            start_ns,
            period_ns,
            k,
        })
    }
}

impl Task for Still {
    type Error = BusError;

    fn wait(&mut self, _: &mut Waiter, _: Duration) -> Result<(), BusError> {
        sleep_until_ns(self.start_ns + (self.k as f64 * self.period_ns).round() as u64);
        Ok(())
    }

    fn work(&mut self, pass: &mut Pass<'_>) -> Result<(), BusError> {
        if pass.stopping || shutdown::requested() {
            return Ok(());
        }
        let stamp = Stamp::at_origin(0, source_time_ns(self.k, self.rate_hz));
        // A flat hand: every sensor angle zero.
        self.glove.publish(&GloveSample {
            stamp,
            ..GloveSample::default()
        })?;
        let sent = self.tracker.publish(&TrackerSample {
            stamp,
            station: 1,
            side: 0,
            wrist: WRIST,
        })?;
        pass.recorder.source_output(&sent);
        self.k += 1;
        Ok(())
    }

    fn counters(&self) -> Counters {
        Counters::of([self.glove.counter(), self.tracker.counter()])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Source time is on the deadline grid and never runs backwards.
    #[test]
    fn source_time_follows_the_deadlines() {
        assert_eq!(source_time_ns(0, 120.0), 0);
        assert_eq!(source_time_ns(120, 120.0), 1_000_000_000);
        let times: Vec<u64> = (0..1000).map(|k| source_time_ns(k, 90.0)).collect();
        assert!(times.windows(2).all(|w| w[0] < w[1]));
    }
}
