//! One configuration for the command line and case files: a command line,
//! printed as a case file with `--print-case` and run from it, gives the
//! same results; bad configurations fail with one clear error on every
//! rank; a closed output pipe ends quietly.

mod common;

use std::process::{Command, Stdio};
use std::time::Duration;

use common::*;

/// Counts and volumes of a run's statistics: what must not depend on how
/// it was configured.
fn results(j: &serde_json::Value) -> Vec<(String, String)> {
    let keys = [
        "command",
        "level",
        "balance",
        "triangles",
        "octants_refined",
        "octants_balanced",
        "estimated_octants",
        "inside_rule",
        "inside_leaves",
        "outside_leaves",
        "cut_leaves",
        "leak",
        "elements",
        "independent_nodes",
        "face_hanging_nodes",
        "edge_hanging_nodes",
        "ghosts",
        "kept_cells",
        "kept_volume",
        "keep",
        "cut_rule",
        "surface_volume",
        "dropped_facets",
        "domain_side",
        "surface",
    ];
    keys.iter()
        .map(|k| {
            (
                k.to_string(),
                j.get(*k).map_or("-".into(), |v| v.to_string()),
            )
        })
        .collect()
}

#[test]
fn print_case_then_run_gives_the_same_results() {
    let dir = scratch("config_round_trip");
    let cases: &[&[&str]] = &[
        &[
            "octree",
            "sphere",
            "--level",
            "5",
            "--balance",
            "face",
            "--fit",
            "0.5",
        ],
        &[
            "octree",
            "torus",
            "--level",
            "5",
            "--inside",
            "winding",
            "--drop-degenerate",
        ],
        &[
            "octree",
            "sphere",
            "--level",
            "4",
            "--domain",
            "-2,-2,-2,4",
            "--max-octants",
            "100000",
            "--balance",
            "none",
            "--drop-duplicates",
        ],
        &[
            "mesh",
            "sphere",
            "--level",
            "5",
            "--keep",
            "inside",
            "--cut-rule",
            "all",
        ],
        &[
            "mesh",
            "torus",
            "--level",
            "5",
            "--keep",
            "outside",
            "--inside",
            "parity",
            "--balance",
            "edge",
            "--inside-point",
            "1,0,0",
        ],
        &[
            "mesh",
            "sphere",
            "--level",
            "4",
            "--keep",
            "outside",
            "--cut-rule",
            "none",
            "--inside",
            "auto",
        ],
        &[
            "mesh",
            "sphere",
            "--box",
            "-3,-1,-1,3,1,1",
            "--roots",
            "3,1,1",
            "--level",
            "3:4",
            "--min-level",
            "1",
            "--distance",
            "0.3:3",
            "--region",
            "box:0,-1,-1,3,1,1:2",
            "--keep",
            "outside",
        ],
    ];
    for (i, args) in cases.iter().enumerate() {
        let case = dir.join(format!("case{i}.toml"));
        let printed = octmesh_ok(1, &[args, &["--print-case"][..]].concat());
        std::fs::write(&case, &printed.stdout).unwrap();
        for np in [1, 2] {
            let direct = dir.join(format!("direct{i}_{np}.json"));
            let from_case = dir.join(format!("case{i}_{np}.json"));
            let out = dir.join(format!("m{i}_{np}.pvtu"));
            let extra = ["--quiet", "--stats", direct.to_str().unwrap()];
            octmesh_ok(np, &[args, &extra[..]].concat());
            let cmd = args[0];
            let mut run = vec![cmd, case.to_str().unwrap(), "--quiet", "--stats"];
            run.push(from_case.to_str().unwrap());
            if cmd == "mesh" {
                run.extend(["--out", out.to_str().unwrap()]);
            }
            octmesh_ok(np, &run);
            let (a, b) = (json_file(&direct), json_file(&from_case));
            assert_eq!(results(&a), results(&b), "{args:?} on {np} rank(s)");
            assert_eq!(int(&a, "octants_balanced"), int(&b, "octants_balanced"));
        }
    }
}

#[test]
fn command_line_overrides_the_case_file() {
    let dir = scratch("config_override");
    let case = dir.join("case.toml");
    std::fs::write(
        &case,
        "[surface]\nfile = \"sphere\"\n[octree]\nlevel = 3\n[mesh]\nkeep = \"inside\"\n",
    )
    .unwrap();
    let stats = dir.join("s.json");
    let s = stats.to_str().unwrap();
    octmesh_ok(
        1,
        &["mesh", case.to_str().unwrap(), "--quiet", "--stats", s],
    );
    let from_case = json_file(&stats);
    assert_eq!(int(&from_case, "level"), 3);
    assert_eq!(from_case["keep"], "inside");
    octmesh_ok(
        1,
        &[
            "mesh",
            case.to_str().unwrap(),
            "--level",
            "5",
            "--keep",
            "all",
            "--stats",
            s,
        ],
    );
    let overridden = json_file(&stats);
    assert_eq!(int(&overridden, "level"), 5);
    assert_eq!(overridden["keep"], "all");
    assert!(int(&overridden, "elements") > int(&from_case, "elements"));
}

/// Runs a failing configuration on `np` ranks and returns each rank's line.
fn expect_config_error(np: usize, args: &[&str], needles: &[&str]) {
    let out = mpirun(np, &octmesh_bin(), args, Duration::from_secs(60));
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
    assert!(!err.contains("panicked"), "{err}");
    for r in 0..np {
        let tag = format!("octmesh: error [rank {r} of {np}]:");
        let at = err
            .find(&tag)
            .unwrap_or_else(|| panic!("{args:?}: no line of rank {r}: {err}"));
        let text = &err[at..];
        for n in needles {
            assert!(text.contains(n), "{args:?}: rank {r} lacks '{n}': {err}");
        }
    }
}

#[test]
fn bad_configurations_fail_on_every_rank() {
    let dir = scratch("config_bad");
    let write = |name: &str, text: &str| {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p.to_str().unwrap().to_string()
    };
    let head = "[surface]\nfile = \"sphere\"\n";
    let malformed = write("malformed.toml", &format!("{head}[octree\nlevel = 3\n"));
    let unknown = write(
        "unknown.toml",
        &format!("{head}[octree]\nlevel = 3\nlevl = 4\n"),
    );
    let wrong_type = write("type.toml", &format!("{head}[octree]\nlevel = \"three\"\n"));
    let range = write(
        "range.toml",
        &format!("{head}[octree]\nlevel = 3\n[domain]\nfit = 1.5\n"),
    );
    let both = write(
        "both.toml",
        &format!("{head}[octree]\nlevel = 3\n[domain]\nfit = 0.5\ncube = [0.0, 0.0, 0.0, 1.0]\n"),
    );
    let box_head = format!("{head}[octree]\nlevel = 3\n[domain]\n");
    let uneven = write(
        "uneven.toml",
        &format!("{box_head}box = [0.0, 0.0, 0.0, 3.0, 1.0, 1.2]\nroots = [3, 1, 1]\n"),
    );
    let inverted = write(
        "inverted.toml",
        &format!("{box_head}box = [0.0, 0.0, 0.0, -3.0, 1.0, 1.0]\nroots = [3, 1, 1]\n"),
    );
    let no_box = write("nobox.toml", &format!("{box_head}roots = [3, 1, 1]\n"));
    let deep = write(
        "deep.toml",
        &format!(
            "{head}[octree]\nlevel = 17\n[domain]\nbox = [0.0, 0.0, 0.0, 3.0, 1.0, 1.0]\nroots = [3, 1, 1]\n"
        ),
    );
    let bad_enum = write(
        "enum.toml",
        &format!("{head}[octree]\nlevel = 3\n[mesh]\nkeep = \"solid\"\n"),
    );
    for np in [1, 3] {
        expect_config_error(
            np,
            &["mesh", &malformed, "--quiet"],
            &["malformed.toml line 3"],
        );
        expect_config_error(
            np,
            &["mesh", &unknown, "--quiet"],
            &["unknown.toml line 5: octree.levl", "unknown field"],
        );
        expect_config_error(
            np,
            &["mesh", &wrong_type, "--quiet"],
            &["type.toml line 4: octree.level", "invalid type"],
        );
        expect_config_error(
            np,
            &["mesh", &range, "--quiet"],
            &["range.toml line 6: domain.fit must be in (0, 1], got 1.5"],
        );
        expect_config_error(
            np,
            &["mesh", &both, "--quiet"],
            &["domain.fit", "domain.cube", "exclude"],
        );
        expect_config_error(
            np,
            &["mesh", &uneven, "--quiet"],
            &[
                "uneven.toml line 6: domain.box",
                "does not divide into 3x1x1 cubic root cells",
                "3 x 1 x 1 (cells of 1 as along x)",
                "3.6 x 1.2 x 1.2 (cells of 1.2 as along z)",
            ],
        );
        expect_config_error(
            np,
            &["mesh", &inverted, "--quiet"],
            &[
                "inverted.toml line 6: domain.box",
                "lowest below the highest",
            ],
        );
        expect_config_error(
            np,
            &["mesh", &no_box, "--quiet"],
            &["nobox.toml line 6: domain.roots needs", "domain.box"],
        );
        expect_config_error(
            np,
            &["mesh", &deep, "--quiet"],
            &["deep.toml line 4: octree.level", "levels go up to 16"],
        );
        expect_config_error(
            np,
            &[
                "octree",
                "sphere",
                "--level",
                "3",
                "--box",
                "0,0,0,1,1,1",
                "--fit",
                "0.5",
            ],
            &["--fit and --box exclude each other"],
        );
        expect_config_error(
            np,
            &[
                "octree",
                "sphere",
                "--level",
                "3",
                "--box",
                "0,0,0,2,1,1",
                "--roots",
                "2,0,1",
            ],
            &["--roots", "positive integers"],
        );
        expect_config_error(
            np,
            &[
                "octree",
                "sphere",
                "--level",
                "3",
                "--box",
                "0,0,0,2,1,1",
                "--roots",
                "3,1,1",
            ],
            &["--box is invalid", "does not divide"],
        );
        expect_config_error(
            np,
            &["mesh", &bad_enum, "--quiet"],
            &["enum.toml line 6: mesh.keep", "unknown keep mode 'solid'"],
        );
        expect_config_error(
            np,
            &[
                "octree", "sphere", "--level", "3", "--fit", "0.5", "--domain", "0,0,0,1",
            ],
            &["--fit and --domain exclude each other"],
        );
        expect_config_error(np, &["octree", "sphere", "--levl", "3"], &["--level"]);
        expect_config_error(
            np,
            &["mesh", "sphere", "--level", "3", "--keep", "solid"],
            &["--keep: unknown keep mode 'solid'"],
        );
        expect_config_error(
            np,
            &["mesh", "missing.toml"],
            &["cannot read the case file 'missing.toml'"],
        );
    }
}

#[test]
fn help_lists_every_subcommand_and_option() {
    for (cmd, options) in [
        (
            "octree",
            &[
                "--level",
                "--balance",
                "--fit",
                "--domain",
                "--inside-point",
                "--print-case",
            ][..],
        ),
        (
            "mesh",
            &["--keep", "--cut-rule", "--out", "--level", "--stats"][..],
        ),
        ("check", &["--json"][..]),
    ] {
        let out = octmesh_ok(1, &[cmd, "--help"]);
        let text = String::from_utf8_lossy(&out.stdout);
        for o in options {
            assert!(text.contains(o), "{cmd} --help lacks {o}:\n{text}");
        }
    }
}

#[test]
fn a_closed_pipe_ends_quietly() {
    // Without mpirun (a singleton): the command's own stdout is the pipe.
    let mut child = Command::new(octmesh_bin())
        .args(["mesh", "sphere", "--level", "5"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Close the read end at once, like `| head -0`.
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert!(
        !err.contains("panicked") && !err.contains("Broken pipe"),
        "{err}"
    );
}
