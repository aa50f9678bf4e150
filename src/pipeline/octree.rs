//! Stages: the octree (surface, curvature and region refinement, partition,
//! balance) and the memory budget they keep to.

use std::path::Path;

use crate::config::Command;
use crate::error::{Error, ErrorKind, Result};
use crate::io::leaves::write_leaves;
use crate::octree::domain::Domain;
use crate::octree::leaf_data::ReplaceFn;
use crate::octree::octant::{Connectivity, Octant};
use crate::octree::LinearOctree;
use crate::parallel::comm::agree;
use crate::refine::curvature::CurvatureRule;
use crate::refine::regions::RegionRules;
use crate::refine::{
    check_estimate, check_level, construct_for_callback, construct_top_for_surface,
    estimate_leaves, SurfaceIndex,
};
use crate::run::budget::{
    available_on_node, BudgetSource, MemoryBudget, BASE_BYTES, BYTES_PER_OCTANT_MESH,
    BYTES_PER_OCTANT_OCTREE, BYTES_PER_TRIANGLE,
};

use super::data;
use super::*;

impl Session {
    /// Plans the memory of the following stages for `command`: an octree
    /// alone, or an octree and its mesh (the default).
    pub fn plan(&mut self, command: Command) {
        self.plan = command;
    }

    /// The memory budget per rank, the same on every rank: the configured
    /// one, else the smallest over the nodes of their available memory
    /// shared among their ranks; `None` when it cannot be known.
    /// Collective.
    pub fn memory_budget(&mut self) -> Option<MemoryBudget> {
        let comm = &*self.comm;
        let (per_rank, source) = match self.config.octree.memory_budget {
            Some(b) => (b.0, BudgetSource::Given),
            None => {
                let on_node = comm.ranks_on_node().max(1);
                // Minima as maxima of the complements; an unknown figure is
                // u64::MAX, whose complement never wins.
                let (per, node) = match available_on_node() {
                    Some(n) => (n / on_node as u64, n),
                    None => (u64::MAX, u64::MAX),
                };
                let mut v = [!per, !node, on_node as u64];
                comm.max_u64(&mut v);
                if !v[0] == u64::MAX {
                    return None;
                }
                let source = BudgetSource::Available {
                    node: !v[1],
                    ranks_on_node: v[2] as usize,
                };
                (!v[0], source)
            }
        };
        // A distributed surface: a rank's home share and about as many near
        // its leaves.
        let triangles = match &self.surface {
            Some(s) => match &s.dist {
                Some(d) => 2 * d.home.total.div_ceil(comm.size() as u64),
                None => s.surface.len() as u64,
            },
            None => 0,
        };
        let b = MemoryBudget {
            per_rank,
            source,
            ranks: comm.size(),
            base: BASE_BYTES + triangles * BYTES_PER_TRIANGLE,
            bytes_per_octant: match self.plan {
                Command::Octree => BYTES_PER_OCTANT_OCTREE,
                Command::Mesh => BYTES_PER_OCTANT_MESH,
            },
        };
        self.facts.budget = Some(b);
        Some(b)
    }

    /// The octant limit of refinement and balance: the configured one, or
    /// the budget's when smaller.
    pub(super) fn octant_limit(&self, budget: Option<MemoryBudget>) -> u64 {
        let own = self.config.octree.limit();
        budget.map_or(own, |b| own.min(b.octant_limit()))
    }

    /// Builds a new octree whose leaves touching the surface are at the
    /// configured level (`octree.level`) and whose other leaves are as
    /// coarse as possible, in the cube of [`Session::domain`]. Fails with
    /// [`ErrorKind::Limit`] before refining when the estimate is above
    /// twice `octree.max_octants`, and as soon as the count exceeds it.
    /// Phases `construct` and `refine`. Replaces the octree, classes and
    /// mesh.
    pub fn refine_surface(&mut self, level: u8) -> Result<()> {
        let checked = self.surface_or_state().and_then(|_| {
            let d = self.next_domain()?;
            check_user_level(level, &d)?;
            Ok(d)
        });
        let domain = agree(&*self.comm, checked)?;
        // Levels count from the root cells; the lattice's are deeper in a
        // brick.
        let level = level + domain.brick.level();
        let comm = self.comm.clone();
        let budget = self.memory_budget();
        let limit = self.octant_limit(budget);
        self.facts.estimate = Some(estimate_leaves(self.index_for(domain)?, level));
        let own_limit = self.config.octree.limit();
        check_estimate(&comm, self.index_for(domain)?, level, own_limit)?;
        if let Some(b) = budget {
            let index = self.index_for(domain)?;
            agree(&*comm, check_budget(&b, index, level))?;
        }
        // Distance bands read the triangles within their distance.
        let halo = self
            .config
            .octree
            .distance
            .iter()
            .map(|b| b.0 * domain.scale())
            .fold(0.0, f64::max);
        let Some(state) = self.surface.as_mut() else {
            return Err(Error::new(ErrorKind::Internal, "the surface vanished"));
        };
        let planned = self.timer.time(&*comm, "distribute", || {
            super::distributed::plan_near(&comm, state, level, halo)
        });
        let planned = agree(&*comm, planned)?;
        if let Some((_, held)) = &planned {
            self.facts.held = self.facts.held.max(*held);
            self.facts.rss_distributed = crate::run::report::peak_rss_bytes();
            self.report_phase(None);
        }
        let index = match &self.surface {
            Some(s) => &s.index,
            None => return Err(Error::new(ErrorKind::Internal, "the surface vanished")),
        };
        let expected = self.facts.estimate.map(|e| e.refined);
        let shown = self.progress("construct", None);
        let top = self.timer.time(&*comm, "construct", || match &planned {
            Some((plan, _)) => plan.top(comm.clone(), index),
            None => construct_top_for_surface(comm.clone(), index, level),
        })?;
        drop(shown);
        report(
            &self.timer,
            &mut *self.observer,
            Some(top.tree().global_len()),
        );
        let shown = self.progress("refine", expected);
        let tree = self.timer.time(&*comm, "refine", || {
            let mut tree = top.refine(limit)?;
            fill_brick(&mut tree, domain, limit)?;
            Ok(tree)
        });
        drop(shown);
        let tree = over_budget(tree, budget, limit, "refinement")?;
        let n = tree.forest_len();
        report(&self.timer, &mut *self.observer, Some(n));
        self.facts.octants_refined = n;
        self.facts.octants_balanced = n;
        self.set_tree(tree, domain);
        Ok(())
    }

    /// Refines by a predicate: a leaf is split while `split(leaf)` is true
    /// and its level is below `max_level`. Without an octree, builds one
    /// from the root in the cube of [`Session::domain`]; otherwise refines
    /// the existing leaves (which may undo their balance). `split` must
    /// answer the same on every rank for the same octant. Phase `refine`.
    pub fn refine_callback(&mut self, max_level: u8, split: impl Fn(Octant) -> bool) -> Result<()> {
        let checked = check_level(max_level)
            .and_then(|_| self.domain())
            .map(|d| (d, self.tree.is_some()));
        let (domain, existing) = agree(&*self.comm, checked)?;
        let budget = self.memory_budget();
        let limit = self.octant_limit(budget);
        let comm = self.comm.clone();
        let tree = &mut self.tree;
        let refined = self.timer.time(&*comm, "refine", || -> Result<()> {
            match tree {
                Some((tree, _)) if existing => tree.refine(max_level, &split, limit),
                _ => {
                    let mut t = construct_for_callback(comm.clone(), max_level, &split)?;
                    t.refine(max_level, &split, limit)?;
                    fill_brick(&mut t, domain, limit)?;
                    *tree = Some((t, domain));
                    Ok(())
                }
            }
        });
        self.refined(refined, budget, limit, "refinement")
    }

    /// Refines the leaves touching the surface further where it curves:
    /// up to `octree.max_level`, while the normals of the triangles
    /// touching a leaf differ by more than `octree.feature_angle` (see
    /// [`crate::refine::curvature`]). Phase `curvature`; nothing happens without a
    /// maximum level above the surface level.
    pub fn refine_curvature(&mut self) -> Result<()> {
        let (level, max) = (self.config.octree.level, self.config.octree.max_level);
        let parts = !self.config.octree.surface_levels.is_empty();
        if level.is_none() || !(parts || max.is_some_and(|m| level.is_some_and(|l| m > l))) {
            return Ok(());
        }
        let ranges = agree(
            &*self.comm,
            self.config.surface_ranges(self.surface_name(), &self.parts),
        )?;
        let angle = self.config.octree.feature_angle();
        let domain = agree(&*self.comm, self.tree_or_state().map(|t| t.1))?;
        self.index_for(domain)?;
        let budget = self.memory_budget();
        let limit = self.octant_limit(budget);
        let comm = self.comm.clone();
        // Per-part levels are a phase of their own in the table.
        let phase = if parts { "surface_levels" } else { "curvature" };
        let shown = self.progress(phase, None);
        let (tree, surface) = (self.tree.as_mut().map(|t| &mut t.0), &self.surface);
        let refined = self.timer.time(&*comm, phase, || -> Result<()> {
            let (Some(tree), Some(s)) = (tree, surface) else {
                return Ok(());
            };
            let k = domain.brick.level();
            let ranges = ranges.iter().map(|&(a, b)| (a + k, b + k)).collect();
            let rule = CurvatureRule::with_ranges(&s.index, ranges, angle);
            let mut buf = Vec::new();
            tree.refine(rule.max_level(), |o| rule.splits(o, &mut buf), limit)
        });
        drop(shown);
        self.refined(refined, budget, limit, "curvature refinement")
    }

    /// Refines the octree by the configured minimum level and regions
    /// (`octree.min_level`, `regions`): a leaf is split while a rule asks
    /// for more (see [`crate::refine::regions`]). Within the octant limit and the
    /// memory budget. Phase `regions`; nothing happens without rules.
    pub fn refine_regions(&mut self) -> Result<()> {
        let bands = self.config.octree.distance.clone();
        let checked = self.tree_or_state().map(|t| t.1).and_then(|d| {
            if !bands.is_empty() {
                self.surface_or_state()?;
            }
            Ok(d)
        });
        let domain = agree(&*self.comm, checked)?;
        if !bands.is_empty() {
            self.index_for(domain)?;
        }
        let budget = self.memory_budget();
        let limit = self.octant_limit(budget);
        let mut rules =
            RegionRules::new(&domain, self.config.octree.min_level, &self.config.regions);
        if let (Some(s), false) = (&self.surface, bands.is_empty()) {
            rules = rules.with_bands(&domain, &bands, &s.index);
        }
        if rules.is_empty() {
            return Ok(());
        }
        let comm = self.comm.clone();
        let shown = self.progress("regions", None);
        let tree = self.tree.as_mut().map(|t| &mut t.0);
        let refined = self.timer.time(&*comm, "regions", || -> Result<()> {
            let Some(tree) = tree else { return Ok(()) };
            check_level(rules.max_level())?;
            let mut scratch = crate::refine::regions::BandScratch::default();
            tree.refine_all(
                |leaves, out| rules.refine_leaves(leaves, out, &mut scratch, limit),
                limit,
            )
        });
        drop(shown);
        self.refined(refined, budget, limit, "region refinement")
    }

    /// Estimated balanced octants per refinement control of the
    /// configuration, for `--dry-run`: `(control, octants)` rows, then their
    /// sum (controls overlap, and grading adds coarser leaves around each:
    /// an order of magnitude, not a bound). Loads the surface
    /// first when there is none; builds nothing. Collective.
    ///
    /// - surface level `L`: the estimate of the surface refinement
    ///   ([`estimate_leaves`]); curvature up to `MAX`: the same at `MAX` (what
    ///   refinement to `MAX` everywhere on the surface would give);
    /// - minimum level `M`: `8^M` per root cell, exact;
    /// - a region at level `l`: the level-`l` cells overlapping its
    ///   bounding box, or for an outside region all cells but those within
    ///   a box it contains (the 2:1 grading around it comes on top);
    /// - a distance band `(d, l)`: the surface's level-`l` estimate plus the
    ///   cells of a slab of thickness `2 d` over the surface's area.
    pub fn estimate(&mut self) -> Result<Vec<(String, u64)>> {
        if self.surface.is_none() {
            self.load_surface()?;
        }
        let domain = agree(&*self.comm, self.next_domain())?;
        let octree = self.config.octree.clone();
        let regions = self.config.regions.clone();
        let level = octree.level.unwrap_or(0);
        // Levels count from the root cells; the lattice's are `k` deeper.
        let (k, roots, trees) = (
            domain.brick.level(),
            domain.brick.roots(),
            domain.brick.trees(),
        );
        let (area, index) = {
            let s = self.surface.as_ref().expect("just loaded");
            (s.surface.area(), self.index_for(domain)?)
        };
        let mut rows = vec![(
            format!("surface level {level}"),
            estimate_leaves(index, level + k).balanced,
        )];
        if let Some(max) = octree.max_level.filter(|&m| m > level) {
            let at_max = estimate_leaves(index, max + k).balanced;
            rows.push((format!("curvature up to level {max} (at most)"), at_max));
        }
        if octree.min_level > 0 {
            rows.push((
                format!("min level {}", octree.min_level),
                trees.saturating_mul(8u64.saturating_pow(octree.min_level as u32)),
            ));
        }
        let cell = |l: u8| domain.root_side() / (1u64 << l) as f64;
        let cells_on = |l: u8, a: usize| (roots[a] as u64 * (1u64 << l)) as f64;
        let cells_per_axis = |l: u8| (1u64 << l) as f64;
        for r in &regions {
            let l = r.level();
            // Inside: the cells overlapping the bounding box; outside: all
            // cells but those within a box the region contains.
            let count = |(lo, hi): ([f64; 3], [f64; 3]), overlapping: bool| -> f64 {
                (0..3)
                    .map(|a| {
                        let (x0, x1) = (
                            (lo[a] - domain.origin[a]) / cell(l),
                            (hi[a] - domain.origin[a]) / cell(l),
                        );
                        let (first, last) = if overlapping {
                            (x0.floor(), x1.ceil())
                        } else {
                            (x0.ceil(), x1.floor())
                        };
                        (last.min(cells_on(l, a)) - first.max(0.0)).max(0.0)
                    })
                    .product()
            };
            let n = if r.outside() {
                let inner = r.inner_box().map_or(0.0, |b| count(b, false));
                trees as f64 * cells_per_axis(l).powi(3) - inner
            } else {
                count(r.bounding_box(), true)
            };
            rows.push((format!("region {}", r.describe()), n.round() as u64));
        }
        for &(d, l) in &octree.distance {
            let slab = 2.0 * d * area / cell(l).powi(3);
            let n = estimate_leaves(index, l + k).balanced as f64 + slab;
            let all = trees as f64 * cells_per_axis(l).powi(3);
            rows.push((
                format!("distance {d} at level {l}"),
                n.min(all).round() as u64,
            ));
        }
        let total = rows.iter().fold(0u64, |t, r| t.saturating_add(r.1));
        rows.push(("total (sum of the controls)".to_string(), total));
        Ok(rows)
    }

    /// Ends a refinement stage: its error (in the budget's words when the
    /// budget stopped it), its row, the new counts, the stale classes and
    /// mesh dropped.
    fn refined(
        &mut self,
        r: Result<()>,
        budget: Option<MemoryBudget>,
        limit: u64,
        during: &str,
    ) -> Result<()> {
        over_budget(r, budget, limit, during)?;
        let n = self.tree().map_or(0, |t| t.forest_len());
        self.report_phase(Some(n));
        self.facts.octants_refined = n;
        self.facts.octants_balanced = n;
        self.classes = Classes::default();
        self.drop_mesh();
        // These refinements have no replace callback: the data is detached.
        self.data = None;
        Ok(())
    }

    pub(super) fn set_tree(&mut self, mut tree: LinearOctree, domain: Domain) {
        tree.set_brick(domain.brick);
        self.tree = Some((tree, domain));
        self.data = None;
        self.classes = Classes::default();
        self.drop_mesh();
    }

    /// Repartitions the leaves in Morton order, equal counts per rank.
    /// Phase `partition`.
    pub fn partition(&mut self) -> Result<()> {
        self.partition_weighted(None::<fn(Octant) -> u64>)
    }

    /// Repartitions the leaves in Morton order: equal counts without
    /// `weight`, else about equal sums of `weight(leaf)`. Leaf classes
    /// are dropped (they follow the old partition). Phase `partition`.
    pub fn partition_weighted(&mut self, weight: Option<impl Fn(Octant) -> u64>) -> Result<()> {
        agree(&*self.comm, self.tree_or_state().map(|_| ()))?;
        let comm = self.comm.clone();
        let tree = self.tree.as_mut().map(|t| &mut t.0);
        let (data, classes) = (&mut self.data, &mut self.classes);
        self.timer.time(&*comm, "partition", || -> Result<()> {
            let Some(tree) = tree else { return Ok(()) };
            data::moving(tree, data, |tree| {
                super::classes::moving_classes(tree, classes, |tree| match &weight {
                    None => tree.partition().map(|_| ()),
                    Some(w) => tree.partition_weighted(w).map(|_| ()),
                })
            })
        })?;
        let count = self.tree().map(|t| t.forest_len());
        self.report_phase(count);
        self.drop_mesh();
        Ok(())
    }

    /// 2:1-balances the octree for `conn` contacts, within the octant
    /// limit (on failure the octree is as it was). Leaves stay on their
    /// ranks. Phase `balance`.
    pub fn balance(&mut self, conn: Connectivity) -> Result<()> {
        self.balance_replace(conn, None)
    }

    /// [`Session::balance`] keeping the leaf data: each leaf balance splits
    /// goes through `replace` (without it, new leaves' data is zero), see
    /// [`crate::octree::leaf_data`]; on failure the octree and the data are as they
    /// were. Phase `balance`.
    pub fn balance_replace(
        &mut self,
        conn: Connectivity,
        replace: Option<ReplaceFn>,
    ) -> Result<()> {
        agree(&*self.comm, self.tree_or_state().map(|_| ()))?;
        // Balance keeps a copy of the leaves to restore when it stops at a
        // limit; the budget applies only when the octree is within a
        // factor of 8 of it, as surface octrees grow by about 1.3.
        let n = self.tree().map_or(0, |t| t.global_len());
        let budget = self
            .memory_budget()
            .filter(|b| n.saturating_mul(8) > b.octant_limit());
        let limit = self.octant_limit(budget);
        let comm = self.comm.clone();
        let expected = self.facts.estimate.map(|e| e.balanced);
        let shown = self.progress("balance", expected);
        let tree = self.tree.as_mut().map(|t| &mut t.0);
        // Kept only when there are classes to carry over (balance then
        // splits a copy, since these are shared).
        let old = match (&tree, self.classes.rule) {
            (Some(t), Some(_)) => Some(t.shared_leaves()),
            _ => None,
        };
        let data = &mut self.data;
        let balanced = self.timer.time(&*comm, "balance", || -> Result<()> {
            let Some(tree) = tree else { return Ok(()) };
            data::changing(tree, data, replace, |tree| {
                tree.balance_with_limit(conn, limit).map(|_| ())
            })
        });
        drop(shown);
        over_budget(balanced, budget, limit, "balance")?;
        let count = self.tree().map(|t| t.forest_len());
        self.report_phase(count);
        self.facts.octants_balanced = self.tree().map_or(0, |t| t.forest_len());
        self.drop_mesh();
        self.carry_classes(old);
        Ok(())
    }

    /// Writes the leaves (`title` goes in the file's header line). Collective.
    pub fn write_leaves(&self, path: &Path, title: &str) -> Result<()> {
        let (tree, _) = agree(&*self.comm, self.tree_or_state())?;
        write_leaves(tree, path, title)
    }
}

/// Fails with the budget's error when the octree estimated at `level` does
/// not fit, naming the largest level that does.
pub(super) fn check_budget(b: &MemoryBudget, index: &SurfaceIndex, level: u8) -> Result<()> {
    let e = estimate_leaves(index, level);
    if b.need(e.balanced) <= b.per_rank {
        return Ok(());
    }
    let fits = (0..level)
        .rev()
        .map(|l| estimate_leaves(index, l))
        .find(|f| b.need(f.balanced) <= b.per_rank);
    let hint = match fits {
        Some(f) => format!("level {} would fit (about {} octants)", f.level, f.balanced),
        None => "no level fits".to_string(),
    };
    let what = format!(
        "about {} octants are estimated at level {level}, so nothing was refined",
        e.balanced
    );
    Err(b.error(e.balanced, &what, &hint))
}

/// A stage's result, with an octant-limit failure that the memory budget
/// (not the configured limit) set turned into the budget's error.
pub(super) fn over_budget<T>(
    r: Result<T>,
    budget: Option<MemoryBudget>,
    limit: u64,
    during: &str,
) -> Result<T> {
    match (r, budget) {
        (Err(e), Some(b)) if e.kind() == ErrorKind::Limit && limit == b.octant_limit() => {
            let what = format!("the octree grew past the {limit} octants that fit during {during}");
            Err(b.error(limit, &what, "a lower level or more ranks would fit"))
        }
        (r, _) => r,
    }
}

/// Checks a level counted from the root cells of `domain`: at most
/// [`crate::octree::octant::MAX_LEVEL`] less the trees' level.
pub(crate) fn check_user_level(level: u8, domain: &Domain) -> Result<()> {
    let most = domain.brick.max_user_level();
    if level > most && !domain.brick.is_cube() {
        let r = domain.brick.roots();
        return Err(Error::invalid(format!(
            "level {level} is too deep for {}x{}x{} root cells: levels go up to {most}",
            r[0], r[1], r[2]
        )));
    }
    check_level(level)
}

/// Splits every octant of a brick's domain down to the trees' level, so each
/// root cell is covered by its own leaves (the void stays as it is).
/// Nothing to do in a cube. Collective.
fn fill_brick(tree: &mut LinearOctree, domain: Domain, limit: u64) -> Result<()> {
    let brick = domain.brick;
    if brick.is_cube() {
        return Ok(());
    }
    tree.set_brick(brick);
    let k = brick.level();
    let shallow = |o: &Octant| o.level() < k && !brick.is_void(*o);
    // Surface refinement usually reaches every tree already: then no copy.
    let mut any = [u64::from(tree.leaves().iter().any(shallow))];
    tree.comm().max_u64(&mut any);
    if any[0] == 0 {
        return Ok(());
    }
    tree.refine(k, |o| shallow(&o), limit)
}
