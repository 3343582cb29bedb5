//! The broad phase of the hand's contacts (R1-R3) and of free motion (R7 with R11, R12, R14's
//! slide): a uniform grid of the blocks' centres, so that the hand and a moving block test the
//! blocks near them rather than every block. Built on the first query, then kept in step with
//! the world's active set (`sync`) and each move of free motion, so a step costs in proportion
//! to what moves.
//!
//! Why a grid and not parry's BVH: blocks are of a size (with cells four times the largest
//! bounding radius, a query for a block's neighbours visits the 8 cells around its corner), a
//! step moves them by a little, and the grid is built in one pass and updated per move without
//! allocating. It is a hash grid: cells hash into a fixed table of buckets (four times the
//! blocks: a rain of 1024 cubes walked 13 candidates a query with twice, 10 with eight times,
//! of which 1 was near), each a linked list through the blocks, so memory is O(blocks) however far apart they are (the hard cases
//! put blocks 10,000 km from the origin).
//!
//! Exactness: a query returns every block whose bounding sphere could reach the query's (a
//! superset: hash collisions only add blocks), sorted by index, so the stage applies the same
//! exact tests in the same order as a loop over all blocks and gets the same bits. A block
//! whose centre is not finite is in every answer, as a loop over all blocks would test it.

use glam::DVec3;

use crate::body::Block;

const NONE: u32 = u32::MAX;

/// Blocks by the cell of their centre.
#[derive(Debug)]
pub(crate) struct BlockGrid {
    /// The cell's edge: four times the largest bounding radius (measured: 8 buckets a query
    /// beat 27 of half the size by a third on a rain of 1024 cubes).
    cell: f64,
    max_radius: f64,
    /// The first block of each bucket, and each block's next in its bucket.
    head: Vec<u32>,
    next: Vec<u32>,
    /// Each block's bucket, or NONE for a block in `unplaced`.
    bucket: Vec<u32>,
    /// Blocks whose centre is not finite: candidates of every query.
    unplaced: Vec<u32>,
    /// Whether the grid has been built (on the first query).
    built: bool,
    /// Each block's centre as the grid last saw it and its bounding radius, side by side, so
    /// that a query's sphere test reads these and not the blocks.
    centre: Vec<DVec3>,
    radius: Vec<f64>,
    /// A query's answer.
    found: Vec<u32>,
    /// The query that last visited each bucket: a bucket that several of a query's cells
    /// hash to is walked once, so an answer never holds a block twice (nor outgrows `found`).
    visited: Vec<u32>,
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
        BlockGrid {
            cell: (4.0 * max_radius).max(1e-6),
            max_radius,
            head: vec![NONE; buckets],
            next: vec![NONE; n],
            bucket: vec![NONE; n],
            unplaced: Vec::with_capacity(n),
            built: false,
            centre: blocks.iter().map(|b| b.pos).collect(),
            radius: blocks.iter().map(|b| b.poly.radius).collect(),
            found: Vec::with_capacity(n),
            visited: vec![0; buckets],
            query: 0,
            seen_lo: DVec3::splat(f64::INFINITY),
            seen_hi: DVec3::splat(f64::NEG_INFINITY),
        }
    }

    fn cell_of(&self, p: DVec3) -> Option<[i64; 3]> {
        let c = p / self.cell;
        c.is_finite()
            .then(|| [floor_i64(c.x), floor_i64(c.y), floor_i64(c.z)])
    }

    fn hash(&self, c: [i64; 3]) -> usize {
        let h = (c[0].wrapping_mul(73_856_093))
            ^ (c[1].wrapping_mul(19_349_663))
            ^ (c[2].wrapping_mul(83_492_791));
        (h as u64 as usize) & (self.head.len() - 1)
    }

    #[inline]
    fn seen(&mut self, p: DVec3) {
        self.seen_lo = self.seen_lo.min(p);
        self.seen_hi = self.seen_hi.max(p);
    }

    fn insert(&mut self, i: usize, p: DVec3) {
        self.centre[i] = p;
        match self.cell_of(p) {
            Some(c) => {
                self.seen(p);
                let h = self.hash(c);
                self.next[i] = self.head[h];
                self.head[h] = i as u32;
                self.bucket[i] = h as u32;
            }
            None => {
                self.bucket[i] = NONE;
                self.unplaced.push(i as u32);
            }
        }
    }

    fn remove(&mut self, i: usize) {
        let h = self.bucket[i];
        if h == NONE {
            if let Some(k) = self.unplaced.iter().position(|&j| j as usize == i) {
                self.unplaced.swap_remove(k);
            }
            return;
        }
        let h = h as usize;
        if self.head[h] as usize == i {
            self.head[h] = self.next[i];
        } else {
            let mut k = self.head[h];
            while k != NONE {
                let nk = self.next[k as usize];
                if nk as usize == i {
                    self.next[k as usize] = self.next[i];
                    break;
                }
                k = nk;
            }
        }
        self.next[i] = NONE;
        self.bucket[i] = NONE;
    }

    fn rebuild(&mut self, blocks: &[Block]) {
        self.head.iter_mut().for_each(|h| *h = NONE);
        self.unplaced.clear();
        for (i, b) in blocks.iter().enumerate() {
            self.insert(i, b.pos);
        }
        self.built = true;
    }

    /// The blocks of `moved` (a superset of those that moved since the grid last saw them)
    /// stand where they are now. The world's active set is such a superset: a block that
    /// moves is active in that step, and stays so into the next.
    pub(crate) fn sync(&mut self, blocks: &[Block], moved: &crate::block_set::BlockSet) {
        if self.built {
            for i in moved.iter() {
                // Most of the set has not moved since the grid last saw it (a move by free
                // motion or a carry tells the grid at once).
                if blocks[i].pos != self.centre[i] {
                    self.moved(i, blocks[i].pos);
                }
            }
        }
    }

    /// Block i now stands at `pos` (after a query built the grid; before, nothing to do).
    pub(crate) fn moved(&mut self, i: usize, pos: DVec3) {
        if !self.built {
            return;
        }
        let same = match (self.cell_of(pos), self.bucket[i]) {
            (Some(c), h) => h != NONE && self.hash(c) == h as usize,
            (None, h) => h == NONE,
        };
        if same {
            self.seen(pos);
            self.centre[i] = pos;
        } else {
            self.remove(i);
            self.insert(i, pos);
        }
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
        if span(0) * span(1) * span(2) > self.head.len() as u128 {
            return self.everything(blocks.len());
        }
        self.query = self.query.wrapping_add(1);
        if self.query == 0 {
            self.visited.iter_mut().for_each(|v| *v = 0);
            self.query = 1;
        }
        for x in lo[0]..=hi[0] {
            for y in lo[1]..=hi[1] {
                for z in lo[2]..=hi[2] {
                    let h = self.hash([x, y, z]);
                    if self.visited[h] == self.query {
                        continue;
                    }
                    self.visited[h] = self.query;
                    let mut k = self.head[h];
                    while k != NONE {
                        let j = k as usize;
                        // Squared: no square root per candidate (the slack dwarfs rounding).
                        let within = reach + self.radius[j] + slack;
                        if (self.centre[j] - centre).length_squared() <= within * within {
                            self.found.push(k);
                        }
                        k = self.next[j];
                    }
                }
            }
        }
        self.found.extend_from_slice(&self.unplaced);
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
                let d = (b.pos - c).length();
                d <= reach + b.poly.radius || d.is_nan()
            })
            .collect()
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
        blocks[3].pos = DVec3::new(5.0, 0.48, 0.01);
        grid.moved(3, blocks[3].pos);
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
            blocks[i].pos += DVec3::new(rnd() - 0.5, 0.0, rnd() - 0.5) * 0.4;
            grid.moved(i, blocks[i].pos);
        }
    }
}
