//! The `octmesh` command: runs the pipeline on a surface, directly or under
//! `mpirun`, and reports a table of phases.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;
use std::rc::Rc;

use octmesh::classify::{CutRule, InsideClassifier, InsideRule, Keep, LeafClass};
use octmesh::comm::{agree, Comm, CommRef, MpiComm, Traffic};
use octmesh::domain::{Domain, DEFAULT_FIT};
use octmesh::geometry::diagnostics::{clean, diagnose, SurfaceReport};
use octmesh::geometry::{load_surface, Aabb};
use octmesh::io::leaves::write_leaves;
use octmesh::io::vtu::write_mesh;
use octmesh::leak::find_leak;
use octmesh::mesh::{Mesh, MeshOptions};
use octmesh::refine::{
    check_estimate, construct_top_for_surface, estimate_leaves, SurfaceIndex, NO_LIMIT,
};
use octmesh::report::{peak_rss_bytes, JsonObject, PhaseTimer};
use octmesh::{Connectivity, Error, Result};

const USAGE: &str = "\
usage: octmesh octree <file.stl | sphere | torus> --level L [options]
       octmesh mesh   <file.stl | sphere | torus> --level L [options]
       octmesh check  <file.stl | sphere | torus> [--json FILE] [--quiet]

octree: builds the surface-refined linear octree, partitions it over the MPI
ranks and 2:1-balances it. Leaves touching the surface are at level L (at
most 18).
mesh: then builds the trilinear hexahedral mesh (ghost layer, independent and
hanging nodes, global numbering) of the kept elements, and writes it.
check: prints the surface diagnostics (welded vertices, boundary,
non-manifold and inconsistently oriented edges, edge-connected components,
degenerate and duplicate facets, Euler characteristic, genus, volume);
--json FILE also writes them as JSON. It also says which inside rule auto
would pick.

options:
  --level L             refinement level of the leaves touching the surface
  --balance KIND        face | edge | corner | none (default corner)
  --fit F               longest side of the surface's bounding box as a
                        fraction of the cube side, 0 < F <= 1 (default 0.7)
  --domain X,Y,Z,S      explicit cube: lowest corner X,Y,Z and side S
                        (user units) instead of --fit
  --max-octants N       stop with an error if the octree would exceed N leaves
  --stats FILE.json     write counts, timings (max over ranks) and peak memory
  --write-leaves FILE   write the balanced leaves (x y z level per line,
                        lattice units of 2^-19 of the cube; .bin = binary)
  --write-refined FILE  write the leaves before balance, same format
  --drop-degenerate     remove zero-area facets after loading
  --drop-duplicates     remove facets repeating the vertices of an earlier one
  --inside RULE         how leaf centres are found inside: parity (ray
                        parity), winding (generalized winding number above
                        1/2: holes, overlapping parts, flipped facets) or
                        auto (parity for one closed, consistently oriented
                        component, else winding; the default for mesh). With
                        octree, also classifies the leaves and counts them
  --inside-point X,Y,Z  a point inside the body: after balance, fail with a
                        leak report if the region outside the surface
                        reaches it through leaves touching no triangle
  --leak-path FILE      with --inside-point, write a leak's path of octant
                        centres (.vtk: legacy VTK polyline; else CSV)
  --quiet               print nothing but errors

mesh options:
  --keep WHICH          all | inside (solid) | outside (fluid); default all
  --cut-rule RULE       for inside/outside, leaves touching the surface are
                        kept when their centre is on the kept side (center,
                        the default), always (all) or never (none)
  --out NAME.pvtu       write one binary VTU per rank and a PVTU
  (--balance must be edge or corner; corner is the default)
";

struct Options {
    command: Command,
    surface: String,
    level: u8,
    balance: Option<Connectivity>,
    fit: f64,
    domain: Option<Domain>,
    max_octants: u64,
    stats: Option<PathBuf>,
    write_leaves: Option<PathBuf>,
    write_refined: Option<PathBuf>,
    quiet: bool,
    keep: Keep,
    cut_rule: CutRule,
    inside: Option<InsideRule>,
    out: Option<PathBuf>,
    drop_degenerate: bool,
    drop_duplicates: bool,
    json: Option<PathBuf>,
    inside_point: Option<[f64; 3]>,
    leak_path: Option<PathBuf>,
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Command {
    Octree,
    Mesh,
    Check,
}

fn parse_args(args: &[String]) -> Result<Options> {
    if args.is_empty() || args[0] == "--help" || args[0] == "-h" {
        return Err(Error::invalid(USAGE));
    }
    let command = match args[0].as_str() {
        "octree" => Command::Octree,
        "mesh" => Command::Mesh,
        "check" => Command::Check,
        other => {
            return Err(Error::invalid(format!(
                "unknown command '{other}'\n{USAGE}"
            )))
        }
    };
    let mut o = Options {
        command,
        surface: String::new(),
        level: u8::MAX,
        balance: Some(Connectivity::Corner),
        fit: DEFAULT_FIT,
        domain: None,
        max_octants: NO_LIMIT,
        stats: None,
        write_leaves: None,
        write_refined: None,
        quiet: false,
        keep: Keep::All,
        cut_rule: CutRule::Center,
        inside: None,
        out: None,
        drop_degenerate: false,
        drop_duplicates: false,
        json: None,
        inside_point: None,
        leak_path: None,
    };
    let mut i = 1;
    let value = |i: usize, name: &str| -> Result<String> {
        args.get(i + 1)
            .cloned()
            .ok_or_else(|| Error::invalid(format!("{name} needs a value")))
    };
    while i < args.len() {
        let a = args[i].as_str();
        let mut consumed = 2;
        match a {
            "--json" if command == Command::Check => o.json = Some(value(i, a)?.into()),
            "--quiet" => {
                o.quiet = true;
                consumed = 1;
            }
            _ if command == Command::Check && a.starts_with("--") => {
                return Err(Error::invalid(format!(
                    "option '{a}' is not valid for check\n{USAGE}"
                )))
            }
            "--level" => {
                let v = value(i, a)?;
                o.level = v
                    .parse::<u32>()
                    .map_err(|_| Error::invalid(format!("--level expects an integer, got '{v}'")))?
                    .min(255) as u8;
            }
            "--balance" => {
                let v = value(i, a)?;
                o.balance = if v == "none" {
                    None
                } else {
                    Some(Connectivity::parse(&v)?)
                };
            }
            "--fit" => {
                let v = value(i, a)?;
                o.fit = v
                    .parse()
                    .map_err(|_| Error::invalid(format!("--fit expects a number, got '{v}'")))?;
            }
            "--domain" => {
                let n = numbers(&value(i, a)?, 4, "--domain", "X,Y,Z,SIDE")?;
                o.domain = Some(Domain::cube([n[0], n[1], n[2]], n[3])?);
            }
            "--max-octants" => {
                let v = value(i, a)?;
                o.max_octants = v.parse().map_err(|_| {
                    Error::invalid(format!("--max-octants expects an integer, got '{v}'"))
                })?;
            }
            "--stats" => o.stats = Some(value(i, a)?.into()),
            "--inside-point" => {
                let n = numbers(&value(i, a)?, 3, "--inside-point", "X,Y,Z")?;
                o.inside_point = Some([n[0], n[1], n[2]]);
            }
            "--leak-path" => o.leak_path = Some(value(i, a)?.into()),
            "--write-leaves" => o.write_leaves = Some(value(i, a)?.into()),
            "--write-refined" => o.write_refined = Some(value(i, a)?.into()),
            "--keep" if command == Command::Mesh => o.keep = Keep::parse(&value(i, a)?)?,
            "--cut-rule" if command == Command::Mesh => o.cut_rule = CutRule::parse(&value(i, a)?)?,
            "--inside" => o.inside = Some(InsideRule::parse(&value(i, a)?)?),
            "--out" if command == Command::Mesh => {
                let v = value(i, a)?;
                if !v.ends_with(".pvtu") {
                    return Err(Error::invalid(format!(
                        "--out expects a file name ending in .pvtu, got '{v}'"
                    )));
                }
                o.out = Some(v.into());
            }
            "--drop-degenerate" => {
                o.drop_degenerate = true;
                consumed = 1;
            }
            "--drop-duplicates" => {
                o.drop_duplicates = true;
                consumed = 1;
            }
            _ if a.starts_with("--") => {
                return Err(Error::invalid(format!("unknown option '{a}'\n{USAGE}")))
            }
            _ => {
                if !o.surface.is_empty() {
                    return Err(Error::invalid(format!("unexpected argument '{a}'")));
                }
                o.surface = a.to_string();
                consumed = 1;
            }
        }
        i += consumed;
    }
    if o.surface.is_empty() {
        return Err(Error::invalid("no surface given (see octmesh --help)"));
    }
    if command == Command::Check {
        return Ok(o);
    }
    if o.level == u8::MAX {
        return Err(Error::invalid("--level is required"));
    }
    if o.leak_path.is_some() && o.inside_point.is_none() {
        return Err(Error::invalid("--leak-path needs --inside-point"));
    }
    if o.level > octmesh::MAX_LEVEL {
        return Err(Error::invalid(format!(
            "level {} is above the maximum level {}",
            o.level,
            octmesh::MAX_LEVEL
        )));
    }
    if command == Command::Mesh
        && !matches!(
            o.balance,
            Some(Connectivity::Edge) | Some(Connectivity::Corner)
        )
    {
        return Err(Error::invalid(format!(
            "meshing needs --balance edge or corner (got {}): with face balance alone a \
             hanging node may depend on another hanging node",
            o.balance.map_or("none", |c| c.name())
        )));
    }
    Ok(o)
}

/// Prints one phase line on rank 0.
struct Table {
    on: bool,
}

impl Table {
    fn row(&self, t: &PhaseTimer, count: Option<u64>) {
        self.phase_row(&t.phases().last().cloned().unwrap_or_default(), count);
    }

    /// The row of one phase (name, seconds).
    fn phase_row(&self, (name, secs): &(String, f64), count: Option<u64>) {
        if self.on {
            let c = count.map(|c| c.to_string()).unwrap_or_default();
            println!("  {name:<12} {secs:>10.3} {c:>14}");
        }
    }
}

/// `n` finite comma-separated numbers, the value of `option`.
fn numbers(v: &str, n: usize, option: &str, form: &str) -> Result<Vec<f64>> {
    let bad = || Error::invalid(format!("{option} expects {form}, got '{v}'"));
    let x: Vec<f64> = v
        .split(',')
        .map(|s| s.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| bad())?;
    if x.len() != n || x.iter().any(|c| !c.is_finite()) {
        return Err(bad());
    }
    Ok(x)
}

fn run(comm: CommRef, o: &Options) -> Result<()> {
    let root = comm.rank() == 0 && !o.quiet;
    let table = Table { on: root };
    let mut timer = PhaseTimer::new();
    // Memory before and after the surface is loaded, so benchmarks can tell
    // the surface (held whole on every rank) from the octree and mesh.
    let rss_start = peak_rss_bytes();
    // Meshes always classify (auto by default); octrees only when asked.
    let inside_rule = match o.command {
        Command::Mesh => Some(o.inside.unwrap_or_default()),
        _ => o.inside,
    };

    let loaded = timer.time(
        &*comm,
        "read",
        || -> Result<(usize, f64, Domain, SurfaceIndex, usize, Option<SurfaceReport>)> {
            let mut surface = load_surface(&o.surface)?;
            let mut dropped = 0;
            if o.drop_degenerate || o.drop_duplicates {
                (surface, dropped) = clean(&surface, o.drop_degenerate, o.drop_duplicates)?;
            }
            let report = (o.stats.is_some() || inside_rule == Some(InsideRule::Auto))
                .then(|| diagnose(&surface));
            let b = surface.bbox();
            let domain = match o.domain {
                Some(d) => d,
                None => Domain::around(b.min, b.max, o.fit)?,
            };
            let index = SurfaceIndex::new(&surface, &domain);
            Ok((
                surface.len(),
                surface.signed_volume().abs(),
                domain,
                index,
                dropped,
                report,
            ))
        },
    );
    let (ntri, surface_volume, domain, index, dropped, report) = agree(&*comm, loaded)?;
    let rss_read = peak_rss_bytes();
    let estimate = estimate_leaves(&index, o.level);
    // The rule actually used, and for auto why.
    let inside = inside_rule.map(|r| match (r, &report) {
        (InsideRule::Auto, Some(rep)) => {
            let (rule, why) = InsideRule::auto_choice(rep);
            (rule, format!(" (auto: {why})"))
        }
        (r, _) => (r, String::new()),
    });
    if root {
        let rule = inside
            .as_ref()
            .map(|(r, why)| format!("inside {}{why}", r.name()));
        let what = match o.command {
            Command::Octree => match &rule {
                Some(r) => format!("octree ({r})"),
                None => "octree".to_string(),
            },
            Command::Mesh => format!(
                "mesh (keep {}, cut rule {}, {})",
                o.keep.name(),
                o.cut_rule.name(),
                rule.unwrap_or_default()
            ),
            Command::Check => unreachable!("check does not build an octree"),
        };
        println!(
            "octmesh {what}: {} ({ntri} triangles), level {}, balance {}, {} rank(s)",
            o.surface,
            o.level,
            o.balance.map_or("none", |c| c.name()),
            comm.size()
        );
        if o.drop_degenerate || o.drop_duplicates {
            println!("  dropped {dropped} facet(s) (degenerate or duplicate)");
        }
        println!(
            "  cube: origin ({:.6}, {:.6}, {:.6}), side {:.6}",
            domain.origin[0], domain.origin[1], domain.origin[2], domain.side
        );
        println!(
            "  estimated octants: {} refined, {} balanced",
            estimate.refined, estimate.balanced
        );
        println!("  {:<12} {:>10} {:>14}", "phase", "time [s]", "count");
    }
    table.row(&timer, None);
    check_estimate(&comm, &index, o.level, o.max_octants)?;

    let top = timer.time(&*comm, "construct", || {
        construct_top_for_surface(comm.clone(), &index, o.level)
    })?;
    table.row(&timer, Some(top.tree().global_len()));
    let mut tree = timer.time(&*comm, "refine", || top.refine(o.max_octants))?;
    let refined = tree.global_len();
    table.row(&timer, Some(refined));
    timer.time(&*comm, "partition", || tree.partition())?;
    table.row(&timer, Some(refined));
    if let Some(p) = &o.write_refined {
        write_leaves(&tree, p, "refined leaves")?;
    }
    if let Some(conn) = o.balance {
        timer.time(&*comm, "balance", || {
            tree.balance_with_limit(conn, o.max_octants)
        })?;
        table.row(&timer, Some(tree.global_len()));
        timer.time(&*comm, "partition", || tree.partition())?;
        table.row(&timer, Some(tree.global_len()));
    }
    let balanced = tree.global_len();
    if let Some(p) = &o.write_leaves {
        write_leaves(&tree, p, "balanced leaves")?;
    }

    let mut stats = JsonObject::new();
    let mut phase_keys = vec!["read", "construct", "refine", "partition", "balance"];
    // Meshes and leak checks need the leaf classes (a leak check only their
    // cut bits, which every rule computes the same way).
    let classify_rule = inside
        .as_ref()
        .map(|(r, _)| *r)
        .or(o.inside_point.map(|_| InsideRule::Parity));
    let classes = match classify_rule {
        Some(rule) => {
            phase_keys.push("classify");
            let (classes, summary) = timer.time(&*comm, "classify", || {
                let c = InsideClassifier::new(&index, rule);
                (c.classify(tree.leaves()), c.summary().cloned())
            });
            table.row(&timer, None);
            if let (true, Some(w)) = (root, &summary) {
                println!(
                    "  winding: {} component(s), {} facet(s) reversed, {} boundary loop(s) \
                     closed by {} cap triangle(s)",
                    w.components, w.reversed_facets, w.boundary_loops, w.cap_triangles
                );
            }
            if inside.is_some() {
                stats.str("inside_rule", rule.name());
            }
            if let Some(w) = &summary {
                stats
                    .int("reversed_facets", w.reversed_facets as u64)
                    .int("boundary_loops", w.boundary_loops as u64);
            }
            Some(classes)
        }
        None => None,
    };
    if let (Command::Octree, Some(classes), true) = (o.command, &classes, o.inside.is_some()) {
        // Leaves per class, over all ranks.
        let mut n = [0u64; 3];
        for &b in classes {
            n[LeafClass::from_bits(b) as usize] += 1;
        }
        comm.sum_u64(&mut n);
        if root {
            println!(
                "  leaves inside {} | outside {} | cut {}",
                n[LeafClass::Inside as usize],
                n[LeafClass::Outside as usize],
                n[LeafClass::Cut as usize]
            );
        }
        stats
            .int("inside_leaves", n[LeafClass::Inside as usize])
            .int("outside_leaves", n[LeafClass::Outside as usize])
            .int("cut_leaves", n[LeafClass::Cut as usize]);
    }
    let mut leak_error = None;
    let mut leak = JsonObject::new();
    leak.bool("checked", o.inside_point.is_some());
    if let Some(point) = o.inside_point {
        phase_keys.push("leak_check");
        let c = classes.as_deref().unwrap_or_default();
        let found = timer.time(&*comm, "leak_check", || find_leak(&tree, c, &domain, point))?;
        table.row(&timer, None);
        let n = found.as_ref().map_or(0, |p| p.len());
        leak.bool("found", found.is_some())
            .int("path_octants", n as u64);
        match found {
            None => {
                if root {
                    println!(
                        "  leak check passed: the inside point ({}, {}, {}) is sealed off from \
                         the domain boundary ({:.3} s)",
                        point[0],
                        point[1],
                        point[2],
                        timer.get("leak_check")
                    );
                }
            }
            Some(path) => {
                if let Some(file) = &o.leak_path {
                    let written = if comm.rank() == 0 {
                        path.write(file, &domain)
                    } else {
                        Ok(())
                    };
                    agree(&*comm, written)?;
                    if root {
                        println!("  wrote the leak path ({n} octants) to {}", file.display());
                    }
                }
                // The surface's box in user units, for the report.
                let bbox = Aabb::from_points(
                    index
                        .triangles()
                        .iter()
                        .flat_map(|t| t.v)
                        .map(|p| domain.from_lattice(p)),
                );
                leak_error = Some(path.to_error(&domain, Some(&bbox)));
            }
        }
    }
    stats.obj("leak", &leak);
    // The surface is not needed to mesh: its memory goes before the mesh's.
    drop(index);
    if o.command == Command::Mesh && leak_error.is_none() {
        phase_keys.extend(["ghost", "nodes", "numbering", "connectivity", "write"]);
        let classes = classes.unwrap_or_default();
        let opts = MeshOptions {
            keep: o.keep,
            cut_rule: o.cut_rule,
        };
        let mesh = Mesh::build(&tree, &domain, Some(&classes), &opts)?;
        timer.append(mesh.phase_timer());
        for phase in mesh.timings() {
            let c = mesh.counts();
            let count = match phase.0.as_str() {
                "ghost" => Some(c.ghosts),
                "nodes" => Some(c.independent_nodes + c.face_hanging_nodes + c.edge_hanging_nodes),
                "connectivity" => Some(c.elements),
                _ => None,
            };
            table.phase_row(phase, count);
        }
        if let Some(out) = &o.out {
            timer.time(&*comm, "write", || write_mesh(&*comm, out, &mesh, &[]))?;
            table.row(&timer, None);
        }
        let c = *mesh.counts();
        let mut cells = [mesh.local_volume_cells()];
        comm.sum_u64(&mut cells);
        let vol = [mesh.cells_to_volume(cells[0])];
        let mut points = [mesh.num_nodes() as u64];
        comm.sum_u64(&mut points);
        if root {
            println!(
                "  elements {} | independent nodes {} | hanging nodes {} face, {} edge | ghosts {}",
                c.elements,
                c.independent_nodes,
                c.face_hanging_nodes,
                c.edge_hanging_nodes,
                c.ghosts
            );
            let rel = (vol[0] - surface_volume) / surface_volume;
            println!(
                "  kept volume {:.6e} | surface volume {:.6e} | relative difference {rel:+.3e}",
                vol[0], surface_volume
            );
            if let Some(out) = &o.out {
                println!("  wrote {}", out.display());
            }
        }
        stats
            .int("elements", c.elements)
            .int("independent_nodes", c.independent_nodes)
            .int("face_hanging_nodes", c.face_hanging_nodes)
            .int("edge_hanging_nodes", c.edge_hanging_nodes)
            .int("elements_with_hanging", c.elements_with_hanging)
            .int("ghosts", c.ghosts)
            .int("points_written", points[0])
            .num("kept_volume", vol[0])
            .int("kept_cells", cells[0])
            .str("keep", o.keep.name())
            .str("cut_rule", o.cut_rule.name());
    }
    stats
        .num("surface_volume", surface_volume)
        .int("dropped_facets", dropped as u64);
    if let Some(r) = &report {
        let mut s = JsonObject::new();
        s.int("triangles", r.triangles as u64)
            .int("boundary_edges", r.boundary_edges as u64)
            .int("non_manifold_edges", r.non_manifold_edges as u64)
            .int("components", r.components as u64)
            .bool("closed", r.closed);
        stats.obj("surface", &s);
    }

    let mut rss = [peak_rss_bytes(), rss_start, rss_read];
    comm.max_u64(&mut rss);
    if root {
        let total: f64 = timer.phases().iter().map(|p| p.1).sum();
        println!("  {:<12} {total:>10.3}", "total");
        println!(
            "  peak RSS {:.1} MiB per rank (max over ranks), {:.1} bytes per leaf",
            rss[0] as f64 / (1 << 20) as f64,
            rss[0] as f64 * comm.size() as f64 / balanced.max(1) as f64
        );
    }
    if let Some(path) = &o.stats {
        let mut t = JsonObject::new();
        for k in &phase_keys {
            t.num(k, timer.get(k));
        }
        // The partition after refinement and the one after balance, apart.
        let mut steps = JsonObject::new();
        let partitions: Vec<f64> = timer
            .phases()
            .iter()
            .filter(|p| p.0 == "partition")
            .map(|p| p.1)
            .collect();
        for (key, secs) in ["refined", "balanced"].iter().zip(&partitions) {
            steps.num(key, *secs);
        }
        let (bytes, bytes_sent, bytes_sum) = comm_stats(&*comm, &timer, &phase_keys);
        let (wait_min, wait_max) = wait_stats(&*comm, &timer, &phase_keys);
        // Peak RSS at the end of each phase (its last run), max over ranks:
        // the phase where it grows set the peak.
        let mut after: Vec<u64> = phase_keys
            .iter()
            .map(|k| {
                let last = timer.peaks().iter().rev().find(|p| p.0 == *k);
                last.map_or(0, |p| p.1)
            })
            .collect();
        comm.max_u64(&mut after);
        let mut peaks = JsonObject::new();
        for (k, b) in phase_keys.iter().zip(&after) {
            peaks.int(k, *b);
        }
        let mut j = JsonObject::new();
        j.str(
            "command",
            if o.command == Command::Mesh {
                "mesh"
            } else {
                "octree"
            },
        )
        .str("surface", &o.surface)
        .int("ranks", comm.size() as u64)
        .int("triangles", ntri as u64)
        .int("level", o.level as u64)
        .str("balance", o.balance.map_or("none", |c| c.name()))
        .int("octants_refined", refined)
        .int("octants_balanced", balanced)
        .int(
            "estimated_octants",
            if o.balance.is_some() {
                estimate.balanced
            } else {
                estimate.refined
            },
        )
        .int("estimated_octants_refined", estimate.refined)
        .merge(&stats)
        .obj("timings", &t)
        .obj("partition_timings", &steps)
        .obj("comm_bytes", &bytes)
        .obj("comm_bytes_sent", &bytes_sent)
        .obj("comm_bytes_sum", &bytes_sum)
        .obj("comm_seconds_min", &wait_min)
        .obj("comm_seconds_max", &wait_max)
        .int("peak_rss_bytes", rss[0])
        .obj("peak_rss_after", &peaks)
        .int("rss_start_bytes", rss[1])
        .int("rss_after_read_bytes", rss[2])
        .num("domain_side", domain.side);
        let written = if comm.rank() == 0 {
            std::fs::write(path, j.to_json())
                .map_err(|e| Error::io(format!("cannot write '{}': {e}", path.display())))
        } else {
            Ok(())
        };
        agree(&*comm, written)?;
    }
    match leak_error {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

/// Seconds spent inside collectives per phase, for `--stats`: the smallest
/// and the largest over ranks (the largest is mostly waiting for the
/// slowest rank; the smallest is closer to what the exchanges cost).
/// Collective.
fn wait_stats(comm: &dyn Comm, timer: &PhaseTimer, keys: &[&str]) -> (JsonObject, JsonObject) {
    let total: f64 = timer.waits().iter().map(|p| p.1).sum();
    let own: Vec<f64> = keys
        .iter()
        .map(|k| timer.wait_of(k))
        .chain([total])
        .collect();
    // One reduction: the maxima, and the minima as maxima of the negatives.
    let mut v: Vec<f64> = own.iter().copied().chain(own.iter().map(|x| -x)).collect();
    comm.max_f64(&mut v);
    let n = own.len();
    let (mut lo, mut hi) = (JsonObject::new(), JsonObject::new());
    for (i, k) in keys.iter().chain(&["total"]).enumerate() {
        lo.num(k, -v[n + i]);
        hi.num(k, v[i]);
    }
    (lo, hi)
}

/// Bytes exchanged with other ranks per phase, for `--stats`: the maximum
/// over ranks of sent + received, the maximum of sent alone, and the sums
/// over all ranks of sent and received (equal when every message arrived).
/// Collective.
fn comm_stats(
    comm: &dyn Comm,
    timer: &PhaseTimer,
    keys: &[&str],
) -> (JsonObject, JsonObject, JsonObject) {
    let total = timer
        .traffic()
        .iter()
        .fold(Traffic::default(), |acc, p| acc + p.1);
    let per_phase: Vec<Traffic> = keys
        .iter()
        .map(|k| timer.traffic_of(k))
        .chain([total])
        .collect();
    let mut max: Vec<u64> = per_phase.iter().flat_map(|t| [t.total(), t.sent]).collect();
    comm.max_u64(&mut max);
    let mut sums = [total.sent, total.received];
    comm.sum_u64(&mut sums);
    let (mut both, mut sent, mut sum) = (JsonObject::new(), JsonObject::new(), JsonObject::new());
    for (i, k) in keys.iter().chain(&["total"]).enumerate() {
        both.int(k, max[2 * i]);
        sent.int(k, max[2 * i + 1]);
    }
    sum.int("sent", sums[0]).int("received", sums[1]);
    (both, sent, sum)
}

/// The `check` command: every rank diagnoses the surface (it is cheap) and
/// rank 0 prints the report and writes the JSON.
fn run_check(comm: CommRef, o: &Options) -> Result<()> {
    let start = std::time::Instant::now();
    let surface = agree(&*comm, load_surface(&o.surface))?;
    let read = start.elapsed().as_secs_f64();
    let report = diagnose(&surface);
    let diagnosed = start.elapsed().as_secs_f64() - read;
    let (rule, why) = InsideRule::auto_choice(&report);
    if comm.rank() == 0 && !o.quiet {
        println!(
            "octmesh check: {} ({} triangles)",
            o.surface, report.triangles
        );
        println!("{report}");
        println!("  inside rule auto: {} ({why})", rule.name());
        println!("  read {read:.3} s | diagnose {diagnosed:.3} s (rank 0)");
    }
    if let Some(path) = &o.json {
        // The report's object with the rule auto picks as a last field.
        let mut json = report.to_json();
        if let Some(end) = json.rfind("\n}") {
            json.insert_str(
                end,
                &format!(",\n  \"auto_inside_rule\": \"{}\"", rule.name()),
            );
        }
        let written = if comm.rank() == 0 {
            std::fs::write(path, json)
                .map_err(|e| Error::io(format!("cannot write '{}': {e}", path.display())))
        } else {
            Ok(())
        };
        agree(&*comm, written)?;
    }
    Ok(())
}

/// Keeps freed memory in the process: the pipeline frees and reallocates
/// arrays of several GB, and returning them to the kernel makes every
/// reuse pay for zeroing fresh pages again.
fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only changes allocator tuning; called before any
    // threads exist.
    unsafe {
        libc::mallopt(libc::M_MMAP_MAX, 0);
        libc::mallopt(libc::M_TRIM_THRESHOLD, i32::MAX);
    }
}

fn main() -> ExitCode {
    keep_freed_memory();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(universe) = mpi::initialize() else {
        eprintln!("octmesh: error: MPI was already initialised");
        return ExitCode::FAILURE;
    };
    let comm: CommRef = Rc::new(MpiComm::new(universe.world()));
    let (rank, size) = (comm.rank(), comm.size());
    let result = parse_args(&args).and_then(|o| match o.command {
        Command::Check => run_check(comm.clone(), &o),
        _ => run(comm.clone(), &o),
    });
    // Report before MPI_Finalize: once one rank exits non-zero, mpirun may
    // kill the others before they print.
    let code = match &result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            if e.message().starts_with("usage:") {
                if rank == 0 {
                    eprint!("{}", e.message());
                }
            } else {
                // One write per line so that ranks' lines do not interleave.
                let line = format!("octmesh: error [rank {rank} of {size}]: {}\n", e.message());
                let _ = std::io::stderr().write_all(line.as_bytes());
            }
            ExitCode::from(2)
        }
    };
    let _ = std::io::stderr().flush();
    if result.is_err() {
        // Every rank has printed before any rank exits: mpirun stops the job
        // at the first non-zero exit.
        comm.barrier();
    }
    drop(comm);
    drop(universe);
    code
}
