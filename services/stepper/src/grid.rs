//! The broad phase of the hand's contacts (R1-R3) and of free motion (R7 with R11, R12, R14's
//! slide): a uniform grid of the blocks' centres, so that the hand and a moving block test the
//! blocks near them rather than every block. Built on the first query, then kept in step with
//! the world's active set (`sync`) and each move of free motion, so a step costs in proportion
//! to what moves.
//!
//! Why a grid and not parry's BVH: blocks are of a size, a step moves them by a little, and
//! the grid is built in one pass and updated per move without allocating. It is a grid of
//! *columns*: cells in x and z only (four times the largest bounding radius: a query for a
//! block's neighbours visits the 2 x 2 columns around its corner), whatever the height, because
//! blocks stand on a floor and a world is wide, not tall. A column's blocks above and below a
//! query are rejected by one comparison of heights, which is cheaper than visiting the cells of
//! a third axis: on a rain of 1024 cubes (`bench stepper`'s falling field; callgrind) a query
//! walked ~11.4 cubic cells and 10 candidates for ~1090 instructions, and walks ~4.4 columns
//! and ~17 candidates (~5 of them at its height) for ~650 (with free motion's mid-step sphere,
//! `motion::free_motion`); a falling block also stays in its column, so telling the grid of its
//! move costs a comparison, not a division (~130 -> ~55 instructions). The candidates' records
//! are small and side by side, so the walk also misses the cache less: the rain's step went
//! from ~1.56M to ~1.05M instructions and from ~275 to ~140 us (mean, `stepper_profile`, the
//! other core busy). A tall tower costs a query one height comparison per block of its column.
//!
//! It is a hash grid: columns fold into a fixed table of buckets (four times the blocks; the
//! columns modulo the table's sides, so that neighbouring columns are neighbouring buckets),
//! each a linked list through the blocks, so memory is O(blocks) however far apart they are
//! (the hard cases put blocks 10,000 km from the origin).
//!
//! Persistent pairs (fat boxes) were weighed and not built: in the rain every block moves by
//! up to 4 cm a step against a pitch of 8 cm, so a fat box that lasts a few steps overlaps most
//! of its neighbours' and its refit query is larger than the query it saves.
//!
//! Exactness: a query returns every block whose bounding sphere could reach the query's (a
//! superset: hash collisions only add blocks), sorted by index, so the stage applies the same
//! exact tests in the same order as a loop over all blocks and gets the same bits. A block
//! whose centre is not finite is in every answer, as a loop over all blocks would test it.

use glam::DVec3;

use crate::body::Block;

const NONE: u32 = u32::MAX;

/// A block as the grid holds it: everything a query's walk reads of a candidate, in one
/// 40-byte record (the walk chases `next` from record to record, so one cache line a
/// candidate instead of one from each of three arrays).
#[derive(Debug, Clone, Copy)]
struct Slot {
    /// The centre as the grid last saw it.
    centre: DVec3,
    /// The bounding radius.
    radius: f64,
    /// The next block in this block's bucket.
    next: u32,
    /// This block's bucket, or NONE for a block in `unplaced`.
    bucket: u32,
}

/// A bucket's first block, and the query that last walked it, side by side (one line).
#[derive(Debug, Clone, Copy)]
struct Bucket {
    head: u32,
    /// A bucket that several of a query's columns hash to is walked once, so an answer never
    /// holds a block twice (nor outgrows `found`).
    visited: u32,
}

/// Blocks by the column (x and z cell) of their centre.
#[derive(Debug)]
pub(crate) struct BlockGrid {
    /// The cell's edge: four times the largest bounding radius (measured with cubic cells: 8
    /// buckets a query beat 27 of half the size by a third on a rain of 1024 cubes).
    cell: f64,
    max_radius: f64,
    /// The buckets: a power of two, four times the blocks (at least 16), `mask` + 1.
    buckets: Vec<Bucket>,
    mask: usize,
    /// The bits of a bucket's index that hold the column's x (the low ones; z the rest).
    x_bits: u32,
    x_mask: usize,
    /// Each block's record, by index.
    slots: Vec<Slot>,
    /// Blocks whose centre is not finite: candidates of every query.
    unplaced: Vec<u32>,
    /// Whether the grid has been built (on the first query).
    built: bool,
    /// A query's answer.
    found: Vec<u32>,
    query: u32,
    /// A box holding every finite centre the grid has been told (it only grows): a query
    /// that cannot reach it has nothing to walk. So a hand far from every block costs its
    /// stage a few comparisons, not a walk of empty cells (the ablation's idle field).
    seen_lo: DVec3,
    seen_hi: DVec3,
}

/// `x.floor() as i64` for a finite `x` (saturating the same way), without the call into libm
/// that `f64::floor` is on a baseline x86-64 target (it was 3 % of a falling step).
#[inline]
fn floor_i64(x: f64) -> i64 {
    let t = x as i64;
    if (t as f64) > x {
        t.saturating_sub(1)
    } else {
        t
    }
}

impl BlockGrid {
    pub(crate) fn new(blocks: &[Block]) -> BlockGrid {
        let n = blocks.len();
        let max_radius = blocks.iter().map(|b| b.poly.radius).fold(0.0, f64::max);
        let buckets = (4 * n).next_power_of_two().max(16);
        let x_bits = buckets.trailing_zeros().div_ceil(2);
        BlockGrid {
            mask: buckets - 1,
            x_bits,
            x_mask: (1 << x_bits) - 1,
            cell: (4.0 * max_radius).max(1e-6),
            max_radius,
            buckets: vec![
                Bucket {
                    head: NONE,
                    visited: 0
                };
                buckets
            ],
            slots: blocks
                .iter()
                .map(|b| Slot {
                    centre: b.pos(),
                    radius: b.poly.radius,
                    next: NONE,
                    bucket: NONE,
                })
                .collect(),
            unplaced: Vec::with_capacity(n),
            built: false,
            found: Vec::with_capacity(n),
            query: 0,
            seen_lo: DVec3::splat(f64::INFINITY),
            seen_hi: DVec3::splat(f64::NEG_INFINITY),
        }
    }

    /// The column (x and z cells) of a finite point.
    fn cell_of(&self, p: DVec3) -> Option<[i64; 2]> {
        let (x, z) = (p.x / self.cell, p.z / self.cell);
        (x.is_finite() && p.y.is_finite() && z.is_finite()).then(|| [floor_i64(x), floor_i64(z)])
    }

    /// The table's sides for the blocks' spread (when the grid is built): the x side covers
    /// the columns the blocks span in x, and the z side theirs, as far as the table's bits go,
    /// shared in proportion to the spans' logarithms when they do not. A row of blocks longer
    /// than a square table's side would otherwise wrap onto itself and walk the blocks of every
    /// wrap in each query. Only speed depends on it: any sides give the same answers.
    fn shape_table(&mut self, blocks: &[Block]) {
        let bits = self.mask.count_ones();
        let (mut lo, mut hi) = ([i64::MAX; 2], [i64::MIN; 2]);
        for c in blocks.iter().filter_map(|b| self.cell_of(b.pos())) {
            for k in 0..2 {
                lo[k] = lo[k].min(c[k]);
                hi[k] = hi[k].max(c[k]);
            }
        }
        // Bits to hold a span of columns (plus the query's reach past each end).
        let need = |k: usize| -> u32 {
            let span = hi[k].saturating_sub(lo[k]).saturating_add(3).max(1) as u64;
            u64::BITS - (span - 1).leading_zeros()
        };
        let x_bits = if lo[0] > hi[0] {
            bits.div_ceil(2)
        } else {
            let (nx, nz) = (need(0), need(1));
            if nx + nz <= bits {
                // Both fit: the spare bits go to both sides alike.
                nx + (bits - nx - nz) / 2
            } else {
                (bits * nx).div_ceil(nx + nz).min(bits)
            }
        };
        self.x_bits = x_bits;
        self.x_mask = (1 << x_bits) - 1;
    }

    /// A column's bucket is its x and z cells modulo the table's sides (a torus of
    /// `2^x_bits` by `2^(bits - x_bits)` columns, [`shape_table`](Self::shape_table)):
    /// neighbouring columns have neighbouring buckets, so a query's 2 x 2 columns are two lines
    /// of the table, and the next block's query (its neighbour in the field) the same two,
    /// where a scrambling hash put each column on a line of its own. Columns a side's width
    /// apart share a bucket: the walk's height and sphere tests reject the far one, as they
    /// reject any collision.
    #[inline]
    fn hash_x(&self, x: i64) -> usize {
        (x as u64 as usize) & self.x_mask
    }

    #[inline]
    fn hash_z(&self, z: i64) -> usize {
        ((z as u64 as usize) << self.x_bits) & self.mask
    }

    fn hash(&self, c: [i64; 2]) -> usize {
        self.hash_x(c[0]) | self.hash_z(c[1])
    }

    #[inline]
    fn seen(&mut self, p: DVec3) {
        self.seen_lo = self.seen_lo.min(p);
        self.seen_hi = self.seen_hi.max(p);
    }

    fn insert(&mut self, i: usize, p: DVec3) {
        self.slots[i].centre = p;
        match self.cell_of(p) {
            Some(c) => {
                self.seen(p);
                let h = self.hash(c);
                self.slots[i].next = self.buckets[h].head;
                self.slots[i].bucket = h as u32;
                self.buckets[h].head = i as u32;
            }
            None => {
                self.slots[i].bucket = NONE;
                self.unplaced.push(i as u32);
            }
        }
    }

    fn remove(&mut self, i: usize) {
        let h = self.slots[i].bucket;
        if h == NONE {
            if let Some(k) = self.unplaced.iter().position(|&j| j as usize == i) {
                self.unplaced.swap_remove(k);
            }
            return;
        }
        let h = h as usize;
        let after = self.slots[i].next;
        if self.buckets[h].head as usize == i {
            self.buckets[h].head = after;
        } else {
            let mut k = self.buckets[h].head;
            while k != NONE {
                let nk = self.slots[k as usize].next;
                if nk as usize == i {
                    self.slots[k as usize].next = after;
                    break;
                }
                k = nk;
            }
        }
        self.slots[i].next = NONE;
        self.slots[i].bucket = NONE;
    }

    fn rebuild(&mut self, blocks: &[Block]) {
        self.shape_table(blocks);
        self.buckets.iter_mut().for_each(|b| b.head = NONE);
        self.unplaced.clear();
        for (i, b) in blocks.iter().enumerate() {
            self.insert(i, b.pos());
        }
        self.built = true;
    }

    /// The blocks of `moved` (a superset of those that moved since the grid last saw them)
    /// stand where they are now. The world's active set is such a superset: a block that
    /// moves is active in that step, and stays so into the next.
    pub(crate) fn sync(&mut self, blocks: &[Block], moved: &crate::block_set::BlockSet) {
        if self.built {
            for i in moved.iter() {
                self.stands_at(i, blocks[i].pos());
            }
        }
    }

    /// Block i stands at `pos`, which may be where the grid last saw it: most blocks a sync
    /// looks at have not moved since (a move by free motion or a carry tells the grid at once).
    #[inline]
    pub(crate) fn stands_at(&mut self, i: usize, pos: DVec3) {
        if self.built && pos != self.slots[i].centre {
            self.moved(i, pos);
        }
    }

    /// Block i now stands at `pos` (after a query built the grid; before, nothing to do).
    pub(crate) fn moved(&mut self, i: usize, pos: DVec3) {
        if !self.built {
            return;
        }
        let (h, was) = (self.slots[i].bucket, self.slots[i].centre);
        // A block that moved straight up or down (a fall, a landing) stays in its column:
        // no division (a placed block's old centre was finite, so its x and z still are).
        let same = if h != NONE && pos.x == was.x && pos.z == was.z && pos.y.is_finite() {
            true
        } else {
            match self.cell_of(pos) {
                Some(c) => h != NONE && self.hash(c) == h as usize,
                None => h == NONE,
            }
        };
        if same {
            self.seen(pos);
            self.slots[i].centre = pos;
        } else {
            self.remove(i);
            self.insert(i, pos);
        }
    }

    /// Whether no block's bounding sphere can come within `reach` of the box [lo, hi]: every
    /// centre the grid holds is farther than that from it along an axis, and none is not
    /// finite. One comparison of boxes, for a caller (the hand's stage) that would otherwise
    /// ask [`near_any_order`](Self::near_any_order) and find nothing. With it, the hand's
    /// stages skipping what a hand that acts on nothing needs, each hand sample's box worked
    /// out once and the test made before the hand's stage is entered (`hand::hand_reach`), a
    /// far hand costs a step ~120 instructions over no hand (callgrind, `stepper_profile
    /// idle` against `idle-no-hand`); ~250 with the box of both samples worked out in the
    /// stage every step, ~820 before the stages skipped a far hand's work.
    #[inline]
    pub(crate) fn nothing_near_box(
        &mut self,
        blocks: &[Block],
        lo: DVec3,
        hi: DVec3,
        reach: f64,
    ) -> bool {
        if !self.built {
            self.rebuild(blocks);
        }
        // As `near_any_order`'s own early out: a slack for the rounding far from the origin
        // (a NaN compares false: not provably apart).
        let slack = 1e-9 * (1.0 + lo.abs().max(hi.abs()).max_element() + reach);
        let m = reach + self.max_radius + slack;
        self.unplaced.is_empty()
            && ((lo - m - slack).cmpgt(self.seen_hi).any()
                || (hi + m + slack).cmplt(self.seen_lo).any())
    }

    /// Every block whose bounding sphere comes within `reach` of `centre` (and maybe a
    /// little more: a slack covers rounding), by index. A caller whose own test is "the
    /// spheres come within m" asks with reach = its own radius + m.
    #[cfg(test)]
    pub(crate) fn near(&mut self, blocks: &[Block], centre: DVec3, reach: f64) -> &[u32] {
        let found = self.near_any_order(blocks, centre, reach);
        found.sort_unstable();
        found
    }

    /// [`near`](Self::near)'s blocks in no particular order, for a caller whose use of them
    /// does not depend on it (a minimum, an "any"); one whose result does sorts them.
    pub(crate) fn near_any_order(
        &mut self,
        blocks: &[Block],
        centre: DVec3,
        reach: f64,
    ) -> &mut [u32] {
        if !self.built {
            self.rebuild(blocks);
        }
        self.found.clear();
        debug_assert!(self.slots.len() < NONE as usize);
        // The callers' own tests decide; this one only has to keep every block they would
        // accept, whatever the rounding of a distance far from the origin: the cells searched
        // and the sphere test below both reach `slack` further.
        let slack = 1e-9 * (1.0 + centre.abs().max_element() + reach);
        let q = reach + self.max_radius + slack;
        // Nowhere near any centre the grid holds: only the unplaced (a second slack covers
        // the rounding of centre -+ q; a NaN compares false and goes on to the cells' test).
        if (centre - q - slack).cmpgt(self.seen_hi).any()
            || (centre + q + slack).cmplt(self.seen_lo).any()
        {
            self.found.extend_from_slice(&self.unplaced);
            return &mut self.found;
        }
        let (lo, hi) = match (self.cell_of(centre - q), self.cell_of(centre + q)) {
            (Some(lo), Some(hi)) if q.is_finite() => (lo, hi),
            _ => return self.everything(blocks.len()),
        };
        let span = |k: usize| (hi[k] - lo[k] + 1) as u128;
        // A query wider than the table (a very fast block): every block, as a plain loop.
        if span(0) * span(1) > self.buckets.len() as u128 {
            return self.everything(blocks.len());
        }
        self.query = self.query.wrapping_add(1);
        if self.query == 0 {
            self.buckets.iter_mut().for_each(|b| b.visited = 0);
            self.query = 1;
        }
        let query = self.query;
        let (x_bits, x_mask, mask) = (self.x_bits, self.x_mask, self.mask);
        let (buckets, slots, found) = (&mut self.buckets, &self.slots, &mut self.found);
        let mut x = lo[0];
        while x <= hi[0] {
            let hx = (x as u64 as usize) & x_mask;
            let mut z = lo[1];
            while z <= hi[1] {
                let h = hx | (((z as u64 as usize) << x_bits) & mask);
                z += 1;
                let bucket = &mut buckets[h];
                // Most buckets are empty (a quarter of a block each): no mark to leave.
                if bucket.head == NONE || bucket.visited == query {
                    continue;
                }
                bucket.visited = query;
                // NONE is past every index: the end of the list and the bounds check are one.
                let mut k = bucket.head;
                while let Some(s) = slots.get(k as usize) {
                    // Most of a column's blocks are above or below the query: its height
                    // alone rejects them (|dy| > q >= within, so the sphere test below would
                    // too: the answer is the same, for a subtraction and a comparison).
                    if (s.centre.y - centre.y).abs() <= q {
                        // Squared: no square root per candidate (the slack dwarfs rounding).
                        let within = reach + s.radius + slack;
                        if (s.centre - centre).length_squared() <= within * within {
                            found.push(k);
                        }
                    }
                    k = s.next;
                }
            }
            x += 1;
        }
        if !self.unplaced.is_empty() {
            self.found.extend_from_slice(&self.unplaced);
        }
        &mut self.found
    }

    fn everything(&mut self, n: usize) -> &mut [u32] {
        self.found.clear();
        self.found.extend(0..n as u32);
        &mut self.found
    }
}

#[cfg(test)]
mod tests {
    use common::config::scene::ShapeSpec;
    use glam::DQuat;

    use super::*;
    use crate::geometry::Polyhedron;

    fn cube_at(p: DVec3, size: f64) -> Block {
        let poly = Polyhedron::from_spec(&ShapeSpec::Box { size: [size; 3] }).unwrap();
        Block::new(String::new(), poly, p, DQuat::IDENTITY, DVec3::ZERO, 4)
    }

    /// The brute-force answer: every block whose bounding sphere comes within `reach` of the
    /// centre (the callers' tests are all of this form or narrower).
    fn within(blocks: &[Block], c: DVec3, reach: f64) -> Vec<u32> {
        (0..blocks.len() as u32)
            .filter(|&j| {
                let b = &blocks[j as usize];
                // As the stages test it: not farther (a NaN distance is not farther).
                let d = (b.pos() - c).length();
                d <= reach + b.poly.radius || d.is_nan()
            })
            .collect()
    }

    /// Columns a side of the table apart share a bucket: a query finds the blocks near it and
    /// none of the others walked with them. A world wider than the table in both x and z (a
    /// diagonal row of 8 cubes, 32 buckets, spanning ~100 x ~50 columns) must wrap.
    #[test]
    fn columns_that_share_a_bucket_answer_only_what_is_near() {
        let spots: Vec<DVec3> = (0..8)
            .map(|k| DVec3::new(-1.0 + k as f64 * 2.0, 0.5, 3.0 - k as f64))
            .collect();
        let blocks: Vec<Block> = spots.iter().map(|&p| cube_at(p, 0.04)).collect();
        let mut grid = BlockGrid::new(&blocks);
        assert!(grid.near(&blocks, spots[0], 0.01).len() == 1, "built");
        let mut buckets: Vec<usize> = spots
            .iter()
            .map(|&p| grid.hash(grid.cell_of(p).unwrap()))
            .collect();
        buckets.sort_unstable();
        buckets.dedup();
        assert!(buckets.len() < spots.len(), "some blocks share a bucket");
        for (i, &p) in spots.iter().enumerate() {
            for reach in [0.0, 0.01, 0.05] {
                assert_eq!(grid.near(&blocks, p, reach), &within(&blocks, p, reach)[..]);
            }
            assert_eq!(grid.near(&blocks, p, 0.01), &[i as u32]);
        }
    }

    /// A query that cannot reach any centre the grid holds answers at once, and a block moved
    /// far away is still found there.
    #[test]
    fn a_query_far_from_every_block_finds_only_what_is_there() {
        let mut blocks: Vec<Block> = (0..20)
            .map(|i| cube_at(DVec3::new(i as f64 * 0.1, 0.02, 0.0), 0.04))
            .collect();
        let mut grid = BlockGrid::new(&blocks);
        let far = DVec3::new(5.0, 0.5, 0.0);
        assert!(grid.near(&blocks, far, 0.05).is_empty());
        let (lo, hi) = (far - 0.01, far + 0.01);
        assert!(grid.nothing_near_box(&blocks, lo, hi, 0.05));
        // Just within reach of the box along x: not provably apart.
        assert!(!grid.nothing_near_box(&blocks, lo, hi, 5.0 - 1.9 - 0.01 - 0.02));
        blocks[3].set_position(DVec3::new(5.0, 0.48, 0.01));
        grid.moved(3, blocks[3].pos());
        assert!(!grid.nothing_near_box(&blocks, lo, hi, 0.05));
        assert_eq!(grid.near(&blocks, far, 0.05), &[3]);
        assert_eq!(
            grid.near(&blocks, DVec3::new(-3.0, 0.0, 0.0), 0.1),
            &[] as &[u32]
        );
        assert_eq!(within(&blocks, far, 0.05), [3]);
    }

    #[test]
    fn a_query_holds_every_block_a_loop_would_find_in_index_order_after_moves() {
        // Cubes of two sizes scattered over a few metres, one far away, one not finite.
        let mut seed = 7u64;
        let mut rnd = move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut blocks: Vec<Block> = (0..300)
            .map(|i| {
                let p = DVec3::new(rnd() * 3.0, rnd() * 0.5, rnd() * 3.0);
                cube_at(p, if i % 3 == 0 { 0.1 } else { 0.04 })
            })
            .collect();
        blocks.push(cube_at(DVec3::new(1e7, 0.0, 1e7), 0.04));
        blocks.push(cube_at(DVec3::new(f64::NAN, 0.0, 0.0), 0.04));
        let mut grid = BlockGrid::new(&blocks);
        for round in 0..200 {
            let c = DVec3::new(rnd() * 3.2 - 0.1, rnd() * 0.6, rnd() * 3.2 - 0.1);
            let reach = if round % 50 == 0 { 20.0 } else { rnd() * 0.3 };
            let got = grid.near(&blocks, c, reach).to_vec();
            assert!(got.windows(2).all(|w| w[0] < w[1]), "sorted, no repeats");
            for j in within(&blocks, c, reach) {
                assert!(got.contains(&j), "round {round}: block {j} missing");
            }
            assert!(got.contains(&301), "a block not finite is in every answer");
            // Move one block and tell the grid.
            let i = (rnd() * 300.0) as usize;
            blocks[i].translate(DVec3::new(rnd() - 0.5, 0.0, rnd() - 0.5) * 0.4);
            grid.moved(i, blocks[i].pos());
        }
    }
}
