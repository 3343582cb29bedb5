//! Which page drives the hand, and the hand's timeline: the webxr stage's rules, with no socket
//! and no bus, so that each can be tested by itself. The stage ([`crate::service`]) hands it
//! what the pages send and publishes the hands it returns, as they are returned.
//!
//! **Which page drives.** The first page that sends a hands frame drives the hand until its
//! socket closes; frames of any other page meanwhile are counted and dropped (a second headset,
//! or the same one reloaded before the old socket timed out, cannot make the hand jump between
//! two people). Any number of pages may watch.
//!
//! **Time.** A frame's source time is its `predictedDisplayTime` mapped to this machine's
//! CLOCK_MONOTONIC by the page's clock offset ([`crate::server`]), which is held fixed from
//! a driving page's first frame on: the stepper's simulated time follows source time, and an
//! offset that moved under it would stretch or shrink the world's time. Frames whose seq or
//! source time does not increase are refused (`order`: replayed, reordered). Order is the
//! driver's own: a new driver's timeline is put after what was published (its held offset
//! shifted when its first frame would come before it), so no page is held to the times of
//! another, a page that sent a time far ahead included (the server refuses frames far ahead of
//! their page's clock, `clock`, and this keeps any that got through from outliving their page).
//!
//! **Hands.** `hand = "right"` or `"left"`: that hand of each frame is published as a one-hand
//! source's only hand (side 0). `hand = "both"`: each frame publishes the right hand, then the
//! left (side 1), with the same source time (docs/model.md "Two hands"); a hand not seen yet
//! is not sent.
//!
//! **Tracking.** A frame without a driving hand publishes that hand's last joints marked
//! untracked, in the frame's time; kinematics holds the grasp through such a gap up to
//! [`common::TRACKING_HOLD_NS`] (100 ms) and then lets go. A driving page whose socket
//! closes (or that sends nothing for [`driver_silence_ns`]) is a gap too: untracked samples go on,
//! every [`GAP_PERIOD_NS`] of this machine's time, in the driver's timeline continued from its
//! last frame, so that the world goes on and what the hand held falls, until a page drives
//! again. While a page drives, only its frames make samples: the world is a function of what
//! it sent, however slowly it came.
//!
//! **Back to the page.** Every world is sent with the seq of the driving page's frame it
//! answers ([`Driving::answers`], looked up by the world's origin, which is that frame's
//! arrival), so the page measures its round trip.

use common::{HandSide, HandsUsed, JointsSample, Stamp, TRACKING_HOLD_NS};
use webxr_wire::page::NO_FRAME;
use webxr_wire::{Handedness, HandsFrame};

/// A driving page that sends no frame for this long (this machine's time) is taken as gone:
/// it left its XR session, or its browser hid it. A page in XR sends a frame every display
/// frame, a hand or not, so only a page that stopped drawing is this silent; a slow one (a
/// loaded machine's emulated headset stalls for a few hundred milliseconds) is not. Less where
/// the session's budget allows less silence ([`driver_silence_ns`]).
pub const SILENCE_NS: u64 = 2_000_000_000;
/// What the gap samples that follow a silent driver leave of the session's
/// `source_silence_ms`: time for the stage to wake and publish on a loaded machine.
pub const SILENCE_MARGIN_NS: u64 = 250_000_000;

/// How long a driving page may send nothing before it is taken as gone and untracked samples
/// go on: [`SILENCE_NS`], or less where the session's `[budget] source_silence_ms` is shorter
/// (that budget less [`SILENCE_MARGIN_NS`], or half of it, whichever is longer), so that a user
/// who leaves XR for a while is a pause within the budget, not a violated one.
pub fn driver_silence_ns(source_silence_ms: f64) -> u64 {
    let budget_ns = (source_silence_ms * 1e6).max(0.0) as u64;
    (budget_ns.saturating_sub(SILENCE_MARGIN_NS))
        .max(budget_ns / 2)
        .min(SILENCE_NS)
}
/// While no page drives after one did: an untracked sample this often (60 Hz).
pub const GAP_PERIOD_NS: u64 = 16_666_667;
/// Frames remembered to answer a world with the frame it answers.
const ORIGINS: usize = 256;
/// Pages whose clock offsets are kept (more than the server admits at once).
const CLOCKS: usize = 16;

/// The offset a new driver's frames are mapped by: its clock's `offset_ns`, shifted later where
/// its first frame (`frame_ns`, its clock) would not come after `last_source_ns`, the last
/// source time published, so a new driver is never held to an earlier one's times.
fn follow_on_offset(frame_ns: i128, offset_ns: i64, last_source_ns: u64) -> i64 {
    let behind = i128::from(last_source_ns) + 1 - (frame_ns + i128::from(offset_ns));
    offset_ns.saturating_add(behind.clamp(0, i128::from(i64::MAX)) as i64)
}

/// The hands a session's frames publish: (slot, the page's hand), slot being the `joints`
/// sample's side ([`HandSide::code`]): one hand as side 0, or the right (0) then the left (1).
fn slots(hands: HandsUsed) -> &'static [(usize, Handedness)] {
    match hands {
        HandsUsed::One(HandSide::Right) => &[(0, Handedness::Right)],
        HandsUsed::One(HandSide::Left) => &[(0, Handedness::Left)],
        HandsUsed::Both => &[(0, Handedness::Right), (1, Handedness::Left)],
    }
}

/// The hands to publish, by slot (the right or the one hand, then the left), in that order;
/// none when a frame was refused or makes no sample.
pub type Hands = [Option<JointsSample>; 2];

/// What the stage counted, for its report.
#[derive(Debug, Default, Clone, Copy)]
pub struct Counts {
    /// Frames published as joints (tracked or not; with both hands, one frame is two samples).
    pub published: u64,
    /// Per slot ([`slots`]): hands published untracked (frames without that hand, and samples
    /// sent while no page drove).
    pub untracked: [u64; 2],
    /// Frames of a page that was not driving.
    pub other_page: u64,
    /// Frames before the page's clock was known.
    pub before_clock: u64,
    /// Frames whose seq or time did not increase.
    pub order: u64,
    /// Frames the driving page numbered that never came (lost on the way, or refused).
    pub seq_gaps: u64,
    /// Driving sockets lost (closed or silent).
    pub drops: u64,
    /// Pages that took over driving after the first.
    pub takeovers: u64,
    /// Drivers whose timeline was moved on to follow what was published.
    pub shifted: u64,
    /// Gaps of a hand (frames without it, or no page) longer than the hold time, both hands'.
    pub long_gaps: u64,
    /// The first driver's clock offset (held for the session), its ping's round trip, and
    /// the pongs its estimate was made of.
    pub offset_ns: i64,
    pub offset_round_trip_ns: u64,
    pub offset_pongs: u32,
}

/// The driving state: which page drives, its held clock, its last frame, and the hands last
/// published (what a gap repeats).
pub struct Driving {
    hands: HandsUsed,
    /// Added to every joint's position (the session's `[source] offset`).
    offset: [f64; 3],
    /// How long a driver may be silent ([`driver_silence_ns`] of the session's budget).
    silence_ns: u64,
    /// The page driving the hand.
    driver: Option<u64>,
    /// Each page's clock: (page, offset ns, round trip ns).
    clocks: [(u64, i64, u64); CLOCKS],
    /// The offset in force since the first driving frame.
    held_offset_ns: Option<i64>,
    last_seq: Option<u32>,
    last_source_ns: u64,
    last_frame_arrival_ns: u64,
    /// The source time of the driving page's last frame.
    last_frame_source_ns: u64,
    /// When the last untracked sample was sent while no page drove (this machine's time).
    last_gap_ns: u64,
    /// Per slot ([`slots`]), the last joints published (what a gap repeats, untracked).
    joints: Hands,
    /// (origin ns, page seq) of the frames published, to answer worlds with their frame,
    /// and how many hand samples the frame was.
    origins: [(u64, u32, u8); ORIGINS],
    origin_next: usize,
    /// Per slot: start of the hand's current gap (source time), when in one, and whether it
    /// was counted as long.
    gap_from_ns: [Option<u64>; 2],
    gap_counted: [bool; 2],
    counts: Counts,
}

impl Driving {
    /// No page drives yet. `hands`, `offset`: the session's `[source] hand` and `offset`;
    /// `silence_ns`: [`driver_silence_ns`] of its budget.
    pub fn new(hands: HandsUsed, offset: [f64; 3], silence_ns: u64) -> Driving {
        Driving {
            hands,
            offset,
            silence_ns,
            driver: None,
            clocks: [(0, 0, 0); CLOCKS],
            held_offset_ns: None,
            last_seq: None,
            last_source_ns: 0,
            last_frame_arrival_ns: 0,
            last_frame_source_ns: 0,
            last_gap_ns: 0,
            joints: [None; 2],
            origins: [(0, NO_FRAME, 0); ORIGINS],
            origin_next: 0,
            gap_from_ns: [None; 2],
            gap_counted: [false; 2],
            counts: Counts::default(),
        }
    }

    pub fn counts(&self) -> &Counts {
        &self.counts
    }

    /// Whether `page` drives the hand (its statistics are the stage's).
    pub fn drives(&self, page: u64) -> bool {
        self.driver == Some(page)
    }

    /// Whether any hand was published yet.
    fn published_any(&self) -> bool {
        self.joints.iter().any(Option::is_some)
    }

    fn clock_of(&self, page: u64) -> Option<(i64, u64)> {
        self.clocks
            .iter()
            .find(|c| c.0 == page)
            .map(|&(_, offset, rt)| (offset, rt))
    }

    /// `page`'s clock: add `offset_ns` to its time (ns) for this machine's; the estimate of
    /// `pongs` pings, the best of round trip `round_trip_ns`.
    pub fn clock(&mut self, page: u64, offset_ns: i64, round_trip_ns: u64, pongs: u32) {
        let slot = match self.clocks.iter().position(|c| c.0 == page) {
            Some(i) => i,
            // The oldest page's slot (pages are numbered in connection order).
            None => (0..CLOCKS).min_by_key(|&i| self.clocks[i].0).unwrap_or(0),
        };
        self.clocks[slot] = (page, offset_ns, round_trip_ns);
        if self.driver == Some(page) || self.driver.is_none() {
            self.counts.offset_pongs = pongs;
        }
    }

    /// `page`'s socket closed: when it drove, no page drives now.
    pub fn closed(&mut self, page: u64) {
        if self.driver == Some(page) {
            self.driver = None;
            self.counts.drops += 1;
        }
    }

    /// A hands frame of `page` that arrived at `arrived_ns` (this machine's clock): the hands
    /// it publishes, none when it is refused (another page drives, the page's clock is not
    /// known yet, or it is out of order; each counted).
    pub fn frame(&mut self, page: u64, arrived_ns: u64, frame: &HandsFrame) -> Hands {
        match self.driver {
            Some(d) if d != page => {
                self.counts.other_page += 1;
                return [None; 2];
            }
            _ => {}
        }
        let Some((offset_ns, round_trip_ns)) = self.clock_of(page) else {
            self.counts.before_clock += 1;
            return [None; 2];
        };
        let frame_ns = (frame.frame_time_ms * 1e6).round() as i128;
        if self.driver.is_none() {
            // A new driver: its seqs start over; its clock is its own, held from now on, and
            // its timeline follows what was published (whatever times an earlier driver sent).
            if self.published_any() {
                self.counts.takeovers += 1;
            }
            self.driver = Some(page);
            self.last_seq = None;
            if self.held_offset_ns.is_none() {
                self.counts.offset_ns = offset_ns;
                self.counts.offset_round_trip_ns = round_trip_ns;
            }
            let held = follow_on_offset(frame_ns, offset_ns, self.last_source_ns);
            if held != offset_ns {
                self.counts.shifted += 1;
            }
            self.held_offset_ns = Some(held);
        }
        let offset_ns = self.held_offset_ns.unwrap_or(offset_ns);
        let source_ns = frame_ns + i128::from(offset_ns);
        let in_order = self.last_seq.is_none_or(|s| frame.seq > s)
            && source_ns > i128::from(self.last_source_ns)
            && source_ns <= i128::from(u64::MAX);
        if !in_order {
            self.counts.order += 1;
            return [None; 2];
        }
        if let Some(last) = self.last_seq {
            self.counts.seq_gaps += u64::from(frame.seq - last - 1);
        }
        self.last_seq = Some(frame.seq);
        self.last_frame_arrival_ns = arrived_ns;
        self.last_frame_source_ns = source_ns as u64;
        let stamp = Stamp {
            seq: 0,
            source_time_ns: source_ns as u64,
            origin_ns: arrived_ns,
            publish_ns: 0,
        };
        let mut out = [None; 2];
        for &(slot, which) in slots(self.hands) {
            out[slot] = match (frame.hand(which), self.joints[slot]) {
                (Some(hand), _) => {
                    let mut j = JointsSample::default();
                    webxr_wire::to_joints(hand, &mut j);
                    let moved = |p: &mut [f64; 3]| {
                        for (v, o) in p.iter_mut().zip(self.offset) {
                            *v += o;
                        }
                    };
                    moved(&mut j.wrist.position);
                    for p in j.joints.iter_mut() {
                        moved(&mut p.position);
                    }
                    Some(j)
                }
                (None, Some(last)) => {
                    let mut j = last;
                    j.tracked = 0;
                    Some(j)
                }
                // Not seen yet: nothing to hold.
                (None, None) => None,
            }
            .map(|mut j| {
                j.side = slot as u32;
                j.stamp = stamp;
                j
            });
        }
        self.published(out, frame.seq)
    }

    /// No page drives (after one did), at `now_ns` (this machine's clock): the hands seen so
    /// far, untracked, every [`GAP_PERIOD_NS`]; a driver silent for longer than its silence
    /// is dropped first.
    pub fn keep_time(&mut self, now_ns: u64) -> Hands {
        if self.driver.is_some() {
            if now_ns.saturating_sub(self.last_frame_arrival_ns) > self.silence_ns {
                // Silent: a page in the background, a socket that died without a close. Should
                // it come back, it drives again as a new driver (its seqs start over).
                self.driver = None;
                self.counts.drops += 1;
            } else {
                return [None; 2];
            }
        }
        if !self.published_any() || now_ns.saturating_sub(self.last_gap_ns) < GAP_PERIOD_NS {
            return [None; 2];
        }
        self.last_gap_ns = now_ns;
        // The driver's timeline goes on at this machine's pace from its last frame (a page
        // that drives again maps its frames by the same offset, so they follow on).
        let since_last = now_ns.saturating_sub(self.last_frame_arrival_ns);
        let stamp = Stamp {
            seq: 0,
            source_time_ns: (self.last_frame_source_ns + since_last).max(self.last_source_ns + 1),
            origin_ns: now_ns,
            publish_ns: 0,
        };
        // Every hand seen so far, untracked, at one time.
        let hands = self.joints.map(|last| {
            last.map(|mut j| {
                j.tracked = 0;
                j.stamp = stamp;
                j
            })
        });
        self.published(hands, NO_FRAME)
    }

    /// Takes `hands` as published (the right, slot 0, first): counts them and their gaps,
    /// keeps them for the next gap, and remembers which page frame they were, by their origin.
    fn published(&mut self, hands: Hands, frame_seq: u32) -> Hands {
        let mut origin = None;
        let mut samples = 0u8;
        for (slot, joints) in hands.iter().enumerate() {
            let Some(joints) = joints else { continue };
            let t = joints.stamp.source_time_ns;
            if joints.tracked == 0 {
                self.counts.untracked[slot] += 1;
                let from = *self.gap_from_ns[slot].get_or_insert(t);
                if !self.gap_counted[slot] && t - from > TRACKING_HOLD_NS {
                    self.gap_counted[slot] = true;
                    self.counts.long_gaps += 1;
                }
            } else {
                self.gap_from_ns[slot] = None;
                self.gap_counted[slot] = false;
            }
            origin = Some(joints.stamp.origin_ns);
            samples += 1;
            self.last_source_ns = t;
            self.joints[slot] = Some(*joints);
        }
        if let Some(origin) = origin {
            self.origins[self.origin_next] = (origin, frame_seq, samples);
            self.origin_next = (self.origin_next + 1) % ORIGINS;
            self.counts.published += 1;
        }
        hands
    }

    /// The seq of the driving page's frame a world of origin `origin_ns` answers
    /// ([`NO_FRAME`]: none, a gap's).
    pub fn answers(&self, origin_ns: u64) -> u32 {
        // The frame it answers is almost always among the newest published: look back from
        // the newest. (A frame of two hands is answered by one world: the stepper publishes
        // once the frame is whole.)
        (1..=ORIGINS)
            .map(|back| self.origins[(self.origin_next + ORIGINS - back) % ORIGINS])
            .find(|&(o, _, _)| o == origin_ns && origin_ns != 0)
            .map_or(NO_FRAME, |(_, seq, _)| seq)
    }

    /// How long the stage may sleep at `now_ns` before it must look again: while a page
    /// drives, until its silence would end (so the gap begins on time, not a period late);
    /// while none drives after one did, a gap's period; before any, [`SILENCE_NS`].
    pub fn look_again_in_ns(&self, now_ns: u64) -> u64 {
        if self.driver.is_some() {
            let due = self.last_frame_arrival_ns.saturating_add(self.silence_ns);
            due.saturating_sub(now_ns).saturating_add(1_000_000)
        } else if self.published_any() {
            GAP_PERIOD_NS
        } else {
            SILENCE_NS
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use common::config::Session;
    use std::path::Path;
    use webxr_wire::{HandJoints, WEBXR_JOINTS};

    const MS: u64 = 1_000_000;

    /// A hand whose joints are `x` metres along x (finite, tracked).
    fn hand(x: f64) -> HandJoints {
        let mut h = HandJoints::default();
        for (j, p) in h.poses.iter_mut().enumerate() {
            p.position = [x, 1.0, -0.01 * j as f64];
        }
        h.radii = [0.01; WEBXR_JOINTS];
        h
    }

    /// Frame `seq` at `t_ms` on the page's clock, with the right hand at `x` when given.
    fn frame(seq: u32, t_ms: f64, right: Option<f64>) -> HandsFrame {
        let mut f = HandsFrame {
            seq,
            frame_time_ms: t_ms,
            ..Default::default()
        };
        if let Some(x) = right {
            f.present[Handedness::Right as usize] = true;
            f.hands[Handedness::Right as usize] = hand(x);
        }
        f
    }

    /// A right-handed session whose pages 1 and 2 have clocks: page 1 offset 1000 s, page 2
    /// 2000 s.
    fn driving() -> Driving {
        let mut d = Driving::new(HandsUsed::One(HandSide::Right), [0.0; 3], SILENCE_NS);
        d.clock(1, 1_000_000 * MS as i64, 2 * MS, 5);
        d.clock(2, 2_000_000 * MS as i64, 2 * MS, 5);
        d
    }

    #[test]
    fn the_first_page_to_send_a_hand_drives_until_its_socket_closes() {
        let mut d = driving();
        assert!(d.frame(1, 10 * MS, &frame(1, 10.0, Some(0.1)))[0].is_some());
        assert!(d.drives(1));
        // Another page's frames are counted and dropped; its socket closing changes nothing.
        assert_eq!(d.frame(2, 11 * MS, &frame(1, 11.0, Some(0.2))), [None; 2]);
        d.closed(2);
        assert_eq!(d.frame(2, 12 * MS, &frame(2, 12.0, Some(0.2))), [None; 2]);
        assert_eq!(d.counts().other_page, 2);
        // The driver's closes: the other takes over, its seqs its own.
        d.closed(1);
        assert_eq!(d.counts().drops, 1);
        let took = d.frame(2, 13 * MS, &frame(1, 13.0, Some(0.2)));
        assert_eq!(took[0].unwrap().wrist.position[0], 0.2);
        assert!(d.drives(2) && !d.drives(1));
        assert_eq!(d.counts().takeovers, 1);
        assert_eq!(d.counts().published, 2);
    }

    #[test]
    fn a_frame_before_its_pages_clock_is_counted_and_dropped() {
        let mut d = driving();
        assert_eq!(d.frame(3, 10 * MS, &frame(1, 10.0, Some(0.1))), [None; 2]);
        assert_eq!(d.counts().before_clock, 1);
        assert!(!d.drives(3), "it did not take the hand");
        assert!(d.frame(1, 10 * MS, &frame(1, 10.0, Some(0.1)))[0].is_some());
    }

    #[test]
    fn the_clock_is_held_from_the_first_driving_frame_on() {
        let mut d = driving();
        let first = d.frame(1, 10 * MS, &frame(1, 10.0, Some(0.1)))[0].unwrap();
        assert_eq!(first.stamp.source_time_ns, 1_000_010 * MS);
        assert_eq!(first.stamp.origin_ns, 10 * MS);
        assert_eq!(d.counts().offset_ns, 1_000_000 * MS as i64);
        // A better estimate later moves nothing already driving.
        d.clock(1, 1_000_005 * MS as i64, MS, 6);
        let second = d.frame(1, 30 * MS, &frame(2, 20.0, Some(0.1)))[0].unwrap();
        assert_eq!(second.stamp.source_time_ns, 1_000_020 * MS);
        assert_eq!(d.counts().offset_pongs, 6);
    }

    #[test]
    fn frames_out_of_order_are_refused_and_missing_seqs_are_counted() {
        let mut d = driving();
        assert!(d.frame(1, 10 * MS, &frame(1, 10.0, Some(0.1)))[0].is_some());
        // The same seq again; a later seq with an earlier time.
        assert_eq!(d.frame(1, 11 * MS, &frame(1, 11.0, Some(0.1))), [None; 2]);
        assert_eq!(d.frame(1, 12 * MS, &frame(3, 9.0, Some(0.1))), [None; 2]);
        assert_eq!(d.counts().order, 2);
        assert!(d.frame(1, 13 * MS, &frame(5, 13.0, Some(0.1)))[0].is_some());
        assert_eq!(
            d.counts().seq_gaps,
            3,
            "seqs 2, 3 and 4 never came in order"
        );
    }

    #[test]
    fn a_frame_without_the_hand_repeats_it_untracked_and_a_long_gap_is_counted_once() {
        let mut d = driving();
        d.frame(1, 0, &frame(1, 0.0, Some(0.1)));
        let mut last = None;
        for (seq, t) in [(2, 50.0), (3, 120.0), (4, 200.0), (5, 260.0)] {
            let out = d.frame(1, t as u64 * MS, &frame(seq, t, None))[0].unwrap();
            assert_eq!(out.tracked, 0);
            assert_eq!(out.wrist.position[0], 0.1, "the last hand, held");
            last = Some(out);
        }
        assert_eq!(last.unwrap().stamp.source_time_ns, 1_000_260 * MS);
        assert_eq!(d.counts().untracked[0], 4);
        assert_eq!(
            d.counts().long_gaps,
            1,
            "200 ms is 150 ms into the gap: once"
        );
        // The hand comes back: a new gap counts anew.
        assert_eq!(
            d.frame(1, 300 * MS, &frame(6, 300.0, Some(0.2)))[0]
                .unwrap()
                .tracked,
            1
        );
        d.frame(1, 310 * MS, &frame(7, 310.0, None));
        d.frame(1, 420 * MS, &frame(8, 420.0, None));
        assert_eq!(d.counts().long_gaps, 2);
    }

    #[test]
    fn a_silent_driver_is_dropped_and_gap_samples_go_on_in_its_timeline() {
        let mut d = driving();
        // Nothing published yet: nothing to keep time with.
        assert_eq!(d.keep_time(5_000 * MS), [None; 2]);
        assert_eq!(d.look_again_in_ns(5_000 * MS), SILENCE_NS);
        let arrived = 10_000 * MS;
        d.frame(1, arrived, &frame(1, 10.0, Some(0.1)));
        // Driving: it looks again when the silence would end (a millisecond late).
        assert_eq!(d.look_again_in_ns(arrived + MS), SILENCE_NS);
        assert_eq!(
            d.keep_time(arrived + SILENCE_NS),
            [None; 2],
            "not silent yet"
        );
        let now = arrived + SILENCE_NS + 1;
        let gap = d.keep_time(now)[0].unwrap();
        assert!(!d.drives(1));
        assert_eq!(d.counts().drops, 1);
        assert_eq!(gap.tracked, 0);
        assert_eq!(gap.stamp.source_time_ns, 1_000_010 * MS + SILENCE_NS + 1);
        assert_eq!(gap.stamp.origin_ns, now);
        assert_eq!(d.answers(now), NO_FRAME, "a gap's world answers no frame");
        // The next a period later, not sooner.
        assert_eq!(d.look_again_in_ns(now), GAP_PERIOD_NS);
        assert_eq!(d.keep_time(now + GAP_PERIOD_NS - 1), [None; 2]);
        let next = d.keep_time(now + GAP_PERIOD_NS)[0].unwrap();
        assert_eq!(
            next.stamp.source_time_ns,
            gap.stamp.source_time_ns + GAP_PERIOD_NS
        );
        assert_eq!(d.counts().untracked[0], 2);
        assert_eq!(d.counts().published, 3);
    }

    #[test]
    fn a_new_driver_is_put_after_what_was_published() {
        let mut d = driving();
        // Page 2's clock runs 1000 s ahead of page 1's mapping: it drives first, far ahead.
        d.frame(2, 10 * MS, &frame(1, 10.0, Some(0.1)));
        d.closed(2);
        let next = d.frame(1, 20 * MS, &frame(1, 20.0, Some(0.1)))[0].unwrap();
        assert_eq!(next.stamp.source_time_ns, 2_000_010 * MS + 1);
        assert_eq!(d.counts().shifted, 1);
        // The first driver's clock is the one reported.
        assert_eq!(d.counts().offset_ns, 2_000_000 * MS as i64);
    }

    #[test]
    fn both_hands_go_out_as_the_right_then_the_left_at_one_time_once_seen() {
        let mut d = Driving::new(HandsUsed::Both, [0.0, -1.0, 0.5], SILENCE_NS);
        d.clock(1, 0, MS, 5);
        let mut f = frame(1, 10.0, None);
        f.present[Handedness::Left as usize] = true;
        f.hands[Handedness::Left as usize] = hand(-0.2);
        let out = d.frame(1, 10 * MS, &f);
        assert!(
            out[0].is_none(),
            "the right hand, not seen yet, is not sent"
        );
        let left = out[1].unwrap();
        assert_eq!((left.side, left.tracked), (1, 1));
        // The session's offset moves the hand.
        assert_eq!(left.wrist.position, [-0.2, 0.0, 0.5]);
        assert_eq!(left.joints[1].position, [-0.2, 0.0, 0.5]);
        let mut both = frame(2, 20.0, Some(0.3));
        both.present[Handedness::Left as usize] = true;
        both.hands[Handedness::Left as usize] = hand(-0.2);
        let [right, left] = d.frame(1, 20 * MS, &both).map(Option::unwrap);
        assert_eq!((right.side, left.side), (0, 1));
        assert_eq!(right.stamp, left.stamp);
        assert_eq!(right.wrist.position[0], 0.3);
        // One world answers the frame of both.
        assert_eq!(d.answers(20 * MS), 2);
        assert_eq!(d.answers(10 * MS), 1);
        assert_eq!(d.answers(15 * MS), NO_FRAME);
        assert_eq!(d.counts().published, 2);
    }

    #[test]
    fn a_new_driver_follows_what_was_published_whatever_time_came_before() {
        // Nothing published yet: the page's own offset.
        assert_eq!(follow_on_offset(1_000, 5_000, 0), 5_000);
        // Its first frame after what was published: its own offset.
        assert_eq!(follow_on_offset(1_000, 5_000, 5_999), 5_000);
        // An earlier driver's time ran 1e9 ms ahead: the new driver's first frame comes just
        // after it, not refused as out of order until our clock catches up with it.
        let poisoned = 1_000_000_000_000_000_u64;
        let held = follow_on_offset(1_000, 5_000, poisoned);
        assert_eq!(1_000 + i128::from(held), i128::from(poisoned) + 1);
    }

    #[test]
    fn one_hand_is_published_as_side_0_and_both_as_the_right_then_the_left() {
        assert_eq!(
            slots(HandsUsed::One(HandSide::Left)),
            &[(0, Handedness::Left)]
        );
        assert_eq!(
            slots(HandsUsed::One(HandSide::Right)),
            &[(0, Handedness::Right)]
        );
        assert_eq!(
            slots(HandsUsed::Both),
            &[(0, Handedness::Right), (1, Handedness::Left)]
        );
        assert_eq!(HandSide::Left.code(), 1);
    }

    #[test]
    fn gap_samples_begin_within_the_sessions_silence_budget() {
        // The default budget (1 s): the gap begins 250 ms before it ends.
        assert_eq!(driver_silence_ns(1000.0), 750_000_000);
        assert!(driver_silence_ns(1000.0) + GAP_PERIOD_NS < 1_000_000_000);
        // webxr.toml's (2.5 s) and larger: at most SILENCE_NS.
        assert_eq!(driver_silence_ns(2500.0), SILENCE_NS);
        assert_eq!(driver_silence_ns(600_000.0), SILENCE_NS);
        // A short one: half of it.
        assert_eq!(driver_silence_ns(100.0), 50_000_000);
        let session = Session::load(
            &Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/sessions/webxr.toml"),
        )
        .unwrap();
        let silence_ns = driver_silence_ns(session.budget.source_silence_ms);
        assert!(
            (silence_ns + SILENCE_MARGIN_NS) as f64 <= session.budget.source_silence_ms * 1e6,
            "webxr.toml's gap begins after {silence_ns} ns of its {} ms budget",
            session.budget.source_silence_ms
        );
    }
}
