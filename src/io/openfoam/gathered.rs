//! A serial case of a mesh gathered on rank 0 ([`crate::io::gathered`]):
//! the conforming mesh (`--conforming`), which has no hanging nodes, so
//! every face is a quadrilateral shared whole by two cells or on a patch.
//!
//! Cells are the gathered elements in their order; internal faces are
//! upper-triangular (by owner, then neighbour), each the owner's face with
//! its points counter-clockwise seen from the neighbour; then the patches
//! in their order (the surface's a `wall`), each face counter-clockwise
//! seen from outside. ASCII: the files are written by one process.

use super::polymesh::header;
use super::*;
use crate::io::gathered::{match_faces, Gathered, ABAQUS_FACE_NODES};
use crate::mesh::faces::SURFACE_PATCH;
use crate::mesh::patches::PatchNames;

/// Writes `g` as the case `dir` (`constant/polyMesh`, `system/` when
/// absent) with the patch names `patches`; an existing mesh is replaced
/// only with `overwrite`. Not collective: rank 0 calls it.
pub fn write_gathered_case(
    dir: &Path,
    g: &Gathered,
    patches: &PatchNames,
    overwrite: bool,
) -> Result<FoamCounts> {
    let target = mesh_dir(dir, 0, 1);
    if g.elements.is_empty() {
        return Err(Error::invalid(
            "the mesh has no elements: there is nothing to write as an OpenFOAM case",
        ));
    }
    if !g.zone_names.is_empty() {
        return Err(Error::invalid(
            "--conforming writes OpenFOAM cases without zones for now: leave out --zones",
        ));
    }
    if target.exists() && !overwrite {
        return Err(Error::invalid(format!(
            "{} exists: pass --overwrite (or set output.overwrite) to replace it",
            target.display()
        )));
    }
    let scratch = partial(&target);
    let _ = fs::remove_dir_all(&scratch);
    let written = fs::create_dir_all(&scratch)
        .map_err(|e| io_err(&scratch, e))
        .and_then(|_| write_polymesh(&scratch, g, patches));
    let counts = match written {
        Ok(c) => c,
        Err(e) => {
            let _ = fs::remove_dir_all(&scratch);
            return Err(e);
        }
    };
    if target.exists() {
        fs::remove_dir_all(&target).map_err(|e| io_err(&target, e))?;
    }
    fs::rename(&scratch, &target).map_err(|e| io_err(&target, e))?;
    system::write_system(dir, 1)?;
    Ok(counts)
}

/// The face of element `h` with Abaqus label `label`, its points
/// counter-clockwise seen from outside the element.
fn outward(g: &Gathered, h: usize, label: usize) -> [u32; 4] {
    // The Abaqus order runs clockwise seen from outside.
    let [a, b, c, d] = ABAQUS_FACE_NODES[label].map(|k| g.elements[h][k]);
    [a, d, c, b]
}

/// The error of an I/O failure on `path`.
fn io(path: &Path) -> impl Fn(std::io::Error) -> Error + '_ {
    move |e| io_err(path, e)
}

fn write_polymesh(dir: &Path, g: &Gathered, patches: &PatchNames) -> Result<FoamCounts> {
    let loc = "constant/polyMesh";
    let fmt = FoamFormat::Ascii;
    // Internal faces: the first element to list a face owns it.
    let (pairs, once) = match_faces(&g.elements);
    let mut internal: Vec<(u32, u32, [u32; 4])> = pairs
        .into_iter()
        .map(|(o, l, n)| (o, n, outward(g, o as usize, l as usize)))
        .collect();
    internal.sort_unstable_by_key(|&(o, n, _)| (o, n));
    if once.len() != g.faces.len() {
        return Err(Error::new(
            ErrorKind::Internal,
            format!(
                "{} faces are in one element only but {} are on patches",
                once.len(),
                g.faces.len()
            ),
        ));
    }
    let names = patches.names();
    if let Some(f) = g.faces.iter().find(|f| f.patch as usize >= names.len()) {
        return Err(Error::invalid(format!(
            "patch {} has no name ({} names)",
            f.patch,
            names.len()
        )));
    }
    let file = |name: &str| dir.join(name);

    let path = file("points");
    let mut w = std::io::BufWriter::new(fs::File::create(&path).map_err(io(&path))?);
    (|| -> std::io::Result<()> {
        w.write_all(&polymesh::points_head(
            fmt,
            loc,
            g.coordinates.len() as u32,
        )?)?;
        for p in &g.coordinates {
            writeln!(w, "({:e} {:e} {:e})", p[0], p[1], p[2])?;
        }
        writeln!(w, ")")?;
        w.flush()
    })()
    .map_err(io(&path))?;

    let boundary: Vec<(u32, [u32; 4])> = g
        .faces
        .iter()
        .map(|f| {
            (
                f.element as u32,
                outward(g, f.element as usize, f.label as usize),
            )
        })
        .collect();
    let path = file("faces");
    let mut w = std::io::BufWriter::new(fs::File::create(&path).map_err(io(&path))?);
    (|| -> std::io::Result<()> {
        header(&mut w, fmt, "faceList", loc, "faces", None)?;
        writeln!(w, "{}\n(", internal.len() + boundary.len())?;
        let all = internal
            .iter()
            .map(|f| f.2)
            .chain(boundary.iter().map(|f| f.1));
        for [a, b, c, d] in all {
            writeln!(w, "4({a} {b} {c} {d})")?;
        }
        writeln!(w, ")")?;
        w.flush()
    })()
    .map_err(io(&path))?;

    let note = format!(
        "nPoints:{} nCells:{} nFaces:{} nInternalFaces:{}",
        g.coordinates.len(),
        g.elements.len(),
        internal.len() + boundary.len(),
        internal.len()
    );
    let owners = internal
        .iter()
        .map(|f| f.0)
        .chain(boundary.iter().map(|f| f.0));
    let lists: [(&str, Vec<u32>); 2] = [
        ("owner", owners.collect()),
        ("neighbour", internal.iter().map(|f| f.1).collect()),
    ];
    for (name, v) in lists {
        let path = file(name);
        let mut w = std::io::BufWriter::new(fs::File::create(&path).map_err(io(&path))?);
        (|| -> std::io::Result<()> {
            header(&mut w, fmt, "labelList", loc, name, Some(&note))?;
            polymesh::write_label_iter(&mut w, fmt, v.len(), v.iter().copied())?;
            w.flush()
        })()
        .map_err(io(&path))?;
    }

    let path = file("boundary");
    let mut w = std::io::BufWriter::new(fs::File::create(&path).map_err(io(&path))?);
    (|| -> std::io::Result<()> {
        header(&mut w, fmt, "polyBoundaryMesh", loc, "boundary", None)?;
        writeln!(w, "{}\n(", names.len())?;
        let mut start = internal.len();
        for (q, name) in names.iter().enumerate() {
            let n = g.faces.iter().filter(|f| f.patch as usize == q).count();
            writeln!(w, "    {name}\n    {{")?;
            if q >= SURFACE_PATCH as usize {
                writeln!(w, "        type            wall;")?;
                writeln!(w, "        inGroups        List<word> 1(wall);")?;
            } else {
                writeln!(w, "        type            patch;")?;
            }
            writeln!(w, "        nFaces          {n};")?;
            writeln!(w, "        startFace       {start};")?;
            writeln!(w, "    }}")?;
            start += n;
        }
        writeln!(w, ")")?;
        w.flush()
    })()
    .map_err(io(&path))?;
    Ok(FoamCounts {
        points: g.coordinates.len() as u64,
        faces: (internal.len() + boundary.len()) as u64,
        internal_faces: internal.len() as u64,
        cells: g.elements.len() as u64,
    })
}
