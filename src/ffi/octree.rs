//! The octree: refinement, balance, partition, leaves, leak check.

use std::ffi::c_void;

use super::handle::octmesh_t;
use super::{
    non_null, octmesh_connect_t, octmesh_gloidx_t, octmesh_locidx_t, octmesh_octant_t,
    octmesh_status_t, out_slice, slice_arg, with_mut, with_ref, write_out, FromC,
};
use crate::error::{Error, ErrorKind, Result};
use crate::octree::LinearOctree;
use crate::{Connectivity, Octant, MAX_LEVEL};

/// Refinement callback: returns non-zero to refine the octant. It must give
/// the same answer for the same octant on every rank (the top of the tree is
/// evaluated redundantly), and must not unwind or longjmp.
pub type octmesh_refine_fn =
    Option<unsafe extern "C" fn(ctx: *mut c_void, o: *const octmesh_octant_t) -> i32>;

/// Weight callback for partitioning: the weight of a leaf. When the sum
/// over all leaves does not fit in 64 bits, `octmesh_octree_partition`
/// fails with `OCTMESH_STATUS_INVALID_ARGUMENT`. Must not unwind or
/// longjmp.
pub type octmesh_weight_fn =
    Option<unsafe extern "C" fn(ctx: *mut c_void, o: *const octmesh_octant_t) -> u64>;

fn level_arg(level: i32, name: &str) -> Result<u8> {
    if (0..=MAX_LEVEL as i32).contains(&level) {
        Ok(level as u8)
    } else {
        Err(Error::invalid(format!(
            "{name} {level} is outside 0..={MAX_LEVEL}"
        )))
    }
}

/// Builds a new octree from the root whose leaves touching the surface are
/// at `level` and whose other leaves are as coarse as possible, in the cube
/// of `octmesh_domain_set` or fitted around the surface. Replaces any
/// previous octree and mesh. Needs a surface. Fails with
/// `OCTMESH_STATUS_LIMIT` before refining when the size estimated from the
/// surface area is more than twice the octant limit or more than the memory
/// budget allows (the message gives the estimate and the finest level that
/// would fit), and otherwise as soon as the count exceeds either.
/// Collective.
///
/// \param[in] h      the handle
/// \param[in] level  level of the leaves touching the surface, 0 to 18
#[no_mangle]
pub extern "C" fn octmesh_octree_refine_surface(h: *mut octmesh_t, level: i32) -> octmesh_status_t {
    with_mut(h, |h| {
        let level = h.agree(level_arg(level, "level"))?;
        h.session.refine_surface(level)
    })
}

/// Refines by a callback: a leaf is split while `refine(ctx, &octant)`
/// returns non-zero and its level is below `max_level`. Without an octree,
/// builds one from the root (in the cube of `octmesh_domain_set`, else
/// fitted around the surface, else the unit cube); otherwise refines the
/// existing leaves (which drops their balance). Drops the mesh.
/// Collective; see `octmesh_refine_fn` for what the callback must satisfy.
///
/// \param[in] h          the handle
/// \param[in] max_level  no leaf is split beyond this level, 0 to 18
/// \param[in] refine     the callback
/// \param[in] ctx        passed to the callback unchanged
#[no_mangle]
pub extern "C" fn octmesh_octree_refine_callback(
    h: *mut octmesh_t,
    max_level: i32,
    refine: octmesh_refine_fn,
    ctx: *mut c_void,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let checked = level_arg(max_level, "max_level").and_then(|l| match refine {
            None => Err(Error::invalid("argument 'refine' is NULL")),
            Some(f) => Ok((l, f)),
        });
        let (level, f) = h.agree(checked)?;
        h.session.refine_callback(level, |o: Octant| {
            let oc = octmesh_octant_t::of(o);
            // SAFETY: a C function pointer given by the caller, called with
            // its own context and a valid octant.
            unsafe { f(ctx, &oc) != 0 }
        })
    })
}

/// 2:1-balances the octree. Leaves stay on their ranks; call
/// `octmesh_octree_partition` afterwards to even out the counts. Drops the
/// mesh. Needs an octree. Fails with `OCTMESH_STATUS_LIMIT`, leaving the
/// octree as it was, when the balanced octree would exceed the octant limit
/// or the memory budget. Collective.
///
/// \param[in] h        the handle
/// \param[in] connect  the contacts balanced: one of `octmesh_connect`
#[no_mangle]
pub extern "C" fn octmesh_octree_balance(
    h: *mut octmesh_t,
    connect: octmesh_connect_t,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let conn = h.agree(Connectivity::from_c(connect))?;
        h.session.balance(conn)
    })
}

/// Repartitions the leaves in Morton order: equal counts when `weight` is
/// NULL, else about equal sums of `weight(ctx, &leaf)` (called once per
/// local leaf). Drops the mesh. Needs an octree. Collective.
///
/// \param[in] h       the handle
/// \param[in] weight  the weight callback, or NULL for equal counts
/// \param[in] ctx     passed to the callback unchanged
#[no_mangle]
pub extern "C" fn octmesh_octree_partition(
    h: *mut octmesh_t,
    weight: octmesh_weight_fn,
    ctx: *mut c_void,
) -> octmesh_status_t {
    with_mut(h, |h| {
        h.session.partition_weighted(weight.map(|f| {
            move |o: Octant| {
                let oc = octmesh_octant_t::of(o);
                // SAFETY: a C function pointer given by the caller.
                unsafe { f(ctx, &oc) }
            }
        }))
    })
}

fn tree_of(h: &octmesh_t) -> Result<&LinearOctree> {
    h.session.tree().ok_or_else(|| {
        Error::new(
            ErrorKind::State,
            "there is no octree yet: call octmesh_octree_refine_surface or \
             octmesh_octree_refine_callback first",
        )
    })
}

/// The number of leaves on this rank and over all ranks. Needs an octree.
/// Not collective.
///
/// \param[in]  h       the handle
/// \param[out] local   leaves on this rank
/// \param[out] global  leaves over all ranks
#[no_mangle]
pub extern "C" fn octmesh_octree_get_num_leaves(
    h: *const octmesh_t,
    local: *mut octmesh_locidx_t,
    global: *mut octmesh_gloidx_t,
) -> octmesh_status_t {
    with_ref(h, |h| {
        non_null(local, "local")?;
        non_null(global, "global")?;
        let t = tree_of(h)?;
        write_out(local, t.local_len() as octmesh_locidx_t);
        write_out(global, t.global_len() as octmesh_gloidx_t);
        Ok(())
    })
}

/// Copies this rank's leaves, in Morton order, to the caller's buffer.
/// Needs an octree. Not collective.
///
/// \param[in]  h         the handle
/// \param[out] out       room for `capacity` leaves; the first `local`
///                       (`octmesh_octree_get_num_leaves`) are written
/// \param[in]  capacity  the room in `out`, at least the local count
#[no_mangle]
pub extern "C" fn octmesh_octree_get_leaves(
    h: *const octmesh_t,
    out: *mut octmesh_octant_t,
    capacity: octmesh_locidx_t,
) -> octmesh_status_t {
    with_ref(h, |h| {
        let t = tree_of(h)?;
        // SAFETY: room for `capacity` values (requirement of the C API).
        let dst = unsafe { out_slice(out, capacity, t.local_len(), "out") }?;
        for (d, &o) in dst.iter_mut().zip(t.leaves()) {
            *d = octmesh_octant_t::of(o);
        }
        Ok(())
    })
}

/// Checks that the region outside the surface does not reach `point`, a
/// point the caller knows to be inside the body: no path of face-adjacent
/// leaves touching no triangle leads from the boundary of the cube to the
/// leaf holding it. Returns `OCTMESH_STATUS_OK` when the point is sealed
/// off, `OCTMESH_STATUS_LEAK` when it is reached (then `octmesh_last_error`
/// describes the path: its length, the first and last leaves' centres and
/// sizes, where it enters the surface's bounding box), and
/// `OCTMESH_STATUS_INVALID_ARGUMENT` when the point is outside the cube or
/// in a leaf touching the surface. Run it after refinement and balance,
/// before `octmesh_mesh_build` with `OCTMESH_KEEP_OUTSIDE`. Needs a surface
/// and an octree. Collective; every rank gets the same status and message.
///
/// \param[in] h      the handle
/// \param[in] point  3 values, user units
#[no_mangle]
pub extern "C" fn octmesh_octree_check_leak(
    h: *mut octmesh_t,
    point: *const f64,
) -> octmesh_status_t {
    with_mut(h, |h| {
        // SAFETY: NULL or 3 values (requirement of the C API).
        let p = h.agree(unsafe { slice_arg(point, 3, "point") }.map(|p| [p[0], p[1], p[2]]))?;
        h.session.check_leak(p, None)
    })
}
