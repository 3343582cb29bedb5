//! CARL hand recordings (`../shared/data/carl/FORMAT.md`): a header `CARL`, version, type and
//! sample count, then per sample a timestamp and optional poses (head, wrists, 26 joints per
//! hand, controllers), then a trailer with the start and end times. All little-endian.
//!
//! Only the right hand is used: its wrist pose and its 26 joints. A sample without the right
//! hand keeps the last known pose and is marked lost. A file that is cut off or damaged yields
//! every sample before the damage, with an error that names the file and the byte offset.

use std::fmt;
use std::path::{Path, PathBuf};

use common::{JointsSample, Pose, Stamp, OPENXR_JOINTS};

const MAGIC: &[u8; 4] = b"CARL";
const POSE_BYTES: usize = 7 * 4;
const JOINTS_BYTES: usize = OPENXR_JOINTS * POSE_BYTES;
const CONTROLLER_BYTES: usize = 7 * 4;
/// No real recording is longer than a day at 1 kHz; a count beyond this is damage.
const MAX_SAMPLES: u64 = 100_000_000;
/// The fewest bytes a sample takes: its time and seven presence flags.
const MIN_SAMPLE_BYTES: usize = 8 + 7;
/// The fewest bytes a sample with the right hand takes (its wrist and joints): only samples
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

/// One sample of the right hand.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CarlSample {
    /// Seconds, in the recording's own clock.
    pub time: f64,
    /// False when the right hand was not tracked in this sample (the poses are the last known).
    pub tracked: bool,
    pub wrist: Pose,
    pub joints: [Pose; OPENXR_JOINTS],
}

/// A whole trace: the good samples, and what stopped the reading early, if anything.
#[derive(Debug, Clone)]
pub struct CarlTrace {
    pub file: PathBuf,
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

impl CarlTrace {
    /// Reads a CARL file. Fails only when not even one sample can be read; later damage is
    /// reported in [`CarlTrace::damage`] with the good samples kept.
    pub fn load(file: &Path) -> Result<CarlTrace, CarlError> {
        let bytes = common::config::read_bounded(file, MAX_FILE_BYTES).map_err(|e| CarlError {
            file: file.into(),
            offset: 0,
            problem: format!("cannot read the file: {e}"),
        })?;
        Self::parse(file, &bytes)
    }

    pub fn parse(file: &Path, bytes: &[u8]) -> Result<CarlTrace, CarlError> {
        let fail = |(offset, problem): (usize, String)| CarlError {
            file: file.into(),
            offset,
            problem,
        };
        let mut c = Cursor { bytes, at: 0 };
        let magic = c.take(4, "the header").map_err(fail)?;
        if magic != MAGIC {
            return Err(fail((
                0,
                format!("not a CARL file: it starts with {magic:02x?}, not \"CARL\""),
            )));
        }
        let version = c.u32("the header").map_err(fail)?;
        if version != 1 {
            return Err(fail((
                4,
                format!("CARL version {version}; only version 1 is known"),
            )));
        }
        let _kind = c.u32("the header").map_err(fail)?;
        let count_at = c.at;
        let count = c.u64("the header").map_err(fail)?;
        // Each sample takes at least its time and 7 flag bytes: a count the file cannot hold
        // is damage.
        let most = ((bytes.len() - c.at) / MIN_SAMPLE_BYTES) as u64;
        if count > MAX_SAMPLES || count > most {
            return Err(fail((
                count_at,
                format!(
                    "sample count {count} is impossible for a file of {} bytes (at most {most})",
                    bytes.len()
                ),
            )));
        }
        // Sized for the samples the file could hold with hands (a sample is 1.5 KiB in memory
        // and may take 15 bytes of the file): the count alone could claim 100 times the file.
        let hand_samples = (bytes.len() - c.at) / MIN_HAND_SAMPLE_BYTES + 1;
        let mut samples = Vec::with_capacity((count as usize).min(hand_samples));
        let mut last: Option<(Pose, [Pose; OPENXR_JOINTS])> = None;
        let mut damage = None;
        for i in 0..count {
            let start = c.at;
            match read_sample(&mut c, i) {
                Ok((time, right)) => {
                    if let Some(prev) = samples.last().map(|s: &CarlSample| s.time) {
                        if time < prev {
                            damage = Some(fail((
                                start,
                                format!("sample {i}: time {time} s goes back from {prev} s"),
                            )));
                            break;
                        }
                    }
                    let tracked = right.is_some();
                    if let Some(r) = right {
                        last = Some(r);
                    }
                    let (wrist, joints) =
                        last.unwrap_or((Pose::IDENTITY, [Pose::IDENTITY; OPENXR_JOINTS]));
                    samples.push(CarlSample {
                        time,
                        tracked: tracked && last.is_some(),
                        wrist,
                        joints,
                    });
                }
                Err(e) => {
                    damage = Some(fail(e));
                    break;
                }
            }
        }
        if samples.is_empty() {
            return Err(damage.unwrap_or_else(|| fail((c.at, "the trace holds no samples".into()))));
        }
        if damage.is_none() {
            // The trailer (start and end times) must follow, and nothing after it.
            if let Err(e) = c.take(16, "the trailer") {
                damage = Some(fail(e));
            } else if c.at != bytes.len() {
                damage = Some(fail((
                    c.at,
                    format!("{} unexpected bytes after the trailer", bytes.len() - c.at),
                )));
            }
        }
        Ok(CarlTrace {
            file: file.into(),
            samples,
            damage,
        })
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
                _reserved: 0,
                wrist: shift(s.wrist),
                joints: s.joints.map(shift),
            };
            if !j.wrist.is_finite() || j.joints.iter().any(|p| !p.is_finite()) {
                // Never let NaN into the pipeline: hold the previous hand, marked lost.
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

type RightHand = (Pose, [Pose; OPENXR_JOINTS]);

fn read_sample(c: &mut Cursor, i: u64) -> Result<(f64, Option<RightHand>), (usize, String)> {
    let what = |part: &str| format!("sample {i}'s {part}");
    let t_at = c.at;
    let time = c.f64(&what("time"))?;
    if !time.is_finite() {
        return Err((t_at, format!("sample {i}: time is {time}")));
    }
    c.opt(POSE_BYTES, &what("head pose"))?;
    c.opt(POSE_BYTES, &what("left wrist"))?;
    let right_wrist = c.opt(POSE_BYTES, &what("right wrist"))?;
    c.opt(JOINTS_BYTES, &what("left joints"))?;
    let right_joints = c.opt(JOINTS_BYTES, &what("right joints"))?;
    c.opt(CONTROLLER_BYTES, &what("left controller"))?;
    c.opt(CONTROLLER_BYTES, &what("right controller"))?;
    let right = match (right_wrist, right_joints) {
        (Some(w), Some(j)) => {
            let mut joints = [Pose::IDENTITY; OPENXR_JOINTS];
            for (k, slot) in joints.iter_mut().enumerate() {
                *slot = pose(&j[k * POSE_BYTES..(k + 1) * POSE_BYTES]);
            }
            Some((pose(w), joints))
        }
        _ => None,
    };
    Ok((time, right))
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
}
