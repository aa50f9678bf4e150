//! The finite-element oracles of [`common::fe_oracle`] on the meshes
//! octmesh writes today, so that meshes without hanging nodes (one level
//! everywhere now, `--conforming` ones later) and meshes with them are
//! told apart by codes that take no hanging-node constraints:
//!
//! - dolfinx (Debian `python3-dolfinx`) reads the `.msh` through Gmsh and
//!   solves a Poisson problem in the trilinear space
//!   (`tools/fe_oracle/poisson_dolfinx.py`). On one-level meshes (the
//!   whole cube at level 3, the solid sphere at level 4 with every leaf
//!   at level 4, and the same snapped to the surface: distorted
//!   hexahedra) the linear solution is exact at every node to 1e-8; on
//!   the solid sphere at level 4 with its 2:1 steps it is off by more than
//!   1e-3. The smooth solution's L2 error on the one-level solid sphere
//!   falls at least 3.5 times per level from level 3 to 5.
//! - CalculiX (Debian `calculix-ccx`) on the `.inp` deck: the displacement
//!   patch test is exact on the same one-level decks (which have no
//!   `*EQUATION`; the snapped one's coordinates are no short decimals),
//!   and on the solid sphere at level 4 it is exact with
//!   the deck's equations and off by more than 1e-3 without them.
//!
//! The independent conformity checker ([`common::conformity`]) says which
//! meshes are conforming, so the oracles' yes and no are checked against
//! a third judge.

mod common;

use std::path::{Path, PathBuf};

use common::conformity::check;
use common::fe_oracle::{
    assert_patch_test_exact, assert_patch_test_fails, assert_second_order, calculix_patch_test,
    Equations, EXACT, FAILED,
};
use common::{json_file, octmesh_ok, scratch};

/// The box of the solid sphere's meshes, as `--domain` and as the frame
/// of the manufactured solutions.
const CUBE: &str = "-1.28,-1.28,-1.28,2.56";
const FRAME: [f64; 4] = [-1.28, -1.28, -1.28, 2.56];

/// Meshes the built-in sphere with `args` on 2 ranks into
/// `DIR/m.inp` and `DIR/m.msh`; the two paths.
fn mesh(dir: &Path, args: &[&str]) -> (PathBuf, PathBuf) {
    std::fs::create_dir_all(dir).unwrap();
    let (inp, msh, stats) = (dir.join("m.inp"), dir.join("m.msh"), dir.join("s.json"));
    let mut all = vec!["mesh", "sphere"];
    all.extend(args);
    all.extend(["--abaqus", inp.to_str().unwrap()]);
    all.extend(["--gmsh", msh.to_str().unwrap()]);
    all.extend(["--stats", stats.to_str().unwrap(), "--quiet"]);
    octmesh_ok(2, &all);
    let s = json_file(&stats);
    let hanging = common::int(&s, "face_hanging_nodes") + common::int(&s, "edge_hanging_nodes");
    let c = check(&msh);
    assert_eq!(
        c.conforming(),
        hanging == 0,
        "{}: the checker and octmesh's {hanging} hanging nodes disagree: {c:?}",
        dir.display()
    );
    (inp, msh)
}

/// The whole cube at level 3.
fn whole_cube(dir: &Path) -> (PathBuf, PathBuf) {
    mesh(dir, &["--level", "3", "--min-level", "3", "--keep", "all"])
}

/// The solid sphere at `level` in [`CUBE`], every leaf at that level when
/// `one_level`, else with the surface's refinement and its 2:1 steps;
/// `more` are further options.
fn solid_sphere(dir: &Path, level: &str, one_level: bool, more: &[&str]) -> (PathBuf, PathBuf) {
    let mut args = vec!["--level", level, "--keep", "inside", "--domain", CUBE];
    if one_level {
        args.extend(["--min-level", level]);
    }
    args.extend(more);
    mesh(dir, &args)
}

#[test]
fn dolfinx_patch_test_exact_on_one_level_meshes_only() {
    let dir = scratch("fe_oracle_dolfinx_patch");
    let (_, cube) = whole_cube(&dir.join("cube3"));
    let (_, sphere) = solid_sphere(&dir.join("sphere4_one_level"), "4", true, &[]);
    let (_, snapped) = solid_sphere(&dir.join("sphere4_snapped"), "4", true, &["--snap"]);
    let (_, hanging) = solid_sphere(&dir.join("sphere4"), "4", false, &[]);
    assert!(!check(&hanging).conforming());
    let Some(e_cube) = assert_patch_test_exact(&cube) else {
        return;
    };
    let e_sphere = assert_patch_test_exact(&sphere).unwrap();
    let e_snapped = assert_patch_test_exact(&snapped).unwrap();
    let e_hanging = assert_patch_test_fails(&hanging).unwrap();
    println!(
        "dolfinx patch test, largest nodal error: whole cube level 3 {e_cube:.2e}, solid sphere \
         level 4 one level {e_sphere:.2e}, the same snapped {e_snapped:.2e}, solid sphere level 4 \
         with hanging nodes {e_hanging:.2e}"
    );
}

#[test]
fn dolfinx_smooth_solution_converges_at_second_order_on_one_level_meshes() {
    let dir = scratch("fe_oracle_dolfinx_order");
    let meshes: Vec<PathBuf> = ["3", "4", "5"]
        .iter()
        .map(|l| solid_sphere(&dir.join(format!("sphere{l}")), l, true, &[]).1)
        .collect();
    let paths: Vec<&Path> = meshes.iter().map(PathBuf::as_path).collect();
    let Some(errors) = assert_second_order(&paths, FRAME, 3.5) else {
        return;
    };
    let shown: Vec<String> = errors.iter().map(|e| format!("{e:.3e}")).collect();
    println!(
        "dolfinx smooth solution on the one-level solid sphere, levels 3-5: L2 errors {}",
        shown.join(", ")
    );
}

#[test]
fn calculix_patch_test_without_equations() {
    let dir = scratch("fe_oracle_calculix");
    let (cube, _) = whole_cube(&dir.join("cube3"));
    let (sphere, _) = solid_sphere(&dir.join("sphere4_one_level"), "4", true, &[]);
    let (snapped, _) = solid_sphere(&dir.join("sphere4_snapped"), "4", true, &["--snap"]);
    let (hanging, _) = solid_sphere(&dir.join("sphere4"), "4", false, &[]);
    for deck in [&cube, &sphere, &snapped] {
        let text = std::fs::read_to_string(deck).unwrap();
        assert!(!text.contains("*EQUATION"), "{}", deck.display());
    }
    let Some(e_cube) = assert_patch_test_exact(&cube) else {
        return;
    };
    let e_sphere = assert_patch_test_exact(&sphere).unwrap();
    let e_snapped = assert_patch_test_exact(&snapped).unwrap();
    let with = calculix_patch_test(&hanging, Equations::Keep).unwrap();
    assert!(with.equations > 0, "the level-4 sphere has hanging nodes");
    assert!(
        with.error <= EXACT,
        "with its equations the deck passes: {with:?}"
    );
    let without = assert_patch_test_fails(&hanging).unwrap();
    assert!(without > FAILED);
    println!(
        "CalculiX patch test, largest interior error: whole cube level 3 {e_cube:.2e}, solid \
         sphere level 4 one level {e_sphere:.2e}, the same snapped {e_snapped:.2e}; solid sphere \
         level 4 with {} hanging nodes: \
         {:.2e} with the equations, {without:.2e} without",
        with.equations, with.error
    );
}
