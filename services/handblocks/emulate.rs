//! `handblocks emulate glove|tracker --link PATH`: a CyberGlove or a FASTRAK on a
//! pseudo-terminal (acquisition's emulator), for sessions without hardware.

use std::fmt;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use acquisition::emulator::{glove, tracker, Fault};
use common::shutdown;

/// Why the emulated device did not run.
#[derive(Debug)]
pub enum EmulateError {
    /// A `--fault` spec was refused (the message says the syntax).
    Fault(String),
    /// `--rate` is not a usable record rate.
    Rate(f64),
    /// The pty or its link could not be made or served.
    Device {
        link: PathBuf,
        error: std::io::Error,
    },
}

impl fmt::Display for EmulateError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            EmulateError::Fault(e) => write!(f, "--fault: {e}"),
            EmulateError::Rate(r) => write!(
                f,
                "--rate {r}: allowed: more than 0 up to 10000 records per second"
            ),
            EmulateError::Device { link, error } => write!(f, "{}: {error}", link.display()),
        }
    }
}

impl std::error::Error for EmulateError {}

/// Serves the device until Ctrl-C, then says what it did.
pub fn run(
    device: &str,
    link: &Path,
    sensors: u8,
    rate: Option<f64>,
    faults: &[String],
) -> Result<ExitCode, EmulateError> {
    let faults = faults
        .iter()
        .map(|f| Fault::parse(f))
        .collect::<Result<Vec<_>, _>>()
        .map_err(EmulateError::Fault)?;
    if let Some(r) = rate.filter(|r| !(r.is_finite() && *r > 0.0 && *r <= 10_000.0)) {
        return Err(EmulateError::Rate(r));
    }
    shutdown::install_signal_handlers();
    eprintln!(
        "handblocks emulate: a {device} at {} (Ctrl-C stops it)",
        link.display()
    );
    let stop = || shutdown::requested();
    let result = if device == "glove" {
        let mut b = glove::GloveBehaviour::new(sensors);
        b.rate_hz = rate.unwrap_or(b.rate_hz);
        b.faults = faults;
        glove::run(link, b, &stop)
    } else {
        let mut b = tracker::TrackerBehaviour::new();
        b.rate_hz = rate.unwrap_or(b.rate_hz);
        b.faults = faults;
        tracker::run(link, b, &stop)
    };
    let report = result.map_err(|error| EmulateError::Device {
        link: link.to_path_buf(),
        error,
    })?;
    eprintln!(
        "handblocks emulate: stopped after {} records, {} unplugs; commands received: {:?}",
        report.records,
        report.unplugs,
        String::from_utf8_lossy(&report.received)
    );
    Ok(ExitCode::SUCCESS)
}
