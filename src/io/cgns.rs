//! CGNS files (`.cgns`, HDF5), one per mesh, written by rank 0 from the
//! gathered mesh ([`super::gathered`]) through the CGNS C library (Debian
//! libcgns-dev; declarations made by `build.rs` from `cgnslib.h`): the same
//! content on any number of ranks.
//!
//! # What is written
//!
//! - `CGNSBase_t` `Base`, cell and physical dimension 3.
//! - One unstructured `Zone_t` named `volume` (the kept region) with
//!   `GridCoordinates` `CoordinateX/Y/Z` (doubles, the surface's units:
//!   the base's `DataClass` is `NormalizedByUnknownDimensional`, as an STL
//!   file names no units), nodes `1..N`: the
//!   independent nodes first, then the hanging nodes, each run in the
//!   order the elements first use them.
//! - `Elements_t` `volume`: `HEXA_8` elements `1..E` in global (Morton)
//!   element order, corners in CGNS order (which is VTK's). On a mesh with
//!   zones ([`crate::mesh::zones`]) one `HEXA_8` section per zone with
//!   elements instead, named after the zone, numbered zone after zone
//!   (each in global element order), and per zone a `Family_t` of its
//!   name and a `ZoneSubRegion_t` `<zone>_region` (`GridLocation` `CellCenter`,
//!   `PointRange` the section's elements, `FamilyName` the zone), so that
//!   readers find each region as a family.
//! - Per patch with boundary faces, in patch order: an `Elements_t` named
//!   after the patch of `QUAD_4` faces numbered on from `E + 1`, corners
//!   counter-clockwise seen from outside the mesh (a face only partly on
//!   the boundary, where some of the finer elements across it were not
//!   kept, is written whole); a `BC_t` of the same name, `BCType`
//!   `FamilySpecified`, `GridLocation` `FaceCenter`, `PointRange` the
//!   section's element range, `FamilyName` the patch; and a `Family_t` of
//!   that name in the base whose `FamilyBC` is `BCWall` for the surface's
//!   patches and `BCTypeUserDefined` for the six sides (inlet, outlet or
//!   symmetry: the user's choice).
//!
//! CGNS names hold at most 32 characters: a longer patch name is an error
//! (rename it with `--patch`).
//!
//! # Hanging nodes
//!
//! CGNS has no constraints. The hanging nodes are ordinary nodes (corners
//! of the finer elements only, so the mesh is non-conforming as written)
//! and, when there are any, the zone holds a `UserDefinedData_t`
//! `HangingNodes` (`GridLocation` `Vertex`, `DataClass`
//! `DimensionlessConstant`) with:
//!
//! - `Descriptor_t` `Description`: what the arrays mean;
//! - `DataArray_t` `Nodes` (Integer, H): the hanging nodes (1-based);
//! - `DataArray_t` `Parents` (Integer, 4 x H, the 4 of a node contiguous):
//!   the independent nodes each depends on (the 4 corners of the coarse
//!   face for a face-hanging node, the 2 ends of the coarse edge then 0 0
//!   for an edge-hanging one);
//! - `DataArray_t` `Weights` (RealDouble, 4 x H): their weights (1/4 each,
//!   or 1/2 1/2 0 0): a hanging node's value is the weighted sum of its
//!   parents' values.

use std::ffi::{c_int, CStr, CString};
use std::path::Path;

use super::gathered::{Blocks, Gathered, ABAQUS_FACE_NODES};
use crate::error::{Error, Result};
use crate::mesh::patches::PatchNames;
use crate::mesh::SIDE_PATCHES;

/// The CGNS C library's declarations (`build.rs`).
#[allow(
    non_upper_case_globals,
    non_camel_case_types,
    non_snake_case,
    dead_code,
    clippy::all
)]
mod sys {
    include!(concat!(env!("OUT_DIR"), "/cgns.rs"));
}

use sys::cg_size_type as cgsize_t;

/// The CGNS data type of `cgsize_t` (32 or 64 bits, as the library was
/// built).
const SIZE_TYPE: sys::DataType_t = match std::mem::size_of::<cgsize_t>() {
    8 => sys::LongInteger,
    _ => sys::Integer,
};

/// The longest CGNS node name.
const MAX_NAME: usize = 32;

/// What [`write_cgns`] wrote.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CgnsCounts {
    /// Nodes, hanging ones included.
    pub nodes: u64,
    /// Hexahedra.
    pub hexahedra: u64,
    /// Boundary conditions (one per patch with boundary faces).
    pub boundary_conditions: u64,
    /// Hanging nodes.
    pub hanging: u64,
}

/// An open CGNS file, closed when dropped.
struct File {
    fn_: c_int,
    /// Whether `fn_` is open.
    open: bool,
    path: String,
}

impl File {
    /// An error with the CGNS library's last message.
    fn error(&self) -> Error {
        // SAFETY: cg_get_error returns a NUL-terminated static buffer.
        let msg = unsafe { CStr::from_ptr(sys::cg_get_error()) };
        Error::io(format!(
            "cannot write '{}': {}",
            self.path,
            msg.to_string_lossy()
        ))
    }

    /// `Ok` when a CGNS call returned `CG_OK`.
    fn check(&self, status: c_int) -> Result<()> {
        match status {
            0 => Ok(()),
            _ => Err(self.error()),
        }
    }
}

impl File {
    /// Closes the file, with the status of the last write (HDF5 flushes
    /// here).
    fn close(&mut self) -> Result<()> {
        self.open = false;
        // SAFETY: fn_ was open.
        self.check(unsafe { sys::cg_close(self.fn_) })
    }
}

impl Drop for File {
    fn drop(&mut self) {
        if self.open {
            // SAFETY: fn_ is a file this value opened and has not closed.
            unsafe { sys::cg_close(self.fn_) };
        }
    }
}

/// `s` as a C string (names are OpenFOAM words: no NUL).
fn c(s: &str) -> CString {
    CString::new(s).expect("CGNS names hold no NUL")
}

/// `v` as a CGNS size, or an error naming `what`.
fn size(v: usize, what: &str) -> Result<cgsize_t> {
    cgsize_t::try_from(v).map_err(|_| {
        Error::invalid(format!(
            "the mesh has too many {what} ({v}) for the CGNS library's 32-bit sizes"
        ))
    })
}

/// Writes `g` (rank 0's gathered mesh; call on rank 0 only) to `path`.
pub fn write_cgns(path: &Path, g: &Gathered, patches: &PatchNames) -> Result<CgnsCounts> {
    let used = g.used_patches();
    let mut names = Vec::with_capacity(used.len());
    for &p in &used {
        let name = patches
            .names()
            .get(p as usize)
            .ok_or_else(|| Error::invalid(format!("patch {p} has no name")))?;
        if name.len() > MAX_NAME || name == "volume" || g.zone_names.contains(name) {
            return Err(Error::invalid(format!(
                "patch '{name}' cannot name a CGNS boundary (at most {MAX_NAME} characters, \
                 not 'volume' nor a zone's name): rename it with --patch"
            )));
        }
        names.push(name.as_str());
    }
    let longest = MAX_NAME - REGION_SUFFIX.len();
    if let Some(z) = g.zone_names.iter().find(|z| z.len() > longest) {
        return Err(Error::invalid(format!(
            "zone '{z}' cannot name a CGNS section and region (at most {longest} characters)"
        )));
    }
    let (nn, ne, nf) = (g.coordinates.len(), g.elements.len(), g.faces.len());
    size(nn, "nodes")?;
    size(8 * ne, "element corners")?;
    size(ne + nf, "elements and faces")?;
    // The file system's own message for a path that cannot be written
    // (the library's would come with HDF5's error stack).
    std::fs::File::create(path)
        .map_err(|e| Error::io(format!("cannot write '{}': {e}", path.display())))?;
    let cpath = CString::new(path.as_os_str().as_encoded_bytes())
        .map_err(|_| Error::invalid(format!("'{}' holds a NUL", path.display())))?;
    let mut file = File {
        fn_: 0,
        open: false,
        path: path.display().to_string(),
    };
    // SAFETY: cpath is NUL-terminated; fn_ receives the file number.
    let mode = sys::CG_MODE_WRITE as c_int;
    let status = unsafe { sys::cg_open(cpath.as_ptr(), mode, &mut file.fn_) };
    file.check(status)?;
    file.open = true;
    write(&file, g, &used, &names)?;
    file.close()?;
    Ok(CgnsCounts {
        nodes: nn as u64,
        hexahedra: ne as u64,
        boundary_conditions: used.len() as u64,
        hanging: g.dependencies.len() as u64,
    })
}

/// The end of a zone's `ZoneSubRegion_t` name (its section has the zone's
/// name).
const REGION_SUFFIX: &str = "_region";

/// The nodes and sections of [`write_cgns`] into the open `file`.
fn write(file: &File, g: &Gathered, used: &[u16], names: &[&str]) -> Result<()> {
    let f = file.fn_;
    let (nn, ne) = (g.coordinates.len(), g.elements.len());
    let (mut b, mut z) = (0, 0);
    let base = c("Base");
    // SAFETY (every call below): the names are NUL-terminated strings and
    // the arrays hold the counts the calls are given; the out-parameters
    // are local integers.
    file.check(unsafe { sys::cg_base_write(f, base.as_ptr(), 3, 3, &mut b) })?;
    // Lengths in the surface's units, which an STL file does not name.
    let at = c("/Base");
    file.check(unsafe { sys::cg_gopath(f, at.as_ptr()) })?;
    file.check(unsafe { sys::cg_dataclass_write(sys::NormalizedByUnknownDimensional) })?;
    let sizes: [cgsize_t; 3] = [nn as cgsize_t, ne as cgsize_t, 0];
    let zone = c("volume");
    file.check(unsafe {
        sys::cg_zone_write(
            f,
            b,
            zone.as_ptr(),
            sizes.as_ptr(),
            sys::Unstructured,
            &mut z,
        )
    })?;
    for (a, name) in ["CoordinateX", "CoordinateY", "CoordinateZ"]
        .iter()
        .enumerate()
    {
        let x: Vec<f64> = g.coordinates.iter().map(|p| p[a]).collect();
        let name = c(name);
        let mut k = 0;
        file.check(unsafe {
            sys::cg_coord_write(
                f,
                b,
                z,
                sys::RealDouble,
                name.as_ptr(),
                x.as_ptr().cast(),
                &mut k,
            )
        })?;
        // A length: exponent 1 of length (mass, length, time,
        // temperature, angle).
        let at = c(&format!(
            "/Base/volume/GridCoordinates/{}",
            name.to_string_lossy()
        ));
        let length: [f32; 5] = [0.0, 1.0, 0.0, 0.0, 0.0];
        file.check(unsafe { sys::cg_gopath(f, at.as_ptr()) })?;
        file.check(unsafe { sys::cg_exponents_write(sys::RealSingle, length.as_ptr().cast()) })?;
    }
    // The volumes: one section (and with zones a family and a sub-region
    // naming it) per block, numbered block after block.
    let blocks = Blocks::of(g);
    let zoned = blocks.blocks.len() > 1 || !g.zone_names.is_empty();
    let mut s = 0;
    let mut first = 1 as cgsize_t;
    for &(_, name, n) in &blocks.blocks {
        let at = (first - 1) as usize;
        let connect: Vec<cgsize_t> = blocks.order[at..at + n]
            .iter()
            .flat_map(|&e| g.elements[e as usize].map(|n| n as cgsize_t + 1))
            .collect();
        let range = [first, first + n as cgsize_t - 1];
        let cname = c(name);
        file.check(unsafe {
            sys::cg_section_write(
                f,
                b,
                z,
                cname.as_ptr(),
                sys::HEXA_8,
                range[0],
                range[1],
                0,
                connect.as_ptr(),
                &mut s,
            )
        })?;
        if zoned {
            let (mut fam, mut sub) = (0, 0);
            file.check(unsafe { sys::cg_family_write(f, b, cname.as_ptr(), &mut fam) })?;
            // A zone's children need distinct names: the section has the
            // zone's.
            let region = format!("{name}{REGION_SUFFIX}");
            let rname = c(&region);
            file.check(unsafe {
                sys::cg_subreg_ptset_write(
                    f,
                    b,
                    z,
                    rname.as_ptr(),
                    3,
                    sys::CellCenter,
                    sys::PointRange,
                    2,
                    range.as_ptr(),
                    &mut sub,
                )
            })?;
            let at = c(&format!("/Base/volume/{region}"));
            file.check(unsafe { sys::cg_gopath(f, at.as_ptr()) })?;
            file.check(unsafe { sys::cg_famname_write(cname.as_ptr()) })?;
        }
        first += n as cgsize_t;
    }
    let mut next = ne as cgsize_t + 1;
    for (&p, &name) in used.iter().zip(names) {
        let faces: Vec<cgsize_t> = g
            .faces
            .iter()
            .filter(|x| x.patch == p)
            .flat_map(|x| {
                let e = &g.elements[x.element as usize];
                // Abaqus's corners run into the element: reversed, outwards.
                let k = ABAQUS_FACE_NODES[x.label as usize];
                [k[3], k[2], k[1], k[0]].map(|v| e[v] as cgsize_t + 1)
            })
            .collect();
        let count = (faces.len() / 4) as cgsize_t;
        let range = [next, next + count - 1];
        next += count;
        let cname = c(name);
        file.check(unsafe {
            sys::cg_section_write(
                f,
                b,
                z,
                cname.as_ptr(),
                sys::QUAD_4,
                range[0],
                range[1],
                0,
                faces.as_ptr(),
                &mut s,
            )
        })?;
        let mut fam = 0;
        file.check(unsafe { sys::cg_family_write(f, b, cname.as_ptr(), &mut fam) })?;
        let kind = match (p as usize) < SIDE_PATCHES.len() {
            true => sys::BCTypeUserDefined,
            false => sys::BCWall,
        };
        let (mut fbc, mut bc) = (0, 0);
        let fam_bc = c("FamBC");
        file.check(unsafe { sys::cg_fambc_write(f, b, fam, fam_bc.as_ptr(), kind, &mut fbc) })?;
        file.check(unsafe {
            sys::cg_boco_write(
                f,
                b,
                z,
                cname.as_ptr(),
                sys::FamilySpecified,
                sys::PointRange,
                2,
                range.as_ptr(),
                &mut bc,
            )
        })?;
        file.check(unsafe { sys::cg_boco_gridlocation_write(f, b, z, bc, sys::FaceCenter) })?;
        let at = c(&format!("/Base/volume/ZoneBC/{name}"));
        file.check(unsafe { sys::cg_gopath(f, at.as_ptr()) })?;
        file.check(unsafe { sys::cg_famname_write(cname.as_ptr()) })?;
    }
    hanging(file, g)
}

/// The `HangingNodes` user data of the zone (none without hanging nodes).
fn hanging(file: &File, g: &Gathered) -> Result<()> {
    let h = g.dependencies.len();
    if h == 0 {
        return Ok(());
    }
    let f = file.fn_;
    let nodes: Vec<cgsize_t> = (0..h)
        .map(|k| (g.num_independent + k) as cgsize_t + 1)
        .collect();
    let mut parents = vec![0 as cgsize_t; 4 * h];
    let mut weights = vec![0f64; 4 * h];
    for (k, d) in g.dependencies.iter().enumerate() {
        let w = 1.0 / d.len() as f64;
        for (i, &m) in d.iter().enumerate() {
            parents[4 * k + i] = m as cgsize_t + 1;
            weights[4 * k + i] = w;
        }
    }
    let (zone, data) = (c("/Base/volume"), c("HangingNodes"));
    let text = c(
        "Hanging nodes of the 2:1 steps: node Nodes[k] (1-based) is the weighted sum \
         sum_i Weights[i,k] * node Parents[i,k] (i = 1..4; a Parents entry 0 has weight 0). \
         A solver must impose these constraints: without them the mesh is non-conforming.",
    );
    let (descr, loc) = (c("Description"), c("/Base/volume/HangingNodes"));
    let h = h as cgsize_t;
    // SAFETY: as in `write`; each array holds the product of its
    // dimensions.
    unsafe {
        file.check(sys::cg_gopath(f, zone.as_ptr()))?;
        file.check(sys::cg_user_data_write(data.as_ptr()))?;
        file.check(sys::cg_gopath(f, loc.as_ptr()))?;
        file.check(sys::cg_gridlocation_write(sys::Vertex))?;
        file.check(sys::cg_dataclass_write(sys::DimensionlessConstant))?;
        file.check(sys::cg_descriptor_write(descr.as_ptr(), text.as_ptr()))?;
        let (n, p, w) = (c("Nodes"), c("Parents"), c("Weights"));
        file.check(sys::cg_array_write(
            n.as_ptr(),
            SIZE_TYPE,
            1,
            &h,
            nodes.as_ptr().cast(),
        ))?;
        let dims: [cgsize_t; 2] = [4, h];
        file.check(sys::cg_array_write(
            p.as_ptr(),
            SIZE_TYPE,
            2,
            dims.as_ptr(),
            parents.as_ptr().cast(),
        ))?;
        file.check(sys::cg_array_write(
            w.as_ptr(),
            sys::RealDouble,
            2,
            dims.as_ptr(),
            weights.as_ptr().cast(),
        ))?;
    }
    Ok(())
}
