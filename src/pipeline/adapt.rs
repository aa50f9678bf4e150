//! Stages for adaptive simulations: the session's octree refined once,
//! coarsened or adapted by callbacks (see [`crate::octree::adapt`]), and
//! partitioned so that families stay together. Attached leaf data is kept
//! (see [`crate::octree::leaf_data`]): the replaced leaves go through the optional
//! replace callback, new leaves' data is zero without one; on failure the
//! octree and the data are as they were.

use super::classes::moving_classes;
use super::data::{changing, moving};
use super::octree::over_budget;
use super::Session;
use crate::error::Result;
use crate::octree::adapt::{Adapt, AdaptStats};
use crate::octree::leaf_data::{LeafData, ReplaceFn};
use crate::octree::LinearOctree;
use crate::parallel::comm::agree;
use crate::refine::check_level;
use crate::Octant;

impl Session {
    /// Splits each leaf once where `split` says so, below `max_level`
    /// ([`LinearOctree::refine_once`]), within the octant limit and the
    /// memory budget (on failure the octree is as it was). Needs an octree.
    /// Drops the leaf classes and the mesh. Phase `refine`.
    pub fn refine_once(
        &mut self,
        max_level: u8,
        split: impl FnMut(Octant) -> bool,
        replace: Option<ReplaceFn>,
    ) -> Result<AdaptStats> {
        agree(
            &*self.comm,
            check_level(max_level).and(self.tree_or_state().map(|_| ())),
        )?;
        let budget = self.memory_budget();
        let limit = self.octant_limit(budget);
        let r = self.change("refine", |t, d| {
            changing(t, d, replace, |t| t.refine_once(max_level, split, limit))
        });
        over_budget(r, budget, limit, "refinement")
    }

    /// Replaces families of eight local sibling leaves by their parent where
    /// `coarsen` says so ([`LinearOctree::coarsen`]; a family split across
    /// ranks is never coarsened). Needs an octree. Drops the leaf classes
    /// and the mesh. Phase `coarsen`.
    pub fn coarsen(
        &mut self,
        recursive: bool,
        coarsen: impl FnMut(&[Octant; 8]) -> bool,
        replace: Option<ReplaceFn>,
    ) -> Result<AdaptStats> {
        agree(&*self.comm, self.tree_or_state().map(|_| ()))?;
        self.change("coarsen", |t, d| {
            changing(t, d, replace, |t| t.coarsen(recursive, coarsen))
        })
    }

    /// Refines, keeps or coarsens each leaf as `decide` asks
    /// ([`LinearOctree::adapt`]), within the octant limit and the memory
    /// budget (on failure the octree is as it was). Needs an octree. Drops
    /// the leaf classes and the mesh. Phase `adapt`.
    pub fn adapt(
        &mut self,
        decide: impl FnMut(Octant) -> Adapt,
        replace: Option<ReplaceFn>,
    ) -> Result<AdaptStats> {
        agree(&*self.comm, self.tree_or_state().map(|_| ()))?;
        let budget = self.memory_budget();
        let limit = self.octant_limit(budget);
        let r = self.change("adapt", |t, d| {
            changing(t, d, replace, |t| t.adapt(decide, limit))
        });
        over_budget(r, budget, limit, "adaptation")
    }

    /// Repartitions the leaves in Morton order, equal counts per rank
    /// without `weight`, else about equal sums of `weight(leaf)`, except
    /// that no family of eight sibling leaves is split
    /// ([`LinearOctree::partition_for_coarsening`],
    /// [`LinearOctree::partition_for_coarsening_weighted`]). Needs an octree.
    /// Drops the leaf classes and the mesh. Phase `partition`.
    pub fn partition_for_coarsening(
        &mut self,
        weight: Option<impl Fn(Octant) -> u64>,
    ) -> Result<()> {
        agree(&*self.comm, self.tree_or_state().map(|_| ()))?;
        let comm = self.comm.clone();
        let tree = &mut self.tree.as_mut().expect("checked above").0;
        let (data, classes) = (&mut self.data, &mut self.classes);
        self.timer.time(&*comm, "partition", || {
            moving(tree, data, |t| {
                moving_classes(t, classes, |t| match weight {
                    None => t.partition_for_coarsening(),
                    Some(w) => t.partition_for_coarsening_weighted(w),
                })
            })
        })?;
        self.changed();
        Ok(())
    }

    /// Runs `f`, a local change of the leaves, on the octree and the leaf
    /// data as phase `phase`, then reports the new count, carries the leaf
    /// classes over and drops the mesh.
    fn change<T>(
        &mut self,
        phase: &str,
        f: impl FnOnce(&mut LinearOctree, &mut Option<LeafData>) -> Result<T>,
    ) -> Result<T> {
        let comm = self.comm.clone();
        let tree = &mut self.tree.as_mut().expect("checked by the caller").0;
        // Shared, not copied: the change makes new leaves.
        let old = self.classes.rule.map(|_| tree.shared_leaves());
        let data = &mut self.data;
        let r = self.timer.time(&*comm, phase, || f(tree, data))?;
        self.changed();
        self.carry_classes(old);
        Ok(r)
    }

    /// Reports the new count and drops the mesh after a change of the
    /// leaves.
    pub(super) fn changed(&mut self) {
        let n = self.tree().map_or(0, |t| t.global_len());
        self.report_phase(Some(n));
        self.facts.octants_refined = n;
        self.facts.octants_balanced = n;
        self.drop_mesh();
    }
}
