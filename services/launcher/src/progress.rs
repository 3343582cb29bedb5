//! The once-a-second progress line: how far the session is, and the p99 of origin -> world and
//! origin -> photon, both since the start and over the last second, so that a budget breach
//! shows when it happens rather than in the report at the end.
//!
//! The stages' reports hold cumulative histograms; the last second's is the newest one less
//! the one the previous line saw (hdrhistogram's `subtract`), kept here between lines.

use std::collections::BTreeMap;
use std::time::Duration;

use common::config::session::Budget;
use common::latency::{new_histogram, Metric, Summary};
use common::Stage;
use hdrhistogram::Histogram;

use crate::report::StageReport;

/// One watched figure: a stage's metric, the cumulative histogram the last line saw, and the
/// newest stretch's summary (kept while a stage has sent no report since: each reports about
/// once a second, not in step with the lines).
struct Watched {
    stage: Stage,
    metric: Metric,
    seen: Histogram<u64>,
    recent: Summary,
}

/// What the progress lines remember between them.
pub(crate) struct Progress {
    world: Watched,
    photon: Watched,
    world_budget_us: Option<f64>,
    photon_budget_ms: Option<f64>,
}

/// The p99 over everything and over the newest part (what `seen` did not hold); None when the
/// stage has not reported.
fn p99s(w: &mut Watched, reports: &BTreeMap<Stage, StageReport>) -> Option<(Summary, Summary)> {
    let now = &reports.get(&w.stage)?.histograms[w.metric as usize];
    if now.len() != w.seen.len() {
        let mut recent = now.clone();
        // A stage that restarted reports less than before: then all of it is recent.
        if recent.subtract(&w.seen).is_err() {
            recent = now.clone();
        }
        w.recent = Summary::of(&recent);
        w.seen = now.clone();
    }
    Some((Summary::of(now), w.recent))
}

impl Progress {
    pub(crate) fn new(budget: &Budget) -> Progress {
        let watch = |stage, metric| Watched {
            stage,
            metric,
            seen: new_histogram(),
            recent: Summary::default(),
        };
        Progress {
            world: watch(Stage::Stepper, Metric::Origin),
            photon: watch(Stage::Renderer, Metric::Photon),
            world_budget_us: budget.origin_to_world_p99_us,
            photon_budget_ms: budget.origin_to_photon_p99_ms,
        }
    }

    /// `handblocks:   3.0 s  world states 361  origin->world p99 311.3 us (last 1 s 290.1)
    /// frames 270  origin->photon p99 18.7 ms (last 1 s 17.9)`, and `OVER BUDGET` after a
    /// figure whose last second broke its budget.
    pub(crate) fn line(
        &mut self,
        elapsed: Duration,
        reports: &BTreeMap<Stage, StageReport>,
    ) -> String {
        let mut line = format!("handblocks: {:5.1} s", elapsed.as_secs_f64());
        let over = |p99: f64, budget: Option<f64>| {
            if budget.is_some_and(|b| p99 > b) {
                " OVER BUDGET"
            } else {
                ""
            }
        };
        if let Some((all, recent)) = p99s(&mut self.world, reports) {
            line.push_str(&format!(
                "  world states {}  origin->world p99 {:.1} us (last 1 s {:.1}{})",
                all.count,
                all.p99,
                recent.p99,
                over(recent.p99, self.world_budget_us)
            ));
        }
        if let Some((all, recent)) = p99s(&mut self.photon, reports) {
            line.push_str(&format!(
                "  frames {}  origin->photon p99 {:.1} ms (last 1 s {:.1}{})",
                all.count,
                all.p99 / 1000.0,
                recent.p99 / 1000.0,
                over(recent.p99 / 1000.0, self.photon_budget_ms)
            ));
        }
        line
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stepper_report(origin_us: &[u64]) -> StageReport {
        let mut origin = new_histogram();
        for us in origin_us {
            origin.record(us * 1000).unwrap();
        }
        let mut report = StageReport::empty(Stage::Stepper);
        report.histograms[Metric::Origin as usize] = origin;
        report
    }

    /// The last second's p99 is that of the samples since the previous line, and a breach of
    /// the budget in it is flagged even while the whole session's p99 is still within it.
    #[test]
    fn the_line_shows_the_last_seconds_p99_and_flags_a_breach() {
        let budget = Budget {
            origin_to_world_p99_us: Some(1000.0),
            ..Budget::default()
        };
        let mut p = Progress::new(&budget);
        let mut reports = BTreeMap::new();
        let calm: Vec<u64> = vec![200; 1000];
        reports.insert(Stage::Stepper, stepper_report(&calm));
        let first = p.line(Duration::from_secs(1), &reports);
        assert!(first.contains("world states 1000"), "{first}");
        assert!(
            first.contains("p99 200.") && !first.contains("OVER"),
            "{first}"
        );
        // The next second: 5 samples at 5 ms. Cumulatively p99 is still 200 us.
        let mut both = calm.clone();
        both.extend(std::iter::repeat_n(5000, 5));
        reports.insert(Stage::Stepper, stepper_report(&both));
        let second = p.line(Duration::from_secs(2), &reports);
        assert!(second.contains("origin->world p99 200."), "{second}");
        assert!(second.contains("(last 1 s 50"), "{second}");
        assert!(second.contains("OVER BUDGET"), "{second}");
        // No new report: the last stretch's figure stays.
        let third = p.line(Duration::from_secs(3), &reports);
        assert!(
            third.contains("(last 1 s 50") && third.contains("OVER BUDGET"),
            "{third}"
        );
        assert!(
            !second.contains("photon"),
            "no renderer, no photon figure: {second}"
        );
    }
}
