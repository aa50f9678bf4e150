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
use std::ffi::c_char;

use super::handle::octmesh_t;
use super::{
    non_null, octmesh_cut_rule_t, octmesh_gloidx_t, octmesh_inside_rule_t, octmesh_keep_t,
    octmesh_locidx_t, octmesh_status_t, path_arg, slice_arg, str_arg, with_mut, with_ref,
    write_out, FromC,
};
use crate::classify::{CutRule, InsideRule, Keep};
use crate::error::{Error, ErrorKind, Result};
use crate::mesh::Mesh;

/// Sizes of the mesh: this rank's part and global totals (the same on
/// every rank).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct octmesh_mesh_counts_t {
    /// Elements on this rank.
    pub local_elements: octmesh_locidx_t,
    /// Nodes on this rank (independent and hanging).
    pub local_nodes: octmesh_locidx_t,
    /// Local nodes `0..num_owned` are owned by this rank.
    pub num_owned: octmesh_locidx_t,
    /// Local nodes `0..num_independent` are independent, the rest hang.
    pub num_independent: octmesh_locidx_t,
    /// Global number of this rank's first owned node.
    pub first_global: octmesh_gloidx_t,
    /// Elements over all ranks.
    pub global_elements: octmesh_gloidx_t,
    /// Independent nodes over all ranks (each counted once).
    pub global_independent: octmesh_gloidx_t,
    /// Face-hanging nodes over all ranks.
    pub global_face_hanging: octmesh_gloidx_t,
    /// Edge-hanging nodes over all ranks.
    pub global_edge_hanging: octmesh_gloidx_t,
}

/// C arrays derived from the mesh, made on first request.
#[derive(Default)]
pub(crate) struct MeshArrays {
    coords: OnceCell<Vec<f64>>,
    global_ids: OnceCell<Vec<octmesh_gloidx_t>>,
    owners: OnceCell<Vec<i32>>,
    sharers: OnceCell<(Vec<i32>, Vec<i32>)>,
    exchange: OnceCell<(Vec<i32>, Vec<i32>, Vec<i32>)>,
    hanging: OnceCell<(Vec<i32>, Vec<i32>)>,
    levels: OnceCell<Vec<i8>>,
    zones: OnceCell<Vec<i32>>,
    zone_names: OnceCell<Vec<std::ffi::CString>>,
    /// The faces' arrays ([`super::faces`]).
    pub(crate) faces: super::faces::FaceCells,
}

/// Builds the mesh of the octree, replacing any previous one. The elements
/// are the leaves `keep` selects, classified against the surface by the
/// rule of `octmesh_mesh_set_inside_rule`; without a surface only
/// `OCTMESH_KEEP_ALL` is allowed. The octree must be balanced for edge or
/// corner contacts (`octmesh_octree_balance`). Collective.
///
/// \param[in] h     the handle
/// \param[in] keep  one of `octmesh_keep_t`
/// \param[in] rule  for leaves touching the surface: one of
///                  `octmesh_cut_rule_t`
#[no_mangle]
pub extern "C" fn octmesh_mesh_build(
    h: *mut octmesh_t,
    keep: octmesh_keep_t,
    rule: octmesh_cut_rule_t,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let checked = Keep::from_c(keep).and_then(|k| Ok((k, CutRule::from_c(rule)?)));
        let (keep, cut_rule) = h.agree(checked)?;
        h.session.build_mesh(keep, cut_rule)
    })
}

/// Sets how the following `octmesh_mesh_build` calls decide whether a
/// leaf's centre is inside the surface (`OCTMESH_INSIDE_RULE_AUTO` until
/// set). Every rank must pass the same rule. The current mesh is kept.
/// Collective.
///
/// \param[in] h     the handle
/// \param[in] rule  one of `octmesh_inside_rule_t`
#[no_mangle]
pub extern "C" fn octmesh_mesh_set_inside_rule(
    h: *mut octmesh_t,
    rule: octmesh_inside_rule_t,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let rule = h.agree(InsideRule::from_c(rule))?;
        let all = h.comm.allgather_u64(rule.to_c() as u64);
        if all.iter().any(|&r| r != all[0]) {
            return Err(Error::invalid(
                "the ranks passed different inside rules to octmesh_mesh_set_inside_rule",
            ));
        }
        h.session.set_inside_rule(rule);
        Ok(())
    })
}

/// Sets whether the following `octmesh_mesh_build` calls give every
/// element a zone (off until set), like the command's `--zones`: `inside`
/// (zone 0) or `outside` (zone 1) of the surface by the element's centre,
/// or the zone named by the last refinement region holding the centre
/// (`octmesh_octree_refine_regions` with `:zone=NAME`). Zones need
/// `OCTMESH_KEEP_ALL`; `octmesh_mesh_write_openfoam` then writes cellZones
/// and faceZones, `octmesh_mesh_write_gmsh` a physical volume per zone.
/// Every rank must pass the same value. The current mesh is kept.
/// Collective.
///
/// \param[in] h   the handle
/// \param[in] on  whether meshes get zones
#[no_mangle]
pub extern "C" fn octmesh_mesh_set_zones(h: *mut octmesh_t, on: bool) -> octmesh_status_t {
    with_mut(h, |h| {
        let all = h.comm.allgather_u64(u64::from(on));
        if all.iter().any(|&r| r != all[0]) {
            return Err(Error::invalid(
                "the ranks passed different values to octmesh_mesh_set_zones",
            ));
        }
        h.session.config_mut().mesh.zones = on;
        Ok(())
    })
}

/// Sets whether `octmesh_mesh_write_gmsh`, `octmesh_mesh_write_abaqus`,
/// `octmesh_mesh_write_exodus`, `octmesh_mesh_write_cgns` and
/// `octmesh_mesh_write_openfoam` (then one serial case written by rank 0)
/// write the current mesh's kept region as a conforming all-hexahedral mesh (off
/// until set), like the command's `--conforming`: no hanging nodes, every
/// inner face shared whole by two elements, the patches and zones of the
/// mesh. The mesh itself, its getters and the other writers keep the
/// hanging-node mesh. Where finer cells wrap around an edge or a corner
/// of coarser ones, which no template covers yet, the conforming mesh
/// refines the coarser cells (up to the finest level of the octree).
/// Every rank must pass the same value.
/// Collective.
///
/// \param[in] h   the handle
/// \param[in] on  whether the single-file meshes are conforming
#[no_mangle]
pub extern "C" fn octmesh_mesh_set_conforming(h: *mut octmesh_t, on: bool) -> octmesh_status_t {
    with_mut(h, |h| {
        let all = h.comm.allgather_u64(u64::from(on));
        if all.iter().any(|&r| r != all[0]) {
            return Err(Error::invalid(
                "the ranks passed different values to octmesh_mesh_set_conforming",
            ));
        }
        h.session.config_mut().mesh.conforming = on;
        Ok(())
    })
}

/// Sets `*num_zones` to the number of zones and `*zones` to the zone of
/// each local element (`0 .. num_zones - 1`; names by
/// `octmesh_mesh_get_zone_name`). Needs a mesh built with zones
/// (`octmesh_mesh_set_zones`). Not collective.
///
/// \param[in]  h          the handle
/// \param[out] num_zones  the number of zones (the same on every rank)
/// \param[out] zones      local_elements zone indices, owned by the handle
#[no_mangle]
pub extern "C" fn octmesh_mesh_get_zones(
    h: *const octmesh_t,
    num_zones: *mut octmesh_locidx_t,
    zones: *mut *const octmesh_locidx_t,
) -> octmesh_status_t {
    with_ref(h, |h| {
        non_null(num_zones, "num_zones")?;
        non_null(zones, "zones")?;
        let z = zones_of(mesh_of(h)?)?;
        let v = h
            .arrays
            .zones
            .get_or_init(|| z.of_elements().iter().map(|&k| k as i32).collect());
        write_out(num_zones, z.names().len() as octmesh_locidx_t);
        write_out(zones, v.as_ptr());
        Ok(())
    })
}

/// Sets `*name` to the name of zone `zone` (`inside`, `outside`, then the
/// regions' zones), NUL-terminated, owned by the handle. Needs a mesh
/// built with zones. Not collective.
///
/// \param[in]  h     the handle
/// \param[in]  zone  0 .. num_zones - 1
/// \param[out] name  the name
#[no_mangle]
pub extern "C" fn octmesh_mesh_get_zone_name(
    h: *const octmesh_t,
    zone: octmesh_locidx_t,
    name: *mut *const c_char,
) -> octmesh_status_t {
    with_ref(h, |h| {
        non_null(name, "name")?;
        let z = zones_of(mesh_of(h)?)?;
        let names = h
            .arrays
            .zone_names
            .get_or_init(|| z.names().iter().map(|n| super::c_string(n)).collect());
        let k = usize::try_from(zone)
            .ok()
            .filter(|&k| k < names.len())
            .ok_or_else(|| {
                Error::invalid(format!(
                    "zone {zone} does not exist: there are {} zones",
                    names.len()
                ))
            })?;
        write_out(name, names[k].as_ptr());
        Ok(())
    })
}

fn zones_of(m: &Mesh) -> Result<&crate::mesh::Zones> {
    m.zones().ok_or_else(|| {
        Error::new(
            ErrorKind::State,
            "the mesh has no zones: call octmesh_mesh_set_zones(h, true) before \
             octmesh_mesh_build (with OCTMESH_KEEP_ALL)",
        )
    })
}

/// The rule the current mesh was classified with:
/// `OCTMESH_INSIDE_RULE_PARITY` or `OCTMESH_INSIDE_RULE_WINDING` (what
/// `OCTMESH_INSIDE_RULE_AUTO` chose), or `OCTMESH_INSIDE_RULE_AUTO` when it
/// was built without a surface (nothing classified). Needs a mesh. Not
/// collective.
///
/// \param[in]  h    the handle
/// \param[out] out  one of `octmesh_inside_rule_t`
#[no_mangle]
pub extern "C" fn octmesh_mesh_get_inside_rule(
    h: *const octmesh_t,
    out: *mut octmesh_inside_rule_t,
) -> octmesh_status_t {
    with_ref(h, |h| {
        non_null(out, "out")?;
        mesh_of(h)?;
        let rule = h.session.classified_with().unwrap_or(InsideRule::Auto);
        write_out(out, rule.to_c());
        Ok(())
    })
}

fn mesh_of(h: &octmesh_t) -> Result<&Mesh> {
    h.session.mesh().ok_or_else(|| {
        Error::new(
            ErrorKind::State,
            "there is no mesh: call octmesh_mesh_build first (after refining and balancing)",
        )
    })
}

/// Runs a pointer getter: checks `out`, finds the mesh, writes the pointer.
fn get_ptr<T>(
    h: *const octmesh_t,
    out: *mut *const T,
    f: impl FnOnce(&Mesh, &MeshArrays) -> *const T,
) -> octmesh_status_t {
    with_ref(h, |h| {
        non_null(out, "out")?;
        let m = mesh_of(h)?;
        write_out(out, f(m, &h.arrays));
        Ok(())
    })
}

fn i32_of(v: impl IntoIterator<Item = u32>) -> Vec<i32> {
    v.into_iter().map(|x| x as i32).collect()
}

/// Writes the mesh sizes to `*out`. Needs a mesh. Not collective.
///
/// \param[in]  h    the handle
/// \param[out] out  the counts
#[no_mangle]
pub extern "C" fn octmesh_mesh_get_counts(
    h: *const octmesh_t,
    out: *mut octmesh_mesh_counts_t,
) -> octmesh_status_t {
    with_ref(h, |h| {
        non_null(out, "out")?;
        let m = mesh_of(h)?;
        let c = m.counts();
        write_out(
            out,
            octmesh_mesh_counts_t {
                local_elements: m.elements().len() as octmesh_locidx_t,
                local_nodes: m.num_nodes() as octmesh_locidx_t,
                num_owned: m.num_owned() as octmesh_locidx_t,
                num_independent: m.num_independent() as octmesh_locidx_t,
                first_global: m.first_global() as octmesh_gloidx_t,
                global_elements: c.elements as octmesh_gloidx_t,
                global_independent: c.independent_nodes as octmesh_gloidx_t,
                global_face_hanging: c.face_hanging_nodes as octmesh_gloidx_t,
                global_edge_hanging: c.edge_hanging_nodes as octmesh_gloidx_t,
            },
        );
        Ok(())
    })
}

/// Sets `*out` to the connectivity: 8 local node numbers (0-based) per
/// local element, VTK hexahedron order, elements in Morton order. Needs a
/// mesh. Not collective.
///
/// ```text
///   VTK hexahedron corner order (x right, y back, z up):
///
///        7 -------- 6
///       /|         /|
///      4 -------- 5 |
///      | |        | |
///      | 3 -------|-2
///      |/         |/
///      0 -------- 1
///
///   0 (x0,y0,z0)  1 (x1,y0,z0)  2 (x1,y1,z0)  3 (x0,y1,z0)
///   4 (x0,y0,z1)  5 (x1,y0,z1)  6 (x1,y1,z1)  7 (x0,y1,z1)
/// ```
///
/// \param[in]  h    the handle
/// \param[out] out  8 * local_elements local node numbers, owned by the
///                  handle
#[no_mangle]
pub extern "C" fn octmesh_mesh_get_connectivity(
    h: *const octmesh_t,
    out: *mut *const octmesh_locidx_t,
) -> octmesh_status_t {
    // Local node numbers are below 2^31 (checked when meshing), so the
    // stored u32 array reads as octmesh_locidx_t without a copy.
    get_ptr(h, out, |m, _| {
        m.connectivity().as_ptr().cast::<octmesh_locidx_t>()
    })
}

/// Sets `*out` to the node coordinates: x, y, z per local node, user
/// units. Needs a mesh. Not collective.
///
/// \param[in]  h    the handle
/// \param[out] out  3 * local_nodes doubles (x, y, z per node, user
///                  units), owned by the handle
#[no_mangle]
pub extern "C" fn octmesh_mesh_get_coordinates(
    h: *const octmesh_t,
    out: *mut *const f64,
) -> octmesh_status_t {
    get_ptr(h, out, |m, a| {
        a.coords
            .get_or_init(|| m.coordinates().into_flattened())
            .as_ptr()
    })
}

/// Sets `*out` to the global numbers (0-based) of the `num_independent`
/// independent local nodes. Needs a mesh. Not collective.
///
/// \param[in]  h    the handle
/// \param[out] out  num_independent global numbers (0-based), owned by the
///                  handle
#[no_mangle]
pub extern "C" fn octmesh_mesh_get_global_ids(
    h: *const octmesh_t,
    out: *mut *const octmesh_gloidx_t,
) -> octmesh_status_t {
    get_ptr(h, out, |m, a| {
        a.global_ids
            .get_or_init(|| {
                m.global_ids()
                    .iter()
                    .map(|&g| g as octmesh_gloidx_t)
                    .collect()
            })
            .as_ptr()
    })
}

/// Sets `*out` to the owner rank of each of the `num_independent`
/// independent local nodes. Needs a mesh. Not collective.
///
/// \param[in]  h      the handle
/// \param[out] ranks  num_independent owner ranks, owned by the handle
#[no_mangle]
pub extern "C" fn octmesh_mesh_get_owners(
    h: *const octmesh_t,
    ranks: *mut *const i32,
) -> octmesh_status_t {
    get_ptr(h, ranks, |m, a| {
        a.owners
            .get_or_init(|| i32_of(m.owners().iter().copied()))
            .as_ptr()
    })
}

/// Sets `*offsets` (`num_independent + 1` entries) and `*ranks` to the
/// ranks using each independent local node, in CSR form: node `i` is used
/// by `ranks[offsets[i] .. offsets[i + 1]]`, sorted, this rank included; a
/// node is shared when it has more than one. Needs a mesh. Not collective.
///
/// \param[in]  h        the handle
/// \param[out] offsets  num_independent + 1 offsets into `ranks`, owned by
///                      the handle
/// \param[out] ranks    the ranks using each node, sorted, owned by the
///                      handle
#[no_mangle]
pub extern "C" fn octmesh_mesh_get_sharers(
    h: *const octmesh_t,
    offsets: *mut *const octmesh_locidx_t,
    ranks: *mut *const i32,
) -> octmesh_status_t {
    with_ref(h, |h| {
        non_null(offsets, "offsets")?;
        non_null(ranks, "ranks")?;
        let m = mesh_of(h)?;
        let (o, r) = h.arrays.sharers.get_or_init(|| {
            let mut o = vec![0i32];
            let mut r = Vec::new();
            for i in 0..m.num_independent() {
                r.extend(m.sharers(i).into_iter().map(|x| x as i32));
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
///
/// \param[in]  h           the handle
/// \param[out] nneighbors  the number of neighbour ranks
/// \param[out] ranks       the neighbour ranks, increasing, owned by the
///                         handle
/// \param[out] offsets     nneighbors + 1 offsets into `nodes`, owned by
///                         the handle
/// \param[out] nodes       local node numbers shared with each neighbour,
///                         by increasing global number, owned by the handle
#[no_mangle]
pub extern "C" fn octmesh_mesh_get_exchange(
    h: *const octmesh_t,
    nneighbors: *mut octmesh_locidx_t,
    ranks: *mut *const i32,
    offsets: *mut *const octmesh_locidx_t,
    nodes: *mut *const octmesh_locidx_t,
) -> octmesh_status_t {
    with_ref(h, |h| {
        non_null(nneighbors, "nneighbors")?;
        non_null(ranks, "ranks")?;
        non_null(offsets, "offsets")?;
        non_null(nodes, "nodes")?;
        let m = mesh_of(h)?;
        let (r, o, n) = h.arrays.exchange.get_or_init(|| {
            let lists = m.exchange_lists();
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
        write_out(nneighbors, r.len() as octmesh_locidx_t);
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
///
/// ```text
///   a face-hanging node (h) at the centre of a coarse face depends on the
///   face's 4 corners; an edge-hanging node (e) at the middle of a coarse
///   edge on the edge's 2 ends:
///
///     d2 -------- d3          d0 ---- e ---- d1
///      |          |
///      |    h     |           e = (d0 + d1) / 2
///      |          |
///     d0 -------- d1          h = (d0 + d1 + d2 + d3) / 4
/// ```
///
/// \param[in]  h      the handle
/// \param[out] count  per hanging node, 2 or 4, owned by the handle
/// \param[out] deps   4 per hanging node: its independent local nodes, -1
///                    for unused entries, owned by the handle
#[no_mangle]
pub extern "C" fn octmesh_mesh_get_hanging(
    h: *const octmesh_t,
    count: *mut *const octmesh_locidx_t,
    deps: *mut *const octmesh_locidx_t,
) -> octmesh_status_t {
    with_ref(h, |h| {
        non_null(count, "count")?;
        non_null(deps, "deps")?;
        let m = mesh_of(h)?;
        let (c, d) = h.arrays.hanging.get_or_init(|| {
            let mesh = m;
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
/// `octmesh_class_t`, one byte each). Needs a mesh. Not collective.
///
/// \param[in]  h    the handle
/// \param[out] out  local_elements classes (`octmesh_class_t`), owned by
///                  the handle
#[no_mangle]
pub extern "C" fn octmesh_mesh_get_element_class(
    h: *const octmesh_t,
    out: *mut *const i8,
) -> octmesh_status_t {
    get_ptr(h, out, |m, _| m.element_class().as_ptr().cast::<i8>())
}

/// Sets `*out` to the level of each local element, counted from the root
/// cells (in a cube, the octree level). Needs a mesh. Not collective.
///
/// \param[in]  h    the handle
/// \param[out] out  local_elements levels, owned by the handle
#[no_mangle]
pub extern "C" fn octmesh_mesh_get_element_level(
    h: *const octmesh_t,
    out: *mut *const i8,
) -> octmesh_status_t {
    get_ptr(h, out, |m, a| {
        let k = m.domain().brick.level();
        a.levels
            .get_or_init(|| m.elements().iter().map(|e| (e.level() - k) as i8).collect())
            .as_ptr()
    })
}

/// Writes the mesh as one binary VTU file per rank (`NAME_<rank>.vtu`
/// beside the PVTU) and the PVTU `pvtu` (a path ending in `.pvtu`) on rank
/// 0. Cell data: level, class, rank; point data: global id (-1 when
/// hanging), hanging kind. Needs a mesh. Collective. The same as
/// `octmesh_mesh_write_vtu_fields` with no fields.
///
/// \param[in] h     the handle
/// \param[in] pvtu  the PVTU path, ending in `.pvtu`, NUL-terminated
#[no_mangle]
pub extern "C" fn octmesh_mesh_write_vtu(
    h: *mut octmesh_t,
    pvtu: *const c_char,
) -> octmesh_status_t {
    octmesh_mesh_write_vtu_fields(h, pvtu, 0, std::ptr::null(), std::ptr::null())
}

/// Writes the mesh as one Gmsh MSH 4.1 file (ASCII), like the command's
/// `--gmsh`: a physical surface per patch with boundary faces (named by
/// `octmesh_mesh_rename_patch`), the physical volume `volume` (one per
/// zone on a mesh with zones), the
/// hanging nodes as plain nodes with their constraints in a
/// `$HangingNodes` section (docs/formats.md). The mesh is gathered on rank
/// 0, which writes the file: the same bytes on any number of ranks. Needs
/// a mesh. Collective.
///
/// \param[in] h     the handle
/// \param[in] path  the file, NUL-terminated (same on every rank)
#[no_mangle]
pub extern "C" fn octmesh_mesh_write_gmsh(
    h: *mut octmesh_t,
    path: *const c_char,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let path = h.agree(path_arg(path, "path"))?;
        h.session.write_gmsh(&path)
    })
}

/// Writes the mesh as one Abaqus/CalculiX input file, like the command's
/// `--abaqus`: `*NODE`, `*ELEMENT, TYPE=C3D8`, per patch with boundary
/// faces an `*NSET`, `*ELSET` and `*SURFACE, TYPE=ELEMENT`, and for every
/// hanging node and each of the 3 displacement degrees of freedom an
/// `*EQUATION` (docs/formats.md). The mesh is gathered on rank 0, which
/// writes the file: the same bytes on any number of ranks. Needs a mesh.
/// Collective.
///
/// \param[in] h     the handle
/// \param[in] path  the file, NUL-terminated (same on every rank)
#[no_mangle]
pub extern "C" fn octmesh_mesh_write_abaqus(
    h: *mut octmesh_t,
    path: *const c_char,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let path = h.agree(path_arg(path, "path"))?;
        h.session.write_abaqus(&path)
    })
}

/// Writes the mesh as one Exodus II file through the netCDF library, like
/// the command's `--exodus`: element block `volume` (HEX8), per patch with
/// boundary faces a side set and a node set named after it (names from
/// `octmesh_mesh_rename_patch`), and the hanging nodes as plain nodes with
/// their constraints in the node set `hanging` and the variables
/// `hanging_nodes`, `hanging_parents`, `hanging_weights`
/// (docs/formats.md). The mesh is gathered on rank 0, which writes the
/// file: the same bytes on any number of ranks. Needs a mesh. Collective.
///
/// \param[in] h     the handle
/// \param[in] path  the file, NUL-terminated (same on every rank)
#[no_mangle]
pub extern "C" fn octmesh_mesh_write_exodus(
    h: *mut octmesh_t,
    path: *const c_char,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let path = h.agree(path_arg(path, "path"))?;
        h.session.write_exodus(&path)
    })
}

/// Writes the mesh as one CGNS file (HDF5) through the CGNS library, like
/// the command's `--cgns`: one unstructured zone `volume` of HEXA_8
/// elements, per patch with boundary faces a QUAD_4 section, a boundary
/// condition and a family named after it, and the hanging nodes as plain
/// nodes with their constraints in the zone's user data `HangingNodes`
/// (docs/formats.md). The mesh is gathered on rank 0, which writes the
/// file: the same content on any number of ranks. Needs a mesh.
/// Collective.
///
/// \param[in] h     the handle
/// \param[in] path  the file, NUL-terminated (same on every rank)
#[no_mangle]
pub extern "C" fn octmesh_mesh_write_cgns(
    h: *mut octmesh_t,
    path: *const c_char,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let path = h.agree(path_arg(path, "path"))?;
        h.session.write_cgns(&path)
    })
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
    // SAFETY: `nfields` entries each (requirement of the API).
    let (names, values) = unsafe {
        (
            slice_arg(names, n, "names")?,
            slice_arg(values, n, "values")?,
        )
    };
    let mut out = Vec::with_capacity(n);
    for k in 0..n {
        let name = str_arg(names[k], &format!("names[{k}]"))?;
        let v: &[f64] = if nodes == 0 {
            &[]
        } else {
            // SAFETY: `nodes` values (requirement of the API).
            unsafe { slice_arg(values[k], nodes, &format!("values[{k}]")) }?
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
///
/// \param[in] h        the handle
/// \param[in] pvtu     the PVTU path, ending in `.pvtu`, NUL-terminated
/// \param[in] nfields  the number of fields, >= 0
/// \param[in] names    nfields names, NUL-terminated
/// \param[in] values   nfields arrays of local_nodes doubles
#[no_mangle]
pub extern "C" fn octmesh_mesh_write_vtu_fields(
    h: *mut octmesh_t,
    pvtu: *const c_char,
    nfields: octmesh_locidx_t,
    names: *const *const c_char,
    values: *const *const f64,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let checked = path_arg(pvtu, "pvtu").and_then(|p| {
            let nodes = mesh_of(h)?.num_nodes();
            // SAFETY: the pointers are the caller's, as documented above.
            let fields = unsafe { field_args(nfields, names, values, nodes) }?;
            Ok((p, fields))
        });
        let (path, fields) = h.agree(checked)?;
        h.session.write_vtu(&path, &fields)
    })
}
