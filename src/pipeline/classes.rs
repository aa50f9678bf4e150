//! Stages: the leaf classes (inside, outside, cut) and the leak check.

use std::path::Path;

use std::sync::Arc;

use crate::classify::{carry_classes, classify_leaves, InsideClassifier, InsideRule, LeafClass};
use crate::error::{Error, ErrorKind, Result};
use crate::leak::find_leak;
use crate::octree::leaf_data::LeafData;
use crate::octree::LinearOctree;
use crate::parallel::comm::agree;
use crate::Octant;

use super::*;

impl Session {
    /// Sets the inside rule of the following classifications and meshes.
    pub fn set_inside_rule(&mut self, rule: InsideRule) {
        self.inside = Some(rule);
    }

    /// The rule `rule` stands for on this surface: itself, or for `auto`
    /// the choice the diagnostics make.
    pub(super) fn resolve(&self, rule: InsideRule) -> Result<InsideRule> {
        Ok(match rule {
            InsideRule::Auto => InsideRule::auto_choice(self.surface_or_state()?.report()).0,
            r => r,
        })
    }

    /// Classifies the leaves against the surface with `rule` (inside,
    /// outside, cut). Phase `classify`.
    pub fn classify(&mut self, rule: InsideRule) -> Result<()> {
        let checked = self.tree_or_state().map(|(_, d)| *d).and_then(|d| {
            let r = self.resolve(rule)?;
            Ok((d, r))
        });
        let (domain, rule) = agree(&*self.comm, checked)?;
        self.index_for(domain)?;
        let comm = self.comm.clone();
        if let (Some((tree, _)), Some(state)) = (&self.tree, self.surface.as_mut()) {
            let near = self.timer.time(&*comm, "distribute", || {
                super::distributed::classify_near(&comm, state, tree)
            });
            if let Some((_, held)) = near {
                self.facts.held = self.facts.held.max(held);
                self.report_phase(None);
            }
        }
        let (tree, surface) = (&self.tree, &self.surface);
        let spare = crate::parallel::cores::spare_core(&*comm);
        let (bits, summary) = self.timer.time(&*comm, "classify", || {
            let (Some((tree, _)), Some(surface)) = (tree, surface) else {
                return (Vec::new(), None);
            };
            let c = match surface.dist.as_ref().and_then(|d| d.shared) {
                // Only the parity rule distributes the surface.
                Some(shared) if rule == InsideRule::Parity => {
                    InsideClassifier::parity_shared(&surface.index, shared)
                }
                _ => InsideClassifier::new(&surface.index, rule),
            };
            (c.classify_spare(tree.leaves(), spare), c.summary().cloned())
        });
        self.report_phase(None);
        if let Some(w) = &summary {
            self.observer.event(&Event::Winding(w));
        }
        let inherit = summary.as_ref().is_none_or(|w| w.cap_triangles == 0);
        self.facts.winding = summary;
        self.classes = Classes {
            bits,
            cut: true,
            rule: Some(rule),
            inherit,
        };
        Ok(())
    }

    /// After a local change of the leaves (refine, coarsen, adapt,
    /// balance) from `old`, carries the classes over
    /// ([`crate::classify::carry_classes`]) and classifies only the new
    /// leaves that need it; without old leaves, classes or a surface to
    /// classify against, drops them. Collective. Phase `classify` (count:
    /// the leaves classified again).
    pub(super) fn carry_classes(&mut self, old: Option<Arc<Vec<Octant>>>) {
        let domain = self.tree.as_ref().map(|t| t.1);
        let (Some(old), Some(rule), Some(domain)) = (old, self.classes.rule, domain) else {
            self.classes = Classes::default();
            return;
        };
        // The surface is there on every rank or on none; a distributed one
        // holds the triangles near other leaves: classify again.
        let spread = self.surface.as_ref().is_some_and(|s| s.dist.is_some());
        if spread || self.index_for(domain).is_err() {
            self.classes = Classes::default();
            return;
        }
        let (Some((tree, _)), Some(surface)) = (&self.tree, &self.surface) else {
            return;
        };
        let comm = self.comm.clone();
        let classes = &mut self.classes;
        let pending = self.timer.time(&*comm, "classify", || {
            let old_bits = std::mem::take(&mut classes.bits);
            let (mut bits, pending) =
                carry_classes(&old, &old_bits, tree.leaves(), classes.inherit);
            if !pending.is_empty() {
                let leaves: Vec<Octant> = pending.iter().map(|&k| tree.leaves()[k]).collect();
                let fresh = InsideClassifier::new(&surface.index, rule).classify(&leaves);
                for (&k, b) in pending.iter().zip(fresh) {
                    bits[k] = b;
                }
            }
            classes.bits = bits;
            pending.len()
        });
        let mut n = [pending as u64];
        comm.sum_u64(&mut n);
        self.report_phase(Some(n[0]));
    }

    /// The class byte of each local leaf (bits `classify::CENTER_INSIDE`,
    /// `CUT`), when the leaves are classified.
    pub fn leaf_classes(&self) -> Option<&[u8]> {
        self.classes.rule.map(|_| self.classes.bits.as_slice())
    }

    /// Counts the leaves per class over all ranks (after
    /// [`Session::classify`]): inside, outside, cut. Collective.
    pub fn count_classes(&mut self) -> Result<[u64; 3]> {
        let local = match self.classes.cut {
            true => Ok(&self.classes),
            false => Err(Error::new(
                ErrorKind::State,
                "the leaves are not classified",
            )),
        };
        let classes = agree(&*self.comm, local)?;
        let mut n = [0u64; 3];
        for &b in &classes.bits {
            n[LeafClass::from_bits(b) as usize] += 1;
        }
        self.comm.sum_u64(&mut n);
        let out = [
            n[LeafClass::Inside as usize],
            n[LeafClass::Outside as usize],
            n[LeafClass::Cut as usize],
        ];
        self.facts.leaf_classes = Some(out);
        self.observer.event(&Event::LeafClasses(out));
        Ok(out)
    }

    // ----- leak check ----------------------------------------------------------

    /// Checks that the region outside the surface does not reach `point`
    /// (user units), known to be inside the body. `Ok(())` when sealed off;
    /// an [`ErrorKind::Leak`] error describing the path when it is reached
    /// (written to `path_file` first, if given). Phase `leak_check`.
    pub fn check_leak(&mut self, point: [f64; 3], path_file: Option<&Path>) -> Result<()> {
        let checked = self
            .tree_or_state()
            .map(|(_, d)| *d)
            .and_then(|d| self.surface_or_state().map(|_| d));
        let domain = agree(&*self.comm, checked)?;
        self.index_for(domain)?;
        if !self.classes.cut {
            // The leak search needs only the cut bits, which every rule
            // computes alike.
            let (Some((tree, _)), Some(s)) = (&self.tree, &self.surface) else {
                return Err(Error::new(ErrorKind::Internal, "the octree vanished"));
            };
            self.classes = Classes {
                bits: classify_leaves(tree.leaves(), &s.index),
                cut: true,
                rule: None,
                inherit: false,
            };
        }
        let comm = self.comm.clone();
        let (tree, classes) = (&self.tree, &self.classes);
        let found = self.timer.time(&*comm, "leak_check", || match tree {
            Some((tree, d)) => find_leak(tree, &classes.bits, d, point),
            _ => Err(Error::new(ErrorKind::Internal, "the octree vanished")),
        })?;
        self.report_phase(None);
        self.facts.leak_checked = true;
        self.facts.leak_path = found.as_ref().map(|p| p.len());
        let seconds = self.timer.get("leak_check");
        let Some(path) = found else {
            self.observer.event(&Event::LeakChecked {
                point,
                path_octants: None,
                seconds,
                written: None,
            });
            return Ok(());
        };
        if let Some(file) = path_file {
            let written = if self.comm.rank() == 0 {
                crate::io::leak_path::write_leak_path(
                    file,
                    &path.centres(&domain),
                    &path.sizes(&domain),
                    path.octants(),
                )
            } else {
                Ok(())
            };
            agree(&*self.comm, written)?;
        }
        self.observer.event(&Event::LeakChecked {
            point,
            path_octants: Some(path.len()),
            seconds,
            written: path_file,
        });
        let bbox = self.surface_or_state()?.bbox;
        Err(path.to_error(&domain, Some(&bbox)))
    }
}

/// Runs `op`, a partition, moving the class bytes with the leaves when
/// there are classes.
pub(super) fn moving_classes<T>(
    tree: &mut LinearOctree,
    classes: &mut Classes,
    op: impl FnOnce(&mut LinearOctree) -> Result<T>,
) -> Result<T> {
    if !classes.cut {
        return op(tree);
    }
    let mut d = LeafData::new(1, tree.local_len());
    d.as_bytes_mut().copy_from_slice(&classes.bits);
    let r = tree.move_with_data(&mut d, op)?;
    classes.bits = d.as_bytes().to_vec();
    Ok(r)
}
