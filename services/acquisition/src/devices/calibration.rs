//! Per-sensor glove calibration: the raw byte a CyberGlove reports (1..=255) to a joint angle.
//!
//! Bend sensors differ from glove to glove and from hand to hand, so the mapping is linear per
//! sensor, `angle = gain * raw + offset`, with gain and offset measured per user (e.g. with
//! the flat-hand / fist poses of the vendor's calibration tools) and kept in a small text file:
//!
//! ```text
//! # handblocks CyberGlove calibration
//! units = degrees          # optional: "radians" (the default) or "degrees", for gain and offset
//! # one line per sensor, in the glove's order: NAME GAIN OFFSET
//! thumb_rotation   0.40  -10.0
//! thumb_mcp        0.35    0.0
//! ...
//! ```
//!
//! The file has 18 or 22 sensor lines, which is the glove size it fits. Each line names its
//! sensor ([`joint_name`]) so that a file in the wrong order, or for the other glove size, is
//! caught at load with the line that is wrong rather than producing a wrong hand. `#` starts a
//! comment; blank lines are ignored. Gains must lie in [-0.1, 0.1] rad per count and offsets in
//! [-2π, 2π] rad (after unit conversion), which any real calibration does.

use std::f64::consts::TAU;
use std::fmt;
use std::path::{Path, PathBuf};

use common::glove::{sensor_order, GloveJoint, SENSORS_18, SENSORS_22};
use common::MAX_GLOVE_SENSORS;

/// The largest |gain| accepted, radians per count (255 counts would be 25 rad).
pub const MAX_GAIN: f64 = 0.1;
/// The largest |offset| accepted, radians.
pub const MAX_OFFSET: f64 = TAU;

/// The largest calibration file read (one has 18 or 22 short lines): a device, a pipe or
/// anything longer is refused naming the file, rather than read for ever.
pub const MAX_FILE_BYTES: u64 = 1 << 20;

/// Raw byte to radians, per sensor.
#[derive(Debug, Clone, PartialEq)]
pub struct Calibration {
    sensor_count: u32,
    gain: [f64; MAX_GLOVE_SENSORS],
    offset: [f64; MAX_GLOVE_SENSORS],
    /// The file it came from; None for [`Calibration::nominal`].
    pub file: Option<PathBuf>,
}

/// Why a calibration file cannot be used: the file, the line (0 for the file as a whole), and
/// what is allowed.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrationError {
    pub file: PathBuf,
    pub line: usize,
    pub problem: String,
}

impl fmt::Display for CalibrationError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.line == 0 {
            write!(f, "{}: {}", self.file.display(), self.problem)
        } else {
            write!(
                f,
                "{}: line {}: {}",
                self.file.display(),
                self.line,
                self.problem
            )
        }
    }
}

impl std::error::Error for CalibrationError {}

/// The name a calibration file uses for a sensor: the joint in snake case.
pub fn joint_name(joint: GloveJoint) -> &'static str {
    use GloveJoint::*;
    match joint {
        ThumbRotation => "thumb_rotation",
        ThumbMcp => "thumb_mcp",
        ThumbIp => "thumb_ip",
        ThumbIndexAbduction => "thumb_index_abduction",
        IndexMcp => "index_mcp",
        IndexPip => "index_pip",
        IndexDip => "index_dip",
        MiddleMcp => "middle_mcp",
        MiddlePip => "middle_pip",
        MiddleDip => "middle_dip",
        MiddleIndexAbduction => "middle_index_abduction",
        RingMcp => "ring_mcp",
        RingPip => "ring_pip",
        RingDip => "ring_dip",
        RingMiddleAbduction => "ring_middle_abduction",
        LittleMcp => "little_mcp",
        LittlePip => "little_pip",
        LittleDip => "little_dip",
        LittleRingAbduction => "little_ring_abduction",
        PalmArch => "palm_arch",
        WristPitch => "wrist_pitch",
        WristYaw => "wrist_yaw",
    }
}

impl Calibration {
    /// A usable stand-in when no calibration file is given: flexion sensors map raw 1..=255 to
    /// 0..1.6 rad, abductions to -0.35..0.35 rad, the wrist to -1..1 rad. Good enough to see a
    /// hand open and close; not a measurement.
    pub fn nominal(sensor_count: u32) -> Option<Calibration> {
        let order = sensor_order(sensor_count)?;
        let mut c = Calibration {
            sensor_count,
            gain: [0.0; MAX_GLOVE_SENSORS],
            offset: [0.0; MAX_GLOVE_SENSORS],
            file: None,
        };
        for (i, joint) in order.iter().enumerate() {
            use GloveJoint::*;
            let (lo, hi) = match joint {
                ThumbIndexAbduction | MiddleIndexAbduction | RingMiddleAbduction
                | LittleRingAbduction => (-0.35, 0.35),
                WristPitch | WristYaw => (-1.0, 1.0),
                _ => (0.0, 1.6),
            };
            let gain = (hi - lo) / 254.0;
            c.gain[i] = gain;
            c.offset[i] = lo - gain;
        }
        Some(c)
    }

    /// Reads a calibration file (format in the module docs).
    pub fn load(file: &Path) -> Result<Calibration, CalibrationError> {
        let text = common::config::read_bounded_text(file, MAX_FILE_BYTES).map_err(|e| {
            CalibrationError {
                file: file.to_path_buf(),
                line: 0,
                problem: format!("cannot read the calibration file: {e}"),
            }
        })?;
        Calibration::parse(file, &text)
    }

    /// Parses the text of a calibration file; `file` is only used to name errors.
    pub fn parse(file: &Path, text: &str) -> Result<Calibration, CalibrationError> {
        let err = |line: usize, problem: String| CalibrationError {
            file: file.to_path_buf(),
            line,
            problem,
        };
        let mut scale = 1.0;
        let mut seen_sensor = false;
        let mut c = Calibration {
            sensor_count: 0,
            gain: [0.0; MAX_GLOVE_SENSORS],
            offset: [0.0; MAX_GLOVE_SENSORS],
            file: Some(file.to_path_buf()),
        };
        let mut n = 0usize;
        let mut names_seen = [0u8; MAX_GLOVE_SENSORS];
        for (i, raw_line) in text.lines().enumerate() {
            let line_no = i + 1;
            let line = raw_line.split('#').next().unwrap_or("").trim();
            if line.is_empty() {
                continue;
            }
            if let Some(rest) = line.strip_prefix("units") {
                let value = rest.trim_start().strip_prefix('=').map(str::trim);
                if seen_sensor {
                    return Err(err(
                        line_no,
                        "`units` must come before the first sensor line".into(),
                    ));
                }
                scale = match value {
                    Some("radians") => 1.0,
                    Some("degrees") => std::f64::consts::PI / 180.0,
                    _ => {
                        return Err(err(
                            line_no,
                            format!("`{line}`: write `units = radians` or `units = degrees`"),
                        ))
                    }
                };
                continue;
            }
            seen_sensor = true;
            let mut fields = line.split_whitespace();
            let (Some(name), Some(gain), Some(offset), None) =
                (fields.next(), fields.next(), fields.next(), fields.next())
            else {
                return Err(err(
                    line_no,
                    format!("`{line}`: expected three fields, NAME GAIN OFFSET"),
                ));
            };
            if n >= SENSORS_22.len() {
                return Err(err(
                    line_no,
                    format!(
                        "`{name}`: more than 22 sensor lines; a CyberGlove has 18 or 22 sensors"
                    ),
                ));
            }
            // Both orders agree up to index_pip; from there the file's own length decides,
            // so accept the name from either order and check the whole order at the end.
            let expected_22 = joint_name(SENSORS_22[n]);
            let expected_18 = SENSORS_18.get(n).map(|j| joint_name(*j));
            if name != expected_22 && Some(name) != expected_18 {
                let expect = match expected_18 {
                    Some(e18) if e18 != expected_22 => {
                        format!("`{e18}` (18-sensor glove) or `{expected_22}` (22-sensor glove)")
                    }
                    _ => format!("`{expected_22}`"),
                };
                return Err(err(
                    line_no,
                    format!(
                        "sensor {} should be {expect}, found `{name}`: the lines must follow the \
                         glove's sensor order",
                        n + 1
                    ),
                ));
            }
            let number = |what: &str, s: &str, max: f64| -> Result<f64, CalibrationError> {
                let v: f64 = s
                    .parse()
                    .map_err(|_| err(line_no, format!("`{name}` {what} `{s}` is not a number")))?;
                let v = v * scale;
                if !v.is_finite() || v.abs() > max {
                    return Err(err(
                        line_no,
                        format!(
                            "`{name}` {what} {s} is out of range: allowed [-{max:.3}, {max:.3}] \
                             radians{}",
                            if scale != 1.0 {
                                format!(" ({:.2} degrees)", max / scale)
                            } else {
                                String::new()
                            }
                        ),
                    ));
                }
                Ok(v)
            };
            c.gain[n] = number("gain", gain, MAX_GAIN)?;
            c.offset[n] = number("offset", offset, MAX_OFFSET)?;
            names_seen[n] = name_index(name);
            n += 1;
        }
        let order: &[GloveJoint] = match n {
            18 => &SENSORS_18,
            22 => &SENSORS_22,
            _ => {
                return Err(err(
                    0,
                    format!(
                        "{n} sensor lines; a calibration has one line per sensor, 18 or 22 \
                         (a CyberGlove's sizes)"
                    ),
                ))
            }
        };
        // The per-line check accepted names of either order; now the size is known, the
        // whole order must be that size's.
        for (i, joint) in order.iter().enumerate() {
            if names_seen[i] != name_index(joint_name(*joint)) {
                return Err(err(
                    0,
                    format!(
                        "{n} sensor lines, so an {n}-sensor glove, but sensor {} is not `{}`: \
                         the lines must follow that glove's sensor order",
                        i + 1,
                        joint_name(*joint)
                    ),
                ));
            }
        }
        c.sensor_count = n as u32;
        Ok(c)
    }

    /// 18 or 22.
    pub fn sensor_count(&self) -> u32 {
        self.sensor_count
    }

    /// Raw bytes (in the glove's order) to radians. Always finite: gains and offsets are
    /// checked finite at load.
    pub fn apply(&self, raw: &[u8], out: &mut [f64; MAX_GLOVE_SENSORS]) {
        let n = (self.sensor_count as usize).min(raw.len());
        for i in 0..n {
            out[i] = self.gain[i] * f64::from(raw[i]) + self.offset[i];
        }
        for v in out.iter_mut().skip(n) {
            *v = 0.0;
        }
    }

    /// The raw byte that gives `angle` on sensor `i` (rounded, clamped to 1..=255): what an
    /// emulated glove sends to show a given hand.
    pub fn raw_for(&self, i: usize, angle: f64) -> u8 {
        let g = self.gain.get(i).copied().unwrap_or(0.0);
        if g == 0.0 || !angle.is_finite() {
            return 1;
        }
        let r = ((angle - self.offset[i]) / g).round();
        r.clamp(1.0, 255.0) as u8
    }
}

fn name_index(name: &str) -> u8 {
    SENSORS_22
        .iter()
        .position(|j| joint_name(*j) == name)
        .map(|i| i as u8 + 1)
        .unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file_for(order: &[GloveJoint], units: &str) -> String {
        let mut s = String::from("# test calibration\n");
        s.push_str(units);
        s.push('\n');
        for (i, j) in order.iter().enumerate() {
            s.push_str(&format!(
                "{}  {} {}\n",
                joint_name(*j),
                0.01,
                -0.1 * i as f64
            ));
        }
        s
    }

    #[test]
    fn parses_both_sizes_and_applies_gain_and_offset() {
        for order in [&SENSORS_18[..], &SENSORS_22[..]] {
            let c = Calibration::parse(Path::new("g.cal"), &file_for(order, "")).unwrap();
            assert_eq!(c.sensor_count() as usize, order.len());
            let raw = [100u8; MAX_GLOVE_SENSORS];
            let mut out = [9.0; MAX_GLOVE_SENSORS];
            c.apply(&raw[..order.len()], &mut out);
            for (i, v) in out.iter().enumerate().take(order.len()) {
                assert!((v - (1.0 - 0.1 * i as f64)).abs() < 1e-12);
            }
            assert!(out[order.len()..].iter().all(|v| *v == 0.0));
        }
    }

    #[test]
    fn degrees_are_converted() {
        let c = Calibration::parse(
            Path::new("g.cal"),
            &file_for(&SENSORS_18, "units = degrees"),
        )
        .unwrap();
        let mut out = [0.0; MAX_GLOVE_SENSORS];
        c.apply(&[1u8; 18], &mut out);
        assert!((out[0] - 0.01f64.to_radians()).abs() < 1e-12);
    }

    #[test]
    fn errors_name_the_file_line_and_range() {
        let mut text = file_for(&SENSORS_22, "");
        text = text.replace("index_pip  0.01", "index_pip  7");
        let e = Calibration::parse(Path::new("glove.cal"), &text).unwrap_err();
        let msg = e.to_string();
        assert!(msg.starts_with("glove.cal: line 8:"), "{msg}");
        assert!(msg.contains("[-0.100, 0.100]"), "{msg}");

        let text = file_for(&SENSORS_22, "").replace("ring_mcp", "ring_pip");
        let msg = Calibration::parse(Path::new("glove.cal"), &text)
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains("`ring_mcp`") && msg.contains("found `ring_pip`"),
            "{msg}"
        );

        let text: String = file_for(&SENSORS_22, "")
            .lines()
            .take(15)
            .collect::<Vec<_>>()
            .join("\n");
        let msg = Calibration::parse(Path::new("glove.cal"), &text)
            .unwrap_err()
            .to_string();
        assert!(msg.contains("13 sensor lines"), "{msg}");

        let text = file_for(&SENSORS_18, "").replace("thumb_mcp  0.01", "thumb_mcp  x");
        let msg = Calibration::parse(Path::new("glove.cal"), &text)
            .unwrap_err()
            .to_string();
        assert!(msg.contains("not a number"), "{msg}");

        let text = file_for(&SENSORS_18, "").replace("thumb_ip  0.01", "thumb_ip  NaN");
        let msg = Calibration::parse(Path::new("glove.cal"), &text)
            .unwrap_err()
            .to_string();
        assert!(msg.contains("out of range"), "{msg}");
    }

    #[test]
    fn an_18_sensor_file_with_a_dip_line_is_caught() {
        // 18 lines, but following the 22-sensor order (so index_dip where middle_mcp belongs).
        let text = file_for(&SENSORS_22[..18], "");
        let msg = Calibration::parse(Path::new("glove.cal"), &text)
            .unwrap_err()
            .to_string();
        assert!(msg.contains("18-sensor glove"), "{msg}");
    }

    #[test]
    fn nominal_covers_raw_range_and_raw_for_inverts() {
        let c = Calibration::nominal(22).unwrap();
        let mut out = [0.0; MAX_GLOVE_SENSORS];
        c.apply(&[1u8; 22], &mut out);
        assert!(out[1].abs() < 1e-12);
        c.apply(&[255u8; 22], &mut out);
        assert!((out[1] - 1.6).abs() < 1e-12);
        for raw in 1..=255u8 {
            let mut a = [0.0; MAX_GLOVE_SENSORS];
            c.apply(&[raw; 22], &mut a);
            assert_eq!(c.raw_for(5, a[5]), raw);
        }
        assert!(Calibration::nominal(20).is_none());
    }

    /// Issue 16: `Calibration::load` read `/dev/zero` (a session's `calibration` may name any
    /// path) until memory ran out; now only a regular file of at most MAX_FILE_BYTES is read.
    #[test]
    fn a_calibration_file_that_is_a_device_or_too_long_is_refused() {
        let e = Calibration::load(Path::new("/dev/zero")).unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.starts_with(
                "/dev/zero: cannot read the calibration file: it is a character device, not a \
                 regular file"
            ),
            "{msg}"
        );
        let dir = std::env::temp_dir().join(format!("hb-cal-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let big = dir.join("big.cal");
        std::fs::write(&big, vec![b'#'; MAX_FILE_BYTES as usize + 1]).unwrap();
        let msg = Calibration::load(&big).unwrap_err().to_string();
        assert!(msg.contains("at most 1048576 are read"), "{msg}");
        std::fs::write(&big, b"thumb_rotation 0.01 \xff\n").unwrap();
        let msg = Calibration::load(&big).unwrap_err().to_string();
        assert!(
            msg.contains("the byte at offset 20 is not valid UTF-8"),
            "{msg}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn the_example_file_loads() {
        let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/devices/glove-22.cal");
        let c = Calibration::load(&file).unwrap();
        assert_eq!(c.sensor_count(), 22);
    }
}
