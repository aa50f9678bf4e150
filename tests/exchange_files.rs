//! The Exodus II and CGNS files (`--exodus FILE.exo`, `--cgns FILE.cgns`)
//! of hanging-node meshes, judged by the formats' own libraries: the
//! netCDF library through Python's `netCDF4` (Debian `python3-netcdf4`),
//! and the CGNS library through `cgnscheck`, `cgnsdiff` (Debian
//! `cgns-convert`) and a small C reader compiled here against `cgnslib.h`
//! (Debian `libcgns-dev`). `scripts/setup.sh` installs them all.
//!
//! On the fluid sphere (every patch, hanging nodes) and the solid bunny,
//! meshed on 1 and 3 ranks:
//!
//! - Exodus: the node and element counts are octmesh's, the block is
//!   `volume` of HEX8 with positive volumes, the side sets and node sets
//!   are the patches (then `hanging`); each side set's faces, taken from
//!   the element and side number by the Exodus convention, are the Gmsh
//!   file's quadrilaterals of the patch, and on the sides of the box have
//!   their 4 nodes in the patch's node set and in its plane; coordinates and connectivity equal those of the Gmsh file of
//!   the same run; each hanging node is the weighted sum of its parents.
//! - CGNS: `cgnscheck` reports no error and no warning; the reader finds
//!   one unstructured zone with octmesh's counts, a HEXA_8 section and a
//!   QUAD_4 section per patch as large as the Exodus side set, a
//!   `FamilySpecified` boundary condition per patch at face centres over
//!   its section's range with a family of its name, and the hanging
//!   nodes' arrays; its coordinates and hexahedra are the Exodus file's.
//! - The Exodus file is byte-identical on 1 and 3 ranks; the CGNS files
//!   have the same content (`cgnsdiff -d` finds nothing, and finds a
//!   difference between two different meshes: the check can fail). HDF5
//!   stores modification times, so CGNS bytes differ.
//! - A patch name too long for CGNS fails the run on every rank (a file
//!   that cannot be written is `tests/fe_files.rs`'s, for all four
//!   single-file formats).

mod common;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;

use common::{json_file, octmesh_ok, require, scratch, shared_model, Oracle};

/// A Python with `netCDF4`, or `None` after a skip.
fn netcdf_python() -> Option<PathBuf> {
    require(Oracle::Python {
        module: "netCDF4",
        package: "python3-netcdf4",
    })
}

/// `cgnscheck`, or `None` after a skip.
fn cgnscheck() -> Option<PathBuf> {
    require(Oracle::Program {
        name: "cgnscheck",
        package: "cgns-convert",
    })
}

/// `cgnsdiff`, or `None` after a skip.
fn cgnsdiff() -> Option<PathBuf> {
    require(Oracle::Program {
        name: "cgnsdiff",
        package: "cgns-convert",
    })
}

/// The files of one run.
struct Run {
    exo: PathBuf,
    cgns: PathBuf,
    msh: PathBuf,
    stats: serde_json::Value,
}

/// Runs `octmesh mesh INPUT ARGS` on `np` ranks with the Exodus, CGNS and
/// Gmsh files in `dir`.
fn mesh(np: usize, dir: &Path, input: &str, args: &[&str]) -> Run {
    std::fs::create_dir_all(dir).unwrap();
    let (exo, cgns, msh, stats) = (
        dir.join("m.exo"),
        dir.join("m.cgns"),
        dir.join("m.msh"),
        dir.join("s.json"),
    );
    let mut all = vec!["mesh", input];
    all.extend(args);
    for (o, p) in [
        ("--exodus", &exo),
        ("--cgns", &cgns),
        ("--gmsh", &msh),
        ("--stats", &stats),
    ] {
        all.extend([o, p.to_str().unwrap()]);
    }
    all.push("--quiet");
    octmesh_ok(np, &all);
    let stats = json_file(&stats);
    Run {
        exo,
        cgns,
        msh,
        stats,
    }
}

/// Reads an Exodus file with netCDF4 and checks it against the Gmsh file
/// of the same run; prints `key values...` lines, and `coord`/`hex` lines
/// to compare with the CGNS reader's.
const EXODUS_READER: &str = r#"
import sys, netCDF4
exo, msh = sys.argv[1], sys.argv[2]
d = netCDF4.Dataset(exo)
d.set_auto_mask(False)
v = d.variables
def names(var):
    return [str(s) for s in netCDF4.chartostring(v[var][:])]
nn, ne = len(d.dimensions["num_nodes"]), len(d.dimensions["num_elem"])
print("counts", nn, ne, len(d.dimensions["num_el_blk"]))
print("attrs", d.file_size, d.floating_point_word_size, d.int64_status, d.maximum_name_length)
x, y, z = [list(map(float, v[c][:])) for c in ("coordx", "coordy", "coordz")]
conn = [[int(a) for a in row] for row in v["connect1"][:]]
print("block", names("eb_names")[0], v["connect1"].elem_type, int(v["eb_prop1"][0]), v["eb_prop1"].getncattr("name"))
# Signed volume at each corner of each hexahedron (triple product of its
# three edges): positive when the corner order is right-handed.
nbr = [(1, 3, 4), (2, 0, 5), (3, 1, 6), (0, 2, 7), (7, 5, 0), (4, 6, 1), (5, 7, 2), (6, 4, 3)]
worst = float("inf")
for e in conn:
    p = [(x[n - 1], y[n - 1], z[n - 1]) for n in e]
    for c, (a, b, u) in enumerate(nbr):
        ea = [p[a][i] - p[c][i] for i in range(3)]
        eb = [p[b][i] - p[c][i] for i in range(3)]
        eu = [p[u][i] - p[c][i] for i in range(3)]
        det = (ea[0] * (eb[1] * eu[2] - eb[2] * eu[1]) - ea[1] * (eb[0] * eu[2] - eb[2] * eu[0])
               + ea[2] * (eb[0] * eu[1] - eb[1] * eu[0]))
        worst = min(worst, det)
print("min_corner_volume", repr(worst))
# Node sets.
ns = {}
if "num_node_sets" in d.dimensions:
    for k, (name, i) in enumerate(zip(names("ns_names"), v["ns_prop1"][:])):
        ns[name] = set(int(a) for a in v["node_ns%d" % (k + 1)][:])
        print("nodeset", name, int(i), len(ns[name]))
# Side sets: the Exodus HEX8 sides, 1-based corners.
side = {1: (1, 2, 6, 5), 2: (2, 3, 7, 6), 3: (3, 4, 8, 7), 4: (1, 5, 8, 4), 5: (1, 4, 3, 2), 6: (5, 6, 7, 8)}
lo = [min(x), min(y), min(z)]
hi = [max(x), max(y), max(z)]
box = {"xmin": (0, lo[0]), "xmax": (0, hi[0]), "ymin": (1, lo[1]), "ymax": (1, hi[1]),
       "zmin": (2, lo[2]), "zmax": (2, hi[2])}
# The Gmsh file's quadrilaterals per physical surface, as node sets.
text = open(msh).read()
tags = {}
for l in text.split("$PhysicalNames\n")[1].split("$EndPhysicalNames")[0].split("\n")[1:]:
    f = l.split()
    if f and f[0] == "2":
        tags[int(f[1])] = f[2].strip('"')
quads = {}
lines = text.split("$Elements\n")[1].split("$EndElements")[0].split("\n")[1:]
at = 0
while at < len(lines) and lines[at].strip():
    dim, tag, typ, count = map(int, lines[at].split())
    if dim == 2:
        quads[tags[tag]] = sorted(tuple(sorted(map(int, l.split()[1:])))
                                  for l in lines[at + 1:at + 1 + count])
    at += 1 + count
if "num_side_sets" in d.dimensions:
    for k, (name, i) in enumerate(zip(names("ss_names"), v["ss_prop1"][:])):
        el = v["elem_ss%d" % (k + 1)][:]
        sd = v["side_ss%d" % (k + 1)][:]
        off, plane, faces = 0, 0.0, []
        for e, s in zip(el, sd):
            nodes = [conn[int(e) - 1][c - 1] for c in side[int(s)]]
            faces.append(tuple(sorted(nodes)))
            if name in box:
                off += sum(1 for n in nodes if n not in ns.get(name, ()))
                a, b = box[name]
                plane = max(plane, max(abs((x, y, z)[a][n - 1] - b) for n in nodes))
        print("sideset", name, int(i), len(el), off, repr(plane), int(sorted(faces) == quads.get(name)))
# Hanging nodes: position against the weighted parents.
if "hanging_nodes" in v:
    h = v["hanging_nodes"][:]
    par = v["hanging_parents"][:]
    w = v["hanging_weights"][:]
    err = 0.0
    for k, n in enumerate(h):
        for c in (x, y, z):
            s = sum(float(w[k][i]) * c[int(par[k][i]) - 1] for i in range(4) if par[k][i] > 0)
            err = max(err, abs(s - c[int(n) - 1]))
        err = max(err, abs(sum(float(a) for a in w[k]) - 1.0))
    print("hanging", len(h), repr(err), sorted(set(int((par[k] > 0).sum()) for k in range(len(h)))))
else:
    print("hanging", 0, 0.0, [])
# Against the Gmsh file: same nodes (exact) and hexahedra.
nodes = text.split("$Nodes\n")[1].split("$EndNodes")[0].split("\n")
m = int(nodes[0].split()[1])
coords = [list(map(float, l.split())) for l in nodes[2 + m:2 + 2 * m]]
bad = sum(1 for i, c in enumerate(coords) if c != [x[i], y[i], z[i]])
elems = text.split("$Elements\n")[1].split("\n")
ne_msh = int(elems[1].split()[3])
hexes = [list(map(int, l.split()[1:])) for l in elems[2:2 + ne_msh]]
print("gmsh", m, ne_msh, bad, sum(1 for a, b in zip(hexes, conn) if a != b))
for i in range(nn):
    print("coord %.17g %.17g %.17g" % (x[i], y[i], z[i]))
for e in conn:
    print("hex", *e)
"#;

/// Reads a CGNS file through the CGNS library: prints the zone, sections,
/// boundary conditions, user data arrays, then `coord`/`hex` lines.
const CGNS_READER: &str = r#"
#include <stdio.h>
#include <stdlib.h>
#include <cgnslib.h>
#define CG(call) do { if (call) { printf("error %s\n", cg_get_error()); return 1; } } while (0)
int main(int argc, char **argv) {
  int fn, nb, nz, ns, nbc, nu, na, phys, cell;
  char name[40], fam[40];
  CG(cg_open(argv[1], CG_MODE_READ, &fn));
  CG(cg_nbases(fn, &nb));
  CG(cg_base_read(fn, 1, name, &cell, &phys));
  CG(cg_nzones(fn, 1, &nz));
  printf("base %s %d %d %d %d\n", name, nb, cell, phys, nz);
  cgsize_t sz[3];
  ZoneType_t zt;
  CG(cg_zone_read(fn, 1, 1, name, sz));
  CG(cg_zone_type(fn, 1, 1, &zt));
  printf("zone %s %d %ld %ld\n", name, zt == Unstructured, (long)sz[0], (long)sz[1]);
  CG(cg_nsections(fn, 1, 1, &ns));
  for (int s = 1; s <= ns; s++) {
    ElementType_t t;
    cgsize_t a, b;
    int nbnd, parent;
    CG(cg_section_read(fn, 1, 1, s, name, &t, &a, &b, &nbnd, &parent));
    printf("section %s %s %ld %ld\n", name, t == HEXA_8 ? "HEXA_8" : t == QUAD_4 ? "QUAD_4" : "other",
           (long)a, (long)b);
  }
  CG(cg_nbocos(fn, 1, 1, &nbc));
  for (int k = 1; k <= nbc; k++) {
    BCType_t bt;
    PointSetType_t pt;
    cgsize_t np, nl, pts[2];
    int ni[3], nds;
    DataType_t dt;
    GridLocation_t loc;
    CG(cg_boco_info(fn, 1, 1, k, name, &bt, &pt, &np, ni, &nl, &dt, &nds));
    CG(cg_boco_gridlocation_read(fn, 1, 1, k, &loc));
    if (pt != PointRange || np != 2) { printf("bc %s not a range\n", name); continue; }
    CG(cg_boco_read(fn, 1, 1, k, pts, NULL));
    CG(cg_goto(fn, 1, "Zone_t", 1, "ZoneBC_t", 1, "BC_t", k, "end"));
    CG(cg_famname_read(fam));
    printf("bc %s %s %s %ld %ld %s\n", name, bt == FamilySpecified ? "FamilySpecified" : "other",
           loc == FaceCenter ? "FaceCenter" : "other", (long)pts[0], (long)pts[1], fam);
  }
  int nf;
  CG(cg_nfamilies(fn, 1, &nf));
  for (int k = 1; k <= nf; k++) {
    int nfbc, ngeo;
    BCType_t bt;
    CG(cg_family_read(fn, 1, k, name, &nfbc, &ngeo));
    if (nfbc == 1) {
      CG(cg_fambc_read(fn, 1, k, 1, fam, &bt));
      printf("family %s %s\n", name, bt == BCWall ? "BCWall" : bt == BCTypeUserDefined ? "UserDefined" : "other");
    }
  }
  CG(cg_goto(fn, 1, "Zone_t", 1, "end"));
  CG(cg_nuser_data(&nu));
  for (int u = 1; u <= nu; u++) {
    CG(cg_user_data_read(u, name));
    CG(cg_goto(fn, 1, "Zone_t", 1, "UserDefinedData_t", u, "end"));
    CG(cg_narrays(&na));
    printf("userdata %s %d\n", name, na);
    for (int i = 1; i <= na; i++) {
      DataType_t dt;
      int dd;
      cgsize_t dims[12];
      CG(cg_array_info(i, name, &dt, &dd, dims));
      printf("array %s %d %ld %ld\n", name, dd, (long)dims[0], dd > 1 ? (long)dims[1] : 0L);
    }
    CG(cg_goto(fn, 1, "Zone_t", 1, "end"));
  }
  cgsize_t one = 1, n = sz[0];
  double *c[3];
  const char *cn[3] = {"CoordinateX", "CoordinateY", "CoordinateZ"};
  for (int a = 0; a < 3; a++) {
    c[a] = malloc(sizeof(double) * (size_t)n);
    CG(cg_coord_read(fn, 1, 1, cn[a], RealDouble, &one, &n, c[a]));
  }
  for (cgsize_t i = 0; i < n; i++) printf("coord %.17g %.17g %.17g\n", c[0][i], c[1][i], c[2][i]);
  cgsize_t size;
  CG(cg_ElementDataSize(fn, 1, 1, 1, &size));
  cgsize_t *e = malloc(sizeof(cgsize_t) * (size_t)size);
  CG(cg_elements_read(fn, 1, 1, 1, e, NULL));
  for (cgsize_t k = 0; k < size; k += 8) {
    printf("hex");
    for (int j = 0; j < 8; j++) printf(" %ld", (long)e[k + j]);
    printf("\n");
  }
  CG(cg_close(fn));
  return 0;
}
"#;

/// The CGNS reader, compiled once per test into `dir`.
fn cgns_reader(dir: &Path) -> PathBuf {
    let (src, exe) = (dir.join("cgns_read.c"), dir.join("cgns_read"));
    std::fs::write(&src, CGNS_READER).unwrap();
    let out = Command::new("cc")
        .args([src.to_str().unwrap(), "-o", exe.to_str().unwrap(), "-lcgns"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "cannot compile the CGNS reader:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    exe
}

/// Runs `prog args`, panics unless it succeeds; its standard output.
fn run(prog: &Path, args: &[&Path]) -> String {
    let out = Command::new(prog).args(args).output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{} failed:\n{text}\n{}",
        prog.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    text
}

/// The lines of `text` starting with `key `, split into words after it.
fn rows<'a>(text: &'a str, key: &str) -> Vec<Vec<&'a str>> {
    text.lines()
        .filter_map(|l| l.strip_prefix(key).and_then(|r| r.strip_prefix(' ')))
        .map(|r| r.split_whitespace().collect())
        .collect()
}

/// The one row of `key`.
fn row<'a>(text: &'a str, key: &str) -> Vec<&'a str> {
    let r = rows(text, key);
    assert_eq!(
        r.len(),
        1,
        "one '{key}' line in:\n{}",
        &text[..text.len().min(3000)]
    );
    r.into_iter().next().unwrap()
}

/// The `coord` and `hex` lines of `text`.
fn geometry(text: &str) -> Vec<&str> {
    text.lines()
        .filter(|l| l.starts_with("coord ") || l.starts_with("hex "))
        .collect()
}

/// Checks the Exodus and CGNS files of `r` with the oracles; `patches` are
/// the patches expected in order. Returns the Exodus reading.
fn check_run(
    python: &Path,
    check: &Path,
    reader: &Path,
    name: &str,
    r: &Run,
    patches: &[&str],
) -> String {
    let s = &r.stats;
    let hanging = common::int(s, "face_hanging_nodes") + common::int(s, "edge_hanging_nodes");
    let nodes = common::int(s, "independent_nodes") + hanging;
    let elements = common::int(s, "elements");
    assert!(hanging > 0, "{name}: the test needs hanging nodes");
    // Exodus, through netCDF.
    let out = Command::new(python)
        .args([
            "-c",
            EXODUS_READER,
            r.exo.to_str().unwrap(),
            r.msh.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let exo = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{name}: netCDF4 could not read {}:\n{}",
        r.exo.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    let n = |w: &str| -> f64 { w.parse().unwrap() };
    assert_eq!(
        row(&exo, "counts"),
        [nodes.to_string(), elements.to_string(), "1".into()],
        "{name}: Exodus counts"
    );
    assert_eq!(
        row(&exo, "attrs"),
        ["1", "8", "0", "32"],
        "{name}: attributes"
    );
    assert_eq!(
        row(&exo, "block"),
        ["volume", "HEX8", "1", "ID"],
        "{name}: block"
    );
    let v = n(row(&exo, "min_corner_volume")[0]);
    assert!(v > 0.0, "{name}: a hexahedron corner of volume {v}");
    let sides = rows(&exo, "sideset");
    let side_names: Vec<&str> = sides.iter().map(|r| r[0]).collect();
    assert_eq!(side_names, patches, "{name}: side sets");
    let mut faces = BTreeMap::new();
    for r in &sides {
        assert_eq!(
            r[3], "0",
            "{name}: side set {}: face nodes off the patch",
            r[0]
        );
        assert_eq!(
            r[5], "1",
            "{name}: side set {}: not the Gmsh quadrilaterals",
            r[0]
        );
        assert!(
            n(r[4]) == 0.0,
            "{name}: side set {} off its plane by {}",
            r[0],
            r[4]
        );
        assert!(n(r[2]) > 0.0, "{name}: side set {} empty", r[0]);
        faces.insert(r[0].to_string(), r[2].parse::<u64>().unwrap());
    }
    let ids: Vec<&str> = sides.iter().map(|r| r[1]).collect();
    let sets: Vec<&str> = rows(&exo, "nodeset").iter().map(|r| r[0]).collect();
    let mut want: Vec<&str> = patches.to_vec();
    want.push("hanging");
    assert_eq!(sets, want, "{name}: node sets");
    let hang = row(&exo, "hanging");
    assert_eq!(hang[0], hanging.to_string(), "{name}: hanging nodes");
    assert!(
        n(hang[1]) <= 1e-12,
        "{name}: a hanging node off its parents' mean by {}",
        hang[1]
    );
    assert_eq!(
        row(&exo, "gmsh"),
        [
            nodes.to_string(),
            elements.to_string(),
            "0".into(),
            "0".into()
        ]
    );
    // CGNS, through cgnscheck and the CGNS library.
    let log = run(check, &[&r.cgns]);
    assert!(
        log.contains("checking complete") && !log.contains("ERROR") && !log.contains("WARNING"),
        "{name}: cgnscheck:\n{log}"
    );
    let cg = run(reader, &[&r.cgns]);
    assert_eq!(
        row(&cg, "base"),
        ["Base", "1", "3", "3", "1"],
        "{name}: base"
    );
    assert_eq!(
        row(&cg, "zone"),
        [
            "volume".to_string(),
            "1".into(),
            nodes.to_string(),
            elements.to_string()
        ],
        "{name}: zone"
    );
    let sections = rows(&cg, "section");
    assert_eq!(
        sections[0],
        [
            "volume".to_string(),
            "HEXA_8".into(),
            "1".into(),
            elements.to_string()
        ]
    );
    let bcs = rows(&cg, "bc");
    assert_eq!(bcs.len(), patches.len(), "{name}: boundary conditions");
    let mut next = elements + 1;
    for ((p, sec), bc) in patches.iter().zip(&sections[1..]).zip(&bcs) {
        let count = faces[*p];
        let range = [next.to_string(), (next + count - 1).to_string()];
        next += count;
        assert_eq!(sec[..2], [*p, "QUAD_4"], "{name}: section");
        assert_eq!(sec[2..], range, "{name}: section {p}");
        assert_eq!(
            bc[..3],
            [*p, "FamilySpecified", "FaceCenter"],
            "{name}: boundary condition"
        );
        assert_eq!(bc[3..5], range, "{name}: boundary condition {p}");
        assert_eq!(bc[5], *p, "{name}: family of {p}");
    }
    assert_eq!(sections.len(), patches.len() + 1);
    let families: BTreeMap<&str, &str> = rows(&cg, "family").iter().map(|r| (r[0], r[1])).collect();
    for p in patches {
        let want = match *p {
            "xmin" | "xmax" | "ymin" | "ymax" | "zmin" | "zmax" => "UserDefined",
            _ => "BCWall",
        };
        assert_eq!(families.get(p), Some(&want), "{name}: family {p}");
    }
    assert_eq!(row(&cg, "userdata"), ["HangingNodes", "3"]);
    let h = hanging.to_string();
    let arrays: BTreeSet<Vec<&str>> = rows(&cg, "array").into_iter().collect();
    let want: BTreeSet<Vec<&str>> = [
        vec!["Nodes", "1", h.as_str(), "0"],
        vec!["Parents", "2", "4", h.as_str()],
        vec!["Weights", "2", "4", h.as_str()],
    ]
    .into_iter()
    .collect();
    assert_eq!(arrays, want, "{name}: hanging node arrays");
    assert!(
        geometry(&cg) == geometry(&exo),
        "{name}: the CGNS coordinates or hexahedra differ from the Exodus file's"
    );
    println!(
        "{name}: {nodes} nodes ({hanging} hanging), {elements} hexahedra, side sets {:?} \
         (IDs {ids:?}); cgnscheck clean",
        faces
    );
    exo
}

/// The full check of `input` meshed with `args` on 1 and 3 ranks, and the
/// same content on both.
fn exchange(name: &str, input: &str, args: &[&str], patches: &[&str]) {
    let (Some(python), Some(check), Some(diff)) = (netcdf_python(), cgnscheck(), cgnsdiff()) else {
        return;
    };
    let dir = scratch(&format!("exchange_{name}"));
    let reader = cgns_reader(&dir);
    let one = mesh(1, &dir.join("np1"), input, args);
    let three = mesh(3, &dir.join("np3"), input, args);
    let a = check_run(&python, &check, &reader, name, &one, patches);
    let b = check_run(
        &python,
        &check,
        &reader,
        &format!("{name} (3 ranks)"),
        &three,
        patches,
    );
    assert!(
        a == b,
        "{name}: the Exodus readings differ on 1 and 3 ranks"
    );
    assert!(
        std::fs::read(&one.exo).unwrap() == std::fs::read(&three.exo).unwrap(),
        "{name}: the Exodus file differs on 1 and 3 ranks"
    );
    let same = run(&diff, &[Path::new("-d"), &one.cgns, &three.cgns]);
    assert!(same.trim().is_empty(), "{name}: cgnsdiff -d:\n{same}");
    // The comparison sees a difference where there is one: the same input
    // one level coarser.
    let mut coarse: Vec<String> = args.iter().map(|s| s.to_string()).collect();
    let at = coarse.iter().position(|a| a == "--level").unwrap() + 1;
    coarse[at] = (coarse[at].parse::<u32>().unwrap() - 1).to_string();
    let coarse: Vec<&str> = coarse.iter().map(String::as_str).collect();
    let other = mesh(1, &dir.join("coarse"), input, &coarse);
    let out = Command::new(&diff)
        .args([Path::new("-d"), &one.cgns, &other.cgns])
        .output()
        .unwrap();
    assert!(
        !String::from_utf8_lossy(&out.stdout).trim().is_empty(),
        "{name}: cgnsdiff -d sees no difference between levels"
    );
}

#[test]
fn fluid_sphere_on_1_and_3_ranks() {
    let all = ["xmin", "xmax", "ymin", "ymax", "zmin", "zmax", "sphere"];
    exchange(
        "sphere_fluid",
        "sphere",
        &["--level", "4", "--keep", "outside"],
        &all,
    );
}

#[test]
fn solid_bunny_on_1_and_3_ranks() {
    let Some(bunny) = shared_model("bunny.stl") else {
        return;
    };
    exchange(
        "bunny_solid",
        bunny.to_str().unwrap(),
        &["--level", "5", "--keep", "inside"],
        &["bunny"],
    );
}

/// A patch name too long for CGNS (over 32 characters) stops the run on
/// every rank with a message that says how to rename it.
#[test]
fn a_long_patch_name_fails_cgns_on_every_rank() {
    let dir = scratch("exchange_long_name");
    let path = dir.join("m.cgns");
    let rename = format!("sphere={}", "w".repeat(33));
    let args = [
        "mesh",
        "sphere",
        "--level",
        "3",
        "--keep",
        "inside",
        "--patch",
        &rename,
        "--cgns",
        path.to_str().unwrap(),
    ];
    let out = common::mpirun(
        2,
        &common::octmesh_bin(),
        &args,
        std::time::Duration::from_secs(300),
    );
    for line in common::rank_error_lines(&out, 2, "--cgns") {
        assert!(line.contains("--patch") && line.contains("32"), "{line}");
    }
}

/// A mesh with zones (the sphere in its box, `--keep all --zones`, and a
/// region's zone `east`) on 1 and 3 ranks: the Exodus file has an element
/// block per zone, named after it with ID `zone index + 1`, holding the
/// zone's element count from the statistics, elements numbered block
/// after block, and the box sides' side sets name faces in their planes
/// (read through those numbers); the CGNS file passes cgnscheck with a
/// section, a family and a sub-region per zone; both files are the same on
/// 1 and 3 ranks.
#[test]
fn zones_become_blocks_and_families() {
    let (Some(python), Some(check), Some(diff)) = (netcdf_python(), cgnscheck(), cgnsdiff()) else {
        return;
    };
    let args = [
        "--level",
        "4",
        "--keep",
        "all",
        "--zones",
        "--region",
        "box:0.5,0.5,0.5,1.5,1.5,1.5:0:zone=east",
    ];
    let dir = scratch("exchange_files_zones");
    let runs: Vec<Run> = [1, 3]
        .iter()
        .map(|&np| mesh(np, &dir.join(format!("np{np}")), "sphere", &args))
        .collect();
    let script = r#"
import sys, netCDF4
d = netCDF4.Dataset(sys.argv[1])
v = d.variables
names = [str(s) for s in netCDF4.chartostring(v["eb_names"][:])]
for b, (name, i) in enumerate(zip(names, v["eb_prop1"][:])):
    print("block", name, int(i), len(d.dimensions["num_el_in_blk%d" % (b + 1)]), v["connect%d" % (b + 1)].elem_type)
print("elements", len(d.dimensions["num_elem"]))
# The side sets name faces by global element number (block after block):
# every face of the box sides' sets lies in its side's plane.
conn = []
for b in range(len(names)):
    conn.extend([list(map(int, r)) for r in v["connect%d" % (b + 1)][:]])
x = [v[c][:] for c in ("coordx", "coordy", "coordz")]
side = {1: (1, 2, 6, 5), 2: (2, 3, 7, 6), 3: (3, 4, 8, 7), 4: (1, 5, 8, 4), 5: (1, 4, 3, 2), 6: (5, 6, 7, 8)}
for k, name in enumerate(str(s) for s in netCDF4.chartostring(v["ss_names"][:])):
    axis, high = "xyz".index(name[0]), name.endswith("max")
    plane = (max if high else min)(x[axis])
    off = 0
    for e, sd in zip(v["elem_ss%d" % (k + 1)][:], v["side_ss%d" % (k + 1)][:]):
        for c in side[int(sd)]:
            off += abs(x[axis][conn[int(e) - 1][c - 1] - 1] - plane) > 1e-12
    print("sideset", name, len(v["elem_ss%d" % (k + 1)][:]), off)
"#;
    let out = Command::new(&python)
        .args(["-c", script, runs[0].exo.to_str().unwrap()])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let zones = runs[0].stats["zones"]
        .as_array()
        .expect("zones in the statistics");
    let want: Vec<String> = zones
        .iter()
        .enumerate()
        .filter(|(_, z)| z["elements"].as_u64().unwrap() > 0)
        .map(|(k, z)| {
            format!(
                "{} {} {} HEX8",
                z["name"].as_str().unwrap(),
                k + 1,
                z["elements"].as_u64().unwrap()
            )
        })
        .collect();
    let got: Vec<String> = rows(&text, "block").iter().map(|r| r.join(" ")).collect();
    assert_eq!(got, want, "the Exodus blocks");
    assert!(got.iter().any(|b| b.starts_with("east ")), "{got:?}");
    assert_eq!(
        row(&text, "elements")[0].parse::<u64>().unwrap(),
        common::int(&runs[0].stats, "elements")
    );
    let sides = rows(&text, "sideset");
    assert_eq!(sides.len(), 6, "{text}");
    for r in &sides {
        assert!(
            r[1] != "0" && r[2] == "0",
            "side set {}: {} faces, {} corners off its plane",
            r[0],
            r[1],
            r[2]
        );
    }
    let report = run(&check, &[&runs[0].cgns]);
    for z in zones.iter().filter(|z| z["elements"].as_u64().unwrap() > 0) {
        let name = z["name"].as_str().unwrap();
        assert!(
            report.contains(&format!("subregion \"{name}_region\"")),
            "cgnscheck saw no region {name}:\n{report}"
        );
    }
    assert!(
        !report.contains("ERROR") && !report.contains("WARNING"),
        "{report}"
    );
    assert!(
        std::fs::read(&runs[0].exo).unwrap() == std::fs::read(&runs[1].exo).unwrap(),
        "the Exodus file differs on 1 and 3 ranks"
    );
    let d = run(&diff, &[Path::new("-d"), &runs[0].cgns, &runs[1].cgns]);
    assert!(d.trim().is_empty(), "the CGNS files differ:\n{d}");
}
