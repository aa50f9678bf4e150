//! Node extraction by a dual traversal of the octree.
//!
//! The sorted leaves of this rank and its ghosts are linked into a pointer
//! tree (regions owned by nobody visible here are "void"). A recursive walk
//! over cells, then the faces, edges and corners shared by sibling subtrees,
//! reaches every lattice point that is a corner of some octant exactly once,
//! with the 8 leaves around it, in the spirit of the cell/face/edge/vertex
//! procedures of dual contouring. No searching and no sorting of corner keys
//! is needed: each point arrives together with the leaves that share it.
//!
//! At a point, a kept leaf occupying one of the 8 positions has the point as
//! a corner; one occupying 2 positions has it in the interior of an edge, 4
//! positions in the interior of a face. A point that is some kept leaf's
//! corner is a node; it hangs when it also lies inside a kept leaf's face
//! (it then depends on that face's 4 corners) or edge (its 2 ends). With an
//! edge- or corner-balanced octree those corners never hang themselves.

use crate::octant::Octant;

/// Reference to a pointer-tree entry: an internal node index, `LEAF | i`
/// for leaf `i` of the merged array, or [`VOID`].
const LEAF: u32 = 1 << 31;
/// A region with no leaf known here (or outside the domain).
const VOID: u32 = u32::MAX;
/// Marks a corner slot not yet given a node.
pub(crate) const UNSET: u32 = u32::MAX;

/// What the traversal produced for the merged (ghost + local) leaves.
pub(crate) struct DualNodes {
    /// 0 independent, 1 edge-hanging, 2 face-hanging, per node found. Node
    /// coordinates are not stored: every node is a corner of a kept leaf, so
    /// [`DualNodes::scatter_coords`] recovers them when they are needed.
    pub kind: Vec<u8>,
    /// Node at each Morton corner of each merged leaf that is kept
    /// ([`UNSET`] for leaves that are not kept).
    pub corners: Vec<[u32; 8]>,
    /// For each hanging node: (node, coarse leaf, its corners the node
    /// depends on, as a bit mask over the 8 Morton corners).
    pub hanging: Vec<(u32, u32, u8)>,
}

/// Runs the traversal over `leaves` (sorted, disjoint, possibly with gaps),
/// counting only leaves with `kept[i]`.
pub(crate) fn extract_nodes(leaves: &[Octant], kept: &[bool]) -> DualNodes {
    assert!(leaves.len() < LEAF as usize, "too many leaves for one rank");
    let mut tree = Vec::with_capacity(leaves.len() / 6 + 1);
    let root = build(leaves, Octant::ROOT, 0, leaves.len(), &mut tree);
    let mut w = Walker {
        tree: &tree,
        kept,
        out: DualNodes {
            kind: Vec::with_capacity(leaves.len() + leaves.len() / 2),
            corners: vec![[UNSET; 8]; leaves.len()],
            hanging: Vec::with_capacity(leaves.len() / 2),
        },
    };
    w.start(0, [root; 8]);
    // The root's faces, edges and corners against the outside.
    for m in 1u32..8 {
        let mut b = m;
        loop {
            let mut refs = [VOID; 8];
            refs[(!b & m) as usize] = root;
            w.start(m, refs);
            if b == 0 {
                break;
            }
            b = (b - 1) & m;
        }
    }
    w.out.kind.shrink_to_fit();
    w.out.hanging.shrink_to_fit();
    w.out
}

/// Lattice coordinates of corner `c` (Morton order) of the octant with
/// anchor `a` and side `s` (decoded once by the caller, not per corner).
#[inline]
fn corner_coords(a: [u32; 3], s: u32, c: usize) -> [u32; 3] {
    std::array::from_fn(|d| a[d] + if c >> d & 1 == 1 { s } else { 0 })
}

impl DualNodes {
    /// Number of nodes found.
    pub fn num_nodes(&self) -> usize {
        self.kind.len()
    }

    /// Writes the lattice coordinates of node `n` to `out[map[n]]` for every
    /// node with `map[n] != UNSET`. `leaf(i)` is merged leaf `i`.
    pub fn scatter_coords(
        &self,
        leaf: impl Fn(usize) -> Octant,
        kept: &[bool],
        map: &[u32],
        out: &mut [[u32; 3]],
    ) {
        for (i, cs) in self.corners.iter().enumerate() {
            if !kept[i] {
                continue;
            }
            let o = leaf(i);
            let (a, s) = (o.coords(), o.side());
            for (c, &n) in cs.iter().enumerate() {
                let m = map[n as usize];
                if m != UNSET {
                    out[m as usize] = corner_coords(a, s, c);
                }
            }
        }
    }

    /// Lattice coordinates of hanging node entry `(_, q, mask)`: the mean
    /// of the corners of leaf `q` it depends on.
    pub fn hanging_coords(q: Octant, mask: u8) -> [u32; 3] {
        let mut sum = [0u32; 3];
        let k = mask.count_ones();
        let (a, s) = (q.coords(), q.side());
        for c in 0..8 {
            if mask >> c & 1 == 1 {
                let x = corner_coords(a, s, c);
                for d in 0..3 {
                    sum[d] += x[d];
                }
            }
        }
        sum.map(|v| v / k)
    }
}

/// Links `leaves[lo..hi]` (the leaves inside `o`) into the pointer tree.
fn build(leaves: &[Octant], o: Octant, lo: usize, hi: usize, tree: &mut Vec<[u32; 8]>) -> u32 {
    if lo == hi {
        return VOID;
    }
    if leaves[lo].level() <= o.level() {
        // The first leaf overlapping `o` is at most its size: it contains it.
        return LEAF | lo as u32;
    }
    let idx = tree.len();
    tree.push([VOID; 8]);
    let mut a = lo;
    for c in 0..8u32 {
        let child = o.child(c);
        let end = child.cell_end();
        let b = if hi - a <= 16 {
            let mut b = a;
            while b < hi && leaves[b].cell_begin() < end {
                b += 1;
            }
            b
        } else {
            a + leaves[a..hi].partition_point(|l| l.cell_begin() < end)
        };
        let r = build(leaves, child, a, b, tree);
        tree[idx][c as usize] = r;
        a = b;
    }
    idx as u32
}

/// Grows a full vector by a quarter instead of doubling it: these arrays
/// hold one entry per node, and doubling would leave up to half unused.
#[inline]
fn grow<T>(v: &mut Vec<T>) {
    if v.len() == v.capacity() {
        v.reserve_exact(v.len() / 4 + 1024);
    }
}

struct Walker<'a> {
    tree: &'a [[u32; 8]],
    kept: &'a [bool],
    out: DualNodes,
}

/// Calls `f` for every subset of `mask` (including 0 and `mask`).
fn subsets(mask: u32, mut f: impl FnMut(u32)) {
    let mut s = mask;
    loop {
        f(s);
        if s == 0 {
            break;
        }
        s = (s - 1) & mask;
    }
}

/// One sub-cell of a sub-cell of kind `m` (see [`Walker::cell`]).
#[derive(Clone, Copy, Default)]
struct Sub {
    /// Its kind.
    m: u8,
    /// Number of octants around it.
    n: u8,
    /// For each: (its side `p2`, parent octant side `p`, child index).
    pos: [(u8, u8, u8); 8],
}

/// For each kind `m < 7`, the sub-cells it splits into.
fn split_table() -> &'static [Vec<Sub>; 7] {
    static TABLE: std::sync::OnceLock<[Vec<Sub>; 7]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        std::array::from_fn(|m| {
            let m = m as u32;
            let free = 7 & !m;
            let mut subs = Vec::new();
            subsets(free, |s| {
                let m2 = m | s;
                subsets(free & !s, |t| {
                    let mut sub = Sub {
                        m: m2 as u8,
                        ..Sub::default()
                    };
                    subsets(m2, |p2| {
                        // Across `m` take the child facing the sub-cell;
                        // along `s` the child on side `p2`; along the rest
                        // the half `t`.
                        let c = (!p2 & m) | (p2 & s) | t;
                        sub.pos[sub.n as usize] = (p2 as u8, (p2 & m) as u8, c as u8);
                        sub.n += 1;
                    });
                    subs.push(sub);
                });
            });
            subs
        })
    })
}

impl Walker<'_> {
    #[inline]
    fn child(&self, r: u32, c: u32) -> u32 {
        if r & LEAF != 0 {
            r
        } else {
            self.tree[r as usize][c as usize]
        }
    }

    /// Visits the sub-cell shared by the octants `refs` around it, at least
    /// one of which is internal: `m` has a bit per axis across which the
    /// octants sit (0: a cell, 1 bit: a face, 2: an edge, 3: a point),
    /// `refs[p]` for `p` a subset of `m` is the octant on side `p`.
    fn cell(&mut self, m: u32, refs: [u32; 8]) {
        for sub in &split_table()[m as usize] {
            let mut nr = [VOID; 8];
            let mut internal = false;
            for &(p2, p, c) in &sub.pos[..sub.n as usize] {
                let r = self.child(refs[p as usize], c as u32);
                internal |= r & LEAF == 0;
                nr[p2 as usize] = r;
            }
            if sub.m == 7 {
                self.point(nr);
            } else if internal {
                self.cell(sub.m as u32, nr);
            }
        }
    }

    /// Starts a walk at a sub-cell of kind `m` (see [`Walker::cell`]).
    fn start(&mut self, m: u32, refs: [u32; 8]) {
        if m == 7 {
            self.point(refs);
        } else if refs.iter().any(|&r| r & LEAF == 0) {
            self.cell(m, refs);
        }
    }

    /// A lattice point with the octants on its 8 sides: descend to the
    /// leaves touching it, then record it.
    fn point(&mut self, mut refs: [u32; 8]) {
        while refs.iter().any(|&r| r & LEAF == 0) {
            for (p, r) in refs.iter_mut().enumerate() {
                *r = self.child(*r, !(p as u32) & 7);
            }
        }
        let kept = |r: u32| r != VOID && self.kept[(r & !LEAF) as usize];
        let mut count = [0u8; 8];
        let mut corner = false;
        for p in 0..8 {
            if kept(refs[p]) {
                count[p] = refs.iter().filter(|&&q| q == refs[p]).count() as u8;
                corner |= count[p] == 1;
            }
        }
        if !corner {
            return;
        }
        let id = self.out.kind.len() as u32;
        let mut kind = 0u8;
        if let Some(p) = (0..8).find(|&p| count[p] == 4) {
            // Face interior of the coarse leaf: its 4 positions span two
            // axes; the third, across which it does not extend, is the
            // face normal.
            let q = refs[p];
            let n = (0..3)
                .find(|&d| refs[p ^ (1 << d)] != q)
                .expect("a face leaf lies on one side of the point");
            let side = (p >> n) & 1;
            let mut mask = 0u8;
            for c in 0..8 {
                if (c >> n) & 1 != side {
                    mask |= 1 << c;
                }
            }
            kind = 2;
            grow(&mut self.out.hanging);
            self.out.hanging.push((id, q & !LEAF, mask));
        } else if let Some(p) = (0..8).find(|&p| count[p] == 2) {
            let q = refs[p];
            let e = (0..3)
                .find(|&d| refs[p ^ (1 << d)] == q)
                .expect("an edge leaf spans the point along one axis");
            // The edge of the coarse leaf through the point: opposite side
            // of the point on the two other axes, both ends along `e`.
            let base = !p & 7 & !(1 << e);
            let mask = (1u8 << base) | (1u8 << (base | (1 << e)));
            kind = 1;
            grow(&mut self.out.hanging);
            self.out.hanging.push((id, q & !LEAF, mask));
        }
        grow(&mut self.out.kind);
        self.out.kind.push(kind);
        for p in 0..8 {
            if count[p] == 1 {
                let leaf = (refs[p] & !LEAF) as usize;
                self.out.corners[leaf][!p & 7] = id;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn uniform(level: u8) -> Vec<Octant> {
        let n = 1u64 << (3 * level as u32);
        let shift = 3 * (crate::octant::LATTICE_BITS - level as u32);
        (0..n)
            .map(|i| Octant::from_parts(i << shift, level))
            .collect()
    }

    fn coords(d: &DualNodes, leaves: &[Octant], kept: &[bool]) -> Vec<[u32; 3]> {
        let map: Vec<u32> = (0..d.num_nodes() as u32).collect();
        let mut out = vec![[u32::MAX; 3]; d.num_nodes()];
        d.scatter_coords(|i| leaves[i], kept, &map, &mut out);
        assert!(
            out.iter().all(|x| x[0] != u32::MAX),
            "a node is no kept leaf's corner"
        );
        out
    }

    #[test]
    fn uniform_grid_has_every_lattice_point_once() {
        let leaves = uniform(2);
        let kept = vec![true; leaves.len()];
        let d = extract_nodes(&leaves, &kept);
        let coords = coords(&d, &leaves, &kept);
        assert_eq!(coords.len(), 125);
        let mut c = coords.clone();
        c.sort_unstable();
        c.dedup();
        assert_eq!(c.len(), 125);
        assert!(d.kind.iter().all(|&k| k == 0));
        for (l, cs) in leaves.iter().zip(&d.corners) {
            let a = l.coords();
            let s = l.side();
            for (j, &n) in cs.iter().enumerate() {
                let want = [
                    a[0] + s * (j as u32 & 1),
                    a[1] + s * (j as u32 >> 1 & 1),
                    a[2] + s * (j as u32 >> 2 & 1),
                ];
                assert_eq!(coords[n as usize], want);
            }
        }
    }

    #[test]
    fn one_refined_octant_hangs_on_its_neighbours() {
        // Root split once, child 0 split again: the 19 new points on child
        // 0's three inner faces hang (3 face centres, 6 edge midpoints on
        // those faces... counted below by brute force).
        let mut leaves: Vec<Octant> = Octant::ROOT.child(0).children().to_vec();
        leaves.extend((1..8).map(|c| Octant::ROOT.child(c)));
        let kept = vec![true; leaves.len()];
        let d = extract_nodes(&leaves, &kept);
        let coords = coords(&d, &leaves, &kept);
        // 27 coarse points + 27 fine points of child 0, 8 of them shared.
        assert_eq!(coords.len(), 27 + 27 - 8);
        let face = d.kind.iter().filter(|&&k| k == 2).count();
        let edge = d.kind.iter().filter(|&&k| k == 1).count();
        // Child 0's faces towards its siblings: 3 centres; its edges inside
        // the root: 3 whole edges, and halves of 6 face-boundary edges.
        assert_eq!(face, 3);
        assert_eq!(edge, 3 + 6);
        for &(n, q, mask) in &d.hanging {
            let corners: Vec<[u32; 3]> = (0..8)
                .filter(|c| mask >> c & 1 == 1)
                .map(|c| coords[d.corners[q as usize][c] as usize])
                .collect();
            let k = d.kind[n as usize];
            assert_eq!(corners.len(), if k == 2 { 4 } else { 2 });
            // The hanging node is the average of what it depends on.
            for ax in 0..3 {
                let sum: u32 = corners.iter().map(|c| c[ax]).sum();
                assert_eq!(sum, coords[n as usize][ax] * corners.len() as u32);
            }
            assert_eq!(
                DualNodes::hanging_coords(leaves[q as usize], mask),
                coords[n as usize]
            );
        }
    }
}
