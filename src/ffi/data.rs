//! User data per leaf (the C side of [`crate::octree::leaf_data`]): its size, the
//! local array, and the replace callback the `_ext` adaptation and balance
//! functions take.

use std::ffi::c_void;

use super::handle::octmesh_t;
use super::{non_null, octmesh_locidx_t, octmesh_octant_t, octmesh_status_t, with_mut, write_out};
use crate::error::{Error, ErrorKind, Result};
use crate::octree::leaf_data::Replace;

/// Replace callback: `num_outgoing` leaves `outgoing` (with their data,
/// `outgoing_data`, the data size bytes each, in the same order) are replaced
/// by `num_incoming` leaves `incoming`, whose data the callback writes to
/// `incoming_data` (zeroed before the call). Both lists are in Morton order
/// and cover the same region: a leaf and its 8 children (refinement), 8
/// siblings and their parent (coarsening; a recursive coarsening calls once
/// per family, finest first), or a leaf and the n finer leaves balance put
/// in its place. The data pointers are NULL when no data is attached.
/// Returns 0 on success; any other value fails the call on every rank
/// (`OCTMESH_STATUS_INVALID_ARGUMENT` on this rank,
/// `OCTMESH_STATUS_REMOTE_FAILURE` on the others) with the octree and the
/// data left as they were. Must not unwind or longjmp.
pub type octmesh_replace_fn = Option<
    unsafe extern "C" fn(
        ctx: *mut c_void,
        num_outgoing: octmesh_locidx_t,
        outgoing: *const octmesh_octant_t,
        outgoing_data: *const c_void,
        num_incoming: octmesh_locidx_t,
        incoming: *const octmesh_octant_t,
        incoming_data: *mut c_void,
    ) -> i32,
>;

/// The Rust side of a C replace callback: calls `f` with `ctx` and turns a
/// non-zero return into an error naming the first outgoing leaf.
pub(crate) fn replacer(
    f: octmesh_replace_fn,
    ctx: *mut c_void,
) -> Option<impl FnMut(Replace<'_>) -> Result<()>> {
    let f = f?;
    let (mut outs, mut ins) = (Vec::new(), Vec::new());
    Some(move |r: Replace<'_>| {
        outs.clear();
        outs.extend(r.outgoing.iter().map(|&o| octmesh_octant_t::of(o)));
        ins.clear();
        ins.extend(r.incoming.iter().map(|&o| octmesh_octant_t::of(o)));
        let (od, id) = if r.size() == 0 {
            (std::ptr::null(), std::ptr::null_mut())
        } else {
            (
                r.outgoing_data.as_ptr() as *const c_void,
                r.incoming_data.as_mut_ptr() as *mut c_void,
            )
        };
        // SAFETY: a C function pointer given by the caller, called with its
        // own context, valid octant arrays of the given lengths and data
        // buffers of the data size times those lengths.
        let rc = unsafe {
            f(
                ctx,
                outs.len() as octmesh_locidx_t,
                outs.as_ptr(),
                od,
                ins.len() as octmesh_locidx_t,
                ins.as_ptr(),
                id,
            )
        };
        if rc != 0 {
            let o = outs[0];
            return Err(Error::invalid(format!(
                "the replace callback returned {rc} replacing {} leaves by {}, the first \
                 at ({}, {}, {}) level {}",
                outs.len(),
                ins.len(),
                o.x,
                o.y,
                o.z,
                o.level
            )));
        }
        Ok(())
    })
}

/// Attaches `bytes` bytes of user data to every local leaf, zeroed, kept in
/// Morton order beside the leaves (`octmesh_octree_data_get`). The data
/// survives `octmesh_octree_refine_once`, `octmesh_octree_coarsen`,
/// `octmesh_octree_adapt`, `octmesh_octree_balance` (new leaves get zeros;
/// their `_ext` forms call a replace callback instead), and moves with its
/// leaves in `octmesh_octree_partition` and
/// `octmesh_octree_partition_for_coarsening`. Other refinements, and a new
/// octree, detach it. Calling again with the same size keeps the data;
/// another size while data is attached fails with `OCTMESH_STATUS_STATE`
/// (detach first with 0). Needs an octree. Collective.
///
/// \param[in] h      the handle
/// \param[in] bytes  bytes per leaf, 0 to detach the data
#[no_mangle]
pub extern "C" fn octmesh_octree_data_set_size(h: *mut octmesh_t, bytes: i32) -> octmesh_status_t {
    with_mut(h, |h| {
        let size = h.agree(
            usize::try_from(bytes)
                .map_err(|_| Error::invalid(format!("data size {bytes} is negative"))),
        )?;
        h.session.set_leaf_data_size(size)
    })
}

/// The bytes of user data per leaf: 0 when none is attached. Not
/// collective.
///
/// \param[in]  h      the handle
/// \param[out] bytes  bytes per leaf
#[no_mangle]
pub extern "C" fn octmesh_octree_data_get_size(
    h: *mut octmesh_t,
    bytes: *mut i32,
) -> octmesh_status_t {
    with_mut(h, |h| {
        non_null(bytes, "bytes")?;
        let n = h.session.leaf_data().map_or(0, |d| d.size());
        write_out(bytes, n as i32);
        Ok(())
    })
}

/// The local user data: `num_leaves` entries of the data size each, leaf
/// `i`'s at byte `i * size`, in the Morton order of
/// `octmesh_octree_get_leaves`. The caller may read and write it; the
/// pointer stays valid until the next call that changes the leaves or the
/// data size. Fails with `OCTMESH_STATUS_STATE` when no data is attached.
/// Not collective.
///
/// \param[in]  h           the handle
/// \param[out] data        the array (NULL when it is empty)
/// \param[out] num_leaves  local leaves (entries)
#[no_mangle]
pub extern "C" fn octmesh_octree_data_get(
    h: *mut octmesh_t,
    data: *mut *mut c_void,
    num_leaves: *mut octmesh_locidx_t,
) -> octmesh_status_t {
    with_mut(h, |h| {
        non_null(data, "data")?;
        non_null(num_leaves, "num_leaves")?;
        let d = h.session.leaf_data_mut().ok_or_else(|| {
            Error::new(
                ErrorKind::State,
                "no leaf data is attached: call octmesh_octree_data_set_size (refinements \
                 other than refine_once, coarsen and adapt, and new octrees, detach it)",
            )
        })?;
        let n = d.len() as octmesh_locidx_t;
        let bytes = d.as_bytes_mut();
        let p = if bytes.is_empty() {
            std::ptr::null_mut()
        } else {
            bytes.as_mut_ptr() as *mut c_void
        };
        write_out(data, p);
        write_out(num_leaves, n);
        Ok(())
    })
}
