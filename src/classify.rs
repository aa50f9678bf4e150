//! Inside/outside classification of leaves against a surface.
//!
//! Every leaf gets a class byte made of two bits:
//!
//! * [`CUT`]: the leaf's *closed* box touches some triangle, by exactly the
//!   rule refinement uses ([`triangle_box_overlap`] on closed sets, as
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
//! [`triangle_box_overlap`]. The three box normals compare raw coordinates,
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
//!   al.'s estimate of `w_caps` ([`WindingTree::eval`], beta 2, third
//!   order) when it puts `w` more than 0.05 from 1/2, ten
//!   times the largest error measured for that setting; closer ones by
//!   [`WindingTree::eval_bounded`], whose error is guaranteed, and if that
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

use std::borrow::Cow;
use std::collections::HashMap;

use crate::geometry::diagnostics::{diagnose, weld, SurfaceReport};
use crate::geometry::intersect::triangle_box_overlap;
use crate::geometry::winding::{boundary_loops, orient_welded, WindingTree};
use crate::geometry::{Aabb, Surface, Triangle};
use crate::octant::{Octant, LATTICE_BITS, MAX_LEVEL, ROOT_LEN};
use crate::refine::{scatter_by_child, SurfaceIndex};

/// Bit set in a leaf's class byte when its centre is inside the surface.
pub const CENTER_INSIDE: u8 = 1;
/// Bit set when the leaf's closed box touches the surface.
pub const CUT: u8 = 2;

/// The class of a leaf, from its class byte.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum LeafClass {
    /// Does not touch the surface, centre outside.
    Outside = 0,
    /// Does not touch the surface, centre inside.
    Inside = 1,
    /// Touches the surface (wherever its centre is).
    Cut = 2,
}

impl LeafClass {
    /// The class of a class byte ([`CUT`] wins over [`CENTER_INSIDE`]).
    pub fn from_bits(bits: u8) -> LeafClass {
        if bits & CUT != 0 {
            LeafClass::Cut
        } else if bits & CENTER_INSIDE != 0 {
            LeafClass::Inside
        } else {
            LeafClass::Outside
        }
    }

    /// The lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            LeafClass::Outside => "outside",
            LeafClass::Inside => "inside",
            LeafClass::Cut => "cut",
        }
    }
}

crate::named_enum! {
    /// Which elements a mesh keeps.
    pub enum Keep: "keep mode" {
        /// Every leaf.
        All = "all",
        /// Leaves inside the surface (cut leaves per the [`CutRule`]).
        Inside = "inside",
        /// Leaves outside the surface (cut leaves per the [`CutRule`]).
        Outside = "outside",
    }
}

crate::named_enum! {
    /// What to do with cut leaves (touching the surface) when keeping inside or
    /// outside.
    #[derive(Default)]
    pub enum CutRule: "cut rule" {
        /// Keep a cut leaf on the side of its centre (the default): inside and
        /// outside then partition the leaves.
        #[default]
        Center = "center",
        /// Keep every cut leaf (the kept part covers its side of the surface).
        All = "all",
        /// Drop every cut leaf (the kept part stays off the surface).
        None = "none",
    }
}

crate::named_enum! {
    /// How the centre of a leaf is found inside or outside the surface.
    #[derive(Default)]
    pub enum InsideRule: "inside rule" {
        /// Parity of surface crossings: exact for one closed surface (of any
        /// genus or orientation), the exclusive or of several overlapping ones,
        /// meaningless near holes.
        Parity = "parity",
        /// Generalized winding number above 1/2, after orienting every
        /// component: the union of overlapping parts, holes closed smoothly.
        Winding = "winding",
        /// Parity for one closed, consistently oriented component, winding
        /// number otherwise (the default).
        #[default]
        Auto = "auto",
    }
}

impl InsideRule {
    /// The rule [`InsideRule::Auto`] picks for a surface with this report,
    /// and why: parity for one closed (no boundary, non-manifold or
    /// inconsistently oriented edge, no degenerate facet), single component,
    /// winding otherwise, since parts may overlap and holes leak.
    pub fn auto_choice(report: &SurfaceReport) -> (InsideRule, String) {
        if report.closed && report.components == 1 {
            return (
                InsideRule::Parity,
                "one closed, consistently oriented component".to_string(),
            );
        }
        let mut why = Vec::new();
        if report.boundary_edges > 0 {
            why.push(format!("{} boundary edges", report.boundary_edges));
        }
        if report.non_manifold_edges > 0 {
            why.push(format!("{} non-manifold edges", report.non_manifold_edges));
        }
        if report.inconsistently_oriented_edges > 0 {
            why.push(format!(
                "{} inconsistently oriented edges",
                report.inconsistently_oriented_edges
            ));
        }
        if report.degenerate > 0 {
            why.push(format!("{} degenerate facets", report.degenerate));
        }
        if report.components != 1 {
            why.push(format!("{} components", report.components));
        }
        (InsideRule::Winding, why.join(", "))
    }

    /// The rule itself, or for [`InsideRule::Auto`] the choice of
    /// [`InsideRule::auto_choice`] (computed only then).
    pub fn resolve(self, report: impl FnOnce() -> SurfaceReport) -> InsideRule {
        match self {
            InsideRule::Auto => InsideRule::auto_choice(&report()).0,
            r => r,
        }
    }
}

/// What the winding-number rule did to the surface before classifying.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct WindingSummary {
    /// Components connected through manifold edges.
    pub components: usize,
    /// Facets reversed to orient the components consistently and outward.
    pub reversed_facets: usize,
    /// Manifold edges left inconsistent (non-orientable components).
    pub conflicting_edges: usize,
    /// Loops of the boundary (holes), each closed by a cap.
    pub boundary_loops: usize,
    /// Triangles of those caps.
    pub cap_triangles: usize,
}

/// Whether a leaf with class byte `bits` is kept. [`Keep::All`] keeps
/// everything; [`Keep::Inside`] keeps non-cut leaves whose centre is inside
/// and [`Keep::Outside`] those whose centre is outside; cut leaves follow
/// `rule` (with [`CutRule::Center`], the side of their centre).
pub fn keeps(keep: Keep, rule: CutRule, bits: u8) -> bool {
    let inside = bits & CENTER_INSIDE != 0;
    let want_inside = match keep {
        Keep::All => return true,
        Keep::Inside => true,
        Keep::Outside => false,
    };
    if bits & CUT == 0 {
        return inside == want_inside;
    }
    match rule {
        CutRule::Center => inside == want_inside,
        CutRule::All => true,
        CutRule::None => false,
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
        debug_assert!(
            leaves
                .windows(2)
                .all(|w| w[0].cell_end() <= w[1].cell_begin()),
            "leaves must be sorted and disjoint"
        );
        let mut out = vec![0u8; leaves.len()];
        if leaves.is_empty() {
            return out;
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
            &mut out,
            &mut buf,
            &mut masks,
        );
        out
    }
}

/// `x.round() as i64` for `|x| < 2^52`, without the library call that
/// `round` is on x86-64 before SSE4.1: `x - trunc(x)` is exact there.
#[inline]
fn round_half_away(x: f64) -> i64 {
    let t = x as i64;
    let frac = x - t as f64;
    t + (frac >= 0.5) as i64 - (frac <= -0.5) as i64
}

/// A triangle rounded to fixed point.
#[derive(Clone, Copy)]
struct FixedTri {
    v: [[i64; 3]; 3],
    /// Sign of `n . t` for the perturbation `t` (+1 or -1): the sign of the
    /// first non-zero component of the normal; 0 for a triangle of zero
    /// area, which parity skips.
    nsign: i8,
}

impl FixedTri {
    fn new(v: [[i64; 3]; 3]) -> FixedTri {
        let n = normal(&v);
        let nsign = n.iter().find(|&&c| c != 0).map_or(0, |&c| c.signum() as i8);
        FixedTri { v, nsign }
    }

    /// Whether `p` (perturbed) is on the side the normal points to.
    #[inline]
    fn positive_side(&self, p: [i64; 3]) -> bool {
        let o = dot(normal(&self.v), sub(p, self.v[0]));
        if o != 0 {
            o > 0
        } else {
            self.nsign > 0
        }
    }
}

/// The surface prepared for classification.
struct Classifier<'a> {
    /// Triangles in lattice units (for the touching tests): the surface's
    /// `surface_len` first (oriented for the winding rule), then the caps.
    tris: Cow<'a, [Triangle]>,
    /// Triangles `0..surface_len` are the surface; the others are caps,
    /// which count for crossings but never make a leaf cut.
    surface_len: usize,
    /// Their normals `(v1 - v0) x (v2 - v1)`, in floating point.
    normals: Vec<[f64; 3]>,
    /// Their bounding boxes (the index's, unless the winding rule added
    /// caps).
    bounds: Cow<'a, [Aabb]>,
    /// The same triangles in fixed point.
    fixed: Vec<FixedTri>,
    /// Fixed-point units per lattice unit is `2^shift`.
    shift: i32,
    /// A fixed-point unit in lattice units, `2^-shift`.
    unit: f64,
    /// How far candidate boxes are grown, in lattice units.
    grow: f64,
    /// Largest absolute coordinate of the triangles and the lattice: scales
    /// the floating-point error bounds.
    big: f64,
    /// Winding rule (else parity).
    winding: bool,
    /// The caps with positive area in fixed-point units, their tree ids
    /// indexing `cap_ids`; `None` when the surface has no boundary.
    caps: Option<WindingTree>,
    /// Index in `fixed` of each triangle of `caps`.
    cap_ids: Vec<u32>,
    summary: Option<WindingSummary>,
}

/// Margin by which Barill et al.'s estimate of the caps' winding number
/// (beta 2, third order) must put a centre away from 1/2 to decide it: ten
/// times the largest error measured for that setting (5e-3, see the tests
/// of [`crate::geometry::winding`]).
const CAP_ESTIMATE_MARGIN: f64 = 0.05;
/// Error budget of the bounded evaluation for centres within the margin
/// (then the caps are summed exactly).
const CAP_POINT_BUDGET: f64 = 1e-3;
/// The same for a region.
const CAP_REGION_BUDGET: f64 = 0.1;
/// Nodes and triangles a region's bound may visit: a bound that needs more
/// (a region near many caps) would cost more than it saves.
const CAP_REGION_WORK: usize = 512;
/// Largest error of a region's bound on the caps' winding number for it to
/// be kept: wider intervals rarely decide a leaf.
const CAP_REGION_ERR: f64 = 0.25;

/// Child masks: children whose bit `k` is set (`POS[k]`) or clear (`NEG[k]`).
const POS: [u8; 3] = [0b1010_1010, 0b1100_1100, 0b1111_0000];
const NEG: [u8; 3] = [0b0101_0101, 0b0011_0011, 0b0000_1111];
/// Direction of child `i`'s centre from its parent's centre.
const SX: [f64; 8] = [-1.0, 1.0, -1.0, 1.0, -1.0, 1.0, -1.0, 1.0];
const SY: [f64; 8] = [-1.0, -1.0, 1.0, 1.0, -1.0, -1.0, 1.0, 1.0];
const SZ: [f64; 8] = [-1.0, -1.0, -1.0, -1.0, 1.0, 1.0, 1.0, 1.0];

/// What one triangle does to the eight children of an octant (bit `i` for
/// child `i`).
#[derive(Clone, Copy, Default)]
struct ChildMasks {
    /// The triangle may touch the child's grown box (a superset of those it
    /// does): it stays a candidate below.
    near: u8,
    /// [`triangle_box_overlap`] certainly says the closed box touches.
    touch: u8,
    /// Too close to call in floating point: ask [`triangle_box_overlap`].
    unsure: u8,
    /// The child's centre may lie on the other side of the triangle's
    /// plane than the parent's centre.
    plane: u8,
    /// The triangle's grown box meets the segment from the parent's centre
    /// to the child's centre: only then can the segment cross it (most
    /// candidates of a large octant are far from its centre).
    seg: u8,
}

impl<'a> Classifier<'a> {
    fn new(index: &'a SurfaceIndex, winding: bool) -> Classifier<'a> {
        let surface = index.triangles();
        // Orientation first: it only swaps vertices, so the box tests and
        // the fixed-point range are those of the input.
        let (tris, ids, orientation) = if winding {
            let (ids, _) = weld(surface);
            let o = orient_welded(surface, &ids);
            (Cow::Owned(o.apply(surface)), ids, Some(o))
        } else {
            (Cow::Borrowed(surface), Vec::new(), None)
        };
        // The largest coordinate to represent: the lattice and every finite
        // vertex.
        // Nine running maxima, not one: a single chain of dependent
        // comparisons costs more than the rest of the set-up together.
        let mut most = [ROOT_LEN as f64; 9];
        for t in tris.iter() {
            for (m, c) in most.iter_mut().zip(t.v.iter().flatten()) {
                let a = c.abs();
                if a > *m && a.is_finite() {
                    *m = a;
                }
            }
        }
        let big = most.into_iter().fold(ROOT_LEN as f64, f64::max);
        // Every fixed-point coordinate, query points included, stays within
        // 2^39 (+1 for the far point), so differences stay below 2^41.
        let mut shift = 20i32;
        while shift > -1000 && big * 2f64.powi(shift) > (1u64 << 39) as f64 {
            shift -= 1;
        }
        let scale = 2f64.powi(shift);
        let round = |p: [f64; 3]| p.map(|c| round_half_away(c * scale));
        let mut fixed: Vec<FixedTri> = tris
            .iter()
            .map(|t| {
                if !t.is_finite() {
                    return FixedTri {
                        v: [[0; 3]; 3],
                        nsign: 0,
                    };
                }
                FixedTri::new(t.v.map(round))
            })
            .collect();
        let surface_len = tris.len();
        let mut tris = tris;
        let (mut caps, mut cap_ids, mut summary) = (None, Vec::new(), None);
        if let Some(o) = orientation {
            // Close every boundary loop with a fan from the mean of its
            // rounded vertices, so that the rounded surface plus the caps
            // has no boundary. The apex gets odd coordinates: centres are
            // even (shift >= 1), so no centre is ever a cap's vertex.
            let mut pos = HashMap::new();
            for (t, f) in fixed.iter().zip(&ids) {
                for (&id, &v) in f.iter().zip(&t.v) {
                    pos.insert(id, v);
                }
            }
            let loops = boundary_loops(&ids, &o.flipped);
            let mut cap_tris = Vec::new();
            let mut owned = tris.into_owned();
            for lp in &loops {
                let mut sum = [0i128; 3];
                for u in lp {
                    for k in 0..3 {
                        sum[k] += pos[u][k] as i128;
                    }
                }
                let z = sum.map(|c| (c.div_euclid(lp.len() as i128) as i64) | 1);
                for i in 0..lp.len() {
                    let (u, v) = (pos[&lp[i]], pos[&lp[(i + 1) % lp.len()]]);
                    let ft = FixedTri::new([v, u, z]);
                    if ft.nsign != 0 {
                        cap_ids.push(fixed.len() as u32);
                        cap_tris.push(Triangle {
                            v: ft.v.map(|p| p.map(|c| c as f64)),
                        });
                    }
                    fixed.push(ft);
                    owned.push(Triangle {
                        v: [v, u, z].map(|p| p.map(|c| c as f64 / scale)),
                    });
                }
            }
            tris = Cow::Owned(owned);
            summary = Some(WindingSummary {
                components: o.components,
                reversed_facets: o.reversed_facets,
                conflicting_edges: o.conflicting_edges,
                boundary_loops: loops.len(),
                cap_triangles: fixed.len() - surface_len,
            });
            if !cap_tris.is_empty() {
                caps = Some(WindingTree::new(&cap_tris));
            }
        }
        let normals = tris
            .iter()
            .map(|t| {
                let [a, b, c] = t.v;
                let e0 = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
                let e1 = [c[0] - b[0], c[1] - b[1], c[2] - b[2]];
                [
                    e0[1] * e1[2] - e0[2] * e1[1],
                    e0[2] * e1[0] - e0[0] * e1[2],
                    e0[0] * e1[1] - e0[1] * e1[0],
                ]
            })
            .collect();
        let bounds = match &tris {
            Cow::Borrowed(_) => Cow::Borrowed(index.boxes()),
            Cow::Owned(t) => Cow::Owned(t.iter().map(Triangle::aabb).collect()),
        };
        Classifier {
            tris,
            surface_len,
            normals,
            bounds,
            fixed,
            shift,
            unit: 2f64.powi(-shift),
            // Rounding moves a vertex by at most half a unit; four units
            // leave room for the floating-point error of the box test.
            grow: 4.0 / scale,
            big,
            winding,
            caps,
            cap_ids,
            summary,
        }
    }

    /// A lattice coordinate in fixed point (exact when `shift >= 0`).
    #[inline]
    fn to_fixed(&self, x: u64) -> i64 {
        if self.shift >= 0 {
            (x as i64) << self.shift
        } else {
            (x as f64 * 2f64.powi(self.shift)).round() as i64
        }
    }

    /// Centre of `o` in fixed point.
    #[inline]
    fn center(&self, o: Octant) -> [i64; 3] {
        let half = (o.side() / 2) as u64;
        o.coords().map(|c| self.to_fixed(c as u64 + half))
    }

    /// Whether the closed box `[lo, hi]` touches triangle `t`: refinement's
    /// rule.
    #[inline]
    fn touches(&self, t: u32, lo: [f64; 3], hi: [f64; 3]) -> bool {
        triangle_box_overlap(&self.tris[t as usize], lo, hi)
    }

    /// Classifies triangle `t` against the children in `want` of the octant
    /// with centre `c` whose children have side `side`; the closed-box
    /// verdicts (`touch`, `unsure`) are computed for the children in `leafy`
    /// only.
    ///
    /// The children's boxes are tested on the 13 axes of
    /// [`triangle_box_overlap`] at once. The three box normals compare raw
    /// coordinates, as `triangle_box_overlap` does, so they are exact. On the
    /// ten others both computations are within `eta` of the exact projections,
    /// so a gap beyond `eta` is a verdict `triangle_box_overlap` shares; the
    /// rest is left to it (exact contacts of lattice-aligned surfaces, mostly).
    /// `near` uses the box normals and the triangle normal only: a superset
    /// is all it needs to be.
    #[inline]
    fn child_masks(&self, t: u32, c: [f64; 3], side: f64, want: u8, leafy: u8) -> ChildMasks {
        let g = self.grow;
        let mut exact = want & leafy;
        let mut near = want;
        let mut seg = 0xffu8;
        let quarter = 0.5 * side;
        let Aabb { min: lo3, max: hi3 } = self.bounds[t as usize];
        for k in 0..3 {
            let (lo, hi) = (lo3[k], hi3[k]);
            // The children on the positive / negative side along `k` whose
            // slab `[ck, ck + extent]` / `[ck - extent, ck]`, grown by `m`,
            // meets the triangle's extent.
            // Branch-free: these verdicts are close to random.
            let bits = |b: bool, m: u8| (b as u8).wrapping_neg() & m;
            let meets = |extent: f64, m: f64| {
                bits((lo <= c[k] + extent + m) & (hi >= c[k] - m), POS[k])
                    | bits((lo <= c[k] + m) & (hi >= c[k] - extent - m), NEG[k])
            };
            exact &= meets(side, 0.0);
            near &= meets(side, g);
            seg &= meets(quarter, g);
        }
        if near == 0 {
            return ChildMasks::default();
        }
        if near & seg != 0 {
            seg &= segments_meeting_box(c, quarter, lo3, hi3, g);
        }
        if exact == 0 && near & seg == 0 {
            // No box verdict wanted and no segment to cross: the boxes alone
            // give `near` (a superset is enough), without the projections.
            return ChildMasks {
                near,
                ..ChildMasks::default()
            };
        }
        let v = &self.tris[t as usize].v;
        let r = v.map(|p| [p[0] - c[0], p[1] - c[1], p[2] - c[2]]);
        let rho = r.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
        let base = rho + side;
        let u = f64::EPSILON;
        let half = 0.5 * side;
        let mut sep = 0u8;
        let mut unsure = 0u8;

        // Triangle normal, for every child: the closed boxes, the grown
        // ones, and the side of the child's centre. A normal that is
        // exactly zero here may not be zero there: leave every child to the
        // exact test then.
        //
        // Error bounds: both computations take differences of coordinates
        // up to `big`, products of a few of them, and projections with lever
        // arms up to `base`; a few dozen ulps of those magnitudes bound the
        // rounding of either, and 128 leaves room to spare.
        let n = self.normals[t as usize];
        let mut plane = 0xff;
        if n == [0.0; 3] {
            unsure = 0xff;
        } else {
            let eta = 128.0 * u * rho * (rho + self.big) * base;
            let tiny = n
                .iter()
                .all(|x| x.abs() <= 256.0 * u * rho * (rho + self.big));
            let p = r.map(|v| n[0] * v[0] + n[1] * v[1] + n[2] * v[2]);
            let (t0, t1) = (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]));
            let l1 = n[0].abs() + n[1].abs() + n[2].abs();
            let rad = half * l1;
            let h = [half * n[0], half * n[1], half * n[2]];
            // The float plane is within `eta_p` of the fixed-point one.
            let eta_p = if self.shift >= 0 {
                64.0 * self.unit * base * base + eta
            } else {
                f64::INFINITY
            };
            let (s0, s1) = (t0 - eta_p, t1 + eta_p);
            let (mut s, mut un, mut far, mut across) = (0u8, 0u8, 0u8, 0u8);
            for i in 0..8 {
                let x = SX[i] * h[0] + SY[i] * h[1] + SZ[i] * h[2];
                let gap = (t0 - x - rad).max(x - rad - t1);
                s |= ((gap > eta) as u8) << i;
                un |= ((gap >= -eta) as u8) << i;
                far |= ((gap > g * l1 + eta) as u8) << i;
                let same = (s0 > 0.0 && s0 > x) || (s1 < 0.0 && s1 < x);
                across |= (!same as u8) << i;
            }
            near &= !far;
            plane = across;
            if tiny {
                unsure |= un;
            } else {
                sep |= s;
                unsure |= un & !s;
            }
        }

        // Edge x box-axis products, for the closed boxes still open. An axis
        // here is zero iff the raw coordinates are equal, and then it is
        // zero there too; a tiny one may be zero there only.
        //
        // On `a = e x k` (`e` the edge from vertex `j`), a point `x` projects
        // to `(x x e)_k`: the edge to `(r_j x e)_k`, the opposite vertex to
        // that minus `n_k`.
        let mut open = exact & !sep;
        if open != 0 {
            let eta = 128.0 * u * (rho + self.big) * base;
            let tiny_e = 16.0 * u * self.big;
            for j in 0..3 {
                let (p, q) = (v[j], v[(j + 1) % 3]);
                let e = [q[0] - p[0], q[1] - p[1], q[2] - p[2]];
                let w = r[j];
                let pe = [
                    w[1] * e[2] - w[2] * e[1],
                    w[2] * e[0] - w[0] * e[2],
                    w[0] * e[1] - w[1] * e[0],
                ];
                for (k, a) in [[0.0, e[2], -e[1]], [-e[2], 0.0, e[0]], [e[1], -e[0], 0.0]]
                    .into_iter()
                    .enumerate()
                {
                    let po = pe[k] - n[k];
                    let (t0, t1) = (pe[k].min(po), pe[k].max(po));
                    if (t0 < -eta && t1 > eta) || a == [0.0; 3] {
                        // The parent's centre projects well inside the
                        // triangle, so every child's box overlaps it here.
                        continue;
                    }
                    let tiny = a.iter().all(|x| x.abs() <= tiny_e);
                    let rad = half * (a[0].abs() + a[1].abs() + a[2].abs());
                    let h = [half * a[0], half * a[1], half * a[2]];
                    let mut m = open;
                    while m != 0 {
                        let i = m.trailing_zeros() as usize;
                        m &= m - 1;
                        let x = SX[i] * h[0] + SY[i] * h[1] + SZ[i] * h[2];
                        let gap = (t0 - x - rad).max(x - rad - t1);
                        if gap > eta && !tiny {
                            sep |= 1 << i;
                            open &= !(1 << i);
                        } else if gap >= -eta {
                            unsure |= 1 << i;
                        }
                    }
                }
                if open == 0 {
                    break;
                }
            }
        }
        let open = exact & !sep;
        ChildMasks {
            near,
            touch: open & !unsure,
            unsure: open & unsure,
            plane,
            seg,
        }
    }

    /// Signed count of surface crossings from a point beyond every vertex
    /// in `+x` (where the winding number is 0) to the root's centre, over
    /// all triangles: +1 for each entered from its positive side.
    fn root_count(&self) -> i32 {
        let p = self.center(Octant::ROOT);
        let far_x = self
            .fixed
            .iter()
            .filter(|t| t.nsign != 0)
            .flat_map(|t| t.v.iter().map(|v| v[0]))
            .fold(p[0], i64::max)
            + 1;
        let q = [far_x, p[1], p[2]];
        let mut count = 0;
        for t in &self.fixed {
            // Only a triangle whose box meets the ray can cross it.
            let meets = (1..3).all(|k| {
                let (a, b) = (
                    t.v[0][k].min(t.v[1][k]).min(t.v[2][k]),
                    t.v[0][k].max(t.v[1][k]).max(t.v[2][k]),
                );
                a <= p[k] && p[k] <= b
            }) && t.v.iter().any(|v| v[0] >= p[0]);
            if meets && t.nsign != 0 && crosses(p, q, t) {
                count += if t.positive_side(q) { 1 } else { -1 };
            }
        }
        count
    }

    /// Whether the centre of `o` is inside, given the signed crossing count
    /// `count` there and, under the winding rule with caps, an interval
    /// holding the caps' winding number over a ball around `o`.
    fn inside(&self, o: Octant, count: i32, interval: Option<(f64, f64)>) -> bool {
        if !self.winding {
            return count & 1 != 0;
        }
        let Some(caps) = &self.caps else {
            // No boundary: the winding number is the count.
            return count >= 1;
        };
        let w = count as f64;
        if let Some((lo, hi)) = interval {
            if w - hi > 0.5 {
                return true;
            }
            if w - lo <= 0.5 {
                return false;
            }
        }
        let pf = self.center(o);
        let p = pf.map(|c| c as f64);
        // The jump across a cap goes where the exact crossing test puts it.
        let side = |id: u32| !self.fixed[self.cap_ids[id as usize] as usize].positive_side(pf);
        let x = w - caps.eval(p) - 0.5;
        if x.abs() > CAP_ESTIMATE_MARGIN {
            return x > 0.0;
        }
        if let Some((v, e)) = caps.eval_bounded(
            p,
            0.0,
            CAP_POINT_BUDGET,
            f64::INFINITY,
            usize::MAX,
            Some(&side),
        ) {
            let x = w - v - 0.5;
            if x.abs() > e {
                return x > 0.0;
            }
        }
        w - caps.eval_exact(p, Some(&side)) > 0.5
    }

    /// An interval holding the caps' winding number over the ball around
    /// `o` (under the winding rule with caps), if no cap comes near and it
    /// is narrow enough to be worth passing down.
    fn region_interval(&self, o: Octant) -> Option<(f64, f64)> {
        let caps = self.caps.as_ref()?;
        let p = self.center(o).map(|c| c as f64);
        // Half the diagonal, and a unit for rounded centres (shift < 0).
        let rho = self.to_fixed(o.side() as u64) as f64 * 0.866_025_403_784_438_7 + 1.0;
        let (v, e) = caps.eval_bounded(
            p,
            rho,
            CAP_REGION_BUDGET,
            CAP_REGION_ERR,
            CAP_REGION_WORK,
            None,
        )?;
        Some((v - e, v + e))
    }

    /// Classifies `leaves` (all inside `o`, none touching the surface or a
    /// cap, so that the count is `count` at every centre).
    fn fill_uncut(
        &self,
        o: Octant,
        count: i32,
        interval: Option<(f64, f64)>,
        leaves: &[Octant],
        out: &mut [u8],
    ) {
        if self.caps.is_none() || !self.winding {
            out.fill(self.inside(o, count, None) as u8);
            return;
        }
        if leaves.len() == 1 && leaves[0] == o {
            out[0] = self.inside(o, count, interval) as u8;
            return;
        }
        let interval = interval.or_else(|| self.region_interval(o));
        if let Some((lo, hi)) = interval {
            let w = count as f64;
            if w - hi > 0.5 || w - lo <= 0.5 {
                out.fill((w - hi > 0.5) as u8);
                return;
            }
        }
        let bounds = split_by_child(o, leaves);
        for i in 0..8 {
            let (b, e) = (bounds[i], bounds[i + 1]);
            if b < e {
                self.fill_uncut(
                    o.child(i as u32),
                    count,
                    interval,
                    &leaves[b..e],
                    &mut out[b..e],
                );
            }
        }
    }

    /// Classifies `leaves` (all inside `o`, written to `out`), given the
    /// signed crossing count at the centre of `o`, the caps' interval
    /// inherited from an ancestor, and the candidate triangles
    /// `buf[lo..hi]`. `masks` is scratch space used as a stack.
    #[allow(clippy::too_many_arguments)]
    fn walk(
        &self,
        o: Octant,
        count: i32,
        interval: Option<(f64, f64)>,
        lo: usize,
        hi: usize,
        leaves: &[Octant],
        out: &mut [u8],
        buf: &mut Vec<u32>,
        masks: &mut Vec<ChildMasks>,
    ) {
        if lo == hi {
            // Nothing near: no leaf below is cut, and no segment below
            // crosses anything.
            self.fill_uncut(o, count, interval, leaves, out);
            return;
        }
        if leaves[0] == o {
            // Only the root gets here; other leaves are done by their parent.
            assert_eq!(leaves.len(), 1, "classify_leaves: the leaves overlap");
            let (blo, bhi) = o.bounds_f64();
            let cut = buf[lo..hi]
                .iter()
                .any(|&t| (t as usize) < self.surface_len && self.touches(t, blo, bhi));
            out[0] = self.inside(o, count, interval) as u8 | if cut { CUT } else { 0 };
            return;
        }
        assert!(o.level() < MAX_LEVEL, "classify_leaves: the leaves overlap");
        // A cap among the candidates is likely to reach the ball around the
        // octant: do not try for an interval then.
        let interval = match interval {
            None if self.caps.is_some()
                && buf[lo..hi].iter().all(|&t| (t as usize) < self.surface_len) =>
            {
                self.region_interval(o)
            }
            i => i,
        };
        let bounds = split_by_child(o, leaves);
        let (mut present, mut leafy) = (0u8, 0u8);
        for i in 0..8 {
            let (b, e) = (bounds[i], bounds[i + 1]);
            if b < e {
                present |= 1 << i;
                if e - b == 1 && leaves[b] == o.child(i as u32) {
                    leafy |= 1 << i;
                }
            }
        }
        let (omin, _) = o.bounds_f64();
        let side = (o.side() / 2) as f64;
        let center = [omin[0] + side, omin[1] + side, omin[2] + side];
        let p = self.center(o);
        let h = self.to_fixed((o.side() / 4) as u64);
        let mstart = masks.len();
        let mut counts = [0i32; 8];
        // Leaf children certainly cut so far need no more box verdicts.
        let (mut touched, mut unsure) = (0u8, 0u8);
        for &t in &buf[lo..hi] {
            let surface = (t as usize) < self.surface_len;
            let decide = if surface { leafy & !touched } else { 0 };
            let m = self.child_masks(t, center, side, present, decide);
            if surface {
                touched |= m.touch;
                unsure |= m.unsure;
            }
            masks.push(m);
            // Only a triangle near the child can cross the segment from the
            // parent's centre (a corner of the child) to the child's centre.
            let cross = m.near & m.plane & m.seg;
            let ft = &self.fixed[t as usize];
            if cross != 0 && ft.nsign != 0 {
                let (mut hit, entering) = self.crossings(o, p, h, ft, cross);
                let d = if entering { 1 } else { -1 };
                while hit != 0 {
                    counts[hit.trailing_zeros() as usize] += d;
                    hit &= hit - 1;
                }
            }
        }
        // Leaf children: cut if touched, or if a triangle too close to call
        // touches by the exact test.
        let mut cut = touched;
        let mut ask = leafy & unsure & !touched;
        while ask != 0 {
            let i = ask.trailing_zeros();
            ask &= ask - 1;
            let bit = 1u8 << i;
            let (cmin, cmax) = o.child(i).bounds_f64();
            if (lo..hi).any(|j| {
                masks[mstart + j - lo].unsure & bit != 0 && self.touches(buf[j], cmin, cmax)
            }) {
                cut |= bit;
            }
        }
        // The candidate lists of the children walked into, one after the
        // other on top of the stack.
        let inner = present & !leafy;
        let lists = scatter_by_child(buf, lo, hi, |j| masks[mstart + j - lo].near & inner);
        masks.truncate(mstart);
        for i in 0..8u32 {
            let bit = 1u8 << i;
            if present & bit == 0 {
                continue;
            }
            let c = o.child(i);
            let n = count + counts[i as usize];
            let (b, e) = (bounds[i as usize], bounds[i as usize + 1]);
            if leafy & bit != 0 {
                let cut = if cut & bit != 0 { CUT } else { 0 };
                out[b] = self.inside(c, n, interval) as u8 | cut;
                continue;
            }
            self.walk(
                c,
                n,
                interval,
                lists[i as usize],
                lists[i as usize + 1],
                &leaves[b..e],
                &mut out[b..e],
                buf,
                masks,
            );
        }
        buf.truncate(lists[0]);
    }

    /// Mask of the children in `mask` whose segment from the centre `p` of
    /// `o` to their own centre (offset `h` per axis) crosses `t`, and
    /// whether `p` is on the positive side of `t` (the segments then enter
    /// the surface there).
    #[inline]
    fn crossings(&self, o: Octant, p: [i64; 3], h: i64, t: &FixedTri, mask: u8) -> (u8, bool) {
        if self.shift >= 0 {
            return crossings_from_center(p, h, t, mask);
        }
        // Rounded centres (absurdly large surfaces): plain tests.
        let mut out = 0u8;
        for i in 0..8 {
            if mask & (1 << i) != 0 && crosses(p, self.center(o.child(i)), t) {
                out |= 1 << i;
            }
        }
        (out, t.positive_side(p))
    }
}

/// Children whose segment from the parent's centre `c` to their own centre
/// (`quarter` away on each axis) meets the box `[lo, hi]` grown by `g`: the
/// parameter intervals of the three slabs along the diagonal must overlap.
/// Rounding is covered by a margin far below `g` in space.
#[inline]
fn segments_meeting_box(c: [f64; 3], quarter: f64, lo: [f64; 3], hi: [f64; 3], g: f64) -> u8 {
    const SLACK: f64 = 1e-9;
    let inv = 1.0 / quarter;
    // Along axis k, the positive children enter the slab at `u[k]` and leave
    // at `w[k]`; the negative ones over `[-w[k], -u[k]]`.
    let u: [f64; 3] = std::array::from_fn(|k| (lo[k] - g - c[k]) * inv);
    let w: [f64; 3] = std::array::from_fn(|k| (hi[k] + g - c[k]) * inv);
    let mut out = 0u8;
    for i in 0..8 {
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        for k in 0..3 {
            let (a, b) = if i >> k & 1 != 0 {
                (u[k], w[k])
            } else {
                (-w[k], -u[k])
            };
            t0 = t0.max(a);
            t1 = t1.min(b);
        }
        out |= ((t0 <= t1 + SLACK) as u8) << i;
    }
    out
}

/// Start of each child's leaves in `leaves` (all strictly inside `o`):
/// child `i` owns `leaves[b[i]..b[i + 1]]`.
#[inline]
fn split_by_child(o: Octant, leaves: &[Octant]) -> [usize; 9] {
    let mut b = [0usize; 9];
    if leaves.len() <= 256 {
        // A short run: count the leaves by child, in one pass.
        let s = 3 * (LATTICE_BITS - 1 - o.level() as u32);
        for l in leaves {
            b[((l.morton() >> s) & 7) as usize + 1] += 1;
        }
        for i in 1..9 {
            b[i] += b[i - 1];
        }
    } else {
        for i in 1..8 {
            let key = o.child(i as u32).key();
            b[i] = b[i - 1] + gallop(&leaves[b[i - 1]..], key);
        }
        b[8] = leaves.len();
    }
    b
}

/// Number of leaves before `key`, searched from the front (exponentially,
/// then by bisection) so that the memory touched stays next to where the
/// walk is, whatever the length of the slice.
#[inline]
fn gallop(leaves: &[Octant], key: u64) -> usize {
    let mut hi = 1;
    while hi < leaves.len() && leaves[hi - 1].key() < key {
        hi *= 2;
    }
    let lo = hi / 2;
    let hi = hi.min(leaves.len());
    lo + leaves[lo..hi].partition_point(|l| l.key() < key)
}

#[inline]
fn sub(a: [i64; 3], b: [i64; 3]) -> [i64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// Cross product of vectors below `2^41`: components below `2^83`.
#[inline]
fn cross(a: [i64; 3], b: [i64; 3]) -> [i128; 3] {
    let m = |x: i64, y: i64| x as i128 * y as i128;
    [
        m(a[1], b[2]) - m(a[2], b[1]),
        m(a[2], b[0]) - m(a[0], b[2]),
        m(a[0], b[1]) - m(a[1], b[0]),
    ]
}

/// `w . d` for `w` below `2^83` and `d` below `2^41`: below `2^126`.
#[inline]
fn dot(w: [i128; 3], d: [i64; 3]) -> i128 {
    w[0] * d[0] as i128 + w[1] * d[1] as i128 + w[2] * d[2] as i128
}

/// Unnormalised normal `(b - a) x (c - a)`.
#[inline]
fn normal(v: &[[i64; 3]; 3]) -> [i128; 3] {
    cross(sub(v[1], v[0]), sub(v[2], v[0]))
}

/// Sign of the first non-zero component (false for negative; true for
/// positive or all zero).
#[inline]
fn first_sign(m: [i128; 3]) -> bool {
    if m[0] != 0 {
        m[0] > 0
    } else if m[1] != 0 {
        m[1] > 0
    } else {
        m[2] >= 0
    }
}

/// Perturbed sign of `orient(p, q, a, b)`, given `w = (a - p) x (b - p)`
/// and `d = q - p`.
#[inline]
fn edge_side(w: [i128; 3], d: [i64; 3], a: [i64; 3], b: [i64; 3]) -> bool {
    let o = dot(w, d);
    if o != 0 {
        return o > 0;
    }
    first_sign(cross(sub(a, b), d))
}

/// Whether segment `pq` crosses the triangle (perturbed, see the module
/// documentation). The triangle must have positive area.
fn crosses(p: [i64; 3], q: [i64; 3], t: &FixedTri) -> bool {
    let [a, b, c] = t.v;
    let n = normal(&t.v);
    let side = |x: [i64; 3]| {
        let o = dot(n, sub(x, a));
        if o != 0 {
            o > 0
        } else {
            t.nsign > 0
        }
    };
    if side(p) == side(q) {
        return false;
    }
    let d = sub(q, p);
    let (ap, bp, cp) = (sub(a, p), sub(b, p), sub(c, p));
    let e0 = edge_side(cross(ap, bp), d, a, b);
    e0 == edge_side(cross(bp, cp), d, b, c) && e0 == edge_side(cross(cp, ap), d, c, a)
}

/// [`crosses`] for the eight segments from `p` to `p + h s` (`s` in
/// `{-1, 1}^3`, child `i` has `s_k = +1` iff bit `k` of `i` is set), for the
/// children in `mask`; returns the mask of those crossing and whether `p` is
/// on the positive side. Shares the work that does not depend on the child.
#[inline]
fn crossings_from_center(p: [i64; 3], h: i64, t: &FixedTri, mask: u8) -> (u8, bool) {
    let [a, b, c] = t.v;
    let n = normal(&t.v);
    let op = dot(n, sub(p, a));
    let pside = if op != 0 { op > 0 } else { t.nsign > 0 };
    let signed = |v: [i128; 3], i: u32| -> i128 {
        let x = if i & 1 != 0 { v[0] } else { -v[0] };
        let y = if i & 2 != 0 { v[1] } else { -v[1] };
        let z = if i & 4 != 0 { v[2] } else { -v[2] };
        x + y + z
    };
    let mut edges: Option<[[i128; 3]; 3]> = None;
    let mut out = 0u8;
    for i in 0..8u32 {
        if mask & (1 << i) == 0 {
            continue;
        }
        let oq = op + h as i128 * signed(n, i);
        let qside = if oq != 0 { oq > 0 } else { t.nsign > 0 };
        if pside == qside {
            continue;
        }
        let w = edges.get_or_insert_with(|| {
            let (ap, bp, cp) = (sub(a, p), sub(b, p), sub(c, p));
            [cross(ap, bp), cross(bp, cp), cross(cp, ap)]
        });
        let s = [
            if i & 1 != 0 { 1 } else { -1 },
            if i & 2 != 0 { 1 } else { -1 },
            if i & 4 != 0 { 1 } else { -1 },
        ];
        let side = |w: [i128; 3], a: [i64; 3], b: [i64; 3]| {
            let o = signed(w, i);
            if o != 0 {
                o > 0
            } else {
                first_sign(cross(sub(a, b), s))
            }
        };
        let e0 = side(w[0], a, b);
        if e0 == side(w[1], b, c) && e0 == side(w[2], c, a) {
            out |= 1 << i;
        }
    }
    (out, pside)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::comm::{CommRef, SerialComm};
    use crate::domain::{Domain, DEFAULT_FIT};
    use crate::geometry::shapes::{default_sphere, default_torus, sphere};
    use crate::geometry::winding::winding_number;
    use crate::octant::CELLS;

    fn norm(p: [f64; 3]) -> f64 {
        f_dot(p, p).sqrt()
    }
    use crate::refine::{build_from_surface, NO_LIMIT};
    use crate::Connectivity;
    use std::rc::Rc;

    use crate::testutil::Rng;

    fn fitted(surface: &Surface) -> (Domain, SurfaceIndex) {
        let b = surface.bbox();
        let d = Domain::around(b.min, b.max, DEFAULT_FIT).unwrap();
        let index = SurfaceIndex::new(surface, &d);
        (d, index)
    }

    /// The surface-refined tree at `level`, optionally 2:1 balanced.
    fn leaves_of(index: &SurfaceIndex, level: u8, balance: bool) -> Vec<Octant> {
        let comm: CommRef = Rc::new(SerialComm);
        let mut t = build_from_surface(comm, index, level, NO_LIMIT).unwrap();
        if balance {
            t.balance(Connectivity::Corner).unwrap();
        }
        t.leaves().to_vec()
    }

    fn f_sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
        [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
    }
    fn f_cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    }
    fn f_dot(a: [f64; 3], b: [f64; 3]) -> f64 {
        a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    }

    /// Classic ray parity in plain floating point (Moller-Trumbore against
    /// every triangle); `None` when some hit is too close to call.
    fn ray_inside(p: [f64; 3], tris: &[Triangle]) -> Option<bool> {
        let dir = [0.356_123_7, 0.581_774_1, 0.731_229_5];
        let mut inside = false;
        for t in tris {
            let [a, b, c] = t.v;
            let (e1, e2) = (f_sub(b, a), f_sub(c, a));
            let pv = f_cross(dir, e2);
            let det = f_dot(e1, pv);
            let n = f_cross(e1, e2);
            let nn = f_dot(n, n).sqrt();
            if nn == 0.0 {
                continue;
            }
            let w = f_sub(p, a);
            if det.abs() <= 1e-12 * nn {
                // Ray parallel to the plane: only a centre in it is a problem.
                if (f_dot(n, w) / nn).abs() < 1e-6 {
                    return None;
                }
                continue;
            }
            let inv = 1.0 / det;
            let u = f_dot(w, pv) * inv;
            let qv = f_cross(w, e1);
            let v = f_dot(dir, qv) * inv;
            let s = f_dot(e2, qv) * inv;
            let eps = 1e-9;
            if u < -eps || v < -eps || u + v > 1.0 + eps || s < -1e-6 {
                continue;
            }
            if u < eps || v < eps || u + v > 1.0 - eps || s < 1e-6 {
                return None;
            }
            inside = !inside;
        }
        Some(inside)
    }

    fn center_f64(o: Octant) -> [f64; 3] {
        let (lo, hi) = o.bounds_f64();
        [
            0.5 * (lo[0] + hi[0]),
            0.5 * (lo[1] + hi[1]),
            0.5 * (lo[2] + hi[2]),
        ]
    }

    /// Compares every leaf with brute force over all triangles; returns
    /// (leaves compared, ambiguous ray tests).
    fn check_brute_force(leaves: &[Octant], index: &SurfaceIndex, bits: &[u8]) -> (usize, usize) {
        let tris = index.triangles();
        let mut skipped = 0;
        for (l, &b) in leaves.iter().zip(bits) {
            let (lo, hi) = l.bounds_f64();
            let cut = tris.iter().any(|t| triangle_box_overlap(t, lo, hi));
            assert_eq!(b & CUT != 0, cut, "CUT of {l:?}");
            match ray_inside(center_f64(*l), tris) {
                Some(inside) => assert_eq!(b & CENTER_INSIDE != 0, inside, "centre of {l:?}"),
                None => skipped += 1,
            }
        }
        (leaves.len(), skipped)
    }

    fn brute_force_surface(surface: &Surface, level: u8) {
        let (_, index) = fitted(surface);
        let leaves = leaves_of(&index, level, true);
        let bits = classify_leaves(&leaves, &index);
        let (n, skipped) = check_brute_force(&leaves, &index, &bits);
        assert!(skipped * 1000 <= n, "{skipped} ambiguous of {n}");
        for class in [LeafClass::Outside, LeafClass::Inside, LeafClass::Cut] {
            let count = bits
                .iter()
                .filter(|&&b| LeafClass::from_bits(b) == class)
                .count();
            assert!(
                count > n / 20,
                "only {count} {} leaves of {n}",
                class.name()
            );
        }
        // Cut leaves have their centres on both sides.
        let cut_in = bits.iter().filter(|&&b| b == CUT | CENTER_INSIDE).count();
        let cut_out = bits.iter().filter(|&&b| b == CUT).count();
        assert!(cut_in > 0 && cut_out > 0, "{cut_in} / {cut_out}");
    }

    #[test]
    fn classify_sphere_matches_brute_force() {
        brute_force_surface(&default_sphere(), 5);
    }

    #[test]
    fn classify_torus_matches_brute_force() {
        brute_force_surface(&default_torus(), 5);
    }

    /// Random octants at every level, near and on the surface, classified
    /// together and some of them alone (so through their own chain of
    /// ancestors only).
    fn random_octants(surface: &Surface, seed: u64, count: usize) {
        let (_, index) = fitted(surface);
        let tris = index.triangles();
        let mut rng = Rng(seed);
        let mut octants = Vec::new();
        for k in 0..count {
            let t = &tris[(rng.next() % tris.len() as u64) as usize];
            let (mut u, mut v) = (rng.unit(), rng.unit());
            if u + v > 1.0 {
                (u, v) = (1.0 - u, 1.0 - v);
            }
            let level = (1 + rng.next() % MAX_LEVEL as u64) as u8;
            let side = (ROOT_LEN >> level) as f64;
            let jitter = if k % 2 == 0 { 0.0 } else { 2.0 * side };
            let p: [f64; 3] = std::array::from_fn(|i| {
                let q = t.v[0][i] + u * (t.v[1][i] - t.v[0][i]) + v * (t.v[2][i] - t.v[0][i]);
                q + jitter * (rng.unit() - 0.5)
            });
            let c: [u32; 3] = std::array::from_fn(|i| {
                let x = p[i].clamp(0.0, ROOT_LEN as f64 - 1.0) as u32;
                x & !((ROOT_LEN >> level) - 1)
            });
            octants.push(Octant::new(c[0], c[1], c[2], level).unwrap());
        }
        // One call per level: octants of one level are disjoint once sorted
        // and deduplicated.
        let (mut n, mut skipped, mut cut) = (0, 0, 0);
        for level in 1..=MAX_LEVEL {
            let mut run: Vec<Octant> = octants
                .iter()
                .copied()
                .filter(|o| o.level() == level)
                .collect();
            run.sort_unstable();
            run.dedup();
            let bits = classify_leaves(&run, &index);
            for (k, (&o, &b)) in run.iter().zip(&bits).enumerate() {
                assert_eq!(b & CUT != 0, index.touches(o), "CUT of {o:?}");
                cut += (b & CUT != 0) as usize;
                match ray_inside(center_f64(o), tris) {
                    Some(inside) => {
                        assert_eq!(b & CENTER_INSIDE != 0, inside, "centre of {o:?}")
                    }
                    None => skipped += 1,
                }
                if k % 25 == 0 {
                    assert_eq!(classify_leaves(&[o], &index), [b], "{o:?} alone");
                }
            }
            n += run.len();
        }
        assert!(n > count / 2, "{n} of {count}");
        assert!(skipped * 100 <= n, "{skipped} ambiguous of {n}");
        assert!(cut > n / 4 && cut < n, "{cut} cut of {n}");
    }

    #[test]
    fn classify_random_octants_sphere() {
        random_octants(&default_sphere(), 0x5eed_0001, 3000);
    }

    #[test]
    fn classify_random_octants_torus() {
        random_octants(&default_torus(), 0x5eed_0002, 3000);
    }

    /// Volume of the kept leaves, in finest cells.
    fn kept_cells(leaves: &[Octant], bits: &[u8], keep: Keep, rule: CutRule) -> u64 {
        leaves
            .iter()
            .zip(bits)
            .filter(|(_, &b)| keeps(keep, rule, b))
            .map(|(l, _)| l.cell_end() - l.cell_begin())
            .sum()
    }

    fn volume_converges(surface: &Surface) {
        let (d, index) = fitted(surface);
        // The enclosed volume in finest cells (the lattice has 2^19 points
        // per side and 8^19 cells).
        let cell = d.side / ROOT_LEN as f64;
        let exact = surface.signed_volume().abs() / (cell * cell * cell);
        let mut last_err = f64::INFINITY;
        let mut last_band = u64::MAX;
        for level in 4..=7 {
            let leaves = leaves_of(&index, level, false);
            let bits = classify_leaves(&leaves, &index);
            let inside = kept_cells(&leaves, &bits, Keep::Inside, CutRule::Center);
            let outside = kept_cells(&leaves, &bits, Keep::Outside, CutRule::Center);
            assert_eq!(inside + outside, CELLS, "level {level}");
            assert_eq!(kept_cells(&leaves, &bits, Keep::All, CutRule::None), CELLS);
            for &b in &bits {
                assert!(
                    keeps(Keep::Inside, CutRule::Center, b)
                        != keeps(Keep::Outside, CutRule::Center, b)
                );
            }
            // Off the surface the classification is exact, so the solid lies
            // between the inside leaves without the cut ones and with them.
            let inner = kept_cells(&leaves, &bits, Keep::Inside, CutRule::None);
            let outer = kept_cells(&leaves, &bits, Keep::Inside, CutRule::All);
            assert!(
                (inner as f64) < exact && exact < outer as f64,
                "level {level}"
            );
            assert!(outer - inner < last_band, "level {level}");
            last_band = outer - inner;
            let err = (inside as f64 - exact).abs() / exact;
            assert!(
                err < last_err.max(2e-3),
                "level {level}: {err} after {last_err}"
            );
            last_err = err;
        }
        assert!(last_err < 0.01, "{last_err}");
    }

    #[test]
    fn classify_sphere_volume_converges() {
        volume_converges(&default_sphere());
    }

    #[test]
    fn classify_torus_volume_converges() {
        volume_converges(&default_torus());
    }

    /// The 12 triangles of the box `lo..hi`, outward (`flip`: inward).
    fn box_surface(lo: [f64; 3], hi: [f64; 3], flip: bool) -> Surface {
        let p = |i: usize| {
            [
                if i & 1 != 0 { hi[0] } else { lo[0] },
                if i & 2 != 0 { hi[1] } else { lo[1] },
                if i & 4 != 0 { hi[2] } else { lo[2] },
            ]
        };
        // Faces as corner quads, counter-clockwise seen from outside.
        let quads = [
            [0, 4, 6, 2], // -x
            [1, 3, 7, 5], // +x
            [0, 1, 5, 4], // -y
            [2, 6, 7, 3], // +y
            [0, 2, 3, 1], // -z
            [4, 5, 7, 6], // +z
        ];
        let mut tris = Vec::new();
        for q in quads {
            for t in [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] {
                let t = if flip { [t[0], t[2], t[1]] } else { t };
                tris.push(Triangle::new(p(t[0]), p(t[1]), p(t[2])));
            }
        }
        Surface::new(tris).unwrap()
    }

    #[test]
    fn classify_lattice_aligned_boxes() {
        // Lattice units are user units; box faces on level-5 boundaries.
        let d = Domain::cube([0.0; 3], ROOT_LEN as f64).unwrap();
        let u = (ROOT_LEN >> 5) as i64;
        let mid = (ROOT_LEN / 2) as i64;
        let boxes: [([i64; 3], [i64; 3]); 4] = [
            // The root's centre on a corner, an edge, a face, and inside.
            ([mid, mid, mid], [mid + 3 * u, mid + 5 * u, mid + 2 * u]),
            (
                [mid - 2 * u, mid, mid],
                [mid + 3 * u, mid + 4 * u, mid + 2 * u],
            ),
            (
                [mid - 3 * u, mid - 2 * u, mid],
                [mid + 4 * u, mid + u, mid + 6 * u],
            ),
            (
                [mid - 5 * u, mid - 3 * u, mid - 4 * u],
                [mid + 2 * u, mid + 6 * u, mid + u],
            ),
        ];
        for (bi, (lo, hi)) in boxes.into_iter().enumerate() {
            for flip in [false, true] {
                let f = |p: [i64; 3]| p.map(|c| c as f64);
                let s = box_surface(f(lo), f(hi), flip);
                let index = SurfaceIndex::new(&s, &d);
                for level in [5u8, 7] {
                    let leaves = leaves_of(&index, level, level == 7);
                    let bits = classify_leaves(&leaves, &index);
                    let h = (ROOT_LEN >> level) as i64;
                    let vol = |grow: i64| -> u64 {
                        // In finest cells, which are lattice units cubed.
                        (0..3)
                            .map(|k| (hi[k] - lo[k] + 2 * grow) as u64)
                            .product::<u64>()
                    };
                    let what = format!("box {bi} flip {flip} level {level}");
                    assert_eq!(
                        kept_cells(&leaves, &bits, Keep::Inside, CutRule::Center),
                        vol(0),
                        "{what}"
                    );
                    assert_eq!(
                        kept_cells(&leaves, &bits, Keep::Inside, CutRule::None),
                        vol(-h),
                        "{what}"
                    );
                    assert_eq!(
                        kept_cells(&leaves, &bits, Keep::Inside, CutRule::All),
                        vol(h),
                        "{what}"
                    );
                    assert_eq!(
                        kept_cells(&leaves, &bits, Keep::Outside, CutRule::Center),
                        CELLS - vol(0),
                        "{what}"
                    );
                    // A slice is classified as in the whole run.
                    let (a, b) = (leaves.len() / 3, 2 * leaves.len() / 3 + 1);
                    assert_eq!(classify_leaves(&leaves[a..b], &index), bits[a..b], "{what}");
                    let (_, bf_skipped) = check_brute_force(&leaves, &index, &bits);
                    // Centres on faces are ambiguous for the float ray test.
                    assert!(bf_skipped < leaves.len() / 4, "{what}: {bf_skipped}");
                }
            }
        }
    }

    #[test]
    fn classify_slices_match_whole_run() {
        for s in [default_sphere(), default_torus()] {
            let (_, index) = fitted(&s);
            let leaves = leaves_of(&index, 6, true);
            let whole = classify_leaves(&leaves, &index);
            let n = leaves.len();
            let cuts = [0, n / 7, n / 2 + 3, n];
            let mut joined = Vec::new();
            for w in cuts.windows(2) {
                joined.extend(classify_leaves(&leaves[w[0]..w[1]], &index));
            }
            assert_eq!(joined, whole);
            // Every other leaf (a run with gaps) too.
            let sparse: Vec<Octant> = leaves.iter().copied().step_by(2).collect();
            let expect: Vec<u8> = whole.iter().copied().step_by(2).collect();
            assert_eq!(classify_leaves(&sparse, &index), expect);
            assert!(classify_leaves(&[], &index).is_empty());
        }
    }

    #[test]
    fn classify_ignores_orientation() {
        let s = default_torus();
        let flipped = Surface::new(
            s.triangles()
                .iter()
                .map(|t| Triangle::new(t.v[0], t.v[2], t.v[1]))
                .collect(),
        )
        .unwrap();
        let (_, index) = fitted(&s);
        let (_, index_flipped) = fitted(&flipped);
        let leaves = leaves_of(&index, 6, false);
        assert_eq!(
            classify_leaves(&leaves, &index),
            classify_leaves(&leaves, &index_flipped)
        );
    }

    /// Segments through shared vertices and edges of a closed octahedron,
    /// exactly: each leaves the solid, so it must cross an odd number of
    /// triangles; segments inside or outside cross an even number.
    #[test]
    fn classify_crossings_through_vertices_and_edges() {
        let r = 1000i64;
        let v = [
            [r, 0, 0],
            [-r, 0, 0],
            [0, r, 0],
            [0, -r, 0],
            [0, 0, r],
            [0, 0, -r],
        ];
        let mut tris = Vec::new();
        for (x, y, z) in [
            (0, 2, 4),
            (2, 1, 4),
            (1, 3, 4),
            (3, 0, 4),
            (2, 0, 5),
            (1, 2, 5),
            (3, 1, 5),
            (0, 3, 5),
        ] {
            let t = [v[x], v[y], v[z]];
            let n = normal(&t);
            let nsign = n.iter().find(|&&c| c != 0).map_or(0, |&c| c.signum() as i8);
            tris.push(FixedTri { v: t, nsign });
        }
        let count = |p: [i64; 3], q: [i64; 3]| tris.iter().filter(|t| crosses(p, q, t)).count();
        let origin = [0, 0, 0];
        // Through every vertex, every edge midpoint, every face centre.
        let mut targets: Vec<[i64; 3]> = v.to_vec();
        for a in 0..6 {
            for b in 0..6 {
                if a / 2 != b / 2 {
                    targets.push(std::array::from_fn(|k| (v[a][k] + v[b][k]) / 2));
                }
            }
        }
        for sx in [-1, 1] {
            for sy in [-1, 1] {
                for sz in [-1, 1] {
                    targets.push([sx * r / 3, sy * r / 3, sz * r / 3]);
                }
            }
        }
        for t in &targets {
            let far = t.map(|c| 3 * c);
            assert_eq!(count(origin, far) % 2, 1, "origin to {far:?}");
            assert_eq!(count(far, origin) % 2, 1, "{far:?} to origin");
            // Ending exactly on the surface: the perturbation puts the end
            // on one side, consistently for both directions.
            let a = count(origin, *t) % 2;
            let b = count(*t, far) % 2;
            assert_eq!((a + b) % 2, 1, "split at {t:?}");
            // Outside to outside along the surface's own plane or edge.
            let beyond = t.map(|c| 2 * c);
            assert_eq!(count(beyond, far) % 2, 0, "{beyond:?} to {far:?}");
        }
        // Along an edge line from vertex to vertex, outside the solid.
        assert_eq!(count([2 * r, -r, 0], [-r, 2 * r, 0]) % 2, 0);
        // And from the centre of each child octant to the origin, which the
        // top-down walk does with the batched test.
        for i in 0..8u32 {
            let s = [
                if i & 1 != 0 { 1 } else { -1 },
                if i & 2 != 0 { 1 } else { -1 },
                if i & 4 != 0 { 1 } else { -1 },
            ];
            for h in [r / 3, r / 2, r, 2 * r] {
                let q = s.map(|c| c * h);
                let direct = tris.iter().filter(|t| crosses(origin, q, t)).count() % 2;
                let batched = tris
                    .iter()
                    .filter(|t| crossings_from_center(origin, h, t, 1 << i).0 != 0)
                    .count()
                    % 2;
                assert_eq!(direct, batched, "child {i} at {h}");
                // (r/3)(1,1,1) is on a face: inside for this perturbation or
                // not, but 2r(1,1,1) is outside.
                if h == 2 * r {
                    assert_eq!(direct, 1);
                }
                if h == r / 2 || h == r {
                    // (r/2)(1,1,1) and r(1,1,1) are outside (|x|+|y|+|z| > r).
                    assert_eq!(direct, 1, "child {i} at {h}");
                }
            }
        }
    }

    /// The batched per-child box test against `triangle_box_overlap` on
    /// each child, for triangles that touch or nearly touch a child box at
    /// a corner, an edge or a face with non-dyadic coordinates, where the
    /// floating-point verdicts are closest to a tie.
    #[test]
    fn classify_batched_box_test_agrees() {
        let mut rng = Rng(0xb0c5_7e57);
        let d = Domain::cube([0.0; 3], ROOT_LEN as f64).unwrap();
        let (mut sure, mut unsure, mut touching, mut crossing) = (0usize, 0usize, 0usize, 0usize);
        for case in 0..4000 {
            let level = (1 + rng.next() % (MAX_LEVEL as u64 - 1)) as u8;
            let side = ROOT_LEN >> level;
            let cells = (ROOT_LEN / side) as u64;
            let c: [u32; 3] = std::array::from_fn(|_| (rng.next() % cells) as u32 * side);
            let o = Octant::new(c[0], c[1], c[2], level).unwrap();
            let half = (side / 2) as f64;
            let center = c.map(|x| x as f64 + half);
            let scale = [0.01 * half, half, 3.0 * half, 65536.0][case % 4];
            let mut v;
            if case % 5 == 4 {
                // A triangle around a point of a segment from the centre to a
                // child's centre (the parity test's segments).
                let i = rng.next() % 8;
                let tau = [0.0, 1.0, rng.unit()][(rng.next() % 3) as usize];
                let p: [f64; 3] = std::array::from_fn(|k| {
                    let s = if i >> k & 1 != 0 { 0.5 } else { -0.5 };
                    center[k] + tau * s * half + 1e-7 * half * (rng.unit() - 0.5)
                });
                let a: [f64; 3] = std::array::from_fn(|_| scale * (rng.unit() - 0.5));
                let b: [f64; 3] = std::array::from_fn(|_| scale * (rng.unit() - 0.5));
                v = [
                    std::array::from_fn(|k| p[k] + a[k]),
                    std::array::from_fn(|k| p[k] + b[k]),
                    std::array::from_fn(|k| p[k] - a[k] - b[k]),
                ];
            } else {
                // A point on a child's boundary: a corner, an edge or a face.
                let mut p: [f64; 3] =
                    std::array::from_fn(|k| c[k] as f64 + half * (rng.next() % 3) as f64);
                for x in p.iter_mut().take(case % 3) {
                    *x += half * rng.unit();
                }
                // Two more vertices, nearly all on one side of that point.
                let dir: [f64; 3] = std::array::from_fn(|_| rng.unit() - 0.5);
                v = [p; 3];
                for vi in v.iter_mut().skip(1) {
                    for k in 0..3 {
                        let away = if dir[k] > 0.0 { 1.0 } else { -1.0 };
                        vi[k] = p[k] + scale * (away * rng.unit() + 0.3 * (rng.unit() - 0.5)) / 3.0;
                    }
                }
            }
            let tri = Triangle::new(v[0], v[1], v[2]);
            let s = match Surface::new(vec![tri]) {
                Ok(s) => s,
                Err(_) => continue,
            };
            let index = SurfaceIndex::new(&s, &d);
            let cl = Classifier::new(&index, false);
            let t = &cl.tris[0];
            let m = cl.child_masks(0, center, half, 0xff, 0xff);
            let pc = cl.center(o);
            let h = cl.to_fixed((side / 4) as u64);
            for i in 0..8u32 {
                let (lo, hi) = o.child(i).bounds_f64();
                let exact = triangle_box_overlap(t, lo, hi);
                let bit = 1u8 << i;
                if m.unsure & bit != 0 {
                    unsure += 1;
                } else {
                    sure += 1;
                    assert_eq!(m.touch & bit != 0, exact, "case {case} child {i}");
                }
                touching += exact as usize;
                if exact {
                    assert!(m.near & bit != 0, "case {case} child {i}");
                }
                // A crossing needs the triangle near the child and its plane
                // between the two centres.
                let ft = &cl.fixed[0];
                if ft.nsign != 0 && cl.crossings(o, pc, h, ft, bit).0 != 0 {
                    crossing += 1;
                    assert!(m.near & m.plane & bit != 0, "case {case} child {i}");
                }
            }
        }
        assert!(
            touching > 2000 && sure > 5 * unsure && unsure > 100 && crossing > 300,
            "{touching} {sure} {unsure} {crossing}"
        );
    }

    #[test]
    fn round_half_away_matches_round() {
        let mut x = 0x2545_f491_4f6c_dd1du64;
        let mut values = vec![
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.5,
            -2.5,
            0.499_999_999_999_999_94,
            -0.499_999_999_999_999_94,
            4_503_599_627_370_495.5,
            -4_503_599_627_370_495.5,
            (1u64 << 39) as f64 + 0.5,
        ];
        for _ in 0..10_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let v = (x >> 11) as f64 / (1u64 << 53) as f64;
            values.push((v - 0.5) * (1u64 << 41) as f64);
            values.push((v - 0.5) * 8.0);
        }
        for v in values {
            assert_eq!(round_half_away(v), v.round() as i64, "{v}");
        }
    }

    #[test]
    fn classify_names_and_rules() {
        assert_eq!(Keep::parse("inside").unwrap(), Keep::Inside);
        assert_eq!(Keep::parse("outside").unwrap().name(), "outside");
        assert_eq!(Keep::parse("all").unwrap(), Keep::All);
        assert!(Keep::parse("in").is_err());
        assert_eq!(CutRule::parse("none").unwrap(), CutRule::None);
        assert_eq!(CutRule::parse("all").unwrap().name(), "all");
        assert_eq!(CutRule::default(), CutRule::Center);
        assert!(CutRule::parse("centre").is_err());
        assert_eq!(LeafClass::from_bits(0), LeafClass::Outside);
        assert_eq!(LeafClass::from_bits(CENTER_INSIDE), LeafClass::Inside);
        assert_eq!(LeafClass::from_bits(CUT).name(), "cut");
        assert_eq!(LeafClass::from_bits(CUT | CENTER_INSIDE), LeafClass::Cut);
        for bits in 0..4u8 {
            let inside = bits & CENTER_INSIDE != 0;
            let cut = bits & CUT != 0;
            assert!(keeps(Keep::All, CutRule::None, bits));
            assert_eq!(keeps(Keep::Inside, CutRule::Center, bits), inside);
            assert_eq!(keeps(Keep::Outside, CutRule::Center, bits), !inside);
            assert_eq!(keeps(Keep::Inside, CutRule::None, bits), inside && !cut);
            assert_eq!(keeps(Keep::Outside, CutRule::None, bits), !inside && !cut);
            assert_eq!(keeps(Keep::Inside, CutRule::All, bits), inside || cut);
            assert_eq!(keeps(Keep::Outside, CutRule::All, bits), !inside || cut);
        }
    }

    /// The surface with the facets `which` reversed.
    fn reversed_where(s: &Surface, which: impl Fn(usize) -> bool) -> Surface {
        let t = s
            .triangles()
            .iter()
            .enumerate()
            .map(|(i, t)| {
                if which(i) {
                    Triangle::new(t.v[0], t.v[2], t.v[1])
                } else {
                    *t
                }
            })
            .collect();
        Surface::new(t).unwrap()
    }

    /// A coarse unit sphere (1280 facets) without the facets whose centroid
    /// is above `z`: one hole around the pole.
    fn holed_sphere(z: f64) -> Surface {
        let s = sphere([0.0; 3], 1.0, 3);
        Surface::new(
            s.triangles()
                .iter()
                .filter(|t| t.centroid()[2] < z)
                .copied()
                .collect(),
        )
        .unwrap()
    }

    #[test]
    fn inside_rule_names_and_auto_choice() {
        assert_eq!(InsideRule::parse("parity").unwrap(), InsideRule::Parity);
        assert_eq!(InsideRule::parse("winding").unwrap().name(), "winding");
        assert_eq!(InsideRule::parse("auto").unwrap(), InsideRule::default());
        assert!(InsideRule::parse("wind").is_err());
        let report = |s: &Surface| diagnose(s);
        let (r, why) = InsideRule::auto_choice(&report(&default_torus()));
        assert_eq!(r, InsideRule::Parity, "{why}");
        let (r, why) = InsideRule::auto_choice(&report(&holed_sphere(0.8)));
        assert_eq!(r, InsideRule::Winding);
        assert!(why.contains("boundary edges"), "{why}");
        let s = default_sphere();
        let (r, why) = InsideRule::auto_choice(&report(&reversed_where(&s, |i| i == 3)));
        assert_eq!(r, InsideRule::Winding);
        assert!(why.contains("3 inconsistently oriented edges"), "{why}");
        let mut two = s.triangles().to_vec();
        two.extend(sphere([3.0, 0.0, 0.0], 1.0, 2).triangles());
        let (r, why) = InsideRule::auto_choice(&report(&Surface::new(two).unwrap()));
        assert_eq!((r, why.as_str()), (InsideRule::Winding, "2 components"));
        assert_eq!(
            InsideRule::Parity.resolve(|| unreachable!()),
            InsideRule::Parity
        );
        assert_eq!(InsideRule::Auto.resolve(|| report(&s)), InsideRule::Parity);
    }

    #[test]
    fn winding_equals_parity_on_one_closed_surface() {
        // One closed, outward surface: the winding number is 0 or 1, the
        // parity of the crossings.
        for s in [default_sphere(), default_torus()] {
            let (_, index) = fitted(&s);
            let leaves = leaves_of(&index, 6, true);
            let parity = classify_leaves(&leaves, &index);
            let w = InsideClassifier::new(&index, InsideRule::Winding);
            assert_eq!(w.rule(), InsideRule::Winding);
            let sum = w.summary().unwrap();
            assert_eq!(
                (sum.components, sum.reversed_facets, sum.cap_triangles),
                (1, 0, 0)
            );
            assert_eq!(w.classify(&leaves), parity);
            let auto = InsideClassifier::new(&index, InsideRule::Auto);
            assert_eq!(auto.rule(), InsideRule::Parity);
            assert!(auto.summary().is_none());
        }
    }

    #[test]
    fn winding_ignores_reversed_facets() {
        // Half the facets at random, or all of them, reversed: classified
        // like the clean sphere, leaf by leaf.
        let s = default_sphere();
        let mut rng = Rng(77);
        let coin: Vec<bool> = (0..s.len()).map(|_| rng.next().is_multiple_of(2)).collect();
        let (_, clean) = fitted(&s);
        let leaves = leaves_of(&clean, 6, true);
        let expect = classify_leaves(&leaves, &clean);
        for (name, messy) in [
            ("half", reversed_where(&s, |i| coin[i])),
            ("all", reversed_where(&s, |_| true)),
        ] {
            let (_, index) = fitted(&messy);
            // Auto: an inward but consistent sphere is closed, for parity.
            let auto = InsideClassifier::new(&index, InsideRule::Auto).rule();
            let want = if name == "all" {
                InsideRule::Parity
            } else {
                InsideRule::Winding
            };
            assert_eq!(auto, want, "{name}");
            let c = InsideClassifier::new(&index, InsideRule::Winding);
            let reversed = c.summary().unwrap().reversed_facets;
            let want = if name == "all" {
                s.len()
            } else {
                coin.iter().filter(|&&b| b).count()
            };
            assert_eq!(reversed, want, "{name}");
            assert_eq!(c.classify(&leaves), expect, "{name}");
        }
    }

    /// Every leaf's centre bit against the winding number summed directly
    /// over the (outward) surface; returns the number of leaves whose
    /// winding number is away from 0 and 1 (where holes matter). Centres are
    /// moved by `(1e-3, 1e-6, 1e-9)` lattice units, which is what the
    /// classification's infinitesimal perturbation does to centres on the
    /// surface.
    fn check_against_direct_winding(index: &SurfaceIndex, leaves: &[Octant], bits: &[u8]) -> usize {
        let tris = index.triangles();
        let parity = classify_leaves(leaves, index);
        let (mut mid, mut ties) = (0, 0);
        for (i, (&l, &b)) in leaves.iter().zip(bits).enumerate() {
            assert_eq!(b & CUT, parity[i] & CUT, "{l:?}: cut differs");
            let c = center_f64(l);
            let w = winding_number(tris, [c[0] + 1e-3, c[1] + 1e-6, c[2] + 1e-9]);
            if (w - 0.5).abs() < 1e-6 {
                ties += 1;
                continue;
            }
            assert_eq!(b & CENTER_INSIDE != 0, w > 0.5, "{l:?}: w = {w}");
            mid += (0.02..0.98).contains(&w) as usize;
        }
        assert!(ties * 100 < leaves.len(), "{ties} ties");
        mid
    }

    #[test]
    fn winding_on_open_surfaces_matches_direct_summation() {
        for (name, s) in [
            ("small hole", holed_sphere(0.9)),
            ("large hole", holed_sphere(0.3)),
            ("bowl", holed_sphere(-0.2)),
        ] {
            let (_, index) = fitted(&s);
            let leaves = leaves_of(&index, 6, true);
            let c = InsideClassifier::new(&index, InsideRule::Auto);
            assert_eq!(c.rule(), InsideRule::Winding);
            let sum = c.summary().unwrap();
            assert_eq!(sum.boundary_loops, 1, "{name}");
            let bits = c.classify(&leaves);
            let mid = check_against_direct_winding(&index, &leaves, &bits);
            assert!(mid > 100, "{name}: {mid}");
            // Parity is wrong somewhere near the hole.
            let parity = classify_leaves(&leaves, &index);
            assert_ne!(parity, bits, "{name}");
        }
    }

    #[test]
    fn winding_on_an_open_lattice_aligned_box() {
        // A box on level-5 planes without its top face: centres of coarser
        // leaves lie in the plane of the opening (ties, w = 1/2) and the cap
        // is a fan in that plane.
        let d = Domain::cube([0.0; 3], ROOT_LEN as f64).unwrap();
        let u = (ROOT_LEN >> 5) as f64;
        let m = (ROOT_LEN / 2) as f64;
        let b = box_surface(
            [m - 5.0 * u, m - 3.0 * u, m - 4.0 * u],
            [m + 2.0 * u, m + 6.0 * u, m + 6.0 * u],
            false,
        );
        // Faces are facets 2k, 2k + 1 of -x, +x, -y, +y, -z, +z: drop +z.
        let open = Surface::new(b.triangles()[..10].to_vec()).unwrap();
        let index = SurfaceIndex::new(&open, &d);
        let c = InsideClassifier::new(&index, InsideRule::Winding);
        assert_eq!(c.summary().unwrap().cap_triangles, 4);
        for level in [4u8, 6] {
            let leaves = leaves_of(&index, level, true);
            let bits = c.classify(&leaves);
            check_against_direct_winding(&index, &leaves, &bits);
        }
    }

    #[test]
    fn winding_gives_the_union_of_overlapping_parts() {
        // Two unit spheres with centres 1 apart, as one soup: the winding
        // number is 2 where they overlap, which parity calls outside.
        let a = sphere([0.0; 3], 1.0, 3);
        let b = sphere([1.0, 0.0, 0.0], 1.0, 3);
        let mut t = a.triangles().to_vec();
        t.extend(b.triangles());
        let s = Surface::new(t).unwrap();
        let (d, index) = fitted(&s);
        let leaves = leaves_of(&index, 6, false);
        let c = InsideClassifier::new(&index, InsideRule::Auto);
        assert_eq!(c.rule(), InsideRule::Winding);
        let wb = c.classify(&leaves);
        let pb = classify_leaves(&leaves, &index);
        let (mut both, mut one) = (0, 0);
        for (i, &l) in leaves.iter().enumerate() {
            if wb[i] & CUT != 0 {
                assert_eq!(pb[i] & CUT, CUT, "{l:?}");
                continue;
            }
            // Uncut centres are at least half a leaf from the facets, far
            // more than the facets are from the spheres.
            let p = d.from_lattice(center_f64(l));
            let ina = norm(p) < 1.0;
            let inb = norm([p[0] - 1.0, p[1], p[2]]) < 1.0;
            assert_eq!(wb[i] & CENTER_INSIDE != 0, ina || inb, "{l:?}");
            assert_eq!(pb[i] & CENTER_INSIDE != 0, ina != inb, "{l:?}");
            both += (ina && inb) as usize;
            one += (ina != inb) as usize;
        }
        assert!(both > 50 && one > 50, "{both} {one}");
    }

    #[test]
    fn winding_slices_match_whole_run() {
        let s = holed_sphere(0.5);
        let (_, index) = fitted(&s);
        let leaves = leaves_of(&index, 7, true);
        let c = InsideClassifier::new(&index, InsideRule::Winding);
        let whole = c.classify(&leaves);
        let n = leaves.len();
        for parts in [2, 3, 7] {
            let mut joined = Vec::new();
            for k in 0..parts {
                joined.extend(c.classify(&leaves[k * n / parts..(k + 1) * n / parts]));
            }
            assert_eq!(joined, whole, "{parts} parts");
        }
        let sparse: Vec<Octant> = leaves.iter().copied().step_by(3).collect();
        let expect: Vec<u8> = whole.iter().copied().step_by(3).collect();
        assert_eq!(c.classify(&sparse), expect);
        // Alone, through its own chain of ancestors.
        for k in (0..n).step_by(97) {
            assert_eq!(c.classify(&leaves[k..k + 1]), [whole[k]], "{:?}", leaves[k]);
        }
    }

    #[test]
    fn winding_on_an_unwelded_soup() {
        // A sphere whose facets share no vertex (each corner moved by up to
        // 1e-6): every facet is a component with its own boundary, capped
        // by a fan of three, and keeps its (outward) orientation. The
        // cracks are far below the leaves, so the classes are parity's.
        let s = sphere([0.0; 3], 1.0, 3);
        let mut k = 0u64;
        let soup: Vec<Triangle> = s
            .triangles()
            .iter()
            .map(|t| Triangle {
                v: t.v.map(|p| {
                    p.map(|c| {
                        k += 1;
                        c + 1e-9 * ((k * 2_654_435_761) % 1000) as f64
                    })
                }),
            })
            .collect();
        let soup = Surface::new(soup).unwrap();
        let (_, index) = fitted(&soup);
        let leaves = leaves_of(&index, 6, true);
        let c = InsideClassifier::new(&index, InsideRule::Auto);
        assert_eq!(c.rule(), InsideRule::Winding);
        let sum = c.summary().unwrap();
        assert_eq!((sum.components, sum.reversed_facets), (s.len(), 0));
        assert_eq!(sum.cap_triangles, 3 * s.len());
        assert_eq!(c.classify(&leaves), classify_leaves(&leaves, &index));
    }
}
