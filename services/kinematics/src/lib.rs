//! Kinematics: turns what the devices report (glove angles and a wrist pose) into the hand the
//! block world needs: check points per finger, finger radii and the palm polyhedron
//! (docs/model.md R1-R2), in the world frame.

pub mod model;
pub mod pairing;
pub mod service;

pub use model::HandModel;
pub use pairing::{GloveHistory, HandStream};

/// The kinematics stage's process (glove and tracker (or joints) to the hand model), as `handblocks service kinematics` runs it.
pub struct Process;

impl common::node::Process for Process {
    const STAGE: common::Stage = common::Stage::Kinematics;
    type Error = common::bus::BusError;
    fn run(
        session: &common::config::Session,
        bus: &common::bus::Bus,
        _launch: &common::node::Launch,
    ) -> Result<(), Self::Error> {
        service::run(session, bus)
    }
}
