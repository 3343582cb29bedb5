//! `handblocks bench tosses` (issue 42, its first part): how far each model is from a real
//! block. 400 tosses of a 10.5 cm acrylic cube tracked at 148 Hz (the ContactNets data,
//! `../shared/data/tosses`, its README gives the format) are each simulated from their first
//! tracked state by every contender, stepping at the tracker's own rate, and scored against the
//! rest of the track: where the cube's centre is (in cube edges), how it is turned, where it ends
//! and on which face.
//!
//! What this part holds and what it does not yet: the paper model and the precise model
//! (rapier3d) at the source's nominal contact values, at values fitted to a quarter of the
//! tosses ([`fit`], frozen in `config/tosses-fit.toml`) and at the precise model's own; neither
//! MuJoCo nor PyBullet (issue 42 asks for both): the page says so, so that nobody reads these
//! figures as the issue's.
//!
//! Frames: the data is z up, the world y up: a point (x, y, z) of the data is (x, z, -y) here
//! (a right-handed turn of -90 deg about x), and so is every orientation. The board is the
//! plane z = 0 "up to a small offset": the offset is measured from the files themselves (the
//! median over the tosses of the last sample's height above a face-down cube's half-width) and
//! taken off every height, so a cube at rest in the data rests on the world's floor.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::{DQuat, DVec3};
use serde_json::{json, Value};

use crate::page::num;

use common::config::scene::{BlockSpec, Effects, PreciseSettings, ShapeSpec, WorldSettings};
use common::config::Scene;
use stepper::Model;

use crate::hands::quantile;
use crate::page::{self, Provenance};
use crate::plot::{Axis, Figure, Join, Panel, Series};

/// The cube's half-width (m), from the data's README (`experiment-source.json`).
pub const HALF_WIDTH: f64 = 0.0524;
/// Its mass (kg), uniform density.
pub const MASS: f64 = 0.37;
/// Its edge (m): the unit of the position error.
pub const EDGE: f64 = 2.0 * HALF_WIDTH;
/// The tracker's rate (Hz): sample k is at k / 148 s.
pub const RATE_HZ: f64 = 148.0;
/// The source's nominal contact values (starting values of its study, not measured truths).
pub const NOMINAL_FRICTION: f64 = 0.18;
pub const NOMINAL_RESTITUTION: f64 = 0.125;
/// Tosses a `--quick` run simulates.
pub const QUICK_TOSSES: usize = 40;
/// Timed rounds (every contender once per round, the order rotated).
const ROUNDS: usize = 3;

/// What `handblocks bench tosses` is given.
#[derive(Debug, Clone)]
pub struct TossesBench {
    pub out_dir: PathBuf,
    pub tosses_dir: PathBuf,
    /// The frozen contact fit (`config/tosses-fit.toml`): read, or written anew with `fit`.
    pub fit_file: PathBuf,
    /// Fit the contact values again ([`fit`]) and write `fit_file` before the run.
    pub fit: bool,
    pub quick: bool,
    /// The repository (its `bench/python/toss_engines.py` drives the outside engines; their
    /// virtual environment is made under its `target/`).
    pub repo: PathBuf,
    /// A Python that imports `mujoco` and `pybullet`; None: the bench's own venv
    /// ([`Outside::prepare`]).
    pub python: Option<PathBuf>,
    /// Whole runs of every contender (each [`ROUNDS`] interleaved rounds): a published time is
    /// the median of the runs' medians, with the run-to-run spread. At least 1.
    pub runs: usize,
}

/// An engine nobody here wrote, driven from Python by `bench/python/toss_engines.py`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutsideEngine {
    MuJoCo,
    PyBullet,
}

impl OutsideEngine {
    pub const ALL: [OutsideEngine; 2] = [OutsideEngine::MuJoCo, OutsideEngine::PyBullet];
    pub fn name(self) -> &'static str {
        match self {
            OutsideEngine::MuJoCo => "mujoco",
            OutsideEngine::PyBullet => "pybullet",
        }
    }
}

/// Contact values, as every contender takes them: Coulomb friction, restitution, and the
/// contact's stiffness as the natural frequency of its spring (None: the engine's own rule).
/// Each engine realises them its own way (`toss_engines.py` says how: MuJoCo's bounce is the
/// damping ratio of its contact spring, PyBullet's spring is critically damped beside its
/// restitution; the precise model takes all three as its `[precise]` keys).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Contact {
    pub friction: f64,
    pub restitution: f64,
    pub contact_hz: Option<f64>,
}

impl Contact {
    pub const NOMINAL: Contact = Contact {
        friction: NOMINAL_FRICTION,
        restitution: NOMINAL_RESTITUTION,
        contact_hz: None,
    };
    fn params(&self) -> Vec<(&'static str, f64)> {
        let mut p = vec![
            ("friction", self.friction),
            ("restitution", self.restitution),
        ];
        if let Some(hz) = self.contact_hz {
            p.push(("contact_hz", hz));
        }
        p
    }
}

/// One engine's contact values fitted to real tosses ([`fit`]), as frozen in the repository's
/// `config/tosses-fit.toml`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fitted {
    pub contact: Contact,
    /// The fit's score: the median position error over the fit's tosses, cube edges.
    pub fit_error: f64,
    /// How many tosses the fit used.
    pub fit_tosses: usize,
}

/// Every engine's fit; an outside engine's is None where it was never fitted (its Python
/// could not be made when `--fit` ran).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fits {
    pub precise: Fitted,
    pub mujoco: Option<Fitted>,
    pub pybullet: Option<Fitted>,
}

impl Fits {
    fn of(&self, e: OutsideEngine) -> Option<Fitted> {
        match e {
            OutsideEngine::MuJoCo => self.mujoco,
            OutsideEngine::PyBullet => self.pybullet,
        }
    }
}

/// The fit's tosses: every fourth of the folder by name (index 0, 4, 8, ...), so that the
/// other three quarters are held out and a fit that only learned its own tosses shows.
pub fn in_fit(index: usize) -> bool {
    index.is_multiple_of(4)
}

/// The grid the fit tries: friction x restitution, the source's nominal values among them;
/// then the contact's stiffness.
pub const FIT_FRICTION: [f64; 10] = [0.05, 0.1, 0.15, 0.18, 0.22, 0.3, 0.4, 0.6, 0.8, 1.0];
pub const FIT_RESTITUTION: [f64; 8] = [0.0, 0.05, 0.1, 0.125, 0.15, 0.2, 0.3, 0.4];
pub const FIT_CONTACT_HZ: [f64; 5] = [15.0, 30.0, 60.0, 120.0, 240.0];

/// The procedure, in words, for the fit file, the JSON and the page.
pub const FIT_PROCEDURE: &str = "every fourth toss by name (the rest held out); for each \
engine at its default substeps, first every friction x restitution of the grid with the \
engine's own contact stiffness, then every contact stiffness (a spring's natural frequency) \
of the grid at that pair; the lowest median position error wins (the first on a tie, the \
engine's own stiffness first)";

/// Fits one engine's contact values to the fit's tosses ([`in_fit`]), by [`FIT_PROCEDURE`]:
/// `median_error` runs the engine on them with the values given and returns the median
/// position error. A grid, not a descent: the error is not smooth in these values (a cube
/// lands on an edge or a face), and a grid says what it tried.
pub fn fit(
    what: &str,
    fit_tosses: usize,
    median_error: &mut dyn FnMut(Contact) -> Result<f64, String>,
    progress: &mut dyn FnMut(&str),
) -> Result<Fitted, String> {
    let mut best: Option<Fitted> = None;
    let consider = |contact: Contact, e: f64, best: &mut Option<Fitted>| {
        if best.is_none_or(|b| e < b.fit_error) {
            *best = Some(Fitted {
                contact,
                fit_error: e,
                fit_tosses,
            });
        }
    };
    for (k, &friction) in FIT_FRICTION.iter().enumerate() {
        for &restitution in &FIT_RESTITUTION {
            let c = Contact {
                friction,
                restitution,
                contact_hz: None,
            };
            let e = median_error(c)?;
            consider(c, e, &mut best);
        }
        progress(&format!(
            "tosses: fit {what}: friction {friction} done ({} of {})",
            k + 1,
            FIT_FRICTION.len()
        ));
    }
    let pair = best.ok_or_else(|| "no toss to fit on".to_string())?.contact;
    for &hz in &FIT_CONTACT_HZ {
        let c = Contact {
            contact_hz: Some(hz),
            ..pair
        };
        let e = median_error(c)?;
        consider(c, e, &mut best);
    }
    progress(&format!("tosses: fit {what}: contact stiffness done"));
    best.ok_or_else(|| "no toss to fit on".to_string())
}

/// `text` as TOML comment lines of at most about 92 characters.
fn comment(text: &str) -> String {
    let mut out = String::new();
    let mut line = String::from("#");
    for word in text.split_whitespace() {
        if line.len() + 1 + word.len() > 92 {
            out.push_str(&line);
            out.push('\n');
            line = String::from("#");
        }
        line.push(' ');
        line.push_str(word);
    }
    out.push_str(&line);
    out.push('\n');
    out
}

/// Writes the fits to `path`, with how they were made.
pub fn write_fit(path: &Path, f: &Fits, tosses_dir: &Path) -> Result<(), String> {
    let mut text = comment(&format!(
        "Every engine's contact values fitted to real cube tosses: written by `handblocks \
         bench tosses --fit`, read by every run of it. The procedure \
         (`handblocks_bench::tosses::fit`), on {}: {FIT_PROCEDURE}. Frictions \
         {FIT_FRICTION:?}; restitutions {FIT_RESTITUTION:?}; contact stiffness (Hz) \
         {FIT_CONTACT_HZ:?}; contact_hz = 0: the engine's own.",
        tosses_dir.display(),
    ));
    let _ = write!(text, "\n[fit]\ntosses = {}\n", f.precise.fit_tosses);
    let engines = [
        ("precise", Some(f.precise)),
        ("mujoco", f.mujoco),
        ("pybullet", f.pybullet),
    ];
    for (name, fitted) in engines {
        let Some(e) = fitted else {
            let _ = write!(
                text,
                "\n# {name}: not fitted (its Python could not be made)\n"
            );
            continue;
        };
        let _ = write!(
            text,
            "\n[{name}]\nfriction = {:?}\nrestitution = {:?}\ncontact_hz = {:?}\n\
             median_position_error_edges = {:.4}\n",
            e.contact.friction,
            e.contact.restitution,
            e.contact.contact_hz.unwrap_or(0.0),
            e.fit_error
        );
    }
    std::fs::write(path, text).map_err(|e| format!("{}: cannot write the fit: {e}", path.display()))
}

/// Reads the frozen fits. Errors name the file and the key, and say how to make it.
pub fn load_fit(path: &Path) -> Result<Fits, String> {
    let text = std::fs::read_to_string(path).map_err(|e| {
        format!(
            "{}: cannot read the contact fit: {e} (make it with `handblocks bench tosses --fit`)",
            path.display()
        )
    })?;
    let doc: toml::Table = text
        .parse()
        .map_err(|e| format!("{}: not TOML: {e}", path.display()))?;
    let get = |table: &str, key: &str, range: std::ops::RangeInclusive<f64>| {
        let v = doc
            .get(table)
            .and_then(|t| t.get(key))
            .and_then(|v| v.as_float().or_else(|| v.as_integer().map(|i| i as f64)))
            .ok_or_else(|| {
                format!(
                    "{}: `{table}.{key}`: required, a number (`handblocks bench tosses --fit` \
                     writes it)",
                    path.display()
                )
            })?;
        if range.contains(&v) {
            Ok(v)
        } else {
            Err(format!(
                "{}: `{table}.{key}` = {v}: outside {}..={}",
                path.display(),
                range.start(),
                range.end()
            ))
        }
    };
    let fit_tosses = get("fit", "tosses", 0.0..=1e9)? as usize;
    let engine = |name: &str| -> Result<Fitted, String> {
        let hz = get(name, "contact_hz", 0.0..=1e5)?;
        Ok(Fitted {
            contact: Contact {
                friction: get(name, "friction", 0.0..=100.0)?,
                restitution: get(name, "restitution", 0.0..=1.0)?,
                contact_hz: (hz > 0.0).then_some(hz),
            },
            fit_error: get(name, "median_position_error_edges", 0.0..=1e6)?,
            fit_tosses,
        })
    };
    let optional = |name: &str| -> Result<Option<Fitted>, String> {
        if doc.contains_key(name) {
            engine(name).map(Some)
        } else {
            Ok(None)
        }
    };
    Ok(Fits {
        precise: engine("precise")?,
        mujoco: optional("mujoco")?,
        pybullet: optional("pybullet")?,
    })
}

/// One tracked sample, in the world's frame (y up).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    pub t: f64,
    pub position: DVec3,
    pub rotation: DQuat,
    /// Linear velocity, m/s.
    pub velocity: DVec3,
    /// Angular velocity in the cube's own frame, rad/s (the data's, its body frame turned
    /// with the world's).
    pub spin_body: DVec3,
}

/// One toss: its samples from the first (in flight) to the last (at rest).
#[derive(Debug, Clone)]
pub struct Toss {
    pub file: PathBuf,
    pub samples: Vec<Sample>,
}

/// The data's frame (z up) to the world's (y up): -90 deg about x.
fn frame() -> DQuat {
    DQuat::from_rotation_x(-std::f64::consts::FRAC_PI_2)
}

/// Reads one toss CSV. Errors name the file, the line and the column.
pub fn load_toss(path: &Path) -> Result<Toss, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("{}: cannot read the toss: {e}", path.display()))?;
    let mut lines = text.lines();
    let header = lines.next().ok_or_else(|| {
        format!(
            "{}: empty (a toss CSV starts with its header)",
            path.display()
        )
    })?;
    let want = [
        "t_s", "x_m", "y_m", "z_m", "qw", "qx", "qy", "qz", "vx_m_s", "vy_m_s", "vz_m_s",
        "wx_rad_s", "wy_rad_s", "wz_rad_s",
    ];
    let got: Vec<&str> = header.split(',').map(str::trim).collect();
    if got != want {
        return Err(format!(
            "{}:1: header {:?}; a toss CSV's is {} (../shared/data/tosses/README.md)",
            path.display(),
            header,
            want.join(",")
        ));
    }
    let r = frame();
    let mut samples = Vec::new();
    for (i, line) in lines.enumerate() {
        let n = i + 2;
        if line.trim().is_empty() {
            continue;
        }
        let mut v = [0.0f64; 14];
        let fields: Vec<&str> = line.split(',').collect();
        if fields.len() != 14 {
            return Err(format!(
                "{}:{n}: {} fields, 14 expected",
                path.display(),
                fields.len()
            ));
        }
        for (k, f) in fields.iter().enumerate() {
            v[k] = f
                .trim()
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| {
                    format!(
                        "{}:{n}: column {} ({}) is {f:?}, not a finite number",
                        path.display(),
                        k + 1,
                        want[k]
                    )
                })?;
        }
        let q = DQuat::from_xyzw(v[5], v[6], v[7], v[4]);
        if (q.length() - 1.0).abs() > 1e-3 {
            return Err(format!(
                "{}:{n}: the quaternion has length {:.4}, not 1",
                path.display(),
                q.length()
            ));
        }
        let to_ours = |x: f64, y: f64, z: f64| DVec3::new(x, z, -y);
        samples.push(Sample {
            t: v[0],
            position: to_ours(v[1], v[2], v[3]),
            rotation: (r * q.normalize() * r.conjugate()).normalize(),
            velocity: to_ours(v[8], v[9], v[10]),
            // The body frame turns with the world's (q' = R q R^-1 keeps a body axis's
            // coordinates as R maps them), and so does a vector in it.
            spin_body: r * DVec3::new(v[11], v[12], v[13]),
        });
    }
    if samples.len() < 10 {
        return Err(format!(
            "{}: {} samples; a toss has at least 10",
            path.display(),
            samples.len()
        ));
    }
    Ok(Toss {
        file: path.to_path_buf(),
        samples,
    })
}

/// Every `*.csv` in `dir`, by name; files that cannot be read are named in the second list and
/// left out.
pub fn load_dir(dir: &Path) -> Result<(Vec<Toss>, Vec<String>), String> {
    let entries = std::fs::read_dir(dir).map_err(|e| {
        format!(
            "{}: cannot list the tosses: {e} (give --tosses DIR, a folder of toss CSVs)",
            dir.display()
        )
    })?;
    let mut files: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "csv"))
        .collect();
    files.sort();
    if files.is_empty() {
        return Err(format!("{}: no toss CSVs (*.csv) here", dir.display()));
    }
    let mut tosses = Vec::new();
    let mut refused = Vec::new();
    for f in files {
        match load_toss(&f) {
            Ok(t) => tosses.push(t),
            Err(e) => refused.push(e),
        }
    }
    Ok((tosses, refused))
}

/// The board's height in the data, measured: the median over the tosses of the last sample's
/// height less the half-width (a cube at rest lies on a face).
pub fn floor_offset(tosses: &[Toss]) -> f64 {
    let h: Vec<f64> = tosses
        .iter()
        .filter_map(|t| t.samples.last())
        .map(|s| s.position.y - HALF_WIDTH)
        .collect();
    median(&h)
}

/// The median, NaNs left out ([`quantile`]).
fn median(v: &[f64]) -> f64 {
    quantile(v, 0.5)
}

/// The cube's corners in its own frame.
fn corners() -> [DVec3; 8] {
    let h = HALF_WIDTH;
    let mut c = [DVec3::ZERO; 8];
    for (i, p) in c.iter_mut().enumerate() {
        *p = DVec3::new(
            if i & 1 == 0 { -h } else { h },
            if i & 2 == 0 { -h } else { h },
            if i & 4 == 0 { -h } else { h },
        );
    }
    c
}

/// The lowest corner's height of a cube at `position`, turned by `rotation`.
fn lowest(position: DVec3, rotation: DQuat) -> f64 {
    corners()
        .iter()
        .map(|c| (position + rotation * *c).y)
        .fold(f64::INFINITY, f64::min)
}

/// The sample at which the real cube first touches the board: its lowest corner within 3 mm
/// of it (the tracking's noise is about 1 mm), or the bottom of a hop. Samples before it are
/// the flight.
pub fn first_impact(toss: &Toss) -> usize {
    let ys: Vec<f64> = toss
        .samples
        .iter()
        .map(|s| lowest(s.position, s.rotation))
        .collect();
    (0..ys.len())
        .find(|&k| {
            ys[k] <= 3e-3 || (k > 0 && k + 1 < ys.len() && ys[k - 1] > ys[k] && ys[k + 1] > ys[k])
        })
        .unwrap_or(ys.len())
}

/// Which face of a cube turned by `rotation` is down: the body axis (+-x, +-y, +-z, as 0-5)
/// closest to the world's -y.
fn face_down(rotation: DQuat) -> usize {
    let down = rotation.conjugate() * DVec3::NEG_Y;
    let axes = [
        DVec3::X,
        DVec3::NEG_X,
        DVec3::Y,
        DVec3::NEG_Y,
        DVec3::Z,
        DVec3::NEG_Z,
    ];
    (0..6)
        .max_by(|&a, &b| down.dot(axes[a]).total_cmp(&down.dot(axes[b])))
        .unwrap_or(0)
}

/// What runs a contender.
#[derive(Debug, Clone)]
pub enum Engine {
    /// The paper model (its only setting: the tracker's rate; no contact values).
    Paper,
    /// The precise model at these settings.
    Precise(PreciseSettings),
    /// An outside engine at `substeps` per sample, with these contact values (None: the
    /// engine's own defaults).
    Outside {
        engine: OutsideEngine,
        substeps: u32,
        contact: Option<Contact>,
    },
}

/// A contender: a model at one setting.
#[derive(Debug, Clone)]
pub struct Contender {
    pub name: &'static str,
    pub setting: String,
    /// The contact values it runs with, by name (JSON: `params`).
    pub params: Vec<(&'static str, f64)>,
    pub engine: Engine,
}

/// The precise model with contact values `c` at `substeps`.
fn precise_with(c: &Contact, substeps: u32) -> PreciseSettings {
    PreciseSettings {
        friction: c.friction,
        restitution: c.restitution,
        contact_hz: c.contact_hz,
        substeps,
        ..PreciseSettings::default()
    }
}

/// The contenders: the paper model at the tracker's rate; then every engine with substeps
/// (the precise model, and each outside engine whose Python is here) at the source's nominal
/// contact values and at the values fitted to real tosses ([`fit`]), each at the precise
/// model's default substeps and at one substep (cheaper), and at the engine's own defaults.
/// Every one samples at the tracker's 148 Hz: the same rates, the same cube.
pub fn contenders(fits: &Fits, outside: &[OutsideEngine]) -> Vec<Contender> {
    let d = PreciseSettings::default();
    let mut v = vec![Contender {
        name: "paper",
        setting: format!("{RATE_HZ} Hz"),
        params: Vec::new(),
        engine: Engine::Paper,
    }];
    let mut engines: Vec<(&'static str, Option<OutsideEngine>, Option<Fitted>)> =
        vec![("precise", None, Some(fits.precise))];
    for &e in outside {
        engines.push((e.name(), Some(e), fits.of(e)));
    }
    for (name, outside, fitted) in engines {
        let make = |contact: Option<Contact>, substeps: u32, what: &str| {
            let engine = match outside {
                None => Engine::Precise(contact.map_or(d, |c| precise_with(&c, substeps))),
                Some(engine) => Engine::Outside {
                    engine,
                    substeps,
                    contact,
                },
            };
            let params = match (&engine, contact) {
                (_, Some(c)) => c.params(),
                (Engine::Precise(p), None) => {
                    vec![("friction", p.friction), ("restitution", p.restitution)]
                }
                _ => Vec::new(),
            };
            Contender {
                name,
                setting: format!("{RATE_HZ} Hz x{substeps} sub, {what}"),
                params,
                engine,
            }
        };
        v.push(make(Some(Contact::NOMINAL), d.substeps, "nominal contact"));
        v.push(make(Some(Contact::NOMINAL), 1, "nominal contact"));
        if let Some(f) = fitted {
            v.push(make(Some(f.contact), d.substeps, "fitted contact"));
            v.push(make(Some(f.contact), 1, "fitted contact"));
        }
        v.push(make(None, d.substeps, "its own defaults"));
    }
    v
}

/// The scene of one toss: the cube where the first sample has it (heights less `floor`), with
/// its velocity, stepping at the tracker's rate.
fn toss_scene(toss: &Toss, floor: f64, precise: Option<&PreciseSettings>) -> Scene {
    let first = toss.samples[0];
    let mut position = first.position;
    position.y -= floor;
    let mut world = WorldSettings {
        step_hz: RATE_HZ,
        ..WorldSettings::default()
    };
    if let Some(p) = precise {
        world.model = common::config::scene::ModelKind::Precise;
        world.precise = *p;
    }
    Scene {
        file: toss.file.clone(),
        world,
        effects: Effects::default(),
        blocks: vec![BlockSpec {
            name: "cube".into(),
            shape: ShapeSpec::Box { size: [EDGE; 3] },
            position: position.to_array(),
            rotation: first.rotation.to_array(),
            velocity: first.velocity.to_array(),
        }],
        hand: None,
        left_hand: None,
    }
}

/// A path: the cube's pose at each sample time, the first sample's as given.
pub type Path7 = Vec<(DVec3, DQuat)>;

/// One of our models' path of one toss, and the time the model's own loop took (ns), apart
/// from building the scene.
fn simulate(
    toss: &Toss,
    floor: f64,
    precise: Option<&PreciseSettings>,
) -> Result<(Path7, u64), String> {
    let scene = toss_scene(toss, floor, precise);
    let steps = toss.samples.len() - 1;
    let mut path = Vec::with_capacity(toss.samples.len());
    let up = DVec3::new(0.0, floor, 0.0);
    let mut model = Model::new(&scene).map_err(|e| e.to_string())?;
    if let Model::Precise(world) = &mut model {
        // The toss's spin, in the world's frame. The paper's free motion carries translation
        // only (R7): its cube loses the spin.
        let first = toss.samples[0];
        world.set_velocity(0, first.velocity, first.rotation * first.spin_body);
    }
    let pose = |m: &Model| {
        m.block(0)
            .map(|b| (b.position + up, b.rotation))
            .unwrap_or((DVec3::NAN, DQuat::IDENTITY))
    };
    path.push(pose(&model));
    let t0 = Instant::now();
    for _ in 0..steps {
        model.step(None);
        path.push(pose(&model));
    }
    let ns = t0.elapsed().as_nanos() as u64;
    Ok((path, ns))
}

/// Every toss's path under one contender, and the time its engine's own loop took in all (ns).
pub fn run_contender(
    c: &Contender,
    tosses: &[&Toss],
    floor: f64,
    outside: Option<&Outside>,
) -> Result<(Vec<Path7>, u64), String> {
    match &c.engine {
        Engine::Paper | Engine::Precise(_) => {
            let precise = match &c.engine {
                Engine::Precise(p) => Some(p),
                _ => None,
            };
            let mut paths = Vec::with_capacity(tosses.len());
            let mut ns = 0;
            for t in tosses {
                let (path, n) = simulate(t, floor, precise)?;
                paths.push(path);
                ns += n;
            }
            Ok((paths, ns))
        }
        Engine::Outside {
            engine,
            substeps,
            contact,
        } => outside
            .ok_or_else(|| format!("{}: its Python is not here", engine.name()))?
            .run(*engine, *substeps, contact.as_ref(), tosses, floor),
    }
}

/// The outside engines' driver: a Python with `mujoco` and `pybullet`, and the script.
#[derive(Debug, Clone)]
pub struct Outside {
    pub python: PathBuf,
    pub script: PathBuf,
    /// Where a run's job paths go (under the run's `--out`).
    pub scratch: PathBuf,
    /// Each engine's version and its binding's floor (ns per call, taken off its time), as
    /// the script reports them.
    pub versions: std::cell::RefCell<Vec<(String, String, f64)>>,
}

/// The engines' versions the bench installs (pinned: a figure names what made it).
pub const OUTSIDE_PACKAGES: [&str; 2] = ["mujoco==4.0.1", "pybullet==3.2.7"];

impl Outside {
    /// Finds or makes the Python: `python` if given, else `repo/target/toss-engines` (a venv
    /// the bench makes and fills from the package index the first time, as tests/run does for
    /// its tools). Errors say what failed and how to run without it.
    pub fn prepare(
        repo: &Path,
        python: Option<&Path>,
        scratch: &Path,
        progress: &mut dyn FnMut(&str),
    ) -> Result<Outside, String> {
        let script = repo.join("bench/python/toss_engines.py");
        if !script.is_file() {
            return Err(format!(
                "{}: the engines' driver is missing",
                script.display()
            ));
        }
        let imports = |py: &Path| {
            std::process::Command::new(py)
                .args(["-c", "import mujoco, pybullet, numpy"])
                .stdout(std::process::Stdio::null())
                .stderr(std::process::Stdio::null())
                .status()
                .is_ok_and(|s| s.success())
        };
        let py = match python {
            Some(p) => {
                if !imports(p) {
                    return Err(format!(
                        "{}: cannot import mujoco, pybullet and numpy (pip install {})",
                        p.display(),
                        OUTSIDE_PACKAGES.join(" ")
                    ));
                }
                p.to_path_buf()
            }
            None => {
                let venv = repo.join("target/toss-engines");
                let py = venv.join("bin/python");
                if !imports(&py) {
                    progress(&format!(
                        "tosses: making {} with {} (once; needs the package index)",
                        venv.display(),
                        OUTSIDE_PACKAGES.join(" ")
                    ));
                    let _ = std::fs::remove_dir_all(&venv);
                    let run = |cmd: &mut std::process::Command| {
                        cmd.stdout(std::process::Stdio::null())
                            .status()
                            .map_err(|e| e.to_string())
                            .and_then(|s| {
                                if s.success() {
                                    Ok(())
                                } else {
                                    Err(format!("exit {s}"))
                                }
                            })
                    };
                    run(std::process::Command::new("python3")
                        .args(["-m", "venv"])
                        .arg(&venv))
                    .map_err(|e| format!("python3 -m venv {}: {e}", venv.display()))?;
                    run(std::process::Command::new(&py)
                        .args(["-m", "pip", "install", "-q"])
                        .args(OUTSIDE_PACKAGES))
                    .map_err(|e| {
                        format!(
                            "{}: pip install {}: {e} (needs the package index; or give \
                             --python PATH, a Python that has them)",
                            venv.display(),
                            OUTSIDE_PACKAGES.join(" ")
                        )
                    })?;
                    if !imports(&py) {
                        return Err(format!(
                            "{}: made, but it cannot import mujoco, pybullet and numpy",
                            venv.display()
                        ));
                    }
                }
                py
            }
        };
        std::fs::create_dir_all(scratch)
            .map_err(|e| format!("{}: cannot create: {e}", scratch.display()))?;
        Ok(Outside {
            python: py,
            script,
            scratch: scratch.to_path_buf(),
            versions: std::cell::RefCell::new(Vec::new()),
        })
    }

    /// Runs `tosses` in `engine`; the paths in the world's frame, and the nanoseconds of the
    /// engine's own loop as the script timed them.
    pub fn run(
        &self,
        engine: OutsideEngine,
        substeps: u32,
        contact: Option<&Contact>,
        tosses: &[&Toss],
        floor: f64,
    ) -> Result<(Vec<Path7>, u64), String> {
        let r = frame();
        // The world (y up) to the data's frame (z up), the board at z = 0.
        let to_data = |p: DVec3| DVec3::new(p.x, -p.z, p.y);
        let paths_file = self.scratch.join(format!(
            "paths-{}-{}.bin",
            engine.name(),
            std::process::id()
        ));
        let job = json!({
            "engine": engine.name(),
            "rate_hz": RATE_HZ,
            "substeps": substeps,
            "half_width": HALF_WIDTH,
            "mass": MASS,
            "gravity": 9.81,
            "params": match contact {
                None => json!({"own_defaults": true}),
                Some(c) => json!({"friction": c.friction, "restitution": c.restitution, "contact_hz": c.contact_hz}),
            },
            "paths": paths_file,
            "tosses": tosses.iter().map(|t| {
                let s = t.samples[0];
                let q = r.conjugate() * s.rotation * r;
                json!({
                    "steps": t.samples.len() - 1,
                    "position": to_data(s.position - DVec3::new(0.0, floor, 0.0)).to_array(),
                    "quaternion": [q.w, q.x, q.y, q.z],
                    "velocity": to_data(s.velocity).to_array(),
                    "spin_body": (r.conjugate() * s.spin_body).to_array(),
                })
            }).collect::<Vec<_>>(),
        });
        let what = format!("{} ({})", self.script.display(), engine.name());
        let mut child = std::process::Command::new(&self.python)
            .arg(&self.script)
            .stdin(std::process::Stdio::piped())
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .map_err(|e| format!("{what}: cannot start {}: {e}", self.python.display()))?;
        if let Some(mut stdin) = child.stdin.take() {
            use std::io::Write as _;
            stdin
                .write_all(job.to_string().as_bytes())
                .map_err(|e| format!("{what}: cannot send the job: {e}"))?;
        }
        let out = child
            .wait_with_output()
            .map_err(|e| format!("{what}: {e}"))?;
        if !out.status.success() {
            return Err(format!(
                "{what}: {}: {}",
                out.status,
                String::from_utf8_lossy(&out.stderr).trim()
            ));
        }
        let reply: Value = String::from_utf8_lossy(&out.stdout)
            .lines()
            .rev()
            .find_map(|l| serde_json::from_str(l).ok())
            .ok_or_else(|| format!("{what}: no JSON reply on its output"))?;
        let ns = reply["engine_ns"]
            .as_u64()
            .ok_or_else(|| format!("{what}: the reply has no engine_ns: {reply}"))?;
        if let Some(v) = reply["version"].as_str() {
            let floor = reply["binding_floor_ns"].as_f64().unwrap_or(f64::NAN);
            let mut versions = self.versions.borrow_mut();
            if !versions.iter().any(|(e, _, _)| e == engine.name()) {
                versions.push((engine.name().to_string(), v.to_string(), floor));
            }
        }
        let bytes =
            std::fs::read(&paths_file).map_err(|e| format!("{}: {e}", paths_file.display()))?;
        let _ = std::fs::remove_file(&paths_file);
        let want: usize = tosses.iter().map(|t| t.samples.len() * 7 * 8).sum();
        if bytes.len() != want {
            return Err(format!(
                "{what}: {} bytes of paths, {want} expected",
                bytes.len()
            ));
        }
        let values: Vec<f64> = bytes
            .chunks_exact(8)
            .map(|b| f64::from_le_bytes(b.try_into().unwrap_or([0; 8])))
            .collect();
        let mut at = 0;
        let mut paths = Vec::with_capacity(tosses.len());
        for t in tosses {
            let mut path = Vec::with_capacity(t.samples.len());
            for _ in 0..t.samples.len() {
                let v = &values[at..at + 7];
                at += 7;
                let position = DVec3::new(v[0], v[2] + floor, -v[1]);
                let q = DQuat::from_xyzw(v[4], v[5], v[6], v[3]);
                path.push((position, (r * q * r.conjugate()).normalize()));
            }
            paths.push(path);
        }
        Ok((paths, ns))
    }
}

/// How one contender did on one toss.
#[derive(Debug, Clone, Copy, Default)]
pub struct TossScore {
    /// Mean distance between the simulated and the real centre over the samples after the
    /// first, in cube edges.
    pub position_error: f64,
    /// The same over the flight (before the first impact) and after it.
    pub position_error_flight: f64,
    pub position_error_after: f64,
    /// Mean angle between the simulated and the real orientation, deg.
    pub rotation_error_deg: f64,
    /// Distance between the final centres, m.
    pub final_position_error_m: f64,
    /// Whether it rests on the same face as the real cube.
    pub same_face: bool,
}

/// How `path` (one pose per sample of `toss`) did against the real track.
pub fn score(toss: &Toss, path: &[(DVec3, DQuat)]) -> TossScore {
    let impact = first_impact(toss).max(1);
    let mut all = (0.0, 0usize);
    let mut flight = (0.0, 0usize);
    let mut after = (0.0, 0usize);
    let mut angle = 0.0;
    for (k, (s, p)) in toss.samples.iter().zip(path).enumerate().skip(1) {
        let d = (p.0 - s.position).length() / EDGE;
        all = (all.0 + d, all.1 + 1);
        if k < impact {
            flight = (flight.0 + d, flight.1 + 1);
        } else {
            after = (after.0 + d, after.1 + 1);
        }
        angle += s.rotation.angle_between(p.1).to_degrees();
    }
    let mean = |(s, n): (f64, usize)| if n > 0 { s / n as f64 } else { f64::NAN };
    let (last, end) = (toss.samples[toss.samples.len() - 1], path[path.len() - 1]);
    TossScore {
        position_error: mean(all),
        position_error_flight: mean(flight),
        position_error_after: mean(after),
        rotation_error_deg: angle / all.1.max(1) as f64,
        final_position_error_m: (end.0 - last.position).length(),
        same_face: face_down(end.1) == face_down(last.rotation),
    }
}

/// One contender's result over every toss.
#[derive(Debug, Clone)]
pub struct Row {
    pub contender: Contender,
    pub per_toss: Vec<(PathBuf, TossScore)>,
    /// The first round's paths (every round computes the same: the engines are deterministic).
    pub paths: Vec<Path7>,
    /// The engine's own time per simulated second, us: the median over the whole runs of
    /// each run's median over its rounds.
    pub us_per_sim_s: f64,
    /// Each round's figure, the runs one after another.
    pub rounds_us_per_sim_s: Vec<f64>,
    /// Each whole run's median (the run-to-run spread).
    pub runs_us_per_sim_s: Vec<f64>,
}

impl Row {
    fn stat(&self, get: impl Fn(&TossScore) -> f64, q: f64) -> f64 {
        let v: Vec<f64> = self.per_toss.iter().map(|(_, s)| get(s)).collect();
        quantile(&v, q)
    }
    /// The median over the tosses the fit did not use ([`in_fit`]).
    fn held_out_median(&self, get: impl Fn(&TossScore) -> f64) -> f64 {
        let v: Vec<f64> = self
            .per_toss
            .iter()
            .enumerate()
            .filter(|(i, _)| !in_fit(*i))
            .map(|(_, (_, s))| get(s))
            .collect();
        median(&v)
    }
    fn same_face_pct(&self) -> f64 {
        let n = self.per_toss.len().max(1) as f64;
        100.0 * self.per_toss.iter().filter(|(_, s)| s.same_face).count() as f64 / n
    }
}

/// Runs every contender on every toss, ROUNDS times (the order of the contenders rotated each
/// round, so that none is always timed first), scoring the first round's paths.
pub fn measure(
    tosses: &[Toss],
    floor: f64,
    cs: &[Contender],
    outside: Option<&Outside>,
    progress: &mut dyn FnMut(&str),
) -> Result<Vec<Row>, String> {
    let all: Vec<&Toss> = tosses.iter().collect();
    let sim_s: f64 = tosses
        .iter()
        .map(|t| (t.samples.len() - 1) as f64 / RATE_HZ)
        .sum();
    let mut rows: Vec<Row> = cs
        .iter()
        .map(|c| Row {
            contender: c.clone(),
            per_toss: Vec::new(),
            paths: Vec::new(),
            us_per_sim_s: f64::NAN,
            rounds_us_per_sim_s: Vec::new(),
            runs_us_per_sim_s: Vec::new(),
        })
        .collect();
    for round in 0..ROUNDS {
        for k in 0..cs.len() {
            let i = (k + round) % cs.len();
            let (paths, ns) = run_contender(&cs[i], &all, floor, outside)
                .map_err(|e| format!("{} ({}): {e}", cs[i].name, cs[i].setting))?;
            if round == 0 {
                rows[i].per_toss = tosses
                    .iter()
                    .zip(&paths)
                    .map(|(t, p)| (t.file.clone(), score(t, p)))
                    .collect();
                rows[i].paths = paths;
            }
            rows[i]
                .rounds_us_per_sim_s
                .push(ns as f64 / 1e3 / sim_s.max(1e-9));
        }
        progress(&format!("tosses: round {} of {ROUNDS} done", round + 1));
    }
    for r in &mut rows {
        r.us_per_sim_s = median(&r.rounds_us_per_sim_s);
        r.runs_us_per_sim_s = vec![r.us_per_sim_s];
    }
    Ok(rows)
}

/// [`measure`] `runs` times over (the paths and scores of the first; they are the same every
/// run), each row's time the median of the runs' medians.
pub fn measure_runs(
    tosses: &[Toss],
    floor: f64,
    cs: &[Contender],
    outside: Option<&Outside>,
    runs: usize,
    progress: &mut dyn FnMut(&str),
) -> Result<Vec<Row>, String> {
    let mut rows = measure(tosses, floor, cs, outside, progress)?;
    for k in 1..runs.max(1) {
        progress(&format!("tosses: whole run {} of {runs}", k + 1));
        let again = measure(tosses, floor, cs, outside, progress)?;
        for (r, a) in rows.iter_mut().zip(again) {
            r.rounds_us_per_sim_s.extend(a.rounds_us_per_sim_s);
            r.runs_us_per_sim_s.push(a.us_per_sim_s);
        }
    }
    for r in &mut rows {
        r.us_per_sim_s = median(&r.runs_us_per_sim_s);
    }
    Ok(rows)
}

/// Fits every engine here ([`fit`]) on the fit's tosses, each at the precise model's default
/// substeps.
pub fn fit_all(
    tosses: &[Toss],
    floor: f64,
    outside: Option<&Outside>,
    progress: &mut dyn FnMut(&str),
) -> Result<Fits, String> {
    let chosen: Vec<&Toss> = tosses
        .iter()
        .enumerate()
        .filter(|(i, _)| in_fit(*i))
        .map(|(_, t)| t)
        .collect();
    let substeps = PreciseSettings::default().substeps;
    let mut fit_engine = |name: &'static str, engine: &dyn Fn(Contact) -> Engine| {
        let mut median_error = |contact: Contact| -> Result<f64, String> {
            let c = Contender {
                name,
                setting: String::new(),
                params: Vec::new(),
                engine: engine(contact),
            };
            let (paths, _) = run_contender(&c, &chosen, floor, outside)?;
            let errors: Vec<f64> = chosen
                .iter()
                .zip(&paths)
                .map(|(t, p)| score(t, p).position_error)
                .collect();
            Ok(median(&errors))
        };
        fit(name, chosen.len(), &mut median_error, progress)
    };
    let precise = fit_engine("precise", &|c| Engine::Precise(precise_with(&c, substeps)))?;
    let mut outside_fit = |e: OutsideEngine| -> Result<Option<Fitted>, String> {
        if outside.is_none() {
            return Ok(None);
        }
        fit_engine(e.name(), &|c| Engine::Outside {
            engine: e,
            substeps,
            contact: Some(c),
        })
        .map(Some)
    };
    Ok(Fits {
        precise,
        mujoco: outside_fit(OutsideEngine::MuJoCo)?,
        pybullet: outside_fit(OutsideEngine::PyBullet)?,
    })
}

/// What the page and the JSON say beside the rows.
pub struct RunFacts<'a> {
    pub tosses: usize,
    pub floor: f64,
    pub refused: &'a [String],
    pub fits: &'a Fits,
    /// Outside engines left out, and why (their Python could not be made).
    pub left_out: Option<String>,
    /// Each outside engine's version and binding floor (ns per call).
    pub versions: Vec<(String, String, f64)>,
}

fn fitted_json(f: &Option<Fitted>) -> Value {
    match f {
        None => Value::Null,
        Some(f) => json!({
            "friction": f.contact.friction,
            "restitution": f.contact.restitution,
            "contact_hz": f.contact.contact_hz,
            "fit_tosses": f.fit_tosses,
            "fit_median_position_error": num(f.fit_error),
        }),
    }
}

pub fn to_json(rows: &[Row], facts: &RunFacts) -> Value {
    json!({
        "fit": {
            "procedure": FIT_PROCEDURE,
            "friction_grid": FIT_FRICTION,
            "restitution_grid": FIT_RESTITUTION,
            "contact_hz_grid": FIT_CONTACT_HZ,
            "precise": fitted_json(&Some(facts.fits.precise)),
            "mujoco": fitted_json(&facts.fits.mujoco),
            "pybullet": fitted_json(&facts.fits.pybullet),
        },
        "engines": rows.iter().map(|r| json!({
            "name": r.contender.name,
            "setting": r.contender.setting,
            "params": r.contender.params.iter().map(|(k, v)| (k.to_string(), json!(v))).collect::<serde_json::Map<_, _>>(),
            "us_per_sim_s": num(r.us_per_sim_s),
            "us_per_sim_s_rounds": r.rounds_us_per_sim_s.iter().map(|v| num(*v)).collect::<Vec<_>>(),
            "us_per_sim_s_runs": r.runs_us_per_sim_s.iter().map(|v| num(*v)).collect::<Vec<_>>(),
            "position_error": {"median": num(r.stat(|s| s.position_error, 0.5)), "p90": num(r.stat(|s| s.position_error, 0.9)), "median_held_out": num(r.held_out_median(|s| s.position_error))},
            "position_error_flight": {"median": num(r.stat(|s| s.position_error_flight, 0.5)), "p90": num(r.stat(|s| s.position_error_flight, 0.9))},
            "position_error_after_impact": {"median": num(r.stat(|s| s.position_error_after, 0.5)), "p90": num(r.stat(|s| s.position_error_after, 0.9))},
            "rotation_error_deg": {"median": num(r.stat(|s| s.rotation_error_deg, 0.5)), "p90": num(r.stat(|s| s.rotation_error_deg, 0.9))},
            "final_position_error_m": {"median": num(r.stat(|s| s.final_position_error_m, 0.5)), "p90": num(r.stat(|s| s.final_position_error_m, 0.9))},
            "same_face_pct": num(r.same_face_pct()),
            "per_toss": r.per_toss.iter().map(|(f, s)| json!({
                "file": f.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default(),
                "position_error": num(s.position_error),
                "position_error_flight": num(s.position_error_flight),
                "position_error_after_impact": num(s.position_error_after),
                "rotation_error_deg": num(s.rotation_error_deg),
                "final_position_error_m": num(s.final_position_error_m),
                "same_face": s.same_face,
            })).collect::<Vec<_>>(),
        })).collect::<Vec<_>>(),
        "goals": goals(rows).iter().map(|g| json!({"goal": g.goal, "met": g.met, "figures": g.figures})).collect::<Vec<_>>(),
        "pareto": pareto(rows).iter().map(|r| json!({"name": r.contender.name, "setting": r.contender.setting, "us_per_sim_s": num(r.us_per_sim_s), "position_error_median": num(r.stat(|s| s.position_error, 0.5))})).collect::<Vec<_>>(),
        "tosses": facts.tosses,
        "refused": facts.refused,
        "floor_offset_m": facts.floor,
        "rate_hz": RATE_HZ,
        "cube": {"edge_m": EDGE, "mass_kg": MASS},
        "nominal": {"friction": NOMINAL_FRICTION, "restitution": NOMINAL_RESTITUTION},
        "outside_versions": facts.versions.iter().map(|(e, v, _)| (e.clone(), json!(v))).collect::<serde_json::Map<_, _>>(),
        "outside_binding_floor_ns": facts.versions.iter().map(|(e, _, f)| (e.clone(), num(*f))).collect::<serde_json::Map<_, _>>(),
        "outside_left_out": facts.left_out,
    })
}

/// The Pareto front across every engine and setting: the rows no other row beats in both
/// time per simulated second and median position error, cheapest first.
pub fn pareto(rows: &[Row]) -> Vec<&Row> {
    let xy: Vec<(f64, f64)> = rows
        .iter()
        .map(|r| (r.us_per_sim_s, r.stat(|s| s.position_error, 0.5)))
        .collect();
    let mut front: Vec<&Row> = crate::plot::pareto_front(&xy)
        .into_iter()
        .map(|i| &rows[i])
        .collect();
    front.sort_by(|a, b| a.us_per_sim_s.total_cmp(&b.us_per_sim_s));
    front
}

/// One of the goals, judged on this run.
pub struct Goal {
    pub goal: &'static str,
    pub met: bool,
    pub figures: String,
}

/// The two goals, judged on the rows: the precise model's best median error no worse
/// than the better outside engine's best, at less time per simulated second; the paper model
/// at least 20x cheaper per simulated second than the cheapest outside engine setting.
pub fn goals(rows: &[Row]) -> Vec<Goal> {
    let med = |r: &Row| r.stat(|s| s.position_error, 0.5);
    let best = |name: &str| {
        rows.iter()
            .filter(|r| r.contender.name == name)
            .min_by(|a, b| med(a).total_cmp(&med(b)))
    };
    let outside: Vec<&Row> = rows
        .iter()
        .filter(|r| matches!(r.contender.engine, Engine::Outside { .. }))
        .collect();
    let mut v = Vec::new();
    let better_outside = OutsideEngine::ALL
        .iter()
        .filter_map(|e| best(e.name()))
        .min_by(|a, b| med(a).total_cmp(&med(b)));
    if let (Some(p), Some(o)) = (best("precise"), better_outside) {
        v.push(Goal {
            goal: "the precise model's median position error no worse than the better outside engine's, at less time per simulated second",
            met: med(p) <= med(o) && p.us_per_sim_s < o.us_per_sim_s,
            figures: format!(
                "precise ({}) {:.3} edges at {:.0} us per simulated s; {} ({}) {:.3} edges at {:.0} us",
                p.contender.setting,
                med(p),
                p.us_per_sim_s,
                o.contender.name,
                o.contender.setting,
                med(o),
                o.us_per_sim_s
            ),
        });
    }
    let cheapest = outside
        .iter()
        .min_by(|a, b| a.us_per_sim_s.total_cmp(&b.us_per_sim_s));
    if let (Some(p), Some(o)) = (best("paper"), cheapest) {
        let ratio = o.us_per_sim_s / p.us_per_sim_s;
        v.push(Goal {
            goal: "the paper model at least 20x cheaper per simulated second than the cheapest outside engine",
            met: ratio >= 20.0,
            figures: format!(
                "{ratio:.1}x: paper {:.0} us per simulated s, {} ({}) {:.0} us; the paper model's median error {:.3} edges",
                p.us_per_sim_s,
                o.contender.name,
                o.contender.setting,
                o.us_per_sim_s,
                med(p)
            ),
        });
    }
    v
}

const WHAT: &str = "How far each engine is from a real block: real tosses of a 10.5 cm acrylic \
cube tracked at 148 Hz (the ContactNets data, ../shared/data/tosses), each simulated from its \
first tracked state (position, orientation, velocity and, for every engine but the paper \
model, spin) at the tracker's rate and scored against the rest of its track, by the paper \
model, the precise model (rapier3d), and two engines nobody here wrote, MuJoCo and PyBullet \
(driven from Python, `bench/python/toss_engines.py`, in a venv the bench makes under target/). \
**How to read it:** position error is the mean over a toss's samples of the distance between \
the simulated and the real centre, in cube edges (10.48 cm); rotation error the mean angle \
between the two orientations; final error where the two cubes end; same face whether they \
rest on the same face. Median and p90 over the tosses. Time is each engine's own loop per \
simulated second: in each whole run the median of interleaved rounds (every contender once \
per round, the order rotated), and on the page the median over the whole runs, with their \
spread [min, max over the runs]; our models' step loop (the scene built \
outside it); for MuJoCo and PyBullet one call per sample (`mj_step(nstep)`, `stepSimulation` \
with `numSubSteps`: the substeps inside the engine), the pose read outside the timed span, \
less per call the binding's floor measured in the same run (a timed call that does no work), \
so that Python's share is not counted as the engine's.";

pub fn markdown(rows: &[Row], facts: &RunFacts, p: &Provenance, seconds: f64) -> String {
    let mut s = page::head(
        "Real cube tosses: how far each engine is from a real block",
        WHAT,
        p,
    );
    let _ = writeln!(
        s,
        "{} tosses ({} refused); the board {:.1} mm below the data's z = 0 (measured: the \
         median last height less the half-width). The run took {seconds:.0} s.{}\n",
        facts.tosses,
        facts.refused.len(),
        -facts.floor * 1e3,
        if facts.versions.is_empty() {
            String::new()
        } else {
            format!(
                " Outside engines: {} (the binding's floor, a timed call that does no work, \
                 taken off each step call).",
                facts
                    .versions
                    .iter()
                    .map(|(e, v, f)| format!("{e} {v}, floor {f:.0} ns per call"))
                    .collect::<Vec<_>>()
                    .join("; ")
            )
        }
    );
    if let Some(why) = &facts.left_out {
        let _ = writeln!(
            s,
            "**MuJoCo and PyBullet are not in this run:** {why}. Their rows and the goals that \
             need them are missing.\n"
        );
    }
    let _ = writeln!(
        s,
        "**The fit** (`config/tosses-fit.toml`; `handblocks bench tosses --fit` makes it \
         again): {FIT_PROCEDURE}. Frictions {FIT_FRICTION:?}, restitutions \
         {FIT_RESTITUTION:?}, contact stiffness {FIT_CONTACT_HZ:?} Hz. The column *held out* \
         is the median over the tosses the fit never saw. The paper model has no contact \
         values to fit.\n"
    );
    s.push_str("| engine | friction | restitution | contact stiffness | fit tosses | fit median error (edges) |\n|---|---:|---:|---:|---:|---:|\n");
    for (name, f) in [
        ("precise", Some(facts.fits.precise)),
        ("mujoco", facts.fits.mujoco),
        ("pybullet", facts.fits.pybullet),
    ] {
        match f {
            Some(f) => {
                let _ = writeln!(
                    s,
                    "| {name} | {} | {} | {} | {} | {:.3} |",
                    f.contact.friction,
                    f.contact.restitution,
                    f.contact
                        .contact_hz
                        .map_or("its own".to_string(), |hz| format!("{hz} Hz")),
                    f.fit_tosses,
                    f.fit_error
                );
            }
            None => {
                let _ = writeln!(s, "| {name} | not fitted | | | | |");
            }
        }
    }
    s.push('\n');
    s.push_str(
        "| engine | setting | position error median / p90 (edges) | held out | in flight | after the first impact | rotation error median / p90 (deg) | final error median / p90 (m) | same face | us per simulated s: median of the runs [min, max over runs] |\n|---|---|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for r in rows {
        let pair = |get: fn(&TossScore) -> f64, d: usize| {
            format!("{:.d$} / {:.d$}", r.stat(get, 0.5), r.stat(get, 0.9), d = d)
        };
        let lo = r
            .runs_us_per_sim_s
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min);
        let hi = r
            .runs_us_per_sim_s
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max);
        let _ = writeln!(
            s,
            "| {} | {} | {} | {:.3} | {} | {} | {} | {} | {:.0} % | {:.0} [{lo:.0}, {hi:.0}] |",
            r.contender.name,
            r.contender.setting,
            pair(|t| t.position_error, 3),
            r.held_out_median(|t| t.position_error),
            pair(|t| t.position_error_flight, 3),
            pair(|t| t.position_error_after, 3),
            pair(|t| t.rotation_error_deg, 1),
            pair(|t| t.final_position_error_m, 3),
            r.same_face_pct(),
            r.us_per_sim_s,
        );
    }
    s.push('\n');
    let _ = writeln!(
        s,
        "**The Pareto front per simulated second** (no other engine or setting both cheaper \
         and more accurate), cheapest first: {}.\n",
        pareto(rows)
            .iter()
            .map(|r| format!(
                "{} ({}) {:.3} edges at {:.0} us",
                r.contender.name,
                r.contender.setting,
                r.stat(|s| s.position_error, 0.5),
                r.us_per_sim_s
            ))
            .collect::<Vec<_>>()
            .join("; ")
    );
    let g = goals(rows);
    if !g.is_empty() {
        s.push_str("## The goals (issue 42)\n\n");
        for g in &g {
            let _ = writeln!(
                s,
                "- **{}:** {}. {}",
                if g.met { "met" } else { "not met" },
                g.goal,
                g.figures
            );
        }
        s.push('\n');
    }
    s.push_str(
        "The paper model carries no spin and drops its inertia on impact (R7, R8): its flight \
         error is what a spinless ballistic path costs, its error after the first impact what R8 \
         costs (the cube stops where it lands).\n\n",
    );
    s.push_str(&page::figure(
        "position error against time per simulated second, one colour per engine, one point per \
         setting (the table names them); and the height of G over time, real and simulated \
         (each engine at its best setting), for the first toss and those at the median and the \
         p90 of the precise model's error",
        "tosses.png",
    ));
    if !facts.refused.is_empty() {
        s.push_str("\n## Refused files\n\n");
        for r in facts.refused {
            let _ = writeln!(s, "- {r}");
        }
    }
    s
}

/// A toss to draw: its name, the real heights over time, and each contender's.
pub struct Drawn {
    pub title: String,
    pub real: Vec<(f64, f64)>,
    pub simulated: Vec<(String, Vec<(f64, f64)>)>,
}

/// The tosses the picture shows: those at the median and the p90 of the precise model's best
/// setting's position error, and the first toss; each engine's best setting's height of G over
/// time beside the real one.
pub fn drawn(rows: &[Row], tosses: &[Toss], floor: f64) -> Vec<Drawn> {
    let med = |r: &Row| r.stat(|s| s.position_error, 0.5);
    let mut best: Vec<&Row> = Vec::new();
    for r in rows {
        match best
            .iter_mut()
            .find(|b| b.contender.name == r.contender.name)
        {
            Some(b) => {
                if med(r) < med(b) {
                    *b = r;
                }
            }
            None => best.push(r),
        }
    }
    let Some(reference) = best.iter().find(|r| r.contender.name == "precise") else {
        return Vec::new();
    };
    let mut by_error: Vec<(f64, usize)> = reference
        .per_toss
        .iter()
        .enumerate()
        .map(|(i, (_, s))| (s.position_error, i))
        .filter(|(e, _)| e.is_finite())
        .collect();
    by_error.sort_by(|a, b| a.0.total_cmp(&b.0));
    if by_error.is_empty() {
        return Vec::new();
    }
    let at = |q: f64| by_error[((by_error.len() - 1) as f64 * q).round() as usize];
    let picks = [
        (0usize, "the first toss"),
        (at(0.5).1, "the median toss"),
        (at(0.9).1, "the p90 toss"),
    ];
    let mut out = Vec::new();
    for (i, why) in picks {
        let Some(toss) = tosses.get(i) else { continue };
        let name = toss
            .file
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let real = toss
            .samples
            .iter()
            .map(|s| (s.t, s.position.y - floor))
            .collect();
        let simulated = best
            .iter()
            .filter_map(|r| {
                let path = r.paths.get(i)?;
                let heights = toss
                    .samples
                    .iter()
                    .zip(path)
                    .map(|(s, p)| (s.t, p.0.y - floor))
                    .collect();
                // The engine's name alone: one label, one colour in every panel.
                Some((r.contender.name.to_string(), heights))
            })
            .collect();
        out.push(Drawn {
            title: format!("{name}, {why}: height of G"),
            real,
            simulated,
        });
    }
    out
}

pub fn figure(rows: &[Row], drawn: &[Drawn]) -> Figure {
    // One series per engine (its settings as points): four colours, not one per setting, so
    // that the palette never wraps and each engine reads the same in every panel.
    let mut series: Vec<Series> = Vec::new();
    for r in rows {
        let point = (r.us_per_sim_s, r.stat(|s| s.position_error, 0.5));
        if !(point.0.is_finite() && point.1.is_finite()) {
            continue;
        }
        match series.iter_mut().find(|s| s.label == r.contender.name) {
            Some(s) => s.points.push(point),
            None => series.push(Series {
                label: r.contender.name.to_string(),
                points: vec![point],
            }),
        }
    }
    let marked = pareto(rows)
        .iter()
        .map(|r| (r.us_per_sim_s, r.stat(|s| s.position_error, 0.5)))
        .collect();
    let mut panels = vec![Panel {
        title: "median position error against cost, every setting (Pareto front ringed)".into(),
        x: Axis::log("us per simulated second"),
        y: Axis::log("position error (cube edges)").with_floor(1e-3),
        series,
        marked,
        join: Join::No,
    }];
    for d in drawn {
        let mut series = vec![Series {
            label: "real".into(),
            points: d.real.clone(),
        }];
        series.extend(d.simulated.iter().map(|(label, points)| Series {
            label: label.clone(),
            points: points.clone(),
        }));
        panels.push(Panel {
            title: d.title.clone(),
            x: Axis::linear("time (s)"),
            y: Axis::linear("height of G (m)"),
            series,
            marked: Vec::new(),
            join: Join::Curve,
        });
    }
    Figure {
        panels,
        columns: 2,
        panel_width: 560,
        panel_height: 400,
        column_weights: Vec::new(),
    }
}

/// The bench: loads the tosses, makes (or finds) the outside engines' Python, fits when asked,
/// runs every contender, writes tosses.json, tosses.md and tosses.png under `out_dir`.
pub fn run(b: &TossesBench) -> Result<Vec<Row>, Box<dyn std::error::Error>> {
    let started = Instant::now();
    let (mut tosses, refused) = load_dir(&b.tosses_dir)?;
    if tosses.is_empty() {
        return Err(format!(
            "{}: no toss could be read: {}",
            b.tosses_dir.display(),
            refused.join("; ")
        )
        .into());
    }
    if b.quick {
        tosses.truncate(QUICK_TOSSES);
    }
    let floor = floor_offset(&tosses);
    std::fs::create_dir_all(&b.out_dir)
        .map_err(|e| format!("{}: cannot create: {e}", b.out_dir.display()))?;
    let mut progress = |line: &str| eprintln!("{line}");
    let (outside, left_out) = match Outside::prepare(
        &b.repo,
        b.python.as_deref(),
        &std::env::temp_dir().join(format!("hb-tosses-{}", std::process::id())),
        &mut progress,
    ) {
        Ok(o) => (Some(o), None),
        Err(e) => {
            eprintln!("tosses: warning: MuJoCo and PyBullet left out: {e}");
            (None, Some(e))
        }
    };
    let fits = if b.fit {
        if b.quick {
            return Err("--fit fits on every fourth of all the tosses; not with --quick".into());
        }
        let f = fit_all(&tosses, floor, outside.as_ref(), &mut progress)?;
        write_fit(&b.fit_file, &f, &b.tosses_dir)?;
        eprintln!("tosses: wrote {}", b.fit_file.display());
        f
    } else {
        load_fit(&b.fit_file)?
    };
    eprintln!(
        "tosses: {} from {} ({} refused); the board at {:.1} mm",
        tosses.len(),
        b.tosses_dir.display(),
        refused.len(),
        floor * 1e3
    );
    let engines: &[OutsideEngine] = if outside.is_some() {
        &OutsideEngine::ALL
    } else {
        &[]
    };
    let cs = contenders(&fits, engines);
    let rows = measure_runs(&tosses, floor, &cs, outside.as_ref(), b.runs, &mut progress)?;
    if let Some(o) = &outside {
        let _ = std::fs::remove_dir(&o.scratch);
    }
    let facts = RunFacts {
        tosses: tosses.len(),
        floor,
        refused: &refused,
        fits: &fits,
        left_out,
        versions: outside
            .as_ref()
            .map(|o| o.versions.borrow().clone())
            .unwrap_or_default(),
    };
    let p = Provenance::of_this_run(b.quick, &b.out_dir);
    let json_file = b.out_dir.join("tosses.json");
    std::fs::write(
        &json_file,
        serde_json::to_string_pretty(&to_json(&rows, &facts))? + "\n",
    )
    .map_err(|e| format!("{}: {e}", json_file.display()))?;
    let md = b.out_dir.join("tosses.md");
    let seconds = started.elapsed().as_secs_f64();
    std::fs::write(&md, markdown(&rows, &facts, &p, seconds))
        .map_err(|e| format!("{}: {e}", md.display()))?;
    let png = b.out_dir.join("tosses.png");
    figure(&rows, &drawn(&rows, &tosses, floor)).write_png(&png)?;
    for r in &rows {
        eprintln!(
            "tosses: {} ({}): position error median {:.3} edges, p90 {:.3}; {:.0} us per simulated s",
            r.contender.name,
            r.contender.setting,
            r.stat(|s| s.position_error, 0.5),
            r.stat(|s| s.position_error, 0.9),
            r.us_per_sim_s
        );
    }
    for g in goals(&rows) {
        eprintln!(
            "tosses: goal {}: {} ({})",
            if g.met { "met" } else { "NOT met" },
            g.goal,
            g.figures
        );
    }
    eprintln!(
        "tosses: wrote {}, tosses.md, tosses.png",
        json_file.display()
    );
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(name: &str, text: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("hb-tosses-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join(name);
        std::fs::write(&f, text).unwrap();
        f
    }

    const HEADER: &str =
        "t_s,x_m,y_m,z_m,qw,qx,qy,qz,vx_m_s,vy_m_s,vz_m_s,wx_rad_s,wy_rad_s,wz_rad_s\n";

    #[test]
    fn a_toss_is_read_into_the_worlds_frame_and_bad_files_are_named() {
        let mut text = HEADER.to_string();
        for k in 0..12 {
            let _ = writeln!(
                text,
                "{},0.1,0.2,{},1,0,0,0,0.5,1.0,-2.0,0,0,3",
                k as f64 / RATE_HZ,
                0.3 - 0.01 * k as f64
            );
        }
        let t = load_toss(&write("good.csv", &text)).unwrap();
        assert_eq!(t.samples.len(), 12);
        // (x, y, z) of the data is (x, z, -y) here.
        let s = t.samples[0];
        assert!((s.position - DVec3::new(0.1, 0.3, -0.2)).length() < 1e-12);
        assert!((s.velocity - DVec3::new(0.5, -2.0, -1.0)).length() < 1e-12);
        // The data's up (z) is the world's up (y), and a spin about the data's z (in the
        // cube's frame, here lined up with the data's) is a spin about the world's y.
        assert!((s.rotation * DVec3::Y - DVec3::Y).length() < 1e-12);
        assert!((s.rotation * s.spin_body - DVec3::new(0.0, 3.0, 0.0)).length() < 1e-12);

        let bad = text.replacen("0.5,1.0", "0.5,nan", 1);
        let e = load_toss(&write("bad.csv", &bad)).unwrap_err();
        assert!(e.contains("bad.csv:2") && e.contains("vy_m_s"), "{e}");
        let e = load_toss(&write("head.csv", "t,x\n")).unwrap_err();
        assert!(e.contains("head.csv:1") && e.contains("header"), "{e}");
    }

    #[test]
    fn the_frozen_fit_is_read_and_a_bad_one_names_its_key() {
        let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/tosses-fit.toml");
        let f = load_fit(&repo).unwrap_or_else(|e| panic!("{e}"));
        for e in [Some(f.precise), f.mujoco, f.pybullet]
            .into_iter()
            .flatten()
        {
            assert!(FIT_FRICTION.contains(&e.contact.friction));
            assert!(FIT_RESTITUTION.contains(&e.contact.restitution));
            assert!(e
                .contact
                .contact_hz
                .is_none_or(|hz| FIT_CONTACT_HZ.contains(&hz)));
        }
        let bad = write(
            "fit.toml",
            "[fit]\ntosses = 100\n[precise]\nfriction = 0.2\nrestitution = 3\ncontact_hz = 0\n\
             median_position_error_edges = 0.1\n",
        );
        let e = load_fit(&bad).unwrap_err();
        assert!(
            e.contains("precise.restitution") && e.contains("0..=1"),
            "{e}"
        );
        let e = load_fit(Path::new("/nowhere/fit.toml")).unwrap_err();
        assert!(e.contains("--fit"), "{e}");
        // Written and read back, the same values.
        let out = write("again.toml", "");
        write_fit(&out, &f, Path::new("tosses")).unwrap();
        assert_eq!(load_fit(&out).unwrap(), f);
    }

    #[test]
    fn the_fit_tries_the_grid_then_the_stiffness_and_keeps_the_lowest() {
        // A made-up error surface, lowest at friction 0.3, restitution 0.1, 60 Hz.
        let mut tried = Vec::new();
        let mut error = |c: Contact| {
            tried.push(c);
            Ok((c.friction - 0.3).abs()
                + (c.restitution - 0.1).abs()
                + c.contact_hz.map_or(0.05, |hz| (hz - 60.0).abs() / 1000.0))
        };
        let f = fit("test", 7, &mut error, &mut |_| {}).unwrap();
        assert_eq!(
            tried.len(),
            FIT_FRICTION.len() * FIT_RESTITUTION.len() + FIT_CONTACT_HZ.len()
        );
        assert_eq!(
            f.contact,
            Contact {
                friction: 0.3,
                restitution: 0.1,
                contact_hz: Some(60.0)
            }
        );
        assert_eq!(f.fit_tosses, 7);
    }

    #[test]
    fn the_face_down_and_the_first_impact_are_read_from_the_pose() {
        assert_eq!(face_down(DQuat::IDENTITY), 3);
        // A quarter turn about z takes the body's -x to the world's -y.
        assert_eq!(
            face_down(DQuat::from_rotation_z(std::f64::consts::FRAC_PI_2)),
            1
        );
        let falling = |y: f64| Sample {
            t: 0.0,
            position: DVec3::new(0.0, y, 0.0),
            rotation: DQuat::IDENTITY,
            velocity: DVec3::ZERO,
            spin_body: DVec3::ZERO,
        };
        let toss = Toss {
            file: PathBuf::from("t"),
            samples: [0.3, 0.2, 0.1, 0.06, 0.09, 0.07, 0.0524, 0.0524]
                .iter()
                .map(|&y| falling(y))
                .collect(),
        };
        // The hop's bottom at 0.06 (7.6 mm up) is the first impact.
        assert_eq!(first_impact(&toss), 3);
    }
}
