//! Bad input through the command on 1 and 3 ranks: a clear message on every
//! rank, a non-zero exit, no panic text, no hang.

mod common;
use common::*;
use std::path::PathBuf;
use std::time::Duration;

fn expect_failure(np: usize, args: &[&str], needle: &str) {
    let out = mpirun(np, &octmesh_bin(), args, Duration::from_secs(120));
    let err = String::from_utf8_lossy(&out.stderr);
    let all = format!("{}{err}", String::from_utf8_lossy(&out.stdout));
    assert!(
        !out.status.success(),
        "{args:?} on {np} ranks should fail:\n{all}"
    );
    assert!(!all.contains("panicked"), "{args:?}: panic text:\n{all}");
    for r in 0..np {
        let line = err
            .lines()
            .find(|l| l.contains(&format!("octmesh: error [rank {r} of {np}]:")));
        let line = line.unwrap_or_else(|| panic!("{args:?}: rank {r} printed no error:\n{all}"));
        assert!(
            line.contains(needle),
            "{args:?}: rank {r} says '{line}', expected '{needle}'"
        );
    }
}

fn bad_files() -> Vec<(PathBuf, &'static str)> {
    let dir = scratch("bad_input");
    let tri = [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let mut v = Vec::new();

    let p = dir.join("empty.stl");
    std::fs::write(&p, b"").unwrap();
    v.push((p, "empty"));

    let p = dir.join("truncated.stl");
    write_stl(&p, &[tri, tri, tri], b"binary");
    let b = std::fs::read(&p).unwrap();
    std::fs::write(&p, &b[..b.len() - 20]).unwrap();
    v.push((p, "truncated"));

    let p = dir.join("count.stl");
    write_stl(&p, &[tri], b"binary");
    let mut b = std::fs::read(&p).unwrap();
    b[80..84].copy_from_slice(&1000u32.to_le_bytes());
    std::fs::write(&p, &b).unwrap();
    v.push((p, "1000 triangles"));

    let p = dir.join("noendloop.stl");
    std::fs::write(
        &p,
        "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendfacet\nendsolid t\n",
    )
    .unwrap();
    v.push((p, "malformed ASCII STL"));

    let p = dir.join("nan.stl");
    write_stl(
        &p,
        &[
            tri,
            [[0.0, f32::NAN, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        ],
        b"binary",
    );
    v.push((p, "non-finite"));

    let p = dir.join("inf.stl");
    write_stl(
        &p,
        &[[[0.0, 0.0, f32::INFINITY], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]],
        b"binary",
    );
    v.push((p, "non-finite"));

    let p = dir.join("degenerate.stl");
    write_stl(&p, &[[[1.0, 1.0, 1.0]; 3], [[2.0, 2.0, 2.0]; 3]], b"binary");
    v.push((p, "degenerate"));

    v.push((dir.join("missing.stl"), "No such file"));
    v.push((dir.clone(), "directory"));
    v
}

#[test]
fn bad_surfaces_fail_cleanly_on_every_rank() {
    for (path, needle) in bad_files() {
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
