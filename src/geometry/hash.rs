//! Fast, fixed hashes: a hasher for maps whose keys are a few machine
//! words, keyed sums (the digests of surfaces and checkpoint headers) and
//! word sums (the checkpoints' block checksums).

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

/// The odd multiplier of [`word_share`].
const SHARE_MUL: u64 = 0xff51_afd7_ed55_8ccd;

/// The share of `word` at `position` in a word sum ([`word_sum`]): `x XOR
/// (x >> 32)` of `x = (word XOR (position + 1) GOLDEN) M` modulo 2^64,
/// `M` odd. For a fixed position a bijection of the word (an exclusive or,
/// a product by an odd number, an xorshift), like [`keyed_share`], at a
/// fraction of its cost: one product, which four lanes take side by side.
#[inline(always)]
pub const fn word_share(word: u64, position: u64) -> u64 {
    let x = (word ^ position.wrapping_add(1).wrapping_mul(GOLDEN)).wrapping_mul(SHARE_MUL);
    x ^ (x >> 32)
}

/// The wrapping sum of [`word_share`] over the little-endian 8-byte words
/// of `bytes` (a multiple of 8 long; a shorter tail is padded with zero
/// bytes), the first at `position`. Sums of pieces add up, as with
/// [`keyed_sum`]. Four lanes of 32 bytes, with AVX2 where the processor
/// has it (the same sum).
pub fn word_sum(bytes: &[u8], position: u64) -> u64 {
    #[cfg(target_arch = "x86_64")]
    if crate::parallel::cores::avx2() {
        // SAFETY: the processor has AVX2.
        return unsafe { word_sum_avx2(bytes, position) };
    }
    word_sum_lanes(bytes, position)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn word_sum_avx2(bytes: &[u8], position: u64) -> u64 {
    word_sum_lanes(bytes, position)
}

#[inline(always)]
fn word_sum_lanes(bytes: &[u8], position: u64) -> u64 {
    let word = |c: &[u8]| u64::from_le_bytes(c.try_into().expect("8 bytes"));
    let mut acc = [0u64; 4];
    let mut key: [u64; 4] = std::array::from_fn(|l| (position + 1 + l as u64).wrapping_mul(GOLDEN));
    let step = GOLDEN.wrapping_mul(4);
    let lanes = bytes.chunks_exact(32);
    let tail = lanes.remainder();
    for c in lanes {
        for l in 0..4 {
            let x = (word(&c[8 * l..8 * l + 8]) ^ key[l]).wrapping_mul(SHARE_MUL);
            acc[l] = acc[l].wrapping_add(x ^ (x >> 32));
            key[l] = key[l].wrapping_add(step);
        }
    }
    let mut s = acc.iter().fold(0u64, |a, &b| a.wrapping_add(b));
    let at = position + (bytes.len() / 32 * 4) as u64;
    for (k, c) in tail.chunks(8).enumerate() {
        let mut w = [0u8; 8];
        w[..c.len()].copy_from_slice(c);
        s = s.wrapping_add(word_share(u64::from_le_bytes(w), at + k as u64));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::hash::{BuildHasher, Hasher};

    #[test]
    fn word_sums_split_and_equal_the_shares() {
        let bytes: Vec<u8> = (0..1000u32).map(|i| (i * 7 + i / 5) as u8).collect();
        let whole = word_sum(&bytes, 11);
        let by_word = (0..125u64).fold(0u64, |s, k| {
            let w = u64::from_le_bytes(
                bytes[8 * k as usize..8 * k as usize + 8]
                    .try_into()
                    .unwrap(),
            );
            s.wrapping_add(word_share(w, 11 + k))
        });
        assert_eq!(whole, by_word);
        assert_eq!(whole, word_sum_lanes(&bytes, 11));
        for cut in [0usize, 8, 40, 96, 992] {
            let parts = word_sum(&bytes[..cut], 11)
                .wrapping_add(word_sum(&bytes[cut..], 11 + cut as u64 / 8));
            assert_eq!(parts, whole, "cut at {cut}");
        }
        for at in [0usize, 31, 32, 500, 999] {
            for bit in [0, 5, 7] {
                let mut b = bytes.clone();
                b[at] ^= 1 << bit;
                assert_ne!(word_sum(&b, 11), whole, "byte {at} bit {bit}");
            }
        }
        let mut b = bytes.clone();
        b.swap(0, 8);
        assert_ne!(word_sum(&b, 11), whole);
        // A short tail is padded with zeros.
        assert_eq!(
            word_sum(&bytes[..5], 3),
            word_share(
                u64::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3], bytes[4], 0, 0, 0]),
                3
            )
        );
    }

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
