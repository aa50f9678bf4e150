//! Curvature refinement (`--level MIN:MAX --feature-angle DEG`): leaves on a
//! flat face stay at MIN, leaves on the cube's sharp edges reach MAX; on
//! the sphere the finer level appears only when the angle is below the
//! turn of the surface across a leaf.

mod common;

use common::*;

/// The closed cube `lo..hi` as 12 outward triangles.
fn cube(lo: f32, hi: f32) -> Vec<[[f32; 3]; 3]> {
    let p = |i: u32| -> [f32; 3] { std::array::from_fn(|k| if i >> k & 1 == 1 { hi } else { lo }) };
    // Each face as two triangles, corners by bits (x = 1, y = 2, z = 4).
    let faces = [
        [0, 4, 6, 2],
        [1, 3, 7, 5],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 2, 3, 1],
        [4, 5, 7, 6],
    ];
    faces
        .iter()
        .flat_map(|f| [[p(f[0]), p(f[1]), p(f[2])], [p(f[0]), p(f[2]), p(f[3])]])
        .collect()
}

/// Which of the cube's faces (as planes x = lo, x = hi, ...) the closed
/// box `a..b` (user units) reaches, within the face's square.
fn faces_touched(a: [f64; 3], b: [f64; 3], lo: f64, hi: f64) -> usize {
    let mut n = 0;
    for k in 0..3 {
        for plane in [lo, hi] {
            let on_plane = a[k] <= plane && plane <= b[k];
            let within = (0..3).filter(|&j| j != k).all(|j| a[j] <= hi && lo <= b[j]);
            n += usize::from(on_plane && within);
        }
    }
    n
}

#[test]
fn sharp_edges_reach_max_and_flat_faces_stay_at_min() {
    let dir = scratch("curvature_cube");
    let stl = dir.join("cube.stl");
    let (lo, hi) = (0.2f32, 0.7f32);
    write_stl(&stl, &cube(lo, hi), b"cube");
    for np in [1, 2] {
        let file = dir.join(format!("leaves{np}.txt"));
        octmesh_ok(
            np,
            &[
                "octree",
                stl.to_str().unwrap(),
                "--level",
                "3:6",
                "--domain",
                "0,0,0,1",
                "--balance",
                "none",
                "--quiet",
                "--write-leaves",
                file.to_str().unwrap(),
            ],
        );
        let leaves = leaves(&file);
        let (mut at_max, mut flat) = (0, 0);
        let unit = (1u64 << 19) as f64;
        // The faces the closed box of an octant (lattice anchor, level) reaches.
        let touched = |c: [u32; 3], level: u8| {
            let len = (1u32 << (19 - level)) as f64 / unit;
            let a: [f64; 3] = std::array::from_fn(|k| c[k] as f64 / unit);
            let b: [f64; 3] = std::array::from_fn(|k| a[k] + len);
            faces_touched(a, b, lo as f64, hi as f64)
        };
        for o in &leaves {
            let n = touched(o.coords(), o.level());
            if n >= 2 {
                // On an edge or a corner the normals turn by 90 degrees.
                at_max += 1;
                assert_eq!(o.level(), 6, "a leaf on an edge or corner: {o:?}");
            } else if n == 1 && o.level() == 3 {
                flat += 1;
            }
            if o.level() > 3 {
                // No finer than needed: the parent was on an edge or corner.
                let p = o.parent();
                assert!(
                    touched(p.coords(), p.level()) >= 2,
                    "{o:?} is finer than any rule asks"
                );
            }
        }
        assert!(
            at_max > 0 && flat > 0,
            "np {np}: {at_max} edge leaves, {flat} flat ones"
        );
    }
}

#[test]
fn the_sphere_refines_only_below_its_turn_per_leaf() {
    let dir = scratch("curvature_sphere");
    let stats = dir.join("s.json");
    let s = stats.to_str().unwrap();
    let run = |angle: &str| {
        octmesh_ok(
            1,
            &[
                "octree",
                "sphere",
                "--level",
                "4:6",
                "--feature-angle",
                angle,
                "--balance",
                "none",
                "--quiet",
                "--stats",
                s,
            ],
        );
        int(&json_file(&stats), "octants_refined")
    };
    octmesh_ok(
        1,
        &[
            "octree",
            "sphere",
            "--level",
            "4",
            "--balance",
            "none",
            "--quiet",
            "--stats",
            s,
        ],
    );
    let plain = int(&json_file(&stats), "octants_refined");
    // A level-4 leaf spans about 10 degrees of the unit sphere (side
    // 2.857 / 16): a 30-degree angle refines nothing, a 2-degree one
    // refines the surface leaves.
    assert_eq!(run("30"), plain);
    assert!(run("2") > plain);
}

/// The fandisk's sharp edges get the finest level: every leaf holding the
/// midpoint of an edge whose two facets turn by more than 45 degrees (well
/// above the 30-degree feature angle) is at MAX. Sharp edges are found here
/// from the facets alone: vertices welded by their coordinates, the
/// dihedral turn from the facets' normals.
#[test]
fn the_fandisk_sharp_edges_reach_max() {
    let Some(fandisk) = shared_model("fandisk.stl") else {
        return;
    };
    let dir = scratch("curvature_fandisk");
    let s = octmesh::internals::geometry::load_surface(fandisk.to_str().unwrap()).unwrap();
    type Key = [u64; 3];
    let key = |p: [f64; 3]| p.map(f64::to_bits);
    let normal = |t: &octmesh::internals::geometry::Triangle| {
        let n = t.normal();
        let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        n.map(|c| c / l)
    };
    let mut by_edge: std::collections::HashMap<(Key, Key), Vec<usize>> = Default::default();
    for (i, t) in s.triangles().iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (key(t.v[k]), key(t.v[(k + 1) % 3]));
            by_edge.entry((a.min(b), a.max(b))).or_default().push(i);
        }
    }
    let cos45 = 45f64.to_radians().cos();
    let mut midpoints = Vec::new();
    for ((a, b), f) in &by_edge {
        if let [i, j] = f[..] {
            let (n, m) = (normal(&s.triangles()[i]), normal(&s.triangles()[j]));
            if n[0] * m[0] + n[1] * m[1] + n[2] * m[2] < cos45 {
                let p = |k: &Key| k.map(f64::from_bits);
                let (a, b) = (p(a), p(b));
                midpoints.push(std::array::from_fn::<f64, 3, _>(|c| 0.5 * (a[c] + b[c])));
            }
        }
    }
    assert!(midpoints.len() > 50, "only {} sharp edges", midpoints.len());
    let (min, max) = ("4", 7u8);
    for np in [1, 2] {
        let file = dir.join(format!("leaves{np}.bin"));
        let stats = dir.join(format!("s{np}.json"));
        octmesh_ok(
            np,
            &[
                "octree",
                fandisk.to_str().unwrap(),
                "--level",
                &format!("{min}:{max}"),
                "--balance",
                "none",
                "--quiet",
                "--write-leaves",
                file.to_str().unwrap(),
                "--stats",
                stats.to_str().unwrap(),
            ],
        );
        let leaves = leaves(&file);
        let side = num(&json_file(&stats), "domain_side");
        // The cube octmesh fitted: centred on the surface's box.
        let b = s.bbox();
        let origin: [f64; 3] = std::array::from_fn(|k| 0.5 * (b.min[k] + b.max[k]) - 0.5 * side);
        let unit = side / (1u64 << 19) as f64;
        let mut coarse = 0;
        for p in &midpoints {
            let q: [u32; 3] = std::array::from_fn(|k| ((p[k] - origin[k]) / unit) as u32);
            let cell = octmesh::internals::octree::octant::morton_encode(q[0], q[1], q[2]);
            let i = leaves.partition_point(|o| o.cell_begin() <= cell) - 1;
            coarse += usize::from(leaves[i].level() < max);
        }
        assert_eq!(
            coarse,
            0,
            "np {np}: {coarse} of {} sharp-edge midpoints lie in leaves below level {max}",
            midpoints.len()
        );
        // Flat parts stay coarser: fewer leaves than the whole surface at MAX.
        let everywhere = dir.join(format!("all{np}.json"));
        octmesh_ok(
            np,
            &[
                "octree",
                fandisk.to_str().unwrap(),
                "--level",
                &max.to_string(),
                "--balance",
                "none",
                "--quiet",
                "--stats",
                everywhere.to_str().unwrap(),
            ],
        );
        let all = int(&json_file(&everywhere), "octants_refined") as usize;
        assert!(
            leaves.len() < all,
            "np {np}: {} leaves, {all} at level {max} everywhere",
            leaves.len()
        );
        println!(
            "np {np}: {} sharp edges, all in level-{max} leaves",
            midpoints.len()
        );
    }
}
