//! Kinematics: turns what the devices report (glove angles and a wrist pose) into the hand the
//! block world needs: check points per finger, finger radii and the palm polyhedron
//! (docs/model.md R1-R2), in the world frame.

pub mod model;
pub mod pairing;
pub mod service;

pub use model::HandModel;
pub use pairing::{GloveHistory, HandStream};

common::process!(
    /// The kinematics stage's process (glove and tracker (or joints) to the hand model), as
    /// `handblocks service kinematics` runs it.
    Kinematics,
    common::bus::BusError,
    service::run
);
