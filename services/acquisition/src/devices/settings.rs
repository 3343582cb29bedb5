//! Session-file settings to driver configurations: the `glove` and `tracker` tables of a
//! `[source] kind = "devices"` session (see `config/devices/emulated-session.toml`).
//!
//! Like the rest of the session reader, every error names the file, the dotted key and what is
//! allowed, and unknown keys are errors, so a typo never silently falls back to a default.

use std::path::Path;
use std::time::Duration;

use common::config::ConfigError;
use common::Pose;
use toml::{Table, Value};

use super::{Format, GloveConfig, GloveMode, Orientation, TrackerConfig, TrackerMode, Units};

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

    fn err(&self, key: &str, problem: impl Into<String>) -> ConfigError {
        let path = if self.prefix.is_empty() {
            key.to_string()
        } else {
            format!("{}.{key}", self.prefix)
        };
        ConfigError::new(self.file, path, problem)
    }

    fn get(&mut self, key: &'static str) -> Option<&'a Value> {
        self.known.push(key);
        self.table.get(key)
    }

    fn string(&mut self, key: &'static str) -> Result<Option<&'a str>, ConfigError> {
        match self.get(key) {
            None => Ok(None),
            Some(Value::String(s)) => Ok(Some(s)),
            Some(_) => Err(self.err(key, "must be a string")),
        }
    }

    fn choice<T>(
        &mut self,
        key: &'static str,
        names: &[&str],
        parse: impl Fn(&str) -> Option<T>,
    ) -> Result<Option<T>, ConfigError> {
        let Some(s) = self.string(key)? else {
            return Ok(None);
        };
        parse(s).map(Some).ok_or_else(|| {
            let quoted: Vec<String> = names.iter().map(|n| format!("\"{n}\"")).collect();
            self.err(key, format!("\"{s}\" is not one of {}", quoted.join(", ")))
        })
    }

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

    fn integer(&mut self, key: &'static str, lo: i64, hi: i64) -> Result<Option<i64>, ConfigError> {
        match self.get(key) {
            None => Ok(None),
            Some(Value::Integer(i)) if (lo..=hi).contains(i) => Ok(Some(*i)),
            Some(Value::Integer(i)) => {
                Err(self.err(key, format!("{i} is out of range: allowed {lo}..={hi}")))
            }
            Some(_) => Err(self.err(key, format!("must be a whole number in {lo}..={hi}"))),
        }
    }

    fn millis(&mut self, key: &'static str) -> Result<Option<Duration>, ConfigError> {
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
/// Keys: `port` (required), `baud`, `sensors` (18 | 22), `calibration`, `mode`
/// ("streamed" | "polled"), `rate_hz` (polled), `answer_ms`, `silence_ms`.
pub fn glove_config(
    file: &Path,
    prefix: &str,
    table: &Table,
    dir: &Path,
    epoch_ns: u64,
) -> Result<GloveConfig, ConfigError> {
    let mut k = Keys::new(file, prefix, table);
    let port = k.string("port")?.ok_or_else(|| {
        k.err(
            "port",
            "required: the glove's serial device, e.g. /dev/ttyUSB0",
        )
    })?;
    let mut cfg = GloveConfig::new(port);
    cfg.epoch_ns = epoch_ns;
    if let Some(b) = k.integer("baud", 300, 4_000_000)? {
        cfg.baud = b as u32;
    }
    match k.get("sensors") {
        None => {}
        Some(Value::Integer(n)) if *n == 18 || *n == 22 => cfg.sensors = Some(*n as u32),
        Some(v) => return Err(k.err("sensors", format!("{v}: a CyberGlove has 18 or 22 sensors"))),
    }
    if let Some(c) = k.string("calibration")? {
        cfg.calibration = Some(dir.join(c));
    }
    let polled = k.choice("mode", &["streamed", "polled"], |s| match s {
        "streamed" => Some(false),
        "polled" => Some(true),
        _ => None,
    })?;
    let rate = k.number("rate_hz", 1.0, 1000.0)?;
    match (polled, rate) {
        (Some(true), r) => {
            cfg.mode = GloveMode::Polled {
                rate_hz: r.unwrap_or(100.0),
            }
        }
        (_, Some(_)) => {
            return Err(k.err(
                "rate_hz",
                "only for mode = \"polled\" (a stream sets its own rate)",
            ))
        }
        _ => {}
    }
    if let Some(d) = k.millis("answer_ms")? {
        cfg.answer_timeout = d;
    }
    if let Some(d) = k.millis("silence_ms")? {
        cfg.silence_timeout = d;
    }
    k.finish()?;
    Ok(cfg)
}

/// The tracker table (`prefix` e.g. `source.tracker`).
///
/// Keys: `port` (required), `baud`, `format` ("binary" | "ascii"), `units` ("cm" | "in"),
/// `orientation` ("quaternion" | "euler"), `mode` ("continuous" | "polled"), `rate_hz`
/// (polled), `station` (1..=4), `to_world` and `wrist_offset` (`{ position, rotation }`),
/// `answer_ms`, `silence_ms`.
pub fn tracker_config(
    file: &Path,
    prefix: &str,
    table: &Table,
    epoch_ns: u64,
) -> Result<TrackerConfig, ConfigError> {
    let mut k = Keys::new(file, prefix, table);
    let port = k.string("port")?.ok_or_else(|| {
        k.err(
            "port",
            "required: the tracker's serial device, e.g. /dev/ttyUSB1",
        )
    })?;
    let mut cfg = TrackerConfig::new(port);
    cfg.epoch_ns = epoch_ns;
    if let Some(b) = k.integer("baud", 300, 4_000_000)? {
        cfg.baud = b as u32;
    }
    if let Some(f) = k.choice("format", &Format::NAMES, Format::from_name)? {
        cfg.format = f;
    }
    if let Some(u) = k.choice("units", &Units::NAMES, Units::from_name)? {
        cfg.units = u;
    }
    if let Some(o) = k.choice("orientation", &Orientation::NAMES, Orientation::from_name)? {
        cfg.orientation = o;
    }
    let polled = k.choice("mode", &["continuous", "polled"], |s| match s {
        "continuous" => Some(false),
        "polled" => Some(true),
        _ => None,
    })?;
    let rate = k.number("rate_hz", 1.0, 1000.0)?;
    match (polled, rate) {
        (Some(true), r) => {
            cfg.mode = TrackerMode::Polled {
                rate_hz: r.unwrap_or(60.0),
            }
        }
        (_, Some(_)) => {
            return Err(k.err(
                "rate_hz",
                "only for mode = \"polled\" (continuous output sets its own rate)",
            ))
        }
        _ => {}
    }
    if let Some(s) = k.integer("station", 1, 4)? {
        cfg.station = s as u8;
    }
    if let Some(p) = k.pose("to_world")? {
        cfg.to_world = p;
    }
    if let Some(p) = k.pose("wrist_offset")? {
        cfg.wrist_offset = p;
    }
    if let Some(d) = k.millis("answer_ms")? {
        cfg.answer_timeout = d;
    }
    if let Some(d) = k.millis("silence_ms")? {
        cfg.silence_timeout = d;
    }
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
        let file = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../config/devices/emulated-session.toml");
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
        assert!(crate::devices::Glove::new(gc).is_ok());
        let tc = tracker_config(&file, "source.tracker", t, 7).unwrap();
        assert_eq!(tc.format, Format::Binary);
        assert_eq!(tc.units, Units::Centimetres);
        assert_eq!(tc.to_world.position, [0.0, 0.45, 0.4]);
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
