//! Fuzz targets: one function per parser of outside bytes, each feeding the bytes to the real
//! parser, discarding the result and checking what the parser promises of a successful parse
//! (finite numbers, counts in range, errors that name the file and where in it).
//!
//! The same functions run in two harnesses:
//! * `fuzz/` (cargo-fuzz's layout, libFuzzer, a nightly toolchain or `RUSTC_BOOTSTRAP=1`) for
//!   long, coverage-guided runs: `cargo fuzz run <target>`;
//! * `tests/stable_fuzz.rs` on stable in `cargo test`: every seed of `fuzz/corpus/<target>/`,
//!   then deterministic mutations of each ([`mutate`]) and generated inputs, each under
//!   `catch_unwind` and a hang watchdog.
//!
//! A target panics only when the parser broke a promise (or panicked itself): that is a
//! finding. A refused input is not.
//!
//! | target        | parser                                                            |
//! |---------------|-------------------------------------------------------------------|
//! | `cyberglove`  | `acquisition::devices::GloveParser` (push / next)                  |
//! | `fastrak`     | `acquisition::devices::FastrakParser` (push / next), record_to_world |
//! | `carl`        | `replay::CarlTrace::parse`, then `joints`                          |
//! | `mcap`        | `recording::Recording::parse`, its samples, and replay's reading of it |
//! | `scene`       | `common::config::Scene::load`                                      |
//! | `session`     | `common::config::Session::load` (a valid scene beside it)          |
//! | `hand`        | `common::config::hand::HandModelSpec::load`                        |
//! | `calibration` | `acquisition::devices::Calibration::parse`                         |
//! | `link`        | `recording::decode_sample` / `decode_slice`: a sample from another machine (the bridge), then the scene view a viewer draws it in |
//! | `stepper_hand`| `stepper::Model::step` under both models, fed hand samples with arbitrary values |
//! | `webxr`       | `webxr_wire::decode_into`: a headset page's hands frame, then `to_joints` |

use std::cell::OnceCell;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use acquisition::devices::cyberglove::GloveEvent;
use acquisition::devices::fastrak::{record_to_world, tracker_axes, TrackerRecord};
use acquisition::devices::{Calibration, FastrakParser, Format, GloveParser, Units};
use common::config::hand::HandModelSpec;
use common::config::{Scene, Session};
use common::{
    FrameSample, GloveSample, HandSample, JointsSample, Pose, Topic, TrackerSample,
    MAX_GLOVE_SENSORS, MAX_SCENE_BLOCKS,
};
use recording::Recording;
use replay::trace::SourceSample;
use replay::{CarlTrace, HandTrace};

/// A target: its name and its function.
pub type Target = (&'static str, fn(&[u8]));

/// Every target by name, in the order the harnesses run them.
pub const TARGETS: [Target; 11] = [
    ("cyberglove", cyberglove),
    ("fastrak", fastrak),
    ("carl", carl),
    ("mcap", mcap),
    ("scene", scene),
    ("session", session),
    ("hand", hand),
    ("calibration", calibration),
    ("link", link),
    ("stepper_hand", stepper_hand),
    ("webxr", webxr),
];

/// The target called `name`.
pub fn target(name: &str) -> Option<fn(&[u8])> {
    TARGETS.iter().find(|(n, _)| *n == name).map(|(_, f)| *f)
}

/// Feeds `stream` to a parser `chunk` bytes at a time (0: as much as fits), draining after
/// each push; `push` returns how many bytes it took, `drain` takes every event out.
fn feed(
    stream: &[u8],
    chunk: usize,
    mut push: impl FnMut(&[u8]) -> usize,
    mut drain: impl FnMut(),
) {
    let mut rest = stream;
    while !rest.is_empty() {
        let take = if chunk == 0 {
            rest.len()
        } else {
            chunk.min(rest.len())
        };
        let took = push(&rest[..take]);
        // A parser whose window takes nothing would stall its driver for good.
        assert!(
            took > 0,
            "the parser took none of {take} bytes: it would stall"
        );
        rest = &rest[took..];
        drain();
    }
    drain();
}

/// `cyberglove`: byte 0 picks the sensor count (18 or 22 mostly, else 0..=31, which the parser
/// clamps), byte 1 the chunk size the bytes arrive in; the rest is the serial stream.
pub fn cyberglove(data: &[u8]) {
    let [config, chunking, stream @ ..] = data else {
        return;
    };
    let sensors = if config & 0x80 == 0 {
        [18, 22][usize::from(config & 1)]
    } else {
        usize::from(config & 0x1f)
    };
    let mut p = GloveParser::new(sensors);
    let n = p.sensors();
    assert!((1..=MAX_GLOVE_SENSORS).contains(&n), "sensor count {n}");
    let mut raw = [0u8; MAX_GLOVE_SENSORS];
    let mut pushed = 0u64;
    let mut records = 0u64;
    let parser = std::cell::RefCell::new(&mut p);
    feed(
        stream,
        usize::from(*chunking % 64),
        |b| {
            let took = parser.borrow_mut().push(b);
            pushed += took as u64;
            took
        },
        || {
            let mut p = parser.borrow_mut();
            while let Some(ev) = p.next(&mut raw) {
                match ev {
                    GloveEvent::Record { header } => {
                        assert!(matches!(header, b'G' | b'S'), "record header {header:#04x}");
                        assert!(
                            raw[..n].iter().all(|b| *b != 0),
                            "a record with a 0 sensor byte: {:?}",
                            &raw[..n]
                        );
                        records += 1;
                    }
                    GloveEvent::SensorCount(c) => assert_ne!(c, 0, "sensor count 0"),
                    GloveEvent::DeviceError(c) => {
                        assert!(c.is_ascii_lowercase(), "error code {c:#04x}")
                    }
                }
            }
        },
    );
    let stats = p.stats;
    assert!(
        stats.garbage_bytes + records * (n as u64 + 2) <= pushed,
        "{} garbage bytes and {records} records of {} bytes from {pushed} bytes",
        stats.garbage_bytes,
        n + 2
    );
}

/// The output lists the driver asks for, and a few more the parser takes.
const FASTRAK_LISTS: [&[u8]; 8] = [
    &[2, 11, 1],
    &[2, 4, 1],
    &[2, 1],
    &[11, 1],
    &[4, 1],
    &[0, 2, 0, 11, 1],
    &[2, 4, 11, 1],
    &[2, 11],
];

/// `fastrak`: byte 0 bit 0 picks the format (binary, ASCII), bit 1 whether byte 1 picks one
/// of [`FASTRAK_LISTS`] or says how many of the following bytes are the item list (so bad
/// lists reach `FastrakParser::new`), bits 2.. the chunk size; the rest is the stream.
pub fn fastrak(data: &[u8]) {
    let [config, list, rest @ ..] = data else {
        return;
    };
    let format = if config & 1 == 0 {
        Format::Binary
    } else {
        Format::Ascii
    };
    let (items, stream): (&[u8], &[u8]) = if config & 2 == 0 {
        (
            FASTRAK_LISTS[usize::from(*list) % FASTRAK_LISTS.len()],
            rest,
        )
    } else {
        let k = (usize::from(*list) % 10).min(rest.len());
        rest.split_at(k)
    };
    let Ok(mut p) = FastrakParser::new(format, items) else {
        return;
    };
    let axes = tracker_axes();
    let mut rec = TrackerRecord::default();
    let mut pushed = 0u64;
    let parser = std::cell::RefCell::new(&mut p);
    feed(
        stream,
        usize::from(config >> 2),
        |b| {
            let took = parser.borrow_mut().push(b);
            pushed += took as u64;
            took
        },
        || {
            let mut p = parser.borrow_mut();
            while p.next(&mut rec) {
                check_tracker_record(&rec);
                for units in [Units::Centimetres, Units::Inches] {
                    if let Some(pose) =
                        record_to_world(&rec, units, axes, &Pose::IDENTITY, &Pose::IDENTITY)
                    {
                        assert!(pose.is_finite(), "record_to_world gave {pose:?}");
                    }
                }
            }
        },
    );
    assert!(p.stats.garbage_bytes <= pushed);
}

/// What the FASTRAK parser promises of a record it accepts.
fn check_tracker_record(r: &TrackerRecord) {
    assert!((1..=4).contains(&r.station), "station {}", r.station);
    assert!(
        r.has_position || r.has_euler || r.has_quaternion,
        "a record with no item"
    );
    let all = r.position.iter().chain(&r.euler).chain(&r.quaternion);
    assert!(all.clone().all(|v| v.is_finite()), "not finite: {r:?}");
    assert!(r.position.iter().all(|v| v.abs() <= 1000.0), "{r:?}");
    if r.has_quaternion {
        let n2: f64 = r.quaternion.iter().map(|q| q * q).sum();
        assert!((0.96..=1.04).contains(&n2), "quaternion norm^2 {n2}");
    }
    let q = r.rotation();
    assert!(q.is_finite(), "rotation {q:?} of {r:?}");
}

/// `carl`: the bytes as a CARL file; a trace read must have finite, ordered times and its
/// `joints` never a NaN; an error names the file and an offset inside it.
pub fn carl(data: &[u8]) {
    let file = Path::new("fuzz.carl");
    let check_error = |e: &replay::CarlError| {
        assert!(
            e.offset <= data.len(),
            "offset {} past {} bytes",
            e.offset,
            data.len()
        );
        let msg = e.to_string();
        assert!(msg.starts_with("fuzz.carl: at byte "), "{msg}");
    };
    let t = match CarlTrace::parse(file, data) {
        Ok(t) => t,
        Err(e) => {
            check_error(&e);
            return;
        }
    };
    if let Some(d) = &t.damage {
        check_error(d);
    }
    assert!(!t.samples.is_empty(), "a trace with no samples");
    for w in t.samples.windows(2) {
        assert!(
            w[0].time <= w[1].time,
            "time goes back: {} {}",
            w[0].time,
            w[1].time
        );
    }
    assert!(t.samples.iter().all(|s| s.time.is_finite()));
    let mut joints = Vec::new();
    t.joints([0.0, -0.9, 0.0], &mut joints);
    assert_eq!(joints.len(), t.samples.len());
    let mut prev = 0;
    for j in &joints {
        assert!(
            j.wrist.is_finite() && j.joints.iter().all(|p| p.is_finite()),
            "a NaN pose left the reader"
        );
        assert!(j.stamp.source_time_ns >= prev, "source time goes back");
        prev = j.stamp.source_time_ns;
    }
    let _ = t.duration();
}

/// `mcap`: the bytes as one of our recordings; then every view of it a tool takes (samples of
/// each topic, worlds, statistics, the summary) and replay's reading of its source topics,
/// which must never let a NaN or an impossible sensor count through.
pub fn mcap(data: &[u8]) {
    let file = Path::new("fuzz.mcap");
    let rec = match Recording::parse(file, data) {
        Ok(r) => r,
        Err(e) => {
            assert!(e.to_string().starts_with("fuzz.mcap: "), "{e}");
            return;
        }
    };
    if let Some(d) = &rec.damage {
        assert!(d.to_string().starts_with("fuzz.mcap: "), "{d}");
    }
    for w in rec.worlds() {
        assert!(w.blocks.len() <= MAX_SCENE_BLOCKS);
        assert!(w.blocks().len() <= w.blocks.len());
    }
    let _ = rec.samples::<GloveSample>(Topic::Glove).count();
    let _ = rec.samples::<TrackerSample>(Topic::Tracker).count();
    let _ = rec.samples::<JointsSample>(Topic::Joints).count();
    let _ = rec.samples::<HandSample>(Topic::Hand).count();
    let _ = rec.samples::<FrameSample>(Topic::Frame).count();
    let stats = rec.stats();
    let summary = rec.summary();
    assert_eq!(
        summary.messages,
        stats.iter().map(|s| s.messages).sum::<u64>()
    );
    for t in &summary.topics {
        assert!(t.seconds >= 0.0 && t.rate_hz >= 0.0, "{t:?}");
    }
    let trace = HandTrace::from_recording(&rec, [0.0, -0.9, 0.0]);
    for s in &trace.samples {
        match s {
            SourceSample::Glove(g) => {
                assert!(g.sensor_count as usize <= MAX_GLOVE_SENSORS, "{g:?}");
                assert!(g.angles.iter().all(|a| a.is_finite()), "{g:?}");
            }
            SourceSample::Tracker(t) => assert!(t.wrist.is_finite(), "{t:?}"),
            SourceSample::Joints(j) => assert!(
                j.wrist.is_finite() && j.joints.iter().all(|p| p.is_finite()),
                "{j:?}"
            ),
            // Played as recorded (the stepper refuses a bad one); its counts fit its arrays.
            SourceSample::Hand(h) => assert!(h.check_counts().is_ok(), "{h:?}"),
        }
    }
    for w in &trace.warnings {
        assert!(w.starts_with("fuzz.mcap: "), "{w}");
    }
}

static NEXT_DIR: AtomicU64 = AtomicU64::new(0);

thread_local! {
    static SCRATCH: OnceCell<PathBuf> = const { OnceCell::new() };
}

/// This thread's scratch folder (made on first use): file targets write their input there.
pub fn scratch_dir() -> PathBuf {
    SCRATCH.with(|d| {
        d.get_or_init(|| {
            let dir = std::env::temp_dir().join(format!(
                "hb-fuzz-{}-{}",
                std::process::id(),
                NEXT_DIR.fetch_add(1, Ordering::Relaxed)
            ));
            std::fs::create_dir_all(&dir)
                .unwrap_or_else(|e| panic!("fuzz harness: cannot make {}: {e}", dir.display()));
            dir
        })
        .clone()
    })
}

/// Removes this thread's scratch folder, if it made one.
pub fn remove_scratch_dir() {
    SCRATCH.with(|d| {
        if let Some(dir) = d.get() {
            let _ = std::fs::remove_dir_all(dir);
        }
    });
}

/// Writes `data` as `name` in this thread's scratch folder.
fn scratch_file(name: &str, data: &[u8]) -> PathBuf {
    let file = scratch_dir().join(name);
    std::fs::write(&file, data)
        .unwrap_or_else(|e| panic!("fuzz harness: cannot write {}: {e}", file.display()));
    file
}

/// A config error must name a file and say something.
fn check_config_error(e: &common::config::ConfigError) {
    assert!(
        !e.file.as_os_str().is_empty(),
        "an error naming no file: {e:?}"
    );
    assert!(!e.problem.is_empty(), "an error with no problem: {e:?}");
}

/// What the scene reader promises of a scene it accepts.
fn check_scene(s: &Scene) {
    use common::config::scene::{HandPoseSpec, ShapeSpec};
    let w = &s.world;
    assert!(w.step_hz.is_finite() && w.step_hz >= 1.0, "{w:?}");
    assert!(
        w.gravity.is_finite() && w.release_angle <= w.grasp_angle,
        "{w:?}"
    );
    assert!(
        s.blocks.len() <= MAX_SCENE_BLOCKS,
        "{} blocks",
        s.blocks.len()
    );
    for b in &s.blocks {
        assert!(b.position.iter().all(|v| v.is_finite()), "{b:?}");
        assert!(b.velocity.iter().all(|v| v.is_finite()), "{b:?}");
        let n2: f64 = b.rotation.iter().map(|q| q * q).sum();
        assert!((n2 - 1.0).abs() < 1e-9, "rotation {:?}", b.rotation);
        match &b.shape {
            ShapeSpec::Box { size } | ShapeSpec::Wedge { size } | ShapeSpec::Tetra { size } => {
                assert!(size.iter().all(|v| v.is_finite() && *v > 0.0), "{b:?}")
            }
            ShapeSpec::Hull { vertices } => {
                assert!((4..=256).contains(&vertices.len()));
                assert!(vertices.iter().flatten().all(|v| v.is_finite()));
            }
        }
    }
    if let Some(h) = &s.hand {
        assert!(!h.keys.is_empty());
        for w in h.keys.windows(2) {
            assert!(w[0].t < w[1].t, "keys out of order");
        }
        for k in &h.keys {
            assert!(k.t.is_finite() && k.wrist.iter().all(|v| v.is_finite()));
            match &k.pose {
                HandPoseSpec::Grip(g) => assert!((0.0..=1.0).contains(g)),
                HandPoseSpec::Angles(a) => {
                    assert!(a.len() == 18 || a.len() == 22);
                    assert!(a.iter().all(|v| v.is_finite()));
                }
                HandPoseSpec::Fingers(f) => {
                    assert!(f.iter().flatten().flatten().all(|v| v.is_finite()))
                }
            }
        }
    }
}

/// `scene`: the bytes as a scene file.
pub fn scene(data: &[u8]) {
    let file = scratch_file("scene.toml", data);
    match Scene::load(&file) {
        Ok(s) => check_scene(&s),
        Err(e) => check_config_error(&e),
    }
}

/// The scene a fuzzed session finds beside it as `s.toml`.
pub const SESSION_SCENE: &str = "[[block]]\nname = \"red\"\nposition = [0.0, 0.05, 0.0]\n\
                                 [hand]\n[[hand.key]]\nt = 0\nwrist = [0.3, 0.3, 0]\n";
/// The hand model a fuzzed session finds beside it as `hand.toml`.
pub const SESSION_HAND: &str = include_str!("../../../config/hand.toml");

/// `session`: the bytes as a session file, with a valid scene (`s.toml`) and hand model
/// (`hand.toml`) beside it for the session to name.
pub fn session(data: &[u8]) {
    let dir = scratch_dir();
    if !dir.join("s.toml").exists() {
        scratch_file("s.toml", SESSION_SCENE.as_bytes());
        scratch_file("hand.toml", SESSION_HAND.as_bytes());
    }
    let file = scratch_file("session.toml", data);
    match Session::load(&file) {
        Ok(s) => {
            check_scene(&s.scene);
            let b = &s.budget;
            assert!(
                b.frame_hz.is_finite() && b.source_silence_ms.is_finite(),
                "{b:?}"
            );
            let r = &s.renderer;
            assert!(
                r.width >= 16 && r.height >= 16 && r.eye != r.target,
                "{r:?}"
            );
        }
        Err(e) => check_config_error(&e),
    }
}

/// `hand`: the bytes as a hand model file.
pub fn hand(data: &[u8]) {
    let file = scratch_file("hand.toml", data);
    match HandModelSpec::load(&file) {
        Ok(m) => {
            let mut all: Vec<f64> = vec![m.thumb_radius, m.palm_half_width, m.palm_half_thickness];
            all.extend(m.thumb_base.iter().chain(&m.thumb_bones));
            for f in &m.fingers {
                all.extend(f.knuckle.iter().chain(&f.bones));
                all.push(f.radius);
            }
            assert!(all.iter().all(|v| v.is_finite()), "{m:?}");
            assert!(m.thumb_bones.iter().all(|b| *b > 0.0));
        }
        Err(e) => check_config_error(&e),
    }
}

/// `calibration`: the bytes as a calibration file (lossy UTF-8, as a reader of the text would
/// see them); a calibration read must map every raw byte to a finite angle.
pub fn calibration(data: &[u8]) {
    let text = String::from_utf8_lossy(data);
    match Calibration::parse(Path::new("fuzz.cal"), &text) {
        Ok(c) => {
            let n = c.sensor_count() as usize;
            assert!(n == 18 || n == 22, "{n} sensors");
            let mut out = [0.0; MAX_GLOVE_SENSORS];
            for raw in [1u8, 2, 127, 128, 254, 255] {
                c.apply(&[raw; MAX_GLOVE_SENSORS][..n], &mut out);
                assert!(out.iter().all(|v| v.is_finite()), "raw {raw}: {out:?}");
                for (i, a) in out.iter().enumerate().take(n) {
                    assert!(c.raw_for(i, *a) >= 1);
                }
            }
        }
        Err(e) => {
            let msg = e.to_string();
            assert!(msg.starts_with("fuzz.cal: "), "{msg}");
            assert!(e.line <= text.lines().count(), "line {} of {msg}", e.line);
        }
    }
}

/// A deterministic xorshift64* generator (the stable harness must regenerate any input from
/// its seed).
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        // Never 0 (xorshift's fixed point); mix the seed so neighbouring seeds differ.
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0xD1B5_4A32_D192_ED03 | 1)
    }

    pub fn next_u64(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.0 = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// Uniform-ish in 0..n (n > 0).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n.max(1) as u64) as usize
    }
}

/// Bytes that make parsers take their rarer paths.
const BYTES: [u8; 4] = [0x00, 0xff, 0x7f, 0x80];
const WORDS: [u32; 6] = [
    u32::MAX,
    0x8000_0000,
    0x7fff_ffff,
    1_000_000_000_000u64 as u32,
    0x7fc0_0000, // f32 NaN
    0x7f80_0000, // f32 +inf
];
const QUADS: [u64; 9] = [
    u64::MAX,
    0x8000_0000_0000_0000,
    i64::MAX as u64,
    1_000_000_000_000,
    0x7ff8_0000_0000_0000, // f64 NaN
    0x7ff0_0000_0000_0000, // f64 +inf
    0xfff0_0000_0000_0000, // f64 -inf
    0x7e37_e43c_8800_759c, // 1e300
    0,
];
/// Text that makes the TOML and text readers take their rarer paths.
const TOKENS: [&[u8]; 16] = [
    b"nan",
    b"inf",
    b"-0",
    b"1e309",
    b"18446744073709551615",
    b"9223372036854775807",
    b"\n",
    b" = ",
    b"\"",
    b"[",
    b"]",
    b"[[block]]\n",
    b"{",
    b",",
    b"#",
    b"\r\n",
];

/// One deterministic mutation of `input` into `out` (cleared first): 1 to 8 stacked edits
/// chosen by `seed`, among bit flips, bytes set to 0x00/0xff/0x7f/0x80, 4- and 8-byte
/// overwrites with extreme integers and float bit patterns (NaN, inf, 1e300), truncation,
/// duplication of a slice, insertion of random bytes, and insertion of tokens for text formats.
pub fn mutate(seed: u64, input: &[u8], out: &mut Vec<u8>) {
    let mut rng = Rng::new(seed);
    out.clear();
    out.extend_from_slice(input);
    let edits = 1 + rng.below(8);
    for _ in 0..edits {
        let len = out.len();
        match rng.below(11) {
            0 | 1 if len > 0 => {
                let at = rng.below(len);
                out[at] ^= 1 << rng.below(8);
            }
            2 if len > 0 => {
                let at = rng.below(len);
                out[at] = BYTES[rng.below(BYTES.len())];
            }
            3 if len >= 4 => {
                let at = rng.below(len - 3);
                let w = WORDS[rng.below(WORDS.len())];
                out[at..at + 4].copy_from_slice(&w.to_le_bytes());
            }
            4 if len >= 8 => {
                let at = rng.below(len - 7);
                let q = QUADS[rng.below(QUADS.len())];
                out[at..at + 8].copy_from_slice(&q.to_le_bytes());
            }
            5 if len > 0 => out.truncate(rng.below(len)),
            6 if len > 0 => {
                let a = rng.below(len);
                let n = 1 + rng.below((len - a).min(4096));
                let at = rng.below(len + 1);
                let piece = out[a..a + n].to_vec();
                out.splice(at..at, piece);
            }
            7 => {
                let at = rng.below(len + 1);
                let n = 1 + rng.below(16);
                let piece: Vec<u8> = (0..n).map(|_| rng.next_u64() as u8).collect();
                out.splice(at..at, piece);
            }
            8 => {
                let at = rng.below(len + 1);
                let t = TOKENS[rng.below(TOKENS.len())];
                out.splice(at..at, t.iter().copied());
            }
            9 if len > 0 => {
                let at = rng.below(len);
                out[at] = rng.next_u64() as u8;
            }
            _ if len > 1 => {
                // Remove a slice.
                let a = rng.below(len);
                let n = 1 + rng.below((len - a).min(64));
                out.drain(a..a + n);
            }
            _ => out.push(rng.next_u64() as u8),
        }
    }
}

/// A generated input: `seed` decides its length (0 to 1 KiB) and bytes; for text targets most
/// bytes are printable.
pub fn generate(seed: u64, text: bool, out: &mut Vec<u8>) {
    let mut rng = Rng::new(seed ^ 0x5eed);
    out.clear();
    let len = rng.below(1025);
    for _ in 0..len {
        let r = rng.next_u64();
        let b = if text && !r.is_multiple_of(8) {
            b" \n=[]\".,#abcdefghijklmnopqrstuvwxyz0123456789-_"[((r >> 8) % 47) as usize]
        } else {
            (r >> 8) as u8
        };
        out.push(b);
    }
}

/// `link`: a sample as the bridge takes it off a zenoh link from another machine (issue 17):
/// the first byte picks the topic (of the recorded ones, in table order), the rest is its
/// message. A message that decodes is exactly the sample it holds: encoding the sample again
/// gives the message back (a world's, but for the CDR padding after its count; a hand of before
/// sides, widened with zeros); its counts
/// fit its arrays (issue 40: a `finger_point_count` of 6 crashed every viewer); and it goes
/// where a viewer's bridge and recorder send it: into the scene view, hand then world, and out
/// as the view's update.
pub fn link(data: &[u8]) {
    use common::{BlockState, Counted, WorldHeader};
    let Some((&which, message)) = data.split_first() else {
        return;
    };
    let topic = Topic::RECORDED[usize::from(which) % Topic::RECORDED.len()];
    let mut out = Vec::new();
    fn round_trip<T: common::bus::Stamped + Counted>(
        topic: Topic,
        message: &[u8],
        out: &mut Vec<u8>,
    ) -> Option<T> {
        let sample = recording::decode_sample::<T>(topic, message).ok()?;
        assert!(sample.check_counts(0).is_ok(), "{topic:?}: counts passed");
        recording::encode_sample(&sample, out);
        if out.len() == message.len() {
            assert_eq!(out.as_slice(), message, "{topic:?}");
        } else {
            // A hand of before sides (`HandSample::LEGACY_SIZE`): read as the right hand, it
            // encodes as the message widened with zeros.
            assert_eq!(topic, Topic::Hand, "{topic:?}: {} bytes", message.len());
            assert_eq!(&out[..message.len()], message, "{topic:?}");
            assert!(out[message.len()..].iter().all(|&b| b == 0), "{topic:?}");
        }
        Some(sample)
    }
    let view = || {
        static VIEW: std::sync::OnceLock<Scene> = std::sync::OnceLock::new();
        let scene = VIEW.get_or_init(|| stepper_scenes()[1].clone());
        scene_view::SceneView::new(scene).expect("the grasp scene makes a view")
    };
    match topic {
        Topic::Glove => drop(round_trip::<GloveSample>(topic, message, &mut out)),
        Topic::Tracker => drop(round_trip::<TrackerSample>(topic, message, &mut out)),
        Topic::Joints => drop(round_trip::<JointsSample>(topic, message, &mut out)),
        Topic::Hand => {
            if let Some(hand) = round_trip::<HandSample>(topic, message, &mut out) {
                assert!(hand.finger_count as usize <= common::MAX_FINGERS);
                let mut v = view();
                v.set_hand(&hand);
                v.set_world(0, |_| BlockState::default());
                v.encode_into(&mut out);
            }
        }
        Topic::Frame => drop(round_trip::<FrameSample>(topic, message, &mut out)),
        Topic::PeerHand => drop(round_trip::<common::PeerHandSample>(
            topic, message, &mut out,
        )),
        Topic::World => {
            if let Ok((header, body)) = recording::decode_slice::<WorldHeader>(topic, message) {
                let size = std::mem::size_of::<BlockState>();
                assert_eq!(body.len() % size, 0);
                assert!(header.check_counts(body.len() / size).is_ok());
                let blocks: Vec<BlockState> = body
                    .chunks_exact(size)
                    // SAFETY: whole elements of plain old data, read unaligned.
                    .map(|c| unsafe { std::ptr::read_unaligned(c.as_ptr() as *const BlockState) })
                    .collect();
                recording::encode_slice(topic, &header, &blocks, &mut out);
                // The CDR header, the header and the count agree; then the padding (ours is
                // zeros, theirs any bytes) and the elements, which agree.
                let count_end = 4 + std::mem::size_of::<WorldHeader>() + 4;
                let body_at = message.len() - body.len();
                assert_eq!(out.len(), message.len());
                assert_eq!(out[..count_end], message[..count_end]);
                assert_eq!(out[body_at..], message[body_at..]);
                let mut v = view();
                v.set_world(blocks.len(), |i| blocks[i]);
                v.encode_into(&mut out);
            }
        }
        Topic::Latency => {}
    }
}

/// Steps of one `stepper_hand` input.
pub const STEPPER_STEPS: u64 = 48;
/// The bound on one step of `stepper_hand`: a step of these small scenes takes microseconds
/// (paper) to a millisecond (precise); a second is a hang whatever else runs on the machine.
pub const STEPPER_STEP_BOUND: std::time::Duration = std::time::Duration::from_secs(1);
/// Bytes of one `stepper_hand` record: step, kind, index (u16 LE), value (f64 LE).
pub const STEPPER_RECORD: usize = 12;

/// The scenes `stepper_hand` steps: a push and a grasp with a thrown block (every rule of a
/// hand at work), under each model.
fn stepper_scenes() -> &'static [Scene; 2] {
    static SCENES: std::sync::OnceLock<[Scene; 2]> = std::sync::OnceLock::new();
    SCENES.get_or_init(|| {
        let load = |name: &str| {
            let file = Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../config/scenes")
                .join(name);
            // Our own files: a harness that cannot read them cannot fuzz anything.
            Scene::load(&file).unwrap_or_else(|e| panic!("{e}"))
        };
        [load("push.toml"), load("grasp-throw-fingers.toml")]
    })
}

/// Applies one `stepper_hand` record to a hand sample: `kind` picks what it sets (mod 8: a
/// check point's coordinate, the wrist's position or rotation, the finger count, a finger's
/// point count, a finger's radius, the palm vertex count, a palm vertex's coordinate, or no
/// hand this step, or, with `lost`, the hand marked untracked as a tracker that lost it sends
/// it), `index` which one, `value` the value (its bits for a count).
fn apply_hand_record(kind: u8, index: u16, value: f64, lost: bool, hand: &mut Option<HandSample>) {
    use common::{MAX_FINGERS, MAX_FINGER_POINTS, MAX_PALM_VERTICES};
    let Some(h) = hand.as_mut() else {
        return;
    };
    let i = usize::from(index);
    let bits = value.to_bits() as u32;
    match kind % 8 {
        0 => {
            let i = i % (MAX_FINGERS * MAX_FINGER_POINTS * 3);
            h.finger_points[i / (MAX_FINGER_POINTS * 3)][i / 3 % MAX_FINGER_POINTS][i % 3] = value;
        }
        1 => match i % 7 {
            k @ 0..=2 => h.wrist.position[k] = value,
            k => h.wrist.rotation[k - 3] = value,
        },
        2 => h.finger_count = bits,
        3 => h.finger_point_count[i % MAX_FINGERS] = bits,
        4 => h.finger_radius[i % MAX_FINGERS] = value,
        5 => h.palm_vertex_count = bits,
        6 => {
            let i = i % (MAX_PALM_VERTICES * 3);
            h.palm_vertices[i / 3][i % 3] = value;
        }
        _ if lost => h.tracked = 0,
        _ => *hand = None,
    }
}

/// `stepper_hand` (issue 28): the stepper driven by hand samples with arbitrary values, as a
/// trace, a recording, a device or a remote peer could send them. Byte 0 picks the model (bit
/// 0: paper or precise), the scene (bit 1: push or grasp-throw-fingers), the paper model's hand
/// rules (bit 2: docs/model.md's tracked hands, T1-T3), what a "no hand" record means (bit
/// 3: the hand marked untracked rather than absent) and, for the paper model, a second hand
/// (bit 4: docs/model.md "Two hands": the scripted hand 1 cm over, in slot 1, so that both
/// hands meet the same block); the rest is records of [`STEPPER_RECORD`] bytes: the step (mod
/// [`STEPPER_STEPS`]), what to set ([`apply_hand_record`]; bit 3 of the kind: on the second
/// hand), which, and the value. Each step's samples are the scene's scripted hand with that
/// step's records applied. Promises: every step ends within
/// [`STEPPER_STEP_BOUND`] (a coordinate of 1e20 once hung it), the world counts exactly the
/// samples `hand::unusable_because` refuses, and every block's pose stays finite.
pub fn stepper_hand(data: &[u8]) {
    use common::config::scene::ModelKind;
    use stepper::{BareFingersHand, HandSource, Model};
    let Some((&pick, records)) = data.split_first() else {
        return;
    };
    let mut scene = stepper_scenes()[usize::from(pick >> 1 & 1)].clone();
    scene.world.model = if pick & 1 == 0 {
        ModelKind::Paper
    } else {
        ModelKind::Precise
    };
    if pick & 4 != 0 && scene.world.model == ModelKind::Paper {
        scene.world.hands = common::config::scene::HandRules::Tracked;
    }
    let lost = pick & 8 != 0;
    let two = pick & 16 != 0 && scene.world.model == ModelKind::Paper;
    let mut model = Model::new(&scene).unwrap_or_else(|e| panic!("{e}"));
    let Some(mut script) = BareFingersHand::from_scene(&scene) else {
        panic!("{}: a scene with a scripted hand", scene.file.display());
    };
    let dt = 1.0 / scene.world.step_hz;
    // The second hand: the scripted one 1 cm along x (every point and the wrist).
    let beside = |h: Option<HandSample>| {
        h.filter(|_| two).map(|mut h| {
            for p in h.finger_points.iter_mut().flatten() {
                p[0] += 0.01;
            }
            for p in h.palm_vertices.iter_mut() {
                p[0] += 0.01;
            }
            h.wrist.position[0] += 0.01;
            h.side = common::HandSide::Left.code();
            h
        })
    };
    let first = script.hand_at(0, 0.0);
    model.set_previous_hand(first.as_ref());
    model.set_previous_hand_of(1, beside(first).as_ref());
    let mut refused = 0u64;
    for n in 1..=STEPPER_STEPS {
        let mut hand = script.hand_at(n, n as f64 * dt);
        let mut second = beside(hand);
        for r in records.chunks_exact(STEPPER_RECORD) {
            if u64::from(r[0]) % STEPPER_STEPS == n - 1 {
                let value = f64::from_le_bytes(r[4..12].try_into().expect("8 bytes"));
                apply_hand_record(
                    r[1],
                    u16::from_le_bytes([r[2], r[3]]),
                    value,
                    lost,
                    if r[1] & 8 != 0 {
                        &mut second
                    } else {
                        &mut hand
                    },
                );
            }
        }
        refused += [&hand, &second]
            .iter()
            .filter(|h| h.as_ref().is_some_and(|h| !stepper::hand::is_usable(h)))
            .count() as u64;
        let t0 = std::time::Instant::now();
        model.step_hands([hand.as_ref(), second.as_ref()]);
        let took = t0.elapsed();
        assert!(
            took < STEPPER_STEP_BOUND,
            "step {n} took {took:?}: the stepper hangs on this hand: {hand:?}"
        );
        assert_eq!(model.rejected_hand_samples(), refused, "step {n}: {hand:?}");
        for b in 0..model.block_count() {
            let Some(block) = model.block(b) else {
                continue;
            };
            assert!(
                block.position.is_finite() && block.rotation.is_finite(),
                "step {n}: block {b} at {:?} {:?} (hand {hand:?})",
                block.position,
                block.rotation
            );
        }
    }
}

/// `webxr`: a message from a headset's page (outside input over a socket): a hands frame, the
/// page's frame statistics or its answer to a clock ping. A decoded hands frame re-encodes to
/// the same bytes (every field was read, each f32 passed on exactly), and its joints, mapped
/// for the pipeline, are finite and within the stated range; decoded statistics and pongs are
/// within theirs.
pub fn webxr(data: &[u8]) {
    use webxr_wire::page::{self, decode_pong, decode_stats};
    use webxr_wire::{decode_into, to_joints, HandsFrame, MAX_POSITION_M};
    match page::kind_of(data) {
        Ok(page::KIND_STATS) => {
            if let Ok(s) = decode_stats(data) {
                assert!(s.js_ms.is_finite() && (0.0..=10_000.0).contains(&s.js_ms));
                assert!(s.round_trip_ms.is_none_or(|r| r.is_finite() && r >= 0.0));
            }
            return;
        }
        Ok(page::KIND_PONG) => {
            if let Ok(p) = decode_pong(data) {
                assert!(p.page_ms.is_finite() && p.server_ms.is_finite());
            }
            return;
        }
        _ => {}
    }
    let mut frame = HandsFrame::default();
    if decode_into(data, &mut frame).is_err() {
        return;
    }
    let mut again = Vec::new();
    webxr_wire::encode(&frame, &mut again);
    assert_eq!(again, data, "a decoded frame re-encodes to its bytes");
    let mut joints = JointsSample::default();
    for hand in frame
        .present
        .iter()
        .zip(&frame.hands)
        .filter(|(p, _)| **p)
        .map(|(_, h)| h)
    {
        to_joints(hand, &mut joints);
        for p in joints.joints.iter().chain([&joints.wrist]) {
            assert!(p.is_finite(), "{p:?}");
            let r = p.position.iter().map(|x| x * x).sum::<f64>().sqrt();
            assert!(r <= MAX_POSITION_M + 1e-3, "{r} m");
            let n = p.rotation.iter().map(|x| x * x).sum::<f64>().sqrt();
            assert!(
                (0.5 - 1e-6..=2.0 + 1e-6).contains(&n),
                "orientation norm {n}"
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mutations_are_deterministic_and_differ() {
        let input = b"CARL\x01\0\0\0 some bytes to mutate";
        let (mut a, mut b) = (Vec::new(), Vec::new());
        mutate(7, input, &mut a);
        mutate(7, input, &mut b);
        assert_eq!(a, b);
        let distinct: std::collections::HashSet<Vec<u8>> = (0..100)
            .map(|s| {
                mutate(s, input, &mut a);
                a.clone()
            })
            .collect();
        assert!(distinct.len() > 90, "{}", distinct.len());
        mutate(3, b"", &mut a); // an empty input still mutates
    }

    #[test]
    fn every_target_takes_empty_and_short_inputs() {
        for (_, t) in TARGETS {
            for d in [&b""[..], b"\0", b"\xff\xff", b"0123"] {
                t(d);
            }
        }
        remove_scratch_dir();
    }
}
