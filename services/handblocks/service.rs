//! `handblocks service NAME --session FILE --bus ID` (hidden): one process of a session, as
//! the launcher starts it. The process itself is its crate's `service::run`.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use common::bus::{Bus, BusConfig, BusError};
use common::config::session::{recording_segment, Override, RestartPolicy};
use common::config::Session;
use common::{shutdown, Stage};

/// What the launcher passes a service besides its name, session and bus.
pub struct ServiceArgs {
    pub frames_dir: Option<PathBuf>,
    pub record: Option<PathBuf>,
    pub preview: Option<PathBuf>,
    pub outcome_dir: Option<PathBuf>,
    pub overrides: Vec<Override>,
    /// Which restart of this process this is (0: its first start).
    pub restart: u32,
}

/// Why a service process stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum ServiceError {
    /// NAME is none of the stages.
    #[error("unknown service {name:?}; one of: {}", stage_names())]
    Unknown { name: String },
    /// The stage's process failed: its session, its bus, or its own work.
    #[error("{error}")]
    Failed {
        stage: Stage,
        #[source]
        error: StageError,
    },
}

fn stage_names() -> String {
    let names: Vec<&str> = Stage::ALL.iter().map(|s| s.name()).collect();
    names.join(", ")
}

/// What failed in a stage's process: setting it up (its session, its bus), or the stage's own
/// work, each stage with its crate's error type.
#[derive(Debug, thiserror::Error)]
pub enum StageError {
    #[error("{0}")]
    Session(#[source] common::config::ConfigError),
    #[error("{0}")]
    Bus(#[source] BusError),
    #[error("{0}")]
    Acquisition(#[source] acquisition::service::AcquisitionError),
    #[error("{0}")]
    Kinematics(#[source] BusError),
    #[error("{0}")]
    Stepper(#[source] stepper::service::StepperError),
    #[error("{0}")]
    Renderer(#[source] renderer::RenderError),
    #[error("{0}")]
    Recorder(#[source] recorder::service::RecorderError),
    #[error("{0}")]
    Replay(#[source] replay::service::ReplayError),
    #[error("{0}")]
    Bridge(#[source] bridge::service::BridgeError),
    #[error("{0}")]
    Webxr(#[source] webxr::WebxrError),
    /// `service external`: that stage is the user's own program.
    #[error(
        "the external source is a program of yours (Python's handblocks.Source), which the \
         launcher starts from [source] command; it is not a handblocks service"
    )]
    External,
}

impl ServiceError {
    /// Who says it: `service` for a name that is none, else the stage (`handblocks stepper: ...`).
    pub fn service(&self) -> &'static str {
        match self {
            ServiceError::Unknown { .. } => "service",
            ServiceError::Failed { stage, .. } => stage.name(),
        }
    }
}

/// Runs the stage until it is asked to stop. A renderer without a GPU adapter exits with
/// [`launcher::RENDERER_SKIPPED_EXIT`] and no message: the launcher goes on without it and
/// says so in one line.
pub fn run(
    name: &str,
    session_file: &Path,
    bus_id: &str,
    args: ServiceArgs,
) -> Result<ExitCode, ServiceError> {
    shutdown::install_signal_handlers();
    shutdown::watch_parent_pipe();
    let Some(stage) = Stage::from_name(name) else {
        return Err(ServiceError::Unknown {
            name: name.to_string(),
        });
    };
    match run_stage(stage, session_file, bus_id, args) {
        Ok(()) => Ok(ExitCode::SUCCESS),
        Err(StageError::Renderer(renderer::RenderError::NoAdapter(_))) => {
            Ok(ExitCode::from(launcher::RENDERER_SKIPPED_EXIT as u8))
        }
        Err(error) => Err(ServiceError::Failed { stage, error }),
    }
}

fn run_stage(
    stage: Stage,
    session_file: &Path,
    bus_id: &str,
    args: ServiceArgs,
) -> Result<(), StageError> {
    let mut session =
        Session::load_with(session_file, &args.overrides).map_err(StageError::Session)?;
    if args.record.is_some() {
        session.recorder.file = args.record;
    }
    if stage == Stage::Recorder {
        // A restarted recorder writes the next segment, leaving the dead one's file whole.
        session.recorder.file = session
            .recorder
            .file
            .map(|f| recording_segment(&f, args.restart));
    }
    // Every process of a session opens the bus as the session says (world sizes, loss).
    let config = BusConfig::for_session_of(bus_id, &session).map_err(StageError::Bus)?;
    let mut bus = Bus::for_stage(&config, stage).map_err(StageError::Bus)?;
    if session.supervise.restart == RestartPolicy::OnFailure {
        bus = bus.supervised(args.restart);
    }
    match stage {
        Stage::Acquisition => {
            acquisition::service::run(&session, &bus).map_err(StageError::Acquisition)
        }
        Stage::Kinematics => {
            kinematics::service::run(&session, &bus).map_err(StageError::Kinematics)
        }
        Stage::Stepper => {
            stepper::service::run_with_outcome(&session, &bus, args.outcome_dir.as_deref())
                .map_err(StageError::Stepper)
        }
        Stage::Renderer => renderer::service::run_with_preview(
            &session,
            &bus,
            renderer::RenderSettings::from_session_framed(&session.renderer, &session.scene),
            // A restarted renderer writes its frames beside the dead one's, in a folder of
            // its own (numbering starts again), so that none of them is overwritten.
            args.frames_dir.map(|dir| renderer::FramesRequest {
                dir: if args.restart > 0 {
                    dir.join(format!("restart-{}", args.restart))
                } else {
                    dir
                },
                every_nth: session.renderer.frames_every,
            }),
            args.preview,
        )
        .map_err(StageError::Renderer),
        Stage::Recorder => recorder::service::run(&session, &bus).map_err(StageError::Recorder),
        Stage::Replay => replay::service::run(&session, &bus).map_err(StageError::Replay),
        Stage::Bridge => bridge::service::run(&session, &bus).map_err(StageError::Bridge),
        Stage::Webxr => webxr::run(&session, &bus).map_err(StageError::Webxr),
        Stage::External => Err(StageError::External),
    }
}
