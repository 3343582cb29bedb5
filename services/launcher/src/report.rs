//! The session report: each stage's latency histograms and topic counters, merged, judged
//! against the session's `[budget]`, printed as a table and written as JSON (docs/design.md).

use std::collections::BTreeMap;

use common::config::session::Budget;
use common::latency::{decode, Metric, Summary};
use common::{LatencySample, Stage, Topic};
use hdrhistogram::Histogram;
use serde_json::{json, Map, Value};

/// What the launcher heard from one stage.
pub struct StageReport {
    pub stage: Stage,
    pub histograms: [Histogram<u64>; 4],
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
            histograms: [h(), h(), h(), h()],
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

    /// This incarnation's report followed by the next one's, that of the same stage started
    /// again after this one died ([`Restart`]): latencies and counts of both; per reader
    /// topic, the seqs between them are returned apart for the restart to show
    /// ([`RestartLoss`]), split at `published_at_death` (the topic's count when the death was
    /// noticed, where known).
    ///
    /// A publisher's counts are the next one's (a supervised outlet's seq, and with it its
    /// count, goes on across a restart); a restarted source's seqs skipped at the restart
    /// (its deadlines missed while it was down) are its restart's loss. A reader's add up; the next one counts gaps from its
    /// first sample, so the seqs between this one's last report and the next one's first
    /// sample are the restart's: those this one read after its last report (it reports about
    /// once a second) and those published while the process was down.
    pub fn then(
        mut self,
        next: StageReport,
        published_at_death: &[(Topic, u64)],
    ) -> (StageReport, Vec<RestartLoss>) {
        for (h, n) in self.histograms.iter_mut().zip(&next.histograms) {
            // Same bounds on both sides: adding cannot fail; were it to, the earlier stays.
            let _ = h.add(n);
        }
        if self.first_output_ns == 0 {
            self.first_output_ns = next.first_output_ns;
        }
        self.last_output_ns = self.last_output_ns.max(next.last_output_ns);
        let mut lost = Vec::new();
        for c in &next.counters {
            let at = self
                .counters
                .iter()
                .position(|e| e.topic == c.topic && e.role == c.role);
            let at = at.unwrap_or_else(|| {
                // Not counted before (an incarnation that died before its first report).
                self.counters.push(common::TopicCounter {
                    count: 0,
                    gaps: 0,
                    last_seq: u64::MAX,
                    ..*c
                });
                self.counters.len() - 1
            });
            match &mut self.counters[at] {
                e if c.role == 0 => {
                    // A restarted source skipped the seqs of the samples due while it was
                    // down (its publisher counter's gaps): its restart's loss.
                    if c.gaps > e.gaps {
                        if let Some(topic) = Topic::from_u32(c.topic) {
                            lost.push(RestartLoss {
                                topic,
                                lost: c.gaps - e.gaps,
                                unreported: 0,
                            });
                        }
                    }
                    *e = *c;
                }
                e => {
                    if c.count > 0 {
                        let first = (c.last_seq + 1).saturating_sub(c.count + c.gaps);
                        let after = if e.count > 0 { e.last_seq + 1 } else { 0 };
                        if let Some(topic) = Topic::from_u32(c.topic) {
                            let at_death = published_at_death
                                .iter()
                                .find(|(t, _)| *t == topic)
                                .map_or(after, |(_, n)| (*n).clamp(after, first.max(after)));
                            lost.push(RestartLoss {
                                topic,
                                unreported: at_death - after,
                                lost: first.saturating_sub(at_death),
                            });
                        }
                        e.last_seq = c.last_seq;
                    }
                    e.count += c.count;
                    e.gaps += c.gaps;
                }
            }
        }
        self.silence_ns = self.silence_ns.max(next.silence_ns);
        self.final_report = next.final_report;
        self.heard_at = next.heard_at;
        if !next.devices.is_empty() {
            self.devices = next.devices;
        }
        self.cpu_s = match (self.cpu_s, next.cpu_s) {
            (Some(a), Some(b)) => Some(a + b),
            (a, b) => a.or(b),
        };
        self.first_output_ns = next.first_output_ns;
        (self, lost)
    }

    pub fn summary(&self, m: Metric) -> Summary {
        Summary::of(&self.histograms[m as usize])
    }
}

/// What one reading stage saw of a topic.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ReaderFlow {
    pub received: u64,
    /// Never read: sequence gaps, or published but not received by the end.
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
    pub fn gaps(&self) -> u64 {
        self.readers.values().map(|r| r.gaps).sum()
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
}

impl Default for Meta {
    fn default() -> Self {
        Meta {
            session_file: String::new(),
            scene_file: String::new(),
            source: "",
            version: String::new(),
            cpus: 0,
            placement: None,
            started: std::time::UNIX_EPOCH,
            seconds: 0.0,
            renderer_skipped: None,
            world: None,
            bridge: None,
        }
    }
}

/// The latency table's terms, printed under it and in `launch --help`.
pub const TERMS: &str = "\
hop          a sample's publish (by the stage before) to its receive here: the bus and the wake-up
process      receive to this stage's publish: its own work
origin->out  the sample's origin (when its source sample entered the pipeline) to this stage's
             publish: the age of what it sends (at the stepper: origin -> world)
origin->px   the renderer only: origin to the frame's GPU work complete (origin -> photon)
received     per topic, the fewest samples any reader of it received; dropped = never read
             (sequence gaps, or published but not received by the end)";

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
    pub fn build(
        stages: Vec<StageReport>,
        budget: &Budget,
        failures: Vec<String>,
        facts: &SessionFacts,
    ) -> Report {
        Report::build_with_restarts(stages, budget, failures, Vec::new(), facts)
    }

    /// [`Report::build`] of a session whose launcher restarted processes: each restarted
    /// stage's report is its incarnations' merged ([`StageReport::then`]), and the samples its
    /// restarts lost are the restarts', not counted as dropped.
    pub fn build_with_restarts(
        mut stages: Vec<StageReport>,
        budget: &Budget,
        failures: Vec<String>,
        restarts: Vec<Restart>,
        facts: &SessionFacts,
    ) -> Report {
        stages.sort_by_key(|s| s.stage);
        let mut topics: BTreeMap<Topic, TopicFlow> = BTreeMap::new();
        // Per topic, seqs its (restarted) publishers skipped: lost while a source was down,
        // counted by every reader as gaps, and shown with the source's restart instead.
        let mut skipped: BTreeMap<Topic, u64> = BTreeMap::new();
        for s in &stages {
            for c in &s.counters {
                let Some(topic) = Topic::from_u32(c.topic) else {
                    continue;
                };
                let flow = topics.entry(topic).or_default();
                if c.role == 0 {
                    flow.published += c.count;
                    *skipped.entry(topic).or_default() += c.gaps;
                }
            }
        }
        for s in &stages {
            for c in &s.counters {
                let Some(topic) = Topic::from_u32(c.topic) else {
                    continue;
                };
                if c.role == 1 {
                    let flow = topics.entry(topic).or_default();
                    let lost_in_restarts: u64 = restarts
                        .iter()
                        .filter(|r| r.stage == s.stage)
                        .flat_map(|r| r.lost.iter().flatten())
                        .filter(|l| l.topic == topic)
                        .map(|l| l.lost + l.unreported)
                        .sum();
                    // Lost on the way: gaps in seq, and whatever was published but never read
                    // (less what its restarts lost, which they show); a reader without its
                    // final report is known only up to its last one.
                    let gaps = c
                        .gaps
                        .saturating_sub(skipped.get(&topic).copied().unwrap_or(0));
                    let dropped = if s.final_report {
                        gaps.max(
                            flow.published
                                .saturating_sub(c.count)
                                .saturating_sub(lost_in_restarts),
                        )
                    } else {
                        gaps
                    };
                    flow.readers.insert(
                        s.stage.name(),
                        ReaderFlow {
                            received: c.count,
                            dropped,
                            gaps: c.gaps,
                            counts_final: s.final_report,
                            lost_in_restarts,
                        },
                    );
                }
            }
        }
        // Topics nobody published on (e.g. joints with a glove source) are not part of the flow.
        topics.retain(|_, f| f.published > 0 || f.readers.values().any(|r| r.received > 0));
        let mut report = Report {
            stages,
            topics,
            violations: Vec::new(),
            not_judged: Vec::new(),
            failures,
            restarts,
            meta: Meta::default(),
        };
        report.violations = report.judge(budget, facts);
        report.judge_what_users_assume(budget, facts);
        report
    }

    /// The budget every session keeps without asking: a source that delivers, and a renderer
    /// that keeps its frame rate.
    fn judge_what_users_assume(&mut self, b: &Budget, facts: &SessionFacts) {
        let source = self.stage(facts.source).map(|s| {
            (
                s.silence_ns,
                s.summary(Metric::Origin).count,
                s.stage.name(),
            )
        });
        match source {
            Some((_, 0, name)) => self.violations.push(format!(
                "source_silence_ms: the source ({name}) delivered no sample in {:.1} s",
                facts.seconds
            )),
            Some((silence_ns, _, name)) if silence_ns as f64 / 1e6 > b.source_silence_ms => {
                self.violations.push(format!(
                    "source_silence_ms: the source ({name}) delivered no sample for {:.0} ms > {}",
                    silence_ns as f64 / 1e6,
                    b.source_silence_ms
                ))
            }
            Some(_) => {}
            None => self
                .violations
                .push("source_silence_ms: the source sent no report".into()),
        }
        if !facts.renders {
            // Nothing drew (off by choice, or no GPU adapter): no frame rate to judge.
            if b.origin_to_photon_p99_ms.is_some() {
                self.not_judged.push(
                    "origin_to_photon_p99_ms: the renderer did not run (skipped: no GPU adapter)"
                        .into(),
                );
            }
            return;
        }
        if facts.seconds < 0.5 {
            self.not_judged
                .push("frame_hz: the session was too short to measure a frame rate".into());
            return;
        }
        if !facts.real_time {
            self.not_judged.push(
                "frame_hz: a speed-0 replay runs as fast as its slowest reader, not in real time"
                    .into(),
            );
            return;
        }
        let frames = self
            .stage(Stage::Renderer)
            .map_or(0, |s| s.summary(Metric::Photon).count);
        // The world's publisher: the stepper, or the bridge of a remote-fed session.
        let worlds = self
            .stage(Stage::Stepper)
            .map(|s| s.summary(Metric::Origin).count)
            .or_else(|| self.topics.get(&Topic::World).map(|f| f.published))
            .unwrap_or(0);
        // Judged over the time there were worlds to draw: from the world publisher's first
        // world to its last (a viewer started before its session, or left running after it,
        // had nothing to draw then), or the whole session where that is not known.
        let world_s = self.world_seconds(facts.seconds);
        if worlds > 0 && world_s < 0.5 {
            self.not_judged.push(format!(
                "frame_hz: worlds arrived for only {world_s:.2} s, too short to measure a frame rate"
            ));
            return;
        }
        // While a restarted renderer was down there were no frames to draw: judged without it.
        let drawing_s = (world_s - facts.renderer_down_s).max(0.5);
        let fps = frames as f64 / drawing_s;
        // A frame is drawn for each new world state: fewer worlds than frame_hz is not the
        // renderer's shortfall.
        let world_hz = worlds as f64 / world_s.max(0.5);
        let wanted = b.frame_hz.min(world_hz);
        let floor = wanted * (1.0 - b.frame_rate_margin);
        if fps < floor {
            self.violations.push(format!(
                "frame_hz: {fps:.1} frames per second < {floor:.1} ({} {wanted:.1} less \
                 frame_rate_margin {:.0} %)",
                if wanted < b.frame_hz {
                    "the world's rate"
                } else {
                    "frame_hz"
                },
                b.frame_rate_margin * 100.0
            ));
        }
    }

    /// How long there were worlds to draw: from the world publisher's (the stepper's, or the
    /// bridge's of a remote-fed session) first world to its last, at most `seconds` (the
    /// session's); `seconds` where that is not known.
    fn world_seconds(&self, seconds: f64) -> f64 {
        self.stage(Stage::Stepper)
            .or_else(|| self.stage(Stage::Bridge))
            .filter(|s| s.first_output_ns > 0 && s.last_output_ns > s.first_output_ns)
            .map_or(seconds, |s| {
                ((s.last_output_ns - s.first_output_ns) as f64 / 1e9).min(seconds)
            })
    }

    /// Frames per second the renderer drew, over the time there were worlds to draw.
    pub fn frame_rate(&self) -> Option<f64> {
        let s = self.stage(Stage::Renderer)?;
        let n = s.summary(Metric::Photon).count;
        let over = self.world_seconds(self.meta.seconds);
        (n > 0 && over > 0.0).then(|| n as f64 / over.max(0.5))
    }

    /// One line on the bridge: what crossed the link and the clock it was stamped by.
    pub fn bridge_line(&self) -> Option<String> {
        let b = self.meta.bridge.as_ref()?;
        let mut parts = Vec::new();
        if let Some(l) = b.get("link").filter(|l| !l.is_null()) {
            let counts = |k: &str| {
                l.get(k)
                    .and_then(|m| m.as_object())
                    .map(|m| {
                        m.iter()
                            .map(|(t, n)| format!("{t} {n}"))
                            .collect::<Vec<_>>()
                            .join(", ")
                    })
                    .filter(|s| !s.is_empty())
            };
            parts.push(format!(
                "bridge: {} {} ({} peer(s) at the end)",
                l["role"].as_str().unwrap_or("?"),
                l["endpoint"].as_str().unwrap_or("?"),
                l["peers_at_end"]
            ));
            if let Some(s) = counts("sent") {
                parts.push(format!("sent {s}"));
            }
            if let Some(s) = counts("taken_in") {
                parts.push(format!("taken in {s}"));
            }
            match l.get("clock").filter(|c| !c.is_null()) {
                Some(c) => parts.push(format!(
                    "the other clock is {:.1} us from ours, +/- {:.1} us ({} round trips)",
                    c["offset_ns"].as_f64().unwrap_or(0.0) / 1e3,
                    c["uncertainty_ns"].as_f64().unwrap_or(0.0) / 1e3,
                    c["exchanges"]
                )),
                None if l["subscribe"].as_array().is_some_and(|a| !a.is_empty()) => {
                    parts.push("the other clock was never reached".into())
                }
                None => {}
            }
            let dropped =
                l["queue_full"].as_u64().unwrap_or(0) + l["malformed"].as_u64().unwrap_or(0);
            if dropped > 0 {
                parts.push(format!(
                    "dropped {dropped} ({} queue full, {} malformed)",
                    l["queue_full"], l["malformed"]
                ));
            }
        }
        if let Some(port) = b.get("foxglove").and_then(|f| f.get("port")) {
            parts.push(format!("Foxglove view served on port {port}"));
        }
        (!parts.is_empty()).then(|| parts.join("; "))
    }

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

    fn judge(&self, b: &Budget, facts: &SessionFacts) -> Vec<String> {
        let mut v = Vec::new();
        if let Some(limit) = b.origin_to_world_p99_us {
            match self.stage(Stage::Stepper) {
                Some(s) if s.summary(Metric::Origin).count > 0 => {
                    let p99 = s.summary(Metric::Origin).p99;
                    if p99 > limit {
                        v.push(format!("origin_to_world_p99_us: {p99} > {limit}"));
                    }
                }
                _ => v.push("origin_to_world_p99_us: the stepper published no world state".into()),
            }
        }
        if let Some(limit) = b.hop_p99_us {
            for s in &self.stages {
                let p99 = s.summary(Metric::Hop).p99;
                if s.summary(Metric::Hop).count > 0 && p99 > limit {
                    v.push(format!("hop_p99_us ({}): {p99} > {limit}", s.stage.name()));
                }
            }
        }
        if let Some(limit_ms) = b.origin_to_photon_p99_ms.filter(|_| facts.renders) {
            match self.stage(Stage::Renderer) {
                Some(s) if s.summary(Metric::Photon).count > 0 => {
                    let p99_ms = s.summary(Metric::Photon).p99 / 1000.0;
                    if p99_ms > limit_ms {
                        v.push(format!("origin_to_photon_p99_ms: {p99_ms} > {limit_ms}"));
                    }
                }
                _ => v.push("origin_to_photon_p99_ms: the renderer drew no frame".into()),
            }
        }
        if let Some(limit) = b.max_dropped {
            let dropped: u64 = self.topics.values().map(|f| f.dropped()).sum();
            if dropped > limit {
                v.push(format!("max_dropped: {dropped} > {limit}"));
            }
        }
        v
    }

    pub fn ok(&self) -> bool {
        self.violations.is_empty() && self.failures.is_empty()
    }

    /// The percentile table and topic flow, for a terminal.
    pub fn table(&self) -> String {
        let mut out = String::new();
        out.push_str(&format!(
            "{:<12} {:<11} {:>8} {:>9} {:>9} {:>9} {:>9} {:>9}   (microseconds)\n",
            "stage", "latency", "count", "p50", "p90", "p99", "p99.9", "max"
        ));
        for s in &self.stages {
            for m in Metric::ALL {
                let x = s.summary(m);
                if x.count == 0 {
                    continue;
                }
                let name = match m {
                    Metric::Hop => "hop",
                    Metric::Process => "process",
                    Metric::Origin => "origin->out",
                    Metric::Photon => "origin->px",
                };
                out.push_str(&format!(
                    "{:<12} {:<11} {:>8} {:>9.1} {:>9.1} {:>9.1} {:>9.1} {:>9.1}\n",
                    s.stage.name(),
                    name,
                    x.count,
                    x.p50,
                    x.p90,
                    x.p99,
                    x.p999,
                    x.max
                ));
            }
        }
        out.push_str(&format!(
            "\n{:<12} {:>10} {:>10} {:>8} {:>8}\n",
            "topic", "published", "received", "dropped", "gaps"
        ));
        let mut not_final: Vec<&str> = Vec::new();
        for (t, f) in &self.topics {
            let partial = f.readers.values().any(|r| !r.counts_final);
            out.push_str(&format!(
                "{:<12} {:>10} {:>10} {:>8} {:>8}{}\n",
                t.name(),
                f.published,
                f.received(),
                f.dropped(),
                f.gaps(),
                if partial { "  *" } else { "" }
            ));
            for (name, r) in &f.readers {
                if !r.counts_final && !not_final.contains(name) {
                    not_final.push(name);
                }
            }
        }
        if !not_final.is_empty() {
            out.push_str(&format!(
                "* counts of {} stop at its last report (it ended without its final report): \
                 dropped there is its sequence gaps only\n",
                not_final.join(", ")
            ));
        }
        let devices: Vec<&common::DeviceCounters> =
            self.stages.iter().flat_map(|s| &s.devices).collect();
        if !devices.is_empty() {
            out.push_str(&format!(
                "\n{:<8} {:>9} {:>8} {:>8} {:>8} {:>7} {:>10} {:>7}\n",
                "device",
                "samples",
                "garbage",
                "rejected",
                "other",
                "losses",
                "reconnects",
                "errors"
            ));
            for d in devices {
                out.push_str(&format!(
                    "{:<8} {:>9} {:>8} {:>8} {:>8} {:>7} {:>10} {:>7}\n",
                    d.name().unwrap_or("?"),
                    d.samples,
                    d.garbage_bytes,
                    d.rejected_records,
                    d.other_station_records,
                    d.link_losses,
                    d.reconnects,
                    d.device_errors
                ));
            }
            out.push_str(
                "garbage: bytes skipped between records; rejected: malformed or out-of-range \
                 records; other: records of other tracker stations; errors: the device's own \
                 error replies\n",
            );
        }
        out.push('\n');
        out.push_str(TERMS);
        out.push('\n');
        if let Some(fps) = self.frame_rate() {
            let over = self.world_seconds(self.meta.seconds);
            out.push_str(&format!(
                "\nframes: {fps:.1} per second over the {over:.1} s worlds came in (of {:.1} s)\n",
                self.meta.seconds
            ));
        }
        if let Some(s) = &self.meta.renderer_skipped {
            out.push_str(&format!("\n{s}\n"));
        }
        if let Some(line) = self.bridge_line() {
            out.push_str(&format!("\n{line}\n"));
        }
        if !self.restarts.is_empty() {
            out.push_str(&format!(
                "\n{:<12} {:>3} {:>8} {:>12}  {:<28} lost at the restart\n",
                "restarted", "n", "at s", "downtime ms", "exit"
            ));
            for r in &self.restarts {
                let lost = match (&r.missing_from_recording, &r.lost) {
                    // A recorder's loss is what its recording misses.
                    (Some(m), _) if !m.is_empty() => m
                        .iter()
                        .map(|(t, n)| format!("{} {n}", t.name()))
                        .collect::<Vec<_>>()
                        .join(", "),
                    (Some(_), _) => "-".into(),
                    (None, Some(l)) if !l.is_empty() => l
                        .iter()
                        .map(|l| format!("{} {}", l.topic.name(), l.lost))
                        .collect::<Vec<_>>()
                        .join(", "),
                    (None, Some(_)) => "-".into(),
                    (None, None) => "? (no report after the restart)".into(),
                };
                out.push_str(&format!(
                    "{:<12} {:>3} {:>8.2} {:>12}  {:<28} {lost}\n",
                    r.stage.name(),
                    r.n,
                    r.at_s,
                    r.downtime_s()
                        .map_or("?".into(), |d| format!("{:.1}", d * 1000.0)),
                    r.exit,
                ));
                if let Some(seg) = &r.segment {
                    out.push_str(&format!("{:<12} recording goes on in {seg}\n", ""));
                }
                if let Some(e) = &r.segment_error {
                    out.push_str(&format!("{:<12} its loss is not counted: {e}\n", ""));
                }
            }
            out.push_str(
                "downtime: the exit noticed to the restarted process's first output; lost: \
                 samples published while it was down, never read by it (not counted as \
                 dropped); a recorder's: samples no segment of the recording holds, counted \
                 from their seqs (its unwritten chunk, at most [recorder] flush_ms of them, \
                 and those published while it was down)\n",
            );
        }
        for f in &self.failures {
            out.push_str(&format!("\nFAILED: {f}\n"));
        }
        for n in &self.not_judged {
            out.push_str(&format!("\nnot judged: {n}\n"));
        }
        if self.violations.is_empty() {
            out.push_str("\nbudget: ok\n");
        } else {
            out.push_str("\nbudget: VIOLATED\n");
            for v in &self.violations {
                out.push_str(&format!("  {v}\n"));
            }
        }
        out
    }

    /// The report JSON of docs/design.md.
    pub fn json(&self) -> Value {
        let summary = |x: Summary| json!({"p50": x.p50, "p90": x.p90, "p99": x.p99, "p999": x.p999, "max": x.max, "count": x.count});
        let mut stages = Map::new();
        for s in &self.stages {
            let mut m = Map::new();
            for metric in [Metric::Hop, Metric::Process, Metric::Origin] {
                m.insert(metric.key().into(), summary(s.summary(metric)));
            }
            if s.stage == Stage::Renderer {
                m.insert(
                    Metric::Photon.key().into(),
                    summary(s.summary(Metric::Photon)),
                );
            }
            m.insert("final_report".into(), json!(s.final_report));
            m.insert("cpu_s".into(), json!(s.cpu_s));
            stages.insert(s.stage.name().into(), Value::Object(m));
        }
        let mut topics = Map::new();
        for (t, f) in &self.topics {
            let readers: Map<String, Value> = f
                .readers
                .iter()
                .map(|(name, r)| {
                    (
                        (*name).to_string(),
                        json!({"received": r.received, "dropped": r.dropped, "gaps": r.gaps, "counts_final": r.counts_final, "lost_in_restarts": r.lost_in_restarts}),
                    )
                })
                .collect();
            topics.insert(
                t.name().into(),
                json!({"published": f.published, "received": f.received(), "dropped": f.dropped(), "gaps": f.gaps(), "readers": readers}),
            );
        }
        let devices: Map<String, Value> = self
            .stages
            .iter()
            .flat_map(|s| &s.devices)
            .filter_map(|d| {
                Some((
                    d.name()?.to_string(),
                    json!({
                        "samples": d.samples,
                        "garbage_bytes": d.garbage_bytes,
                        "rejected_records": d.rejected_records,
                        "other_station_records": d.other_station_records,
                        "link_losses": d.link_losses,
                        "reconnects": d.reconnects,
                        "device_errors": d.device_errors,
                    }),
                ))
            })
            .collect();
        let mut restart_counts = Map::new();
        for r in &self.restarts {
            let n = restart_counts
                .get(r.stage.name())
                .and_then(Value::as_u64)
                .unwrap_or(0);
            restart_counts.insert(r.stage.name().into(), json!(n + 1));
        }
        let restart_log: Vec<Value> = self
            .restarts
            .iter()
            .map(|r| {
                let lost = r.lost.as_ref().map(|l| {
                    l.iter()
                        .map(|l| (l.topic.name().to_string(), json!(l.lost)))
                        .collect::<Map<String, Value>>()
                });
                let unreported = r.lost.as_ref().map(|l| {
                    l.iter()
                        .map(|l| (l.topic.name().to_string(), json!(l.unreported)))
                        .collect::<Map<String, Value>>()
                });
                json!({
                    "stage": r.stage.name(),
                    "n": r.n,
                    "at_s": r.at_s,
                    "exit": r.exit,
                    "downtime_ms": r.downtime_s().map(|d| d * 1000.0),
                    "lost": lost,
                    "read_after_last_report": unreported,
                    "segment": r.segment,
                    "missing_from_recording": r.missing_from_recording.as_ref().map(|m| {
                        m.iter()
                            .map(|(t, n)| (t.name().to_string(), json!(n)))
                            .collect::<Map<String, Value>>()
                    }),
                    "segment_error": r.segment_error,
                })
            })
            .collect();
        let m = &self.meta;
        json!({
            "restarts": restart_counts,
            "restart_log": restart_log,
            "devices": devices,
            "session": {
                "file": m.session_file,
                "scene": m.scene_file,
                "source": m.source,
                "started": rfc3339(m.started),
                "seconds": m.seconds,
            },
            "version": m.version,
            "machine": {"cpus": m.cpus, "placement": m.placement},
            "renderer": {
                "skipped": m.renderer_skipped,
                "frames_per_second": self.frame_rate(),
            },
            "stages": stages,
            "topics": topics,
            "budget": {
                "ok": self.violations.is_empty(),
                "violations": self.violations,
                "not_judged": self.not_judged,
            },
            "failures": self.failures,
            "world": m.world,
            "bridge": m.bridge,
        })
    }
}

/// `t` as UTC, `2026-12-01T16:53:05Z` (days to civil date: H. Hinnant's algorithm).
pub fn rfc3339(t: std::time::SystemTime) -> String {
    let secs = t
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs()) as i64;
    let (days, rem) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stage(stage: Stage, metric: Metric, n: u64, silence_ms: u64) -> StageReport {
        let mut histograms = [
            common::latency::new_histogram(),
            common::latency::new_histogram(),
            common::latency::new_histogram(),
            common::latency::new_histogram(),
        ];
        for _ in 0..n {
            histograms[metric as usize].saturating_record(100_000);
        }
        StageReport {
            stage,
            histograms,
            counters: Vec::new(),
            heard_at: std::time::Instant::now(),
            devices: Vec::new(),
            cpu_s: None,
            final_report: true,
            silence_ns: silence_ms * 1_000_000,
            first_output_ns: 0,
            last_output_ns: 0,
        }
    }

    fn judged(frames: u64, worlds: u64, silence_ms: u64, budget: &Budget) -> Report {
        let facts = SessionFacts {
            seconds: 10.0,
            source: Stage::Acquisition,
            renders: true,
            real_time: true,
            renderer_down_s: 0.0,
        };
        Report::build(
            vec![
                stage(Stage::Acquisition, Metric::Origin, worlds, silence_ms),
                stage(Stage::Stepper, Metric::Origin, worlds, 0),
                stage(Stage::Renderer, Metric::Photon, frames, 0),
            ],
            budget,
            Vec::new(),
            &facts,
        )
    }

    #[test]
    fn a_renderer_well_below_frame_hz_fails_the_session() {
        let b = Budget::default(); // frame_hz 90, margin 0.25: at least 67.5 per second
        let r = judged(450, 1200, 10, &b);
        assert!(!r.ok());
        assert!(
            r.violations[0].starts_with("frame_hz: 45.0 frames per second < 67.5"),
            "{:?}",
            r.violations
        );
        assert!(judged(700, 1200, 10, &b).ok());
        // A world at 60 Hz cannot be drawn at 90: judged against the world's rate.
        assert!(judged(550, 600, 10, &b).ok());
        let r = judged(300, 600, 10, &b);
        assert!(
            r.violations[0].contains("the world's rate 60.0"),
            "{:?}",
            r.violations
        );
    }

    /// Issue 28: a remote viewer started 2 s before its session and left 5 s after it had
    /// worlds for 5 s of its 12: its frame rate is judged over those 5 s, not diluted by the
    /// 7 s without a world to draw; a renderer that stops drawing while worlds still come
    /// still fails.
    #[test]
    fn frame_rate_is_judged_over_the_time_worlds_were_there() {
        let b = Budget::default(); // frame_hz 90, margin 0.25
        let facts = SessionFacts {
            seconds: 12.0,
            source: Stage::Bridge,
            renders: true,
            real_time: true,
            renderer_down_s: 0.0,
        };
        let judge = |frames: u64| {
            let mut bridge = stage(Stage::Bridge, Metric::Origin, 600, 0);
            (bridge.first_output_ns, bridge.last_output_ns) = (2_000_000_000, 7_000_000_000);
            // The bridge publishes the worlds it takes in.
            bridge.counters.push(common::TopicCounter {
                topic: Topic::World as u32,
                role: 0,
                count: 600,
                gaps: 0,
                last_seq: 599,
            });
            Report::build(
                vec![bridge, stage(Stage::Renderer, Metric::Photon, frames, 0)],
                &b,
                Vec::new(),
                &facts,
            )
        };
        // 120 worlds a second for 5 s, drawn at 88 frames a second: kept (over 12 s it would
        // read 36.7 frames a second).
        let r = judge(440);
        assert!(r.ok(), "{:?}", r.violations);
        // Drawn for 2 s of the 5: 36 a second < 67.5.
        let r = judge(180);
        assert!(
            r.violations[0].starts_with("frame_hz: 36.0 frames per second < 67.5"),
            "{:?}",
            r.violations
        );
    }

    #[test]
    fn a_silent_source_fails_the_session() {
        let b = Budget::default();
        let r = judged(900, 1200, 1500, &b);
        assert_eq!(
            r.violations,
            vec!["source_silence_ms: the source (acquisition) delivered no sample for 1500 ms > 1000"]
        );
        let r = judged(0, 0, 10_000, &b);
        assert!(
            r.violations[0].contains("delivered no sample in 10.0 s"),
            "{:?}",
            r.violations
        );
    }

    fn counter(
        topic: Topic,
        role: u32,
        count: u64,
        gaps: u64,
        last_seq: u64,
    ) -> common::TopicCounter {
        common::TopicCounter {
            topic: topic as u32,
            role,
            count,
            gaps,
            last_seq,
        }
    }

    /// Issue 16: a restarted reader's counts add to its dead incarnation's; the seqs between
    /// them are the restart's (split at what was published when the death was noticed), not
    /// gaps, and the budget's `max_dropped` does not count them.
    #[test]
    fn a_restarted_stages_reports_merge_and_its_losses_are_the_restarts() {
        let mut dead = stage(Stage::Kinematics, Metric::Hop, 90, 0);
        dead.final_report = false;
        // It read seqs 0..=99 by its last report (2 gaps), and published 100 hands.
        dead.counters = vec![
            counter(Topic::Tracker, 1, 98, 2, 99),
            counter(Topic::Hand, 0, 100, 0, 99),
        ];
        // Restarted: its first tracker was seq 130, its last 229, one gap; hands went on.
        let mut next = stage(Stage::Kinematics, Metric::Hop, 10, 0);
        next.counters = vec![
            counter(Topic::Tracker, 1, 99, 1, 229),
            counter(Topic::Hand, 0, 215, 0, 214),
        ];
        // 112 trackers were published when its death was noticed.
        let (merged, lost) = dead.then(next, &[(Topic::Tracker, 112)]);
        assert_eq!(
            lost,
            [RestartLoss {
                topic: Topic::Tracker,
                lost: 18,
                unreported: 12
            }]
        );
        assert_eq!(merged.counters[0], counter(Topic::Tracker, 1, 197, 3, 229));
        assert_eq!(merged.counters[1], counter(Topic::Hand, 0, 215, 0, 214));
        assert_eq!(merged.summary(Metric::Hop).count, 100);
        assert!(merged.final_report);

        let restart = Restart {
            stage: Stage::Kinematics,
            n: 1,
            at_s: 1.0,
            exit: "signal: 9 (SIGKILL)".into(),
            noticed_ns: 1_000_000_000,
            first_output_ns: Some(1_150_000_000),
            lost: Some(lost),
            published_at_death: Vec::new(),
            segment: None,
            missing_from_recording: None,
            segment_error: None,
        };
        assert_eq!(restart.downtime_s(), Some(0.15));
        let mut source = stage(Stage::Acquisition, Metric::Origin, 10, 0);
        source.counters = vec![counter(Topic::Tracker, 0, 230, 0, 229)];
        let budget = Budget {
            max_dropped: Some(0),
            ..Budget::default()
        };
        let r = Report::build_with_restarts(
            vec![source, merged],
            &budget,
            Vec::new(),
            vec![restart],
            &SessionFacts::default(),
        );
        let flow = &r.topics[&Topic::Tracker].readers["kinematics"];
        assert_eq!(
            (flow.received, flow.lost_in_restarts, flow.dropped),
            (197, 30, 3)
        );
        assert!(
            r.table().contains("kinematics     1     1.00        150.0"),
            "{}",
            r.table()
        );
        assert_eq!(r.json()["restarts"]["kinematics"], 1);
        assert_eq!(r.json()["restart_log"][0]["lost"]["tracker"], 18);
    }

    #[test]
    fn times_are_utc_dates() {
        let at = |s| std::time::UNIX_EPOCH + std::time::Duration::from_secs(s);
        assert_eq!(rfc3339(at(0)), "1970-01-01T00:00:00Z");
        assert_eq!(rfc3339(at(951_782_400)), "2000-02-29T00:00:00Z");
        assert_eq!(rfc3339(at(1_796_143_985)), "2026-12-01T16:53:05Z");
    }
}
