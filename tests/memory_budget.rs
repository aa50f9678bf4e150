//! The memory budget: runs that would not fit stop before refining, with
//! the budget's error on every rank; runs whose real size outgrows the
//! estimate stop before allocating; nothing is killed by the kernel.

mod common;

use std::time::Duration;

use common::*;
use octmesh::internals::run::budget::{BASE_BYTES, BYTES_PER_OCTANT_MESH, BYTES_PER_TRIANGLE};

/// Runs a command expected to fail with the budget's error on every rank.
fn expect_budget_error(np: usize, args: &[&str], needle: &str) {
    let out = mpirun(np, &octmesh_bin(), args, Duration::from_secs(120));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
    for (r, line) in rank_error_lines(&out, np, &format!("{args:?}"))
        .iter()
        .enumerate()
    {
        assert!(
            line.starts_with(&format!("octmesh: error [rank {r} of {np}]:")),
            "{line}"
        );
        assert!(line.contains("memory budget:"), "{line}");
        assert!(line.contains(needle), "'{needle}' not in {line}");
    }
}

#[test]
fn runs_far_too_large_stop_before_refining() {
    expect_budget_error(1, &["octree", "sphere", "--level", "18"], "would fit");
    expect_budget_error(
        2,
        &["mesh", "sphere", "--level", "18", "--keep", "inside"],
        "would fit",
    );
    if let Some(dragon) = shared_model("dragon.stl") {
        expect_budget_error(
            2,
            &[
                "mesh",
                dragon.to_str().unwrap(),
                "--level",
                "16",
                "--keep",
                "inside",
            ],
            "nothing was refined",
        );
    }
    // A given budget: the same words, the caller's figure.
    expect_budget_error(
        1,
        &["mesh", "sphere", "--level", "9", "--memory-budget", "80MiB"],
        "more than the budget of 80 MiB per rank",
    );
}

#[test]
fn a_run_that_outgrows_its_estimate_stops_before_allocating() {
    let dir = scratch("memory_budget_in_run");
    for np in [1, 2] {
        let stats = dir.join(format!("s{np}.json"));
        let s = stats.to_str().unwrap();
        octmesh_ok(
            np,
            &["mesh", "sphere", "--level", "6", "--quiet", "--stats", s],
        );
        let j = json_file(&stats);
        let (estimate, real) = (int(&j, "estimated_octants"), int(&j, "octants_balanced"));
        assert!(
            estimate < real,
            "this case needs an estimate below the real count"
        );
        // A budget whose octant limit lies between the estimate and the real
        // count: the check before refining passes, balance must stop.
        let base = BASE_BYTES + int(&j, "triangles") * BYTES_PER_TRIANGLE;
        let limit = (estimate + real) / 2;
        let budget = base + limit * BYTES_PER_OCTANT_MESH / np as u64;
        let b = budget.to_string();
        expect_budget_error(
            np,
            &[
                "mesh",
                "sphere",
                "--level",
                "6",
                "--memory-budget",
                &b,
                "--quiet",
            ],
            "grew past",
        );
        // Enough memory: the same run succeeds and reports its budget.
        let roomy = (budget * 2).to_string();
        octmesh_ok(
            np,
            &[
                "mesh",
                "sphere",
                "--level",
                "6",
                "--memory-budget",
                &roomy,
                "--quiet",
                "--stats",
                s,
            ],
        );
        assert_eq!(int(&json_file(&stats), "memory_budget_bytes"), budget * 2);
    }
}

#[test]
fn a_bad_budget_names_the_option() {
    let out = mpirun(
        1,
        &octmesh_bin(),
        &[
            "octree",
            "sphere",
            "--level",
            "3",
            "--memory-budget",
            "lots",
        ],
        Duration::from_secs(60),
    );
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--memory-budget expects a size in bytes"),
        "{err}"
    );
}
