//! Octants and their Morton keys.
//!
//! An octant is a cube `(x, y, z, level)` on the integer lattice of
//! [`ROOT_LEN`] = 2^19 points per side, the same units as p4est's 3D
//! quadrants. Its side is `ROOT_LEN >> level` and its anchor `(x, y, z)` is its
//! lowest corner, aligned to the side.
//!
//! The whole octant is packed into one `u64`:
//!
//! ```text
//!  63 62 61 ........................... 5 4 ... 0
//!  0  0 | Morton code of the anchor (57 bits) | level (5 bits)
//!         z18 y18 x18 z17 y17 x17 ... z0 y0 x0
//! ```
//!
//! Because the level sits below the Morton code, sorting keys as integers is a
//! pre-order traversal of the octree: an ancestor comes right before its
//! first descendant, and disjoint octants are in Morton (Z) order. This is the
//! order p4est's `p8est_quadrant_compare` defines.
//!
//! A second integer view is the *cell range*: an octant covers the finest
//! lattice cells (level 19) with Morton indices `cell_begin()..cell_end()`. A
//! rank's share of a linear octree is such a contiguous range of cells.

use crate::error::{Error, Result};

/// Bits per coordinate of the lattice.
pub const LATTICE_BITS: u32 = 19;
/// Lattice points per side of the root cube.
pub const ROOT_LEN: u32 = 1 << LATTICE_BITS;
/// Deepest level a leaf may have (p4est's `P8EST_QMAXLEVEL`). Level 19 cells
/// exist only as units of [`Octant::cell_begin`]. Asking for a deeper level is
/// an error, never a wrap.
pub const MAX_LEVEL: u8 = 18;
/// Number of finest cells in the root cube, `8^19`.
pub const CELLS: u64 = 1 << (3 * LATTICE_BITS);

pub(crate) const LEVEL_BITS: u32 = 5;
pub(crate) const LEVEL_MASK: u64 = (1 << LEVEL_BITS) - 1;

/// Spreads the low 21 bits of `v` so that bit `i` lands on bit `3 i`.
#[inline]
pub const fn spread3(v: u32) -> u64 {
    let mut x = (v as u64) & 0x1f_ffff;
    x = (x | (x << 32)) & 0x001f_0000_0000_ffff;
    x = (x | (x << 16)) & 0x001f_0000_ff00_00ff;
    x = (x | (x << 8)) & 0x100f_00f0_0f00_f00f;
    x = (x | (x << 4)) & 0x10c3_0c30_c30c_30c3;
    x = (x | (x << 2)) & 0x1249_2492_4924_9249;
    x
}

/// Inverse of [`spread3`]: gathers bits `0, 3, 6, ...` of `m`.
#[inline]
pub fn compact3(m: u64) -> u32 {
    let mut x = m & 0x1249_2492_4924_9249;
    x = (x ^ (x >> 2)) & 0x10c3_0c30_c30c_30c3;
    x = (x ^ (x >> 4)) & 0x100f_00f0_0f00_f00f;
    x = (x ^ (x >> 8)) & 0x001f_0000_ff00_00ff;
    x = (x ^ (x >> 16)) & 0x001f_0000_0000_ffff;
    x = (x ^ (x >> 32)) & 0x1f_ffff;
    x as u32
}

/// Morton code of a lattice point (x in the lowest bit of each triple).
#[inline]
pub fn morton_encode(x: u32, y: u32, z: u32) -> u64 {
    spread3(x) | (spread3(y) << 1) | (spread3(z) << 2)
}

/// Inverse of [`morton_encode`].
#[inline]
pub fn morton_decode(m: u64) -> [u32; 3] {
    [compact3(m), compact3(m >> 1), compact3(m >> 2)]
}

crate::named_enum! {
    /// Which contacts between leaves the 2:1 condition applies to.
    #[derive(PartialOrd, Ord)]
    pub enum Connectivity: "connectivity" {
        /// Leaves sharing a face (what finite volumes and DG need).
        Face = "face",
        /// Leaves sharing a face or an edge (what continuous FEM needs).
        Edge = "edge",
        /// Leaves sharing a face, an edge or a corner.
        Corner = "corner" | "full",
    }
}

impl Connectivity {
    /// Offsets (in units of an octant's side) of the same-size neighbours
    /// that touch it with a contact of this kind: 6, 18 or 26 of them.
    pub fn offsets(self) -> &'static [[i32; 3]] {
        let n = match self {
            Connectivity::Face => 6,
            Connectivity::Edge => 18,
            Connectivity::Corner => 26,
        };
        &NEIGHBOR_OFFSETS[..n]
    }

    /// Whether two boxes that touch in a contact of dimension `dim`
    /// (2 face, 1 edge, 0 corner) count.
    pub fn counts_contact(self, dim: u32) -> bool {
        match self {
            Connectivity::Face => dim == 2,
            Connectivity::Edge => dim >= 1,
            Connectivity::Corner => true,
        }
    }
}

/// The 26 neighbour offsets, faces first, then edges, then corners, so that
/// a prefix of 6, 18 or 26 serves face, edge or corner connectivity.
pub const NEIGHBOR_OFFSETS: [[i32; 3]; 26] = [
    // faces, p4est numbering: -x +x -y +y -z +z
    [-1, 0, 0],
    [1, 0, 0],
    [0, -1, 0],
    [0, 1, 0],
    [0, 0, -1],
    [0, 0, 1],
    // edges parallel to x, then y, then z (p4est edge numbering)
    [0, -1, -1],
    [0, 1, -1],
    [0, -1, 1],
    [0, 1, 1],
    [-1, 0, -1],
    [1, 0, -1],
    [-1, 0, 1],
    [1, 0, 1],
    [-1, -1, 0],
    [1, -1, 0],
    [-1, 1, 0],
    [1, 1, 0],
    // corners, bit 0 = x, bit 1 = y, bit 2 = z
    [-1, -1, -1],
    [1, -1, -1],
    [-1, 1, -1],
    [1, 1, -1],
    [-1, -1, 1],
    [1, -1, 1],
    [-1, 1, 1],
    [1, 1, 1],
];

/// An octant packed in a `u64` (see the module documentation). Ordering is
/// Morton pre-order.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
#[repr(transparent)]
pub struct Octant(u64);

impl std::fmt::Debug for Octant {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let [x, y, z] = self.coords();
        write!(f, "Octant({x}, {y}, {z}, L{})", self.level())
    }
}

impl Octant {
    /// The root cube.
    pub const ROOT: Octant = Octant(0);

    /// Creates an octant, checking the level, the range and the alignment of
    /// the anchor.
    pub fn new(x: u32, y: u32, z: u32, level: u8) -> Result<Octant> {
        if level > MAX_LEVEL {
            return Err(Error::invalid(format!(
                "level {level} is above the maximum level {MAX_LEVEL}"
            )));
        }
        let mask = (ROOT_LEN >> level) - 1;
        for (c, name) in [(x, 'x'), (y, 'y'), (z, 'z')] {
            if c >= ROOT_LEN {
                return Err(Error::invalid(format!(
                    "octant {name} = {c} is outside the lattice [0, {ROOT_LEN})"
                )));
            }
            if c & mask != 0 {
                return Err(Error::invalid(format!(
                    "octant {name} = {c} is not aligned to level {level}"
                )));
            }
        }
        Ok(Octant::from_parts(morton_encode(x, y, z), level))
    }

    /// Builds an octant from a Morton code of its anchor and its level,
    /// without checks.
    #[inline]
    pub const fn from_parts(morton: u64, level: u8) -> Octant {
        Octant((morton << LEVEL_BITS) | level as u64)
    }

    /// Reinterprets a key produced by [`Octant::key`].
    #[inline]
    pub const fn from_key(key: u64) -> Octant {
        Octant(key)
    }

    /// Views a slice of octants as their keys, without copying.
    pub fn as_keys(octants: &[Octant]) -> &[u64] {
        // SAFETY: Octant is repr(transparent) over u64.
        unsafe { std::slice::from_raw_parts(octants.as_ptr() as *const u64, octants.len()) }
    }

    /// The packed key; integer order is Morton pre-order.
    #[inline]
    pub const fn key(self) -> u64 {
        self.0
    }

    /// Refinement level, 0 for the root.
    #[inline]
    pub const fn level(self) -> u8 {
        (self.0 & LEVEL_MASK) as u8
    }

    /// Morton code of the anchor.
    #[inline]
    pub const fn morton(self) -> u64 {
        self.0 >> LEVEL_BITS
    }

    /// Anchor coordinates in lattice units.
    #[inline]
    pub fn coords(self) -> [u32; 3] {
        morton_decode(self.morton())
    }

    /// Side length in lattice units.
    #[inline]
    pub const fn side(self) -> u32 {
        ROOT_LEN >> self.level()
    }

    /// Number of level-19 cells below this octant's level: `3 * (19 - level)`
    /// bits of the Morton code belong to its interior.
    #[inline]
    const fn shift(self) -> u32 {
        3 * (LATTICE_BITS - self.level() as u32)
    }

    /// First finest cell covered (its Morton index).
    #[inline]
    pub const fn cell_begin(self) -> u64 {
        self.morton()
    }

    /// One past the last finest cell covered.
    #[inline]
    pub const fn cell_end(self) -> u64 {
        self.morton() + (1u64 << self.shift())
    }

    /// The parent; the root is its own parent.
    #[inline]
    pub const fn parent(self) -> Octant {
        if self.level() == 0 {
            return self;
        }
        let l = self.level() - 1;
        let s = 3 * (LATTICE_BITS - l as u32);
        Octant::from_parts((self.morton() >> s) << s, l)
    }

    /// Ancestor (or self) at `level <= self.level()`.
    #[inline]
    pub const fn ancestor(self, level: u8) -> Octant {
        let s = 3 * (LATTICE_BITS - level as u32);
        Octant::from_parts((self.morton() >> s) << s, level)
    }

    /// Child `i` in Morton order (`i` in `0..8`, bit 0 = x, 1 = y, 2 = z).
    /// The caller ensures `level() < MAX_LEVEL`.
    #[inline]
    pub const fn child(self, i: u32) -> Octant {
        let l = self.level() + 1;
        let s = 3 * (LATTICE_BITS - l as u32);
        Octant::from_parts(self.morton() | ((i as u64) << s), l)
    }

    /// The eight children in Morton order.
    pub fn children(self) -> [Octant; 8] {
        std::array::from_fn(|i| self.child(i as u32))
    }

    /// Position among its siblings (0 for the root).
    #[inline]
    pub const fn child_id(self) -> u32 {
        if self.level() == 0 {
            return 0;
        }
        ((self.morton() >> self.shift()) & 7) as u32
    }

    /// Whether `self` is a strict ancestor of `other`.
    #[inline]
    pub const fn is_ancestor_of(self, other: Octant) -> bool {
        self.level() < other.level()
            && (other.morton() >> self.shift()) == (self.morton() >> self.shift())
    }

    /// Whether `other` lies inside `self` (or equals it).
    #[inline]
    pub const fn contains(self, other: Octant) -> bool {
        self.level() <= other.level()
            && (other.morton() >> self.shift()) == (self.morton() >> self.shift())
    }

    /// Whether the two octants share interior (one contains the other).
    #[inline]
    pub const fn overlaps(self, other: Octant) -> bool {
        self.contains(other) || other.contains(self)
    }

    /// The eight children of the parent (the family), in Morton order; the
    /// root's family is just the root, repeated.
    pub fn siblings(self) -> [Octant; 8] {
        if self.level() == 0 {
            return [self; 8];
        }
        self.parent().children()
    }

    /// Whether both have the same parent and level (an octant is its own
    /// sibling).
    pub fn is_sibling_of(self, other: Octant) -> bool {
        self.level() == other.level() && self.level() > 0 && self.parent() == other.parent()
    }

    /// Nearest common ancestor (an octant is its own ancestor here).
    pub fn nearest_common_ancestor(self, other: Octant) -> Octant {
        let diff = self.morton() ^ other.morton();
        let mut level = self.level().min(other.level());
        if diff != 0 {
            let top = 63 - diff.leading_zeros(); // highest differing bit
            let common = (LATTICE_BITS - 1 - top / 3) as u8; // levels fully shared
            level = level.min(common);
        }
        self.ancestor(level)
    }

    /// First (lowest Morton) descendant at `level >= self.level()`.
    pub const fn first_descendant(self, level: u8) -> Octant {
        Octant::from_parts(self.morton(), level)
    }

    /// Last (highest Morton) descendant at `level >= self.level()`.
    pub const fn last_descendant(self, level: u8) -> Octant {
        let s = 3 * (LATTICE_BITS - level as u32);
        let m = self.cell_end() - (1u64 << s);
        Octant::from_parts(m, level)
    }

    /// The same-size octant shifted by `d` sides, or `None` if it falls
    /// outside the root cube.
    #[inline]
    pub fn neighbor(self, d: [i32; 3]) -> Option<Octant> {
        let len = self.side() as i64;
        let c = self.coords();
        let mut n = [0u32; 3];
        for k in 0..3 {
            let v = c[k] as i64 + d[k] as i64 * len;
            if v < 0 || v >= ROOT_LEN as i64 {
                return None;
            }
            n[k] = v as u32;
        }
        Some(Octant::from_parts(
            morton_encode(n[0], n[1], n[2]),
            self.level(),
        ))
    }

    /// Neighbour across face `f` (0..6: -x, +x, -y, +y, -z, +z).
    pub fn face_neighbor(self, f: usize) -> Option<Octant> {
        self.neighbor(NEIGHBOR_OFFSETS[f])
    }

    /// The six face neighbours in [`Octant::face_neighbor`]'s order, with
    /// the anchor decoded once (for loops over every leaf).
    pub fn face_neighbors(self) -> [Option<Octant>; 6] {
        let (c, len, level) = (self.coords(), self.side(), self.level());
        std::array::from_fn(|f| {
            let (axis, plus) = (f / 2, f % 2 == 1);
            let mut n = c;
            if plus {
                n[axis] = n[axis].checked_add(len).filter(|&v| v < ROOT_LEN)?;
            } else {
                n[axis] = n[axis].checked_sub(len)?;
            }
            Some(Octant::from_parts(morton_encode(n[0], n[1], n[2]), level))
        })
    }

    /// Neighbour across edge `e` (0..12, p4est numbering: 0-3 parallel to
    /// x, 4-7 to y, 8-11 to z).
    pub fn edge_neighbor(self, e: usize) -> Option<Octant> {
        self.neighbor(NEIGHBOR_OFFSETS[6 + e])
    }

    /// Neighbour across corner `c` (0..8, bit 0 = +x, 1 = +y, 2 = +z).
    pub fn corner_neighbor(self, c: usize) -> Option<Octant> {
        self.neighbor(NEIGHBOR_OFFSETS[18 + c])
    }

    /// Whether the octant touches the boundary of the root cube.
    pub fn touches_domain_boundary(self) -> bool {
        let len = self.side();
        self.coords().iter().any(|&c| c == 0 || c + len == ROOT_LEN)
    }

    /// Lower and upper corners in lattice units.
    pub fn bounds_f64(self) -> ([f64; 3], [f64; 3]) {
        let c = self.coords();
        let l = self.side() as f64;
        let lo = [c[0] as f64, c[1] as f64, c[2] as f64];
        (lo, [lo[0] + l, lo[1] + l, lo[2] + l])
    }

    /// Whether two octants touch (share at least a boundary point) without
    /// overlapping, and the dimension of their contact: 2 face, 1 edge,
    /// 0 corner.
    pub fn contact(self, other: Octant) -> Option<u32> {
        let (a, la) = (self.coords(), self.side() as i64);
        let (b, lb) = (other.coords(), other.side() as i64);
        let mut dim = 0;
        for k in 0..3 {
            let (a0, a1) = (a[k] as i64, a[k] as i64 + la);
            let (b0, b1) = (b[k] as i64, b[k] as i64 + lb);
            if a1 < b0 || b1 < a0 {
                return None;
            }
            if a1 > b0 && b1 > a0 {
                dim += 1; // overlapping interval of positive length
            }
        }
        if dim == 3 {
            None // interiors overlap
        } else {
            Some(dim)
        }
    }
}

/// Appends to `out` the coarsest octants that exactly cover the finest cells
/// `begin..end` in Morton order (the minimal complete linear octree of that
/// range). Both ends must be multiples of the cells of a [`MAX_LEVEL`] octant.
pub fn cover_cells(mut begin: u64, end: u64, out: &mut Vec<Octant>) {
    while begin < end {
        let align = if begin == 0 {
            LATTICE_BITS
        } else {
            (begin.trailing_zeros() / 3).min(LATTICE_BITS)
        };
        let mut k = align;
        while (1u64 << (3 * k)) > end - begin {
            k -= 1;
        }
        let level = (LATTICE_BITS - k) as u8;
        debug_assert!(level <= MAX_LEVEL);
        out.push(Octant::from_parts(begin, level));
        begin += 1u64 << (3 * k);
    }
}

/// The minimal complete set of octants strictly between `a` and `b`
/// (`a < b`, disjoint), in Morton order: the construction step of Sundar et
/// al.'s `completeRegion`.
pub fn complete_region(a: Octant, b: Octant, out: &mut Vec<Octant>) {
    cover_cells(a.cell_end(), b.cell_begin(), out);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn face_neighbors_match_face_neighbor() {
        let mut o = Octant::ROOT;
        for c in [0u32, 7, 3, 5, 1] {
            o = o.child(c);
            let all = o.face_neighbors();
            for (f, n) in all.iter().enumerate() {
                assert_eq!(*n, o.face_neighbor(f), "{o:?} face {f}");
            }
        }
    }

    #[test]
    fn morton_roundtrip() {
        for &(x, y, z) in &[
            (0, 0, 0),
            (1, 2, 3),
            (ROOT_LEN - 1, 5, ROOT_LEN - 1),
            (12345, 67890, 424242),
        ] {
            assert_eq!(morton_decode(morton_encode(x, y, z)), [x, y, z]);
        }
        assert_eq!(morton_encode(1, 0, 0), 1);
        assert_eq!(morton_encode(0, 1, 0), 2);
        assert_eq!(morton_encode(0, 0, 1), 4);
    }

    #[test]
    fn level_limit_is_an_error() {
        assert!(Octant::new(0, 0, 0, MAX_LEVEL).is_ok());
        assert!(Octant::new(0, 0, 0, MAX_LEVEL + 1).is_err());
        assert!(Octant::new(1, 0, 0, 3).is_err());
        assert!(Octant::new(ROOT_LEN, 0, 0, 3).is_err());
    }

    #[test]
    fn parent_child_and_order() {
        let o = Octant::new(1 << 17, 3 << 16, 0, 3).unwrap();
        for (i, c) in o.children().iter().enumerate() {
            assert_eq!(c.parent(), o);
            assert_eq!(c.child_id() as usize, i);
            assert!(o.is_ancestor_of(*c));
            assert!(o < *c, "ancestor sorts first");
            assert!(!c.is_ancestor_of(o));
        }
        let ch = o.children();
        assert!(ch.windows(2).all(|w| w[0] < w[1]));
        // The last descendant of the first child sorts before the second child.
        assert!(ch[0].last_descendant(MAX_LEVEL) < ch[1]);
        assert_eq!(o.first_descendant(5).parent().parent(), o);
        assert_eq!(o.last_descendant(5).ancestor(3), o);
    }

    #[test]
    fn nca() {
        let a = Octant::new(0, 0, 0, 5).unwrap();
        let b = Octant::new(ROOT_LEN / 2, 0, 0, 5).unwrap();
        assert_eq!(a.nearest_common_ancestor(b), Octant::ROOT);
        let c = a.children()[7];
        assert_eq!(a.nearest_common_ancestor(c), a);
        let d = a.children()[1].children()[2];
        assert_eq!(c.nearest_common_ancestor(d), a);
    }

    #[test]
    fn neighbors_and_contact() {
        let o = Octant::new(0, 0, 0, 2).unwrap();
        assert!(o.face_neighbor(0).is_none());
        let n = o.face_neighbor(1).unwrap();
        assert_eq!(n.coords(), [ROOT_LEN / 4, 0, 0]);
        assert_eq!(o.contact(n), Some(2));
        assert_eq!(o.contact(o.edge_neighbor(11).unwrap()), Some(1)); // offset [1, 0, 1]
        assert!(o.siblings().contains(&o) && o.siblings().iter().all(|s| s.is_sibling_of(o)));
        let c = o.corner_neighbor(7).unwrap();
        assert_eq!(o.contact(c), Some(0));
        assert_eq!(o.contact(o.children()[0]), None);
        assert!(o.touches_domain_boundary());
    }

    #[test]
    fn cover_is_complete_and_coarsest() {
        let mut out = Vec::new();
        cover_cells(0, CELLS, &mut out);
        assert_eq!(out, vec![Octant::ROOT]);
        out.clear();
        let a = Octant::ROOT.child(0).child(3).child(5);
        let b = Octant::ROOT.child(6).child(1);
        complete_region(a, b, &mut out);
        let mut cur = a.cell_end();
        for o in &out {
            assert_eq!(o.cell_begin(), cur);
            // coarsest: the parent would overlap a or b or not fit
            let p = o.parent();
            assert!(p.cell_begin() < a.cell_end() || p.cell_end() > b.cell_begin());
            cur = o.cell_end();
        }
        assert_eq!(cur, b.cell_begin());
    }
}
