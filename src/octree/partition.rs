//! Morton-order partition: contiguous runs of leaves, equal counts or equal
//! weights, moved with one `alltoallv`.
//!
//! Leaf `i` (global Morton index, or global prefix of weights `s_i` with
//! total `W`) goes to rank `floor(s_i * P / W)`. That destination never
//! decreases along the Morton order, so ranks keep contiguous ranges, and it
//! depends only on the global sequence of weights, never on the current
//! partition: partitioning twice gives the same result as once.

use crate::error::{Error, Result};
use crate::octree::octant::Octant;
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

    /// Gives every rank about the same number of leaves, but never splits a
    /// family of eight sibling leaves between ranks, so that
    /// [`LinearOctree::coarsen`] and [`LinearOctree::adapt`] can coarsen
    /// every family afterwards. The result is identical to p4est's
    /// `p8est_partition_ext (p8est, 1, NULL)`, see
    /// [`coarsening_cut`] for the rule. One rank: nothing to do. Collective.
    pub fn partition_for_coarsening(&mut self) -> Result<PartitionStats> {
        if self.comm().size() == 1 {
            return Ok(PartitionStats::default());
        }
        let (n, p) = (self.global_len(), self.comm().size());
        // p4est's equal split: rank q from floor(q n / p). (`partition`
        // rounds up instead; both are even within one leaf.)
        let cuts = (0..=p)
            .map(|q| (q as u128 * n as u128 / p as u128) as u64)
            .collect();
        self.keep_families(cuts)
    }

    /// [`LinearOctree::partition_for_coarsening`] by weight: about the same
    /// total weight per rank, `weight` called once per local leaf, then no
    /// family split; identical to p4est's `p8est_partition_ext (p8est, 1,
    /// weight_fn)`. Its split is p4est's, which rounds the ranks' shares of
    /// the weight down where [`LinearOctree::partition_weighted`] rounds them
    /// up: rank q starts at the first leaf whose exclusive prefix of weights
    /// reaches `floor(q W / P)`, and the last rank ends at the last leaf. When
    /// every weight is 0 nothing moves (as in p4est). The sum must fit in a
    /// `u64`, as for [`LinearOctree::partition_weighted`]. Collective.
    pub fn partition_for_coarsening_weighted(
        &mut self,
        weight: impl Fn(Octant) -> u64,
    ) -> Result<PartitionStats> {
        let w: Vec<u64> = self.leaves().iter().map(|&o| weight(o)).collect();
        let (sums, total) = self.weight_sums(&w)?;
        let p = self.comm().size();
        if p == 1 || total == 0 {
            return Ok(PartitionStats::default());
        }
        let me = self.comm().rank();
        let first = self.global_offsets()[me];
        let before: u64 = sums[..me].iter().sum();
        // The rank whose weights reach a share finds where; the others
        // contribute 0 to the maximum.
        let mut cuts = vec![0u64; p + 1];
        cuts[p] = self.global_len();
        let mut acc = before;
        let mut k = 0;
        for (q, cut) in cuts.iter_mut().enumerate().take(p).skip(1) {
            let share = (total as u128 * q as u128 / p as u128) as u64;
            if share == 0 || !(before < share && share <= before + sums[me]) {
                continue;
            }
            // The first local k >= 1 with before + w[..k] >= share.
            while acc < share {
                acc += w[k];
                k += 1;
            }
            *cut = first + k as u64;
        }
        self.comm().max_u64(&mut cuts[1..p]);
        self.keep_families(cuts)
    }

    /// Moves the leaves to the ranks of `cuts` (first global leaf of each
    /// rank, the total appended), each cut inside a family first moved by
    /// [`coarsening_cut`].
    fn keep_families(&mut self, cuts: Vec<u64>) -> Result<PartitionStats> {
        let (n, p) = (self.global_len(), self.comm().size());
        // Rank q decides its own cut from the leaves [c - 7, c + 7) around
        // it: the family of leaf c, if complete, lies inside.
        let me = self.comm().rank();
        let first = self.global_offsets()[me];
        let last = first + self.local_len() as u64;
        let window = |q: usize| {
            let c = cuts[q];
            if q == 0 || c == cuts[q + 1] {
                (c, c)
            } else {
                (c.saturating_sub(7), (c + 7).min(n))
            }
        };
        let keys = Octant::as_keys(self.leaves());
        let mut send = Vec::new();
        let mut counts = vec![0usize; p];
        for (q, count) in counts.iter_mut().enumerate() {
            let (a, b) = window(q);
            let (a, b) = (a.max(first), b.min(last));
            if a < b {
                send.extend_from_slice(&keys[(a - first) as usize..(b - first) as usize]);
                *count = (b - a) as usize;
            }
        }
        // Ranks send in rank order, which is the global order.
        let (near, _) = self.comm().alltoallv_u64(&send, &counts);
        let (lo, _) = window(me);
        let near: Vec<Octant> = near.into_iter().map(Octant::from_key).collect();
        let mine = if lo == cuts[me] {
            cuts[me]
        } else {
            coarsening_cut(&cuts, me, &near, lo)
        };
        let moved = self.comm().allgather_u64(mine);
        // Ranks that the split leaves empty stay empty; a non-empty
        // rank ends where the next non-empty one starts.
        let mut start = vec![n; p + 1];
        for q in (0..p).rev() {
            start[q] = if cuts[q] < cuts[q + 1] {
                moved[q]
            } else {
                start[q + 1]
            };
        }
        let counts = (0..p)
            .map(|q| {
                let (a, b) = (start[q].max(first), start[q + 1].min(last));
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
        let (sums, total) = self.weight_sums(&w)?;
        let r = self.comm().rank();
        let mut prefix: Vec<u64> = Vec::with_capacity(w.len());
        let mut acc: u64 = sums[..r].iter().sum();
        for &x in &w {
            prefix.push(acc);
            acc += x;
        }
        let p = self.comm().size();
        self.redistribute(|i| destination(prefix[i], total, p))
    }

    /// Each rank's sum of `w` (this rank's weights) and the total, or the
    /// same error on every rank when the total does not fit. Collective.
    fn weight_sums(&self, w: &[u64]) -> Result<(Vec<u64>, u64)> {
        // u64::MAX stands for a local sum that overflows; it makes the
        // total overflow too, on every rank alike.
        let local = w
            .iter()
            .try_fold(0u64, |a, &x| a.checked_add(x))
            .unwrap_or(u64::MAX);
        let sums = self.comm().allgather_u64(local);
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
        Ok((sums, total))
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

/// Where [`LinearOctree::partition_for_coarsening`] puts the start of
/// rank `q`, given the equal split `cuts` (first global leaf of each rank,
/// with the total appended) and the global leaves `near[i]` = leaf `lo + i`
/// around `cuts[q]`, which must hold leaves `cuts[q] - 7 ..= cuts[q] + 6`
/// where they exist.
///
/// The rule of p4est's `p4est_partition_for_coarsening` and
/// `p4est_partition_correction`: if leaf `c = cuts[q]` belongs to a complete
/// family of eight leaves `f..f + 8` that it does not start, the cut moves
/// to one end of the family: the family goes to the rank that the equal
/// split gives most of its leaves (the lowest such rank on a tie), so the
/// cut moves up to `f + 8` when that rank is below `q` and down to `f`
/// otherwise.
pub fn coarsening_cut(cuts: &[u64], q: usize, near: &[Octant], lo: u64) -> u64 {
    let c = cuts[q];
    let at = |g: u64| near.get(g.checked_sub(lo)? as usize).copied();
    let Some(leaf) = at(c) else { return c };
    let k = leaf.child_id() as u64;
    if leaf.level() == 0 || k == 0 {
        return c;
    }
    let (min, max) = (c - k, c - k + 7);
    let parent = leaf.parent();
    if !(0..8).all(|j| at(min + j) == Some(parent.child(j as u32))) {
        return c;
    }
    // Leaves of the family each rank holds under the equal split; p4est
    // searches down from q (ties to the lower rank), then up (strictly more).
    let held = |r: usize| {
        let (a, b) = (cuts[r].max(min), cuts[r + 1].min(max + 1));
        b.saturating_sub(a)
    };
    let (mut best, mut most) = (q, held(q));
    for r in (0..q).rev().take_while(|&r| min < cuts[r + 1]) {
        if held(r) >= most {
            (best, most) = (r, held(r));
        }
    }
    for r in (best + 1..cuts.len() - 1).take_while(|&r| cuts[r] <= max) {
        if held(r) > most {
            (best, most) = (r, held(r));
        }
    }
    if best < q {
        max + 1
    } else {
        min
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

    /// Leaves `lo..lo + 14` with a family of level-2 leaves at global
    /// indices `f..f + 8` and level-1 leaves (no family) elsewhere.
    fn around(lo: u64, f: u64) -> Vec<Octant> {
        let family = Octant::ROOT.child(5).children();
        (lo..lo + 14)
            .map(|g| match g.checked_sub(f) {
                Some(j) if j < 8 => family[j as usize],
                _ => Octant::ROOT.child((g % 3) as u32),
            })
            .collect()
    }

    #[test]
    fn coarsening_cut_moves_to_the_rank_holding_most() {
        let cuts = [0, 10, 20];
        // 5 of the family on rank 0, 3 on rank 1: up to the family's end.
        assert_eq!(coarsening_cut(&cuts, 1, &around(3, 5), 3), 13);
        // 2 and 6: down to its start.
        assert_eq!(coarsening_cut(&cuts, 1, &around(3, 8), 3), 8);
        // 4 and 4: p4est gives a tie to the lower rank.
        assert_eq!(coarsening_cut(&cuts, 1, &around(3, 6), 3), 14);
        // The cut at the family's first leaf, or the family incomplete.
        assert_eq!(coarsening_cut(&cuts, 1, &around(3, 10), 3), 10);
        let mut broken = around(3, 6);
        broken[10] = Octant::ROOT.child(5).child(7).child(0);
        assert_eq!(coarsening_cut(&cuts, 1, &broken, 3), 10);
        // Three ranks share a family: the middle one holds most.
        let cuts = [0, 9, 12, 30];
        assert_eq!(coarsening_cut(&cuts, 1, &around(2, 7), 2), 7);
        assert_eq!(coarsening_cut(&cuts, 2, &around(5, 7), 5), 15);
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
