//! End-to-end on the device emulators: a CyberGlove and a FASTRAK, each emulated on a real
//! pseudo-terminal by `handblocks emulate`, drive a whole session exactly as hardware on
//! /dev/ttyUSB* would (issue 4).

use std::path::Path;
use std::process::{Child, Command, Stdio};

use serde_json::Value;

mod support;
use support::{assert_nothing_left, repo, Scratch, EXE};

struct Emulator(Child);

impl Emulator {
    fn start(args: &[&str], link: &Path) -> Emulator {
        let child = Command::new(EXE)
            .arg("emulate")
            .args(args)
            .arg("--link")
            .arg(link)
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
        while !link.exists() && std::time::Instant::now() < deadline {
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
        assert!(
            link.exists(),
            "the emulator did not create {}",
            link.display()
        );
        Emulator(child)
    }
}

impl Drop for Emulator {
    fn drop(&mut self) {
        let _ = Command::new("kill")
            .args(["-INT", &self.0.id().to_string()])
            .status();
        let _ = self.0.wait();
    }
}

fn run_session(tag: &str, tracker_args: &[&str]) -> (std::process::Output, Value, String) {
    let dir = Scratch::new(&format!("dev-{tag}"));
    let (glove_link, tracker_link) = (dir.path("glove"), dir.path("tracker"));
    let _glove = Emulator::start(&["glove", "--sensors", "22"], &glove_link);
    let mut args = vec!["tracker"];
    args.extend_from_slice(tracker_args);
    let _tracker = Emulator::start(&args, &tracker_link);
    let session = dir.path("session.toml");
    std::fs::write(
        &session,
        format!(
            "scene = {:?}\n[source]\nkind = \"devices\"\n\
             [source.glove]\nport = {:?}\nsensors = 22\ncalibration = {:?}\n\
             [source.tracker]\nport = {:?}\nformat = \"binary\"\nunits = \"cm\"\n\
             to_world = {{ position = [0.0, 0.45, 0.4], rotation = [0.0, 0.0, 0.0, 1.0] }}\n\
             [renderer]\nmode = \"off\"\n[budget]\nmax_dropped = 0\n",
            repo()
                .join("config/scenes/grasp-throw.toml")
                .to_string_lossy(),
            glove_link.to_string_lossy(),
            repo().join("config/devices/glove-22.cal").to_string_lossy(),
            tracker_link.to_string_lossy(),
        ),
    )
    .unwrap();
    let id = format!("dev{tag}{}", std::process::id());
    let report = dir.path("report.json");
    let out = Command::new(EXE)
        .args([
            "launch",
            "--quiet",
            "--duration",
            "3",
            "--bus-id",
            &id,
            "--report",
        ])
        .arg(&report)
        .arg(&session)
        .output()
        .unwrap();
    assert_nothing_left(&id);
    let v: Value = serde_json::from_str(
        &std::fs::read_to_string(&report)
            .unwrap_or_else(|_| panic!("no report: {}", String::from_utf8_lossy(&out.stderr))),
    )
    .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    (out, v, stderr)
}

/// The session file a user starts with (config/devices/emulated-session.toml): its emulated
/// hand reaches the block and pushes it.
#[test]
fn the_emulated_session_file_s_hand_pushes_its_block() {
    let dir = Scratch::new("dev-file");
    let (glove_link, tracker_link) = (dir.path("glove"), dir.path("tracker"));
    let _glove = Emulator::start(&["glove", "--sensors", "22"], &glove_link);
    let _tracker = Emulator::start(&["tracker"], &tracker_link);
    let id = format!("devfile{}", std::process::id());
    let report = dir.path("report.json");
    let out = Command::new(EXE)
        .args(["launch", "--quiet", "--no-preview", "--duration", "5"])
        .args(["--bus-id", &id, "--set", "renderer.mode=off"])
        .args(["--set", "budget.origin_to_world_p99_us=1000000"])
        .arg("--set")
        .arg(format!("source.glove.port={}", glove_link.display()))
        .arg("--set")
        .arg(format!("source.tracker.port={}", tracker_link.display()))
        .arg("--report")
        .arg(&report)
        .arg(repo().join("config/devices/emulated-session.toml"))
        .output()
        .unwrap();
    assert_nothing_left(&id);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let events = v["world"]["events"].as_array().unwrap();
    assert!(
        events.iter().any(|e| e["kind"] == "push"),
        "the hand never reached the block: {events:?}"
    );
}

#[test]
fn a_session_runs_on_the_emulated_glove_and_tracker_through_real_ttys() {
    let (out, v, stderr) = run_session("ok", &[]);
    assert!(
        out.status.success(),
        "{}\n{stderr}",
        String::from_utf8_lossy(&out.stdout)
    );
    let topic = |t: &str, k: &str| v["topics"][t][k].as_u64().unwrap();
    // 3 s of a 120 Hz tracker and a 100 Hz glove.
    assert!(
        topic("tracker", "published") > 240,
        "{}",
        topic("tracker", "published")
    );
    assert!(
        topic("glove", "published") > 200,
        "{}",
        topic("glove", "published")
    );
    assert_eq!(topic("hand", "published"), topic("tracker", "published"));
    assert_eq!(topic("world", "published"), topic("hand", "published"));
    for t in ["glove", "tracker", "hand", "world"] {
        assert_eq!(topic(t, "dropped"), 0, "{t}");
    }
    // A clean start is a first connection, not a reconnect.
    for d in ["glove", "tracker"] {
        assert_eq!(v["devices"][d]["reconnects"], 0, "{d}: {}", v["devices"]);
    }
}

#[test]
fn a_tracker_that_stops_answering_is_reported_and_the_session_goes_on() {
    // The tracker goes quiet for a second at record 100 (~0.8 s in).
    let (out, v, stderr) = run_session("silent", &["--fault", "silence@100:1000"]);
    assert!(
        out.status.success(),
        "{}\n{stderr}",
        String::from_utf8_lossy(&out.stdout)
    );
    assert!(
        stderr.contains("tracker"),
        "no tracker error was reported: {stderr}"
    );
    let published = v["topics"]["tracker"]["published"].as_u64().unwrap();
    // Before the silence and after the reconnection: samples on both sides of it.
    assert!(published > 130 && published < 330, "{published}");
    assert_eq!(
        v["topics"]["world"]["published"].as_u64().unwrap(),
        published
    );
}

#[test]
fn bad_device_settings_are_refused_before_anything_starts() {
    let dir = Scratch::new("dev-bad");
    let session = dir.path("bad.toml");
    std::fs::write(
        &session,
        format!(
            "scene = {:?}\n[source]\nkind = \"devices\"\n[source.glove]\nport = \"/dev/null\"\nsensors = 19\n\
             [source.tracker]\nport = \"/dev/null\"\n",
            repo().join("config/scenes/grasp-throw.toml").to_string_lossy()
        ),
    )
    .unwrap();
    let out = Command::new(EXE)
        .args(["launch", "--quiet"])
        .arg(&session)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("bad.toml") && stderr.contains("source.glove.sensors"),
        "{stderr}"
    );
}

/// Issue 16: the drivers counted rejected and garbage records, but no report showed them. The
/// session report has them per device, in its table and its JSON.
#[test]
fn garbage_and_rejected_device_records_are_in_the_session_report() {
    let (out, v, stderr) = run_session(
        "noisy",
        &["--fault", "garbage@60", "--fault", "corrupt@120:7"],
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    let tracker = &v["devices"]["tracker"];
    let count = |k: &str| tracker[k].as_u64().unwrap_or_else(|| panic!("{k}: {v:#}"));
    assert!(count("garbage_bytes") > 0, "{tracker}");
    assert!(
        count("garbage_bytes") + count("rejected_records") >= 2,
        "{tracker}"
    );
    // Every valid record was published, those read as the session stopped too (a fresh
    // tests/run once saw 3 of them unpublished while the machine was loaded), unless the
    // publisher fell behind the drivers (said, as dropped).
    let published = v["topics"]["tracker"]["published"].as_u64().unwrap();
    assert!(
        count("samples") == published || stderr.contains("were dropped"),
        "{tracker} vs {published}"
    );
    assert!(
        v["devices"]["glove"]["samples"].as_u64().unwrap() > 200,
        "{v:#}"
    );
    assert!(
        stdout.contains("device     samples  garbage rejected"),
        "{stdout}"
    );
}
