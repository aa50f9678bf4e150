//! The `comm_bytes`, `comm_calls` and `comm_seconds` fields of `--stats`: nothing crosses
//! ranks on one rank;
//! on two and three ranks every phase that exchanges leaves or nodes reports
//! bytes, and the bytes sent over all ranks equal those received. Also the
//! memory marks and the two partition timings the benchmarks read.

mod common;

use common::{octmesh_ok, scratch};

fn stats(np: usize, dir: &std::path::Path) -> serde_json::Value {
    let path = dir.join(format!("np{np}.json"));
    octmesh_ok(
        np,
        &[
            "mesh",
            "sphere",
            "--level",
            "5",
            "--quiet",
            "--stats",
            path.to_str().unwrap(),
        ],
    );
    serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap()
}

const PHASES: [&str; 10] = [
    "read",
    "construct",
    "refine",
    "partition",
    "balance",
    "classify",
    "ghost",
    "nodes",
    "numbering",
    "connectivity",
];

#[test]
fn one_rank_exchanges_nothing() {
    let j = stats(1, &scratch("comm_bytes_1"));
    for k in PHASES.iter().chain(&["total"]) {
        assert_eq!(j["comm_bytes"][k].as_u64(), Some(0), "phase {k}");
        assert_eq!(j["comm_bytes_sent"][k].as_u64(), Some(0), "phase {k}");
        assert_eq!(j["comm_bytes_received"][k].as_u64(), Some(0), "phase {k}");
    }
    // One rank still calls the collectives (MPI's own copies).
    assert!(j["comm_calls"]["ghost"].as_u64().unwrap() > 0);
    assert_eq!(j["comm_bytes_sum"]["sent"].as_u64(), Some(0));
    assert_eq!(j["comm_bytes_sum"]["received"].as_u64(), Some(0));
    // Collectives on one rank only copy: a small part of each phase.
    let (mut inside, mut phases) = (0.0, 0.0);
    for k in PHASES {
        let lo = j["comm_seconds_min"][k].as_f64().unwrap();
        let hi = j["comm_seconds_max"][k].as_f64().unwrap();
        let phase = j["timings"][k].as_f64().unwrap();
        assert_eq!(lo, hi, "{k}: one rank, one reading");
        assert!(
            hi <= phase + 1e-6,
            "{k}: {hi} s inside collectives in a {phase} s phase"
        );
        inside += hi;
        phases += phase;
    }
    assert!(
        inside < 0.5 * phases,
        "{inside} s inside collectives of {phases} s"
    );
}

#[test]
fn time_inside_collectives_fits_in_the_phases() {
    let j = stats(2, &scratch("comm_seconds_2"));
    let mut sum = 0.0;
    for k in PHASES {
        let lo = j["comm_seconds_min"][k].as_f64().unwrap();
        let hi = j["comm_seconds_max"][k].as_f64().unwrap();
        let phase = j["timings"][k].as_f64().unwrap();
        // A rank's time inside collectives is part of its phase time, which
        // is at most the phase's (largest) time; the barrier that starts
        // each phase is not counted.
        assert!(0.0 <= lo && lo <= hi, "{k}: min {lo} max {hi}");
        assert!(
            hi <= phase + 1e-6,
            "{k}: {hi} s inside collectives in a {phase} s phase"
        );
        sum += hi;
    }
    // Ghost exchange and node numbering cannot happen without collectives.
    for k in ["ghost", "numbering"] {
        assert!(j["comm_seconds_max"][k].as_f64().unwrap() > 0.0, "{k}");
    }
    // The total also covers every phase the run had.
    let extra: f64 = j["comm_seconds_max"]
        .as_object()
        .unwrap()
        .iter()
        .filter(|(k, _)| *k != "total" && !PHASES.contains(&k.as_str()))
        .map(|(_, v)| v.as_f64().unwrap())
        .sum();
    sum += extra;
    let total = j["comm_seconds_max"]["total"].as_f64().unwrap();
    assert!(
        total > 0.0 && total <= sum + 1e-6,
        "total {total}, phases {sum}"
    );
}

#[test]
fn memory_marks_and_partition_steps() {
    let j = stats(2, &scratch("comm_bytes_marks"));
    // High-water marks taken in this order cannot decrease.
    let start = j["rss_start_bytes"].as_u64().unwrap();
    let read = j["rss_after_read_bytes"].as_u64().unwrap();
    let peak = j["peak_rss_bytes"].as_u64().unwrap();
    assert!(
        0 < start && start <= read && read <= peak,
        "{start} {read} {peak}"
    );
    // The two partitions, apart, add up to the partition timing.
    let a = j["partition_timings"]["refined"].as_f64().unwrap();
    let b = j["partition_timings"]["balanced"].as_f64().unwrap();
    let sum = j["timings"]["partition"].as_f64().unwrap();
    assert!(a >= 0.0 && b >= 0.0);
    assert!(
        (a + b - sum).abs() <= 1e-9 * sum.max(1.0),
        "{a} + {b} != {sum}"
    );
}

#[test]
fn sent_equals_received_on_2_and_3_ranks() {
    let dir = scratch("comm_bytes_23");
    let mut calls_by_np = Vec::new();
    for np in [2, 3] {
        let j = stats(np, &dir);
        calls_by_np.push(j["comm_calls"].clone());
        let sent = j["comm_bytes_sum"]["sent"].as_u64().unwrap();
        let received = j["comm_bytes_sum"]["received"].as_u64().unwrap();
        assert!(sent > 0, "np {np}: nothing sent");
        assert_eq!(sent, received, "np {np}");
        // Balance probes, ghost leaves and shared nodes cross the partition
        // boundaries whenever there is more than one rank.
        for k in ["balance", "ghost", "numbering"] {
            let both = j["comm_bytes"][k].as_u64().unwrap();
            let out = j["comm_bytes_sent"][k].as_u64().unwrap();
            assert!(both > 0 && out > 0, "np {np}: no bytes in {k}");
            assert!(
                out <= both,
                "np {np}: {k} sent {out} > sent+received {both}"
            );
            // The maxima of sent and of received bound that of their sum.
            let got = j["comm_bytes_received"][k].as_u64().unwrap();
            assert!(got > 0 && got <= both, "np {np}: {k} received {got}");
            assert!(out + got >= both, "np {np}: {k} {out} + {got} < {both}");
            // Each of these phases takes part in collectives.
            let calls = j["comm_calls"][k].as_u64().unwrap();
            assert!(calls > 0, "np {np}: no collective in {k}");
        }
        let calls = j["comm_calls"].as_object().unwrap();
        let phases: u64 = calls
            .iter()
            .filter(|(k, _)| *k != "total")
            .map(|(_, v)| v.as_u64().unwrap())
            .sum();
        let total = calls["total"].as_u64().unwrap();
        assert!(
            phases <= total,
            "np {np}: {phases} calls in phases > {total}"
        );
        // Each rank's total is at most the sum over ranks and at least an
        // equal share of it.
        let per_rank = j["comm_bytes"]["total"].as_u64().unwrap();
        assert!(per_rank <= sent + received, "np {np}");
        assert!(per_rank * np as u64 >= sent + received, "np {np}");
        // Every phase the run had.
        let phase_sum: u64 = j["comm_bytes"]
            .as_object()
            .unwrap()
            .iter()
            .filter(|(k, _)| *k != "total")
            .map(|(_, v)| v.as_u64().unwrap())
            .sum();
        assert!(phase_sum >= per_rank, "np {np}: phases below the total");
    }
    // The exchanges of the ghost layer, the node numbering and the
    // construction are a fixed number of collectives, whatever the number
    // of ranks.
    for k in ["construct", "refine", "ghost", "numbering"] {
        assert_eq!(
            calls_by_np[0][k], calls_by_np[1][k],
            "{k}: collectives on 2 and 3 ranks"
        );
    }
}
