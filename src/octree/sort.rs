//! Radix sort for integer keys, used where comparison sorts of millions of
//! Morton keys would dominate.

/// Sorts `v` ascending, looking only at bits `lo..hi` (the caller knows the
/// other bits are equal in all keys). Uses `tmp` as scratch.
pub fn radix_sort_bits(v: &mut Vec<u64>, tmp: &mut Vec<u64>, lo: u32, hi: u32) {
    if v.len() < 256 {
        v.sort_unstable();
        return;
    }
    let mut counts = digit_counts(v, lo, hi);
    let n = v.len();
    // Scratch is fully overwritten by each scatter, so its old contents do
    // not matter; only its length must match.
    if tmp.len() != n {
        tmp.clear();
        tmp.resize(n, 0);
    }
    for (d, count) in counts.iter_mut().enumerate() {
        let Some(shift) = bucket_starts(count, n, lo, d) else {
            continue;
        };
        for &k in v.iter() {
            let b = ((k >> shift) as usize) & (BUCKETS - 1);
            tmp[count[b]] = k;
            count[b] += 1;
        }
        std::mem::swap(v, tmp);
    }
}

/// Bits per digit of the radix sorts.
const DIGIT: u32 = 11;
const BUCKETS: usize = 1 << DIGIT;

/// The histograms of every digit of bits `lo..hi` of `keys`, in one read.
fn digit_counts(keys: &[u64], lo: u32, hi: u32) -> Vec<[usize; BUCKETS]> {
    let digits = hi.saturating_sub(lo).div_ceil(DIGIT) as usize;
    let mut counts = vec![[0usize; BUCKETS]; digits];
    for &k in keys {
        for (d, c) in counts.iter_mut().enumerate() {
            c[((k >> (lo + d as u32 * DIGIT)) as usize) & (BUCKETS - 1)] += 1;
        }
    }
    counts
}

/// Turns digit `d`'s histogram `count` (of `n` keys) into bucket starts and
/// returns the digit's shift, or `None` when the digit is the same in every
/// key (no scatter needed).
fn bucket_starts(count: &mut [usize; BUCKETS], n: usize, lo: u32, d: usize) -> Option<u32> {
    if count.contains(&n) {
        return None;
    }
    let mut sum = 0;
    for c in count.iter_mut() {
        let m = *c;
        *c = sum;
        sum += m;
    }
    Some(lo + d as u32 * DIGIT)
}

/// Sorts `keys` ascending, carrying `vals` along (`vals[i]` goes where
/// `keys[i]` goes; equal keys keep their order), looking only at bits
/// `lo..hi` as [`radix_sort_bits`] does.
pub fn radix_sort_pairs_bits(keys: &mut Vec<u64>, vals: &mut Vec<u32>, lo: u32, hi: u32) {
    assert_eq!(keys.len(), vals.len());
    let n = keys.len();
    if n < 256 {
        let mut both: Vec<(u64, u32)> = keys.iter().copied().zip(vals.iter().copied()).collect();
        both.sort_by_key(|p| p.0);
        for (i, (k, v)) in both.into_iter().enumerate() {
            keys[i] = k;
            vals[i] = v;
        }
        return;
    }
    let mut counts = digit_counts(keys, lo, hi);
    // Scratch written in full by each scatter before it is read: left
    // uninitialized rather than zeroed first (tens of megabytes).
    let (mut tk, mut tv) = (Vec::<u64>::with_capacity(n), Vec::<u32>::with_capacity(n));
    for (d, count) in counts.iter_mut().enumerate() {
        let Some(shift) = bucket_starts(count, n, lo, d) else {
            continue;
        };
        {
            let (ok, ov) = (tk.spare_capacity_mut(), tv.spare_capacity_mut());
            for (&k, &v) in keys.iter().zip(vals.iter()) {
                let b = ((k >> shift) as usize) & (BUCKETS - 1);
                ok[count[b]].write(k);
                ov[count[b]].write(v);
                count[b] += 1;
            }
        }
        // SAFETY: the bucket starts partition 0..n, so the scatter wrote
        // every one of the first `n` slots of both.
        unsafe {
            tk.set_len(n);
            tv.set_len(n);
        }
        std::mem::swap(keys, &mut tk);
        std::mem::swap(vals, &mut tv);
        tk.clear();
        tv.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sorts_pairs_stably() {
        for n in [100usize, 50_000] {
            let mut x = 77u64;
            let keys: Vec<u64> = (0..n)
                .map(|_| {
                    x = x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
                    // Few distinct keys: many ties, whose order must stay.
                    (x >> 50) << 3 | 5
                })
                .collect();
            let mut want: Vec<(u64, u32)> = keys.iter().copied().zip(0u32..).collect();
            want.sort_by_key(|p| p.0);
            let (mut k, mut v) = (keys.clone(), (0..n as u32).collect::<Vec<_>>());
            radix_sort_pairs_bits(&mut k, &mut v, 3, 64);
            let got: Vec<(u64, u32)> = k.into_iter().zip(v).collect();
            assert_eq!(got, want);
        }
    }

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

/// The last index `j` with `key(j) <= m` among `n` keys sorted ascending,
/// searched outwards from `hint` by doubling steps: `O(log d)` for an
/// answer `d` places away, so neighbour look-ups in Morton order stay in
/// cache. `None` when every key is above `m`.
#[inline]
pub fn gallop_last_le(n: usize, hint: usize, m: u64, key: impl Fn(usize) -> u64) -> Option<usize> {
    if n == 0 {
        return None;
    }
    let hint = hint.min(n - 1);
    let (mut lo, mut hi);
    if key(hint) <= m {
        lo = hint;
        let mut step = 1;
        while lo + step < n && key(lo + step) <= m {
            lo += step;
            step *= 2;
        }
        hi = (lo + step).min(n);
    } else {
        hi = hint;
        let mut step = 1;
        while hi >= step && key(hi - step) > m {
            hi -= step;
            step *= 2;
        }
        lo = hi.saturating_sub(step);
        if key(lo) > m {
            return None;
        }
    }
    // key(lo) <= m < key(hi) (or hi == n): bisect.
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        if key(mid) <= m {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some(lo)
}

#[cfg(test)]
mod gallop_tests {
    use super::gallop_last_le;

    #[test]
    fn gallop_matches_partition_point() {
        let keys: Vec<u64> = (0..200).map(|i| 3 * i + (i % 3)).collect();
        for hint in [0, 1, 50, 199, 500] {
            for m in 0..700 {
                let want = keys.partition_point(|&k| k <= m).checked_sub(1);
                assert_eq!(
                    gallop_last_le(keys.len(), hint, m, |j| keys[j]),
                    want,
                    "hint {hint} m {m}"
                );
            }
        }
        assert_eq!(gallop_last_le(0, 0, 5, |_| 0), None);
    }
}
