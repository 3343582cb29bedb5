//! A set of block indices as a bit set sized for its world: R14's sleeping, woken, candidate,
//! load and supporter sets. Replaces the u128 masks that held worlds to 128 blocks.
//!
//! Every set of a world has the same number of words, fixed when the world is built, so that
//! the operations are plain word loops and a step allocates nothing: sets are cleared and
//! refilled, never grown. Iteration is lowest index first, as the masks' was, so the judging
//! order (and with it every result) is the same bit for bit.

/// Block indices `0..capacity` as bits.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct BlockSet {
    words: Vec<u64>,
}

impl BlockSet {
    /// An empty set that can hold the indices `0..capacity`.
    pub fn new(capacity: usize) -> BlockSet {
        BlockSet {
            words: vec![0; capacity.div_ceil(64)],
        }
    }

    #[inline]
    pub fn clear(&mut self) {
        self.words.iter_mut().for_each(|w| *w = 0);
    }

    /// The indices `0..n` and no others (`n` at most the capacity).
    #[inline]
    pub fn fill_to(&mut self, n: usize) {
        for (k, w) in self.words.iter_mut().enumerate() {
            let lo = k * 64;
            *w = if n >= lo + 64 {
                u64::MAX
            } else if n > lo {
                (1u64 << (n - lo)) - 1
            } else {
                0
            };
        }
    }

    #[inline]
    pub fn insert(&mut self, i: usize) {
        self.words[i / 64] |= 1 << (i % 64);
    }

    #[inline]
    pub fn remove(&mut self, i: usize) {
        self.words[i / 64] &= !(1 << (i % 64));
    }

    #[inline]
    pub fn contains(&self, i: usize) -> bool {
        self.words[i / 64] & (1 << (i % 64)) != 0
    }

    #[inline]
    pub fn is_empty(&self) -> bool {
        self.words.iter().all(|&w| w == 0)
    }

    /// The lowest index in the set.
    #[inline]
    pub fn first(&self) -> Option<usize> {
        self.words
            .iter()
            .position(|&w| w != 0)
            .map(|k| k * 64 + self.words[k].trailing_zeros() as usize)
    }

    /// Removes and returns the lowest index.
    #[inline]
    pub fn pop_first(&mut self) -> Option<usize> {
        let i = self.first()?;
        self.remove(i);
        Some(i)
    }

    /// Whether the two sets share an index.
    #[inline]
    pub fn intersects(&self, other: &BlockSet) -> bool {
        self.words.iter().zip(&other.words).any(|(a, b)| a & b != 0)
    }

    /// self = other (same capacity: no allocation).
    #[inline]
    pub fn copy_from(&mut self, other: &BlockSet) {
        self.words.copy_from_slice(&other.words);
    }

    /// self |= other.
    #[inline]
    pub fn union_with(&mut self, other: &BlockSet) {
        self.words
            .iter_mut()
            .zip(&other.words)
            .for_each(|(a, b)| *a |= b);
    }

    /// self &= other.
    #[inline]
    pub fn intersect_with(&mut self, other: &BlockSet) {
        self.words
            .iter_mut()
            .zip(&other.words)
            .for_each(|(a, b)| *a &= b);
    }

    /// self &= !other.
    #[inline]
    pub fn difference_with(&mut self, other: &BlockSet) {
        self.words
            .iter_mut()
            .zip(&other.words)
            .for_each(|(a, b)| *a &= !b);
    }

    /// self |= add & !not_a & !not_b.
    #[inline]
    pub fn union_with_except(&mut self, add: &BlockSet, not_a: &BlockSet, not_b: &BlockSet) {
        for (k, w) in self.words.iter_mut().enumerate() {
            *w |= add.words[k] & !not_a.words[k] & !not_b.words[k];
        }
    }

    /// The indices in the set and not in `other` (of the same world), lowest first.
    pub fn iter_except<'a>(&'a self, other: &'a BlockSet) -> impl Iterator<Item = usize> + 'a {
        self.words
            .iter()
            .zip(&other.words)
            .enumerate()
            .flat_map(|(k, (&w, &not))| bits(k, w & !not))
    }

    /// The indices in the set, lowest first.
    pub fn iter(&self) -> impl Iterator<Item = usize> + '_ {
        self.words.iter().enumerate().flat_map(|(k, &w)| bits(k, w))
    }
}

/// The indices of word `k`'s set bits `w`, lowest first.
#[inline]
fn bits(k: usize, w: u64) -> impl Iterator<Item = usize> {
    let mut m = w;
    std::iter::from_fn(move || {
        if m == 0 {
            None
        } else {
            let i = m.trailing_zeros() as usize;
            m &= m - 1;
            Some(k * 64 + i)
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `iter_except` yields what `iter` yields of the set less the other, across words.
    #[test]
    fn iter_except_yields_the_difference_lowest_first() {
        let (mut s, mut t) = (BlockSet::new(200), BlockSet::new(200));
        for i in [0, 5, 63, 64, 100, 130, 199] {
            s.insert(i);
        }
        for i in [5, 64, 131, 199] {
            t.insert(i);
        }
        assert_eq!(s.iter_except(&t).collect::<Vec<_>>(), [0, 63, 100, 130]);
        assert_eq!(
            s.iter_except(&BlockSet::new(200)).collect::<Vec<_>>(),
            s.iter().collect::<Vec<_>>()
        );
        assert_eq!(s.iter_except(&s).count(), 0);
    }

    /// `fill_to(n)` holds exactly 0..n, at word edges too.
    #[test]
    fn fill_to_holds_exactly_the_first_n() {
        for n in [0, 1, 63, 64, 65, 127, 128, 130] {
            let mut s = BlockSet::new(130);
            s.insert(129);
            s.fill_to(n);
            assert_eq!(
                s.iter().collect::<Vec<_>>(),
                (0..n).collect::<Vec<_>>(),
                "n = {n}"
            );
        }
    }

    #[test]
    fn a_set_holds_indices_across_words_and_yields_them_lowest_first() {
        let mut s = BlockSet::new(4096);
        for i in [4095, 0, 64, 63, 130, 1000] {
            s.insert(i);
        }
        assert_eq!(s.iter().collect::<Vec<_>>(), [0, 63, 64, 130, 1000, 4095]);
        assert_eq!(s.first(), Some(0));
        assert_eq!(s.pop_first(), Some(0));
        assert_eq!(s.first(), Some(63));
        assert!(s.contains(4095) && !s.contains(4094));
        s.remove(4095);
        assert!(!s.contains(4095));
        let mut t = BlockSet::new(4096);
        t.insert(130);
        assert!(s.intersects(&t));
        s.difference_with(&t);
        assert!(!s.intersects(&t));
        s.union_with(&t);
        s.intersect_with(&t);
        assert_eq!(s.iter().collect::<Vec<_>>(), [130]);
        let (mut u, mut a, mut b) = (BlockSet::new(200), BlockSet::new(200), BlockSet::new(200));
        for i in [1, 2, 3, 150] {
            a.insert(i);
        }
        b.insert(2);
        let c = BlockSet::new(200);
        let mut d = BlockSet::new(200);
        d.insert(150);
        u.union_with_except(&a, &b, &d);
        assert_eq!(u.iter().collect::<Vec<_>>(), [1, 3]);
        u.copy_from(&c);
        assert!(u.is_empty() && u.first().is_none());
    }
}
