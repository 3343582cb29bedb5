//! The null source (`[source] kind = "null"`, services/null): the stage added last by issue 44,
//! with one row in the stage table, its stage among the glove and tracker topics' publishers,
//! one `[source] kind` and one crate. A session on it runs the whole pipeline on a still hand.

use std::path::PathBuf;

use serde_json::Value;

mod support;
use support::{assert_nothing_left, launch_session, repo, Scratch, CEILINGS_TOML};

fn session(dir: &Scratch, rest: &str) -> PathBuf {
    let scene = repo().join("config/scenes/grasp-throw.toml");
    let p = dir.path("null.toml");
    std::fs::write(&p, format!("scene = {:?}\n{rest}", scene.to_string_lossy())).unwrap();
    p
}

#[test]
fn a_null_source_holds_a_still_hand_through_the_pipeline() {
    let dir = Scratch::new("null");
    let s = session(
        &dir,
        &format!(
            "[source]\nkind = \"null\"\nrate_hz = 100\n[renderer]\nmode = \"off\"\n\
             [budget]\n{CEILINGS_TOML}max_dropped = 0\n"
        ),
    );
    let report_file = dir.path("report.json");
    let id = format!("itnull{}", std::process::id());
    let out = launch_session(&s, &id, 2.0, Some(&report_file));
    let text = support::both(&out);
    assert!(out.status.success(), "launch failed: {text}");
    assert_nothing_left(&id);
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(&report_file).unwrap()).unwrap();
    for stage in ["null", "kinematics", "stepper"] {
        assert!(
            report["stages"][stage]["final_report"].as_bool() == Some(true),
            "{stage} sent no final report: {text}"
        );
    }
    assert!(report["stages"]["acquisition"].is_null(), "{text}");
    let topic = |t: &str, k: &str| report["topics"][t][k].as_u64().unwrap_or(0);
    let tracker = topic("tracker", "published");
    assert!(
        tracker >= 100,
        "2 s at 100 Hz gave {tracker} tracker samples"
    );
    assert_eq!(topic("glove", "published"), tracker);
    assert_eq!(topic("hand", "published"), tracker, "one hand per pair");
    assert_eq!(topic("world", "published"), tracker, "one world per hand");
    for t in ["glove", "tracker", "hand", "world"] {
        assert_eq!(topic(t, "dropped"), 0, "{t} dropped samples: {text}");
    }
}

/// The null source takes `rate_hz` only, checked as every key is.
#[test]
fn a_null_source_refuses_a_key_it_does_not_take() {
    let dir = Scratch::new("null-key");
    let s = session(&dir, "[source]\nkind = \"null\"\nfile = \"x.carl\"\n");
    // The session is read before anything starts: nothing runs.
    let out = std::process::Command::new(support::EXE)
        .args(["launch", "--quiet", "--duration", "1"])
        .arg(&s)
        .output()
        .unwrap();
    let text = support::both(&out);
    assert!(!out.status.success(), "{text}");
    assert!(text.contains("source.file"), "{text}");
}
