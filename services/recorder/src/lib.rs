//! The recorder: writes every sample of every topic to an MCAP file
//! ([`recording`]) and counts, per topic, what it missed (gaps in seq).

pub mod service;

/// The recorder's process (the MCAP recording), as `handblocks service recorder` runs it: a
/// restarted recorder writes the next segment, leaving the dead one's file whole.
pub struct Process;

impl common::node::Process for Process {
    const STAGE: common::Stage = common::Stage::Recorder;
    type Error = service::RecorderError;
    fn run(
        session: &common::config::Session,
        bus: &common::bus::Bus,
        launch: &common::node::Launch,
    ) -> Result<(), Self::Error> {
        let mut session = session.clone();
        session.recorder.file = session
            .recorder
            .file
            .map(|f| launch.output_of(common::Stage::Recorder, &f));
        service::run(&session, bus)
    }
}
