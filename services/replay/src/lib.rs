//! Replay: a recorded hand takes the place of acquisition, and downstream cannot tell.
//!
//! Today it reads CARL traces ([`carl`]: real Quest hand tracking, OpenXR joints) and
//! publishes them on `joints` with their recorded timing.

pub mod carl;
pub mod service;

pub use carl::{CarlError, CarlTrace};
