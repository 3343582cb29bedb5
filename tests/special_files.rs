//! Issue 40, finding 8: a FIFO, a device, a socket or a folder given where a file is read is
//! refused at once, by name and kind, before anything opens it for reading. A FIFO with no
//! writer used to block `simulate --hand` for ever (the file was opened, blocking, before its
//! type was checked), and `replay` called it "no such file". Every command here runs under a
//! deadline, so that a regression fails instead of hanging the suite.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

mod support;
use support::{repo, Scratch, EXE};

/// How long a refusal may take: it is immediate; a blocked open never ends.
const DEADLINE: Duration = Duration::from_secs(30);

/// Runs `handblocks ARGS` in `dir` with nothing on stdin; its exit status and its stdout and
/// stderr together. Kills it and fails the test when it outlives [`DEADLINE`].
fn run_with_deadline(dir: &Path, args: &[&str]) -> (std::process::ExitStatus, String) {
    let mut child = Command::new(EXE)
        .current_dir(dir)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run handblocks");
    let start = Instant::now();
    while child.try_wait().expect("wait for handblocks").is_none() {
        if start.elapsed() > DEADLINE {
            let _ = child.kill();
            let _ = child.wait();
            panic!("handblocks {args:?} still ran after {DEADLINE:?}: it blocked on the file");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let out = child.wait_with_output().expect("handblocks' output");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status, text)
}

/// A FIFO (named pipe) at `path`, with no writer.
fn mkfifo(path: &Path) {
    use std::os::unix::ffi::OsStrExt as _;
    let c = std::ffi::CString::new(path.as_os_str().as_bytes()).expect("a path without NUL");
    // SAFETY: a NUL-terminated path that outlives the call.
    let rc = unsafe { libc::mkfifo(c.as_ptr(), 0o600) };
    assert_eq!(rc, 0, "mkfifo {}", path.display());
}

fn scene() -> String {
    repo()
        .join("config/scenes/carl-push.toml")
        .display()
        .to_string()
}

/// Refused (exit status not 0), naming the file and what it is.
fn assert_refused(status: std::process::ExitStatus, text: &str, name: &str, kind: &str) {
    assert!(!status.success(), "{text}");
    assert!(text.contains(name), "the message names {name}: {text}");
    assert!(
        text.contains(&format!("it is {kind}, not a regular file")),
        "the message says it is {kind}: {text}"
    );
}

#[test]
fn simulate_refuses_a_fifo_as_hand_trace_instead_of_blocking() {
    let dir = Scratch::new("special-simulate-hand");
    let fifo = dir.path("lift.fifo");
    mkfifo(&fifo);
    let (status, text) = run_with_deadline(
        &dir.0,
        &[
            "simulate",
            &scene(),
            "--hand",
            "lift.fifo",
            "--frames",
            "10",
        ],
    );
    assert_refused(status, &text, "lift.fifo", "a FIFO (named pipe)");
}

#[test]
fn simulate_refuses_a_folder_or_a_device_as_hand_trace_by_kind() {
    let dir = Scratch::new("special-simulate-kinds");
    std::fs::create_dir(dir.path("traces")).expect("a folder");
    let (status, text) = run_with_deadline(
        &dir.0,
        &["simulate", &scene(), "--hand", "traces", "--frames", "10"],
    );
    assert_refused(status, &text, "traces", "a folder");
    let (status, text) = run_with_deadline(
        &dir.0,
        &[
            "simulate",
            &scene(),
            "--hand",
            "/dev/zero",
            "--frames",
            "10",
        ],
    );
    assert_refused(status, &text, "/dev/zero", "a character device");
}

#[test]
fn simulate_refuses_a_fifo_as_scene_instead_of_blocking() {
    let dir = Scratch::new("special-simulate-scene");
    mkfifo(&dir.path("scene.toml"));
    let (status, text) = run_with_deadline(&dir.0, &["simulate", "scene.toml", "--frames", "10"]);
    assert_refused(status, &text, "scene.toml", "a FIFO (named pipe)");
}

#[test]
fn replay_names_a_fifo_a_fifo_not_a_missing_file() {
    let dir = Scratch::new("special-replay");
    mkfifo(&dir.path("lift.fifo"));
    let (status, text) = run_with_deadline(&dir.0, &["replay", "lift.fifo", "--quiet"]);
    assert_refused(status, &text, "lift.fifo", "a FIFO (named pipe)");
    assert!(!text.contains("no such file"), "{text}");
}

#[test]
fn replay_names_a_socket_and_a_folder_by_kind() {
    let dir = Scratch::new("special-replay-kinds");
    let _listener =
        std::os::unix::net::UnixListener::bind(dir.path("hand.sock")).expect("a unix socket");
    let (status, text) = run_with_deadline(&dir.0, &["replay", "hand.sock", "--quiet"]);
    assert_refused(status, &text, "hand.sock", "a socket");
    std::fs::create_dir(dir.path("traces")).expect("a folder");
    let (status, text) = run_with_deadline(&dir.0, &["replay", "traces", "--quiet"]);
    assert_refused(status, &text, "traces", "a folder");
}

#[test]
fn inspect_refuses_a_fifo_instead_of_blocking() {
    let dir = Scratch::new("special-inspect");
    mkfifo(&dir.path("live.mcap"));
    let (status, text) = run_with_deadline(&dir.0, &["inspect", "live.mcap"]);
    assert_refused(status, &text, "live.mcap", "a FIFO (named pipe)");
}
