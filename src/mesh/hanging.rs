//! The hanging nodes' dependencies, stored by reference to the coarse
//! element they hang on.
//!
//! A face-hanging node sits at the centre of a face of a coarser kept
//! element and depends on that face's 4 corners; an edge-hanging node sits
//! at the middle of an edge and depends on its 2 ends:
//!
//! ```text
//!        coarse element C           C's face seen from the fine side
//!       +-----------+               c2-----e-----c3
//!      /           /|                |     |     |
//!     /           / |                e-----h-----e     h: face-hanging,
//!    +-----------+  |                |     |     |        deps c0 c1 c2 c3
//!    |           |  +                c0----e-----c1    e: edge-hanging,
//!    |           | /                                      deps its 2 c's
//!    |           |/
//!    +-----------+
//! ```
//!
//! Those corners are C's own corner nodes, so a hanging node stores only C
//! (a local element index, or a row of [`Hanging::ghost_rows`] when C is
//! another rank's) and a byte with a bit per Morton corner of C it depends
//! on: 5 bytes per hanging node instead of 16 (face) or 8 (edge), which is
//! a tenth of the mesh's peak memory. The explicit lists
//! ([`Hanging::face_lists`], [`Hanging::edge_lists`]) are made on first
//! request for callers that want slices.

use std::sync::OnceLock;

use super::VTK_TO_MORTON;

/// Marks a coarse reference that is a row of [`Hanging::ghost_rows`].
pub(crate) const GHOST: u32 = 0x8000_0000;

/// The dependencies of one hanging node: 4 local node indices for a
/// face-hanging node, 2 for an edge-hanging one, in the Morton order of the
/// coarse element's corners. Dereferences to a slice.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HangingDeps {
    len: u8,
    nodes: [u32; 4],
}

impl std::ops::Deref for HangingDeps {
    type Target = [u32];
    fn deref(&self) -> &[u32] {
        &self.nodes[..self.len as usize]
    }
}

/// Hanging nodes of one kind: per node, its coarse element (a local element
/// index, or [`GHOST`] | a row of [`Hanging`]'s ghost rows) and the Morton
/// corners of that element it depends on (a bit each).
#[derive(Debug, Default)]
pub(crate) struct Refs {
    pub coarse: Vec<u32>,
    pub mask: Vec<u8>,
}

/// The hanging nodes of one rank's mesh: face-hanging first, then
/// edge-hanging, as in the local node order.
#[derive(Debug, Default)]
pub(crate) struct Hanging {
    face: Refs,
    edge: Refs,
    /// Local node indices at the Morton corners of the coarse elements held
    /// by other ranks (few: partition boundaries only).
    ghost_rows: Vec<[u32; 8]>,
    face_lists: OnceLock<Vec<[u32; 4]>>,
    edge_lists: OnceLock<Vec<[u32; 2]>>,
}

impl Hanging {
    /// The face- and edge-hanging nodes; `ghost_rows` are the rows the
    /// coarse references marked [`GHOST`] point to.
    pub fn new(face: Refs, edge: Refs, ghost_rows: Vec<[u32; 8]>) -> Self {
        debug_assert_eq!(face.coarse.len(), face.mask.len());
        debug_assert_eq!(edge.coarse.len(), edge.mask.len());
        Hanging {
            face,
            edge,
            ghost_rows,
            face_lists: OnceLock::new(),
            edge_lists: OnceLock::new(),
        }
    }

    /// Number of hanging nodes.
    pub fn len(&self) -> usize {
        self.face.coarse.len() + self.edge.coarse.len()
    }

    /// Number of face-hanging nodes (the first ones).
    pub fn num_face(&self) -> usize {
        self.face.coarse.len()
    }

    /// The dependencies of hanging node `k`; `connectivity` is the mesh's
    /// (VTK order).
    #[inline]
    pub fn deps(&self, k: usize, connectivity: &[[u32; 8]]) -> HangingDeps {
        let nf = self.num_face();
        let (c, mask) = if k < nf {
            (self.face.coarse[k], self.face.mask[k])
        } else {
            (self.edge.coarse[k - nf], self.edge.mask[k - nf])
        };
        let mut out = HangingDeps {
            len: 0,
            nodes: [0; 4],
        };
        // A ghost's row is in Morton order, an element's in VTK order.
        const SAME: [usize; 8] = [0, 1, 2, 3, 4, 5, 6, 7];
        let (row, place) = if c & GHOST != 0 {
            (&self.ghost_rows[(c & !GHOST) as usize], &SAME)
        } else {
            (&connectivity[c as usize], &VTK_TO_MORTON)
        };
        // The set bits in increasing order (at most four).
        let mut rest = mask;
        while rest != 0 && out.len < 4 {
            out.nodes[out.len as usize] = row[place[rest.trailing_zeros() as usize]];
            out.len += 1;
            rest &= rest - 1;
        }
        out
    }

    /// [`Hanging::deps`] of the hanging nodes of `range`, in order, each
    /// coarse element's row asked of the processor [`AHEAD`] nodes before
    /// it is read: the coarse elements come in the walk's order, not in
    /// memory's.
    pub fn deps_in<'a>(
        &'a self,
        range: std::ops::Range<usize>,
        connectivity: &'a [[u32; 8]],
    ) -> impl Iterator<Item = HangingDeps> + 'a {
        range.map(move |k| {
            let ahead = (k + AHEAD < self.len()).then(|| self.coarse_element(k + AHEAD));
            if let Some(c) = ahead.flatten() {
                super::prefetch(connectivity, c);
            }
            self.deps(k, connectivity)
        })
    }

    /// The local element hanging node `k` lies on a face or edge of, if
    /// it is local (not another rank's).
    #[inline]
    pub fn coarse_element(&self, k: usize) -> Option<usize> {
        let nf = self.num_face();
        let c = if k < nf {
            self.face.coarse[k]
        } else {
            self.edge.coarse[k - nf]
        };
        (c & GHOST == 0).then_some(c as usize)
    }

    /// The face-hanging nodes' dependency lists (made on first request).
    pub fn face_lists(&self, connectivity: &[[u32; 8]]) -> &[[u32; 4]] {
        self.face_lists.get_or_init(|| {
            self.deps_in(0..self.num_face(), connectivity)
                .map(|d| [d[0], d[1], d[2], d[3]])
                .collect()
        })
    }

    /// The edge-hanging nodes' dependency lists (made on first request).
    pub fn edge_lists(&self, connectivity: &[[u32; 8]]) -> &[[u32; 2]] {
        self.edge_lists.get_or_init(|| {
            self.deps_in(self.num_face()..self.len(), connectivity)
                .map(|d| [d[0], d[1]])
                .collect()
        })
    }
}

/// How many hanging nodes ahead a pass over them asks for the rows it
/// will read.
const AHEAD: usize = 16;

/// The hanging nodes found by the independent nodes they depend on, for
/// callers that meet a hanging point as the middle of a known edge or face
/// (the OpenFOAM writer's polygons). An edge-hanging node is known by its
/// edge's two ends, a face-hanging node by the diagonal of its face that
/// holds the face's lowest node: two nodes either way, and never the same
/// two (an edge's ends differ along one axis, a diagonal's along two).
/// Entries are grouped by the lower of the two (a counting sort), so a
/// look-up reads the few entries of one node.
#[derive(Debug, Default)]
pub(crate) struct DepsIndex {
    /// Entries of independent node `a`: `start[a]..start[a + 1]`.
    start: Vec<u32>,
    /// The higher node of the two; the hanging node (`k` for local node
    /// `num_independent + k`).
    entries: Vec<(u32, u32)>,
}

/// The two nodes a face-hanging node is known by, from its face's corners
/// in Morton order (`d[0]`, `d[3]` and `d[1]`, `d[2]` are diagonals): the
/// diagonal with the lowest node.
#[inline]
pub(crate) fn face_diagonal(d: [u32; 4]) -> (u32, u32) {
    if d[0].min(d[3]) < d[1].min(d[2]) {
        (d[0], d[3])
    } else {
        (d[1], d[2])
    }
}

impl DepsIndex {
    /// The index of `hanging`'s nodes; `ni` independent nodes,
    /// `connectivity` the mesh's.
    pub fn new(hanging: &Hanging, connectivity: &[[u32; 8]], ni: usize) -> DepsIndex {
        let pair = |d: HangingDeps| -> Option<(usize, u32)> {
            let (a, b) = match d.len() {
                4 => face_diagonal([d[0], d[1], d[2], d[3]]),
                _ => (d[0], d[1]),
            };
            // Dependencies are independent nodes; anything else is no
            // entry any query could find.
            ((a.max(b) as usize) < ni).then_some((a.min(b) as usize, a.max(b)))
        };
        let mut start = vec![0u32; ni + 1];
        let all = || hanging.deps_in(0..hanging.len(), connectivity);
        for d in all() {
            if let Some((a, _)) = pair(d) {
                start[a + 1] += 1;
            }
        }
        for a in 0..ni {
            start[a + 1] += start[a];
        }
        let mut entries = vec![(0u32, 0u32); start[ni] as usize];
        // `start[a]` runs to the end of `a`'s entries, then all move back.
        for (k, d) in all().enumerate() {
            if let Some((a, b)) = pair(d) {
                entries[start[a] as usize] = (b, k as u32);
                start[a] += 1;
            }
        }
        start.copy_within(0..ni, 1);
        start[0] = 0;
        DepsIndex { start, entries }
    }

    /// The hanging node (`k`, local node `num_independent + k`) known by
    /// local nodes `a` and `b` (any order), if one is.
    #[inline]
    pub fn find(&self, a: u32, b: u32) -> Option<usize> {
        let (a, b) = (a.min(b) as usize, a.max(b));
        if a + 1 >= self.start.len() {
            return None;
        }
        let run = &self.entries[self.start[a] as usize..self.start[a + 1] as usize];
        run.iter().find(|e| e.0 == b).map(|e| e.1 as usize)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deps_index_knows_each_hanging_node_by_its_two_nodes_only() {
        let m = crate::testutil::sphere_mesh(5);
        let index = m.hanging_index();
        let (ni, nh) = (m.num_independent() as u32, m.num_hanging());
        assert!(m.num_face_hanging() > 0 && nh > m.num_face_hanging());
        let mut known = std::collections::HashSet::new();
        for k in 0..nh {
            let d = m.hanging_deps(k);
            let (a, b) = match d.len() {
                4 => face_diagonal([d[0], d[1], d[2], d[3]]),
                _ => (d[0], d[1]),
            };
            assert_eq!(index.find(a, b), Some(k), "hanging node {k}");
            assert_eq!(index.find(b, a), Some(k), "hanging node {k}");
            if d.len() == 4 {
                // The other diagonal names no node.
                let (c, e) = if (a, b) == (d[0], d[3]) {
                    (d[1], d[2])
                } else {
                    (d[0], d[3])
                };
                assert_eq!(index.find(c, e), None);
            }
            known.insert((a.min(b), a.max(b)));
        }
        let mut rng = crate::testutil::Rng(7);
        let mut tried = 0;
        for _ in 0..100_000 {
            let a = rng.range(0, ni as i64 - 1) as u32;
            // Near `a`, where the entries are.
            let b = (a as i64 + rng.range(1, 200)).min(ni as i64 + 50) as u32;
            if !known.contains(&(a, b)) {
                tried += 1;
                assert_eq!(index.find(a, b), None, "{a} {b}");
            }
        }
        assert!(tried > 90_000);
    }
}
