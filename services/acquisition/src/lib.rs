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

/// The acquisition stage's process (the glove and tracker, or the scene's scripted hand), as `handblocks service acquisition` runs it.
pub struct Process;

impl common::node::Process for Process {
    const STAGE: common::Stage = common::Stage::Acquisition;
    type Error = service::AcquisitionError;
    fn run(
        session: &common::config::Session,
        bus: &common::bus::Bus,
        _launch: &common::node::Launch,
    ) -> Result<(), Self::Error> {
        service::run(session, bus)
    }
}
