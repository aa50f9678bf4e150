//! Clean walls: drop kept leaves until the boundary of the kept region is a
//! manifold and every element has kept neighbours along all three axes, as
//! snappyHexMesh's castellated stage leaves its meshes.
//!
//! Two kept elements that touch only along an edge or at a corner make the
//! wall patch non-manifold (OpenFOAM's `checkMesh`: "multiply connected
//! (shared edge)"), and an element whose kept neighbours all lie along one
//! or two axes has a singular least-squares stencil ("cells with small
//! determinant"). At every corner `v` of a kept leaf the eight finest cells
//! around `v` are looked at, each kept or not (outside the domain counts as
//! not kept):
//!
//! ```text
//!     kept ■  dropped □           ■ □      the kept cells of the 2x2x2 block
//!                                 □ ■  ←   must be face-connected, and so
//!       (one layer of the block)           must the dropped ones
//! ```
//!
//! - when the kept cells fall in several face-connected groups, the leaves
//!   outside the largest group (ties: the group with the lowest cell) go;
//! - when the dropped cells do, the lowest kept cell touching two dropped
//!   groups goes;
//! - a kept leaf with no kept face neighbour across either face normal to
//!   some axis goes.
//!
//! Every rank decides for its own leaves from the statuses of the previous
//! sweep (its own and its ghosts'), so the result does not depend on the
//! partition. The first sweep looks at every kept leaf in one dual walk of
//! the leaves (`mesh::dual::walk_points`, which hands each corner
//! its block); sweeps then repeat around the leaves dropped last, looking
//! their neighbours up, until none is.

use crate::mesh::dual::{leaf_at, side_masks, walk_points, DualTree, Merged};
use crate::octree::ghost::GhostLayer;
use crate::octree::octant::{morton_encode, Octant, ROOT_LEN};
use crate::octree::LinearOctree;
use crate::parallel::comm::Comm;

/// Class bit of a leaf the clean-up dropped.
pub const REMOVED: u8 = 0x80;
/// Class bit of a leaf dropped in the last sweep.
const JUST_REMOVED: u8 = 0x40;

/// Drops kept leaves (sets [`REMOVED`] in their class byte) as the module
/// documentation says; `keep` tells which class bytes are kept before.
/// `ghosts` is the ghost layer of `tree` with each leaf's class byte as its
/// data (its data is stale on return). Returns the number dropped over all
/// ranks. Collective.
pub(crate) fn clean_walls(
    tree: &LinearOctree,
    ghosts: &mut GhostLayer,
    classes: &mut [u8],
    keep: impl Fn(u8) -> bool + Copy,
) -> u64 {
    let comm: &dyn Comm = &**tree.comm();
    let kept = move |b: u8| b & REMOVED == 0 && keep(b);
    let mut total = 0u64;
    let mut first = true;
    let b = ghosts.before;
    let nl = tree.local_len();
    let mut class: Vec<u8> = Vec::with_capacity(ghosts.len() + nl);
    loop {
        // The ghosts stay; only their classes change from sweep to sweep.
        if !first {
            ghosts.exchange_data(comm, |i| classes[i] as u64);
        }
        class.clear();
        class.extend(ghosts.data[..b].iter().map(|&w| w as u8));
        class.extend_from_slice(classes);
        class.extend(ghosts.data[b..].iter().map(|&w| w as u8));
        // The ghosts and the local leaves in one run, without a copy of
        // every leaf.
        let leaves = Merged {
            before: &ghosts.leaves[..b],
            local: tree.leaves(),
            after: &ghosts.leaves[b..],
        };
        let view = View {
            leaves,
            class: &class,
            kept: &kept,
        };
        let local = b..b + nl;
        // Every kept local leaf in the first sweep; then the kept local
        // leaves around those dropped in the last sweep.
        let drop: Vec<usize> = if first {
            first_sweep(leaves, &class, local.clone(), kept)
        } else {
            let mut candidates: Vec<usize> = Vec::new();
            for j in 0..leaves.len() {
                if class[j] & JUST_REMOVED != 0 {
                    view.ring(j, |k| {
                        if local.contains(&k) && kept(class[k]) {
                            candidates.push(k);
                        }
                    });
                }
            }
            candidates.sort_unstable();
            candidates.dedup();
            candidates
                .into_iter()
                .filter(|&i| view.must_go(i))
                .map(|i| i - b)
                .collect()
        };
        for c in classes.iter_mut() {
            *c &= !JUST_REMOVED;
        }
        for &i in &drop {
            classes[i] |= REMOVED | JUST_REMOVED;
        }
        let mut n = [drop.len() as u64];
        comm.sum_u64(&mut n);
        total += n[0];
        first = false;
        if n[0] == 0 {
            break;
        }
    }
    for c in classes.iter_mut() {
        *c &= !JUST_REMOVED;
    }
    total
}

/// The first sweep over every kept local leaf at once (positions in
/// `local`, counted from its start): one dual walk reaches every leaf
/// corner with the 8 leaves around it, which are the corner's block, and
/// the cells across each face at its corners, which are its face
/// neighbours under 2:1 balance; no search. The later sweeps, around a few
/// dropped leaves, look their rings up instead ([`View::must_go`], the same
/// rules).
fn first_sweep(
    leaves: Merged,
    class: &[u8],
    local: std::ops::Range<usize>,
    kept: impl Fn(u8) -> bool,
) -> Vec<usize> {
    // The walk goes over the kept leaves only: a dropped leaf is to the
    // rules what a gap is (not kept), and leaving the dropped ones out takes
    // their part of the walk away. `at[k]`: kept leaf `k`'s position in
    // `leaves`.
    // Room for every leaf: what stays unwritten is never resident.
    let (mut kl, mut at) = (
        Vec::with_capacity(leaves.len()),
        Vec::with_capacity(leaves.len()),
    );
    let all = leaves.parts().into_iter().flatten();
    for (j, (&o, &c)) in all.zip(class).enumerate() {
        if kept(c) {
            kl.push(o);
            at.push(j as u32);
        }
    }
    let lb = at.partition_point(|&j| (j as usize) < local.start);
    let le = at.partition_point(|&j| (j as usize) < local.end);
    let merged = Merged {
        before: &kl[..lb],
        local: &kl[lb..le],
        after: &kl[le..],
    };
    // Per kept local leaf: bit `2a + h` when a kept cell lies across its
    // face on side `h` (1: high) of axis `a` at some corner; GOES when a
    // corner block drops it.
    const GOES: u8 = 0x80;
    let mut seen = vec![0u8; le - lb];
    let local_kept = lb..le;
    let drop_masks = block_drop_masks();
    walk_points(&DualTree::new(&merged), |refs| {
        // `status` bit `p`: a kept leaf on side `p`. A leaf on two sides
        // is on two sides across an axis too (it is a box), so a leaf
        // alone on its side is on no side across from it: the point is one
        // of its corners.
        let (same, status, remote) = side_masks(refs, &local_kept);
        let drops = drop_masks[status as usize];
        let mut mine = status & !remote & !(same[0] | same[1] | same[2]);
        while mine != 0 {
            let p = mine.trailing_zeros() as usize;
            mine &= mine - 1;
            let Some(j) = leaf_at(refs[p]) else { continue };
            let bits = &mut seen[j - lb];
            for a in 0..3 {
                // On the high side of the point along `a`, the leaf has the
                // point on its low face.
                let high = (p >> a) & 1 == 0;
                if status >> (p ^ (1 << a)) & 1 == 1 {
                    *bits |= 1 << (2 * a + high as usize);
                }
            }
            if drops >> p & 1 == 1 {
                *bits |= GOES;
            }
        }
    });
    (0..le - lb)
        .filter(|&i| {
            let m = seen[i];
            m & GOES != 0 || (0..3).any(|a| m >> (2 * a) & 3 == 0)
        })
        .map(|i| at[lb + i] as usize - local.start)
        .collect()
}

/// Local and ghost leaves in Morton order with their class bytes.
struct View<'a, K: Fn(u8) -> bool> {
    leaves: Merged<'a>,
    class: &'a [u8],
    kept: &'a K,
}

impl<K: Fn(u8) -> bool> View<'_, K> {
    /// The leaf holding the finest cell at `x`, searched outwards from leaf
    /// `hint` (neighbours are usually close in Morton order).
    fn at(&self, x: [i64; 3], hint: usize) -> Option<usize> {
        if x.iter().any(|&c| c < 0 || c >= ROOT_LEN as i64) {
            return None;
        }
        let m = morton_encode(x[0] as u32, x[1] as u32, x[2] as u32);
        let leaves = self.leaves;
        let j = crate::octree::sort::gallop_last_le(leaves.len(), hint, m, |k| {
            leaves.get(k).cell_begin()
        })?;
        (leaves.get(j).cell_end() > m).then_some(j)
    }

    /// Calls `f` with every leaf touching leaf `i` (some more than once):
    /// the leaves holding its [`ring_cells`], which under 2:1 balance are
    /// all of them.
    fn ring(&self, i: usize, mut f: impl FnMut(usize)) {
        for (_, x) in ring_cells(self.leaves.get(i)) {
            if let Some(j) = self.at(x, i) {
                f(j);
            }
        }
    }

    /// Whether kept leaf `i` must go.
    fn must_go(&self, i: usize) -> bool {
        let l = self.leaves.get(i);
        let (c, s) = (l.coords().map(|v| v as i64), l.side() as i64);
        let h = (s / 2).max(1);
        // Statuses of a 4x4x4 grid of half-size cells centred on the leaf
        // (the leaf is the middle 2x2x2): the cells next to the leaf's
        // faces, edges and corners.
        let mut grid = [true; 64];
        let mut known = 0u64;
        let edge = |g: usize| -> i64 {
            match g {
                0 => -h,
                1 => 0,
                2 => h,
                3 => s,
                _ => s + h,
            }
        };
        for (k, x) in ring_cells(l) {
            if known >> k & 1 == 1 {
                continue;
            }
            let g = [k & 3, (k >> 2) & 3, k >> 4];
            let Some(j) = self.at(x, i) else {
                grid[k] = false;
                continue;
            };
            let status = (self.kept)(self.class[j]);
            // The leaf covers every grid cell inside its box: settle them
            // all with this one look-up.
            let lj = self.leaves.get(j);
            let (lc, ls) = (lj.coords(), lj.side() as i64);
            let lo: [i64; 3] = std::array::from_fn(|a| lc[a] as i64);
            let mut range = [(0usize, 0usize); 3];
            for a in 0..3 {
                let first = (0..4).find(|&t| c[a] + edge(t) >= lo[a]).unwrap_or(4);
                let last = (0..4).rev().find(|&t| c[a] + edge(t + 1) <= lo[a] + ls);
                range[a] = match last {
                    Some(l) if l >= first => (first, l),
                    _ => (g[a], g[a]),
                };
            }
            for z in range[2].0..=range[2].1 {
                for y in range[1].0..=range[1].1 {
                    for x in range[0].0..=range[0].1 {
                        let q = x | y << 2 | z << 4;
                        grid[q] = status;
                        known |= 1 << q;
                    }
                }
            }
        }
        let at = |g: [usize; 3]| grid[g[0] | g[1] << 2 | g[2] << 4];
        // Kept neighbours along each axis.
        for axis in 0..3 {
            let any = [0usize, 3].iter().any(|&side| {
                (1..3).any(|p| {
                    (1..3).any(|q| {
                        let mut g = [0; 3];
                        g[axis] = side;
                        g[(axis + 1) % 3] = p;
                        g[(axis + 2) % 3] = q;
                        at(g)
                    })
                })
            });
            if !any {
                return true;
            }
        }
        // The 2x2x2 blocks at the corners: corner bit a set = the high side,
        // block cells from grid index 1 or 2 (the leaf's) outwards.
        for corner in 0..8usize {
            let kept: [bool; 8] = std::array::from_fn(|k| {
                at(std::array::from_fn(|a| {
                    let hi = (corner >> a) & 1 == 1;
                    let bit = (k >> a) & 1;
                    // Block cell bit 0 is the low side of the corner.
                    match (hi, bit) {
                        (false, 0) => 0,
                        (false, _) => 1,
                        (true, 0) => 2,
                        (true, _) => 3,
                    }
                }))
            });
            let own = (0..3).fold(0usize, |k, a| k | (((corner >> a) & 1) ^ 1) << a);
            if block_drop_masks()[status_byte(&kept)] >> own & 1 == 1 {
                return true;
            }
        }
        false
    }
}

/// The 56 cells of the 4x4x4 grid of half-size cells centred on `leaf`
/// (index `x | y << 2 | z << 4`; the leaf is the middle 2x2x2) that lie
/// outside it, each with the finest cell sampled for it: the one touching
/// the leaf, so that corner cells see the leaf's corner neighbour even
/// under edge balance.
fn ring_cells(leaf: Octant) -> impl Iterator<Item = (usize, [i64; 3])> {
    let (c, s) = (leaf.coords().map(|v| v as i64), leaf.side() as i64);
    let h = (s / 2).max(1);
    (0..64usize).filter_map(move |k| {
        let g = [k & 3, (k >> 2) & 3, k >> 4];
        if g.iter().all(|&v| v == 1 || v == 2) {
            return None;
        }
        let x = std::array::from_fn(|a| {
            c[a] + match g[a] {
                0 => -1,
                1 => 0,
                2 => h,
                _ => s,
            }
        });
        Some((k, x))
    })
}

/// Face-connected groups of the cells `member` selects in a 2x2x2 block:
/// a group label per cell (`u8::MAX` for non-members), labels numbered by
/// lowest cell.
fn groups(member: &[bool; 8]) -> ([u8; 8], usize) {
    let mut label = [u8::MAX; 8];
    let mut n = 0;
    for start in 0..8 {
        if !member[start] || label[start] != u8::MAX {
            continue;
        }
        // Each cell is pushed at most once: eight slots suffice.
        let mut stack = [0usize; 8];
        let mut top = 1;
        stack[0] = start;
        label[start] = n as u8;
        while top > 0 {
            top -= 1;
            let k = stack[top];
            for a in 0..3 {
                let j = k ^ (1 << a);
                if member[j] && label[j] == u8::MAX {
                    label[j] = n as u8;
                    stack[top] = j;
                    top += 1;
                }
            }
        }
        n += 1;
    }
    (label, n)
}

/// The block's statuses as a byte (bit `k`: cell `k` kept).
fn status_byte(kept: &[bool; 8]) -> usize {
    (0..8).fold(0, |b, k| b | (kept[k] as usize) << k)
}

/// For each block ([`status_byte`]), the cells that must go
/// ([`block_drops`]) as a bit mask: 256 blocks, computed once.
fn block_drop_masks() -> &'static [u8; 256] {
    static TABLE: std::sync::OnceLock<[u8; 256]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        std::array::from_fn(|b| {
            let kept: [bool; 8] = std::array::from_fn(|k| b >> k & 1 == 1);
            (0..8)
                .filter(|&k| kept[k] && block_drops(&kept, k))
                .fold(0u8, |m, k| m | 1 << k)
        })
    })
}

/// Whether block cell `own` (kept) must go, by the block rules.
fn block_drops(kept: &[bool; 8], own: usize) -> bool {
    let (label, n) = groups(kept);
    if n > 1 {
        let mut size = vec![0usize; n];
        for k in 0..8 {
            if kept[k] {
                size[label[k] as usize] += 1;
            }
        }
        // Largest group; ties go to the lowest label (the lowest cell).
        let best = (0..n)
            .max_by_key(|&g| (size[g], std::cmp::Reverse(g)))
            .unwrap_or(0);
        return label[own] as usize != best;
    }
    let dropped: [bool; 8] = std::array::from_fn(|k| !kept[k]);
    let (dl, dn) = groups(&dropped);
    if dn > 1 {
        let bridge = (0..8).find(|&k| {
            kept[k] && {
                let mut seen = [false; 8];
                let mut count = 0;
                for a in 0..3 {
                    let j = k ^ (1 << a);
                    if dropped[j] && !seen[dl[j] as usize] {
                        seen[dl[j] as usize] = true;
                        count += 1;
                    }
                }
                count >= 2
            }
        });
        return bridge == Some(own);
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    fn block(cells: &[usize]) -> [bool; 8] {
        std::array::from_fn(|k| cells.contains(&k))
    }

    #[test]
    fn block_rules() {
        // Two cells sharing an edge only (0 and 3 differ in x and y): the
        // higher one goes.
        let b = block(&[0, 3]);
        assert!(!block_drops(&b, 0));
        assert!(block_drops(&b, 3));
        // Corner contact only.
        let b = block(&[1, 6]);
        assert!(!block_drops(&b, 1) && block_drops(&b, 6));
        // A larger group wins.
        let b = block(&[0, 1, 6]);
        assert!(!block_drops(&b, 0) && !block_drops(&b, 1) && block_drops(&b, 6));
        // Manifold configurations keep everything.
        for cells in [
            &[0usize][..],
            &[0, 1],
            &[0, 1, 2, 3],
            &[0, 1, 2, 3, 4, 5, 6, 7],
        ] {
            let b = block(cells);
            assert!(cells.iter().all(|&k| !block_drops(&b, k)), "{cells:?}");
        }
        // Dropped cells touching along an edge only: a kept cell bridging
        // both goes (the lowest).
        let b = block(&[1, 2, 4, 5, 6, 7]);
        let gone: Vec<usize> = (0..8).filter(|&k| b[k] && block_drops(&b, k)).collect();
        assert_eq!(gone, vec![1]);
    }

    #[test]
    fn first_sweep_drops_what_the_lookup_rules_drop() {
        use crate::classify::{classify_leaves, keeps, CutRule, Keep};
        use crate::octree::domain::Domain;
        use crate::octree::octant::Connectivity;
        use crate::parallel::comm::{CommRef, SerialComm};
        use crate::refine::{build_from_surface, SurfaceIndex, NO_LIMIT};
        let mut dropped = 0;
        for (name, level) in [("torus", 5), ("sphere", 6)] {
            let comm: CommRef = std::rc::Rc::new(SerialComm);
            let s = crate::geometry::load_surface(name).unwrap();
            let b = s.bbox();
            // A loose fit: thin walls and corner contacts to drop.
            let domain = Domain::around(b.min, b.max, 0.95).unwrap();
            let index = SurfaceIndex::new(&s, &domain);
            let mut t = build_from_surface(comm, &index, level, NO_LIMIT).unwrap();
            t.balance(Connectivity::Corner).unwrap();
            let class = classify_leaves(t.leaves(), &index);
            for keep in [Keep::Inside, Keep::Outside] {
                let kept = move |c: u8| keeps(keep, CutRule::Center, c);
                let leaves = t.leaves();
                let whole = Merged {
                    before: &[],
                    local: leaves,
                    after: &[],
                };
                let view = View {
                    leaves: whole,
                    class: &class,
                    kept: &kept,
                };
                let want: Vec<usize> = (0..leaves.len())
                    .filter(|&i| kept(class[i]) && view.must_go(i))
                    .collect();
                let got = first_sweep(whole, &class, 0..leaves.len(), kept);
                assert_eq!(got, want, "{name} level {level}");
                dropped += got.len();
            }
        }
        assert!(dropped > 0, "no case drops a leaf");
    }
}
