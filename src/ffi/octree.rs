//! Surfaces, refinement, balance and partition.

use std::ffi::{c_char, c_void, CStr};

use super::handle::{octmesh_t, SurfaceState};
use super::{
    non_null, octmesh_connect, octmesh_connect_t, octmesh_octant_t, octmesh_status_t, path_arg,
    with_mut, with_ref, write_out,
};
use crate::error::{Error, Result};
use crate::geometry::{shapes, stl, Surface, Triangle};
use crate::octree::LinearOctree;
use crate::refine::{
    check_estimate, construct_for_callback, construct_top_for_surface, SurfaceIndex,
};
use crate::{Connectivity, Octant, MAX_LEVEL};

/// Refinement callback: returns non-zero to refine the octant. It must give
/// the same answer for the same octant on every rank (the top of the tree is
/// evaluated redundantly), and must not unwind or longjmp.
pub type octmesh_refine_fn =
    Option<unsafe extern "C" fn(ctx: *mut c_void, o: *const octmesh_octant_t) -> i32>;

/// Weight callback for partitioning: the weight of a leaf. When the sum
/// over all leaves does not fit in 64 bits, `octmesh_partition` fails with
/// `OCTMESH_STATUS_INVALID_ARGUMENT`. Must not unwind or longjmp.
pub type octmesh_weight_fn =
    Option<unsafe extern "C" fn(ctx: *mut c_void, o: *const octmesh_octant_t) -> u64>;

/// Installs a new surface, replacing the old one; the octree and mesh are
/// kept (a later mesh classifies against the new surface).
fn set_surface(h: &mut octmesh_t, loaded: Result<Surface>) -> Result<()> {
    let surface = h.agree(loaded)?;
    let domain = match &h.tree {
        Some((_, d)) => *d,
        None => {
            let b = surface.bbox();
            match h.explicit_domain {
                Some(d) => d,
                None => h.agree(crate::domain::Domain::around(b.min, b.max, h.options.fit))?,
            }
        }
    };
    let index = SurfaceIndex::new(&surface, &domain);
    h.surface = Some(SurfaceState {
        surface,
        index,
        index_domain: domain,
        auto_rule: Default::default(),
    });
    Ok(())
}

/// Reads the surface from an STL file (ASCII or binary) at `path`; every
/// rank reads the file. Replaces any previous surface. Collective: a
/// failure on any rank (missing file on one rank) fails on every rank.
#[no_mangle]
pub unsafe extern "C" fn octmesh_surface_from_stl(
    h: *mut octmesh_t,
    path: *const c_char,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let loaded = path_arg(path, "path").and_then(|p| stl::read_stl_file(&p));
        set_surface(h, loaded)
    })
}

/// Sets the surface from `ntri` triangles: `xyz` holds 9 doubles per
/// triangle (x, y, z of its three vertices), user units. The data is
/// copied. Collective; each rank passes the whole surface.
#[no_mangle]
pub unsafe extern "C" fn octmesh_surface_from_triangles(
    h: *mut octmesh_t,
    ntri: i64,
    xyz: *const f64,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let loaded = non_null(xyz, "xyz").and_then(|_| {
            if ntri <= 0 || ntri as u64 > (isize::MAX as u64) / 72 {
                return Err(Error::invalid(format!("ntri must be positive, got {ntri}")));
            }
            // SAFETY: non-NULL, 9 * ntri values (requirement of the C API).
            let v = unsafe { std::slice::from_raw_parts(xyz, 9 * ntri as usize) };
            let tris = v
                .chunks_exact(9)
                .map(|t| Triangle::new([t[0], t[1], t[2]], [t[3], t[4], t[5]], [t[6], t[7], t[8]]))
                .collect();
            Surface::new(tris)
        });
        set_surface(h, loaded)
    })
}

/// Sets a built-in surface: `"sphere"` (radius 1 at the origin) or
/// `"torus"`. Collective.
#[no_mangle]
pub unsafe extern "C" fn octmesh_surface_builtin(
    h: *mut octmesh_t,
    name: *const c_char,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let loaded = non_null(name, "name").and_then(|_| {
            // SAFETY: non-NULL, NUL-terminated (requirement of the C API).
            match unsafe { CStr::from_ptr(name) }.to_bytes() {
                b"sphere" => Ok(shapes::default_sphere()),
                b"torus" => Ok(shapes::default_torus()),
                other => Err(Error::invalid(format!(
                    "unknown built-in surface '{}' (expected sphere or torus)",
                    String::from_utf8_lossy(other)
                ))),
            }
        });
        set_surface(h, loaded)
    })
}

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
/// at `level` (0 to 18) and whose other leaves are as coarse as possible,
/// in the cube of `octmesh_set_domain` or fitted around the
/// surface. Replaces any previous octree and mesh. Needs a surface.
/// With an octant limit (option `max_octants`), fails with
/// `OCTMESH_STATUS_LIMIT` before refining when the size estimated from the
/// surface area is more than twice the limit (the message gives the
/// estimate and the finest level that would fit), and otherwise as soon as
/// the count exceeds the limit. Collective.
#[no_mangle]
pub unsafe extern "C" fn octmesh_refine_surface(h: *mut octmesh_t, level: i32) -> octmesh_status_t {
    with_mut(h, |h| {
        let checked = level_arg(level, "level").and_then(|l| {
            let domain = h.new_tree_domain()?;
            h.index_for(&domain)?;
            Ok((l, domain))
        });
        let (level, domain) = h.agree(checked)?;
        let (comm, limit) = (h.comm.clone(), h.limit());
        let index = h.index_for(&domain)?;
        check_estimate(&comm, index, level, limit)?;
        let tree = construct_top_for_surface(comm, index, level)?.refine(limit)?;
        h.tree = Some((tree, domain));
        h.mesh = None;
        Ok(())
    })
}

/// Refines by a callback: a leaf is split while `refine(ctx, &octant)`
/// returns non-zero and its level is below `max_level` (0 to 18). Without
/// an octree, builds one from the root (in the cube of
/// `octmesh_set_domain`, else fitted around the surface,
/// else the unit cube); otherwise refines the existing leaves (which drops
/// their balance). Drops the mesh. Collective; see `octmesh_refine_fn`
/// for what the callback must satisfy.
#[no_mangle]
pub unsafe extern "C" fn octmesh_refine_callback(
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
        let split = |o: Octant| {
            let oc = octmesh_octant_t::of(o);
            // SAFETY: a C function pointer given by the caller, called with
            // its own context and a valid octant.
            unsafe { f(ctx, &oc) != 0 }
        };
        let limit = h.limit();
        match &mut h.tree {
            Some((tree, _)) => tree.refine(level, split, limit)?,
            None => {
                let domain = h.agree(h.new_tree_domain())?;
                let mut tree = construct_for_callback(h.comm.clone(), level, split)?;
                tree.refine(level, split, limit)?;
                h.tree = Some((tree, domain));
            }
        }
        h.mesh = None;
        Ok(())
    })
}

/// 2:1-balances the octree for `connect` contacts (one of
/// `octmesh_connect`). Leaves stay on their ranks; call
/// `octmesh_partition` afterwards to even out the counts. Drops the mesh.
/// Needs an octree. Fails with `OCTMESH_STATUS_LIMIT`, leaving the octree
/// as it was, when the balanced octree would exceed the octant limit.
/// Collective.
#[no_mangle]
pub unsafe extern "C" fn octmesh_balance(
    h: *mut octmesh_t,
    connect: octmesh_connect_t,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let conn = match connect {
            x if x == octmesh_connect::OCTMESH_CONNECT_FACE as i32 => Ok(Connectivity::Face),
            x if x == octmesh_connect::OCTMESH_CONNECT_EDGE as i32 => Ok(Connectivity::Edge),
            x if x == octmesh_connect::OCTMESH_CONNECT_CORNER as i32 => Ok(Connectivity::Corner),
            x => Err(Error::invalid(format!(
                "connect {x} is not one of OCTMESH_CONNECT_FACE, _EDGE, _CORNER"
            ))),
        };
        let checked = conn.and_then(|c| h.tree_or_state().map(|_| c));
        let conn = h.agree(checked)?;
        let limit = h.limit();
        let (tree, _) = h.tree_mut_or_state()?;
        tree.balance_with_limit(conn, limit)?;
        h.mesh = None;
        Ok(())
    })
}

/// Repartitions the leaves in Morton order: equal counts when `weight` is
/// NULL, else about equal sums of `weight(ctx, &leaf)` (called once per
/// local leaf). Drops the mesh. Needs an octree. Collective.
#[no_mangle]
pub unsafe extern "C" fn octmesh_partition(
    h: *mut octmesh_t,
    weight: octmesh_weight_fn,
    ctx: *mut c_void,
) -> octmesh_status_t {
    with_mut(h, |h| {
        h.agree(h.tree_or_state().map(|_| ()))?;
        let (tree, _) = h.tree_mut_or_state()?;
        match weight {
            None => tree.partition()?,
            Some(f) => tree.partition_weighted(|o: Octant| {
                let oc = octmesh_octant_t::of(o);
                // SAFETY: a C function pointer given by the caller.
                unsafe { f(ctx, &oc) }
            })?,
        };
        h.mesh = None;
        Ok(())
    })
}

fn tree_of(h: &octmesh_t) -> Result<&LinearOctree> {
    h.tree_or_state().map(|(t, _)| t)
}

/// Writes the number of leaves on this rank to `*local` and over all ranks
/// to `*global`. Needs an octree. Not collective.
#[no_mangle]
pub unsafe extern "C" fn octmesh_get_num_leaves(
    h: *const octmesh_t,
    local: *mut i64,
    global: *mut i64,
) -> octmesh_status_t {
    with_ref(h, |h| {
        non_null(local, "local")?;
        non_null(global, "global")?;
        let t = tree_of(h)?;
        write_out(local, t.local_len() as i64);
        write_out(global, t.global_len() as i64);
        Ok(())
    })
}

/// Writes this rank's leaves to `out`, which has room for the local number
/// of leaves (`octmesh_get_num_leaves`), in Morton order. Needs an
/// octree. Not collective.
#[no_mangle]
pub unsafe extern "C" fn octmesh_get_leaves(
    h: *const octmesh_t,
    out: *mut octmesh_octant_t,
) -> octmesh_status_t {
    with_ref(h, |h| {
        non_null(out, "out")?;
        let t = tree_of(h)?;
        for (i, &o) in t.leaves().iter().enumerate() {
            // SAFETY: room for local_len values (requirement of the C API).
            write_out(unsafe { out.add(i) }, octmesh_octant_t::of(o));
        }
        Ok(())
    })
}

/// Checks that the region outside the surface does not reach `point[3]`
/// (user units), a point the caller knows to be inside the body: no path of
/// face-adjacent leaves touching no triangle leads from the boundary of the
/// cube to the leaf holding it. Returns `OCTMESH_STATUS_OK` when the point
/// is sealed off, `OCTMESH_STATUS_LEAK` when it is reached (then
/// `octmesh_last_error` describes the path: its length, the first and last
/// leaves' centres and sizes, where it enters the surface's bounding box),
/// and `OCTMESH_STATUS_INVALID_ARGUMENT` when the point is outside the cube
/// or in a leaf touching the surface. Run it after refinement and balance,
/// before `octmesh_mesh` with `OCTMESH_KEEP_OUTSIDE`. Needs a surface and an
/// octree. Collective; every rank gets the same status and message.
#[no_mangle]
pub unsafe extern "C" fn octmesh_check_leak(
    h: *mut octmesh_t,
    point: *const f64,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let checked = non_null(point, "point").and_then(|_| {
            // SAFETY: non-NULL, 3 values (requirement of the C API).
            let p = unsafe { std::slice::from_raw_parts(point, 3) };
            let domain = h.tree_or_state()?.1;
            h.index_for(&domain)?;
            Ok(([p[0], p[1], p[2]], domain))
        });
        let (p, domain) = h.agree(checked)?;
        h.index_for(&domain)?;
        let (tree, _) = h.tree_or_state()?;
        let s = h
            .surface
            .as_ref()
            .ok_or_else(|| Error::new(crate::ErrorKind::Internal, "the surface vanished"))?;
        let classes = crate::classify::classify_leaves(tree.leaves(), &s.index);
        crate::leak::check_leak(tree, &classes, &domain, p, Some(&s.surface.bbox()))
    })
}
