//! The distributed mesh against itself on one process, and a finite-element
//! patch test solved in parallel through the owner and sharer lists.
//!
//! Run by `cargo test`, this program launches itself under `mpirun` on 1 to
//! 4 ranks. Each launched copy builds meshes on all ranks, gathers them on
//! rank 0 and compares them with the same mesh built by rank 0 alone:
//! elements by key, independent nodes by coordinates (one owner each,
//! global numbers a bijection onto `0..N`), hanging nodes with their
//! dependencies by coordinates, symmetric sharer lists. Then it solves the
//! Laplace equation with a linear Dirichlet condition by conjugate gradients
//! on the hanging-node mesh; the discrete solution must be that linear
//! function at every node.

mod common;

use std::collections::{BTreeMap, BTreeSet};
use std::rc::Rc;
use std::time::Duration;

use mpi::collective::SystemOperation;
use mpi::traits::*;

use octmesh::internals::classify::{classify_leaves, CutRule, Keep};
use octmesh::internals::geometry::load_surface;
use octmesh::internals::mesh::{Mesh, MeshOptions, VTK_TO_MORTON};
use octmesh::internals::octree::domain::{Domain, DEFAULT_FIT};
use octmesh::internals::parallel::comm::{CommRef, MpiComm, SerialComm};
use octmesh::internals::refine::{build_from_surface, SurfaceIndex, NO_LIMIT};
use octmesh::Connectivity;

fn main() {
    common::runner::main(
        "mesh_nodes",
        |_| child(),
        |r| {
            r.on_ranks(
                1..=4,
                "run",
                "nodes: all checks passed",
                Duration::from_secs(600),
            );
        },
    );
}

/// A mesh reduced to rank-independent facts, keyed by lattice coordinates.
#[derive(Debug, PartialEq, Eq)]
struct GlobalMesh {
    elements: BTreeSet<u64>,
    independent: BTreeSet<[u32; 3]>,
    /// Hanging node -> sorted dependency coordinates.
    hanging: BTreeMap<[u32; 3], Vec<[u32; 3]>>,
}

/// Everything rank `r` knows, flattened to integers for gathering.
fn flatten(m: &Mesh) -> Vec<u64> {
    let mut v = vec![m.elements().len() as u64];
    v.extend(m.elements().iter().map(|e| e.key()));
    v.push(m.num_independent() as u64);
    let lattice = m.node_lattice();
    for (i, &x) in lattice[..m.num_independent()].iter().enumerate() {
        v.extend([x[0] as u64, x[1] as u64, x[2] as u64]);
        v.push(m.global_id(i));
        v.push(m.owner(i) as u64);
    }
    v.push(m.num_hanging() as u64);
    for k in 0..m.num_hanging() {
        let deps = m.hanging_deps(k);
        let x = lattice[m.num_independent() + k];
        v.extend([x[0] as u64, x[1] as u64, x[2] as u64, deps.len() as u64]);
        for &d in deps.iter() {
            let y = lattice[d as usize];
            v.extend([y[0] as u64, y[1] as u64, y[2] as u64]);
        }
    }
    let lists = m.exchange_lists();
    v.push(lists.len() as u64);
    for (r, nodes) in lists {
        v.push(r as u64);
        v.push(nodes.len() as u64);
        v.extend(nodes.iter().map(|&n| m.global_id(n as usize)));
    }
    v
}

/// Parses gathered [`flatten`] records and checks the cross-rank facts.
fn unflatten(parts: &[Vec<u64>], tag: &str) -> GlobalMesh {
    let mut g = GlobalMesh {
        elements: BTreeSet::new(),
        independent: BTreeSet::new(),
        hanging: BTreeMap::new(),
    };
    let mut ids: BTreeMap<[u32; 3], (u64, u64)> = BTreeMap::new();
    let mut lists: BTreeMap<(u64, u64), Vec<u64>> = BTreeMap::new();
    let mut owned_count = vec![0u64; parts.len()];
    for (rank, v) in parts.iter().enumerate() {
        let mut it = v.iter().copied();
        let mut next = || it.next().expect("truncated record");
        let ne = next();
        for _ in 0..ne {
            assert!(g.elements.insert(next()), "{tag}: element on two ranks");
        }
        let ni = next();
        for _ in 0..ni {
            let x = [next() as u32, next() as u32, next() as u32];
            let (gid, owner) = (next(), next());
            g.independent.insert(x);
            if owner == rank as u64 {
                owned_count[rank] += 1;
            }
            let prev = ids.insert(x, (gid, owner));
            if let Some(p) = prev {
                assert_eq!(p, (gid, owner), "{tag}: ranks disagree on node {x:?}");
            }
        }
        let nh = next();
        for _ in 0..nh {
            let x = [next() as u32, next() as u32, next() as u32];
            let c = next() as usize;
            let mut deps: Vec<[u32; 3]> = (0..c)
                .map(|_| [next() as u32, next() as u32, next() as u32])
                .collect();
            deps.sort_unstable();
            if let Some(p) = g.hanging.insert(x, deps.clone()) {
                assert_eq!(p, deps, "{tag}: ranks disagree on hanging node {x:?}");
            }
        }
        let nl = next();
        for _ in 0..nl {
            let (r, len) = (next(), next());
            let l: Vec<u64> = (0..len).map(|_| next()).collect();
            lists.insert((rank as u64, r), l);
        }
    }
    // Global numbers are a bijection onto 0..N, owned ranges contiguous.
    let n = ids.len() as u64;
    let mut seen = vec![false; n as usize];
    for (x, &(gid, owner)) in &ids {
        assert!(gid < n, "{tag}: global id {gid} of {x:?} out of 0..{n}");
        assert!(!seen[gid as usize], "{tag}: global id {gid} used twice");
        seen[gid as usize] = true;
        let first: u64 = owned_count[..owner as usize].iter().sum();
        assert!(
            gid >= first && gid < first + owned_count[owner as usize],
            "{tag}: node {x:?} numbered {gid} outside its owner {owner}'s range"
        );
    }
    for ((a, b), l) in &lists {
        assert_eq!(
            lists.get(&(*b, *a)),
            Some(l),
            "{tag}: sharer lists of ranks {a} and {b} differ"
        );
    }
    for (x, deps) in &g.hanging {
        assert!(
            !g.independent.contains(x),
            "{tag}: {x:?} both hanging and not"
        );
        for d in deps {
            assert!(
                g.independent.contains(d),
                "{tag}: {x:?} depends on a hanging node"
            );
        }
        // The point is the mean of the points it depends on.
        for ax in 0..3 {
            let sum: u64 = deps.iter().map(|d| d[ax] as u64).sum();
            assert_eq!(
                sum,
                x[ax] as u64 * deps.len() as u64,
                "{tag}: {x:?} is not the mean of its dependencies {deps:?}"
            );
        }
    }
    g
}

/// How the balanced octree is spread over the ranks before meshing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Skew {
    /// Equal counts.
    Equal,
    /// Most weight near the bottom of the cube: thin ranks, many ghosts.
    Front,
    /// All weight on the last leaf: every rank but the last is empty or
    /// nearly so.
    Single,
}

struct Case {
    shape: &'static str,
    level: u8,
    conn: Connectivity,
    keep: Keep,
    skew: Skew,
}

fn build(comm: CommRef, case: &Case) -> (Mesh, Domain) {
    let s = load_surface(case.shape).unwrap();
    let b = s.bbox();
    let domain = Domain::around(b.min, b.max, DEFAULT_FIT).unwrap();
    let index = SurfaceIndex::new(&s, &domain);
    let mut t = build_from_surface(comm, &index, case.level, NO_LIMIT).unwrap();
    t.partition().unwrap();
    t.balance(case.conn).unwrap();
    match case.skew {
        Skew::Equal => {
            t.partition().unwrap();
        }
        Skew::Front => {
            t.partition_weighted(|o| if o.coords()[2] < (1 << 17) { 40 } else { 1 })
                .unwrap();
        }
        Skew::Single => {
            let last = octmesh::Octant::ROOT.last_descendant(octmesh::MAX_LEVEL);
            t.partition_weighted(|o| if o.contains(last) { 1 << 40 } else { 0 })
                .unwrap();
        }
    }
    let classes = classify_leaves(t.leaves(), &index);
    let opts = MeshOptions {
        keep: case.keep,
        cut_rule: CutRule::Center,
        clean_walls: false,
    };
    (
        Mesh::build(&t, &domain, Some(&classes), &opts).unwrap(),
        domain,
    )
}

fn child() {
    // A failed check must end the job, not unwind into MPI_Finalize while
    // the other ranks wait in a collective.
    std::panic::set_hook(Box::new(|info| {
        eprintln!("{info}");
        std::process::exit(101);
    }));
    let universe = mpi::initialize().expect("MPI init");
    let world = universe.world();
    let comm: CommRef = Rc::new(MpiComm::new(universe.world()));
    let rank = comm.rank();
    let cases = [
        Case {
            shape: "sphere",
            level: 5,
            conn: Connectivity::Corner,
            keep: Keep::All,
            skew: Skew::Equal,
        },
        Case {
            shape: "sphere",
            level: 6,
            conn: Connectivity::Edge,
            keep: Keep::All,
            skew: Skew::Front,
        },
        Case {
            shape: "torus",
            level: 6,
            conn: Connectivity::Corner,
            keep: Keep::Inside,
            skew: Skew::Equal,
        },
        Case {
            shape: "torus",
            level: 5,
            conn: Connectivity::Edge,
            keep: Keep::Outside,
            skew: Skew::Single,
        },
        Case {
            shape: "sphere",
            level: 6,
            conn: Connectivity::Corner,
            keep: Keep::Inside,
            skew: Skew::Front,
        },
    ];
    for case in &cases {
        let tag = format!(
            "{} L{} {} keep {} skew {:?} np {}",
            case.shape,
            case.level,
            case.conn.name(),
            case.keep.name(),
            case.skew,
            comm.size()
        );
        let (mesh, _) = build(comm.clone(), case);
        let parts = common::gather(&comm, flatten(&mesh));
        if rank == 0 {
            let dist = unflatten(&parts, &tag);
            let serial: CommRef = Rc::new(SerialComm);
            let (one, _) = build(serial, case);
            let alone = unflatten(&[flatten(&one)], &tag);
            assert_eq!(dist.elements, alone.elements, "{tag}: elements differ");
            assert_eq!(
                dist.independent, alone.independent,
                "{tag}: independent nodes differ"
            );
            assert_eq!(dist.hanging, alone.hanging, "{tag}: hanging nodes differ");
            let without_ghosts = |m: &Mesh| octmesh::internals::mesh::MeshCounts {
                ghosts: 0,
                ..*m.counts()
            };
            assert_eq!(
                without_ghosts(&mesh),
                without_ghosts(&one),
                "{tag}: global counts differ"
            );
            assert!(!dist.hanging.is_empty(), "{tag}: no hanging nodes to test");
            println!(
                "{tag}: {} elements, {} independent, {} hanging nodes: same as on one process",
                dist.elements.len(),
                dist.independent.len(),
                dist.hanging.len()
            );
        }
        if case.keep == Keep::All {
            patch_test(&world, &mesh, &tag);
        }
    }
    if rank == 0 {
        println!("nodes: all checks passed");
    }
}

/// Stiffness of the trilinear unit cube (Morton corner order), by 2-point
/// Gauss quadrature, which is exact for it.
fn unit_stiffness() -> [[f64; 8]; 8] {
    let g = [0.5 - 0.5 / 3f64.sqrt(), 0.5 + 0.5 / 3f64.sqrt()];
    let mut k = [[0.0; 8]; 8];
    for &x in &g {
        for &y in &g {
            for &z in &g {
                let p = [x, y, z];
                let grad = |c: usize| -> [f64; 3] {
                    let f = |d: usize| if c >> d & 1 == 1 { p[d] } else { 1.0 - p[d] };
                    let s = |d: usize| if c >> d & 1 == 1 { 1.0 } else { -1.0 };
                    [s(0) * f(1) * f(2), f(0) * s(1) * f(2), f(0) * f(1) * s(2)]
                };
                for (i, row) in k.iter_mut().enumerate() {
                    for (j, kij) in row.iter_mut().enumerate() {
                        let (a, b) = (grad(i), grad(j));
                        *kij += 0.125 * (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]);
                    }
                }
            }
        }
    }
    k
}

/// Sums the values of shared nodes over their users, so that every rank
/// holds the assembled value. Uses the exchange lists only.
fn sum_shared(world: &impl Communicator, mesh: &Mesh, y: &mut [f64]) {
    let lists = mesh.exchange_lists();
    let p = world.size() as usize;
    let mut send_counts = vec![0i32; p];
    let mut send = Vec::new();
    for (r, nodes) in &lists {
        send_counts[*r as usize] = nodes.len() as i32;
    }
    for (_, nodes) in &lists {
        send.extend(nodes.iter().map(|&n| y[n as usize]));
    }
    // Sorted by rank already, so the send buffer is in rank order.
    let recv_counts = send_counts.clone();
    let displs = |c: &[i32]| -> Vec<i32> {
        c.iter()
            .scan(0, |a, &x| {
                let d = *a;
                *a += x;
                Some(d)
            })
            .collect()
    };
    let (sd, rd) = (displs(&send_counts), displs(&recv_counts));
    let mut recv = vec![0.0; send.len()];
    {
        let sp = mpi::datatype::Partition::new(&send[..], &send_counts[..], &sd[..]);
        let mut rp = mpi::datatype::PartitionMut::new(&mut recv[..], &recv_counts[..], &rd[..]);
        world.all_to_all_varcount_into(&sp, &mut rp);
    }
    let mut at = 0;
    for (_, nodes) in &lists {
        for &n in nodes {
            y[n as usize] += recv[at];
            at += 1;
        }
    }
}

/// The hanging-node constraints as (independent node, weight) lists.
fn expand(mesh: &Mesh, n: u32) -> Vec<(usize, f64)> {
    let ni = mesh.num_independent();
    if (n as usize) < ni {
        vec![(n as usize, 1.0)]
    } else {
        let deps = mesh.hanging_deps(n as usize - ni);
        let w = 1.0 / deps.len() as f64;
        deps.iter().map(|&d| (d as usize, w)).collect()
    }
}

/// y = A x over the independent nodes, assembled on every rank.
fn apply(world: &impl Communicator, mesh: &Mesh, k1: &[[f64; 8]; 8], x: &[f64], y: &mut [f64]) {
    let h_unit = mesh.domain().side / octmesh::internals::octree::octant::ROOT_LEN as f64;
    y.iter_mut().for_each(|v| *v = 0.0);
    for (e, conn) in mesh.elements().iter().zip(mesh.connectivity()) {
        let h = e.side() as f64 * h_unit;
        let mut corner = [0u32; 8];
        for (v, &n) in conn.iter().enumerate() {
            corner[VTK_TO_MORTON[v]] = n;
        }
        let maps: Vec<Vec<(usize, f64)>> = corner.iter().map(|&n| expand(mesh, n)).collect();
        let xe: Vec<f64> = maps
            .iter()
            .map(|m| m.iter().map(|&(i, w)| w * x[i]).sum())
            .collect();
        for i in 0..8 {
            let ye: f64 = (0..8).map(|j| h * k1[i][j] * xe[j]).sum();
            for &(n, w) in &maps[i] {
                y[n] += w * ye;
            }
        }
    }
    sum_shared(world, mesh, y);
}

fn patch_test(world: &impl Communicator, mesh: &Mesh, tag: &str) {
    let k1 = unit_stiffness();
    let ni = mesh.num_independent();
    let (a, b, c, d) = (0.7, -1.3, 2.1, 0.4);
    let exact = |p: [f64; 3]| a + b * p[0] + c * p[1] + d * p[2];
    let root = octmesh::internals::octree::octant::ROOT_LEN;
    let lattice = mesh.node_lattice();
    let coords = mesh.coordinates();
    let on_boundary: Vec<bool> = (0..ni)
        .map(|i| lattice[i].iter().any(|&q| q == 0 || q == root))
        .collect();
    let owned = mesh.num_owned();
    let dot = |u: &[f64], v: &[f64]| -> f64 {
        let local: f64 = (0..owned).map(|i| u[i] * v[i]).sum();
        let mut s = 0.0;
        world.all_reduce_into(&local, &mut s, SystemOperation::sum());
        s
    };

    // A constant has zero energy: A 1 = 0 at every node.
    let ones = vec![1.0; ni];
    let mut y = vec![0.0; ni];
    apply(world, mesh, &k1, &ones, &mut y);
    let worst = y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let mut w = 0.0;
    world.all_reduce_into(&worst, &mut w, SystemOperation::max());
    assert!(
        w < 1e-12 * mesh.domain().side,
        "{tag}: A*1 is not zero ({w:e})"
    );

    // Dirichlet data on the boundary, zero inside; solve for the inside.
    let mut u: Vec<f64> = (0..ni)
        .map(|i| {
            if on_boundary[i] {
                exact(coords[i])
            } else {
                0.0
            }
        })
        .collect();
    apply(world, mesh, &k1, &u, &mut y);
    let mut r: Vec<f64> = (0..ni)
        .map(|i| if on_boundary[i] { 0.0 } else { -y[i] })
        .collect();
    let mut p = r.clone();
    let mut rr = dot(&r, &r);
    let r0 = rr.sqrt().max(1e-300);
    let mut q = vec![0.0; ni];
    let mut iters = 0;
    while rr.sqrt() > 1e-14 * r0 && iters < 5000 {
        apply(world, mesh, &k1, &p, &mut q);
        for i in 0..ni {
            if on_boundary[i] {
                q[i] = 0.0;
            }
        }
        let alpha = rr / dot(&p, &q);
        for i in 0..ni {
            u[i] += alpha * p[i];
            r[i] -= alpha * q[i];
        }
        let rr_new = dot(&r, &r);
        let beta = rr_new / rr;
        rr = rr_new;
        for i in 0..ni {
            p[i] = r[i] + beta * p[i];
        }
        iters += 1;
    }
    // Every node, hanging ones through their constraints, is exact.
    let scale = 1.0 + a.abs() + (b.abs() + c.abs() + d.abs()) * 2.0 * mesh.domain().side;
    let mut err = 0.0f64;
    for n in 0..mesh.num_nodes() as u32 {
        let v: f64 = expand(mesh, n).iter().map(|&(i, w)| w * u[i]).sum();
        err = err.max((v - exact(coords[n as usize])).abs() / scale);
    }
    let mut e = 0.0;
    world.all_reduce_into(&err, &mut e, SystemOperation::max());
    assert!(
        e < 1e-9,
        "{tag}: patch test error {e:e} after {iters} CG iterations"
    );
    if world.rank() == 0 {
        println!("{tag}: patch test exact to {e:.1e} after {iters} CG iterations");
    }
}
