//! `handblocks replay FILE`: a recording or a CARL trace played into the pipeline in place of
//! the devices, in one word (as `ros2 bag play FILE`).
//!
//! It writes the session a replay needs, a small file of absolute paths in a private folder
//! of its own (the processes read the session file themselves), and launches it:
//! - the scene: `--scene`; else, for one of our recordings, the scene it recorded (its
//!   metadata names it); else, for a CARL trace, the scene and offset of the configuration's
//!   session that replays the same file (`replay-carl-push.toml` for `example_push_0.carl`);
//!   else `scenes/carl-push.toml` with the CARL sessions' offset;
//! - `[source] kind = "replay"` with `--speed`, `--loop`, `--topics`, `--hands` and `--offset`;
//! - the renderer headless (an animated preview is left in out/), `--set` for the rest.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use crate::cli::{LaunchArgs, ReplayArgs};
use crate::launch::LaunchCommandError;
use crate::locate::{self, Kind};

/// The offset the CARL sessions use: the recorded hands are held ~1.5 m up.
const CARL_OFFSET: [f64; 3] = [0.0, -1.45, 0.0];

/// A trace's first bytes, from a regular file only (refused before a read could block): enough
/// to tell a recording (MCAP's magic) from a CARL trace.
fn trace_head(file: &Path) -> Result<Vec<u8>, String> {
    use std::io::Read as _;
    let mut head = Vec::with_capacity(8);
    common::config::open_regular(file)
        .and_then(|f| f.take(8).read_to_end(&mut head).map_err(|e| e.to_string()))
        .map_err(|e| format!("{}: cannot read the trace: {e}", file.display()))?;
    Ok(head)
}

/// The scene and offset for `file` (its first bytes `head`), and where they came from.
fn scene_for(
    file: &Path,
    head: &[u8],
    args: &ReplayArgs,
) -> Result<(PathBuf, [f64; 3], String), String> {
    // Refused here, before any process starts, when it is neither kind of trace.
    let is_mcap = recording::Recording::is_mcap(head);
    if !is_mcap && !head.starts_with(b"CARL") {
        return Err(format!(
            "{}: neither a recording nor a CARL trace: it starts with {} (a recording starts \
             with MCAP's magic, 89 4d 43 41 50; a CARL trace with \"CARL\")",
            file.display(),
            replay::carl::show_bytes(&head[..head.len().min(4)])
        ));
    }
    if let Some(scene) = &args.scene {
        if let Some(why) =
            locate::missing(scene, Kind::Scene).or_else(|| locate::wrong_kind(scene, Kind::Scene))
        {
            return Err(format!("--scene {}: {why}", scene.display()));
        }
        let scene = locate::resolve(scene, Kind::Scene);
        return Ok((scene, args.offset.unwrap_or_default(), "--scene".into()));
    }
    if is_mcap {
        let rec = recording::Recording::open_topics(file, &[]).map_err(|e| format!("{e}"))?;
        return match rec.metadata.get("scene").map(PathBuf::from) {
            Some(scene) if scene.is_file() => Ok((
                scene,
                args.offset.unwrap_or_default(),
                "the scene it recorded".into(),
            )),
            Some(scene) => Err(format!(
                "{} was recorded on the scene {}, which is not here; give the scene with --scene",
                file.display(),
                scene.display()
            )),
            None => Err(format!(
                "{} names no scene (recorded by another tool?); give one with --scene",
                file.display()
            )),
        };
    }
    // A CARL trace: the session of the configuration that replays the same file.
    let name = file.file_name().map(|n| n.to_string_lossy().into_owned());
    if let (Some(root), Some(name)) = (locate::config_root(), name) {
        let sessions = std::fs::read_dir(root.dir.join("sessions"))
            .into_iter()
            .flatten()
            .flatten()
            .map(|e| e.path());
        for path in sessions {
            // Bounded, and only a regular file: a FIFO left in the folder must not hang it.
            let Ok(table) =
                common::config::read_bounded_text(&path, common::config::MAX_CONFIG_BYTES)
                    .unwrap_or_default()
                    .parse::<toml::Table>()
            else {
                continue;
            };
            let source = table.get("source").and_then(|s| s.as_table());
            let names_it = source
                .and_then(|s| s.get("file"))
                .and_then(|f| f.as_str())
                .is_some_and(|f| Path::new(f).file_name().is_some_and(|n| *n == *name));
            let scene = table.get("scene").and_then(|s| s.as_str());
            if let (true, Some(scene)) = (names_it, scene) {
                let offset = source
                    .and_then(|s| s.get("offset"))
                    .and_then(|o| o.as_array())
                    .and_then(|a| {
                        let v: Vec<f64> = a.iter().filter_map(|x| x.as_float()).collect();
                        <[f64; 3]>::try_from(v).ok()
                    })
                    .unwrap_or_default();
                let dir = path.parent().unwrap_or(Path::new("."));
                return Ok((
                    dir.join(scene),
                    args.offset.unwrap_or(offset),
                    format!("as {}", path.display()),
                ));
            }
        }
        return Ok((
            root.dir.join("scenes/carl-push.toml"),
            args.offset.unwrap_or(CARL_OFFSET),
            "no session names this trace; --scene and --offset choose".into(),
        ));
    }
    Err(format!(
        "no scene for {}: give one with --scene",
        file.display()
    ))
}

/// The source topics (glove, tracker, joints) a trace holds: a CARL trace holds joints; a
/// recording, the ones it has messages of.
fn held_topics(file: &Path, head: &[u8]) -> Result<Vec<&'static str>, String> {
    if !recording::Recording::is_mcap(head) {
        return Ok(vec![common::Topic::Joints.name()]);
    }
    let rec = recording::Recording::open_topics(file, &[]).map_err(|e| format!("{e}"))?;
    let stats = rec.stats();
    Ok([
        common::Topic::Glove,
        common::Topic::Tracker,
        common::Topic::Joints,
    ]
    .into_iter()
    .filter(|&t| stats[t as usize].messages > 0)
    .map(|t| t.name())
    .collect())
}

fn toml_path(p: &Path) -> String {
    let abs = std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    toml::Value::String(abs.display().to_string()).to_string()
}

/// Runs the replay session; its exit status is `launch`'s.
pub fn run(args: ReplayArgs) -> Result<ExitCode, crate::error::CliError> {
    let refuse = |why: String| crate::error::CliError::Replay(why);
    let file = std::path::absolute(&args.file).unwrap_or_else(|_| args.file.clone());
    // A FIFO, a device, a socket or a folder is named for what it is (not "no such file"),
    // before anything opens it: a FIFO would block the replay for ever.
    match std::fs::metadata(&file) {
        Err(_) => {
            return Err(refuse(format!(
                "{}: no such file (a recording, .mcap, or a CARL trace, .carl)",
                args.file.display()
            )))
        }
        Ok(meta) if !meta.is_file() => {
            return Err(refuse(format!(
                "{}: it is {}, not a regular file: give the path of a recording (.mcap) or a \
                 CARL trace (.carl)",
                args.file.display(),
                common::config::file_kind_name(&meta)
            )))
        }
        Ok(_) => {}
    }
    let head = trace_head(&file).map_err(refuse)?;
    let (scene, offset, why) = scene_for(&file, &head, &args).map_err(refuse)?;
    // --topics that the trace does not hold would play nothing: said now, by name, rather
    // than as a session whose source delivered no sample.
    let asked: Vec<String> = args
        .topics
        .iter()
        .flat_map(|t| t.split(','))
        .map(|t| t.trim().trim_start_matches('/').to_string())
        .filter(|t| !t.is_empty())
        .collect();
    if !asked.is_empty() {
        let held = held_topics(&file, &head).map_err(refuse)?;
        if !asked.iter().any(|t| held.contains(&t.as_str())) {
            return Err(refuse(format!(
                "{}: it holds only {} of the source topics, so --topics {} would play nothing \
                 (leave --topics out to play all it holds)",
                args.file.display(),
                if held.is_empty() {
                    "none".to_string()
                } else {
                    held.join(", ")
                },
                asked.join(",")
            )));
        }
    }
    let topics: Vec<String> = asked
        .iter()
        .map(|t| toml::Value::String(t.clone()).to_string())
        .collect();
    let mut text = format!(
        "# Written by `handblocks replay {}`: the trace in place of the devices.\n\
         scene = {}\n",
        args.file.display(),
        toml_path(&scene)
    );
    if let Some(hand) = locate::config_root().map(|r| r.dir.join("hand.toml")) {
        if hand.is_file() {
            text.push_str(&format!("hand_model = {}\n", toml_path(&hand)));
        }
    }
    text.push_str(&format!(
        "\n[source]\nkind = \"replay\"\nfile = {}\nspeed = {}\nloop = {}\noffset = [{}, {}, {}]\n\
         topics = [{}]\nhands = {}\n\n[renderer]\nmode = \"headless\"\n",
        toml_path(&file),
        args.speed,
        args.looped,
        offset[0],
        offset[1],
        offset[2],
        topics.join(", "),
        toml::Value::String(args.hands.clone())
    ));
    // A private folder of its own for the session file, removed when the session ends.
    let dir = std::env::temp_dir().join(format!("handblocks-replay-{}", std::process::id()));
    let stem = file
        .file_stem()
        .map_or_else(|| "trace".to_string(), |s| s.to_string_lossy().into_owned());
    let session = dir.join(format!("replay-{stem}.toml"));
    std::fs::create_dir_all(&dir)
        .and_then(|()| std::fs::write(&session, &text))
        .map_err(|e| {
            refuse(format!(
                "cannot write the replay's session {}: {e}",
                session.display()
            ))
        })?;
    if !args.quiet {
        eprintln!(
            "handblocks replay: {} on {} ({why}), speed {}{}",
            args.file.display(),
            scene.display(),
            args.speed,
            if args.looped { ", looped" } else { "" }
        );
    }
    let launched = crate::launch::run(LaunchArgs {
        session: session.clone(),
        overrides: args.overrides,
        no_preview: args.no_preview,
        force: args.force,
        duration: args.duration,
        report: args.report,
        bus_id: None,
        quiet: args.quiet,
        frames_dir: None,
        record: args.record,
        world: args.world,
    });
    let _ = std::fs::remove_dir_all(&dir);
    launched.map_err(|e: LaunchCommandError| e.into())
}
