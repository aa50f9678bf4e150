//! Fields across adaptation steps: the mesh before a change of the octree
//! is kept when asked, and element and nodal fields move from it to the
//! new mesh (see the crate's `mesh::transfer` module).
//!
//! ```text
//!   octmesh_mesh_keep_previous(h, true);
//!   octmesh_mesh_build(h, ...);                  old mesh, fields u_old
//!   octmesh_octree_adapt(h, ...); balance; partition_for_coarsening
//!   octmesh_mesh_build(h, ...);                  new mesh
//!   octmesh_mesh_transfer_nodes(h, 1, u_old, u_new, capacity, &missing);
//! ```

use super::handle::octmesh_t;
use super::{
    non_null, octmesh_gloidx_t, octmesh_locidx_t, octmesh_status_t, out_slice, slice_arg, with_mut,
    write_out,
};
use crate::error::{Error, ErrorKind, Result};

/// Where each local element of the current mesh came from in the previous
/// mesh (arrays owned by the handle, valid until the mesh changes).
///
/// ```text
///   old  +-------+-------+      new  +---+---+-------+
///        |       |   |   |           |   |   |       |
///        |   a   +---+---+           +---+---+   B   |   A in a: level_change +1
///        |       |   |   |           |   |   |       |   B over 4: -1, old_count 4
///        +-------+---+---+           +---+---+-------+
/// ```
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct octmesh_element_map_t {
    /// Local elements of the current mesh (entries of each array).
    pub num_elements: octmesh_locidx_t,
    /// Global number in the previous mesh of the first old element each
    /// element overlaps, -1 when none (a leaf the old mesh did not keep).
    pub old_first: *const octmesh_gloidx_t,
    /// How many old elements it overlaps: global numbers `old_first ..
    /// old_first + old_count`.
    pub old_count: *const octmesh_locidx_t,
    /// New level minus old level: 0 unchanged, `k > 0` inside an old
    /// element `k` levels coarser (refined), `-k` over old elements the
    /// finest of which is `k` levels finer (coarsened).
    pub level_change: *const i8,
    /// Elements over all ranks that overlap no old element.
    pub uncovered: octmesh_gloidx_t,
}

/// Keeps (`keep` true) or stops keeping the mesh that a change of the
/// octree or a new `octmesh_mesh_build` replaces, for the transfer calls
/// below. Off by default: the kept mesh costs about as much memory as the
/// current one; turning it off frees a kept mesh. Not collective (call it
/// alike on every rank).
///
/// \param[in] h     the handle
/// \param[in] keep  true to keep the previous mesh, false to drop it
#[no_mangle]
pub extern "C" fn octmesh_mesh_keep_previous(h: *mut octmesh_t, keep: bool) -> octmesh_status_t {
    with_mut(h, |h| {
        h.session.keep_previous_mesh(keep);
        Ok(())
    })
}

/// Where each local element of the current mesh came from in the previous
/// one (`octmesh_element_map_t`). Needs a kept previous mesh and a current
/// one. Collective (on the first call for a mesh).
///
/// \param[in]  h    the handle
/// \param[out] map  the map, arrays owned by the handle
#[no_mangle]
pub extern "C" fn octmesh_mesh_get_element_map(
    h: *mut octmesh_t,
    map: *mut octmesh_element_map_t,
) -> octmesh_status_t {
    with_mut(h, |h| {
        crate::parallel::comm::agree(&*h.comm, non_null(map, "map"))?;
        let m = h.session.element_map()?;
        if m.old_first.len() > i32::MAX as usize {
            return Err(Error::new(ErrorKind::Limit, "too many local elements"));
        }
        // u64::MAX reads as -1 through the signed type, counts are far
        // below 2^31: the arrays are handed out as they are.
        write_out(
            map,
            octmesh_element_map_t {
                num_elements: m.old_first.len() as octmesh_locidx_t,
                old_first: m.old_first.as_ptr() as *const octmesh_gloidx_t,
                old_count: m.old_count.as_ptr() as *const octmesh_locidx_t,
                level_change: m.level_change.as_ptr(),
                uncovered: m.uncovered as octmesh_gloidx_t,
            },
        );
        Ok(())
    })
}

/// The caller's old field (`ncomp` values per old item) and the output
/// buffer for `ncomp` values per new item, both checked on every rank.
///
/// # Safety
/// `old` is NULL or valid for `ncomp * old_items` values; `out` is NULL or
/// valid for writes of `capacity` values.
unsafe fn field_args<'a>(
    ncomp: octmesh_locidx_t,
    old: *const f64,
    old_items: usize,
    out: *mut f64,
    capacity: octmesh_locidx_t,
    new_items: usize,
) -> Result<(usize, &'a [f64], &'a mut [f64])> {
    if ncomp < 1 {
        return Err(Error::invalid(format!(
            "argument 'ncomp' must be at least 1, got {ncomp}"
        )));
    }
    let n = ncomp as usize;
    // SAFETY: the caller's contract.
    let old = unsafe { slice_arg(old, n * old_items, "old_values") }?;
    let out = unsafe { out_slice(out, capacity, n * new_items, "new_values") }?;
    Ok((n, old, out))
}

/// The item counts of the previous and the current mesh, or a state error.
fn counts(h: &octmesh_t, item: fn(&crate::mesh::Mesh) -> usize) -> Result<(usize, usize)> {
    match (h.session.previous_mesh(), h.session.mesh()) {
        (Some(old), Some(new)) => Ok((item(old), item(new))),
        _ => Err(Error::new(
            ErrorKind::State,
            "a transfer needs a kept previous mesh (octmesh_mesh_keep_previous) and a new mesh",
        )),
    }
}

/// Moves an element field from the previous mesh to the current one:
/// copied into unchanged and refined elements, the volume-weighted mean of
/// the old elements inside a coarsened one (in Morton order: the same bits
/// on any number of ranks, and a conserved quantity stays conserved), NaN
/// in an element that overlaps no old one. Collective.
///
/// \param[in]  h           the handle
/// \param[in]  ncomp       values per element, 1 or more
/// \param[in]  old_values  `ncomp` values per local element of the previous
///                         mesh, element-major (`[e * ncomp + c]`)
/// \param[out] new_values  `ncomp` values per local element of the current
///                         mesh, element-major
/// \param[in]  capacity    room in `new_values`, in values
#[no_mangle]
pub extern "C" fn octmesh_mesh_transfer_elements(
    h: *mut octmesh_t,
    ncomp: octmesh_locidx_t,
    old_values: *const f64,
    new_values: *mut f64,
    capacity: octmesh_locidx_t,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let args = counts(h, |m| m.elements().len()).and_then(|(o, n)| {
            // SAFETY: the caller's arrays (requirement of the C API).
            unsafe { field_args(ncomp, old_values, o, new_values, capacity, n) }
        });
        let (n, old, out) = crate::parallel::comm::agree(&*h.comm, args)?;
        let values = h.session.transfer_elements(n, old)?;
        out[..values.len()].copy_from_slice(&values);
        Ok(())
    })
}

/// Moves a trilinear nodal field from the previous mesh to the current
/// one: each new node gets the old field's value at its position (a node
/// on an old face, edge or corner is evaluated in one element chosen by
/// position alone, so the values are the same bits on any number of
/// ranks). The old hanging nodes are taken as the means of their
/// dependencies, and the new ones are set so. A field trilinear over the
/// domain moves exactly. Nodes in no old element get NaN. Collective.
///
/// \param[in]  h           the handle
/// \param[in]  ncomp       values per node, 1 or more
/// \param[in]  old_values  `ncomp` values per local node of the previous
///                         mesh (hanging nodes included), node-major
/// \param[out] new_values  `ncomp` values per local node of the current
///                         mesh (hanging nodes included), node-major
/// \param[in]  capacity    room in `new_values`, in values
/// \param[out] missing     nodes over all ranks in no old element (may be
///                         NULL)
#[no_mangle]
pub extern "C" fn octmesh_mesh_transfer_nodes(
    h: *mut octmesh_t,
    ncomp: octmesh_locidx_t,
    old_values: *const f64,
    new_values: *mut f64,
    capacity: octmesh_locidx_t,
    missing: *mut octmesh_gloidx_t,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let args = counts(h, |m| m.num_nodes()).and_then(|(o, n)| {
            // SAFETY: the caller's arrays (requirement of the C API).
            unsafe { field_args(ncomp, old_values, o, new_values, capacity, n) }
        });
        let (n, old, out) = crate::parallel::comm::agree(&*h.comm, args)?;
        let (values, lost) = h.session.transfer_nodes(n, old)?;
        out[..values.len()].copy_from_slice(&values);
        if !missing.is_null() {
            write_out(missing, lost as octmesh_gloidx_t);
        }
        Ok(())
    })
}
