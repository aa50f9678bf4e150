//! OpenFOAM cases written by `octmesh mesh --openfoam`, judged by OpenFOAM
//! itself (Debian's `openfoam` package, v1912, installed by
//! `scripts/setup.sh`) and by an independent reading of the written files.
//!
//! - `checkMesh -allTopology -allGeometry` on the sphere, bunny, tangaroa
//!   (outside), armadillo (inside) and torus (all), on 1 rank and on 3
//!   (`-parallel`, processor directories): one region, no multiply
//!   connected patch, cells and volume equal to octmesh's, and no failed
//!   check but "concave cells (using face planes)", which flags every cell
//!   with two coplanar faces and so every split 2:1 face: snappyHexMesh's
//!   own castellated meshes fail it the same way (see the closing note of
//!   the issue). Plain `checkMesh -allTopology` must say `Mesh OK.`.
//! - `potentialFoam` around the sphere: the mean speed in a shell over the
//!   equator within 3 % of the same run on snappyHexMesh's castellated mesh
//!   (`../shared/openfoam/sphere_castellated`: 1.693).
//! - `potentialFoam` around the sphere in a box, as the staircase and
//!   snapped: the peak speed at the equator within 2 % of the exact 1.5 U
//!   on the snapped mesh and not on the staircase (velocities reconstructed
//!   from the written fluxes; see the test for why).
//! - A laminar `simpleFoam` run around the bunny (level 7, the settings of
//!   `../shared/openfoam/bunny_simplefoam`) on 1 and 2 ranks: the force on
//!   the body within 2 % of the same run on snappyHexMesh's castellated
//!   mesh (0.729, 0.067, 0.086), and the same on both rank counts.
//! - An ASCII STL with two solids gives two surface patches, each face on
//!   its solid's side, the same on 3 ranks, accepted by checkMesh.
//! - The ASCII files read back here: every cell closes, each side patch
//!   covers its side.
//! - Bad input: an existing mesh without `--overwrite`, bad patch names, an
//!   empty kept region, an unwritable directory, a write failing on one
//!   rank only.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use common::{foam, octmesh_bin, openfoam, scratch, shared_model};

/// The reference case `openfoam/<name>` of the shared folder
/// ([`common::require`]).
fn reference_case(name: &str) -> Option<PathBuf> {
    common::require(common::Oracle::Shared(&format!("openfoam/{name}")))
}

/// Runs octmesh on `np` ranks; returns its statistics.
fn octmesh(np: usize, args: &[&str], stats: &Path) -> serde_json::Value {
    let mut all: Vec<&str> = args.to_vec();
    let s = stats.to_str().unwrap();
    all.extend(["--stats", s, "--quiet"]);
    let out = common::mpirun(np, &octmesh_bin(), &all, Duration::from_secs(600));
    assert!(
        out.status.success(),
        "octmesh {args:?} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_str(&std::fs::read_to_string(stats).unwrap()).unwrap()
}

/// checkMesh's verdict on `case`, asserted as the module says.
fn judge(rc: &Path, case: &Path, np: usize, stats: &serde_json::Value, tag: &str) {
    let par = if np > 1 {
        format!("mpirun --oversubscribe -np {np} checkMesh -parallel")
    } else {
        "checkMesh".to_string()
    };
    let all = foam(rc, case, &format!("{par} -allTopology -allGeometry"));
    assert!(
        all.contains("Number of regions: 1 (OK)"),
        "{tag}: regions:\n{all}"
    );
    assert!(
        !all.contains("multiply connected ("),
        "{tag}: a patch is not manifold:\n{all}"
    );
    for line in all.lines().filter(|l| l.contains("***")) {
        assert!(
            line.contains("Concave cells (using face planes)"),
            "{tag}: checkMesh failed a check: {line}\n{all}"
        );
    }
    let cells = common::number_after(&all, "cells:");
    assert_eq!(
        cells as u64,
        stats["elements"].as_u64().unwrap(),
        "{tag}: cells"
    );
    let volume = common::number_after(&all, "Total volume =");
    let kept = stats["kept_volume"].as_f64().unwrap();
    assert!(
        ((volume - kept) / kept).abs() < 1e-6,
        "{tag}: OpenFOAM's volume {volume} is not octmesh's {kept}"
    );
    let plain = foam(rc, case, &format!("{par} -allTopology"));
    assert!(
        plain.contains("\nMesh OK."),
        "{tag}: checkMesh -allTopology:\n{plain}"
    );
    println!(
        "{tag}: checkMesh: {cells} cells, volume {volume:.6e} = octmesh's, one region, manifold patches, Mesh OK"
    );
}

#[test]
fn checkmesh_accepts_the_cases_octmesh_writes() {
    let Some(rc) = openfoam() else { return };
    let dir = scratch("openfoam_checkmesh");
    let mut cases: Vec<(String, &str, &str, usize)> = vec![
        ("sphere".into(), "outside", "5", 1),
        ("sphere".into(), "outside", "5", 3),
        ("torus".into(), "all", "5", 1),
        ("torus".into(), "all", "5", 3),
        ("torus".into(), "inside", "6", 3),
    ];
    for (model, keep, level) in [
        ("bunny.stl", "outside", "7"),
        ("tangaroa.stl", "outside", "7"),
        ("armadillo.stl", "inside", "7"),
    ] {
        if let Some(p) = shared_model(model) {
            for np in [1, 3] {
                cases.push((p.to_string_lossy().into_owned(), keep, level, np));
            }
        }
    }
    for (k, (surface, keep, level, np)) in cases.iter().enumerate() {
        let case = dir.join(format!("case{k}"));
        let stats = dir.join(format!("case{k}.json"));
        let tag = format!(
            "{} level {level} keep {keep} np {np}",
            Path::new(surface).file_name().unwrap().to_string_lossy()
        );
        let s = octmesh(
            *np,
            &[
                "mesh",
                surface,
                "--level",
                level,
                "--keep",
                keep,
                "--openfoam",
                case.to_str().unwrap(),
            ],
            &stats,
        );
        judge(&rc, &case, *np, &s, &tag);
    }
}

#[test]
fn potential_flow_around_the_sphere_matches_snappyhexmesh() {
    let Some(rc) = openfoam() else { return };
    let Some(reference) = reference_case("sphere_castellated") else {
        return;
    };
    let case = scratch("openfoam_potential");
    // The reference's fields and settings; octmesh adds the mesh only.
    std::fs::create_dir_all(case.join("system")).unwrap();
    for f in ["controlDict", "fvSchemes", "fvSolution"] {
        std::fs::copy(
            reference.join("system").join(f),
            case.join("system").join(f),
        )
        .unwrap();
    }
    std::fs::create_dir_all(case.join("0")).unwrap();
    for f in ["U", "p"] {
        std::fs::copy(reference.join("0").join(f), case.join("0").join(f)).unwrap();
    }
    let stats = case.join("stats.json");
    let c = case.to_str().unwrap();
    octmesh(
        1,
        &[
            "mesh",
            "sphere",
            "--level",
            "6",
            "--keep",
            "outside",
            "--openfoam",
            c,
        ],
        &stats,
    );
    foam(&rc, &case, "potentialFoam -writep");
    foam(&rc, &case, "postProcess -func writeCellCentres -time 0");
    let u = read_vectors(&case.join("0/U"));
    let centres = read_vectors(&case.join("0/C"));
    assert_eq!(u.len(), centres.len());
    let shell: Vec<f64> = (0..u.len())
        .filter(|&i| {
            let c = centres[i];
            let r = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
            c[0].abs() < 0.15 && r > 1.1 && r < 1.4
        })
        .map(|i| (u[i][0] * u[i][0] + u[i][1] * u[i][1] + u[i][2] * u[i][2]).sqrt())
        .collect();
    assert!(shell.len() > 100, "too few shell cells: {}", shell.len());
    let mean = shell.iter().sum::<f64>() / shell.len() as f64;
    let snappy = 1.693;
    println!(
        "potentialFoam around the sphere, level 6: shell mean speed {mean:.4} over {} cells \
         (snappyHexMesh castellated: {snappy})",
        shell.len()
    );
    assert!(
        ((mean - snappy) / snappy).abs() < 0.03,
        "shell mean speed {mean} is not within 3 % of snappyHexMesh's {snappy}"
    );
}

/// The reference case's field file `name` (`U` or `p`) for an octmesh case:
/// the reference's one `sides` patch is octmesh's four side patches, and
/// on several ranks the processor patches are declared.
fn field_for_octmesh(reference: &Path, name: &str, parallel: bool) -> String {
    let text = std::fs::read_to_string(reference.join("0").join(name)).unwrap();
    let mut out = String::new();
    for line in text.lines() {
        if let Some(rest) = line.strip_prefix("    sides ") {
            out.push_str(&format!("    \"(ymin|ymax|zmin|zmax)\" {rest}\n"));
            if parallel {
                out.push_str("    \"procBoundary.*\" { type processor; }\n");
            }
        } else {
            out.push_str(line);
            out.push('\n');
        }
    }
    assert!(
        out.contains("ymin|ymax"),
        "no sides patch in the reference's 0/{name}"
    );
    out
}

/// The total force `Sum of forces / Total : (x y z)` a forces function
/// object printed.
fn total_force(log: &str) -> [f64; 3] {
    let at = log.find("Sum of forces").expect("a force in the log");
    let line = log[at..]
        .lines()
        .find(|l| l.trim_start().starts_with("Total"))
        .expect("a total force");
    parse_vector(line[line.find('(').unwrap()..].trim())
}

#[test]
fn simplefoam_force_on_the_bunny_matches_snappyhexmesh() {
    let Some(rc) = openfoam() else { return };
    let Some(reference) = reference_case("bunny_simplefoam") else {
        return;
    };
    let Some(bunny) = shared_model("bunny.stl") else {
        return;
    };
    // snappyHexMesh's castellated mesh at the same level, same run.
    let snappy = [0.729, 0.067, 0.086];
    let norm = |v: [f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    let mut forces = Vec::new();
    for np in [1usize, 2] {
        let case = scratch(&format!("openfoam_simplefoam_np{np}"));
        let c = case.to_str().unwrap();
        let stats = case.with_extension("json");
        octmesh(
            np,
            &[
                "mesh",
                bunny.to_str().unwrap(),
                "--level",
                "7",
                "--keep",
                "outside",
                "--openfoam",
                c,
                "--patch",
                "xmin=inlet",
                "--patch",
                "xmax=outlet",
            ],
            &stats,
        );
        // The reference's settings and fields; octmesh gives the mesh.
        let mut constants = vec![case.join("constant")];
        let mut times = vec![case.join("0")];
        if np > 1 {
            constants = (0..np)
                .map(|r| case.join(format!("processor{r}/constant")))
                .chain(constants)
                .collect();
            times = (0..np)
                .map(|r| case.join(format!("processor{r}/0")))
                .collect();
        }
        for dir in &constants {
            std::fs::create_dir_all(dir).unwrap();
            for f in ["transportProperties", "turbulenceProperties"] {
                std::fs::copy(reference.join("constant").join(f), dir.join(f)).unwrap();
            }
        }
        for f in ["controlDict", "fvSchemes", "fvSolution"] {
            std::fs::copy(
                reference.join("system").join(f),
                case.join("system").join(f),
            )
            .unwrap();
        }
        for dir in &times {
            std::fs::create_dir_all(dir).unwrap();
            for f in ["U", "p"] {
                std::fs::write(dir.join(f), field_for_octmesh(&reference, f, np > 1)).unwrap();
            }
        }
        let run = |solver: &str| {
            if np > 1 {
                format!("mpirun --oversubscribe -np {np} {solver} -parallel")
            } else {
                solver.to_string()
            }
        };
        foam(&rc, &case, &run("potentialFoam"));
        let log = foam(&rc, &case, &run("simpleFoam"));
        assert!(log.contains("\nEnd"), "simpleFoam did not finish:\n{log}");
        let log = foam(
            &rc,
            &case,
            &format!(
                "{} -postProcess -latestTime -func \"forcesIncompressible(patches=(bunny),rhoInf=1)\"",
                run("simpleFoam")
            ),
        );
        let f = total_force(&log);
        let diff = [f[0] - snappy[0], f[1] - snappy[1], f[2] - snappy[2]];
        let rel = norm(diff) / norm(snappy);
        println!(
            "simpleFoam around the bunny, level 7, {np} rank(s): force ({:.4}, {:.4}, {:.4}), \
             {:.2} % from snappyHexMesh's ({}, {}, {})",
            f[0],
            f[1],
            f[2],
            100.0 * rel,
            snappy[0],
            snappy[1],
            snappy[2]
        );
        assert!(
            rel < 0.02,
            "force {f:?} is {:.2} % from snappyHexMesh's {snappy:?} (at most 2 %)",
            100.0 * rel
        );
        forces.push(f);
    }
    let d = [0, 1, 2].map(|k| forces[1][k] - forces[0][k]);
    assert!(
        norm(d) < 0.01 * norm(forces[0]),
        "the force on 2 ranks {:?} differs from 1 rank's {:?}",
        forces[1],
        forces[0]
    );
}

/// The internal field of an ASCII `volVectorField`.
fn read_vectors(path: &Path) -> Vec<[f64; 3]> {
    let text = std::fs::read_to_string(path).unwrap();
    let at = text.find("internalField").expect("internalField");
    let rest = &text[at..];
    let open = rest.find("\n(").expect("a list");
    let n: usize = rest[..open]
        .split_whitespace()
        .last()
        .and_then(|w| w.parse().ok())
        .expect("list size");
    rest[open + 2..]
        .lines()
        .filter(|l| l.starts_with('('))
        .take(n)
        .map(parse_vector)
        .collect()
}

/// An ASCII vector, `(x y z)`.
fn parse_vector(line: &str) -> [f64; 3] {
    let v: Vec<f64> = line
        .trim_matches(|c| c == '(' || c == ')')
        .split_whitespace()
        .map(|w| w.parse().unwrap())
        .collect();
    [v[0], v[1], v[2]]
}

/// The points and the faces (point labels) of an ASCII polyMesh.
fn read_points_and_faces(mesh: &Path) -> (Vec<[f64; 3]>, Vec<Vec<usize>>) {
    let points = list_lines(&mesh.join("points"))
        .iter()
        .map(|l| parse_vector(l))
        .collect();
    let faces = list_lines(&mesh.join("faces"))
        .iter()
        .map(|l| {
            l[l.find('(').unwrap() + 1..l.len() - 1]
                .split_whitespace()
                .map(|w| w.parse().unwrap())
                .collect()
        })
        .collect();
    (points, faces)
}

/// The body of an ASCII list file: the lines between the outer parentheses.
fn list_lines(path: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(path).unwrap();
    let body = &text[text.find("}").unwrap()..];
    let open = body.find("\n(").unwrap();
    let close = body.rfind(')').unwrap();
    body[open + 2..close]
        .lines()
        .map(|l| l.trim().to_string())
        .filter(|l| !l.is_empty())
        .collect()
}

#[test]
fn ascii_files_read_back_close_every_cell() {
    let dir = scratch("openfoam_ascii");
    let case = dir.join("torus");
    let stats = dir.join("stats.json");
    let s = octmesh(
        1,
        &[
            "mesh",
            "torus",
            "--level",
            "5",
            "--openfoam",
            case.to_str().unwrap(),
            "--openfoam-format",
            "ascii",
        ],
        &stats,
    );
    let mesh = case.join("constant/polyMesh");
    let (points, faces) = read_points_and_faces(&mesh);
    let (owner, neighbour) = owner_and_neighbour(&mesh);
    assert_eq!(owner.len(), faces.len());
    let cells = owner.iter().chain(&neighbour).max().unwrap() + 1;
    assert_eq!(cells as u64, s["elements"].as_u64().unwrap());
    // Newell area vectors.
    let area = |f: &[usize]| {
        let mut a = [0.0f64; 3];
        for k in 0..f.len() {
            let (p, q) = (points[f[k]], points[f[(k + 1) % f.len()]]);
            a[0] += (p[1] - q[1]) * (p[2] + q[2]);
            a[1] += (p[2] - q[2]) * (p[0] + q[0]);
            a[2] += (p[0] - q[0]) * (p[1] + q[1]);
        }
        a.map(|x| x / 2.0)
    };
    let mut sum = vec![[0.0f64; 3]; cells];
    let mut total = vec![0.0f64; cells];
    for (i, f) in faces.iter().enumerate() {
        let a = area(f);
        let m = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
        for k in 0..3 {
            sum[owner[i]][k] += a[k];
        }
        total[owner[i]] += m;
        if i < neighbour.len() {
            assert!(
                owner[i] < neighbour[i],
                "face {i}: owner must be the lower cell"
            );
            for k in 0..3 {
                sum[neighbour[i]][k] -= a[k];
            }
            total[neighbour[i]] += m;
        }
    }
    for c in 0..cells {
        let m = sum[c].iter().map(|x| x.abs()).fold(0.0, f64::max);
        assert!(m < 1e-9 * total[c], "cell {c} does not close: {:?}", sum[c]);
    }
    // Each side patch covers its side of the cube (everything is kept).
    let boundary = std::fs::read_to_string(mesh.join("boundary")).unwrap();
    let side = s["domain_side"].as_f64().unwrap();
    for name in ["xmin", "xmax", "ymin", "ymax", "zmin", "zmax"] {
        let at = boundary.find(&format!("    {name}\n")).unwrap();
        let n = common::number_after(&boundary[at..], "nFaces") as usize;
        let start = common::number_after(&boundary[at..], "startFace") as usize;
        let a: f64 = faces[start..start + n]
            .iter()
            .map(|f| {
                let v = area(f);
                (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
            })
            .sum();
        assert!(
            ((a - side * side) / (side * side)).abs() < 1e-12,
            "{name}: area {a}"
        );
    }
    println!(
        "torus level 5: {} points, {} faces, {cells} cells read back: every cell closes, each side patch covers its side",
        points.len(),
        faces.len()
    );
}

/// `(nFaces, startFace)` of each patch of a `boundary` file.
fn patches_of(boundary: &Path) -> Vec<(String, usize, usize)> {
    let text = std::fs::read_to_string(boundary).unwrap();
    let mut out = Vec::new();
    let lines: Vec<&str> = text.lines().collect();
    for (i, l) in lines.iter().enumerate() {
        if lines.get(i + 1).is_some_and(|n| n.trim() == "{") && l.starts_with("    ") {
            let rest = lines[i..].join("\n");
            let n = common::number_after(&rest, "nFaces") as usize;
            let start = common::number_after(&rest, "startFace") as usize;
            out.push((l.trim().to_string(), n, start));
        }
    }
    out
}

#[test]
fn solids_of_an_ascii_stl_become_patches() {
    let dir = scratch("openfoam_solids");
    let two = dir.join("halves.stl");
    let one = dir.join("whole.stl");
    common::write_sphere_solids(&two, &[("top", Some(true)), ("bottom", Some(false))]);
    common::write_sphere_solids(&one, &[("top", None)]);
    let run = |stl: &Path, case: &Path, np: usize, extra: &[&str]| {
        let mut args = vec![
            "mesh",
            stl.to_str().unwrap(),
            "--level",
            "5",
            "--keep",
            "outside",
            "--openfoam",
            case.to_str().unwrap(),
            "--openfoam-format",
            "ascii",
        ];
        args.extend(extra);
        octmesh(np, &args, &dir.join("stats.json"))
    };
    let case = dir.join("halves");
    let stats = run(&two, &case, 1, &["--patch", "bottom=floor"]);
    let whole = dir.join("whole");
    run(&one, &whole, 1, &[]);
    let mesh = case.join("constant/polyMesh");
    let patches = patches_of(&mesh.join("boundary"));
    let names: Vec<&str> = patches.iter().map(|p| p.0.as_str()).collect();
    assert_eq!(
        names,
        ["xmin", "xmax", "ymin", "ymax", "zmin", "zmax", "top", "floor"]
    );
    let single = patches_of(&whole.join("constant/polyMesh/boundary"));
    assert_eq!(
        single[6].0, "top",
        "one named solid names the surface patch"
    );
    assert!(patches[6].1 > 0 && patches[7].1 > 0);
    assert_eq!(
        patches[6].1 + patches[7].1,
        single[6].1,
        "the halves split the surface"
    );
    // Each face sits on its half: its centre's height has the half's sign
    // (within a cell of the equator).
    let (points, faces) = read_points_and_faces(&mesh);
    let cell = stats["domain_side"].as_f64().unwrap() / 32.0;
    for (k, sign) in [(6, 1.0), (7, -1.0)] {
        let (_, n, start) = patches[k];
        for f in &faces[start..start + n] {
            let z = f.iter().map(|&p| points[p][2]).sum::<f64>() / f.len() as f64;
            assert!(
                sign * z > -cell,
                "a face at z = {z} on patch {}",
                patches[k].0
            );
        }
    }
    // The same patches on 3 ranks: per-patch face counts add up.
    let par = dir.join("halves_np3");
    run(&two, &par, 3, &["--patch", "bottom=floor"]);
    let mut counts = [0usize; 8];
    for r in 0..3 {
        let b = par.join(format!("processor{r}/constant/polyMesh/boundary"));
        for (k, p) in patches_of(&b).iter().take(8).enumerate() {
            assert_eq!(p.0, names[k]);
            counts[k] += p.1;
        }
    }
    let serial: Vec<usize> = patches.iter().map(|p| p.1).collect();
    assert_eq!(counts.to_vec(), serial, "patch sizes differ on 3 ranks");
    if let Some(rc) = openfoam() {
        judge(&rc, &case, 1, &stats, "two solids");
    }
    println!(
        "sphere as two solids: top {} and floor {} faces (one solid: {}), each on its half, same on 3 ranks",
        patches[6].1, patches[7].1, single[6].1
    );
}

fn octmesh_err(args: &[&str]) -> String {
    let out = Command::new(octmesh_bin()).args(args).output().unwrap();
    assert!(!out.status.success(), "octmesh {args:?} should fail");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn bad_openfoam_requests_fail_clearly() {
    let dir = scratch("openfoam_bad");
    let case = dir.join("case");
    let c = case.to_str().unwrap();
    let base = ["mesh", "sphere", "--keep", "outside", "--openfoam", c];
    let stats = dir.join("s.json");
    octmesh(1, &[&base[..], &["--level", "3"]].concat(), &stats);
    let before = std::fs::read(case.join("constant/polyMesh/owner")).unwrap();
    // An existing mesh stays unless --overwrite.
    let e = octmesh_err(&[&base[..], &["--level", "4"]].concat());
    assert!(e.contains("exists") && e.contains("--overwrite"), "{e}");
    assert_eq!(
        std::fs::read(case.join("constant/polyMesh/owner")).unwrap(),
        before
    );
    octmesh(
        1,
        &[&base[..], &["--level", "4", "--overwrite"]].concat(),
        &stats,
    );
    assert_ne!(
        std::fs::read(case.join("constant/polyMesh/owner")).unwrap(),
        before
    );
    assert!(!case.join("constant/polyMesh.octmesh-partial").exists());
    // Patch names.
    let base = [&base[..], &["--level", "3"]].concat();
    let e = octmesh_err(&[&base[..], &["--patch", "xmin=in let"]].concat());
    assert!(
        e.contains("--patch") && e.contains("not a valid patch name"),
        "{e}"
    );
    let e = octmesh_err(&[&base[..], &["--patch", "xmin=ymin"]].concat());
    assert!(e.contains("unique"), "{e}");
    let e = octmesh_err(&[&base[..], &["--patch", "nowhere=a"]].concat());
    assert!(e.contains("unknown patch 'nowhere'"), "{e}");
    // Renamed patches reach the boundary file.
    octmesh(
        1,
        &[
            &base[..],
            &[
                "--overwrite",
                "--patch",
                "xmin=inlet",
                "--patch",
                "sphere=body",
            ],
        ]
        .concat(),
        &stats,
    );
    let b = std::fs::read_to_string(case.join("constant/polyMesh/boundary")).unwrap();
    assert!(
        b.contains("    inlet\n") && b.contains("    body\n") && !b.contains("    xmin\n"),
        "{b}"
    );
    // Nothing kept.
    let empty = dir.join("empty");
    let e = octmesh_err(&[
        "mesh",
        "sphere",
        "--level",
        "1",
        "--keep",
        "inside",
        "--cut-rule",
        "none",
        "--openfoam",
        empty.to_str().unwrap(),
    ]);
    assert!(e.contains("no elements"), "{e}");
    assert!(!empty.join("constant/polyMesh").exists());
    // An unwritable place.
    let e = octmesh_err(&[
        "mesh",
        "sphere",
        "--level",
        "3",
        "--openfoam",
        "/proc/octmesh-case",
    ]);
    assert!(e.contains("/proc/octmesh-case"), "{e}");
}

/// Files of every `processor<r>/constant/polyMesh` of `case` (empty when
/// there is none), as (path below the case, bytes).
fn processor_meshes(case: &Path, np: usize) -> Vec<(String, Vec<u8>)> {
    let mut v = Vec::new();
    for r in 0..np {
        let dir = case.join(format!("processor{r}/constant/polyMesh"));
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        let mut names: Vec<_> = entries.flatten().map(|e| e.file_name()).collect();
        names.sort();
        for n in names {
            let rel = format!("processor{r}/constant/polyMesh/{}", n.to_string_lossy());
            v.push((rel.clone(), std::fs::read(case.join(&rel)).unwrap()));
        }
    }
    v
}

/// A write that fails on one rank only (here rank 1 of 3, whose scratch
/// directory cannot be made because a file stands in its place): every
/// rank reports it and exits non-zero, no rank leaves a mesh or a scratch
/// directory behind in a new case, and an existing case keeps every byte
/// of its old mesh on every rank, even with `--overwrite`.
#[test]
fn a_write_failing_on_one_rank_fails_every_rank() {
    let dir = scratch("openfoam_one_rank_fails");
    let np = 3;
    // A run expected to succeed goes through `octmesh_ok`, which asserts it.
    let run = |case: &Path, level: &str, ok: bool| {
        let args = [
            "mesh",
            "sphere",
            "--level",
            level,
            "--keep",
            "outside",
            "--openfoam",
            case.to_str().unwrap(),
            "--overwrite",
            "--quiet",
        ];
        if ok {
            common::octmesh_ok(np, &args)
        } else {
            common::mpirun(np, &octmesh_bin(), &args, Duration::from_secs(300))
        }
    };
    let block = |case: &Path| {
        let constant = case.join("processor1/constant");
        std::fs::create_dir_all(&constant).unwrap();
        std::fs::write(constant.join("polyMesh.octmesh-partial"), b"in the way").unwrap();
    };
    // Ranks 0 and 2 made their scratch directories: gone after the failure.
    let expect_no_scratch = |case: &Path| {
        for r in [0, 2] {
            let scratch = case.join(format!("processor{r}/constant/polyMesh.octmesh-partial"));
            assert!(!scratch.exists(), "{} was left", scratch.display());
        }
    };
    let expect_failure = |out: &std::process::Output, tag: &str| {
        for (r, line) in common::rank_error_lines(out, np, tag).iter().enumerate() {
            assert!(
                line.contains("processor1") && line.contains("polyMesh.octmesh-partial"),
                "{tag}: rank {r} says '{line}'"
            );
        }
    };

    // A new case: nothing of a mesh is left, on any rank.
    let fresh = dir.join("fresh");
    block(&fresh);
    expect_failure(&run(&fresh, "3", false), "new case");
    assert!(processor_meshes(&fresh, np).is_empty(), "a mesh was left");
    expect_no_scratch(&fresh);

    // An existing case: the old mesh stays, byte for byte, on every rank.
    let case = dir.join("case");
    run(&case, "3", true);
    let before = processor_meshes(&case, np);
    assert_eq!(before.len(), 5 * np, "five polyMesh files per rank");
    block(&case);
    expect_failure(&run(&case, "4", false), "existing case");
    let after = processor_meshes(&case, np);
    assert!(
        before == after,
        "the old mesh changed on some rank after a failed overwrite"
    );
    expect_no_scratch(&case);
    // Out of the way, the same command overwrites the case.
    std::fs::remove_file(case.join("processor1/constant/polyMesh.octmesh-partial")).unwrap();
    run(&case, "4", true);
    assert!(
        processor_meshes(&case, np) != before,
        "level 4 did not replace level 3"
    );
    println!(
        "a write failing on rank 1 of {np}: every rank reported it, no mesh left in a new case, \
         the old one intact in an existing case"
    );
}

/// A box domain of 6 x 2 x 1 root cells around the sphere with a wake box
/// and two distance bands (a towing-tank layout), fluid kept, written for
/// OpenFOAM on 1 and 3 ranks: checkMesh as for the other cases, and each
/// side patch lies on its face of the box.
#[test]
fn checkmesh_accepts_a_box_domain() {
    let Some(rc) = openfoam() else { return };
    let dir = scratch("openfoam_box");
    let (lo, hi) = ([-3.0, -2.0, -1.5], [9.0, 2.0, 0.5]);
    let bbox = format!(
        "{},{},{},{},{},{}",
        lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]
    );
    for np in [1, 3] {
        let case = dir.join(format!("case{np}"));
        let stats = dir.join(format!("case{np}.json"));
        let s = octmesh(
            np,
            &[
                "mesh",
                "sphere",
                "--box",
                &bbox,
                "--roots",
                "6,2,1",
                "--level",
                "4",
                "--region",
                "box:0,-1,-1,6,1,0.5:3",
                "--distance",
                "0.2:4,0.6:3",
                "--keep",
                "outside",
                "--openfoam",
                case.to_str().unwrap(),
            ],
            &stats,
        );
        let tag = format!("sphere in a 6x2x1 box np {np}");
        judge(&rc, &case, np, &s, &tag);
        // The cut-off sphere (the box ends at z = 0.5) leaves the top open.
        let box_volume: f64 = (0..3).map(|k| hi[k] - lo[k]).product();
        let kept = s["kept_volume"].as_f64().unwrap();
        assert!(
            kept < box_volume && kept > 0.9 * box_volume,
            "{tag}: {kept}"
        );
        let par = if np > 1 {
            "mpirun --oversubscribe -np 3 checkMesh -parallel"
        } else {
            "checkMesh"
        };
        // -allGeometry prints each patch's bounding box.
        let text = foam(&rc, &case, &format!("{par} -allTopology -allGeometry"));
        for (p, name) in ["xmin", "xmax", "ymin", "ymax", "zmin", "zmax"]
            .iter()
            .enumerate()
        {
            let (axis, at) = (p / 2, if p % 2 == 0 { lo[p / 2] } else { hi[p / 2] });
            let line = text
                .lines()
                .find(|l| l.split_whitespace().next() == Some(name))
                .unwrap_or_else(|| panic!("{tag}: no patch {name}:\n{text}"));
            // "... (x0 y0 z0) (x1 y1 z1)": the patch's bounding box.
            let nums: Vec<f64> = line
                .replace(['(', ')'], " ")
                .split_whitespace()
                .rev()
                .take(6)
                .map(|w| w.parse().unwrap())
                .collect();
            let (top, bottom) = (&nums[..3], &nums[3..]);
            // Reversed: top is (z1, y1, x1), bottom (z0, y0, x0).
            assert_eq!(top[2 - axis], at, "{tag}: {line}");
            assert_eq!(bottom[2 - axis], at, "{tag}: {line}");
        }
    }
}

/// The towing tank: the built-in Wigley hull (length 1) in a box of
/// 6 x 2 x 1 hull lengths (6 x 2 x 1 root cells), curvature refinement at
/// the deck's edges, a wake box and two distance bands, fluid kept, written
/// for OpenFOAM on 1 and 2 ranks: checkMesh as for the other cases, the
/// hull's wall closed and singly connected, and the water displaced about
/// the hull's volume.
#[test]
fn checkmesh_accepts_a_towing_tank_around_a_hull() {
    let Some(rc) = openfoam() else { return };
    let dir = scratch("openfoam_tank");
    for np in [1, 2] {
        let case = dir.join(format!("case{np}"));
        let stats = dir.join(format!("case{np}.json"));
        let s = octmesh(
            np,
            &[
                "mesh",
                "hull",
                "--box",
                "-1.5,-1,-0.6,4.5,1,0.4",
                "--roots",
                "6,2,1",
                "--level",
                "6:7",
                "--region",
                "box:0.5,-0.3,-0.3,3,0.3,0.2:3",
                "--distance",
                "0.05:5,0.15:4",
                "--keep",
                "outside",
                "--openfoam",
                case.to_str().unwrap(),
            ],
            &stats,
        );
        let tag = format!("towing tank np {np}");
        judge(&rc, &case, np, &s, &tag);
        let par = if np > 1 {
            "mpirun --oversubscribe -np 2 checkMesh -parallel"
        } else {
            "checkMesh"
        };
        let text = foam(&rc, &case, &format!("{par} -allTopology"));
        let wall = text
            .lines()
            .find(|l| l.split_whitespace().next() == Some("hull"))
            .unwrap_or_else(|| panic!("{tag}: no hull patch:\n{text}"));
        // checkMesh -parallel does not judge a patch's topology.
        assert!(
            np > 1 || wall.contains("ok (closed singly connected)"),
            "{tag}: {wall}"
        );
        // Box 6 x 2 x 1 = 12; the hull displaces 4 B L T / 9 + 2 B L D / 3.
        let hull = 4.0 * 0.1 * 0.0625 / 9.0 + 2.0 * 0.1 * 0.05 / 3.0;
        let displaced = 12.0 - s["kept_volume"].as_f64().unwrap();
        assert!(
            displaced > 0.5 * hull && displaced < 2.0 * hull,
            "{tag}: the fluid leaves {displaced} for a hull of {hull}"
        );
    }
}

/// The list of numbers after `List<scalar>` at the start of `text`, in
/// either of OpenFOAM's ASCII forms (`N\n(\n...\n)` or `N(...)`).
fn scalar_list(text: &str) -> Vec<f64> {
    let open = text.find('(').expect("a list");
    let n: usize = text[..open]
        .split_whitespace()
        .last()
        .and_then(|w| w.parse().ok())
        .expect("list size");
    let close = open + text[open..].find(')').expect("the list's end");
    let v: Vec<f64> = text[open + 1..close]
        .split_whitespace()
        .map(|w| w.parse().unwrap())
        .collect();
    assert_eq!(v.len(), n, "list size");
    v
}

/// An ASCII `surfaceScalarField` (the flux `phi`): the internal faces'
/// values, then the boundary faces' in the order of `patches`
/// (`(name, nFaces, startFace)` from the mesh's boundary file).
fn read_face_scalars(path: &Path, patches: &[(String, usize, usize)]) -> Vec<f64> {
    let text = std::fs::read_to_string(path).unwrap();
    let at = text.find("internalField").expect("internalField");
    let mut out = scalar_list(&text[at..]);
    let boundary = &text[text.find("boundaryField").expect("boundaryField")..];
    for (name, n, start) in patches {
        assert_eq!(out.len(), *start, "patch {name} does not follow");
        let block = &boundary[boundary
            .find(&format!("\n    {name}\n"))
            .unwrap_or_else(|| panic!("no patch {name} in {}", path.display()))..];
        let value = &block[block.find("value").expect("a value")..];
        let rest = value["value".len()..].trim_start();
        if let Some(u) = rest.strip_prefix("uniform") {
            let x: f64 = u.split(';').next().unwrap().trim().parse().unwrap();
            out.extend(std::iter::repeat_n(x, *n));
        } else {
            let v = scalar_list(&rest[rest.find("List<scalar>").expect("a list")..]);
            assert_eq!(v.len(), *n, "patch {name}");
            out.extend(v);
        }
    }
    out
}

/// The `owner` and `neighbour` lists of an ASCII polyMesh.
fn owner_and_neighbour(mesh: &Path) -> (Vec<usize>, Vec<usize>) {
    let read = |name: &str| -> Vec<usize> {
        (list_lines(&mesh.join(name)).iter())
            .map(|l| l.parse().unwrap())
            .collect()
    };
    (read("owner"), read("neighbour"))
}

/// Cell velocities reconstructed from face fluxes as OpenFOAM's
/// `fvc::reconstruct` defines them: in each cell, `U` solves
/// `(sum S S^T / |S|) U = sum (S / |S|) phi` over its faces (area vectors
/// `S` as OpenFOAM computes them: triangles about the mean of the face's
/// points). Also returns each cell's centre (the mean of its faces' mean
/// points, enough to pick cells by position).
fn reconstruct(case: &Path, phi_file: &Path) -> (Vec<[f64; 3]>, Vec<[f64; 3]>) {
    let mesh = case.join("constant/polyMesh");
    let (points, faces) = read_points_and_faces(&mesh);
    let (owner, neighbour) = owner_and_neighbour(&mesh);
    let patches = patches_of(&mesh.join("boundary"));
    let phi = read_face_scalars(phi_file, &patches);
    assert_eq!(phi.len(), faces.len());
    let cells = owner.iter().max().unwrap() + 1;
    let mut t = vec![[0.0f64; 9]; cells];
    let mut b = vec![[0.0f64; 3]; cells];
    let mut centre = vec![[0.0f64; 4]; cells];
    for (k, f) in faces.iter().enumerate() {
        let m = f.len() as f64;
        let mid = [0, 1, 2].map(|a| f.iter().map(|&p| points[p][a]).sum::<f64>() / m);
        let mut s = [0.0f64; 3];
        for i in 0..f.len() {
            let (p, q) = (points[f[i]], points[f[(i + 1) % f.len()]]);
            let (u, v) = (
                [0, 1, 2].map(|a| p[a] - mid[a]),
                [0, 1, 2].map(|a| q[a] - mid[a]),
            );
            s[0] += 0.5 * (u[1] * v[2] - u[2] * v[1]);
            s[1] += 0.5 * (u[2] * v[0] - u[0] * v[2]);
            s[2] += 0.5 * (u[0] * v[1] - u[1] * v[0]);
        }
        let a = (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]).sqrt();
        let mut add = |c: usize| {
            for i in 0..3 {
                b[c][i] += s[i] / a * phi[k];
                for j in 0..3 {
                    t[c][3 * i + j] += s[i] * s[j] / a;
                }
                centre[c][i] += mid[i];
            }
            centre[c][3] += 1.0;
        };
        add(owner[k]);
        if k < neighbour.len() {
            add(neighbour[k]);
        }
    }
    let det = |m: &[f64; 9]| {
        m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6])
            + m[2] * (m[3] * m[7] - m[4] * m[6])
    };
    let u = t
        .iter()
        .zip(&b)
        .map(|(m, r)| {
            let d = det(m);
            // Cramer's rule: column k replaced by the right-hand side.
            [0, 1, 2].map(|k| {
                let mut mk = *m;
                for i in 0..3 {
                    mk[3 * i + k] = r[i];
                }
                det(&mk) / d
            })
        })
        .collect();
    let c = centre
        .iter()
        .map(|c| [c[0] / c[3], c[1] / c[3], c[2] / c[3]])
        .collect();
    (u, c)
}

fn speed(u: [f64; 3]) -> f64 {
    (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt()
}

/// Potential flow past a sphere of radius R = 1 in a uniform stream U = 1
/// peaks at 1.5 U on the equator (the plane x = 0). The built-in sphere
/// (centre 0, radius 1) in a box of 15 x 10 x 10 root cells of side 1, the
/// sphere 5 radii from the inlet (xmin, fixed U) and from the sides (slip),
/// 10 from the outlet (xmax, fixed p): the side walls' images raise the
/// stream at the sphere by about 0.56 (R / 5)^3 = 0.45 %. Cells of 1/64
/// (h / R = 0.016) within 0.03 of the surface, coarser bands further out,
/// fluid kept; once as the octree's staircase and once snapped (`--snap`,
/// least scaled Jacobian 0.1), both written in ASCII and solved by
/// `potentialFoam` with the reference case's settings.
///
/// The speed is the cell velocity OpenFOAM reconstructs from the solved
/// fluxes (`fvc::reconstruct(phi)`), recomputed here from the written
/// fluxes: this OpenFOAM build (Debian 12, v1912 under gcc 12) writes
/// wrong `U` in cells whose reconstruction tensor is not diagonal (the
/// tensor-vector products are miscompiled with tree vectorization, which
/// later OpenFOAM releases switch off for them), so the written `U` is right
/// on the staircase (checked here to 1e-6) and wrong by up to thousands on
/// snapped cells (counted and printed).
///
/// The peak speed is the largest cell speed within 2 h of the equatorial
/// plane, where the exact flow peaks; the wall cells' centres lie h / 2
/// off the wall, where the exact speed is about 1.5 (1 - h / 2R), 0.8 %
/// below the peak. It must be within 2 % of 1.5 on the snapped mesh and
/// not within 2 % on the staircase. The largest speed anywhere is printed,
/// not asserted: on both meshes it lies off the equator, at the fluid's
/// staircase corners (BENCHMARKS.md, "Snapping").
///
/// The solver settings are the reference's (two non-orthogonal
/// correctors); without the correction the staircase's equatorial peak is
/// within 2 % too (BENCHMARKS.md).
#[test]
fn potential_flow_peaks_at_one_and_a_half_on_the_snapped_sphere() {
    let Some(rc) = openfoam() else { return };
    let Some(reference) = reference_case("sphere_castellated") else {
        return;
    };
    let dir = scratch("openfoam_peak");
    let h = 1.0 / 64.0;
    let mut equator = Vec::new();
    for snap in [false, true] {
        let name = if snap { "snapped" } else { "staircase" };
        let case = dir.join(name);
        let _ = std::fs::remove_dir_all(&case);
        let c = case.to_str().unwrap();
        let mut args = vec![
            "mesh",
            "sphere",
            "--box",
            "-5,-5,-5,10,5,5",
            "--roots",
            "15,10,10",
            "--level",
            "6",
            "--distance",
            "0.03:6,0.1:5,0.3:4,0.8:3,2:2",
            "--keep",
            "outside",
            "--openfoam",
            c,
            "--openfoam-format",
            "ascii",
        ];
        if snap {
            args.push("--snap");
        }
        let stats = octmesh(1, &args, &dir.join(format!("{name}.json")));
        for f in ["fvSchemes", "fvSolution"] {
            std::fs::copy(
                reference.join("system").join(f),
                case.join("system").join(f),
            )
            .unwrap();
        }
        // The reference's controlDict, with the fields written to 12 digits.
        let control = std::fs::read_to_string(reference.join("system/controlDict")).unwrap();
        assert!(control.contains("writeFormat ascii;"), "{control}");
        std::fs::write(
            case.join("system/controlDict"),
            control.replace(
                "writeFormat ascii;",
                "writeFormat ascii; writePrecision 12;",
            ),
        )
        .unwrap();
        std::fs::create_dir_all(case.join("0")).unwrap();
        for f in ["U", "p"] {
            std::fs::copy(reference.join("0").join(f), case.join("0").join(f)).unwrap();
        }
        let log = foam(&rc, &case, "potentialFoam -writephi");
        assert!(
            log.contains("\nEnd"),
            "potentialFoam did not finish:\n{log}"
        );
        let (u, centres) = reconstruct(&case, &case.join("0/phi"));
        let written = read_vectors(&case.join("0/U"));
        assert_eq!(u.len(), written.len());
        let differ = u
            .iter()
            .zip(&written)
            .filter(|(a, w)| (0..3).any(|k| (a[k] - w[k]).abs() > 1e-6 * speed(**w).max(1.0)))
            .count();
        if !snap {
            assert_eq!(
                differ, 0,
                "the staircase's reconstructed velocities differ from OpenFOAM's in {differ} cells"
            );
        }
        let top = |pick: &dyn Fn(usize) -> bool| {
            (0..u.len())
                .filter(|&i| pick(i))
                .map(|i| (speed(u[i]), i))
                .fold((0.0f64, 0usize), |a, b| if b.0 > a.0 { b } else { a })
        };
        let (global, g) = top(&|_| true);
        let (peak, e) = top(&|i| centres[i][0].abs() < 2.0 * h);
        let at = |i: usize| {
            let p = centres[i];
            format!("({:.3}, {:.3}, {:.3}), r {:.4}", p[0], p[1], p[2], speed(p))
        };
        println!(
            "{name}: {} cells, {:?}; peak speed within 2h of the equator {peak:.4} ({:+.2} % of 1.5) at {}; \
             largest anywhere {global:.4} ({:+.2} %) at {}; OpenFOAM's written U differs in {differ} cells",
            u.len(),
            stats.get("snap").map(|s| s.to_string()),
            100.0 * (peak / 1.5 - 1.0),
            at(e),
            100.0 * (global / 1.5 - 1.0),
            at(g),
        );
        equator.push(peak);
    }
    let (stair, snapped) = (equator[0], equator[1]);
    assert!(
        (snapped / 1.5 - 1.0).abs() < 0.02,
        "snapped: peak speed {snapped} is not within 2 % of 1.5"
    );
    assert!(
        (stair / 1.5 - 1.0).abs() >= 0.02,
        "staircase: peak speed {stair} is within 2 % of 1.5"
    );
}
