//! The *anchor* (docs/model.md R9 Precision): where a world's own frame is in the scene's. Both
//! models compute in that frame, so a scene far from the scene's origin computes with numbers
//! of the size it computes with at the origin: f64 rounds a position at 99 km to 1.5e-11 m, and
//! a step's `pos + d` there lost that much every step, which a toppling stack or a tip past an
//! edge amplified to 0.2 mm under the paper model, and a contact solve to 85 mm under the
//! precise one (`push.toml` moved 99 km along x). One rule and one set of crossings for both
//! models ([`crate::World`], [`crate::PreciseWorld`]), so that they cannot disagree on where a
//! scene's frame is: poses and check points cross into the world's frame where the world takes
//! them (the scene, the hand) and out where it gives them (the `world` sample, `block(i)`).

use glam::DVec3;

use common::{HandSample, WorldHeader, MAX_FINGERS, MAX_FINGER_POINTS, MAX_PALM_VERTICES};

/// The world frame's origin for blocks at `positions` (scene frame): the middle of their box
/// in x and z, rounded to a whole multiple of [`ANCHOR_GRID_M`] (exact), and zero for every
/// scene whose middle is within [`ANCHOR_NEAR_M`] of the origin; on the floor (y = 0: the
/// floor stays the plane y = 0). A world keeps it for its life; a block's position in the
/// world frame is its scene position less the anchor, exact to the scene value's own rounding.
pub fn local_origin(positions: impl Iterator<Item = [f64; 3]>) -> DVec3 {
    let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    for p in positions {
        let p = DVec3::from_array(p);
        lo = lo.min(p);
        hi = hi.max(p);
    }
    if !(lo.is_finite() && hi.is_finite()) {
        return DVec3::ZERO;
    }
    let mid = (lo + hi) * 0.5;
    let snap = |v: f64| {
        if v.abs() < ANCHOR_NEAR_M {
            0.0
        } else {
            (v / ANCHOR_GRID_M).round() * ANCHOR_GRID_M
        }
    };
    DVec3::new(snap(mid.x), 0.0, snap(mid.z))
}

/// The anchor's grid: 1 m. A scene moved by whole metres then has the shift itself as its
/// anchor, and its blocks' positions in the world frame are the moved scene's less the shift,
/// exactly: the far run computes what the origin run of that (rounded) scene computes, bit for
/// bit. A coarser grid leaves up to half of it in every position, and positions of tens of
/// metres round a hundred times coarser than the origin run's (64 m: the far-from-origin scene
/// moved 1 km along x ended 3e-5 m from its origin run).
pub const ANCHOR_GRID_M: f64 = 1.0;

/// Within this of the origin the anchor is zero: such a scene computes as it always has.
pub const ANCHOR_NEAR_M: f64 = 32.0;

/// `p` (world frame) in the scene's frame. Not even an addition when the anchor is zero (an
/// addition of zero would turn -0.0 into 0.0).
#[inline]
pub(crate) fn to_scene(p: DVec3, anchor: DVec3) -> DVec3 {
    if anchor == DVec3::ZERO {
        p
    } else {
        p + anchor
    }
}

/// `h` moved by `by` (every point, the palm and the wrist) into `out`.
pub(crate) fn translate_hand(h: &HandSample, by: DVec3, out: &mut HandSample) {
    *out = *h;
    let shift = |p: &mut [f64; 3]| *p = (DVec3::from_array(*p) + by).to_array();
    for f in 0..(h.finger_count as usize).min(MAX_FINGERS) {
        let n = (h.finger_point_count[f] as usize).min(MAX_FINGER_POINTS);
        out.finger_points[f][..n].iter_mut().for_each(shift);
    }
    let n = (h.palm_vertex_count as usize).min(MAX_PALM_VERTICES);
    out.palm_vertices[..n].iter_mut().for_each(shift);
    shift(&mut out.wrist.position);
}

/// The header's check points (written in the world frame) moved out to the scene's: nothing
/// to do when the anchor is zero.
pub(crate) fn finger_points_to_scene(out: &mut WorldHeader, anchor: DVec3) {
    if anchor == DVec3::ZERO {
        return;
    }
    for f in 0..(out.finger_count as usize).min(MAX_FINGERS) {
        let n = (out.finger_point_count[f] as usize).min(MAX_FINGER_POINTS);
        for p in &mut out.finger_points[f][..n] {
            *p = (DVec3::from_array(*p) + anchor).to_array();
        }
    }
}
