//! The pipeline, once: a [`Session`] holds the surface, the domain, the
//! octree, the leaf classes and the mesh, with one method per stage.
//!
//! ```text
//!  load_surface ─► refine_surface ─► partition ─► balance ─► partition
//!   (read)         (construct,                  (balance)
//!                   refine)
//!      ─► classify ─► check_leak ─► build_mesh ─► snap ─► write_vtu ─► quality
//!                                   (ghost, nodes,  (when    (when asked)
//!                                    numbering,      asked)
//!                                    connectivity)
//! ```
//!
//! The `octmesh` command runs the whole sequence a [`Config`] asks for
//! ([`Session::run`]); the C handle calls the stages one by one as its user
//! does. Both see the same checks, limits, timings and errors, so a new
//! stage is added here once. Every stage is collective over the session's
//! communicator, times itself as a phase (the names of [`Event::Phase`]),
//! and tells its [`Observer`] what it did. A failed stage leaves the session
//! as it was before the call.

mod adapt;
mod checkpoint;
mod classes;
mod conforming;
mod data;
mod distributed;
mod fe;
mod mesh;
pub mod observer;
mod octree;
mod quality;
pub mod stats;
mod surface;
mod table;
mod transfer;

use std::cell::OnceCell;

use crate::classify::{InsideRule, WindingSummary};
use crate::config::{Command, Config};
use crate::error::{Error, ErrorKind, Result};
use crate::geometry::diagnostics::{diagnose, SurfaceReport};
use crate::geometry::parts::PartLocator;
use crate::geometry::{Aabb, Surface};
use crate::mesh::{Boundary, Faces, Mesh};
use crate::octree::domain::Domain;
use crate::octree::LinearOctree;
use crate::parallel::comm::{agree, CommRef};
use crate::refine::{LeafEstimate, SurfaceIndex};
use crate::run::budget::MemoryBudget;
use crate::run::progress::{self, Progress, Style};
use crate::run::report::{peak_rss_bytes, PhaseTimer};

pub use observer::{Event, Observer, Silent, VolumeReference};
use transfer::Previous;

pub use stats::Stats;
pub use table::Table;

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
    /// This rank's home share when the surface is distributed over the
    /// ranks (`index` then holds only the triangles near its leaves).
    dist: Option<distributed::Distributed>,
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
    /// Whether a leaf that is not cut passes its class to its descendants
    /// and ancestors (`classify::carry_classes`): with the parity, or the
    /// winding number of a closed surface.
    inherit: bool,
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
    /// Peak memory after the distributed surface's first redistribution.
    rss_distributed: u64,
    /// The sizes of the last gathered mesh's pieces joined through faces.
    pieces: Option<Vec<u64>>,
    /// Whether the surface was distributed over the ranks.
    distributed: bool,
    /// The most triangles this rank's surface index held.
    held: usize,
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
    /// What the current mesh kept: its leaves and cut leaves.
    mesh_kept: Option<(crate::classify::Keep, crate::classify::CutRule)>,
    timer: PhaseTimer,
    observer: Box<dyn Observer>,
    surface: Option<SurfaceState>,
    /// The surface's box and volume after [`Session::release_surface`].
    released: Option<(Aabb, f64, String)>,
    /// The hash of the last surface loaded, kept when it is released.
    surface_hash: Option<u64>,
    /// The octree and the cube it was built in.
    tree: Option<(LinearOctree, Domain)>,
    /// User data per local leaf, when attached (`data.rs`).
    data: Option<crate::octree::leaf_data::LeafData>,
    classes: Classes,
    mesh: Option<Mesh>,
    /// The mesh before the octree last changed, kept for data transfer
    /// when asked (`transfer.rs`).
    previous: Previous,
    /// The faces of the mesh of a generation.
    faces: Option<(u64, Faces)>,
    /// The finite-element boundary of the mesh of a generation.
    boundary: Option<(u64, Boundary)>,
    /// The mesh of a generation (hanging-node or conforming) gathered on rank 0 for the single-file
    /// writers (empty on the other ranks).
    gathered: Option<((u64, bool), crate::io::gathered::Gathered)>,
    /// The quality of the mesh of a generation, when measured.
    quality: Option<(u64, crate::mesh::quality::Quality)>,
    /// The snap that made the mesh of a generation.
    snapped: Option<(u64, crate::mesh::snap::SnapReport)>,
    /// The snap asked for the conforming mesh of a generation's mesh
    /// ([`Session::snap`] with `mesh.conforming`): made when it is built.
    conforming_snap: Option<(u64, crate::mesh::snap::SnapOptions)>,
    /// The boundary layers of the last OpenFOAM case written with them.
    layer_report: Option<crate::io::openfoam::LayerReport>,
    /// The named parts of the surface (patches), kept when it is released.
    parts: Vec<String>,
    /// Which part is nearest a point, for surfaces of several parts.
    locator: Option<PartLocator>,
    facts: Facts,
    /// Whether the next surface read is distributed ([`Session::run`]).
    distribute: bool,
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
            mesh_kept: None,
            config,
            timer: PhaseTimer::new(),
            observer: Box::new(Silent),
            surface: None,
            released: None,
            surface_hash: None,
            tree: None,
            classes: Classes::default(),
            mesh: None,
            previous: Previous::default(),
            faces: None,
            boundary: None,
            gathered: None,
            quality: None,
            snapped: None,
            conforming_snap: None,
            layer_report: None,
            parts: Vec::new(),
            data: None,
            locator: None,
            facts: Facts {
                rss_start: peak_rss_bytes(),
                ..Facts::default()
            },
            distribute: false,
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
        match (&self.surface, d.is_explicit()) {
            // An explicit cube or box does not depend on the surface's box.
            (_, true) => d.resolve([0.0; 3], [0.0; 3]),
            (Some(s), false) => d.resolve(s.bbox.min, s.bbox.max),
            (None, false) => Domain::cube([0.0; 3], 1.0),
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

    // ----- the whole run -----------------------------------------------------

    /// Runs every stage `command` needs with the session's configuration:
    /// read, refine, partition, balance, partition, the optional
    /// classification and leak check, then for meshes the mesh and its
    /// files, and finally the statistics file. The configuration must be
    /// valid ([`Config::validate`]). A leak found is returned as its error
    /// after the statistics are written.
    pub fn run(&mut self, command: Command) -> Result<Stats> {
        self.inside = self.config.inside_rule(command);
        self.plan = command;
        self.distribute = self.may_distribute(command);
        self.load_surface()?;
        self.distribute = false;
        if command == Command::Mesh {
            // Renames name the surface's parts: check them before the work.
            agree(&*self.comm, self.patch_names())?;
        }
        match self.config.octree.load.clone() {
            Some(p) => self.load_octree(&p)?,
            None => self.build_octree()?,
        }
        if let Some(p) = self.config.output.leaves.clone() {
            self.write_leaves(&p, "balanced leaves")?;
        }
        if let Some(p) = self.config.output.save.clone() {
            self.save_octree(&p)?;
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
        // A snap needs the surface after meshing, zones while meshing (the
        // solids they split the inside by).
        let snap = command == Command::Mesh && (self.config.mesh.snap || self.config.wall_layer());
        let zones = command == Command::Mesh && self.config.mesh.zones;
        if !snap && !zones {
            self.release_surface();
        }
        if command == Command::Mesh && leak.is_ok() {
            let m = self.config.mesh.clone();
            self.build_mesh(m.keep, m.cut_rule)?;
            if zones && !snap {
                self.release_surface();
            }
            if snap && self.config.mesh.snap {
                let foam = self.config.output.openfoam.is_some();
                self.snap(&m.snap_options(foam))?;
                self.release_surface();
            }
            if let Some(out) = self.config.output.vtu.clone() {
                self.write_vtu(&out, &[])?;
                self.write_boundary_vtp(&out)?;
            }
            if let Some(dir) = self.config.output.openfoam.clone() {
                self.write_openfoam(&dir)?;
                self.release_surface();
            }
            // One gather for every single-file mesh.
            let out = self.config.output.clone();
            let fe: Vec<(fe::FeFormat, &std::path::Path)> = [
                (fe::FeFormat::Gmsh, &out.gmsh),
                (fe::FeFormat::Abaqus, &out.abaqus),
                (fe::FeFormat::Exodus, &out.exodus),
                (fe::FeFormat::Cgns, &out.cgns),
            ]
            .into_iter()
            .filter_map(|(f, p)| p.as_deref().map(|p| (f, p)))
            .collect();
            self.write_fe_files(&fe)?;
            if self.config.output.wants_quality() {
                self.quality()?;
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

    /// The octree stages of [`Session::run`]: refine (surface, curvature,
    /// regions), partition, balance and partition again as configured.
    fn build_octree(&mut self) -> Result<()> {
        // Known now: sizes became levels once the domain was.
        // Parts with their own levels start from the least of them.
        let level = agree(
            &*self.comm,
            self.config
                .first_surface_level()
                .ok_or_else(|| Error::invalid("octree.level is required")),
        )?;
        let parts = self.config.surface_ranges(self.surface_name(), &self.parts);
        agree(&*self.comm, parts)?;
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
        Ok(())
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
