//! Refinement regions and the minimum level, checked against a brute-force
//! construction written here: the leaves octmesh writes before balance are
//! exactly the coarsest octree in which every leaf satisfies every rule.

mod common;

use common::*;

const N: f64 = (1u64 << 19) as f64;

/// A rule in the unit cube: (shape, level, outside).
enum Shape {
    Box([f64; 3], [f64; 3]),
    Ball([f64; 3], f64),
}

/// Whether the rule asks to split the closed box `lo..hi` at `level`.
fn wants(
    shape: &Shape,
    rule_level: u32,
    outside: bool,
    level: u32,
    lo: [f64; 3],
    hi: [f64; 3],
) -> bool {
    if level >= rule_level {
        return false;
    }
    let meets = match shape {
        Shape::Box(a, b) => (0..3).all(|k| a[k] <= hi[k] && lo[k] <= b[k]),
        Shape::Ball(c, r) => {
            let d2: f64 = (0..3)
                .map(|k| (lo[k] - c[k]).max(0.0).max(c[k] - hi[k]).powi(2))
                .sum();
            d2 <= r * r
        }
    };
    let inside = match shape {
        Shape::Box(a, b) => (0..3).all(|k| a[k] < lo[k] && hi[k] < b[k]),
        Shape::Ball(c, r) => (0..8).all(|m| {
            let d2: f64 = (0..3)
                .map(|k| (if m >> k & 1 == 1 { hi[k] } else { lo[k] } - c[k]).powi(2))
                .sum();
            d2 < r * r
        }),
    };
    if outside {
        !inside
    } else {
        meets
    }
}

/// The leaves (x, y, z, level in lattice units) of the coarsest octree of
/// the unit cube in which no rule wants a split.
fn brute_force(rules: &[(Shape, u32, bool)], min_level: u32) -> Vec<(u32, u32, u32, u32)> {
    brute_force_in(rules, min_level, [0.0; 3])
}

/// [`brute_force`] in the unit cube at `origin` (one root cell of a box).
fn brute_force_in(
    rules: &[(Shape, u32, bool)],
    min_level: u32,
    origin: [f64; 3],
) -> Vec<(u32, u32, u32, u32)> {
    let mut out = Vec::new();
    let mut stack = vec![(0u32, 0u32, 0u32, 0u32)];
    while let Some((x, y, z, l)) = stack.pop() {
        let len = 1u32 << (19 - l);
        let lo = [
            origin[0] + x as f64 / N,
            origin[1] + y as f64 / N,
            origin[2] + z as f64 / N,
        ];
        let hi = [
            origin[0] + (x + len) as f64 / N,
            origin[1] + (y + len) as f64 / N,
            origin[2] + (z + len) as f64 / N,
        ];
        let split = l < min_level || rules.iter().any(|(s, rl, o)| wants(s, *rl, *o, l, lo, hi));
        if split && l < 18 {
            let h = len / 2;
            for c in 0..8u32 {
                stack.push((
                    x + (c & 1) * h,
                    y + (c >> 1 & 1) * h,
                    z + (c >> 2 & 1) * h,
                    l + 1,
                ));
            }
        } else {
            out.push((x, y, z, l));
        }
    }
    out.sort_unstable();
    out
}

#[test]
fn region_leaves_equal_a_brute_force_construction() {
    let dir = scratch("regions_brute_force");
    let rules = vec![
        (Shape::Box([0.1, 0.2, 0.3], [0.4, 0.5, 0.6]), 6, false),
        (Shape::Ball([0.7, 0.7, 0.7], 0.2), 5, false),
        (Shape::Ball([0.5, 0.5, 0.5], 0.45), 4, true),
    ];
    let expected = brute_force(&rules, 2);
    let args = [
        "octree",
        "sphere",
        "--level",
        "0",
        "--domain",
        "0,0,0,1",
        "--balance",
        "none",
        "--min-level",
        "2",
        "--region",
        "box:0.1,0.2,0.3,0.4,0.5,0.6:6",
        "--region",
        "sphere:0.7,0.7,0.7,0.2:5",
        "--region",
        "sphere:0.5,0.5,0.5,0.45:4:outside",
        "--quiet",
    ];
    for np in [1, 2, 3] {
        let file = dir.join(format!("leaves{np}.txt"));
        octmesh_ok(
            np,
            &[&args[..], &["--write-leaves", file.to_str().unwrap()]].concat(),
        );
        let mut got: Vec<(u32, u32, u32, u32)> = leaves(&file)
            .iter()
            .map(|o| {
                let c = o.coords();
                (c[0], c[1], c[2], o.level() as u32)
            })
            .collect();
        got.sort_unstable();
        assert_eq!(got.len(), expected.len(), "np {np}");
        assert!(
            got == expected,
            "np {np}: the leaves differ from the brute-force octree"
        );
    }
    // The same rules from a case file.
    let case = dir.join("case.toml");
    let printed = octmesh_ok(1, &[&args[..], &["--print-case"]].concat());
    std::fs::write(&case, &printed.stdout).unwrap();
    let file = dir.join("from_case.txt");
    octmesh_ok(
        2,
        &[
            "octree",
            case.to_str().unwrap(),
            "--write-leaves",
            file.to_str().unwrap(),
        ],
    );
    assert_eq!(leaves(&file).len(), expected.len());
}

/// In a box of 3 x 2 x 1 unit root cells, levels count from the root cells
/// and regions reach across them: the leaves of each tree (p4est's brick
/// order) are the brute-force octree of that root cell.
#[test]
fn region_leaves_in_a_box_equal_a_brute_force_construction() {
    let dir = scratch("regions_brick");
    let rules = vec![
        (Shape::Box([0.6, 0.2, 0.3], [2.4, 1.5, 0.6]), 5, false),
        (Shape::Ball([2.7, 1.7, 0.7], 0.4), 4, false),
        (Shape::Ball([1.5, 1.0, 0.5], 1.2), 3, true),
    ];
    // p4est's brick order: the Morton order of the root cells' positions.
    let mut trees: Vec<[u32; 3]> = (0..2)
        .flat_map(|y| (0..3).map(move |x| [x, y, 0]))
        .collect();
    trees.sort_by_key(|t| octmesh::internals::octree::octant::morton_encode(t[0], t[1], t[2]));
    let mut expected: Vec<(u32, u32, u32, u32, u32)> = Vec::new();
    for (i, t) in trees.iter().enumerate() {
        let origin = t.map(f64::from);
        for (x, y, z, l) in brute_force_in(&rules, 1, origin) {
            expected.push((i as u32, x, y, z, l));
        }
    }
    expected.sort_unstable();
    for np in [1, 3] {
        let file = dir.join(format!("leaves{np}.txt"));
        octmesh_ok(
            np,
            &[
                "octree",
                "sphere",
                "--box",
                "0,0,0,3,2,1",
                "--roots",
                "3,2,1",
                "--level",
                "0",
                "--balance",
                "none",
                "--min-level",
                "1",
                "--region",
                "box:0.6,0.2,0.3,2.4,1.5,0.6:5",
                "--region",
                "sphere:2.7,1.7,0.7,0.4:4",
                "--region",
                "sphere:1.5,1.0,0.5,1.2:3:outside",
                "--quiet",
                "--write-leaves",
                file.to_str().unwrap(),
            ],
        );
        let text = std::fs::read_to_string(&file).unwrap();
        let mut got: Vec<(u32, u32, u32, u32, u32)> = text
            .lines()
            .filter(|l| !l.starts_with('#'))
            .map(|l| {
                let v: Vec<u32> = l.split_whitespace().map(|w| w.parse().unwrap()).collect();
                (v[0], v[1], v[2], v[3], v[4])
            })
            .collect();
        got.sort_unstable();
        assert_eq!(got.len(), expected.len(), "np {np}");
        assert!(
            got == expected,
            "np {np}: the leaves differ from the brute-force octrees"
        );
    }
}

#[test]
fn bad_regions_name_the_option_or_key() {
    let out = octmesh_fails(&[
        "octree",
        "sphere",
        "--level",
        "3",
        "--region",
        "box:1,0,0,0,1,1:4",
    ]);
    assert!(out.contains("--region expects box:"), "{out}");
    assert!(out.contains("min below max"), "{out}");
    let dir = scratch("regions_bad");
    let case = dir.join("bad.toml");
    std::fs::write(
        &case,
        "[surface]\nfile = \"sphere\"\n[octree]\nlevel = 3\n[[regions]]\nshape = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1.0\nlevel = 30\n",
    )
    .unwrap();
    let out = octmesh_fails(&["octree", case.to_str().unwrap()]);
    assert!(
        out.contains("bad.toml: regions number 1 (sphere) has level 30"),
        "{out}"
    );
    let out = octmesh_fails(&["octree", "sphere", "--level", "3", "--min-level", "19"]);
    assert!(
        out.contains("--min-level is 19: above the maximum level 18"),
        "{out}"
    );
}

/// Runs octmesh on one rank expecting exit status 2; returns stderr.
fn octmesh_fails(args: &[&str]) -> String {
    let out = mpirun(1, &octmesh_bin(), args, std::time::Duration::from_secs(60));
    assert_eq!(out.status.code(), Some(2), "{args:?}");
    String::from_utf8_lossy(&out.stderr).into()
}

/// Distance from the box `lo..hi` to the unit sphere at the origin.
fn sphere_distance(lo: [f64; 3], hi: [f64; 3]) -> f64 {
    let near: f64 = (0..3)
        .map(|k| (lo[k].max(0.0).max(-hi[k])).powi(2))
        .sum::<f64>()
        .sqrt();
    let far: f64 = (0..3)
        .map(|k| lo[k].abs().max(hi[k].abs()).powi(2))
        .sum::<f64>()
        .sqrt();
    if near > 1.0 {
        near - 1.0
    } else if far < 1.0 {
        1.0 - far
    } else {
        0.0
    }
}

#[test]
fn distance_bands_follow_the_exact_distance() {
    let dir = scratch("regions_distance");
    // The built-in sphere is a polyhedron within 1e-3 of the unit sphere.
    let tol = 2e-3;
    let bands = [(0.1, 6u8), (0.3, 5u8)];
    for np in [1, 2] {
        let file = dir.join(format!("leaves{np}.txt"));
        octmesh_ok(
            np,
            &[
                "octree",
                "sphere",
                "--level",
                "2",
                "--distance",
                "0.1:6,0.3:5",
                "--domain",
                "-2,-2,-2,4",
                "--balance",
                "none",
                "--quiet",
                "--write-leaves",
                file.to_str().unwrap(),
            ],
        );
        let user = |c: [u32; 3], level: u8| {
            let len = 4.0 / (1u32 << level) as f64;
            let lo: [f64; 3] = std::array::from_fn(|k| -2.0 + 4.0 * c[k] as f64 / N);
            let hi: [f64; 3] = std::array::from_fn(|k| lo[k] + len);
            sphere_distance(lo, hi)
        };
        let mut in_band = 0;
        for o in leaves(&file) {
            let d = user(o.coords(), o.level());
            // Close enough: at least the band's level.
            for (bd, bl) in bands {
                if d < bd - tol {
                    in_band += 1;
                    assert!(
                        o.level() >= bl,
                        "{o:?} at distance {d} is coarser than level {bl}"
                    );
                }
            }
            // No finer than a rule asks: the parent was within a band that
            // wanted more, or below the surface level.
            if o.level() > 2 {
                let p = o.parent();
                let dp = user(p.coords(), p.level());
                let wanted = bands
                    .iter()
                    .any(|&(bd, bl)| p.level() < bl && dp <= bd + tol);
                assert!(wanted, "{o:?}: its parent at distance {dp} needed no split");
            }
        }
        assert!(in_band > 0);
    }
}

/// `--dry-run` prints the estimate of every control and builds nothing: the
/// surface row is the estimate a real run reports, a minimum level and a
/// region covering the cube are exact, and no output file appears.
#[test]
fn dry_run_prints_an_estimate_per_control_and_builds_nothing() {
    let dir = scratch("regions_dry_run");
    let out = dir.join("never.pvtu");
    let stats = dir.join("never.json");
    let args = [
        "mesh",
        "sphere",
        "--level",
        "6:8",
        "--min-level",
        "4",
        "--region",
        "box:-9,-9,-9,9,9,9:5",
        "--region",
        "sphere:0,0,0,0.5:7:outside",
        "--distance",
        "0.1:7",
        "--out",
        out.to_str().unwrap(),
        "--stats",
        stats.to_str().unwrap(),
        "--dry-run",
    ];
    let printed = String::from_utf8_lossy(&octmesh_ok(2, &args).stdout).into_owned();
    let value = |label: &str| -> u64 {
        let line = printed
            .lines()
            .find(|l| l.trim_start().starts_with(label))
            .unwrap_or_else(|| panic!("no '{label}' row in:\n{printed}"));
        line.split_whitespace().last().unwrap().parse().unwrap()
    };
    assert!(!out.exists() && !stats.exists(), "a dry run wrote files");
    assert_eq!(value("min level 4"), 8u64.pow(4));
    assert_eq!(value("region box:-9,-9,-9,9,9,9:5"), 8u64.pow(5));
    assert!(value("region sphere:0,0,0,0.5:7:outside") > 0);
    assert!(value("curvature up to level 8") > value("surface level 6"));
    assert!(value("distance 0.1 at level 7") > 0);
    let rows = [
        "surface level 6",
        "curvature up to level 8",
        "min level 4",
        "region box",
        "region sphere",
        "distance 0.1",
    ];
    let sum: u64 = rows.iter().map(|r| value(r)).sum();
    assert_eq!(value("total"), sum);
    // The surface row is the estimate of the real run.
    let real = dir.join("real.json");
    octmesh_ok(
        1,
        &[
            "mesh",
            "sphere",
            "--level",
            "6",
            "--quiet",
            "--stats",
            real.to_str().unwrap(),
        ],
    );
    let j = json_file(&real);
    let once = String::from_utf8_lossy(
        &octmesh_ok(1, &["mesh", "sphere", "--level", "6", "--dry-run"]).stdout,
    )
    .into_owned();
    assert!(
        once.contains(&format!(" {}\n", int(&j, "estimated_octants"))),
        "the surface estimate {} is not in:\n{once}",
        int(&j, "estimated_octants")
    );
    println!("{printed}");
}

/// Cell sizes in user units give the level whose cell is not larger:
/// `--size`, `--size S:FINE` and `--min-size` build the same octrees as the
/// levels they round to, on either side of a level's cell size; sizes
/// that clash with levels, or are not positive, are refused.
#[test]
fn sizes_round_to_the_level_whose_cell_is_not_larger() {
    let dir = scratch("regions_sizes");
    let stats = |args: &[&str], tag: &str| -> serde_json::Value {
        let path = dir.join(format!("{tag}.json"));
        let mut all = args.to_vec();
        all.extend(["--quiet", "--stats", path.to_str().unwrap()]);
        octmesh_ok(2, &all);
        json_file(&path)
    };
    let base = stats(&["octree", "sphere", "--level", "5"], "base");
    let side = base["domain_side"].as_f64().unwrap();
    let cell5 = side / 32.0;
    for (size, level) in [(cell5 * 1.001, 5u64), (cell5 * 0.999, 6), (cell5 * 2.0, 4)] {
        let s = size.to_string();
        let by_size = stats(&["octree", "sphere", "--size", &s], &format!("s{level}"));
        let l = level.to_string();
        let by_level = stats(&["octree", "sphere", "--level", &l], &format!("l{level}"));
        assert_eq!(int(&by_size, "level"), level, "--size {s}");
        assert_eq!(
            int(&by_size, "octants_balanced"),
            int(&by_level, "octants_balanced"),
            "--size {s} against --level {level}"
        );
    }
    // A range and a minimum size.
    let (coarse, fine, floor) = (
        (cell5 * 1.001).to_string(),
        (cell5 / 4.0).to_string(),
        (cell5 * 4.0).to_string(),
    );
    let range = format!("{coarse}:{fine}");
    let by_size = stats(
        &["mesh", "sphere", "--size", &range, "--min-size", &floor],
        "range_size",
    );
    let by_level = stats(
        &["mesh", "sphere", "--level", "5:7", "--min-level", "3"],
        "range_level",
    );
    for k in ["octants_balanced", "elements", "independent_nodes"] {
        assert_eq!(int(&by_size, k), int(&by_level, k), "{k}");
    }
    // Regions and distance bands by size, and sizes counted from the root
    // cells of a box.
    let region_by_size = format!("sphere:0.5,0,0,0.4:size={}", cell5 / 4.0 * 1.001);
    let band_by_size = format!("0.1:{}", cell5 / 2.0 * 0.999);
    let by_size = stats(
        &[
            "octree",
            "sphere",
            "--level",
            "5",
            "--region",
            &region_by_size,
            "--distance-size",
            &band_by_size,
        ],
        "region_size",
    );
    let by_level = stats(
        &[
            "octree",
            "sphere",
            "--level",
            "5",
            "--region",
            "sphere:0.5,0,0,0.4:7",
            "--distance",
            "0.1:7",
        ],
        "region_level",
    );
    assert_eq!(
        int(&by_size, "octants_balanced"),
        int(&by_level, "octants_balanced")
    );
    let boxed = |size: &str, tag: &str| {
        let mut a = vec!["octree", "sphere", "--box", "-1.5,-1.5,-1.5,3,1.5,1.5"];
        a.extend(["--roots", "3,2,2", "--level", "0", "--min-size", size]);
        stats(&a, tag)
    };
    // Root cells of 1.5: a size of 0.2 is level 3 (0.1875), 0.1875 too.
    let by_size = boxed("0.2", "box_size");
    let exact = boxed("0.1875", "box_exact");
    assert_eq!(int(&by_size, "octants_balanced"), 12 * 8 * 8 * 8);
    assert_eq!(int(&exact, "octants_balanced"), 12 * 8 * 8 * 8);
    let e = octmesh_fails(&[
        "octree",
        "sphere",
        "--level",
        "4",
        "--region",
        "box:0,0,0,1,1,1:size=-1",
    ]);
    assert!(e.contains("positive size"), "{e}");
    let e = octmesh_fails(&[
        "octree",
        "sphere",
        "--level",
        "4",
        "--distance",
        "0.1:5",
        "--distance-size",
        "0.1:0.01",
    ]);
    assert!(e.contains("--distance-size excludes --distance"), "{e}");
    let e = octmesh_fails(&["octree", "sphere", "--size", "0.1", "--level", "4"]);
    assert!(e.contains("--size excludes --level"), "{e}");
    let e = octmesh_fails(&["octree", "sphere", "--size=-1"]);
    assert!(e.contains("positive size"), "{e}");
    let e = octmesh_fails(&["octree", "sphere", "--size", "0.1:0.2"]);
    assert!(e.contains("larger than the surface size"), "{e}");
    let e = octmesh_fails(&["octree", "sphere", "--size", "1e-9"]);
    assert!(e.contains("above the maximum level"), "{e}");
}
