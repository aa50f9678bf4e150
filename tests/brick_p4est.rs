//! Box domains against p4est's bricks: octmesh refines a surface in a box of
//! NX x NY x NZ root cells and writes its refined and balanced leaves as
//! `tree x y z level`; the reference program rebuilds the refined forest on
//! `p8est_connectivity_new_brick(NX, NY, NZ, 0, 0, 0)`, balances it with
//! `p8est_balance`, and counts nodes with `p8est_nodes_new` and
//! `p8est_lnodes_new`. The balanced leaves must be identical, tree by tree,
//! and the node counts equal, on 1 to 4 ranks.

mod common;
use common::*;
use std::path::Path;

/// `(tree, x, y, z, level)` of each leaf of a brick leaf file, and its
/// `# brick` line.
fn brick_leaves(path: &Path) -> (String, Vec<[u32; 5]>) {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{path:?}: {e}"));
    let brick = text
        .lines()
        .find(|l| l.starts_with("# brick "))
        .unwrap_or_else(|| panic!("{path:?} has no brick line"))
        .to_string();
    let leaves = text
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            let v: Vec<u32> = l.split_whitespace().map(|t| t.parse().unwrap()).collect();
            v.try_into()
                .unwrap_or_else(|v| panic!("{path:?}: not five fields: {v:?}"))
        })
        .collect();
    (brick, leaves)
}

struct Case<'a> {
    surface: &'a Path,
    bbox: &'a str,
    roots: [u32; 3],
    level: u32,
}

fn compare(case: &Case, conn: &str, np: usize, dir: &Path) {
    let r = case.roots;
    let tag = format!(
        "{}_{}x{}x{}_{}_{conn}_{np}",
        case.surface.file_stem().unwrap().to_string_lossy(),
        r[0],
        r[1],
        r[2],
        case.level
    );
    let refined = dir.join(format!("{tag}_refined.txt"));
    let ours = dir.join(format!("{tag}_octmesh.txt"));
    let theirs = dir.join(format!("{tag}_p4est.txt"));
    let our_stats = dir.join(format!("{tag}_octmesh.json"));
    let their_stats = dir.join(format!("{tag}_p4est.json"));
    let roots = format!("{},{},{}", r[0], r[1], r[2]);
    let level = case.level.to_string();
    // Face balance cannot be meshed: only the octree then.
    let command = if conn == "face" { "octree" } else { "mesh" };
    octmesh_ok(
        np,
        &[
            command,
            case.surface.to_str().unwrap(),
            "--box",
            case.bbox,
            "--roots",
            &roots,
            "--level",
            &level,
            "--balance",
            conn,
            "--quiet",
            "--write-refined",
            refined.to_str().unwrap(),
            "--write-leaves",
            ours.to_str().unwrap(),
            "--stats",
            our_stats.to_str().unwrap(),
        ],
    );
    let mut args = vec![
        "--in",
        refined.to_str().unwrap(),
        "--balance",
        conn,
        "--out",
        theirs.to_str().unwrap(),
        "--json",
        their_stats.to_str().unwrap(),
    ];
    if conn != "face" {
        args.push("--nodes");
    }
    p4est_ref_ok(np, &args, &tag);
    let (brick, a) = brick_leaves(&ours);
    assert_eq!(
        brick,
        format!("# brick {} {} {}", r[0], r[1], r[2]),
        "{tag}"
    );
    let (_, b) = brick_leaves(&theirs);
    let (_, before) = brick_leaves(&refined);
    assert!(a.len() > before.len(), "{tag}: balance added nothing");
    let trees = (r[0] * r[1] * r[2]) as usize;
    let mut seen = vec![false; trees];
    for l in &a {
        seen[l[0] as usize] = true;
    }
    assert!(
        seen.iter().all(|&s| s),
        "{tag}: some tree has no leaf: {seen:?}"
    );
    common::assert_same_leaves(&a, &b, &tag);
    let (s, p) = (json_file(&our_stats), json_file(&their_stats));
    assert_eq!(int(&s, "octants_balanced"), a.len() as u64, "{tag}");
    if conn != "face" {
        let m = &s;
        assert_eq!(int(m, "elements"), a.len() as u64, "{tag}: keep all");
        assert_eq!(
            int(m, "independent_nodes"),
            int(&p, "lnodes_global"),
            "{tag}: independent nodes against p8est_lnodes"
        );
        assert_eq!(
            int(m, "elements_with_hanging"),
            int(&p, "lnodes_hanging_elements"),
            "{tag}: elements with hanging nodes against p8est_lnodes"
        );
        if conn == "corner" {
            for k in ["face_hanging_nodes", "edge_hanging_nodes"] {
                assert_eq!(int(m, k), int(&p, k), "{tag}: {k} against p8est_nodes");
            }
        }
        // Keep all: the elements fill the box exactly.
        let b: Vec<f64> = case.bbox.split(',').map(|t| t.parse().unwrap()).collect();
        let volume = (b[3] - b[0]) * (b[4] - b[1]) * (b[5] - b[2]);
        let kept = num(m, "kept_volume");
        assert!(
            (kept - volume).abs() < 1e-9 * volume,
            "{tag}: kept volume {kept}, box volume {volume}"
        );
    }
    println!("{tag}: {} balanced leaves equal to p4est", a.len());
}

/// The built-in sphere in a 3 x 1 x 1 box that cuts it (the surface leaves
/// the box on four sides), every connectivity, 1 to 4 ranks.
#[test]
fn sphere_in_a_brick_equals_p4est() {
    let dir = scratch("brick_sphere");
    let case = Case {
        surface: Path::new("sphere"),
        bbox: "-1.5,-0.5,-0.5,1.5,0.5,0.5",
        roots: [3, 1, 1],
        level: 4,
    };
    for (np, conn) in [(1, "corner"), (2, "edge"), (3, "face"), (4, "corner")] {
        compare(&case, conn, np, &dir);
    }
}

/// The bunny in a 3 x 1 x 1 and a 4 x 2 x 3 brick around it (the issue's
/// cases), 1 to 4 ranks.
#[test]
fn bunny_in_bricks_equals_p4est() {
    let Some(bunny) = shared_model("bunny.stl") else {
        return;
    };
    let dir = scratch("brick_bunny");
    let long = Case {
        surface: &bunny,
        bbox: "-1.6,-0.6,-0.6,2.0,0.6,0.6",
        roots: [3, 1, 1],
        level: 5,
    };
    let block = Case {
        surface: &bunny,
        bbox: "-1.0,-0.55,-0.75,1.0,0.45,0.75",
        roots: [4, 2, 3],
        level: 4,
    };
    for (np, conn) in [(1, "corner"), (2, "face"), (3, "edge"), (4, "corner")] {
        compare(&long, conn, np, &dir);
    }
    for (np, conn) in [(1, "edge"), (2, "corner"), (3, "corner"), (4, "face")] {
        compare(&block, conn, np, &dir);
    }
}
