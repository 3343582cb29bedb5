//! Scene files: the world's settings, the effects it simulates, its blocks and the scripted
//! hand (docs/design.md, "Effects"). This module checks the file's form and ranges; geometric
//! checks (a block inside another or below the floor) belong to the stepper, which knows the
//! shapes.

use std::path::{Path, PathBuf};

use toml::Value;

use super::catalog::{FileKind, Spec};
use super::reader::{parse_file, span, vector, Reader};
use super::session::Override;
use super::ConfigError;
use crate::samples::{MAX_FINGERS, MAX_FINGER_POINTS, MAX_SCENE_BLOCKS};

/// Positions are limited to 100 km from the origin: beyond that f64 metres still work, but no
/// hand reaches there and a typo is more likely than intent.
const POSITION_RANGE: std::ops::RangeInclusive<f64> = -1.0e5..=1.0e5;

/// A whole scene file.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// The file it was read from (for messages).
    pub file: PathBuf,
    pub world: WorldSettings,
    pub effects: Effects,
    pub blocks: Vec<BlockSpec>,
    /// The scripted hand; None when the scene has no `[hand]`. With a `[left_hand]` beside
    /// it, this is the right hand (docs/model.md "Two hands": slot 0).
    pub hand: Option<HandScript>,
    /// `[left_hand]`: a second scripted hand, the left (slot 1), in the same form as `[hand]`.
    /// Through the hand model it is the right hand mirrored in its wrist's x (the thumb on the
    /// wrist's +x side); bare `fingers` are taken as given. Only beside a `[hand]`, shaped the
    /// same way (both bare or both through the hand model), and only in the paper model.
    pub left_hand: Option<HandScript>,
}

/// R3's grasp angle in the paper, degrees (`[world] grasp_angle`'s default).
pub const GRASP_ANGLE_DEG: f64 = 120.0;

/// `[world]`.
#[derive(Debug, Clone, PartialEq)]
pub struct WorldSettings {
    /// Fixed steps per second (dt = 1 / step_hz).
    pub step_hz: f64,
    /// g in m/s^2 (docs/model.md g_step = (0, -g dt^2, 0)).
    pub gravity: f64,
    pub model: ModelKind,
    /// docs/model.md tolerances.
    pub contact_eps: f64,
    pub hull_eps: f64,
    pub angle_eps: f64,
    /// R3: the largest angle between pseudo-normals above which the hand grasps, radians.
    pub grasp_angle: f64,
    /// R3 [extension]: below this angle a grasp ends; equal to grasp_angle in the paper.
    pub release_angle: f64,
    /// R13 [extension]: steps averaged for the throw velocity; 1 in the paper.
    pub throw_window: u32,
    /// `[precise]`: the rigid-body reference's own settings. They live beside `model` (not
    /// in `Scene`) because they only mean something together with it, and so that scenes built
    /// in code with `WorldSettings::default()` get them too.
    pub precise: PreciseSettings,
    /// `[world] hands`: which rules a hand grasps and throws by (docs/model.md "Tracked
    /// hands"): the paper's (R3, R13), the default, or the tracked rules T1-T3 beside them.
    pub hands: HandRules,
    /// `[tracked]`: the tracked rules' own settings (read whatever `hands` says, as
    /// `[precise]` is, so that `--set tracked.KEY=...` can be given before `hands`).
    pub tracked: TrackedSettings,
    /// Each `[[block]]`'s own `color = [r, g, b]` (0 to 1, sRGB), in scene order (lattice
    /// copies share their table's); None where the table has none (the renderer then takes it
    /// from the name, `config::colors::block_colors`). Only the views read it. It
    /// lives here rather than in `BlockSpec` or `Scene` because scenes are also built in code
    /// (benchmarks, tests) by struct literal; `..WorldSettings::default()` gives them none.
    pub block_colors: Vec<Option<[f32; 3]>>,
}

impl Default for WorldSettings {
    fn default() -> Self {
        WorldSettings {
            step_hz: 120.0,
            gravity: 9.81,
            model: ModelKind::Paper,
            contact_eps: 1e-4,
            hull_eps: 1e-6,
            angle_eps: 1e-9,
            grasp_angle: GRASP_ANGLE_DEG.to_radians(),
            release_angle: GRASP_ANGLE_DEG.to_radians(),
            throw_window: 1,
            precise: PreciseSettings::default(),
            hands: HandRules::Paper,
            tracked: TrackedSettings::default(),
            block_colors: Vec::new(),
        }
    }
}

/// `[world] hands`: the rules a hand grasps, holds and throws by.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HandRules {
    /// R3 decides every step afresh, R13 throws with the last step's displacement: the paper.
    Paper,
    /// docs/model.md T1-T3: a grasp holds while the grip stays within `grip_margin` of the
    /// block, through tracking gaps up to `gap_hold`, and throws with a fitted velocity.
    Tracked,
}

impl HandRules {
    pub fn name(self) -> &'static str {
        match self {
            HandRules::Paper => "paper",
            HandRules::Tracked => "tracked",
        }
    }
}

/// `[tracked]`: the numbers of docs/model.md's tracked-hand rules, each with why.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackedSettings {
    /// T1: once grasped, a block stays grasped until the hand's grip (the check points whose
    /// contacts made R3's grasp) opens by this much (metres). Trackers jitter by 2-11 mm (sd);
    /// a grip must open by more than that before it lets go.
    pub grip_margin: f64,
    /// T1: the grip must be found open at every step for this long (seconds) before it lets
    /// go. A tracker's noise is new in every sample: one sample's outlier (a point 13 mm off,
    /// 2.6 sd of 5 mm) can open a grip by the margin for the steps it shapes, two samples in a
    /// row almost never; a hand that opens stays open. 30 ms is three samples at 90 Hz.
    pub grip_open_time: f64,
    /// T2: a hand that is not tracked keeps what it holds, unmoved by new contacts, for up to
    /// this long (seconds); then it lets go with no throw.
    pub gap_hold: f64,
    /// T3: the throw's velocity is the least-squares line through the held block's path from
    /// this long before the grip left the block up to the release (seconds).
    pub throw_fit_window: f64,
}

impl Default for TrackedSettings {
    fn default() -> Self {
        TrackedSettings {
            grip_margin: 0.02,
            grip_open_time: 0.03,
            gap_hold: 0.25,
            throw_fit_window: 0.075,
        }
    }
}

/// `[precise]`: the settings of the rigid-body reference (rapier3d). The model steps at the
/// scene's `step_hz` (the same timeline as the paper model); these say how finely each step is
/// solved. rapier's own defaults (4 substeps at 60 Hz, 30 Hz soft contacts, Simplified
/// friction, sleeping) sink a stack by ~0.55 mm per body and put a slowly tipping block to
/// sleep before it falls, so a reference cannot use them (../shared/notes/accuracy.md). The
/// defaults here, measured by `handblocks bench accuracy`: at the default 120 Hz, 8 substeps
/// with contacts as stiff as a substep allows sink a 6-cube tower by 0.54 mm in all (the sink
/// falls with the square of the substep) and get every static tipping decision right.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PreciseSettings {
    /// Solver substeps per step (rapier's `num_solver_iterations`): the substep is
    /// dt / substeps.
    pub substeps: u32,
    /// Solver (PGS) iterations per substep (rapier's `num_internal_pgs_iterations`).
    pub solver_iterations: u32,
    /// Contact stiffness as the natural frequency of the contact spring, Hz. None: Box2D's
    /// rule, 0.125 / substep dt, the stiffest a substep resolves stably (at rapier's default
    /// 60 Hz x 4 that is rapier's own 30 Hz).
    pub contact_hz: Option<f64>,
    /// Damping ratio of the contact spring (rapier's default 10 is heavily overdamped: soft).
    pub contact_damping: f64,
    /// Coulomb friction coefficient, blocks and floor ("perfect friction" is a high one).
    pub friction: f64,
    /// Restitution, blocks and floor: 0 (the paper's blocks do not bounce, R8) unless a scene
    /// asks (`handblocks bench tosses` runs a real acrylic cube's, 0.125 nominal).
    pub restitution: f64,
    /// Continuous collision detection (no tunnelling, docs/model.md R12's counterpart).
    pub ccd: bool,
    /// Whether still bodies may sleep (rapier: below 0.05 m/s and 0.5 rad/s for 0.5 s). Off by
    /// default: a block released 2 degrees past its tipping edge turns slower than that for
    /// its first half second, and sleeping would freeze it upright.
    pub sleep: bool,
    /// The penetration rapier leaves uncorrected, metres (its default 5 mm is 5% of a 10 cm
    /// block: a final pose cannot be within 1 mm with it).
    pub allowed_penetration: f64,
    /// Radius of a bare check-point hand's fingers (a hand with no hand model has none), m.
    pub bare_finger_radius: f64,
}

impl Default for PreciseSettings {
    fn default() -> Self {
        PreciseSettings {
            substeps: 8,
            solver_iterations: 2,
            contact_hz: None,
            contact_damping: 1.0,
            friction: 2.0,
            restitution: 0.0,
            ccd: true,
            sleep: false,
            allowed_penetration: 1e-4,
            bare_finger_radius: 0.002,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModelKind {
    /// docs/model.md's rules R1-R14: the product.
    Paper,
    /// The rigid-body reference (rapier3d).
    Precise,
}

/// `[effects]`: what the stepper simulates; an effect that is off costs nothing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Effects {
    /// R7 gravity.
    pub gravity: bool,
    /// R7, R13 inertia.
    pub inertia: bool,
    pub floor: FloorEffect,
    pub hand: HandEffect,
    /// R10.
    pub carry: bool,
    pub stacking: Stacking,
}

impl Default for Effects {
    fn default() -> Self {
        Effects {
            gravity: true,
            inertia: true,
            floor: FloorEffect::Tipping,
            hand: HandEffect::Grasp,
            carry: true,
            stacking: Stacking::Paper,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FloorEffect {
    None,
    /// R8 only.
    Rest,
    /// R8 and R9.
    Tipping,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HandEffect {
    None,
    /// R4, R6.
    Push,
    /// R4-R6.
    Grasp,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stacking {
    /// R11.
    Paper,
    /// R14 [extension].
    Supported,
}

/// `[[block]]`.
#[derive(Debug, Clone, PartialEq)]
pub struct BlockSpec {
    pub name: String,
    pub shape: ShapeSpec,
    /// Where the centre of gravity starts, metres.
    pub position: [f64; 3],
    /// Unit quaternion `[x, y, z, w]` (normalised on load).
    pub rotation: [f64; 4],
    /// Initial inertia, m/s (docs/model.md v is this times dt).
    pub velocity: [f64; 3],
}

/// A block's shape in its own frame.
#[derive(Debug, Clone, PartialEq)]
pub enum ShapeSpec {
    /// Full extents x, y, z.
    Box { size: [f64; 3] },
    /// A triangular prism filling half the `size` box: the right triangle with legs along +x
    /// and +y, extruded along z.
    Wedge { size: [f64; 3] },
    /// The corner tetrahedron of the `size` box: its origin corner and the three corners one
    /// edge away along x, y and z.
    Tetra { size: [f64; 3] },
    /// The convex hull of these vertices.
    Hull { vertices: Vec<[f64; 3]> },
}

/// `[hand]`: keyframes, linearly interpolated (rotation by slerp); after the last key the
/// hand holds still.
#[derive(Debug, Clone, PartialEq)]
pub struct HandScript {
    pub keys: Vec<HandKey>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct HandKey {
    /// Seconds from the start; strictly increasing.
    pub t: f64,
    pub wrist: [f64; 3],
    pub wrist_rotation: [f64; 4],
    pub pose: HandPoseSpec,
}

/// How a key shapes the fingers. Every key of a scene uses the same kind.
#[derive(Debug, Clone, PartialEq)]
pub enum HandPoseSpec {
    /// 0 open .. 1 fist, through the hand model.
    Grip(f64),
    /// Glove angles in radians, CyberGlove sensor order (18 or 22), through the hand model.
    Angles(Vec<f64>),
    /// Bare check points per finger, knuckle to tip, in the wrist's frame: no hand model, no
    /// palm. Every key has the same number of fingers and points per finger.
    Fingers(Vec<Vec<[f64; 3]>>),
}

impl Scene {
    /// Reads and checks a scene file.
    pub fn load(file: &Path) -> Result<Scene, ConfigError> {
        Scene::from_table(file, &parse_file(file)?)
    }

    /// Reads a scene file with `--set KEY=VALUE` overrides applied (`world.hands=tracked`,
    /// `tracked.grip_margin=0.03`), each checked exactly as the file's own keys are; an error
    /// about an overridden key says it came from `--set`.
    pub fn load_with(file: &Path, overrides: &[Override]) -> Result<Scene, ConfigError> {
        let mut table = parse_file(file)?;
        for o in overrides {
            o.apply(file, &mut table)?;
        }
        Scene::from_table(file, &table).map_err(|e| e.given_with_set(overrides))
    }

    /// Checks a scene already parsed as TOML (Python's `handblocks.simulate` given a dict):
    /// `file` names it in errors, and relative paths in it are taken from its folder.
    pub fn from_table(file: &Path, table: &toml::Table) -> Result<Scene, ConfigError> {
        let root = Reader::root(file, FileKind::Scene, table);
        let (blocks, block_colors) = blocks(&root)?;
        let scene = Scene {
            file: file.to_path_buf(),
            world: WorldSettings {
                precise: precise(root.table("precise")?)?,
                tracked: tracked(root.table("tracked")?)?,
                block_colors,
                ..world(root.table("world")?)?
            },
            effects: effects(root.table("effects")?)?,
            blocks,
            hand: match root.table("hand")? {
                Some(h) => Some(hand(h, "hand")?),
                None => None,
            },
            left_hand: match root.table("left_hand")? {
                Some(h) => Some(hand(h, "left_hand")?),
                None => None,
            },
        };
        if scene.left_hand.is_some() {
            two_hands(&root, &scene)?;
        }
        root.finish()?;
        Ok(scene)
    }
}

fn world(r: Option<Reader>) -> Result<WorldSettings, ConfigError> {
    let d = WorldSettings::default();
    let Some(r) = r else { return Ok(d) };
    let grasp_deg = r
        .f64_in("grasp_angle", Some(GRASP_ANGLE_DEG), 0.0..=180.0)?
        .unwrap_or(GRASP_ANGLE_DEG);
    // Its default is grasp_angle's value: given after the getter, which notes no default.
    let release_deg = r
        .f64_in("release_angle", None, 0.0..=180.0)?
        .unwrap_or(grasp_deg);
    if release_deg > grasp_deg {
        return Err(r.err(
            "release_angle",
            format!("{release_deg} is above grasp_angle {grasp_deg}; allowed: 0 to grasp_angle"),
        ));
    }
    let w = WorldSettings {
        step_hz: r
            .f64_in("step_hz", Some(d.step_hz), 1.0..=100_000.0)?
            .unwrap_or(d.step_hz),
        gravity: r
            .f64_in("gravity", Some(d.gravity), 0.0..=1000.0)?
            .unwrap_or(d.gravity),
        model: match r.choice("model", &["paper", "precise"])? {
            "precise" => ModelKind::Precise,
            _ => ModelKind::Paper,
        },
        contact_eps: r
            .f64_in("contact_eps", Some(d.contact_eps), 1e-9..=0.1)?
            .unwrap_or(d.contact_eps),
        hull_eps: r
            .f64_in("hull_eps", Some(d.hull_eps), 1e-12..=0.1)?
            .unwrap_or(d.hull_eps),
        angle_eps: r
            .f64_in("angle_eps", Some(d.angle_eps), 1e-15..=0.1)?
            .unwrap_or(d.angle_eps),
        grasp_angle: grasp_deg.to_radians(),
        release_angle: release_deg.to_radians(),
        throw_window: r.u64_in("throw_window", 1, 1..=1000)? as u32,
        precise: d.precise,
        hands: match r.choice("hands", &["paper", "tracked"])? {
            "tracked" => HandRules::Tracked,
            _ => HandRules::Paper,
        },
        tracked: d.tracked,
        block_colors: Vec::new(),
    };
    r.finish()?;
    Ok(w)
}

fn tracked(r: Option<Reader>) -> Result<TrackedSettings, ConfigError> {
    let d = TrackedSettings::default();
    let Some(r) = r else { return Ok(d) };
    let t = TrackedSettings {
        grip_margin: r
            .f64_in("grip_margin", Some(d.grip_margin), 0.0..=0.2)?
            .unwrap_or(d.grip_margin),
        grip_open_time: r
            .f64_in("grip_open_time", Some(d.grip_open_time), 0.0..=1.0)?
            .unwrap_or(d.grip_open_time),
        gap_hold: r
            .f64_in("gap_hold", Some(d.gap_hold), 0.0..=10.0)?
            .unwrap_or(d.gap_hold),
        throw_fit_window: r
            .f64_in("throw_fit_window", Some(d.throw_fit_window), 0.0..=2.0)?
            .unwrap_or(d.throw_fit_window),
    };
    r.finish()?;
    Ok(t)
}

fn precise(r: Option<Reader>) -> Result<PreciseSettings, ConfigError> {
    let d = PreciseSettings::default();
    let Some(r) = r else { return Ok(d) };
    let p = PreciseSettings {
        substeps: r.u64_in("substeps", d.substeps as u64, 1..=256)? as u32,
        solver_iterations: r.u64_in("solver_iterations", d.solver_iterations as u64, 1..=64)?
            as u32,
        contact_hz: r.f64_in("contact_hz", None, 1.0..=100_000.0)?,
        contact_damping: r
            .f64_in("contact_damping", Some(d.contact_damping), 0.0..=100.0)?
            .unwrap_or(d.contact_damping),
        friction: r
            .f64_in("friction", Some(d.friction), 0.0..=100.0)?
            .unwrap_or(d.friction),
        restitution: r
            .f64_in("restitution", Some(d.restitution), 0.0..=1.0)?
            .unwrap_or(d.restitution),
        ccd: r.bool("ccd", d.ccd)?,
        sleep: r.bool("sleep", d.sleep)?,
        allowed_penetration: r
            .f64_in(
                "allowed_penetration",
                Some(d.allowed_penetration),
                1e-7..=0.1,
            )?
            .unwrap_or(d.allowed_penetration),
        bare_finger_radius: r
            .f64_in(
                "bare_finger_radius",
                Some(d.bare_finger_radius),
                1e-4..=0.05,
            )?
            .unwrap_or(d.bare_finger_radius),
    };
    r.finish()?;
    Ok(p)
}

fn effects(r: Option<Reader>) -> Result<Effects, ConfigError> {
    let d = Effects::default();
    let Some(r) = r else { return Ok(d) };
    let e = Effects {
        gravity: r.bool("gravity", d.gravity)?,
        inertia: r.bool("inertia", d.inertia)?,
        floor: match r.choice("floor", &["tipping", "rest", "none"])? {
            "none" => FloorEffect::None,
            "rest" => FloorEffect::Rest,
            _ => FloorEffect::Tipping,
        },
        hand: match r.choice("hand", &["grasp", "push", "none"])? {
            "none" => HandEffect::None,
            "push" => HandEffect::Push,
            _ => HandEffect::Grasp,
        },
        carry: r.bool("carry", d.carry)?,
        stacking: match r.choice("stacking", &["paper", "supported"])? {
            "supported" => Stacking::Supported,
            _ => Stacking::Paper,
        },
    };
    r.finish()?;
    Ok(e)
}

fn unit_quaternion(r: &Reader, key: &'static str) -> Result<[f64; 4], ConfigError> {
    const IDENTITY: [f64; 4] = [0.0, 0.0, 0.0, 1.0];
    let q = r.array_or::<4>(key, -2.0..=2.0, IDENTITY)?;
    let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    if (norm - 1.0).abs() > 1e-3 {
        return Err(r.err(
            key,
            format!("quaternion [x, y, z, w] has length {norm:.6}; it must be a unit quaternion (length 1 within 0.001)"),
        ));
    }
    Ok(q.map(|v| v / norm))
}

/// The longest block name a scene takes, in characters: names label blocks in reports, events
/// and the text summary, which aligns them in a column.
pub const MAX_BLOCK_NAME_CHARS: usize = 128;

/// The `[[block]]` tables. A table with `count = [nx, ny, nz]` stands for a lattice of that
/// many copies, `spacing = [dx, dy, dz]` metres apart, the first at `position`, named
/// `name_x_y_z` (a 32 x 1 x 32 field of cubes is one table). Returns the blocks and each one's
/// `color` (see [`WorldSettings::block_colors`]).
#[allow(clippy::type_complexity)]
fn blocks(root: &Reader) -> Result<(Vec<BlockSpec>, Vec<Option<[f32; 3]>>), ConfigError> {
    let tables = root.tables("block")?;
    let mut out: Vec<BlockSpec> = Vec::new();
    let mut colors: Vec<Option<[f32; 3]>> = Vec::new();
    let mut names = std::collections::HashSet::new();
    for (i, r) in tables.into_iter().enumerate() {
        let name = r.string("name")?.unwrap_or_else(|| format!("block{i}"));
        if name.is_empty()
            || name.chars().count() > MAX_BLOCK_NAME_CHARS
            || name.chars().any(char::is_control)
        {
            return Err(r.err(
                "name",
                format!(
                    "a name of {} characters{}: allowed: 1 to {MAX_BLOCK_NAME_CHARS} characters, \
                     none of them control characters (names label blocks in reports and events)",
                    name.chars().count(),
                    if name.chars().any(char::is_control) {
                        " with control characters"
                    } else {
                        ""
                    }
                ),
            ));
        }
        let shape_kind = r.choice("shape", &["box", "wedge", "tetra", "hull"])?;
        let size = || -> Result<[f64; 3], ConfigError> {
            r.array_or::<3>("size", 1e-4..=1e3, [0.1, 0.1, 0.1])
        };
        let shape = match shape_kind {
            "wedge" => ShapeSpec::Wedge { size: size()? },
            "tetra" => ShapeSpec::Tetra { size: size()? },
            "hull" => {
                if r.has("size") {
                    return Err(r.err("size", "a hull block takes `vertices`, not `size`"));
                }
                ShapeSpec::Hull {
                    vertices: hull_vertices(&r)?,
                }
            }
            _ => ShapeSpec::Box { size: size()? },
        };
        let position = r.array::<3>("position", POSITION_RANGE)?.ok_or_else(|| {
            r.err(
                "position",
                "required: the centre of gravity [x, y, z] in metres",
            )
        })?;
        let rotation = unit_quaternion(&r, "rotation")?;
        let velocity = r.array_or::<3>("velocity", -1.0e4..=1.0e4, [0.0; 3])?;
        // sRGB components, as a colour picker gives them (0.8, not 204).
        let color = r
            .array::<3>("color", 0.0..=1.0)?
            .map(|c| c.map(|v| v as f32));
        let count = r.array_or::<3>("count", 1.0..=MAX_SCENE_BLOCKS as f64, [1.0; 3])?;
        if count.iter().any(|v| v.fract() != 0.0) {
            return Err(r.err(
                "count",
                format!("{count:?}: copies along x, y and z must be whole numbers"),
            ));
        }
        let count = count.map(|v| v as usize);
        let copies = count.iter().product::<usize>();
        let spacing = r.array::<3>("spacing", 0.0..=1e3)?;
        let spacing = match (spacing, copies) {
            (Some(s), _) => s,
            (None, 1) => [0.0; 3],
            (None, _) => {
                return Err(r.err(
                    "spacing",
                    "required with `count`: the distance [dx, dy, dz] in metres between \
                     neighbouring copies' centres",
                ))
            }
        };
        let name_key = r.key("name");
        r.finish()?;
        if out.len() + copies > MAX_SCENE_BLOCKS {
            return Err(root.err(
                "block",
                format!(
                    "{} blocks; allowed: at most {MAX_SCENE_BLOCKS}",
                    out.len() + copies
                ),
            ));
        }
        for x in 0..count[0] {
            for y in 0..count[1] {
                for z in 0..count[2] {
                    let name = if copies == 1 {
                        name.clone()
                    } else {
                        format!("{name}_{x}_{y}_{z}")
                    };
                    if !names.insert(name.clone()) {
                        return Err(ConfigError::new(
                            root.file,
                            name_key,
                            format!("{name:?} is used by another block; names must be unique"),
                        ));
                    }
                    let at = [x, y, z];
                    out.push(BlockSpec {
                        name,
                        shape: shape.clone(),
                        position: std::array::from_fn(|k| position[k] + at[k] as f64 * spacing[k]),
                        rotation,
                        velocity,
                    });
                    colors.push(color);
                }
            }
        }
    }
    Ok((out, colors))
}

/// A hull's vertex coordinates, metres in the block's frame.
const VERTEX_RANGE: std::ops::RangeInclusive<f64> = -1e3..=1e3;
/// How many vertices a hull takes.
const HULL_VERTICES: std::ops::RangeInclusive<usize> = 4..=256;

fn hull_vertices(r: &Reader) -> Result<Vec<[f64; 3]>, ConfigError> {
    let Some(v) = r.raw("vertices", || Spec {
        allowed: format!(
            "{} to {} points, each coordinate {}",
            HULL_VERTICES.start(),
            HULL_VERTICES.end(),
            span(&VERTEX_RANGE)
        ),
        ..Spec::of("list of [x, y, z] points")
    }) else {
        return Err(r.err(
            "vertices",
            "required for shape = \"hull\": [[x, y, z], ...] in the block's frame",
        ));
    };
    let Value::Array(items) = v else {
        return Err(r.err(
            "vertices",
            format!("expected a list of [x, y, z], found {}", v.type_str()),
        ));
    };
    if !HULL_VERTICES.contains(&items.len()) {
        return Err(r.err(
            "vertices",
            format!(
                "{} vertices; allowed: 4 to 256 (a solid needs at least 4)",
                items.len()
            ),
        ));
    }
    items
        .iter()
        .enumerate()
        .map(|(i, p)| {
            vector::<3>(p, &VERTEX_RANGE).map_err(|e| r.err("vertices", format!("vertex {i}: {e}")))
        })
        .collect()
}

/// A `[left_hand]` beside the scene's `[hand]`: what two scripted hands need.
fn two_hands(root: &Reader, scene: &Scene) -> Result<(), ConfigError> {
    let (Some(right), Some(left)) = (&scene.hand, &scene.left_hand) else {
        return Err(root.err(
            "left_hand",
            "a [left_hand] needs a [hand] beside it (the right hand; a scene of one hand gives \
             it as [hand], whichever hand it means)",
        ));
    };
    if right.is_bare() != left.is_bare() {
        return Err(root.err(
            "left_hand",
            "[hand] and [left_hand] must shape their fingers the same way: both bare `fingers`, \
             or both `grip`/`angles` through the hand model",
        ));
    }
    if scene.world.model == ModelKind::Precise {
        return Err(root.err(
            "left_hand",
            "two hands are the paper model's (docs/model.md \"Two hands\"): the precise model \
             takes one; remove [left_hand] or set `world.model` = \"paper\"",
        ));
    }
    Ok(())
}

impl HandScript {
    /// Whether the keys give bare check points (`fingers`) rather than going through the hand
    /// model (every key of a script is shaped the same way).
    pub fn is_bare(&self) -> bool {
        self.keys
            .iter()
            .any(|k| matches!(k.pose, HandPoseSpec::Fingers(_)))
    }

    /// The time of the last key, after which the hand holds still.
    pub fn end_time(&self) -> f64 {
        self.keys.last().map_or(0.0, |k| k.t)
    }
}

/// A `[hand]` or `[left_hand]` table (`name`) of keys.
fn hand(r: Reader, name: &str) -> Result<HandScript, ConfigError> {
    let keys = r.tables("key")?;
    if keys.is_empty() {
        return Err(r.err(
            "key",
            format!("a [{name}] needs at least one [[{name}.key]]"),
        ));
    }
    let mut out: Vec<HandKey> = Vec::with_capacity(keys.len());
    for k in keys {
        let t = k.f64_required("t", 0.0..=1.0e6)?;
        if let Some(prev) = out.last() {
            if t <= prev.t {
                return Err(k.err(
                    "t",
                    format!(
                        "{t} is not after the previous key's {}; keys must be in increasing time",
                        prev.t
                    ),
                ));
            }
        }
        let given: Vec<&str> = ["grip", "angles", "fingers"]
            .into_iter()
            .filter(|key| k.has(key))
            .collect();
        if given.len() > 1 {
            return Err(k.err(
                given[1],
                format!(
                    "give one of grip, angles or fingers, not {}",
                    given.join(" and ")
                ),
            ));
        }
        let pose = if k.has("fingers") {
            HandPoseSpec::Fingers(fingers(&k)?)
        } else if let Some(a) = k.numbers("angles", -std::f64::consts::PI..=std::f64::consts::PI)? {
            if a.len() != 18 && a.len() != 22 {
                return Err(k.err(
                    "angles",
                    format!("{} angles; a CyberGlove has 18 or 22 sensors", a.len()),
                ));
            }
            HandPoseSpec::Angles(a)
        } else {
            HandPoseSpec::Grip(k.f64_in("grip", Some(0.0), 0.0..=1.0)?.unwrap_or(0.0))
        };
        if let Some(first) = out.first() {
            let same = match (&first.pose, &pose) {
                (HandPoseSpec::Fingers(a), HandPoseSpec::Fingers(b)) => {
                    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.len() == y.len())
                }
                (HandPoseSpec::Fingers(_), _) | (_, HandPoseSpec::Fingers(_)) => false,
                (HandPoseSpec::Angles(a), HandPoseSpec::Angles(b)) => a.len() == b.len(),
                _ => true,
            };
            if !same {
                return Err(k.err(
                    "fingers",
                    "every key must shape the hand the same way: all grip/angles (with the same sensor count), or all fingers with the same number of fingers and points",
                ));
            }
        }
        out.push(HandKey {
            t,
            wrist: k.array::<3>("wrist", POSITION_RANGE)?.ok_or_else(|| {
                k.err("wrist", "required: the wrist position [x, y, z] in metres")
            })?,
            wrist_rotation: unit_quaternion(&k, "wrist_rotation")?,
            pose,
        });
        k.finish()?;
    }
    r.finish()?;
    Ok(HandScript { keys: out })
}

/// A bare finger point's coordinates, metres in the wrist's frame.
const FINGER_POINT_RANGE: std::ops::RangeInclusive<f64> = -10.0..=10.0;

fn fingers(k: &Reader) -> Result<Vec<Vec<[f64; 3]>>, ConfigError> {
    let bad = |p: String| k.err("fingers", p);
    let Some(Value::Array(list)) = k.raw("fingers", || Spec {
        allowed: format!(
            "1 to {MAX_FINGERS} fingers of 1 to {MAX_FINGER_POINTS} points, each coordinate {}",
            span(&FINGER_POINT_RANGE)
        ),
        ..Spec::of("list of fingers, each a list of [x, y, z] points")
    }) else {
        return Err(bad(
            "expected a list of fingers, each a list of [x, y, z] points".into(),
        ));
    };
    if list.is_empty() || list.len() > MAX_FINGERS {
        return Err(bad(format!(
            "{} fingers; allowed: 1 to {MAX_FINGERS}",
            list.len()
        )));
    }
    list.iter()
        .enumerate()
        .map(|(f, finger)| {
            let Value::Array(points) = finger else {
                return Err(bad(format!(
                    "finger {f}: expected a list of [x, y, z] points"
                )));
            };
            if points.is_empty() || points.len() > MAX_FINGER_POINTS {
                return Err(bad(format!(
                    "finger {f}: {} points; allowed: 1 to {MAX_FINGER_POINTS}",
                    points.len()
                )));
            }
            points
                .iter()
                .enumerate()
                .map(|(i, p)| {
                    vector::<3>(p, &FINGER_POINT_RANGE)
                        .map_err(|e| bad(format!("finger {f} point {i}: {e}")))
                })
                .collect()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(text: &str) -> Result<Scene, ConfigError> {
        let dir = std::env::temp_dir().join(format!("hb-scene-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join(format!("s{}.toml", crate::monotonic_ns()));
        std::fs::write(&file, text).unwrap();
        let r = Scene::load(&file);
        std::fs::remove_file(&file).unwrap();
        r
    }

    /// `n` cubes on a grid, as scene text.
    fn cubes(n: usize) -> String {
        (0..n)
            .map(|i| {
                format!(
                    "[[block]]\nsize = [0.04, 0.04, 0.04]\nposition = [{}, 0.02, {}]\n",
                    (i % 64) as f64 * 0.08,
                    (i / 64) as f64 * 0.08
                )
            })
            .collect()
    }

    #[test]
    fn a_scene_takes_4096_blocks_and_refuses_more_naming_count_and_limit() {
        assert_eq!(load(&cubes(MAX_SCENE_BLOCKS)).unwrap().blocks.len(), 4096);
        let e = load(&cubes(MAX_SCENE_BLOCKS + 1)).unwrap_err();
        assert_eq!(e.key, "block");
        assert!(
            e.problem.contains("4097 blocks") && e.problem.contains("at most 4096"),
            "{e}"
        );
    }

    /// One table with `count` is a lattice of copies, `spacing` apart, named by their place.
    #[test]
    fn a_block_with_count_is_a_lattice_of_copies() {
        let s = load(
            "[[block]]\nname = \"cube\"\nsize = [0.04, 0.04, 0.04]\nposition = [0.1, 0.02, -0.2]\n\
             count = [32, 2, 16]\nspacing = [0.06, 0.05, 0.07]\n\
             [[block]]\nname = \"lone\"\nposition = [2.0, 0.05, 0.0]\n",
        )
        .unwrap();
        assert_eq!(s.blocks.len(), 32 * 2 * 16 + 1);
        assert_eq!(s.blocks[0].name, "cube_0_0_0");
        assert_eq!(s.blocks[0].position, [0.1, 0.02, -0.2]);
        let last = &s.blocks[1023];
        assert_eq!(last.name, "cube_31_1_15");
        let want = [0.1 + 31.0 * 0.06, 0.02 + 0.05, -0.2 + 15.0 * 0.07];
        for (got, want) in last.position.iter().zip(want) {
            assert!((got - want).abs() < 1e-12, "{:?}", last.position);
        }
        assert_eq!(s.blocks[1024].name, "lone");
        // Too many copies, fractions, a missing spacing and a clash of names are refused.
        let e = load(
            "[[block]]\nposition = [0, 0.05, 0]\ncount = [64, 1, 65]\nspacing = [0.1, 0, 0.1]\n",
        )
        .unwrap_err();
        assert!(
            e.problem.contains("4160 blocks") && e.problem.contains("at most 4096"),
            "{e}"
        );
        let e = load(
            "[[block]]\nposition = [0, 0.05, 0]\ncount = [2.5, 1, 1]\nspacing = [0.1, 0, 0]\n",
        )
        .unwrap_err();
        assert_eq!(e.key, "block[0].count");
        let e = load("[[block]]\nposition = [0, 0.05, 0]\ncount = [2, 1, 1]\n").unwrap_err();
        assert!(
            e.key == "block[0].spacing" && e.problem.contains("required with `count`"),
            "{e}"
        );
        let e = load(
            "[[block]]\nname = \"a\"\nposition = [0, 0.05, 0]\ncount = [2, 1, 1]\nspacing = [0.2, 0, 0]\n\
             [[block]]\nname = \"a_1_0_0\"\nposition = [1, 0.05, 0]\n",
        )
        .unwrap_err();
        assert!(
            e.key == "block[1].name" && e.problem.contains("\"a_1_0_0\""),
            "{e}"
        );
    }

    #[test]
    fn a_full_scene_loads_with_defaults() {
        let s = load(
            r#"
            [[block]]
            name = "red"
            position = [0.0, 0.05, 0.0]
            [[block]]
            shape = "hull"
            vertices = [[0,0,0],[1,0,0],[0,1,0],[0,0,1]]
            position = [1.0, 0.5, 0.0]
            [hand]
            [[hand.key]]
            t = 0.0
            wrist = [0.0, 0.3, -0.3]
            grip = 0.5
            "#,
        )
        .unwrap();
        assert_eq!(s.world.step_hz, 120.0);
        assert_eq!(s.blocks.len(), 2);
        assert_eq!(s.blocks[1].name, "block1");
        assert_eq!(s.blocks[0].shape, ShapeSpec::Box { size: [0.1; 3] });
        assert_eq!(s.hand.unwrap().keys[0].pose, HandPoseSpec::Grip(0.5));
    }

    #[test]
    fn a_block_colour_is_read_per_table_and_its_range_is_named() {
        let s = load(
            "[[block]]\nname = \"a\"\nposition = [0, 0.05, 0]\ncolor = [0.2, 0.4, 1]\n\
             [[block]]\nname = \"b\"\nposition = [1, 0.05, 0]\ncount = [2, 1, 1]\nspacing = [0.2, 0, 0]\n",
        )
        .unwrap();
        assert_eq!(
            s.world.block_colors,
            vec![Some([0.2, 0.4, 1.0]), None, None]
        );
        let e = load("[[block]]\nposition = [0, 0.05, 0]\ncolor = [255, 0, 0]\n").unwrap_err();
        assert_eq!(e.key, "block[0].color");
        assert!(e.problem.contains("allowed: 0 to 1"), "{e}");
        // The message names the file, the key and the range.
        let text = e.to_string();
        assert!(text.contains(&*e.file.to_string_lossy()) && text.contains("block[0].color"));
    }

    #[test]
    fn unknown_key_is_named_with_what_is_allowed() {
        let e = load("[world]\nstep_hz = 120\nstephz = 3\n").unwrap_err();
        assert_eq!(e.key, "world.stephz");
        assert!(
            e.problem.contains("unknown key") && e.problem.contains("step_hz"),
            "{e}"
        );
    }

    #[test]
    fn out_of_range_value_names_the_range() {
        let e = load("[world]\nstep_hz = 0\n").unwrap_err();
        assert_eq!(e.key, "world.step_hz");
        assert!(e.problem.contains("allowed: 1 to"), "{e}");
        let e = load("[[block]]\nposition = [0, 0.05]\n").unwrap_err();
        assert_eq!(e.key, "block[0].position");
    }

    #[test]
    fn a_block_name_too_long_empty_or_with_control_characters_is_refused() {
        let long = "n".repeat(65_536);
        let e = load(&format!(
            "[[block]]\nname = \"{long}\"\nposition = [0, 0.05, 0]\n"
        ))
        .unwrap_err();
        assert_eq!(e.key, "block[0].name");
        assert!(e.problem.contains("65536 characters"), "{e}");
        assert!(e.problem.contains("1 to 128"), "{e}");
        for bad in ["", "a\\u0007b"] {
            let e = load(&format!(
                "[[block]]\nname = \"{bad}\"\nposition = [0, 0.05, 0]\n"
            ))
            .unwrap_err();
            assert_eq!(e.key, "block[0].name", "{bad:?}");
        }
        let ok = "m".repeat(MAX_BLOCK_NAME_CHARS);
        let s = load(&format!(
            "[[block]]\nname = \"{ok}\"\nposition = [0, 0.05, 0]\n"
        ))
        .unwrap();
        assert_eq!(s.blocks[0].name, ok);
    }

    #[test]
    fn wrong_type_and_bad_choice_are_named() {
        let e = load("[effects]\nfloor = \"bouncy\"\n").unwrap_err();
        assert_eq!(e.key, "effects.floor");
        assert!(e.problem.contains("\"tipping\""), "{e}");
        let e = load("[effects]\ngravity = 1\n").unwrap_err();
        assert!(e.problem.contains("true or false"), "{e}");
    }

    #[test]
    fn nan_and_non_unit_quaternions_are_refused() {
        let e = load("[[block]]\nposition = [nan, 0, 0]\n").unwrap_err();
        assert!(e.problem.contains("not a finite"), "{e}");
        let e = load("[[block]]\nposition = [0, 0.05, 0]\nrotation = [0, 0, 0, 2]\n").unwrap_err();
        assert!(e.problem.contains("unit quaternion"), "{e}");
    }

    #[test]
    fn a_left_hand_needs_a_right_one_shaped_alike_and_the_paper_model() {
        let right = "[hand]\n[[hand.key]]\nt = 0\nwrist = [0.1, 0.2, 0]\ngrip = 0.5\n";
        let left = "[left_hand]\n[[left_hand.key]]\nt = 0\nwrist = [-0.1, 0.2, 0]\ngrip = 0.5\n\
                    [[left_hand.key]]\nt = 2\nwrist = [-0.1, 0.3, 0]\n";
        let s = load(&format!("{right}{left}")).unwrap();
        assert_eq!(s.left_hand.as_ref().unwrap().keys.len(), 2);
        assert_eq!(s.left_hand.as_ref().unwrap().end_time(), 2.0);
        assert!(!s.left_hand.unwrap().is_bare());
        assert!(load(right).unwrap().left_hand.is_none());

        let e = load(left).unwrap_err();
        assert!(
            e.key == "left_hand" && e.problem.contains("needs a [hand]"),
            "{e}"
        );
        let bare = "[hand]\n[[hand.key]]\nt = 0\nwrist = [0, 0.2, 0]\nfingers = [[[0, 0, 0]]]\n";
        let e = load(&format!("{bare}{left}")).unwrap_err();
        assert!(
            e.key == "left_hand" && e.problem.contains("the same way"),
            "{e}"
        );
        let e = load(&format!("[world]\nmodel = \"precise\"\n{right}{left}")).unwrap_err();
        assert!(e.key == "left_hand" && e.problem.contains("precise"), "{e}");
        let e = load("[hand]\n[[hand.key]]\nt = 0\nwrist = [0, 0, 0]\n[left_hand]\n").unwrap_err();
        assert!(e.problem.contains("[[left_hand.key]]"), "{e}");
    }

    #[test]
    fn hand_keys_must_increase_and_agree() {
        let e = load("[hand]\n[[hand.key]]\nt = 1\nwrist = [0,0,0]\n[[hand.key]]\nt = 0.5\nwrist = [0,0,0]\n").unwrap_err();
        assert_eq!(e.key, "hand.key[1].t");
        let e = load("[hand]\n[[hand.key]]\nt = 0\nwrist = [0,0,0]\nfingers = [[[0,0,0]]]\n[[hand.key]]\nt = 1\nwrist = [0,0,0]\n").unwrap_err();
        assert!(e.problem.contains("same way"), "{e}");
    }

    #[test]
    fn the_precise_table_has_defaults_and_named_ranges() {
        let s = load("[precise]\nsubsteps = 16\nccd = false\n").unwrap();
        assert_eq!(s.world.precise.substeps, 16);
        assert!(!s.world.precise.ccd);
        assert_eq!(s.world.precise.solver_iterations, 2);
        let e = load("[precise]\nsubsteps = 0\n").unwrap_err();
        assert_eq!(e.key, "precise.substeps");
        assert!(e.problem.contains("allowed: 1 to 256"), "{e}");
        let e = load("[precise]\nsubstep = 4\n").unwrap_err();
        assert!(e.problem.contains("unknown key"), "{e}");
    }

    #[test]
    fn a_missing_file_is_named() {
        let e = Scene::load(Path::new("/nonexistent/x.toml")).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("/nonexistent/x.toml: cannot read"),
            "{e}"
        );
    }
}
