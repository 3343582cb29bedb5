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

common::process!(
    /// The replay stage's process (a recorded hand), as `handblocks service replay` runs it.
    Replay,
    service::ReplayError,
    service::run
);
