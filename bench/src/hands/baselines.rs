//! The throw rules of hand-tracking SDKs, written here from their stated parameters only (no
//! SDK code was read or copied), scored on the same degraded samples as the world's rules.
//!
//! Each works on the held block's path as the SDK would see it: the block attached to the
//! wrist at the grab, block pose = W(t) W(t_grab)^-1 block pose at the grab, evaluated at the
//! degraded wrist samples ([`Track`]; samples as delivered, a gap's repeated poses included:
//! to an SDK a gap looks like a hand standing still). Only samples stamped at or before the
//! release are used.
//!
//! * `ultraleap`: the mean velocity over a 50 ms window ending 20 ms before the release (the
//!   path interpolated linearly between samples at the window's ends), scaled by a factor
//!   rising linearly from 1.0 at 0.5 m/s to 1.5 at 5 m/s of that mean speed (clamped outside);
//! * `xri` (older Unity XR Interaction Toolkit): the mean of the frame-to-frame velocities of
//!   the last 20 frames (samples) within 0.25 s before the release, x1.5;
//! * `meta`: a RANSAC line fit of position against time over the last 10 samples before the
//!   release: every pair of samples is a hypothesis (45 of them: exhaustive, so no random
//!   draw), a sample is an inlier within 2 cm of the line, the hypothesis with the most
//!   inliers wins (ties: the smaller sum of inlier distances), then least squares over its
//!   inliers; grab and release by Meta's pinch hysteresis scaled to the cube ([`meta_pinch`]);
//! * `mrtk`: the object's last-frame velocity: the difference of the last two samples (by
//!   sample, not by step).
//!
//! And two references that are no baseline ([`oracle`]): least-squares fits of a straight line
//! and of a constant acceleration to the same degraded path over a window centred on the
//! release, evaluated there: what an estimator told the exact release moment could do with
//! the same samples.

use common::HandSample;
use glam::{DMat3, DQuat, DVec3};

use super::throws::{Hold, CUBE};

/// The held block's G at the degraded samples.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Track {
    /// Sample times (s), increasing.
    pub t: Vec<f64>,
    pub p: Vec<DVec3>,
}

/// The block's G in the wrist frame, from a wrist pose and G at the same moment.
pub fn g_local(wrist: (DVec3, DQuat), g: DVec3) -> DVec3 {
    wrist.1.inverse() * (g - wrist.0)
}

fn wrist_of(h: &HandSample) -> (DVec3, DQuat) {
    (
        DVec3::from_array(h.wrist.position),
        DQuat::from_array(h.wrist.rotation).normalize(),
    )
}

fn time_of(h: &HandSample) -> f64 {
    h.stamp.source_time_ns as f64 / 1e9
}

/// The block's path attached at `g_local`, at every sample stamped at or before `until` (s).
pub fn reconstruct(samples: &[HandSample], g_local: DVec3, until: f64) -> Track {
    let mut track = Track::default();
    for h in samples {
        let t = time_of(h);
        if t > until + 1e-12 {
            break;
        }
        let (w, r) = wrist_of(h);
        track.t.push(t);
        track.p.push(w + r * g_local);
    }
    track
}

impl Track {
    /// The path at time `t`, linearly between samples, held at the ends.
    pub fn at(&self, t: f64) -> Option<DVec3> {
        let n = self.t.len();
        if n == 0 {
            return None;
        }
        if t <= self.t[0] {
            return Some(self.p[0]);
        }
        if t >= self.t[n - 1] {
            return Some(self.p[n - 1]);
        }
        let j = self.t.partition_point(|&x| x <= t).clamp(1, n - 1);
        let (t0, t1) = (self.t[j - 1], self.t[j]);
        let s = if t1 > t0 { (t - t0) / (t1 - t0) } else { 1.0 };
        Some(self.p[j - 1].lerp(self.p[j], s))
    }

    /// Indices of the samples at or before `t`.
    fn upto(&self, t: f64) -> usize {
        self.t.partition_point(|&x| x <= t + 1e-12)
    }
}

/// Ultraleap's speed scale: 1.0 at 0.5 m/s rising linearly to 1.5 at 5 m/s, clamped.
pub fn ultraleap_scale(speed: f64) -> f64 {
    1.0 + 0.5 * ((speed - 0.5) / 4.5).clamp(0.0, 1.0)
}

/// `ultraleap`: the mean velocity over [t_rel - 70 ms, t_rel - 20 ms], scaled.
pub fn ultraleap(track: &Track, t_rel: f64) -> Option<DVec3> {
    let (a, b) = (t_rel - 0.070, t_rel - 0.020);
    let v = (track.at(b)? - track.at(a)?) / (b - a);
    Some(v * ultraleap_scale(v.length()))
}

/// XRI's scale.
pub const XRI_SCALE: f64 = 1.5;

/// `xri`: the mean frame velocity over the last 20 frames within 0.25 s before the release,
/// x1.5.
pub fn xri(track: &Track, t_rel: f64) -> Option<DVec3> {
    let end = track.upto(t_rel);
    let start = track.t[..end].partition_point(|&x| x < t_rel - 0.25);
    let start = start.max(end.saturating_sub(20));
    let mut sum = DVec3::ZERO;
    let mut n = 0u32;
    for j in start + 1..end {
        let dt = track.t[j] - track.t[j - 1];
        if dt > 0.0 {
            sum += (track.p[j] - track.p[j - 1]) / dt;
            n += 1;
        }
    }
    (n > 0).then(|| sum / f64::from(n) * XRI_SCALE)
}

/// `mrtk`: the last two samples' difference.
pub fn mrtk(track: &Track, t_rel: f64) -> Option<DVec3> {
    let end = track.upto(t_rel);
    if end < 2 {
        return None;
    }
    let dt = track.t[end - 1] - track.t[end - 2];
    (dt > 0.0).then(|| (track.p[end - 1] - track.p[end - 2]) / dt)
}

/// Meta's RANSAC: samples in the fit, inlier distance (m).
pub const META_SAMPLES: usize = 10;
pub const META_INLIER: f64 = 0.02;

/// Least-squares line p = a + b (t - t0) through the given samples; b.
fn line_fit(ts: &[f64], ps: &[DVec3]) -> Option<(DVec3, DVec3, f64)> {
    let n = ts.len() as f64;
    if ts.len() < 2 {
        return None;
    }
    let tm = ts.iter().sum::<f64>() / n;
    let pm = ps.iter().copied().sum::<DVec3>() / n;
    let mut stt = 0.0;
    let mut stp = DVec3::ZERO;
    for (t, p) in ts.iter().zip(ps) {
        stt += (t - tm) * (t - tm);
        stp += (*p - pm) * (t - tm);
    }
    (stt > 0.0).then(|| (pm, stp / stt, tm))
}

/// `meta`: the RANSAC line fit's slope over the last 10 samples at or before the release.
pub fn meta(track: &Track, t_rel: f64) -> Option<DVec3> {
    let end = track.upto(t_rel);
    let start = end.saturating_sub(META_SAMPLES);
    let (ts, ps) = (&track.t[start..end], &track.p[start..end]);
    let mut best: Option<(usize, f64, Vec<usize>)> = None;
    for i in 0..ts.len() {
        for j in i + 1..ts.len() {
            let dt = ts[j] - ts[i];
            if dt <= 0.0 {
                continue;
            }
            let b = (ps[j] - ps[i]) / dt;
            let mut inliers = Vec::new();
            let mut cost = 0.0;
            for k in 0..ts.len() {
                let d = (ps[k] - (ps[i] + b * (ts[k] - ts[i]))).length();
                if d <= META_INLIER {
                    inliers.push(k);
                    cost += d;
                }
            }
            let better = match &best {
                None => true,
                Some((n, c, _)) => inliers.len() > *n || (inliers.len() == *n && cost < *c),
            };
            if better {
                best = Some((inliers.len(), cost, inliers));
            }
        }
    }
    let (_, _, inliers) = best?;
    let its: Vec<f64> = inliers.iter().map(|&k| ts[k]).collect();
    let ips: Vec<DVec3> = inliers.iter().map(|&k| ps[k]).collect();
    line_fit(&its, &ips).map(|(_, b, _)| b)
}

/// The oracle references' half window (s): the fit takes the samples within this of the
/// release, on both sides.
pub const ORACLE_HALF_WINDOW: f64 = 0.05;

/// A reference, not a baseline: the velocity at `centre` of the least-squares fit of a
/// straight line (`quadratic` false) or of a constant acceleration (p(t) = p0 + v (t - c) +
/// a (t - c)^2 / 2, c = `centre`) to the held block's path attached at `g_local` at every
/// *tracked* sample stamped within `half` of `centre` (a gap's repeated poses left out). A
/// quadratic with fewer than three distinct sample times is a line; None with fewer than two.
pub fn oracle(
    samples: &[HandSample],
    g_local: DVec3,
    centre: f64,
    half: f64,
    quadratic: bool,
) -> Option<DVec3> {
    let mut ts = Vec::new();
    let mut ps = Vec::new();
    for h in samples {
        let t = time_of(h);
        if h.tracked == 0 || (t - centre).abs() > half + 1e-12 {
            continue;
        }
        let (w, r) = wrist_of(h);
        ts.push(t);
        ps.push(w + r * g_local);
    }
    let mut distinct = ts.clone();
    distinct.dedup();
    if quadratic && distinct.len() >= 3 && half > 0.0 {
        // In u = (t - centre) / half, on [-1, 1]: a well-conditioned 3 x 3 system.
        let mut m = DMat3::ZERO;
        let mut rhs = DMat3::ZERO;
        for (t, p) in ts.iter().zip(&ps) {
            let u = (t - centre) / half;
            let phi = DVec3::new(1.0, u, u * u);
            m += DMat3::from_cols(phi * phi.x, phi * phi.y, phi * phi.z);
            rhs += DMat3::from_cols(phi * p.x, phi * p.y, phi * p.z);
        }
        if m.determinant().abs() > 1e-12 {
            let c = m.inverse() * rhs;
            return Some(DVec3::new(c.x_axis.y, c.y_axis.y, c.z_axis.y) / half);
        }
    }
    (distinct.len() >= 2)
        .then(|| line_fit(&ts, &ps).map(|(_, b, _)| b))
        .flatten()
}

/// Meta's pinch, scaled to the cube: grab when the thumb-tip to index-tip distance is within
/// 2 cm of the cube's width; release when it opens 4 cm wider than the grip (the median
/// aperture over the first 100 ms of the grab, or over what of it has been seen).
pub const PINCH_GRAB_MARGIN: f64 = 0.02;
pub const PINCH_RELEASE_OPENING: f64 = 0.04;
const PINCH_GRIP_WINDOW: f64 = 0.1;

/// The thumb-tip (finger 0's last point) to index-tip (finger 1's last point) distance.
pub fn aperture(h: &HandSample) -> Option<f64> {
    let thumb = h.finger(0).last()?;
    let index = h.finger(1).last()?;
    Some((DVec3::from_array(*thumb) - DVec3::from_array(*index)).length())
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let n = s.len();
    if n == 0 {
        f64::NAN
    } else if n % 2 == 1 {
        s[n / 2]
    } else {
        (s[n / 2 - 1] + s[n / 2]) / 2.0
    }
}

/// Meta's grabs and releases on the degraded samples: (time, what, sample index).
pub fn meta_pinch(samples: &[HandSample]) -> Vec<(f64, Hold, usize)> {
    let mut out = Vec::new();
    let mut grip: Option<(f64, Vec<f64>)> = None;
    for (k, h) in samples.iter().enumerate() {
        let Some(a) = aperture(h) else { continue };
        let t = time_of(h);
        match &mut grip {
            None => {
                if a <= CUBE + PINCH_GRAB_MARGIN {
                    out.push((t, Hold::Grab, k));
                    grip = Some((t, vec![a]));
                }
            }
            Some((t0, seen)) => {
                if t - *t0 <= PINCH_GRIP_WINDOW {
                    seen.push(a);
                }
                if a > median(seen) + PINCH_RELEASE_OPENING {
                    out.push((t, Hold::Let, k));
                    grip = None;
                }
            }
        }
    }
    out
}

/// The wrist of sample `k`.
pub fn wrist_at(samples: &[HandSample], k: usize) -> Option<(DVec3, DQuat)> {
    samples.get(k).map(wrist_of)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(v: DVec3, rate: f64, n: usize) -> Track {
        let mut tr = Track::default();
        for k in 0..n {
            let t = k as f64 / rate;
            tr.t.push(t);
            tr.p.push(DVec3::new(0.1, 1.0, -0.2) + v * t);
        }
        tr
    }

    #[test]
    fn every_baseline_returns_a_constant_velocity_with_its_scale_accounted_for() {
        for rate in [30.0, 90.0, 120.0] {
            for v in [
                DVec3::new(0.3, 0.2, -0.1),
                DVec3::new(2.0, 1.0, -3.0),
                DVec3::new(0.0, 6.0, 0.0),
            ] {
                let tr = line(v, rate, 60);
                let t_rel = tr.t[50];
                let close = |a: DVec3, b: DVec3| (a - b).length() < 1e-9 * (1.0 + b.length());
                let u = ultraleap(&tr, t_rel).expect("ultraleap");
                assert!(close(u, v * ultraleap_scale(v.length())), "{rate} {v}: {u}");
                let x = xri(&tr, t_rel).expect("xri");
                assert!(close(x, v * XRI_SCALE), "{rate} {v}: {x}");
                let m = meta(&tr, t_rel).expect("meta");
                assert!(close(m, v), "{rate} {v}: {m}");
                let r = mrtk(&tr, t_rel).expect("mrtk");
                assert!(close(r, v), "{rate} {v}: {r}");
            }
        }
        assert_eq!(ultraleap_scale(0.2), 1.0);
        assert!((ultraleap_scale(2.75) - 1.25).abs() < 1e-12);
        assert_eq!(ultraleap_scale(9.0), 1.5);
    }

    #[test]
    fn meta_ransac_ignores_an_outlier() {
        let v = DVec3::new(1.0, 2.0, 0.0);
        let mut tr = line(v, 90.0, 30);
        tr.p[27] += DVec3::new(0.0, 0.05, 0.0);
        let m = meta(&tr, tr.t[29]).expect("meta");
        assert!((m - v).length() < 1e-9, "{m}");
        assert!(mrtk(&tr, tr.t[28]).is_some_and(|r| (r - v).length() > 1.0));
    }

    /// Hand samples at `rate` whose wrist moves at constant `v` under a fixed rotation;
    /// samples `lost` untracked (holding the last pose).
    fn moving_hand(v: DVec3, rate: f64, n: usize, lost: &[usize]) -> Vec<HandSample> {
        let r = DQuat::from_axis_angle(DVec3::new(1.0, 2.0, 3.0).normalize(), 0.7);
        let mut out: Vec<HandSample> = Vec::new();
        for k in 0..n {
            let t_ns = (k as f64 * 1e9 / rate).ceil() as u64;
            let t = t_ns as f64 / 1e9;
            let mut h = match (lost.contains(&k), out.last()) {
                (true, Some(last)) => HandSample {
                    tracked: 0,
                    ..*last
                },
                _ => HandSample {
                    wrist: common::Pose {
                        position: (DVec3::new(0.1, 1.0, -0.2) + v * t).to_array(),
                        rotation: r.to_array(),
                    },
                    tracked: 1,
                    ..HandSample::default()
                },
            };
            h.stamp.source_time_ns = t_ns;
            out.push(h);
        }
        out
    }

    #[test]
    fn the_oracle_returns_a_constant_velocity() {
        let v = DVec3::new(1.5, -0.4, 2.2);
        let g = DVec3::new(0.0, -0.08, 0.01);
        for rate in [30.0, 90.0, 120.0] {
            let s = moving_hand(v, rate, 60, &[]);
            let centre = time_of(&s[30]) + 0.003;
            for quadratic in [false, true] {
                let o = oracle(&s, g, centre, ORACLE_HALF_WINDOW, quadratic).expect("oracle");
                assert!(
                    (o - v).length() < 0.01 * v.length(),
                    "{rate} {quadratic}: {o}"
                );
                assert!((o - v).length() < 1e-6, "{rate} {quadratic}: {o}");
            }
        }
        // A gap's repeated poses are left out (kept, they would read a hand standing still).
        let s = moving_hand(v, 90.0, 60, &[28, 29, 30, 31]);
        let centre = time_of(&s[30]);
        for quadratic in [false, true] {
            let o = oracle(&s, g, centre, ORACLE_HALF_WINDOW, quadratic).expect("oracle");
            assert!((o - v).length() < 1e-6, "gap {quadratic}: {o}");
        }
        // Nothing tracked in the window: no velocity.
        let lost: Vec<usize> = (20..40).collect();
        let s = moving_hand(v, 90.0, 60, &lost);
        assert!(oracle(&s, g, time_of(&s[30]), ORACLE_HALF_WINDOW, true).is_none());
    }

    #[test]
    fn too_few_samples_give_no_velocity_not_a_panic() {
        let empty = Track::default();
        assert!(ultraleap(&empty, 1.0).is_none());
        assert!(xri(&empty, 1.0).is_none());
        assert!(meta(&empty, 1.0).is_none());
        assert!(mrtk(&empty, 1.0).is_none());
        let one = line(DVec3::X, 90.0, 1);
        assert!(xri(&one, 1.0).is_none() && mrtk(&one, 1.0).is_none() && meta(&one, 1.0).is_none());
    }
}
