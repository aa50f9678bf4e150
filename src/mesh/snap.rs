//! Body-fitted meshes: the nodes on the surface moved onto it.
//!
//! [`Mesh::snap`] moves every independent node on the surface patch (a
//! node of a kept element next to a dropped one, not on the domain's
//! sides) to the closest point of the surface, found by exact
//! point-triangle distance through a bounding-box tree. Sharp features are
//! kept: surface edges whose facets' normals differ by more than the
//! feature angle (and open or non-manifold edges) are *feature edges*,
//! their ends where not exactly two of them meet are *feature corners*; a
//! node within [`FEATURE_REACH`] cells of a corner goes to the corner,
//! else one that near a feature edge goes to the edge's closest point.
//! Hanging nodes stay the mean of their dependencies, so the constraint
//! stays exact.
//!
//! # Validity
//!
//! After the move every element touching a moved node is measured by its
//! corners' scaled Jacobians ([`super::quality`]). At a corner below the
//! least scaled Jacobian allowed ([`SnapOptions::min_jacobian`]) the
//! corner's surface node is blamed (a hanging corner's neighbours along
//! the edges, as it follows its face or edge; else every surface node of
//! the element), and a blamed node moves a smaller fraction of its
//! displacement, down the steps of [`FRACTIONS`], until the element is
//! valid; after [`STEPS`] steps the node stays where the octree put it.
//! Only the elements around nodes that changed are measured again. The
//! nodes that end between are *partly snapped*, and the elements that
//! depend on them are reported. Then, up to `iterations` times, the
//! interior nodes within `layers` element layers of the surface nodes take
//! the mean displacement of the elements around them (the surface and
//! everything further in fixed), each move kept only where every element
//! around stays valid, and every partly snapped node tries a step up again
//! at the same time under the same rule (one check of the elements serves
//! both); the relaxed layers make room for it. A node whose step up is
//! refused stops trying: on the bunny's fluid mesh at level 5 over 95 % of
//! the later steps up that were kept came from nodes whose previous one
//! was, and the refused ones cost most of the relaxation's checks.
//!
//! # Limits
//!
//! The topology does not change. An element at a corner of the staircase
//! that is convex seen from the kept side has two or three faces on the
//! surface; where the surface bends away from the kept side (a fluid mesh
//! around a convex body, a saddle) moving all their nodes onto it flattens
//! or inverts the element, so some of those nodes stay partly snapped
//! (about half of a fluid sphere's). Hanging nodes on the surface cannot
//! reach it either: refining the leaves next to the surface to its level
//! (a distance band) keeps 2:1 steps off it.
//!
//! # Rank counts
//!
//! A node's target depends only on its lattice point and the surface, and
//! every rank holding a node computes it the same way. Every decision that
//! involves elements of several ranks (a step back, a refused move, the
//! layers) is a flag per node or-ed over the ranks sharing it through the
//! node exchange lists, and the smoothing's sums over the elements around
//! a node are fixed-point integers, exact in any order. So every rank
//! holding a node gives it the same bits, whatever the number of ranks.
//! Hanging nodes are the mean of their dependencies taken in the order of
//! their lattice points.

use serde::Serialize;

use crate::error::{Error, Result};
use crate::geometry::bvh::Bvh;
use crate::geometry::distance::{closest_point_triangle, point_box2, point_triangle2};
use crate::geometry::{Aabb, Surface, Triangle};
use crate::parallel::comm::{agree, Comm};
use crate::refine::SurfaceIndex;
use std::borrow::Cow;
use std::collections::HashMap;
use std::hash::BuildHasherDefault;
use std::sync::atomic::{AtomicU64, Ordering};

use super::dual::Bits;
use super::faces::SURFACE_PATCH;
use super::quality::{corner_scaled_jacobians, CORNER_EDGES};
use super::{Mesh, VTK_TO_MORTON};

/// Default feature angle, degrees: surface edges whose facets' normals
/// differ by more are kept as features.
pub const DEFAULT_FEATURE_ANGLE: f64 = 30.0;
/// Default element layers around the surface nodes that are relaxed.
pub const DEFAULT_LAYERS: u32 = 2;
/// Default relaxation iterations.
pub const DEFAULT_ITERATIONS: u32 = 3;
/// The least scaled Jacobian a corner of a snapped element may have by
/// default: valid elements, as close to the surface as they go.
pub const DEFAULT_MIN_JACOBIAN: f64 = 0.001;
/// The least scaled Jacobian for a finite-volume mesh (an OpenFOAM case):
/// flatter cells put their centres so far from their faces that
/// `checkMesh` finds faces skewer than 4.
pub const FOAM_MIN_JACOBIAN: f64 = 0.1;
/// The fractions of its displacement a surface node may move, in the order
/// they are tried: the first steps back little, as the curvature of a
/// smooth surface only asks for a back-off of the order of the cell size
/// squared over the radius of curvature.
pub const FRACTIONS: [f64; 8] = [1.0, 0.96875, 0.9375, 0.875, 0.75, 0.5, 0.25, 0.0];
/// Steps back of a surface node's displacement before it is left unmoved.
pub const STEPS: u8 = (FRACTIONS.len() - 1) as u8;
/// How near a feature corner or edge (in cells of the node's finest
/// element) a surface node must be to be attracted to it.
pub const FEATURE_REACH: f64 = 0.6;
/// Surface nodes further than this (in cells of the node's finest element)
/// from the surface are not moved.
pub const SURFACE_REACH: f64 = 4.0;
/// A relaxation move shorter than this fraction of the node's cell is
/// not made; the relaxation stops when no node moves.
pub const RELAX_TOLERANCE: f64 = 1e-3;
/// Fixed-point scale of the smoothing's sums: 2^32 per lattice unit.
const FIXED: f64 = 4294967296.0;
/// Passes over at least this many nodes or elements are shared with a
/// second thread when the rank has a spare core: below it a thread's
/// start costs more than it saves.
const SPLIT_AT: usize = 1 << 15;
/// The pieces such a pass is cut into ([`crate::parallel::cores::map_chunks`]).
const CHUNK: usize = 1 << 13;

/// How [`Mesh::snap`] moves the nodes.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SnapOptions {
    /// Surface edges whose facets' normals differ by more than this
    /// (degrees, 0 to 180) are features; 180 keeps none.
    pub feature_angle_deg: f64,
    /// Element layers around the surface nodes whose interior nodes are
    /// relaxed (0: none).
    pub layers: u32,
    /// Relaxation iterations (0: the surface nodes alone, scaled back).
    pub iterations: u32,
    /// The least scaled Jacobian a corner of an element may have after
    /// the snap, in (0, 0.5].
    pub min_jacobian: f64,
}

impl Default for SnapOptions {
    fn default() -> Self {
        SnapOptions {
            feature_angle_deg: DEFAULT_FEATURE_ANGLE,
            layers: DEFAULT_LAYERS,
            iterations: DEFAULT_ITERATIONS,
            min_jacobian: DEFAULT_MIN_JACOBIAN,
        }
    }
}

impl SnapOptions {
    /// Checks the ranges the configuration declares for the `mesh.snap_*`
    /// keys ([`crate::config::options`]): the angle in [0, 180], at most
    /// 100 layers and 1000 iterations, the least scaled Jacobian in (0, 0.5].
    pub fn check(&self) -> Result<()> {
        crate::config::options::check_snap(self)
    }
}

/// What [`Mesh::snap`] did, over all ranks (each node counted once, by its
/// owner), the same on every rank.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct SnapReport {
    /// Independent nodes on the surface patch.
    pub surface_nodes: u64,
    /// Of those, the ones moved onto the surface.
    pub snapped: u64,
    /// Moved part of the way (a valid position nearer was not found).
    pub partial: u64,
    /// Not moved: no valid position, also on a side of the domain, or no
    /// surface within reach.
    pub unsnapped: u64,
    /// Snapped nodes that went to a feature edge or corner.
    pub feature_nodes: u64,
    /// Interior nodes the relaxation moved.
    pub relaxed_nodes: u64,
    /// Elements that depend on a partly or not snapped surface node.
    pub reported_elements: u64,
    /// Smallest scaled Jacobian over all elements afterwards.
    pub min_scaled_jacobian: f64,
    /// Relaxation iterations run (they stop early when nothing moves).
    pub iterations: u32,
}

/// The finite-volume geometry of a snapped mesh
/// ([`Mesh::snapped_fv_geometry`]), user units.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FvGeometry {
    /// Per face, its area.
    pub face_area: Vec<f64>,
    /// Per face, its centre.
    pub face_centre: Vec<[f64; 3]>,
    /// Per face, its unit normal (from its owner out).
    pub face_normal: Vec<[f64; 3]>,
    /// Per local element, its centre.
    pub cell_centre: Vec<[f64; 3]>,
    /// Per local element, its volume.
    pub cell_volume: Vec<f64>,
}

/// The surface in lattice units with its trees, and its features.
struct Target<'s> {
    /// The surface's triangles and their tree: the classification's index
    /// when it was built for the mesh's domain, else made here.
    tris: Cow<'s, [Triangle]>,
    bvh: Cow<'s, Bvh>,
    /// Feature edges as degenerate triangles `a b b`.
    edges: Vec<Triangle>,
    edge_bvh: Bvh,
    /// Feature corners as degenerate triangles `p p p`.
    corners: Vec<Triangle>,
    corner_bvh: Bvh,
    /// The cells of a coarse grid near a feature (see [`FeatureCells`]).
    near_features: FeatureCells,
}

/// The half side (in cells of the node's finest element) of the cube
/// around a node whose triangles [`NearTriangles`] gathers.
const NEAR_REACH: f64 = 2.0;

/// The triangles whose bounding boxes meet a cube around a recent surface
/// node: the nearest of them to a point `x` well inside the cube is the
/// nearest of all when it is nearer than the cube's side from `x` (every
/// other triangle lies outside the cube).
#[derive(Default)]
struct NearTriangles {
    centre: [f64; 3],
    half: f64,
    /// The triangles and their bounding boxes.
    found: Vec<(u32, Aabb)>,
    /// With `wide` (the processor has AVX-512F), the same eight to a
    /// chunk, as columns.
    wide: bool,
    chunks: Vec<Chunk>,
    /// The last answer, a first bound for the tree.
    last: Option<u32>,
}

/// Eight gathered triangles (the last chunk padded with boxes at
/// infinity), coordinate `k` of lane `j` at `[k][j]`.
#[derive(Clone, Copy)]
struct Chunk {
    ids: [u32; 8],
    lo: [[f64; 8]; 3],
    hi: [[f64; 8]; 3],
    a: [[f64; 8]; 3],
    b: [[f64; 8]; 3],
    c: [[f64; 8]; 3],
}

impl Chunk {
    const EMPTY: Chunk = Chunk {
        ids: [u32::MAX; 8],
        lo: [[f64::INFINITY; 8]; 3],
        hi: [[f64::INFINITY; 8]; 3],
        a: [[0.0; 8]; 3],
        b: [[0.0; 8]; 3],
        c: [[0.0; 8]; 3],
    };
}

impl NearTriangles {
    /// Gathers the triangles around the cube of half side `half` at `x`.
    fn gather(&mut self, bvh: &Bvh, tris: &[Triangle], x: [f64; 3], half: f64) {
        self.centre = x;
        self.half = half;
        self.found.clear();
        bvh.query_candidate_boxes(x.map(|v| v - half), x.map(|v| v + half), &mut self.found);
        self.chunks.clear();
        if self.wide {
            for piece in self.found.chunks(8) {
                self.chunks.push(Chunk::EMPTY);
                let ch = self.chunks.last_mut().expect("a chunk was pushed");
                for (j, &(t, b)) in piece.iter().enumerate() {
                    let [p, q, r] = tris[t as usize].v;
                    ch.ids[j] = t;
                    for k in 0..3 {
                        ch.lo[k][j] = b.min[k];
                        ch.hi[k][j] = b.max[k];
                        ch.a[k][j] = p[k];
                        ch.b[k][j] = q[k];
                        ch.c[k][j] = r[k];
                    }
                }
            }
        }
    }

    /// The triangle nearest `x` (ties to the lowest index) if the gathered
    /// ones prove it: nearer than any point outside the cube, with a
    /// margin for rounding.
    fn nearest(&self, tris: &[Triangle], x: [f64; 3]) -> Option<u32> {
        let dx = (0..3)
            .map(|a| (x[a] - self.centre[a]).abs())
            .fold(0.0, f64::max);
        let room = self.half - dx;
        if room <= 0.0 {
            return None;
        }
        let mut near = Nearest {
            best: None,
            bound: 0.98 * room * room,
        };
        // The last answer first: usually near, it prunes the rest.
        if let Some(t) = self.last {
            let [p, q, r] = tris[t as usize].v;
            near.offer(t, point_triangle2(x, p, q, r));
        }
        #[cfg(target_arch = "x86_64")]
        if self.wide {
            // SAFETY: `wide` says the processor has AVX-512F.
            unsafe { wide::scan(&self.chunks, tris, x, &mut near) };
            return near.best.map(|b| b.0);
        }
        for &(t, b) in &self.found {
            if point_box2(x, b.min, b.max) > near.bound {
                continue;
            }
            let [p, q, r] = tris[t as usize].v;
            near.offer(t, point_triangle2(x, p, q, r));
        }
        near.best.map(|b| b.0)
    }
}

/// The nearest triangle so far and its squared distance, and the bound a
/// nearer one must beat (the distance limit until one is found).
struct Nearest {
    best: Option<(u32, f64)>,
    bound: f64,
}

impl Nearest {
    /// Triangle `t` at squared distance `d`: kept if nearer, or as near
    /// with a lower index (so the answer does not depend on the order).
    #[inline(always)]
    fn offer(&mut self, t: u32, d: f64) {
        let better = match self.best {
            None => d < self.bound,
            Some((bt, bd)) => d < bd || (d == bd && t < bt),
        };
        if better {
            self.best = Some((t, d));
            self.bound = d;
        }
    }
}

/// The cells of a grid of side `side` (lattice units) that some feature
/// edge or corner's bounding box, grown by `side`, overlaps: a point in no
/// such cell has no feature within `side`, which spares most surface nodes
/// their two tree queries (most are far from any feature).
struct FeatureCells {
    side: f64,
    /// The cells' keys ([`FeatureCells::key`]).
    cells: std::collections::HashSet<u64, BuildHasherDefault<FoldHasher>>,
}

impl FeatureCells {
    fn new(items: &[Triangle], side: f64) -> FeatureCells {
        let mut cells = std::collections::HashSet::default();
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
    fn key(c: [i64; 3]) -> u64 {
        (c[0] as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)
            ^ (c[1] as u64).wrapping_mul(0xc2b2_ae3d_27d4_eb4f)
            ^ (c[2] as u64).wrapping_mul(0x1656_67b1_9e37_79f9)
    }

    /// Whether a feature may lie within `side` of `x`.
    fn near(&self, x: [f64; 3]) -> bool {
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
struct Region {
    /// Cell side (lattice units), cells per axis, and the growth.
    side: f64,
    cells: usize,
    grow: f64,
    /// One bit per cell, x fastest.
    bits: Bits,
    any: bool,
}

impl Region {
    /// The region of the nodes at `points` for cells of at most `largest`
    /// (lattice units) and a reach of `reach`.
    fn new(points: impl Iterator<Item = [f64; 3]>, largest: f64, reach: f64) -> Region {
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
        };
        for p in points {
            let c = p.map(|v| r.index(v));
            r.bits.set(r.key(c));
            r.any = true;
        }
        r
    }

    #[inline]
    fn index(&self, v: f64) -> usize {
        ((v / self.side).floor().max(0.0) as usize).min(self.cells - 1)
    }

    #[inline]
    fn key(&self, c: [usize; 3]) -> usize {
        (c[2] * self.cells + c[1]) * self.cells + c[0]
    }

    /// Whether box `b` meets the region (see [`Region`]).
    fn meets(&self, b: &Aabb) -> bool {
        if !self.any || b.is_empty() {
            return false;
        }
        let lo = b.min.map(|v| self.index(v - self.grow));
        let hi = b.max.map(|v| self.index(v + self.grow));
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    if self.bits.get(self.key([x, y, z])) {
                        return true;
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
    /// if given, is `surface` in the lattice units of `mesh`'s domain.
    fn new(
        surface: &Surface,
        index: Option<&'s SurfaceIndex>,
        mesh: &Mesh,
        feature_angle_deg: f64,
        region: &Region,
        reach: f64,
        found: Option<(Vec<Triangle>, Vec<Triangle>)>,
    ) -> Target<'s> {
        let (tris, bvh) = match index {
            Some(ix) => (Cow::Borrowed(&ix.tris[..]), Cow::Borrowed(&ix.bvh)),
            None => {
                let d = mesh.domain();
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
    fn of(&self, x: [f64; 3], h: f64, near: &mut NearTriangles) -> Option<([f64; 3], bool)> {
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

/// A fast, fixed hash for the welding maps and the feature cells (their
/// order never shows: the outputs follow the triangles' order).
#[derive(Default)]
struct FoldHasher(u64);

impl std::hash::Hasher for FoldHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for c in bytes.chunks(8) {
            let mut w = [0u8; 8];
            w[..c.len()].copy_from_slice(c);
            self.write_u64(u64::from_le_bytes(w));
        }
    }
    fn write_u64(&mut self, x: u64) {
        self.0 = (self.0.rotate_left(26) ^ x).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    }
}

type FoldMap<K, V> = HashMap<K, V, BuildHasherDefault<FoldHasher>>;

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
fn features(
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
            let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
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
                n[0] * m[0] + n[1] * m[1] + n[2] * m[2] < cos_limit
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
fn order(p: [f64; 3], q: [f64; 3]) -> std::cmp::Ordering {
    (0..3)
        .map(|a| p[a].total_cmp(&q[a]))
        .find(|o| o.is_ne())
        .unwrap_or(std::cmp::Ordering::Equal)
}

/// The state of one snap: positions in lattice units, per local node.
struct Snapper<'a> {
    mesh: &'a Mesh,
    comm: &'a dyn Comm,
    /// Whether a second thread may take pieces of the long passes
    /// ([`crate::parallel::cores::map_chunks`]).
    spare: bool,
    /// The processor has AVX-512F ([`crate::parallel::cores::avx512`]).
    wide: bool,
    lists: Vec<(u32, Vec<u32>)>,
    ni: usize,
    /// Lattice points of every local node.
    lattice: Vec<[u32; 3]>,
    /// Hanging node `k`'s dependencies in the order of their lattice
    /// points (2 or 4).
    deps: Vec<([u32; 4], u8)>,
    /// Current positions of every local node.
    pos: Vec<[f64; 3]>,
    /// Independent surface nodes that move, with their targets and
    /// steps back (`STEPS`: unmoved).
    snap: Vec<bool>,
    target: Vec<[f64; 3]>,
    step: Vec<u8>,
    /// Partly snapped nodes that still try to step up: a node whose step
    /// up was refused once stops (the next tries nearly all fail too).
    climbing: Vec<bool>,
    /// Interior independent nodes that the relaxation moves.
    layer: Vec<bool>,
    /// Elements touching a node that may move.
    active: Vec<u32>,
    /// The active elements depending on each independent node: node `n`'s
    /// are `adj[adj_start[n]..adj_start[n + 1]]`.
    adj_start: Vec<u32>,
    adj: Vec<u32>,
    /// The finest element side at each independent node (lattice units).
    side: Vec<u64>,
    /// The least scaled Jacobian allowed.
    min_jacobian: f64,
    /// Scratch kept from one use to the next (fresh pages cost more than
    /// the work on them): per independent node, the check's flags (all
    /// zero between uses) and the relaxation's sums; one bit per element,
    /// whether it was seen (all clear between uses).
    flags: Vec<u8>,
    sums: Vec<u64>,
    seen: Bits,
    /// Per element, the least figure of [`corner_verdict`] at its last
    /// measurement. Every move is followed by the measurement of the
    /// elements around, so for the active elements it is the current one.
    least: Vec<f64>,
}

impl<'a> Snapper<'a> {
    /// Calls `f` with each independent node element `e`'s corners depend
    /// on (hanging corners through their dependencies; repeats possible).
    fn support(&self, e: usize, mut f: impl FnMut(usize)) {
        for &c in &self.mesh.connectivity()[e] {
            let c = c as usize;
            if c < self.ni {
                f(c);
            } else {
                let (d, n) = self.deps[c - self.ni];
                for &x in &d[..n as usize] {
                    f(x as usize);
                }
            }
        }
    }

    /// The independent nodes element `e`'s corners depend on, as
    /// [`Snapper::support`] gives them: the first `len` of the array.
    #[inline]
    fn support_list(&self, e: usize) -> ([u32; 32], usize) {
        let mut nodes = [0u32; 32];
        let mut len = 0;
        self.support(e, |n| {
            nodes[len] = n as u32;
            len += 1;
        });
        (nodes, len)
    }

    /// In a pass over the elements `list`, now at `k`: fetches the corners'
    /// positions for the element a few places ahead. Nodes are numbered
    /// apart from elements, so an element's corners lie all over that
    /// array, and the passes wait on those loads otherwise.
    #[inline]
    fn fetch_ahead(&self, list: &[u32], k: usize) {
        if let Some(&ahead) = list.get(k + 6) {
            for &n in &self.mesh.connectivity()[ahead as usize] {
                super::prefetch(&self.pos, n as usize);
            }
        }
    }

    /// Node `n`'s lattice point.
    #[inline]
    fn lattice(&self, n: usize) -> [f64; 3] {
        self.lattice[n].map(f64::from)
    }

    /// Flags the `eligible` nodes to blame for invalid element `e`: at
    /// each corner below the least scaled Jacobian the corner's node (through its
    /// dependencies when it hangs), else its three neighbours along the
    /// edges, else every eligible node of the element.
    /// Newly flagged nodes are appended to `flagged`.
    fn blame(
        &self,
        e: usize,
        failed: u8,
        eligible: impl Fn(usize) -> bool,
        flags: &mut [u8],
        flagged: &mut Vec<u32>,
    ) {
        let c = &self.mesh.connectivity()[e];
        let mut any = false;
        let mut flag = |node: u32, any: &mut bool| {
            let node = node as usize;
            let mut visit = |n: usize| {
                if eligible(n) {
                    if flags[n] == 0 {
                        flags[n] = 1;
                        flagged.push(n as u32);
                    }
                    *any = true;
                }
            };
            if node < self.ni {
                visit(node);
            } else {
                let (d, k) = self.deps[node - self.ni];
                d[..k as usize].iter().for_each(|&x| visit(x as usize));
            }
        };
        for v in 0..8 {
            if failed >> v & 1 == 0 {
                continue;
            }
            // A hanging corner is where its face or edge puts it: moving
            // its dependencies back rarely helps, its neighbours do.
            let mut here = false;
            if (c[v] as usize) < self.ni {
                flag(c[v], &mut here);
            }
            if !here {
                for w in CORNER_EDGES[v] {
                    flag(c[w], &mut here);
                }
            }
            any |= here;
        }
        if !any {
            for &n in c {
                flag(n, &mut any);
            }
        }
    }

    /// Combines `words` values per independent node over the ranks sharing
    /// it: each rank's own values are sent, and `combine` folds in those
    /// received (it must be commutative and associative).
    fn exchange<T: Copy + Into<u64>>(
        &self,
        vals: &mut [T],
        words: usize,
        combine: impl Fn(&mut T, u64),
    ) {
        if self.comm.size() == 1 {
            return;
        }
        let mut counts = vec![0usize; self.comm.size()];
        let mut send = Vec::new();
        for (r, nodes) in &self.lists {
            counts[*r as usize] = nodes.len() * words;
            for &n in nodes {
                let n = n as usize;
                send.extend(vals[n * words..(n + 1) * words].iter().map(|&v| v.into()));
            }
        }
        let (recv, got) = self.comm.alltoallv_u64(&send, &counts);
        let mut at = 0;
        for (r, &len) in got.iter().enumerate() {
            if let Ok(k) = self.lists.binary_search_by_key(&(r as u32), |l| l.0) {
                let nodes = &self.lists[k].1;
                for (j, &n) in nodes.iter().enumerate() {
                    let n = n as usize;
                    for w in 0..words {
                        combine(&mut vals[n * words + w], recv[at + j * words + w]);
                    }
                }
            }
            at += len;
        }
    }

    /// The position of surface node `n` after its steps back.
    fn snapped_position(&self, n: usize) -> [f64; 3] {
        let (x, t, k) = (self.lattice(n), self.target[n], self.step[n]);
        match k {
            0 => t,
            STEPS => x,
            _ => {
                let s = FRACTIONS[k as usize];
                std::array::from_fn(|a| x[a] + (t[a] - x[a]) * s)
            }
        }
    }

    /// Hanging nodes from their dependencies.
    fn update_hanging(&mut self) {
        for k in 0..self.deps.len() {
            self.pos[self.ni + k] = mean(&self.pos, self.deps[k]);
        }
    }

    fn place_surface_nodes(&mut self) {
        for n in 0..self.ni {
            if self.snap[n] {
                self.pos[n] = self.snapped_position(n);
            }
        }
    }

    /// The elements a snap may change, from the surface nodes that may
    /// move (`surface`): the nodes the relaxation moves (interior nodes
    /// within `opts.layers` elements of those, off every patch), the
    /// active elements (those depending on either kind, in storage order)
    /// and the adjacency from the nodes to them (compressed rows: node
    /// `n`'s elements are `adj[start[n]..start[n + 1]]`, each once, in
    /// order). Collective.
    #[allow(clippy::type_complexity)]
    fn moving_elements(
        &self,
        surface: &dyn Fn(usize) -> bool,
        masks: &[u64],
        opts: &SnapOptions,
    ) -> (Vec<bool>, Vec<u32>, Vec<u32>, Vec<u32>) {
        let (ni, elements) = (self.ni, self.mesh.elements().len());
        // Byte flags: the passes look them up all over the nodes, and a
        // byte array stays in cache where a word array does not.
        let mut near: Vec<u8> = (0..ni).map(|n| surface(n) as u8).collect();
        for _ in 0..opts.layers {
            let mut next = near.clone();
            for e in 0..elements {
                let mut touch = false;
                self.support(e, |n| touch |= near[n] != 0);
                if touch {
                    self.support(e, |n| next[n] = 1);
                }
            }
            self.exchange(&mut next, 1, |a, b| *a |= b as u8);
            near = next;
        }
        let layer: Vec<bool> = (0..ni)
            .map(|n| near[n] != 0 && masks[n] == 0 && opts.iterations > 0)
            .collect();
        let moving: Vec<bool> = (0..ni).map(|n| surface(n) || layer[n]).collect();
        drop(near);
        // Each node once per element (a node several hanging corners
        // depend on comes up several times): `last` holds the element
        // that last counted it.
        let mut active = Vec::new();
        let mut start = vec![0u32; ni + 1];
        let mut last = vec![u32::MAX; ni];
        for e in 0..elements {
            let (nodes, len) = self.support_list(e);
            let nodes = &nodes[..len];
            if nodes.iter().any(|&n| moving[n as usize]) {
                active.push(e as u32);
                for &n in nodes {
                    let n = n as usize;
                    if last[n] != e as u32 {
                        last[n] = e as u32;
                        start[n + 1] += 1;
                    }
                }
            }
        }
        drop(last);
        for n in 0..ni {
            start[n + 1] += start[n];
        }
        let mut adj = vec![0u32; start[ni] as usize];
        let mut fill = start.clone();
        for &e in &active {
            self.support(e as usize, |n| {
                // The elements come in order: a repeat is the last one.
                let at = fill[n] as usize;
                if at == start[n] as usize || adj[at - 1] != e {
                    adj[at] = e;
                    fill[n] += 1;
                }
            });
        }
        debug_assert!((0..ni).all(|n| fill[n] == start[n + 1]));
        (layer, active, start, adj)
    }

    /// The elements of `cands` with a corner below the least scaled
    /// Jacobian, and those corners ([`corner_verdict`]); every element's
    /// figure is kept in `least`. Their hanging corners are placed from their dependencies
    /// first: every hanging node depending on a changed node is a corner of
    /// an element around it.
    fn bad_among(&mut self, cands: &[u32]) -> Vec<(u32, u8)> {
        let conn = self.mesh.connectivity();
        let j2 = self.min_jacobian * self.min_jacobian;
        let (ni, deps) = (self.ni, &self.deps);
        let (fixed, hanging) = self.pos.split_at_mut(ni);
        let fixed = &*fixed;
        // With a spare core two threads measure: they may place the same
        // hanging node (with the same bits), and each element's figure is
        // stored by the one that measures it.
        let hanging = crate::parallel::cores::shared_f64(hanging.as_flattened_mut());
        let least = crate::parallel::cores::shared_f64(&mut self.least);
        let m = Measure {
            conn,
            ni,
            deps,
            fixed,
            hanging,
            least,
            j2,
            wide: self.wide,
        };
        let measure = |part: std::ops::Range<usize>| m.part(&cands[part]);
        let spare = self.spare && cands.len() >= SPLIT_AT;
        crate::parallel::cores::map_chunks(spare, cands.len(), CHUNK, measure).concat()
    }

    /// The active elements depending on the nodes `nodes`, once each:
    /// only they can have changed.
    fn around(&mut self, nodes: &[u32]) -> Vec<u32> {
        // One bit per element (a set that stays in the first cache
        // level), all zero from one call to the next; read out word by
        // word, the elements come in storage order without a sort, so
        // the measurements read the connectivity and the positions near
        // where they read last.
        let (mut lo, mut hi) = (usize::MAX, 0);
        for &n in nodes {
            let n = n as usize;
            let (a, b) = (self.adj_start[n] as usize, self.adj_start[n + 1] as usize);
            for &e in &self.adj[a..b] {
                self.seen.set(e as usize);
                lo = lo.min(e as usize);
                hi = hi.max(e as usize);
            }
        }
        let mut out = Vec::new();
        self.seen.drain_into(lo, hi, &mut out);
        out
    }

    /// Steps back the displacements of the surface nodes of invalid
    /// elements until every element is valid or those nodes are back.
    fn scale_back(&mut self) {
        let cands = self.active.clone();
        // The hanging nodes follow in the first measurement: every one that
        // depends on a moving node is a corner of an active element.
        self.place_surface_nodes();
        self.settle(
            cands,
            |s, n| s.snap[n] && s.step[n] < STEPS,
            |s, n| {
                s.step[n] += 1;
                s.pos[n] = s.snapped_position(n);
            },
        );
    }

    /// Measures the elements `cands`; while some are invalid, the nodes
    /// they blame (among those `blamable` accepts) take one step back
    /// (`step_back`, on every rank holding them) and the elements around
    /// them are measured again. Collective.
    fn settle(
        &mut self,
        mut cands: Vec<u32>,
        blamable: impl Fn(&Self, usize) -> bool,
        mut step_back: impl FnMut(&mut Self, usize),
    ) {
        // Kept from one call to the next and left all zero: fresh pages
        // cost more than the rounds after the first, which are small.
        let mut flags = std::mem::take(&mut self.flags);
        flags.resize(self.ni, 0);
        let mut flagged: Vec<u32> = Vec::new();
        loop {
            let bad = self.bad_among(&cands);
            flagged.clear();
            for (e, failed) in bad {
                self.blame(
                    e as usize,
                    failed,
                    |n| blamable(self, n),
                    &mut flags,
                    &mut flagged,
                );
            }
            // The owner of a flagged node has its flag after the exchange.
            self.exchange(&mut flags, 1, |a, b| *a |= b as u8);
            if self.comm.size() > 1 {
                // Flags other ranks set on shared nodes.
                for (_, nodes) in &self.lists {
                    flagged.extend(nodes.iter().filter(|&&n| flags[n as usize] != 0));
                }
                flagged.sort_unstable();
                flagged.dedup();
            }
            let owned = self.mesh.num_owned() as u32;
            let mut count = [flagged.iter().filter(|&&n| n < owned).count() as u64];
            self.comm.sum_u64(&mut count);
            if count[0] == 0 {
                for &n in &flagged {
                    flags[n as usize] = 0;
                }
                break;
            }
            for &n in &flagged {
                step_back(self, n as usize);
            }
            cands = self.around(&flagged);
            for &n in &flagged {
                flags[n as usize] = 0;
            }
        }
        debug_assert!(flags.iter().all(|&f| f == 0));
        self.flags = flags;
    }

    /// Undoes the moves of `moved` nodes (already made) in invalid
    /// elements (`undo` restores a node's position) until every element is
    /// valid or nothing is left to undo. Only elements around moved nodes
    /// are measured: the others were valid (or beyond help) before.
    fn refuse_invalid(&mut self, moved: &mut [bool], mut undo: impl FnMut(&mut Self, usize)) {
        let nodes: Vec<u32> = (0..self.ni as u32).filter(|&n| moved[n as usize]).collect();
        // When many nodes moved, nearly every active element is around one
        // (93 to 98 % on the dragon): measuring them all costs less than
        // finding which. The others change nothing: their positions did
        // not move, and they blame no node that moved.
        let cands = if nodes.len() * 8 > self.ni {
            self.active.clone()
        } else {
            self.around(&nodes)
        };
        let moved = std::cell::Cell::from_mut(moved).as_slice_of_cells();
        self.settle(
            cands,
            |_, n| moved[n].get(),
            |s, n| {
                moved[n].set(false);
                undo(s, n);
            },
        );
    }

    /// One relaxation step of the layer nodes, each moving only by more
    /// than [`RELAX_TOLERANCE`] of its cell, and one step up of every
    /// partly snapped node, the moves kept where the elements stay valid;
    /// returns how many moved (over all ranks, owned nodes).
    fn relax(&mut self) -> u64 {
        // The hanging nodes are where their dependencies put them: the
        // measurements after every change placed those around it.
        let ni = self.ni;
        let conn = self.mesh.connectivity();
        let mut sums = std::mem::take(&mut self.sums);
        sums.clear();
        sums.resize(4 * ni, 0);
        let elements = self.mesh.elements();
        for (k, &e) in self.active.iter().enumerate() {
            self.fetch_ahead(&self.active, k);
            let c = &conn[e as usize];
            if !c
                .iter()
                .any(|&n| (n as usize) < ni && self.layer[n as usize])
            {
                continue;
            }
            // The corners' lattice points from the element's anchor and
            // side (the same numbers as the nodes' own, without fetching
            // eight of them from all over memory).
            let (anchor, side) = (elements[e as usize].coords(), elements[e as usize].side());
            let mut d = [0.0f64; 3];
            for (v, &n) in c.iter().enumerate() {
                let p = self.pos[n as usize];
                let x = super::dual::corner_coords(anchor, side, VTK_TO_MORTON[v]);
                debug_assert_eq!(x, self.lattice[n as usize]);
                for a in 0..3 {
                    d[a] += p[a] - f64::from(x[a]);
                }
            }
            let fixed = d.map(|v| ((v / 8.0) * FIXED).round() as i64 as u64);
            for &n in c {
                let n = n as usize;
                if n < ni && self.layer[n] {
                    for a in 0..3 {
                        sums[4 * n + a] = sums[4 * n + a].wrapping_add(fixed[a]);
                    }
                    sums[4 * n + 3] += 1;
                }
            }
        }
        self.exchange(&mut sums, 4, |a, b| *a = a.wrapping_add(b));
        let mut moved = vec![false; ni];
        let mut old = Vec::new();
        for n in 0..ni {
            let count = sums[4 * n + 3];
            if !self.layer[n] || count == 0 {
                continue;
            }
            let x = self.lattice(n);
            let p: [f64; 3] = std::array::from_fn(|a| {
                x[a] + (sums[4 * n + a] as i64 as f64 / FIXED) / count as f64
            });
            // Moves below the tolerance are not made: the elements around
            // need no new check, and the relaxation ends.
            let tol = RELAX_TOLERANCE * self.side[n] as f64;
            if (0..3).any(|a| (self.pos[n][a] - p[a]).abs() > tol) {
                old.push((n as u32, self.pos[n]));
                self.pos[n] = p;
                moved[n] = true;
            }
        }
        self.sums = sums;
        // The partly snapped nodes step up at the same time: one check of
        // the elements around serves both moves.
        for (n, m) in moved.iter_mut().enumerate() {
            if self.snap[n] && self.climbing[n] && self.step[n] > 0 {
                self.step[n] -= 1;
                self.pos[n] = self.snapped_position(n);
                *m = true;
            }
        }
        self.refuse_invalid(&mut moved, |s, n| {
            if s.snap[n] {
                s.climbing[n] = false;
                s.step[n] += 1;
                s.pos[n] = s.snapped_position(n);
            } else {
                let k = old.binary_search_by_key(&(n as u32), |o| o.0).unwrap_or(0);
                s.pos[n] = old[k].1;
            }
        });
        let mut count = [moved[..self.mesh.num_owned()]
            .iter()
            .filter(|&&m| m)
            .count() as u64];
        self.comm.sum_u64(&mut count);
        count[0]
    }
}

/// Per corner of the hexahedron `p` (VTK order), the determinant of its
/// three edges ([`CORNER_EDGES`]) and the product of their squared
/// lengths. Computed across the corners (one array per coordinate), so
/// each step is one operation on all eight: the compiler packs them.
#[inline(always)]
fn corner_terms(p: &[[f64; 3]; 8]) -> ([f64; 8], [f64; 8]) {
    let column = |a: usize| -> [f64; 8] { std::array::from_fn(|k| p[k][a]) };
    let (x, y, z) = (column(0), column(1), column(2));
    let edge = |c: &[f64; 8], e: usize| -> [f64; 8] {
        std::array::from_fn(|k| c[CORNER_EDGES[k][e]] - c[k])
    };
    let (ax, ay, az) = (edge(&x, 0), edge(&y, 0), edge(&z, 0));
    let (bx, by, bz) = (edge(&x, 1), edge(&y, 1), edge(&z, 1));
    let (cx, cy, cz) = (edge(&x, 2), edge(&y, 2), edge(&z, 2));
    let det = std::array::from_fn(|k| {
        ax[k] * (by[k] * cz[k] - bz[k] * cy[k]) - ay[k] * (bx[k] * cz[k] - bz[k] * cx[k])
            + az[k] * (bx[k] * cy[k] - by[k] * cx[k])
    });
    let product = std::array::from_fn(|k| {
        (ax[k] * ax[k] + ay[k] * ay[k] + az[k] * az[k])
            * (bx[k] * bx[k] + by[k] * by[k] + bz[k] * bz[k])
            * (cx[k] * cx[k] + cy[k] * cy[k] + cz[k] * cz[k])
    });
    (det, product)
}

/// The corners of the hexahedron `p` (VTK order) whose scaled Jacobian is
/// below `sqrt(j2)` or not positive, as bits (bit `k`: corner `k`; 0 when
/// the element is valid), tested as `det >= j |e0| |e1| |e2|` squared
/// without roots or divisions; and the least over the corners of the
/// scaled Jacobian times its absolute value (0 where an edge has no
/// length), which orders the elements as their least scaled Jacobians do.
#[inline(always)]
fn corner_verdict(p: &[[f64; 3]; 8], j2: f64) -> (u8, f64) {
    let (det, product) = corner_terms(p);
    let mut failed = 0u8;
    for k in 0..8 {
        let pass = det[k] > 0.0 && det[k] * det[k] >= j2 * product[k];
        failed |= (!pass as u8) << k;
    }
    let figure: [f64; 8] = std::array::from_fn(|k| {
        if product[k] == 0.0 {
            0.0
        } else {
            det[k] * det[k].abs() / product[k]
        }
    });
    (failed, figure.iter().fold(f64::INFINITY, |l, &f| l.min(f)))
}

/// What [`Snapper::bad_among`] measures with, shared by its threads.
struct Measure<'a> {
    conn: &'a [[u32; 8]],
    ni: usize,
    deps: &'a [([u32; 4], u8)],
    fixed: &'a [[f64; 3]],
    /// The hanging nodes' positions, placed as they are met (two threads
    /// may place the same one, with the same bits).
    hanging: &'a [AtomicU64],
    /// Per element, its least figure, stored by the thread measuring it.
    least: &'a [AtomicU64],
    j2: f64,
    /// The processor has AVX-512F.
    wide: bool,
}

impl Measure<'_> {
    /// The elements of `part` with a corner below the least scaled
    /// Jacobian, and those corners; with AVX-512 where the processor has
    /// it ([`wide`]): the same verdicts and figures. (A least figure of
    /// zero may come with the other sign.)
    fn part(&self, part: &[u32]) -> Vec<(u32, u8)> {
        #[cfg(target_arch = "x86_64")]
        if self.wide {
            // SAFETY: `wide` says the processor has AVX-512F.
            return unsafe { wide::measure(self, part) };
        }
        self.run(part, corner_verdict)
    }

    /// [`Measure::part`] with the corner test `verdict`.
    #[inline(always)]
    fn run(
        &self,
        part: &[u32],
        verdict: impl Fn(&[[f64; 3]; 8], f64) -> (u8, f64),
    ) -> Vec<(u32, u8)> {
        let (conn, ni, deps, fixed) = (self.conn, self.ni, self.deps, self.fixed);
        let mut bad = Vec::new();
        for (k, &e) in part.iter().enumerate() {
            if let Some(&ahead) = part.get(k + 6) {
                for &n in &conn[ahead as usize] {
                    let n = n as usize;
                    if n < ni {
                        super::prefetch(fixed, n);
                    } else {
                        super::prefetch(self.hanging, 3 * (n - ni));
                    }
                }
            }
            let mut p = [[0.0; 3]; 8];
            for (q, &n) in p.iter_mut().zip(&conn[e as usize]) {
                let n = n as usize;
                *q = if n < ni {
                    fixed[n]
                } else {
                    let m = mean(fixed, deps[n - ni]);
                    for (w, v) in self.hanging[3 * (n - ni)..][..3].iter().zip(m) {
                        w.store(v.to_bits(), Ordering::Relaxed);
                    }
                    m
                };
            }
            let (failed, figure) = verdict(&p, self.j2);
            self.least[e as usize].store(figure.to_bits(), Ordering::Relaxed);
            if failed != 0 {
                bad.push((e, failed));
            }
        }
        bad
    }
}

/// The element check and the nearest-triangle scan with AVX-512, chosen at
/// run time (the build targets x86-64-v2). Measured on the dragon at level
/// 10, one thread: a full check of its 1.83 million active elements in
/// about 0.15 s instead of 0.25 s, its 1.2 million nearest-point queries
/// 7 to 13 % faster.
#[cfg(target_arch = "x86_64")]
mod wide {
    use super::{point_triangle2, Chunk, Measure, Nearest, Triangle, CORNER_EDGES};
    use std::arch::x86_64::*;

    /// [`Measure::part`] compiled for AVX-512F, the corner test inlined.
    ///
    /// # Safety
    /// The processor must have AVX-512F.
    #[target_feature(enable = "avx512f")]
    pub unsafe fn measure(m: &Measure, part: &[u32]) -> Vec<(u32, u8)> {
        // SAFETY: this function runs only where AVX-512F is.
        m.run(part, |p, j2| unsafe { corner_verdict(p, j2) })
    }

    /// [`super::NearTriangles::nearest`]'s loop over the gathered
    /// triangles, a chunk of eight at a time: their boxes' distances and,
    /// where one is within `bound`, all eight triangles' distances
    /// ([`crate::geometry::distance::wide::point_triangle2`], the same
    /// bits); then the lanes in turn exactly as the scalar loop takes
    /// them.
    ///
    /// # Safety
    /// The processor must have AVX-512F.
    #[target_feature(enable = "avx512f")]
    pub unsafe fn scan(chunks: &[Chunk], tris: &[Triangle], x: [f64; 3], near: &mut Nearest) {
        let xs = x.map(|v| _mm512_set1_pd(v));
        // SAFETY: loads of eight values from arrays of eight.
        let load = |v: &[f64; 8]| unsafe { _mm512_loadu_pd(v.as_ptr()) };
        let zero = _mm512_setzero_pd();
        for ch in chunks {
            // `point_box2`, lane by lane.
            let d: [__m512d; 3] = std::array::from_fn(|k| {
                let below = _mm512_max_pd(_mm512_sub_pd(load(&ch.lo[k]), xs[k]), zero);
                let dk = _mm512_max_pd(below, _mm512_sub_pd(xs[k], load(&ch.hi[k])));
                _mm512_mul_pd(dk, dk)
            });
            let box2 = _mm512_add_pd(_mm512_add_pd(d[0], d[1]), d[2]);
            let mut within =
                _mm512_cmp_pd_mask::<_CMP_LE_OQ>(box2, _mm512_set1_pd(near.bound)) as u32;
            if within == 0 {
                continue;
            }
            let mut boxes = [0.0; 8];
            // SAFETY: a store of eight values into an array of eight.
            unsafe { _mm512_storeu_pd(boxes.as_mut_ptr(), box2) };
            // SAFETY: the caller's processor has AVX-512F.
            let (dist, degenerate) =
                unsafe { crate::geometry::distance::wide::point_triangle2(x, &ch.a, &ch.b, &ch.c) };
            while within != 0 {
                let j = within.trailing_zeros() as usize;
                within &= within - 1;
                if boxes[j] > near.bound {
                    continue;
                }
                let t = ch.ids[j];
                let d = if degenerate >> j & 1 == 1 {
                    let [p, q, r] = tris[t as usize].v;
                    point_triangle2(x, p, q, r)
                } else {
                    dist[j]
                };
                near.offer(t, d);
            }
        }
    }

    /// Lane `k` holds `f(k)`.
    #[inline(always)]
    fn lanes(f: impl Fn(usize) -> i64) -> __m512i {
        let v: [i64; 8] = std::array::from_fn(f);
        // SAFETY: an unaligned load of 64 bytes from an array of 64.
        unsafe { _mm512_loadu_si512(v.as_ptr().cast()) }
    }

    /// [`super::corner_verdict`], lane `k` for corner `k`.
    ///
    /// # Safety
    /// The processor must have AVX-512F.
    #[target_feature(enable = "avx512f")]
    #[inline]
    pub unsafe fn corner_verdict(p: &[[f64; 3]; 8], j2: f64) -> (u8, f64) {
        // Each lane does the scalar code's operations in its order, with
        // no fused multiply-adds: the same roundings, the same bits.
        let column = |a: usize| {
            _mm512_set_pd(
                p[7][a], p[6][a], p[5][a], p[4][a], p[3][a], p[2][a], p[1][a], p[0][a],
            )
        };
        let (x, y, z) = (column(0), column(1), column(2));
        let edge = |c: __m512d, e: usize| {
            _mm512_sub_pd(
                _mm512_permutexvar_pd(lanes(|k| CORNER_EDGES[k][e] as i64), c),
                c,
            )
        };
        let (ax, ay, az) = (edge(x, 0), edge(y, 0), edge(z, 0));
        let (bx, by, bz) = (edge(x, 1), edge(y, 1), edge(z, 1));
        let (cx, cy, cz) = (edge(x, 2), edge(y, 2), edge(z, 2));
        let (mul, add, sub) = (_mm512_mul_pd, _mm512_add_pd, _mm512_sub_pd);
        let det = add(
            sub(
                mul(ax, sub(mul(by, cz), mul(bz, cy))),
                mul(ay, sub(mul(bx, cz), mul(bz, cx))),
            ),
            mul(az, sub(mul(bx, cy), mul(by, cx))),
        );
        let length = |u: __m512d, v: __m512d, w: __m512d| add(add(mul(u, u), mul(v, v)), mul(w, w));
        let product = mul(
            mul(length(ax, ay, az), length(bx, by, bz)),
            length(cx, cy, cz),
        );
        let zero = _mm512_setzero_pd();
        let positive = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(det, zero);
        let enough =
            _mm512_cmp_pd_mask::<_CMP_GE_OQ>(mul(det, det), mul(_mm512_set1_pd(j2), product));
        let failed = !(positive & enough);
        let flat_edge = _mm512_cmp_pd_mask::<_CMP_EQ_OQ>(product, zero);
        let figure = _mm512_div_pd(mul(det, _mm512_abs_pd(det)), product);
        let figure = _mm512_mask_blend_pd(flat_edge, figure, zero);
        (failed, _mm512_reduce_min_pd(figure))
    }
}

/// The volume of the trilinear hexahedron with corners `p` in VTK order:
/// its Jacobian determinant integrated by 2 x 2 x 2 Gauss points, which is
/// exact (the determinant has degree 2 in each reference coordinate). The
/// elements of a snapped mesh, hanging faces included, fit together
/// without gaps, so these add up to the mesh's volume.
pub fn hexahedron_volume(p: &[[f64; 3]; 8]) -> f64 {
    hexahedron_volume_centre(p).0
}

/// The area vector and centroid of the quadrilateral `p` (in order), as
/// OpenFOAM computes them: the triangles from the mean of the corners to
/// each edge, their area vectors summed and their centroids weighted by
/// the area along the total's direction. Exact for a planar face.
pub fn quad_area_centre(p: &[[f64; 3]; 4]) -> ([f64; 3], [f64; 3]) {
    let m: [f64; 3] = std::array::from_fn(|a| (p[0][a] + p[1][a] + p[2][a] + p[3][a]) * 0.25);
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let tri: [([f64; 3], [f64; 3]); 4] = std::array::from_fn(|k| {
        let (a, b) = (p[k], p[(k + 1) % 4]);
        let s = cross(sub(a, m), sub(b, m)).map(|x| 0.5 * x);
        let c = std::array::from_fn(|i| (m[i] + a[i] + b[i]) / 3.0);
        (s, c)
    });
    let total: [f64; 3] = std::array::from_fn(|i| tri.iter().map(|t| t.0[i]).sum());
    let len2 = total[0] * total[0] + total[1] * total[1] + total[2] * total[2];
    if len2 == 0.0 {
        return (total, m);
    }
    let mut weight = 0.0;
    let mut centre = [0.0; 3];
    for (s, c) in &tri {
        // The triangle's area along the face's normal.
        let w = (s[0] * total[0] + s[1] * total[1] + s[2] * total[2]) / len2.sqrt();
        weight += w;
        for i in 0..3 {
            centre[i] += w * c[i];
        }
    }
    (total, centre.map(|x| x / weight))
}

/// The volume and centroid of the trilinear hexahedron with corners `p`
/// in VTK order (2 x 2 x 2 Gauss points, exact for both).
pub fn hexahedron_volume_centre(p: &[[f64; 3]; 8]) -> (f64, [f64; 3]) {
    let g = [0.5 - 0.5 / 3f64.sqrt(), 0.5 + 0.5 / 3f64.sqrt()];
    // The permutation is its own inverse: Morton corner m is VTK corner
    // VTK_TO_MORTON[m].
    let q: [[f64; 3]; 8] = std::array::from_fn(|m| p[VTK_TO_MORTON[m]]);
    let (mut volume, mut first) = (0.0, [0.0; 3]);
    for &u in &g {
        for &v in &g {
            for &w in &g {
                let t = [u, v, w];
                let det = jacobian_at(&q, t) / 8.0;
                let mut x = [0.0; 3];
                for (m, y) in q.iter().enumerate() {
                    let n: f64 = (0..3)
                        .map(|a| if m >> a & 1 == 1 { t[a] } else { 1.0 - t[a] })
                        .product();
                    for a in 0..3 {
                        x[a] += n * y[a];
                    }
                }
                volume += det;
                for a in 0..3 {
                    first[a] += det * x[a];
                }
            }
        }
    }
    (volume, first.map(|x| x / volume))
}

/// The Jacobian determinant of the trilinear map of corners `q` (Morton
/// order) at reference point `t`.
fn jacobian_at(q: &[[f64; 3]; 8], t: [f64; 3]) -> f64 {
    let mut jac = [[0.0f64; 3]; 3];
    for (m, x) in q.iter().enumerate() {
        for (a, row) in jac.iter_mut().enumerate() {
            // d N_m / d t_a
            let mut dn = if m >> a & 1 == 1 { 1.0 } else { -1.0 };
            for (b, &tb) in t.iter().enumerate() {
                if b != a {
                    dn *= if m >> b & 1 == 1 { tb } else { 1.0 - tb };
                }
            }
            for (r, &xk) in row.iter_mut().zip(x) {
                *r += dn * xk;
            }
        }
    }
    let [a, b, c] = jac;
    a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
        + a[2] * (b[0] * c[1] - b[1] * c[0])
}

/// Whether a node with patch mask `mask` is on the surface patch.
fn is_on_surface(mask: u64) -> bool {
    mask >> SURFACE_PATCH & 1 != 0
}

/// Whether a node with patch mask `mask` and finest element side `side`
/// (`u64::MAX`: no local element) is sent to the surface: on the surface
/// patch and on no side of the domain.
fn is_queried(mask: u64, side: u64) -> bool {
    is_on_surface(mask) && mask & ((1u64 << SURFACE_PATCH) - 1) == 0 && side != u64::MAX
}

/// The mean of the positions of a hanging node's dependencies, in the
/// order given (their lattice points'), pairwise.
fn mean(pos: &[[f64; 3]], (d, n): ([u32; 4], u8)) -> [f64; 3] {
    let p = |k: usize| pos[d[k] as usize];
    if n == 2 {
        let (a, b) = (p(0), p(1));
        std::array::from_fn(|k| (a[k] + b[k]) * 0.5)
    } else {
        let (a, b, c, e) = (p(0), p(1), p(2), p(3));
        std::array::from_fn(|k| ((a[k] + b[k]) + (c[k] + e[k])) * 0.25)
    }
}

impl Mesh {
    /// Snaps the mesh to `surface` (see the module documentation): moves
    /// the surface nodes onto it, scales back where an element would be
    /// invalid, relaxes the layers next to it, and stores the positions,
    /// which [`Mesh::coordinates`] and everything built on it then return.
    /// A snapped mesh is snapped again from the lattice. Collective; the
    /// positions are the same bits on any number of ranks.
    pub fn snap(
        &mut self,
        comm: &dyn Comm,
        surface: &Surface,
        opts: &SnapOptions,
    ) -> Result<SnapReport> {
        self.snap_indexed(comm, surface, None, opts)
    }

    /// [`Mesh::snap`] with the surface's index if there is one for this
    /// mesh's domain (the classification's): its triangles and tree are
    /// used instead of made again.
    pub(crate) fn snap_indexed(
        &mut self,
        comm: &dyn Comm,
        surface: &Surface,
        index: Option<&SurfaceIndex>,
        opts: &SnapOptions,
    ) -> Result<SnapReport> {
        let spare = crate::parallel::cores::spare_core(comm);
        self.snap_threads(
            comm,
            surface,
            index,
            opts,
            spare,
            crate::parallel::cores::avx512(),
        )
    }

    /// [`Mesh::snap_indexed`], with a second thread where `spare` allows
    /// and the kernels for AVX-512 where `wide` says the processor has it
    /// (the same bits either way).
    fn snap_threads(
        &mut self,
        comm: &dyn Comm,
        surface: &Surface,
        index: Option<&SurfaceIndex>,
        opts: &SnapOptions,
        spare: bool,
        wide: bool,
    ) -> Result<SnapReport> {
        let index = index.filter(|ix| ix.tris.len() == surface.len());
        agree(comm, opts.check())?;
        self.moved = None;
        self.moved_lattice = None;
        // On a lone rank with a spare core, the surface's features (which
        // depend on the surface only) are found on a second thread while
        // this one finds the nodes to move; they are then cut to the
        // region those nodes give, as if found in it (see [`features`]).
        let early = match index {
            Some(ix) if spare && comm.size() == 1 && opts.feature_angle_deg < 180.0 => Some(ix),
            _ => None,
        };
        let (found, (masks, mut s, side, reach, region)) = crate::parallel::cores::join(
            early.is_some(),
            || early.map(|ix| features(&ix.tris, opts.feature_angle_deg, |_| true)),
            || {
                let lattice_u = self.node_lattice();
                let masks = self.plain_patch_masks(comm, &lattice_u);
                let ni = self.num_independent();
                let deps: Vec<([u32; 4], u8)> = (0..self.num_hanging())
                    .map(|k| {
                        let mut d = [0u32; 4];
                        let h = self.hanging_deps(k);
                        d[..h.len()].copy_from_slice(&h);
                        d[..h.len()].sort_unstable_by_key(|&x| lattice_u[x as usize]);
                        (d, h.len() as u8)
                    })
                    .collect();
                let s = Snapper {
                    mesh: self,
                    comm,
                    spare,
                    wide,
                    lists: if comm.size() > 1 {
                        self.exchange_lists()
                    } else {
                        Vec::new()
                    },
                    ni,
                    pos: lattice_u.iter().map(|q| q.map(f64::from)).collect(),
                    lattice: lattice_u,
                    deps,
                    snap: vec![false; ni],
                    target: vec![[0.0; 3]; ni],
                    step: vec![STEPS; ni],
                    climbing: vec![true; ni],
                    layer: vec![false; ni],
                    active: Vec::new(),
                    adj_start: Vec::new(),
                    adj: Vec::new(),
                    side: Vec::new(),
                    min_jacobian: opts.min_jacobian,
                    least: vec![f64::NAN; self.elements().len()],
                    flags: Vec::new(),
                    sums: Vec::new(),
                    seen: Bits::new(self.elements().len()),
                };
                // The finest element side at each node, over the ranks.
                let mut side = vec![u64::MAX; ni];
                for (e, c) in self.elements().iter().zip(self.connectivity()) {
                    for &n in c {
                        let n = n as usize;
                        if n < ni {
                            side[n] = side[n].min(e.side() as u64);
                        }
                    }
                }
                s.exchange(&mut side, 1, |a, b| *a = (*a).min(b));
                let queried = |n: usize| is_queried(masks[n], side[n]);
                let largest = (0..ni).filter(|&n| queried(n)).map(|n| side[n]).max();
                let reach = FEATURE_REACH * largest.unwrap_or(1) as f64;
                // The features that can attract a node lie within `reach` of
                // it.
                let region = Region::new(
                    (0..ni).filter(|&n| queried(n)).map(|n| s.lattice(n)),
                    largest.unwrap_or(1) as f64,
                    reach,
                );
                (masks, s, side, reach, region)
            },
        );
        let ni = s.ni;
        let on_surface = |n: usize| is_on_surface(masks[n]);
        let queried = |n: usize| is_queried(masks[n], side[n]);
        let found = found.map(|(edges, corners)| {
            let meets = |t: &Triangle| region.meets(&t.aabb());
            (
                edges.into_iter().filter(meets).collect(),
                corners.into_iter().filter(meets).collect(),
            )
        });
        let target_surface = Target::new(
            surface,
            index,
            self,
            opts.feature_angle_deg,
            &region,
            reach,
            found,
        );

        let mut feature = vec![false; ni];
        // In the Morton order of their lattice points: each query's
        // neighbours come next, and the gathered triangles serve more.
        // (One node per lattice point: the keys are distinct.)
        let mut order: Vec<u32> = (0..ni as u32).filter(|&n| queried(n as usize)).collect();
        let mut keys: Vec<u64> = order
            .iter()
            .map(|&n| super::numbering::node_key(s.lattice[n as usize]))
            .collect();
        crate::octree::sort::radix_sort_pairs_bits(&mut keys, &mut order, 0, 64);
        drop(keys);
        // A node's target depends on nothing but its point: the pieces of
        // the order may go to two threads. The elements that may change
        // are found meanwhile, from the nodes queried (nearly all of them
        // find a target).
        let spare_here = s.spare && order.len() >= SPLIT_AT;
        let query = |part: std::ops::Range<usize>| {
            let mut near_tris = NearTriangles {
                wide,
                ..NearTriangles::default()
            };
            order[part]
                .iter()
                .map(|&n| {
                    let n = n as usize;
                    let x = s.lattice[n].map(f64::from);
                    target_surface.of(x, side[n] as f64, &mut near_tris)
                })
                .collect::<Vec<_>>()
        };
        let (targets, (layer, active, adj_start, adj)) =
            crate::parallel::cores::map_chunks_after(spare_here, order.len(), CHUNK, query, || {
                s.moving_elements(&queried, &masks, opts)
            });
        for (&n, found) in order.iter().zip(targets.into_iter().flatten()) {
            let n = n as usize;
            if let Some((t, f)) = found {
                s.snap[n] = true;
                s.target[n] = t;
                s.step[n] = 0;
                feature[n] = f;
            }
        }
        drop(target_surface);
        s.layer = layer;
        s.active = active;
        s.adj_start = adj_start;
        s.adj = adj;
        s.side = side;

        s.scale_back();
        let mut relaxed = vec![false; ni];
        let mut iterations = 0;
        for _ in 0..opts.iterations {
            iterations += 1;
            let moved = s.relax();
            if moved == 0 {
                break;
            }
        }
        for (n, r) in relaxed.iter_mut().enumerate() {
            *r = s.layer[n] && s.pos[n] != s.lattice(n);
        }
        s.place_surface_nodes();
        s.update_hanging();

        // Figures, each node once (by its owner).
        let owned = self.num_owned();
        let mut counts = [0u64; 8];
        for n in 0..owned {
            if on_surface(n) {
                counts[0] += 1;
                match (s.snap[n], s.step[n]) {
                    (true, 0) => {
                        counts[1] += 1;
                        counts[4] += feature[n] as u64;
                    }
                    (true, k) if k < STEPS => counts[2] += 1,
                    _ => counts[3] += 1,
                }
            }
            counts[6] += relaxed[n] as u64;
        }
        for &e in &s.active {
            let mut reported = false;
            s.support(e as usize, |n| reported |= on_surface(n) && s.step[n] > 0);
            counts[7] += reported as u64;
        }
        comm.sum_u64(&mut counts);
        let domain = *self.domain();
        let active = std::mem::take(&mut s.active);
        // The minimum in user units, as the quality measures it. The
        // lattice positions' figures (no roots), as last measured, pick
        // the elements that may hold it: the two differ by rounding only,
        // far inside the margin.
        let squared: Vec<f64> = active.iter().map(|&e| s.least[e as usize]).collect();
        let pos = s.pos;
        debug_assert!(active.iter().zip(&squared).all(|(&e, &q)| {
            let p = self.connectivity()[e as usize].map(|n| pos[n as usize]);
            corner_verdict(&p, 0.0).1 == q
        }));
        let least = squared.iter().copied().fold(f64::INFINITY, f64::min);
        let near = least + 1e-9 * least.abs() + 1e-12;
        self.moved = Some(pos.iter().map(|&p| domain.from_lattice(p)).collect());
        self.moved_lattice = Some(pos);
        let mut min_j = 1.0f64;
        for (&e, &q) in active.iter().zip(&squared) {
            if q <= near {
                let p = self.element_corners(e as usize, None);
                for j in corner_scaled_jacobians(&p) {
                    min_j = min_j.min(j);
                }
            }
        }
        let mut worst = [-min_j];
        comm.max_f64(&mut worst);
        Ok(SnapReport {
            surface_nodes: counts[0],
            snapped: counts[1],
            partial: counts[2],
            unsnapped: counts[3],
            feature_nodes: counts[4],
            relaxed_nodes: counts[6],
            reported_elements: counts[7],
            min_scaled_jacobian: -worst[0],
            iterations,
        })
    }

    /// The finite-volume geometry of a snapped mesh, from the moved
    /// points: per face of `faces` its area, centre and unit normal
    /// ([`quad_area_centre`]), per local element its centre and volume
    /// (the trilinear element's, [`hexahedron_volume_centre`]). `None` on
    /// an unsnapped mesh, whose faces are the octree's
    /// ([`Mesh::face_area`], [`Mesh::face_centre`]).
    pub fn snapped_fv_geometry(&self, faces: &super::Faces) -> Result<Option<FvGeometry>> {
        if self.moved.is_none() {
            return Ok(None);
        }
        let list = faces.faces();
        let corners: Vec<[u32; 3]> = list.iter().flat_map(|f| f.corners()).collect();
        let at = self.point_positions(&corners)?;
        let mut g = FvGeometry::default();
        for q in at.chunks_exact(4) {
            let (s, c) = quad_area_centre(&[q[0], q[1], q[2], q[3]]);
            let a = (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]).sqrt();
            g.face_area.push(a);
            g.face_centre.push(c);
            g.face_normal
                .push(if a > 0.0 { s.map(|x| x / a) } else { s });
        }
        for e in 0..self.elements().len() {
            let (v, c) = hexahedron_volume_centre(&self.element_corners(e, None));
            g.cell_volume.push(v);
            g.cell_centre.push(c);
        }
        Ok(Some(g))
    }

    /// User-unit positions of lattice points `points` that are local nodes
    /// or the midpoints of local elements' edges and faces (the corners of
    /// the finite-volume faces): where the octree puts them, or on a
    /// snapped mesh the moved nodes and the means of the corners of those
    /// edges and faces (as hanging nodes are, so the same bits as the
    /// ranks holding them as nodes). A point that is neither is an
    /// internal error.
    pub fn point_positions(&self, points: &[[u32; 3]]) -> Result<Vec<[f64; 3]>> {
        let domain = self.domain();
        let Some(moved) = &self.moved_lattice else {
            return Ok(points
                .iter()
                .map(|q| domain.from_lattice(q.map(f64::from)))
                .collect());
        };
        let lattice = self.node_lattice();
        let mut nodes: Vec<([u32; 3], u32)> = lattice
            .iter()
            .enumerate()
            .map(|(n, &q)| (q, n as u32))
            .collect();
        nodes.sort_unstable();
        let mut out = vec![[f64::NAN; 3]; points.len()];
        let mut missing: Vec<([u32; 3], u32)> = Vec::new();
        for (i, q) in points.iter().enumerate() {
            match nodes.binary_search_by_key(q, |x| x.0) {
                Ok(k) => out[i] = domain.from_lattice(moved[nodes[k].1 as usize]),
                Err(_) => missing.push((*q, i as u32)),
            }
        }
        self.midpoint_positions(moved, missing, &mut out)?;
        Ok(out)
    }

    /// [`Mesh::point_positions`] of points that are no local node: the
    /// midpoints of local elements' edges and faces.
    pub(crate) fn off_node_positions(&self, points: &[[u32; 3]]) -> Result<Vec<[f64; 3]>> {
        let Some(moved) = &self.moved_lattice else {
            return self.point_positions(points);
        };
        let mut out = vec![[f64::NAN; 3]; points.len()];
        let missing = points
            .iter()
            .enumerate()
            .map(|(i, &q)| (q, i as u32))
            .collect();
        self.midpoint_positions(moved, missing, &mut out)?;
        Ok(out)
    }

    /// Sets `out[i]` for each `(point, i)` of `missing` to the mean of the
    /// moved corners of the local element edge or face it is the midpoint
    /// of.
    fn midpoint_positions(
        &self,
        moved: &[[f64; 3]],
        mut missing: Vec<([u32; 3], u32)>,
        out: &mut [[f64; 3]],
    ) -> Result<()> {
        if missing.is_empty() {
            return Ok(());
        }
        let domain = self.domain();
        missing.sort_unstable();
        // Edges: Morton corner pairs differing in one bit; faces: the four
        // corners with one bit fixed. The same for every element.
        let mut sets: Vec<Vec<usize>> = Vec::with_capacity(18);
        for m in 0..8usize {
            for k in 0..3 {
                if m >> k & 1 == 0 {
                    sets.push(vec![m, m | 1 << k]);
                }
            }
        }
        for k in 0..3 {
            for bit in [0, 1usize << k] {
                sets.push((0..8).filter(|m| m & (1 << k) == bit).collect());
            }
        }
        for (e, c) in self.elements().iter().zip(self.connectivity()) {
            let (a, s) = (e.coords(), e.side());
            if s < 2 {
                continue;
            }
            let corner = |m: usize| [0, 1, 2].map(|k| a[k] + if m >> k & 1 == 1 { s } else { 0 });
            for set in sets.iter().map(|s| s.as_slice()) {
                let mid: [u32; 3] = std::array::from_fn(|k| {
                    let lo = set.iter().map(|&m| corner(m)[k]).min().unwrap_or(0);
                    let hi = set.iter().map(|&m| corner(m)[k]).max().unwrap_or(0);
                    (lo + hi) / 2
                });
                let Ok(first) = missing.binary_search_by_key(&mid, |x| x.0) else {
                    continue;
                };
                // The corners as nodes, in the order of their points.
                let mut corners: Vec<([u32; 3], u32)> = set
                    .iter()
                    .map(|&m| (corner(m), c[VTK_TO_MORTON[m]]))
                    .collect();
                corners.sort_unstable();
                let mut d = [0u32; 4];
                for (j, x) in corners.iter().enumerate() {
                    d[j] = x.1;
                }
                let p = domain.from_lattice(mean(moved, (d, corners.len() as u8)));
                let mut j = first;
                while j > 0 && missing[j - 1].0 == mid {
                    j -= 1;
                }
                while j < missing.len() && missing[j].0 == mid {
                    out[missing[j].1 as usize] = p;
                    j += 1;
                }
            }
        }
        if out.iter().any(|p| p[0].is_nan()) {
            return Err(Error::new(
                crate::error::ErrorKind::Internal,
                "a face corner of the snapped mesh is no node and no midpoint of a local element",
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::classify::Keep;
    use crate::geometry::shapes::default_sphere;
    use crate::parallel::comm::SerialComm;
    use crate::testutil::mesh_of;

    #[test]
    fn a_second_thread_and_avx512_give_the_same_bits() {
        // Level 7: more surface nodes and active elements than SPLIT_AT,
        // so the passes are shared; outside, so nodes step back and up.
        let (mut m, s) = mesh_of("sphere", 7, Keep::Outside);
        let index = SurfaceIndex::new(&s, m.domain());
        let opts = SnapOptions {
            feature_angle_deg: 10.0,
            ..SnapOptions::default()
        };
        // A snapped mesh is snapped again from the lattice.
        let mut run = |spare: bool, wide: bool| {
            let r = m
                .snap_threads(&SerialComm, &s, Some(&index), &opts, spare, wide)
                .unwrap();
            (format!("{r:?}"), m.moved_lattice.clone().unwrap())
        };
        let one = run(false, false);
        assert!(one.1.len() > 2 * SPLIT_AT);
        // With AVX-512 (where the processor has it) too.
        let wide = crate::parallel::cores::avx512();
        for other in [run(true, false), run(false, wide), run(true, wide)] {
            assert_eq!(one.0, other.0);
            assert!(one
                .1
                .iter()
                .zip(&other.1)
                .all(|(a, b)| a.map(f64::to_bits) == b.map(f64::to_bits)));
        }
    }

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
    fn snapped_sphere_is_valid_and_on_the_surface() {
        for keep in [Keep::Inside, Keep::Outside] {
            let (mut m, s) = mesh_of("sphere", 5, keep);
            let r = m.snap(&SerialComm, &s, &SnapOptions::default()).unwrap();
            eprintln!("{keep:?} {r:?}");
            assert!(r.surface_nodes > 1000);
            assert_eq!(r.snapped + r.partial + r.unsnapped, r.surface_nodes);
            assert!(
                r.min_scaled_jacobian >= DEFAULT_MIN_JACOBIAN * 0.99,
                "{r:?}"
            );
            let x = m.coordinates();
            assert!(m.moved().is_some());
            let j = m.scaled_jacobians(None);
            assert!(j.iter().all(|&j| j > 0.0));
            let _ = x;
        }
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

    #[test]
    fn hexahedron_volumes() {
        let cube: [[f64; 3]; 8] = std::array::from_fn(|v| {
            let m = VTK_TO_MORTON[v];
            [
                (m & 1) as f64 * 2.0,
                (m >> 1 & 1) as f64,
                (m >> 2 & 1) as f64 * 3.0,
            ]
        });
        assert!((hexahedron_volume(&cube) - 6.0).abs() < 1e-14);
        // A sheared box keeps its volume.
        let mut sheared = cube;
        for p in &mut sheared[4..] {
            p[0] += 0.7;
        }
        assert!((hexahedron_volume(&sheared) - 6.0).abs() < 1e-14);
        let mut raised = cube;
        raised[6][2] += 1.0;
        // The top face z = 3 + x y / 2 over [0, 2] x [0, 1]: 6 + 0.5.
        assert!((hexahedron_volume(&raised) - 6.5).abs() < 1e-14);
    }

    /// Numbers in `[-0.5, 0.5)` from `seed` (xorshift: the same on
    /// every run).
    fn uniform(mut x: u64) -> impl FnMut() -> f64 {
        move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        }
    }

    #[test]
    fn the_squared_test_agrees_with_the_scaled_jacobians() {
        let mut next = uniform(0x9e37_79b9_7f4a_7c15);
        let mut agree = 0;
        for _ in 0..2000 {
            let p: [[f64; 3]; 8] = std::array::from_fn(|v| {
                let m = VTK_TO_MORTON[v];
                [0, 1, 2].map(|a| (m >> a & 1) as f64 + 0.6 * next())
            });
            let j = corner_scaled_jacobians(&p);
            for t in [0.001, 0.1, 0.3] {
                let slow = j.iter().all(|&v| v >= t);
                let near = j.iter().any(|&v| (v - t).abs() < 1e-12);
                if !near {
                    let (failed, least) = corner_verdict(&p, t * t);
                    assert_eq!(failed == 0, slow, "{p:?} {t}");
                    assert_eq!(least >= t * t, slow, "{p:?} {t}");
                    agree += slow as usize;
                }
            }
        }
        assert!(agree > 500, "{agree}");
    }

    #[test]
    #[cfg(target_arch = "x86_64")]
    fn the_wide_test_gives_the_same_bits() {
        if !crate::parallel::cores::avx512() {
            eprintln!("skipped: this processor has no AVX-512F");
            return;
        }
        let mut next = uniform(0x2545_f491_4f6c_dd1d);
        let mut failing = 0;
        for round in 0..4000 {
            let mut p: [[f64; 3]; 8] = std::array::from_fn(|v| {
                let m = VTK_TO_MORTON[v];
                [0, 1, 2].map(|a| (m >> a & 1) as f64 * 1024.0 + 700.0 * next())
            });
            // Flat and collapsed elements too: an edge of no length, two
            // corners in one plane.
            if round % 7 == 0 {
                p[6] = p[5];
            }
            if round % 11 == 0 {
                p[3][2] = p[0][2];
            }
            for j in [0.0, 0.001, 0.1, 0.5] {
                let scalar = corner_verdict(&p, j * j);
                // SAFETY: the processor has AVX-512F (checked above).
                let wide = unsafe { wide::corner_verdict(&p, j * j) };
                assert_eq!(scalar.0, wide.0, "{p:?} {j}");
                // The same number; a zero may come with either sign.
                assert!(scalar.1 == wide.1, "{p:?} {j}: {scalar:?} {wide:?}");
                assert_eq!(scalar.1.to_bits() | 1 << 63, wide.1.to_bits() | 1 << 63);
                failing += (scalar.0 != 0) as usize;
            }
        }
        assert!(failing > 1000, "{failing}");
    }

    #[test]
    fn quads_and_hexahedra_centres() {
        // A planar trapezoid: area 1.5, centroid x = (0 + 2 + 1 + 0 ...).
        let p = [
            [0.0, 0.0, 0.0],
            [2.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ];
        let (s, c) = quad_area_centre(&p);
        assert!((s[2] - 1.5).abs() < 1e-15 && s[0] == 0.0 && s[1] == 0.0);
        // Its centroid: the square [0,1]^2 (area 1, centre 0.5, 0.5) and
        // the triangle (1,0) (2,0) (1,1) (area 0.5, centre 4/3, 1/3).
        let want = [(0.5 + 0.5 * 4.0 / 3.0) / 1.5, (0.5 + 0.5 / 3.0) / 1.5];
        assert!((c[0] - want[0]).abs() < 1e-15 && (c[1] - want[1]).abs() < 1e-15);
        let cube: [[f64; 3]; 8] = std::array::from_fn(|v| {
            let m = VTK_TO_MORTON[v];
            [(m & 1) as f64, (m >> 1 & 1) as f64, (m >> 2 & 1) as f64]
        });
        let (v, c) = hexahedron_volume_centre(&cube);
        assert!((v - 1.0).abs() < 1e-15);
        assert!(c.iter().all(|&x| (x - 0.5).abs() < 1e-15));
    }

    #[test]
    fn options_are_checked() {
        assert!(SnapOptions::default().check().is_ok());
        let bad = SnapOptions {
            feature_angle_deg: 200.0,
            ..SnapOptions::default()
        };
        assert!(bad.check().is_err());
        let bad = SnapOptions {
            feature_angle_deg: f64::NAN,
            ..SnapOptions::default()
        };
        assert!(bad.check().is_err());
    }
}
