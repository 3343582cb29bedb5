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

mod error;
pub mod placement;
mod process;
mod progress;
pub mod report;

use std::collections::BTreeMap;
use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime};

use common::bus::{Bus, BusConfig, Inlet, Services};
use common::config::session::{recording_segment, Override, RenderMode, RestartPolicy, Source};
use common::config::Session;
use common::{shutdown, topics, Stage, Topic};

use crate::placement::Placement;

use error::describe_exit;
pub use error::LaunchError;
use process::ServiceProcess;
use report::{Report, Restart, StageReport};

/// How long the processes may take to attach to the bus.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(20);
/// How long a stopping process may take to send its final report.
const FINAL_REPORT_TIMEOUT: Duration = Duration::from_secs(5);
/// A stage that has reported and then says nothing for this long is stopped (SIGSTOP) or hung:
/// every stage reports about once a second, idle or not.
const STALLED_AFTER: Duration = Duration::from_secs(3);
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
        if let Err(reason) = std::fs::File::open(file) {
            return Err(LaunchError::TraceUnreadable {
                session: session.file.clone(),
                trace: file.clone(),
                reason,
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

/// The frames an earlier session left in `dir` (`frame_*.png`, links too): a session writes
/// its frames new, so these are refused without `--force` and removed with it.
fn frames_in(dir: &Path) -> Vec<PathBuf> {
    let mut frames: Vec<PathBuf> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .filter(|e| {
            let name = e.file_name();
            let name = name.to_string_lossy();
            name.starts_with("frame_") && name.ends_with(".png")
        })
        .map(|e| e.path())
        .collect();
    frames.sort();
    frames
}

/// `path` can be written: it is not a folder, and its folder exists (or can be made) and takes
/// a new file. `path` itself is not opened (that would follow a link there): a probe file of
/// its own is created beside it and removed.
fn check_writable(what: &'static str, path: &Path) -> Result<(), LaunchError> {
    if std::fs::symlink_metadata(path).is_ok_and(|m| m.is_dir()) {
        return Err(LaunchError::OutputIsFolder {
            what,
            path: path.to_path_buf(),
        });
    }
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|reason| LaunchError::OutputFolder {
            what,
            dir: dir.to_path_buf(),
            path: path.to_path_buf(),
            reason,
        })?;
    }
    common::output::check_folder_writable(path).map_err(|reason| LaunchError::OutputUnwritable {
        what,
        path: path.to_path_buf(),
        reason,
    })
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

/// The readers of a session, in the order they stop (after the source): pipeline order.
fn readers(session: &Session) -> Vec<Stage> {
    // A remote-fed session (a viewer) has no pipeline of its own: the bridge is its source.
    let remote_fed = matches!(session.source, Source::Remote);
    let mut v = if remote_fed {
        Vec::new()
    } else {
        vec![Stage::Kinematics, Stage::Stepper]
    };
    // A bridge that takes topics in from the other machine publishes them here: it stops
    // before their readers (the renderer, the recorder), or what it publishes after they
    // drained is lost (a frame taken in after the recorder stopped counted as dropped). It
    // still stops after the stepper, whose hand and world it drains to send them.
    let bridge_publishes = session.bridge.is_on() && !session.bridge.outputs().is_empty();
    if bridge_publishes && !remote_fed {
        v.push(Stage::Bridge);
    }
    if session.renderer.mode != RenderMode::Off {
        v.push(Stage::Renderer);
    }
    // Only when recording: a reader of every topic costs a wake-up per sample on cores the
    // pipeline needs, and a session pays only for what it asks for.
    if session.recorder.file.is_some() {
        v.push(Stage::Recorder);
    }
    // The bridge reads what it sends out (and, for a Foxglove view, what it shows).
    if session.bridge.is_on() && !remote_fed && !bridge_publishes {
        v.push(Stage::Bridge);
    }
    v
}

/// Subscribers each topic must have before the source may start: as many as the topic table
/// names readers of it among `stages`, the bridge counted only on `bridge_inputs` (the table
/// names it a reader of every topic; a session says which it reads).
fn expected_subscribers(stages: &[Stage], bridge_inputs: &[Topic]) -> Vec<(Topic, usize)> {
    Topic::ALL
        .into_iter()
        .map(|t| {
            let n = t
                .readers()
                .iter()
                .filter(|s| stages.contains(s))
                .filter(|s| **s != Stage::Bridge || bridge_inputs.contains(&t))
                .count();
            (t, n)
        })
        .filter(|(_, n)| *n > 0)
        .collect()
}

/// Runs one session. The resources of its bus are removed whatever happens.
pub fn launch(opts: &LaunchOptions) -> Result<LaunchOutcome, LaunchError> {
    let session = load_session(opts)?;
    preflight(opts, &session)?;
    let id = opts.bus_id.clone().unwrap_or_else(BusConfig::fresh_id);
    // The world topic is sized from the scene; every stage opens the bus the same way.
    let bus_config = BusConfig::for_session_of(&id, &session)?;
    shutdown::install_signal_handlers();
    for said in BusConfig::sweep_abandoned() {
        eprintln!("handblocks: {said}");
    }
    if bus_config.has_live_processes() {
        return Err(LaunchError::BusIdInUse { id });
    }
    if !bus_config.leftover_shm_files().is_empty() || bus_config.root.exists() {
        // Left by a session whose processes are all gone.
        bus_config
            .remove_resources()
            .map_err(|reason| LaunchError::LeftoverFiles {
                id: id.clone(),
                prefix: bus_config.prefix.clone(),
                reason,
            })?;
    }
    let supervised = session.supervise.restart == RestartPolicy::OnFailure;
    if opts.force {
        // Forced: what is at the outputs' paths goes, the entry itself (a link, never its
        // target), and the outputs are then created new. The recording's restart segments go
        // with it, so that no stale `name.1.mcap` sits beside the new recording as if a
        // restart had written it (preflight refused all of these without --force).
        let mut replaced: Vec<PathBuf> = Vec::new();
        if let Some(rec) = &session.recorder.file {
            let restarts = if supervised {
                session.supervise.max_restarts
            } else {
                0
            };
            replaced.extend((0..=restarts).map(|n| recording_segment(rec, n)));
        }
        replaced.extend(opts.report.iter().cloned());
        replaced.extend(opts.frames_dir.iter().flat_map(|d| frames_in(d)));
        for path in replaced {
            common::output::remove_for_replace(&path).map_err(|reason| {
                LaunchError::OutputUnwritable {
                    what: "--force",
                    path,
                    reason,
                }
            })?;
        }
    }
    // The session's folder, with this launcher named in it: a later launch (any bus id)
    // sweeps it at once if this launcher is killed.
    bus_config.claim_as_launcher()?;

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
    // Every process is reaped and every port dropped by now: the files are ours to remove.
    let cleanup = bus_config.remove_resources();
    let mut report = result?;
    cleanup.map_err(|reason| LaunchError::Cleanup {
        prefix: bus_config.prefix.clone(),
        reason,
    })?;
    report.meta.world = world_json;
    report.meta.bridge = bridge_json;
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

/// Steps 2 to 6 of the launch (the module docs), on a bus that `launch` prepared and cleans up;
/// returns the report of step 7 for `launch` to complete.
fn run_session(
    opts: &LaunchOptions,
    session: &Session,
    bus_config: &BusConfig,
) -> Result<Report, LaunchError> {
    let started_at = SystemTime::now();
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
    let mut supervision = Supervision {
        latency: &latency,
        budget: session.budget.clone(),
        reports: BTreeMap::new(),
        failures: Vec::new(),
        stalled: Vec::new(),
        restarting: Restarting {
            bus: &bus,
            bus_config,
            starter: &starter,
            placement: &placement,
            // A lossless bus (a speed-0 replay) promises every sample to every reader; a
            // process that died broke that promise, and a restart cannot keep it.
            restart: if bus_config.lossless {
                RestartPolicy::Never
            } else {
                session.supervise.restart
            },
            supervise: session.supervise,
            recording: session.recorder.file.clone(),
            restarts: Vec::new(),
            earlier: BTreeMap::new(),
            due: Vec::new(),
            started: Instant::now(),
        },
    };
    // 5. and 6.
    let ran_for = supervision.run(opts, source, &mut procs);
    supervision.stop_in_order(&mut procs);
    supervision.merge_incarnations();
    let Supervision {
        reports,
        failures,
        restarting,
        ..
    } = supervision;
    let mut restarts = restarting.restarts;
    if let Some(rec) = &restarting.recording {
        count_recording_losses(rec, &mut restarts);
    }
    drop(procs);
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
        cpus: std::thread::available_parallelism().map_or(1, |n| n.get()),
        placement: placement.describe(),
        started: started_at,
        seconds: facts.seconds,
        renderer_skipped,
        world: None,
        bridge: None,
    };
    Ok(report)
}

/// How this session's service processes are started: each is `handblocks service NAME` on the
/// session file and bus, with the `--set` overrides every process gets and its stage's own
/// arguments.
struct Starter<'a> {
    exe: &'a Path,
    /// Absolute, so a process started elsewhere reads the same file.
    session_file: PathBuf,
    bus_id: &'a str,
    overrides: Vec<OsString>,
    renderer_args: Vec<OsString>,
    recorder_args: Vec<OsString>,
    stepper_args: Vec<OsString>,
    renderer_env: Vec<(&'static str, OsString)>,
}

impl<'a> Starter<'a> {
    fn new(opts: &'a LaunchOptions, session: &Session, bus_config: &'a BusConfig) -> Starter<'a> {
        let absolute = |p: &PathBuf| std::path::absolute(p).unwrap_or_else(|_| p.clone());
        let mut renderer_args: Vec<OsString> = Vec::new();
        if let Some(dir) = &opts.frames_dir {
            renderer_args.extend(["--frames-dir".into(), absolute(dir).into()]);
        }
        if let Some(preview) = &opts.preview {
            renderer_args.extend(["--preview".into(), absolute(preview).into()]);
        }
        let recorder_args: Vec<OsString> = match &session.recorder.file {
            Some(file) if opts.record.is_some() => vec!["--record".into(), file.into()],
            _ => Vec::new(),
        };
        // Without a desktop session, the Vulkan loader's Wayland support prints
        // "XDG_RUNTIME_DIR is invalid" on every launch of a headless renderer. The session's
        // own root (private, removed at the end, no Wayland socket in it) quiets it without
        // touching the user's environment.
        let renderer_env = if session.renderer.mode == RenderMode::Headless
            && std::env::var_os("XDG_RUNTIME_DIR").is_none()
        {
            vec![("XDG_RUNTIME_DIR", bus_config.root.clone().into_os_string())]
        } else {
            Vec::new()
        };
        Starter {
            exe: &opts.exe,
            session_file: absolute(&opts.session),
            bus_id: &bus_config.id,
            overrides: opts
                .overrides
                .iter()
                .flat_map(|o| ["--set".into(), format!("{}={}", o.key, o.value).into()])
                .collect(),
            renderer_args,
            recorder_args,
            stepper_args: vec!["--outcome-dir".into(), bus_config.root.clone().into()],
            renderer_env,
        }
    }

    /// Starts `stage`'s process on the CPUs `placement` gives it; `restart` is 0 for its first
    /// start, n for its n-th restart.
    fn start(
        &self,
        stage: Stage,
        placement: &Placement,
        restart: u32,
    ) -> Result<ServiceProcess, LaunchError> {
        let mut extra = self.overrides.clone();
        if restart > 0 {
            extra.extend(["--restart".into(), restart.to_string().into()]);
        }
        extra.extend_from_slice(match stage {
            Stage::Renderer => &self.renderer_args,
            Stage::Recorder => &self.recorder_args,
            Stage::Stepper => &self.stepper_args,
            _ => &[],
        });
        let env: Vec<(&str, &std::ffi::OsStr)> = if stage == Stage::Renderer {
            self.renderer_env
                .iter()
                .map(|(k, v)| (*k, v.as_os_str()))
                .collect()
        } else {
            Vec::new()
        };
        ServiceProcess::start(
            self.exe,
            stage,
            &self.session_file,
            self.bus_id,
            &extra,
            placement.cpus_of(stage),
            &env,
        )
        .map_err(|reason| LaunchError::Spawn {
            stage,
            exe: self.exe.to_path_buf(),
            reason,
        })
    }
}

/// Issue 28: once the session has ended, each recorder restart's loss as its recording
/// shows it: the seqs that neither the dead recorder's segment nor the next one holds.
fn count_recording_losses(recording: &Path, restarts: &mut [Restart]) {
    let last = restarts
        .iter()
        .filter(|r| r.stage == Stage::Recorder)
        .map(|r| r.n)
        .max();
    let Some(last) = last else { return };
    match recording::SegmentChain::open(recording, last + 1) {
        Ok(chain) => {
            for r in restarts.iter_mut().filter(|r| r.stage == Stage::Recorder) {
                r.missing_from_recording = chain
                    .gaps
                    .get(r.n as usize - 1)
                    .map(|g| g.iter().map(|g| (g.topic, g.lost())).collect());
                if r.missing_from_recording.is_none() {
                    r.segment_error = Some(format!(
                        "its segment {} was not written",
                        common::config::session::recording_segment(recording, r.n).display()
                    ));
                }
            }
        }
        Err(e) => {
            for r in restarts.iter_mut().filter(|r| r.stage == Stage::Recorder) {
                r.segment_error = Some(e.to_string());
            }
        }
    }
}

/// Step 3: starts the readers, the last in the pipeline first, and waits until every one is
/// attached. Returns their processes (recorder first) and, when the renderer found no GPU
/// adapter, the line that says it was skipped; the pipeline then gets every CPU.
fn start_readers(
    starter: &Starter,
    session: &Session,
    services: &Services,
    placement: &mut Placement,
) -> Result<(Vec<ServiceProcess>, Option<String>), LaunchError> {
    let mut stages = readers(session);
    let mut procs: Vec<ServiceProcess> = Vec::new();
    for stage in stages.iter().rev() {
        procs.push(starter.start(*stage, placement, 0)?);
    }
    let bridge_inputs = session.bridge_inputs();
    let renderer_skipped = wait_until_connected(services, &mut stages, &bridge_inputs, &mut procs)?;
    if let Some(line) = &renderer_skipped {
        eprintln!("handblocks: {line}");
        // The pipeline was placed apart from a renderer that is not there: give it every CPU.
        if placement.describe().is_some() {
            *placement = Placement::shared();
            for p in procs.iter_mut() {
                p.unpin();
            }
        }
    }
    Ok((procs, renderer_skipped))
}

/// Step 4: starts the source last, so no sample is lost at start-up, and waits until it is
/// attached (the session's time starts then, however long it took to start). `procs` ends in
/// pipeline order: source first, recorder last.
fn start_source(
    starter: &Starter,
    session: &Session,
    services: &Services,
    placement: &Placement,
    procs: &mut Vec<ServiceProcess>,
) -> Result<Stage, LaunchError> {
    let (source, outputs): (Stage, Vec<Topic>) = match session.source {
        Source::Replay { .. } => (Stage::Replay, Stage::Replay.recorded_outputs().collect()),
        Source::Remote => (Stage::Bridge, session.bridge.outputs()),
        _ => (
            Stage::Acquisition,
            Stage::Acquisition.recorded_outputs().collect(),
        ),
    };
    procs.push(starter.start(source, placement, 0)?);
    procs.reverse();
    wait_for_source(services, source, &outputs, procs)?;
    Ok(source)
}

/// What the launcher gathers while the session runs and stops: every stage's newest latency
/// report, and what went wrong with the processes.
struct Supervision<'a> {
    latency: &'a Inlet<topics::Latency>,
    budget: common::config::session::Budget,
    reports: BTreeMap<Stage, StageReport>,
    failures: Vec<String>,
    /// The stages already said to be stalled (each is said once).
    stalled: Vec<Stage>,
    restarting: Restarting<'a>,
}

/// Issue 16, supervision: what restarting a dead process takes and what the restarts were.
struct Restarting<'a> {
    /// The launcher's node, which removes a dead process's node and ports.
    bus: &'a Bus,
    /// The session's bus: where its publishers keep their seq.
    bus_config: &'a BusConfig,
    starter: &'a Starter<'a>,
    placement: &'a Placement,
    /// The policy in force (`never` on a lossless bus, whatever the session says).
    restart: RestartPolicy,
    supervise: common::config::session::Supervise,
    /// The session's recording, whose next segment a restarted recorder writes.
    recording: Option<PathBuf>,
    restarts: Vec<Restart>,
    /// Per restarted stage, the merged reports of its dead incarnations.
    earlier: BTreeMap<Stage, StageReport>,
    /// Dead processes waiting out their back-off: index into the processes, and when.
    due: Vec<(usize, Instant)>,
    /// The session's start (restart times count from it).
    started: Instant,
}

impl Restarting<'_> {
    fn count(&self, stage: Stage) -> u32 {
        self.restarts.iter().filter(|r| r.stage == stage).count() as u32
    }
}

impl Supervision<'_> {
    /// Issue 16: a stage stopped with SIGSTOP (or hung) left no trace in the report; its
    /// reports stop, so a stage silent for [`STALLED_AFTER`] is a failure, said at once.
    fn check_stalled(&mut self, opts: &LaunchOptions, procs: &[ServiceProcess]) {
        for p in procs {
            let Some(r) = self.reports.get(&p.stage) else {
                continue;
            };
            let silent = r.heard_at.elapsed();
            if r.final_report || silent < STALLED_AFTER || self.stalled.contains(&p.stage) {
                continue;
            }
            self.stalled.push(p.stage);
            let line = format!(
                "the {} process has sent no report for {:.1} s: it is stopped (SIGSTOP?) or \
                 hung, and what it reads is piling up unread",
                p.stage.name(),
                silent.as_secs_f64()
            );
            if opts.progress {
                eprintln!("handblocks: {line}");
            }
            self.failures.push(line);
        }
    }

    /// Step 5: runs for `--duration`, until Ctrl-C / SIGTERM, until a replay's trace ends, or
    /// until a process exits (a failure), printing progress; returns how long it ran.
    fn run(
        &mut self,
        opts: &LaunchOptions,
        source: Stage,
        procs: &mut [ServiceProcess],
    ) -> Duration {
        let started = Instant::now();
        self.restarting.started = started;
        let mut next_progress = Duration::from_secs(1);
        let mut progress = progress::Progress::new(&self.budget);
        loop {
            // 10 ms: a dead child is noticed (and restarted) within it.
            std::thread::sleep(Duration::from_millis(10));
            collect(self.latency, &mut self.reports);
            self.note_first_outputs();
            if shutdown::requested() || opts.duration.is_some_and(|d| started.elapsed() >= d) {
                break;
            }
            // A replay that played its whole trace has sent its final report: the session
            // ends, as `ros2 bag play` does.
            if has_final(&self.reports, source) {
                if opts.progress {
                    eprintln!(
                        "handblocks: the trace ended after {:.1} s; stopping",
                        started.elapsed().as_secs_f64()
                    );
                }
                break;
            }
            if let Err(line) = self.supervise_children(opts, procs) {
                if opts.progress {
                    eprintln!("handblocks: {line}");
                }
                self.failures.push(line);
                break;
            }
            self.check_stalled(opts, procs);
            if opts.progress && started.elapsed() >= next_progress {
                next_progress += Duration::from_secs(1);
                eprintln!("{}", progress.line(started.elapsed(), &self.reports));
            }
        }
        started.elapsed()
    }

    /// Notices processes that died: each is restarted (after its back-off) when the session's
    /// `[supervise]` allows, else the session fails with the returned line. Processes whose
    /// back-off is over are started again here.
    fn supervise_children(
        &mut self,
        opts: &LaunchOptions,
        procs: &mut [ServiceProcess],
    ) -> Result<(), String> {
        for (i, p) in procs.iter_mut().enumerate() {
            if self.restarting.due.iter().any(|(j, _)| *j == i) {
                continue;
            }
            let Some(status) = p.poll_exit() else {
                continue;
            };
            let stage = p.stage;
            let noticed_ns = common::monotonic_ns();
            let exit = describe_exit(Some(status));
            let done = self.restarting.count(stage);
            let policy = self.restarting.supervise;
            if self.restarting.restart == RestartPolicy::Never {
                return Err(format!(
                    "the {} process exited during the session ({exit})",
                    stage.name()
                ));
            }
            if done >= policy.max_restarts {
                return Err(format!(
                    "the {} process exited during the session ({exit}) after {done} restarts; \
                     [supervise] max_restarts = {} allows no more",
                    stage.name(),
                    policy.max_restarts
                ));
            }
            // Its last reports are read before it is written off: what arrives later is the
            // restarted process's.
            collect(self.latency, &mut self.reports);
            self.retire_incarnation(stage);
            self.stalled.retain(|s| *s != stage);
            // Reaped (poll_exit waited on it): iceoryx2 now sees its node dead, and removing
            // it frees its ports for the process that takes its place.
            let (removed, failed) = self.restarting.bus.cleanup_dead_nodes();
            if failed > 0 {
                eprintln!(
                    "handblocks: {failed} dead node(s) of the {} process could not be removed \
                     ({removed} were)",
                    stage.name()
                );
            }
            let n = done + 1;
            let wait = policy.backoff(n);
            let segment = (stage == Stage::Recorder)
                .then(|| {
                    self.restarting
                        .recording
                        .as_ref()
                        .map(|f| recording_segment(f, n).display().to_string())
                })
                .flatten();
            let at_s = self.restarting.started.elapsed().as_secs_f64();
            if opts.progress {
                eprintln!(
                    "handblocks: the {} process exited ({exit}) at {at_s:.2} s; restart {n} of \
                     at most {} in {} ms",
                    stage.name(),
                    policy.max_restarts,
                    wait.as_millis()
                );
            }
            // What its publishers had sent at its death: the samples after it were published
            // while it was down.
            let published_at_death = Topic::ALL
                .into_iter()
                .filter(|t| t.readers().contains(&stage))
                .filter_map(|t| Some((t, self.restarting.bus_config.published_count(t)?)))
                .collect();
            self.restarting.restarts.push(Restart {
                stage,
                n,
                at_s,
                exit,
                noticed_ns,
                first_output_ns: None,
                lost: None,
                published_at_death,
                segment,
                missing_from_recording: None,
                segment_error: None,
            });
            self.restarting.due.push((i, Instant::now() + wait));
        }
        let now = Instant::now();
        while let Some(k) = self.restarting.due.iter().position(|(_, at)| *at <= now) {
            let (i, _) = self.restarting.due.remove(k);
            let stage = procs[i].stage;
            let n = self.restarting.count(stage);
            let started = self
                .restarting
                .starter
                .start(stage, self.restarting.placement, n)
                .map_err(|e| format!("the {} process could not be restarted: {e}", stage.name()))?;
            procs[i] = started;
        }
        Ok(())
    }

    /// A dead incarnation's report joins those of the stage's earlier ones; the samples lost
    /// between it and the one before go to that restart.
    fn retire_incarnation(&mut self, stage: Stage) {
        // One that died before its first report counted nothing, but its restart is still
        // to be told apart from it.
        let current = self
            .reports
            .remove(&stage)
            .unwrap_or_else(|| StageReport::empty(stage));
        let merged = match self.restarting.earlier.remove(&stage) {
            None => current,
            Some(earlier) => {
                let n = self.restarting.count(stage);
                let restart = self
                    .restarting
                    .restarts
                    .iter_mut()
                    .find(|r| r.stage == stage && r.n == n);
                let at_death = restart
                    .as_ref()
                    .map_or(&[][..], |r| &r.published_at_death[..]);
                let (merged, lost) = earlier.then(current, at_death);
                if let Some(r) = restart {
                    r.lost = Some(lost);
                }
                merged
            }
        };
        self.restarting.earlier.insert(stage, merged);
    }

    /// At the end: every restarted stage's report is all its incarnations' together.
    fn merge_incarnations(&mut self) {
        let stages: Vec<Stage> = self.restarting.earlier.keys().copied().collect();
        for stage in stages {
            self.retire_incarnation(stage);
            if let Some(merged) = self.restarting.earlier.remove(&stage) {
                self.reports.insert(stage, merged);
            }
        }
    }

    /// A restarted process's first output ends its downtime.
    fn note_first_outputs(&mut self) {
        let reports = &self.reports;
        let restarts = &mut self.restarting.restarts;
        for k in 0..restarts.len() {
            let (stage, noticed_ns) = (restarts[k].stage, restarts[k].noticed_ns);
            // Only the stage's latest restart: its report is the running incarnation's.
            if restarts[k].first_output_ns.is_some()
                || restarts[k + 1..].iter().any(|q| q.stage == stage)
            {
                continue;
            }
            if let Some(rep) = reports.get(&stage) {
                if rep.first_output_ns >= noticed_ns {
                    restarts[k].first_output_ns = Some(rep.first_output_ns);
                }
            }
        }
    }

    /// Step 6: stops the processes in pipeline order; each stage drains what the one before it
    /// sent and sends its final report, and is released and reaped once that report is read
    /// (or it gave up). A process without a final report, or that failed, is a failure.
    fn stop_in_order(&mut self, procs: &mut [ServiceProcess]) {
        for (i, p) in procs.iter_mut().enumerate() {
            if self.restarting.due.iter().any(|(j, _)| *j == i) {
                // Dead and waiting out its back-off when the session ended: its death is in
                // the report as a restart (never made), not a failure; its reports so far
                // are its earlier incarnations'.
                continue;
            }
            p.request_stop();
            let deadline = Instant::now() + FINAL_REPORT_TIMEOUT;
            while !has_final(&self.reports, p.stage) {
                collect(self.latency, &mut self.reports);
                if Instant::now() > deadline
                    || (p.poll_exit().is_some() && !has_final(&self.reports, p.stage))
                {
                    break;
                }
                std::thread::sleep(Duration::from_millis(1));
            }
            collect(self.latency, &mut self.reports);
            let cpu = p.cpu_seconds();
            if let Some(r) = self.reports.get_mut(&p.stage) {
                r.cpu_s = cpu;
            }
            let status = p.release_and_reap(Duration::from_secs(5));
            if !has_final(&self.reports, p.stage) {
                self.failures.push(format!(
                    "the {} process sent no final report ({})",
                    p.stage.name(),
                    describe_exit(status)
                ));
            } else if !status.is_some_and(|s| s.success())
                && !self.failures.iter().any(|f| f.contains(p.stage.name()))
            {
                self.failures.push(format!(
                    "the {} process failed ({})",
                    p.stage.name(),
                    describe_exit(status)
                ));
            }
        }
    }
}

fn has_final(reports: &BTreeMap<Stage, StageReport>, stage: Stage) -> bool {
    reports.get(&stage).is_some_and(|r| r.final_report)
}

/// Polls `ready` until it returns None (all attached) or the start-up fails: a process exits,
/// or CONNECT_TIMEOUT passes (then the error says what `ready` last reported missing).
fn wait_for_start(
    procs: &mut [ServiceProcess],
    mut ready: impl FnMut() -> Option<String>,
) -> Result<(), LaunchError> {
    let deadline = Instant::now() + CONNECT_TIMEOUT;
    while let Some(missing) = ready() {
        if let Some(p) = procs.iter_mut().find_map(|p| p.poll_exit().map(|_| p)) {
            return Err(LaunchError::ExitedDuringStartup {
                stage: p.stage,
                status: p.exit,
            });
        }
        if Instant::now() > deadline {
            return Err(LaunchError::AttachTimeout {
                waited: CONNECT_TIMEOUT,
                missing,
            });
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    Ok(())
}

/// Every reader attached (see [`wait_for_readers`]). A renderer that found no GPU adapter
/// exits with [`RENDERER_SKIPPED_EXIT`] before it attaches: the session goes on without it,
/// and the returned line says what was skipped and how to get it.
fn wait_until_connected(
    services: &Services,
    stages: &mut Vec<Stage>,
    bridge_inputs: &[Topic],
    procs: &mut Vec<ServiceProcess>,
) -> Result<Option<String>, LaunchError> {
    let Err(e) = wait_for_readers(services, stages, bridge_inputs, procs) else {
        return Ok(None);
    };
    let skipped = procs.iter_mut().position(|p| {
        p.stage == Stage::Renderer
            && p.poll_exit()
                .is_some_and(|s| s.code() == Some(RENDERER_SKIPPED_EXIT))
    });
    let Some(i) = skipped else {
        return Err(e);
    };
    procs.remove(i);
    stages.retain(|s| *s != Stage::Renderer);
    wait_for_readers(services, stages, bridge_inputs, procs)?;
    Ok(Some(
        "renderer skipped: no GPU adapter (no Vulkan driver found), so no frames and no \
         preview; to draw, install one: sudo apt-get install mesa-vulkan-drivers libvulkan1 \
         (./run does this)"
            .to_string(),
    ))
}

/// Every reader attached: each topic has its subscribers, and each reader's latency publisher
/// (created last) exists.
fn wait_for_readers(
    services: &Services,
    stages: &[Stage],
    bridge_inputs: &[Topic],
    procs: &mut [ServiceProcess],
) -> Result<(), LaunchError> {
    let expected = expected_subscribers(stages, bridge_inputs);
    wait_for_start(procs, || {
        let mut missing: Vec<String> = expected
            .iter()
            .filter(|(t, n)| services.subscribers(*t) < *n)
            .map(|(t, n)| format!("{} ({} of {n} readers)", t.name(), services.subscribers(*t)))
            .collect();
        let reporting = services.publishers(Topic::Latency);
        if reporting < stages.len() {
            missing.push(format!("latency ({reporting} of {} stages)", stages.len()));
        }
        (!missing.is_empty()).then(|| missing.join(", "))
    })
}

/// The source attached: the publishers of its samples (`outputs`: the topics the table names
/// it a publisher of, its latency report aside; a remote-fed session's bridge, those it takes
/// in) exist, so the session's time can start.
fn wait_for_source(
    services: &Services,
    source: Stage,
    outputs: &[Topic],
    procs: &mut [ServiceProcess],
) -> Result<(), LaunchError> {
    wait_for_start(procs, || {
        let missing: Vec<&str> = outputs
            .iter()
            .copied()
            .filter(|t| services.publishers(*t) == 0)
            .map(|t| t.name())
            .collect();
        (!missing.is_empty())
            .then(|| format!("the {} publishers of {}", source.name(), missing.join(", ")))
    })
}

/// Reads every latency report waiting; the newest of each stage replaces the older one
/// (histograms are cumulative).
fn collect(latency: &Inlet<topics::Latency>, reports: &mut BTreeMap<Stage, StageReport>) {
    while let Ok(Some(s)) = latency.receive() {
        match StageReport::decode(s.payload()) {
            Ok(r) => {
                reports.insert(r.stage, r);
            }
            Err(e) => eprintln!("handblocks: ignoring a malformed latency report: {e}"),
        }
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The counts the table gives are those the launcher used to list by hand (which left out
    /// `joints`: its readers, kinematics and the recorder, open it before their latency
    /// publisher, which the launcher also waits for).
    #[test]
    fn expected_subscribers_follow_the_topic_table() {
        let all = [
            Stage::Kinematics,
            Stage::Stepper,
            Stage::Renderer,
            Stage::Recorder,
        ];
        assert_eq!(
            expected_subscribers(&all, &[]),
            [
                (Topic::Glove, 2),
                (Topic::Tracker, 2),
                (Topic::Joints, 2),
                (Topic::Hand, 3),
                (Topic::World, 2),
                (Topic::Frame, 1),
            ]
        );
        assert_eq!(
            expected_subscribers(&[Stage::Kinematics, Stage::Stepper], &[]),
            [
                (Topic::Glove, 1),
                (Topic::Tracker, 1),
                (Topic::Joints, 1),
                (Topic::Hand, 1),
            ]
        );
        // The bridge counts on the topics its session sends, not on every one it could.
        assert_eq!(
            expected_subscribers(
                &[Stage::Kinematics, Stage::Stepper, Stage::Bridge],
                &[Topic::Hand, Topic::World]
            ),
            [
                (Topic::Glove, 1),
                (Topic::Tracker, 1),
                (Topic::Joints, 1),
                (Topic::Hand, 2),
                (Topic::World, 1),
            ]
        );
    }
}
