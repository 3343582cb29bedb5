//! Starting: steps 3 and 4 of a launch (the crate docs). The readers start first, the last in
//! the pipeline first, and the launcher waits until every one is attached to the bus (each
//! topic has its subscribers, each reader its latency publisher); the source starts last, so
//! no sample is lost at start-up. The [`Starter`] is kept for the session: supervision starts
//! a dead process again the same way.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use common::bus::{BusConfig, Services};
use common::config::session::RenderMode;
use common::config::Session;
use common::{Stage, Topic};

use crate::placement::Placement;
use crate::process::ServiceProcess;
use crate::{LaunchError, LaunchOptions, RENDERER_SKIPPED_EXIT};

/// How long the processes may take to attach to the bus.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(20);

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

/// How this session's service processes are started: each is `handblocks service NAME` on the
/// session file and bus, with the `--set` overrides every process gets and its stage's own
/// arguments.
pub(crate) struct Starter<'a> {
    exe: &'a Path,
    /// Absolute, so a process started elsewhere reads the same file.
    pub(crate) session_file: PathBuf,
    bus_id: &'a str,
    overrides: Vec<OsString>,
    renderer_args: Vec<OsString>,
    recorder_args: Vec<OsString>,
    stepper_args: Vec<OsString>,
    renderer_env: Vec<(&'static str, OsString)>,
    /// `[source] kind = "external"`: the user's program, started as the source.
    external_command: Option<Vec<String>>,
}

impl<'a> Starter<'a> {
    pub(crate) fn new(
        opts: &'a LaunchOptions,
        session: &Session,
        bus_config: &'a BusConfig,
    ) -> Starter<'a> {
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
            external_command: match &session.source {
                common::config::session::Source::External { command } => Some(command.clone()),
                _ => None,
            },
        }
    }

    /// Starts `stage`'s process on the CPUs `placement` gives it; `restart` is 0 for its first
    /// start, n for its n-th restart.
    pub(crate) fn start(
        &self,
        stage: Stage,
        placement: &Placement,
        restart: u32,
    ) -> Result<ServiceProcess, LaunchError> {
        if let (Stage::External, Some(command)) = (stage, &self.external_command) {
            return ServiceProcess::start_program(
                command,
                stage,
                &self.session_file,
                self.bus_id,
                placement.cpus_of(stage),
            )
            .map_err(|reason| LaunchError::Spawn {
                stage,
                exe: PathBuf::from(&command[0]),
                reason,
            });
        }
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

/// Step 3: starts the readers, the last in the pipeline first, and waits until every one is
/// attached. Returns their processes (recorder first) and, when the renderer found no GPU
/// adapter, the line that says it was skipped; the pipeline then gets every CPU.
pub(crate) fn start_readers(
    starter: &Starter,
    session: &Session,
    services: &Services,
    placement: &mut Placement,
) -> Result<(Vec<ServiceProcess>, Option<String>), LaunchError> {
    let mut stages = session.graph().readers;
    let mut procs: Vec<ServiceProcess> = Vec::new();
    for stage in stages.iter().rev() {
        procs.push(starter.start(*stage, placement, 0)?);
    }
    let bridge_inputs = session.bridge_inputs();
    // A session that waits for its viewer ([remote] wait_for_viewer_s): its bridge attaches
    // once a viewer does, so it is given that long on top.
    let timeout = CONNECT_TIMEOUT
        + Duration::from_secs(
            session
                .bridge
                .link
                .as_ref()
                .map_or(0, |l| l.wait_for_viewer_s),
        );
    let renderer_skipped =
        wait_until_connected(services, &mut stages, &bridge_inputs, &mut procs, timeout)?;
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
pub(crate) fn start_source(
    starter: &Starter,
    session: &Session,
    services: &Services,
    placement: &Placement,
    procs: &mut Vec<ServiceProcess>,
) -> Result<Stage, LaunchError> {
    let graph = session.graph();
    let (source, outputs) = (graph.source, graph.source_outputs);
    procs.push(starter.start(source, placement, 0)?);
    procs.reverse();
    wait_for_source(services, source, &outputs, procs)?;
    Ok(source)
}

/// Polls `ready` until it returns None (all attached) or the start-up fails: a process exits,
/// or CONNECT_TIMEOUT passes (then the error says what `ready` last reported missing).
fn wait_for_start(
    procs: &mut [ServiceProcess],
    timeout: Duration,
    mut ready: impl FnMut() -> Option<String>,
) -> Result<(), LaunchError> {
    let deadline = Instant::now() + timeout;
    while let Some(missing) = ready() {
        if let Some(p) = procs.iter_mut().find_map(|p| p.poll_exit().map(|_| p)) {
            return Err(LaunchError::ExitedDuringStartup {
                stage: p.stage,
                status: p.exit,
            });
        }
        if Instant::now() > deadline {
            return Err(LaunchError::AttachTimeout {
                waited: timeout,
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
    timeout: Duration,
) -> Result<Option<String>, LaunchError> {
    let Err(e) = wait_for_readers(services, stages, bridge_inputs, procs, timeout) else {
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
    wait_for_readers(services, stages, bridge_inputs, procs, timeout)?;
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
    timeout: Duration,
) -> Result<(), LaunchError> {
    let expected = expected_subscribers(stages, bridge_inputs);
    wait_for_start(procs, timeout, || {
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
    wait_for_start(procs, CONNECT_TIMEOUT, || {
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
                (Topic::PeerHand, 2),
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
