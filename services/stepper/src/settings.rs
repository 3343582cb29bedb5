//! The scene's settings as the rules read them, decided once in `World::new`: the numbers
//! ([`Settings`]) and which passes run ([`Passes`], docs/design.md "Effects"). Every stage of
//! `World::step` is handed these read-only, as rapier hands each stage its integration
//! parameters; none of them can change in a step.

use glam::DVec3;

use crate::tracked::TrackedRules;

/// The scene's numbers as the rules use them.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Settings {
    /// g_step = (0, -g dt^2, 0), zero when gravity is off.
    pub g_step: DVec3,
    pub inertia: bool,
    pub contact_eps: f64,
    pub hull_eps: f64,
    pub angle_eps: f64,
    pub grasp_angle: f64,
    pub release_angle: f64,
    /// T1-T3 under `[world] hands = "tracked"`; None under the paper's rules.
    pub tracked: Option<TrackedRules>,
}

/// Which passes run each step (docs/design.md "Effects"): an effect that is off costs nothing.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Passes {
    /// R1-R6 (and R13's release).
    pub hand: bool,
    /// R5 may grasp (hand = "grasp"); otherwise two contacts always push (R6).
    pub grasp: bool,
    /// R10.
    pub carry: bool,
    /// R7 gravity or inertia moves free blocks.
    pub free_motion: bool,
    /// R8.
    pub floor: bool,
    /// R9.
    pub tipping: bool,
    /// R11 (paper stacking) and R12's casts against other blocks: only with two blocks or more.
    pub blocks: bool,
    /// R14 replaces R11 (stacking = "supported"): only with two blocks or more.
    pub supported: bool,
}
