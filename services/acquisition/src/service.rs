//! The acquisition process: samples the source at its rate and publishes `glove` and
//! `tracker`, stamping each pair with one origin (the moment it entered the pipeline).

use common::bus::Bus;
use common::config::session::Source;
use common::config::Session;
use common::latency::{Metric, Reporter};
use common::stamp::sleep_until_ns;
use common::{monotonic_ns, shutdown, GloveSample, Stage, Stamp, Topic, TrackerSample};

use crate::scripted::{source_time_ns, ScriptedHand};

/// Runs until asked to stop.
pub fn run(session: &Session, bus: &Bus) -> Result<(), Box<dyn std::error::Error>> {
    let rate_hz = match &session.source {
        Source::Scripted { rate_hz } => *rate_hz,
        other => {
            return Err(format!(
                "{}: source kind \"{}\" is not available yet; use kind = \"scripted\"",
                session.file.display(),
                other.kind()
            )
            .into())
        }
    };
    let script = session.scene.hand.as_ref().ok_or_else(|| {
        format!(
            "{}: the scene has no [hand] for the scripted source",
            session.scene_file.display()
        )
    })?;
    let hand =
        ScriptedHand::new(script).map_err(|e| format!("{}: {e}", session.scene_file.display()))?;

    let mut glove = bus.outlet::<GloveSample>(Topic::Glove)?;
    let mut tracker = bus.outlet::<TrackerSample>(Topic::Tracker)?;
    let mut reporter = Reporter::new(Stage::Acquisition, bus.outlet(Topic::Latency)?);

    let start_ns = monotonic_ns();
    let period_ns = 1e9 / rate_hz;
    let mut k: u64 = 0;
    while !shutdown::requested() {
        let deadline = start_ns + (k as f64 * period_ns).round() as u64;
        sleep_until_ns(deadline);
        if shutdown::requested() {
            break;
        }
        let stamp = Stamp::at_origin(0, source_time_ns(k, rate_hz));
        let (g, t) = hand.samples_at(k as f64 / rate_hz, stamp);
        glove.publish(&g)?;
        let sent = tracker.publish(&t)?;
        reporter.recorder.record(
            Metric::Process,
            sent.publish_ns.saturating_sub(sent.origin_ns),
        );
        reporter.recorder.record(
            Metric::Origin,
            sent.publish_ns.saturating_sub(sent.origin_ns),
        );
        reporter.maybe_report(&[glove.counter(), tracker.counter()])?;
        k += 1;
    }
    reporter.finish(&[glove.counter(), tracker.counter()])?;
    Ok(())
}
