//! The one runner of the test programs that launch themselves under
//! `mpirun` (`harness = false` in Cargo.toml).
//!
//! Such a program's `main` calls [`main`]: run by `cargo test`, it runs the
//! program's tests, each of which may launch copies of the program under
//! `mpirun` ([`launch`], [`Runner::on_ranks`]); a launched copy finds its
//! mode in `OCTMESH_<PROGRAM>_CHILD` ([`child_var`]) and runs the child
//! function instead. A test fails by panicking. The runner prints
//! `test NAME ... ok` (or `FAILED`, or `skipped` when an oracle was missing
//! and [`super::oracles_required`] is off) for each test and closes with
//! one line CI parses, `PROGRAM: P passed, F failed` (then `, S skipped`
//! and the failed tests' names when there are any); it exits with status 1
//! when a test failed.
//!
//! Usage: `cargo test --release --test PROGRAM [NAME_FILTER]` runs the
//! tests whose name contains the filter.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::Ordering;
use std::sync::OnceLock;
use std::time::Duration;

use super::{mpirun_env, SKIPS};

/// The program's name, set by [`main`].
static PROGRAM: OnceLock<&'static str> = OnceLock::new();

/// The variable that gives a launched copy of `program` its mode:
/// `OCTMESH_<PROGRAM>_CHILD` (`OCTMESH_TRANSFER_CHILD` for `transfer`).
pub fn child_var(program: &str) -> String {
    format!("OCTMESH_{}_CHILD", program.to_uppercase())
}

/// `main` of a self-launching test program named `program` (its name in
/// Cargo.toml): in a launched copy runs `child` with its mode; otherwise
/// runs `tests` on a [`Runner`], prints the closing line and exits 1 if a
/// test failed.
pub fn main(program: &'static str, child: impl FnOnce(&str), tests: impl FnOnce(&mut Runner)) {
    PROGRAM.set(program).expect("runner::main called once");
    if let Ok(mode) = std::env::var(child_var(program)) {
        child(&mode);
        return;
    }
    let mut runner = Runner {
        program,
        filter: filter(),
        passed: 0,
        skipped: 0,
        failed: Vec::new(),
    };
    tests(&mut runner);
    runner.finish();
}

/// The first argument that is not an option (nor an option's value), as
/// libtest takes a name filter.
fn filter() -> Option<String> {
    const WITH_VALUE: [&str; 6] = [
        "--skip",
        "--test-threads",
        "--color",
        "--format",
        "--logfile",
        "-Z",
    ];
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        if WITH_VALUE.contains(&a.as_str()) {
            args.next();
        } else if !a.starts_with('-') {
            return Some(a);
        }
    }
    None
}

/// Launches this program on `np` ranks in `mode` and waits at most
/// `limit`; panics with the output unless every rank succeeded. Returns
/// the standard output. A `skipped: ` line from a launched copy (an oracle
/// missing there) counts as a skip of the calling test.
pub fn launch(np: usize, mode: &str, limit: Duration) -> String {
    let program = PROGRAM.get().expect("runner::main sets the program");
    let me = std::env::current_exe().expect("own path");
    let var = child_var(program);
    let out = mpirun_env(np, &me, &[], &[(&var, mode)], limit);
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{program} ({mode}) on {np} ranks failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    if stdout.lines().any(|l| l.starts_with("skipped: ")) {
        SKIPS.fetch_add(1, Ordering::Relaxed);
    }
    stdout
}

/// "1 rank", "3 ranks".
pub fn ranks(np: usize) -> String {
    format!("{np} rank{}", if np == 1 { "" } else { "s" })
}

/// Runs the tests of one program and counts them.
pub struct Runner {
    program: &'static str,
    filter: Option<String>,
    passed: usize,
    skipped: usize,
    failed: Vec<String>,
}

impl Runner {
    /// Runs the test `name` (unless the filter leaves it out): `f`'s value,
    /// or `None` when it panicked (a failure) or was left out.
    pub fn test<T>(&mut self, name: &str, f: impl FnOnce() -> T) -> Option<T> {
        if self.filter.as_deref().is_some_and(|p| !name.contains(p)) {
            return None;
        }
        println!("test {name} ...");
        let skips = SKIPS.load(Ordering::Relaxed);
        match catch_unwind(AssertUnwindSafe(f)) {
            Ok(v) => {
                if SKIPS.load(Ordering::Relaxed) > skips {
                    println!("test {name} ... skipped (an oracle is missing, see above)");
                    self.skipped += 1;
                } else {
                    println!("test {name} ... ok");
                    self.passed += 1;
                }
                Some(v)
            }
            Err(_) => {
                println!("test {name} ... FAILED");
                self.failed.push(name.to_string());
                None
            }
        }
    }

    /// One test per rank count in `nps`, `on N ranks`: the program launched
    /// in `mode` must succeed and print `marker`. Prints each run's output;
    /// returns the standard output of each run that passed, by rank count.
    pub fn on_ranks(
        &mut self,
        nps: impl IntoIterator<Item = usize>,
        mode: &str,
        marker: &str,
        limit: Duration,
    ) -> Vec<(usize, String)> {
        let mut outputs = Vec::new();
        for np in nps {
            let out = self.test(&format!("on {}", ranks(np)), || {
                let out = launch(np, mode, limit);
                print!("{out}");
                assert!(
                    out.contains(marker),
                    "on {}: no '{marker}' in\n{out}",
                    ranks(np)
                );
                out
            });
            if let Some(out) = out {
                outputs.push((np, out));
            }
        }
        outputs
    }

    /// [`Runner::on_ranks`] for programs whose results must not depend on
    /// the rank count: each run must also print `count` lines starting
    /// with one of `prefixes`, and a last test requires those lines to be
    /// the same in every run.
    pub fn identical_on_ranks(
        &mut self,
        nps: impl IntoIterator<Item = usize>,
        mode: &str,
        marker: &str,
        prefixes: &[&str],
        count: usize,
        limit: Duration,
    ) -> Vec<(usize, String)> {
        let lines = |out: &str| -> Vec<String> {
            out.lines()
                .filter(|l| prefixes.iter().any(|p| l.starts_with(p)))
                .map(str::to_string)
                .collect()
        };
        let outputs = self.on_ranks(nps, mode, marker, limit);
        self.test("the same results on every rank count", || {
            let Some((np1, first)) = outputs.first() else {
                panic!("no run passed");
            };
            let first = lines(first);
            for (np, out) in &outputs {
                let l = lines(out);
                assert_eq!(l.len(), count, "on {}:\n{out}", ranks(*np));
                assert_eq!(
                    l,
                    first,
                    "the results on {} differ from those on {}",
                    ranks(*np),
                    ranks(*np1)
                );
            }
        });
        outputs
    }

    /// Prints the closing line and exits 1 if a test failed.
    fn finish(self) {
        let mut line = format!(
            "{}: {} passed, {} failed",
            self.program,
            self.passed,
            self.failed.len()
        );
        if self.skipped > 0 {
            line.push_str(&format!(", {} skipped", self.skipped));
        }
        if !self.failed.is_empty() {
            line.push_str(&format!(" ({})", self.failed.join(", ")));
        }
        println!("{line}");
        if !self.failed.is_empty() {
            std::process::exit(1);
        }
    }
}
