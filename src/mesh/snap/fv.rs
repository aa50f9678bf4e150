//! The finite-volume geometry of a snapped mesh, and the positions of
//! its points (nodes and the midpoints of element edges and faces).

use crate::error::{Error, Result};
use crate::geometry::cells::{hexahedron_volume_centre, quad_area_centre, VTK_TO_MORTON};
use crate::geometry::vector::norm;
use crate::mesh::{Faces, Mesh};

use super::mean;

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

impl Mesh {
    /// The finite-volume geometry of a snapped mesh, from the moved
    /// points: per face of `faces` its area, centre and unit normal
    /// ([`quad_area_centre`]), per local element its centre and volume
    /// (the trilinear element's, [`hexahedron_volume_centre`]). `None` on
    /// an unsnapped mesh, whose faces are the octree's
    /// ([`Mesh::face_area`], [`Mesh::face_centre`]).
    pub fn snapped_fv_geometry(&self, faces: &Faces) -> Result<Option<FvGeometry>> {
        if self.moved.is_none() {
            return Ok(None);
        }
        let list = faces.faces();
        let corners: Vec<[u32; 3]> = list.iter().flat_map(|f| f.corners()).collect();
        let at = self.point_positions(&corners)?;
        let mut g = FvGeometry::default();
        for q in at.chunks_exact(4) {
            let (s, c) = quad_area_centre(&[q[0], q[1], q[2], q[3]]);
            let a = norm(s);
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
