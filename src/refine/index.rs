//! The surface in lattice units with its bounding-box tree, for octant
//! queries.

use super::*;
use crate::geometry::bvh::Bvh;
use crate::geometry::{Aabb, Surface, Triangle};
use crate::octree::domain::Domain;
use crate::octree::octant::Octant;

/// A surface in lattice units, ready for octant queries.
pub struct SurfaceIndex {
    pub(crate) tris: Vec<Triangle>,
    /// The part (STL solid) of each triangle, in the same order; empty
    /// when the surface has fewer than two parts.
    pub(crate) part: Vec<u16>,
    pub(crate) bvh: Bvh,
    pub(crate) projected_area: f64,
}

impl SurfaceIndex {
    /// Maps the surface to the lattice of `domain` and builds its
    /// bounding-box tree.
    pub fn new(surface: &Surface, domain: &Domain) -> SurfaceIndex {
        SurfaceIndex::of_triangles(surface.triangles(), &surface.parts().of, domain)
    }

    /// [`SurfaceIndex::new`] for triangles in user units and their parts
    /// (`of`: one per triangle, or empty), which need not make a valid
    /// surface (a rank's share of one may be empty).
    pub fn of_triangles(triangles: &[Triangle], of: &[u16], domain: &Domain) -> SurfaceIndex {
        let tris: Vec<Triangle> = triangles
            .iter()
            .map(|t| Triangle {
                v: [
                    domain.to_lattice(t.v[0]),
                    domain.to_lattice(t.v[1]),
                    domain.to_lattice(t.v[2]),
                ],
            })
            .collect();
        // Stored in the tree's leaf order, the triangles near an octant sit
        // together in memory, which the walks down the octree feel: input
        // files often list facets in no spatial order at all.
        let mut bvh = Bvh::new(&tris);
        let order = bvh.renumber();
        let tris: Vec<Triangle> = order.iter().map(|&i| tris[i as usize]).collect();
        let part = if of.is_empty() {
            Vec::new()
        } else {
            order.iter().map(|&i| of[i as usize]).collect()
        };
        let projected_area = projected_area(&tris);
        SurfaceIndex {
            tris,
            part,
            bvh,
            projected_area,
        }
    }

    /// The sum over the triangles meeting the root cube of area times the
    /// 1-norm of the unit normal (the sum of the areas projected on the
    /// three coordinate planes), in lattice units squared. A plane piece of
    /// this measure `P` meets about `P / h^2` cubes of a grid of side `h`.
    pub fn projected_area(&self) -> f64 {
        self.projected_area
    }

    /// The part (STL solid) of triangle `t` of [`SurfaceIndex::triangles`]
    /// (0 for surfaces of fewer than two parts).
    pub fn part_of(&self, t: u32) -> usize {
        self.part.get(t as usize).map_or(0, |&p| p as usize)
    }

    /// Triangles in lattice units.
    pub fn triangles(&self) -> &[Triangle] {
        &self.tris
    }

    /// Whether the closed box of `o` touches the surface.
    pub fn touches(&self, o: Octant) -> bool {
        let (lo, hi) = o.bounds_f64();
        self.bvh.any_overlap(&self.tris, lo, hi)
    }

    /// The triangles' bounding boxes, in the order of [`SurfaceIndex::triangles`].
    pub(crate) fn boxes(&self) -> &[Aabb] {
        // The tree's own boxes: renumbered, its slots are the triangles.
        self.bvh.slot_boxes()
    }

    /// Indices of the triangles whose bounding boxes meet the closed box of
    /// `o`: a superset of [`SurfaceIndex::touching`].
    pub fn candidates(&self, o: Octant, out: &mut Vec<u32>) {
        let (lo, hi) = o.bounds_f64();
        self.bvh.query_candidates(lo, hi, out);
    }

    /// Whether the closed box `lo..hi` (lattice units) comes within `d` of
    /// the surface (exact distance; `buf` is scratch space).
    pub fn box_within(&self, lo: [f64; 3], hi: [f64; 3], d: f64, buf: &mut Vec<u32>) -> bool {
        let (a, b) = (lo.map(|x| x - d), hi.map(|x| x + d));
        buf.clear();
        self.bvh.query_candidates(a, b, buf);
        crate::geometry::distance::any_box_within(&self.tris, buf, lo, hi, d, &mut Vec::new())
    }

    /// Indices of the triangles touching the closed box of `o`.
    pub fn touching(&self, o: Octant, out: &mut Vec<u32>) {
        let (lo, hi) = o.bounds_f64();
        self.bvh.query_box(&self.tris, lo, hi, out);
    }
}
