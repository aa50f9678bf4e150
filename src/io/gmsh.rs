//! Gmsh MSH 4.1 files (ASCII), one per mesh, written by rank 0 from the
//! gathered mesh ([`super::gathered`]): the same bytes on any number of
//! ranks.
//!
//! # What is written
//!
//! - `$MeshFormat 4.1 0 8`.
//! - `$PhysicalNames`: one physical surface (dimension 2) per patch that
//!   has boundary faces, tag `patch id + 1` (the sides `xmin xmax ymin ymax
//!   zmin zmax` are 1..6, the surface or its parts follow), named after the
//!   patch; one physical volume (dimension 3, tag 1) named `volume`, the
//!   kept region, or on a mesh with zones ([`crate::mesh::zones`]) one
//!   physical volume per zone that has elements, tag `zone index + 1`
//!   (`inside` 1, `outside` 2, the regions' zones from 3), named after
//!   the zone.
//! - `$Entities`: one surface entity per patch (same tag as its physical
//!   group) and one volume entity per physical volume (same tag) bounded
//!   by the patches its elements have faces on, with their bounding
//!   boxes.
//! - `$Nodes`: one block, on the volume entity, nodes `1..N`: the
//!   independent nodes first, then the hanging nodes, each run in the
//!   order the elements first use them ([`super::gathered`]).
//! - `$Elements`: the hexahedra (type 5, Gmsh's corner order, which is
//!   VTK's) tagged `1..E` in global (Morton) element order, a block per
//!   volume entity (each block in tag order), then per patch the boundary element faces as quadrilaterals
//!   (type 3) tagged from `E + 1`, their corners counter-clockwise seen
//!   from outside the element. A face only partly on the boundary (where
//!   some of the finer elements across it were not kept) is written whole.
//! - `$NodeData` view `hanging`: per node the number of nodes it depends
//!   on (0 independent, 2 edge-hanging, 4 face-hanging), to see them in
//!   Gmsh.
//! - `$HangingNodes` (a section Gmsh skips, as the MSH format ignores
//!   sections it does not know): the number of hanging nodes, then one
//!   line per hanging node, `tag count dep_1 .. dep_count`: the node's
//!   value (and position, before snapping) is the mean of its `count` (2
//!   or 4) dependencies, weights `1/count`.
//!
//! # Hanging nodes
//!
//! MSH has no constraints. A mesh with hanging nodes is written as it is:
//! its hanging nodes are ordinary nodes, corners of the finer elements
//! only, so the file is a **non-conforming** mesh; a code reading it must
//! add the constraints of `$HangingNodes` itself (or use a conforming
//! mesh). Counts, physical groups, quality and visualisation work as
//! usual.

use std::fmt::Write as _;
use std::path::Path;

use super::gathered::{Gathered, ABAQUS_FACE_NODES};
use crate::error::{Error, Result};
use crate::mesh::patches::PatchNames;

/// What [`write_gmsh`] wrote: nodes, hexahedra, boundary quadrilaterals.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GmshCounts {
    /// Nodes, hanging ones included.
    pub nodes: u64,
    /// Hexahedra.
    pub hexahedra: u64,
    /// Boundary quadrilaterals.
    pub quadrilaterals: u64,
}

/// The bounding box of `points`, as 6 numbers.
fn bbox(points: impl Iterator<Item = [f64; 3]>) -> [f64; 6] {
    let mut b = [
        f64::INFINITY,
        f64::INFINITY,
        f64::INFINITY,
        -f64::INFINITY,
        -f64::INFINITY,
        -f64::INFINITY,
    ];
    for p in points {
        for a in 0..3 {
            b[a] = b[a].min(p[a]);
            b[a + 3] = b[a + 3].max(p[a]);
        }
    }
    if b[0] > b[3] {
        b = [0.0; 6];
    }
    b
}

/// The text of the MSH 4.1 file of `g` (rank 0's gathered mesh) with
/// `patches`' names.
pub fn gmsh_text(g: &Gathered, patches: &PatchNames) -> Result<String> {
    let mut s = String::new();
    let used = g.used_patches();
    let name = |p: u16| -> Result<String> {
        let n = patches
            .names()
            .get(p as usize)
            .ok_or_else(|| Error::invalid(format!("patch {p} has no name")))?;
        Ok(n.clone())
    };
    let w = |s: &mut String, args: std::fmt::Arguments| {
        s.write_fmt(args).expect("writing to a string");
    };
    w(
        &mut s,
        format_args!("$MeshFormat\n4.1 0 8\n$EndMeshFormat\n"),
    );
    let volumes = volumes(g, &used);
    w(
        &mut s,
        format_args!("$PhysicalNames\n{}\n", used.len() + volumes.len()),
    );
    for &p in &used {
        w(&mut s, format_args!("2 {} \"{}\"\n", p + 1, name(p)?));
    }
    for v in &volumes {
        w(&mut s, format_args!("3 {} \"{}\"\n", v.tag, v.name));
    }
    w(&mut s, format_args!("$EndPhysicalNames\n"));
    // Entities with their boxes.
    let corners = |f: &super::gathered::GatheredFace| {
        let e = &g.elements[f.element as usize];
        ABAQUS_FACE_NODES[f.label as usize].map(|v| e[v])
    };
    w(
        &mut s,
        format_args!("$Entities\n0 0 {} {}\n", used.len(), volumes.len()),
    );
    for &p in &used {
        let b = bbox(
            g.faces
                .iter()
                .filter(|f| f.patch == p)
                .flat_map(|f| corners(f).map(|n| g.coordinates[n as usize])),
        );
        w(
            &mut s,
            format_args!(
                "{} {:e} {:e} {:e} {:e} {:e} {:e} 1 {} 0\n",
                p + 1,
                b[0],
                b[1],
                b[2],
                b[3],
                b[4],
                b[5],
                p + 1
            ),
        );
    }
    for v in &volumes {
        let b = bbox(
            v.elements
                .iter()
                .flat_map(|&e| g.elements[e].map(|n| g.coordinates[n as usize])),
        );
        w(
            &mut s,
            format_args!(
                "{} {:e} {:e} {:e} {:e} {:e} {:e} 1 {} {}",
                v.tag,
                b[0],
                b[1],
                b[2],
                b[3],
                b[4],
                b[5],
                v.tag,
                v.patches.len()
            ),
        );
        for &p in &v.patches {
            w(&mut s, format_args!(" {}", p + 1));
        }
        s.push('\n');
    }
    w(&mut s, format_args!("$EndEntities\n"));
    // Nodes: one block on the volume.
    let n = g.coordinates.len();
    w(
        &mut s,
        format_args!("$Nodes\n1 {n} {} {n}\n3 1 0 {n}\n", n.min(1)),
    );
    for t in 1..=n {
        w(&mut s, format_args!("{t}\n"));
    }
    for p in &g.coordinates {
        w(&mut s, format_args!("{:e} {:e} {:e}\n", p[0], p[1], p[2]));
    }
    w(&mut s, format_args!("$EndNodes\n"));
    // Elements: the hexahedra, then a block of quadrilaterals per patch.
    let ne = g.elements.len();
    let total = ne + g.faces.len();
    w(
        &mut s,
        format_args!(
            "$Elements\n{} {total} {} {total}\n",
            used.len() + volumes.len(),
            total.min(1)
        ),
    );
    for v in &volumes {
        w(&mut s, format_args!("3 {} 5 {}\n", v.tag, v.elements.len()));
        for &k in &v.elements {
            w(&mut s, format_args!("{}", k + 1));
            for n in &g.elements[k] {
                w(&mut s, format_args!(" {}", n + 1));
            }
            s.push('\n');
        }
    }
    let mut tag = ne;
    for &p in &used {
        let faces: Vec<_> = g.faces.iter().filter(|f| f.patch == p).collect();
        w(&mut s, format_args!("2 {} 3 {}\n", p + 1, faces.len()));
        for f in faces {
            tag += 1;
            // Abaqus's corners run into the element: reversed, outwards.
            let c = corners(f);
            w(
                &mut s,
                format_args!(
                    "{tag} {} {} {} {}\n",
                    c[3] + 1,
                    c[2] + 1,
                    c[1] + 1,
                    c[0] + 1
                ),
            );
        }
    }
    w(&mut s, format_args!("$EndElements\n"));
    // The hanging nodes: a view, and the constraints.
    w(
        &mut s,
        format_args!("$NodeData\n1\n\"hanging\"\n1\n0\n3\n0\n1\n{n}\n"),
    );
    for t in 0..n {
        let c = match t.checked_sub(g.num_independent) {
            Some(k) => g.dependencies[k].len(),
            None => 0,
        };
        w(&mut s, format_args!("{} {c}\n", t + 1));
    }
    w(&mut s, format_args!("$EndNodeData\n"));
    w(
        &mut s,
        format_args!("$HangingNodes\n{}\n", g.dependencies.len()),
    );
    for (k, d) in g.dependencies.iter().enumerate() {
        w(
            &mut s,
            format_args!("{} {}", g.num_independent + k + 1, d.len()),
        );
        for m in d {
            w(&mut s, format_args!(" {}", m + 1));
        }
        s.push('\n');
    }
    w(&mut s, format_args!("$EndHangingNodes\n"));
    Ok(s)
}

/// A volume entity with its physical group: tag, name, elements (global
/// order) and the patches its elements have boundary faces on.
struct Volume {
    tag: usize,
    name: String,
    elements: Vec<usize>,
    patches: Vec<u16>,
}

/// The volumes of `g`: one per zone with elements, or one, `volume`, for
/// the whole mesh without zones (`used`: the patches with faces).
fn volumes(g: &Gathered, used: &[u16]) -> Vec<Volume> {
    if g.zone_names.is_empty() || g.element_zones.len() != g.elements.len() {
        return vec![Volume {
            tag: 1,
            name: "volume".to_string(),
            elements: (0..g.elements.len()).collect(),
            patches: used.to_vec(),
        }];
    }
    let mut out: Vec<Volume> = (g.zone_names.iter().enumerate())
        .map(|(z, name)| Volume {
            tag: z + 1,
            name: name.clone(),
            elements: Vec::new(),
            patches: Vec::new(),
        })
        .collect();
    for (k, &z) in g.element_zones.iter().enumerate() {
        out[z as usize].elements.push(k);
    }
    for f in &g.faces {
        let p = &mut out[g.element_zones[f.element as usize] as usize].patches;
        if p.last() != Some(&f.patch) {
            p.push(f.patch);
        }
    }
    out.retain(|v| !v.elements.is_empty());
    out
}

/// Writes `g` (rank 0's gathered mesh; call on rank 0 only) to `path`.
pub fn write_gmsh(path: &Path, g: &Gathered, patches: &PatchNames) -> Result<GmshCounts> {
    let text = gmsh_text(g, patches)?;
    std::fs::write(path, text)
        .map_err(|e| Error::io(format!("cannot write '{}': {e}", path.display())))?;
    Ok(GmshCounts {
        nodes: g.coordinates.len() as u64,
        hexahedra: g.elements.len() as u64,
        quadrilaterals: g.faces.len() as u64,
    })
}
