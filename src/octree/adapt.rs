//! Adaptation of an existing octree between the steps of a simulation:
//! refinement by one split per leaf, coarsening of families of eight
//! sibling leaves, and [`LinearOctree::adapt`], one decision per leaf.
//!
//! The semantics follow p4est's `p8est_refine_ext` / `p8est_coarsen_ext`
//! and t8code's adapt callback:
//!
//! - a family is coarsened only when its eight leaves are all on this rank,
//!   next to each other in the local run; a family split across ranks is
//!   left as it is, whatever the callback would say (p4est's rule). Partition
//!   with [`LinearOctree::partition_for_coarsening`] first to keep families
//!   together;
//! - non-recursive operations look only at the leaves they were given: the
//!   children of a split are not split again, and the parent made by a
//!   coarsening is not coarsened again in the same call;
//! - recursive coarsening repeats until no family on the rank is accepted.
//!   For a callback that depends only on the family it is shown, the result
//!   does not depend on the order families are visited in, so it equals
//!   repeating the non-recursive call until nothing changes;
//! - no leaf moves between ranks: the only communication is a few
//!   collectives of one or two numbers per rank (the octant limit, the
//!   counts, the ranks' new ranges). Every operation clears the balance
//!   flag: balance again afterwards, then partition.

use crate::error::Result;
use crate::octree::limits::{check_level, global_limit};
use crate::octree::octant::{Octant, MAX_LEVEL};
use crate::octree::LinearOctree;
use crate::parallel::comm::agree;

/// A leaf's wish in [`LinearOctree::adapt`] (t8code's convention: refine
/// 1, keep 0, coarsen -1).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(i8)]
pub enum Adapt {
    /// Replace the leaf by its parent, if all eight siblings ask for it.
    Coarsen = -1,
    /// Leave the leaf as it is.
    Keep = 0,
    /// Replace the leaf by its eight children (once, not recursively).
    Refine = 1,
}

/// What an adaptation did, summed over all ranks.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AdaptStats {
    /// Leaves replaced by their eight children.
    pub refined: u64,
    /// Families of eight leaves replaced by their parent.
    pub coarsened: u64,
}

/// Whether `l[0..8]` is a family: eight sibling leaves in child order.
#[inline]
fn is_family(l: &[Octant]) -> bool {
    l.len() >= 8 && l[0].level() > 0 && l[0].child_id() == 0 && {
        let p = l[0].parent();
        (1..8).all(|i| l[i] == p.child(i as u32))
    }
}

impl LinearOctree {
    /// Splits every leaf for which `split` returns true and whose level is
    /// below `max_level` into its eight children, once: the children are
    /// not offered to `split` (p4est's non-recursive refinement; see
    /// [`LinearOctree::refine`] for the recursive one). Fails on every rank
    /// with [`crate::ErrorKind::Limit`] if the octree would have more than
    /// `limit` leaves, leaving it unchanged. Collective.
    pub fn refine_once(
        &mut self,
        max_level: u8,
        mut split: impl FnMut(Octant) -> bool,
        limit: u64,
    ) -> Result<AdaptStats> {
        agree(&**self.comm(), check_level(max_level))?;
        let marks: Vec<bool> = self
            .leaves()
            .iter()
            .map(|&o| o.level() < max_level && split(o))
            .collect();
        let refined = marks.iter().filter(|&&m| m).count();
        let new_len = self.local_len() + 7 * refined;
        let comm = self.comm().clone();
        // Counted before allocating, so that a refused call costs nothing.
        agree(&*comm, global_limit(&comm, new_len, limit))?;
        let mut out = Vec::with_capacity(new_len);
        for (&o, &m) in self.leaves().iter().zip(&marks) {
            if m {
                out.extend_from_slice(&o.children());
            } else {
                out.push(o);
            }
        }
        self.replace_leaves(out, refined as u64, 0)
    }

    /// Replaces families of eight sibling leaves by their parent where
    /// `coarsen` returns true. `coarsen` sees the family in child (Morton)
    /// order, and only families whose eight leaves are on this rank; a
    /// family split across ranks is never coarsened. With `recursive`, a
    /// parent made by coarsening may complete a new family, which is offered
    /// to `coarsen` in turn; without it, only families of the leaves the call
    /// started from are offered (p4est's `p8est_coarsen_ext` with
    /// `coarsen_recursive` 1 or 0). Collective.
    pub fn coarsen(
        &mut self,
        recursive: bool,
        mut coarsen: impl FnMut(&[Octant; 8]) -> bool,
    ) -> Result<AdaptStats> {
        let leaves = self.leaves();
        let mut out: Vec<Octant> = Vec::with_capacity(leaves.len());
        let mut families = 0u64;
        if recursive {
            // The output is a stack: a family can only be completed by the
            // leaf just pushed, so each new leaf (or parent) is checked once.
            for &o in leaves {
                out.push(o);
                while let Some(start) = out.len().checked_sub(8) {
                    let fam = &out[start..];
                    if !is_family(fam) || !coarsen(fam.try_into().expect("eight leaves")) {
                        break;
                    }
                    let parent = out[start].parent();
                    out.truncate(start);
                    out.push(parent);
                    families += 1;
                }
            }
        } else {
            let mut i = 0;
            while i < leaves.len() {
                let fam = &leaves[i..leaves.len().min(i + 8)];
                if is_family(fam) && coarsen(fam.try_into().expect("eight leaves")) {
                    out.push(leaves[i].parent());
                    families += 1;
                    i += 8;
                } else {
                    out.push(leaves[i]);
                    i += 1;
                }
            }
        }
        self.replace_leaves(out, 0, families)
    }

    /// Refines, keeps or coarsens each leaf as `decide` asks; `decide` is
    /// called once per local leaf, in Morton order. [`Adapt::Refine`] splits
    /// a leaf once (a leaf at [`MAX_LEVEL`] is kept); a family is coarsened
    /// only when its eight leaves are on this rank and all ask for
    /// [`Adapt::Coarsen`], otherwise they are kept. Not recursive: new
    /// children and parents are not offered to `decide` again (t8code's
    /// non-recursive `t8_forest_adapt`). Fails on every rank with
    /// [`crate::ErrorKind::Limit`] if the octree would have more than
    /// `limit` leaves, leaving it unchanged. Collective.
    pub fn adapt(
        &mut self,
        mut decide: impl FnMut(Octant) -> Adapt,
        limit: u64,
    ) -> Result<AdaptStats> {
        let leaves = self.leaves();
        let wish: Vec<Adapt> = leaves
            .iter()
            .map(|&o| match decide(o) {
                Adapt::Refine if o.level() >= MAX_LEVEL => Adapt::Keep,
                w => w,
            })
            .collect();
        // Which leaves start a family that goes, and the resulting size,
        // before anything is allocated for the new leaves.
        let mut coarsened = vec![false; leaves.len()];
        let (mut families, mut refined) = (0usize, 0usize);
        let mut i = 0;
        while i < leaves.len() {
            let end = leaves.len().min(i + 8);
            if wish[i] == Adapt::Coarsen
                && is_family(&leaves[i..end])
                && wish[i..end].iter().all(|&w| w == Adapt::Coarsen)
            {
                coarsened[i] = true;
                families += 1;
                i += 8;
            } else {
                refined += (wish[i] == Adapt::Refine) as usize;
                i += 1;
            }
        }
        let new_len = leaves.len() + 7 * refined - 7 * families;
        let comm = self.comm().clone();
        agree(&*comm, global_limit(&comm, new_len, limit))?;
        let mut out = Vec::with_capacity(new_len);
        let mut i = 0;
        while i < leaves.len() {
            if coarsened[i] {
                out.push(leaves[i].parent());
                i += 8;
                continue;
            }
            if wish[i] == Adapt::Refine {
                out.extend_from_slice(&leaves[i].children());
            } else {
                out.push(leaves[i]);
            }
            i += 1;
        }
        self.replace_leaves(out, refined as u64, families as u64)
    }

    /// Installs the adapted local leaves and returns the global counts.
    /// Collective.
    fn replace_leaves(
        &mut self,
        leaves: Vec<Octant>,
        refined: u64,
        coarsened: u64,
    ) -> Result<AdaptStats> {
        let mut counts = [refined, coarsened];
        self.comm().sum_u64(&mut counts);
        self.set_leaves(leaves);
        self.refresh()?;
        Ok(AdaptStats {
            refined: counts[0],
            coarsened: counts[1],
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::parallel::comm::{CommRef, SerialComm};
    use crate::refine::{build_from_callback, NO_LIMIT};
    use std::rc::Rc;

    fn comm() -> CommRef {
        Rc::new(SerialComm)
    }

    /// Leaves refined towards the point `p`, down to `level`.
    fn towards(p: [u32; 3], level: u8) -> LinearOctree {
        build_from_callback(
            comm(),
            level,
            move |o| {
                let c = o.coords();
                (0..3).all(|k| c[k] <= p[k] && p[k] < c[k] + o.side())
            },
            NO_LIMIT,
        )
        .unwrap()
    }

    #[test]
    fn refine_once_splits_only_the_marked_leaves() {
        let mut t = LinearOctree::new_uniform(comm(), 2).unwrap();
        let marked: Vec<Octant> = t.leaves().iter().step_by(5).copied().collect();
        let s = t
            .refine_once(18, |o| marked.contains(&o), NO_LIMIT)
            .unwrap();
        assert_eq!(s.refined, marked.len() as u64);
        assert_eq!(t.global_len(), 64 + 7 * marked.len() as u64);
        t.check().unwrap();
        // Not recursive: no grandchildren even though the predicate would
        // accept anything below a marked leaf.
        assert!(t.leaves().iter().all(|o| o.level() <= 3));
        let s = t.refine_once(3, |_| true, NO_LIMIT).unwrap();
        assert_eq!(s.refined, 64 - marked.len() as u64, "max level respected");
        assert!(t.leaves().iter().all(|o| o.level() == 3));
    }

    #[test]
    fn refine_once_refuses_over_the_limit_unchanged() {
        let mut t = LinearOctree::new_uniform(comm(), 2).unwrap();
        let before = t.leaves().to_vec();
        let e = t.refine_once(18, |_| true, 500).unwrap_err();
        assert_eq!(e.kind(), crate::ErrorKind::Limit);
        assert_eq!(t.leaves(), &before[..]);
    }

    #[test]
    fn non_recursive_coarsen_goes_up_one_level() {
        let mut t = LinearOctree::new_uniform(comm(), 3).unwrap();
        let mut seen = 0;
        let s = t
            .coarsen(false, |f| {
                seen += 1;
                assert!(f.iter().all(|o| o.parent() == f[0].parent()));
                true
            })
            .unwrap();
        assert_eq!((seen, s.coarsened), (64, 64));
        assert_eq!(t.global_len(), 64);
        assert!(t.leaves().iter().all(|o| o.level() == 2));
    }

    #[test]
    fn recursive_coarsen_equals_repeated_non_recursive() {
        // Coarsen families whose parent is not at the refined point's
        // corner at levels 6 and below: a rule that depends on the family
        // only, so the fixpoint is unique.
        let rule = |f: &[Octant; 8]| {
            let p = f[0].parent();
            p.level() >= 4 || p.coords()[0] > 0
        };
        let base = towards([1000, 70_000, 300_000], 9);
        let mut rec = LinearOctree::from_local_leaves(comm(), base.leaves().to_vec()).unwrap();
        let s = rec.coarsen(true, rule).unwrap();
        let mut once = LinearOctree::from_local_leaves(comm(), base.leaves().to_vec()).unwrap();
        let (mut total, mut rounds) = (0, 0);
        loop {
            let s = once.coarsen(false, rule).unwrap();
            if s.coarsened == 0 {
                break;
            }
            total += s.coarsened;
            rounds += 1;
        }
        assert!(rounds > 2, "the test should coarsen over several levels");
        assert_eq!(s.coarsened, total);
        assert_eq!(rec.leaves(), once.leaves());
        rec.check().unwrap();
    }

    #[test]
    fn adapt_refines_keeps_and_coarsens_whole_families_only() {
        let mut t = LinearOctree::new_uniform(comm(), 2).unwrap();
        let leaves = t.leaves().to_vec();
        // Family 0: all coarsen. Family 1: one keeps. Leaf 16: refine.
        let decide = |o: Octant| {
            let i = leaves.iter().position(|&x| x == o).unwrap();
            match i {
                0..=7 => Adapt::Coarsen,
                8..=14 => Adapt::Coarsen,
                16 => Adapt::Refine,
                _ => Adapt::Keep,
            }
        };
        let s = t.adapt(decide, NO_LIMIT).unwrap();
        assert_eq!((s.refined, s.coarsened), (1, 1));
        t.check().unwrap();
        assert_eq!(t.leaves()[0], leaves[0].parent());
        assert_eq!(&t.leaves()[1..9], &leaves[8..16]);
        assert_eq!(&t.leaves()[9..17], &leaves[16].children());
        assert_eq!(t.global_len(), 64 - 7 + 7);
    }

    #[test]
    fn refine_then_coarsen_everything_is_the_identity() {
        let base = towards([3, 400_000, 123_456], 7);
        let mut t = LinearOctree::from_local_leaves(comm(), base.leaves().to_vec()).unwrap();
        let r = t.refine_once(18, |_| true, NO_LIMIT).unwrap();
        let c = t.coarsen(false, |_| true).unwrap();
        assert_eq!(r.refined, base.global_len());
        assert_eq!(c.coarsened, base.global_len());
        assert_eq!(t.leaves(), base.leaves());
    }

    #[test]
    fn adapt_keeps_a_leaf_at_the_maximum_level_that_asks_to_refine() {
        let mut t = towards([5, 6, 7], MAX_LEVEL);
        let before = t.global_len();
        let s = t
            .adapt(
                |o| {
                    if o.level() == MAX_LEVEL {
                        Adapt::Refine
                    } else {
                        Adapt::Keep
                    }
                },
                NO_LIMIT,
            )
            .unwrap();
        assert_eq!((s, t.global_len()), (AdaptStats::default(), before));
    }

    #[test]
    fn adapt_keeps_a_family_that_is_not_complete_at_its_level() {
        // Refine one leaf of a family: the other seven asking to coarsen
        // must be kept, since the family is not eight leaves.
        let mut t = LinearOctree::new_uniform(comm(), 1).unwrap();
        t.refine_once(18, |o| o.child_id() == 3, NO_LIMIT).unwrap();
        let before = t.leaves().to_vec();
        let s = t
            .adapt(
                |o| {
                    if o.level() == 1 {
                        Adapt::Coarsen
                    } else {
                        Adapt::Keep
                    }
                },
                NO_LIMIT,
            )
            .unwrap();
        assert_eq!(s, AdaptStats::default());
        assert_eq!(t.leaves(), &before[..]);
    }
}
