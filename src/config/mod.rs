//! The one configuration of a meshing run.
//!
//! [`Config`] holds every choice of the pipeline, grouped by stage. Three
//! front ends fill it and nothing else decides a default:
//!
//! - the command line ([`cli`], `octmesh octree|mesh ...`),
//! - a TOML case file ([`case`], `octmesh mesh case.toml`), whose tables and
//!   keys are the fields below (`octmesh mesh ... --print-case` prints the
//!   case file of a command line),
//! - the C API's `octmesh_options_t` and setters.
//!
//! A case file sets the keys it names; the rest keep their defaults:
//!
//! ```toml
//! [surface]
//! file = "bunny.stl"        # an STL file, or the built-in "sphere", "torus" or "hull"
//!
//! [octree]
//! level = 9
//!
//! [[regions]]              # as many as wanted
//! shape = "box"
//! min = [0.0, 0.0, 0.0]
//! max = [1.0, 0.5, 0.5]
//! level = 8
//!
//! [mesh]
//! keep = "outside"
//! ```
//!
//! Every option and key, with its default and range, is declared once in
//! [`options::OPTIONS`]; `docs/options.md` is generated from it.
//!
//! [`Config::validate`] checks a filled configuration for a command and
//! reports the first problem as a [`ConfigError`] naming the key, which each
//! front end turns into its own words (the option, or the file, line and
//! key).

pub mod case;
pub mod cli;
mod layers;
pub mod options;
mod reference;
mod values;

pub use layers::PatchLayers;
pub use options::{DEFAULT_FEATURE_ANGLE, DEFAULT_QUALITY_WORST};

use std::collections::BTreeMap;
use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::classify::{CutRule, InsideRule, Keep};
use crate::io::openfoam::FoamFormat;
use crate::mesh::patches::PatchNames;
use crate::octree::domain::{Domain, DEFAULT_FIT};
use crate::octree::octant::{Connectivity, MAX_LEVEL};
use crate::refine::regions::Region;
use crate::run::budget::ByteSize;

crate::named_enum! {
    /// What a run builds.
    pub enum Command: "command" {
        /// The balanced octree (and optionally its leaf classes).
        Octree = "octree",
        /// The octree, then the hexahedral mesh of the kept leaves.
        Mesh = "mesh",
    }
}

crate::named_enum! {
    /// The 2:1 balance of the octree: none, or the contacts it applies to.
    #[derive(Default)]
    pub enum Balance: "connectivity" {
        /// No balance: the leaves stay as refinement left them.
        None = "none",
        /// Leaves sharing a face.
        Face = "face",
        /// Leaves sharing a face or an edge (enough for meshing).
        Edge = "edge",
        /// Leaves sharing a face, an edge or a corner (the default).
        #[default]
        Corner = "corner" | "full",
    }
}

impl Balance {
    /// The connectivity balanced for, or `None` without balance.
    pub fn connectivity(self) -> Option<Connectivity> {
        match self {
            Balance::None => None,
            Balance::Face => Some(Connectivity::Face),
            Balance::Edge => Some(Connectivity::Edge),
            Balance::Corner => Some(Connectivity::Corner),
        }
    }
}

/// Every choice of a run. `Config::default()` holds the defaults, and only
/// it does.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    /// The surface and its clean-up.
    pub surface: SurfaceConfig,
    /// The root cube.
    pub domain: DomainConfig,
    /// Refinement, balance and limits.
    pub octree: OctreeConfig,
    /// Inside/outside classification of the leaves.
    pub classify: ClassifyConfig,
    /// The leak check of a fluid region.
    pub leak: LeakConfig,
    /// Which leaves become elements.
    pub mesh: MeshConfig,
    /// Refinement regions (`[[regions]]` tables: `shape = "box"` with `min`,
    /// `max`; `"sphere"` with `center`, `radius`; `"cylinder"` with `start`,
    /// `end`, `radius`; each with `level` and optionally `outside = true`).
    pub regions: Vec<Region>,
    /// Boundary layers per wall patch (`[[layers]]` tables: `patch` with
    /// any of `layers`, `expansion`, `first_layer`, `final_layer`,
    /// `thickness`; the rest from `[mesh]`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub layers: Vec<PatchLayers>,
    /// Files written and what is printed.
    pub output: OutputConfig,
}

/// `[surface]`: what is meshed.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SurfaceConfig {
    /// An STL file (ASCII or binary), or the built-in `sphere` (radius 1 at
    /// the origin, 20,480 triangles), `torus` or `hull` (a Wigley hull).
    pub file: String,
    /// More surfaces meshed together with `file` (STL files or built-in
    /// names, `--surface`): each file is a part of the surface (a patch of
    /// its own, with its own levels through `octree.surface_levels`), named
    /// after its stem, or its solids when it names them.
    pub others: Vec<String>,
    /// Remove zero-area facets right after loading.
    pub drop_degenerate: bool,
    /// Remove facets with the same (welded) vertices as an earlier facet.
    pub drop_duplicates: bool,
    /// On several ranks, each rank keeps only the triangles near its part of
    /// the domain (where the run allows it; see `Session::run`).
    pub distributed: bool,
}

/// `[domain]`: the root cube, fitted around the surface or given, or a box
/// of cubic root cells.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DomainConfig {
    /// Longest side of the surface's bounding box as a fraction of the cube
    /// side, in (0, 1]; the cube is centred on the box. Unset: 0.7, unless
    /// `cube` is given.
    pub fit: Option<f64>,
    /// An explicit cube `[x, y, z, side]`: lowest corner and side, user
    /// units. Excludes `fit`.
    pub cube: Option<[f64; 4]>,
    /// A box `[x0, y0, z0, x1, y1, z1]` (lowest and highest corner, user
    /// units) split into `roots` cubic root cells, each a tree of the
    /// forest (like a blockMesh background). Excludes `fit` and `cube`.
    #[serde(rename = "box")]
    pub bbox: Option<[f64; 6]>,
    /// Root cells of `box` along x, y and z (unset: 1 x 1 x 1). Levels
    /// count from them: a leaf at level `l` has side `2^-l` of a root cell.
    pub roots: Option<[u32; 3]>,
}

impl DomainConfig {
    /// The fit used when no cube is given.
    pub fn fit(&self) -> f64 {
        self.fit.unwrap_or(DEFAULT_FIT)
    }

    /// The root cube for a surface with bounding box `min..max`.
    pub fn resolve(&self, min: [f64; 3], max: [f64; 3]) -> crate::Result<Domain> {
        if let Some(b) = self.bbox {
            let roots = self.roots.unwrap_or([1, 1, 1]);
            return Domain::brick([b[0], b[1], b[2]], [b[3], b[4], b[5]], roots);
        }
        match self.cube {
            Some([x, y, z, s]) => Domain::cube([x, y, z], s),
            None => Domain::around(min, max, self.fit()),
        }
    }

    /// Whether the domain does not depend on the surface (a cube or a box
    /// is given).
    pub fn is_explicit(&self) -> bool {
        self.cube.is_some() || self.bbox.is_some()
    }
}

/// `[octree]`: refinement and balance.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OctreeConfig {
    /// Level of the leaves touching the surface, 0 to 18 (required). A
    /// leaf at level `l` has side `2^-l` of the cube.
    pub level: Option<u8>,
    /// With curvature refinement: leaves touching the surface are refined
    /// further, up to this level, where the normals of the triangles
    /// touching them differ by more than `feature_angle` (`--level
    /// MIN:MAX`). Unset: every surface leaf at `level`.
    pub max_level: Option<u8>,
    /// The feature angle of curvature refinement, degrees, in (0, 180)
    /// (unset: [`DEFAULT_FEATURE_ANGLE`]).
    pub feature_angle: Option<f64>,
    /// Levels per part of the surface, `{ name = [min, max] }` (`--surface-level
    /// NAME=MIN[:MAX]`): leaves touching the part get `min`, and up to `max`
    /// where it curves (as `level` and `max_level` do for the parts not
    /// named). Names are the surface's patch names before renames: the
    /// solids of an ASCII STL file, or the file stem.
    pub surface_levels: BTreeMap<String, [u8; 2]>,
    /// Every leaf at least this level (default 0).
    pub min_level: u8,
    /// The surface level as a cell size in user units instead of
    /// `level` (cfMesh style): the coarsest level whose cell is not larger
    /// (`--size S`).
    pub size: Option<f64>,
    /// `max_level` as a cell size (`--size S:FINE`).
    pub max_size: Option<f64>,
    /// `min_level` as a cell size: every leaf at most this large
    /// (`--min-size S`).
    pub min_size: Option<f64>,
    /// Distance bands around the surface, `[[distance, level], ...]` with
    /// increasing distances (user units): a leaf is refined while its level
    /// is below a band's and its box comes within the band's distance of
    /// the surface (exact distances).
    pub distance: Vec<(f64, u8)>,
    /// `distance` with cell sizes in user units instead of levels,
    /// `[[distance, size], ...]` (`--distance-size`): each size becomes the
    /// coarsest level whose cell is not larger. Excludes `distance`.
    pub distance_size: Vec<(f64, f64)>,
    /// 2:1 balance (default corner).
    pub balance: Balance,
    /// Stop with an error instead of building more leaves than this, over
    /// all ranks (refinement and balance); refused before refining when the
    /// estimate is above twice the limit. Unset: no limit.
    pub max_octants: Option<u64>,
    /// Memory each rank may use, in bytes or with a unit (`"4GiB"`): a run
    /// expected to need more stops before refining, and one that grows past
    /// it stops before allocating (see [`crate::run::budget`]). Unset: the
    /// node's available memory shared among its ranks.
    pub memory_budget: Option<ByteSize>,
    /// Take the octree of this checkpoint (written by `output.save`)
    /// instead of refining: the surface is still read, to classify the
    /// leaves, and must be the one the checkpoint was saved from.
    pub load: Option<PathBuf>,
}

impl OctreeConfig {
    /// The feature angle of curvature refinement, degrees.
    pub fn feature_angle(&self) -> f64 {
        self.feature_angle.unwrap_or(DEFAULT_FEATURE_ANGLE)
    }

    /// The octant limit, [`crate::refine::NO_LIMIT`] when unset.
    pub fn limit(&self) -> u64 {
        self.max_octants.unwrap_or(crate::refine::NO_LIMIT)
    }
}

/// `[classify]`: how leaf centres are found inside the surface.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ClassifyConfig {
    /// `parity`, `winding` or `auto`. Meshes always classify (unset: auto);
    /// octrees classify and count the leaves per class only when it is set.
    pub inside: Option<InsideRule>,
}

/// `[leak]`: does the outside region reach a point inside the body?
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LeakConfig {
    /// A point inside the body, user units: after balance, the run stops
    /// with a leak report if the region outside the surface reaches it
    /// through leaves touching no triangle.
    pub inside_point: Option<[f64; 3]>,
    /// Where to write a leak's path: `.vtk` for legacy VTK lines, any other
    /// name for CSV `step,x,y,z,size,level`. Needs `inside_point`.
    pub path: Option<PathBuf>,
}

/// `[mesh]`: which leaves become elements.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MeshConfig {
    /// `all`, `inside` (solid) or `outside` (fluid).
    pub keep: Keep,
    /// For inside or outside: leaves touching the surface are kept when
    /// their centre is on the kept side (`center`), always (`all`) or never
    /// (`none`).
    pub cut_rule: CutRule,
    /// Patch renames, `{ default name = new name }`: the sides are `xmin
    /// xmax ymin ymax zmin zmax`, the surface is named after its file's
    /// stem (also reachable as `surface`). Names follow OpenFOAM's word
    /// rules and must be unique.
    pub patches: BTreeMap<String, String>,
    /// Drop kept leaves that touch the rest only along an edge or at a
    /// corner, or have kept neighbours along fewer than three axes, so the
    /// walls are manifold (see [`crate::mesh::manifold`]). Unset: on when
    /// writing an OpenFOAM case.
    pub clean_walls: Option<bool>,
    /// Snap the mesh to the surface ([`crate::mesh::snap`]): the nodes on
    /// the surface patch move onto it, where every element stays valid.
    /// Needs `keep` inside or outside.
    pub snap: bool,
    /// Surface edges whose facets' normals differ by more than this
    /// (degrees, 0 to 180) are features the snapped mesh keeps.
    pub snap_feature_angle: f64,
    /// Element layers around the surface nodes that the snap relaxes.
    pub snap_layers: u32,
    /// Relaxation iterations of the snap.
    pub snap_iterations: u32,
    /// The least scaled Jacobian an element's corner may have after the
    /// snap, in (0, 0.5]. Unset: 0.1 when writing an OpenFOAM case (what
    /// keeps `checkMesh`'s skewness below 4), else 0.001.
    pub snap_min_jacobian: Option<f64>,
    /// Mark every element with a zone ([`crate::mesh::zones`]): `inside`
    /// or `outside` of the surface by its centre, or the zone of the last
    /// region (`[[regions]]` with `zone = "name"`) holding its centre.
    /// Needs `keep` all.
    pub zones: bool,
    /// Write the single-file finite-element meshes (`gmsh`, `abaqus`,
    /// `exodus`, `cgns`), the OpenFOAM case (serial) and the VTU (rank 0's
    /// piece) as conforming all-hexahedral meshes, and measure their
    /// `quality`
    /// ([`crate::mesh::conforming`]): no hanging nodes, every inner face
    /// shared whole by two elements.
    pub conforming: bool,
    /// Add a layer of cells between the staircase and the surface when
    /// writing the OpenFOAM case ([`crate::io::openfoam`]): every wall
    /// point on the surface, no old cell with a face on the wall. Needs
    /// `keep` inside or outside, `cut_rule` none and an OpenFOAM case as
    /// the only mesh output; replaces `snap`.
    pub wall_layer: bool,
    /// Boundary layers on every wall patch (`[[layers]]` tables set them
    /// per patch): this many cells on each wall face in the wall layer's
    /// room, growing by `layer_expansion` away from the wall. Implies
    /// `wall_layer` and its needs.
    pub layers: Option<u32>,
    /// Each boundary layer's height over the one before it (> 0).
    pub layer_expansion: f64,
    /// The first boundary layer's height (the one on the wall). One of
    /// `first_layer`, `final_layer` and `layer_thickness` gives the
    /// thickness.
    pub first_layer: Option<f64>,
    /// The last boundary layer's height (the farthest from the wall).
    pub final_layer: Option<f64>,
    /// All boundary layers together.
    pub layer_thickness: Option<f64>,
    /// The layer thicknesses are fractions (below 1) of the local wall
    /// cell's side, not lengths in the surface's units.
    pub relative_sizes: bool,
}

impl MeshConfig {
    /// The snap's options; `foam`: an OpenFOAM case is written.
    pub fn snap_options(&self, foam: bool) -> crate::mesh::snap::SnapOptions {
        use crate::mesh::snap::{DEFAULT_MIN_JACOBIAN, FOAM_MIN_JACOBIAN};
        let j = if foam {
            FOAM_MIN_JACOBIAN
        } else {
            DEFAULT_MIN_JACOBIAN
        };
        crate::mesh::snap::SnapOptions {
            feature_angle_deg: self.snap_feature_angle,
            layers: self.snap_layers,
            iterations: self.snap_iterations,
            min_jacobian: self.snap_min_jacobian.unwrap_or(j),
        }
    }
}

impl Default for MeshConfig {
    fn default() -> MeshConfig {
        MeshConfig {
            keep: Keep::All,
            cut_rule: CutRule::default(),
            patches: BTreeMap::new(),
            clean_walls: None,
            snap: false,
            snap_feature_angle: crate::mesh::snap::DEFAULT_FEATURE_ANGLE,
            snap_layers: crate::mesh::snap::DEFAULT_LAYERS,
            snap_iterations: crate::mesh::snap::DEFAULT_ITERATIONS,
            snap_min_jacobian: None,
            zones: false,
            conforming: false,
            wall_layer: false,
            layers: None,
            layer_expansion: 1.0,
            first_layer: None,
            final_layer: None,
            layer_thickness: None,
            relative_sizes: false,
        }
    }
}

/// `[output]`: files and printing.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OutputConfig {
    /// Print nothing but errors.
    pub quiet: bool,
    /// JSON statistics: counts, timings (seconds, max over ranks), peak
    /// memory, bytes exchanged per phase.
    pub stats: Option<PathBuf>,
    /// The balanced leaves, one `x y z level` per line in lattice units
    /// (`.bin`: binary).
    pub leaves: Option<PathBuf>,
    /// The leaves before balance, same format.
    pub refined_leaves: Option<PathBuf>,
    /// An octree checkpoint of the balanced octree and its domain, one file
    /// written by all ranks ([`crate::octree::checkpoint`]).
    pub save: Option<PathBuf>,
    /// The mesh: one binary VTU per rank and a PVTU (a name ending in
    /// `.pvtu`).
    pub vtu: Option<PathBuf>,
    /// An OpenFOAM case directory: `constant/polyMesh` on one rank,
    /// `processor<r>/constant/polyMesh` on several, and the `system/` files
    /// that are absent.
    pub openfoam: Option<PathBuf>,
    /// One Gmsh MSH 4.1 file of the mesh ([`crate::io::gmsh`]).
    pub gmsh: Option<PathBuf>,
    /// One Abaqus/CalculiX input file of the mesh ([`crate::io::abaqus`]).
    pub abaqus: Option<PathBuf>,
    /// One Exodus II file of the mesh ([`crate::io::exodus`]).
    pub exodus: Option<PathBuf>,
    /// One CGNS file of the mesh ([`crate::io::cgns`]).
    pub cgns: Option<PathBuf>,
    /// `binary` (default) or `ascii` lists in the OpenFOAM files.
    pub openfoam_format: FoamFormat,
    /// Replace an existing OpenFOAM mesh.
    pub overwrite: bool,
    /// Measure the mesh's quality ([`crate::mesh::quality`]): the figures
    /// in the run's table and `stats` (`--quality`). Off by default: it
    /// costs about two node extractions.
    pub quality: bool,
    /// Measure the mesh's quality and write the `quality_worst` elements
    /// with the smallest scaled Jacobians to this VTU file (a name ending in
    /// `.vtu`).
    pub quality_out: Option<PathBuf>,
    /// How many elements `quality_out` holds, at least 1 (unset: 100).
    pub quality_worst: Option<u64>,
}

impl OutputConfig {
    /// The elements written to `quality_out`.
    pub fn quality_worst(&self) -> u64 {
        self.quality_worst.unwrap_or(DEFAULT_QUALITY_WORST)
    }

    /// Whether a run measures the mesh's quality: asked for, or for the
    /// worst elements' file.
    pub fn wants_quality(&self) -> bool {
        self.quality || self.quality_out.is_some()
    }
}

/// A problem with one key of a configuration. `message` follows the key's
/// name ("must be ...", "is required") or, when it starts with "unknown",
/// stands after a colon; `{table.key}` in it names another key.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ConfigError {
    /// The key, `table.field` (e.g. `domain.fit`).
    pub key: &'static str,
    /// What is wrong.
    pub message: String,
}

impl ConfigError {
    fn new(key: &'static str, message: impl Into<String>) -> ConfigError {
        ConfigError {
            key,
            message: message.into(),
        }
    }

    /// The message with keys named by `label` (an option, or a case
    /// file's key).
    pub fn render(&self, label: impl Fn(&str) -> String) -> String {
        let mut text = self.message.clone();
        for key in options::keys() {
            text = text.replace(&format!("{{{key}}}"), &label(key));
        }
        let sep = if text.starts_with("unknown") {
            ": "
        } else {
            " "
        };
        format!("{}{sep}{text}", label(self.key))
    }
}

impl Config {
    /// Whether the run writes a mesh for a solver (OpenFOAM, Gmsh,
    /// Abaqus/CalculiX, Exodus II, CGNS), which turns `--clean-walls` on
    /// unless it is set: a solver needs walls it can take and a mesh in one
    /// piece.
    pub fn writes_solver_mesh(&self) -> bool {
        let o = &self.output;
        o.openfoam.is_some()
            || o.gmsh.is_some()
            || o.abaqus.is_some()
            || o.exodus.is_some()
            || o.cgns.is_some()
    }

    /// Checks the configuration for `command`: required keys, ranges,
    /// consistency. Rank-local (every rank checks the same values).
    pub fn validate(&self, command: Command) -> Result<(), ConfigError> {
        if self.surface.file.is_empty() {
            return Err(ConfigError::new(
                "surface.file",
                "is required: no surface given",
            ));
        }
        self.check_sizes()?;
        if self.octree.level.is_none() && self.octree.size.is_some() {
            // The levels follow once the domain is known
            // (`Config::with_sizes`); the rest is checked then.
            return Ok(());
        }
        let Some(level) = self.octree.level else {
            if self.octree.load.is_some() {
                // The checkpoint holds the octree: no level is needed.
                return options::check_ranges(self, command == Command::Mesh);
            }
            return Err(ConfigError::new("octree.level", "is required"));
        };
        options::check_ranges(self, command == Command::Mesh)?;
        if let Some(max) = self.octree.max_level {
            if max > MAX_LEVEL || max < level {
                return Err(ConfigError::new(
                    "octree.max_level",
                    format!(
                        "is {max}: it must be between {{octree.level}} ({level}) and {MAX_LEVEL}"
                    ),
                ));
            }
        }
        for (name, &[min, max]) in &self.octree.surface_levels {
            if min > max || max > MAX_LEVEL {
                return Err(ConfigError::new(
                    "octree.surface_levels",
                    format!(
                        "gives '{name}' the levels {min} to {max}: the minimum must not be above \
                         the maximum, nor the maximum above {MAX_LEVEL}"
                    ),
                ));
            }
        }
        let bands = &self.octree.distance;
        if let Some((i, &(d, l))) = bands.iter().enumerate().find(|(i, &(d, l))| {
            !(d.is_finite() && d >= 0.0) || l > MAX_LEVEL || (*i > 0 && d <= bands[i - 1].0)
        }) {
            return Err(ConfigError::new(
                "octree.distance",
                format!(
                    "band {} ({d}, level {l}) is invalid: distances must be finite, non-negative \
                     and increasing, levels at most {MAX_LEVEL}",
                    i + 1
                ),
            ));
        }
        for (i, r) in self.regions.iter().enumerate() {
            if let Err(m) = r.validate() {
                return Err(ConfigError::new(
                    "regions",
                    format!("number {} ({}) {m}", i + 1, r.shape()),
                ));
            }
        }
        if self.domain.fit.is_some() && self.domain.cube.is_some() {
            return Err(ConfigError::new(
                "domain.fit",
                "and {domain.cube} exclude each other: give one",
            ));
        }
        if let Some([x, y, z, s]) = self.domain.cube {
            if let Err(e) = Domain::cube([x, y, z], s) {
                return Err(ConfigError::new("domain.cube", format!("is invalid: {e}")));
            }
        }
        self.check_box(level)?;
        if let Some(p) = self.leak.inside_point {
            if p.iter().any(|c| !c.is_finite()) {
                return Err(ConfigError::new(
                    "leak.inside_point",
                    format!("must be finite, got {p:?}"),
                ));
            }
        } else if self.leak.path.is_some() {
            return Err(ConfigError::new("leak.path", "needs {leak.inside_point}"));
        }
        if command == Command::Mesh {
            if !matches!(self.octree.balance, Balance::Edge | Balance::Corner) {
                return Err(ConfigError::new(
                    "octree.balance",
                    format!(
                        "must be edge or corner for meshing (got {}): with face balance alone a \
                         hanging node may depend on another hanging node",
                        self.octree.balance
                    ),
                ));
            }
            if let Some(v) = &self.output.vtu {
                if v.extension().is_none_or(|e| e != "pvtu") {
                    return Err(ConfigError::new(
                        "output.vtu",
                        format!("expects a file name ending in .pvtu, got '{}'", v.display()),
                    ));
                }
            }
            if let Some(q) = &self.output.quality_out {
                if q.extension().is_none_or(|e| e != "vtu") {
                    return Err(ConfigError::new(
                        "output.quality_out",
                        format!("expects a file name ending in .vtu, got '{}'", q.display()),
                    ));
                }
            }
            if self.output.quality_worst.is_some() && self.output.quality_out.is_none() {
                return Err(ConfigError::new(
                    "output.quality_worst",
                    "needs {output.quality_out}",
                ));
            }
            if self.mesh.zones && self.mesh.keep != Keep::All {
                return Err(ConfigError::new(
                    "mesh.zones",
                    format!(
                        "needs {{mesh.keep}} all (got {}): zones divide the whole domain, \
                         the inside and the outside together",
                        self.mesh.keep.name()
                    ),
                ));
            }
            if self.mesh.conforming && self.wall_layer() {
                let key = match self.mesh.wall_layer {
                    true => "mesh.wall_layer",
                    false => self.layers_key(),
                };
                return Err(ConfigError::new(
                    "mesh.conforming",
                    format!(
                        "does not take {{{key}}} yet: the layers are made in the hanging-node \
                             mesh's OpenFOAM case"
                    ),
                ));
            }
            if self.wall_layer() {
                self.check_wall_layer()?;
                self.check_layers()?;
            }
            if self.mesh.snap && self.mesh.keep == Keep::All {
                return Err(ConfigError::new(
                    "mesh.snap",
                    "needs {mesh.keep} inside or outside: with all leaves kept no node is on the surface",
                ));
            }
            // The patches renamed must exist, which only the surface's
            // parts tell (checked once it is read); the new names are
            // checked here.
            for (i, (_, to)) in self.mesh.patches.iter().enumerate() {
                if let Err(e) = crate::mesh::patches::check_word(to) {
                    return Err(ConfigError::new("mesh.patches", e.message().to_string()));
                }
                if self.mesh.patches.values().take(i).any(|t| t == to) {
                    return Err(ConfigError::new(
                        "mesh.patches",
                        format!("two patches are renamed '{to}': names must be unique"),
                    ));
                }
            }
        }
        Ok(())
    }

    /// The wall layer's needs: a wall, the staircase kept off the surface,
    /// an OpenFOAM case and no other mesh output (only the OpenFOAM writer
    /// makes the layer).
    fn check_wall_layer(&self) -> Result<(), ConfigError> {
        let key = match self.mesh.wall_layer {
            true => "mesh.wall_layer",
            false => self.layers_key(),
        };
        if self.mesh.keep == Keep::All {
            return Err(ConfigError::new(
                key,
                "needs {mesh.keep} inside or outside: with all leaves kept there is no wall",
            ));
        }
        if self.mesh.cut_rule != CutRule::None {
            return Err(ConfigError::new(
                key,
                format!(
                    "needs {{mesh.cut_rule}} none (got {}): the layer fills the room between \
                     the surface and the staircase kept off it",
                    self.mesh.cut_rule.name()
                ),
            ));
        }
        if self.mesh.snap {
            return Err(ConfigError::new(
                key,
                "and {mesh.snap} exclude each other: the layer puts the wall on the surface",
            ));
        }
        if self.output.openfoam.is_none() {
            return Err(ConfigError::new(
                key,
                "needs {output.openfoam}: only the OpenFOAM case gets the layer",
            ));
        }
        let o = &self.output;
        for (other, given) in [
            ("{output.vtu}", o.vtu.is_some()),
            ("{output.gmsh}", o.gmsh.is_some()),
            ("{output.abaqus}", o.abaqus.is_some()),
            ("{output.exodus}", o.exodus.is_some()),
            ("{output.cgns}", o.cgns.is_some()),
        ] {
            if given {
                return Err(ConfigError::new(
                    key,
                    format!(
                        "is made by the OpenFOAM writer only: {other} would get the mesh \
                         without it; write it in a separate run"
                    ),
                ));
            }
        }
        Ok(())
    }

    /// A box excludes the other domain keys, divides into cubic root cells,
    /// and leaves room below its trees for the levels asked for.
    fn check_box(&self, level: u8) -> Result<(), ConfigError> {
        let d = &self.domain;
        let Some(b) = d.bbox else {
            return match d.roots {
                Some(_) => Err(ConfigError::new("domain.roots", "needs {domain.box}")),
                None => Ok(()),
            };
        };
        for (other, given) in [
            ("{domain.fit}", d.fit.is_some()),
            ("{domain.cube}", d.cube.is_some()),
        ] {
            if given {
                return Err(ConfigError::new(
                    "domain.box",
                    format!("and {other} exclude each other: give one"),
                ));
            }
        }
        let roots = d.roots.unwrap_or([1, 1, 1]);
        let brick = crate::octree::brick::Brick::new(roots)
            .map_err(|e| ConfigError::new("domain.roots", format!("is invalid: {e}")))?;
        Domain::brick([b[0], b[1], b[2]], [b[3], b[4], b[5]], roots)
            .map_err(|e| ConfigError::new("domain.box", format!("is invalid: {e}")))?;
        let o = &self.octree;
        let deepest = [
            ("octree.level", level),
            ("octree.max_level", o.max_level.unwrap_or(0)),
            ("octree.min_level", o.min_level),
        ]
        .into_iter()
        .chain(
            o.surface_levels
                .values()
                .map(|r| ("octree.surface_levels", r[1])),
        )
        .chain(o.distance.iter().map(|b| ("octree.distance", b.1)))
        .chain(self.regions.iter().map(|r| ("regions", r.level())))
        .max_by_key(|k| k.1);
        let most = brick.max_user_level();
        match deepest {
            Some((key, l)) if l > most => Err(ConfigError::new(
                key,
                format!(
                    "asks for level {l}: with {}x{}x{} root cells the trees are at level {} of \
                     the lattice, so levels go up to {most}",
                    roots[0],
                    roots[1],
                    roots[2],
                    brick.level()
                ),
            )),
            _ => Ok(()),
        }
    }

    /// Every surface file: `surface.file`, then `surface.others`.
    pub fn surface_files(&self) -> Vec<String> {
        std::iter::once(self.surface.file.clone())
            .chain(self.surface.others.iter().cloned())
            .collect()
    }

    /// Whether any level is given as a size.
    pub fn has_sizes(&self) -> bool {
        let o = &self.octree;
        o.size.is_some()
            || o.max_size.is_some()
            || o.min_size.is_some()
            || !o.distance_size.is_empty()
            || self.regions.iter().any(|r| r.size().is_some())
    }

    /// Sizes are positive, finite, each exclusive with its level, and the
    /// fine size not larger than the surface size.
    fn check_sizes(&self) -> Result<(), ConfigError> {
        let o = &self.octree;
        let sizes = [
            ("octree.size", o.size),
            ("octree.max_size", o.max_size),
            ("octree.min_size", o.min_size),
        ];
        for (key, v) in sizes {
            if let Some(v) = v.filter(|v| !(v.is_finite() && *v > 0.0)) {
                return Err(ConfigError::new(
                    key,
                    format!("must be a positive size, got {v}"),
                ));
            }
        }
        let clash = [
            (
                "octree.size",
                o.size.is_some() && o.level.is_some(),
                "{octree.level}",
            ),
            (
                "octree.max_size",
                o.max_size.is_some() && o.max_level.is_some(),
                "{octree.max_level}",
            ),
            (
                "octree.min_size",
                o.min_size.is_some() && o.min_level > 0,
                "{octree.min_level}",
            ),
        ];
        if let Some((key, _, other)) = clash.iter().find(|c| c.1) {
            return Err(ConfigError::new(
                key,
                format!("excludes {other}: give one of them"),
            ));
        }
        let bands = &o.distance_size;
        if let Some((i, &(d, c))) = bands.iter().enumerate().find(|(i, &(d, c))| {
            !(d.is_finite() && d >= 0.0 && c.is_finite() && c > 0.0)
                || (*i > 0 && d <= bands[i - 1].0)
        }) {
            return Err(ConfigError::new(
                "octree.distance_size",
                format!(
                    "band {} ({d}, size {c}) is invalid: distances must be finite, non-negative \
                     and increasing, sizes positive",
                    i + 1
                ),
            ));
        }
        if !bands.is_empty() && !o.distance.is_empty() {
            return Err(ConfigError::new(
                "octree.distance_size",
                "excludes {octree.distance}: give one of them",
            ));
        }
        if o.max_size.is_some() && o.size.is_none() {
            return Err(ConfigError::new("octree.max_size", "needs {octree.size}"));
        }
        if let (Some(s), Some(f)) = (o.size, o.max_size) {
            if f > s {
                return Err(ConfigError::new(
                    "octree.max_size",
                    format!("has a finest size {f} larger than the surface size {s}"),
                ));
            }
        }
        Ok(())
    }

    /// The configuration with its sizes turned into levels for root cells
    /// of side `side` (user units; the cube's side for a cube): each the
    /// coarsest level whose cell is not larger than the size. Unchanged
    /// without sizes.
    pub fn with_sizes(&self, side: f64) -> crate::Result<Config> {
        let mut c = self.clone();
        let o = &mut c.octree;
        let level = |s: f64| crate::refine::regions::level_for_size(side, s);
        if let Some(s) = o.size.take() {
            o.level = Some(level(s)?);
        }
        if let Some(s) = o.max_size.take() {
            o.max_level = Some(level(s)?);
        }
        if let Some(s) = o.min_size.take() {
            o.min_level = level(s)?;
        }
        for (d, s) in std::mem::take(&mut o.distance_size) {
            o.distance.push((d, level(s)?));
        }
        for r in &mut c.regions {
            *r = r.sized(side)?;
        }
        Ok(c)
    }

    /// The surface level the first refinement goes to: `octree.level`, or
    /// the least minimum of `octree.surface_levels` when lower (the parts'
    /// own levels then come from [`Config::surface_ranges`]).
    pub fn first_surface_level(&self) -> Option<u8> {
        let least = self.octree.surface_levels.values().map(|r| r[0]).min();
        match (self.octree.level, least) {
            (Some(l), Some(m)) => Some(l.min(m)),
            (l, _) => l,
        }
    }

    /// The `(min, max)` levels of each part of a surface called `surface`
    /// with named `parts` (one range when it has fewer than two parts):
    /// `octree.surface_levels` where it names the part, else `octree.level`
    /// to `octree.max_level`. A name that is no part of the surface is an
    /// error listing the names there are.
    pub fn surface_ranges(&self, surface: &str, parts: &[String]) -> crate::Result<Vec<(u8, u8)>> {
        let o = &self.octree;
        let level = o.level.unwrap_or(0);
        let default = (level, o.max_level.unwrap_or(level).max(level));
        let names = PatchNames::with_parts(surface, parts);
        let surface_names = &names.names()[crate::mesh::faces::SURFACE_PATCH as usize..];
        let mut ranges = vec![default; surface_names.len()];
        for (name, &[min, max]) in &o.surface_levels {
            let Some(p) = surface_names.iter().position(|n| n == name) else {
                return Err(crate::Error::invalid(format!(
                    "octree.surface_levels names '{name}', which is no part of the surface (its \
                     parts: {})",
                    surface_names.join(", ")
                )));
            };
            ranges[p] = (min, max);
        }
        Ok(ranges)
    }

    /// The patch names for a surface called `surface` (a file or a
    /// built-in name) with named `parts` (none for most files), renamed by
    /// `mesh.patches`.
    pub fn patch_names_for(&self, surface: &str, parts: &[String]) -> crate::Result<PatchNames> {
        PatchNames::with_parts(surface, parts).renamed(
            self.mesh
                .patches
                .iter()
                .map(|(a, b)| (a.as_str(), b.as_str())),
        )
    }

    /// The inside rule the run classifies with: the configured one, `auto`
    /// for meshes when unset, none for octrees when unset.
    pub fn inside_rule(&self, command: Command) -> Option<InsideRule> {
        match command {
            Command::Mesh => Some(self.classify.inside.unwrap_or_default()),
            Command::Octree => self.classify.inside,
        }
    }

    /// The configuration with every default that applies made explicit
    /// (`domain.fit` when no cube is given), as `--print-case` shows it.
    pub fn resolved(&self) -> Config {
        let mut c = self.clone();
        if !c.domain.is_explicit() {
            c.domain.fit = Some(c.domain.fit());
        }
        c
    }

    /// The TOML case file of this configuration.
    pub fn to_toml(&self) -> String {
        // Serialising plain data to TOML cannot fail: no maps with
        // non-string keys, no values TOML lacks.
        toml::to_string(self).unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sphere(level: u8) -> Config {
        let mut c = Config::default();
        c.surface.file = "sphere".into();
        c.octree.level = Some(level);
        c
    }

    #[test]
    fn validation_names_the_key() {
        assert!(sphere(5).validate(Command::Mesh).is_ok());
        let e = sphere(19).validate(Command::Octree).unwrap_err();
        assert_eq!(e.key, "octree.level");
        assert!(e
            .render(|k| k.to_string())
            .contains("above the maximum level 18"));
        let mut c = sphere(4);
        c.domain.fit = Some(0.5);
        c.domain.cube = Some([0.0, 0.0, 0.0, 1.0]);
        let e = c.validate(Command::Octree).unwrap_err();
        let text = e.render(|k| format!("<{k}>"));
        assert_eq!(
            text,
            "<domain.fit> and <domain.cube> exclude each other: give one"
        );
        let mut c = sphere(4);
        c.octree.balance = Balance::Face;
        assert!(c.validate(Command::Octree).is_ok());
        let e = c.validate(Command::Mesh).unwrap_err();
        assert!(e.message.contains("edge or corner"), "{e:?}");
        let mut c = sphere(4);
        c.leak.path = Some("x.vtk".into());
        let e = c.validate(Command::Octree).unwrap_err();
        assert_eq!(
            e.render(|k| k.to_string()),
            "leak.path needs leak.inside_point"
        );
    }

    #[test]
    fn conforming_takes_quality_vtu_and_snap_but_not_the_wall_layer() {
        let mut c = sphere(4);
        c.mesh.conforming = true;
        c.output.vtu = Some("m.pvtu".into());
        c.output.quality = true;
        c.output.quality_out = Some("w.vtu".into());
        assert!(c.validate(Command::Mesh).is_ok());
        c.mesh.keep = Keep::Inside;
        c.mesh.snap = true;
        assert!(c.validate(Command::Mesh).is_ok());
        c.mesh.snap = false;
        c.output.vtu = None;
        c.mesh.cut_rule = CutRule::None;
        c.mesh.wall_layer = true;
        c.output.openfoam = Some("case".into());
        let e = c.validate(Command::Mesh).unwrap_err();
        assert_eq!(e.key, "mesh.conforming");
        assert!(
            e.render(|k| k.to_string()).contains("mesh.wall_layer"),
            "{e:?}"
        );
    }

    #[test]
    fn toml_round_trip_keeps_every_field() {
        let mut c = sphere(7);
        c.domain.cube = Some([-2.0, -2.0, -2.0, 4.0]);
        c.octree.balance = Balance::Edge;
        c.octree.max_octants = Some(123_456);
        c.octree.memory_budget = Some(crate::run::budget::ByteSize(3 << 30));
        c.classify.inside = Some(InsideRule::Winding);
        c.leak.inside_point = Some([0.0, 0.1, 0.2]);
        c.leak.path = Some("leak.csv".into());
        c.mesh.keep = Keep::Outside;
        c.mesh.cut_rule = CutRule::None;
        c.mesh.snap = true;
        c.mesh.snap_feature_angle = 45.0;
        c.mesh.snap_layers = 3;
        c.mesh.snap_iterations = 7;
        c.mesh.snap_min_jacobian = Some(0.2);
        c.output.stats = Some("s.json".into());
        c.output.vtu = Some("m.pvtu".into());
        c.surface.drop_duplicates = true;
        c.octree.min_level = 2;
        c.regions = vec![
            Region::parse("box:0,0,0,1,1,1:5").unwrap(),
            Region::parse("cylinder:0,0,0,1,0,0,0.5:4:outside").unwrap(),
            Region::parse("sphere:0,0,0,1:size=0.125").unwrap(),
        ];
        c.octree.distance_size = vec![(0.1, 0.05), (0.3, 0.1)];
        c.octree.surface_levels.insert("wing".into(), [6, 8]);
        c.domain.bbox = Some([0.0, 0.0, 0.0, 3.0, 1.0, 1.0]);
        c.domain.roots = Some([3, 1, 1]);
        let text = c.to_toml();
        let back: Config = toml::from_str(&text).unwrap();
        assert_eq!(back, c, "{text}");
        // That every key is declared is checked in `options`.
    }
}
