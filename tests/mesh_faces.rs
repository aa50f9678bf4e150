//! Finite-volume faces, patches and the cell halo, checked on 1 to 4 ranks.
//!
//! Run by `cargo test`, this program launches itself under `mpirun` on 1 to
//! 4 ranks. On every rank each local element must close (its faces' area
//! vectors, pointing out of it, sum to zero) and be wrapped by faces of
//! total area 6 s². Rank 0 gathers every rank's faces and compares them
//! with the faces of the same mesh built by rank 0 alone (by owner and
//! other global element or patch, area and centre), and compares each
//! pair of ranks' shared faces and exchange lists (same faces, same order
//! on both sides). On one rank the faces are compared with a brute-force
//! search over all pairs of elements, and with every leaf kept each side
//! patch must cover its side of the cube.

mod common;

use std::collections::BTreeSet;
use std::rc::Rc;
use std::time::Duration;

use octmesh::internals::classify::{classify_leaves, CutRule, Keep};
use octmesh::internals::geometry::load_surface;
use octmesh::internals::mesh::{Faces, Mesh, MeshOptions, Other, NUM_PATCHES, SURFACE_PATCH};
use octmesh::internals::octree::domain::{Domain, DEFAULT_FIT};
use octmesh::internals::octree::octant::ROOT_LEN;
use octmesh::internals::parallel::comm::{CommRef, MpiComm, SerialComm};
use octmesh::internals::refine::{build_from_surface, SurfaceIndex, NO_LIMIT};
use octmesh::Connectivity;

fn main() {
    common::runner::main(
        "mesh_faces",
        |_| child(),
        |r| {
            r.on_ranks(
                1..=4,
                "run",
                "faces: all checks passed",
                Duration::from_secs(600),
            );
        },
    );
}

struct Case {
    shape: &'static str,
    level: u8,
    conn: Connectivity,
    keep: Keep,
    /// Weight the partition towards the bottom of the cube.
    skewed: bool,
    clean_walls: bool,
}

fn build(comm: CommRef, case: &Case) -> Mesh {
    let s = load_surface(case.shape).unwrap();
    let b = s.bbox();
    let domain = Domain::around(b.min, b.max, DEFAULT_FIT).unwrap();
    let index = SurfaceIndex::new(&s, &domain);
    let mut t = build_from_surface(comm, &index, case.level, NO_LIMIT).unwrap();
    t.partition().unwrap();
    t.balance(case.conn).unwrap();
    if case.skewed {
        t.partition_weighted(|o| if o.coords()[2] < (1 << 17) { 40 } else { 1 })
            .unwrap();
    } else {
        t.partition().unwrap();
    }
    let classes = classify_leaves(t.leaves(), &index);
    let opts = MeshOptions {
        keep: case.keep,
        cut_rule: CutRule::Center,
        clean_walls: case.clean_walls,
    };
    Mesh::build(&t, &domain, Some(&classes), &opts).unwrap()
}

/// A face reduced to rank-independent integers: the two global elements
/// (lower first; a boundary's patch as `u64::MAX - patch`), nine times the
/// centre in lattice units, twice the area.
type GlobalFace = (u64, u64, [u64; 3], u64);

fn global_faces(m: &Mesh, f: &Faces) -> Vec<GlobalFace> {
    let mut out = Vec::new();
    for face in f.faces() {
        let a = m.global_element(face.owner() as usize);
        let b = match face.other() {
            Other::Patch(p) => u64::MAX - p as u64,
            _ => m.other_global(face).unwrap(),
        };
        // A shared face is listed by both ranks: keep the lower rank's.
        if let Other::Halo(h) = face.other() {
            if m.halo().owners[h as usize] < m.rank() as u32 {
                continue;
            }
        }
        let c = face.lattice_centre();
        // Centres are multiples of 1/9 lattice unit (the quadrilaterals'
        // centroids).
        let centre = c.map(|x| (9.0 * x).round() as u64);
        for k in 0..3 {
            assert!(
                (centre[k] as f64 - 9.0 * c[k]).abs() < 1e-6,
                "centre off a ninth"
            );
        }
        out.push((
            a.min(b),
            a.max(b),
            centre,
            (2.0 * face.lattice_area()) as u64,
        ));
    }
    out
}

/// Each local element's faces close and cover 6 s².
fn check_closure(m: &Mesh, f: &Faces, tag: &str) {
    let n = m.elements().len();
    let mut sum = vec![[0f64; 3]; n];
    let mut total = vec![0f64; n];
    let mut add = |e: usize, face: &octmesh::internals::mesh::Face, sign: f64| {
        let a = face.lattice_area();
        let nrm = face.unit_normal();
        for k in 0..3 {
            sum[e][k] += sign * a * nrm[k];
        }
        total[e] += a;
    };
    for face in f.faces() {
        add(face.owner() as usize, face, 1.0);
        if let Other::Element(j) = face.other() {
            add(j as usize, face, -1.0);
        }
    }
    for (i, e) in m.elements().iter().enumerate() {
        let s = e.side() as f64;
        assert_eq!(sum[i], [0.0; 3], "{tag}: element {i} does not close");
        assert_eq!(total[i], 6.0 * s * s, "{tag}: element {i} faces cover");
    }
    // Orderings: internal upper-triangular, boundary by patch.
    let internal = &f.faces()[..f.num_internal()];
    for w in internal.windows(2) {
        assert!(
            (w[0].owner(), w[0].other()) < (w[1].owner(), w[1].other()),
            "{tag}: order"
        );
    }
    for face in internal {
        let Other::Element(j) = face.other() else {
            panic!("{tag}: non-internal face among internal ones");
        };
        assert!(face.owner() < j, "{tag}: owner must be the lower element");
    }
    for p in 0..NUM_PATCHES {
        for face in &f.faces()[f.patch_range(p)] {
            assert_eq!(
                face.other(),
                Other::Patch(p as u16),
                "{tag}: patch grouping"
            );
        }
    }
}

/// Brute force on one rank: every pair of elements whose boundaries share
/// an area, and the area left over on each element.
fn brute_force(m: &Mesh, f: &Faces, tag: &str) {
    let el = m.elements();
    let boxes: Vec<([u32; 3], u32)> = el.iter().map(|e| (e.coords(), e.side())).collect();
    let mut order: Vec<usize> = (0..el.len()).collect();
    order.sort_by_key(|&i| boxes[i].0[0]);
    let max_side = boxes.iter().map(|b| b.1).max().unwrap_or(0);
    let mut pairs = BTreeSet::new();
    let mut shared_area = 0f64;
    // Area each element's face shares with kept elements, p4est face order.
    let mut covered = vec![[0i64; 6]; el.len()];
    for (a, &i) in order.iter().enumerate() {
        let (p, s) = boxes[i];
        for &j in &order[a + 1..] {
            let (q, t) = boxes[j];
            if q[0] > p[0] + s + max_side {
                break;
            }
            // Overlap lengths per axis; a shared face touches on one axis
            // and overlaps with positive length on the other two.
            let ov: Vec<i64> = (0..3)
                .map(|k| (p[k] + s).min(q[k] + t) as i64 - p[k].max(q[k]) as i64)
                .collect();
            let touching = ov.iter().filter(|&&o| o == 0).count();
            if touching == 1 && ov.iter().all(|&o| o >= 0) {
                pairs.insert((i.min(j) as u32, i.max(j) as u32));
                let area = ov.iter().filter(|&&o| o > 0).product::<i64>();
                shared_area += area as f64;
                let k = ov.iter().position(|&o| o == 0).unwrap();
                let j_above = q[k] == p[k] + s;
                covered[i][2 * k + usize::from(j_above)] += area;
                covered[j][2 * k + usize::from(!j_above)] += area;
            }
        }
    }
    let faces: BTreeSet<(u32, u32)> = f.faces()[..f.num_internal()]
        .iter()
        .map(|face| match face.other() {
            Other::Element(j) => (face.owner(), j),
            _ => unreachable!(),
        })
        .collect();
    assert_eq!(faces.len(), f.num_internal(), "{tag}: a pair listed twice");
    assert_eq!(
        faces, pairs,
        "{tag}: internal faces differ from brute force"
    );
    let total: f64 = el.iter().map(|e| 6.0 * (e.side() as f64).powi(2)).sum();
    let boundary: f64 = f.faces()[f.num_internal()..]
        .iter()
        .map(|x| x.lattice_area())
        .sum();
    assert_eq!(boundary, total - 2.0 * shared_area, "{tag}: boundary area");
    // The finite-element boundary: every element face not wholly shared,
    // on its side's patch at the domain's sides, else on the surface.
    let mut expected = Vec::new();
    for (i, &(p, s)) in boxes.iter().enumerate() {
        for (face, &area) in covered[i].iter().enumerate() {
            if area == (s as i64).pow(2) {
                continue;
            }
            let (k, plus) = (face / 2, face % 2 == 1);
            let at_side = if plus {
                p[k] + s == ROOT_LEN
            } else {
                p[k] == 0
            };
            let patch = if at_side { face as u16 } else { SURFACE_PATCH };
            expected.push((i as u32, face as u8, patch));
        }
    }
    let serial = octmesh::internals::parallel::comm::SerialComm;
    let got: Vec<(u32, u8, u16)> = m
        .boundary(&serial, f, None)
        .unwrap()
        .faces()
        .iter()
        .map(|b| (b.element, b.face, b.patch))
        .collect();
    assert_eq!(
        got, expected,
        "{tag}: boundary element faces differ from brute force"
    );
    let root = (ROOT_LEN as f64).powi(2);
    for p in 0..6 {
        let side: f64 = f.faces()[f.patch_range(p)]
            .iter()
            .map(|x| x.lattice_area())
            .sum();
        if m.counts().elements == el.len() as u64
            && f.patch_range(SURFACE_PATCH as usize).is_empty()
        {
            assert_eq!(side, root, "{tag}: side patch {p} must cover its side");
        }
    }
}

fn flatten_faces(v: &[GlobalFace]) -> Vec<u64> {
    v.iter()
        .flat_map(|f| [f.0, f.1, f.2[0], f.2[1], f.2[2], f.3])
        .collect()
}

/// Each local node's lattice point and patch mask, flattened as
/// `[x, y, z, mask]`.
fn node_patches(comm: &CommRef, m: &Mesh, f: &Faces) -> Vec<u64> {
    let b = m.boundary(&**comm, f, None).unwrap();
    let mut v = Vec::new();
    for (n, p) in m.node_lattice().iter().enumerate() {
        let mask: u64 = b.node_patches(n).iter().map(|&q| 1u64 << q).sum();
        v.extend([p[0] as u64, p[1] as u64, p[2] as u64, mask]);
    }
    v
}

/// The patches of the boundary faces through lattice point `p` from the
/// whole mesh's elements (sorted, all on one rank): each pair of the eight
/// finest cells around `p` across a plane through it, one in an element and
/// one not, is a boundary face through `p`.
fn brute_node_mask(all: &[octmesh::internals::octree::octant::Octant], p: [u64; 3]) -> u64 {
    let root = ROOT_LEN as u64;
    let cell = |b: usize| -> Option<[u64; 3]> {
        let mut q = [0u64; 3];
        for a in 0..3 {
            if b >> a & 1 == 1 {
                if p[a] >= root {
                    return None;
                }
                q[a] = p[a];
            } else {
                if p[a] == 0 {
                    return None;
                }
                q[a] = p[a] - 1;
            }
        }
        Some(q)
    };
    let kept = |q: [u64; 3]| {
        // The last element starting at or before the cell in Morton order
        // is the only one that may hold it.
        let cell = octmesh::internals::octree::octant::morton_encode(
            q[0] as u32,
            q[1] as u32,
            q[2] as u32,
        );
        let k = all.partition_point(|e| e.cell_begin() <= cell);
        k > 0 && {
            let e = all[k - 1];
            let (c, s) = (e.coords(), e.side() as u64);
            (0..3).all(|a| c[a] as u64 <= q[a] && q[a] < c[a] as u64 + s)
        }
    };
    let state: Vec<Option<bool>> = (0..8).map(|b| cell(b).map(kept)).collect();
    let mut mask = 0u64;
    for b in 0..8 {
        if state[b] != Some(true) {
            continue;
        }
        for a in 0..3 {
            match state[b ^ (1 << a)] {
                Some(true) => {}
                Some(false) => mask |= 1 << SURFACE_PATCH,
                None => mask |= 1 << (2 * a + (b >> a & 1 ^ 1)),
            }
        }
    }
    mask
}

/// For each neighbour rank: the shared faces (global pairs, lower rank's
/// element first) and the exchange lists (global numbers), flattened as
/// `[rank, nfaces, pairs..., nsend, send..., nrecv, recv...]`.
fn shared(m: &Mesh, f: &Faces) -> Vec<u64> {
    let halo = m.cell_halo(f);
    let mut v = Vec::new();
    for (k, (r, range)) in f.halo_ranges().iter().enumerate() {
        assert_eq!(halo.ranks[k], *r);
        v.push(*r as u64);
        v.push(range.len() as u64);
        for face in &f.faces()[range.clone()] {
            let (a, b) = (
                m.global_element(face.owner() as usize),
                m.other_global(face).unwrap(),
            );
            let (lo, hi) = if (m.rank() as u32) < *r {
                (a, b)
            } else {
                (b, a)
            };
            v.extend([lo, hi]);
        }
        v.push(halo.send[k].len() as u64);
        v.extend(halo.send[k].iter().map(|&e| m.global_element(e as usize)));
        v.push(halo.recv[k].len() as u64);
        v.extend(halo.recv[k].iter().map(|&h| m.halo().global[h as usize]));
    }
    v
}

/// Per rank, per neighbour: (faces, send, recv).
type Lists = Vec<std::collections::BTreeMap<u64, (Vec<u64>, Vec<u64>, Vec<u64>)>>;

fn unflatten_shared(parts: &[Vec<u64>]) -> Lists {
    parts
        .iter()
        .map(|v| {
            let mut map = std::collections::BTreeMap::new();
            let mut at = 0;
            while at < v.len() {
                let r = v[at];
                let n = v[at + 1] as usize;
                let faces = v[at + 2..at + 2 + 2 * n].to_vec();
                at += 2 + 2 * n;
                let ns = v[at] as usize;
                let send = v[at + 1..at + 1 + ns].to_vec();
                at += 1 + ns;
                let nr = v[at] as usize;
                let recv = v[at + 1..at + 1 + nr].to_vec();
                at += 1 + nr;
                map.insert(r, (faces, send, recv));
            }
            map
        })
        .collect()
}

fn child() {
    std::panic::set_hook(Box::new(|info| {
        eprintln!("{info}");
        std::process::exit(101);
    }));
    let universe = mpi::initialize().expect("MPI init");
    let comm: CommRef = Rc::new(MpiComm::new(universe.world()));
    let rank = comm.rank();
    let cases = [
        Case {
            shape: "sphere",
            level: 5,
            conn: Connectivity::Corner,
            keep: Keep::All,
            skewed: false,
            clean_walls: false,
        },
        Case {
            shape: "torus",
            level: 5,
            conn: Connectivity::Edge,
            keep: Keep::Outside,
            skewed: true,
            clean_walls: false,
        },
        Case {
            shape: "sphere",
            level: 6,
            conn: Connectivity::Corner,
            keep: Keep::Inside,
            skewed: true,
            clean_walls: false,
        },
        Case {
            shape: "torus",
            level: 6,
            conn: Connectivity::Corner,
            keep: Keep::Outside,
            skewed: false,
            clean_walls: false,
        },
        Case {
            shape: "torus",
            level: 6,
            conn: Connectivity::Corner,
            keep: Keep::Inside,
            skewed: true,
            clean_walls: true,
        },
        Case {
            shape: "sphere",
            level: 6,
            conn: Connectivity::Edge,
            keep: Keep::Outside,
            skewed: false,
            clean_walls: true,
        },
    ];
    for case in &cases {
        let tag = format!(
            "{} L{} {} keep {}{} np {}",
            case.shape,
            case.level,
            case.conn.name(),
            case.keep.name(),
            if case.clean_walls { " clean walls" } else { "" },
            comm.size()
        );
        let mesh = build(comm.clone(), case);
        let faces = mesh.faces().unwrap();
        check_closure(&mesh, &faces, &tag);
        let parts = common::gather(&comm, flatten_faces(&global_faces(&mesh, &faces)));
        let lists = common::gather(&comm, shared(&mesh, &faces));
        let nodes = common::gather(&comm, node_patches(&comm, &mesh, &faces));
        if rank == 0 {
            let dist: BTreeSet<Vec<u64>> = parts.concat().chunks(6).map(|c| c.to_vec()).collect();
            let n: usize = parts.iter().map(|p| p.len() / 6).sum();
            assert_eq!(dist.len(), n, "{tag}: a face listed twice");
            let serial: CommRef = Rc::new(SerialComm);
            let one = build(serial, case);
            let one_faces = one.faces().unwrap();
            check_closure(&one, &one_faces, &tag);
            brute_force(&one, &one_faces, &tag);
            let alone: BTreeSet<Vec<u64>> = flatten_faces(&global_faces(&one, &one_faces))
                .chunks(6)
                .map(|c| c.to_vec())
                .collect();
            assert_eq!(dist, alone, "{tag}: faces differ from one process's");
            // Every rank's nodes carry the patches brute force finds (so
            // shared nodes agree); the check is quadratic, so a sample.
            let all = one.elements();
            let mut on_boundary = 0;
            for (r, v) in nodes.iter().enumerate() {
                for (k, c) in v.chunks(4).enumerate() {
                    if k % 7 != 0 && c[3] == 0 {
                        continue;
                    }
                    let want = brute_node_mask(all, [c[0], c[1], c[2]]);
                    assert_eq!(
                        c[3],
                        want,
                        "{tag}: rank {r} node at {:?}: patches {:b}, brute force {:b}",
                        &c[..3],
                        c[3],
                        want
                    );
                    on_boundary += usize::from(want != 0);
                }
            }
            assert!(on_boundary > 0, "{tag}: no boundary node");
            let lists = unflatten_shared(&lists);
            let mut pairs = 0;
            for (a, map) in lists.iter().enumerate() {
                for (&b, (faces, send, recv)) in map {
                    let theirs = lists[b as usize]
                        .get(&(a as u64))
                        .unwrap_or_else(|| panic!("{tag}: rank {b} lists no faces with {a}"));
                    assert_eq!(
                        faces, &theirs.0,
                        "{tag}: ranks {a} and {b} list shared faces differently"
                    );
                    assert_eq!(
                        send, &theirs.2,
                        "{tag}: {a}'s send list is not {b}'s receive list"
                    );
                    assert_eq!(
                        recv, &theirs.1,
                        "{tag}: {a}'s receive list is not {b}'s send list"
                    );
                    pairs += faces.len() / 2;
                }
            }
            let surface = one_faces.patch_range(SURFACE_PATCH as usize).len();
            println!(
                "{tag}: {} faces ({} internal, {} on the surface), {} shared between ranks: \
                 same as on one process, closed, brute force equal",
                alone.len(),
                one_faces.num_internal(),
                surface,
                pairs / 2
            );
        }
    }
    if rank == 0 {
        println!("faces: all checks passed");
    }
}
