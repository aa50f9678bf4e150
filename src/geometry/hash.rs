//! A fast, fixed hasher for maps whose keys are a few machine words.

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

#[cfg(test)]
mod tests {
    use super::*;
    use std::hash::{BuildHasher, Hasher};

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
