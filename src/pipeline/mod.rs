//! The pipeline, once: a [`Session`] holds the surface, the domain, the
//! octree, the leaf classes and the mesh, with one method per stage.
//!
//! ```text
//!  load_surface ─► refine_surface ─► partition ─► balance ─► partition
//!   (read)         (construct,                  (balance)
//!                   refine)
//!      ─► classify ─► check_leak ─► build_mesh ─► write_vtu
//!                                   (ghost, nodes, numbering, connectivity)
//! ```
//!
//! The `octmesh` command runs the whole sequence a [`Config`] asks for
//! ([`Session::run`]); the C handle calls the stages one by one as its user
//! does. Both see the same checks, limits, timings and errors, so a new
//! stage is added here once. Every stage is collective over the session's
//! communicator, times itself as a phase (the names of [`Event::Phase`]),
//! and tells its [`Observer`] what it did. A failed stage leaves the session
//! as it was before the call.

pub mod observer;
pub mod stats;

use std::cell::OnceCell;
use std::path::Path;

use crate::budget::{
    available_on_node, BudgetSource, MemoryBudget, BASE_BYTES, BYTES_PER_OCTANT_MESH,
    BYTES_PER_OCTANT_OCTREE, BYTES_PER_TRIANGLE,
};
use crate::classify::{
    classify_leaves, CutRule, InsideClassifier, InsideRule, Keep, LeafClass, WindingSummary,
};
use crate::comm::{agree, CommRef};
use crate::config::{Command, Config};
use crate::curvature::CurvatureRule;
use crate::domain::Domain;
use crate::error::{Error, ErrorKind, Result};
use crate::geometry::diagnostics::{clean, diagnose, SurfaceReport};
use crate::geometry::{load_surface, Aabb, Surface};
use crate::io::leaves::write_leaves;
use crate::io::vtu::write_mesh;
use crate::leak::find_leak;
use crate::mesh::{Mesh, MeshOptions};
use crate::octant::{Connectivity, Octant};
use crate::octree::LinearOctree;
use crate::progress::{self, Progress, Style};
use crate::refine::{
    check_estimate, check_level, construct_for_callback, construct_top_for_surface,
    estimate_leaves, LeafEstimate, SurfaceIndex,
};
use crate::regions::RegionRules;
use crate::report::{peak_rss_bytes, PhaseTimer};

pub use observer::{Event, Observer, Silent};

/// The feature angle of curvature refinement when none is configured,
/// degrees (snappyHexMesh's `resolveFeatureAngle` default).
pub const DEFAULT_FEATURE_ANGLE: f64 = 30.0;
pub use stats::Stats;

/// The surface and what is derived from it.
struct SurfaceState {
    /// What the surface is called in messages and statistics.
    name: String,
    surface: Surface,
    /// The triangles in lattice units of `index_domain`.
    index: SurfaceIndex,
    index_domain: Domain,
    /// Facets the clean-up dropped, when one ran.
    dropped: Option<usize>,
    /// The diagnostics, computed on first need.
    report: OnceCell<SurfaceReport>,
    /// Bounding box and enclosed volume, kept for reports after the
    /// surface itself is released.
    bbox: Aabb,
    volume: f64,
}

impl SurfaceState {
    fn report(&self) -> &SurfaceReport {
        self.report.get_or_init(|| diagnose(&self.surface))
    }
}

/// The leaf classes of the current octree. A plain struct, not an
/// `Option`: every byte of it is written whenever it changes.
#[derive(Default)]
struct Classes {
    /// One class byte per local leaf (empty when `cut` is false).
    bits: Vec<u8>,
    /// Whether `bits` holds at least the cut bit of every leaf.
    cut: bool,
    /// The rule the inside bits were classified with; `None` when only the
    /// cut bit was computed (for a leak check).
    rule: Option<InsideRule>,
}

/// Counts a run gathers for its statistics.
#[derive(Clone, Debug, Default)]
struct Facts {
    octants_refined: u64,
    octants_balanced: u64,
    winding: Option<WindingSummary>,
    leaf_classes: Option<[u64; 3]>,
    leak_checked: bool,
    leak_path: Option<usize>,
    triangles: usize,
    dropped: Option<usize>,
    estimate: Option<LeafEstimate>,
    /// The surface's diagnostics, when the run computed them.
    report: Option<SurfaceReport>,
    /// The memory budget of the last refinement or balance.
    budget: Option<MemoryBudget>,
    /// Peak memory before anything and after reading, bytes (this rank).
    rss_start: u64,
    rss_read: u64,
}

/// A meshing session over a communicator: the pipeline's state and stages.
pub struct Session {
    comm: CommRef,
    config: Config,
    /// The inside rule meshes and classifications use when none is given.
    inside: Option<InsideRule>,
    /// What the memory budget plans for.
    plan: Command,
    /// How rank 0 shows the progress of long phases, if at all.
    progress: Option<Style>,
    /// Counts the meshes built, so that views of a mesh know it changed.
    mesh_generation: u64,
    timer: PhaseTimer,
    observer: Box<dyn Observer>,
    surface: Option<SurfaceState>,
    /// The surface's box and volume after [`Session::release_surface`].
    released: Option<(Aabb, f64, String)>,
    /// The octree and the cube it was built in.
    tree: Option<(LinearOctree, Domain)>,
    classes: Classes,
    mesh: Option<Mesh>,
    facts: Facts,
}

impl Session {
    /// A session with nothing built yet. `config` gives every choice a
    /// stage does not take as an argument.
    pub fn new(comm: CommRef, config: Config) -> Session {
        Session {
            comm,
            inside: config.classify.inside,
            plan: Command::Mesh,
            progress: None,
            mesh_generation: 0,
            config,
            timer: PhaseTimer::new(),
            observer: Box::new(Silent),
            surface: None,
            released: None,
            tree: None,
            classes: Classes::default(),
            mesh: None,
            facts: Facts {
                rss_start: peak_rss_bytes(),
                ..Facts::default()
            },
        }
    }

    /// Sends the events of the following stages to `observer`.
    pub fn set_observer(&mut self, observer: Box<dyn Observer>) {
        self.observer = observer;
    }

    /// The configuration.
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// Changes the configuration for the following stages (what is built
    /// stays).
    pub fn config_mut(&mut self) -> &mut Config {
        &mut self.config
    }

    /// The communicator.
    pub fn comm(&self) -> &CommRef {
        &self.comm
    }

    /// The octree, if one was built.
    pub fn tree(&self) -> Option<&LinearOctree> {
        self.tree.as_ref().map(|(t, _)| t)
    }

    /// The mesh, if one was built since the octree last changed.
    pub fn mesh(&self) -> Option<&Mesh> {
        self.mesh.as_ref()
    }

    /// A number that changes whenever a new mesh is built.
    pub fn mesh_generation(&self) -> u64 {
        self.mesh_generation
    }

    /// The phases run so far.
    pub fn timer(&self) -> &PhaseTimer {
        &self.timer
    }

    /// The inside rule the leaves of the current mesh (or octree) were
    /// classified with, if they were.
    pub fn classified_with(&self) -> Option<InsideRule> {
        self.classes.rule
    }

    /// The cube of the current octree or, without one, of the next one:
    /// the configured cube, else the one fitted around the surface, else
    /// the unit cube.
    pub fn domain(&self) -> Result<Domain> {
        if let Some((_, d)) = &self.tree {
            return Ok(*d);
        }
        self.next_domain()
    }

    fn next_domain(&self) -> Result<Domain> {
        let d = &self.config.domain;
        match (&self.surface, d.cube) {
            // An explicit cube does not depend on the surface's box.
            (_, Some(_)) => d.resolve([0.0; 3], [0.0; 3]),
            (Some(s), None) => d.resolve(s.bbox.min, s.bbox.max),
            (None, None) => Domain::cube([0.0; 3], 1.0),
        }
    }

    /// The surface, or a state error saying how to give one.
    fn surface_or_state(&self) -> Result<&SurfaceState> {
        self.surface.as_ref().ok_or_else(|| {
            Error::new(
                ErrorKind::State,
                "there is no surface: load one first (octmesh_surface_from_stl, \
                 octmesh_surface_from_triangles or octmesh_surface_builtin)",
            )
        })
    }

    /// The octree, or a state error saying how to make one.
    fn tree_or_state(&self) -> Result<&(LinearOctree, Domain)> {
        self.tree.as_ref().ok_or_else(|| {
            Error::new(
                ErrorKind::State,
                "there is no octree yet: refine first (octmesh_octree_refine_surface or \
                 octmesh_octree_refine_callback)",
            )
        })
    }

    /// Tells the observer about the last phase recorded.
    fn report_phase(&mut self, count: Option<u64>) {
        report(&self.timer, &mut *self.observer, count);
    }

    /// Shows the progress of long phases on rank 0 in `style` (none by
    /// default).
    pub fn set_progress(&mut self, style: Option<Style>) {
        self.progress = style;
    }

    /// The progress display of phase `name` with `expected` octants, on
    /// rank 0 when asked for; it ends when dropped.
    fn progress(&self, name: &str, expected: Option<u64>) -> Option<Progress> {
        let style = self.progress.filter(|_| self.comm.rank() == 0)?;
        let ranks = self.comm.size() as u64;
        Some(Progress::start(
            name,
            expected,
            ranks,
            style,
            progress::delay(),
        ))
    }

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
        let triangles = self.surface.as_ref().map_or(0, |s| s.surface.len()) as u64;
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
    fn octant_limit(&self, budget: Option<MemoryBudget>) -> u64 {
        let own = self.config.octree.limit();
        budget.map_or(own, |b| own.min(b.octant_limit()))
    }

    // ----- surface -------------------------------------------------------

    /// Reads the configured surface (`surface.file`: an STL file, `sphere`
    /// or `torus`), cleans it as configured, and indexes it for the cube
    /// the next octree will use. Phase `read`. Collective: a failure on any
    /// rank (a file missing on one node) fails on every rank.
    pub fn load_surface(&mut self) -> Result<()> {
        let file = self.config.surface.file.clone();
        self.install_surface(&file, || load_surface(&file))
    }

    /// Installs `surface` (read by the caller on every rank) under `name`,
    /// as [`Session::load_surface`] does with a file.
    pub fn set_surface(&mut self, name: &str, surface: Result<Surface>) -> Result<()> {
        self.install_surface(name, || surface)
    }

    fn install_surface(&mut self, name: &str, get: impl FnOnce() -> Result<Surface>) -> Result<()> {
        let (drop_degenerate, drop_duplicates) = (
            self.config.surface.drop_degenerate,
            self.config.surface.drop_duplicates,
        );
        let want_report =
            self.config.output.stats.is_some() || self.inside == Some(InsideRule::Auto);
        let comm = self.comm.clone();
        let (tree_domain, domain_config) = (self.tree.as_ref().map(|t| t.1), &self.config.domain);
        let loaded = self.timer.time(&*comm, "read", || -> Result<SurfaceState> {
            let mut surface = get()?;
            let mut dropped = None;
            if drop_degenerate || drop_duplicates {
                let (cleaned, n) = clean(&surface, drop_degenerate, drop_duplicates)?;
                surface = cleaned;
                dropped = Some(n);
            }
            let bbox = surface.bbox();
            let domain = match tree_domain {
                Some(d) => d,
                None => domain_config.resolve(bbox.min, bbox.max)?,
            };
            let report = OnceCell::new();
            if want_report {
                let _ = report.set(diagnose(&surface));
            }
            Ok(SurfaceState {
                name: name.to_string(),
                index: SurfaceIndex::new(&surface, &domain),
                index_domain: domain,
                volume: surface.signed_volume().abs(),
                bbox,
                surface,
                dropped,
                report,
            })
        });
        let state = agree(&*self.comm, loaded)?;
        self.facts.rss_read = peak_rss_bytes();
        let level = self.config.octree.level;
        let estimate = level.map(|l| estimate_leaves(&state.index, l));
        let inside = self.inside.map(|r| match r {
            InsideRule::Auto => {
                let (rule, why) = InsideRule::auto_choice(state.report());
                (rule, format!(" (auto: {why})"))
            }
            r => (r, String::new()),
        });
        self.observer.event(&Event::SurfaceLoaded {
            name: &state.name,
            triangles: state.surface.len(),
            dropped: state.dropped,
            domain: state.index_domain,
            estimate,
            inside: inside.as_ref().map(|(r, why)| (*r, why.as_str())),
        });
        self.facts.triangles = state.surface.len();
        self.facts.dropped = state.dropped;
        self.facts.estimate = estimate;
        self.facts.report = state.report.get().cloned();
        // The phase's row comes after the facts it found.
        self.report_phase(None);
        self.surface = Some(state);
        self.released = None;
        self.classes = Classes::default();
        Ok(())
    }

    /// Frees the surface (its triangles and index) once no stage needs it:
    /// meshing does not, and its memory then goes before the mesh's.
    pub fn release_surface(&mut self) {
        if let Some(s) = self.surface.take() {
            self.released = Some((s.bbox, s.volume, s.name));
        }
    }

    /// The surface index mapped to the cube `domain` (re-mapped if the
    /// surface was indexed for another cube).
    fn index_for(&mut self, domain: Domain) -> Result<&SurfaceIndex> {
        let s = self
            .surface
            .as_mut()
            .ok_or_else(|| Error::new(ErrorKind::State, "there is no surface: load one first"))?;
        if s.index_domain != domain {
            s.index = SurfaceIndex::new(&s.surface, &domain);
            s.index_domain = domain;
        }
        Ok(&s.index)
    }

    // ----- octree ----------------------------------------------------------

    /// Builds a new octree whose leaves touching the surface are at the
    /// configured level (`octree.level`) and whose other leaves are as
    /// coarse as possible, in the cube of [`Session::domain`]. Fails with
    /// [`ErrorKind::Limit`] before refining when the estimate is above
    /// twice `octree.max_octants`, and as soon as the count exceeds it.
    /// Phases `construct` and `refine`. Replaces the octree, classes and
    /// mesh.
    pub fn refine_surface(&mut self, level: u8) -> Result<()> {
        let checked = self.surface_or_state().and_then(|_| {
            check_level(level)?;
            self.next_domain()
        });
        let domain = agree(&*self.comm, checked)?;
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
        let index = match &self.surface {
            Some(s) => &s.index,
            None => return Err(Error::new(ErrorKind::Internal, "the surface vanished")),
        };
        let expected = self.facts.estimate.map(|e| e.refined);
        let shown = self.progress("construct", None);
        let top = self.timer.time(&*comm, "construct", || {
            construct_top_for_surface(comm.clone(), index, level)
        })?;
        drop(shown);
        report(
            &self.timer,
            &mut *self.observer,
            Some(top.tree().global_len()),
        );
        let shown = self.progress("refine", expected);
        let tree = self.timer.time(&*comm, "refine", || top.refine(limit));
        drop(shown);
        let tree = over_budget(tree, budget, limit, "refinement")?;
        report(&self.timer, &mut *self.observer, Some(tree.global_len()));
        self.facts.octants_refined = tree.global_len();
        self.facts.octants_balanced = tree.global_len();
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
                    *tree = Some((t, domain));
                    Ok(())
                }
            }
        });
        over_budget(refined, budget, limit, "refinement")?;
        let count = self.tree().map(|t| t.global_len());
        self.report_phase(count);
        let n = self.tree().map_or(0, |t| t.global_len());
        self.facts.octants_refined = n;
        self.facts.octants_balanced = n;
        self.classes = Classes::default();
        self.mesh = None;
        Ok(())
    }

    /// Refines the leaves touching the surface further where it curves:
    /// up to `octree.max_level`, while the normals of the triangles
    /// touching a leaf differ by more than `octree.feature_angle` (see
    /// [`crate::curvature`]). Phase `curvature`; nothing happens without a
    /// maximum level above the surface level.
    pub fn refine_curvature(&mut self) -> Result<()> {
        let (level, max) = (self.config.octree.level, self.config.octree.max_level);
        let Some(max) = max.filter(|&m| level.is_some_and(|l| m > l)) else {
            return Ok(());
        };
        let angle = self
            .config
            .octree
            .feature_angle
            .unwrap_or(DEFAULT_FEATURE_ANGLE);
        let domain = agree(&*self.comm, self.tree_or_state().map(|t| t.1))?;
        self.index_for(domain)?;
        let budget = self.memory_budget();
        let limit = self.octant_limit(budget);
        let comm = self.comm.clone();
        let shown = self.progress("curvature", None);
        let (tree, surface) = (self.tree.as_mut().map(|t| &mut t.0), &self.surface);
        let refined = self.timer.time(&*comm, "curvature", || -> Result<()> {
            let (Some(tree), Some(s)) = (tree, surface) else {
                return Ok(());
            };
            let rule = CurvatureRule::new(&s.index, max, angle);
            let mut buf = Vec::new();
            tree.refine(rule.max_level(), |o| rule.splits(o, &mut buf), limit)
        });
        drop(shown);
        over_budget(refined, budget, limit, "curvature refinement")?;
        let n = self.tree().map_or(0, |t| t.global_len());
        self.report_phase(Some(n));
        self.facts.octants_refined = n;
        self.facts.octants_balanced = n;
        self.classes = Classes::default();
        self.mesh = None;
        Ok(())
    }

    /// Refines the octree by the configured minimum level and regions
    /// (`octree.min_level`, `regions`): a leaf is split while a rule asks
    /// for more (see [`crate::regions`]). Within the octant limit and the
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
            let mut buf = Vec::new();
            tree.refine(rules.max_level(), |o| rules.splits(o, &mut buf), limit)
        });
        drop(shown);
        over_budget(refined, budget, limit, "region refinement")?;
        let n = self.tree().map_or(0, |t| t.global_len());
        self.report_phase(Some(n));
        self.facts.octants_refined = n;
        self.facts.octants_balanced = n;
        self.classes = Classes::default();
        self.mesh = None;
        Ok(())
    }

    fn set_tree(&mut self, tree: LinearOctree, domain: Domain) {
        self.tree = Some((tree, domain));
        self.classes = Classes::default();
        self.mesh = None;
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
        self.timer.time(&*comm, "partition", || -> Result<()> {
            let Some(tree) = tree else { return Ok(()) };
            match &weight {
                None => tree.partition().map(|_| ()),
                Some(w) => tree.partition_weighted(w).map(|_| ()),
            }
        })?;
        let count = self.tree().map(|t| t.global_len());
        self.report_phase(count);
        self.classes = Classes::default();
        self.mesh = None;
        Ok(())
    }

    /// 2:1-balances the octree for `conn` contacts, within the octant
    /// limit (on failure the octree is as it was). Leaves stay on their
    /// ranks. Phase `balance`.
    pub fn balance(&mut self, conn: Connectivity) -> Result<()> {
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
        let balanced = self.timer.time(&*comm, "balance", || -> Result<()> {
            let Some(tree) = tree else { return Ok(()) };
            tree.balance_with_limit(conn, limit).map(|_| ())
        });
        drop(shown);
        over_budget(balanced, budget, limit, "balance")?;
        let count = self.tree().map(|t| t.global_len());
        self.report_phase(count);
        self.facts.octants_balanced = self.tree().map_or(0, |t| t.global_len());
        self.classes = Classes::default();
        self.mesh = None;
        Ok(())
    }

    /// Writes the leaves (`title` goes in the file's header line). Collective.
    pub fn write_leaves(&self, path: &Path, title: &str) -> Result<()> {
        let (tree, _) = agree(&*self.comm, self.tree_or_state())?;
        write_leaves(tree, path, title)
    }

    // ----- classification ----------------------------------------------------

    /// Sets the inside rule of the following classifications and meshes.
    pub fn set_inside_rule(&mut self, rule: InsideRule) {
        self.inside = Some(rule);
    }

    /// The rule `rule` stands for on this surface: itself, or for `auto`
    /// the choice the diagnostics make.
    fn resolve(&self, rule: InsideRule) -> Result<InsideRule> {
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

    // ----- mesh ------------------------------------------------------------------

    /// Builds the mesh of the leaves that `keep` selects, classified against
    /// the surface with the session's inside rule when there is a surface
    /// (without one only [`Keep::All`] is allowed). The octree must be
    /// balanced for edge or corner contacts. Phases `ghost`, `nodes`,
    /// `numbering`, `connectivity`.
    pub fn build_mesh(&mut self, keep: Keep, cut_rule: CutRule) -> Result<()> {
        agree(&*self.comm, self.tree_or_state().map(|_| ()))?;
        // Classes made with another rule (or only the cut bits of a leak
        // check) are redone while the surface is there.
        let rule = self.inside.unwrap_or_default();
        if self.surface.is_some() {
            let wanted = agree(&*self.comm, self.resolve(rule))?;
            if self.classes.rule != Some(wanted) {
                self.classify(rule)?;
            }
        }
        let (tree, domain) = self.tree_or_state()?;
        let classes = self.classes.rule.map(|_| self.classes.bits.as_slice());
        let shown = self.progress("mesh", None);
        let mesh = Mesh::build(tree, domain, classes, &MeshOptions { keep, cut_rule });
        drop(shown);
        let mesh = mesh?;
        self.timer.append(mesh.phase_timer());
        let c = *mesh.counts();
        for (name, seconds) in mesh.timings() {
            let count = match name.as_str() {
                "ghost" => Some(c.ghosts),
                "nodes" => Some(c.independent_nodes + c.face_hanging_nodes + c.edge_hanging_nodes),
                "connectivity" => Some(c.elements),
                _ => None,
            };
            self.observer.event(&Event::Phase {
                name,
                seconds: *seconds,
                count,
            });
        }
        let mut cells = [mesh.local_volume_cells()];
        self.comm.sum_u64(&mut cells);
        self.observer.event(&Event::Meshed {
            counts: c,
            kept_volume: mesh.cells_to_volume(cells[0]),
            surface_volume: self.surface_volume(),
        });
        self.mesh = Some(mesh);
        self.mesh_generation += 1;
        Ok(())
    }

    fn surface_volume(&self) -> f64 {
        match (&self.surface, &self.released) {
            (Some(s), _) => s.volume,
            (None, Some((_, v, _))) => *v,
            _ => 0.0,
        }
    }

    /// Writes the mesh as one binary VTU per rank and a PVTU, with the
    /// caller's point `fields` (name, one value per local node). Phase
    /// `write`.
    pub fn write_vtu(&mut self, pvtu: &Path, fields: &[(&str, &[f64])]) -> Result<()> {
        let local = self
            .mesh
            .as_ref()
            .map(|_| ())
            .ok_or_else(|| Error::new(ErrorKind::State, "there is no mesh: build it first"));
        agree(&*self.comm, local)?;
        let comm = self.comm.clone();
        let mesh = &self.mesh;
        self.timer.time(&*comm, "write", || match mesh {
            Some(m) => write_mesh(&*comm, pvtu, m, fields).map(|_| ()),
            None => Ok(()),
        })?;
        self.report_phase(None);
        self.observer.event(&Event::Wrote(pvtu));
        Ok(())
    }

    // ----- the whole run -----------------------------------------------------

    /// Runs every stage `command` needs with the session's configuration:
    /// read, refine, partition, balance, partition, the optional
    /// classification and leak check, then for meshes the mesh and its
    /// files, and finally the statistics file. The configuration must be
    /// valid ([`Config::validate`]). A leak found is returned as its error
    /// after the statistics are written.
    pub fn run(&mut self, command: Command) -> Result<Stats> {
        let level = agree(
            &*self.comm,
            self.config
                .octree
                .level
                .ok_or_else(|| Error::invalid("octree.level is required")),
        )?;
        self.inside = self.config.inside_rule(command);
        self.plan = command;
        self.load_surface()?;
        self.refine_surface(level)?;
        self.refine_curvature()?;
        self.refine_regions()?;
        self.partition()?;
        if let Some(p) = self.config.output.refined_leaves.clone() {
            self.write_leaves(&p, "refined leaves")?;
        }
        if let Some(conn) = self.config.octree.balance.connectivity() {
            self.balance(conn)?;
            self.partition()?;
        }
        if let Some(p) = self.config.output.leaves.clone() {
            self.write_leaves(&p, "balanced leaves")?;
        }
        // Leak checks need the cut bits, which parity gives cheapest.
        let point = self.config.leak.inside_point;
        if let Some(rule) = self.inside.or(point.map(|_| InsideRule::Parity)) {
            self.classify(rule)?;
        }
        if command == Command::Octree && self.config.classify.inside.is_some() {
            self.count_classes()?;
        }
        let mut leak = Ok(());
        if let Some(p) = point {
            let file = self.config.leak.path.clone();
            leak = self.check_leak(p, file.as_deref());
            if leak.as_ref().is_err_and(|e| e.kind() != ErrorKind::Leak) {
                return leak.map(|_| Stats::default());
            }
        }
        self.release_surface();
        if command == Command::Mesh && leak.is_ok() {
            let m = self.config.mesh.clone();
            self.build_mesh(m.keep, m.cut_rule)?;
            if let Some(out) = self.config.output.vtu.clone() {
                self.write_vtu(&out, &[])?;
            }
        }
        let stats = self.stats(command);
        let total: f64 = self.timer.phases().iter().map(|p| p.1).sum();
        let bytes_per_leaf = stats.peak_rss_bytes as f64 * self.comm.size() as f64
            / stats.octants_balanced.max(1) as f64;
        self.observer.event(&Event::Finished {
            seconds: total,
            peak_rss: stats.peak_rss_bytes,
            bytes_per_leaf,
        });
        if let Some(path) = self.config.output.stats.clone() {
            crate::io::json::write_json(&*self.comm, &path, &stats)?;
        }
        leak.map(|_| stats)
    }
}

/// Tells `observer` about the last phase `timer` recorded, with `count`.
fn report(timer: &PhaseTimer, observer: &mut dyn Observer, count: Option<u64>) {
    if let Some((name, seconds)) = timer.phases().last() {
        observer.event(&Event::Phase {
            name,
            seconds: *seconds,
            count,
        });
    }
}

/// Fails with the budget's error when the octree estimated at `level` does
/// not fit, naming the largest level that does.
fn check_budget(b: &MemoryBudget, index: &SurfaceIndex, level: u8) -> Result<()> {
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
fn over_budget<T>(
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
