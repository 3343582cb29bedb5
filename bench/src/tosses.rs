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
}

/// The precise model's contact values fitted to real tosses ([`fit`]), as frozen in the
/// repository's `config/tosses-fit.toml`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fitted {
    pub friction: f64,
    pub restitution: f64,
    /// The fit's score: the median position error over the fit's tosses, cube edges.
    pub fit_error: f64,
    /// How many tosses the fit used.
    pub fit_tosses: usize,
}

/// The fit's tosses: every fourth of the folder by name (index 0, 4, 8, ...), so that the
/// other three quarters are held out and a fit that only learned its own tosses shows.
pub fn in_fit(index: usize) -> bool {
    index.is_multiple_of(4)
}

/// The grid the fit tries: friction x restitution, the source's nominal values among them.
pub const FIT_FRICTION: [f64; 10] = [0.05, 0.1, 0.15, 0.18, 0.22, 0.3, 0.4, 0.6, 0.8, 1.0];
pub const FIT_RESTITUTION: [f64; 8] = [0.0, 0.05, 0.1, 0.125, 0.15, 0.2, 0.3, 0.4];

/// Fits the precise model's friction and restitution to the fit's tosses ([`in_fit`]): every
/// pair of [`FIT_FRICTION`] x [`FIT_RESTITUTION`] at the model's default substeps, scored by
/// the median position error over those tosses; the lowest wins (the first on a tie). A grid,
/// not a descent: the error is not smooth in these values (a cube lands on an edge or a face),
/// and a grid says what it tried.
pub fn fit(tosses: &[Toss], floor: f64, progress: &mut dyn FnMut(&str)) -> Result<Fitted, String> {
    let chosen: Vec<&Toss> = tosses
        .iter()
        .enumerate()
        .filter(|(i, _)| in_fit(*i))
        .map(|(_, t)| t)
        .collect();
    let mut best: Option<Fitted> = None;
    for (k, &friction) in FIT_FRICTION.iter().enumerate() {
        for &restitution in &FIT_RESTITUTION {
            let c = Contender {
                name: "precise",
                setting: String::new(),
                params: Vec::new(),
                precise: Some(PreciseSettings {
                    friction,
                    restitution,
                    ..PreciseSettings::default()
                }),
            };
            let mut errors = Vec::with_capacity(chosen.len());
            for t in &chosen {
                let (path, _) = simulate(t, floor, &c)?;
                errors.push(score(t, &path).position_error);
            }
            let e = median(&errors);
            if best.is_none_or(|b| e < b.fit_error) {
                best = Some(Fitted {
                    friction,
                    restitution,
                    fit_error: e,
                    fit_tosses: chosen.len(),
                });
            }
        }
        progress(&format!(
            "tosses: fit: friction {friction} done ({} of {})",
            k + 1,
            FIT_FRICTION.len()
        ));
    }
    best.ok_or_else(|| "no toss to fit on".to_string())
}

/// Writes the fit to `path`, with how it was made.
pub fn write_fit(path: &Path, f: &Fitted, tosses_dir: &Path) -> Result<(), String> {
    let text = format!(
        "# The precise model's contact values fitted to real cube tosses: written by\n\
         # `handblocks bench tosses --fit`, read by every run of it. The procedure\n\
         # (`handblocks_bench::tosses::fit`): every fourth toss of {} by name\n\
         # ({} tosses; the rest are held out), every friction of {:?}\n\
         # x every restitution of {:?}, at the precise model's\n\
         # default substeps; the pair with the lowest median position error wins.\n\
         [precise]\nfriction = {:?}\nrestitution = {:?}\n\n[fit]\ntosses = {}\nmedian_position_error_edges = {:.4}\n",
        tosses_dir.display(),
        f.fit_tosses,
        FIT_FRICTION,
        FIT_RESTITUTION,
        f.friction,
        f.restitution,
        f.fit_tosses,
        f.fit_error
    );
    std::fs::write(path, text).map_err(|e| format!("{}: cannot write the fit: {e}", path.display()))
}

/// Reads the frozen fit. Errors name the file and the key, and say how to make it.
pub fn load_fit(path: &Path) -> Result<Fitted, String> {
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
            .ok_or_else(|| format!("{}: `{table}.{key}`: required, a number", path.display()))?;
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
    Ok(Fitted {
        friction: get("precise", "friction", 0.0..=100.0)?,
        restitution: get("precise", "restitution", 0.0..=1.0)?,
        fit_error: get("fit", "median_position_error_edges", 0.0..=1e6)?,
        fit_tosses: get("fit", "tosses", 0.0..=1e9)? as usize,
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

/// A contender: a model at one setting.
#[derive(Debug, Clone)]
pub struct Contender {
    pub name: &'static str,
    pub setting: String,
    /// The contact values it runs with, by name (JSON: `params`).
    pub params: Vec<(&'static str, f64)>,
    /// The precise model's settings; None: the paper model.
    pub precise: Option<PreciseSettings>,
}

/// The contenders of this part: the paper model (its only setting: the tracker's rate; it has
/// no contact values to fit), and the precise model at the source's nominal contact values (its
/// default substeps, and one substep: cheaper), at the values fitted to real tosses ([`fit`])
/// and at its own defaults (the paper's "perfect friction", no bounce).
pub fn contenders(fitted: &Fitted) -> Vec<Contender> {
    let d = PreciseSettings::default();
    let fit = PreciseSettings {
        friction: fitted.friction,
        restitution: fitted.restitution,
        ..d
    };
    let nominal = PreciseSettings {
        friction: NOMINAL_FRICTION,
        restitution: NOMINAL_RESTITUTION,
        ..d
    };
    vec![
        Contender {
            name: "paper",
            setting: format!("{RATE_HZ} Hz"),
            params: Vec::new(),
            precise: None,
        },
        Contender {
            name: "precise",
            setting: format!("{RATE_HZ} Hz x{} sub, nominal contact", nominal.substeps),
            params: vec![
                ("friction", nominal.friction),
                ("restitution", nominal.restitution),
            ],
            precise: Some(nominal),
        },
        Contender {
            name: "precise",
            setting: format!("{RATE_HZ} Hz x1 sub, nominal contact"),
            params: vec![
                ("friction", nominal.friction),
                ("restitution", nominal.restitution),
            ],
            precise: Some(PreciseSettings {
                substeps: 1,
                ..nominal
            }),
        },
        Contender {
            name: "precise",
            setting: format!("{RATE_HZ} Hz x{} sub, fitted contact", fit.substeps),
            params: vec![("friction", fit.friction), ("restitution", fit.restitution)],
            precise: Some(fit),
        },
        Contender {
            name: "precise",
            setting: format!("{RATE_HZ} Hz x{} sub, its own defaults", d.substeps),
            params: vec![("friction", d.friction), ("restitution", d.restitution)],
            precise: Some(d),
        },
    ]
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

/// One contender's path of one toss: the cube's pose at each sample time (the first sample's
/// as given), and the time the model's own loop took (ns), apart from building the scene.
fn simulate(toss: &Toss, floor: f64, c: &Contender) -> Result<(Vec<(DVec3, DQuat)>, u64), String> {
    let scene = toss_scene(toss, floor, c.precise.as_ref());
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

fn score(toss: &Toss, path: &[(DVec3, DQuat)]) -> TossScore {
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
    /// Median over the rounds of the model's own time per simulated second, us.
    pub us_per_sim_s: f64,
    /// Each round's figure (the spread).
    pub rounds_us_per_sim_s: Vec<f64>,
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
/// round, so that none is always timed first), scoring the first round's paths (the models are
/// deterministic: every round computes the same).
pub fn measure(
    tosses: &[Toss],
    floor: f64,
    fitted: &Fitted,
    progress: &mut dyn FnMut(&str),
) -> Result<Vec<Row>, String> {
    let cs = contenders(fitted);
    let sim_s: f64 = tosses
        .iter()
        .map(|t| (t.samples.len() - 1) as f64 / RATE_HZ)
        .sum();
    let mut rows: Vec<Row> = cs
        .iter()
        .map(|c| Row {
            contender: c.clone(),
            per_toss: Vec::new(),
            us_per_sim_s: f64::NAN,
            rounds_us_per_sim_s: Vec::new(),
        })
        .collect();
    for round in 0..ROUNDS {
        for k in 0..cs.len() {
            let i = (k + round) % cs.len();
            let mut ns = 0u64;
            for toss in tosses {
                let (path, t) = simulate(toss, floor, &cs[i])
                    .map_err(|e| format!("{} ({}): {e}", cs[i].name, cs[i].setting))?;
                ns += t;
                if round == 0 {
                    rows[i]
                        .per_toss
                        .push((toss.file.clone(), score(toss, &path)));
                }
            }
            rows[i]
                .rounds_us_per_sim_s
                .push(ns as f64 / 1e3 / sim_s.max(1e-9));
        }
        progress(&format!("tosses: round {} of {ROUNDS} done", round + 1));
    }
    for r in &mut rows {
        r.us_per_sim_s = median(&r.rounds_us_per_sim_s);
    }
    Ok(rows)
}

pub fn to_json(
    rows: &[Row],
    tosses: usize,
    floor: f64,
    refused: &[String],
    fitted: &Fitted,
) -> Value {
    json!({
        "fit": {
            "friction": fitted.friction,
            "restitution": fitted.restitution,
            "fit_tosses": fitted.fit_tosses,
            "fit_median_position_error": num(fitted.fit_error),
            "procedure": "every fourth toss by name (the rest held out); a grid of friction x restitution at the precise model's default substeps; the lowest median position error",
            "friction_grid": FIT_FRICTION,
            "restitution_grid": FIT_RESTITUTION,
        },
        "engines": rows.iter().map(|r| json!({
            "name": r.contender.name,
            "setting": r.contender.setting,
            "params": r.contender.params.iter().map(|(k, v)| (k.to_string(), json!(v))).collect::<serde_json::Map<_, _>>(),
            "us_per_sim_s": num(r.us_per_sim_s),
            "us_per_sim_s_rounds": r.rounds_us_per_sim_s.iter().map(|v| num(*v)).collect::<Vec<_>>(),
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
        "tosses": tosses,
        "refused": refused,
        "floor_offset_m": floor,
        "rate_hz": RATE_HZ,
        "cube": {"edge_m": EDGE, "mass_kg": 0.37},
        "nominal": {"friction": NOMINAL_FRICTION, "restitution": NOMINAL_RESTITUTION},
        "not_yet": ["MuJoCo", "PyBullet"],
    })
}

const WHAT: &str = "How far each model is from a real block: real tosses of a 10.5 cm acrylic \
cube tracked at 148 Hz (the ContactNets data, ../shared/data/tosses), each simulated from its \
first tracked state (position, orientation, velocity and, for the precise model, spin) at the \
tracker's rate and scored against the rest of its track. **How to read it:** position error is \
the mean over a toss's samples of the distance between the simulated and the real centre, in \
cube edges (10.48 cm); rotation error the mean angle between the two orientations; final error \
where the two cubes end; same face whether they rest on the same face. Median and p90 over the \
tosses; time is the model's own loop per simulated second (the scene built outside it), the \
median of interleaved rounds. **Not yet here (issue 42):** MuJoCo and PyBullet: these figures \
compare our two models with a real cube, not yet with the engines people use.";

pub fn markdown(
    rows: &[Row],
    tosses: usize,
    floor: f64,
    refused: &[String],
    fitted: &Fitted,
    p: &Provenance,
    seconds: f64,
) -> String {
    let mut s = page::head(
        "Real cube tosses: how far each model is from a real block",
        WHAT,
        p,
    );
    let _ = writeln!(
        s,
        "{tosses} tosses ({} refused); the board {:.1} mm below the data's z = 0 (measured: the \
         median last height less the half-width). The run took {seconds:.0} s.\n",
        refused.len(),
        -floor * 1e3
    );
    let _ = writeln!(
        s,
        "**The fit** (`config/tosses-fit.toml`, `handblocks bench tosses --fit` makes it again): \
         friction {} and restitution {} for the precise model, the pair of a grid of {} \
         frictions ({:?}) x {} restitutions ({:?}) at its default substeps with the lowest \
         median position error over every fourth toss by name ({} tosses, {:.3} edges); the \
         column *held out* is the median over the other tosses, which the fit never saw. The \
         paper model has no contact values to fit.\n",
        fitted.friction,
        fitted.restitution,
        FIT_FRICTION.len(),
        FIT_FRICTION,
        FIT_RESTITUTION.len(),
        FIT_RESTITUTION,
        fitted.fit_tosses,
        fitted.fit_error
    );
    s.push_str(
        "| model | setting | position error median / p90 (edges) | held out | in flight | after the first impact | rotation error median / p90 (deg) | final error median / p90 (m) | same face | us per simulated s (rounds) |\n|---|---|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for r in rows {
        let pair = |get: fn(&TossScore) -> f64, d: usize| {
            format!("{:.d$} / {:.d$}", r.stat(get, 0.5), r.stat(get, 0.9), d = d)
        };
        let rounds: Vec<String> = r
            .rounds_us_per_sim_s
            .iter()
            .map(|v| format!("{v:.0}"))
            .collect();
        let _ = writeln!(
            s,
            "| {} | {} | {} | {:.3} | {} | {} | {} | {} | {:.0} % | {:.0} ({}) |",
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
            rounds.join(", ")
        );
    }
    s.push('\n');
    s.push_str(
        "The paper model carries no spin and drops its inertia on impact (R7, R8): its flight \
         error is what a spinless ballistic path costs, its error after the first impact what R8 \
         costs (the cube stops where it lands).\n\n",
    );
    s.push_str(&page::figure(
        "position error against time per simulated second, one point per model and setting; \
         and the height of G over time, real and simulated, for the first toss and those at the \
         median and the p90 of the precise model's error",
        "tosses.png",
    ));
    if !refused.is_empty() {
        s.push_str("\n## Refused files\n\n");
        for r in refused {
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

/// The tosses the picture shows: those at the median and the p90 of the first precise
/// contender's position error, and the first toss; each contender's height of G over time
/// beside the real one.
pub fn drawn(rows: &[Row], tosses: &[Toss], floor: f64) -> Vec<Drawn> {
    let Some(reference) = rows.iter().find(|r| r.contender.precise.is_some()) else {
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
        let simulated = rows
            .iter()
            .filter_map(|r| {
                let (path, _) = simulate(toss, floor, &r.contender).ok()?;
                let heights = toss
                    .samples
                    .iter()
                    .zip(&path)
                    .map(|(s, p)| (s.t, p.0.y - floor))
                    .collect();
                Some((
                    format!("{} ({})", r.contender.name, r.contender.setting),
                    heights,
                ))
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
    let series = rows
        .iter()
        .map(|r| Series {
            label: format!("{} ({})", r.contender.name, r.contender.setting),
            points: vec![(r.us_per_sim_s, r.stat(|s| s.position_error, 0.5))]
                .into_iter()
                .filter(|p| p.0.is_finite() && p.1.is_finite())
                .collect(),
        })
        .filter(|s| !s.points.is_empty())
        .collect();
    let mut panels = vec![Panel {
        title: "median position error against cost".into(),
        x: Axis::log("us per simulated second"),
        y: Axis::log("position error (cube edges)").with_floor(1e-3),
        series,
        marked: Vec::new(),
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
        panel_width: 520,
        panel_height: 360,
        column_weights: Vec::new(),
    }
}

/// The bench: loads the tosses, runs every contender, writes tosses.json, tosses.md and
/// tosses.png under `out_dir`.
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
    let fitted = if b.fit {
        if b.quick {
            return Err("--fit fits on every fourth of all the tosses; not with --quick".into());
        }
        let f = fit(&tosses, floor, &mut |line| eprintln!("{line}"))?;
        write_fit(&b.fit_file, &f, &b.tosses_dir)?;
        eprintln!(
            "tosses: fitted friction {}, restitution {} (median error {:.3} edges over {} tosses); wrote {}",
            f.friction,
            f.restitution,
            f.fit_error,
            f.fit_tosses,
            b.fit_file.display()
        );
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
    let rows = measure(&tosses, floor, &fitted, &mut |line| eprintln!("{line}"))?;
    std::fs::create_dir_all(&b.out_dir)
        .map_err(|e| format!("{}: cannot create: {e}", b.out_dir.display()))?;
    let p = Provenance::of_this_run(b.quick, &b.out_dir);
    let json_file = b.out_dir.join("tosses.json");
    std::fs::write(
        &json_file,
        serde_json::to_string_pretty(&to_json(&rows, tosses.len(), floor, &refused, &fitted))?
            + "\n",
    )
    .map_err(|e| format!("{}: {e}", json_file.display()))?;
    let md = b.out_dir.join("tosses.md");
    let seconds = started.elapsed().as_secs_f64();
    std::fs::write(
        &md,
        markdown(&rows, tosses.len(), floor, &refused, &fitted, &p, seconds),
    )
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
        assert!(FIT_FRICTION.contains(&f.friction) && FIT_RESTITUTION.contains(&f.restitution));
        let bad = write(
            "fit.toml",
            "[precise]\nfriction = 0.2\nrestitution = 3\n[fit]\ntosses = 100\n\
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
        assert_eq!(load_fit(&out).unwrap().friction, f.friction);
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
