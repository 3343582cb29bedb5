//! The CyberGlove: 18 or 22 bend sensors, one byte each, over RS-232 (8N1, usually 115200 baud,
//! about 100 samples a second).
//!
//! The protocol, as far as this driver uses it:
//! * `G` asks for one sample. The glove answers `G`, one byte per sensor in the glove's sensor
//!   order ([`common::glove`]), then a 0 byte. Sensor bytes are never 0 (the glove reports
//!   1..=255), which is what makes the 0 a terminator and lets the parser resynchronise.
//! * `S` starts streaming: the glove sends one such record after another, each starting with
//!   `S` instead of `G`, until it receives the byte 0x03 (control-C).
//! * `?S` asks for the number of sensors: the answer is `?S`, one byte with the count, and a
//!   0 byte.
//! * A glove that cannot sample answers `e` and a code letter instead (`eg`: no glove plugged
//!   into the interface unit; `es`: sampling error).
//!
//! Opening the glove stops any stream left running, asks the sensor count and checks it
//! against the configuration and the calibration file, then (streamed mode) starts the stream.

use std::time::Instant;

pub use common::config::devices::{GloveConfig, GloveMode};
use common::{monotonic_ns, GloveSample, Stamp, MAX_GLOVE_SENSORS};

use super::calibration::Calibration;
use super::link_loop::{self, LinkUpkeep, Protocol, RecordBuffer, RecordBytes};
use super::serial::{check_link, Link, LinkSettings, LinkStats};
use super::{DeviceError, ReadOutcome};

const DEVICE: &str = "glove";
/// Control-C: ends streamed mode.
pub const STOP_STREAM: u8 = 0x03;

/// The driver's own checks of a configuration (the session reader checked the file's keys;
/// these also catch a configuration built in code).
fn check(cfg: &GloveConfig) -> Result<(), DeviceError> {
    check_link("glove", "glove.baud", &cfg.link)?;
    if let Some(n) = cfg.sensors {
        if n != 18 && n != 22 {
            return Err(DeviceError::Config {
                key: "glove.sensors",
                problem: format!("{n}: a CyberGlove has 18 or 22 sensors"),
            });
        }
    }
    if let GloveMode::Polled { rate_hz } = cfg.mode {
        if !(rate_hz.is_finite() && (1.0..=1000.0).contains(&rate_hz)) {
            return Err(DeviceError::Config {
                key: "glove.rate_hz",
                problem: format!("{rate_hz}: allowed 1..=1000 samples per second"),
            });
        }
    }
    Ok(())
}

/// What the parser found next in the byte stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GloveEvent {
    /// A sample record (`G` polled, `S` streamed); its sensor bytes were written out.
    Record { header: u8 },
    /// The answer to `?S`: the glove's sensor count.
    SensorCount(u8),
    /// An `e` error reply with its code letter.
    DeviceError(u8),
}

/// Bytes in, glove records out; pure, fixed-size, no allocation.
///
/// Resynchronisation: a record is `H b1..bn 0` with every `bi` non-zero, so after noise or a
/// cut record the parser skips to the next header byte and accepts it only if exactly n
/// non-zero bytes and a 0 follow. A candidate that fails is dropped one byte at a time, so a
/// real header hidden in the rejected bytes is still found.
#[derive(Debug, Clone)]
pub struct GloveParser {
    bytes: RecordBytes,
    sensors: usize,
    pub stats: LinkStats,
}

impl GloveParser {
    /// A parser for a glove of `sensors` sensors (1..=22; the driver uses 18 or 22).
    pub fn new(sensors: usize) -> GloveParser {
        GloveParser {
            bytes: RecordBytes::new(256),
            sensors: sensors.clamp(1, MAX_GLOVE_SENSORS),
            stats: LinkStats::default(),
        }
    }

    pub fn sensors(&self) -> usize {
        self.sensors
    }

    /// Appends bytes (for tests and emulators); returns how many fit.
    pub fn push(&mut self, bytes: &[u8]) -> usize {
        self.bytes.push(bytes, &mut self.stats.garbage_bytes)
    }

    /// The next complete event, or None until more bytes arrive. Sample bytes go to `raw`.
    pub fn next(&mut self, raw: &mut [u8; MAX_GLOVE_SENSORS]) -> Option<GloveEvent> {
        let n = self.sensors;
        let mut p = 0;
        let result = loop {
            // Skip to a possible header.
            let filled = self.bytes.filled();
            while p < filled.len() && !matches!(filled[p], b'G' | b'S' | b'?' | b'e') {
                p += 1;
            }
            if p >= filled.len() {
                break None;
            }
            let avail = &filled[p..];
            match avail[0] {
                b'G' | b'S' => {
                    let data_end = (1 + n).min(avail.len());
                    if let Some(z) = avail[1..data_end].iter().position(|b| *b == 0) {
                        // A 0 inside the data: this record was cut short.
                        let _ = z;
                        self.stats.rejected_records += 1;
                        p += 1;
                        continue;
                    }
                    if avail.len() < n + 2 {
                        break None; // wait for the rest
                    }
                    if avail[n + 1] != 0 {
                        self.stats.rejected_records += 1;
                        p += 1;
                        continue;
                    }
                    raw[..n].copy_from_slice(&avail[1..=n]);
                    let header = avail[0];
                    self.stats.garbage_bytes += p as u64;
                    self.bytes.consume(p + n + 2);
                    return Some(GloveEvent::Record { header });
                }
                b'?' => {
                    if avail.len() < 4 {
                        if avail.len() >= 2 && avail[1] != b'S' {
                            p += 1;
                            continue;
                        }
                        break None;
                    }
                    if avail[1] == b'S' && avail[3] == 0 && avail[2] != 0 {
                        let count = avail[2];
                        self.stats.garbage_bytes += p as u64;
                        self.bytes.consume(p + 4);
                        return Some(GloveEvent::SensorCount(count));
                    }
                    p += 1;
                }
                _ => {
                    // `e` and a lower-case code letter.
                    if avail.len() < 2 {
                        break None;
                    }
                    if avail[1].is_ascii_lowercase() {
                        let code = avail[1];
                        self.stats.garbage_bytes += p as u64;
                        self.stats.device_errors += 1;
                        self.bytes.consume(p + 2);
                        return Some(GloveEvent::DeviceError(code));
                    }
                    p += 1;
                }
            }
        };
        // Everything before p can never start a record.
        self.stats.garbage_bytes += p as u64;
        self.bytes.consume(p);
        result
    }
}

/// What an `e` error code means, for messages.
pub fn error_code_meaning(code: u8) -> &'static str {
    match code {
        b'g' => "no glove is plugged into the interface unit",
        b's' => "the interface unit reports a sampling error",
        _ => "an unknown error",
    }
}

/// An open CyberGlove.
pub struct Glove {
    cfg: GloveConfig,
    calibration: Calibration,
    /// The sensor count the configuration and calibration allow (None: either).
    expected: Option<u32>,
    sensors: u32,
    parser: GloveParser,
    raw: [u8; MAX_GLOVE_SENSORS],
    upkeep: LinkUpkeep,
    /// The last `e` code since the last sample: a silence report says what the glove said.
    last_device_error: Option<u8>,
    seq: u64,
}

impl Glove {
    /// Checks the configuration and loads the calibration, without touching the port: the
    /// first `read` connects. For a session that should start even while the glove is off.
    pub fn new(cfg: GloveConfig) -> Result<Glove, DeviceError> {
        check(&cfg)?;
        let file_cal = match &cfg.calibration {
            Some(file) => Some(Calibration::load(file)?),
            None => None,
        };
        if let (Some(n), Some(c)) = (cfg.sensors, &file_cal) {
            if c.sensor_count() != n {
                return Err(DeviceError::Config {
                    key: "glove.calibration",
                    problem: format!(
                        "{} has {} sensor lines but `sensors` = {n}: use the calibration of this \
                         glove",
                        c.file
                            .as_ref()
                            .map(|f| f.display().to_string())
                            .unwrap_or_default(),
                        c.sensor_count()
                    ),
                });
            }
        }
        let expected = cfg.sensors.or(file_cal.as_ref().map(|c| c.sensor_count()));
        let sensors = expected.unwrap_or(22);
        let calibration = match file_cal {
            Some(c) => c,
            None => Calibration::nominal(sensors).ok_or(DeviceError::Config {
                key: "glove.sensors",
                problem: format!("{sensors}: a CyberGlove has 18 or 22 sensors"),
            })?,
        };
        Ok(Glove {
            upkeep: LinkUpkeep::new(cfg.link.backoff),
            cfg,
            calibration,
            expected,
            sensors,
            parser: GloveParser::new(sensors as usize),
            raw: [0; MAX_GLOVE_SENSORS],
            last_device_error: None,
            seq: 0,
        })
    }

    /// Opens the glove now: the port, the sensor-count check, the stream. Fails with the
    /// reason when any of that fails (wrong port, no answer, wrong glove size).
    pub fn open(cfg: GloveConfig) -> Result<Glove, DeviceError> {
        let mut g = Glove::new(cfg)?;
        link_loop::connect_now(&mut g)?;
        Ok(g)
    }

    /// The glove's sensor count (as answered at the last connection, or as configured).
    pub fn sensor_count(&self) -> u32 {
        self.sensors
    }

    pub fn config(&self) -> &GloveConfig {
        &self.cfg
    }

    /// Counters since `new`, across reconnections.
    pub fn stats(&self) -> LinkStats {
        self.upkeep.stats.with_parser(&self.parser.stats)
    }

    /// Whether the driver currently has its link (false while reconnecting).
    pub fn connected(&self) -> bool {
        self.upkeep.connected()
    }

    /// Waits up to the read slice for the next sample and writes it into `out` (angles in
    /// radians, `sensor_count`, a fresh stamp). Never allocates on the sample path.
    ///
    /// `Err` reports a problem the driver is already handling (the link is being
    /// re-established with backoff): log it and call `read` again.
    pub fn read(&mut self, out: &mut GloveSample) -> Result<ReadOutcome, DeviceError> {
        link_loop::read(self, out)
    }
}

impl RecordBuffer for GloveParser {
    fn window(&mut self) -> (&mut RecordBytes, &mut LinkStats) {
        (&mut self.bytes, &mut self.stats)
    }

    fn stats(&self) -> &LinkStats {
        &self.stats
    }
}

impl Protocol for Glove {
    type Sample = GloveSample;
    type Buffer = GloveParser;
    const DEVICE: &'static str = DEVICE;
    const POLL_COMMAND: &'static [u8] = b"G";

    fn poll_rate_hz(&self) -> Option<f64> {
        match self.cfg.mode {
            GloveMode::Streamed => None,
            GloveMode::Polled { rate_hz } => Some(rate_hz),
        }
    }

    fn link(&self) -> &LinkSettings {
        &self.cfg.link
    }

    fn connect(&mut self) -> Result<Link, DeviceError> {
        let mut link =
            link_loop::open_quiet(DEVICE, &self.cfg.link, &[STOP_STREAM], &mut self.parser)?;
        link.write_all(b"?S")?;
        let deadline = Instant::now() + self.cfg.link.answer_timeout;
        let reported = loop {
            if let Some(ev) = self.parser.next(&mut self.raw) {
                match ev {
                    GloveEvent::SensorCount(n) => break u32::from(n),
                    GloveEvent::DeviceError(code) => self.last_device_error = Some(code),
                    GloveEvent::Record { .. } => {}
                }
                continue;
            }
            let now = Instant::now();
            if now >= deadline {
                let hint = match self.last_device_error {
                    Some(code) => format!(
                        "it answered `e{}`: {}",
                        code as char,
                        error_code_meaning(code)
                    ),
                    None => format!(
                        "is it switched on, on this port, at {} baud?",
                        self.cfg.link.baud
                    ),
                };
                return Err(DeviceError::NoAnswer {
                    device: DEVICE,
                    port: self.cfg.link.port.clone(),
                    command: "`?S` (sensor count)",
                    waited: self.cfg.link.answer_timeout,
                    hint,
                });
            }
            link_loop::receive_until(&mut link, &mut self.parser, deadline)?;
        };
        if reported != 18 && reported != 22 {
            return Err(DeviceError::UnsupportedSensorCount {
                port: self.cfg.link.port.clone(),
                reported,
            });
        }
        if let Some(expected) = self.expected {
            if reported != expected {
                return Err(DeviceError::SensorCount {
                    port: self.cfg.link.port.clone(),
                    reported,
                    configured: self.cfg.sensors,
                    calibration: self
                        .calibration
                        .file
                        .clone()
                        .map(|f| (f, self.calibration.sensor_count())),
                });
            }
        } else if reported != self.sensors {
            // No size was configured: follow the glove (nominal calibration).
            if let Some(c) = Calibration::nominal(reported) {
                self.calibration = c;
            }
        }
        self.sensors = reported;
        if self.parser.sensors() != reported as usize {
            let stats = self.parser.stats;
            self.parser = GloveParser::new(reported as usize);
            self.parser.stats = stats;
        }
        if self.cfg.mode == GloveMode::Streamed {
            link.write_all(b"S")?;
        }
        Ok(link)
    }

    /// A record becomes calibrated angles with a fresh stamp; an `e` reply in between is kept
    /// for a silence report, and a sample clears it (the glove recovered).
    fn take_sample(&mut self, out: &mut GloveSample) -> bool {
        while let Some(ev) = self.parser.next(&mut self.raw) {
            match ev {
                GloveEvent::Record { .. } => {
                    let now_ns = monotonic_ns();
                    self.calibration
                        .apply(&self.raw[..self.sensors as usize], &mut out.angles);
                    out.sensor_count = self.sensors;
                    out.stamp =
                        Stamp::at_origin(self.seq, now_ns.saturating_sub(self.cfg.epoch_ns));
                    self.seq += 1;
                    self.last_device_error = None;
                    return true;
                }
                GloveEvent::DeviceError(code) => self.last_device_error = Some(code),
                GloveEvent::SensorCount(_) => {}
            }
        }
        false
    }

    fn take_reported(&mut self) -> Option<&'static str> {
        self.last_device_error.take().map(error_code_meaning)
    }

    fn parts(&mut self) -> (&mut LinkUpkeep, &mut GloveParser) {
        (&mut self.upkeep, &mut self.parser)
    }
}

impl Drop for Glove {
    /// Leaves the glove quiet for the next program that opens it.
    fn drop(&mut self) {
        self.upkeep.send_if_up(&[STOP_STREAM]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(header: u8, values: &[u8]) -> Vec<u8> {
        let mut v = vec![header];
        v.extend_from_slice(values);
        v.push(0);
        v
    }

    fn values(k: u8, n: usize) -> Vec<u8> {
        (0..n)
            .map(|i| 1 + (k as usize * 7 + i * 11) as u8 % 250)
            .collect()
    }

    fn drain(p: &mut GloveParser) -> Vec<(GloveEvent, Vec<u8>)> {
        let mut raw = [0u8; MAX_GLOVE_SENSORS];
        let mut out = Vec::new();
        while let Some(ev) = p.next(&mut raw) {
            out.push((ev, raw[..p.sensors()].to_vec()));
        }
        out
    }

    #[test]
    fn clean_stream_of_both_sizes() {
        for n in [18, 22] {
            let mut p = GloveParser::new(n);
            let mut bytes = Vec::new();
            for k in 0..5 {
                bytes.extend(record(b'S', &values(k, n)));
            }
            p.push(&bytes);
            let got = drain(&mut p);
            assert_eq!(got.len(), 5);
            for (k, (ev, raw)) in got.iter().enumerate() {
                assert_eq!(*ev, GloveEvent::Record { header: b'S' });
                assert_eq!(raw, &values(k as u8, n));
            }
            assert_eq!(p.stats.garbage_bytes, 0);
            assert_eq!(p.stats.rejected_records, 0);
        }
    }

    #[test]
    fn byte_at_a_time_is_the_same() {
        let mut p = GloveParser::new(18);
        let mut bytes = record(b'G', &values(1, 18));
        bytes.extend(b"?S\x12\0");
        bytes.extend(b"eg");
        let mut got = Vec::new();
        let mut raw = [0u8; MAX_GLOVE_SENSORS];
        for b in bytes {
            p.push(&[b]);
            while let Some(ev) = p.next(&mut raw) {
                got.push(ev);
            }
        }
        assert_eq!(
            got,
            vec![
                GloveEvent::Record { header: b'G' },
                GloveEvent::SensorCount(18),
                GloveEvent::DeviceError(b'g')
            ]
        );
    }

    #[test]
    fn noise_and_cut_records_are_skipped() {
        let n = 22;
        let mut bytes = Vec::new();
        bytes.extend(b"\xff\x00garbage G\x01\x02"); // noise, including a false header
        bytes.extend(record(b'S', &values(1, n)));
        let cut = record(b'S', &values(2, n));
        bytes.extend(&cut[..9]); // a record cut short, then the next one
        bytes.extend(record(b'S', &values(3, n)));
        bytes.extend(b"S\x05\x06\x00"); // a short record with an early terminator
        bytes.extend(record(b'S', &values(4, n)));
        let mut p = GloveParser::new(n);
        p.push(&bytes);
        let got = drain(&mut p);
        let ks: Vec<Vec<u8>> = got.iter().map(|(_, r)| r.clone()).collect();
        assert_eq!(ks, vec![values(1, n), values(3, n), values(4, n)]);
        assert!(p.stats.garbage_bytes > 0);
        assert!(p.stats.rejected_records >= 2);
    }

    #[test]
    fn a_record_of_the_wrong_size_is_never_accepted() {
        // An 18-sensor glove's records seen by a 22-sensor parser: each is too short.
        let mut p = GloveParser::new(22);
        for k in 0..4 {
            p.push(&record(b'S', &values(k, 18)));
        }
        assert!(drain(&mut p).is_empty());
    }

    #[test]
    fn arbitrary_bytes_never_panic() {
        // A deterministic pseudo-random stream, fed in uneven chunks.
        let mut x: u32 = 12345;
        let mut p = GloveParser::new(22);
        let mut raw = [0u8; MAX_GLOVE_SENSORS];
        for _ in 0..2000 {
            let mut chunk = [0u8; 37];
            for b in chunk.iter_mut() {
                x = x.wrapping_mul(1_103_515_245).wrapping_add(12345);
                *b = (x >> 16) as u8;
            }
            let take = (x as usize % 37) + 1;
            p.push(&chunk[..take]);
            while p.next(&mut raw).is_some() {}
        }
    }

    #[test]
    fn config_checks_name_the_key() {
        let mut cfg = GloveConfig::new("/dev/null");
        cfg.sensors = Some(20);
        let Err(e) = Glove::new(cfg) else {
            panic!("accepted 20 sensors")
        };
        assert!(e.to_string().contains("glove.sensors"), "{e}");
    }
}
