//! Zones (`--zones`, `mesh.zones`): the inside and the outside of the
//! surface and the regions' zones, as OpenFOAM cellZones and faceZones.
//!
//! Run by `cargo test`, this program launches itself under `mpirun` on 1
//! and on 3 ranks. Each run meshes the sphere in its box at level 5
//! keeping every leaf with zones, through a [`Session`], and writes the
//! OpenFOAM case (ASCII on 1 rank, binary on 3; the zone files are ASCII
//! in both). Then:
//!
//! - the zones' element counts equal the element counts of the same run
//!   keeping inside and keeping outside (without wall clean-up), and with
//!   the clean-up (an OpenFOAM case) the inside zone is what keeping inside
//!   keeps cleaned, the outside zone the rest;
//! - OpenFOAM's `splitMeshRegions -cellZones -overwrite` (with `-parallel`
//!   on 3 ranks) makes exactly the two regions `inside` and `outside`, and
//!   `checkMesh -region` says `Mesh OK.` on each, with the zone's cells,
//!   and (on 1 rank, where it judges them) no multiply connected patch;
//! - the two sides of the interface that splitMeshRegions made,
//!   `inside_to_outside` and `outside_to_inside`, have the same area to
//!   1e-12 relative (read from the region meshes, which OpenFOAM wrote);
//! - on 1 rank, the faceZone `inside_outside` oriented by its flipMap is a
//!   closed surface around the inside zone: its flux of `x / 3` (the
//!   divergence theorem) is the inside zone's volume from checkMesh, which
//!   a flipMap wrong on any face would change;
//! - a region with `zone = "east"` adds the zone `east` after `inside` and
//!   `outside`, with the elements whose centre it holds, in the written
//!   cellZones too;
//! - `--gmsh` with zones gives one physical volume per zone: Gmsh's Python
//!   API reads the file, finds the physical volumes `inside`, `outside`
//!   and `east` with the zones' element counts, and the file has the same
//!   bytes on 1 and 3 ranks;
//! - the bunny at level 7 (shared model), whose centre rule alone leaves
//!   edges shared by four interface faces: with the wall clean-up the
//!   inside zone is what `--keep inside --openfoam` keeps, and checkMesh
//!   finds both sides of the interface closed and singly connected;
//! - zones without keep all fail on every rank, through the library and
//!   through the command, with a message naming keep all.
//!
//! Without OpenFOAM, Gmsh's Python module or the shared models the checks that need it are skipped, and fail under
//! `CI=true` (`tests/common`).

mod common;

use std::path::{Path, PathBuf};
use std::rc::Rc;
use std::time::Duration;

use common::runner::{launch, ranks};
use octmesh::internals::classify::Keep;
use octmesh::internals::config::{Command, Config};
use octmesh::internals::io::openfoam::FoamFormat;
use octmesh::internals::parallel::comm::{CommRef, MpiComm};
use octmesh::internals::pipeline::Session;
use octmesh::internals::refine::regions::Region;

const LIMIT: Duration = Duration::from_secs(600);

fn main() {
    common::runner::main("zones", child, |r| {
        for np in [1, 3] {
            r.test(&format!("sphere in the box on {}", ranks(np)), || {
                sphere_in_the_box(np)
            });
            r.test(&format!("a region's zone on {}", ranks(np)), || {
                region_zone(np)
            });
            r.test(
                &format!("zones without keep all fail on {}", ranks(np)),
                || zones_need_keep_all(np),
            );
        }
        r.test("gmsh physical volumes per zone", gmsh_volumes);
        r.test("a zone per closed solid", zones_per_solid);
        r.test("the bunny's interface is manifold", bunny_interface);
    });
}

/// The sphere at level 5 (`keep`, with zones or not) run through a session
/// on the world.
fn config(keep: Keep, zones: bool) -> Config {
    let mut c = Config::default();
    c.surface.file = "sphere".into();
    c.octree.level = Some(5);
    c.mesh.keep = keep;
    c.mesh.zones = zones;
    c.output.quiet = true;
    c
}

/// What a launched copy does: `MODE:DIR`.
fn child(mode: &str) {
    std::panic::set_hook(Box::new(|info| {
        eprintln!("{info}");
        std::process::exit(101);
    }));
    let universe = mpi::initialize().expect("MPI init");
    let comm: CommRef = Rc::new(MpiComm::new(universe.world()));
    let (mode, dir) = mode.split_once(':').expect("MODE:DIR");
    let root = comm.rank() == 0;
    let run = |c: Config| Session::new(comm.clone(), c).run(Command::Mesh);
    let print_zones = |s: &octmesh::Stats| {
        for z in s.mesh.as_ref().unwrap().zones.as_ref().unwrap() {
            if root {
                println!("zone {} {}", z.name, z.elements);
            }
        }
    };
    match mode {
        "sphere" => {
            for (keep, clean) in [
                (Keep::Inside, false),
                (Keep::Outside, false),
                (Keep::Inside, true),
            ] {
                let mut c = config(keep, false);
                c.mesh.clean_walls = Some(clean);
                let s = run(c).unwrap();
                let n = s.mesh.unwrap().counts.elements;
                if root {
                    let tag = if clean { "cleaned" } else { "plain" };
                    println!("keep {}-{tag} {n}", keep.name());
                }
            }
            // Without a case the walls are not cleaned.
            let s = run(config(Keep::All, true)).unwrap();
            for z in s.mesh.as_ref().unwrap().zones.as_ref().unwrap() {
                if root {
                    println!("plain-zone {} {}", z.name, z.elements);
                }
            }
            let mut c = config(Keep::All, true);
            c.output.openfoam = Some(dir.into());
            c.output.openfoam_format = match comm.size() {
                1 => FoamFormat::Ascii,
                _ => FoamFormat::Binary,
            };
            print_zones(&run(c).unwrap());
        }
        "region" => {
            let mut c = config(Keep::All, true);
            c.regions = vec![Region::parse("box:0.5,-9,-9,9,9,9:0:zone=east").unwrap()];
            c.output.openfoam = Some(dir.into());
            print_zones(&run(c).unwrap());
        }
        "bad" => {
            let e = run(config(Keep::Inside, true)).unwrap_err();
            println!("rank {} error: {e}", comm.rank());
        }
        _ => panic!("unknown mode {mode}"),
    }
}

/// The `PREFIX NAME COUNT` lines of a run's output, as (name, count).
fn counted(out: &str, prefix: &str) -> Vec<(String, u64)> {
    out.lines()
        .filter_map(|l| l.strip_prefix(prefix))
        .map(|l| {
            let (n, c) = l.split_once(' ').unwrap();
            (n.to_string(), c.parse().unwrap())
        })
        .collect()
}

/// The mesh directories of `case` (`region` empty: the base mesh).
fn mesh_dirs(case: &Path, np: usize, region: &str) -> Vec<PathBuf> {
    let under = |d: PathBuf| d.join("constant").join(region).join("polyMesh");
    match np {
        1 => vec![under(case.to_path_buf())],
        _ => (0..np)
            .map(|r| under(case.join(format!("processor{r}"))))
            .collect(),
    }
}

fn sphere_in_the_box(np: usize) {
    let case = common::scratch(&format!("zones_sphere_{np}"));
    let out = launch(np, &format!("sphere:{}", case.display()), LIMIT);
    let keep = counted(&out, "keep ");
    let plain = counted(&out, "plain-zone ");
    let zones = counted(&out, "zone ");
    println!(
        "{}: keep runs {keep:?}, zones {plain:?}, cleaned for OpenFOAM {zones:?}",
        ranks(np)
    );
    let named = |a: u64, b: u64| [("inside".to_string(), a), ("outside".to_string(), b)];
    assert_eq!(
        plain,
        named(keep[0].1, keep[1].1),
        "the zones hold what keep inside and keep outside keep"
    );
    let all = keep[0].1 + keep[1].1;
    assert_eq!(
        zones,
        named(keep[2].1, all - keep[2].1),
        "with the wall clean-up the inside zone is what keep inside keeps cleaned"
    );
    // The base mesh's zone files list every cell once.
    let mut cells = [0usize; 2];
    for d in mesh_dirs(&case, np, "") {
        let z = read_zones(&d.join("cellZones"));
        assert_eq!(z.len(), 2, "{}", d.display());
        for (k, (name, labels)) in z.iter().enumerate() {
            assert_eq!(name, &zones[k].0);
            cells[k] += labels.len();
        }
    }
    assert_eq!(cells.map(|c| c as u64), [zones[0].1, zones[1].1]);
    if np == 1 {
        faces_zone_encloses_the_inside(&case);
    }
    let Some(rc) = common::openfoam() else { return };
    // The region meshes in ASCII, to read them back here.
    let dict = case.join("system").join("controlDict");
    let text = std::fs::read_to_string(&dict).unwrap();
    std::fs::write(
        &dict,
        text.replace("writeFormat     binary;", "writeFormat     ascii;"),
    )
    .unwrap();
    let par = |cmd: &str| match np {
        1 => cmd.to_string(),
        _ => format!("mpirun --oversubscribe -np {np} {cmd} -parallel"),
    };
    let split = common::foam(&rc, &case, &par("splitMeshRegions -cellZones -overwrite"));
    let made: Vec<&str> = split
        .lines()
        .filter_map(|l| l.strip_prefix("Creating mesh for region "))
        .collect();
    assert_eq!(made.len(), 2, "two regions:\n{split}");
    let mut area = Vec::new();
    for (k, (region, other)) in [("inside", "outside"), ("outside", "inside")]
        .into_iter()
        .enumerate()
    {
        assert!(made.iter().any(|m| m.ends_with(region)), "{made:?}");
        let check = common::foam(&rc, &case, &par(&format!("checkMesh -region {region}")));
        assert!(
            check.contains("\nMesh OK."),
            "checkMesh -region {region}:\n{check}"
        );
        if np == 1 {
            // checkMesh -parallel does not judge a patch's topology.
            assert!(
                !check.contains("multiply connected ("),
                "{region}:\n{check}"
            );
        }
        let n = common::number_after(&check, "cells:") as u64;
        assert_eq!(n, zones[k].1, "cells of region {region}");
        let patch = format!("{region}_to_{other}");
        let a: f64 = mesh_dirs(&case, np, region)
            .iter()
            .map(|d| patch_area(d, &patch))
            .sum();
        println!(
            "{}: region {region}: {n} cells, Mesh OK, {patch} area {a:.15e}",
            ranks(np)
        );
        area.push(a);
    }
    let rel = (area[0] - area[1]).abs() / area[0];
    assert!(area[0] > 1.0 && rel < 1e-12, "interface areas {area:?}");
}

/// The flux of `x / 3` through the faceZone `inside_outside` of the
/// serial ASCII case, oriented by its flipMap, is the volume of the cells
/// of the cellZone `inside`.
fn faces_zone_encloses_the_inside(case: &Path) {
    let d = &mesh_dirs(case, 1, "")[0];
    let points = read_points(&d.join("points"));
    let faces = read_faces(&d.join("faces"));
    let zones = read_zones(&d.join("faceZones"));
    let flips = read_flips(&d.join("faceZones"));
    assert_eq!(zones.len(), 1);
    assert_eq!(zones[0].0, "inside_outside");
    let mut flux = 0.0;
    for (&f, &flip) in zones[0].1.iter().zip(&flips[0]) {
        let (n, c) = normal_and_centre(&faces[f], &points);
        let s = if flip { -1.0 } else { 1.0 };
        flux += s * (0..3).map(|k| n[k] * c[k]).sum::<f64>() / 3.0;
    }
    // The inside cells' volume: the same flux over their faces, each cell
    // closed, from the owner and neighbour lists.
    let owner = read_labels(&d.join("owner"));
    let neighbour = read_labels(&d.join("neighbour"));
    let cells = &read_zones(&d.join("cellZones"))[0].1;
    let mut inside = vec![false; owner.iter().max().unwrap() + 1];
    cells.iter().for_each(|&c| inside[c] = true);
    let mut volume = 0.0;
    for (f, face) in faces.iter().enumerate() {
        let (n, c) = normal_and_centre(face, &points);
        let v = (0..3).map(|k| n[k] * c[k]).sum::<f64>() / 3.0;
        if inside[owner[f]] {
            volume += v;
        }
        if f < neighbour.len() && inside[neighbour[f]] {
            volume -= v;
        }
    }
    println!(
        "1 rank: faceZone inside_outside encloses {flux:.12e}, the inside cells {volume:.12e}"
    );
    assert!(volume > 1.0, "{volume}");
    assert!(
        ((flux - volume) / volume).abs() < 1e-12,
        "the faceZone's flipMap: flux {flux}, volume {volume}"
    );
}

fn region_zone(np: usize) {
    let case = common::scratch(&format!("zones_region_{np}"));
    let out = launch(np, &format!("region:{}", case.display()), LIMIT);
    let zones = counted(&out, "zone ");
    let names: Vec<&str> = zones.iter().map(|z| z.0.as_str()).collect();
    assert_eq!(names, ["inside", "outside", "east"], "{out}");
    assert!(zones.iter().all(|z| z.1 > 0), "{zones:?}");
    // The box x > 0.5 lies beyond the sphere's inside zone in part only.
    let mut cells = [0u64; 3];
    for d in mesh_dirs(&case, np, "") {
        for (k, (_, l)) in read_zones(&d.join("cellZones")).iter().enumerate() {
            cells[k] += l.len() as u64;
        }
        let faces = read_zones(&d.join("faceZones"));
        let names: Vec<&str> = faces.iter().map(|z| z.0.as_str()).collect();
        assert_eq!(names, ["inside_outside", "inside_east", "outside_east"]);
    }
    assert_eq!(
        cells.to_vec(),
        zones.iter().map(|z| z.1).collect::<Vec<_>>()
    );
}

fn zones_need_keep_all(np: usize) {
    let out = launch(np, "bad:-", LIMIT);
    let lines: Vec<&str> = out.lines().filter(|l| l.contains(" error: ")).collect();
    assert_eq!(lines.len(), np, "{out}");
    for l in &lines {
        assert!(l.contains("need keep all"), "{l}");
    }
    let cli = common::mpirun(
        np,
        &common::octmesh_bin(),
        &[
            "mesh", "sphere", "--level", "3", "--keep", "inside", "--zones",
        ],
        LIMIT,
    );
    for l in common::rank_error_lines(&cli, np, "--zones --keep inside") {
        assert!(l.contains("--zones needs --keep all"), "{l}");
    }
}

// ----- reading OpenFOAM's ASCII files ---------------------------------------

/// The text after a FoamFile header, without comments.
fn body(path: &Path) -> String {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    let at = text.find("FoamFile").expect("a FoamFile header");
    let rest = &text[at..];
    let end = rest.find('}').unwrap();
    rest[end + 1..]
        .lines()
        .map(|l| l.split("//").next().unwrap())
        .collect::<Vec<_>>()
        .join("\n")
}

/// The words and numbers of `s`, with `(` and `)` as tokens of their own.
fn tokens(s: &str) -> Vec<String> {
    s.replace('(', " ( ")
        .replace(')', " ) ")
        .split_whitespace()
        .map(str::to_string)
        .collect()
}

/// The list that starts at `t[*i]` (`N ( items )`): each item's tokens.
fn list(t: &[String], i: &mut usize) -> Vec<Vec<String>> {
    let n: usize = t[*i]
        .parse()
        .unwrap_or_else(|_| panic!("a count, got {}", t[*i]));
    *i += 1;
    assert_eq!(t[*i], "(");
    *i += 1;
    let mut out = Vec::with_capacity(n);
    while t[*i] != ")" {
        // An item: a token, or `k ( ... )`, or `( ... )`.
        let mut item = Vec::new();
        if t[*i] == "(" || t.get(*i + 1).is_some_and(|x| x == "(") {
            if t[*i] != "(" {
                *i += 1;
            }
            *i += 1;
            while t[*i] != ")" {
                item.push(t[*i].clone());
                *i += 1;
            }
        } else {
            item.push(t[*i].clone());
        }
        *i += 1;
        out.push(item);
    }
    *i += 1;
    assert_eq!(out.len(), n);
    out
}

fn read_points(path: &Path) -> Vec<[f64; 3]> {
    let t = tokens(&body(path));
    list(&t, &mut 0)
        .iter()
        .map(|p| std::array::from_fn(|k| p[k].parse().unwrap()))
        .collect()
}

fn read_faces(path: &Path) -> Vec<Vec<usize>> {
    let t = tokens(&body(path));
    list(&t, &mut 0)
        .iter()
        .map(|f| f.iter().map(|x| x.parse().unwrap()).collect())
        .collect()
}

fn read_labels(path: &Path) -> Vec<usize> {
    let t = tokens(&body(path));
    list(&t, &mut 0)
        .iter()
        .map(|x| x[0].parse().unwrap())
        .collect()
}

/// The entries `name { ... KEY List<T> N ( ... ) ; }` of a zones file:
/// each name with the list after `key`.
fn zone_lists(path: &Path, key: &str) -> Vec<(String, Vec<String>)> {
    let t = tokens(&body(path));
    let mut i = 0;
    let n: usize = t[i].parse().unwrap();
    i += 2;
    let mut out = Vec::new();
    for _ in 0..n {
        let name = t[i].clone();
        while t[i] != key {
            i += 1;
        }
        i += 2; // the key and List<...>
        let l = list(&t, &mut i).into_iter().map(|x| x[0].clone()).collect();
        while t[i] != "}" {
            i += 1;
        }
        i += 1;
        out.push((name, l));
    }
    out
}

/// A cellZones or faceZones file: each zone's name and labels.
fn read_zones(path: &Path) -> Vec<(String, Vec<usize>)> {
    let key = match path.file_name().unwrap().to_str().unwrap() {
        "cellZones" => "cellLabels",
        _ => "faceLabels",
    };
    zone_lists(path, key)
        .into_iter()
        .map(|(n, l)| (n, l.iter().map(|x| x.parse().unwrap()).collect()))
        .collect()
}

/// Each faceZone's flipMap.
fn read_flips(path: &Path) -> Vec<Vec<bool>> {
    zone_lists(path, "flipMap")
        .into_iter()
        .map(|(_, l)| l.iter().map(|x| x == "1" || x == "true").collect())
        .collect()
}

/// A polygon's area vector (Newell) and its points' mean.
fn normal_and_centre(face: &[usize], points: &[[f64; 3]]) -> ([f64; 3], [f64; 3]) {
    let mut n = [0.0; 3];
    let mut c = [0.0; 3];
    for (k, &a) in face.iter().enumerate() {
        let (p, q) = (points[a], points[face[(k + 1) % face.len()]]);
        n[0] += 0.5 * (p[1] * q[2] - p[2] * q[1]);
        n[1] += 0.5 * (p[2] * q[0] - p[0] * q[2]);
        n[2] += 0.5 * (p[0] * q[1] - p[1] * q[0]);
        (0..3).for_each(|j| c[j] += p[j] / face.len() as f64);
    }
    (n, c)
}

/// The area of patch `name` of the ASCII mesh in `dir` (0 when this piece
/// has no such patch).
fn patch_area(dir: &Path, name: &str) -> f64 {
    let t = tokens(&body(&dir.join("boundary")));
    let Some(at) = t.iter().position(|x| x == name) else {
        return 0.0;
    };
    let value = |key: &str| -> usize {
        let k = at + t[at..].iter().position(|x| x == key).unwrap();
        t[k + 1].trim_end_matches(';').parse().unwrap()
    };
    let (n, start) = (value("nFaces"), value("startFace"));
    let points = read_points(&dir.join("points"));
    let faces = read_faces(&dir.join("faces"));
    faces[start..start + n]
        .iter()
        .map(|f| {
            let (a, _) = normal_and_centre(f, &points);
            (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
        })
        .sum()
}

/// Gmsh's physical volumes of the sphere with a region's zone, written on
/// 1 and 3 ranks.
fn gmsh_volumes() {
    let dir = common::scratch("zones_gmsh");
    let mut files = Vec::new();
    for np in [1, 3] {
        let (msh, stats) = (
            dir.join(format!("z{np}.msh")),
            dir.join(format!("z{np}.json")),
        );
        common::octmesh_ok(
            np,
            &[
                "mesh",
                "sphere",
                "--level",
                "4",
                "--keep",
                "all",
                "--zones",
                "--region",
                "box:0.5,-9,-9,9,9,9:0:zone=east",
                "--gmsh",
                msh.to_str().unwrap(),
                "--stats",
                stats.to_str().unwrap(),
                "--quiet",
            ],
        );
        files.push((msh, common::json_file(&stats)));
    }
    let bytes = |p: &Path| std::fs::read(p).unwrap();
    assert!(
        bytes(&files[0].0) == bytes(&files[1].0),
        "the .msh differs on 1 and 3 ranks"
    );
    let zones: Vec<(String, u64)> = files[0].1["zones"]
        .as_array()
        .unwrap()
        .iter()
        .map(|z| {
            (
                z["name"].as_str().unwrap().to_string(),
                z["elements"].as_u64().unwrap(),
            )
        })
        .collect();
    let Some(python) = common::require(common::Oracle::Python {
        module: "gmsh",
        package: "python3-gmsh",
    }) else {
        return;
    };
    let script = r#"
import sys, gmsh
gmsh.initialize()
gmsh.option.setNumber("General.Terminal", 0)
gmsh.open(sys.argv[1])
for d, t in gmsh.model.getPhysicalGroups(3):
    n = 0
    for e in gmsh.model.getEntitiesForPhysicalGroup(d, t):
        types, elems, _ = gmsh.model.mesh.getElements(d, e)
        n += sum(len(x) for x in elems)
    print("volume", gmsh.model.getPhysicalName(d, t), n)
gmsh.finalize()
"#;
    let out = std::process::Command::new(python)
        .args(["-c", script, files[0].0.to_str().unwrap()])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "gmsh:\n{text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let read = counted(&text, "volume ");
    println!("gmsh physical volumes {read:?}, zones {zones:?}");
    assert_eq!(read, zones);
}

/// The bunny with zones for OpenFOAM: the inside zone is the cleaned solid
/// and both region meshes have a manifold interface.
fn bunny_interface() {
    let Some(bunny) = common::shared_model("bunny.stl") else {
        return;
    };
    let dir = common::scratch("zones_bunny");
    let b = bunny.to_str().unwrap();
    let elements = |args: &[&str], name: &str| {
        let (case, stats) = (dir.join(name), dir.join(format!("{name}.json")));
        let mut all = vec!["mesh", b, "--level", "7"];
        all.extend(args);
        all.extend(["--openfoam", case.to_str().unwrap()]);
        all.extend(["--stats", stats.to_str().unwrap(), "--quiet"]);
        common::octmesh_ok(1, &all);
        (case, common::json_file(&stats))
    };
    let (_, solid) = elements(&["--keep", "inside"], "solid");
    let (case, s) = elements(&["--keep", "all", "--zones"], "zones");
    let inside = s["zones"][0]["elements"].as_u64().unwrap();
    assert_eq!(inside, solid["elements"].as_u64().unwrap());
    assert!(
        s["cleaned"].as_u64().unwrap() > 0,
        "the clean-up moved no leaf"
    );
    let Some(rc) = common::openfoam() else { return };
    common::foam(&rc, &case, "splitMeshRegions -cellZones -overwrite");
    for region in ["inside", "outside"] {
        let check = common::foam(&rc, &case, &format!("checkMesh -region {region}"));
        assert!(check.contains("\nMesh OK."), "{region}:\n{check}");
        assert!(
            !check.contains("multiply connected ("),
            "{region}:\n{check}"
        );
        assert!(
            check.contains("ok (closed singly connected)"),
            "{region}:\n{check}"
        );
    }
    println!("bunny level 7: inside zone {inside} = keep inside's, a manifold interface, Mesh OK");
}

/// Writes an ASCII STL of the built-in sphere scaled by `r` and moved by
/// each of `centres`, one solid each, named by `names`; all in one solid
/// named `both` when `one` is set.
fn write_spheres(path: &Path, names: &[&str], centres: &[[f64; 3]], r: f64, one: bool) {
    let s = octmesh::internals::geometry::shapes::default_sphere();
    let mut text = String::new();
    for (k, (name, c)) in names.iter().zip(centres).enumerate() {
        if !one || k == 0 {
            let name = if one { "both" } else { name };
            text.push_str(&format!("solid {name}\n"));
        }
        for t in s.triangles() {
            text.push_str("facet normal 0 0 0\n outer loop\n");
            for v in &t.v {
                let p: Vec<String> = (0..3).map(|a| format!("{:e}", c[a] + r * v[a])).collect();
                text.push_str(&format!("  vertex {}\n", p.join(" ")));
            }
            text.push_str(" endloop\nendfacet\n");
        }
        if !one || k + 1 == names.len() {
            let name = if one { "both" } else { name };
            text.push_str(&format!("endsolid {name}\n"));
        }
    }
    std::fs::write(path, text).unwrap();
}

/// The zones of `stl` (level 5, keep all, zones) on `np` ranks: names and
/// element counts, and the Gmsh file's bytes.
fn solid_zones(dir: &Path, stl: &Path, np: usize) -> (Vec<(String, u64)>, Vec<u8>) {
    let tag = format!("{}_{np}", stl.file_stem().unwrap().to_string_lossy());
    let (msh, stats) = (
        dir.join(format!("{tag}.msh")),
        dir.join(format!("{tag}.json")),
    );
    common::octmesh_ok(
        np,
        &[
            "mesh",
            stl.to_str().unwrap(),
            "--level",
            "5",
            "--keep",
            "all",
            "--zones",
            "--gmsh",
            msh.to_str().unwrap(),
            "--stats",
            stats.to_str().unwrap(),
            "--quiet",
        ],
    );
    let s = common::json_file(&stats);
    let zones = s["zones"]
        .as_array()
        .unwrap()
        .iter()
        .map(|z| {
            let name = z["name"].as_str().unwrap().to_string();
            (name, z["elements"].as_u64().unwrap())
        })
        .collect();
    (zones, std::fs::read(msh).unwrap())
}

/// Two spheres apart, each its own solid of an ASCII STL: the inside
/// splits into a zone per solid (`left`, `right`), which together hold
/// what the same triangles as one solid keep inside, on 1 and 3 ranks
/// alike. The halves of one sphere (open solids) do not split it.
fn zones_per_solid() {
    let dir = common::scratch("zones_solids");
    let (two, one, halves) = (
        dir.join("two.stl"),
        dir.join("one.stl"),
        dir.join("halves.stl"),
    );
    let centres = [[-0.61, 0.013, 0.027], [0.59, -0.021, 0.011]];
    write_spheres(&two, &["left", "right"], &centres, 0.47, false);
    write_spheres(&one, &["left", "right"], &centres, 0.47, true);
    common::write_sphere_solids(&halves, &[("top", Some(true)), ("bottom", Some(false))]);
    let (zones, msh1) = solid_zones(&dir, &two, 1);
    let names: Vec<&str> = zones.iter().map(|z| z.0.as_str()).collect();
    assert_eq!(names, ["inside", "outside", "left", "right"]);
    let (whole, _) = solid_zones(&dir, &one, 1);
    assert_eq!(whole.len(), 2, "one solid: {whole:?}");
    assert_eq!(
        zones[0].1, 0,
        "every inside element is in a solid: {zones:?}"
    );
    assert!(zones[2].1 > 0 && zones[3].1 > 0, "{zones:?}");
    assert_eq!(
        zones[2].1 + zones[3].1,
        whole[0].1,
        "{zones:?} against {whole:?}"
    );
    assert_eq!(zones[1].1, whole[1].1);
    // Mirror images: the same count each side.
    assert!(
        zones[2].1.abs_diff(zones[3].1) * 10 < zones[2].1,
        "{zones:?}"
    );
    let (three, msh3) = solid_zones(&dir, &two, 3);
    assert_eq!(three, zones);
    assert!(msh1 == msh3, "the .msh differs on 1 and 3 ranks");
    let text = String::from_utf8_lossy(&msh1);
    for name in ["left", "right"] {
        assert!(
            text.contains(&format!(
                "3 {} \"{name}\"",
                if name == "left" { 3 } else { 4 }
            )),
            "no volume {name}"
        );
    }
    let (open, _) = solid_zones(&dir, &halves, 1);
    let names: Vec<&str> = open.iter().map(|z| z.0.as_str()).collect();
    assert_eq!(names, ["inside", "outside"], "open halves are no solids");
    println!("zones per solid: {zones:?}; one solid: {whole:?}");
}
