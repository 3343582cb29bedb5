//! Replay of real recorded hands (CARL traces: Meta Quest hand tracking, OpenXR joints) in
//! place of acquisition (issue 5, in part).

use std::path::PathBuf;
use std::process::Command;

use common::{BlockMode, JointsSample, Topic, WorldSample};
use recording::Recording;

mod support;
use support::{assert_nothing_left, assert_same_poses, repo, simulate_trace, Scratch, EXE};

fn carl(name: &str) -> PathBuf {
    repo().join("../shared/data/carl").join(name)
}

/// Replays `trace` through the five processes at `speed`; returns the last world sample.
fn replay(tag: &str, trace: &str, speed: f64, seconds: f64) -> WorldSample {
    let dir = Scratch::new(&format!("replay-{tag}"));
    let log = dir.path("replay.mcap");
    let session = dir.path("replay.toml");
    std::fs::write(
        &session,
        format!(
            "scene = {:?}\n[source]\nkind = \"replay\"\nfile = {:?}\nspeed = {speed}\noffset = [0.0, -0.85, 0.0]\n\
             [renderer]\nmode = \"off\"\n[recorder]\nfile = {:?}\n[budget]\nmax_dropped = 0\n",
            repo().join("config/scenes/drop.toml").to_string_lossy(),
            carl(trace).to_string_lossy(),
            log.to_string_lossy(),
        ),
    )
    .unwrap();
    let id = format!("rp{tag}{}", std::process::id());
    let out = Command::new(EXE)
        .args([
            "launch",
            "--quiet",
            "--duration",
            &seconds.to_string(),
            "--bus-id",
            &id,
        ])
        .arg(&session)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert_nothing_left(&id);
    let rec = Recording::open(&log).unwrap();
    let joints = rec.samples::<JointsSample>(Topic::Joints).count();
    assert_eq!(
        joints,
        218,
        "{tag}: every sample of the trace was replayed\n{}",
        String::from_utf8_lossy(&out.stdout)
    );
    rec.worlds().last().unwrap()
}

#[test]
fn a_replay_is_the_same_world_at_any_speed_and_in_one_process() {
    // Recorded timing (2.4 s) and as fast as the pipeline consumes (both given ample time on a
    // loaded machine): the world follows the
    // trace's own source times, so both give the same bits, and so does `simulate --hand`.
    let timed = replay("timed", "example_push_0.carl", 1.0, 6.0);
    let fast = replay("fast", "example_push_0.carl", 0.0, 5.0);
    assert_eq!(timed.step, fast.step);
    assert_eq!(timed.blocks(), fast.blocks());
    assert_eq!(timed.finger_points, fast.finger_points);

    let v = simulate_trace(
        &repo().join("config/scenes/drop.toml"),
        &carl("example_push_0.carl"),
        [0.0, -0.85, 0.0],
        timed.step,
    );
    assert_eq!(v["frames"].as_u64(), Some(timed.step));
    assert_same_poses(&v, &timed);
}

/// `simulate --hand TRACE config/scenes/drop.toml`.
fn simulate_drop_with(trace: &std::path::Path) -> std::process::Output {
    Command::new(EXE)
        .args(["simulate", "--hand"])
        .arg(trace)
        .arg(repo().join("config/scenes/drop.toml"))
        .output()
        .unwrap()
}

#[test]
fn a_damaged_trace_names_the_file_and_offset_and_the_good_part_still_runs() {
    let dir = Scratch::new("replay-bad");
    let bytes = std::fs::read(carl("example_lift_0.carl")).unwrap();
    let cut = dir.path("cut.carl");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let out = simulate_drop_with(&cut);
    assert!(out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("cut.carl: at byte ") && stderr.contains("using the"),
        "{stderr}"
    );

    // MCAP's magic and then garbage: read as a recording, damaged right after the magic.
    let err = refused(&dir, "wrong.carl", b"\x89MCAP0\r\n not a trace");
    assert!(
        err.contains("wrong.carl: no hand samples")
            && err.contains("wrong.carl: damaged at byte offset 8"),
        "{err}"
    );
    // Neither kind.
    let err = refused(&dir, "junk.carl", b"JUNKJUNKJUNK");
    assert!(
        err.contains("junk.carl: at byte 0: not a CARL file"),
        "{err}"
    );
}

/// Issue 16: a speed-0 replay of a 10 kHz recording gave the stepper everything, but the
/// recorder 1,907 of 30,124 glove samples and the renderer 1,025 of 30,124 worlds: only the
/// stepper paced the replay. A speed-0 session's bus is lossless: every publisher waits for
/// its slowest reader, so every reader gets every sample.
#[test]
fn a_speed_0_replay_of_a_10_khz_recording_reaches_every_reader_whole() {
    let dir = Scratch::new("replay-10k");
    let source = dir.path("10k.mcap");
    let live = Command::new(EXE)
        .current_dir(repo())
        .args(["launch", "--quiet", "--no-preview", "--duration", "2"])
        .args([
            "--set",
            "source.rate_hz=10000",
            "--set",
            "renderer.mode=off",
        ])
        .args(["--set", "budget.origin_to_world_p99_us=1000000"])
        .args(["--bus-id", &format!("r10k{}", std::process::id())])
        .arg("--record")
        .arg(&source)
        .arg("config/sessions/live.toml")
        .output()
        .unwrap();
    assert!(live.status.success(), "{}", support::both(&live));
    let recorded = Recording::open(&source).unwrap().stats()[Topic::Glove as usize].messages;
    assert!(recorded > 15_000, "{recorded} glove samples recorded");

    let session = dir.path("replay.toml");
    std::fs::write(
        &session,
        format!(
            "scene = {:?}\n[source]\nkind = \"replay\"\nfile = {:?}\nspeed = 0\n\
             [renderer]\nmode = \"headless\"\nwidth = 160\nheight = 120\n[recorder]\nfile = {:?}\n\
             [budget]\nmax_dropped = 0\n",
            repo()
                .join("config/scenes/grasp-throw.toml")
                .to_string_lossy(),
            source.to_string_lossy(),
            dir.path("again.mcap").to_string_lossy(),
        ),
    )
    .unwrap();
    let report = dir.path("report.json");
    let id = format!("rp10k{}", std::process::id());
    let out = support::launch_session(&session, &id, 60.0, Some(&report));
    assert!(out.status.success(), "{}", support::both(&out));
    every_reader_got(&report, recorded);

    // Issue 28: the recorder, stopped (SIGSTOP) as the replay process starts and resumed
    // 0.5 s later, had not yet connected to the replay's publishers: iceoryx2 skipped it once
    // its buffer was full, and it lost 33 glove and 32 tracker samples, in 10 runs of 10. The
    // replay now fills at most half its buffer until it has taken its first sample.
    std::fs::remove_file(dir.path("again.mcap")).unwrap();
    let report = dir.path("stopped.json");
    let id = format!("rp10s{}", std::process::id());
    let child = Command::new(EXE)
        .current_dir(repo())
        .args(["launch", "--quiet", "--duration", "60", "--bus-id", &id])
        .arg("--report")
        .arg(&report)
        .arg(&session)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(30);
    while support::find_service_now("replay", &id).is_none() {
        assert!(std::time::Instant::now() < deadline, "no replay process");
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    let recorder = support::find_service_now("recorder", &id).expect("a recorder");
    let signal = |s: &str| {
        Command::new("kill")
            .args([s, &recorder.to_string()])
            .status()
            .unwrap()
    };
    assert!(signal("-STOP").success());
    std::thread::sleep(std::time::Duration::from_millis(500));
    assert!(signal("-CONT").success());
    let out = child.wait_with_output().unwrap();
    assert_nothing_left(&id);
    assert!(out.status.success(), "{}", support::both(&out));
    every_reader_got(&report, recorded);
}

/// Every reader of every pipeline topic received `recorded` samples, none dropped (the report at
/// `report`).
fn every_reader_got(report: &std::path::Path, recorded: u64) {
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(report).unwrap()).unwrap();
    for t in ["glove", "tracker", "hand", "world"] {
        assert_eq!(
            v["topics"][t]["published"].as_u64(),
            Some(recorded),
            "{t}: {v:#}"
        );
        for (reader, r) in v["topics"][t]["readers"].as_object().unwrap() {
            assert_eq!(
                r["received"].as_u64(),
                Some(recorded),
                "{t} at the {reader}: {r}"
            );
            assert_eq!(r["dropped"].as_u64(), Some(0), "{t} at the {reader}: {r}");
        }
    }
}

/// The byte offset of sample `k`'s timestamp in a CARL file (FORMAT.md's layout: a 20-byte
/// header, then per sample a timestamp and seven optional poses, hands and controllers).
fn carl_timestamp_offset(bytes: &[u8], k: usize) -> usize {
    const SIZES: [usize; 7] = [28, 28, 28, 26 * 28, 26 * 28, 28, 28];
    let mut at = 20;
    for i in 0..=k {
        if i == k {
            return at;
        }
        at += 8;
        for size in SIZES {
            let present = bytes[at] == 1;
            at += 1 + if present { size } else { 0 };
        }
    }
    unreachable!()
}

/// Issue 16: one sample time set far in the future (a 4-byte change in a CARL file) made the
/// stepper try ~2e12 catch-up steps: `simulate` hung even with `--frames`, and a live replay
/// slept until then. The trace loader re-times the samples after a jump of more than 10 s and
/// says so (and the stepper's timeline takes one step for any jump a live source makes).
#[test]
fn a_trace_whose_clock_jumps_decades_ahead_runs_promptly_and_says_so() {
    let dir = Scratch::new("replay-jump");
    let mut bytes = std::fs::read(carl("example_push_0.carl")).unwrap();
    let at = carl_timestamp_offset(&bytes, 100);
    let t = f64::from_le_bytes(bytes[at..at + 8].try_into().unwrap());
    assert!(t.is_finite() && t > 0.0 && t < 1e6, "sample 100's time {t}");
    bytes[at..at + 8].copy_from_slice(&(t + 2.0e9).to_le_bytes());
    let jumped = dir.path("jumped.carl");
    std::fs::write(&jumped, &bytes).unwrap();
    let mut child = Command::new(EXE)
        .args(["simulate", "--hand"])
        .arg(&jumped)
        .args(["--hand-offset=0,-0.85,0", "--frames", "600"])
        .arg(repo().join("config/scenes/drop.toml"))
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let start = std::time::Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > std::time::Duration::from_secs(60) {
            let _ = child.kill();
            panic!("simulate still runs after 60 s on a trace whose clock jumps");
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let out = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stdout.contains("after 600 steps"), "{stdout}");
    assert!(
        stderr.contains("jumped.carl: sample 100 (joints topic) is +2000000000.")
            && stderr.contains("re-timed"),
        "{stderr}"
    );
    // Re-timed, the trace is the original but for one 10 ms step: the same pushing hand.
    assert!(!stdout.contains("clock jumped"), "{stdout}");
}

/// Writes `bytes` as trace `name`, checks that `simulate --hand` refuses it (exit 2), and
/// returns what it said.
fn refused(dir: &Scratch, name: &str, bytes: &[u8]) -> String {
    let file = dir.path(name);
    std::fs::write(&file, bytes).unwrap();
    let out = simulate_drop_with(&file);
    assert_eq!(out.status.code(), Some(2));
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// What a recording's hand must do to its scene's block.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Contact {
    /// Pushed, never grasped.
    Push,
    /// Grasped, and while grasped the block's centre rose at least this high (metres).
    GraspLiftedTo(f64),
    /// Grasped, and while grasped the block travelled at least this far horizontally.
    GraspCarried(f64),
    /// Grasped.
    Grasp,
}

/// Replays `config/sessions/replay-carl-NAME.toml` as shipped (recorded timing), records it,
/// and checks the kind of contact, that nothing is NaN, and that `simulate --hand` agrees.
fn carl_session_meets_its_block(name: &str, contact: Contact) {
    let session_file = repo().join(format!("config/sessions/replay-carl-{name}.toml"));
    let session = common::config::Session::load(&session_file).unwrap();
    let common::config::session::Source::Replay { file, offset, .. } = &session.source else {
        panic!("{name}: not a replay session");
    };
    let trace = replay::CarlTrace::load(file).unwrap();
    let dir = Scratch::new(&format!("carl-{name}"));
    let rec_file = dir.path("run.mcap");
    let id = format!("cs{name}{}", std::process::id());
    let out = Command::new(EXE)
        .current_dir(repo())
        .args(["launch", "--quiet", "--bus-id", &id, "--duration"])
        .arg((trace.duration() + 1.5).to_string())
        .arg("--record")
        .arg(&rec_file)
        .arg(&session_file)
        .output()
        .unwrap();
    assert_nothing_left(&id);
    assert!(
        out.status.success(),
        "{name}: {}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let rec = Recording::open(&rec_file).unwrap();
    let worlds: Vec<WorldSample> = rec.worlds().collect();
    assert_eq!(
        worlds.len(),
        trace.samples.len(),
        "{name}: one world per sample"
    );
    for w in &worlds {
        let finite = w.blocks().iter().all(|b| b.pose.is_finite())
            && w.finger_points
                .iter()
                .flatten()
                .flatten()
                .all(|v| v.is_finite());
        assert!(finite, "{name}: world {} holds a NaN", w.stamp.seq);
    }
    let modes: Vec<BlockMode> = worlds.iter().map(|w| w.blocks()[0].mode()).collect();
    let grasped: Vec<&WorldSample> = worlds.iter().filter(|w| w.grasped_block == 0).collect();
    match contact {
        Contact::Push => {
            assert!(
                modes.contains(&BlockMode::Pushed),
                "{name}: never pushed: {modes:?}"
            );
            assert!(grasped.is_empty(), "{name}: grasped");
        }
        Contact::Grasp => assert!(!grasped.is_empty(), "{name}: never grasped: {modes:?}"),
        Contact::GraspLiftedTo(height) => {
            let top = grasped
                .iter()
                .map(|w| w.blocks()[0].pose.position[1])
                .fold(f64::MIN, f64::max);
            assert!(top >= height, "{name}: lifted only to {top} m: {modes:?}");
        }
        Contact::GraspCarried(distance) => {
            let at = |w: &WorldSample| {
                let p = w.blocks()[0].pose.position;
                (p[0], p[2])
            };
            let (Some(first), Some(last)) = (grasped.first(), grasped.last()) else {
                panic!("{name}: never grasped: {modes:?}");
            };
            let (a, b) = (at(first), at(last));
            let moved = ((a.0 - b.0).powi(2) + (a.1 - b.1).powi(2)).sqrt();
            assert!(moved >= distance, "{name}: carried only {moved} m");
        }
    }

    // Our recording of it (the `joints` topic, offset already applied) replays to the same
    // worlds, as fast as the pipeline consumes it.
    if name == "push" {
        let again_session = dir.path("again.toml");
        let again_file = dir.path("again.mcap");
        std::fs::write(
            &again_session,
            format!(
                "scene = {:?}\n[source]\nkind = \"replay\"\nfile = {:?}\nspeed = 0\n[renderer]\nmode = \"off\"\n[budget]\nmax_dropped = 0\n",
                session.scene_file.to_string_lossy(),
                rec_file.to_string_lossy()
            ),
        )
        .unwrap();
        let id = format!("ca{name}{}", std::process::id());
        let out = Command::new(EXE)
            .args([
                "launch",
                "--quiet",
                "--bus-id",
                &id,
                "--duration",
                "3",
                "--record",
            ])
            .arg(&again_file)
            .arg(&again_session)
            .output()
            .unwrap();
        assert_nothing_left(&id);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let again: Vec<WorldSample> = Recording::open(&again_file).unwrap().worlds().collect();
        assert_eq!(again.len(), worlds.len());
        for (a, b) in again.iter().zip(&worlds) {
            assert_eq!((a.stamp.seq, a.step), (b.stamp.seq, b.step));
            assert_eq!(a.blocks(), b.blocks(), "world {}", a.stamp.seq);
            assert_eq!(a.finger_points, b.finger_points, "world {}", a.stamp.seq);
        }
    }

    // The same world in one process.
    let last = worlds.last().unwrap();
    let v = simulate_trace(&session.scene_file, file, *offset, last.step);
    assert_same_poses(&v, last);
}

#[test]
fn the_carl_push_recording_pushes_its_block() {
    carl_session_meets_its_block("push", Contact::Push);
}

#[test]
fn the_carl_pull_recording_closes_the_hand_around_its_block() {
    carl_session_meets_its_block("pull", Contact::Grasp);
}

#[test]
fn the_carl_lift_recording_picks_its_block_up() {
    carl_session_meets_its_block("lift", Contact::GraspLiftedTo(0.4));
}

#[test]
fn the_carl_settle_recording_carries_its_block_and_puts_it_down() {
    carl_session_meets_its_block("settle", Contact::GraspCarried(0.3));
}

/// Issue 41 item 1: both hands of a CARL trace through the processes (`[source] hands =
/// "both"`: the replay sends each sample's right and left, kinematics makes each apart, the
/// stepper takes them as one frame) give the world `simulate --hands both` gives, bit for bit;
/// the recording holds both hands (the left's `joints` and `hand` samples marked side 1).
#[test]
fn both_hands_of_a_carl_trace_replay_to_the_world_simulate_gives() {
    let trace = carl("example_lift_0.carl");
    let scene = repo().join("config/scenes/carl-lift.toml");
    let samples = replay::CarlTrace::load(&trace).unwrap().samples.len();
    let dir = Scratch::new("replay-both-hands");
    let (log, session) = (dir.path("both.mcap"), dir.path("both.toml"));
    std::fs::write(
        &session,
        format!(
            "scene = {:?}\n[source]\nkind = \"replay\"\nfile = {:?}\nspeed = 0\nhands = \"both\"\n\
             offset = [0.0, -0.92, 0.0]\n[renderer]\nmode = \"off\"\n[recorder]\nfile = {:?}\n\
             [budget]\nmax_dropped = 0\n",
            scene.to_string_lossy(),
            trace.to_string_lossy(),
            log.to_string_lossy(),
        ),
    )
    .unwrap();
    let id = format!("rb{}", std::process::id());
    let out = Command::new(EXE)
        .args(["launch", "--quiet", "--duration", "6", "--bus-id", &id])
        .arg(&session)
        .output()
        .unwrap();
    assert_nothing_left(&id);
    assert!(
        out.status.success(),
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let rec = Recording::open(&log).unwrap();
    let joints: Vec<JointsSample> = rec.samples::<JointsSample>(Topic::Joints).collect();
    assert_eq!(joints.len(), 2 * samples, "both hands of every sample");
    assert!(joints.chunks(2).all(|p| p[0].side == 0
        && p[1].side == 1
        && p[0].stamp.source_time_ns == p[1].stamp.source_time_ns));
    let hands: Vec<common::HandSample> = rec.samples(Topic::Hand).collect();
    assert_eq!(hands.iter().filter(|h| h.side == 1).count(), samples);
    let last = rec.worlds().last().unwrap();
    let out = Command::new(EXE)
        .args(["simulate", "--json", "--hands", "both", "--frames"])
        .arg(last.step.to_string())
        .args(["--hand-offset", "0,-0.92,0", "--hand"])
        .arg(&trace)
        .arg(&scene)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["frames"].as_u64(), Some(last.step));
    assert_same_poses(&v, &last);
    // The held cube says which hand holds it (bit 0: the right) while grasped.
    assert!(rec
        .worlds()
        .any(|w| w.blocks()[0].mode() == BlockMode::Grasped && w.blocks()[0].held_by == 1));
}
