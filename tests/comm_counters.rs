//! The byte counters of `MpiComm` against counts worked out by hand for each
//! collective, on 1 to 4 ranks, its count of collective operations, and its
//! time inside collectives against a rank that arrives late.
//!
//! Run by `cargo test`, this program launches itself under `mpirun`; each
//! launched copy checks its own counters and exits non-zero on a mismatch.

mod common;

use std::rc::Rc;
use std::time::Duration;

use octmesh::internals::parallel::comm::{CommRef, MpiComm, Traffic};

fn main() {
    common::runner::main(
        "comm_counters",
        |_| child(),
        |r| {
            r.on_ranks(
                1..=4,
                "run",
                "comm counters agree",
                Duration::from_secs(120),
            );
        },
    );
}

fn check(what: &str, got: Traffic, sent: u64, received: u64) {
    assert_eq!(
        got,
        Traffic { sent, received },
        "{what}: counted {got:?}, expected sent {sent} received {received}"
    );
}

fn child() {
    let universe = mpi::initialize().expect("MPI init");
    let comm: CommRef = Rc::new(MpiComm::new(universe.world()));
    let (r, p) = (comm.rank() as u64, comm.size() as u64);
    check("fresh communicator", comm.traffic(), 0, 0);
    assert_eq!(comm.comm_seconds(), 0.0, "fresh communicator");
    assert_eq!(comm.collectives(), 0, "fresh communicator");

    // Rank r sends q + 1 values to rank q (itself included) and so receives
    // r + 1 values from every rank; nothing else crosses (no counts).
    let counts: Vec<usize> = (0..p as usize).map(|q| q + 1).collect();
    let send: Vec<u64> = counts
        .iter()
        .enumerate()
        .flat_map(|(q, &c)| std::iter::repeat_n(100 * r + q as u64, c))
        .collect();
    let t0 = comm.traffic();
    let (recv, rc) = comm.alltoallv_u64(&send, &counts);
    assert_eq!(recv.len() as u64, (r + 1) * p);
    assert!(rc.iter().all(|&c| c as u64 == r + 1));
    let all_out: u64 = (1..=p).sum();
    check(
        "alltoallv",
        comm.traffic() - t0,
        8 * (all_out - (r + 1)),
        8 * (r + 1) * (p - 1),
    );

    // Sparse exchanges back to back, nothing in between: each rank sends to
    // the next one only, the round in the data, and one rank is sometimes
    // late, so that others run ahead into the next exchange. No message may
    // land in another round.
    for round in 0..60u64 {
        let (next, prev) = (((r + 1) % p) as usize, ((r + p - 1) % p) as usize);
        let n = (round % 3) as usize + 1;
        let mut counts = vec![0usize; p as usize];
        counts[next] = n;
        if r == 0 && round % 7 == 0 {
            std::thread::sleep(Duration::from_millis(5));
        }
        let (recv, rc) = comm.alltoallv_u64(&vec![1000 * round + r; n], &counts);
        assert_eq!(rc[prev], n, "round {round}");
        assert_eq!(rc.iter().sum::<usize>(), n, "round {round}");
        assert_eq!(recv, vec![1000 * round + prev as u64; n], "round {round}");
    }

    let t0 = comm.traffic();
    let mut v = [r, 2 * r, 3];
    comm.max_u64(&mut v);
    assert_eq!(v, [p - 1, 2 * (p - 1), 3]);
    let others = if p > 1 { 24 } else { 0 };
    check("max_u64 of 3 values", comm.traffic() - t0, others, others);

    let t0 = comm.traffic();
    let gathered = comm.allgather_u64(r * r);
    assert_eq!(gathered, (0..p).map(|q| q * q).collect::<Vec<_>>());
    check(
        "allgather_u64",
        comm.traffic() - t0,
        8 * (p - 1),
        8 * (p - 1),
    );

    // An all-gather of r + 1 bytes from rank r: the lengths (one value),
    // then this rank's bytes to each other rank and theirs back.
    let t0 = comm.traffic();
    let c0 = comm.collectives();
    let mine = vec![r as u8; r as usize + 1];
    let (all, lens) = comm.allgatherv_bytes(&mine);
    let expected: Vec<u8> = (0..p).flat_map(|q| vec![q as u8; q as usize + 1]).collect();
    assert_eq!(all, expected);
    assert_eq!(lens, (1..=p as usize).collect::<Vec<_>>());
    check(
        "allgatherv_bytes",
        comm.traffic() - t0,
        (8 + r + 1) * (p - 1),
        8 * (p - 1) + all.len() as u64 - (r + 1),
    );
    assert_eq!(
        comm.collectives() - c0,
        2,
        "allgatherv_bytes: lengths and bytes"
    );

    // A broadcast of 5 bytes: the 8-byte length and the bytes, once per
    // receiving rank at the root.
    let root = (p - 1) as usize;
    let t0 = comm.traffic();
    let mut msg = if r as usize == root {
        b"hello".to_vec()
    } else {
        Vec::new()
    };
    comm.broadcast_bytes(root, &mut msg);
    assert_eq!(msg, b"hello");
    if r as usize == root {
        check(
            "broadcast at the root",
            comm.traffic() - t0,
            13 * (p - 1),
            0,
        );
    } else {
        check("broadcast at a receiver", comm.traffic() - t0, 0, 13);
    }

    let t0 = comm.traffic();
    comm.barrier();
    check("barrier", comm.traffic() - t0, 0, 0);

    // Time inside collectives: rank 0 arrives 200 ms late at a reduction,
    // so every other rank waits about that long inside it; rank 0 does not.
    let late = Duration::from_millis(200);
    comm.barrier();
    let w0 = comm.comm_seconds();
    if r == 0 {
        std::thread::sleep(late);
    }
    let mut v = [r];
    comm.sum_u64(&mut v);
    let waited = comm.comm_seconds() - w0;
    assert!(waited >= 0.0);
    if r > 0 {
        assert!(
            waited >= 0.5 * late.as_secs_f64(),
            "rank {r} waited {waited} s for a rank 200 ms late"
        );
    } else {
        assert!(
            waited < 0.5 * late.as_secs_f64(),
            "rank 0 came last but waited {waited} s"
        );
    }

    // Collective operations: the same count on every rank, whatever the
    // data, and the same on one rank as on several.
    let calls = |what: &str, expected: u64, f: &dyn Fn()| {
        let c0 = comm.collectives();
        f();
        let got = comm.collectives() - c0;
        assert_eq!(got, expected, "{what}: {got} collective operations");
    };
    calls("barrier", 1, &|| comm.barrier());
    calls("max_u64", 1, &|| comm.max_u64(&mut [r, 1, 2]));
    calls("sum_u64", 1, &|| comm.sum_u64(&mut [r]));
    calls("max_f64", 1, &|| comm.max_f64(&mut [r as f64]));
    calls("allgather_u64", 1, &|| {
        comm.allgather_u64(r);
    });
    calls("alltoallv, rank 0 sends nothing", 1, &|| {
        let counts: Vec<usize> = (0..p as usize).map(|_| r as usize).collect();
        let send = vec![7u64; (r * p) as usize];
        comm.alltoallv_u64(&send, &counts);
    });
    calls("broadcast of 5 bytes", 2, &|| {
        let mut msg = b"hello".to_vec();
        comm.broadcast_bytes(0, &mut msg);
    });
    calls("broadcast of nothing", 1, &|| {
        let mut msg = Vec::new();
        comm.broadcast_bytes(0, &mut msg);
    });

    // Over all ranks, what was sent arrived.
    let total = comm.traffic();
    let mut sums = [total.sent, total.received];
    comm.sum_u64(&mut sums);
    assert_eq!(sums[0], sums[1], "sent and received differ over the ranks");
    assert_eq!(sums[0] == 0, p == 1);
    if r == 0 {
        println!("comm counters agree on {p} rank(s)");
    }
}
