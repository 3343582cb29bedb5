//! R14 supported stacking [extension] (docs/model.md): with `stacking = "supported"` a block stands on
//! the blocks below it as on a floor, and a stack holds exactly when statics says it does.
//!
//! The stage runs before free motion (stage 3 of "Order of one step") and decides every block
//! that rests on another block or carries one:
//! 1. **Who is looked at.** Resting and supported blocks sleep: they cost nothing unless
//!    something stirred them: the hand moved a block near them, a block near them moved or
//!    changed mode in the previous step ("a block whose supporter moved is judged again in the
//!    next step", a block landing on their load). Waking floods through the sleeping blocks that
//!    touch (bounding spheres within contact_eps), so a whole stack is judged again when its top
//!    is touched: the top's weight is part of every load below it.
//! 2. **Supporters.** A touching pair (SAT depth >= -contact_eps) supports upward: the SAT axis
//!    of least overlap is the pair's contact normal, and the lower block supports the upper one
//!    when that normal has an upward component (docs/model.md's "at points below its G", read as
//!    "under it": side contacts between neighbours hold nothing up and make no cycles; a touch
//!    along an edge only, whose normal is ambiguous, is a side contact). The
//!    contact points are the pair's manifold ([`contact_points`]): vertices of either within
//!    contact_eps of the other, and edge-plane crossings (a box turned 45 deg on another).
//! 3. **Judged bottom up** (a block after its supporters; ties and cycles by index). For block b,
//!    S = b and its load (everything resting on b, transitively, not blocks the hand holds).
//!    The support set H of S is the 2-D hull of the contact points through which S rests on
//!    what is not in S: the supporters' contact points and the floor contacts of S's blocks.
//!    For a simple stack that is b's interface with its supporter, as docs/model.md says; for a block
//!    resting on two (a pyramid, a bridge) it also counts the other supports of b's load, since
//!    the load does not rest on b alone (**[resolved]**: otherwise a pyramid's corner block would
//!    carry half the pyramid on its own footprint and tip). G_L = the volume-weighted centre of S.
//! 4. **Verdict.** G_L's vertical projection in H (within hull_eps): b is `supported` (or
//!    `resting` when only the floor holds it), v = 0, nothing moves. Otherwise S tips rigidly by
//!    R9's cases with G_L for G and Gm = g_step, about H's vertex or edge nearest G_L; the turn is
//!    limited as R9 limits it, by the first vertex of S that reaches the floor, and by the first
//!    contact with a block outside S (bisection on the SAT depth). A turn that cannot start
//!    without entering another block releases b as `free` (R7, R12 then decide).
//!
//! While a load tips over a block's edge, and while it still leans on the block it tipped over,
//! its weight rests on that edge, not on the block as a load (**[resolved]**): that block leaves
//! it out of its own G_L (`Block::tipped_over`), so a stack toppling off a base, or lying
//! across its edge afterwards, does not drag the base along.
//!
//! A tipping block that loses contact with its supporters (its contact normal turns sideways)
//! has no supporter in the next step and is free: R7 moves it, R12 stops it, R8/R9 land it.
//! Since blocks that touch are no longer held (R11), two more rules keep them apart
//! (**[resolved]**): a free block against another's side slides down along that face rather
//! than hanging where R12's cast would stop it (`interference::slide_along_sides`; a touching
//! blocker stops a step only if no separating axis stays separated, `sat_allows_motion`), and
//! an R9 turn on the floor that would swing a block into the neighbour it leans on is not taken
//! (`interference::turn_enters_neighbour`).

use glam::{DQuat, DVec2, DVec3};

use common::BlockMode;

use crate::block_set::BlockSet;
use crate::body::{Block, Moved};
use crate::floor::{in_hull, landing_angle, tip_about_hull};
use crate::geometry::{contact_points, convex_hull_2d, rotate_vertices, sat_depth};
use crate::interference::{pair_axis, SIDE_CONTACT_NY};
use crate::settings::{Passes, Settings};

/// Contact points kept per touching pair (a box on a box needs 16 at most).
pub const MAX_PAIR_POINTS: usize = 64;

/// Halvings of the turn when S would enter a block outside it: 2^-40 of a step's turn.
const BISECTIONS: u32 = 40;

/// One support found this step: `lower` holds `upper` up through `points[start..end]`
/// (relative to upper's G, world orientation).
#[derive(Debug, Clone, Copy)]
pub(crate) struct SupportEdge {
    lower: usize,
    upper: usize,
    start: usize,
    end: usize,
}

/// Stage 3 (R14) with its own scratch, preallocated in `World::new` so that a step does not
/// allocate.
#[derive(Debug)]
pub(crate) struct Support {
    /// Per block: the blocks supporting it, and those it supports. Only the rows of `edges`
    /// are ever non-empty, so only those are cleared.
    below: Vec<BlockSet>,
    above: Vec<BlockSet>,
    flood: Flood,
    loads: Loads,
    edges: Vec<SupportEdge>,
    points: Vec<DVec3>,
    /// The contact points of the cut under S, relative to G_L.
    cut: Vec<DVec3>,
    hull_in: Vec<DVec2>,
    hull_out: Vec<DVec2>,
    /// A block's vertices turned by a trial rotation.
    turned: Vec<DVec3>,
}

/// The step's block sets: what sleeps, what is awake, what the hand moved, what woke, and the
/// bottom-up order's pending and ready ones.
#[derive(Debug, Default)]
struct Flood {
    sleeping: BlockSet,
    awake: BlockSet,
    stir: BlockSet,
    fixed: BlockSet,
    woken: BlockSet,
    queue: BlockSet,
    cand: BlockSet,
    pending: BlockSet,
    ready: BlockSet,
}

/// One judged block's sets: its load, the load's frontier, S (the block and its load) and the
/// blocks S rests on.
#[derive(Debug, Default)]
struct Loads {
    load: BlockSet,
    front: BlockSet,
    s_mask: BlockSet,
    under: BlockSet,
    /// Blocks moved with a load this step.
    touched: BlockSet,
}

impl Support {
    pub(crate) fn new(blocks: usize, max_vertices: usize) -> Support {
        let edges = 8 * blocks + 16;
        let points = 24 * edges;
        let set = || BlockSet::new(blocks);
        Support {
            below: (0..blocks).map(|_| set()).collect(),
            above: (0..blocks).map(|_| set()).collect(),
            flood: Flood {
                sleeping: set(),
                awake: set(),
                stir: set(),
                fixed: set(),
                woken: set(),
                queue: set(),
                cand: set(),
                pending: set(),
                ready: set(),
            },
            loads: Loads {
                load: set(),
                front: set(),
                s_mask: set(),
                under: set(),
                touched: set(),
            },
            edges: Vec::with_capacity(edges),
            points: Vec::with_capacity(points),
            cut: Vec::with_capacity(points),
            hull_in: Vec::with_capacity(points),
            hull_out: Vec::with_capacity(2 * points + 2),
            turned: Vec::with_capacity(max_vertices),
        }
    }
}

/// Whether the bounding spheres of a and b come within `margin`.
#[inline]
fn near(a: &Block, b: &Block, margin: f64) -> bool {
    (b.pos() - a.pos()).length() <= a.poly.radius + b.poly.radius + margin
}

impl Support {
    /// Stage 3 (R14): finds supporters, judges bottom up, holds or tips each block with its
    /// load. Blocks it decides are marked `judged`; stages 4 (R7) and 5 (R8, R9) leave them.
    pub(crate) fn judge_stacks(
        &mut self,
        blocks: &mut [Block],
        active: &mut BlockSet,
        settings: &Settings,
        passes: &Passes,
    ) {
        // Nothing active: nothing awake or stirring, so nothing to wake and no candidate (the
        // flood below would find none).
        if active.is_empty() {
            return;
        }
        // The sets are the stage's own scratch; taken out for the step so that judging a
        // block can read them beside the rest of it (a swap of two vectors each: no
        // allocation).
        let mut flood = std::mem::take(&mut self.flood);
        let mut loads = std::mem::take(&mut self.loads);
        loads.touched.clear();
        self.judge_with(blocks, active, settings, passes, &mut flood, &mut loads);
        // Every block R14 judged or moved with a load takes part in the rest of the step.
        if !flood.cand.is_empty() {
            active.union_with(&flood.cand);
            active.union_with(&loads.touched);
        }
        self.flood = flood;
        self.loads = loads;
    }

    fn judge_with(
        &mut self,
        blocks: &mut [Block],
        active: &BlockSet,
        settings: &Settings,
        passes: &Passes,
        f: &mut Flood,
        loads: &mut Loads,
    ) {
        let n = blocks.len();
        let eps = settings.contact_eps;
        for set in [&mut f.awake, &mut f.stir, &mut f.fixed] {
            set.clear();
        }
        // A block outside the active set rests untouched since it left (`finish_block`): not
        // moved, stirred, released or grasped, its rotated vertices fresh and `judged` clear,
        // so it is sleeping, as the loop below would find it. Only the active blocks are
        // looked at: a field nothing touches costs R14 a few word operations, not a loop.
        f.sleeping.fill_to(n);
        f.sleeping.difference_with(active);
        for i in active.iter() {
            let b = &mut blocks[i];
            b.judged = false;
            if b.moved != Moved::No || b.mode == BlockMode::Grasped {
                // The hand moved or holds it (R4-R6, R5, R10): not judged, never a load.
                f.fixed.insert(i);
                if b.moved != Moved::No {
                    f.stir.insert(i);
                }
                continue;
            }
            if b.stirred {
                f.stir.insert(i);
            }
            if b.released {
                // R13: it starts flying in the next step.
                continue;
            }
            match b.mode {
                BlockMode::Resting | BlockMode::Supported => f.sleeping.insert(i),
                _ => f.awake.insert(i),
            }
        }
        // 1. Wake the sleeping blocks near anything that moves, flooding through touching ones.
        f.woken.copy_from(&f.sleeping);
        f.woken.intersect_with(&f.stir);
        f.queue.copy_from(&f.stir);
        f.queue.union_with(&f.awake);
        while let Some(i) = f.queue.pop_first() {
            for j in f.sleeping.iter() {
                if !f.woken.contains(j) && near(&blocks[i], &blocks[j], eps) {
                    f.woken.insert(j);
                    f.queue.insert(j);
                }
            }
        }
        f.cand.copy_from(&f.awake);
        f.cand.union_with(&f.woken);
        if f.cand.is_empty() {
            return;
        }
        // 2. Supporters: every touching pair with a candidate, once.
        {
            for e in &self.edges {
                self.below[e.upper].clear();
                self.above[e.lower].clear();
            }
            self.edges.clear();
            self.points.clear();
            for i in f.cand.iter() {
                for j in 0..n {
                    if j == i || (f.cand.contains(j) && j < i) {
                        continue;
                    }
                    let (a, b) = (&blocks[i], &blocks[j]);
                    if !near(a, b, eps) {
                        continue;
                    }
                    let (depth, axis) = pair_axis(a, b, eps);
                    if depth.is_nan() || depth < -eps {
                        continue;
                    }
                    let (lo, up) = if axis.y > SIDE_CONTACT_NY {
                        (i, j)
                    } else if axis.y < -SIDE_CONTACT_NY {
                        (j, i)
                    } else {
                        continue;
                    };
                    let (l, u) = (&blocks[lo], &blocks[up]);
                    let start = self.points.len();
                    contact_points(
                        &u.poly,
                        u.rot(),
                        &u.rel,
                        &l.poly,
                        l.rot(),
                        &l.rel,
                        l.pos() - u.pos(),
                        eps,
                        start + MAX_PAIR_POINTS,
                        &mut self.points,
                    );
                    if self.points.len() == start {
                        continue;
                    }
                    self.edges.push(SupportEdge {
                        lower: lo,
                        upper: up,
                        start,
                        end: self.points.len(),
                    });
                    self.below[up].insert(lo);
                    self.above[lo].insert(up);
                }
            }
        }
        // 3. Bottom up: a block after its supporters; a cycle is broken at its lowest index.
        f.pending.copy_from(&f.cand);
        while !f.pending.is_empty() {
            f.ready.clear();
            for i in f.pending.iter() {
                if !self.below[i].intersects(&f.pending) {
                    f.ready.insert(i);
                }
            }
            if f.ready.is_empty() {
                if let Some(i) = f.pending.first() {
                    f.ready.insert(i);
                }
            }
            for i in f.ready.iter() {
                self.judge(blocks, i, &f.fixed, &f.woken, loads, settings, passes);
            }
            f.pending.difference_with(&f.ready);
        }
    }

    /// R14 for block i: hold it, tip it with its load, or leave it to R7/R9.
    #[allow(clippy::too_many_arguments)]
    fn judge(
        &mut self,
        blocks: &mut [Block],
        i: usize,
        fixed: &BlockSet,
        woken: &BlockSet,
        l: &mut Loads,
        settings: &Settings,
        passes: &Passes,
    ) {
        if blocks[i].moved != Moved::No {
            // Moved this step as part of a load: not judged again.
            return;
        }
        let on_blocks = !self.below[i].is_empty();
        // The load: every block resting on b, transitively (not blocks the hand holds).
        l.load.clear();
        l.front.copy_from(&self.above[i]);
        l.front.difference_with(fixed);
        while let Some(j) = l.front.pop_first() {
            // A block tipping over b's edge rests on that edge, not on b as a load.
            if j == i || l.load.contains(j) || blocks[j].tipped_over.contains(i) {
                continue;
            }
            l.load.insert(j);
            l.front.union_with_except(&self.above[j], fixed, &l.load);
        }
        l.load.remove(i);
        {
            let b = &mut blocks[i];
            if !on_blocks && l.load.is_empty() {
                // Neither on a block nor under one: R7 or R9 decide as without R14, except a
                // sleeping block woken on the floor (its load may have left), which R9 would
                // skip: judged here by the same test.
                let woken_resting =
                    woken.contains(i) && b.mode == BlockMode::Resting && b.on_floor();
                if !woken_resting {
                    b.tipped_over.clear();
                    if b.mode == BlockMode::Supported {
                        b.mode = BlockMode::Free;
                    }
                    return;
                }
            }
        }
        l.s_mask.copy_from(&l.load);
        l.s_mask.insert(i);
        let s_mask = &l.s_mask;
        let gpos = blocks[i].pos();
        // G_L relative to b's G (precision far from the origin), and the cut's contact points.
        let mut vol = 0.0;
        let mut moment = DVec3::ZERO;
        for j in s_mask.iter() {
            let bj = &blocks[j];
            vol += bj.poly.volume;
            moment += (bj.pos() - gpos) * bj.poly.volume;
        }
        let gl = moment / vol;
        self.cut.clear();
        for j in s_mask.iter() {
            let bj = &blocks[j];
            let off = bj.pos() - gpos - gl;
            for k in bj.floor().iter().take_while(|&k| k < bj.rel.len()) {
                self.cut.push(bj.rel[k] + off);
            }
        }
        for e in &self.edges {
            if s_mask.contains(e.upper) && !s_mask.contains(e.lower) {
                let off = blocks[e.upper].pos() - gpos - gl;
                for p in &self.points[e.start..e.end] {
                    self.cut.push(*p + off);
                }
            }
        }
        self.hull_in.clear();
        self.hull_in
            .extend(self.cut.iter().map(|p| DVec2::new(p.x, p.z)));
        convex_hull_2d(&mut self.hull_in, &mut self.hull_out);
        let h = &self.hull_out[..];
        let verdict = in_hull(h, DVec2::ZERO, settings.hull_eps);
        let held = match verdict {
            None => {
                // Nothing under it after all (a touch without contact points).
                let b = &mut blocks[i];
                b.tipped_over.clear();
                if b.mode == BlockMode::Supported {
                    b.mode = BlockMode::Free;
                }
                return;
            }
            Some(inside) => inside,
        };
        let cut = &self.cut;
        let vertex_of = |q: DVec2| -> DVec3 {
            cut.iter()
                .copied()
                .find(|p| p.x == q.x && p.z == q.y)
                .unwrap_or(DVec3::new(q.x, 0.0, q.y))
        };
        let tip = if held {
            None
        } else {
            tip_about_hull(h, DVec2::ZERO, settings.g_step, vertex_of)
        };
        let Some((pivot_gl, axis, theta)) = tip else {
            // G_L in H (or no turn: no gravity): b does not move, exactly.
            let b = &mut blocks[i];
            b.v = DVec3::ZERO;
            b.judged = true;
            // Still leaning on the edge it tipped over: still no load of that block.
            b.tipped_over.intersect_with(&self.below[i]);
            b.mode = if on_blocks {
                BlockMode::Supported
            } else {
                BlockMode::Resting
            };
            return;
        };
        let pivot = pivot_gl + gl;
        // R9's limit: the first vertex of S that reaches the floor.
        let mut theta = theta;
        if passes.floor {
            for j in s_mask.iter() {
                let bj = &blocks[j];
                let pj = pivot + (gpos - bj.pos());
                theta = theta.min(landing_angle(
                    &bj.rel,
                    bj.pos().y,
                    bj.floor(),
                    pj,
                    axis,
                    settings.angle_eps,
                ));
            }
        }
        // And the first contact with a block outside S.
        let hull_eps = settings.hull_eps;
        let collides = |theta: f64, turned: &mut Vec<DVec3>| -> bool {
            let q = DQuat::from_axis_angle(axis, theta);
            for j in s_mask.iter() {
                let bj = &blocks[j];
                let pj = pivot + (gpos - bj.pos());
                let shift = pj - q * pj;
                let rot = (q * bj.rot()).normalize();
                let mut turned_ready = false;
                for (k, bk) in blocks.iter().enumerate() {
                    if s_mask.contains(k) {
                        continue;
                    }
                    // G's new place; the turn about G does not change the bounding sphere.
                    let off = (bk.pos() - bj.pos()) - shift;
                    if off.length() > bj.poly.radius + bk.poly.radius + hull_eps {
                        continue;
                    }
                    if !turned_ready {
                        rotate_vertices(&bj.poly, rot, turned);
                        turned_ready = true;
                    }
                    let after = sat_depth(&bj.poly, rot, turned, &bk.poly, bk.rot(), &bk.rel, off);
                    if after <= hull_eps {
                        continue;
                    }
                    let before = sat_depth(
                        &bj.poly,
                        bj.rot(),
                        &bj.rel,
                        &bk.poly,
                        bk.rot(),
                        &bk.rel,
                        bk.pos() - bj.pos(),
                    );
                    // Never deeper than it already is (or than hull_eps, when it only
                    // touches): a turn may not creep into a neighbour step by step.
                    if after > before.max(hull_eps) {
                        return true;
                    }
                }
            }
            false
        };
        if passes.blocks && collides(theta, &mut self.turned) {
            let (mut lo, mut hi) = (0.0, theta);
            for _ in 0..BISECTIONS {
                let mid = 0.5 * (lo + hi);
                if collides(mid, &mut self.turned) {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            theta = lo;
        }
        if theta.is_nan() || theta <= settings.angle_eps || !theta.is_finite() {
            // It cannot start to turn without entering another block: let R7/R12 decide.
            let b = &mut blocks[i];
            b.mode = BlockMode::Free;
            b.v = DVec3::ZERO;
            b.tipped_over.clear();
            return;
        }
        // S turns rigidly about the pivot (perfect friction: the load rides on b).
        l.under.clear();
        for e in &self.edges {
            if s_mask.contains(e.upper) && !s_mask.contains(e.lower) {
                l.under.insert(e.lower);
            }
        }
        let q = DQuat::from_axis_angle(axis, theta);
        for j in s_mask.iter() {
            let bj = &mut blocks[j];
            let pj = pivot + (gpos - bj.pos());
            bj.rotate_about(q, pj);
            bj.v = DVec3::ZERO;
            bj.moved = Moved::Stacked;
            bj.mode = BlockMode::Tipping;
            bj.judged = true;
            l.touched.insert(j);
            if j == i {
                bj.tipped_over.copy_from(&l.under);
            } else {
                bj.tipped_over.clear();
            }
        }
    }
}
