//! Morton-order partition: contiguous runs of leaves, equal counts or equal
//! weights, moved with one `alltoallv`.
//!
//! Leaf `i` (global Morton index, or global prefix of weights `s_i` with
//! total `W`) goes to rank `floor(s_i * P / W)`. That destination never
//! decreases along the Morton order, so ranks keep contiguous ranges, and it
//! depends only on the global sequence of weights, never on the current
//! partition: partitioning twice gives the same result as once.

use crate::error::{Error, Result};
use crate::octant::Octant;
use crate::octree::LinearOctree;

/// What a partition did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PartitionStats {
    /// Leaves this rank sent to other ranks.
    pub sent: u64,
    /// Leaves this rank received from other ranks.
    pub received: u64,
}

/// Destination rank of each item, given its global exclusive prefix of
/// weights `prefix` and the global total `total`.
#[inline]
pub fn destination(prefix: u64, total: u64, ranks: usize) -> usize {
    if total == 0 {
        return 0;
    }
    ((prefix as u128 * ranks as u128) / total as u128).min(ranks as u128 - 1) as usize
}

/// First index of each of `parts` contiguous parts of `weights` (with
/// `weights.len()` appended), by the rule of the module documentation.
pub fn split_by_weight(weights: &[u64], parts: usize) -> Vec<usize> {
    let total: u64 = weights.iter().sum();
    let mut bounds = vec![weights.len(); parts + 1];
    let mut prefix = 0u64;
    let mut next = 0usize;
    for (i, &w) in weights.iter().enumerate() {
        let d = destination(prefix, total, parts);
        while next <= d {
            bounds[next] = i;
            next += 1;
        }
        prefix += w;
    }
    bounds
}

impl LinearOctree {
    /// Gives every rank the same number of leaves (within one). Collective.
    pub fn partition(&mut self) -> Result<PartitionStats> {
        let n = self.global_len();
        let p = self.comm().size();
        let first = self.global_offsets()[self.comm().rank()];
        let last = first + self.local_len() as u64;
        // Rank q receives global indices [ceil(q n / p), ceil((q+1) n / p)),
        // the indices whose destination is q.
        let start = |q: usize| ((q as u128 * n as u128).div_ceil(p as u128)) as u64;
        let counts = (0..p)
            .map(|q| {
                let (a, b) = (start(q).max(first), start(q + 1).min(last));
                b.saturating_sub(a) as usize
            })
            .collect();
        self.send_counts(counts)
    }

    /// Gives every rank about the same total weight; `weight` is called once
    /// per local leaf. The sum of the weights over all leaves must fit in a
    /// `u64`; otherwise every rank fails with an
    /// [`crate::ErrorKind::InvalidArgument`] error and nothing moves.
    /// Collective.
    pub fn partition_weighted(&mut self, weight: impl Fn(Octant) -> u64) -> Result<PartitionStats> {
        let w: Vec<u64> = self.leaves().iter().map(|&o| weight(o)).collect();
        // u64::MAX stands for a local sum that overflows; it makes the
        // total overflow too, on every rank alike.
        let local = w
            .iter()
            .try_fold(0u64, |a, &x| a.checked_add(x))
            .unwrap_or(u64::MAX);
        let sums = self.comm().allgather_u64(local);
        let r = self.comm().rank();
        let total = sums
            .iter()
            .try_fold(0u64, |a, &x| a.checked_add(x))
            .filter(|&t| t < u64::MAX)
            .ok_or_else(|| {
                Error::invalid(
                    "the partition weights add up to more than 2^64 - 2 over all leaves; \
                     use smaller weights",
                )
            })?;
        let mut prefix: Vec<u64> = Vec::with_capacity(w.len());
        let mut acc: u64 = sums[..r].iter().sum();
        for &x in &w {
            prefix.push(acc);
            acc += x;
        }
        let p = self.comm().size();
        self.redistribute(|i| destination(prefix[i], total, p))
    }

    /// Sends local leaf `i` to rank `dest(i)` (non-decreasing in `i`).
    fn redistribute(&mut self, dest: impl Fn(usize) -> usize) -> Result<PartitionStats> {
        let mut counts = vec![0usize; self.comm().size()];
        for i in 0..self.local_len() {
            counts[dest(i)] += 1;
        }
        self.send_counts(counts)
    }

    /// Sends the first `counts[0]` local leaves to rank 0, the next
    /// `counts[1]` to rank 1, and so on.
    fn send_counts(&mut self, counts: Vec<usize>) -> Result<PartitionStats> {
        let me = self.comm().rank();
        let sent = (self.local_len() - counts[me]) as u64;
        let mut moving = [sent];
        self.comm().sum_u64(&mut moving);
        if moving[0] == 0 {
            return Ok(PartitionStats::default());
        }
        // Destinations grow with the Morton index, so this rank sends a
        // prefix to lower ranks and a suffix to higher ones and keeps the
        // middle in place: only moving leaves are copied.
        let lo: usize = counts[..me].iter().sum();
        let hi = lo + counts[me];
        let keys = Octant::as_keys(self.leaves());
        let mut send = Vec::with_capacity(keys.len() - counts[me]);
        send.extend_from_slice(&keys[..lo]);
        send.extend_from_slice(&keys[hi..]);
        let mut out_counts = counts;
        out_counts[me] = 0;
        let (recv, rc) = self.comm().alltoallv_u64(&send, &out_counts);
        drop(send);
        let received = recv.len() as u64;
        // Leaves from lower ranks come first in Morton order.
        let before: usize = rc[..me].iter().sum();
        let balanced = self.balanced();
        let mut leaves = self.take_leaves();
        leaves.truncate(hi);
        leaves.splice(..lo, recv[..before].iter().map(|&k| Octant::from_key(k)));
        leaves.extend(recv[before..].iter().map(|&k| Octant::from_key(k)));
        self.set_leaves(leaves);
        self.set_balanced(balanced);
        self.refresh()?;
        Ok(PartitionStats { sent, received })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_is_contiguous_and_even() {
        let w = vec![1u64; 10];
        assert_eq!(split_by_weight(&w, 3), vec![0, 4, 7, 10]);
        let w = vec![5, 0, 0, 1, 1, 1, 1, 1];
        let b = split_by_weight(&w, 2);
        assert_eq!(b, vec![0, 1, 8]);
        assert_eq!(split_by_weight(&[], 2), vec![0, 0, 0]);
    }

    #[test]
    fn destination_is_monotone() {
        let mut last = 0;
        for i in 0..1000 {
            let d = destination(i, 1000, 7);
            assert!(d >= last && d < 7);
            last = d;
        }
    }
}
