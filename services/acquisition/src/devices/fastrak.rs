//! The Polhemus FASTRAK: up to four receivers ("stations"), 120 records a second shared among
//! the active ones, over RS-232.
//!
//! The protocol, as far as this driver uses it (single-character commands, except `O`, which
//! ends with a carriage return):
//! * `c` / `C`: continuous output off / on; `P`: one record per active station.
//! * `F` / `f`: ASCII / binary records. `U` / `u`: inches / centimetres.
//! * `O<station>,<item>,<item>,...\r`: the output list of a station. Items used here:
//!   0 a space, 1 CR LF, 2 position x y z, 4 Euler angles (azimuth, elevation, roll, degrees),
//!   11 orientation quaternion (q0 = w, q1, q2, q3).
//! * Every record starts with `0`, the station number (`1`..`4`, ASCII in both formats) and an
//!   error character (a space when all is well), then the items in list order. ASCII items are
//!   signed decimal fields (`Sxxx.xx` for positions and angles, `Sx.xxxx` for quaternion
//!   components, separated by blanks); binary items are IEEE-754 single floats, least
//!   significant byte first. The driver always ends the list with item 1 (CR LF), which frames
//!   the ASCII records and is one more check on the binary ones.
//!
//! Resynchronisation: a candidate record is accepted only if it is complete, every value is a
//! finite number in the device's range, the quaternion has unit length and the record ends in
//! CR LF; otherwise the parser drops one byte and looks for the next `0<station>` header. ASCII
//! fields are read as signed numbers between blanks or signs rather than by column, so both
//! the FASTRAK's fixed columns and a tolerant writer parse.
//!
//! # Frames
//! The FASTRAK reports in its transmitter's frame: x forward, y right, z down (right-handed),
//! orientation as the receiver's rotation from that frame. The project's frame is right-handed
//! with y up; the fixed mapping used here takes the transmitter's forward to -z, right to +x and
//! down to -y:
//!
//! ```text
//! project (x, y, z) = (tracker y, -tracker z, -tracker x)
//! ```
//!
//! and rotations are conjugated by the same mapping, so a receiver aligned with the
//! transmitter gives the identity rotation. Then `to_world` (the transmitter's pose in the
//! world, in those project axes) places the result, and `wrist_offset` (the wrist's pose in the
//! receiver's frame, project axes: where on the hand the receiver is strapped) moves it from
//! the receiver to the wrist. Positions are converted from inches (2.54 cm) or centimetres to
//! metres.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use common::{monotonic_ns, Pose, Stamp, TrackerSample};
use glam::{DMat3, DQuat, DVec3};

use super::link_loop::{self, LinkUpkeep, Protocol, RecordBuffer};
use super::serial::{Backoff, Link, LinkState, LinkStats};
use super::{DeviceError, ReadOutcome};

const DEVICE: &str = "tracker";

/// Output-list item numbers.
pub mod item {
    pub const SPACE: u8 = 0;
    pub const CRLF: u8 = 1;
    pub const POSITION: u8 = 2;
    pub const EULER: u8 = 4;
    pub const QUATERNION: u8 = 11;
}

/// Record encoding.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    Ascii,
    Binary,
}

/// Position units the tracker reports in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Units {
    Inches,
    Centimetres,
}

impl Format {
    /// The names a session file uses.
    pub const NAMES: [&'static str; 2] = ["ascii", "binary"];

    /// `"ascii"` or `"binary"`.
    pub fn from_name(name: &str) -> Option<Format> {
        match name {
            "ascii" => Some(Format::Ascii),
            "binary" => Some(Format::Binary),
            _ => None,
        }
    }
}

impl Units {
    /// The names a session file uses.
    pub const NAMES: [&'static str; 4] = ["cm", "centimetres", "in", "inches"];

    /// `"cm"`/`"centimetres"` or `"in"`/`"inches"`.
    pub fn from_name(name: &str) -> Option<Units> {
        match name {
            "cm" | "centimetres" | "centimeters" => Some(Units::Centimetres),
            "in" | "inches" => Some(Units::Inches),
            _ => None,
        }
    }

    pub fn metres_per_unit(self) -> f64 {
        match self {
            Units::Inches => 0.0254,
            Units::Centimetres => 0.01,
        }
    }
}

/// Which orientation item the driver asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Orientation {
    /// Item 11: no gimbal lock, the default.
    Quaternion,
    /// Item 4: for firmware or setups that only give Euler angles.
    Euler,
}

impl Orientation {
    /// The names a session file uses.
    pub const NAMES: [&'static str; 2] = ["quaternion", "euler"];

    pub fn from_name(name: &str) -> Option<Orientation> {
        match name {
            "quaternion" => Some(Orientation::Quaternion),
            "euler" => Some(Orientation::Euler),
            _ => None,
        }
    }
}

/// How records are requested.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TrackerMode {
    /// `C`: the tracker sends at its own rate (120 Hz shared among active stations).
    Continuous,
    /// `P` at `rate_hz`.
    Polled { rate_hz: f64 },
}

/// Where the tracker is, how to read it, and where its frame sits in the world.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackerConfig {
    pub port: PathBuf,
    /// Usually 115200 (the FASTRAK's switches set it).
    pub baud: u32,
    pub format: Format,
    pub units: Units,
    pub orientation: Orientation,
    pub mode: TrackerMode,
    /// The receiver on the hand, 1..=4.
    pub station: u8,
    /// The transmitter's pose in the world (project axes, see the module docs).
    pub to_world: Pose,
    /// The wrist's pose in the receiver's frame (project axes).
    pub wrist_offset: Pose,
    pub answer_timeout: Duration,
    pub silence_timeout: Duration,
    pub read_slice: Duration,
    pub backoff: Backoff,
    /// CLOCK_MONOTONIC (ns) that is source time 0; give the glove and the tracker the same.
    pub epoch_ns: u64,
}

impl TrackerConfig {
    /// The usual settings: 115200 baud, binary, centimetres, quaternions, continuous,
    /// station 1, transmitter at the world origin.
    pub fn new(port: impl Into<PathBuf>) -> TrackerConfig {
        TrackerConfig {
            port: port.into(),
            baud: 115_200,
            format: Format::Binary,
            units: Units::Centimetres,
            orientation: Orientation::Quaternion,
            mode: TrackerMode::Continuous,
            station: 1,
            to_world: Pose::IDENTITY,
            wrist_offset: Pose::IDENTITY,
            answer_timeout: Duration::from_millis(500),
            silence_timeout: Duration::from_millis(500),
            read_slice: Duration::from_millis(50),
            backoff: Backoff::default(),
            epoch_ns: monotonic_ns(),
        }
    }

    fn check(&self) -> Result<(), DeviceError> {
        super::serial::check_timing(
            "tracker",
            &[
                self.answer_timeout,
                self.silence_timeout,
                self.read_slice,
                self.backoff.first,
                self.backoff.max,
            ],
        )?;
        if !(1..=4).contains(&self.station) {
            return Err(DeviceError::Config {
                key: "tracker.station",
                problem: format!("{}: a FASTRAK has stations 1 to 4", self.station),
            });
        }
        if self.baud == 0 {
            return Err(DeviceError::Config {
                key: "tracker.baud",
                problem: "0: give the tracker's baud rate, usually 115200".into(),
            });
        }
        for (key, pose) in [
            ("tracker.to_world", &self.to_world),
            ("tracker.wrist_offset", &self.wrist_offset),
        ] {
            let n = DQuat::from_array(pose.rotation).length();
            if !pose.is_finite() || (n - 1.0).abs() > 1e-3 {
                return Err(DeviceError::Config {
                    key,
                    problem: "needs a finite position and a unit quaternion [x, y, z, w]".into(),
                });
            }
        }
        if let TrackerMode::Polled { rate_hz } = self.mode {
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
    pub fn output_list(&self) -> [u8; 3] {
        let o = match self.orientation {
            Orientation::Quaternion => item::QUATERNION,
            Orientation::Euler => item::EULER,
        };
        [item::POSITION, o, item::CRLF]
    }
}

/// One decoded record, in the tracker's own frame and units.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TrackerRecord {
    pub station: u8,
    /// The record's error character (b' ' when all is well).
    pub error: u8,
    pub position: [f64; 3],
    pub has_position: bool,
    /// Azimuth, elevation, roll in degrees.
    pub euler: [f64; 3],
    pub has_euler: bool,
    /// w, x, y, z as the FASTRAK sends them (q0 scalar).
    pub quaternion: [f64; 4],
    pub has_quaternion: bool,
}

const MAX_ITEMS: usize = 8;
const MAX_ASCII_RECORD: usize = 160;

/// Bytes in, FASTRAK records out; pure, fixed-size, no allocation.
#[derive(Debug, Clone)]
pub struct FastrakParser {
    format: Format,
    items: [u8; MAX_ITEMS],
    item_count: usize,
    buf: [u8; 1024],
    len: usize,
    pub stats: LinkStats,
}

fn binary_item_len(item: u8) -> Option<usize> {
    match item {
        item::SPACE => Some(1),
        item::CRLF => Some(2),
        item::POSITION | item::EULER => Some(12),
        item::QUATERNION => Some(16),
        _ => None,
    }
}

fn value_count(item: u8) -> usize {
    match item {
        item::POSITION | item::EULER => 3,
        item::QUATERNION => 4,
        _ => 0,
    }
}

impl FastrakParser {
    /// A parser for records of `items` (supported: 0, 1, 2, 4, 11; ASCII lists must end in 1).
    pub fn new(format: Format, items: &[u8]) -> Result<FastrakParser, String> {
        if items.is_empty() || items.len() > MAX_ITEMS {
            return Err(format!("an output list has 1 to {MAX_ITEMS} items"));
        }
        if let Some(bad) = items.iter().find(|i| binary_item_len(**i).is_none()) {
            return Err(format!(
                "output item {bad} is not supported (use 0, 1, 2, 4, 11)"
            ));
        }
        if format == Format::Ascii && items.last() != Some(&item::CRLF) {
            return Err("an ASCII output list must end with item 1 (CR LF)".into());
        }
        let mut p = FastrakParser {
            format,
            items: [0; MAX_ITEMS],
            item_count: items.len(),
            buf: [0; 1024],
            len: 0,
            stats: LinkStats::default(),
        };
        p.items[..items.len()].copy_from_slice(items);
        Ok(p)
    }

    fn items(&self) -> &[u8] {
        &self.items[..self.item_count]
    }

    fn binary_len(&self) -> usize {
        3 + self
            .items()
            .iter()
            .map(|i| binary_item_len(*i).unwrap_or(0))
            .sum::<usize>()
    }

    pub fn clear(&mut self) {
        self.len = 0;
    }

    pub fn space(&mut self) -> &mut [u8] {
        if self.len == self.buf.len() {
            let half = self.buf.len() / 2;
            self.buf.copy_within(half.., 0);
            self.len -= half;
            self.stats.garbage_bytes += half as u64;
        }
        &mut self.buf[self.len..]
    }

    pub fn commit(&mut self, n: usize) {
        self.len = (self.len + n).min(self.buf.len());
    }

    /// Appends bytes (for tests); returns how many fit.
    pub fn push(&mut self, bytes: &[u8]) -> usize {
        let space = self.space();
        let n = bytes.len().min(space.len());
        space[..n].copy_from_slice(&bytes[..n]);
        self.commit(n);
        n
    }

    fn consume(&mut self, n: usize) {
        let n = n.min(self.len);
        self.buf.copy_within(n..self.len, 0);
        self.len -= n;
    }

    /// The next valid record (any station), or None until more bytes arrive.
    pub fn next(&mut self, out: &mut TrackerRecord) -> bool {
        let mut p = 0;
        let found = loop {
            while p < self.len && self.buf[p] != b'0' {
                p += 1;
            }
            if p >= self.len {
                break None;
            }
            let avail = &self.buf[p..self.len];
            if avail.len() < 3 {
                // Reject early when what is there already cannot be a header.
                if avail.len() >= 2 && !(b'1'..=b'4').contains(&avail[1]) {
                    p += 1;
                    continue;
                }
                break None;
            }
            if !(b'1'..=b'4').contains(&avail[1]) || !(0x20..0x7f).contains(&avail[2]) {
                p += 1;
                continue;
            }
            let verdict = match self.format {
                Format::Binary => self.try_binary(p, out),
                Format::Ascii => self.try_ascii(p, out),
            };
            match verdict {
                Verdict::Record(len) => break Some(len),
                Verdict::Incomplete => break None,
                Verdict::Bad => {
                    self.stats.rejected_records += 1;
                    p += 1;
                }
            }
        };
        self.stats.garbage_bytes += p as u64;
        match found {
            Some(len) => {
                self.consume(p + len);
                true
            }
            None => {
                self.consume(p);
                false
            }
        }
    }

    fn try_binary(&self, p: usize, out: &mut TrackerRecord) -> Verdict {
        let need = self.binary_len();
        let avail = &self.buf[p..self.len];
        if avail.len() < need {
            return Verdict::Incomplete;
        }
        let mut rec = header(avail);
        let mut at = 3;
        for &it in self.items() {
            let len = binary_item_len(it).unwrap_or(0);
            let bytes = &avail[at..at + len];
            let ok = match it {
                item::SPACE => bytes[0] == b' ',
                item::CRLF => bytes == b"\r\n",
                _ => {
                    let mut v = [0.0f64; 4];
                    for (k, chunk) in bytes.chunks_exact(4).enumerate() {
                        v[k] =
                            f64::from(f32::from_le_bytes([chunk[0], chunk[1], chunk[2], chunk[3]]));
                    }
                    rec.set(it, &v)
                }
            };
            if !ok {
                return Verdict::Bad;
            }
            at += len;
        }
        if !rec.plausible() {
            return Verdict::Bad;
        }
        *out = rec;
        Verdict::Record(need)
    }

    fn try_ascii(&self, p: usize, out: &mut TrackerRecord) -> Verdict {
        let avail = &self.buf[p..self.len];
        let window = &avail[..avail.len().min(MAX_ASCII_RECORD)];
        let Some(end) = window.windows(2).position(|w| w == b"\r\n") else {
            if avail.len() >= MAX_ASCII_RECORD {
                return Verdict::Bad;
            }
            return Verdict::Incomplete;
        };
        let mut rec = header(avail);
        let mut values = [0.0f64; 4 * MAX_ITEMS];
        let Some(count) = parse_numbers(&avail[3..end], &mut values) else {
            return Verdict::Bad;
        };
        let mut at = 0;
        for &it in self.items() {
            let n = value_count(it);
            if n == 0 {
                continue;
            }
            if at + n > count || !rec.set(it, &values[at..at + n]) {
                return Verdict::Bad;
            }
            at += n;
        }
        if at != count || !rec.plausible() {
            return Verdict::Bad;
        }
        *out = rec;
        Verdict::Record(end + 2)
    }
}

enum Verdict {
    Record(usize),
    Incomplete,
    Bad,
}

fn header(avail: &[u8]) -> TrackerRecord {
    TrackerRecord {
        station: avail[1] - b'0',
        error: avail[2],
        ..TrackerRecord::default()
    }
}

impl TrackerRecord {
    fn set(&mut self, it: u8, v: &[f64]) -> bool {
        if v.iter().any(|x| !x.is_finite()) {
            return false;
        }
        match it {
            item::POSITION => {
                self.position.copy_from_slice(&v[..3]);
                self.has_position = true;
            }
            item::EULER => {
                self.euler.copy_from_slice(&v[..3]);
                self.has_euler = true;
            }
            item::QUATERNION => {
                self.quaternion.copy_from_slice(&v[..4]);
                self.has_quaternion = true;
            }
            _ => {}
        }
        true
    }

    /// Values a working FASTRAK can report (positions within 10 m in either unit, angles in
    /// their ranges, unit quaternions): anything else is a damaged record.
    fn plausible(&self) -> bool {
        if self.position.iter().any(|v| v.abs() > 1000.0) {
            return false;
        }
        if self.has_euler {
            let [az, el, roll] = self.euler;
            if az.abs() > 180.01 || el.abs() > 90.01 || roll.abs() > 180.01 {
                return false;
            }
        }
        if self.has_quaternion {
            let n2: f64 = self.quaternion.iter().map(|q| q * q).sum();
            if !(0.96..=1.04).contains(&n2) {
                return false;
            }
        }
        self.has_quaternion || self.has_euler || self.has_position
    }

    /// The receiver's rotation in the tracker frame (unit), from the quaternion or the Euler
    /// angles (azimuth about z, then elevation about y, then roll about x).
    pub fn rotation(&self) -> DQuat {
        if self.has_quaternion {
            let [w, x, y, z] = self.quaternion;
            DQuat::from_xyzw(x, y, z, w).normalize()
        } else if self.has_euler {
            let [az, el, roll] = self.euler;
            DQuat::from_rotation_z(az.to_radians())
                * DQuat::from_rotation_y(el.to_radians())
                * DQuat::from_rotation_x(roll.to_radians())
        } else {
            DQuat::IDENTITY
        }
    }
}

/// Reads signed decimal numbers separated by blanks (or by the next number's sign) into `out`;
/// None if anything else is there or there are too many.
fn parse_numbers(body: &[u8], out: &mut [f64]) -> Option<usize> {
    let mut count = 0;
    let mut i = 0;
    while i < body.len() {
        let c = body[i];
        if c == b' ' || c == b'\t' {
            i += 1;
            continue;
        }
        if !(c == b'+' || c == b'-' || c == b'.' || c.is_ascii_digit()) {
            return None;
        }
        let start = i;
        i += 1;
        while i < body.len() {
            let c = body[i];
            let exp_sign = (c == b'+' || c == b'-') && matches!(body[i - 1], b'e' | b'E');
            if c.is_ascii_digit() || c == b'.' || c == b'e' || c == b'E' || exp_sign {
                i += 1;
            } else {
                break;
            }
        }
        let text = std::str::from_utf8(&body[start..i]).ok()?;
        let v: f64 = text.parse().ok()?;
        if count >= out.len() {
            return None;
        }
        out[count] = v;
        count += 1;
    }
    Some(count)
}

/// The fixed axis mapping tracker (x forward, y right, z down) -> project (y up, forward -z).
pub fn tracker_axes() -> DQuat {
    DQuat::from_mat3(&DMat3::from_cols(
        DVec3::new(0.0, 0.0, -1.0), // tracker x (forward)
        DVec3::new(1.0, 0.0, 0.0),  // tracker y (right)
        DVec3::new(0.0, -1.0, 0.0), // tracker z (down)
    ))
}

/// A record's receiver pose as the wrist's pose in the world (metres, unit quaternion), or
/// None if the result is not finite.
pub fn record_to_world(
    rec: &TrackerRecord,
    units: Units,
    axes: DQuat,
    to_world: &Pose,
    wrist_offset: &Pose,
) -> Option<Pose> {
    let s = units.metres_per_unit();
    let p_t = DVec3::from_array(rec.position) * s;
    let p = axes * p_t;
    let q = axes * rec.rotation() * axes.conjugate();
    let w_q = DQuat::from_array(to_world.rotation);
    let w_p = DVec3::from_array(to_world.position);
    let sensor_p = w_p + w_q * p;
    let sensor_q = w_q * q;
    let o_q = DQuat::from_array(wrist_offset.rotation);
    let o_p = DVec3::from_array(wrist_offset.position);
    let wrist_p = sensor_p + sensor_q * o_p;
    let wrist_q = (sensor_q * o_q).normalize();
    let pose = Pose {
        position: wrist_p.to_array(),
        rotation: wrist_q.to_array(),
    };
    pose.is_finite().then_some(pose)
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
        cfg.check()?;
        let parser = FastrakParser::new(cfg.format, &cfg.output_list()).map_err(|problem| {
            DeviceError::Config {
                key: "tracker",
                problem,
            }
        })?;
        Ok(Tracker {
            upkeep: LinkUpkeep::new(cfg.backoff),
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
        let link = t.connect()?;
        t.upkeep.up(link, t.parser.stats.garbage_bytes);
        Ok(t)
    }

    pub fn config(&self) -> &TrackerConfig {
        &self.cfg
    }

    pub fn stats(&self) -> LinkStats {
        let mut s = self.upkeep.stats;
        s.garbage_bytes += self.parser.stats.garbage_bytes;
        s.rejected_records += self.parser.stats.rejected_records;
        s
    }

    pub fn connected(&self) -> bool {
        self.upkeep.connected()
    }

    fn connect(&mut self) -> Result<Link, DeviceError> {
        let mut link = Link::open(DEVICE, &self.cfg.port, self.cfg.baud)?;
        link.write_all(b"c")?;
        link.drain(Duration::from_millis(30), Duration::from_millis(300))?;
        self.parser.clear();
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
        let list = self.cfg.output_list();
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
        let deadline = Instant::now() + self.cfg.answer_timeout;
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
                        port: self.cfg.port.clone(),
                        station: self.cfg.station,
                        seen,
                    });
                }
                return Err(DeviceError::NoAnswer {
                    device: DEVICE,
                    port: self.cfg.port.clone(),
                    command: "`P` (one record)",
                    waited: self.cfg.answer_timeout,
                    hint: format!(
                        "is it switched on, on this port, at {} baud (its switches set the rate)?",
                        self.cfg.baud
                    ),
                });
            }
            let space = self.parser.space();
            let got = link.read_some(space, (deadline - now).min(Duration::from_millis(20)))?;
            self.parser.commit(got);
        }
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

impl RecordBuffer for FastrakParser {
    fn space(&mut self) -> &mut [u8] {
        FastrakParser::space(self)
    }

    fn commit(&mut self, n: usize) {
        FastrakParser::commit(self, n)
    }

    fn clear(&mut self) {
        FastrakParser::clear(self)
    }

    fn garbage_bytes(&self) -> u64 {
        self.stats.garbage_bytes
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

    fn read_slice(&self) -> Duration {
        self.cfg.read_slice
    }

    fn silence_timeout(&self) -> Duration {
        self.cfg.silence_timeout
    }

    fn port(&self) -> &Path {
        &self.cfg.port
    }

    fn connect(&mut self) -> Result<Link, DeviceError> {
        Tracker::connect(self)
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
        if let LinkState::Up(link) = &mut self.upkeep.state {
            let _ = link.write_all(b"c");
        }
    }
}

/// Encodes one record as a FASTRAK would (used by the emulator and the tests): `values` in
/// device units, the quaternion as w, x, y, z.
pub fn encode_record(
    format: Format,
    items: &[u8],
    station: u8,
    position: [f64; 3],
    euler: [f64; 3],
    quaternion: [f64; 4],
    out: &mut Vec<u8>,
) {
    use std::io::Write;
    out.push(b'0');
    out.push(b'0' + station);
    out.push(b' ');
    for &it in items {
        let vals: &[f64] = match it {
            item::POSITION => &position,
            item::EULER => &euler,
            item::QUATERNION => &quaternion,
            item::SPACE => {
                out.push(b' ');
                continue;
            }
            item::CRLF => {
                out.extend_from_slice(b"\r\n");
                continue;
            }
            _ => continue,
        };
        for v in vals {
            match format {
                Format::Binary => out.extend_from_slice(&(*v as f32).to_le_bytes()),
                Format::Ascii => {
                    let _ = if it == item::QUATERNION {
                        write!(out, "{v:7.4}")
                    } else {
                        write!(out, "{v:7.2}")
                    };
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIST_Q: [u8; 3] = [item::POSITION, item::QUATERNION, item::CRLF];
    const LIST_E: [u8; 3] = [item::POSITION, item::EULER, item::CRLF];

    fn quat(k: u32) -> [f64; 4] {
        let a = k as f64 * 0.1;
        let (s, c) = (a / 2.0).sin_cos();
        let axis = DVec3::new(1.0, 2.0, 2.0) / 3.0;
        [c, s * axis.x, s * axis.y, s * axis.z]
    }

    fn stream(format: Format, list: &[u8], ks: std::ops::Range<u32>) -> Vec<u8> {
        let mut out = Vec::new();
        for k in ks {
            encode_record(
                format,
                list,
                1 + (k % 2) as u8,
                [k as f64, -2.5 * k as f64, 100.25],
                [k as f64, -(k as f64) / 2.0, 170.0],
                quat(k),
                &mut out,
            );
        }
        out
    }

    fn drain(p: &mut FastrakParser) -> Vec<TrackerRecord> {
        let mut r = TrackerRecord::default();
        let mut v = Vec::new();
        while p.next(&mut r) {
            v.push(r);
        }
        v
    }

    #[test]
    fn clean_streams_in_both_formats() {
        for format in [Format::Ascii, Format::Binary] {
            for list in [&LIST_Q, &LIST_E] {
                let mut p = FastrakParser::new(format, list).unwrap();
                p.push(&stream(format, list, 0..10));
                let recs = drain(&mut p);
                assert_eq!(recs.len(), 10, "{format:?} {list:?}");
                for (k, r) in recs.iter().enumerate() {
                    assert_eq!(r.station, 1 + (k % 2) as u8);
                    assert!((r.position[1] + 2.5 * k as f64).abs() < 0.006);
                    if list == &LIST_Q {
                        for (a, b) in r.quaternion.iter().zip(quat(k as u32)) {
                            assert!((a - b).abs() < 1e-4);
                        }
                    } else {
                        assert!((r.euler[2] - 170.0).abs() < 1e-4);
                    }
                }
                assert_eq!(p.stats.garbage_bytes, 0);
            }
        }
    }

    #[test]
    fn noise_and_cut_records_resynchronise() {
        for format in [Format::Ascii, Format::Binary] {
            let mut bytes = b"\x00\xff01 junk\r\n0".to_vec();
            bytes.extend(stream(format, &LIST_Q, 0..2));
            let cut = stream(format, &LIST_Q, 2..3);
            bytes.extend(&cut[..cut.len() / 2]);
            bytes.extend(stream(format, &LIST_Q, 3..5));
            bytes.extend(b"01 "); // a lone header
            bytes.extend(stream(format, &LIST_Q, 5..6));
            let mut p = FastrakParser::new(format, &LIST_Q).unwrap();
            // Feed in uneven pieces.
            let mut recs = Vec::new();
            for chunk in bytes.chunks(7) {
                p.push(chunk);
                recs.extend(drain(&mut p));
            }
            let xs: Vec<f64> = recs.iter().map(|r| r.position[0].round()).collect();
            assert_eq!(xs, vec![0.0, 1.0, 3.0, 4.0, 5.0], "{format:?}");
            assert!(p.stats.garbage_bytes > 0);
        }
    }

    #[test]
    fn non_finite_and_out_of_range_values_are_rejected() {
        let mut bytes = Vec::new();
        encode_record(
            Format::Binary,
            &LIST_Q,
            1,
            [f64::NAN, 0.0, 0.0],
            [0.0; 3],
            quat(1),
            &mut bytes,
        );
        encode_record(
            Format::Binary,
            &LIST_Q,
            1,
            [1.0, 0.0, 0.0],
            [0.0; 3],
            [2.0, 0.0, 0.0, 0.0],
            &mut bytes,
        );
        encode_record(
            Format::Binary,
            &LIST_Q,
            1,
            [f64::INFINITY, 0.0, 0.0],
            [0.0; 3],
            quat(1),
            &mut bytes,
        );
        let mut p = FastrakParser::new(Format::Binary, &LIST_Q).unwrap();
        p.push(&bytes);
        assert!(drain(&mut p).is_empty());
        let mut p = FastrakParser::new(Format::Ascii, &LIST_Q).unwrap();
        p.push(b"01    nan   0.00   0.00 1.0000 0.0000 0.0000 0.0000\r\n");
        p.push(b"01   1.00   0.00   0.00 1.0000 0.0000 0.0000\r\n"); // a value short
        assert!(drain(&mut p).is_empty());
    }

    #[test]
    fn ascii_fields_that_touch_still_parse() {
        let mut p = FastrakParser::new(Format::Ascii, &LIST_E).unwrap();
        p.push(b"02 -100.00-120.50  +3.25-179.99 -89.00 180.00\r\n");
        let r = drain(&mut p);
        assert_eq!(r.len(), 1);
        assert_eq!(r[0].station, 2);
        assert_eq!(r[0].position, [-100.0, -120.5, 3.25]);
        assert_eq!(r[0].euler, [-179.99, -89.0, 180.0]);
    }

    #[test]
    fn arbitrary_bytes_never_panic() {
        for format in [Format::Ascii, Format::Binary] {
            let mut x: u32 = 99;
            let mut p = FastrakParser::new(format, &LIST_Q).unwrap();
            let mut r = TrackerRecord::default();
            for _ in 0..3000 {
                let mut chunk = [0u8; 41];
                for b in chunk.iter_mut() {
                    x = x.wrapping_mul(1_103_515_245).wrapping_add(12345);
                    // Bias towards header and digit bytes so candidates get far.
                    *b = match (x >> 16) % 4 {
                        0 => b"01234 .-\r\n"[(x >> 20) as usize % 10],
                        _ => (x >> 16) as u8,
                    };
                }
                p.push(&chunk[..(x as usize % 41) + 1]);
                while p.next(&mut r) {
                    assert!(r.position.iter().all(|v| v.is_finite()));
                }
            }
        }
    }

    #[test]
    fn frame_mapping_takes_forward_to_minus_z_and_down_to_minus_y() {
        let axes = tracker_axes();
        let rec = |pos: [f64; 3], q: DQuat| TrackerRecord {
            station: 1,
            error: b' ',
            position: pos,
            has_position: true,
            quaternion: [q.w, q.x, q.y, q.z],
            has_quaternion: true,
            ..Default::default()
        };
        let id = Pose::IDENTITY;
        let p = record_to_world(
            &rec([100.0, 0.0, 0.0], DQuat::IDENTITY),
            Units::Centimetres,
            axes,
            &id,
            &id,
        )
        .unwrap();
        assert!((DVec3::from_array(p.position) - DVec3::new(0.0, 0.0, -1.0)).length() < 1e-12);
        let p = record_to_world(
            &rec([0.0, 10.0, 10.0], DQuat::IDENTITY),
            Units::Inches,
            axes,
            &id,
            &id,
        )
        .unwrap();
        assert!((DVec3::from_array(p.position) - DVec3::new(0.254, -0.254, 0.0)).length() < 1e-12);
        // Aligned receiver: identity. A yaw (azimuth) about the tracker's down axis becomes a
        // rotation about the world's -y: positive azimuth turns forward (-z) towards right (+x).
        assert!(DQuat::from_array(p.rotation).angle_between(DQuat::IDENTITY) < 1e-12);
        let yaw = DQuat::from_rotation_z(0.5);
        let p = record_to_world(&rec([0.0; 3], yaw), Units::Inches, axes, &id, &id).unwrap();
        let fwd = DQuat::from_array(p.rotation) * DVec3::new(0.0, 0.0, -1.0);
        assert!(fwd.x > 0.4 && fwd.y.abs() < 1e-12, "{fwd}");
        // to_world lifts the transmitter 1 m; the wrist offset moves along the receiver.
        let to_world = Pose {
            position: [0.0, 1.0, 0.0],
            rotation: [0.0, 0.0, 0.0, 1.0],
        };
        let offset = Pose {
            position: [0.0, 0.0, 0.1],
            rotation: [0.0, 0.0, 0.0, 1.0],
        };
        let p = record_to_world(
            &rec([0.0; 3], DQuat::IDENTITY),
            Units::Inches,
            axes,
            &to_world,
            &offset,
        )
        .unwrap();
        assert!((DVec3::from_array(p.position) - DVec3::new(0.0, 1.0, 0.1)).length() < 1e-12);
    }

    #[test]
    fn euler_and_quaternion_agree() {
        let axis_angles = [(10.0, 20.0, 30.0), (-170.0, 45.0, -90.0)];
        for (az, el, roll) in axis_angles {
            let q = DQuat::from_euler(
                glam::EulerRot::ZYX,
                f64::to_radians(az),
                f64::to_radians(el),
                f64::to_radians(roll),
            );
            let a = TrackerRecord {
                euler: [az, el, roll],
                has_euler: true,
                ..Default::default()
            }
            .rotation();
            assert!(a.angle_between(q) < 1e-9);
        }
    }

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
