//! The `octmesh` command: runs the pipeline on a surface, directly or under
//! `mpirun`, and reports a table of phases.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;
use std::rc::Rc;

use octmesh::comm::{agree, CommRef, MpiComm};
use octmesh::domain::{Domain, DEFAULT_FIT};
use octmesh::geometry::load_surface;
use octmesh::io::leaves::write_leaves;
use octmesh::refine::{construct_for_surface, SurfaceIndex, NO_LIMIT};
use octmesh::report::{peak_rss_bytes, JsonObject, PhaseTimer};
use octmesh::{Connectivity, Error, Result};

const USAGE: &str = "\
usage: octmesh octree <file.stl | sphere | torus> --level L [options]

Builds the surface-refined linear octree, partitions it over the MPI ranks
and 2:1-balances it. Leaves touching the surface are at level L (at most 18).

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
  --quiet               print nothing but errors
";

struct Options {
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
}

fn parse_args(args: &[String]) -> Result<Options> {
    if args.is_empty() || args[0] == "--help" || args[0] == "-h" {
        return Err(Error::invalid(USAGE));
    }
    if args[0] != "octree" {
        return Err(Error::invalid(format!(
            "unknown command '{}'\n{USAGE}",
            args[0]
        )));
    }
    let mut o = Options {
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
                let v = value(i, a)?;
                let n: Vec<f64> = v
                    .split(',')
                    .map(|s| s.trim().parse::<f64>())
                    .collect::<std::result::Result<_, _>>()
                    .map_err(|_| {
                        Error::invalid(format!("--domain expects X,Y,Z,SIDE, got '{v}'"))
                    })?;
                if n.len() != 4 {
                    return Err(Error::invalid(format!(
                        "--domain expects X,Y,Z,SIDE, got '{v}'"
                    )));
                }
                o.domain = Some(Domain::cube([n[0], n[1], n[2]], n[3])?);
            }
            "--max-octants" => {
                let v = value(i, a)?;
                o.max_octants = v.parse().map_err(|_| {
                    Error::invalid(format!("--max-octants expects an integer, got '{v}'"))
                })?;
            }
            "--stats" => o.stats = Some(value(i, a)?.into()),
            "--write-leaves" => o.write_leaves = Some(value(i, a)?.into()),
            "--write-refined" => o.write_refined = Some(value(i, a)?.into()),
            "--quiet" => {
                o.quiet = true;
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
    if o.level == u8::MAX {
        return Err(Error::invalid("--level is required"));
    }
    if o.level > octmesh::MAX_LEVEL {
        return Err(Error::invalid(format!(
            "level {} is above the maximum level {}",
            o.level,
            octmesh::MAX_LEVEL
        )));
    }
    Ok(o)
}

fn run_octree(comm: CommRef, o: &Options) -> Result<()> {
    let root = comm.rank() == 0 && !o.quiet;
    let mut timer = PhaseTimer::new();
    let say = |name: &str, t: &PhaseTimer, count: Option<u64>| {
        if root {
            let c = count.map(|c| c.to_string()).unwrap_or_default();
            println!(
                "  {name:<12} {:>10.3} {c:>14}",
                t.phases().last().map_or(0.0, |p| p.1)
            );
        }
    };

    let loaded = timer.time(
        &*comm,
        "read",
        || -> Result<(usize, Domain, SurfaceIndex)> {
            let surface = load_surface(&o.surface)?;
            let b = surface.bbox();
            let domain = match o.domain {
                Some(d) => d,
                None => Domain::around(b.min, b.max, o.fit)?,
            };
            let index = SurfaceIndex::new(&surface, &domain);
            Ok((surface.len(), domain, index))
        },
    );
    let (ntri, domain, index) = agree(&*comm, loaded)?;
    if root {
        println!(
            "octmesh octree: {} ({ntri} triangles), level {}, balance {}, {} rank(s)",
            o.surface,
            o.level,
            o.balance.map_or("none", |c| c.name()),
            comm.size()
        );
        println!(
            "  cube: origin ({:.6}, {:.6}, {:.6}), side {:.6}",
            domain.origin[0], domain.origin[1], domain.origin[2], domain.side
        );
        println!("  {:<12} {:>10} {:>14}", "phase", "time [s]", "leaves");
    }
    say("read", &timer, None);

    let mut tree = timer.time(&*comm, "construct", || {
        construct_for_surface(comm.clone(), &index, o.level)
    })?;
    say("construct", &timer, Some(tree.global_len()));
    timer.time(&*comm, "refine", || {
        tree.refine_surface(&index, o.level, o.max_octants)
    })?;
    let refined = tree.global_len();
    say("refine", &timer, Some(refined));
    timer.time(&*comm, "partition", || tree.partition())?;
    say("partition", &timer, Some(refined));
    if let Some(p) = &o.write_refined {
        write_leaves(&tree, p, "refined leaves")?;
    }
    if let Some(conn) = o.balance {
        timer.time(&*comm, "balance", || tree.balance(conn))?;
        say("balance", &timer, Some(tree.global_len()));
        timer.time(&*comm, "partition", || tree.partition())?;
        say("partition", &timer, Some(tree.global_len()));
    }
    let balanced = tree.global_len();
    if let Some(p) = &o.write_leaves {
        write_leaves(&tree, p, "balanced leaves")?;
    }
    let mut rss = [peak_rss_bytes()];
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
        for k in ["read", "construct", "refine", "partition", "balance"] {
            t.num(k, timer.get(k));
        }
        let mut j = JsonObject::new();
        j.str("command", "octree")
            .str("surface", &o.surface)
            .int("ranks", comm.size() as u64)
            .int("triangles", ntri as u64)
            .int("level", o.level as u64)
            .str("balance", o.balance.map_or("none", |c| c.name()))
            .int("octants_refined", refined)
            .int("octants_balanced", balanced)
            .obj("timings", &t)
            .int("peak_rss_bytes", rss[0])
            .num("domain_side", domain.side);
        let written = if comm.rank() == 0 {
            std::fs::write(path, j.to_json())
                .map_err(|e| Error::io(format!("cannot write '{}': {e}", path.display())))
        } else {
            Ok(())
        };
        agree(&*comm, written)?;
    }
    Ok(())
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(universe) = mpi::initialize() else {
        eprintln!("octmesh: error: MPI was already initialised");
        return ExitCode::FAILURE;
    };
    let comm: CommRef = Rc::new(MpiComm::new(universe.world()));
    let (rank, size) = (comm.rank(), comm.size());
    let result = parse_args(&args).and_then(|o| run_octree(comm.clone(), &o));
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
