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
        })
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
}

impl Default for SessionFacts {
    fn default() -> Self {
        SessionFacts {
            seconds: 0.0,
            source: Stage::Acquisition,
            renders: false,
            real_time: true,
        }
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
    pub meta: Meta,
}

impl Report {
    pub fn build(
        mut stages: Vec<StageReport>,
        budget: &Budget,
        failures: Vec<String>,
        facts: &SessionFacts,
    ) -> Report {
        stages.sort_by_key(|s| s.stage);
        let mut topics: BTreeMap<Topic, TopicFlow> = BTreeMap::new();
        for s in &stages {
            for c in &s.counters {
                let Some(topic) = Topic::from_u32(c.topic) else {
                    continue;
                };
                let flow = topics.entry(topic).or_default();
                if c.role == 0 {
                    flow.published += c.count;
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
                    // Lost on the way: gaps in seq, and whatever was published but never read;
                    // a reader without its final report is known only up to its last one.
                    let dropped = if s.final_report {
                        c.gaps.max(flow.published.saturating_sub(c.count))
                    } else {
                        c.gaps
                    };
                    flow.readers.insert(
                        s.stage.name(),
                        ReaderFlow {
                            received: c.count,
                            dropped,
                            gaps: c.gaps,
                            counts_final: s.final_report,
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
        let worlds = self
            .stage(Stage::Stepper)
            .map_or(0, |s| s.summary(Metric::Origin).count);
        let fps = frames as f64 / facts.seconds;
        // A frame is drawn for each new world state: fewer worlds than frame_hz is not the
        // renderer's shortfall.
        let world_hz = worlds as f64 / facts.seconds;
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

    /// Frames per second the renderer drew, when it drew.
    pub fn frame_rate(&self) -> Option<f64> {
        let s = self.stage(Stage::Renderer)?;
        let n = s.summary(Metric::Photon).count;
        (n > 0 && self.meta.seconds > 0.0).then(|| n as f64 / self.meta.seconds)
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
            out.push_str(&format!(
                "\nframes: {fps:.1} per second over {:.1} s\n",
                self.meta.seconds
            ));
        }
        if let Some(s) = &self.meta.renderer_skipped {
            out.push_str(&format!("\n{s}\n"));
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
                        json!({"received": r.received, "dropped": r.dropped, "gaps": r.gaps, "counts_final": r.counts_final}),
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
        let m = &self.meta;
        json!({
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
        }
    }

    fn judged(frames: u64, worlds: u64, silence_ms: u64, budget: &Budget) -> Report {
        let facts = SessionFacts {
            seconds: 10.0,
            source: Stage::Acquisition,
            renders: true,
            real_time: true,
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

    #[test]
    fn times_are_utc_dates() {
        let at = |s| std::time::UNIX_EPOCH + std::time::Duration::from_secs(s);
        assert_eq!(rfc3339(at(0)), "1970-01-01T00:00:00Z");
        assert_eq!(rfc3339(at(951_782_400)), "2000-02-29T00:00:00Z");
        assert_eq!(rfc3339(at(1_796_143_985)), "2026-12-01T16:53:05Z");
    }
}
