//! A conforming mesh of the kept leaves of a whole octree: the conditions,
//! the marks and every kept macro cell's template, with nodes numbered by
//! first use in Morton order of the macro cells, so the result depends on
//! the leaves alone.
//!
//! The kept region and the zones do not change: each leaf has a tag (0:
//! dropped, else kept, in zone `tag - 1`); a family whose leaves have
//! different tags is split like a family that is not whole, so each macro
//! cell has one tag, and the refinement the conditions add inherits the
//! tag of the cell it refines. Dropped macro cells still mark corners,
//! which only makes a kept cell's pattern finer where it meets them.

use super::assemble::GlobalPoint;
use super::{conditions, macro_template, Marks, MACRO};
use crate::error::Result;
use crate::geometry::hash::FoldMap;
use crate::octree::octant::{Connectivity, Octant};
use crate::octree::LinearOctree;
use crate::parallel::comm::CommRef;

/// A conforming all-hexahedral mesh in the octree's lattice refined
/// [`MACRO`] times.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Conforming {
    /// Node positions, numbered by first use.
    pub points: Vec<GlobalPoint>,
    /// Hexahedra, VTK corner order, positive volume.
    pub hexes: Vec<[u32; 8]>,
    /// Each hexahedron's tag (that of its macro cell, never 0).
    pub tags: Vec<u32>,
    /// Kept macro cells (parents of the conditioned octree's families).
    pub macro_cells: usize,
}

/// Kept macro cells whose marks have no template yet.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Uncovered {
    /// How many.
    pub count: usize,
    /// Their classes ([`Marks::class`]), each once, increasing.
    pub classes: Vec<Marks>,
    /// The first one in Morton order.
    pub first: Octant,
}

/// Builds the conforming mesh of `leaves` (a complete, sorted octree of one
/// process) keeping those with a tag other than 0. `comm` must be a communicator of
/// one rank: the conditions run through [`LinearOctree::balance`]. `Ok(Err)`
/// when a kept macro cell has marks without a template.
pub fn build(
    comm: CommRef,
    leaves: &[Octant],
    tags: &[u32],
) -> Result<std::result::Result<Conforming, Uncovered>> {
    debug_assert_eq!(leaves.len(), tags.len());
    let (macros, flags) = conditions::families(leaves, tags);
    let mut tree = LinearOctree::from_local_leaves(comm, macros.clone())?;
    tree.balance(Connectivity::Corner)?;
    let balanced = tree.leaves();
    // Balance only refines: each balanced cell lies in one macro cell.
    let mut keep = Vec::with_capacity(balanced.len());
    let mut j = 0;
    for &b in balanced {
        while !macros[j].contains(b) {
            j += 1;
        }
        keep.push(flags[j]);
    }
    let marks = conditions::marks(balanced);
    let templates: Vec<_> = (0..=255u8).map(|m| macro_template(Marks(m))).collect();
    let mut uncovered: Vec<Octant> = Vec::new();
    let mut classes: Vec<Marks> = Vec::new();
    let mut out = Conforming::default();
    let mut index: FoldMap<GlobalPoint, u32> = FoldMap::default();
    for ((&o, &m), &tag) in balanced.iter().zip(&marks).zip(&keep) {
        if tag == 0 {
            continue;
        }
        out.macro_cells += 1;
        let Some(template) = &templates[m.0 as usize] else {
            uncovered.push(o);
            classes.push(m.class());
            continue;
        };
        let (a, s) = (o.coords(), u64::from(o.side()));
        let place = |p: [i32; 3]| -> GlobalPoint {
            std::array::from_fn(|d| u64::from(a[d]) * MACRO as u64 + p[d] as u64 * s)
        };
        for h in template.iter() {
            let hex = h.map(|p| {
                let g = place(p);
                let next = out.points.len() as u32;
                *index.entry(g).or_insert_with(|| {
                    out.points.push(g);
                    next
                })
            });
            out.hexes.push(hex);
            out.tags.push(tag);
        }
    }
    if let Some(&first) = uncovered.first() {
        classes.sort();
        classes.dedup();
        return Ok(Err(Uncovered {
            count: uncovered.len(),
            classes,
            first,
        }));
    }
    Ok(Ok(out))
}
