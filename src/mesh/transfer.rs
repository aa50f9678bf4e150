//! Moving a solver's fields from the mesh before an adaptation step to the
//! mesh after it: which old elements each new element came from
//! ([`ElementMap`]), element fields ([`transfer_elements`]) and trilinear
//! nodal fields ([`transfer_nodes`]).
//!
//! Both meshes cover the same domain with octree leaves, so every new
//! element either equals an old element, lies inside one (refined), or
//! contains old elements (coarsened), possibly only some of them kept (a
//! solid or fluid mesh), or none (a leaf that was not an element):
//!
//! ```text
//!   old  +-------+-------+      new  +---+---+-------+
//!        |       |   |   |           |   |   |       |
//!        |   a   +---+---+           +---+---+   B   |   A in a: refined (+1)
//!        |       |   |   |           |   |   |       |   B over 4: coarsened (-1)
//!        +-------+---+---+           +---+---+-------+
//! ```
//!
//! The partitions of the two meshes differ: old elements travel to the
//! ranks whose new cell range they overlap in one all-to-all (an element
//! straddling a new rank boundary goes to both), which is all the element
//! map and the element transfer need.
//!
//! **Nodal fields.** A new node takes the value of the old trilinear field
//! at its position. A point on a face, edge or corner between old
//! elements is evaluated in one canonical element: of the eight finest
//! cells around the point, taken in the order of their offsets (the cell
//! above the point along every axis first, as [`crate::octree::search`]'s tie rule),
//! the first that lies in an old element. The point goes to the old owners
//! of those cells (one all-to-all, usually to a single rank), which answer
//! with the value and the rank of the cell they used; so every rank, on any
//! number of ranks, evaluates a node in the same element with the same
//! arithmetic, and the values are the same bits. The old field's hanging
//! nodes are taken as the means of their dependencies (whatever the caller
//! stored there), and so are the new ones, so the new field satisfies the
//! new mesh's constraints exactly. A field that is trilinear over the
//! domain is transferred exactly (to rounding), on refinement and on
//! coarsening.
//!
//! Values are interleaved per node (or element): component `c` of node `n`
//! is `values[n * ncomp + c]`.

use crate::error::{Error, ErrorKind, Result};
use crate::octree::octant::{morton_encode, Octant, LATTICE_BITS};
use crate::octree::owner_of_cell;
use crate::octree::sort::gallop_last_le;
use crate::parallel::comm::{offsets, Comm};

use super::{Mesh, VTK_TO_MORTON};

/// Where each new local element came from, in the new mesh's element order.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ElementMap {
    /// Global number (in the old mesh) of the first old element the new
    /// element overlaps, `u64::MAX` when it overlaps none.
    pub old_first: Vec<u64>,
    /// How many old elements it overlaps: their global numbers are
    /// `old_first .. old_first + old_count` (kept elements are numbered in
    /// Morton order, so those inside one octant are consecutive).
    pub old_count: Vec<u32>,
    /// New level minus old level: 0 for the same element, `k > 0` for an
    /// element inside an old one `k` levels coarser (refined), `-k` for an
    /// element containing old ones, the finest `k` levels finer
    /// (coarsened); 0 also when it overlaps none.
    pub level_change: Vec<i8>,
    /// New elements that overlap no old element, over all ranks.
    pub uncovered: u64,
}

/// The old elements overlapping this rank's new elements, in Morton order,
/// with their global numbers and `words` payload words each.
struct Received {
    leaves: Vec<Octant>,
    global: Vec<u64>,
    payload: Vec<u64>,
    words: usize,
}

impl Received {
    /// The range of received old elements overlapping `e`, from `start` on
    /// (the new elements are visited in order); returns the range.
    fn overlapping(&self, e: Octant, start: &mut usize) -> std::ops::Range<usize> {
        let (b, end) = (e.cell_begin(), e.cell_end());
        let mut i = *start;
        while i < self.leaves.len() && self.leaves[i].cell_end() <= b {
            i += 1;
        }
        let first = i;
        while i < self.leaves.len() && self.leaves[i].cell_begin() < end {
            i += 1;
        }
        // The last one may extend into the next new element.
        *start = if i > first { i - 1 } else { i };
        first..i
    }
}

/// Checks that `old` and `new` are meshes of the same domain on the same
/// ranks.
fn check_pair(old: &Mesh, new: &Mesh) -> Result<()> {
    if old.domain != new.domain || old.size != new.size || old.rank != new.rank {
        return Err(Error::invalid(
            "the old and new meshes must cover the same domain on the same ranks",
        ));
    }
    if old.first_cells.len() != old.size + 1 || new.first_cells.len() != new.size + 1 {
        return Err(Error::new(
            ErrorKind::State,
            "a mesh without its partition's first cells cannot transfer data",
        ));
    }
    Ok(())
}

/// Sends each old element, with `payload(local element)` (`words` words),
/// to every rank whose new cell range it overlaps. Collective.
fn send_old(
    comm: &dyn Comm,
    old: &Mesh,
    new: &Mesh,
    words: usize,
    payload: impl Fn(usize, &mut Vec<u64>),
) -> Received {
    let p = comm.size();
    let first = &new.first_cells;
    let targets = |e: Octant| {
        let a = owner_of_cell(first, e.cell_begin());
        let b = owner_of_cell(first, e.cell_end() - 1);
        // Ranks in between with an empty range get nothing.
        (a..=b).filter(move |&r| first[r] < first[r + 1])
    };
    let mut counts = vec![0usize; p];
    for &e in old.elements.iter() {
        for r in targets(e) {
            counts[r] += 2 + words;
        }
    }
    let starts = offsets(&counts);
    let mut at = starts.clone();
    let mut send = vec![0u64; starts[p]];
    let mut buf = Vec::with_capacity(words);
    for (i, &e) in old.elements.iter().enumerate() {
        buf.clear();
        payload(i, &mut buf);
        debug_assert_eq!(buf.len(), words);
        for r in targets(e) {
            let s = &mut send[at[r]..at[r] + 2 + words];
            s[0] = e.key();
            s[1] = old.first_element + i as u64;
            s[2..].copy_from_slice(&buf);
            at[r] += 2 + words;
        }
    }
    let (recv, _) = comm.alltoallv_u64(&send, &counts);
    drop(send);
    // Ranks' old ranges are consecutive in Morton order, so the
    // concatenation is sorted.
    let n = recv.len() / (2 + words);
    let mut r = Received {
        leaves: Vec::with_capacity(n),
        global: Vec::with_capacity(n),
        payload: Vec::with_capacity(n * words),
        words,
    };
    for w in recv.chunks_exact(2 + words) {
        r.leaves.push(Octant::from_key(w[0]));
        r.global.push(w[1]);
        r.payload.extend_from_slice(&w[2..]);
    }
    r
}

impl ElementMap {
    /// The map from `old`'s elements to `new`'s. Collective; both meshes
    /// must be of the same domain and ranks (an error on every rank
    /// otherwise).
    pub fn new(comm: &dyn Comm, old: &Mesh, new: &Mesh) -> Result<ElementMap> {
        crate::parallel::comm::agree(comm, check_pair(old, new))?;
        let got = send_old(comm, old, new, 0, |_, _| {});
        let n = new.elements.len();
        let mut map = ElementMap {
            old_first: Vec::with_capacity(n),
            old_count: Vec::with_capacity(n),
            level_change: Vec::with_capacity(n),
            uncovered: 0,
        };
        let mut start = 0;
        let mut uncovered = 0u64;
        for &e in new.elements.iter() {
            let range = got.overlapping(e, &mut start);
            if range.is_empty() {
                uncovered += 1;
                map.old_first.push(u64::MAX);
                map.old_count.push(0);
                map.level_change.push(0);
                continue;
            }
            // One old element at most as fine (unchanged, refined), or the
            // finest of those inside (coarsened).
            let finest = got.leaves[range.clone()]
                .iter()
                .map(|o| o.level())
                .max()
                .unwrap_or(0);
            let change = e.level() as i8 - finest as i8;
            map.old_first.push(got.global[range.start]);
            map.old_count.push(range.len() as u32);
            map.level_change.push(change);
        }
        let mut sum = [uncovered];
        comm.sum_u64(&mut sum);
        map.uncovered = sum[0];
        Ok(map)
    }
}

/// Checks a field's length: `ncomp` values per item.
fn check_len(values: &[f64], ncomp: usize, items: usize, what: &str) -> Result<()> {
    if ncomp == 0 {
        return Err(Error::invalid("a field needs at least one component"));
    }
    if values.len() != ncomp * items {
        return Err(Error::invalid(format!(
            "the old {what} field has {} values, expected {ncomp} per {what} ({} {what}s)",
            values.len(),
            items
        )));
    }
    Ok(())
}

/// An element field (`ncomp` values per element of `old`) on `new`'s
/// elements: copied into refined and unchanged elements, the volume-weighted
/// mean of the old elements inside a coarsened one (in Morton order, so the
/// same bits on any number of ranks: a conserved quantity stays conserved
/// to rounding); NaN where a new element overlaps no old one. Collective.
pub fn transfer_elements(
    comm: &dyn Comm,
    old: &Mesh,
    new: &Mesh,
    ncomp: usize,
    values: &[f64],
) -> Result<Vec<f64>> {
    let check = check_pair(old, new).and(check_len(values, ncomp, old.elements.len(), "element"));
    crate::parallel::comm::agree(comm, check)?;
    let got = send_old(comm, old, new, ncomp, |i, out| {
        out.extend(
            values[i * ncomp..(i + 1) * ncomp]
                .iter()
                .map(|v| v.to_bits()),
        );
    });
    let mut out = vec![f64::NAN; new.elements.len() * ncomp];
    let mut start = 0;
    let mut sum = vec![0.0f64; ncomp];
    for (k, &e) in new.elements.iter().enumerate() {
        let range = got.overlapping(e, &mut start);
        let dst = &mut out[k * ncomp..(k + 1) * ncomp];
        if range.len() == 1 && got.leaves[range.start].level() <= e.level() {
            let src = &got.payload[range.start * ncomp..(range.start + 1) * ncomp];
            for (d, &s) in dst.iter_mut().zip(src) {
                *d = f64::from_bits(s);
            }
        } else if !range.is_empty() {
            sum.fill(0.0);
            let mut volume = 0.0f64;
            for j in range {
                // Volumes relative to the new element: exact powers of two.
                let w = ((got.leaves[j].side() as f64) / (e.side() as f64)).powi(3);
                volume += w;
                let src = &got.payload[j * got.words..(j + 1) * got.words];
                for (s, &v) in sum.iter_mut().zip(src) {
                    *s += w * f64::from_bits(v);
                }
            }
            for (d, s) in dst.iter_mut().zip(&sum) {
                *d = s / volume;
            }
        }
    }
    Ok(out)
}

/// Bits per coordinate of a lattice point in a request (0 ..= 2^19).
const POINT_BITS: u32 = LATTICE_BITS + 1;
/// No old element holds the point (answer).
const NONE: u64 = 8;

fn pack(p: [u32; 3]) -> u64 {
    p[0] as u64 | (p[1] as u64) << POINT_BITS | (p[2] as u64) << (2 * POINT_BITS)
}

fn unpack(w: u64) -> [u32; 3] {
    let m = (1u64 << POINT_BITS) - 1;
    [
        (w & m) as u32,
        (w >> POINT_BITS & m) as u32,
        (w >> (2 * POINT_BITS) & m) as u32,
    ]
}

/// The finest cell `k` around lattice point `p` in the canonical order: bit
/// `j` of `k` means one cell lower along axis `j`; `None` for a cell
/// outside `[0, hi)`. Cell 0 is the highest of the eight in Morton order,
/// cell 7 the lowest.
#[inline]
fn cell_around(p: [u32; 3], hi: [u32; 3], k: usize) -> Option<u64> {
    let mut c = [0u32; 3];
    for j in 0..3 {
        c[j] = if (k >> j) & 1 == 1 {
            p[j].checked_sub(1)?
        } else if p[j] < hi[j] {
            p[j]
        } else {
            return None;
        };
    }
    Some(morton_encode(c[0], c[1], c[2]))
}

/// The old ranks holding the cells around `p` (the ranks' cell ranges are
/// consecutive in Morton order, so when the lowest and the highest cell
/// have one owner, all have).
fn owners_around(p: [u32; 3], hi: [u32; 3], first: &[u64], out: &mut Vec<u32>) {
    out.clear();
    let ranks = first.len() - 1;
    if ranks == 1 {
        out.push(0);
        return;
    }
    let lowest = (0..8).rev().find_map(|k| cell_around(p, hi, k));
    let highest = (0..8).find_map(|k| cell_around(p, hi, k));
    let (Some(a), Some(b)) = (lowest, highest) else {
        return;
    };
    let (ra, rb) = (owner_of_cell(first, a), owner_of_cell(first, b));
    if ra == rb {
        out.push(ra as u32);
        return;
    }
    for c in (0..8).filter_map(|k| cell_around(p, hi, k)) {
        let r = owner_of_cell(first, c) as u32;
        if !out.contains(&r) {
            out.push(r);
        }
    }
}

/// Every local node's value with the hanging ones replaced by the means of
/// their dependencies.
fn constrained(mesh: &Mesh, ncomp: usize, values: &[f64]) -> Vec<f64> {
    let mut v = values.to_vec();
    resolve_hanging(mesh, ncomp, &mut v);
    v
}

/// Sets each hanging node of `mesh` to the mean of its dependencies.
fn resolve_hanging(mesh: &Mesh, ncomp: usize, v: &mut [f64]) {
    let ni = mesh.num_independent;
    for k in 0..mesh.num_hanging() {
        let deps = mesh.hanging_deps(k);
        let w = 1.0 / deps.len() as f64;
        for c in 0..ncomp {
            let s: f64 = deps.iter().map(|&d| v[d as usize * ncomp + c]).sum();
            v[(ni + k) * ncomp + c] = s * w;
        }
    }
}

/// A trilinear nodal field (`ncomp` values per local node of `old`, the
/// hanging ones included) evaluated at `new`'s nodes (see the module
/// documentation for the canonical element of a point). Nodes of `new` in
/// no old element (a region the old mesh did not keep) get NaN; their
/// number over all ranks is returned with the values. Collective.
pub fn transfer_nodes(
    comm: &dyn Comm,
    old: &Mesh,
    new: &Mesh,
    ncomp: usize,
    values: &[f64],
) -> Result<(Vec<f64>, u64)> {
    let check = check_pair(old, new).and(check_len(values, ncomp, old.num_nodes(), "node"));
    crate::parallel::comm::agree(comm, check)?;
    let p = comm.size();
    let hi = new.domain.brick.hi();
    let first = &old.first_cells;
    let lattice = new.node_lattice();
    let ni = new.num_independent;

    // Requests: each independent new node to each distinct old owner of
    // the cells around it (one for most nodes: remembered, not searched
    // again).
    const MANY: u32 = u32::MAX;
    let mut counts = vec![0usize; p];
    let mut owners = Vec::with_capacity(8);
    let single: Vec<u32> = lattice[..ni]
        .iter()
        .map(|&q| {
            owners_around(q, hi, first, &mut owners);
            for &r in &owners {
                counts[r as usize] += 1;
            }
            if owners.len() == 1 {
                owners[0]
            } else {
                MANY
            }
        })
        .collect();
    let starts = offsets(&counts);
    let mut at = starts.clone();
    let mut send = vec![0u64; starts[p]];
    let mut node_of = vec![0u32; starts[p]];
    for (n, q) in lattice[..ni].iter().enumerate() {
        owners.clear();
        match single[n] {
            MANY => owners_around(*q, hi, first, &mut owners),
            r => owners.push(r),
        }
        for &r in &owners {
            let s = &mut at[r as usize];
            send[*s] = pack(*q);
            node_of[*s] = n as u32;
            *s += 1;
        }
    }
    drop(single);
    drop(lattice);
    let (recv, recv_counts) = comm.alltoallv_u64(&send, &counts);
    drop(send);

    // The old owners evaluate.
    let field = constrained(old, ncomp, values);
    let (begin, end) = (first[old.rank], first[old.rank + 1]);
    let elements: &[Octant] = &old.elements;
    let mut answers = Vec::with_capacity(recv.len() * (1 + ncomp));
    let mut value = vec![0.0f64; ncomp];
    // Requests come in the new mesh's node order, close in space one after
    // the other: search from the last answer.
    let mut hint = 0;
    for &w in &recv {
        let q = unpack(w);
        let mut found = NONE;
        for k in 0..8 {
            let Some(c) = cell_around(q, hi, k).filter(|c| (begin..end).contains(c)) else {
                continue;
            };
            let Some(i) = gallop_last_le(elements.len(), hint, c, |i| elements[i].cell_begin())
            else {
                continue;
            };
            if elements[i].cell_end() <= c {
                continue;
            }
            hint = i;
            evaluate(old, i, q, ncomp, &field, &mut value);
            found = k as u64;
            break;
        }
        answers.push(found);
        if found == NONE {
            answers.extend(std::iter::repeat_n(f64::NAN.to_bits(), ncomp));
        } else {
            answers.extend(value.iter().map(|v| v.to_bits()));
        }
    }
    drop((recv, field));
    let back_counts: Vec<usize> = recv_counts.iter().map(|n| n * (1 + ncomp)).collect();
    let (back, _) = comm.alltoallv_u64(&answers, &back_counts);
    drop(answers);

    // The answer from the first cell in canonical order wins.
    let mut out = vec![f64::NAN; new.num_nodes() * ncomp];
    let mut best = vec![NONE; ni];
    for (s, w) in back.chunks_exact(1 + ncomp).enumerate() {
        let n = node_of[s] as usize;
        if w[0] < best[n] {
            best[n] = w[0];
            for c in 0..ncomp {
                out[n * ncomp + c] = f64::from_bits(w[1 + c]);
            }
        }
    }
    resolve_hanging(new, ncomp, &mut out);
    // Only owned nodes count, so that each node counts once.
    let mut missing = [(0..new.num_owned).filter(|&n| best[n] == NONE).count() as u64];
    comm.sum_u64(&mut missing);
    Ok((out, missing[0]))
}

/// The trilinear interpolation of `field` in local element `e` of `mesh`
/// at lattice point `q` (inside the element's closed box).
fn evaluate(mesh: &Mesh, e: usize, q: [u32; 3], ncomp: usize, field: &[f64], out: &mut [f64]) {
    let o = mesh.elements[e];
    let (a, s) = (o.coords(), o.side() as f64);
    // Exact binary fractions in [0, 1].
    let t: [f64; 3] = std::array::from_fn(|j| (q[j] - a[j]) as f64 / s);
    out.fill(0.0);
    let conn = &mesh.connectivity[e];
    for (v, &n) in conn.iter().enumerate() {
        let m = VTK_TO_MORTON[v];
        let w = (0..3)
            .map(|j| if (m >> j) & 1 == 1 { t[j] } else { 1.0 - t[j] })
            .product::<f64>();
        for c in 0..ncomp {
            out[c] += w * field[n as usize * ncomp + c];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_pack_cells_go_round_in_order_and_owners_are_found() {
        let top = 1u32 << LATTICE_BITS;
        for p in [[0, 0, 0], [top, top, top], [5, top, 77]] {
            assert_eq!(unpack(pack(p)), p);
        }
        let hi = [top; 3];
        let around =
            |p: [u32; 3]| -> Vec<Option<u64>> { (0..8).map(|k| cell_around(p, hi, k)).collect() };
        let c = around([0, 0, 0]);
        assert_eq!(c[0], Some(0));
        assert!(c[1..].iter().all(|c| c.is_none()));
        let c = around([top, top, top]);
        assert_eq!(c.iter().filter(|c| c.is_some()).count(), 1);
        assert_eq!(c[7], Some(morton_encode(top - 1, top - 1, top - 1)));
        let c = around([4, 4, 4]);
        assert_eq!(c[0], Some(morton_encode(4, 4, 4)));
        assert_eq!(c[1], Some(morton_encode(3, 4, 4)));
        assert_eq!(c[6], Some(morton_encode(4, 3, 3)));
        // Cell 0 is the highest and cell 7 the lowest in Morton order.
        let codes: Vec<u64> = c.iter().map(|c| c.unwrap()).collect();
        assert_eq!(codes.iter().max(), Some(&codes[0]));
        assert_eq!(codes.iter().min(), Some(&codes[7]));
        // Owners: ranks split at cell 3 of the 8 around (4, 4, 4).
        let mut sorted = codes.clone();
        sorted.sort_unstable();
        let first = [0, sorted[3], 1 << 57];
        let mut out = Vec::new();
        owners_around([4, 4, 4], hi, &first, &mut out);
        assert_eq!(out.len(), 2);
        owners_around([2, 2, 2], hi, &first, &mut out);
        assert_eq!(out, vec![0]);
    }
}
