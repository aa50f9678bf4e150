//! Radix sort for integer keys, used where comparison sorts of millions of
//! Morton keys would dominate.

/// Sorts `v` ascending, looking only at bits `lo..hi` (the caller knows the
/// other bits are equal in all keys). Uses `tmp` as scratch.
pub fn radix_sort_bits(v: &mut Vec<u64>, tmp: &mut Vec<u64>, lo: u32, hi: u32) {
    const DIGIT: u32 = 11;
    const BUCKETS: usize = 1 << DIGIT;
    if v.len() < 256 {
        v.sort_unstable();
        return;
    }
    // All digit histograms in one read of the keys, then one scatter per
    // digit that is not constant.
    let digits = hi.saturating_sub(lo).div_ceil(DIGIT) as usize;
    let mut counts = vec![[0usize; BUCKETS]; digits];
    for &k in v.iter() {
        for (d, c) in counts.iter_mut().enumerate() {
            c[((k >> (lo + d as u32 * DIGIT)) as usize) & (BUCKETS - 1)] += 1;
        }
    }
    let n = v.len();
    // Scratch is fully overwritten by each scatter, so its old contents do
    // not matter; only its length must match.
    if tmp.len() != n {
        tmp.clear();
        tmp.resize(n, 0);
    }
    for (d, count) in counts.iter_mut().enumerate() {
        if count.contains(&n) {
            continue; // this digit is the same everywhere
        }
        let shift = lo + d as u32 * DIGIT;
        let mut sum = 0;
        for c in count.iter_mut() {
            let m = *c;
            *c = sum;
            sum += m;
        }
        for &k in v.iter() {
            let b = ((k >> shift) as usize) & (BUCKETS - 1);
            tmp[count[b]] = k;
            count[b] += 1;
        }
        std::mem::swap(v, tmp);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sorts_like_std() {
        let mut x = 0x9e37_79b9_7f4a_7c15u64;
        let mut v: Vec<u64> = (0..10_000)
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                (x >> 3) << 5 | 7
            })
            .collect();
        let mut w = v.clone();
        w.sort_unstable();
        radix_sort_bits(&mut v, &mut Vec::new(), 5, 64);
        assert_eq!(v, w);
    }

    #[test]
    fn sorts_a_bit_range_with_constant_digits() {
        // Bits below `lo` and above `hi` equal in all keys; some digits in
        // between constant too.
        let mut x = 12_345u64;
        let mut v: Vec<u64> = (0..5_000)
            .map(|_| {
                x = x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
                ((x >> 20) & 0x7ff) << 42 | ((x >> 40) & 0xff) << 21 | 0b1_0101
            })
            .collect();
        let mut w = v.clone();
        w.sort_unstable();
        let mut tmp = vec![7; 3];
        radix_sort_bits(&mut v, &mut tmp, 20, 57);
        assert_eq!(v, w);
    }
}
