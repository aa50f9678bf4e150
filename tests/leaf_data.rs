//! Per-leaf user data through an adaptive loop (`octmesh::internals::octree::leaf_data`): a
//! sphere moves through the cube for 50 steps; every step refines the
//! leaves its surface cuts (up to level 6) and coarsens the families it
//! does not cut (odd steps with `adapt_with_data`, even steps with
//! `refine_once_with_data` then `coarsen_with_data`, recursive every tenth
//! step), balances (corner) and partitions for coarsening; every seventh
//! step also partitions by weight first, every fifth by weight keeping
//! families. Each leaf carries 16 bytes: its own key and a value. The
//! replace callbacks compute the children's keys
//! from the parent's stored key (and the parent's from the first child's),
//! prolong the value by copy and restrict it by the mean. Checked after
//! every step, on 1 to 4 ranks:
//!
//! - every leaf's stored key is its own key (the data moved with it);
//! - the integral (sum of volume x value) equals the initial one to
//!   round-off;
//! - the leaf counts and the integral, summed in global leaf order, are
//!   identical bit for bit on every rank count.
//!
//! (The counts of coarsened families may differ: a recursive coarsening
//! does not merge a family that its own parents complete across a rank
//! boundary, p4est's rule; on 3 ranks one such family stays at step 50,
//! and balance splits the family merged on other rank counts back, so the
//! leaves are the same.)
//!
//! Run by `cargo test`, this program launches itself under `mpirun`.

mod common;

use std::rc::Rc;
use std::time::Duration;

use octmesh::internals::octree::adapt::Adapt;
use octmesh::internals::octree::leaf_data::{LeafData, Replace};
use octmesh::internals::parallel::comm::{CommRef, MpiComm};
use octmesh::internals::refine::NO_LIMIT;
use octmesh::{Connectivity, LinearOctree, Octant, Result};

const STEPS: u32 = 50;
const LEVEL: u8 = 3;
const MAX_LEVEL: u8 = 6;

// The sphere of the adaptation tests moves 6000 along x per step.
const STEP_X: i64 = 6_000;

fn cut(o: Octant, step: u32) -> bool {
    common::sphere_cuts(o, common::SPHERE_START_X + STEP_X * step as i64)
}

fn key(d: &[u8]) -> u64 {
    u64::from_le_bytes(d[..8].try_into().unwrap())
}

fn value(d: &[u8]) -> f64 {
    f64::from_le_bytes(d[8..16].try_into().unwrap())
}

fn put(d: &mut [u8], k: u64, v: f64) {
    d[..8].copy_from_slice(&k.to_le_bytes());
    d[8..16].copy_from_slice(&v.to_le_bytes());
}

/// Prolongs by copy, restricts by the mean; keys from the stored ones.
fn replace(mut r: Replace<'_>) -> Result<()> {
    let stored: Vec<Octant> = (0..r.outgoing.len())
        .map(|i| Octant::from_key(key(r.outgoing_datum(i))))
        .collect();
    assert_eq!(stored, r.outgoing, "outgoing data belongs to other leaves");
    match (r.outgoing.len(), r.incoming.len()) {
        (8, 1) => {
            let mean = (0..8).map(|i| value(r.outgoing_datum(i))).sum::<f64>() / 8.0;
            let parent = stored[0].parent();
            assert_eq!(parent, r.incoming[0]);
            put(r.incoming_datum(0), parent.key(), mean);
        }
        (1, n) => {
            let v = value(r.outgoing_datum(0));
            let children = stored[0].children();
            let incoming = r.incoming;
            for (i, &o) in incoming.iter().enumerate() {
                // Refinement: the stored parent's children; balance (n may
                // be more than 8): a descendant of it.
                let k = if n == 8 {
                    children[i]
                } else {
                    assert!(stored[0].is_ancestor_of(o));
                    o
                };
                put(r.incoming_datum(i), k.key(), v);
            }
        }
        other => panic!("unexpected replacement {other:?}"),
    }
    Ok(())
}

/// The integral summed in global leaf order on rank 0 (0 elsewhere), and
/// this rank's own part; checks every leaf's key.
fn integral(t: &LinearOctree, d: &LeafData) -> (f64, f64) {
    assert_eq!(d.len(), t.local_len());
    let mut terms = Vec::with_capacity(t.local_len());
    for (i, &o) in t.leaves().iter().enumerate() {
        assert_eq!(
            key(d.get(i)),
            o.key(),
            "leaf {i} carries another leaf's data"
        );
        terms.push((o.side() as f64).powi(3) * value(d.get(i)));
    }
    let local: f64 = terms.iter().sum();
    let p = t.comm().size();
    let mut counts = vec![0usize; p];
    counts[0] = terms.len();
    let bits: Vec<u64> = terms.iter().map(|x| x.to_bits()).collect();
    let (all, _) = t.comm().alltoallv_u64(&bits, &counts);
    (all.iter().map(|&b| f64::from_bits(b)).sum(), local)
}

fn child() {
    let universe = mpi::initialize().expect("MPI init");
    let comm: CommRef = Rc::new(MpiComm::new(universe.world()));
    let mut t = LinearOctree::new_uniform(comm.clone(), LEVEL).unwrap();
    let mut d = LeafData::from_fn(&t, 16, |o, b| {
        let c = o.coords().map(|x| x as f64 / 524_288.0);
        put(
            b,
            o.key(),
            1.0 + c[0] + 2.0 * c[1] * c[1] + (3.0 * c[2]).sin() / 3.0,
        );
    });
    t.partition_for_coarsening_with_data(&mut d).unwrap();
    let (start, _) = integral(&t, &d);
    let mut start = [start];
    comm.max_f64(&mut start);
    let (mut worst, mut refined, mut coarsened) = (0f64, 0u64, 0u64);
    for step in 1..=STEPS {
        let s = if step % 2 == 1 {
            let decide = |o: Octant| match cut(o, step) {
                true if o.level() < MAX_LEVEL => Adapt::Refine,
                true => Adapt::Keep,
                false => Adapt::Coarsen,
            };
            let s = t
                .adapt_with_data(&mut d, decide, NO_LIMIT, replace)
                .unwrap();
            (s.refined, s.coarsened)
        } else {
            let split = |o: Octant| cut(o, step);
            let r = t
                .refine_once_with_data(&mut d, MAX_LEVEL, split, NO_LIMIT, replace)
                .unwrap();
            let merge = |f: &[Octant; 8]| f.iter().all(|&o| !cut(o, step));
            let c = t
                .coarsen_with_data(&mut d, step % 10 == 0, merge, replace)
                .unwrap();
            (r.refined, c.coarsened)
        };
        refined += s.0;
        coarsened += s.1;
        t.balance_with_data(&mut d, Connectivity::Corner, NO_LIMIT, replace)
            .unwrap();
        if step % 7 == 0 {
            t.partition_weighted_with_data(&mut d, |o| 1 + o.level() as u64)
                .unwrap();
            integral(&t, &d);
        }
        if step % 5 == 0 {
            t.partition_for_coarsening_weighted_with_data(&mut d, |o| 1 + o.level() as u64)
                .unwrap();
            integral(&t, &d);
        }
        t.partition_for_coarsening_with_data(&mut d).unwrap();
        let (total, _) = integral(&t, &d);
        if comm.rank() == 0 {
            let rel = (total - start[0]).abs() / start[0];
            worst = worst.max(rel);
            assert!(rel < 1e-12, "step {step}: integral {total} vs {}", start[0]);
            println!(
                "STEP {step} leaves {} integral {:016x}",
                t.global_len(),
                total.to_bits()
            );
        }
    }
    if comm.rank() == 0 {
        assert!(refined > 0 && coarsened > 0, "{refined} {coarsened}");
        println!(
            "DONE np {} refined {refined} coarsened {coarsened} leaves {} \
             worst relative integral change {worst:.2e}",
            comm.size(),
            t.global_len()
        );
    }
}

fn main() {
    common::runner::main(
        "leaf_data",
        |_| child(),
        |r| {
            let limit = Duration::from_secs(600);
            let outputs =
                r.identical_on_ranks(1..=4, "run", "DONE", &["STEP"], STEPS as usize, limit);
            for (_, stdout) in &outputs {
                let done = stdout.lines().find(|l| l.starts_with("DONE"));
                println!("{}", done.expect("a DONE line"));
            }
        },
    );
}
