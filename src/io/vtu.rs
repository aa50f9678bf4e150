//! VTK XML unstructured-grid output: one binary `.vtu` per rank and a `.pvtu`
//! that lists them, for ParaView and VisIt.
//!
//! # Encoding
//!
//! Each piece is `VTKFile version="1.0"`, `byte_order="LittleEndian"`,
//! `header_type="UInt64"`, with every array in one `<AppendedData
//! encoding="raw">` block: per array a `u64` byte count, then the values as
//! little-endian bytes. Raw appended data is what VTK itself writes by default;
//! it costs no encoding time and no 4/3 size overhead (base64), and arrays go
//! straight from the caller's slices to the file.
//!
//! Two details keep the files readable by meshio (`tools/check_vtu.py`), whose
//! raw reader is stricter than VTK's; both are legal VTK:
//!
//! - a newline follows the last array, because meshio drops everything after
//!   the last `\n` before `</AppendedData>`;
//! - the arrays lie in the appended block in the *reverse* of their order in
//!   the XML. meshio re-encodes the block array by array, finds each
//!   `DataArray` by `offset` attribute and overwrites that attribute as it
//!   goes; a rewritten offset can equal the raw offset of a later array (it
//!   does for an empty piece: 24 = 2 * 12 base64 characters = 3 * 8 bytes),
//!   and the first match in document order wins. With the reversed layout the
//!   array being looked up always comes before the already rewritten ones.
//!   VTK reads each array at its `offset`, so the order does not matter to it.
//!
//! Caller fields ([`VtuPiece::point_fields`], e.g. a solution) are `Float64`
//! point arrays declared after `global_id` and `hanging`; they take part in
//! the reversed layout like every other array.
//!
//! Hexahedra use `VTK_HEXAHEDRON` (type 12) point order: the bottom face
//! counter-clockwise seen from above, then the top face.

use std::collections::HashSet;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::mesh::quality::WorstElement;
use crate::parallel::comm::{agree, Comm};
use crate::parallel::direct::DirectWriter;

/// One rank's part of a hexahedral mesh, ready to write.
#[derive(Clone, Copy, Debug)]
pub struct VtuPiece<'a> {
    /// Node coordinates, user units.
    pub points: &'a [[f64; 3]],
    /// Local point indices of each cell, `VTK_HEXAHEDRON` (type 12) order.
    pub cells: &'a [[u32; 8]],
    /// Octree level of each cell.
    pub cell_level: &'a [u8],
    /// Classification of each cell: 0 outside, 1 inside, 2 cut by the surface.
    pub cell_class: &'a [u8],
    /// The writing rank, stored as a constant `Int32` cell array `rank`.
    pub rank: u32,
    /// Global id of each independent node, -1 for hanging nodes.
    pub point_global_id: &'a [i64],
    /// Per node: 0 independent, 1 edge-hanging, 2 face-hanging.
    pub point_hanging: &'a [u8],
    /// Caller fields, written as `Float64` point arrays after `global_id`
    /// and `hanging`, in this order: `(name, one value per point)`. Names
    /// must be non-empty, free of control characters, distinct, and neither
    /// `global_id` nor `hanging`; XML special characters (`&<>"'`) in them
    /// are escaped. Every rank of [`write_parallel`] must pass the same
    /// names in the same order.
    pub point_fields: &'a [(&'a str, &'a [f64])],
}

/// `VTK_HEXAHEDRON`.
const HEX_TYPE: u8 = 12;

/// Size in bytes of the write buffer and of the chunks arrays are encoded in:
/// large, so that a 30M-cell piece (about 3 GB) goes out in a few thousand
/// big writes.
const CHUNK: usize = 1 << 20;

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Section {
    PointData,
    CellData,
    Points,
    Cells,
}

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Array {
    GlobalId,
    Hanging,
    /// `VtuPiece::point_fields[k]`.
    Field(usize),
    Level,
    Rank,
    Class,
    Points,
    Connectivity,
    Offsets,
    Types,
}

/// How one array appears in the XML and how many bytes it takes.
#[derive(Clone, Copy, Debug)]
struct ArrayDesc<'a> {
    array: Array,
    section: Section,
    /// Unescaped; see [`xml_attr`].
    name: &'a str,
    vtk_type: &'static str,
    components: usize,
    /// Bytes per point (`per_cell == false`) or per cell.
    bytes_per_item: usize,
    per_cell: bool,
}

/// octmesh's own arrays, in XML document order; [`all_arrays`] adds the
/// caller fields.
const ARRAYS: [ArrayDesc<'static>; 9] = [
    ArrayDesc {
        array: Array::GlobalId,
        section: Section::PointData,
        name: "global_id",
        vtk_type: "Int64",
        components: 1,
        bytes_per_item: 8,
        per_cell: false,
    },
    ArrayDesc {
        array: Array::Hanging,
        section: Section::PointData,
        name: "hanging",
        vtk_type: "UInt8",
        components: 1,
        bytes_per_item: 1,
        per_cell: false,
    },
    ArrayDesc {
        array: Array::Level,
        section: Section::CellData,
        name: "level",
        vtk_type: "UInt8",
        components: 1,
        bytes_per_item: 1,
        per_cell: true,
    },
    ArrayDesc {
        array: Array::Rank,
        section: Section::CellData,
        name: "rank",
        vtk_type: "Int32",
        components: 1,
        bytes_per_item: 4,
        per_cell: true,
    },
    ArrayDesc {
        array: Array::Class,
        section: Section::CellData,
        name: "class",
        vtk_type: "UInt8",
        components: 1,
        bytes_per_item: 1,
        per_cell: true,
    },
    ArrayDesc {
        array: Array::Points,
        section: Section::Points,
        name: "Points",
        vtk_type: "Float64",
        components: 3,
        bytes_per_item: 24,
        per_cell: false,
    },
    ArrayDesc {
        array: Array::Connectivity,
        section: Section::Cells,
        name: "connectivity",
        vtk_type: "Int64",
        components: 1,
        bytes_per_item: 64,
        per_cell: true,
    },
    ArrayDesc {
        array: Array::Offsets,
        section: Section::Cells,
        name: "offsets",
        vtk_type: "Int64",
        components: 1,
        bytes_per_item: 8,
        per_cell: true,
    },
    ArrayDesc {
        array: Array::Types,
        section: Section::Cells,
        name: "types",
        vtk_type: "UInt8",
        components: 1,
        bytes_per_item: 1,
        per_cell: true,
    },
];

/// Every array of a file with the point fields `fields`, in XML document
/// order: octmesh's own arrays with the fields after the last of its point
/// arrays. The `.pvtu` declares the same list (without `Cells`), so the two
/// cannot drift apart.
fn all_arrays<'a>(fields: &[&'a str]) -> Vec<ArrayDesc<'a>> {
    let mut out = Vec::with_capacity(ARRAYS.len() + fields.len());
    for d in ARRAYS {
        out.push(d);
        if d.array == Array::Hanging {
            out.extend(fields.iter().enumerate().map(|(k, &name)| ArrayDesc {
                array: Array::Field(k),
                section: Section::PointData,
                name,
                vtk_type: "Float64",
                components: 1,
                bytes_per_item: 8,
                per_cell: false,
            }));
        }
    }
    out
}

fn field_names<'a>(piece: &VtuPiece<'a>) -> Vec<&'a str> {
    piece.point_fields.iter().map(|f| f.0).collect()
}

/// Checks the names of caller point fields (see [`VtuPiece::point_fields`]).
fn check_field_names(names: &[&str]) -> Result<()> {
    let mut seen = HashSet::with_capacity(names.len());
    for (k, &name) in names.iter().enumerate() {
        let bad = if name.is_empty() {
            Some("is empty")
        } else if name
            .chars()
            .any(|c| c.is_control() || c == '\u{FFFE}' || c == '\u{FFFF}')
        {
            Some("contains a control character")
        } else if ARRAYS
            .iter()
            .any(|d| d.section == Section::PointData && d.name == name)
        {
            Some("is the name of one of octmesh's own point arrays")
        } else if !seen.insert(name) {
            Some("is given twice")
        } else {
            None
        };
        if let Some(why) = bad {
            return Err(Error::invalid(format!(
                "VTU point field {k}: name {name:?} {why}"
            )));
        }
    }
    Ok(())
}

const SECTIONS: [(Section, &str); 4] = [
    (Section::PointData, "PointData"),
    (Section::CellData, "CellData"),
    (Section::Points, "Points"),
    (Section::Cells, "Cells"),
];

fn io_err(path: &Path, e: std::io::Error) -> Error {
    Error::io(format!("cannot write '{}': {e}", path.display()))
}

/// Escapes text for a double-quoted XML attribute.
fn xml_attr(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            _ => out.push(c),
        }
    }
    out
}

/// Checks that every array has the right length and every cell index names a
/// point, so that the file is a valid mesh. Returns the rank as `Int32`.
fn validate(piece: &VtuPiece) -> Result<i32> {
    let (np, nc) = (piece.points.len(), piece.cells.len());
    let lens = [
        ("cell_level", piece.cell_level.len(), nc, "cells"),
        ("cell_class", piece.cell_class.len(), nc, "cells"),
        ("point_global_id", piece.point_global_id.len(), np, "points"),
        ("point_hanging", piece.point_hanging.len(), np, "points"),
    ];
    for (name, got, want, of) in lens {
        if got != want {
            return Err(Error::invalid(format!(
                "VTU piece: {name} has {got} entries for {want} {of}"
            )));
        }
    }
    for (k, (name, values)) in piece.point_fields.iter().enumerate() {
        if values.len() != np {
            return Err(Error::invalid(format!(
                "VTU piece: point field {k} ({name:?}) has {} entries for {np} points",
                values.len()
            )));
        }
    }
    check_field_names(&field_names(piece))?;
    if let Some(c) = piece
        .cells
        .iter()
        .position(|c| c.iter().any(|&i| i as usize >= np))
    {
        return Err(Error::invalid(format!(
            "VTU piece: cell {c} has point indices {:?}, but there are only {np} points",
            piece.cells[c]
        )));
    }
    i32::try_from(piece.rank)
        .map_err(|_| Error::invalid(format!("VTU piece: rank {} exceeds Int32", piece.rank)))
}

/// Encodes `items` as little-endian bytes through `buf` in chunks of about
/// [`CHUNK`] bytes: no copy of the whole array is ever built.
fn put<W: Write, T, const N: usize>(
    w: &mut W,
    buf: &mut Vec<u8>,
    items: impl Iterator<Item = T>,
    enc: impl Fn(T) -> [u8; N],
) -> std::io::Result<()> {
    buf.clear();
    for x in items {
        buf.extend_from_slice(&enc(x));
        if buf.len() >= CHUNK {
            w.write_all(buf)?;
            buf.clear();
        }
    }
    w.write_all(buf)?;
    buf.clear();
    Ok(())
}

/// Writes one array's values (without the byte-count header).
fn put_array<W: Write>(
    w: &mut W,
    buf: &mut Vec<u8>,
    piece: &VtuPiece,
    rank: i32,
    array: Array,
) -> std::io::Result<()> {
    let nc = piece.cells.len();
    match array {
        Array::GlobalId => put(w, buf, piece.point_global_id.iter(), |v| v.to_le_bytes()),
        // Byte arrays are already in file order.
        Array::Hanging => w.write_all(piece.point_hanging),
        Array::Field(k) => put(w, buf, piece.point_fields[k].1.iter(), |v| v.to_le_bytes()),
        Array::Level => w.write_all(piece.cell_level),
        Array::Class => w.write_all(piece.cell_class),
        Array::Rank => put(w, buf, std::iter::repeat_n(rank, nc), i32::to_le_bytes),
        Array::Points => put(w, buf, piece.points.iter().flatten(), |v| v.to_le_bytes()),
        Array::Connectivity => put(w, buf, piece.cells.iter().flatten(), |&i| {
            (i as i64).to_le_bytes()
        }),
        // VTK offsets are the end of each cell's run in `connectivity`.
        Array::Offsets => put(w, buf, (1..=nc as i64).map(|k| 8 * k), i64::to_le_bytes),
        Array::Types => put(w, buf, std::iter::repeat_n(HEX_TYPE, nc), |t| [t]),
    }
}

/// Writes one piece as a binary VTU file (VTK XML UnstructuredGrid,
/// `AppendedData` raw, `header_type` UInt64, little endian; see the module
/// documentation). Not collective.
///
/// Arrays: `Points` Float64 x 3; `Cells` with `connectivity` and `offsets`
/// Int64 and `types` UInt8 (all 12); cell data `level` UInt8, `rank` Int32,
/// `class` UInt8; point data `global_id` Int64, `hanging` UInt8, then the
/// caller's [`VtuPiece::point_fields`], Float64. A piece with no cells and no
/// points is a valid, empty file.
///
/// Errors: [`crate::ErrorKind::InvalidArgument`] if an array length does not
/// match its point or cell count, a cell names a point that does not exist,
/// or a field name is not allowed (nothing is written then); [`crate::ErrorKind::Io`] if the file cannot be
/// written.
pub fn write_vtu(path: &Path, piece: &VtuPiece) -> Result<()> {
    let rank = validate(piece)?;
    let (np, nc) = (piece.points.len(), piece.cells.len());
    let arrays = all_arrays(&field_names(piece));
    let bytes = |d: &ArrayDesc| d.bytes_per_item * if d.per_cell { nc } else { np };
    // Offsets for the reversed layout (see the module documentation).
    let mut offsets = vec![0usize; arrays.len()];
    let mut at = 0usize;
    for (k, d) in arrays.iter().enumerate().rev() {
        offsets[k] = at;
        at += 8 + bytes(d);
    }

    let write = || -> std::io::Result<()> {
        let mut w = DirectWriter::create(path)?;
        writeln!(w, "<?xml version=\"1.0\"?>")?;
        writeln!(
            w,
            "<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" \
             header_type=\"UInt64\">"
        )?;
        writeln!(w, "  <UnstructuredGrid>")?;
        writeln!(
            w,
            "    <Piece NumberOfPoints=\"{np}\" NumberOfCells=\"{nc}\">"
        )?;
        for (section, tag) in SECTIONS {
            writeln!(w, "      <{tag}>")?;
            for (k, d) in arrays.iter().enumerate() {
                if d.section == section {
                    writeln!(
                        w,
                        "        <DataArray type=\"{}\" Name=\"{}\" NumberOfComponents=\"{}\" \
                         format=\"appended\" offset=\"{}\"/>",
                        d.vtk_type,
                        xml_attr(d.name),
                        d.components,
                        offsets[k]
                    )?;
                }
            }
            writeln!(w, "      </{tag}>")?;
        }
        writeln!(w, "    </Piece>")?;
        writeln!(w, "  </UnstructuredGrid>")?;
        write!(w, "  <AppendedData encoding=\"raw\">\n   _")?;
        let mut buf = Vec::with_capacity(CHUNK + 64);
        for d in arrays.iter().rev() {
            w.write_all(&(bytes(d) as u64).to_le_bytes())?;
            put_array(&mut w, &mut buf, piece, rank, d.array)?;
        }
        // The newline is for meshio (module documentation).
        write!(w, "\n  </AppendedData>\n</VTKFile>\n")?;
        // Sync so that late write errors (full disk, quota on a network file
        // system) are reported here instead of being lost when the file closes.
        w.sync_all()
    };
    write().map_err(|e| io_err(path, e))
}

fn check_pvtu_path(path: &Path) -> Result<()> {
    if path.extension().is_some_and(|e| e == "pvtu") && path.file_stem().is_some() {
        Ok(())
    } else {
        Err(Error::invalid(format!(
            "'{}' is not a .pvtu path",
            path.display()
        )))
    }
}

/// Writes a PVTU file that references the given piece files (paths relative
/// to the PVTU's directory, escaped here) and declares the arrays
/// [`write_vtu`] writes for pieces with the point fields named
/// `point_fields` (in their order). Not collective.
///
/// Errors: [`crate::ErrorKind::InvalidArgument`] if `path` does not end in
/// `.pvtu` or a field name is not allowed (see [`VtuPiece::point_fields`]);
/// [`crate::ErrorKind::Io`] if it cannot be written.
pub fn write_pvtu(path: &Path, pieces: &[String], point_fields: &[&str]) -> Result<()> {
    check_pvtu_path(path)?;
    check_field_names(point_fields)?;
    let arrays = all_arrays(point_fields);
    let write = || -> std::io::Result<()> {
        let mut w = BufWriter::new(File::create(path)?);
        writeln!(w, "<?xml version=\"1.0\"?>")?;
        writeln!(
            w,
            "<VTKFile type=\"PUnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" \
             header_type=\"UInt64\">"
        )?;
        writeln!(w, "  <PUnstructuredGrid GhostLevel=\"0\">")?;
        // Cells are not declared in a PVTU; the other sections are.
        for (section, tag) in &SECTIONS[..3] {
            writeln!(w, "    <P{tag}>")?;
            for d in arrays.iter().filter(|d| d.section == *section) {
                writeln!(
                    w,
                    "      <PDataArray type=\"{}\" Name=\"{}\" NumberOfComponents=\"{}\"/>",
                    d.vtk_type,
                    xml_attr(d.name),
                    d.components
                )?;
            }
            writeln!(w, "    </P{tag}>")?;
        }
        for p in pieces {
            writeln!(w, "    <Piece Source=\"{}\"/>", xml_attr(p))?;
        }
        writeln!(w, "  </PUnstructuredGrid>")?;
        writeln!(w, "</VTKFile>")?;
        w.into_inner().map_err(|e| e.into_error())?.sync_all()
    };
    write().map_err(|e| io_err(path, e))
}

/// Checks that `names` are rank 0's. Collective.
fn same_as_rank_0(comm: &dyn Comm, names: &[&str]) -> Result<()> {
    // Length-prefixed, so that no two lists encode alike.
    let mut mine = Vec::new();
    for n in names {
        mine.extend_from_slice(&(n.len() as u64).to_le_bytes());
        mine.extend_from_slice(n.as_bytes());
    }
    let mut root = mine.clone();
    comm.broadcast_bytes(0, &mut root);
    if root == mine {
        Ok(())
    } else {
        Err(Error::invalid(format!(
            "VTU point fields differ between ranks: rank {} has {names:?}, unlike rank 0",
            comm.rank()
        )))
    }
}

/// File name of rank `rank`'s piece for a `.pvtu` path: `NAME_<rank>.vtu` in
/// the same directory, the rank zero-padded to at least 4 digits
/// (`out/mesh.pvtu`, 3 gives `out/mesh_0003.vtu`).
pub fn piece_path(pvtu: &Path, rank: usize) -> PathBuf {
    let stem = pvtu.file_stem().unwrap_or_default().to_string_lossy();
    pvtu.with_file_name(format!("{stem}_{rank:04}.vtu"))
}

/// Writes a mesh distributed over the ranks of `comm`: every rank writes its
/// piece to [`piece_path`]`(pvtu, rank)`, then rank 0 writes the PVTU listing
/// all of them. Collective. Returns the PVTU path.
///
/// A failure on any rank (invalid piece, unwritable directory, point field
/// names other than rank 0's) becomes an error on every rank through
/// [`crate::parallel::comm::agree`], never a hang; the PVTU is only written once every
/// piece is.
pub fn write_parallel(comm: &dyn Comm, pvtu: &Path, piece: &VtuPiece) -> Result<PathBuf> {
    let fields = field_names(piece);
    let same = same_as_rank_0(comm, &fields);
    let mine = check_pvtu_path(pvtu)
        .and(same)
        .and_then(|()| write_vtu(&piece_path(pvtu, comm.rank()), piece));
    agree(comm, mine)?;
    let index = if comm.rank() == 0 {
        // Sources are relative to the PVTU's directory, where the pieces are.
        let names: Vec<String> = (0..comm.size())
            .map(|r| {
                piece_path(pvtu, r)
                    .file_name()
                    .unwrap_or_default()
                    .to_string_lossy()
                    .into_owned()
            })
            .collect();
        write_pvtu(pvtu, &names, &fields)
    } else {
        Ok(())
    };
    agree(comm, index)?;
    Ok(pvtu.to_path_buf())
}

/// Writes a mesh: every rank its piece, rank 0 the PVTU, with the cell data
/// `level`, `rank`, `class` and the point data `global_id` (-1 for hanging
/// nodes), `hanging` and the user's `fields` (one value per local node, in
/// the mesh's local node order). Collective; returns the PVTU path.
pub fn write_mesh(
    comm: &dyn Comm,
    pvtu: &Path,
    mesh: &crate::mesh::Mesh,
    fields: &[(&str, &[f64])],
) -> Result<PathBuf> {
    let points = mesh.coordinates();
    // Levels count from the root cells of a box domain.
    let k = mesh.domain().brick.level();
    let levels: Vec<u8> = mesh.elements().iter().map(|e| e.level() - k).collect();
    let ni = mesh.num_independent();
    let global: Vec<i64> = (0..mesh.num_nodes())
        .map(|i| if i < ni { mesh.global_id(i) as i64 } else { -1 })
        .collect();
    let hanging: Vec<u8> = (0..mesh.num_nodes())
        .map(|i| match i.checked_sub(ni) {
            None => 0,
            Some(k) if k < mesh.num_face_hanging() => 2,
            Some(_) => 1,
        })
        .collect();
    let piece = VtuPiece {
        points: &points,
        cells: mesh.connectivity(),
        cell_level: &levels,
        cell_class: mesh.element_class(),
        rank: comm.rank() as u32,
        point_global_id: &global,
        point_hanging: &hanging,
        point_fields: fields,
    };
    write_parallel(comm, pvtu, &piece)
}

/// Writes a mesh that rank 0 holds whole ([`crate::io::gathered`], the
/// conforming mesh of [`crate::mesh::conforming`]): rank 0's piece holds
/// every node and hexahedron in the gathered numbering, the other ranks'
/// pieces are empty, and rank 0 writes the PVTU. Cell data `level` and
/// `class` are those of the octree leaf each hexahedron's centre lies in
/// ([`crate::io::gathered::Gathered::element_level`]; 0 when the gathered
/// mesh has none), `rank` is 0 (the writer's); point data `global_id` is
/// the node's number in the gathered mesh (that of the Gmsh, Abaqus,
/// Exodus and CGNS files, less one) and `hanging` is 0 for the
/// independent nodes, 1 and 2 for edge- and face-hanging ones. Apart from
/// the piece names the files are the same on any number of ranks.
/// Collective; returns the PVTU path.
pub fn write_gathered(
    comm: &dyn Comm,
    pvtu: &Path,
    g: &crate::io::gathered::Gathered,
) -> Result<PathBuf> {
    let n = g.coordinates.len();
    let cells = g.elements.len();
    let or_zeros = |v: &[u8]| {
        if v.len() == cells {
            v.to_vec()
        } else {
            vec![0; cells]
        }
    };
    let (level, class) = (or_zeros(&g.element_level), or_zeros(&g.element_class));
    let global: Vec<i64> = (0..n as i64).collect();
    let hanging: Vec<u8> = (0..n)
        .map(|i| match i.checked_sub(g.num_independent) {
            None => 0,
            Some(k) if g.dependencies[k].len() == 4 => 2,
            Some(_) => 1,
        })
        .collect();
    let piece = VtuPiece {
        points: &g.coordinates,
        cells: &g.elements,
        cell_level: &level,
        cell_class: &class,
        rank: 0,
        point_global_id: &global,
        point_hanging: &hanging,
        point_fields: &[],
    };
    write_parallel(comm, pvtu, &piece)
}

/// Writes `worst` ([`crate::mesh::Mesh::worst_elements`]) as one VTU file for ParaView:
/// each element with its own 8 points (none shared), cell data `level`,
/// `class` (and `rank`, 0: the writer's), point data `scaled_jacobian`
/// (the element's), `corner_scaled_jacobian` (the corner's), `element`
/// (global number) and `owner_rank`; `global_id` is -1. Not collective.
pub fn write_worst_vtu(path: &Path, worst: &[WorstElement]) -> Result<()> {
    let points: Vec<[f64; 3]> = worst.iter().flat_map(|w| w.corners).collect();
    let cells: Vec<[u32; 8]> = (0..worst.len() as u32)
        .map(|k| std::array::from_fn(|v| 8 * k + v as u32))
        .collect();
    let level: Vec<u8> = worst.iter().map(|w| w.level).collect();
    let class: Vec<u8> = worst.iter().map(|w| w.class).collect();
    let per_point = |f: &dyn Fn(&WorstElement) -> f64| -> Vec<f64> {
        worst.iter().flat_map(|w| [f(w); 8]).collect()
    };
    let value = per_point(&|w| w.scaled_jacobian);
    let element = per_point(&|w| w.global as f64);
    let owner = per_point(&|w| w.rank as f64);
    let corner: Vec<f64> = worst.iter().flat_map(|w| w.corner_values).collect();
    let none = vec![-1i64; points.len()];
    let independent = vec![0u8; points.len()];
    let fields: [(&str, &[f64]); 4] = [
        ("scaled_jacobian", &value),
        ("corner_scaled_jacobian", &corner),
        ("element", &element),
        ("owner_rank", &owner),
    ];
    write_vtu(
        path,
        &VtuPiece {
            points: &points,
            cells: &cells,
            cell_level: &level,
            cell_class: &class,
            rank: 0,
            point_global_id: &none,
            point_hanging: &independent,
            point_fields: &fields,
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::ErrorKind;
    use crate::parallel::comm::SerialComm;
    use std::process::Command;
    use std::sync::atomic::{AtomicUsize, Ordering};

    /// A fresh scratch directory under the system temp dir.
    fn scratch(tag: &str) -> PathBuf {
        static N: AtomicUsize = AtomicUsize::new(0);
        let d = std::env::temp_dir().join(format!(
            "octmesh_vtu_{}_{}_{tag}",
            std::process::id(),
            N.fetch_add(1, Ordering::Relaxed)
        ));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// Two unit cubes sharing the face x = 1: 12 points on a 3 x 2 x 2 grid.
    struct Mesh {
        points: Vec<[f64; 3]>,
        cells: Vec<[u32; 8]>,
        level: Vec<u8>,
        class: Vec<u8>,
        gid: Vec<i64>,
        hanging: Vec<u8>,
    }

    fn two_cubes() -> Mesh {
        let p = |i: u32, j: u32, k: u32| i + 3 * (j + 2 * k);
        let mut points = Vec::new();
        for k in 0..2 {
            for j in 0..2 {
                for i in 0..3 {
                    points.push([i as f64, j as f64, k as f64]);
                }
            }
        }
        let cells: Vec<[u32; 8]> = (0..2)
            .map(|i| {
                [
                    p(i, 0, 0),
                    p(i + 1, 0, 0),
                    p(i + 1, 1, 0),
                    p(i, 1, 0),
                    p(i, 0, 1),
                    p(i + 1, 0, 1),
                    p(i + 1, 1, 1),
                    p(i, 1, 1),
                ]
            })
            .collect();
        // Points 10 and 11 play hanging nodes; the others are numbered 0..=9.
        let hanging = (0..12)
            .map(|i| [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 2][i])
            .collect();
        let gid = (0..12).map(|i| if i < 10 { i } else { -1 }).collect();
        Mesh {
            points,
            cells,
            level: vec![1, 2],
            class: vec![1, 2],
            gid,
            hanging,
        }
    }

    fn piece(m: &Mesh, rank: u32) -> VtuPiece<'_> {
        VtuPiece {
            points: &m.points,
            cells: &m.cells,
            cell_level: &m.level,
            cell_class: &m.class,
            rank,
            point_global_id: &m.gid,
            point_hanging: &m.hanging,
            point_fields: &[],
        }
    }

    const EMPTY: VtuPiece<'static> = VtuPiece {
        points: &[],
        cells: &[],
        cell_level: &[],
        cell_class: &[],
        rank: 1,
        point_global_id: &[],
        point_hanging: &[],
        point_fields: &[],
    };

    fn attr<'s>(tag: &'s str, name: &str) -> &'s str {
        let key = format!(" {name}=\"");
        let start = tag
            .find(&key)
            .unwrap_or_else(|| panic!("no {name} in {tag}"))
            + key.len();
        &tag[start..start + tag[start..].find('"').unwrap()]
    }

    /// A reader for exactly the format written here: checks the framing and
    /// returns (XML header, name -> (type, components, payload)).
    #[allow(clippy::type_complexity)]
    fn read_back(path: &Path) -> (String, Vec<(String, String, String, Vec<u8>)>) {
        let bytes = std::fs::read(path).unwrap();
        let open = b"<AppendedData encoding=\"raw\">";
        let at = bytes
            .windows(open.len())
            .position(|w| w == open)
            .expect("no raw AppendedData");
        let xml = String::from_utf8(bytes[..at].to_vec()).unwrap();
        let mut i = at + open.len();
        while bytes[i].is_ascii_whitespace() {
            i += 1;
        }
        assert_eq!(bytes[i], b'_', "appended data must start with '_'");
        let data = i + 1;
        let tail = b"\n  </AppendedData>\n</VTKFile>\n";
        assert!(bytes.ends_with(tail), "bad file tail");
        let end = bytes.len() - tail.len();

        let mut arrays = Vec::new();
        let mut spans = Vec::new();
        for tag in xml.split("<DataArray").skip(1) {
            let tag = &tag[..tag.find("/>").unwrap()];
            assert_eq!(attr(tag, "format"), "appended");
            let off: usize = attr(tag, "offset").parse().unwrap();
            let n = u64::from_le_bytes(bytes[data + off..data + off + 8].try_into().unwrap());
            let payload = bytes[data + off + 8..data + off + 8 + n as usize].to_vec();
            spans.push((off, 8 + n as usize));
            arrays.push((
                attr(tag, "Name").to_string(),
                attr(tag, "type").to_string(),
                attr(tag, "NumberOfComponents").to_string(),
                payload,
            ));
        }
        // The blocks tile the appended data exactly: no gap, overlap or junk.
        spans.sort();
        let mut pos = 0;
        for (off, len) in spans {
            assert_eq!(off, pos, "gap or overlap in appended data");
            pos += len;
        }
        assert_eq!(data + pos, end, "appended data length");
        (xml, arrays)
    }

    fn le<const N: usize>(b: &[u8]) -> Vec<[u8; N]> {
        assert_eq!(b.len() % N, 0);
        b.chunks(N).map(|c| c.try_into().unwrap()).collect()
    }

    #[test]
    fn vtu_structure_and_bytes_read_back() {
        let dir = scratch("structure");
        let m = two_cubes();
        let path = dir.join("two.vtu");
        write_vtu(&path, &piece(&m, 3)).unwrap();
        let (xml, arrays) = read_back(&path);
        assert!(xml.starts_with("<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\""));
        for s in [
            "version=\"1.0\"",
            "byte_order=\"LittleEndian\"",
            "header_type=\"UInt64\"",
            "<Piece NumberOfPoints=\"12\" NumberOfCells=\"2\">",
        ] {
            assert!(xml.contains(s), "missing {s}");
        }
        // Document order of the sections.
        let at: Vec<usize> = ["<PointData>", "<CellData>", "<Points>", "<Cells>"]
            .iter()
            .map(|t| xml.find(t).unwrap_or_else(|| panic!("missing {t}")))
            .collect();
        assert!(at.windows(2).all(|w| w[0] < w[1]), "section order {at:?}");
        let names: Vec<&str> = arrays.iter().map(|a| a.0.as_str()).collect();
        assert_eq!(
            names,
            [
                "global_id",
                "hanging",
                "level",
                "rank",
                "class",
                "Points",
                "connectivity",
                "offsets",
                "types"
            ]
        );
        for (name, ty, comps, b) in &arrays {
            match name.as_str() {
                "Points" => {
                    assert_eq!((ty.as_str(), comps.as_str()), ("Float64", "3"));
                    let v: Vec<f64> = le::<8>(b).into_iter().map(f64::from_le_bytes).collect();
                    assert_eq!(v, m.points.concat());
                }
                "connectivity" => {
                    assert_eq!(ty, "Int64");
                    let v: Vec<i64> = le::<8>(b).into_iter().map(i64::from_le_bytes).collect();
                    let want: Vec<i64> = m.cells.concat().iter().map(|&i| i as i64).collect();
                    assert_eq!(v, want);
                }
                "offsets" => {
                    assert_eq!(ty, "Int64");
                    let v: Vec<i64> = le::<8>(b).into_iter().map(i64::from_le_bytes).collect();
                    assert_eq!(v, [8, 16]);
                }
                "types" => assert_eq!((ty.as_str(), b.as_slice()), ("UInt8", &[12u8, 12][..])),
                "level" => assert_eq!((ty.as_str(), b.as_slice()), ("UInt8", &m.level[..])),
                "class" => assert_eq!((ty.as_str(), b.as_slice()), ("UInt8", &m.class[..])),
                "rank" => {
                    assert_eq!(ty, "Int32");
                    let v: Vec<i32> = le::<4>(b).into_iter().map(i32::from_le_bytes).collect();
                    assert_eq!(v, [3, 3]);
                }
                "global_id" => {
                    assert_eq!(ty, "Int64");
                    let v: Vec<i64> = le::<8>(b).into_iter().map(i64::from_le_bytes).collect();
                    assert_eq!(v, m.gid);
                }
                "hanging" => assert_eq!((ty.as_str(), b.as_slice()), ("UInt8", &m.hanging[..])),
                other => panic!("unexpected array {other}"),
            }
            if name != "Points" {
                assert_eq!(comps, "1", "{name}");
            }
        }
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn empty_piece_is_a_complete_file() {
        let dir = scratch("empty");
        let path = dir.join("empty.vtu");
        write_vtu(&path, &EMPTY).unwrap();
        let (xml, arrays) = read_back(&path);
        assert!(xml.contains("<Piece NumberOfPoints=\"0\" NumberOfCells=\"0\">"));
        assert_eq!(arrays.len(), 9);
        assert!(arrays.iter().all(|a| a.3.is_empty()));
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn pvtu_lists_arrays_and_pieces() {
        let dir = scratch("pvtu");
        let path = dir.join("m.pvtu");
        write_pvtu(
            &path,
            &["m_0000.vtu".into(), "a&b\".vtu".into()],
            &["u", "<v>"],
        )
        .unwrap();
        let s = std::fs::read_to_string(&path).unwrap();
        assert!(s.contains("<VTKFile type=\"PUnstructuredGrid\""));
        for d in &ARRAYS {
            let decl = format!("<PDataArray type=\"{}\" Name=\"{}\"", d.vtk_type, d.name);
            assert_eq!(s.contains(&decl), d.section != Section::Cells, "{decl}");
        }
        // The fields follow hanging, inside PPointData.
        let hang = s.find("Name=\"hanging\"").unwrap();
        let u = s
            .find("<PDataArray type=\"Float64\" Name=\"u\" NumberOfComponents=\"1\"/>")
            .unwrap();
        let v = s.find("Name=\"&lt;v&gt;\"").unwrap();
        let end = s.find("</PPointData>").unwrap();
        assert!(hang < u && u < v && v < end, "{s}");
        let pp = s.find("<PPointData>").unwrap();
        let pc = s.find("<PCellData>").unwrap();
        let pts = s.find("<PPoints>").unwrap();
        assert!(pp < pc && pc < pts);
        assert!(s.contains("<Piece Source=\"m_0000.vtu\"/>"));
        assert!(s.contains("<Piece Source=\"a&amp;b&quot;.vtu\"/>"));
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn piece_path_pads_rank() {
        let p = Path::new("out/mesh.pvtu");
        assert_eq!(piece_path(p, 3), Path::new("out/mesh_0003.vtu"));
        assert_eq!(piece_path(p, 12345), Path::new("out/mesh_12345.vtu"));
        assert_eq!(piece_path(Path::new("m.pvtu"), 0), Path::new("m_0000.vtu"));
    }

    #[test]
    fn bad_lengths_and_indices_are_invalid_arguments() {
        let dir = scratch("invalid");
        let path = dir.join("bad.vtu");
        let m = two_cubes();
        let short_u8 = [1u8];
        let short_i64 = [0i64; 11];
        // A cell pointing one past the last point.
        let mut cells = m.cells.clone();
        cells[1][6] = 12;
        let x: Vec<f64> = m.points.iter().map(|p| p[0]).collect();
        let bad = [
            VtuPiece {
                cell_level: &short_u8,
                ..piece(&m, 0)
            },
            VtuPiece {
                cell_class: &short_u8,
                ..piece(&m, 0)
            },
            VtuPiece {
                point_global_id: &short_i64,
                ..piece(&m, 0)
            },
            VtuPiece {
                point_hanging: &m.hanging[..11],
                ..piece(&m, 0)
            },
            VtuPiece {
                cells: &cells,
                ..piece(&m, 0)
            },
            // Cells without points.
            VtuPiece {
                points: &[],
                point_global_id: &[],
                point_hanging: &[],
                ..piece(&m, 0)
            },
            VtuPiece {
                rank: u32::MAX,
                ..piece(&m, 0)
            },
            // Point fields: short, empty name, control character, reserved
            // name, duplicate.
            VtuPiece {
                point_fields: &[("u", &x[..11])],
                ..piece(&m, 0)
            },
            VtuPiece {
                point_fields: &[("", &x)],
                ..piece(&m, 0)
            },
            VtuPiece {
                point_fields: &[("a\nb", &x)],
                ..piece(&m, 0)
            },
            VtuPiece {
                point_fields: &[("hanging", &x)],
                ..piece(&m, 0)
            },
            VtuPiece {
                point_fields: &[("u", &x), ("u", &x)],
                ..piece(&m, 0)
            },
        ];
        for (k, p) in bad.iter().enumerate() {
            let e = write_vtu(&path, p).unwrap_err();
            assert_eq!(e.kind(), ErrorKind::InvalidArgument, "case {k}: {e}");
            assert!(!path.exists(), "case {k} created a file");
            let e = write_parallel(&SerialComm, &dir.join("bad.pvtu"), p).unwrap_err();
            assert_eq!(e.kind(), ErrorKind::InvalidArgument, "case {k}: {e}");
            assert!(!dir.join("bad.pvtu").exists(), "case {k} wrote the PVTU");
            assert!(!dir.join("bad_0000.vtu").exists(), "case {k} wrote a piece");
        }
        for names in [&["global_id"][..], &[""], &["x", "x"]] {
            let e = write_pvtu(&dir.join("bad.pvtu"), &[], names).unwrap_err();
            assert_eq!(e.kind(), ErrorKind::InvalidArgument, "{names:?}");
            assert!(!dir.join("bad.pvtu").exists(), "{names:?}");
        }
        for p in ["m.vtu", "m", "m.pvtu.tmp"] {
            let e = write_pvtu(&dir.join(p), &[], &[]).unwrap_err();
            assert_eq!(e.kind(), ErrorKind::InvalidArgument, "{p}");
            let e = write_parallel(&SerialComm, &dir.join(p), &piece(&m, 0)).unwrap_err();
            assert_eq!(e.kind(), ErrorKind::InvalidArgument, "{p}");
        }
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn missing_directory_is_an_io_error() {
        let dir = scratch("io").join("does_not_exist");
        let m = two_cubes();
        let e = write_vtu(&dir.join("a.vtu"), &piece(&m, 0)).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Io);
        assert!(e.message().contains("does_not_exist"), "{e}");
        let e = write_pvtu(&dir.join("a.pvtu"), &["a_0000.vtu".into()], &[]).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Io);
        let e = write_parallel(&SerialComm, &dir.join("a.pvtu"), &piece(&m, 0)).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Io);
        assert!(e.message().contains("a_0000.vtu"), "{e}");
        std::fs::remove_dir_all(dir.parent().unwrap()).ok();
    }

    /// A Python that can import meshio: `$OCTMESH_PYTHON`, else `python3`,
    /// else `/usr/bin/python3` (a pyenv `python3` first in PATH does not see
    /// Debian's python3-meshio). Panics, never skips, when there is none.
    fn python_with_meshio() -> String {
        let candidates: Vec<String> = match std::env::var("OCTMESH_PYTHON") {
            Ok(p) => vec![p],
            Err(_) => vec!["python3".into(), "/usr/bin/python3".into()],
        };
        for c in &candidates {
            let ok = Command::new(c)
                .args(["-c", "import meshio"])
                .output()
                .is_ok_and(|o| o.status.success());
            if ok {
                return c.clone();
            }
        }
        panic!(
            "no Python with meshio found (tried {candidates:?}): install Debian's python3-meshio \
             (apt-get install python3-meshio) or set OCTMESH_PYTHON"
        );
    }

    fn check_vtu(pvtu: &Path) -> std::process::Output {
        let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tools/check_vtu.py");
        Command::new(python_with_meshio())
            .arg(script)
            .arg(pvtu)
            .output()
            .expect("cannot run tools/check_vtu.py")
    }

    fn check_json(pvtu: &Path) -> serde_json::Value {
        let out = check_vtu(pvtu);
        assert!(
            out.status.success(),
            "check_vtu.py failed: {}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        serde_json::from_slice(&out.stdout).expect("check_vtu.py printed no JSON")
    }

    #[test]
    fn meshio_reads_two_pieces_one_empty() {
        let dir = scratch("meshio");
        let pvtu = dir.join("mesh.pvtu");
        let m = two_cubes();
        write_vtu(&piece_path(&pvtu, 0), &piece(&m, 0)).unwrap();
        write_vtu(&piece_path(&pvtu, 1), &EMPTY).unwrap();
        write_pvtu(
            &pvtu,
            &["mesh_0000.vtu".into(), "mesh_0001.vtu".into()],
            &[],
        )
        .unwrap();
        let j = check_json(&pvtu);
        assert_eq!(j["pieces"], 2, "{j}");
        assert_eq!(j["cells"], 2, "{j}");
        assert_eq!(j["points"], 12, "{j}");
        assert!((j["volume"].as_f64().unwrap() - 2.0).abs() < 1e-12, "{j}");
        assert_eq!(j["levels"], serde_json::json!({"1": 1, "2": 1}), "{j}");
        assert_eq!(j["hanging_points"], 2, "{j}");
        assert_eq!(j["min_global_id"], 0, "{j}");
        assert_eq!(j["max_global_id"], 9, "{j}");
        std::fs::remove_dir_all(&dir).ok();
    }

    /// 18 points and 2 cells: with the arrays in document order in the
    /// appended block, meshio would take one array's offset for another's
    /// (module documentation); the reversed layout must read back right.
    #[test]
    fn meshio_reads_sizes_that_trip_offset_lookup() {
        let dir = scratch("layout");
        let mut m = two_cubes();
        // Six unused independent points on the plane z = 2.
        for j in 0..2 {
            for i in 0..3 {
                m.points.push([i as f64, j as f64, 2.0]);
                m.gid.push(10 + m.gid.len() as i64);
                m.hanging.push(0);
            }
        }
        let pvtu = write_parallel(&SerialComm, &dir.join("l.pvtu"), &piece(&m, 0)).unwrap();
        let j = check_json(&pvtu);
        assert_eq!(j["points"], 18, "{j}");
        assert!((j["volume"].as_f64().unwrap() - 2.0).abs() < 1e-12, "{j}");
        assert_eq!(j["levels"], serde_json::json!({"1": 1, "2": 1}), "{j}");
        assert_eq!(j["hanging_points"], 2, "{j}");
        assert_eq!(
            (j["min_global_id"].clone(), j["max_global_id"].clone()),
            (0.into(), 27.into()),
            "{j}"
        );
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn write_parallel_serial_is_readable() {
        let dir = scratch("parallel");
        let m = two_cubes();
        let pvtu = write_parallel(&SerialComm, &dir.join("p.pvtu"), &piece(&m, 0)).unwrap();
        assert_eq!(pvtu, dir.join("p.pvtu"));
        assert!(dir.join("p_0000.vtu").exists());
        let j = check_json(&pvtu);
        assert_eq!(
            (j["pieces"].clone(), j["cells"].clone()),
            (1.into(), 2.into()),
            "{j}"
        );
        assert!((j["volume"].as_f64().unwrap() - 2.0).abs() < 1e-12, "{j}");
        std::fs::remove_dir_all(&dir).ok();
    }

    /// x and y + 10 z of each point of `m`.
    fn xy_fields(m: &Mesh) -> (Vec<f64>, Vec<f64>) {
        let x = m.points.iter().map(|p| p[0]).collect();
        let y = m.points.iter().map(|p| p[1] + 10.0 * p[2]).collect();
        (x, y)
    }

    #[test]
    fn point_fields_follow_hanging_and_read_back() {
        let dir = scratch("fields");
        let m = two_cubes();
        let (x, y) = xy_fields(&m);
        let path = dir.join("f.vtu");
        let fields = [("x", &x[..]), ("y&\"z\"", &y[..])];
        let p = VtuPiece {
            point_fields: &fields,
            ..piece(&m, 0)
        };
        write_vtu(&path, &p).unwrap();
        let (xml, arrays) = read_back(&path);
        assert!(xml.contains("Name=\"y&amp;&quot;z&quot;\""), "{xml}");
        let names: Vec<&str> = arrays.iter().map(|a| a.0.as_str()).collect();
        assert_eq!(
            names[..5],
            ["global_id", "hanging", "x", "y&amp;&quot;z&quot;", "level"]
        );
        assert_eq!(arrays.len(), 11);
        for (k, want) in [(2, &x), (3, &y)] {
            let (_, ty, comps, b) = &arrays[k];
            assert_eq!((ty.as_str(), comps.as_str()), ("Float64", "1"));
            let v: Vec<f64> = le::<8>(b).into_iter().map(f64::from_le_bytes).collect();
            assert_eq!(&v, want);
        }
        // The PointData section holds exactly the four point arrays.
        let pd = &xml[xml.find("<PointData>").unwrap()..xml.find("</PointData>").unwrap()];
        assert_eq!(pd.matches("<DataArray").count(), 4, "{pd}");
        std::fs::remove_dir_all(&dir).ok();
    }

    /// Point fields round-trip through meshio, with one empty piece and
    /// sizes where the offsets would trip meshio without the reversed layout.
    #[test]
    fn meshio_reads_point_fields() {
        let dir = scratch("meshio_fields");
        let pvtu = dir.join("f.pvtu");
        let mut m = two_cubes();
        for i in 0..6 {
            m.points.push([i as f64, 0.5, 2.0]);
            m.gid.push(10 + i);
            m.hanging.push(0);
        }
        let (x, y) = xy_fields(&m);
        let fields = [("x", &x[..]), ("y<&>\"'", &y[..])];
        let p = VtuPiece {
            point_fields: &fields,
            ..piece(&m, 0)
        };
        let names = ["x", "y<&>\"'"];
        let no_values: [(&str, &[f64]); 2] = [("x", &[]), ("y<&>\"'", &[])];
        let empty = VtuPiece {
            point_fields: &no_values,
            ..EMPTY
        };
        write_vtu(&piece_path(&pvtu, 0), &p).unwrap();
        write_vtu(&piece_path(&pvtu, 1), &empty).unwrap();
        write_pvtu(&pvtu, &["f_0000.vtu".into(), "f_0001.vtu".into()], &names).unwrap();
        let j = check_json(&pvtu);
        assert_eq!(j["points"], 18, "{j}");
        assert!((j["volume"].as_f64().unwrap() - 2.0).abs() < 1e-12, "{j}");
        let f = &j["fields"];
        assert_eq!(f.as_object().map(|o| o.len()), Some(2), "{j}");
        let sum = |v: &[f64]| v.iter().sum::<f64>();
        for (name, v) in [("x", &x), ("y<&>\"'", &y)] {
            let min = v.iter().copied().fold(f64::INFINITY, f64::min);
            let max = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            assert_eq!(f[name]["min"].as_f64(), Some(min), "{name}: {j}");
            assert_eq!(f[name]["max"].as_f64(), Some(max), "{name}: {j}");
            let s = f[name]["sum"].as_f64().unwrap();
            assert!((s - sum(v)).abs() < 1e-9, "{name}: {s} vs {}", sum(v));
        }
        // Without fields the JSON still has the key, empty.
        let plain = write_parallel(&SerialComm, &dir.join("plain.pvtu"), &piece(&m, 0)).unwrap();
        assert_eq!(check_json(&plain)["fields"], serde_json::json!({}));
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn check_vtu_rejects_pieces_without_the_declared_fields() {
        let dir = scratch("reject_fields");
        let pvtu = dir.join("r.pvtu");
        let m = two_cubes();
        let (x, _) = xy_fields(&m);
        // Declared in the PVTU, missing in the piece.
        write_vtu(&piece_path(&pvtu, 0), &piece(&m, 0)).unwrap();
        write_pvtu(&pvtu, &["r_0000.vtu".into()], &["x"]).unwrap();
        assert!(!check_vtu(&pvtu).status.success(), "missing field accepted");
        // In the piece, not declared.
        let fields = [("x", &x[..])];
        let p = VtuPiece {
            point_fields: &fields,
            ..piece(&m, 0)
        };
        write_vtu(&piece_path(&pvtu, 0), &p).unwrap();
        write_pvtu(&pvtu, &["r_0000.vtu".into()], &[]).unwrap();
        assert!(
            !check_vtu(&pvtu).status.success(),
            "undeclared field accepted"
        );
        // Both agree: accepted.
        write_pvtu(&pvtu, &["r_0000.vtu".into()], &["x"]).unwrap();
        let j = check_json(&pvtu);
        assert_eq!(j["fields"]["x"]["max"], 2.0, "{j}");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn check_vtu_rejects_missing_and_corrupt_pieces() {
        let dir = scratch("reject");
        let pvtu = dir.join("x.pvtu");
        write_pvtu(&pvtu, &["x_0000.vtu".into()], &[]).unwrap();
        let out = check_vtu(&pvtu);
        assert!(!out.status.success(), "missing piece accepted");
        // A piece cut short inside its appended data.
        let m = two_cubes();
        let piece0 = piece_path(&pvtu, 0);
        write_vtu(&piece0, &piece(&m, 0)).unwrap();
        let bytes = std::fs::read(&piece0).unwrap();
        std::fs::write(&piece0, &bytes[..bytes.len() - 100]).unwrap();
        let out = check_vtu(&pvtu);
        assert!(!out.status.success(), "truncated piece accepted");
        std::fs::remove_dir_all(&dir).ok();
    }
}
