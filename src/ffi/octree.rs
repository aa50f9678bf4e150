//! The octree: refinement, balance, partition, leaves, leak check.

use std::ffi::{c_char, c_void};

use super::handle::octmesh_t;
use super::{
    non_null, octmesh_connect_t, octmesh_gloidx_t, octmesh_locidx_t, octmesh_octant_t,
    octmesh_status_t, out_slice, path_arg, slice_arg, str_arg, with_mut, with_ref, write_out,
    FromC,
};
use crate::error::{Error, ErrorKind, Result};
use crate::octree::LinearOctree;
use crate::refine::regions::Region;
use crate::{Connectivity, Octant, MAX_LEVEL};

/// Refinement callback: returns true to refine the octant. It must give
/// the same answer for the same octant on every rank (the top of the tree is
/// evaluated redundantly), and must not unwind or longjmp.
pub type octmesh_refine_fn =
    Option<unsafe extern "C" fn(ctx: *mut c_void, o: *const octmesh_octant_t) -> bool>;

/// Weight callback for partitioning: the weight of a leaf. When the sum
/// over all leaves does not fit in 64 bits, `octmesh_octree_partition`
/// fails with `OCTMESH_STATUS_INVALID_ARGUMENT`. Must not unwind or
/// longjmp.
pub type octmesh_weight_fn =
    Option<unsafe extern "C" fn(ctx: *mut c_void, o: *const octmesh_octant_t) -> u64>;

pub(super) fn level_arg(level: i32, name: &str) -> Result<u8> {
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

/// Curvature refinement after `octmesh_octree_refine_surface(h,
/// min_level)`, like the command's `--level MIN:MAX --feature-angle DEG`:
/// a leaf touching the surface is split, up to `max_level`, while the unit
/// normals of the triangles touching it differ by more than
/// `feature_angle` degrees. Needs an octree refined to the surface and the
/// surface. Drops the balance and the mesh. Collective.
///
/// \param[in] h              the handle
/// \param[in] min_level      the surface level the octree was refined to
/// \param[in] max_level      the finest level, min_level to 18
/// \param[in] feature_angle  degrees, in (0, 180); 30 is the command's
///                           default
#[no_mangle]
pub extern "C" fn octmesh_octree_refine_curvature(
    h: *mut octmesh_t,
    min_level: i32,
    max_level: i32,
    feature_angle: f64,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let checked = curvature_args(min_level, max_level, feature_angle);
        let (lo, hi) = h.agree(checked)?;
        let octree = &mut h.session.config_mut().octree;
        let before = (octree.level, octree.max_level, octree.feature_angle);
        (octree.level, octree.max_level, octree.feature_angle) =
            (Some(lo), Some(hi), Some(feature_angle));
        let done = h.session.refine_curvature();
        if done.is_err() {
            let octree = &mut h.session.config_mut().octree;
            (octree.level, octree.max_level, octree.feature_angle) = before;
        }
        done
    })
}

/// Checks a `(min_level, max_level)` range and a feature angle.
fn curvature_args(min_level: i32, max_level: i32, feature_angle: f64) -> Result<(u8, u8)> {
    let lo = level_arg(min_level, "min_level")?;
    let hi = level_arg(max_level, "max_level")?;
    if hi < lo {
        return Err(Error::invalid(format!(
            "max_level {hi} is below min_level {lo}"
        )));
    }
    crate::config::options::check_key("octree.feature_angle", "feature_angle", feature_angle)?;
    Ok((lo, hi))
}

/// Refinement of one part of the surface (a solid of an ASCII STL, named
/// as its patch is before renames) to its own levels, like the command's
/// `--surface-level NAME=MIN:MAX --feature-angle DEG`: a leaf touching the
/// part is split while below `min_level`, and up to `max_level` while the
/// unit normals of the part's triangles touching it differ by more than
/// `feature_angle` degrees. Call it once per part after
/// `octmesh_octree_refine_surface(h, L)` with `L` the least minimum; the
/// order of the calls does not matter. Needs an octree and the surface.
/// Drops the balance and the mesh. Collective.
///
/// \param[in] h              the handle
/// \param[in] name           the part's name, NUL-terminated
/// \param[in] min_level      the part's level, 0 to 18
/// \param[in] max_level      its finest level where it curves, min_level
///                           to 18
/// \param[in] feature_angle  degrees, in (0, 180)
#[no_mangle]
pub extern "C" fn octmesh_octree_refine_surface_part(
    h: *mut octmesh_t,
    name: *const c_char,
    min_level: i32,
    max_level: i32,
    feature_angle: f64,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let checked = str_arg(name, "name").and_then(|n| {
            let (lo, hi) = curvature_args(min_level, max_level, feature_angle)?;
            Ok((n.to_string(), lo, hi))
        });
        let (n, lo, hi) = h.agree(checked)?;
        // This part alone, as an action: the configuration is restored.
        let octree = &mut h.session.config_mut().octree;
        let saved = octree.clone();
        octree.level = Some(0);
        octree.max_level = None;
        octree.feature_angle = Some(feature_angle);
        octree.surface_levels = [(n, [lo, hi])].into_iter().collect();
        let done = h.session.refine_curvature();
        h.session.config_mut().octree = saved;
        done
    })
}

/// Region refinement of the current octree, like the command's
/// `--min-level`, `--region` and `--distance`: every leaf is split until
/// it is at least `min_level`, at least each region's level where its box
/// (closed) overlaps the region, and at least each band's level where its
/// box comes within the band's distance of the surface (exact distances).
/// The result is the coarsest octree that satisfies every rule. Drops the
/// balance and the mesh. Collective: every rank passes the same rules.
///
/// \param[in] h          the handle
/// \param[in] min_level  0 to 18 (0: no minimum)
/// \param[in] nregions   number of regions, >= 0
/// \param[in] regions    nregions NUL-terminated strings in the command's
///                       form: `box:X0,Y0,Z0,X1,Y1,Z1:LEVEL`,
///                       `sphere:CX,CY,CZ,R:LEVEL` or
///                       `cylinder:X0,Y0,Z0,X1,Y1,Z1,R:LEVEL`, each
///                       optionally followed by `:outside`, then by
///                       `:zone=NAME` (the zone of
///                       `octmesh_mesh_set_zones`); user units
/// \param[in] nbands     number of distance bands, >= 0 (bands need the
///                       surface)
/// \param[in] distances  nbands increasing distances, user units
/// \param[in] levels     nbands levels, 0 to 18
#[no_mangle]
pub extern "C" fn octmesh_octree_refine_regions(
    h: *mut octmesh_t,
    min_level: i32,
    nregions: octmesh_locidx_t,
    regions: *const *const c_char,
    nbands: octmesh_locidx_t,
    distances: *const f64,
    levels: *const i32,
) -> octmesh_status_t {
    with_mut(h, |h| {
        // SAFETY: the arrays are the caller's, of the documented lengths.
        let checked = level_arg(min_level, "min_level")
            .and_then(|m| Ok((m, unsafe { region_args(nregions, regions) }?)))
            .and_then(|(m, r)| Ok((m, r, unsafe { band_args(nbands, distances, levels) }?)));
        let (min, regions, bands) = h.agree(checked)?;
        let config = h.session.config_mut();
        let before = (
            config.octree.min_level,
            config.regions.clone(),
            config.octree.distance.clone(),
        );
        (
            config.octree.min_level,
            config.regions,
            config.octree.distance,
        ) = (min, regions, bands);
        let done = h.session.refine_regions();
        if done.is_err() {
            let config = h.session.config_mut();
            (
                config.octree.min_level,
                config.regions,
                config.octree.distance,
            ) = before;
        }
        done
    })
}

/// Reads `n` region strings.
///
/// # Safety
/// `p` points to `n` NUL-terminated strings (when `n > 0`).
unsafe fn region_args(n: i32, p: *const *const c_char) -> Result<Vec<Region>> {
    let n = usize::try_from(n)
        .map_err(|_| Error::invalid(format!("nregions is {n}, must be at least 0")))?;
    if n == 0 {
        return Ok(Vec::new());
    }
    // SAFETY: `n` pointers (requirement of the API).
    let ptrs = unsafe { slice_arg(p, n, "regions") }?;
    let mut out = Vec::with_capacity(n);
    for (k, &s) in ptrs.iter().enumerate() {
        let text = str_arg(s, &format!("regions[{k}]"))?;
        out.push(
            Region::parse(text)
                .map_err(|e| Error::invalid(format!("regions[{k}]: {}", e.message())))?,
        );
    }
    Ok(out)
}

/// Reads `n` distance bands.
///
/// # Safety
/// `d` and `l` point to `n` values each (when `n > 0`).
unsafe fn band_args(n: i32, d: *const f64, l: *const i32) -> Result<Vec<(f64, u8)>> {
    let n = usize::try_from(n)
        .map_err(|_| Error::invalid(format!("nbands is {n}, must be at least 0")))?;
    if n == 0 {
        return Ok(Vec::new());
    }
    // SAFETY: `n` values each (requirement of the API).
    let (d, l) = unsafe { (slice_arg(d, n, "distances")?, slice_arg(l, n, "levels")?) };
    let mut out = Vec::with_capacity(n);
    for k in 0..n {
        let level = level_arg(l[k], &format!("levels[{k}]"))?;
        if !(d[k].is_finite() && d[k] > 0.0) || (k > 0 && d[k] <= d[k - 1]) {
            return Err(Error::invalid(format!(
                "distances must be positive and increasing: distances[{k}] = {}",
                d[k]
            )));
        }
        out.push((d[k], level));
    }
    Ok(out)
}

/// Refines by a callback: a leaf is split while `refine(ctx, &octant)`
/// returns true and its level is below `max_level`. Without an octree,
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
            unsafe { f(ctx, &oc) }
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
/// \param[in] connect  the contacts balanced: one of `octmesh_connect_t`
#[no_mangle]
pub extern "C" fn octmesh_octree_balance(
    h: *mut octmesh_t,
    connect: octmesh_connect_t,
) -> octmesh_status_t {
    octmesh_octree_balance_ext(h, connect, None, std::ptr::null_mut())
}

/// `octmesh_octree_balance` keeping the user data
/// (`octmesh_octree_data_set_size`): each leaf balance splits goes through
/// `replace` once with all the leaves that take its place (1 -> n), which
/// writes their data (p4est's `p8est_balance_ext` with a `replace_fn`).
/// If `replace` fails on any rank, every rank fails and the octree and the
/// data are as they were. Collective.
///
/// \param[in] h        the handle
/// \param[in] connect  the contacts balanced: one of `octmesh_connect_t`
/// \param[in] replace  the replace callback, or NULL (new leaves' data
///                     zeroed)
/// \param[in] ctx      passed to the callback unchanged
#[no_mangle]
pub extern "C" fn octmesh_octree_balance_ext(
    h: *mut octmesh_t,
    connect: octmesh_connect_t,
    replace: super::data::octmesh_replace_fn,
    ctx: *mut c_void,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let conn = h.agree(Connectivity::from_c(connect))?;
        let mut r = super::data::replacer(replace, ctx);
        let r = r.as_mut().map(|r| r as crate::octree::leaf_data::ReplaceFn);
        h.session.balance_replace(conn, r)
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

/// Saves the octree, its domain and the attached leaf data
/// (`octmesh_octree_data_set_size`) to one checkpoint file, like the
/// command's `--save`: every rank writes its leaves and data at their
/// global offset, with the hash of the handle's surface (0
/// without one). The layout is in docs/formats.md. Needs an octree.
/// Collective; a path that cannot be written fails every rank.
///
/// \param[in] h     the handle
/// \param[in] path  the file, NUL-terminated (same on every rank)
#[no_mangle]
pub extern "C" fn octmesh_octree_save(h: *mut octmesh_t, path: *const c_char) -> octmesh_status_t {
    with_mut(h, |h| {
        let path = h.agree(path_arg(path, "path"))?;
        h.session.save_octree(&path)
    })
}

/// Replaces the octree by the one of a checkpoint written by
/// `octmesh_octree_save` on any number of ranks: the same leaves in Morton
/// order, in the equal-count partition of `octmesh_octree_partition`, in
/// the checkpoint's domain, with its leaf data attached when it holds some
/// (`octmesh_octree_data_get` reads it). With a surface loaded, a
/// checkpoint saved from another surface is refused. Drops the mesh.
/// Collective: a missing or unreadable file, one that is not a checkpoint,
/// of another version, truncated, or with a damaged byte (its checksums
/// differ) fails every rank with the same message, `OCTMESH_STATUS_FORMAT`
/// for a bad file, and leaves the handle as it was.
///
/// \param[in] h     the handle
/// \param[in] path  the file, NUL-terminated (same on every rank)
#[no_mangle]
pub extern "C" fn octmesh_octree_load(h: *mut octmesh_t, path: *const c_char) -> octmesh_status_t {
    with_mut(h, |h| {
        let path = h.agree(path_arg(path, "path"))?;
        h.session.load_octree(&path)
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
