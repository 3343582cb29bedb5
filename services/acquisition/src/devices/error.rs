//! What can go wrong with a device, for both drivers and their reader threads: one enum, so a
//! caller matches on the case (a missing port, a silent device, a glove of another size) and a
//! person reads one whole sentence from `Display`.

use std::fmt;
use std::path::PathBuf;
use std::time::Duration;

use super::calibration::CalibrationError;

/// What went wrong with a device, worded for the person at the keyboard: what happened and
/// what to do. `Display` gives the whole sentence.
#[derive(Debug, Clone, PartialEq)]
pub enum DeviceError {
    /// The serial device could not be opened (missing, busy, no permission).
    Open {
        device: &'static str,
        port: PathBuf,
        reason: String,
    },
    /// Reading or writing the open port failed (cable pulled, adapter gone).
    Io {
        device: &'static str,
        port: PathBuf,
        reason: String,
    },
    /// The device did not answer a command in time.
    NoAnswer {
        device: &'static str,
        port: PathBuf,
        command: &'static str,
        waited: Duration,
        hint: String,
    },
    /// The device answered at first and then went quiet: no valid record for `waited`.
    Silent {
        device: &'static str,
        port: PathBuf,
        waited: Duration,
        /// Bytes that arrived in that time but made no valid record.
        garbage_bytes: u64,
        /// What the device itself reported meanwhile, if anything (a CyberGlove's `e` code).
        reported: Option<&'static str>,
    },
    /// The glove has another number of sensors than the configuration or calibration says.
    SensorCount {
        port: PathBuf,
        reported: u32,
        configured: Option<u32>,
        calibration: Option<(PathBuf, u32)>,
    },
    /// The glove reports a sensor count no CyberGlove has.
    UnsupportedSensorCount { port: PathBuf, reported: u32 },
    /// The configured tracker station never reported, while others did.
    StationMissing {
        port: PathBuf,
        station: u8,
        seen: [bool; 4],
    },
    /// The calibration file is unusable.
    Calibration(CalibrationError),
    /// A configuration value is out of range.
    Config { key: &'static str, problem: String },
    /// A reconnection attempt failed; another follows after `retry_in`.
    Reconnecting {
        device: &'static str,
        port: PathBuf,
        attempt: u32,
        retry_in: Duration,
        cause: Box<DeviceError>,
    },
}

impl DeviceError {
    /// The port the error is about, if any.
    pub fn port(&self) -> Option<&std::path::Path> {
        match self {
            DeviceError::Open { port, .. }
            | DeviceError::Io { port, .. }
            | DeviceError::NoAnswer { port, .. }
            | DeviceError::Silent { port, .. }
            | DeviceError::SensorCount { port, .. }
            | DeviceError::UnsupportedSensorCount { port, .. }
            | DeviceError::StationMissing { port, .. }
            | DeviceError::Reconnecting { port, .. } => Some(port),
            DeviceError::Calibration(_) | DeviceError::Config { .. } => None,
        }
    }
}

impl fmt::Display for DeviceError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DeviceError::Open {
                device,
                port,
                reason,
            } => write!(
                f,
                "cannot open the {device} port {}: {reason}; check that the device is plugged \
                 in, that `port` names it, and that you may open it (group dialout)",
                port.display()
            ),
            DeviceError::Io {
                device,
                port,
                reason,
            } => write!(
                f,
                "the {device} link on {} failed: {reason}; was the cable or adapter pulled? \
                 reconnecting",
                port.display()
            ),
            DeviceError::NoAnswer {
                device,
                port,
                command,
                waited,
                hint,
            } => write!(
                f,
                "the {device} on {} did not answer {command} within {} ms: {hint}",
                port.display(),
                waited.as_millis()
            ),
            DeviceError::Silent {
                device,
                port,
                waited,
                garbage_bytes,
                reported,
            } => {
                write!(
                    f,
                    "the {device} on {} stopped answering: no valid record for {} ms",
                    port.display(),
                    waited.as_millis()
                )?;
                if let Some(r) = reported {
                    write!(f, " (it reported: {r})")?;
                }
                if *garbage_bytes > 0 {
                    write!(
                        f,
                        " ({garbage_bytes} bytes arrived that made no record: is the baud rate right?)"
                    )?;
                }
                write!(f, "; reconnecting")
            }
            DeviceError::SensorCount {
                port,
                reported,
                configured,
                calibration,
            } => {
                write!(
                    f,
                    "the glove on {} answered {reported} sensors but ",
                    port.display()
                )?;
                match (configured, calibration) {
                    (Some(c), Some((file, n))) => write!(
                        f,
                        "the config says {c} (calibration {} has {n} entries)",
                        file.display()
                    )?,
                    (Some(c), None) => write!(f, "the config says {c}")?,
                    (None, Some((file, n))) => write!(
                        f,
                        "the calibration {} has {n} entries",
                        file.display()
                    )?,
                    (None, None) => write!(f, "the driver expected another count")?,
                }
                write!(
                    f,
                    ": set sensors = {reported} and use a calibration file for a {reported}-sensor glove"
                )
            }
            DeviceError::UnsupportedSensorCount { port, reported } => write!(
                f,
                "the glove on {} says it has {reported} sensors; CyberGloves have 18 or 22: \
                 is this a CyberGlove, at the right baud rate?",
                port.display()
            ),
            DeviceError::StationMissing {
                port,
                station,
                seen,
            } => {
                write!(
                    f,
                    "the FASTRAK on {} did not report station {station}",
                    port.display()
                )?;
                let active: Vec<String> = (0..4)
                    .filter(|i| seen[*i])
                    .map(|i| (i + 1).to_string())
                    .collect();
                if active.is_empty() {
                    write!(f, "; no station reported")?;
                } else {
                    write!(f, "; stations reporting: {}", active.join(", "))?;
                }
                write!(
                    f,
                    ": plug the receiver into station {station} or set `station` to one that reports"
                )
            }
            DeviceError::Calibration(e) => write!(f, "{e}"),
            DeviceError::Config { key, problem } => write!(f, "`{key}`: {problem}"),
            DeviceError::Reconnecting {
                device,
                port,
                attempt,
                retry_in,
                cause,
            } => write!(
                f,
                "{device} on {}: reconnection attempt {attempt} failed ({cause}); next try in {} ms",
                port.display(),
                retry_in.as_millis()
            ),
        }
    }
}

impl std::error::Error for DeviceError {}

impl From<CalibrationError> for DeviceError {
    fn from(e: CalibrationError) -> Self {
        DeviceError::Calibration(e)
    }
}
