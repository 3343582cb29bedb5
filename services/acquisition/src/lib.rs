//! Acquisition: turns a hand source into `glove` and `tracker` samples at the source's rate.
//!
//! Today's source is the built-in scripted hand ([`scripted`]): a scene's `[hand]` keyframes,
//! interpolated and sampled like a device would be. The real CyberGlove and FASTRAK drivers
//! are issue 4.

pub mod devices;
pub mod emulator;
pub mod scripted;
pub mod service;

pub use scripted::{HandTarget, ScriptedHand};

common::process!(
    /// The acquisition stage's process (the glove and tracker, or the scene's scripted hand), as
    /// `handblocks service acquisition` runs it.
    Acquisition,
    service::AcquisitionError,
    service::run
);
