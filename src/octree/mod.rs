//! The distributed linear octree: each rank holds a Morton-contiguous, sorted
//! run of the global leaves.
//!
//! Rank `r` owns the finest cells `first_cell[r]..first_cell[r + 1]`; its leaves
//! cover exactly that range. An empty rank has `first_cell[r] ==
//! first_cell[r + 1]`. These per-rank boundaries (p4est's
//! `global_first_position`) let any rank find the owner of any point without
//! communication.

pub mod adapt;
pub mod balance;
pub mod brick;
pub mod checkpoint;
pub mod domain;
pub mod ghost;
pub mod leaf_data;
pub mod limits;
pub mod octant;
pub mod partition;
pub mod search;
pub mod sort;

use std::sync::Arc;

use crate::error::{Error, ErrorKind, Result};
use crate::octree::brick::Brick;
use crate::octree::octant::{
    Connectivity, Octant, CELLS, LATTICE_BITS, LEVEL_BITS, LEVEL_MASK, MAX_LEVEL,
};
use crate::parallel::comm::{agree, CommRef};

/// A distributed, complete, linear octree (see the module documentation).
pub struct LinearOctree {
    comm: CommRef,
    // Shared with meshes that keep every leaf, so they need no copy.
    leaves: Arc<Vec<Octant>>,
    first_cell: Vec<u64>,
    offsets: Vec<u64>,
    balanced: Option<Connectivity>,
    /// The root cells of the domain (the cube unless set).
    brick: Brick,
}

impl std::fmt::Debug for LinearOctree {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LinearOctree")
            .field("rank", &self.comm.rank())
            .field("local", &self.leaves.len())
            .field("global", &self.global_len())
            .finish()
    }
}

impl LinearOctree {
    /// The root cells of the domain the octree lives in: balance skips the
    /// void outside a brick.
    pub fn brick(&self) -> Brick {
        self.brick
    }

    /// Leaves over all ranks outside the void of a brick: the forest's
    /// leaves, as p4est counts them. Collective in a brick (a sum), the
    /// same as [`LinearOctree::global_len`] in a cube.
    pub fn forest_len(&self) -> u64 {
        let b = self.brick;
        if b.is_cube() {
            return self.global_len();
        }
        let mut n = [self.leaves.iter().filter(|o| !b.is_void(**o)).count() as u64];
        self.comm.sum_u64(&mut n);
        n[0]
    }

    /// Places the octree in a brick of root cells (see [`crate::octree::brick`]).
    pub fn set_brick(&mut self, brick: Brick) {
        self.brick = brick;
    }

    /// Wraps this rank's sorted leaves. Collective. The union over ranks
    /// must be a complete linear octree in rank order; that is checked
    /// cheaply here (local order and contiguity, and that the ranks' ranges
    /// tile the root), and fully by [`LinearOctree::check`].
    pub fn from_local_leaves(comm: CommRef, leaves: Vec<Octant>) -> Result<LinearOctree> {
        let local = check_local(&leaves);
        agree(&*comm, local)?;
        let mut t = LinearOctree {
            comm,
            leaves: Arc::new(leaves),
            first_cell: Vec::new(),
            offsets: Vec::new(),
            balanced: None,
            brick: Brick::CUBE,
        };
        t.refresh()?;
        Ok(t)
    }

    /// The uniform octree at `level`, split into equal Morton ranges.
    /// Collective.
    pub fn new_uniform(comm: CommRef, level: u8) -> Result<LinearOctree> {
        if level > MAX_LEVEL {
            return Err(Error::invalid(format!(
                "level {level} is above the maximum level {MAX_LEVEL}"
            )));
        }
        let n = 1u64 << (3 * level as u32);
        let (p, r) = (comm.size() as u128, comm.rank() as u128);
        let begin = (n as u128 * r / p) as u64;
        let end = (n as u128 * (r + 1) / p) as u64;
        let shift = 3 * (crate::octree::octant::LATTICE_BITS - level as u32);
        let leaves = (begin..end)
            .map(|i| Octant::from_parts(i << shift, level))
            .collect();
        LinearOctree::from_local_leaves(comm, leaves)
    }

    /// Recomputes the per-rank ranges and offsets after the local leaves
    /// changed. Collective.
    pub(crate) fn refresh(&mut self) -> Result<()> {
        let (first_cell, offsets) = layout(&*self.comm, &self.leaves)?;
        self.first_cell = first_cell;
        self.offsets = offsets;
        Ok(())
    }

    /// The strongest connectivity the octree is known to be 2:1 balanced
    /// for: set by [`LinearOctree::balance`], kept by partitioning, cleared
    /// by refinement.
    pub fn balanced(&self) -> Option<Connectivity> {
        self.balanced
    }

    pub(crate) fn set_balanced(&mut self, conn: Option<Connectivity>) {
        self.balanced = conn;
    }

    /// The communicator.
    pub fn comm(&self) -> &CommRef {
        &self.comm
    }

    /// This rank's leaves in Morton order.
    pub fn leaves(&self) -> &[Octant] {
        &self.leaves
    }

    /// Replaces the local leaves (crate internal: callers refresh after).
    pub(crate) fn set_leaves(&mut self, leaves: Vec<Octant>) {
        // Any change of the leaf set may break balance; `balance` and
        // `partition` restore the flag themselves.
        self.balanced = None;
        self.leaves = Arc::new(leaves);
    }

    /// Takes the local leaves out, leaving none (copied only if a mesh
    /// still shares them). Crate internal: callers set them back.
    pub(crate) fn take_leaves(&mut self) -> Vec<Octant> {
        self.balanced = None;
        let shared = std::mem::take(&mut self.leaves);
        Arc::try_unwrap(shared).unwrap_or_else(|a| (*a).clone())
    }

    /// The local leaves, shared rather than copied.
    pub(crate) fn shared_leaves(&self) -> Arc<Vec<Octant>> {
        Arc::clone(&self.leaves)
    }

    /// Number of leaves on this rank.
    pub fn local_len(&self) -> usize {
        self.leaves.len()
    }

    /// Number of leaves on all ranks.
    pub fn global_len(&self) -> u64 {
        *self.offsets.last().unwrap_or(&0)
    }

    /// Global index of the first leaf of each rank, with the total appended.
    pub fn global_offsets(&self) -> &[u64] {
        &self.offsets
    }

    /// First finest cell of each rank's range, with `CELLS` appended.
    pub fn first_cells(&self) -> &[u64] {
        &self.first_cell
    }

    /// This rank's range of finest cells.
    pub fn local_cells(&self) -> (u64, u64) {
        let r = self.comm.rank();
        (self.first_cell[r], self.first_cell[r + 1])
    }

    /// The rank whose range holds finest cell `cell`.
    pub fn owner_of_cell(&self, cell: u64) -> usize {
        owner_of_cell(&self.first_cell, cell)
    }

    /// Index of the local leaf containing the anchor of `o`, if `o`'s anchor
    /// lies in this rank's range.
    pub fn find_local(&self, o: Octant) -> Option<usize> {
        let (b, e) = self.local_cells();
        let c = o.cell_begin();
        if c < b || c >= e {
            return None;
        }
        Some(containing_leaf(&self.leaves, o))
    }

    /// Maximum leaf level over all ranks. Collective.
    pub fn max_level(&self) -> u8 {
        let mut m = [self.leaves.iter().map(|o| o.level()).max().unwrap_or(0) as u64];
        self.comm.max_u64(&mut m);
        m[0] as u8
    }

    /// Full check that the global octree is complete and linear: local
    /// leaves strictly increasing and contiguous, and the ranks' ranges
    /// tiling the root cube. Collective.
    pub fn check(&self) -> Result<()> {
        agree(&*self.comm, check_local(&self.leaves))?;
        layout(&*self.comm, &self.leaves).map(|_| ())
    }
}

/// Per-rank first cells and global offsets of locally contiguous leaves,
/// after checking that the ranks' ranges tile `[0, CELLS)`. Collective; every
/// rank reaches the same verdict because it is computed from gathered data.
fn layout(
    comm: &dyn crate::parallel::comm::Comm,
    leaves: &[Octant],
) -> Result<(Vec<u64>, Vec<u64>)> {
    let p = comm.size();
    let firsts = comm.allgather_u64(leaves.first().map_or(u64::MAX, |o| o.cell_begin()));
    let ends = comm.allgather_u64(leaves.last().map_or(u64::MAX, |o| o.cell_end()));
    let counts = comm.allgather_u64(leaves.len() as u64);
    let mut first_cell = vec![CELLS; p + 1];
    let mut expect = 0u64;
    for r in 0..p {
        if counts[r] == 0 {
            continue;
        }
        if firsts[r] != expect {
            return Err(Error::new(
                ErrorKind::Internal,
                format!(
                    "leaves of rank {r} begin at cell {} but the previous ranks end at cell {expect}",
                    firsts[r]
                ),
            ));
        }
        expect = ends[r];
    }
    if expect != CELLS {
        return Err(Error::new(
            ErrorKind::Internal,
            format!("the leaves end at cell {expect}, not at the end of the root ({CELLS})"),
        ));
    }
    for r in (0..p).rev() {
        first_cell[r] = if counts[r] == 0 {
            first_cell[r + 1]
        } else {
            firsts[r]
        };
    }
    let mut offsets = vec![0u64; p + 1];
    for r in 0..p {
        offsets[r + 1] = offsets[r] + counts[r];
    }
    Ok((first_cell, offsets))
}

/// The rank whose range holds finest cell `cell`, given the per-rank first
/// cells with the total appended (empty ranks share their successor's first
/// cell and are never chosen).
#[inline]
pub fn owner_of_cell(first_cell: &[u64], cell: u64) -> usize {
    let p = first_cell.len() - 1;
    first_cell[..p].partition_point(|&f| f <= cell) - 1
}

/// Index of the leaf that contains the anchor of `o` in a sorted complete
/// run of leaves that covers that anchor.
#[inline]
pub fn containing_leaf(leaves: &[Octant], o: Octant) -> usize {
    // Probe with the finest possible level so that a leaf with the same
    // anchor but a finer level still sorts at or before the probe.
    let probe = (o.morton() << 5) | 31;
    leaves.partition_point(|x| x.key() <= probe) - 1
}

/// Local order and contiguity: strictly increasing, each leaf starts where
/// the previous ends.
fn check_local(leaves: &[Octant]) -> Result<()> {
    // One pass without branches: each leaf's end XOR the next one's
    // beginning, or-ed together; the pair at fault is looked for only when
    // there is one.
    let keys = Octant::as_keys(leaves);
    let mut differ = 0u64;
    for w in keys.windows(2) {
        let shift = 3 * LATTICE_BITS.wrapping_sub((w[0] & LEVEL_MASK) as u32);
        let end = (w[0] >> LEVEL_BITS).wrapping_add(1u64.wrapping_shl(shift));
        differ |= end ^ (w[1] >> LEVEL_BITS);
    }
    if differ == 0 {
        return Ok(());
    }
    for (i, w) in leaves.windows(2).enumerate() {
        if w[0].cell_end() != w[1].cell_begin() {
            let what = if w[0].cell_end() > w[1].cell_begin() {
                "overlap or are out of order"
            } else {
                "leave a gap"
            };
            return Err(Error::new(
                ErrorKind::Internal,
                format!("leaves {i} {:?} and {} {:?} {what}", w[0], i + 1, w[1]),
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::parallel::comm::SerialComm;
    use std::rc::Rc;

    #[test]
    fn uniform_is_complete() {
        let t = LinearOctree::new_uniform(Rc::new(SerialComm), 2).unwrap();
        assert_eq!(t.global_len(), 64);
        t.check().unwrap();
        let o = t.leaves()[10].children()[3];
        assert_eq!(t.find_local(o), Some(10));
    }

    #[test]
    fn gaps_are_rejected() {
        let c: CommRef = Rc::new(SerialComm);
        let mut l = Octant::ROOT.children().to_vec();
        l.remove(3);
        assert!(LinearOctree::from_local_leaves(c, l).is_err());
    }
}

/// Finds the leaf containing a cell in a sorted complete run of leaves,
/// faster than a binary search over the whole run: the run's cell range is
/// cut into about one bucket per leaf, and a lookup searches only the
/// leaves that begin in one bucket.
#[derive(Clone, Debug, Default)]
pub struct LeafIndex {
    begin: u64,
    shift: u32,
    /// `start[b]`: number of leaves beginning before bucket `b`.
    start: Vec<u32>,
}

impl LeafIndex {
    /// Indexes `leaves`, which must cover `begin..end` contiguously.
    pub fn new(leaves: &[Octant], begin: u64, end: u64) -> LeafIndex {
        let span = end.saturating_sub(begin).max(1);
        let want = (leaves.len() as u64).clamp(1, 1 << 26);
        let mut shift = 0;
        while (span >> shift) > want {
            shift += 1;
        }
        let buckets = ((span - 1) >> shift) as usize + 1;
        let mut start = vec![0u32; buckets + 1];
        let mut i = 0usize;
        for (b, s) in start.iter_mut().enumerate() {
            let cell = begin + ((b as u64) << shift);
            while i < leaves.len() && leaves[i].cell_begin() < cell {
                i += 1;
            }
            *s = i as u32;
        }
        start[buckets] = leaves.len() as u32;
        LeafIndex {
            begin,
            shift,
            start,
        }
    }

    /// Index of the leaf containing cell `cell` (which must lie in the
    /// indexed range).
    #[inline]
    pub fn find(&self, leaves: &[Octant], cell: u64) -> usize {
        let b = ((cell - self.begin) >> self.shift) as usize;
        let lo = self.start[b] as usize;
        let hi = self.start[b + 1] as usize;
        lo + leaves[lo..hi].partition_point(|x| x.cell_begin() <= cell) - 1
    }
}
