//! The precise reference model (docs/model.md, "The precise reference model"): the same scene under
//! a full rigid-body engine, rapier3d (f64), as the yardstick for "what accuracy costs in time".
//!
//! Each block is a dynamic collider of the very shape the paper model uses, G at the body
//! origin: a box is parry's exact cuboid, any other shape the convex hull of the polyhedron
//! ([`Polyhedron::from_spec`]); restitution 0 and a high Coulomb
//! friction (the paper's "perfect friction"), CCD on (a fast block is one of rapier's bullets,
//! see `choose_bullets`); the floor is a fixed half-space; the hand
//! is a set of kinematic colliders (module [`hand`]) moved to each step's hand pose, so push,
//! grasp, carry and throw scenes run here too. The engine knows nothing of the paper's modes,
//! so module [`modes`] derives one per block from its contacts and velocities, with the paper's
//! own grasp rule (R3's grasp_angle over the contact normals).
//!
//! Time is the paper model's: one [`PreciseWorld::step`] is one fixed step of 1 / step_hz, the
//! stepper's timeline decides how many steps a hand sample brings, and nothing the model
//! computes reads a clock (one step reads it twice, around rapier's own step, only to tell
//! `bench stepper` what our wrapper costs beside rapier: [`PreciseWorld::pipeline_ns`]).
//! rapier without its `parallel` feature is deterministic for the same binary and inputs, so
//! two runs give identical bytes.
//!
//! The wrapper's own work per step is kept near-linear and off the bodies that need none: the
//! choice of bullets finds meeting swept boxes with a grid (module `bullets`) and touches only
//! the bodies whose CCD flag changes; the mode derivation skips bodies that slept through the
//! step (module [`modes`]).
//!
//! Like the paper model it computes in its own frame near the blocks (the *anchor*, module
//! [`crate::anchor`], the same rule): rapier's positions far from the origin round as coarsely
//! as the scene's coordinates (1.5e-11 m at 99 km), every contact solve there starts from
//! rounded numbers, and a push 99 km along x ended 85 mm from the run at the origin. Blocks and
//! the hand enter the engine less the anchor, and poses and check points leave it plus the
//! anchor; within 32 m of the origin the anchor is zero and not a bit changes.
//!
//! No rapier type leaves this module: the rest of the crate sees poses, modes and events
//! through [`crate::model::Model`].

mod bullets;
mod hand;
mod modes;
#[cfg(test)]
mod tests;

use std::path::PathBuf;
use std::time::Instant;

use glam::{DQuat, DVec3};
use rapier3d_f64::prelude::{
    CoefficientCombineRule, ColliderBuilder, ColliderHandle, FrictionModel, PhysicsWorld,
    RigidBodyBuilder, RigidBodyHandle, SharedShape, SpringCoefficients, Vector,
};

use common::config::scene::{FloorEffect, HandEffect, PreciseSettings, ShapeSpec};
use common::config::Scene;
use common::{
    BlockMode, BlockState, HandSample, Pose, WorldHeader, WorldSample, MAX_FINGERS,
    MAX_FINGER_POINTS,
};

use crate::anchor::{finger_points_to_scene, local_origin, to_scene, translate_hand};
use crate::geometry::Polyhedron;
use crate::world::{BlockView, Event, EventKind, Fingers, WorldError};

use hand::HandBodies;

/// What a collider is, in its `user_data`: the kind in the top byte, an index below.
const KIND_FLOOR: u128 = 1 << 120;
const KIND_BLOCK: u128 = 2 << 120;
const KIND_HAND: u128 = 3 << 120;
const KIND_MASK: u128 = 0xff << 120;

/// A contact point counts as touching within this distance (rapier also reports speculative
/// points up to its prediction distance, 2 cm, which are not touching yet).
const TOUCH_EPS: f64 = 1e-3;

/// One block's engine handles and the state the modes are derived from.
struct PreciseBlock {
    name: String,
    body: RigidBodyHandle,
    collider: ColliderHandle,
    mode: BlockMode,
    /// Touching the floor or another block after the previous step (an impact is a contact
    /// that begins).
    touching: bool,
    floor_contacts: usize,
    /// The collider's CCD thickness (parry's, the shape's thinnest extent) and the radius of
    /// its bounding sphere about G, for the choice of this step's bullets.
    thickness: f64,
    radius: f64,
    /// Whether its body is one of rapier's bullets now (`ccd_enabled`), and the last step that
    /// chose it: `choose_bullets` switches the flag only when the choice changes.
    bullet: bool,
    chosen_at: u64,
    /// The last step whose mode derivation judged it, and the mode that derivation found before
    /// `carried` (what a neighbour's `carried` test reads).
    judged_at: u64,
    judged: BlockMode,
}

/// The scene under rapier3d: see the module documentation.
pub struct PreciseWorld {
    file: PathBuf,
    physics: PhysicsWorld,
    blocks: Vec<PreciseBlock>,
    hand: Option<HandBodies>,
    settings: PreciseSettings,
    dt: f64,
    grasp_angle: f64,
    release_angle: f64,
    steps: u64,
    events: Vec<Event>,
    /// The hand at the previous step, in the world's frame.
    prev_hand: Option<HandSample>,
    /// Where the world's frame is in the scene's ([`local_origin`]): rapier's bodies, the
    /// floor and the hand's colliders live in that frame.
    anchor: DVec3,
    /// Hand samples refused where they entered (`hand::unusable_because`).
    rejected_hands: u64,
    fingers: Fingers,
    /// Scratch of the mode derivation, kept so that a step does not allocate.
    touches: Vec<modes::Touches>,
    modes: Vec<BlockMode>,
    /// Scratch of the bullet choice: fast blocks (motion this step, index), fastest first,
    /// and their swept boxes' grid.
    fast: Vec<(f64, usize)>,
    choice: bullets::BulletChoice,
    /// The blocks whose bodies are bullets now.
    bullets: Vec<usize>,
    /// Block index of each body (by the body handle's arena index; `u32::MAX`: not a block), to
    /// read the island manager's awake bodies as blocks.
    block_of_body: Vec<u32>,
    /// Blocks whose bodies were awake after the previous step, and the blocks the mode
    /// derivation judges this step (scratch).
    awake_before: Vec<usize>,
    awake_now: Vec<usize>,
    judge: Vec<usize>,
    /// Scratch of the mode derivation's pass over every contact pair (module [`modes`]), and
    /// how many blocks are grasped now (`carried` needs one).
    swept: Vec<modes::Swept>,
    grasped: usize,
    /// Judge every block every step by its own contact query, asleep or not (the derivation
    /// as it was before sleeping bodies were skipped and pairs swept: the tests' reference).
    judge_all: bool,
    /// Nanoseconds spent in rapier's `PhysicsPipeline::step` since the world was built.
    pipeline_ns: u64,
}

impl PreciseWorld {
    /// Builds the engine's world of a scene. The caller has validated the scene's geometry
    /// (the paper model's checks: shapes are solids, nothing starts below the floor or inside
    /// another block), so what fails here is only what rapier itself refuses.
    pub fn new(scene: &Scene) -> Result<PreciseWorld, WorldError> {
        let w = &scene.world;
        let p = w.precise;
        let e = &scene.effects;
        let dt = 1.0 / w.step_hz;
        let mut physics = PhysicsWorld::new();
        physics.gravity = if e.gravity {
            Vector::new(0.0, -w.gravity, 0.0)
        } else {
            Vector::ZERO
        };
        let ip = &mut physics.integration_parameters;
        ip.dt = dt;
        ip.num_solver_iterations = p.substeps as usize;
        ip.num_internal_pgs_iterations = p.solver_iterations as usize;
        let substep = dt / p.substeps as f64;
        let contact_hz = p.contact_hz.unwrap_or(0.125 / substep);
        ip.contact_softness = SpringCoefficients::new(contact_hz, p.contact_damping);
        // Contacts with the floor: rapier's default is twice as stiff as between bodies; keep
        // its ratio, within the substep's stable limit.
        ip.static_contact_softness =
            SpringCoefficients::new((2.0 * contact_hz).min(0.25 / substep), p.contact_damping);
        ip.max_ccd_substeps = if p.ccd { 1 } else { 0 };
        ip.normalized_allowed_linear_error = p.allowed_penetration;
        ip.friction_model = FrictionModel::Coulomb;
        // A pair of blocks that moved a little keeps its contacts in rapier's default (until it
        // moves 5 cm); a reference recomputes them.
        ip.contact_recycling = false;

        if e.floor != FloorEffect::None {
            let floor = ColliderBuilder::new(SharedShape::halfspace(Vector::Y))
                .friction(p.friction)
                .friction_combine_rule(CoefficientCombineRule::Max)
                .restitution(p.restitution)
                .user_data(KIND_FLOOR)
                .build();
            physics.colliders.insert(floor);
        }
        // The paper model's anchor (on the floor: the floor's half-space stays y = 0).
        let anchor = local_origin(scene.blocks.iter().map(|b| b.position));
        let mut blocks = Vec::with_capacity(scene.blocks.len());
        let mut block_of_body = Vec::with_capacity(scene.blocks.len());
        for (i, spec) in scene.blocks.iter().enumerate() {
            let bad = |problem: String| WorldError {
                file: scene.file.clone(),
                block: Some(spec.name.clone()),
                problem,
            };
            let poly =
                Polyhedron::from_spec(&spec.shape).map_err(|p| bad(format!("shape: {p}")))?;
            let builder = match &spec.shape {
                // A box is parry's exact cuboid (G is its centre, as in the polyhedron): its
                // contacts come from parry's box-box path (separating axes, face clipping). A
                // hull of the same eight vertices goes through the generic GJK path
                // (contact_manifold_pfm_pfm), which for faces touching at exactly zero distance
                // gave tilted normals: an aligned tower spawned face on face was kicked 6 to 12
                // degrees in its first step and fell.
                ShapeSpec::Box { size } => {
                    ColliderBuilder::cuboid(size[0] / 2.0, size[1] / 2.0, size[2] / 2.0)
                }
                _ => {
                    let points: Vec<Vector> = poly.vertices.to_vec();
                    ColliderBuilder::convex_hull(&points).ok_or_else(|| {
                        bad("rapier3d cannot build a convex hull of its vertices".into())
                    })?
                }
            };
            let collider = builder
                .friction(p.friction)
                .friction_combine_rule(CoefficientCombineRule::Max)
                .restitution(p.restitution)
                .restitution_combine_rule(CoefficientCombineRule::Min)
                .user_data(KIND_BLOCK | i as u128)
                .build();
            let rot = DQuat::from_array(spec.rotation).normalize();
            let velocity = if e.inertia {
                DVec3::from_array(spec.velocity)
            } else {
                DVec3::ZERO
            };
            let mut body = RigidBodyBuilder::dynamic()
                .translation(DVec3::from_array(spec.position) - anchor)
                .linvel(velocity)
                .can_sleep(p.sleep)
                .build();
            body.set_rotation(rot, false);
            let thickness = collider.shape().ccd_thickness();
            let radius = collider.shape().compute_local_bounding_sphere().radius;
            let body = physics.bodies.insert(body);
            let slot = body.into_raw_parts().0 as usize;
            if block_of_body.len() <= slot {
                block_of_body.resize(slot + 1, u32::MAX);
            }
            block_of_body[slot] = i as u32;
            let collider =
                physics
                    .colliders
                    .insert_with_parent(collider, body, &mut physics.bodies);
            blocks.push(PreciseBlock {
                name: spec.name.clone(),
                body,
                collider,
                mode: BlockMode::Free,
                touching: false,
                floor_contacts: 0,
                thickness,
                radius,
                bullet: false,
                chosen_at: 0,
                judged_at: 0,
                judged: BlockMode::Free,
            });
        }
        let hand =
            (e.hand != HandEffect::None).then(|| HandBodies::new(p.bare_finger_radius, p.friction));
        let n = blocks.len();
        Ok(PreciseWorld {
            touches: Vec::with_capacity(n),
            modes: Vec::with_capacity(n),
            fast: Vec::with_capacity(n),
            choice: bullets::BulletChoice::default(),
            bullets: Vec::with_capacity(n),
            block_of_body,
            // Every body starts awake (and is judged after the first step).
            awake_before: (0..n).collect(),
            awake_now: Vec::with_capacity(n),
            judge: Vec::with_capacity(n),
            swept: Vec::with_capacity(n),
            grasped: 0,
            judge_all: false,
            pipeline_ns: 0,
            file: scene.file.clone(),
            physics,
            events: Vec::with_capacity(16 * blocks.len() + 16),
            blocks,
            hand,
            settings: p,
            dt,
            grasp_angle: w.grasp_angle,
            release_angle: w.release_angle,
            steps: 0,
            prev_hand: None,
            anchor,
            rejected_hands: 0,
            fingers: Fingers {
                count: 0,
                point_count: [0; MAX_FINGERS],
                points: [[[0.0; 3]; MAX_FINGER_POINTS]; MAX_FINGERS],
            },
        })
    }

    /// Hand samples this world refused where they entered (`hand::unusable_because`).
    pub fn rejected_hand_samples(&self) -> u64 {
        self.rejected_hands
    }

    /// The world frame's origin in the scene's ([`local_origin`]).
    pub fn anchor(&self) -> DVec3 {
        self.anchor
    }

    /// `hand` in the world's frame: a translated copy when the anchor is not zero, else none
    /// (the caller uses `hand` itself: not a bit changes near the origin).
    fn in_world_frame(&self, hand: &HandSample) -> Option<HandSample> {
        (self.anchor != DVec3::ZERO).then(|| {
            let mut local = *hand;
            translate_hand(hand, -self.anchor, &mut local);
            local
        })
    }

    /// The hand the first step starts from (see `World::set_previous_hand`): the kinematic
    /// colliders are placed there, so the first step moves them with the hand's own velocity.
    pub fn set_previous_hand(&mut self, hand: Option<&HandSample>) {
        self.prev_hand = hand
            .filter(|h| hand::is_usable(h))
            .map(|h| self.in_world_frame(h).unwrap_or(*h));
        if let (Some(bodies), Some(h)) = (self.hand.as_mut(), self.prev_hand.as_ref()) {
            bodies.place(&mut self.physics, h);
        }
    }

    /// One fixed step of 1 / step_hz with the hand's pose at this step (None: no hand this
    /// step, its colliders are switched off; a hand the rules cannot use, a value not finite
    /// or out of range: refused and counted, the hand holds its last good pose).
    pub fn step(&mut self, hand: Option<&HandSample>) {
        self.steps += 1;
        self.events.clear();
        // A hand the rules cannot use is refused where it enters, and the hand holds its last
        // good pose (already in the world's frame), as in the paper model. A usable one enters
        // the world's frame here (translated only when the anchor is not zero).
        let local = match hand {
            Some(h) if !hand::is_usable(h) => {
                self.rejected_hands += 1;
                self.prev_hand
            }
            Some(h) => self.in_world_frame(h),
            None => None,
        };
        let hand = if local.is_some() {
            local.as_ref()
        } else {
            hand.filter(|h| hand::is_usable(h))
        };
        if let Some(bodies) = self.hand.as_mut() {
            match hand {
                Some(h) => {
                    if self.prev_hand.is_none() || bodies.needs_layout(h) {
                        bodies.place(&mut self.physics, h);
                    }
                    bodies.drive(&mut self.physics, h);
                }
                None => bodies.switch_off(&mut self.physics),
            }
        }
        if self.settings.ccd {
            self.choose_bullets();
        }
        let t0 = Instant::now();
        self.physics.step();
        self.pipeline_ns += t0.elapsed().as_nanos() as u64;
        self.settle_modes();
        self.fingers.copy_from(hand);
        self.prev_hand = hand.copied();
    }

    /// CCD (`ccd = true`): which blocks are rapier's "bullets" this step. rapier sweeps every
    /// fast dynamic body against fixed colliders (the floor) on its own; a body with
    /// `ccd_enabled` (a bullet) also sweeps the kinematic and dynamic bodies, but never another
    /// bullet (rapier's `ccd::sweeps::tier_allows`). With `ccd_enabled` on every block no block
    /// ever swept another one: a 200 m/s cube passed a 1 cm wall block. So a block is a
    /// bullet only while it moves fast (rapier's criterion: its farthest point moves more than
    /// half its thinnest extent in the step), fastest first, and not when its swept box meets a
    /// faster bullet's (that bullet sweeps it: the two are swept against each other once).
    /// Slow blocks are never bullets: they are the targets.
    ///
    /// The meeting boxes come from a grid ([`bullets::BulletChoice`]: near-linear, the same
    /// choice as testing each block against every bullet so far, which cost ~8 M box tests a
    /// step in a rain of 4096 cubes), and only a body whose flag changes is written: rapier's
    /// `get_mut` files a body as modified, and every modified body is re-examined by the
    /// pipeline's next step.
    fn choose_bullets(&mut self) {
        let dt = self.dt;
        let g = self.physics.gravity;
        self.fast.clear();
        for (i, b) in self.blocks.iter().enumerate() {
            let body = &self.physics.bodies[b.body];
            let v = body.linvel() + g * dt;
            let motion = (v.length() + body.angvel().length() * b.radius) * dt;
            if motion > 0.5 * b.thickness {
                self.fast.push((motion, i));
            }
        }
        // Fastest first; equal motions by index (deterministic).
        self.fast
            .sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        self.choice.clear();
        for &(motion, i) in &self.fast {
            let b = &self.blocks[i];
            let body = &self.physics.bodies[b.body];
            let p0 = body.translation();
            let p1 = p0 + (body.linvel() + g * dt) * dt;
            let reach = DVec3::splat(b.radius + (motion - (p1 - p0).length()).max(0.0));
            self.choice.push(p0.min(p1) - reach, p0.max(p1) + reach);
        }
        let step = self.steps;
        for &rank in self.choice.choose() {
            let i = self.fast[rank as usize].1;
            let b = &mut self.blocks[i];
            b.chosen_at = step;
            if !b.bullet {
                b.bullet = true;
                self.bullets.push(i);
                if let Some(body) = self.physics.bodies.get_mut(b.body) {
                    body.enable_ccd(true);
                }
            }
        }
        let (blocks, bodies) = (&mut self.blocks, &mut self.physics.bodies);
        self.bullets.retain(|&i| {
            let b = &mut blocks[i];
            if b.chosen_at == step {
                return true;
            }
            b.bullet = false;
            if let Some(body) = bodies.get_mut(b.body) {
                body.enable_ccd(false);
            }
            false
        });
    }

    fn emit(&mut self, kind: EventKind, block: usize) {
        self.events.push(Event {
            step: self.steps,
            kind,
            block,
            hands: 0,
        });
    }

    /// The `world` sample's header: steps, block count, the grasped block and the hand's check
    /// points as they are (the engine keeps fingers outside blocks by pushing the blocks, not
    /// by relocating the fingers), in the scene's frame. Leaves `stamp` and `hand_seq` alone.
    pub fn write_header(&self, out: &mut WorldHeader) {
        out.step = self.steps;
        out.block_count = self.blocks.len() as u32;
        out.grasped_block = self
            .blocks
            .iter()
            .position(|b| b.mode == BlockMode::Grasped)
            .map_or(-1, |i| i as i32);
        out.finger_count = self.fingers.count;
        out.finger_point_count = self.fingers.point_count;
        out.finger_points = self.fingers.points;
        finger_points_to_scene(out, self.anchor);
    }

    /// Block `i`'s state in the `world` sample: its body's pose and the mode.
    pub fn block_state(&self, i: usize) -> BlockState {
        let b = &self.blocks[i];
        let body = &self.physics.bodies[b.body];
        BlockState {
            pose: Pose {
                position: to_scene(body.translation(), self.anchor).to_array(),
                rotation: body.rotation().to_array(),
            },
            mode: b.mode as u32,
            // The precise model takes one hand (slot 0).
            held_by: u32::from(b.mode == BlockMode::Grasped),
        }
    }

    /// The whole `world` sample, held by value (see `World::write_sample`).
    pub fn write_sample(&self, out: &mut WorldSample) {
        self.write_header(&mut out.header);
        out.blocks.clear();
        out.blocks
            .extend((0..self.blocks.len()).map(|i| self.block_state(i)));
    }

    pub fn steps(&self) -> u64 {
        self.steps
    }

    pub fn events(&self) -> &[Event] {
        &self.events
    }

    pub fn block_count(&self) -> usize {
        self.blocks.len()
    }

    pub fn block_names(&self) -> impl Iterator<Item = &str> {
        self.blocks.iter().map(|b| b.name.as_str())
    }

    /// Block `i`'s G, rotation, derived mode, and its velocity as a displacement per step (the
    /// paper's v, for comparison).
    pub fn block(&self, i: usize) -> Option<BlockView> {
        let b = self.blocks.get(i)?;
        let body = &self.physics.bodies[b.body];
        Some(BlockView {
            position: to_scene(body.translation(), self.anchor),
            rotation: *body.rotation(),
            mode: b.mode,
            v: body.linvel() * self.dt,
            floor_contacts: b.floor_contacts,
        })
    }

    /// Bodies the engine disabled because their state went non-finite (none, normally).
    pub fn quarantined(&self) -> usize {
        self.physics.quarantine().bodies().len()
    }

    pub fn file(&self) -> &std::path::Path {
        &self.file
    }

    /// Sets block `i`'s linear (m/s) and angular (rad/s, the world's frame) velocity, waking
    /// it: a scene gives a block's start velocity but no spin (the paper's free motion has
    /// none), and `handblocks bench tosses` starts a real toss with both.
    pub fn set_velocity(&mut self, i: usize, linear: DVec3, angular: DVec3) {
        let Some(b) = self.blocks.get(i) else { return };
        if !(linear.is_finite() && angular.is_finite()) {
            return;
        }
        if let Some(body) = self.physics.bodies.get_mut(b.body) {
            body.set_linvel(linear, true);
            body.set_angvel(angular, true);
        }
    }

    /// The settings this world runs with.
    pub fn settings(&self) -> &PreciseSettings {
        &self.settings
    }

    /// Nanoseconds spent inside rapier's `PhysicsPipeline::step` over every step so far: the
    /// rest of a step's time is our wrapper's (hand colliders, bullets, modes), which
    /// `bench stepper` reports apart so that the precise model is not charged for it unseen.
    pub fn pipeline_ns(&self) -> u64 {
        self.pipeline_ns
    }
}
