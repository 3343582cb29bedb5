//! The world and its step, in docs/model.md's "Order of one step".
//!
//! [`World::step`] reads as that order, stages 1-6 between the step's start (0) and end (7): each
//! stage is a function of the child module `step`, named for what it does, calling the rules'
//! functions and stage structs' methods in their own modules (`hand` R1-R6 and R13's release,
//! `interference` R10, `support` R14, `motion` R7 with R11-R12, `floor` R8-R9), and is handed
//! exactly what it reads and writes: the blocks, the hand now and before, the scene's
//! settings, its own scratch, the step's events. So the step shows its data flow, and no stage
//! needs the world (as rapier's pipeline hands each stage the sets it touches). The passes a
//! scene does not enable (docs/design.md "Effects") are decided once in [`World::new`] and cost
//! one branch per step; resting blocks that nothing touches are skipped.

use std::fmt;
use std::path::PathBuf;
use std::sync::Arc;

use glam::{DQuat, DVec3};

use common::config::scene::{FloorEffect, HandEffect, ShapeSpec, Stacking};
use common::config::Scene;
use common::{BlockMode, BlockState, HandSample, Pose, WorldHeader, WorldSample, MAX_SCENE_BLOCKS};

use crate::anchor::{finger_points_to_scene, to_scene, translate_hand};
pub use crate::anchor::{local_origin, ANCHOR_GRID_M, ANCHOR_NEAR_M};
use crate::block_set::BlockSet;
use crate::body::Block;
use crate::event::StepEvents;
pub use crate::event::{Event, EventKind};
use crate::floor::Floor;
use crate::geometry::{sat_depth, Polyhedron};
use crate::grid::BlockGrid;
// The check points as drawn are the hand's (R5 relocates them); the precise model fills the same.
pub(crate) use crate::hand::Fingers;
use crate::hand::{check_point_box, is_usable, HandContacts, EMPTY_BOX};
use crate::interference::Carry;
use crate::settings::{Passes, Settings};
use crate::support::Support;
use crate::tracked::{GripPath, TrackedCounts, TrackedRules};
use crate::two_hands::TwoHands;
use crate::HAND_SLOTS;

mod step;

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

/// The block world: docs/model.md's paper model (rules R1-R13, and R14 when the scene asks for it).
pub struct World {
    file: PathBuf,
    settings: Settings,
    passes: Passes,
    blocks: Vec<Block>,
    steps: u64,
    events: StepEvents,
    // ---- each hand's own state, by hand slot (`HAND_SLOTS`: slot 1 only in a two-hand world)
    /// The hand at the previous step (P-, W-), when there was one.
    prev_hand: [Option<HandSample>; HAND_SLOTS],
    /// The box of its check points (`hand::check_point_box`; empty without one).
    prev_hand_box: [(DVec3, DVec3); HAND_SLOTS],
    /// The check points as drawn (R5's relocation).
    fingers: [Fingers; HAND_SLOTS],
    /// Whether a second hand has taken part (a step given slot 1's hand): from then on every
    /// step decides each hand's actions apart and combines them (`TwoHands`); before it, a
    /// step is the one-hand step exactly.
    /// The hand slots given a hand so far (bit k: slot k; slot 0 always): the slots a step
    /// decides, so that a world of one or two hands costs what it did before shared worlds.
    slots_seen: u8,
    two_hands: TwoHands,
    // ---- the stages that keep scratch, each its own, preallocated so that a step does not
    // allocate ----
    hand_contacts: HandContacts,
    carry: Carry,
    support: Support,
    floor: Floor,
    /// Free motion's broad phase (R7 with R11, R12).
    grid: BlockGrid,
    /// The blocks a step must look at: every block not at rest, and any at rest that a stage
    /// touched. A block outside it rests, untouched, with its step scratch as stage 0 finds
    /// it (`Block::begin_step`), so no stage has anything to do with it ("resting blocks that
    /// nothing touches cost nothing"); it joins again when the hand, a carry or R14 touches it.
    active: BlockSet,
    /// Stage 6's blocks that leave `active`.
    quiet: BlockSet,
    /// The blocks that free motion left in the air, with no mode change: their floor stage and
    /// stage 6 are done in free motion's pass (`World::step`, stage 4), and the last pass skips
    /// them.
    flown: BlockSet,
    /// Stage 6's events of the step, appended to `events` after the floor stage's.
    settled: StepEvents,
    /// Each block's `world` sample entry (pose of G, mode) as the last step left it, side by
    /// side: stage 6 rewrites the active blocks' entries (a block outside `active` did not
    /// change). Publishing a world then reads 64 contiguous bytes a block instead of
    /// gathering from every block's large state: a live stepper that sleeps between samples
    /// steps with cold caches, and the gather was the larger part of its time at 1024 blocks.
    states: Vec<BlockState>,
    /// Where the world's own frame is in the scene's: a point on the floor near the blocks
    /// ([`local_origin`], module `anchor`, the precise model's rule too). Blocks, the hand and
    /// every stage work in the world's frame, so a scene far from the scene's origin computes
    /// with numbers of the size it computes with at the origin: f64 rounds a position at 99 km
    /// to 1.5e-11 m, and a step's `pos + d` there lost that much every step, which a toppling
    /// stack or a tip past an edge amplified to 0.2 mm (and a block came to rest 17 um above
    /// the floor). Poses and check points cross into this frame where the world takes them
    /// (the scene, the hand) and out where it gives them (the `world` sample, [`World::block`]).
    /// Zero for a scene within 32 m of the origin: nothing moves and not a bit changes there.
    anchor: DVec3,
    /// Hand samples refused where they entered the world (`hand::unusable_because`: a value
    /// not finite, a point beyond `hand::HAND_RANGE_M`): the hand holds its last good pose
    /// for that step.
    rejected_hands: u64,
    /// The hand of this step in the world's frame (when `anchor` is not zero): the sample
    /// translated once, where it enters, into preallocated space.
    hand_local: [HandSample; HAND_SLOTS],
    /// T2: consecutive steps the hand has not been tracked (or absent), under tracked rules.
    untracked_steps: [u64; HAND_SLOTS],
    /// What the tracked rules did.
    tracked_counts: TrackedCounts,
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
        if scene.blocks.len() > MAX_SCENE_BLOCKS {
            return Err(err(
                scene,
                None,
                format!("{} blocks; at most {MAX_SCENE_BLOCKS}", scene.blocks.len()),
            ));
        }
        let dt = 1.0 / w.step_hz;
        let e = &scene.effects;
        let settings = Settings {
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
            tracked: TrackedRules::of(w.hands, &w.tracked, w.step_hz),
        };
        let mut blocks = Vec::with_capacity(scene.blocks.len());
        let mut max_vertices = 0;
        // Each distinct shape's hull once, shared by its blocks (body.rs: `Block::poly`).
        // Scenes hold few distinct shapes: a linear search.
        let mut hulls: Vec<(&ShapeSpec, Arc<Polyhedron>)> = Vec::new();
        let anchor = local_origin(scene.blocks.iter().map(|b| b.position));
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
            let poly = match hulls.iter().find(|(shape, _)| **shape == spec.shape) {
                Some((_, hull)) => Arc::clone(hull),
                None => {
                    let hull = Arc::new(
                        Polyhedron::from_spec(&spec.shape)
                            .map_err(|p| err(scene, Some(&spec.name), format!("shape: {p}")))?,
                    );
                    hulls.push((&spec.shape, Arc::clone(&hull)));
                    hull
                }
            };
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
                DVec3::from_array(spec.position) - anchor,
                q,
                v,
                w.throw_window as usize,
            ));
        }
        // R14's sets of blocks are sized for this world once, here; so are T3's paths.
        let n = blocks.len();
        let path_capacity = settings.tracked.map_or(0, |t| t.path_capacity());
        for b in &mut blocks {
            b.tipped_over = BlockSet::new(n);
            b.grip = GripPath::with_capacity(path_capacity);
        }
        // Geometric validation (the loader checks form and ranges, we check shapes).
        if e.floor != FloorEffect::None {
            for b in &blocks {
                let low = b.pos().y + b.lowest_rel_y();
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
        // Pairs that start inside each other, the first by (i, j): the grid's blocks near
        // each one, in index order, rather than every pair (8 million at 4096 blocks).
        let mut grid = BlockGrid::new(&blocks);
        for i in 0..blocks.len() {
            let near = grid.near_any_order(
                &blocks,
                blocks[i].pos(),
                blocks[i].poly.radius + w.contact_eps,
            );
            near.sort_unstable();
            for j in near.iter().map(|&j| j as usize).filter(|&j| j > i) {
                let (a, b) = (&blocks[i], &blocks[j]);
                let off = b.pos() - a.pos();
                if off.length() > a.poly.radius + b.poly.radius + w.contact_eps {
                    continue;
                }
                let depth = sat_depth(&a.poly, a.rot(), &a.rel, &b.poly, b.rot(), &b.rel, off);
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
        // Every block is looked at in the first step (a block that starts on the floor has its
        // first impact then).
        let mut active = BlockSet::new(n);
        (0..n).for_each(|i| active.insert(i));
        // Stage 0 for the first step (the last step's stage 6 does it for the others).
        blocks.iter_mut().for_each(Block::begin_step);
        let states = blocks.iter().map(|b| state_of(b, anchor)).collect();
        Ok(World {
            file: scene.file.clone(),
            settings,
            passes,
            blocks,
            steps: 0,
            events: StepEvents::with_capacity(16 * n + 16),
            prev_hand: [None; HAND_SLOTS],
            prev_hand_box: [EMPTY_BOX; HAND_SLOTS],
            fingers: [Fingers::NONE; HAND_SLOTS],
            slots_seen: 1,
            two_hands: TwoHands::new(n),
            hand_contacts: HandContacts::new(),
            carry: Carry::new(n),
            floor: Floor::new(max_vertices),
            grid,
            active,
            quiet: BlockSet::new(n),
            flown: BlockSet::new(n),
            // Stage 6 reports at most a release and a mode change a block.
            settled: StepEvents::with_capacity(2 * n + 16),
            states,
            support: Support::new(
                if e.stacking == Stacking::Supported {
                    n
                } else {
                    0
                },
                max_vertices,
            ),
            anchor,
            hand_local: [HandSample::default(); HAND_SLOTS],
            rejected_hands: 0,
            untracked_steps: [0; HAND_SLOTS],
            tracked_counts: TrackedCounts::default(),
        })
    }

    /// What the tracked rules (T1-T3) did; all zero under the paper's.
    pub fn tracked_counts(&self) -> TrackedCounts {
        self.tracked_counts
    }

    /// Hand samples this world refused where they entered (`hand::unusable_because`).
    pub fn rejected_hand_samples(&self) -> u64 {
        self.rejected_hands
    }

    /// The world frame's origin in the scene's ([`local_origin`]).
    pub fn anchor(&self) -> DVec3 {
        self.anchor
    }

    /// `hand` in the world's frame: itself when the anchor is zero, else translated into
    /// `hand_local`.
    fn hand_in_world_frame<'a>(
        anchor: DVec3,
        hand: Option<&'a HandSample>,
        hand_local: &'a mut HandSample,
    ) -> Option<&'a HandSample> {
        match hand {
            Some(h) if anchor != DVec3::ZERO => {
                translate_hand(h, -anchor, hand_local);
                Some(hand_local)
            }
            other => other,
        }
    }

    /// Exactly one fixed step (dt = 1 / step_hz) with the hand's pose at this step; the world
    /// keeps the previous one itself (P-, W-). `None` is "no hand this step"; a hand the rules
    /// cannot use (`hand::unusable_because`: a value not finite, a point out of range) is
    /// refused and counted, and the hand holds its last good pose. The one hand is slot 0's
    /// ([`World::step_hands`]).
    pub fn step(&mut self, hand: Option<&HandSample>) {
        self.step_hands([hand]);
    }

    /// Exactly one fixed step with each hand's pose at this step, by hand slot
    /// ([`HAND_SLOTS`]: slot 0 the right, slot 1 the left, then each participant's of a shared
    /// world; `N` slots given, the rest None, at most [`HAND_SLOTS`] read). Until another slot
    /// than 0 is first given a hand this is the one-hand step, bit for bit; from then on each
    /// hand's actions are decided apart and combined block by block (docs/model.md "Two
    /// hands"). It reads as docs/model.md's "Order of one step": each stage a function of
    /// module `step`, handed what it reads and writes; the passes the scene does not enable
    /// are skipped here, in the open.
    pub fn step_hands<const N: usize>(&mut self, given: [Option<&HandSample>; N]) {
        let mut hands = [None; HAND_SLOTS];
        for (slot, hand) in hands.iter_mut().zip(given) {
            *slot = hand;
        }
        self.steps += 1;
        for (k, hand) in hands.iter().enumerate() {
            self.slots_seen |= u8::from(hand.is_some()) << k;
        }
        let (steps, seen) = (self.steps, self.slots_seen);
        let two = seen > 1;
        let World {
            settings,
            passes,
            blocks,
            events,
            prev_hand,
            prev_hand_box,
            fingers,
            two_hands,
            hand_contacts,
            carry,
            support,
            floor,
            grid,
            active,
            quiet,
            flown,
            settled,
            states,
            anchor,
            hand_local,
            untracked_steps,
            tracked_counts,
            rejected_hands,
            ..
        } = self;
        let anchor = *anchor;
        // 0. The step's start: the hands enter the world's frame (a hand the rules cannot use
        //    holds its last good pose), the step's events and scratch begin.
        let now = step::take_hands(hands, anchor, prev_hand, hand_local, rejected_hands);
        let prev = prev_hand.each_ref().map(Option::as_ref);
        step::start_step(steps, two, events, settled, quiet, flown, fingers, now);
        // Whether a stage moved blocks without telling the grid (the hand's, R14's) since the
        // last step's stage 6 brought it up to date: free motion then syncs it first.
        let mut grid_behind = false;
        if passes.hand {
            // 1. Hand contacts (R1-R3; T1-T2 under tracked hands; H1-H2 with two) for every
            //    block near a hand, then R13 ends the grasps they no longer confirm.
            let (acted, gaps) = step::decide_hand_actions(
                blocks,
                active,
                grid,
                hand_contacts,
                two_hands,
                events,
                prev_hand_box,
                untracked_steps,
                tracked_counts,
                now,
                prev,
                settings,
                passes,
                steps,
                seen,
            );
            // 2. Hand-driven motion (R5, R4, R6), then carry (R10) from the blocks it moved.
            grid_behind |= step::move_with_hands(
                blocks, active, grid, carry, fingers, now, prev, gaps, acted, settings, passes,
                steps, two,
            );
        }
        // 3. Supported stacking (R14, when the scene asks for it): blocks on blocks are judged
        //    bottom up, held or tipped with their load.
        if passes.supported {
            support.judge_stacks(blocks, active, settings, passes);
            grid_behind = true;
        }
        // 4. Free motion (R7, with R12) for the rest, except blocks held by R11 or R14; none
        //    without gravity and inertia.
        if passes.free_motion {
            step::move_free_blocks(
                blocks,
                active,
                grid,
                grid_behind,
                quiet,
                flown,
                settled,
                states,
                settings,
                passes,
                anchor,
            );
            grid_behind = false;
        }
        // 5. Floor (R8, R9) for every block that moved or is in floor contact, not resting;
        // 6. releases (R13) take effect for the next step, modes and events are settled: both
        //    in one pass, block by block.
        step::land_and_settle(
            blocks,
            active,
            grid,
            grid_behind,
            floor,
            quiet,
            flown,
            events,
            settled,
            states,
            settings,
            passes,
            anchor,
        );
        // 7. This step's hands are the next step's previous ones.
        step::keep_hands(prev_hand, prev_hand_box, now);
    }

    /// Sets the hand the next step takes as its previous one (P-, W-) without stepping: a
    /// caller that knows the hand before the first step (a scripted hand at t = 0) gives it
    /// here so that the first step sees the hand's motion, not a standing start.
    pub fn set_previous_hand(&mut self, hand: Option<&HandSample>) {
        self.set_previous_hand_of(0, hand);
    }

    /// [`World::set_previous_hand`] for the hand in slot `slot` (< [`HAND_SLOTS`]).
    pub fn set_previous_hand_of(&mut self, slot: usize, hand: Option<&HandSample>) {
        let slot = slot.min(HAND_SLOTS - 1);
        self.prev_hand[slot] = World::hand_in_world_frame(
            self.anchor,
            hand.filter(|h| is_usable(h)),
            &mut self.hand_local[slot],
        )
        .copied();
        self.prev_hand_box[slot] = self.prev_hand[slot]
            .as_ref()
            .map_or(EMPTY_BOX, check_point_box);
    }

    /// The `world` sample's header: steps, block count, the grasped block and the check points
    /// as drawn (R5's relocated finger points). Leaves `stamp` and `hand_seq` alone.
    pub fn write_header(&self, out: &mut WorldHeader) {
        out.step = self.steps;
        out.block_count = self.blocks.len() as u32;
        // The first grasped block: a grasped block is never at rest, so it is in `active`,
        // which iterates lowest first (no pass over every block).
        out.grasped_block = self
            .active
            .iter()
            .find(|&i| self.blocks[i].mode == BlockMode::Grasped)
            .map_or(-1, |i| i as i32);
        let fingers = &self.fingers[0];
        out.finger_count = fingers.count;
        out.finger_point_count = fingers.point_count;
        out.finger_points = fingers.points;
        finger_points_to_scene(out, self.anchor);
    }

    /// Block `i`'s state in the `world` sample: the pose of G and the mode.
    pub fn block_state(&self, i: usize) -> BlockState {
        self.states[i]
    }

    /// The whole `world` sample, held by value ([`World::write_header`] and each
    /// [`World::block_state`]); allocates only when the sample's block vector must grow.
    pub fn write_sample(&self, out: &mut WorldSample) {
        self.write_header(&mut out.header);
        out.blocks.clear();
        out.blocks
            .extend((0..self.blocks.len()).map(|i| self.block_state(i)));
    }

    /// Fixed steps taken since the world began.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// What happened in the last step.
    pub fn events(&self) -> &[Event] {
        self.events.as_slice()
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
            position: to_scene(b.pos(), self.anchor),
            rotation: b.rot(),
            mode: b.mode,
            v: b.v,
            floor_contacts: b.floor().len(),
        })
    }

    /// Block `i`'s vertices in the world frame (for tests and tools).
    pub fn block_vertices(&self, i: usize) -> impl Iterator<Item = DVec3> + '_ {
        self.blocks.get(i).into_iter().flat_map(move |b| {
            let anchor = self.anchor;
            b.poly
                .vertices
                .iter()
                .map(move |v| to_scene(b.pos(), anchor) + b.rot() * *v)
        })
    }

    /// The scene file this world came from.
    pub fn file(&self) -> &std::path::Path {
        &self.file
    }
}

/// Block `b`'s entry of the `world` sample: the pose of G and the mode.
fn state_of(b: &Block, anchor: DVec3) -> BlockState {
    BlockState {
        pose: Pose {
            position: to_scene(b.pos(), anchor).to_array(),
            rotation: b.rot().to_array(),
        },
        mode: b.mode as u32,
        held_by: u32::from(b.held_by),
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
