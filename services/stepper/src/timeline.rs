//! The hand's timeline (docs/model.md, "Conventions"): on each hand sample the world takes as
//! many fixed steps as bring world time up to that sample's source time, with the hand at each
//! step interpolated between the previous and the current sample. World time never reads a
//! wall clock, so the same hand samples always give bit-identical worlds, live (the stepper
//! process, [`crate::service`]) or replayed ([`crate::simulate_samples`]): both advance this
//! one timeline.

use common::HandSample;
use glam::{DQuat, DVec3};

/// Maps a hand's source timeline onto fixed steps.
#[derive(Debug, Clone)]
pub struct Timeline {
    step_hz: f64,
    /// Source time of the first hand sample: world time 0.
    origin_ns: Option<u64>,
    previous: Option<HandSample>,
    steps_taken: u64,
    scratch: HandSample,
}

impl Timeline {
    pub fn new(step_hz: f64) -> Self {
        Timeline {
            step_hz,
            origin_ns: None,
            previous: None,
            steps_taken: 0,
            scratch: HandSample::default(),
        }
    }

    /// True once the first hand sample has set world time 0.
    pub fn started(&self) -> bool {
        self.origin_ns.is_some()
    }

    /// Source time of step `k`, in ns after world time 0: k / step_hz rounded up to a whole
    /// ns, the same grid a source at the step rate stamps its samples on, so that at equal
    /// rates each step takes its hand sample exactly, not an interpolation of it.
    fn step_time_ns(&self, k: u64) -> u64 {
        (k as f64 * 1e9 / self.step_hz).ceil() as u64
    }

    /// Fixed steps whose time is at or before `source_time_ns` (world time 0 at the first sample).
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
        let origin = *self.origin_ns.get_or_insert(hand.stamp.source_time_ns);
        let due = self.steps_due(hand.stamp.source_time_ns);
        let now = hand.stamp.source_time_ns;
        while self.steps_taken < due {
            let k = self.steps_taken + 1;
            let t_ns = origin + self.step_time_ns(k);
            match &self.previous {
                Some(prev) if prev.stamp.source_time_ns < now && t_ns < now => {
                    let span = (now - prev.stamp.source_time_ns) as f64;
                    let s = (t_ns.saturating_sub(prev.stamp.source_time_ns) as f64 / span)
                        .clamp(0.0, 1.0);
                    interpolate(prev, hand, s, &mut self.scratch);
                    step(Some(&self.scratch));
                }
                _ => step(Some(hand)),
            }
            self.steps_taken = k;
        }
        self.previous = Some(*hand);
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
    fn a_source_that_does_not_start_at_zero_starts_world_time_at_its_first_sample() {
        let mut tl = Timeline::new(100.0);
        let mut n = 0;
        tl.advance(&hand_at(5_000_000_000, 0.0), |_| n += 1);
        assert_eq!(n, 0);
        tl.advance(&hand_at(5_010_000_000, 0.0), |_| n += 1);
        assert_eq!(n, 1);
    }
}
