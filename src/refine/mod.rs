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
//! For a surface, the walk down the top already knows which triangles'
//! boxes meet each coarse leaf; [`construct_top_for_surface`] keeps those
//! lists for this rank's chunk, so that [`SurfaceTop::refine`] starts from
//! them instead of searching the bounding-box tree once per coarse leaf (a
//! search costs about as much as refining a small octant below it).
//!
//! # Surface refinement
//!
//! An octant is refined while its level is below the target level and its
//! closed box touches a triangle (see [`crate::geometry::intersect`] for the
//! exact touching rule). Each child receives the triangles whose bounding
//! boxes meet its box, taken from its parent's; the exact test only has to
//! find one that touches, so most candidates are only compared by boxes. The
//! children of an octant one level above the target are leaves whatever they
//! touch, so the most numerous level costs no geometric test at all.
//!
//! # Estimating the size first
//!
//! [`estimate_leaves`] predicts the number of leaves from the surface area
//! alone, before any refinement (see its documentation for the model and
//! its measured accuracy), and [`check_estimate`] uses it to refuse, before
//! spending time and memory, a refinement that would be far above an octant
//! limit. The limit itself is still enforced exactly while refining (and by
//! [`LinearOctree::balance_with_limit`] while balancing).

use crate::error::Result;
use crate::octree::octant::Octant;
use crate::octree::partition::split_by_weight;
use crate::octree::LinearOctree;
use crate::parallel::comm::{agree, CommRef};

pub mod curvature;
pub mod distributed;
mod estimate;
mod index;
pub mod regions;
mod surface;

#[cfg(test)]
mod tests;

pub use estimate::*;
pub use index::*;
pub use surface::*;

pub use crate::octree::limits::{check_level, NO_LIMIT};
pub(crate) use crate::octree::limits::{global_limit, limit_error};

/// Depth of the top of the tree that every rank computes redundantly to
/// split the work.
pub const COARSE_LEVEL: u8 = 6;

/// Top of the tree: leaves of the rule down to `COARSE_LEVEL` with an
/// estimate of the work below each, identical on every rank.
pub(crate) fn coarse_top(
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

/// This rank's contiguous chunk of the coarse leaves, by estimated work.
pub(crate) fn chunk(comm: &CommRef, coarse: &[(Octant, u64)]) -> std::ops::Range<usize> {
    let w: Vec<u64> = coarse.iter().map(|c| c.1).collect();
    let b = split_by_weight(&w, comm.size());
    b[comm.rank()]..b[comm.rank() + 1]
}

/// This rank's contiguous chunk of the coarse leaves, as a linear octree.
pub(crate) fn construct(comm: CommRef, coarse: Vec<(Octant, u64)>) -> Result<LinearOctree> {
    let r = chunk(&comm, &coarse);
    let mine = coarse[r].iter().map(|c| c.0).collect();
    LinearOctree::from_local_leaves(comm, mine)
}

/// Construction for surface refinement: the top of the surface-refined
/// octree, split over the ranks by estimated work. Collective.
pub fn construct_for_surface(
    comm: CommRef,
    surface: &SurfaceIndex,
    level: u8,
) -> Result<LinearOctree> {
    Ok(construct_top_for_surface(comm, surface, level)?.into_tree())
}

/// [`construct_for_surface`], keeping what the walk down the top of the
/// tree found for [`SurfaceTop::refine`]. Collective.
pub fn construct_top_for_surface(
    comm: CommRef,
    surface: &SurfaceIndex,
    level: u8,
) -> Result<SurfaceTop<'_>> {
    agree(&*comm, check_level(level))?;
    let weight = 1u64 << (2 * (level.saturating_sub(COARSE_LEVEL)) as u32).min(60);
    let (coarse, lists) = surface_top(surface, level, weight);
    let r = chunk(&comm, &coarse);
    let lists = lists.slice(r.clone());
    let mine = coarse[r].iter().map(|c| c.0).collect();
    drop(coarse);
    Ok(SurfaceTop {
        tree: LinearOctree::from_local_leaves(comm, mine)?,
        lists,
        surface,
        level,
    })
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

pub(crate) fn refine_rec(
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
            return Err(limit_error(limit, "refining"));
        }
    }
    Ok(())
}

impl LinearOctree {
    /// Replaces each local leaf by the leaves `expand` appends for it (in
    /// Morton order, covering exactly the leaf); `expand` fails as soon as
    /// more than `limit` leaves are out (an [`crate::ErrorKind::Limit`] error).
    /// Collective.
    pub fn refine_with(
        &mut self,
        mut expand: impl FnMut(Octant, &mut Vec<Octant>) -> Result<()>,
        limit: u64,
    ) -> Result<()> {
        self.refine_all(
            |leaves, out| leaves.iter().try_for_each(|&o| expand(o, out)),
            limit,
        )
    }

    /// Replaces the local leaves by those `expand` appends for all of them
    /// at once (in Morton order, covering exactly the same cells), for
    /// refinements that share work between neighbouring leaves; the limit
    /// as in [`LinearOctree::refine_with`]. Collective.
    pub fn refine_all(
        &mut self,
        expand: impl FnOnce(&[Octant], &mut Vec<Octant>) -> Result<()>,
        limit: u64,
    ) -> Result<()> {
        let mut out = Vec::with_capacity(self.local_len());
        let result = expand(self.leaves(), &mut out);
        let comm = self.comm().clone();
        let global = global_limit(&comm, out.len(), limit);
        agree(&*comm, result.and(global))?;
        self.set_leaves(out);
        self.refresh()
    }

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
        self.refine_with(
            |o, out| refine_rec(o, max_level, &mut split, out, limit),
            limit,
        )
    }
}
