//! CARL hand recordings (`../shared/data/carl/FORMAT.md`): a header `CARL`, version, type and
//! sample count, then per sample a timestamp and optional poses (head, wrists, 26 joints per
//! hand, controllers), then a trailer with the start and end times. All little-endian.
//!
//! One hand is read at a time ([`CarlTrace::load_hand`]; [`CarlTrace::load`] reads the right
//! one): its wrist pose and its 26 joints. A sample without that hand (its wrist or its joints
//! absent) keeps the last known pose and is marked lost. [`CarlTrace::tracked_counts`] says
//! which hands a file tracks, and in how many samples, without building either trace. A file
//! that is cut off or damaged yields every sample before the damage, with an error that names
//! the file and the byte offset.

use std::fmt;
use std::path::{Path, PathBuf};

use common::{HandSide, JointsSample, Pose, Stamp, OPENXR_JOINTS};

/// A file's first bytes as a person reads them: text in quotes where they are printable ASCII
/// (`"# ha"`), else hex (`89 4d 43 41`). Error messages that say what a file starts with use it.
pub fn show_bytes(bytes: &[u8]) -> String {
    if !bytes.is_empty() && bytes.iter().all(|b| (0x20..0x7f).contains(b)) {
        format!("{:?}", String::from_utf8_lossy(bytes))
    } else {
        bytes
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect::<Vec<_>>()
            .join(" ")
    }
}

const MAGIC: &[u8; 4] = b"CARL";
const POSE_BYTES: usize = 7 * 4;
const JOINTS_BYTES: usize = OPENXR_JOINTS * POSE_BYTES;
const CONTROLLER_BYTES: usize = 7 * 4;
/// No real recording is longer than a day at 1 kHz; a count beyond this is damage.
const MAX_SAMPLES: u64 = 100_000_000;
/// The fewest bytes a sample takes: its time and seven presence flags.
const MIN_SAMPLE_BYTES: usize = 8 + 7;
/// The fewest bytes a sample with a hand takes (its wrist and joints): only samples
/// that big can fill the file, so the sample list is first sized for that many.
const MIN_HAND_SAMPLE_BYTES: usize = MIN_SAMPLE_BYTES + POSE_BYTES + JOINTS_BYTES;
/// The largest CARL file read: about 1.4 KiB a sample, so over four hours at 90 Hz.
pub const MAX_FILE_BYTES: u64 = 2 << 30;

/// What is wrong with a CARL file.
#[derive(Debug, Clone, PartialEq)]
pub struct CarlError {
    pub file: PathBuf,
    /// Byte offset of the first bad byte.
    pub offset: usize,
    pub problem: String,
}

impl fmt::Display for CarlError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}: at byte {}: {}",
            self.file.display(),
            self.offset,
            self.problem
        )
    }
}

impl std::error::Error for CarlError {}

/// One sample of one hand (the trace's [`CarlTrace::side`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CarlSample {
    /// Seconds, in the recording's own clock.
    pub time: f64,
    /// False when the hand was not tracked in this sample (the poses are the last known, or
    /// identity before the hand was first seen).
    pub tracked: bool,
    pub wrist: Pose,
    pub joints: [Pose; OPENXR_JOINTS],
}

/// A whole trace: the good samples, and what stopped the reading early, if anything.
#[derive(Debug, Clone)]
pub struct CarlTrace {
    pub file: PathBuf,
    /// The hand these samples are of.
    pub side: HandSide,
    pub samples: Vec<CarlSample>,
    /// Set when the file is damaged after some good samples: they are kept, this says why the
    /// rest is not.
    pub damage: Option<CarlError>,
}

struct Cursor<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Cursor<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], (usize, String)> {
        if self.bytes.len() - self.at < n {
            return Err((
                self.at,
                format!(
                    "the file ends inside {what} ({} of {n} bytes)",
                    self.bytes.len() - self.at
                ),
            ));
        }
        let s = &self.bytes[self.at..self.at + n];
        self.at += n;
        Ok(s)
    }
    fn u32(&mut self, what: &str) -> Result<u32, (usize, String)> {
        let b = self.take(4, what)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }
    fn u64(&mut self, what: &str) -> Result<u64, (usize, String)> {
        let b = self.take(8, what)?;
        Ok(u64::from_le_bytes([
            b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7],
        ]))
    }
    fn f64(&mut self, what: &str) -> Result<f64, (usize, String)> {
        Ok(f64::from_bits(self.u64(what)?))
    }
    /// An optional block of `n` bytes: a flag byte, 0 absent, 1 present.
    fn opt(&mut self, n: usize, what: &str) -> Result<Option<&'a [u8]>, (usize, String)> {
        let at = self.at;
        match self.take(1, what)?[0] {
            0 => Ok(None),
            1 => self.take(n, what).map(Some),
            flag => Err((at, format!("{what}: presence flag {flag}, expected 0 or 1"))),
        }
    }
}

/// A pose from 7 little-endian f32: quaternion x, y, z, w, then translation x, y, z.
fn pose(b: &[u8]) -> Pose {
    let f =
        |i: usize| f32::from_le_bytes([b[4 * i], b[4 * i + 1], b[4 * i + 2], b[4 * i + 3]]) as f64;
    Pose {
        rotation: [f(0), f(1), f(2), f(3)],
        position: [f(4), f(5), f(6)],
    }
}

/// Which slot of a sample's pair of hands `side` is: the file stores the left hand first.
fn slot(side: HandSide) -> usize {
    match side {
        HandSide::Left => 0,
        HandSide::Right => 1,
    }
}

/// One hand as the file holds it in one sample: its wrist pose and its 26 joints, still bytes.
type HandBytes<'a> = (&'a [u8], &'a [u8]);

/// One good sample as read: its time, and each hand (left, right) that it holds whole.
struct RawSample<'a> {
    time: f64,
    hands: [Option<HandBytes<'a>>; 2],
}

/// Reads a CARL file's header, then its samples one by one, then checks its trailer: what
/// [`CarlTrace::parse_hand`] and [`CarlTrace::tracked_counts`] share, so that both read
/// exactly the same samples and find the same damage at the same byte.
struct Reader<'a> {
    file: &'a Path,
    c: Cursor<'a>,
    count: u64,
    /// The next sample's index.
    next: u64,
    /// The last good sample's time.
    previous_time: Option<f64>,
}

impl<'a> Reader<'a> {
    fn fail(&self, (offset, problem): (usize, String)) -> CarlError {
        CarlError {
            file: self.file.into(),
            offset,
            problem,
        }
    }

    /// Checks the header: the magic, the version, and a sample count the file can hold.
    fn open(file: &'a Path, bytes: &'a [u8]) -> Result<Reader<'a>, CarlError> {
        let mut r = Reader {
            file,
            c: Cursor { bytes, at: 0 },
            count: 0,
            next: 0,
            previous_time: None,
        };
        let magic = r.c.take(4, "the header").map_err(|e| r.fail(e))?;
        if magic != MAGIC {
            return Err(r.fail((
                0,
                format!(
                    "not a CARL file: it starts with {}, not \"CARL\"",
                    show_bytes(magic)
                ),
            )));
        }
        let version = r.c.u32("the header").map_err(|e| r.fail(e))?;
        if version != 1 {
            return Err(r.fail((
                4,
                format!("CARL version {version}; only version 1 is known"),
            )));
        }
        let _kind = r.c.u32("the header").map_err(|e| r.fail(e))?;
        let count_at = r.c.at;
        let count = r.c.u64("the header").map_err(|e| r.fail(e))?;
        // Each sample takes at least its time and 7 flag bytes: a count the file cannot hold
        // is damage.
        let most = ((bytes.len() - r.c.at) / MIN_SAMPLE_BYTES) as u64;
        if count > MAX_SAMPLES || count > most {
            return Err(r.fail((
                count_at,
                format!(
                    "sample count {count} is impossible for a file of {} bytes (at most {most})",
                    bytes.len()
                ),
            )));
        }
        r.count = count;
        Ok(r)
    }

    /// How many samples to make room for: the count, but no more than the file could hold
    /// with a hand in each (a sample is 1.5 KiB in memory and may take 15 bytes of the file:
    /// the count alone could claim 100 times the file).
    fn capacity(&self) -> usize {
        let hand_samples = (self.c.bytes.len() - self.c.at) / MIN_HAND_SAMPLE_BYTES + 1;
        (self.count as usize).min(hand_samples)
    }

    /// The next sample; None after the last one the header counts. After an error the
    /// caller stops: the rest of the file is not read.
    fn sample(&mut self) -> Option<Result<RawSample<'a>, CarlError>> {
        if self.next >= self.count {
            return None;
        }
        let i = self.next;
        self.next += 1;
        let start = self.c.at;
        let raw = match read_sample(&mut self.c, i) {
            Ok(raw) => raw,
            Err(e) => return Some(Err(self.fail(e))),
        };
        if let Some(prev) = self.previous_time {
            if raw.time < prev {
                let time = raw.time;
                return Some(Err(self.fail((
                    start,
                    format!("sample {i}: time {time} s goes back from {prev} s"),
                ))));
            }
        }
        self.previous_time = Some(raw.time);
        Some(Ok(raw))
    }

    /// After the last sample: the trailer (start and end times) must follow, and nothing
    /// after it. The damage, if any.
    fn trailer(mut self) -> Option<CarlError> {
        if let Err(e) = self.c.take(16, "the trailer") {
            Some(self.fail(e))
        } else if self.c.at != self.c.bytes.len() {
            let extra = self.c.bytes.len() - self.c.at;
            Some(self.fail((
                self.c.at,
                format!("{extra} unexpected bytes after the trailer"),
            )))
        } else {
            None
        }
    }

    /// Where reading stopped, for "no samples" errors.
    fn no_samples(&self) -> CarlError {
        self.fail((self.c.at, "the trace holds no samples".into()))
    }
}

/// A hand's wrist and joints from their bytes.
fn hand_poses((wrist, joints): HandBytes) -> (Pose, [Pose; OPENXR_JOINTS]) {
    let mut out = [Pose::IDENTITY; OPENXR_JOINTS];
    for (k, slot) in out.iter_mut().enumerate() {
        *slot = pose(&joints[k * POSE_BYTES..(k + 1) * POSE_BYTES]);
    }
    (pose(wrist), out)
}

impl CarlTrace {
    /// Reads a CARL file's right hand ([`CarlTrace::load_hand`] with [`HandSide::Right`]).
    /// Fails only when not even one sample can be read; later damage is reported in
    /// [`CarlTrace::damage`] with the good samples kept.
    pub fn load(file: &Path) -> Result<CarlTrace, CarlError> {
        Self::load_hand(file, HandSide::Right)
    }

    /// Reads one hand of a CARL file. Fails only when not even one sample can be read (a file
    /// that tracks no `side` hand at all still reads: every sample is then lost); later damage
    /// is reported in [`CarlTrace::damage`] with the good samples kept.
    pub fn load_hand(file: &Path, side: HandSide) -> Result<CarlTrace, CarlError> {
        let bytes = read(file)?;
        Self::parse_hand(file, &bytes, side)
    }

    /// [`CarlTrace::load`] of a file's bytes: the right hand.
    pub fn parse(file: &Path, bytes: &[u8]) -> Result<CarlTrace, CarlError> {
        Self::parse_hand(file, bytes, HandSide::Right)
    }

    /// [`CarlTrace::load_hand`] of a file's bytes (`file` names it in errors).
    pub fn parse_hand(file: &Path, bytes: &[u8], side: HandSide) -> Result<CarlTrace, CarlError> {
        let mut r = Reader::open(file, bytes)?;
        let mut samples = Vec::with_capacity(r.capacity());
        let mut last: Option<(Pose, [Pose; OPENXR_JOINTS])> = None;
        let mut damage = None;
        while let Some(raw) = r.sample() {
            let raw = match raw {
                Ok(raw) => raw,
                Err(e) => {
                    damage = Some(e);
                    break;
                }
            };
            let hand = raw.hands[slot(side)];
            if let Some(h) = hand {
                last = Some(hand_poses(h));
            }
            let (wrist, joints) = last.unwrap_or((Pose::IDENTITY, [Pose::IDENTITY; OPENXR_JOINTS]));
            samples.push(CarlSample {
                time: raw.time,
                tracked: hand.is_some(),
                wrist,
                joints,
            });
        }
        if samples.is_empty() {
            return Err(damage.unwrap_or_else(|| r.no_samples()));
        }
        if damage.is_none() {
            damage = r.trailer();
        }
        Ok(CarlTrace {
            file: file.into(),
            side,
            samples,
            damage,
        })
    }

    /// Which hands `file` tracks: for the left and the right hand (in that order), the number
    /// of good samples that hold it whole (its wrist pose and its joints; what a trace of that
    /// hand marks `tracked`). It reads the samples as [`CarlTrace::load_hand`] does, without
    /// making poses, and fails where it fails; samples after damage are not counted.
    pub fn tracked_counts(file: &Path) -> Result<[(HandSide, usize); 2], CarlError> {
        let bytes = read(file)?;
        Self::parse_tracked_counts(file, &bytes)
    }

    /// [`CarlTrace::tracked_counts`] of a file's bytes.
    pub fn parse_tracked_counts(
        file: &Path,
        bytes: &[u8],
    ) -> Result<[(HandSide, usize); 2], CarlError> {
        let mut r = Reader::open(file, bytes)?;
        let mut counts = [0usize; 2];
        let mut samples = 0usize;
        let mut damage = None;
        while let Some(raw) = r.sample() {
            match raw {
                Ok(raw) => {
                    samples += 1;
                    for (n, hand) in counts.iter_mut().zip(raw.hands) {
                        *n += hand.is_some() as usize;
                    }
                }
                Err(e) => {
                    damage = Some(e);
                    break;
                }
            }
        }
        if samples == 0 {
            return Err(damage.unwrap_or_else(|| r.no_samples()));
        }
        Ok(HandSide::BOTH.map(|side| (side, counts[slot(side)])))
    }

    /// Samples in which the hand was tracked.
    pub fn tracked_samples(&self) -> usize {
        self.samples.iter().filter(|s| s.tracked).count()
    }

    /// The trace as `joints` samples: source time in ns from the first sample, poses moved by
    /// `offset` (metres, world frame), stamps' seq and origin left for the publisher.
    pub fn joints(&self, offset: [f64; 3], out: &mut Vec<JointsSample>) {
        out.clear();
        let t0 = self.samples.first().map_or(0.0, |s| s.time);
        let shift = |p: Pose| Pose {
            position: [
                p.position[0] + offset[0],
                p.position[1] + offset[1],
                p.position[2] + offset[2],
            ],
            rotation: p.rotation,
        };
        for s in &self.samples {
            let mut j = JointsSample {
                stamp: Stamp {
                    source_time_ns: ((s.time - t0) * 1e9).round() as u64,
                    ..Default::default()
                },
                tracked: s.tracked as u32,
                side: 0,
                wrist: shift(s.wrist),
                joints: s.joints.map(shift),
            };
            if common::first_joint_fault(std::iter::once(&j.wrist).chain(&j.joints)).is_some() {
                // Never let what is no hand into the pipeline (NaN, a joint beyond any room,
                // a rotation that is none: every source's check): hold the previous hand,
                // marked lost.
                match out.last() {
                    Some(prev) => {
                        j.wrist = prev.wrist;
                        j.joints = prev.joints;
                    }
                    None => {
                        j.wrist = Pose::IDENTITY;
                        j.joints = [Pose::IDENTITY; OPENXR_JOINTS];
                    }
                }
                j.tracked = 0;
            }
            out.push(j);
        }
    }

    /// Seconds from the first sample to the last.
    pub fn duration(&self) -> f64 {
        match (self.samples.first(), self.samples.last()) {
            (Some(a), Some(b)) => b.time - a.time,
            _ => 0.0,
        }
    }
}

/// Reads a CARL file, at most [`MAX_FILE_BYTES`] of a regular file.
fn read(file: &Path) -> Result<Vec<u8>, CarlError> {
    common::config::read_bounded(file, MAX_FILE_BYTES).map_err(|e| CarlError {
        file: file.into(),
        offset: 0,
        problem: format!("cannot read the file: {e}"),
    })
}

fn read_sample<'a>(c: &mut Cursor<'a>, i: u64) -> Result<RawSample<'a>, (usize, String)> {
    let what = |part: &str| format!("sample {i}'s {part}");
    let t_at = c.at;
    let time = c.f64(&what("time"))?;
    if !time.is_finite() {
        return Err((t_at, format!("sample {i}: time is {time}")));
    }
    c.opt(POSE_BYTES, &what("head pose"))?;
    let left_wrist = c.opt(POSE_BYTES, &what("left wrist"))?;
    let right_wrist = c.opt(POSE_BYTES, &what("right wrist"))?;
    let left_joints = c.opt(JOINTS_BYTES, &what("left joints"))?;
    let right_joints = c.opt(JOINTS_BYTES, &what("right joints"))?;
    c.opt(CONTROLLER_BYTES, &what("left controller"))?;
    c.opt(CONTROLLER_BYTES, &what("right controller"))?;
    Ok(RawSample {
        time,
        hands: [left_wrist.zip(left_joints), right_wrist.zip(right_joints)],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn data(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../../shared/data/carl")
            .join(name)
    }

    #[test]
    fn every_recording_parses_to_its_last_byte() {
        for (name, n) in [
            ("example_push_0.carl", 218),
            ("example_pull_0.carl", 254),
            ("example_lift_0.carl", 264),
            ("example_settle_0.carl", 305),
        ] {
            let t = CarlTrace::load(&data(name)).unwrap();
            assert_eq!(t.samples.len(), n, "{name}");
            assert!(t.damage.is_none(), "{name}: {:?}", t.damage);
            assert!(t.samples.iter().all(|s| s.tracked));
            // About 90 Hz.
            let rate = (n - 1) as f64 / t.duration();
            assert!((60.0..120.0).contains(&rate), "{name}: {rate} Hz");
            // Hands 0.8 to 1.7 m above the floor, y up.
            assert!(t
                .samples
                .iter()
                .all(|s| (0.8..1.7).contains(&s.wrist.position[1])));
        }
    }

    #[test]
    fn a_cut_file_keeps_its_good_samples_and_names_the_offset() {
        let bytes = std::fs::read(data("example_push_0.carl")).unwrap();
        let cut = &bytes[..bytes.len() / 2];
        let t = CarlTrace::parse(Path::new("cut.carl"), cut).unwrap();
        assert!(
            t.samples.len() > 50 && t.samples.len() < 218,
            "{}",
            t.samples.len()
        );
        let e = t.damage.unwrap();
        assert!(e.to_string().starts_with("cut.carl: at byte "), "{e}");
        assert!(e.problem.contains("ends inside"), "{e}");
    }

    #[test]
    fn wrong_magic_absurd_counts_and_bad_flags_are_named() {
        let e = CarlTrace::parse(Path::new("x.carl"), b"MCAP\x01\0\0\0").unwrap_err();
        assert!(e.problem.contains("not a CARL file"), "{e}");
        let mut b = std::fs::read(data("example_pull_0.carl")).unwrap();
        b[12..20].copy_from_slice(&u64::MAX.to_le_bytes());
        let e = CarlTrace::parse(Path::new("x.carl"), &b).unwrap_err();
        assert_eq!(e.offset, 12);
        assert!(e.problem.contains("impossible"), "{e}");
        let mut b = std::fs::read(data("example_pull_0.carl")).unwrap();
        b[28] = 7; // the first sample's head-pose flag
        let e = CarlTrace::parse(Path::new("x.carl"), &b).unwrap_err();
        assert_eq!(e.offset, 28);
        assert!(e.problem.contains("presence flag 7"), "{e}");
    }

    /// A file of `n` samples holding no pose at all (15 bytes each), then the trailer.
    fn poseless(count: u64, n: usize, tail: &[u8]) -> Vec<u8> {
        let mut b = b"CARL".to_vec();
        b.extend(1u32.to_le_bytes());
        b.extend(1u32.to_le_bytes());
        b.extend(count.to_le_bytes());
        for k in 0..n {
            b.extend((k as f64 / 90.0).to_le_bytes());
            b.extend([0u8; 7]);
        }
        b.extend(tail);
        b
    }

    /// Issue 16 (found writing the `carl` fuzz target): the count check assumed 16 bytes a
    /// sample, so a valid file of more than 16 samples without poses (15 bytes each) was
    /// refused as "impossible".
    #[test]
    fn a_carl_file_of_samples_without_poses_is_read() {
        let b = poseless(40, 40, &[0u8; 16]);
        let t = CarlTrace::parse(Path::new("x.carl"), &b).unwrap();
        assert_eq!(t.samples.len(), 40);
        assert!(t.damage.is_none(), "{:?}", t.damage);
        assert!(t.samples.iter().all(|s| !s.tracked));
    }

    /// Issue 16: the sample list was sized by the header's count, which a file of 15-byte
    /// samples may set to a 15th of its length: 100 times the file in memory (1.5 KiB a
    /// sample) before a sample was read. Now it is sized for what the file can hold with hands.
    #[test]
    fn a_carl_sample_count_is_not_trusted_for_memory() {
        // fuzz/corpus/carl/regression-count-sizes-memory: a count of 4000, one sample, then
        // damage (bytes 7: a presence flag 7).
        let b = poseless(4000, 1, &[7u8; 60_000 - 15]);
        let t = CarlTrace::parse(Path::new("x.carl"), &b).unwrap();
        assert_eq!(t.samples.len(), 1);
        assert!(
            t.samples.capacity() <= 60_000 / 771 + 1,
            "{}",
            t.samples.capacity()
        );
        let e = t.damage.unwrap();
        // Sample 1's time (8 bytes of 7s: a tiny positive number), then its head-pose flag.
        assert_eq!(e.offset, 20 + 15 + 8);
        assert!(e.to_string().starts_with("x.carl: at byte 43: "), "{e}");
        assert!(e.problem.contains("presence flag 7"), "{e}");
    }

    /// Issue 16: `load` read `/dev/zero` (a replay session may name any path) until memory
    /// ran out; now only a regular file of at most MAX_FILE_BYTES is read.
    #[test]
    fn a_carl_file_that_is_a_device_is_refused() {
        let e = CarlTrace::load(Path::new("/dev/zero")).unwrap_err();
        assert_eq!(e.offset, 0);
        assert!(
            e.to_string().starts_with(
                "/dev/zero: at byte 0: cannot read the file: it is a character device, not a \
                 regular file"
            ),
            "{e}"
        );
    }

    #[test]
    fn nan_poses_never_leave_the_reader_and_time_starts_at_zero() {
        let mut b = std::fs::read(data("example_lift_0.carl")).unwrap();
        // Sample 0: time(8) + head flag(1) [+28 if present] ...; find the right wrist by parsing.
        let t = CarlTrace::parse(Path::new("x"), &b).unwrap();
        let mut joints = Vec::new();
        t.joints([0.0, -0.9, 0.0], &mut joints);
        assert_eq!(joints[0].stamp.source_time_ns, 0);
        assert!(
            (joints[0].wrist.position[1] - (t.samples[0].wrist.position[1] - 0.9)).abs() < 1e-12
        );
        // Poison every f32 of the file's body that looks like a coordinate: NaN bytes.
        for chunk in b[20..].chunks_mut(4).step_by(97) {
            chunk.copy_from_slice(&f32::NAN.to_le_bytes());
        }
        if let Ok(t) = CarlTrace::parse(Path::new("x"), &b) {
            t.joints([0.0; 3], &mut joints);
            assert!(joints
                .iter()
                .all(|j| j.wrist.is_finite() && j.joints.iter().all(|p| p.is_finite())));
        }
    }

    /// FNV-1a over every bit of a trace's samples (time, tracked, wrist, joints).
    fn fingerprint(t: &CarlTrace) -> u64 {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        let mut eat = |x: u64| {
            h ^= x;
            h = h.wrapping_mul(0x100_0000_01b3);
        };
        for s in &t.samples {
            eat(s.time.to_bits());
            eat(s.tracked as u64);
            for p in std::iter::once(&s.wrist).chain(s.joints.iter()) {
                for v in p.rotation.iter().chain(p.position.iter()) {
                    eat(v.to_bits());
                }
            }
        }
        h
    }

    /// The right hand reads bit for bit as it did before the side became a parameter: these
    /// fingerprints were taken from the right-hand-only reader.
    #[test]
    fn the_right_hand_is_read_as_before_bit_for_bit() {
        for (name, n, print) in [
            ("example_push_0.carl", 218, 0x7f46_7ae0_300e_91fb_u64),
            ("example_pull_0.carl", 254, 0x783c_b1a5_444f_6567),
            ("example_lift_0.carl", 264, 0x9593_9dfa_a867_963d),
            ("example_settle_0.carl", 305, 0xb82f_2dd7_e5a8_83de),
        ] {
            let file = data(name);
            let bytes = std::fs::read(&file).unwrap();
            for t in [
                CarlTrace::load(&file).unwrap(),
                CarlTrace::load_hand(&file, HandSide::Right).unwrap(),
                CarlTrace::parse(&file, &bytes).unwrap(),
                CarlTrace::parse_hand(&file, &bytes, HandSide::Right).unwrap(),
            ] {
                assert_eq!(t.side, HandSide::Right);
                assert_eq!(t.samples.len(), n, "{name}");
                assert_eq!(fingerprint(&t), print, "{name}");
            }
        }
    }

    /// Both hands of every recording: the right one tracked throughout, the left one in part
    /// (it comes into view late, or leaves it, in three of the four).
    #[test]
    fn either_hand_of_every_recording_and_its_tracked_counts() {
        for (name, n, left, right) in [
            ("example_push_0.carl", 218, 165, 218),
            ("example_pull_0.carl", 254, 168, 254),
            ("example_lift_0.carl", 264, 264, 264),
            ("example_settle_0.carl", 305, 246, 305),
        ] {
            let file = data(name);
            let counts = CarlTrace::tracked_counts(&file).unwrap();
            assert_eq!(
                counts,
                [(HandSide::Left, left), (HandSide::Right, right)],
                "{name}"
            );
            let l = CarlTrace::load_hand(&file, HandSide::Left).unwrap();
            let r = CarlTrace::load(&file).unwrap();
            assert_eq!(l.side, HandSide::Left);
            assert!(l.damage.is_none(), "{name}: {:?}", l.damage);
            assert_eq!(l.samples.len(), n, "{name}");
            assert_eq!(l.tracked_samples(), left, "{name}");
            assert_eq!(r.tracked_samples(), right, "{name}");
            // The same clock, different hands: the wrists are apart wherever both are tracked.
            for (a, b) in l.samples.iter().zip(&r.samples) {
                assert_eq!(a.time.to_bits(), b.time.to_bits());
                if a.tracked {
                    let d: f64 = (0..3)
                        .map(|k| (a.wrist.position[k] - b.wrist.position[k]).powi(2))
                        .sum::<f64>()
                        .sqrt();
                    assert!(d > 0.05, "{name}: wrists {d} m apart");
                    assert!((0.8..1.7).contains(&a.wrist.position[1]), "{name}");
                }
            }
            // Before the left hand is first seen it is lost, at identity.
            let first = l.samples.iter().position(|s| s.tracked).unwrap();
            assert!(l.samples[..first]
                .iter()
                .all(|s| s.wrist == Pose::IDENTITY && !s.tracked));
            // After, an untracked sample holds the last tracked pose.
            for w in l.samples[first..].windows(2) {
                if !w[1].tracked {
                    assert_eq!(w[1].wrist, w[0].wrist, "{name}");
                    assert_eq!(w[1].joints, w[0].joints, "{name}");
                }
            }
        }
    }

    /// Every joint of every example, either hand, offset as the CARL sessions do, passes the
    /// joint check every source makes: a replay holds no sample of them.
    #[test]
    fn every_joint_of_every_recording_is_a_joint() {
        for name in [
            "example_push_0.carl",
            "example_pull_0.carl",
            "example_lift_0.carl",
            "example_settle_0.carl",
        ] {
            for side in [HandSide::Left, HandSide::Right] {
                let t = CarlTrace::load_hand(&data(name), side).unwrap();
                for s in &t.samples {
                    let fault =
                        common::first_joint_fault(std::iter::once(&s.wrist).chain(&s.joints));
                    assert_eq!(fault, None, "{name} {side:?} at {} s", s.time);
                }
            }
        }
    }

    /// A damaged file keeps its good samples for the left hand as for the right: the same
    /// samples, the same damage at the same byte, and the counts stop there too.
    #[test]
    fn a_cut_file_keeps_its_good_left_samples_too() {
        let full_file = data("example_push_0.carl");
        let bytes = std::fs::read(&full_file).unwrap();
        let full = CarlTrace::parse_hand(&full_file, &bytes, HandSide::Left).unwrap();
        let cut = &bytes[..bytes.len() * 3 / 4];
        let l = CarlTrace::parse_hand(Path::new("cut.carl"), cut, HandSide::Left).unwrap();
        let r = CarlTrace::parse(Path::new("cut.carl"), cut).unwrap();
        assert_eq!(l.samples.len(), r.samples.len());
        assert!(l.samples.len() > 100 && l.samples.len() < 218);
        assert_eq!(l.samples[..], full.samples[..l.samples.len()]);
        let (el, er) = (l.damage.unwrap(), r.damage.unwrap());
        assert_eq!(el, er);
        assert!(el.to_string().starts_with("cut.carl: at byte "), "{el}");
        assert!(el.problem.contains("ends inside"), "{el}");
        let tracked = l.samples.iter().filter(|s| s.tracked).count();
        assert!(tracked > 0);
        assert_eq!(
            CarlTrace::parse_tracked_counts(Path::new("cut.carl"), cut).unwrap(),
            [
                (HandSide::Left, tracked),
                (HandSide::Right, r.samples.len())
            ]
        );
    }

    #[test]
    fn tracked_counts_name_what_is_wrong_and_count_no_hands_in_a_poseless_file() {
        let e =
            CarlTrace::parse_tracked_counts(Path::new("x.carl"), b"MCAP\x01\0\0\0").unwrap_err();
        assert_eq!(e.offset, 0);
        assert!(e.problem.contains("not a CARL file"), "{e}");
        let e = CarlTrace::tracked_counts(Path::new("/dev/zero")).unwrap_err();
        assert!(e.problem.contains("not a regular file"), "{e}");
        let b = poseless(40, 40, &[0u8; 16]);
        assert_eq!(
            CarlTrace::parse_tracked_counts(Path::new("x.carl"), &b).unwrap(),
            [(HandSide::Left, 0), (HandSide::Right, 0)]
        );
        let t = CarlTrace::parse_hand(Path::new("x.carl"), &b, HandSide::Left).unwrap();
        assert_eq!((t.samples.len(), t.tracked_samples()), (40, 0));
        let e = CarlTrace::parse_tracked_counts(Path::new("x.carl"), &poseless(0, 0, &[0u8; 16]))
            .unwrap_err();
        assert!(e.problem.contains("no samples"), "{e}");
    }
}
