//! The search: a breadth-first sweep over face-adjacent open leaves from
//! the domain's boundary, across ranks through the ghost layer.

use std::collections::VecDeque;

use crate::classify::CUT;
use crate::error::{Error, Result};
use crate::octree::domain::Domain;
use crate::octree::octant::Octant;
use crate::octree::LeafIndex;
use crate::parallel::comm::Comm;

/// Distance of a leaf the search has not reached.
pub(crate) const UNREACHED: u32 = u32::MAX;

/// Local and ghost leaves with their classes: the graph of open leaves.
/// Node `i < local.len()` is local leaf `i`, node `local.len() + j` ghost `j`.
pub(crate) struct Graph<'a> {
    pub(crate) local: &'a [Octant],
    pub(crate) local_class: &'a [u8],
    pub(crate) index: LeafIndex,
    pub(crate) range: (u64, u64),
    pub(crate) ghosts: &'a [Octant],
    pub(crate) ghost_class: &'a [u8],
}

impl Graph<'_> {
    pub(crate) fn key(&self, node: usize) -> u64 {
        let nl = self.local.len();
        if node < nl {
            self.local[node].key()
        } else {
            self.ghosts[node - nl].key()
        }
    }

    /// The open leaves sharing part of a face with `leaf` (a local leaf),
    /// as nodes, into `out` (cleared first).
    pub(crate) fn open_neighbours(&self, leaf: Octant, out: &mut Vec<usize>) {
        out.clear();
        let c = leaf.coords();
        let side = leaf.side();
        for (f, n) in leaf.face_neighbors().into_iter().enumerate() {
            let Some(n) = n else {
                continue; // the cube's boundary
            };
            let axis = f / 2;
            let plus = f % 2 == 1;
            let plane = if plus { c[axis] + side } else { c[axis] };
            // A leaf overlapping `n` touches the face if it contains `n` or
            // lies against the face plane inside it.
            let faces = |m: Octant| {
                m.level() <= n.level()
                    || if plus {
                        m.coords()[axis] == plane
                    } else {
                        m.coords()[axis] + m.side() == plane
                    }
            };
            let (b, e) = (n.cell_begin(), n.cell_end());
            if b >= self.range.0 && e <= self.range.1 {
                let mut j = self.index.find(self.local, b);
                while j < self.local.len() && self.local[j].cell_begin() < e {
                    if faces(self.local[j]) && self.local_class[j] & CUT == 0 {
                        out.push(j);
                    }
                    j += 1;
                }
            } else {
                let nl = self.local.len();
                for (arr, class, base) in [
                    (self.local, self.local_class, 0),
                    (self.ghosts, self.ghost_class, nl),
                ] {
                    let mut j = arr.partition_point(|x| x.cell_begin() <= b);
                    if j > 0 && arr[j - 1].cell_end() > b {
                        j -= 1;
                    }
                    while j < arr.len() && arr[j].cell_begin() < e {
                        if faces(arr[j]) && class[j] & CUT == 0 {
                            out.push(base + j);
                        }
                        j += 1;
                    }
                }
            }
        }
    }

    /// Index of the local leaf `o` (which must be local).
    pub(crate) fn local_index(&self, o: Octant) -> Option<usize> {
        let (b, e) = self.range;
        if o.cell_begin() < b || o.cell_begin() >= e {
            return None;
        }
        let i = self.index.find(self.local, o.cell_begin());
        (self.local[i] == o).then_some(i)
    }
}

/// Hop distances from the boundary leaves, computed collectively.
pub(crate) struct Search<'a> {
    pub(crate) g: Graph<'a>,
    pub(crate) comm: &'a dyn Comm,
    pub(crate) owners: &'a [u32],
    /// Distance of each local leaf.
    pub(crate) dist: Vec<u32>,
    /// Smallest distance proposed to each ghost's owner so far.
    pub(crate) proposed: Vec<u32>,
    /// Ghosts whose proposal changed since the last exchange.
    pub(crate) dirty: Vec<u32>,
}

impl Search<'_> {
    /// Sweeps the local leaves in order of distance from `seeds` (pairs of
    /// distance and local index, distances already set), recording
    /// proposals for ghosts.
    pub(crate) fn sweep(&mut self, seeds: &mut Vec<(u32, u32)>) {
        seeds.sort_unstable();
        let nl = self.g.local.len();
        let mut queue: VecDeque<(u32, u32)> = VecDeque::new();
        let mut nb = Vec::with_capacity(16);
        let mut s = 0;
        loop {
            // Merge the sorted seeds with the queue (whose distances never
            // decrease): leaves leave in order of distance, as in Dijkstra.
            let take_seed = match (seeds.get(s), queue.front()) {
                (None, None) => break,
                (Some(_), None) => true,
                (None, Some(_)) => false,
                (Some(a), Some(b)) => a.0 <= b.0,
            };
            let (d, i) = if take_seed {
                s += 1;
                seeds[s - 1]
            } else {
                queue.pop_front().unwrap_or_default()
            };
            let i = i as usize;
            if self.dist[i] != d {
                continue; // superseded by a shorter distance
            }
            self.g.open_neighbours(self.g.local[i], &mut nb);
            let next = d + 1;
            for &m in &nb {
                if m < nl {
                    if self.dist[m] > next {
                        self.dist[m] = next;
                        queue.push_back((next, m as u32));
                    }
                } else {
                    let j = m - nl;
                    if self.proposed[j] > next {
                        self.proposed[j] = next;
                        self.dirty.push(j as u32);
                    }
                }
            }
        }
        seeds.clear();
    }

    /// Sends the proposals; returns whether any rank sent one, and fills
    /// `seeds` with the local leaves whose distance dropped.
    pub(crate) fn exchange(&mut self, seeds: &mut Vec<(u32, u32)>) -> bool {
        self.dirty.sort_unstable();
        self.dirty.dedup();
        let mut total = [self.dirty.len() as u64];
        self.comm.sum_u64(&mut total);
        if total[0] == 0 {
            return false;
        }
        let p = self.comm.size();
        let mut counts = vec![0usize; p];
        // Ghosts are sorted by owner, so this is grouped by rank.
        let mut send = Vec::with_capacity(2 * self.dirty.len());
        for &j in &self.dirty {
            let j = j as usize;
            counts[self.owners[j] as usize] += 2;
            send.push(self.g.ghosts[j].key());
            send.push(self.proposed[j] as u64);
        }
        self.dirty.clear();
        let (recv, _) = self.comm.alltoallv_u64(&send, &counts);
        for pair in recv.chunks_exact(2) {
            let (o, d) = (Octant::from_key(pair[0]), pair[1] as u32);
            if let Some(i) = self.g.local_index(o) {
                if self.dist[i] > d {
                    self.dist[i] = d;
                    seeds.push((d, i as u32));
                }
            }
        }
        true
    }

    /// The exact distances of all ghosts, asked from their owners.
    pub(crate) fn ghost_distances(&self) -> Vec<u32> {
        let p = self.comm.size();
        let mut counts = vec![0usize; p];
        for &r in self.owners {
            counts[r as usize] += 1;
        }
        let keys: Vec<u64> = self.g.ghosts.iter().map(|o| o.key()).collect();
        let (asked, asked_counts) = self.comm.alltoallv_u64(&keys, &counts);
        let answers: Vec<u64> = asked
            .iter()
            .map(|&k| {
                self.g
                    .local_index(Octant::from_key(k))
                    .map_or(UNREACHED as u64, |i| self.dist[i] as u64)
            })
            .collect();
        let (got, _) = self.comm.alltoallv_u64(&answers, &asked_counts);
        got.into_iter().map(|d| d as u32).collect()
    }
}

/// The finest lattice cell holding `point` (user units, the tie rule of
/// [`crate::octree::search::point_cell`]), or an error if it is outside the domain.
pub(crate) fn point_cell(domain: &Domain, point: [f64; 3]) -> Result<u64> {
    crate::octree::search::point_cell(domain, point).ok_or_else(|| {
        let top = domain.upper();
        let what = if domain.brick.is_cube() {
            "cube"
        } else {
            "box"
        };
        Error::invalid(format!(
            "the inside point ({}, {}, {}) is not in the {what} (from ({}, {}, {}) to ({}, {}, {}))",
            point[0],
            point[1],
            point[2],
            domain.origin[0],
            domain.origin[1],
            domain.origin[2],
            top[0],
            top[1],
            top[2]
        ))
    })
}

pub(crate) fn put(b: &mut Vec<u8>, v: u64) {
    b.extend_from_slice(&v.to_le_bytes());
}

pub(crate) fn get(b: &[u8], i: usize) -> u64 {
    let mut a = [0u8; 8];
    a.copy_from_slice(&b[8 * i..8 * i + 8]);
    u64::from_le_bytes(a)
}
