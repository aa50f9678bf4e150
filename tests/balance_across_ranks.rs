//! Balance on skewed partitions, with empty ranks and ripples that cross
//! several ranks, compared with the same octree balanced on one process.
//!
//! Run by `cargo test`, this program launches itself under `mpirun` on 1 to
//! 4 ranks; each launched copy does the checks and exits non-zero on a
//! mismatch.

mod common;

use std::rc::Rc;
use std::time::Duration;

use octmesh::internals::parallel::comm::{CommRef, MpiComm, SerialComm};
use octmesh::internals::refine::{build_from_callback, NO_LIMIT};
use octmesh::{Connectivity, LinearOctree, Octant};

fn main() {
    common::runner::main(
        "balance_across_ranks",
        |_| child(),
        |r| {
            r.on_ranks(1..=4, "run", "all cases agree", Duration::from_secs(300));
        },
    );
}

/// All leaves on rank 0 (empty elsewhere).
fn gather(t: &LinearOctree) -> Vec<Octant> {
    let p = t.comm().size();
    let keys: Vec<u64> = t.leaves().iter().map(|o| o.key()).collect();
    let mut counts = vec![0; p];
    counts[0] = keys.len();
    let (all, _) = t.comm().alltoallv_u64(&keys, &counts);
    all.into_iter().map(Octant::from_key).collect()
}

fn towards(p: [u32; 3]) -> impl Fn(Octant) -> bool {
    move |o: Octant| {
        let c = o.coords();
        (0..3).all(|k| c[k] <= p[k] && p[k] < c[k] + o.side())
    }
}

fn child() {
    let universe = mpi::initialize().expect("MPI init");
    let comm: CommRef = Rc::new(MpiComm::new(universe.world()));
    let rank = comm.rank();
    let points = [
        [157_286u32, 91_000, 200_001],
        [262_143, 262_144, 262_143],
        [1, 524_000, 77_777],
    ];
    let mut cases = 0;
    for (pi, p) in points.iter().enumerate() {
        for conn in [Connectivity::Face, Connectivity::Edge, Connectivity::Corner] {
            for skew in ["equal", "front", "single"] {
                let mut t = build_from_callback(comm.clone(), 12, towards(*p), NO_LIMIT).unwrap();
                match skew {
                    "equal" => {
                        t.partition().unwrap();
                    }
                    // Most of the weight on the first leaves: thin ranks
                    // near the fine region, so ripples cross several ranks.
                    "front" => {
                        let split = t.global_len() / 8;
                        let first = t.global_offsets()[rank];
                        let keys: Vec<Octant> = t.leaves().to_vec();
                        let heavy: std::collections::HashSet<Octant> = keys
                            .iter()
                            .enumerate()
                            .filter(|(i, _)| first + (*i as u64) < split)
                            .map(|(_, o)| *o)
                            .collect();
                        t.partition_weighted(|o| if heavy.contains(&o) { 1000 } else { 1 })
                            .unwrap();
                    }
                    // One leaf carries all the weight: the middle ranks are empty.
                    _ => {
                        let target = towards(*p);
                        t.partition_weighted(|o| u64::from(target(o) && o.level() == 12))
                            .unwrap();
                        let counts = t.comm().allgather_u64(t.local_len() as u64);
                        if counts.len() >= 3 {
                            assert!(counts.contains(&0), "expected empty ranks: {counts:?}");
                        }
                    }
                }
                let unbalanced = gather(&t);
                t.balance(conn).unwrap();
                t.check().unwrap();
                let parallel = gather(&t);
                if rank == 0 {
                    let mut s =
                        LinearOctree::from_local_leaves(Rc::new(SerialComm), unbalanced).unwrap();
                    s.balance(conn).unwrap();
                    assert_eq!(
                        s.leaves(),
                        &parallel[..],
                        "point {pi}, {conn:?}, partition {skew}: {} ranks differ from one",
                        comm.size()
                    );
                    common::assert_balanced(&parallel, conn);
                }
                cases += 1;
            }
        }
    }
    if rank == 0 {
        println!(
            "balance_across_ranks on {} ranks: {cases} cases, all cases agree",
            comm.size()
        );
    }
    drop(comm);
    drop(universe);
}
