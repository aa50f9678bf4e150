//! 2:1 balance across ranks, for face, edge or corner connectivity.
//!
//! # The rule
//!
//! A family (the eight children of `p`, at level `l`) needs every same-size
//! neighbour `m` of `p` that touches it with a counted contact to be covered
//! at level `l - 1` or finer: no leaf may strictly contain `m`. That is
//! necessary in any balanced refinement (a leaf strictly containing `m`
//! would touch a level-`l` leaf in the family), and applying it to every
//! family until nothing changes gives a balanced tree (Sundar, Sampath &
//! Biros 2008). So the result is the coarsest balanced refinement, which is
//! unique: the same on any number of ranks, and the same as p4est's.
//!
//! Three facts keep the work small:
//! - the siblings of `p` are always covered (a leaf containing one would
//!   contain `p`), so only the neighbours outside `p`'s parent matter;
//! - such a neighbour `m` is covered exactly when its parent `q` is not a
//!   leaf and not inside one, and covering `m` means splitting `q`; so a
//!   family probes the distinct parents `q` (at most 7) rather than every
//!   `m` (up to 19);
//! - an internal node's rule follows from its descendants' rules, so only
//!   families that contain at least one leaf are processed, and after a split
//!   only the new families.
//!
//! The probes of one level are radix-sorted and resolved in one sequential
//! sweep over the leaves, which is far cheaper than a search per probe.
//! Most probes repeat one made by a neighbouring family; a small
//! direct-mapped table drops those before they are stored.
//!
//! # Passes and rounds
//!
//! Levels are processed from the finest to the coarsest: splitting a leaf to
//! cover a level-`l-1` octant only creates leaves coarser than `l`, which are
//! processed later in the same pass. A probe `m` that lies in another rank's
//! range is sent to that rank; a probe that straddles a rank boundary cannot
//! be inside a leaf and is dropped. Each round is one local pass and
//! one `alltoallv` of probes; rounds repeat until no rank sends anything, so
//! a ripple may cross any number of ranks.

use crate::error::Result;
use crate::octree::brick::Brick;
use crate::octree::limits::{limit_error, NO_LIMIT};
use crate::octree::octant::{spread3, Connectivity, Octant, MAX_LEVEL};
use crate::octree::sort::{gallop_last_le, radix_sort_bits};
use crate::octree::{owner_of_cell, LinearOctree};

/// What a balance did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BalanceStats {
    /// Communication rounds (1 on a single rank).
    pub rounds: u32,
    /// Probes this rank sent to other ranks.
    pub probes_sent: u64,
    /// Leaves this rank gained.
    pub leaves_added: u64,
}

impl LinearOctree {
    /// Refines the octree until no two leaves in contact of the given kind
    /// differ by more than one level. Collective. Leaves stay where they are
    /// in the Morton order; call [`LinearOctree::partition`] afterwards to
    /// even out the counts.
    pub fn balance(&mut self, conn: Connectivity) -> Result<BalanceStats> {
        self.balance_with_limit(conn, NO_LIMIT)
    }

    /// [`LinearOctree::balance`] that fails with an
    /// [`crate::ErrorKind::Limit`] error, on every rank, instead of creating
    /// more than `limit` leaves over all ranks. The growth is checked
    /// before each batch of splits is applied, so a rank never holds much
    /// more than `limit` leaves (the whole tree could grow several times
    /// over). On failure the octree is left as it was; for that it keeps a
    /// copy of the local leaves while it works (8 bytes per leaf), but only
    /// when there is a limit. Collective.
    pub fn balance_with_limit(&mut self, conn: Connectivity, limit: u64) -> Result<BalanceStats> {
        let comm = self.comm().clone();
        let before = self.local_len();
        let was_balanced = self.balanced();
        let backup = (limit != NO_LIMIT).then(|| self.leaves().to_vec());
        // Balancing for a weaker contact keeps a stronger balance.
        let strongest = was_balanced.map_or(conn, |b| b.max(conn));
        let mut b = Balancer::new(self, conn, limit);
        let mut stats = BalanceStats::default();
        let over = loop {
            stats.rounds += 1;
            b.local_pass();
            let sent: usize = b.outbox.iter().map(|o| o.len()).sum();
            // One reduction: probes to send, leaves, and ranks over the limit.
            let mut total = [sent as u64, b.leaves.len() as u64, u64::from(b.over)];
            comm.sum_u64(&mut total);
            if total[2] > 0 || total[1] > limit {
                break true;
            }
            if total[0] == 0 {
                break false;
            }
            stats.probes_sent += sent as u64;
            let (send, counts) = b.take_outbox();
            let (recv, _) = comm.alltoallv_u64(&send, &counts);
            b.apply_probes(recv.into_iter().map(Octant::from_key).collect());
        };
        let mut leaves = std::mem::take(&mut b.leaves);
        drop(b);
        crate::run::report::trim_heap();
        if over {
            // Every rank gets here in the same round (the decision is on
            // reduced values); nothing was published, so the ranges and
            // offsets are still those of the backup.
            self.set_leaves(backup.unwrap_or_default());
            self.set_balanced(was_balanced);
            return Err(limit_error(limit, "2:1 balancing"));
        }
        // The work vector was sized for the worst case; the octree is kept
        // for the rest of the pipeline, so give the slack back.
        leaves.shrink_to_fit();
        self.set_leaves(leaves);
        stats.leaves_added = (self.local_len() - before) as u64;
        self.refresh()?;
        self.set_balanced(Some(strongest));
        Ok(stats)
    }
}

/// For a family parent that is child `c` of its own parent `pp`, the
/// distinct steps from `pp` to the parents `q` of its counted neighbours
/// outside `pp`: along axis `k`, 0 (the neighbour stays in `pp`'s slab) or
/// 1 (it lies beyond `pp` on the side where `c` sits, bit `k` of `c`); never
/// all 0. Up to 7 for corner contacts, 6 for edges, 3 for faces.
///
/// ```text
///   pp's row along x:   [ q  ][    pp    ][ q' ]
///                              [c0][c1]
///   child c0 (bit clear) reaches q below, c1 (bit set) q' above; offsets
///   that stay inside pp (c0 + 1, c1 - 1) reach no other parent.
/// ```
fn probe_steps(offsets: &[[i32; 3]]) -> [([[u8; 3]; 7], usize); 8] {
    std::array::from_fn(|c| {
        let mut steps = [[0u8; 3]; 7];
        let mut n = 0;
        for d in offsets {
            let side = |k: usize| if c >> k & 1 == 1 { 1 } else { -1 };
            let e: [u8; 3] = std::array::from_fn(|k| (d[k] == side(k)) as u8);
            if e != [0; 3] && !steps[..n].contains(&e) {
                steps[n] = e;
                n += 1;
            }
        }
        (steps, n)
    })
}

/// Slots of [`Balancer::recent`]: `2^RECENT_BITS` (128 KiB).
const RECENT_BITS: u32 = 14;

/// Splits of a pass not yet moved into the leaf buffer: a leaf split in
/// the pass is replaced, in the buffer, only at the pass's end, and until
/// then its pieces are looked up here.
///
/// ```text
///   leaves:   [ a ][ b ][      c      ][ d ]     groups: (c, arena[4..12])
///   arena:    [ · · · · | c0 c1 c2 c3 c4 c5 c6 c7 ]
///   merged:   [ a ][ b ][c0][c1] ... [c7][ d ]
/// ```
///
/// A group whose pieces are split again at a coarser level gets its new
/// pieces at the arena's end; the old ones stay unused until the merge.
#[derive(Default)]
struct Overlay {
    /// By leaf index.
    groups: Vec<Group>,
    /// The pieces of every group, each group's in Morton order.
    arena: Vec<Octant>,
    /// Octants the groups add to the buffer (each replaces one leaf).
    added: usize,
    /// Scratch: a level's new groups.
    fresh: Vec<Group>,
}

/// Leaf `idx` is replaced by `arena[start..start + len]`.
#[derive(Clone, Copy, Debug, Default)]
struct Group {
    idx: usize,
    start: usize,
    len: usize,
}

impl Group {
    /// Where its pieces are in the arena.
    fn pieces(&self) -> std::ops::Range<usize> {
        self.start..self.start + self.len
    }
}

struct Balancer {
    /// The domain's root cells: families in the void, and probes leaving
    /// the brick, are skipped (p4est's brick has nothing there).
    brick: Brick,
    /// Upper lattice bounds of the brick.
    hi: [i64; 3],
    /// [`probe_steps`] of the connectivity.
    steps: [([[u8; 3]; 7], usize); 8],
    begin: u64,
    end: u64,
    first_cell: Vec<u64>,
    leaves: Vec<Octant>,
    /// Splits made but not yet moved into `leaves`.
    overlay: Overlay,
    /// `pending[l]`: parents of families at level `l` still to process.
    pending: Vec<Vec<Octant>>,
    outbox: Vec<Vec<u64>>,
    /// Direct-mapped filter of the local probes already pushed at the
    /// current level (`u64::MAX`: empty). Neighbouring families share most
    /// of their probes (about 14 pushes per distinct probe on a surface
    /// refinement); dropping the repeats here keeps the probe list, its
    /// sort buffer and the sort about that much smaller. Repeats it misses
    /// are removed after the sort.
    recent: Vec<u64>,
    /// Most leaves the rank may hold (the global limit).
    limit: usize,
    /// Set when applying the splits would exceed `limit`; the pass stops.
    over: bool,
}

impl Balancer {
    fn new(tree: &mut LinearOctree, conn: Connectivity, limit: u64) -> Balancer {
        let (begin, end) = tree.local_cells();
        let p = tree.comm().size();
        let mut leaves = tree.take_leaves();
        // Headroom for the balance's growth, so the leaf buffer is not
        // reallocated (and its pages faulted in again) at every level.
        leaves.reserve(leaves.len() / 4);
        let mut pending = vec![Vec::new(); MAX_LEVEL as usize + 1];
        for &o in &leaves {
            queue_family(&mut pending, o);
        }
        let brick = tree.brick();
        Balancer {
            overlay: Overlay::default(),
            steps: probe_steps(conn.offsets()),
            brick,
            hi: brick.hi().map(|v| v as i64),
            begin,
            end,
            first_cell: tree.first_cells().to_vec(),
            leaves,
            pending,
            outbox: vec![Vec::new(); p],
            recent: vec![u64::MAX; 1 << RECENT_BITS],
            limit: limit.min(usize::MAX as u64) as usize,
            over: false,
        }
    }

    /// Processes all pending families, finest level first.
    ///
    /// The splits of each level go to the overlay, and the leaf buffer is
    /// rewritten once at the end: each level's few splits would otherwise
    /// move every leaf after the first of them (a coarse level's handful of
    /// splits cost as much as the finest level's hundreds of thousands).
    fn local_pass(&mut self) {
        let mut splits: Vec<(usize, Octant)> = Vec::new();
        let mut nested: Vec<(usize, usize, Octant)> = Vec::new();
        let mut probes: Vec<u64> = Vec::new();
        let mut tmp: Vec<u64> = Vec::new();
        // A family at level `l <= k + 1` (k: the trees' level) asks only
        // that neighbours of level `l - 1 <= k` exist: every tree is split to
        // its own level already.
        let lowest = (self.brick.level() as usize + 2).max(2);
        for l in (lowest..=MAX_LEVEL as usize).rev() {
            if self.over {
                break;
            }
            let mut fams = std::mem::take(&mut self.pending[l]);
            if fams.is_empty() {
                continue;
            }
            if !fams.windows(2).all(|w| w[0] <= w[1]) {
                fams.sort_unstable();
            }
            fams.dedup();
            probes.clear();
            // Probes of different levels may share a Morton code.
            self.recent.fill(u64::MAX);
            for &p in &fams {
                self.probe_family(p, &mut probes);
            }
            // Resolve the probes in one sorted sweep over the leaves instead
            // of a random-access search each: the sweep is sequential in
            // memory.
            let qlevel = (l - 2) as u8;
            let low = 3 * (crate::octree::octant::LATTICE_BITS - qlevel as u32);
            radix_sort_bits(&mut probes, &mut tmp, low, 57);
            probes.dedup();
            splits.clear();
            nested.clear();
            let (mut i, mut g) = (0usize, 0usize);
            let n = self.leaves.len();
            let groups = &self.overlay.groups;
            for &q in &probes {
                // Galloping: the coarse levels' few probes skip most leaves.
                let leaves = &self.leaves;
                if let Some(j) = gallop_last_le(n, i, q, |k| leaves[k].cell_begin()) {
                    i = j;
                }
                let member = Octant::from_parts(q, qlevel + 1);
                // A leaf split earlier in this pass: look among its pieces.
                if let Some(h) = gallop_last_le(groups.len(), g, i as u64, |k| groups[k].idx as u64)
                {
                    g = h;
                    if groups[h].idx == i {
                        let piece = &self.overlay.arena[groups[h].pieces()];
                        let k = piece.partition_point(|o| o.cell_begin() <= q) - 1;
                        if piece[k].level() <= qlevel {
                            nested.push((h, k, member));
                        }
                        continue;
                    }
                }
                if self.leaves[i].level() <= qlevel {
                    // q is a leaf or inside one: it must be split.
                    splits.push((i, member));
                }
            }
            self.pending[l] = fams; // keep the allocation
            self.pending[l].clear();
            self.defer_splits(&mut splits, &mut nested);
        }
        self.merge_overlay();
    }

    /// For family parent `p` (level `l - 1`), collects the octants `q` at
    /// level `l - 2` that must not be leaves: the parents of `p`'s counted
    /// neighbours outside `p`'s own parent. A neighbour `m` is covered
    /// exactly when its parent `q` is an internal node, and splitting `q`
    /// creates `m` and its siblings at once, so probing `q` (at most 7 per
    /// family) replaces probing every `m` (up to 19). Local `q` go to
    /// `probes` (Morton codes); `q` inside one other rank go to its outbox
    /// as their first child; `q` straddling ranks are internal already.
    #[inline]
    fn probe_family(&mut self, p: Octant, probes: &mut Vec<u64>) {
        if self.brick.is_void(p) {
            return;
        }
        let (steps, n) = &self.steps[p.child_id() as usize];
        let c = p.coords();
        let len = p.side() as i64;
        let qmask = !(2 * p.side() - 1);
        let qlevel = p.level() - 1;
        // Per axis, `pp`'s coordinate and the one a step beyond it (`None`
        // outside the domain), spread into their Morton bits: each probe's
        // code is then three of them or-ed.
        let spread: [[Option<u64>; 2]; 3] = std::array::from_fn(|k| {
            let beyond = c[k] as i64
                + if p.child_id() >> k & 1 == 1 {
                    len
                } else {
                    -len
                };
            [
                Some(spread3(c[k] & qmask) << k),
                (beyond >= 0 && beyond < self.hi[k]).then(|| spread3(beyond as u32 & qmask) << k),
            ]
        });
        for e in &steps[..*n] {
            let at = |k: usize| spread[k][e[k] as usize];
            let (Some(x), Some(y), Some(z)) = (at(0), at(1), at(2)) else {
                continue;
            };
            let qb = x | y | z;
            let q = Octant::from_parts(qb, qlevel);
            let qe = q.cell_end();
            if qb >= self.begin && qe <= self.end {
                let slot = (qb.wrapping_mul(0x9e37_79b9_7f4a_7c15) >> (64 - RECENT_BITS)) as usize;
                if self.recent[slot] != qb {
                    self.recent[slot] = qb;
                    probes.push(qb);
                }
            } else if qe <= self.begin || qb >= self.end {
                let r = owner_of_cell(&self.first_cell, qb);
                if qe <= self.first_cell[r + 1] {
                    self.outbox[r].push(q.child(0).key());
                }
            }
        }
    }

    /// Replaces each leaf named in `splits` by the coarsest set of octants
    /// that covers every required octant inside it.
    fn apply_splits(&mut self, splits: &mut [(usize, Octant)]) {
        self.defer_splits(splits, &mut []);
        self.merge_overlay();
    }

    /// Records in the overlay the splits of one level: leaf `i` to be
    /// replaced by the coarsest set of octants in which every `member` of
    /// its pairs in `splits` is a leaf or has leaves below it, and piece
    /// `k` of group `g` for the triples `(g, k, member)` of `nested`. The
    /// new octants are queued for their own levels. Sets `over` instead
    /// when the leaves would exceed the limit.
    fn defer_splits(
        &mut self,
        splits: &mut [(usize, Octant)],
        nested: &mut [(usize, usize, Octant)],
    ) {
        if splits.is_empty() && nested.is_empty() {
            return;
        }
        splits.sort_unstable();
        nested.sort_unstable();
        // Each split octant becomes at least 8: refuse before allocating.
        // Sorted, its entries come in runs, one per split octant.
        let runs = |n: usize, starts: usize| (n > 0) as usize + starts;
        let split = runs(
            splits.len(),
            splits.windows(2).filter(|w| w[0].0 != w[1].0).count(),
        ) + runs(
            nested.len(),
            nested
                .windows(2)
                .filter(|w| w[0].0 != w[1].0 || w[0].1 != w[1].1)
                .count(),
        );
        let after = self.leaves.len() + self.overlay.added;
        if after.saturating_add(7 * split) > self.limit {
            self.over = true;
            return;
        }
        let Overlay {
            groups,
            arena,
            added,
            fresh,
        } = &mut self.overlay;
        let pending = &mut self.pending;
        // `piece` replaced by the coarsest cover of `members` at the arena's
        // end, the new octants queued for their own levels.
        let mut split_into = |arena: &mut Vec<Octant>, piece: Octant, members: &[Octant]| {
            let from = arena.len();
            refine_to(piece, members, arena);
            for &o in &arena[from..] {
                queue_family(pending, o);
            }
        };
        // Each split octant makes at least 8 pieces: one allocation of that
        // size, not a doubling series whose every buffer is fresh memory.
        arena.reserve(8 * split);
        let mut members = Vec::new();
        // Pieces split again: each group's new pieces go to the arena's end.
        let mut x = 0;
        let mut old = Vec::new();
        while x < nested.len() {
            let g = nested[x].0;
            let grp = groups[g];
            old.clear();
            old.extend_from_slice(&arena[grp.pieces()]);
            let start = arena.len();
            for (k, &piece) in old.iter().enumerate() {
                members.clear();
                while x < nested.len() && nested[x].0 == g && nested[x].1 == k {
                    if members.last() != Some(&nested[x].2) {
                        members.push(nested[x].2);
                    }
                    x += 1;
                }
                if members.is_empty() {
                    arena.push(piece);
                } else {
                    split_into(arena, piece, &members);
                }
            }
            let len = arena.len() - start;
            *added += len - grp.len;
            groups[g] = Group { start, len, ..grp };
        }
        // Leaves split for the first time: new groups, merged in by leaf.
        let mut i = 0;
        while i < splits.len() {
            let idx = splits[i].0;
            members.clear();
            while i < splits.len() && splits[i].0 == idx {
                if members.last() != Some(&splits[i].1) {
                    members.push(splits[i].1);
                }
                i += 1;
            }
            let start = arena.len();
            split_into(arena, self.leaves[idx], &members);
            let len = arena.len() - start;
            *added += len - 1;
            fresh.push(Group { idx, start, len });
        }
        // In place from the back: no second buffer of every group.
        let (mut a, mut b) = (groups.len(), fresh.len());
        groups.resize(a + b, Group::default());
        for w in (0..a + b).rev() {
            if b == 0 {
                break;
            }
            if a > 0 && groups[a - 1].idx > fresh[b - 1].idx {
                a -= 1;
                groups[w] = groups[a];
            } else {
                b -= 1;
                groups[w] = fresh[b];
            }
        }
        fresh.clear();
        crate::run::progress::set_done((self.leaves.len() + self.overlay.added) as u64);
    }

    /// Moves the overlay's pieces into the leaf buffer, in place: the
    /// leaves are moved to their final places from the back, so the buffer
    /// is not copied into a second one of the same size (whose pages would
    /// all be faulted in).
    fn merge_overlay(&mut self) {
        let Overlay {
            groups,
            arena,
            added,
            ..
        } = &mut self.overlay;
        if groups.is_empty() {
            return;
        }
        let old_len = self.leaves.len();
        let new_len = old_len + *added;
        self.leaves.resize(new_len, Octant::ROOT);
        // From the back: the leaves after each split leaf move up by the
        // number of octants added before them, then its pieces go in.
        let mut tail = old_len; // leaves[idx + 1..tail] still at their old place
        let mut write = new_len;
        for grp in groups.iter().rev() {
            let n = tail - (grp.idx + 1);
            self.leaves.copy_within(grp.idx + 1..tail, write - n);
            write -= n;
            self.leaves[write - grp.len..write].copy_from_slice(&arena[grp.pieces()]);
            write -= grp.len;
            tail = grp.idx;
        }
        debug_assert_eq!(write, tail);
        groups.clear();
        arena.clear();
        *added = 0;
    }

    /// Applies probes received from other ranks: sorted, then found by a
    /// galloping sweep, as the local ones (they are few, near the ends of
    /// the range: an index of every leaf would cost more than they do).
    fn apply_probes(&mut self, mut probes: Vec<Octant>) {
        probes.sort_unstable();
        let mut splits = Vec::new();
        let (n, mut i) = (self.leaves.len(), 0);
        for m in probes {
            if m.cell_begin() < self.begin || m.cell_end() > self.end {
                continue; // stale: cannot happen with a consistent partition
            }
            let leaves = &self.leaves;
            // The leaves cover the range: some leaf starts at or before it.
            if let Some(j) = gallop_last_le(n, i, m.cell_begin(), |k| leaves[k].cell_begin()) {
                i = j;
            }
            if self.leaves[i].level() < m.level() {
                splits.push((i, m));
            }
        }
        if !splits.is_empty() {
            self.apply_splits(&mut splits);
        }
    }

    fn take_outbox(&mut self) -> (Vec<u64>, Vec<usize>) {
        let mut send = Vec::new();
        let mut counts = Vec::with_capacity(self.outbox.len());
        for o in &mut self.outbox {
            o.sort_unstable();
            o.dedup();
            counts.push(o.len());
            send.append(o);
        }
        (send, counts)
    }
}

/// Queues the family of leaf `o` (its parent) for processing at `o`'s level.
/// Sibling leaves are usually adjacent, so a repeat of the last entry is
/// skipped here; the rest are removed by the sort before processing.
#[inline]
fn queue_family(pending: &mut [Vec<Octant>], o: Octant) {
    let l = o.level() as usize;
    let q = o.parent();
    if l >= 2 && pending[l].last() != Some(&q) {
        pending[l].push(q);
    }
}

/// Appends the coarsest complete set of octants inside `c` in which every
/// octant of `members` (sorted, strictly inside `c`) is a leaf or has leaves
/// below it.
fn refine_to(c: Octant, members: &[Octant], out: &mut Vec<Octant>) {
    let mut j = 0;
    for ch in c.children() {
        let start = j;
        while j < members.len() && ch.contains(members[j]) {
            j += 1;
        }
        let mut sub = &members[start..j];
        while let Some((&first, rest)) = sub.split_first() {
            if first == ch {
                sub = rest; // ch itself is required: being a leaf covers it
            } else {
                break;
            }
        }
        if sub.is_empty() {
            out.push(ch);
        } else {
            refine_to(ch, sub, out);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::parallel::comm::{CommRef, SerialComm};
    use crate::refine::{build_from_callback, NO_LIMIT};
    use std::rc::Rc;

    /// Independent O(n^2) check: every pair of leaves in counted contact
    /// differs by at most one level.
    fn brute_force_balanced(leaves: &[Octant], conn: Connectivity) -> bool {
        for (i, a) in leaves.iter().enumerate() {
            for b in &leaves[i + 1..] {
                if let Some(dim) = a.contact(*b) {
                    if conn.counts_contact(dim) && a.level().abs_diff(b.level()) > 1 {
                        return false;
                    }
                }
            }
        }
        true
    }

    #[test]
    fn corner_refinement_is_balanced_and_minimal() {
        for conn in [Connectivity::Face, Connectivity::Edge, Connectivity::Corner] {
            let comm: CommRef = Rc::new(SerialComm);
            // Refining towards one interior point leaves level jumps behind.
            let p = [157_286u32, 91_000, 200_001];
            let contains = |o: Octant| {
                (0..3).all(|k| o.coords()[k] <= p[k] && p[k] < o.coords()[k] + o.side())
            };
            let mut t = build_from_callback(comm, 7, contains, NO_LIMIT).unwrap();
            assert!(!brute_force_balanced(t.leaves(), conn));
            let before = t.leaves().to_vec();
            t.balance(conn).unwrap();
            t.check().unwrap();
            assert!(brute_force_balanced(t.leaves(), conn), "{conn:?}");
            // Coarsest: merging any complete family of leaves breaks balance
            // or loses an original leaf.
            let leaves = t.leaves().to_vec();
            for (i, w) in leaves.windows(8).enumerate() {
                if w[0].child_id() == 0
                    && w[7].child_id() == 7
                    && w.iter().all(|o| o.parent() == w[0].parent())
                {
                    let parent = w[0].parent();
                    if before.iter().any(|o| parent.is_ancestor_of(*o)) {
                        continue; // the input itself was finer here
                    }
                    let mut merged = leaves[..i].to_vec();
                    merged.push(parent);
                    merged.extend_from_slice(&leaves[i + 8..]);
                    assert!(
                        !brute_force_balanced(&merged, conn),
                        "{conn:?} not coarsest at {parent:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn limit_fails_and_keeps_the_octree() {
        let comm: CommRef = Rc::new(SerialComm);
        let p = [157_286u32, 91_000, 200_001];
        let contains =
            |o: Octant| (0..3).all(|k| o.coords()[k] <= p[k] && p[k] < o.coords()[k] + o.side());
        let mut t = build_from_callback(comm, 9, contains, NO_LIMIT).unwrap();
        let before = t.leaves().to_vec();
        let mut full = build_from_callback(Rc::new(SerialComm), 9, contains, NO_LIMIT).unwrap();
        full.balance(Connectivity::Corner).unwrap();
        let balanced = full.global_len();
        assert!(balanced > before.len() as u64 + 8);
        for limit in [before.len() as u64, balanced - 1] {
            let e = t
                .balance_with_limit(Connectivity::Corner, limit)
                .unwrap_err();
            assert_eq!(e.kind(), crate::ErrorKind::Limit);
            assert!(e.message().contains("balancing"), "{e}");
            assert_eq!(t.leaves(), &before[..]);
            assert_eq!(t.balanced(), None);
            t.check().unwrap();
        }
        t.balance_with_limit(Connectivity::Corner, balanced)
            .unwrap();
        assert_eq!(t.leaves(), full.leaves());
        assert_eq!(t.balanced(), Some(Connectivity::Corner));
        // A balanced octree keeps its flag when a later balance fails.
        let e = t.balance_with_limit(Connectivity::Face, balanced - 1);
        assert!(e.is_err());
        assert_eq!(t.leaves(), full.leaves());
        assert_eq!(t.balanced(), Some(Connectivity::Corner));
    }

    #[test]
    fn probe_steps_reach_the_parents_of_the_outside_neighbours() {
        // An interior family parent at level 5, each child position: the
        // parents of its neighbours outside its own parent, found one
        // neighbour at a time, are the steps' parents exactly.
        let pp = Octant::ROOT.child(3).child(5).child(6).child(1);
        for conn in [Connectivity::Face, Connectivity::Edge, Connectivity::Corner] {
            let steps = probe_steps(conn.offsets());
            for c in 0..8u32 {
                let p = pp.child(c);
                let mut brute: Vec<Octant> = (conn.offsets().iter())
                    .map(|&d| p.neighbor(d).unwrap().parent())
                    .filter(|&q| q != pp)
                    .collect();
                brute.sort_unstable();
                brute.dedup();
                let (list, n) = steps[c as usize];
                let mut got: Vec<Octant> = list[..n]
                    .iter()
                    .map(|e| {
                        let d = std::array::from_fn(|k| {
                            e[k] as i32 * if c >> k & 1 == 1 { 1 } else { -1 }
                        });
                        pp.neighbor(d).unwrap()
                    })
                    .collect();
                got.sort_unstable();
                assert_eq!(got.len(), n, "{conn:?} child {c}: a repeated step");
                got.dedup();
                assert_eq!(got, brute, "{conn:?} child {c}");
                let want = match conn {
                    Connectivity::Face => 3,
                    Connectivity::Edge => 6,
                    Connectivity::Corner => 7,
                };
                assert_eq!(n, want);
            }
        }
    }

    #[test]
    fn refine_to_builds_coarsest_cover() {
        let c = Octant::ROOT;
        let m = Octant::ROOT.child(5).child(2);
        let mut out = Vec::new();
        refine_to(c, &[m], &mut out);
        assert_eq!(out.len(), 15);
        assert!(out.contains(&m));
    }
}
