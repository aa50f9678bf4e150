//! Node counts equal to p4est's on the same balanced octree: octmesh meshes
//! a surface and writes its balanced leaves; the reference program rebuilds
//! that octree in p8est and counts independent and hanging nodes with
//! `p8est_nodes_new` (corner balance) and `p8est_lnodes_new` of degree 1
//! (edge and corner balance).

mod common;
use common::*;
use std::path::Path;

fn compare(surface: &Path, level: u32, conn: &str, np: usize, dir: &Path) {
    let tag = format!(
        "{}_{level}_{conn}_{np}",
        surface.file_stem().unwrap().to_string_lossy()
    );
    let leaves_file = dir.join(format!("{tag}.bin"));
    let ours = dir.join(format!("{tag}_octmesh.json"));
    let theirs = dir.join(format!("{tag}_p4est.json"));
    octmesh_ok(
        np,
        &[
            "mesh",
            surface.to_str().unwrap(),
            "--level",
            &level.to_string(),
            "--balance",
            conn,
            "--quiet",
            "--write-leaves",
            leaves_file.to_str().unwrap(),
            "--stats",
            ours.to_str().unwrap(),
        ],
    );
    p4est_ref_ok(
        np,
        &[
            "--in",
            leaves_file.to_str().unwrap(),
            "--balance",
            conn,
            "--nodes",
            "--json",
            theirs.to_str().unwrap(),
        ],
        &tag,
    );
    let (a, b) = (json_file(&ours), json_file(&theirs));
    let n = |v: &serde_json::Value, k: &str| {
        v[k].as_u64()
            .unwrap_or_else(|| panic!("{tag}: no integer '{k}' in {v}"))
    };
    assert_eq!(
        n(&a, "octants_balanced"),
        n(&b, "leaves_balanced"),
        "{tag}: p4est changed the balanced octree"
    );
    assert_eq!(
        n(&a, "elements"),
        n(&a, "octants_balanced"),
        "{tag}: keep all"
    );
    assert_eq!(
        n(&a, "independent_nodes"),
        n(&b, "lnodes_global"),
        "{tag}: independent nodes against p8est_lnodes"
    );
    assert_eq!(
        n(&a, "elements_with_hanging"),
        n(&b, "lnodes_hanging_elements"),
        "{tag}: elements with a hanging face or edge against p8est_lnodes"
    );
    assert!(
        n(&a, "face_hanging_nodes") > 0,
        "{tag}: no hanging nodes at all"
    );
    if conn == "corner" {
        assert_eq!(
            n(&a, "independent_nodes"),
            n(&b, "indep_nodes"),
            "{tag}: independent nodes against p8est_nodes"
        );
        assert_eq!(
            n(&a, "face_hanging_nodes"),
            n(&b, "face_hanging_nodes"),
            "{tag}: face-hanging nodes against p8est_nodes"
        );
        assert_eq!(
            n(&a, "edge_hanging_nodes"),
            n(&b, "edge_hanging_nodes"),
            "{tag}: edge-hanging nodes against p8est_nodes"
        );
    }
    println!(
        "{tag}: {} elements, {} independent, {} face-hanging, {} edge-hanging nodes: equal to p4est",
        n(&a, "elements"),
        n(&a, "independent_nodes"),
        n(&a, "face_hanging_nodes"),
        n(&a, "edge_hanging_nodes")
    );
}

#[test]
fn sphere_node_counts_equal_p4est() {
    let dir = scratch("nodes_sphere");
    let mut np = 0;
    for level in [4, 6, 7] {
        for conn in ["edge", "corner"] {
            np = np % 4 + 1;
            compare(Path::new("sphere"), level, conn, np, &dir);
        }
    }
    compare(Path::new("torus"), 6, "corner", 3, &dir);
}

#[test]
fn shared_model_node_counts_equal_p4est() {
    let dir = scratch("nodes_models");
    let mut np = 1;
    for name in ["bunny.stl", "armadillo.stl"] {
        let Some(path) = shared_model(name) else {
            continue;
        };
        for level in [5, 7] {
            for conn in ["edge", "corner"] {
                np = np % 4 + 1;
                compare(&path, level, conn, np, &dir);
            }
        }
    }
}
