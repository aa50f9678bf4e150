//! Finite-volume faces, boundary patches and the cell halo of a mesh.
//!
//! Every face of a kept element is listed once per rank that holds one of
//! its two sides:
//!
//! - **internal**: between two local elements;
//! - **boundary**: a kept element's face that no kept element shares, with
//!   its patch (a side of the domain, or the surface);
//! - **halo**: between a local element and an element of another rank,
//!   listed on both ranks, each with its own element as the owner.
//!
//! Where a coarse element meets four finer ones (a 2:1 interface) its face
//! is split into the four fine faces, as OpenFOAM's `hexRef8` does:
//!
//! ```text
//!      coarse face           kept fine            dropped fine
//!     +-----------+     +-----+-----+        +-----+-----+
//!     |           |     |  c  |  d  |        |  ·  |  d  |   the parts of a
//!     |     e     |  →  +-----+-----+   or   +-----+-----+   coarse face next
//!     |           |     |  a  |  b  |        |  ·  |  b  |   to dropped fine
//!     +-----------+     +-----+-----+        +-----+-----+   leaves (·) are
//!                                                             boundary faces
//! ```
//!
//! Each face is a planar quadrilateral, measured in halves of the emitting
//! element's side: a whole face, a quarter, a half (two dropped quarters
//! side by side) or, when three quarters are dropped, the two quadrilaterals
//! the L-shaped remainder splits into along the diagonal from the centre to
//! the far corner. Corners of faces are always corners of kept elements, so
//! every point a finite-volume writer needs already exists.
//!
//! # Orderings
//!
//! [`Faces::faces`] lists the internal faces first, sorted by owner, then
//! neighbour (upper-triangular: the owner is the lower local element), then
//! the boundary faces grouped by patch (each group by element), then the
//! halo faces grouped by neighbour rank, each group sorted by the global
//! numbers of the lower rank's element, then the higher rank's: both ranks
//! list their shared faces in the same order. A face's normal points from
//! its owner to the other side (out of the domain on a boundary). Corners
//! run counter-clockwise seen from the side the normal points to.
//!
//! # Patches
//!
//! Patch `0..6` are the sides of the domain, `xmin xmax ymin ymax zmin zmax`
//! ([`SIDE_PATCHES`]); patch 6 is the surface. Names are given by the
//! caller ([`crate::mesh::patches::PatchNames`]).

use std::ops::Range;

use crate::octree::octant::{Octant, LATTICE_BITS};

use super::dual::Merged;
use super::Mesh;

mod walk;

pub(in crate::mesh) use walk::{FaceKind, Kept};

pub use crate::geometry::names::SIDE_PATCHES;

/// Patch id of the surface (the faces next to dropped leaves).
pub const SURFACE_PATCH: u16 = 6;

/// Number of patches: the six sides and the surface.
pub const NUM_PATCHES: usize = 7;
const _: () = assert!(NUM_PATCHES == SIDE_PATCHES.len() + 1);

/// What lies on the other side of a face.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Other {
    /// A local element.
    Element(u32),
    /// A halo element ([`Halo`] index), owned by another rank.
    Halo(u32),
    /// Nothing: a boundary face on this patch.
    Patch(u16),
}

/// One face, in 16 bytes. See the module documentation for the
/// conventions.
///
/// A face is measured in halves of the face of the element that emitted
/// it: its [`Face::origin`] is that element face's lowest corner, its
/// [`Face::half`] half that face's side, and its [`Face::shape`] four
/// corners `(a, b)` with `a, b` in `0..=2`, 2 bits each, corner `k` in bits
/// `4k..4k+4` (`a` low): point `origin + half * (a e_u + b e_v)` where
/// `(e_u, e_v, e_axis)` is right-handed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Face {
    owner: u32,
    /// [`Other`] in one word: an element below 2^31, a halo element from
    /// 2^31 on, a patch `p` as `u32::MAX - p`.
    other: u32,
    /// Bits 0-4: the shape's place in [`SHAPES`]; 5-6: the normal's axis;
    /// 7: the normal points towards decreasing coordinates; 8: the face
    /// lies on the emitting element's high side; 9 on: the emitting
    /// element's location code (a 1, then its Morton code at its level).
    code: u64,
}

/// Halo elements are numbered from here in [`Face`]'s other side.
const HALO_BASE: u32 = 1 << 31;
/// Marks a group of quarters in [`Mesh::faces`]'s scratch list.
const FINE: u32 = 1 << 31;
/// Patches are numbered down from `u32::MAX`, at most this many.
const MAX_PATCHES: u32 = 1 << 16;
/// An element's `covered` bits when every quarter of its six faces faces a
/// kept element: it has no boundary face.
const ALL_COVERED: u32 = u32::MAX >> 8;

impl Other {
    /// The one-word form [`Face`] stores.
    fn encode(self) -> u32 {
        match self {
            Other::Element(j) => j,
            Other::Halo(h) => HALO_BASE + h,
            Other::Patch(p) => u32::MAX - p as u32,
        }
    }

    fn decode(v: u32) -> Other {
        if v < HALO_BASE {
            Other::Element(v)
        } else if v > u32::MAX - MAX_PATCHES {
            Other::Patch((u32::MAX - v) as u16)
        } else {
            Other::Halo(v - HALO_BASE)
        }
    }
}

/// The in-plane axes `(u, v)` of a face normal to `axis`, right-handed with
/// it.
pub const fn plane_axes(axis: usize) -> (usize, usize) {
    ((axis + 1) % 3, (axis + 2) % 3)
}

/// The whole face: `(0,0) (2,0) (2,2) (0,2)`.
const WHOLE: [(u8, u8); 4] = [(0, 0), (2, 0), (2, 2), (0, 2)];

/// Twice the signed (shoelace) area of a quadrilateral in halves,
/// positive when counter-clockwise in `(u, v)`.
const fn twice_area(corners: &[(u8, u8); 4]) -> i32 {
    let mut sum = 0;
    let mut k = 0;
    while k < 4 {
        let (a, b) = corners[k];
        let (c, d) = corners[(k + 1) % 4];
        sum += a as i32 * d as i32 - c as i32 * b as i32;
        k += 1;
    }
    sum
}

const fn pack(corners: [(u8, u8); 4]) -> u16 {
    let mut c = corners;
    if twice_area(&corners) < 0 {
        c.swap(1, 3);
    }
    let mut out = 0u16;
    let mut k = 0;
    while k < 4 {
        out |= ((c[k].0 as u16) | (c[k].1 as u16) << 2) << (4 * k);
        k += 1;
    }
    out
}

/// A quarter of a face in halves, `(a, b)` its lowest corner.
const fn quarter(a: u8, b: u8) -> [(u8, u8); 4] {
    [(a, b), (a + 1, b), (a + 1, b + 1), (a, b + 1)]
}

/// Every shape a face takes, packed as [`Face::shape`], a face holding its
/// place: the whole face ([`WHOLE_SHAPE`]), quarter `q` (`1 + q`), the
/// half-face columns `a` (`5 + a`) and rows `b` (`7 + b`), and the two
/// quadrilaterals of the L that three dropped quarters leave around kept
/// quarter `q` (`9 + 2 q`, `10 + 2 q`; see [`dropped_pieces`]).
const SHAPES: [u16; 17] = {
    let mut out = [0u16; 17];
    out[0] = pack(WHOLE);
    let mut q = 0;
    while q < 4 {
        out[1 + q] = pack(quarter(q as u8 & 1, q as u8 >> 1));
        // The kept quarter's outer corner K, the far corner O, the centre
        // M: the L-shaped rest splits along M-O into two quadrilaterals
        // whose corners are all kept corners.
        let (ku, kv) = (2 * (q as u8 & 1), 2 * (q as u8 >> 1));
        let (ou, ov) = (2 - ku, 2 - kv);
        out[9 + 2 * q] = pack([(1, kv), (ou, kv), (ou, ov), (1, 1)]);
        out[10 + 2 * q] = pack([(1, 1), (ou, ov), (ku, ov), (ku, 1)]);
        q += 1;
    }
    let mut a = 0;
    while a < 2 {
        out[5 + a] = pack([
            (a as u8, 0),
            (a as u8 + 1, 0),
            (a as u8 + 1, 2),
            (a as u8, 2),
        ]);
        out[7 + a] = pack([
            (0, a as u8),
            (2, a as u8),
            (2, a as u8 + 1),
            (0, a as u8 + 1),
        ]);
        a += 1;
    }
    out
};

/// [`SHAPES`]' whole face.
const WHOLE_SHAPE: u8 = 0;

/// [`Face::whole_corner_octants`] by a face's bits 5-8 (normal axis, sign,
/// high side): the emitting element's Morton corners in the order of
/// [`Face::corners`].
const WHOLE_CORNERS: [[u8; 4]; 16] = {
    let mut out = [[0u8; 4]; 16];
    let mut i = 0;
    while i < 16 {
        let (axis, negative, plus) = (i & 3, i >> 2 & 1 == 1, i >> 3 & 1);
        // The (u, v) axes of `corners`.
        let (u, v) = match axis {
            0 => (1, 2),
            1 => (2, 0),
            _ => (0, 1),
        };
        let mut k = 0;
        while axis < 3 && k < 4 {
            // A negative normal sees the (u, v) order clockwise: reverse.
            let j = if negative { (4 - k) % 4 } else { k };
            let w = (SHAPES[WHOLE_SHAPE as usize] >> (4 * j)) as usize & 15;
            out[i][k] = (plus << axis | ((w & 3) / 2) << u | ((w >> 2) / 2) << v) as u8;
            k += 1;
        }
        i += 1;
    }
    out
};

impl Face {
    /// The local element on this side (the owner).
    #[inline]
    pub fn owner(&self) -> u32 {
        self.owner
    }

    /// The other side.
    #[inline]
    pub fn other(&self) -> Other {
        Other::decode(self.other)
    }

    /// The normal axis, 0 to 2.
    #[inline]
    pub fn axis(&self) -> usize {
        (self.code >> 5 & 3) as usize
    }

    /// Whether the normal points towards decreasing coordinates.
    #[inline]
    pub fn negative(&self) -> bool {
        self.code >> 7 & 1 == 1
    }

    /// The four corners in halves, packed (see [`Face`]).
    #[inline]
    pub fn shape(&self) -> u16 {
        SHAPES[(self.code & 31) as usize]
    }

    /// The element that emitted the face.
    #[inline]
    fn emitter(&self) -> Octant {
        let loc = self.code >> 9;
        let level = (63 - loc.leading_zeros()) / 3;
        let m = loc ^ 1 << (3 * level);
        Octant::from_parts(m << (3 * (LATTICE_BITS - level)), level as u8)
    }

    /// Lowest lattice corner of the square the corners are measured in
    /// (the emitting element's face).
    #[inline]
    pub fn origin(&self) -> [u32; 3] {
        let e = self.emitter();
        let mut o = e.coords();
        if self.code >> 8 & 1 == 1 {
            o[self.axis()] += e.side();
        }
        o
    }

    /// The side of the element that emitted the face, lattice units.
    #[inline]
    pub fn emitter_side(&self) -> u32 {
        self.emitter().side()
    }

    /// Half that square's side, lattice units.
    #[inline]
    pub fn half(&self) -> u32 {
        self.emitter().side() / 2
    }

    /// For a face that is the whole face of the element that emitted it:
    /// that element's corners (Morton order, 0 to 7) in the order of
    /// [`Face::corners`]; `None` for a part of a face. No coordinates are
    /// decoded.
    #[inline]
    pub fn whole_corner_octants(&self) -> Option<[usize; 4]> {
        if self.code & 31 != WHOLE_SHAPE as u64 {
            return None;
        }
        Some(WHOLE_CORNERS[(self.code >> 5 & 15) as usize].map(usize::from))
    }

    /// Corner `k` in halves, `(a, b)`, in the stored (counter-clockwise in
    /// `(u, v)`) order.
    fn corner_halves(&self, k: usize) -> (u32, u32) {
        let w = (self.shape() >> (4 * k)) & 15;
        ((w & 3) as u32, (w >> 2) as u32)
    }

    /// The four corners in lattice coordinates, counter-clockwise seen from
    /// the side the normal points to.
    pub fn corners(&self) -> [[u32; 3]; 4] {
        let (axis, h, o) = (self.axis(), self.half(), self.origin());
        std::array::from_fn(|k| {
            // A negative normal sees the (u, v) order clockwise: reverse.
            let j = if self.negative() { (4 - k) % 4 } else { k };
            let (a, b) = self.corner_halves(j);
            let (a, b) = (a * h, b * h);
            // The (u, v) of `plane_axes` written out: indexing a point by a
            // variable axis stalls on store forwarding in this hot loop.
            match axis {
                0 => [o[0], o[1] + a, o[2] + b],
                1 => [o[0] + b, o[1], o[2] + a],
                _ => [o[0] + a, o[1] + b, o[2]],
            }
        })
    }

    /// Area in lattice units squared.
    pub fn lattice_area(&self) -> f64 {
        let c = std::array::from_fn(|k| {
            let (a, b) = self.corner_halves(k);
            (a as u8, b as u8)
        });
        0.5 * twice_area(&c) as f64 * (self.half() as f64).powi(2)
    }

    /// Centroid in lattice coordinates.
    pub fn lattice_centre(&self) -> [f64; 3] {
        let (u, v) = plane_axes(self.axis());
        let (mut a2, mut cu, mut cv) = (0.0, 0.0, 0.0);
        for k in 0..4 {
            let (x0, y0) = self.corner_halves(k);
            let (x1, y1) = self.corner_halves((k + 1) % 4);
            let (x0, y0, x1, y1) = (x0 as f64, y0 as f64, x1 as f64, y1 as f64);
            let cross = x0 * y1 - x1 * y0;
            a2 += cross;
            cu += (x0 + x1) * cross;
            cv += (y0 + y1) * cross;
        }
        let (h, o) = (self.half() as f64, self.origin());
        let mut c = [o[0] as f64, o[1] as f64, o[2] as f64];
        c[u] += cu / (3.0 * a2) * h;
        c[v] += cv / (3.0 * a2) * h;
        c
    }

    /// The unit normal, from the owner to the other side.
    pub fn unit_normal(&self) -> [f64; 3] {
        let mut n = [0.0; 3];
        n[self.axis()] = if self.negative() { -1.0 } else { 1.0 };
        n
    }

    /// The same face seen from the other side (normal reversed).
    fn flipped(mut self, owner: u32, other: Other) -> Face {
        self.code ^= 1 << 7;
        self.owner = owner;
        self.other = other.encode();
        self
    }
}

/// The kept elements of other ranks that touch a local element (by a face,
/// an edge or a corner), in Morton order: the lower ranks' first.
#[derive(Clone, Debug, Default)]
pub struct Halo {
    /// The elements.
    pub leaves: Vec<Octant>,
    /// Owner rank of each.
    pub owners: Vec<u32>,
    /// Global element number of each.
    pub global: Vec<u64>,
    /// Class byte of each (the classification's bits: centre inside, cut, void).
    pub classes: Vec<u8>,
    /// How many come before this rank's range.
    pub before: usize,
}

impl Halo {
    /// The kept ghosts of `ghosts`: `data` holds each ghost's class in the
    /// low byte and its global element number above it.
    pub(crate) fn from_ghosts(
        ghosts: &crate::octree::ghost::GhostLayer,
        keep: impl Fn(u8) -> bool,
    ) -> Halo {
        let mut h = Halo::default();
        for (i, &leaf) in ghosts.leaves.iter().enumerate() {
            if i == ghosts.before {
                h.before = h.leaves.len();
            }
            if keep(ghosts.data[i] as u8) {
                h.leaves.push(leaf);
                h.owners.push(ghosts.owners[i]);
                h.global.push(ghosts.data[i] >> 8);
                h.classes.push(ghosts.data[i] as u8);
            }
        }
        if ghosts.before == ghosts.leaves.len() {
            h.before = h.leaves.len();
        }
        h
    }

    /// The local `elements` between the halo elements of lower and of
    /// higher ranks: the run the dual walks go over.
    pub(crate) fn around<'a>(&'a self, elements: &'a [Octant]) -> Merged<'a> {
        Merged {
            before: &self.leaves[..self.before],
            local: elements,
            after: &self.leaves[self.before..],
        }
    }

    /// Number of halo elements.
    pub fn len(&self) -> usize {
        self.leaves.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.leaves.is_empty()
    }
}

/// Send and receive lists of a cell-centred halo exchange with each
/// neighbour rank: the local elements sharing a face with the rank's
/// elements, and those elements (as [`Halo`] indices), both sorted by
/// global element number, so both sides list the same elements in the same
/// order.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct CellHalo {
    /// Neighbour ranks, increasing.
    pub ranks: Vec<u32>,
    /// Per neighbour rank, the local elements to send.
    pub send: Vec<Vec<u32>>,
    /// Per neighbour rank, the halo elements received (indices into
    /// [`Halo`]).
    pub recv: Vec<Vec<u32>>,
}

/// The faces of one rank's part of the mesh. See the module documentation.
#[derive(Clone, Debug)]
pub struct Faces {
    faces: Vec<Face>,
    num_internal: usize,
    /// Start of each patch's boundary faces, and the end of the last.
    patch_start: Vec<usize>,
    /// Halo faces per neighbour rank.
    halo_ranges: Vec<(u32, Range<usize>)>,
}

impl Default for Faces {
    fn default() -> Faces {
        Faces {
            faces: Vec::new(),
            num_internal: 0,
            patch_start: vec![0; NUM_PATCHES + 1],
            halo_ranges: Vec::new(),
        }
    }
}

impl Faces {
    /// Every face: internal, boundary by patch, halo by rank.
    pub fn faces(&self) -> &[Face] {
        &self.faces
    }

    /// Number of internal faces (the first ones).
    pub fn num_internal(&self) -> usize {
        self.num_internal
    }

    /// Number of patches: the six sides, then the surface's (one, or one
    /// per part after [`Faces::split_surface`]).
    pub fn num_patches(&self) -> usize {
        self.patch_start.len().saturating_sub(1)
    }

    /// Splits the surface patch into `n` patches, ids `SURFACE_PATCH ..
    /// SURFACE_PATCH + n`: `part(face)` (below `n`) gives each surface
    /// face's. Each new patch keeps the faces in element order.
    pub fn split_surface(&mut self, n: usize, mut part: impl FnMut(&Face) -> u16) {
        let s = SURFACE_PATCH as usize;
        if n < 2 || self.num_patches() != NUM_PATCHES {
            return;
        }
        let range = self.patch_range(s);
        let mut counts = vec![0usize; n];
        let surface = &mut self.faces[range.clone()];
        for f in surface.iter_mut() {
            let p = part(f).min(n as u16 - 1);
            counts[p as usize] += 1;
            f.other = Other::Patch(SURFACE_PATCH + p).encode();
        }
        surface.sort_by_key(|f| f.other());
        self.patch_start.truncate(s + 1);
        for c in counts {
            let last = self.patch_start[self.patch_start.len() - 1];
            self.patch_start.push(last + c);
        }
        debug_assert_eq!(self.patch_start[self.patch_start.len() - 1], range.end);
    }

    /// The boundary faces of patch `p` (a range of [`Faces::faces`]).
    pub fn patch_range(&self, p: usize) -> Range<usize> {
        self.patch_start[p]..self.patch_start[p + 1]
    }

    /// The halo faces per neighbour rank (ranks increasing).
    pub fn halo_ranges(&self) -> &[(u32, Range<usize>)] {
        &self.halo_ranges
    }

    /// The halo faces: from the end of the boundary faces to the end.
    pub fn halo_range(&self) -> Range<usize> {
        self.patch_start[self.patch_start.len() - 1]..self.faces.len()
    }
}

impl Mesh {
    /// The send and receive lists of a cell-centred halo exchange, from
    /// `faces` (this mesh's [`Mesh::faces`]).
    pub fn cell_halo(&self, faces: &Faces) -> CellHalo {
        let mut out = CellHalo::default();
        for (r, range) in faces.halo_ranges() {
            let mut send: Vec<u32> = Vec::new();
            let mut recv: Vec<u32> = Vec::new();
            for f in &faces.faces()[range.clone()] {
                send.push(f.owner());
                if let Other::Halo(h) = f.other() {
                    recv.push(h);
                }
            }
            send.sort_unstable();
            send.dedup();
            recv.sort_unstable_by_key(|&h| self.halo.global[h as usize]);
            recv.dedup();
            out.ranks.push(*r);
            out.send.push(send);
            out.recv.push(recv);
        }
        out
    }

    /// Global number of local element `i`: local elements are numbered
    /// contiguously per rank, in rank order.
    pub fn global_element(&self, i: usize) -> u64 {
        self.first_element + i as u64
    }

    /// Global number of local element 0.
    pub fn first_element(&self) -> u64 {
        self.first_element
    }

    /// The kept elements of other ranks touching local ones.
    pub fn halo(&self) -> &Halo {
        &self.halo
    }

    /// The global element number across face `f` (`None` on a boundary).
    pub fn other_global(&self, f: &Face) -> Option<u64> {
        match f.other() {
            Other::Element(j) => Some(self.global_element(j as usize)),
            Other::Halo(h) => Some(self.halo.global[h as usize]),
            Other::Patch(_) => None,
        }
    }

    /// Centre of local element `i`, user units.
    pub fn element_centre(&self, i: usize) -> [f64; 3] {
        let e = self.elements[i];
        let (c, h) = (e.coords(), e.side() as f64 / 2.0);
        self.domain
            .from_lattice([c[0] as f64 + h, c[1] as f64 + h, c[2] as f64 + h])
    }

    /// Volume of local element `i`, user units.
    pub fn element_volume(&self, i: usize) -> f64 {
        self.cells_to_volume((self.elements[i].side() as u64).pow(3))
    }

    /// Area of face `f`, user units.
    pub fn face_area(&self, f: &Face) -> f64 {
        let h = 1.0 / self.domain.scale();
        f.lattice_area() * h * h
    }

    /// Centre of face `f`, user units.
    pub fn face_centre(&self, f: &Face) -> [f64; 3] {
        self.domain.from_lattice(f.lattice_centre())
    }
}

#[cfg(test)]
mod tests {
    use super::walk::{dropped_pieces, element_face};
    use super::*;

    #[test]
    fn pages_made_by_a_second_thread_leave_the_same_faces() {
        let mesh = crate::testutil::sphere_mesh(6);
        let (one, two) = (
            mesh.faces_with(false).unwrap(),
            mesh.faces_with(true).unwrap(),
        );
        assert!(one.faces().len() >= 3 * mesh.elements().len());
        assert_eq!(one.faces(), two.faces());
        assert_eq!(
            (one.num_internal(), &one.patch_start),
            (two.num_internal(), &two.patch_start)
        );
    }

    /// A packed shape's corners in halves.
    fn unpack(shape: u16) -> [(u8, u8); 4] {
        std::array::from_fn(|k| {
            let w = shape >> (4 * k) & 15;
            ((w & 3) as u8, (w >> 2) as u8)
        })
    }

    #[test]
    fn pieces_cover_the_dropped_quarters() {
        for kept in 1u8..15 {
            let (places, n) = dropped_pieces(kept);
            let pieces: Vec<[(u8, u8); 4]> = places[..n]
                .iter()
                .map(|&i| unpack(SHAPES[i as usize]))
                .collect();
            let area: i32 = pieces.iter().map(|p| twice_area(p).abs()).sum();
            let dropped = 4 - kept.count_ones() as i32;
            assert_eq!(area, 2 * dropped, "kept {kept:04b}");
            // No piece covers a kept quarter's centre.
            for p in &pieces {
                for q in 0..4u8 {
                    if kept & (1 << q) != 0 {
                        let c = ((q & 1) as f64 + 0.5, (q >> 1) as f64 + 0.5);
                        assert!(!inside(p, c), "kept {kept:04b} piece {p:?}");
                    }
                }
            }
        }
    }

    fn inside(p: &[(u8, u8); 4], c: (f64, f64)) -> bool {
        let mut sign = 0.0f64;
        for k in 0..4 {
            let (a, b) = (p[k].0 as f64, p[k].1 as f64);
            let (x, y) = (p[(k + 1) % 4].0 as f64, p[(k + 1) % 4].1 as f64);
            let cross = (x - a) * (c.1 - b) - (y - b) * (c.0 - a);
            if cross != 0.0 {
                if sign != 0.0 && cross.signum() != sign {
                    return false;
                }
                sign = cross.signum();
            }
        }
        true
    }

    #[test]
    fn a_face_keeps_its_parts_in_sixteen_bytes() {
        assert_eq!(std::mem::size_of::<Face>(), 16);
        for o in [
            Other::Element(0),
            Other::Element(HALO_BASE - 1),
            Other::Halo(0),
            Other::Halo(HALO_BASE - MAX_PATCHES - 1),
            Other::Patch(0),
            Other::Patch(u16::MAX),
        ] {
            assert_eq!(Other::decode(o.encode()), o);
        }
        // Every octant level, both sides, every shape.
        let mut x = 99u64;
        for level in 0..=crate::octree::octant::MAX_LEVEL {
            for _ in 0..50 {
                x = x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
                let side = crate::octree::octant::ROOT_LEN >> level;
                let c = [x >> 7, x >> 27, x >> 47].map(|v| v as u32 % (1 << level) * side);
                let e = Octant::new(c[0], c[1], c[2], level).unwrap();
                let (axis, plus) = ((x >> 3) as usize % 3, x & 1 == 1);
                let place = (x >> 11) as usize % SHAPES.len();
                let (shape, f) = (
                    SHAPES[place],
                    element_face(7, e, axis, plus, place as u8, Other::Halo(5)),
                );
                let mut origin = c;
                if plus {
                    origin[axis] += side;
                }
                assert_eq!((f.origin(), f.half(), f.shape()), (origin, side / 2, shape));
                assert_eq!((f.axis(), f.negative(), f.owner()), (axis, !plus, 7));
                assert_eq!(f.other(), Other::Halo(5));
            }
        }
    }

    #[test]
    fn every_boundary_piece_is_a_known_shape() {
        for kept in 0..16u8 {
            let (places, n) = dropped_pieces(kept);
            for &piece in &places[..n] {
                assert!((piece as usize) < SHAPES.len(), "{kept:04b}: {piece}");
            }
        }
        // The shapes are distinct, counter-clockwise, and pack as stored.
        for (i, &s) in SHAPES.iter().enumerate() {
            assert!(twice_area(&unpack(s)) > 0, "shape {i}");
            assert_eq!(pack(unpack(s)), s, "shape {i}");
            assert!(!SHAPES[..i].contains(&s), "shape {i} twice");
        }
    }

    #[test]
    fn corners_follow_the_normal() {
        for normal in 0..6u8 {
            let axis = normal / 2;
            // The low face of the element of side 4 at (4, 4, 4), its
            // normal either way.
            let e = Octant::new(4, 4, 4, crate::octree::octant::MAX_LEVEL - 1).unwrap();
            let mut f = element_face(0, e, axis as usize, false, WHOLE_SHAPE, Other::Patch(0));
            if normal % 2 == 0 {
                f = f.flipped(0, Other::Patch(0));
            }
            assert_eq!((f.origin(), f.half()), ([4, 4, 4], 2));
            let c = f.corners();
            for plus in [false, true] {
                let mut g = element_face(0, e, axis as usize, plus, WHOLE_SHAPE, Other::Patch(0));
                if normal % 2 == 0 {
                    g = g.flipped(0, Other::Patch(0));
                }
                let m = g.whole_corner_octants().expect("a whole face");
                let at = |m| crate::mesh::dual::corner_coords(e.coords(), e.side(), m);
                assert_eq!(m.map(at), g.corners(), "normal {normal} plus {plus}");
            }
            let d = |a: [u32; 3], b: [u32; 3]| [0, 1, 2].map(|k| b[k] as f64 - a[k] as f64);
            let (p, q) = (d(c[0], c[1]), d(c[0], c[2]));
            let cross = [
                p[1] * q[2] - p[2] * q[1],
                p[2] * q[0] - p[0] * q[2],
                p[0] * q[1] - p[1] * q[0],
            ];
            let n = f.unit_normal();
            let dot: f64 = (0..3).map(|k| cross[k] * n[k]).sum();
            assert!(dot > 0.0, "normal {normal}: {c:?}");
            assert_eq!(f.lattice_area(), 16.0);
            assert_eq!(f.lattice_centre(), {
                let mut m = [4.0; 3];
                let (u, v) = plane_axes(axis as usize);
                m[u] = 6.0;
                m[v] = 6.0;
                m
            });
        }
    }
}
