//! `handblocks launch SESSION` (and the bare `handblocks`): runs a session through the
//! launcher, then prints a summary of what the world came to (`world_summary`; all of it with
//! `--blocks`/`--events`), the latency table, the preview's path and the budget's verdict.

use std::path::Path;
use std::process::ExitCode;

use common::config::session::RenderMode;

use crate::cli::{LaunchArgs, VERSION};

/// Why a session did not run, or ran but its report could not be written.
#[derive(Debug, thiserror::Error)]
pub enum LaunchCommandError {
    /// The services are this executable started again: it must know where it is.
    #[error("cannot find my own executable to start the services: {0}")]
    OwnExecutable(std::io::Error),
    /// The session file, its overrides or its recording settings were refused.
    #[error(transparent)]
    Session(launcher::LaunchError),
    /// The launcher could not start or supervise the processes.
    #[error(transparent)]
    Run(launcher::LaunchError),
    /// `--report FILE` could not be written (the session itself ran).
    #[error(transparent)]
    Report(launcher::LaunchError),
}

/// Runs the session; 0 when it kept its budget, 1 when it did not or a process failed.
pub fn run(args: LaunchArgs) -> Result<ExitCode, LaunchCommandError> {
    if let Some(why) = crate::locate::missing(&args.session, crate::locate::Kind::Session)
        .or_else(|| crate::locate::wrong_kind(&args.session, crate::locate::Kind::Session))
    {
        return Err(LaunchCommandError::Session(launcher::LaunchError::Session(
            common::config::ConfigError::new(&args.session, "", why),
        )));
    }
    let exe = std::env::current_exe().map_err(LaunchCommandError::OwnExecutable)?;
    let mut opts = launcher::LaunchOptions {
        // A name (`live`) or a config path is found from any folder.
        session: crate::locate::resolve(&args.session, crate::locate::Kind::Session),
        duration: args.duration,
        report: args.report.clone(),
        bus_id: args.bus_id,
        exe,
        progress: !args.quiet,
        frames_dir: args.frames_dir,
        record: args.record,
        overrides: args.overrides,
        force: args.force,
        preview: None,
        version: VERSION.to_string(),
    };
    let s = launcher::load_session(&opts).map_err(LaunchCommandError::Session)?;
    // A session without a display leaves something to look at.
    if s.renderer.mode == RenderMode::Headless && !args.no_preview {
        opts.preview = Some(launcher::default_preview_path(&opts.session));
    }
    if !args.quiet {
        // A replay that does not loop ends by itself.
        let ends_itself = matches!(
            s.source,
            common::config::session::Source::Replay { looped: false, .. }
        );
        let until = match args.duration {
            Some(d) if ends_itself => {
                format!("for {:.1} s or until the trace ends", d.as_secs_f64())
            }
            Some(d) => format!("for {:.1} s", d.as_secs_f64()),
            None if ends_itself => "until the trace ends (Ctrl-C stops it sooner)".to_string(),
            None => "until Ctrl-C".to_string(),
        };
        eprintln!("handblocks: launching {} {until}", opts.session.display());
        if let Some(line) = hands_line(&s) {
            eprintln!("handblocks: {line}");
        }
    }
    let outcome = launcher::launch(&opts).map_err(LaunchCommandError::Run)?;
    if let Some(world) = &outcome.world {
        print!(
            "{}",
            crate::world_summary::summary(world, outcome.report.meta.world.as_ref(), args.world)
        );
        println!(
            "(a session steps its world for as long as it runs, {} steps a second; `handblocks \
             simulate` steps the scene's hand plus 3 s, so their counts differ)\n",
            s.scene.world.step_hz
        );
    }
    print!("{}", outcome.report.table());
    if let Some(path) = &outcome.preview {
        println!("{}", preview_line(path));
        let gif = renderer::preview::gif_path(path);
        if gif.is_file() {
            println!("{}", gif_line(&gif));
        }
    }
    if let Some(path) = &s.recorder.file {
        println!("{}", recording_line(path));
    }
    if let Some(path) = &args.report {
        launcher::write_report(&outcome.report, path).map_err(LaunchCommandError::Report)?;
    }
    Ok(if outcome.report.ok() {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}

/// `preview: out/live-preview.png (animated PNG, 36 frames over 2.4 s, 640 x 360, 412 KB; open
/// it in a web browser)`.
fn preview_line(path: &Path) -> String {
    animation_line(
        path,
        renderer::preview::describe(path),
        "animated PNG",
        "open it in a web browser",
    )
}

/// One line of a written animation: its frames, size and what opens it.
fn animation_line(
    path: &Path,
    info: Option<renderer::preview::PreviewInfo>,
    kind: &str,
    open_with: &str,
) -> String {
    let size = std::fs::metadata(path).map_or(0, |m| m.len());
    match info {
        Some(d) => format!(
            "preview: {} ({kind}, {} frames over {:.1} s, {} x {}, {:.0} KB; {open_with})",
            path.display(),
            d.frames,
            d.duration_ms as f64 / 1000.0,
            d.width,
            d.height,
            size as f64 / 1024.0
        ),
        None => format!("preview: {} ({size} bytes)", path.display()),
    }
}

/// `recorded: out/live.mcap (2.1 MB; list it: handblocks inspect ...; replay it: handblocks
/// replay ...; or open it in Foxglove)`, with the segments a restarted recorder wrote.
fn recording_line(path: &Path) -> String {
    let segments: Vec<std::path::PathBuf> = (0u32..)
        .map(|n| common::config::session::recording_segment(path, n))
        .take_while(|p| p.exists())
        .collect();
    let bytes: u64 = segments
        .iter()
        .filter_map(|p| std::fs::metadata(p).ok())
        .map(|m| m.len())
        .sum();
    if segments.is_empty() {
        return format!(
            "recorded: nothing at {} (the recorder wrote no file)",
            path.display()
        );
    }
    let more = match segments.len() {
        1 => String::new(),
        n => format!(" in {n} segments (a restarted recorder went on in the next)"),
    };
    format!(
        "recorded: {} ({:.1} MB{more}; list it: handblocks inspect {0}; replay it: handblocks \
         replay {0}; or open it in Foxglove)",
        path.display(),
        bytes as f64 / 1e6
    )
}

/// `preview: out/live-preview.gif (GIF, 36 frames over 2.4 s, 640 x 360, 300 KB; any image
/// viewer)`: the same animation for viewers and chats that do not play animated PNGs.
fn gif_line(path: &Path) -> String {
    animation_line(
        path,
        renderer::preview::describe_gif(path),
        "GIF",
        "any image viewer",
    )
}

/// For a session whose hand is tracked (a headset, an external tracker, a replayed trace), which
/// hand rules its scene grasps and throws by (docs/model.md "Tracked hands"): the paper's R3 and
/// R13, which a tracker's jitter makes flicker, or T1-T3. None for a glove or a scripted hand.
fn hands_line(s: &common::config::Session) -> Option<String> {
    use common::config::scene::HandRules;
    use common::config::session::Source;
    use common::HandsUsed;
    let tracked_source = match &s.source {
        Source::Webxr(w) if w.hand == HandsUsed::Both => {
            "a headset's two tracked hands (docs/model.md \"Two hands\")"
        }
        Source::Webxr(_) => "a headset's tracked hand",
        Source::External { .. } => "an external tracker's hand (or two)",
        Source::Shared => "several people's hands, each from their own machine (docs/sessions.md \"Shared sessions\")",
        Source::Replay {
            hands: HandsUsed::Both,
            ..
        } => "a recorded pair of hands (docs/model.md \"Two hands\")",
        Source::Replay { .. } => "a recorded hand",
        _ => return None,
    };
    let w = &s.scene.world;
    Some(match w.hands {
        HandRules::Tracked => format!(
            "{tracked_source}, under the tracked hand rules (docs/model.md T1-T3: grip margin \
             {} m held open {} s, gaps held {} s, throws fitted over {} s)",
            w.tracked.grip_margin,
            w.tracked.grip_open_time,
            w.tracked.gap_hold,
            w.tracked.throw_fit_window
        ),
        HandRules::Paper => format!(
            "{tracked_source}, under the paper's hand rules (R3, R13): a tracker's jitter can \
             make a grasp flicker; --set scene.world.hands=tracked holds it (docs/model.md \
             T1-T3)"
        ),
    })
}
