//! `handblocks bench latency|accuracy|stability|stepper|hands` (the benchmarks are the bench crate's), and
//! the hidden `bench-peer`, the publishing half of the latency benchmark's peer.

use std::process::ExitCode;

use crate::cli::{BenchKind, LatencyPart};

/// Why a benchmark could not run. One that ran exits 0: its figures are its verdict.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// The latency benchmark starts this executable as the session's services.
    #[error("cannot find my own executable: {0}")]
    OwnExecutable(std::io::Error),
    /// The benchmark itself failed; `name` is `latency`, `accuracy`, `stability`, `stepper`, `hands`, `tosses` or `shared`.
    #[error("{error}")]
    Run {
        name: &'static str,
        error: Box<dyn std::error::Error>,
    },
    /// `bench-peer` could not publish.
    #[error(transparent)]
    Peer(Box<dyn std::error::Error>),
}

impl BenchError {
    /// The command the message names after `handblocks` (none for a missing executable).
    pub fn command(&self) -> Option<String> {
        match self {
            BenchError::OwnExecutable(_) => None,
            BenchError::Run { name, .. } => Some(format!("bench {name}")),
            BenchError::Peer(_) => Some("bench-peer".to_string()),
        }
    }
}

/// `bench latency transport`'s sweep: how many runs, of which transports.
struct Sweep {
    runs: u64,
    only: Vec<handblocks_bench::transport::Transport>,
}

/// `bench latency PART`: each part writes its own files and its key of `latency.json`; `all`
/// runs transport, pipeline and load in turn (with `--quick`, the pipeline for 2 s).
fn latency(
    part: LatencyPart,
    quick: bool,
    exe: std::path::PathBuf,
    session: std::path::PathBuf,
    seconds: std::time::Duration,
    sweep: Sweep,
    out: std::path::PathBuf,
) -> Result<(), Box<dyn std::error::Error>> {
    let all = part == LatencyPart::All;
    if all || part == LatencyPart::Transport {
        handblocks_bench::transport::run(&handblocks_bench::transport::TransportBench {
            exe: exe.clone(),
            out_dir: out.clone(),
            quick,
            runs: sweep.runs,
            only: sweep.only,
        })?;
    }
    if all || part == LatencyPart::Pipeline {
        let seconds = if all && quick {
            2.0
        } else {
            seconds.as_secs_f64()
        };
        handblocks_bench::latency::run(&handblocks_bench::latency::LatencyBench {
            exe: exe.clone(),
            session: session.clone(),
            seconds,
            out_dir: out.clone(),
            quick: all && quick,
            runs: sweep.runs,
        })?;
    }
    if all || part == LatencyPart::Load {
        handblocks_bench::load::run(&handblocks_bench::load::LoadBench {
            exe,
            session,
            out_dir: out,
            quick,
        })?;
    }
    Ok(())
}

/// `bench hands --traces`: the folder as given when it exists; else, for a relative path, the
/// same path beside the repository this binary was built from (`../shared` beside the
/// checkout, as the CARL traces are found when `target/release/handblocks` runs elsewhere).
fn traces_dir(given: std::path::PathBuf) -> std::path::PathBuf {
    if given.is_dir() || given.is_absolute() {
        return given;
    }
    let beside = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(&given);
    if beside.is_dir() {
        beside
    } else {
        given
    }
}

/// Runs one benchmark; its results are files under its `--out` folder.
pub fn run(which: BenchKind) -> Result<ExitCode, BenchError> {
    let (name, result) = match which {
        BenchKind::Latency {
            part,
            quick,
            session,
            seconds,
            runs,
            transports,
            out,
        } => {
            let exe = std::env::current_exe().map_err(BenchError::OwnExecutable)?;
            let name = match part {
                LatencyPart::Pipeline => "latency",
                LatencyPart::Transport => "latency transport",
                LatencyPart::Load => "latency load",
                LatencyPart::All => "latency all",
            };
            let sweep = Sweep {
                runs,
                only: transports,
            };
            (
                name,
                latency(part, quick, exe, session, seconds, sweep, out),
            )
        }
        BenchKind::Accuracy { out, quick, runs } => {
            let b = handblocks_bench::accuracy::AccuracyBench {
                out_dir: out,
                quick,
                runs: usize::try_from(runs).unwrap_or(1),
            };
            ("accuracy", handblocks_bench::accuracy::run(&b).map(drop))
        }
        BenchKind::Stability { out, quick } => {
            let b = handblocks_bench::stability::StabilityBench {
                out_dir: out,
                quick,
            };
            ("stability", handblocks_bench::stability::run(&b).map(drop))
        }
        BenchKind::Hands {
            out,
            traces,
            throws,
            quick,
        } => {
            let b = handblocks_bench::hands::HandsBench {
                out_dir: out,
                traces_dir: traces_dir(traces),
                throws: usize::try_from(throws).unwrap_or(usize::MAX),
                quick,
                only: Vec::new(),
            };
            ("hands", handblocks_bench::hands::run(&b).map(drop))
        }
        BenchKind::Tosses {
            out,
            tosses,
            fit,
            quick,
            python,
            runs,
        } => {
            let b = handblocks_bench::tosses::TossesBench {
                repo: std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")),
                python,
                runs: usize::try_from(runs).unwrap_or(1),
                out_dir: out,
                tosses_dir: traces_dir(tosses),
                fit_file: std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                    .join("config/tosses-fit.toml"),
                fit,
                quick,
            };
            ("tosses", handblocks_bench::tosses::run(&b).map(drop))
        }
        BenchKind::Shared {
            out,
            quick,
            seconds,
            traces,
        } => {
            let exe = std::env::current_exe().map_err(BenchError::OwnExecutable)?;
            let b = handblocks_bench::shared::SharedBench {
                exe,
                repo: std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")),
                out_dir: out,
                carl: traces_dir(traces).join("example_lift_0.carl"),
                seconds: if quick { seconds.min(10.0) } else { seconds },
                quick,
            };
            ("shared", handblocks_bench::shared::run(&b).map(drop))
        }
        BenchKind::Stepper { out, quick, runs } => {
            let b = handblocks_bench::stepper::StepperBench {
                out_dir: out,
                quick,
                runs: usize::try_from(runs).unwrap_or(1),
            };
            ("stepper", handblocks_bench::stepper::run(&b).map(drop))
        }
    };
    result.map_err(|error| BenchError::Run { name, error })?;
    Ok(ExitCode::SUCCESS)
}

/// `bench-transport-peer`: the writing half of one transport run.
pub fn transport_peer(
    transport: &str,
    endpoint: String,
    bytes: usize,
    rate_hz: f64,
    count: u64,
) -> Result<ExitCode, BenchError> {
    let transport = handblocks_bench::transport::Transport::from_name(transport)
        .ok_or_else(|| BenchError::Peer(format!("unknown transport {transport:?}").into()))?;
    let args = handblocks_bench::transport::PeerArgs {
        transport,
        endpoint,
        bytes,
        rate_hz,
        count,
    };
    handblocks_bench::transport::peer(&args).map_err(BenchError::Peer)?;
    Ok(ExitCode::SUCCESS)
}

/// `bench-peer`: publishes `count` hands at `rate` Hz on the bus `bus`.
pub fn peer(bus: &str, rate: f64, count: u64) -> Result<ExitCode, BenchError> {
    handblocks_bench::latency::peer_publisher(bus, rate, count).map_err(BenchError::Peer)?;
    Ok(ExitCode::SUCCESS)
}
