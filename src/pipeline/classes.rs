//! Stages: the leaf classes (inside, outside, cut) and the leak check.

use std::path::Path;

use crate::classify::{classify_leaves, InsideClassifier, InsideRule, LeafClass};
use crate::comm::agree;
use crate::error::{Error, ErrorKind, Result};
use crate::leak::find_leak;

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
        let (tree, surface) = (&self.tree, &self.surface);
        let (bits, summary) = self.timer.time(&*comm, "classify", || {
            let (Some((tree, _)), Some(surface)) = (tree, surface) else {
                return (Vec::new(), None);
            };
            let c = InsideClassifier::new(&surface.index, rule);
            (c.classify(tree.leaves()), c.summary().cloned())
        });
        self.report_phase(None);
        if let Some(w) = &summary {
            self.observer.event(&Event::Winding(w));
        }
        self.facts.winding = summary;
        self.classes = Classes {
            bits,
            cut: true,
            rule: Some(rule),
        };
        Ok(())
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
                path.write(file, &domain)
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
