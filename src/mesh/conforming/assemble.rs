//! Assembly: every macro cell's template placed in the octree's lattice.

use super::{macro_template, Marks, MACRO};
use crate::octree::octant::Octant;

/// A point of the octree's lattice refined by [`MACRO`]: templates' nodes
/// on macro cells of any level land on it exactly, so nodes shared by
/// neighbouring macro cells have one key.
pub type GlobalPoint = [u64; 3];

/// The hexahedra of all macro cells (VTK order, positive volumes), or the
/// first macro cell whose marks have no template.
pub fn assemble(macros: &[Octant], marks: &[Marks]) -> Result<Vec<[GlobalPoint; 8]>, Octant> {
    let mut out = Vec::new();
    for (&o, &m) in macros.iter().zip(marks) {
        let template = macro_template(m).ok_or(o)?;
        let (a, s) = (o.coords(), u64::from(o.side()));
        let place = |p: [i32; 3]| -> GlobalPoint {
            std::array::from_fn(|d| u64::from(a[d]) * MACRO as u64 + p[d] as u64 * s)
        };
        out.extend(template.iter().map(|h| h.map(place)));
    }
    Ok(out)
}
