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
    tmp.clear();
    tmp.resize(v.len(), 0);
    let mut shift = lo;
    while shift < hi {
        let mut count = [0usize; BUCKETS];
        for &k in v.iter() {
            count[((k >> shift) as usize) & (BUCKETS - 1)] += 1;
        }
        if count.contains(&v.len()) {
            shift += DIGIT; // this digit is the same everywhere
            continue;
        }
        let mut sum = 0;
        for c in count.iter_mut() {
            let n = *c;
            *c = sum;
            sum += n;
        }
        for &k in v.iter() {
            let d = ((k >> shift) as usize) & (BUCKETS - 1);
            tmp[count[d]] = k;
            count[d] += 1;
        }
        std::mem::swap(v, tmp);
        shift += DIGIT;
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
}
