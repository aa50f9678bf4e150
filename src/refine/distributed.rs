//! The distributed surface: each rank keeps its home share of the triangles
//! (a contiguous run of the file) and, for the stages at hand, only the
//! triangles near its part of the domain.
//!
//! - The top of the surface refinement ([`plan_top`]) is the same as
//!   [`super::construct_top_for_surface`]'s without the whole surface: whether an
//!   octant of the top splits is whether some triangle touches it, an "or"
//!   over triangles, so each rank marks the octants its home triangles
//!   touch (levels below [`COARSE_LEVEL`]; at that level, the octants some
//!   triangle's box meets, for the weights) and one all-gather of these bit
//!   sets gives every rank the same top and the same chunks.
//! - [`redistribute`] then sends each home triangle to the ranks whose
//!   range of cells its bounding box, grown by a halo, may touch (one sparse
//!   exchange). Every decision of refinement, curvature and distance bands
//!   about a leaf reads only the triangles touching the leaf's box (grown by
//!   the band), so a rank decides its leaves as with the whole surface.
//! - Classification walks from the root to each leaf carrying the crossing
//!   count from each octant's centre to its children's. Inside the rank's
//!   range the segments cross only triangles touching its cells; above it,
//!   the segments from an ancestor's centre to its child's cross triangles
//!   anywhere along them, so with `paths` a rank also receives the
//!   triangles whose boxes meet those few segments ([`path_segments`]). The
//!   root's count, a sum over all triangles, is summed over the ranks'
//!   home shares instead (`crate::classify`).
//!
//! Triangles keep their global ids; a rank holds its received triangles in
//! id order, so its index is the same whatever order they arrived in.

use std::collections::BTreeSet;

use super::{CoarseLists, SurfaceIndex, SurfaceTop, COARSE_LEVEL};
use crate::error::{Error, ErrorKind, Result};
use crate::geometry::bvh::Bvh;
use crate::geometry::intersect::triangle_box_overlap;
use crate::geometry::{Aabb, Triangle};
use crate::octree::domain::Domain;
use crate::octree::octant::{cover_cells, morton_encode, Octant, CELLS, LATTICE_BITS, ROOT_LEN};
use crate::octree::partition::split_by_weight;
use crate::octree::{owner_of_cell, LinearOctree};
use crate::parallel::comm::{agree, Comm, CommRef};

/// How far, in lattice units, boxes are grown beyond what a stage needs: the
/// rounding of the lattice and fixed-point coordinates stays far below it.
pub const MARGIN: f64 = 4.0;

/// Longest piece of a path segment searched at once, lattice units (a
/// cell of level 8).
const PIECE: f64 = (ROOT_LEN >> 8) as f64;

/// Words per triangle sent: the global id, the part, nine coordinates.
const WORDS: usize = 11;

/// This rank's home share of a surface: triangles `first..first + len` (in
/// user units) of the `total`, with what the ranks agreed on about the whole.
#[derive(Clone, Debug)]
pub struct HomeShare {
    pub tris: Vec<Triangle>,
    /// The part of each triangle; empty for surfaces of fewer than two parts.
    pub part: Vec<u16>,
    pub first: u64,
    pub total: u64,
    /// The whole surface's bounding box.
    pub bbox: Aabb,
    /// The whole surface's signed volume about its box's centre (summed
    /// over the ranks' shares in rank order).
    pub volume: f64,
}

impl HomeShare {
    /// Checks the shares of all ranks together as [`crate::geometry::Surface::new`]
    /// checks a whole surface (the same errors, on every rank), and returns
    /// this rank's. Collective.
    pub fn new(
        comm: &dyn Comm,
        tris: Vec<Triangle>,
        part: Vec<u16>,
        first: u64,
    ) -> Result<HomeShare> {
        let mut counts = [tris.len() as u64];
        comm.sum_u64(&mut counts);
        let total = counts[0];
        // The first non-finite triangle over all ranks (as a complement, for
        // the maximum), the box, and how many triangles have an area.
        let bad = tris.iter().position(|t| !t.is_finite());
        let mut v = [!bad.map_or(u64::MAX, |i| first + i as u64)];
        comm.max_u64(&mut v);
        let bad = !v[0];
        let mut b = Aabb::empty();
        for t in tris.iter().filter(|t| t.is_finite()) {
            b = b.union(&t.aabb());
        }
        let mut m = [
            b.max[0], b.max[1], b.max[2], -b.min[0], -b.min[1], -b.min[2],
        ];
        comm.max_f64(&mut m);
        let bbox = Aabb {
            min: [-m[3], -m[4], -m[5]],
            max: [m[0], m[1], m[2]],
        };
        let mut areas = [tris.iter().filter(|t| !t.is_degenerate()).count() as u64];
        comm.sum_u64(&mut areas);
        let checked = if total == 0 {
            Err(Error::geometry("surface has no triangles"))
        } else if total > u32::MAX as u64 {
            Err(Error::new(
                ErrorKind::Limit,
                format!(
                    "surface has {total} triangles, more than the supported {}",
                    u32::MAX
                ),
            ))
        } else if bad != u64::MAX {
            Err(Error::geometry(format!(
                "triangle {bad} has a non-finite coordinate (NaN or infinity)"
            )))
        } else if !bbox.longest_side().is_finite() {
            Err(Error::geometry(format!(
                "surface extent overflows f64 (bounding box {:?} to {:?})",
                bbox.min, bbox.max
            )))
        } else if bbox.longest_side() == 0.0 {
            Err(Error::geometry(format!(
                "surface has zero extent: all {total} triangles collapse to the point {:?}",
                bbox.min
            )))
        } else if areas[0] == 0 {
            Err(Error::geometry(format!(
                "all {total} triangles are degenerate (zero area): the surface has no area"
            )))
        } else {
            Ok(())
        };
        checked?;
        let c = bbox.center();
        let sub = |a: [f64; 3]| [a[0] - c[0], a[1] - c[1], a[2] - c[2]];
        let mine: f64 = tris
            .iter()
            .map(|t| {
                let (a, b, d) = (sub(t.v[0]), sub(t.v[1]), sub(t.v[2]));
                a[0] * (b[1] * d[2] - b[2] * d[1])
                    + a[1] * (b[2] * d[0] - b[0] * d[2])
                    + a[2] * (b[0] * d[1] - b[1] * d[0])
            })
            .sum();
        let volume = sum_in_rank_order(comm, mine) / 6.0;
        Ok(HomeShare {
            tris,
            part,
            first,
            total,
            bbox,
            volume,
        })
    }

    /// The triangles in lattice units of `domain`, in share order.
    pub fn lattice(&self, domain: &Domain) -> Vec<Triangle> {
        self.tris
            .iter()
            .map(|t| Triangle {
                v: t.v.map(|p| domain.to_lattice(p)),
            })
            .collect()
    }
}

/// The sum of every rank's `x`, added in rank order (the same bits on every
/// rank). Collective.
pub fn sum_in_rank_order(comm: &dyn Comm, x: f64) -> f64 {
    let (all, _) = comm.allgatherv_bytes(&x.to_le_bytes());
    all.chunks_exact(8)
        .map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes")))
        .sum()
}

/// Bits of the levels `0..=l` of the top: level `l` starts at `base(l)`.
fn base(l: u8) -> usize {
    ((1usize << (3 * l as usize)) - 1) / 7
}

/// Index of `o` among the octants of its level, in Morton order.
fn rank_in_level(o: Octant) -> usize {
    (o.morton() >> (3 * (LATTICE_BITS - o.level() as u32))) as usize
}

/// What the whole surface's top is made of, marked from `tris` (lattice
/// units): below the top's last level `stop`, the octants some triangle
/// touches by refinement's test; at `stop` (when refinement goes deeper),
/// the octants some triangle's box meets.
fn top_bits(tris: &[Triangle], max_level: u8) -> Vec<u64> {
    let stop = max_level.min(COARSE_LEVEL);
    let mut bits = vec![0u64; base(stop + 1).div_ceil(64)];
    let root = ROOT_LEN as f64;
    for t in tris {
        let b = t.aabb();
        if (0..3).any(|k| b.max[k] < 0.0 || b.min[k] > root) {
            continue;
        }
        for l in 0..=stop.min(max_level.saturating_sub(1)) {
            let side = (ROOT_LEN >> l) as f64;
            let n = 1i64 << l;
            // Cell `i` meets the box when `i side <= max` and `(i + 1) side
            // >= min` (exact: `side` is a power of two).
            let range = |k: usize| {
                let lo = ((b.min[k] / side).ceil() as i64 - 1).clamp(0, n - 1);
                let hi = ((b.max[k] / side).floor() as i64).clamp(0, n - 1);
                lo..=hi
            };
            for z in range(2) {
                for y in range(1) {
                    for x in range(0) {
                        let s = side as i64;
                        let o = Octant::from_parts(
                            morton_encode((x * s) as u32, (y * s) as u32, (z * s) as u32),
                            l,
                        );
                        let (lo, hi) = o.bounds_f64();
                        let i = base(l) + rank_in_level(o);
                        // Marked already: the exact test would change nothing.
                        if bits[i / 64] >> (i % 64) & 1 != 0 {
                            continue;
                        }
                        let meets = (0..3).all(|k| b.min[k] <= hi[k] && lo[k] <= b.max[k]);
                        if meets && (l == stop || triangle_box_overlap(t, lo, hi)) {
                            bits[i / 64] |= 1 << (i % 64);
                        }
                    }
                }
            }
        }
    }
    bits
}

/// The top of the surface refinement to `level` and its split over the
/// ranks, the same as [`super::construct_top_for_surface`] makes from the whole
/// surface.
pub struct TopPlan {
    coarse: Vec<(Octant, u64)>,
    /// Rank `r` takes `coarse[bounds[r]..bounds[r + 1]]`.
    bounds: Vec<usize>,
    level: u8,
}

/// [`TopPlan`] from every rank's home triangles `home` (lattice units).
/// Collective: one all-gather of the top's bit sets.
pub fn plan_top(comm: &CommRef, home: &[Triangle], level: u8) -> Result<TopPlan> {
    agree(&**comm, super::check_level(level))?;
    let mine = top_bits(home, level);
    let bytes: Vec<u8> = mine.iter().flat_map(|w| w.to_le_bytes()).collect();
    let (all, _) = comm.allgatherv_bytes(&bytes);
    let mut bits = vec![0u64; mine.len()];
    for (i, b) in all.chunks_exact(8).enumerate() {
        bits[i % mine.len().max(1)] |= u64::from_le_bytes(b.try_into().expect("8 bytes"));
    }
    let bit = |o: Octant| {
        let i = base(o.level()) + rank_in_level(o);
        bits[i / 64] >> (i % 64) & 1 != 0
    };
    let stop = level.min(COARSE_LEVEL);
    let deep = 1u64 << (2 * (level.saturating_sub(COARSE_LEVEL)) as u32).min(60);
    let mut coarse = Vec::new();
    let mut stack = vec![Octant::ROOT];
    while let Some(o) = stack.pop() {
        if o.level() >= level {
            coarse.push((o, 1));
        } else if o.level() == stop {
            coarse.push((o, if bit(o) { deep } else { 1 }));
        } else if bit(o) {
            for i in (0..8).rev() {
                stack.push(o.child(i));
            }
        } else {
            coarse.push((o, 1));
        }
    }
    let w: Vec<u64> = coarse.iter().map(|c| c.1).collect();
    let bounds = split_by_weight(&w, comm.size());
    Ok(TopPlan {
        coarse,
        bounds,
        level,
    })
}

impl TopPlan {
    /// The first finest cell of each rank's chunk, with [`CELLS`] appended.
    pub fn first_cells(&self) -> Vec<u64> {
        let p = self.bounds.len() - 1;
        let mut f: Vec<u64> = (0..p)
            .map(|r| {
                self.coarse
                    .get(self.bounds[r])
                    .map_or(CELLS, |c| c.0.cell_begin())
            })
            .collect();
        f.push(CELLS);
        f
    }

    /// This rank's chunk as the top [`SurfaceTop::refine`] starts from, with
    /// its lists taken from `local`, which must hold every triangle whose
    /// box meets the chunk ([`redistribute`]). Collective.
    pub fn top<'a>(&self, comm: CommRef, local: &'a SurfaceIndex) -> Result<SurfaceTop<'a>> {
        let r = comm.rank();
        let stop = self.level.min(COARSE_LEVEL);
        let mut lists = CoarseLists::default();
        let mut buf = Vec::new();
        let mut mine = Vec::new();
        for &(o, w) in &self.coarse[self.bounds[r]..self.bounds[r + 1]] {
            buf.clear();
            // As the whole surface's walk: a list only at the top's last
            // level, above the target, where some triangle's box meets.
            if o.level() == stop && o.level() < self.level && w > 1 {
                local.candidates(o, &mut buf);
            }
            lists.push(&buf);
            mine.push(o);
        }
        Ok(SurfaceTop {
            tree: LinearOctree::from_local_leaves(comm, mine)?,
            lists,
            surface: local,
            level: self.level,
        })
    }
}

/// The triangles a rank received: in user units, with their parts (empty
/// when the surface has fewer than two) and global ids, in id order.
pub struct Received {
    pub tris: Vec<Triangle>,
    pub part: Vec<u16>,
    pub ids: Vec<u64>,
}

/// The ranks whose cell ranges (`first_cells`, [`LinearOctree::first_cells`])
/// hold a cell meeting the closed box `lo..hi` (lattice units), maybe a few
/// more, appended to `out`.
fn ranks_of_box(first_cells: &[u64], lo: [f64; 3], hi: [f64; 3], out: &mut Vec<usize>) {
    let root = ROOT_LEN as f64;
    if (0..3).any(|k| hi[k] < 0.0 || lo[k] > root) {
        return;
    }
    let extent = (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max);
    // The finest level whose cells are at least as wide as the box: it
    // meets at most two per axis.
    let mut s = 0u8;
    while s < 18 && ((ROOT_LEN >> (s + 1)) as f64) >= extent {
        s += 1;
    }
    let side = ROOT_LEN >> s;
    let n = (1i64 << s) - 1;
    let range = |k: usize| {
        let a = ((lo[k] / side as f64).floor() as i64).clamp(0, n);
        let b = ((hi[k] / side as f64).floor() as i64).clamp(0, n);
        a..=b
    };
    let span = 1u64 << (3 * (LATTICE_BITS - s as u32));
    for z in range(2) {
        for y in range(1) {
            for x in range(0) {
                let m = morton_encode(x as u32 * side, y as u32 * side, z as u32 * side);
                let (a, b) = (
                    owner_of_cell(first_cells, m),
                    owner_of_cell(first_cells, m + span - 1),
                );
                out.extend((a..=b).filter(|&r| first_cells[r] < first_cells[r + 1]));
            }
        }
    }
}

/// Whether rank `r` receives from [`redistribute`] with a halo of at least
/// `grow` - [`MARGIN`] every triangle whose box this accepts: the box `b`
/// (lattice units) grown by `grow` may meet a cell of `r`'s range. A box
/// holding an accepted box is accepted too, and a box within `grow` of a
/// point of `r`'s cells (closed) is.
pub fn box_reaches_rank(first_cells: &[u64], r: usize, b: &Aabb, grow: f64) -> bool {
    let mut out = Vec::new();
    ranks_of_box(
        first_cells,
        b.min.map(|x| x - grow),
        b.max.map(|x| x + grow),
        &mut out,
    );
    out.contains(&r)
}

/// The segments from an octant's centre to a child's centre that the
/// classification walk of rank `r` follows outside its range of cells
/// (`first_cells`): into each octant of the range's cover and each of their
/// ancestors. Lattice units.
pub fn path_segments(first_cells: &[u64], r: usize) -> Vec<([f64; 3], [f64; 3])> {
    let (a, b) = (first_cells[r], first_cells[r + 1]);
    if a >= b {
        return Vec::new();
    }
    let mut cover = Vec::new();
    cover_cells(a, b, &mut cover);
    let mut all = BTreeSet::new();
    for c in cover {
        let mut o = c;
        while all.insert(o.key()) && o.level() > 0 {
            o = o.parent();
        }
    }
    let centre = |o: Octant| {
        let h = (o.side() / 2) as f64;
        o.coords().map(|c| c as f64 + h)
    };
    all.into_iter()
        .map(Octant::from_key)
        .filter(|o| o.level() > 0)
        .map(|o| (centre(o.parent()), centre(o)))
        .collect()
}

/// Whether the segment `p..q` meets the closed box `lo..hi`.
fn segment_meets(p: [f64; 3], q: [f64; 3], lo: [f64; 3], hi: [f64; 3]) -> bool {
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for k in 0..3 {
        let d = q[k] - p[k];
        if d == 0.0 {
            if p[k] < lo[k] || p[k] > hi[k] {
                return false;
            }
            continue;
        }
        let (mut a, mut b) = ((lo[k] - p[k]) / d, (hi[k] - p[k]) / d);
        if a > b {
            std::mem::swap(&mut a, &mut b);
        }
        t0 = t0.max(a);
        t1 = t1.min(b);
        if t0 > t1 {
            return false;
        }
    }
    true
}

/// Sends each home triangle to the ranks whose range of cells
/// (`first_cells`, one per rank and [`CELLS`]) its bounding box grown by
/// `halo` + [`MARGIN`] lattice units may touch, and with `paths` also to
/// the ranks whose [`path_segments`] its box meets, and returns what this
/// rank received. Collective: one sparse exchange.
pub fn redistribute(
    comm: &dyn Comm,
    home: &HomeShare,
    domain: &Domain,
    first_cells: &[u64],
    halo: f64,
    paths: bool,
) -> Received {
    let p = comm.size();
    let lat = home.lattice(domain);
    let g = halo + MARGIN;
    let mut to: Vec<Vec<u32>> = vec![Vec::new(); p];
    let mut ranks = Vec::new();
    for (i, t) in lat.iter().enumerate() {
        let b = t.aabb();
        ranks.clear();
        ranks_of_box(
            first_cells,
            b.min.map(|x| x - g),
            b.max.map(|x| x + g),
            &mut ranks,
        );
        ranks.sort_unstable();
        ranks.dedup();
        for &r in &ranks {
            to[r].push(i as u32);
        }
    }
    if paths {
        let bvh = Bvh::new(&lat);
        let mut found = Vec::new();
        for (r, list) in to.iter_mut().enumerate() {
            let before = list.len();
            for (a, b) in path_segments(first_cells, r) {
                // In pieces no longer than a cell of level 8 per axis, whose
                // boxes hold few triangles the segment misses.
                let len = (0..3).map(|k| (b[k] - a[k]).abs()).fold(0.0, f64::max);
                let pieces = (len / PIECE).ceil().max(1.0) as usize;
                for j in 0..pieces {
                    let at =
                        |f: f64| -> [f64; 3] { std::array::from_fn(|k| a[k] + (b[k] - a[k]) * f) };
                    let (pa, pb) = (
                        at(j as f64 / pieces as f64),
                        at((j + 1) as f64 / pieces as f64),
                    );
                    let lo: [f64; 3] = std::array::from_fn(|k| pa[k].min(pb[k]) - MARGIN);
                    let hi: [f64; 3] = std::array::from_fn(|k| pa[k].max(pb[k]) + MARGIN);
                    found.clear();
                    bvh.query_candidates(lo, hi, &mut found);
                    for &i in &found {
                        let bb = lat[i as usize].aabb();
                        let (l, h) = (bb.min.map(|x| x - MARGIN), bb.max.map(|x| x + MARGIN));
                        if segment_meets(a, b, l, h) {
                            list.push(i);
                        }
                    }
                }
            }
            if list.len() > before {
                list.sort_unstable();
                list.dedup();
            }
        }
    }
    drop(lat);
    let counts: Vec<usize> = to.iter().map(|l| l.len() * WORDS).collect();
    let mut send = Vec::with_capacity(counts.iter().sum());
    for list in &to {
        for &i in list {
            let i = i as usize;
            send.push(home.first + i as u64);
            send.push(home.part.get(i).copied().unwrap_or(0) as u64);
            send.extend(home.tris[i].v.iter().flatten().map(|c| c.to_bits()));
        }
    }
    drop(to);
    let (got, _) = comm.alltoallv_u64(&send, &counts);
    drop(send);
    let mut order: Vec<usize> = (0..got.len() / WORDS).collect();
    order.sort_unstable_by_key(|&j| got[j * WORDS]);
    let parts = !home.part.is_empty();
    let mut out = Received {
        tris: Vec::with_capacity(order.len()),
        part: Vec::new(),
        ids: Vec::with_capacity(order.len()),
    };
    for j in order {
        let w = &got[j * WORDS..(j + 1) * WORDS];
        out.ids.push(w[0]);
        if parts {
            out.part.push(w[1] as u16);
        }
        let c = |k: usize| f64::from_bits(w[2 + k]);
        out.tris.push(Triangle {
            v: [[c(0), c(1), c(2)], [c(3), c(4), c(5)], [c(6), c(7), c(8)]],
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_box_reaches_the_ranks_of_the_cells_it_meets() {
        // Four ranks, a quarter of the cells each.
        let f = [0, CELLS / 4, CELLS / 2, 3 * CELLS / 4, CELLS];
        let mut out = Vec::new();
        let h = ROOT_LEN as f64 / 2.0;
        // A small box at the cube's centre touches all eight children.
        ranks_of_box(&f, [h - 1.0; 3], [h + 1.0; 3], &mut out);
        out.sort_unstable();
        out.dedup();
        assert_eq!(out, vec![0, 1, 2, 3]);
        out.clear();
        ranks_of_box(&f, [1.0; 3], [2.0; 3], &mut out);
        out.dedup();
        assert_eq!(out, vec![0]);
    }

    #[test]
    fn a_box_reaches_the_rank_of_a_point_within_the_growth() {
        // Two ranks: the lower and upper halves in Morton order (z < h, z >= h).
        let f = [0, CELLS / 2, CELLS];
        let h = ROOT_LEN as f64 / 2.0;
        let b = |lo: f64, hi: f64| Aabb {
            min: [1.0, 1.0, lo],
            max: [2.0, 2.0, hi],
        };
        // A box below the plane reaches the upper rank only when grown
        // across it; a box holding it reaches whatever it reaches.
        assert!(!box_reaches_rank(&f, 1, &b(h - 20.0, h - 10.0), 1.0));
        assert!(box_reaches_rank(&f, 1, &b(h - 20.0, h - 10.0), 12.0));
        assert!(box_reaches_rank(&f, 1, &b(h - 30.0, h - 10.0), 12.0));
        assert!(box_reaches_rank(&f, 0, &b(h - 20.0, h - 10.0), 0.0));
    }

    #[test]
    fn path_segments_start_at_the_root() {
        let f = [0, CELLS / 8 + 5, CELLS];
        let s = path_segments(&f, 1);
        let h = ROOT_LEN as f64 / 2.0;
        assert!(s.iter().any(|(p, _)| *p == [h; 3]));
        assert!(segment_meets([0.0; 3], [4.0; 3], [1.0; 3], [2.0; 3]));
        assert!(!segment_meets(
            [0.0; 3],
            [4.0, 0.0, 0.0],
            [1.0; 3],
            [2.0; 3]
        ));
    }
}
