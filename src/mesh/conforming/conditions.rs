//! The octree conditions of the scheme, on a rank's complete set of leaves:
//! leaves in whole families, the macro tree (the families' parents)
//! balanced across corners, and each macro cell's marks.

use super::Marks;
use crate::error::Result;
use crate::geometry::hash::FoldMap;
use crate::octree::octant::{Connectivity, Octant};
use crate::octree::LinearOctree;
use crate::parallel::comm::CommRef;

/// The macro tree of a complete, sorted set of leaves: a leaf whose
/// siblings are not all leaves becomes a macro cell of its own (it will be
/// split), every whole family becomes its parent, and the result is
/// balanced across corners. The mesh's leaves are the macro cells'
/// children; everything added is the scheme's extra refinement.
pub fn macro_tree(comm: CommRef, leaves: &[Octant]) -> Result<Vec<Octant>> {
    let (macros, _) = families(leaves, &vec![0; leaves.len()]);
    let mut tree = LinearOctree::from_local_leaves(comm, macros)?;
    tree.balance(Connectivity::Corner)?;
    Ok(tree.leaves().to_vec())
}

/// The macro cells of a complete, sorted set of leaves before the
/// balance, each with the tags of its eight children (Morton order): a
/// whole family of leaves becomes its parent with its leaves' tags, any
/// other leaf a macro cell of its own whose children share its tag.
pub fn families(leaves: &[Octant], tags: &[u32]) -> (Vec<Octant>, Vec<[u32; 8]>) {
    let mut macros = Vec::with_capacity(leaves.len() / 4);
    let mut out = Vec::with_capacity(leaves.len() / 4);
    let mut i = 0;
    while i < leaves.len() {
        let o = leaves[i];
        let whole = o.level() > 0
            && o.child_id() == 0
            && i + 8 <= leaves.len()
            && (0..8).all(|k| leaves[i + k] == o.parent().child(k as u32));
        if whole {
            macros.push(o.parent());
            out.push(std::array::from_fn(|k| tags[i + k]));
            i += 8;
        } else {
            macros.push(o);
            out.push([tags[i]; 8]);
            i += 1;
        }
    }
    (macros, out)
}

/// The marks of each macro cell of a corner-balanced macro tree: corner
/// `c` of a cell is marked when a macro cell one level finer has it as a
/// corner (a finer cell that touches a coarser cell's corner point has it
/// as one of its own corners: both are aligned to the finer size).
pub fn marks(macros: &[Octant]) -> Vec<Marks> {
    let corner = |o: Octant, c: usize| -> [u32; 3] {
        let (a, s) = (o.coords(), o.side());
        std::array::from_fn(|d| a[d] + if c >> d & 1 == 1 { s } else { 0 })
    };
    let mut finest: FoldMap<[u32; 3], u8> = FoldMap::default();
    for &o in macros {
        for c in 0..8 {
            let level = finest.entry(corner(o, c)).or_insert(0);
            *level = (*level).max(o.level());
        }
    }
    macros
        .iter()
        .map(|&o| {
            let bits = (0..8)
                .filter(|&c| finest[&corner(o, c)] > o.level())
                .fold(0u8, |m, c| m | 1 << c);
            Marks(bits)
        })
        .collect()
}
