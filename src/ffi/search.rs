//! Point location: the leaf or mesh element holding each of the caller's
//! points (see [`crate::octree::search`] for the tie rule).

use super::handle::octmesh_t;
use super::{octmesh_gloidx_t, octmesh_locidx_t, octmesh_status_t, with_ref};
use crate::error::{Error, ErrorKind, Result};
use crate::mesh::locate_elements;
use crate::octree::search::{locate, Location};

/// The points of a call and its two output arrays.
type Arrays<'a> = (Vec<[f64; 3]>, &'a mut [i32], &'a mut [octmesh_gloidx_t]);

/// The caller's points and output arrays; `n == 0` allows NULL pointers, so
/// a rank without points passes nothing.
///
/// # Safety
/// Each pointer is NULL or valid for `3 n` (`xyz`) or `n` values.
unsafe fn arrays<'a>(
    n: octmesh_locidx_t,
    xyz: *const f64,
    rank_out: *mut i32,
    index_out: *mut octmesh_gloidx_t,
    index_name: &str,
) -> Result<Arrays<'a>> {
    if n < 0 {
        return Err(Error::invalid(format!("argument 'n' is negative ({n})")));
    }
    if n == 0 {
        return Ok((Vec::new(), &mut [], &mut []));
    }
    let n = n as usize;
    // SAFETY: 3 n values (requirement of the C API).
    let x = unsafe { super::slice_arg(xyz, 3 * n, "xyz") }?;
    // SAFETY: room for n values each (requirement of the C API).
    let r = unsafe { super::out_slice(rank_out, n as octmesh_locidx_t, n, "rank_out") }?;
    let g = unsafe { super::out_slice(index_out, n as octmesh_locidx_t, n, index_name) }?;
    let pts = x.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
    Ok((pts, r, g))
}

/// Writes each location as (rank, global index), -1 where missing.
fn write(found: &[Location], rank_out: &mut [i32], index_out: &mut [octmesh_gloidx_t]) {
    for (i, l) in found.iter().enumerate() {
        rank_out[i] = l.rank().map_or(-1, |r| r as i32);
        index_out[i] = match *l {
            Location::Found { global, .. } => global as octmesh_gloidx_t,
            _ => -1,
        };
    }
}

/// Finds the leaf containing each of this rank's points: its rank and its
/// global index (leaves numbered in Morton order over all ranks, as
/// `octmesh_octree_get_leaves` lists them rank after rank). A point on a
/// face, edge or corner shared by several leaves belongs to the leaf whose
/// half-open box `[lo, hi)` holds it; points on the domain's highest faces
/// belong to the last leaves. Points outside the cube (or outside the box
/// of a box domain) and NaN points get -1 in both outputs. The answers do
/// not depend on the number of ranks. Needs an octree. Collective: every
/// rank calls it, with its own points (`n` may differ, and be 0).
///
/// \param[in]  h           the handle
/// \param[in]  n           number of points on this rank, 0 or more
/// \param[in]  xyz         3 n coordinates (x, y, z per point), user units;
///                         may be NULL when n is 0
/// \param[out] rank_out    n ranks holding the points' leaves, -1 outside
/// \param[out] global_out  n global leaf indices, -1 outside
#[no_mangle]
pub extern "C" fn octmesh_octree_locate_points(
    h: *const octmesh_t,
    n: octmesh_locidx_t,
    xyz: *const f64,
    rank_out: *mut i32,
    global_out: *mut octmesh_gloidx_t,
) -> octmesh_status_t {
    with_ref(h, |h| {
        // SAFETY: the caller's arrays (requirement of the C API).
        let args = unsafe { arrays(n, xyz, rank_out, global_out, "global_out") };
        let tree = h.session.tree().ok_or_else(|| {
            Error::new(
                ErrorKind::State,
                "there is no octree yet: refine first (octmesh_octree_refine_surface or \
                 octmesh_octree_refine_callback)",
            )
        });
        // Agreed before the exchanges, so that no rank waits alone.
        let ((pts, r, g), tree) = h.agree(args.and_then(|a| tree.map(|t| (a, t))))?;
        let found = locate(tree, &h.session.domain()?, &pts);
        write(&found, r, g);
        Ok(())
    })
}

/// Finds the mesh element containing each of this rank's points: the rank
/// holding it and its global element number (elements numbered
/// contiguously per rank, in rank order). Same tie rule as
/// `octmesh_octree_locate_points`. A point outside the domain gets -1 in
/// both outputs; a point inside the domain but in a leaf the mesh did not
/// keep (inside the body of a fluid mesh, outside it for a solid mesh)
/// gets the rank holding that leaf and element -1. Needs a mesh.
/// Collective: every rank calls it, with its own points.
///
/// \param[in]  h            the handle
/// \param[in]  n            number of points on this rank, 0 or more
/// \param[in]  xyz          3 n coordinates (x, y, z per point), user
///                          units; may be NULL when n is 0
/// \param[out] rank_out     n ranks holding the points' leaves, -1 outside
/// \param[out] element_out  n global element numbers, -1 outside the
///                          domain or outside the mesh
#[no_mangle]
pub extern "C" fn octmesh_mesh_locate_points(
    h: *const octmesh_t,
    n: octmesh_locidx_t,
    xyz: *const f64,
    rank_out: *mut i32,
    element_out: *mut octmesh_gloidx_t,
) -> octmesh_status_t {
    with_ref(h, |h| {
        // SAFETY: the caller's arrays (requirement of the C API).
        let args = unsafe { arrays(n, xyz, rank_out, element_out, "element_out") };
        let mesh = h.session.mesh().ok_or_else(|| {
            Error::new(
                ErrorKind::State,
                "there is no mesh: call octmesh_mesh_build first (after refining and balancing)",
            )
        });
        let (pts, r, e) = h.agree(args.and_then(|a| mesh.map(|_| a)))?;
        let (Some(tree), Some(mesh)) = (h.session.tree(), h.session.mesh()) else {
            unreachable!("a mesh implies its octree");
        };
        let found = locate_elements(tree, mesh, &pts);
        write(&found, r, e);
        Ok(())
    })
}
