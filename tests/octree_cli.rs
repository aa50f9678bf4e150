//! The `octmesh octree` command on 1 to 4 ranks: identical leaves for every
//! rank count, complete and balanced by independent checks, and its JSON.

mod common;
use common::*;
use octmesh::Connectivity;

#[test]
fn balanced_leaves_are_identical_for_every_rank_count() {
    let dir = scratch("rank_invariance");
    for (shape, level) in [("sphere", 6), ("torus", 6)] {
        for conn in ["face", "edge", "corner"] {
            let mut reference = None;
            for np in 1..=4 {
                let out = dir.join(format!("{shape}_{conn}_{np}.txt"));
                let refined = dir.join(format!("{shape}_{conn}_{np}_refined.bin"));
                octmesh_ok(
                    np,
                    &[
                        "octree",
                        shape,
                        "--level",
                        &level.to_string(),
                        "--balance",
                        conn,
                        "--quiet",
                        "--write-leaves",
                        out.to_str().unwrap(),
                        "--write-refined",
                        refined.to_str().unwrap(),
                    ],
                );
                let l = leaves(&out);
                let r = leaves(&refined);
                match &reference {
                    None => {
                        assert_complete_linear(&r);
                        assert_complete_linear(&l);
                        assert_balanced(&l, Connectivity::parse(conn).unwrap());
                        // Balance only refines: every refined leaf is covered.
                        assert!(l.len() > r.len());
                        reference = Some((r, l));
                    }
                    Some((r0, l0)) => {
                        assert_eq!(&r, r0, "{shape} refined leaves differ on {np} ranks");
                        assert_eq!(
                            &l, l0,
                            "{shape} {conn} balanced leaves differ on {np} ranks"
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn stats_json_has_the_documented_fields() {
    let dir = scratch("stats");
    let stats = dir.join("s.json");
    let out = octmesh_ok(
        2,
        &[
            "octree",
            "sphere",
            "--level",
            "5",
            "--stats",
            stats.to_str().unwrap(),
        ],
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("balance"), "phase table missing:\n{text}");
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    assert_eq!(j["ranks"], 2);
    assert_eq!(j["triangles"], 20480);
    assert_eq!(j["level"], 5);
    assert_eq!(j["balance"], "corner");
    let refined = j["octants_refined"].as_u64().unwrap();
    let balanced = j["octants_balanced"].as_u64().unwrap();
    assert!(balanced > refined && refined > 1000);
    for k in ["read", "construct", "refine", "partition", "balance"] {
        assert!(j["timings"][k].as_f64().unwrap() >= 0.0, "timing {k}");
    }
    assert!(j["peak_rss_bytes"].as_u64().unwrap() > 1 << 20);
}

#[test]
fn balance_none_keeps_the_refined_leaves() {
    let dir = scratch("none");
    let a = dir.join("a.txt");
    let b = dir.join("b.txt");
    octmesh_ok(
        3,
        &[
            "octree",
            "torus",
            "--level",
            "5",
            "--balance",
            "none",
            "--quiet",
            "--write-leaves",
            a.to_str().unwrap(),
            "--write-refined",
            b.to_str().unwrap(),
        ],
    );
    assert_eq!(leaves(&a), leaves(&b));
}
