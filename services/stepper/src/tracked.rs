//! docs/model.md "Tracked hands": the rules T1-T3 that `[world] hands = "tracked"` adds to the
//! paper's, for hands a tracker measures (a headset, a webcam, a recorded trace) rather than a
//! glove on a still tracker.
//!
//! The paper re-decides R3 from scratch every step and throws with one step's displacement
//! (R13). A tracked finger jitters by millimetres across the face it rests on, so R3 flickers
//! (a real lift grasped and dropped its cube three times in 330 ms), and one difference of two
//! noisy poses is the noisiest velocity there is. These rules keep the paper's contact model
//! (R1-R2) and its grasp test (R3) and add, each with one number:
//!
//! * **T1 grip margin**: once grasped, a block stays grasped while R3's test still passes when
//!   check points up to `grip_margin` outside the block count as touching it. A grip must open
//!   by the margin (more than a tracker's jitter) to let go.
//! * **T2 tracking gap**: a hand that is not tracked touches nothing new and keeps what it holds
//!   for up to `gap_hold`; a longer gap lets go with no throw (the hand's last poses are old).
//! * **T3 fitted throw**: the released block's velocity is a least-squares fit of its path
//!   while held (constant acceleration, [`fit_velocity`]) over `throw_fit_window` before the
//!   last step at which R3 itself still found the grasp (the fingers leaving the block), and
//!   evaluated there, using every tracked step up to the release.
//!
//! Nothing here runs under `hands = "paper"`: its settings are `None` and its per-block paths
//! hold no memory.

use glam::DVec3;

use common::config::scene::{HandRules, TrackedSettings};
use common::BlockMode;

use crate::block_set::BlockSet;
use crate::body::{Block, HandAction};

/// The tracked rules' numbers in steps, decided once by `World::new`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct TrackedRules {
    /// T1, metres.
    pub grip_margin: f64,
    /// T2: the most consecutive untracked steps a hand keeps its grasps through.
    pub gap_hold_steps: u64,
    /// T3: the fit's window before the evaluation step, in steps.
    pub fit_window_steps: u64,
    /// dt, seconds.
    pub dt: f64,
}

impl TrackedRules {
    /// The scene's tracked rules at `step_hz`; None under `hands = "paper"`.
    pub(crate) fn of(hands: HandRules, t: &TrackedSettings, step_hz: f64) -> Option<TrackedRules> {
        match hands {
            HandRules::Paper => None,
            HandRules::Tracked => Some(TrackedRules {
                grip_margin: t.grip_margin,
                gap_hold_steps: (t.gap_hold * step_hz).round() as u64,
                fit_window_steps: ((t.throw_fit_window * step_hz).round() as u64).max(1),
                dt: 1.0 / step_hz,
            }),
        }
    }

    /// How many path points a held block keeps: the window before the evaluation step and as
    /// many after it (T3 evaluates at most one window back from the release).
    pub(crate) fn path_capacity(&self) -> usize {
        (2 * self.fit_window_steps as usize + 2).min(MAX_PATH_POINTS)
    }
}

/// The most path points a held block keeps (T3), whatever the window: 8.5 s at 120 Hz.
pub const MAX_PATH_POINTS: usize = 1024;

/// A held block's path for T3: G at each tracked step it was held (a ring buffer, preallocated
/// once per block under tracked rules), and the last step at which R3 itself found the grasp.
#[derive(Debug, Clone, Default)]
pub struct GripPath {
    points: Vec<(u64, DVec3)>,
    next: usize,
    len: usize,
    /// The last step at which R3 (not T1's margin) found the grasp.
    pub firm_step: u64,
}

impl GripPath {
    /// A path keeping up to `capacity` points (0 under paper rules: no memory, never used).
    pub(crate) fn with_capacity(capacity: usize) -> GripPath {
        GripPath {
            points: vec![(0, DVec3::ZERO); capacity],
            next: 0,
            len: 0,
            firm_step: 0,
        }
    }

    /// A new grasp starts a new path.
    pub(crate) fn clear(&mut self) {
        self.next = 0;
        self.len = 0;
    }

    /// G at a tracked step of the grasp.
    pub(crate) fn push(&mut self, step: u64, pos: DVec3) {
        let cap = self.points.len();
        if cap == 0 {
            return;
        }
        self.points[self.next] = (step, pos);
        self.next = (self.next + 1) % cap;
        self.len = (self.len + 1).min(cap);
    }

    /// The points kept, oldest first.
    fn iter(&self) -> impl Iterator<Item = (u64, DVec3)> + '_ {
        let cap = self.points.len();
        let start = (self.next + cap - self.len) % cap.max(1);
        (0..self.len).map(move |k| self.points[(start + k) % cap])
    }

    /// T3: the velocity (m/s) the block leaves with when released at step `now`: the fit of
    /// [`fit_velocity`] over the kept points from one window before the evaluation step on,
    /// evaluated at the evaluation step (the last firm step, no more than a window before
    /// `now`). None when fewer than two points fall in that span (then the caller throws as
    /// R13 does).
    pub(crate) fn throw_velocity(&self, now: u64, rules: &TrackedRules) -> Option<DVec3> {
        let w = rules.fit_window_steps;
        let at = self.firm_step.clamp(now.saturating_sub(w), now);
        let from = at.saturating_sub(w);
        let origin = self.iter().last()?.1;
        fit_velocity(
            self.iter()
                .filter(|(s, _)| (from..=now).contains(s))
                .map(|(s, p)| ((s as f64 - at as f64) * rules.dt, p - origin)),
        )
    }
}

/// The velocity at u = 0 of the least-squares fit of positions `p` at times `u` (seconds,
/// relative to the time wanted): constant acceleration, p(u) = p0 + v u + a u^2 / 2, with four
/// points or more spanning three distinct times; a straight line (constant velocity) with two
/// or three; None with fewer.
///
/// Why this fit: a thrown hand accelerates up to the release, so a mean of differences over a
/// window (a straight line) reads the velocity of the window's middle, late by half the window
/// and low by the acceleration times that; a quadratic follows the acceleration and, evaluated
/// where the fingers left the block, uses the points on both sides of it. Least squares
/// averages the tracker's white noise over every point in the window instead of differencing
/// two of them. Points should be relative to one of them (the caller's `origin`), so that the
/// sums stay small far from the world's origin.
pub fn fit_velocity(points: impl Iterator<Item = (f64, DVec3)>) -> Option<DVec3> {
    // Normal equations for the basis (1, u, u^2): the sums of u^k (k = 0..4) and of p u^k.
    let mut s = [0.0f64; 5];
    let mut t = [DVec3::ZERO; 3];
    let (mut u_lo, mut u_hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for (u, p) in points {
        let mut uk = 1.0;
        for (k, sk) in s.iter_mut().enumerate() {
            *sk += uk;
            if k < 3 {
                t[k] += p * uk;
            }
            uk *= u;
        }
        u_lo = u_lo.min(u);
        u_hi = u_hi.max(u);
    }
    let n = s[0];
    if n < 2.0 || u_hi - u_lo <= 0.0 {
        return None;
    }
    // Quadratic: solve [[s0 s1 s2] [s1 s2 s3] [s2 s3 s4]] x = t by Cramer's rule for the
    // middle coefficient (v), per axis.
    if n >= 4.0 {
        let det3 = |m: [[f64; 3]; 3]| {
            m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
                - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
                + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
        };
        let m = [[s[0], s[1], s[2]], [s[1], s[2], s[3]], [s[2], s[3], s[4]]];
        let d = det3(m);
        // A well-spread window's determinant is of the order of n^3 (span/2)^6 / 180; far
        // below that the points crowd onto two times and the quadratic is not determined.
        let span = u_hi - u_lo;
        if d.abs() > 1e-9 * n * n * n * span.powi(6) {
            let axis = |a: usize| {
                let ta = [t[0][a], t[1][a], t[2][a]];
                let mv = [
                    [m[0][0], ta[0], m[0][2]],
                    [m[1][0], ta[1], m[1][2]],
                    [m[2][0], ta[2], m[2][2]],
                ];
                det3(mv) / d
            };
            return Some(DVec3::new(axis(0), axis(1), axis(2)));
        }
    }
    // Straight line: v = cov(u, p) / var(u).
    let mean_u = s[1] / n;
    let var = s[2] - n * mean_u * mean_u;
    if var <= 0.0 {
        return None;
    }
    Some((t[1] - t[0] * mean_u) / var)
}

/// T2: a step of a tracking gap no longer than gap_hold. Every block the hand holds keeps its
/// grasp (stage 2 moves it with the wrist, which holds still or catches up at the gap's end);
/// no other block gets a hand action. Whether the hand holds any; `gap_starts` counts the gap
/// once, at its first step.
pub(crate) fn hold_grasps(
    blocks: &mut [Block],
    active: &BlockSet,
    gap_starts: bool,
    counts: &mut TrackedCounts,
) -> bool {
    let mut held = false;
    // A grasped block is never at rest: it is in `active`.
    for i in active.iter() {
        let b = &mut blocks[i];
        if b.mode == BlockMode::Grasped {
            b.set_action(HandAction::Grasp);
            held = true;
        }
    }
    counts.gaps_held += u64::from(held && gap_starts);
    held
}

/// What the tracked rules did (counts for reports and tests).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TrackedCounts {
    /// Steps at which a grasp held only by T1's margin (R3 alone would have let go).
    pub grip_held_steps: u64,
    /// Tracking gaps a hand kept its grasp through (T2), counted once each.
    pub gaps_held: u64,
    /// Grasps ended because a gap outlasted `gap_hold` (T2): dropped with no throw.
    pub gap_releases: u64,
    /// Throws whose velocity came from T3's fit (the rest had too few tracked points and
    /// threw as R13).
    pub fitted_throws: u64,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rules(window_steps: u64) -> TrackedRules {
        TrackedRules {
            grip_margin: 0.02,
            gap_hold_steps: 30,
            fit_window_steps: window_steps,
            dt: 1.0 / 120.0,
        }
    }

    #[test]
    fn t3_a_constant_acceleration_is_fitted_exactly() {
        let (v0, a) = (DVec3::new(1.0, 2.0, -0.5), DVec3::new(20.0, -9.81, 3.0));
        let pts: Vec<(f64, DVec3)> = (-18..=3)
            .map(|k| {
                let u = k as f64 / 120.0;
                (u, v0 * u + a * u * u * 0.5)
            })
            .collect();
        let v = fit_velocity(pts.iter().copied()).unwrap();
        assert!((v - v0).length() < 1e-9, "{v} vs {v0}");
    }

    #[test]
    fn t3_two_or_three_points_fit_a_line_and_one_is_none() {
        let p = |u: f64| (u, DVec3::new(2.0 * u, 0.0, 0.0));
        assert_eq!(fit_velocity([p(0.0)].into_iter()), None);
        let v = fit_velocity([p(-0.01), p(0.0)].into_iter()).unwrap();
        assert!((v.x - 2.0).abs() < 1e-12);
        let v = fit_velocity([p(-0.02), p(-0.01), p(0.0)].into_iter()).unwrap();
        assert!((v.x - 2.0).abs() < 1e-12);
        // Four points on two times: no quadratic, the line.
        let v = fit_velocity([p(-0.01), p(-0.01), p(0.0), p(0.0)].into_iter()).unwrap();
        assert!((v.x - 2.0).abs() < 1e-9);
    }

    #[test]
    fn t3_the_path_is_evaluated_at_the_last_firm_step() {
        let r = rules(12);
        let mut path = GripPath::with_capacity(r.path_capacity());
        // Constant velocity 3 m/s up to step 100, then the hand stops dead.
        for s in 50..=110u64 {
            let x = 3.0 * (s.min(100) as f64) / 120.0;
            path.push(s, DVec3::new(x, 0.0, 0.0));
        }
        path.firm_step = 100;
        // Evaluated at step 100 from the window before it and the points after it: the
        // velocity the hand had where the grip left, not the stop after it.
        // velocity the hand had about where the grip left (a quadratic through a kink reads
        // half of it there), not the stop after it (0).
        let v = path.throw_velocity(110, &r).unwrap();
        assert!(v.x > 1.2 && v.x < 3.5, "{v}");
        // Evaluated before the kink, exact.
        path.firm_step = 95;
        let v = path.throw_velocity(98, &r).unwrap();
        assert!((v.x - 3.0).abs() < 1e-9, "{v}");
        // A firm step far in the past is clamped to a window before the release: the stop.
        path.firm_step = 10;
        let v = path.throw_velocity(130, &r).unwrap();
        assert!(v.x.abs() < 1e-9, "{v}");
    }

    #[test]
    fn t3_the_ring_keeps_the_newest_points() {
        let mut path = GripPath::with_capacity(4);
        for s in 0..10u64 {
            path.push(s, DVec3::splat(s as f64));
        }
        let kept: Vec<u64> = path.iter().map(|(s, _)| s).collect();
        assert_eq!(kept, vec![6, 7, 8, 9]);
        path.clear();
        assert_eq!(path.iter().count(), 0);
        let mut none = GripPath::with_capacity(0);
        none.push(1, DVec3::ONE);
        assert_eq!(none.iter().count(), 0);
    }
}
