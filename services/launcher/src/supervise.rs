//! Supervision: steps 5 and 6 of a launch (the crate docs). While the session runs, the
//! launcher reads every stage's latency reports, prints progress, says a stalled stage, and
//! notices a process that died: the session fails, or, under `[supervise] restart =
//! "on-failure"`, the process is started again after its back-off while the others go on. At
//! the end it stops the processes in pipeline order, each after its final report, and merges
//! each restarted stage's incarnations; what the restarts cost is counted, the recorder's from
//! its recording's segments.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use common::bus::{Bus, BusConfig, Inlet};
use common::config::session::RestartPolicy;
use common::config::Session;
use common::node::restart_output;
use common::stage::OnRestart;
use common::{shutdown, topics, Stage, Topic};

use crate::error::describe_exit;
use crate::placement::Placement;
use crate::process::ServiceProcess;
use crate::progress;
use crate::report::{Restart, StageReport};
use crate::start::Starter;
use crate::LaunchOptions;

/// How long a stopping process may take to send its final report.
const FINAL_REPORT_TIMEOUT: Duration = Duration::from_secs(5);
/// A stage that has reported and then says nothing for this long is stopped (SIGSTOP) or hung:
/// every stage reports about once a second, idle or not.
const STALLED_AFTER: Duration = Duration::from_secs(3);

/// What the launcher gathers while the session runs and stops: every stage's newest latency
/// report, and what went wrong with the processes.
pub(crate) struct Supervision<'a> {
    latency: &'a Inlet<topics::Latency>,
    budget: common::config::session::Budget,
    reports: BTreeMap<Stage, StageReport>,
    failures: Vec<String>,
    /// The stages already said to be stalled (each is said once).
    stalled: Vec<Stage>,
    restarting: Restarting<'a>,
}

/// Issue 16, supervision: what restarting a dead process takes and what the restarts were.
struct Restarting<'a> {
    /// The launcher's node, which removes a dead process's node and ports.
    bus: &'a Bus,
    /// The session's bus: where its publishers keep their seq.
    bus_config: &'a BusConfig,
    starter: &'a Starter<'a>,
    placement: &'a Placement,
    /// The policy in force (`never` on a lossless bus, whatever the session says).
    restart: RestartPolicy,
    supervise: common::config::session::Supervise,
    /// The session's recording, whose next segment a restarted recorder writes.
    recording: Option<PathBuf>,
    restarts: Vec<Restart>,
    /// Per restarted stage, the merged reports of its dead incarnations.
    earlier: BTreeMap<Stage, StageReport>,
    /// Dead processes waiting out their back-off: index into the processes, and when.
    due: Vec<(usize, Instant)>,
    /// The session's start (restart times count from it).
    started: Instant,
}

impl Restarting<'_> {
    fn count(&self, stage: Stage) -> u32 {
        self.restarts.iter().filter(|r| r.stage == stage).count() as u32
    }
}

/// What supervision gathered, once every process is stopped: every stage's report (a restarted
/// stage's, its incarnations' together), the failures, and the restarts with what they cost.
pub(crate) struct Supervised {
    pub(crate) reports: BTreeMap<Stage, StageReport>,
    pub(crate) failures: Vec<String>,
    pub(crate) restarts: Vec<Restart>,
}

impl<'a> Supervision<'a> {
    /// Supervision of `session`'s processes, which `starter` started on the CPUs `placement`
    /// gives them, reading the stages' reports from `latency`; `bus` (the launcher's node)
    /// removes a dead process's node before it is started again.
    pub(crate) fn new(
        session: &Session,
        latency: &'a Inlet<topics::Latency>,
        bus: &'a Bus,
        bus_config: &'a BusConfig,
        starter: &'a Starter<'a>,
        placement: &'a Placement,
    ) -> Supervision<'a> {
        Supervision {
            latency,
            budget: session.budget.clone(),
            reports: BTreeMap::new(),
            failures: Vec::new(),
            stalled: Vec::new(),
            restarting: Restarting {
                bus,
                bus_config,
                starter,
                placement,
                // A lossless bus (a speed-0 replay) promises every sample to every reader; a
                // process that died broke that promise, and a restart cannot keep it.
                restart: if bus_config.lossless {
                    RestartPolicy::Never
                } else {
                    session.supervise.restart
                },
                supervise: session.supervise,
                recording: session.recorder.file.clone(),
                restarts: Vec::new(),
                earlier: BTreeMap::new(),
                due: Vec::new(),
                started: Instant::now(),
            },
        }
    }

    /// After [`Supervision::stop_in_order`]: every restarted stage's incarnations merged, and
    /// each recorder restart's loss read from the recording's segments.
    pub(crate) fn finish(mut self) -> Supervised {
        self.merge_incarnations();
        let Supervision {
            reports,
            failures,
            restarting,
            ..
        } = self;
        let mut restarts = restarting.restarts;
        if let Some(rec) = &restarting.recording {
            count_recording_losses(rec, &mut restarts);
        }
        Supervised {
            reports,
            failures,
            restarts,
        }
    }

    /// Issue 16: a stage stopped with SIGSTOP (or hung) left no trace in the report; its
    /// reports stop, so a stage silent for [`STALLED_AFTER`] is a failure, said at once.
    fn check_stalled(&mut self, opts: &LaunchOptions, procs: &[ServiceProcess]) {
        for p in procs {
            let Some(r) = self.reports.get(&p.stage) else {
                continue;
            };
            let silent = r.heard_at.elapsed();
            if r.final_report || silent < STALLED_AFTER || self.stalled.contains(&p.stage) {
                continue;
            }
            self.stalled.push(p.stage);
            let line = format!(
                "the {} process has sent no report for {:.1} s: it is stopped (SIGSTOP?) or \
                 hung, and what it reads is piling up unread",
                p.stage.name(),
                silent.as_secs_f64()
            );
            if opts.progress {
                eprintln!("handblocks: {line}");
            }
            self.failures.push(line);
        }
    }

    /// Step 5: runs for `--duration`, until Ctrl-C / SIGTERM, until a replay's trace ends, or
    /// until a process exits (a failure), printing progress; returns how long it ran.
    pub(crate) fn run(
        &mut self,
        opts: &LaunchOptions,
        source: Stage,
        procs: &mut [ServiceProcess],
    ) -> Duration {
        let started = Instant::now();
        self.restarting.started = started;
        let mut next_progress = Duration::from_secs(1);
        let mut progress = progress::Progress::new(&self.budget);
        loop {
            // 10 ms: a dead child is noticed (and restarted) within it.
            std::thread::sleep(Duration::from_millis(10));
            collect(self.latency, &mut self.reports);
            self.note_first_outputs();
            if shutdown::requested() || opts.duration.is_some_and(|d| started.elapsed() >= d) {
                break;
            }
            // A replay that played its whole trace has sent its final report: the session
            // ends, as `ros2 bag play` does.
            if has_final(&self.reports, source) {
                if opts.progress {
                    eprintln!(
                        "handblocks: the trace ended after {:.1} s; stopping",
                        started.elapsed().as_secs_f64()
                    );
                }
                break;
            }
            if let Err(line) = self.supervise_children(opts, procs) {
                if opts.progress {
                    eprintln!("handblocks: {line}");
                }
                self.failures.push(line);
                break;
            }
            self.check_stalled(opts, procs);
            if opts.progress && started.elapsed() >= next_progress {
                next_progress += Duration::from_secs(1);
                eprintln!("{}", progress.line(started.elapsed(), &self.reports));
            }
        }
        started.elapsed()
    }

    /// Notices processes that died: each is restarted (after its back-off) when the session's
    /// `[supervise]` allows, else the session fails with the returned line. Processes whose
    /// back-off is over are started again here.
    fn supervise_children(
        &mut self,
        opts: &LaunchOptions,
        procs: &mut [ServiceProcess],
    ) -> Result<(), String> {
        for (i, p) in procs.iter_mut().enumerate() {
            if self.restarting.due.iter().any(|(j, _)| *j == i) {
                continue;
            }
            let Some(status) = p.poll_exit() else {
                continue;
            };
            let stage = p.stage;
            let noticed_ns = common::monotonic_ns();
            let exit = describe_exit(Some(status));
            let done = self.restarting.count(stage);
            let policy = self.restarting.supervise;
            if self.restarting.restart == RestartPolicy::Never {
                return Err(format!(
                    "the {} process exited during the session ({exit})",
                    stage.name()
                ));
            }
            if done >= policy.max_restarts {
                return Err(format!(
                    "the {} process exited during the session ({exit}) after {done} restarts; \
                     [supervise] max_restarts = {} allows no more",
                    stage.name(),
                    policy.max_restarts
                ));
            }
            // Its last reports are read before it is written off: what arrives later is the
            // restarted process's.
            collect(self.latency, &mut self.reports);
            self.retire_incarnation(stage);
            self.stalled.retain(|s| *s != stage);
            // Reaped (poll_exit waited on it): iceoryx2 now sees its node dead, and removing
            // it frees its ports for the process that takes its place.
            let (removed, failed) = self.restarting.bus.cleanup_dead_nodes();
            if failed > 0 {
                eprintln!(
                    "handblocks: {failed} dead node(s) of the {} process could not be removed \
                     ({removed} were)",
                    stage.name()
                );
            }
            let n = done + 1;
            let wait = policy.backoff(n);
            let segment = (stage.on_restart() == OnRestart::NextSegment)
                .then(|| {
                    self.restarting
                        .recording
                        .as_ref()
                        .map(|f| restart_output(stage, f, n).display().to_string())
                })
                .flatten();
            let at_s = self.restarting.started.elapsed().as_secs_f64();
            if opts.progress {
                eprintln!(
                    "handblocks: the {} process exited ({exit}) at {at_s:.2} s; restart {n} of \
                     at most {} in {} ms",
                    stage.name(),
                    policy.max_restarts,
                    wait.as_millis()
                );
            }
            // What its publishers had sent at its death: the samples after it were published
            // while it was down.
            let published_at_death = Topic::ALL
                .into_iter()
                .filter(|t| t.readers().contains(&stage))
                .filter_map(|t| Some((t, self.restarting.bus_config.published_count(t)?)))
                .collect();
            self.restarting.restarts.push(Restart {
                stage,
                n,
                at_s,
                exit,
                noticed_ns,
                first_output_ns: None,
                lost: None,
                published_at_death,
                segment,
                missing_from_recording: None,
                segment_error: None,
            });
            self.restarting.due.push((i, Instant::now() + wait));
        }
        let now = Instant::now();
        while let Some(k) = self.restarting.due.iter().position(|(_, at)| *at <= now) {
            let (i, _) = self.restarting.due.remove(k);
            let stage = procs[i].stage;
            let n = self.restarting.count(stage);
            let started = self
                .restarting
                .starter
                .start(stage, self.restarting.placement, n)
                .map_err(|e| format!("the {} process could not be restarted: {e}", stage.name()))?;
            procs[i] = started;
        }
        Ok(())
    }

    /// A dead incarnation's report joins those of the stage's earlier ones; the samples lost
    /// between it and the one before go to that restart.
    fn retire_incarnation(&mut self, stage: Stage) {
        // One that died before its first report counted nothing, but its restart is still
        // to be told apart from it.
        let current = self
            .reports
            .remove(&stage)
            .unwrap_or_else(|| StageReport::empty(stage));
        let merged = match self.restarting.earlier.remove(&stage) {
            None => current,
            Some(earlier) => {
                let n = self.restarting.count(stage);
                let restart = self
                    .restarting
                    .restarts
                    .iter_mut()
                    .find(|r| r.stage == stage && r.n == n);
                let at_death = restart
                    .as_ref()
                    .map_or(&[][..], |r| &r.published_at_death[..]);
                let (merged, lost) = earlier.then(current, at_death);
                if let Some(r) = restart {
                    r.lost = Some(lost);
                }
                merged
            }
        };
        self.restarting.earlier.insert(stage, merged);
    }

    /// At the end: every restarted stage's report is all its incarnations' together.
    fn merge_incarnations(&mut self) {
        let stages: Vec<Stage> = self.restarting.earlier.keys().copied().collect();
        for stage in stages {
            self.retire_incarnation(stage);
            if let Some(merged) = self.restarting.earlier.remove(&stage) {
                self.reports.insert(stage, merged);
            }
        }
    }

    /// A restarted process's first output ends its downtime.
    fn note_first_outputs(&mut self) {
        let reports = &self.reports;
        let restarts = &mut self.restarting.restarts;
        for k in 0..restarts.len() {
            let (stage, noticed_ns) = (restarts[k].stage, restarts[k].noticed_ns);
            // Only the stage's latest restart: its report is the running incarnation's.
            if restarts[k].first_output_ns.is_some()
                || restarts[k + 1..].iter().any(|q| q.stage == stage)
            {
                continue;
            }
            if let Some(rep) = reports.get(&stage) {
                if rep.first_output_ns >= noticed_ns {
                    restarts[k].first_output_ns = Some(rep.first_output_ns);
                }
            }
        }
    }

    /// Step 6: stops the processes in pipeline order; each stage drains what the one before it
    /// sent and sends its final report, and is released and reaped once that report is read
    /// (or it gave up). A process without a final report, or that failed, is a failure.
    pub(crate) fn stop_in_order(&mut self, procs: &mut [ServiceProcess]) {
        for (i, p) in procs.iter_mut().enumerate() {
            if self.restarting.due.iter().any(|(j, _)| *j == i) {
                // Dead and waiting out its back-off when the session ended: its death is in
                // the report as a restart (never made), not a failure; its reports so far
                // are its earlier incarnations'.
                continue;
            }
            p.request_stop();
            let deadline = Instant::now() + FINAL_REPORT_TIMEOUT;
            while !has_final(&self.reports, p.stage) {
                collect(self.latency, &mut self.reports);
                if Instant::now() > deadline
                    || (p.poll_exit().is_some() && !has_final(&self.reports, p.stage))
                {
                    break;
                }
                std::thread::sleep(Duration::from_millis(1));
            }
            collect(self.latency, &mut self.reports);
            let cpu = p.cpu_seconds();
            if let Some(r) = self.reports.get_mut(&p.stage) {
                r.cpu_s = cpu;
            }
            // What it still does after its final report (the renderer draws and encodes its
            // preview) is the stage table's ([`Stage::exit_wait`]).
            let status = p.release_and_reap(p.stage.exit_wait());
            if !has_final(&self.reports, p.stage) {
                self.failures.push(format!(
                    "the {} process sent no final report ({})",
                    p.stage.name(),
                    describe_exit(status)
                ));
            } else if !status.is_some_and(|s| s.success())
                && !self.failures.iter().any(|f| f.contains(p.stage.name()))
            {
                self.failures.push(format!(
                    "the {} process failed ({})",
                    p.stage.name(),
                    describe_exit(status)
                ));
            }
        }
    }
}

fn has_final(reports: &BTreeMap<Stage, StageReport>, stage: Stage) -> bool {
    reports.get(&stage).is_some_and(|r| r.final_report)
}

/// Reads every latency report waiting; the newest of each stage replaces the older one
/// (histograms are cumulative).
fn collect(latency: &Inlet<topics::Latency>, reports: &mut BTreeMap<Stage, StageReport>) {
    while let Ok(Some(s)) = latency.receive() {
        match StageReport::decode(s.payload()) {
            Ok(r) => {
                reports.insert(r.stage, r);
            }
            Err(e) => eprintln!("handblocks: ignoring a malformed latency report: {e}"),
        }
    }
}

/// Issue 28: once the session has ended, each recorder restart's loss as its recording
/// shows it: the seqs that neither the dead recorder's segment nor the next one holds.
fn count_recording_losses(recording: &Path, restarts: &mut [Restart]) {
    let last = restarts
        .iter()
        .filter(|r| r.stage.on_restart() == OnRestart::NextSegment)
        .map(|r| r.n)
        .max();
    let Some(last) = last else { return };
    match recording::SegmentChain::open(recording, last + 1) {
        Ok(chain) => {
            for r in restarts
                .iter_mut()
                .filter(|r| r.stage.on_restart() == OnRestart::NextSegment)
            {
                r.missing_from_recording = chain
                    .gaps
                    .get(r.n as usize - 1)
                    .map(|g| g.iter().map(|g| (g.topic, g.lost())).collect());
                if r.missing_from_recording.is_none() {
                    r.segment_error = Some(format!(
                        "its segment {} was not written",
                        common::config::session::recording_segment(recording, r.n).display()
                    ));
                }
            }
        }
        Err(e) => {
            for r in restarts
                .iter_mut()
                .filter(|r| r.stage.on_restart() == OnRestart::NextSegment)
            {
                r.segment_error = Some(e.to_string());
            }
        }
    }
}
