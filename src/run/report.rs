//! Timings and memory per phase, for the phase table and the statistics
//! ([`crate::pipeline::Stats`]).

use std::time::Instant;

use crate::parallel::comm::{Comm, Traffic};

/// Peak resident set size of this process in bytes (`getrusage`).
pub fn peak_rss_bytes() -> u64 {
    // SAFETY: getrusage only writes into the zeroed struct we pass.
    unsafe {
        let mut u: libc::rusage = std::mem::zeroed();
        if libc::getrusage(libc::RUSAGE_SELF, &mut u) == 0 {
            (u.ru_maxrss as u64) * 1024
        } else {
            0
        }
    }
}

/// Returns memory freed by a finished phase to the operating system, when
/// there is enough of it to matter.
///
/// glibc keeps freed blocks below its (adaptive, up to 32 MiB) mmap
/// threshold in the heap, so the buffers of balance and partition would
/// otherwise stay resident under the mesh built next: at sphere level 11
/// that was 25 bytes per leaf of a 72-byte peak. Returned pages cost a page
/// fault each when they are used again (about 2.3 us per 4 KiB on the
/// benchmark machine, several times the cost of writing them), so a free
/// heap below [`TRIM_MIN_FREE`] stays: it is small against any peak, and a
/// small octree would otherwise pay those faults in every phase.
pub fn trim_heap() {
    trim_heap_above(TRIM_MIN_FREE);
}

/// [`trim_heap`] with another threshold: a stage about to allocate arrays
/// for many leaves gives back a free heap of `min_free` bytes or more (the
/// large arrays it makes are mapped apart from the heap, so they would not
/// reuse it).
pub fn trim_heap_above(min_free: usize) {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallinfo2 only reads the allocator's statistics, and
    // malloc_trim only releases free heap pages; no pointer is involved.
    unsafe {
        if libc::mallinfo2().fordblks >= min_free {
            libc::malloc_trim(0);
        }
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    let _ = min_free;
}

/// Free heap bytes below which [`trim_heap`] keeps them (glibc's own
/// dynamic trim threshold stops growing at the same 64 MiB).
pub const TRIM_MIN_FREE: usize = 64 << 20;

/// Wall-clock phases, each reported as the maximum over ranks, and, for this
/// rank, the bytes exchanged with other ranks ([`Traffic`]), the seconds
/// inside collectives, the number of collective operations
/// ([`Comm::collectives`]) and the peak memory in each phase.
#[derive(Clone, Debug, Default)]
pub struct PhaseTimer {
    phases: Vec<(String, f64)>,
    traffic: Vec<(String, Traffic)>,
    waits: Vec<(String, f64)>,
    calls: Vec<(String, u64)>,
    peaks: Vec<(String, u64)>,
}

impl PhaseTimer {
    /// An empty timer.
    pub fn new() -> PhaseTimer {
        PhaseTimer::default()
    }

    /// Runs `f` as phase `name`, with barriers so the time is the
    /// collective time of the phase. Collective.
    pub fn time<T>(&mut self, comm: &dyn Comm, name: &str, f: impl FnOnce() -> T) -> T {
        comm.barrier();
        let bytes0 = comm.traffic();
        let wait0 = comm.comm_seconds();
        let calls0 = comm.collectives();
        let t0 = Instant::now();
        let r = f();
        let elapsed = t0.elapsed().as_secs_f64();
        // Read before the reduction below, which is bookkeeping, not the phase.
        let bytes = comm.traffic() - bytes0;
        let wait = comm.comm_seconds() - wait0;
        let calls = comm.collectives() - calls0;
        let mut dt = [elapsed];
        comm.max_f64(&mut dt);
        self.phases.push((name.to_string(), dt[0]));
        self.traffic.push((name.to_string(), bytes));
        self.waits.push((name.to_string(), wait));
        self.calls.push((name.to_string(), calls));
        self.peaks.push((name.to_string(), peak_rss_bytes()));
        r
    }

    /// This rank's peak resident set size (bytes) at the end of each phase,
    /// in the order the phases ran: the phase where it grows is the one that
    /// set the peak. Rank-local, not reduced.
    pub fn peaks(&self) -> &[(String, u64)] {
        &self.peaks
    }

    /// Appends every phase of `other` (time, traffic, time inside
    /// collectives, collective operations and peak), in its order.
    pub fn append(&mut self, other: &PhaseTimer) {
        self.phases.extend_from_slice(&other.phases);
        self.traffic.extend_from_slice(&other.traffic);
        self.waits.extend_from_slice(&other.waits);
        self.calls.extend_from_slice(&other.calls);
        self.peaks.extend_from_slice(&other.peaks);
    }

    /// Bytes this rank exchanged in phase `name`, summed over the phases of
    /// that name (zero if it did not run). Rank-local, not reduced.
    pub fn traffic_of(&self, name: &str) -> Traffic {
        self.traffic
            .iter()
            .filter(|p| p.0 == name)
            .fold(Traffic::default(), |acc, p| acc + p.1)
    }

    /// This rank's bytes per phase, in the order the phases ran.
    pub fn traffic(&self) -> &[(String, Traffic)] {
        &self.traffic
    }

    /// Seconds this rank spent inside collectives ([`Comm::comm_seconds`])
    /// in phase `name`, summed over the phases of that name. Rank-local,
    /// not reduced: the largest over ranks is mostly waiting for the
    /// slowest rank, the smallest is closer to the cost of the exchanges.
    pub fn wait_of(&self, name: &str) -> f64 {
        self.waits.iter().filter(|p| p.0 == name).map(|p| p.1).sum()
    }

    /// Collective operations this rank took part in during phase `name`,
    /// summed over the phases of that name. Rank-local, not reduced (every
    /// rank calls the same collectives, so it is the same on all ranks).
    pub fn calls_of(&self, name: &str) -> u64 {
        self.calls.iter().filter(|p| p.0 == name).map(|p| p.1).sum()
    }

    /// This rank's collective operations per phase, in the order the phases
    /// ran.
    pub fn calls(&self) -> &[(String, u64)] {
        &self.calls
    }

    /// This rank's seconds inside collectives per phase, in the order the
    /// phases ran.
    pub fn waits(&self) -> &[(String, f64)] {
        &self.waits
    }

    /// Seconds of phase `name` (0 if it did not run).
    pub fn get(&self, name: &str) -> f64 {
        // A fold from +0.0: an empty f64 sum is -0.0.
        self.phases
            .iter()
            .filter(|p| p.0 == name)
            .fold(0.0, |acc, p| acc + p.1)
    }

    /// Phases in the order they ran.
    pub fn phases(&self) -> &[(String, f64)] {
        &self.phases
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn peak_memory_is_read() {
        assert!(peak_rss_bytes() > 0);
    }

    impl PhaseTimer {
        /// Stands in for a communicator that counts bytes.
        fn record_traffic(&mut self, name: &str, bytes: Traffic) {
            self.traffic.push((name.to_string(), bytes));
        }

        /// Stands in for a communicator that counts its time.
        fn record_wait(&mut self, name: &str, secs: f64) {
            self.waits.push((name.to_string(), secs));
        }
    }

    #[test]
    fn traffic_is_summed_by_phase_name() {
        let mut t = PhaseTimer::new();
        let c = crate::parallel::comm::SerialComm;
        t.time(&c, "partition", || ());
        t.record_traffic(
            "partition",
            Traffic {
                sent: 3,
                received: 5,
            },
        );
        t.record_traffic(
            "ghost",
            Traffic {
                sent: 7,
                received: 0,
            },
        );
        assert_eq!(t.traffic_of("partition").total(), 8);
        assert_eq!(t.traffic_of("ghost").sent, 7);
        assert_eq!(t.traffic_of("balance"), Traffic::default());
        assert_eq!(t.traffic().len(), 3);
    }

    #[test]
    fn waits_are_summed_by_phase_name() {
        let mut t = PhaseTimer::new();
        let c = crate::parallel::comm::SerialComm;
        t.time(&c, "ghost", || ());
        t.record_wait("ghost", 0.25);
        t.record_wait("ghost", 0.5);
        t.record_wait("nodes", 2.0);
        // A serial communicator never waits.
        assert_eq!(t.waits()[0], ("ghost".to_string(), 0.0));
        assert_eq!(t.wait_of("ghost"), 0.75);
        assert_eq!(t.wait_of("nodes"), 2.0);
        assert_eq!(t.wait_of("balance"), 0.0);
    }
}
