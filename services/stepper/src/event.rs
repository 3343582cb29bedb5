//! What happened in a step: the events both models report (a mode change is an event), and the
//! paper model's per-step list that its stages append to.

use common::BlockMode;

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
    /// In a two-hand world, the hands a grasp, release or push is by (bit k: hand slot k,
    /// `crate::HAND_SLOTS`); 0 for the other events and in a one-hand world.
    pub hands: u8,
}

/// The events of the step being taken. A stage that reports something (the floor's R8 impacts,
/// the step's end) is handed this list, so that it needs neither the world nor its step count;
/// preallocated, so that recording an event does not allocate.
#[derive(Debug)]
pub(crate) struct StepEvents {
    step: u64,
    events: Vec<Event>,
    /// Whether events name their hands (a two-hand world).
    pub(crate) name_hands: bool,
}

impl StepEvents {
    pub(crate) fn with_capacity(capacity: usize) -> StepEvents {
        StepEvents {
            step: 0,
            events: Vec::with_capacity(capacity),
            name_hands: false,
        }
    }

    /// Forgets the previous step's events; those recorded from now on are step `step`'s.
    pub(crate) fn begin(&mut self, step: u64) {
        self.step = step;
        self.events.clear();
    }

    pub(crate) fn emit(&mut self, kind: EventKind, block: usize) {
        self.emit_by(kind, block, 0);
    }

    /// An event by the hands `hands` (named only in a two-hand world).
    pub(crate) fn emit_by(&mut self, kind: EventKind, block: usize, hands: u8) {
        self.events.push(Event {
            step: self.step,
            kind,
            block,
            hands: if self.name_hands { hands } else { 0 },
        });
    }

    /// Moves `later`'s events after this list's (no allocation within the capacity).
    pub(crate) fn append(&mut self, later: &mut StepEvents) {
        self.events.extend_from_slice(&later.events);
        later.events.clear();
    }

    pub(crate) fn as_slice(&self) -> &[Event] {
        &self.events
    }
}
