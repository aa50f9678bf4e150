//! Fast, fixed hashes: a hasher for maps whose keys are a few machine
//! words, and keyed sums, the digests of surfaces and checkpoint files.

use std::collections::{HashMap, HashSet};
use std::hash::BuildHasherDefault;

/// A fast, fixed hash: each word of the key folded into the state by an
/// exclusive or and a full-width multiplication whose halves are folded
/// together. Not for keys an adversary picks; for the snap's welding maps
/// and feature cells and the gathered mesh's node maps, whose order never
/// shows (the outputs follow the triangles' or the elements' order).
#[derive(Default)]
pub(crate) struct FoldHasher(u64);

impl std::hash::Hasher for FoldHasher {
    #[inline]
    fn finish(&self) -> u64 {
        self.0
    }
    #[inline]
    fn write(&mut self, bytes: &[u8]) {
        for c in bytes.chunks(8) {
            let mut w = [0u8; 8];
            w[..c.len()].copy_from_slice(c);
            self.write_u64(u64::from_le_bytes(w));
        }
    }
    #[inline]
    fn write_u64(&mut self, x: u64) {
        // The full 128-bit product, its halves folded: hash tables index by
        // the low bits, and a 64-bit product's low bits see only the key's
        // low bits (all zero in the Morton keys of a coarse lattice).
        let m = u128::from(self.0 ^ x) * 0x9e37_79b9_7f4a_7c15;
        self.0 = (m as u64) ^ ((m >> 64) as u64);
    }
}

/// A map with [`FoldHasher`].
pub(crate) type FoldMap<K, V> = HashMap<K, V, BuildHasherDefault<FoldHasher>>;

/// A set with [`FoldHasher`].
pub(crate) type FoldSet<K> = HashSet<K, BuildHasherDefault<FoldHasher>>;

/// The odd multiplier that spreads positions over the 64 bits (2^64 over
/// the golden ratio).
const GOLDEN: u64 = 0x9e37_79b9_7f4a_7c15;

/// MurmurHash3's 64-bit finaliser: a bijection of `u64` in which every input
/// bit changes about half the output bits.
#[inline]
pub const fn mix64(mut x: u64) -> u64 {
    x ^= x >> 33;
    x = x.wrapping_mul(0xff51_afd7_ed55_8ccd);
    x ^= x >> 33;
    x = x.wrapping_mul(0xc4ce_b9fe_1a85_ec53);
    x ^ (x >> 33)
}

/// The share of `word` at `position` in a keyed sum: a digest of words is
/// the wrapping sum of the shares of its words. Sums of pieces add up, so
/// a digest can be computed by ranks holding different pieces; and for a
/// fixed position the share is a bijection of the word, so changing any
/// one word always changes the digest.
#[inline]
pub const fn keyed_share(word: u64, position: u64) -> u64 {
    mix64(word ^ position.wrapping_add(1).wrapping_mul(GOLDEN))
}

/// The keyed sum of `words` placed from `position` on.
pub fn keyed_sum(words: impl IntoIterator<Item = u64>, position: u64) -> u64 {
    let mut s = 0u64;
    for (k, w) in words.into_iter().enumerate() {
        s = s.wrapping_add(keyed_share(w, position + k as u64));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::hash::{BuildHasher, Hasher};

    #[test]
    fn keyed_sums_split_and_see_one_changed_word() {
        let words: Vec<u64> = (0..100u64).map(|i| i * i).collect();
        let whole = keyed_sum(words.iter().copied(), 7);
        let parts = keyed_sum(words[..40].iter().copied(), 7)
            .wrapping_add(keyed_sum(words[40..].iter().copied(), 47));
        assert_eq!(whole, parts);
        for bit in [0, 13, 63] {
            let mut w = words.clone();
            w[50] ^= 1 << bit;
            assert_ne!(keyed_sum(w, 7), whole);
        }
        // Positions count: swapped words differ.
        let mut w = words.clone();
        w.swap(3, 4);
        assert_ne!(keyed_sum(w, 7), whole);
    }

    /// Keys that differ only in their high bits (Morton keys of a coarse
    /// lattice) spread over a table's low index bits.
    #[test]
    fn keys_with_zero_low_bits_spread() {
        let build = BuildHasherDefault::<FoldHasher>::default();
        let mut low = HashSet::new();
        for k in 0u64..4096 {
            let mut h = build.build_hasher();
            h.write_u64(k << 30);
            low.insert(h.finish() & 0xffff);
        }
        assert!(
            low.len() > 4000,
            "{} distinct low halves of 4096",
            low.len()
        );
    }
}
