//! The floor (paper 3.2): R8 impact and R9 stability, evaluated relative to G (vertices as
//! rotation * body vertex, G' - G = t * Gm) so that far from the origin nothing changes.
//!
//! Stage 5 of `World::step` is `Floor::land_block`, with its own hull buffers; R9's [`stability`]
//! and its hull cases are shared with R14 (`support`).

use std::f64::consts::TAU;

use glam::{DQuat, DVec2, DVec3};

use common::BlockMode;

use crate::body::{Block, Moved, VertexSet};
use crate::event::{EventKind, StepEvents};
use crate::geometry::{convex_hull_2d, point_segment_2d};
use crate::grid::BlockGrid;
use crate::interference::turn_enters_neighbour;
use crate::settings::{Passes, Settings};

/// R9's verdict for a block in floor contact.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Stability {
    /// G' lies in the contact hull (boundary included, within hull_eps).
    Resting,
    /// Rotate by `theta` about the unit `axis` through the point `pivot` (relative to G).
    Tipping {
        pivot: DVec3,
        axis: DVec3,
        theta: f64,
    },
}

/// R8: lifts the block out of the floor by its deepest vertex, and returns the contact set
/// (vertices with y <= contact_eps) and the lift.
pub(crate) fn lift_and_contacts(b: &mut Block, contact_eps: f64) -> (VertexSet, f64) {
    let low = b.pos().y + b.lowest_rel_y();
    let lift = if low < 0.0 { -low } else { 0.0 };
    b.lift(lift);
    let mut set = VertexSet::EMPTY;
    for (i, v) in b.rel.iter().enumerate() {
        if b.pos().y + v.y <= contact_eps {
            set.insert(i);
        }
    }
    (set, lift)
}

/// The parameters R9 needs.
#[derive(Debug, Clone, Copy)]
pub struct R9Params {
    pub hull_eps: f64,
    pub angle_eps: f64,
}

/// R9: the stability of a block whose vertices (relative to G, world orientation) are `rel`,
/// with G at height `gy` above the floor, contact set `set` and intended displacement `gm`.
/// `hull_in`/`hull_out` are scratch buffers.
pub fn stability(
    rel: &[DVec3],
    gy: f64,
    set: &VertexSet,
    gm: DVec3,
    p: R9Params,
    hull_in: &mut Vec<DVec2>,
    hull_out: &mut Vec<DVec2>,
) -> Stability {
    // G' - G = t Gm where the ray meets the floor; straight below G without a downward part.
    let g2 = if gm.y < 0.0 {
        let t = gy / -gm.y;
        DVec2::new(t * gm.x, t * gm.z)
    } else {
        DVec2::ZERO
    };
    hull_in.clear();
    for i in set.iter().take_while(|&i| i < rel.len()) {
        hull_in.push(DVec2::new(rel[i].x, rel[i].z));
    }
    convex_hull_2d(hull_in, hull_out);
    let h = &hull_out[..];
    match in_hull(h, g2, p.hull_eps) {
        None | Some(true) => return Stability::Resting,
        Some(false) => {}
    }
    // The 3-D vertex of a hull point (its x, z were copied exactly).
    let vertex_of = |q: DVec2| -> DVec3 {
        set.iter()
            .take_while(|&i| i < rel.len())
            .map(|i| rel[i])
            .find(|v| v.x == q.x && v.z == q.y)
            .unwrap_or(DVec3::new(q.x, -gy, q.y))
    };
    let tip = tip_about_hull(h, g2, gm, vertex_of);
    let Some((pivot, axis, theta)) = tip else {
        return Stability::Resting;
    };
    // Limit: the smallest rotation about the same axis that brings a vertex not in contact
    // down to the floor (it then joins the contact set).
    let theta_c = landing_angle(rel, gy, set, pivot, axis, p.angle_eps);
    Stability::Tipping {
        pivot,
        axis,
        theta: theta.min(theta_c),
    }
}

/// Whether G' (`g2`, relative to G) lies in the hull `h` (boundary included, within
/// `hull_eps`); None for an empty hull. Shared by R9 (the floor) and R14 (a block's supporters).
pub(crate) fn in_hull(h: &[DVec2], g2: DVec2, hull_eps: f64) -> Option<bool> {
    Some(match h.len() {
        0 => return None,
        1 => (g2 - h[0]).length() <= hull_eps,
        2 => point_segment_2d(g2, h[0], h[1]).0 <= hull_eps,
        n => (0..n).all(|k| {
            let (a, b) = (h[k], h[(k + 1) % n]);
            let e = b - a;
            e.perp_dot(g2 - a) >= -hull_eps * e.length()
        }),
    })
}

/// R9's three cases for a G' outside the non-empty hull `h` (relative to G): the pivot
/// (relative to G), the unit axis and theta = atan(|R| / |CG|), before the landing limit.
/// `vertex_of` gives the 3-D contact point (relative to G) of a hull point. Shared by R9 and R14
/// (there G is the load's G_L).
pub(crate) fn tip_about_hull(
    h: &[DVec2],
    g2: DVec2,
    gm: DVec3,
    vertex_of: impl Fn(DVec2) -> DVec3,
) -> Option<(DVec3, DVec3, f64)> {
    match h.len() {
        0 => None,
        1 => case_one(vertex_of(h[0]), gm),
        2 => case_two(vertex_of(h[0]), vertex_of(h[1]), g2, gm),
        n => {
            // Case 3: the edge of H nearest to G', then case 2.
            let mut best = (f64::INFINITY, 0);
            for k in 0..n {
                let d = point_segment_2d(g2, h[k], h[(k + 1) % n]).0;
                if d < best.0 {
                    best = (d, k);
                }
            }
            let k = best.1;
            case_two(vertex_of(h[k]), vertex_of(h[(k + 1) % n]), g2, gm)
        }
    }
}

/// Case 1: one contact vertex C (relative to G). Gm = T + R with T parallel to GC; theta =
/// atan(|R| / |CG|) about X = (G - C) x R through C (moves G along R).
fn case_one(c: DVec3, gm: DVec3) -> Option<(DVec3, DVec3, f64)> {
    let l = c.length();
    if l.is_nan() || l <= 0.0 {
        return None;
    }
    let u = c / l;
    let t = u * gm.dot(u);
    let r = gm - t;
    let axis = (-c).cross(r);
    let al = axis.length();
    if al.is_nan() || al <= 0.0 {
        return None;
    }
    Some((c, axis / al, (r.length() / l).atan()))
}

/// Case 2: two contact vertices V1, V2 (relative to G); G' (relative to G, x z).
fn case_two(v1: DVec3, v2: DVec3, g2: DVec2, gm: DVec3) -> Option<(DVec3, DVec3, f64)> {
    let a = DVec2::new(v1.x, v1.z);
    let b = DVec2::new(v2.x, v2.z);
    let e2 = b - a;
    let l2 = e2.length_squared();
    let s = if l2 > 0.0 {
        (g2 - a).dot(e2) / l2
    } else {
        -1.0
    };
    if !(0.0..=1.0).contains(&s) {
        // G' outside the strip between the two perpendicular floor lines: the vertex nearer
        // to G is C, and case 1.
        let c = if v1.length() <= v2.length() { v1 } else { v2 };
        return case_one(c, gm);
    }
    let e = (v2 - v1).normalize_or_zero();
    if e == DVec3::ZERO {
        return case_one(v1, gm);
    }
    // Equation 5: remove Gm's component along V1V2; C = foot of the perpendicular from G.
    let gm2 = gm - e * gm.dot(e);
    let c = v1 - e * v1.dot(e);
    let l = c.length();
    if l.is_nan() || l <= 0.0 {
        return None;
    }
    let u = c / l;
    let r = gm2 - u * gm2.dot(u);
    let sense = (-c).cross(r).dot(e);
    if sense == 0.0 {
        return None;
    }
    let axis = if sense > 0.0 { e } else { -e };
    Some((c, axis, (r.length() / l).atan()))
}

/// The smallest positive angle about `axis` through `pivot` (relative to G; G at height `gy`)
/// at which a vertex not in `set` reaches the floor; infinity if none does within a turn.
pub(crate) fn landing_angle(
    rel: &[DVec3],
    gy: f64,
    set: &VertexSet,
    pivot: DVec3,
    axis: DVec3,
    angle_eps: f64,
) -> f64 {
    let cy = gy + pivot.y;
    let mut best = f64::INFINITY;
    for (j, v) in rel.iter().enumerate() {
        if set.contains(j) {
            continue;
        }
        let p = *v - pivot;
        let par = axis.dot(p);
        // y(phi) = K + A cos(phi) + B sin(phi) (Rodrigues' formula, y component).
        let k = cy + axis.y * par;
        let a = p.y - axis.y * par;
        let b = axis.cross(p).y;
        let m = a.hypot(b);
        if m.is_nan() || m <= 0.0 {
            continue;
        }
        let ratio = -k / m;
        if !(-1.0..=1.0).contains(&ratio) {
            continue;
        }
        let alpha = b.atan2(a);
        let delta = ratio.acos();
        for root in [alpha - delta, alpha + delta] {
            let r = root.rem_euclid(TAU);
            if r > angle_eps && r < best {
                best = r;
            }
        }
    }
    best
}

/// Whether block b is in the air: its lowest vertex above contact_eps, read off its box, which
/// is exactly `rel`'s lowest y. R8 then lifts nothing and finds no contact, and the floor stage
/// comes to [`leave_the_floor`] without a pass over the vertices: most blocks of a rain, every
/// step. False when the box bounds nothing (`Block::box_exact`): the stage's exact path decides.
#[inline]
pub(crate) fn in_the_air(b: &Block, contact_eps: f64) -> bool {
    b.box_exact && b.pos().y + b.rel_lo.y > contact_eps
}

/// The floor stage (R8, R9) of a block [`in_the_air`]: no floor contact, and a block that
/// rested or tipped (not turned by R14) is free. It reads and writes this block only, so it
/// may be done for a block as soon as the block's pose is final for the step.
#[inline]
pub(crate) fn leave_the_floor(b: &mut Block) {
    if b.on_floor() {
        b.set_floor(VertexSet::EMPTY);
    }
    if b.moved != Moved::Stacked && matches!(b.mode, BlockMode::Resting | BlockMode::Tipping) {
        b.mode = BlockMode::Free;
    }
}

/// Stage 5 (R8, R9) with its own scratch: the 2-D hull buffers of R9 and, for R14, a block's
/// vertices at the pose an R9 turn started from (preallocated for the scene's largest hull, so
/// that a step does not allocate).
#[derive(Debug)]
pub(crate) struct Floor {
    hull_in: Vec<DVec2>,
    hull_out: Vec<DVec2>,
    turned: Vec<DVec3>,
}

impl Floor {
    pub(crate) fn new(max_vertices: usize) -> Floor {
        Floor {
            hull_in: Vec::with_capacity(max_vertices + 1),
            hull_out: Vec::with_capacity(2 * max_vertices + 2),
            turned: Vec::with_capacity(max_vertices),
        }
    }

    /// Stage 5 for block i (R8 then R9), if it moved or is in floor contact and not resting;
    /// R8's impact goes to `events`. Called by the step's last pass, block by block in the
    /// active set's order, just before stage 6 settles the same block (`World::step`): a
    /// block's floor stage reads of the others only their poses (R14's check of a turn against
    /// its neighbours), which stage 6 does not change, so doing the two stages block by block
    /// is doing them one after the other, in one pass over memory instead of two.
    pub(crate) fn land_block(
        &mut self,
        blocks: &mut [Block],
        grid: &mut BlockGrid,
        i: usize,
        settings: &Settings,
        passes: &Passes,
        events: &mut StepEvents,
    ) {
        let eps = settings.contact_eps;
        let p9 = R9Params {
            hull_eps: settings.hull_eps,
            angle_eps: settings.angle_eps,
        };
        {
            let b = &blocks[i];
            // Resting and untouched: skipped entirely. Every other block is looked at, also
            // one that did not move: a block that starts on the floor has its first impact
            // on step 1, and a block R11 held may be resting on the floor.
            if b.moved == Moved::No && b.mode == BlockMode::Resting {
                return;
            }
            // R14 held it this step, or holds it asleep: R9 has nothing to add.
            if passes.supported
                && b.moved == Moved::No
                && (b.judged || b.mode == BlockMode::Supported)
            {
                return;
            }
        }
        let g_step = settings.g_step;
        let inertia = settings.inertia;
        let tipping = passes.tipping;
        let b = &mut blocks[i];
        if in_the_air(b, eps) {
            leave_the_floor(b);
            return;
        }
        let prev = *b.floor();
        let (set, _) = lift_and_contacts(b, eps);
        let by_hand = matches!(b.moved, Moved::Hand | Moved::Carried);
        if b.moved == Moved::Stacked {
            // R14 turned it (its R9): after the rotation apply R8 again, nothing more.
            let impact = set.has_new_vs(&prev);
            b.set_floor(set);
            if impact {
                events.emit(EventKind::Impact, i);
            }
            return;
        }
        if b.mode == BlockMode::Grasped || set.is_empty() {
            // R5: of the floor rules only R8's lift applies to a grasped block.
            b.set_floor(set);
            if set.is_empty() && matches!(b.mode, BlockMode::Resting | BlockMode::Tipping) {
                b.mode = BlockMode::Free;
            }
            if set.has_new_vs(&prev) {
                events.emit(EventKind::Impact, i);
            }
            return;
        }
        let mut set = set;
        let mut impact = set.has_new_vs(&prev);
        // The pose an R9 turn started from (R14 checks it against the neighbours).
        let mut turned_from = None;
        if !tipping {
            // floor = "rest": R8 only; a block on the floor stays (no rebound, no slide).
            b.v = DVec3::ZERO;
            if !by_hand {
                b.mode = BlockMode::Resting;
            }
        } else {
            // R9's Gm: after a push g_step (the hand's motion is not inertia); on the
            // landing step R7's d before R12 cut it; otherwise v + g_step.
            let gm = match b.moved {
                Moved::Hand | Moved::Carried => g_step,
                Moved::Free => b.free_d(inertia, g_step),
                _ => {
                    if inertia {
                        b.v + g_step
                    } else {
                        g_step
                    }
                }
            };
            match stability(
                &b.rel,
                b.pos().y,
                &set,
                gm,
                p9,
                &mut self.hull_in,
                &mut self.hull_out,
            ) {
                // R11 holds a block that touches another: R9 may find it resting on the
                // floor, but never tips it (it "stays where it is").
                Stability::Tipping { .. } if b.mode == BlockMode::Supported => {
                    b.v = DVec3::ZERO;
                }
                Stability::Resting => {
                    b.v = DVec3::ZERO;
                    if !by_hand {
                        b.mode = BlockMode::Resting;
                    }
                }
                Stability::Tipping { pivot, axis, theta } => {
                    let before = b.pos();
                    turned_from = Some((b.pos(), b.rot(), set));
                    b.rotate_about(DQuat::from_axis_angle(axis, theta), pivot);
                    let turned = b.pos() - before;
                    // After the rotation apply R8 again.
                    let (after, _) = lift_and_contacts(b, eps);
                    set = after;
                    impact |= set.has_new_vs(&prev);
                    b.v = if inertia { turned } else { DVec3::ZERO };
                    if b.moved == Moved::No || b.moved == Moved::Free {
                        b.moved = Moved::Tipped;
                    }
                    if !by_hand {
                        b.mode = BlockMode::Tipping;
                    }
                }
            }
        }
        // R8: on an impact the inertia is dropped; after a push, perfect friction.
        if impact || by_hand {
            b.v = DVec3::ZERO;
        }
        b.set_floor(set);
        // R14: blocks that touch are not held by R11, so an R9 turn on the floor may swing a
        // block into the neighbour it leans on. It does not turn then: it leans on it.
        if let Some((pos, rot, set)) = turned_from {
            if passes.supported
                && turn_enters_neighbour(
                    blocks,
                    grid,
                    i,
                    pos,
                    rot,
                    settings.hull_eps,
                    &mut self.turned,
                )
            {
                let b = &mut blocks[i];
                b.set_position(pos);
                b.set_rotation(rot);
                b.set_floor(set);
                b.v = DVec3::ZERO;
                if !by_hand {
                    b.mode = BlockMode::Resting;
                }
                return;
            }
        }
        if impact {
            events.emit(EventKind::Impact, i);
        }
    }
}
