//! How the faces are found: a walk over the dual tree for the faces
//! between local elements, the halo's faces by the local side, and the
//! boundary pieces each kept element leaves uncovered.

use crate::error::{Error, ErrorKind, Result};
use crate::mesh::dual::{walk_faces, FaceVisitor, Merged, FAMILY_FACES};
use crate::mesh::Mesh;
use crate::octree::octant::{Octant, LATTICE_BITS};

use super::*;

/// Which list a face emitted by [`Mesh::for_each_face`] belongs to.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(in crate::mesh) enum FaceKind {
    /// Between two local elements.
    Internal,
    /// On a patch.
    Boundary,
    /// Between a local element and another rank's.
    Halo,
}

/// What [`Mesh::walk_faces`] reports.
enum Found {
    /// Two local elements sharing the whole high face of `low` (the same
    /// size as `high` or finer), normal to `axis`.
    Pair { axis: usize, low: u32, high: u32 },
    /// Two local elements sharing the whole low face of `high`, normal to
    /// `axis`: quarter `q` (see [`Mesh::walk_faces`]) of the coarser
    /// `low`'s high face.
    Quarter {
        axis: usize,
        low: u32,
        high: u32,
        q: u8,
    },
    /// The local elements `i..i + 8` are the children of one parent: the
    /// twelve faces between them, each a `Pair`.
    Family(u32),
    /// A face between a local and a halo element, by the local side.
    Halo(Face),
}

/// Where a kept element is: local index or halo index.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(in crate::mesh) enum At {
    Local(u32),
    Halo(u32),
}

/// The kept elements around this rank: halo before, local, halo after, all
/// in Morton order.
pub(in crate::mesh) struct Kept<'a> {
    pub(in crate::mesh) local: &'a [Octant],
    pub(in crate::mesh) halo: &'a Halo,
}

impl<'a> Kept<'a> {
    /// The kept elements of a mesh: `local`, then its `halo`.
    pub(in crate::mesh) fn new(local: &'a [Octant], halo: &'a Halo) -> Kept<'a> {
        Kept { local, halo }
    }

    /// The last kept element starting at or before finest cell `c` (a
    /// Morton cell index).
    fn last_at_or_before_cell(&self, c: u64, hint: usize) -> Option<(At, Octant)> {
        let before = &self.halo.leaves[..self.halo.before];
        let after = &self.halo.leaves[self.halo.before..];
        let find = |s: &[Octant]| s.partition_point(|l| l.cell_begin() <= c).checked_sub(1);
        if after.first().is_some_and(|a| a.cell_begin() <= c) {
            let k = self.halo.before + find(after)?;
            return Some((At::Halo(k as u32), self.halo.leaves[k]));
        }
        let local = self.local;
        if let Some(j) =
            crate::octree::sort::gallop_last_le(local.len(), hint, c, |k| local[k].cell_begin())
        {
            return Some((At::Local(j as u32), local[j]));
        }
        find(before).map(|j| (At::Halo(j as u32), before[j]))
    }

    /// Whether a halo element holds finest cell `c`, searched from the
    /// halo leaf `hint` (left at the answer's place: look-ups in Morton
    /// order stay short).
    pub(in crate::mesh) fn halo_holds(&self, c: u64, hint: &std::cell::Cell<usize>) -> bool {
        // The halo's leaves are in Morton order (those before the local
        // ones, then those after).
        let h = &self.halo.leaves;
        match crate::octree::sort::gallop_last_le(h.len(), hint.get(), c, |k| h[k].cell_begin()) {
            Some(k) => {
                hint.set(k);
                c < h[k].cell_end()
            }
            None => false,
        }
    }

    /// The kept element holding finest cell `c`, if one does.
    pub(in crate::mesh) fn holding_cell(&self, c: u64, hint: usize) -> Option<(At, Octant)> {
        self.last_at_or_before_cell(c, hint)
            .filter(|(_, l)| c < l.cell_end())
    }
}

fn other_of(a: At) -> Other {
    match a {
        At::Local(j) => Other::Element(j),
        At::Halo(j) => Other::Halo(j),
    }
}

/// The boundary pieces of a face whose fine neighbours `kept` (bit `2b + a`
/// for the quarter at `(a, b)` in halves) are partly kept: the dropped
/// quarters' union as quadrilaterals with corners on kept corners, as
/// places in [`SHAPES`] (the first `n` of the array).
pub(super) fn dropped_pieces(kept: u8) -> ([u8; 2], usize) {
    let dropped = !kept & 15;
    match dropped.count_ones() {
        1 => ([1 + dropped.trailing_zeros() as u8, 0], 1),
        2 => match dropped {
            // One column (`a` the same) or one row: a half face.
            0b0101 => ([5, 0], 1),
            0b1010 => ([6, 0], 1),
            0b0011 => ([7, 0], 1),
            0b1100 => ([8, 0], 1),
            // Two opposite quarters.
            _ => {
                let (p, q) = (dropped.trailing_zeros(), 7 - dropped.leading_zeros());
                ([1 + p as u8, 1 + q as u8], 2)
            }
        },
        3 => {
            let q = kept.trailing_zeros() as u8;
            ([9 + 2 * q, 10 + 2 * q], 2)
        }
        _ => ([0, 0], 0),
    }
}

/// The face of element `e` (local index `i`, the owner) on side `plus` of
/// `axis`, of shape `shape` (a place in [`SHAPES`]) in halves of that face.
pub(super) fn element_face(
    i: u32,
    e: Octant,
    axis: usize,
    plus: bool,
    shape: u8,
    other: Other,
) -> Face {
    let level = e.level() as u32;
    let loc = 1 << (3 * level) | e.morton() >> (3 * (LATTICE_BITS - level));
    Face {
        owner: i,
        other: other.encode(),
        code: shape as u64
            | (axis as u64) << 5
            | (!plus as u64) << 7
            | (plus as u64) << 8
            | loc << 9,
    }
}

/// The visitor of [`Mesh::walk_faces`]'s dual walk.
struct Visitor<'a, F> {
    merged: Merged<'a>,
    /// Halo elements before the local ones.
    hb: usize,
    /// Local elements.
    nl: usize,
    /// See [`Mesh::walk_faces`].
    covered: &'a mut [u32],
    found: &'a mut F,
}

/// Per child of a family, the faces it shares with its siblings
/// ([`FAMILY_FACES`]), as bits of `covered` (see [`Mesh::walk_faces`]).
const FAMILY_COVERED: [u32; 8] = {
    let mut m = [0; 8];
    let mut k = 0;
    while k < FAMILY_FACES.len() {
        let (a, low, high) = FAMILY_FACES[k];
        m[low] |= 15 << (4 * (2 * a + 1));
        m[high] |= 15 << (4 * (2 * a));
        k += 1;
    }
    m
};

impl<F: FnMut(Found)> Visitor<'_, F> {
    /// The kept element at merged index `k`.
    #[inline]
    fn at(&self, k: usize) -> At {
        if k < self.hb {
            At::Halo(k as u32)
        } else if k < self.hb + self.nl {
            At::Local((k - self.hb) as u32)
        } else {
            At::Halo((k - self.nl) as u32)
        }
    }
}

impl<F: FnMut(Found)> FaceVisitor for Visitor<'_, F> {
    /// A family of local elements; one with a halo child goes pair by
    /// pair.
    #[inline]
    fn family(&mut self, b: usize) -> bool {
        if b < self.hb || b - self.hb + 8 > self.nl {
            return false;
        }
        let i = b - self.hb;
        for (c, m) in FAMILY_COVERED.iter().enumerate() {
            self.covered[i + c] |= m;
        }
        (self.found)(Found::Family(i as u32));
        true
    }

    #[inline(always)]
    fn pair(&mut self, axis: usize, low: usize, high: usize) {
        // Most pairs: two local elements of the same size.
        let (i, j) = (low.wrapping_sub(self.hb), high.wrapping_sub(self.hb));
        if i < self.nl
            && j < self.nl
            && self.merged.local[i].level() == self.merged.local[j].level()
        {
            self.covered[i] |= 15 << (4 * (2 * axis + 1));
            self.covered[j] |= 15 << (4 * (2 * axis));
            (self.found)(Found::Pair {
                axis,
                low: i as u32,
                high: j as u32,
            });
            return;
        }
        self.any_pair(axis, low, high);
    }
}

impl<F: FnMut(Found)> Visitor<'_, F> {
    /// [`FaceVisitor::pair`] for any two kept elements.
    #[inline(never)]
    fn any_pair(&mut self, axis: usize, low: usize, high: usize) {
        let (face, whole) = (element_face, WHOLE_SHAPE);
        let (a, b) = (self.at(low), self.at(high));
        let (la, lb) = (self.merged.get(low), self.merged.get(high));
        // `fine` (local or not) against the coarser `coarse`: which
        // quarter of the coarse face the fine one is, from the fine
        // octant's place among its siblings.
        let mut finer = |fine: At, lf: Octant, coarse: At, lc: Octant, fine_low: bool| {
            let (u, v) = plane_axes(axis);
            let id = lf.child_id();
            let q = (id >> u & 1) | (id >> v & 1) << 1;
            if let At::Local(c) = coarse {
                self.covered[c as usize] |= 1 << (4 * (2 * axis + !fine_low as usize) + q as usize);
            }
            match (fine, coarse) {
                (At::Local(i), At::Local(c)) => {
                    self.covered[i as usize] |= 15 << (4 * (2 * axis + fine_low as usize));
                    (self.found)(if fine_low {
                        Found::Pair {
                            axis,
                            low: i,
                            high: c,
                        }
                    } else {
                        Found::Quarter {
                            axis,
                            low: c,
                            high: i,
                            q: q as u8,
                        }
                    });
                }
                (At::Local(i), At::Halo(_)) => {
                    self.covered[i as usize] |= 15 << (4 * (2 * axis + fine_low as usize));
                    let f = face(i, lf, axis, fine_low, whole, other_of(coarse));
                    (self.found)(Found::Halo(f));
                }
                (At::Halo(_), At::Local(c)) => {
                    let f = face(c, lc, axis, !fine_low, 1 + q as u8, other_of(fine));
                    (self.found)(Found::Halo(f));
                }
                _ => {}
            }
        };
        if la.level() > lb.level() {
            finer(a, la, b, lb, true);
        } else if lb.level() > la.level() {
            finer(b, lb, a, la, false);
        } else {
            if let At::Local(i) = a {
                self.covered[i as usize] |= 15 << (4 * (2 * axis + 1));
            }
            if let At::Local(j) = b {
                self.covered[j as usize] |= 15 << (4 * (2 * axis));
            }
            match (a, b) {
                (At::Local(i), At::Local(j)) => {
                    // The low element comes first in Morton order.
                    debug_assert!(i < j);
                    (self.found)(Found::Pair {
                        axis,
                        low: i,
                        high: j,
                    });
                }
                (At::Local(i), At::Halo(_)) => {
                    let f = face(i, la, axis, true, whole, other_of(b));
                    (self.found)(Found::Halo(f));
                }
                (At::Halo(_), At::Local(j)) => {
                    let f = face(j, lb, axis, false, whole, other_of(a));
                    (self.found)(Found::Halo(f));
                }
                _ => {}
            }
        }
    }
}

impl Mesh {
    /// Extracts this rank's faces (see [`crate::mesh::faces`]). Local work
    /// only: the halo came with the mesh.
    pub fn faces(&self) -> Result<Faces> {
        self.faces_with(false)
    }

    /// [`Mesh::faces`]; with `spare_core` (see [`crate::parallel::cores::spare_core`]),
    /// a second thread has the kernel make the pages of the face list and
    /// of the scratch arrays while this one walks (the same faces).
    pub fn faces_with(&self, spare_core: bool) -> Result<Faces> {
        let elements: &[Octant] = &self.elements;
        let nl = elements.len();
        // Element numbers and the quarters' groups (at most three per
        // element) below `FINE`.
        if nl >= (FINE / 3) as usize {
            return Err(Error::new(ErrorKind::Limit, "too many local elements"));
        }
        // An internal face's owner, the lower of its two elements, is the
        // one on its low side: two octants sharing a face part in their
        // least common ancestor's children that differ in the normal's bit
        // alone, the low one first in Morton order. So element `i` owns
        // the faces on its three high sides, and they are listed in owner
        // order from what the walk finds per element, with no sort of the
        // faces:
        //
        //   - `whole[3 i + a]`: 1 + the element across the whole high face
        //     `a` of `i` (the same size or coarser), or `FINE | g` when
        //     finer elements are across it, 0 when there is none;
        //   - `quarters[4 g + q]`: the element across quarter `q` of that
        //     face, `u32::MAX` when none (a quarter is listed as the finer
        //     element's face).
        //
        // The list comes first in the heap, so that the scratch arrays,
        // freed at the end, leave their room for what comes next rather
        // than holes under it. Room never written costs no memory.
        let mut faces: Vec<Face> = Vec::with_capacity(4 * nl);
        let mut whole = vec![0u32; 3 * nl];
        let mut quarters: Vec<u32> = Vec::new();
        let mut halo: Vec<Face> = Vec::new();
        let mut covered = vec![0u32; nl];
        // Every element has six faces or more, each shared by two at most:
        // the list holds `3 nl` faces at least.
        let fresh = [
            crate::parallel::cores::bytes_of(&covered),
            crate::parallel::cores::bytes_of(&whole),
            (
                faces.as_ptr() as usize,
                3 * nl * std::mem::size_of::<Face>(),
            ),
        ];
        // Boundary faces per patch, counted as the internal ones are
        // listed (the walk has marked every element's covered quarters).
        let mut per_patch = [0usize; NUM_PATCHES];
        crate::parallel::cores::with_pages_made(spare_core, &fresh, || {
            self.walk_faces(&mut covered, |found| match found {
                Found::Pair { axis, low, high } => whole[3 * low as usize + axis] = high + 1,
                Found::Quarter { axis, low, high, q } => {
                    let w = &mut whole[3 * low as usize + axis];
                    if *w == 0 {
                        *w = FINE | (quarters.len() / 4) as u32;
                        quarters.extend([u32::MAX; 4]);
                    }
                    quarters[4 * (*w & !FINE) as usize + q as usize] = high;
                }
                Found::Family(i) => {
                    for (a, low, high) in FAMILY_FACES {
                        whole[3 * (i as usize + low) + a] = i + high as u32 + 1;
                    }
                }
                Found::Halo(face) => halo.push(face),
            });
            let full = WHOLE_SHAPE;
            for (i, &e) in elements.iter().enumerate() {
                let first = faces.len();
                for a in 0..3 {
                    let w = whole[3 * i + a];
                    if w & FINE != 0 {
                        let g = 4 * (w & !FINE) as usize;
                        for &j in quarters[g..g + 4].iter().filter(|&&j| j != u32::MAX) {
                            let f = elements[j as usize];
                            let face = element_face(j, f, a, false, full, Other::Element(i as u32));
                            faces.push(face.flipped(i as u32, Other::Element(j)));
                        }
                    } else if w != 0 {
                        faces.push(element_face(
                            i as u32,
                            e,
                            a,
                            true,
                            full,
                            Other::Element(w - 1),
                        ));
                    }
                }
                // Each owner's few faces (at most twelve) by the other
                // element: insertion.
                let own = &mut faces[first..];
                for k in 1..own.len() {
                    let mut m = k;
                    while m > 0 && own[m].other < own[m - 1].other {
                        own.swap(m, m - 1);
                        m -= 1;
                    }
                }
                self.element_boundary(i as u32, e, covered[i], |_, p| per_patch[p as usize] += 1);
            }
        });
        drop(whole);
        drop(quarters);
        // The boundary faces, grouped by patch: written in place behind the
        // internal ones (no list of their own to grow, sort and copy).
        let num_internal = faces.len();
        let mut patch_start = vec![num_internal; NUM_PATCHES + 1];
        for p in 0..NUM_PATCHES {
            patch_start[p + 1] = patch_start[p] + per_patch[p];
        }
        let num_boundary = patch_start[NUM_PATCHES] - num_internal;
        faces.reserve_exact(num_boundary + halo.len());
        let room = &mut faces.spare_capacity_mut()[..num_boundary];
        crate::parallel::cores::make_pages(&[crate::parallel::cores::bytes_of(room)]);
        let mut next: Vec<usize> = patch_start.iter().map(|s| s - num_internal).collect();
        self.boundary_pieces(&covered, |f, p| {
            room[next[p as usize]].write(f);
            next[p as usize] += 1;
        });
        drop(covered);
        if (0..NUM_PATCHES).any(|p| num_internal + next[p] != patch_start[p + 1]) {
            return Err(Error::new(
                ErrorKind::Internal,
                "the boundary faces differ from their count",
            ));
        }
        // SAFETY: the pieces counted per patch were each written once, at
        // their patch's places: every place of `room` holds a face.
        unsafe { faces.set_len(num_internal + num_boundary) };
        let me = self.rank as u32;
        let first = self.first_element;
        let key = |f: &Face| -> (u32, u64, u64) {
            let Other::Halo(h) = f.other() else {
                return (u32::MAX, 0, 0);
            };
            let (r, g) = (self.halo.owners[h as usize], self.halo.global[h as usize]);
            let mine = first + f.owner as u64;
            if me < r {
                (r, mine, g)
            } else {
                (r, g, mine)
            }
        };
        halo.sort_unstable_by_key(key);
        let mut halo_ranges = Vec::new();
        let base = num_internal + num_boundary;
        let mut a = 0;
        while a < halo.len() {
            let r = key(&halo[a]).0;
            let b = a + halo[a..].partition_point(|f| key(f).0 == r);
            halo_ranges.push((r, base + a..base + b));
            a = b;
        }
        faces.append(&mut halo);
        Ok(Faces {
            faces,
            num_internal,
            patch_start,
            halo_ranges,
        })
    }

    /// Emits every face of [`Mesh::faces`] once, with its kind, to `put`,
    /// before sorting: each internal face by the finer side or, between two
    /// equal elements, by the lower one (not yet oriented from the lower
    /// element), a halo face by the local side, then the boundary faces in
    /// element order, then face, then piece. One dual walk of the local and
    /// halo elements ([`walk_faces`]) meets every pair of kept elements
    /// sharing a face once, at the finer face, with no search, and marks the
    /// quarters of each element face that face a kept element; the faces'
    /// unmarked parts are the boundary: a side patch outside the domain,
    /// else the surface, a coarse face partly covered by finer kept
    /// elements in the pieces of [`dropped_pieces`].
    pub(in crate::mesh) fn for_each_face(&self, mut put: impl FnMut(FaceKind, Face)) {
        let elements: &[Octant] = &self.elements;
        let whole = WHOLE_SHAPE;
        let mut covered = vec![0u32; self.elements.len()];
        self.walk_faces(&mut covered, |found| match found {
            Found::Pair { axis, low, high } => {
                let e = elements[low as usize];
                let f = element_face(low, e, axis, true, whole, Other::Element(high));
                put(FaceKind::Internal, f);
            }
            Found::Quarter {
                axis, low, high, ..
            } => {
                let e = elements[high as usize];
                let f = element_face(high, e, axis, false, whole, Other::Element(low));
                put(FaceKind::Internal, f);
            }
            Found::Family(i) => {
                for (a, low, high) in FAMILY_FACES {
                    let (low, high) = (i + low as u32, i + high as u32);
                    let e = elements[low as usize];
                    let f = element_face(low, e, a, true, whole, Other::Element(high));
                    put(FaceKind::Internal, f);
                }
            }
            Found::Halo(f) => put(FaceKind::Halo, f),
        });
        self.boundary_pieces(&covered, |f, _| put(FaceKind::Boundary, f));
    }

    /// The walk behind [`Mesh::for_each_face`] and [`Mesh::faces`]: one
    /// dual walk of the local and halo elements ([`walk_faces`]) reports
    /// each pair of local elements sharing a face, and each halo face by
    /// the local side. Sets, per element of `covered` (all 0 before), bit
    /// `4 f + q` when quarter `q` of its face `f` faces a kept element (see
    /// [`Mesh::boundary_pieces`]).
    fn walk_faces(&self, covered: &mut [u32], mut found: impl FnMut(Found)) {
        let elements: &[Octant] = &self.elements;
        let (nl, hb) = (elements.len(), self.halo.before);
        let mut visitor = Visitor {
            merged: self.halo.around(elements),
            hb,
            nl,
            covered,
            found: &mut found,
        };
        walk_faces(&self.dual_tree, &mut visitor);
    }

    /// The boundary faces, from the walk's `covered` bits, in element
    /// order, then face, then piece: `put(face, patch)`. A face's
    /// unmarked parts are the boundary: a side patch outside the domain,
    /// else the surface, a coarse face partly covered by finer kept
    /// elements in the pieces of [`dropped_pieces`].
    #[inline(always)]
    fn boundary_pieces(&self, covered: &[u32], mut put: impl FnMut(Face, u16)) {
        for (i, (&e, &cov)) in self.elements.iter().zip(covered).enumerate() {
            self.element_boundary(i as u32, e, cov, &mut put);
        }
    }

    /// The boundary faces of element `i` (octant `e`, `covered` bits
    /// `cov`), as [`Mesh::boundary_pieces`] lists them.
    #[inline(always)]
    fn element_boundary(&self, i: u32, e: Octant, cov: u32, mut put: impl FnMut(Face, u16)) {
        if cov == ALL_COVERED {
            return;
        }
        let outside = self.domain.brick.outside_faces(e);
        for f in 0..6 {
            let (axis, plus) = (f / 2, f % 2 == 1);
            let mask = (cov >> (4 * f) & 15) as u8;
            let mut side = |shape: u8, patch: u16| {
                let face = element_face(i, e, axis, plus, shape, Other::Patch(patch));
                put(face, patch);
            };
            if outside >> f & 1 == 1 {
                // Outside the cube or a brick's box: a side patch.
                side(WHOLE_SHAPE, f as u16);
            } else if mask == 0 {
                side(WHOLE_SHAPE, SURFACE_PATCH);
            } else {
                let (shapes, n) = dropped_pieces(mask);
                for &shape in &shapes[..n] {
                    side(shape, SURFACE_PATCH);
                }
            }
        }
    }
}
