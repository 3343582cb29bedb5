//! A hand trace of either kind, as the samples a source publishes: one of our MCAP recordings
//! (its `glove` + `tracker` or `joints` topics; or, where it holds none of them, its `hand`
//! topic: a shared world's host records every participant's hands as its stepper took them)
//! or a CARL file (its right hand as `joints`).
//!
//! The file's first bytes decide which reader runs. Whatever the kind, the samples come out
//! ready to publish: recorded source times (from 0 for CARL), poses moved by the offset, and
//! never a NaN: a sample that is not finite or claims an impossible count, or joints that fail
//! the check every source of joints makes ([`common::Pose::joint_fault`]), holds the previous
//! good one (a hand sample also marked lost), with a warning that names file and offset.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use common::stamp::MAX_SOURCE_GAP_NS;
use common::{
    GloveSample, HandSample, JointFault, JointsSample, Pose, Stage, Topic, TrackerSample,
    MAX_GLOVE_SENSORS, MAX_JOINT_DISTANCE_M,
};
use recording::Recording;

use crate::carl::CarlTrace;

/// One sample of a hand source, as it goes onto the bus.
// Held by value: a trace is one flat Vec read in order, and boxing the joints would cost an
// allocation per sample for a few KiB saved on the small variants.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SourceSample {
    Glove(GloveSample),
    Tracker(TrackerSample),
    Joints(JointsSample),
    /// A hand as a stepper took it (a shared world host's recording: every participant's,
    /// each marked with its participant), played to the stepper with no kinematics between.
    Hand(HandSample),
}

impl SourceSample {
    pub fn source_time_ns(&self) -> u64 {
        match self {
            SourceSample::Glove(s) => s.stamp.source_time_ns,
            SourceSample::Tracker(s) => s.stamp.source_time_ns,
            SourceSample::Joints(s) => s.stamp.source_time_ns,
            SourceSample::Hand(s) => s.stamp.source_time_ns,
        }
    }

    fn set_source_time_ns(&mut self, t: u64) {
        match self {
            SourceSample::Glove(s) => s.stamp.source_time_ns = t,
            SourceSample::Tracker(s) => s.stamp.source_time_ns = t,
            SourceSample::Joints(s) => s.stamp.source_time_ns = t,
            SourceSample::Hand(s) => s.stamp.source_time_ns = t,
        }
    }

    /// The topic it is published on.
    pub fn topic(&self) -> Topic {
        match self {
            SourceSample::Glove(_) => Topic::Glove,
            SourceSample::Tracker(_) => Topic::Tracker,
            SourceSample::Joints(_) => Topic::Joints,
            SourceSample::Hand(_) => Topic::Hand,
        }
    }

    /// True for the samples that each make one hand sample downstream (tracker, joints), or
    /// are one (a hand).
    pub fn makes_a_hand(&self) -> bool {
        !matches!(self, SourceSample::Glove(_))
    }
}

/// Which reader a trace went through.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TraceKind {
    Mcap,
    Carl,
}

/// A loaded trace: its samples in publish order, and what was wrong with the file.
#[derive(Debug, Clone)]
pub struct HandTrace {
    pub file: PathBuf,
    pub kind: TraceKind,
    pub samples: Vec<SourceSample>,
    /// Damage that ended reading early, and bad samples that were replaced: one line each,
    /// naming the file and the byte offset.
    pub warnings: Vec<String>,
}

/// Warnings about bad samples beyond this many are summed up in one line.
const MAX_SAMPLE_WARNINGS: usize = 5;

fn shift(p: Pose, offset: [f64; 3]) -> Pose {
    Pose {
        position: [
            p.position[0] + offset[0],
            p.position[1] + offset[1],
            p.position[2] + offset[2],
        ],
        rotation: p.rotation,
    }
}

impl HandTrace {
    /// Reads `file` (MCAP or CARL, by its first bytes) and moves its poses by `offset` metres.
    /// Fails when the file cannot be read, is neither kind, or holds no hand samples.
    pub fn load(file: &Path, offset: [f64; 3]) -> Result<HandTrace, String> {
        HandTrace::load_hand(file, offset, common::HandSide::Right)
    }

    /// The hands `hands` names of `file`: one ([`HandTrace::load_hand`]), or both. Both of a
    /// CARL file are its right and left hand of each sample, one after the other (the left's
    /// `joints` marked `side` 1), as a headset sends them; one of our recordings holds the
    /// hands it was made with, each `joints` sample marked with its side, and plays as it is.
    pub fn load_hands(
        file: &Path,
        offset: [f64; 3],
        hands: common::HandsUsed,
    ) -> Result<HandTrace, String> {
        let common::HandsUsed::One(side) = hands else {
            let right = HandTrace::load_hand(file, offset, common::HandSide::Right)?;
            if right.kind == TraceKind::Mcap {
                return Ok(right);
            }
            let left = HandTrace::load_hand(file, offset, common::HandSide::Left)?;
            let mut both = right.clone();
            both.samples.clear();
            for (r, l) in right.samples.iter().zip(&left.samples) {
                both.samples.push(*r);
                let mut l = *l;
                if let SourceSample::Joints(j) = &mut l {
                    j.side = common::HandSide::Left.code();
                }
                both.samples.push(l);
            }
            return Ok(both);
        };
        HandTrace::load_hand(file, offset, side)
    }

    /// [`HandTrace::load`] of one hand: a CARL file holds both (`side`); one of our recordings
    /// holds the one hand it was made with, which is read as the right (asking it for the left
    /// is an error that says so).
    pub fn load_hand(
        file: &Path,
        offset: [f64; 3],
        side: common::HandSide,
    ) -> Result<HandTrace, String> {
        let head = {
            use std::io::Read;
            let mut head = [0u8; 8];
            // Only a regular file, refused before a read could block (a FIFO with no writer
            // would hang here for ever, deaf to Ctrl-C in Python; issue 40).
            let n = common::config::open_regular(file)
                .and_then(|mut f| f.read(&mut head).map_err(|e| e.to_string()))
                .map_err(|e| format!("{}: cannot read the trace: {e}", file.display()))?;
            head[..n].to_vec()
        };
        let trace = if Recording::is_mcap(&head) {
            if side != common::HandSide::Right {
                return Err(format!(
                    "{}: one of our recordings holds the one hand it was recorded with (read as \
                     the right); the {} hand can be taken from a CARL file, which holds both",
                    file.display(),
                    side.name()
                ));
            }
            let sources: Vec<Topic> = Stage::Replay.recorded_outputs().collect();
            let rec = Recording::open_topics(file, &sources).map_err(|e| e.to_string())?;
            HandTrace::from_recording(&rec, offset)
        } else {
            let carl = CarlTrace::load_hand(file, side).map_err(|e| {
                format!("{e} (a hand trace is one of our MCAP recordings or a CARL file)")
            })?;
            let mut joints = Vec::new();
            carl.joints(offset, &mut joints);
            HandTrace {
                file: file.to_path_buf(),
                kind: TraceKind::Carl,
                samples: joints.into_iter().map(SourceSample::Joints).collect(),
                warnings: carl.damage.iter().map(|d| d.to_string()).collect(),
            }
        };
        let mut trace = trace;
        trace.mend_clock_jumps();
        if trace.hands() == 0 {
            let mut why = format!(
                "{}: no hand samples to replay (an MCAP recording needs a `tracker` or `joints` \
                 topic, or, a shared world host's, a `hand` topic)",
                file.display()
            );
            for w in &trace.warnings {
                let _ = write!(why, "; {w}");
            }
            return Err(why);
        }
        Ok(trace)
    }

    /// The source topics of a recording, in the order they were published.
    pub fn from_recording(rec: &Recording, offset: [f64; 3]) -> HandTrace {
        let mut trace = HandTrace {
            file: rec.path.clone(),
            kind: TraceKind::Mcap,
            samples: Vec::new(),
            warnings: rec.damage.iter().map(|d| d.to_string()).collect(),
        };
        if rec.refused_messages > 0 {
            // Refused by the reader (issue 40: counts past their arrays), so never played.
            trace.warnings.push(format!(
                "{}: {} messages skipped, their counts past their arrays (the first {})",
                rec.path.display(),
                rec.refused_messages,
                rec.first_refused.as_deref().unwrap_or("")
            ));
        }
        // A source's samples where the recording holds any; else its hands as the stepper took
        // them (a shared world's host has no source samples: its hands are its participants').
        let mut sources: Vec<Topic> = Stage::Replay.recorded_outputs().collect();
        let has_source_samples = rec
            .messages
            .iter()
            .any(|m| m.topic != Topic::Hand && sources.contains(&m.topic));
        if has_source_samples {
            sources.retain(|t| *t != Topic::Hand);
        }
        let mut order: Vec<_> = rec
            .messages
            .iter()
            .filter(|m| sources.contains(&m.topic))
            .collect();
        // Stable: samples published in the same nanosecond keep their file order.
        order.sort_by_key(|m| m.publish_ns);
        let mut bad = 0usize;
        let mut last_glove: Option<GloveSample> = None;
        let mut last_wrist: Option<Pose> = None;
        let mut last_joints: Option<JointsSample> = None;
        let mut warn = |trace: &mut HandTrace, topic: Topic, seq: u64, at: u64, what: &str| {
            bad += 1;
            if bad <= MAX_SAMPLE_WARNINGS {
                trace.warnings.push(format!(
                    "{}: the {} sample with seq {seq} (in the record at byte offset {at}) {what}; \
                     it holds the previous sample",
                    rec.path.display(),
                    topic.name()
                ));
            }
        };
        for m in order {
            let at = m.record_offset;
            match m.topic {
                Topic::Glove => {
                    let Some(mut g) = rec.sample::<GloveSample>(m) else {
                        continue;
                    };
                    let count = g.sensor_count as usize;
                    let problem = if count > MAX_GLOVE_SENSORS {
                        Some(format!(
                            "claims {count} sensors (at most {MAX_GLOVE_SENSORS})"
                        ))
                    } else if g.angles.iter().any(|a| !a.is_finite()) {
                        Some("has an angle that is not a finite number".to_string())
                    } else {
                        None
                    };
                    if let Some(p) = problem {
                        warn(&mut trace, m.topic, g.stamp.seq, at, &p);
                        let prev = last_glove.unwrap_or_default();
                        g.sensor_count = prev.sensor_count;
                        g.angles = prev.angles;
                    }
                    last_glove = Some(g);
                    trace.samples.push(SourceSample::Glove(g));
                }
                Topic::Tracker => {
                    let Some(mut t) = rec.sample::<TrackerSample>(m) else {
                        continue;
                    };
                    t.wrist = shift(t.wrist, offset);
                    if !t.wrist.is_finite() {
                        warn(
                            &mut trace,
                            m.topic,
                            t.stamp.seq,
                            at,
                            "has a pose that is not finite",
                        );
                        t.wrist = last_wrist.unwrap_or(Pose::IDENTITY);
                    }
                    last_wrist = Some(t.wrist);
                    trace.samples.push(SourceSample::Tracker(t));
                }
                Topic::Joints => {
                    let Some(mut j) = rec.sample::<JointsSample>(m) else {
                        continue;
                    };
                    j.wrist = shift(j.wrist, offset);
                    j.joints = j.joints.map(|p| shift(p, offset));
                    // The check every source of joints makes (a headset's page, a program).
                    let poses = std::iter::once(&j.wrist).chain(&j.joints);
                    if let Some((k, fault)) = common::first_joint_fault(poses) {
                        let joint = match k {
                            0 => "the wrist".to_string(),
                            k => format!("joint {}", k - 1),
                        };
                        let what = match fault {
                            JointFault::NonFinite => "has a pose that is not finite".to_string(),
                            JointFault::TooFar { metres } => format!(
                                "has {joint} {metres} m from the origin (at most \
                                 {MAX_JOINT_DISTANCE_M})"
                            ),
                            JointFault::NoRotation { norm } => format!(
                                "has {joint} rotated by a quaternion of norm {norm}, no rotation"
                            ),
                        };
                        warn(&mut trace, m.topic, j.stamp.seq, at, &what);
                        let prev = last_joints.unwrap_or(JointsSample {
                            wrist: Pose::IDENTITY,
                            joints: [Pose::IDENTITY; common::OPENXR_JOINTS],
                            ..j
                        });
                        j.wrist = prev.wrist;
                        j.joints = prev.joints;
                        j.tracked = 0;
                    }
                    last_joints = Some(j);
                    trace.samples.push(SourceSample::Joints(j));
                }
                Topic::Hand => {
                    let Some(h) = rec.sample::<HandSample>(m) else {
                        continue;
                    };
                    // Hands are in the world's frame as the stepper took them: an offset
                    // would move them off the worlds recorded beside them.
                    if offset != [0.0; 3] {
                        trace.warnings.push(format!(
                            "{}: holds hands as a stepper took them (a shared world's host \
                             recording), not a source's samples: the offset is not applied",
                            rec.path.display()
                        ));
                        return trace;
                    }
                    // Played as recorded: the stepper refuses it, as it refused it live, and
                    // its hand holds its last good pose.
                    if let Some(why) = h.unusable_because() {
                        warn(&mut trace, m.topic, h.stamp.seq, at, why);
                    }
                    trace.samples.push(SourceSample::Hand(h));
                }
                _ => {}
            }
        }
        if bad > MAX_SAMPLE_WARNINGS {
            trace.warnings.push(format!(
                "{}: {} more bad samples held their previous one",
                rec.path.display(),
                bad - MAX_SAMPLE_WARNINGS
            ));
        }
        trace
    }

    /// Issue 16: a sample whose source time is more than [`MAX_SOURCE_GAP_NS`] from the one
    /// before (either way) is a jump of the clock, not time passing (one changed timestamp in
    /// a CARL file put a sample 60 years ahead, and the replay slept until then): it and every
    /// later sample are moved so that it comes 10 ms after the one before, keeping their
    /// spacing; each jump is a warning naming the sample.
    fn mend_clock_jumps(&mut self) {
        const AFTER_JUMP_NS: i128 = 10_000_000;
        let mut correction: i128 = 0;
        let mut previous: Option<i128> = None;
        let mut jumps = 0usize;
        for (i, s) in self.samples.iter_mut().enumerate() {
            let mut t = s.source_time_ns() as i128 + correction;
            if let Some(p) = previous {
                if (t - p).abs() > MAX_SOURCE_GAP_NS as i128 {
                    jumps += 1;
                    if jumps <= MAX_SAMPLE_WARNINGS {
                        self.warnings.push(format!(
                            "{}: sample {i} ({} topic) is {:+.3} s from the one before (a jump \
                             of the source's clock, more than {} s): it and the samples after it \
                             are re-timed to go on 10 ms later",
                            self.file.display(),
                            s.topic().name(),
                            (t - p) as f64 / 1e9,
                            MAX_SOURCE_GAP_NS / 1_000_000_000
                        ));
                    }
                    correction += p + AFTER_JUMP_NS - t;
                    t = p + AFTER_JUMP_NS;
                }
            }
            let t = t.clamp(0, u64::MAX as i128);
            s.set_source_time_ns(t as u64);
            previous = Some(t);
        }
        if jumps > MAX_SAMPLE_WARNINGS {
            self.warnings.push(format!(
                "{}: {} more jumps of the source's clock were re-timed",
                self.file.display(),
                jumps - MAX_SAMPLE_WARNINGS
            ));
        }
    }

    /// Samples that each make one hand downstream (tracker or joints).
    pub fn hands(&self) -> usize {
        self.samples.iter().filter(|s| s.makes_a_hand()).count()
    }

    /// Source time of the first sample: the replay's clock starts there.
    pub fn first_source_time_ns(&self) -> u64 {
        self.samples
            .iter()
            .map(|s| s.source_time_ns())
            .min()
            .unwrap_or(0)
    }
}
