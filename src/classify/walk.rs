//! The walk down the tree that classifies leaves: parity (or the signed
//! crossing count of the winding rule) carried from each octant's centre
//! to its children's, with the candidate triangles passed down.

use std::borrow::Cow;
use std::collections::HashMap;

use super::masks::*;
use super::rules::*;
use super::SharedCounts;
use crate::geometry::diagnostics::weld;
use crate::geometry::intersect::triangle_box_overlap;
use crate::geometry::predicates::*;
use crate::geometry::winding::{boundary_loops, orient_welded, WindingTree};
use crate::geometry::{Aabb, Triangle};
use crate::octree::octant::{Octant, LATTICE_BITS, MAX_LEVEL, ROOT_LEN};
use crate::refine::{scatter_by_child, SurfaceIndex};

/// The surface prepared for classification.
pub(crate) struct Classifier<'a> {
    /// Triangles in lattice units (for the touching tests): the surface's
    /// `surface_len` first (oriented for the winding rule), then the caps.
    pub(crate) tris: Cow<'a, [Triangle]>,
    /// Triangles `0..surface_len` are the surface; the others are caps,
    /// which count for crossings but never make a leaf cut.
    pub(crate) surface_len: usize,
    /// Their normals `(v1 - v0) x (v2 - v1)`, in floating point.
    pub(crate) normals: Vec<[f64; 3]>,
    /// Their bounding boxes (the index's, unless the winding rule added
    /// caps).
    pub(crate) bounds: Cow<'a, [Aabb]>,
    /// The same triangles in fixed point.
    pub(crate) fixed: Vec<FixedTri>,
    /// Fixed-point units per lattice unit is `2^shift`.
    pub(crate) shift: i32,
    /// A fixed-point unit in lattice units, `2^-shift`.
    pub(crate) unit: f64,
    /// How far candidate boxes are grown, in lattice units.
    pub(crate) grow: f64,
    /// Largest absolute coordinate of the triangles and the lattice: scales
    /// the floating-point error bounds.
    pub(crate) big: f64,
    /// Winding rule (else parity).
    pub(crate) winding: bool,
    /// The caps with positive area in fixed-point units, their tree ids
    /// indexing `cap_ids`; `None` when the surface has no boundary.
    pub(crate) caps: Option<WindingTree>,
    /// Index in `fixed` of each triangle of `caps`.
    pub(crate) cap_ids: Vec<u32>,
    pub(crate) summary: Option<WindingSummary>,
    /// The processor has AVX-512F: the child masks take the eight children
    /// side by side ([`crate::parallel::cores::avx512`]; the same bits).
    pub(crate) wide: bool,
    /// The root's count, when it comes from all ranks.
    pub(crate) root: Option<i32>,
}

/// Margin by which Barill et al.'s estimate of the caps' winding number
/// (beta 2, third order) must put a centre away from 1/2 to decide it: ten
/// times the largest error measured for that setting (5e-3, see the tests
/// of [`crate::geometry::winding`]).
pub(crate) const CAP_ESTIMATE_MARGIN: f64 = 0.05;
/// Error budget of the bounded evaluation for centres within the margin
/// (then the caps are summed exactly).
pub(crate) const CAP_POINT_BUDGET: f64 = 1e-3;
/// The same for a region.
pub(crate) const CAP_REGION_BUDGET: f64 = 0.1;
/// Nodes and triangles a region's bound may visit: a bound that needs more
/// (a region near many caps) would cost more than it saves.
pub(crate) const CAP_REGION_WORK: usize = 512;
/// Largest error of a region's bound on the caps' winding number for it to
/// be kept: wider intervals rarely decide a leaf.
pub(crate) const CAP_REGION_ERR: f64 = 0.25;

impl<'a> Classifier<'a> {
    pub(crate) fn new(index: &'a SurfaceIndex, winding: bool) -> Classifier<'a> {
        Classifier::with_shared(index, winding, None)
    }

    /// [`Classifier::new`]; with `shared`, the largest coordinate and the
    /// root's count of the whole surface, of which `index` holds a part
    /// (the distributed surface).
    pub(crate) fn with_shared(
        index: &'a SurfaceIndex,
        winding: bool,
        shared: Option<SharedCounts>,
    ) -> Classifier<'a> {
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
        let mut big = most.into_iter().fold(ROOT_LEN as f64, f64::max);
        if let Some(s) = shared {
            big = s.big;
        }
        let shift = shift_for(big);
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
            wide: crate::parallel::cores::avx512(),
            root: shared.map(|s| s.root_count),
        }
    }

    /// A lattice coordinate in fixed point (exact when `shift >= 0`).
    #[inline]
    pub(crate) fn to_fixed(&self, x: u64) -> i64 {
        if self.shift >= 0 {
            (x as i64) << self.shift
        } else {
            (x as f64 * 2f64.powi(self.shift)).round() as i64
        }
    }

    /// Centre of `o` in fixed point.
    #[inline]
    pub(crate) fn center(&self, o: Octant) -> [i64; 3] {
        let half = (o.side() / 2) as u64;
        o.coords().map(|c| self.to_fixed(c as u64 + half))
    }

    /// Whether the closed box `[lo, hi]` touches triangle `t`: refinement's
    /// rule.
    #[inline]
    pub(crate) fn touches(&self, t: u32, lo: [f64; 3], hi: [f64; 3]) -> bool {
        triangle_box_overlap(&self.tris[t as usize], lo, hi)
    }

    /// Signed count of surface crossings from a point beyond every vertex
    /// in `+x` (where the winding number is 0) to the root's centre, over
    /// all triangles: +1 for each entered from its positive side.
    pub(crate) fn root_count(&self) -> i32 {
        if let Some(c) = self.root {
            return c;
        }
        let p = self.center(Octant::ROOT);
        let far_x = far_x(&self.fixed, p);
        count_along(&self.fixed, p, far_x)
    }

    /// Whether the centre of `o` is inside, given the signed crossing count
    /// `count` there and, under the winding rule with caps, an interval
    /// holding the caps' winding number over a ball around `o`.
    pub(crate) fn inside(&self, o: Octant, count: i32, interval: Option<(f64, f64)>) -> bool {
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
    pub(crate) fn region_interval(&self, o: Octant) -> Option<(f64, f64)> {
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
    pub(crate) fn fill_uncut(
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
    pub(crate) fn walk(
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
    pub(crate) fn crossings(
        &self,
        o: Octant,
        p: [i64; 3],
        h: i64,
        t: &FixedTri,
        mask: u8,
    ) -> (u8, bool) {
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

/// Start of each child's leaves in `leaves` (all strictly inside `o`):
/// child `i` owns `leaves[b[i]..b[i + 1]]`.
#[inline]
pub(crate) fn split_by_child(o: Octant, leaves: &[Octant]) -> [usize; 9] {
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
pub(crate) fn gallop(leaves: &[Octant], key: u64) -> usize {
    let mut hi = 1;
    while hi < leaves.len() && leaves[hi - 1].key() < key {
        hi *= 2;
    }
    let lo = hi / 2;
    let hi = hi.min(leaves.len());
    lo + leaves[lo..hi].partition_point(|l| l.key() < key)
}

/// Fixed-point units per lattice unit are `2^shift` for a surface whose
/// largest coordinate (or the lattice's) is `big`: every fixed-point
/// coordinate, query points included, stays within 2^39 (+1 for the far
/// point), so differences stay below 2^41.
pub(crate) fn shift_for(big: f64) -> i32 {
    let mut shift = 20i32;
    while shift > -1000 && big * 2f64.powi(shift) > (1u64 << 39) as f64 {
        shift -= 1;
    }
    shift
}

/// One past the largest `x` of the triangles' vertices and `p`.
pub(crate) fn far_x(fixed: &[FixedTri], p: [i64; 3]) -> i64 {
    fixed
        .iter()
        .filter(|t| t.nsign != 0)
        .flat_map(|t| t.v.iter().map(|v| v[0]))
        .fold(p[0], i64::max)
        + 1
}

/// Signed count of crossings of `fixed` from the point `far_x` along `+x`
/// from `p` back to `p`: +1 for each entered from its positive side.
pub(crate) fn count_along(fixed: &[FixedTri], p: [i64; 3], far_x: i64) -> i32 {
    let q = [far_x, p[1], p[2]];
    let mut count = 0;
    for t in fixed {
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
