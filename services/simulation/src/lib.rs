//! A scene's block world run in one process, deterministically: the hand from the scene's
//! keyframes or from a trace, made into hands exactly as the live processes make them. The
//! command `handblocks simulate` and Python's `handblocks.simulate` both call [`run`], so the
//! two agree bit for bit (and with a live session of the same scene at the step rate).
//!
//! A run can be long (`--frames` is the caller's to choose) and a caller may need to stop it
//! (Python's Ctrl-C, which only the caller can see): [`run_with_progress`] calls a hook after
//! every step, which may [`Stop`] the run: the stepper's own runs
//! ([`stepper::simulate_with`], [`stepper::simulate_samples_with`]) call it.

use std::fmt;
use std::path::{Path, PathBuf};

use common::config::scene::ModelKind;
use common::config::{ConfigError, Scene};

pub use stepper::Report;

/// A progress hook's answer ([`stepper::Stop`]): stop the run here (the run returns
/// [`SimulateError::Stopped`]). The hook ([`Progress`]) is called once a step with the steps
/// taken so far, whatever a step costs (a step of a thousand blocks takes milliseconds, one of
/// a single block microseconds), so a caller that wants to look less often looks at the
/// clock: see python/src/simulate.rs.
pub use stepper::{Progress, Stop};

/// What to simulate beside the scene.
#[derive(Debug, Clone, Default)]
pub struct SimulateSettings {
    /// `paper` or `precise` replaces the scene's `[world] model`; None keeps it.
    pub model: Option<ModelKind>,
    /// One of our recordings or a CARL file, in place of the scene's `[hand]`.
    pub trace: Option<PathBuf>,
    /// Moves the trace's hand, metres.
    pub hand_offset: [f64; 3],
    /// Which hands of the trace drive the world (a CARL file holds both): one (the right by
    /// default) or both (docs/model.md "Two hands").
    pub hands: common::HandsUsed,
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
    /// The caller's progress hook stopped the run after `steps` steps.
    Stopped { steps: u64 },
}

impl fmt::Display for SimulateError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SimulateError::Scene(e) => write!(f, "{e}"),
            SimulateError::Script { scene, error } => write!(f, "{}: {error}", scene.display()),
            SimulateError::Trace(e) => write!(f, "{e}"),
            SimulateError::World(e) => write!(f, "{e}"),
            SimulateError::Stopped { steps } => write!(f, "stopped after {steps} steps"),
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
    run_with_progress(scene, settings, &mut |_, _| Ok(()))
}

/// [`run`], calling `progress` with the steps taken after every step; when it answers
/// [`Stop`], the run ends there with [`SimulateError::Stopped`].
pub fn run_with_progress(
    scene: &Scene,
    settings: &SimulateSettings,
    progress: &mut Progress<'_>,
) -> Result<(Report, Notes), SimulateError> {
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
            settings.hands,
            settings.frames,
            &mut notes,
            progress,
        )?,
        None => simulate_scene(&scene, settings.frames, progress)?,
    };
    Ok((report, notes))
}

/// The scene's own hands (its `[hand]`, and its `[left_hand]` if it has one): bare check
/// points (`fingers` keys), or keyframes through the hand model as a live session samples
/// them, or no hand.
fn simulate_scene(
    scene: &Scene,
    frames: Option<u64>,
    progress: &mut Progress<'_>,
) -> Result<Report, SimulateError> {
    let frames = frames.unwrap_or_else(|| stepper::default_frames(scene));
    let bare = scene.hand.as_ref().is_some_and(|h| h.is_bare());
    if bare {
        let mut right = stepper::BareFingersHand::from_scene(scene);
        let mut left = stepper::BareFingersHand::left_of_scene(scene);
        let hands = [
            right.as_mut().map(|h| h as &mut dyn stepper::HandSource),
            left.as_mut().map(|h| h as &mut dyn stepper::HandSource),
        ];
        return stepper::simulate_hands_with(scene, frames, hands, progress).map_err(run_error);
    }
    if scene.hand.is_none() {
        return step_hand(scene, frames, None, progress);
    }
    // The same path as a live session: keyframes -> glove + tracker -> the hand model, each
    // hand on its own side (the left mirrored).
    let scripted =
        acquisition::ScriptedHand::of_scene(scene).map_err(|error| SimulateError::Script {
            scene: scene.file.clone(),
            error,
        })?;
    let model = kinematics::HandModel::default();
    let step_hz = scene.world.step_hz;
    let mut sources: Vec<_> = scripted
        .iter()
        .zip([common::HandSide::Right, common::HandSide::Left])
        .map(|(script, side)| {
            let model = &model;
            let mut hand = common::HandSample::default();
            move |step: u64, _t: f64| {
                // Sampled exactly as the acquisition process samples it (k / rate), so that a
                // live session at the step rate computes bit-identical worlds.
                let (glove, tracker) = script.samples_at(
                    step as f64 / step_hz,
                    common::Stamp {
                        seq: step,
                        ..Default::default()
                    },
                );
                model.solve_side(side, &glove, &tracker.wrist, &mut hand);
                Some(hand)
            }
        })
        .collect();
    let mut sources = sources.iter_mut();
    let hands = [
        sources.next().map(|h| h as &mut dyn stepper::HandSource),
        sources.next().map(|h| h as &mut dyn stepper::HandSource),
    ];
    stepper::simulate_hands_with(scene, frames, hands, progress).map_err(run_error)
}

/// The `hand` samples of one of our recordings that holds hands but no source samples (no
/// tracker, no joints): a shared world's host records its participants' hands so, as its
/// stepper took them. None for a CARL file, or a recording with source samples (those are
/// made into hands anew, as a live replay makes them).
fn recorded_hands(trace: &Path) -> Result<Option<Vec<common::HandSample>>, SimulateError> {
    use common::Topic;
    let head = {
        use std::io::Read;
        let mut head = [0u8; 8];
        let n = common::config::open_regular(trace)
            .and_then(|mut f| f.read(&mut head).map_err(|e| e.to_string()))
            .map_err(|e| SimulateError::Trace(format!("{}: {e}", trace.display())))?;
        head[..n].to_vec()
    };
    if !recording::Recording::is_mcap(&head) {
        return Ok(None);
    }
    let rec =
        recording::Recording::open_topics(trace, &[Topic::Tracker, Topic::Joints, Topic::Hand])
            .map_err(|e| SimulateError::Trace(e.to_string()))?;
    let has = |t: Topic| rec.messages.iter().any(|m| m.topic == t);
    if has(Topic::Tracker) || has(Topic::Joints) || !has(Topic::Hand) {
        return Ok(None);
    }
    Ok(Some(
        rec.samples::<common::HandSample>(Topic::Hand).collect(),
    ))
}

/// A run's end: the world's error, or where the hook stopped it.
fn run_error(e: stepper::RunError) -> SimulateError {
    match e {
        stepper::RunError::World(e) => SimulateError::World(e),
        stepper::RunError::Stopped { steps } => SimulateError::Stopped { steps },
    }
}

fn step_hand(
    scene: &Scene,
    frames: u64,
    hand: Option<&mut dyn stepper::HandSource>,
    progress: &mut Progress<'_>,
) -> Result<Report, SimulateError> {
    stepper::simulate_with(scene, frames, hand, progress).map_err(run_error)
}

/// A trace's samples become hands exactly as in a live replay (kinematics'
/// [`kinematics::HandStream`]: one hand per tracker or joints sample, gloves paired by source
/// time; then the stepper's timeline), then 2 s to settle. The trace is one of our MCAP
/// recordings or a CARL file.
fn simulate_trace(
    scene: &Scene,
    trace: &Path,
    offset: [f64; 3],
    hands: common::HandsUsed,
    frames: Option<u64>,
    notes: &mut Notes,
    progress: &mut Progress<'_>,
) -> Result<Report, SimulateError> {
    if let Some(recorded) = recorded_hands(trace)? {
        if offset != [0.0; 3] {
            return Err(SimulateError::Trace(format!(
                "{}: holds hands as the stepper took them (in the world's frame), not a \
                 source's: --hand-offset moves a source's hand; leave it out",
                trace.display()
            )));
        }
        notes.lines.push(format!(
            "{}: no source samples; its {} recorded hands (a shared world's host records \
             every participant's) step the world as its stepper took them",
            trace.display(),
            recorded.len()
        ));
        return stepper::simulate_samples_with(scene, &recorded, frames, progress)
            .map_err(run_error);
    }
    let trace =
        replay::HandTrace::load_hands(trace, offset, hands).map_err(SimulateError::Trace)?;
    let hands = hands_of(&trace, notes);
    stepper::simulate_samples_with(scene, &hands, frames, progress).map_err(run_error)
}

/// A trace's samples as hands (kinematics' [`kinematics::HandStream`], as the live process
/// makes them), noting the trace's warnings.
fn hands_of(trace: &replay::HandTrace, notes: &mut Notes) -> Vec<common::HandSample> {
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
            // A shared world host's recording (`recorded_hands` takes those before here).
            replay::SourceSample::Hand(h) => Some(h),
        };
        hands.extend(hand.copied());
    }
    hands
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(name: &str) -> Scene {
        let file = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../config/scenes")
            .join(name);
        Scene::load(&file).expect("a scene of the repository")
    }

    fn carl(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../../shared/data/carl")
            .join(name)
    }

    #[test]
    fn the_progress_hook_is_called_after_every_step_and_can_stop_the_run() {
        let scene = scene("grasp-throw.toml");
        let settings = SimulateSettings {
            frames: Some(500),
            ..SimulateSettings::default()
        };
        let mut seen = Vec::new();
        run_with_progress(&scene, &settings, &mut |n, _| {
            seen.push(n);
            Ok(())
        })
        .expect("the scene runs");
        assert_eq!(seen, (1..=500).collect::<Vec<u64>>());
        let stopped = run_with_progress(&scene, &settings, &mut |n, _| {
            if n == 123 {
                Err(Stop)
            } else {
                Ok(())
            }
        });
        assert!(
            matches!(stopped, Err(SimulateError::Stopped { steps: 123 })),
            "{stopped:?}"
        );
    }

    #[test]
    fn the_progress_hook_can_stop_a_trace_run_in_its_trace_and_in_its_settling() {
        let scene = scene("carl-push.toml");
        let trace = carl("example_push_0.carl");
        // The 2.4 s trace brings ~290 steps at 120 Hz: 100 is inside it, 400 in the settling
        // after it, 100_000 far into a long `frames`.
        for (frames, stop_at) in [(None, 100), (None, 400), (Some(1 << 40), 100_000)] {
            let settings = SimulateSettings {
                trace: Some(trace.clone()),
                hand_offset: [0.0, -1.45, 0.0],
                frames,
                ..SimulateSettings::default()
            };
            let mut last = 0;
            let stopped = run_with_progress(&scene, &settings, &mut |n, _| {
                assert_eq!(n, last + 1, "one call a step");
                last = n;
                if n >= stop_at {
                    Err(Stop)
                } else {
                    Ok(())
                }
            });
            assert!(
                matches!(stopped, Err(SimulateError::Stopped { steps }) if steps == stop_at),
                "{stopped:?}"
            );
        }
    }
}
