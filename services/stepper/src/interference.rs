//! Block against block (paper 3.3): R10 carry, R11 support (paper mode), R12 no tunnelling, and
//! R14's block-against-block tests that the free motion and floor stages make (a block sliding
//! down another's side, an R9 turn swinging into a neighbour). Every function here is handed
//! the blocks it looks at; `Carry` keeps its own queue.
//!
//! Two different notions of "interfere", both from docs/model.md:
//! - R11: touching within contact_eps counts (a block resting on another is held by it). This
//!   is parry's GJK distance, which is exact for separated convex shapes.
//! - R10: the blocks a hand-moved block *then* interferes with, i.e. that it now overlaps.
//!   Touching alone does not carry (**judgment call**): otherwise a block could never be lifted
//!   off a stack, because the block below touches it. Overlap is the SAT depth (exact for
//!   convex polyhedra and allocation-free, unlike EPA) above hull_eps, so that two faces that
//!   merely coincide are not an overlap by rounding.

use glam::{DQuat, DVec3};
use parry3d_f64::math::Pose;
use parry3d_f64::query::{self, ShapeCastOptions};

use common::BlockMode;

use crate::block_set::BlockSet;
use crate::body::{Block, Moved};
use crate::geometry::{rotate_vertices, sat_allows_motion, sat_axis, sat_depth};
use crate::grid::BlockGrid;
use crate::settings::{Passes, Settings};

/// The pair's poses with block `a`'s G as the origin (precision far from the world origin).
fn rel_poses(a: &Block, b: &Block) -> (Pose, Pose) {
    (
        Pose::from_parts(DVec3::ZERO, a.rot()),
        Pose::from_parts(b.pos() - a.pos(), b.rot()),
    )
}

/// [`sat_depth`] of the pair as they stand (b's offset from a's G): > 0 overlap, < 0 gap.
pub(crate) fn pair_depth(a: &Block, b: &Block) -> f64 {
    let off = b.pos() - a.pos();
    sat_depth(&a.poly, a.rot(), &a.rel, &b.poly, b.rot(), &b.rel, off)
}

/// [`sat_axis`] of the pair as they stand: (depth, unit axis from a to b).
pub(crate) fn pair_axis(a: &Block, b: &Block, tie: f64) -> (f64, DVec3) {
    let off = b.pos() - a.pos();
    sat_axis(&a.poly, a.rot(), &a.rel, &b.poly, b.rot(), &b.rel, off, tie)
}

/// [`sat_allows_motion`] of a moving by `d` past b as they stand.
fn pair_allows_motion(a: &Block, b: &Block, d: DVec3, eps: f64, hull_eps: f64) -> bool {
    let (off, (pa, pb)) = (b.pos() - a.pos(), (&a.poly, &b.poly));
    sat_allows_motion(
        pa,
        a.rot(),
        &a.rel,
        pb,
        b.rot(),
        &b.rel,
        off,
        d,
        eps,
        hull_eps,
    )
}

/// Whether the bounding spheres of a and b come within `margin`.
#[inline]
fn near(a: &Block, b: &Block, margin: f64) -> bool {
    (b.pos() - a.pos()).length() <= a.poly.radius + b.poly.radius + margin
}

/// Whether a, swept by `d`, and b as it stands are more than `margin` apart along a world
/// axis: their boxes (of the rotated vertices) cannot come within `margin`, so neither can
/// the blocks, and a GJK query would find them apart. Exact, and a few comparisons where GJK
/// costs hundreds: side by side in a field or a rain, the bounding spheres of neighbours
/// overlap but their boxes do not. Says false (ask GJK) if either box bounds nothing (a
/// rotation with a NaN: `Block::box_exact`).
#[inline]
pub(crate) fn boxes_apart(a: &Block, d: DVec3, b: &Block, margin: f64) -> bool {
    if !a.box_exact || !b.box_exact {
        return false;
    }
    // b relative to a's G, as the queries pose them.
    let off = b.pos() - a.pos();
    let (a_lo, a_hi) = (a.rel_lo + d.min(DVec3::ZERO), a.rel_hi + d.max(DVec3::ZERO));
    let (b_lo, b_hi) = (off + b.rel_lo, off + b.rel_hi);
    (b_lo - a_hi).max_element() > margin || (a_lo - b_hi).max_element() > margin
}

/// The slack on `boxes_apart`'s margin: well above the rounding of a box (1e-16 relative)
/// and of GJK's distance, well below any eps a scene may set.
const BOX_SLACK: f64 = 1e-9;

/// R11: a and b touch or overlap (distance <= contact_eps).
pub(crate) fn touching(a: &Block, b: &Block, eps: f64) -> bool {
    if !near(a, b, eps) || boxes_apart(a, DVec3::ZERO, b, eps + BOX_SLACK) {
        return false;
    }
    let (pa, pb) = rel_poses(a, b);
    match query::distance(&pa, &a.poly.shape, &pb, &b.poly.shape) {
        Ok(d) => d.distance <= eps,
        Err(_) => false,
    }
}

/// R10: a and b overlap by more than `tol` (SAT depth).
pub(crate) fn overlapping(a: &Block, b: &Block, tol: f64) -> bool {
    if !near(a, b, 0.0) {
        return false;
    }
    // Boxes apart: the blocks are disjoint, so SAT finds a separating axis among its (complete)
    // set and a depth below zero, not above tol (>= 0). Blocks side by side in a pushed pile
    // have overlapping spheres but boxes apart.
    if tol >= 0.0 && boxes_apart(a, DVec3::ZERO, b, BOX_SLACK) {
        return false;
    }
    pair_depth(a, b) > tol
}

/// A contact whose normal's vertical part is below this (a face within 0.57 deg of vertical) is
/// a side contact: it holds nothing up. Exactly vertical faces give |n.y| ~ 1e-17 after a
/// rotation, and a block that turned over an edge ends with its faces off vertical by the
/// bisection's and landing's leftovers (1e-5 was seen): such a face is a wall, not a slope the
/// block rests on (it would make the block beside a tower carry the tower as its load).
/// R14's supporters and its slide along sides (`slide_along_sides`) share it.
pub const SIDE_CONTACT_NY: f64 = 0.01;

/// Stage 2's R10, with its own breadth-first queue (preallocated for every block, so that a
/// step does not allocate).
#[derive(Debug)]
pub(crate) struct Carry {
    queue: Vec<usize>,
    /// The step's active blocks as the stage began: the candidates to be hand-moved roots.
    roots: BlockSet,
    /// The grid's answer for the block being carried, by index.
    near: Vec<u32>,
}

impl Carry {
    pub(crate) fn new(blocks: usize) -> Carry {
        Carry {
            queue: Vec::with_capacity(blocks),
            roots: BlockSet::new(blocks),
            near: Vec::with_capacity(blocks),
        }
    }

    /// R10: every block that a hand-moved block now overlaps (by more than `hull_eps`) is
    /// translated by the same translation (G's displacement of the hand-moved block),
    /// transitively, breadth first from each hand-moved block; each block moves at most once
    /// per step; no rotation.
    pub(crate) fn carry(
        &mut self,
        blocks: &mut [Block],
        active: &mut BlockSet,
        grid: &mut BlockGrid,
        hull_eps: f64,
    ) {
        let queue = &mut self.queue;
        // The hand moved only active blocks; the grid sees them where they are now.
        grid.sync(blocks, active);
        // A hand-moved block is active; a block it carries joins.
        self.roots.copy_from(active);
        for root in self.roots.iter() {
            if blocks[root].moved != Moved::Hand {
                continue;
            }
            let t = blocks[root].pos() - blocks[root].start_pos();
            if t == DVec3::ZERO {
                continue;
            }
            queue.clear();
            queue.push(root);
            let mut head = 0;
            while head < queue.len() {
                let i = queue[head];
                head += 1;
                // The blocks whose spheres reach i's (overlapping's own first test), by index.
                self.near.clear();
                let (pos, r) = (blocks[i].pos(), blocks[i].poly.radius);
                self.near
                    .extend_from_slice(grid.near_any_order(blocks, pos, r));
                self.near.sort_unstable();
                for &j in &self.near {
                    let j = j as usize;
                    if j == i || blocks[j].moved != Moved::No {
                        continue;
                    }
                    if overlapping(&blocks[i], &blocks[j], hull_eps) {
                        let b = &mut blocks[j];
                        b.translate(t);
                        b.moved = Moved::Carried;
                        b.mode = BlockMode::Carried;
                        active.insert(j);
                        grid.moved(j, b.pos());
                        queue.push(j);
                    }
                }
            }
        }
    }
}

/// R11 (paper mode): block i touches another block (within `contact_eps`). `near`: the
/// blocks that may (the broad phase's answer, by index: `grid::BlockGrid::near`).
pub(crate) fn touches_another(blocks: &[Block], near: &[u32], i: usize, contact_eps: f64) -> bool {
    let a = &blocks[i];
    near.iter()
        .map(|&j| j as usize)
        .any(|j| j != i && touching(a, &blocks[j], contact_eps))
}

/// R14 with R7: the part of block i's free step `d` it can take along the blocks it touches at
/// their sides. Where `d` would enter a touching block across a side contact (a contact normal
/// within 0.57 deg of horizontal, [`SIDE_CONTACT_NY`]), its component into that block is
/// removed: the block slides down the face (R14 **[resolved]**: side contacts hold nothing up,
/// so a block that turned over an edge and hangs against the face below it falls along it
/// instead of hanging in the air). Contacts from above or below are R12's to stop. Removing a
/// component never lengthens the step.
pub(crate) fn slide_along_sides(
    blocks: &[Block],
    near: &[u32],
    i: usize,
    d: DVec3,
    settings: &Settings,
) -> DVec3 {
    let a = &blocks[i];
    let eps = settings.contact_eps;
    let mut d = d;
    for (j, b) in near.iter().map(|&j| (j as usize, &blocks[j as usize])) {
        if j == i || (b.pos() - a.pos()).length() > a.poly.radius + b.poly.radius + eps {
            continue;
        }
        // The separating axis itself (no tie-break): the face the block slides along.
        let (depth, n) = pair_axis(a, b, 0.0);
        if depth < -eps || n.y.abs() >= SIDE_CONTACT_NY {
            continue;
        }
        if pair_allows_motion(a, b, d, eps, settings.hull_eps) {
            continue;
        }
        let closing = d.dot(n);
        if closing > 0.0 {
            d -= n * closing;
        }
    }
    d
}

/// R12: the fraction in [0, 1] of the step `d` block i can take before it first touches the
/// floor (when there is one) or another block: a shape cast, so no speed tunnels through.
#[allow(clippy::too_many_arguments)]
pub(crate) fn cast_fraction(
    blocks: &[Block],
    near: &[u32],
    i: usize,
    d: DVec3,
    settings: &Settings,
    passes: &Passes,
) -> f64 {
    let a = &blocks[i];
    let mut toi = 1.0f64;
    if passes.floor && d.y < 0.0 {
        // Translation only: the lowest vertex leads; exact. (Its box's floor is that vertex's
        // height when the box is exact: no pass over the vertices.)
        let lowest = if a.box_exact {
            a.rel_lo.y
        } else {
            a.lowest_rel_y()
        };
        let bottom = a.pos().y + lowest;
        toi = toi.min((bottom / -d.y).max(0.0));
    }
    if passes.blocks {
        let len = d.length();
        let opts = ShapeCastOptions {
            max_time_of_impact: 1.0,
            target_distance: 0.0,
            stop_at_penetration: false,
            compute_impact_geometry_on_penetration: false,
        };
        let mid = a.pos() + d * 0.5;
        for (j, b) in near.iter().map(|&j| (j as usize, &blocks[j as usize])) {
            if j == i {
                continue;
            }
            // Broad phase: the swept sphere against b's sphere.
            if (b.pos() - mid).length() > a.poly.radius + b.poly.radius + 0.5 * len {
                continue;
            }
            // R14 lets blocks that touch move (R11 holds them): a blocker the block already
            // touches stops it exactly when the step approaches it. The shape cast cannot
            // tell: it says time of impact 0 for a block merely sliding past another's side
            // (which would hang in the air), and may miss a touching one it moves into.
            if passes.supported && pair_depth(a, b) >= -settings.contact_eps {
                let (eps, hull_eps) = (settings.contact_eps, settings.hull_eps);
                if !pair_allows_motion(a, b, d, eps, hull_eps) {
                    toi = 0.0;
                }
                continue;
            }
            // The swept box against b's: apart, the cast cannot hit.
            if boxes_apart(a, d, b, settings.contact_eps + BOX_SLACK) {
                continue;
            }
            let (pa, pb) = rel_poses(a, b);
            if let Ok(Some(hit)) =
                query::cast_shapes(&pa, d, &a.poly.shape, &pb, DVec3::ZERO, &b.poly.shape, opts)
            {
                if hit.time_of_impact.is_finite() {
                    toi = toi.min(hit.time_of_impact.clamp(0.0, 1.0));
                }
            }
        }
    }
    toi
}

/// R14 for R9's turns on the floor: whether block i, turned from the pose (`pos`, `rot`) to
/// where it is now, entered another block deeper than it was (or than `hull_eps`). `turned` is
/// the caller's scratch for i's vertices at `rot`. The blocks it looks at are the grid's near
/// i (an "any": in no order), not every block: the grid must see every other block where it
/// is (the floor stage's pass keeps it so, `World::step`).
pub(crate) fn turn_enters_neighbour(
    blocks: &[Block],
    grid: &mut BlockGrid,
    i: usize,
    pos: DVec3,
    rot: DQuat,
    hull_eps: f64,
    turned: &mut Vec<DVec3>,
) -> bool {
    let a = &blocks[i];
    rotate_vertices(&a.poly, rot, turned);
    for &k in grid
        .near_any_order(blocks, a.pos(), a.poly.radius + hull_eps)
        .iter()
    {
        let (k, b) = (k as usize, &blocks[k as usize]);
        if k == i || (b.pos() - a.pos()).length() > a.poly.radius + b.poly.radius + hull_eps {
            continue;
        }
        let after = pair_depth(a, b);
        if after <= hull_eps {
            continue;
        }
        let before = sat_depth(
            &a.poly,
            rot,
            turned,
            &b.poly,
            b.rot(),
            &b.rel,
            b.pos() - pos,
        );
        if after > before.max(hull_eps) {
            return true;
        }
    }
    false
}

#[cfg(test)]
mod tests {
    use common::config::scene::ShapeSpec;

    use super::*;
    use crate::geometry::Polyhedron;

    /// The box test only ever skips what GJK would have found apart: over random pairs of
    /// rotated boxes and wedges close to each other, whenever `boxes_apart` says apart, the
    /// pair's distance is over eps (R11 would not touch) and the shape cast along `d` finds
    /// no impact (R12 would not cut), so skipping the query changes no result.
    #[test]
    fn boxes_apart_never_hides_a_touch_or_an_impact() {
        let mut seed = 11u64;
        let mut rnd = move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let eps = 1e-4;
        let block = |rnd: &mut dyn FnMut() -> f64, at: DVec3| {
            let size = [
                0.02 + 0.08 * rnd(),
                0.02 + 0.08 * rnd(),
                0.02 + 0.08 * rnd(),
            ];
            let spec = if rnd() < 0.5 {
                ShapeSpec::Box { size }
            } else {
                ShapeSpec::Wedge { size }
            };
            let axis = DVec3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5).normalize_or(DVec3::Y);
            let rot = if rnd() < 0.3 {
                DQuat::IDENTITY
            } else {
                DQuat::from_axis_angle(axis, rnd() * 6.3)
            };
            let poly = Polyhedron::from_spec(&spec).unwrap();
            Block::new(String::new(), poly, at, rot, DVec3::ZERO, 1)
        };
        let (mut skipped, mut checked) = (0, 0);
        for _ in 0..20_000 {
            let a = block(&mut rnd, DVec3::new(1.0, 0.5, -2.0));
            let off = DVec3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5) * 0.25;
            let b = block(&mut rnd, a.pos() + off);
            let d = DVec3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5) * 0.1;
            checked += 1;
            if boxes_apart(&a, DVec3::ZERO, &b, eps + BOX_SLACK) {
                let (pa, pb) = rel_poses(&a, &b);
                let dist = query::distance(&pa, &a.poly.shape, &pb, &b.poly.shape).unwrap();
                assert!(
                    dist.distance > eps,
                    "apart by box but {} away",
                    dist.distance
                );
            }
            if boxes_apart(&a, d, &b, eps + BOX_SLACK) {
                skipped += 1;
                let (pa, pb) = rel_poses(&a, &b);
                let opts = ShapeCastOptions {
                    max_time_of_impact: 1.0,
                    target_distance: 0.0,
                    stop_at_penetration: false,
                    compute_impact_geometry_on_penetration: false,
                };
                let hit = query::cast_shapes(
                    &pa,
                    d,
                    &a.poly.shape,
                    &pb,
                    DVec3::ZERO,
                    &b.poly.shape,
                    opts,
                )
                .unwrap();
                assert!(hit.is_none(), "apart by swept box but hit {hit:?}");
            }
        }
        // Both outcomes occur often enough for the test to mean something.
        assert!(
            skipped > 2_000 && skipped < checked - 2_000,
            "{skipped} of {checked}"
        );
    }
}
