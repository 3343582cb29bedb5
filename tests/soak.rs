//! Issue 16, "Soak": the scripted hand at 1 kHz for 60 s with the recorder (and the headless
//! renderer) on: no sample dropped, no gap in any topic, the recording holds every sample, and
//! the budget held at the tests' ceilings (only a broken pipeline crosses them; the soak's
//! latency is printed, and judged by `bench latency`, not here). Its own test binary, so that no other session of the suite shares the
//! two cores with it (cargo runs test binaries one after another).

use common::Topic;
use recording::Recording;
use serde_json::Value;

mod support;
use support::{both, launch_session, repo, Scratch, CEILINGS_TOML};

const RATE_HZ: u64 = 1000;
const SECONDS: f64 = 60.0;

#[test]
fn a_60_s_soak_at_1_khz_drops_nothing_records_everything_and_keeps_the_ceilings() {
    let dir = Scratch::new("soak");
    let log = dir.path("soak.mcap");
    let session = dir.path("soak.toml");
    std::fs::write(
        &session,
        format!(
            "scene = {:?}\n[source]\nkind = \"scripted\"\nrate_hz = {RATE_HZ}\n\
             [renderer]\nmode = \"headless\"\n[recorder]\nfile = {:?}\n\
             [budget]\n{CEILINGS_TOML}max_dropped = 0\n",
            repo()
                .join("config/scenes/grasp-throw.toml")
                .to_string_lossy(),
            log.to_string_lossy(),
        ),
    )
    .unwrap();
    // A fresh clone's soak once failed at origin -> world p99 1597 us against 1000 with 0 drops
    // and 0 gaps: a busy machine, not a broken pipeline. The ceilings catch only the latter.
    let report_file = dir.path("soak.json");
    let id = format!("soak{}", std::process::id());
    let out = launch_session(&session, &id, SECONDS, Some(&report_file));
    let report: Value = serde_json::from_str(&std::fs::read_to_string(&report_file).unwrap())
        .unwrap_or_else(|e| panic!("{e}\n{}", both(&out)));
    // The renderer needs a Vulkan driver (tests/run installs one); without it, it is skipped
    // and says so, and the rest of the soak still counts.
    assert!(out.status.success(), "{}", both(&out));
    assert_eq!(report["budget"]["ok"], Value::Bool(true), "{}", both(&out));
    let expected = (RATE_HZ as f64 * SECONDS) as u64;
    for t in ["glove", "tracker", "hand", "world"] {
        let topic = &report["topics"][t];
        let published = topic["published"].as_u64().unwrap();
        assert!(
            published.abs_diff(expected) <= expected / 50,
            "{t}: {published} published in {SECONDS} s at {RATE_HZ} Hz\n{}",
            both(&out)
        );
        assert_eq!(
            topic["dropped"].as_u64(),
            Some(0),
            "{t} dropped\n{}",
            both(&out)
        );
        assert_eq!(topic["gaps"].as_u64(), Some(0), "{t} gaps\n{}", both(&out));
    }
    let rec = Recording::open(&log).unwrap();
    assert!(rec.complete, "{:?}", rec.damage);
    let stats = rec.stats();
    for t in [Topic::Glove, Topic::Tracker, Topic::Hand, Topic::World] {
        let s = stats[t as usize];
        assert_eq!(
            s.messages,
            report["topics"][t.name()]["published"].as_u64().unwrap(),
            "{}: every sample published is in the recording",
            t.name()
        );
        assert_eq!(s.gaps, 0, "{}: no gap in the recording", t.name());
    }
    eprintln!(
        "soak: {expected} samples a topic; origin -> world p99 {} us, p99.9 {} us, max {} us",
        report["stages"]["stepper"]["origin_us"]["p99"],
        report["stages"]["stepper"]["origin_us"]["p999"],
        report["stages"]["stepper"]["origin_us"]["max"]
    );
}
