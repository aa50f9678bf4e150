//! The `octmesh` command line: parsed with clap into a [`Config`], on top
//! of a case file when one is given.
//!
//! Options keep the names they always had; each fills one key of the
//! configuration ([`OPTIONS`]), so an error about a key names the option
//! when it came from the command line, and the file, line and key when it
//! came from a case file.

use std::path::PathBuf;

use clap::error::{ContextKind, ContextValue, ErrorKind as ClapKind};
use clap::{Args, Parser, Subcommand};

use super::case::CaseFile;
use super::{Balance, Command, Config, ConfigError};
use crate::classify::{CutRule, InsideRule, Keep};
use crate::error::{Error, Result};
use crate::io::openfoam::FoamFormat;
use crate::refine::regions::Region;
use crate::run::budget::ByteSize;

/// The option that fills each key.
pub const OPTIONS: &[(&str, &str)] = &[
    ("surface.file", "the surface argument"),
    ("surface.others", "--surface"),
    ("surface.drop_degenerate", "--drop-degenerate"),
    ("surface.drop_duplicates", "--drop-duplicates"),
    ("domain.fit", "--fit"),
    ("domain.cube", "--domain"),
    ("domain.box", "--box"),
    ("domain.roots", "--roots"),
    ("octree.level", "--level"),
    ("octree.min_level", "--min-level"),
    ("octree.max_level", "--level"),
    ("octree.size", "--size"),
    ("octree.max_size", "--size"),
    ("octree.min_size", "--min-size"),
    ("octree.feature_angle", "--feature-angle"),
    ("octree.surface_levels", "--surface-level"),
    ("octree.distance", "--distance"),
    ("octree.distance_size", "--distance-size"),
    ("octree.balance", "--balance"),
    ("octree.max_octants", "--max-octants"),
    ("octree.memory_budget", "--memory-budget"),
    ("classify.inside", "--inside"),
    ("leak.inside_point", "--inside-point"),
    ("leak.path", "--leak-path"),
    ("mesh.keep", "--keep"),
    ("mesh.cut_rule", "--cut-rule"),
    ("mesh.patches", "--patch"),
    ("mesh.clean_walls", "--clean-walls"),
    ("mesh.snap", "--snap"),
    ("mesh.snap_feature_angle", "--snap-feature-angle"),
    ("mesh.snap_layers", "--snap-layers"),
    ("mesh.snap_iterations", "--snap-iterations"),
    ("mesh.snap_min_jacobian", "--snap-min-jacobian"),
    ("output.quiet", "--quiet"),
    ("output.stats", "--stats"),
    ("output.leaves", "--write-leaves"),
    ("output.refined_leaves", "--write-refined"),
    ("output.vtu", "--out"),
    ("output.openfoam", "--openfoam"),
    ("output.openfoam_format", "--openfoam-format"),
    ("output.overwrite", "--overwrite"),
    ("output.quality", "--quality"),
    ("output.quality_out", "--quality-out"),
    ("output.quality_worst", "--quality-worst"),
    ("regions", "--region"),
];

/// The option of a key.
pub fn option_of(key: &str) -> &'static str {
    OPTIONS
        .iter()
        .find(|(k, _)| *k == key)
        .map_or("an option", |(_, o)| o)
}

#[derive(Parser, Debug)]
#[command(
    name = "octmesh",
    version,
    about = "Parallel 2:1-balanced linear octrees and hexahedral meshes from STL surfaces",
    long_about = "Parallel 2:1-balanced linear octrees and hexahedral meshes from STL \
                  surfaces. Run it directly or under mpirun; every rank takes part.",
    after_help = "Lattice units: the root cube is [0, 2^19]^3; a leaf at level l has side \
                  2^(19-l). User units are the STL file's."
)]
struct Cli {
    #[command(subcommand)]
    command: CliCommand,
}

#[derive(Subcommand, Debug)]
enum CliCommand {
    /// Builds the surface-refined linear octree, partitions it over the MPI
    /// ranks and 2:1-balances it.
    Octree(OctreeArgs),
    /// Builds the octree, then the trilinear hexahedral mesh (ghost layer,
    /// independent and hanging nodes, global numbering) of the kept leaves.
    Mesh(MeshArgs),
    /// Prints the surface diagnostics (welded vertices, boundary and
    /// non-manifold edges, components, degenerate and duplicate facets,
    /// genus, volume) and the inside rule auto would pick.
    Check(CheckArgs),
}

/// The options of `octree`, also taken by `mesh`.
#[derive(Args, Debug)]
struct OctreeArgs {
    /// An STL file (ASCII or binary), the built-in `sphere`, `torus` or `hull`, or
    /// a case file (`.toml`) whose settings the options below override.
    input: String,
    /// Another surface meshed with the first (an STL file or a built-in
    /// name), repeatable: each file is a part with its own patch and, with
    /// --surface-level, its own levels
    #[arg(long = "surface", value_name = "FILE")]
    others: Vec<String>,
    /// Level of the leaves touching the surface (0 to 18); MIN:MAX refines
    /// them further, up to MAX, where the surface curves by more than the
    /// feature angle
    #[arg(long, value_name = "L[:MAX]", value_parser = parse_level_range)]
    level: Option<(u8, Option<u8>)>,
    /// Levels of one part of the surface (a solid of an ASCII STL, by its
    /// patch name), NAME=MIN[:MAX], repeatable; --level applies to the rest
    #[arg(long, value_name = "NAME=MIN[:MAX]", value_parser = parse_part_levels)]
    surface_level: Vec<(String, (u8, Option<u8>))>,
    /// Feature angle of curvature refinement, degrees [default: 30]
    #[arg(long, value_name = "DEG", value_parser = parse_finite)]
    feature_angle: Option<f64>,
    /// Every leaf at least this level [default: 0]
    #[arg(long, value_name = "L", value_parser = parse_level)]
    min_level: Option<u8>,
    /// The surface level as a cell size in user units instead of --level:
    /// the coarsest level whose cell is not larger; S:FINE gives the
    /// curvature refinement's finest size
    #[arg(long, value_name = "S[:FINE]", value_parser = parse_size_range)]
    size: Option<(f64, Option<f64>)>,
    /// --min-level as a cell size: every leaf at most this large
    #[arg(long, value_name = "S", value_parser = parse_finite)]
    min_size: Option<f64>,
    /// Distance bands around the surface, D1:L1,D2:L2,... with increasing
    /// distances D (user units): leaves within D of the surface get level L
    #[arg(long, value_name = "D:L,...", value_parser = parse_bands)]
    distance: Option<Bands>,
    /// Distance bands with cell sizes instead of levels, D1:S1,D2:S2,...
    /// (user units): leaves within D of the surface get the coarsest level
    /// whose cell is not larger than S
    #[arg(long, value_name = "D:S,...", value_parser = parse_size_bands)]
    distance_size: Option<SizeBands>,
    /// A refinement region, repeatable: box:X0,Y0,Z0,X1,Y1,Z1:LEVEL,
    /// sphere:CX,CY,CZ,R:LEVEL or cylinder:X0,Y0,Z0,X1,Y1,Z1,R:LEVEL (user
    /// units), then :outside to refine where the shape is not
    #[arg(long, value_name = "SHAPE:NUMBERS:LEVEL", allow_hyphen_values = true, value_parser = Region::parse)]
    region: Vec<Region>,
    /// 2:1 balance: face, edge, corner or none [default: corner]
    #[arg(long, value_name = "KIND", value_parser = Balance::parse)]
    balance: Option<Balance>,
    /// Longest side of the surface's bounding box as a fraction of the cube
    /// side, 0 < F <= 1 [default: 0.7]
    #[arg(long, allow_hyphen_values = true, value_name = "F", value_parser = parse_finite)]
    fit: Option<f64>,
    /// Explicit cube instead of --fit: lowest corner X,Y,Z and side S, user
    /// units
    #[arg(long, allow_hyphen_values = true, value_name = "X,Y,Z,S", value_parser = parse_numbers::<4>)]
    domain: Option<[f64; 4]>,
    /// A box domain instead of the cube: lowest corner X0,Y0,Z0 and highest
    /// X1,Y1,Z1, user units, split into the --roots cubic root cells
    #[arg(long = "box", allow_hyphen_values = true, value_name = "X0,Y0,Z0,X1,Y1,Z1", value_parser = parse_numbers::<6>)]
    bbox: Option<[f64; 6]>,
    /// Root cells of --box along x, y, z (trees of the forest; levels count
    /// from them) [default: 1,1,1]
    #[arg(long, value_name = "NX,NY,NZ", value_parser = parse_roots)]
    roots: Option<[u32; 3]>,
    /// Stop with an error instead of building more than N leaves (refinement
    /// and balance); refused before refining when the estimate is above 2N
    #[arg(long, value_name = "N", value_parser = parse_count)]
    max_octants: Option<u64>,
    /// Memory each rank may use (512MiB, 4GiB, ...): a run expected to need
    /// more stops before refining with the largest level that fits
    /// [default: the node's available memory shared among its ranks]
    #[arg(long, value_name = "SIZE", value_parser = ByteSize::parse)]
    memory_budget: Option<ByteSize>,
    /// Write counts, timings (seconds, max over ranks), peak memory (bytes,
    /// max over ranks) and bytes exchanged per phase as JSON
    #[arg(long, value_name = "FILE.json")]
    stats: Option<PathBuf>,
    /// Write the balanced leaves, one `x y z level` per line in lattice units
    /// (.bin: binary)
    #[arg(long, value_name = "FILE")]
    write_leaves: Option<PathBuf>,
    /// Write the leaves before balance, same format
    #[arg(long, value_name = "FILE")]
    write_refined: Option<PathBuf>,
    /// Remove zero-area facets right after loading
    #[arg(long)]
    drop_degenerate: bool,
    /// Remove facets with the same (welded) vertices as an earlier facet
    #[arg(long)]
    drop_duplicates: bool,
    /// How a leaf's centre is found inside: parity (ray parity), winding
    /// (generalized winding number above 1/2: holes, overlapping parts,
    /// flipped facets) or auto (parity for one closed, consistently oriented
    /// component, else winding; the default for mesh). With octree, also
    /// classifies the leaves and counts them
    #[arg(long, value_name = "RULE", value_parser = InsideRule::parse)]
    inside: Option<InsideRule>,
    /// A point inside the body (user units): after balance, fail with a leak
    /// report if the region outside the surface reaches it
    #[arg(long, allow_hyphen_values = true, value_name = "X,Y,Z", value_parser = parse_numbers::<3>)]
    inside_point: Option<[f64; 3]>,
    /// With --inside-point, write a leak's path (.vtk: legacy VTK lines; any
    /// other name: CSV step,x,y,z,size,level)
    #[arg(long, value_name = "FILE")]
    leak_path: Option<PathBuf>,
    /// Print nothing but errors
    #[arg(long)]
    quiet: bool,
    /// Print the case file (TOML) equivalent to this command line and stop
    #[arg(long)]
    print_case: bool,
    /// Print the estimated octant count of each refinement control and
    /// stop, without building anything
    #[arg(long)]
    dry_run: bool,
}

/// The options of `mesh`.
#[derive(Args, Debug)]
struct MeshArgs {
    #[command(flatten)]
    octree: OctreeArgs,
    /// Which leaves become elements: all, inside (solid) or outside (fluid)
    /// [default: all]
    #[arg(long, value_name = "WHICH", value_parser = Keep::parse)]
    keep: Option<Keep>,
    /// For inside or outside: leaves touching the surface are kept when their
    /// centre is on the kept side (center, the default), always (all) or
    /// never (none)
    #[arg(long, value_name = "RULE", value_parser = CutRule::parse)]
    cut_rule: Option<CutRule>,
    /// Write one binary VTU per rank and a PVTU (cell data level, rank,
    /// class; point data global_id, hanging)
    #[arg(long, value_name = "NAME.pvtu")]
    out: Option<PathBuf>,
    /// Write an OpenFOAM case: DIR/constant/polyMesh on one rank,
    /// DIR/processor<r>/constant/polyMesh on several (run solvers with
    /// -parallel), and the system/ files that are absent
    #[arg(long, value_name = "DIR")]
    openfoam: Option<PathBuf>,
    /// Lists in the OpenFOAM files: binary or ascii [default: binary]
    #[arg(long, value_name = "FORMAT", value_parser = FoamFormat::parse)]
    openfoam_format: Option<FoamFormat>,
    /// Replace an existing OpenFOAM mesh
    #[arg(long)]
    overwrite: bool,
    /// Rename a patch, OLD=NEW (repeatable): the sides xmin xmax ymin ymax
    /// zmin zmax, the surface by its file's stem or as `surface`
    #[arg(long, value_name = "OLD=NEW", value_parser = parse_rename)]
    patch: Vec<(String, String)>,
    /// Drop kept leaves touching the rest only along an edge or at a
    /// corner, or with kept neighbours along fewer than three axes, so the
    /// walls are manifold [default: true with --openfoam, else false]
    #[arg(long, value_name = "BOOL")]
    clean_walls: Option<bool>,
    /// Snap the mesh to the surface: the nodes on the surface move onto
    /// it (sharp edges kept), scaled back where an element would be
    /// invalid, the layers next to it relaxed (needs --keep inside or
    /// outside)
    #[arg(long)]
    snap: bool,
    /// Surface edges whose facets' normals differ by more than this many
    /// degrees stay sharp in the snapped mesh [default: 30]
    #[arg(long, value_name = "DEGREES")]
    snap_feature_angle: Option<f64>,
    /// Element layers around the surface nodes the snap relaxes [default: 2]
    #[arg(long, value_name = "N")]
    snap_layers: Option<u32>,
    /// Relaxation iterations of the snap [default: 3]
    #[arg(long, value_name = "N")]
    snap_iterations: Option<u32>,
    /// The least scaled Jacobian an element's corner may have after the
    /// snap, in (0, 0.5] [default: 0.1 with --openfoam, else 0.001]
    #[arg(long, value_name = "J")]
    snap_min_jacobian: Option<f64>,
    /// Measure the mesh's quality: scaled Jacobian histogram, checkMesh's
    /// non-orthogonality and skewness, in the table and --stats
    #[arg(long)]
    quality: bool,
    /// Measure the quality and write the worst elements by scaled Jacobian
    /// to a VTU file
    #[arg(long, value_name = "FILE.vtu")]
    quality_out: Option<PathBuf>,
    /// How many elements --quality-out writes [default: 100]
    #[arg(long, value_name = "N")]
    quality_worst: Option<u64>,
}

fn parse_rename(s: &str) -> std::result::Result<(String, String), String> {
    match s.split_once('=') {
        Some((a, b)) if !a.is_empty() => Ok((a.to_string(), b.to_string())),
        _ => Err(format!("expects OLD=NEW, got '{s}'")),
    }
}

/// The options of `check`.
#[derive(Args, Debug)]
struct CheckArgs {
    /// An STL file or the built-in `sphere`, `torus` or `hull`.
    surface: String,
    /// Also write the diagnostics as JSON
    #[arg(long, value_name = "FILE")]
    json: Option<PathBuf>,
    /// Print nothing but errors
    #[arg(long)]
    quiet: bool,
}

/// What a command line asks for.
#[derive(Clone, Debug)]
pub enum Invocation {
    /// Build an octree or a mesh with this configuration.
    Run {
        /// What to build.
        command: Command,
        /// Every setting.
        config: Box<Config>,
        /// Print the case file instead of running.
        print_case: bool,
        /// Print the estimates instead of running.
        dry_run: bool,
    },
    /// Diagnose a surface.
    Check {
        /// The surface.
        surface: String,
        /// JSON output.
        json: Option<PathBuf>,
        /// Print nothing but errors.
        quiet: bool,
    },
    /// Print this text (help or version) and succeed.
    Print(String),
}

/// Parses the arguments after the program name. Errors are
/// [`crate::ErrorKind::InvalidArgument`] and name the option (or the case
/// file's line and key).
pub fn parse(args: &[String]) -> Result<Invocation> {
    let argv = std::iter::once("octmesh".to_string()).chain(args.iter().cloned());
    let cli = match Cli::try_parse_from(argv) {
        Ok(c) => c,
        Err(e) => return clap_error(e),
    };
    let mut quality = (false, None, None);
    let mut snap = (false, None, None, None, None);
    let (command, octree, mesh) = match cli.command {
        CliCommand::Check(c) => {
            return Ok(Invocation::Check {
                surface: c.surface,
                json: c.json,
                quiet: c.quiet,
            })
        }
        CliCommand::Octree(o) => (Command::Octree, o, None),
        CliCommand::Mesh(m) => {
            let foam = (
                m.openfoam,
                m.openfoam_format,
                m.overwrite,
                m.patch,
                m.clean_walls,
            );
            quality = (m.quality, m.quality_out, m.quality_worst);
            snap = (
                m.snap,
                m.snap_feature_angle,
                m.snap_layers,
                m.snap_iterations,
                m.snap_min_jacobian,
            );
            (
                Command::Mesh,
                m.octree,
                Some((m.keep, m.cut_rule, m.out, foam)),
            )
        }
    };
    let case = if octree.input.ends_with(".toml") {
        Some(CaseFile::read(octree.input.as_ref())?)
    } else {
        None
    };
    let mut config = case.as_ref().map(|c| c.config.clone()).unwrap_or_default();
    let mut given = Vec::new();
    let mut set = |key: &'static str, present: bool| {
        if present {
            given.push(key);
        }
        present
    };
    if case.is_none() {
        config.surface.file = octree.input.clone();
        set("surface.file", true);
    }
    let o = &octree;
    if set("surface.others", !o.others.is_empty()) {
        // The command line's extra surfaces replace the case file's.
        config.surface.others = o.others.clone();
    }
    if let Some((min, max)) = o.level {
        set("octree.level", true);
        config.octree.level = Some(min);
        if set("octree.max_level", max.is_some()) {
            config.octree.max_level = max;
        }
    }
    if let Some((size, fine)) = o.size {
        set("octree.size", true);
        config.octree.size = Some(size);
        if set("octree.max_size", fine.is_some()) {
            config.octree.max_size = fine;
        }
    }
    if set("octree.min_size", o.min_size.is_some()) {
        config.octree.min_size = o.min_size;
    }
    if set("octree.surface_levels", !o.surface_level.is_empty()) {
        // The command line's part levels replace the case file's.
        config.octree.surface_levels.clear();
        for (name, (min, max)) in &o.surface_level {
            let r = [*min, max.unwrap_or(*min)];
            if config
                .octree
                .surface_levels
                .insert(name.clone(), r)
                .is_some()
            {
                return Err(Error::invalid(format!(
                    "--surface-level gives '{name}' twice"
                )));
            }
        }
    }
    if set("octree.feature_angle", o.feature_angle.is_some()) {
        config.octree.feature_angle = o.feature_angle;
    }
    if set("octree.min_level", o.min_level.is_some()) {
        config.octree.min_level = o.min_level.unwrap_or(0);
    }
    if let Some(b) = &o.distance_size {
        set("octree.distance_size", true);
        config.octree.distance_size = b.0.clone();
    }
    if let Some(b) = &o.distance {
        set("octree.distance", true);
        config.octree.distance = b.0.clone();
    }
    if set("regions", !o.region.is_empty()) {
        // The command line's regions replace the case file's.
        config.regions = o.region.clone();
    }
    if let Some(b) = o.balance {
        set("octree.balance", true);
        config.octree.balance = b;
    }
    let domains = [
        ("--fit", o.fit.is_some()),
        ("--domain", o.domain.is_some()),
        ("--box", o.bbox.is_some()),
    ];
    let named: Vec<&str> = domains.iter().filter(|g| g.1).map(|g| g.0).collect();
    if named.len() > 1 {
        return Err(Error::invalid(format!(
            "{} exclude each other: give one",
            named.join(" and ")
        )));
    }
    if set("domain.fit", o.fit.is_some()) {
        // The command line's domain choice replaces the case file's.
        config.domain = super::DomainConfig {
            fit: o.fit,
            ..Default::default()
        };
    }
    if set("domain.cube", o.domain.is_some()) {
        config.domain = super::DomainConfig {
            cube: o.domain,
            ..Default::default()
        };
    }
    if set("domain.box", o.bbox.is_some()) {
        config.domain = super::DomainConfig {
            bbox: o.bbox,
            roots: config.domain.roots,
            ..Default::default()
        };
    }
    if set("domain.roots", o.roots.is_some()) {
        config.domain.roots = o.roots;
    }
    if set("octree.max_octants", o.max_octants.is_some()) {
        config.octree.max_octants = o.max_octants;
    }
    if set("octree.memory_budget", o.memory_budget.is_some()) {
        config.octree.memory_budget = o.memory_budget;
    }
    for (key, flag, field) in [
        (
            "surface.drop_degenerate",
            o.drop_degenerate,
            &mut config.surface.drop_degenerate,
        ),
        (
            "surface.drop_duplicates",
            o.drop_duplicates,
            &mut config.surface.drop_duplicates,
        ),
        ("output.quiet", o.quiet, &mut config.output.quiet),
    ] {
        if set(key, flag) {
            *field = true;
        }
    }
    if set("classify.inside", o.inside.is_some()) {
        config.classify.inside = o.inside;
    }
    if set("leak.inside_point", o.inside_point.is_some()) {
        config.leak.inside_point = o.inside_point;
    }
    for (key, value, field) in [
        ("leak.path", &o.leak_path, &mut config.leak.path),
        ("output.stats", &o.stats, &mut config.output.stats),
        ("output.leaves", &o.write_leaves, &mut config.output.leaves),
        (
            "output.refined_leaves",
            &o.write_refined,
            &mut config.output.refined_leaves,
        ),
    ] {
        if set(key, value.is_some()) {
            *field = value.clone();
        }
    }
    if let Some((keep, cut_rule, out, (foam, format, overwrite, renames, clean))) = mesh {
        if set("mesh.clean_walls", clean.is_some()) {
            config.mesh.clean_walls = clean;
        }
        if set("output.openfoam", foam.is_some()) {
            config.output.openfoam = foam;
        }
        if let Some(f) = format {
            set("output.openfoam_format", true);
            config.output.openfoam_format = f;
        }
        if set("output.overwrite", overwrite) {
            config.output.overwrite = true;
        }
        if set("mesh.patches", !renames.is_empty()) {
            for (a, b) in renames {
                if config.mesh.patches.insert(a.clone(), b).is_some() {
                    return Err(Error::invalid(format!("--patch renames '{a}' twice")));
                }
            }
        }
        if let Some(k) = keep {
            set("mesh.keep", true);
            config.mesh.keep = k;
        }
        if let Some(r) = cut_rule {
            set("mesh.cut_rule", true);
            config.mesh.cut_rule = r;
        }
        if set("output.vtu", out.is_some()) {
            config.output.vtu = out;
        }
        let (measure, quality_out, worst) = quality;
        if set("output.quality", measure) {
            config.output.quality = true;
        }
        if set("output.quality_out", quality_out.is_some()) {
            config.output.quality_out = quality_out;
        }
        if set("output.quality_worst", worst.is_some()) {
            config.output.quality_worst = worst;
        }
        let (on, angle, layers, iterations, min_jacobian) = snap;
        if set("mesh.snap_min_jacobian", min_jacobian.is_some()) {
            config.mesh.snap_min_jacobian = min_jacobian;
        }
        if set("mesh.snap", on) {
            config.mesh.snap = true;
        }
        if let Some(a) = angle {
            set("mesh.snap_feature_angle", true);
            config.mesh.snap_feature_angle = a;
        }
        if let Some(l) = layers {
            set("mesh.snap_layers", true);
            config.mesh.snap_layers = l;
        }
        if let Some(i) = iterations {
            set("mesh.snap_iterations", true);
            config.mesh.snap_iterations = i;
        }
    }
    let label = |key: &str| match &case {
        Some(c) if !given.contains(&key) => c.label(key),
        _ => option_of(key).to_string(),
    };
    config
        .validate(command)
        .map_err(|e: ConfigError| Error::invalid(e.render(label)))?;
    Ok(Invocation::Run {
        command,
        config: Box::new(config),
        print_case: octree.print_case,
        dry_run: octree.dry_run,
    })
}

/// A clap error in octmesh's words: help and version are printed, a value
/// that does not parse names its option, the rest keeps clap's text (with
/// its "a similar argument exists" tips).
fn clap_error(e: clap::Error) -> Result<Invocation> {
    match e.kind() {
        ClapKind::DisplayHelp | ClapKind::DisplayVersion => {
            return Ok(Invocation::Print(e.render().to_string()))
        }
        ClapKind::DisplayHelpOnMissingArgumentOrSubcommand => {
            return Err(Error::invalid(format!("usage: {}", e.render())))
        }
        _ => {}
    }
    let arg = match e.get(ContextKind::InvalidArg) {
        Some(ContextValue::String(a)) => a.split([' ', '=']).next().map(str::to_string),
        _ => None,
    };
    let source = std::error::Error::source(&e).map(|s| s.to_string());
    let message = match (e.kind(), arg, source) {
        (ClapKind::ValueValidation, Some(arg), Some(why)) => {
            let sep = if why.starts_with("unknown") {
                ": "
            } else {
                " "
            };
            format!("{arg}{sep}{why}")
        }
        _ => {
            let text = e.render().to_string();
            let text = text.strip_prefix("error: ").unwrap_or(&text);
            text.trim_end().to_string()
        }
    };
    Err(Error::invalid(message))
}

fn parse_level(s: &str) -> std::result::Result<u8, String> {
    let l: u32 = s
        .parse()
        .map_err(|_| format!("expects an integer, got '{s}'"))?;
    // Out-of-range levels are reported by validation, with the maximum.
    Ok(l.min(u8::MAX as u32) as u8)
}

/// Distance bands as one option value (clap reads a bare `Vec` as several
/// values).
#[derive(Clone, Debug)]
struct Bands(Vec<(f64, u8)>);

/// `D1:L1,D2:L2,...`.
fn parse_bands(s: &str) -> std::result::Result<Bands, String> {
    let bad = || format!("expects D1:L1,D2:L2,... (distance:level pairs), got '{s}'");
    s.split(',')
        .map(|band| {
            let (d, l) = band.split_once(':').ok_or_else(bad)?;
            Ok((
                parse_finite(d).map_err(|_| bad())?,
                parse_level(l).map_err(|_| bad())?,
            ))
        })
        .collect::<std::result::Result<_, String>>()
        .map(Bands)
}

#[derive(Clone, Debug)]
struct SizeBands(Vec<(f64, f64)>);

/// `D1:S1,D2:S2,...`.
fn parse_size_bands(s: &str) -> std::result::Result<SizeBands, String> {
    let bad = || format!("expects D1:S1,D2:S2,... (distance:size pairs), got '{s}'");
    s.split(',')
        .map(|band| {
            let (d, c) = band.split_once(':').ok_or_else(bad)?;
            Ok((
                parse_finite(d).map_err(|_| bad())?,
                parse_finite(c).map_err(|_| bad())?,
            ))
        })
        .collect::<std::result::Result<_, String>>()
        .map(SizeBands)
}

/// `L` or `MIN:MAX`.
fn parse_size_range(s: &str) -> std::result::Result<(f64, Option<f64>), String> {
    match s.split_once(':') {
        None => Ok((parse_finite(s)?, None)),
        Some((a, b)) => Ok((parse_finite(a)?, Some(parse_finite(b)?))),
    }
}

/// `NAME=MIN[:MAX]`.
fn parse_part_levels(s: &str) -> std::result::Result<(String, (u8, Option<u8>)), String> {
    match s.split_once('=') {
        Some((name, r)) if !name.is_empty() => Ok((name.to_string(), parse_level_range(r)?)),
        _ => Err(format!("expects NAME=MIN[:MAX], got '{s}'")),
    }
}

fn parse_level_range(s: &str) -> std::result::Result<(u8, Option<u8>), String> {
    match s.split_once(':') {
        None => Ok((parse_level(s)?, None)),
        Some((a, b)) => Ok((parse_level(a)?, Some(parse_level(b)?))),
    }
}

fn parse_count(s: &str) -> std::result::Result<u64, String> {
    s.parse()
        .map_err(|_| format!("expects a non-negative integer, got '{s}'"))
}

/// `NX,NY,NZ`: three positive counts.
fn parse_roots(s: &str) -> std::result::Result<[u32; 3], String> {
    let bad = || format!("expects three comma-separated positive integers NX,NY,NZ, got '{s}'");
    let v: Vec<u32> = s
        .split(',')
        .map(|t| t.trim().parse::<u32>().ok().filter(|&n| n > 0))
        .collect::<Option<_>>()
        .ok_or_else(bad)?;
    v.try_into().map_err(|_| bad())
}

fn parse_finite(s: &str) -> std::result::Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(x) if x.is_finite() => Ok(x),
        _ => Err(format!("expects a number, got '{s}'")),
    }
}

/// `N` finite comma-separated numbers.
fn parse_numbers<const N: usize>(s: &str) -> std::result::Result<[f64; N], String> {
    let bad = || format!("expects {N} comma-separated numbers, got '{s}'");
    let v: Vec<f64> = s
        .split(',')
        .map(parse_finite)
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| bad())?;
    v.try_into().map_err(|_| bad())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(args: &[&str]) -> Result<Config> {
        let args: Vec<String> = args.iter().map(|s| s.to_string()).collect();
        match parse(&args)? {
            Invocation::Run { config, .. } => Ok(*config),
            other => panic!("{other:?}"),
        }
    }

    fn fails(args: &[&str], needle: &str) {
        let e = run(args).unwrap_err();
        assert!(e.message().contains(needle), "{args:?}: {}", e.message());
    }

    #[test]
    fn options_fill_the_config() {
        let c = run(&[
            "mesh",
            "bunny.stl",
            "--level",
            "7",
            "--keep",
            "inside",
            "--fit",
            "0.5",
            "--balance",
            "edge",
            "--inside",
            "winding",
            "--quiet",
            "--out",
            "m.pvtu",
        ])
        .unwrap();
        assert_eq!(c.surface.file, "bunny.stl");
        assert_eq!(c.octree.level, Some(7));
        assert_eq!(c.octree.balance, Balance::Edge);
        assert_eq!(c.domain.fit, Some(0.5));
        assert_eq!(c.mesh.keep, Keep::Inside);
        assert_eq!(c.classify.inside, Some(InsideRule::Winding));
        assert!(c.output.quiet);
        assert_eq!(c.output.vtu, Some("m.pvtu".into()));
    }

    #[test]
    fn errors_name_the_option() {
        fails(
            &["octree", "sphere", "--level", "x"],
            "--level expects an integer",
        );
        fails(
            &["octree", "sphere", "--level", "19"],
            "above the maximum level 18",
        );
        fails(
            &["octree", "sphere", "--level", "4", "--fit", "2"],
            "--fit must be in (0, 1]",
        );
        fails(
            &["octree", "sphere", "--level", "4", "--balance", "diagonal"],
            "--balance: unknown connectivity 'diagonal'",
        );
        fails(&["octree", "sphere"], "--level is required");
        let c = run(&[
            "octree",
            "sphere",
            "--level",
            "3",
            "--inside-point",
            "-0.5,0,-1e-3",
        ]);
        assert_eq!(c.unwrap().leak.inside_point, Some([-0.5, 0.0, -1e-3]));
        fails(
            &["octree", "sphere", "--level", "3", "--fit", "-1"],
            "--fit must be in (0, 1]",
        );
        fails(&["octree", "sphere", "--levl", "3"], "--level");
        fails(
            &[
                "octree", "sphere", "--level", "3", "--fit", "0.5", "--domain", "0,0,0,1",
            ],
            "--fit and --domain exclude each other",
        );
        fails(
            &["octree", "sphere", "--level", "3", "--leak-path", "x.vtk"],
            "--leak-path needs --inside-point",
        );
        fails(
            &["octree", "sphere", "--level", "3", "--keep", "inside"],
            "--keep",
        );
        fails(
            &["mesh", "sphere", "--level", "3", "--out", "m.vtu"],
            "ending in .pvtu",
        );
    }
}
