//! `handblocks simulate SCENE`: a scene's block world alone, in one process, deterministically;
//! the hand from the scene's keyframes or, with `--hand TRACE`, from a trace, made into hands
//! by kinematics' [`kinematics::HandStream`] exactly as the live process makes them.

use std::fmt;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use common::config::scene::{HandPoseSpec, ModelKind};
use common::config::{ConfigError, Scene};

/// What `handblocks simulate` was given.
pub struct SimulateArgs {
    pub scene: PathBuf,
    pub frames: Option<u64>,
    /// `paper` or `precise` (clap allows only those): replaces the scene's [world] model.
    pub model: Option<String>,
    /// `--hand TRACE`: one of our recordings or a CARL file, in place of the scene's [hand].
    pub trace: Option<PathBuf>,
    pub hand_offset: [f64; 3],
    pub json: bool,
}

/// Why a simulation was refused or stopped.
#[derive(Debug)]
pub enum SimulateError {
    /// The scene file was refused (the message names file, key and range).
    Scene(ConfigError),
    /// The scene's [hand] keyframes cannot be played.
    Script {
        scene: PathBuf,
        error: acquisition::scripted::ScriptError,
    },
    /// The trace cannot be read or holds no hand samples.
    Trace(String),
    /// The world refused the scene or a step.
    World(stepper::WorldError),
}

impl fmt::Display for SimulateError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SimulateError::Scene(e) => write!(f, "{e}"),
            SimulateError::Script { scene, error } => write!(f, "{}: {error}", scene.display()),
            SimulateError::Trace(e) => write!(f, "{e}"),
            SimulateError::World(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for SimulateError {}

pub fn run(args: SimulateArgs) -> Result<ExitCode, SimulateError> {
    let file = crate::locate::resolve(&args.scene, crate::locate::Kind::Scene);
    let mut scene = Scene::load(&file).map_err(SimulateError::Scene)?;
    match args.model.as_deref() {
        Some("precise") => scene.world.model = ModelKind::Precise,
        Some(_) => scene.world.model = ModelKind::Paper,
        None => {}
    }
    // Why this many steps (a live session of the same scene steps as long as it runs).
    if args.frames.is_none() {
        let why = match &args.trace {
            Some(_) => "the trace's hands, then 2 s to settle".to_string(),
            None => format!(
                "{} steps: the hand's last key plus 3 s to settle",
                stepper::default_frames(&scene)
            ),
        };
        eprintln!(
            "handblocks simulate: {why}, at {} steps a second (--frames N to choose; a live \
             session steps for as long as it runs)",
            scene.world.step_hz
        );
    }
    let report = match &args.trace {
        Some(trace) => simulate_trace(&scene, trace, args.hand_offset, args.frames)?,
        None => simulate_scene(&scene, args.frames)?,
    };
    if args.json {
        println!("{}", report.to_json());
    } else {
        print!("{}", report.to_text());
    }
    Ok(ExitCode::SUCCESS)
}

/// The scene's own hand: bare check points (`fingers` keys), or keyframes through the hand
/// model as a live session samples them, or no hand.
fn simulate_scene(scene: &Scene, frames: Option<u64>) -> Result<stepper::Report, SimulateError> {
    let frames = frames.unwrap_or_else(|| stepper::default_frames(scene));
    let bare = scene.hand.as_ref().is_some_and(|h| {
        h.keys
            .iter()
            .any(|k| matches!(k.pose, HandPoseSpec::Fingers(_)))
    });
    let report = if bare {
        let mut hand = stepper::BareFingersHand::from_scene(scene);
        stepper::simulate(
            scene,
            frames,
            hand.as_mut().map(|h| h as &mut dyn stepper::HandSource),
        )
    } else if let Some(script) = &scene.hand {
        // The same path as a live session: keyframes -> glove + tracker -> the hand model.
        let scripted =
            acquisition::ScriptedHand::new(script).map_err(|error| SimulateError::Script {
                scene: scene.file.clone(),
                error,
            })?;
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
        stepper::simulate(scene, frames, Some(&mut source))
    } else {
        stepper::simulate(scene, frames, None)
    };
    report.map_err(SimulateError::World)
}

/// `simulate --hand TRACE`: the trace's samples become hands exactly as in a live replay
/// (kinematics' [`kinematics::HandStream`]: one hand per tracker or joints sample, gloves
/// paired by source time; then the stepper's timeline), then 2 s to settle. TRACE is one of
/// our MCAP recordings or a CARL file.
fn simulate_trace(
    scene: &Scene,
    trace: &Path,
    offset: [f64; 3],
    frames: Option<u64>,
) -> Result<stepper::Report, SimulateError> {
    let trace = replay::HandTrace::load(trace, offset).map_err(SimulateError::Trace)?;
    for w in &trace.warnings {
        eprintln!("handblocks simulate: warning: {w}");
    }
    if !trace.warnings.is_empty() {
        eprintln!(
            "handblocks simulate: using the {} good samples",
            trace.samples.len()
        );
    }
    let mut stream = kinematics::HandStream::new(kinematics::HandModel::default());
    let mut hands: Vec<common::HandSample> = Vec::with_capacity(trace.hands());
    for sample in &trace.samples {
        let hand = match sample {
            replay::SourceSample::Glove(g) => {
                stream.glove(g);
                None
            }
            replay::SourceSample::Tracker(t) => stream.tracker(t),
            replay::SourceSample::Joints(j) => Some(stream.joints(j)),
        };
        hands.extend(hand.copied());
    }
    stepper::simulate_samples(scene, &hands, frames).map_err(SimulateError::World)
}
