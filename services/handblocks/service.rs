//! `handblocks service NAME --session FILE --bus ID` (hidden): one process of a session, as
//! the launcher starts it. The process itself is its crate's [`Process`], listed once here.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use common::bus::{Bus, BusConfig, BusError};
use common::config::session::{Override, RestartPolicy};
use common::config::Session;
use common::node::{Launch, Process};
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

/// The processes `handblocks service` runs, one line per service crate: each crate's
/// [`Process`] names its row of the stage table and has the one entry signature, so this list
/// is all that ties a stage to its crate. It generates [`StageError`] (a variant per crate,
/// holding that crate's own error) and the dispatch from a stage to its process.
macro_rules! processes {
    ($($variant:ident: $process:ty),* $(,)?) => {
        /// What failed in a stage's process: setting it up (its session, its bus), or the
        /// stage's own work, each stage with its crate's error type.
        #[derive(Debug, thiserror::Error)]
        pub enum StageError {
            #[error(transparent)]
            Session(common::config::ConfigError),
            #[error(transparent)]
            Bus(BusError),
            $(
                #[error(transparent)]
                $variant(<$process as Process>::Error),
            )*
            /// A stage no crate of this binary runs: the launcher starts a program of the
            /// user's as it (`[source] command`).
            #[error(
                "the {} stage is a program of yours (Python's handblocks.Source), which the \
                 launcher starts from [source] command; it is not a handblocks service",
                .0.name()
            )]
            NoProcess(Stage),
        }

        /// Runs `stage`'s process.
        fn run_process(
            stage: Stage,
            session: &Session,
            bus: &Bus,
            launch: &Launch,
        ) -> Result<(), StageError> {
            $(
                if stage == <$process as Process>::STAGE {
                    return <$process as Process>::run(session, bus, launch)
                        .map_err(StageError::$variant);
                }
            )*
            Err(StageError::NoProcess(stage))
        }
    };
}

processes! {
    Acquisition: acquisition::Process,
    Replay: replay::Process,
    Kinematics: kinematics::Process,
    Stepper: stepper::Process,
    Renderer: renderer::Process,
    Recorder: recorder::Process,
    Bridge: bridge::Process,
    Webxr: webxr::Process,
    Null: null_source::Process,
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
    // Every process of a session opens the bus as the session says (world sizes, loss).
    let config = BusConfig::for_session_of(bus_id, &session).map_err(StageError::Bus)?;
    let mut bus = Bus::for_stage(&config, stage).map_err(StageError::Bus)?;
    if session.wake == common::config::session::WakeUp::Event {
        bus = bus.woken_by_events();
    }
    if session.supervise.restart == RestartPolicy::OnFailure {
        bus = bus.supervised(args.restart);
    }
    let launch = Launch {
        frames_dir: args.frames_dir,
        preview: args.preview,
        outcome_dir: args.outcome_dir,
        restart: args.restart,
    };
    run_process(stage, &session, &bus, &launch)
}
