//! The recorder: writes every sample of every topic to a file and counts what it missed.
//!
//! Today's file is a plain framed log ([`log`]); MCAP with schemas and chunking is issue 5.

pub mod log;
pub mod service;
