//! The launcher: starts a session's processes, supervises them, stops them in order, and
//! judges the merged latency report against the session's budget.
//!
//! One launch, in order:
//! 1. load the session (and its scene) — errors name the file and key;
//! 2. create every service of the session under its own iceoryx2 prefix and root path;
//! 3. start the readers (recorder, renderer, stepper, kinematics), each as
//!    `handblocks service NAME`, and wait until every one is attached;
//! 4. start the source last, so no sample is lost at start-up;
//! 5. run for `--duration` or until Ctrl-C / SIGTERM, printing progress; a process that dies
//!    meanwhile fails the session, or, with `[supervise] restart = "on-failure"`, is started
//!    again (its dead node's ports removed first) while the others keep running;
//! 6. stop the processes in pipeline order: each drains its inputs, sends its final report,
//!    and is released and reaped once the launcher has read that report;
//! 7. remove the session's iceoryx2 resources, print the table, write the JSON report.
//!
//! This file holds those steps in order ([`launch`], `run_session`) and what they are given
//! and give back; the rest is by concept: `start` (steps 3 and 4), `supervise` (5 and 6),
//! `outputs` (the files a session writes: checked before, replaced with `--force`), `report`
//! (step 7: the merged report, its budget, its table and JSON), `placement` (which CPUs each
//! process gets), `process` (one child process) and `sweep` (what crashed sessions left in
//! /dev/shm outside their folders).

mod error;
pub mod machine;
mod outputs;
pub mod placement;
mod process;
mod progress;
pub mod report;
mod start;
mod supervise;
pub mod sweep;

use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

use common::bus::{Bus, BusConfig};
use common::config::session::{recording_segment, Override, RenderMode, RestartPolicy, Source};
use common::config::Session;
use common::{shutdown, topics, Stage};

use crate::placement::Placement;

pub use error::LaunchError;
use outputs::{check_writable, frames_in};
use report::Report;
use start::{start_readers, start_source, Starter};
use supervise::{Supervised, Supervision};

/// How long a session's end waits for the tools reading it from outside (`echo`, `hz`,
/// Python's `Session`, which look for the card every 100 to 200 ms) to let go of its bus
/// before its files are removed.
const READERS_LET_GO: Duration = Duration::from_secs(1);

/// The renderer's exit status when it found no GPU adapter and the session goes on without it.
pub const RENDERER_SKIPPED_EXIT: i32 = 3;

/// What `handblocks launch` was asked to do.
#[derive(Debug, Clone, Default)]
pub struct LaunchOptions {
    pub session: PathBuf,
    /// None: until Ctrl-C or SIGTERM.
    pub duration: Option<Duration>,
    pub report: Option<PathBuf>,
    /// None: a fresh id.
    pub bus_id: Option<String>,
    /// The executable that holds the services (normally this one).
    pub exe: PathBuf,
    /// Print progress once a second.
    pub progress: bool,
    /// Where the renderer writes PNG frames (every `[renderer] frames_every`-th), if anywhere.
    pub frames_dir: Option<PathBuf>,
    /// Record every topic to this MCAP file, in place of the session's `[recorder] file`.
    pub record: Option<PathBuf>,
    /// `--set KEY=VALUE` overrides of the session file's keys (every process gets them).
    pub overrides: Vec<Override>,
    /// Overwrite an existing recording.
    pub force: bool,
    /// Write an animated preview here (a headless session; see [`default_preview_path`]).
    pub preview: Option<PathBuf>,
    /// What the report names as the version (`0.1.0 (commit abc1234)`).
    pub version: String,
}

/// Where a headless session's animated preview goes by default: `out/<session>-preview.png`.
pub fn default_preview_path(session: &Path) -> PathBuf {
    let stem = session
        .file_stem()
        .map_or("session".into(), |s| s.to_string_lossy().into_owned());
    PathBuf::from("out").join(format!("{stem}-preview.png"))
}

/// Loads the session as `launch` will run it: with the `--set` overrides and `--record`.
///
/// Loading checks every key, the device settings of a devices session included; a replay's
/// trace must also be readable, which is said here, naming the key, rather than by a child
/// process after the others have started.
pub fn load_session(opts: &LaunchOptions) -> Result<Session, LaunchError> {
    let mut session = Session::load_with(&opts.session, &opts.overrides)?;
    if let Some(file) = &opts.record {
        session.recorder.file = Some(std::path::absolute(file).unwrap_or_else(|_| file.clone()));
    }
    if let Source::Replay { file, .. } = &session.source {
        // Only a regular file (issue 40: a FIFO named here hung `launch`).
        if let Err(reason) = common::config::open_regular(file) {
            return Err(LaunchError::TraceUnreadable {
                session: session.file.clone(),
                trace: file.clone(),
                reason: std::io::Error::other(reason),
            });
        }
    }
    Ok(session)
}

/// What can be known wrong before any process starts, each naming the option, file or key.
pub fn preflight(opts: &LaunchOptions, session: &Session) -> Result<(), LaunchError> {
    if session.renderer.mode == RenderMode::Window
        && std::env::var_os("DISPLAY").is_none_or(|d| d.is_empty())
        && std::env::var_os("WAYLAND_DISPLAY").is_none_or(|d| d.is_empty())
    {
        return Err(LaunchError::NoDisplay {
            session: session.file.clone(),
        });
    }
    if opts.frames_dir.is_some() && session.renderer.mode == RenderMode::Off {
        return Err(LaunchError::NoFramesToWrite {
            session: session.file.clone(),
        });
    }
    if let Some(rec) = &session.recorder.file {
        // The segments a restarted recorder would write count as the recording.
        let restarts = match session.supervise.restart {
            RestartPolicy::OnFailure => session.supervise.max_restarts,
            RestartPolicy::Never => 0,
        };
        let existing = (0..=restarts)
            .map(|n| recording_segment(rec, n))
            .find(|f| common::output::taken(f));
        if let Some(file) = existing.filter(|_| !opts.force) {
            return Err(LaunchError::RecordingExists {
                session: session.file.clone(),
                file,
                from_option: opts.record.is_some(),
            });
        }
        check_writable("the recording", rec)?;
    }
    if let Some(report) = &opts.report {
        if common::output::taken(report) && !opts.force {
            return Err(LaunchError::OutputExists {
                what: "--report",
                path: report.clone(),
                link: common::output::is_link(report),
            });
        }
        check_writable("--report", report)?;
    }
    if let Some(dir) = &opts.frames_dir {
        if dir.exists() && !dir.is_dir() {
            return Err(LaunchError::OutputIsNotFolder {
                what: "--frames-dir",
                path: dir.clone(),
            });
        }
        if let Some(frame) = frames_in(dir).first().filter(|_| !opts.force) {
            return Err(LaunchError::OutputExists {
                what: "--frames-dir",
                path: frame.clone(),
                link: common::output::is_link(frame),
            });
        }
    }
    if let Some(preview) = &opts.preview {
        // The session's own output at a fixed path, replaced each run (renamed over: a link
        // there is replaced, not followed).
        check_writable("the preview", preview)?;
    }
    Ok(())
}

/// How a launch ended.
pub struct LaunchOutcome {
    pub report: Report,
    pub bus: BusConfig,
    /// What the world came to (the stepper's final state and events, as `simulate` prints).
    pub world: Option<String>,
    /// The animated preview, when one was written.
    pub preview: Option<PathBuf>,
}

/// Runs one session. The resources of its bus are removed whatever happens.
pub fn launch(opts: &LaunchOptions) -> Result<LaunchOutcome, LaunchError> {
    let session = load_session(opts)?;
    preflight(opts, &session)?;
    let id = opts.bus_id.clone().unwrap_or_else(BusConfig::fresh_id);
    // The world topic is sized from the scene; every stage opens the bus the same way.
    let bus_config = BusConfig::for_session_of(&id, &session)?;
    shutdown::install_signal_handlers();
    clear_bus(&bus_config, &id)?;
    if opts.force {
        outputs::remove_for_force(opts, &session)?;
    }
    // The session's folder, with this launcher named in it: a later launch (any bus id)
    // sweeps it at once if this launcher is killed.
    bus_config.claim_as_launcher()?;
    // ... and its card, for `handblocks sessions`, `echo` and `hz`.
    bus_config.write_card(
        &std::path::absolute(&session.file).unwrap_or_else(|_| session.file.clone()),
        session.source.kind(),
    )?;

    let result = run_session(opts, &session, &bus_config);
    // The stepper left the world's outcome in the session's folder when it stopped.
    let world = std::fs::read_to_string(bus_config.root.join("outcome.txt")).ok();
    let world_json = std::fs::read_to_string(bus_config.root.join("outcome.json"))
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok());
    // The bridge left what it did there too.
    let bridge_json = std::fs::read_to_string(bus_config.root.join("bridge.json"))
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok());
    // And a source its refusals by kind.
    let refused = report::refusals::read_refusals(&bus_config.root);
    // Every process is reaped and every port dropped by now. A tool reading the session from
    // outside (`echo`, `hz`, Python) sees the card go and lets go of the bus; then the files
    // are ours to remove.
    bus_config.withdraw_card(READERS_LET_GO);
    let cleanup = bus_config.remove_resources();
    let mut report = result?;
    cleanup.map_err(|reason| LaunchError::Cleanup {
        prefix: bus_config.prefix.clone(),
        reason,
    })?;
    report.meta.world = world_json;
    report.meta.bridge = bridge_json;
    report.meta.refused = refused;
    let preview = opts.preview.clone().filter(|p| {
        report.meta.renderer_skipped.is_none() && p.metadata().is_ok_and(|m| m.len() > 0)
    });
    Ok(LaunchOutcome {
        report,
        bus: bus_config,
        world,
        preview,
    })
}

/// Makes ready the bus `id`: the folders of sessions whose launcher is gone are swept, and
/// what crashed sessions left in /dev/shm outside any folder ([`sweep::sweep_shm`]); a
/// session still running on this id is refused; what one whose processes are all gone left
/// on it is removed.
fn clear_bus(bus_config: &BusConfig, id: &str) -> Result<(), LaunchError> {
    for said in BusConfig::sweep_abandoned()
        .into_iter()
        .chain(sweep::sweep_shm())
    {
        eprintln!("handblocks: {said}");
    }
    if bus_config.has_live_processes() {
        return Err(LaunchError::BusIdInUse { id: id.to_string() });
    }
    if !bus_config.leftover_shm_files().is_empty() || bus_config.root.exists() {
        // Left by a session whose processes are all gone.
        bus_config
            .remove_resources()
            .map_err(|reason| LaunchError::LeftoverFiles {
                id: id.to_string(),
                prefix: bus_config.prefix.clone(),
                reason,
            })?;
    }
    Ok(())
}

/// Steps 2 to 6 of the launch (the module docs), on a bus that `launch` prepared and cleans up;
/// returns the report of step 7 for `launch` to complete.
fn run_session(
    opts: &LaunchOptions,
    session: &Session,
    bus_config: &BusConfig,
) -> Result<Report, LaunchError> {
    let started_at = SystemTime::now();
    // What the machine does besides the session, read before and after it (machine.rs).
    let cpu_before = machine::CpuReading::now();
    // 2. The services, and the launcher's own inlet of every stage's latency reports.
    let bus = Bus::open(bus_config, "launcher")?;
    let services = bus.create_services()?;
    let latency = bus.inlet::<topics::Latency>()?;
    let starter = Starter::new(opts, session, bus_config);
    let mut placement = Placement::for_session(
        session.renderer.mode != RenderMode::Off,
        session.renderer.own_cpus,
    );
    if opts.progress {
        if let Some(line) = placement.describe() {
            eprintln!("handblocks: {line}");
        }
    }
    // 3. and 4.
    let (mut procs, renderer_skipped) =
        start_readers(&starter, session, &services, &mut placement)?;
    let source = start_source(&starter, session, &services, &placement, &mut procs)?;
    let mut supervision =
        Supervision::new(session, &latency, &bus, bus_config, &starter, &placement);
    // 5. and 6.
    let ran_for = supervision.run(opts, source, &mut procs);
    supervision.stop_in_order(&mut procs);
    let Supervised {
        reports,
        failures,
        restarts,
    } = supervision.finish();
    drop(procs);
    let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
    let machine_load = cpu_before
        .zip(machine::CpuReading::now())
        .map(|(before, after)| before.load_until(&after, cpus));
    drop(latency);
    drop(services);
    drop(bus);
    // 7. (the report; `launch` removes the resources).
    let seconds = ran_for.as_secs_f64();
    let facts = report::SessionFacts {
        seconds,
        source,
        renders: session.renderer.mode != RenderMode::Off && renderer_skipped.is_none(),
        real_time: !bus_config.lossless,
        renderer_down_s: restarts
            .iter()
            .filter(|r| r.stage == Stage::Renderer)
            .map(|r| r.downtime_s().unwrap_or((seconds - r.at_s).max(0.0)))
            .sum(),
    };
    let mut report = Report::build_with_restarts(
        reports.into_values().collect(),
        &session.budget,
        failures,
        restarts,
        &facts,
    );
    report.meta = report::Meta {
        session_file: starter.session_file.display().to_string(),
        scene_file: std::fs::canonicalize(&session.scene_file)
            .unwrap_or_else(|_| session.scene_file.clone())
            .display()
            .to_string(),
        source: session.source.kind(),
        version: opts.version.clone(),
        cpus,
        machine_load,
        placement: placement.describe(),
        started: started_at,
        seconds: facts.seconds,
        renderer_skipped,
        world: None,
        bridge: None,
        refused: report::refusals::Refusals::new(),
    };
    Ok(report)
}

/// Writes the report JSON to `path`, creating its folder: a new private file (mode 0600: it
/// holds a person's hand motion).
pub fn write_report(report: &Report, path: &Path) -> Result<(), LaunchError> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|reason| LaunchError::ReportFolder {
            dir: dir.to_path_buf(),
            reason,
        })?;
    }
    let text = serde_json::to_string_pretty(&report.json()).map_err(LaunchError::ReportJson)?;
    // Created new and private (a link or a file planted there since the launch is refused,
    // never written through; `--force` removed what was there before the session started).
    common::output::create_new(path)
        .and_then(|mut f| std::io::Write::write_all(&mut f, (text + "\n").as_bytes()))
        .map_err(|reason| LaunchError::ReportWrite {
            path: path.to_path_buf(),
            reason,
        })
}
