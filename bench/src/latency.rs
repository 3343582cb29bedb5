//! `handblocks bench latency`: what the pipeline adds to the transport.
//!
//! The peer is the floor any stage could reach on this machine at this moment: the fastest
//! bare wake-up measured in this run (issue 46). Three bare hops run at the session's rate
//! with hand-sized samples: iceoryx2 (a second process publishes and notifies; this one
//! sleeps on the listener, wakes, receives and records the hop), and `bench latency
//! transport`'s `futex` and `eventfd` (shared memory written in place, a futex word or an
//! eventfd to wake on, no library). The one with the lowest p99 is the peer, so no ratio
//! flatters the pipeline by comparing it with its own transport. Then the real session runs
//! (five processes, scripted hand at 120 Hz), and each stage's hop is reported as a ratio to
//! the peer's. Origin -> world is reported with its absolute target, and as a ratio to the
//! peer hop (it spans three hops and two stages' work). Then the session again under each
//! other `[pipeline] wait`, and under `wake = "event"` (iceoryx2's event, the wake-up before
//! the doorbell).

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::bus::{Bus, BusConfig, WaitStrategy};
use common::config::session::WakeUp;
use common::latency::{new_histogram, Metric, Summary};
use common::{monotonic_ns, topics, HandSample, Stage, Stamp};
use hdrhistogram::Histogram;
use serde_json::{json, Value};

use crate::page::{self, Provenance};
use crate::plot::{Axis, Figure, Join, Panel, Series};

/// Options of `handblocks bench latency`.
pub struct LatencyBench {
    pub exe: PathBuf,
    pub session: PathBuf,
    pub seconds: f64,
    pub out_dir: PathBuf,
    /// A shortened run (`bench latency all --quick`); the page says so.
    pub quick: bool,
    /// Whole runs, one after another (each the bare hops and every session); each figure
    /// published is the median of the runs', their spread beside it.
    pub runs: u64,
}

/// The publishing half of the peer, run as its own process by the benchmark.
pub fn peer_publisher(
    bus_id: &str,
    rate_hz: f64,
    count: u64,
) -> Result<(), Box<dyn std::error::Error>> {
    let bus = Bus::open(&BusConfig::for_session(bus_id)?, "peer-publisher")?;
    let mut out = bus.outlet::<topics::Hand>()?;
    let period = 1e9 / rate_hz;
    let start = monotonic_ns();
    let sample = HandSample::default();
    for k in 0..count {
        common::stamp::sleep_until_ns(start + (k as f64 * period) as u64);
        let mut s = sample;
        s.stamp = Stamp::at_origin(0, 0);
        out.publish(&s)?;
    }
    // Stay until the reader has everything (it holds our samples' memory until then).
    common::shutdown::watch_parent_pipe();
    common::shutdown::wait_for_release(Duration::from_secs(5));
    Ok(())
}

fn peer(exe: &Path, seconds: f64) -> Result<Histogram<u64>, Box<dyn std::error::Error>> {
    let id = format!("peer{}", std::process::id());
    let config = BusConfig::for_session(&id)?;
    let count = (seconds * 120.0) as u64;
    let result = (|| -> Result<Histogram<u64>, Box<dyn std::error::Error>> {
        let bus = Bus::open(&config, "peer-subscriber")?;
        let _services = bus.create_services()?;
        let inlet = bus.inlet::<topics::Hand>()?;
        let mut child = Command::new(exe)
            .args([
                "bench-peer",
                "--bus",
                &id,
                "--rate",
                "120",
                "--count",
                &count.to_string(),
            ])
            .stdin(Stdio::piped())
            .spawn()?;
        let mut hop = new_histogram();
        let deadline = Instant::now() + Duration::from_secs_f64(seconds + 10.0);
        let mut received = 0;
        while received < count && Instant::now() < deadline {
            inlet.wait(Duration::from_millis(50))?;
            while let Some(s) = inlet.receive()? {
                hop.saturating_record(monotonic_ns().saturating_sub(s.stamp.publish_ns).max(1));
                received += 1;
            }
        }
        drop(child.stdin.take());
        let _ = child.wait();
        if received < count {
            return Err(format!("the peer received {received} of {count} samples").into());
        }
        Ok(hop)
    })();
    let _ = config.remove_resources();
    result
}

/// A summary as the reports write it (us).
pub(crate) fn summary_json(s: Summary) -> Value {
    json!({"p50": s.p50, "p90": s.p90, "p99": s.p99, "p999": s.p999, "max": s.max, "count": s.count})
}

fn ratio(a: f64, b: f64) -> f64 {
    if b > 0.0 {
        (a / b * 100.0).round() / 100.0
    } else {
        f64::NAN
    }
}

/// Runs the benchmark `b.runs` times; writes `pipeline.json` (every number the median of the
/// runs', and each run whole under `runs`), `pipeline.md` (medians with their spread) and
/// `latency.json`'s `pipeline` rows (medians); `pipeline.png` is the last run's.
pub fn run(b: &LatencyBench) -> Result<Value, Box<dyn std::error::Error>> {
    let n = b.runs.max(1);
    let quiet = crate::page::Quietness::start();
    let mut values = Vec::new();
    let mut rows = Vec::new();
    for k in 0..n {
        if n > 1 {
            eprintln!("bench latency: run {} of {n}", k + 1);
        }
        let (v, r) = run_once(b)?;
        values.push(v);
        rows.push(r);
    }
    let mut value = median_of(&values.iter().collect::<Vec<_>>());
    // The adaptive waits' per-arrival traces are the last run's (counts of one run).
    if let (Some(waits), Some(last)) = (
        value["wait_strategies"].as_array_mut(),
        values.last().and_then(|l| l["wait_strategies"].as_array()),
    ) {
        for (w, l) in waits.iter_mut().zip(last) {
            if let (Some(o), Some(t)) = (w.as_object_mut(), l.get("trace")) {
                o.insert("trace".into(), t.clone());
            }
        }
    }
    value["runs"] = Value::Array(values);
    value["how_quiet"] = json!(quiet.line());
    let rows = median_of(&rows.iter().collect::<Vec<_>>());
    let file = b.out_dir.join("pipeline.json");
    std::fs::write(&file, serde_json::to_string_pretty(&value)? + "\n")?;
    let merged = merge_into_latency_json(&b.out_dir, "pipeline", rows)?;
    let provenance = Provenance::of_this_run(b.quick, &b.out_dir).with_quietness(&quiet);
    std::fs::write(b.out_dir.join("pipeline.md"), markdown(&value, &provenance))?;
    eprintln!(
        "bench latency: wrote {}, pipeline.md and {} ({n} run{}: each figure the median)",
        file.display(),
        merged.display(),
        if n == 1 { "" } else { "s" }
    );
    Ok(value)
}

/// `values` (the same shape: one run's JSON each) with every number the median of theirs at
/// the same place (arrays matched by index; a place a run lacks is left out of its median).
fn median_of(values: &[&Value]) -> Value {
    let Some(first) = values.first() else {
        return Value::Null;
    };
    match first {
        Value::Number(_) => {
            let mut xs: Vec<f64> = values.iter().filter_map(|v| v.as_f64()).collect();
            xs.sort_by(f64::total_cmp);
            let m = match xs.len() {
                0 => return (*first).clone(),
                n if n % 2 == 1 => xs[n / 2],
                n => (xs[n / 2 - 1] + xs[n / 2]) / 2.0,
            };
            if values.iter().all(|v| v.is_u64()) && m.fract() == 0.0 {
                json!(m as u64)
            } else {
                json!((m * 1000.0).round() / 1000.0)
            }
        }
        Value::Object(o) => Value::Object(
            o.keys()
                .map(|k| {
                    let at: Vec<&Value> = values.iter().filter_map(|v| v.get(k)).collect();
                    (k.clone(), median_of(&at))
                })
                .collect(),
        ),
        Value::Array(a) => Value::Array(
            a.iter()
                .enumerate()
                .map(|(i, x)| {
                    // Rows (a stage's metric, a wait's session) are matched by what names
                    // them; anything else by its place.
                    let at: Vec<&Value> = match row_key(x) {
                        Some(key) => values
                            .iter()
                            .filter_map(|v| {
                                v.as_array()?
                                    .iter()
                                    .find(|y| row_key(y).as_ref() == Some(&key))
                            })
                            .collect(),
                        None => values.iter().filter_map(|v| v.get(i)).collect(),
                    };
                    median_of(&at)
                })
                .collect(),
        ),
        other => (*other).clone(),
    }
}

/// What names a row of a run's JSON: its stage, metric, transport, wait and wake, where it
/// has any.
fn row_key(v: &Value) -> Option<String> {
    let o = v.as_object()?;
    let key: Vec<&str> = ["stage", "metric", "transport", "wait", "wake"]
        .iter()
        .filter_map(|k| o.get(*k).and_then(Value::as_str))
        .collect();
    (!key.is_empty()).then(|| key.join("/"))
}

/// The runs' lowest and highest number at `path` in `v["runs"]` (None with fewer than two).
fn spread(v: &Value, path: &[&str]) -> Option<(f64, f64)> {
    let xs: Vec<f64> = v["runs"]
        .as_array()?
        .iter()
        .filter_map(|r| {
            path.iter()
                .try_fold(r, |at, key| match key.parse::<usize>() {
                    Ok(i) => at.get(i),
                    Err(_) => at.get(*key),
                })
                .and_then(Value::as_f64)
        })
        .collect();
    (xs.len() > 1).then(|| {
        xs.iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| {
                (lo.min(x), hi.max(x))
            })
    })
}

/// One run: the bare hops and every session. Its JSON (`pipeline.json`'s shape) and its
/// `latency.json` rows; writes `pipeline.png`.
fn run_once(b: &LatencyBench) -> Result<(Value, Value), Box<dyn std::error::Error>> {
    eprintln!(
        "bench latency: bare two-process hops (iceoryx2, futex, eventfd; hand-sized, 120 Hz) for {:.0} s each ...",
        b.seconds
    );
    let iceoryx2_histogram = peer(&b.exe, b.seconds)?;
    let mut bare: Vec<(&'static str, Histogram<u64>)> = vec![("iceoryx2", iceoryx2_histogram)];
    for t in [
        crate::transport::Transport::Futex,
        crate::transport::Transport::Eventfd,
    ] {
        let row = crate::transport::measure(
            &b.exe,
            &crate::transport::PeerArgs {
                transport: t,
                endpoint: format!("pl{}_{}", std::process::id(), t.name()),
                bytes: std::mem::size_of::<HandSample>(),
                rate_hz: 120.0,
                count: (b.seconds * 120.0) as u64,
            },
        )?;
        bare.push((t.name(), row.histogram));
    }
    for (name, h) in &bare {
        let s = Summary::of(h);
        eprintln!(
            "bench latency: bare hop {name}: p50 {:.1} us, p99 {:.1} us",
            s.p50, s.p99
        );
    }
    // The peer: the fastest bare wake-up (futex or eventfd), by p99.
    let (peer_name, peer_histogram) = bare[1..]
        .iter()
        .min_by(|a, b| Summary::of(&a.1).p99.total_cmp(&Summary::of(&b.1).p99))
        .map(|(n, h)| (*n, h.clone()))
        .ok_or("no bare hop measured")?;
    let peer = Summary::of(&peer_histogram);
    eprintln!(
        "bench latency: the session {} for {:.0} s ...",
        b.session.display(),
        b.seconds
    );
    let outcome = launcher::launch(&launcher::LaunchOptions {
        session: b.session.clone(),
        duration: Some(Duration::from_secs_f64(b.seconds)),
        report: None,
        bus_id: None,
        exe: b.exe.clone(),
        progress: false,
        frames_dir: None,
        record: None,
        ..launcher::LaunchOptions::default()
    })?;
    let report = &outcome.report;
    let mut stages = serde_json::Map::new();
    let mut table = format!(
        "{:<12} {:>10} {:>10} {:>12}   (microseconds; peer = bare hop measured in this run)\n",
        "hop into", "p50", "p99", "p99 / peer"
    );
    table.push_str(&format!(
        "{:<12} {:>10.1} {:>10.1} {:>12}   ({peer_name})\n",
        "peer", peer.p50, peer.p99, "1.00"
    ));
    for s in &report.stages {
        let hop = s.summary(Metric::Hop);
        if hop.count == 0 {
            continue;
        }
        table.push_str(&format!(
            "{:<12} {:>10.1} {:>10.1} {:>12.2}\n",
            s.stage.name(),
            hop.p50,
            hop.p99,
            ratio(hop.p99, peer.p99)
        ));
        stages.insert(
            s.stage.name().into(),
            json!({"hop_us": summary_json(hop), "hop_p99_over_peer_p99": ratio(hop.p99, peer.p99)}),
        );
    }
    let world = report.summary_of(Stage::Stepper, Metric::Origin);
    // Where origin -> world goes, stage by stage: the source's origin -> publish (its own
    // work after the origin stamp), then each hop (the wake-up) and each stage's work.
    let source_stage = report
        .stages
        .iter()
        .find(|s| s.stage.role() == common::topic::Role::Source)
        .map_or(Stage::Acquisition, |s| s.stage);
    let parts = [
        (
            "source origin -> publish",
            report.summary_of(source_stage, Metric::Origin),
        ),
        (
            "hop into kinematics",
            report.summary_of(Stage::Kinematics, Metric::Hop),
        ),
        (
            "kinematics work",
            report.summary_of(Stage::Kinematics, Metric::Process),
        ),
        (
            "hop into the stepper",
            report.summary_of(Stage::Stepper, Metric::Hop),
        ),
        (
            "stepper work",
            report.summary_of(Stage::Stepper, Metric::Process),
        ),
    ];
    let budget: Vec<Value> = parts
        .iter()
        .map(|(part, x)| json!({"part": part, "p50_us": x.p50, "p99_us": x.p99}))
        .collect();
    table.push_str(&format!(
        "\norigin -> world  p50 {:.1} us  p99 {:.1} us  (target p99 <= 200 us; p99 / peer hop p99 = {:.2})\n",
        world.p50,
        world.p99,
        ratio(world.p99, peer.p99)
    ));
    let dropped: u64 = report.topics.values().map(|f| f.dropped()).sum();
    table.push_str(&format!("dropped samples: {dropped}\n"));
    // The wait strategies ([pipeline] wait), each a session of its own after the first
    // (which ran the session's own setting): origin -> world and CPU per stage.
    // The first session ran with its own strategy; the others run once each.
    let own_session = common::config::Session::load(&b.session)?;
    let (own, own_wake) = (own_session.wait, own_session.wake);
    let mut waits = vec![wait_row(own.name(), own_wake.name(), report)];
    // Each other wait under the session's wake-up, and the default wait under the other
    // wake-up (the doorbell against iceoryx2's event: issue 46's before and after).
    let other_wake = match own_wake {
        WakeUp::Doorbell => WakeUp::Event,
        WakeUp::Event => WakeUp::Doorbell,
    };
    let mut runs: Vec<(WaitStrategy, WakeUp)> = [
        WaitStrategy::Event,
        WaitStrategy::Adaptive,
        WaitStrategy::Spin,
    ]
    .into_iter()
    .filter(|&w| w != own)
    .map(|w| (w, own_wake))
    .collect();
    runs.insert(0, (WaitStrategy::Event, other_wake));
    for (wait, wake) in runs {
        let (wait, wake) = (wait.name(), wake.name());
        eprintln!(
            "bench latency: the session with [pipeline] wait = {wait:?}, wake = {wake:?} for {:.0} s ...",
            b.seconds
        );
        // The adaptive stages keep a record per arrival (where the publish fell against the
        // window they polled in), written into DIR/wait-trace as they stop. The launcher's
        // threads have ended here: nothing reads the environment while it changes.
        let traces = b.out_dir.join("wait-trace");
        if wait == "adaptive" {
            std::fs::create_dir_all(&traces)?;
            std::env::set_var(common::bus::Waiter::TRACE_ENV, &traces);
        }
        let o = launcher::launch(&launcher::LaunchOptions {
            session: b.session.clone(),
            duration: Some(Duration::from_secs_f64(b.seconds)),
            exe: b.exe.clone(),
            overrides: vec![
                common::config::session::Override::parse(&format!("pipeline.wait=\"{wait}\""))?,
                common::config::session::Override::parse(&format!("pipeline.wake=\"{wake}\""))?,
            ],
            ..launcher::LaunchOptions::default()
        });
        std::env::remove_var(common::bus::Waiter::TRACE_ENV);
        let mut row = wait_row(wait, wake, &o?.report);
        if wait == "adaptive" {
            row["trace"] = wait_traces(&traces);
        }
        waits.push(row);
    }
    table.push_str(&format!(
        "\n{:<20} {:<10} {:>10} {:>10}   CPU seconds per stage\n",
        "[pipeline] wait", "wake", "o->w p50", "o->w p99"
    ));
    for w in &waits {
        table.push_str(&format!(
            "{:<20} {:<10} {:>10.1} {:>10.1}   {}\n",
            w["wait"].as_str().unwrap_or(""),
            w["wake"].as_str().unwrap_or(""),
            w["origin_to_world_us"]["p50"].as_f64().unwrap_or(f64::NAN),
            w["origin_to_world_us"]["p99"].as_f64().unwrap_or(f64::NAN),
            w["cpu_s"]
                .as_object()
                .map(|m| m
                    .iter()
                    .map(|(k, v)| format!("{k} {v}"))
                    .collect::<Vec<_>>()
                    .join(", "))
                .unwrap_or_default()
        ));
    }
    if let Some(t) = waits.iter().find_map(|w| w.get("trace")) {
        table.push_str(&wait_trace_lines(t));
    }
    print!("{table}");
    let value = json!({
        "seconds": b.seconds,
        "peer_hop_us": summary_json(peer),
        "peer": peer_name,
        "bare_hops_us": bare
            .iter()
            .map(|(n, h)| (n.to_string(), summary_json(Summary::of(h))))
            .collect::<serde_json::Map<_, _>>(),
        "wake": own_wake.name(),
        "stages": stages,
        "origin_to_world_us": summary_json(world),
        "origin_to_world_p99_over_peer_hop_p99": ratio(world.p99, peer.p99),
        "origin_to_world_parts": budget,
        "dropped": dropped,
        "wait_strategies": waits,
        "session": report.json(),
    });
    std::fs::create_dir_all(&b.out_dir)?;
    // The suite's file: per stage its hop, processing and origin -> out, origin -> world and
    // origin -> photon, and the bare hop, each with its p99 as a ratio to the bare hop's.
    let row = |stage: &str, metric: &str, x: Summary| {
        json!({"stage": stage, "metric": metric, "p50_us": x.p50, "p90_us": x.p90,
            "p99_us": x.p99, "p999_us": x.p999, "max_us": x.max, "count": x.count,
            "p99_over_bare_hop_p99": ratio(x.p99, peer.p99)})
    };
    let mut rows = Vec::new();
    for s in &report.stages {
        for (metric, name) in [
            (Metric::Hop, "hop"),
            (Metric::Process, "process"),
            (Metric::Origin, "origin->out"),
        ] {
            let x = s.summary(metric);
            if x.count > 0 {
                rows.push(row(s.stage.name(), name, x));
            }
        }
        if s.stage == Stage::Renderer && s.summary(Metric::Photon).count > 0 {
            rows.push(row("renderer", "origin->photon", s.summary(Metric::Photon)));
        }
    }
    rows.push(row("stepper", "origin->world", world));
    rows.push(row("bare hop", "hop", peer));
    for (name, h) in &bare {
        let mut r = row("bare hop", name, Summary::of(h));
        r["transport"] = json!(name);
        rows.push(r);
    }
    figure(report, &peer_histogram).write_png(&b.out_dir.join("pipeline.png"))?;
    Ok((value, Value::Array(rows)))
}

/// `pipeline.md`: what was measured, how to read it, the run, the figure and the tables, from
/// the JSON this run wrote (so the page and `pipeline.json` cannot disagree).
fn markdown(v: &Value, provenance: &Provenance) -> String {
    // Each session's length, for CPU per second.
    let seconds = v["seconds"]
        .as_f64()
        .filter(|s| *s > 0.0)
        .unwrap_or(f64::NAN);
    let us = |x: &Value| x.as_f64().map_or("-".to_string(), |x| format!("{x:.1}"));
    let what = format!(
        "What the pipeline adds to the transport. The peer is the floor any stage could reach \
         on this machine at this moment: the fastest of two bare wake-ups between two \
         processes (a futex word, an eventfd; hand-sized samples written in shared memory at \
         120 Hz, no library, no processing; {s:.0} s each), measured in this run beside \
         iceoryx2's own hop; here the peer is `{peer}`. Then the real session runs ({s:.0} s: \
         its processes, the scripted hand at 120 Hz, `[pipeline] wake = \"{wake}\"`), and each \
         stage's hop (the stage before's publish to its receive) is reported as a ratio to \
         the peer's; then the session again with each other `[pipeline] wait` strategy, and \
         with the other wake-up (`doorbell`: kinematics and the stepper sleep on a futex word \
         their publishers ring; `event`: every stage on iceoryx2's event, as before issue \
         46).\n\n\
         How to read it: a ratio of 1.00 means the stage wakes as fast as a bare hop; 2.00, \
         twice as slow at p99. The bare hops run on an idle machine, so each sample wakes a \
         CPU from idle, whose tail on a VM is long; the session's hops run while its renderer \
         keeps the CPUs busy, so they may come out faster than the bare hop. Origin -> world is the age of the world a stage sends (from \
         when the hand sample entered the pipeline: three hops and two stages' work), with \
         its target p99 <= 200 us and <= 3x the bare hop's p99. {runs} whole runs, one \
         after another: every figure is the median of the runs' (the peer too, which may be \
         a different bare hop in each run), the lowest and highest run in brackets; \
         `pipeline.json` keeps each run whole under `runs`. The figure draws the last run's \
         histograms by percentile (p50 to the tail, HdrHistogram's log axis).",
        runs = v["runs"].as_array().map_or(1, |r| r.len()),
        s = v["seconds"].as_f64().unwrap_or(0.0),
        peer = v["peer"].as_str().unwrap_or("-"),
        wake = v["wake"].as_str().unwrap_or("-"),
    );
    let mut md = page::head(
        "Benchmark: the pipeline's latency against a bare hop",
        &what,
        provenance,
    );
    // A median with its runs' spread: "91.6 (85.0-107.5)".
    let spread_of = |path: &[&str]| {
        spread(v, path).map_or(String::new(), |(lo, hi)| format!(" ({lo:.1}-{hi:.1})"))
    };
    let at = |path: &[&str]| {
        let x = path
            .iter()
            .try_fold(v, |at, key| match key.parse::<usize>() {
                Ok(i) => at.get(i),
                Err(_) => at.get(*key),
            });
        format!("{}{}", x.map_or("-".to_string(), us), spread_of(path))
    };
    let world_p99 = v["origin_to_world_us"]["p99"].as_f64().unwrap_or(f64::NAN);
    let over = v["origin_to_world_p99_over_peer_hop_p99"]
        .as_f64()
        .unwrap_or(f64::NAN);
    md.push_str(&format!(
        "**origin -> world p50 {} us, p99 {} us** under `[pipeline] wait = \"event\"`, wake \
         `{}` (goals: p99 <= 200 us, {}; p99 <= 3x the bare hop's p99, {}: {over:.2}x, the \
         bare hop's p99 {} us); **{} samples dropped**.\n\n",
        at(&["origin_to_world_us", "p50"]),
        at(&["origin_to_world_us", "p99"]),
        v["wake"].as_str().unwrap_or("-"),
        if world_p99 <= 200.0 { "met" } else { "not met" },
        if over <= 3.0 { "met" } else { "not met" },
        at(&["peer_hop_us", "p99"]),
        v["dropped"],
    ));
    // Where the time goes: the p50s add up to origin -> world's; the wake-ups are the hops.
    if let Some(parts) = v["origin_to_world_parts"].as_array() {
        md.push_str(
            "## Where origin -> world goes\n\nThe p50s add up to origin -> world's p50 (p99s do \
             not add: each part's worst samples are not the same samples). The wake-ups are the \
             two hops; the rest is work: the source's own, from its origin stamp to its \
             publish, and each stage's.\n\n| part | p50 (us) | p99 |\n|---|---|---|\n",
        );
        let (mut p50_sum, mut hops_p50) = (0.0, 0.0);
        for (i, p) in parts.iter().enumerate() {
            let i = i.to_string();
            let name = p["part"].as_str().unwrap_or("");
            let p50 = p["p50_us"].as_f64().unwrap_or(0.0);
            p50_sum += p50;
            if name.starts_with("hop") {
                hops_p50 += p50;
            }
            md.push_str(&format!(
                "| {name} | {} | {} |\n",
                at(&["origin_to_world_parts", &i, "p50_us"]),
                at(&["origin_to_world_parts", &i, "p99_us"]),
            ));
        }
        md.push_str(&format!(
            "| sum | {p50_sum:.1} | - |\n| origin -> world | {} | {} |\n\n\
             The two wake-ups are {hops_p50:.1} us of the {p50_sum:.1} us p50 ({:.0} %).{}\n\n",
            at(&["origin_to_world_us", "p50"]),
            at(&["origin_to_world_us", "p99"]),
            if p50_sum > 0.0 {
                100.0 * hops_p50 / p50_sum
            } else {
                0.0
            },
            if world_p99 > 200.0 {
                " Where origin -> world's p99 is over 200 us, the hops' own p99s (in the table \
                 above) show how much of it a wake-up could still win; the rest is the \
                 stages' work and the source's, which no wake-up removes."
            } else {
                ""
            },
        ));
    }
    md.push_str(&page::figure(
        "hop into each stage beside the bare hop, and origin to world and to photon, by percentile",
        "pipeline.png",
    ));
    md.push_str(
        "## Hop into each stage\n\n| hop into | p50 (us) | p90 | p99 | p99.9 | max | count | p99 / bare hop p99 |\n|---|---|---|---|---|---|---|---|\n",
    );
    let peer = &v["peer_hop_us"];
    // A row of histogram figures at `path`, p50 and p99 with their runs' spread.
    let row = |name: &str, path: &[&str], ratio: String| {
        let h = path
            .iter()
            .try_fold(v, |at, key| at.get(*key))
            .unwrap_or(&Value::Null);
        let with = |k: &str| {
            let mut p = path.to_vec();
            p.push(k);
            at(&p)
        };
        format!(
            "| {name} | {} | {} | {} | {} | {} | {} | {ratio} |\n",
            with("p50"),
            us(&h["p90"]),
            with("p99"),
            us(&h["p999"]),
            us(&h["max"]),
            h["count"]
        )
    };
    md.push_str(&row(
        &format!("bare hop (peer: {})", v["peer"].as_str().unwrap_or("-")),
        &["peer_hop_us"],
        "1.00".into(),
    ));
    for (name, h) in v["bare_hops_us"].as_object().into_iter().flatten() {
        let r = match (h["p99"].as_f64(), peer["p99"].as_f64()) {
            (Some(a), Some(b)) if b > 0.0 => format!("{:.2}", a / b),
            _ => "-".into(),
        };
        md.push_str(&row(
            &format!("bare hop ({name})"),
            &["bare_hops_us", name],
            r,
        ));
    }
    for (stage, x) in v["stages"].as_object().into_iter().flatten() {
        md.push_str(&row(
            stage,
            &["stages", stage, "hop_us"],
            x["hop_p99_over_peer_p99"]
                .as_f64()
                .map_or("-".into(), |r| format!("{r:.2}")),
        ));
    }
    md.push_str(
        "\n## Each `[pipeline] wait` strategy and wake-up, a session each\n\n| wait | wake | origin -> world p50 (us) | p99 | dropped | CPU ms per second, per stage |\n|---|---|---|---|---|---|\n",
    );
    for (i, w) in v["wait_strategies"]
        .as_array()
        .into_iter()
        .flatten()
        .enumerate()
    {
        let i = i.to_string();
        md.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} |\n",
            w["wait"].as_str().unwrap_or(""),
            w["wake"].as_str().unwrap_or(""),
            at(&["wait_strategies", &i, "origin_to_world_us", "p50"]),
            at(&["wait_strategies", &i, "origin_to_world_us", "p99"]),
            w["dropped"],
            w["cpu_s"]
                .as_object()
                .map(|m| m
                    .iter()
                    .map(|(k, v)| format!(
                        "{k} {:.1}",
                        v.as_f64().unwrap_or(f64::NAN) / seconds * 1000.0
                    ))
                    .collect::<Vec<_>>()
                    .join(", "))
                .unwrap_or_default()
        ));
    }
    if let Some(t) = v["wait_strategies"]
        .as_array()
        .and_then(|a| a.iter().find_map(|w| w.get("trace")))
    {
        md.push_str(&format!("\n```{}```\n", wait_trace_lines(t)));
    }
    md
}

/// Latency by percentile on HdrHistogram's "nines" axis: each stage's hop beside the bare hop
/// of the same run, and the ages of what leaves the stepper (origin -> world) and the screen
/// (origin -> photon).
fn figure(report: &launcher::report::Report, bare_hop: &Histogram<u64>) -> Figure {
    let mut hops = vec![Series::nines("bare hop", bare_hop)];
    for s in &report.stages {
        if !s.histograms[Metric::Hop as usize].is_empty() {
            hops.push(Series::nines(
                s.stage.name(),
                &s.histograms[Metric::Hop as usize],
            ));
        }
    }
    let mut ages = vec![Series::nines("bare hop", bare_hop)];
    if let Some(h) = report.histogram(Stage::Stepper, Metric::Origin) {
        ages.push(Series::nines("origin -> world", h));
    }
    if let Some(h) = report.histogram(Stage::Renderer, Metric::Photon) {
        ages.push(Series::nines("origin -> photon", h));
    }
    let panel = |title: &str, series: Vec<Series>| Panel {
        title: title.to_string(),
        x: Axis::nines(),
        y: Axis::log("latency (us)"),
        series,
        marked: Vec::new(),
        join: Join::Curve,
    };
    Figure {
        panels: vec![
            panel("hop into each stage, and the bare hop", hops),
            panel("origin -> world and -> photon", ages),
        ],
        columns: 2,
        panel_width: 500,
        panel_height: 380,
        column_weights: Vec::new(),
    }
}

/// What an adaptive session's per-arrival traces (`DIR/wait-trace/wait-STAGE.csv`, written
/// by `Waiter::finish`) say, per stage: how many arrivals the poll window caught, where the
/// others' publishes fell against their windows, and the time from a publish to the wait's
/// return (p50) for those found by polling and those woken by the event.
fn wait_traces(dir: &std::path::Path) -> Value {
    let mut out = serde_json::Map::new();
    for stage in ["kinematics", "stepper"] {
        let Ok(text) = std::fs::read_to_string(dir.join(format!("wait-{stage}.csv"))) else {
            continue;
        };
        use common::bus::{WaitOutcome, WaitRecord};
        let records: Vec<WaitRecord> = text
            .lines()
            .skip(1)
            .filter_map(WaitRecord::from_csv)
            .collect();
        let count = |o: WaitOutcome| records.iter().filter(|r| r.outcome() == o).count();
        let to_return_us = |polled: bool| -> Vec<f64> {
            records
                .iter()
                .filter(|r| r.open_ns != 0 && r.polled == polled)
                .map(|r| (r.returned_ns as f64 - r.publish_ns as f64) / 1e3)
                .collect()
        };
        let (polled, early, inside, late, no_window) = (
            count(WaitOutcome::Polled),
            count(WaitOutcome::Early),
            count(WaitOutcome::Inside),
            count(WaitOutcome::Late),
            count(WaitOutcome::NoWindow),
        );
        let (by_poll, by_event) = (to_return_us(true), to_return_us(false));
        let p50 = |mut v: Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v.get(v.len() / 2).copied()
        };
        out.insert(
            stage.to_string(),
            json!({"found_by_polling": polled, "published_before_window": early,
                "published_in_window_not_seen": inside, "published_after_window": late,
                "before_any_window": no_window,
                "publish_to_return_p50_us_polled": p50(by_poll),
                "publish_to_return_p50_us_woken": p50(by_event)}),
        );
    }
    Value::Object(out)
}

/// The adaptive traces' summary as table lines.
fn wait_trace_lines(t: &Value) -> String {
    let mut s = String::from(
        "
adaptive, per arrival (DIR/wait-trace): found by polling / published before, inside \
         (not seen), after the window; publish -> return p50 polled / woken (us)\n",
    );
    for (stage, v) in t.as_object().into_iter().flatten() {
        let n = |k: &str| v[k].as_u64().unwrap_or(0);
        let us = |k: &str| v[k].as_f64().map_or("-".to_string(), |x| format!("{x:.1}"));
        s.push_str(&format!(
            "  {stage:<12} {} / {}, {}, {};  {} / {}\n",
            n("found_by_polling"),
            n("published_before_window"),
            n("published_in_window_not_seen"),
            n("published_after_window"),
            us("publish_to_return_p50_us_polled"),
            us("publish_to_return_p50_us_woken"),
        ));
    }
    s
}

/// One wait strategy's session: origin -> world, and each stage's CPU seconds.
fn wait_row(wait: &str, wake: &str, report: &launcher::report::Report) -> Value {
    let world = report.summary_of(Stage::Stepper, Metric::Origin);
    let cpu: serde_json::Map<String, Value> = report
        .stages
        .iter()
        .map(|s| (s.stage.name().to_string(), json!(s.cpu_s)))
        .collect();
    json!({"wait": wait, "wake": wake, "origin_to_world_us": summary_json(world), "cpu_s": cpu,
        "dropped": report.topics.values().map(|f| f.dropped()).sum::<u64>()})
}

/// Puts one part's results under its key (`transport`, `pipeline`, `load`) in the suite's
/// `DIR/latency.json`, keeping the other parts a run into the same folder left there: each
/// part run alone, or `all`, ends with one file holding what was measured.
pub fn merge_into_latency_json(
    dir: &Path,
    part: &str,
    value: Value,
) -> Result<PathBuf, Box<dyn std::error::Error>> {
    let file = dir.join("latency.json");
    let mut all = std::fs::read_to_string(&file)
        .ok()
        .and_then(|t| serde_json::from_str::<Value>(&t).ok())
        .filter(|v| {
            v.as_object().is_some_and(|o| {
                o.keys()
                    .all(|k| ["transport", "pipeline", "load"].contains(&k.as_str()))
            })
        })
        .unwrap_or_else(|| json!({}));
    all[part] = value;
    std::fs::write(&file, serde_json::to_string_pretty(&all)? + "\n")?;
    Ok(file)
}
