//! Exodus II files (`.exo`), one per mesh, written by rank 0 from the
//! gathered mesh ([`super::gathered`]) through the netCDF C library (the
//! `netcdf` crate over the system's libnetcdf): the same bytes on any
//! number of ranks.
//!
//! # What is written
//!
//! A netCDF file in the 64-bit offset format (CDF-2) laid out as the Exodus
//! II library lays out a "large model" file (`file_size = 1`: one variable
//! per coordinate), 32-bit integers (`int64_status = 0`):
//!
//! - Global attributes `title` (`octmesh`), `api_version` and `version`
//!   (8.03, floats), `floating_point_word_size` (8),
//!   `file_size` (1), `maximum_name_length` (the longest name, at least
//!   32), `int64_status` (0).
//! - Dimensions `len_string` (33), `len_line` (81), `four` (4), `len_name`
//!   (`maximum_name_length + 1`), `time_step` (unlimited, no steps),
//!   `num_dim` (3), `num_nodes`, `num_elem`, `num_el_blk`,
//!   `num_el_in_blk<b>`, `num_nod_per_el<b>` (8), and when there are boundary
//!   faces `num_side_sets`, `num_side_ss<i>`, `num_node_sets`,
//!   `num_nod_ns<i>`.
//! - `coor_names` (`x y z`), `coordx coordy coordz` (doubles, the
//!   surface's units), `time_whole` (empty).
//! - One element block, ID 1, named `volume` (the kept region, as the
//!   Gmsh writer's physical volume), or on a mesh with zones
//!   ([`crate::mesh::zones`]) one block per zone with elements, ID `zone
//!   index + 1` (`inside` 1, `outside` 2, the regions' zones from 3, as
//!   the Gmsh file's volumes), named after the zone: `eb_status`,
//!   `eb_prop1` (attribute `name = "ID"`), `eb_names`, and per block
//!   `connect<b>` (attribute `elem_type = "HEX8"`). The elements are
//!   numbered block after block, each block in global (Morton) element
//!   order; corners in HEX8 order (which is VTK's).
//! - Per patch with boundary faces, in patch order, a side set and a node
//!   set, both with ID `patch id + 1` (the sides `xmin .. zmax` are 1..6,
//!   as in the Gmsh file) and the patch's name (`ss_names`, `ns_names`;
//!   `ss_status`, `ss_prop1`, `ns_status`, `ns_prop1` with `name = "ID"`).
//!   `elem_ss<i>` and `side_ss<i>` list the faces as element and Exodus
//!   side (HEX8 side 1 = corners 1 2 6 5, 2 = 2 3 7 6, 3 = 3 4 8 7,
//!   4 = 1 5 8 4, 5 = 1 4 3 2, 6 = 5 6 7 8); `node_ns<i>` the patch's
//!   nodes, hanging ones included. A face only partly on the boundary
//!   (where some of the finer elements across it were not kept) is listed
//!   whole.
//! - Nodes `1..N`: the independent nodes first, then the hanging nodes,
//!   each run in the order the elements first use them.
//!
//! # Hanging nodes
//!
//! Exodus II has no constraints. The hanging nodes are ordinary nodes
//! (corners of the finer elements only, so the mesh is non-conforming as
//! written) and, when there are any, the file has one more node set,
//! named `hanging` (ID: the last patch set's ID + 1), listing them, and
//! three variables Exodus readers skip:
//!
//! - dimensions `num_hanging_nodes` (H) and `num_hanging_parents` (4);
//! - `hanging_nodes(num_hanging_nodes)`: the hanging nodes (1-based);
//! - `hanging_parents(num_hanging_nodes, num_hanging_parents)`: the
//!   independent nodes each depends on (1-based; 4 corners of the coarse
//!   face for a face-hanging node, the 2 ends of the coarse edge then 0 0
//!   for an edge-hanging one);
//! - `hanging_weights(num_hanging_nodes, num_hanging_parents)`: their
//!   weights (1/4 each, or 1/2 1/2 0 0): a hanging node's value is the
//!   weighted sum of its parents' values.

use std::path::Path;

use netcdf::types::{NcTypeDescriptor, NcVariableType};
use netcdf::{FileMut, Options};

use super::gathered::{Blocks, Gathered};
use crate::error::{Error, Result};
use crate::mesh::patches::PatchNames;

/// The Exodus side (1..6) of each face label of [`Gathered`] (the Abaqus
/// face `S1..S6` less one): S1 (z low) is side 5, S2 (z high) 6, S3 (y
/// low) 1, S4 (x high) 2, S5 (y high) 3, S6 (x low) 4.
pub const EXODUS_SIDE: [i32; 6] = [5, 6, 1, 2, 3, 4];

/// The Exodus API version the layout follows (`api_version`, `version`).
const EXODUS_VERSION: f32 = 8.03;

/// Exodus's shortest `maximum_name_length`.
const MIN_NAME: usize = 32;

/// What [`write_exodus`] wrote.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ExodusCounts {
    /// Nodes, hanging ones included.
    pub nodes: u64,
    /// Hexahedra.
    pub hexahedra: u64,
    /// Side sets (one per patch with boundary faces).
    pub side_sets: u64,
    /// Hanging nodes.
    pub hanging: u64,
}

/// netCDF's text type (`NC_CHAR`), for the name arrays.
#[repr(transparent)]
#[derive(Clone, Copy)]
struct NcChar(u8);

// SAFETY: one byte, the size and layout of NC_CHAR.
unsafe impl NcTypeDescriptor for NcChar {
    fn type_descriptor() -> NcVariableType {
        NcVariableType::Char
    }
}

/// `names` as a `names.len() x len` character array, NUL-padded.
fn name_array(names: &[&str], len: usize) -> Vec<NcChar> {
    let mut out = vec![NcChar(0); names.len() * len];
    for (k, n) in names.iter().enumerate() {
        for (i, b) in n.bytes().take(len - 1).enumerate() {
            out[k * len + i] = NcChar(b);
        }
    }
    out
}

/// `v` as an Exodus 32-bit integer, or an error naming `what`.
fn int(v: usize, what: &str) -> Result<i32> {
    i32::try_from(v).map_err(|_| {
        Error::invalid(format!(
            "the mesh has too many {what} ({v}) for an Exodus II file with 32-bit integers"
        ))
    })
}

/// One set of the file (side set or node set): its ID, name and members,
/// made once for the definitions and the data.
struct Set<'a> {
    id: i32,
    name: &'a str,
    /// Its nodes, 1-based.
    nodes: Vec<i32>,
    /// A side set's faces as element (1-based, file numbering) and Exodus
    /// side; empty for the `hanging` node set.
    faces: (Vec<i32>, Vec<i32>),
}

/// Writes `g` (rank 0's gathered mesh; call on rank 0 only) to `path`.
pub fn write_exodus(path: &Path, g: &Gathered, patches: &PatchNames) -> Result<ExodusCounts> {
    let fail = |e: netcdf::Error| Error::io(format!("cannot write '{}': {e}", path.display()));
    // The file system's own message for a path that cannot be written.
    std::fs::File::create(path)
        .map_err(|e| Error::io(format!("cannot write '{}': {e}", path.display())))?;
    let (nn, ne) = (g.coordinates.len(), g.elements.len());
    int(nn, "nodes")?;
    int(ne.max(g.faces.len()), "elements")?;
    let blocks = Blocks::of(g);
    let used = g.used_patches();
    let mut sets = Vec::with_capacity(used.len());
    for &p in &used {
        let name = patches
            .names()
            .get(p as usize)
            .ok_or_else(|| Error::invalid(format!("patch {p} has no name")))?;
        let nodes = g.patch_nodes.get(p as usize).map_or(&[][..], |l| &l[..]);
        let faces = (g.faces.iter().filter(|f| f.patch == p))
            .map(|f| {
                (
                    blocks.number[f.element as usize],
                    EXODUS_SIDE[f.label as usize],
                )
            })
            .unzip();
        sets.push(Set {
            id: p as i32 + 1,
            name,
            nodes: nodes.iter().map(|&n| n as i32 + 1).collect(),
            faces,
        });
    }
    let hanging = g.dependencies.len();
    let hanging_set = Set {
        id: sets.last().map_or(1, |s| s.id + 1),
        name: "hanging",
        nodes: (0..hanging)
            .map(|k| (g.num_independent + k) as i32 + 1)
            .collect(),
        faces: (Vec::new(), Vec::new()),
    };
    let mut node_sets: Vec<&Set> = sets.iter().collect();
    if hanging > 0 {
        node_sets.push(&hanging_set);
    }
    let name_len = (node_sets.iter().map(|s| s.name.len()))
        .chain(blocks.blocks.iter().map(|b| b.1.len()))
        .max()
        .unwrap_or(0)
        .max(MIN_NAME);
    let mut file = netcdf::create_with(path, Options::_64BIT_OFFSET).map_err(fail)?;
    define(&mut file, g, &blocks, &sets, &node_sets, name_len).map_err(fail)?;
    file.enddef().map_err(fail)?;
    put(&mut file, g, &blocks, &sets, &node_sets, name_len).map_err(fail)?;
    file.close().map_err(fail)?;
    Ok(ExodusCounts {
        nodes: nn as u64,
        hexahedra: ne as u64,
        side_sets: sets.len() as u64,
        hanging: hanging as u64,
    })
}

/// Adds variable `name` of type `T` over `dims`, without the fill pass
/// (every value is written).
fn variable<T: NcTypeDescriptor>(
    file: &mut FileMut,
    name: &str,
    dims: &[&str],
) -> netcdf::Result<()> {
    let mut v = file.add_variable::<T>(name, dims)?;
    // SAFETY: every variable is written whole before the file is closed
    // (`put`), so no unfilled value is ever read.
    unsafe { v.set_nofill() }
}

/// Defines the `<prefix>_status`, `<prefix>_prop1` (the IDs) and
/// `<prefix>_names` of a list of blocks or sets counted by `count`.
fn define_list(file: &mut FileMut, prefix: &str, count: &str) -> netcdf::Result<()> {
    variable::<i32>(file, &format!("{prefix}_status"), &[count])?;
    let ids = format!("{prefix}_prop1");
    variable::<i32>(file, &ids, &[count])?;
    file.variable_mut(&ids)
        .expect("just added")
        .put_attribute("name", "ID")?;
    variable::<NcChar>(file, &format!("{prefix}_names"), &[count, "len_name"])
}

/// Writes the lists of [`define_list`]: every entry active, its ID and
/// name (`len` bytes each).
fn put_list(
    file: &mut FileMut,
    prefix: &str,
    ids: &[i32],
    names: &[&str],
    len: usize,
) -> netcdf::Result<()> {
    put_all(file, &format!("{prefix}_status"), &vec![1i32; ids.len()])?;
    put_all(file, &format!("{prefix}_prop1"), ids)?;
    put_all(file, &format!("{prefix}_names"), &name_array(names, len))
}

/// The netCDF definitions: attributes, dimensions, variables.
fn define(
    file: &mut FileMut,
    g: &Gathered,
    blocks: &Blocks,
    sets: &[Set],
    node_sets: &[&Set],
    name_len: usize,
) -> netcdf::Result<()> {
    file.add_attribute("title", "octmesh")?;
    file.add_attribute("api_version", EXODUS_VERSION)?;
    file.add_attribute("version", EXODUS_VERSION)?;
    file.add_attribute("floating_point_word_size", 8i32)?;
    file.add_attribute("file_size", 1i32)?;
    file.add_attribute("maximum_name_length", name_len as i32)?;
    file.add_attribute("int64_status", 0i32)?;
    file.add_dimension("len_string", 33)?;
    file.add_dimension("len_line", 81)?;
    file.add_dimension("four", 4)?;
    file.add_dimension("len_name", name_len + 1)?;
    file.add_unlimited_dimension("time_step")?;
    file.add_dimension("num_dim", 3)?;
    file.add_dimension("num_nodes", g.coordinates.len())?;
    file.add_dimension("num_elem", g.elements.len())?;
    file.add_dimension("num_el_blk", blocks.blocks.len())?;
    variable::<f64>(file, "time_whole", &["time_step"])?;
    variable::<NcChar>(file, "coor_names", &["num_dim", "len_name"])?;
    for c in ["coordx", "coordy", "coordz"] {
        variable::<f64>(file, c, &["num_nodes"])?;
    }
    // The element blocks.
    define_list(file, "eb", "num_el_blk")?;
    for (b, &(_, _, n)) in blocks.blocks.iter().enumerate() {
        let (elems, nodes) = (
            format!("num_el_in_blk{}", b + 1),
            format!("num_nod_per_el{}", b + 1),
        );
        file.add_dimension(&elems, n)?;
        file.add_dimension(&nodes, 8)?;
        let connect = format!("connect{}", b + 1);
        variable::<i32>(file, &connect, &[&elems, &nodes])?;
        file.variable_mut(&connect)
            .expect("just added")
            .put_attribute("elem_type", "HEX8")?;
    }
    // Side sets, one per patch.
    if !sets.is_empty() {
        file.add_dimension("num_side_sets", sets.len())?;
        define_list(file, "ss", "num_side_sets")?;
        for (k, s) in sets.iter().enumerate() {
            let n = s.faces.0.len();
            let dim = format!("num_side_ss{}", k + 1);
            file.add_dimension(&dim, n)?;
            variable::<i32>(file, &format!("elem_ss{}", k + 1), &[&dim])?;
            variable::<i32>(file, &format!("side_ss{}", k + 1), &[&dim])?;
        }
    }
    // Node sets: the patches', then `hanging`.
    if !node_sets.is_empty() {
        file.add_dimension("num_node_sets", node_sets.len())?;
        define_list(file, "ns", "num_node_sets")?;
        for (k, s) in node_sets.iter().enumerate() {
            let n = s.nodes.len();
            let dim = format!("num_nod_ns{}", k + 1);
            file.add_dimension(&dim, n)?;
            variable::<i32>(file, &format!("node_ns{}", k + 1), &[&dim])?;
        }
    }
    if !g.dependencies.is_empty() {
        file.add_dimension("num_hanging_nodes", g.dependencies.len())?;
        file.add_dimension("num_hanging_parents", 4)?;
        variable::<i32>(file, "hanging_nodes", &["num_hanging_nodes"])?;
        let dims = ["num_hanging_nodes", "num_hanging_parents"];
        variable::<i32>(file, "hanging_parents", &dims)?;
        variable::<f64>(file, "hanging_weights", &dims)?;
    }
    Ok(())
}

/// Writes `list` into variable `name`, whole.
fn put_all<T: NcTypeDescriptor>(file: &mut FileMut, name: &str, list: &[T]) -> netcdf::Result<()> {
    file.variable_mut(name)
        .ok_or_else(|| netcdf::Error::from(format!("no variable {name}")))?
        .put_values(list, ..)
}

/// The netCDF data, after [`define`].
fn put(
    file: &mut FileMut,
    g: &Gathered,
    blocks: &Blocks,
    sets: &[Set],
    node_sets: &[&Set],
    name_len: usize,
) -> netcdf::Result<()> {
    let len = name_len + 1;
    put_all(file, "coor_names", &name_array(&["x", "y", "z"], len))?;
    for (a, c) in ["coordx", "coordy", "coordz"].iter().enumerate() {
        let x: Vec<f64> = g.coordinates.iter().map(|p| p[a]).collect();
        put_all(file, c, &x)?;
    }
    let ids: Vec<i32> = blocks.blocks.iter().map(|b| b.0).collect();
    let names: Vec<&str> = blocks.blocks.iter().map(|b| b.1).collect();
    put_list(file, "eb", &ids, &names, len)?;
    let mut at = 0;
    for (b, &(_, _, n)) in blocks.blocks.iter().enumerate() {
        let connect: Vec<i32> = blocks.order[at..at + n]
            .iter()
            .flat_map(|&e| g.elements[e as usize].map(|n| n as i32 + 1))
            .collect();
        put_all(file, &format!("connect{}", b + 1), &connect)?;
        at += n;
    }
    if !sets.is_empty() {
        let ids: Vec<i32> = sets.iter().map(|s| s.id).collect();
        let names: Vec<&str> = sets.iter().map(|s| s.name).collect();
        put_list(file, "ss", &ids, &names, len)?;
        for (k, s) in sets.iter().enumerate() {
            put_all(file, &format!("elem_ss{}", k + 1), &s.faces.0)?;
            put_all(file, &format!("side_ss{}", k + 1), &s.faces.1)?;
        }
    }
    if !node_sets.is_empty() {
        let ids: Vec<i32> = node_sets.iter().map(|s| s.id).collect();
        let names: Vec<&str> = node_sets.iter().map(|s| s.name).collect();
        put_list(file, "ns", &ids, &names, len)?;
        for (k, s) in node_sets.iter().enumerate() {
            put_all(file, &format!("node_ns{}", k + 1), &s.nodes)?;
        }
    }
    let h = g.dependencies.len();
    if h > 0 {
        // The `hanging` node set's list, the last node set.
        let hanging = &node_sets.last().expect("the hanging node set").nodes;
        put_all(file, "hanging_nodes", hanging)?;
        let mut parents = vec![0i32; 4 * h];
        let mut weights = vec![0f64; 4 * h];
        for (k, d) in g.dependencies.iter().enumerate() {
            let w = 1.0 / d.len() as f64;
            for (i, &m) in d.iter().enumerate() {
                parents[4 * k + i] = m as i32 + 1;
                weights[4 * k + i] = w;
            }
        }
        put_all(file, "hanging_parents", &parents)?;
        put_all(file, "hanging_weights", &weights)?;
    }
    Ok(())
}
