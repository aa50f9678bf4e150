//! Spare cores: a second thread for a rank whose node has more cores than
//! ranks (a serial run on a workstation, say). With a rank on every core,
//! as an MPI job is usually laid out, nothing here starts a thread.
//!
//! The work split this way is always split the same way and combined in
//! the same order, so a result never depends on whether a second thread
//! ran it.

use crate::parallel::comm::Comm;
use std::ops::Range;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};

/// The environment variable that, set to `0`, keeps every rank on one
/// thread (for a host program whose own threads hold the other cores, or
/// to measure the serial passes).
pub const SPARE_CORE_VAR: &str = "OCTMESH_SPARE_CORE";

/// Whether this rank may run one more thread: the node has more cores
/// than ranks on it, and [`SPARE_CORE_VAR`] is not `0`. Collective (the
/// ranks on a node are counted).
pub fn spare_core(comm: &dyn Comm) -> bool {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let allowed = std::env::var_os(SPARE_CORE_VAR).is_none_or(|v| v != "0");
    cores > comm.ranks_on_node() && allowed
}

/// Whether this processor has AVX-512F. The build targets x86-64-v2, so
/// the snap's kernels written for it (`mesh::snap`, `geometry::distance`)
/// are chosen at run time; they give the scalar code's bits.
pub fn avx512() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        static HAS: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
        *HAS.get_or_init(|| std::is_x86_feature_detected!("avx512f"))
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// Whether this processor has AVX2 (four `f64` lanes): where AVX-512F is
/// missing, refinement's box tests take four children at a time with it
/// (`geometry::intersect::wide4`); the same bits as the scalar
/// code.
pub fn avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        static HAS: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
        *HAS.get_or_init(|| std::is_x86_feature_detected!("avx2"))
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// Runs `a` and `b` and returns both results: with `spare`, `a` on a
/// second thread while this one runs `b`; else (or when the thread cannot
/// start) one after the other on this thread. A panic in either reaches
/// the caller as it would from a plain call.
pub fn join<A, B, FA, FB>(spare: bool, a: FA, b: FB) -> (A, B)
where
    A: Send,
    FA: FnOnce() -> A + Send,
    FB: FnOnce() -> B,
{
    if !spare {
        return (a(), b());
    }
    // The closure stays here when the thread cannot start: `a` then runs
    // on this thread.
    let slot = std::sync::Mutex::new(Some(a));
    std::thread::scope(|scope| {
        let spawned = std::thread::Builder::new()
            .name("octmesh-spare".into())
            .spawn_scoped(scope, || {
                let a = slot.lock().map(|mut s| s.take()).unwrap_or(None);
                a.map(|a| a())
            });
        let rb = b();
        let ra = match spawned {
            Ok(handle) => match handle.join() {
                Ok(r) => r,
                Err(payload) => std::panic::resume_unwind(payload),
            },
            Err(_) => None,
        };
        let ra = match ra {
            Some(r) => r,
            None => {
                let a = slot.lock().map(|mut s| s.take()).unwrap_or(None);
                a.expect("the second thread neither ran nor left its work")()
            }
        };
        (ra, rb)
    })
}

/// The address and length in bytes of `v`'s items, for
/// [`with_pages_made`].
pub fn bytes_of<T>(v: &[T]) -> (usize, usize) {
    (v.as_ptr() as usize, std::mem::size_of_val(v))
}

/// Runs `work` on this thread after the kernel made the pages of fresh
/// memory `ranges` (address, bytes), so that `work`'s first writes there
/// find them made. A page costs the kernel about 1.5 µs on a virtual
/// machine like the ones measured in BENCHMARKS.md when a first write
/// makes it, a third of a large face extraction's time, and about a third
/// less when made in bulk. With `spare`, a second thread makes them while
/// `work` runs, which takes that time off this thread; without, this
/// thread makes them first, in bulk ([`make_pages`]). The memory must stay
/// allocated while `work` runs; no byte of it changes.
pub fn with_pages_made<R>(spare: bool, ranges: &[(usize, usize)], work: impl FnOnce() -> R) -> R {
    #[cfg(target_os = "linux")]
    if spare {
        let ranges = ranges.to_vec();
        return join(true, move || make_pages(&ranges), work).1;
    }
    make_pages(ranges);
    work()
}

/// Has the kernel make the pages of fresh memory `ranges` (address,
/// bytes) now, in bulk, as first writes would one by one; no byte changes.
/// Linux only; elsewhere nothing (the writes make them).
pub fn make_pages(ranges: &[(usize, usize)]) {
    #[cfg(target_os = "linux")]
    populate(ranges);
    #[cfg(not(target_os = "linux"))]
    let _ = ranges;
}

/// See [`make_pages`].
#[cfg(target_os = "linux")]
fn populate(ranges: &[(usize, usize)]) {
    // SAFETY: sysconf only reads a system constant.
    let page = unsafe { libc::sysconf(libc::_SC_PAGESIZE) }.max(4096) as usize;
    for &(at, len) in ranges {
        // Whole pages inside the range only: the pages it shares with
        // other memory are made by their first write, as usual.
        let (a, b) = ((at + page - 1) & !(page - 1), (at + len) & !(page - 1));
        if b > a {
            // SAFETY: MADV_POPULATE_WRITE makes the pages of this
            // process' own mapping as a write would, without changing a
            // byte; a range not mapped (or an older kernel) is an error
            // that is ignored, as the pages are then made when written.
            unsafe { libc::madvise(a as *mut libc::c_void, b - a, libc::MADV_POPULATE_WRITE) };
        }
    }
}

/// Runs `f` on the pieces `0..n` is cut into (`chunk` long, the last
/// shorter) and returns its results in the pieces' order. With `spare`,
/// this thread and a second one each take the next piece not yet taken,
/// so a thread slowed down (by another process on its core, say) takes
/// fewer; the pieces and the order are the same either way.
pub fn map_chunks<T, F>(spare: bool, n: usize, chunk: usize, f: F) -> Vec<T>
where
    T: Send,
    F: Fn(Range<usize>) -> T + Sync,
{
    map_chunks_after(spare, n, chunk, f, || ()).0
}

/// [`map_chunks`], with `first` run on this thread before it takes any
/// piece (with `spare` the second thread starts on the pieces at once):
/// work of another kind that overlaps the pieces. Returns both results.
pub fn map_chunks_after<T, F, B, G>(
    spare: bool,
    n: usize,
    chunk: usize,
    f: F,
    first: G,
) -> (Vec<T>, B)
where
    T: Send,
    F: Fn(Range<usize>) -> T + Sync,
    G: FnOnce() -> B,
{
    let chunk = chunk.max(1);
    let count = n.div_ceil(chunk);
    let piece = |c: usize| c * chunk..((c + 1) * chunk).min(n);
    if !spare || count < 2 {
        let b = first();
        return ((0..count).map(|c| f(piece(c))).collect(), b);
    }
    let next = AtomicUsize::new(0);
    let work = || {
        let mut done = Vec::new();
        loop {
            let c = next.fetch_add(1, Ordering::Relaxed);
            if c >= count {
                return done;
            }
            done.push((c, f(piece(c))));
        }
    };
    let (a, (b, first)) = join(true, work, || {
        let first = first();
        (work(), first)
    });
    let mut slots: Vec<Option<T>> = (0..count).map(|_| None).collect();
    for (c, r) in a.into_iter().chain(b) {
        slots[c] = Some(r);
    }
    let all = slots
        .into_iter()
        .map(|r| r.expect("every piece is taken once"))
        .collect();
    (all, first)
}

/// `v` seen as atomic words, so that threads may store into it at once
/// (each into its own places, or the same bits where they meet).
pub fn shared_f64(v: &mut [f64]) -> &[AtomicU64] {
    const {
        assert!(std::mem::size_of::<AtomicU64>() == std::mem::size_of::<f64>());
        assert!(std::mem::align_of::<AtomicU64>() == std::mem::align_of::<f64>());
    }
    // SAFETY: same size and alignment (checked above), and the exclusive
    // borrow is held for as long as the atomic view lives.
    unsafe { std::slice::from_raw_parts(v.as_mut_ptr().cast(), v.len()) }
}

#[cfg(test)]
mod tests {
    use super::{join, map_chunks};

    #[test]
    fn the_pieces_come_back_in_order() {
        for spare in [false, true] {
            let r = map_chunks(spare, 100_003, 1000, |r| (r.start, r.end));
            assert_eq!(r.len(), 101);
            assert!(r.windows(2).all(|w| w[0].1 == w[1].0));
            assert_eq!((r[0].0, r[100].1), (0, 100_003));
        }
        assert!(map_chunks(true, 0, 10, |r| r.len()).is_empty());
    }

    #[test]
    fn both_halves_run_on_one_or_two_threads() {
        for spare in [false, true] {
            let v: Vec<u64> = (0..10_000).collect();
            let (lo, hi) = v.split_at(5_000);
            let (a, b) = join(spare, || lo.iter().sum::<u64>(), || hi.iter().sum::<u64>());
            assert_eq!(a + b, v.iter().sum::<u64>());
            assert_eq!(a, (0..5_000).sum::<u64>());
        }
    }

    #[test]
    fn a_panic_on_the_second_thread_reaches_the_caller() {
        let r = std::panic::catch_unwind(|| join(true, || panic!("in a"), || 1));
        assert!(r.is_err());
    }
}
