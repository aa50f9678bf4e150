//! Triangulated surfaces: validated triangle soups, STL input and output,
//! built-in analytic shapes, an exact-formulation triangle/box test and a
//! bounding-box tree for box queries.
//!
//! All geometry is stored in `f64`. STL coordinates are `f32` and are widened
//! on input, so converting back to `f32` for output is lossless for surfaces
//! that were read from a file and not transformed.

pub mod bvh;
pub mod cells;
pub mod diagnostics;
pub mod distance;
pub(crate) mod hash;
pub mod intersect;
pub mod names;
pub mod parts;
pub mod predicates;
pub mod shapes;
pub mod stl;
pub(crate) mod vector;
pub mod winding;

use std::path::Path;

use crate::error::{Error, ErrorKind, Result};
use crate::parallel::comm::{Comm, SerialComm};

pub use bvh::Bvh;

pub use intersect::triangle_box_overlap;
use vector::{cross, dot, norm, sub};

/// The larger of two numbers that are not NaN, as one instruction
/// (`f64::max` also orders NaNs, which costs a compare and a blend in
/// the hot loops of the box and triangle tests).
#[inline(always)]
pub(crate) fn fmax(a: f64, b: f64) -> f64 {
    if a > b {
        a
    } else {
        b
    }
}

/// The smaller of two numbers that are not NaN ([`fmax`]).
#[inline(always)]
pub(crate) fn fmin(a: f64, b: f64) -> f64 {
    if a < b {
        a
    } else {
        b
    }
}

/// A closed axis-aligned box `[min, max]`.
///
/// The empty box has `min = +inf` and `max = -inf` so that expanding it by a
/// point gives the degenerate box around that point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Lower corner.
    pub min: [f64; 3],
    /// Upper corner.
    pub max: [f64; 3],
}

impl Aabb {
    /// The empty box, neutral element of [`Aabb::union`] and [`Aabb::expand`].
    pub fn empty() -> Aabb {
        Aabb {
            min: [f64::INFINITY; 3],
            max: [f64::NEG_INFINITY; 3],
        }
    }

    /// The smallest box containing all `points` (empty if there are none).
    pub fn from_points(points: impl IntoIterator<Item = [f64; 3]>) -> Aabb {
        let mut b = Aabb::empty();
        for p in points {
            b.expand(p);
        }
        b
    }

    /// Grows the box so that it contains `p`.
    pub fn expand(&mut self, p: [f64; 3]) {
        *self = self.union(&Aabb { min: p, max: p });
    }

    /// The smallest box containing both boxes.
    pub fn union(&self, other: &Aabb) -> Aabb {
        let mut b = *self;
        for k in 0..3 {
            b.min[k] = b.min[k].min(other.min[k]);
            b.max[k] = b.max[k].max(other.max[k]);
        }
        b
    }

    /// True if the box contains no point (`min > max` on some axis).
    pub fn is_empty(&self) -> bool {
        (0..3).any(|k| self.min[k] > self.max[k])
    }

    /// Centre point `(min + max) / 2`.
    pub fn center(&self) -> [f64; 3] {
        [
            0.5 * (self.min[0] + self.max[0]),
            0.5 * (self.min[1] + self.max[1]),
            0.5 * (self.min[2] + self.max[2]),
        ]
    }

    /// Side lengths `max - min` (negative for the empty box).
    pub fn extent(&self) -> [f64; 3] {
        sub(self.max, self.min)
    }

    /// The largest side length.
    pub fn longest_side(&self) -> f64 {
        let e = self.extent();
        e[0].max(e[1]).max(e[2])
    }

    /// True if the closed boxes share at least one point; boxes that only
    /// touch at a face, edge or corner overlap.
    pub fn overlaps(&self, other: &Aabb) -> bool {
        (0..3).all(|k| self.min[k] <= other.max[k] && other.min[k] <= self.max[k])
    }
}

/// A triangle given by its three vertices; the orientation (counter-clockwise
/// seen from outside) defines the outward normal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Triangle {
    /// The vertices, in order.
    pub v: [[f64; 3]; 3],
}

impl Triangle {
    /// Creates a triangle from its vertices.
    pub fn new(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> Triangle {
        Triangle { v: [a, b, c] }
    }

    /// Unnormalised normal `(v1 - v0) x (v2 - v0)`; its length is twice the
    /// area.
    pub fn normal(&self) -> [f64; 3] {
        cross(sub(self.v[1], self.v[0]), sub(self.v[2], self.v[0]))
    }

    /// Area of the triangle.
    pub fn area(&self) -> f64 {
        0.5 * norm(self.normal())
    }

    /// Bounding box of the three vertices.
    pub fn aabb(&self) -> Aabb {
        Aabb::from_points(self.v)
    }

    /// Centroid (mean of the vertices).
    pub fn centroid(&self) -> [f64; 3] {
        let [a, b, c] = self.v;
        let third = 1.0 / 3.0;
        [
            (a[0] + b[0] + c[0]) * third,
            (a[1] + b[1] + c[1]) * third,
            (a[2] + b[2] + c[2]) * third,
        ]
    }

    /// True if the area is exactly zero or not finite.
    pub fn is_degenerate(&self) -> bool {
        let a = self.area();
        a == 0.0 || !a.is_finite()
    }

    /// True if every coordinate is finite.
    pub fn is_finite(&self) -> bool {
        self.v.iter().flatten().all(|c| c.is_finite())
    }
}

/// A validated triangle surface: at least one triangle, finite coordinates,
/// not every triangle degenerate and a non-zero extent.
///
/// Individual degenerate triangles are kept because they are harmless for box
/// queries, and dropping them would change the triangle numbering that error
/// messages refer to. The surface is not checked for being closed.
#[derive(Clone, Debug)]
pub struct Surface {
    triangles: Vec<Triangle>,
    bbox: Aabb,
    parts: Parts,
}

/// The named parts of a surface: the `solid` blocks of an ASCII STL file.
/// Each becomes a boundary patch ([`names`]).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Parts {
    /// Part names in order of first appearance (`solid` blocks with the
    /// same name are one part; an unnamed block's name is empty). Empty
    /// when the file names no part (binary STL, built-in shapes).
    pub names: Vec<String>,
    /// The part of each triangle; empty when there are fewer than two
    /// parts.
    pub of: Vec<u16>,
}

/// Most parts a surface may have (each is a patch, tracked as a bit).
pub const MAX_PARTS: usize = 57;

impl Surface {
    /// Validates `triangles` and builds a surface.
    ///
    /// Errors (all [`ErrorKind::Geometry`] except the size limit): no
    /// triangles, a non-finite coordinate (the message names the first
    /// offending triangle), an infinite extent, every triangle degenerate, or
    /// a zero extent. More than `u32::MAX` triangles is an
    /// [`ErrorKind::Limit`] error because triangle indices are `u32`.
    pub fn new(triangles: Vec<Triangle>) -> Result<Surface> {
        if triangles.is_empty() {
            return Err(Error::geometry("surface has no triangles"));
        }
        if triangles.len() > u32::MAX as usize {
            return Err(Error::new(
                ErrorKind::Limit,
                format!(
                    "surface has {} triangles, more than the supported {}",
                    triangles.len(),
                    u32::MAX
                ),
            ));
        }
        if let Some(i) = triangles.iter().position(|t| !t.is_finite()) {
            return Err(Error::geometry(format!(
                "triangle {i} has a non-finite coordinate (NaN or infinity)"
            )));
        }
        let bbox = bbox_of(&triangles);
        let longest = bbox.longest_side();
        if !longest.is_finite() {
            return Err(Error::geometry(format!(
                "surface extent overflows f64 (bounding box {:?} to {:?})",
                bbox.min, bbox.max
            )));
        }
        if longest == 0.0 {
            return Err(Error::geometry(format!(
                "surface has zero extent: all {} triangles collapse to the point {:?}",
                triangles.len(),
                bbox.min
            )));
        }
        if triangles.iter().all(Triangle::is_degenerate) {
            return Err(Error::geometry(format!(
                "all {} triangles are degenerate (zero area): the surface has no area",
                triangles.len()
            )));
        }
        Ok(Surface {
            triangles,
            bbox,
            parts: Parts::default(),
        })
    }

    /// A surface without triangles standing for one distributed over the
    /// ranks (each holds a share elsewhere): its box and part names.
    pub(crate) fn stand_in(bbox: Aabb, names: Vec<String>) -> Surface {
        Surface {
            triangles: Vec::new(),
            bbox,
            parts: Parts {
                names,
                of: Vec::new(),
            },
        }
    }

    /// The surface with these parts (`parts.of`, when not empty, has one
    /// entry per triangle below `parts.names.len()`).
    pub fn with_parts(mut self, parts: Parts) -> Result<Surface> {
        if parts.names.len() > MAX_PARTS {
            return Err(Error::new(
                ErrorKind::Limit,
                format!(
                    "the surface has {} named parts (solids), more than the supported {MAX_PARTS}",
                    parts.names.len()
                ),
            ));
        }
        let bad_len = !parts.of.is_empty() && parts.of.len() != self.triangles.len();
        if bad_len || parts.of.iter().any(|&p| p as usize >= parts.names.len()) {
            return Err(Error::invalid("surface parts do not match the triangles"));
        }
        self.parts = parts;
        Ok(self)
    }

    /// The named parts.
    pub fn parts(&self) -> &Parts {
        &self.parts
    }

    /// A 64-bit hash of the triangles (their vertex coordinates' bits, in
    /// order), never 0: what an octree checkpoint records of the surface it
    /// was built from. The same on every rank that read the same surface.
    pub fn hash(&self) -> u64 {
        let words = self
            .triangles
            .iter()
            .flat_map(|t| t.v.iter().flatten().map(|c| c.to_bits()));
        let h = hash::mix64(hash::keyed_sum(words, 0) ^ self.triangles.len() as u64);
        h.max(1)
    }

    /// The triangles, in input order.
    pub fn triangles(&self) -> &[Triangle] {
        &self.triangles
    }

    /// Number of triangles.
    pub fn len(&self) -> usize {
        self.triangles.len()
    }

    /// Always false for a validated surface; provided for API symmetry.
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// Bounding box of all vertices (computed once at construction).
    pub fn bbox(&self) -> Aabb {
        self.bbox
    }

    /// Enclosed volume, positive for a closed outward-oriented surface.
    ///
    /// Vertices are taken relative to the bounding-box centre so that a
    /// surface far from the origin does not lose digits to cancellation.
    pub fn signed_volume(&self) -> f64 {
        let c = self.bbox.center();
        let sum: f64 = self
            .triangles
            .iter()
            .map(|t| {
                let a = sub(t.v[0], c);
                let b = sub(t.v[1], c);
                let d = sub(t.v[2], c);
                dot(a, cross(b, d))
            })
            .sum();
        sum / 6.0
    }

    /// Total area of all triangles.
    pub fn area(&self) -> f64 {
        self.triangles.iter().map(Triangle::area).sum()
    }

    /// Applies `f` to every vertex and returns the transformed surface.
    ///
    /// The result is not re-validated: `f` is expected to be a finite,
    /// non-collapsing map such as a scaling plus translation.
    pub fn map_points(&self, f: impl Fn([f64; 3]) -> [f64; 3]) -> Surface {
        let triangles: Vec<Triangle> = self
            .triangles
            .iter()
            .map(|t| Triangle {
                v: [f(t.v[0]), f(t.v[1]), f(t.v[2])],
            })
            .collect();
        let bbox = bbox_of(&triangles);
        Surface {
            triangles,
            bbox,
            parts: self.parts.clone(),
        }
    }
}

fn bbox_of(triangles: &[Triangle]) -> Aabb {
    Aabb::from_points(triangles.iter().flat_map(|t| t.v))
}

/// Loads a surface from a specification: `"sphere"`, `"torus"` and `"hull"`
/// name the built-in shapes ([`shapes::default_sphere`],
/// [`shapes::default_torus`], [`shapes::default_hull`]);
/// anything else is a path to an STL file (so a file literally called
/// `sphere` must be given as `./sphere`).
pub fn load_surface(spec: &str) -> Result<Surface> {
    load_surface_on(&SerialComm, spec)
}

/// [`load_surface`] on every rank of `comm`, each rank reading its share of
/// an STL file ([`stl::read_stl_file_on`]). Collective; the result is the
/// same on every rank.
pub fn load_surface_on(comm: &dyn Comm, spec: &str) -> Result<Surface> {
    match shapes::builtin(spec) {
        Some(s) => Ok(s),
        None => stl::read_stl_file_on(comm, Path::new(spec)),
    }
}

/// Loads several surface specifications ([`load_surface`]) as one surface
/// whose parts are the files' solids (ASCII files with named solids) or the
/// files themselves, named after their stems (`sphere`, `bunny`). One
/// specification is [`load_surface`] itself.
pub fn load_surfaces(specs: &[String]) -> Result<Surface> {
    load_surfaces_on(&SerialComm, specs)
}

/// [`load_surfaces`] on every rank of `comm` ([`load_surface_on`]).
/// Collective; the result is the same on every rank.
pub fn load_surfaces_on(comm: &dyn Comm, specs: &[String]) -> Result<Surface> {
    if specs.len() == 1 {
        return load_surface_on(comm, &specs[0]);
    }
    let mut triangles = Vec::new();
    let mut parts = Parts::default();
    for spec in specs {
        let s = load_surface_on(comm, spec)?;
        let own = s.parts();
        let first = parts.names.len() as u16;
        if own.names.is_empty() {
            parts.names.push(names::surface_patch_name(spec));
        } else {
            parts.names.extend(own.names.iter().cloned());
        }
        // One part per file unless the file's own parts tell them apart.
        parts
            .of
            .extend((0..s.len()).map(|t| first + own.of.get(t).copied().unwrap_or(0)));
        triangles.extend_from_slice(s.triangles());
    }
    Surface::new(triangles)?.with_parts(parts)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> Triangle {
        Triangle::new(a, b, c)
    }

    #[test]
    fn aabb_basics() {
        let mut b = Aabb::empty();
        assert!(b.is_empty());
        b.expand([1.0, 2.0, 3.0]);
        assert!(!b.is_empty());
        assert_eq!(b.longest_side(), 0.0);
        let c = Aabb::from_points([[0.0, 0.0, 0.0], [2.0, 1.0, 4.0]]);
        let u = b.union(&c);
        assert_eq!(u.min, [0.0, 0.0, 0.0]);
        assert_eq!(u.max, [2.0, 2.0, 4.0]);
        assert_eq!(u.center(), [1.0, 1.0, 2.0]);
        assert_eq!(u.extent(), [2.0, 2.0, 4.0]);
        assert_eq!(u.longest_side(), 4.0);
        let touching = Aabb::from_points([[2.0, 2.0, 4.0], [3.0, 3.0, 5.0]]);
        assert!(u.overlaps(&touching));
        let apart = Aabb::from_points([[2.0 + 1e-12, 0.0, 0.0], [3.0, 3.0, 5.0]]);
        assert!(!u.overlaps(&apart));
        assert!(!u.overlaps(&Aabb::empty()));
    }

    #[test]
    fn triangle_basics() {
        let t = tri([0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0]);
        assert_eq!(t.normal(), [0.0, 0.0, 4.0]);
        assert_eq!(t.area(), 2.0);
        assert!(!t.is_degenerate());
        let s = tri([0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [2.0, 2.0, 2.0]);
        assert!(s.is_degenerate());
        let huge = tri([0.0; 3], [1e300, 0.0, 0.0], [0.0, 1e300, 0.0]);
        assert!(huge.is_degenerate());
    }

    #[test]
    fn surface_validation() {
        let e = Surface::new(vec![]).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Geometry);
        assert_eq!(e.message(), "surface has no triangles");

        let good = tri([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        let mut tris = vec![good; 20];
        tris[17].v[1][2] = f64::NAN;
        let e = Surface::new(tris.clone()).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Geometry);
        assert_eq!(
            e.message(),
            "triangle 17 has a non-finite coordinate (NaN or infinity)"
        );
        tris[17].v[1][2] = f64::NEG_INFINITY;
        assert!(Surface::new(tris).unwrap_err().message().contains("17"));

        let p = [1.0, 2.0, 3.0];
        let e = Surface::new(vec![tri(p, p, p); 3]).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Geometry);
        assert!(e.message().contains("zero extent"), "{e}");

        let seg = tri([0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]);
        let e = Surface::new(vec![seg, seg]).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Geometry);
        assert!(e.message().contains("degenerate"), "{e}");

        // One degenerate triangle among good ones is accepted.
        let s = Surface::new(vec![good, seg]).unwrap();
        assert_eq!(s.len(), 2);
        assert!(!s.is_empty());
        assert_eq!(s.area(), 0.5);
    }

    #[test]
    fn volume_of_far_away_tetrahedron() {
        let o = [1.0e6, -2.0e6, 3.0e6];
        let p = |x: f64, y: f64, z: f64| [o[0] + x, o[1] + y, o[2] + z];
        let (a, b, c, d) = (
            p(0.0, 0.0, 0.0),
            p(1.0, 0.0, 0.0),
            p(0.0, 1.0, 0.0),
            p(0.0, 0.0, 1.0),
        );
        let s = Surface::new(vec![tri(a, c, b), tri(a, b, d), tri(a, d, c), tri(b, c, d)]).unwrap();
        assert!((s.signed_volume() - 1.0 / 6.0).abs() < 1e-12);
        let m = s.map_points(|q| {
            [
                2.0 * (q[0] - o[0]),
                2.0 * (q[1] - o[1]),
                2.0 * (q[2] - o[2]),
            ]
        });
        assert!((m.signed_volume() - 8.0 / 6.0).abs() < 1e-12);
        assert_eq!(m.bbox().min, [0.0; 3]);
        assert_eq!(m.bbox().max, [2.0; 3]);
    }

    #[test]
    fn load_builtin_shapes() {
        assert_eq!(load_surface("sphere").unwrap().len(), 20480);
        assert_eq!(load_surface("torus").unwrap().len(), 2 * 96 * 48);
        let e = load_surface("").unwrap_err();
        assert_eq!(e.kind(), ErrorKind::InvalidArgument);
    }
}
