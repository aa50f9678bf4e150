//! Point location: the leaf, mesh element or owner rank holding each of a
//! set of user points, for probes, particle tracking and data transfer.
//!
//! A point maps to one finest lattice cell ([`point_cell`]); the rank whose
//! cell range holds that cell ([`LinearOctree::first_cells`], p4est's
//! `global_first_position`) owns the point, found without communication
//! ([`owner_ranks`]). [`locate`] and `mesh::locate_elements` are collective:
//! each rank sends its points' cells to their owners in one all-to-all,
//! the owners look them up among their leaves, and a second all-to-all
//! returns the answers, in the caller's point order. This is the routing
//! of p4est's `p8est_search_partition` done with the first cells directly,
//! since a point's owner is a single binary search.
//!
//! **Tie rule.** A point belongs to the leaf whose half-open box `[lo, hi)`
//! holds its lattice coordinates `(p - origin) * 2^19 / side`: on a face,
//! edge or corner shared by several leaves, the leaf above it along each
//! axis on which it lies on a boundary. Points on the domain's highest
//! faces (the cube's, or a box domain's box's) are clamped into the last
//! cell, so the closed domain is covered. The answer depends only on the
//! leaves, never on the number of ranks or the partition. Since the rule
//! applies to the lattice coordinates, a point given in user units within
//! rounding of a face may fall on either side of it.
//!
//! **Outside.** A point outside the closed cube, or outside a box
//! domain's box (in the void of the embedding cube), or with a NaN
//! coordinate is [`Location::Outside`]; it is reported, never dropped.

use crate::octree::domain::Domain;
use crate::octree::octant::{morton_encode, Octant};
use crate::octree::{owner_of_cell, LeafIndex, LinearOctree};
use crate::parallel::comm::offsets;

/// Where a point lies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Location {
    /// In `leaf`: local leaf (or element) `local` of rank `rank`, number
    /// `global` over all ranks (leaves, or elements, in rank order).
    Found {
        /// The rank holding the leaf.
        rank: u32,
        /// Index of the leaf (element) among that rank's.
        local: u32,
        /// Global index of the leaf (element).
        global: u64,
        /// The leaf itself.
        leaf: Octant,
    },
    /// Inside the domain, in a leaf of rank `rank` that is not an element
    /// of the mesh (only from [`crate::mesh::locate_elements`]: for example
    /// inside the body of a fluid mesh).
    NoElement {
        /// The rank holding the leaf.
        rank: u32,
        /// The leaf, which the mesh did not keep.
        leaf: Octant,
    },
    /// Outside the domain, in the void around a box domain, or NaN.
    Outside,
}

impl Location {
    /// The rank holding the point's leaf, if it is in the domain.
    pub fn rank(&self) -> Option<u32> {
        match *self {
            Location::Found { rank, .. } | Location::NoElement { rank, .. } => Some(rank),
            Location::Outside => None,
        }
    }
}

/// The finest lattice cell (its Morton index, as [`Octant::cell_begin`])
/// holding `p`, with the module's tie rule; `None` outside the domain or
/// for NaN coordinates.
#[inline]
pub fn point_cell(domain: &Domain, p: [f64; 3]) -> Option<u64> {
    Lattice::new(domain).cell(p)
}

/// [`point_cell`] with the domain's constants computed once.
struct Lattice {
    origin: [f64; 3],
    scale: f64,
    hi: [u32; 3],
}

impl Lattice {
    fn new(domain: &Domain) -> Lattice {
        Lattice {
            origin: domain.origin,
            scale: domain.scale(),
            hi: domain.brick.hi(),
        }
    }

    #[inline]
    fn cell(&self, p: [f64; 3]) -> Option<u64> {
        // The same arithmetic as `Domain::to_lattice`.
        let q: [f64; 3] = std::array::from_fn(|k| (p[k] - self.origin[k]) * self.scale);
        // `contains` is false for NaN.
        if !(0..3).all(|k| (0.0..=self.hi[k] as f64).contains(&q[k])) {
            return None;
        }
        // The highest faces belong to the last cell.
        let i: [u32; 3] = std::array::from_fn(|k| (q[k] as u32).min(self.hi[k] - 1));
        Some(morton_encode(i[0], i[1], i[2]))
    }
}

/// The rank owning each point (holding the leaf that contains it), `None`
/// outside the domain. Local: no communication.
pub fn owner_ranks(tree: &LinearOctree, domain: &Domain, points: &[[f64; 3]]) -> Vec<Option<u32>> {
    let first = tree.first_cells();
    let lattice = Lattice::new(domain);
    points
        .iter()
        .map(|&p| lattice.cell(p).map(|c| owner_of_cell(first, c) as u32))
        .collect()
}

/// The leaf containing each point, in `points`' order. Collective: every
/// rank calls it with its own points (any number, none included).
pub fn locate(tree: &LinearOctree, domain: &Domain, points: &[[f64; 3]]) -> Vec<Location> {
    route(tree, domain, points, tree.global_offsets(), |i, _| Some(i))
}

/// No cell: the point is outside.
const OUTSIDE: u64 = u64::MAX;

/// Sends each point's cell to its owner, which finds the leaf holding it
/// and answers with `lookup(local leaf index, leaf)`, the local index of
/// the leaf or element (`None`: no element); `bases[r]` is the global
/// index of rank `r`'s first. Returns the answers in the caller's order.
/// Collective.
pub(crate) fn route(
    tree: &LinearOctree,
    domain: &Domain,
    points: &[[f64; 3]],
    bases: &[u64],
    lookup: impl Fn(usize, Octant) -> Option<usize>,
) -> Vec<Location> {
    let comm = tree.comm();
    let p = comm.size();
    let first = tree.first_cells();
    let lattice = Lattice::new(domain);
    let cells: Vec<u64> = points
        .iter()
        .map(|&x| lattice.cell(x).unwrap_or(OUTSIDE))
        .collect();
    let owner: Vec<u32> = cells
        .iter()
        .map(|&c| match c {
            OUTSIDE => p as u32,
            c => owner_of_cell(first, c) as u32,
        })
        .collect();
    // Counting sort of the points by owner (outside points last, unsent).
    let mut counts = vec![0usize; p + 1];
    for &r in &owner {
        counts[r as usize] += 1;
    }
    let starts = offsets(&counts);
    let mut at = starts.clone();
    let mut order = vec![0u32; points.len()];
    let mut send = vec![0u64; starts[p]];
    for (i, &r) in owner.iter().enumerate() {
        let slot = &mut at[r as usize];
        order[*slot] = i as u32;
        if (r as usize) < p {
            send[*slot] = cells[i];
        }
        *slot += 1;
    }
    drop((cells, owner));
    let (recv, recv_counts) = comm.alltoallv_u64(&send, &counts[..p]);
    drop(send);

    // The owner's side: every received cell lies in this rank's range.
    // Answers: the local index (`u64::MAX`: no element) and the leaf.
    let leaves = tree.leaves();
    let (begin, end) = tree.local_cells();
    // An index pays for itself only for many points per leaf.
    let index = (!recv.is_empty() && recv.len() * 8 >= leaves.len())
        .then(|| LeafIndex::new(leaves, begin, end));
    let mut answers = Vec::with_capacity(2 * recv.len());
    for &c in &recv {
        let i = match &index {
            Some(ix) => ix.find(leaves, c),
            None => leaves.partition_point(|x| x.cell_begin() <= c) - 1,
        };
        let local = lookup(i, leaves[i]).map_or(u64::MAX, |e| e as u64);
        answers.extend([local, leaves[i].key()]);
    }
    drop(recv);
    let back_counts: Vec<usize> = recv_counts.iter().map(|n| 2 * n).collect();
    let (back, _) = comm.alltoallv_u64(&answers, &back_counts);
    drop(answers);

    let mut out = vec![Location::Outside; points.len()];
    let mut r = 0;
    for (k, w) in back.chunks_exact(2).enumerate() {
        // Answers come back grouped by rank in the order sent.
        while k >= starts[r + 1] {
            r += 1;
        }
        let leaf = Octant::from_key(w[1]);
        out[order[k] as usize] = if w[0] == u64::MAX {
            Location::NoElement {
                rank: r as u32,
                leaf,
            }
        } else {
            Location::Found {
                rank: r as u32,
                local: w[0] as u32,
                global: bases[r] + w[0],
                leaf,
            }
        };
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::parallel::comm::{CommRef, SerialComm};
    use std::rc::Rc;

    #[test]
    fn ties_go_up_and_the_top_faces_clamp() {
        let c: CommRef = Rc::new(SerialComm);
        let t = LinearOctree::new_uniform(c, 1).unwrap();
        let d = Domain::cube([0.0; 3], 2.0).unwrap();
        let pts = [
            [0.5, 0.5, 0.5],
            [1.0, 0.5, 0.5],
            [1.0, 1.0, 1.0],
            [2.0, 2.0, 2.0],
            [0.0, 0.0, 0.0],
            [2.0, 0.0, 0.5],
            [2.0001, 0.5, 0.5],
            [f64::NAN, 0.5, 0.5],
            [-1e-300, 0.5, 0.5],
        ];
        let got: Vec<Option<u64>> = locate(&t, &d, &pts)
            .iter()
            .map(|l| match l {
                Location::Found { global, .. } => Some(*global),
                _ => None,
            })
            .collect();
        let want = [
            Some(0),
            Some(1),
            Some(7),
            Some(7),
            Some(0),
            Some(1),
            None,
            None,
            None,
        ];
        assert_eq!(got, want);
        assert_eq!(owner_ranks(&t, &d, &pts[..2]), vec![Some(0), Some(0)]);
    }

    #[test]
    fn the_void_of_a_box_is_outside() {
        let d = Domain::brick([0.0; 3], [3.0, 1.0, 1.0], [3, 1, 1]).unwrap();
        assert!(point_cell(&d, [3.0, 1.0, 1.0]).is_some());
        assert!(point_cell(&d, [2.5, 0.5, 0.5]).is_some());
        assert!(point_cell(&d, [3.5, 0.5, 0.5]).is_none());
        assert!(point_cell(&d, [0.5, 1.5, 0.5]).is_none());
    }
}
