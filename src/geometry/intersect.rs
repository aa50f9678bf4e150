//! Triangle / axis-aligned box overlap by the separating-axis theorem.
//!
//! Candidate axes (Akenine-Möller 2001): the three box face normals, the
//! triangle normal, and the nine cross products of a triangle edge with a
//! box axis. For convex sets these 13 axes are enough: if none separates,
//! the sets intersect.
//!
//! # Touching rule
//!
//! The box and the triangle are both *closed* sets. They overlap iff no axis
//! separates them with a strictly positive gap: on every axis, with `[t0, t1]`
//! the triangle's projection and `[b0, b1]` the box's, they are separated iff
//! `t0 > b1 || t1 < b0`. Consequently a triangle that touches the box only at
//! a box face, edge or corner overlaps it, and a triangle lying exactly in the
//! plane of a box face overlaps it if it meets that face. A gap of any
//! positive size (even `1e-9`) means no overlap.
//!
//! Degenerate triangles (segments and points) are handled: cross-product
//! axes of zero length are skipped, and the remaining axes (box normals and
//! segment-direction x box-axis products) are exactly the candidate set for
//! a segment or a point against a box.
//!
//! # Precision
//!
//! The box-normal tests compare the raw coordinates, so they are exact. The
//! other axes work on coordinates relative to `box_min`, which keeps the
//! numbers small for a small box far from the origin; a vertex lying exactly
//! on a box corner or face is then mapped to exactly the same value as that
//! corner, so exact contact is detected on those axes too. When all inputs
//! are small integers (or dyadic values of similar size) every operation is
//! exact and the result is the exact answer for closed sets. Inputs must be
//! finite.

use super::vector::{cross, dot, sub};
use super::{fmax, Triangle};

/// True if the closed triangle and the closed box `[box_min, box_max]` share
/// at least one point (see the module documentation for the touching rule).
/// A box with `box_min > box_max` on some axis is empty and overlaps nothing.
pub fn triangle_box_overlap(tri: &Triangle, box_min: [f64; 3], box_max: [f64; 3]) -> bool {
    let [p, q, r] = tri.v;
    // Box face normals, on untranslated coordinates so they are exact.
    for k in 0..3 {
        let lo = p[k].min(q[k]).min(r[k]);
        let hi = p[k].max(q[k]).max(r[k]);
        if box_min[k] > box_max[k] || lo > box_max[k] || hi < box_min[k] {
            return false;
        }
    }

    let v = [sub(p, box_min), sub(q, box_min), sub(r, box_min)];
    let h = sub(box_max, box_min);
    let e = [sub(v[1], v[0]), sub(v[2], v[1]), sub(v[0], v[2])];

    if separates(cross(e[0], e[1]), &v, h) {
        return false;
    }
    const AXES: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for edge in &e {
        for axis in &AXES {
            if separates(cross(*edge, *axis), &v, h) {
                return false;
            }
        }
    }
    true
}

/// Whether one of the nine edge axes of the overlap test (a triangle edge
/// crossed with a box axis) puts the triangle more than `d` away from the
/// closed box, gaps measured along unit axes: then their distance is more
/// than `d`. A lower bound only: `false` does not mean they are within `d`.
/// The box's own axes and the triangle's normal are the callers' cheaper
/// tests (a box gap, [`plane_apart`]).
///
/// Written out per axis, without branches on the data: the axis
/// `e x u_k` has two non-zero components (`e[l]` at `j`, `-e[j]` at `l`,
/// `j, k, l` cyclic), the edge's two ends project to one point (the
/// opposite vertex gives the other end of the triangle's interval), and
/// the box projects to its centre's projection plus or minus a radius.
pub fn edges_apart(tri: &Triangle, box_min: [f64; 3], box_max: [f64; 3], d: f64) -> bool {
    let [p, q, r] = tri.v;
    let v = [sub(p, box_min), sub(q, box_min), sub(r, box_min)];
    let c = sub(box_max, box_min).map(|x| 0.5 * x);
    let d2 = d * d;
    let mut apart = false;
    for i in 0..3 {
        let (a, b) = (v[i], v[(i + 2) % 3]);
        let e = sub(v[(i + 1) % 3], a);
        for k in 0..3 {
            let (j, l) = ((k + 1) % 3, (k + 2) % 3);
            let (pa, pb) = (a[j] * e[l] - a[l] * e[j], b[j] * e[l] - b[l] * e[j]);
            let centre = c[j] * e[l] - c[l] * e[j];
            let radius = e[l].abs() * c[j] + e[j].abs() * c[l];
            let (t_min, t_max) = if pa < pb { (pa, pb) } else { (pb, pa) };
            let g = fmax(t_min - (centre + radius), (centre - radius) - t_max);
            apart |= g > 0.0 && g * g > d2 * (e[j] * e[j] + e[l] * e[l]);
        }
    }
    apart
}

/// Whether the triangle's plane puts it more than `d` away from the closed
/// box.
#[inline]
pub fn plane_apart(tri: &Triangle, box_min: [f64; 3], box_max: [f64; 3], d: f64) -> bool {
    let [p, q, r] = tri.v;
    let v = [sub(p, box_min), sub(q, box_min), sub(r, box_min)];
    let n = cross(sub(v[1], v[0]), sub(v[2], v[1]));
    // All three vertices project to one point; the box, to its centre's
    // projection plus or minus a radius.
    let c = sub(box_max, box_min).map(|x| 0.5 * x);
    let (t, centre) = (dot(n, v[0]), dot(n, c));
    let radius = n[0].abs() * c[0] + n[1].abs() * c[1] + n[2].abs() * c[2];
    let g = (t - centre).abs() - radius;
    g > 0.0 && g * g > d * d * dot(n, n)
}

/// True if `axis` separates the triangle `v` from the box `[0, h]` with a
/// strictly positive gap. A zero axis separates nothing.
/// (Written out rather than through [`gap`]: this is the hottest test of
/// surface refinement, and the two comparisons measured faster.)
#[inline]
fn separates(axis: [f64; 3], v: &[[f64; 3]; 3], h: [f64; 3]) -> bool {
    if axis == [0.0; 3] {
        return false;
    }
    let d0 = dot(axis, v[0]);
    let d1 = dot(axis, v[1]);
    let d2 = dot(axis, v[2]);
    let t_min = d0.min(d1).min(d2);
    let t_max = d0.max(d1).max(d2);
    // The box [0, h] projects onto [sum of negative terms, sum of positive
    // terms] of axis[k] * h[k].
    let (mut b_min, mut b_max) = (0.0, 0.0);
    for k in 0..3 {
        let t = axis[k] * h[k];
        if t > 0.0 {
            b_max += t;
        } else {
            b_min += t;
        }
    }
    t_min > b_max || t_max < b_min
}

/// The separating-axis test of [`triangle_box_overlap`] for one triangle
/// against several boxes at once, a box per vector lane, written once for
/// every vector width, with its entry point `triangle_boxes_overlap` (eight
/// boxes, a vector's lanes at a time). The module that expands it defines
/// the vector type `V` and names the target feature, the number of lanes
/// and the intrinsics for the load, `splat`, `sub`, `mul` and `add`; it
/// defines these primitives too (each lane by lane, with
/// the scalar operation's rounding): `min` and `max` (with `f64::min`'s and
/// `f64::max`'s answers for NaN), `gt` and `lt` (the lanes' bits of an
/// ordered comparison), `is_zero`, and `split_add(b_min, b_max, t)` (`t`
/// added to `b_max` where it is positive, to `b_min` elsewhere).
///
/// Each lane does the scalar test's operations in its order, with no fused
/// multiply-adds, so every lane has the scalar test's verdict; the lanes
/// are only not cut short at their first separating axis.
#[cfg(target_arch = "x86_64")]
macro_rules! box_lanes {
    ($feature:literal, $lanes:literal, $load:ident, $splat:ident, $sub:ident, $mul:ident, $add:ident) => {
        /// The boxes of `want` that the closed triangle touches: bit `i`
        /// when `triangle_box_overlap(tri, [lo[0][i], lo[1][i], lo[2][i]],
        /// ..hi..)` holds, the boxes taken as many at a time as a vector
        /// has lanes.
        ///
        /// # Safety
        /// The processor must have the module's target feature.
        #[target_feature(enable = $feature)]
        pub(crate) unsafe fn triangle_boxes_overlap(
            tri: &Triangle,
            lo: &[[f64; 8]; 3],
            hi: &[[f64; 8]; 3],
            want: u8,
        ) -> u8 {
            const LANES: usize = $lanes;
            let mask = (0xffu16 >> (8 - LANES)) as u8;
            let mut out = 0u8;
            for first in (0..8).step_by(LANES) {
                let w = want >> first & mask;
                if w != 0 {
                    // SAFETY: `LANES` values from `first`, within the
                    // arrays of eight.
                    let load = |v: &[f64; 8]| unsafe { $load(v.as_ptr().add(first)) };
                    out |= overlap(tri, lo.map(|v| load(&v)), hi.map(|v| load(&v)), w) << first;
                }
            }
            out
        }

        #[target_feature(enable = $feature)]
        #[inline]
        fn splat(x: f64) -> V {
            $splat(x)
        }

        #[target_feature(enable = $feature)]
        #[inline]
        fn sub(a: V, b: V) -> V {
            $sub(a, b)
        }

        #[target_feature(enable = $feature)]
        #[inline]
        fn mul(a: V, b: V) -> V {
            $mul(a, b)
        }

        #[target_feature(enable = $feature)]
        #[inline]
        fn add(a: V, b: V) -> V {
            $add(a, b)
        }

        /// The lanes of `want` whose box `[bmin, bmax]` the closed triangle
        /// touches.
        #[target_feature(enable = $feature)]
        #[inline]
        fn overlap(tri: &Triangle, bmin: [V; 3], bmax: [V; 3], want: u8) -> u8 {
            let [p, q, r] = tri.v;
            let mut open = want;
            for k in 0..3 {
                let tlo = p[k].min(q[k]).min(r[k]);
                let thi = p[k].max(q[k]).max(r[k]);
                let out = gt(bmin[k], bmax[k]) | gt(splat(tlo), bmax[k]) | lt(splat(thi), bmin[k]);
                open &= !out;
            }
            if open == 0 {
                return 0;
            }
            let at = |x: [f64; 3]| -> [V; 3] { std::array::from_fn(|k| sub(splat(x[k]), bmin[k])) };
            let vsub =
                |a: [V; 3], b: [V; 3]| -> [V; 3] { std::array::from_fn(|k| sub(a[k], b[k])) };
            let v = [at(p), at(q), at(r)];
            let h: [V; 3] = std::array::from_fn(|k| sub(bmax[k], bmin[k]));
            let e = [vsub(v[1], v[0]), vsub(v[2], v[1]), vsub(v[0], v[2])];
            open &= !separates(cross(e[0], e[1]), &v, h);
            let (one, zero) = (splat(1.0), splat(0.0));
            let axes = [[one, zero, zero], [zero, one, zero], [zero, zero, one]];
            for edge in &e {
                for axis in &axes {
                    if open == 0 {
                        return 0;
                    }
                    open &= !separates(cross(*edge, *axis), &v, h);
                }
            }
            open
        }

        /// `super::super::cross`, lane by lane.
        #[target_feature(enable = $feature)]
        #[inline]
        fn cross(a: [V; 3], b: [V; 3]) -> [V; 3] {
            [
                sub(mul(a[1], b[2]), mul(a[2], b[1])),
                sub(mul(a[2], b[0]), mul(a[0], b[2])),
                sub(mul(a[0], b[1]), mul(a[1], b[0])),
            ]
        }

        /// `super::separates`, lane by lane: the lanes where `axis`
        /// separates the triangle `v` from the box `[0, h]`.
        #[target_feature(enable = $feature)]
        #[inline]
        fn separates(axis: [V; 3], v: &[[V; 3]; 3], h: [V; 3]) -> u8 {
            let null = is_zero(axis[0]) & is_zero(axis[1]) & is_zero(axis[2]);
            let dot = |b: [V; 3]| {
                add(
                    add(mul(axis[0], b[0]), mul(axis[1], b[1])),
                    mul(axis[2], b[2]),
                )
            };
            let d = [dot(v[0]), dot(v[1]), dot(v[2])];
            let t_min = min(min(d[0], d[1]), d[2]);
            let t_max = max(max(d[0], d[1]), d[2]);
            let (mut b_min, mut b_max) = (splat(0.0), splat(0.0));
            for k in 0..3 {
                (b_min, b_max) = split_add(b_min, b_max, mul(axis[k], h[k]));
            }
            (gt(t_min, b_max) | lt(t_max, b_min)) & !null
        }
    };
}

/// [`triangle_box_overlap`] of one triangle against eight boxes at once
/// with AVX-512 (the children of an octant, one per lane).
#[cfg(target_arch = "x86_64")]
pub(crate) mod wide {
    use super::Triangle;
    use std::arch::x86_64::*;

    type V = __m512d;
    box_lanes!(
        "avx512f",
        8,
        _mm512_loadu_pd,
        _mm512_set1_pd,
        _mm512_sub_pd,
        _mm512_mul_pd,
        _mm512_add_pd
    );

    #[target_feature(enable = "avx512f")]
    #[inline]
    fn gt(a: V, b: V) -> u8 {
        _mm512_cmp_pd_mask::<_CMP_GT_OQ>(a, b)
    }

    #[target_feature(enable = "avx512f")]
    #[inline]
    fn lt(a: V, b: V) -> u8 {
        _mm512_cmp_pd_mask::<_CMP_LT_OQ>(a, b)
    }

    #[target_feature(enable = "avx512f")]
    #[inline]
    fn is_zero(a: V) -> u8 {
        _mm512_cmp_pd_mask::<_CMP_EQ_OQ>(a, _mm512_setzero_pd())
    }

    /// `f64::min` lane by lane: `vminpd` answers `b` when either is NaN,
    /// `f64::min` answers `a` when `b` is.
    #[target_feature(enable = "avx512f")]
    #[inline]
    fn min(a: V, b: V) -> V {
        _mm512_mask_mov_pd(
            _mm512_min_pd(a, b),
            _mm512_cmp_pd_mask::<_CMP_UNORD_Q>(b, b),
            a,
        )
    }

    /// `f64::max` lane by lane, as [`min`].
    #[target_feature(enable = "avx512f")]
    #[inline]
    fn max(a: V, b: V) -> V {
        _mm512_mask_mov_pd(
            _mm512_max_pd(a, b),
            _mm512_cmp_pd_mask::<_CMP_UNORD_Q>(b, b),
            a,
        )
    }

    #[target_feature(enable = "avx512f")]
    #[inline]
    fn split_add(b_min: V, b_max: V, t: V) -> (V, V) {
        let pos = gt(t, _mm512_setzero_pd());
        (
            _mm512_mask_add_pd(b_min, !pos, b_min, t),
            _mm512_mask_add_pd(b_max, pos, b_max, t),
        )
    }
}

/// [`triangle_box_overlap`] of one triangle against eight boxes, four at a
/// time with AVX2 (processors without AVX-512F).
#[cfg(target_arch = "x86_64")]
pub(crate) mod wide4 {
    use super::Triangle;
    use std::arch::x86_64::*;

    type V = __m256d;
    box_lanes!(
        "avx2",
        4,
        _mm256_loadu_pd,
        _mm256_set1_pd,
        _mm256_sub_pd,
        _mm256_mul_pd,
        _mm256_add_pd
    );

    #[target_feature(enable = "avx2")]
    #[inline]
    fn gt(a: V, b: V) -> u8 {
        _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_GT_OQ>(a, b)) as u8
    }

    #[target_feature(enable = "avx2")]
    #[inline]
    fn lt(a: V, b: V) -> u8 {
        _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_LT_OQ>(a, b)) as u8
    }

    #[target_feature(enable = "avx2")]
    #[inline]
    fn is_zero(a: V) -> u8 {
        _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_EQ_OQ>(a, _mm256_setzero_pd())) as u8
    }

    /// `f64::min` lane by lane, as [`super::wide`]'s.
    #[target_feature(enable = "avx2")]
    #[inline]
    fn min(a: V, b: V) -> V {
        _mm256_blendv_pd(_mm256_min_pd(a, b), a, _mm256_cmp_pd::<_CMP_UNORD_Q>(b, b))
    }

    /// `f64::max` lane by lane, as [`super::wide`]'s.
    #[target_feature(enable = "avx2")]
    #[inline]
    fn max(a: V, b: V) -> V {
        _mm256_blendv_pd(_mm256_max_pd(a, b), a, _mm256_cmp_pd::<_CMP_UNORD_Q>(b, b))
    }

    #[target_feature(enable = "avx2")]
    #[inline]
    fn split_add(b_min: V, b_max: V, t: V) -> (V, V) {
        let pos = _mm256_cmp_pd::<_CMP_GT_OQ>(t, _mm256_setzero_pd());
        (
            _mm256_blendv_pd(_mm256_add_pd(b_min, t), b_min, pos),
            _mm256_blendv_pd(b_max, _mm256_add_pd(b_max, t), pos),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Aabb;
    use std::cmp::Ordering;

    const LO: [f64; 3] = [0.0, 0.0, 0.0];
    const HI: [f64; 3] = [1.0, 1.0, 1.0];

    fn t(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> Triangle {
        Triangle::new(a, b, c)
    }

    fn shift(tri: Triangle, d: [f64; 3]) -> Triangle {
        Triangle {
            v: tri.v.map(|p| [p[0] + d[0], p[1] + d[1], p[2] + d[2]]),
        }
    }

    fn unit_box(tri: &Triangle) -> bool {
        triangle_box_overlap(tri, LO, HI)
    }

    #[test]
    fn inside_and_far() {
        let inside = t([0.2, 0.2, 0.2], [0.8, 0.3, 0.4], [0.5, 0.9, 0.7]);
        assert!(unit_box(&inside));
        let far = shift(inside, [10.0, -3.0, 7.0]);
        assert!(!unit_box(&far));
    }

    #[test]
    fn touching_corner() {
        let at_vertex = t([1.0, 1.0, 1.0], [2.0, 3.0, 2.0], [3.0, 2.0, 2.0]);
        assert!(unit_box(&at_vertex));
        assert!(!unit_box(&shift(at_vertex, [1e-9, 0.0, 0.0])));
        // The corner (1,1,1) lies inside this triangle, the box is on one side.
        let through = t([3.0, 0.0, 0.0], [0.0, 3.0, 0.0], [0.0, 0.0, 3.0]);
        assert!(unit_box(&through));
        let off = shift(through, [1e-9, 0.0, 0.0]);
        assert!(!unit_box(&off));
        assert!(!unit_box(&t(
            [-1e-9, 0.0, 0.0],
            [-3.0, 0.0, 0.0],
            [0.0, -3.0, -3.0]
        )));
    }

    #[test]
    fn touching_edge() {
        // The triangle's edge x + y = 2 touches the box edge x = y = 1.
        let tri = t([2.0, 0.0, 0.5], [0.0, 2.0, 0.5], [2.0, 2.0, 0.5]);
        assert!(unit_box(&tri));
        assert!(!unit_box(&shift(tri, [1e-9, 1e-9, 0.0])));
        // Tilted so that only the triangle edge meets the box edge.
        let tilted = t([2.0, 0.0, 0.5], [0.0, 2.0, 0.5], [2.0, 2.0, 5.0]);
        assert!(unit_box(&tilted));
        assert!(!unit_box(&shift(tilted, [1e-9, 1e-9, 0.0])));
    }

    #[test]
    fn touching_face() {
        let on_top = t([0.2, 0.2, 1.0], [0.8, 0.2, 1.0], [0.5, 3.0, 1.0]);
        assert!(unit_box(&on_top));
        assert!(!unit_box(&shift(on_top, [0.0, 0.0, 1e-9])));
        // Standing on the face with one vertex.
        let standing = t([0.5, 0.5, 1.0], [0.0, 0.0, 2.0], [1.0, 0.0, 2.0]);
        assert!(unit_box(&standing));
        assert!(!unit_box(&shift(standing, [0.0, 0.0, 1e-9])));
    }

    #[test]
    fn crossing_without_inside_vertex() {
        let slab = t([-3.0, -3.0, 0.5], [5.0, -3.0, 0.5], [0.5, 5.0, 0.5]);
        assert!(unit_box(&slab));
        let oblique = t([-1.0, 0.5, -1.0], [2.0, 0.5, -1.0], [0.5, 0.3, 3.0]);
        assert!(unit_box(&oblique));
        // Bounding boxes overlap but the plane passes beside the box.
        let beside = t([-1.0, 3.25, 0.0], [3.25, -1.0, 0.0], [3.25, -1.0, 1.0]);
        assert!(unit_box(&shift(beside, [-0.25, 0.0, 0.0])));
        assert!(!unit_box(&beside));
    }

    #[test]
    fn large_triangle_containing_box_in_plane() {
        let big = t(
            [-100.0, -100.0, 0.0],
            [100.0, -100.0, 0.0],
            [0.0, 100.0, 0.0],
        );
        assert!(unit_box(&big));
        assert!(triangle_box_overlap(&big, [0.0, 0.0, 0.0], [1.0, 1.0, 0.0]));
        assert!(!triangle_box_overlap(
            &big,
            [0.0, 0.0, 1e-9],
            [1.0, 1.0, 1e-9]
        ));
    }

    #[test]
    fn degenerate_triangles() {
        let seg = t([-1.0, 0.5, 0.5], [2.0, 0.5, 0.5], [2.0, 0.5, 0.5]);
        assert!(unit_box(&seg));
        let diag = t([-1.0, 2.0, 0.5], [2.0, -1.0, 0.5], [0.5, 0.5, 0.5]);
        assert!(unit_box(&diag));
        // Bounding box overlaps, but the segment passes the corner at a gap.
        let miss = t([-0.5, 3.0, 0.5], [3.0, -0.5, 0.5], [3.0, -0.5, 0.5]);
        assert!(!unit_box(&miss));
        let corner = t([-1.0, 3.0, 0.5], [3.0, -1.0, 0.5], [1.0, 1.0, 0.5]);
        assert!(unit_box(&corner));
        let p = [0.25, 1.0, 0.75];
        assert!(unit_box(&t(p, p, p)));
        let q = [0.25, 1.0 + 1e-9, 0.75];
        assert!(!unit_box(&t(q, q, q)));
    }

    #[test]
    fn empty_box() {
        let tri = t([-3.0, -3.0, 0.5], [5.0, -3.0, 0.5], [0.5, 5.0, 0.5]);
        assert!(!triangle_box_overlap(
            &tri,
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 1.0]
        ));
    }

    // ---- independent exact check: rational Sutherland-Hodgman clipping ----

    #[derive(Clone, Copy, Debug)]
    struct Q {
        n: i128,
        d: i128,
    }

    fn gcd(mut a: i128, mut b: i128) -> i128 {
        a = a.abs();
        b = b.abs();
        while b != 0 {
            (a, b) = (b, a % b);
        }
        a
    }

    impl Q {
        fn int(n: i64) -> Q {
            Q { n: n as i128, d: 1 }
        }
        fn new(n: i128, d: i128) -> Q {
            assert!(d != 0);
            let s = if d < 0 { -1 } else { 1 };
            let g = gcd(n, d).max(1);
            Q {
                n: s * n / g,
                d: s * d / g,
            }
        }
        fn add(self, o: Q) -> Q {
            Q::new(self.n * o.d + o.n * self.d, self.d * o.d)
        }
        fn sub(self, o: Q) -> Q {
            Q::new(self.n * o.d - o.n * self.d, self.d * o.d)
        }
        fn mul(self, o: Q) -> Q {
            Q::new(self.n * o.n, self.d * o.d)
        }
        fn div(self, o: Q) -> Q {
            Q::new(self.n * o.d, self.d * o.n)
        }
        fn sign(self) -> Ordering {
            self.n.cmp(&0)
        }
    }

    type P = [Q; 3];

    /// Keeps the part of the closed polygon where `s * (p[k] - bound) >= 0`.
    fn clip(poly: &[P], k: usize, bound: Q, upper: bool) -> Vec<P> {
        let dist = |p: &P| {
            let d = p[k].sub(bound);
            if upper {
                Q::new(-d.n, d.d)
            } else {
                d
            }
        };
        let mut out = Vec::new();
        for i in 0..poly.len() {
            let cur = poly[i];
            let next = poly[(i + 1) % poly.len()];
            let (dc, dn) = (dist(&cur), dist(&next));
            let cur_in = dc.sign() != Ordering::Less;
            let next_in = dn.sign() != Ordering::Less;
            if cur_in {
                out.push(cur);
            }
            if cur_in != next_in {
                let s = dc.div(dc.sub(dn));
                let mut p = cur;
                for (j, c) in p.iter_mut().enumerate() {
                    *c = cur[j].add(s.mul(next[j].sub(cur[j])));
                }
                out.push(p);
            }
        }
        out
    }

    fn exact_overlap(tri: [[i64; 3]; 3], lo: [i64; 3], hi: [i64; 3]) -> bool {
        let mut poly: Vec<P> = tri.iter().map(|p| p.map(Q::int)).collect();
        for k in 0..3 {
            poly = clip(&poly, k, Q::int(lo[k]), false);
            poly = clip(&poly, k, Q::int(hi[k]), true);
            if poly.is_empty() {
                return false;
            }
        }
        // Every surviving point must really lie in the box.
        for p in &poly {
            for k in 0..3 {
                assert!(p[k].sub(Q::int(lo[k])).sign() != Ordering::Less);
                assert!(Q::int(hi[k]).sub(p[k]).sign() != Ordering::Less);
            }
        }
        true
    }

    use crate::testutil::Rng;

    /// Eight boxes at once give, lane by lane, the scalar test's verdict:
    /// integer triangles against the eight children of an integer box
    /// (contacts at faces, edges and corners, degenerate triangles), then
    /// real ones at random scales and an infinite vertex.
    #[test]
    #[cfg(target_arch = "x86_64")]
    fn eight_boxes_at_once_match_the_scalar_test() {
        let (w8, w4) = (
            crate::parallel::cores::avx512(),
            crate::parallel::cores::avx2(),
        );
        if !w8 && !w4 {
            println!("neither AVX-512F nor AVX2 here: the eight-box tests were not compared");
            return;
        }
        let mut rng = Rng(0x8b0c_5e57);
        let (mut hits, mut misses) = (0u32, 0u32);
        for case in 0..100_000 {
            let real = case % 3 == 2;
            let scale = [1.0, 1e-3, 1e6][case % 5 % 3];
            let coord = |rng: &mut Rng| -> f64 {
                if real {
                    scale * (rng.unit() * 8.0 - 4.0)
                } else {
                    rng.range(-3, 5) as f64
                }
            };
            let mut v = [[0.0; 3]; 3];
            for p in v.iter_mut() {
                for c in p.iter_mut() {
                    *c = coord(&mut rng);
                }
            }
            if case % 7 == 0 {
                v[2] = v[1];
            }
            if case % 997 == 0 {
                v[0][1] = f64::INFINITY;
            }
            let tri = Triangle { v };
            // The parent box [base, base + 2 half].
            let half = if real {
                scale * rng.unit() * 2.0
            } else {
                rng.range(1, 3) as f64
            };
            let base: [f64; 3] = std::array::from_fn(|_| coord(&mut rng) - half);
            let (mut lo, mut hi) = ([[0.0; 8]; 3], [[0.0; 8]; 3]);
            for i in 0..8 {
                for k in 0..3 {
                    lo[k][i] = base[k] + if i >> k & 1 != 0 { half } else { 0.0 };
                    hi[k][i] = lo[k][i] + half;
                }
            }
            let want = if case % 2 == 0 {
                0xff
            } else {
                rng.next() as u8
            };
            // SAFETY: each runs only where its instructions are.
            let wide = w8.then(|| unsafe { wide::triangle_boxes_overlap(&tri, &lo, &hi, want) });
            let four = w4.then(|| unsafe { wide4::triangle_boxes_overlap(&tri, &lo, &hi, want) });
            for i in 0..8 {
                let b = |a: &[[f64; 8]; 3]| [a[0][i], a[1][i], a[2][i]];
                let scalar = want >> i & 1 != 0 && triangle_box_overlap(&tri, b(&lo), b(&hi));
                for (name, got) in [("AVX-512F", wide), ("AVX2", four)] {
                    if let Some(got) = got {
                        assert_eq!(
                            got >> i & 1 != 0,
                            scalar,
                            "{name} case {case} lane {i}: {tri:?}"
                        );
                    }
                }
                if want >> i & 1 != 0 {
                    if scalar {
                        hits += 1;
                    } else {
                        misses += 1;
                    }
                }
            }
        }
        assert!(hits > 50_000 && misses > 50_000, "{hits} / {misses}");
    }

    #[test]
    fn clipping_reference_sanity() {
        let tri = [[2, 0, 0], [0, 2, 0], [2, 2, 0]];
        assert!(exact_overlap(tri, [0, 0, 0], [1, 1, 1]));
        assert!(!exact_overlap(tri, [0, 0, 1], [1, 1, 1]));
        assert!(exact_overlap(tri, [0, 0, 0], [1, 1, 0]));
        let far = [[5, 5, 5], [6, 5, 5], [5, 6, 5]];
        assert!(!exact_overlap(far, [0, 0, 0], [1, 1, 1]));
    }

    #[test]
    fn random_integer_cases_match_exact_clipping() {
        let mut rng = Rng(0x0c7e_5eed);
        let (mut hits, mut misses, mut degenerate, mut subtle) = (0u32, 0u32, 0u32, 0u32);
        for case in 0..200_000 {
            let span = if case % 2 == 0 { 3 } else { 6 };
            let mut tri = [[0i64; 3]; 3];
            for p in tri.iter_mut() {
                for c in p.iter_mut() {
                    *c = rng.range(-span + 2, span);
                }
            }
            if case % 7 == 0 {
                // Force collinear or coincident vertices now and then.
                tri[2] = if case % 14 == 0 {
                    tri[1]
                } else {
                    [
                        2 * tri[1][0] - tri[0][0],
                        2 * tri[1][1] - tri[0][1],
                        2 * tri[1][2] - tri[0][2],
                    ]
                };
            }
            let mut lo = [0i64; 3];
            let mut hi = [0i64; 3];
            for k in 0..3 {
                lo[k] = rng.range(-1, 2);
                hi[k] = lo[k] + rng.range(0, 2);
            }
            let f = |p: [i64; 3]| p.map(|c| c as f64);
            let ftri = Triangle::new(f(tri[0]), f(tri[1]), f(tri[2]));
            if ftri.is_degenerate() {
                degenerate += 1;
            }
            let fast = triangle_box_overlap(&ftri, f(lo), f(hi));
            let exact = exact_overlap(tri, lo, hi);
            let boxes_meet = ftri.aabb().overlaps(&Aabb {
                min: f(lo),
                max: f(hi),
            });
            if boxes_meet && !exact {
                subtle += 1;
            }
            assert_eq!(
                fast, exact,
                "case {case}: triangle {tri:?} box {lo:?}..{hi:?}"
            );
            if exact {
                hits += 1;
            } else {
                misses += 1;
            }
        }
        assert!(hits > 20_000 && misses > 20_000, "{hits} / {misses}");
        assert!(degenerate > 20_000, "{degenerate}");
        // Cases only the normal or edge-cross axes can reject.
        assert!(subtle > 5_000, "{subtle}");
    }
}
