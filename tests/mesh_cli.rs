//! The `octmesh mesh` command: solid and fluid selections, volumes, the
//! PVTU read back by an independent reader (meshio), the boundary faces'
//! PVTP read back by VTK itself, and its errors.

mod common;
use common::*;
use std::path::Path;
use std::process::Command;
use std::time::Duration;

/// Runs `octmesh mesh` and returns its statistics.
fn mesh_stats(
    np: usize,
    surface: &str,
    level: u32,
    extra: &[&str],
    dir: &Path,
) -> serde_json::Value {
    let stats = dir.join(format!(
        "{}_{level}_{}_{np}.json",
        Path::new(surface).file_stem().unwrap().to_string_lossy(),
        extra.join("_").replace(['/', '.'], "")
    ));
    let level = level.to_string();
    let mut args = vec![
        "mesh",
        surface,
        "--level",
        &level,
        "--quiet",
        "--stats",
        stats.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    octmesh_ok(np, &args);
    json_file(&stats)
}

#[test]
fn inside_and_outside_tile_the_cube() {
    let dir = scratch("mesh_tile");
    for (surface, np) in [("sphere", 1), ("torus", 3)] {
        let all = mesh_stats(np, surface, 6, &["--keep", "all"], &dir);
        let inside = mesh_stats(np, surface, 6, &["--keep", "inside"], &dir);
        let outside = mesh_stats(np, surface, 6, &["--keep", "outside"], &dir);
        assert_eq!(
            int(&all, "kept_cells"),
            1u64 << 57,
            "{surface}: all = the cube"
        );
        assert_eq!(
            int(&inside, "kept_cells") + int(&outside, "kept_cells"),
            int(&all, "kept_cells"),
            "{surface}: inside + outside"
        );
        assert_eq!(
            int(&inside, "elements") + int(&outside, "elements"),
            int(&all, "elements"),
            "{surface}: every element on exactly one side"
        );
        let side = num(&all, "domain_side");
        assert!((num(&all, "kept_volume") - side.powi(3)).abs() <= 1e-12 * side.powi(3));
        // Both selections are meshes of their own: nodes only where used.
        assert!(int(&inside, "independent_nodes") < int(&all, "independent_nodes"));
        assert!(int(&outside, "independent_nodes") < int(&all, "independent_nodes"));
    }
}

/// Relative error of the solid's volume at each level.
fn volume_errors(surface: &str, levels: &[u32], np: usize, dir: &Path) -> Vec<f64> {
    levels
        .iter()
        .map(|&l| {
            let s = mesh_stats(np, surface, l, &["--keep", "inside"], dir);
            let (v, want) = (num(&s, "kept_volume"), num(&s, "surface_volume"));
            let e = (v - want).abs() / want;
            println!("{surface} level {l}: solid volume {v:.6e}, enclosed {want:.6e}, relative error {e:.2e}");
            e
        })
        .collect()
}

#[test]
fn solid_volume_converges_for_built_in_shapes() {
    let dir = scratch("mesh_volume");
    for surface in ["sphere", "torus"] {
        let e = volume_errors(surface, &[4, 6, 8], 2, &dir);
        assert!(
            e[1] < e[0] && e[2] < e[1],
            "{surface}: errors {e:?} do not shrink"
        );
        assert!(e[2] < 2e-3, "{surface}: level 8 error {:e}", e[2]);
    }
}

#[test]
fn solid_volume_converges_for_shared_models() {
    let dir = scratch("mesh_volume_models");
    for name in ["bunny.stl", "dragon.stl"] {
        let Some(path) = shared_model(name) else {
            continue;
        };
        let e = volume_errors(path.to_str().unwrap(), &[5, 7, 9], 2, &dir);
        assert!(
            e[1] < e[0] && e[2] < e[1],
            "{name}: errors {e:?} do not shrink"
        );
        assert!(e[2] < 1e-2, "{name}: level 9 error {:e}", e[2]);
    }
}

#[test]
fn pvtu_is_read_back_by_meshio() {
    let dir = scratch("mesh_vtu");
    for (keep, np) in [("all", 1), ("inside", 3), ("outside", 2)] {
        let out = dir.join(format!("torus_{keep}.pvtu"));
        let s = mesh_stats(
            np,
            "torus",
            5,
            &[
                "--keep",
                keep,
                "--balance",
                "edge",
                "--out",
                out.to_str().unwrap(),
            ],
            &dir,
        );
        let py = Command::new(python_with_meshio())
            .arg(repo().join("tools").join("check_vtu.py"))
            .arg(&out)
            .output()
            .expect("run tools/check_vtu.py");
        assert!(
            py.status.success(),
            "check_vtu.py failed: {}",
            String::from_utf8_lossy(&py.stderr)
        );
        let r: serde_json::Value =
            serde_json::from_slice(&py.stdout).expect("JSON from check_vtu.py");
        assert_eq!(int(&r, "pieces"), np as u64, "{keep}: one piece per rank");
        assert_eq!(int(&r, "cells"), int(&s, "elements"), "{keep}: cells");
        assert_eq!(
            int(&r, "points"),
            int(&s, "points_written"),
            "{keep}: points"
        );
        let (v, want) = (num(&r, "volume"), num(&s, "kept_volume"));
        assert!(
            (v - want).abs() <= 1e-9 * want,
            "{keep}: volume {v} against {want}"
        );
        assert_eq!(
            int(&r, "max_global_id") + 1,
            int(&s, "independent_nodes"),
            "{keep}: ids"
        );
        assert!(
            int(&r, "hanging_points") > 0,
            "{keep}: hanging points flagged"
        );
    }
}

/// `tools/check_vtp.py` (VTK's own reader) on a boundary PVTP.
fn check_vtp(pvtp: &Path) -> serde_json::Value {
    let out = Command::new(python_with("vtk", "python3-vtk9"))
        .arg(repo().join("tools/check_vtp.py"))
        .arg(pvtp)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "check_vtp.py {}: {}",
        pvtp.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn boundary_pvtp_is_read_back_by_vtk() {
    let dir = scratch("mesh_boundary_vtp");
    // Everything kept: each side patch covers its side, outwards.
    let all = dir.join("all.pvtu");
    let s = mesh_stats(2, "sphere", 4, &["--out", all.to_str().unwrap()], &dir);
    let side = s["domain_side"].as_f64().unwrap();
    let v = check_vtp(&dir.join("all_boundary.pvtp"));
    for p in 0..6 {
        let e = &v["patches"][p.to_string()];
        let area = e["area"].as_f64().unwrap();
        assert!(
            ((area - side * side) / (side * side)).abs() < 1e-12,
            "side {p}: {area}"
        );
        let n = e["normal"][p / 2].as_f64().unwrap();
        let out = if p % 2 == 0 { -1.0 } else { 1.0 };
        assert!(
            (n - out * area).abs() < 1e-9 * area,
            "side {p} does not face out"
        );
    }
    assert!(
        v["patches"].get("6").is_none(),
        "no surface faces when all is kept"
    );
    // The fluid around the sphere on 1 and 3 ranks: the same patches, and
    // the faces of the OpenFOAM case written in the same run.
    let mut seen = Vec::new();
    for np in [1usize, 3] {
        let pvtu = dir.join(format!("fluid{np}.pvtu"));
        let case = dir.join(format!("case{np}"));
        mesh_stats(
            np,
            "sphere",
            5,
            &[
                "--keep",
                "outside",
                "--out",
                pvtu.to_str().unwrap(),
                "--openfoam",
                case.to_str().unwrap(),
            ],
            &dir,
        );
        let v = check_vtp(&dir.join(format!("fluid{np}_boundary.pvtp")));
        assert_eq!(v["names"]["6"], "sphere");
        let counts: Vec<u64> = (0..7)
            .map(|p| v["patches"][p.to_string()]["faces"].as_u64().unwrap_or(0))
            .collect();
        let polymesh = if np == 1 {
            vec![case.join("constant/polyMesh/boundary")]
        } else {
            (0..np)
                .map(|r| case.join(format!("processor{r}/constant/polyMesh/boundary")))
                .collect()
        };
        let names = ["xmin", "xmax", "ymin", "ymax", "zmin", "zmax", "sphere"];
        let mut foam = vec![0u64; 7];
        for b in polymesh {
            let text = std::fs::read_to_string(b).unwrap();
            for (k, name) in names.iter().enumerate() {
                let at = text.find(&format!("    {name}\n")).unwrap();
                let n = text[at..].split("nFaces").nth(1).unwrap();
                let n: u64 = n
                    .trim_start()
                    .split(';')
                    .next()
                    .unwrap()
                    .trim()
                    .parse()
                    .unwrap();
                foam[k] += n;
            }
        }
        assert_eq!(
            counts, foam,
            "np {np}: PVTP faces per patch against the polyMesh"
        );
        // The surface patch is closed: its area vectors cancel.
        let s6 = &v["patches"]["6"];
        let area = s6["area"].as_f64().unwrap();
        for k in 0..3 {
            assert!(s6["normal"][k].as_f64().unwrap().abs() < 1e-9 * area);
        }
        seen.push(counts);
    }
    assert_eq!(seen[0], seen[1], "patches differ between 1 and 3 ranks");
    println!(
        "boundary PVTP: sides cover the cube, faces per patch {:?} on 1 and 3 ranks = polyMesh",
        seen[0]
    );
}

#[test]
fn mesh_rejects_face_balance_and_unwritable_output() {
    for np in [1, 3] {
        let out = mpirun(
            np,
            &octmesh_bin(),
            &["mesh", "sphere", "--level", "4", "--balance", "face"],
            Duration::from_secs(120),
        );
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success());
        assert!(err.contains("edge or corner"), "{err}");
        assert!(!err.contains("panicked"), "{err}");

        let out = mpirun(
            np,
            &octmesh_bin(),
            &[
                "mesh",
                "sphere",
                "--level",
                "4",
                "--out",
                "/nonexistent/dir/m.pvtu",
            ],
            Duration::from_secs(120),
        );
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success());
        for r in 0..np {
            assert!(
                err.contains(&format!("[rank {r} of {np}]")),
                "rank {r} reported nothing: {err}"
            );
        }
        assert!(err.contains("/nonexistent/dir"), "{err}");
        assert!(!err.contains("panicked"), "{err}");
    }
}
