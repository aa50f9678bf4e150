//! The faces as OpenFOAM polygons: each face's corners and the mesh points
//! on its edges, in order, as point labels.

use super::*;

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
pub(super) struct NodeLabels {
    /// Local nodes below this are their own labels.
    pub(super) direct: u32,
    /// Local nodes.
    pub(super) nn: u32,
    /// The labels of nodes `direct..nn` (`u32::MAX` for an unused one).
    pub(super) tail: Vec<u32>,
    /// `(label, node)` for each label below `direct` that is not its
    /// node's number, by label.
    pub(super) moved: Vec<(u32, u32)>,
}

impl NodeLabels {
    pub(super) fn new(mesh: &Mesh) -> NodeLabels {
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
    pub(super) fn node(&self, l: u32, at: &mut usize) -> u32 {
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
pub(super) struct Labeller<'a> {
    pub(super) nodes: &'a NodeLabels,
    /// Each halo point's label plus one (zero: not used yet), by its
    /// place in the searched set.
    pub(super) halo: Vec<u32>,
    /// The used halo points' places, in label order.
    pub(super) order: Vec<u32>,
    /// A face used an unused node (an inconsistent mesh).
    pub(super) unused_hit: bool,
}

impl Labeller<'_> {
    #[inline]
    pub(super) fn of(&mut self, id: u32) -> u32 {
        if id < self.nodes.direct {
            id
        } else {
            self.rare(id)
        }
    }

    #[cold]
    pub(super) fn rare(&mut self, id: u32) -> u32 {
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
pub(super) fn face_polygons(
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
pub(super) const POLYGON_CHUNK: usize = 1 << 13;

/// Polygons of consecutive faces: their points (numbers, then labels),
/// then each face's count.
#[derive(Default)]
pub(super) struct Chunk {
    pub(super) ids: Vec<u32>,
    pub(super) lens: Vec<u8>,
}

/// The parts of the mesh and its faces the polygons are made from, copied
/// into each thread's maker: read in the hot loop by one load each.
#[derive(Clone, Copy)]
pub(super) struct MeshParts<'m> {
    pub(super) faces: &'m [Face],
    pub(super) halo_start: usize,
    pub(super) elements: &'m [crate::octree::octant::Octant],
    pub(super) conn: &'m [[u32; 8]],
    pub(super) nn: usize,
    pub(super) ni: usize,
}

/// What the polygons are made from, made once for the threads that make
/// them.
pub(super) struct PolygonIndex<'m> {
    pub(super) parts: MeshParts<'m>,
    /// The hanging nodes by the nodes they depend on.
    pub(super) hanging: DepsIndex,
    /// The halo's corners.
    pub(super) halo: PointIndex,
    /// Whether an edge between two local nodes may carry a point.
    pub(super) midpoints: EdgeMidpoints,
}

impl<'m> PolygonIndex<'m> {
    /// The index of `mesh` and `faces`; with `spare_core`, the hanging
    /// nodes' part on a second thread.
    pub(super) fn new(mesh: &'m Mesh, faces: &'m Faces, spare_core: bool) -> Self {
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
pub(super) struct Polygons<'m> {
    pub(super) m: MeshParts<'m>,
    pub(super) hanging: &'m DepsIndex,
    pub(super) midpoints: &'m EdgeMidpoints,
    /// A copy of the index's: the searches' hint is this thread's.
    pub(super) halo: PointIndex,
    /// The last emitter and its cube: faces come by owner, so a few in a
    /// row share it.
    pub(super) last: (u32, ([u32; 3], u32)),
}

impl<'m> Polygons<'m> {
    pub(super) fn new(ix: &'m PolygonIndex<'m>) -> Self {
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
    pub(super) fn hanging_on(
        &self,
        (c, s): ([u32; 3], u32),
        row: &[u32; 8],
        x: [u32; 3],
    ) -> Option<u32> {
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
    pub(super) fn off_corner(
        &mut self,
        cube: ([u32; 3], u32),
        row: &[u32; 8],
        x: [u32; 3],
    ) -> Option<u32> {
        self.hanging_on(cube, row, x).or_else(|| self.halo_point(x))
    }

    /// The number of the halo's corner at `x` (`nn + j`), if `x` is one.
    pub(super) fn halo_point(&mut self, x: [u32; 3]) -> Option<u32> {
        Some((self.m.nn + self.halo.find(point_key(x))?) as u32)
    }

    /// The local element whose whole face `f` is: the owner, or a finer
    /// local neighbour.
    pub(super) fn emitter(&self, f: &Face) -> Option<u32> {
        if self.m.elements[f.owner() as usize].side() == f.emitter_side() {
            return Some(f.owner());
        }
        match f.other() {
            Other::Element(j) => Some(j),
            _ => None,
        }
    }

    #[inline]
    pub(super) fn cube(&self, e: u32) -> ([u32; 3], u32) {
        let o = self.m.elements[e as usize];
        (o.coords(), o.side())
    }

    /// The point in the middle of the edge from `xa` to `xb`, if there is
    /// one; the edge lies on the cube `(c, s)` (corner nodes `row`), and
    /// `ends` are its ends' local nodes when they are the cube's corners.
    #[inline]
    pub(super) fn midpoint(
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
    pub(super) fn chunk(&mut self, range: std::ops::Range<usize>, c: &mut Chunk) -> Result<()> {
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
    pub(super) fn polygon(&mut self, i: usize, poly: &mut Vec<u32>) -> Result<()> {
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
