//! OpenFOAM cases: `constant/polyMesh` on one rank, and on P ranks one
//! `processor<r>/constant/polyMesh` per rank with processor patches, laid
//! out as `decomposePar` does, so a solver runs on it with `-parallel`
//! without decomposing.
//!
//! # What is written
//!
//! Per mesh: `points` (vectorField; in binary its count is padded with
//! blanks like the label count below, as the positions stream to the file
//! while the faces are made), `faces` (faceList, or faceCompactList
//! in binary: offsets, then point labels, whose count is padded with
//! blanks to a fixed width as it is written after them), `owner`,
//! `neighbour` (labelList), `boundary` (polyBoundaryMesh). Labels are
//! 32-bit and scalars 64-bit (`arch "LSB;label=32;scalar=64"`, Debian's
//! build).
//!
//! - Cells are the local elements in Morton order.
//! - Faces are [`crate::mesh::Faces`] in their order: internal faces
//!   upper-triangular, then the patches `xmin xmax ymin ymax zmin zmax` and
//!   the surface (a `wall`), then one `procBoundary<me>to<r>` patch per
//!   neighbour rank. Points run counter-clockwise seen from the side the
//!   normal points to (right-hand rule: from owner to neighbour, out of
//!   the domain on a boundary).
//! - Every face lists every mesh point on its edges, so a face with a
//!   hanging point on an edge is a polygon with that point (as OpenFOAM's
//!   `hexRef8` leaves them). Points are this rank's: its local nodes in
//!   their order (but the few that are no corner of a face, only a hanging
//!   node's dependency, whose labels the last nodes take), then the
//!   corners of halo elements that its faces use and that are no local
//!   node, in the order the faces first use them.
//! - Both sides of a processor patch list the shared faces in the same
//!   order ([`crate::mesh::faces`]), each starting at the same point (the
//!   lowest in lattice order); the higher rank's then run the other way.
//!
//! With zones ([`crate::mesh::zones`]) each mesh also has `cellZones` and
//! `faceZones` (see `zones.rs`): one cellZone per zone, one faceZone per
//! interface between two zones, whose faces are internal faces (or
//! processor faces), as `splitMeshRegions -cellZones` wants them.
//!
//! `system/controlDict`, `fvSchemes`, `fvSolution` (and on P ranks
//! `decomposeParDict`) are written when absent and never overwritten.
//!
//! # Failures
//!
//! An existing mesh is replaced only with `overwrite`. Each rank writes its
//! mesh beside the final place (`polyMesh.octmesh-partial`) and the meshes
//! are moved in only when every rank has written its own: a failure on one
//! rank leaves no case looking complete, and every rank reports it.

mod gathered;
mod layer;
mod layer_cell;
mod layer_points;
mod layer_stack;
mod polygons;
mod polymesh;
mod system;
mod zones;

use std::fs;
use std::io::Write;
use std::ops::Range;
use std::path::{Path, PathBuf};

pub use gathered::write_gathered_case;
pub use layer_stack::{
    LayerPlan, LayerReport, LayerSpec, LayerThickness, PatchLayerReport, FILL as LAYER_FILL,
};

use crate::error::{Error, ErrorKind, Result};
use crate::geometry::cells::{corner_coords, VTK_TO_MORTON};
use crate::geometry::Surface;
use crate::mesh::faces::{Face, Faces, Other, SURFACE_PATCH};
use crate::mesh::hanging::{face_diagonal, DepsIndex};
use crate::mesh::patches::PatchNames;
use crate::mesh::points::{
    corner_at, edge_midpoint, halo_corners, point_key, EdgeMidpoints, PointIndex,
};
use crate::mesh::Mesh;
use crate::parallel::comm::{agree, Comm};
use crate::parallel::direct::DirectWriter;

use polygons::*;
use polymesh::*;
use system::*;
use zones::*;

crate::named_enum! {
    /// Binary or ASCII list data.
    #[derive(Default)]
    pub enum FoamFormat: "OpenFOAM format" {
        /// Raw little-endian lists (OpenFOAM's `format binary`).
        #[default]
        Binary = "binary",
        /// Text.
        Ascii = "ascii",
    }
}

/// How to write a case.
#[derive(Clone, Debug, Default)]
pub struct FoamOptions {
    /// List encoding.
    pub format: FoamFormat,
    /// Replace an existing mesh.
    pub overwrite: bool,
    /// Patch names.
    pub patches: PatchNames,
}

/// Sizes of what one rank wrote.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FoamCounts {
    /// Points.
    pub points: u64,
    /// Faces, all kinds.
    pub faces: u64,
    /// Internal faces.
    pub internal_faces: u64,
    /// Cells.
    pub cells: u64,
}

/// The directory of this rank's mesh.
fn mesh_dir(case: &Path, rank: usize, size: usize) -> PathBuf {
    if size == 1 {
        case.join("constant").join("polyMesh")
    } else {
        case.join(format!("processor{rank}"))
            .join("constant")
            .join("polyMesh")
    }
}

fn partial(dir: &Path) -> PathBuf {
    dir.with_file_name("polyMesh.octmesh-partial")
}

fn io_err(what: &Path, e: std::io::Error) -> Error {
    Error::io(format!("{}: {e}", what.display()))
}

/// The wall layer of a case: the mesh is the staircase kept off
/// `surface`, and the case gets cells between its wall and the surface
/// (see `layer.rs`): one per wall face, or a buffer and the boundary
/// layers of `plan` (see `layer_stack.rs`).
#[derive(Clone, Copy, Debug)]
pub struct WallLayer<'a> {
    /// The surface the wall goes onto.
    pub surface: &'a Surface,
    /// The boundary layers, if any.
    pub plan: Option<&'a LayerPlan>,
}

/// Writes the case `dir` for `mesh`'s `faces` (collective), with a wall
/// layer if asked; returns this rank's counts and, with boundary layers,
/// their report (the same on every rank).
pub fn write_case(
    comm: &dyn Comm,
    dir: &Path,
    (mesh, faces): (&Mesh, &Faces),
    opts: &FoamOptions,
    wall_layer: Option<WallLayer<'_>>,
) -> Result<(FoamCounts, Option<LayerReport>)> {
    let (me, p) = (comm.rank(), comm.size());
    let target = mesh_dir(dir, me, p);
    let check = if mesh.counts().elements == 0 {
        Err(Error::invalid(
            "the mesh has no elements: there is nothing to write as an OpenFOAM case",
        ))
    } else if target.exists() && !opts.overwrite {
        Err(Error::invalid(format!(
            "{} exists: pass --overwrite (or set output.overwrite) to replace it",
            target.display()
        )))
    } else {
        Ok(())
    };
    agree(comm, check)?;
    // The interfaces between zones, known to every rank before any
    // writes (a rank whose directory failed must still take part).
    let interfaces = zone_interfaces(comm, mesh, faces);
    let (layered, report) = match wall_layer {
        Some(w) => {
            let clock = std::time::Instant::now();
            let (pm, report) =
                layer::layered_case(comm, (mesh, faces), w.surface, w.plan, &opts.patches)?;
            let mut seconds = [clock.elapsed().as_secs_f64()];
            comm.max_f64(&mut seconds);
            let report = report.map(|r| LayerReport {
                seconds: seconds[0],
                ..r
            });
            (Some(pm), report)
        }
        None => (None, None),
    };
    // A core no rank of this node runs on makes the polygons while this
    // rank labels them (a serial run on a workstation, say).
    let spare_core = crate::parallel::cores::spare_core(comm);
    let scratch = partial(&target);
    let written = (|| -> Result<FoamCounts> {
        let _ = fs::remove_dir_all(&scratch);
        fs::create_dir_all(&scratch).map_err(|e| io_err(&scratch, e))?;
        if let Some(pm) = &layered {
            let loc = location(me, p);
            return layer::write_layered(&scratch, pm, opts, (&loc, me));
        }
        write_polymesh(
            &scratch,
            (mesh, faces),
            opts,
            &interfaces,
            (me, p),
            spare_core,
        )
    })();
    if written.is_err() {
        let _ = fs::remove_dir_all(&scratch);
    }
    let counts = match agree(comm, written) {
        Ok(c) => c,
        Err(e) => {
            let _ = fs::remove_dir_all(&scratch);
            return Err(e);
        }
    };
    let moved = (|| -> Result<()> {
        if target.exists() {
            fs::remove_dir_all(&target).map_err(|e| io_err(&target, e))?;
        }
        fs::rename(&scratch, &target).map_err(|e| io_err(&target, e))?;
        if me == 0 {
            write_system(dir, p)?;
            if p > 1 {
                remove_extra_processors(dir, p)?;
            }
        }
        Ok(())
    })();
    agree(comm, moved)?;
    Ok((counts, report))
}

/// Removes `processor<r>` directories for `r >= p` left by an earlier run
/// on more ranks (OpenFOAM counts them).
fn remove_extra_processors(dir: &Path, p: usize) -> Result<()> {
    let Ok(entries) = fs::read_dir(dir) else {
        return Ok(());
    };
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        if let Some(r) = name
            .strip_prefix("processor")
            .and_then(|r| r.parse::<usize>().ok())
        {
            if r >= p {
                fs::remove_dir_all(e.path()).map_err(|err| io_err(&e.path(), err))?;
            }
        }
    }
    Ok(())
}

fn create(path: &Path) -> Result<DirectWriter> {
    DirectWriter::create(path).map_err(|e| io_err(path, e))
}

#[allow(clippy::too_many_arguments)]
fn write_polymesh(
    dir: &Path,
    (mesh, faces): (&Mesh, &Faces),
    opts: &FoamOptions,
    interfaces: &[(u16, u16)],
    (me, p): (usize, usize),
    spare_core: bool,
) -> Result<FoamCounts> {
    let fmt = opts.format;
    let location = location(me, p);
    let loc = location.as_str();
    let nodes = NodeLabels::new(mesh);
    let mut points = PointsOut::new(&dir.join("points"), fmt, loc, mesh)?;
    let mut fill = NodeFill::new(mesh, &nodes);
    let halo = write_faces(
        &dir.join("faces"),
        (fmt, loc),
        (mesh, faces),
        &nodes,
        spare_core,
        || fill.step(&mut points),
    )?;
    points.halo(&halo)?;
    let num_points = points.finish(loc)?;
    let nf = faces.faces().len();
    let ni = faces.num_internal();
    let counts = FoamCounts {
        points: num_points as u64,
        faces: nf as u64,
        internal_faces: ni as u64,
        cells: mesh.elements().len() as u64,
    };
    let result = (|| -> std::io::Result<()> {
        let owners = faces.faces().iter().map(|f| f.owner());
        let neighbours = faces.faces()[..ni].iter().map(|f| match f.other() {
            Other::Element(j) => j,
            _ => 0,
        });
        let patches: Vec<Range<usize>> = (0..faces.num_patches())
            .map(|q| faces.patch_range(q))
            .collect();
        write_cells(
            dir,
            (fmt, loc, me),
            &counts,
            (owners, neighbours),
            opts,
            (&patches, faces.halo_ranges()),
        )?;
        match mesh.zones() {
            Some(z) => write_zones(dir, loc, faces, z, interfaces),
            None => Ok(()),
        }
    })();
    result.map_err(|e| Error::io(format!("writing {}: {e}", dir.display())))?;
    Ok(counts)
}

/// A processor patch: the neighbour rank and its faces.
type ProcFaces = (u32, Range<usize>);

/// The location in the files' headers of rank `me`'s mesh of `p`.
fn location(me: usize, p: usize) -> String {
    if p == 1 {
        "constant/polyMesh".to_string()
    } else {
        format!("processor{me}/constant/polyMesh")
    }
}

/// Writes `owner`, `neighbour` and `boundary`: the boundary faces by patch
/// (`patches`, named by `opts`), then a processor patch per neighbour rank
/// (`procs`).
fn write_cells(
    dir: &Path,
    (fmt, loc, me): (FoamFormat, &str, usize),
    counts: &FoamCounts,
    (owners, neighbours): (impl Iterator<Item = u32>, impl Iterator<Item = u32>),
    opts: &FoamOptions,
    (patches, procs): (&[Range<usize>], &[ProcFaces]),
) -> std::io::Result<()> {
    let note = format!(
        "nPoints:{} nCells:{} nFaces:{} nInternalFaces:{}",
        counts.points, counts.cells, counts.faces, counts.internal_faces
    );
    let (nf, ni) = (counts.faces as usize, counts.internal_faces as usize);
    let path = dir.join("owner");
    let mut w = create(&path).map_err(std::io::Error::other)?;
    header(&mut w, fmt, "labelList", loc, "owner", Some(&note))?;
    write_label_iter(&mut w, fmt, nf, owners)?;
    w.flush()?;

    let path = dir.join("neighbour");
    let mut w = create(&path).map_err(std::io::Error::other)?;
    header(&mut w, fmt, "labelList", loc, "neighbour", Some(&note))?;
    write_label_iter(&mut w, fmt, ni, neighbours)?;
    w.flush()?;

    let path = dir.join("boundary");
    let mut w = create(&path).map_err(std::io::Error::other)?;
    header(
        &mut w,
        FoamFormat::Ascii,
        "polyBoundaryMesh",
        loc,
        "boundary",
        None,
    )?;
    let np = patches.len();
    if opts.patches.names().len() != np {
        return Err(std::io::Error::other(format!(
            "{} patch names for {np} patches",
            opts.patches.names().len()
        )));
    }
    writeln!(w, "{}\n(", np + procs.len())?;
    for (q, r) in patches.iter().enumerate() {
        writeln!(w, "    {}\n    {{", opts.patches.name(q))?;
        if q >= SURFACE_PATCH as usize {
            writeln!(w, "        type            wall;")?;
            writeln!(w, "        inGroups        List<word> 1(wall);")?;
        } else {
            writeln!(w, "        type            patch;")?;
        }
        writeln!(w, "        nFaces          {};", r.len())?;
        writeln!(w, "        startFace       {};", r.start)?;
        writeln!(w, "    }}")?;
    }
    for (r, range) in procs {
        writeln!(w, "    procBoundary{me}to{r}\n    {{")?;
        writeln!(w, "        type            processor;")?;
        writeln!(w, "        inGroups        List<word> 1(processor);")?;
        writeln!(w, "        nFaces          {};", range.len())?;
        writeln!(w, "        startFace       {};", range.start)?;
        writeln!(w, "        matchTolerance  0.0001;")?;
        writeln!(w, "        transform       unknown;")?;
        writeln!(w, "        myProcNo        {me};")?;
        writeln!(w, "        neighbProcNo    {r};")?;
        writeln!(w, "    }}")?;
    }
    writeln!(w, ")")?;
    w.flush()
}
