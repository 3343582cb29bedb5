//! The device settings of a `[source] kind = "devices"` session: its `glove` and `tracker`
//! tables, read and checked when the session loads (docs/design.md, "Sessions"), so a typo in a
//! port or a glove size is reported before any process starts, like every other key.
//!
//! These are settings, not drivers: acquisition::devices opens the ports, speaks the
//! protocols and checks what only a driver can (the calibration file, the device's answers).
//! The structs live here because the session file is this crate's to read, and the launcher,
//! which must not depend on acquisition, checks the whole session before it starts anything.
//!
//! Like the rest of the session reader, every error names the file, the dotted key and what is
//! allowed, and unknown keys are errors, so a typo never silently falls back to a default.

use std::path::{Path, PathBuf};
use std::time::Duration;

use toml::{Table, Value};

use super::catalog::{self, list, num, FileKind, Spec};
use super::ConfigError;
use crate::{monotonic_ns, Pose};

/// Exponential backoff between reconnection attempts: quick for a glitch, patient for a
/// device that is switched off, and never a busy loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Backoff {
    pub first: Duration,
    pub max: Duration,
    next: Duration,
    attempt: u32,
}

impl Backoff {
    pub fn new(first: Duration, max: Duration) -> Backoff {
        Backoff {
            first,
            max,
            next: first,
            attempt: 0,
        }
    }

    /// The delay before the next attempt, and that attempt's number (from 1).
    pub fn next_delay(&mut self) -> (Duration, u32) {
        let d = self.next;
        self.attempt += 1;
        self.next = (self.next * 2).min(self.max);
        (d, self.attempt)
    }

    pub fn reset(&mut self) {
        self.next = self.first;
        self.attempt = 0;
    }
}

impl Default for Backoff {
    fn default() -> Self {
        Backoff::new(Duration::from_millis(100), Duration::from_secs(2))
    }
}

/// How a device sits on its serial line: the same for the glove and the tracker, because
/// the link policy (answer, silence, reconnection) is one for both drivers.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkSettings {
    /// The serial device, e.g. `/dev/ttyUSB0` (or an emulator's pseudo-terminal).
    pub port: PathBuf,
    /// Usually 115200 (the CyberGlove's usual rate; the FASTRAK's switches set it).
    pub baud: u32,
    /// How long to wait for the answer to a command at open.
    pub answer_timeout: Duration,
    /// No valid record for this long means the device stopped answering: report and reconnect.
    pub silence_timeout: Duration,
    /// The longest one `read` call blocks, so the caller can check for shutdown.
    pub read_slice: Duration,
    /// Reconnection backoff.
    pub backoff: Backoff,
}

impl LinkSettings {
    /// The usual settings: 115200 baud, half a second to answer and between records.
    pub fn new(port: impl Into<PathBuf>) -> LinkSettings {
        LinkSettings {
            port: port.into(),
            baud: 115_200,
            answer_timeout: Duration::from_millis(500),
            silence_timeout: Duration::from_millis(500),
            read_slice: Duration::from_millis(50),
            backoff: Backoff::default(),
        }
    }
}

/// How glove samples are requested.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GloveMode {
    /// The glove sends records on its own (`S`): the lowest latency, the usual choice.
    Streamed,
    /// The driver sends `G` at `rate_hz` and waits for each answer: for links that drop
    /// bytes under a continuous stream, or to pace the glove.
    Polled { rate_hz: f64 },
}

/// Where the CyberGlove is and how to read it.
#[derive(Debug, Clone, PartialEq)]
pub struct GloveConfig {
    pub link: LinkSettings,
    /// 18 or 22 when the session insists on a glove size; None accepts what the glove reports
    /// (within what the calibration fits).
    pub sensors: Option<u32>,
    /// A calibration file (acquisition::devices::calibration); None uses a nominal mapping.
    pub calibration: Option<PathBuf>,
    pub mode: GloveMode,
    /// CLOCK_MONOTONIC (ns) that is source time 0; give the glove and the tracker the same.
    pub epoch_ns: u64,
}

impl GloveConfig {
    /// The usual settings: 115200 baud, streamed, size and calibration from the glove.
    pub fn new(port: impl Into<PathBuf>) -> GloveConfig {
        GloveConfig {
            link: LinkSettings::new(port),
            sensors: None,
            calibration: None,
            mode: GloveMode::Streamed,
            epoch_ns: monotonic_ns(),
        }
    }
}

/// FASTRAK record encoding.
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

    /// Its name in a session file.
    pub fn name(self) -> &'static str {
        match self {
            Format::Ascii => "ascii",
            Format::Binary => "binary",
        }
    }

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

    /// Its (short) name in a session file.
    pub fn name(self) -> &'static str {
        match self {
            Units::Centimetres => "cm",
            Units::Inches => "in",
        }
    }

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

/// Which orientation item the tracker driver asks for.
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

    /// Its name in a session file.
    pub fn name(self) -> &'static str {
        match self {
            Orientation::Quaternion => "quaternion",
            Orientation::Euler => "euler",
        }
    }

    pub fn from_name(name: &str) -> Option<Orientation> {
        match name {
            "quaternion" => Some(Orientation::Quaternion),
            "euler" => Some(Orientation::Euler),
            _ => None,
        }
    }
}

/// How tracker records are requested.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TrackerMode {
    /// `C`: the tracker sends at its own rate (120 Hz shared among active stations).
    Continuous,
    /// `P` at `rate_hz`.
    Polled { rate_hz: f64 },
}

/// Where the FASTRAK is, how to read it, and where its frame sits in the world.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackerConfig {
    pub link: LinkSettings,
    pub format: Format,
    pub units: Units,
    pub orientation: Orientation,
    pub mode: TrackerMode,
    /// The receiver on the hand, 1..=4.
    pub station: u8,
    /// The transmitter's pose in the world (project axes, see acquisition::devices::fastrak).
    pub to_world: Pose,
    /// The wrist's pose in the receiver's frame (project axes).
    pub wrist_offset: Pose,
    /// CLOCK_MONOTONIC (ns) that is source time 0; give the glove and the tracker the same.
    pub epoch_ns: u64,
}

impl TrackerConfig {
    /// The usual settings: 115200 baud, binary, centimetres, quaternions, continuous,
    /// station 1, transmitter at the world origin.
    pub fn new(port: impl Into<PathBuf>) -> TrackerConfig {
        TrackerConfig {
            link: LinkSettings::new(port),
            format: Format::Binary,
            units: Units::Centimetres,
            orientation: Orientation::Quaternion,
            mode: TrackerMode::Continuous,
            station: 1,
            to_world: Pose::IDENTITY,
            wrist_offset: Pose::IDENTITY,
            epoch_ns: monotonic_ns(),
        }
    }
}

/// A device table's reader: its own, not [`super::reader::Reader`], because its messages are
/// the drivers' own wording (and tests and users know them).
struct Keys<'a> {
    file: &'a Path,
    prefix: &'a str,
    table: &'a Table,
    known: Vec<&'static str>,
}

impl<'a> Keys<'a> {
    fn new(file: &'a Path, prefix: &'a str, table: &'a Table) -> Keys<'a> {
        Keys {
            file,
            prefix,
            table,
            known: Vec::new(),
        }
    }

    fn path(&self, key: &str) -> String {
        if self.prefix.is_empty() {
            key.to_string()
        } else {
            format!("{}.{key}", self.prefix)
        }
    }

    fn err(&self, key: &str, problem: impl Into<String>) -> ConfigError {
        ConfigError::new(self.file, self.path(key), problem)
    }

    /// Tells the key catalog (when one is being made) what this getter checks of `key`.
    fn note(&self, key: &str, spec: impl FnOnce() -> Spec) {
        catalog::note(FileKind::Devices, || self.path(key), spec);
    }

    fn get(&mut self, key: &'static str) -> Option<&'a Value> {
        self.known.push(key);
        self.table.get(key)
    }

    /// The raw value; `spec` says, for the key catalog, what the caller accepts.
    fn raw(&mut self, key: &'static str, spec: impl FnOnce() -> Spec) -> Option<&'a Value> {
        self.note(key, spec);
        self.get(key)
    }

    fn string(&mut self, key: &'static str) -> Result<Option<&'a str>, ConfigError> {
        self.note(key, || Spec::of("string"));
        self.string_value(key)
    }

    fn string_value(&mut self, key: &'static str) -> Result<Option<&'a str>, ConfigError> {
        match self.get(key) {
            None => Ok(None),
            Some(Value::String(s)) => Ok(Some(s)),
            Some(_) => Err(self.err(key, "must be a string")),
        }
    }

    /// One of `names`, parsed; None when absent, and the caller keeps `default` (its name,
    /// for the key catalog).
    fn choice<T>(
        &mut self,
        key: &'static str,
        names: &[&str],
        default: &str,
        parse: impl Fn(&str) -> Option<T>,
    ) -> Result<Option<T>, ConfigError> {
        let quoted = || -> Vec<String> { names.iter().map(|n| format!("\"{n}\"")).collect() };
        self.note(key, || Spec {
            allowed: quoted().join(", "),
            default: Some(format!("\"{default}\"")),
            ..Spec::of("string")
        });
        let Some(s) = self.string_value(key)? else {
            return Ok(None);
        };
        parse(s).map(Some).ok_or_else(|| {
            self.err(
                key,
                format!("\"{s}\" is not one of {}", quoted().join(", ")),
            )
        })
    }

    /// A number in `lo..=hi` (its getter notes it for the key catalog).
    fn number(&mut self, key: &'static str, lo: f64, hi: f64) -> Result<Option<f64>, ConfigError> {
        let v = match self.get(key) {
            None => return Ok(None),
            Some(Value::Integer(i)) => *i as f64,
            Some(Value::Float(f)) => *f,
            Some(_) => return Err(self.err(key, format!("must be a number in [{lo}, {hi}]"))),
        };
        if !(v.is_finite() && (lo..=hi).contains(&v)) {
            return Err(self.err(key, format!("{v} is out of range: allowed [{lo}, {hi}]")));
        }
        Ok(Some(v))
    }

    /// A whole number in `lo..=hi`; None when absent, and the caller keeps `default` (for the
    /// key catalog).
    fn integer(
        &mut self,
        key: &'static str,
        lo: i64,
        hi: i64,
        default: i64,
    ) -> Result<Option<i64>, ConfigError> {
        self.note(key, || Spec {
            allowed: format!("{lo} to {hi}"),
            default: Some(default.to_string()),
            ..Spec::of("whole number")
        });
        match self.get(key) {
            None => Ok(None),
            Some(Value::Integer(i)) if (lo..=hi).contains(i) => Ok(Some(*i)),
            Some(Value::Integer(i)) => {
                Err(self.err(key, format!("{i} is out of range: allowed {lo}..={hi}")))
            }
            Some(_) => Err(self.err(key, format!("must be a whole number in {lo}..={hi}"))),
        }
    }

    /// Milliseconds, 10 to 60000; None when absent, and the caller keeps `default`.
    fn millis(
        &mut self,
        key: &'static str,
        default: Duration,
    ) -> Result<Option<Duration>, ConfigError> {
        self.note(key, || Spec {
            allowed: "10 to 60000".into(),
            default: Some(num(default.as_secs_f64() * 1000.0)),
            ..Spec::of("number (milliseconds)")
        });
        Ok(self
            .number(key, 10.0, 60_000.0)?
            .map(|ms| Duration::from_secs_f64(ms / 1000.0)))
    }

    fn vector<const N: usize>(key: &str, v: &Value, keys: &Keys) -> Result<[f64; N], ConfigError> {
        let bad = || keys.err(key, format!("must be an array of {N} numbers"));
        let Value::Array(items) = v else {
            return Err(bad());
        };
        if items.len() != N {
            return Err(bad());
        }
        let mut out = [0.0; N];
        for (o, item) in out.iter_mut().zip(items) {
            *o = match item {
                Value::Integer(i) => *i as f64,
                Value::Float(f) if f.is_finite() => *f,
                _ => return Err(bad()),
            };
        }
        Ok(out)
    }

    /// `{ position = [x, y, z], rotation = [x, y, z, w] }`, both optional.
    fn pose(&mut self, key: &'static str) -> Result<Option<Pose>, ConfigError> {
        self.note(key, || Spec::of("table { position, rotation }"));
        self.note(&format!("{key}.position"), || Spec {
            allowed: "each -100 to 100".into(),
            default: Some(list(&Pose::IDENTITY.position)),
            ..Spec::of("list of 3 numbers")
        });
        self.note(&format!("{key}.rotation"), || Spec {
            allowed: "a unit quaternion [x, y, z, w]".into(),
            default: Some(list(&Pose::IDENTITY.rotation)),
            ..Spec::of("list of 4 numbers")
        });
        let Some(v) = self.get(key) else {
            return Ok(None);
        };
        let Value::Table(t) = v else {
            return Err(self.err(
                key,
                "must be a table { position = [x, y, z], rotation = [x, y, z, w] }",
            ));
        };
        let mut pose = Pose::IDENTITY;
        for (k, v) in t {
            match k.as_str() {
                "position" => {
                    pose.position = Self::vector::<3>(&format!("{key}.position"), v, self)?;
                    if pose.position.iter().any(|p| p.abs() > 100.0) {
                        return Err(self.err(
                            &format!("{key}.position"),
                            "out of range: each coordinate within [-100, 100] metres",
                        ));
                    }
                }
                "rotation" => {
                    pose.rotation = Self::vector::<4>(&format!("{key}.rotation"), v, self)?;
                    let n = pose.rotation.iter().map(|q| q * q).sum::<f64>().sqrt();
                    if (n - 1.0).abs() > 1e-3 {
                        return Err(self.err(
                            &format!("{key}.rotation"),
                            format!("must be a unit quaternion [x, y, z, w]; its length is {n}"),
                        ));
                    }
                    pose.rotation = pose.rotation.map(|q| q / n);
                }
                other => {
                    return Err(self.err(
                        &format!("{key}.{other}"),
                        "unknown key; allowed here: position, rotation",
                    ))
                }
            }
        }
        Ok(Some(pose))
    }

    /// `port` (required) and `baud`: where the device is and how fast it talks.
    fn link(&mut self, device: &str, example_port: &str) -> Result<LinkSettings, ConfigError> {
        let port = self.string("port")?.ok_or_else(|| {
            self.err(
                "port",
                format!("required: the {device}'s serial device, e.g. {example_port}"),
            )
        })?;
        let mut link = LinkSettings::new(port);
        if let Some(b) = self.integer("baud", 300, 4_000_000, link.baud.into())? {
            link.baud = b as u32;
        }
        Ok(link)
    }

    /// `answer_ms` and `silence_ms`: how long the device may take to answer, and to send the
    /// next record, before the driver reports it.
    fn timeouts(&mut self, link: &mut LinkSettings) -> Result<(), ConfigError> {
        if let Some(d) = self.millis("answer_ms", link.answer_timeout)? {
            link.answer_timeout = d;
        }
        if let Some(d) = self.millis("silence_ms", link.silence_timeout)? {
            link.silence_timeout = d;
        }
        Ok(())
    }

    /// `mode` (`own_mode`, the device sending on its own, or "polled") and `rate_hz`, which
    /// only polling takes: the poll rate (`default_hz` when not given) when polled, None when
    /// the device sends on its own. `own_rate` says in a message what sets the rate then.
    fn poll_rate(
        &mut self,
        own_mode: &'static str,
        default_hz: f64,
        own_rate: &str,
    ) -> Result<Option<f64>, ConfigError> {
        let polled = self.choice("mode", &[own_mode, "polled"], own_mode, |s| match s {
            "polled" => Some(true),
            s if s == own_mode => Some(false),
            _ => None,
        })?;
        self.note("rate_hz", || Spec {
            allowed: "1 to 1000, only with mode = \"polled\"".into(),
            default: Some(num(default_hz)),
            ..Spec::of("number")
        });
        let rate = self.number("rate_hz", 1.0, 1000.0)?;
        match (polled, rate) {
            (Some(true), r) => Ok(Some(r.unwrap_or(default_hz))),
            (_, Some(_)) => Err(self.err(
                "rate_hz",
                format!("only for mode = \"polled\" ({own_rate} sets its own rate)"),
            )),
            _ => Ok(None),
        }
    }

    fn finish(self) -> Result<(), ConfigError> {
        for key in self.table.keys() {
            if !self.known.iter().any(|k| k == key) {
                let mut allowed = self.known.clone();
                allowed.sort();
                return Err(self.err(
                    key,
                    format!("unknown key; allowed here: {}", allowed.join(", ")),
                ));
            }
        }
        Ok(())
    }
}

/// The glove table (`prefix` is its dotted key, e.g. `source.glove`, for messages). A
/// relative `calibration` path is resolved against `dir` (the session file's folder).
///
/// Its keys, their defaults and ranges: docs/config.md ("Device tables of a session").
pub fn glove_config(
    file: &Path,
    prefix: &str,
    table: &Table,
    dir: &Path,
    epoch_ns: u64,
) -> Result<GloveConfig, ConfigError> {
    let mut k = Keys::new(file, prefix, table);
    let mut cfg = GloveConfig {
        link: k.link("glove", "/dev/ttyUSB0")?,
        epoch_ns,
        ..GloveConfig::new("")
    };
    match k.raw("sensors", || Spec {
        allowed: "18 or 22".into(),
        ..Spec::of("whole number")
    }) {
        None => {}
        Some(Value::Integer(n)) if *n == 18 || *n == 22 => cfg.sensors = Some(*n as u32),
        Some(v) => return Err(k.err("sensors", format!("{v}: a CyberGlove has 18 or 22 sensors"))),
    }
    if let Some(c) = k.string("calibration")? {
        cfg.calibration = Some(dir.join(c));
    }
    if let Some(rate_hz) = k.poll_rate("streamed", 100.0, "a stream")? {
        cfg.mode = GloveMode::Polled { rate_hz };
    }
    k.timeouts(&mut cfg.link)?;
    k.finish()?;
    Ok(cfg)
}

/// The tracker table (`prefix` e.g. `source.tracker`).
///
/// Its keys, their defaults and ranges: docs/config.md ("Device tables of a session").
pub fn tracker_config(
    file: &Path,
    prefix: &str,
    table: &Table,
    epoch_ns: u64,
) -> Result<TrackerConfig, ConfigError> {
    let mut k = Keys::new(file, prefix, table);
    let mut cfg = TrackerConfig {
        link: k.link("tracker", "/dev/ttyUSB1")?,
        epoch_ns,
        ..TrackerConfig::new("")
    };
    if let Some(f) = k.choice(
        "format",
        &Format::NAMES,
        cfg.format.name(),
        Format::from_name,
    )? {
        cfg.format = f;
    }
    if let Some(u) = k.choice("units", &Units::NAMES, cfg.units.name(), Units::from_name)? {
        cfg.units = u;
    }
    if let Some(o) = k.choice(
        "orientation",
        &Orientation::NAMES,
        cfg.orientation.name(),
        Orientation::from_name,
    )? {
        cfg.orientation = o;
    }
    if let Some(rate_hz) = k.poll_rate("continuous", 60.0, "continuous output")? {
        cfg.mode = TrackerMode::Polled { rate_hz };
    }
    if let Some(s) = k.integer("station", 1, 4, cfg.station.into())? {
        cfg.station = s as u8;
    }
    if let Some(p) = k.pose("to_world")? {
        cfg.to_world = p;
    }
    if let Some(p) = k.pose("wrist_offset")? {
        cfg.wrist_offset = p;
    }
    k.timeouts(&mut cfg.link)?;
    k.finish()?;
    Ok(cfg)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(text: &str) -> Table {
        text.parse().unwrap()
    }

    #[test]
    fn the_example_session_reads() {
        let file =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/devices/emulated-session.toml");
        let all = table(&std::fs::read_to_string(&file).unwrap());
        let Some(Value::Table(source)) = all.get("source") else {
            panic!("no [source]")
        };
        let Some(Value::Table(g)) = source.get("glove") else {
            panic!("no glove")
        };
        let Some(Value::Table(t)) = source.get("tracker") else {
            panic!("no tracker")
        };
        let dir = file.parent().unwrap();
        let gc = glove_config(&file, "source.glove", g, dir, 7).unwrap();
        assert_eq!(gc.sensors, Some(22));
        assert_eq!(gc.epoch_ns, 7);
        assert!(gc.calibration.as_ref().unwrap().ends_with("glove-22.cal"));
        let tc = tracker_config(&file, "source.tracker", t, 7).unwrap();
        assert_eq!(tc.format, Format::Binary);
        assert_eq!(tc.units, Units::Centimetres);
        assert_eq!(tc.to_world.position, [0.0, 0.30, 0.4]);
    }

    #[test]
    fn errors_name_file_key_and_range() {
        let f = Path::new("s.toml");
        let e = glove_config(f, "source.glove", &table("baud = 1"), f, 0).unwrap_err();
        assert_eq!(e.key, "source.glove.port");
        let e = glove_config(
            f,
            "source.glove",
            &table("port = \"x\"\nsensors = 20"),
            f,
            0,
        )
        .unwrap_err();
        assert_eq!(e.key, "source.glove.sensors");
        assert!(e.problem.contains("18 or 22"));
        let e = glove_config(
            f,
            "source.glove",
            &table("port = \"x\"\nrate_hz = 50"),
            f,
            0,
        )
        .unwrap_err();
        assert!(e.problem.contains("polled"));
        let e = glove_config(
            f,
            "source.glove",
            &table("port = \"x\"\nbaudrate = 9600"),
            f,
            0,
        )
        .unwrap_err();
        assert_eq!(e.key, "source.glove.baudrate");
        assert!(e.problem.contains("unknown key"));
        let e = tracker_config(
            f,
            "source.tracker",
            &table("port = \"x\"\nunits = \"mm\""),
            0,
        )
        .unwrap_err();
        assert!(
            e.to_string()
                .starts_with("s.toml: `source.tracker.units`: \"mm\""),
            "{e}"
        );
        let e = tracker_config(f, "source.tracker", &table("port = \"x\"\nstation = 5"), 0)
            .unwrap_err();
        assert!(e.problem.contains("1..=4"));
        let e = tracker_config(
            f,
            "source.tracker",
            &table("port = \"x\"\nto_world = { rotation = [0, 0, 0, 2] }"),
            0,
        )
        .unwrap_err();
        assert_eq!(e.key, "source.tracker.to_world.rotation");
        let c = tracker_config(
            f,
            "source.tracker",
            &table(
                "port = \"x\"\nmode = \"polled\"\nrate_hz = 30\nformat = \"ascii\"\nunits = \"in\"",
            ),
            0,
        )
        .unwrap();
        assert_eq!(c.mode, TrackerMode::Polled { rate_hz: 30.0 });
        assert_eq!((c.format, c.units), (Format::Ascii, Units::Inches));
    }
}
