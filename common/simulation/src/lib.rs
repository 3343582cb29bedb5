//! A scene's block world run in one process, deterministically: the hand from the scene's
//! keyframes or from a trace, made into hands exactly as the live processes make them. The
//! command `handblocks simulate` and Python's `handblocks.simulate` both call [`run`], so the
//! two agree bit for bit (and with a live session of the same scene at the step rate).

use std::fmt;
use std::path::{Path, PathBuf};

use common::config::scene::{HandPoseSpec, ModelKind};
use common::config::{ConfigError, Scene};

pub use stepper::Report;

/// What to simulate beside the scene.
#[derive(Debug, Clone, Default)]
pub struct SimulateSettings {
    /// `paper` or `precise` replaces the scene's `[world] model`; None keeps it.
    pub model: Option<ModelKind>,
    /// One of our recordings or a CARL file, in place of the scene's `[hand]`.
    pub trace: Option<PathBuf>,
    /// Moves the trace's hand, metres.
    pub hand_offset: [f64; 3],
    /// Steps in all; None: the scene's hand plus 3 s to settle, or the trace's hands plus 2 s.
    pub frames: Option<u64>,
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

/// What the run said on the way, for the caller to show: why this many steps, and the
/// trace's warnings (damage, bad samples replaced).
#[derive(Debug, Clone, Default)]
pub struct Notes {
    pub lines: Vec<String>,
}

/// Runs `scene` (already loaded) under `settings`; the report and what it noted.
pub fn run(scene: &Scene, settings: &SimulateSettings) -> Result<(Report, Notes), SimulateError> {
    let mut scene = scene.clone();
    if let Some(model) = settings.model {
        scene.world.model = model;
    }
    let mut notes = Notes::default();
    if settings.frames.is_none() {
        let why = match &settings.trace {
            Some(_) => "the trace's hands, then 2 s to settle".to_string(),
            None => format!(
                "{} steps: the hand's last key plus 3 s to settle",
                stepper::default_frames(&scene)
            ),
        };
        notes.lines.push(format!(
            "{why}, at {} steps a second (--frames N to choose; a live session steps for as \
             long as it runs)",
            scene.world.step_hz
        ));
    }
    let report = match &settings.trace {
        Some(trace) => simulate_trace(
            &scene,
            trace,
            settings.hand_offset,
            settings.frames,
            &mut notes,
        )?,
        None => simulate_scene(&scene, settings.frames)?,
    };
    Ok((report, notes))
}

/// The scene's own hand: bare check points (`fingers` keys), or keyframes through the hand
/// model as a live session samples them, or no hand.
fn simulate_scene(scene: &Scene, frames: Option<u64>) -> Result<Report, SimulateError> {
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

/// A trace's samples become hands exactly as in a live replay (kinematics'
/// [`kinematics::HandStream`]: one hand per tracker or joints sample, gloves paired by source
/// time; then the stepper's timeline), then 2 s to settle. The trace is one of our MCAP
/// recordings or a CARL file.
fn simulate_trace(
    scene: &Scene,
    trace: &Path,
    offset: [f64; 3],
    frames: Option<u64>,
    notes: &mut Notes,
) -> Result<Report, SimulateError> {
    let trace = replay::HandTrace::load(trace, offset).map_err(SimulateError::Trace)?;
    for w in &trace.warnings {
        notes.lines.push(format!("warning: {w}"));
    }
    if !trace.warnings.is_empty() {
        notes
            .lines
            .push(format!("using the {} good samples", trace.samples.len()));
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
