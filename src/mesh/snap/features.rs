//! Where a surface node goes: the surface's feature edges and corners,
//! the region of a rank's nodes they are read in, and the target of a node.

use std::borrow::Cow;

use crate::geometry::bvh::Bvh;
use crate::geometry::distance::closest_point_triangle;
use crate::geometry::hash::{FoldMap, FoldSet};
use crate::geometry::vector::{dot, norm};
use crate::geometry::{Aabb, Surface, Triangle};
use crate::mesh::dual::Bits;
use crate::octree::domain::Domain;
use crate::refine::SurfaceIndex;

use super::nearest::{NearTriangles, NEAR_REACH};
use super::{FEATURE_REACH, SURFACE_REACH};
use crate::refine::distributed::box_reaches_rank;

/// The surface in lattice units with its trees, and its features.
pub(super) struct Target<'s> {
    /// The surface's triangles and their tree: the classification's index
    /// when it was built for the mesh's domain, else made here.
    pub(super) tris: Cow<'s, [Triangle]>,
    pub(super) bvh: Cow<'s, Bvh>,
    /// Feature edges as degenerate triangles `a b b`.
    pub(super) edges: Vec<Triangle>,
    pub(super) edge_bvh: Bvh,
    /// Feature corners as degenerate triangles `p p p`.
    pub(super) corners: Vec<Triangle>,
    pub(super) corner_bvh: Bvh,
    /// The cells of a coarse grid near a feature (see [`FeatureCells`]).
    pub(super) near_features: FeatureCells,
}

/// The cells of a grid of side `side` (lattice units) that some feature
/// edge or corner's bounding box, grown by `side`, overlaps: a point in no
/// such cell has no feature within `side`, which spares most surface nodes
/// their two tree queries (most are far from any feature).
pub(super) struct FeatureCells {
    pub(super) side: f64,
    /// The cells' keys ([`FeatureCells::key`]).
    pub(super) cells: FoldSet<u64>,
}

impl FeatureCells {
    pub(super) fn new(items: &[Triangle], side: f64) -> FeatureCells {
        let mut cells = FoldSet::default();
        let cell = |x: f64| (x / side).floor() as i64;
        for t in items {
            let b = t.aabb();
            let lo = b.min.map(|x| cell(x - side));
            let hi = b.max.map(|x| cell(x + side));
            for i in lo[0]..=hi[0] {
                for j in lo[1]..=hi[1] {
                    for k in lo[2]..=hi[2] {
                        cells.insert(Self::key([i, j, k]));
                    }
                }
            }
        }
        FeatureCells { side, cells }
    }

    /// One word per cell, hashed in one step. Two cells may share a key:
    /// a point then only takes the exact feature queries it could skip.
    #[inline]
    pub(super) fn key(c: [i64; 3]) -> u64 {
        (c[0] as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)
            ^ (c[1] as u64).wrapping_mul(0xc2b2_ae3d_27d4_eb4f)
            ^ (c[2] as u64).wrapping_mul(0x1656_67b1_9e37_79f9)
    }

    /// Whether a feature may lie within `side` of `x`.
    pub(super) fn near(&self, x: [f64; 3]) -> bool {
        !self.cells.is_empty()
            && self
                .cells
                .contains(&Self::key(x.map(|v| (v / self.side).floor() as i64)))
    }
}

/// Where a feature can attract one of a rank's surface nodes from: the
/// cells of a coarse grid over the lattice cube that hold such a node. A
/// box *meets* the region when, grown by the feature reach, it overlaps
/// one of them; a larger box meets it whenever a smaller one inside does,
/// so the facets around an edge or a vertex that meets it meet it too.
/// A rank reads only the facets that meet its region: with several ranks
/// each has part of the surface, far less than the box of its nodes holds
/// (a Morton part is not a box).
pub(super) struct Region {
    /// Cell side (lattice units), cells per axis, and the growth.
    pub(super) side: f64,
    pub(super) cells: usize,
    pub(super) grow: f64,
    /// One bit per cell, x fastest.
    pub(super) bits: Bits,
    pub(super) any: bool,
    /// With a partly held surface: the ranks' cell ranges and this rank's
    /// number. A box then meets the region only if it also reaches the
    /// rank's cells by the growth: every facet whose box does is held, as
    /// is every facet around its edges and vertices (a larger box reaches
    /// further), and every feature within reach of a node still meets it.
    pub(super) held: Option<(Vec<u64>, usize)>,
}

impl Region {
    /// The region of the nodes at `points` for cells of at most `largest`
    /// (lattice units) and a reach of `reach`.
    pub(super) fn new(points: impl Iterator<Item = [f64; 3]>, largest: f64, reach: f64) -> Region {
        let root = crate::octree::octant::ROOT_LEN as f64;
        // Cells of 16 of the largest surface cells, at most 128 a side.
        let side = (16.0 * largest).max(root / 128.0);
        let cells = (root / side).ceil() as usize;
        let mut r = Region {
            side,
            cells,
            grow: reach * (1.0 + 1e-9) + 1.0,
            bits: Bits::new(cells * cells * cells),
            any: false,
            held: None,
        };
        for p in points {
            let c = p.map(|v| r.index(v));
            r.bits.set(r.key(c));
            r.any = true;
        }
        r
    }

    #[inline]
    pub(super) fn index(&self, v: f64) -> usize {
        ((v / self.side).floor().max(0.0) as usize).min(self.cells - 1)
    }

    #[inline]
    pub(super) fn key(&self, c: [usize; 3]) -> usize {
        (c[2] * self.cells + c[1]) * self.cells + c[0]
    }

    /// Whether box `b` meets the region (see [`Region`]).
    pub(super) fn meets(&self, b: &Aabb) -> bool {
        if !self.any || b.is_empty() {
            return false;
        }
        let lo = b.min.map(|v| self.index(v - self.grow));
        let hi = b.max.map(|v| self.index(v + self.grow));
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    if self.bits.get(self.key([x, y, z])) {
                        return self
                            .held
                            .as_ref()
                            .is_none_or(|(cells, r)| box_reaches_rank(cells, *r, b, self.grow));
                    }
                }
            }
        }
        false
    }
}

impl<'s> Target<'s> {
    /// `reach` is the largest feature reach any query will use
    /// ([`FEATURE_REACH`] times the largest cell); the features are those
    /// for the feature angle (degrees) that meet `region`, or `found`. `index`,
    /// if given, is `surface` in the lattice units of `domain`.
    pub(super) fn new(
        surface: &Surface,
        index: Option<&'s SurfaceIndex>,
        domain: &Domain,
        feature_angle_deg: f64,
        region: &Region,
        reach: f64,
        found: Option<(Vec<Triangle>, Vec<Triangle>)>,
    ) -> Target<'s> {
        let (tris, bvh) = match index {
            Some(ix) => (Cow::Borrowed(&ix.tris[..]), Cow::Borrowed(&ix.bvh)),
            None => {
                let d = domain;
                let tris: Vec<Triangle> = surface
                    .triangles()
                    .iter()
                    .map(|t| Triangle {
                        v: t.v.map(|p| d.to_lattice(p)),
                    })
                    .collect();
                let bvh = Bvh::new(&tris);
                (Cow::Owned(tris), Cow::Owned(bvh))
            }
        };
        let (edges, corners) = if let Some(found) = found {
            found
        } else if feature_angle_deg < 180.0 {
            features(&tris, feature_angle_deg, |b| region.meets(b))
        } else {
            (Vec::new(), Vec::new())
        };
        let items: Vec<Triangle> = edges.iter().chain(&corners).copied().collect();
        Target {
            near_features: FeatureCells::new(&items, reach.max(1.0)),
            bvh,
            edge_bvh: Bvh::new(&edges),
            corner_bvh: Bvh::new(&corners),
            tris,
            edges,
            corners,
        }
    }

    /// Where a surface node at `x` goes, for cells of side `h` around it
    /// (lattice units): a feature corner, a feature edge's or the surface's
    /// closest point, and whether it is a feature.
    /// `near` holds the triangles around the previous queries (nodes come
    /// in traversal order, so the next is usually close).
    #[inline]
    pub(super) fn of(
        &self,
        x: [f64; 3],
        h: f64,
        near: &mut NearTriangles,
    ) -> Option<([f64; 3], bool)> {
        let reach2 = (FEATURE_REACH * h) * (FEATURE_REACH * h);
        if self.near_features.near(x) {
            if let Some((i, _)) = self.corner_bvh.nearest(&self.corners, x, reach2) {
                return Some((self.corners[i as usize].v[0], true));
            }
            if let Some((i, _)) = self.edge_bvh.nearest(&self.edges, x, reach2) {
                let [a, b, c] = self.edges[i as usize].v;
                return Some((closest_point_triangle(x, a, b, c), true));
            }
        }
        // Most surface nodes lie within a cell of the surface: the
        // triangles gathered around a recent node usually hold the answer,
        // provably; else the tree, bounded by the previous answer from
        // the start (the answer is the same).
        let i = match near.nearest(&self.tris, x) {
            Some(i) => i,
            None => {
                near.gather(&self.bvh, &self.tris, x, NEAR_REACH * h);
                match near.nearest(&self.tris, x) {
                    Some(i) => i,
                    None => {
                        let far = SURFACE_REACH * h;
                        let hint = near.last;
                        self.bvh.nearest_from(&self.tris, x, far * far, hint)?.0
                    }
                }
            }
        };
        near.last = Some(i);
        let [a, b, c] = self.tris[i as usize].v;
        Some((closest_point_triangle(x, a, b, c), false))
    }
}

/// The feature edges (as triangles `a b b`) and corners (`p p p`) of
/// `tris` for a feature angle in degrees whose boxes `meets` accepts:
/// edges between facets whose normals differ by more, and edges without
/// exactly two facets; corners where not exactly two feature edges meet.
/// Vertices with the same bits are one (-0 and 0 too); edges come in the
/// order of their first facet, each from its lower end ([`order`]),
/// corners in that order of their points: the same whichever facets
/// around them are read.
///
/// Only the facets whose boxes `meets` accepts are read. It must accept
/// every box holding one it accepts (as [`Region::meets`] does): then
/// every facet around an edge or a vertex it accepts is read, so those are
/// found as over the whole surface (a rank reads the part near its own
/// nodes).
pub(super) fn features(
    tris: &[Triangle],
    angle_deg: f64,
    meets: impl Fn(&Aabb) -> bool,
) -> (Vec<Triangle>, Vec<Triangle>) {
    let tris: Vec<&Triangle> = tris.iter().filter(|t| meets(&t.aabb())).collect();
    let bits = |c: f64| if c == 0.0 { 0 } else { c.to_bits() };
    // A tuple, not an array: its fields hash as three words, without the
    // byte-slice path an array takes.
    let mut vertex: FoldMap<(u64, u64, u64), u32> = FoldMap::default();
    vertex.reserve(tris.len() / 2 + 16);
    let mut point: Vec<[f64; 3]> = Vec::with_capacity(tris.len() / 2 + 16);
    // Facets sharing a vertex or an edge mostly lie close together in a
    // file: a small direct-mapped table of recent answers (it stays in
    // cache) spares most look-ups in the large maps their cache misses.
    const RECENT: usize = 1 << 12;
    let slot = |h: u64| (h.wrapping_mul(0x9e37_79b9_7f4a_7c15) >> 52) as usize;
    let mut recent_vertex = vec![((u64::MAX, u64::MAX, u64::MAX), 0u32); RECENT];
    let ids: Vec<[u32; 3]> = tris
        .iter()
        .map(|t| {
            t.v.map(|p| {
                let [x, y, z] = p.map(bits);
                let r = &mut recent_vertex[slot(x ^ y.rotate_left(21) ^ z.rotate_left(42))];
                if r.0 == (x, y, z) {
                    return r.1;
                }
                let id = *vertex.entry((x, y, z)).or_insert_with(|| {
                    // One zero: the points do not depend on which facet
                    // names a vertex first.
                    point.push(p.map(|c| c + 0.0));
                    (point.len() - 1) as u32
                });
                *r = ((x, y, z), id);
                id
            })
        })
        .collect();
    drop(vertex);
    let nv = point.len();
    let flat = |v: &[u32; 3]| v[0] == v[1] || v[1] == v[2] || v[0] == v[2];
    // Per edge (low, high vertex): its first facet, the second, and how
    // many use it; per facet corner, its edge's place in `uses`.
    let mut edge_at: FoldMap<(u32, u32), u32> = FoldMap::default();
    edge_at.reserve(3 * tris.len() / 2 + 16);
    let mut uses: Vec<(u32, u32, u32)> = Vec::with_capacity(3 * tris.len() / 2 + 16);
    let mut facet_edges = vec![[u32::MAX; 3]; ids.len()];
    let mut recent_edge = vec![(u64::MAX, 0u32); RECENT];
    for (t, v) in ids.iter().enumerate() {
        if flat(v) {
            continue;
        }
        for k in 0..3 {
            let (a, b) = (v[k], v[(k + 1) % 3]);
            let key = (a.min(b) as u64) << 32 | a.max(b) as u64;
            let r = &mut recent_edge[slot(key)];
            let at = if r.0 == key {
                r.1
            } else {
                let at = *edge_at.entry((a.min(b), a.max(b))).or_insert_with(|| {
                    uses.push((t as u32, u32::MAX, 0));
                    (uses.len() - 1) as u32
                });
                *r = (key, at);
                at
            };
            let u = &mut uses[at as usize];
            if u.2 == 1 {
                u.1 = t as u32;
            }
            u.2 += 1;
            facet_edges[t][k] = at;
        }
    }
    drop(edge_at);
    let cos_limit = angle_deg.to_radians().cos();
    // Unit normals, each facet's once.
    let unit: Vec<[f64; 3]> = tris
        .iter()
        .map(|t| {
            let n = t.normal();
            let l = norm(n);
            if l > 0.0 {
                [n[0] / l, n[1] / l, n[2] / l]
            } else {
                [0.0; 3]
            }
        })
        .collect();
    let mut edges = Vec::new();
    let mut degree = vec![0u32; nv];
    for (t, v) in ids.iter().enumerate() {
        if flat(v) {
            continue;
        }
        for k in 0..3 {
            let (a, b) = (v[k].min(v[(k + 1) % 3]), v[k].max(v[(k + 1) % 3]));
            let (first, second, count) = uses[facet_edges[t][k] as usize];
            if first != t as u32 {
                continue;
            }
            let sharp = if count == 2 {
                let (n, m) = (unit[first as usize], unit[second as usize]);
                dot(n, m) < cos_limit
            } else {
                true
            };
            let (a, b) = (a as usize, b as usize);
            if sharp && meets(&Aabb::from_points([point[a], point[b]])) {
                // From the lower end (coordinates compared in turn), so
                // the closest points' bits do not depend on which facets
                // were read.
                let (p, q) = (point[a], point[b]);
                let (p, q) = if order(q, p).is_lt() { (q, p) } else { (p, q) };
                edges.push(Triangle::new(p, q, q));
                degree[a] += 1;
                degree[b] += 1;
            }
        }
    }
    let mut corners: Vec<Triangle> = (0..nv)
        .filter(|&v| degree[v] > 0 && degree[v] != 2)
        .filter(|&v| meets(&Aabb::from_points([point[v]])))
        .map(|v| Triangle::new(point[v], point[v], point[v]))
        .collect();
    corners.sort_unstable_by(|a, b| order(a.v[0], b.v[0]));
    (edges, corners)
}

/// Points compared by x, then y, then z.
pub(super) fn order(p: [f64; 3], q: [f64; 3]) -> std::cmp::Ordering {
    (0..3)
        .map(|a| p[a].total_cmp(&q[a]))
        .find(|o| o.is_ne())
        .unwrap_or(std::cmp::Ordering::Equal)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::shapes::default_sphere;

    #[test]
    fn features_found_everywhere_then_cut_are_those_found_in_the_region() {
        // A tiny feature angle makes most of the sphere's edges features;
        // the region is that of the vertices on one side of a plane.
        let s = default_sphere();
        let b = s.bbox();
        let domain =
            crate::octree::domain::Domain::around(b.min, b.max, crate::octree::domain::DEFAULT_FIT)
                .unwrap();
        let tris = SurfaceIndex::new(&s, &domain).tris;
        let (all_edges, all_corners) = features(&tris, 0.01, |_| true);
        let mid = 0.5 * crate::octree::octant::ROOT_LEN as f64;
        let side = |p: [f64; 3]| p[0] + 0.3 * p[1] < mid;
        let points = tris.iter().flat_map(|t| t.v).filter(|&p| side(p));
        let largest = crate::octree::octant::ROOT_LEN as f64 / 256.0;
        let region = Region::new(points, largest, FEATURE_REACH * largest);
        let (edges, corners) = features(&tris, 0.01, |b| region.meets(b));
        assert!(!corners.is_empty() && edges.len() < all_edges.len());
        let cut = |v: &[Triangle]| {
            v.iter()
                .filter(|t| region.meets(&t.aabb()))
                .map(|t| t.v)
                .collect::<Vec<_>>()
        };
        let kept = |v: &[Triangle]| v.iter().map(|t| t.v).collect::<Vec<_>>();
        assert_eq!(cut(&all_edges), kept(&edges));
        assert_eq!(cut(&all_corners), kept(&corners));
        // An edge from a point of the region meets it.
        assert!(all_edges
            .iter()
            .all(|t| !side(t.v[0]) || region.meets(&t.aabb())));
    }

    #[test]
    fn a_cube_has_twelve_feature_edges_and_eight_corners() {
        // Two triangles per face of the unit cube.
        let v = |m: usize| [(m & 1) as f64, (m >> 1 & 1) as f64, (m >> 2 & 1) as f64];
        let quads = [
            [0, 2, 3, 1],
            [4, 5, 7, 6],
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 4, 6, 2],
            [1, 3, 7, 5],
        ];
        let mut tris = Vec::new();
        for q in quads {
            tris.push(Triangle::new(v(q[0]), v(q[1]), v(q[2])));
            tris.push(Triangle::new(v(q[0]), v(q[2]), v(q[3])));
        }
        let around_origin = |h: f64| Aabb {
            min: [-h; 3],
            max: [h; 3],
        };
        let all = around_origin(10.0);
        let (edges, corners) = features(&tris, 30.0, |b| b.overlaps(&all));
        assert_eq!(edges.len(), 12);
        assert_eq!(corners.len(), 8);
        // The face diagonals are flat: no feature even at 0 degrees.
        let (edges, _) = features(&tris, 0.0, |b| b.overlaps(&all));
        assert_eq!(edges.len(), 12);
        // A box holding the corner at the origin only: its three edges,
        // found from the facets around it alone, and itself.
        let (edges, corners) = features(&tris, 30.0, |b| b.overlaps(&around_origin(0.1)));
        assert_eq!(edges.len(), 3);
        assert_eq!(corners.len(), 1);
        assert_eq!(corners[0].v[0], [0.0; 3]);
        let s = default_sphere();
        let (edges, corners) = features(s.triangles(), 30.0, |b| b.overlaps(&all));
        assert!(edges.is_empty() && corners.is_empty());
    }
}
