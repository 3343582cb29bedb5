//! The precise reference model (MODEL.md, "The precise reference model"): the same scene under
//! a full rigid-body engine, rapier3d (f64), as the yardstick for "what accuracy costs in time".
//!
//! Each block is a dynamic convex-hull collider built from the very polyhedron the paper model
//! uses ([`Polyhedron::from_spec`], G at the body origin), with restitution 0 and a high Coulomb
//! friction (the paper's "perfect friction"), CCD on; the floor is a fixed half-space; the hand
//! is a set of kinematic colliders (module [`hand`]) moved to each step's hand pose, so push,
//! grasp, carry and throw scenes run here too. The engine knows nothing of the paper's modes,
//! so module [`modes`] derives one per block from its contacts and velocities, with the paper's
//! own grasp rule (R3's grasp_angle over the contact normals).
//!
//! Time is the paper model's: one [`PreciseWorld::step`] is one fixed step of 1 / step_hz, the
//! stepper's timeline decides how many steps a hand sample brings, and nothing reads a clock.
//! rapier without its `parallel` feature is deterministic for the same binary and inputs, so
//! two runs give identical bytes.
//!
//! No rapier type leaves this module: the rest of the crate sees poses, modes and events
//! through [`crate::model::Model`].

mod hand;
mod modes;

use std::path::PathBuf;

use glam::{DQuat, DVec3};
use rapier3d_f64::prelude::{
    CoefficientCombineRule, ColliderBuilder, ColliderHandle, FrictionModel, PhysicsWorld,
    RigidBodyBuilder, RigidBodyHandle, SharedShape, SpringCoefficients, Vector,
};

use common::config::scene::{FloorEffect, HandEffect, PreciseSettings};
use common::config::Scene;
use common::{BlockMode, HandSample, WorldSample, MAX_FINGERS, MAX_FINGER_POINTS};

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
    prev_hand: Option<HandSample>,
    fingers: Fingers,
    /// Scratch of the mode derivation, kept so that a step does not allocate.
    touches: Vec<modes::Touches>,
    modes: Vec<BlockMode>,
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
                .restitution(0.0)
                .user_data(KIND_FLOOR)
                .build();
            physics.colliders.insert(floor);
        }
        let mut blocks = Vec::with_capacity(scene.blocks.len());
        for (i, spec) in scene.blocks.iter().enumerate() {
            let bad = |problem: String| WorldError {
                file: scene.file.clone(),
                block: Some(spec.name.clone()),
                problem,
            };
            let poly =
                Polyhedron::from_spec(&spec.shape).map_err(|p| bad(format!("shape: {p}")))?;
            let points: Vec<Vector> = poly.vertices.to_vec();
            let collider = ColliderBuilder::convex_hull(&points)
                .ok_or_else(|| bad("rapier3d cannot build a convex hull of its vertices".into()))?
                .friction(p.friction)
                .friction_combine_rule(CoefficientCombineRule::Max)
                .restitution(0.0)
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
                .translation(DVec3::from_array(spec.position))
                .linvel(velocity)
                .ccd_enabled(p.ccd)
                .can_sleep(p.sleep)
                .build();
            body.set_rotation(rot, false);
            let body = physics.bodies.insert(body);
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
            });
        }
        let hand =
            (e.hand != HandEffect::None).then(|| HandBodies::new(p.bare_finger_radius, p.friction));
        let n = blocks.len();
        Ok(PreciseWorld {
            touches: Vec::with_capacity(n),
            modes: Vec::with_capacity(n),
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
            fingers: Fingers {
                count: 0,
                point_count: [0; MAX_FINGERS],
                points: [[[0.0; 3]; MAX_FINGER_POINTS]; MAX_FINGERS],
            },
        })
    }

    /// The hand the first step starts from (see `World::set_previous_hand`): the kinematic
    /// colliders are placed there, so the first step moves them with the hand's own velocity.
    pub fn set_previous_hand(&mut self, hand: Option<&HandSample>) {
        self.prev_hand = hand.filter(|h| hand::is_usable(h)).copied();
        if let (Some(bodies), Some(h)) = (self.hand.as_mut(), self.prev_hand.as_ref()) {
            bodies.place(&mut self.physics, h);
        }
    }

    /// One fixed step of 1 / step_hz with the hand's pose at this step (None, or a hand with
    /// a non-finite value: no hand this step, its colliders are switched off).
    pub fn step(&mut self, hand: Option<&HandSample>) {
        self.steps += 1;
        self.events.clear();
        let hand = hand.filter(|h| hand::is_usable(h));
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
        self.physics.step();
        self.settle_modes();
        self.copy_fingers(hand);
        self.prev_hand = hand.copied();
    }

    fn copy_fingers(&mut self, hand: Option<&HandSample>) {
        match hand {
            Some(h) => {
                let fc = (h.finger_count as usize).min(MAX_FINGERS);
                self.fingers.count = fc as u32;
                for f in 0..MAX_FINGERS {
                    self.fingers.point_count[f] = if f < fc {
                        h.finger_point_count[f].min(MAX_FINGER_POINTS as u32)
                    } else {
                        0
                    };
                }
                self.fingers.points = h.finger_points;
            }
            None => {
                self.fingers.count = 0;
                self.fingers.point_count = [0; MAX_FINGERS];
            }
        }
    }

    fn emit(&mut self, kind: EventKind, block: usize) {
        self.events.push(Event {
            step: self.steps,
            kind,
            block,
        });
    }

    /// Block poses (pose of G), modes, the grasped block and the hand's check points as they
    /// are (the engine keeps fingers outside blocks by pushing the blocks, not by relocating
    /// the fingers). Leaves `out.stamp` and `out.hand_seq` alone.
    pub fn write_sample(&self, out: &mut WorldSample) {
        out.step = self.steps;
        out.block_count = self.blocks.len() as u32;
        out.grasped_block = -1;
        for (i, b) in self.blocks.iter().enumerate() {
            let body = &self.physics.bodies[b.body];
            out.blocks[i].pose.position = body.translation().to_array();
            out.blocks[i].pose.rotation = body.rotation().to_array();
            out.blocks[i].mode = b.mode as u32;
            if b.mode == BlockMode::Grasped && out.grasped_block < 0 {
                out.grasped_block = i as i32;
            }
        }
        out.finger_count = self.fingers.count;
        out.finger_point_count = self.fingers.point_count;
        out.finger_points = self.fingers.points;
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
            position: body.translation(),
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

    /// The settings this world runs with.
    pub fn settings(&self) -> &PreciseSettings {
        &self.settings
    }
}
