//! Octant-for-octant equality with p4est: octmesh writes its refined leaves,
//! the reference program rebuilds that octree in p8est and balances it with
//! the same connectivity, and the balanced leaves must be identical.

mod common;
use common::*;
use std::path::Path;

fn compare(surface: &Path, level: u32, conn: &str, np: usize, dir: &Path) {
    let tag = format!(
        "{}_{level}_{conn}_{np}",
        surface.file_stem().unwrap().to_string_lossy()
    );
    let refined = dir.join(format!("{tag}_refined.bin"));
    let ours = dir.join(format!("{tag}_octmesh.bin"));
    let theirs = dir.join(format!("{tag}_p4est.bin"));
    octmesh_ok(
        np,
        &[
            "octree",
            surface.to_str().unwrap(),
            "--level",
            &level.to_string(),
            "--balance",
            conn,
            "--quiet",
            "--write-refined",
            refined.to_str().unwrap(),
            "--write-leaves",
            ours.to_str().unwrap(),
        ],
    );
    p4est_ref_ok(
        np,
        &[
            "--in",
            refined.to_str().unwrap(),
            "--balance",
            conn,
            "--out",
            theirs.to_str().unwrap(),
        ],
        &tag,
    );
    let (a, b) = (leaves(&ours), leaves(&theirs));
    assert!(
        a.len() > leaves(&refined).len(),
        "{tag}: balance added nothing"
    );
    common::assert_same_leaves(&a, &b, &tag);
    println!("{tag}: {} balanced leaves equal to p4est", a.len());
}

#[test]
fn balanced_sphere_equals_p4est() {
    let dir = scratch("p4est_sphere");
    let sphere = Path::new("sphere");
    let mut np = 0;
    for level in [4, 6, 7] {
        for conn in ["face", "edge", "corner"] {
            np = np % 4 + 1;
            compare(sphere, level, conn, np, &dir);
        }
    }
}

#[test]
fn balanced_shared_models_equal_p4est() {
    let dir = scratch("p4est_models");
    let mut np = 1;
    for name in ["bunny.stl", "armadillo.stl"] {
        let Some(path) = shared_model(name) else {
            continue;
        };
        for level in [5, 7] {
            for conn in ["face", "edge", "corner"] {
                np = np % 4 + 1;
                compare(&path, level, conn, np, &dir);
            }
        }
    }
}
