//! The stage loop, written once: what every process of a session does around its own work.
//!
//! A stage (a process of the graph, [`crate::topic::Stage`]) sleeps until there may be work,
//! does it, reports its latency about once a second, and when it is asked to stop (SIGINT,
//! SIGTERM, its launcher gone) does its work a last time, so that what its inputs still hold is
//! taken, then says its final words and sends its final report, which the launcher waits for.
//! That loop is [`run`]; a stage is only its per-sample work, a [`Task`], as a node of dora or a
//! task of copper is. The loop allocates nothing: counters travel in a [`Counters`] on the
//! stack.
//!
//! ```no_run
//! use std::time::Duration;
//! use common::bus::{Bus, BusError, Inlet, Outlet, Waiter};
//! use common::node::{self, Counters, Pass, Task};
//! use common::{monotonic_ns, topics, Stage};
//!
//! /// Forwards each hand sample it reads (a stage that does nothing but its hop).
//! struct Relay {
//!     hand_in: Inlet<topics::Hand>,
//!     hand_out: Outlet<topics::Hand>,
//! }
//!
//! impl Task for Relay {
//!     type Error = BusError;
//!     fn wait(&mut self, waiter: &mut Waiter, timeout: Duration) -> Result<(), BusError> {
//!         waiter.wait(&[&self.hand_in], timeout)
//!     }
//!     fn work(&mut self, pass: &mut Pass<'_>) -> Result<(), BusError> {
//!         while let Some(s) = self.hand_in.receive()? {
//!             let received = pass.arrived(&s.stamp);
//!             let sent = self.hand_out.publish(s.payload())?;
//!             pass.recorder.output(received, &sent);
//!         }
//!         Ok(())
//!     }
//!     fn counters(&self) -> Counters {
//!         Counters::of([self.hand_in.counter(), self.hand_out.counter()])
//!     }
//! }
//! # fn f(bus: &Bus) -> Result<(), BusError> {
//! let mut relay = Relay { hand_in: bus.inlet()?, hand_out: bus.outlet()? };
//! node::run(Stage::Kinematics, bus, Default::default(), &mut relay)
//! # }
//! ```

use std::path::{Path, PathBuf};
use std::time::Duration;

use crate::bus::{Bus, BusError, WaitStrategy, Waiter};
use crate::config::session::recording_segment;
use crate::config::Session;
use crate::latency::{LatencyRecorder, Reporter};
use crate::samples::{TopicCounter, MAX_TOPIC_COUNTERS};
use crate::stage::OnRestart;
use crate::stamp::{monotonic_ns, Stamp};
use crate::topic::{topics, Stage};

/// What the launcher hands a stage's process besides its session and its bus (the command
/// line of `handblocks service NAME`): one type for every stage, so that every service crate's
/// entry has one signature ([`Process::run`]) and `handblocks service` starts any of them
/// alike.
#[derive(Debug, Clone, Default)]
pub struct Launch {
    /// `--frames-dir`: where the renderer writes its frames.
    pub frames_dir: Option<PathBuf>,
    /// `--preview`: where the renderer writes its preview.
    pub preview: Option<PathBuf>,
    /// `--outcome-dir`: where the stepper writes the session's outcome.
    pub outcome_dir: Option<PathBuf>,
    /// Which restart of this process this is (0: its first start).
    pub restart: u32,
}

impl Launch {
    /// Where `stage`, in this start of its process, writes the output the session gives it at
    /// `path`, so that a restart never overwrites what the dead process wrote: its stage
    /// table's [`Stage::on_restart`] says how ([`restart_output`]).
    pub fn output_of(&self, stage: Stage, path: &Path) -> PathBuf {
        restart_output(stage, path, self.restart)
    }
}

/// Where `stage`'s `restart`-th process writes the output its session puts at `path` (the
/// launcher reads it there too): the same path, the next segment of a recording, or a folder
/// of its own beside the dead one's.
pub fn restart_output(stage: Stage, path: &Path, restart: u32) -> PathBuf {
    match stage.on_restart() {
        _ if restart == 0 => path.to_path_buf(),
        OnRestart::Resume => path.to_path_buf(),
        OnRestart::NextSegment => recording_segment(path, restart),
        OnRestart::OwnFolder => path.join(format!("restart-{restart}")),
    }
}

/// A stage's process, as `handblocks service NAME` runs it: every service crate has one, with
/// this one signature (as a task of copper has `new(config)`), so that the list of processes in
/// `handblocks service` is one line per crate and nothing else matches on a stage to start it.
pub trait Process {
    /// The row of the stage table this process is.
    const STAGE: Stage;
    /// What the process fails with, its crate's own error.
    type Error: std::error::Error + Send + Sync + 'static;
    /// Runs the stage until it is asked to stop.
    fn run(session: &Session, bus: &Bus, launch: &Launch) -> Result<(), Self::Error>;
}

/// Declares a service crate's [`Process`] for a stage that takes nothing of [`Launch`]: its
/// process is `run(session, bus)`. A stage that does (the stepper's outcome folder, the
/// renderer's frames and preview, the recorder's segments) writes its `impl` out.
///
/// ```ignore
/// common::process!(
///     /// The kinematics stage's process, as `handblocks service kinematics` runs it.
///     Kinematics, common::bus::BusError, service::run
/// );
/// ```
#[macro_export]
macro_rules! process {
    ($(#[$doc:meta])* $stage:ident, $error:ty, $run:path) => {
        $(#[$doc])*
        pub struct Process;

        impl $crate::node::Process for Process {
            const STAGE: $crate::Stage = $crate::Stage::$stage;
            type Error = $error;
            fn run(
                session: &$crate::config::Session,
                bus: &$crate::bus::Bus,
                _launch: &$crate::node::Launch,
            ) -> Result<(), $error> {
                $run(session, bus)
            }
        }
    };
}

/// How long a stage with nothing to do sleeps before it looks for a stop request again.
pub const IDLE_WAIT: Duration = Duration::from_millis(50);

/// One stage's own work; [`run`] does the rest.
pub trait Task {
    /// What the stage's work can fail with; a bus error is one of them.
    type Error: From<BusError>;

    /// Sleeps until there may be work (a sample on the stage's inlets, a source's deadline, a
    /// device's delivery), at most `timeout`. A stage that reads inlets:
    /// `waiter.wait(&[&self.hand_in], timeout)`. Not called on the last pass.
    fn wait(&mut self, waiter: &mut Waiter, timeout: Duration) -> Result<(), Self::Error>;

    /// Does all the work there is now: takes every sample its inlets hold, publishes what they
    /// give. [`Pass::arrived`] records each input's hop (and the first's arrival for the
    /// adaptive waiter); the recorder takes the rest. On the last pass ([`Pass::stopping`]) a
    /// source sends nothing new.
    fn work(&mut self, pass: &mut Pass<'_>) -> Result<(), Self::Error>;

    /// The counters of the stage's ports, for its latency reports.
    fn counters(&self) -> Counters;

    /// Once, after the last pass, before the final report: the stage's final words, its
    /// outcome files, what a device driver still delivers.
    fn stop(&mut self, reporter: &mut Reporter) -> Result<(), Self::Error> {
        let _ = reporter;
        Ok(())
    }

    /// Once, after the final report: work that changes no count and that the launcher need
    /// not wait on before it judges the session (the renderer's preview, drawn again and
    /// encoded at the end). The launcher waits for the process to exit, not for this.
    fn after_final_report(&mut self) {}
}

/// What one pass of the loop hands a stage's work.
pub struct Pass<'r> {
    /// The stage's latency histograms.
    pub recorder: &'r mut LatencyRecorder,
    /// True on the last pass, after the stage was asked to stop.
    pub stopping: bool,
    waiter: &'r mut Waiter,
    first: bool,
    ended: bool,
}

impl Pass<'_> {
    /// The stage's work is done (a replay that played its trace): no more passes; its
    /// [`Task::stop`] and final report follow, and [`run`] returns.
    pub fn end(&mut self) {
        self.ended = true;
    }

    /// An input sample was taken: records its hop (publish to now), and tells the adaptive
    /// waiter when the first of this pass was sent (not when we woke: a late wake-up would
    /// shift its next predicted arrival late by as much). Returns now, the receive time.
    pub fn arrived(&mut self, input: &Stamp) -> u64 {
        let received = monotonic_ns();
        if std::mem::take(&mut self.first) {
            self.waiter.arrived(input.publish_ns);
        }
        self.recorder.hop(input, received);
        received
    }
}

/// A stage's port counters, at most [`MAX_TOPIC_COUNTERS`], on the stack.
#[derive(Debug, Clone, Copy)]
pub struct Counters {
    counters: [TopicCounter; MAX_TOPIC_COUNTERS],
    len: usize,
}

impl FromIterator<TopicCounter> for Counters {
    fn from_iter<I: IntoIterator<Item = TopicCounter>>(ports: I) -> Counters {
        let mut counters = Counters::of([]);
        ports.into_iter().for_each(|c| counters.push(c));
        counters
    }
}

impl Counters {
    /// The counters of `N` ports (more than [`MAX_TOPIC_COUNTERS`] does not compile).
    pub fn of<const N: usize>(ports: [TopicCounter; N]) -> Counters {
        const { assert!(N <= MAX_TOPIC_COUNTERS) };
        let mut counters = [TopicCounter::default(); MAX_TOPIC_COUNTERS];
        counters[..N].copy_from_slice(&ports);
        Counters { counters, len: N }
    }

    /// Adds one port's counter (past [`MAX_TOPIC_COUNTERS`], none: a report holds no more).
    pub fn push(&mut self, counter: TopicCounter) {
        if self.len < MAX_TOPIC_COUNTERS {
            self.counters[self.len] = counter;
            self.len += 1;
        }
    }

    pub fn as_slice(&self) -> &[TopicCounter] {
        &self.counters[..self.len]
    }
}

/// Runs `task` as stage `stage` until the process is asked to stop: wait, work, report; then a
/// last pass, [`Task::stop`] and the final report (or, once a pass says the work is done,
/// [`Pass::end`], its stop and final report). `strategy` is how the stage waits
/// (`[session] wait`); with the adaptive one the waiter says what it learned when it stops.
pub fn run<T: Task>(
    stage: Stage,
    bus: &Bus,
    strategy: WaitStrategy,
    task: &mut T,
) -> Result<(), T::Error> {
    let mut reporter = Reporter::new(stage, bus.outlet::<topics::Latency>()?);
    let mut waiter = Waiter::for_stage(strategy);
    loop {
        let stopping = crate::shutdown::requested();
        if !stopping {
            task.wait(&mut waiter, IDLE_WAIT)?;
        }
        let mut pass = Pass {
            recorder: &mut reporter.recorder,
            stopping,
            waiter: &mut waiter,
            first: true,
            ended: false,
        };
        task.work(&mut pass)?;
        if stopping || pass.ended {
            if waiter.strategy() == WaitStrategy::Adaptive {
                eprintln!("{}", waiter.finish(stage.name()));
            }
            task.stop(&mut reporter)?;
            // After the stop: what it still sent (a device's last deliveries) counts.
            let reported = reporter.finish(task.counters().as_slice());
            task.after_final_report();
            return Ok(reported?);
        }
        reporter.maybe_report(task.counters().as_slice())?;
    }
}
