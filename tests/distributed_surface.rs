//! The distributed surface (`--distributed-surface`: each rank keeps the
//! triangles near its part of the domain) against every rank holding the
//! whole surface, on 1 to 4 ranks: the same leaves, the same Gmsh file
//! (classes decide which leaves are kept) and the same OpenFOAM case, for a
//! binary sphere, the bunny (also with curvature levels and a distance
//! band, and snapped), the dragon (also snapped, fluid and solid) and the
//! open bunny under parity, with each rank's VTU;
//! runs that need the whole surface (the winding rule, a file of several
//! solids) keep it whole, say so in their statistics, and give the same
//! files. The dragon's surface on 8 ranks costs each rank at most a quarter
//! of its cost on one rank; a truncated file is the same error on every
//! rank.
//!
//! Run by `cargo test`, this program launches the command under `mpirun`.

mod common;

use std::path::{Path, PathBuf};
use std::time::Duration;

use octmesh::internals::geometry::stl::write_stl_binary;

/// One comparison: a surface file, its level and the options of both runs,
/// and whether the distributed run may distribute (on several ranks).
struct Case {
    name: &'static str,
    file: PathBuf,
    level: &'static str,
    args: Vec<&'static str>,
    /// `--keep`.
    keep: &'static str,
    distributes: bool,
}

fn main() {
    common::runner::main(
        "distributed_surface",
        |mode| panic!("no child mode {mode}"),
        |r| {
            let dir = common::scratch("distributed_surface");
            let sphere = dir.join("sphere.stl");
            let s = octmesh::internals::geometry::shapes::default_sphere();
            write_stl_binary(&sphere, &s).unwrap();
            let halves = dir.join("halves.stl");
            common::write_sphere_solids(&halves, &[("top", Some(true)), ("bottom", Some(false))]);
            let parity = vec!["--inside", "parity"];
            let mut cases = vec![
                Case {
                    name: "sphere",
                    file: sphere.clone(),
                    level: "5",
                    args: parity.clone(),
                    keep: "outside",
                    distributes: true,
                },
                Case {
                    name: "solids",
                    file: halves,
                    level: "5",
                    args: parity.clone(),
                    keep: "outside",
                    distributes: false,
                },
            ];
            // Not a test of its own, so that a filter picks these cases too
            // (a missing model still fails under CI).
            let models = ["bunny.stl", "dragon.stl", "bunny_open.stl"].map(common::shared_model);
            if let [Some(bunny), Some(dragon), Some(open)] = models {
                cases.push(Case {
                    name: "bunny",
                    file: bunny.clone(),
                    level: "7",
                    args: parity.clone(),
                    keep: "outside",
                    distributes: true,
                });
                cases.push(Case {
                    name: "bunny_bands",
                    file: bunny.clone(),
                    level: "6:8",
                    args: vec![
                        "--inside",
                        "parity",
                        "--feature-angle",
                        "20",
                        "--distance",
                        "0.02:7",
                    ],
                    keep: "outside",
                    distributes: true,
                });
                cases.push(Case {
                    name: "dragon",
                    file: dragon.clone(),
                    level: "7",
                    args: parity.clone(),
                    keep: "outside",
                    distributes: true,
                });
                cases.push(Case {
                    name: "open_parity",
                    file: open.clone(),
                    level: "7",
                    args: parity.clone(),
                    keep: "outside",
                    distributes: true,
                });
                cases.push(Case {
                    name: "open_winding",
                    file: open,
                    level: "7",
                    args: vec!["--inside", "winding"],
                    keep: "outside",
                    distributes: false,
                });
                // Snapped, fluid and solid: each rank holds the triangles
                // within the snap's reach of its cells.
                let snap = vec!["--inside", "parity", "--snap"];
                for (name, file, level, keep) in [
                    ("bunny_snap", &bunny, "7", "outside"),
                    ("dragon_snap", &dragon, "7", "outside"),
                    ("dragon_snap_solid", &dragon, "6", "inside"),
                ] {
                    cases.push(Case {
                        name,
                        file: file.clone(),
                        level,
                        args: snap.clone(),
                        keep,
                        distributes: true,
                    });
                }
                r.test(
                    "the dragon's surface on 8 ranks: at most a quarter of one rank's",
                    || dragon_memory(&dir, &dragon),
                );
            }
            for c in &cases {
                r.test(
                    &format!("{}: the same leaves, mesh and case on 1 to 4 ranks", c.name),
                    || same_as_whole(&dir, c),
                );
            }
            r.test(
                "a truncated binary file: the same error on every rank",
                || {
                    let b = std::fs::read(&sphere).unwrap();
                    let f = dir.join("short.stl");
                    std::fs::write(&f, &b[..b.len() - 75]).unwrap();
                    for np in 2..=4 {
                        let args = ["octree", f.to_str().unwrap(), "--level", "3"];
                        let limit = Duration::from_secs(300);
                        let whole = common::mpirun(np, &common::octmesh_bin(), &args, limit);
                        let mut d = args.to_vec();
                        d.extend(["--distributed-surface", "--inside", "parity"]);
                        let dist = common::mpirun(np, &common::octmesh_bin(), &d, limit);
                        let a = common::rank_error_lines(&whole, np, "whole");
                        let b = common::rank_error_lines(&dist, np, "distributed");
                        assert_eq!(a, b);
                        assert!(a[0].contains("truncated"), "{}", a[0]);
                    }
                },
            );
        },
    );
}

/// The files of one run of `mesh` on `np` ranks, `tag` naming them.
struct Run {
    leaves: Vec<u8>,
    msh: Vec<u8>,
    case: Vec<(String, Vec<u8>)>,
    /// The PVTU and each rank's VTU.
    vtu: Vec<(String, Vec<u8>)>,
    stats: serde_json::Value,
}

fn run(dir: &Path, c: &Case, np: usize, distributed: bool) -> Run {
    let tag = format!("{}_{np}_{}", c.name, if distributed { "d" } else { "w" });
    let leaves = dir.join(format!("{tag}.txt"));
    let msh = dir.join(format!("{tag}.msh"));
    let case = dir.join(format!("{tag}_case"));
    let stats = dir.join(format!("{tag}.json"));
    let vtu = dir.join(format!("{tag}_vtu"));
    let _ = std::fs::remove_dir_all(&case);
    let _ = std::fs::remove_dir_all(&vtu);
    std::fs::create_dir_all(&vtu).unwrap();
    let pvtu = vtu.join("mesh.pvtu");
    let mut args = vec![
        "mesh",
        c.file.to_str().unwrap(),
        "--level",
        c.level,
        "--keep",
        c.keep,
        "--write-leaves",
        leaves.to_str().unwrap(),
        "--gmsh",
        msh.to_str().unwrap(),
        "--openfoam",
        case.to_str().unwrap(),
        "--out",
        pvtu.to_str().unwrap(),
        "--stats",
        stats.to_str().unwrap(),
        "--quiet",
    ];
    args.extend(c.args.iter().copied());
    if distributed {
        args.push("--distributed-surface");
    }
    common::octmesh_ok(np, &args);
    let mut files = Vec::new();
    collect(&case, &case, &mut files);
    files.sort();
    let mut vtus = Vec::new();
    collect(&vtu, &vtu, &mut vtus);
    vtus.sort();
    Run {
        vtu: vtus,
        leaves: std::fs::read(&leaves).unwrap(),
        msh: std::fs::read(&msh).unwrap(),
        case: files,
        stats: common::json_file(&stats),
    }
}

/// Every file under `dir`, by its path relative to `root`.
fn collect(root: &Path, dir: &Path, out: &mut Vec<(String, Vec<u8>)>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            collect(root, &p, out);
        } else {
            let rel = p.strip_prefix(root).unwrap().display().to_string();
            out.push((rel, std::fs::read(&p).unwrap()));
        }
    }
}

fn same_as_whole(dir: &Path, c: &Case) {
    let one = run(dir, c, 1, false);
    assert!(one.msh.len() > 1000, "{}: the mesh is nearly empty", c.name);
    for np in 1..=4 {
        let whole = if np == 1 {
            None
        } else {
            Some(run(dir, c, np, false))
        };
        let whole = whole.as_ref().unwrap_or(&one);
        let d = run(dir, c, np, true);
        let spread = d.stats["distributed_surface"].as_bool().unwrap();
        assert_eq!(spread, c.distributes && np > 1, "{} on {np} ranks", c.name);
        if spread {
            // Each rank held less than the whole surface.
            let held = common::int(&d.stats, "triangles_held");
            let all = common::int(&d.stats, "triangles");
            assert!(held < all, "{}: {held} of {all} triangles held", c.name);
        }
        assert!(
            d.leaves == whole.leaves,
            "{}: other leaves on {np} ranks",
            c.name
        );
        assert!(
            d.msh == one.msh,
            "{}: another Gmsh file on {np} ranks",
            c.name
        );
        let names = |r: &Run| r.case.iter().map(|f| f.0.clone()).collect::<Vec<_>>();
        assert_eq!(
            names(&d),
            names(whole),
            "{}: case files on {np} ranks",
            c.name
        );
        for (a, b) in d.case.iter().zip(&whole.case) {
            assert!(a.1 == b.1, "{}: {} differs on {np} ranks", c.name, a.0);
        }
        // The same ranks' pieces: as the whole surface's run on as many.
        assert_eq!(d.vtu.len(), whole.vtu.len(), "{}: VTU files", c.name);
        assert!(d.vtu.len() > np, "{}: no VTU files", c.name);
        for (a, b) in d.vtu.iter().zip(&whole.vtu) {
            assert!(a == b, "{}: {} differs on {np} ranks", c.name, a.0);
        }
        for k in ["kept_cells", "octants_balanced"] {
            assert_eq!(d.stats[k], whole.stats[k], "{}: {k}", c.name);
        }
    }
}

/// The dragon's surface cost per rank: the peak resident memory after
/// reading (one rank, whole surface) or after the first redistribution
/// (8 ranks, distributed), less the memory at the start.
fn dragon_memory(dir: &Path, dragon: &Path) {
    let cost = |np: usize, extra: &[&str]| -> u64 {
        let stats = dir.join(format!("dragon_memory_{np}.json"));
        let mut args = vec![
            "octree",
            dragon.to_str().unwrap(),
            "--level",
            "6",
            "--inside",
            "parity",
            "--stats",
            stats.to_str().unwrap(),
            "--quiet",
        ];
        args.extend(extra);
        common::octmesh_ok(np, &args);
        let s = common::json_file(&stats);
        let after = match s["rss_after_distribute_bytes"].as_u64() {
            Some(b) => b,
            None => common::int(&s, "rss_after_read_bytes"),
        };
        after - common::int(&s, "rss_start_bytes")
    };
    let one = cost(1, &[]);
    let eight = cost(8, &["--distributed-surface"]);
    assert!(
        eight * 4 <= one,
        "8 ranks: {eight} bytes per rank, one rank {one}"
    );
}
