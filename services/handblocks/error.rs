//! Why a subcommand refused or could not finish, one variant per subcommand, each holding its
//! operation's own error. The message is the whole line `main` prints: `handblocks`, the
//! subcommand (or the service) it came from, and the reason, exactly as the tests read them.

use recording::RecordingError;

use crate::bench::BenchError;
use crate::emulate::EmulateError;
use crate::launch::LaunchCommandError;
use crate::list::ListError;
use crate::monitor::MonitorError;
use crate::service::ServiceError;
use crate::simulate::SimulateError;

#[derive(Debug, thiserror::Error)]
pub enum CliError {
    /// `launch` (and the bare `handblocks`): the session could not be loaded or run, or its
    /// report not written.
    #[error("handblocks: {0}")]
    Launch(#[from] LaunchCommandError),
    #[error("handblocks simulate: {0}")]
    Simulate(#[from] SimulateError),
    /// `inspect`: the file cannot be read at all (damage further on is a verdict, exit 1).
    #[error("handblocks inspect: {0}")]
    Inspect(#[from] RecordingError),
    #[error("handblocks list: {0}")]
    List(#[from] ListError),
    #[error("handblocks emulate: {0}")]
    Emulate(#[from] EmulateError),
    /// `service NAME`: one process of a session failed.
    #[error("handblocks {}: {}", .0.service(), .0)]
    Service(#[from] ServiceError),
    #[error("{}: {}", bench_command(.0), .0)]
    Bench(#[from] BenchError),
    /// `replay`: the trace or its scene cannot be used (a refusal before the launch).
    #[error("handblocks replay: {0}")]
    Replay(String),
    /// `echo`, `hz`: no session to look at, or its bus cannot be read.
    #[error("handblocks {0}: {1}")]
    Monitor(&'static str, MonitorError),
    /// A command refused what it was given before doing anything, saying what to do instead.
    #[error("handblocks {0}: {1}")]
    Refused(&'static str, String),
}

/// Who says a benchmark's error: `handblocks bench NAME`, or `handblocks` alone when it could
/// not start at all.
fn bench_command(e: &BenchError) -> String {
    match e.command() {
        Some(command) => format!("handblocks {command}"),
        None => "handblocks".to_string(),
    }
}

impl CliError {
    /// The exit status of every refusal: "could not run" (a failed budget or a damaged
    /// recording is a verdict, 1, and no error).
    pub const EXIT_STATUS: u8 = 2;
}
