//! Hexahedra, quadrilaterals and polygons: the corner numbering of an
//! element, the scaled Jacobians of its corners, the volume and centroid of
//! a trilinear hexahedron, and the area vectors and centres of faces the
//! way OpenFOAM computes them, shared by the snap ([`crate::mesh::snap`]),
//! the quality figures ([`crate::mesh::quality`]), the faces
//! ([`crate::mesh::faces`]) and the OpenFOAM writer.
//!
//! # Corner numbering
//!
//! Elements list their corners in VTK's hexahedron order; the octree names
//! the corners of an octant in Morton order (bit `a` of the corner: the
//! upper side along axis `a`). [`VTK_TO_MORTON`] maps the one to the other
//! (and back: the permutation is its own inverse), `corner_coords` gives
//! a Morton corner's lattice point, and [`CORNER_EDGES`] each VTK corner's
//! three neighbours along the edges (the picture is in
//! [`crate::mesh::quality`]).
//!
//! # Face centres
//!
//! Two definitions of a face's centre, both from the triangles between the
//! mean of its points and each edge, which agree on a planar face:
//! [`polygon_area_centre`] weights the triangles' centroids by their areas
//! (OpenFOAM v1912's `primitiveMesh`, what its `checkMesh` measures, for
//! the quality figures), [`quad_area_centre`] by their areas along the
//! face's normal (for the C finite-volume arrays of a snapped mesh). Each
//! keeps its own order of operations, so its callers' bits do not change.

use super::vector::{add, cross, det, dot, norm, scale, sub};

/// VTK hexahedron corner `v` is Morton corner `VTK_TO_MORTON[v]`
/// (Morton corner bits: x, y, z). The permutation is its own inverse.
pub const VTK_TO_MORTON: [usize; 8] = [0, 1, 3, 2, 4, 5, 7, 6];

/// Lattice coordinates of corner `c` (Morton order) of the octant with
/// anchor `a` and side `s` (decoded once by the caller, not per corner).
#[inline]
pub(crate) fn corner_coords(a: [u32; 3], s: u32, c: usize) -> [u32; 3] {
    std::array::from_fn(|d| a[d] + if c >> d & 1 == 1 { s } else { 0 })
}

/// For each corner (VTK order), its three neighbours along the edges, in a
/// right-handed order on the undistorted element (see the module picture).
pub const CORNER_EDGES: [[usize; 3]; 8] = [
    [1, 3, 4],
    [2, 0, 5],
    [3, 1, 6],
    [0, 2, 7],
    [7, 5, 0],
    [4, 6, 1],
    [5, 7, 2],
    [6, 4, 3],
];

/// Keeps a division by a zero projection finite, as OpenFOAM's `ROOTVSMALL`
/// does.
pub(crate) const TINY: f64 = 1e-150;

/// OpenFOAM's `VSMALL`: a cell with less volume has its estimate as the
/// centre.
const VERY_SMALL: f64 = 1e-300;

/// The scaled Jacobian at each corner of a hexahedron whose corners `p` are
/// in VTK order (see the module documentation).
#[inline]
pub fn corner_scaled_jacobians(p: &[[f64; 3]; 8]) -> [f64; 8] {
    std::array::from_fn(|k| {
        let e = CORNER_EDGES[k].map(|j| sub(p[j], p[k]));
        let product = norm(e[0]) * norm(e[1]) * norm(e[2]);
        if product == 0.0 {
            0.0
        } else {
            det(e[0], e[1], e[2]) / product
        }
    })
}

/// The scaled Jacobian of a hexahedron with corners `p` in VTK order: the
/// minimum over its corners, in [-1, 1].
#[inline]
pub fn scaled_jacobian(p: &[[f64; 3]; 8]) -> f64 {
    corner_scaled_jacobians(p)
        .into_iter()
        .fold(f64::INFINITY, f64::min)
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
#[inline]
pub fn quad_area_centre(p: &[[f64; 3]; 4]) -> ([f64; 3], [f64; 3]) {
    let m: [f64; 3] = std::array::from_fn(|a| (p[0][a] + p[1][a] + p[2][a] + p[3][a]) * 0.25);
    let tri: [([f64; 3], [f64; 3]); 4] = std::array::from_fn(|k| {
        let (a, b) = (p[k], p[(k + 1) % 4]);
        let s = cross(sub(a, m), sub(b, m)).map(|x| 0.5 * x);
        let c = std::array::from_fn(|i| (m[i] + a[i] + b[i]) / 3.0);
        (s, c)
    });
    let total: [f64; 3] = std::array::from_fn(|i| tri.iter().map(|t| t.0[i]).sum());
    let len2 = dot(total, total);
    if len2 == 0.0 {
        return (total, m);
    }
    let mut weight = 0.0;
    let mut centre = [0.0; 3];
    for (s, c) in &tri {
        // The triangle's area along the face's normal.
        let w = dot(*s, total) / len2.sqrt();
        weight += w;
        for i in 0..3 {
            centre[i] += w * c[i];
        }
    }
    (total, centre.map(|x| x / weight))
}

/// The volume and centroid of the trilinear hexahedron with corners `p`
/// in VTK order (2 x 2 x 2 Gauss points, exact for both).
#[inline]
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
    det(a, b, c)
}

/// The area vector and centre of the polygon `p` (points in order, area
/// vector by the right-hand rule), as OpenFOAM v1912's `primitiveMesh`
/// computes them (see the module documentation): a triangle directly;
/// otherwise the triangles from the mean of the points to each edge, the
/// area vector half the sum of their cross products, the centre the mean
/// of their centroids weighted by their areas. A polygon of (almost) no
/// area has its mean as the centre and a zero area vector.
#[inline]
pub fn polygon_area_centre(p: &[[f64; 3]]) -> ([f64; 3], [f64; 3]) {
    if p.len() == 3 {
        let s = scale(cross(sub(p[1], p[0]), sub(p[2], p[0])), 0.5);
        let c = scale(add(add(p[0], p[1]), p[2]), 1.0 / 3.0);
        return (s, c);
    }
    let m = scale(
        p.iter().fold([0.0; 3], |a, &q| add(a, q)),
        1.0 / p.len() as f64,
    );
    let (mut sum_n, mut sum_a, mut sum_ac) = ([0.0; 3], 0.0, [0.0; 3]);
    for (k, &a) in p.iter().enumerate() {
        let b = p[(k + 1) % p.len()];
        let n = cross(sub(b, a), sub(m, a));
        let w = norm(n);
        sum_n = add(sum_n, n);
        sum_a += w;
        sum_ac = add(sum_ac, scale(add(add(a, b), m), w));
    }
    if sum_a < TINY {
        return ([0.0; 3], m);
    }
    (scale(sum_n, 0.5), scale(sum_ac, 1.0 / (3.0 * sum_a)))
}

/// The centre of a cell from its faces, each `(centre, area vector out of
/// the cell)`, as OpenFOAM's `primitiveMesh` computes it: the pyramids
/// from the mean of the face centres to each face, their centroids
/// weighted by their volumes (the mean itself when the volume is
/// (almost) zero).
#[inline]
pub fn cell_centre(faces: &[([f64; 3], [f64; 3])]) -> [f64; 3] {
    cell_centre_volume(faces).0
}

/// The centre of a cell as [`cell_centre`], and its volume: the sum of the
/// pyramids' (OpenFOAM's `cellVolumes`).
pub fn cell_centre_volume(faces: &[([f64; 3], [f64; 3])]) -> ([f64; 3], f64) {
    let est = scale(
        faces.iter().fold([0.0; 3], |a, f| add(a, f.0)),
        1.0 / faces.len().max(1) as f64,
    );
    let (mut volume, mut moment) = (0.0, [0.0; 3]);
    for &(c, s) in faces {
        // Three times the pyramid's volume, and its centroid.
        let v = dot(s, sub(c, est));
        let pc = add(scale(c, 0.75), scale(est, 0.25));
        volume += v;
        moment = add(moment, scale(pc, v));
    }
    if volume.abs() > VERY_SMALL {
        (scale(moment, 1.0 / volume), volume / 3.0)
    } else {
        (est, volume / 3.0)
    }
}

/// The flatness of a face of more than three `points` with centre `c` and
/// area vector `s` ([`polygon_area_centre`]), as OpenFOAM's `checkMesh`
/// measures it: `|s|` over the sum of the areas of the triangles from `c`
/// to each edge (1 for a planar convex face, towards 0 for a butterfly).
pub fn face_flatness(points: &[[f64; 3]], c: [f64; 3], s: [f64; 3]) -> f64 {
    let mut sum = 0.0;
    for (k, &a) in points.iter().enumerate() {
        let b = points[(k + 1) % points.len()];
        sum += 0.5 * norm(cross(sub(b, a), sub(c, a)));
    }
    norm(s) / (sum + TINY)
}

/// The twist of a face as snappyHexMesh's `minTwist` measures it
/// (OpenFOAM's `polyMeshGeometry::checkFaceTwist`): the smallest cosine
/// between the unit vector `nf` (from the owner's centre to the
/// neighbour's, or to the face centre on a boundary) and the normals of
/// the triangles from the face centre `c` to each edge. 1 for a planar
/// face normal to `nf`.
pub fn face_twist(points: &[[f64; 3]], c: [f64; 3], nf: [f64; 3]) -> f64 {
    let mut twist = 1.0f64;
    for (k, &a) in points.iter().enumerate() {
        let b = points[(k + 1) % points.len()];
        let n = cross(sub(b, a), sub(c, a));
        let m = norm(n);
        if m > VERY_SMALL {
            twist = twist.min(dot(nf, n) / m);
        }
    }
    twist
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The unit cube's corners in VTK order, mapped by `f`.
    fn cube(f: impl Fn([f64; 3]) -> [f64; 3]) -> [[f64; 3]; 8] {
        const UNIT: [[f64; 3]; 8] = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 1.0],
            [1.0, 1.0, 1.0],
            [0.0, 1.0, 1.0],
        ];
        UNIT.map(f)
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-14
    }

    #[test]
    fn the_corner_table_follows_the_edges_right_handed() {
        let c = cube(|p| p);
        for (k, e) in CORNER_EDGES.iter().enumerate() {
            // Each neighbour differs from the corner in exactly one
            // coordinate, each along a different axis.
            let mut axes = [false; 3];
            for &j in e {
                let d = sub(c[j], c[k]);
                let along: Vec<usize> = (0..3).filter(|&a| d[a] != 0.0).collect();
                assert_eq!(along.len(), 1, "corner {k} -> {j}");
                axes[along[0]] = true;
            }
            assert_eq!(axes, [true; 3], "corner {k}");
        }
        assert_eq!(corner_scaled_jacobians(&c), [1.0; 8]);
    }

    #[test]
    fn distorted_hexahedra_have_their_closed_form_values() {
        // A box with sides 2, 3, 0.5: right angles everywhere.
        let b = cube(|p| [2.0 * p[0] + 1.0, 3.0 * p[1], 0.5 * p[2] - 4.0]);
        assert!(close(scaled_jacobian(&b), 1.0));
        // Sheared, x += s z: the edges x, y, (s, 0, 1) at every corner;
        // det 1 over lengths 1, 1, sqrt(1 + s^2).
        for s in [0.5, 1.0, 3.0] {
            let h = cube(|p| [p[0] + s * p[2], p[1], p[2]]);
            let want = 1.0 / (1.0f64 + s * s).sqrt();
            for j in corner_scaled_jacobians(&h) {
                assert!(close(j, want), "shear {s}: {j} vs {want}");
            }
        }
        // An affine parallelepiped on a = (1, 0, 0), b = (1, 1, 0),
        // c = (0, 1, 1): det 1, lengths 1, sqrt 2, sqrt 2, so 1/2 at every
        // corner.
        let (a, bb, c) = ([1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 1.0]);
        let h = cube(|p| [0, 1, 2].map(|k| p[0] * a[k] + p[1] * bb[k] + p[2] * c[k]));
        for j in corner_scaled_jacobians(&h) {
            assert!(close(j, 0.5), "{j}");
        }
        // Mirrored (z -> -z): every corner inverted, -1.
        let m = cube(|p| [p[0], p[1], -p[2]]);
        assert_eq!(corner_scaled_jacobians(&m), [-1.0; 8]);
        // Flattened (top on the bottom): coplanar edges, 0 everywhere.
        let f = cube(|p| [p[0], p[1], 0.0]);
        assert_eq!(corner_scaled_jacobians(&f), [0.0; 8]);
        // The top face collapsed to the point (0.5, 0.5, 1) (a pyramid):
        // the top corners' edges along the top have length zero, so 0 there;
        // a bottom corner, e.g. 0, has edges x, y, (0.5, 0.5, 1): det 1 over
        // 1 * 1 * sqrt(1.5).
        let py = cube(|p| if p[2] == 1.0 { [0.5, 0.5, 1.0] } else { p });
        let j = corner_scaled_jacobians(&py);
        assert_eq!(&j[4..], &[0.0; 4]);
        for v in &j[..4] {
            assert!(close(*v, 1.0 / 1.5f64.sqrt()), "{v}");
        }
        assert_eq!(scaled_jacobian(&py), 0.0);
        // Corner 6 pulled from (1, 1, 1) to (2, 2, 2). At 6 the edges to 5,
        // 7, 2 are (-1, -2, -1), (-2, -1, -1), (-1, -1, -2): det 4, lengths
        // sqrt 6 each, so 4 / (6 sqrt 6). At 5 (and by symmetry 2 and 7):
        // edges to 4, 6, 1 are (-1, 0, 0), (1, 2, 1), (0, 0, -1): det 2 over
        // sqrt 6. The rest keep their right angles.
        let mut pulled = cube(|p| p);
        pulled[6] = [2.0, 2.0, 2.0];
        let j = corner_scaled_jacobians(&pulled);
        let at6 = 4.0 / (6.0 * 6f64.sqrt());
        let at5 = 2.0 / 6f64.sqrt();
        let want = [1.0, 1.0, at5, 1.0, 1.0, at5, at6, at5];
        for k in 0..8 {
            assert!(close(j[k], want[k]), "corner {k}: {} vs {}", j[k], want[k]);
        }
        assert!(close(scaled_jacobian(&pulled), at6));
        // Corner 0 pushed through the element to (1.5, 0.5, 0.5): its
        // edges (-0.5, -0.5, -0.5), (-1.5, 0.5, -0.5), (-1.5, -0.5, 0.5) to
        // 1, 3, 4 give det -1.5 over (sqrt 0.75 * sqrt 2.75 * sqrt 2.75).
        let mut through = cube(|p| p);
        through[0] = [1.5, 0.5, 0.5];
        let j0 = corner_scaled_jacobians(&through)[0];
        let want = -1.5 / (0.75f64.sqrt() * 2.75);
        assert!(close(j0, want), "{j0} vs {want}");
        assert!(scaled_jacobian(&through) < 0.0);
    }

    #[test]
    fn polygons_and_cells_as_openfoam_measures_them() {
        // A planar quadrilateral, tilted: its area vector is the exact one
        // (1 x 2 rectangle in the plane z = x), its centre the centroid,
        // with or without a point in the middle of an edge.
        let q = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 1.0],
            [1.0, 2.0, 1.0],
            [0.0, 2.0, 0.0],
        ];
        let (s, c) = polygon_area_centre(&q);
        let want_s = [-2.0, 0.0, 2.0];
        for a in 0..3 {
            assert!(close(s[a], want_s[a]), "{s:?}");
            assert!(close(c[a], [0.5, 1.0, 0.5][a]), "{c:?}");
        }
        let five = [q[0], q[1], [1.0, 1.0, 1.0], q[2], q[3]];
        let (s5, c5) = polygon_area_centre(&five);
        for a in 0..3 {
            assert!(
                close(s5[a], want_s[a]) && close(c5[a], c[a]),
                "{s5:?} {c5:?}"
            );
        }
        // A trapezoid's centroid is not its corners' mean.
        let trapezoid = [
            [0.0, 0.0, 0.0],
            [4.0, 0.0, 0.0],
            [3.0, 1.0, 0.0],
            [1.0, 1.0, 0.0],
        ];
        let (st, ct) = polygon_area_centre(&trapezoid);
        assert!(
            close(st[2], 3.0) && close(ct[0], 2.0) && close(ct[1], 4.0 / 9.0),
            "{ct:?}"
        );
        // A triangle, and a polygon of no area.
        let (s3, c3) = polygon_area_centre(&[[0.0; 3], [3.0, 0.0, 0.0], [0.0, 3.0, 0.0]]);
        assert!(close(s3[2], 4.5) && close(c3[0], 1.0) && close(c3[1], 1.0));
        let flat = [[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [1.0, 0.0, 0.0]];
        assert_eq!(polygon_area_centre(&flat), ([0.0; 3], [1.0, 0.0, 0.0]));
        // A sheared box (a parallelepiped: planar faces), its faces with
        // outward area vectors: the centre is its corners' mean, however
        // many faces a side is split into.
        let p = cube(|[x, y, z]| [x + 0.5 * z, y + 0.25 * x, z]);
        let sides: [[usize; 4]; 6] = [
            [0, 3, 2, 1],
            [4, 5, 6, 7],
            [0, 1, 5, 4],
            [2, 3, 7, 6],
            [0, 4, 7, 3],
            [1, 2, 6, 5],
        ];
        let faces: Vec<([f64; 3], [f64; 3])> = sides
            .iter()
            .map(|f| {
                let (s, c) = polygon_area_centre(&f.map(|k| p[k]));
                (c, s)
            })
            .collect();
        let mean = p
            .iter()
            .fold([0.0; 3], |a, x| [0, 1, 2].map(|k| a[k] + x[k] / 8.0));
        let centre = cell_centre(&faces);
        for a in 0..3 {
            assert!(close(centre[a], mean[a]), "{centre:?} {mean:?}");
        }
        // The bottom split into its four quarters.
        let mid = |a: [f64; 3], b: [f64; 3]| [0, 1, 2].map(|k| 0.5 * (a[k] + b[k]));
        let (b0, b1, b2, b3) = (p[0], p[3], p[2], p[1]);
        let m = mid(b0, b2);
        let quarters = [
            [b0, mid(b0, b1), m, mid(b3, b0)],
            [mid(b0, b1), b1, mid(b1, b2), m],
            [m, mid(b1, b2), b2, mid(b2, b3)],
            [mid(b3, b0), m, mid(b2, b3), b3],
        ];
        let mut split: Vec<([f64; 3], [f64; 3])> = faces[1..].to_vec();
        for q in &quarters {
            let (s, c) = polygon_area_centre(q);
            split.push((c, s));
        }
        let centre = cell_centre(&split);
        for a in 0..3 {
            assert!(close(centre[a], mean[a]), "{centre:?} {mean:?}");
        }
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
}
