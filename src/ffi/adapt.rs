//! Adaptation of the octree between simulation steps: refine once,
//! coarsen families, adapt leaf by leaf, partition keeping families
//! together (the C side of [`crate::octree::adapt`]).

use std::ffi::c_void;

use super::data::{octmesh_replace_fn, replacer};
use super::handle::octmesh_t;
use super::octree::{level_arg, octmesh_refine_fn, octmesh_weight_fn};
use super::{octmesh_gloidx_t, octmesh_octant_t, octmesh_status_t, with_mut, write_out};
use crate::error::{Error, Result};
use crate::octree::adapt::{Adapt, AdaptStats};
use crate::octree::leaf_data::ReplaceFn;
use crate::Octant;

/// Coarsening callback: `family` points to the eight sibling leaves of a
/// family in Morton order (child 0 first); returns true to replace them by
/// their parent. Must not unwind or longjmp.
pub type octmesh_coarsen_fn =
    Option<unsafe extern "C" fn(ctx: *mut c_void, family: *const octmesh_octant_t) -> bool>;

/// Adaptation callback (t8code's convention): returns a positive value to
/// refine the leaf, 0 to keep it, a negative value to coarsen it (its family
/// is coarsened only if all eight ask for it). Must not unwind or longjmp.
pub type octmesh_adapt_fn =
    Option<unsafe extern "C" fn(ctx: *mut c_void, o: *const octmesh_octant_t) -> i32>;

/// The global counts of an adaptation, written to the caller's pointers
/// when they are not NULL.
fn write_counts(s: AdaptStats, refined: *mut octmesh_gloidx_t, coarsened: *mut octmesh_gloidx_t) {
    for (p, v) in [(refined, s.refined), (coarsened, s.coarsened)] {
        if !p.is_null() {
            write_out(p, v as octmesh_gloidx_t);
        }
    }
}

fn callback<F>(f: Option<F>, name: &str) -> Result<F> {
    f.ok_or_else(|| Error::invalid(format!("argument '{name}' is NULL")))
}

/// Splits each leaf below `max_level` for which `refine(ctx, &leaf)`
/// returns true into its eight children, once: the children are not
/// offered to the callback (p4est's non-recursive `p8est_refine`; for
/// recursive refinement use `octmesh_octree_refine_callback`). Fails with
/// `OCTMESH_STATUS_LIMIT`, leaving the octree as it was, when the octree
/// would exceed the octant limit or the memory budget. Drops the balance,
/// the leaf classes and the mesh. Needs an octree. Collective.
///
/// \param[in]  h          the handle
/// \param[in]  max_level  leaves at this level are not split, 0 to 18
/// \param[in]  refine     the callback, called once per local leaf below
///                        max_level
/// \param[in]  ctx        passed to the callback unchanged
/// \param[out] refined    leaves split over all ranks, or NULL
#[no_mangle]
pub extern "C" fn octmesh_octree_refine_once(
    h: *mut octmesh_t,
    max_level: i32,
    refine: octmesh_refine_fn,
    ctx: *mut c_void,
    refined: *mut octmesh_gloidx_t,
) -> octmesh_status_t {
    octmesh_octree_refine_once_ext(h, max_level, refine, None, ctx, refined)
}

/// `octmesh_octree_refine_once` keeping the user data
/// (`octmesh_octree_data_set_size`): each split leaf goes through
/// `replace` (1 -> 8), which writes the children's data (p4est's
/// `p8est_refine_ext` with a `replace_fn`). All `refine` calls come before
/// the first `replace` call. If `replace` fails on any rank, every rank
/// fails and the octree and the data are as they were. Collective.
///
/// \param[in]  h          the handle
/// \param[in]  max_level  leaves at this level are not split, 0 to 18
/// \param[in]  refine     the callback, called once per local leaf below
///                        max_level
/// \param[in]  replace    the replace callback, or NULL (children's data
///                        zeroed)
/// \param[in]  ctx        passed to both callbacks unchanged
/// \param[out] refined    leaves split over all ranks, or NULL
#[no_mangle]
pub extern "C" fn octmesh_octree_refine_once_ext(
    h: *mut octmesh_t,
    max_level: i32,
    refine: octmesh_refine_fn,
    replace: octmesh_replace_fn,
    ctx: *mut c_void,
    refined: *mut octmesh_gloidx_t,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let checked =
            callback(refine, "refine").and_then(|f| Ok((f, level_arg(max_level, "max_level")?)));
        let (f, level) = h.agree(checked)?;
        let mut r = replacer(replace, ctx);
        let split = |o: Octant| {
            let oc = octmesh_octant_t::of(o);
            // SAFETY: a C function pointer given by the caller, called with
            // its own context and a valid octant.
            unsafe { f(ctx, &oc) }
        };
        let s = h
            .session
            .refine_once(level, split, r.as_mut().map(|r| r as ReplaceFn))?;
        write_counts(s, refined, std::ptr::null_mut());
        Ok(())
    })
}

/// Replaces each family of eight sibling leaves on this rank for which
/// `coarsen(ctx, family)` returns true by its parent. A family whose
/// leaves are on different ranks is never offered nor coarsened (p4est's
/// rule): partition with `octmesh_octree_partition_for_coarsening` first to
/// keep families together. With `recursive` true, a parent made by
/// coarsening that completes a new family is offered in turn; with false,
/// only families of the leaves present before the call are (p4est's
/// `p8est_coarsen`). Drops the balance, the leaf classes and the mesh.
/// Needs an octree. Collective.
///
/// \param[in]  h          the handle
/// \param[in]  recursive  true to coarsen repeatedly
/// \param[in]  coarsen    the callback
/// \param[in]  ctx        passed to the callback unchanged
/// \param[out] coarsened  families coarsened over all ranks, or NULL
#[no_mangle]
pub extern "C" fn octmesh_octree_coarsen(
    h: *mut octmesh_t,
    recursive: bool,
    coarsen: octmesh_coarsen_fn,
    ctx: *mut c_void,
    coarsened: *mut octmesh_gloidx_t,
) -> octmesh_status_t {
    octmesh_octree_coarsen_ext(h, recursive, coarsen, None, ctx, coarsened)
}

/// `octmesh_octree_coarsen` keeping the user data: each coarsened family
/// goes through `replace` (8 -> 1; with `recursive`, once per family,
/// finest first), which writes the parent's data (p4est's
/// `p8est_coarsen_ext` with a `replace_fn`). All `coarsen` calls come
/// before the first `replace` call. If `replace` fails on any rank, every
/// rank fails and the octree and the data are as they were. Collective.
///
/// \param[in]  h          the handle
/// \param[in]  recursive  true to coarsen repeatedly
/// \param[in]  coarsen    the callback
/// \param[in]  replace    the replace callback, or NULL (parents' data
///                        zeroed)
/// \param[in]  ctx        passed to both callbacks unchanged
/// \param[out] coarsened  families coarsened over all ranks, or NULL
#[no_mangle]
pub extern "C" fn octmesh_octree_coarsen_ext(
    h: *mut octmesh_t,
    recursive: bool,
    coarsen: octmesh_coarsen_fn,
    replace: octmesh_replace_fn,
    ctx: *mut c_void,
    coarsened: *mut octmesh_gloidx_t,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let f = h.agree(callback(coarsen, "coarsen"))?;
        let mut r = replacer(replace, ctx);
        let merge = |fam: &[Octant; 8]| {
            let c = fam.map(octmesh_octant_t::of);
            // SAFETY: a C function pointer given by the caller, called with
            // its own context and eight valid octants.
            unsafe { f(ctx, c.as_ptr()) }
        };
        let s = h
            .session
            .coarsen(recursive, merge, r.as_mut().map(|r| r as ReplaceFn))?;
        write_counts(s, std::ptr::null_mut(), coarsened);
        Ok(())
    })
}

/// Calls `adapt(ctx, &leaf)` once per local leaf, in Morton order, and
/// then refines each leaf that asked for it once (a leaf at level 18 is
/// kept) and coarsens each family of eight leaves on this rank that all
/// asked for it; other leaves are kept (t8code's `t8_forest_adapt`, not
/// recursive). Fails with `OCTMESH_STATUS_LIMIT`, leaving the octree as it
/// was, when the octree would exceed the octant limit or the memory budget.
/// Drops the balance, the leaf classes and the mesh. Needs an octree.
/// Collective.
///
/// \param[in]  h          the handle
/// \param[in]  adapt      the callback: > 0 refine, 0 keep, < 0 coarsen
/// \param[in]  ctx        passed to the callback unchanged
/// \param[out] refined    leaves split over all ranks, or NULL
/// \param[out] coarsened  families coarsened over all ranks, or NULL
#[no_mangle]
pub extern "C" fn octmesh_octree_adapt(
    h: *mut octmesh_t,
    adapt: octmesh_adapt_fn,
    ctx: *mut c_void,
    refined: *mut octmesh_gloidx_t,
    coarsened: *mut octmesh_gloidx_t,
) -> octmesh_status_t {
    octmesh_octree_adapt_ext(h, adapt, None, ctx, refined, coarsened)
}

/// `octmesh_octree_adapt` keeping the user data: each split leaf (1 -> 8)
/// and each coarsened family (8 -> 1) goes through `replace`, which writes
/// the new leaves' data. All `adapt` calls come before the first `replace`
/// call. If `replace` fails on any rank, every rank fails and the octree
/// and the data are as they were. Collective.
///
/// \param[in]  h          the handle
/// \param[in]  adapt      the callback: > 0 refine, 0 keep, < 0 coarsen
/// \param[in]  replace    the replace callback, or NULL (new leaves' data
///                        zeroed)
/// \param[in]  ctx        passed to both callbacks unchanged
/// \param[out] refined    leaves split over all ranks, or NULL
/// \param[out] coarsened  families coarsened over all ranks, or NULL
#[no_mangle]
pub extern "C" fn octmesh_octree_adapt_ext(
    h: *mut octmesh_t,
    adapt: octmesh_adapt_fn,
    replace: octmesh_replace_fn,
    ctx: *mut c_void,
    refined: *mut octmesh_gloidx_t,
    coarsened: *mut octmesh_gloidx_t,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let f = h.agree(callback(adapt, "adapt"))?;
        let mut r = replacer(replace, ctx);
        let decide = |o: Octant| {
            let oc = octmesh_octant_t::of(o);
            // SAFETY: a C function pointer given by the caller, called with
            // its own context and a valid octant.
            match unsafe { f(ctx, &oc) } {
                w if w > 0 => Adapt::Refine,
                0 => Adapt::Keep,
                _ => Adapt::Coarsen,
            }
        };
        let s = h
            .session
            .adapt(decide, r.as_mut().map(|r| r as ReplaceFn))?;
        write_counts(s, refined, coarsened);
        Ok(())
    })
}

/// Repartitions the leaves in Morton order like `octmesh_octree_partition`
/// (equal counts when `weight` is NULL, else about equal sums of
/// `weight(ctx, &leaf)`, called once per local leaf), then moves each
/// boundary that would split a family of eight sibling leaves to one end of
/// the family, so that `octmesh_octree_coarsen` and `octmesh_octree_adapt`
/// can coarsen every family afterwards. The result is identical to p4est's
/// `p8est_partition_ext (p8est, 1, weight_fn)`, whose shares of the weight
/// round down where `octmesh_octree_partition` rounds up; when every weight
/// is 0 nothing moves. Drops the leaf classes and the mesh. Needs an octree.
/// Collective.
///
/// \param[in] h       the handle
/// \param[in] weight  the weight callback, or NULL for equal counts
/// \param[in] ctx     passed to the callback unchanged
#[no_mangle]
pub extern "C" fn octmesh_octree_partition_for_coarsening(
    h: *mut octmesh_t,
    weight: octmesh_weight_fn,
    ctx: *mut c_void,
) -> octmesh_status_t {
    with_mut(h, |h| {
        h.session.partition_for_coarsening(weight.map(|f| {
            move |o: Octant| {
                let oc = octmesh_octant_t::of(o);
                // SAFETY: a C function pointer given by the caller.
                unsafe { f(ctx, &oc) }
            }
        }))
    })
}
