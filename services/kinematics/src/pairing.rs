//! Which glove reading goes with a tracker sample.
//!
//! Kinematics makes one hand per tracker sample with "the newest glove reading" (docs/design.md).
//! Newest *at the tracker's source time*, not newest received: when kinematics falls behind
//! (a descheduled process, a replay as fast as it is consumed) several gloves may be waiting,
//! and pairing a tracker with a glove from its future would make the hand depend on timing.
//! Pairing by source time makes the hand a function of the samples alone, which is what lets a
//! replay reproduce a live run bit for bit.
//!
//! [`HandStream`] is that rule together with the hand model: the one place where source
//! samples become hands, for the kinematics process and for `simulate --hand` alike.

use common::{GloveSample, HandSample, JointsSample, Stamp, TrackerSample};

use crate::model::HandModel;

/// Glove readings kept to pair with trackers that arrive late (a second of a 120 Hz glove).
pub const GLOVE_HISTORY: usize = 128;

pub use common::TRACKING_HOLD_NS;

/// The most recent glove readings, in arrival order, in a fixed ring (no allocation).
pub struct GloveHistory {
    ring: [GloveSample; GLOVE_HISTORY],
    len: usize,
    next: usize,
}

impl Default for GloveHistory {
    fn default() -> Self {
        GloveHistory {
            ring: [GloveSample::default(); GLOVE_HISTORY],
            len: 0,
            next: 0,
        }
    }
}

impl GloveHistory {
    pub fn push(&mut self, glove: &GloveSample) {
        self.ring[self.next] = *glove;
        self.next = (self.next + 1) % GLOVE_HISTORY;
        self.len = (self.len + 1).min(GLOVE_HISTORY);
    }

    /// The glove to pair with a tracker sample of `source_time_ns`: the newest reading at or
    /// before it; if every reading held is later, the oldest held; `None` before any glove.
    pub fn at(&self, source_time_ns: u64) -> Option<&GloveSample> {
        let mut oldest = None;
        for back in 1..=self.len {
            let g = &self.ring[(self.next + GLOVE_HISTORY - back) % GLOVE_HISTORY];
            if g.stamp.source_time_ns <= source_time_ns {
                return Some(g);
            }
            oldest = Some(g);
        }
        oldest
    }
}

/// The source samples of a hand (glove, tracker, joints) in, hand samples out: what the
/// kinematics process does with each sample it receives, and what `handblocks simulate --hand`
/// does with a trace, so that the two make the same hands from the same samples.
///
/// One hand per tracker sample (with the glove [`GloveHistory::at`] its source time, keeping
/// the older of the two origins), one per joints sample from a hand tracker; a glove alone makes
/// none. The hand is kept between samples: a joints sample the model cannot use yields the
/// previous hand, marked lost, so that a reader still gets one hand per source sample.
/// Nothing here allocates: the service calls it for every sample.
pub struct HandStream {
    model: HandModel,
    /// Each hand's own gloves, hand and tracking gap, by slot (0 the right, 1 the left): a
    /// two-hand source's hands are made apart, so that one hand's samples never shape the
    /// other.
    sides: [SideStream; 2],
    /// Hands made so far: the next hand's `seq` (a bus outlet stamps its own on publishing).
    made: u64,
    /// Lost hands released after [`TRACKING_HOLD_NS`] (each gap counted once).
    releases: u64,
}

/// One hand's part of a [`HandStream`].
struct SideStream {
    gloves: GloveHistory,
    hand: HandSample,
    /// Source time of the last tracked joints sample.
    last_tracked_ns: Option<u64>,
}

impl SideStream {
    fn new(side: common::HandSide) -> SideStream {
        SideStream {
            gloves: GloveHistory::default(),
            hand: HandSample {
                side: side.code(),
                ..HandSample::default()
            },
            last_tracked_ns: None,
        }
    }
}

fn slot(side: u32) -> usize {
    match common::HandSide::from_code(side) {
        common::HandSide::Right => 0,
        common::HandSide::Left => 1,
    }
}

impl HandStream {
    pub fn new(model: HandModel) -> Self {
        HandStream {
            model,
            sides: [
                SideStream::new(common::HandSide::Right),
                SideStream::new(common::HandSide::Left),
            ],
            made: 0,
            releases: 0,
        }
    }

    /// Gaps in tracking longer than [`TRACKING_HOLD_NS`], after which the hand let go.
    pub fn releases(&self) -> u64 {
        self.releases
    }

    /// Keeps a glove reading to pair with the trackers of its time (and later ones) on the
    /// same hand ([`GloveSample::side`]).
    pub fn glove(&mut self, glove: &GloveSample) {
        self.sides[slot(glove.side)].gloves.push(glove);
    }

    /// The hand at a tracker sample, on the tracker's side ([`TrackerSample::side`], the left
    /// through the mirrored model): `None` for a wrist pose that is not finite (no hand can be
    /// placed there, and the stepper must never see a NaN). Before any glove the hand is the
    /// model's at zero angles.
    pub fn tracker(&mut self, tracker: &TrackerSample) -> Option<&HandSample> {
        if !tracker.wrist.is_finite() {
            return None;
        }
        let side = common::HandSide::from_code(tracker.side);
        let own = &mut self.sides[slot(tracker.side)];
        let glove = own.gloves.at(tracker.stamp.source_time_ns);
        self.model.solve_side(
            side,
            glove.unwrap_or(&GloveSample::default()),
            &tracker.wrist,
            &mut own.hand,
        );
        own.last_tracked_ns = Some(tracker.stamp.source_time_ns);
        let mut stamp = Stamp::derived(self.made, &tracker.stamp);
        if let Some(g) = glove {
            stamp.origin_ns = stamp.origin_ns.min(g.stamp.origin_ns);
        }
        own.hand.stamp = stamp;
        self.made += 1;
        Some(&own.hand)
    }

    /// The hand at a joints sample: the joints' hand, or, when the model cannot use them, the
    /// previous hand marked lost. A hand lost for longer than [`TRACKING_HOLD_NS`] (source
    /// time since its last tracked sample) lets go: it keeps its wrist but has no fingers and
    /// no palm, so it touches nothing, until it is tracked again.
    ///
    /// The hand is the joints' side ([`JointsSample::side`], copied to [`HandSample::side`]):
    /// a two-hand tracker's hands are made apart, each with its own held pose and gap.
    pub fn joints(&mut self, joints: &JointsSample) -> &HandSample {
        let now = joints.stamp.source_time_ns;
        let side = common::HandSide::from_code(joints.side);
        let own = &mut self.sides[slot(joints.side)];
        let hand = &mut own.hand;
        let tracked = joints.tracked != 0 && self.model.from_joints(joints, hand);
        if tracked {
            own.last_tracked_ns = Some(now);
        } else {
            hand.tracked = 0;
            let held = own
                .last_tracked_ns
                .is_some_and(|t| now.saturating_sub(t) <= TRACKING_HOLD_NS);
            if !held {
                if hand.finger_count > 0 {
                    self.releases += 1;
                }
                hand.finger_count = 0;
                hand.palm_vertex_count = 0;
            }
        }
        hand.side = side.code();
        hand.stamp = Stamp::derived(self.made, &joints.stamp);
        self.made += 1;
        hand
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn glove(t: u64) -> GloveSample {
        let mut g = GloveSample::default();
        g.stamp.source_time_ns = t;
        g
    }

    #[test]
    fn each_hand_pairs_its_own_gloves_and_is_made_on_its_own_side() {
        let mut stream = HandStream::new(HandModel::default());
        // A fist on the left glove, an open right glove, the same source time.
        let mut left_glove = glove(10);
        left_glove.side = 1;
        left_glove.angles = [1.0; common::MAX_GLOVE_SENSORS];
        stream.glove(&glove(10));
        stream.glove(&left_glove);
        let tracker = |side: u32| TrackerSample {
            stamp: Stamp {
                source_time_ns: 10,
                ..Stamp::default()
            },
            station: 1 + side,
            side,
            wrist: common::Pose::IDENTITY,
        };
        let right = *stream.tracker(&tracker(0)).unwrap();
        let left = *stream.tracker(&tracker(1)).unwrap();
        assert_eq!((right.side, left.side), (0, 1));
        // The right hand is flat (its own open glove), the left curled (its own fist).
        let tip_y = |h: &HandSample| h.finger(1)[3][1];
        assert!(tip_y(&right).abs() < 1e-12, "{}", tip_y(&right));
        assert!(tip_y(&left) < -0.03, "{}", tip_y(&left));
        assert_eq!((right.stamp.seq, left.stamp.seq), (0, 1));
    }

    #[test]
    fn a_tracker_takes_the_newest_glove_at_or_before_its_time() {
        let mut h = GloveHistory::default();
        assert!(h.at(5).is_none());
        for t in [10, 20, 30, 40] {
            h.push(&glove(t));
        }
        assert_eq!(h.at(30).unwrap().stamp.source_time_ns, 30);
        assert_eq!(h.at(35).unwrap().stamp.source_time_ns, 30);
        assert_eq!(h.at(99).unwrap().stamp.source_time_ns, 40);
        // Every glove is later: the oldest held.
        assert_eq!(h.at(1).unwrap().stamp.source_time_ns, 10);
        for t in 0..(2 * GLOVE_HISTORY as u64) {
            h.push(&glove(100 + t));
        }
        assert_eq!(
            h.at(50).unwrap().stamp.source_time_ns,
            100 + GLOVE_HISTORY as u64
        );
    }

    fn tracker(t: u64, origin: u64) -> TrackerSample {
        let mut s = TrackerSample::default();
        s.stamp.source_time_ns = t;
        s.stamp.origin_ns = origin;
        s
    }

    #[test]
    fn a_stream_makes_one_hand_per_tracker_or_joints_sample() {
        let model = HandModel::default();
        let mut stream = HandStream::new(model.clone());
        let mut g = glove(10);
        g.stamp.origin_ns = 5;
        g.angles[3] = 0.7;
        stream.glove(&g);
        // The tracker's hand is the model's with the glove of its time, the older origin kept.
        let t = tracker(12, 9);
        let hand = *stream.tracker(&t).unwrap();
        let mut expected = HandSample::default();
        model.solve(&g, &t.wrist, &mut expected);
        assert_eq!(hand.finger_points, expected.finger_points);
        assert_eq!(
            hand.stamp,
            Stamp {
                seq: 0,
                source_time_ns: 12,
                origin_ns: 5,
                publish_ns: 0
            }
        );
        // A wrist that is not finite makes no hand and takes no seq.
        let mut bad = tracker(13, 9);
        bad.wrist.position[0] = f64::NAN;
        assert!(stream.tracker(&bad).is_none());
        // Joints the model cannot use: the previous hand, marked lost, with the joints' stamp.
        let mut j = JointsSample::default();
        j.wrist.rotation = [0.0; 4];
        j.stamp.source_time_ns = 20;
        j.tracked = 1;
        let lost = *stream.joints(&j);
        assert_eq!(lost.tracked, 0);
        assert_eq!(lost.finger_points, hand.finger_points);
        assert_eq!((lost.stamp.seq, lost.stamp.source_time_ns), (1, 20));
    }

    /// A lost hand keeps its grasp (its last pose, fingers and all) for up to
    /// `TRACKING_HOLD_NS` of source time, then lets go (no fingers, no palm), counted once per
    /// gap; tracked again, it has its fingers back.
    #[test]
    fn a_lost_hand_holds_for_the_hold_time_then_lets_go() {
        let mut stream = HandStream::new(HandModel::default());
        let mut j = JointsSample::default();
        for (k, p) in j.joints.iter_mut().enumerate() {
            p.position = [0.01 * k as f64, 1.0, 0.0];
        }
        let at = |j: &JointsSample, ms: u64, tracked: u32| {
            let mut j = *j;
            j.stamp.source_time_ns = ms * 1_000_000;
            j.tracked = tracked;
            j
        };
        let fingers = |s: &mut HandStream, j: JointsSample| s.joints(&j).finger_count;
        assert_eq!(fingers(&mut stream, at(&j, 0, 1)), 5);
        assert_eq!(
            fingers(&mut stream, at(&j, 50, 0)),
            5,
            "held within the hold time"
        );
        assert_eq!(
            fingers(&mut stream, at(&j, 100, 0)),
            5,
            "held at exactly the hold time"
        );
        assert_eq!(stream.releases(), 0);
        assert_eq!(fingers(&mut stream, at(&j, 101, 0)), 0, "let go after it");
        assert_eq!(fingers(&mut stream, at(&j, 160, 0)), 0);
        assert_eq!(stream.releases(), 1, "one gap, one release");
        assert_eq!(stream.joints(&at(&j, 160, 0)).palm_vertex_count, 0);
        assert_eq!(fingers(&mut stream, at(&j, 200, 1)), 5, "tracked again");
        assert_eq!(fingers(&mut stream, at(&j, 250, 0)), 5);
        assert_eq!(stream.releases(), 1);
    }
}
