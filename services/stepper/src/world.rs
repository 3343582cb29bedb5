//! The world and its step, in docs/model.md's "Order of one step".
//!
//! [`World::step`] reads as that order: each stage is a method named for its rules, in its own
//! module (`hand` R1-R6, `interference` R10-R12, `motion` R7 and R13, `floor` R8-R9). The
//! passes a scene does not enable (docs/design.md "Effects") are decided once in [`World::new`] and
//! cost one branch per step; resting blocks that nothing touches are skipped.

use std::fmt;
use std::path::PathBuf;

use glam::{DQuat, DVec2, DVec3};

use common::config::scene::{FloorEffect, HandEffect, Stacking};
use common::config::Scene;
use common::{BlockMode, HandSample, WorldSample, MAX_BLOCKS, MAX_FINGERS, MAX_FINGER_POINTS};

use crate::body::{Block, Moved};
use crate::geometry::{sat_depth, Polyhedron};

/// What is wrong with a scene for the model: names the file, the block (when one is at fault)
/// and the problem.
#[derive(Debug, Clone, PartialEq)]
pub struct WorldError {
    pub file: PathBuf,
    pub block: Option<String>,
    pub problem: String,
}

impl fmt::Display for WorldError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.block {
            Some(b) => write!(
                f,
                "{}: block {:?}: {}",
                self.file.display(),
                b,
                self.problem
            ),
            None => write!(f, "{}: {}", self.file.display(), self.problem),
        }
    }
}

impl std::error::Error for WorldError {}

/// What happened to a block in a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EventKind {
    /// R5: the hand grasped the block (it was not grasped in the previous step).
    Grasp,
    /// R13: the grasp ended; the block flies on with its last grasped displacement.
    Release,
    /// R4/R6: the hand started pushing the block.
    Push,
    /// R10: the block started being carried by a hand-moved block.
    Carry,
    /// R8: a vertex not in the previous contact set touched the floor.
    Impact,
    /// R9: the block started tipping.
    Topple,
    /// R9: the block came to rest on the floor.
    Rest,
    /// R11 (paper) or R14 (supported): the block is held up by another block.
    Support,
}

impl EventKind {
    /// The event a block's change into `mode` is reported as (both models: a mode change is
    /// an event); None for `free`, which is the absence of the others.
    pub fn on_entering(mode: BlockMode) -> Option<EventKind> {
        match mode {
            BlockMode::Grasped => Some(EventKind::Grasp),
            BlockMode::Pushed => Some(EventKind::Push),
            BlockMode::Carried => Some(EventKind::Carry),
            BlockMode::Tipping => Some(EventKind::Topple),
            BlockMode::Resting => Some(EventKind::Rest),
            BlockMode::Supported => Some(EventKind::Support),
            BlockMode::Free => None,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            EventKind::Grasp => "grasp",
            EventKind::Release => "release",
            EventKind::Push => "push",
            EventKind::Carry => "carry",
            EventKind::Impact => "impact",
            EventKind::Topple => "topple",
            EventKind::Rest => "rest",
            EventKind::Support => "support",
        }
    }
}

/// One event: in which step (1-based: the step after which `World::steps` equals it), what,
/// and to which block (index in the scene's order).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Event {
    pub step: u64,
    pub kind: EventKind,
    pub block: usize,
}

/// The scene's settings as the rules use them.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Params {
    /// g_step = (0, -g dt^2, 0), zero when gravity is off.
    pub g_step: DVec3,
    pub inertia: bool,
    pub contact_eps: f64,
    pub hull_eps: f64,
    pub angle_eps: f64,
    pub grasp_angle: f64,
    pub release_angle: f64,
}

/// Which passes run each step (docs/design.md "Effects"): an effect that is off costs nothing.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Passes {
    /// R1-R6 (and R13's release).
    pub hand: bool,
    /// R5 may grasp (hand = "grasp"); otherwise two contacts always push (R6).
    pub grasp: bool,
    /// R10.
    pub carry: bool,
    /// R7 gravity or inertia moves free blocks.
    pub free_motion: bool,
    /// R8.
    pub floor: bool,
    /// R9.
    pub tipping: bool,
    /// R11 (paper stacking) and R12's casts against other blocks: only with two blocks or more.
    pub blocks: bool,
    /// R14 replaces R11 (stacking = "supported"): only with two blocks or more.
    pub supported: bool,
}

/// The check points as drawn (R5's relocation), in the hand sample's layout.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Fingers {
    pub count: u32,
    pub point_count: [u32; MAX_FINGERS],
    pub points: [[[f64; 3]; MAX_FINGER_POINTS]; MAX_FINGERS],
}

impl Fingers {
    /// The hand's check points as they arrive (both models publish them; the paper model's R5
    /// then relocates those inside a grasped block); none without a hand.
    pub(crate) fn copy_from(&mut self, hand: Option<&HandSample>) {
        match hand {
            Some(h) => {
                let fc = (h.finger_count as usize).min(MAX_FINGERS);
                self.count = fc as u32;
                for f in 0..MAX_FINGERS {
                    self.point_count[f] = if f < fc {
                        h.finger_point_count[f].min(MAX_FINGER_POINTS as u32)
                    } else {
                        0
                    };
                }
                self.points = h.finger_points;
            }
            None => {
                self.count = 0;
                self.point_count = [0; MAX_FINGERS];
            }
        }
    }
}

/// The block world: docs/model.md's paper model (rules R1-R13, and R14 when the scene asks for it).
pub struct World {
    pub(crate) file: PathBuf,
    pub(crate) params: Params,
    pub(crate) passes: Passes,
    pub(crate) blocks: Vec<Block>,
    pub(crate) steps: u64,
    pub(crate) events: Vec<Event>,
    /// The hand at the previous step (P-, W-), when there was one.
    pub(crate) prev_hand: Option<HandSample>,
    pub(crate) fingers: Fingers,
    // ---- scratch, preallocated so that a step does not allocate ----
    pub(crate) contacts: Vec<crate::hand::Contact>,
    pub(crate) queue: Vec<usize>,
    pub(crate) hull_in: Vec<DVec2>,
    pub(crate) hull_out: Vec<DVec2>,
    pub(crate) support: crate::support::SupportScratch,
}

fn err(scene: &Scene, block: Option<&str>, problem: impl Into<String>) -> WorldError {
    WorldError {
        file: scene.file.clone(),
        block: block.map(str::to_string),
        problem: problem.into(),
    }
}

impl World {
    /// Builds the world of a scene, checking what the scene loader cannot: shapes that are
    /// solids, no block starting below the floor or inside another, and the options this
    /// model implements. It is the paper model whatever `[world] model` says: the choice
    /// between the models is [`crate::Model::new`]'s.
    pub fn new(scene: &Scene) -> Result<World, WorldError> {
        let w = &scene.world;
        if scene.blocks.len() > MAX_BLOCKS {
            return Err(err(
                scene,
                None,
                format!("{} blocks; at most {MAX_BLOCKS}", scene.blocks.len()),
            ));
        }
        let dt = 1.0 / w.step_hz;
        let e = &scene.effects;
        let params = Params {
            g_step: if e.gravity {
                DVec3::new(0.0, -w.gravity * dt * dt, 0.0)
            } else {
                DVec3::ZERO
            },
            inertia: e.inertia,
            contact_eps: w.contact_eps,
            hull_eps: w.hull_eps,
            angle_eps: w.angle_eps,
            grasp_angle: w.grasp_angle,
            release_angle: w.release_angle,
        };
        let mut blocks = Vec::with_capacity(scene.blocks.len());
        let mut max_vertices = 0;
        for spec in &scene.blocks {
            // Scenes built in code (benchmarks, tools) skip the loader's checks: repeat the
            // ones the model relies on.
            let finite = spec
                .position
                .iter()
                .chain(&spec.velocity)
                .chain(&spec.rotation)
                .all(|v| v.is_finite());
            let q = DQuat::from_array(spec.rotation);
            if !finite || q.length() < 1e-9 {
                return Err(err(
                    scene,
                    Some(&spec.name),
                    "position, velocity and rotation must be finite, and the rotation a non-zero quaternion",
                ));
            }
            let q = q.normalize();
            let poly = Polyhedron::from_spec(&spec.shape)
                .map_err(|p| err(scene, Some(&spec.name), format!("shape: {p}")))?;
            if poly.vertices.len() > 256 {
                return Err(err(
                    scene,
                    Some(&spec.name),
                    format!(
                        "its hull has {} vertices; allowed: at most 256",
                        poly.vertices.len()
                    ),
                ));
            }
            max_vertices = max_vertices.max(poly.vertices.len());
            let v = if e.inertia {
                DVec3::from_array(spec.velocity) * dt
            } else {
                DVec3::ZERO
            };
            blocks.push(Block::new(
                spec.name.clone(),
                poly,
                DVec3::from_array(spec.position),
                q,
                v,
                w.throw_window as usize,
            ));
        }
        // Geometric validation (the loader checks form and ranges, we check shapes).
        if e.floor != FloorEffect::None {
            for b in &blocks {
                let low = b.pos.y + b.lowest_rel_y();
                if low < -w.contact_eps {
                    return Err(err(
                        scene,
                        Some(&b.name),
                        format!(
                            "starts below the floor: its lowest vertex is at y = {low:.6} m; \
                             allowed: y >= 0 (within contact_eps = {})",
                            w.contact_eps
                        ),
                    ));
                }
            }
        }
        for i in 0..blocks.len() {
            for j in i + 1..blocks.len() {
                let (a, b) = (&blocks[i], &blocks[j]);
                let off = b.pos - a.pos;
                if off.length() > a.poly.radius + b.poly.radius + w.contact_eps {
                    continue;
                }
                let depth = sat_depth(&a.poly, a.rot, &a.rel, &b.poly, b.rot, &b.rel, off);
                if depth > w.contact_eps {
                    return Err(err(
                        scene,
                        Some(&b.name),
                        format!(
                            "starts inside block {:?} (they overlap by {depth:.6} m; touching is allowed)",
                            a.name
                        ),
                    ));
                }
            }
        }
        let n = blocks.len();
        let passes = Passes {
            hand: e.hand != HandEffect::None,
            grasp: e.hand == HandEffect::Grasp,
            carry: e.carry && n > 1,
            free_motion: e.gravity || e.inertia,
            floor: e.floor != FloorEffect::None,
            tipping: e.floor == FloorEffect::Tipping,
            blocks: n > 1,
            supported: e.stacking == Stacking::Supported && n > 1,
        };
        Ok(World {
            file: scene.file.clone(),
            params,
            passes,
            blocks,
            steps: 0,
            events: Vec::with_capacity(16 * n + 16),
            prev_hand: None,
            fingers: Fingers {
                count: 0,
                point_count: [0; MAX_FINGERS],
                points: [[[0.0; 3]; MAX_FINGER_POINTS]; MAX_FINGERS],
            },
            contacts: Vec::with_capacity(crate::hand::MAX_CONTACTS),
            queue: Vec::with_capacity(n),
            hull_in: Vec::with_capacity(max_vertices + 1),
            hull_out: Vec::with_capacity(2 * max_vertices + 2),
            support: crate::support::SupportScratch::new(
                if e.stacking == Stacking::Supported {
                    n
                } else {
                    0
                },
                max_vertices,
            ),
        })
    }

    /// Exactly one fixed step (dt = 1 / step_hz) with the hand's pose at this step; the world
    /// keeps the previous one itself (P-, W-). `None`, or a hand with a non-finite value, is
    /// "no hand this step". docs/model.md "Order of one step":
    pub fn step(&mut self, hand: Option<&HandSample>) {
        self.steps += 1;
        self.events.clear();
        let hand = hand.filter(|h| crate::hand::is_usable(h));
        self.begin_step(hand);
        if self.passes.hand {
            // 1. Hand contacts (R1-R3) for every block near the hand.
            self.hand_contacts(hand);
            // 2. Hand-driven motion (R5, R4, R6), then carry (R10).
            self.hand_motion(hand);
            if self.passes.carry {
                self.carry();
            }
        }
        // 3a. Supported stacking (R14, when the scene asks for it): blocks on blocks are judged
        //     bottom up, held or tipped with their load.
        if self.passes.supported {
            self.support_stage();
        }
        // 3. Free motion (R7, with R12) for the rest, except blocks held by R11 or R14. Without
        //    gravity and inertia nothing moves freely, and R11 has nothing to hold.
        if self.passes.free_motion {
            self.free_motion();
        }
        // 4. Floor (R8, R9) for every block that moved or is in floor contact, not resting.
        if self.passes.floor {
            self.floor_stage();
        }
        // 5. Releases (R13) take effect for the next step; modes and events are settled.
        self.finish_step(hand);
    }

    /// Sets the hand the next step takes as its previous one (P-, W-) without stepping: a
    /// caller that knows the hand before the first step (a scripted hand at t = 0) gives it
    /// here so that the first step sees the hand's motion, not a standing start.
    pub fn set_previous_hand(&mut self, hand: Option<&HandSample>) {
        self.prev_hand = hand.filter(|h| crate::hand::is_usable(h)).copied();
    }

    /// Block poses (pose of G), modes, the grasped block and the check points as drawn (R5's
    /// relocated finger points). Leaves `out.stamp` and `out.hand_seq` alone.
    pub fn write_sample(&self, out: &mut WorldSample) {
        out.step = self.steps;
        out.block_count = self.blocks.len() as u32;
        out.grasped_block = -1;
        for (i, b) in self.blocks.iter().enumerate() {
            out.blocks[i].pose.position = b.pos.to_array();
            out.blocks[i].pose.rotation = b.rot.to_array();
            out.blocks[i].mode = b.mode as u32;
            if b.mode == BlockMode::Grasped && out.grasped_block < 0 {
                out.grasped_block = i as i32;
            }
        }
        out.finger_count = self.fingers.count;
        out.finger_point_count = self.fingers.point_count;
        out.finger_points = self.fingers.points;
    }

    /// Fixed steps taken since the world began.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// What happened in the last step.
    pub fn events(&self) -> &[Event] {
        &self.events
    }

    /// The blocks' names, in the scene's order (the order of `WorldSample::blocks`).
    pub fn block_names(&self) -> impl Iterator<Item = &str> {
        self.blocks.iter().map(|b| b.name.as_str())
    }

    /// The number of blocks.
    pub fn block_count(&self) -> usize {
        self.blocks.len()
    }

    /// Block `i`'s centre of gravity, rotation, mode and inertia v (per step).
    pub fn block(&self, i: usize) -> Option<BlockView> {
        self.blocks.get(i).map(|b| BlockView {
            position: b.pos,
            rotation: b.rot,
            mode: b.mode,
            v: b.v,
            floor_contacts: b.floor.len(),
        })
    }

    /// Block `i`'s vertices in the world frame (for tests and tools).
    pub fn block_vertices(&self, i: usize) -> impl Iterator<Item = DVec3> + '_ {
        self.blocks
            .get(i)
            .into_iter()
            .flat_map(|b| b.poly.vertices.iter().map(move |v| b.pos + b.rot * *v))
    }

    /// The scene file this world came from.
    pub fn file(&self) -> &std::path::Path {
        &self.file
    }

    fn begin_step(&mut self, hand: Option<&HandSample>) {
        for b in &mut self.blocks {
            b.start_pos = b.pos;
            b.start_rot = b.rot;
            b.mode_before = b.mode;
            b.moved = Moved::No;
            b.intended = DVec3::ZERO;
            b.action = crate::body::HandAction::None;
            b.released = false;
        }
        self.fingers.copy_from(hand);
    }

    pub(crate) fn emit(&mut self, kind: EventKind, block: usize) {
        self.events.push(Event {
            step: self.steps,
            kind,
            block,
        });
    }

    fn finish_step(&mut self, hand: Option<&HandSample>) {
        for i in 0..self.blocks.len() {
            let (before, now, released) = {
                let b = &self.blocks[i];
                (b.mode_before, b.mode, b.released)
            };
            {
                // R14 judges again what touches a block that moved or changed mode.
                let b = &mut self.blocks[i];
                b.stirred = b.pos != b.start_pos || b.rot != b.start_rot || b.mode != b.mode_before;
            }
            if released {
                self.emit(EventKind::Release, i);
            }
            if before == now {
                continue;
            }
            if let Some(k) = EventKind::on_entering(now) {
                self.emit(k, i);
            }
        }
        self.prev_hand = hand.copied();
    }
}

/// A read-only view of one block's state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BlockView {
    pub position: DVec3,
    pub rotation: DQuat,
    pub mode: BlockMode,
    /// The inertia v (G's displacement per step).
    pub v: DVec3,
    /// Vertices in floor contact.
    pub floor_contacts: usize,
}
