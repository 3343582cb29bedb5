//! A stage on the bus, the smallest whole one: the first thing to read before writing a
//! process of your own. A stage is only its own work, a [`Task`]; the stage loop around it,
//! [`node::run`], is written once (common/src/node.rs): it sleeps until there may be work,
//! does it, sends a latency report about once a second and a final one when the stage stops.
//! This example opens a session of its own, publishes glove samples as the acquisition stage
//! would, runs a stage that reads and prints them, as the kinematics stage would in its own
//! process, and removes what it made.
//!
//! ```text
//! cargo run --release -p common --example stage
//! ```
//!
//! What a real stage adds (see `services/kinematics/src/service.rs`, the shortest): it
//! publishes what its work makes (`pass.recorder.output` records each output's latency), runs
//! until it is asked to stop (`common::shutdown`) rather than ending its own work, and the
//! launcher starts it, with the session's bus id, as `handblocks service NAME`.

use std::time::Duration;

use common::bus::{Bus, BusConfig, BusError, Inlet, WaitStrategy, Waiter};
use common::node::{self, Counters, Pass, Task};
use common::{topics, GloveSample, Stage};

/// Glove samples the source publishes, and the reader waits for.
const SAMPLES: u64 = 5;

/// The reading stage: its one port.
struct Reader {
    glove_in: Inlet<topics::Glove>,
}

impl Task for Reader {
    type Error = BusError;

    /// Sleeps on the inlet's events, at most `timeout`.
    fn wait(&mut self, waiter: &mut Waiter, timeout: Duration) -> Result<(), BusError> {
        waiter.wait(&[&self.glove_in], timeout)
    }

    /// Drains the inlet (zero-copy: a sample reads the publisher's memory).
    fn work(&mut self, pass: &mut Pass<'_>) -> Result<(), BusError> {
        while let Some(sample) = self.glove_in.receive()? {
            let stamp = sample.payload().stamp;
            // The hop (publish to now) goes into the stage's latency report.
            let received = pass.arrived(&stamp);
            println!(
                "glove seq {} (source time {:.1} ms) arrived {} us after its publish",
                stamp.seq,
                stamp.source_time_ns as f64 / 1e6,
                (received - stamp.publish_ns) / 1000
            );
        }
        // A real stage runs until asked to stop; this one's work is done with the last sample.
        if self.glove_in.counter().count >= SAMPLES {
            pass.end();
        }
        Ok(())
    }

    fn counters(&self) -> Counters {
        Counters::of([self.glove_in.counter()])
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // A session's resources: its own /dev/shm prefix and private folder, so that this
    // example never meets a running session.
    let config = BusConfig::for_session(&format!("example{}", std::process::id()))?;
    {
        // The launcher creates every topic of the table first, with its sizing.
        let launcher = Bus::open(&config, "launcher")?;
        let _services = launcher.create_services()?;

        // A reader attaches before its source starts (the launcher's order), so that it
        // misses nothing. A stage's node may open only the ports the topic table grants it.
        let kinematics = Bus::for_stage(&config, Stage::Kinematics)?;
        let mut reader = Reader {
            glove_in: kinematics.inlet()?,
        };

        // The source: its outlet stamps each sample's seq and publish time.
        let acquisition = Bus::for_stage(&config, Stage::Acquisition)?;
        let mut glove_out = acquisition.outlet::<topics::Glove>()?;
        for k in 0..SAMPLES {
            let mut sample = GloveSample::default();
            sample.stamp.source_time_ns = k * 8_333_333; // a 120 Hz glove
            sample.stamp.origin_ns = common::monotonic_ns();
            glove_out.publish(&sample)?;
        }

        // The stage's final report waits until the launcher has read it; this process is its
        // own launcher, and no one reads it.
        common::shutdown::release();
        // The stage loop: wait, work, report, until the work ends; then the final report.
        // `WaitStrategy::Event` sleeps on the inlets (a session's `[session] wait`).
        node::run(
            Stage::Kinematics,
            &kinematics,
            WaitStrategy::Event,
            &mut reader,
        )?;
        let counted = reader.glove_in.counter();
        println!(
            "received {} samples, {} missing from the seqs; the outlet sent {}",
            counted.count,
            counted.gaps,
            glove_out.counter().count
        );
    }
    // Every port and node is closed. What the session left in /dev/shm and its folder,
    // removed (the launcher's last step).
    config.remove_resources()?;
    Ok(())
}
