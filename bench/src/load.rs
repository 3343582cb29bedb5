//! `handblocks bench latency load`: the pipeline under load, every topic recorded.
//!
//! The scripted hand at 1 kHz (eight times the step rate: every hand sample still makes a
//! world sample) for 60 s (`--quick`: 5 s), the session's renderer on as it says, the recorder
//! writing every topic. The verdict is the flow, not a timing: every sample published is
//! received by every reader (0 dropped, 0 gaps) and is in the recording; the latency of each
//! stage under that load is the figure, with an `.hgrm` file per histogram and a plot on
//! HdrHistogram's "nines" axis.

use std::path::{Path, PathBuf};
use std::time::Duration;

use common::config::session::Override;
use common::latency::Metric;
use common::Topic;
use recording::Recording;
use serde_json::{json, Map, Value};

use crate::hgrm::percentile_distribution;
use crate::latency::summary_json;
use crate::page::{self, Provenance};
use crate::plot::{Axis, Figure, Join, Panel, Series};

/// The source rate under load.
pub const LOAD_RATE_HZ: u32 = 1000;

/// Options of `handblocks bench latency load`.
pub struct LoadBench {
    pub exe: PathBuf,
    pub session: PathBuf,
    pub out_dir: PathBuf,
    /// 5 s instead of 60.
    pub quick: bool,
}

impl LoadBench {
    pub fn seconds(&self) -> f64 {
        if self.quick {
            5.0
        } else {
            60.0
        }
    }
}

/// Runs the load; writes `load.json`, `load.md`, `load.png` and `hgrm/load-*.hgrm` into the
/// output folder and returns the JSON.
pub fn run(b: &LoadBench) -> Result<Value, Box<dyn std::error::Error>> {
    let seconds = b.seconds();
    std::fs::create_dir_all(&b.out_dir)?;
    // The recording is the check, not an output: it goes once read (~100 MB a minute).
    let recording = b.out_dir.join(format!("load-{}.mcap", std::process::id()));
    eprintln!(
        "bench latency load: {} at {LOAD_RATE_HZ} Hz for {seconds:.0} s, every topic recorded ...",
        b.session.display()
    );
    let set = |key: &str, value: &str| Override::parse(&format!("{key}={value}"));
    let overrides = vec![
        set("source.kind", "\"scripted\"")?,
        set("source.rate_hz", "1000")?,
    ];
    let outcome = launcher::launch(&launcher::LaunchOptions {
        session: b.session.clone(),
        duration: Some(Duration::from_secs_f64(seconds)),
        exe: b.exe.clone(),
        progress: true,
        record: Some(recording.clone()),
        force: true,
        overrides,
        ..launcher::LaunchOptions::default()
    });
    let recorded = match &outcome {
        Ok(_) => Some(Recording::open(&recording).map(|r| r.stats())),
        Err(_) => None,
    };
    let _ = std::fs::remove_file(&recording);
    let outcome = outcome?;
    let stats = recorded.transpose()?;
    let report = &outcome.report;

    let mut topics = Map::new();
    let (mut dropped, mut gaps, mut unrecorded) = (0u64, 0u64, 0u64);
    for (t, f) in &report.topics {
        let rec = stats.map(|s| s[*t as usize]);
        dropped += f.dropped();
        gaps += f.gaps() + rec.map_or(0, |r| r.gaps);
        if *t != Topic::Latency {
            unrecorded += f.published.saturating_sub(rec.map_or(0, |r| r.messages));
        }
        topics.insert(
            t.name().into(),
            json!({
                "published": f.published, "received": f.received(), "dropped": f.dropped(),
                "gaps": f.gaps(),
                "recorded": rec.map(|r| r.messages), "recorded_gaps": rec.map(|r| r.gaps),
            }),
        );
    }
    let hgrm_dir = b.out_dir.join("hgrm");
    std::fs::create_dir_all(&hgrm_dir)?;
    let mut stages = Map::new();
    let mut files = 0;
    for s in &report.stages {
        let mut m = Map::new();
        for metric in Metric::ALL {
            let h = &s.histograms[metric as usize];
            if h.is_empty() {
                continue;
            }
            m.insert(metric.key().into(), summary_json(s.summary(metric)));
            std::fs::write(
                hgrm_dir.join(format!(
                    "load-{}-{}.hgrm",
                    s.stage.name(),
                    metric_name(metric)
                )),
                percentile_distribution(h, 1000.0),
            )?;
            files += 1;
        }
        stages.insert(s.stage.name().into(), Value::Object(m));
    }
    let value = json!({
        "quick": b.quick,
        "rate_hz": LOAD_RATE_HZ,
        "seconds": report.meta.seconds,
        "dropped": dropped,
        "gaps": gaps,
        "published_not_recorded": unrecorded,
        "budget_ok": report.ok(),
        "violations": report.violations,
        "failures": report.failures,
        "topics": topics,
        "stages": stages,
    });
    std::fs::write(
        b.out_dir.join("load.json"),
        serde_json::to_string_pretty(&value)? + "\n",
    )?;
    crate::latency::merge_into_latency_json(&b.out_dir, "load", value.clone())?;
    let provenance = Provenance::of_this_run(b.quick, &b.out_dir);
    std::fs::write(
        b.out_dir.join("load.md"),
        markdown(&value, report, &provenance),
    )?;
    let drawn = figure(report).write_png(&b.out_dir.join("load.png"))?;
    eprintln!(
        "bench latency load: {dropped} dropped, {gaps} gaps, {unrecorded} not recorded; wrote {}, \
         load.md{}, and {files} .hgrm files in {}",
        b.out_dir.join("load.json").display(),
        if drawn { ", load.png" } else { "" },
        hgrm_dir.display()
    );
    Ok(value)
}

fn metric_name(m: Metric) -> &'static str {
    match m {
        Metric::Hop => "hop",
        Metric::Process => "process",
        Metric::Origin => "origin",
        Metric::Photon => "photon",
        Metric::Page => "page_js",
    }
}

fn markdown(v: &Value, report: &launcher::report::Report, provenance: &Provenance) -> String {
    let seconds = v["seconds"].as_f64().unwrap_or(0.0);
    let what = format!(
        "The whole pipeline under load: the session's processes with the scripted hand at \
         {LOAD_RATE_HZ} Hz (eight times the step rate, so every hand sample still makes a world \
         sample) for {seconds:.1} s{}, the recorder writing every topic. The verdict is the \
         flow, not a timing: every sample published must be received by every reader \
         (0 dropped, 0 gaps) and be in the recording. The latency of each stage under that \
         load is the figure; there is no peer here (the bare hop beside the pipeline is \
         [pipeline.md](pipeline.md)).\n\n\
         How to read it: *hop* is a sample's publish by the stage before to its receive here \
         (the bus and the wake-up), *process* this stage's own work, *origin* the age of what \
         the stage sends (from when its source sample entered the pipeline), *photon* the \
         renderer's origin to the frame's GPU work complete. The figure draws hop and origin \
         by percentile, p50 to the tail, on HdrHistogram's log axis; every histogram is also \
         an `.hgrm` file under `hgrm/`.",
        if v["quick"].as_bool() == Some(true) {
            " (quick run: 5 s instead of 60)"
        } else {
            ""
        }
    );
    let mut md = page::head(
        "Benchmark: the pipeline at 1 kHz, every topic recorded",
        &what,
        provenance,
    );
    md.push_str(&format!(
        "**{} dropped, {} gaps, {} published but not recorded**; the session's budget {}.\n\n",
        v["dropped"],
        v["gaps"],
        v["published_not_recorded"],
        if report.ok() { "held" } else { "was VIOLATED" }
    ));
    md.push_str(&page::figure(
        "hop into each stage and origin to each stage's output by percentile, one line per stage",
        "load.png",
    ));
    md.push_str(
        "## Latency per stage\n\n| stage | metric | count | p50 (us) | p90 | p99 | p99.9 | max |\n|---|---|---|---|---|---|---|---|\n",
    );
    for s in &report.stages {
        for metric in Metric::ALL {
            let x = s.summary(metric);
            if x.count == 0 {
                continue;
            }
            md.push_str(&format!(
                "| {} | {} | {} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} |\n",
                s.stage.name(),
                metric_name(metric),
                x.count,
                x.p50,
                x.p90,
                x.p99,
                x.p999,
                x.max
            ));
        }
    }
    md.push_str("\n## Flow per topic\n\n| topic | published | received | dropped | gaps | recorded |\n|---|---|---|---|---|---|\n");
    if let Some(topics) = v["topics"].as_object() {
        for (t, f) in topics {
            md.push_str(&format!(
                "| {t} | {} | {} | {} | {} | {} |\n",
                f["published"], f["received"], f["dropped"], f["gaps"], f["recorded"]
            ));
        }
    }
    for line in report.violations.iter().chain(&report.failures) {
        md.push_str(&format!("\n- {line}"));
    }
    md.push('\n');
    md
}

/// Latency by percentile on HdrHistogram's "nines" axis: a panel for the hop into each stage
/// and one for each stage's origin -> out, a line per stage.
fn figure(report: &launcher::report::Report) -> Figure {
    let panel = |metric: Metric, title: &str| Panel {
        title: title.to_string(),
        x: Axis::nines(),
        y: Axis::log("latency (us)"),
        series: report
            .stages
            .iter()
            .filter(|s| !s.histograms[metric as usize].is_empty())
            .map(|s| Series::nines(s.stage.name(), &s.histograms[metric as usize]))
            .collect(),
        marked: Vec::new(),
        join: Join::Curve,
    };
    Figure {
        panels: vec![
            panel(Metric::Hop, "hop into each stage, 1 kHz"),
            panel(Metric::Origin, "origin -> each stage's output, 1 kHz"),
        ],
        columns: 2,
        panel_width: 500,
        panel_height: 380,
        column_weights: Vec::new(),
    }
}

/// The `.hgrm` files a load run writes, for the tests.
pub fn hgrm_files(out_dir: &Path) -> Vec<PathBuf> {
    std::fs::read_dir(out_dir.join("hgrm"))
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            p.file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with("load-"))
        })
        .collect()
}
