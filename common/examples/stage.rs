//! A stage on the bus, the smallest whole one: the first thing to read before writing a
//! process of your own. It opens a session of its own, publishes glove samples on one node and
//! reads them on another, as two stages would in two processes, and removes what it made.
//!
//! ```text
//! cargo run --release -p common --example stage
//! ```
//!
//! What a real stage adds (see `services/kinematics/src/service.rs`, the shortest): it runs
//! until `common::shutdown::requested()`, sends a latency report about once a second and a
//! final one when it stops (`common::latency::Reporter`), and the launcher starts it, with the
//! session's bus id, as `handblocks service NAME`.

use std::time::Duration;

use common::bus::{wait_any, Bus, BusConfig, Wakeable};
use common::{topics, GloveSample, Stage};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // A session's resources: its own /dev/shm prefix and private folder, so that this
    // example never meets a running session.
    let config = BusConfig::for_session(&format!("example{}", std::process::id()))?;
    {
        // The launcher creates every topic of the table first, with its sizing.
        let launcher = Bus::open(&config, "launcher")?;
        let _services = launcher.create_services()?;

        // A reader attaches before its source starts (the launcher's order), so that it
        // misses nothing.
        // A stage's node may open only the ports the topic table grants it.
        let kinematics = Bus::for_stage(&config, Stage::Kinematics)?;
        let glove_in = kinematics.inlet::<topics::Glove>()?;

        // The source: its outlet stamps each sample's seq and publish time.
        let acquisition = Bus::for_stage(&config, Stage::Acquisition)?;
        let mut glove_out = acquisition.outlet::<topics::Glove>()?;
        for k in 0..5 {
            let mut sample = GloveSample::default();
            sample.stamp.source_time_ns = k * 8_333_333; // a 120 Hz glove
            sample.stamp.origin_ns = common::monotonic_ns();
            glove_out.publish(&sample)?;
        }

        // The reader sleeps on its inlets' events, then drains each (zero-copy: a sample
        // reads the publisher's memory).
        let inlets: [&dyn Wakeable; 1] = [&glove_in];
        wait_any(&inlets, Duration::from_millis(100))?;
        while let Some(sample) = glove_in.receive()? {
            let stamp = sample.payload().stamp;
            println!(
                "glove seq {} (source time {:.1} ms) arrived {} us after its publish",
                stamp.seq,
                stamp.source_time_ns as f64 / 1e6,
                (common::monotonic_ns() - stamp.publish_ns) / 1000
            );
        }
        let counted = glove_in.counter();
        println!(
            "received {} samples, {} missing from the seqs; the outlet sent {}",
            counted.count,
            counted.gaps,
            glove_out.counter().count
        );
    }
    // Every port and node is closed. What the session left in /dev/shm and its folder, removed (the launcher's last step).
    config.remove_resources()?;
    Ok(())
}
