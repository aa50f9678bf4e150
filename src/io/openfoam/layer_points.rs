//! The points of the wall layer: where each wall point of the staircase
//! goes on the surface, and how far the staircase point moves in.
//!
//! A wall point's outer point is the first hit of a ray along the mean of
//! its faces' outward normals within [`CAST`] cells (else along its faces'
//! normals and between, the nearest hit; else its closest surface point).
//! The outer points then spread along the surface by [`SMOOTH`] rounds of
//! neighbour means projected back onto it, a round kept per point only
//! where its outer point stays ahead of its faces, and the staircase point
//! moves in along its normal until the outer point is [`DEPTH`] cells ahead
//! of each of its faces (at most [`REACH`] cells), so no new cell starts
//! flat. Last, the points of new cells that are invalid or near checkMesh's
//! limits move (`Ctx::improve`, [`cell_figure`]): outer points along the
//! surface, staircase points under their outer points. With boundary
//! layers the slabs of a new cell cut evenly into the buffer and the
//! layers (the layers' last resort, `layer_stack`) must be valid too at
//! both ends: a cell valid as a whole can be too sheared or twisted for a
//! thin slab at the surface or at the staircase.
//!
//! Parallel: a wall point's faces may lie on several ranks. Each point has
//! a home rank (by a hash of its lattice key) that merges what the ranks
//! know of it (the normals of its faces, its finest face), sums the
//! neighbour means and outer normals of each round as integers (fixed
//! point), takes the least of the ranks' cell figures, and tells the ranks
//! that only have the point in a cell where it moved. Every rank that
//! has a wall point then computes the same position from the same data, and
//! the positions do not depend on the number of ranks.

use std::collections::{BTreeMap, HashMap};

use super::layer::{PolyMesh, Wall};
use super::layer_cell::{end_slabs, with_prism};
use super::*;
use crate::geometry::bvh::Bvh;
use crate::geometry::distance::closest_point_triangle;
use crate::geometry::vector::{add, add_scaled, dot, norm, scale, sub};
use crate::geometry::{Surface, Triangle};
use crate::octree::domain::Domain;
use crate::parallel::cores::{join, map_chunks, spare_core};

/// How far (in cells of the point's finest wall face) a ray looks for the
/// surface.
const CAST: f64 = 3.0;
/// Rounds of smoothing along the surface.
const SMOOTH: usize = 5;
/// Wall points per piece of a pass shared with a spare core.
const CHUNK: usize = 4096;
/// How far (cells) the outer point must be ahead of each face of its
/// staircase point.
const DEPTH: f64 = 0.2;
/// How far (cells) a staircase point may move in.
const REACH: f64 = 0.6;
/// How far (cells) a staircase point may move from the staircase while
/// the new cells are improved.
const SHIFT: f64 = 0.7;
/// Fixed-point scale of the neighbour sums, in lattice units.
const FIXED: f64 = (1u64 << 32) as f64;

/// The home rank of a key.
pub(super) fn home(key: u64, p: usize) -> usize {
    ((key.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 32) % p as u64) as usize
}

/// Sends `out[r]` to rank `r`; returns what each rank sent here.
pub(super) fn exchange(comm: &dyn Comm, out: Vec<Vec<u64>>) -> Vec<Vec<u64>> {
    let counts: Vec<usize> = out.iter().map(Vec::len).collect();
    let (recv, rc) = comm.alltoallv_u64(&out.concat(), &counts);
    let mut at = 0;
    rc.iter()
        .map(|&n| {
            at += n;
            recv[at - n..at].to_vec()
        })
        .collect()
}

/// What a home rank knows of one wall point.
#[derive(Default)]
struct Entry {
    mask: u64,
    size: u64,
    walls: Vec<u32>,
    watchers: Vec<u32>,
}

/// The wall points' home ranks and what they know.
pub(crate) struct Directory {
    entries: BTreeMap<u64, Entry>,
}

/// What the home rank tells a rank with faces at a wall point.
#[derive(Clone, Copy, Default)]
struct Merged {
    mask: u64,
    size: f64,
    walls: u64,
    lowest: u64,
    watchers: u64,
}

impl Directory {
    /// For each directed edge `(ka, kb)` (lattice keys) of this rank's wall
    /// faces whose other face is not here, the rank whose face has `(kb,
    /// ka)`: `None` when no rank or several do (collective).
    pub(super) fn match_edges(comm: &dyn Comm, edges: &[(u64, u64)]) -> Vec<Option<u32>> {
        let p = comm.size();
        let pair = |a: u64, b: u64| a.min(b) ^ a.max(b).rotate_left(29);
        let mut out = vec![Vec::new(); p];
        for &(a, b) in edges {
            out[home(pair(a, b), p)].extend([a, b]);
        }
        // By edge: who sent it, and its direction.
        type Senders = Vec<(usize, u64, u64)>;
        let mut table: BTreeMap<(u64, u64), Senders> = BTreeMap::new();
        for (r, recs) in exchange(comm, out).iter().enumerate() {
            for c in recs.chunks_exact(2) {
                let k = (c[0].min(c[1]), c[0].max(c[1]));
                table.entry(k).or_default().push((r, c[0], c[1]));
            }
        }
        let mut reply = vec![Vec::new(); p];
        for v in table.values() {
            let ok = v.len() == 2 && v[0].0 != v[1].0 && v[0].1 == v[1].2 && v[0].2 == v[1].1;
            for (i, &(r, a, b)) in v.iter().enumerate() {
                let partner = if ok { v[1 - i].0 as u64 } else { u64::MAX };
                reply[r].extend([a, b, partner]);
            }
        }
        let back: HashMap<(u64, u64), u64> = exchange(comm, reply)
            .iter()
            .flat_map(|r| r.chunks_exact(3).map(|c| ((c[0], c[1]), c[2])))
            .collect();
        edges
            .iter()
            .map(|e| back.get(e).filter(|&&r| r != u64::MAX).map(|&r| r as u32))
            .collect()
    }

    /// Registers this rank's wall points (key, normals mask, finest face)
    /// and the points it has in cells only (`watch`, keys); returns the
    /// directory and, per wall point, the merged data (collective).
    fn register(comm: &dyn Comm, wall: &[(u64, u64, f64)], watch: &[u64]) -> (Self, Vec<Merged>) {
        let p = comm.size();
        let mut out = vec![Vec::new(); p];
        for &(k, m, s) in wall {
            out[home(k, p)].extend([k, 1, m, s.to_bits()]);
        }
        for &k in watch {
            out[home(k, p)].extend([k, 0, 0, 0]);
        }
        let mut entries: BTreeMap<u64, Entry> = BTreeMap::new();
        for (r, recs) in exchange(comm, out).iter().enumerate() {
            for c in recs.chunks_exact(4) {
                let e = entries.entry(c[0]).or_insert_with(|| Entry {
                    size: u64::MAX,
                    ..Entry::default()
                });
                if c[1] == 1 {
                    e.mask |= c[2];
                    // Positive numbers order as their bits do.
                    e.size = e.size.min(c[3]);
                    e.walls.push(r as u32);
                } else {
                    e.watchers.push(r as u32);
                }
            }
        }
        let mut reply = vec![Vec::new(); p];
        for (&k, e) in &entries {
            let lowest = e.walls.first().copied().unwrap_or(0) as u64;
            for &r in &e.walls {
                reply[r as usize].extend([
                    k,
                    e.mask,
                    e.size,
                    e.walls.len() as u64,
                    lowest,
                    e.watchers.len() as u64,
                ]);
            }
        }
        let back: HashMap<u64, Merged> = exchange(comm, reply)
            .iter()
            .flat_map(|r| {
                r.chunks_exact(6).map(|c| {
                    (
                        c[0],
                        Merged {
                            mask: c[1],
                            size: f64::from_bits(c[2]),
                            walls: c[3],
                            lowest: c[4],
                            watchers: c[5],
                        },
                    )
                })
            })
            .collect();
        let merged = wall
            .iter()
            .map(|w| back.get(&w.0).copied().unwrap_or_default())
            .collect();
        (Directory { entries }, merged)
    }

    /// Combines the rows (`w` words each) of the points several ranks
    /// have over those ranks with `combine`, which must not depend on the
    /// order (collective): the combined rows by key.
    fn merge_shared(
        &self,
        comm: &dyn Comm,
        rows: &[(u64, Vec<u64>)],
        w: usize,
        combine: impl Fn(&mut [u64], &[u64]),
    ) -> HashMap<u64, Vec<u64>> {
        let p = comm.size();
        let mut out = vec![Vec::new(); p];
        for (k, v) in rows {
            out[home(*k, p)].push(*k);
            out[home(*k, p)].extend_from_slice(v);
        }
        let mut merged: BTreeMap<u64, Vec<u64>> = BTreeMap::new();
        for recs in exchange(comm, out) {
            for c in recs.chunks_exact(w + 1) {
                match merged.get_mut(&c[0]) {
                    Some(m) => combine(m, &c[1..]),
                    None => {
                        merged.insert(c[0], c[1..].to_vec());
                    }
                }
            }
        }
        let mut reply = vec![Vec::new(); p];
        for (k, m) in &merged {
            for &r in self.entries.get(k).map_or(&[][..], |e| &e.walls) {
                reply[r as usize].push(*k);
                reply[r as usize].extend_from_slice(m);
            }
        }
        exchange(comm, reply)
            .iter()
            .flat_map(|r| r.chunks_exact(w + 1).map(|c| (c[0], c[1..].to_vec())))
            .collect()
    }

    /// Sends the final positions of wall points to the ranks that have them
    /// in cells only (collective): what arrived here, by key.
    fn tell_watchers(&self, comm: &dyn Comm, rows: &[(u64, [f64; 3])]) -> Vec<(u64, [f64; 3])> {
        let p = comm.size();
        let mut out = vec![Vec::new(); p];
        for (k, x) in rows {
            out[home(*k, p)].push(*k);
            out[home(*k, p)].extend(x.map(f64::to_bits));
        }
        let mut reply = vec![Vec::new(); p];
        for recs in exchange(comm, out) {
            for c in recs.chunks_exact(4) {
                for &r in self.entries.get(&c[0]).map_or(&[][..], |e| &e.watchers) {
                    reply[r as usize].extend_from_slice(c);
                }
            }
        }
        exchange(comm, reply)
            .iter()
            .flat_map(|r| {
                r.chunks_exact(4)
                    .map(|c| (c[0], [c[1], c[2], c[3]].map(f64::from_bits)))
            })
            .collect()
    }
}

/// The surface and its tree.
struct Near<'s> {
    tris: &'s [Triangle],
    bvh: Bvh,
}

impl Near<'_> {
    /// The closest surface point to `x`.
    fn project(&self, x: [f64; 3]) -> [f64; 3] {
        self.project_from(x, &mut None)
    }

    /// [`Near::project`] starting from the triangle `hint` (the answer
    /// does not depend on it), which becomes the nearest triangle.
    fn project_from(&self, x: [f64; 3], hint: &mut Option<u32>) -> [f64; 3] {
        match self.bvh.nearest_from(self.tris, x, f64::INFINITY, *hint) {
            Some((t, _)) => {
                *hint = Some(t);
                let [a, b, c] = self.tris[t as usize].v;
                closest_point_triangle(x, a, b, c)
            }
            None => x,
        }
    }

    /// The outer point of the wall point `p` with face normals `dirs`,
    /// mean normal `n` and finest face `h`.
    fn target(&self, p: [f64; 3], n: Option<[f64; 3]>, dirs: &[[f64; 3]], h: f64) -> [f64; 3] {
        let Some(n) = n else {
            return self.project(p);
        };
        if let Some(t) = self.bvh.first_hit(self.tris, p, n, CAST * h) {
            return add_scaled(p, n, t);
        }
        let mut best: Option<(f64, [f64; 3])> = None;
        let between = dirs.iter().filter_map(|&d| unit(add(d, n)));
        for d in dirs.iter().copied().chain(between) {
            if let Some(t) = self.bvh.first_hit(self.tris, p, d, CAST * h) {
                if best.is_none_or(|b| t < b.0) {
                    best = Some((t, add_scaled(p, d, t)));
                }
            }
        }
        best.map_or_else(|| self.project(p), |b| b.1)
    }
}

fn unit(v: [f64; 3]) -> Option<[f64; 3]> {
    let l = norm(v);
    (l > 1e-9).then(|| scale(v, 1.0 / l))
}

/// The unit outward normals of the axis directions in `mask`.
fn axes(mask: u64) -> Vec<[f64; 3]> {
    (0..6)
        .filter(|d| mask >> d & 1 == 1)
        .map(|d| {
            let mut v = [0.0; 3];
            v[d / 2] = if d % 2 == 1 { 1.0 } else { -1.0 };
            v
        })
        .collect()
}

/// How far `x` lies ahead of the least of the planes through `p` with
/// normals `dirs`.
fn margin(x: [f64; 3], p: [f64; 3], dirs: &[[f64; 3]]) -> f64 {
    dirs.iter()
        .map(|&d| dot(d, sub(x, p)))
        .fold(f64::INFINITY, f64::min)
}

/// The wall points' moved-in staircase positions and their outer points.
pub(super) type InnerOuter = (Vec<[f64; 3]>, Vec<[f64; 3]>);

/// The wall points' positions: the staircase's moved in where needed
/// (`inner`) and on the surface (`outer`), by wall point number; the
/// points of `pm` other ranks move are moved (collective).
pub(super) fn place(
    comm: &dyn Comm,
    pm: &mut PolyMesh,
    wall: &Wall,
    (domain, surface): (&Domain, &Surface),
    slab: f64,
) -> Result<InnerOuter> {
    let nw = wall.labels.len();
    let (mut mask, mut size) = (vec![0u64; nw], vec![f64::INFINITY; nw]);
    for (k, poly) in wall.polys.iter().enumerate() {
        for &i in poly {
            mask[i as usize] |= 1 << wall.dirs[k];
            size[i as usize] = size[i as usize].min(wall.sides[k]);
        }
    }
    let mut on_wall = vec![false; pm.points.len()];
    wall.labels.iter().for_each(|&l| on_wall[l as usize] = true);
    let mut watch: Vec<u64> = (0..pm.points.len())
        .filter(|&l| pm.watch[l] && !on_wall[l])
        .map(|l| point_key(pm.lattice[l]))
        .collect();
    watch.sort_unstable();
    watch.dedup();
    let recs: Vec<(u64, u64, f64)> = (0..nw).map(|i| (wall.keys[i], mask[i], size[i])).collect();
    // A spare core builds the surface's tree while this one registers the
    // wall points, and shares the passes over the points (each point's
    // result is its own, so the split changes no bit).
    let spare = spare_core(comm);
    let (bvh, (directory, merged)) = join(
        spare,
        || Bvh::new(surface.triangles()),
        || Directory::register(comm, &recs, &watch),
    );
    let near = Near {
        tris: surface.triangles(),
        bvh,
    };
    let p: Vec<[f64; 3]> = wall.labels.iter().map(|&l| pm.points[l as usize]).collect();
    let dirs: Vec<Vec<[f64; 3]>> = merged.iter().map(|m| axes(m.mask)).collect();
    let h: Vec<f64> = merged.iter().map(|m| m.size).collect();
    let normal: Vec<Option<[f64; 3]>> = dirs
        .iter()
        .map(|d| unit(d.iter().copied().fold([0.0; 3], add)))
        .collect();
    let mut s: Vec<[f64; 3]> = map_chunks(spare, nw, CHUNK, |r| {
        r.map(|i| near.target(p[i], normal[i], &dirs[i], h[i]))
            .collect::<Vec<_>>()
    })
    .concat();
    let shared: Vec<usize> = (0..nw).filter(|&i| merged[i].walls > 1).collect();
    let ctx = Ctx::new(comm, &directory, wall, &shared, (domain, spare), slab);
    // The nearest triangle of each outer point's last projection.
    let mut hints: Vec<Option<u32>> = vec![None; nw];
    for _ in 0..SMOOTH {
        let means = ctx.neighbour_means(&s, Points::All);
        let moved = map_chunks(spare, nw, CHUNK, |r| {
            r.map(|i| {
                let mut hint = hints[i];
                let x = near.project_from(scale(add(s[i], means[i]), 0.5), &mut hint);
                let (d, m) = (&dirs[i], margin(s[i], p[i], &dirs[i]));
                let x = (margin(x, p[i], d) >= m.min(DEPTH * h[i])).then_some(x);
                (x, hint)
            })
            .collect::<Vec<_>>()
        });
        for (i, (x, hint)) in moved.into_iter().flatten().enumerate() {
            hints[i] = hint;
            if let Some(x) = x {
                s[i] = x;
            }
        }
    }
    // The staircase point moves in along its normal until its outer point
    // is DEPTH cells ahead of each of its faces.
    let inner: Vec<[f64; 3]> = (0..nw)
        .map(|i| {
            let Some(n) = normal[i] else { return p[i] };
            let need = dirs[i]
                .iter()
                .filter(|&&d| dot(d, n) > 1e-9)
                .map(|&d| (DEPTH * h[i] - dot(d, sub(s[i], p[i]))) / dot(d, n))
                .fold(0.0, f64::max);
            add_scaled(p[i], n, -need.min(REACH * h[i]))
        })
        .collect();
    let mut inner = inner;
    let old = OldCells::new(pm, wall);
    ctx.improve((&near, &mut hints), (&p, &h, &old), &mut inner, &mut s);
    let me = comm.rank() as u64;
    let rows: Vec<(u64, [f64; 3])> = (0..nw)
        .filter(|&i| merged[i].watchers > 0 && merged[i].lowest == me)
        .map(|i| (wall.keys[i], inner[i]))
        .collect();
    let moved = directory.tell_watchers(comm, &rows);
    if !moved.is_empty() {
        let by_key: HashMap<u64, [f64; 3]> = moved.into_iter().collect();
        for (l, x) in pm.points.iter_mut().enumerate() {
            if pm.watch[l] && !on_wall[l] {
                if let Some(y) = by_key.get(&point_key(pm.lattice[l])) {
                    *x = *y;
                }
            }
        }
    }
    Ok((inner, s))
}

/// The staircase cells under the wall faces, for an estimate of their
/// centres once their wall points move: by wall face, its cell's cube
/// centre and the wall points among the cube's corners (a cell may be
/// coarser than its wall face, and have several).
struct OldCells {
    cube: Vec<[f64; 3]>,
    corners: Vec<Vec<u32>>,
}

impl OldCells {
    fn new(pm: &PolyMesh, wall: &Wall) -> OldCells {
        let mut at: HashMap<u32, usize> = HashMap::new();
        for &f in &wall.faces {
            let n = at.len();
            at.entry(pm.owner[f]).or_insert(n);
        }
        let mut labels: Vec<Vec<u32>> = vec![Vec::new(); at.len()];
        for f in 0..pm.owner.len() {
            let cells = [Some(pm.owner[f]), pm.neighbour.get(f).copied()];
            for c in cells.into_iter().flatten() {
                if let Some(&j) = at.get(&c) {
                    labels[j].extend_from_slice(pm.face(f));
                }
            }
        }
        let number: HashMap<u32, u32> = wall
            .labels
            .iter()
            .enumerate()
            .map(|(i, &l)| (l, i as u32))
            .collect();
        let cells: Vec<([f64; 3], Vec<u32>)> = labels
            .into_iter()
            .map(|mut ls| {
                ls.sort_unstable();
                ls.dedup();
                let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
                for &l in &ls {
                    let x = pm.points[l as usize];
                    for k in 0..3 {
                        lo[k] = lo[k].min(x[k]);
                        hi[k] = hi[k].max(x[k]);
                    }
                }
                let corners = ls
                    .iter()
                    .filter(|&&l| {
                        let x = pm.points[l as usize];
                        (0..3).all(|k| x[k] == lo[k] || x[k] == hi[k])
                    })
                    .filter_map(|l| number.get(l).copied())
                    .collect();
                (scale(add(lo, hi), 0.5), corners)
            })
            .collect();
        let (cube, corners) = wall
            .faces
            .iter()
            .map(|f| cells[at[&pm.owner[*f]]].clone())
            .unzip();
        OldCells { cube, corners }
    }

    /// The centre of the staircase cell under wall face `k` with its wall
    /// points at `inner`.
    fn centre(&self, k: usize, p: &[[f64; 3]], inner: &dyn Fn(u32) -> [f64; 3]) -> [f64; 3] {
        let shift = self.corners[k]
            .iter()
            .map(|&i| sub(inner(i), p[i as usize]))
            .fold([0.0; 3], add);
        add_scaled(self.cube[k], shift, 1.0 / 8.0)
    }
}

/// What the passes over the wall points share.
struct Ctx<'a> {
    comm: &'a dyn Comm,
    directory: &'a Directory,
    wall: &'a Wall,
    /// The wall points with faces on several ranks.
    shared: &'a [usize],
    domain: &'a Domain,
    /// The fraction of a new cell next to the surface that must be a valid
    /// cell on its own (the boundary layers' even cut), 0 for none.
    slab: f64,
    /// Whether a spare core shares the passes.
    spare: bool,
    /// Each wall point's neighbours along the wall's edges, one per face
    /// that has the edge: `nbrs[nbr_start[i]..nbr_start[i + 1]]`.
    nbr_start: Vec<usize>,
    nbrs: Vec<u32>,
    /// Each wall point's faces: `faces_at[face_start[i]..face_start[i + 1]]`.
    face_start: Vec<usize>,
    faces_at: Vec<u32>,
}

/// Which wall points a pass computes.
#[derive(Clone, Copy)]
enum Points<'a> {
    All,
    /// These (the same shared points on every rank that has them).
    Only(&'a [usize]),
}

impl<'a> Points<'a> {
    fn each(self, n: usize, mut f: impl FnMut(usize)) {
        match self {
            Points::All => (0..n).for_each(&mut f),
            Points::Only(list) => list.iter().for_each(|&i| f(i)),
        }
    }
}

impl<'a> Ctx<'a> {
    fn new(
        comm: &'a dyn Comm,
        directory: &'a Directory,
        wall: &'a Wall,
        shared: &'a [usize],
        (domain, spare): (&'a Domain, bool),
        slab: f64,
    ) -> Ctx<'a> {
        let nw = wall.labels.len();
        let (mut nbr_start, mut face_start) = (vec![0usize; nw + 1], vec![0usize; nw + 1]);
        for poly in &wall.polys {
            for &i in poly {
                nbr_start[i as usize + 1] += 2;
                face_start[i as usize + 1] += 1;
            }
        }
        for i in 0..nw {
            nbr_start[i + 1] += nbr_start[i];
            face_start[i + 1] += face_start[i];
        }
        let (mut nbrs, mut faces_at) = (vec![0u32; nbr_start[nw]], vec![0u32; face_start[nw]]);
        let (mut nn, mut nf) = (nbr_start.clone(), face_start.clone());
        for (k, poly) in wall.polys.iter().enumerate() {
            let n = poly.len();
            for j in 0..n {
                let i = poly[j] as usize;
                nbrs[nn[i]] = poly[(j + 1) % n];
                nbrs[nn[i] + 1] = poly[(j + n - 1) % n];
                nn[i] += 2;
                faces_at[nf[i]] = k as u32;
                nf[i] += 1;
            }
        }
        Ctx {
            comm,
            directory,
            wall,
            shared,
            domain,
            slab,
            spare,
            nbr_start,
            nbrs,
            face_start,
            faces_at,
        }
    }

    /// The wall faces that have wall point `i`.
    fn faces_of(&self, i: usize) -> &[u32] {
        &self.faces_at[self.face_start[i]..self.face_start[i + 1]]
    }

    /// The shared points among `which`.
    fn shared_in(&self, which: Points) -> Vec<usize> {
        match which {
            Points::All => self.shared.to_vec(),
            Points::Only(list) => {
                let mut keep = Vec::new();
                let mut sh = self.shared.iter().peekable();
                // Both lists ascend.
                for &i in list {
                    while sh.next_if(|&&j| j < i).is_some() {}
                    if sh.next_if(|&&j| j == i).is_some() {
                        keep.push(i);
                    }
                }
                keep
            }
        }
    }

    /// Sums of `W` integers per wall point of `which`, combined over the
    /// ranks for shared points (collective).
    fn add_shared<const W: usize>(&self, which: Points, sums: &mut [[i64; W]]) {
        let shared = self.shared_in(which);
        let rows: Vec<(u64, Vec<u64>)> = shared
            .iter()
            .map(|&i| (self.wall.keys[i], sums[i].map(|x| x as u64).to_vec()))
            .collect();
        let total = self.directory.merge_shared(self.comm, &rows, W, |m, v| {
            for j in 0..W {
                m[j] = (m[j] as i64).wrapping_add(v[j] as i64) as u64;
            }
        });
        for &i in &shared {
            if let Some(t) = total.get(&self.wall.keys[i]) {
                sums[i] = std::array::from_fn(|j| t[j] as i64);
            }
        }
    }

    /// The mean of each wall point's neighbours along the wall's edges
    /// (each edge counted once per face that has it), summed in fixed
    /// point so that it does not depend on the ranks (collective). Only
    /// the points of `which` are computed (the others are left at zero).
    fn neighbour_means(&self, s: &[[f64; 3]], which: Points) -> Vec<[f64; 3]> {
        let fixed = |x: [f64; 3]| {
            self.domain
                .to_lattice(x)
                .map(|v| (v * FIXED).round() as i64)
        };
        let mut sums = vec![[0i64; 4]; s.len()];
        // Each point's fixed-point position once, when all are wanted.
        let all: Vec<[i64; 3]> = match which {
            Points::All => s.iter().map(|&x| fixed(x)).collect(),
            Points::Only(_) => Vec::new(),
        };
        which.each(s.len(), |i| {
            let nb = &self.nbrs[self.nbr_start[i]..self.nbr_start[i + 1]];
            let mut v = [0i64; 4];
            for &b in nb {
                let f = if all.is_empty() {
                    fixed(s[b as usize])
                } else {
                    all[b as usize]
                };
                for k in 0..3 {
                    v[k] = v[k].wrapping_add(f[k]);
                }
            }
            v[3] = nb.len() as i64;
            sums[i] = v;
        });
        self.add_shared(which, &mut sums);
        let mut means = vec![[0.0; 3]; s.len()];
        which.each(s.len(), |i| {
            let v = sums[i];
            let deg = v[3].max(1) as f64;
            means[i] = self
                .domain
                .from_lattice(std::array::from_fn(|k| v[k] as f64 / deg / FIXED));
        });
        means
    }

    /// Each wall point's normal of the outer surface: the mean of the unit
    /// normals of its faces' outer polygons, summed in fixed point over the
    /// ranks (collective). Only the points of `which` are computed.
    fn outer_normals(&self, s: &[[f64; 3]], which: Points) -> Vec<Option<[f64; 3]>> {
        let np = self.wall.polys.len();
        // Each face's fixed-point unit normal, computed once when first needed.
        let mut normal: Vec<Option<Option<[i64; 3]>>> = vec![None; np];
        let mut sums = vec![[0i64; 3]; s.len()];
        which.each(s.len(), |i| {
            let mut v = [0i64; 3];
            for &k in self.faces_of(i) {
                let f = *normal[k as usize].get_or_insert_with(|| {
                    let poly = &self.wall.polys[k as usize];
                    let a = super::layer::polygon_area(poly.iter().map(|&i| s[i as usize]));
                    unit(a).map(|u| u.map(|v| (v * FIXED).round() as i64))
                });
                if let Some(f) = f {
                    for j in 0..3 {
                        v[j] = v[j].wrapping_add(f[j]);
                    }
                }
            }
            sums[i] = v;
        });
        self.add_shared(which, &mut sums);
        let mut out = vec![None; s.len()];
        which.each(s.len(), |i| out[i] = unit(sums[i].map(|x| x as f64)));
        out
    }

    /// The least over wall points of `q` (each point's rows combined by
    /// the least over the ranks; collective).
    fn least_shared(&self, q: &mut [f64], w: usize) {
        let rows: Vec<(u64, Vec<u64>)> = self
            .shared
            .iter()
            .map(|&i| {
                (
                    self.wall.keys[i],
                    q[i * w..(i + 1) * w].iter().map(|x| x.to_bits()).collect(),
                )
            })
            .collect();
        let total = self.directory.merge_shared(self.comm, &rows, w, |m, v| {
            for j in 0..m.len() {
                m[j] = f64::from_bits(m[j]).min(f64::from_bits(v[j])).to_bits();
            }
        });
        for &i in self.shared {
            if let Some(t) = total.get(&self.wall.keys[i]) {
                for (x, &b) in q[i * w..(i + 1) * w].iter_mut().zip(t) {
                    *x = f64::from_bits(b);
                }
            }
        }
    }

    /// Moves the wall points of new cells that are invalid (a face pyramid
    /// of nearly no or negative volume) or near checkMesh's limits
    /// ([`cell_figure`]): each round, every point of such a cell tries a
    /// few candidates and takes the best if it makes its worst cell better.
    /// Its outer point moves along the surface towards its neighbours'
    /// mean or towards the place that copies the inner points' shape
    /// (which spreads outer points that crowd where the surface runs
    /// nearly along the faces); its inner point moves towards the place
    /// under its outer point along the outer surface's normal (which
    /// straightens a sheared thin cell) or towards its neighbours' mean,
    /// within [`SHIFT`] cells of the staircase. Collective; the same moves
    /// on every rank.
    fn improve(
        &self,
        (near, hints): (&Near, &mut [Option<u32>]),
        (p, h, old): (&[[f64; 3]], &[f64], &OldCells),
        inner: &mut [[f64; 3]],
        s: &mut [[f64; 3]],
    ) {
        let nw = s.len();
        let worst = |inner: &[[f64; 3]], s: &[[f64; 3]], i: usize, m: Moved| {
            self.faces_of(i)
                .iter()
                .map(|&k| cell_figure(self.wall, (p, old), k as usize, (inner, s), (m, self.slab)))
                .fold(f64::INFINITY, f64::min)
        };
        const OUTER: [(bool, f64); 4] = [(false, 0.5), (false, 1.0), (true, 0.5), (true, 1.0)];
        const INNER: [(bool, f64); 3] = [(false, 0.5), (false, 1.0), (true, 0.5)];
        const N: usize = OUTER.len() + INNER.len();
        // The fewest points of bad cells so far, and when.
        let mut fewest = (u64::MAX, 0);
        // Each cell's figure, measured again only when one of its points
        // moves (all its points are on this rank).
        let (wall, slab) = (self.wall, self.slab);
        let mut figure: Vec<f64> = map_chunks(self.spare, self.wall.polys.len(), CHUNK, |r| {
            r.map(|k| cell_figure(wall, (p, old), k, (&*inner, &*s), (Moved::None, slab)))
                .collect::<Vec<_>>()
        })
        .concat();
        for round in 0..ROUNDS {
            // A point's figure is its worst cell's.
            let mut q = vec![f64::INFINITY; nw];
            for (k, poly) in self.wall.polys.iter().enumerate() {
                for &i in poly {
                    q[i as usize] = q[i as usize].min(figure[k]);
                }
            }
            self.least_shared(&mut q, 1);
            let bad: Vec<usize> = (0..nw).filter(|&i| q[i] < FAIR).collect();
            let mut any = [bad.len() as u64];
            self.comm.sum_u64(&mut any);
            if any[0] < fewest.0 {
                fewest = (any[0], round);
            }
            // None left, or moves that go round in circles.
            if any[0] == 0 || round >= fewest.1 + STALL {
                return;
            }
            // Only the points that move need their neighbours' means and
            // normals.
            let means = self.neighbour_means(s, Points::Only(&bad));
            let inner_means = self.neighbour_means(inner, Points::Only(&bad));
            let normals = self.outer_normals(s, Points::Only(&bad));
            let mut tries = vec![f64::NEG_INFINITY; N * nw];
            let mut cand: Vec<[Moved; N]> = vec![[Moved::None; N]; nw];
            for &i in &bad {
                let shape = add(means[i], sub(inner[i], inner_means[i]));
                for (j, &(by_shape, w)) in OUTER.iter().enumerate() {
                    let to = if by_shape { shape } else { means[i] };
                    let x = near.project_from(add_scaled(s[i], sub(to, s[i]), w), &mut hints[i]);
                    cand[i][j] = Moved::Outer(i as u32, x);
                }
                let under = normals[i].map(|n| {
                    let depth = dot(n, sub(s[i], inner[i])).max(DEPTH * h[i]);
                    add_scaled(s[i], n, -depth)
                });
                for (j, &(by_mean, w)) in INNER.iter().enumerate() {
                    let Some(to) = (if by_mean { Some(inner_means[i]) } else { under }) else {
                        continue;
                    };
                    let x = add_scaled(inner[i], sub(to, inner[i]), w);
                    let d = sub(x, p[i]);
                    let (l, lim) = (norm(d), SHIFT * h[i]);
                    let x = add_scaled(p[i], d, if l > lim { lim / l } else { 1.0 });
                    cand[i][OUTER.len() + j] = Moved::Inner(i as u32, x);
                }
                for j in 0..N {
                    if !matches!(cand[i][j], Moved::None) {
                        tries[i * N + j] = worst(inner, s, i, cand[i][j]);
                    }
                }
            }
            self.least_shared(&mut tries, N);
            let mut moves = [0u64];
            let mut dirty = vec![false; figure.len()];
            for &i in &bad {
                let best = (0..N).fold(None, |b: Option<usize>, j| match b {
                    Some(b) if tries[i * N + b] >= tries[i * N + j] => Some(b),
                    _ => Some(j),
                });
                if let Some(j) = best.filter(|&j| tries[i * N + j] > q[i]) {
                    match cand[i][j] {
                        Moved::Outer(_, x) => s[i] = x,
                        Moved::Inner(_, x) => inner[i] = x,
                        Moved::None => {}
                    }
                    moves[0] += 1;
                    for &k in self.faces_of(i) {
                        dirty[k as usize] = true;
                    }
                }
            }
            for (k, f) in figure.iter_mut().enumerate() {
                if dirty[k] {
                    *f = cell_figure(self.wall, (p, old), k, (inner, s), (Moved::None, self.slab));
                }
            }
            // Stuck everywhere: more rounds would change nothing.
            self.comm.sum_u64(&mut moves);
            if moves[0] == 0 {
                return;
            }
        }
    }
}

/// Rounds of improvement at most.
const ROUNDS: usize = 30;
/// Rounds without fewer points of bad cells after which improving stops.
const STALL: usize = 4;
/// The least pyramid figure (in cubes of the face's side) of a valid new
/// cell.
const GOOD: f64 = 0.01;
/// The figure below which a new cell's points try to move.
const FAIR: f64 = -0.9 / 1.9;
/// The non-orthogonality (degrees) and skewness a new cell aims below:
/// checkMesh's 65 and 4, with a margin.
const NON_ORTHO: f64 = 60.0;
const SKEW: f64 = 3.5;

/// One wall point moved: its inner or its outer point.
#[derive(Clone, Copy)]
enum Moved {
    None,
    Inner(u32, [f64; 3]),
    Outer(u32, [f64; 3]),
}

/// How good the new cell on wall face `k` is, as checkMesh measures it
/// (OpenFOAM's face and cell centres), higher is better. An invalid cell
/// (a face pyramid of less than [`GOOD`] cubes of the face's side) is
/// below -1, by that volume; a valid one is in (-1, 0], from its worst
/// ratio to [`NON_ORTHO`] and [`SKEW`] of: the non-orthogonality of its
/// staircase face (the old cell's centre estimated from the staircase
/// cube and its moved wall points, [`OldCells`]), the angle between each side face's normal
/// and the way to it from the centre (the side's share of the
/// non-orthogonality with the next new cell), and the skewness of its
/// outer face. `moved` replaces one point.
fn cell_figure(
    wall: &Wall,
    (p, old_cells): (&[[f64; 3]], &OldCells),
    k: usize,
    (inner, s): (&[[f64; 3]], &[[f64; 3]]),
    (moved, slab): (Moved, f64),
) -> f64 {
    let poly = &wall.polys[k];
    let inner_at = |i: u32| match moved {
        Moved::Inner(j, x) if j == i => x,
        _ => inner[i as usize],
    };
    let outer_at = |i: u32| match moved {
        Moved::Outer(j, x) if j == i => x,
        _ => s[i as usize],
    };
    let side = wall.sides[k];
    let layered = match slab > 0.0 {
        true => match end_slabs(poly, (inner_at, outer_at), side, slab) {
            pyramid if pyramid < GOOD => -2.0 + pyramid.max(-1.0),
            _ => 0.0,
        },
        false => 0.0,
    };
    let whole = with_prism(poly, inner_at, outer_at, side, |b, faces, c, pyramid| {
        if pyramid < GOOD {
            return -2.0 + pyramid.max(-1.0);
        }
        let old = old_cells.centre(k, p, &inner_at);
        // The largest angle, from the least cosine.
        let cosine = |u: [f64; 3], v: [f64; 3]| {
            let l = norm(u) * norm(v);
            if l > 0.0 {
                (dot(u, v) / l).clamp(-1.0, 1.0)
            } else {
                1.0
            }
        };
        let least = faces[2..]
            .iter()
            .map(|&(sf, cf)| cosine(sub(cf, c), sf))
            .fold(cosine(sub(c, old), scale(faces[0].0, -1.0)), f64::min);
        let mut worst = least.acos().to_degrees() / NON_ORTHO;
        // checkMesh's boundary skewness: the outer face centre's offset along
        // the face from the cell centre, against 0.4 of the distance normal to
        // it or the face's extent that way.
        let (sf, cf) = faces[1];
        let cpf = sub(cf, c);
        if let Some(u) = unit(sf) {
            let d = scale(u, dot(u, cpf));
            let sv = sub(cpf, d);
            let l = norm(sv);
            if l > 0.0 {
                let dir = scale(sv, 1.0 / l);
                let fd = b
                    .iter()
                    .map(|&x| dot(dir, sub(x, cf)).abs())
                    .fold(0.4 * norm(d), f64::max);
                worst = worst.max(l / fd.max(f64::MIN_POSITIVE) / SKEW);
            }
        }
        -worst / (1.0 + worst)
    });
    whole.min(layered)
}
