//! The choice of a step's bullets (`PreciseWorld::choose_bullets`) in near-linear time.
//!
//! The rule is greedy: the fast blocks in order (fastest first), a block is a bullet unless its
//! swept box meets the swept box of a bullet chosen before it. Testing each block against every
//! bullet so far is quadratic (a rain of 4096 cubes: ~8 M box tests a step). The same choice
//! comes from the pairs of boxes that meet: a block is a bullet iff no earlier block it meets
//! is one, so one pass in rank order over the pairs decides every block, exactly as the
//! quadratic loop did (the same boxes, the same closed overlap test, the same order).
//!
//! The pairs come from a hierarchical grid: level L has cells of side h0 * 2^L (h0: the
//! largest extent of a box up to twice the smallest box's), and a box lives at the lowest level
//! whose cell side is at least its largest extent, in the (at most 2 x 2 x 2) cells it covers
//! there. A pair of boxes
//! is found by looking up the smaller box's cells at the larger box's level (a box never covers
//! more than a few cells of a level at or above its own), so a pair costs a few lookups whatever
//! the mix of sizes: a 200 m/s bullet among resting cubes neither fills thousands of small
//! cells nor makes every small box test it. Cells are hashed into a table sized to the entries
//! and filled by counting sort, so nothing allocates once the scratch has grown; a hash
//! collision only adds candidates that the exact box test turns away.

use glam::DVec3;

/// Up to this many fast blocks the choice tests each against every bullet so far, as the rule
/// reads: cheaper than building the grid below ~160 boxes (measured on a rain of cubes' boxes:
/// 64 boxes 5 us direct, 14 us by the grid; 256: 82 and 52 us; 4096: 21 ms and 1.2 ms).
const DIRECT_MAX: usize = 160;

/// Levels above the smallest box's: a box more than 2^MAX_LEVEL times larger than the smallest
/// (or with a coordinate that is not finite) is tested against every box instead.
const MAX_LEVEL: u32 = 48;

/// Scratch of the choice, kept between steps so that a step does not allocate.
#[derive(Default)]
pub(super) struct BulletChoice {
    /// The swept boxes, in rank order (fastest first).
    boxes: Vec<(DVec3, DVec3)>,
    /// Each box's level, `u32::MAX` for a box tested against every box (`wild`).
    level: Vec<u32>,
    /// Each level's 1 / side, and the cells each box covers at its own level.
    inv: Vec<f64>,
    ranges: Vec<([i64; 3], [i64; 3])>,
    wild: Vec<u32>,
    /// (bucket, rank) of every cell a box covers at its level, then the ranks by bucket.
    entries: Vec<(u32, u32)>,
    starts: Vec<u32>,
    slots: Vec<u32>,
    /// The pairs of boxes that meet, (lower rank, higher rank); a pair may appear twice.
    pairs: Vec<(u32, u32)>,
    blocked: Vec<bool>,
    chosen: Vec<u32>,
}

/// The closed overlap test of two boxes (NaN meets nothing).
#[inline]
fn meets(a: &(DVec3, DVec3), b: &(DVec3, DVec3)) -> bool {
    b.0.cmple(a.1).all() && a.0.cmple(b.1).all()
}

/// The cell coordinate of `x` on a grid whose side is 1 / `inv`: monotone in `x` (a product
/// with a positive number, then the floor, saturating at i64's ends), which is all the pair
/// search relies on. The floor by truncation: `f64::floor` is a libm call on x86-64's baseline.
#[inline]
fn cell(x: f64, inv: f64) -> i64 {
    let v = x * inv;
    let t = v as i64;
    if (t as f64) > v {
        t.saturating_sub(1)
    } else {
        t
    }
}

#[inline]
fn cells(p: DVec3, inv: f64) -> [i64; 3] {
    [cell(p.x, inv), cell(p.y, inv), cell(p.z, inv)]
}

#[inline]
fn bucket(level: u32, c: [i64; 3], bits: u32) -> u32 {
    let mut k = (c[0] as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)
        ^ (c[1] as u64).wrapping_mul(0xc2b2_ae3d_27d4_eb4f)
        ^ (c[2] as u64).wrapping_mul(0x1656_67b1_9e37_79f9)
        ^ u64::from(level).wrapping_mul(0x27d4_eb2f_1656_67c5);
    k ^= k >> 31;
    k = k.wrapping_mul(0x94d0_49bb_1331_11eb);
    (k >> (64 - bits)) as u32
}

/// The cells `b` covers on a grid of side 1 / `inv`, inclusive, per axis.
#[inline]
fn range(b: &(DVec3, DVec3), inv: f64) -> ([i64; 3], [i64; 3]) {
    (cells(b.0, inv), cells(b.1, inv))
}

fn for_each_cell(lo: [i64; 3], hi: [i64; 3], mut f: impl FnMut([i64; 3])) {
    for x in lo[0]..=hi[0] {
        for y in lo[1]..=hi[1] {
            for z in lo[2]..=hi[2] {
                f([x, y, z]);
            }
        }
    }
}

impl BulletChoice {
    /// Starts a new choice.
    pub(super) fn clear(&mut self) {
        self.boxes.clear();
    }

    /// The next fast block's swept box (ranks are given fastest first).
    pub(super) fn push(&mut self, lo: DVec3, hi: DVec3) {
        self.boxes.push((lo, hi));
    }

    /// The ranks of the bullets, ascending: each box that meets no box of a lower rank
    /// chosen before it.
    pub(super) fn choose(&mut self) -> &[u32] {
        self.choose_with(DIRECT_MAX)
    }

    /// [`Self::choose`], testing directly up to `direct_max` boxes (the tests set 0 to check
    /// the grid on small sets too).
    fn choose_with(&mut self, direct_max: usize) -> &[u32] {
        let m = self.boxes.len();
        self.chosen.clear();
        self.pairs.clear();
        if m <= direct_max {
            for (r, b) in self.boxes.iter().enumerate() {
                if !self
                    .chosen
                    .iter()
                    .any(|&q| meets(&self.boxes[q as usize], b))
                {
                    self.chosen.push(r as u32);
                }
            }
            return &self.chosen;
        }
        self.find_pairs();
        // A pair (a, b) blocks b once a is chosen; ranks in order, pairs sorted by a.
        self.pairs.sort_unstable();
        self.blocked.clear();
        self.blocked.resize(m, false);
        let mut p = 0;
        for a in 0..m as u32 {
            let free = !self.blocked[a as usize];
            if free {
                self.chosen.push(a);
            }
            while p < self.pairs.len() && self.pairs[p].0 == a {
                if free {
                    self.blocked[self.pairs[p].1 as usize] = true;
                }
                p += 1;
            }
        }
        &self.chosen
    }

    /// Every pair of boxes that meet, each at least once, as (lower rank, higher rank).
    fn find_pairs(&mut self) {
        let boxes = &self.boxes;
        let extent = |b: &(DVec3, DVec3)| (b.1 - b.0).max_element();
        // The base cell: the largest extent up to twice the smallest, so that a field of
        // similar boxes lives on one level (each box then looks up a single level), while
        // much larger ones (a fast bullet) go to levels of their own, and much smaller ones
        // never share a cell with many others.
        let sized = || {
            boxes
                .iter()
                .map(extent)
                .filter(|e| e.is_finite() && *e > 0.0)
        };
        let smallest = sized().fold(f64::INFINITY, f64::min);
        let h0 = if smallest.is_finite() {
            sized()
                .filter(|&e| e <= 2.0 * smallest)
                .fold(smallest, f64::max)
        } else {
            1.0
        };
        // h0 * 2^L is exact (a power of two times a float), and each level's inverse is
        // computed once, so every use of a level's grid sees the same numbers.
        let side = |l: u32| h0 * (1u64 << l) as f64;
        self.level.clear();
        self.wild.clear();
        self.ranges.clear();
        let mut top = 0;
        // The levels that hold a box (bit L): a look-up skips the others.
        let mut occupied = 0u64;
        for (r, b) in boxes.iter().enumerate() {
            let e = extent(b);
            let finite = b.0.is_finite() && b.1.is_finite();
            let level = (0..=MAX_LEVEL).find(|&l| e <= side(l));
            match level {
                Some(l) if finite => {
                    self.level.push(l);
                    top = top.max(l);
                    occupied |= 1 << l;
                }
                _ => {
                    self.level.push(u32::MAX);
                    self.wild.push(r as u32);
                }
            }
        }
        self.inv.clear();
        self.inv.extend((0..=top).map(|l| 1.0 / side(l)));
        // The cells of each box at its own level, into a table of twice as many buckets,
        // filled by counting sort: `starts[k]..starts[k + 1]` are bucket k's slots.
        let mut count = 0usize;
        for (b, &l) in boxes.iter().zip(&self.level) {
            let (lo, hi) = if l == u32::MAX {
                ([0; 3], [-1; 3])
            } else {
                range(b, self.inv[l as usize])
            };
            count += (0..3)
                .map(|k| (hi[k] - lo[k] + 1).max(0) as usize)
                .product::<usize>();
            self.ranges.push((lo, hi));
        }
        let bits = (2 * count).max(16).next_power_of_two().trailing_zeros();
        let buckets = 1usize << bits;
        self.entries.clear();
        for (r, (&(lo, hi), &l)) in self.ranges.iter().zip(&self.level).enumerate() {
            let entries = &mut self.entries;
            for_each_cell(lo, hi, |c| entries.push((bucket(l, c, bits), r as u32)));
        }
        let (starts, slots) = (&mut self.starts, &mut self.slots);
        starts.clear();
        starts.resize(buckets + 1, 0);
        for &(k, _) in &self.entries {
            starts[k as usize] += 1;
        }
        for k in 1..buckets {
            starts[k] += starts[k - 1];
        }
        starts[buckets] = self.entries.len() as u32;
        slots.clear();
        slots.resize(self.entries.len(), 0);
        for &(k, r) in self.entries.iter().rev() {
            starts[k as usize] -= 1;
            slots[starts[k as usize] as usize] = r;
        }
        // Each box looks itself up at its own level (pairs with a higher rank there) and at
        // every level above (pairs with any rank). A pair is kept in the cell that holds the
        // low corner of the two boxes' intersection only, so a pair sharing several cells
        // counts once (twice at most when a hash collision files the same box twice).
        let (level, inv, starts, slots, pairs) = (
            &self.level,
            &self.inv,
            &self.starts,
            &self.slots,
            &mut self.pairs,
        );
        for (q, bq) in boxes.iter().enumerate() {
            let lq = level[q];
            if lq == u32::MAX {
                continue;
            }
            for l in (lq..=top).filter(|&l| occupied & (1 << l) != 0) {
                let h = inv[l as usize];
                let (lo, hi) = if l == lq {
                    self.ranges[q]
                } else {
                    range(bq, h)
                };
                for_each_cell(lo, hi, |c| {
                    let k = bucket(l, c, bits) as usize;
                    for &r in &slots[starts[k] as usize..starts[k + 1] as usize] {
                        let r = r as usize;
                        if r == q || level[r] != l || (l == lq && r < q) {
                            continue;
                        }
                        let br = &boxes[r];
                        if meets(bq, br) && cells(bq.0.max(br.0), h) == c {
                            pairs.push((q.min(r) as u32, q.max(r) as u32));
                        }
                    }
                });
            }
        }
        // Boxes off the grid meet whatever they meet.
        for &w in &self.wild {
            let w = w as usize;
            for (r, br) in boxes.iter().enumerate() {
                if r != w && meets(&boxes[w], br) {
                    pairs.push((w.min(r) as u32, w.max(r) as u32));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rule as `choose_bullets` first wrote it: each box against every bullet so far.
    fn quadratic(boxes: &[(DVec3, DVec3)]) -> Vec<u32> {
        let mut chosen: Vec<u32> = Vec::new();
        for (r, b) in boxes.iter().enumerate() {
            if !chosen.iter().any(|&q| meets(&boxes[q as usize], b)) {
                chosen.push(r as u32);
            }
        }
        chosen
    }

    /// A small deterministic generator (xorshift64*).
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> f64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    fn check(boxes: &[(DVec3, DVec3)], what: &str) {
        let mut c = BulletChoice::default();
        // Twice through the same scratch (a second step reuses it), the grid whatever the
        // count, then as a step chooses.
        for direct_max in [0, 0, DIRECT_MAX] {
            c.clear();
            for b in boxes {
                c.push(b.0, b.1);
            }
            assert_eq!(
                c.choose_with(direct_max),
                quadratic(boxes).as_slice(),
                "{what}"
            );
        }
    }

    #[test]
    fn the_grid_chooses_what_the_quadratic_rule_chooses() {
        let mut rng = Rng(0x1234_5678_9abc_def1);
        for case in 0..300 {
            let n = 1 + (rng.next() * 400.0) as usize;
            // Spread and sizes from packed to sparse, one size or a wide mix (a few huge).
            let spread = 0.05 + rng.next() * 5.0;
            let mix = rng.next() < 0.5;
            let offset = if case % 7 == 0 { 1e6 } else { 0.0 };
            let boxes: Vec<(DVec3, DVec3)> = (0..n)
                .map(|_| {
                    let c = DVec3::new(rng.next(), rng.next(), rng.next()) * spread - spread / 2.0
                        + offset;
                    let size = if mix {
                        0.01 * 10f64.powf(rng.next() * 3.0)
                    } else {
                        0.07
                    };
                    let half =
                        DVec3::new(rng.next(), rng.next(), rng.next()) * size / 2.0 + size / 4.0;
                    (c - half, c + half)
                })
                .collect();
            check(&boxes, &format!("case {case}: {n} boxes"));
        }
    }

    #[test]
    fn touching_identical_nested_and_unplaceable_boxes_are_chosen_as_before() {
        let b = |lo: [f64; 3], hi: [f64; 3]| (DVec3::from_array(lo), DVec3::from_array(hi));
        let nan = f64::NAN;
        let inf = f64::INFINITY;
        let cases: Vec<Vec<(DVec3, DVec3)>> = vec![
            // Faces touching exactly (closed test: they meet), on and off cell boundaries.
            (0..10)
                .map(|i| b([i as f64, 0.0, 0.0], [i as f64 + 1.0, 1.0, 1.0]))
                .collect(),
            (0..10)
                .map(|i| b([0.1 * i as f64, 0.0, 0.0], [0.1 * (i + 1) as f64, 0.1, 0.1]))
                .collect(),
            // The same box five times; a point box.
            vec![b([0.0; 3], [1.0; 3]); 5],
            vec![
                b([0.5; 3], [0.5; 3]),
                b([0.0; 3], [1.0; 3]),
                b([0.5; 3], [0.5; 3]),
            ],
            // Nested: one huge box among small ones, first and last.
            std::iter::once(b([-100.0; 3], [100.0; 3]))
                .chain((0..20).map(|i| b([i as f64 * 0.2; 3], [i as f64 * 0.2 + 0.1; 3])))
                .collect(),
            (0..20)
                .map(|i| b([i as f64 * 0.2; 3], [i as f64 * 0.2 + 0.1; 3]))
                .chain(std::iter::once(b([-100.0; 3], [100.0; 3])))
                .collect(),
            // Boxes no grid holds: NaN meets nothing, an infinite box meets everything.
            vec![
                b([nan; 3], [nan; 3]),
                b([0.0; 3], [1.0; 3]),
                b([-inf; 3], [inf; 3]),
                b([2.0; 3], [3.0; 3]),
                b([0.0, nan, 0.0], [1.0; 3]),
            ],
            // Far apart sizes: 1e-9 and 1e9.
            vec![
                b([0.0; 3], [1e-9; 3]),
                b([-1e9; 3], [1e9; 3]),
                b([5e-10; 3], [2e-9; 3]),
            ],
            // Negative coordinates across zero.
            (0..30)
                .map(|i| {
                    let x = -1.0 + 0.07 * i as f64;
                    b([x, -0.03, -0.03], [x + 0.075, 0.03, 0.03])
                })
                .collect(),
        ];
        for (k, boxes) in cases.iter().enumerate() {
            check(boxes, &format!("case {k}"));
        }
    }
}
