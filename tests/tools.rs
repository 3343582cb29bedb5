//! The day-one tools, run as a user runs them, from a folder that is not the repository:
//! `list`, `replay FILE` (a CARL trace, in one word), and on that running replay `sessions`,
//! `hz` and `echo` (as `ros2 bag play`, `ros2 topic hz/echo`).

use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;

mod support;
use support::{assert_nothing_left, both, repo, Scratch, EXE};

fn run_in(dir: &std::path::Path, args: &[&str]) -> Output {
    Command::new(EXE)
        .current_dir(dir)
        .args(args)
        .output()
        .expect("run handblocks")
}

#[test]
fn list_and_the_default_session_are_found_from_any_folder() {
    let dir = Scratch::new("tools-list");
    let out = run_in(&dir.0, &["list"]);
    let text = both(&out);
    assert!(out.status.success(), "{text}");
    assert!(text.contains("configuration: "), "{text}");
    assert!(text.contains("sessions/live.toml"), "{text}");
    assert!(text.contains("scenes/grasp-throw.toml"), "{text}");
    // A description is a whole sentence, never cut at the line's end.
    assert!(
        text.contains("The default session: the built-in scripted hand grasps and throws a block."),
        "{text}"
    );
    // A scene by its name, from here.
    let out = run_in(&dir.0, &["simulate", "grasp-throw", "--frames", "10"]);
    assert!(out.status.success(), "{}", both(&out));
    assert!(
        String::from_utf8_lossy(&out.stdout).contains("after 10 steps"),
        "{}",
        both(&out)
    );
}

/// The copy of config/ built into the binary (what `cargo install` leaves when the repository
/// is gone): written out once into the cache folder, and the default session runs from it.
#[test]
fn the_built_in_configuration_runs_the_default_session() {
    let dir = Scratch::new("tools-builtin");
    let id = format!("tb{}", std::process::id());
    let out = Command::new(EXE)
        .current_dir(&dir.0)
        .env("HANDBLOCKS_CONFIG", "builtin")
        .env("XDG_CACHE_HOME", dir.path("cache"))
        .args([
            "launch",
            "--quiet",
            "--no-preview",
            "--duration",
            "2",
            "--bus-id",
            &id,
        ])
        .args(["--set", "renderer.mode=off"])
        .args(["--set", "budget.origin_to_world_p99_us=1000000"])
        .output()
        .unwrap();
    assert_nothing_left(&id);
    assert!(out.status.success(), "{}", both(&out));
    let written = std::fs::read_dir(dir.path("cache/handblocks"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| {
            p.file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with("config-"))
        })
        .expect("the built-in copy written out");
    assert!(written.join("sessions/live.toml").is_file());
    assert!(written.join("scenes/grasp-throw.toml").is_file());
    assert!(
        String::from_utf8_lossy(&out.stdout).contains("what the world came to"),
        "{}",
        both(&out)
    );
}

#[test]
fn replay_sessions_hz_and_echo_work_from_another_folder() {
    let trace = repo().join("../shared/data/carl/example_push_0.carl");
    if !trace.is_file() {
        eprintln!("skipped: {} is not there", trace.display());
        return;
    }
    let dir = Scratch::new("tools-replay");
    let report = dir.path("report.json");
    let replay = Command::new(EXE)
        .current_dir(&dir.0)
        .arg("replay")
        .arg(&trace)
        .args(["--loop", "--duration", "10", "--quiet", "--no-preview"])
        .args(["--set", "renderer.mode=off"])
        .args(["--set", "budget.origin_to_world_p99_us=1000000"])
        .arg("--report")
        .arg(&report)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run handblocks replay");
    // `sessions --json` names it once it runs: found by its launcher's pid (a loaded machine
    // may take seconds to start the processes; this waits only as long as that takes).
    let deadline = Instant::now() + Duration::from_secs(30);
    let id = loop {
        let out = run_in(&dir.0, &["sessions", "--json"]);
        assert!(out.status.success(), "{}", both(&out));
        let list: Value = serde_json::from_slice(&out.stdout).expect("sessions --json");
        let ours = list
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["launcher_pid"].as_u64() == Some(replay.id() as u64))
            .cloned();
        if let Some(s) = ours {
            let names: Vec<&str> = s["processes"]
                .as_array()
                .unwrap()
                .iter()
                .filter_map(|p| p["name"].as_str())
                .collect();
            if names.contains(&"replay") && names.contains(&"stepper") {
                assert!(s["session"]
                    .as_str()
                    .unwrap()
                    .contains("replay-example_push_0"));
                break s["id"].as_str().unwrap().to_string();
            }
        }
        assert!(
            Instant::now() < deadline,
            "the replay never showed in `sessions`"
        );
        std::thread::sleep(Duration::from_millis(100));
    };
    let hz = run_in(
        &dir.0,
        &["hz", "world", "--session", &id, "--seconds", "2.5"],
    );
    let text = both(&hz);
    assert!(hz.status.success(), "{text}");
    let rate: f64 = text
        .lines()
        .find_map(|l| l.strip_prefix("average rate: "))
        .and_then(|r| r.trim().parse().ok())
        .unwrap_or_else(|| panic!("no rate: {text}"));
    // A CARL trace is ~90 samples a second; only a broken tap reads none or absurdly many.
    assert!(rate > 10.0 && rate < 1000.0, "{text}");
    // And how long its samples took to reach it (publish -> taken), as the stages' hop.
    assert!(text.contains("publish -> taken here: p50 "), "{text}");
    let echo = run_in(&dir.0, &["echo", "/hand", "--session", &id, "-n", "2"]);
    let text = String::from_utf8_lossy(&echo.stdout).into_owned();
    assert!(echo.status.success(), "{}", both(&echo));
    assert_eq!(text.matches("---").count(), 2, "{text}");
    assert!(text.contains("finger_count: 5"), "{text}");
    assert!(text.contains("stamp:\n  seq: "), "{text}");
    let bad = run_in(&dir.0, &["echo", "stars", "--session", &id]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(
        both(&bad).contains("\"stars\" is not a topic"),
        "{}",
        both(&bad)
    );

    let out = replay.wait_with_output().unwrap();
    assert!(out.status.success(), "{}", both(&out));
    assert_nothing_left(&id);
    let r: Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    assert_eq!(r["session"]["source"], "replay", "{r}");
    // Gone with its launcher.
    let out = run_in(&dir.0, &["echo", "world", "--session", &id]);
    assert_eq!(out.status.code(), Some(2), "{}", both(&out));
}
