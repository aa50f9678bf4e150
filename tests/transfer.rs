//! Fields across adaptation steps (`octmesh::internals::mesh::transfer`): a sphere
//! moves through the unit cube; each step refines the leaves its surface
//! cuts (up to level 6), coarsens the families it does not cut, balances
//! (corner), partitions for coarsening and builds the new mesh. Checked at
//! every step, on 1 to 4 ranks:
//!
//! - the element map equals a brute-force overlap search over all old and
//!   new elements gathered on rank 0 (first old element, count, level
//!   change);
//! - a trilinear nodal field (two components) sampled on the old mesh is
//!   transferred exactly (1e-12) to every new node, hanging ones included;
//! - an element field is copied into refined and unchanged elements and
//!   averaged by volume into coarsened ones, so its integral is conserved
//!   to round-off;
//! - the transferred values, gathered by global node and element number,
//!   are the same bits on every rank count.
//!
//! Then a smooth field transferred from a uniform mesh to its refinement:
//! the error at the new nodes falls about 4 times per level (trilinear
//! interpolation is second order).
//!
//! Run by `cargo test`, this program launches itself under `mpirun`.

mod common;

use std::cell::RefCell;
use std::rc::Rc;
use std::time::Duration;

use octmesh::internals::classify::{CutRule, Keep};
use octmesh::internals::config::Config;
use octmesh::internals::mesh::{transfer_elements, transfer_nodes, ElementMap, Mesh, MeshOptions};
use octmesh::internals::octree::adapt::Adapt;
use octmesh::internals::octree::domain::Domain;
use octmesh::internals::parallel::comm::{CommRef, MpiComm};
use octmesh::internals::pipeline::{Event, Observer, Session};
use octmesh::internals::refine::NO_LIMIT;
use octmesh::{Connectivity, LinearOctree, Octant};

const STEPS: u32 = 6;
const MAX_LEVEL: u8 = 6;
const STEP_X: i64 = 20_972;

fn trilinear(p: [f64; 3]) -> [f64; 2] {
    let [x, y, z] = p;
    [
        1.0 + 2.0 * x - 3.0 * y + 0.5 * z + 4.0 * x * y - 2.0 * y * z
            + 3.0 * x * z
            + 5.0 * x * y * z,
        -2.0 + x * y * z - 0.25 * x,
    ]
}

fn smooth(p: [f64; 3]) -> f64 {
    (2.0 * p[0]).sin() * (3.0 * p[1]).cos() + (p[2] * p[0]).exp()
}

fn mesh(t: &LinearOctree, d: &Domain) -> Mesh {
    Mesh::build(t, d, None, &MeshOptions::default()).unwrap()
}

/// A hash of the values in a global order: rank 0 gathers (key, bits)
/// pairs, sorts them and folds them (0 elsewhere); a key with two values
/// fails.
fn hash_by_global(comm: &CommRef, pairs: Vec<(u64, u64)>) -> u64 {
    let flat: Vec<u64> = pairs.iter().flat_map(|&(g, b)| [g, b]).collect();
    let mut all: Vec<(u64, u64)> = common::gather(comm, flat)
        .concat()
        .chunks_exact(2)
        .map(|w| (w[0], w[1]))
        .collect();
    all.sort_unstable();
    all.dedup();
    if comm.rank() == 0 {
        let mut g: Vec<u64> = all.iter().map(|a| a.0).collect();
        g.dedup();
        assert_eq!(
            g.len(),
            all.len(),
            "a node has different values on two ranks"
        );
    }
    all.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &(g, b)| {
        (h ^ g ^ b.rotate_left(17)).wrapping_mul(0x0100_0000_01b3)
    })
}

/// Rank 0 checks the map against every old element overlapping each new
/// one.
fn check_map(comm: &CommRef, old: &Mesh, new: &Mesh, map: &ElementMap) {
    let old_keys = common::gather(comm, old.elements().iter().map(|o| o.key()).collect()).concat();
    let new_keys = common::gather(comm, new.elements().iter().map(|o| o.key()).collect()).concat();
    let entries: Vec<u64> = (0..new.elements().len())
        .flat_map(|i| {
            [
                map.old_first[i],
                map.old_count[i] as u64,
                map.level_change[i] as i64 as u64,
            ]
        })
        .collect();
    let entries = common::gather(comm, entries).concat();
    if comm.rank() != 0 {
        return;
    }
    let old: Vec<Octant> = old_keys.into_iter().map(Octant::from_key).collect();
    assert_eq!(map.uncovered, 0);
    for (k, &key) in new_keys.iter().enumerate() {
        let e = Octant::from_key(key);
        let over: Vec<usize> = (0..old.len()).filter(|&j| old[j].overlaps(e)).collect();
        assert!(!over.is_empty(), "new element {k} overlaps no old one");
        assert!(over.windows(2).all(|w| w[1] == w[0] + 1));
        let finest = over.iter().map(|&j| old[j].level()).max().unwrap();
        let change = e.level() as i64 - finest as i64;
        let got = &entries[3 * k..3 * k + 3];
        assert_eq!(
            (got[0], got[1], got[2] as i64),
            (over[0] as u64, over.len() as u64, change),
            "new element {k} ({e:?})"
        );
    }
}

fn moving_loop(comm: &CommRef) {
    let d = Domain::cube([0.0; 3], 1.0).unwrap();
    let mut t = LinearOctree::new_uniform(comm.clone(), 3).unwrap();
    t.balance(Connectivity::Corner).unwrap();
    let mut old = mesh(&t, &d);
    let (mut refined, mut coarsened) = (0u64, 0u64);
    for step in 1..=STEPS {
        let x = common::SPHERE_START_X + STEP_X * step as i64;
        let s = t
            .adapt(
                |o| match common::sphere_cuts(o, x) {
                    true if o.level() < MAX_LEVEL => Adapt::Refine,
                    true => Adapt::Keep,
                    false => Adapt::Coarsen,
                },
                NO_LIMIT,
            )
            .unwrap();
        refined += s.refined;
        coarsened += s.coarsened;
        t.balance(Connectivity::Corner).unwrap();
        t.partition_for_coarsening().unwrap();
        let new = mesh(&t, &d);

        let map = ElementMap::new(&**comm, &old, &new).unwrap();
        check_map(comm, &old, &new, &map);

        // Trilinear nodal field: exact at every new node.
        let values: Vec<f64> = old.coordinates().into_iter().flat_map(trilinear).collect();
        let (moved, missing) = transfer_nodes(&**comm, &old, &new, 2, &values).unwrap();
        assert_eq!(missing, 0);
        let mut worst = 0f64;
        for (i, p) in new.coordinates().into_iter().enumerate() {
            let want = trilinear(p);
            for c in 0..2 {
                worst = worst.max((moved[2 * i + c] - want[c]).abs());
            }
        }
        let mut w = [worst];
        comm.max_f64(&mut w);
        assert!(
            w[0] < 1e-12,
            "step {step}: trilinear transfer error {}",
            w[0]
        );
        // Nodes by position: global node numbers follow the partition.
        let node_hash = hash_by_global(
            comm,
            new.node_lattice()
                .iter()
                .enumerate()
                .map(|(i, q)| {
                    let at = (q[0] as u64) << 40 | (q[1] as u64) << 20 | q[2] as u64;
                    (at, moved[2 * i].to_bits() ^ moved[2 * i + 1].to_bits())
                })
                .collect(),
        );

        // Element field: copy and volume mean, integral conserved.
        let centre = |o: &Octant| {
            let (lo, hi) = o.bounds_f64();
            std::array::from_fn::<f64, 3, _>(|k| (lo[k] + hi[k]) / 2.0 / 524_288.0)
        };
        let ev: Vec<f64> = old.elements().iter().map(|o| smooth(centre(o))).collect();
        let got = transfer_elements(&**comm, &old, &new, 1, &ev).unwrap();
        let volume = |o: &Octant| (o.side() as f64 / 524_288.0).powi(3);
        let local = [
            old.elements()
                .iter()
                .zip(&ev)
                .map(|(o, v)| volume(o) * v)
                .sum::<f64>(),
            new.elements()
                .iter()
                .zip(&got)
                .map(|(o, v)| volume(o) * v)
                .sum::<f64>(),
        ];
        let parts = common::gather(comm, local.iter().map(|v| v.to_bits()).collect()).concat();
        if comm.rank() == 0 {
            let sum =
                |k: usize| -> f64 { parts.chunks_exact(2).map(|w| f64::from_bits(w[k])).sum() };
            let (before, after) = (sum(0), sum(1));
            assert!(
                (before - after).abs() < 1e-13 * before.abs(),
                "step {step}: integral {before} became {after}"
            );
        }
        for (i, e) in new.elements().iter().enumerate() {
            if map.level_change[i] >= 0 && map.old_count[i] == 1 {
                // The old element's own value: computed again from it.
                let o = e.ancestor(e.level() - map.level_change[i] as u8);
                assert_eq!(got[i], smooth(centre(&o)), "element {i}");
            }
        }
        let first = new.first_element();
        let element_hash = hash_by_global(
            comm,
            got.iter()
                .enumerate()
                .map(|(i, v)| (first + i as u64, v.to_bits()))
                .collect(),
        );
        if comm.rank() == 0 {
            println!(
                "STEP {step} elements {} nodes {node_hash:016x} elements {element_hash:016x}",
                new.counts().elements
            );
        }
        old = new;
    }
    if comm.rank() == 0 {
        assert!(refined > 0 && coarsened > 0);
    }
}

/// The largest error of a smooth field transferred from the uniform mesh
/// at `level` to the uniform mesh one level finer.
fn refinement_error(comm: &CommRef, level: u8) -> f64 {
    let d = Domain::cube([0.0; 3], 1.0).unwrap();
    let mut t = LinearOctree::new_uniform(comm.clone(), level).unwrap();
    t.balance(Connectivity::Corner).unwrap();
    let old = mesh(&t, &d);
    t.refine_once(level + 1, |_| true, NO_LIMIT).unwrap();
    t.balance(Connectivity::Corner).unwrap();
    t.partition().unwrap();
    let new = mesh(&t, &d);
    let values: Vec<f64> = old.coordinates().into_iter().map(smooth).collect();
    let (moved, _) = transfer_nodes(&**comm, &old, &new, 1, &values).unwrap();
    let mut worst = [new
        .coordinates()
        .into_iter()
        .zip(&moved)
        .map(|(p, v)| (v - smooth(p)).abs())
        .fold(0.0, f64::max)];
    comm.max_f64(&mut worst);
    worst[0]
}

/// Collects the counts of the `classify` phases.
struct Classified(Rc<RefCell<Vec<u64>>>);

impl Observer for Classified {
    fn event(&mut self, e: &Event<'_>) {
        if let Event::Phase {
            name: "classify",
            count: Some(n),
            ..
        } = e
        {
            self.0.borrow_mut().push(*n);
        }
    }
}

/// A fluid mesh around the built-in sphere through a session, adapted
/// near a moving point: the classes carried across adapt, balance and the
/// partitions equal a fresh classification, and only some leaves are
/// classified again; the nodal transfer through the session is exact for a
/// trilinear field on the kept elements.
fn carried_classes(comm: &CommRef) {
    let mut config = Config::default();
    config.surface.file = "sphere".into();
    config.domain.cube = Some([-2.0, -2.0, -2.0, 4.0]);
    let mut s = Session::new(comm.clone(), config);
    s.load_surface().unwrap();
    s.refine_surface(5).unwrap();
    s.balance(Connectivity::Corner).unwrap();
    s.partition().unwrap();
    s.keep_previous_mesh(true);
    s.build_mesh(Keep::Outside, CutRule::Center).unwrap();
    let seen = Rc::new(RefCell::new(Vec::new()));
    s.set_observer(Box::new(Classified(seen.clone())));
    let rule = s.classified_with().expect("classified by the mesh");
    let mut total_redone = 0;
    for step in 0..4u32 {
        // A point moving along x; leaves near it refined to level 7.
        let p = [-1.2 + 0.5 * step as f64, 0.1, 0.0];
        let near = |o: Octant| {
            let (lo, hi) = o.bounds_f64();
            let side = 4.0 / 524_288.0;
            (0..3).all(|k| {
                let (a, b) = (-2.0 + lo[k] * side, -2.0 + hi[k] * side);
                p[k] >= a - 0.3 && p[k] <= b + 0.3
            })
        };
        let old_coords = s.mesh().unwrap().coordinates();
        let values: Vec<f64> = old_coords.iter().map(|&x| trilinear(x)[0]).collect();
        s.adapt(
            |o| match (near(o), o.level()) {
                (true, l) if l < 7 => Adapt::Refine,
                (false, l) if l > 5 => Adapt::Coarsen,
                _ => Adapt::Keep,
            },
            None,
        )
        .unwrap();
        s.balance(Connectivity::Corner).unwrap();
        s.partition_for_coarsening(None::<fn(Octant) -> u64>)
            .unwrap();
        let carried = s.leaf_classes().expect("classes carried").to_vec();
        let leaves = s.tree().unwrap().global_len();
        let redone: u64 = seen.borrow_mut().drain(..).sum();
        assert!(redone < leaves / 2, "{redone} of {leaves} classified again");
        total_redone += redone;
        s.classify(rule).unwrap();
        seen.borrow_mut().clear();
        assert_eq!(s.leaf_classes().unwrap(), &carried[..], "step {step}");
        s.build_mesh(Keep::Outside, CutRule::Center).unwrap();
        let (moved, missing) = s.transfer_nodes(1, &values).unwrap();
        let new = s.mesh().unwrap();
        let mut worst = [new
            .coordinates()
            .iter()
            .zip(&moved)
            .filter(|(_, v)| !v.is_nan())
            .map(|(&x, v)| (v - trilinear(x)[0]).abs())
            .fold(0.0, f64::max)];
        comm.max_f64(&mut worst);
        assert!(worst[0] < 1e-12, "step {step}: {}", worst[0]);
        if comm.rank() == 0 {
            println!("CLASSES step {step} classified again {redone} of {leaves}, nodes without an old element {missing}");
        }
    }
    assert!(total_redone > 0, "no leaf near the surface changed");
}

/// Collects every phase (name, seconds, count).
struct Phases(Rc<RefCell<Vec<(String, f64, u64)>>>);

impl Observer for Phases {
    fn event(&mut self, e: &Event<'_>) {
        if let Event::Phase {
            name,
            seconds,
            count,
        } = e
        {
            let n = count.unwrap_or(0);
            self.0.borrow_mut().push((name.to_string(), *seconds, n));
        }
    }
}

/// `OCTMESH_TRANSFER_CHILD=bench OCTMESH_TRANSFER_LEVEL=L mpirun -np P
/// <this test>`: one adaptation step of the fluid mesh around the sphere
/// at level L (the leaves in the upper cap's box refined once, the far
/// field coarsened once), then the classes carried against a fresh
/// classification, and the transfers against the mesh build. Prints one
/// BENCH line on rank 0.
fn bench(comm: &CommRef) {
    let level: u8 = std::env::var("OCTMESH_TRANSFER_LEVEL")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(8);
    let mut config = Config::default();
    config.surface.file = "sphere".into();
    config.domain.cube = Some([-2.0, -2.0, -2.0, 4.0]);
    let mut s = Session::new(comm.clone(), config);
    s.load_surface().unwrap();
    s.refine_surface(level).unwrap();
    s.partition().unwrap();
    s.balance(Connectivity::Corner).unwrap();
    s.partition().unwrap();
    s.keep_previous_mesh(true);
    s.build_mesh(Keep::Outside, CutRule::Center).unwrap();
    let rule = s.classified_with().unwrap();
    let old = s.mesh().unwrap();
    let values: Vec<f64> = old.coordinates().iter().map(|&x| trilinear(x)[0]).collect();
    let evalues = vec![1.0; old.elements().len()];
    let phases = Rc::new(RefCell::new(Vec::new()));
    s.set_observer(Box::new(Phases(phases.clone())));
    let to_user = |o: Octant| {
        let (lo, hi) = o.bounds_f64();
        let h = 4.0 / 524_288.0;
        let c: [f64; 3] = std::array::from_fn(|k| -2.0 + (lo[k] + hi[k]) / 2.0 * h);
        c
    };
    s.adapt(
        |o| {
            let c = to_user(o);
            if c[2] > 0.5 && c[0].abs() < 1.2 && c[1].abs() < 1.2 && o.level() <= level {
                Adapt::Refine
            } else if c[0] < -1.2 && o.level() > 3 {
                Adapt::Coarsen
            } else {
                Adapt::Keep
            }
        },
        None,
    )
    .unwrap();
    s.balance(Connectivity::Corner).unwrap();
    s.partition_for_coarsening(None::<fn(Octant) -> u64>)
        .unwrap();
    s.build_mesh(Keep::Outside, CutRule::Center).unwrap();
    s.element_map().unwrap();
    s.transfer_elements(1, &evalues).unwrap();
    s.transfer_nodes(1, &values).unwrap();
    s.classify(rule).unwrap();
    if comm.rank() == 0 {
        let all = phases.borrow();
        let sum = |names: &[&str]| -> f64 {
            all.iter()
                .filter(|p| names.contains(&p.0.as_str()))
                .map(|p| p.1)
                .sum()
        };
        let carried: Vec<String> = all
            .iter()
            .filter(|p| p.0 == "classify")
            .map(|p| format!("{:.4} s ({} leaves)", p.1, p.2))
            .collect();
        let transfers: Vec<String> = all
            .iter()
            .filter(|p| p.0 == "transfer")
            .map(|p| format!("{:.4}", p.1))
            .collect();
        println!(
            "BENCH np={} level={level} leaves={} elements={}: classify carried {} (the last: \
             all again); mesh build (ghost nodes numbering connectivity) {:.4} s; transfers \
             (map, elements, nodes) {} s",
            comm.size(),
            s.tree().unwrap().global_len(),
            s.mesh().unwrap().counts().elements,
            carried.join(", "),
            sum(&["ghost", "nodes", "numbering", "connectivity"]),
            transfers.join(", ")
        );
    }
}

fn child(mode: &str) {
    let universe = mpi::initialize().expect("MPI init");
    let comm: CommRef = Rc::new(MpiComm::new(universe.world()));
    if mode == "bench" {
        bench(&comm);
        return;
    }
    moving_loop(&comm);
    carried_classes(&comm);
    let errors: Vec<f64> = (2..=5).map(|l| refinement_error(&comm, l)).collect();
    if comm.rank() == 0 {
        for w in errors.windows(2) {
            let ratio = w[0] / w[1];
            assert!(ratio > 3.0, "error ratio {ratio} per level: {errors:?}");
        }
        println!("ERRORS {errors:.3?}");
        println!("DONE np {}", comm.size());
    }
}

fn main() {
    common::runner::main("transfer", child, |r| {
        let prefixes = ["STEP", "ERRORS", "CLASSES"];
        let limit = Duration::from_secs(600);
        let count = STEPS as usize + 5;
        let outputs = r.identical_on_ranks(1..=4, "run", "DONE", &prefixes, count, limit);
        for (np, stdout) in &outputs {
            let errors = stdout.lines().find(|l| l.starts_with("ERRORS"));
            println!("np {np}: {}", errors.expect("an ERRORS line"));
        }
    });
}
