//! The boundary faces as VTK XML polygon data: one binary `.vtp` per rank
//! and a `.pvtp` listing them, written beside the mesh's PVTU by `--out`
//! (`mesh.pvtu` gives `mesh_boundary.pvtp` and `mesh_boundary_<rank>.vtp`).
//!
//! One quadrilateral per boundary face ([`crate::mesh::faces`]: whole
//! faces, and the pieces next to dropped finer leaves), its four corners
//! counter-clockwise seen from outside the mesh, each face with its own
//! points (the file is for looking at, not for topology). Cell data:
//! `patch` (`Int32`, the patch id) and `element` (`Int64`, the global
//! number of the element the face bounds). The patch names are listed in
//! a comment at the top of every file: `patch 0 = xmin, patch 1 = xmax,
//! ...`.
//!
//! Encoding as in [`super::vtu`]: appended raw data, `UInt64` headers,
//! arrays stored in the reverse of their XML order so that meshio reads
//! the files too.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::mesh::patches::PatchNames;
use crate::mesh::{Faces, Mesh, Other};
use crate::parallel::comm::{agree, Comm};
use crate::parallel::direct::DirectWriter;

/// The PVTP path of the boundary beside `pvtu`: `NAME_boundary.pvtp`.
pub fn boundary_path(pvtu: &Path) -> PathBuf {
    let stem = pvtu.file_stem().unwrap_or_default().to_string_lossy();
    pvtu.with_file_name(format!("{stem}_boundary.pvtp"))
}

/// Rank `rank`'s piece of `pvtp`: `NAME_<rank>.vtp`, 4 digits at least.
pub fn piece_path(pvtp: &Path, rank: usize) -> PathBuf {
    let stem = pvtp.file_stem().unwrap_or_default().to_string_lossy();
    pvtp.with_file_name(format!("{stem}_{rank:04}.vtp"))
}

fn io_err(path: &Path, e: std::io::Error) -> Error {
    Error::io(format!("cannot write '{}': {e}", path.display()))
}

/// The patch list as an XML comment (names are patch words: no `--`).
fn names_comment(names: &PatchNames) -> String {
    let list: Vec<String> = names
        .names()
        .iter()
        .enumerate()
        .map(|(k, n)| format!("patch {k} = {n}"))
        .collect();
    format!("<!-- octmesh boundary faces: {} -->", list.join(", "))
}

/// The XML declaration, the patch list and the opening `VTKFile` tag.
fn header(w: &mut impl Write, kind: &str, names: &PatchNames) -> std::io::Result<()> {
    writeln!(w, "<?xml version=\"1.0\"?>")?;
    writeln!(w, "{}", names_comment(names))?;
    writeln!(
        w,
        "<VTKFile type=\"{kind}\" version=\"1.0\" byte_order=\"LittleEndian\" \
         header_type=\"UInt64\">"
    )
}

/// One rank's boundary faces as arrays.
struct Piece {
    points: Vec<f64>,
    patch: Vec<i32>,
    element: Vec<i64>,
}

fn piece_of(mesh: &Mesh, faces: &Faces) -> Result<Piece> {
    let end = faces.halo_range().start;
    let list = &faces.faces()[faces.num_internal()..end];
    let mut p = Piece {
        points: Vec::with_capacity(12 * list.len()),
        patch: Vec::with_capacity(list.len()),
        element: Vec::with_capacity(list.len()),
    };
    let mut corners = Vec::with_capacity(4 * list.len());
    for f in list {
        let Other::Patch(id) = f.other() else {
            continue;
        };
        corners.extend(f.corners());
        p.patch.push(id as i32);
        p.element
            .push(mesh.global_element(f.owner() as usize) as i64);
    }
    // Where the nodes are: moved on a snapped mesh.
    for x in mesh.point_positions(&corners)? {
        p.points.extend(x);
    }
    Ok(p)
}

/// Writes one piece (not collective).
fn write_piece(path: &Path, piece: &Piece, names: &PatchNames) -> Result<()> {
    let n = piece.patch.len();
    // (XML section, name, type, components, bytes), in XML order.
    let arrays: [(&str, &str, &str, usize, usize); 5] = [
        ("CellData", "patch", "Int32", 1, 4 * n),
        ("CellData", "element", "Int64", 1, 8 * n),
        ("Points", "Points", "Float64", 3, 8 * 12 * n),
        ("Polys", "connectivity", "Int64", 1, 8 * 4 * n),
        ("Polys", "offsets", "Int64", 1, 8 * n),
    ];
    let mut offsets = [0usize; 5];
    let mut at = 0;
    for k in (0..5).rev() {
        offsets[k] = at;
        at += 8 + arrays[k].4;
    }
    let write = || -> std::io::Result<()> {
        // Values go one by one: a small buffer in front of the direct one.
        let mut w = BufWriter::with_capacity(1 << 16, DirectWriter::create(path)?);
        header(&mut w, "PolyData", names)?;
        writeln!(w, "  <PolyData>")?;
        writeln!(
            w,
            "    <Piece NumberOfPoints=\"{}\" NumberOfVerts=\"0\" NumberOfLines=\"0\" \
             NumberOfStrips=\"0\" NumberOfPolys=\"{n}\">",
            4 * n
        )?;
        for section in ["CellData", "Points", "Polys"] {
            writeln!(w, "      <{section}>")?;
            for (k, a) in arrays.iter().enumerate().filter(|(_, a)| a.0 == section) {
                writeln!(
                    w,
                    "        <DataArray type=\"{}\" Name=\"{}\" NumberOfComponents=\"{}\" \
                     format=\"appended\" offset=\"{}\"/>",
                    a.2, a.1, a.3, offsets[k]
                )?;
            }
            writeln!(w, "      </{section}>")?;
        }
        writeln!(w, "    </Piece>")?;
        writeln!(w, "  </PolyData>")?;
        write!(w, "  <AppendedData encoding=\"raw\">\n   _")?;
        for k in (0..5).rev() {
            w.write_all(&(arrays[k].4 as u64).to_le_bytes())?;
            match k {
                0 => piece
                    .patch
                    .iter()
                    .try_for_each(|v| w.write_all(&v.to_le_bytes()))?,
                1 => piece
                    .element
                    .iter()
                    .try_for_each(|v| w.write_all(&v.to_le_bytes()))?,
                2 => piece
                    .points
                    .iter()
                    .try_for_each(|v| w.write_all(&v.to_le_bytes()))?,
                3 => (0..4 * n as i64).try_for_each(|v| w.write_all(&v.to_le_bytes()))?,
                _ => (1..=n as i64).try_for_each(|v| w.write_all(&(4 * v).to_le_bytes()))?,
            }
        }
        // The newline is for meshio (see `vtu`).
        write!(w, "\n  </AppendedData>\n</VTKFile>\n")?;
        w.into_inner().map_err(|e| e.into_error())?.sync_all()
    };
    write().map_err(|e| io_err(path, e))
}

/// Writes the PVTP that lists the pieces (rank 0).
fn write_index(pvtp: &Path, ranks: usize, names: &PatchNames) -> Result<()> {
    let write = || -> std::io::Result<()> {
        let mut w = BufWriter::new(File::create(pvtp)?);
        header(&mut w, "PPolyData", names)?;
        writeln!(w, "  <PPolyData GhostLevel=\"0\">")?;
        writeln!(w, "    <PCellData>")?;
        writeln!(w, "      <PDataArray type=\"Int32\" Name=\"patch\"/>")?;
        writeln!(w, "      <PDataArray type=\"Int64\" Name=\"element\"/>")?;
        writeln!(w, "    </PCellData>")?;
        writeln!(w, "    <PPoints>")?;
        writeln!(
            w,
            "      <PDataArray type=\"Float64\" NumberOfComponents=\"3\"/>"
        )?;
        writeln!(w, "    </PPoints>")?;
        for r in 0..ranks {
            let name = piece_path(pvtp, r);
            let file = name.file_name().unwrap_or_default().to_string_lossy();
            writeln!(w, "    <Piece Source=\"{file}\"/>")?;
        }
        writeln!(w, "  </PPolyData>")?;
        writeln!(w, "</VTKFile>")?;
        w.into_inner().map_err(|e| e.into_error())?.sync_all()
    };
    write().map_err(|e| io_err(pvtp, e))
}

/// Writes the boundary faces of `mesh` beside the PVTU `pvtu` (see the
/// module documentation). Collective; a failure on one rank is reported
/// on every rank, and the PVTP is written only once every piece is.
/// Returns the PVTP path.
pub fn write_boundary(
    comm: &dyn Comm,
    pvtu: &Path,
    mesh: &Mesh,
    faces: &Faces,
    names: &PatchNames,
) -> Result<PathBuf> {
    let pvtp = boundary_path(pvtu);
    let piece = agree(comm, piece_of(mesh, faces))?;
    agree(
        comm,
        write_piece(&piece_path(&pvtp, comm.rank()), &piece, names),
    )?;
    let index = if comm.rank() == 0 {
        write_index(&pvtp, comm.size(), names)
    } else {
        Ok(())
    };
    agree(comm, index)?;
    Ok(pvtp)
}
