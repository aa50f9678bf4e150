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
