//! Stage 1 of a two-hand world (docs/model.md "Two hands"): each hand's R1-R3 (and T1-T2) are
//! decided as a one-hand world decides them, apart, then combined block by block into the one
//! action stage 2 applies:
//!
//! * both hands grasp: a two-hand grasp, moved by the mean of the two wrists' motions
//!   (`hand::move_by_hand`);
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
            actions: [Vec::with_capacity(blocks), Vec::with_capacity(blocks)],
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

    /// Combines the two hands' kept actions into each block's action (the module's rules) and
    /// the hands acting on it (`Block::acting_hands`); reports hands joining or leaving a grasp
    /// that goes on. Whether any block has an action.
    pub(crate) fn combine(
        &mut self,
        blocks: &mut [Block],
        settings: &Settings,
        events: &mut StepEvents,
    ) -> bool {
        let [first, second] = &self.actions;
        let (mut a, mut b) = (first.iter().peekable(), second.iter().peekable());
        let mut acted = false;
        loop {
            // The next block either hand acts on, in block order, and each hand's action on it.
            let (i, x, y) = match (a.peek(), b.peek()) {
                (None, None) => break,
                (Some(&&(i, x)), Some(&&(j, _))) if i < j => {
                    a.next();
                    (i, x, HandAction::None)
                }
                (Some(&&(i, x)), Some(&&(j, y))) if i == j => {
                    a.next();
                    b.next();
                    (i, x, y)
                }
                (_, Some(&&(j, y))) => {
                    b.next();
                    (j, HandAction::None, y)
                }
                (Some(&&(i, x)), None) => {
                    a.next();
                    (i, x, HandAction::None)
                }
            };
            let (action, hands) = combined(x, y, settings);
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

/// The block's action from the first hand's `x` and the second's `y`, and the hands it is by.
fn combined(x: HandAction, y: HandAction, settings: &Settings) -> (HandAction, u8) {
    use HandAction::{Grasp, None};
    match (x, y) {
        (Grasp, Grasp) => (Grasp, 0b11),
        (Grasp, _) => (Grasp, 0b01),
        (_, Grasp) => (Grasp, 0b10),
        (x, None) => (x, u8::from(x != None)),
        (None, y) => (y, 0b10),
        // Two pushes: R6 across the hands, the mean of their translations (those that move it).
        (x, y) => {
            let t = |a: HandAction| match a {
                HandAction::Push { c, b } => {
                    push_one_point(c, b, DVec3::ZERO, settings.hull_eps, settings.contact_eps)
                        .map(|p| p.t)
                }
                HandAction::Translate(t) => Some(t),
                _ => Option::None,
            };
            match (t(x), t(y)) {
                (Some(p), Some(q)) => (HandAction::Translate((p + q) * 0.5), 0b11),
                (Some(p), Option::None) => (HandAction::Translate(p), 0b01),
                (Option::None, Some(q)) => (HandAction::Translate(q), 0b10),
                (Option::None, Option::None) => (None, 0),
            }
        }
    }
}
