//! The session report: each stage's latency histograms and topic counters, merged, judged
//! against the session's `[budget]`, printed as a table and written as JSON (DESIGN.md).

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

/// The merged report of a session.
pub struct Report {
    /// Stages in pipeline order.
    pub stages: Vec<StageReport>,
    pub topics: BTreeMap<Topic, TopicFlow>,
    pub violations: Vec<String>,
    /// Stages that failed (crashed, or sent no final report).
    pub failures: Vec<String>,
}

impl Report {
    pub fn build(mut stages: Vec<StageReport>, budget: &Budget, failures: Vec<String>) -> Report {
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
                    // Lost on the way: gaps in seq, and whatever was published but never read.
                    let dropped = c.gaps.max(flow.published.saturating_sub(c.count));
                    flow.readers.insert(
                        s.stage.name(),
                        ReaderFlow {
                            received: c.count,
                            dropped,
                            gaps: c.gaps,
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
            failures,
        };
        report.violations = report.judge(budget);
        report
    }

    fn stage(&self, stage: Stage) -> Option<&StageReport> {
        self.stages.iter().find(|s| s.stage == stage)
    }

    fn judge(&self, b: &Budget) -> Vec<String> {
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
        if let Some(limit_ms) = b.origin_to_photon_p99_ms {
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
        for (t, f) in &self.topics {
            out.push_str(&format!(
                "{:<12} {:>10} {:>10} {:>8} {:>8}\n",
                t.name(),
                f.published,
                f.received(),
                f.dropped(),
                f.gaps()
            ));
        }
        for f in &self.failures {
            out.push_str(&format!("\nFAILED: {f}\n"));
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

    /// The report JSON of DESIGN.md.
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
                        json!({"received": r.received, "dropped": r.dropped, "gaps": r.gaps}),
                    )
                })
                .collect();
            topics.insert(
                t.name().into(),
                json!({"published": f.published, "received": f.received(), "dropped": f.dropped(), "gaps": f.gaps(), "readers": readers}),
            );
        }
        json!({
            "stages": stages,
            "topics": topics,
            "budget": {"ok": self.violations.is_empty(), "violations": self.violations},
            "failures": self.failures,
        })
    }
}
