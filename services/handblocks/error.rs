//! Why a subcommand refused or could not finish, one variant per subcommand, each holding its
//! operation's own error. The message is the whole line `main` prints: `handblocks`, the
//! subcommand (or the service) it came from, and the reason, exactly as the tests read them.

use std::fmt;

use recording::RecordingError;

use crate::bench::BenchError;
use crate::emulate::EmulateError;
use crate::launch::LaunchCommandError;
use crate::list::ListError;
use crate::monitor::MonitorError;
use crate::service::ServiceError;
use crate::simulate::SimulateError;

#[derive(Debug)]
pub enum CliError {
    /// `launch` (and the bare `handblocks`): the session could not be loaded or run, or its
    /// report not written.
    Launch(LaunchCommandError),
    Simulate(SimulateError),
    /// `inspect`: the file cannot be read at all (damage further on is a verdict, exit 1).
    Inspect(RecordingError),
    List(ListError),
    Emulate(EmulateError),
    /// `service NAME`: one process of a session failed.
    Service(ServiceError),
    Bench(BenchError),
    /// `replay`: the trace or its scene cannot be used (a refusal before the launch).
    Replay(String),
    /// `echo`, `hz`: no session to look at, or its bus cannot be read.
    Monitor(&'static str, MonitorError),
    /// A command refused what it was given before doing anything, saying what to do instead.
    Refused(&'static str, String),
}

impl CliError {
    /// The exit status of every refusal: "could not run" (a failed budget or a damaged
    /// recording is a verdict, 1, and no error).
    pub const EXIT_STATUS: u8 = 2;
}

impl fmt::Display for CliError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CliError::Launch(e) => write!(f, "handblocks: {e}"),
            CliError::Simulate(e) => write!(f, "handblocks simulate: {e}"),
            CliError::Inspect(e) => write!(f, "handblocks inspect: {e}"),
            CliError::List(e) => write!(f, "handblocks list: {e}"),
            CliError::Emulate(e) => write!(f, "handblocks emulate: {e}"),
            CliError::Service(e) => write!(f, "handblocks {}: {e}", e.service()),
            CliError::Replay(e) => write!(f, "handblocks replay: {e}"),
            CliError::Monitor(command, e) => write!(f, "handblocks {command}: {e}"),
            CliError::Refused(command, why) => write!(f, "handblocks {command}: {why}"),
            CliError::Bench(e) => match e.command() {
                Some(command) => write!(f, "handblocks {command}: {e}"),
                None => write!(f, "handblocks: {e}"),
            },
        }
    }
}

impl std::error::Error for CliError {}

impl From<LaunchCommandError> for CliError {
    fn from(e: LaunchCommandError) -> Self {
        CliError::Launch(e)
    }
}

impl From<SimulateError> for CliError {
    fn from(e: SimulateError) -> Self {
        CliError::Simulate(e)
    }
}

impl From<RecordingError> for CliError {
    fn from(e: RecordingError) -> Self {
        CliError::Inspect(e)
    }
}

impl From<ListError> for CliError {
    fn from(e: ListError) -> Self {
        CliError::List(e)
    }
}

impl From<EmulateError> for CliError {
    fn from(e: EmulateError) -> Self {
        CliError::Emulate(e)
    }
}

impl From<ServiceError> for CliError {
    fn from(e: ServiceError) -> Self {
        CliError::Service(e)
    }
}

impl From<BenchError> for CliError {
    fn from(e: BenchError) -> Self {
        CliError::Bench(e)
    }
}
