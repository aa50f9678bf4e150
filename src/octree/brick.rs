//! Box domains: a brick of NX x NY x NZ cubic root cells (trees), as p4est's
//! `p8est_connectivity_new_brick(NX, NY, NZ, 0, 0, 0)`.
//!
//! The brick is embedded in the lattice's root cube: with `k` the smallest
//! level at which `2^k >= max(NX, NY, NZ)`, each tree is an octant of level
//! `k` and the trees fill the corner `[0, NX 2^(19-k)) x [0, NY 2^(19-k)) x
//! [0, NZ 2^(19-k))` of the cube. The rest of the cube is *void*:
//!
//! ```text
//!   z=0 slice of a 3 x 1 x 1 brick (k = 2):
//!   +-----+-----+-----+-----+
//!   |     void  (never refined,   |
//!   |     never a mesh element)   |
//!   +-----+-----+-----+-----+
//!   |     void                    |
//!   +-----+-----+-----+-----+
//!   |     void                    |
//!   +-----+-----+-----+-----+
//!   | t0  | t1  | t2  |void |      trees: level-k octants
//!   +-----+-----+-----+-----+
//! ```
//!
//! Why an embedding rather than a forest of separate trees: a leaf stays one
//! `u64` in one Morton order, so construction, partition, balance, ghost
//! layer and meshing run unchanged across tree boundaries. p4est orders the
//! trees of a brick along the Morton curve of the smallest power-of-two grid
//! holding it, skipping the cells outside; that is exactly the embedded
//! cube's Morton order, so a leaf's position in octmesh's order equals its
//! (tree, Morton index in tree) position in p4est's.
//!
//! The void is covered by the coarsest octants that fit (a few dozen for
//! small bricks); they keep the octree complete, take no part in balance
//! (no probe from or into them), are never refined by a rule, and are never
//! kept in a mesh. Levels users give are counted from the root cells, so
//! the octree level of a user level `l` is `l + k`.

use crate::error::{Error, Result};
use crate::octree::octant::{morton_encode, spread3, Octant, LATTICE_BITS, MAX_LEVEL, ROOT_LEN};

/// The bits of a Morton code that hold the x coordinate.
const DILATED_X: u64 = spread3(u32::MAX);

/// The brick's upper bounds ([`Brick::hi`]), each spread to its axis's bits
/// of a Morton code.
const fn dilated_hi(roots: [u32; 3], level: u8) -> [u64; 3] {
    let side = ROOT_LEN >> level;
    [
        spread3(roots[0] * side),
        spread3(roots[1] * side) << 1,
        spread3(roots[2] * side) << 2,
    ]
}

/// Root cells per axis above which a brick is refused: beyond `2^9` the
/// trees would leave less than half the levels to refinement.
pub const MAX_ROOTS: u32 = 512;

/// The brick of root cells of a domain, in lattice terms.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Brick {
    roots: [u32; 3],
    level: u8,
    /// [`dilated_hi`]: kept because [`Brick::is_void`] runs per leaf.
    dilated_hi: [u64; 3],
}

impl Default for Brick {
    fn default() -> Brick {
        Brick::CUBE
    }
}

impl Brick {
    /// The single root cube (1 x 1 x 1).
    pub const CUBE: Brick = Brick {
        roots: [1, 1, 1],
        level: 0,
        dilated_hi: dilated_hi([1, 1, 1], 0),
    };

    /// A brick of `roots[0] x roots[1] x roots[2]` trees, each at least 1
    /// and at most [`MAX_ROOTS`].
    pub fn new(roots: [u32; 3]) -> Result<Brick> {
        if roots.iter().any(|&n| n == 0 || n > MAX_ROOTS) {
            return Err(Error::invalid(format!(
                "the root cells per axis must be between 1 and {MAX_ROOTS}, got {}x{}x{}",
                roots[0], roots[1], roots[2]
            )));
        }
        let most = roots.into_iter().max().unwrap_or(1);
        let level = (32 - (most - 1).leading_zeros()) as u8;
        Ok(Brick {
            roots,
            level,
            dilated_hi: dilated_hi(roots, level),
        })
    }

    /// Root cells per axis.
    pub fn roots(&self) -> [u32; 3] {
        self.roots
    }

    /// Number of trees.
    pub fn trees(&self) -> u64 {
        self.roots.iter().map(|&n| n as u64).product()
    }

    /// The octree level of the trees (`k`): user level `l` is octree level
    /// `l + k`.
    pub fn level(&self) -> u8 {
        self.level
    }

    /// The deepest user level (counted from the trees).
    pub fn max_user_level(&self) -> u8 {
        MAX_LEVEL - self.level
    }

    /// Whether this is the plain root cube.
    pub fn is_cube(&self) -> bool {
        *self == Brick::CUBE
    }

    /// Upper lattice bound of the brick per axis (the lower one is 0).
    pub fn hi(&self) -> [u32; 3] {
        let side = ROOT_LEN >> self.level;
        self.roots.map(|n| n * side)
    }

    /// Whether `o` lies outside the brick (its interior misses it). An
    /// octant that is not void has its anchor inside the brick.
    #[inline]
    pub fn is_void(&self, o: Octant) -> bool {
        if self.is_cube() {
            return false;
        }
        // Dilated integers keep their order: a coordinate is at least the
        // bound exactly when its bits of the Morton code are at least the
        // bound's, spread the same way. No decoding.
        let m = o.morton();
        (0..3).any(|k| m & (DILATED_X << k) >= self.dilated_hi[k])
    }

    /// Whether the lattice point `x` (finest cell anchor) lies in the
    /// brick.
    #[inline]
    pub fn holds_cell(&self, x: [i64; 3]) -> bool {
        let hi = self.hi();
        (0..3).all(|k| x[k] >= 0 && x[k] < hi[k] as i64)
    }

    /// Whether the non-void octant `o` touches the brick's boundary.
    pub fn touches_boundary(&self, o: Octant) -> bool {
        let (c, len, hi) = (o.coords(), o.side(), self.hi());
        (0..3).any(|k| c[k] == 0 || c[k] + len >= hi[k])
    }

    /// The six face neighbours of `o` in [`Octant::face_neighbor`]'s
    /// order, `None` where they leave the brick.
    #[inline]
    pub fn face_neighbors(&self, o: Octant) -> [Option<Octant>; 6] {
        let n = o.face_neighbors();
        if self.is_cube() {
            return n;
        }
        let hi = self.hi();
        n.map(|n| n.filter(|n| !self.is_void_in(*n, hi)))
    }

    /// Bit `f` set when face `f` of `o` (`2 axis + 1` on the high side)
    /// lies on the domain's boundary: [`Brick::face_neighbors`] is `None`
    /// there, found without building the neighbours.
    #[inline]
    pub fn outside_faces(&self, o: Octant) -> u8 {
        let (c, s, hi) = (o.coords(), o.side(), self.hi());
        let mut bits = 0;
        for a in 0..3 {
            bits |= ((c[a] == 0) as u8) << (2 * a);
            bits |= ((c[a] + s >= hi[a]) as u8) << (2 * a + 1);
        }
        bits
    }

    #[inline]
    fn is_void_in(&self, o: Octant, hi: [u32; 3]) -> bool {
        let c = o.coords();
        (0..3).any(|k| c[k] >= hi[k])
    }

    /// The brick's trees' Morton codes (at the trees' level), in p4est's
    /// tree order.
    pub fn tree_codes(&self) -> Vec<u64> {
        let mut codes = Vec::with_capacity(self.trees() as usize);
        for z in 0..self.roots[2] {
            for y in 0..self.roots[1] {
                for x in 0..self.roots[0] {
                    codes.push(morton_encode(x, y, z));
                }
            }
        }
        codes.sort_unstable();
        codes
    }

    /// Tree numbers and tree-relative leaves: [`TreeMap::to_tree`] and
    /// back.
    pub fn tree_map(&self) -> TreeMap {
        TreeMap {
            brick: *self,
            codes: self.tree_codes(),
        }
    }
}

/// Converts between octants of the embedding cube and p4est's `(tree, x, y,
/// z, level)` with tree-relative coordinates on the tree's own `2^19`
/// lattice.
pub struct TreeMap {
    brick: Brick,
    codes: Vec<u64>,
}

impl TreeMap {
    /// The tree of a non-void octant at or below the trees' level and its
    /// anchor and level relative to the tree; `None` for void or coarser
    /// octants.
    pub fn to_tree(&self, o: Octant) -> Option<(u32, [u32; 3], u8)> {
        let k = self.brick.level;
        if self.brick.is_void(o) || o.level() < k {
            return None;
        }
        let c = o.coords();
        let shift = LATTICE_BITS - k as u32;
        let t = c.map(|v| v >> shift);
        let code = morton_encode(t[0], t[1], t[2]);
        let tree = self.codes.binary_search(&code).ok()? as u32;
        let mask = (1u32 << shift) - 1;
        Some((tree, c.map(|v| (v & mask) << k), o.level() - k))
    }

    /// The octant of tree `tree` with tree-relative anchor `x` and level
    /// `level` (p4est's units), or an error when it is not one.
    pub fn from_tree(&self, tree: u32, x: [u32; 3], level: u8) -> Result<Octant> {
        let k = self.brick.level;
        let Some(&code) = self.codes.get(tree as usize) else {
            return Err(Error::invalid(format!(
                "tree {tree} is not in the {} trees of the brick",
                self.codes.len()
            )));
        };
        if level > self.brick.max_user_level() || x.iter().any(|&v| v >= ROOT_LEN) {
            return Err(Error::invalid(format!(
                "leaf ({}, {}, {}) at level {level} of tree {tree} is out of range",
                x[0], x[1], x[2]
            )));
        }
        let t = crate::octree::octant::morton_decode(code);
        let shift = LATTICE_BITS - k as u32;
        let c: [u32; 3] = std::array::from_fn(|a| (t[a] << shift) | (x[a] >> k));
        if x.iter().any(|&v| v & ((1 << k) - 1) != 0) {
            return Err(Error::invalid(format!(
                "leaf ({}, {}, {}) of tree {tree} is finer than the lattice allows in this brick",
                x[0], x[1], x[2]
            )));
        }
        Octant::new(c[0], c[1], c[2], level + k)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn void_from_the_morton_code_agrees_with_the_coordinates() {
        for roots in [[3, 1, 1], [4, 2, 3], [5, 7, 2], [16, 8, 8], [2, 2, 2]] {
            let b = Brick::new(roots).unwrap();
            let hi = b.hi();
            let mut seed = 12345u64;
            for _ in 0..20_000 {
                seed = seed
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let level = (seed >> 59) as u8 % (MAX_LEVEL + 1);
                let mask = !((ROOT_LEN >> level) - 1) & (ROOT_LEN - 1);
                let c = [seed >> 5, seed >> 24, seed >> 43].map(|v| v as u32 & mask);
                let o = Octant::from_parts(morton_encode(c[0], c[1], c[2]), level);
                let by_coords = (0..3).any(|k| c[k] >= hi[k]);
                assert_eq!(b.is_void(o), by_coords, "{roots:?} {o:?}");
            }
        }
    }

    #[test]
    fn outside_faces_agree_with_the_face_neighbours() {
        for roots in [[1, 1, 1], [3, 1, 1], [4, 2, 3], [5, 7, 2]] {
            let b = Brick::new(roots).unwrap();
            let hi = b.hi();
            let mut seed = 777u64;
            let mut outside = 0;
            for _ in 0..20_000 {
                seed = seed
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let level = b.level() + (seed >> 59) as u8 % (MAX_LEVEL + 1 - b.level());
                let mask = !((ROOT_LEN >> level) - 1) & (ROOT_LEN - 1);
                let c: [u32; 3] = std::array::from_fn(|k| {
                    // Inside the brick, often against one of its sides.
                    let v = (seed >> (5 + 19 * k)) as u32 % hi[k];
                    match (seed >> (60 - k)) & 3 {
                        0 => 0,
                        1 => hi[k] - 1,
                        _ => v,
                    }
                });
                let c = c.map(|v| v & mask);
                let o = Octant::from_parts(morton_encode(c[0], c[1], c[2]), level);
                let bits = b.outside_faces(o);
                for (f, n) in b.face_neighbors(o).iter().enumerate() {
                    assert_eq!(bits >> f & 1 == 1, n.is_none(), "{roots:?} {o:?} face {f}");
                }
                outside += bits.count_ones();
            }
            assert!(outside > 1000, "{roots:?}: the sides were seldom reached");
        }
    }

    #[test]
    fn levels_and_bounds() {
        assert_eq!(Brick::new([1, 1, 1]).unwrap(), Brick::CUBE);
        let b = Brick::new([3, 1, 1]).unwrap();
        assert_eq!(b.level(), 2);
        assert_eq!(b.hi(), [3 * ROOT_LEN / 4, ROOT_LEN / 4, ROOT_LEN / 4]);
        assert_eq!(Brick::new([4, 2, 3]).unwrap().level(), 2);
        assert_eq!(Brick::new([5, 1, 1]).unwrap().level(), 3);
        assert!(Brick::new([0, 1, 1]).is_err());
        assert!(Brick::new([MAX_ROOTS + 1, 1, 1]).is_err());
    }

    #[test]
    fn tree_order_is_p4est_brick_order() {
        // p8est_connectivity_new_brick (4, 2, 3): trees 0..8 fill the first
        // 2x2x2 block, 8..16 the block at x = 2..4, then z = 2.
        let b = Brick::new([4, 2, 3]).unwrap();
        let codes = b.tree_codes();
        let xyz: Vec<[u32; 3]> = codes
            .iter()
            .map(|&c| crate::octree::octant::morton_decode(c))
            .collect();
        assert_eq!(xyz[0], [0, 0, 0]);
        assert_eq!(xyz[1], [1, 0, 0]);
        assert_eq!(xyz[7], [1, 1, 1]);
        assert_eq!(xyz[8], [2, 0, 0]);
        assert_eq!(xyz[16], [0, 0, 2]);
        assert_eq!(xyz[23], [3, 1, 2]);
    }

    #[test]
    fn tree_coordinates_round_trip_and_void() {
        let b = Brick::new([3, 1, 1]).unwrap();
        let map = b.tree_map();
        let o = Octant::new(ROOT_LEN / 2 + ROOT_LEN / 16, 0, ROOT_LEN / 8, 4).unwrap();
        let (tree, x, level) = map.to_tree(o).unwrap();
        assert_eq!(tree, 2);
        assert_eq!(level, 2);
        assert_eq!(x, [ROOT_LEN / 4, 0, ROOT_LEN / 2]);
        assert_eq!(map.from_tree(tree, x, level).unwrap(), o);
        let void = Octant::new(3 * ROOT_LEN / 4, 0, 0, 2).unwrap();
        assert!(b.is_void(void));
        assert!(map.to_tree(void).is_none());
        assert!(!b.is_void(o));
        assert!(map.from_tree(3, [0; 3], 0).is_err());
    }
}
