//! The report's tests: merging a restarted stage's reports, judging the budget (frame rate,
//! a silent source), the table's and the JSON's restarts, and the report's dates.

use common::config::session::Budget;

use super::*;

fn stage(stage: Stage, metric: Metric, n: u64, silence_ms: u64) -> StageReport {
    let mut histograms: [_; common::samples::METRICS] =
        std::array::from_fn(|_| common::latency::new_histogram());
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

fn counter(topic: Topic, role: u32, count: u64, gaps: u64, last_seq: u64) -> common::TopicCounter {
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

/// Issue 40: the webxr stage's refusals were in the report only as a total
/// (`rejected_records`), their kinds only on stderr. A source stage leaves its refusals by kind
/// in the session's folder (`refused.headset.json`); the report names each kind under the
/// device, in the JSON and in the table. A file that is not a regular file (a FIFO: never
/// opened for a blocking read), too big, or not an object of counts is left out.
#[test]
fn a_sources_refusals_by_kind_are_in_the_report() {
    let dir = std::env::temp_dir().join(format!("hb-refusals-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(
        refusals::refusals_file(&dir, "headset"),
        r#"{"token": 2, "flood": 40, "text": 0}"#,
    )
    .unwrap();
    let fifo = refusals::refusals_file(&dir, "external");
    let path = std::ffi::CString::new(fifo.as_os_str().as_encoded_bytes()).unwrap();
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(path.as_ptr(), 0o600) }, 0);
    let refused = refusals::read_refusals(&dir);
    assert_eq!(refused.keys().copied().collect::<Vec<_>>(), ["headset"]);
    std::fs::remove_file(&fifo).unwrap();
    for bad in ["[1, 2]", r#"{"token": -1}"#, &" ".repeat(70 << 10)] {
        std::fs::write(&fifo, bad).unwrap();
        assert!(
            !refusals::read_refusals(&dir).contains_key("external"),
            "{bad:.20}"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();

    let mut webxr = stage(Stage::Webxr, Metric::Origin, 10, 0);
    webxr.devices = vec![common::DeviceCounters {
        device: 3,
        samples: 10,
        rejected_records: 42,
        ..Default::default()
    }];
    let facts = SessionFacts {
        seconds: 10.0,
        source: Stage::Webxr,
        renders: false,
        real_time: true,
        renderer_down_s: 0.0,
    };
    let mut r = Report::build(vec![webxr], &Budget::default(), Vec::new(), &facts);
    r.meta.refused = refused;
    let json = r.json();
    assert_eq!(
        json["devices"]["headset"]["refused"],
        serde_json::json!({"flood": 40, "token": 2}),
        "{json}"
    );
    assert_eq!(json["devices"]["headset"]["rejected_records"], 42);
    let table = r.table();
    assert!(
        table.contains("headset refused: flood 40, token 2\n"),
        "{table}"
    );
    // A device whose stage left no file has no `refused` key (the report's shape as before).
    r.meta.refused.clear();
    assert!(r.json()["devices"]["headset"].get("refused").is_none());
}

/// Issue 40: a remote viewer that missed the first 28 worlds (the link came up after the
/// session's source started) showed 56 gaps per topic: its recorder's 28 and its renderer's
/// 28, added. A loss before the bus is every reader's alike: the topic counts it once.
#[test]
fn a_loss_every_reader_saw_is_counted_once() {
    let mut bridge = stage(Stage::Bridge, Metric::Hop, 10, 0);
    // The bridge publishes under the sender's seqs: the 28 it never got are its outlet's gaps.
    bridge.counters = vec![counter(Topic::World, 0, 72, 28, 99)];
    let mut recorder = stage(Stage::Recorder, Metric::Process, 10, 0);
    recorder.counters = vec![counter(Topic::World, 1, 72, 28, 99)];
    let mut renderer = stage(Stage::Renderer, Metric::Photon, 10, 0);
    renderer.counters = vec![counter(Topic::World, 1, 72, 28, 99)];
    let facts = SessionFacts {
        seconds: 1.0,
        source: Stage::Bridge,
        renders: true,
        real_time: true,
        renderer_down_s: 0.0,
    };
    let r = Report::build(
        vec![bridge, recorder, renderer],
        &Budget::default(),
        Vec::new(),
        &facts,
    );
    let world = &r.topics[&Topic::World];
    assert_eq!(world.gaps(), 28, "{world:?}");
    assert_eq!(world.dropped(), 0, "{world:?}");
}

#[test]
fn the_table_explains_only_the_terms_it_prints() {
    let r = judged(700, 1200, 10, &Budget::default());
    let table = r.table();
    for printed in ["origin->out", "origin->px", "received"] {
        assert!(
            table.lines().any(|l| l.starts_with(printed)),
            "{printed} is not explained:\n{table}"
        );
    }
    // A glove session has no headset page: its terms are not explained.
    for absent in ["sent->drawn", "page js", "hop  ", "process  "] {
        assert!(
            !table.lines().any(|l| l.starts_with(absent)),
            "{absent} explained but not printed:\n{table}"
        );
    }
    assert_eq!(terms_of(&[]), "");
    assert!(terms_of(&["page js"]).starts_with("page js      the webxr source only"));
}

#[test]
fn a_broken_budget_says_whether_the_machine_looked_loaded_and_what_to_try() {
    let b = Budget::default();
    let mut r = judged(450, 1200, 10, &b);
    assert!(!r.ok());
    let loaded = crate::machine::MachineLoad {
        cpus: 2,
        seconds: 10.0,
        others_cpu_s: 9.0,
        steal_s: 0.0,
        session_cpu_s: 8.0,
    };
    r.meta.machine_load = Some(loaded);
    let table = r.table();
    assert!(
        table.contains(
            "the machine looked loaded: other processes used 0.90 of this machine's 2 CPU(s)"
        ),
        "{table}"
    );
    assert!(
        table.contains("run it again when the machine is idle"),
        "{table}"
    );
    r.meta.machine_load = Some(crate::machine::MachineLoad {
        others_cpu_s: 0.2,
        ..loaded
    });
    let table = r.table();
    assert!(table.contains("the machine looked quiet"), "{table}");
    assert!(
        table.contains("the session itself missed its budget"),
        "{table}"
    );
    // A kept budget needs no advice.
    let mut ok = judged(700, 1200, 10, &b);
    ok.meta.machine_load = Some(loaded);
    assert!(!ok.table().contains("looked loaded"));
    // The JSON carries the load and its verdict.
    let json = ok.json();
    assert_eq!(json["machine"]["load"]["looked_loaded"], true);
    assert_eq!(json["machine"]["load"]["others_cpu_s"], 9.0);
}
