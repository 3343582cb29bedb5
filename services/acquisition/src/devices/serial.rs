//! The serial link both devices sit on, and the policy for getting it back when it goes.
//!
//! The link is the `serialport` crate's POSIX tty, opened 8N1, raw, no flow control — the
//! settings of both the CyberGlove and the FASTRAK. A pseudo-terminal (the emulators) goes
//! through exactly the same code, which is the point: the tests exercise the real path.
//!
//! Reads take an explicit timeout so a driver's `read` never blocks longer than its time slice
//! and the caller can notice a shutdown request.

use std::io::{Read, Write};
use std::os::fd::AsRawFd;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use serialport::{DataBits, FlowControl, Parity, SerialPort, StopBits, TTYPort};

pub use common::config::devices::{Backoff, LinkSettings};

use super::DeviceError;

/// Counters a driver keeps across reconnections; cheap to copy out for a status line or a test.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LinkStats {
    /// Valid records turned into samples (for the tracker: of the configured station).
    pub samples: u64,
    /// Bytes skipped while looking for the start of a record (noise, or the rest of a cut
    /// record).
    pub garbage_bytes: u64,
    /// Record candidates rejected: a header that was not followed by a well-formed record, or a
    /// record whose values were out of range or not finite.
    pub rejected_records: u64,
    /// Records of other tracker stations (skipped, not an error).
    pub other_station_records: u64,
    /// Times the link was lost (I/O error or silence) and the driver began reconnecting.
    pub link_losses: u64,
    /// Successful reconnections after a loss.
    pub reconnects: u64,
    /// Error records the device sent (the CyberGlove's `e` replies).
    pub device_errors: u64,
}

impl LinkStats {
    /// The counters as the session report carries them, as `device`'s.
    pub fn device_counters(&self, device: common::samples::DeviceKind) -> common::DeviceCounters {
        common::DeviceCounters {
            device: device as u32,
            _reserved: 0,
            samples: self.samples,
            garbage_bytes: self.garbage_bytes,
            rejected_records: self.rejected_records,
            other_station_records: self.other_station_records,
            link_losses: self.link_losses,
            reconnects: self.reconnects,
            device_errors: self.device_errors,
        }
    }

    /// A driver's counters with its parser's byte-level ones added: what the driver reports,
    /// across reconnections (the parser is replaced when the glove's size changes).
    pub fn with_parser(mut self, parser: &LinkStats) -> LinkStats {
        self.garbage_bytes += parser.garbage_bytes;
        self.rejected_records += parser.rejected_records;
        self.device_errors += parser.device_errors;
        self
    }
}

/// An open serial port.
pub struct Link {
    port: TTYPort,
    path: PathBuf,
    device: &'static str,
    timeout: Duration,
}

impl Link {
    /// Opens `path` at `baud`, 8N1, raw, no flow control.
    pub fn open(device: &'static str, path: &Path, baud: u32) -> Result<Link, DeviceError> {
        let timeout = Duration::from_millis(10);
        let port = serialport::new(path.to_string_lossy(), baud)
            .data_bits(DataBits::Eight)
            .parity(Parity::None)
            .stop_bits(StopBits::One)
            .flow_control(FlowControl::None)
            .timeout(timeout)
            .open_native()
            .map_err(|e| DeviceError::Open {
                device,
                port: path.to_path_buf(),
                reason: e.to_string(),
            })?;
        Ok(Link {
            port,
            path: path.to_path_buf(),
            device,
            timeout,
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    fn io_error(&self, what: &str, e: impl std::fmt::Display) -> DeviceError {
        DeviceError::Io {
            device: self.device,
            port: self.path.clone(),
            reason: format!("{what}: {e}"),
        }
    }

    /// Writes a whole command.
    pub fn write_all(&mut self, bytes: &[u8]) -> Result<(), DeviceError> {
        self.set_timeout(Duration::from_millis(200))?;
        self.port
            .write_all(bytes)
            .map_err(|e| self.io_error("write", e))?;
        self.port.flush().map_err(|e| self.io_error("flush", e))
    }

    fn set_timeout(&mut self, timeout: Duration) -> Result<(), DeviceError> {
        if self.timeout != timeout {
            self.port
                .set_timeout(timeout)
                .map_err(|e| self.io_error("set timeout", e))?;
            self.timeout = timeout;
        }
        Ok(())
    }

    /// Reads what is there, waiting at most `timeout` for the first byte. `Ok(0)` means
    /// nothing arrived in time; an error means the link itself is gone.
    pub fn read_some(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize, DeviceError> {
        if buf.is_empty() {
            return Ok(0);
        }
        // Wait here rather than in `serialport`'s read: its timeout result is an `io::Error`
        // built from a string, an allocation per timeout, which on a polled device is one per
        // sample.
        if !self.wait_readable(timeout) {
            return Ok(0);
        }
        self.set_timeout(Duration::from_millis(1))?;
        match self.port.read(buf) {
            // A tty read of 0 bytes after poll said readable is a hangup.
            Ok(0) => Err(self.io_error("read", "hang-up (end of file)")),
            Ok(n) => Ok(n),
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => Ok(0),
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => Ok(0),
            Err(e) => Err(self.io_error("read", e)),
        }
    }

    /// Whether the port has bytes (or a hang-up to report) within `timeout`.
    fn wait_readable(&self, timeout: Duration) -> bool {
        let mut pfd = libc::pollfd {
            fd: self.port.as_raw_fd(),
            events: libc::POLLIN,
            revents: 0,
        };
        let ts = libc::timespec {
            tv_sec: timeout.as_secs().min(3600) as libc::time_t,
            tv_nsec: timeout.subsec_nanos() as libc::c_long,
        };
        // SAFETY: one valid pollfd, a valid timespec, no signal mask.
        let rc = unsafe { libc::ppoll(&mut pfd, 1, &ts, std::ptr::null()) };
        // An error or a hang-up: let the read report it.
        rc != 0
    }

    /// Throws away what the device sent so far: waits until the line has been quiet for
    /// `quiet`, at most `limit` in all (a streaming device is never quiet; the caller stopped
    /// its stream first).
    pub fn drain(&mut self, quiet: Duration, limit: Duration) -> Result<u64, DeviceError> {
        let end = Instant::now() + limit;
        let mut scratch = [0u8; 256];
        let mut dropped = 0u64;
        loop {
            let now = Instant::now();
            if now >= end {
                return Ok(dropped);
            }
            let n = self.read_some(&mut scratch, quiet.min(end - now))?;
            if n == 0 {
                return Ok(dropped);
            }
            dropped += n as u64;
        }
    }
}

/// The longest timeout or backoff a configuration may give: longer is surely a mistake (and
/// would overflow deadline arithmetic near `Duration::MAX`).
pub const MAX_WAIT: Duration = Duration::from_secs(3600);

/// Checks a driver's timeouts and backoff delays: each within 1 ms ..= [`MAX_WAIT`].
pub fn check_timing(device: &'static str, waits: &[Duration]) -> Result<(), DeviceError> {
    for w in waits {
        if *w < Duration::from_millis(1) || *w > MAX_WAIT {
            return Err(DeviceError::Config {
                key: device,
                problem: format!(
                    "a timeout or backoff of {w:?}: allowed 1 ms to {} s",
                    MAX_WAIT.as_secs()
                ),
            });
        }
    }
    Ok(())
}

/// Checks a driver's link settings: its timeouts and backoff ([`check_timing`]) and a baud
/// rate other than 0 (`baud_key` names it in the message).
pub fn check_link(
    device: &'static str,
    baud_key: &'static str,
    link: &LinkSettings,
) -> Result<(), DeviceError> {
    check_timing(
        device,
        &[
            link.answer_timeout,
            link.silence_timeout,
            link.read_slice,
            link.backoff.first,
            link.backoff.max,
        ],
    )?;
    if link.baud == 0 {
        return Err(DeviceError::Config {
            key: baud_key,
            problem: format!("0: give the {device}'s baud rate, usually 115200"),
        });
    }
    Ok(())
}

/// Whether a driver has its link, or is waiting to try again.
pub enum LinkState {
    Up(Link),
    Down { retry_at: Instant },
}

/// Sleeps until `deadline` or for at most `slice`, whichever is sooner.
pub fn sleep_toward(deadline: Instant, slice: Duration) {
    let now = Instant::now();
    if deadline > now {
        std::thread::sleep((deadline - now).min(slice));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backoff_doubles_to_its_cap_and_resets() {
        let mut b = Backoff::new(Duration::from_millis(100), Duration::from_millis(350));
        assert_eq!(b.next_delay(), (Duration::from_millis(100), 1));
        assert_eq!(b.next_delay(), (Duration::from_millis(200), 2));
        assert_eq!(b.next_delay(), (Duration::from_millis(350), 3));
        assert_eq!(b.next_delay(), (Duration::from_millis(350), 4));
        b.reset();
        assert_eq!(b.next_delay(), (Duration::from_millis(100), 1));
    }

    #[test]
    fn opening_a_missing_port_names_it() {
        let Err(e) = Link::open("glove", Path::new("/nonexistent/ttyUSB9"), 115200) else {
            panic!("opened a missing port");
        };
        let msg = e.to_string();
        assert!(msg.contains("/nonexistent/ttyUSB9"), "{msg}");
        assert!(msg.contains("glove"), "{msg}");
    }
}
