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
//! * **T1 grip margin**: once grasped, a block stays grasped until the hand's own grip (the
//!   check points whose contacts made R3's grasp at the last firm step) opens by `grip_margin`
//!   (more than a tracker's jitter). The grip's aperture, not its points against the block: R5
//!   moves the block by the wrist, and a tracker's error in the wrist moves the block against
//!   every finger at once.
//! * **T2 tracking gap**: a hand that is not tracked touches nothing new and keeps what it holds
//!   for up to `gap_hold`; a longer gap lets go with no throw (the hand's last poses are old).
//! * **T3 fitted throw**: the released block's velocity is the least-squares straight line
//!   through its path while held, over `throw_fit_window` before the last step at which R3
//!   itself still found the grasp (the fingers leaving the block) and every tracked step from
//!   there up to the release: the velocity around the moment the fingers left it.
//!
//! Nothing here runs under `hands = "paper"`: its settings are `None` and its per-block paths
//! hold no memory.

use glam::DVec3;

use common::config::scene::{HandRules, TrackedSettings};
use common::{HandSample, MAX_FINGERS, MAX_FINGER_POINTS};

use crate::block_set::BlockSet;
use crate::body::{Block, HandAction};
use crate::hand::Contact;
use crate::HAND_SLOTS;

/// The tracked rules' numbers in steps, decided once by `World::new`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct TrackedRules {
    /// T1: how far the grip must open to let go, metres.
    pub grip_margin: f64,
    /// T1: how many steps in a row the grip must be found open to let go (at least 1).
    pub grip_open_steps: u32,
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
                grip_open_steps: ((t.grip_open_time * step_hz).round() as u32).max(1),
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

/// T3's polynomial: a straight line. `handblocks bench hands` measured a constant
/// acceleration over 0.15 s against it: the quadratic's freedom cost more in a tracker's noise
/// than it won in bias (p90 speed error 31 % against 27 % at `quest`, and 21 % against 5 % on
/// exact poses, where a window ending at the release reads the speed peak low), for a few
/// degrees of direction on curved paths (p90 12 against 15 deg at `quest`).
const FIT_DEGREE: usize = 1;

/// The most path points a held block keeps (T3), whatever the window: 8.5 s at 120 Hz.
pub const MAX_PATH_POINTS: usize = 1024;

/// The most check points T1 remembers of a grip.
pub const MAX_GRIP_POINTS: usize = 16;

/// One check point of a grip (T1): which (`finger * MAX_FINGER_POINTS + index`), where it was
/// at the last firm step, and the pseudo-normal of its contact then.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct GripPoint {
    point: u16,
    at: DVec3,
    normal: DVec3,
}

/// A held block's grip and path: T1's grip (the check points whose contacts made R3's grasp
/// at the last firm step, fixed-size), and T3's path (G at each tracked step it was held, a ring
/// buffer preallocated once per block under tracked rules) with the last step at which R3 itself
/// found the grasp.
#[derive(Debug, Clone, Default)]
pub struct GripPath {
    points: Vec<(u64, DVec3)>,
    next: usize,
    len: usize,
    /// The last step at which R3 (not T1) found the grasp, by either hand.
    pub firm_step: u64,
    /// Each hand's grip and its length (by hand slot, `crate::HAND_SLOTS`): in a two-hand
    /// grasp each hand opens its own. Allocated with the path, only under tracked rules (the
    /// only rules that read it): 7 KiB a block that a paper world does not carry.
    grip: Vec<([GripPoint; MAX_GRIP_POINTS], usize)>,
    /// Each hand's steps in a row with its grip found open (T1's `grip_open_time`).
    open_steps: [u32; HAND_SLOTS],
}

impl GripPath {
    /// A path keeping up to `capacity` points (0 under paper rules: no memory, never used).
    pub(crate) fn with_capacity(capacity: usize) -> GripPath {
        GripPath {
            points: vec![(0, DVec3::ZERO); capacity],
            next: 0,
            len: 0,
            firm_step: 0,
            grip: if capacity == 0 {
                Vec::new()
            } else {
                vec![([GripPoint::default(); MAX_GRIP_POINTS], 0); HAND_SLOTS]
            },
            open_steps: [0; HAND_SLOTS],
        }
    }

    /// T1: remembers the grip at a firm step: each check point with a contact (its first
    /// contact's pseudo-normal), where `hand` (in slot `slot`) has it (P-, where R1 found the
    /// contact). A firm step whose contacts hold no gripping pair ([`gripping_pairs`]: R3 can
    /// find its opposed normals on one finger, a tracked finger's points straddling an edge)
    /// keeps the grip before it: there is nothing in it that could open.
    pub(crate) fn record_grip(
        &mut self,
        slot: usize,
        contacts: &[Contact],
        hand: &HandSample,
        release_angle: f64,
    ) {
        let mut grip = [GripPoint::default(); MAX_GRIP_POINTS];
        let mut len = 0;
        for c in contacts {
            if len == MAX_GRIP_POINTS {
                break;
            }
            if grip[..len].iter().any(|g| g.point == c.point) {
                continue;
            }
            if let Some(at) = point_of(hand, c.point) {
                grip[len] = GripPoint {
                    point: c.point,
                    at,
                    normal: c.n,
                };
                len += 1;
            }
        }
        self.open_steps[slot] = 0;
        let Some((kept, kept_len)) = self.grip.get_mut(slot) else {
            return;
        };
        let keep_old = *kept_len > 0 && !grips(&grip[..len], release_angle);
        if !keep_old {
            *kept = grip;
            *kept_len = len;
        }
    }

    /// T1: whether the grip still holds in `hand`: its gripping pairs ([`gripping_pairs`]) still
    /// at the block (each point no farther than twice the margin outside it: `outside(p)`, how
    /// far p is outside, negative inside) are on average no more than `margin` farther apart
    /// now than at the firm step. The hand's own aperture, not its points against the block: a
    /// tracker's error in the wrist (which R5 moves the block by) moves the block against every
    /// finger at once, and would open a grip that did not open. The mean over the pairs, not
    /// any one pair: one pair's distance carries both points' noise (5 mm of it per point
    /// opened a single pair by the margin about once a throw), the mean of many does not. The
    /// distance to the block for a grip whose points cannot open (a block held between the
    /// thumb's base and the knuckles) when the hand leaves it (presses it into the floor).
    pub(crate) fn grip_holds(
        &self,
        slot: usize,
        hand: &HandSample,
        release_angle: f64,
        margin: f64,
        outside: impl Fn(DVec3) -> f64,
    ) -> bool {
        let Some((grip, len)) = self.grip.get(slot) else {
            return false;
        };
        let grip = &grip[..*len];
        if !grips(grip, release_angle) {
            return false;
        }
        let near = |g: &GripPoint| point_of(hand, g.point).filter(|&p| outside(p) <= 2.0 * margin);
        let (mut opened, mut n) = (0.0, 0u32);
        for (a, b) in thumb_pairs(grip) {
            if let (Some(pa), Some(pb)) = (near(a), near(b)) {
                opened += (pa - pb).length() - (a.at - b.at).length();
                n += 1;
            }
        }
        n > 0 && opened <= margin * f64::from(n)
    }

    /// T1 at a step R3 does not confirm the grasp: whether the hand in `slot` still holds it.
    /// It lets go once [`GripPath::grip_holds`] has found the grip open at `open_steps` steps
    /// in a row.
    pub(crate) fn still_held(&mut self, slot: usize, grip_holds: bool, open_steps: u32) -> bool {
        if grip_holds {
            self.open_steps[slot] = 0;
            return true;
        }
        self.open_steps[slot] = self.open_steps[slot].saturating_add(1);
        if self.open_steps[slot] < open_steps {
            return true;
        }
        // It lets go: nothing of this hand is opening any more.
        self.open_steps[slot] = 0;
        false
    }

    /// Whether a hand's grip is being found open (T1's `grip_open_time` still running): the
    /// fingers have left the block, so its path while they have is no part of the throw (T3).
    pub(crate) fn opening(&self) -> bool {
        self.open_steps.iter().any(|&n| n > 0)
    }

    /// A new grasp starts a new path.
    pub(crate) fn clear(&mut self) {
        self.next = 0;
        self.len = 0;
        self.open_steps = [0; HAND_SLOTS];
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

    /// T3: the velocity (m/s) the block leaves with when released at step `now`: the line
    /// ([`fit_velocity_of_degree`], [`FIT_DEGREE`]) through the kept points from one window
    /// before the evaluation step on, evaluated at the evaluation step (the last firm step, no more than a window before
    /// `now`); with fewer than two points in that span (a tracking gap took them), the fit of
    /// every point kept. None with fewer than two points in all (then the caller throws
    /// nothing: v = 0).
    pub(crate) fn throw_velocity(&self, now: u64, rules: &TrackedRules) -> Option<DVec3> {
        let w = rules.fit_window_steps;
        let at = self.firm_step.clamp(now.saturating_sub(w), now);
        let from = at.saturating_sub(w);
        let origin = self.iter().last()?.1;
        let fit = |from: u64| {
            fit_velocity_of_degree(
                self.iter()
                    .filter(|(s, _)| (from..=now).contains(s))
                    .map(|(s, p)| ((s as f64 - at as f64) * rules.dt, p - origin)),
                FIT_DEGREE,
            )
        };
        // Too few tracked points in the window (a gap took them): every point kept.
        fit(from).or_else(|| fit(0))
    }
}

/// T1's pairs of a grip: each of the thumb's check points (finger 0, in every hand a source
/// makes) against each other finger's. A hand opens by parting its thumb from its fingers; two
/// points of one finger never part, nor do two fingers side by side, yet a tracked finger's
/// noise can oppose their normals (R3 then finds a grasp in them), and a grip measured on such
/// pairs would never let go.
fn thumb_pairs(grip: &[GripPoint]) -> impl Iterator<Item = (&GripPoint, &GripPoint)> + '_ {
    let thumb = |g: &GripPoint| (g.point as usize) < MAX_FINGER_POINTS;
    grip.iter()
        .filter(move |a| thumb(a))
        .flat_map(move |a| grip.iter().filter(move |b| !thumb(b)).map(move |b| (a, b)))
}

/// Whether a grip grips: some thumb pair ([`thumb_pairs`]) whose contacts' pseudo-normals
/// opened wider than `release_angle` (R3's own test, on the thumb against a finger).
fn grips(grip: &[GripPoint], release_angle: f64) -> bool {
    let opposed = release_angle.cos();
    thumb_pairs(grip).any(|(a, b)| a.normal.dot(b.normal) < opposed)
}

/// Check point `point` (`finger * MAX_FINGER_POINTS + index`) of `hand`, when it has it.
fn point_of(hand: &HandSample, point: u16) -> Option<DVec3> {
    let (f, k) = (
        point as usize / MAX_FINGER_POINTS,
        point as usize % MAX_FINGER_POINTS,
    );
    (f < (hand.finger_count as usize).min(MAX_FINGERS) && k < hand.finger_point_count[f] as usize)
        .then(|| DVec3::from_array(hand.finger_points[f][k]))
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
    fit_velocity_of_degree(points, 2)
}

/// [`fit_velocity`] with a polynomial of `degree` (1 to 3) in place of the quadratic, falling
/// back to lower degrees where the points do not determine it (fewer than degree + 2 points,
/// or too few distinct times).
pub fn fit_velocity_of_degree(
    points: impl Iterator<Item = (f64, DVec3)>,
    degree: usize,
) -> Option<DVec3> {
    const K: usize = 4;
    // Normal equations for the basis (1, x, x^2, x^3), x = u / SCALE: the sums of x^k
    // (k = 0..6) and of p x^k (k = 0..3).
    let mut sums = [0.0f64; 2 * K - 1];
    let mut rhs = [DVec3::ZERO; K];
    let (mut u_lo, mut u_hi) = (f64::INFINITY, f64::NEG_INFINITY);
    // Times are scaled by 0.1 s (windows are tens to hundreds of milliseconds), which keeps
    // the powers near 1.
    const SCALE: f64 = 0.1;
    for (u, p) in points {
        let x = u / SCALE;
        let mut xk = 1.0;
        for (k, sk) in sums.iter_mut().enumerate() {
            *sk += xk;
            if k < K {
                rhs[k] += p * xk;
            }
            xk *= x;
        }
        u_lo = u_lo.min(u);
        u_hi = u_hi.max(u);
    }
    let n = sums[0];
    if n < 2.0 || u_hi - u_lo <= 0.0 {
        return None;
    }
    let mut degree = degree.clamp(1, K - 1);
    while degree >= 1 {
        if n >= (degree + 2) as f64 || degree == 1 {
            let m = degree + 1;
            if let Some(v) = solve_slope(&sums, &rhs, m) {
                return Some(v / SCALE);
            }
        }
        degree -= 1;
    }
    None
}

/// The coefficient of x^1 in the least-squares polynomial with `m` coefficients, from the
/// normal equations' sums (Gaussian elimination with partial pivoting, per axis at once);
/// None when the system is singular (the points crowd onto fewer times than coefficients).
fn solve_slope(sums: &[f64], rhs: &[DVec3], m: usize) -> Option<DVec3> {
    let mut a = [[0.0f64; 4]; 4];
    let mut b = [DVec3::ZERO; 4];
    for (i, row) in a.iter_mut().enumerate().take(m) {
        row[..m].copy_from_slice(&sums[i..i + m]);
        b[i] = rhs[i];
    }
    let scale = (0..m).map(|i| a[i][i].abs()).fold(0.0, f64::max);
    for col in 0..m {
        let pivot = (col..m).max_by(|&x, &y| a[x][col].abs().total_cmp(&a[y][col].abs()))?;
        if a[pivot][col].abs() <= 1e-12 * scale {
            return None;
        }
        a.swap(col, pivot);
        b.swap(col, pivot);
        for row in 0..m {
            if row != col {
                let f = a[row][col] / a[col][col];
                let pivot_row = a[col];
                for (x, p) in a[row][col..m].iter_mut().zip(&pivot_row[col..m]) {
                    *x -= f * p;
                }
                b[row] -= b[col] * f;
            }
        }
    }
    Some(b[1] / a[1][1])
}

/// T2: a step of a tracking gap no longer than gap_hold. Every block the hand holds keeps its
/// grasp (stage 2 moves it with the wrist, which holds still or catches up at the gap's end);
/// no other block gets a hand action. Whether the hand holds any; `gap_starts` counts the gap
/// once, at its first step.
pub(crate) fn hold_grasps(
    blocks: &mut [Block],
    active: &BlockSet,
    slot: usize,
    gap_starts: bool,
    counts: &mut TrackedCounts,
) -> bool {
    let mut held = false;
    // A grasped block is never at rest: it is in `active`.
    for i in active.iter() {
        let b = &mut blocks[i];
        if b.grasped_by(slot) {
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
            grip_open_steps: 1,
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
    fn t3_a_cubic_fit_follows_a_changing_acceleration_and_falls_back_when_undetermined() {
        let (v0, a, j) = (
            DVec3::new(3.0, -1.0, 0.5),
            DVec3::new(5.0, 2.0, 0.0),
            DVec3::splat(-40.0),
        );
        let path = |u: f64| v0 * u + a * u * u * 0.5 + j * u * u * u / 6.0;
        let pts: Vec<(f64, DVec3)> = (-20..=4)
            .map(|k| (k as f64 / 120.0, path(k as f64 / 120.0)))
            .collect();
        let v = fit_velocity_of_degree(pts.iter().copied(), 3).unwrap();
        assert!((v - v0).length() < 1e-8, "{v}");
        // Four points: a cubic needs five for a least-squares fit here; the quadratic is used.
        let v = fit_velocity_of_degree(pts[..4].iter().copied(), 3).unwrap();
        assert!(v.is_finite());
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
