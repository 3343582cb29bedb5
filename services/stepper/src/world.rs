//! The world and its step, in docs/model.md's "Order of one step".
//!
//! [`World::step`] reads as that order: each stage is a function or a stage struct's method,
//! named for its rules, in its own module (`hand` R1-R6 and R13's release, `interference` R10,
//! `support` R14, `motion` R7 with R11-R12, `floor` R8-R9), and is handed exactly what it reads
//! and writes: the blocks, the hand now and before, the scene's settings, its own scratch, the
//! step's events. So the step shows its data flow, and no stage module needs the world (as
//! rapier's pipeline hands each stage the sets it touches). The passes a scene does not enable
//! (docs/design.md "Effects") are decided once in [`World::new`] and cost one branch per step;
//! resting blocks that nothing touches are skipped.

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
use crate::body::{Block, Moved};
use crate::event::StepEvents;
pub use crate::event::{Event, EventKind};
use crate::floor::{in_the_air, leave_the_floor, Floor};
use crate::geometry::{sat_depth, Polyhedron};
use crate::grid::BlockGrid;
// The check points as drawn are the hand's (R5 relocates them); the precise model fills the same.
pub(crate) use crate::hand::Fingers;
use crate::hand::{
    check_point_box, end_grasps, hand_reach, is_usable, move_by_hand, HandContacts, Letting,
    EMPTY_BOX,
};
use crate::interference::Carry;
use crate::motion::move_freely;
use crate::settings::{Passes, Settings};
use crate::support::Support;
use crate::tracked::{hold_grasps, GripPath, TrackedCounts, TrackedRules};
use crate::two_hands::TwoHands;
use crate::HAND_SLOTS;

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
    two_handed: bool,
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
    /// touched. A block outside it rests, untouched, with its step scratch as stage 0 would
    /// set it, so no stage has anything to do with it ("resting blocks that nothing touches
    /// cost nothing"); it joins again when the hand, a carry or R14 touches it.
    active: BlockSet,
    /// Stage 5's blocks that leave `active`.
    quiet: BlockSet,
    /// The blocks that free motion left in the air, with no mode change: their floor stage and
    /// stage 5 are done in free motion's pass (`World::step`, stage 3), and the last pass skips
    /// them.
    flown: BlockSet,
    /// Stage 5's events of the step, appended to `events` after the floor stage's.
    settled: StepEvents,
    /// Each block's `world` sample entry (pose of G, mode) as the last step left it, side by
    /// side: stage 5 rewrites the active blocks' entries (a block outside `active` did not
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
        // Stage 0 for the first step (the last step's stage 5 does it for the others).
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
            two_handed: false,
            two_hands: TwoHands::new(n),
            hand_contacts: HandContacts::new(),
            carry: Carry::new(n),
            floor: Floor::new(max_vertices),
            grid,
            active,
            quiet: BlockSet::new(n),
            flown: BlockSet::new(n),
            // Stage 5 reports at most a release and a mode change a block.
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
        self.step_hands([hand, None]);
    }

    /// Exactly one fixed step with each hand's pose at this step, by hand slot
    /// ([`HAND_SLOTS`]: slot 0 the right, slot 1 the left). Until slot 1 is first given a hand
    /// this is the one-hand step, bit for bit; from then on each hand's actions are decided
    /// apart and combined block by block (docs/model.md "Two hands"). docs/model.md "Order of
    /// one step", each stage handed what it reads and writes:
    pub fn step_hands(&mut self, hands: [Option<&HandSample>; HAND_SLOTS]) {
        self.steps += 1;
        self.two_handed |= hands[1].is_some();
        let two = self.two_handed;
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
        let mut now: [Option<&HandSample>; HAND_SLOTS] = [None; HAND_SLOTS];
        for ((slot, local), hand) in hand_local.iter_mut().enumerate().zip(hands) {
            let refused = hand.is_some_and(|h| !is_usable(h));
            *rejected_hands += u64::from(refused);
            now[slot] = if refused {
                // Refused where it enters: the hand holds its last good pose (already in this
                // frame), so a glitch of one sample neither drops what the hand grasps nor moves
                // it; a hand that was absent stays absent.
                match prev_hand[slot].as_ref() {
                    Some(last_good) => {
                        *local = *last_good;
                        Some(&*local)
                    }
                    None => None,
                }
            } else {
                World::hand_in_world_frame(anchor, hand, local)
            };
        }
        let prev = [prev_hand[0].as_ref(), prev_hand[1].as_ref()];
        // 0. Every block starts the step where it is, with nothing done to it yet: the last
        //    step's stage 5 left it so (`Block::begin_step`, in the same pass), and nothing changes a
        //    block between steps.
        events.begin(self.steps);
        events.name_hands = two;
        settled.name_hands = two;
        for (f, hand) in fingers.iter_mut().zip(now) {
            f.copy_from(hand);
        }
        // Whether a stage moved blocks without telling the grid (the hand's, R14's) since the
        // last step's stage 5 brought it up to date: free motion then syncs it first.
        let mut grid_behind = false;
        if passes.hand {
            let mut gaps = [None; HAND_SLOTS];
            let mut acted = false;
            for slot in 0..if two { HAND_SLOTS } else { 1 } {
                let (hand, prev) = (now[slot], prev[slot]);
                // T2 (tracked hands): a hand that is not tracked touches nothing new and keeps
                // what it holds, for up to gap_hold; then it lets go with no throw.
                let gap = match settings.tracked {
                    Some(t) if hand.is_none_or(|h| h.tracked == 0) => {
                        untracked_steps[slot] += 1;
                        Some(untracked_steps[slot] <= t.gap_hold_steps)
                    }
                    _ => {
                        untracked_steps[slot] = 0;
                        None
                    }
                };
                gaps[slot] = gap;
                // 1. Hand contacts (R1-R3) for every block near the hand: each block's hand
                //    action; then R13 ends the grasps they no longer confirm.
                acted |= match (hand, gap) {
                    (_, Some(hold)) => {
                        prev_hand_box[slot] = hand.map_or(EMPTY_BOX, check_point_box);
                        hold && hold_grasps(
                            blocks,
                            active,
                            slot,
                            untracked_steps[slot] == 1,
                            tracked_counts,
                        )
                    }
                    (Some(h), None) => {
                        let (now_box, before) = (check_point_box(h), prev_hand_box[slot]);
                        prev_hand_box[slot] = now_box;
                        match hand_reach(
                            blocks,
                            grid,
                            now_box,
                            before,
                            settings.contact_eps + settings.tracked.map_or(0.0, |t| t.grip_margin),
                        ) {
                            Some(reach) => hand_contacts.decide_actions(
                                blocks,
                                active,
                                grid,
                                slot,
                                h,
                                prev,
                                reach,
                                settings,
                                passes.grasp,
                                self.steps,
                                tracked_counts,
                            ),
                            None => false,
                        }
                    }
                    (None, None) => false,
                };
                // Two hands: this hand's actions are kept apart until both are decided.
                if two {
                    two_hands.keep(slot, blocks, active);
                }
            }
            if two {
                acted = two_hands.combine(blocks, settings, events);
            }
            // R5 grasps only with hand = "grasp": without it no block is ever grasped, and R13
            // has nothing to end (no pass over the active set: ~16 instructions a block).
            if passes.grasp {
                let letting_of = |held_by: u8| match settings.tracked {
                    None => Letting::Throw,
                    // T2: a drop when every hand that held it was lost for too long.
                    Some(_)
                        if (0..HAND_SLOTS)
                            .filter(|k| held_by & (1 << k) != 0)
                            .all(|k| gaps[k] == Some(false))
                            && held_by != 0 =>
                    {
                        Letting::Drop
                    }
                    Some(rules) => Letting::FittedThrow {
                        now: self.steps,
                        rules,
                    },
                };
                end_grasps(blocks, active, settings.inertia, letting_of, tracked_counts);
            }
            // 2. Hand-driven motion (R5, R4, R6), then carry (R10) from the blocks it moved. A
            //    hand that acts on nothing (far from every block, or no hand) moves nothing and
            //    carries nothing: neither stage runs, not even a pass over the active set.
            //    T3 keeps the path of what a tracked hand holds.
            let tracked_now = (0..HAND_SLOTS).any(|k| now[k].is_some() && gaps[k].is_none());
            let path_step = (settings.tracked.is_some() && tracked_now).then_some(self.steps);
            let moved = acted
                && now.iter().any(Option::is_some)
                && move_by_hand(blocks, active, now, prev, settings, fingers, path_step, two);
            if passes.carry && moved {
                carry.carry(blocks, active, grid, settings.hull_eps);
            }
            grid_behind |= moved;
        }
        // 3a. Supported stacking (R14, when the scene asks for it): blocks on blocks are judged
        //     bottom up, held or tipped with their load.
        if passes.supported {
            support.judge_stacks(blocks, active, settings, passes);
            grid_behind = true;
        }
        quiet.clear();
        flown.clear();
        settled.begin(self.steps);
        // 3. Free motion (R7, with R12) for the rest, except blocks held by R11 or R14. Without
        //    gravity and inertia nothing moves freely, and R11 has nothing to hold. The grid
        //    must see the hand's and R14's moves first.
        if passes.free_motion {
            if grid_behind {
                grid.sync(blocks, active);
                grid_behind = false;
            }
            for i in active.iter() {
                let Some(start) = move_freely(blocks, i, grid, settings, passes) else {
                    continue;
                };
                // A block it left in the air (most of a rain) has its floor stage and stage 5
                // now, while its lines are in the cache, instead of in the last pass: both
                // read and write this block only (`leave_the_floor`, `finish_block`), and no
                // later block's free motion reads what they change (it reads poses and boxes,
                // which they leave). Only when stage 5 reports nothing, so that `settled`
                // lists its events in block order.
                let b = &mut blocks[i];
                if (!passes.floor || in_the_air(b, settings.contact_eps))
                    && b.mode == b.mode_before
                    && !b.released
                {
                    if passes.floor {
                        leave_the_floor(b);
                    }
                    finish_block(i, b, Some(start), quiet, grid, settled, states, anchor);
                    flown.insert(i);
                } else {
                    b.record_start(start);
                }
            }
        }
        // 4. Floor (R8, R9) for every block that moved or is in floor contact, not resting;
        // 5. releases (R13) take effect for the next step; modes and events are settled, and
        //    this hand is the next step's previous one. Both in one pass, block by block (a
        //    block's floor stage reads of the others only their poses, which stage 5 leaves;
        //    `Floor::land_block`): stage 5's events wait in `settled` so that the list reads
        //    as the two stages one after the other (every impact, then the rest). The blocks
        //    free motion left flying had both already.
        // R14's check of an R9 turn asks the grid for the turning block's neighbours: it must
        // see every block where it is (stage 5 tells it of each block the floor stage moved,
        // before the next block's turn is checked).
        if passes.supported && passes.floor && grid_behind {
            grid.sync(blocks, active);
        }
        for i in active.iter_except(flown) {
            if passes.floor {
                floor.land_block(blocks, grid, i, settings, passes, events);
            }
            finish_block(
                i,
                &mut blocks[i],
                None,
                quiet,
                grid,
                settled,
                states,
                anchor,
            );
        }
        active.difference_with(quiet);
        events.append(settled);
        for slot in 0..HAND_SLOTS {
            prev_hand[slot] = now[slot].copied();
            if now[slot].is_none() {
                // With a hand, stage 1 kept its box for the next step (and without the hand's
                // stages nothing reads it).
                prev_hand_box[slot] = EMPTY_BOX;
            }
        }
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

/// Stage 5 for block i: the step's release (R13) and mode change as events, and whether R14
/// judges what touches it again in the next step (it moved or changed mode). A block that
/// rests and that nothing moved, turned, released or acted on this step goes into `quiet`, to
/// leave `active`: until a stage touches it, no step looks at it. It ends with its scratch as
/// the next step's stage 0 sets it (`Block::begin_step`). `start`: where the block started
/// the step, when free motion moved it and did not record it (`Block::translate_unrecorded`).
#[allow(clippy::too_many_arguments)]
fn finish_block(
    i: usize,
    b: &mut Block,
    start: Option<DVec3>,
    quiet: &mut BlockSet,
    grid: &mut BlockGrid,
    events: &mut StepEvents,
    states: &mut [BlockState],
    anchor: DVec3,
) {
    // The entry's rotation changes only when the block's did (a block's line 2, read only
    // then: a falling block's step does not fetch it).
    let state = &mut states[i];
    state.pose.position = to_scene(b.pos(), anchor).to_array();
    if b.rotated() {
        state.pose.rotation = b.rot().to_array();
    }
    state.mode = b.mode as u32;
    state.held_by = u32::from(b.held_by);
    // The grid sees every block where this step left it (the floor stage's moves, the
    // hand's): the next step's stages query it without a pass of their own to sync it.
    grid.stands_at(i, b.pos());
    // R14 judges again what touches a block that moved or changed mode.
    let shifted = match start {
        Some(start) => b.pos() != start,
        None => b.shifted_this_step(),
    };
    b.stirred = shifted || b.turned_this_step() || b.mode != b.mode_before;
    if b.released {
        events.emit_by(EventKind::Release, i, b.released_by);
    }
    if b.mode_before != b.mode {
        if let Some(k) = EventKind::on_entering(b.mode) {
            let hands = match k {
                EventKind::Grasp => b.held_by,
                EventKind::Push => b.acting_hands,
                _ => 0,
            };
            events.emit_by(k, i, hands);
        }
    }
    if b.mode == BlockMode::Resting
        && !b.stirred
        && !b.released
        && b.moved == Moved::No
        && !b.acted()
    {
        // What R14's first pass would do to it in every later step while it sleeps
        // outside the active set (`Support::judge_with` skips it).
        b.judged = false;
        quiet.insert(i);
    }
    // The next step's stage 0, for the blocks that stay active and those that sleep.
    b.begin_step();
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
