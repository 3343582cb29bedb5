//! Stage 1 of a world of several hands (docs/model.md "Two hands"; a shared world's hands are
//! combined the same way, whoever's they are): each hand's R1-R3 (and T1-T2) are
//! decided as a one-hand world decides them, apart, then combined block by block into the one
//! action stage 2 applies:
//!
//! * both hands grasp: a two-hand grasp, moved by the mean of the two wrists' motions
//!   (`hand::move_by_hand`); several people's hands that grasp one block hold it together,
//!   moved by the mean of all their wrists' motions (no hand has authority over another's);
//! * one hand grasps: that hand's grasp, whatever the other does to the block (a hand pushing
//!   a block the other holds does not tear it from the grip);
//! * both push (R4 or R6): R6's rule across the hands, the mean of their translations;
//! * one acts: its action.
//!
//! A hand joining or leaving a grasp that goes on (a block passed from hand to hand, one hand
//! letting go of a two-hand grasp) is no release: the block stays grasped by the other hand and
//! moves with it, so nothing is thrown; the step reports the hand that joined (`grasp`) or
//! left (`release`).

use glam::DVec3;

use common::BlockMode;

use crate::block_set::BlockSet;
use crate::body::{Block, HandAction};
use crate::event::{EventKind, StepEvents};
use crate::motion::push_one_point;
use crate::settings::Settings;
use crate::HAND_SLOTS;

/// Each hand's actions of the step, kept apart until both are decided: preallocated for every
/// block, so that a step does not allocate.
#[derive(Debug)]
pub(crate) struct TwoHands {
    /// Per hand slot: (block, action) in block order, for the blocks the hand acts on.
    actions: [Vec<(u32, HandAction)>; HAND_SLOTS],
}

impl TwoHands {
    pub(crate) fn new(blocks: usize) -> TwoHands {
        TwoHands {
            actions: std::array::from_fn(|_| Vec::with_capacity(blocks)),
        }
    }

    /// Takes hand `slot`'s actions off the blocks (stage 1 just decided them), leaving every
    /// block with none for the next hand's stage 1.
    pub(crate) fn keep(&mut self, slot: usize, blocks: &mut [Block], active: &BlockSet) {
        let kept = &mut self.actions[slot];
        kept.clear();
        // Stage 1 put every block a hand acts on in `active`; it iterates lowest first.
        for i in active.iter() {
            let b = &mut blocks[i];
            if b.acted() {
                kept.push((i as u32, b.action()));
                b.set_action(HandAction::None);
            }
        }
    }

    /// Combines the hands' kept actions into each block's action (the module's rules) and
    /// the hands acting on it (`Block::acting_hands`); reports hands joining or leaving a grasp
    /// that goes on. Whether any block has an action.
    pub(crate) fn combine(
        &mut self,
        blocks: &mut [Block],
        settings: &Settings,
        events: &mut StepEvents,
    ) -> bool {
        // Each slot's list is in block order: walk them together, one cursor per slot.
        let mut next = [0usize; HAND_SLOTS];
        let mut acted = false;
        // The next block any hand acts on, in block order, and each hand's action on it.
        while let Some(i) = (0..HAND_SLOTS)
            .filter_map(|k| self.actions[k].get(next[k]).map(|&(i, _)| i))
            .min()
        {
            let mut by_slot = [HandAction::None; HAND_SLOTS];
            for k in 0..HAND_SLOTS {
                if let Some(&(j, action)) = self.actions[k].get(next[k]) {
                    if j == i {
                        by_slot[k] = action;
                        next[k] += 1;
                    }
                }
            }
            let (action, hands) = combined(&by_slot, settings);
            let block = &mut blocks[i as usize];
            if block.mode == BlockMode::Grasped && action == HandAction::Grasp {
                // A grasp that goes on: a hand joining it, or letting go of it.
                let (joined, left) = (hands & !block.held_by, block.held_by & !hands);
                if joined != 0 {
                    events.emit_by(EventKind::Grasp, i as usize, joined);
                }
                if left != 0 {
                    events.emit_by(EventKind::Release, i as usize, left);
                }
            }
            acted |= action != HandAction::None;
            block.set_action(action);
            block.acting_hands = hands;
        }
        acted
    }
}

/// The block's action from each hand's (by slot), and the hands it is by (bit k: slot k).
/// Any grasp wins, by every hand that grasps (two people grasping one block hold it
/// together, as one person's two hands do); a hand acting alone keeps its action; two or
/// more pushes are R6 across the hands, the mean of their translations (those that move it).
fn combined(by_slot: &[HandAction; HAND_SLOTS], settings: &Settings) -> (HandAction, u8) {
    let bit = |k: usize| 1u8 << k;
    let grasping = (0..HAND_SLOTS)
        .filter(|&k| by_slot[k] == HandAction::Grasp)
        .fold(0u8, |mask, k| mask | bit(k));
    if grasping != 0 {
        return (HandAction::Grasp, grasping);
    }
    let acting = (0..HAND_SLOTS)
        .filter(|&k| by_slot[k] != HandAction::None)
        .fold(0u8, |mask, k| mask | bit(k));
    if acting.count_ones() == 1 {
        let k = acting.trailing_zeros() as usize;
        return (by_slot[k], acting);
    }
    let translation = |a: HandAction| match a {
        HandAction::Push { c, b } => {
            push_one_point(c, b, DVec3::ZERO, settings.hull_eps, settings.contact_eps).map(|p| p.t)
        }
        HandAction::Translate(t) => Some(t),
        _ => None,
    };
    // Summed from the first translation, not from zero, so that one hand's is its own bit
    // for bit (a -0.0 stays -0.0) and two hands' is (p + q) * 0.5 as it always was.
    let (mut sum, mut moving, mut n) = (None::<DVec3>, 0u8, 0u32);
    for (k, &action) in by_slot.iter().enumerate() {
        if let Some(t) = translation(action) {
            sum = Some(sum.map_or(t, |s| s + t));
            moving |= bit(k);
            n += 1;
        }
    }
    match sum {
        None => (HandAction::None, 0),
        Some(t) if n == 1 => (HandAction::Translate(t), moving),
        Some(t) => (HandAction::Translate(t * (1.0 / f64::from(n))), moving),
    }
}
