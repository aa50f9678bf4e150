//! Adaptation equal to p4est, step by step: a sphere moves through the cube;
//! every step refines the leaves its surface cuts, coarsens the families it
//! does not cut, balances (corner) and partitions for coarsening. The
//! reference is `tools/p4est_ref/octmesh_p4est_adapt` (p8est_refine,
//! p8est_coarsen, p8est_balance, p8est_partition_ext with
//! partition_for_coarsening); see its header for the sphere and the files.
//!
//! Two cases: from the uniform level 3 down to level 8, and from the root
//! down to level 5 (the equal split leaves ranks empty and its cuts fall
//! inside the only family). Run by `cargo test`, this program runs the
//! reference and itself under `mpirun` on 1 to 4 ranks, octmesh twice: with `refine_once` then
//! `coarsen`, and with one `adapt` pass (the same rule: cut leaves refine,
//! uncut ones ask to coarsen), then partitioning by weight (the leaf's
//! level) for coarsening, then coarsening recursively. After every step the leaves and every
//! rank's count must equal p4est's.

mod common;

use std::path::{Path, PathBuf};
use std::rc::Rc;
use std::time::Duration;

use octmesh::internals::io::leaves::write_leaves;
use octmesh::internals::octree::adapt::Adapt;
use octmesh::internals::parallel::comm::{CommRef, MpiComm};
use octmesh::internals::refine::NO_LIMIT;
use octmesh::{Connectivity, LinearOctree, Octant};

const STEPS: u32 = 10;
/// Initial level and maximum level of each case.
const CASES: [(u8, u8); 2] = [(3, 8), (0, 5)];

// The sphere of the reference program moves this far along x per step.
const STEP_X: i64 = 20_972;

/// Whether the closed box of `o` meets the surface of the sphere at `step`.
fn cut(o: Octant, step: u32) -> bool {
    common::sphere_cuts(o, common::SPHERE_START_X + STEP_X * step as i64)
}

fn main() {
    let child_main = |arg: &str| {
        let a: Vec<&str> = arg.splitn(4, ':').collect();
        let level = |i: usize| a[i].parse::<u8>().expect("MODE:LEVEL:MAX:DIR");
        child(a[0], level(1), level(2), Path::new(a[3]));
    };
    common::runner::main("adapt_p4est", child_main, |r| {
        let base = common::scratch("adapt_p4est");
        // Builds both reference programs.
        r.test("the p4est reference builds", || {
            common::p4est_ref();
        });
        let mut moved_cuts = 0;
        for np in 1..=4 {
            for (level, max_level) in CASES {
                let name = format!(
                    "levels {level}-{max_level} on {}",
                    common::runner::ranks(np)
                );
                r.test(&name, || {
                    moved_cuts += equal_to_p4est(&base, np, level, max_level);
                });
            }
        }
        // The option must have been exercised: an equal split inside a family.
        r.test("the equal split falls inside a family", || {
            assert!(moved_cuts > 0, "the equal split never fell inside a family");
            println!("{moved_cuts} cuts moved to keep families together");
        });
    });
}

/// The reference and octmesh on `np` ranks from `level` to `max_level`,
/// in every mode: the same leaves and counts at every step. Returns the
/// number of cuts the reference moved to keep families together.
fn equal_to_p4est(base: &Path, np: usize, level: u8, max_level: u8) -> usize {
    let reference = common::repo()
        .join("tools")
        .join("p4est_ref")
        .join("octmesh_p4est_adapt");
    let limit = Duration::from_secs(300);
    let mut moved_cuts = 0;
    let dir = |what: &str| -> PathBuf {
        let d = base.join(format!("np{np}_{level}_{max_level}_{what}"));
        std::fs::create_dir_all(&d).unwrap();
        d
    };
    let mut equal_split = Vec::new();
    for variant in ["", "--weighted", "--recursive"] {
        let weighted = variant == "--weighted";
        let theirs = dir(&format!("p4est{variant}"));
        let mut args = vec![
            "--steps".to_string(),
            STEPS.to_string(),
            "--level".into(),
            level.to_string(),
            "--max-level".into(),
            max_level.to_string(),
            "--out".into(),
            theirs.display().to_string(),
        ];
        if !variant.is_empty() {
            args.push(variant.into());
        }
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = common::mpirun(np, &reference, &args, limit);
        assert!(
            out.status.success(),
            "p4est reference on {np} ranks failed:\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let reference_counts = read_counts(&theirs);
        let moved = (!weighted).then_some(&mut moved_cuts);
        check_reference(&reference_counts, &theirs, np, moved);
        if variant.is_empty() {
            equal_split = reference_counts.clone();
        } else if weighted && np == 3 {
            // Weights by level move the boundaries (on 2 and 4 ranks the
            // sphere's symmetry in y and z gives every rank equal weight).
            assert_ne!(equal_split, reference_counts, "weights changed nothing");
        } else if variant == "--recursive" && level == 3 {
            assert_ne!(equal_split, reference_counts, "recursion changed nothing");
        }
        let modes: &[&str] = match variant {
            "--weighted" => &["weighted"],
            "--recursive" => &["recursive"],
            _ => &["separate", "adapt"],
        };
        for &mode in modes {
            let ours = dir(mode);
            let arg = format!("{mode}:{level}:{max_level}:{}", ours.display());
            print!("{}", common::runner::launch(np, &arg, limit));
            let counts = read_counts(&ours);
            for step in 0..=STEPS {
                let tag = format!("np {np}, levels {level}-{max_level}, {mode}, step {step}");
                let file = format!("step_{step}.bin");
                let (a, b) = (
                    common::leaves(&ours.join(&file)),
                    common::leaves(&theirs.join(&file)),
                );
                assert_eq!(a.len(), b.len(), "{tag}: octmesh and p4est leaf counts");
                if let Some(i) = (0..a.len()).find(|&i| a[i] != b[i]) {
                    panic!(
                        "{tag}: first difference at leaf {i}: octmesh {:?}, p4est {:?}",
                        a[i], b[i]
                    );
                }
                assert_eq!(
                    counts[step as usize], reference_counts[step as usize],
                    "{tag}: step, refined, coarsened, leaves, leaves per rank"
                );
            }
            println!(
                "np {np}, levels {level}-{max_level}, {mode}: {} steps equal to p4est, \
                 {} leaves at the end",
                STEPS, counts[STEPS as usize][3]
            );
        }
    }
    moved_cuts
}

/// The lines of `counts.txt`: step, refined, coarsened, leaves, per rank.
fn read_counts(dir: &Path) -> Vec<Vec<u64>> {
    let text = std::fs::read_to_string(dir.join("counts.txt")).expect("counts.txt");
    let rows: Vec<Vec<u64>> = text
        .lines()
        .map(|l| l.split_whitespace().map(|w| w.parse().unwrap()).collect())
        .collect();
    assert_eq!(
        rows.len(),
        STEPS as usize + 1,
        "{}: one line per step",
        dir.display()
    );
    rows
}

/// Checks made on the reference alone, so that the comparison means
/// something: the sequence refines and coarsens, every step's leaves are a
/// complete balanced octree, and no rank boundary splits a family.
fn check_reference(rows: &[Vec<u64>], dir: &Path, np: usize, mut moved: Option<&mut usize>) {
    let refined: u64 = rows.iter().map(|r| r[1]).sum();
    let coarsened: u64 = rows.iter().map(|r| r[2]).sum();
    assert!(
        refined > 0 && coarsened > 0,
        "refined {refined}, coarsened {coarsened}"
    );
    // Coarsening behind the moving sphere, not only at the start.
    assert!(
        rows[STEPS as usize][2] > 0,
        "nothing coarsened in the last step"
    );
    for (step, row) in rows.iter().enumerate().skip(1) {
        let l = common::leaves(&dir.join(format!("step_{step}.bin")));
        assert_eq!(l.len() as u64, row[3]);
        common::assert_complete_linear(&l);
        common::assert_balanced(&l, Connectivity::Corner);
        let n = l.len() as u64;
        let mut start = 0u64;
        for (r, &c) in row[4..].iter().enumerate() {
            if r > 0 && c > 0 && start < n {
                let first = l[start as usize];
                // The rank starts a family, or its first leaf's family is
                // not eight leaves.
                let k = first.child_id() as u64;
                let split = k > 0
                    && start >= k
                    && (0..8).all(|j| {
                        l.get((start - k + j) as usize) == Some(&first.parent().child(j as u32))
                    });
                assert!(!split, "step {step}: rank {r} starts inside a family");
                let equal = (r as u128 * n as u128 / np as u128) as u64;
                if let Some(m) = moved.as_deref_mut() {
                    *m += (equal != start) as usize;
                }
            }
            start += c;
        }
        assert_eq!(start, n);
    }
}

/// The octmesh side: the same sequence through the Rust API.
fn child(mode: &str, level: u8, max_level: u8, dir: &Path) {
    let universe = mpi::initialize().expect("MPI init");
    let comm: CommRef = Rc::new(MpiComm::new(universe.world()));
    if mode == "separate" {
        split_families_stay(&comm);
    }
    let mut t = LinearOctree::new_uniform(comm.clone(), level).unwrap();
    let mut lines = vec![line(&t, 0, 0, 0)];
    write_leaves(&t, &dir.join("step_0.bin"), "adapt").unwrap();
    for step in 1..=STEPS {
        let (refined, coarsened) = match mode {
            "separate" | "weighted" | "recursive" => {
                let r = t
                    .refine_once(max_level, |o| cut(o, step), NO_LIMIT)
                    .unwrap();
                let c = t
                    .coarsen(mode == "recursive", |f| f.iter().all(|&o| !cut(o, step)))
                    .unwrap();
                (r.refined, c.coarsened)
            }
            "adapt" => {
                let s = t
                    .adapt(
                        |o| match cut(o, step) {
                            true if o.level() < max_level => Adapt::Refine,
                            true => Adapt::Keep,
                            false => Adapt::Coarsen,
                        },
                        NO_LIMIT,
                    )
                    .unwrap();
                (s.refined, s.coarsened)
            }
            _ => panic!("unknown mode {mode}"),
        };
        t.balance(Connectivity::Corner).unwrap();
        if mode == "weighted" {
            t.partition_for_coarsening_weighted(|o| o.level() as u64)
                .unwrap();
        } else {
            t.partition_for_coarsening().unwrap();
        }
        write_leaves(&t, &dir.join(format!("step_{step}.bin")), "adapt").unwrap();
        lines.push(line(&t, step, refined, coarsened));
    }
    if comm.rank() == 0 {
        std::fs::write(dir.join("counts.txt"), lines.concat()).unwrap();
    }
}

/// A family whose leaves are on two ranks is not coarsened, whatever the
/// callback says, until a partition for coarsening brings it together.
fn split_families_stay(comm: &CommRef) {
    let p = comm.size() as u64;
    let mut t = LinearOctree::new_uniform(comm.clone(), 2).unwrap();
    // The uniform split gives rank q the leaves from floor(64 q / p).
    let rank_of = |i: u64| (0..p).rev().find(|&q| q * 64 / p <= i).unwrap();
    let whole = (0..8)
        .filter(|k| rank_of(8 * k) == rank_of(8 * k + 7))
        .count() as u64;
    let mut offered = 0u64;
    let s = t
        .coarsen(false, |_| {
            offered += 1;
            true
        })
        .unwrap();
    let mut all = [offered];
    comm.sum_u64(&mut all);
    assert_eq!(
        (s.coarsened, all[0]),
        (whole, whole),
        "split families offered"
    );
    assert_eq!(t.global_len(), 64 - 7 * whole);
    if whole < 8 {
        t.partition_for_coarsening().unwrap();
        let s = t.coarsen(false, |_| true).unwrap();
        assert_eq!(s.coarsened, 8 - whole, "the rest, once together");
        assert_eq!(t.global_len(), 8);
    }
    t.partition_for_coarsening().unwrap();
    t.coarsen(false, |_| true).unwrap();
    assert_eq!(t.global_len(), 1);
    if comm.rank() == 0 {
        println!(
            "{} of 8 families split on {p} ranks, coarsened after the partition",
            8 - whole
        );
    }
}

/// One line of `counts.txt`, as the reference writes it.
fn line(t: &LinearOctree, step: u32, refined: u64, coarsened: u64) -> String {
    let per_rank: Vec<String> = t
        .global_offsets()
        .windows(2)
        .map(|w| (w[1] - w[0]).to_string())
        .collect();
    format!(
        "{step} {refined} {coarsened} {} {}\n",
        t.global_len(),
        per_rank.join(" ")
    )
}
