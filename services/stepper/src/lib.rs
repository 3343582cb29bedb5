//! The block world (MODEL.md) as a library, and the stepper process that runs it.

pub mod service;
pub mod world;

pub use world::{Event, World, WorldError};
