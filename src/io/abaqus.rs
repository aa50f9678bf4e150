//! Abaqus / CalculiX input files (`.inp`), one per mesh, written by rank 0
//! from the gathered mesh ([`super::gathered`]): the same bytes on any
//! number of ranks. The file is a mesh deck to `*INCLUDE` or to complete
//! with materials, sections and steps.
//!
//! # What is written
//!
//! - `*NODE`: nodes `1..N` (coordinates in at most 20 characters, the
//!   width CalculiX reads: exact where the shortest exact form fits, else
//!   to 13 or more significant digits), the independent nodes first, then the hanging
//!   nodes, each run in the order the elements first use them
//!   ([`super::gathered`]); `*NSET, NSET=NALL, GENERATE` holds them all.
//! - `*ELEMENT, TYPE=C3D8`: elements `1..E` in global (Morton) element
//!   order (the mesh's global element number + 1), corners in C3D8 order
//!   (which is VTK's); `*ELSET, ELSET=EALL, GENERATE` holds them all.
//! - Per patch with boundary faces (named after the patch): `*NSET` of the
//!   independent nodes a condition on the patch must prescribe: those on
//!   the patch and those the patch's hanging nodes depend on (a node
//!   eliminated by an equation cannot take a `*BOUNDARY`; a `*BOUNDARY`
//!   on the set fixes the hanging nodes through their equations). Where
//!   a coarse element's face is only partly on the boundary (some of the
//!   finer elements across it were not kept) some of those dependencies
//!   lie off the patch, inside the mesh: a prescribed field is then
//!   applied there too, which is exact for constant and linear fields
//!   (the patch test) and a first-order approximation otherwise. Then
//!   `*ELSET` of the elements with a face on it, and
//!   `*SURFACE, TYPE=ELEMENT` listing those faces by their labels `S1..S6`
//!   (S1 = corners 1-2-3-4, S2 = 5-8-7-6, S3 = 1-5-6-2, S4 = 2-6-7-3,
//!   S5 = 3-7-8-4, S6 = 4-8-5-1). A face only partly on the boundary
//!   (where some of the finer elements across it were not kept) is listed
//!   whole.
//! - The hanging nodes' constraints: for each hanging node `h` and each
//!   degree of freedom `i` in 1, 2, 3 an `*EQUATION`
//!   `u_i(h) - sum_k w u_i(d_k) = 0`, with `w = 1/4` over the 4 corners
//!   of the coarse face a face-hanging node lies in, `w = 1/2` over the 2
//!   ends of the coarse edge an edge-hanging node lies on. The hanging
//!   node comes first, so it is the degree of freedom the equation
//!   eliminates. Displacements only: a deck for heat transfer (degree of
//!   freedom 11) needs the same equations on 11.
//!
//! Without the equations a hanging-node mesh falls apart at each 2:1 step
//! (the hanging corners belong to the fine elements only); with them it
//! is a conforming trilinear discretisation and passes the patch test.

use std::fmt::Write as _;
use std::path::Path;

use super::gathered::Gathered;
use crate::error::{Error, Result};
use crate::mesh::patches::PatchNames;

/// `x` in at most 20 characters (CalculiX reads a number from a field of
/// 20): exact when the shortest form that reads back as `x` fits, else
/// rounded to the most significant digits that fit (at least 13).
fn number(x: f64) -> String {
    let shortest = format!("{x:e}");
    if shortest.len() <= 20 {
        return shortest;
    }
    let mut digits = 16;
    loop {
        let t = format!("{x:.digits$e}");
        if t.len() <= 20 || digits == 0 {
            return t;
        }
        digits -= 1;
    }
}

/// Entries per data line of a set.
const PER_LINE: usize = 16;

/// Writes `list` (0-based, written 1-based) as set data lines.
fn set_lines(s: &mut String, list: impl Iterator<Item = u64>) {
    let mut k = 0;
    for v in list {
        if k > 0 {
            s.push_str(if k % PER_LINE == 0 { ",\n" } else { ", " });
        }
        write!(s, "{}", v + 1).expect("writing to a string");
        k += 1;
    }
    if k > 0 {
        s.push('\n');
    }
}

/// The text of the input file of `g` (rank 0's gathered mesh) with
/// `patches`' names.
pub fn abaqus_text(g: &Gathered, patches: &PatchNames) -> Result<String> {
    let mut s = String::new();
    let n = g.coordinates.len();
    let ne = g.elements.len();
    let w = |s: &mut String, args: std::fmt::Arguments| {
        s.write_fmt(args).expect("writing to a string");
    };
    w(
        &mut s,
        format_args!(
            "** Written by octmesh {}: {n} nodes ({} hanging, constrained by equations), \
             {ne} C3D8 elements\n",
            env!("CARGO_PKG_VERSION"),
            n - g.num_independent
        ),
    );
    w(&mut s, format_args!("*NODE\n"));
    for (k, p) in g.coordinates.iter().enumerate() {
        let [x, y, z] = p.map(number);
        w(&mut s, format_args!("{}, {x}, {y}, {z}\n", k + 1));
    }
    w(&mut s, format_args!("*ELEMENT, TYPE=C3D8\n"));
    for (k, e) in g.elements.iter().enumerate() {
        w(&mut s, format_args!("{}", k + 1));
        for v in e {
            w(&mut s, format_args!(", {}", v + 1));
        }
        s.push('\n');
    }
    if n > 0 {
        w(
            &mut s,
            format_args!("*NSET, NSET=NALL, GENERATE\n1, {n}, 1\n"),
        );
    }
    if ne > 0 {
        w(
            &mut s,
            format_args!("*ELSET, ELSET=EALL, GENERATE\n1, {ne}, 1\n"),
        );
    }
    for p in g.used_patches() {
        let name = patches
            .names()
            .get(p as usize)
            .ok_or_else(|| Error::invalid(format!("patch {p} has no name")))?;
        let faces: Vec<_> = g.faces.iter().filter(|f| f.patch == p).collect();
        let nodes = g.patch_nodes.get(p as usize).map_or(&[][..], |v| &v[..]);
        // The independent nodes on the patch and those its hanging nodes
        // depend on.
        let mut set: Vec<u32> = Vec::with_capacity(nodes.len());
        for &m in nodes {
            match (m as usize).checked_sub(g.num_independent) {
                None => set.push(m),
                Some(k) => set.extend(g.dependencies[k].iter()),
            }
        }
        set.sort_unstable();
        set.dedup();
        w(&mut s, format_args!("*NSET, NSET={name}\n"));
        set_lines(&mut s, set.into_iter().map(u64::from));
        let mut elements: Vec<u64> = faces.iter().map(|f| f.element).collect();
        elements.dedup();
        w(&mut s, format_args!("*ELSET, ELSET={name}\n"));
        set_lines(&mut s, elements.into_iter());
        w(
            &mut s,
            format_args!("*SURFACE, NAME={name}, TYPE=ELEMENT\n"),
        );
        for f in faces {
            w(
                &mut s,
                format_args!("{}, S{}\n", f.element + 1, f.label + 1),
            );
        }
    }
    if !g.dependencies.is_empty() {
        w(&mut s, format_args!("*EQUATION\n"));
        for (k, d) in g.dependencies.iter().enumerate() {
            let h = g.num_independent + k + 1;
            let c = -1.0 / d.len() as f64;
            for dof in 1..=3 {
                w(&mut s, format_args!("{}\n{h}, {dof}, 1.", d.len() + 1));
                for (j, m) in d.iter().enumerate() {
                    // Four terms a line.
                    let sep = if (j + 1) % 4 == 0 { "\n" } else { ", " };
                    w(&mut s, format_args!("{sep}{}, {dof}, {c:?}", m + 1));
                }
                s.push('\n');
            }
        }
    }
    Ok(s)
}

/// Writes `g` (rank 0's gathered mesh; call on rank 0 only) to `path`,
/// with the hanging nodes' equations.
pub fn write_abaqus(path: &Path, g: &Gathered, patches: &PatchNames) -> Result<()> {
    let text = abaqus_text(g, patches)?;
    std::fs::write(path, text)
        .map_err(|e| Error::io(format!("cannot write '{}': {e}", path.display())))
}
