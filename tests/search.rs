//! Point location against brute force, the same on 1 to 4 ranks.
//!
//! A fixed set of points (random ones; points on the lattice lines of a
//! random level, so on leaf faces, edges and corners; points on the domain's
//! boundary; points outside it and NaN) is located in the balanced octree
//! of the sphere at level 4 and in its fluid mesh (`Keep::Outside`), in a
//! cube and in a box of 4 x 3 x 3 root cells. Rank 0 gathers the leaves,
//! the elements and the answers and checks every answer against a scan of
//! all leaves with the half-open tie rule; it writes the answers to a file
//! per rank count, and the driver requires the files to be equal.
//!
//! `OCTMESH_SEARCH_BENCH=1 cargo test --release --test search` also times
//! locating 1e6 random points in the level-8 sphere octree on 1 and 2 ranks.

mod common;

use std::path::Path;
use std::rc::Rc;
use std::time::{Duration, Instant};

use octmesh::internals::classify::{CutRule, Keep};
use octmesh::internals::config::Config;
use octmesh::internals::mesh::locate_elements;
use octmesh::internals::octree::domain::Domain;
use octmesh::internals::octree::search::{locate, owner_ranks, Location};
use octmesh::internals::parallel::comm::{CommRef, MpiComm};
use octmesh::internals::pipeline::Session;
use octmesh::{Connectivity, Octant};

const CHILD: &str = "OCTMESH_SEARCH_CHILD";
const POINTS: usize = 6000;
const NONE: u64 = u64::MAX;

fn main() {
    if let Ok(arg) = std::env::var(CHILD) {
        let (mode, dir) = arg.split_once(':').expect("MODE:DIR");
        child(mode, Path::new(dir));
        return;
    }
    let dir = common::scratch("search");
    let me = std::env::current_exe().expect("own path");
    let limit = Duration::from_secs(300);
    for np in 1..=4 {
        let arg = format!("check:{}", dir.display());
        let out = common::mpirun_env(np, &me, &[], &[(CHILD, &arg)], limit);
        let text = format!(
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(out.status.success(), "search on {np} ranks failed:\n{text}");
        assert!(text.contains("SEARCH OK"), "np {np}:\n{text}");
        print!("{text}");
    }
    for case in ["cube", "box"] {
        let read = |np: usize| std::fs::read(dir.join(format!("{case}_np{np}.txt"))).unwrap();
        let one = read(1);
        for np in 2..=4 {
            assert!(
                read(np) == one,
                "{case}: the answers on {np} ranks differ from 1 rank's"
            );
        }
    }
    println!("search: 4 rank counts agree");
    if std::env::var("OCTMESH_SEARCH_BENCH").is_ok_and(|v| v == "1") {
        for np in [1, 2] {
            let arg = format!("bench:{}", dir.display());
            let out = common::mpirun_env(np, &me, &[], &[(CHILD, &arg)], limit);
            assert!(
                out.status.success(),
                "{}",
                String::from_utf8_lossy(&out.stderr)
            );
            print!("{}", String::from_utf8_lossy(&out.stdout));
        }
    }
}

/// splitmix64: a fixed sequence with no dependency.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

/// The test points of a domain whose upper lattice bound is `hi`.
fn points(domain: &Domain, seed: u64) -> Vec<[f64; 3]> {
    let hi = domain.brick.hi().map(|v| v as f64);
    let mut rng = Rng(seed);
    let mut out = Vec::with_capacity(POINTS);
    for i in 0..POINTS {
        let q: [f64; 3] = match i % 6 {
            // Anywhere in the domain and around it (some outside).
            0 => std::array::from_fn(|k| (rng.unit() * 1.2 - 0.1) * hi[k]),
            // On the lines of the grid of a random level: a face, edge or
            // corner of every leaf at that level or finer there.
            1..=3 => {
                let level = rng.below(8) as u32;
                let step = (1u64 << (19 - level)) as f64;
                std::array::from_fn(|k| {
                    if rng.below(4) == 0 {
                        rng.unit() * hi[k]
                    } else {
                        (rng.below((hi[k] / step) as u64 + 1) as f64) * step
                    }
                })
            }
            // On the domain's boundary, highest faces included.
            4 => std::array::from_fn(|k| match rng.below(3) {
                0 => 0.0,
                1 => hi[k],
                _ => rng.unit() * hi[k],
            }),
            // Just outside, or NaN.
            _ => {
                let mut q: [f64; 3] = std::array::from_fn(|k| rng.unit() * hi[k]);
                let k = rng.below(3) as usize;
                q[k] = match rng.below(3) {
                    0 => -0.5,
                    1 => hi[k] + 0.5,
                    _ => f64::NAN,
                };
                q
            }
        };
        out.push(domain.from_lattice(q));
    }
    out
}

/// The brute-force leaf index holding `p`: the one leaf whose half-open
/// box holds its lattice point, the highest faces of the domain belonging
/// to the leaves below them; `None` outside or in the void.
fn brute(domain: &Domain, leaves: &[Octant], p: [f64; 3]) -> Option<usize> {
    let q = domain.to_lattice(p);
    let hi = domain.brick.hi();
    if !(0..3).all(|k| q[k] >= 0.0 && q[k] <= hi[k] as f64) {
        return None;
    }
    // The highest faces are moved half a cell into the domain.
    let q: [f64; 3] = std::array::from_fn(|k| q[k].min(hi[k] as f64 - 0.5));
    let holds = |o: &Octant| {
        let (c, s) = (o.coords(), o.side());
        (0..3).all(|k| c[k] as f64 <= q[k] && q[k] < (c[k] + s) as f64)
    };
    let found: Vec<usize> = (0..leaves.len()).filter(|&i| holds(&leaves[i])).collect();
    assert_eq!(found.len(), 1, "{p:?} (lattice {q:?}) in leaves {found:?}");
    (!domain.brick.is_void(leaves[found[0]])).then_some(found[0])
}

fn session(comm: &CommRef, bbox: Option<([f64; 6], [u32; 3])>, level: u8) -> Session {
    let mut config = Config::default();
    config.surface.file = "sphere".into();
    match bbox {
        Some((b, roots)) => {
            config.domain.bbox = Some(b);
            config.domain.roots = Some(roots);
        }
        None => config.domain.cube = Some([-2.0, -2.0, -2.0, 4.0]),
    }
    let mut s = Session::new(comm.clone(), config);
    s.load_surface().unwrap();
    s.refine_surface(level).unwrap();
    s.partition().unwrap();
    s.balance(Connectivity::Corner).unwrap();
    s.partition().unwrap();
    s
}

fn child(mode: &str, dir: &Path) {
    std::panic::set_hook(Box::new(|info| {
        eprintln!("{info}");
        std::process::exit(101);
    }));
    let universe = mpi::initialize().expect("MPI init");
    let comm: CommRef = Rc::new(MpiComm::new(universe.world()));
    if mode == "bench" {
        bench(&comm);
    } else {
        check(&comm, "cube", None, dir);
        // Root cells of side 1: lattice steps are powers of two in user
        // units, so the lattice points above are exact.
        let b = ([-2.0, -1.5, -1.5, 2.0, 1.5, 1.5], [4, 3, 3]);
        check(&comm, "box", Some(b), dir);
    }
    if comm.rank() == 0 {
        println!("SEARCH OK np={}", comm.size());
    }
    drop(comm);
    drop(universe);
}

fn check(comm: &CommRef, case: &str, bbox: Option<([f64; 6], [u32; 3])>, dir: &Path) {
    let (rank, p) = (comm.rank(), comm.size());
    let mut s = session(comm, bbox, 4);
    s.build_mesh(Keep::Outside, CutRule::Center).unwrap();
    let domain = s.domain().unwrap();
    let (tree, mesh) = (s.tree().unwrap(), s.mesh().unwrap());
    let all = points(&domain, 23);
    // Round robin over the ranks, the last one without points from 3 ranks
    // on.
    let takers = if p >= 3 { p - 1 } else { p };
    let mine: Vec<usize> = (0..all.len()).filter(|i| i % takers == rank).collect();
    let pts: Vec<[f64; 3]> = mine.iter().map(|&i| all[i]).collect();
    let leaves = locate(tree, &domain, &pts);
    let elements = locate_elements(tree, mesh, &pts);
    let owners = owner_ranks(tree, &domain, &pts);
    let offsets = tree.global_offsets();
    let mut rows = Vec::new();
    for (j, &i) in mine.iter().enumerate() {
        let (leaf, key) = match leaves[j] {
            Location::Found {
                rank: r,
                local,
                global,
                leaf,
            } => {
                assert_eq!(owners[j], Some(r));
                assert_eq!(global, offsets[r as usize] + local as u64);
                (global, leaf.key())
            }
            Location::NoElement { .. } => panic!("a leaf without element"),
            Location::Outside => {
                assert_eq!(owners[j], None);
                (NONE, NONE)
            }
        };
        let element = match elements[j] {
            Location::Found { global, leaf, .. } => {
                assert_eq!(leaf.key(), key);
                global
            }
            Location::NoElement { leaf, rank: r } => {
                assert_eq!((leaf.key(), Some(r)), (key, owners[j]));
                NONE - 1
            }
            Location::Outside => NONE,
        };
        rows.extend([i as u64, leaf, key, element]);
    }
    let gathered = common::gather(comm, rows);
    let all_leaves = common::gather(comm, tree.leaves().iter().map(|o| o.key()).collect());
    let all_elements = common::gather(comm, mesh.elements().iter().map(|o| o.key()).collect());
    if rank != 0 {
        return;
    }
    let leaves: Vec<Octant> = all_leaves
        .concat()
        .into_iter()
        .map(Octant::from_key)
        .collect();
    let elements: Vec<u64> = all_elements.concat();
    let mut answers = vec![[NONE; 3]; all.len()];
    let mut seen = vec![false; all.len()];
    for w in gathered.concat().chunks_exact(4) {
        let i = w[0] as usize;
        assert!(!seen[i], "point {i} answered twice");
        seen[i] = true;
        answers[i] = [w[1], w[2], w[3]];
    }
    assert!(seen.iter().all(|&b| b), "points lost");
    let (mut outside, mut inside_body) = (0, 0);
    for (i, &pt) in all.iter().enumerate() {
        let want = brute(&domain, &leaves, pt);
        let [leaf, key, element] = answers[i];
        match want {
            None => {
                outside += 1;
                assert_eq!((leaf, element), (NONE, NONE), "{case} point {i} {pt:?}");
            }
            Some(w) => {
                assert_eq!(
                    (leaf, key),
                    (w as u64, leaves[w].key()),
                    "{case} point {i} {pt:?}"
                );
                let e = elements.binary_search(&key).ok();
                if e.is_none() {
                    inside_body += 1;
                }
                assert_eq!(
                    element,
                    e.map_or(NONE - 1, |e| e as u64),
                    "{case} point {i}"
                );
            }
        }
    }
    assert!(
        outside > POINTS / 10,
        "{case}: only {outside} points outside"
    );
    assert!(inside_body > 0, "{case}: no point in the body");
    let text: String = answers
        .iter()
        .map(|a| format!("{} {} {}\n", a[0] as i64, a[1] as i64, a[2] as i64))
        .collect();
    std::fs::write(dir.join(format!("{case}_np{p}.txt")), text).unwrap();
    println!(
        "{case} np={p}: {} points, {outside} outside, {inside_body} in the body, {} leaves",
        all.len(),
        leaves.len()
    );
}

/// Locates 1e6 random points (1e6 / p per rank) in the level-8 sphere
/// octree in its fitted cube; prints the slowest rank's seconds.
fn bench(comm: &CommRef) {
    let (rank, p) = (comm.rank(), comm.size());
    let mut config = Config::default();
    config.surface.file = "sphere".into();
    let mut s = Session::new(comm.clone(), config);
    s.load_surface().unwrap();
    s.refine_surface(8).unwrap();
    s.partition().unwrap();
    s.balance(Connectivity::Corner).unwrap();
    s.partition().unwrap();
    let domain = s.domain().unwrap();
    let tree = s.tree().unwrap();
    let total = 1_000_000usize;
    let n = total / p + usize::from(rank < total % p);
    let mut rng = Rng(1 + rank as u64);
    let up = domain.upper();
    let pts: Vec<[f64; 3]> = (0..n)
        .map(|_| {
            std::array::from_fn(|k| domain.origin[k] + rng.unit() * (up[k] - domain.origin[k]))
        })
        .collect();
    let time = |f: &dyn Fn() -> usize| {
        let mut best = f64::INFINITY;
        for _ in 0..3 {
            comm.barrier();
            let t = Instant::now();
            let k = f();
            let mut m = [t.elapsed().as_secs_f64()];
            comm.max_f64(&mut m);
            best = best.min(m[0]);
            assert_eq!(k, n);
        }
        best
    };
    let owners = time(&|| owner_ranks(tree, &domain, &pts).len());
    let located = time(&|| locate(tree, &domain, &pts).len());
    if rank == 0 {
        println!(
            "BENCH np={p} leaves={} points={total}: owner_ranks {:.3} s ({:.1} M points/s), \
             locate {:.3} s ({:.1} M points/s)",
            tree.global_len(),
            owners,
            total as f64 / owners / 1e6,
            located,
            total as f64 / located / 1e6
        );
    }
}
