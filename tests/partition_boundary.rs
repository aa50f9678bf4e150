//! `tools/bench/partition_boundary.py` measures the ghost layer of
//! partitions offline, from a leaf file, with its own contact search (probes
//! around each leaf, binary search on Morton keys). BENCHMARKS.md compares
//! orders by its counts, so its Morton counts must be octmesh's own: the
//! ghosts over all ranks and the most ghost-phase bytes a rank sent and
//! received, on a number of ranks that splits the sphere unevenly.

mod common;

use std::process::Command;

use common::*;

#[test]
fn offline_ghost_counts_are_octmesh_ghost_layer() {
    let Some(python) = require(Oracle::Python {
        module: "numpy",
        package: "python3-numpy",
    }) else {
        return;
    };
    let dir = scratch("partition_boundary");
    let leaves = dir.join("sphere.bin");
    let stats = dir.join("stats.json");
    let case = [
        "sphere",
        "--level",
        "6",
        "--fit",
        "0.7",
        "--balance",
        "corner",
    ];
    let mut octree = vec!["octree"];
    octree.extend(case);
    octree.extend(["--write-leaves", leaves.to_str().unwrap()]);
    octmesh_ok(1, &octree);
    let mut mesh = vec!["mesh"];
    mesh.extend(case);
    mesh.extend(["--stats", stats.to_str().unwrap()]);
    octmesh_ok(3, &mesh);
    assert!(
        int(&json_file(&stats), "ghosts") > 0,
        "no ghosts on 3 ranks"
    );

    let tool = repo().join("tools/bench/partition_boundary.py");
    let out = Command::new(&python)
        .arg(&tool)
        .arg(&leaves)
        .args(["--parts", "3", "--orders", "morton,hilbert,rcb", "--stats"])
        .arg(&stats)
        .output()
        .expect("run tools/bench/partition_boundary.py");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "the offline counts differ from octmesh's:\n{text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(text.matches("(same)").count(), 3, "{text}");

    let out = Command::new(&python)
        .arg(&tool)
        .arg("--self-test")
        .output()
        .expect("run tools/bench/partition_boundary.py --self-test");
    assert!(
        out.status.success(),
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}
