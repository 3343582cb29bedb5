//! Issue 43: every wrong usage says what to do next, before anything starts. One test per
//! message: the command as a new user typed it, and what the answer must say (what was
//! wrong, the allowed range or kind, and the command that does what they meant). Each comment
//! gives the message before.
//!
//! Each refusal must exit 2 and start no process (nothing of a session's is printed, and it
//! answers well within the ceiling a refusal could take).

use std::process::Command;
use std::time::{Duration, Instant};

mod support;
use support::{both, repo, Scratch, EXE};

/// Runs `handblocks ARGS` in a scratch folder holding a fake CARL trace (`push.carl`), a fake
/// recording (`live.mcap`), a file (`file`) and a folder (`folder`); returns its output after
/// checking the refusal's exit status and that nothing started.
fn refused(tag: &str, args: &[&str]) -> String {
    let dir = Scratch::new(tag);
    std::fs::write(
        dir.path("push.carl"),
        b"CARL\x01\x00\x00\x00not a real trace",
    )
    .unwrap();
    std::fs::write(dir.path("live.mcap"), b"\x89MCAP0\r\nnot a real recording").unwrap();
    std::fs::write(dir.path("file"), b"a file").unwrap();
    std::fs::create_dir_all(dir.path("folder")).unwrap();
    let started = Instant::now();
    let out = Command::new(EXE)
        .current_dir(&dir.0)
        .args(args)
        .output()
        .unwrap();
    let text = both(&out);
    assert_eq!(out.status.code(), Some(2), "{args:?}: {text}");
    assert!(
        !text.contains("renderer:") && started.elapsed() < Duration::from_secs(30),
        "{args:?} started something: {text}"
    );
    text
}

fn says(tag: &str, args: &[&str], wants: &[&str]) {
    let text = refused(tag, args);
    for want in wants {
        assert!(text.contains(want), "{args:?}: no {want:?} in:\n{text}");
    }
    // clap's "to pass '-1' as a value, use '-- -1'" is not what to do next.
    assert!(!text.contains("use '--"), "{args:?}: {text}");
}

fn config(rel: &str) -> String {
    repo().join("config").join(rel).display().to_string()
}

macro_rules! wrong_usage {
    ($($(#[$doc:meta])* $name:ident: [$($arg:expr),*] => [$($want:expr),*];)*) => {
        $(
            $(#[$doc])*
            #[test]
            fn $name() {
                says(stringify!($name), &[$($arg),*], &[$($want),*]);
            }
        )*
    };
}

wrong_usage! {
    /// Before: "cannot read the file: not UTF-8 text: the byte at offset 12 ...".
    launching_a_carl_trace_points_to_replay:
        ["launch", "push.carl"] => ["a CARL trace (a recorded hand), not a session", "handblocks replay push.carl"];
    /// Before: the same UTF-8 complaint.
    launching_a_recording_points_to_replay:
        ["launch", "live.mcap"] => ["an MCAP recording (a recorded hand), not a session", "handblocks replay live.mcap"];
    /// Before: "cannot read the file: not UTF-8 text ...".
    simulating_a_carl_trace_points_to_simulate_hand:
        ["simulate", "push.carl"] => ["not a scene", "handblocks simulate SCENE --hand push.carl"];
    /// Before: "`budget`: unknown key; allowed here: block, effects, hand, ...".
    simulating_a_session_names_its_scene:
        ["simulate", &config("sessions/live.toml")] => ["a session file, not a scene", "handblocks simulate grasp-throw", "handblocks launch"];
    /// Before: "cannot read the file: it is a folder, not a regular file".
    launching_a_folder_points_to_list:
        ["launch", "folder"] => ["a folder, not a session file", "handblocks list folder"];
    /// Before: the same.
    simulating_a_folder_points_to_list:
        ["simulate", "folder"] => ["a folder, not a scene file", "handblocks list folder"];
    /// Before: "unexpected argument '-5' found; tip: to pass '-5' as a value, use '-- -5'".
    negative_frames_give_the_allowed_range:
        ["simulate", "grasp-throw", "--frames", "-5"] => ["allowed: a whole number of steps, 0 to 10000000"];
    /// Before: accepted, and ran for as long as it took.
    too_many_frames_give_the_allowed_range:
        ["simulate", "grasp-throw", "--frames", "20000000"] => ["0 to 10000000"];
    /// Before: "unexpected argument '-1' found; ... use '-- -1'".
    a_negative_speed_gives_the_allowed_range:
        ["replay", "push.carl", "--speed", "-1"] => ["allowed 0 (as fast as the pipeline takes it) to 1000"];
    /// Before: "No such file or directory (os error 2)".
    inspecting_a_missing_file_says_what_writes_one:
        ["inspect", "nosuch.mcap"] => ["nosuch.mcap: no such file", "handblocks launch --record FILE"];
    /// Before: "not an MCAP recording (wrong magic at offset 0 ...)".
    inspecting_a_carl_trace_points_to_replay_and_python:
        ["inspect", "push.carl"] => ["a CARL trace, not an MCAP recording", "handblocks replay push.carl", "handblocks.Recording"];
    /// Before: the renderer started, then "--frames-dir file: File exists (os error 17)".
    frames_dir_on_a_file_asks_for_a_folder:
        ["launch", "live", "--duration", "1", "--frames-dir", "file"] => ["--frames-dir: file exists and is not a folder", "give a folder"];
    /// Before: "a tracker at ... (Ctrl-C stops it)", then "No such file or directory".
    an_emulated_device_in_a_missing_folder_is_refused_first:
        ["emulate", "tracker", "--link", "nosuch/dir/tracker"] => ["the folder nosuch/dir does not exist", "e.g. /tmp/tracker"];
    /// Before: "no session runs on this machine" (the count was never checked).
    echo_zero_samples_gives_the_allowed_range:
        ["echo", "world", "-n", "0"] => ["1 or more", "leave -n out to print until Ctrl-C"];
    /// Before: "unexpected argument '-3' found; ... use '-- -3'".
    echo_a_negative_count_gives_the_allowed_range:
        ["echo", "world", "-n", "-3"] => ["1 or more"];
    /// Before: "/tmp/.../nosuch.toml: cannot read the file: No such file or directory" (not
    /// which key named it, nor that --set gave it).
    a_missing_scene_names_the_key_that_named_it:
        ["launch", "live", "--set", "scene=nosuch.toml"] => ["`scene`: ", "nosuch.toml: no such scene file", "(given with --set)", "`handblocks list`"];
    /// Before: the replay's own temporary session named, and "/tmp/nosuch: no such file".
    a_replays_misspelt_scene_is_suggested:
        ["replay", "push.carl", "--scene", "carl-psh"] => ["--scene carl-psh: no such file, and no scene of that name (did you mean `carl-push`?)"];
    /// Already good, kept: a bare misspelt scene name.
    a_misspelt_scene_is_suggested:
        ["simulate", "grasp-thro"] => ["did you mean `grasp-throw`?", "`handblocks list` lists them"];
    /// Before: "`world.stephz`: unknown key; allowed here: ..." (the nearest not named).
    an_unknown_set_key_lists_the_allowed_keys:
        ["simulate", "grasp-throw", "--set", "world.stephz=120"] => ["`world.stephz`: unknown key (did you mean `step_hz`?); allowed here:", "(given with --set)"];
    /// Already good, kept: an out-of-range key gives its range.
    an_out_of_range_set_value_gives_the_range:
        ["simulate", "grasp-throw", "--set", "world.step_hz=0"] => ["`world.step_hz`: 0 is out of range; allowed: 1 to 100000"];
    /// Already good, kept: --set without a value.
    a_set_without_a_value_shows_the_form:
        ["simulate", "grasp-throw", "--set", "world.step_hz"] => ["give KEY=VALUE, e.g. renderer.mode=off"];
    /// Already good, kept: an enum key lists its values.
    a_wrong_render_mode_lists_the_modes:
        ["launch", "live", "--set", "renderer.mode=fancy"] => ["\"fancy\" is not allowed; one of: \"headless\", \"window\", \"off\""];
    /// Already good, kept: an offset of two numbers.
    a_short_offset_asks_for_three_numbers:
        ["simulate", "grasp-throw", "--hand", "push.carl", "--hand-offset", "1,2"] => ["give three numbers, X,Y,Z (metres)"];
    /// Already good, kept: a bus id with a slash.
    a_bad_bus_id_gives_the_allowed_characters:
        ["launch", "live", "--duration", "1", "--bus-id", "bad/id"] => ["must be 1 to 48 letters, digits, `_` or `-`"];
    /// Already good, kept: a negative window.
    a_negative_window_gives_the_allowed_range:
        ["topics", "--window", "-1"] => ["allowed: more than 0 and at most a year of seconds"];
}
