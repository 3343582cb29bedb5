//! The FASTRAK driver: opens the port, sets the output format, units and list, checks that the
//! configured station reports, and reads its records through the shared read loop
//! ([`crate::devices::link_loop`]), as the wrist's pose in the world.

use std::time::Instant;

use common::{monotonic_ns, Stamp, TrackerSample};
use glam::DQuat;

use super::frame::{record_to_world, tracker_axes, TrackerRecord};
use super::parser::{item, FastrakParser};
use super::{Format, Orientation, TrackerConfig, TrackerMode, Units};
use crate::devices::link_loop::{self, LinkUpkeep, Protocol, RecordBuffer};
use crate::devices::serial::{check_link, Link, LinkSettings, LinkStats};
use crate::devices::{DeviceError, ReadOutcome};

const DEVICE: &str = "tracker";

/// The driver's own checks of a configuration (the session reader checked the file's keys;
/// these also catch a configuration built in code).
fn check(cfg: &TrackerConfig) -> Result<(), DeviceError> {
    check_link(DEVICE, "tracker.baud", &cfg.link)?;
    if !(1..=4).contains(&cfg.station) {
        return Err(DeviceError::Config {
            key: "tracker.station",
            problem: format!("{}: a FASTRAK has stations 1 to 4", cfg.station),
        });
    }
    for (key, pose) in [
        ("tracker.to_world", &cfg.to_world),
        ("tracker.wrist_offset", &cfg.wrist_offset),
    ] {
        let n = DQuat::from_array(pose.rotation).length();
        if !pose.is_finite() || (n - 1.0).abs() > 1e-3 {
            return Err(DeviceError::Config {
                key,
                problem: "needs a finite position and a unit quaternion [x, y, z, w]".into(),
            });
        }
    }
    if let TrackerMode::Polled { rate_hz } = cfg.mode {
        if !(rate_hz.is_finite() && (1.0..=1000.0).contains(&rate_hz)) {
            return Err(DeviceError::Config {
                key: "tracker.rate_hz",
                problem: format!("{rate_hz}: allowed 1..=1000 records per second"),
            });
        }
    }
    Ok(())
}

/// The output list the driver sets: position, the orientation item, CR LF.
pub fn output_list(cfg: &TrackerConfig) -> [u8; 3] {
    let o = match cfg.orientation {
        Orientation::Quaternion => item::QUATERNION,
        Orientation::Euler => item::EULER,
    };
    [item::POSITION, o, item::CRLF]
}

/// An open FASTRAK, reading one station.
pub struct Tracker {
    cfg: TrackerConfig,
    parser: FastrakParser,
    axes: DQuat,
    record: TrackerRecord,
    upkeep: LinkUpkeep,
    seq: u64,
}

impl Tracker {
    /// Checks the configuration without touching the port; the first `read` connects.
    pub fn new(cfg: TrackerConfig) -> Result<Tracker, DeviceError> {
        check(&cfg)?;
        let parser = FastrakParser::new(cfg.format, &output_list(&cfg)).map_err(|problem| {
            DeviceError::Config {
                key: "tracker",
                problem,
            }
        })?;
        Ok(Tracker {
            upkeep: LinkUpkeep::new(cfg.link.backoff),
            cfg,
            parser,
            axes: tracker_axes(),
            record: TrackerRecord::default(),
            seq: 0,
        })
    }

    /// Opens the tracker now: port, output settings, and a check that the station reports.
    pub fn open(cfg: TrackerConfig) -> Result<Tracker, DeviceError> {
        let mut t = Tracker::new(cfg)?;
        link_loop::connect_now(&mut t)?;
        Ok(t)
    }

    pub fn config(&self) -> &TrackerConfig {
        &self.cfg
    }

    /// Counters since `new`, across reconnections.
    pub fn stats(&self) -> LinkStats {
        self.upkeep.stats.with_parser(&self.parser.stats)
    }

    pub fn connected(&self) -> bool {
        self.upkeep.connected()
    }

    /// Waits up to the read slice for the next record of the configured station and writes
    /// the wrist pose (world frame, metres) into `out`. Never allocates on the sample path.
    ///
    /// `Err` reports a problem the driver is already handling (reconnecting with backoff): log
    /// it and call `read` again.
    pub fn read(&mut self, out: &mut TrackerSample) -> Result<ReadOutcome, DeviceError> {
        link_loop::read(self, out)
    }
}

impl Protocol for Tracker {
    type Sample = TrackerSample;
    type Buffer = FastrakParser;
    const DEVICE: &'static str = DEVICE;
    const POLL_COMMAND: &'static [u8] = b"P";

    fn poll_rate_hz(&self) -> Option<f64> {
        match self.cfg.mode {
            TrackerMode::Continuous => None,
            TrackerMode::Polled { rate_hz } => Some(rate_hz),
        }
    }

    fn link(&self) -> &LinkSettings {
        &self.cfg.link
    }

    fn connect(&mut self) -> Result<Link, DeviceError> {
        let mut link = link_loop::open_quiet(DEVICE, &self.cfg.link, b"c", &mut self.parser)?;
        let mut cmd = [0u8; 32];
        cmd[0] = match self.cfg.format {
            Format::Ascii => b'F',
            Format::Binary => b'f',
        };
        cmd[1] = match self.cfg.units {
            Units::Inches => b'U',
            Units::Centimetres => b'u',
        };
        link.write_all(&cmd[..2])?;
        // Every station gets the same list, so records of other stations parse too (and are
        // skipped) instead of looking like damage.
        let list = output_list(&self.cfg);
        for station in 1..=4u8 {
            let mut n = 0;
            for b in [b'O', b'0' + station] {
                cmd[n] = b;
                n += 1;
            }
            for it in list {
                cmd[n] = b',';
                n += 1;
                if it >= 10 {
                    cmd[n] = b'0' + it / 10;
                    n += 1;
                }
                cmd[n] = b'0' + it % 10;
                n += 1;
            }
            cmd[n] = b'\r';
            n += 1;
            link.write_all(&cmd[..n])?;
        }
        link.write_all(b"P")?;
        let deadline = Instant::now() + self.cfg.link.answer_timeout;
        let mut seen = [false; 4];
        loop {
            while self.parser.next(&mut self.record) {
                let s = self.record.station;
                if (1..=4).contains(&s) {
                    seen[usize::from(s - 1)] = true;
                }
                if s == self.cfg.station {
                    // Drop the rest of the answer to `P`; the stream starts clean.
                    self.parser.clear();
                    if self.cfg.mode == TrackerMode::Continuous {
                        link.write_all(b"C")?;
                    }
                    return Ok(link);
                }
            }
            let now = Instant::now();
            if now >= deadline {
                if seen.iter().any(|s| *s) {
                    return Err(DeviceError::StationMissing {
                        port: self.cfg.link.port.clone(),
                        station: self.cfg.station,
                        seen,
                    });
                }
                return Err(DeviceError::NoAnswer {
                    device: DEVICE,
                    port: self.cfg.link.port.clone(),
                    command: "`P` (one record)",
                    waited: self.cfg.link.answer_timeout,
                    hint: format!(
                        "is it switched on, on this port, at {} baud (its switches set the rate)?",
                        self.cfg.link.baud
                    ),
                });
            }
            link_loop::receive_until(&mut link, &mut self.parser, deadline)?;
        }
    }

    /// Only the configured station's records become samples; other stations' are counted and
    /// skipped (every station reports the same list), and a record the tracker flags or that
    /// does not place the wrist in the world is rejected, not an end of the search.
    fn take_sample(&mut self, out: &mut TrackerSample) -> bool {
        while self.parser.next(&mut self.record) {
            if self.record.station != self.cfg.station {
                self.upkeep.stats.other_station_records += 1;
                continue;
            }
            if self.record.error != b' ' {
                // The tracker flags the record itself as bad; not a sample.
                self.upkeep.stats.rejected_records += 1;
                continue;
            }
            let Some(wrist) = record_to_world(
                &self.record,
                self.cfg.units,
                self.axes,
                &self.cfg.to_world,
                &self.cfg.wrist_offset,
            ) else {
                self.upkeep.stats.rejected_records += 1;
                continue;
            };
            let now_ns = monotonic_ns();
            out.wrist = wrist;
            out.station = u32::from(self.cfg.station);
            out.stamp = Stamp::at_origin(self.seq, now_ns.saturating_sub(self.cfg.epoch_ns));
            self.seq += 1;
            return true;
        }
        false
    }

    /// The FASTRAK sends no error replies of its own (its per-record error character is
    /// counted as a rejected record), so a silence report has nothing to add.
    fn take_reported(&mut self) -> Option<&'static str> {
        None
    }

    fn parts(&mut self) -> (&mut LinkUpkeep, &mut FastrakParser) {
        (&mut self.upkeep, &mut self.parser)
    }
}

impl Drop for Tracker {
    /// Leaves the tracker quiet for the next program that opens it.
    fn drop(&mut self) {
        self.upkeep.send_if_up(b"c");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn config_checks_name_the_key() {
        let mut cfg = TrackerConfig::new("/dev/null");
        cfg.station = 5;
        let Err(e) = Tracker::new(cfg) else {
            panic!("accepted station 5")
        };
        assert!(e.to_string().contains("tracker.station"), "{e}");
    }
}
