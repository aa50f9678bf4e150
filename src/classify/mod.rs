//! Inside/outside classification of leaves against a surface.
//!
//! Every leaf gets a class byte made of two bits:
//!
//! * [`CUT`]: the leaf's *closed* box touches some triangle, by exactly the
//!   rule refinement uses ([`triangle_box_overlap`](crate::geometry::intersect::triangle_box_overlap) on closed sets, as
//!   [`SurfaceIndex::touches`]); contact at a face, edge or corner counts.
//! * [`CENTER_INSIDE`]: the leaf's centre lies inside the surface, decided
//!   by an [`InsideRule`]: the parity of the number of surface crossings
//!   along a segment from a point known to be outside, or the generalized
//!   winding number above 1/2 (see "Winding number" below).
//!
//! [`LeafClass`] names the three combinations that matter, and [`keeps`]
//! turns the bits into the decision "is this element in the mesh" for a
//! [`Keep`] mode and a [`CutRule`] (default [`CutRule::Center`], under which
//! keeping the inside and keeping the outside partition the leaves exactly).
//!
//! # Parity, top-down
//!
//! The root's centre is classified once with a segment to a point beyond the
//! surface's bounding box, over all triangles. Below that, for every octant
//! on the way down to the leaves,
//!
//! ```text
//! inside(child centre) = inside(parent centre) XOR (segment parent centre -> child centre
//!                                                   crosses the surface an odd number of times)
//! ```
//!
//! The parent's centre is a corner of each child, so that segment lies in the
//! closed child box and only triangles near the child can cross it. The
//! candidate triangles are passed down as in refinement (each child filters
//! its parent's list), and an octant with no candidate hands its parity to all
//! its descendants without a single test: the cost sits near the surface.
//! Only the ancestors of the given leaves are visited. A leaf's bits depend
//! on the leaf and the surface alone, never on the other leaves of the slice,
//! so any split of the leaves over ranks gives the same bytes.
//!
//! # Exact predicates and the tie rule
//!
//! Triangle vertices (lattice units) are rounded once to fixed-point
//! integers `x * 2^k`, with `k <= 20` chosen so that every coordinate stays
//! within `2^39`; octant centres are integers on the lattice, hence exact.
//! Rounding moves vertices, but identical vertices move identically, so a
//! closed surface stays closed, and the parity is taken against this rounded
//! surface. Orientations are exact `i128` determinants (differences below
//! `2^41` keep every determinant below `2^126`).
//!
//! Centres exactly on the surface, segments through an edge or a vertex, and
//! axis-aligned faces (plates and boxes on octant boundaries are common) are
//! resolved by *simulation of simplicity* with one shared perturbation: every
//! query point is translated by the infinitesimal vector `(e, e^2, e^3)`,
//! `e -> 0+`. Both predicates are linear in that translation, so a zero
//! determinant is replaced by the sign of the first non-zero coefficient:
//!
//! * plane side, `orient(a, b, c, x + t) = orient(a, b, c, x) + n . t` with
//!   `n = (b - a) x (c - a)`: on a tie, the sign of the first non-zero of
//!   `n_x, n_y, n_z` (never all zero for a triangle of positive area);
//! * edge side, `orient(p + t, q + t, a, b) = orient(p, q, a, b) + t . ((a - b) x (q - p))`:
//!   on a tie, the first non-zero component of `(a - b) x (q - p)`. It is
//!   only needed once the segment is known to cross the triangle's plane,
//!   which rules out an edge parallel to the segment, so it is never zero.
//!
//! Segment `pq` crosses triangle `abc` iff `p` and `q` are on opposite sides
//! of its plane and `orient(p, q, a, b)`, `orient(p, q, b, c)` and
//! `orient(p, q, c, a)` have the same sign. Because the perturbed answers are
//! those of a real configuration (the surface against slightly translated
//! points) in which no segment meets an edge or a vertex, a segment through
//! a shared edge or vertex is counted exactly as often as the translated
//! segment crosses the surface, which keeps the parity right for any closed
//! surface, of any genus and either orientation. (Ties cannot simply be read
//! as "positive": the two triangles sharing an edge see it in opposite
//! directions, so both or neither would count it.) Triangles of zero area
//! after rounding are skipped: a segment in general position cannot cross
//! them.
//!
//! # Box tests
//!
//! An octant on the way down tests each of its candidate triangles against
//! its eight children at once, on the 13 separating axes of
//! [`triangle_box_overlap`](crate::geometry::intersect::triangle_box_overlap). The three box normals compare raw coordinates,
//! as `triangle_box_overlap` does; on the other ten a verdict is taken only
//! when the floating-point gap exceeds a bound on the rounding error of both
//! computations, and the few cases within the bound (exact contacts of
//! lattice-aligned surfaces, mostly) go to `triangle_box_overlap` itself, so
//! [`CUT`] is refinement's rule bit for bit. A child's candidates are the
//! triangles that may touch its box grown by four fixed-point units, more than
//! the rounding of the vertices, so they include every rounded triangle that
//! can cross a segment in the child. A floating-point test of the triangle's
//! plane, with a bound on the rounding of the vertices, spares the exact
//! crossing test for children whose centre is clearly on the parent centre's
//! side.
//!
//! Parity expects a closed surface (every edge shared by an even number of
//! triangles). For an open surface the classification is still
//! deterministic and rank-independent, but meaningless near the holes. A
//! surface reaching more than about `2^20` domain sides away needs `k < 0`:
//! centres are then rounded too, which keeps the result deterministic and
//! rank-independent but no longer exact for leaves next to the surface.
//!
//! # Winding number
//!
//! Under [`InsideRule::Winding`] a centre is inside when the generalized
//! winding number `w` of the surface ([`crate::geometry::winding`]) is
//! above 1/2: overlapping closed parts give their union, holes are closed
//! smoothly. The surface is first oriented: every component connected
//! through manifold edges consistently, then outward (positive volume about
//! its centroid). Evaluating `w` at every leaf would cost a tree traversal
//! per leaf; instead `w` is split into an exact integer part and a small
//! smooth part:
//!
//! * the boundary of the oriented surface, as a chain of directed edges, is
//!   split into loops, and each loop is closed by a fan of *cap* triangles
//!   from the mean of its vertices (in fixed point, after rounding, so that
//!   the rounded surface plus the caps has no boundary at all);
//! * the surface plus the caps is closed, so its winding number at a point
//!   is the signed number of times a path from outside crosses it: +1 when
//!   entering a triangle from its positive side. That count is carried down
//!   the tree exactly like the parity (same segments, same candidates, same
//!   exact predicates and perturbation, caps included as candidates but
//!   never making a leaf cut), with the sign of each crossing;
//! * `w = count - w_caps`. The caps are usually few (one fan per hole; none
//!   for a closed surface, where `w` is the count itself; three per facet
//!   for a soup without shared vertices). A centre is decided by Barill et
//!   al.'s estimate of `w_caps` ([`WindingTree::eval`](crate::geometry::winding::WindingTree::eval), beta 2, third
//!   order) when it puts `w` more than 0.05 from 1/2, ten
//!   times the largest error measured for that setting; closer ones by
//!   [`WindingTree::eval_bounded`](crate::geometry::winding::WindingTree::eval_bounded), whose error is guaranteed, and if that
//!   cannot tell, by summing the caps exactly. Near a cap, where the
//!   floating-point numerator of a solid angle is within its rounding error
//!   of zero, its sign is taken from the exact predicate (with the
//!   perturbation), so the jump of `w_caps` across a cap is exactly where
//!   the count jumps.
//!
//! Coherence: at every octant on the way down without a cap among its
//! candidates (and before it has one) the walk asks for a guaranteed bound
//! of `w_caps` over the ball around the octant; when no cap comes near, the
//! interval is passed to all descendants, and a leaf whose
//! count puts `count - w_caps` on one side of 1/2 for the whole interval is
//! decided without evaluating anything; a subtree without candidate
//! triangles is filled at once. Every decision depends on the leaf and its
//! ancestors only, so the classes are the same on any number of ranks.

use crate::geometry::diagnostics::diagnose;
use crate::geometry::{Aabb, Surface, Triangle};
use crate::octree::octant::{Octant, ROOT_LEN};
use crate::refine::SurfaceIndex;

mod carry;
mod masks;
mod rules;
mod walk;

#[cfg(test)]
mod tests;

pub use carry::carry_classes;
pub use rules::{
    keeps, CutRule, InsideRule, Keep, LeafClass, WindingSummary, CENTER_INSIDE, CUT, VOID,
};

use walk::Classifier;

/// What the walk of a rank holding part of the surface needs from the whole
/// of it: the largest coordinate (which sets the fixed point) and the signed
/// count of crossings to the root's centre.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SharedCounts {
    pub big: f64,
    pub root_count: i32,
}

/// [`SharedCounts`] of the surface whose share on this rank is `home`
/// (lattice units; each triangle on exactly one rank): maxima and sums over
/// the ranks, the same as the whole surface gives. Collective.
pub fn shared_counts(comm: &dyn crate::parallel::comm::Comm, home: &[Triangle]) -> SharedCounts {
    let mut big = [ROOT_LEN as f64];
    for c in home.iter().flat_map(|t| t.v.iter().flatten()) {
        if c.is_finite() && c.abs() > big[0] {
            big[0] = c.abs();
        }
    }
    comm.max_f64(&mut big);
    let big = big[0];
    let shift = walk::shift_for(big);
    let scale = 2f64.powi(shift);
    let round = |p: [f64; 3]| p.map(|c| crate::geometry::predicates::round_half_away(c * scale));
    let fixed: Vec<crate::geometry::predicates::FixedTri> = home
        .iter()
        .filter(|t| t.is_finite())
        .map(|t| crate::geometry::predicates::FixedTri::new(t.v.map(round)))
        .collect();
    let half = (ROOT_LEN / 2) as u64;
    let c = if shift >= 0 {
        (half as i64) << shift
    } else {
        (half as f64 * 2f64.powi(shift)).round() as i64
    };
    let p = [c; 3];
    // Coordinates within 2^40: exact as f64.
    let mut far = [walk::far_x(&fixed, p) as f64];
    comm.max_f64(&mut far);
    let n = walk::count_along(&fixed, p, far[0] as i64);
    let mut v = [n.max(0) as u64, (-n).max(0) as u64];
    comm.sum_u64(&mut v);
    SharedCounts {
        big,
        root_count: v[0] as i32 - v[1] as i32,
    }
}

/// Class byte of every leaf (bits [`CENTER_INSIDE`] | [`CUT`]) by ray
/// parity, for a sorted run of disjoint leaves (one rank's part of a linear
/// octree; it need not be complete). The result depends on each leaf and the
/// surface only, not on which other leaves are in the slice. Not collective.
///
/// # Panics
/// If some leaves overlap (and, in debug builds, if they are not sorted).
pub fn classify_leaves(leaves: &[Octant], index: &SurfaceIndex) -> Vec<u8> {
    InsideClassifier::new(index, InsideRule::Parity).classify(leaves)
}

/// [`classify_leaves`] under `rule` ([`InsideRule::Auto`] diagnoses the
/// surface in lattice units first). Not collective.
pub fn classify_leaves_with(leaves: &[Octant], index: &SurfaceIndex, rule: InsideRule) -> Vec<u8> {
    InsideClassifier::new(index, rule).classify(leaves)
}

/// Leaves below which [`InsideClassifier::classify_spare`] stays on one
/// thread: about 18 ms of work here, while each thread also scans every
/// triangle at the root (a few milliseconds on the dragon's 871,306).
const SPARE_MIN_LEAVES: usize = 1 << 17;

/// A surface prepared for classification under an [`InsideRule`]: built
/// once, it classifies any number of runs of leaves.
///
/// Under [`InsideRule::Winding`] the surface is first oriented (see
/// [`crate::geometry::winding::orient`]) and its boundary closed by caps;
/// the winding number at a leaf centre is then the signed count of
/// crossings of the closed surface (exact, carried down the tree like the
/// parity) minus the caps' winding number (a small soup, evaluated with a
/// guaranteed error). See the module documentation.
pub struct InsideClassifier<'a> {
    c: Classifier<'a>,
    rule: InsideRule,
}

impl<'a> InsideClassifier<'a> {
    /// Prepares `index` for `rule`; [`InsideRule::Auto`] is resolved by
    /// diagnosing the triangles (in lattice units) with
    /// [`InsideRule::auto_choice`].
    pub fn new(index: &'a SurfaceIndex, rule: InsideRule) -> InsideClassifier<'a> {
        let rule = match rule {
            InsideRule::Auto => match Surface::new(index.triangles().to_vec()) {
                Ok(s) => InsideRule::auto_choice(&diagnose(&s)).0,
                Err(_) => InsideRule::Winding,
            },
            r => r,
        };
        InsideClassifier {
            c: Classifier::new(index, rule == InsideRule::Winding),
            rule,
        }
    }

    /// The parity rule over `index`, a part of a surface distributed over
    /// the ranks that holds every triangle the walk to this rank's leaves
    /// meets ([`crate::refine::distributed`]); `shared` gives what needs the
    /// whole surface ([`shared_counts`]).
    pub fn parity_shared(index: &'a SurfaceIndex, shared: SharedCounts) -> InsideClassifier<'a> {
        InsideClassifier {
            c: Classifier::with_shared(index, false, Some(shared)),
            rule: InsideRule::Parity,
        }
    }

    /// The rule in use ([`InsideRule::Parity`] or [`InsideRule::Winding`]).
    pub fn rule(&self) -> InsideRule {
        self.rule
    }

    /// For the winding rule, what was done to the surface.
    pub fn summary(&self) -> Option<&WindingSummary> {
        self.c.summary.as_ref()
    }

    /// Class byte of every leaf, as [`classify_leaves`]: the result depends
    /// on each leaf and the surface only. Not collective.
    ///
    /// # Panics
    /// If some leaves overlap (and, in debug builds, if they are not sorted).
    pub fn classify(&self, leaves: &[Octant]) -> Vec<u8> {
        self.classify_spare(leaves, false)
    }

    /// [`InsideClassifier::classify`]; with `spare` (a spare core, see
    /// [`crate::parallel::cores`]) and enough leaves, the two halves of `leaves` on
    /// two threads, each walking down from the root. The same bytes either
    /// way.
    ///
    /// # Panics
    /// As [`InsideClassifier::classify`].
    pub fn classify_spare(&self, leaves: &[Octant], spare: bool) -> Vec<u8> {
        debug_assert!(
            leaves
                .windows(2)
                .all(|w| w[0].cell_end() <= w[1].cell_begin()),
            "leaves must be sorted and disjoint"
        );
        let mut out = vec![0u8; leaves.len()];
        // A second walk's start costs more than classifying a small run.
        let spare = spare && leaves.len() >= SPARE_MIN_LEAVES;
        let mid = if spare {
            leaves.len() / 2
        } else {
            leaves.len()
        };
        let (first, second) = out.split_at_mut(mid);
        crate::parallel::cores::join(
            spare,
            || self.walk_from_root(&leaves[..mid], first),
            || self.walk_from_root(&leaves[mid..], second),
        );
        out
    }

    /// Classifies `leaves` into `out`, walking down from the root.
    fn walk_from_root(&self, leaves: &[Octant], out: &mut [u8]) {
        if leaves.is_empty() {
            return;
        }
        let c = &self.c;
        let root_count = c.root_count();
        // Candidates of the root: whatever may touch its grown box.
        let g = c.grow;
        let lo = [-g; 3];
        let hi = [ROOT_LEN as f64 + g; 3];
        // A superset is all the walk needs: compare bounding boxes only.
        let mut buf: Vec<u32> = (0..c.tris.len() as u32)
            .filter(|&t| c.bounds[t as usize].overlaps(&Aabb { min: lo, max: hi }))
            .collect();
        let n = buf.len();
        let mut masks = Vec::new();
        c.walk(
            Octant::ROOT,
            root_count,
            None,
            0,
            n,
            leaves,
            out,
            &mut buf,
            &mut masks,
        );
    }
}
