//! The hand's timeline (docs/model.md, "Conventions"): on each hand sample the world takes as
//! many fixed steps as bring world time up to that sample's source time, with the hand at each
//! step interpolated between the previous and the current sample. World time never reads a
//! wall clock, so the same hand samples always give bit-identical worlds, live (the stepper
//! process, [`crate::service`]) or replayed ([`crate::simulate_samples`]): both advance this
//! one timeline.

use common::{HandSample, HAND_SLOTS};
use glam::{DQuat, DVec3};

/// The longest stretch of source time one hand sample may bring in steps
/// ([`common::stamp::MAX_SOURCE_GAP_NS`]): a source whose clock jumps further is a
/// discontinuity, not a stretch of world time to catch up on (that would be ~1e12 steps).
/// World time then goes on one step past the samples before the jump, and the jump is counted
/// ([`Timeline::jumps`]).
pub const MAX_CATCH_UP_NS: u64 = common::stamp::MAX_SOURCE_GAP_NS;

/// Maps a hand's source timeline onto fixed steps.
#[derive(Debug, Clone)]
pub struct Timeline {
    step_hz: f64,
    /// Source time of the first hand sample: world time 0.
    origin_ns: Option<u64>,
    /// Each hand's last sample, by hand slot.
    previous: [Option<HandSample>; HAND_SLOTS],
    /// The last frame's source time.
    last_ns: Option<u64>,
    steps_taken: u64,
    scratch: [HandSample; HAND_SLOTS],
    /// Discontinuities of the source's clock so far (see [`MAX_CATCH_UP_NS`]).
    jumps: u64,
    /// Steps taken before the last discontinuity: world time since `origin_ns` counts from
    /// there (0 for a source whose clock never jumped).
    base_steps: u64,
}

impl Timeline {
    pub fn new(step_hz: f64) -> Self {
        Timeline {
            step_hz,
            origin_ns: None,
            previous: [None; HAND_SLOTS],
            last_ns: None,
            steps_taken: 0,
            scratch: [HandSample::default(); HAND_SLOTS],
            jumps: 0,
            base_steps: 0,
        }
    }

    /// How many times the source's clock jumped by more than [`MAX_CATCH_UP_NS`] (either way)
    /// between two samples; each time world time went on by one step.
    pub fn jumps(&self) -> u64 {
        self.jumps
    }

    /// True once the first hand sample has set world time 0.
    pub fn started(&self) -> bool {
        self.origin_ns.is_some()
    }

    /// Source time of step `k`, in ns after world time 0: k / step_hz rounded up to a whole
    /// ns, the same grid a source at the step rate stamps its samples on, so that at equal
    /// rates each step takes its hand sample exactly, not an interpolation of it.
    fn step_time_ns(&self, k: u64) -> u64 {
        // A float to integer cast saturates: no overflow for any k.
        (k as f64 * 1e9 / self.step_hz).ceil() as u64
    }

    /// Fixed steps since `origin_ns` whose time is at or before `source_time_ns` (world time 0
    /// at the first sample, or at the last discontinuity).
    fn steps_due(&self, source_time_ns: u64) -> u64 {
        let origin = self.origin_ns.unwrap_or(source_time_ns);
        let elapsed = source_time_ns.saturating_sub(origin);
        let mut k = (elapsed as f64 * self.step_hz / 1e9).floor() as u64;
        // Settle float rounding at the grid's edges.
        while k > 0 && self.step_time_ns(k) > elapsed {
            k -= 1;
        }
        while self.step_time_ns(k + 1) <= elapsed {
            k += 1;
        }
        k
    }

    /// Takes the steps `hand` brings, calling `step` with the hand at each step's time.
    pub fn advance(&mut self, hand: &HandSample, mut step: impl FnMut(Option<&HandSample>)) {
        let mut hands = [None; HAND_SLOTS];
        hands[0] = Some(hand);
        self.advance_hands(hands, |h| step(h[0]));
    }

    /// Takes the steps one frame of hands brings (by hand slot, `crate::HAND_SLOTS`; a
    /// hand the frame lacks is None), calling `step` with each hand at each step's time: the
    /// frame's time is its newest hand's, and each hand is interpolated between its own
    /// previous sample and this one (a hand the last frame lacked is taken as it is). A
    /// source that tracks two hands sends both in every frame, a lost one with `tracked = 0`.
    ///
    /// `N` slots given (at most [`HAND_SLOTS`] read): a source of one person's hands gives two.
    pub fn advance_hands<const N: usize>(
        &mut self,
        hands: [Option<&HandSample>; N],
        mut step: impl FnMut([Option<&HandSample>; N]),
    ) {
        let Some(now) = hands.iter().flatten().map(|h| h.stamp.source_time_ns).max() else {
            return;
        };
        if let Some(last) = self.last_ns {
            if now.abs_diff(last) > MAX_CATCH_UP_NS {
                // A jump of the source's clock: re-base so that this sample falls on the next
                // step, taken with this hand as it is (no interpolation across the jump).
                self.origin_ns = Some(now.saturating_sub(self.step_time_ns(1)));
                self.base_steps = self.steps_taken;
                self.previous = [None; HAND_SLOTS];
                self.jumps += 1;
            }
        }
        let origin = *self.origin_ns.get_or_insert(now);
        let due = self.base_steps + self.steps_due(now);
        while self.steps_taken < due {
            let k = self.steps_taken + 1;
            let t_ns = origin.saturating_add(self.step_time_ns(k - self.base_steps));
            let mut at_step = [None; N];
            for (k, scratch) in self.scratch.iter_mut().enumerate().take(N) {
                at_step[k] = hand_at(t_ns, hands[k], &self.previous[k], scratch);
            }
            step(at_step);
            self.steps_taken = k;
        }
        self.previous = [None; HAND_SLOTS];
        for (previous, hand) in self.previous.iter_mut().zip(hands) {
            *previous = hand.copied();
        }
        self.last_ns = Some(now);
    }
}

/// The hand a fraction `s` of the way from `a` to `b`: points linearly, the wrist by slerp.
pub fn interpolate(a: &HandSample, b: &HandSample, s: f64, out: &mut HandSample) {
    *out = *b;
    let lerp = |p: [f64; 3], q: [f64; 3]| {
        DVec3::from_array(p)
            .lerp(DVec3::from_array(q), s)
            .to_array()
    };
    // A pose between a lost sample (held at its last pose) and a tracked one is not measured:
    // it is the catch-up after a gap (T2 and T3 of tracked hands read this; the paper's
    // rules do not).
    if s < 1.0 {
        out.tracked = a.tracked.min(b.tracked);
    }
    out.wrist.position = lerp(a.wrist.position, b.wrist.position);
    out.wrist.rotation = DQuat::from_array(a.wrist.rotation)
        .slerp(DQuat::from_array(b.wrist.rotation), s)
        .normalize()
        .to_array();
    // Point layouts differ only if the source changed hands; then take b as is.
    if a.finger_count == b.finger_count && a.finger_point_count == b.finger_point_count {
        for f in 0..b.finger_count as usize {
            for i in 0..b.finger_point_count[f] as usize {
                out.finger_points[f][i] = lerp(a.finger_points[f][i], b.finger_points[f][i]);
            }
        }
    }
    if a.palm_vertex_count == b.palm_vertex_count {
        for i in 0..b.palm_vertex_count as usize {
            out.palm_vertices[i] = lerp(a.palm_vertices[i], b.palm_vertices[i]);
        }
    }
}

/// One frame of hands: each hand by slot (`crate::HAND_SLOTS`, [`HandSample::slot`]; slot 0
/// the right or a one-hand source's only hand, slot 1 the left, then each participant's of a
/// shared world), None for a hand it lacks.
pub type HandFrame = [Option<HandSample>; HAND_SLOTS];

/// Makes a stream of hand samples (one per hand per source frame, each marked with its side,
/// [`HandSample::side`]) into frames of both hands, for [`Timeline::advance_hands`]: the
/// stepper process's and `simulate`'s one way of doing it, so that both take the same steps.
///
/// A frame is the samples of one source time. It is complete, and given out at once, when it
/// holds the right hand and, once a left hand has been seen, the left; a sample of another
/// time, or a second of the same hand, gives out the frame before it as it is (a source of two
/// hands sends both in every frame, a lost one with `tracked = 0`, so this happens only when
/// it does not). A one-hand source's frames are its samples, each given out as it arrives.
///
/// A hand the world cannot use (`hand::unusable_because`) is refused and counted: in a frame
/// with a usable hand it holds its last good sample (so a glitch on one hand does not drop
/// what it holds, nor stop the other hand); a frame with no usable hand brings no steps.
#[derive(Debug, Clone, Default)]
pub struct HandFrames {
    pending: HandFrame,
    refused: [bool; HAND_SLOTS],
    pending_ns: Option<u64>,
    last_good: HandFrame,
    /// The slots a hand has been seen in (bit k: slot k): a frame is complete when it holds
    /// each of them and slot 0's.
    seen: u32,
    /// Hands refused so far, and the first one's seq and why.
    pub refused_hands: u64,
    pub first_refused: Option<(u64, &'static str)>,
}

impl HandFrames {
    pub fn new() -> HandFrames {
        HandFrames::default()
    }

    /// Whether a hand other than slot 0's (a left hand, another participant's) has been seen:
    /// from then on a frame waits for every slot seen.
    pub fn two_handed(&self) -> bool {
        self.seen & !1 != 0
    }

    /// Whether a frame is being gathered (its right came, its left not yet; in a shared world,
    /// not yet every participant's): the world does not answer it until it is complete.
    pub fn waiting(&self) -> bool {
        self.pending_ns.is_some()
    }

    /// Each hand's last good sample (the held hands of a world that steps on after its
    /// source ended).
    pub fn last_good(&self) -> &HandFrame {
        &self.last_good
    }

    /// Takes one hand sample; calls `frame` with each frame it completes (none, one or two).
    /// A hand of a participant out of range ([`HandSample::slot`]) is refused and counted, and
    /// touches no frame.
    pub fn push(&mut self, hand: &HandSample, mut frame: impl FnMut(&HandFrame)) {
        let Some(slot) = hand.slot() else {
            self.refused_hands += 1;
            self.first_refused
                .get_or_insert((hand.stamp.seq, "its participant number is out of range"));
            return;
        };
        self.seen |= 1 << slot;
        let t = hand.stamp.source_time_ns;
        if self.pending[slot].is_some()
            || self.refused[slot]
            || self.pending_ns.is_some_and(|p| p != t)
        {
            self.flush(&mut frame);
        }
        self.pending_ns = Some(t);
        match crate::hand::unusable_because(hand) {
            Some(why) => {
                self.refused[slot] = true;
                self.refused_hands += 1;
                self.first_refused.get_or_insert((hand.stamp.seq, why));
            }
            None => self.pending[slot] = Some(*hand),
        }
        let has = |k: usize| self.pending[k].is_some() || self.refused[k];
        let required = self.seen | 1;
        if (0..HAND_SLOTS).all(|k| required & (1 << k) == 0 || has(k)) {
            self.flush(&mut frame);
        }
    }

    /// Gives out the frame being gathered, complete or not (the source stopped).
    pub fn flush(&mut self, mut frame: impl FnMut(&HandFrame)) {
        let Some(t) = self.pending_ns.take() else {
            return;
        };
        if self.pending.iter().any(Option::is_some) {
            for k in 0..HAND_SLOTS {
                if self.refused[k] && self.pending[k].is_none() {
                    self.pending[k] = self.last_good[k].map(|mut held| {
                        held.stamp.source_time_ns = t;
                        held
                    });
                }
            }
            frame(&self.pending);
            for k in 0..HAND_SLOTS {
                if self.pending[k].is_some() {
                    self.last_good[k] = self.pending[k];
                }
            }
        }
        self.pending = [None; HAND_SLOTS];
        self.refused = [false; HAND_SLOTS];
    }
}

/// `hand` at the step of time `t_ns`: interpolated from `previous` (its last sample) when the
/// step falls between the two, into `scratch`; as it is otherwise.
fn hand_at<'a>(
    t_ns: u64,
    hand: Option<&'a HandSample>,
    previous: &Option<HandSample>,
    scratch: &'a mut HandSample,
) -> Option<&'a HandSample> {
    let hand = hand?;
    let now = hand.stamp.source_time_ns;
    Some(match previous {
        Some(prev) if prev.stamp.source_time_ns < now && t_ns < now => {
            let span = (now - prev.stamp.source_time_ns) as f64;
            let s = (t_ns.saturating_sub(prev.stamp.source_time_ns) as f64 / span).clamp(0.0, 1.0);
            interpolate(prev, hand, s, scratch);
            &*scratch
        }
        _ => hand,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hand_at(t_ns: u64, x: f64) -> HandSample {
        let mut h = HandSample::default();
        h.stamp.source_time_ns = t_ns;
        h.wrist.position = [x, 0.0, 0.0];
        h
    }

    #[test]
    fn equal_rates_take_one_step_per_sample_at_the_sample() {
        let mut tl = Timeline::new(120.0);
        let mut xs = Vec::new();
        for k in 0..240u64 {
            let t = (k as f64 * 1e9 / 120.0).ceil() as u64;
            tl.advance(&hand_at(t, k as f64), |h| {
                xs.push(h.unwrap().wrist.position[0])
            });
        }
        assert_eq!(xs.len(), 239);
        assert!(xs
            .iter()
            .enumerate()
            .all(|(i, x)| (x - (i + 1) as f64).abs() < 1e-6));
    }

    #[test]
    fn a_90_hz_source_drives_120_hz_steps_at_real_speed_with_interpolated_hands() {
        let mut tl = Timeline::new(120.0);
        let mut xs = Vec::new();
        for k in 0..=90u64 {
            // x moves 1 m per second.
            let t = (k as f64 * 1e9 / 90.0).ceil() as u64;
            tl.advance(&hand_at(t, k as f64 / 90.0), |h| {
                xs.push(h.unwrap().wrist.position[0])
            });
        }
        assert_eq!(xs.len(), 120, "one second of steps");
        for (i, x) in xs.iter().enumerate() {
            assert!((x - (i + 1) as f64 / 120.0).abs() < 1e-6, "step {i}: {x}");
        }
    }

    #[test]
    fn a_clock_that_jumps_decades_ahead_or_back_costs_one_step_and_is_counted() {
        let period = 1_000_000_000 / 120;
        for jump_to in [u64::MAX - 5, 2_000_000_000_000_000_000, 0] {
            let mut tl = Timeline::new(120.0);
            let mut n = 0u64;
            let start = 100_000_000_000u64;
            for k in 0..=120u64 {
                tl.advance(&hand_at(start + k * period, 0.0), |_| n += 1);
            }
            let before = n;
            tl.advance(&hand_at(jump_to, 1.0), |h| {
                n += 1;
                assert_eq!(h.unwrap().wrist.position[0], 1.0, "the hand as it is");
            });
            assert!(
                n - before <= 1,
                "{jump_to}: {} steps for the jump",
                n - before
            );
            assert_eq!(tl.jumps(), 1);
            // Time goes on at its rate after the jump.
            for k in 1..=120u64 {
                tl.advance(&hand_at(jump_to.saturating_add(k * period), 0.0), |_| {
                    n += 1
                });
            }
            if jump_to < u64::MAX - 5 {
                assert!((n - before).abs_diff(121) <= 2, "{jump_to}: {}", n - before);
            }
        }
    }

    #[test]
    fn a_ten_second_dropout_is_caught_up_on_not_a_jump() {
        let mut tl = Timeline::new(120.0);
        let mut n = 0u64;
        tl.advance(&hand_at(0, 0.0), |_| n += 1);
        tl.advance(&hand_at(MAX_CATCH_UP_NS, 0.0), |_| n += 1);
        assert_eq!((n, tl.jumps()), (1200, 0));
    }

    #[test]
    fn a_shared_frame_waits_for_every_participants_hands_and_refuses_a_number_out_of_range() {
        let person = |t: u64, participant: u32, side: u32| {
            let mut h = hand_at(t, f64::from(participant));
            h.participant = participant;
            h.side = side;
            h.finger_count = 1;
            h.finger_point_count[0] = 1;
            h
        };
        let mut frames = HandFrames::new();
        let mut given = Vec::new();
        // Participant 0's right and participant 2's left at t = 0 (a first frame: each
        // participant's hands seen so far), then the same at t = 10 ms.
        for t in [0, 10_000_000] {
            frames.push(&person(t, 0, 0), |f| given.push(*f));
            frames.push(&person(t, 2, 1), |f| given.push(*f));
        }
        // The first frame is given out on its own (only slot 0 was known), the second hand of
        // t = 0 when t = 10 ms begins; from then on a frame waits for both.
        assert_eq!(given.len(), 3);
        let last = given[2];
        assert!(
            last[0].is_some() && last[5].is_some(),
            "slots 0 and 5 in one frame"
        );
        assert_eq!(last[5].map(|h| h.stamp.source_time_ns), Some(10_000_000));
        assert!(frames.two_handed());
        // A participant number past MAX_PARTICIPANTS is refused and counted; the frame it
        // would have joined is not held up.
        let before = frames.refused_hands;
        frames.push(
            &person(20_000_000, common::MAX_PARTICIPANTS as u32, 0),
            |f| given.push(*f),
        );
        assert_eq!(frames.refused_hands, before + 1);
        assert!(frames
            .first_refused
            .is_some_and(|(_, why)| why.contains("participant")));
    }

    #[test]
    fn a_source_that_does_not_start_at_zero_starts_world_time_at_its_first_sample() {
        let mut tl = Timeline::new(100.0);
        let mut n = 0;
        tl.advance(&hand_at(5_000_000_000, 0.0), |_| n += 1);
        assert_eq!(n, 0);
        tl.advance(&hand_at(5_010_000_000, 0.0), |_| n += 1);
        assert_eq!(n, 1);
    }
}
