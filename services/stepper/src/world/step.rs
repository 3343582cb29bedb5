//! The stages of one step, numbered as docs/model.md's "Order of one step" (1-6) between the
//! step's start (0) and end (7), each a function handed the sets it reads and writes (as
//! rapier's `PhysicsPipeline` hands each stage the sets it touches). [`World::step_hands`]
//! calls them in order:
//!
//! 0. [`take_hands`], [`start_step`]: the hands enter the world's frame and the step begins;
//! 1. [`decide_hand_actions`]: hand contacts (R1-R3, T1-T2, H1-H2), then R13 ends grasps;
//! 2. [`move_with_hands`]: hand-driven motion (R5, R4, R6), then carry (R10);
//! 3. `Support::judge_stacks`: supported stacking (R14, when the scene asks for it);
//! 4. [`move_free_blocks`]: free motion (R7, with R12) except blocks held by R11 or R14;
//! 5. and 6. [`land_and_settle`]: floor (R8, R9), then settling (R13's releases take effect,
//!    modes and events), in one pass block by block ([`finish_block`] is stage 6 of a block);
//! 7. [`keep_hands`]: this step's hands are the next step's previous ones.
//!
//! Moving the stages here moved code, not arithmetic: every stage does what it did, in the
//! same order, so a step is the same bit for bit.

use glam::DVec3;

use common::{BlockMode, BlockState, HandSample};

use super::World;
use crate::anchor::to_scene;
use crate::block_set::BlockSet;
use crate::body::{Block, Moved};
use crate::event::{EventKind, StepEvents};
use crate::floor::{in_the_air, leave_the_floor, Floor};
use crate::grid::BlockGrid;
use crate::hand::{
    check_point_box, end_grasps, hand_reach, is_usable, move_by_hand, Fingers, HandContacts,
    Letting, EMPTY_BOX,
};
use crate::interference::Carry;
use crate::motion::move_freely;
use crate::settings::{Passes, Settings};
use crate::tracked::{hold_grasps, TrackedCounts};
use crate::two_hands::TwoHands;
use crate::HAND_SLOTS;

/// Stage 0's first half: each hand of this step in the world's frame, by slot. A hand the
/// rules cannot use (`hand::is_usable`) is refused and counted in `rejected_hands`.
pub(super) fn take_hands<'a>(
    hands: [Option<&'a HandSample>; HAND_SLOTS],
    anchor: DVec3,
    prev_hand: &[Option<HandSample>; HAND_SLOTS],
    hand_local: &'a mut [HandSample; HAND_SLOTS],
    rejected_hands: &mut u64,
) -> [Option<&'a HandSample>; HAND_SLOTS] {
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
    now
}

/// Stage 0's second half: the step's events and the scratch of stages 4-6 begin empty, and
/// the check points as drawn start as the hands give them (R5 relocates them in stage 2).
/// Every block already starts the step where it is, with nothing done to it yet: the last
/// step's stage 6 left it so (`Block::begin_step`, in the same pass), and nothing changes a
/// block between steps.
#[allow(clippy::too_many_arguments)]
pub(super) fn start_step(
    step: u64,
    two: bool,
    events: &mut StepEvents,
    settled: &mut StepEvents,
    quiet: &mut BlockSet,
    flown: &mut BlockSet,
    fingers: &mut [Fingers; HAND_SLOTS],
    now: [Option<&HandSample>; HAND_SLOTS],
) {
    events.begin(step);
    events.name_hands = two;
    settled.name_hands = two;
    for (f, hand) in fingers.iter_mut().zip(now) {
        f.copy_from(hand);
    }
    quiet.clear();
    flown.clear();
    settled.begin(step);
}

/// Stage 1. Hand contacts (R1-R3) for every block near each hand: each block's hand action;
/// with two hands each hand's actions apart, then combined (H1-H2); then R13 ends the grasps
/// they no longer confirm. Returns whether a hand acted on a block, and each hand's T2 gap
/// (`Some(hold)`: the hand is not tracked, and still holds what it holds while `hold`).
#[allow(clippy::too_many_arguments)]
pub(super) fn decide_hand_actions(
    blocks: &mut [Block],
    active: &mut BlockSet,
    grid: &mut BlockGrid,
    hand_contacts: &mut HandContacts,
    two_hands: &mut TwoHands,
    events: &mut StepEvents,
    prev_hand_box: &mut [(DVec3, DVec3); HAND_SLOTS],
    untracked_steps: &mut [u64; HAND_SLOTS],
    tracked_counts: &mut TrackedCounts,
    now: [Option<&HandSample>; HAND_SLOTS],
    prev: [Option<&HandSample>; HAND_SLOTS],
    settings: &Settings,
    passes: &Passes,
    steps: u64,
    seen: u8,
) -> (bool, [Option<bool>; HAND_SLOTS]) {
    let two = seen > 1;
    let mut gaps = [None; HAND_SLOTS];
    let mut acted = false;
    for slot in (0..HAND_SLOTS).filter(|k| seen & (1 << k) != 0) {
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
        // Each block's hand action (R1-R3) for the blocks near the hand (broad phase first);
        // an untracked hand holds what it holds instead (T2).
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
                        steps,
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
            Some(rules) => Letting::FittedThrow { now: steps, rules },
        };
        end_grasps(blocks, active, settings.inertia, letting_of, tracked_counts);
    }
    (acted, gaps)
}

/// Stage 2. Hand-driven motion (R5, R4, R6), then carry (R10) from the blocks it moved. A
/// hand that acts on nothing (far from every block, or no hand) moves nothing and carries
/// nothing: neither runs, not even a pass over the active set. T3 keeps the path of what a
/// tracked hand holds. Returns whether the hands moved a block (without telling the grid).
#[allow(clippy::too_many_arguments)]
pub(super) fn move_with_hands(
    blocks: &mut [Block],
    active: &mut BlockSet,
    grid: &mut BlockGrid,
    carry: &mut Carry,
    fingers: &mut [Fingers; HAND_SLOTS],
    now: [Option<&HandSample>; HAND_SLOTS],
    prev: [Option<&HandSample>; HAND_SLOTS],
    gaps: [Option<bool>; HAND_SLOTS],
    acted: bool,
    settings: &Settings,
    passes: &Passes,
    steps: u64,
    two: bool,
) -> bool {
    let tracked_now = (0..HAND_SLOTS).any(|k| now[k].is_some() && gaps[k].is_none());
    let path_step = (settings.tracked.is_some() && tracked_now).then_some(steps);
    let moved = acted
        && now.iter().any(Option::is_some)
        && move_by_hand(blocks, active, now, prev, settings, fingers, path_step, two);
    if passes.carry && moved {
        carry.carry(blocks, active, grid, settings.hull_eps);
    }
    moved
}

/// Stage 4. Free motion (R7, with R12) for the rest, except blocks held by R11 or R14.
/// Without gravity and inertia nothing moves freely, and R11 has nothing to hold: the step
/// calls this only with `passes.free_motion`. The grid must see the hand's and R14's moves
/// first (`grid_behind`). A block it leaves in the air has stages 5 and 6 here, and joins
/// `flown`, which the last pass skips.
#[allow(clippy::too_many_arguments)]
pub(super) fn move_free_blocks(
    blocks: &mut [Block],
    active: &BlockSet,
    grid: &mut BlockGrid,
    grid_behind: bool,
    quiet: &mut BlockSet,
    flown: &mut BlockSet,
    settled: &mut StepEvents,
    states: &mut [BlockState],
    settings: &Settings,
    passes: &Passes,
    anchor: DVec3,
) {
    if grid_behind {
        grid.sync(blocks, active);
    }
    for i in active.iter() {
        let Some(start) = move_freely(blocks, i, grid, settings, passes) else {
            continue;
        };
        // A block it left in the air (most of a rain) has its floor stage and stage 6
        // now, while its lines are in the cache, instead of in the last pass: both
        // read and write this block only (`leave_the_floor`, `finish_block`), and no
        // later block's free motion reads what they change (it reads poses and boxes,
        // which they leave). Only when stage 6 reports nothing, so that `settled`
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

/// Stage 5. Floor (R8, R9) for every block that moved or is in floor contact, not resting;
/// stage 6. releases (R13) take effect for the next step; modes and events are settled. Both
/// in one pass, block by block (a block's floor stage reads of the others only their poses,
/// which stage 6 leaves; `Floor::land_block`): stage 6's events wait in `settled` so that the
/// list reads as the two stages one after the other (every impact, then the rest). The blocks
/// free motion left flying (`flown`) had both already. Blocks that rest untouched leave
/// `active`.
#[allow(clippy::too_many_arguments)]
pub(super) fn land_and_settle(
    blocks: &mut [Block],
    active: &mut BlockSet,
    grid: &mut BlockGrid,
    grid_behind: bool,
    floor: &mut Floor,
    quiet: &mut BlockSet,
    flown: &BlockSet,
    events: &mut StepEvents,
    settled: &mut StepEvents,
    states: &mut [BlockState],
    settings: &Settings,
    passes: &Passes,
    anchor: DVec3,
) {
    // R14's check of an R9 turn asks the grid for the turning block's neighbours: it must
    // see every block where it is (stage 6 tells it of each block the floor stage moved,
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
}

/// Stage 7. This step's hands are the next step's previous ones (P-, W-).
pub(super) fn keep_hands(
    prev_hand: &mut [Option<HandSample>; HAND_SLOTS],
    prev_hand_box: &mut [(DVec3, DVec3); HAND_SLOTS],
    now: [Option<&HandSample>; HAND_SLOTS],
) {
    for slot in 0..HAND_SLOTS {
        prev_hand[slot] = now[slot].copied();
        if now[slot].is_none() {
            // With a hand, stage 1 kept its box for the next step (and without the hand's
            // stages nothing reads it).
            prev_hand_box[slot] = EMPTY_BOX;
        }
    }
}

/// Stage 6 for block i: the step's release (R13) and mode change as events, and whether R14
/// judges what touches it again in the next step (it moved or changed mode). A block that
/// rests and that nothing moved, turned, released or acted on this step goes into `quiet`, to
/// leave `active`: until a stage touches it, no step looks at it. It ends with its scratch as
/// the next step's stage 0 finds it (`Block::begin_step`). `start`: where the block started
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
