//! The acquisition process: samples the source at its rate and publishes `glove` and
//! `tracker`, stamping each pair with one origin (the moment it entered the pipeline).

use std::time::Duration;

use common::bus::{Bus, BusError, Outlet, WaitStrategy, Waiter};
use common::config::session::Source;
use common::config::Session;
use common::latency::{LatencyRecorder, Reporter};
use common::node::{self, Counters, Pass, Task};
use common::samples::DeviceKind;
use common::stamp::sleep_until_ns;
use common::{monotonic_ns, shutdown, topics, Stage, Stamp};

use crate::devices::{
    DeviceError, DeviceEvent, DeviceReaders, Glove, GloveConfig, Tracker, TrackerConfig,
};
use crate::scripted::{source_time_ns, ScriptedHand};

/// Why the acquisition process stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum AcquisitionError {
    #[error("{0}")]
    Bus(#[from] BusError),
    /// The session's source is not one the acquisition process runs (its message names it).
    #[error("{0}")]
    NotThisSource(String),
    /// The scene's hand script cannot be played (the message names the scene).
    #[error("{0}")]
    Script(String),
    /// A device's configuration is refused.
    #[error("{0}")]
    Device(#[source] DeviceError),
    /// The device reader threads could not be started.
    #[error("{0}")]
    Threads(#[source] std::io::Error),
}

/// Runs until asked to stop.
pub fn run(session: &Session, bus: &Bus) -> Result<(), AcquisitionError> {
    match &session.source {
        Source::Scripted { rate_hz } => run_scripted(session, bus, *rate_hz),
        Source::Devices { glove, tracker } => run_devices(bus, glove, tracker),
        other => Err(AcquisitionError::NotThisSource(format!(
            "{}: source kind \"{}\" is not run by the acquisition process",
            session.file.display(),
            other.kind()
        ))),
    }
}

/// The glove and tracker outlets, whatever the source.
struct Outlets {
    glove: Outlet<topics::Glove>,
    tracker: Outlet<topics::Tracker>,
}

impl Outlets {
    fn open(bus: &Bus) -> Result<Outlets, BusError> {
        Ok(Outlets {
            glove: bus.outlet()?,
            tracker: bus.outlet()?,
        })
    }

    /// Publishes what a driver delivered (an error is said, not published).
    fn publish_device_event(
        &mut self,
        ev: DeviceEvent,
        recorder: &mut LatencyRecorder,
    ) -> Result<(), BusError> {
        match ev {
            DeviceEvent::Glove(g) => {
                let sent = self.glove.publish(&g)?;
                recorder.source_output(&sent);
            }
            DeviceEvent::Tracker(t) => {
                let sent = self.tracker.publish(&t)?;
                recorder.source_output(&sent);
            }
            DeviceEvent::Error(e) => eprintln!("handblocks acquisition: {e}"),
        }
        Ok(())
    }

    fn counters(&self) -> Counters {
        Counters::of([self.glove.counter(), self.tracker.counter()])
    }
}

/// A CyberGlove and a FASTRAK: each driver reads on its own thread; this stage stamps and
/// publishes what they deliver and reports device errors without stopping (the drivers
/// reconnect by themselves).
struct Devices {
    /// Taken when the stage stops (the drivers' last deliveries).
    readers: Option<DeviceReaders>,
    delivered: Option<DeviceEvent>,
    out: Outlets,
}

impl Task for Devices {
    type Error = BusError;

    fn wait(&mut self, _: &mut Waiter, timeout: Duration) -> Result<(), BusError> {
        self.delivered = match &self.readers {
            Some(readers) => readers.recv_timeout(timeout),
            None => None,
        };
        Ok(())
    }

    fn work(&mut self, pass: &mut Pass<'_>) -> Result<(), BusError> {
        match self.delivered.take() {
            Some(ev) => self.out.publish_device_event(ev, pass.recorder),
            None => Ok(()),
        }
    }

    fn counters(&self) -> Counters {
        self.out.counters()
    }

    fn stop(&mut self, reporter: &mut Reporter) -> Result<(), BusError> {
        // What the drivers read as the session stopped is published too: a driver's count of
        // samples is what was published.
        let Some(readers) = self.readers.take() else {
            return Ok(());
        };
        let mut last_error = None;
        let out = &mut self.out;
        let stats = readers.stop_delivering(|ev| {
            if let Err(e) = out.publish_device_event(ev, &mut reporter.recorder) {
                last_error.get_or_insert(e);
            }
        });
        if let Some(e) = last_error {
            return Err(e);
        }
        reporter.set_devices([
            stats.glove.device_counters(DeviceKind::Glove),
            stats.tracker.device_counters(DeviceKind::Tracker),
        ]);
        if stats.dropped > 0 {
            eprintln!("handblocks acquisition: {} device samples arrived faster than they could be published and were dropped", stats.dropped);
        }
        Ok(())
    }
}

fn run_devices(
    bus: &Bus,
    glove: &GloveConfig,
    tracker: &TrackerConfig,
) -> Result<(), AcquisitionError> {
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
    let out = Outlets::open(bus)?;
    // `new` checks the configuration and connects on the first read, so a device that is not
    // there yet (or is unplugged) is reported and retried instead of failing the session.
    let glove = Glove::new(gc).map_err(AcquisitionError::Device)?;
    let tracker = Tracker::new(tc).map_err(AcquisitionError::Device)?;
    let readers =
        DeviceReaders::spawn(Some(glove), Some(tracker)).map_err(AcquisitionError::Threads)?;
    let mut devices = Devices {
        readers: Some(readers),
        delivered: None,
        out,
    };
    // A source: it sleeps on its devices, not by the session's wait strategy.
    Ok(node::run(
        Stage::Acquisition,
        bus,
        WaitStrategy::Event,
        &mut devices,
    )?)
}

/// The scripted hand: the scene's keyframes sampled at `rate_hz` on absolute deadlines.
struct Scripted {
    /// The scene's hands: its `[hand]`, then its `[left_hand]` if it has one. Each deadline
    /// sends a glove and a tracker for each, the right's first, with one source time.
    hands: Vec<ScriptedHand>,
    rate_hz: f64,
    start_ns: u64,
    period_ns: f64,
    /// The next sample's index on the deadline grid (its seq).
    k: u64,
    out: Outlets,
}

impl Task for Scripted {
    type Error = BusError;

    fn wait(&mut self, _: &mut Waiter, _: Duration) -> Result<(), BusError> {
        sleep_until_ns(self.start_ns + (self.k as f64 * self.period_ns).round() as u64);
        Ok(())
    }

    fn work(&mut self, pass: &mut Pass<'_>) -> Result<(), BusError> {
        if pass.stopping || shutdown::requested() {
            return Ok(());
        }
        let k = self.k;
        let stamp = Stamp::at_origin(0, source_time_ns(k, self.rate_hz));
        for hand in &self.hands {
            let (g, t) = hand.samples_at(k as f64 / self.rate_hz, stamp);
            self.out.glove.publish(&g)?;
            let sent = self.out.tracker.publish(&t)?;
            pass.recorder.source_output(&sent);
        }
        self.k += 1;
        Ok(())
    }

    fn counters(&self) -> Counters {
        self.out.counters()
    }
}

fn run_scripted(session: &Session, bus: &Bus, rate_hz: f64) -> Result<(), AcquisitionError> {
    if session.scene.hand.is_none() {
        return Err(AcquisitionError::Script(format!(
            "{}: the scene has no [hand] for the scripted source",
            session.scene_file.display()
        )));
    }
    let hands = ScriptedHand::of_scene(&session.scene)
        .map_err(|e| AcquisitionError::Script(format!("{}: {e}", session.scene_file.display())))?;
    let mut out = Outlets::open(bus)?;

    // The session's timeline: a restarted source goes on on its first incarnation's deadline
    // grid, at the first deadline still ahead, so source time (and the hand the script gives)
    // goes on where it would have been. Sample k has seq k: the deadlines missed while it was
    // down are seqs never sent, which every reader counts as lost (with two hands, deadline k
    // sends seqs 2k and 2k + 1).
    let (start_ns, resumed) = bus.session_epoch_ns("acquisition");
    let period_ns = 1e9 / rate_hz;
    let k: u64 = if resumed {
        (monotonic_ns().saturating_sub(start_ns) as f64 / period_ns).ceil() as u64
    } else {
        0
    };
    out.glove.skip_to(k * hands.len() as u64);
    out.tracker.skip_to(k * hands.len() as u64);
    let mut scripted = Scripted {
        hands,
        rate_hz,
        start_ns,
        period_ns,
        k,
        out,
    };
    // A source: it sleeps until its deadlines, not by the session's wait strategy.
    Ok(node::run(
        Stage::Acquisition,
        bus,
        WaitStrategy::Event,
        &mut scripted,
    )?)
}
