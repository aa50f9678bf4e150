//! Lattice points found by their Morton code: the sorted index the
//! boundary tagging ([`super::boundary`]) and the OpenFOAM writer share to
//! turn a face's corners into point numbers.
//!
//! Faces come in Morton order, so consecutive look-ups land near each
//! other: each one gallops from the previous hit and stays in cache.

use crate::octree::octant::{morton_decode, morton_encode};
use crate::octree::sort::{gallop_last_le, radix_sort_bits};

/// A lattice point's Morton code (21 bits per axis, so the far corner of
/// the root fits): sorted codes keep neighbouring points close together.
pub fn point_key(p: [u32; 3]) -> u64 {
    morton_encode(p[0], p[1], p[2])
}

/// The Morton corner of the cube with lowest corner `c` and side `s` that
/// lies at lattice point `p`, if one does.
#[inline]
pub fn corner_at(c: [u32; 3], s: u32, p: [u32; 3]) -> Option<usize> {
    let mut m = 0;
    for a in 0..3 {
        if p[a] == c[a] + s {
            m |= 1 << a;
        } else if p[a] != c[a] {
            return None;
        }
    }
    Some(m)
}

/// The mesh points near this rank a face's edge can carry between its
/// corners: the hanging local nodes (from `lattice`, the mesh's
/// [`super::Mesh::node_lattice`]) and the halo elements' corners. A mesh
/// point in the middle of an edge of a local element's face hangs on that
/// element, so the independent nodes never do; leaving them out keeps a
/// [`PointFilter`] of these small enough to stay in cache.
pub fn edge_points<'m>(
    mesh: &'m super::Mesh,
    lattice: &'m [[u32; 3]],
) -> impl Iterator<Item = [u32; 3]> + Clone + 'm {
    lattice[mesh.num_independent()..]
        .iter()
        .copied()
        .chain(halo_corners(mesh))
}

/// The corners of the halo elements (repeats included).
pub fn halo_corners(mesh: &super::Mesh) -> impl Iterator<Item = [u32; 3]> + Clone + '_ {
    mesh.halo().leaves.iter().flat_map(|h| {
        let (c, s) = (h.coords(), h.side());
        (0..8).map(move |k| super::dual::corner_coords(c, s, k))
    })
}

/// A set of lattice points, sorted by [`point_key`], each known by its
/// position in the set.
#[derive(Clone, Debug, Default)]
pub struct PointIndex {
    keys: Vec<u64>,
    hint: usize,
}

impl PointIndex {
    /// The set of the points with these keys (duplicates merged).
    pub fn new(mut keys: Vec<u64>) -> PointIndex {
        let mut tmp = Vec::new();
        radix_sort_bits(&mut keys, &mut tmp, 0, 63);
        keys.dedup();
        PointIndex { keys, hint: 0 }
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.keys.len()
    }

    /// Whether the set is empty.
    pub fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }

    /// The point at place `j`.
    pub fn point(&self, j: usize) -> [u32; 3] {
        morton_decode(self.keys[j])
    }

    /// The position of the point with key `k`, if it is in the set.
    pub fn find(&mut self, k: u64) -> Option<usize> {
        let keys = &self.keys;
        let j = gallop_last_le(keys.len(), self.hint, k, |i| keys[i])?;
        self.hint = j;
        (keys[j] == k).then_some(j)
    }
}

/// A one-hash bit filter over a set of lattice points: `false` means the
/// point is surely absent. Most face edges carry no hanging point, and the
/// filter (a few bits per point, in cache) answers those without a search,
/// from the coordinates (no Morton code to make).
#[derive(Clone, Debug)]
pub struct PointFilter {
    bits: Vec<u64>,
    shift: u32,
}

impl PointFilter {
    /// The filter of `points`.
    pub fn new(points: impl Iterator<Item = [u32; 3]> + Clone) -> PointFilter {
        // About 16 bits per point: a false positive costs one search.
        let n = (16 * points.clone().count().max(1))
            .next_power_of_two()
            .max(64);
        Self::with_bits(points, n.trailing_zeros())
    }

    /// The filter of `points` in `2^log2_bits` bits (at least 64).
    pub fn with_bits(points: impl Iterator<Item = [u32; 3]>, log2_bits: u32) -> PointFilter {
        let log2_bits = log2_bits.max(6);
        let mut f = PointFilter {
            bits: vec![0; 1 << (log2_bits - 6)],
            shift: 64 - log2_bits,
        };
        for p in points {
            let h = f.slot(p);
            f.bits[h >> 6] |= 1 << (h & 63);
        }
        f
    }

    fn slot(&self, p: [u32; 3]) -> usize {
        // Coordinates past 21 bits only fold onto others: more false
        // positives, never a miss.
        let k = p[0] as u64 ^ (p[1] as u64) << 21 ^ (p[2] as u64) << 42;
        (k.wrapping_mul(0x9e37_79b9_7f4a_7c15) >> self.shift) as usize
    }

    /// Whether the lattice point `p` may be in the set.
    pub fn may_hold(&self, p: [u32; 3]) -> bool {
        let h = self.slot(p);
        self.bits[h >> 6] >> (h & 63) & 1 == 1
    }
}

/// Which face edges between two local nodes may carry a mesh point in
/// their middle. One can only where a local edge-hanging node hangs on the
/// edge, and that node's dependencies are the edge's ends (a face-hanging
/// node is the middle of no face edge), or where a halo element has a
/// corner. Such a halo element touches the edge and, the octree being
/// balanced across edges, has half the edge's length, so it also has a
/// corner at one of the edge's ends:
///
/// ```text
///   a ------ m ------ b     local element's edge
///   |  halo  |
///   +--------+              a halo corner at m has one at a (or b)
/// ```
///
/// So each local node carries two marks, "end of an edge-hanging node's
/// edge" and "maybe a halo corner" (from a [`PointFilter`] of the halo's
/// corners, empty on one rank), and most edges are answered from the two
/// ends' marks, with no midpoint made and no hashing.
#[derive(Clone, Debug)]
pub struct EdgeMidpoints {
    marks: Vec<u8>,
    halo: PointFilter,
}

/// Mark: an end of an edge-hanging node's edge.
const HANGING_END: u8 = 1;
/// Mark: maybe a corner of a halo element.
const HALO_CORNER: u8 = 2;

impl EdgeMidpoints {
    /// The marks of `mesh`'s local nodes and its halo's corners. A node
    /// that may be a halo corner is found at the corners of the local
    /// elements (every local node is one's, or only a dependency, which no
    /// face uses), so no node's lattice point is stored.
    pub fn new(mesh: &super::Mesh) -> EdgeMidpoints {
        let halo = PointFilter::new(halo_corners(mesh));
        let mut marks = vec![0u8; mesh.num_nodes()];
        if !mesh.halo().leaves.is_empty() {
            // Most elements are far from every halo element: one look-up
            // of a coarse cell settles them, instead of eight of `halo`.
            let near = NearCells::new(&mesh.halo().leaves);
            for (&e, row) in mesh.elements().iter().zip(mesh.connectivity()) {
                if !near.may_touch(e) {
                    continue;
                }
                let (c, s) = (e.coords(), e.side());
                for (v, &n) in row.iter().enumerate() {
                    let p = super::dual::corner_coords(c, s, super::VTK_TO_MORTON[v]);
                    if halo.may_hold(p) {
                        marks[n as usize] |= HALO_CORNER;
                    }
                }
            }
        }
        for d in mesh.edge_hanging() {
            marks[d[0] as usize] |= HANGING_END;
            marks[d[1] as usize] |= HANGING_END;
        }
        EdgeMidpoints { marks, halo }
    }

    /// Whether the edge between local nodes `a` and `b`, with midpoint
    /// `m`, may carry a mesh point at `m` (`false`: surely not).
    pub fn may_hold(&self, a: usize, b: usize, m: [u32; 3]) -> bool {
        let (x, y) = (self.marks[a], self.marks[b]);
        x & y & HANGING_END != 0 || ((x | y) & HALO_CORNER != 0 && self.halo.may_hold(m))
    }

    /// [`EdgeMidpoints::may_hold`] before the midpoint is known: `false`
    /// when the answer is `false` whatever it is.
    #[inline]
    pub fn may_hold_ends(&self, a: usize, b: usize) -> bool {
        let (x, y) = (self.marks[a], self.marks[b]);
        x & y & HANGING_END != 0 || (x | y) & HALO_CORNER != 0
    }
}

/// Coarse cells (of side [`NearCells::SIDE_BITS`] bits) around a set of
/// octants, hashed to a bit filter small enough to stay in cache:
/// [`NearCells::may_touch`] is `false` for an octant that surely touches
/// none of them (not even at a corner).
///
/// ```text
///   |  cell  |  cell  |  cell  |     an octant of the set marks the cells
///   |     [##|##]     |        |     holding its closed box grown by one
///   |    ^mark both   |        |     lattice unit down; an octant no larger
///                                    than a cell touches it only if the
///                                    cell of its lowest corner is marked
/// ```
///
/// An octant no larger than a cell lies in the cell of its lowest corner
/// `c`; a point `p = c + d s` of its closed box (`d` in `{0, 1}^3`, side
/// `s`) is in the closed box of a set member `h` only if `p - d` (a point
/// of the octant's own cell) is in `h`'s closed box grown by one unit
/// down, whose cells are marked.
#[derive(Clone, Debug)]
struct NearCells {
    /// The marked cells, by their coordinates in cells.
    cells: PointFilter,
}

impl NearCells {
    /// Log2 of a cell's side in lattice units.
    const SIDE_BITS: u32 = crate::octree::octant::LATTICE_BITS - 7;
    /// Log2 of the filter's size in bits.
    const FILTER_BITS: u32 = 21;

    fn new(set: &[crate::octree::octant::Octant]) -> NearCells {
        let k = Self::SIDE_BITS;
        let cells = set.iter().flat_map(|h| {
            let (c, s) = (h.coords(), h.side());
            let lo = c.map(|v| v.saturating_sub(1) >> k);
            let hi = c.map(|v| (v + s) >> k);
            (lo[2]..=hi[2]).flat_map(move |z| {
                (lo[1]..=hi[1]).flat_map(move |y| (lo[0]..=hi[0]).map(move |x| [x, y, z]))
            })
        });
        NearCells {
            cells: PointFilter::with_bits(cells, Self::FILTER_BITS),
        }
    }

    /// Whether `o` may touch an octant of the set.
    #[inline]
    fn may_touch(&self, o: crate::octree::octant::Octant) -> bool {
        if o.side() > 1 << Self::SIDE_BITS {
            return true;
        }
        self.cells
            .may_hold(o.coords().map(|v| v >> Self::SIDE_BITS))
    }
}

/// The midpoint of `a`-`b` when they differ along one axis by an even
/// length (an edge that may carry a hanging point).
#[inline]
pub fn edge_midpoint(a: [u32; 3], b: [u32; 3]) -> Option<[u32; 3]> {
    let differ = (a[0] != b[0]) as u32 + (a[1] != b[1]) as u32 + (a[2] != b[2]) as u32;
    // The sums are even on every axis exactly when the one differing
    // length is (equal coordinates sum to an even number).
    let sum = [
        a[0] as u64 + b[0] as u64,
        a[1] as u64 + b[1] as u64,
        a[2] as u64 + b[2] as u64,
    ];
    if differ != 1 || (sum[0] | sum[1] | sum[2]) & 1 != 0 {
        return None;
    }
    Some(sum.map(|v| (v / 2) as u32))
}

/// The polygon of a quadrilateral face as mesh points: its corners in
/// order with, between two corners, their midpoint when the mesh has a
/// point there (a hanging point on the edge): when `may_hold` allows it
/// and `exists` says so from its key. Appends `(key, point)` pairs to
/// `out`.
pub fn face_polygon(
    corners: &[[u32; 3]; 4],
    may_hold: impl Fn([u32; 3]) -> bool,
    mut exists: impl FnMut(u64) -> bool,
    out: &mut Vec<(u64, [u32; 3])>,
) {
    for k in 0..4 {
        out.push((point_key(corners[k]), corners[k]));
        if let Some(m) = edge_midpoint(corners[k], corners[(k + 1) % 4]) {
            if may_hold(m) {
                let km = point_key(m);
                if exists(km) {
                    out.push((km, m));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn near_cells_miss_no_touching_octant() {
        use crate::octree::octant::{Octant, ROOT_LEN};
        let mut rng = crate::testutil::Rng(12_345);
        let mut next = |n: u32| rng.range(0, n as i64 - 1) as u32;
        // Octants of levels around the cell's (level 7), near each other.
        let random = |next: &mut dyn FnMut(u32) -> u32| {
            let level = 4 + next(8) as u8;
            let s = ROOT_LEN >> level;
            let at = |v: u32| (v / s) * s;
            let base = ROOT_LEN / 4;
            let c = [0; 3].map(|_| at(base + next(ROOT_LEN / 16)));
            Octant::new(c[0], c[1], c[2], level).unwrap()
        };
        let touch = |a: Octant, b: Octant| {
            let (ca, cb) = (a.coords(), b.coords());
            (0..3).all(|k| ca[k] <= cb[k] + b.side() && cb[k] <= ca[k] + a.side())
        };
        let (mut touching, mut rejected) = (0, 0);
        for _ in 0..200 {
            let set: Vec<Octant> = (0..3).map(|_| random(&mut next)).collect();
            let near = NearCells::new(&set);
            for _ in 0..200 {
                let o = random(&mut next);
                if set.iter().any(|&h| touch(o, h)) {
                    touching += 1;
                    assert!(near.may_touch(o), "{o:?} touches one of {set:?}");
                } else if !near.may_touch(o) {
                    rejected += 1;
                }
            }
        }
        // The test meets both cases, and the filter rejects some octants.
        assert!(touching > 100 && rejected > 1000, "{touching} {rejected}");
    }

    #[test]
    fn midpoints() {
        assert_eq!(edge_midpoint([0, 0, 0], [4, 0, 0]), Some([2, 0, 0]));
        assert_eq!(edge_midpoint([0, 4, 0], [0, 0, 0]), Some([0, 2, 0]));
        assert_eq!(edge_midpoint([0, 0, 0], [3, 0, 0]), None);
        assert_eq!(edge_midpoint([0, 0, 0], [2, 2, 0]), None);
        assert_eq!(edge_midpoint([1, 1, 1], [1, 1, 1]), None);
        assert_eq!(edge_midpoint([3, 1, 5], [3, 1, 9]), Some([3, 1, 7]));
        assert_eq!(edge_midpoint([3, 1, 5], [3, 1, 8]), None);
    }

    #[test]
    fn index_finds_members_only() {
        let pts = [[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0], [2, 0, 0]];
        let mut idx = PointIndex::new(pts.iter().map(|&p| point_key(p)).collect());
        assert_eq!(idx.len(), 4);
        for p in pts {
            let j = idx.find(point_key(p)).expect("a member");
            assert!(j < 4);
        }
        assert_eq!(idx.find(point_key([1, 0, 0])), None);
        assert_eq!(idx.find(point_key([9, 9, 9])), None);
    }

    #[test]
    fn filter_never_misses() {
        let points = (0..1000u32).map(|i| [i, 2 * i, 3 * i]);
        let f = PointFilter::new(points.clone());
        assert!(points.clone().all(|p| f.may_hold(p)));
        let false_hits = (0..1000u32)
            .filter(|&i| f.may_hold([i + 1, 2 * i, 3 * i]))
            .count();
        assert!(false_hits < 100, "{false_hits} false positives");
    }

    #[test]
    fn polygon_takes_existing_midpoints() {
        let c = [[0, 0, 0], [4, 0, 0], [4, 4, 0], [0, 4, 0]];
        let mut out = Vec::new();
        face_polygon(&c, |_| true, |k| k == point_key([4, 2, 0]), &mut out);
        let pts: Vec<[u32; 3]> = out.iter().map(|p| p.1).collect();
        assert_eq!(
            pts,
            vec![[0, 0, 0], [4, 0, 0], [4, 2, 0], [4, 4, 0], [0, 4, 0]]
        );
    }
}
