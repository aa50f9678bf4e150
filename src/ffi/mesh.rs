//! The mesh: building it, reading its arrays, writing VTU.
//!
//! Array getters hand out pointers into memory owned by the handle. They
//! stay valid until the next call that changes or drops the mesh
//! ([`octmesh_mesh`], refinement, balance, partition) or
//! [`super::handle::octmesh_destroy`]. Local node numbering is
//! `[owned | other independent | hanging]` (see the crate's `mesh` module):
//! nodes `0..num_owned` are owned by this rank, `0..num_independent` are
//! independent, the rest hang.

use std::cell::OnceCell;
use std::ffi::{c_char, CStr};

use super::handle::{octmesh_t, MeshState};
use super::{
    inside_rule_of, inside_rule_value, non_null, octmesh_cut_rule, octmesh_cut_rule_t,
    octmesh_inside_rule_t, octmesh_keep, octmesh_keep_t, octmesh_status_t, path_arg, with_mut,
    with_ref, write_out,
};
use crate::classify::{classify_leaves_with, CutRule, InsideRule, Keep};
use crate::error::{Error, ErrorKind, Result};
use crate::geometry::diagnostics::diagnose;
use crate::io::vtu::write_mesh;
use crate::mesh::{Mesh, MeshOptions};

/// Sizes of the mesh: this rank's part and global totals (the same on
/// every rank).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct octmesh_mesh_counts_t {
    /// Elements on this rank.
    pub local_elements: i64,
    /// Nodes on this rank (independent and hanging).
    pub local_nodes: i64,
    /// Local nodes `0..num_owned` are owned by this rank.
    pub num_owned: i64,
    /// Local nodes `0..num_independent` are independent, the rest hang.
    pub num_independent: i64,
    /// Global number of this rank's first owned node.
    pub first_global: i64,
    /// Elements over all ranks.
    pub global_elements: i64,
    /// Independent nodes over all ranks (each counted once).
    pub global_independent: i64,
    /// Face-hanging nodes over all ranks.
    pub global_face_hanging: i64,
    /// Edge-hanging nodes over all ranks.
    pub global_edge_hanging: i64,
}

/// C arrays derived from the mesh, made on first request.
#[derive(Default)]
pub(crate) struct MeshArrays {
    coords: OnceCell<Vec<f64>>,
    global_ids: OnceCell<Vec<i64>>,
    owners: OnceCell<Vec<i32>>,
    sharers: OnceCell<(Vec<i32>, Vec<i32>)>,
    exchange: OnceCell<(Vec<i32>, Vec<i32>, Vec<i32>)>,
    hanging: OnceCell<(Vec<i32>, Vec<i32>)>,
    levels: OnceCell<Vec<i8>>,
}

/// Builds the mesh of the octree, replacing any previous one. `keep` (one
/// of `octmesh_keep`) selects the elements among the leaves, classified
/// against the surface (by the rule of `octmesh_set_inside_rule`); without
/// a surface only `OCTMESH_KEEP_ALL` is allowed. `rule` (one of
/// `octmesh_cut_rule`) decides for leaves touching the surface. The octree
/// must be balanced for edge or corner contacts (`octmesh_balance`).
/// Collective.
#[no_mangle]
pub unsafe extern "C" fn octmesh_mesh(
    h: *mut octmesh_t,
    keep: octmesh_keep_t,
    rule: octmesh_cut_rule_t,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let keep = match keep {
            x if x == octmesh_keep::OCTMESH_KEEP_ALL as i32 => Ok(Keep::All),
            x if x == octmesh_keep::OCTMESH_KEEP_INSIDE as i32 => Ok(Keep::Inside),
            x if x == octmesh_keep::OCTMESH_KEEP_OUTSIDE as i32 => Ok(Keep::Outside),
            x => Err(Error::invalid(format!(
                "keep {x} is not one of OCTMESH_KEEP_ALL, _INSIDE, _OUTSIDE"
            ))),
        };
        let rule = match rule {
            x if x == octmesh_cut_rule::OCTMESH_CUT_RULE_CENTER as i32 => Ok(CutRule::Center),
            x if x == octmesh_cut_rule::OCTMESH_CUT_RULE_ALL as i32 => Ok(CutRule::All),
            x if x == octmesh_cut_rule::OCTMESH_CUT_RULE_NONE as i32 => Ok(CutRule::None),
            x => Err(Error::invalid(format!(
                "rule {x} is not one of OCTMESH_CUT_RULE_CENTER, _ALL, _NONE"
            ))),
        };
        let checked = keep.and_then(|k| Ok((k, rule?, h.tree_or_state()?.1)));
        let (keep, cut_rule, domain) = h.agree(checked)?;
        // Classify against the surface mapped to the octree's cube, if there
        // is a surface (keeping all elements needs none).
        if h.surface.is_some() {
            h.index_for(&domain)?;
        }
        let (tree, _) = h.tree_or_state()?;
        let chosen = h.inside_rule;
        let classified = h.surface.as_ref().map(|s| {
            let rule = match chosen {
                InsideRule::Auto => *s
                    .auto_rule
                    .get_or_init(|| InsideRule::auto_choice(&diagnose(&s.surface)).0),
                r => r,
            };
            (classify_leaves_with(tree.leaves(), &s.index, rule), rule)
        });
        let (classes, inside_rule) = match classified {
            Some((c, r)) => (Some(c), Some(r)),
            None => (None, None),
        };
        let opts = MeshOptions { keep, cut_rule };
        let mesh = Mesh::build(tree, &domain, classes.as_deref(), &opts)?;
        h.mesh = Some(MeshState {
            mesh,
            inside_rule,
            cache: MeshArrays::default(),
        });
        Ok(())
    })
}

/// Sets how the following `octmesh_mesh` calls decide whether a leaf's
/// centre is inside the surface: one of `octmesh_inside_rule`
/// (`OCTMESH_INSIDE_RULE_AUTO` until set). Every rank must pass the same
/// rule. The current mesh is kept. Collective.
#[no_mangle]
pub unsafe extern "C" fn octmesh_set_inside_rule(
    h: *mut octmesh_t,
    rule: octmesh_inside_rule_t,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let rule = h.agree(inside_rule_of(rule))?;
        let all = h.comm.allgather_u64(inside_rule_value(rule) as u64);
        if all.iter().any(|&r| r != all[0]) {
            return Err(Error::invalid(
                "the ranks passed different inside rules to octmesh_set_inside_rule",
            ));
        }
        h.inside_rule = rule;
        Ok(())
    })
}

/// Writes to `*out` the rule the current mesh was classified with:
/// `OCTMESH_INSIDE_RULE_PARITY` or `OCTMESH_INSIDE_RULE_WINDING` (what
/// `OCTMESH_INSIDE_RULE_AUTO` chose), or `OCTMESH_INSIDE_RULE_AUTO` when it
/// was built without a surface (nothing classified). Needs a mesh. Not
/// collective.
#[no_mangle]
pub unsafe extern "C" fn octmesh_mesh_get_inside_rule(
    h: *const octmesh_t,
    out: *mut octmesh_inside_rule_t,
) -> octmesh_status_t {
    with_ref(h, |h| {
        non_null(out, "out")?;
        let rule = mesh_of(h)?.inside_rule.unwrap_or(InsideRule::Auto);
        write_out(out, inside_rule_value(rule));
        Ok(())
    })
}

fn mesh_of(h: &octmesh_t) -> Result<&MeshState> {
    h.mesh.as_ref().ok_or_else(|| {
        Error::new(
            ErrorKind::State,
            "there is no mesh: call octmesh_mesh first (after refining and balancing)",
        )
    })
}

/// Runs a pointer getter: checks `out`, finds the mesh, writes the pointer.
fn get_ptr<T>(
    h: *const octmesh_t,
    out: *mut *const T,
    f: impl FnOnce(&MeshState) -> *const T,
) -> octmesh_status_t {
    with_ref(h, |h| {
        non_null(out, "out")?;
        let m = mesh_of(h)?;
        write_out(out, f(m));
        Ok(())
    })
}

fn i32_of(v: impl IntoIterator<Item = u32>) -> Vec<i32> {
    v.into_iter().map(|x| x as i32).collect()
}

/// Writes the mesh sizes to `*out`. Needs a mesh. Not collective.
#[no_mangle]
pub unsafe extern "C" fn octmesh_mesh_get_counts(
    h: *const octmesh_t,
    out: *mut octmesh_mesh_counts_t,
) -> octmesh_status_t {
    with_ref(h, |h| {
        non_null(out, "out")?;
        let m = &mesh_of(h)?.mesh;
        let c = m.counts();
        write_out(
            out,
            octmesh_mesh_counts_t {
                local_elements: m.elements().len() as i64,
                local_nodes: m.num_nodes() as i64,
                num_owned: m.num_owned() as i64,
                num_independent: m.num_independent() as i64,
                first_global: m.first_global() as i64,
                global_elements: c.elements as i64,
                global_independent: c.independent_nodes as i64,
                global_face_hanging: c.face_hanging_nodes as i64,
                global_edge_hanging: c.edge_hanging_nodes as i64,
            },
        );
        Ok(())
    })
}

/// Sets `*out` to the connectivity: 8 local node numbers (0-based) per
/// local element, VTK hexahedron order, elements in Morton order. Needs a
/// mesh. Not collective.
#[no_mangle]
pub unsafe extern "C" fn octmesh_mesh_get_connectivity(
    h: *const octmesh_t,
    out: *mut *const i32,
) -> octmesh_status_t {
    // Local node numbers are below 2^31 (checked when meshing), so the
    // stored u32 array reads as int32 without a copy.
    get_ptr(h, out, |m| m.mesh.connectivity().as_ptr().cast::<i32>())
}

/// Sets `*out` to the node coordinates: x, y, z per local node, user
/// units. Needs a mesh. Not collective.
#[no_mangle]
pub unsafe extern "C" fn octmesh_mesh_get_coordinates(
    h: *const octmesh_t,
    out: *mut *const f64,
) -> octmesh_status_t {
    get_ptr(h, out, |m| {
        m.cache
            .coords
            .get_or_init(|| m.mesh.coordinates().into_flattened())
            .as_ptr()
    })
}

/// Sets `*out` to the global numbers (0-based) of the `num_independent`
/// independent local nodes. Needs a mesh. Not collective.
#[no_mangle]
pub unsafe extern "C" fn octmesh_mesh_get_global_ids(
    h: *const octmesh_t,
    out: *mut *const i64,
) -> octmesh_status_t {
    get_ptr(h, out, |m| {
        m.cache
            .global_ids
            .get_or_init(|| m.mesh.global_ids().iter().map(|&g| g as i64).collect())
            .as_ptr()
    })
}

/// Sets `*out` to the owner rank of each of the `num_independent`
/// independent local nodes. Needs a mesh. Not collective.
#[no_mangle]
pub unsafe extern "C" fn octmesh_mesh_get_owners(
    h: *const octmesh_t,
    out: *mut *const i32,
) -> octmesh_status_t {
    get_ptr(h, out, |m| {
        m.cache
            .owners
            .get_or_init(|| i32_of(m.mesh.owners().iter().copied()))
            .as_ptr()
    })
}

/// Sets `*offsets` (`num_independent + 1` entries) and `*ranks` to the
/// ranks using each independent local node, in CSR form: node `i` is used
/// by `ranks[offsets[i] .. offsets[i + 1]]`, sorted, this rank included; a
/// node is shared when it has more than one. Needs a mesh. Not collective.
#[no_mangle]
pub unsafe extern "C" fn octmesh_mesh_get_sharers(
    h: *const octmesh_t,
    offsets: *mut *const i32,
    ranks: *mut *const i32,
) -> octmesh_status_t {
    with_ref(h, |h| {
        non_null(offsets, "offsets")?;
        non_null(ranks, "ranks")?;
        let m = mesh_of(h)?;
        let (o, r) = m.cache.sharers.get_or_init(|| {
            let mut o = vec![0i32];
            let mut r = Vec::new();
            for i in 0..m.mesh.num_independent() {
                r.extend(m.mesh.sharers(i).into_iter().map(|x| x as i32));
                o.push(r.len() as i32);
            }
            (o, r)
        });
        write_out(offsets, o.as_ptr());
        write_out(ranks, r.as_ptr());
        Ok(())
    })
}

/// The halo-exchange lists: `*nneighbors` other ranks share nodes with this
/// one, `(*ranks)[k]` is the k-th (increasing), and it shares the local
/// nodes `(*nodes)[(*offsets)[k] .. (*offsets)[k + 1]]`, ordered by global
/// number, so both ranks of a pair list the same nodes in the same order.
/// Needs a mesh. Not collective.
#[no_mangle]
pub unsafe extern "C" fn octmesh_mesh_get_exchange(
    h: *const octmesh_t,
    nneighbors: *mut i32,
    ranks: *mut *const i32,
    offsets: *mut *const i32,
    nodes: *mut *const i32,
) -> octmesh_status_t {
    with_ref(h, |h| {
        non_null(nneighbors, "nneighbors")?;
        non_null(ranks, "ranks")?;
        non_null(offsets, "offsets")?;
        non_null(nodes, "nodes")?;
        let m = mesh_of(h)?;
        let (r, o, n) = m.cache.exchange.get_or_init(|| {
            let lists = m.mesh.exchange_lists();
            let mut r = Vec::with_capacity(lists.len());
            let mut o = vec![0i32];
            let mut n = Vec::new();
            for (rank, l) in lists {
                r.push(rank as i32);
                n.extend(l.into_iter().map(|x| x as i32));
                o.push(n.len() as i32);
            }
            (r, o, n)
        });
        write_out(nneighbors, r.len() as i32);
        write_out(ranks, r.as_ptr());
        write_out(offsets, o.as_ptr());
        write_out(nodes, n.as_ptr());
        Ok(())
    })
}

/// The hanging nodes: hanging node `k` is local node `num_independent + k`
/// (`local_nodes - num_independent` of them); `(*count)[k]` is 2 (edge-
/// hanging) or 4 (face-hanging), and its value is the mean of the
/// independent local nodes `(*deps)[4k .. 4k + count]` (weights
/// `1/count`; unused entries are -1). Needs a mesh. Not collective.
#[no_mangle]
pub unsafe extern "C" fn octmesh_mesh_get_hanging(
    h: *const octmesh_t,
    count: *mut *const i32,
    deps: *mut *const i32,
) -> octmesh_status_t {
    with_ref(h, |h| {
        non_null(count, "count")?;
        non_null(deps, "deps")?;
        let m = mesh_of(h)?;
        let (c, d) = m.cache.hanging.get_or_init(|| {
            let mesh = &m.mesh;
            let hang = (0..mesh.num_hanging()).map(|k| mesh.hanging_deps(k));
            let c = hang.clone().map(|x| x.len() as i32).collect();
            let d = hang
                .flat_map(|x| (0..4).map(move |j| x.get(j).map_or(-1, |&n| n as i32)))
                .collect();
            (c, d)
        });
        write_out(count, c.as_ptr());
        write_out(deps, d.as_ptr());
        Ok(())
    })
}

/// Sets `*out` to the class of each local element (one of
/// `octmesh_class`). Needs a mesh. Not collective.
#[no_mangle]
pub unsafe extern "C" fn octmesh_mesh_get_element_class(
    h: *const octmesh_t,
    out: *mut *const i8,
) -> octmesh_status_t {
    get_ptr(h, out, |m| m.mesh.element_class().as_ptr().cast::<i8>())
}

/// Sets `*out` to the octree level of each local element. Needs a mesh.
/// Not collective.
#[no_mangle]
pub unsafe extern "C" fn octmesh_mesh_get_element_level(
    h: *const octmesh_t,
    out: *mut *const i8,
) -> octmesh_status_t {
    get_ptr(h, out, |m| {
        m.cache
            .levels
            .get_or_init(|| m.mesh.elements().iter().map(|e| e.level() as i8).collect())
            .as_ptr()
    })
}

/// Writes the mesh as one binary VTU file per rank (`NAME_<rank>.vtu`
/// beside the PVTU) and the PVTU `pvtu` (a path ending in `.pvtu`) on rank
/// 0. Cell data: level, class, rank; point data: global id (-1 when
/// hanging), hanging kind. Needs a mesh. Collective. The same as
/// `octmesh_mesh_write_vtu_fields` with no fields.
#[no_mangle]
pub unsafe extern "C" fn octmesh_mesh_write_vtu(
    h: *mut octmesh_t,
    pvtu: *const c_char,
) -> octmesh_status_t {
    // SAFETY: no fields, so no field pointer is read.
    unsafe { octmesh_mesh_write_vtu_fields(h, pvtu, 0, std::ptr::null(), std::ptr::null()) }
}

/// Reads the `nfields` caller fields of `octmesh_mesh_write_vtu_fields`,
/// `nodes` values each.
///
/// # Safety
/// As documented for `octmesh_mesh_write_vtu_fields`.
unsafe fn field_args<'a>(
    nfields: i32,
    names: *const *const c_char,
    values: *const *const f64,
    nodes: usize,
) -> Result<Vec<(&'a str, &'a [f64])>> {
    let n = usize::try_from(nfields)
        .map_err(|_| Error::invalid(format!("nfields is {nfields}, must be at least 0")))?;
    if n == 0 {
        return Ok(Vec::new());
    }
    non_null(names, "names")?;
    non_null(values, "values")?;
    // SAFETY: non-NULL and `nfields` entries long (requirement of the API).
    let (names, values) = unsafe {
        (
            std::slice::from_raw_parts(names, n),
            std::slice::from_raw_parts(values, n),
        )
    };
    let mut out = Vec::with_capacity(n);
    for k in 0..n {
        non_null(names[k], &format!("names[{k}]"))?;
        // SAFETY: non-NULL and NUL-terminated (requirement of the API).
        let name = unsafe { CStr::from_ptr(names[k]) }
            .to_str()
            .map_err(|_| Error::invalid(format!("names[{k}] is not UTF-8")))?;
        let v: &[f64] = if nodes == 0 {
            &[]
        } else {
            non_null(values[k], &format!("values[{k}]"))?;
            // SAFETY: non-NULL and `nodes` values long (requirement of the API).
            unsafe { std::slice::from_raw_parts(values[k], nodes) }
        };
        out.push((name, v));
    }
    Ok(out)
}

/// Writes the mesh like `octmesh_mesh_write_vtu`, with `nfields` caller
/// fields (a solution, an error, ...) added as point data: field `k` is
/// called `names[k]` (a non-empty UTF-8 string without control characters,
/// distinct from the other names and from `global_id` and `hanging`) and
/// `values[k]` points to `local_nodes` doubles, one per local node in the
/// mesh's node order, hanging nodes included (a hanging node's value is
/// usually the mean of its dependencies, see `octmesh_mesh_get_hanging`).
/// They are written as `Float64` arrays. `nfields` may be 0, and `names`
/// and `values` are then not read (they may be NULL); `values[k]` may be
/// NULL on a rank with no nodes. Every rank must pass the same names in the
/// same order. The arrays are only read during the call. Needs a mesh.
/// Collective.
#[no_mangle]
pub unsafe extern "C" fn octmesh_mesh_write_vtu_fields(
    h: *mut octmesh_t,
    pvtu: *const c_char,
    nfields: i32,
    names: *const *const c_char,
    values: *const *const f64,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let checked = path_arg(pvtu, "pvtu").and_then(|p| {
            let nodes = mesh_of(h)?.mesh.num_nodes();
            // SAFETY: the pointers are the caller's, as documented above.
            let fields = unsafe { field_args(nfields, names, values, nodes) }?;
            Ok((p, fields))
        });
        let (path, fields) = h.agree(checked)?;
        write_mesh(&*h.comm, &path, &mesh_of(h)?.mesh, &fields).map(|_| ())
    })
}
