//! The sets the mesh build keeps per leaf: the leaves around a rank in one
//! sequence ([`Merged`]), one bit per item ([`Bits`]) and a subset with its
//! ranks ([`Ranks`]).

use crate::octree::octant::Octant;

/// The merged run of leaves the traversal works on: ghosts of lower ranks,
/// the local leaves, the other ghosts, without copying them into one array
/// (or the same for something per leaf, such as its class).
#[derive(Clone, Copy)]
pub(crate) struct Merged<'a, T: Copy = Octant> {
    /// Ghosts before the local range.
    pub before: &'a [T],
    /// The local leaves.
    pub local: &'a [T],
    /// Ghosts after it.
    pub after: &'a [T],
}

impl<T: Copy> Merged<'_, T> {
    /// Number of leaves.
    pub fn len(&self) -> usize {
        self.before.len() + self.local.len() + self.after.len()
    }

    /// Leaf `i`.
    #[inline]
    pub fn get(&self, i: usize) -> T {
        let b = self.before.len();
        if i < b {
            self.before[i]
        } else if i < b + self.local.len() {
            self.local[i - b]
        } else {
            self.after[i - b - self.local.len()]
        }
    }

    /// The three runs in merged order: before, local, after.
    pub fn parts(&self) -> [&[T]; 3] {
        [self.before, self.local, self.after]
    }

    /// Merged indices of the local leaves.
    pub fn local_range(&self) -> std::ops::Range<usize> {
        self.before.len()..self.before.len() + self.local.len()
    }
}

/// One bit per entry.
pub(crate) struct Bits {
    words: Vec<u64>,
}

impl Bits {
    /// `n` entries from `f`.
    pub fn from_fn(n: usize, mut f: impl FnMut(usize) -> bool) -> Bits {
        let mut words = vec![0u64; n.div_ceil(64)];
        for (w, word) in words.iter_mut().enumerate() {
            for b in 0..64.min(n - 64 * w) {
                *word |= (f(64 * w + b) as u64) << b;
            }
        }
        Bits { words }
    }

    /// `n` entries, none set.
    pub fn new(n: usize) -> Bits {
        Bits {
            words: vec![0; n.div_ceil(64)],
        }
    }

    /// Entry `i`.
    #[inline]
    pub fn get(&self, i: usize) -> bool {
        self.words[i >> 6] >> (i & 63) & 1 == 1
    }

    /// Sets entry `i`.
    #[inline]
    pub fn set(&mut self, i: usize) {
        self.words[i >> 6] |= 1 << (i & 63);
    }

    /// Appends the set entries among `lo..=hi` to `out` in increasing
    /// order and clears them.
    pub fn drain_into(&mut self, lo: usize, hi: usize, out: &mut Vec<u32>) {
        if lo > hi {
            return;
        }
        for w in lo >> 6..=hi >> 6 {
            let mut bits = std::mem::take(&mut self.words[w]);
            while bits != 0 {
                out.push((w * 64) as u32 + bits.trailing_zeros());
                bits &= bits - 1;
            }
        }
    }
}

/// A set of entries numbered in order: `rank(i)` is the number of members
/// before `i`. One bit and half a byte per entry instead of a `u32` map.
pub(crate) struct Ranks {
    bits: Bits,
    before: Vec<u32>,
    count: u32,
    // Every entry a member: the rank is the index (the usual case on one
    // rank), without touching the bits.
    full: bool,
}

impl Ranks {
    /// Appends to `out` the entries of `v` (one per entry of the set) that
    /// are members, in order: whole words of members at a time.
    pub fn select<T: Copy>(&self, v: &[T], out: &mut Vec<T>) {
        if self.full {
            out.extend_from_slice(v);
            return;
        }
        for (w, &word) in self.bits.words.iter().enumerate() {
            let base = 64 * w;
            if word == u64::MAX {
                out.extend_from_slice(&v[base..base + 64]);
                continue;
            }
            let mut rest = word;
            while rest != 0 {
                out.push(v[base + rest.trailing_zeros() as usize]);
                rest &= rest - 1;
            }
        }
    }

    /// The members among `n` entries, given by `f`.
    pub fn from_fn(n: usize, f: impl FnMut(usize) -> bool) -> Ranks {
        let bits = Bits::from_fn(n, f);
        let mut before = Vec::with_capacity(bits.words.len());
        let mut count = 0u32;
        for w in &bits.words {
            before.push(count);
            count += w.count_ones();
        }
        Ranks {
            bits,
            before,
            count,
            full: count as usize == n,
        }
    }

    /// Whether `i` is a member.
    #[inline]
    pub fn contains(&self, i: usize) -> bool {
        self.full || self.bits.get(i)
    }

    /// Members before `i`.
    #[inline]
    pub fn rank(&self, i: usize) -> u32 {
        if self.full {
            return i as u32;
        }
        let w = self.bits.words[i >> 6] & ((1u64 << (i & 63)) - 1);
        self.before[i >> 6] + w.count_ones()
    }

    /// Members before `i`, and whether `i` is one, without a branch.
    #[inline]
    pub fn rank_member(&self, i: usize) -> (u32, bool) {
        let word = self.bits.words[i >> 6];
        let below = word & ((1u64 << (i & 63)) - 1);
        (
            self.before[i >> 6] + below.count_ones(),
            word >> (i & 63) & 1 == 1,
        )
    }

    /// Whether every entry is a member.
    pub fn is_full(&self) -> bool {
        self.full
    }

    /// Number of members.
    pub fn count(&self) -> u32 {
        self.count
    }
}
