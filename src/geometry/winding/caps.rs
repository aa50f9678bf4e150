//! Caps that close the boundary loops of an open surface.

use super::*;
use crate::geometry::diagnostics::weld;
use crate::geometry::vector::{add, scale};
use crate::geometry::Triangle;

/// Caps closing the boundary of `tris` (taken as oriented): for every loop
/// `u_0 -> u_1 -> ..` of the boundary (see the module documentation), the
/// fan of triangles `(u_{i+1}, u_i, z)` with `z` the mean of the loop's
/// vertices. `tris` plus the caps has no boundary edge; empty when `tris`
/// has none.
pub fn close_boundary(tris: &[Triangle]) -> Vec<Triangle> {
    let (ids, nv) = weld(tris);
    let mut pos = vec![[0.0; 3]; nv];
    for (t, f) in tris.iter().zip(&ids) {
        for k in 0..3 {
            pos[f[k] as usize] = t.v[k];
        }
    }
    let mut caps = Vec::new();
    for lp in boundary_loops(&ids, &vec![false; tris.len()]) {
        let z = scale(
            lp.iter().fold([0.0; 3], |s, &u| add(s, pos[u as usize])),
            1.0 / lp.len() as f64,
        );
        for i in 0..lp.len() {
            let (u, v) = (pos[lp[i] as usize], pos[lp[(i + 1) % lp.len()] as usize]);
            caps.push(Triangle::new(v, u, z));
        }
    }
    caps
}
