//! `handblocks.simulate`: the block world as a function. It calls what `handblocks simulate`
//! calls ([`simulation::run`]) and returns the report's figures as arrays beside the report's
//! JSON text, which is the command's `--json` output byte for byte.
//!
//! What comes from Python is bounded before anything runs (issue 40): a scene dict must be a
//! tree no deeper than [`MAX_DICT_DEPTH`] (a dict that holds itself would recurse until the
//! stack overflows and the interpreter dies), and `frames` at most [`MAX_FRAMES`]. The run
//! itself lets go of the GIL and looks for Ctrl-C every [`SIGNAL_CHECK_EVERY`].

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};

use common::config::scene::ModelKind;
use common::config::Scene;
use simulation::{SimulateError as RunError, SimulateSettings, Stop};

use crate::arrays::array;
use crate::{RecordingError, SceneError, SimulateError};

/// The name a scene given as a dict has in error messages.
pub const DICT_SCENE: &str = "<dict>";

/// The most steps `frames` may ask for: ten million, a day of world time at the default
/// 120 steps a second (about 15 s of computing for grasp-throw, a day for the thousand blocks
/// of field-1024 under the precise model; Ctrl-C stops either). More is a typo, or a run that
/// would hold the interpreter for days.
pub const MAX_FRAMES: u64 = 10_000_000;

/// How often a run looks for Ctrl-C (and any other Python signal handler): often enough that
/// a person sees Ctrl-C act at once, seldom enough that taking the GIL back costs the run
/// nothing measurable (a step is microseconds; the hook that looks runs after each).
const SIGNAL_CHECK_EVERY: Duration = Duration::from_millis(50);

/// How deeply a scene dict may nest dicts, lists and tuples. A scene file's deepest value (a
/// hand key's `fingers`: hand, keys, a key, its fingers, a finger, a point) is 6 deep; deeper
/// is a mistake, and a bound keeps the conversion's recursion far from the stack's end.
pub const MAX_DICT_DEPTH: usize = 64;

/// Runs a scene (a file, a bare name found in the configuration folder, or a dict of the
/// scene file's tables) and returns the report as a dict (see python/handblocks).
#[pyfunction]
#[pyo3(signature = (scene, hand=None, model=None, frames=None, hand_offset=(0.0, 0.0, 0.0), hands="right", trajectory=false))]
#[allow(clippy::too_many_arguments)]
pub fn simulate<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyAny>,
    hand: Option<PathBuf>,
    model: Option<&str>,
    frames: Option<&Bound<'py, PyAny>>,
    hand_offset: (f64, f64, f64),
    hands: &str,
    trajectory: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let Some(hands) = common::HandsUsed::parse(hands) else {
        return Err(PyValueError::new_err(format!(
            "hands={hands:?}: allowed: \"right\", \"left\" or \"both\" (the hands of the trace \
             that drive the world)"
        )));
    };
    let frames = frames.map(checked_frames).transpose()?;
    let model = match model {
        None => None,
        Some("paper") => Some(ModelKind::Paper),
        Some("precise") => Some(ModelKind::Precise),
        Some(other) => {
            return Err(PyValueError::new_err(format!(
                "model={other:?}: allowed: \"paper\", \"precise\", or None for the scene's \
                 [world] model"
            )))
        }
    };
    let scene = load_scene(scene)?;
    let settings = SimulateSettings {
        model,
        trace: hand,
        hand_offset: [hand_offset.0, hand_offset.1, hand_offset.2],
        hands,
        frames,
    };
    // Without the GIL (other Python threads go on), back with it every
    // `SIGNAL_CHECK_EVERY` for a moment to run the signal handlers: Ctrl-C's
    // KeyboardInterrupt stops the run and is raised here.
    let mut interrupted: Option<PyErr> = None;
    // `trajectory`: every block's pose and mode after every step (the path to plot).
    let mut path_position: Vec<f64> = Vec::new();
    let mut path_rotation: Vec<f64> = Vec::new();
    let mut path_mode: Vec<u32> = Vec::new();
    let mut path_steps = 0usize;
    let ran = py.detach(|| {
        let mut last_check = Instant::now();
        simulation::run_with_progress(&scene, &settings, &mut |_, world| {
            if trajectory {
                path_steps += 1;
                for i in 0..world.block_count() {
                    if let Some(b) = world.block(i) {
                        path_position.extend(b.position.to_array());
                        path_rotation.extend(b.rotation.to_array());
                        path_mode.push(b.mode as u32);
                    }
                }
            }
            if last_check.elapsed() < SIGNAL_CHECK_EVERY {
                return Ok(());
            }
            last_check = Instant::now();
            Python::attach(|py| py.check_signals()).map_err(|e| {
                interrupted = Some(e);
                Stop
            })
        })
    });
    let (report, notes) = ran.map_err(|e| match e {
        RunError::Scene(e) => SceneError::new_err(e.to_string()),
        RunError::Trace(e) => RecordingError::new_err(e),
        RunError::Stopped { steps } => interrupted
            .take()
            .unwrap_or_else(|| SimulateError::new_err(format!("stopped after {steps} steps"))),
        e => SimulateError::new_err(e.to_string()),
    })?;
    let out = PyDict::new(py);
    let b = report.blocks.len();
    out.set_item("frames", report.frames)?;
    out.set_item(
        "names",
        report
            .blocks
            .iter()
            .map(|x| x.name.clone())
            .collect::<Vec<_>>(),
    )?;
    out.set_item(
        "position",
        array(
            py,
            report.blocks.iter().flat_map(|x| x.position).collect(),
            &[b, 3],
        )?,
    )?;
    out.set_item(
        "rotation",
        array(
            py,
            report.blocks.iter().flat_map(|x| x.rotation).collect(),
            &[b, 4],
        )?,
    )?;
    out.set_item(
        "mode",
        array(
            py,
            report.blocks.iter().map(|x| x.mode as u32).collect(),
            &[b],
        )?,
    )?;
    let events = PyList::empty(py);
    for e in &report.events {
        let d = PyDict::new(py);
        d.set_item("step", e.step)?;
        d.set_item("kind", e.kind.name())?;
        d.set_item("block", &e.block)?;
        d.set_item("hand", e.hand.map(|h| h.name()))?;
        d.set_item("participant", e.participant)?;
        events.append(d)?;
    }
    out.set_item("events", events)?;
    out.set_item("clock_jumps", report.clock_jumps)?;
    out.set_item("refused_hands", report.refused_hands)?;
    if trajectory && path_steps > 0 {
        // Blocks never come or go in a run: each step wrote all of them.
        let n = b.max(1);
        let steps = path_mode.len() / n;
        out.set_item("path_position", array(py, path_position, &[steps, b, 3])?)?;
        out.set_item("path_rotation", array(py, path_rotation, &[steps, b, 4])?)?;
        out.set_item("path_mode", array(py, path_mode, &[steps, b])?)?;
        out.set_item("step_hz", scene.world.step_hz)?;
    }
    out.set_item("json", report.to_json())?;
    out.set_item("text", report.to_text())?;
    out.set_item("notes", notes.lines)?;
    Ok(out)
}

/// `frames` as given: an int from 0 to [`MAX_FRAMES`] (a numpy integer too); else a
/// ValueError that states the range, or a TypeError for what is no int at all.
fn checked_frames(frames: &Bound<'_, PyAny>) -> PyResult<u64> {
    let allowed = format!(
        "allowed: 0 to {MAX_FRAMES} steps, or None for the scene's hand (or the trace's) plus \
         time to settle"
    );
    if frames.is_instance_of::<PyBool>() {
        return Err(pyo3::exceptions::PyTypeError::new_err(format!(
            "frames={frames}: a number of steps, not a bool; {allowed}"
        )));
    }
    match frames.extract::<u64>() {
        Ok(n) if n <= MAX_FRAMES => Ok(n),
        Ok(_) => Err(PyValueError::new_err(format!("frames={frames}: {allowed}"))),
        // An int beyond u64 or below 0 (`__index__` worked, the range did not).
        Err(_) if frames.hasattr("__index__").unwrap_or(false) => {
            Err(PyValueError::new_err(format!("frames={frames}: {allowed}")))
        }
        Err(_) => Err(pyo3::exceptions::PyTypeError::new_err(format!(
            "frames: an int, not {}; {allowed}",
            frames
                .get_type()
                .name()
                .map_or("?".into(), |n| n.to_string())
        ))),
    }
}

/// The scene: a dict is checked as the file would be (its errors name `<dict>`); a path is
/// used as given when it exists, else a bare name is looked up as the command line does.
fn load_scene(scene: &Bound<'_, PyAny>) -> PyResult<Scene> {
    let loaded =
        if let Ok(dict) = scene.cast::<PyDict>() {
            let toml::Value::Table(table) = to_toml(dict.as_any(), "", &mut Vec::new())? else {
                return Err(PyValueError::new_err("a dict that is not a table"));
            };
            Scene::from_table(Path::new(DICT_SCENE), &table)
        } else {
            let path: PathBuf =
                scene.extract().map_err(|_| {
                    pyo3::exceptions::PyTypeError::new_err(format!(
                "scene: a path (str or os.PathLike) or a dict of the scene's tables, not {}",
                scene.get_type().name().map_or("?".into(), |n| n.to_string())
            ))
                })?;
            Scene::load(&resolve_scene(&path))
        };
    loaded.map_err(|e| SceneError::new_err(e.to_string()))
}

/// `given` when it exists; else a bare name (`grasp-throw`) in `$HANDBLOCKS_CONFIG/scenes`,
/// `./config/scenes`, or the repository this package was built from (while its `config/` is
/// there), as `handblocks simulate` looks; else `given` (its error then names it as given).
fn resolve_scene(given: &Path) -> PathBuf {
    if given.exists() || given.components().count() != 1 {
        return given.to_path_buf();
    }
    let name = given.to_string_lossy();
    let file = if name.ends_with(".toml") {
        name.into_owned()
    } else {
        format!("{name}.toml")
    };
    std::env::var_os("HANDBLOCKS_CONFIG")
        .map(PathBuf::from)
        .into_iter()
        .chain([
            PathBuf::from("config"),
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../config"),
        ])
        .map(|dir| dir.join("scenes").join(&file))
        .find(|p| p.is_file())
        .unwrap_or_else(|| given.to_path_buf())
}

/// A Python value as TOML: dicts, lists and tuples, bool, int, float, str, and anything with
/// `tolist()` (a numpy array or scalar). `at` names the key in errors; `inside` holds the
/// dicts, lists and tuples that contain `v` (their identity and key path), so that a value
/// that holds itself is refused by name instead of recursing until the stack overflows, and
/// so is nesting deeper than [`MAX_DICT_DEPTH`].
fn to_toml(
    v: &Bound<'_, PyAny>,
    at: &str,
    inside: &mut Vec<(usize, String)>,
) -> PyResult<toml::Value> {
    if inside.len() >= MAX_DICT_DEPTH {
        return Err(PyValueError::new_err(format!(
            "{DICT_SCENE}: `{at}` nests deeper than {MAX_DICT_DEPTH} dicts and lists (a scene \
             nests a few); give the scene's tables as plain dicts and lists"
        )));
    }
    let container = v.is_instance_of::<PyDict>()
        || v.is_instance_of::<PyList>()
        || v.is_instance_of::<PyTuple>();
    if container {
        let id = v.as_ptr() as usize;
        if let Some((_, outer)) = inside.iter().find(|(i, _)| *i == id) {
            let what = if v.is_instance_of::<PyDict>() {
                "dict"
            } else {
                "list"
            };
            let outer = if outer.is_empty() {
                "the scene dict itself".to_string()
            } else {
                format!("the {what} at `{outer}` again")
            };
            return Err(PyValueError::new_err(format!(
                "{DICT_SCENE}: key `{at}` holds {outer}, which contains it (a cycle); a scene \
                 is a tree: give each table a dict (or list) of its own"
            )));
        }
        inside.push((id, at.to_string()));
    }
    let value = to_toml_in(v, at, inside);
    if container {
        inside.pop();
    }
    value
}

/// [`to_toml`] of one value, its containers already in `inside`.
fn to_toml_in(
    v: &Bound<'_, PyAny>,
    at: &str,
    inside: &mut Vec<(usize, String)>,
) -> PyResult<toml::Value> {
    let name = |k: &str| {
        if at.is_empty() {
            k.to_string()
        } else {
            format!("{at}.{k}")
        }
    };
    if let Ok(d) = v.cast::<PyDict>() {
        let mut t = toml::Table::new();
        for (k, item) in d.iter() {
            let key: String = k.extract().map_err(|_| {
                PyValueError::new_err(format!(
                    "{DICT_SCENE}: the keys of {} must be strings",
                    if at.is_empty() { "the scene" } else { at }
                ))
            })?;
            let value = to_toml(&item, &name(&key), inside)?;
            t.insert(key, value);
        }
        return Ok(toml::Value::Table(t));
    }
    if v.is_instance_of::<PyBool>() {
        return Ok(toml::Value::Boolean(v.extract()?));
    }
    if v.is_instance_of::<PyInt>() {
        return v.extract::<i64>().map(toml::Value::Integer).map_err(|_| {
            PyValueError::new_err(format!("{DICT_SCENE}: {at}: an integer beyond 64 bits"))
        });
    }
    if v.is_instance_of::<PyFloat>() {
        return Ok(toml::Value::Float(v.extract()?));
    }
    if v.is_instance_of::<PyString>() {
        return Ok(toml::Value::String(v.extract()?));
    }
    if v.is_instance_of::<PyList>() || v.is_instance_of::<PyTuple>() {
        let mut items = Vec::new();
        for (i, item) in v.try_iter()?.enumerate() {
            items.push(to_toml(&item?, &format!("{at}[{i}]"), inside)?);
        }
        return Ok(toml::Value::Array(items));
    }
    if v.hasattr("tolist")? {
        // Counted as a level of its own: a `tolist()` that returns its own kind again would
        // otherwise recurse without end.
        inside.push((0, at.to_string()));
        let value = to_toml(&v.call_method0("tolist")?, at, inside);
        inside.pop();
        return value;
    }
    Err(PyValueError::new_err(format!(
        "{DICT_SCENE}: {at}: a {} has no TOML form; give a dict, list, bool, int, float or str",
        v.get_type().name().map_or("?".into(), |n| n.to_string())
    )))
}
