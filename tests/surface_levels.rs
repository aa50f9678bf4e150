//! Levels per part of the surface (`--surface-level NAME=MIN[:MAX]`): the
//! sphere as two solids of one ASCII STL, each with its own range, refines
//! exactly as the two halves refined alone, merged (each leaf the finer of
//! the two runs'): the rule is "split while some part asks for more", so the
//! coarsest octree satisfying both parts is the finer of the two coarsest
//! octrees satisfying each.

mod common;

use common::*;
use octmesh::internals::octree::octant::Octant;
use std::path::{Path, PathBuf};

/// The refined leaves of `octmesh octree SURFACE ARGS`, in a fixed cube
/// unless ARGS give one.
fn refined(surface: &Path, args: &[&str], out: PathBuf, np: usize) -> Vec<Octant> {
    let mut all = vec!["octree", surface.to_str().unwrap()];
    if !args.contains(&"--domain") {
        all.extend(["--domain", "-1.5,-1.5,-1.5,3"]);
    }
    all.extend([
        "--balance",
        "none",
        "--quiet",
        "--write-refined",
        out.to_str().unwrap(),
    ]);
    all.extend(args);
    octmesh_ok(np, &all);
    leaves(&out)
}

/// The finer of two complete linear octrees at every place: the leaves of
/// each that no leaf of the other lies strictly inside.
fn finer_of(a: &[Octant], b: &[Octant]) -> Vec<Octant> {
    let keep = |x: &Octant, other: &[Octant]| {
        // The first leaf of `other` not before `x` in Morton order is
        // inside `x` when any is.
        let i = other.partition_point(|o| o < x);
        !other
            .get(i)
            .is_some_and(|o| *o != *x && x.is_ancestor_of(*o))
    };
    let mut out: Vec<Octant> = a.iter().filter(|x| keep(x, b)).copied().collect();
    out.extend(b.iter().filter(|x| keep(x, a)));
    out.sort_unstable();
    out.dedup();
    out
}

#[test]
fn each_solid_refines_to_its_own_levels() {
    let dir = scratch("surface_levels");
    let (two, top, bottom) = (
        dir.join("two.stl"),
        dir.join("top.stl"),
        dir.join("bottom.stl"),
    );
    write_sphere_solids(&two, &[("top", Some(true)), ("bottom", Some(false))]);
    write_sphere_solids(&top, &[("top", Some(true))]);
    write_sphere_solids(&bottom, &[("bottom", Some(false))]);
    // (the two-solid run's options, the top half's, the bottom half's)
    let cases: [(&[&str], &[&str], &[&str]); 2] = [
        (
            &[
                "--level",
                "3",
                "--surface-level",
                "top=6",
                "--surface-level",
                "bottom=4",
            ],
            &["--level", "6"],
            &["--level", "4"],
        ),
        (
            &[
                "--level",
                "2",
                "--surface-level",
                "top=4:6",
                "--surface-level",
                "bottom=3",
                "--feature-angle",
                "8",
            ],
            &["--level", "4:6", "--feature-angle", "8"],
            &["--level", "3"],
        ),
    ];
    for (k, (both, up, down)) in cases.iter().enumerate() {
        let a = refined(&top, up, dir.join(format!("top{k}.bin")), 1);
        let b = refined(&bottom, down, dir.join(format!("bottom{k}.bin")), 1);
        let want = finer_of(&a, &b);
        assert_complete_linear(&want);
        let deepest = |l: &[Octant]| l.iter().map(|o| o.level()).max().unwrap();
        assert!(
            deepest(&a) > deepest(&b),
            "case {k}: the halves' levels do not differ"
        );
        for np in [1, 3] {
            let got = refined(&two, both, dir.join(format!("two{k}_{np}.bin")), np);
            assert_eq!(
                got.len(),
                want.len(),
                "case {k} np {np}: {} leaves, the halves merged give {}",
                got.len(),
                want.len()
            );
            assert!(got == want, "case {k} np {np}: the leaves differ");
            println!(
                "case {k} np {np}: {} leaves, as the halves refined alone",
                got.len()
            );
        }
    }
    // A name that is no part of the surface fails on every rank.
    for np in [1, 2] {
        let out = mpirun(
            np,
            &octmesh_bin(),
            &[
                "octree",
                two.to_str().unwrap(),
                "--level",
                "3",
                "--surface-level",
                "middle=5",
            ],
            std::time::Duration::from_secs(60),
        );
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{err}");
        assert_eq!(
            err.matches("'middle', which is no part of the surface (its parts: top, bottom)")
                .count(),
            np,
            "{err}"
        );
    }
}

/// Two STL files meshed together (`--surface`): each file is a part, with
/// its own levels and its own wall patch; the octree is the finer of the
/// two files' octrees, as for the solids of one file.
#[test]
fn several_files_are_parts_with_their_own_levels() {
    let dir = scratch("surface_files");
    let sphere = octmesh::internals::geometry::shapes::default_sphere();
    let tris = |dx: f64| -> Vec<[[f32; 3]; 3]> {
        sphere
            .triangles()
            .iter()
            .map(|t| t.v.map(|v| [(v[0] + dx) as f32, v[1] as f32, v[2] as f32]))
            .collect()
    };
    let (near, far) = (dir.join("near.stl"), dir.join("far.stl"));
    write_stl(&near, &tris(0.0), b"near");
    write_stl(&far, &tris(3.0), b"far");
    let cube = ["--domain", "-2,-2,-2,6"];
    let a = refined(
        &near,
        &[&cube[..], &["--level", "5"]].concat(),
        dir.join("a.bin"),
        1,
    );
    let b = refined(
        &far,
        &[&cube[..], &["--level", "4"]].concat(),
        dir.join("b.bin"),
        1,
    );
    let want = finer_of(&a, &b);
    let far_arg = far.to_str().unwrap();
    for np in [1, 2] {
        let args = [
            &cube[..],
            &[
                "--surface",
                far_arg,
                "--level",
                "4",
                "--surface-level",
                "near=5",
            ],
        ]
        .concat();
        let got = refined(&near, &args, dir.join(format!("both{np}.bin")), np);
        assert!(
            got == want,
            "np {np}: {} leaves, the files merged give {}",
            got.len(),
            want.len()
        );
    }
    // Each file is a wall patch of the OpenFOAM case.
    let case = dir.join("case");
    octmesh_ok(
        2,
        &[
            "mesh",
            near.to_str().unwrap(),
            "--surface",
            far_arg,
            "--level",
            "4",
            "--keep",
            "outside",
            "--quiet",
            "--openfoam",
            case.to_str().unwrap(),
        ],
    );
    let boundary =
        std::fs::read_to_string(case.join("processor0/constant/polyMesh/boundary")).unwrap();
    for name in ["near", "far"] {
        let at = boundary
            .find(&format!("    {name}\n"))
            .unwrap_or_else(|| panic!("no patch {name}:\n{boundary}"));
        assert!(
            boundary[at..].lines().take(4).any(|l| l.contains("wall")),
            "{boundary}"
        );
    }
}
