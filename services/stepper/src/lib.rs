//! The block world of docs/model.md: rules R1-R13 of Funahashi et al. (1996), "Block manipulation
//! with hand in virtual space", for any convex polyhedron, and the R14 extension (supported
//! stacking).
//!
//! A [`World`] is built from a scene ([`World::new`]) and advanced one fixed step at a time
//! with the hand of that step ([`World::step`]); [`World::write_sample`] fills the `world`
//! topic's sample. [`simulate()`] runs a scene for N steps from a [`HandSource`] and renders the
//! report (`handblocks simulate`). No shared memory is needed for any of it: the stepper
//! process (module [`service`]) wraps this library in the IPC loop.
//!
//! Modules, named for the concept as in dimforge's parry/rapier:
//! - [`geometry`]: convex polyhedra with G at the origin, and the exact queries the rules use;
//! - [`body`]: one block's state (pose, v, floor contact set, mode);
//! - [`hand`]: R1-R3 contacts, R5/R4/R6 hand-driven motion, R13 release detection;
//! - [`interference`]: R10 carry, R11 support, R12 shape casts, R14's side contacts;
//! - [`motion`]: R4's decomposition, R7 free motion;
//! - [`floor`]: R8 impact, R9 stability;
//! - [`support`]: R14 supported stacking (blocks stand on blocks as statics says);
//! - [`event`]: what a step reports (both models);
//! - [`world`]: the world and its step, in docs/model.md's order: it hands each stage above
//!   the sets that stage reads and writes, so none of them depends on the world;
//! - `two_hands`: a two-hand world's stage 1, each hand's actions combined block by block;
//! - [`block_set`]: sets of block indices as bit sets sized for their world (R14's);
//! - [`precise`]: the precise reference model (rapier3d), beside the paper's;
//! - [`anchor`]: the frame both models compute in, near the blocks wherever the scene is;
//! - [`model`]: the one switch between the two that the process and `simulate` hold;
//! - [`timeline`]: steps on the hand's source time, for the process and `simulate` alike;
//! - [`simulate`](mod@simulate): `handblocks simulate`, the bare check-point hand;
//! - [`service`]: the stepper process, a shell of IPC around the above.

pub mod anchor;
pub mod block_set;
pub mod body;
pub mod event;
pub mod floor;
pub mod geometry;
pub(crate) mod grid;
pub mod hand;
pub mod hand_log;
pub mod interference;
pub mod model;
pub mod motion;
pub mod precise;
pub mod service;
mod settings;
pub mod simulate;
pub mod support;
pub mod timeline;
pub mod tracked;
mod two_hands;
pub mod world;

/// The hands a world takes in one step ([`common::HandSample::slot`]): a headset tracks two,
/// and a shared world holds up to [`common::MAX_PARTICIPANTS`] people. Slot 0 is a one-hand
/// world's only hand and a two-hand world's right; slot 1 is the left (docs/model.md "Two
/// hands"); slots 2k and 2k+1 are participant k's right and left.
pub use common::HAND_SLOTS;

pub use model::Model;
pub use motion::{push_one_point, PushOutcome};
pub use precise::PreciseWorld;
pub use simulate::{
    default_frames, outcome, side_slot, simulate, simulate_frames_with, simulate_hands_with,
    simulate_samples, simulate_samples_with, simulate_with, slot_side, BareFingersHand,
    BlockReport, EventReport, HandFrame, HandSource, Progress, Report, RunError, Stop,
};
pub use world::{BlockView, Event, EventKind, World, WorldError};

/// The stepper's process (the block world), as `handblocks service stepper` runs it: it writes
/// the session's outcome into `--outcome-dir` when it stops.
pub struct Process;

impl common::node::Process for Process {
    const STAGE: common::Stage = common::Stage::Stepper;
    type Error = service::StepperError;
    fn run(
        session: &common::config::Session,
        bus: &common::bus::Bus,
        launch: &common::node::Launch,
    ) -> Result<(), Self::Error> {
        service::run_with_outcome(session, bus, launch.outcome_dir.as_deref())
    }
}
