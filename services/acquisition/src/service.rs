//! The acquisition process: samples the source at its rate and publishes `glove` and
//! `tracker`, stamping each pair with one origin (the moment it entered the pipeline).

use std::time::Duration;

use common::bus::{Bus, Outlet};
use common::config::session::Source;
use common::config::Session;
use common::latency::Reporter;
use common::stamp::sleep_until_ns;
use common::{monotonic_ns, shutdown, topics, Stage, Stamp};

use crate::devices::{DeviceEvent, DeviceReaders, Glove, GloveConfig, Tracker, TrackerConfig};
use crate::scripted::{source_time_ns, ScriptedHand};

/// Runs until asked to stop.
pub fn run(session: &Session, bus: &Bus) -> Result<(), Box<dyn std::error::Error>> {
    match &session.source {
        Source::Scripted { rate_hz } => run_scripted(session, bus, *rate_hz),
        Source::Devices { glove, tracker } => run_devices(bus, glove, tracker),
        other => Err(format!(
            "{}: source kind \"{}\" is not run by the acquisition process",
            session.file.display(),
            other.kind()
        )
        .into()),
    }
}

/// Publishes what a driver delivered (an error is said, not published).
fn publish_device_event(
    ev: DeviceEvent,
    glove_out: &mut Outlet<topics::Glove>,
    tracker_out: &mut Outlet<topics::Tracker>,
    reporter: &mut Reporter,
) -> Result<(), Box<dyn std::error::Error>> {
    match ev {
        DeviceEvent::Glove(g) => {
            let sent = glove_out.publish(&g)?;
            reporter.recorder.source_output(&sent);
        }
        DeviceEvent::Tracker(t) => {
            let sent = tracker_out.publish(&t)?;
            reporter.recorder.source_output(&sent);
        }
        DeviceEvent::Error(e) => eprintln!("handblocks acquisition: {e}"),
    }
    Ok(())
}

/// A CyberGlove and a FASTRAK: each driver reads on its own thread; this loop stamps and
/// publishes what they deliver and reports device errors without stopping (the drivers
/// reconnect by themselves).
fn run_devices(
    bus: &Bus,
    glove: &GloveConfig,
    tracker: &TrackerConfig,
) -> Result<(), Box<dyn std::error::Error>> {
    // The session read and checked the settings when it loaded; both devices share one
    // timeline, starting now (or, restarted, when the first incarnation started).
    let (epoch_ns, _) = bus.session_epoch_ns("acquisition");
    let gc = GloveConfig {
        epoch_ns,
        ..glove.clone()
    };
    let tc = TrackerConfig {
        epoch_ns,
        ..tracker.clone()
    };
    let mut glove_out = bus.outlet::<topics::Glove>()?;
    let mut tracker_out = bus.outlet::<topics::Tracker>()?;
    let mut reporter = Reporter::new(Stage::Acquisition, bus.outlet::<topics::Latency>()?);
    // `new` checks the configuration and connects on the first read, so a device that is not
    // there yet (or is unplugged) is reported and retried instead of failing the session.
    let readers = DeviceReaders::spawn(Some(Glove::new(gc)?), Some(Tracker::new(tc)?))?;
    while !shutdown::requested() {
        if let Some(ev) = readers.recv_timeout(Duration::from_millis(50)) {
            publish_device_event(ev, &mut glove_out, &mut tracker_out, &mut reporter)?;
        }
        reporter.maybe_report(&[glove_out.counter(), tracker_out.counter()])?;
    }
    // What the drivers read as the session stopped is published too: a driver's count of
    // samples is what was published.
    let mut last_error = None;
    let stats = readers.stop_delivering(|ev| {
        if let Err(e) = publish_device_event(ev, &mut glove_out, &mut tracker_out, &mut reporter) {
            last_error.get_or_insert(e);
        }
    });
    if let Some(e) = last_error {
        return Err(e);
    }
    reporter.set_devices([
        stats.glove.device_counters(1),
        stats.tracker.device_counters(2),
    ]);
    if stats.dropped > 0 {
        eprintln!("handblocks acquisition: {} device samples arrived faster than they could be published and were dropped", stats.dropped);
    }
    reporter.finish(&[glove_out.counter(), tracker_out.counter()])?;
    Ok(())
}

/// The scripted hand: the scene's keyframes sampled at `rate_hz` on absolute deadlines.
fn run_scripted(
    session: &Session,
    bus: &Bus,
    rate_hz: f64,
) -> Result<(), Box<dyn std::error::Error>> {
    let script = session.scene.hand.as_ref().ok_or_else(|| {
        format!(
            "{}: the scene has no [hand] for the scripted source",
            session.scene_file.display()
        )
    })?;
    let hand =
        ScriptedHand::new(script).map_err(|e| format!("{}: {e}", session.scene_file.display()))?;

    let mut glove = bus.outlet::<topics::Glove>()?;
    let mut tracker = bus.outlet::<topics::Tracker>()?;
    let mut reporter = Reporter::new(Stage::Acquisition, bus.outlet::<topics::Latency>()?);

    // The session's timeline: a restarted source goes on on its first incarnation's deadline
    // grid, at the first deadline still ahead, so source time (and the hand the script gives)
    // goes on where it would have been. Sample k has seq k: the deadlines missed while it was
    // down are seqs never sent, which every reader counts as lost.
    let (start_ns, resumed) = bus.session_epoch_ns("acquisition");
    let period_ns = 1e9 / rate_hz;
    let mut k: u64 = if resumed {
        (monotonic_ns().saturating_sub(start_ns) as f64 / period_ns).ceil() as u64
    } else {
        0
    };
    glove.skip_to(k);
    tracker.skip_to(k);
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
        reporter.recorder.source_output(&sent);
        reporter.maybe_report(&[glove.counter(), tracker.counter()])?;
        k += 1;
    }
    reporter.finish(&[glove.counter(), tracker.counter()])?;
    Ok(())
}
