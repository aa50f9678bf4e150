//! The ghost layer: the leaves of other ranks that touch this rank's leaves
//! by a face, an edge or a corner, with their owner ranks.
//!
//! Each rank finds, for each of its own leaves near the boundary of its
//! Morton range, which other ranks own a leaf touching it, and sends the
//! leaf there; nothing is gathered globally. The test is exact without any
//! assumption on balance: the part of a same-size neighbour region that
//! touches the leaf is split until each piece lies in one rank's range (a
//! piece owned by one rank is covered by that rank's leaves, and the ones
//! covering the contact touch the leaf). Subtrees whose whole 3×3×3
//! neighbourhood lies in this rank's range are skipped, so the work grows
//! with the partition boundary, not with the number of leaves.

use crate::octree::octant::{Connectivity, Octant};
use crate::octree::{owner_of_cell, LinearOctree};
use crate::parallel::comm::Comm;

/// Leaves of other ranks touching this rank's leaves, sorted in Morton order,
/// each with its owner rank and a word of data sent along by the owner (the
/// mesh sends each leaf's class and element number).
#[derive(Clone, Debug, Default)]
pub struct GhostLayer {
    /// Ghost leaves in Morton order (those of lower ranks first).
    pub leaves: Vec<Octant>,
    /// Owner rank of each ghost.
    pub owners: Vec<u32>,
    /// The word the owner attached to each ghost.
    pub data: Vec<u64>,
    /// Number of ghosts that come before this rank's range.
    pub before: usize,
    /// Number of (local leaf, rank) pairs this rank sent.
    pub sent: u64,
    /// The local leaves sent, grouped by destination rank (p4est's
    /// mirrors), in the order sent, so that new data can follow the same
    /// way ([`GhostLayer::exchange_data`]).
    mirrors: Vec<u32>,
    /// How many of `mirrors` go to each rank.
    mirror_counts: Vec<usize>,
}

impl GhostLayer {
    /// Number of ghosts.
    pub fn len(&self) -> usize {
        self.leaves.len()
    }

    /// Whether there are none (always so on one rank).
    pub fn is_empty(&self) -> bool {
        self.leaves.is_empty()
    }

    /// Replaces the ghosts' data words with new ones, `data(i)` for local
    /// leaf `i`, for the same leaves as when the layer was built: one
    /// exchange of the words, without finding the ghosts again. Collective.
    pub fn exchange_data(&mut self, comm: &dyn Comm, data: impl Fn(usize) -> u64) {
        let send: Vec<u64> = self.mirrors.iter().map(|&i| data(i as usize)).collect();
        let (recv, _) = comm.alltoallv_u64(&send, &self.mirror_counts);
        debug_assert_eq!(recv.len(), self.data.len());
        self.data = recv;
    }
}

/// Builds the ghost layer of `tree`. `data(i)` travels with local leaf `i`.
/// Collective.
pub fn build_ghost_layer(tree: &LinearOctree, data: impl Fn(usize) -> u64) -> GhostLayer {
    let comm: &dyn Comm = &**tree.comm();
    let p = comm.size();
    let me = comm.rank();
    let mut per_rank: Vec<Vec<u64>> = vec![Vec::new(); p];
    let mut mirrors: Vec<Vec<u32>> = vec![Vec::new(); p];
    let mut sent = 0u64;
    if p > 1 && tree.local_len() > 0 {
        let scan = Scan {
            leaves: tree.leaves(),
            first: tree.first_cells(),
            range: tree.local_cells(),
            me,
        };
        let mut tops = Vec::new();
        crate::octree::octant::cover_cells(scan.range.0, scan.range.1, &mut tops);
        let mut lo = 0;
        let mut ranks = Vec::new();
        for t in tops {
            let hi = lo + scan.leaves[lo..].partition_point(|l| l.cell_begin() < t.cell_end());
            scan.visit(t, lo, hi, &mut |i, leaf| {
                ranks.clear();
                scan.touching_ranks(leaf, &mut ranks);
                ranks.sort_unstable();
                ranks.dedup();
                for &r in &ranks {
                    per_rank[r].push(leaf.key());
                    per_rank[r].push(data(i));
                    mirrors[r].push(i as u32);
                    sent += 1;
                }
            });
            lo = hi;
        }
    }
    let counts: Vec<usize> = per_rank.iter().map(|v| v.len()).collect();
    let send: Vec<u64> = per_rank.concat();
    let (recv, rcounts) = comm.alltoallv_u64(&send, &counts);
    let mut g = GhostLayer {
        sent,
        mirror_counts: mirrors.iter().map(|m| m.len()).collect(),
        mirrors: mirrors.concat(),
        ..GhostLayer::default()
    };
    let mut at = 0;
    for (src, &c) in rcounts.iter().enumerate() {
        for pair in recv[at..at + c].chunks_exact(2) {
            g.leaves.push(Octant::from_key(pair[0]));
            g.owners.push(src as u32);
            g.data.push(pair[1]);
        }
        if src < me {
            g.before = g.leaves.len();
        }
        at += c;
    }
    g
}

struct Scan<'a> {
    leaves: &'a [Octant],
    first: &'a [u64],
    range: (u64, u64),
    me: usize,
}

impl Scan<'_> {
    fn inside(&self, o: Octant) -> bool {
        o.cell_begin() >= self.range.0 && o.cell_end() <= self.range.1
    }

    /// Whether every neighbour of `o` in the domain lies in this rank's
    /// range.
    fn neighbourhood_is_local(&self, o: Octant) -> bool {
        Connectivity::Corner
            .offsets()
            .iter()
            .all(|&d| o.neighbor(d).is_none_or(|n| self.inside(n)))
    }

    /// Calls `f` for each leaf of `leaves[lo..hi]` (the leaves inside `o`)
    /// that may touch another rank.
    fn visit(&self, o: Octant, lo: usize, hi: usize, f: &mut impl FnMut(usize, Octant)) {
        if self.neighbourhood_is_local(o) {
            return;
        }
        if hi - lo == 1 && self.leaves[lo] == o {
            f(lo, o);
            return;
        }
        let mut a = lo;
        for c in o.children() {
            let b = a + self.leaves[a..hi].partition_point(|l| l.cell_begin() < c.cell_end());
            if b > a {
                self.visit(c, a, b, f);
            }
            a = b;
        }
    }

    /// Pushes every other rank owning a leaf that touches `leaf`.
    fn touching_ranks(&self, leaf: Octant, out: &mut Vec<usize>) {
        for &d in Connectivity::Corner.offsets() {
            if let Some(n) = leaf.neighbor(d) {
                if !self.inside(n) {
                    self.descend(n, d, out);
                }
            }
        }
    }

    /// `region` lies in direction `d` of the leaf and touches it; split it
    /// until each piece has one owner, keeping only pieces touching the leaf.
    fn descend(&self, region: Octant, d: [i32; 3], out: &mut Vec<usize>) {
        let r0 = owner_of_cell(self.first, region.cell_begin());
        let r1 = owner_of_cell(self.first, region.cell_end() - 1);
        if r0 == r1 {
            if r0 != self.me {
                out.push(r0);
            }
            return;
        }
        for (c, child) in region.children().into_iter().enumerate() {
            // The child must sit on the side of the region facing the leaf.
            let faces_leaf = (0..3).all(|k| {
                let bit = (c >> k) & 1;
                match d[k] {
                    1 => bit == 0,
                    -1 => bit == 1,
                    _ => true,
                }
            });
            if faces_leaf {
                self.descend(child, d, out);
            }
        }
    }
}
