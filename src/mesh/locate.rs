//! The mesh element holding each of a set of user points: the routing of
//! [`crate::octree::search`], answered by the elements (a sorted subset of
//! the leaves).

use crate::octree::search::{route, Location};
use crate::octree::LinearOctree;

use super::Mesh;

/// The mesh element containing each point, in `points`' order:
/// [`Location::NoElement`] for a point in a leaf the mesh did not keep.
/// `mesh` must be built from `tree` as it is (same leaves and partition).
/// Collective: every rank calls it with its own points.
pub fn locate_elements(tree: &LinearOctree, mesh: &Mesh, points: &[[f64; 3]]) -> Vec<Location> {
    let firsts = tree.comm().allgather_u64(mesh.first_element());
    let elements = mesh.elements();
    // Elements are a sorted subset of the leaves.
    route(tree, mesh.domain(), points, &firsts, |_, leaf| {
        elements.binary_search(&leaf).ok()
    })
}
