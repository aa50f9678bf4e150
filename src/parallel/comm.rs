//! The few collective operations octmesh needs, over MPI or over one process.
//!
//! Every algorithm talks to a [`Comm`] instead of to rsmpi directly. Buffers are
//! plain integers and bytes (never derived MPI datatypes), so the same code
//! works when the host program, not octmesh, initialised MPI, and serial unit
//! tests run without MPI at all through [`SerialComm`].
//!
//! [`MpiComm`] counts the bytes each rank hands to MPI for other ranks and
//! receives from them ([`Comm::traffic`]); [`crate::run::report::PhaseTimer`]
//! attributes them to phases.

use std::cell::Cell;
use std::ops::{Add, AddAssign, Sub};
use std::rc::Rc;

use mpi::collective::SystemOperation;
use mpi::datatype::PartitionMut;
use mpi::topology::SimpleCommunicator;
use mpi::traits::*;

use crate::error::{Error, ErrorKind, Result};

/// Shared handle to a communicator.
pub type CommRef = Rc<dyn Comm>;

/// Collective operations over a group of ranks. All methods are collective
/// unless stated otherwise: every rank must call them in the same order.
pub trait Comm {
    /// This process's rank, in `0..size()`. Not collective.
    fn rank(&self) -> usize;
    /// Number of ranks. Not collective.
    fn size(&self) -> usize;
    /// Blocks until every rank has called it.
    fn barrier(&self);
    /// Element-wise maximum over ranks.
    fn max_u64(&self, values: &mut [u64]);
    /// Element-wise sum over ranks.
    fn sum_u64(&self, values: &mut [u64]);
    /// Element-wise maximum over ranks.
    fn max_f64(&self, values: &mut [f64]);
    /// Gathers one value from every rank, in rank order, on every rank.
    fn allgather_u64(&self, value: u64) -> Vec<u64>;
    /// Personalised all-to-all: `send[displs[q]..displs[q]+counts[q]]` goes to
    /// rank `q`; returns what every rank sent here, concatenated in rank order,
    /// and the count received from each rank. Sparse: only the ranks that
    /// exchange data send messages, so a rank's traffic is its data, with
    /// nothing per other rank.
    fn alltoallv_u64(&self, send: &[u64], counts: &[usize]) -> (Vec<u64>, Vec<usize>);
    /// Replaces `bytes` on every rank with rank `root`'s bytes.
    fn broadcast_bytes(&self, root: usize, bytes: &mut Vec<u8>);
    /// Gathers every rank's `mine` on every rank: returns them concatenated
    /// in rank order, and the length of each.
    fn allgatherv_bytes(&self, mine: &[u8]) -> (Vec<u8>, Vec<usize>);
    /// The MPI communicator underneath, for MPI-IO ([`super::file`]);
    /// `None` for a single process without MPI.
    fn mpi_raw(&self) -> Option<mpi_sys::MPI_Comm> {
        None
    }
    /// Bytes this rank has exchanged with other ranks so far (see
    /// [`Traffic`]). Not collective. The default, for communicators that do
    /// not count, is zero.
    fn traffic(&self) -> Traffic {
        Traffic::default()
    }
    /// Seconds this rank has spent inside the collectives above so far,
    /// waiting for the other ranks included. Not collective. The default,
    /// for communicators that do not count, is zero.
    fn comm_seconds(&self) -> f64 {
        0.0
    }
    /// Collective operations this rank has handed to MPI so far: one per
    /// reduction, all-gather, barrier and all-to-all (whose messages go
    /// between neighbours; only its closing barrier involves all ranks), two
    /// per non-empty broadcast (the length, then the bytes). Each costs
    /// rounds that grow with the number of ranks, so a phase scales only if
    /// its count stays flat. Not collective. The default, for communicators
    /// that do not count, is zero.
    fn collectives(&self) -> u64 {
        0
    }
    /// Number of this communicator's ranks on this rank's node (sharing its
    /// memory). Collective. The default, for communicators of one node, is
    /// all of them.
    fn ranks_on_node(&self) -> usize {
        self.size()
    }
}

/// Payload bytes a rank has sent to and received from *other* ranks through
/// the [`Comm`] collectives (data a rank keeps for itself is not counted).
///
/// The count is the data octmesh hands to MPI, not the bytes on the wire of
/// MPI's internal algorithms (trees, rings, pipelining), which depend on the
/// MPI library: an all-to-all counts each block once at its sender and once
/// at its receiver; a
/// broadcast counts the message once per receiving rank at the root and once
/// at each receiver; a reduction or all-gather counts each rank's
/// contribution as sent to, and the result as received from, the other
/// ranks (a reduction of `n` values: `8 n` bytes each way per rank; an
/// all-gather of one value on `p` ranks: `8 (p - 1)` each way; an all-gather
/// of `n` bytes from this rank: `n (p - 1)` sent, the others' bytes
/// received). Summed over
/// the ranks, sent always equals received. One rank exchanges nothing.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Traffic {
    /// Bytes handed to MPI for other ranks.
    pub sent: u64,
    /// Bytes received from other ranks.
    pub received: u64,
}

impl Traffic {
    /// `sent + received`.
    pub fn total(&self) -> u64 {
        self.sent + self.received
    }
}

impl Add for Traffic {
    type Output = Traffic;
    fn add(self, o: Traffic) -> Traffic {
        Traffic {
            sent: self.sent + o.sent,
            received: self.received + o.received,
        }
    }
}

impl AddAssign for Traffic {
    fn add_assign(&mut self, o: Traffic) {
        *self = *self + o;
    }
}

impl Sub for Traffic {
    type Output = Traffic;
    /// Difference of two readings of the same counters (later minus earlier).
    fn sub(self, o: Traffic) -> Traffic {
        Traffic {
            sent: self.sent - o.sent,
            received: self.received - o.received,
        }
    }
}

/// Exclusive prefix sums of `counts` with the total appended (`len + 1`
/// entries).
pub fn offsets(counts: &[usize]) -> Vec<usize> {
    let mut out = Vec::with_capacity(counts.len() + 1);
    let mut acc = 0usize;
    out.push(0);
    for &c in counts {
        acc += c;
        out.push(acc);
    }
    out
}

/// Makes a collective decision out of a rank-local result: if any rank failed,
/// every rank returns an error. The failing rank keeps its own error; the
/// others receive the message of the lowest failing rank, kind
/// [`ErrorKind::RemoteFailure`] unless all ranks failed with the same kind.
pub fn agree<T>(comm: &dyn Comm, local: Result<T>) -> Result<T> {
    let code = match &local {
        Ok(_) => 0u64,
        Err(e) => e.kind() as i32 as u64,
    };
    // One reduction carries "anyone failed" and "lowest failing rank".
    let mut flags = [
        code,
        if code != 0 {
            u64::MAX - comm.rank() as u64
        } else {
            0
        },
    ];
    comm.max_u64(&mut flags);
    if flags[0] == 0 {
        return local;
    }
    let root = (u64::MAX - flags[1]) as usize;
    let mut msg = match &local {
        Err(e) if comm.rank() == root => {
            let mut b = (e.kind() as i32).to_le_bytes().to_vec();
            b.extend_from_slice(e.message().as_bytes());
            b
        }
        _ => Vec::new(),
    };
    comm.broadcast_bytes(root, &mut msg);
    match local {
        Err(e) => Err(e),
        Ok(_) => {
            let kind = ErrorKind::from_code(i32::from_le_bytes([msg[0], msg[1], msg[2], msg[3]]));
            let text = String::from_utf8_lossy(&msg[4..]);
            let kind = if kind == ErrorKind::Limit || kind == ErrorKind::RemoteFailure {
                kind
            } else {
                ErrorKind::RemoteFailure
            };
            Err(Error::new(kind, format!("rank {root}: {text}")))
        }
    }
}

/// A single process: every collective is a local copy.
#[derive(Clone, Copy, Debug, Default)]
pub struct SerialComm;

impl Comm for SerialComm {
    fn rank(&self) -> usize {
        0
    }
    fn size(&self) -> usize {
        1
    }
    fn barrier(&self) {}
    fn max_u64(&self, _values: &mut [u64]) {}
    fn sum_u64(&self, _values: &mut [u64]) {}
    fn max_f64(&self, _values: &mut [f64]) {}
    fn allgather_u64(&self, value: u64) -> Vec<u64> {
        vec![value]
    }
    fn alltoallv_u64(&self, send: &[u64], counts: &[usize]) -> (Vec<u64>, Vec<usize>) {
        (send[..counts[0]].to_vec(), counts.to_vec())
    }
    fn broadcast_bytes(&self, _root: usize, _bytes: &mut Vec<u8>) {}
    fn allgatherv_bytes(&self, mine: &[u8]) -> (Vec<u8>, Vec<usize>) {
        (mine.to_vec(), vec![mine.len()])
    }
}

/// An MPI communicator. Owned: it is freed when dropped (for the world
/// communicator, nothing is freed).
pub struct MpiComm {
    comm: SimpleCommunicator,
    sent: Cell<u64>,
    received: Cell<u64>,
    busy: Cell<f64>,
    calls: Cell<u64>,
    exchanges: Cell<u64>,
}

/// The tags of [`Comm::alltoallv_u64`]'s messages (this one and the next).
const SPARSE_TAG: i32 = 7001;

impl MpiComm {
    /// Wraps a communicator octmesh owns (the world, or a duplicate).
    pub fn new(comm: SimpleCommunicator) -> MpiComm {
        MpiComm {
            comm,
            sent: Cell::new(0),
            received: Cell::new(0),
            busy: Cell::new(0.0),
            calls: Cell::new(0),
            exchanges: Cell::new(0),
        }
    }

    /// Runs `calls` collective operations, adding their wall time to
    /// [`Comm::comm_seconds`] and their number to [`Comm::collectives`].
    fn timed_n<T>(&self, calls: u64, f: impl FnOnce() -> T) -> T {
        self.calls.set(self.calls.get() + calls);
        self.time_only(f)
    }

    /// Runs one collective operation (see [`MpiComm::timed_n`]).
    fn timed<T>(&self, f: impl FnOnce() -> T) -> T {
        self.timed_n(1, f)
    }

    /// Adds the wall time of `f` to [`Comm::comm_seconds`].
    fn time_only<T>(&self, f: impl FnOnce() -> T) -> T {
        let t0 = std::time::Instant::now();
        let r = f();
        self.busy.set(self.busy.get() + t0.elapsed().as_secs_f64());
        r
    }

    fn count(&self, sent: usize, received: usize) {
        self.sent.set(self.sent.get() + sent as u64);
        self.received.set(self.received.get() + received as u64);
    }

    /// Counts a reduction or all-gather: this rank's `bytes` go to the others
    /// and as many come back, when there are other ranks.
    fn count_symmetric(&self, bytes: usize) {
        if self.size() > 1 {
            self.count(bytes, bytes);
        }
    }

    /// The underlying rsmpi communicator.
    pub fn raw(&self) -> &SimpleCommunicator {
        &self.comm
    }
}

impl Comm for MpiComm {
    fn rank(&self) -> usize {
        self.comm.rank() as usize
    }
    fn ranks_on_node(&self) -> usize {
        // MPI_Comm_split_type(MPI_COMM_TYPE_SHARED): the ranks sharing memory.
        self.calls.set(self.calls.get() + 1);
        self.comm.split_shared(0).size() as usize
    }
    fn size(&self) -> usize {
        self.comm.size() as usize
    }
    fn barrier(&self) {
        self.timed(|| self.comm.barrier());
    }
    fn max_u64(&self, values: &mut [u64]) {
        let send = values.to_vec();
        self.timed(|| {
            self.comm
                .all_reduce_into(&send[..], values, SystemOperation::max())
        });
        self.count_symmetric(8 * values.len());
    }
    fn sum_u64(&self, values: &mut [u64]) {
        let send = values.to_vec();
        self.timed(|| {
            self.comm
                .all_reduce_into(&send[..], values, SystemOperation::sum())
        });
        self.count_symmetric(8 * values.len());
    }
    fn max_f64(&self, values: &mut [f64]) {
        let send = values.to_vec();
        self.timed(|| {
            self.comm
                .all_reduce_into(&send[..], values, SystemOperation::max())
        });
        self.count_symmetric(8 * values.len());
    }
    fn allgather_u64(&self, value: u64) -> Vec<u64> {
        let mut out = vec![0u64; self.size()];
        self.timed(|| self.comm.all_gather_into(&value, &mut out[..]));
        self.count_symmetric(8 * (self.size() - 1));
        out
    }
    fn alltoallv_u64(&self, send: &[u64], counts: &[usize]) -> (Vec<u64>, Vec<usize>) {
        let (p, me) = (self.size(), self.rank());
        let offs = offsets(counts);
        // Two tags, one for even and one for odd exchanges: a rank can be at
        // most one exchange ahead of another (each ends with a barrier), so
        // its next messages never match this exchange's probes.
        let round = self.exchanges.get();
        self.exchanges.set(round + 1);
        let tag = SPARSE_TAG + (round % 2) as i32;
        let mut blocks: Vec<(usize, Vec<u64>)> = Vec::new();
        // The sparse exchange of Hoefler, Siebert and Lumsdaine (NBX):
        // synchronous sends to the ranks that get data, receives of whatever
        // arrives, and a non-blocking barrier entered once this rank's sends
        // were all matched; when the barrier completes, every message has
        // been received. No rank learns anything about the ranks it does not
        // talk to: the cost per rank follows its neighbours, not P.
        self.timed(|| {
            mpi::request::scope(|scope| {
                let mut sends: Vec<_> = (0..p)
                    .filter(|&q| q != me && counts[q] > 0)
                    .map(|q| {
                        self.comm
                            .process_at_rank(q as i32)
                            .immediate_synchronous_send_with_tag(
                                scope,
                                &send[offs[q]..offs[q + 1]],
                                tag,
                            )
                    })
                    .collect();
                let mut barrier = None;
                loop {
                    if let Some((msg, status)) = self
                        .comm
                        .any_process()
                        .immediate_matched_probe_with_tag(tag)
                    {
                        let n = status.count(u64::equivalent_datatype()) as usize;
                        let mut buf = vec![0u64; n];
                        msg.matched_receive_into(&mut buf[..]);
                        blocks.push((status.source_rank() as usize, buf));
                        continue;
                    }
                    match barrier.take() {
                        None => {
                            sends = sends.into_iter().filter_map(|r| r.test().err()).collect();
                            if sends.is_empty() {
                                barrier = Some(self.comm.immediate_barrier());
                            }
                        }
                        Some(b) => match b.test() {
                            Ok(_) => break,
                            Err(b) => barrier = Some(b),
                        },
                    }
                    // Oversubscribed ranks share cores: let the others run.
                    std::thread::yield_now();
                }
            })
        });
        blocks.push((me, send[offs[me]..offs[me + 1]].to_vec()));
        blocks.sort_unstable_by_key(|b| b.0);
        let mut rc = vec![0usize; p];
        let mut recv = Vec::with_capacity(blocks.iter().map(|b| b.1.len()).sum());
        for (src, block) in blocks {
            rc[src] = block.len();
            recv.extend_from_slice(&block);
        }
        // Blocks a rank addresses to itself never leave it.
        self.count(8 * (offs[p] - counts[me]), 8 * (recv.len() - rc[me]));
        (recv, rc)
    }
    fn broadcast_bytes(&self, root: usize, bytes: &mut Vec<u8>) {
        let mut len = bytes.len() as u64;
        let proc = self.comm.process_at_rank(root as i32);
        self.time_only(|| {
            proc.broadcast_into(&mut len);
            bytes.resize(len as usize, 0);
            if len > 0 {
                proc.broadcast_into(&mut bytes[..]);
            }
        });
        self.calls.set(self.calls.get() + 1 + u64::from(len > 0));
        let others = self.size() - 1;
        let message = 8 + bytes.len();
        if self.rank() == root {
            self.count(message * others, 0);
        } else {
            self.count(0, message);
        }
    }
    fn allgatherv_bytes(&self, mine: &[u8]) -> (Vec<u8>, Vec<usize>) {
        let p = self.size();
        let lens: Vec<usize> = self
            .allgather_u64(mine.len() as u64)
            .into_iter()
            .map(|n| n as usize)
            .collect();
        let offs = offsets(&lens);
        let mut out = vec![0u8; offs[p]];
        // MPI counts and displacements are `int`: each round moves at most
        // `cap` bytes per rank, so that one round's total fits.
        let cap = (i32::MAX as usize / p).max(1);
        let rounds = lens.iter().map(|n| n.div_ceil(cap)).max().unwrap_or(0);
        let mut buf = Vec::new();
        for k in 0..rounds {
            let piece = |n: usize| n.saturating_sub(k * cap).min(cap);
            let pieces: Vec<usize> = lens.iter().map(|&n| piece(n)).collect();
            let counts: Vec<i32> = pieces.iter().map(|&c| c as i32).collect();
            let lo = (k * cap).min(mine.len());
            let send = &mine[lo..lo + piece(mine.len())];
            // One round (the usual case) lands in place; more go through a
            // buffer of one round's pieces.
            let (target, displs): (&mut [u8], Vec<i32>) = if rounds == 1 {
                (&mut out[..], offs[..p].iter().map(|&d| d as i32).collect())
            } else {
                let d = offsets(&pieces);
                buf.resize(d[p], 0);
                (&mut buf[..], d[..p].iter().map(|&d| d as i32).collect())
            };
            self.timed(|| {
                let mut part = PartitionMut::new(target, &counts[..], &displs[..]);
                self.comm.all_gather_varcount_into(send, &mut part);
            });
            if rounds > 1 {
                for q in 0..p {
                    let (d, c) = (displs[q] as usize, pieces[q]);
                    let at = offs[q] + k * cap;
                    out[at..at + c].copy_from_slice(&buf[d..d + c]);
                }
            }
        }
        if p > 1 {
            self.count(mine.len() * (p - 1), offs[p] - mine.len());
        }
        (out, lens)
    }
    fn mpi_raw(&self) -> Option<mpi_sys::MPI_Comm> {
        Some(self.comm.as_raw())
    }
    fn traffic(&self) -> Traffic {
        Traffic {
            sent: self.sent.get(),
            received: self.received.get(),
        }
    }
    fn comm_seconds(&self) -> f64 {
        self.busy.get()
    }
    fn collectives(&self) -> u64 {
        self.calls.get()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn offsets_are_exclusive_prefix_sums() {
        assert_eq!(offsets(&[3, 0, 2]), vec![0, 3, 3, 5]);
    }

    #[test]
    fn serial_comm_exchanges_nothing() {
        let c = SerialComm;
        let (recv, _) = c.alltoallv_u64(&[1, 2, 3], &[3]);
        assert_eq!(recv, vec![1, 2, 3]);
        let mut v = vec![0u8; 10];
        c.broadcast_bytes(0, &mut v);
        assert_eq!(c.traffic(), Traffic::default());
    }

    #[test]
    fn traffic_differences_and_sums() {
        let a = Traffic {
            sent: 10,
            received: 4,
        };
        let b = Traffic {
            sent: 25,
            received: 9,
        };
        assert_eq!(
            b - a,
            Traffic {
                sent: 15,
                received: 5
            }
        );
        assert_eq!((a + b).total(), 48);
    }

    #[test]
    fn serial_agree_passes_errors_through() {
        let c = SerialComm;
        let r: Result<u32> = agree(&c, Err(Error::invalid("bad level")));
        assert_eq!(r.unwrap_err().message(), "bad level");
        assert_eq!(agree(&c, Ok(5)).unwrap(), 5);
    }
}
