//! The single-file finite-element meshes (`--abaqus FILE.inp`, `--gmsh
//! FILE.msh`) of hanging-node meshes, judged by the programs that read
//! them: CalculiX (Debian `calculix-ccx`) and Gmsh's Python API (Debian
//! `python3-gmsh`), both installed by `scripts/setup.sh`.
//!
//! - The patch test in CalculiX on the solid sphere (level 4 and 5) and the
//!   solid bunny (level 5): the deck, completed with a material, a
//!   section and a static step that prescribes a linear displacement
//!   `u = A x + b` on every node of the patch node sets, gives every
//!   interior independent node `u` to 1e-8 relative to the field's size.
//!   CalculiX prints 7 significant digits, so the cube and the field are
//!   chosen to make every exact nodal value a short decimal: a printed
//!   value is then exact unless the solver is off by half a unit in its
//!   7th digit, and anything larger shows in full. The same deck without
//!   its `*EQUATION`s must fail the test by far (the hanging corners come
//!   loose), which shows the test can fail.
//! - A gravity load in CalculiX on the solid bunny (level 5) and
//!   armadillo (level 7), meshed on 1 and 3 ranks: held at the bottom,
//!   the total reaction is the weight the held nodes do not carry
//!   themselves, to CalculiX's printed digits, and nothing sideways; the
//!   elements weigh the kept volume octmesh reports.
//! - The solid bunny at level 5 is one piece joined through faces with
//!   the clean-up a finite-element file turns on; without it the run
//!   reports the pieces and warns.
//! - The deck and the `.msh` are byte-identical on 1 to 4 ranks.
//! - Gmsh opens the `.msh`: its node, hexahedron and quadrilateral
//!   counts are octmesh's and the `.inp`'s, its physical surfaces are the
//!   patches with faces, and its physical volume is `volume`.
//! - A file that cannot be written (Abaqus, Gmsh, Exodus II, CGNS) fails
//!   the run on every rank.

mod common;

use std::collections::{BTreeSet, HashSet};
use std::path::{Path, PathBuf};
use std::process::Command;

use common::fe_oracle::{ccx, patch_test, read_deck, run_ccx, without_equations};
use common::{json_file, octmesh_ok, require, scratch, shared_model, Oracle};

/// A Python with `gmsh`, or `None` after a skip.
fn gmsh_python() -> Option<PathBuf> {
    require(Oracle::Python {
        module: "gmsh",
        package: "python3-gmsh",
    })
}

/// Runs `octmesh mesh INPUT ARGS --abaqus DIR/m.inp --gmsh DIR/m.msh` on
/// `np` ranks; returns the two files' paths and the statistics.
fn mesh(
    np: usize,
    dir: &Path,
    input: &str,
    args: &[&str],
) -> (PathBuf, PathBuf, serde_json::Value) {
    std::fs::create_dir_all(dir).unwrap();
    let (inp, msh, stats) = (dir.join("m.inp"), dir.join("m.msh"), dir.join("s.json"));
    let mut all = vec!["mesh", input];
    all.extend(args);
    all.extend([
        "--abaqus",
        inp.to_str().unwrap(),
        "--gmsh",
        msh.to_str().unwrap(),
    ]);
    all.extend(["--stats", stats.to_str().unwrap(), "--quiet"]);
    octmesh_ok(np, &all);
    let s = json_file(&stats);
    (inp, msh, s)
}

/// The patch test of `input` meshed with `args`, with and without the
/// equations; returns both errors.
fn patch_tests(name: &str, input: &str, args: &[&str]) -> Option<(f64, f64)> {
    let ccx = ccx()?;
    let dir = scratch(&format!("fe_files_{name}"));
    let (inp, _, stats) = mesh(1, &dir.join("mesh"), input, args);
    let text = std::fs::read_to_string(&inp).unwrap();
    let hanging =
        common::int(&stats, "face_hanging_nodes") + common::int(&stats, "edge_hanging_nodes");
    assert!(hanging > 0, "{name}: the test needs hanging nodes");
    let deck = read_deck(&text);
    assert_eq!(
        deck.hanging.len() as u64,
        hanging,
        "{name}: an equation set per hanging node"
    );
    let (with, interior) = patch_test(&ccx, &dir.join("with"), &text);
    let (without, _) = patch_test(&ccx, &dir.join("without"), &without_equations(&text));
    println!(
        "{name}: {interior} interior independent nodes, {hanging} hanging; patch test error \
         {with:.3e} with the equations, {without:.3e} without"
    );
    assert!(interior > 0, "{name}: no interior node");
    assert!(
        with <= 1e-8,
        "{name}: patch test off by {with:e} with the equations"
    );
    assert!(
        without > 1e-3,
        "{name}: without the equations the error is only {without:e}"
    );
    Some((with, without))
}

#[test]
fn calculix_patch_test_solid_sphere() {
    for level in ["4", "5"] {
        patch_tests(
            &format!("sphere{level}"),
            "sphere",
            &[
                "--level",
                level,
                "--keep",
                "inside",
                "--domain",
                "-1.28,-1.28,-1.28,2.56",
            ],
        );
    }
}

#[test]
fn calculix_patch_test_solid_bunny() {
    let Some(bunny) = shared_model("bunny.stl") else {
        return;
    };
    patch_tests(
        "bunny5",
        bunny.to_str().unwrap(),
        &[
            "--level",
            "5",
            "--keep",
            "inside",
            "--domain",
            "-0.64,-0.64,-0.64,1.28",
        ],
    );
}

/// The gravity test: the deck of `input` meshed on `np` ranks with `args`,
/// held at its nodes outside any equation in the lowest tenth of its
/// height and
/// loaded by its own weight (density 2.5, g = 4 along -z). CalculiX's
/// total reaction of the held nodes must be the weight, `2.5 * 4 * V`
/// with V the kept volume octmesh reports, to 1e-5 relative (the printed
/// 7 digits), and nothing sideways. Returns the reaction.
fn gravity_test(name: &str, np: usize, input: &str, args: &[&str]) -> Option<[f64; 3]> {
    let ccx = ccx()?;
    let dir = scratch(&format!("fe_files_gravity_{name}_np{np}"));
    let (inp, _, stats) = mesh(np, &dir.join("mesh"), input, args);
    let pieces = stats["pieces"]
        .as_array()
        .expect("pieces in the statistics");
    assert_eq!(pieces.len(), 1, "{name}: the mesh is one piece: {pieces:?}");
    let text = std::fs::read_to_string(&inp).unwrap();
    let deck = read_deck(&text);
    let (lo, hi) = deck
        .coords
        .values()
        .fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p[2]), b.max(p[2])));
    // Nodes of no equation: a support on a hanging node would constrain
    // a freedom twice, and CalculiX's reaction at a node leaves out what
    // reaches it through an equation.
    let held: Vec<u64> = deck
        .coords
        .iter()
        .filter(|(n, p)| p[2] < lo + 0.1 * (hi - lo) && !deck.in_equations.contains(n))
        .map(|(n, _)| *n)
        .collect();
    assert!(held.len() >= 3, "{name}: too few nodes to hold");
    let mut job = text;
    job.push_str("*NSET, NSET=HELD\n");
    for n in &held {
        job.push_str(&format!("{n}\n"));
    }
    job.push_str(
        "*MATERIAL, NAME=M\n*ELASTIC\n1000., 0.3\n*DENSITY\n2.5\n\
         *SOLID SECTION, ELSET=EALL, MATERIAL=M\n*STEP\n*STATIC\n*BOUNDARY\nHELD, 1, 3, 0.\n\
         *DLOAD\nEALL, GRAV, 4., 0., 0., -1.\n*NODE PRINT, NSET=HELD, TOTALS=ONLY\nRF\n*END STEP\n",
    );
    let dat = run_ccx(&ccx, &dir.join("gravity"), &job);
    let total = dat
        .split("total force")
        .nth(1)
        .and_then(|t| {
            let v: Vec<f64> = t
                .lines()
                .skip(1)
                .flat_map(|l| l.split_whitespace().map(|x| x.parse::<f64>()))
                .collect::<Result<Vec<_>, _>>()
                .ok()?;
            (v.len() == 3).then(|| [v[0], v[1], v[2]])
        })
        .unwrap_or_else(|| panic!("{name}: no total reaction in job.dat:\n{dat}"));
    // The elements are the octree's cubes: a cube's weight goes an eighth
    // to each corner, and CalculiX's reaction leaves out the load a held
    // node carries itself.
    let held_set: HashSet<u64> = held.iter().copied().collect();
    let (mut weight, mut reaching) = (0.0, 0.0);
    for e in &deck.elements {
        let p: Vec<[f64; 3]> = e.iter().map(|n| deck.coords[n]).collect();
        let side = |k: usize| {
            let (a, b) = p
                .iter()
                .fold((f64::MAX, f64::MIN), |(a, b), q| (a.min(q[k]), b.max(q[k])));
            b - a
        };
        let w = 2.5 * 4.0 * side(0) * side(1) * side(2);
        weight += w;
        reaching += w * e.iter().filter(|n| !held_set.contains(n)).count() as f64 / 8.0;
    }
    let volume = stats["kept_volume"].as_f64().unwrap();
    assert!(
        (weight - 10.0 * volume).abs() <= 1e-9 * weight,
        "{name}: the deck's elements weigh {weight}, the kept volume {volume}"
    );
    println!(
        "{name} on {np} rank(s): {} elements, {} held nodes, reaction {total:?}, weight {weight:.7e}, \
         of which {reaching:.7e} away from the held nodes",
        common::int(&stats, "elements"),
        held.len()
    );
    assert!(
        (total[2] - reaching).abs() <= 1e-5 * weight,
        "{name}: vertical reaction {} against the weight away from the held nodes {reaching}",
        total[2]
    );
    for r in &total[..2] {
        assert!(r.abs() <= 1e-5 * weight, "{name}: sideways reaction {r}");
    }
    Some(total)
}

#[test]
fn calculix_gravity_load_bunny_and_armadillo() {
    for (model, level) in [("bunny.stl", "5"), ("armadillo.stl", "7")] {
        let Some(path) = shared_model(model) else {
            return;
        };
        let args = ["--level", level, "--keep", "inside"];
        let name = model.trim_end_matches(".stl");
        let one = gravity_test(name, 1, path.to_str().unwrap(), &args);
        let three = gravity_test(name, 3, path.to_str().unwrap(), &args);
        // The decks are the same bytes; the solver's round-off is not.
        if let (Some(a), Some(b)) = (one, three) {
            assert!(
                (a[2] - b[2]).abs() <= 1e-9 * a[2].abs(),
                "{name}: the reactions differ on 1 and 3 ranks: {a:?} {b:?}"
            );
        }
    }
}

/// A solid that comes out in pieces touching along edges or corners is
/// joined by the clean-up a finite-element file turns on, and when the
/// clean-up is turned off the run says so.
#[test]
fn a_mesh_in_pieces_is_cleaned_or_reported() {
    let Some(bunny) = shared_model("bunny.stl") else {
        return;
    };
    let dir = scratch("fe_files_pieces");
    let bunny = bunny.to_str().unwrap();
    let (_, _, s) = mesh(
        2,
        &dir.join("default"),
        bunny,
        &["--level", "5", "--keep", "inside"],
    );
    let pieces = s["pieces"].as_array().unwrap();
    assert_eq!(pieces.len(), 1, "the clean-up leaves one piece: {pieces:?}");
    assert!(
        common::int(&s, "cleaned") > 0,
        "the clean-up dropped nothing"
    );
    let stats = dir.join("off.json");
    let inp = dir.join("off.inp");
    let args = [
        "mesh",
        bunny,
        "--level",
        "5",
        "--keep",
        "inside",
        "--clean-walls",
        "false",
        "--abaqus",
        inp.to_str().unwrap(),
        "--stats",
        stats.to_str().unwrap(),
    ];
    let out = common::mpirun(
        2,
        &common::octmesh_bin(),
        &args,
        std::time::Duration::from_secs(300),
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}");
    let s = json_file(&stats);
    let pieces = s["pieces"].as_array().unwrap();
    assert!(
        pieces.len() > 1,
        "the bunny at level 5 without the clean-up: {pieces:?}"
    );
    let total: u64 = pieces.iter().map(|p| p.as_u64().unwrap()).sum();
    assert_eq!(total, common::int(&s, "elements"));
    assert!(
        text.contains(&format!("warning: the mesh is {} pieces", pieces.len())),
        "no warning:\n{text}"
    );
}

/// The deck and the msh on `np` ranks equal those on one rank, byte for
/// byte.
fn same_files_on_ranks(name: &str, input: &str, args: &[&str], ranks: &[usize]) {
    let dir = scratch(&format!("fe_files_ranks_{name}"));
    let (inp1, msh1, _) = mesh(1, &dir.join("np1"), input, args);
    let (inp1, msh1) = (std::fs::read(inp1).unwrap(), std::fs::read(msh1).unwrap());
    for &np in ranks {
        let (inp, msh, s) = mesh(np, &dir.join(format!("np{np}")), input, args);
        assert_eq!(common::int(&s, "ranks"), np as u64);
        assert!(
            std::fs::read(inp).unwrap() == inp1,
            "{name}: the .inp differs on {np} ranks"
        );
        assert!(
            std::fs::read(msh).unwrap() == msh1,
            "{name}: the .msh differs on {np} ranks"
        );
    }
}

#[test]
fn files_are_the_same_on_1_to_4_ranks() {
    let sphere = [
        "--level",
        "4",
        "--keep",
        "inside",
        "--domain",
        "-1.28,-1.28,-1.28,2.56",
    ];
    same_files_on_ranks("sphere", "sphere", &sphere, &[2, 3, 4]);
    let fluid = ["--level", "4", "--keep", "outside", "--snap"];
    same_files_on_ranks("sphere_fluid_snapped", "sphere", &fluid, &[3]);
    if let Some(bunny) = shared_model("bunny.stl") {
        let args = ["--level", "5", "--keep", "inside"];
        same_files_on_ranks("bunny", bunny.to_str().unwrap(), &args, &[3]);
    }
}

/// Gmsh reads `msh`: nodes, hexahedra, quadrilaterals, and the physical
/// groups as `dim tag name` lines.
fn gmsh_read(python: &Path, msh: &Path) -> (u64, u64, u64, BTreeSet<(i32, String)>) {
    let script = r#"
import sys, gmsh
gmsh.initialize()
gmsh.option.setNumber("General.Terminal", 0)
gmsh.open(sys.argv[1])
tags, _, _ = gmsh.model.mesh.getNodes()
def count(dim, t):
    types, elems, _ = gmsh.model.mesh.getElements(dim)
    return sum(len(e) for ty, e in zip(types, elems) if ty == t)
print("counts", len(tags), count(3, 5), count(2, 3))
for d, t in gmsh.model.getPhysicalGroups():
    print("group", d, gmsh.model.getPhysicalName(d, t))
gmsh.finalize()
"#;
    let out = Command::new(python)
        .args(["-c", script, msh.to_str().unwrap()])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "gmsh could not read {}:\n{text}\n{}",
        msh.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    let mut counts = [0u64; 3];
    let mut groups = BTreeSet::new();
    for line in text.lines() {
        let f: Vec<&str> = line.split_whitespace().collect();
        match f.first() {
            Some(&"counts") => {
                for k in 0..3 {
                    counts[k] = f[k + 1].parse().unwrap();
                }
            }
            Some(&"group") => {
                groups.insert((f[1].parse().unwrap(), f[2..].join(" ")));
            }
            _ => {}
        }
    }
    (counts[0], counts[1], counts[2], groups)
}

/// Gmsh's reading of the msh of `input` meshed with `args` against
/// octmesh's counts, the deck's surfaces and the `patches` expected.
fn gmsh_check(python: &Path, name: &str, input: &str, args: &[&str], patches: &[&str]) {
    let dir = scratch(&format!("fe_files_gmsh_{name}"));
    let (inp, msh, s) = mesh(1, &dir, input, args);
    let (nodes, hexes, quads, groups) = gmsh_read(python, &msh);
    let hanging = common::int(&s, "face_hanging_nodes") + common::int(&s, "edge_hanging_nodes");
    assert_eq!(
        nodes,
        common::int(&s, "independent_nodes") + hanging,
        "{name}: nodes"
    );
    assert_eq!(hexes, common::int(&s, "elements"), "{name}: hexahedra");
    let deck = read_deck(&std::fs::read_to_string(inp).unwrap());
    assert_eq!(
        quads as usize, deck.surfaces,
        "{name}: a quadrilateral per boundary face"
    );
    assert_eq!(deck.coords.len() as u64, nodes, "{name}: the deck's nodes");
    let mut want: BTreeSet<(i32, String)> = patches.iter().map(|p| (2, p.to_string())).collect();
    want.insert((3, "volume".into()));
    assert_eq!(groups, want, "{name}: physical groups");
    // The hanging nodes' constraints are in the file, one line each.
    let text = std::fs::read_to_string(&msh).unwrap();
    let section = text
        .split("$HangingNodes\n")
        .nth(1)
        .expect("a $HangingNodes section");
    let count: u64 = section.lines().next().unwrap().parse().unwrap();
    assert_eq!(count, hanging, "{name}: $HangingNodes");
    println!(
        "{name}: gmsh read {nodes} nodes, {hexes} hexahedra, {quads} quadrilaterals, {groups:?}"
    );
}

#[test]
fn gmsh_reads_the_msh() {
    let Some(python) = gmsh_python() else {
        return;
    };
    let solid = ["--level", "4", "--keep", "inside"];
    gmsh_check(&python, "sphere", "sphere", &solid, &["sphere"]);
    let fluid = ["--level", "4", "--keep", "outside"];
    let all = ["xmin", "xmax", "ymin", "ymax", "zmin", "zmax", "sphere"];
    gmsh_check(&python, "sphere_fluid", "sphere", &fluid, &all);
    if let Some(bunny) = shared_model("bunny.stl") {
        let args = ["--level", "5", "--keep", "inside"];
        gmsh_check(&python, "bunny", bunny.to_str().unwrap(), &args, &["bunny"]);
    }
}

/// A file that cannot be written fails the run on every rank with the
/// path in the message, and nothing is left half-written.
#[test]
fn an_unwritable_file_fails_every_rank() {
    let dir = scratch("fe_files_unwritable");
    for (option, name) in [
        ("--abaqus", "m.inp"),
        ("--gmsh", "m.msh"),
        ("--exodus", "m.exo"),
        ("--cgns", "m.cgns"),
    ] {
        let path = dir.join("no_such_dir").join(name);
        let p = path.to_str().unwrap();
        let args = [
            "mesh", "sphere", "--level", "3", "--keep", "inside", option, p,
        ];
        let out = common::mpirun(
            2,
            &common::octmesh_bin(),
            &args,
            std::time::Duration::from_secs(300),
        );
        let lines = common::rank_error_lines(&out, 2, option);
        assert!(lines[0].contains(name), "{option}: {}", lines[0]);
        assert!(!path.exists());
    }
}

/// Every leaf at level 2 or finer, two overlapping refinement boxes at
/// levels 4 and 5, every leaf kept, in the cube whose lattice points are
/// short decimals: finer regions the conforming templates cover today.
const CONFORMING: [&str; 13] = [
    "--level",
    "2",
    "--min-level",
    "2",
    "--domain",
    "-1.28,-1.28,-1.28,2.56",
    "--region",
    "box:-0.3,-0.3,-0.3,0.3,0.3,0.3:4",
    "--region",
    "box:0.1,0.1,0.1,0.6,0.5,0.4:5",
    "--conforming",
    "--balance",
    "corner",
];

/// `--conforming` writes meshes without hanging nodes: the checker that
/// reads only the `.msh` finds none and every inner face in two elements,
/// the elements fill the domain, the deck has no `*EQUATION` and passes
/// the patch test in CalculiX as it is, Gmsh reads the counts the deck
/// has, the files are the same on 1 to 3 ranks, and dolfinx solves on the
/// `.msh`: exact on a linear field, second order on a smooth one.
#[test]
fn conforming_meshes_need_no_equations() {
    let dir = scratch("fe_files_conforming");
    let (inp, msh, stats) = mesh(1, &dir.join("np1"), "sphere", &CONFORMING);
    let hanging =
        common::int(&stats, "face_hanging_nodes") + common::int(&stats, "edge_hanging_nodes");
    assert!(
        hanging > 0,
        "the octree needs 2:1 steps for the test to mean anything"
    );
    let c = common::conformity::check(&msh);
    println!(
        "conforming: {} hexahedra from {} leaves, volume {}, min scaled Jacobian {:.3}",
        c.elements,
        common::int(&stats, "elements"),
        c.volume,
        c.min_scaled_jacobian
    );
    assert!(c.conforming(), "not conforming: {c:?}");
    assert!(c.elements as u64 > common::int(&stats, "elements"));
    assert!(((c.volume - 2.56f64.powi(3)) / 2.56f64.powi(3)).abs() < 1e-12);
    assert!(c.min_scaled_jacobian >= 0.3, "{}", c.min_scaled_jacobian);
    let text = std::fs::read_to_string(&inp).unwrap();
    assert!(!text.contains("*EQUATION"));
    let deck = read_deck(&text);
    assert!(deck.hanging.is_empty());
    assert_eq!(deck.elements.len(), c.elements);
    for np in [2, 3] {
        let (i, m, _) = mesh(np, &dir.join(format!("np{np}")), "sphere", &CONFORMING);
        assert!(
            std::fs::read(i).unwrap() == text.as_bytes(),
            "the .inp on {np} ranks"
        );
        assert!(
            std::fs::read(m).unwrap() == std::fs::read(&msh).unwrap(),
            "the .msh on {np} ranks"
        );
    }
    if let Some(python) = gmsh_python() {
        let (nodes, hexes, quads, groups) = gmsh_read(&python, &msh);
        assert_eq!(
            (nodes, hexes),
            (deck.coords.len() as u64, c.elements as u64)
        );
        assert_eq!(quads as usize, deck.surfaces);
        assert!(groups.contains(&(3, "volume".to_string())));
    }
    if let Some(ccx) = ccx() {
        let (error, interior) = patch_test(&ccx, &dir.join("patch"), &text);
        println!("conforming: patch test error {error:.3e} over {interior} interior nodes");
        assert!(interior > 0);
        assert!(
            error <= 1e-8,
            "patch test off by {error:e} without equations"
        );
    }
    // dolfinx, which knows no hanging nodes: exact on the linear field,
    // and the smooth field's L2 error falls at second order when every
    // level rises by one (a uniform level and a box one finer).
    if let Some(error) = common::fe_oracle::assert_patch_test_exact(&msh) {
        println!("conforming: dolfinx patch test error {error:.3e}");
        let mut meshes = Vec::new();
        for level in [3u8, 4, 5] {
            let (a, region) = (
                level.to_string(),
                format!("box:-0.3,-0.3,-0.3,0.3,0.3,0.3:{}", level + 1),
            );
            let args = [
                "--level",
                &a,
                "--min-level",
                &a,
                "--domain",
                CONFORMING[5],
                "--region",
                &region,
                "--conforming",
            ];
            let (_, m, _) = mesh(2, &dir.join(format!("level{level}")), "sphere", &args);
            meshes.push(m);
        }
        let paths: Vec<&Path> = meshes.iter().map(|m| m.as_path()).collect();
        let errors =
            common::fe_oracle::assert_second_order(&paths, [-1.28, -1.28, -1.28, 2.56], 3.5);
        println!("conforming: dolfinx L2 errors {errors:?}");
    }
}

/// Solids of real surfaces, whose staircases have the mark classes the
/// templates leave out: the closure meshes them all. The independent
/// checker finds no hanging node and every inner face in two elements, the
/// volume is the hanging-node mesh's kept volume, the least scaled Jacobian
/// is the templates' floor, the files are the same on 1 to 3 ranks, and
/// CalculiX passes the patch test without a single `*EQUATION`.
#[test]
fn conforming_meshes_of_real_surfaces() {
    let mut cases = vec![("sphere".to_string(), "5")];
    if let Some(bunny) = shared_model("bunny.stl") {
        cases.push((bunny.to_str().unwrap().to_string(), "5"));
    }
    for (input, level) in &cases {
        let name = Path::new(input).file_stem().unwrap().to_str().unwrap();
        let dir = scratch(&format!("fe_files_conforming_{name}"));
        let args = ["--level", level, "--keep", "inside", "--conforming"];
        let (inp, msh, stats) = mesh(1, &dir.join("np1"), input, &args);
        let c = common::conformity::check(&msh);
        let kept = stats["kept_volume"].as_f64().unwrap();
        println!(
            "conforming {name}: {} hexahedra from {} elements, volume {} (kept {kept}), min \
             scaled Jacobian {:.3}",
            c.elements,
            common::int(&stats, "elements"),
            c.volume,
            c.min_scaled_jacobian
        );
        assert!(c.conforming(), "{name}: not conforming: {c:?}");
        assert!(((c.volume - kept) / kept).abs() < 1e-12, "{name}: volume");
        assert!(c.min_scaled_jacobian >= 0.3, "{}", c.min_scaled_jacobian);
        let text = std::fs::read_to_string(&inp).unwrap();
        assert!(!text.contains("*EQUATION"));
        for np in [2, 3] {
            let (i, m, _) = mesh(np, &dir.join(format!("np{np}")), input, &args);
            assert!(
                std::fs::read(i).unwrap() == text.as_bytes(),
                "{name}: .inp, {np} ranks"
            );
            assert!(
                std::fs::read(m).unwrap() == std::fs::read(&msh).unwrap(),
                "{name}: .msh, {np} ranks"
            );
        }
        if let Some(ccx) = ccx() {
            let (error, interior) = patch_test(&ccx, &dir.join("patch"), &text);
            println!(
                "conforming {name}: patch test error {error:.3e} over {interior} interior nodes"
            );
            assert!(interior > 0);
            assert!(error <= 1e-8, "{name}: patch test off by {error:e}");
        }
    }
}

/// The triangles of a binary STL file.
fn stl_triangles(path: &Path) -> Vec<[[f64; 3]; 3]> {
    let bytes = std::fs::read(path).unwrap();
    let n = u32::from_le_bytes(bytes[80..84].try_into().unwrap()) as usize;
    assert_eq!(bytes.len(), 84 + 50 * n, "{}: a binary STL", path.display());
    let f = |at: usize| f64::from(f32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()));
    (0..n)
        .map(|t| {
            let at = 84 + 50 * t + 12;
            std::array::from_fn(|v| std::array::from_fn(|a| f(at + 12 * v + 4 * a)))
        })
        .collect()
}

/// The distance from `p` to triangle `t` (the closest point by the regions
/// of the triangle's plane: vertices, edges, inside).
fn triangle_distance(p: [f64; 3], t: &[[f64; 3]; 3]) -> f64 {
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let seg = |a: [f64; 3], b: [f64; 3]| {
        let (ab, ap) = (sub(b, a), sub(p, a));
        let s = (dot(ap, ab) / dot(ab, ab).max(f64::MIN_POSITIVE)).clamp(0.0, 1.0);
        let q = [a[0] + s * ab[0], a[1] + s * ab[1], a[2] + s * ab[2]];
        dot(sub(p, q), sub(p, q)).sqrt()
    };
    let [a, b, c] = *t;
    let (ab, ac) = (sub(b, a), sub(c, a));
    let n = [
        ab[1] * ac[2] - ab[2] * ac[1],
        ab[2] * ac[0] - ab[0] * ac[2],
        ab[0] * ac[1] - ab[1] * ac[0],
    ];
    let nn = dot(n, n);
    let edges = seg(a, b).min(seg(b, c)).min(seg(c, a));
    if nn == 0.0 {
        return edges;
    }
    // Inside the prism over the triangle: the distance to the plane.
    let side = |u: [f64; 3], v: [f64; 3]| {
        let (e, w) = (sub(v, u), sub(p, u));
        let x = [
            e[1] * w[2] - e[2] * w[1],
            e[2] * w[0] - e[0] * w[2],
            e[0] * w[1] - e[1] * w[0],
        ];
        dot(x, n) >= 0.0
    };
    if side(a, b) && side(b, c) && side(c, a) {
        dot(sub(p, a), n).abs() / nn.sqrt()
    } else {
        edges
    }
}

/// The triangles of a surface binned by their boxes grown by `tol` in a
/// grid: a point within `tol` of a triangle finds it in its own cell.
struct Near {
    tris: Vec<[[f64; 3]; 3]>,
    cell: f64,
    bins: std::collections::HashMap<[i64; 3], Vec<u32>>,
    tol: f64,
}

impl Near {
    fn new(tris: Vec<[[f64; 3]; 3]>, tol: f64) -> Near {
        let (mut lo, mut hi) = ([f64::MAX; 3], [f64::MIN; 3]);
        for p in tris.iter().flatten() {
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        let cell = (0..3).map(|a| hi[a] - lo[a]).fold(0.0, f64::max) / 64.0;
        let mut bins: std::collections::HashMap<[i64; 3], Vec<u32>> = Default::default();
        for (i, t) in tris.iter().enumerate() {
            let b = |a: usize, f: fn(f64, f64) -> f64, d: f64| {
                ((t.iter().map(|p| p[a]).fold(t[0][a], f) + d) / cell).floor() as i64
            };
            let (l, h) = (
                [0, 1, 2].map(|a| b(a, f64::min, -tol)),
                [0, 1, 2].map(|a| b(a, f64::max, tol)),
            );
            for x in l[0]..=h[0] {
                for y in l[1]..=h[1] {
                    for z in l[2]..=h[2] {
                        bins.entry([x, y, z]).or_default().push(i as u32);
                    }
                }
            }
        }
        Near {
            tris,
            cell,
            bins,
            tol,
        }
    }

    /// Whether `p` is within the tolerance of the surface.
    fn on(&self, p: [f64; 3]) -> bool {
        let key = p.map(|x| (x / self.cell).floor() as i64);
        self.bins.get(&key).is_some_and(|v| {
            v.iter()
                .any(|&i| triangle_distance(p, &self.tris[i as usize]) <= self.tol)
        })
    }
}

/// `--conforming --snap`: the conforming solid of the sphere and the bunny
/// at level 5 snapped. Read back from the `.msh` alone: conforming, every
/// hexahedron's eight corner Jacobians positive, and most of the wall's
/// nodes (every node of a boundary quadrilateral: a solid inside the
/// domain has no face on its sides) within 1e-9 of the model's size of
/// the surface's triangles (at least the snapped ones the run reports; the
/// rest sit at the staircase's convex corners, where the snap steps back).
/// The least fractions: all of the sphere's wall, and 85 % of the bunny's
/// (89.3 % measured: 1,308 of 1,464, 149 of the 156 others at cells with
/// two or three wall faces). The files are the same on 1 and 2 ranks, and
/// CalculiX's patch test passes on the snapped deck.
#[test]
fn conforming_meshes_snapped_to_the_surface() {
    let sphere = octmesh::internals::geometry::shapes::default_sphere();
    let sphere = sphere.triangles().iter().map(|t| t.v).collect();
    let mut cases = vec![("sphere".to_string(), sphere, 0.999)];
    if let Some(bunny) = shared_model("bunny.stl") {
        let tris = stl_triangles(&bunny);
        cases.push((bunny.to_str().unwrap().to_string(), tris, 0.85));
    }
    for (input, tris, least) in cases {
        let name = Path::new(&input).file_stem().unwrap().to_str().unwrap();
        let dir = scratch(&format!("fe_files_conforming_snapped_{name}"));
        let args = ["--level", "5", "--keep", "inside", "--conforming", "--snap"];
        let (inp, msh, stats) = mesh(1, &dir.join("np1"), &input, &args);
        let c = common::conformity::check(&msh);
        assert!(c.conforming(), "{name}: not conforming: {c:?}");
        assert!(c.min_scaled_jacobian > 0.0, "{name}: {c:?}");
        let m = common::conformity::read_msh(&msh);
        let wall: BTreeSet<u64> = m.quads.iter().flatten().copied().collect();
        // The model's size: the longest side of its box.
        let size = (0..3)
            .map(|a| {
                let c = tris.iter().flatten().map(|p| p[a]);
                c.clone().fold(f64::MIN, f64::max) - c.fold(f64::MAX, f64::min)
            })
            .fold(0.0, f64::max);
        let near = Near::new(tris, 1e-9 * size);
        let on = wall.iter().filter(|t| near.on(m.points[t])).count();
        let snap = &stats["snap"];
        println!(
            "conforming {name} snapped: {on} of {} wall nodes on the surface, report {snap}, least \
             scaled Jacobian {:.4}",
            wall.len(),
            c.min_scaled_jacobian
        );
        assert_eq!(
            common::int(snap, "surface_nodes"),
            wall.len() as u64,
            "{name}"
        );
        assert!(on as u64 >= common::int(snap, "snapped"), "{name}: {on}");
        assert!(
            on as f64 >= least * wall.len() as f64,
            "{name}: {on} of {}",
            wall.len()
        );
        assert!(
            (c.min_scaled_jacobian - common::num(snap, "min_scaled_jacobian")).abs() < 1e-9,
            "{name}"
        );
        let text = std::fs::read_to_string(&inp).unwrap();
        let (i, m2, _) = mesh(2, &dir.join("np2"), &input, &args);
        assert!(
            std::fs::read(i).unwrap() == text.as_bytes(),
            "{name}: .inp, 2 ranks"
        );
        assert!(
            std::fs::read(m2).unwrap() == std::fs::read(&msh).unwrap(),
            "{name}: .msh, 2 ranks"
        );
        if let Some(ccx) = ccx() {
            let (error, interior) = patch_test(&ccx, &dir.join("patch"), &text);
            println!("conforming {name} snapped: patch test error {error:.3e} over {interior} interior nodes");
            assert!(interior > 0);
            assert!(error <= 1e-8, "{name}: patch test off by {error:e}");
        }
    }
}

/// What `--conforming` cannot do (the wall layer) is an error on every rank.
#[test]
fn conforming_refuses_what_it_cannot_do() {
    let dir = scratch("fe_files_conforming_refused");
    let case = dir.join("case");
    let args = [
        "mesh",
        "sphere",
        "--level",
        "2",
        "--keep",
        "inside",
        "--conforming",
        "--cut-rule",
        "none",
        "--wall-layer",
        "--openfoam",
        case.to_str().unwrap(),
    ];
    let out = common::mpirun(
        2,
        &common::octmesh_bin(),
        &args,
        std::time::Duration::from_secs(300),
    );
    let lines = common::rank_error_lines(&out, 2, "--conforming --wall-layer");
    assert!(
        lines.iter().all(|l| l.contains("--wall-layer")),
        "{lines:?}"
    );
}

/// `--conforming --quality --out`: the quality measures the conforming
/// mesh (its hexahedra; Gmsh's smallest scaled Jacobian of the `.msh` and
/// the independent checker's equal octmesh's to 1e-9, and the templates
/// make it less than 1), the worst elements' VTU holds its smallest
/// value, and the VTU holds the `.msh`'s hexahedra on its points (meshio
/// reads both), all in rank 0's piece; the figures and files are the
/// same on 1 and 2 ranks.
#[test]
fn conforming_quality_and_vtu_are_the_conforming_mesh() {
    let dir = scratch("fe_files_conforming_quality");
    let mut runs = Vec::new();
    for np in [1, 2] {
        let d = dir.join(format!("np{np}"));
        std::fs::create_dir_all(&d).unwrap();
        let path = |f: &str| d.join(f).to_str().unwrap().to_string();
        let (msh, pvtu, worst, stats) = (
            path("m.msh"),
            path("m.pvtu"),
            path("worst.vtu"),
            path("s.json"),
        );
        let mut args = vec!["mesh", "sphere"];
        args.extend(CONFORMING);
        args.extend([
            "--gmsh",
            &msh,
            "--out",
            &pvtu,
            "--quality",
            "--quality-out",
            &worst,
            "--stats",
            &stats,
            "--quiet",
        ]);
        octmesh_ok(np, &args);
        runs.push((d.clone(), json_file(Path::new(&stats))));
    }
    let (d1, s1) = &runs[0];
    let (d2, s2) = &runs[1];
    assert_eq!(s1["quality"], s2["quality"], "quality on 1 and 2 ranks");
    let read = |d: &Path, f: &str| std::fs::read(d.join(f)).unwrap();
    for f in ["m.msh", "m_0000.vtu", "worst.vtu"] {
        assert!(read(d1, f) == read(d2, f), "{f} differs on 2 ranks");
    }
    let q = &s1["quality"];
    let ours = q["scaled_jacobian_min"].as_f64().unwrap();
    let msh = d1.join("m.msh");
    let c = common::conformity::check(&msh);
    assert!(c.conforming(), "{c:?}");
    assert_eq!(common::int(q, "elements"), c.elements as u64);
    assert!(
        common::int(q, "elements") > common::int(s1, "elements"),
        "the conforming mesh has more hexahedra than the octree leaves"
    );
    assert!(ours < 0.99, "the templates should make non-cubes: {ours}");
    assert!((c.min_scaled_jacobian - ours).abs() <= 1e-9);
    // The worst elements' file, read by meshio: its smallest element value.
    let python = common::python_with_meshio();
    let script = r#"
import sys, meshio, numpy as np
w = meshio.read(sys.argv[1])
print("worst %d %.17g" % (len(w.points) // 8, w.point_data["scaled_jacobian"].min()))
v = meshio.read(sys.argv[2]); m = meshio.read(sys.argv[3])
def hexes(x):
    return np.concatenate([c.data for c in x.cells if c.type == "hexahedron"])
hv, hm = hexes(v), hexes(m)
same = hv.shape == hm.shape and bool((hv == hm).all())
dp = float(np.abs(v.points - m.points).max()) if v.points.shape == m.points.shape else -1.0
print("vtu %d %d msh %d %d same %d %.17g" % (len(hv), len(v.points), len(hm), len(m.points), same, dp))
"#;
    let out = Command::new(&python)
        .args([
            "-c",
            script,
            d1.join("worst.vtu").to_str().unwrap(),
            d2.join("m_0000.vtu").to_str().unwrap(),
            msh.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "meshio failed:\n{text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let words = |tag: &str| -> Vec<f64> {
        let line = text.lines().find(|l| l.starts_with(tag)).unwrap();
        line.split_whitespace()
            .skip(1)
            .filter_map(|w| w.parse().ok())
            .collect()
    };
    let w = words("worst ");
    // serde_json's float parsing may be one unit in the last place off.
    assert!(
        (w[1] - ours).abs() <= 1e-12,
        "worst element {}, {ours}",
        w[1]
    );
    let v = words("vtu ");
    println!("conforming: {text}");
    assert_eq!(v[0], c.elements as f64, "VTU hexahedra");
    assert_eq!(v[0], v[2], "VTU and .msh hexahedra");
    assert_eq!(v[1], v[3], "VTU and .msh points");
    assert_eq!(v[4], 1.0, "the VTU's hexahedra are the .msh's");
    assert_eq!(v[5], 0.0, "the VTU's points are the .msh's");
    // Every piece as check_vtu.py reads it: rank 1's is empty.
    let check = Command::new(&python)
        .arg(common::repo().join("tools/check_vtu.py"))
        .arg(d2.join("m.pvtu"))
        .output()
        .unwrap();
    assert!(
        check.status.success(),
        "{}",
        String::from_utf8_lossy(&check.stderr)
    );
    let j: serde_json::Value = serde_json::from_slice(&check.stdout).unwrap();
    assert_eq!(common::int(&j, "pieces"), 2);
    assert_eq!(common::int(&j, "cells"), c.elements as u64);
    assert_eq!(common::int(&j, "hanging_points"), 0);
    let Some(gmsh) = require(Oracle::Python {
        module: "gmsh",
        package: "python3-gmsh",
    }) else {
        return;
    };
    let (n, gmsh_min) = common::fe_oracle::gmsh_min_scaled_jacobian(&gmsh, &msh);
    println!("conforming: {n} hexahedra, smallest scaled Jacobian gmsh {gmsh_min}, octmesh {ours}");
    assert_eq!(n, c.elements as u64);
    assert!(
        (gmsh_min - ours).abs() <= 1e-9,
        "gmsh {gmsh_min}, octmesh {ours}"
    );
}

/// `--conforming --openfoam`: one serial case of hexahedra only, which
/// checkMesh accepts (`Mesh OK.`, no polyhedra), the same files on 1 and
/// 3 ranks; `--quality`'s face figures of the conforming mesh are what
/// checkMesh prints for the case.
#[test]
fn conforming_openfoam_case_is_all_hexahedra() {
    let dir = scratch("fe_files_conforming_foam");
    let mut cases = Vec::new();
    let stats = dir.join("s.json");
    for np in [1, 3] {
        let case = dir.join(format!("np{np}"));
        let _ = std::fs::remove_dir_all(&case);
        let mut args = vec!["mesh", "sphere"];
        args.extend(CONFORMING);
        args.extend(["--openfoam", case.to_str().unwrap(), "--quiet"]);
        if np == 1 {
            args.extend(["--quality", "--stats", stats.to_str().unwrap()]);
        }
        octmesh_ok(np, &args);
        cases.push(case);
    }
    let poly = |c: &Path, f: &str| std::fs::read(c.join("constant/polyMesh").join(f)).unwrap();
    for f in ["points", "faces", "owner", "neighbour", "boundary"] {
        assert!(
            poly(&cases[0], f) == poly(&cases[1], f),
            "{f} differs on 3 ranks"
        );
    }
    assert!(!cases[1].join("processor0").exists());
    let Some(rc) = common::openfoam() else {
        return;
    };
    let text = common::foam(&rc, &cases[0], "checkMesh -allGeometry -allTopology");
    let count = |what: &str| -> u64 {
        let line = text
            .lines()
            .find(|l| l.trim_start().starts_with(what))
            .unwrap_or_else(|| panic!("no {what} in:\n{text}"));
        line.split_whitespace().last().unwrap().parse().unwrap()
    };
    assert!(text.contains("Mesh OK."), "{text}");
    assert_eq!(count("polyhedra:"), 0);
    assert_eq!(count("hexahedra:"), count("cells:"));
    println!("conforming: checkMesh OK on {} hexahedra", count("cells:"));
    let q = json_file(&stats)["quality"].clone();
    assert_eq!(common::int(&q, "elements"), count("cells:"));
    // checkMesh prints 8 significant digits.
    for (label, key) in [
        ("Mesh non-orthogonality Max:", "non_orthogonality_max"),
        ("average:", "non_orthogonality_average"),
        ("Max skewness =", "skewness_max"),
        ("minimum:", "determinant_min"),
    ] {
        let printed = common::number_after(&text, label);
        let ours = q[key].as_f64().unwrap();
        assert!(
            (ours - printed).abs() <= 1e-7 * printed.abs().max(1e-3),
            "{key}: octmesh {ours}, checkMesh {printed}"
        );
    }
    assert!(q["non_orthogonality_max"].as_f64().unwrap() > 1.0);
}
