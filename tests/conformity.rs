//! The written meshes judged from the files alone: the conformity checker
//! of [`common::conformity`] (points, hexahedra and boundary
//! quadrilaterals of the `.msh`, nothing of octmesh's structures) and
//! Gmsh's own quality measure.
//!
//! - On hanging-node meshes (the solid sphere at level 4, the solid bunny
//!   at level 5, the fluid around the sphere) the points the checker finds
//!   inside other elements' edges and faces are exactly the hanging nodes
//!   the file lists, there are faces used once that are not boundary (the
//!   two sides of the 2:1 interfaces), no face is in three elements, every
//!   boundary quadrilateral is an element face used once, and the volume
//!   is octmesh's kept volume to 1e-12 relative.
//! - A mesh without hanging nodes (one level everywhere) passes every
//!   check: the checker can say yes as well as no.
//! - Gmsh's `AnalyseMeshQuality` plugin on the snapped fluid mesh: its
//!   smallest IGE measure (for hexahedra, the scaled Jacobian at the
//!   corners) equals the smallest scaled Jacobian `--quality` reports, and
//!   equals the checker's.

mod common;

use std::collections::HashSet;
use std::path::Path;

use common::conformity::check;
use common::{json_file, octmesh_ok, require, scratch, shared_model, Oracle};

/// Meshes `input` with `args` on `np` ranks into `DIR/m.msh`; the path
/// and the statistics.
fn mesh(
    np: usize,
    name: &str,
    input: &str,
    args: &[&str],
) -> (std::path::PathBuf, serde_json::Value) {
    let dir = scratch(&format!("conformity_{name}"));
    let (msh, stats) = (dir.join("m.msh"), dir.join("s.json"));
    let mut all = vec!["mesh", input];
    all.extend(args);
    all.extend([
        "--gmsh",
        msh.to_str().unwrap(),
        "--stats",
        stats.to_str().unwrap(),
        "--quiet",
    ]);
    octmesh_ok(np, &all);
    let s = json_file(&stats);
    (msh, s)
}

/// The tags of the `$HangingNodes` section.
fn listed_hanging(msh: &Path) -> HashSet<u64> {
    let text = std::fs::read_to_string(msh).unwrap();
    let body = text.split("$HangingNodes\n").nth(1).expect("$HangingNodes");
    body.lines()
        .skip(1)
        .take_while(|l| !l.starts_with('$'))
        .map(|l| l.split_whitespace().next().unwrap().parse().unwrap())
        .collect()
}

/// The checker on a hanging-node mesh finds the listed hanging nodes and
/// nothing else.
fn hanging_mesh(name: &str, np: usize, input: &str, args: &[&str]) {
    let (msh, s) = mesh(np, name, input, args);
    let c = check(&msh);
    let hanging = listed_hanging(&msh);
    let found: HashSet<u64> = c.in_edges.union(&c.in_faces).copied().collect();
    println!(
        "{name}: {} elements, {} points inside edges, {} inside faces, {} listed hanging; \
         {} faces used once ({} not boundary); volume {:.12e}",
        c.elements,
        c.in_edges.len(),
        c.in_faces.len(),
        hanging.len(),
        c.faces_used_once,
        c.unmatched_faces,
        c.volume
    );
    assert!(!hanging.is_empty(), "{name}: the test needs hanging nodes");
    assert_eq!(found, hanging, "{name}: the points inside edges and faces");
    assert_eq!(
        c.in_edges.len() as u64,
        common::int(&s, "edge_hanging_nodes"),
        "{name}: edge-hanging"
    );
    assert_eq!(
        c.in_faces.len() as u64,
        common::int(&s, "face_hanging_nodes"),
        "{name}: face-hanging"
    );
    assert!(c.unmatched_faces > 0, "{name}: the 2:1 faces are used once");
    assert_eq!(c.crowded_faces, 0, "{name}: a face in three elements");
    assert_eq!(
        c.stray_boundary, 0,
        "{name}: a boundary quadrilateral off the elements"
    );
    assert!(!c.conforming());
    assert_eq!(c.elements as u64, common::int(&s, "elements"));
    let kept = s["kept_volume"].as_f64().unwrap();
    assert!(
        (c.volume - kept).abs() <= 1e-12 * kept,
        "{name}: volume {} against the kept volume {kept}",
        c.volume
    );
}

#[test]
fn the_checker_finds_the_hanging_nodes() {
    let cube = ["--domain", "-1.28,-1.28,-1.28,2.56"];
    let mut solid = vec!["--level", "4", "--keep", "inside"];
    solid.extend(cube);
    hanging_mesh("sphere_solid", 2, "sphere", &solid);
    hanging_mesh(
        "sphere_fluid",
        3,
        "sphere",
        &["--level", "4", "--keep", "outside"],
    );
    if let Some(bunny) = shared_model("bunny.stl") {
        let args = ["--level", "5", "--keep", "inside"];
        hanging_mesh("bunny", 2, bunny.to_str().unwrap(), &args);
    }
}

#[test]
fn a_mesh_of_one_level_is_conforming() {
    let args = ["--level", "3", "--min-level", "3", "--keep", "all"];
    let (msh, s) = mesh(2, "uniform", "sphere", &args);
    let c = check(&msh);
    assert_eq!(c.elements, 512, "level 3 everywhere");
    assert!(c.conforming(), "{c:?}");
    assert_eq!(c.faces_used_once, 6 * 64);
    let kept = s["kept_volume"].as_f64().unwrap();
    assert!((c.volume - kept).abs() <= 1e-12 * kept);
    assert!((c.min_scaled_jacobian - 1.0).abs() < 1e-12);
}

#[test]
fn gmsh_measures_the_scaled_jacobian_octmesh_reports() {
    let Some(python) = require(Oracle::Python {
        module: "gmsh",
        package: "python3-gmsh",
    }) else {
        return;
    };
    let args = ["--level", "4", "--keep", "outside", "--snap", "--quality"];
    let (msh, s) = mesh(2, "snapped", "sphere", &args);
    let ours = s["quality"]["scaled_jacobian_min"].as_f64().unwrap();
    let (n, gmsh_min) = common::fe_oracle::gmsh_min_scaled_jacobian(&python, &msh);
    let checker = check(&msh).min_scaled_jacobian;
    println!("snapped sphere fluid: {n} hexahedra; smallest scaled Jacobian: gmsh {gmsh_min}, octmesh {ours}, checker {checker}");
    assert_eq!(n, common::int(&s, "elements"));
    assert!(ours < 0.99, "the snap should distort some element");
    assert!(
        (gmsh_min - ours).abs() <= 1e-9,
        "gmsh {gmsh_min}, octmesh {ours}"
    );
    assert!(
        (checker - ours).abs() <= 1e-9,
        "checker {checker}, octmesh {ours}"
    );
}
