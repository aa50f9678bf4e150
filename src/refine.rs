//! Construction of the distributed octree and its refinement, by a user
//! predicate or by a surface.
//!
//! # Construction (the seed paper's Algorithm 1, made rank-independent)
//!
//! Every rank walks the same top of the tree, down to [`COARSE_LEVEL`], with
//! the refinement rule; those coarse leaves are a prefix of the final tree on
//! any number of ranks. They are split into contiguous Morton chunks of about
//! equal estimated work, so each rank starts from the minimal complete set of
//! octants between its first and last coarse octant, and refines only those.
//! The global leaf set is therefore the same for every rank count: it is
//! defined by the rule alone.
//!
//! # Surface refinement
//!
//! An octant is refined while its level is below the target level and its
//! closed box touches a triangle (see [`crate::geometry::intersect`] for the
//! exact touching rule). Each child receives only the triangles that touched
//! its parent, so a triangle is tested about once per level it spans. The
//! children of an octant one level above the target are leaves whatever they
//! touch, so the most numerous level costs no geometric test at all.

use crate::comm::{agree, CommRef};
use crate::domain::Domain;
use crate::error::{Error, ErrorKind, Result};
use crate::geometry::bvh::Bvh;
use crate::geometry::intersect::triangle_box_overlap;
use crate::geometry::{Surface, Triangle};
use crate::octant::{Octant, MAX_LEVEL};
use crate::octree::LinearOctree;
use crate::partition::split_by_weight;

/// Depth of the top of the tree that every rank computes redundantly to
/// split the work.
pub const COARSE_LEVEL: u8 = 6;

/// No limit on the number of octants.
pub const NO_LIMIT: u64 = u64::MAX;

/// A surface in lattice units, ready for octant queries.
pub struct SurfaceIndex {
    tris: Vec<Triangle>,
    boxes: Vec<[f64; 6]>,
    bvh: Bvh,
}

impl SurfaceIndex {
    /// Maps the surface to the lattice of `domain` and builds its
    /// bounding-box tree.
    pub fn new(surface: &Surface, domain: &Domain) -> SurfaceIndex {
        let tris: Vec<Triangle> = surface
            .triangles()
            .iter()
            .map(|t| Triangle {
                v: [
                    domain.to_lattice(t.v[0]),
                    domain.to_lattice(t.v[1]),
                    domain.to_lattice(t.v[2]),
                ],
            })
            .collect();
        let boxes = tris
            .iter()
            .map(|t| {
                let b = t.aabb();
                [b.min[0], b.min[1], b.min[2], b.max[0], b.max[1], b.max[2]]
            })
            .collect();
        let bvh = Bvh::new(&tris);
        SurfaceIndex { tris, boxes, bvh }
    }

    /// Triangles in lattice units.
    pub fn triangles(&self) -> &[Triangle] {
        &self.tris
    }

    /// Whether the closed box of `o` touches the surface.
    pub fn touches(&self, o: Octant) -> bool {
        let (lo, hi) = o.bounds_f64();
        self.bvh.any_overlap(&self.tris, lo, hi)
    }

    /// Indices of the triangles touching the closed box of `o`.
    pub fn touching(&self, o: Octant, out: &mut Vec<u32>) {
        let (lo, hi) = o.bounds_f64();
        self.bvh.query_box(&self.tris, lo, hi, out);
    }
}

fn check_level(level: u8) -> Result<()> {
    if level > MAX_LEVEL {
        return Err(Error::invalid(format!(
            "level {level} is above the maximum level {MAX_LEVEL}"
        )));
    }
    Ok(())
}

fn limit_error(limit: u64) -> Error {
    Error::new(
        ErrorKind::Limit,
        format!("the octree would exceed the limit of {limit} octants; raise the limit or lower the level"),
    )
}

/// Top of the tree: leaves of the rule down to `COARSE_LEVEL` with an
/// estimate of the work below each, identical on every rank.
fn coarse_top(
    max_level: u8,
    mut split: impl FnMut(Octant) -> bool,
    deep_weight: u64,
) -> Vec<(Octant, u64)> {
    let stop = max_level.min(COARSE_LEVEL);
    let mut out = Vec::new();
    let mut stack = vec![Octant::ROOT];
    while let Some(o) = stack.pop() {
        let wants = o.level() < max_level && split(o);
        if !wants {
            out.push((o, 1));
        } else if o.level() == stop {
            out.push((o, deep_weight));
        } else {
            // Reverse so that popping yields Morton order.
            for i in (0..8).rev() {
                stack.push(o.child(i));
            }
        }
    }
    out
}

/// This rank's contiguous chunk of the coarse leaves, as a linear octree.
fn construct(comm: CommRef, coarse: Vec<(Octant, u64)>) -> Result<LinearOctree> {
    let w: Vec<u64> = coarse.iter().map(|c| c.1).collect();
    let b = split_by_weight(&w, comm.size());
    let mine = coarse[b[comm.rank()]..b[comm.rank() + 1]]
        .iter()
        .map(|c| c.0)
        .collect();
    LinearOctree::from_local_leaves(comm, mine)
}

/// Construction for surface refinement: the top of the surface-refined
/// octree, split over the ranks by estimated work. Collective.
pub fn construct_for_surface(
    comm: CommRef,
    surface: &SurfaceIndex,
    level: u8,
) -> Result<LinearOctree> {
    agree(&*comm, check_level(level))?;
    let weight = 1u64 << (2 * (level.saturating_sub(COARSE_LEVEL)) as u32).min(60);
    construct(comm, coarse_top(level, |o| surface.touches(o), weight))
}

/// Construction for refinement by a predicate (see
/// [`build_from_callback`] for the requirements on `split`). Collective.
pub fn construct_for_callback(
    comm: CommRef,
    max_level: u8,
    split: impl FnMut(Octant) -> bool,
) -> Result<LinearOctree> {
    agree(&*comm, check_level(max_level))?;
    construct(comm, coarse_top(max_level, split, 8))
}

/// Builds the octree whose leaves touching `surface` are exactly at `level`
/// and whose other leaves are as coarse as possible. Collective.
pub fn build_from_surface(
    comm: CommRef,
    surface: &SurfaceIndex,
    level: u8,
    limit: u64,
) -> Result<LinearOctree> {
    let mut t = construct_for_surface(comm, surface, level)?;
    t.refine_surface(surface, level, limit)?;
    Ok(t)
}

impl LinearOctree {
    /// Refines every leaf whose closed box touches the surface until the
    /// touching leaves are at `level`. Collective.
    pub fn refine_surface(&mut self, surface: &SurfaceIndex, level: u8, limit: u64) -> Result<()> {
        agree(&**self.comm(), check_level(level))?;
        let mut w = SurfaceWalker {
            tris: &surface.tris,
            boxes: &surface.boxes,
            level,
            buf: Vec::new(),
            out: Vec::with_capacity(self.local_len()),
            limit: limit.min(usize::MAX as u64) as usize,
        };
        let mut result = Ok(());
        for &o in self.leaves() {
            if o.level() >= level {
                w.out.push(o);
                continue;
            }
            w.buf.clear();
            surface.touching(o, &mut w.buf);
            if w.buf.is_empty() {
                w.out.push(o);
                continue;
            }
            let n = w.buf.len();
            if let Err(e) = w.walk(o, 0, n) {
                result = Err(e);
                break;
            }
        }
        let comm = self.comm().clone();
        let result = result.and_then(|_| global_limit(&comm, w.out.len(), limit));
        agree(&*comm, result)?;
        *self.leaves_mut() = w.out;
        self.refresh()
    }
}

fn global_limit(comm: &CommRef, local: usize, limit: u64) -> Result<()> {
    let mut n = [local as u64];
    comm.sum_u64(&mut n);
    if n[0] > limit {
        return Err(limit_error(limit));
    }
    Ok(())
}

struct SurfaceWalker<'a> {
    tris: &'a [Triangle],
    boxes: &'a [[f64; 6]],
    level: u8,
    /// Stack of triangle lists; each level's list is a suffix.
    buf: Vec<u32>,
    out: Vec<Octant>,
    limit: usize,
}

impl SurfaceWalker<'_> {
    /// Refines `o`, which touches the triangles `buf[lo..hi]`.
    fn walk(&mut self, o: Octant, lo: usize, hi: usize) -> Result<()> {
        if o.level() + 1 == self.level {
            self.out.extend_from_slice(&o.children());
            return self.check_limit();
        }
        let (min, _) = o.bounds_f64();
        let half = (o.side() / 2) as f64;
        for i in 0..8u32 {
            let c = o.child(i);
            let cmin = [
                min[0] + if i & 1 != 0 { half } else { 0.0 },
                min[1] + if i & 2 != 0 { half } else { 0.0 },
                min[2] + if i & 4 != 0 { half } else { 0.0 },
            ];
            let cmax = [cmin[0] + half, cmin[1] + half, cmin[2] + half];
            let start = self.buf.len();
            for j in lo..hi {
                let t = self.buf[j];
                let b = &self.boxes[t as usize];
                if b[0] <= cmax[0]
                    && b[3] >= cmin[0]
                    && b[1] <= cmax[1]
                    && b[4] >= cmin[1]
                    && b[2] <= cmax[2]
                    && b[5] >= cmin[2]
                    && triangle_box_overlap(&self.tris[t as usize], cmin, cmax)
                {
                    self.buf.push(t);
                }
            }
            let end = self.buf.len();
            if end > start {
                self.walk(c, start, end)?;
                self.buf.truncate(start);
            } else {
                self.out.push(c);
            }
        }
        self.check_limit()
    }

    fn check_limit(&self) -> Result<()> {
        if self.out.len() > self.limit {
            return Err(limit_error(self.limit as u64));
        }
        Ok(())
    }
}

/// Builds the octree in which an octant is refined while `split` returns
/// true and its level is below `max_level`. `split` must give the same
/// answer for the same octant on every rank (it is evaluated redundantly for
/// the top of the tree). Collective.
pub fn build_from_callback(
    comm: CommRef,
    max_level: u8,
    mut split: impl FnMut(Octant) -> bool,
    limit: u64,
) -> Result<LinearOctree> {
    let mut t = construct_for_callback(comm, max_level, &mut split)?;
    t.refine(max_level, split, limit)?;
    Ok(t)
}

fn refine_rec(
    o: Octant,
    max_level: u8,
    split: &mut impl FnMut(Octant) -> bool,
    out: &mut Vec<Octant>,
    limit: u64,
) -> Result<()> {
    if o.level() < max_level && split(o) {
        for c in o.children() {
            refine_rec(c, max_level, split, out, limit)?;
        }
    } else {
        out.push(o);
        if out.len() as u64 > limit {
            return Err(limit_error(limit));
        }
    }
    Ok(())
}

impl LinearOctree {
    /// Refines the existing leaves recursively while `split` returns true
    /// and the level is below `max_level`. Collective.
    pub fn refine(
        &mut self,
        max_level: u8,
        mut split: impl FnMut(Octant) -> bool,
        limit: u64,
    ) -> Result<()> {
        let checked = check_level(max_level);
        agree(&**self.comm(), checked)?;
        let mut out = Vec::with_capacity(self.local_len());
        let mut result = Ok(());
        for &o in self.leaves() {
            if let Err(e) = refine_rec(o, max_level, &mut split, &mut out, limit) {
                result = Err(e);
                break;
            }
        }
        let comm = self.comm().clone();
        let result = result.and_then(|_| global_limit(&comm, out.len(), limit));
        agree(&*comm, result)?;
        *self.leaves_mut() = out;
        self.refresh()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::comm::SerialComm;
    use std::rc::Rc;

    #[test]
    fn callback_build_matches_recursive_definition() {
        // Refine towards the corner (0,0,0): leaves near it are finest.
        let comm: CommRef = Rc::new(SerialComm);
        let t = build_from_callback(comm, 8, |o| o.coords() == [0, 0, 0], NO_LIMIT).unwrap();
        t.check().unwrap();
        assert_eq!(t.global_len(), 1 + 7 * 8);
        assert!(t.leaves()[0].level() == 8);
    }

    #[test]
    fn limit_stops_early() {
        let comm: CommRef = Rc::new(SerialComm);
        let e = build_from_callback(comm, 5, |_| true, 1000).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Limit);
    }
}
