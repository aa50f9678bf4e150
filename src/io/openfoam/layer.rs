//! The wall layer: a case whose wall lies on the surface, made by
//! pillowing the staircase kept off it.
//!
//! Every wall face of the staircase (a face of a surface patch, with the
//! hanging points on its edges) gets one more cell between it and the
//! surface: the wall face becomes an internal face between its old cell and
//! the new one, the new cell's outer face is the face's polygon on the
//! surface (the same patch), and the new cells meet each other across the
//! wall's edges. So no old cell keeps a face on the wall, a staircase corner
//! with two or three wall faces is not flattened, and every wall point lies
//! on the surface. The points on the surface (`layer_points`) are found from
//! the surface alone, merged over the ranks by integer sums, so a point on a
//! partition boundary has the same position on every rank that has it and
//! on any number of ranks.
//!
//! The case is made in memory from the staircase's faces (the points,
//! polygons, owners and patches of [`super::polygons`]), changed, then
//! written: the wall layer is for the meshes a CFD user runs a solver on,
//! not for the largest ones the streaming writer is made for. `stack` adds
//! a column of cells per wall face between layers of points (one cell for
//! the wall layer; the buffer and N boundary layers of `layer_stack`).

use std::collections::HashMap;
use std::ops::Range;

use super::*;
use crate::geometry::Surface;

pub(super) use super::layer_points::Directory;

/// One rank's polyMesh in memory.
pub(super) struct PolyMesh {
    /// Positions by label.
    pub(super) points: Vec<[f64; 3]>,
    /// The staircase's lattice point of each label (new points: none).
    pub(super) lattice: Vec<[u32; 3]>,
    /// Whether another rank may have the point (a point on a processor
    /// face, a node another rank uses, a hanging node), by label.
    pub(super) watch: Vec<bool>,
    /// Face `i`'s labels: `ids[start[i]..start[i + 1]]`.
    pub(super) start: Vec<usize>,
    pub(super) ids: Vec<u32>,
    pub(super) owner: Vec<u32>,
    /// One per internal face (the first ones).
    pub(super) neighbour: Vec<u32>,
    pub(super) cells: usize,
    /// Boundary faces by patch.
    pub(super) patches: Vec<Range<usize>>,
    /// Processor faces by neighbour rank (ranks increasing).
    pub(super) procs: Vec<(u32, Range<usize>)>,
}

impl PolyMesh {
    /// The labels of face `i`.
    pub(super) fn face(&self, i: usize) -> &[u32] {
        &self.ids[self.start[i]..self.start[i + 1]]
    }

    /// The staircase's case: the polygons, points and lists the streaming
    /// writer would write, kept.
    pub(super) fn from_mesh(mesh: &Mesh, faces: &Faces) -> Result<PolyMesh> {
        let nodes = NodeLabels::new(mesh);
        let mut ids = Vec::new();
        let mut start = vec![0usize];
        let halo = face_polygons(
            (mesh, faces),
            &nodes,
            false,
            || Ok(false),
            |c| {
                let mut at = 0;
                for &n in &c.lens {
                    ids.extend_from_slice(&c.ids[at..at + n as usize]);
                    at += n as usize;
                    start.push(ids.len());
                }
                Ok(())
            },
        )?;
        let node_lattice = mesh.node_lattice();
        let (ni, shared) = (mesh.num_independent() as u32, mesh.shared_nodes());
        let mut at = 0;
        let mut lattice = Vec::with_capacity(nodes.direct as usize + halo.len());
        let mut watch = Vec::with_capacity(lattice.capacity());
        for l in 0..nodes.direct {
            let n = nodes.node(l, &mut at);
            lattice.push(node_lattice[n as usize]);
            watch.push(n >= ni || shared.binary_search(&n).is_ok());
        }
        watch.extend(halo.iter().map(|_| true));
        lattice.extend(halo);
        let domain = mesh.domain();
        let points = lattice
            .iter()
            .map(|x| domain.from_lattice(x.map(f64::from)))
            .collect();
        let ni = faces.num_internal();
        Ok(PolyMesh {
            points,
            lattice,
            watch,
            start,
            ids,
            owner: faces.faces().iter().map(|f| f.owner()).collect(),
            neighbour: faces.faces()[..ni]
                .iter()
                .map(|f| match f.other() {
                    Other::Element(j) => j,
                    _ => 0,
                })
                .collect(),
            cells: mesh.elements().len(),
            patches: (0..faces.num_patches())
                .map(|q| faces.patch_range(q))
                .collect(),
            procs: faces.halo_ranges().to_vec(),
        })
    }
}

/// The wall of a staircase: its faces, its points and the edges between
/// its faces.
pub(super) struct Wall {
    /// The wall faces (the faces of the surface patches), in face order.
    pub(super) faces: Vec<usize>,
    /// The wall points' labels, by lattice key.
    pub(super) labels: Vec<u32>,
    pub(super) keys: Vec<u64>,
    /// Each wall face's points as wall point numbers.
    pub(super) polys: Vec<Vec<u32>>,
    /// Each wall face's outward axis: `2 * axis + (1 if positive)`.
    pub(super) dirs: Vec<u8>,
    /// Each wall face's side length (user units).
    pub(super) sides: Vec<f64>,
    /// The wall face on the other side of each directed edge `(a, b)` of a
    /// wall face (wall point numbers): `(b, a)` in that face.
    pub(super) across: HashMap<(u32, u32), usize>,
    /// The directed edges whose other face is on another rank, with it.
    pub(super) remote: Vec<((u32, u32), u32)>,
}

impl Wall {
    /// The wall of `pm` (collective: edges whose other face is on another
    /// rank are matched through the directory).
    pub(super) fn new(comm: &dyn Comm, pm: &PolyMesh, domain_side: f64) -> Result<Wall> {
        let faces: Vec<usize> = (SURFACE_PATCH as usize..pm.patches.len())
            .flat_map(|q| pm.patches[q].clone())
            .collect();
        let key = |l: u32| point_key(pm.lattice[l as usize]);
        let mut labels: Vec<u32> = faces.iter().flat_map(|&f| pm.face(f)).copied().collect();
        labels.sort_unstable_by_key(|&l| (key(l), l));
        labels.dedup();
        let keys: Vec<u64> = labels.iter().map(|&l| key(l)).collect();
        let mut number = HashMap::with_capacity(labels.len());
        for (i, &l) in labels.iter().enumerate() {
            number.insert(l, i as u32);
        }
        let lattice_len = domain_side / crate::octree::octant::ROOT_LEN as f64;
        let mut polys = Vec::with_capacity(faces.len());
        let (mut dirs, mut sides) = (Vec::new(), Vec::new());
        let mut across = HashMap::with_capacity(4 * faces.len());
        let mut local = Ok(());
        for (k, &f) in faces.iter().enumerate() {
            let poly: Vec<u32> = pm.face(f).iter().map(|l| number[l]).collect();
            let xs: Vec<[u32; 3]> = pm.face(f).iter().map(|&l| pm.lattice[l as usize]).collect();
            let span = |a: usize| {
                let lo = xs.iter().map(|x| x[a]).min().unwrap_or(0);
                xs.iter().map(|x| x[a]).max().unwrap_or(0) - lo
            };
            let axis = (0..3).find(|&a| span(a) == 0).unwrap_or(0);
            let area = polygon_area(pm.face(f).iter().map(|&l| pm.points[l as usize]));
            dirs.push(2 * axis as u8 + u8::from(area[axis] > 0.0));
            sides.push((0..3).map(span).max().unwrap_or(0) as f64 * lattice_len);
            for i in 0..poly.len() {
                let e = (poly[i], poly[(i + 1) % poly.len()]);
                if across.insert(e, k).is_some() && local.is_ok() {
                    local = Err(Error::invalid(format!(
                        "the wall is not manifold at {:?}: an edge has more than two wall faces \
                         (--clean-walls true keeps the walls manifold)",
                        pm.points[labels[e.0 as usize] as usize]
                    )));
                }
            }
            polys.push(poly);
        }
        agree(comm, local)?;
        // Edges without their reverse here: on another rank, or open.
        let open: Vec<(u32, u32)> = across
            .keys()
            .filter(|&&(a, b)| !across.contains_key(&(b, a)))
            .copied()
            .collect();
        let mut open = open;
        open.sort_unstable();
        let partners = Directory::match_edges(
            comm,
            &open
                .iter()
                .map(|&(a, b)| (keys[a as usize], keys[b as usize]))
                .collect::<Vec<_>>(),
        );
        let mut remote = Vec::with_capacity(open.len());
        let mut local = Ok(());
        for (&e, r) in open.iter().zip(partners) {
            match r {
                Some(r) => remote.push((e, r)),
                None if local.is_ok() => {
                    local = Err(Error::invalid(format!(
                        "the wall is open at {:?}: the wall layer needs a closed wall \
                         (a surface inside the domain)",
                        pm.points[labels[e.0 as usize] as usize]
                    )))
                }
                None => {}
            }
        }
        agree(comm, local)?;
        Ok(Wall {
            faces,
            labels,
            keys,
            polys,
            dirs,
            sides,
            across,
            remote,
        })
    }
}

/// The area vector of a polygon (the sum of its fan's triangles about its
/// mean point).
pub(super) fn polygon_area(pts: impl Iterator<Item = [f64; 3]> + Clone) -> [f64; 3] {
    use crate::geometry::vector::{add, cross, scale, sub};
    let n = pts.clone().count().max(1);
    let c = scale(pts.clone().fold([0.0; 3], add), 1.0 / n as f64);
    let v: Vec<[f64; 3]> = pts.collect();
    let mut a = [0.0; 3];
    for i in 0..v.len() {
        a = add(a, cross(sub(v[i], c), sub(v[(i + 1) % v.len()], c)));
    }
    scale(a, 0.5)
}

/// Adds layers of cells on the wall of `pm`: `layers[0]` are the wall
/// points' new positions (the staircase's, moved in where needed), each
/// next one a layer of new points farther out, the last on the surface,
/// all by wall point number. Each wall face gets a column of
/// `layers.len() - 1` cells.
pub(super) fn stack(pm: &mut PolyMesh, wall: &Wall, layers: &[Vec<[f64; 3]>]) {
    let m = layers.len() - 1;
    let np = pm.points.len() as u32;
    let nw = wall.labels.len() as u32;
    for (i, &l) in wall.labels.iter().enumerate() {
        pm.points[l as usize] = layers[0][i];
    }
    for layer in &layers[1..] {
        pm.points.extend_from_slice(layer);
        pm.watch.extend(layer.iter().map(|_| false));
    }
    // The label of wall point `i` in point layer `j`.
    let at = |j: usize, i: u32| match j {
        0 => wall.labels[i as usize],
        _ => np + (j as u32 - 1) * nw + i,
    };
    let cells = pm.cells as u32;
    // A column's cells are consecutive, the wall's first.
    let cell_of = |k: usize, j: usize| cells + (k * m + j) as u32;
    let mut wall_at = vec![usize::MAX; pm.owner.len()];
    for (k, &f) in wall.faces.iter().enumerate() {
        wall_at[f] = k;
    }
    // Internal faces: the old ones, the wall faces, the faces between a
    // column's cells, the sides between new cells on this rank; then
    // ordered by owner and neighbour.
    let mut internal: Vec<(u32, u32, Vec<u32>)> = (0..pm.neighbour.len())
        .map(|i| (pm.owner[i], pm.neighbour[i], pm.face(i).to_vec()))
        .collect();
    for (k, &f) in wall.faces.iter().enumerate() {
        internal.push((pm.owner[f], cell_of(k, 0), pm.face(f).to_vec()));
        for j in 1..m {
            let poly = wall.polys[k].iter().map(|&i| at(j, i)).collect();
            internal.push((cell_of(k, j - 1), cell_of(k, j), poly));
        }
    }
    let side = |(a, b): (u32, u32), j: usize| vec![at(j, a), at(j, b), at(j + 1, b), at(j + 1, a)];
    for (k, poly) in wall.polys.iter().enumerate() {
        for i in 0..poly.len() {
            let e = (poly[i], poly[(i + 1) % poly.len()]);
            if let Some(&g) = wall.across.get(&(e.1, e.0)) {
                if k < g {
                    for j in 0..m {
                        internal.push((cell_of(k, j), cell_of(g, j), side(e, j)));
                    }
                }
            }
        }
    }
    internal.sort_by_key(|f| (f.0, f.1));
    let mut start = vec![0usize];
    let mut ids = Vec::with_capacity(pm.ids.len() * 2);
    let (mut owner, mut neighbour) = (Vec::new(), Vec::new());
    let mut put = |o: u32, poly: &[u32], ids: &mut Vec<u32>, start: &mut Vec<usize>| {
        owner.push(o);
        ids.extend_from_slice(poly);
        start.push(ids.len());
    };
    for (o, n, poly) in &internal {
        neighbour.push(*n);
        put(*o, poly, &mut ids, &mut start);
    }
    let mut patches = Vec::with_capacity(pm.patches.len());
    for q in 0..pm.patches.len() {
        let first = start.len() - 1;
        for f in pm.patches[q].clone() {
            match wall_at[f] {
                usize::MAX => put(pm.owner[f], pm.face(f), &mut ids, &mut start),
                k => {
                    let poly: Vec<u32> = wall.polys[k].iter().map(|&i| at(m, i)).collect();
                    put(cell_of(k, m - 1), &poly, &mut ids, &mut start);
                }
            }
        }
        patches.push(first..start.len() - 1);
    }
    // Processor faces: the old ones, then the sides whose other cell is on
    // that rank, ordered by their staircase edge's keys and their layer on
    // both sides and starting at the edge's lower point (the other side
    // then runs the other way, as a processor patch's faces do).
    let mut new_sides: Vec<(u32, u64, u64, usize, Vec<u32>, usize)> = Vec::new();
    for &((a, b), r) in &wall.remote {
        let k = wall.across[&(a, b)];
        let (ka, kb) = (wall.keys[a as usize], wall.keys[b as usize]);
        for j in 0..m {
            let mut poly = side((a, b), j);
            if kb < ka {
                poly.rotate_left(1);
            }
            new_sides.push((r, ka.min(kb), ka.max(kb), j, poly, cell_of(k, j) as usize));
        }
    }
    new_sides.sort_by_key(|s| (s.0, s.1, s.2, s.3));
    let mut ranks: Vec<u32> = pm.procs.iter().map(|p| p.0).collect();
    ranks.extend(new_sides.iter().map(|s| s.0));
    ranks.sort_unstable();
    ranks.dedup();
    let mut procs = Vec::with_capacity(ranks.len());
    for r in ranks {
        let first = start.len() - 1;
        if let Some((_, range)) = pm.procs.iter().find(|p| p.0 == r) {
            for f in range.clone() {
                put(pm.owner[f], pm.face(f), &mut ids, &mut start);
            }
        }
        for s in new_sides.iter().filter(|s| s.0 == r) {
            put(s.5 as u32, &s.4, &mut ids, &mut start);
        }
        procs.push((r, first..start.len() - 1));
    }
    pm.start = start;
    pm.ids = ids;
    pm.owner = owner;
    pm.neighbour = neighbour;
    pm.cells += wall.faces.len() * m;
    pm.patches = patches;
    pm.procs = procs;
}

/// Builds the case of `mesh` with a wall layer on `surface`, and the
/// boundary layers of `plan` in it (collective; the same result on every
/// rank).
pub(super) fn layered_case(
    comm: &dyn Comm,
    (mesh, faces): (&Mesh, &Faces),
    surface: &Surface,
    plan: Option<&super::layer_stack::LayerPlan>,
    names: &PatchNames,
) -> Result<(PolyMesh, Option<super::layer_stack::LayerReport>)> {
    let local = PolyMesh::from_mesh(mesh, faces);
    let mut pm = agree(comm, local)?;
    let wall = Wall::new(comm, &pm, mesh.domain().side)?;
    // With layers the wall cell is cut into the buffer and the layers; the
    // cut's last resort (`layer_stack`) is the even one, whose slab at the
    // surface must then be valid too.
    let slab = plan.map_or(0.0, |p| 1.0 / f64::from(p.most() + 1));
    let (inner, outer) =
        super::layer_points::place(comm, &mut pm, &wall, (mesh.domain(), surface), slab)?;
    let report = match plan {
        Some(plan) => Some(super::layer_stack::add_layers(
            comm,
            &mut pm,
            &wall,
            (plan, names, mesh.domain().side),
            (inner, outer),
        )),
        None => {
            stack(&mut pm, &wall, &[inner, outer]);
            None
        }
    };
    Ok((pm, report))
}

/// Writes `pm` as the polyMesh files in `dir`.
pub(super) fn write_layered(
    dir: &Path,
    pm: &PolyMesh,
    opts: &FoamOptions,
    (loc, me): (&str, usize),
) -> Result<FoamCounts> {
    let fmt = opts.format;
    let nf = pm.owner.len();
    let counts = FoamCounts {
        points: pm.points.len() as u64,
        faces: nf as u64,
        internal_faces: pm.neighbour.len() as u64,
        cells: pm.cells as u64,
    };
    let written = (|| -> std::io::Result<()> {
        let head = points_head(fmt, loc, pm.points.len() as u32)?;
        let mut w = create(&dir.join("points")).map_err(std::io::Error::other)?;
        w.write_all(&head)?;
        match fmt {
            FoamFormat::Binary => write_raw(&mut w, &pm.points)?,
            FoamFormat::Ascii => {
                for x in &pm.points {
                    writeln!(w, "({:.17e} {:.17e} {:.17e})", x[0], x[1], x[2])?;
                }
            }
        }
        w.write_all(b")\n")?;
        w.flush()?;
        let mut w = create(&dir.join("faces")).map_err(std::io::Error::other)?;
        match fmt {
            FoamFormat::Binary => {
                header(&mut w, fmt, "faceCompactList", loc, "faces", None)?;
                write!(w, "{}\n(", nf + 1)?;
                let offsets: Vec<u32> = pm.start.iter().map(|&s| s as u32).collect();
                write_raw(&mut w, &offsets)?;
                write!(w, ")\n\n{}\n(", pm.ids.len())?;
                write_raw(&mut w, &pm.ids)?;
                w.write_all(b")\n")?;
            }
            FoamFormat::Ascii => {
                header(&mut w, fmt, "faceList", loc, "faces", None)?;
                writeln!(w, "{nf}\n(")?;
                for i in 0..nf {
                    let f = pm.face(i);
                    write!(w, "{}(", f.len())?;
                    for (k, x) in f.iter().enumerate() {
                        write!(w, "{}{x}", if k > 0 { " " } else { "" })?;
                    }
                    writeln!(w, ")")?;
                }
                writeln!(w, ")")?;
            }
        }
        w.flush()?;
        write_cells(
            dir,
            (fmt, loc, me),
            &counts,
            (pm.owner.iter().copied(), pm.neighbour.iter().copied()),
            opts,
            (&pm.patches, &pm.procs),
        )
    })();
    written.map_err(|e| Error::io(format!("writing {}: {e}", dir.display())))?;
    Ok(counts)
}
