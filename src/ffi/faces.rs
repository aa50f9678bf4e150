//! Finite-volume faces, boundary patches, the cell halo, finite-element
//! boundaries, and OpenFOAM cases.
//!
//! `octmesh_mesh_build_faces` (collective) extracts them from the current
//! mesh; the getters then hand out arrays owned by the handle, valid until
//! the mesh changes, the patches are renamed (names only) or the handle is
//! destroyed. Units are the user's (lengths, areas, volumes); indices are
//! 0-based.
//!
//! Faces of a rank come in three consecutive groups (see the crate's
//! `mesh::faces` module):
//!
//! ```text
//!   0            num_internal     patch_offsets[num_patches]      num_faces
//!   | internal    | boundary, by patch      | shared with other ranks, |
//!   | owner <     | patch p: patch_offsets  | by rank: face_offsets of |
//!   | neighbour   | [p] .. [p + 1]          | octmesh_cell_halo_t      |
//! ```
//!
//! A face's normal points from its owner (a local element) to the other
//! side. Where a coarse element meets finer ones its face is split into
//! the fine faces, so a cell can have more than six faces.

use std::cell::OnceCell;
use std::ffi::{c_char, CString};

use super::handle::octmesh_t;
use super::{
    non_null, octmesh_foam_format_t, octmesh_gloidx_t, octmesh_locidx_t, octmesh_status_t,
    path_arg, str_arg, with_mut, with_ref, write_out, FromC,
};
use crate::error::{Error, ErrorKind, Result};
use crate::io::openfoam::FoamFormat;
use crate::mesh::{Boundary, Faces, Mesh, Other};

/// The finite-volume view of this rank's part of the mesh (arrays owned
/// by the handle). Cells are the local elements, in the mesh's order.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct octmesh_faces_t {
    /// Faces of this rank: internal, boundary and shared.
    pub num_faces: octmesh_locidx_t,
    /// The first `num_internal` faces are between two local elements.
    pub num_internal: octmesh_locidx_t,
    /// Patches: 0..6 the sides `xmin xmax ymin ymax zmin zmax`, 6 the
    /// surface (`octmesh_mesh_get_patch_name`).
    pub num_patches: octmesh_locidx_t,
    /// Owner element of each face (local, 0-based).
    pub owner: *const octmesh_locidx_t,
    /// Other side of each face: the local element for internal faces
    /// (greater than the owner), `-1 - patch` for boundary faces, and the
    /// index into `halo_global`/`halo_rank` of `octmesh_cell_halo_t` for
    /// faces shared with another rank.
    pub neighbour: *const octmesh_locidx_t,
    /// Area of each face.
    pub area: *const f64,
    /// Centroid of each face, x y z.
    pub centre: *const f64,
    /// Unit normal of each face, x y z, from the owner to the other side.
    pub normal: *const f64,
    /// `num_patches + 1` face indices: patch `p`'s boundary faces are
    /// `patch_offsets[p] .. patch_offsets[p + 1]`.
    pub patch_offsets: *const octmesh_locidx_t,
    /// Centre of each local element, x y z.
    pub cell_centre: *const f64,
    /// Volume of each local element.
    pub cell_volume: *const f64,
    /// Global number of local element 0: local element `e` is global
    /// element `first_element + e` (contiguous per rank, in rank order).
    pub first_element: octmesh_gloidx_t,
    /// Elements over all ranks.
    pub global_elements: octmesh_gloidx_t,
}

/// What a cell-centred code needs to exchange its unknowns with the other
/// ranks (arrays owned by the handle).
///
/// ```text
///   for k in 0 .. num_ranks:        with rank ranks[k]
///     send  the values of local elements send[send_offsets[k] .. send_offsets[k+1]]
///     recv  into halo elements        recv[recv_offsets[k] .. recv_offsets[k+1]]
/// ```
///
/// Both ranks of a pair list the same elements in the same order (by
/// global element number), so plain `MPI_Isend`/`MPI_Irecv` of the packed
/// values match.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct octmesh_cell_halo_t {
    /// Halo elements: elements of other ranks touching a local element.
    pub num_halo: octmesh_locidx_t,
    /// Global element number of each halo element.
    pub halo_global: *const octmesh_gloidx_t,
    /// Owner rank of each halo element.
    pub halo_rank: *const i32,
    /// Neighbour ranks (sharing at least one face), increasing.
    pub num_ranks: octmesh_locidx_t,
    /// The neighbour ranks.
    pub ranks: *const i32,
    /// `num_ranks + 1` face indices: the faces shared with `ranks[k]` are
    /// `face_offsets[k] .. face_offsets[k + 1]`, in the same order on
    /// both ranks.
    pub face_offsets: *const octmesh_locidx_t,
    /// `num_ranks + 1` offsets into `send`.
    pub send_offsets: *const octmesh_locidx_t,
    /// Local elements to send, per neighbour rank.
    pub send: *const octmesh_locidx_t,
    /// `num_ranks + 1` offsets into `recv`.
    pub recv_offsets: *const octmesh_locidx_t,
    /// Halo elements (indices into `halo_global`) received, per neighbour
    /// rank.
    pub recv: *const octmesh_locidx_t,
}

/// The finite-element boundary of this rank's part of the mesh (arrays
/// owned by the handle).
///
/// ```text
///   local faces of an element (p4est order):
///              z
///              |   3 (+y)
///              |  /            face  normal
///         +----5----+           0     -x
///        /|   /    /|           1     +x
///       +---------+ |           2     -y
///       | |       | 1 --- x     3     +y
///       0 |       | |           4     -z
///       | +------2--+           5     +z
///       |/        |/
///       +----4----+
/// ```
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct octmesh_boundary_t {
    /// Element faces wholly or partly on the boundary.
    pub num_faces: octmesh_locidx_t,
    /// `3 * num_faces` values: local element, local face (0..6, above),
    /// patch; sorted by element then face.
    pub faces: *const octmesh_locidx_t,
    /// `local_nodes + 1` offsets into `node_patches`.
    pub node_offsets: *const octmesh_locidx_t,
    /// The patches of each local node (hanging nodes included), increasing:
    /// node `n` lies on `node_patches[node_offsets[n] .. node_offsets[n+1]]`
    /// (none off the boundary). Every rank holding a node gives it the
    /// same patches.
    pub node_patches: *const octmesh_locidx_t,
}

/// Arrays of the faces, made on first request.
struct FvArrays {
    owner: Vec<i32>,
    neighbour: Vec<i32>,
    area: Vec<f64>,
    centre: Vec<f64>,
    normal: Vec<f64>,
    patch_offsets: Vec<i32>,
    cell_centre: Vec<f64>,
    cell_volume: Vec<f64>,
}

/// Arrays of the cell halo, made on first request.
struct HaloArrays {
    global: Vec<i64>,
    rank: Vec<i32>,
    ranks: Vec<i32>,
    face_offsets: Vec<i32>,
    send_offsets: Vec<i32>,
    send: Vec<i32>,
    recv_offsets: Vec<i32>,
    recv: Vec<i32>,
}

/// Arrays of the finite-element boundary, made on first request.
struct BoundaryArrays {
    faces: Vec<i32>,
    node_offsets: Vec<i32>,
    node_patches: Vec<i32>,
}

/// The C arrays of this module, reset with the mesh's.
#[derive(Default)]
pub(crate) struct FaceCells {
    fv: OnceCell<FvArrays>,
    halo: OnceCell<HaloArrays>,
    boundary: OnceCell<BoundaryArrays>,
    /// Reset by a rename.
    pub(crate) patch_names: OnceCell<Vec<CString>>,
}

/// Extracts the finite-volume faces, the cell halo and the finite-element
/// boundary of the current mesh, for the getters of this section. Needs a
/// mesh. Collective.
///
/// \param[in] h  the handle
#[no_mangle]
pub extern "C" fn octmesh_mesh_build_faces(h: *mut octmesh_t) -> octmesh_status_t {
    with_mut(h, |h| {
        h.session.boundary()?;
        Ok(())
    })
}

fn faces_of(h: &octmesh_t) -> Result<(&Mesh, &Faces, &Boundary)> {
    let missing = || {
        Error::new(
            ErrorKind::State,
            "there are no faces: call octmesh_mesh_build_faces after octmesh_mesh_build",
        )
    };
    let mesh = h.session.mesh().ok_or_else(missing)?;
    let faces = h.session.current_faces().ok_or_else(missing)?;
    let boundary = h.session.current_boundary().ok_or_else(missing)?;
    Ok((mesh, faces, boundary))
}

fn neighbour_code(f: &crate::mesh::Face) -> i32 {
    match f.other() {
        Other::Element(j) | Other::Halo(j) => j as i32,
        Other::Patch(p) => -1 - p as i32,
    }
}

fn fv_arrays(m: &Mesh, faces: &Faces) -> FvArrays {
    let list = faces.faces();
    let n = m.elements().len();
    // A snapped mesh's geometry comes from its moved points (the point
    // look-ups cannot fail for its own faces; the octree's otherwise).
    if let Ok(Some(g)) = m.snapped_fv_geometry(faces) {
        return FvArrays {
            owner: list.iter().map(|f| f.owner() as i32).collect(),
            neighbour: list.iter().map(neighbour_code).collect(),
            area: g.face_area,
            centre: g.face_centre.into_flattened(),
            normal: g.face_normal.into_flattened(),
            patch_offsets: (0..faces.num_patches())
                .map(|p| faces.patch_range(p).start as i32)
                .chain([faces.halo_range().start as i32])
                .collect(),
            cell_centre: g.cell_centre.into_flattened(),
            cell_volume: g.cell_volume,
        };
    }
    FvArrays {
        owner: list.iter().map(|f| f.owner() as i32).collect(),
        neighbour: list.iter().map(neighbour_code).collect(),
        area: list.iter().map(|f| m.face_area(f)).collect(),
        centre: list.iter().flat_map(|f| m.face_centre(f)).collect(),
        normal: list.iter().flat_map(|f| f.unit_normal()).collect(),
        patch_offsets: (0..faces.num_patches())
            .map(|p| faces.patch_range(p).start as i32)
            .chain([faces.halo_range().start as i32])
            .collect(),
        cell_centre: (0..n).flat_map(|e| m.element_centre(e)).collect(),
        cell_volume: (0..n).map(|e| m.element_volume(e)).collect(),
    }
}

fn offsets_of(lists: &[Vec<u32>]) -> Vec<i32> {
    let mut o = vec![0i32];
    for l in lists {
        o.push(o[o.len() - 1] + l.len() as i32);
    }
    o
}

fn halo_arrays(m: &Mesh, faces: &Faces) -> HaloArrays {
    let cells = m.cell_halo(faces);
    let halo = m.halo();
    let mut face_offsets: Vec<i32> = faces
        .halo_ranges()
        .iter()
        .map(|(_, r)| r.start as i32)
        .collect();
    face_offsets.push(faces.faces().len() as i32);
    HaloArrays {
        global: halo.global.iter().map(|&g| g as i64).collect(),
        rank: halo.owners.iter().map(|&r| r as i32).collect(),
        ranks: cells.ranks.iter().map(|&r| r as i32).collect(),
        face_offsets,
        send_offsets: offsets_of(&cells.send),
        send: cells.send.iter().flatten().map(|&e| e as i32).collect(),
        recv_offsets: offsets_of(&cells.recv),
        recv: cells.recv.iter().flatten().map(|&e| e as i32).collect(),
    }
}

fn boundary_arrays(b: &Boundary) -> BoundaryArrays {
    BoundaryArrays {
        faces: b
            .faces()
            .iter()
            .flat_map(|f| [f.element as i32, f.face as i32, f.patch as i32])
            .collect(),
        node_offsets: b.node_offsets().iter().map(|&o| o as i32).collect(),
        node_patches: b.patch_list().iter().map(|&p| p as i32).collect(),
    }
}

/// Writes the finite-volume faces and cells to `*out`: on a snapped mesh
/// (`octmesh_mesh_snap`) their geometry is that of the moved points. Needs
/// `octmesh_mesh_build_faces`. Not collective.
///
/// \param[in]  h    the handle
/// \param[out] out  counts and arrays owned by the handle
#[no_mangle]
pub extern "C" fn octmesh_mesh_get_faces(
    h: *const octmesh_t,
    out: *mut octmesh_faces_t,
) -> octmesh_status_t {
    with_ref(h, |h| {
        non_null(out, "out")?;
        let (m, faces, _) = faces_of(h)?;
        let a = h.arrays.faces.fv.get_or_init(|| fv_arrays(m, faces));
        write_out(
            out,
            octmesh_faces_t {
                num_faces: faces.faces().len() as i32,
                num_internal: faces.num_internal() as i32,
                num_patches: faces.num_patches() as i32,
                owner: a.owner.as_ptr(),
                neighbour: a.neighbour.as_ptr(),
                area: a.area.as_ptr(),
                centre: a.centre.as_ptr(),
                normal: a.normal.as_ptr(),
                patch_offsets: a.patch_offsets.as_ptr(),
                cell_centre: a.cell_centre.as_ptr(),
                cell_volume: a.cell_volume.as_ptr(),
                first_element: m.first_element() as i64,
                global_elements: m.counts().elements as i64,
            },
        );
        Ok(())
    })
}

/// Writes the cell halo and its exchange lists to `*out`. Needs
/// `octmesh_mesh_build_faces`. Not collective.
///
/// \param[in]  h    the handle
/// \param[out] out  counts and arrays owned by the handle
#[no_mangle]
pub extern "C" fn octmesh_mesh_get_cell_halo(
    h: *const octmesh_t,
    out: *mut octmesh_cell_halo_t,
) -> octmesh_status_t {
    with_ref(h, |h| {
        non_null(out, "out")?;
        let (m, faces, _) = faces_of(h)?;
        let a = h.arrays.faces.halo.get_or_init(|| halo_arrays(m, faces));
        write_out(
            out,
            octmesh_cell_halo_t {
                num_halo: a.global.len() as i32,
                halo_global: a.global.as_ptr(),
                halo_rank: a.rank.as_ptr(),
                num_ranks: a.ranks.len() as i32,
                ranks: a.ranks.as_ptr(),
                face_offsets: a.face_offsets.as_ptr(),
                send_offsets: a.send_offsets.as_ptr(),
                send: a.send.as_ptr(),
                recv_offsets: a.recv_offsets.as_ptr(),
                recv: a.recv.as_ptr(),
            },
        );
        Ok(())
    })
}

/// Writes the finite-element boundary (element faces and node patches) to
/// `*out`. Needs `octmesh_mesh_build_faces`. Not collective.
///
/// \param[in]  h    the handle
/// \param[out] out  counts and arrays owned by the handle
#[no_mangle]
pub extern "C" fn octmesh_mesh_get_boundary(
    h: *const octmesh_t,
    out: *mut octmesh_boundary_t,
) -> octmesh_status_t {
    with_ref(h, |h| {
        non_null(out, "out")?;
        let (_, _, b) = faces_of(h)?;
        let a = h.arrays.faces.boundary.get_or_init(|| boundary_arrays(b));
        write_out(
            out,
            octmesh_boundary_t {
                num_faces: (a.faces.len() / 3) as i32,
                faces: a.faces.as_ptr(),
                node_offsets: a.node_offsets.as_ptr(),
                node_patches: a.node_patches.as_ptr(),
            },
        );
        Ok(())
    })
}

/// Sets `*name` to patch `patch`'s name (NUL-terminated, owned by the
/// handle, valid until a rename or the handle's destruction). Needs a
/// surface or a mesh (the surface patch is named after the surface). Not
/// collective.
///
/// \param[in]  h      the handle
/// \param[in]  patch  0 .. num_patches - 1
/// \param[out] name   the name
#[no_mangle]
pub extern "C" fn octmesh_mesh_get_patch_name(
    h: *const octmesh_t,
    patch: octmesh_locidx_t,
    name: *mut *const c_char,
) -> octmesh_status_t {
    with_ref(h, |h| {
        non_null(name, "name")?;
        let names = match h.arrays.faces.patch_names.get() {
            Some(n) => n,
            None => {
                let made: Vec<CString> = h
                    .session
                    .patch_names()?
                    .names()
                    .iter()
                    .map(|n| super::c_string(n))
                    .collect();
                h.arrays.faces.patch_names.get_or_init(|| made)
            }
        };
        let p = usize::try_from(patch)
            .ok()
            .filter(|&p| p < names.len())
            .ok_or_else(|| {
                Error::invalid(format!(
                    "patch {patch} does not exist: there are {} patches",
                    names.len()
                ))
            })?;
        write_out(name, names[p].as_ptr());
        Ok(())
    })
}

/// Renames patch `from` (its current name, e.g. `xmin`) to `to` (an
/// OpenFOAM word: letters, digits and `_`, not starting with a digit, not
/// another patch's name), like the command's `--patch from=to`. Used by
/// `octmesh_mesh_write_openfoam` and `octmesh_mesh_get_patch_name`; patch
/// ids do not change. Collective (every rank must rename alike).
///
/// \param[in] h     the handle
/// \param[in] from  the current name, NUL-terminated
/// \param[in] to    the new name, NUL-terminated
#[no_mangle]
pub extern "C" fn octmesh_mesh_rename_patch(
    h: *mut octmesh_t,
    from: *const c_char,
    to: *const c_char,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let checked = str_arg(from, "from").and_then(|f| Ok((f, str_arg(to, "to")?)));
        let (from, to) = h.agree(checked)?;
        let before = h.session.config().mesh.patches.clone();
        let renamed = h.session.rename_patch(from, to);
        if let Err(e) = h.agree(renamed) {
            // Another rank refused: undo this rank's rename.
            h.session.config_mut().mesh.patches = before;
            return Err(e);
        }
        h.arrays.faces.patch_names = OnceCell::new();
        Ok(())
    })
}

/// Sets whether `octmesh_mesh_write_openfoam` gives the case a wall layer
/// (off until set), like the command's `--wall-layer`: every wall face of
/// the staircase gets one more cell whose outer face lies on the surface.
/// Needs a mesh built with `OCTMESH_KEEP_INSIDE` or `OCTMESH_KEEP_OUTSIDE`
/// and `OCTMESH_CUT_RULE_NONE`, not snapped, and the surface still loaded
/// when writing. Every rank must pass the same value. Collective.
///
/// \param[in] h   the handle
/// \param[in] on  whether the OpenFOAM case gets the wall layer
#[no_mangle]
pub extern "C" fn octmesh_mesh_set_wall_layer(h: *mut octmesh_t, on: bool) -> octmesh_status_t {
    with_mut(h, |h| {
        let all = h.comm.allgather_u64(u64::from(on));
        if all.iter().any(|&r| r != all[0]) {
            return Err(Error::invalid(
                "the ranks passed different values to octmesh_mesh_set_wall_layer",
            ));
        }
        h.session.config_mut().mesh.wall_layer = on;
        Ok(())
    })
}

/// Sets the boundary layers of the OpenFOAM case on every wall patch, like
/// the command's `--layers`, `--layer-expansion`, `--first-layer`,
/// `--final-layer`, `--layer-thickness` and `--relative-sizes`: `layers`
/// cells on each wall face next to the surface, growing by `expansion`
/// away from it, inside the wall layer's cell (which they imply, with its
/// needs, see `octmesh_mesh_set_wall_layer`). Exactly one of
/// `first_layer`, `final_layer` and `thickness` is above 0, the others
/// 0. `layers` 0 turns the layers off. Every rank must pass the same
/// values. Collective.
///
/// \param[in] h            the handle
/// \param[in] layers       layers per wall face, 0 for none
/// \param[in] expansion    each layer's height over the one before (> 0)
/// \param[in] first_layer  the first layer's height, or 0
/// \param[in] final_layer  the last layer's height, or 0
/// \param[in] thickness    all layers' thickness, or 0
/// \param[in] relative     the heights are fractions (below 1) of the
///                         local wall cell's side
#[no_mangle]
pub extern "C" fn octmesh_mesh_set_layers(
    h: *mut octmesh_t,
    layers: i32,
    expansion: f64,
    first_layer: f64,
    final_layer: f64,
    thickness: f64,
    relative: bool,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let bits = [
            layers as u64,
            expansion.to_bits(),
            first_layer.to_bits(),
            final_layer.to_bits(),
            thickness.to_bits(),
            u64::from(relative),
        ];
        let mut same = true;
        for b in bits {
            let all = h.comm.allgather_u64(b);
            same &= all.iter().all(|&r| r == all[0]);
        }
        if !same {
            return Err(Error::invalid(
                "the ranks passed different values to octmesh_mesh_set_layers",
            ));
        }
        let mut c = h.session.config().clone();
        let given = |v: f64| (v != 0.0).then_some(v);
        c.mesh.layers = match layers {
            0 => None,
            n if n < 0 => {
                return Err(Error::invalid(format!(
                    "layers must be 0 (none) or more, got {n}"
                )))
            }
            n => Some(n as u32),
        };
        c.mesh.layer_expansion = expansion;
        c.mesh.first_layer = given(first_layer);
        c.mesh.final_layer = given(final_layer);
        c.mesh.layer_thickness = given(thickness);
        c.mesh.relative_sizes = relative;
        if c.mesh.layers.is_some() {
            c.check_layer_settings()?;
        }
        *h.session.config_mut() = c;
        Ok(())
    })
}

/// Writes the mesh as an OpenFOAM case in `dir`, like the command's
/// `--openfoam`: `dir/constant/polyMesh` on one rank, else
/// `dir/processor<r>/constant/polyMesh` with processor patches (ready for
/// `mpirun -np P solver -parallel`), and a minimal `dir/system` when it is
/// absent. Patches are named by `octmesh_mesh_rename_patch`. An existing
/// mesh is replaced only when `overwrite` is true. All or nothing: if
/// one rank fails, no rank's mesh is left in place. Needs a mesh.
/// Collective.
///
/// \param[in] h          the handle
/// \param[in] dir        the case directory, NUL-terminated
/// \param[in] format     one of `octmesh_foam_format_t`
/// \param[in] overwrite  true to replace an existing mesh
#[no_mangle]
pub extern "C" fn octmesh_mesh_write_openfoam(
    h: *mut octmesh_t,
    dir: *const c_char,
    format: octmesh_foam_format_t,
    overwrite: bool,
) -> octmesh_status_t {
    with_mut(h, |h| {
        let checked = path_arg(dir, "dir").and_then(|d| Ok((d, FoamFormat::from_c(format)?)));
        let (dir, format) = h.agree(checked)?;
        let out = &mut h.session.config_mut().output;
        let before = (out.openfoam_format, out.overwrite);
        (out.openfoam_format, out.overwrite) = (format, overwrite);
        let written = h.session.write_openfoam(&dir);
        let out = &mut h.session.config_mut().output;
        (out.openfoam_format, out.overwrite) = before;
        written.map(|_| ())
    })
}
