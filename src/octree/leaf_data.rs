//! Per-leaf user data of a fixed size, kept beside the leaves in Morton
//! order, that survives adaptation, balance and partition.
//!
//! A [`LeafData`] holds `size` bytes for each local leaf of a
//! [`LinearOctree`], leaf `i`'s bytes at `[i * size, (i + 1) * size)`, in the
//! leaves' (Morton) order. The `*_with_data` methods of [`LinearOctree`]
//! change the leaves and the data together:
//!
//! - refinement, coarsening, adaptation and balance keep the data of every
//!   leaf that stays, and call a replace callback ([`Replace`]) for each
//!   leaf or group of leaves that goes: one leaf split into eight (refine,
//!   adapt) or into several (balance: 1 -> n), eight siblings merged into
//!   their parent (coarsen, adapt). A recursive coarsening calls it once
//!   per family, finest first, so a callback always sees 8 -> 1 there
//!   (p4est's `replace_fn`). The incoming data is zeroed before the call;
//!   a callback that does nothing leaves zeros;
//! - partition moves the data with its leaves, in an exchange beside the
//!   leaves' one with the same counts.
//!
//! The operation itself runs as without data (balance is not slowed); the
//! data is then brought over by walking the old and new leaves together in
//! Morton order. All callbacks of the operation's own (split, coarsen,
//! decide) are called before the first replace. If a replace callback
//! fails on any rank, every rank returns an error and the octree and the
//! data are as they were before the call.

use std::sync::Arc;

use crate::error::{Error, ErrorKind, Result};
use crate::octree::adapt::{Adapt, AdaptStats};
use crate::octree::balance::BalanceStats;
use crate::octree::octant::{Connectivity, Octant};
use crate::octree::partition::PartitionStats;
use crate::octree::LinearOctree;
use crate::parallel::comm::{agree, Comm};

/// Fixed-size user data per local leaf, in Morton order (see the module
/// documentation).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LeafData {
    size: usize,
    len: usize,
    bytes: Vec<u8>,
}

impl LeafData {
    /// Zeroed data of `size` bytes for each of `len` leaves.
    pub fn new(size: usize, len: usize) -> LeafData {
        LeafData {
            size,
            len,
            bytes: vec![0; size * len],
        }
    }

    /// Data of `size` bytes per leaf from `bytes`, leaf after leaf (a
    /// length that is a multiple of `size`; `size` 0 gives no leaves).
    pub fn from_bytes(size: usize, bytes: Vec<u8>) -> LeafData {
        let len = bytes.len().checked_div(size).unwrap_or(0);
        debug_assert_eq!(len * size, bytes.len());
        LeafData { size, len, bytes }
    }

    /// Zeroed data of `size` bytes for each local leaf of `tree`.
    pub fn for_tree(tree: &LinearOctree, size: usize) -> LeafData {
        LeafData::new(size, tree.local_len())
    }

    /// Data of `size` bytes per leaf of `tree`, leaf `i`'s bytes written by
    /// `init(leaves[i], bytes)`.
    pub fn from_fn(
        tree: &LinearOctree,
        size: usize,
        mut init: impl FnMut(Octant, &mut [u8]),
    ) -> LeafData {
        let mut d = LeafData::for_tree(tree, size);
        for (i, &o) in tree.leaves().iter().enumerate() {
            init(o, d.get_mut(i));
        }
        d
    }

    /// Bytes per leaf.
    pub fn size(&self) -> usize {
        self.size
    }

    /// Number of leaves.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether there are no leaves.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Leaf `i`'s bytes.
    pub fn get(&self, i: usize) -> &[u8] {
        &self.bytes[i * self.size..(i + 1) * self.size]
    }

    /// Leaf `i`'s bytes, to write.
    pub fn get_mut(&mut self, i: usize) -> &mut [u8] {
        &mut self.bytes[i * self.size..(i + 1) * self.size]
    }

    /// All bytes, leaf after leaf.
    pub fn as_bytes(&self) -> &[u8] {
        &self.bytes
    }

    /// All bytes, leaf after leaf, to write.
    pub fn as_bytes_mut(&mut self) -> &mut [u8] {
        &mut self.bytes
    }

    /// Fails unless there is one entry per local leaf of `tree`.
    /// Rank-local.
    fn check(&self, tree: &LinearOctree) -> Result<()> {
        if self.len != tree.local_len() {
            return Err(Error::invalid(format!(
                "the leaf data has {} entries for {} local leaves",
                self.len,
                tree.local_len()
            )));
        }
        Ok(())
    }

    /// Moves the data of a partition: the leaves of global indices
    /// `old[r]..old[r + 1]` were on rank `r` and are now on the rank whose
    /// range in `new` holds them. Collective.
    fn transfer(&mut self, comm: &dyn Comm, old: &[u64], new: &[u64]) {
        let (me, p) = (comm.rank(), comm.size());
        let n = (new[me + 1] - new[me]) as usize;
        if old == new {
            return; // nothing moved
        }
        if self.size == 0 {
            *self = LeafData::new(0, n);
            return;
        }
        let overlap = |a: u64, b: u64, c: u64, d: u64| (b.min(d)).saturating_sub(a.max(c)) as usize;
        let send: Vec<usize> = (0..p)
            .map(|q| overlap(old[me], old[me + 1], new[q], new[q + 1]))
            .collect();
        let recv: Vec<usize> = (0..p)
            .map(|r| overlap(old[r], old[r + 1], new[me], new[me + 1]))
            .collect();
        let s = self.size;
        let words = |leaves: usize| (leaves * s).div_ceil(8);
        // Leaves go in global order: a prefix to lower ranks, a suffix to
        // higher ones, the middle stays. Each block is padded to whole
        // words (the exchange is of u64).
        let mut buf = Vec::new();
        let mut counts = vec![0usize; p];
        let mut at = 0usize;
        for q in 0..p {
            let bytes = &self.bytes[at * s..(at + send[q]) * s];
            at += send[q];
            if q == me {
                continue;
            }
            counts[q] = words(send[q]);
            buf.extend(bytes.chunks(8).map(|c| {
                let mut w = [0u8; 8];
                w[..c.len()].copy_from_slice(c);
                u64::from_ne_bytes(w)
            }));
        }
        let lo: usize = send[..me].iter().sum();
        let (got, _) = comm.alltoallv_u64(&buf, &counts);
        drop(buf);
        // The middle stays where it is, as the leaves' does: the suffix
        // sent away is cut, the middle moves only by the difference between
        // the prefix sent and the prefix received (no second array whose
        // pages would all be faulted in).
        let received = |range: std::ops::Range<usize>| {
            let mut w: usize = recv[..range.start]
                .iter()
                .enumerate()
                .filter(|&(r, _)| r != me)
                .map(|(_, &k)| words(k))
                .sum();
            let mut out = Vec::new();
            for (r, &k) in recv.iter().enumerate().take(range.end).skip(range.start) {
                if r == me {
                    continue;
                }
                let block = &got[w..w + words(k)];
                w += words(k);
                out.extend(block.iter().flat_map(|x| x.to_ne_bytes()).take(k * s));
            }
            out
        };
        let before = received(0..me);
        let after = received(me + 1..p);
        let keep = send[me] * s;
        let bytes = &mut self.bytes;
        bytes.truncate((lo + send[me]) * s);
        if before.len() > lo * s {
            let grow = before.len() - lo * s;
            bytes.resize(bytes.len() + grow, 0);
            bytes.copy_within(lo * s..lo * s + keep, before.len());
        } else {
            bytes.copy_within(lo * s..lo * s + keep, before.len());
            bytes.truncate(before.len() + keep);
        }
        bytes[..before.len()].copy_from_slice(&before);
        bytes.extend_from_slice(&after);
        if bytes.capacity() > 2 * bytes.len() {
            bytes.shrink_to_fit();
        }
        debug_assert_eq!(bytes.len(), n * s);
        self.len = n;
    }
}

/// One replacement, handed to a replace callback: `outgoing` leaves (with
/// their data, [`Replace::size`] bytes each, in the same order) are
/// replaced by `incoming` leaves, whose data the callback writes (zeroed
/// before the call). Both lists are in Morton order and cover the same
/// region: one leaf and its eight children (refinement), eight siblings and
/// their parent (coarsening), or one leaf and the finer leaves balance put
/// in its place.
pub struct Replace<'a> {
    /// The leaves that go.
    pub outgoing: &'a [Octant],
    /// Their data, `size` bytes each.
    pub outgoing_data: &'a [u8],
    /// The leaves that come.
    pub incoming: &'a [Octant],
    /// Their data, `size` bytes each, to write.
    pub incoming_data: &'a mut [u8],
    size: usize,
}

impl Replace<'_> {
    /// Bytes per leaf.
    pub fn size(&self) -> usize {
        self.size
    }

    /// The data of outgoing leaf `i`.
    pub fn outgoing_datum(&self, i: usize) -> &[u8] {
        &self.outgoing_data[i * self.size..(i + 1) * self.size]
    }

    /// The data of incoming leaf `i`, to write.
    pub fn incoming_datum(&mut self, i: usize) -> &mut [u8] {
        &mut self.incoming_data[i * self.size..(i + 1) * self.size]
    }
}

/// A replace callback as the `*_with_data` methods take it.
pub type ReplaceFn<'a> = &'a mut dyn FnMut(Replace<'_>) -> Result<()>;

/// The data of `new` (leaves covering the same cells as `old`), by walking
/// both in Morton order: kept leaves keep their data, the others go through
/// `replace`. Rank-local.
pub(crate) fn remap(
    old: &[Octant],
    new: &[Octant],
    data: &LeafData,
    replace: ReplaceFn,
) -> Result<LeafData> {
    let s = data.size;
    let mut out = LeafData::new(s, new.len());
    let broken = || Error::new(ErrorKind::Internal, "leaf data: old and new leaves differ");
    let (mut i, mut j) = (0usize, 0usize);
    while i < old.len() {
        let (a, b) = (old[i], *new.get(j).ok_or_else(broken)?);
        if a == b {
            out.get_mut(j).copy_from_slice(data.get(i));
            i += 1;
            j += 1;
        } else if a.is_ancestor_of(b) {
            let k = j;
            while j < new.len() && a.is_ancestor_of(new[j]) {
                j += 1;
            }
            replace(Replace {
                outgoing: &old[i..i + 1],
                outgoing_data: data.get(i),
                incoming: &new[k..j],
                incoming_data: &mut out.bytes[k * s..j * s],
                size: s,
            })?;
            i += 1;
        } else if b.is_ancestor_of(a) {
            let k = i;
            while i < old.len() && b.is_ancestor_of(old[i]) {
                i += 1;
            }
            let (leaves, bytes) = (&old[k..i], &data.bytes[k * s..i * s]);
            coarsen_nested(leaves, bytes, s, out.get_mut(j), replace)?;
            j += 1;
        } else {
            return Err(broken());
        }
    }
    if j != new.len() {
        return Err(broken());
    }
    Ok(out)
}

/// Merges `leaves` (tiling one octant) into it family by family, finest
/// first, as a recursive coarsening does, writing the octant's data to
/// `dst`: each family is one 8 -> 1 replacement.
fn coarsen_nested(
    leaves: &[Octant],
    bytes: &[u8],
    s: usize,
    dst: &mut [u8],
    replace: ReplaceFn,
) -> Result<()> {
    let mut stack: Vec<Octant> = Vec::with_capacity(16);
    let mut sdata: Vec<u8> = Vec::with_capacity(16 * s);
    let mut parent_data = vec![0u8; s];
    for (i, &o) in leaves.iter().enumerate() {
        stack.push(o);
        sdata.extend_from_slice(&bytes[i * s..(i + 1) * s]);
        while let Some(start) = stack.len().checked_sub(8) {
            let fam = &stack[start..];
            let p = fam[0].parent();
            if fam[0].level() == 0 || !(0..8).all(|c| fam[c] == p.child(c as u32)) {
                break;
            }
            parent_data.fill(0);
            replace(Replace {
                outgoing: fam,
                outgoing_data: &sdata[start * s..],
                incoming: std::slice::from_ref(&p),
                incoming_data: &mut parent_data,
                size: s,
            })?;
            stack.truncate(start);
            sdata.truncate(start * s);
            stack.push(p);
            sdata.extend_from_slice(&parent_data);
        }
    }
    if stack.len() != 1 {
        return Err(Error::new(
            ErrorKind::Internal,
            "leaf data: coarsened leaves do not tile their parent",
        ));
    }
    dst.copy_from_slice(&sdata);
    Ok(())
}

impl LinearOctree {
    /// Runs `op`, which changes the local leaves without moving any to
    /// another rank, then brings `data` over to the new leaves through
    /// `replace` (see the module documentation). If `op` fails, nothing
    /// changed; if `replace` fails on any rank, the old leaves are put back
    /// and every rank fails. Collective.
    pub fn change_with_data<T>(
        &mut self,
        data: &mut LeafData,
        replace: ReplaceFn,
        op: impl FnOnce(&mut LinearOctree) -> Result<T>,
    ) -> Result<T> {
        agree(&**self.comm(), data.check(self))?;
        // The old leaves stay shared, not copied, while `op` builds new ones.
        let old: Arc<Vec<Octant>> = self.shared_leaves();
        let was = self.balanced();
        let r = op(self)?;
        let comm = self.comm().clone();
        match agree(&*comm, remap(&old, self.leaves(), data, replace)) {
            Ok(d) => {
                *data = d;
                Ok(r)
            }
            Err(e) => {
                let old = Arc::try_unwrap(old).unwrap_or_else(|a| (*a).clone());
                self.set_leaves(old);
                self.set_balanced(was);
                self.refresh()?;
                Err(e)
            }
        }
    }

    /// Runs `op`, which moves leaves between ranks without changing them
    /// (a partition), then moves `data` the same way. Collective.
    pub fn move_with_data<T>(
        &mut self,
        data: &mut LeafData,
        op: impl FnOnce(&mut LinearOctree) -> Result<T>,
    ) -> Result<T> {
        agree(&**self.comm(), data.check(self))?;
        let old = self.global_offsets().to_vec();
        let r = op(self)?;
        let comm = self.comm().clone();
        data.transfer(&*comm, &old, self.global_offsets());
        Ok(r)
    }

    /// [`LinearOctree::refine_once`] keeping `data`: each split leaf goes
    /// through `replace` (1 -> 8). Collective.
    pub fn refine_once_with_data(
        &mut self,
        data: &mut LeafData,
        max_level: u8,
        split: impl FnMut(Octant) -> bool,
        limit: u64,
        mut replace: impl FnMut(Replace<'_>) -> Result<()>,
    ) -> Result<AdaptStats> {
        self.change_with_data(data, &mut replace, |t| {
            t.refine_once(max_level, split, limit)
        })
    }

    /// [`LinearOctree::coarsen`] keeping `data`: each coarsened family goes
    /// through `replace` (8 -> 1; finest first when recursive). Collective.
    pub fn coarsen_with_data(
        &mut self,
        data: &mut LeafData,
        recursive: bool,
        coarsen: impl FnMut(&[Octant; 8]) -> bool,
        mut replace: impl FnMut(Replace<'_>) -> Result<()>,
    ) -> Result<AdaptStats> {
        self.change_with_data(data, &mut replace, |t| t.coarsen(recursive, coarsen))
    }

    /// [`LinearOctree::adapt`] keeping `data`: split leaves (1 -> 8) and
    /// coarsened families (8 -> 1) go through `replace`. Collective.
    pub fn adapt_with_data(
        &mut self,
        data: &mut LeafData,
        decide: impl FnMut(Octant) -> Adapt,
        limit: u64,
        mut replace: impl FnMut(Replace<'_>) -> Result<()>,
    ) -> Result<AdaptStats> {
        self.change_with_data(data, &mut replace, |t| t.adapt(decide, limit))
    }

    /// [`LinearOctree::balance_with_limit`] keeping `data`: each leaf that
    /// balance splits goes through `replace` once with all the leaves that
    /// replace it (1 -> n). Keeps a copy of the local leaves while it
    /// works. Collective.
    pub fn balance_with_data(
        &mut self,
        data: &mut LeafData,
        conn: Connectivity,
        limit: u64,
        mut replace: impl FnMut(Replace<'_>) -> Result<()>,
    ) -> Result<BalanceStats> {
        self.change_with_data(data, &mut replace, |t| t.balance_with_limit(conn, limit))
    }

    /// [`LinearOctree::partition`] moving `data` with the leaves.
    /// Collective.
    pub fn partition_with_data(&mut self, data: &mut LeafData) -> Result<PartitionStats> {
        self.move_with_data(data, |t| t.partition())
    }

    /// [`LinearOctree::partition_weighted`] moving `data` with the leaves.
    /// Collective.
    pub fn partition_weighted_with_data(
        &mut self,
        data: &mut LeafData,
        weight: impl Fn(Octant) -> u64,
    ) -> Result<PartitionStats> {
        self.move_with_data(data, |t| t.partition_weighted(weight))
    }

    /// [`LinearOctree::partition_for_coarsening`] moving `data` with the
    /// leaves. Collective.
    pub fn partition_for_coarsening_with_data(
        &mut self,
        data: &mut LeafData,
    ) -> Result<PartitionStats> {
        self.move_with_data(data, |t| t.partition_for_coarsening())
    }

    /// [`LinearOctree::partition_for_coarsening_weighted`] moving `data`
    /// with the leaves. Collective.
    pub fn partition_for_coarsening_weighted_with_data(
        &mut self,
        data: &mut LeafData,
        weight: impl Fn(Octant) -> u64,
    ) -> Result<PartitionStats> {
        self.move_with_data(data, |t| t.partition_for_coarsening_weighted(weight))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::parallel::comm::{CommRef, SerialComm};
    use crate::refine::{build_from_callback, NO_LIMIT};
    use std::rc::Rc;

    fn comm() -> CommRef {
        Rc::new(SerialComm)
    }

    /// A leaf's own key, as its data.
    fn key_of(o: Octant, d: &mut [u8]) {
        d.copy_from_slice(&o.key().to_le_bytes());
    }

    /// Children get their own keys from the parent's (checked), parents
    /// from the first child's.
    fn rekey(r: Replace<'_>) -> Result<()> {
        let mut r = r;
        for i in 0..r.outgoing.len() {
            let k = u64::from_le_bytes(r.outgoing_datum(i).try_into().unwrap());
            assert_eq!(k, r.outgoing[i].key());
        }
        for i in 0..r.incoming.len() {
            let o = r.incoming[i];
            key_of(o, r.incoming_datum(i));
        }
        Ok(())
    }

    fn check_keys(t: &LinearOctree, d: &LeafData) {
        assert_eq!(d.len(), t.local_len());
        for (i, &o) in t.leaves().iter().enumerate() {
            assert_eq!(d.get(i), &o.key().to_le_bytes()[..], "leaf {i}");
        }
    }

    #[test]
    fn data_follows_refine_coarsen_adapt_and_balance() {
        let p = [157_286u32, 91_000, 200_001];
        let at = move |o: Octant| {
            (0..3).all(|k| o.coords()[k] <= p[k] && p[k] < o.coords()[k] + o.side())
        };
        let mut t = build_from_callback(comm(), 6, at, NO_LIMIT).unwrap();
        let mut d = LeafData::from_fn(&t, 8, key_of);
        check_keys(&t, &d);
        let mut calls = (0, 0);
        let mut count = |r: Replace<'_>| {
            match (r.outgoing.len(), r.incoming.len()) {
                (1, 8) => calls.0 += 1,
                (8, 1) => calls.1 += 1,
                other => panic!("{other:?}"),
            }
            rekey(r)
        };
        let s = t
            .refine_once_with_data(&mut d, 18, |o| o.level() < 3, NO_LIMIT, &mut count)
            .unwrap();
        check_keys(&t, &d);
        let c = t
            .coarsen_with_data(&mut d, false, |f| f[0].level() > 3, &mut count)
            .unwrap();
        check_keys(&t, &d);
        assert_eq!(calls, (s.refined, c.coarsened));
        let a = t
            .adapt_with_data(
                &mut d,
                |o| if at(o) { Adapt::Refine } else { Adapt::Coarsen },
                NO_LIMIT,
                rekey,
            )
            .unwrap();
        assert!(a.refined > 0 && a.coarsened > 0);
        check_keys(&t, &d);
        let mut many = 0;
        t.balance_with_data(&mut d, Connectivity::Corner, NO_LIMIT, |r| {
            assert_eq!(r.outgoing.len(), 1);
            many += (r.incoming.len() > 8) as usize;
            rekey(r)
        })
        .unwrap();
        assert!(many > 0, "balance should split some leaf more than once");
        check_keys(&t, &d);
        t.partition_with_data(&mut d).unwrap();
        check_keys(&t, &d);
    }

    #[test]
    fn recursive_coarsening_replaces_family_by_family() {
        let mut t = LinearOctree::new_uniform(comm(), 3).unwrap();
        // The value 1 on each leaf; parents take the sum: the root gets 512
        // from 64 + 8 replacements.
        let mut d = LeafData::from_fn(&t, 4, |_, b| b.copy_from_slice(&1u32.to_le_bytes()));
        let mut calls = 0;
        t.coarsen_with_data(
            &mut d,
            true,
            |_| true,
            |mut r| {
                assert_eq!((r.outgoing.len(), r.incoming.len()), (8, 1));
                calls += 1;
                let sum: u32 = (0..8)
                    .map(|i| u32::from_le_bytes(r.outgoing_datum(i).try_into().unwrap()))
                    .sum();
                r.incoming_datum(0).copy_from_slice(&sum.to_le_bytes());
                Ok(())
            },
        )
        .unwrap();
        assert_eq!((t.global_len(), calls), (1, 73));
        assert_eq!(d.as_bytes(), &512u32.to_le_bytes()[..]);
    }

    #[test]
    fn a_failing_replace_leaves_tree_and_data_as_before() {
        let mut t = LinearOctree::new_uniform(comm(), 2).unwrap();
        t.balance(Connectivity::Face).unwrap();
        let mut d = LeafData::from_fn(&t, 8, key_of);
        let (leaves, bytes) = (t.leaves().to_vec(), d.clone());
        let mut n = 0;
        let e = t
            .refine_once_with_data(
                &mut d,
                18,
                |_| true,
                NO_LIMIT,
                |r| {
                    n += 1;
                    if n == 5 {
                        return Err(Error::invalid("no"));
                    }
                    rekey(r)
                },
            )
            .unwrap_err();
        assert_eq!(e.message(), "no");
        assert_eq!((t.leaves(), &d), (&leaves[..], &bytes));
        assert_eq!(t.balanced(), Some(Connectivity::Face));
        assert_eq!(t.global_len(), 64);
        // A wrong length is refused before anything changes.
        let mut short = LeafData::new(8, 3);
        assert!(t.partition_with_data(&mut short).is_err());
        // Size 0: only the leaves.
        let mut none = LeafData::for_tree(&t, 0);
        t.refine_once_with_data(&mut none, 18, |_| true, NO_LIMIT, |_| Ok(()))
            .unwrap();
        assert_eq!((none.len(), none.as_bytes().len()), (512, 0));
    }
}
