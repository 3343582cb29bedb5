//! The session report: each stage's latency histograms and topic counters, merged, judged
//! against the session's `[budget]`, printed as a table and written as JSON (docs/design.md).
//!
//! This module holds the report's types; each thing done with them has its own file:
//! - `merge`: a restarted stage's incarnations into one report, and the stages' counters into
//!   the topics' flow ([`Report::build`]);
//! - `budget`: the session judged against its `[budget]` and what every session keeps
//!   without asking (a source that delivers, a renderer that keeps its frame rate);
//! - `table`: the report as the launcher prints it;
//! - `json`: the report JSON of docs/design.md;
//! - `refusals`: what a source refused, by kind, from the file its stage leaves.

mod budget;
mod json;
mod merge;
pub mod refusals;
mod table;
#[cfg(test)]
mod tests;

use std::collections::BTreeMap;

use common::latency::{decode, Metric, Summary};
use common::{LatencySample, Stage, Topic};
use hdrhistogram::Histogram;
use serde_json::Value;

pub use json::rfc3339;
pub use table::{terms_of, TERMS};

/// What the launcher heard from one stage.
pub struct StageReport {
    pub stage: Stage,
    pub histograms: [Histogram<u64>; common::samples::METRICS],
    pub counters: Vec<common::TopicCounter>,
    pub final_report: bool,
    /// A source only: the longest stretch without a sample it sent, ns.
    pub silence_ns: u64,
    /// When the launcher read it (a stage reports about once a second, idle or not).
    pub heard_at: std::time::Instant,
    /// The acquisition process with devices: what each driver counted.
    pub devices: Vec<common::DeviceCounters>,
    /// CPU time the stage's process used over the session (the launcher reads it as the
    /// process stops), seconds.
    pub cpu_s: Option<f64>,
    /// When the process first published what it makes (CLOCK_MONOTONIC ns; 0: not yet), and
    /// when it last did.
    pub first_output_ns: u64,
    pub last_output_ns: u64,
}

impl StageReport {
    pub fn decode(sample: &LatencySample) -> Result<StageReport, String> {
        let stage = Stage::from_u32(sample.stage)
            .ok_or_else(|| format!("unknown stage {}", sample.stage))?;
        let h = |m| decode(sample, m);
        Ok(StageReport {
            stage,
            histograms: [
                h(Metric::Hop)?,
                h(Metric::Process)?,
                h(Metric::Origin)?,
                h(Metric::Photon)?,
                h(Metric::Page)?,
            ],
            counters: sample
                .counters
                .iter()
                .filter(|c| c.topic != u32::MAX)
                .copied()
                .collect(),
            final_report: sample.final_report != 0,
            silence_ns: sample.silence_ns,
            heard_at: std::time::Instant::now(),
            devices: sample
                .devices
                .iter()
                .filter(|d| d.name().is_some())
                .copied()
                .collect(),
            cpu_s: None,
            first_output_ns: sample.first_output_ns,
            last_output_ns: sample.last_output_ns,
        })
    }

    /// An empty report of `stage`: an incarnation that died before its first report.
    pub fn empty(stage: Stage) -> StageReport {
        let h = common::latency::new_histogram;
        StageReport {
            stage,
            histograms: std::array::from_fn(|_| h()),
            counters: Vec::new(),
            final_report: false,
            silence_ns: 0,
            heard_at: std::time::Instant::now(),
            devices: Vec::new(),
            cpu_s: None,
            first_output_ns: 0,
            last_output_ns: 0,
        }
    }

    pub fn summary(&self, m: Metric) -> Summary {
        Summary::of(&self.histograms[m as usize])
    }
}

/// What one reading stage saw of a topic.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ReaderFlow {
    pub received: u64,
    /// Never read: sequence gaps, or published but not received by the end (of a source that
    /// reads a topic back, its gaps only: it stops first, before the last samples).
    pub dropped: u64,
    /// Gaps in the sequence numbers it received (samples overwritten before it read them).
    pub gaps: u64,
    /// False when the reader ended without its final report (killed, hung): its counts are
    /// those of its last report, so `received` stops there and `dropped` is its gaps only;
    /// what was published after that report was not dropped by the bus (issue 16: a killed
    /// process used to show a second of samples as dropped).
    pub counts_final: bool,
    /// Samples between a dead incarnation's last report and its restart's first sample
    /// ([`Restart::lost`]): the restarts' losses, shown with them, not as dropped.
    pub lost_in_restarts: u64,
}

/// Per topic: samples published, and per reading stage, received, dropped and gaps.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TopicFlow {
    pub published: u64,
    pub readers: BTreeMap<&'static str, ReaderFlow>,
}

impl TopicFlow {
    pub fn received(&self) -> u64 {
        self.readers.values().map(|r| r.received).min().unwrap_or(0)
    }
    pub fn dropped(&self) -> u64 {
        self.readers.values().map(|r| r.dropped).sum()
    }
    /// The most seqs any one reader missed: a loss before the bus (a link that came up late,
    /// a source's restart) is missed by every reader alike and is counted once (issue 40: a
    /// remote viewer's 28 missing worlds were 56 gaps, the recorder's and the renderer's).
    pub fn gaps(&self) -> u64 {
        self.readers.values().map(|r| r.gaps).max().unwrap_or(0)
    }
}

/// What the launcher knows of a session besides its stages' reports, for judging it.
#[derive(Debug, Clone)]
pub struct SessionFacts {
    /// From the source's start to the stop.
    pub seconds: f64,
    /// Acquisition or replay.
    pub source: Stage,
    /// A renderer drew (not off, not skipped).
    pub renders: bool,
    /// False for a speed-0 replay: samples go as fast as the slowest reader takes them, not
    /// at a rate, so there is no frame rate to keep.
    pub real_time: bool,
    /// Seconds the renderer was down (died, until its restart's first frame): the frame rate
    /// is judged over the rest of the session.
    pub renderer_down_s: f64,
}

impl Default for SessionFacts {
    fn default() -> Self {
        SessionFacts {
            seconds: 0.0,
            source: Stage::Acquisition,
            renders: false,
            real_time: true,
            renderer_down_s: 0.0,
        }
    }
}

/// What a reader's restart cost on one topic it reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RestartLoss {
    pub topic: Topic,
    /// Published while the process was down (from its death noticed to the restarted
    /// process's first sample): never read by it.
    pub lost: u64,
    /// Read by the dead process after its last report (so in no count of it); where the
    /// topic's published count at the death is not known, these are counted as lost.
    pub unreported: u64,
}

/// One restart of a process by the launcher (`[supervise] restart = "on-failure"`).
#[derive(Debug, Clone, PartialEq)]
pub struct Restart {
    pub stage: Stage,
    /// Which restart of this stage (1 for its first).
    pub n: u32,
    /// When the launcher noticed the exit, seconds since the session's start.
    pub at_s: f64,
    /// How it ended (`signal: 9 (SIGKILL)`, `exit status: 101`).
    pub exit: String,
    /// When the launcher noticed the exit (CLOCK_MONOTONIC ns).
    pub noticed_ns: u64,
    /// When the restarted process first published (or wrote) what it makes; None if it never
    /// did.
    pub first_output_ns: Option<u64>,
    /// Per topic the stage reads, what the restart cost; None until the restarted process
    /// has reported.
    pub lost: Option<Vec<RestartLoss>>,
    /// Per topic the stage reads, how many samples its publishers had sent when the death
    /// was noticed (where they keep their seq: a supervised session).
    pub published_at_death: Vec<(Topic, u64)>,
    /// The recorder's: the segment the restarted recorder writes.
    pub segment: Option<String>,
    /// The recorder's, read from the segments once the session ended: per topic, the samples
    /// that neither the dead recorder's segment nor its restart's holds (its open chunk, and
    /// what was published while none ran), counted from the seqs. None when not read (no
    /// recording, or a segment could not be read: `segment_error` says why).
    pub missing_from_recording: Option<Vec<(Topic, u64)>>,
    pub segment_error: Option<String>,
}

impl Restart {
    /// The exit noticed to the restarted process's first output, seconds (the launcher
    /// notices within its 10 ms poll of its children).
    pub fn downtime_s(&self) -> Option<f64> {
        self.first_output_ns
            .map(|t| t.saturating_sub(self.noticed_ns) as f64 / 1e9)
    }
}

/// What the report says about where it came from.
#[derive(Debug, Clone)]
pub struct Meta {
    pub session_file: String,
    pub scene_file: String,
    pub source: &'static str,
    pub version: String,
    pub cpus: usize,
    /// What other processes did with the machine while the session ran, where it could be
    /// read (`crate::machine`).
    pub machine_load: Option<crate::machine::MachineLoad>,
    /// How the processes were placed on the CPUs, when they were.
    pub placement: Option<String>,
    pub started: std::time::SystemTime,
    pub seconds: f64,
    /// Why the renderer did not run, when it was skipped.
    pub renderer_skipped: Option<String>,
    /// The world's outcome (`simulate --json`'s form), when the stepper wrote it.
    pub world: Option<Value>,
    /// What the bridge did (`bridge.json`: the link, what crossed it, the clock estimate),
    /// when the session had one.
    pub bridge: Option<Value>,
    /// What a source refused, by kind, per device name (`refused.NAME.json`, which its
    /// stage leaves in the session's folder: [`refusals`]).
    pub refused: refusals::Refusals,
}

impl Default for Meta {
    fn default() -> Self {
        Meta {
            session_file: String::new(),
            scene_file: String::new(),
            source: "",
            version: String::new(),
            cpus: 0,
            machine_load: None,
            placement: None,
            started: std::time::UNIX_EPOCH,
            seconds: 0.0,
            renderer_skipped: None,
            world: None,
            bridge: None,
            refused: refusals::Refusals::new(),
        }
    }
}

/// The merged report of a session.
pub struct Report {
    /// Stages in pipeline order.
    pub stages: Vec<StageReport>,
    pub topics: BTreeMap<Topic, TopicFlow>,
    pub violations: Vec<String>,
    /// Budget keys that could not be judged in this session, and why.
    pub not_judged: Vec<String>,
    /// Stages that failed (crashed, or sent no final report).
    pub failures: Vec<String>,
    /// The processes the launcher restarted, in order.
    pub restarts: Vec<Restart>,
    pub meta: Meta,
}

impl Report {
    fn stage(&self, stage: Stage) -> Option<&StageReport> {
        self.stages.iter().find(|s| s.stage == stage)
    }

    /// `stage`'s histogram of `metric`, if it reported one that is not empty.
    pub fn histogram(&self, stage: Stage, metric: Metric) -> Option<&Histogram<u64>> {
        self.stage(stage)
            .map(|s| &s.histograms[metric as usize])
            .filter(|h| !h.is_empty())
    }

    /// The summary of `stage`'s `metric` (empty when it sent no report).
    pub fn summary_of(&self, stage: Stage, metric: Metric) -> Summary {
        self.stage(stage)
            .map(|s| s.summary(metric))
            .unwrap_or_default()
    }

    pub fn ok(&self) -> bool {
        self.violations.is_empty() && self.failures.is_empty()
    }
}
