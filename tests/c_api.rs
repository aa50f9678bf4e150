//! The C ABI from C: small programs in `tests/c` compiled with `mpicc`
//! against `include/octmesh.h` and the `liboctmesh.so` of this build, run
//! under `mpirun` on 1 and 2 ranks.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use common::{
    compile_c_test as compile, deps_dir, mpirun, python_with_meshio, repo, require, run_with_limit,
    scratch, stage_library, Oracle,
};

/// Compiles `tests/c/NAME.c` against this build's library, staged in the
/// scratch directory `c_api_NAME`: (that directory, the program).
fn c_program(name: &str) -> (PathBuf, PathBuf) {
    let dir = scratch(&format!("c_api_{name}"));
    let lib = dir.join("lib");
    stage_library(&deps_dir(), &lib);
    let exe = compile(name, &lib, &dir);
    (dir, exe)
}

fn run_ok(np: usize, exe: &Path, args: &[&str]) -> String {
    let out = mpirun(np, exe, args, Duration::from_secs(300));
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{} on {np} ranks failed:\n{stdout}\n{}",
        exe.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

fn line_starting<'a>(text: &'a str, prefix: &str) -> &'a str {
    text.lines()
        .find(|l| l.starts_with(prefix))
        .unwrap_or_else(|| panic!("no line starting with {prefix} in:\n{text}"))
}

/// Checks the PVTU written with point fields by `pipeline.c` against its
/// line `FIELDS points=P x_sum=S x_min=A x_max=B`, through
/// `tools/check_vtu.py` (meshio).
fn check_fields(pvtu: &Path, line: &str) {
    let out = Command::new(python_with_meshio())
        .arg(repo().join("tools").join("check_vtu.py"))
        .arg(pvtu)
        .output()
        .expect("run tools/check_vtu.py");
    assert!(
        out.status.success(),
        "check_vtu.py failed on {}: {}",
        pvtu.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    let want = |key: &str| -> f64 {
        line.split_whitespace()
            .find_map(|w| w.strip_prefix(&format!("{key}=")))
            .unwrap_or_else(|| panic!("no {key} in {line}"))
            .parse()
            .unwrap()
    };
    let points = want("points");
    assert_eq!(j["points"].as_f64(), Some(points), "{line}\n{j}");
    let f = &j["fields"];
    assert_eq!(f.as_object().map(|o| o.len()), Some(2), "{j}");
    let x = &f["x"];
    let sum = x["sum"].as_f64().unwrap();
    let tol = 1e-9 * (1.0 + want("x_sum").abs() + points);
    assert!((sum - want("x_sum")).abs() <= tol, "x sum {sum}: {line}");
    assert_eq!(x["min"].as_f64(), Some(want("x_min")), "{line}\n{j}");
    assert_eq!(x["max"].as_f64(), Some(want("x_max")), "{line}\n{j}");
    // The sphere lies in [-1, 1]^3, and the mesh touches both sides.
    assert!(want("x_min") < -0.5 && want("x_max") > 0.5, "{line}");
    let one = &f["one"];
    assert_eq!(one["sum"].as_f64(), Some(points), "{j}");
    assert_eq!(
        (one["min"].as_f64(), one["max"].as_f64()),
        (Some(1.0), Some(1.0)),
        "{j}"
    );
}

#[test]
fn pipeline_from_c_on_1_and_2_ranks() {
    let (dir, exe) = c_program("pipeline");
    let mut sphere = Vec::new();
    let mut callback = Vec::new();
    for np in [1, 2] {
        let pvtu = dir.join(format!("sphere_np{np}.pvtu"));
        let fields = dir.join(format!("fields_np{np}.pvtu"));
        let out = run_ok(
            np,
            &exe,
            &[pvtu.to_str().unwrap(), fields.to_str().unwrap()],
        );
        assert_eq!(out.matches("PIPELINE OK").count(), np, "{out}");
        assert!(pvtu.is_file(), "{} not written", pvtu.display());
        for r in 0..np {
            assert!(dir.join(format!("sphere_np{np}_{r:04}.vtu")).is_file());
        }
        check_fields(&fields, line_starting(&out, "FIELDS"));
        sphere.push(line_starting(&out, "SPHERE").to_string());
        callback.push(line_starting(&out, "CALLBACK").to_string());
    }
    // Global counts do not depend on the number of ranks.
    assert_eq!(sphere[0], sphere[1]);
    assert_eq!(callback[0], callback[1]);
    // ... and equal those of the octmesh command on the same input, whose
    // Abaqus, Gmsh and Exodus files are those of the C API, byte for byte
    // (a CGNS file holds HDF5 modification times: tests/exchange_files.rs
    // compares contents).
    let (inp, msh, exo) = (
        dir.join("cli.inp"),
        dir.join("cli.msh"),
        dir.join("cli.exo"),
    );
    let cli = common::octmesh_ok(
        1,
        &[
            "mesh",
            "sphere",
            "--level",
            "5",
            "--keep",
            "inside",
            "--abaqus",
            inp.to_str().unwrap(),
            "--gmsh",
            msh.to_str().unwrap(),
            "--exodus",
            exo.to_str().unwrap(),
        ],
    );
    let conforming = dir.join("cli_conforming.msh");
    common::octmesh_ok(
        1,
        &[
            "mesh",
            "sphere",
            "--level",
            "5",
            "--keep",
            "inside",
            "--conforming",
            "--gmsh",
            conforming.to_str().unwrap(),
            "--quiet",
        ],
    );
    for np in [1, 2] {
        for (name, cli_file) in [("conforming", &conforming), ("hanging", &msh)] {
            let c_file = dir.join(format!("sphere_np{np}.pvtu_{name}.msh"));
            assert!(
                std::fs::read(&c_file).unwrap() == std::fs::read(cli_file).unwrap(),
                "{} differs from the command's {}",
                c_file.display(),
                cli_file.display()
            );
        }
        let cgns = dir.join(format!("sphere_np{np}.pvtu.cgns"));
        assert!(cgns.is_file(), "{} not written", cgns.display());
        for (ext, cli_file) in [("inp", &inp), ("msh", &msh), ("exo", &exo)] {
            let c_file = dir.join(format!("sphere_np{np}.pvtu.{ext}"));
            assert!(
                std::fs::read(&c_file).unwrap() == std::fs::read(cli_file).unwrap(),
                "{} differs from the command's {}",
                c_file.display(),
                cli_file.display()
            );
        }
    }
    let cli = String::from_utf8_lossy(&cli.stdout).into_owned();
    let nums = |line: &str| -> Vec<u64> {
        line.split(|c: char| !c.is_ascii_digit())
            .filter(|w| !w.is_empty())
            .map(|w| w.parse().unwrap())
            .collect()
    };
    let cli_line = cli
        .lines()
        .map(str::trim)
        .find(|l| l.starts_with("elements"))
        .expect("elements line");
    let c = nums(cli_line);
    // elements, independent, face, edge (ghosts last).
    let f = nums(&sphere[0]);
    assert_eq!(
        &f[..4],
        &c[..4],
        "C API: {}\ncommand: {cli_line}",
        sphere[0]
    );
}

/// Faces, cell halo, boundary and OpenFOAM output through the C API: the
/// program checks the arrays against each other and MPI exchanges; the
/// global counts it prints must not depend on the number of ranks.
/// `zones.c` on 1 and 2 ranks: its own checks pass, its zone counts are
/// the same on both, the case it wrote has the zones in `cellZones`, and
/// its Gmsh file has the bytes of the command's with the same settings.
#[test]
fn zones_from_c_on_1_and_2_ranks() {
    let (dir, exe) = c_program("zones");
    let mut lines = Vec::new();
    for np in [1, 2] {
        let case = dir.join(format!("case{np}"));
        let msh = dir.join(format!("c{np}.msh"));
        let out = run_ok(np, &exe, &[case.to_str().unwrap(), msh.to_str().unwrap()]);
        lines.push(line_starting(&out, "ZONES ").to_string());
        let cz = match np {
            1 => case.join("constant/polyMesh/cellZones"),
            _ => case.join("processor1/constant/polyMesh/cellZones"),
        };
        let text = std::fs::read_to_string(&cz).unwrap();
        for z in ["inside", "outside", "east"] {
            assert!(
                text.contains(&format!("\n{z}\n{{")),
                "{z} in {}",
                cz.display()
            );
        }
        let cli = dir.join(format!("cli{np}.msh"));
        common::octmesh_ok(
            np,
            &[
                "mesh",
                "sphere",
                "--level",
                "4",
                "--keep",
                "all",
                "--zones",
                "--region",
                "box:0.5,-9,-9,9,9,9:0:zone=east",
                "--gmsh",
                cli.to_str().unwrap(),
                "--quiet",
            ],
        );
        assert!(
            std::fs::read(&msh).unwrap() == std::fs::read(&cli).unwrap(),
            "the C API's .msh differs from the command's on {np} ranks"
        );
    }
    assert_eq!(lines[0], lines[1]);
    println!("{}", lines[0]);
}

#[test]
fn faces_from_c_on_1_2_and_3_ranks() {
    let (dir, exe) = c_program("faces");
    let mut lines = Vec::new();
    for np in [1, 2, 3] {
        let case = dir.join(format!("case_np{np}"));
        let out = run_ok(np, &exe, &[case.to_str().unwrap()]);
        assert_eq!(out.matches("FACES OK").count(), np, "{out}");
        lines.push(line_starting(&out, "FACES internal").to_string());
    }
    assert_eq!(lines[0], lines[1], "np 1 and 2 differ");
    assert_eq!(lines[0], lines[2], "np 1 and 3 differ");
}

/// The memory budget of `octmesh_options_t`: refused before refining, and
/// stopped in the run when the estimate was too low, with the handle
/// usable after both (issue 22). The in-run budget is computed like the
/// command's test: between the estimate and the real size.
#[test]
fn memory_budget_from_c_on_1_and_2_ranks() {
    use octmesh::internals::run::budget::{BASE_BYTES, BYTES_PER_OCTANT_MESH, BYTES_PER_TRIANGLE};
    let (dir, exe) = c_program("budget");
    for np in [1, 2] {
        let stats = dir.join(format!("s{np}.json"));
        common::octmesh_ok(
            np,
            &[
                "mesh",
                "sphere",
                "--level",
                "6",
                "--quiet",
                "--stats",
                stats.to_str().unwrap(),
            ],
        );
        let j = common::json_file(&stats);
        let (estimate, real) = (
            common::int(&j, "estimated_octants"),
            common::int(&j, "octants_balanced"),
        );
        assert!(
            estimate < real,
            "the in-run case needs an estimate below the real count"
        );
        let base = BASE_BYTES + common::int(&j, "triangles") * BYTES_PER_TRIANGLE;
        let budget = base + (estimate + real) / 2 * BYTES_PER_OCTANT_MESH / np as u64;
        let out = run_ok(np, &exe, &[&budget.to_string()]);
        assert_eq!(out.matches("BUDGET OK").count(), np, "{out}");
    }
}

#[test]
fn misuse_from_c_on_1_and_2_ranks() {
    let (dir, exe) = c_program("misuse");
    let good = dir.join("sphere.stl");
    octmesh::internals::geometry::stl::write_stl_binary(
        &good,
        &octmesh::internals::geometry::shapes::default_sphere(),
    )
    .unwrap();
    let missing = dir.join("no-such-file.stl");
    for np in [1, 2] {
        let out = run_ok(
            np,
            &exe,
            &[good.to_str().unwrap(), missing.to_str().unwrap()],
        );
        assert_eq!(out.matches("MISUSE OK").count(), np, "{out}");
    }
}

/// Builds the library with the `ffi-test-panic` feature in its own target
/// directory and checks that a panic inside becomes a status.
#[test]
fn panic_becomes_a_status() {
    let root = repo();
    let target = root.join("target").join("ffi-test-panic");
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".to_string());
    let mut cmd = Command::new(cargo);
    cmd.current_dir(&root)
        .args([
            "build",
            "--release",
            "--lib",
            "--features",
            "ffi-test-panic",
        ])
        .arg("--target-dir")
        .arg(&target);
    let out = run_with_limit(cmd, Duration::from_secs(1200));
    assert!(
        out.status.success(),
        "cargo build --features ffi-test-panic failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let dir = scratch("c_api_panic");
    let lib = dir.join("lib");
    stage_library(&target.join("release"), &lib);
    let exe = compile("panic", &lib, &dir);
    for np in [1, 2] {
        let out = run_ok(np, &exe, &[]);
        assert_eq!(out.matches("PANIC OK").count(), np, "{out}");
    }
}

#[test]
fn leak_check_from_c_on_1_and_2_ranks() {
    let (_, exe) = c_program("leak");
    for np in [1, 2] {
        let out = run_ok(np, &exe, &[]);
        assert_eq!(out.matches("LEAK OK").count(), np, "{out}");
    }
}

/// Point location from C: own leaves found on their rank, the same grid
/// answers on 1 and 2 ranks.
#[test]
fn point_location_from_c_on_1_and_2_ranks() {
    let (_, exe) = c_program("search");
    let mut sums = Vec::new();
    for np in [1, 2] {
        let out = run_ok(np, &exe, &[]);
        assert_eq!(out.matches("SEARCH OK").count(), np, "{out}");
        sums.push(line_starting(&out, "SEARCH sum=").to_string());
    }
    assert_eq!(sums[0], sums[1], "np 1 and 2 differ");
}

/// Refinement controls of one case: max level, feature angle, min level,
/// distance bands (`D:L,...` or `-`), regions.
type Controls = (
    &'static str,
    &'static str,
    &'static str,
    &'static str,
    &'static [&'static str],
);

/// A box domain in the settings' words: corners, then root cells.
const BOX: &str = "box:-1.5,-0.5,-0.5,1.5,0.5,0.5:3,1,1";

/// The C API and the command (through a case file from `--print-case`) on
/// the same settings give the same global counts.
#[test]
fn the_c_api_and_the_command_agree_on_the_same_settings() {
    let (dir, exe) = c_program("settings");
    // (surface, level, keep, cut rule, inside rule, balance, fit) as the
    // command's words and as the C constants' values.
    // The sphere as two solids, `top` and `bottom`.
    let halves = dir.join("halves.stl");
    common::write_sphere_solids(&halves, &[("top", Some(true)), ("bottom", Some(false))]);
    let halves = halves.to_str().unwrap();
    let with_hull = format!("{halves}+hull");
    let cases: &[([&str; 7], [&str; 7])] = &[
        (
            ["sphere", "5", "inside", "center", "auto", "corner", "0.7"],
            ["sphere", "5", "1", "0", "0", "3", "0.7"],
        ),
        (
            ["torus", "5", "outside", "all", "winding", "edge", "0.5"],
            ["torus", "5", "2", "1", "2", "2", "0.5"],
        ),
        (
            ["sphere", "4", "all", "none", "parity", "corner", "0.9"],
            ["sphere", "4", "0", "2", "1", "3", "0.9"],
        ),
        // A box of 3 x 1 x 1 root cells cutting the sphere: levels count
        // from the root cells in both.
        (
            ["sphere", "3", "outside", "center", "auto", "corner", BOX],
            ["sphere", "3", "2", "0", "0", "3", BOX],
        ),
        // The top solid with its own levels (curvature up to 6).
        (
            [halves, "3", "inside", "center", "auto", "corner", "0.7"],
            [halves, "3", "1", "0", "0", "3", "0.7"],
        ),
        // The halves and the built-in hull as three parts, the hull finer.
        (
            [&with_hull, "3", "all", "center", "auto", "corner", "0.7"],
            [&with_hull, "3", "0", "0", "0", "3", "0.7"],
        ),
    ];
    // Refinement controls: (max level, feature angle, min level, bands,
    // regions) for the command and for `octmesh_octree_refine_curvature`
    // and `octmesh_octree_refine_regions`; none for the first cases.
    let controls: &[Option<Controls>] = &[
        None,
        Some((
            "7",
            "20",
            "3",
            "0.3:6,0.8:5",
            &["box:-2,-2,-2,0,2,0:5", "sphere:1,0,0,0.5:6:outside"],
        )),
        Some(("4", "30", "2", "-", &["cylinder:-1,0,0,1,0,0,0.4:6"])),
        Some(("5", "25", "1", "0.2:4", &["box:0,-0.5,-0.5,1.5,0.5,0.5:3"])),
        Some((
            "3",
            "10",
            "0",
            "-",
            &["part:top=5:6", "sphere:0,0,-1,0.3:5"],
        )),
        Some(("3", "30", "0", "-", &["part:hull=5:6"])),
    ];
    for (i, (words, values)) in cases.iter().enumerate() {
        let [surface, level, keep, cut, inside, balance, fit] = *words;
        let level_range;
        // A+B: the first surface, then --surface for the others.
        let mut files = surface.split('+');
        let mut args = vec![
            "mesh",
            files.next().unwrap(),
            "--keep",
            keep,
            "--cut-rule",
            cut,
            "--inside",
            inside,
            "--balance",
            balance,
        ];
        for other in files {
            args.extend(["--surface", other]);
        }
        match fit.strip_prefix("box:").and_then(|b| b.split_once(':')) {
            Some((bbox, roots)) => args.extend(["--box", bbox, "--roots", roots]),
            None => args.extend(["--fit", fit]),
        }
        let mut values: Vec<&str> = values.to_vec();
        match controls[i] {
            None => args.extend(["--level", level]),
            Some((max, angle, min, bands, regions)) => {
                level_range = format!("{level}:{max}");
                args.extend(["--level", &level_range, "--feature-angle", angle]);
                args.extend(["--min-level", min]);
                if bands != "-" {
                    args.extend(["--distance", bands]);
                }
                for r in regions {
                    match r.strip_prefix("part:") {
                        Some(p) => args.extend(["--surface-level", p]),
                        None => args.extend(["--region", r]),
                    }
                }
                values.extend([max, angle, min, bands]);
                values.extend(regions.iter());
            }
        }
        let case = dir.join(format!("case{i}.toml"));
        let printed = common::octmesh_ok(1, &[&args[..], &["--print-case"]].concat());
        std::fs::write(&case, &printed.stdout).unwrap();
        let stats = dir.join(format!("stats{i}.json"));
        common::octmesh_ok(
            2,
            &[
                "mesh",
                case.to_str().unwrap(),
                "--quiet",
                "--stats",
                stats.to_str().unwrap(),
            ],
        );
        let j = common::json_file(&stats);
        let cli: Vec<u64> = [
            "elements",
            "independent_nodes",
            "face_hanging_nodes",
            "edge_hanging_nodes",
        ]
        .iter()
        .map(|k| common::int(&j, k))
        .collect();
        for np in [1, 2] {
            let out = run_ok(np, &exe, &values);
            let c: Vec<u64> = line_starting(&out, "COUNTS")
                .split_whitespace()
                .skip(1)
                .map(|w| w.parse().unwrap())
                .collect();
            assert_eq!(
                c, cli,
                "{args:?}: the C API on {np} rank(s) against the command"
            );
        }
    }
}

/// Snapping through `octmesh_mesh_snap` (`tests/c/snap.c`) on 1 and 2
/// ranks: the report equal to the command's statistics on the same
/// settings.
#[test]
fn snap_from_c_equals_the_command() {
    let (dir, exe) = c_program("snap");
    let stats = dir.join("stats.json");
    common::octmesh_ok(
        1,
        &[
            "mesh",
            "sphere",
            "--level",
            "5",
            "--keep",
            "outside",
            "--snap",
            "--quiet",
            "--stats",
            stats.to_str().unwrap(),
        ],
    );
    let r = common::json_file(&stats)["snap"].clone();
    for np in [1, 2] {
        let out = run_ok(np, &exe, &[]);
        assert_eq!(out.matches("SNAP OK").count(), np, "{out}");
        let line = line_starting(&out, "SNAP surface");
        let field = |key: &str| -> &str {
            line.split_whitespace()
                .find_map(|w| w.strip_prefix(&format!("{key}=")))
                .unwrap_or_else(|| panic!("no {key} in {line}"))
        };
        for (key, json) in [
            ("surface", "surface_nodes"),
            ("snapped", "snapped"),
            ("partial", "partial"),
            ("unsnapped", "unsnapped"),
            ("reported", "reported_elements"),
        ] {
            assert_eq!(
                field(key).parse::<u64>().ok(),
                r[json].as_u64(),
                "np {np}: {key}"
            );
        }
        let c: f64 = field("sj_min").parse().unwrap();
        let j = r["min_scaled_jacobian"].as_f64().unwrap();
        assert!((c - j).abs() <= 1e-15 * j.abs(), "np {np}: {c} against {j}");
    }
}

/// The mesh's quality through `octmesh_mesh_get_quality` (`tests/c/quality.c`)
/// on 1 and 2 ranks: every figure equal to the command's statistics on the
/// same settings.
#[test]
fn quality_from_c_equals_the_command() {
    let (dir, exe) = c_program("quality");
    let stats = dir.join("stats.json");
    common::octmesh_ok(
        1,
        &[
            "mesh",
            "sphere",
            "--level",
            "5",
            "--keep",
            "outside",
            "--quiet",
            "--quality",
            "--stats",
            stats.to_str().unwrap(),
        ],
    );
    let q = common::json_file(&stats)["quality"].clone();
    let histogram: Vec<String> = q["scaled_jacobian_histogram"]["counts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c.to_string())
        .collect();
    for np in [1, 2] {
        let out = run_ok(np, &exe, &[]);
        assert_eq!(out.matches("QUALITY OK").count(), np, "{out}");
        let line = line_starting(&out, "QUALITY elements");
        let field = |key: &str| -> &str {
            line.split_whitespace()
                .find_map(|w| w.strip_prefix(&format!("{key}=")))
                .unwrap_or_else(|| panic!("no {key} in {line}"))
        };
        for (key, json) in [
            ("elements", "elements"),
            ("inverted", "inverted_elements"),
            ("internal_faces", "internal_faces"),
        ] {
            assert_eq!(
                field(key).parse::<u64>().ok(),
                q[json].as_u64(),
                "np {np}: {key}"
            );
        }
        for (key, json) in [
            ("sj_min", "scaled_jacobian_min"),
            ("nonorth_max", "non_orthogonality_max"),
            ("nonorth_average", "non_orthogonality_average"),
            ("skewness_max", "skewness_max"),
        ] {
            // serde_json's default float parsing may be one unit in the
            // last place off (no float_roundtrip feature); C printed 17
            // digits, which read back exactly.
            let (c, j) = (
                field(key).parse::<f64>().unwrap(),
                q[json].as_f64().unwrap(),
            );
            assert!(
                (c - j).abs() <= 2.0 * f64::EPSILON * j.abs(),
                "np {np}: {key}: C {c}, command {j}"
            );
        }
        assert_eq!(field("histogram"), histogram.join(","), "np {np}");
    }
}

/// `tests/c/adapt.c`: the moving sphere of `tests/adapt_p4est.rs` (root to
/// level 5) through `octmesh_octree_adapt`, `_refine_once`, `_coarsen` and
/// `_partition_for_coarsening`: leaves and per-rank counts equal to p4est's
/// after every step.
#[test]
fn adaptation_from_c_equals_p4est_on_1_to_3_ranks() {
    let (dir, exe) = c_program("adapt");
    common::p4est_ref();
    let reference = repo().join("tools/p4est_ref/octmesh_p4est_adapt");
    let counts = |d: &Path| -> Vec<String> {
        let text = std::fs::read_to_string(d.join("counts.txt")).expect("counts.txt");
        text.lines().map(str::to_string).collect()
    };
    for np in [1, 2, 3] {
        let (ours, theirs) = (dir.join(format!("c{np}")), dir.join(format!("p4est{np}")));
        std::fs::create_dir_all(&ours).unwrap();
        std::fs::create_dir_all(&theirs).unwrap();
        let out = run_ok(np, &exe, &[ours.to_str().unwrap()]);
        assert_eq!(out.matches("ADAPT OK").count(), np, "{out}");
        let args = ["--steps", "10", "--level", "0", "--max-level", "5", "--out"];
        let mut args = args.to_vec();
        args.push(theirs.to_str().unwrap());
        run_ok(np, &reference, &args);
        let (a, b) = (counts(&ours), counts(&theirs));
        // The reference also has the initial root (step 0).
        assert_eq!(a.len(), 10);
        assert_eq!(
            a[..],
            b[1..],
            "np {np}: step, refined, coarsened, leaves, per rank"
        );
        for step in 1..=10 {
            let x = common::leaves(&ours.join(format!("step_{step}.txt")));
            let y = common::leaves(&theirs.join(format!("step_{step}.bin")));
            assert!(x == y, "np {np}, step {step}: leaves differ from p4est's");
        }
        let coarsened: u64 = a
            .iter()
            .map(|l| l.split(' ').nth(2).unwrap().parse::<u64>().unwrap())
            .sum();
        assert!(coarsened > 0, "np {np}: nothing coarsened");
    }
}

/// `tests/c/leaf_data.c`: 16 bytes of user data per leaf through the
/// `_ext` adaptation and balance calls and both partitions, each leaf's
/// data its own octant after every call; size rules; a replace callback
/// failing on one rank fails every rank with the leaves and data as before.
#[test]
fn leaf_data_from_c_on_1_to_3_ranks() {
    let (_, exe) = c_program("leaf_data");
    for np in [1, 2, 3] {
        let out = run_ok(np, &exe, &[]);
        assert_eq!(out.matches("LEAF DATA OK").count(), np, "{out}");
        println!("np {np}: {}", line_starting(&out, "LEAF DATA refines"));
    }
}

/// `tests/c/transfer.c`: fields across six adaptation steps with the
/// previous mesh kept: a trilinear nodal field arrives exactly, an element
/// field's integral is conserved, the element map agrees with the levels;
/// bad calls fail on every rank.
#[test]
fn field_transfer_from_c_on_1_to_3_ranks() {
    let (_, exe) = c_program("transfer");
    for np in [1, 2, 3] {
        let out = run_ok(np, &exe, &[]);
        assert_eq!(out.matches("TRANSFER OK").count(), np, "{out}");
        println!("np {np}: {}", line_starting(&out, "TRANSFER refined"));
    }
}

/// `tests/fortran/leaf_data.f90`: the user data from Fortran (the module
/// `fortran/octmesh.f90` and its C shim built here with `mpif90` and
/// `mpicc`): a bind(c) replace function conserves the integral through the
/// `_ext` calls and both partitions; a failing one changes nothing.
#[test]
fn leaf_data_from_fortran_on_1_to_3_ranks() {
    let fortran = Oracle::Program {
        name: "mpif90",
        package: "gfortran and libopenmpi-dev",
    };
    if require(fortran).is_none() {
        return;
    }
    let dir = scratch("c_api_leaf_data_fortran");
    let lib = dir.join("lib");
    stage_library(&deps_dir(), &lib);
    let root = repo();
    let run = |prog: &str, args: Vec<std::ffi::OsString>| {
        let mut cmd = Command::new(prog);
        cmd.current_dir(&dir).args(args);
        let out = run_with_limit(cmd, Duration::from_secs(120));
        assert!(
            out.status.success(),
            "{prog} failed:\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
    };
    run(
        "mpicc",
        vec![
            "-c".into(),
            "-I".into(),
            root.join("include").into(),
            root.join("fortran/octmesh_f.c").into(),
            "-o".into(),
            "octmesh_f.o".into(),
        ],
    );
    run(
        "mpif90",
        vec![
            "-c".into(),
            root.join("fortran/octmesh.f90").into(),
            "-o".into(),
            "octmesh.o".into(),
        ],
    );
    run(
        "mpif90",
        vec![
            root.join("tests/fortran/leaf_data.f90").into(),
            "octmesh.o".into(),
            "octmesh_f.o".into(),
            "-o".into(),
            "leaf_data_f".into(),
            "-L".into(),
            lib.clone().into(),
            format!("-Wl,-rpath,{}", lib.display()).into(),
            "-loctmesh".into(),
        ],
    );
    for np in [1, 2, 3] {
        let ckpt = dir.join(format!("np{np}.ckpt"));
        let out = run_ok(np, &dir.join("leaf_data_f"), &[ckpt.to_str().unwrap()]);
        assert_eq!(out.matches("FORTRAN LEAF DATA OK").count(), np, "{out}");
    }
}

/// `tests/cpp/leaf_data.cpp`: the user data through the C++ wrapper
/// (`include/octmesh.hpp`, C++14): lambdas as callbacks and replace
/// callables, every leaf's data its own octant after each call, a throwing
/// replace turned into `octmesh::Error` on every rank.
#[test]
fn leaf_data_from_cpp_on_1_to_3_ranks() {
    let cpp = Oracle::Program {
        name: "mpicxx",
        package: "g++ and libopenmpi-dev",
    };
    if require(cpp).is_none() {
        return;
    }
    let dir = scratch("c_api_leaf_data_cpp");
    let lib = dir.join("lib");
    stage_library(&deps_dir(), &lib);
    let root = repo();
    let exe = dir.join("leaf_data_cpp");
    let mut cmd = Command::new("mpicxx");
    cmd.args(["-std=c++14", "-Wall", "-Wextra", "-Werror", "-I"])
        .arg(root.join("include"))
        .arg(root.join("tests/cpp/leaf_data.cpp"))
        .arg("-o")
        .arg(&exe)
        .arg("-L")
        .arg(&lib)
        .arg(format!("-Wl,-rpath,{}", lib.display()))
        .arg("-loctmesh");
    let out = run_with_limit(cmd, Duration::from_secs(180));
    assert!(
        out.status.success(),
        "mpicxx failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for np in [1, 2, 3] {
        let ckpt = dir.join(format!("np{np}.ckpt"));
        let out = run_ok(np, &exe, &[ckpt.to_str().unwrap()]);
        assert_eq!(out.matches("CPP LEAF DATA OK").count(), np, "{out}");
    }
}
