//! Bad input on 1 and 3 ranks, through the command (a clear message on every
//! rank, a non-zero exit, no panic text, no hang) and through the C API
//! (`tests/c/bad_input.c`: the expected status on every rank, the handle
//! intact and still working), and octant limits. Also an internal error (a
//! panic injected on one rank with the command's test-only
//! `OCTMESH_FAULT_PANIC_RANK`): the whole job ends promptly with exit status
//! 3 and one line naming the rank.

mod common;
use common::*;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Duration;

fn expect_failure(np: usize, args: &[&str], needle: &str) {
    let out = mpirun(np, &octmesh_bin(), args, Duration::from_secs(120));
    let lines = rank_error_lines(&out, np, &format!("{args:?}"));
    for (r, line) in lines.iter().enumerate() {
        assert!(
            line.contains(needle),
            "{args:?}: rank {r} says '{line}', expected '{needle}'"
        );
    }
}

/// The bad files: path, words of the message, and the C API status.
fn bad_files() -> Vec<(PathBuf, &'static str, &'static str)> {
    let dir = scratch("bad_input");
    let tri = [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let mut v = Vec::new();

    let p = dir.join("empty.stl");
    std::fs::write(&p, b"").unwrap();
    v.push((p, "empty", "OCTMESH_STATUS_FORMAT"));

    let p = dir.join("truncated.stl");
    write_stl(&p, &[tri, tri, tri], b"binary");
    let b = std::fs::read(&p).unwrap();
    std::fs::write(&p, &b[..b.len() - 20]).unwrap();
    v.push((p, "truncated", "OCTMESH_STATUS_FORMAT"));

    let p = dir.join("count.stl");
    write_stl(&p, &[tri], b"binary");
    let mut b = std::fs::read(&p).unwrap();
    b[80..84].copy_from_slice(&1000u32.to_le_bytes());
    std::fs::write(&p, &b).unwrap();
    v.push((p, "1000 triangles", "OCTMESH_STATUS_FORMAT"));

    let p = dir.join("noendloop.stl");
    std::fs::write(
        &p,
        "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendfacet\nendsolid t\n",
    )
    .unwrap();
    v.push((p, "malformed ASCII STL", "OCTMESH_STATUS_FORMAT"));

    let p = dir.join("nan.stl");
    write_stl(
        &p,
        &[
            tri,
            [[0.0, f32::NAN, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        ],
        b"binary",
    );
    v.push((p, "non-finite", "OCTMESH_STATUS_GEOMETRY"));

    let p = dir.join("inf.stl");
    write_stl(
        &p,
        &[[[0.0, 0.0, f32::INFINITY], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]],
        b"binary",
    );
    v.push((p, "non-finite", "OCTMESH_STATUS_GEOMETRY"));

    let p = dir.join("degenerate.stl");
    write_stl(&p, &[[[1.0, 1.0, 1.0]; 3], [[2.0, 2.0, 2.0]; 3]], b"binary");
    v.push((p, "degenerate", "OCTMESH_STATUS_GEOMETRY"));

    v.push((dir.join("missing.stl"), "No such file", "OCTMESH_STATUS_IO"));
    v.push((dir.clone(), "directory", "OCTMESH_STATUS_IO"));
    v
}

#[test]
fn bad_surfaces_fail_cleanly_on_every_rank() {
    for (path, needle, _) in bad_files() {
        for np in [1, 3] {
            expect_failure(
                np,
                &["octree", path.to_str().unwrap(), "--level", "3"],
                needle,
            );
        }
    }
}

#[test]
fn bad_arguments_fail_cleanly_on_every_rank() {
    for np in [1, 3] {
        expect_failure(
            np,
            &["octree", "sphere", "--level", "19"],
            "above the maximum level 18",
        );
        expect_failure(
            np,
            &["octree", "sphere", "--level", "x"],
            "--level expects an integer",
        );
        expect_failure(
            np,
            &["octree", "sphere", "--level", "4", "--balance", "diagonal"],
            "unknown connectivity",
        );
        expect_failure(
            np,
            &["octree", "sphere", "--level", "4", "--fit", "2"],
            "--fit must be in (0, 1]",
        );
        expect_failure(np, &["octree", "", "--level", "4"], "no surface given");
        expect_failure(
            np,
            &["octree", "sphere", "--level", "7", "--max-octants", "1000"],
            "limit of 1000 octants",
        );
    }
}

/// Checks the output of a run in which `rank` of `np` panicked.
fn expect_internal_error(out: &Output, rank: usize, np: usize, how: &str) {
    let err = String::from_utf8_lossy(&out.stderr);
    let all = format!("{}{err}", String::from_utf8_lossy(&out.stdout));
    assert!(!out.status.success(), "{how} should fail:\n{all}");
    let line = format!("octmesh: internal error on rank {rank} of {np}: fault injected");
    assert_eq!(err.matches(&line).count(), 1, "{how}: no '{line}':\n{all}");
    // The command's hook replaces Rust's default panic message.
    assert!(!all.contains("panicked"), "{how}: panic text:\n{all}");
}

/// The injected panic as the process environment sets it.
fn fault_env(rank: usize) -> [(&'static str, String); 2] {
    [
        ("OCTMESH_FAULT_PANIC_RANK", rank.to_string()),
        // No backtrace from the hook, whatever the caller's environment says.
        ("RUST_BACKTRACE", "0".to_string()),
    ]
}

#[test]
fn a_panic_on_one_rank_aborts_the_whole_job() {
    let args = ["mesh", "sphere", "--level", "4"];
    for rank in [1, 0] {
        let env = fault_env(rank);
        let env: Vec<(&str, &str)> = env.iter().map(|(k, v)| (*k, v.as_str())).collect();
        // Before the hook, the other rank waited in a collective forever;
        // mpirun_env panics when the job outlives the limit.
        let out = mpirun_env(2, &octmesh_bin(), &args, &env, Duration::from_secs(60));
        let how = format!("a panic on rank {rank} of 2");
        expect_internal_error(&out, rank, 2, &how);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains("aborting the MPI job"), "{how}:\n{err}");
    }
}

#[test]
fn a_panic_without_mpirun_exits_with_status_3() {
    let mut cmd = Command::new(octmesh_bin());
    cmd.args(["mesh", "sphere", "--level", "4"])
        .env_remove("OCTMESH_MPI")
        .envs(fault_env(0));
    let out = run_with_limit(cmd, Duration::from_secs(60));
    expect_internal_error(&out, 0, 1, "a panic without mpirun");
    assert_eq!(out.status.code(), Some(3));
}

/// The C test program, built against this build's library.
fn c_program(dir: &Path) -> PathBuf {
    let lib = dir.join("lib");
    stage_library(&deps_dir(), &lib);
    compile_c_test("bad_input", &lib, dir)
}

fn c_ok(np: usize, exe: &Path, args: &[&str]) {
    let out = mpirun(np, exe, args, Duration::from_secs(120));
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        out.status.success(),
        "bad_input {args:?} on {np} ranks failed:\n{text}"
    );
    assert_eq!(
        text.matches("BAD INPUT OK").count(),
        np,
        "bad_input {args:?} on {np} ranks:\n{text}"
    );
}

#[test]
fn bad_files_through_the_c_api_on_1_and_3_ranks() {
    let exe = c_program(&scratch("bad_input_c_files"));
    for (path, needle, status) in bad_files() {
        for np in [1, 3] {
            c_ok(np, &exe, &["file", path.to_str().unwrap(), status, needle]);
        }
    }
}

#[test]
fn faults_through_the_c_api_on_1_and_3_ranks() {
    let dir = scratch("bad_input_c_cases");
    let exe = c_program(&dir);
    let good = dir.join("sphere.stl");
    octmesh::internals::geometry::stl::write_stl_binary(
        &good,
        &octmesh::internals::geometry::shapes::default_sphere(),
    )
    .unwrap();
    let missing = dir.join("missing.stl");
    let sub = dir.join("a-directory.stl");
    std::fs::create_dir_all(&sub).unwrap();
    for np in [1, 3] {
        c_ok(
            np,
            &exe,
            &[
                "cases",
                good.to_str().unwrap(),
                missing.to_str().unwrap(),
                sub.to_str().unwrap(),
            ],
        );
    }
}
