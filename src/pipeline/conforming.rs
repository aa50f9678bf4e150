//! Stage: the conforming all-hexahedral mesh ([`crate::mesh::conforming`])
//! in place of the hanging-node mesh in the single-file finite-element
//! files. Rank 0 builds it from every rank's leaves (8 bytes a leaf) and
//! takes the patches and zones from the gathered hanging-node mesh of the
//! same leaves, so the files are the same on any number of ranks. With a
//! snap, rank 0 snaps it ([`crate::mesh::snap::snap_conforming`]).

use std::rc::Rc;

use crate::error::{Error, ErrorKind, Result};
use crate::geometry::hash::FoldMap;
use crate::geometry::Surface;
use crate::io::gathered::{match_faces, Gathered, GatheredFace, ABAQUS_FACE, ABAQUS_FACE_NODES};
use crate::mesh::conforming::build::{build, Conforming};
use crate::mesh::conforming::MACRO;
use crate::mesh::faces::SURFACE_PATCH;
use crate::mesh::snap::{snap_conforming, SnapOptions, SnapReport};
use crate::octree::domain::Domain;
use crate::octree::octant::{morton_encode, Octant};
use crate::parallel::comm::{Comm, SerialComm};
use crate::refine::SurfaceIndex;

/// The kept bit of a leaf key sent to rank 0 (keys use 62 bits).
const KEPT: u64 = 1 << 63;

/// Rank 0: the conforming mesh of the octree whose local leaves are
/// `leaves` and kept ones `elements` (a sorted subset, of classes
/// `classes`), as a gathered mesh with `hanging`'s patches and zones, the
/// macro cells the closure split, and the conforming mesh itself (for the
/// snap); other ranks: empty ones and 0. Errors only on rank 0 (the caller
/// agrees them). Collective.
pub(super) fn conforming_gathered(
    comm: &dyn Comm,
    leaves: &[Octant],
    (elements, classes): (&[Octant], &[u8]),
    domain: &Domain,
    hanging: &Gathered,
) -> Result<(Gathered, u64, Conforming)> {
    let mut send = Vec::with_capacity(leaves.len());
    let mut e = elements.iter().peekable();
    for &o in leaves {
        let kept = e.next_if(|&&k| k == o).is_some();
        send.push(o.key() | if kept { KEPT } else { 0 });
    }
    let mut counts = vec![0; comm.size()];
    counts[0] = send.len();
    let (all, _) = comm.alltoallv_u64(&send, &counts);
    let classes: Vec<u64> = classes.iter().map(|&c| u64::from(c)).collect();
    counts[0] = classes.len();
    let (classes, _) = comm.alltoallv_u64(&classes, &counts);
    if comm.rank() != 0 {
        return Ok((Gathered::default(), 0, Conforming::default()));
    }
    let leaves: Vec<Octant> = all.iter().map(|&k| Octant::from_key(k & !KEPT)).collect();
    let kept: Vec<Octant> = all
        .iter()
        .filter(|&&k| k & KEPT != 0)
        .map(|&k| Octant::from_key(k & !KEPT))
        .collect();
    let zones = &hanging.element_zones;
    let mut next = 0usize;
    let tags: Vec<u32> = all
        .iter()
        .map(|&k| {
            if k & KEPT == 0 {
                return 0;
            }
            next += 1;
            1 + zones.get(next - 1).map_or(0, |&z| u32::from(z))
        })
        .collect();
    let mesh = build(Rc::new(SerialComm), &leaves, &tags)?;
    let mut g = to_gathered(&mesh, &kept, domain, hanging)?;
    (g.element_level, g.element_class) = leaf_of_each(&mesh, &kept, &classes, domain)?;
    Ok((g, mesh.refined as u64, mesh))
}

/// Snaps `g`, the gathered form of the conforming mesh `mesh`
/// ([`snap_conforming`]): its nodes on a surface patch (patches from
/// [`SURFACE_PATCH`] up) and on no side of the domain move onto
/// `surface`, `g`'s coordinates become the snapped ones. Rank 0's work
/// (the caller shares the report: [`share_report`]).
pub(super) fn snap_gathered(
    g: &mut Gathered,
    mesh: &Conforming,
    domain: &Domain,
    surface: &Surface,
    index: Option<&SurfaceIndex>,
    opts: &SnapOptions,
    spare: bool,
) -> Result<SnapReport> {
    let mut masks = vec![0u64; g.coordinates.len()];
    for (p, nodes) in g.patch_nodes.iter().enumerate() {
        let bit = 1u64 << p.min(SURFACE_PATCH as usize);
        for &n in nodes {
            masks[n as usize] |= bit;
        }
    }
    let (pos, report) = snap_conforming(mesh, surface, index, domain, &masks, opts, spare)?;
    g.coordinates = pos;
    Ok(report)
}

/// Rank 0's snap report `r` on every rank (the other ranks pass the
/// default). Collective.
pub(super) fn share_report(comm: &dyn Comm, r: SnapReport) -> SnapReport {
    let mut n = [
        r.surface_nodes,
        r.snapped,
        r.partial,
        r.unsnapped,
        r.feature_nodes,
        r.relaxed_nodes,
        r.reported_elements,
        r.partial_by_wall_faces[0],
        r.partial_by_wall_faces[1],
        r.partial_by_wall_faces[2],
        r.unsnapped_by_wall_faces[0],
        r.unsnapped_by_wall_faces[1],
        r.unsnapped_by_wall_faces[2],
        u64::from(r.iterations),
    ];
    comm.sum_u64(&mut n);
    let mut least = [match comm.rank() {
        0 => -r.min_scaled_jacobian,
        _ => f64::NEG_INFINITY,
    }];
    comm.max_f64(&mut least);
    SnapReport {
        surface_nodes: n[0],
        snapped: n[1],
        partial: n[2],
        unsnapped: n[3],
        feature_nodes: n[4],
        relaxed_nodes: n[5],
        reported_elements: n[6],
        partial_by_wall_faces: [n[7], n[8], n[9]],
        unsnapped_by_wall_faces: [n[10], n[11], n[12]],
        min_scaled_jacobian: -least[0],
        iterations: n[13] as u32,
    }
}

/// The gathered form of `mesh`: positions in user units, boundary faces
/// with the patch of the hanging-node mesh's element face (of `kept`, in
/// global element order) they lie on, zones from the tags.
fn to_gathered(
    mesh: &Conforming,
    kept: &[Octant],
    domain: &Domain,
    hanging: &Gathered,
) -> Result<Gathered> {
    let unit = MACRO as u64;
    let coordinates = mesh
        .points
        .iter()
        .map(|p| domain.from_lattice(p.map(|c| c as f64 / unit as f64)))
        .collect();
    // Faces seen once are the boundary.
    let (_, once) = match_faces(&mesh.hexes);
    let patch_of: FoldMap<(u64, u8), u16> = hanging
        .faces
        .iter()
        .map(|f| ((f.element, f.label), f.patch))
        .collect();
    let mut faces = Vec::with_capacity(once.len());
    for &(h, label) in &once {
        let hex = &mesh.hexes[h as usize];
        let quad = ABAQUS_FACE_NODES[label as usize].map(|c| mesh.points[hex[c] as usize]);
        let axis = (0..3)
            .find(|&a| quad.iter().all(|p| p[a] == quad[0][a]))
            .ok_or_else(|| {
                Error::new(
                    ErrorKind::Internal,
                    "a boundary face of the conforming mesh is not flat",
                )
            })?;
        let centre: u64 = hex.iter().map(|&n| mesh.points[n as usize][axis]).sum();
        let plane = quad[0][axis] / unit;
        // The element is on the side of the hexahedron's centre.
        let upper = centre < 8 * quad[0][axis];
        let mut q = [0u32; 3];
        for (a, c) in q.iter_mut().enumerate() {
            *c = if a == axis {
                (plane - u64::from(upper)) as u32
            } else {
                (quad.iter().map(|p| p[a]).sum::<u64>() / (4 * unit)) as u32
            };
        }
        let cell = morton_encode(q[0], q[1], q[2]);
        let e = kept.partition_point(|o| o.cell_end() <= cell);
        let inside = kept.get(e).is_some_and(|o| o.cell_begin() <= cell);
        let face = ABAQUS_FACE[2 * axis + usize::from(upper)];
        let patch = inside
            .then(|| patch_of.get(&(e as u64, face)))
            .flatten()
            .ok_or_else(|| {
                Error::new(
                    ErrorKind::Internal,
                    format!(
                        "a boundary face of the conforming mesh at lattice cell {q:?} lies on no \
                     boundary face of the hanging-node mesh"
                    ),
                )
            })?;
        faces.push(GatheredFace {
            patch: *patch,
            element: u64::from(h),
            label,
        });
    }
    faces.sort_unstable();
    let highest = faces
        .iter()
        .map(|f| f.patch as usize + 1)
        .max()
        .unwrap_or(0);
    let mut patch_nodes = vec![Vec::new(); highest];
    for f in &faces {
        let hex = &mesh.hexes[f.element as usize];
        patch_nodes[f.patch as usize].extend(ABAQUS_FACE_NODES[f.label as usize].map(|c| hex[c]));
    }
    for nodes in &mut patch_nodes {
        nodes.sort_unstable();
        nodes.dedup();
    }
    let element_zones = if hanging.zone_names.is_empty() {
        Vec::new()
    } else {
        mesh.tags.iter().map(|&t| (t - 1) as u16).collect()
    };
    Ok(Gathered {
        coordinates,
        num_independent: mesh.points.len(),
        elements: mesh.hexes.clone(),
        dependencies: Vec::new(),
        patch_nodes,
        faces,
        zone_names: hanging.zone_names.clone(),
        element_zones,
        ..Gathered::default()
    })
}

/// Per hexahedron of `mesh`, the level (from the root cells) and class
/// (`classes`, per kept leaf) of the kept leaf of `kept` its centre lies
/// in: the kept leaves tile the conforming mesh's region.
fn leaf_of_each(
    mesh: &Conforming,
    kept: &[Octant],
    classes: &[u64],
    domain: &Domain,
) -> Result<(Vec<u8>, Vec<u8>)> {
    let root = domain.brick.level();
    let unit = MACRO as u64;
    let mut level = Vec::with_capacity(mesh.hexes.len());
    let mut class = Vec::with_capacity(mesh.hexes.len());
    for hex in &mesh.hexes {
        let q: [u32; 3] = std::array::from_fn(|a| {
            let sum: u64 = hex.iter().map(|&n| mesh.points[n as usize][a]).sum();
            (sum / (8 * unit)) as u32
        });
        let cell = morton_encode(q[0], q[1], q[2]);
        let e = kept.partition_point(|o| o.cell_end() <= cell);
        match kept.get(e).filter(|o| o.cell_begin() <= cell) {
            Some(o) => {
                level.push(o.level() - root);
                class.push(classes.get(e).copied().unwrap_or(0) as u8);
            }
            None => {
                return Err(Error::new(
                    ErrorKind::Internal,
                    format!("a hexahedron of the conforming mesh at lattice cell {q:?} lies in no kept leaf"),
                ))
            }
        }
    }
    Ok((level, class))
}
