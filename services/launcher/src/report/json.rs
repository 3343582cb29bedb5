//! The report JSON of docs/design.md, written with serde: each part of the file is a view
//! struct here that borrows from the [`Report`] and derives `Serialize`, so the file's shape
//! reads off these types rather than off code that builds it key by key.
//!
//! The report's users parse this file (tests, the benchmarks, people's scripts): its keys,
//! their values and how numbers are written stay as they were. Keys come out sorted, as they
//! always have: [`Report::json`] goes through [`serde_json::Value`], whose map (serde_json
//! without `preserve_order`) keeps its keys in order; the fields below are declared in that
//! order too, so the views written directly give the same text. Counts are integers, times
//! and latencies floats (`0.0`, never `0`), and an absent value is `null`.

use std::collections::BTreeMap;

use common::latency::{Metric, Summary};
use common::{DeviceCounters, Stage};
use serde::Serialize;
use serde_json::Value;

use super::{ReaderFlow, Report, Restart, RestartLoss, StageReport, TopicFlow};

impl Report {
    /// The report JSON of docs/design.md.
    pub fn json(&self) -> Value {
        // Every map of the views is keyed by a string: nothing here can fail to convert.
        serde_json::to_value(ReportJson::of(self))
            .expect("the report's JSON views have string keys only")
    }
}

/// The whole file.
#[derive(Serialize)]
struct ReportJson<'a> {
    /// What the bridge did (`bridge.json`), as it wrote it.
    bridge: &'a Option<Value>,
    budget: BudgetJson<'a>,
    devices: BTreeMap<&'static str, DeviceJson>,
    failures: &'a [String],
    machine: MachineJson<'a>,
    renderer: RendererJson<'a>,
    restart_log: Vec<RestartJson<'a>>,
    /// Per restarted stage, how many times.
    restarts: BTreeMap<&'static str, u64>,
    session: SessionJson<'a>,
    stages: BTreeMap<&'static str, StageJson>,
    topics: BTreeMap<&'static str, TopicJson>,
    version: &'a str,
    /// The world's outcome (`simulate --json`'s form), as the stepper wrote it.
    world: &'a Option<Value>,
}

impl<'a> ReportJson<'a> {
    fn of(report: &'a Report) -> ReportJson<'a> {
        let m = &report.meta;
        let mut restarts: BTreeMap<&'static str, u64> = BTreeMap::new();
        for r in &report.restarts {
            *restarts.entry(r.stage.name()).or_insert(0) += 1;
        }
        ReportJson {
            bridge: &m.bridge,
            budget: BudgetJson {
                not_judged: &report.not_judged,
                ok: report.violations.is_empty(),
                violations: &report.violations,
            },
            devices: report
                .stages
                .iter()
                .flat_map(|s| &s.devices)
                .filter_map(|d| {
                    let name = d.name()?;
                    Some((name, DeviceJson::of(d, m.refused.get(name))))
                })
                .collect(),
            failures: &report.failures,
            machine: MachineJson {
                cpus: m.cpus,
                load: m.machine_load.map(|l| LoadJson {
                    looked_loaded: l.looked_loaded(),
                    others_cpu_s: l.others_cpu_s,
                    others_fraction: l.others_fraction(),
                    seconds: l.seconds,
                    session_cpu_s: l.session_cpu_s,
                    steal_s: l.steal_s,
                }),
                placement: &m.placement,
            },
            renderer: RendererJson {
                frames_per_second: report.frame_rate(),
                skipped: &m.renderer_skipped,
            },
            restart_log: report.restarts.iter().map(RestartJson::of).collect(),
            restarts,
            session: SessionJson {
                file: &m.session_file,
                scene: &m.scene_file,
                seconds: m.seconds,
                source: m.source,
                started: rfc3339(m.started),
            },
            stages: report
                .stages
                .iter()
                .map(|s| (s.stage.name(), StageJson::of(s)))
                .collect(),
            topics: report
                .topics
                .iter()
                .map(|(t, f)| (t.name(), TopicJson::of(f)))
                .collect(),
            version: &m.version,
            world: &m.world,
        }
    }
}

#[derive(Serialize)]
struct BudgetJson<'a> {
    not_judged: &'a [String],
    ok: bool,
    violations: &'a [String],
}

/// What a device's driver counted (the acquisition process with devices).
#[derive(Serialize)]
struct DeviceJson {
    device_errors: u64,
    garbage_bytes: u64,
    link_losses: u64,
    other_station_records: u64,
    reconnects: u64,
    /// A source's refusals by kind (`rejected_records` is their total), when its stage left
    /// them ([`super::refusals`]); absent otherwise.
    #[serde(skip_serializing_if = "Option::is_none")]
    refused: Option<BTreeMap<String, u64>>,
    rejected_records: u64,
    samples: u64,
}

impl DeviceJson {
    fn of(d: &DeviceCounters, refused: Option<&BTreeMap<String, u64>>) -> DeviceJson {
        DeviceJson {
            device_errors: d.device_errors,
            garbage_bytes: d.garbage_bytes,
            link_losses: d.link_losses,
            other_station_records: d.other_station_records,
            reconnects: d.reconnects,
            refused: refused.cloned(),
            rejected_records: d.rejected_records,
            samples: d.samples,
        }
    }
}

#[derive(Serialize)]
struct MachineJson<'a> {
    cpus: usize,
    /// What other processes did with the machine while the session ran (null where
    /// `/proc/stat` could not be read).
    load: Option<LoadJson>,
    placement: &'a Option<String>,
}

/// `crate::machine::MachineLoad`, with its verdict.
#[derive(Serialize)]
struct LoadJson {
    /// Others took more than `machine::LOADED_FRACTION` of the CPUs' time.
    looked_loaded: bool,
    others_cpu_s: f64,
    /// (others_cpu_s + steal_s) / (seconds x cpus).
    others_fraction: f64,
    seconds: f64,
    session_cpu_s: f64,
    steal_s: f64,
}

#[derive(Serialize)]
struct RendererJson<'a> {
    frames_per_second: Option<f64>,
    skipped: &'a Option<String>,
}

/// One restart of a process by the launcher.
#[derive(Serialize)]
struct RestartJson<'a> {
    at_s: f64,
    downtime_ms: Option<f64>,
    exit: &'a str,
    /// Per topic the stage reads, published while it was down; null until the restarted
    /// process reported.
    lost: Option<BTreeMap<&'static str, u64>>,
    missing_from_recording: Option<BTreeMap<&'static str, u64>>,
    n: u32,
    /// Per topic, read by the dead process after its last report.
    read_after_last_report: Option<BTreeMap<&'static str, u64>>,
    segment: &'a Option<String>,
    segment_error: &'a Option<String>,
    stage: &'static str,
}

impl<'a> RestartJson<'a> {
    fn of(r: &'a Restart) -> RestartJson<'a> {
        let per_topic = |f: fn(&RestartLoss) -> u64| {
            r.lost
                .as_ref()
                .map(|l| l.iter().map(|l| (l.topic.name(), f(l))).collect())
        };
        RestartJson {
            at_s: r.at_s,
            downtime_ms: r.downtime_s().map(|d| d * 1000.0),
            exit: &r.exit,
            lost: per_topic(|l| l.lost),
            missing_from_recording: r
                .missing_from_recording
                .as_ref()
                .map(|m| m.iter().map(|(t, n)| (t.name(), *n)).collect()),
            n: r.n,
            read_after_last_report: per_topic(|l| l.unreported),
            segment: &r.segment,
            segment_error: &r.segment_error,
            stage: r.stage.name(),
        }
    }
}

#[derive(Serialize)]
struct SessionJson<'a> {
    file: &'a str,
    scene: &'a str,
    seconds: f64,
    source: &'a str,
    /// UTC, [`rfc3339`].
    started: String,
}

/// One stage: its latencies (keyed by [`Metric::key`]; origin to photon the renderer's only),
/// whether it sent its final report, and the CPU time it used.
#[derive(Serialize)]
struct StageJson {
    cpu_s: Option<f64>,
    final_report: bool,
    #[serde(flatten)]
    latencies: BTreeMap<&'static str, SummaryJson>,
}

impl StageJson {
    fn of(s: &StageReport) -> StageJson {
        let mut metrics = vec![Metric::Hop, Metric::Process, Metric::Origin];
        if s.stage == Stage::Renderer {
            metrics.push(Metric::Photon);
        }
        if s.stage == Stage::Webxr {
            // The headset's page: a hands frame sent to the world that answers it drawn, and
            // its JavaScript time per XR frame.
            metrics.extend([Metric::Photon, Metric::Page]);
        }
        StageJson {
            cpu_s: s.cpu_s,
            final_report: s.final_report,
            latencies: metrics
                .into_iter()
                .map(|m| (m.key(), SummaryJson::of(s.summary(m))))
                .collect(),
        }
    }
}

/// A latency's percentiles, microseconds, and how many samples it holds.
#[derive(Serialize)]
struct SummaryJson {
    count: u64,
    max: f64,
    p50: f64,
    p90: f64,
    p99: f64,
    p999: f64,
}

impl SummaryJson {
    fn of(x: Summary) -> SummaryJson {
        SummaryJson {
            count: x.count,
            max: x.max,
            p50: x.p50,
            p90: x.p90,
            p99: x.p99,
            p999: x.p999,
        }
    }
}

/// One topic: published, and of its readers together the fewest received, the dropped, and
/// the most gaps any one reader saw (a loss before the bus counted once); then each reader's
/// own counts.
#[derive(Serialize)]
struct TopicJson {
    dropped: u64,
    gaps: u64,
    published: u64,
    readers: BTreeMap<&'static str, ReaderJson>,
    received: u64,
}

impl TopicJson {
    fn of(f: &TopicFlow) -> TopicJson {
        TopicJson {
            dropped: f.dropped(),
            gaps: f.gaps(),
            published: f.published,
            readers: f
                .readers
                .iter()
                .map(|(name, r)| (*name, ReaderJson::of(r)))
                .collect(),
            received: f.received(),
        }
    }
}

/// What one reading stage saw of a topic ([`ReaderFlow`]).
#[derive(Serialize)]
struct ReaderJson {
    counts_final: bool,
    dropped: u64,
    gaps: u64,
    lost_in_restarts: u64,
    received: u64,
}

impl ReaderJson {
    fn of(r: &ReaderFlow) -> ReaderJson {
        ReaderJson {
            counts_final: r.counts_final,
            dropped: r.dropped,
            gaps: r.gaps,
            lost_in_restarts: r.lost_in_restarts,
            received: r.received,
        }
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
