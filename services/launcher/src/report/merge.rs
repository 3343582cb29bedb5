//! Merging: the reports of a stage's incarnations (a process the launcher restarted) into
//! one, and every stage's topic counters into the flow of each topic, what the restarts lost
//! kept apart from what was dropped. The merged [`Report`] is then judged (`budget`).

use std::collections::BTreeMap;

use common::config::session::Budget;
use common::Topic;

use super::{Meta, ReaderFlow, Report, Restart, RestartLoss, SessionFacts, StageReport, TopicFlow};

impl StageReport {
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
                    // A source that reads a topic back (a replay pacing itself on `world`, the
                    // webxr stage sending each world to its page) stops first, by design,
                    // before the stepper's last worlds: what is published after its last pass
                    // was never its to read, so only its seq gaps count as lost.
                    let feedback = s.stage.role() == common::topic::Role::Source;
                    let dropped = if s.final_report && !feedback {
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
}
