//! Replay: a recorded hand takes the place of acquisition, and downstream cannot tell.
//!
//! It reads our own MCAP recordings (the `glove` + `tracker` or `joints` topics a live
//! session recorded) and CARL traces ([`carl`]: real Quest hand tracking, OpenXR joints), as
//! one [`HandTrace`], and publishes them with their recorded timing ([`service`]).

pub mod carl;
pub mod service;
pub mod trace;

pub use carl::{CarlError, CarlTrace};
pub use trace::{HandTrace, SourceSample, TraceKind};

/// The replay stage's process (a recorded hand), as `handblocks service replay` runs it.
pub struct Process;

impl common::node::Process for Process {
    const STAGE: common::Stage = common::Stage::Replay;
    type Error = service::ReplayError;
    fn run(
        session: &common::config::Session,
        bus: &common::bus::Bus,
        _launch: &common::node::Launch,
    ) -> Result<(), Self::Error> {
        service::run(session, bus)
    }
}
