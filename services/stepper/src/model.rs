//! The one switch between the two models a scene can run on (`[world] model`): the paper's
//! rules ([`World`], the product) and the rigid-body reference ([`PreciseWorld`], rapier3d).
//! The stepper process, `simulate` and the benchmarks hold a [`Model`] and never ask which it
//! is; both take the same hand per step and fill the same `world` sample, so the renderer,
//! the recorder, replay and `simulate --json` cannot tell them apart.
//!
//! An enum, not a trait object: two variants, known here, and a step of the paper model must
//! stay one predictable branch away (no allocation, no indirection on its hot path).

use common::config::scene::{HandRules, ModelKind, Stacking};
use common::config::Scene;
use common::{BlockState, HandSample, WorldHeader, WorldSample};

use crate::precise::PreciseWorld;
use crate::tracked::TrackedCounts;
use crate::world::{BlockView, Event, World, WorldError};

/// A world under one of the two models.
// The paper model stays inline (its step is the product's hot path); the precise one is boxed
// because rapier's sets are large. One `Model` lives per process, so the size does not matter.
#[allow(clippy::large_enum_variant)]
pub enum Model {
    Paper(World),
    Precise(Box<PreciseWorld>),
}

impl Model {
    /// Builds the world of `scene` under the model it names. The precise model is checked by
    /// the paper model's own scene checks first (shapes are solids, nothing starts below the
    /// floor or inside another block), so that both refuse the same scenes with the same
    /// messages; its stacking rule is the engine's, so `[effects] stacking` is not its concern.
    pub fn new(scene: &Scene) -> Result<Model, WorldError> {
        match scene.world.model {
            ModelKind::Paper => World::new(scene).map(Model::Paper),
            ModelKind::Precise if scene.world.hands == HandRules::Tracked => Err(WorldError {
                file: scene.file.clone(),
                block: None,
                problem: "`world.hands` = \"tracked\" is the paper model's (docs/model.md T1-T3); \
                          the precise model grasps by R3 alone: give `world.hands` = \"paper\" \
                          with `world.model` = \"precise\""
                    .into(),
            }),
            ModelKind::Precise => {
                let mut checked = scene.clone();
                checked.world.model = ModelKind::Paper;
                checked.effects.stacking = Stacking::Paper;
                World::new(&checked)?;
                PreciseWorld::new(scene).map(|w| Model::Precise(Box::new(w)))
            }
        }
    }

    /// What the tracked hand rules (T1-T3) did: zero under the paper's rules and under the
    /// precise model (which has none).
    pub fn tracked_counts(&self) -> TrackedCounts {
        match self {
            Model::Paper(w) => w.tracked_counts(),
            Model::Precise(_) => TrackedCounts::default(),
        }
    }

    /// Which model this is.
    pub fn kind(&self) -> ModelKind {
        match self {
            Model::Paper(_) => ModelKind::Paper,
            Model::Precise(_) => ModelKind::Precise,
        }
    }

    /// One fixed step with the hand at this step (see [`World::step`]).
    pub fn step(&mut self, hand: Option<&HandSample>) {
        match self {
            Model::Paper(w) => w.step(hand),
            Model::Precise(w) => w.step(hand),
        }
    }

    /// One step with each hand by slot ([`crate::HAND_SLOTS`]; [`World::step_hands`]). The
    /// precise model takes the first hand only: two hands are the paper model's, and
    /// `simulate` and the stepper refuse the precise model with two before they start.
    pub fn step_hands<const N: usize>(&mut self, hands: [Option<&HandSample>; N]) {
        match self {
            Model::Paper(w) => w.step_hands(hands),
            Model::Precise(w) => w.step(hands.first().copied().flatten()),
        }
    }

    /// [`World::set_previous_hand_of`].
    pub fn set_previous_hand_of(&mut self, slot: usize, hand: Option<&HandSample>) {
        match self {
            Model::Paper(w) => w.set_previous_hand_of(slot, hand),
            Model::Precise(w) if slot == 0 => w.set_previous_hand(hand),
            Model::Precise(_) => {}
        }
    }

    /// Hand samples the world refused where they entered (`hand::unusable_because`); for
    /// each, the hand held its last good pose.
    pub fn rejected_hand_samples(&self) -> u64 {
        match self {
            Model::Paper(w) => w.rejected_hand_samples(),
            Model::Precise(w) => w.rejected_hand_samples(),
        }
    }

    /// The hand the first step takes as its previous one (see [`World::set_previous_hand`]).
    pub fn set_previous_hand(&mut self, hand: Option<&HandSample>) {
        match self {
            Model::Paper(w) => w.set_previous_hand(hand),
            Model::Precise(w) => w.set_previous_hand(hand),
        }
    }

    /// Fills the `world` sample held by value (see [`World::write_sample`]).
    pub fn write_sample(&self, out: &mut WorldSample) {
        match self {
            Model::Paper(w) => w.write_sample(out),
            Model::Precise(w) => w.write_sample(out),
        }
    }

    /// The `world` sample's header (see [`World::write_header`]).
    pub fn write_header(&self, out: &mut WorldHeader) {
        match self {
            Model::Paper(w) => w.write_header(out),
            Model::Precise(w) => w.write_header(out),
        }
    }

    /// Block `i`'s state in the `world` sample.
    pub fn block_state(&self, i: usize) -> BlockState {
        match self {
            Model::Paper(w) => w.block_state(i),
            Model::Precise(w) => w.block_state(i),
        }
    }

    pub fn steps(&self) -> u64 {
        match self {
            Model::Paper(w) => w.steps(),
            Model::Precise(w) => w.steps(),
        }
    }

    /// What happened in the last step.
    pub fn events(&self) -> &[Event] {
        match self {
            Model::Paper(w) => w.events(),
            Model::Precise(w) => w.events(),
        }
    }

    pub fn block_count(&self) -> usize {
        match self {
            Model::Paper(w) => w.block_count(),
            Model::Precise(w) => w.block_count(),
        }
    }

    /// Block `i`'s G, rotation, mode and v (a displacement per step).
    pub fn block(&self, i: usize) -> Option<BlockView> {
        match self {
            Model::Paper(w) => w.block(i),
            Model::Precise(w) => w.block(i),
        }
    }
}
