//! The leak check for fluid meshes (`octmesh::internals::leak`, `--inside-point`).
//!
//! Run by `cargo test` (through `tests/common/runner.rs`), this program
//! launches itself under `mpirun` on 1, 2 and 3 ranks to run the Rust API in
//! parallel (a closed sphere, a sphere with a cap cut away, a maze of cut
//! cells on a uniform grid), and checks the results here, on one process,
//! with geometry written for the test: the path starts on the domain
//! boundary and ends at the point, consecutive octants share a face, no
//! octant meets a triangle (triangles clipped against the boxes), and the
//! path crosses the full sphere only through the removed cap. It also runs
//! the `octmesh` command on the open and closed Stanford bunny and on the
//! holed sphere (exit status, the message on every rank, the path files).
//!
//! Usage: `cargo test --release --test leak [NAME_FILTER]`.

mod common;

use std::collections::{BTreeMap, VecDeque};
use std::hash::{Hash, Hasher};
use std::path::Path;
use std::rc::Rc;
use std::sync::OnceLock;
use std::time::Duration;

use octmesh::internals::classify::{classify_leaves, CUT};
use octmesh::internals::geometry::{load_surface, shapes, Surface, Triangle};
use octmesh::internals::leak::find_leak;
use octmesh::internals::octree::domain::{Domain, DEFAULT_FIT};
use octmesh::internals::octree::octant::ROOT_LEN;
use octmesh::internals::octree::LinearOctree;
use octmesh::internals::parallel::comm::{CommRef, MpiComm};
use octmesh::internals::refine::{build_from_surface, SurfaceIndex, NO_LIMIT};
use octmesh::{Connectivity, Octant, Result};

use common::*;

/// Triangles of the unit icosphere whose centroid has `z` above this are
/// removed: a cap of about 9 degrees, a hole about 0.31 across.
const CAP_Z: f64 = 0.9877;
/// Leaves at this level (side 2.857 / 2^6 = 0.045) are much smaller than
/// the hole: it leaks.
const FINE: u8 = 6;
/// Leaves at this level (side 0.357) are wider than the hole: no leak.
const COARSE: u8 = 3;
/// Ranks the parallel runs use.
const RANKS: [usize; 3] = [1, 2, 3];

fn main() {
    common::runner::main("leak", child, |r| {
        let tests: &[(&str, fn())] = &[
            ("closed_sphere_has_no_leak", closed_sphere_has_no_leak),
            (
                "holed_sphere_leaks_through_the_hole",
                holed_sphere_leaks_through_the_hole,
            ),
            (
                "holed_sphere_is_sealed_at_a_coarse_level",
                holed_sphere_is_sealed_at_a_coarse_level,
            ),
            (
                "maze_path_is_shortest_on_any_rank_count",
                maze_path_is_shortest_on_any_rank_count,
            ),
            (
                "bunny_open_leaks_and_bunny_does_not",
                bunny_open_leaks_and_bunny_does_not,
            ),
            (
                "cli_reports_a_leak_on_every_rank",
                cli_reports_a_leak_on_every_rank,
            ),
            (
                "cli_passes_on_a_closed_surface",
                cli_passes_on_a_closed_surface,
            ),
            (
                "cli_rejects_a_point_on_the_surface",
                cli_rejects_a_point_on_the_surface,
            ),
        ];
        for (name, f) in tests {
            r.test(name, *f);
        }
    });
}

// ---------------------------------------------------------------------------
// Shapes

/// The default icosphere (radius 1 at the origin, 20,480 triangles).
fn full_sphere() -> Surface {
    shapes::default_sphere()
}

/// Whether a sphere triangle belongs to the removed cap.
fn in_cap(t: &Triangle) -> bool {
    t.centroid()[2] > CAP_Z
}

/// The icosphere without its cap around +z.
fn holed_sphere() -> Surface {
    let kept: Vec<Triangle> = full_sphere()
        .triangles()
        .iter()
        .filter(|t| !in_cap(t))
        .copied()
        .collect();
    Surface::new(kept).expect("holed sphere")
}

/// The default cube around a surface (what the command uses).
fn domain_of(s: &Surface) -> Domain {
    let b = s.bbox();
    Domain::around(b.min, b.max, DEFAULT_FIT).expect("domain")
}

/// The maze on the uniform level-4 grid (16 cells per side): a closed shell
/// of cut cells at 1 and 14 with an opening at the top, and floors at
/// z = 11, 8, 5 with openings in alternate corners, so the way in snakes
/// down through the ranks' Morton ranges.
fn maze_cut(c: [u32; 3]) -> bool {
    let [x, y, z] = c;
    let inner = |v: u32| (1..=14).contains(&v);
    if !(inner(x) && inner(y) && inner(z)) {
        return false;
    }
    let shell = [x, y, z].iter().any(|&v| v == 1 || v == 14);
    if shell {
        return !(z == 14 && x == 2 && y == 2);
    }
    match z {
        11 | 5 => !(x == 13 && y == 13),
        8 => !(x == 2 && y == 2),
        _ => false,
    }
}

/// The cell of the maze's inside point.
const MAZE_POINT: [u32; 3] = [7, 7, 3];

// ---------------------------------------------------------------------------
// The MPI side

/// What a parallel run found, as text: `none`, `error KIND`, or
/// `path KEY KEY ...` (boundary first).
fn describe(r: &Result<Option<octmesh::internals::leak::LeakPath>>) -> String {
    match r {
        Ok(None) => "none".into(),
        Ok(Some(p)) => {
            let keys: Vec<String> = p.octants().iter().map(|o| o.key().to_string()).collect();
            format!("path {}", keys.join(" "))
        }
        Err(e) => format!("error {:?}", e.kind()),
    }
}

fn surface_run(
    comm: &CommRef,
    s: &Surface,
    level: u8,
    point: [f64; 3],
) -> Result<Option<octmesh::internals::leak::LeakPath>> {
    let domain = domain_of(s);
    let index = SurfaceIndex::new(s, &domain);
    let mut tree = build_from_surface(comm.clone(), &index, level, NO_LIMIT)?;
    tree.partition()?;
    tree.balance(Connectivity::Corner)?;
    tree.partition()?;
    let classes = classify_leaves(tree.leaves(), &index);
    find_leak(&tree, &classes, &domain, point)
}

/// The maze's result and the number of ranks owning leaves of its path.
fn maze_run(comm: &CommRef) -> (Result<Option<octmesh::internals::leak::LeakPath>>, usize) {
    let tree = LinearOctree::new_uniform(comm.clone(), 4).expect("uniform tree");
    let classes: Vec<u8> = tree
        .leaves()
        .iter()
        .map(|o| if maze_cut(cell_of(*o)) { CUT } else { 0 })
        .collect();
    let domain = Domain::cube([0.0; 3], 16.0).expect("domain");
    let p = MAZE_POINT.map(|v| v as f64 + 0.5);
    let r = find_leak(&tree, &classes, &domain, p);
    let mut owners: Vec<usize> = match &r {
        Ok(Some(path)) => path
            .octants()
            .iter()
            .map(|o| tree.owner_of_cell(o.cell_begin()))
            .collect(),
        _ => Vec::new(),
    };
    owners.sort_unstable();
    owners.dedup();
    (r, owners.len())
}

/// Grid cell of a level-4 octant.
fn cell_of(o: Octant) -> [u32; 3] {
    o.coords().map(|v| v >> 15)
}

/// One launched copy: every rank computes each case; rank 0 prints the
/// results after checking that every rank has the same.
fn child(which: &str) {
    let universe = mpi::initialize().expect("MPI");
    let comm: CommRef = Rc::new(MpiComm::new(universe.world()));
    let mut results: Vec<(&str, String)> = Vec::new();
    match which {
        "sphere" => {
            let full = full_sphere();
            let holed = holed_sphere();
            let cases: [(&str, &Surface, u8, [f64; 3]); 4] = [
                ("closed_centre", &full, 7, [0.0; 3]),
                ("closed_off_centre", &full, 7, [0.3, -0.2, 0.5]),
                ("holed_fine", &holed, FINE, [0.0; 3]),
                ("holed_coarse", &holed, COARSE, [0.0; 3]),
            ];
            for (name, s, level, point) in cases {
                results.push((name, describe(&surface_run(&comm, s, level, point))));
            }
        }
        "maze" => {
            let (r, owners) = maze_run(&comm);
            results.push(("maze", describe(&r)));
            if comm.rank() == 0 {
                println!("OWNERS maze {owners}");
            }
        }
        other => panic!("unknown child case {other}"),
    }
    for (name, text) in &results {
        let mut h = std::collections::hash_map::DefaultHasher::new();
        text.hash(&mut h);
        let all = comm.allgather_u64(h.finish());
        if comm.rank() == 0 {
            let agree = all.iter().all(|&x| x == all[0]);
            println!("RESULT {name} {text}");
            println!("RANKS {name} {}", if agree { "agree" } else { "DIFFER" });
        }
    }
    drop(comm);
    drop(universe);
}

/// Runs the child case on `np` ranks; returns name -> result, after
/// checking that all ranks agreed.
fn launch(which: &str, np: usize) -> BTreeMap<String, String> {
    launch_text(which, np).0
}

/// [`launch`], also returning the whole output.
fn launch_text(which: &str, np: usize) -> (BTreeMap<String, String>, String) {
    let text = common::runner::launch(np, which, Duration::from_secs(600));
    let mut m = BTreeMap::new();
    for l in text.lines() {
        if let Some(rest) = l.strip_prefix("RESULT ") {
            let (name, r) = rest.split_once(' ').expect("RESULT name text");
            m.insert(name.to_string(), r.to_string());
        }
        if let Some(rest) = l.strip_prefix("RANKS ") {
            assert!(
                rest.ends_with(" agree"),
                "{which} on {np} ranks: ranks differ: {rest}"
            );
        }
    }
    assert!(
        !m.is_empty(),
        "{which} on {np} ranks printed nothing:\n{text}"
    );
    (m, text)
}

/// The sphere cases on 1, 2 and 3 ranks (run once, shared by the tests).
fn sphere_runs() -> &'static Vec<BTreeMap<String, String>> {
    static RUNS: OnceLock<Vec<BTreeMap<String, String>>> = OnceLock::new();
    RUNS.get_or_init(|| RANKS.iter().map(|&np| launch("sphere", np)).collect())
}

/// Parses `path KEY ...`.
fn path_of(text: &str) -> Vec<Octant> {
    let rest = text
        .strip_prefix("path ")
        .unwrap_or_else(|| panic!("expected a path, got '{text}'"));
    rest.split(' ')
        .map(|k| Octant::from_key(k.parse().expect("key")))
        .collect()
}

/// The same result for every rank count; returns it.
fn same_on_all_rank_counts(runs: &[BTreeMap<String, String>], case: &str) -> String {
    let first = &runs[0][case];
    for (r, np) in runs.iter().zip(RANKS) {
        assert_eq!(&r[case], first, "{case}: {np} ranks differ from 1 rank");
    }
    first.clone()
}

// ---------------------------------------------------------------------------
// Independent geometry

/// Closed box of an octant in user units.
fn user_box(d: &Domain, o: Octant) -> ([f64; 3], [f64; 3]) {
    let h = d.side / ROOT_LEN as f64;
    let c = o.coords();
    let lo = std::array::from_fn(|k| d.origin[k] + c[k] as f64 * h);
    let hi = std::array::from_fn(|k| d.origin[k] + (c[k] + o.side()) as f64 * h);
    (lo, hi)
}

/// Whether a triangle meets a closed box: the triangle is clipped against
/// the six planes of the box (Sutherland-Hodgman); something is left iff
/// they meet.
fn triangle_meets_box(t: &[[f64; 3]; 3], lo: [f64; 3], hi: [f64; 3]) -> bool {
    let mut poly: Vec<[f64; 3]> = t.to_vec();
    for k in 0..3 {
        for (bound, keep_below) in [(lo[k], false), (hi[k], true)] {
            let inside = |p: &[f64; 3]| {
                if keep_below {
                    p[k] <= bound
                } else {
                    p[k] >= bound
                }
            };
            let mut out = Vec::with_capacity(poly.len() + 2);
            for i in 0..poly.len() {
                let a = poly[i];
                let b = poly[(i + 1) % poly.len()];
                match (inside(&a), inside(&b)) {
                    (true, true) => out.push(b),
                    (true, false) | (false, true) => {
                        let t = (bound - a[k]) / (b[k] - a[k]);
                        let mut x: [f64; 3] = std::array::from_fn(|j| a[j] + t * (b[j] - a[j]));
                        x[k] = bound;
                        out.push(x);
                        if !inside(&a) {
                            out.push(b);
                        }
                    }
                    (false, false) => {}
                }
            }
            poly = out;
            if poly.is_empty() {
                return false;
            }
        }
    }
    true
}

/// Whether the open segment `p q` crosses triangle `t` (Moller-Trumbore).
fn segment_crosses(p: [f64; 3], q: [f64; 3], t: &[[f64; 3]; 3]) -> bool {
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let d = sub(q, p);
    let e1 = sub(t[1], t[0]);
    let e2 = sub(t[2], t[0]);
    let h = cross(d, e2);
    let a = dot(e1, h);
    if a == 0.0 {
        return false;
    }
    let s = sub(p, t[0]);
    let u = dot(s, h) / a;
    let qv = cross(s, e1);
    let v = dot(d, qv) / a;
    let w = dot(e2, qv) / a;
    u >= 0.0 && v >= 0.0 && u + v <= 1.0 && w > 0.0 && w < 1.0
}

/// Whether two closed boxes share a face patch of positive area.
fn share_face(a: ([f64; 3], [f64; 3]), b: ([f64; 3], [f64; 3])) -> bool {
    let mut touching = 0;
    let mut overlapping = 0;
    for k in 0..3 {
        let lo = a.0[k].max(b.0[k]);
        let hi = a.1[k].min(b.1[k]);
        if hi > lo {
            overlapping += 1;
        } else if hi == lo {
            touching += 1;
        }
    }
    overlapping == 2 && touching == 1
}

fn on_domain_boundary(d: &Domain, b: ([f64; 3], [f64; 3])) -> bool {
    (0..3).any(|k| b.0[k] == d.origin[k] || b.1[k] == d.origin[k] + d.side)
}

fn contains(b: ([f64; 3], [f64; 3]), p: [f64; 3]) -> bool {
    (0..3).all(|k| b.0[k] <= p[k] && p[k] <= b.1[k])
}

/// The checks every reported path must pass, against the surface's
/// triangles (user units).
fn assert_valid_path(
    d: &Domain,
    boxes: &[([f64; 3], [f64; 3])],
    tris: &[Triangle],
    point: [f64; 3],
) {
    assert!(!boxes.is_empty());
    assert!(
        on_domain_boundary(d, boxes[0]),
        "the path starts at {:?}, not on the domain boundary",
        boxes[0]
    );
    assert!(
        contains(*boxes.last().unwrap(), point),
        "the path ends at {:?}, which does not hold the point {point:?}",
        boxes.last()
    );
    for w in boxes.windows(2) {
        assert!(
            share_face(w[0], w[1]),
            "{:?} and {:?} share no face",
            w[0],
            w[1]
        );
    }
    for b in boxes {
        for t in tris {
            let tb = t.aabb();
            if (0..3).any(|k| tb.max[k] < b.0[k] || tb.min[k] > b.1[k]) {
                continue;
            }
            assert!(
                !triangle_meets_box(&t.v, b.0, b.1),
                "path box {b:?} meets triangle {:?}",
                t.v
            );
        }
    }
}

// ---------------------------------------------------------------------------
// Tests: the Rust API in parallel

fn closed_sphere_has_no_leak() {
    let runs = sphere_runs();
    for case in ["closed_centre", "closed_off_centre"] {
        for (r, np) in runs.iter().zip(RANKS) {
            assert_eq!(r[case], "none", "{case} on {np} ranks");
        }
    }
}

fn holed_sphere_leaks_through_the_hole() {
    let hole = 2.0 * (1.0 - CAP_Z * CAP_Z).sqrt();
    let d = domain_of(&holed_sphere());
    let leaf = d.side / (1u32 << FINE) as f64;
    assert!(4.0 * leaf < hole, "level {FINE}: leaf {leaf}, hole {hole}");
    let runs = sphere_runs();
    let text = same_on_all_rank_counts(runs, "holed_fine");
    let path = path_of(&text);
    let holed = holed_sphere();
    let d = domain_of(&holed);
    let boxes: Vec<_> = path.iter().map(|&o| user_box(&d, o)).collect();
    assert_valid_path(&d, &boxes, holed.triangles(), [0.0; 3]);
    // Along the polyline through the centres (each segment lies in two
    // boxes that touch no kept triangle) the full sphere is crossed an odd
    // number of times (outside to the centre), and only through the cap.
    let full = full_sphere();
    let centres: Vec<[f64; 3]> = boxes
        .iter()
        .map(|b| std::array::from_fn(|k| 0.5 * (b.0[k] + b.1[k])))
        .collect();
    let (mut cap, mut kept) = (0, 0);
    for w in centres.windows(2) {
        for t in full.triangles() {
            if segment_crosses(w[0], w[1], &t.v) {
                if in_cap(t) {
                    cap += 1;
                } else {
                    kept += 1;
                }
            }
        }
    }
    assert_eq!(kept, 0, "the path crosses kept triangles");
    assert_eq!(cap % 2, 1, "the path crosses the cap {cap} times");
    // And the path's leaves near the unit sphere are in the hole's cone.
    let hole_boxes = boxes
        .iter()
        .zip(&centres)
        .filter(|(_, c)| {
            let r = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
            (r - 1.0).abs() < 0.05 && c[2] / r > 0.97
        })
        .count();
    assert!(hole_boxes > 0, "no path octant in the hole's cap region");
    println!(
        "holed sphere, level {FINE}: leak path of {} octants, crossing the cap {cap} time(s)",
        path.len()
    );
}

fn holed_sphere_is_sealed_at_a_coarse_level() {
    // The hole is narrower than the leaves at this level.
    let hole = 2.0 * (1.0 - CAP_Z * CAP_Z).sqrt();
    let d = domain_of(&holed_sphere());
    let leaf = d.side / (1u32 << COARSE) as f64;
    assert!(
        leaf > hole,
        "level {COARSE}: leaf {leaf} is not wider than the hole {hole}"
    );
    for (r, np) in sphere_runs().iter().zip(RANKS) {
        assert_eq!(
            r["holed_coarse"], "none",
            "holed sphere at level {COARSE}, {np} ranks"
        );
    }
}

/// Hop distances on the maze grid by a plain breadth-first search.
fn maze_distance() -> u32 {
    const N: usize = 16;
    let idx = |c: [usize; 3]| c[0] + N * (c[1] + N * c[2]);
    let mut dist = vec![u32::MAX; N * N * N];
    let mut q = VecDeque::new();
    for z in 0..N {
        for y in 0..N {
            for x in 0..N {
                let c = [x, y, z];
                let open = !maze_cut(c.map(|v| v as u32));
                if open && c.iter().any(|&v| v == 0 || v == N - 1) {
                    dist[idx(c)] = 0;
                    q.push_back(c);
                }
            }
        }
    }
    while let Some(c) = q.pop_front() {
        for k in 0..3 {
            for s in [-1i64, 1] {
                let v = c[k] as i64 + s;
                if !(0..N as i64).contains(&v) {
                    continue;
                }
                let mut n = c;
                n[k] = v as usize;
                if !maze_cut(n.map(|v| v as u32)) && dist[idx(n)] == u32::MAX {
                    dist[idx(n)] = dist[idx(c)] + 1;
                    q.push_back(n);
                }
            }
        }
    }
    dist[idx(MAZE_POINT.map(|v| v as usize))]
}

fn maze_path_is_shortest_on_any_rank_count() {
    let mut runs = Vec::new();
    for np in RANKS {
        let (m, out) = launch_text("maze", np);
        // On several ranks the path runs through several ranks' leaves, so
        // the distances and the walk crossed rank boundaries.
        let owners: usize = out
            .lines()
            .find_map(|l| l.strip_prefix("OWNERS maze "))
            .expect("OWNERS line")
            .parse()
            .expect("a count");
        assert!(owners == 1 || np > 1);
        if np > 1 {
            assert!(owners > 1, "the maze path stays on one of {np} ranks");
        }
        runs.push(m);
    }
    let text = same_on_all_rank_counts(&runs, "maze");
    let path = path_of(&text);
    let want = maze_distance();
    assert!(
        want > 40 && want < u32::MAX,
        "the maze is not a maze: {want}"
    );
    assert_eq!(path.len() as u32, want + 1, "not a shortest path");
    let cells: Vec<[u32; 3]> = path.iter().map(|&o| cell_of(o)).collect();
    assert!(cells[0].iter().any(|&v| v == 0 || v == 15));
    assert_eq!(*cells.last().unwrap(), MAZE_POINT);
    for w in cells.windows(2) {
        let steps: u32 = (0..3).map(|k| w[0][k].abs_diff(w[1][k])).sum();
        assert_eq!(steps, 1, "{w:?}");
    }
    assert!(cells.iter().all(|&c| !maze_cut(c)));
}

// ---------------------------------------------------------------------------
// Tests: the command

/// Runs octmesh under mpirun without asserting success.
fn octmesh_run(np: usize, args: &[&str]) -> std::process::Output {
    mpirun(np, &octmesh_bin(), args, Duration::from_secs(600))
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// Reads a CSV path file: centres and sizes.
fn read_csv(path: &Path) -> Vec<([f64; 3], f64)> {
    let t = std::fs::read_to_string(path).expect("read csv");
    let mut lines = t.lines();
    assert_eq!(lines.next(), Some("step,x,y,z,size,level"));
    lines
        .enumerate()
        .map(|(i, l)| {
            let f: Vec<&str> = l.split(',').collect();
            assert_eq!(f.len(), 6, "{l}");
            assert_eq!(f[0].parse::<usize>().unwrap(), i);
            let v: Vec<f64> = f[1..5].iter().map(|s| s.parse().expect("number")).collect();
            ([v[0], v[1], v[2]], v[3])
        })
        .collect()
}

/// Reads a legacy VTK path written by octmesh: centres and sizes,
/// checking the structure (line cells joining the points in order).
fn read_vtk(path: &Path) -> Vec<([f64; 3], f64)> {
    let t = std::fs::read_to_string(path).expect("read vtk");
    assert!(t.starts_with("# vtk DataFile Version"));
    assert!(t.contains("\nDATASET UNSTRUCTURED_GRID\n"));
    let mut w = t.split_whitespace();
    let pos = |w: &mut std::str::SplitWhitespace, s: &str| {
        assert!(w.any(|tok| tok == s), "no {s} in the VTK file");
    };
    let num = |w: &mut std::str::SplitWhitespace| -> usize {
        w.next().expect("a number").parse().expect("an integer")
    };
    pos(&mut w, "POINTS");
    let n = num(&mut w);
    assert_eq!(w.next(), Some("double"));
    let pts: Vec<[f64; 3]> = (0..n)
        .map(|_| std::array::from_fn(|_| w.next().unwrap().parse::<f64>().unwrap()))
        .collect();
    assert!(n >= 2, "a path of {n} points");
    assert_eq!(w.next(), Some("CELLS"));
    assert_eq!(num(&mut w), n - 1);
    assert_eq!(num(&mut w), 3 * (n - 1));
    for i in 1..n {
        assert_eq!([num(&mut w), num(&mut w), num(&mut w)], [2, i - 1, i]);
    }
    assert_eq!(w.next(), Some("CELL_TYPES"));
    assert_eq!(num(&mut w), n - 1);
    for _ in 1..n {
        assert_eq!(num(&mut w), 3, "VTK_LINE");
    }
    pos(&mut w, "POINT_DATA");
    assert_eq!(num(&mut w), n);
    pos(&mut w, "size");
    assert_eq!(w.next(), Some("double"));
    pos(&mut w, "default");
    let sizes: Vec<f64> = (0..n).map(|_| w.next().unwrap().parse().unwrap()).collect();
    pts.into_iter().zip(sizes).collect()
}

/// Boxes from centres and sizes.
fn boxes_of(rows: &[([f64; 3], f64)]) -> Vec<([f64; 3], [f64; 3])> {
    rows.iter()
        .map(|(c, s)| {
            (
                std::array::from_fn(|k| c[k] - 0.5 * s),
                std::array::from_fn(|k| c[k] + 0.5 * s),
            )
        })
        .collect()
}

/// A file's boxes are valid within rounding: boxes recomputed from printed
/// centres are not exact, so faces are compared with a tolerance by
/// snapping them to the domain's lattice.
fn snap(d: &Domain, rows: &[([f64; 3], f64)]) -> Vec<([f64; 3], [f64; 3])> {
    let h = d.side / ROOT_LEN as f64;
    boxes_of(rows)
        .into_iter()
        .map(|(lo, hi)| {
            let s = |v: f64, k: usize| d.origin[k] + ((v - d.origin[k]) / h).round() * h;
            (
                std::array::from_fn(|k| s(lo[k], k)),
                std::array::from_fn(|k| s(hi[k], k)),
            )
        })
        .collect()
}

/// The volume centroid of a closed surface (divergence theorem).
fn centroid(s: &Surface) -> [f64; 3] {
    let mut v = 0.0;
    let mut m = [0.0; 3];
    for t in s.triangles() {
        let [a, b, c] = t.v;
        let det = a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
            + a[2] * (b[0] * c[1] - b[1] * c[0]);
        v += det / 6.0;
        for k in 0..3 {
            m[k] += det / 24.0 * (a[k] + b[k] + c[k]);
        }
    }
    m.map(|x| x / v)
}

/// Crossings of the ray from `p` in direction `dir` with the surface.
fn ray_crossings(s: &Surface, p: [f64; 3], dir: [f64; 3]) -> usize {
    let far = std::array::from_fn(|k| p[k] + 10.0 * dir[k]);
    s.triangles()
        .iter()
        .filter(|t| segment_crosses(p, far, &t.v))
        .count()
}

fn bunny_open_leaks_and_bunny_does_not() {
    let (Some(open), Some(closed)) = (shared_model("bunny_open.stl"), shared_model("bunny.stl"))
    else {
        return;
    };
    let so = load_surface(open.to_str().unwrap()).unwrap();
    let sc = load_surface(closed.to_str().unwrap()).unwrap();
    // A point deep in the closed bunny: its volume centroid, inside by ray
    // parity in three directions.
    let pc = centroid(&sc);
    for dir in [[0.6, 0.64, 0.48], [-0.36, 0.8, -0.48], [0.0, -0.6, 0.8]] {
        assert_eq!(
            ray_crossings(&sc, pc, dir) % 2,
            1,
            "centroid {pc:?} not inside"
        );
    }
    // The same point relative to the bounding box of the open bunny (the
    // same object, scaled and moved).
    let (bc, bo) = (sc.bbox(), so.bbox());
    let po: [f64; 3] = std::array::from_fn(|k| {
        bo.min[k] + (pc[k] - bc.min[k]) / (bc.max[k] - bc.min[k]) * (bo.max[k] - bo.min[k])
    });
    let dir = scratch("leak_bunny");
    let arg = |p: [f64; 3]| format!("{},{},{}", p[0], p[1], p[2]);
    let (pc_s, po_s) = (arg(pc), arg(po));
    let csv = dir.join("bunny_open_path.csv");
    let level = "8";
    let out = octmesh_run(
        2,
        &[
            "octree",
            open.to_str().unwrap(),
            "--level",
            level,
            "--inside-point",
            &po_s,
            "--leak-path",
            csv.to_str().unwrap(),
        ],
    );
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "bunny_open: {err}");
    assert!(err.contains("leak: the outside region reaches"), "{err}");
    let rows = read_csv(&csv);
    let d = domain_of(&so);
    let boxes = snap(&d, &rows);
    assert_valid_path(&d, &boxes, so.triangles(), po);
    println!(
        "bunny_open, level {level}: leak path of {} octants",
        rows.len()
    );
    // The closed bunny at the same level: sealed.
    let out = octmesh_run(
        2,
        &[
            "octree",
            closed.to_str().unwrap(),
            "--level",
            level,
            "--inside-point",
            &pc_s,
        ],
    );
    assert!(
        out.status.success(),
        "closed bunny: {}\n{}",
        text(&out.stdout),
        text(&out.stderr)
    );
    assert!(text(&out.stdout).contains("leak check passed"));
}

/// The holed sphere as an STL file in `dir`.
fn holed_stl(dir: &Path) -> String {
    let p = dir.join("holed_sphere.stl");
    octmesh::internals::geometry::stl::write_stl_binary(&p, &holed_sphere()).expect("write stl");
    p.to_str().unwrap().to_string()
}

fn cli_reports_a_leak_on_every_rank() {
    let dir = scratch("leak_cli");
    let stl = holed_stl(&dir);
    let surface = load_surface(&stl).unwrap();
    let d = domain_of(&surface);
    let level = FINE.to_string();
    let mut files = Vec::new();
    for (np, name) in [(2, "path.vtk"), (3, "path.csv")] {
        let file = dir.join(name);
        let stats = dir.join(format!("stats_{np}.json"));
        let out = octmesh_run(
            np,
            &[
                "mesh",
                &stl,
                "--level",
                &level,
                "--keep",
                "outside",
                "--inside-point",
                "0,0,0",
                "--leak-path",
                file.to_str().unwrap(),
                "--stats",
                stats.to_str().unwrap(),
            ],
        );
        let err = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{np} ranks:\n{err}");
        let rows = if name.ends_with(".vtk") {
            read_vtk(&file)
        } else {
            read_csv(&file)
        };
        let n = rows.len();
        // The same message on every rank, with the path's length.
        let mut messages = Vec::new();
        for r in 0..np {
            let head = format!("octmesh: error [rank {r} of {np}]: ");
            let at = err
                .find(&head)
                .unwrap_or_else(|| panic!("no message from rank {r}:\n{err}"));
            // The message: its first line and the indented lines after it.
            let mut lines = err[at + head.len()..].lines();
            let mut m = lines.next().unwrap_or_default().to_string();
            for l in lines.take_while(|l| l.starts_with("  ")) {
                m.push('\n');
                m.push_str(l);
            }
            messages.push(m);
        }
        assert!(messages.iter().all(|m| *m == messages[0]), "{messages:#?}");
        let m = &messages[0];
        assert!(m.contains(&format!("a path of {n} face-adjacent")), "{m}");
        assert!(m.contains("from the boundary: #1 ("), "{m}");
        assert!(m.contains("enters the surface's bounding box"), "{m}");
        // The mesh was not built; the statistics record the leak.
        let s = json_file(&stats);
        assert_eq!(s["leak"]["checked"], true);
        assert_eq!(s["leak"]["found"], true);
        assert_eq!(s["leak"]["path_octants"].as_u64(), Some(n as u64));
        assert!(s["timings"]["leak_check"].as_f64().unwrap() > 0.0);
        assert!(
            s.get("elements").is_none(),
            "a mesh was built despite the leak"
        );
        let boxes = snap(&d, &rows);
        assert_valid_path(&d, &boxes, surface.triangles(), [0.0; 3]);
        files.push(rows);
    }
    assert_eq!(files[0], files[1], "2 and 3 ranks wrote different paths");
    // An independent reader: meshio reads the VTK file as line cells.
    let py = python_with_meshio();
    let script = "import meshio, sys\n\
                  m = meshio.read(sys.argv[1])\n\
                  n = sum(len(c.data) for c in m.cells if c.type == 'line')\n\
                  print(len(m.points), n, sorted(m.point_data))\n";
    let out = std::process::Command::new(&py)
        .args(["-c", script, dir.join("path.vtk").to_str().unwrap()])
        .output()
        .expect("run python");
    let said = text(&out.stdout);
    assert!(out.status.success(), "meshio: {}", text(&out.stderr));
    let n = files[0].len();
    assert!(
        said.starts_with(&format!("{n} {} ", n - 1)),
        "meshio read: {said}"
    );
    assert!(said.contains("size"), "meshio read: {said}");
}

fn cli_passes_on_a_closed_surface() {
    let dir = scratch("leak_cli_pass");
    let stats = dir.join("stats.json");
    let out = octmesh_ok(
        2,
        &[
            "mesh",
            "sphere",
            "--level",
            "6",
            "--keep",
            "outside",
            "--inside-point",
            "0.1,0.2,-0.3",
            "--stats",
            stats.to_str().unwrap(),
        ],
    );
    let said = text(&out.stdout);
    assert!(said.contains("leak check passed"), "{said}");
    let s = json_file(&stats);
    assert_eq!(s["leak"]["checked"], true);
    assert_eq!(s["leak"]["found"], false);
    assert_eq!(s["leak"]["path_octants"].as_u64(), Some(0));
    assert!(s["elements"].as_u64().unwrap() > 0);
    // Without the option the check does not run.
    octmesh_ok(
        1,
        &[
            "octree",
            "sphere",
            "--level",
            "4",
            "--stats",
            stats.to_str().unwrap(),
        ],
    );
    assert_eq!(json_file(&stats)["leak"]["checked"], false);
}

fn cli_rejects_a_point_on_the_surface() {
    // The centroid of a triangle of the sphere: its leaf is cut.
    let c = full_sphere().triangles()[100].centroid();
    let p = format!("{},{},{}", c[0], c[1], c[2]);
    let out = octmesh_run(
        2,
        &["octree", "sphere", "--level", "5", "--inside-point", &p],
    );
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("touching the surface"), "{err}");
    assert_eq!(err.matches("octmesh: error [rank").count(), 2, "{err}");
    let out = octmesh_run(
        1,
        &["octree", "sphere", "--level", "3", "--leak-path", "x.vtk"],
    );
    assert!(text(&out.stderr).contains("--leak-path needs --inside-point"));
}
