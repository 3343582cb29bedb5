//! `handblocks`: the one binary that holds every service of the system.
//!
//! A hand, measured by a data glove and a 6-DoF tracker (or scripted, or replayed), grasps,
//! pushes, carries and throws virtual blocks at interactive rate. `launch` runs a session as
//! separate processes over shared memory; `service` is how the launcher starts each of them.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use clap::{CommandFactory, Parser, Subcommand};
use common::bus::{Bus, BusConfig};
use common::config::Session;
use common::{shutdown, Stage};

/// The version and the commit it was built from (build.rs).
const VERSION: &str = concat!(
    env!("CARGO_PKG_VERSION"),
    " (commit ",
    env!("HANDBLOCKS_COMMIT"),
    ")"
);

/// `launch --help`'s closing text: the report's terms and where the documents are.
const LAUNCH_AFTER_HELP: &str = concat!(
    "The latency table (microseconds), per stage:\n",
    "  hop          a sample's publish (by the stage before) to its receive here: the bus and the wake-up\n",
    "  process      receive to this stage's publish: its own work\n",
    "  origin->out  the sample's origin (when its source sample entered the pipeline) to this\n",
    "               stage's publish: the age of what it sends (at the stepper: origin -> world)\n",
    "  origin->px   the renderer only: origin to the frame's GPU work complete (origin -> photon)\n",
    "  received     per topic, the fewest samples any reader received; dropped = never read\n",
    "\n",
    "Besides the session's [budget] keys, every session is judged on what users assume: the source\n",
    "delivers a sample at least every `source_silence_ms` (default 1000), and the renderer draws at\n",
    "least (1 - `frame_rate_margin`) x frame_hz frames per second (default margin 0.25; frame_hz, or\n",
    "the world's rate when that is lower). The design: docs/design.md; the model: docs/model.md."
);

#[derive(Parser)]
#[command(
    name = "handblocks",
    version = VERSION,
    about = "A hand grasps, pushes, carries and throws virtual blocks at interactive rate.",
    long_about = "A hand grasps, pushes, carries and throws virtual blocks at interactive rate.\n\n\
        A session runs as independent processes (acquisition, kinematics, stepper, renderer, \
        recorder) exchanging zero-copy samples over iceoryx2; the launcher measures every \
        stage's latency and judges it against the session's [budget].\n\n\
        Start with:  ./run                        (set-up, build, the live session: the scripted hand)\n\
        \x20            handblocks launch --help     (options, the report and its terms)\n\
        \x20            handblocks list              (the scenes and sessions)\n\n\
        The design: docs/design.md; the model's rules: docs/model.md (in the repository)."
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand)]
enum Command {
    /// Run a session: start its processes, measure latency, judge the budget.
    ///
    /// After the session it prints what the world came to (each block's final pose and mode,
    /// the events, as `simulate` does), the latency table, and the budget's verdict. A headless
    /// session also writes an animated preview (out/SESSION-preview.png; --no-preview: none).
    /// A replay session ends when its trace does (unless [source] loop = true).
    ///
    /// Exit status: 0 when the session ran within its [budget], 1 when it ran but violated the
    /// budget or a process failed, 2 when it could not run (bad config, no processes).
    #[command(after_help = LAUNCH_AFTER_HELP)]
    Launch {
        /// The session file (which scene, which source, renderer, recorder, budget), or a scene
        /// file (run with the default settings: the scripted hand, headless).
        #[arg(default_value = "config/sessions/live.toml")]
        session: PathBuf,
        /// Override a key of the session file, e.g. --set renderer.mode=off, --set
        /// budget.max_dropped=0, --set source.file=/data/carl/example_push_0.carl (paths, as in
        /// the file, start at the session file's folder). Checked as the file's keys are.
        /// Repeatable.
        #[arg(long = "set", value_name = "KEY=VALUE", value_parser = parse_override)]
        overrides: Vec<common::config::session::Override>,
        /// No animated preview (a headless session writes one by default).
        #[arg(long)]
        no_preview: bool,
        /// Overwrite the recording (--record or [recorder] file) if it exists.
        #[arg(long)]
        force: bool,
        /// Stop after this many seconds (default: run until Ctrl-C or SIGTERM).
        #[arg(long, value_name = "SECONDS", value_parser = parse_seconds)]
        duration: Option<Duration>,
        /// Also write the report as JSON to this file.
        #[arg(long, value_name = "FILE")]
        report: Option<PathBuf>,
        /// The session's bus id (iceoryx2 prefix `hb_<ID>_`); default: a fresh one.
        #[arg(long, value_name = "ID")]
        bus_id: Option<String>,
        /// No progress lines while running.
        #[arg(long)]
        quiet: bool,
        /// Write rendered frames as PNG into DIR (every `[renderer] frames_every`-th frame).
        #[arg(long, value_name = "DIR")]
        frames_dir: Option<PathBuf>,
        /// Record every topic to this MCAP file (overrides the session's `[recorder] file`);
        /// list it with `handblocks inspect FILE`, replay it with `[source] kind = "replay"`.
        #[arg(long, value_name = "FILE")]
        record: Option<PathBuf>,
    },
    /// List a recording's topics: messages, sequence gaps, time span and rate of each.
    ///
    /// Reads an MCAP file the recorder wrote (`[recorder] file` in a session). A file cut off
    /// by a crash is read up to its last complete chunk and the damage is named with its byte
    /// offset. The file also opens in the standard MCAP tools (`mcap info FILE`, Foxglove).
    /// Exit status: 0 for an intact recording, 1 when it is damaged (what could be read is
    /// listed), 2 when it cannot be read at all.
    Inspect {
        /// The recording (.mcap).
        recording: PathBuf,
        /// Print {"file", "complete", "damage", "foreign_messages", "topics": [{"topic",
        /// "messages", "gaps", "seconds", "rate_hz", "schema", "bytes"}]}.
        #[arg(long)]
        json: bool,
    },
    /// Run a scene's block world alone, in one process, deterministically.
    ///
    /// The scene's [hand] keyframes drive the hand, sampled once per step: `grip`/`angles` keys
    /// through the hand model, `fingers` keys as bare check points. Two runs print identical
    /// bytes. Exit status 2 when the scene is refused (the message names file, key and range).
    Simulate {
        /// The scene file (docs/design.md, "Effects"; the rules: docs/model.md).
        scene: PathBuf,
        /// Steps to run (default: the hand's last key plus 3 s).
        #[arg(long, value_name = "N")]
        frames: Option<u64>,
        /// Override the scene's [world] model.
        #[arg(long, value_parser = ["paper", "precise"])]
        model: Option<String>,
        /// Drive the hand from a trace instead of the scene's [hand]: one of our MCAP recordings
        /// (its glove + tracker or joints topics) or a CARL file (OpenXR joints), through the
        /// hand model and the stepper's own timeline, exactly as a live replay would.
        #[arg(long, value_name = "TRACE")]
        hand: Option<PathBuf>,
        /// Move the traced hand by X,Y,Z metres (real traces hold the hand ~1 m above the floor).
        #[arg(long, value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true)]
        hand_offset: Option<[f64; 3]>,
        /// Print {"frames", "blocks": [{"name", "position", "rotation", "mode"}], "events"}.
        #[arg(long)]
        json: bool,
    },
    /// Benchmarks, each reported against a peer measured in the same run.
    Bench {
        #[command(subcommand)]
        which: BenchKind,
    },
    /// Emulate a CyberGlove or a FASTRAK on a pseudo-terminal, for sessions without hardware.
    ///
    /// The device appears at --link (a symbolic link to the pty), which a session's
    /// [source.glove] or [source.tracker] `port` names exactly as it would name /dev/ttyUSB0.
    /// See config/devices/emulated-session.toml. Ctrl-C stops it.
    Emulate {
        /// glove or tracker.
        #[arg(value_parser = ["glove", "tracker"])]
        device: String,
        /// Where the device appears.
        #[arg(long, value_name = "PATH")]
        link: PathBuf,
        /// Glove sensors (18 or 22).
        #[arg(long, default_value = "22", value_parser = clap::value_parser!(u8).range(18..=22))]
        sensors: u8,
        /// Records per second (glove default 100, tracker default 120).
        #[arg(long, value_name = "HZ")]
        rate: Option<f64>,
        /// A fault to inject, KIND@RECORD[:ARG]: garbage@100, truncate@200:5, corrupt@300:7,
        /// silence@400:1500 (ms, or `forever`), unplug@500:1000. Repeatable.
        #[arg(long = "fault", value_name = "SPEC")]
        faults: Vec<String>,
    },
    /// The publishing half of the latency benchmark's peer (started by `bench latency`).
    #[command(hide = true)]
    BenchPeer {
        #[arg(long)]
        bus: String,
        #[arg(long)]
        rate: f64,
        #[arg(long)]
        count: u64,
    },
    /// List the scenes and sessions under config/ (or DIR), each with its first comment line.
    List {
        /// Where to look.
        #[arg(default_value = "config")]
        dir: PathBuf,
    },
    /// Print a shell completion script (bash, zsh, fish, elvish, powershell).
    ///
    /// For bash: handblocks completions bash > ~/.local/share/bash-completion/completions/handblocks
    Completions {
        /// bash, zsh, fish, elvish or powershell.
        shell: clap_complete::Shell,
    },
    /// Run one process of a session (the launcher starts each one this way).
    #[command(hide = true)]
    Service {
        /// acquisition, kinematics, stepper, renderer or recorder.
        name: String,
        /// The session file.
        #[arg(long)]
        session: PathBuf,
        /// The session's bus id, as the launcher chose it.
        #[arg(long)]
        bus: String,
        /// The renderer only: write PNG frames here.
        #[arg(long, value_name = "DIR")]
        frames_dir: Option<PathBuf>,
        /// The recorder only: the file, in place of the session's `[recorder] file`.
        #[arg(long, value_name = "FILE")]
        record: Option<PathBuf>,
        /// The renderer only: write the animated preview here.
        #[arg(long, value_name = "FILE")]
        preview: Option<PathBuf>,
        /// The stepper only: write the world's outcome into this folder when stopping.
        #[arg(long, value_name = "DIR")]
        outcome_dir: Option<PathBuf>,
        /// The session's --set overrides, as the launcher got them.
        #[arg(long = "set", value_name = "KEY=VALUE", value_parser = parse_override)]
        overrides: Vec<common::config::session::Override>,
    },
}

#[derive(Subcommand)]
enum BenchKind {
    /// Per-hop and origin -> world latency of the whole process set, against a bare
    /// two-process iceoryx2 hop measured in the same run.
    Latency {
        /// The session to measure.
        #[arg(long, default_value = "config/sessions/live.toml")]
        session: PathBuf,
        /// Seconds for the peer, and again for the session.
        #[arg(long, default_value = "10", value_parser = parse_seconds)]
        seconds: Duration,
        /// Where latency.json goes.
        #[arg(long, default_value = "out/bench")]
        out: PathBuf,
    },
    /// What accuracy costs in time: the paper model and the precise one (rapier3d) against
    /// exact answers at several settings each, timed in the same run.
    Accuracy {
        /// Where accuracy.json, accuracy.md and accuracy.png go.
        #[arg(long, default_value = "out/bench")]
        out: PathBuf,
        /// A reduced sweep (under a minute on 2 cores).
        #[arg(long)]
        quick: bool,
    },
    /// Every hard case (config/scenes/hard/) under the paper model, R11 only (stacks) and the
    /// precise one, with drift, sink, penetration, decision, time to rest and a state hash.
    Stability {
        /// Where stability.json, stability.md and stability.png go.
        #[arg(long, default_value = "out/bench")]
        out: PathBuf,
        /// Leave out the slowest precise runs (under a minute on 2 cores).
        #[arg(long)]
        quick: bool,
    },
}

fn parse_vec3(s: &str) -> Result<[f64; 3], String> {
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() != 3 {
        return Err(format!("{s:?}: give three numbers, X,Y,Z (metres)"));
    }
    let mut v = [0.0; 3];
    for (slot, p) in v.iter_mut().zip(&parts) {
        *slot = p
            .trim()
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite() && x.abs() <= 1e5)
            .ok_or_else(|| format!("{p:?} is not a number of metres within 100 km"))?;
    }
    Ok(v)
}

fn parse_override(s: &str) -> Result<common::config::session::Override, String> {
    common::config::session::Override::parse(s)
}

fn parse_seconds(s: &str) -> Result<Duration, String> {
    let v: f64 = s
        .parse()
        .map_err(|_| format!("{s:?} is not a number of seconds"))?;
    if !(v.is_finite() && v > 0.0 && v <= 86_400.0 * 365.0) {
        return Err(format!(
            "{s}: allowed: more than 0 and at most a year of seconds"
        ));
    }
    Ok(Duration::from_secs_f64(v))
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        // `cargo run --release`: the live session, until Ctrl-C.
        None => launch(LaunchArgs {
            session: PathBuf::from("config/sessions/live.toml"),
            ..LaunchArgs::default()
        }),
        Some(Command::Launch {
            session,
            overrides,
            no_preview,
            force,
            duration,
            report,
            bus_id,
            quiet,
            frames_dir,
            record,
        }) => launch(LaunchArgs {
            session,
            overrides,
            no_preview,
            force,
            duration,
            report,
            bus_id,
            quiet,
            frames_dir,
            record,
        }),
        Some(Command::List { dir }) => list(&dir),
        Some(Command::Completions { shell }) => {
            clap_complete::generate(
                shell,
                &mut Cli::command(),
                "handblocks",
                &mut std::io::stdout(),
            );
            ExitCode::SUCCESS
        }
        Some(Command::Simulate {
            scene,
            frames,
            model,
            hand,
            hand_offset,
            json,
        }) => simulate(
            &scene,
            frames,
            model.as_deref(),
            hand.as_deref(),
            hand_offset.unwrap_or_default(),
            json,
        ),
        Some(Command::Inspect { recording, json }) => inspect(&recording, json),
        Some(Command::Service {
            name,
            session,
            bus,
            frames_dir,
            record,
            preview,
            outcome_dir,
            overrides,
        }) => service(
            &name,
            &session,
            &bus,
            ServiceArgs {
                frames_dir,
                record,
                preview,
                outcome_dir,
                overrides,
            },
        ),
        Some(Command::Bench {
            which:
                BenchKind::Latency {
                    session,
                    seconds,
                    out,
                },
        }) => {
            let exe = match std::env::current_exe() {
                Ok(e) => e,
                Err(e) => {
                    eprintln!("handblocks: cannot find my own executable: {e}");
                    return ExitCode::from(2);
                }
            };
            let b = handblocks_bench::latency::LatencyBench {
                exe,
                session,
                seconds: seconds.as_secs_f64(),
                out_dir: out,
            };
            bench_exit("latency", handblocks_bench::latency::run(&b))
        }
        Some(Command::Bench {
            which: BenchKind::Accuracy { out, quick },
        }) => {
            let b = handblocks_bench::accuracy::AccuracyBench {
                out_dir: out,
                quick,
            };
            bench_exit("accuracy", handblocks_bench::accuracy::run(&b))
        }
        Some(Command::Bench {
            which: BenchKind::Stability { out, quick },
        }) => {
            let b = handblocks_bench::stability::StabilityBench {
                out_dir: out,
                quick,
            };
            bench_exit("stability", handblocks_bench::stability::run(&b))
        }
        Some(Command::Emulate {
            device,
            link,
            sensors,
            rate,
            faults,
        }) => emulate(&device, &link, sensors, rate, &faults),
        Some(Command::BenchPeer { bus, rate, count }) => {
            match handblocks_bench::latency::peer_publisher(&bus, rate, count) {
                Ok(()) => ExitCode::SUCCESS,
                Err(e) => {
                    eprintln!("handblocks bench-peer: {e}");
                    ExitCode::from(2)
                }
            }
        }
    }
}

/// What `handblocks launch` was given.
#[derive(Default)]
struct LaunchArgs {
    session: PathBuf,
    overrides: Vec<common::config::session::Override>,
    no_preview: bool,
    force: bool,
    duration: Option<Duration>,
    report: Option<PathBuf>,
    bus_id: Option<String>,
    quiet: bool,
    frames_dir: Option<PathBuf>,
    record: Option<PathBuf>,
}

fn launch(args: LaunchArgs) -> ExitCode {
    let exe = match std::env::current_exe() {
        Ok(e) => e,
        Err(e) => {
            eprintln!("handblocks: cannot find my own executable to start the services: {e}");
            return ExitCode::from(2);
        }
    };
    let mut opts = launcher::LaunchOptions {
        session: args.session,
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
    let s = match launcher::load_session(&opts) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("handblocks: {e}");
            return ExitCode::from(2);
        }
    };
    // A session without a display leaves something to look at.
    if s.renderer.mode == common::config::session::RenderMode::Headless && !args.no_preview {
        opts.preview = Some(launcher::default_preview_path(&opts.session));
    }
    if !args.quiet {
        let until = args.duration.map_or("until Ctrl-C".to_string(), |d| {
            format!("for {:.1} s", d.as_secs_f64())
        });
        eprintln!("handblocks: launching {} {until}", opts.session.display());
    }
    // A replay's trace must be readable: say so now, naming the key, not from a child.
    if let common::config::session::Source::Replay { file, .. } = &s.source {
        if let Err(e) = std::fs::File::open(file) {
            eprintln!(
                "handblocks: {}: [source] file = {}: cannot read it: {e} (a recording of ours, \
                 .mcap, or a CARL trace; relative paths start at the session file's folder; \
                 README.md, \"CARL traces\", says where to get them)",
                s.file.display(),
                file.display()
            );
            return ExitCode::from(2);
        }
    }
    // The device settings are the drivers' to read: check them here, before any process starts.
    if let common::config::session::Source::Devices {
        glove,
        tracker,
        dir,
    } = &s.source
    {
        if let Err(e) = acquisition::service::device_configs(&s, glove, tracker, dir, 0) {
            eprintln!("handblocks: {e}");
            return ExitCode::from(2);
        }
    }
    match launcher::launch(&opts) {
        Ok(outcome) => {
            if let Some(world) = &outcome.world {
                println!("what the world came to (as simulate prints it): {world}");
            }
            print!("{}", outcome.report.table());
            if let Some(path) = &outcome.preview {
                println!("{}", preview_line(path));
            }
            if let Some(path) = &args.report {
                if let Err(e) = launcher::write_report(&outcome.report, path) {
                    eprintln!("handblocks: {e}");
                    return ExitCode::from(2);
                }
            }
            if outcome.report.ok() {
                ExitCode::SUCCESS
            } else {
                ExitCode::from(1)
            }
        }
        Err(e) => {
            eprintln!("handblocks: {e}");
            ExitCode::from(2)
        }
    }
}

/// `preview: out/live-preview.png (animated PNG, 36 frames, 640 x 240, 412 KB; open it in a
/// web browser)`.
fn preview_line(path: &std::path::Path) -> String {
    let size = std::fs::metadata(path).map_or(0, |m| m.len());
    match renderer::preview::describe(path) {
        Some(d) => format!(
            "preview: {} (animated PNG, {} frames, {} x {}, {:.0} KB; open it in a web browser)",
            path.display(),
            d.frames,
            d.width,
            d.height,
            size as f64 / 1024.0
        ),
        None => format!("preview: {} ({size} bytes)", path.display()),
    }
}

/// `handblocks list`: scenes and sessions with their first comment line.
fn list(dir: &std::path::Path) -> ExitCode {
    let mut files = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else {
            if d == dir {
                eprintln!("handblocks list: cannot read the folder {}", dir.display());
                return ExitCode::from(2);
            }
            continue;
        };
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "toml") {
                files.push(p);
            }
        }
    }
    files.sort();
    let mut scenes = Vec::new();
    let mut sessions = Vec::new();
    for f in files {
        let Ok(text) = std::fs::read_to_string(&f) else {
            continue;
        };
        let Ok(table) = text.parse::<toml::Table>() else {
            continue;
        };
        let first = text
            .lines()
            .map(str::trim)
            .find(|l| l.starts_with('#'))
            .map(|l| l.trim_start_matches('#').trim().to_string())
            .unwrap_or_default();
        if table.contains_key("scene") {
            sessions.push((f, first));
        } else if table.contains_key("block") || table.contains_key("hand") {
            scenes.push((f, first));
        }
    }
    let w = scenes
        .iter()
        .chain(&sessions)
        .map(|(f, _)| f.display().to_string().len())
        .max()
        .unwrap_or(0);
    println!("sessions (handblocks launch SESSION, or ./run SESSION):");
    for (f, first) in &sessions {
        println!("  {:w$}  {first}", f.display().to_string());
    }
    println!("scenes (handblocks simulate SCENE; handblocks launch SCENE runs it with the scripted hand):");
    for (f, first) in &scenes {
        println!("  {:w$}  {first}", f.display().to_string());
    }
    ExitCode::SUCCESS
}

fn simulate(
    scene_file: &std::path::Path,
    frames: Option<u64>,
    model: Option<&str>,
    trace: Option<&std::path::Path>,
    hand_offset: [f64; 3],
    json: bool,
) -> ExitCode {
    use common::config::scene::{HandPoseSpec, ModelKind};
    use common::config::Scene;
    let fail = |e: &dyn std::fmt::Display| {
        eprintln!("handblocks simulate: {e}");
        ExitCode::from(2)
    };
    let mut scene = match Scene::load(scene_file) {
        Ok(s) => s,
        Err(e) => return fail(&e),
    };
    match model {
        Some("precise") => scene.world.model = ModelKind::Precise,
        Some(_) => scene.world.model = ModelKind::Paper,
        None => {}
    }
    if let Some(t) = trace {
        return simulate_trace(&scene, t, hand_offset, frames, json);
    }
    let frames = frames.unwrap_or_else(|| stepper::default_frames(&scene));
    let bare = scene.hand.as_ref().is_some_and(|h| {
        h.keys
            .iter()
            .any(|k| matches!(k.pose, HandPoseSpec::Fingers(_)))
    });
    let report = if bare {
        let mut hand = stepper::BareFingersHand::from_scene(&scene);
        stepper::simulate(
            &scene,
            frames,
            hand.as_mut().map(|h| h as &mut dyn stepper::HandSource),
        )
    } else if let Some(script) = &scene.hand {
        // The same path as a live session: keyframes -> glove + tracker -> the hand model.
        let scripted = match acquisition::ScriptedHand::new(script) {
            Ok(s) => s,
            Err(e) => return fail(&format!("{}: {e}", scene.file.display())),
        };
        let model = kinematics::HandModel::default();
        let mut hand = common::HandSample::default();
        let step_hz = scene.world.step_hz;
        let mut source = |step: u64, _t: f64| {
            // Sampled exactly as the acquisition process samples it (k / rate), so that a live
            // session at the step rate computes bit-identical worlds.
            let (glove, tracker) = scripted.samples_at(
                step as f64 / step_hz,
                common::Stamp {
                    seq: step,
                    ..Default::default()
                },
            );
            model.solve(&glove, &tracker.wrist, &mut hand);
            Some(hand)
        };
        stepper::simulate(&scene, frames, Some(&mut source))
    } else {
        stepper::simulate(&scene, frames, None)
    };
    match report {
        Ok(r) if json => {
            println!("{}", r.to_json());
            ExitCode::SUCCESS
        }
        Ok(r) => {
            print!("{}", r.to_text());
            ExitCode::SUCCESS
        }
        Err(e) => fail(&e),
    }
}

/// `simulate --hand TRACE`: the trace's samples become hands exactly as in a live replay
/// (kinematics: one hand per tracker or joints sample, gloves paired by source time; then the
/// stepper's timeline), then 2 s to settle. TRACE is one of our MCAP recordings or a CARL file.
fn simulate_trace(
    scene: &common::config::Scene,
    trace: &std::path::Path,
    offset: [f64; 3],
    frames: Option<u64>,
    json: bool,
) -> ExitCode {
    let trace = match replay::HandTrace::load(trace, offset) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("handblocks simulate: {e}");
            return ExitCode::from(2);
        }
    };
    for w in &trace.warnings {
        eprintln!("handblocks simulate: warning: {w}");
    }
    if !trace.warnings.is_empty() {
        eprintln!(
            "handblocks simulate: using the {} good samples",
            trace.samples.len()
        );
    }
    let model = kinematics::HandModel::default();
    let mut hands: Vec<common::HandSample> = Vec::with_capacity(trace.hands());
    let mut hand = common::HandSample::default();
    let mut gloves = kinematics::GloveHistory::default();
    for sample in &trace.samples {
        let stamp = match sample {
            replay::SourceSample::Glove(g) => {
                gloves.push(g);
                continue;
            }
            replay::SourceSample::Tracker(t) => {
                let glove = gloves.at(t.stamp.source_time_ns);
                model.solve(
                    glove.unwrap_or(&common::GloveSample::default()),
                    &t.wrist,
                    &mut hand,
                );
                t.stamp
            }
            replay::SourceSample::Joints(j) => {
                // A joints sample the model cannot use keeps the previous hand, marked lost, as
                // the process does.
                if !model.from_joints(j, &mut hand) {
                    hand.tracked = 0;
                }
                j.stamp
            }
        };
        hand.stamp = common::Stamp {
            seq: hands.len() as u64,
            ..stamp
        };
        hands.push(hand);
    }
    match stepper::simulate_samples(scene, &hands, frames) {
        Ok(r) => {
            if json {
                println!("{}", r.to_json());
            } else {
                print!("{}", r.to_text());
            }
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("handblocks simulate: {e}");
            ExitCode::from(2)
        }
    }
}

fn inspect(path: &std::path::Path, json: bool) -> ExitCode {
    use recording::{sample_type, Recording, RECORDED_TOPICS};
    // Counts and gaps come from every message; no sample needs to stay in memory.
    let rec = match Recording::open_topics(path, &[]) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("handblocks inspect: {e}");
            return ExitCode::from(2);
        }
    };
    let stats = rec.stats();
    let rows: Vec<_> = RECORDED_TOPICS
        .iter()
        .map(|&t| {
            let s = stats[t as usize];
            let seconds = s.last_publish_ns.saturating_sub(s.first_publish_ns) as f64 * 1e-9;
            let rate = if s.messages > 1 && seconds > 0.0 {
                (s.messages - 1) as f64 / seconds
            } else {
                0.0
            };
            let (schema, bytes) = sample_type(t);
            (t.name(), s, seconds, rate, schema, bytes)
        })
        .collect();
    let damage = rec.damage.as_ref().map(|d| d.to_string());
    let file_bytes = std::fs::metadata(path).map_or(0, |m| m.len());
    // Log times are publish times on the recorder's Unix offset: the span of the recording.
    let offset: Option<u64> = rec
        .metadata
        .get("unix_offset_ns")
        .and_then(|v| v.parse().ok());
    let span = stats
        .iter()
        .filter(|s| s.messages > 0)
        .fold(None, |acc, s| {
            let (a, b) = acc.unwrap_or((u64::MAX, 0));
            Some((a.min(s.first_publish_ns), b.max(s.last_publish_ns)))
        });
    let utc = |ns: u64| launcher::report::rfc3339(std::time::UNIX_EPOCH + Duration::from_nanos(ns));
    let (start, end) = match (offset, span) {
        (Some(o), Some((a, b))) => (Some(utc(a + o)), Some(utc(b + o))),
        _ => (None, None),
    };
    let session = rec.metadata.get("session").cloned();
    if json {
        let topics: Vec<serde_json::Value> = rows
            .iter()
            .map(|(name, s, seconds, rate, schema, bytes)| {
                serde_json::json!({
                    "topic": name, "messages": s.messages, "gaps": s.gaps,
                    "seconds": seconds, "rate_hz": rate, "schema": schema, "bytes": bytes,
                })
            })
            .collect();
        println!(
            "{}",
            serde_json::json!({
                "file": path.display().to_string(),
                "bytes": file_bytes,
                "start": start,
                "end": end,
                "session": session,
                "scene": rec.metadata.get("scene"),
                "complete": rec.complete,
                "damage": damage,
                "foreign_messages": rec.foreign_messages,
                "topics": topics,
            })
        );
    } else {
        println!(
            "{}: {} messages, {:.1} KB, {}",
            path.display(),
            stats.iter().map(|s| s.messages).sum::<u64>(),
            file_bytes as f64 / 1024.0,
            if rec.complete {
                "complete"
            } else {
                "damaged (read up to the damage)"
            }
        );
        if let (Some(a), Some(b)) = (&start, &end) {
            println!("from {a} to {b} (UTC)");
        }
        match &session {
            Some(s) => println!("recorded by the session {s}"),
            None => println!("recorded by: not named in the file (not a session's recording)"),
        }
        println!(
            "{:<8} {:>9} {:>6} {:>9} {:>9}  schema",
            "topic", "messages", "gaps", "seconds", "rate_hz"
        );
        for (name, s, seconds, rate, schema, bytes) in &rows {
            println!(
                "{name:<8} {:>9} {:>6} {seconds:>9.3} {rate:>9.1}  {schema} ({bytes} bytes)",
                s.messages, s.gaps
            );
        }
        if rec.foreign_messages > 0 {
            println!(
                "{} messages on channels of other tools were skipped",
                rec.foreign_messages
            );
        }
        if let Some(d) = &damage {
            println!("damage: {d}");
        }
    }
    if rec.complete {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    }
}

fn emulate(
    device: &str,
    link: &std::path::Path,
    sensors: u8,
    rate: Option<f64>,
    faults: &[String],
) -> ExitCode {
    use acquisition::emulator::{glove, tracker, Fault};
    let faults = match faults
        .iter()
        .map(|f| Fault::parse(f))
        .collect::<Result<Vec<_>, _>>()
    {
        Ok(f) => f,
        Err(e) => {
            eprintln!("handblocks emulate: --fault: {e}");
            return ExitCode::from(2);
        }
    };
    if let Some(r) = rate.filter(|r| !(r.is_finite() && *r > 0.0 && *r <= 10_000.0)) {
        eprintln!(
            "handblocks emulate: --rate {r}: allowed: more than 0 up to 10000 records per second"
        );
        return ExitCode::from(2);
    }
    shutdown::install_signal_handlers();
    eprintln!(
        "handblocks emulate: a {device} at {} (Ctrl-C stops it)",
        link.display()
    );
    let stop = || shutdown::requested();
    let result = if device == "glove" {
        let mut b = glove::GloveBehaviour::new(sensors);
        b.rate_hz = rate.unwrap_or(b.rate_hz);
        b.faults = faults;
        glove::run(link, b, &stop)
    } else {
        let mut b = tracker::TrackerBehaviour::new();
        b.rate_hz = rate.unwrap_or(b.rate_hz);
        b.faults = faults;
        tracker::run(link, b, &stop)
    };
    match result {
        Ok(report) => {
            eprintln!(
                "handblocks emulate: stopped after {} records, {} unplugs; commands received: {:?}",
                report.records,
                report.unplugs,
                String::from_utf8_lossy(&report.received)
            );
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("handblocks emulate: {}: {e}", link.display());
            ExitCode::from(2)
        }
    }
}

/// What the launcher passes a service besides its name, session and bus.
struct ServiceArgs {
    frames_dir: Option<PathBuf>,
    record: Option<PathBuf>,
    preview: Option<PathBuf>,
    outcome_dir: Option<PathBuf>,
    overrides: Vec<common::config::session::Override>,
}

fn service(
    name: &str,
    session_file: &std::path::Path,
    bus_id: &str,
    args: ServiceArgs,
) -> ExitCode {
    shutdown::install_signal_handlers();
    shutdown::watch_parent_pipe();
    let Some(stage) = Stage::from_name(name) else {
        let names: Vec<&str> = Stage::ALL.iter().map(|s| s.name()).collect();
        eprintln!(
            "handblocks service: unknown service {name:?}; one of: {}",
            names.join(", ")
        );
        return ExitCode::from(2);
    };
    let result = (|| -> Result<(), Box<dyn std::error::Error>> {
        let mut session = Session::load_with(session_file, &args.overrides)?;
        if args.record.is_some() {
            session.recorder.file = args.record;
        }
        let bus = Bus::open(&BusConfig::for_session(bus_id)?, stage.name())?;
        match stage {
            Stage::Acquisition => acquisition::service::run(&session, &bus),
            Stage::Kinematics => kinematics::service::run(&session, &bus),
            Stage::Stepper => {
                stepper::service::run_with_outcome(&session, &bus, args.outcome_dir.as_deref())
            }
            Stage::Renderer => renderer::service::run_with_preview(
                &session,
                &bus,
                renderer::RenderSettings::from_session_framed(&session.renderer, &session.scene),
                args.frames_dir.map(|dir| renderer::FramesRequest {
                    dir,
                    every_nth: session.renderer.frames_every,
                }),
                args.preview,
            ),
            Stage::Recorder => recorder::service::run(&session, &bus),
            Stage::Replay => replay::service::run(&session, &bus),
        }
    })();
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // No GPU adapter: the launcher goes on without a renderer and says so in one line.
            if matches!(
                e.downcast_ref::<renderer::RenderError>(),
                Some(renderer::RenderError::NoAdapter(_))
            ) {
                return ExitCode::from(launcher::RENDERER_SKIPPED_EXIT as u8);
            }
            eprintln!("handblocks {}: {e}", stage.name());
            ExitCode::from(2)
        }
    }
}

/// A benchmark's exit: 0 when it ran (its figures are its verdict), 2 with the reason when it
/// could not run.
fn bench_exit<T, E: std::fmt::Display>(name: &str, result: Result<T, E>) -> ExitCode {
    match result {
        Ok(_) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("handblocks bench {name}: {e}");
            ExitCode::from(2)
        }
    }
}
