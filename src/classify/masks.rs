//! Child masks: what one triangle does to the eight children of an octant
//! (may touch, certainly touches, may separate the centres), computed for
//! all eight at once.

use super::walk::*;
use crate::geometry::predicates::*;
use crate::geometry::{fmax, fmin, Aabb};

/// Child masks: children whose bit `k` is set (`POS[k]`) or clear (`NEG[k]`).
pub(crate) const POS: [u8; 3] = [0b1010_1010, 0b1100_1100, 0b1111_0000];
pub(crate) const NEG: [u8; 3] = [0b0101_0101, 0b0011_0011, 0b0000_1111];
/// Direction of child `i`'s centre from its parent's centre.
pub(crate) const SX: [f64; 8] = [-1.0, 1.0, -1.0, 1.0, -1.0, 1.0, -1.0, 1.0];
pub(crate) const SY: [f64; 8] = [-1.0, -1.0, 1.0, 1.0, -1.0, -1.0, 1.0, 1.0];
pub(crate) const SZ: [f64; 8] = [-1.0, -1.0, -1.0, -1.0, 1.0, 1.0, 1.0, 1.0];

/// What one triangle does to the eight children of an octant (bit `i` for
/// child `i`).
#[derive(Clone, Copy, Default, Debug, PartialEq, Eq)]
pub(crate) struct ChildMasks {
    /// The triangle may touch the child's grown box (a superset of those it
    /// does): it stays a candidate below.
    pub(crate) near: u8,
    /// [`triangle_box_overlap`] certainly says the closed box touches.
    pub(crate) touch: u8,
    /// Too close to call in floating point: ask [`triangle_box_overlap`].
    pub(crate) unsure: u8,
    /// The child's centre may lie on the other side of the triangle's
    /// plane than the parent's centre.
    pub(crate) plane: u8,
    /// The triangle's grown box meets the segment from the parent's centre
    /// to the child's centre: only then can the segment cross it (most
    /// candidates of a large octant are far from its centre).
    pub(crate) seg: u8,
}

impl Classifier<'_> {
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
    pub(crate) fn child_masks(
        &self,
        t: u32,
        c: [f64; 3],
        side: f64,
        want: u8,
        leafy: u8,
    ) -> ChildMasks {
        #[cfg(target_arch = "x86_64")]
        if self.wide {
            // SAFETY: `wide` is set only where AVX-512F is.
            return unsafe { wide::child_masks(self, t, c, side, want, leafy) };
        }
        self.masks_with::<false>(t, c, side, want, leafy)
    }

    /// [`Classifier::child_masks`], the eight children's lanes side by
    /// side when `WIDE` (only inside a function compiled for AVX-512F).
    #[inline(always)]
    fn masks_with<const WIDE: bool>(
        &self,
        t: u32,
        c: [f64; 3],
        side: f64,
        want: u8,
        leafy: u8,
    ) -> ChildMasks {
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
            seg &= segments_meeting_box::<WIDE>(c, quarter, lo3, hi3, g);
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
        let rho = r.iter().flatten().fold(0.0f64, |m, x| fmax(m, x.abs()));
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
            let (t0, t1) = (fmin(fmin(p[0], p[1]), p[2]), fmax(fmax(p[0], p[1]), p[2]));
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
            let span = Span { h, t0, t1, rad };
            let [s, un, far, across] = plane_lanes::<WIDE>(&span, eta, g * l1 + eta, s0, s1);
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
                    let (t0, t1) = (fmin(pe[k], po), fmax(pe[k], po));
                    if (t0 < -eta && t1 > eta) || a == [0.0; 3] {
                        // The parent's centre projects well inside the
                        // triangle, so every child's box overlaps it here.
                        continue;
                    }
                    let tiny = a.iter().all(|x| x.abs() <= tiny_e);
                    let rad = half * (a[0].abs() + a[1].abs() + a[2].abs());
                    let h = [half * a[0], half * a[1], half * a[2]];
                    let span = Span { h, t0, t1, rad };
                    let (apart, close) = edge_lanes::<WIDE>(&span, eta, tiny, open);
                    sep |= apart;
                    open &= !apart;
                    unsure |= close;
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
}

/// A triangle's extent `[t0, t1]` on one separating axis, and what the
/// children's boxes give there: child `i`'s centre projects to
/// `SX[i] h[0] + SY[i] h[1] + SZ[i] h[2]` (the parent's centre to 0), its
/// box to that plus or minus `rad`.
struct Span {
    h: [f64; 3],
    t0: f64,
    t1: f64,
    rad: f64,
}

impl Span {
    /// Child `i`'s centre on the axis, and the gap between its box and
    /// the triangle (positive: apart).
    #[inline(always)]
    fn gap(&self, i: usize) -> (f64, f64) {
        let h = self.h;
        let x = SX[i] * h[0] + SY[i] * h[1] + SZ[i] * h[2];
        (x, fmax(self.t0 - x - self.rad, x - self.rad - self.t1))
    }
}

/// On the triangle's normal: the children certainly apart (gap above
/// `eta`), possibly touching (gap at least `-eta`), apart even when grown
/// (gap above `far`), and whose centre may lie across the plane from the
/// parent's (the plane known within `[s0, s1]`).
#[inline(always)]
fn plane_lanes<const WIDE: bool>(span: &Span, eta: f64, far: f64, s0: f64, s1: f64) -> [u8; 4] {
    #[cfg(target_arch = "x86_64")]
    if WIDE {
        // SAFETY: `WIDE` code runs only where AVX-512F is.
        return unsafe { wide::plane_lanes(span, eta, far, s0, s1) };
    }
    let mut out = [0u8; 4];
    for i in 0..8 {
        let (x, gap) = span.gap(i);
        out[0] |= ((gap > eta) as u8) << i;
        out[1] |= ((gap >= -eta) as u8) << i;
        out[2] |= ((gap > far) as u8) << i;
        let same = (s0 > 0.0) & (s0 > x) | (s1 < 0.0) & (s1 < x);
        out[3] |= (!same as u8) << i;
    }
    out
}

/// On an edge-by-box-axis product, for the children in `open`: those
/// certainly apart (never on a `tiny` axis), and those neither apart nor
/// clearly overlapping.
#[inline(always)]
fn edge_lanes<const WIDE: bool>(span: &Span, eta: f64, tiny: bool, open: u8) -> (u8, u8) {
    #[cfg(target_arch = "x86_64")]
    if WIDE {
        // SAFETY: `WIDE` code runs only where AVX-512F is.
        return unsafe { wide::edge_lanes(span, eta, tiny, open) };
    }
    let (mut apart, mut close) = (0u8, 0u8);
    let mut m = open;
    while m != 0 {
        let i = m.trailing_zeros() as usize;
        m &= m - 1;
        let (_, gap) = span.gap(i);
        // Without branches: the verdicts are close to random.
        let a = (gap > eta) & !tiny;
        apart |= (a as u8) << i;
        close |= ((!a & (gap >= -eta)) as u8) << i;
    }
    (apart, close)
}

/// Children whose segment from the parent's centre `c` to their own centre
/// (`quarter` away on each axis) meets the box `[lo, hi]` grown by `g`: the
/// parameter intervals of the three slabs along the diagonal must overlap.
/// Rounding is covered by a margin far below `g` in space.
#[inline(always)]
pub(crate) fn segments_meeting_box<const WIDE: bool>(
    c: [f64; 3],
    quarter: f64,
    lo: [f64; 3],
    hi: [f64; 3],
    g: f64,
) -> u8 {
    let inv = 1.0 / quarter;
    // Along axis k, the positive children enter the slab at `u[k]` and leave
    // at `w[k]`; the negative ones over `[-w[k], -u[k]]`.
    let u: [f64; 3] = std::array::from_fn(|k| (lo[k] - g - c[k]) * inv);
    let w: [f64; 3] = std::array::from_fn(|k| (hi[k] + g - c[k]) * inv);
    #[cfg(target_arch = "x86_64")]
    if WIDE {
        // SAFETY: `WIDE` code runs only where AVX-512F is.
        return unsafe { wide::segments(u, w) };
    }
    let mut out = 0u8;
    for i in 0..8 {
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        for k in 0..3 {
            let (a, b) = if i >> k & 1 != 0 {
                (u[k], w[k])
            } else {
                (-w[k], -u[k])
            };
            t0 = fmax(t0, a);
            t1 = fmin(t1, b);
        }
        out |= ((t0 <= t1 + SLACK) as u8) << i;
    }
    out
}

/// Margin of [`segments_meeting_box`]'s parameter intervals.
const SLACK: f64 = 1e-9;

/// [`crosses`] for the eight segments from `p` to `p + h s` (`s` in
/// `{-1, 1}^3`, child `i` has `s_k = +1` iff bit `k` of `i` is set), for the
/// children in `mask`; returns the mask of those crossing and whether `p` is
/// on the positive side. Shares the work that does not depend on the child.
#[inline]
pub(crate) fn crossings_from_center(p: [i64; 3], h: i64, t: &FixedTri, mask: u8) -> (u8, bool) {
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

/// The lanes of [`Classifier::child_masks`] with AVX-512F: child `i` in
/// lane `i`. Each lane does the scalar code's operations in its order,
/// with no fused multiply-adds, and `_mm512_max_pd(a, b)` is `fmax(a, b)`
/// (`a > b ? a : b`), so every verdict has the scalar code's bits.
#[cfg(target_arch = "x86_64")]
mod wide {
    use super::*;
    use std::arch::x86_64::*;

    /// [`Classifier::child_masks`] compiled for AVX-512F.
    ///
    /// # Safety
    /// The processor must have AVX-512F.
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn child_masks(
        cl: &Classifier,
        t: u32,
        c: [f64; 3],
        side: f64,
        want: u8,
        leafy: u8,
    ) -> ChildMasks {
        cl.masks_with::<true>(t, c, side, want, leafy)
    }

    /// `v[i]` in lane `i`.
    #[inline(always)]
    fn load(v: &[f64; 8]) -> __m512d {
        // SAFETY: an unaligned load of 64 bytes from an array of 64.
        unsafe { _mm512_loadu_pd(v.as_ptr()) }
    }

    /// Child centres and gaps ([`Span::gap`]) in all eight lanes.
    ///
    /// # Safety
    /// The processor must have AVX-512F.
    #[target_feature(enable = "avx512f")]
    #[inline]
    unsafe fn gaps(span: &Span) -> (__m512d, __m512d) {
        let (mul, add, sub) = (_mm512_mul_pd, _mm512_add_pd, _mm512_sub_pd);
        let h = span.h.map(|v| _mm512_set1_pd(v));
        let x = add(
            add(mul(load(&SX), h[0]), mul(load(&SY), h[1])),
            mul(load(&SZ), h[2]),
        );
        let rad = _mm512_set1_pd(span.rad);
        let below = sub(sub(_mm512_set1_pd(span.t0), x), rad);
        let above = sub(sub(x, rad), _mm512_set1_pd(span.t1));
        (x, _mm512_max_pd(below, above))
    }

    /// [`super::plane_lanes`].
    ///
    /// # Safety
    /// The processor must have AVX-512F.
    #[target_feature(enable = "avx512f")]
    #[inline]
    pub(super) unsafe fn plane_lanes(span: &Span, eta: f64, far: f64, s0: f64, s1: f64) -> [u8; 4] {
        let (x, gap) = gaps(span);
        let apart = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(gap, _mm512_set1_pd(eta));
        let close = _mm512_cmp_pd_mask::<_CMP_GE_OQ>(gap, _mm512_set1_pd(-eta));
        let far = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(gap, _mm512_set1_pd(far));
        let mut same = 0u8;
        if s0 > 0.0 {
            same |= _mm512_cmp_pd_mask::<_CMP_GT_OQ>(_mm512_set1_pd(s0), x);
        }
        if s1 < 0.0 {
            same |= _mm512_cmp_pd_mask::<_CMP_LT_OQ>(_mm512_set1_pd(s1), x);
        }
        [apart, close, far, !same]
    }

    /// [`super::edge_lanes`].
    ///
    /// # Safety
    /// The processor must have AVX-512F.
    #[target_feature(enable = "avx512f")]
    #[inline]
    pub(super) unsafe fn edge_lanes(span: &Span, eta: f64, tiny: bool, open: u8) -> (u8, u8) {
        let (_, gap) = gaps(span);
        let over = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(gap, _mm512_set1_pd(eta));
        let apart = if tiny { 0 } else { over & open };
        let close = _mm512_cmp_pd_mask::<_CMP_GE_OQ>(gap, _mm512_set1_pd(-eta)) & open & !apart;
        (apart, close)
    }

    /// [`super::segments_meeting_box`]'s lanes, from the slab parameters
    /// `u`, `w`.
    ///
    /// # Safety
    /// The processor must have AVX-512F.
    #[target_feature(enable = "avx512f")]
    #[inline]
    pub(super) unsafe fn segments(u: [f64; 3], w: [f64; 3]) -> u8 {
        let mut t0 = _mm512_setzero_pd();
        let mut t1 = _mm512_set1_pd(1.0);
        for k in 0..3 {
            // Lanes of the children on the positive side along `k` take
            // `[u, w]`, the others `[-w, -u]`.
            let a = _mm512_mask_blend_pd(POS[k], _mm512_set1_pd(-w[k]), _mm512_set1_pd(u[k]));
            let b = _mm512_mask_blend_pd(POS[k], _mm512_set1_pd(-u[k]), _mm512_set1_pd(w[k]));
            t0 = _mm512_max_pd(t0, a);
            t1 = _mm512_min_pd(t1, b);
        }
        let reach = _mm512_add_pd(t1, _mm512_set1_pd(SLACK));
        _mm512_cmp_pd_mask::<_CMP_LE_OQ>(t0, reach)
    }
}
