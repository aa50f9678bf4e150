//! The fuzz targets' bodies (`fuzz/src`) on stable Rust, without libFuzzer:
//! every file of the committed corpora `fuzz/regressions/stl` and
//! `fuzz/regressions/api` (seeds and the inputs of crashes found and
//! fixed), then a bounded number of pseudo-random inputs (fixed seed,
//! mutations of the corpus and raw bytes). The `api` inputs are run twice
//! and the second run must end with as many live Rust allocations as it
//! started with (a handle or a buffer left behind is a leak).

#[path = "../fuzz/src/api.rs"]
mod api_body;
#[path = "../fuzz/src/stl.rs"]
mod stl_body;

mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// Counts the live allocations of each thread (tests run in parallel
/// threads; each body runs on one).
struct Counting;

thread_local! {
    static LIVE: Cell<i64> = const { Cell::new(0) };
}

fn bump(d: i64) {
    // `try_with`: no count during thread teardown.
    let _ = LIVE.try_with(|c| c.set(c.get() + d));
}

// SAFETY: forwards to the system allocator; the counter is a plain
// thread-local cell that never allocates.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        bump(1);
        // SAFETY: the caller's layout, forwarded.
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        bump(-1);
        // SAFETY: allocated by `alloc` above with this layout.
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn alloc_zeroed(&self, l: Layout) -> *mut u8 {
        bump(1);
        // SAFETY: as in `alloc`.
        unsafe { System.alloc_zeroed(l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        // SAFETY: as in `dealloc`; a reallocation keeps the count.
        unsafe { System.realloc(p, l, n) }
    }
}

#[global_allocator]
static ALLOC: Counting = Counting;

fn live() -> i64 {
    LIVE.with(|c| c.get())
}

/// Pseudo-random inputs per target at most, and the time they may take
/// (an `api` input takes milliseconds, most `stl` ones microseconds).
const RANDOM_INPUTS: [usize; 2] = [20_000, 3000];
const RANDOM_TIME: Duration = Duration::from_secs(4);

/// splitmix64.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

fn corpus(target: &str) -> Vec<(PathBuf, Vec<u8>)> {
    let dir = common::repo().join("fuzz").join("regressions").join(target);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.expect("directory entry").path())
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    files
        .into_iter()
        .map(|p| {
            let b = std::fs::read(&p).expect("read corpus file");
            (p, b)
        })
        .collect()
}

/// A random input: a corpus file mutated (bytes changed, cut, spliced with
/// another) or raw random bytes.
fn random_input(rng: &mut Rng, seeds: &[(PathBuf, Vec<u8>)]) -> Vec<u8> {
    if seeds.is_empty() || rng.below(4) == 0 {
        let n = rng.below(400);
        return (0..n).map(|_| rng.next() as u8).collect();
    }
    let mut v = seeds[rng.below(seeds.len())].1.clone();
    for _ in 0..1 + rng.below(8) {
        match rng.below(4) {
            0 if !v.is_empty() => {
                let i = rng.below(v.len());
                v[i] = rng.next() as u8;
            }
            1 if !v.is_empty() => v.truncate(rng.below(v.len())),
            2 => {
                let other = &seeds[rng.below(seeds.len())].1;
                let from = rng.below(other.len());
                v.extend_from_slice(&other[from..]);
            }
            _ => {
                let i = rng.below(v.len() + 1);
                v.insert(i, rng.next() as u8);
            }
        }
    }
    v
}

/// Runs `body` on `input`; on a panic, saves the input under
/// `target/fuzz-failures` and fails naming it.
fn run_one(target: &str, what: &str, input: &[u8], body: &dyn Fn(&[u8])) {
    if catch_unwind(AssertUnwindSafe(|| body(input))).is_err() {
        let dir = common::repo()
            .join("target")
            .join("fuzz-failures")
            .join(target);
        std::fs::create_dir_all(&dir).expect("create target/fuzz-failures");
        let path = dir.join(format!("failure-{}", what.replace(['/', ' '], "_")));
        std::fs::write(&path, input).expect("save the failing input");
        panic!(
            "{target} failed on {what}; input saved to {} (replay it with \
             `cargo +nightly fuzz run {target} {}` in fuzz/)",
            path.display(),
            path.display()
        );
    }
}

fn replay(target: &str, body: &dyn Fn(&[u8]), seed: u64, max_inputs: usize) {
    let files = corpus(target);
    assert!(!files.is_empty(), "the {target} corpus is empty");
    for (path, bytes) in &files {
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        run_one(target, &name, bytes, body);
    }
    let mut rng = Rng(seed);
    let start = Instant::now();
    let mut n = 0;
    while n < max_inputs && start.elapsed() < RANDOM_TIME {
        let input = random_input(&mut rng, &files);
        run_one(target, &format!("random {n}"), &input, body);
        n += 1;
    }
    println!(
        "{target}: {} corpus files and {n} random inputs in {:.2} s",
        files.len(),
        start.elapsed().as_secs_f64()
    );
    assert!(
        n >= 20,
        "{target}: only {n} random inputs ran in {RANDOM_TIME:?}"
    );
}

#[test]
fn stl_corpus_and_random_inputs() {
    replay("stl", &stl_body::run, 0x5eed_0001, RANDOM_INPUTS[0]);
}

/// The CLI's bad files, written by the same helper, go through the body too
/// (they are also in the committed corpus, as bytes).
#[test]
fn stl_body_on_generated_bad_files() {
    let dir = common::scratch("fuzz_regression_stl");
    let tri = [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let p = dir.join("nan.stl");
    common::write_stl(
        &p,
        &[tri, [[0.0, f32::NAN, 0.0], tri[1], tri[2]]],
        b"solid x",
    );
    let bytes = std::fs::read(&p).unwrap();
    run_one("stl", "generated nan", &bytes, &stl_body::run);
    run_one(
        "stl",
        "generated truncated",
        &bytes[..bytes.len() - 7],
        &stl_body::run,
    );
}

/// Runs an `api` input twice; the second run must not change the number of
/// live allocations of this thread (the first may fill lazily made
/// buffers).
fn api_without_leaks(input: &[u8]) {
    api_body::run(input);
    let before = live();
    api_body::run(input);
    let after = live();
    assert_eq!(
        after,
        before,
        "{} allocation(s) left behind by one run",
        after - before
    );
}

#[test]
fn api_corpus_and_random_inputs() {
    // Live allocations are counted per thread: keep the library's work on
    // this one (a spare core's thread may free what this one allocated).
    std::env::set_var(octmesh::internals::parallel::cores::SPARE_CORE_VAR, "0");
    api_body::init_mpi();
    replay("api", &api_without_leaks, 0x5eed_0002, RANDOM_INPUTS[1]);
    let _ = std::fs::remove_dir_all(
        std::env::temp_dir().join(format!("octmesh-fuzz-api-{}", std::process::id())),
    );
}

/// The counter the leak check relies on sees an allocation and its release.
#[test]
fn allocation_counter_counts() {
    let before = live();
    let v = vec![1u8; 16];
    assert_eq!(live(), before + 1);
    let w = v.clone();
    assert_eq!(live(), before + 2);
    drop((v, w));
    assert_eq!(live(), before);
}
