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
        .args(["--loop", "--duration", "15", "--quiet", "--no-preview"])
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
    // Issue 43: nothing waits in silence. A CARL replay sends joints, not glove (its replay
    // process holds a glove publisher that never sends): echo says so within a second, naming
    // what the session does send, and exits 2 (it used to wait for the session's end).
    let none = run_in(&dir.0, &["echo", "glove", "--session", &id, "-n", "1"]);
    assert_eq!(none.status.code(), Some(2), "{}", both(&none));
    let text = both(&none);
    assert!(
        text.contains("nothing sends glove")
            && text.contains("it sends joints, hand, world")
            && text.contains("--wait"),
        "{text}"
    );
    // The same look at a topic it sends prints at once.
    let rate = |name: &str, list: &Value| {
        list.as_array()
            .and_then(|l| l.iter().find(|t| t["topic"] == name))
            .and_then(|t| t["rate_hz"].as_f64())
    };
    // Asked to wait, hz says it waits, and --seconds ends it on time with no sample.
    let hz = run_in(
        &dir.0,
        &["hz", "glove", "--session", &id, "--seconds", "2", "--wait"],
    );
    let text = both(&hz);
    assert!(hz.status.success(), "{text}");
    assert!(
        text.contains("no sample in 1 s; waiting") && text.contains("0 samples"),
        "{text}"
    );
    // `topics`: every recorded topic with its publishers, readers and type (as ros2 -v).
    let topics = run_in(
        &dir.0,
        &["topics", "--session", &id, "--json", "--window", "0.5"],
    );
    assert!(topics.status.success(), "{}", both(&topics));
    let list: Value = serde_json::from_slice(&topics.stdout).expect("topics --json");
    let entry = |name: &str| {
        list.as_array()
            .and_then(|l| l.iter().find(|t| t["topic"] == name))
            .cloned()
            .unwrap_or_else(|| panic!("{name} missing: {list}"))
    };
    assert!(entry("/joints")["publishers"].as_u64() >= Some(1), "{list}");
    // Rates read through the look's own inlets: a CARL trace's ~90 a second, no glove.
    assert!(
        rate("/joints", &list).is_some_and(|r| r > 10.0 && r < 1000.0),
        "{list}"
    );
    assert_eq!(rate("/glove", &list), Some(0.0), "{list}");
    assert!(entry("/hand")["readers"].as_u64() >= Some(1), "{list}");
    assert!(
        entry("/world")["type"]
            .as_str()
            .is_some_and(|t| t.starts_with("handblocks/")),
        "{list}"
    );
    let plain = run_in(&dir.0, &["topics", "--session", &id]);
    let text = String::from_utf8_lossy(&plain.stdout).into_owned();
    assert!(text.lines().any(|l| l == "/world"), "{text}");
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

/// Issue 43: a path given with --set starts where the user stands, as on any command line
/// (it used to start at the session file's folder, config/sessions/).
#[test]
fn a_set_path_starts_at_the_current_folder() {
    let trace = repo().join("../shared/data/carl/example_push_0.carl");
    if !trace.is_file() {
        eprintln!("skipped: {} is not there", trace.display());
        return;
    }
    let dir = Scratch::new("set-path");
    std::fs::copy(&trace, dir.path("my.carl")).unwrap();
    let out = run_in(
        &dir.0,
        &[
            "launch",
            "replay-carl-push",
            "--set",
            "source.file=my.carl",
            "--set",
            "renderer.mode=off",
            "--duration",
            "1",
            "--quiet",
            "--no-preview",
        ],
    );
    let text = both(&out);
    assert!(out.status.success(), "{text}");
    assert!(!text.contains("config/sessions/my.carl"), "{text}");
}

/// Runs `handblocks ARGS` with `TMPDIR` set (where it looks for session folders besides
/// /tmp) and its address space capped at 2 GiB (a card read without bound, a link to
/// /dev/zero, then fails at once instead of taking the machine's memory), for at most
/// `within`: None when it had not ended by then (it is killed).
fn run_bounded(tmpdir: &std::path::Path, args: &[&str], within: Duration) -> Option<Output> {
    let mut cmd = Command::new("sh");
    cmd.arg("-c")
        .arg("ulimit -v 2097152; exec \"$0\" \"$@\"")
        .arg(EXE)
        .args(args)
        .env("TMPDIR", tmpdir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    let mut child = cmd.spawn().expect("run handblocks");
    let deadline = Instant::now() + within;
    while child.try_wait().unwrap().is_none() {
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            return None;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    Some(child.wait_with_output().unwrap())
}

/// When process `pid` started: /proc/PID/stat's 22nd field (clock ticks after boot).
fn start_ticks(pid: u32) -> u64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap();
    let rest = &stat[stat.rfind(')').unwrap() + 1..];
    rest.split_whitespace().nth(19).unwrap().parse().unwrap()
}

/// Issue 40, finding 11: `handblocks sessions` read every `session.toml` under this user's
/// folder of sessions: it listed a card another user owns, hung for ever on a card that is a
/// FIFO, read a card linked to /dev/zero until memory ran out, and listed as running a card
/// naming any live pid (`echo` and `hz` then waited for ever). Now a card is listed only when
/// it is a regular file of this user's, of a few KiB at most, in a folder of this user's, and
/// the pid and start time it records are a live process's of this user (its launcher).
#[test]
fn sessions_lists_only_cards_of_this_user_that_name_their_running_launcher() {
    use std::os::unix::fs::DirBuilderExt as _;
    let dir = Scratch::new("tools-cards");
    // SAFETY: getuid has no preconditions.
    let uid = unsafe { libc::getuid() };
    let base = dir.path(&format!("hb-iox2-{uid}"));
    std::fs::DirBuilder::new()
        .mode(0o700)
        .create(&base)
        .unwrap();
    let me = std::process::id();
    let ticks = start_ticks(me);
    let tag = format!("k{}", me % 100_000);
    // A session folder as a launcher leaves it: its `launcher` record (pid, start time) and its
    // card. This test process stands in for the launcher.
    let folder = |suffix: &str, card_ticks: u64| -> (String, std::path::PathBuf) {
        let id = format!("{tag}{suffix}");
        let root = base.join(&id);
        std::fs::DirBuilder::new()
            .mode(0o700)
            .create(&root)
            .unwrap();
        std::fs::write(root.join("launcher"), format!("{me} {ticks}\n")).unwrap();
        std::fs::write(
            root.join("session.toml"),
            format!(
                "id = \"{id}\"\nsession = \"/x/live.toml\"\nsource = \"scripted\"\n\
                 world_blocks = 1\nlossless = false\nstarted_unix_s = 1\n\
                 launcher_pid = {me}\nlauncher_start_ticks = {card_ticks}\n"
            ),
        )
        .unwrap();
        (id, root)
    };
    // A card as a launcher writes it: listed.
    let (good, _) = folder("g", ticks);
    // The pid of a process that started at another time (the launcher died and the kernel
    // gave its pid to this process): not its launcher.
    folder("r", ticks + 1);
    // A FIFO in place of the card: nobody ever writes it.
    let (_, fifo) = folder("f", ticks);
    let card = fifo.join("session.toml");
    std::fs::remove_file(&card).unwrap();
    let c = std::ffi::CString::new(card.as_os_str().as_encoded_bytes()).unwrap();
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    // A link to /dev/zero: endless.
    let (_, zero) = folder("z", ticks);
    std::fs::remove_file(zero.join("session.toml")).unwrap();
    std::os::unix::fs::symlink("/dev/zero", zero.join("session.toml")).unwrap();
    // A card of another user's (root can make one): not this user's session.
    if uid == 0 {
        let (_, foreign) = folder("o", ticks);
        std::os::unix::fs::chown(foreign.join("session.toml"), Some(4242), Some(4242)).unwrap();
    }

    let out = run_bounded(&dir.0, &["sessions", "--json"], Duration::from_secs(20))
        .expect("`handblocks sessions` hung on a card (a FIFO?)");
    assert!(out.status.success(), "{}", both(&out));
    let list: Value = serde_json::from_slice(&out.stdout).expect("sessions --json");
    let ours: Vec<&str> = list
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|s| s["id"].as_str())
        .filter(|id| id.starts_with(&tag))
        .collect();
    assert_eq!(ours, [good.as_str()], "{list}");
    // The text form and a look at one: the same cards, no hang.
    let out = run_bounded(&dir.0, &["sessions"], Duration::from_secs(20))
        .expect("`handblocks sessions` hung");
    assert!(out.status.success(), "{}", both(&out));
    let out = run_bounded(
        &dir.0,
        &["echo", "world", "--session", &format!("{tag}r")],
        Duration::from_secs(20),
    )
    .expect("`handblocks echo` on a card of a pid that is not its launcher");
    assert_eq!(out.status.code(), Some(2), "{}", both(&out));
    assert!(both(&out).contains("no session"), "{}", both(&out));
}

/// Issue 40, findings 11 and 13: `echo` and `hz` left a file of the session's prefix in
/// /dev/shm (iceoryx2's management segment, made again as they let go of a bus whose files
/// the launcher had removed under them; four after a SIGKILL), and printed iceoryx2's raw
/// warnings about each storage they could not remove when the session ended. Now the session's
/// end withdraws its card and waits a moment for such readers to let go before it removes its
/// files, a reader that let go tidies what an ended session left, and a tool says in one line
/// that the session ended; one killed mid-session leaves nothing either (the launcher removes
/// the session's files).
#[test]
fn echo_and_hz_say_when_the_session_ended_and_leave_nothing() {
    let dir = Scratch::new("tools-end");
    let id = format!("te{}", std::process::id());
    let launcher = Command::new(EXE)
        .current_dir(repo())
        .args(["launch", "--quiet", "--no-preview", "--duration", "6"])
        .args(["--bus-id", &id])
        .args(["--set", "renderer.mode=off"])
        .args(["--set", "budget.origin_to_world_p99_us=1000000"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run handblocks launch");
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let out = run_in(&dir.0, &["sessions", "--json"]);
        let list: Value = serde_json::from_slice(&out.stdout).unwrap_or_default();
        let runs = list.as_array().is_some_and(|l| {
            l.iter().any(|s| {
                s["id"] == id.as_str()
                    && s["processes"]
                        .as_array()
                        .is_some_and(|p| p.iter().any(|p| p["name"] == "stepper"))
            })
        });
        if runs {
            break;
        }
        assert!(Instant::now() < deadline, "the session never showed");
        std::thread::sleep(Duration::from_millis(100));
    }
    let look = |args: &[&str]| {
        Command::new(EXE)
            .current_dir(&dir.0)
            .args(args)
            .args(["--session", &id])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("run handblocks")
    };
    let echo = look(&["echo", "world"]);
    let hz = look(&["hz", "hand"]);
    let mut killed = look(&["echo", "hand"]);
    std::thread::sleep(Duration::from_millis(1500));
    killed.kill().unwrap();
    killed.wait().unwrap();
    let out = launcher.wait_with_output().unwrap();
    assert!(out.status.success(), "{}", both(&out));
    for (tool, child) in [("echo", echo), ("hz", hz)] {
        let out = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr).into_owned();
        assert!(out.status.success(), "{tool}: {}", both(&out));
        assert!(
            err.contains(&format!("handblocks {tool}: session {id} ended")),
            "{tool}: {err}"
        );
        // Its own lines only: none of iceoryx2's log.
        assert!(
            err.lines().all(|l| l.starts_with("handblocks ")),
            "{tool}: {err}"
        );
    }
    assert_nothing_left(&id);
}

/// `inspect FILE --world-hashes`: a line `STEP HASH` per recorded world, in file order, the
/// same on every run (two participants' recordings of a shared session are `diff`ed), each
/// hash the world's [`common::world_hash`]; a recording without worlds is refused, naming it.
#[test]
fn inspect_lists_a_hash_per_recorded_world_and_refuses_a_file_without_worlds() {
    let dir = Scratch::new("tools-hashes");
    let file = dir.path("hashes.mcap");
    let id = format!("th{}", std::process::id());
    let out = Command::new(EXE)
        .current_dir(repo())
        .args(["launch", "--quiet", "--no-preview", "--duration", "2"])
        .args(["--bus-id", &id])
        .args(["--set", "renderer.mode=off"])
        .args(["--set", "budget.origin_to_world_p99_us=1000000"])
        .arg("--record")
        .arg(&file)
        .output()
        .expect("run handblocks launch");
    assert_nothing_left(&id);
    assert!(out.status.success(), "{}", both(&out));

    let hashes = || run_in(&dir.0, &["inspect", "hashes.mcap", "--world-hashes"]);
    let out = hashes();
    assert!(out.status.success(), "{}", both(&out));
    assert!(out.stderr.is_empty(), "{}", both(&out));
    let text = String::from_utf8(out.stdout.clone()).unwrap();
    let worlds: Vec<common::WorldSample> = recording::Recording::open(&file)
        .unwrap()
        .worlds()
        .collect();
    assert!(worlds.len() > 10, "{} worlds", worlds.len());
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), worlds.len(), "{text}");
    let mut last_step = None;
    for (line, w) in lines.iter().zip(&worlds) {
        let (step, hash) = line.split_once(' ').expect("STEP HASH");
        let step: u64 = step.parse().expect("a step");
        assert!(last_step < Some(step), "steps not increasing at {line}");
        last_step = Some(step);
        assert_eq!(hash.len(), 16, "{line}");
        assert!(
            hash.bytes().all(|c| matches!(c, b'0'..=b'9' | b'a'..=b'f')),
            "{line}"
        );
        assert_eq!(step, w.step);
        assert_eq!(
            u64::from_str_radix(hash, 16).unwrap(),
            common::world_hash::of_view(&w.view())
        );
    }
    // The blocks moved (the scripted hand grasps and throws one): the hashes are not all one.
    let distinct: std::collections::BTreeSet<&str> =
        lines.iter().map(|l| l.split_once(' ').unwrap().1).collect();
    assert!(distinct.len() > 1, "{text}");
    // Twice, the same bytes.
    assert_eq!(hashes().stdout, out.stdout);

    // With the table's --json or another listing: refused by name.
    for other in [&["--json"][..], &["--samples", "world"]] {
        let mut args = vec!["inspect", "hashes.mcap", "--world-hashes"];
        args.extend(other);
        let out = run_in(&dir.0, &args);
        assert_eq!(out.status.code(), Some(2), "{}", both(&out));
        assert!(
            String::from_utf8_lossy(&out.stderr).contains("cannot be used with"),
            "{}",
            both(&out)
        );
    }

    // A recording of a glove alone: no worlds to hash.
    let gloves = dir.path("gloves.mcap");
    let mut w = recording::RecordingWriter::create(&gloves).unwrap();
    for k in 0..10u64 {
        let g = common::GloveSample {
            stamp: common::Stamp {
                seq: k,
                source_time_ns: k * 8_333_333,
                origin_ns: 1_000 + k * 8_333_333,
                publish_ns: 2_000 + k * 8_333_333,
            },
            ..Default::default()
        };
        w.write(common::Topic::Glove, &g).unwrap();
    }
    w.finish().unwrap();
    let out = run_in(&dir.0, &["inspect", "gloves.mcap", "--world-hashes"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{}", both(&out));
    assert!(out.stdout.is_empty(), "{}", both(&out));
    assert!(
        err.contains("gloves.mcap: holds no world samples") && err.contains("glove 10"),
        "{err}"
    );
}
