//! A fast, fixed hasher for maps whose keys are a few machine words.

use std::collections::{HashMap, HashSet};
use std::hash::BuildHasherDefault;

/// A fast, fixed hash: each word of the key folded into the state by a
/// rotation, an exclusive or and a multiplication. Not for keys an
/// adversary picks; for the snap's welding maps and feature cells, whose
/// order never shows (the outputs follow the triangles' order).
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
        self.0 = (self.0.rotate_left(26) ^ x).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    }
}

/// A map with [`FoldHasher`].
pub(crate) type FoldMap<K, V> = HashMap<K, V, BuildHasherDefault<FoldHasher>>;

/// A set with [`FoldHasher`].
pub(crate) type FoldSet<K> = HashSet<K, BuildHasherDefault<FoldHasher>>;
