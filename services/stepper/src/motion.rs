//! Motion without the floor: R4's one-point push (the paper's equations 1-2), R7 gravity and
//! inertia with R11's hold (R14's in supported stacking) and R12's cut, and R13's throw velocity.

use glam::DVec3;

use common::BlockMode;

use crate::body::{Block, Moved};
use crate::grid::BlockGrid;
use crate::interference::{cast_fraction, slide_along_sides, touches_another};
use crate::settings::{Passes, Settings};

/// R4's decomposition of a one-point push (the paper's Fig. 5).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PushOutcome {
    /// T = ((B - C) . u) u with u = (G - C) / |G - C|: the translation.
    pub t: DVec3,
    /// R = (B - C) - T.
    pub r: DVec3,
    /// theta = atan(|R| / |CG|).
    pub theta: f64,
    /// X = (C - G) x R, normalised: the axis through G that moves the contact point along R.
    /// None when |R| or |T| is below contact_eps (R4: skip the rotation).
    pub axis: Option<DVec3>,
}

/// R4: the check point moved to B after touching the block at C; G is the block's centre of
/// gravity (any common origin: pass them relative to G for precision). None when the finger
/// is leaving or resting ((B - C) . u <= hull_eps): nothing happens.
pub fn push_one_point(
    c: DVec3,
    b: DVec3,
    g: DVec3,
    hull_eps: f64,
    contact_eps: f64,
) -> Option<PushOutcome> {
    let cg = g - c;
    let l = cg.length();
    if l.is_nan() || l <= 0.0 {
        return None;
    }
    let u = cg / l;
    let cb = b - c;
    let along = cb.dot(u);
    if along <= hull_eps {
        return None;
    }
    let t = u * along;
    let r = cb - t;
    let rl = r.length();
    let theta = (rl / l).atan();
    let axis = if rl < contact_eps || t.length() < contact_eps {
        None
    } else {
        let x = (c - g).cross(r);
        let xl = x.length();
        (xl > 0.0).then(|| x / xl)
    };
    Some(PushOutcome { t, r, theta, axis })
}

/// Stage 4 for block i: R7 (with R12) if the hand did not move it and it is not grasped,
/// resting, tipping or in floor contact (the floor stage moves those), unless R11 holds it.
/// A block released this step (R13) waits for the next. When it moved it (`Moved::Free`):
/// where the block started the step, which the caller must record (`Block::record_start`)
/// unless it ends the block's step with it.
///
/// Called block by block in the active set's order (`World::step`); the grid must see every
/// block where it is (the last step's stage 6 left it so, and `BlockGrid::sync` after the
/// hand's and R14's moves), and each move here tells it.
#[inline]
pub(crate) fn move_freely(
    blocks: &mut [Block],
    i: usize,
    grid: &mut BlockGrid,
    settings: &Settings,
    passes: &Passes,
) -> Option<DVec3> {
    let eps = settings.contact_eps;
    {
        let b = &blocks[i];
        if b.moved != Moved::No
            || b.released
            || b.mode == BlockMode::Grasped
            || b.mode == BlockMode::Resting
        {
            return None;
        }
    }
    // R14 decided it in stage 3, or holds it asleep (supported, untouched).
    if passes.supported {
        let b = &blocks[i];
        if b.judged || b.mode == BlockMode::Supported {
            return None;
        }
    }
    // One query for all of this block's tests: R11's touch (spheres within eps of the
    // block where it stands), R14's slide (the same) and R12's cast along d (spheres within
    // |d| / 2 of the sphere at mid-step, `cast_fraction`'s own test). Without R14 the cast
    // is along d itself, and one sphere about the mid-step centre holds both: radius +
    // eps + |d| / 2 (a block within eps of the start is within that of the middle). With
    // R14 the cast is along the slid path (no longer than d, but turned), so the sphere is
    // about the start: radius + eps + |d|. Half the reach of a falling block's query on the
    // rain (|d| ~ 2 cm at p50): fewer columns and fewer candidates at its height. In no
    // order: R11's is an "any", R12's a minimum; the slide, whose result depends on the
    // order, sorts them.
    // R7: d = v + g_step (v is not changed before it is used below).
    let d = if settings.inertia {
        blocks[i].v
    } else {
        DVec3::ZERO
    } + settings.g_step;
    let near: &mut [u32] = if passes.blocks {
        let (pos, r) = (blocks[i].pos(), blocks[i].poly.radius);
        if passes.supported {
            grid.near_any_order(blocks, pos, r + eps + d.length())
        } else {
            grid.near_any_order(blocks, pos + d * 0.5, r + eps + 0.5 * d.length())
        }
    } else {
        &mut []
    };
    // R11 (paper): a block that touches another is not affected by gravity or inertia.
    if passes.blocks && !passes.supported && touches_another(blocks, near, i, eps) {
        let b = &mut blocks[i];
        b.mode = BlockMode::Supported;
        b.v = DVec3::ZERO;
        return None;
    }
    {
        let b = &mut blocks[i];
        if b.mode == BlockMode::Supported {
            b.mode = BlockMode::Free;
        }
        // In floor contact: the floor stage decides (R9's Gm = v + g_step).
        if passes.floor && b.on_floor() {
            return None;
        }
    }
    // R7: d = v + g_step; no rotation.
    if d == DVec3::ZERO {
        return None;
    }
    // R14: a block against another's side slides down along it (side contacts hold
    // nothing up). Without R14 a touching block is held by R11 and never gets here.
    let path = if passes.supported {
        near.sort_unstable();
        slide_along_sides(blocks, near, i, d, settings)
    } else {
        d
    };
    // R12: stop at the first time of impact; v is the actual displacement.
    let f = cast_fraction(blocks, near, i, path, settings, passes);
    let b = &mut blocks[i];
    // d is kept only when the step taken is not d itself (R12 cut it, R14 slid it): a block
    // falling freely does not write the line `intended` is on (`Block::free_d`).
    b.intended_kept = f != 1.0 || passes.supported;
    if b.intended_kept {
        b.intended = d;
    }
    let actual = path * f;
    let start = b.translate_unrecorded(actual);
    b.v = if settings.inertia {
        actual
    } else {
        DVec3::ZERO
    };
    b.moved = Moved::Free;
    b.mode = BlockMode::Free;
    grid.moved(i, b.pos());
    Some(start)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn r4_leaving_finger_does_nothing() {
        let g = DVec3::ZERO;
        let c = DVec3::new(-0.05, 0.0, 0.0);
        assert!(push_one_point(c, c + DVec3::new(-0.01, 0.0, 0.0), g, 1e-6, 1e-4).is_none());
        assert!(push_one_point(c, c + DVec3::new(0.0, 0.01, 0.0), g, 1e-6, 1e-4).is_none());
    }
}
