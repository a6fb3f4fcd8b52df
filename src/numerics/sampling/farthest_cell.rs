//! The farthest cell of a distance map that local fronts lower: the largest
//! finite value per chunk of 64 consecutive cells, and a tournament tree
//! over the chunks.
//!
//! A front marks the cells it sets; when it ends, each marked chunk is
//! scanned again (64 sequential reads) and its leaf-to-root path replayed
//! (`log₂(n / 64)` comparisons). Keeping every cell in an indexed heap
//! instead costs a sift through a heap of `n` entries, scattered in memory,
//! for every cell a front sets: it was 44 % of farthest-point sampling on a
//! 1024² grid.
//!
//! Ties (frequent under a constant metric, where the farthest cells of a
//! symmetric set are many) go to the cell whose index scrambles highest
//! (`i · 0x9E3779B1 mod 2³²`, a bijection): a fixed order that does not
//! favour the first rows, whose aligned samples would make the geodesic
//! Delaunay triangulation degenerate more often.

/// `log₂` of the cells per chunk.
const CHUNK_BITS: u32 = 6;

/// An entry: a value and its cell (`u32::MAX` with `-inf`: none).
type Entry = (f64, u32);

const NONE: Entry = (f64::NEG_INFINITY, u32::MAX);

/// The tie-break rank of cell `i`.
#[inline]
fn rank(i: u32) -> u32 {
    i.wrapping_mul(0x9E37_79B1)
}

/// Whether entry `b` beats entry `a`: a larger value, or the same value
/// and a higher [`rank`].
#[inline]
fn beats(b: Entry, a: Entry) -> bool {
    b.0 > a.0 || (b.0 == a.0 && rank(b.1) > rank(a.1))
}

/// The larger entry.
#[inline]
fn larger(a: Entry, b: Entry) -> Entry {
    if beats(b, a) {
        b
    } else {
        a
    }
}

/// The cell with the largest finite value of a map, after the changes of
/// the last front are [flushed](FarthestCell::flush).
#[derive(Debug, Clone)]
pub(crate) struct FarthestCell {
    /// Cells of the map.
    n: usize,
    /// Leaves of the tree (a power of two, at least the chunk count).
    leaves: usize,
    /// `tree[1]` is the root, `tree[leaves + c]` chunk `c`'s best entry.
    tree: Vec<Entry>,
    /// Chunks marked since the last flush.
    dirty: Vec<u32>,
    /// Whether each chunk is in `dirty`.
    is_dirty: Vec<bool>,
}

impl FarthestCell {
    /// An empty tree for a map of `n` cells (no finite value yet).
    pub(crate) fn new(n: usize) -> Self {
        let chunks = n.div_ceil(1 << CHUNK_BITS).max(1);
        let leaves = chunks.next_power_of_two();
        Self {
            n,
            leaves,
            tree: vec![NONE; 2 * leaves],
            dirty: Vec::new(),
            is_dirty: vec![false; chunks],
        }
    }

    /// Notes that cell `i`'s value changed.
    #[inline]
    pub(crate) fn mark(&mut self, i: usize) {
        let c = i >> CHUNK_BITS;
        if !self.is_dirty[c] {
            self.is_dirty[c] = true;
            self.dirty.push(c as u32);
        }
    }

    /// Scans the marked chunks of `u` again and replays their paths.
    pub(crate) fn flush(&mut self, u: &[f64]) {
        while let Some(c) = self.dirty.pop() {
            let c = c as usize;
            self.is_dirty[c] = false;
            self.update(c, u);
        }
    }

    /// Builds the whole tree from `u`.
    pub(crate) fn rebuild(&mut self, u: &[f64]) {
        self.dirty.clear();
        self.is_dirty.fill(false);
        for c in 0..self.is_dirty.len() {
            self.tree[self.leaves + c] = self.scan(c, u);
        }
        for k in (1..self.leaves).rev() {
            self.tree[k] = larger(self.tree[2 * k], self.tree[2 * k + 1]);
        }
    }

    /// Forgets every value.
    pub(crate) fn clear(&mut self) {
        self.tree.fill(NONE);
        self.dirty.clear();
        self.is_dirty.fill(false);
    }

    /// The cell with the largest finite value and that value.
    pub(crate) fn peek(&self) -> Option<(usize, f64)> {
        let (v, i) = self.tree[1];
        (i != u32::MAX).then_some((i as usize, v))
    }

    /// The best finite entry of chunk `c`.
    fn scan(&self, c: usize, u: &[f64]) -> Entry {
        let start = c << CHUNK_BITS;
        let end = ((c + 1) << CHUNK_BITS).min(self.n);
        let mut best = NONE;
        for (k, &v) in u[start..end].iter().enumerate() {
            let e = (v, (start + k) as u32);
            if v < f64::INFINITY && beats(e, best) {
                best = e;
            }
        }
        best
    }

    fn update(&mut self, c: usize, u: &[f64]) {
        let mut k = self.leaves + c;
        self.tree[k] = self.scan(c, u);
        while k > 1 {
            k /= 2;
            self.tree[k] = larger(self.tree[2 * k], self.tree[2 * k + 1]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// After any sequence of lowered cells and flushes, the tree names
        /// the largest finite value and, among its cells, the highest
        /// ranked, as a scan does.
        #[test]
        fn it_names_the_largest_finite_value(
            n in 1usize..700,
            steps in proptest::collection::vec((0usize..700, 0u8..8), 0..300),
        ) {
            let mut u = vec![f64::INFINITY; n];
            let mut far = FarthestCell::new(n);
            for (k, (i, v)) in steps.into_iter().enumerate() {
                let i = i % n;
                // Values from a small set, so that ties happen.
                u[i] = u[i].min(f64::from(v));
                far.mark(i);
                if k % 3 == 0 {
                    far.flush(&u);
                    let want = u
                        .iter()
                        .enumerate()
                        .filter(|(_, v)| v.is_finite())
                        .fold(None, |best: Option<(usize, f64)>, (i, &v)| match best {
                            Some((j, b)) if b > v || (b == v && rank(j as u32) > rank(i as u32)) => {
                                best
                            }
                            _ => Some((i, v)),
                        });
                    prop_assert_eq!(far.peek(), want);
                    let mut fresh = FarthestCell::new(n);
                    fresh.rebuild(&u);
                    prop_assert_eq!(fresh.peek(), want);
                }
            }
            far.clear();
            prop_assert_eq!(far.peek(), None);
        }
    }
}
