//! Mesh quality: Knupp's scaled Jacobian of each element, and the figures
//! of the finite-volume faces and cells as OpenFOAM's `checkMesh` defines
//! them.
//!
//! # Scaled Jacobian
//!
//! At each corner of a trilinear hexahedron the three edges leaving it,
//! each divided by its length, form a matrix whose determinant is the
//! corner's scaled Jacobian (Knupp 2000): 1 for a right angle between every
//! pair, 0 when the edges are coplanar, negative when the corner is
//! inverted. The element's value is the minimum over its 8 corners. It is
//! computed from the corners' coordinates alone ([`scaled_jacobian`]), so it
//! measures moved nodes as well; an edge of length zero makes its corner's
//! value 0 (degenerate). The edges are taken in an order that is
//! right-handed on the undistorted element ([`CORNER_EDGES`]):
//!
//! ```text
//!         7 ---------- 6          corner: its neighbours (first, second, third)
//!        /|           /|           0: 1 3 4    4: 7 5 0
//!       / |          / |           1: 2 0 5    5: 4 6 1
//!      4 ---------- 5  |           2: 3 1 6    6: 5 7 2
//!      |  |         |  |           3: 0 2 7    7: 6 4 3
//!      |  3 --------|- 2
//!      | /          | /          z
//!      |/           |/           |  y
//!      0 ---------- 1            | /
//!                                |/___ x        (VTK hexahedron order)
//! ```
//!
//! The histogram has [`HISTOGRAM_BINS`] bins of width 0.1 over [-1, 1]: bin
//! `k` counts the elements with `-1 + k/10 <= J < -1 + (k+1)/10`, the last
//! bin includes 1 (and values a rounding error above it), the first the
//! values below -1. Elements with `J <= 0` are counted as inverted.
//!
//! # Face figures (`checkMesh`)
//!
//! For a face with area vector `S` (from its owner out), centre `f`, owner
//! centre `P` and neighbour centre `N`, `d = N - P`:
//!
//! - **non-orthogonality**: the angle between `d` and `S`. `checkMesh`
//!   prints the largest angle over the internal faces and the angle whose
//!   cosine is the mean cosine over the internal faces ("average"); faces
//!   between ranks (processor faces) count once, boundary faces not at all.
//! - **skewness**: the distance from the face centre to the point where the
//!   line from `P` to `N` crosses the face's plane, divided by the larger
//!   of `0.2 |d|` and the extent of the face from its centre in that
//!   direction (the largest projection of a face point). On a boundary face
//!   the line is the normal through `P` and the floor is `0.4` times the
//!   distance from `P` to the plane. `checkMesh` prints the maximum over
//!   all faces.
//!
//! - **the rest of `checkMesh -allGeometry`** (`figures.rs`): the cell
//!   determinant (`S S^T` summed over a cell's internal faces, each `S`
//!   over their mean area, its determinant over 8), the interpolation
//!   weight (`min(dP, dN) / (dP + dN)` with the distances from the cells'
//!   centres to the face's plane along `S`), the volume ratio of a face's
//!   two cells, the face flatness, and snappyHexMesh's twist (the smallest
//!   cosine between the line through the cells' centres and the normals
//!   of the face's triangles), with the counts of faces and cells outside
//!   `meshQualityDict`'s default limits ([`limits`]).
//!
//! On an unsnapped mesh, faces are the planar, convex polygons of
//! [`crate::mesh::faces`]: their centroid and area are exact, the extent is
//! reached at one of the four corners (a hanging midpoint on an edge lies
//! between two of them), and cell centres are the elements' centres.
//! OpenFOAM computes a cell centre from the faces (pyramids from the mean
//! of the face centres to each face, weighted by volume): for a closed
//! polyhedron with planar faces that is the exact centroid, so the coarse
//! cell of a 2:1 interface, a polyhedron of up to 24 faces there, has the
//! centre of its cube (checked in this module's tests).
//!
//! # Snapped meshes
//!
//! After [`Mesh::snap`] the faces are measured on the moved points, as
//! `checkMesh` measures the OpenFOAM case octmesh writes: each face is the
//! polygon of its corners and the mesh points on its edges (hanging points,
//! on the straight edge between two corners), in one order on every rank
//! (from its lowest lattice point, turning as seen from the element with
//! the lower global number). Its area vector and centre are OpenFOAM
//! v1912's (`primitiveMesh`): triangles from the mean of its points to
//! each edge, the area vector half the sum of their cross products, the
//! centre their centroids' mean weighted by their areas
//! ([`polygon_area_centre`]). A cell's centre comes from all its faces (a
//! coarse element's split face as its fine faces) by the pyramid rule above
//! ([`cell_centre`]), the faces taken in the order of their corners' lattice
//! sums; the halo elements' centres are sent by their ranks through the cell
//! halo. Faces are no longer planar nor cells cubes, so these are not the
//! octree's figures: on the snapped fluid sphere at level 6 (`--openfoam`)
//! the largest non-orthogonality is 37.7 degrees against the octree's 25.2,
//! the largest skewness 3.86 against 1, both equal to what `checkMesh`
//! prints (tests/snap.rs).
//!
//! # Rank counts
//!
//! Every face is measured once, by the rank holding the element with the
//! lower global number (the owner in the single-rank case), oriented from
//! that element, with centres computed the same way on every rank; the
//! cosines are summed as fixed-point integers, which is exact and so
//! independent of the order of the sum. The figures are therefore the same
//! bits on any number of ranks.

use serde::Serialize;

use crate::error::{Error, ErrorKind, Result};
use crate::geometry::cells::TINY;
use crate::geometry::vector::{cross, dot, norm, scale, sub};
use crate::mesh::faces::{FaceKind, Faces, Other};
use crate::mesh::points::{
    corner_at, edge_points, face_polygon, point_key, PointFilter, PointIndex,
};
use crate::mesh::{Mesh, VTK_TO_MORTON};
use crate::parallel::comm::{agree, Comm};

pub use crate::geometry::cells::{
    cell_centre, corner_scaled_jacobians, polygon_area_centre, scaled_jacobian, CORNER_EDGES,
};
pub use figures::{limits, LimitCounts};

mod figures;

use crate::geometry::cells::cell_centre_volume;
use figures::{AreaTensor, Figures};

/// Bins of the scaled-Jacobian histogram (width 0.1 over [-1, 1]).
pub const HISTOGRAM_BINS: usize = 20;

/// The histogram bin of a scaled Jacobian (see the module documentation).
pub fn histogram_bin(j: f64) -> usize {
    let k = ((j + 1.0) * 10.0).floor();
    if k.is_nan() || k < 0.0 {
        0
    } else {
        (k as usize).min(HISTOGRAM_BINS - 1)
    }
}

/// The cosine of the angle between `d = neighbour - owner` and the area
/// vector `s` (1 when orthogonal, as OpenFOAM's `faceOrthogonality`).
pub fn face_orthogonality(owner: [f64; 3], neighbour: [f64; 3], s: [f64; 3]) -> f64 {
    let d = sub(neighbour, owner);
    dot(d, s) / (norm(d) * norm(s) + TINY)
}

/// The skewness of a face between two cells (see the module
/// documentation): `centre` and area vector `s` of the face, its `points`,
/// the owner's and neighbour's centres.
pub fn face_skewness(
    centre: [f64; 3],
    s: [f64; 3],
    points: &[[f64; 3]],
    owner: [f64; 3],
    neighbour: [f64; 3],
) -> f64 {
    let to_face = sub(centre, owner);
    let d = sub(neighbour, owner);
    // Where the line owner -> neighbour meets the face's plane, as a
    // fraction of d.
    let t = dot(s, to_face) / (dot(s, d) + TINY);
    let miss = sub(to_face, scale(d, t));
    skew_ratio(miss, centre, points, 0.2 * norm(d))
}

/// The skewness of a boundary face: the owner's centre seen along the
/// face's normal (see the module documentation).
pub fn boundary_face_skewness(
    centre: [f64; 3],
    s: [f64; 3],
    points: &[[f64; 3]],
    owner: [f64; 3],
) -> f64 {
    let to_face = sub(centre, owner);
    let n = scale(s, 1.0 / (norm(s) + TINY));
    let along = dot(n, to_face);
    let miss = sub(to_face, scale(n, along));
    skew_ratio(miss, centre, points, 0.4 * along.abs())
}

/// `|miss|` over the larger of `floor` and the face's extent from its
/// centre along `miss`.
fn skew_ratio(miss: [f64; 3], centre: [f64; 3], points: &[[f64; 3]], floor: f64) -> f64 {
    let m = norm(miss);
    let dir = scale(miss, 1.0 / (m + TINY));
    let extent = points
        .iter()
        .map(|&p| dot(dir, sub(p, centre)).abs())
        .fold(floor + TINY, f64::max);
    m / extent
}

/// A cell's centre and volume.
type Cell = ([f64; 3], f64);

/// What one face of a snapped mesh looks like to the figures: its polygon
/// (corners and the mesh points on its edges), area vector and centre, all
/// oriented from the element with the lower global number (a boundary
/// face: out of the domain).
struct MovedFaces {
    /// Per face, where its points start in `points`; one more at the end.
    start: Vec<usize>,
    /// The faces' points, user units.
    points: Vec<[f64; 3]>,
    /// Per face, its area vector and centre.
    geometry: Vec<([f64; 3], [f64; 3])>,
    /// Per face, whether its orientation is the reverse of the list's
    /// (a halo face whose other element has the lower global number).
    flipped: Vec<bool>,
}

/// The scaled-Jacobian histogram: bin edges and counts (see the module
/// documentation).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Histogram {
    /// `HISTOGRAM_BINS + 1` edges, -1 to 1.
    pub edges: Vec<f64>,
    /// Elements per bin, over all ranks.
    pub counts: Vec<u64>,
}

/// The quality figures of a mesh, the same on every rank and every rank
/// count.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Quality {
    /// Elements measured, over all ranks.
    pub elements: u64,
    /// Smallest scaled Jacobian (1 without elements).
    pub scaled_jacobian_min: f64,
    /// Elements whose scaled Jacobian is at most 0.
    pub inverted_elements: u64,
    /// The scaled Jacobians' histogram.
    pub scaled_jacobian_histogram: Histogram,
    /// Internal faces, processor faces once (what `checkMesh` averages
    /// non-orthogonality over).
    pub internal_faces: u64,
    /// Largest non-orthogonality, degrees (`checkMesh`'s "Max").
    pub non_orthogonality_max: f64,
    /// `checkMesh`'s "average": the angle of the mean cosine, degrees.
    pub non_orthogonality_average: f64,
    /// Largest skewness over all faces (`checkMesh`'s "Max skewness").
    pub skewness_max: f64,
    /// Largest skewness of the internal faces (`meshQualityDict`'s
    /// `maxInternalSkewness` limits it).
    pub internal_skewness_max: f64,
    /// Largest skewness of the boundary faces (`maxBoundarySkewness`).
    pub boundary_skewness_max: f64,
    /// Smallest cell determinant (`checkMesh`'s "Cell determinant
    /// (wellposedness) : minimum"; 1 for a cube, 0 for a cell without
    /// internal faces).
    pub determinant_min: f64,
    /// Mean cell determinant ("average").
    pub determinant_average: f64,
    /// Smallest face interpolation weight (`checkMesh`'s "Face
    /// interpolation weight : minimum"; 0.5 between equal cubes).
    pub face_weight_min: f64,
    /// Mean interpolation weight of the internal faces.
    pub face_weight_average: f64,
    /// Smallest ratio of the volumes of a face's two cells ("Face volume
    /// ratio : minimum").
    pub volume_ratio_min: f64,
    /// Mean volume ratio of the internal faces.
    pub volume_ratio_average: f64,
    /// Smallest face flatness ("Face flatness ... min"; 1 for planar
    /// faces).
    pub face_flatness_min: f64,
    /// Mean face flatness over every face.
    pub face_flatness_average: f64,
    /// Smallest face twist (snappyHexMesh's `minTwist` measure; 1 for
    /// planar faces normal to the line between their cells' centres).
    pub face_twist_min: f64,
    /// What fails `meshQualityDict`'s default limits.
    pub limits: LimitCounts,
}

impl Mesh {
    /// The corners of local element `i` in VTK order, user units: from
    /// `coords` (one per local node, e.g. moved ones), or without it the
    /// snapped positions ([`Mesh::moved`]) or, on an unsnapped mesh, where
    /// the octree puts them (computed from the element, no node array).
    pub fn element_corners(&self, i: usize, coords: Option<&[[f64; 3]]>) -> [[f64; 3]; 8] {
        match coords.or(self.moved()) {
            Some(x) => self.connectivity()[i].map(|n| x[n as usize]),
            None => {
                let e = self.elements()[i];
                let (a, s) = (e.coords(), e.side());
                std::array::from_fn(|v| {
                    let m = VTK_TO_MORTON[v];
                    let q = [0, 1, 2].map(|k| (a[k] + if m >> k & 1 == 1 { s } else { 0 }) as f64);
                    self.domain().from_lattice(q)
                })
            }
        }
    }

    /// The scaled Jacobian of each local element, its corners as in
    /// [`Mesh::element_corners`].
    pub fn scaled_jacobians(&self, coords: Option<&[[f64; 3]]>) -> Vec<f64> {
        (0..self.elements().len())
            .map(|i| scaled_jacobian(&self.element_corners(i, coords)))
            .collect()
    }

    /// The centre of a local or halo element, lattice units.
    fn centre_of(&self, o: Other) -> [f64; 3] {
        let leaf = match o {
            Other::Element(j) => self.elements()[j as usize],
            Other::Halo(h) => self.halo().leaves[h as usize],
            Other::Patch(_) => return [0.0; 3],
        };
        let (c, h) = (leaf.coords(), leaf.side() as f64 / 2.0);
        [c[0] as f64 + h, c[1] as f64 + h, c[2] as f64 + h]
    }

    /// The volume of a local or halo element, lattice units.
    fn volume_of(&self, o: Other) -> f64 {
        let leaf = match o {
            Other::Element(j) => self.elements()[j as usize],
            Other::Halo(h) => self.halo().leaves[h as usize],
            Other::Patch(_) => return 0.0,
        };
        (leaf.side() as f64).powi(3)
    }

    /// The quality of this mesh: the scaled Jacobians from the corners of
    /// [`Mesh::element_corners`] with `coords`, and the face figures over
    /// the faces of [`Mesh::faces`]: with the octree geometry, measured as
    /// they are made, element by element (nothing is stored per face), or
    /// on a snapped mesh with the moved points (see the module
    /// documentation). Collective: the figures are reduced over the ranks.
    /// Returns the figures and the local scaled Jacobians.
    pub fn quality(
        &self,
        comm: &dyn Comm,
        coords: Option<&[[f64; 3]]>,
    ) -> Result<(Quality, Vec<f64>)> {
        let local = self.elements().len();
        if local > u32::MAX as usize {
            return Err(Error::new(ErrorKind::Limit, "too many local elements"));
        }
        let jac = self.scaled_jacobians(coords);
        let mut figures = Figures::new();
        for &j in &jac {
            figures.element(j);
        }
        if self.moved().is_some() {
            self.moved_face_figures(comm, &mut figures)?;
        } else {
            self.octree_face_figures(comm, &mut figures);
        }
        let q = figures.reduce(comm);
        Ok((q, jac))
    }
    /// The face figures of an unsnapped mesh, from the octree's geometry:
    /// measured as [`Mesh::for_each_face`] makes the faces (nothing is
    /// stored per face). Local work.
    fn octree_face_figures(&self, comm: &dyn Comm, figures: &mut Figures) {
        let me = comm.rank() as u32;
        // The figures are ratios and angles, unchanged by the map from the
        // lattice to user units (a scaling and a shift): they are computed
        // on the lattice, where the coordinates are exact.
        let cell = |o: Other| (self.centre_of(o), self.volume_of(o));
        let mut tensors = vec![AreaTensor::default(); self.elements().len()];
        self.for_each_face(|kind, f| {
            let c = f.lattice_centre();
            let s = scale(f.unit_normal(), f.lattice_area());
            let mut corners = f.corners().map(|q| q.map(|x| x as f64));
            let own = cell(Other::Element(f.owner()));
            // The corners turn about the area vector, which points out of
            // the first cell (the twist sees the order).
            let mut orient = |s: [f64; 3], towards: [f64; 3]| {
                let turn = cross(sub(corners[2], corners[0]), sub(corners[3], corners[1]));
                if dot(turn, s) < 0.0 {
                    corners.reverse();
                }
                if dot(s, towards) < 0.0 {
                    corners.reverse();
                    scale(s, -1.0)
                } else {
                    s
                }
            };
            if kind == FaceKind::Boundary {
                let s = orient(s, sub(c, own.0));
                figures.boundary_face(&corners, c, s, own.0);
                return;
            }
            tensors[f.owner() as usize].add(s);
            if let Other::Element(j) = f.other() {
                tensors[j as usize].add(s);
            }
            // Seen from the element with the lower global number: the
            // owner on one rank, and the same bits on any number.
            let (p, n, s) = match f.other() {
                Other::Halo(h) if self.halo().owners[h as usize] < me => return,
                Other::Element(j) if j < f.owner() => (cell(f.other()), own, scale(s, -1.0)),
                other => (own, cell(other), s),
            };
            let s = orient(s, sub(n.0, p.0));
            figures.internal_face(&corners, c, s, p, n);
        });
        for t in &tensors {
            figures.cell(t);
        }
    }

    /// The faces of `faces` on the moved points of a snapped mesh (see
    /// [`MovedFaces`]). Local work.
    fn moved_faces(&self, faces: &Faces) -> Result<MovedFaces> {
        // The points a face edge can carry in its middle (the points the
        // OpenFOAM writer puts there): hanging nodes and halo corners.
        let lattice = self.node_lattice();
        let filter = PointFilter::new(edge_points(self, &lattice));
        let mut index = PointIndex::new(edge_points(self, &lattice).map(point_key).collect());
        let (elements, conn) = (self.elements(), self.connectivity());
        let moved = self.moved().unwrap_or(&[]);
        // The node at lattice point `p` if it is a corner of local element
        // `e` (most face points are): no search.
        let corner_node = |e: u32, p: [u32; 3]| -> Option<usize> {
            let (c, s) = (elements[e as usize].coords(), elements[e as usize].side());
            corner_at(c, s, p).map(|m| conn[e as usize][VTK_TO_MORTON[m]] as usize)
        };
        let list = faces.faces();
        let mut start = Vec::with_capacity(list.len() + 1);
        start.push(0);
        let mut points: Vec<[f64; 3]> = Vec::with_capacity(4 * list.len());
        // The other points (hanging points of other ranks' elements, the
        // centres of split faces), found by their lattice points.
        let mut rest: Vec<[u32; 3]> = Vec::new();
        let mut rest_at: Vec<usize> = Vec::new();
        let mut flipped = Vec::with_capacity(list.len());
        let mut poly: Vec<(u64, [u32; 3])> = Vec::with_capacity(8);
        for f in list {
            poly.clear();
            face_polygon(
                &f.corners(),
                |p| filter.may_hold(p),
                |k| index.find(k).is_some(),
                &mut poly,
            );
            let flip = match f.other() {
                Other::Halo(h) => {
                    self.halo().global[h as usize] < self.global_element(f.owner() as usize)
                }
                _ => false,
            };
            // One order on every rank: from the lowest point, turning as
            // seen from the element with the lower global number.
            let first = (0..poly.len()).min_by_key(|&k| poly[k].0).unwrap_or(0);
            poly.rotate_left(first);
            if flip {
                poly[1..].reverse();
            }
            for &(_, p) in &poly {
                let node = corner_node(f.owner(), p).or(match f.other() {
                    Other::Element(j) => corner_node(j, p),
                    _ => None,
                });
                match node {
                    Some(n) if n < moved.len() => points.push(moved[n]),
                    _ => {
                        rest_at.push(points.len());
                        rest.push(p);
                        points.push([f64::NAN; 3]);
                    }
                }
            }
            start.push(points.len());
            flipped.push(flip);
        }
        for (k, x) in rest_at.into_iter().zip(self.point_positions(&rest)?) {
            points[k] = x;
        }
        let geometry = start
            .windows(2)
            .map(|w| polygon_area_centre(&points[w[0]..w[1]]))
            .collect();
        Ok(MovedFaces {
            start,
            points,
            geometry,
            flipped,
        })
    }

    /// The face figures of a snapped mesh from its moved points, the way
    /// `checkMesh` computes them: each face's polygon with the mesh points
    /// on its edges, its area vector and centre by
    /// [`polygon_area_centre`], each cell's centre by [`cell_centre`] over
    /// all its faces (a coarse element's split face as its fine faces),
    /// taken in the order of their corners' lattice sums so that the bits
    /// do not depend on the rank count; the centres of the halo elements
    /// come from their ranks. Collective.
    fn moved_face_figures(&self, comm: &dyn Comm, figures: &mut Figures) -> Result<()> {
        let local = (|| -> Result<(Faces, MovedFaces, Vec<Cell>)> {
            let faces = self.faces()?;
            let moved = self.moved_faces(&faces)?;
            // Each element's faces with their area vectors out of it, in the
            // order of the faces' corner sums (unique among one element's
            // faces, the same on any rank).
            let list = faces.faces();
            let n = self.elements().len();
            // Bucketed by element (a counting sort), then each element's few
            // faces sorted by key.
            let mut offset = vec![0usize; n + 1];
            for f in list {
                offset[f.owner() as usize + 1] += 1;
                if let Other::Element(j) = f.other() {
                    offset[j as usize + 1] += 1;
                }
            }
            for e in 0..n {
                offset[e + 1] += offset[e];
            }
            let mut next = offset.clone();
            let mut sides = vec![([0u64; 3], 0u32, false); offset[n]];
            for (k, f) in list.iter().enumerate() {
                let mut key = [0u64; 3];
                for c in f.corners() {
                    for a in 0..3 {
                        key[a] += c[a] as u64;
                    }
                }
                sides[next[f.owner() as usize]] = (key, k as u32, moved.flipped[k]);
                next[f.owner() as usize] += 1;
                if let Other::Element(j) = f.other() {
                    sides[next[j as usize]] = (key, k as u32, true);
                    next[j as usize] += 1;
                }
            }
            let mut cells = vec![([0.0; 3], 0.0); n];
            let mut cell: Vec<([f64; 3], [f64; 3])> = Vec::with_capacity(32);
            for (e, centre) in cells.iter_mut().enumerate() {
                let mine = &mut sides[offset[e]..offset[e + 1]];
                mine.sort_unstable_by_key(|x| x.0);
                cell.clear();
                for &(_, k, negate) in mine.iter() {
                    let (s, c) = moved.geometry[k as usize];
                    cell.push((c, if negate { scale(s, -1.0) } else { s }));
                }
                *centre = cell_centre_volume(&cell);
            }
            Ok((faces, moved, cells))
        })();
        let (faces, moved, cells) = agree(comm, local)?;
        let halo_cells = self.exchange_cells(comm, &faces, &cells);
        let mut tensors = vec![AreaTensor::default(); cells.len()];
        for (k, f) in faces.faces().iter().enumerate() {
            let points = &moved.points[moved.start[k]..moved.start[k + 1]];
            let (s, c) = moved.geometry[k];
            let own = cells[f.owner() as usize];
            if let Other::Patch(_) = f.other() {
                figures.boundary_face(points, c, s, own.0);
                continue;
            }
            tensors[f.owner() as usize].add(s);
            let n = match f.other() {
                // The element on the other rank measures it.
                Other::Halo(_) if moved.flipped[k] => continue,
                Other::Halo(h) => halo_cells[h as usize],
                Other::Element(j) => {
                    tensors[j as usize].add(s);
                    cells[j as usize]
                }
                Other::Patch(_) => unreachable!("boundary faces are measured above"),
            };
            figures.internal_face(points, c, s, own, n);
        }
        for t in &tensors {
            figures.cell(t);
        }
        Ok(())
    }

    /// The halo elements' `cells` (centre and volume, one per local element
    /// on each rank), through the cell halo of `faces`; elements not in it
    /// get zeros. Collective.
    fn exchange_cells(&self, comm: &dyn Comm, faces: &Faces, cells: &[Cell]) -> Vec<Cell> {
        let halo = self.cell_halo(faces);
        let mut counts = vec![0usize; comm.size()];
        let mut send: Vec<u64> = Vec::new();
        for (r, list) in halo.ranks.iter().zip(&halo.send) {
            counts[*r as usize] = 4 * list.len();
            for &e in list {
                let (c, v) = cells[e as usize];
                send.extend(c.map(f64::to_bits));
                send.push(v.to_bits());
            }
        }
        let (got, _) = comm.alltoallv_u64(&send, &counts);
        // Received in rank order, each rank's in the order of its send
        // list, which is the order of this rank's receive list.
        let mut out = vec![([0.0; 3], 0.0); self.halo().leaves.len()];
        let mut at = 0;
        for list in &halo.recv {
            for &h in list {
                let c = std::array::from_fn(|a| f64::from_bits(got[at + a]));
                out[h as usize] = (c, f64::from_bits(got[at + 3]));
                at += 4;
            }
        }
        out
    }
}

/// One of the elements with the smallest scaled Jacobians, as gathered on
/// rank 0 by [`Mesh::worst_elements`].
#[derive(Clone, Debug, PartialEq)]
pub struct WorstElement {
    /// Its scaled Jacobian.
    pub scaled_jacobian: f64,
    /// Its global element number.
    pub global: u64,
    /// The rank holding it.
    pub rank: u32,
    /// Its octree level.
    pub level: u8,
    /// Its class ([`crate::classify::LeafClass`] as a byte).
    pub class: u8,
    /// Its corners, VTK order, user units.
    pub corners: [[f64; 3]; 8],
    /// The scaled Jacobian at each corner.
    pub corner_values: [f64; 8],
}

/// Words per element sent to rank 0: value, number, rank/level/class, 24
/// coordinates, 8 corner values.
const WORST_WORDS: usize = 35;

impl WorstElement {
    /// Worst first; ties by global number, so the choice does not depend on
    /// the rank count.
    fn order(&self, o: &WorstElement) -> std::cmp::Ordering {
        self.scaled_jacobian
            .total_cmp(&o.scaled_jacobian)
            .then(self.global.cmp(&o.global))
    }

    fn encode(&self, out: &mut Vec<u64>) {
        out.push(self.scaled_jacobian.to_bits());
        out.push(self.global);
        out.push(self.rank as u64 | (self.level as u64) << 32 | (self.class as u64) << 40);
        out.extend(self.corners.iter().flatten().map(|x| x.to_bits()));
        out.extend(self.corner_values.iter().map(|x| x.to_bits()));
    }

    fn decode(w: &[u64]) -> WorstElement {
        let f = |k: usize| f64::from_bits(w[k]);
        WorstElement {
            scaled_jacobian: f(0),
            global: w[1],
            rank: w[2] as u32,
            level: (w[2] >> 32) as u8,
            class: (w[2] >> 40) as u8,
            corners: std::array::from_fn(|v| std::array::from_fn(|k| f(3 + 3 * v + k))),
            corner_values: std::array::from_fn(|v| f(27 + v)),
        }
    }
}

impl Mesh {
    /// The `n` elements with the smallest scaled Jacobians over all ranks
    /// (ties by global number), worst first, on rank 0; empty on the
    /// others. `coords` are as for [`Mesh::element_corners`] and `jac` the local
    /// scaled Jacobians ([`Mesh::quality`]). Collective.
    pub fn worst_elements(
        &self,
        comm: &dyn Comm,
        coords: Option<&[[f64; 3]]>,
        jac: &[f64],
        n: usize,
    ) -> Vec<WorstElement> {
        let element = |i: usize| {
            let corners = self.element_corners(i, coords);
            WorstElement {
                scaled_jacobian: jac[i],
                global: self.global_element(i),
                rank: comm.rank() as u32,
                level: self.elements()[i].level(),
                class: self.element_class()[i],
                corners,
                corner_values: corner_scaled_jacobians(&corners),
            }
        };
        // The local n worst by value; the global number breaks ties the
        // same way as the local index, since local numbers are contiguous.
        let mut local: Vec<usize> = (0..jac.len()).collect();
        let key = |&i: &usize| (jac[i], i);
        let cmp = |a: &usize, b: &usize| {
            let (x, y) = (key(a), key(b));
            x.0.total_cmp(&y.0).then(x.1.cmp(&y.1))
        };
        if local.len() > n {
            local.select_nth_unstable_by(n, cmp);
            local.truncate(n);
        }
        let mut send = Vec::with_capacity(local.len() * WORST_WORDS);
        for &i in &local {
            element(i).encode(&mut send);
        }
        let mut counts = vec![0; comm.size()];
        counts[0] = send.len();
        let (got, _) = comm.alltoallv_u64(&send, &counts);
        let mut all: Vec<WorstElement> = got
            .chunks_exact(WORST_WORDS)
            .map(WorstElement::decode)
            .collect();
        all.sort_by(|a, b| a.order(b));
        all.truncate(n);
        all
    }
}

/// The faces of a hexahedron in VTK order by their Abaqus labels
/// ([`crate::mesh::hexahedra::ABAQUS_FACE_NODES`] reversed), each turning
/// about its normal out of the hexahedron.
const HEX_FACES: [[usize; 4]; 6] = [
    [3, 2, 1, 0],
    [5, 6, 7, 4],
    [1, 5, 4, 0],
    [2, 6, 5, 1],
    [3, 7, 6, 2],
    [0, 4, 7, 3],
];

/// The quality of a mesh of conforming hexahedra `hexes` (VTK order) on
/// `points` (user units) that one rank holds whole, as [`Mesh::quality`]
/// measures a hanging-node mesh: the scaled Jacobian of each hexahedron at
/// its 8 corners, and the face figures over its quadrilaterals, each
/// measured as OpenFOAM does on the polygon of its 4 corners (area vector
/// and centre by [`polygon_area_centre`], cell centres and volumes by the
/// pyramid rule of [`cell_centre`]), an internal face oriented from the
/// hexahedron with the lower number. The other ranks pass empty lists:
/// the reduction gives every rank the holder's figures, so they do not
/// depend on the rank count. Collective. Returns the figures and the
/// scaled Jacobians (empty on the other ranks).
pub fn hexahedra_quality(
    comm: &dyn Comm,
    points: &[[f64; 3]],
    hexes: &[[u32; 8]],
) -> (Quality, Vec<f64>) {
    let corners = |h: usize| hexes[h].map(|n| points[n as usize]);
    // The corners of face `label` of `h`, turning about the normal out of
    // `h`.
    let face = |h: usize, label: u8| {
        let c = corners(h);
        HEX_FACES[label as usize].map(|k| c[k])
    };
    let jac: Vec<f64> = (0..hexes.len())
        .map(|h| scaled_jacobian(&corners(h)))
        .collect();
    let mut figures = Figures::new();
    for &j in &jac {
        figures.element(j);
    }
    let cells: Vec<Cell> = (0..hexes.len())
        .map(|h| {
            let faces: [([f64; 3], [f64; 3]); 6] = std::array::from_fn(|l| {
                let (s, c) = polygon_area_centre(&face(h, l as u8));
                (c, s)
            });
            cell_centre_volume(&faces)
        })
        .collect();
    // Faces matched by their sorted corners (the Abaqus labels are these
    // faces' labels, turned inwards).
    let (mut pairs, mut once) = super::hexahedra::match_faces(hexes);
    // One order whatever the hash map's.
    pairs.sort_unstable();
    once.sort_unstable();
    let mut tensors = vec![AreaTensor::default(); hexes.len()];
    for &(a, label, b) in &pairs {
        let q = face(a as usize, label);
        let (s, c) = polygon_area_centre(&q);
        tensors[a as usize].add(s);
        tensors[b as usize].add(s);
        figures.internal_face(&q, c, s, cells[a as usize], cells[b as usize]);
    }
    for &(h, label) in &once {
        let q = face(h as usize, label);
        let (s, c) = polygon_area_centre(&q);
        figures.boundary_face(&q, c, s, cells[h as usize].0);
    }
    for t in &tensors {
        figures.cell(t);
    }
    (figures.reduce(comm), jac)
}

/// The `n` hexahedra of [`hexahedra_quality`]'s mesh with the smallest
/// scaled Jacobians `jac` (ties by number), worst first, each with its
/// number as the global number, rank 0, and its `level` and `class`
/// (per hexahedron). Not collective.
pub fn worst_hexahedra(
    points: &[[f64; 3]],
    hexes: &[[u32; 8]],
    jac: &[f64],
    (level, class): (&[u8], &[u8]),
    n: usize,
) -> Vec<WorstElement> {
    let mut order: Vec<usize> = (0..jac.len()).collect();
    let cmp = |a: &usize, b: &usize| jac[*a].total_cmp(&jac[*b]).then(a.cmp(b));
    if order.len() > n {
        order.select_nth_unstable_by(n, cmp);
        order.truncate(n);
    }
    order.sort_unstable_by(cmp);
    order
        .into_iter()
        .map(|h| {
            let corners = hexes[h].map(|k| points[k as usize]);
            WorstElement {
                scaled_jacobian: jac[h],
                global: h as u64,
                rank: 0,
                level: level.get(h).copied().unwrap_or(0),
                class: class.get(h).copied().unwrap_or(0),
                corners,
                corner_values: corner_scaled_jacobians(&corners),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::parallel::comm::SerialComm;
    use crate::testutil::sphere_mesh;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-14
    }

    #[test]
    fn two_conforming_hexahedra() {
        // Two unit cubes sharing the face x = 1, the second's far face
        // moved: one internal face, six boundary faces each.
        let mut points = Vec::new();
        for x in 0..3 {
            for (y, z) in [(0, 0), (1, 0), (1, 1), (0, 1)] {
                let far = if x == 2 { 0.5 * y as f64 } else { 0.0 };
                points.push([x as f64 + far, y as f64, z as f64]);
            }
        }
        // VTK order: bottom (z = 0) counter-clockwise, then top.
        let hex = |x: u32| {
            [
                4 * x,
                4 * x + 4,
                4 * x + 5,
                4 * x + 1,
                4 * x + 3,
                4 * x + 7,
                4 * x + 6,
                4 * x + 2,
            ]
        };
        let hexes = [hex(0), hex(1)];
        let (q, jac) = hexahedra_quality(&SerialComm, &points, &hexes);
        assert_eq!(q.elements, 2);
        assert_eq!(q.internal_faces, 1);
        assert_eq!(jac[0], 1.0);
        assert!(jac[1] < 1.0 && jac[1] > 0.5, "{jac:?}");
        assert_eq!(q.scaled_jacobian_min, jac[1]);
        assert_eq!(q.inverted_elements, 0);
        // The second cell's centre moved off the first's axis.
        assert!(q.non_orthogonality_max > 1.0, "{q:?}");
        // Volumes 1 and 1.25.
        assert!((q.volume_ratio_min - 0.8).abs() < 1e-12, "{q:?}");
        let worst = worst_hexahedra(&points, &hexes, &jac, (&[1, 1], &[2, 1]), 1);
        assert_eq!(worst.len(), 1);
        assert_eq!((worst[0].global, worst[0].class), (1, 1));
    }

    #[test]
    fn histogram_bins_are_tenths() {
        assert_eq!(histogram_bin(-1.0), 0);
        assert_eq!(histogram_bin(-1.5), 0);
        assert_eq!(histogram_bin(-0.95), 0);
        assert_eq!(histogram_bin(0.0), 10);
        assert_eq!(histogram_bin(0.05), 10);
        assert_eq!(histogram_bin(0.75), 17);
        assert_eq!(histogram_bin(0.99), 19);
        assert_eq!(histogram_bin(1.0), 19);
        assert_eq!(histogram_bin(1.0 + 1e-15), 19);
        assert_eq!(histogram_bin(f64::NAN), 0);
    }

    #[test]
    fn a_fine_face_on_a_coarse_cell() {
        // Coarse cell [-1, 1]^3 (centre 0, h = 1); fine cell [0, 1]^2 x
        // [1, 2], centre (0.5, 0.5, 1.5); their face [0, 1]^2 at z = 1.
        let (p, n) = ([0.0; 3], [0.5, 0.5, 1.5]);
        let (c, s) = ([0.5, 0.5, 1.0], [0.0, 0.0, 1.0]);
        let pts = [
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 1.0],
            [1.0, 1.0, 1.0],
            [0.0, 1.0, 1.0],
        ];
        // cos = 1.5 / sqrt(0.5 + 2.25).
        assert!(close(face_orthogonality(p, n, s), 1.5 / 2.75f64.sqrt()));
        // The line P -> N meets z = 1 at (1/3, 1/3): sv = (1/6, 1/6), the
        // face reaches sqrt(2)/2 from its centre that way; 0.2 |d| is less.
        assert!(close(face_skewness(c, s, &pts, p, n), 1.0 / 3.0));
        // The same face seen from the fine side.
        let back = face_skewness(c, [0.0, 0.0, -1.0], &pts, n, p);
        assert!(close(back, 1.0 / 3.0));
        // Boundary: half of the coarse cell's top face, x in [0, 1]: the
        // centre (0.5, 0, 1) is 0.5 off the normal through P; the face
        // reaches 0.5 that way, 0.4 * 1 is less: skewness 1.
        let half = [
            [0.0, -1.0, 1.0],
            [1.0, -1.0, 1.0],
            [1.0, 1.0, 1.0],
            [0.0, 1.0, 1.0],
        ];
        let b = boundary_face_skewness([0.5, 0.0, 1.0], [0.0, 0.0, 2.0], &half, p);
        assert!(close(b, 1.0));
        // A whole face straight ahead: 0.
        let whole = [
            [-1.0, -1.0, 1.0],
            [1.0, -1.0, 1.0],
            [1.0, 1.0, 1.0],
            [-1.0, 1.0, 1.0],
        ];
        assert_eq!(
            boundary_face_skewness([0.0, 0.0, 1.0], [0.0, 0.0, 4.0], &whole, p),
            0.0
        );
    }

    #[test]
    fn openfoam_cell_centres_are_the_cube_centres() {
        // OpenFOAM's cell centre: the mean of the face centres as an
        // estimate, then the pyramids from it to each face, weighted by
        // volume. Applied here to every element's faces, split 2:1 faces
        // included, it must give the element's centre and volume.
        let mesh = sphere_mesh(4);
        let faces = mesh.faces().unwrap();
        let n = mesh.elements().len();
        let mut sides: Vec<Vec<([f64; 3], [f64; 3])>> = vec![Vec::new(); n];
        for f in faces.faces() {
            let c = mesh.face_centre(f);
            let s = scale(f.unit_normal(), mesh.face_area(f));
            sides[f.owner() as usize].push((c, s));
            if let Other::Element(j) = f.other() {
                sides[j as usize].push((c, scale(s, -1.0)));
            }
        }
        let mut split = 0;
        for (i, list) in sides.iter().enumerate() {
            split += (list.len() > 6) as usize;
            let k = list.len() as f64;
            let est = list
                .iter()
                .fold([0.0; 3], |a, (c, _)| [0, 1, 2].map(|x| a[x] + c[x] / k));
            let (mut vol, mut mom) = (0.0, [0.0; 3]);
            for (c, s) in list {
                let v = dot(*s, sub(*c, est));
                vol += v;
                for x in 0..3 {
                    mom[x] += v * (0.75 * c[x] + 0.25 * est[x]);
                }
            }
            let centre = mom.map(|m| m / vol);
            let want = mesh.element_centre(i);
            let side = mesh.element_volume(i).cbrt();
            for x in 0..3 {
                assert!((centre[x] - want[x]).abs() < 1e-12 * side, "element {i}");
            }
            assert!((vol / 3.0 - mesh.element_volume(i)).abs() < 1e-12 * side.powi(3));
            // The corners the scaled Jacobian reads are the element's.
            let j = scaled_jacobian(&mesh.element_corners(i, None));
            assert!(close(j, 1.0), "{j}");
        }
        assert!(split > 0, "no 2:1 interface in the test mesh");
    }

    #[test]
    fn octree_meshes_have_the_2_to_1_angle() {
        // Every face joins equal elements (cosine 1) or a fine element to a
        // coarse one, whose centres are 1.5 h apart along the normal and
        // h / sqrt 2 across it (h the fine side): the figures follow from
        // the count of each kind.
        let mesh = sphere_mesh(5);
        let faces = mesh.faces().unwrap();
        let comm = SerialComm;
        let coords = mesh.coordinates();
        let (q, jac) = mesh.quality(&comm, None).unwrap();
        // The nodes' array gives the same corners, so the same figures.
        assert_eq!(
            mesh.quality(&comm, Some(&coords)).unwrap(),
            (q.clone(), jac.clone())
        );
        let level = |o: Other| match o {
            Other::Element(j) => mesh.elements()[j as usize].level(),
            _ => unreachable!(),
        };
        let internal = &faces.faces()[..faces.num_internal()];
        let fine_coarse = internal
            .iter()
            .filter(|f| level(Other::Element(f.owner())) != level(f.other()))
            .count();
        assert!(fine_coarse > 0);
        let cos = 1.5 / 2.75f64.sqrt();
        let angle = cos.acos().to_degrees();
        assert!((q.non_orthogonality_max - angle).abs() < 1e-9, "{q:?}");
        let n = internal.len() as f64;
        let mean = ((n - fine_coarse as f64) + fine_coarse as f64 * cos) / n;
        assert!((q.non_orthogonality_average - mean.acos().to_degrees()).abs() < 1e-9);
        assert_eq!(q.internal_faces, internal.len() as u64);
        assert_eq!(q.elements, mesh.elements().len() as u64);
        assert_eq!(
            q.scaled_jacobian_histogram.counts.iter().sum::<u64>(),
            q.elements
        );
        assert_eq!(
            q.scaled_jacobian_histogram.counts[HISTOGRAM_BINS - 1],
            q.elements
        );
        assert_eq!(q.inverted_elements, 0);
        assert!(jac.iter().all(|&j| close(j, 1.0)));
        // 1/3 on the 2:1 faces; at least that.
        assert!(q.skewness_max >= 1.0 / 3.0 - 1e-12);
        let worst = mesh.worst_elements(&comm, None, &jac, 5);
        assert_eq!(worst.len(), 5);
        assert!(worst.windows(2).all(|w| w[0].order(&w[1]).is_lt()));
    }
}
