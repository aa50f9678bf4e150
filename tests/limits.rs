//! The octant estimate and the octant limit through the command: the
//! estimate against the leaves actually built, a limit far below the
//! estimate refused before refining, a limit just below the count reached
//! while refining, and one between the refined and the balanced count
//! reached while balancing, on 1 and 3 ranks.

mod common;
use common::*;
use std::time::Duration;

/// The factor the estimate is documented to be within (`refine::estimate_leaves`).
const FACTOR: f64 = 1.25;

/// Runs `octmesh octree SURFACE --level L --stats` and returns the stats.
fn stats(np: usize, surface: &str, level: u8, name: &str) -> serde_json::Value {
    let dir = scratch(name);
    let json = dir.join("stats.json");
    let leaves = dir.join("leaves.bin");
    octmesh_ok(
        np,
        &[
            "octree",
            surface,
            "--level",
            &level.to_string(),
            "--stats",
            json.to_str().unwrap(),
            "--write-leaves",
            leaves.to_str().unwrap(),
            "--quiet",
        ],
    );
    let mut j = json_file(&json);
    // The balanced count, from the leaves written rather than the stats.
    let written = common::leaves(&leaves);
    assert_complete_linear(&written);
    j["leaves_written"] = serde_json::json!(written.len());
    j
}

fn ratio(j: &serde_json::Value, est: &str, actual: &str) -> f64 {
    let e = j[est].as_f64().unwrap_or_else(|| panic!("no {est} in {j}"));
    let a = j[actual]
        .as_f64()
        .unwrap_or_else(|| panic!("no {actual} in {j}"));
    e / a
}

#[test]
fn estimate_is_within_the_stated_factor() {
    for surface in ["sphere", "torus"] {
        for level in [6u8, 8] {
            let j = stats(1, surface, level, &format!("limits_est_{surface}_{level}"));
            assert_eq!(j["leaves_written"], j["octants_balanced"], "{j}");
            let r = ratio(&j, "estimated_octants_refined", "octants_refined");
            let b = ratio(&j, "estimated_octants", "leaves_written");
            println!(
                "{surface} level {level}: estimate / actual = {r:.3} refined, {b:.3} balanced"
            );
            for x in [r, b] {
                assert!(
                    (1.0 / FACTOR..=FACTOR).contains(&x),
                    "{surface} level {level}: estimate / actual {x:.3} outside 1/{FACTOR}..{FACTOR}\n{j}"
                );
            }
        }
    }
}

fn fail(np: usize, args: &[&str], needle: &str) -> (String, String) {
    let out = mpirun(np, &octmesh_bin(), args, Duration::from_secs(120));
    let so = String::from_utf8_lossy(&out.stdout).into_owned();
    let se = String::from_utf8_lossy(&out.stderr).into_owned();
    for line in rank_error_lines(&out, np, &format!("{args:?}")) {
        assert!(line.contains(needle), "{args:?}: '{line}' lacks '{needle}'");
    }
    (so, se)
}

fn phase_ran(stdout: &str, phase: &str) -> bool {
    stdout
        .lines()
        .any(|l| l.split_whitespace().next() == Some(phase))
}

#[test]
fn limits_fail_before_while_refining_and_while_balancing() {
    // Counts without a limit.
    let j = stats(1, "sphere", 7, "limits_counts");
    let refined = j["octants_refined"].as_u64().unwrap();
    let balanced = j["octants_balanced"].as_u64().unwrap();
    let estimate = j["estimated_octants_refined"].as_u64().unwrap();
    assert!(balanced > refined);
    for np in [1, 3] {
        // Far below the estimate: refused before refining (no refine row),
        // with the estimate and a level that fits.
        let (so, se) = fail(
            np,
            &["octree", "sphere", "--level", "7", "--max-octants", "1000"],
            "limit of 1000 octants",
        );
        assert!(
            se.contains(&format!(
                "about {estimate} octants are estimated at level 7"
            )),
            "{se}"
        );
        assert!(se.contains("level 3 would fit"), "{se}");
        assert!(
            !phase_ran(&so, "refine") && !phase_ran(&so, "construct"),
            "{so}"
        );
        assert!(
            so.contains(&format!("estimated octants: {estimate} refined")),
            "{so}"
        );

        // Just below the count: the refinement stops.
        let limit = (refined - 1).to_string();
        let (so, _) = fail(
            np,
            &["octree", "sphere", "--level", "7", "--max-octants", &limit],
            &format!("limit of {limit} octants (stopped while refining)"),
        );
        assert!(
            phase_ran(&so, "construct") && !phase_ran(&so, "refine"),
            "{so}"
        );

        // Between the refined and the balanced count: the balance stops.
        let limit = (balanced - 1).to_string();
        let (so, _) = fail(
            np,
            &["octree", "sphere", "--level", "7", "--max-octants", &limit],
            &format!("limit of {limit} octants (stopped while 2:1 balancing)"),
        );
        assert!(
            phase_ran(&so, "refine") && !phase_ran(&so, "balance"),
            "{so}"
        );

        // Exactly the balanced count fits.
        let limit = balanced.to_string();
        octmesh_ok(
            np,
            &[
                "octree",
                "sphere",
                "--level",
                "7",
                "--max-octants",
                &limit,
                "--quiet",
            ],
        );
    }
}
