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
//! `system/controlDict`, `fvSchemes`, `fvSolution` (and on P ranks
//! `decomposeParDict`) are written when absent and never overwritten.
//!
//! # Failures
//!
//! An existing mesh is replaced only with `overwrite`. Each rank writes its
//! mesh beside the final place (`polyMesh.octmesh-partial`) and the meshes
//! are moved in only when every rank has written its own: a failure on one
//! rank leaves no case looking complete, and every rank reports it.

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use super::direct::DirectWriter;
use crate::error::{Error, ErrorKind, Result};
use crate::mesh::dual::corner_coords;
use crate::mesh::faces::{Face, Faces, Other, SURFACE_PATCH};
use crate::mesh::hanging::{face_diagonal, DepsIndex};
use crate::mesh::patches::PatchNames;
use crate::mesh::points::{
    corner_at, edge_midpoint, halo_corners, point_key, EdgeMidpoints, PointIndex,
};
use crate::mesh::Mesh;
use crate::mesh::VTK_TO_MORTON;
use crate::parallel::comm::{agree, Comm};

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

/// The labels of one rank's local nodes in its case.
///
/// A rank's points are its local nodes and the halo's corners that its
/// faces use and that are no local node. Every local node is a corner of a
/// face but for the few that are only a dependency of a hanging node (at
/// partition boundaries), so the nodes keep their numbers as labels, the
/// last ones moving into the places the unused ones leave below
/// `direct`; the halo's points follow ([`Labeller`]), in the order the
/// faces first use them. A label is then found without a table for nearly
/// every point.
///
/// ```text
///   node   0  1  2  3  4  5  6  7      node 3 unused: direct = 7
///   label  0  1  2  -  4  5  6  3      node 7 takes label 3
/// ```
struct NodeLabels {
    /// Local nodes below this are their own labels.
    direct: u32,
    /// Local nodes.
    nn: u32,
    /// The labels of nodes `direct..nn` (`u32::MAX` for an unused one).
    tail: Vec<u32>,
    /// `(label, node)` for each label below `direct` that is not its
    /// node's number, by label.
    moved: Vec<(u32, u32)>,
}

impl NodeLabels {
    fn new(mesh: &Mesh) -> NodeLabels {
        let nn = mesh.num_nodes() as u32;
        let unused: Vec<u32> = mesh.dependency_only_nodes().collect();
        let direct = nn - unused.len() as u32;
        let movers = (direct..nn).filter(|n| unused.binary_search(n).is_err());
        let holes = unused.iter().copied().take_while(|&n| n < direct);
        let moved: Vec<(u32, u32)> = holes.zip(movers).collect();
        let mut tail = vec![u32::MAX; (nn - direct) as usize];
        for &(l, n) in &moved {
            tail[(n - direct) as usize] = l;
        }
        NodeLabels {
            direct,
            nn,
            tail,
            moved,
        }
    }

    /// The node of label `l` below `direct`, for labels asked in
    /// increasing order; `at` counts the entries of `moved` passed.
    #[inline]
    fn node(&self, l: u32, at: &mut usize) -> u32 {
        match self.moved.get(*at) {
            Some(&(h, n)) if h == l => {
                *at += 1;
                n
            }
            _ => l,
        }
    }
}

/// Labels point numbers (see [`Polygons::polygon`]) in face order: the
/// nodes by their [`NodeLabels`], the halo's points as they are first
/// used.
struct Labeller<'a> {
    nodes: &'a NodeLabels,
    /// Each halo point's label plus one (zero: not used yet), by its
    /// place in the searched set.
    halo: Vec<u32>,
    /// The used halo points' places, in label order.
    order: Vec<u32>,
    /// A face used an unused node (an inconsistent mesh).
    unused_hit: bool,
}

impl Labeller<'_> {
    #[inline]
    fn of(&mut self, id: u32) -> u32 {
        if id < self.nodes.direct {
            id
        } else {
            self.rare(id)
        }
    }

    #[cold]
    fn rare(&mut self, id: u32) -> u32 {
        let nodes = self.nodes;
        if id < nodes.nn {
            let l = nodes.tail[(id - nodes.direct) as usize];
            self.unused_hit |= l == u32::MAX;
            return l;
        }
        let j = (id - nodes.nn) as usize;
        if self.halo[j] == 0 {
            self.order.push(j as u32);
            self.halo[j] = nodes.direct + self.order.len() as u32;
        }
        self.halo[j] - 1
    }
}

/// Turns each face of `faces`, in order, into its polygon of point labels
/// (`nodes` for the local nodes, the halo's points labelled as they come)
/// and hands them on in chunks to `emit`; returns the halo points used, in
/// label order. No list of every label is kept: the caller streams them.
///
/// `side` is other work for this thread, in short steps (it answers
/// whether there is more): with `spare_core`, a second thread makes
/// polygons while this one does those steps, then both take the chunks of
/// faces as they come, and this one labels and hands them on in order.
/// The same labels come out either way.
fn face_polygons(
    (mesh, faces): (&Mesh, &Faces),
    nodes: &NodeLabels,
    spare_core: bool,
    mut side: impl FnMut() -> Result<bool>,
    mut emit: impl FnMut(&Chunk) -> Result<()>,
) -> Result<Vec<[u32; 3]>> {
    use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};
    let nf = faces.faces().len();
    let chunks = nf.div_ceil(POLYGON_CHUNK);
    let two = spare_core && chunks >= 2;
    if !two {
        // Alone, the side work goes first: what it holds is freed before
        // the index is made.
        while side()? {}
    }
    let ix = PolygonIndex::new(mesh, faces, two);
    let mut labels = Labeller {
        nodes,
        halo: vec![0; ix.halo.len()],
        order: Vec::new(),
        unused_hit: false,
    };
    let mut total = 0usize;
    let mut take = |c: &mut Chunk| -> Result<()> {
        for id in &mut c.ids {
            *id = labels.of(*id);
        }
        total += c.ids.len();
        if total > i32::MAX as usize {
            return Err(Error::new(
                ErrorKind::Limit,
                "more than 2^31 face labels on one rank",
            ));
        }
        emit(c)
    };
    let range = |k: usize| k * POLYGON_CHUNK..nf.min((k + 1) * POLYGON_CHUNK);
    // The next chunk to make, whichever thread takes it.
    let next = AtomicUsize::new(0);
    let mut mine = Polygons::new(&ix);
    std::thread::scope(|scope| -> Result<()> {
        let (ready, arrived) = std::sync::mpsc::sync_channel::<(usize, Result<Chunk>)>(4);
        let (done, spare) = std::sync::mpsc::channel::<Chunk>();
        let (next, ix) = (&next, &ix);
        // Stops the other thread at its next chunk when this one fails.
        struct Stop<'s>(&'s AtomicUsize, usize);
        impl Drop for Stop<'_> {
            fn drop(&mut self) {
                self.0.store(self.1, Relaxed);
            }
        }
        let _stop = Stop(next, chunks);
        let helper = two
            && std::thread::Builder::new()
                .name("octmesh-polygons".into())
                .spawn_scoped(scope, move || {
                    let mut maker = Polygons::new(ix);
                    loop {
                        let k = next.fetch_add(1, Relaxed);
                        if k >= chunks {
                            return;
                        }
                        let mut c = spare.try_recv().unwrap_or_default();
                        let made = maker.chunk(range(k), &mut c);
                        let failed = made.is_err();
                        // A closed channel: the labelling side stopped.
                        if ready.send((k, made.map(|()| c))).is_err() || failed {
                            return;
                        }
                    }
                })
                .is_ok();
        let mut more_side = two;
        // Chunks made ahead of their turn, and emptied ones to reuse.
        let mut held: std::collections::BTreeMap<usize, Chunk> = Default::default();
        let mut pool: Vec<Chunk> = Vec::new();
        let mut want = 0;
        while want < chunks {
            if let Some(mut c) = held.remove(&want) {
                take(&mut c)?;
                want += 1;
                if helper && pool.len() >= 2 {
                    let _ = done.send(c);
                } else {
                    pool.push(c);
                }
                continue;
            }
            let got = match helper {
                true => arrived.try_recv().ok(),
                false => None,
            };
            if let Some((k, c)) = got {
                held.insert(k, c?);
                continue;
            }
            if more_side {
                more_side = side()?;
                continue;
            }
            let k = next.fetch_add(1, Relaxed);
            if k < chunks {
                let mut c = pool.pop().unwrap_or_default();
                mine.chunk(range(k), &mut c)?;
                held.insert(k, c);
            } else {
                if !helper {
                    return Err(Error::new(ErrorKind::Internal, "a chunk of faces was lost"));
                }
                // The rest is the other thread's: wait for it.
                let (k, c) = arrived
                    .recv()
                    .map_err(|_| Error::new(ErrorKind::Internal, "the polygon thread stopped"))?;
                held.insert(k, c?);
            }
        }
        while more_side {
            more_side = side()?;
        }
        Ok(())
    })?;
    if labels.unused_hit {
        return Err(Error::new(
            ErrorKind::Internal,
            "a face uses a node that no local element has as a corner",
        ));
    }
    Ok(labels
        .order
        .iter()
        .map(|&j| ix.halo.point(j as usize))
        .collect())
}

/// Faces per chunk of polygons.
const POLYGON_CHUNK: usize = 1 << 13;

/// Polygons of consecutive faces: their points (numbers, then labels),
/// then each face's count.
#[derive(Default)]
struct Chunk {
    ids: Vec<u32>,
    lens: Vec<u8>,
}

/// The parts of the mesh and its faces the polygons are made from, copied
/// into each thread's maker: read in the hot loop by one load each.
#[derive(Clone, Copy)]
struct MeshParts<'m> {
    faces: &'m [Face],
    halo_start: usize,
    elements: &'m [crate::octree::octant::Octant],
    conn: &'m [[u32; 8]],
    nn: usize,
    ni: usize,
}

/// What the polygons are made from, made once for the threads that make
/// them.
struct PolygonIndex<'m> {
    parts: MeshParts<'m>,
    /// The hanging nodes by the nodes they depend on.
    hanging: DepsIndex,
    /// The halo's corners.
    halo: PointIndex,
    /// Whether an edge between two local nodes may carry a point.
    midpoints: EdgeMidpoints,
}

impl<'m> PolygonIndex<'m> {
    /// The index of `mesh` and `faces`; with `spare_core`, the hanging
    /// nodes' part on a second thread.
    fn new(mesh: &'m Mesh, faces: &'m Faces, spare_core: bool) -> Self {
        // Every corner of a kept element near this rank is a mesh point. A
        // face's corners and edge midpoints are local nodes or corners of
        // halo elements. Those that are not a local element's corners (the
        // corners of a split coarse face's pieces, the midpoints of face
        // edges) lie in the middle of a coarse kept element's face or edge:
        // they hang on it, when they are local nodes, and are found by that
        // face's corners or that edge's ends. Only the halo's corners are
        // searched by their points.
        let (hanging, (halo, midpoints)) = crate::parallel::cores::join(
            spare_core,
            || mesh.hanging_index(),
            || {
                let halo = PointIndex::new(halo_corners(mesh).map(point_key).collect());
                (halo, EdgeMidpoints::new(mesh))
            },
        );
        PolygonIndex {
            parts: MeshParts {
                faces: faces.faces(),
                halo_start: faces.halo_range().start,
                elements: mesh.elements(),
                conn: mesh.connectivity(),
                nn: mesh.num_nodes(),
                ni: mesh.num_independent(),
            },
            hanging,
            halo,
            midpoints,
        }
    }
}

/// The part of [`face_polygons`] that needs no labels, one per thread:
/// each face's points as numbers.
struct Polygons<'m> {
    m: MeshParts<'m>,
    hanging: &'m DepsIndex,
    midpoints: &'m EdgeMidpoints,
    /// A copy of the index's: the searches' hint is this thread's.
    halo: PointIndex,
    /// The last emitter and its cube: faces come by owner, so a few in a
    /// row share it.
    last: (u32, ([u32; 3], u32)),
}

impl<'m> Polygons<'m> {
    fn new(ix: &'m PolygonIndex<'m>) -> Self {
        Polygons {
            m: ix.parts,
            hanging: &ix.hanging,
            midpoints: &ix.midpoints,
            halo: ix.halo.clone(),
            last: (u32::MAX, ([0; 3], 0)),
        }
    }

    /// The local node at `x`, in the middle of an edge or a face of the
    /// cube `(c, s)` whose corner nodes are `row`, if it hangs there.
    fn hanging_on(&self, (c, s): ([u32; 3], u32), row: &[u32; 8], x: [u32; 3]) -> Option<u32> {
        // The Morton corner bits of the axes where `x` is on the high side,
        // and the axes where it is in the middle.
        let (mut high, mut middle) = (0usize, [0usize; 2]);
        let mut n = 0;
        for a in 0..3 {
            match x[a].wrapping_sub(c[a]) {
                0 => {}
                d if d == s => high |= 1 << a,
                d if 2 * d == s && n < 2 => {
                    middle[n] = 1 << a;
                    n += 1;
                }
                _ => return None,
            }
        }
        let node = |m: usize| row[VTK_TO_MORTON[m]];
        let (a, b) = match n {
            1 => (node(high), node(high | middle[0])),
            2 => {
                let [u, v] = middle;
                face_diagonal([
                    node(high),
                    node(high | u),
                    node(high | v),
                    node(high | u | v),
                ])
            }
            _ => return None,
        };
        let k = self.hanging.find(a, b)?;
        Some((self.m.ni + k) as u32)
    }

    /// The point at `x` that is no corner of the cube `(c, s)` (corner
    /// nodes `row`): a node hanging on it, or a corner of the halo.
    fn off_corner(&mut self, cube: ([u32; 3], u32), row: &[u32; 8], x: [u32; 3]) -> Option<u32> {
        self.hanging_on(cube, row, x).or_else(|| self.halo_point(x))
    }

    /// The number of the halo's corner at `x` (`nn + j`), if `x` is one.
    fn halo_point(&mut self, x: [u32; 3]) -> Option<u32> {
        Some((self.m.nn + self.halo.find(point_key(x))?) as u32)
    }

    /// The local element whose whole face `f` is: the owner, or a finer
    /// local neighbour.
    fn emitter(&self, f: &Face) -> Option<u32> {
        if self.m.elements[f.owner() as usize].side() == f.emitter_side() {
            return Some(f.owner());
        }
        match f.other() {
            Other::Element(j) => Some(j),
            _ => None,
        }
    }

    #[inline]
    fn cube(&self, e: u32) -> ([u32; 3], u32) {
        let o = self.m.elements[e as usize];
        (o.coords(), o.side())
    }

    /// The point in the middle of the edge from `xa` to `xb`, if there is
    /// one; the edge lies on the cube `(c, s)` (corner nodes `row`), and
    /// `ends` are its ends' local nodes when they are the cube's corners.
    #[inline]
    fn midpoint(
        &mut self,
        (cube, row): (([u32; 3], u32), &[u32; 8]),
        ends: Option<(usize, usize)>,
        xa: [u32; 3],
        xb: [u32; 3],
    ) -> Option<(u32, [u32; 3])> {
        let m = edge_midpoint(xa, xb)?;
        let hanging = match ends {
            Some((a, b)) => {
                if !self.midpoints.may_hold(a, b, m) {
                    return None;
                }
                let k = self.hanging.find(a as u32, b as u32);
                k.map(|k| (self.m.ni + k) as u32)
            }
            None => self.hanging_on(cube, row, m),
        };
        let p = hanging.or_else(|| self.halo_point(m))?;
        Some((p, m))
    }

    /// Makes the polygons of faces `range` into `c`, its lists cleared
    /// first.
    fn chunk(&mut self, range: std::ops::Range<usize>, c: &mut Chunk) -> Result<()> {
        c.ids.clear();
        c.lens.clear();
        for i in range {
            let start = c.ids.len();
            self.polygon(i, &mut c.ids)?;
            c.lens.push((c.ids.len() - start) as u8);
        }
        Ok(())
    }

    /// Appends face `i`'s points, in order, to `poly`, as numbers: a local
    /// node `n < nn`, or `nn + j` for the point at place `j` of the halo's
    /// corners.
    fn polygon(&mut self, i: usize, poly: &mut Vec<u32>) -> Result<()> {
        let f = &self.m.faces[i];
        // Most faces are the whole face of a local element: their corners
        // are its nodes, and an edge's midpoint is looked for only when
        // both ends may carry one.
        let whole = (i < self.m.halo_start)
            .then(|| f.whole_corner_octants())
            .flatten()
            .and_then(|m| Some((self.emitter(f)?, m)));
        if let Some((e, m)) = whole {
            let conn = self.m.conn;
            let row = &conn[e as usize];
            // A loop, not `map`, which was not inlined and handed its
            // result back through memory.
            let mut nodes = [0usize; 4];
            for k in 0..4 {
                nodes[k] = row[VTK_TO_MORTON[m[k]]] as usize;
            }
            for k in 0..4 {
                let (a, b) = (nodes[k], nodes[(k + 1) % 4]);
                poly.push(a as u32);
                if self.midpoints.may_hold_ends(a, b) {
                    // The element's cube only for an edge that may hold a
                    // point: most hold none.
                    if self.last.0 != e {
                        self.last = (e, self.cube(e));
                    }
                    let (c, s) = self.last.1;
                    let (xa, xb) = (
                        corner_coords(c, s, m[k]),
                        corner_coords(c, s, m[(k + 1) % 4]),
                    );
                    let m = self.midpoint(((c, s), row), Some((a, b)), xa, xb);
                    poly.extend(m.map(|m| m.0));
                }
            }
            return Ok(());
        }
        let c = f.corners();
        let e = self.emitter(f).unwrap_or(f.owner());
        let cube = self.cube(e);
        let conn = self.m.conn;
        let row = &conn[e as usize];
        let nodes = c.map(|x| corner_at(cube.0, cube.1, x).map(|m| row[VTK_TO_MORTON[m]] as usize));
        // At most a corner and a midpoint per side.
        let mut face = [(0u32, [0u32; 3]); 8];
        let mut n = 0;
        for k in 0..4 {
            let p = match nodes[k] {
                Some(n) => n as u32,
                None => self.off_corner(cube, row, c[k]).ok_or_else(|| {
                    Error::new(
                        ErrorKind::Internal,
                        format!("face corner {:?} is no element's corner", c[k]),
                    )
                })?,
            };
            face[n] = (p, c[k]);
            n += 1;
            let (xa, xb) = (c[k], c[(k + 1) % 4]);
            let ends = nodes[k].zip(nodes[(k + 1) % 4]);
            if let Some(m) = self.midpoint((cube, row), ends, xa, xb) {
                face[n] = m;
                n += 1;
            }
        }
        let face = &mut face[..n];
        if i >= self.m.halo_start {
            // Both sides start at the lowest point.
            let at = (0..n).min_by_key(|&k| point_key(face[k].1)).unwrap_or(0);
            face.rotate_left(at);
        }
        poly.extend(face.iter().map(|p| p.0));
        Ok(())
    }
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

/// Writes the case `dir` for `mesh`'s `faces` (collective).
pub fn write_case(
    comm: &dyn Comm,
    dir: &Path,
    mesh: &Mesh,
    faces: &Faces,
    opts: &FoamOptions,
) -> Result<FoamCounts> {
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
    // A core no rank of this node runs on makes the polygons while this
    // rank labels them (a serial run on a workstation, say).
    let spare_core = crate::parallel::cores::spare_core(comm);
    let scratch = partial(&target);
    let written = (|| -> Result<FoamCounts> {
        let _ = fs::remove_dir_all(&scratch);
        fs::create_dir_all(&scratch).map_err(|e| io_err(&scratch, e))?;
        write_polymesh(&scratch, mesh, faces, opts, (me, p), spare_core)
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
    Ok(counts)
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

fn header(
    out: &mut impl Write,
    format: FoamFormat,
    class: &str,
    location: &str,
    object: &str,
    note: Option<&str>,
) -> std::io::Result<()> {
    writeln!(
        out,
        "/*--------------------------------*- C++ -*----------------------------------*\\"
    )?;
    writeln!(out, "  written by octmesh {}", env!("CARGO_PKG_VERSION"))?;
    writeln!(
        out,
        "\\*---------------------------------------------------------------------------*/"
    )?;
    writeln!(out, "FoamFile\n{{")?;
    writeln!(out, "    version     2.0;")?;
    writeln!(out, "    format      {};", format.name())?;
    writeln!(out, "    arch        \"LSB;label=32;scalar=64\";")?;
    writeln!(out, "    class       {class};")?;
    if let Some(n) = note {
        writeln!(out, "    note        \"{n}\";")?;
    }
    writeln!(out, "    location    \"{location}\";")?;
    writeln!(out, "    object      {object};")?;
    writeln!(out, "}}\n")
}

/// Writes the `n` labels of `v` as a labelList body.
fn write_label_iter(
    out: &mut impl Write,
    format: FoamFormat,
    n: usize,
    v: impl Iterator<Item = u32>,
) -> std::io::Result<()> {
    write!(out, "{n}\n(")?;
    match format {
        FoamFormat::Binary => {
            // Through one small buffer, reused: no copy of the whole list
            // (tens of megabytes, all of it fresh pages to fault in).
            const CHUNK: usize = 1 << 16;
            let mut buf = Vec::with_capacity(CHUNK);
            for x in v {
                buf.push(x);
                if buf.len() == CHUNK {
                    write_raw(out, &buf)?;
                    buf.clear();
                }
            }
            write_raw(out, &buf)?;
            writeln!(out, ")")
        }
        FoamFormat::Ascii => {
            writeln!(out)?;
            for x in v {
                writeln!(out, "{x}")?;
            }
            writeln!(out, ")")
        }
    }
}

/// Numbers written to binary lists as their raw little-endian bytes:
/// 32-bit labels (below 2^31 they have the bits of OpenFOAM's signed ones)
/// and points of three 64-bit scalars. Both are plain numbers without
/// padding.
trait Raw: Copy {
    /// Appends the little-endian bytes (for big-endian machines).
    fn put_le(&self, out: &mut Vec<u8>);
}

impl Raw for u32 {
    fn put_le(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
}

impl Raw for [f64; 3] {
    fn put_le(&self, out: &mut Vec<u8>) {
        self.iter()
            .for_each(|x| out.extend_from_slice(&x.to_le_bytes()));
    }
}

/// Writes `v` as raw little-endian bytes.
fn write_raw<T: Raw>(out: &mut impl Write, v: &[T]) -> std::io::Result<()> {
    if cfg!(target_endian = "little") {
        // SAFETY: `T` is `u32` or `[f64; 3]` (no padding, every bit
        // pattern a value) and any alignment suits `u8`; the bytes are
        // those of `v`, which outlives the borrow.
        let bytes = unsafe {
            std::slice::from_raw_parts(v.as_ptr().cast::<u8>(), std::mem::size_of_val(v))
        };
        out.write_all(bytes)
    } else {
        let mut buf = Vec::with_capacity(std::mem::size_of_val(v));
        v.iter().for_each(|x| x.put_le(&mut buf));
        out.write_all(&buf)
    }
}

/// The local nodes' positions, written to [`PointsOut`] in label order in
/// short steps: on a mesh that is not snapped, the nodes' lattice points
/// are gathered from the elements' corners first.
struct NodeFill<'m> {
    nodes: &'m NodeLabels,
    /// By node; empty on a snapped mesh.
    lattice: Vec<[u32; 3]>,
    /// Elements whose corners are in `lattice`.
    gathered: usize,
    /// Labels written, and the entries of `nodes.moved` passed.
    written: u32,
    moved_at: usize,
}

impl<'m> NodeFill<'m> {
    /// Elements, or labels, per step.
    const STEP: usize = 1 << 15;

    fn new(mesh: &'m Mesh, nodes: &'m NodeLabels) -> Self {
        let lattice = match mesh.moved() {
            Some(_) => Vec::new(),
            None => vec![[0; 3]; mesh.num_nodes()],
        };
        NodeFill {
            nodes,
            lattice,
            gathered: 0,
            written: 0,
            moved_at: 0,
        }
    }

    /// One step into `out`; whether there are more.
    fn step(&mut self, out: &mut PointsOut) -> Result<bool> {
        let (mesh, snapped) = (out.mesh, out.mesh.moved());
        let ne = mesh.elements().len();
        if snapped.is_none() && self.gathered < ne {
            let r = self.gathered..ne.min(self.gathered + Self::STEP);
            self.gathered = r.end;
            let lattice = &mut self.lattice;
            mesh.for_each_corner_in(r, |n, x| lattice[n as usize] = x);
            return Ok(true);
        }
        let direct = self.nodes.direct;
        let end = direct.min(self.written + Self::STEP as u32);
        let domain = out.mesh.domain();
        for l in self.written..end {
            let n = self.nodes.node(l, &mut self.moved_at) as usize;
            out.put(match snapped {
                Some(m) => m[n],
                None => domain.from_lattice(self.lattice[n].map(f64::from)),
            })?;
        }
        self.written = end;
        if end == direct {
            self.lattice = Vec::new();
        }
        Ok(end < direct)
    }
}

/// The `points` file in label order ([`NodeLabels`]): the local nodes, then
/// the halo points the faces used (user units: the moved positions on a
/// snapped mesh, the lattice's otherwise). In binary the positions stream
/// to the file and the count goes last over room left for it, as in
/// `faces`: no array of every position is made. ASCII cases (small ones)
/// keep the positions and write them at the end.
struct PointsOut<'m> {
    mesh: &'m Mesh,
    fmt: FoamFormat,
    path: PathBuf,
    /// Binary: the file's writer, from the first position on.
    w: Option<DirectWriter>,
    /// Where the first position goes (binary).
    data_at: u64,
    /// Binary: the positions not yet handed to `w`; ASCII: all of them.
    block: Vec<[f64; 3]>,
    /// On a snapped mesh, the halo points with their labels: their
    /// positions are the means of moved corners, found in one pass at the
    /// end (NaN until then).
    off_node: Vec<([u32; 3], u32)>,
    count: u32,
}

impl<'m> PointsOut<'m> {
    fn new(path: &Path, fmt: FoamFormat, loc: &str, mesh: &'m Mesh) -> Result<Self> {
        let head = points_head(fmt, loc, 0).map_err(|e| io_err(path, e))?;
        let w = match fmt {
            FoamFormat::Binary => {
                let mut w = create(path)?;
                w.restart_at(head.len() as u64)
                    .map_err(|e| io_err(path, e))?;
                Some(w)
            }
            FoamFormat::Ascii => None,
        };
        Ok(PointsOut {
            mesh,
            fmt,
            path: path.to_path_buf(),
            w,
            data_at: head.len() as u64,
            block: Vec::with_capacity(1 << 14),
            off_node: Vec::new(),
            count: 0,
        })
    }

    /// The halo points at lattice points `xs`, in label order, after the
    /// nodes.
    fn halo(&mut self, xs: &[[u32; 3]]) -> Result<()> {
        xs.iter().try_for_each(|&x| {
            let p = match self.mesh.moved() {
                Some(_) => {
                    self.off_node.push((x, self.count));
                    [f64::NAN; 3]
                }
                None => self.mesh.domain().from_lattice(x.map(f64::from)),
            };
            self.put(p)
        })
    }

    /// The next position.
    fn put(&mut self, p: [f64; 3]) -> Result<()> {
        self.count += 1;
        self.block.push(p);
        if let Some(w) = &mut self.w {
            if self.block.len() == self.block.capacity() {
                write_raw(w, &self.block).map_err(|e| io_err(&self.path, e))?;
                self.block.clear();
            }
        }
        Ok(())
    }

    /// Writes what is left, the off-node positions, the end and the
    /// header.
    fn finish(mut self, loc: &str) -> Result<u32> {
        let path = self.path.clone();
        let io = |e: std::io::Error| io_err(&path, e);
        let q: Vec<[u32; 3]> = self.off_node.iter().map(|o| o.0).collect();
        let off = if q.is_empty() {
            Vec::new()
        } else {
            self.mesh.off_node_positions(&q)?
        };
        let head = points_head(self.fmt, loc, self.count).map_err(io)?;
        match self.w.take() {
            Some(mut w) => {
                write_raw(&mut w, &self.block).map_err(io)?;
                w.write_all(b")\n").map_err(io)?;
                for (&(_, l), p) in self.off_node.iter().zip(&off) {
                    w.restart_at(self.data_at + 24 * l as u64).map_err(io)?;
                    write_raw(&mut w, std::slice::from_ref(p)).map_err(io)?;
                }
                w.restart_at(0).map_err(io)?;
                w.write_all(&head).map_err(io)?;
                w.flush().map_err(io)?;
            }
            None => {
                for (&(_, l), p) in self.off_node.iter().zip(&off) {
                    self.block[l as usize] = *p;
                }
                let mut w = create(&path)?;
                w.write_all(&head).map_err(io)?;
                for x in &self.block {
                    writeln!(w, "({:.17e} {:.17e} {:.17e})", x[0], x[1], x[2]).map_err(io)?;
                }
                w.write_all(b")\n").map_err(io)?;
                w.flush().map_err(io)?;
            }
        }
        Ok(self.count)
    }
}

/// The `points` file up to its first position: in binary the count padded
/// to [`COUNT_WIDTH`] (so it can be written last), in ASCII as is.
fn points_head(fmt: FoamFormat, loc: &str, count: u32) -> std::io::Result<Vec<u8>> {
    let mut head = Vec::new();
    header(&mut head, fmt, "vectorField", loc, "points", None)?;
    match fmt {
        FoamFormat::Binary => write!(head, "{count:<COUNT_WIDTH$}\n(")?,
        FoamFormat::Ascii => write!(head, "{count}\n(\n")?,
    }
    Ok(head)
}

/// Width of a count written after its list in binary (the labels of
/// `faces`, the positions of `points`): the list is streamed before its
/// length is known, and the count written over room left for it
/// (OpenFOAM skips the trailing blanks).
const COUNT_WIDTH: usize = 20;

/// Writes the `faces` file of this rank, the face polygons streamed from
/// [`face_polygons`] (which runs the steps of `side` on the way); returns
/// the halo points they used, in label order.
fn write_faces(
    path: &Path,
    (fmt, loc): (FoamFormat, &str),
    mesh: (&Mesh, &Faces),
    nodes: &NodeLabels,
    spare_core: bool,
    side: impl FnMut() -> Result<bool>,
) -> Result<Vec<[u32; 3]>> {
    let io = |e: std::io::Error| io_err(path, e);
    let nf = mesh.1.faces().len();
    match fmt {
        FoamFormat::Binary => {
            // A faceCompactList: the offsets, then the labels. Both go to
            // the file as they come, each through its own writer at its
            // own place; the header, the end of the offsets and the label
            // count are written last.
            let mut head = Vec::new();
            header(&mut head, fmt, "faceCompactList", loc, "faces", None).map_err(io)?;
            write!(head, "{}\n(", nf + 1).map_err(io)?;
            // Between the two lists: the end of the offsets, then the
            // label count (written last, over the same room).
            let between = |count: u32| format!(")\n\n{count:<COUNT_WIDTH$}\n(");
            let offsets_end = head.len() + 4 * (nf + 1);
            let data_at = offsets_end + between(0).len();
            let mut w = DirectWriter::create(path).map_err(io)?;
            w.restart_at(data_at as u64).map_err(io)?;
            let mut wo = DirectWriter::open(path).map_err(io)?;
            wo.restart_at(head.len() as u64).map_err(io)?;
            let mut offsets = Vec::with_capacity(POLYGON_CHUNK + 1);
            offsets.push(0u32);
            let mut total = 0u32;
            let halo = face_polygons(mesh, nodes, spare_core, side, |c| {
                offsets.extend(c.lens.iter().map(|&n| {
                    total += n as u32;
                    total
                }));
                write_raw(&mut wo, &offsets).map_err(io)?;
                offsets.clear();
                write_raw(&mut w, &c.ids).map_err(io)
            })?;
            write_raw(&mut wo, &offsets).map_err(io)?;
            w.write_all(b")\n").map_err(io)?;
            w.flush().map_err(io)?;
            drop(w);
            wo.write_all(between(total).as_bytes()).map_err(io)?;
            wo.restart_at(0).map_err(io)?;
            wo.write_all(&head).map_err(io)?;
            wo.flush().map_err(io)?;
            Ok(halo)
        }
        FoamFormat::Ascii => {
            let mut w = create(path)?;
            header(&mut w, fmt, "faceList", loc, "faces", None).map_err(io)?;
            writeln!(w, "{nf}\n(").map_err(io)?;
            let halo = face_polygons(mesh, nodes, spare_core, side, |c| {
                let mut at = 0;
                c.lens
                    .iter()
                    .try_for_each(|&n| -> std::io::Result<()> {
                        let l = &c.ids[at..at + n as usize];
                        at += n as usize;
                        write!(w, "{}(", l.len())?;
                        for (k, x) in l.iter().enumerate() {
                            if k > 0 {
                                write!(w, " ")?;
                            }
                            write!(w, "{x}")?;
                        }
                        writeln!(w, ")")
                    })
                    .map_err(io)
            })?;
            writeln!(w, ")").map_err(io)?;
            w.flush().map_err(io)?;
            Ok(halo)
        }
    }
}

fn create(path: &Path) -> Result<DirectWriter> {
    DirectWriter::create(path).map_err(|e| io_err(path, e))
}

#[allow(clippy::too_many_arguments)]
fn write_polymesh(
    dir: &Path,
    mesh: &Mesh,
    faces: &Faces,
    opts: &FoamOptions,
    (me, p): (usize, usize),
    spare_core: bool,
) -> Result<FoamCounts> {
    let fmt = opts.format;
    let location = if p == 1 {
        "constant/polyMesh".to_string()
    } else {
        format!("processor{me}/constant/polyMesh")
    };
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
    let note = format!(
        "nPoints:{} nCells:{} nFaces:{} nInternalFaces:{}",
        counts.points, counts.cells, counts.faces, counts.internal_faces
    );
    let result = (|| -> std::io::Result<()> {
        let owners = faces.faces().iter().map(|f| f.owner());
        let path = dir.join("owner");
        let mut w = create(&path).map_err(std::io::Error::other)?;
        header(&mut w, fmt, "labelList", loc, "owner", Some(&note))?;
        write_label_iter(&mut w, fmt, nf, owners)?;
        w.flush()?;

        let neighbours = faces.faces()[..ni].iter().map(|f| match f.other() {
            Other::Element(j) => j,
            _ => 0,
        });
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
        let halo = faces.halo_ranges();
        let np = faces.num_patches();
        if opts.patches.names().len() != np {
            return Err(std::io::Error::other(format!(
                "{} patch names for {np} patches",
                opts.patches.names().len()
            )));
        }
        writeln!(w, "{}\n(", np + halo.len())?;
        for q in 0..np {
            let r = faces.patch_range(q);
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
        for (r, range) in halo {
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
    })();
    result.map_err(|e| Error::io(format!("writing {}: {e}", dir.display())))?;
    Ok(counts)
}

/// Writes the minimal `system/` files that are absent.
fn write_system(case: &Path, p: usize) -> Result<()> {
    let sys = case.join("system");
    fs::create_dir_all(&sys).map_err(|e| io_err(&sys, e))?;
    let mut files = vec![
        ("controlDict", CONTROL_DICT.to_string()),
        ("fvSchemes", FV_SCHEMES.to_string()),
        ("fvSolution", FV_SOLUTION.to_string()),
    ];
    if p > 1 {
        files.push((
            "decomposeParDict",
            format!("numberOfSubdomains {p};\n\nmethod          scotch;\n"),
        ));
    }
    for (name, body) in files {
        let path = sys.join(name);
        if path.exists() {
            continue;
        }
        let mut text = Vec::new();
        header(
            &mut text,
            FoamFormat::Ascii,
            "dictionary",
            "system",
            name,
            None,
        )
        .and_then(|_| text.write_all(body.as_bytes()))
        .map_err(|e| io_err(&path, e))?;
        fs::write(&path, text).map_err(|e| io_err(&path, e))?;
    }
    Ok(())
}

const CONTROL_DICT: &str = "application     simpleFoam;

startFrom       latestTime;
startTime       0;
stopAt          endTime;
endTime         500;
deltaT          1;
writeControl    timeStep;
writeInterval   100;
purgeWrite      0;
writeFormat     binary;
writePrecision  8;
writeCompression off;
timeFormat      general;
timePrecision   6;
runTimeModifiable true;
";

const FV_SCHEMES: &str = "ddtSchemes
{
    default         steadyState;
}

gradSchemes
{
    default         Gauss linear;
}

divSchemes
{
    default         none;
    div(phi,U)      bounded Gauss linearUpwind grad(U);
    div((nuEff*dev2(T(grad(U))))) Gauss linear;
    div(div(phi,U)) Gauss linear;
}

laplacianSchemes
{
    default         Gauss linear corrected;
}

interpolationSchemes
{
    default         linear;
}

snGradSchemes
{
    default         corrected;
}
";

const FV_SOLUTION: &str = "solvers
{
    p
    {
        solver          GAMG;
        smoother        GaussSeidel;
        tolerance       1e-7;
        relTol          0.01;
    }

    Phi
    {
        $p;
    }

    U
    {
        solver          smoothSolver;
        smoother        GaussSeidel;
        tolerance       1e-8;
        relTol          0.1;
    }
}

SIMPLE
{
    nNonOrthogonalCorrectors 0;
    consistent      yes;
}

potentialFlow
{
    nNonOrthogonalCorrectors 3;
}

relaxationFactors
{
    equations
    {
        U               0.9;
        \".*\"            0.9;
    }
}
";

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::sphere_mesh;

    /// Each face's labels, then each label's lattice point.
    type Written = (Vec<Vec<u32>>, Vec<[u32; 3]>);

    /// The labels of every face and the points in label order.
    fn polygons(mesh: &Mesh, faces: &Faces, spare_core: bool) -> Written {
        let mut out = Vec::new();
        let labels = NodeLabels::new(mesh);
        let halo = face_polygons(
            (mesh, faces),
            &labels,
            spare_core,
            || Ok(false),
            |c| {
                let mut at = 0;
                for &n in &c.lens {
                    out.push(c.ids[at..at + n as usize].to_vec());
                    at += n as usize;
                }
                Ok(())
            },
        )
        .unwrap();
        let (lattice, mut at) = (mesh.node_lattice(), 0);
        let mut points: Vec<[u32; 3]> = (0..labels.direct)
            .map(|l| lattice[labels.node(l, &mut at) as usize])
            .collect();
        points.extend(halo);
        (out, points)
    }

    #[test]
    fn a_second_thread_makes_the_same_polygons() {
        let mesh = sphere_mesh(6);
        let faces = mesh.faces().unwrap();
        // Several chunks, the last one short.
        assert!(faces.faces().len() > 3 * POLYGON_CHUNK + 1);
        let (serial, points) = polygons(&mesh, &faces, false);
        assert!(
            serial.iter().any(|l| l.len() > 4),
            "no polygon with a hanging point"
        );
        assert_eq!((serial, points), polygons(&mesh, &faces, true));
    }

    /// Every label is a distinct point that some face uses, and each face
    /// is its four corners in order with the points between them on its
    /// edges.
    #[test]
    fn labels_are_the_points_of_the_faces() {
        let mesh = sphere_mesh(5);
        let faces = mesh.faces().unwrap();
        let (polys, points) = polygons(&mesh, &faces, false);
        let mut keys: Vec<u64> = points.iter().map(|&x| point_key(x)).collect();
        keys.sort_unstable();
        keys.dedup();
        assert_eq!(keys.len(), points.len(), "two labels at one point");
        let mut used = vec![false; points.len()];
        for (f, poly) in faces.faces().iter().zip(&polys) {
            poly.iter().for_each(|&l| used[l as usize] = true);
            let at: Vec<[u32; 3]> = poly.iter().map(|&l| points[l as usize]).collect();
            let c = f.corners();
            let corners: Vec<usize> = c
                .iter()
                .map(|x| at.iter().position(|y| y == x).expect("a corner is missing"))
                .collect();
            let mut extra = 0;
            for k in 0..4 {
                let (a, b) = (corners[k], corners[(k + 1) % 4]);
                // The points after corner k up to corner k + 1 (cyclically).
                let between = (b + at.len() - a - 1) % at.len();
                assert!(between <= 1, "a side holds {between} points");
                if between == 1 {
                    let m = at[(a + 1) % at.len()];
                    assert_eq!(Some(m), edge_midpoint(c[k], c[(k + 1) % 4]));
                }
                extra += between;
            }
            assert_eq!(at.len(), 4 + extra, "the corners out of order");
        }
        assert!(used.iter().all(|&u| u), "a point no face uses");
    }
}
