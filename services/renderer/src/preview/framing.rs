//! Framing the action in space: the 16:9 band of the eye's image the preview keeps, and each
//! frame's camera (one direction for all; each frame's aim and distance its own, smoothed over
//! time), holding that moment's hand and the blocks framed (step 5 of the plan).

use glam::DVec3;

use super::action::{centre_of, radius_of, Shown};
use super::store::KeptState;
use super::{HOLD_S, MIN_VIEW_M, SMOOTH_S};
use crate::camera::{centre_along, distance_along, frame_spheres, CameraSettings, Viewer};

/// The preview's aspect.
const ASPECT: f64 = 16.0 / 9.0;
/// The top of each frame kept free of the action (a fraction of its height), for the
/// overlay's box.
const OVERLAY_ROOM: f64 = 0.1;
/// The radius the framing gives a finger point or a palm vertex (metres).
const POINT_RADIUS_M: f64 = 0.01;

/// A rectangle of an image, pixels (x to the right, y down).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rect {
    pub x0: f64,
    pub y0: f64,
    pub x1: f64,
    pub y1: f64,
}

impl Rect {
    pub fn point(x: f64, y: f64) -> Rect {
        Rect {
            x0: x,
            y0: y,
            x1: x,
            y1: y,
        }
    }

    pub fn union(self, o: Rect) -> Rect {
        Rect {
            x0: self.x0.min(o.x0),
            y0: self.y0.min(o.y0),
            x1: self.x1.max(o.x1),
            y1: self.y1.max(o.y1),
        }
    }

    /// Whether the point `x, y` lies inside (edges included).
    pub fn contains(&self, x: f64, y: f64) -> bool {
        (self.x0..=self.x1).contains(&x) && (self.y0..=self.y1).contains(&y)
    }

    pub fn width(&self) -> f64 {
        self.x1 - self.x0
    }

    pub fn height(&self) -> f64 {
        self.y1 - self.y0
    }

    pub(super) fn scaled(self, k: f64) -> Rect {
        Rect {
            x0: self.x0 * k,
            y0: self.y0 * k,
            x1: self.x1 * k,
            y1: self.y1 * k,
        }
    }
}

/// The crop of the eye's image (`width` x `height`) and the camera of each frame `shown`
/// picked, for the session camera `session`.
pub(super) fn cameras(
    states: &[KeptState],
    shown: &Shown,
    radii: &[f64],
    session: &CameraSettings,
    (width, height): (u32, u32),
) -> (Rect, Vec<CameraSettings>) {
    let Shown {
        blocks,
        framed,
        chosen,
        times,
        ..
    } = shown;
    let (blocks, m) = (*blocks, chosen.len());
    let radius = |k: usize| radius_of(radii, k);

    // 5. The cameras: one direction for all, each frame's aim and distance its own.
    let band = (f64::from(width) / ASPECT).min(f64::from(height));
    let fit = (width, ((band * (1.0 - OVERLAY_ROOM)).round() as u32).max(1));
    let y0 = ((f64::from(height) - band) * 0.5 - band * OVERLAY_ROOM * 0.5).max(0.0);
    let crop = Rect {
        x0: 0.0,
        y0,
        x1: f64::from(width),
        y1: y0 + band,
    };
    let sets: Vec<Vec<(DVec3, f64)>> = chosen
        .iter()
        .map(|&i| {
            let s = &states[i];
            // A hand below the floor (a trace's resting hand) is framed where it would show.
            let mut v: Vec<(DVec3, f64)> = s
                .hand_points()
                .map(|p| (DVec3::new(p.x, p.y.max(0.0), p.z), POINT_RADIUS_M))
                .collect();
            v.extend(
                (0..blocks)
                    .filter(|&k| framed[k])
                    .map(|k| (centre_of(s, k), radius(k))),
            );
            v
        })
        .collect();
    let all: Vec<(DVec3, f64)> = sets.iter().flatten().copied().collect();
    let mono = CameraSettings {
        ipd_m: 0.0,
        ..*session
    };
    let cameras: Vec<CameraSettings> = match frame_spheres(&all, session, fit.0, fit.1) {
        None => vec![mono; m],
        Some(c) => {
            let forward = Viewer::new(&c).forward;
            let whole = DVec3::from_array(c.target);
            let aims: Vec<DVec3> = sets
                .iter()
                .map(|s| centre_along(s, forward).unwrap_or(whole))
                .collect();
            let gauss = |dt: f64, sigma: f64| (-0.5 * (dt / sigma).powi(2)).exp();
            let aims: Vec<DVec3> = (0..m)
                .map(|k| {
                    let (mut sum, mut weights) = (DVec3::ZERO, 0.0);
                    for j in 0..m {
                        let g = gauss(times[j] - times[k], SMOOTH_S);
                        sum += aims[j] * g;
                        weights += g;
                    }
                    sum / weights
                })
                .collect();
            let need: Vec<f64> = (0..m)
                .map(|k| distance_along(&sets[k], aims[k], forward, session, fit, MIN_VIEW_M))
                .collect();
            let within =
                move |k: usize| (0..m).filter(move |&j| (times[j] - times[k]).abs() <= HOLD_S);
            // At least what any frame within HOLD_S needs, so an average over as long is at
            // least what this frame needs.
            let held: Vec<f64> = (0..m)
                .map(|k| within(k).map(|j| need[j]).fold(0.0, f64::max))
                .collect();
            (0..m)
                .map(|k| {
                    let (mut sum, mut weights) = (0.0, 0.0);
                    for j in within(k) {
                        let g = gauss(times[j] - times[k], 0.5 * HOLD_S);
                        sum += held[j] * g;
                        weights += g;
                    }
                    let d = (sum / weights).max(need[k]);
                    CameraSettings {
                        eye: (aims[k] - forward * d).to_array(),
                        target: aims[k].to_array(),
                        ..mono
                    }
                })
                .collect()
        }
    };
    (crop, cameras)
}
