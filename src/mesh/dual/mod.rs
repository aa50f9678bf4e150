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

use crate::error::{Error, ErrorKind, Result};
use crate::octree::octant::{Octant, LATTICE_BITS};

pub(crate) use crate::geometry::cells::corner_coords;
pub(crate) use sets::{Bits, Merged, Ranks};

mod sets;

/// Reference to a pointer-tree entry: an internal node index (flagged
/// [`BOTTOM`] when it has no internal child), `LEAF | i` for leaf `i` of
/// the merged array, `FAMILY | i` for an internal node whose children are
/// the eight leaves from `i` on, or [`VOID`].
const LEAF: u32 = 1 << 31;
/// See [`LEAF`]. Most internal nodes of a balanced octree are parents of
/// eight leaves; naming them by their first leaf instead of an entry of 8
/// words takes the pointer tree from about 4.6 to about 1 byte per leaf.
const FAMILY: u32 = 1 << 30;
/// See [`LEAF`]: `BOTTOM | i` (`i` below 2^29) for internal node `i` whose
/// children are all leaves or [`VOID`], a family with gaps. Along a surface
/// that cuts the kept region most nodes are such: as inside a family, the
/// centre is the only point within one that can be a leaf's corner.
const BOTTOM: u32 = 1 << 29;
/// A region with no leaf known here (or outside the domain).
const VOID: u32 = u32::MAX;
/// Marks a corner slot not yet given a node.
pub(crate) const UNSET: u32 = u32::MAX;
/// Corner-table entries carry the node's kind in their two top bits: none
/// for an independent node, [`FACE`] or [`EDGE`] for the index of a
/// face- or edge-hanging node in its own list.
pub(crate) const TAG: u32 = 0xC000_0000;
/// Tag of a face-hanging node.
pub(crate) const FACE: u32 = 0x8000_0000;
/// Tag of an edge-hanging node.
pub(crate) const EDGE: u32 = 0x4000_0000;

/// Node flag: a corner of a kept local leaf.
pub(crate) const CORNER: u8 = 1;
/// Node flag: a dependency of a used hanging node on a ghost leaf (those
/// on a local leaf are corners of it).
pub(crate) const DEP: u8 = 2;
/// Node flag: another rank may use it (a kept ghost leaf around it, or a
/// dependency of such a hanging node); only these need the directory.
pub(crate) const BOUNDARY: u8 = 4;
/// Used here: a corner of a local element or a dependency of one's hanging
/// corner.
pub(crate) const USED: u8 = CORNER | DEP;

/// The corners of a leaf's face by its shape `n | side << 2` (normal axis,
/// side): those whose bit `n` is not `side`.
const FACE_MASKS: [u8; 32] = {
    let mut t = [0u8; 32];
    let mut shape = 0;
    while shape < 8 {
        let (n, side) = (shape & 3, shape >> 2 & 1);
        let mut c = 0;
        while c < 8 && n < 3 {
            if (c >> n) & 1 != side {
                t[shape] |= 1 << c;
            }
            c += 1;
        }
        shape += 1;
    }
    t
};

/// The two ends of a leaf's edge by its shape `e | base << 2` (axis, the
/// Morton corner at its low end).
const EDGE_MASKS: [u8; 32] = {
    let mut t = [0u8; 32];
    let mut shape = 0;
    while shape < 32 {
        let (e, base) = (shape & 3, shape >> 2);
        if e < 3 {
            t[shape] = (1 << base) | (1 << (base | 1 << e));
        }
        shape += 1;
    }
    t
};

/// The hanging nodes of one kind (face or edge) the traversal found, 5
/// bytes each: the coarse leaf the node hangs on, and a code byte with the
/// node's flags in its top 3 bits and, below, which face (normal axis `n`
/// and side: `n | side << 2`) or edge (axis `e` and the Morton corner
/// `base` at its low end: `e | base << 2`) of the leaf it lies on.
pub(crate) struct Entries {
    pub leaf: Vec<u32>,
    pub code: Vec<u8>,
    face: bool,
}

impl Entries {
    fn new(face: bool, capacity: usize) -> Entries {
        Entries {
            leaf: Vec::with_capacity(capacity),
            code: Vec::with_capacity(capacity),
            face,
        }
    }

    /// Number of entries.
    pub fn len(&self) -> usize {
        self.leaf.len()
    }

    fn push(&mut self, q: u32, shape: u8, flags: u8) {
        debug_assert!(shape < 32 && flags < 8);
        grow(&mut self.leaf);
        grow(&mut self.code);
        self.leaf.push(q);
        self.code.push(shape | flags << 5);
    }

    /// Entry `k`: (coarse leaf, mask of the leaf's Morton corners it
    /// depends on, flags).
    #[inline]
    pub fn get(&self, k: usize) -> (u32, u8, u8) {
        let c = self.code[k];
        (self.leaf[k], self.mask_of(c), c >> 5)
    }

    /// Every entry, as [`Entries::get`].
    pub fn iter(&self) -> impl Iterator<Item = (u32, u8, u8)> + '_ {
        (0..self.len()).map(|k| self.get(k))
    }

    /// The dependency mask of a code byte.
    #[inline]
    pub fn mask_of(&self, code: u8) -> u8 {
        let table = if self.face { &FACE_MASKS } else { &EDGE_MASKS };
        table[(code & 31) as usize]
    }

    /// Gives back unused capacity.
    fn shrink_to_fit(&mut self) {
        self.leaf.shrink_to_fit();
        self.code.shrink_to_fit();
    }
}

/// What the traversal produced for the merged (ghost + local) leaves.
pub(crate) struct DualNodes {
    /// Flags ([`CORNER`], [`DEP`], [`BOUNDARY`]) per independent node, in
    /// the order the traversal found them. Coordinates are not stored
    /// (every node is a corner of a kept leaf), except for the few in
    /// `boundary_points`.
    pub flags: Vec<u8>,
    /// Node at each Morton corner of each merged leaf: an independent
    /// node's index, or [`FACE`] / [`EDGE`] with a hanging node's index.
    pub corners: Vec<[u32; 8]>,
    /// Face-hanging nodes (see [`Entries`]).
    pub face: Entries,
    /// Edge-hanging nodes.
    pub edge: Entries,
    /// Independent nodes with a kept ghost leaf around them, and their
    /// lattice points, in node order (few: partition boundaries only).
    pub boundary_points: Vec<(u32, [u32; 3])>,
    /// Face- and edge-hanging nodes whose directory cell (the finest cell
    /// above the point along every axis, see [`crate::mesh::numbering`])
    /// lies in a local leaf: this rank counts them.
    pub directory_here: [u64; 2],
    /// Face- and edge-hanging nodes (indices into `face`, `edge`) with no
    /// leaf known above them (a gap, or the domain's upper boundary): their
    /// directory is looked up.
    pub directory_unknown: [Vec<u32>; 2],
}

/// Runs the traversal over `leaves` (sorted, disjoint, possibly with gaps):
/// the kept leaves only, the elements in `leaves.local_range()` and the
/// halo elements around them. A dropped leaf would change no node (a point
/// is a node by the kept leaves around it alone), so leaving the dropped
/// ones out as gaps takes their part of the walk away.
///
/// Returns the tree too: the face walk of the same mesh goes over it again.
pub(crate) fn extract_nodes(leaves: Merged) -> Result<(DualNodes, DualTree)> {
    let n = leaves.len();
    if n >= LEAF as usize {
        return Err(Error::new(
            ErrorKind::Limit,
            format!("{n} leaves and ghosts on one rank: at most 2^31 - 1 can be meshed"),
        ));
    }
    let local = leaves.local_range();
    let mut overflow = false;
    let mut out = DualNodes {
        flags: Vec::with_capacity(n),
        corners: vec![[UNSET; 8]; n],
        face: Entries::new(true, n / 4),
        edge: Entries::new(false, n / 2),
        boundary_points: Vec::new(),
        directory_here: [0; 2],
        directory_unknown: [Vec::new(), Vec::new()],
    };
    let tree = DualTree::new(&leaves);
    walk_points(&tree, |refs| {
        record_point(&leaves, &local, &mut overflow, &mut out, refs)
    });
    if overflow {
        return Err(Error::new(
            ErrorKind::Limit,
            "more than 2^30 - 1 nodes of one kind on one rank",
        ));
    }
    out.flags.shrink_to_fit();
    out.face.shrink_to_fit();
    out.edge.shrink_to_fit();
    out.propagate(&local)?;
    Ok((out, tree))
}

/// The dependencies of a hanging node on the corners `mask` of leaf `o`,
/// whose row of the corner table is `row`: (node, its lattice point), in
/// Morton corner order. The leaf's anchor is decoded once.
pub(crate) fn entry_deps(
    o: Octant,
    row: &[u32; 8],
    mask: u8,
) -> impl Iterator<Item = (u32, [u32; 3])> + '_ {
    let (a, s) = (o.coords(), o.side());
    (row.iter().enumerate())
        .filter(move |&(c, _)| mask >> c & 1 == 1)
        .map(move |(c, &n)| (n, corner_coords(a, s, c)))
}

impl DualNodes {
    /// Marks the dependencies of hanging nodes: used when the hanging node
    /// is, boundary when it is. The corners of a local coarse leaf are
    /// corners of an element already, so only a ghost's, or a boundary
    /// node's, are looked at.
    fn propagate(&mut self, local: &std::ops::Range<usize>) -> Result<()> {
        let corners = &self.corners;
        let flags = &mut self.flags;
        for (q, mask, f) in self.face.iter().chain(self.edge.iter()) {
            let ghost = !local.contains(&(q as usize));
            let add = (if f & USED != 0 && ghost { DEP } else { 0 }) | (f & BOUNDARY);
            if add == 0 {
                continue;
            }
            for (c, &dep) in corners[q as usize].iter().enumerate() {
                if mask >> c & 1 == 1 {
                    if dep & TAG != 0 {
                        return Err(Error::new(
                            ErrorKind::Internal,
                            "a hanging node depends on a node that is not independent",
                        ));
                    }
                    flags[dep as usize] |= add;
                }
            }
        }
        Ok(())
    }

    /// Lattice coordinates of a hanging node depending on the corners
    /// `mask` of leaf `q`: their mean.
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

/// Links the sorted leaves into the pointer tree in one pass, in the order
/// a recursive descent would create its entries (pre-order): `path[l]` is
/// the open internal node at level `l` on the way to the last leaf. A leaf
/// closes the nodes that are not its ancestors and opens the missing ones.
///
/// ```text
///   level 0        [ root ]
///                 /   |    \
///   level 1  [n1]   LEAF    ...      path = [root, n1, n2]
///            /  \
///   level 2 [n2] VOID                next leaf: keeps the ancestors it
///           /|\                      shares with the last one, closes
///          leaves                    the rest (a family collapses)
/// ```
fn build(leaves: &Merged) -> (Vec<[u32; 8]>, u32) {
    let n = leaves.len();
    let mut nodes: Vec<[u32; 8]> = Vec::with_capacity(n / 24 + 1);
    let mut root = VOID;
    let mut path = [0u32; crate::octree::octant::MAX_LEVEL as usize + 1];
    let mut open = 0usize;
    let mut last = 0u64;
    // Child index of the octant with Morton code `m` within its parent at
    // level `l - 1`.
    let digit = |m: u64, l: usize| (m >> (3 * (LATTICE_BITS - l as u32)) & 7) as usize;
    // Closes the open node at level `l` on the way to the leaf with Morton
    // code `m`: eight consecutive leaves become a family, other children
    // that are all leaves or gaps make its reference [`BOTTOM`].
    let close = |nodes: &mut Vec<[u32; 8]>, root: &mut u32, path: &[u32], l: usize, m: u64| {
        let idx = path[l] as usize;
        let e = nodes[idx];
        let first = e[0] & !LEAF;
        let family = e[0] != VOID
            && e[0] & LEAF != 0
            && first < FAMILY
            && (1..8).all(|c| e[c] == e[0] + c as u32);
        let r = if family {
            // No child is internal: nothing was pushed after it.
            debug_assert_eq!(idx + 1, nodes.len());
            nodes.pop();
            FAMILY | first
        } else if idx < BOTTOM as usize && e.iter().all(|&c| c & LEAF != 0) {
            BOTTOM | idx as u32
        } else {
            return;
        };
        if l == 0 {
            *root = r;
        } else {
            nodes[path[l - 1] as usize][digit(m, l)] = r;
        }
    };
    let mut i = 0u32;
    for part in leaves.parts() {
        for o in part {
            let (m, level) = (o.morton(), o.level() as usize);
            // Leading base-8 digits shared with the last leaf: the open
            // nodes up to that level are also this leaf's ancestors.
            let shared = ((m ^ last).leading_zeros() - (64 - 3 * LATTICE_BITS)) / 3;
            let keep = open.min(shared as usize + 1).min(level);
            for l in (keep..open).rev() {
                close(&mut nodes, &mut root, &path, l, last);
            }
            for l in keep..level {
                let idx = nodes.len() as u32;
                nodes.push([VOID; 8]);
                if l == 0 {
                    root = idx;
                } else {
                    nodes[path[l - 1] as usize][digit(m, l)] = idx;
                }
                path[l] = idx;
            }
            if level == 0 {
                root = LEAF | i;
            } else {
                nodes[path[level - 1] as usize][digit(m, level)] = LEAF | i;
            }
            open = level;
            last = m;
            i += 1;
        }
    }
    for l in (0..open).rev() {
        close(&mut nodes, &mut root, &path, l, last);
    }
    debug_assert_eq!(i as usize, n);
    (nodes, root)
}

/// Grows a full vector by a quarter instead of doubling it: these arrays
/// hold one entry per node, and doubling would leave up to half unused.
#[inline]
fn grow<T>(v: &mut Vec<T>) {
    if v.len() == v.capacity() {
        v.reserve_exact(v.len() / 4 + 1024);
    }
}

/// The pointer tree over a merged run of leaves, built once and walked by
/// [`walk_points`] and [`walk_faces`] (about one byte per leaf). It stays
/// valid while the leaves it was built on do not change.
pub(crate) struct DualTree {
    nodes: Vec<[u32; 8]>,
    root: u32,
}

impl std::fmt::Debug for DualTree {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "DualTree({} entries)", self.nodes.len())
    }
}

impl DualTree {
    /// Links `leaves` (sorted, disjoint, possibly with gaps).
    pub(crate) fn new(leaves: &Merged) -> DualTree {
        let (nodes, root) = build(leaves);
        DualTree { nodes, root }
    }
}

/// Visits every lattice point that is a corner of some leaf of `tree`'s
/// leaves exactly once, calling `visit` with the 8 leaves around it:
/// `refs[p]` is `LEAF | i` for merged leaf `i` holding the finest cell on
/// side `p` of the point (bit `a` of `p` set: the high side along axis
/// `a`), or [`VOID`] (see [`leaf_at`]).
pub(crate) fn walk_points(tree: &DualTree, visit: impl FnMut(&[u32; 8])) {
    let root = tree.root;
    let mut w = Walker {
        tree: &tree.nodes,
        visit,
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
}

/// Visits every pair of `tree`'s leaves that share a face (the whole face
/// of the smaller, or either when they are the same size) exactly once,
/// calling `visit(axis, low, high)` with the leaf on the low and the high
/// side along `axis` (merged indices). Leaves facing a gap (no leaf, or
/// outside the root) are not visited. The walk of [`walk_points`] without
/// its edges and points; a parent of eight leaves is reported whole
/// ([`FaceVisitor::family`]).
pub(crate) fn walk_faces(tree: &DualTree, visit: &mut impl FaceVisitor) {
    let mut w = FaceWalker {
        tree: &tree.nodes,
        visit,
    };
    if tree.root & LEAF == 0 {
        w.cell::<0>([tree.root; 8]);
    }
}

/// The twelve faces between the eight children of one parent, as `(axis,
/// child on the low side, child on the high side)`: along each axis, the
/// four children with that axis' bit clear face their siblings with it
/// set.
pub(crate) const FAMILY_FACES: [(usize, usize, usize); 12] = {
    let mut f = [(0, 0, 0); 12];
    let mut k = 0;
    let mut axis = 0;
    while axis < 3 {
        let mut c = 0;
        while c < 8 {
            if c >> axis & 1 == 0 {
                f[k] = (axis, c, c | 1 << axis);
                k += 1;
            }
            c += 1;
        }
        axis += 1;
    }
    f
};

/// What [`walk_faces`] reports.
pub(crate) trait FaceVisitor {
    /// Leaves `low` and `high` (merged indices) share a face normal to
    /// `axis`, `low` on its low side.
    fn pair(&mut self, axis: usize, low: usize, high: usize);

    /// Leaves `b..b + 8` are the eight children of one parent, and share
    /// the twelve faces between them ([`FAMILY_FACES`]). Half the faces of
    /// a balanced octree are of this kind: a visitor can take them in one
    /// step and return `true`; on `false` (the default) the walk reports
    /// them as twelve [`FaceVisitor::pair`]s.
    #[inline]
    fn family(&mut self, _b: usize) -> bool {
        false
    }
}

/// See [`walk_faces`].
struct FaceWalker<'a, 'v, V> {
    tree: &'a [[u32; 8]],
    visit: &'v mut V,
}

impl<V: FaceVisitor> FaceWalker<'_, '_, V> {
    #[inline]
    fn child(&self, r: u32, c: u32) -> u32 {
        if r & LEAF != 0 {
            r
        } else if r & FAMILY != 0 {
            LEAF | ((r & !FAMILY) + c)
        } else {
            self.tree[(r & !BOTTOM) as usize][c as usize]
        }
    }

    /// [`Walker::cell`] for cells and faces only: a face whose two sides
    /// are leaves is visited.
    fn cell<const M: usize>(&mut self, refs: [u32; 8]) {
        if M == 0 && refs[0] & FAMILY != 0 {
            let b = (refs[0] & !FAMILY) as usize;
            if !self.visit.family(b) {
                for (axis, low, high) in FAMILY_FACES {
                    self.visit.pair(axis, b + low, b + high);
                }
            }
            return;
        }
        if M == 0 && refs[0] & (LEAF | FAMILY | BOTTOM) == BOTTOM {
            // Leaves and gaps only below: the faces between the leaves.
            let e = &self.tree[(refs[0] & !BOTTOM) as usize];
            for (axis, low, high) in FAMILY_FACES {
                if e[low] != VOID && e[high] != VOID {
                    let (low, high) = ((e[low] & !LEAF) as usize, (e[high] & !LEAF) as usize);
                    self.visit.pair(axis, low, high);
                }
            }
            return;
        }
        macro_rules! subs {
            ($($k:literal)*) => { $( self.sub::<M, $k>(&refs); )* };
        }
        subs!(0 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 18 19 20 21 22 23 24 25 26);
    }

    /// [`Walker::sub`] for cells and faces only.
    #[inline(always)]
    fn sub<const M: usize, const K: usize>(&mut self, refs: &[u32; 8]) {
        if K >= SPLIT.1[M] as usize || SPLIT.0[M][K].m.count_ones() > 1 {
            return;
        }
        // As in `Walker::sub`; the face walk is a separate type so that
        // the node walk's code stays as it was measured.
        let sub = &SPLIT.0[M][K];
        let mut nr = [VOID; 8];
        let mut internal = false;
        for &(p2, p, c) in &sub.pos[..sub.n as usize] {
            let r = self.child(refs[p as usize], c as u32);
            internal |= r & LEAF == 0;
            nr[p2 as usize] = r;
        }
        if internal {
            match sub.m {
                0 => self.cell::<0>(nr),
                1 => self.cell::<1>(nr),
                2 => self.cell::<2>(nr),
                _ => self.cell::<4>(nr),
            }
        } else if sub.m != 0 {
            let (low, high) = (nr[0], nr[sub.m as usize]);
            if low != VOID && high != VOID {
                let axis = sub.m.trailing_zeros() as usize;
                let (low, high) = ((low & !LEAF) as usize, (high & !LEAF) as usize);
                self.visit.pair(axis, low, high);
            }
        }
    }
}

/// The merged leaf a [`walk_points`] reference names, if any.
#[inline]
pub(crate) fn leaf_at(r: u32) -> Option<usize> {
    (r != VOID).then_some((r & !LEAF) as usize)
}

struct Walker<'a, F> {
    tree: &'a [[u32; 8]],
    visit: F,
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

/// For each kind `m < 7`, the sub-cells it splits into: `SPLIT.0[m]`, the
/// first `SPLIT.1[m]` of them. Across `m` each takes the child facing it;
/// along the axes `s` it spans, the child on its side `p2`; along the rest
/// the half `t`. The centre point (all free axes spanned) comes first.
const SPLIT: ([[Sub; 27]; 7], [u8; 7]) = {
    const NONE: Sub = Sub {
        m: 0,
        n: 0,
        pos: [(0, 0, 0); 8],
    };
    let mut table = [[NONE; 27]; 7];
    let mut lens = [0u8; 7];
    let mut m = 0usize;
    while m < 7 {
        let mu = m as u32;
        let free = 7 & !mu;
        // Subsets of a mask run from the whole mask down to 0.
        let mut s = free;
        loop {
            let m2 = mu | s;
            let rest = free & !s;
            let mut t = rest;
            loop {
                let mut sub = Sub {
                    m: m2 as u8,
                    ..NONE
                };
                let mut p2 = m2;
                loop {
                    let c = (!p2 & mu) | (p2 & s) | t;
                    sub.pos[sub.n as usize] = (p2 as u8, (p2 & mu) as u8, c as u8);
                    sub.n += 1;
                    if p2 == 0 {
                        break;
                    }
                    p2 = (p2 - 1) & m2;
                }
                table[m][lens[m] as usize] = sub;
                lens[m] += 1;
                if t == 0 {
                    break;
                }
                t = (t - 1) & rest;
            }
            if s == 0 {
                break;
            }
            s = (s - 1) & free;
        }
        m += 1;
    }
    (table, lens)
};

impl<F: FnMut(&[u32; 8])> Walker<'_, F> {
    #[inline]
    fn child(&self, r: u32, c: u32) -> u32 {
        if r & LEAF != 0 {
            r
        } else if r & FAMILY != 0 {
            LEAF | ((r & !FAMILY) + c)
        } else {
            self.tree[(r & !BOTTOM) as usize][c as usize]
        }
    }

    /// Visits the sub-cell shared by the octants `refs` around it, at least
    /// one of which is internal: `M` has a bit per axis across which the
    /// octants sit (0: a cell, 1 bit: a face, 2: an edge, 3: a point),
    /// `refs[p]` for `p` a subset of `M` is the octant on side `p`.
    fn cell<const M: usize>(&mut self, refs: [u32; 8]) {
        // Around the lowest internal nodes (families of leaves, with or
        // without gaps) every sub-cell but the centre point has leaves or
        // gaps alone on its sides: the centre point, the first sub-cell, is
        // all there is to visit. Along a surface this spares about three
        // quarters of the full visits (Armadillo level 11, kept inside).
        if refs.iter().all(|&r| r & (LEAF | FAMILY | BOTTOM) != 0) {
            self.sub::<M, 0>(&refs);
            return;
        }
        // Written out sub-cell by sub-cell: every loop below has a length
        // known at compile time.
        macro_rules! subs {
            ($($k:literal)*) => { $( self.sub::<M, $k>(&refs); )* };
        }
        subs!(0 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 18 19 20 21 22 23 24 25 26);
    }

    /// Sub-cell `K` of a sub-cell of kind `M` (see [`Walker::cell`]).
    #[inline(always)]
    fn sub<const M: usize, const K: usize>(&mut self, refs: &[u32; 8]) {
        if K >= SPLIT.1[M] as usize {
            return;
        }
        let sub = &SPLIT.0[M][K];
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
            self.descend(sub.m, nr);
        }
    }

    /// [`Walker::cell`] for a kind known at run time: one copy of the walk
    /// per kind, so that each copy's loops have fixed lengths.
    #[inline(always)]
    fn descend(&mut self, m: u8, refs: [u32; 8]) {
        match m {
            0 => self.cell::<0>(refs),
            1 => self.cell::<1>(refs),
            2 => self.cell::<2>(refs),
            3 => self.cell::<3>(refs),
            4 => self.cell::<4>(refs),
            5 => self.cell::<5>(refs),
            _ => self.cell::<6>(refs),
        }
    }

    /// Starts a walk at a sub-cell of kind `m` (see [`Walker::cell`]).
    fn start(&mut self, m: u32, refs: [u32; 8]) {
        if m == 7 {
            self.point(refs);
        } else if refs.iter().any(|&r| r & LEAF == 0) {
            self.descend(m as u8, refs);
        }
    }

    /// A lattice point with the octants on its 8 sides: descend to the
    /// leaves touching it, then visit it.
    fn point(&mut self, mut refs: [u32; 8]) {
        while refs.iter().any(|&r| r & LEAF == 0) {
            for (p, r) in refs.iter_mut().enumerate() {
                *r = self.child(*r, !(p as u32) & 7);
            }
        }
        (self.visit)(&refs);
    }
}

/// The sides' bit masks at a point (see [`record_point`]): `same[d]`, the
/// sides whose leaf is also on the side across axis `d`; the sides with a
/// leaf; the sides whose leaf is not local (or none).
#[inline]
pub(crate) fn side_masks(refs: &[u32; 8], local: &std::ops::Range<usize>) -> ([u8; 3], u8, u8) {
    #[cfg(target_arch = "x86_64")]
    {
        side_masks_sse2(refs, local)
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        side_masks_scalar(refs, local)
    }
}

/// [`side_masks`], a side at a time (other processors; the reference of
/// the SSE2 version's test).
#[cfg_attr(all(target_arch = "x86_64", not(test)), allow(dead_code))]
fn side_masks_scalar(refs: &[u32; 8], local: &std::ops::Range<usize>) -> ([u8; 3], u8, u8) {
    let local = |r: u32| local.contains(&((r & !LEAF) as usize));
    let (mut same, mut valid, mut remote) = ([0u8; 3], 0u8, 0u8);
    for p in 0..8 {
        let r = refs[p];
        valid |= ((r != VOID) as u8) << p;
        remote |= (!local(r) as u8) << p;
        for (d, s) in same.iter_mut().enumerate() {
            *s |= ((refs[p ^ (1 << d)] == r) as u8) << p;
        }
    }
    (same, valid, remote)
}

/// [`side_masks`] with SSE2 (every x86-64 processor): the sides in two
/// registers of four, compared with themselves shuffled. A fifth less time
/// for the walk with its records (Armadillo level 10, in-process minimum
/// of four against the scalar version).
#[cfg(target_arch = "x86_64")]
#[inline]
fn side_masks_sse2(refs: &[u32; 8], local: &std::ops::Range<usize>) -> ([u8; 3], u8, u8) {
    use std::arch::x86_64::*;
    // SAFETY: SSE2 is part of x86-64; the loads read the 32 bytes of `refs`.
    unsafe {
        let lo = _mm_loadu_si128(refs.as_ptr().cast());
        let hi = _mm_loadu_si128(refs.as_ptr().add(4).cast());
        let bits = |v: __m128i| _mm_movemask_ps(_mm_castsi128_ps(v)) as u8;
        let pair = |a: __m128i, b: __m128i| bits(a) | bits(b) << 4;
        // Across x: sides 0<->1, 2<->3; across y: 0<->2, 1<->3.
        let x = pair(
            _mm_cmpeq_epi32(lo, _mm_shuffle_epi32::<0b10_11_00_01>(lo)),
            _mm_cmpeq_epi32(hi, _mm_shuffle_epi32::<0b10_11_00_01>(hi)),
        );
        let y = pair(
            _mm_cmpeq_epi32(lo, _mm_shuffle_epi32::<0b01_00_11_10>(lo)),
            _mm_cmpeq_epi32(hi, _mm_shuffle_epi32::<0b01_00_11_10>(hi)),
        );
        let z = bits(_mm_cmpeq_epi32(lo, hi)) * 0x11;
        let none = _mm_set1_epi32(VOID as i32);
        let valid = !pair(_mm_cmpeq_epi32(lo, none), _mm_cmpeq_epi32(hi, none));
        // Leaf indices are below 2^31: signed comparisons serve.
        let index = _mm_set1_epi32(!LEAF as i32);
        let (a, b) = (_mm_and_si128(lo, index), _mm_and_si128(hi, index));
        let start = _mm_set1_epi32(local.start as i32);
        let end = _mm_set1_epi32(local.end as i32);
        let inside =
            |v: __m128i| _mm_andnot_si128(_mm_cmplt_epi32(v, start), _mm_cmplt_epi32(v, end));
        let remote = !pair(inside(a), inside(b));
        ([x, y, z], valid, remote)
    }
}

/// Node extraction at one point of the walk (see [`walk_points`]).
fn record_point(
    leaves: &Merged,
    local: &std::ops::Range<usize>,
    overflow: &mut bool,
    out: &mut DualNodes,
    refs: &[u32; 8],
) {
    // Bit `p` of `same[d]`: the leaf on side `p` (every leaf of the walk
    // is kept) is also on side `p ^ 1 << d`. A leaf around the point fills
    // an aligned block of 1, 2 or 4 sides, which holds a neighbour of each
    // of its sides along every axis it spans: no axis, the point is its
    // corner; one, inside its edge; two, inside its face.
    let (same, valid, remote) = side_masks(refs, local);
    let same = same.map(|s| s & valid);
    let corners = valid & !(same[0] | same[1] | same[2]);
    if corners == 0 {
        return;
    }
    let mut flags = if remote & valid != 0 { BOUNDARY } else { 0 };
    if corners & !remote != 0 {
        flags |= CORNER;
    }
    let most = out.flags.len().max(out.face.len()).max(out.edge.len());
    if most >= 1 << 30 {
        // The tag bits leave 30 bits for the index.
        *overflow = true;
        return;
    }
    let id;
    // The axes the leaf on side `p` spans at the point, as bits.
    let along = |p: usize| (0..3).fold(0, |m, d| m | (same[d] >> p & 1) << d);
    // The sides whose leaf spans two axes, and one.
    let two = same[0] & same[1] | same[0] & same[2] | same[1] & same[2];
    let one = (same[0] | same[1] | same[2]) & !two;
    // The leaf above the point along every axis holds its directory cell.
    let above = (valid >> 7 & 1 != 0, (valid & !remote) >> 7 & 1 != 0);
    let mut directory = |kind: usize, k: usize| match above {
        (true, here) => out.directory_here[kind] += here as u64,
        (false, _) => out.directory_unknown[kind].push(k as u32),
    };
    if two != 0 {
        let p = two.trailing_zeros() as usize;
        // Face interior of the coarse leaf: its 4 positions span two
        // axes; the third, across which it does not extend, is the
        // face normal.
        let n = (!along(p) & 7).trailing_zeros() as usize;
        let side = (p >> n) & 1;
        id = FACE | out.face.len() as u32;
        directory(0, out.face.len());
        out.face.push(refs[p] & !LEAF, (n | side << 2) as u8, flags);
    } else if one != 0 {
        let p = one.trailing_zeros() as usize;
        let e = along(p).trailing_zeros() as usize;
        // The edge of the coarse leaf through the point: opposite side
        // of the point on the two other axes, both ends along `e`.
        let base = !p & 7 & !(1 << e);
        id = EDGE | out.edge.len() as u32;
        directory(1, out.edge.len());
        out.edge.push(refs[p] & !LEAF, (e | base << 2) as u8, flags);
    } else {
        id = out.flags.len() as u32;
        grow(&mut out.flags);
        out.flags.push(flags);
        if flags & BOUNDARY != 0 {
            let p = corners.trailing_zeros() as usize;
            let o = leaves.get((refs[p] & !LEAF) as usize);
            let x = corner_coords(o.coords(), o.side(), !p & 7);
            out.boundary_points.push((id, x));
        }
    }
    let mut rest = corners;
    while rest != 0 {
        let p = rest.trailing_zeros() as usize;
        rest &= rest - 1;
        out.corners[(refs[p] & !LEAF) as usize][!p & 7] = id;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn uniform(level: u8) -> Vec<Octant> {
        let n = 1u64 << (3 * level as u32);
        let shift = 3 * (crate::octree::octant::LATTICE_BITS - level as u32);
        (0..n)
            .map(|i| Octant::from_parts(i << shift, level))
            .collect()
    }

    fn whole(leaves: &[Octant]) -> Merged<'_> {
        Merged {
            before: &[],
            local: leaves,
            after: &[],
        }
    }

    /// Lattice coordinates of every corner-table entry, found independently
    /// from the leaves: (entry, point) pairs, checked to agree.
    fn points(d: &DualNodes, leaves: &[Octant]) -> std::collections::BTreeMap<u32, [u32; 3]> {
        let mut at = std::collections::BTreeMap::new();
        for (l, cs) in leaves.iter().zip(&d.corners) {
            for (c, &n) in cs.iter().enumerate() {
                let x = corner_coords(l.coords(), l.side(), c);
                assert_eq!(*at.entry(n).or_insert(x), x, "entry {n:#x} at two points");
            }
        }
        at
    }

    /// Writes the lattice coordinates of independent node `n` to
    /// `out[map(n)]` for every node with `map(n) != UNSET`.
    fn scatter_coords(
        d: &DualNodes,
        leaves: Merged,
        kept: &Bits,
        map: impl Fn(u32) -> u32,
        out: &mut [[u32; 3]],
    ) {
        for (i, cs) in d.corners.iter().enumerate() {
            if !kept.get(i) {
                continue;
            }
            let o = leaves.get(i);
            let (a, s) = (o.coords(), o.side());
            for (c, &n) in cs.iter().enumerate() {
                if n & TAG != 0 {
                    continue;
                }
                let m = map(n);
                if m != UNSET {
                    out[m as usize] = corner_coords(a, s, c);
                }
            }
        }
    }

    #[test]
    fn ranks_select_the_members_in_order() {
        let mut rng = crate::testutil::Rng(0x5e1e_c7ed);
        for n in [0, 1, 63, 64, 65, 200, 1000] {
            // Runs of members and of others, and scattered ones.
            let member: Vec<bool> = (0..n)
                .map(|i| match (i / 64) % 3 {
                    0 => true,
                    1 => false,
                    _ => rng.next() & 1 == 0,
                })
                .collect();
            let v: Vec<u32> = (0..n as u32).map(|i| i * 7 + 1).collect();
            let ranks = Ranks::from_fn(n, |i| member[i]);
            let mut got = Vec::new();
            ranks.select(&v, &mut got);
            let want: Vec<u32> = v
                .iter()
                .zip(&member)
                .filter(|p| *p.1)
                .map(|p| *p.0)
                .collect();
            assert_eq!(got, want, "{n}");
            for (k, &x) in got.iter().enumerate() {
                assert_eq!(ranks.rank(((x - 1) / 7) as usize), k as u32);
            }
            // The branch-free query agrees with the count of members before
            // each entry, members or not.
            let mut before = 0;
            for (i, &m) in member.iter().enumerate() {
                assert_eq!(ranks.rank_member(i), (before, m), "{n} {i}");
                before += m as u32;
            }
            let full = Ranks::from_fn(n, |_| true);
            assert!(full.is_full());
            assert!((0..n).all(|i| full.rank_member(i) == (i as u32, true)));
        }
    }

    #[test]
    fn uniform_grid_has_every_lattice_point_once() {
        let leaves = uniform(2);
        let kept = Bits::from_fn(leaves.len(), |_| true);
        let d = extract_nodes(whole(&leaves)).unwrap().0;
        assert_eq!(d.flags.len(), 125);
        assert!(d.face.len() == 0 && d.edge.len() == 0);
        let at = points(&d, &leaves);
        assert_eq!(at.len(), 125);
        let distinct: std::collections::BTreeSet<_> = at.values().collect();
        assert_eq!(distinct.len(), 125);
        // Scattering reproduces the same coordinates.
        let mut out = vec![[u32::MAX; 3]; 125];
        scatter_coords(&d, whole(&leaves), &kept, |n| n, &mut out);
        for (n, x) in at {
            assert_eq!(out[n as usize], x);
        }
        assert!(d.flags.iter().all(|&f| f == CORNER));
    }

    #[test]
    fn one_refined_octant_hangs_on_its_neighbours() {
        // Root split once, child 0 split again.
        let mut leaves: Vec<Octant> = Octant::ROOT.child(0).children().to_vec();
        leaves.extend((1..8).map(|c| Octant::ROOT.child(c)));
        let d = extract_nodes(whole(&leaves)).unwrap().0;
        let at = points(&d, &leaves);
        // 27 coarse points + 27 fine points of child 0, 8 of them shared.
        assert_eq!(at.len(), 27 + 27 - 8);
        // Child 0's faces towards its siblings: 3 centres; its edges inside
        // the root: 3 whole edges, and halves of 6 face-boundary edges.
        assert_eq!(d.face.len(), 3);
        assert_eq!(d.edge.len(), 3 + 6);
        assert_eq!(d.flags.len(), 27 + 8 - 1);
        let entries = d.face.iter().map(|(q, m, f)| (FACE, q, m, f));
        let entries = entries.chain(d.edge.iter().map(|(q, m, f)| (EDGE, q, m, f)));
        let mut k = [0u32; 2];
        for (tag, q, mask, flags) in entries {
            let id = tag | k[(tag == EDGE) as usize];
            k[(tag == EDGE) as usize] += 1;
            assert_eq!(mask.count_ones(), if tag == FACE { 4 } else { 2 });
            assert_eq!(flags, CORNER);
            let deps: Vec<[u32; 3]> = (0..8)
                .filter(|c| mask >> c & 1 == 1)
                .map(|c| {
                    let n = d.corners[q as usize][c];
                    assert_eq!(n & TAG, 0, "dependencies are independent");
                    at[&n]
                })
                .collect();
            // The hanging node is the average of what it depends on.
            for ax in 0..3 {
                let sum: u32 = deps.iter().map(|c| c[ax]).sum();
                assert_eq!(sum, at[&id][ax] * deps.len() as u32);
            }
            assert_eq!(DualNodes::hanging_coords(leaves[q as usize], mask), at[&id]);
        }
        // Every independent node is a corner; the coarse leaves are local,
        // so their corners need no mark as dependencies.
        assert!(d
            .flags
            .iter()
            .all(|&f| f & CORNER != 0 && f & BOUNDARY == 0));
        assert!(d.flags.iter().all(|&f| f & DEP == 0));
    }

    #[test]
    fn ghosts_mark_boundary_nodes_and_their_dependencies() {
        // Child 0 refined; only its fine child 1 is local, the rest ghosts.
        let fine = Octant::ROOT.child(0).children();
        let mut after: Vec<Octant> = fine[2..].to_vec();
        after.extend((1..8).map(|c| Octant::ROOT.child(c)));
        let m = Merged {
            before: &fine[..1],
            local: &fine[1..2],
            after: &after,
        };
        let d = extract_nodes(m).unwrap().0;
        let all: Vec<Octant> = (0..m.len()).map(|i| m.get(i)).collect();
        let at = points(&d, &all);
        let mine = fine[1];
        let is_corner =
            |x: [u32; 3]| (0..8).any(|c| corner_coords(mine.coords(), mine.side(), c) == x);
        for (n, &f) in d.flags.iter().enumerate() {
            let x = at[&(n as u32)];
            // Every point touches a ghost here.
            assert!(f & BOUNDARY != 0, "node at {x:?}");
            assert_eq!(f & CORNER != 0, is_corner(x), "node at {x:?}");
        }
        // The centre of coarse child 1's face is a corner of the local leaf
        // and hangs on that face; the face's far corner (h, h, h) is used
        // only as its dependency.
        let h = mine.side() * 2;
        let far = at
            .iter()
            .find(|(_, &x)| x == [h, h, h])
            .map(|(&n, _)| n)
            .unwrap();
        assert_eq!(d.flags[far as usize] & USED, DEP);
        let used: Vec<u8> = (d.face.iter()).chain(d.edge.iter()).map(|e| e.2).collect();
        assert!(used.contains(&(CORNER | BOUNDARY)));
        assert!(used.iter().all(|&f| f & BOUNDARY != 0));
    }

    #[test]
    #[cfg(target_arch = "x86_64")]
    fn sse2_side_masks_equal_the_scalar_ones() {
        let mut rng = crate::testutil::Rng(0x51de);
        let local = 1000..2000usize;
        // Few distinct values, so that sides repeat; local, ghost and no
        // leaf; indices next to the local range's ends.
        let pool = [
            VOID,
            LEAF | 999,
            LEAF | 1000,
            LEAF | 1999,
            LEAF | 2000,
            LEAF,
            LEAF | 0x7FFF_FFFE,
        ];
        for _ in 0..100_000 {
            let refs: [u32; 8] = std::array::from_fn(|_| {
                let k = rng.next() as usize % (pool.len() + 3);
                pool.get(k).copied().unwrap_or(LEAF | (1000 + k as u32))
            });
            assert_eq!(
                side_masks_sse2(&refs, &local),
                side_masks_scalar(&refs, &local),
                "{refs:x?}"
            );
        }
    }

    /// The recursive descent the one-pass [`build`] replaces: the children
    /// of `o` found by searching the sorted leaves.
    fn build_by_descent(leaves: &[Octant], o: Octant, tree: &mut Vec<[u32; 8]>, lo: usize) -> u32 {
        if leaves.is_empty() {
            return VOID;
        }
        if leaves[0].level() <= o.level() {
            return LEAF | lo as u32;
        }
        let idx = tree.len();
        tree.push([VOID; 8]);
        let mut a = 0;
        for c in 0..8u32 {
            let end = o.child(c).cell_end();
            let b = a + leaves[a..].partition_point(|l| l.cell_begin() < end);
            let r = build_by_descent(&leaves[a..b], o.child(c), tree, lo + a);
            tree[idx][c as usize] = r;
            a = b;
        }
        if (0..8).all(|c| tree[idx][c] == LEAF | (lo + c) as u32) {
            tree.pop();
            return FAMILY | lo as u32;
        }
        if tree[idx].iter().all(|&c| c & LEAF != 0) {
            return BOTTOM | idx as u32;
        }
        idx as u32
    }

    /// A random complete tree, `depth` rounds of splitting leaves below
    /// `max_level` with probability `split`, then leaves removed with
    /// probability `drop` (gaps). Not balanced.
    fn random_leaves(
        rng: &mut crate::testutil::Rng,
        depth: usize,
        max_level: u8,
        split: f64,
        drop: f64,
    ) -> Vec<Octant> {
        let mut leaves = vec![Octant::ROOT];
        for _ in 0..depth {
            leaves = leaves
                .iter()
                .flat_map(|&o| {
                    if o.level() < max_level && rng.unit() < split {
                        o.children().to_vec()
                    } else {
                        vec![o]
                    }
                })
                .collect();
        }
        leaves.retain(|_| rng.unit() >= drop);
        leaves
    }

    /// `leaves` as ghosts before (the first `before`), local leaves (half
    /// the rest) and ghosts after.
    fn split_in_three(leaves: &[Octant], before: usize) -> Merged<'_> {
        let (before, rest) = leaves.split_at(before);
        let (local, after) = rest.split_at(rest.len() / 2);
        Merged {
            before,
            local,
            after,
        }
    }

    #[test]
    fn one_pass_build_equals_the_recursive_descent() {
        let mut rng = crate::testutil::Rng(7);
        for case in 0..200 {
            let drop = [0.0, 0.1, 0.6][case % 3];
            let leaves = random_leaves(&mut rng, 1 + case % 5, 6, 0.5, drop);
            let merged = split_in_three(&leaves, leaves.len() / 3);
            let mut want = Vec::new();
            let want_root = build_by_descent(&leaves, Octant::ROOT, &mut want, 0);
            let (got, got_root) = build(&merged);
            assert_eq!((got_root, &got), (want_root, &want), "case {case}");
        }
    }

    /// Records what [`walk_faces`] reports, families as their pairs.
    struct Pairs(Vec<(usize, usize, usize)>);

    impl FaceVisitor for Pairs {
        fn pair(&mut self, axis: usize, low: usize, high: usize) {
            self.0.push((axis, low, high));
        }
    }

    #[test]
    fn the_face_walk_meets_every_face_once() {
        let mut rng = crate::testutil::Rng(11);
        for case in 0..120 {
            let drop = [0.0, 0.1, 0.5][case % 3];
            let leaves = random_leaves(&mut rng, 1 + case % 4, 4, 0.6, drop);
            let tree = DualTree::new(&split_in_three(&leaves, leaves.len() / 4));
            let mut got = Pairs(Vec::new());
            walk_faces(&tree, &mut got);
            let mut got = got.0;
            got.sort_unstable();
            // Every two leaves touching along a face of positive area.
            let mut want = Vec::new();
            for (i, a) in leaves.iter().enumerate() {
                for (j, b) in leaves.iter().enumerate() {
                    let (ca, cb) = (a.coords(), b.coords());
                    let (sa, sb) = (a.side(), b.side());
                    for axis in 0..3 {
                        let overlap = (0..3)
                            .filter(|&k| k != axis)
                            .all(|k| ca[k].max(cb[k]) < (ca[k] + sa).min(cb[k] + sb));
                        if overlap && ca[axis] + sa == cb[axis] {
                            want.push((axis, i, j));
                        }
                    }
                }
            }
            want.sort_unstable();
            assert_eq!(got, want, "case {case}");
        }
    }
}
