//! Exact Euclidean distances between points, segments, triangles and
//! axis-aligned boxes, for distance bands around a surface.
//!
//! The distance between two disjoint convex polytopes is attained by a
//! pair of features at least one of which is a vertex, or by two edges.
//! So the box-to-triangle distance is the least of: each box corner to the
//! triangle, each triangle vertex to the box, and each of the 12 box edges
//! to each of the 3 triangle edges; and zero when they overlap.

use super::intersect::triangle_box_overlap;
use super::vector::{add_scaled, dist2, dot, sub};
use super::{fmax, Triangle};

/// Squared distance from `p` to the box `lo..hi`.
pub fn point_box2(p: [f64; 3], lo: [f64; 3], hi: [f64; 3]) -> f64 {
    (0..3)
        .map(|k| {
            let d = (lo[k] - p[k]).max(0.0).max(p[k] - hi[k]);
            d * d
        })
        .sum()
}

/// Squared distance from `p` to the triangle `a b c` (Ericson's region
/// tests, "Real-Time Collision Detection" 5.1.5).
pub fn point_triangle2(p: [f64; 3], a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> f64 {
    dist2(p, closest_point_triangle(p, a, b, c))
}

/// The point of the triangle `a b c` closest to `p` (Ericson's region
/// tests, "Real-Time Collision Detection" 5.1.5); a degenerate triangle is
/// the union of its edges.
pub fn closest_point_triangle(p: [f64; 3], a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> [f64; 3] {
    let (ab, ac, ap) = (sub(b, a), sub(c, a), sub(p, a));
    let (d1, d2) = (dot(ab, ap), dot(ac, ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = sub(p, b);
    let (d3, d4) = (dot(ab, bp), dot(ac, bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return add_scaled(a, ab, d1 / (d1 - d3));
    }
    let cp = sub(p, c);
    let (d5, d6) = (dot(ab, cp), dot(ac, cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return add_scaled(a, ac, d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return add_scaled(b, sub(c, b), w);
    }
    let denom = va + vb + vc;
    if denom.is_nan() || denom <= 0.0 {
        // A degenerate triangle: its edges hold it; the first nearest wins.
        let mut best = segment_closest(a, b, p);
        for q in [segment_closest(b, c, p), segment_closest(a, c, p)] {
            if dist2(p, q) < dist2(p, best) {
                best = q;
            }
        }
        return best;
    }
    let (v, w) = (vb / denom, vc / denom);
    add_scaled(add_scaled(a, ab, v), ac, w)
}

/// The point of the segment `a b` closest to `p`.
fn segment_closest(a: [f64; 3], b: [f64; 3], p: [f64; 3]) -> [f64; 3] {
    let d = sub(b, a);
    let l = dot(d, d);
    let t = if l > 0.0 {
        (dot(sub(p, a), d) / l).clamp(0.0, 1.0)
    } else {
        0.0
    };
    add_scaled(a, d, t)
}

/// Squared distance between the segments `p1 q1` and `p2 q2` (Ericson
/// 5.1.9, with the parallel and degenerate cases).
pub fn segment_segment2(p1: [f64; 3], q1: [f64; 3], p2: [f64; 3], q2: [f64; 3]) -> f64 {
    let (d1, d2, r) = (sub(q1, p1), sub(q2, p2), sub(p1, p2));
    let (a, e, f) = (dot(d1, d1), dot(d2, d2), dot(d2, r));
    if a <= 0.0 && e <= 0.0 {
        return dist2(p1, p2);
    }
    let (s, t) = if a <= 0.0 {
        (0.0, (f / e).clamp(0.0, 1.0))
    } else {
        let c = dot(d1, r);
        if e <= 0.0 {
            ((-c / a).clamp(0.0, 1.0), 0.0)
        } else {
            let b = dot(d1, d2);
            let denom = a * e - b * b;
            let mut s = if denom > 0.0 {
                ((b * f - c * e) / denom).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let mut t = (b * s + f) / e;
            if t < 0.0 {
                t = 0.0;
                s = (-c / a).clamp(0.0, 1.0);
            } else if t > 1.0 {
                t = 1.0;
                s = ((b - c) / a).clamp(0.0, 1.0);
            }
            (s, t)
        }
    };
    dist2(add_scaled(p1, d1, s), add_scaled(p2, d2, t))
}

/// Whether the closed box `lo..hi` comes within `d` of the triangle
/// (distance at most `d`).
pub fn box_within(t: &Triangle, lo: [f64; 3], hi: [f64; 3], d: f64) -> bool {
    box_within_quick(t, lo, hi, d).unwrap_or_else(|| box_within_rest(t, lo, hi, d))
}

/// Whether any triangle `tris[i]`, `i` in `ids`, comes within `d` of the
/// closed box `lo..hi`: the cheap answers of all first, the exact
/// distances of the undecided ones only when no cheap answer accepts (most
/// boxes near a surface have some triangle clearly within `d`).
/// `undecided` is scratch.
pub fn any_box_within(
    tris: &[Triangle],
    ids: &[u32],
    lo: [f64; 3],
    hi: [f64; 3],
    d: f64,
    undecided: &mut Vec<u32>,
) -> bool {
    undecided.clear();
    for &i in ids {
        match box_within_quick(&tris[i as usize], lo, hi, d) {
            Some(true) => return true,
            Some(false) => {}
            None => undecided.push(i),
        }
    }
    undecided
        .iter()
        .any(|&i| box_within_rest(&tris[i as usize], lo, hi, d))
}

/// The cheap part of [`box_within`]: `Some` answer from the vertices, the
/// boxes, separating axes (a gap of more than `d` along a unit axis) and
/// one overlap test (with the box grown by `d / sqrt 3`), `None` when only
/// the exact distances decide.
fn box_within_quick(t: &Triangle, lo: [f64; 3], hi: [f64; 3], d: f64) -> Option<bool> {
    let d2 = d * d;
    let [a, b, c] = t.v;
    // Quick accept and reject on the triangle's vertices and box, without
    // branches on the data (the answers are hard to predict).
    let near = point_box2(a, lo, hi)
        .min(point_box2(b, lo, hi))
        .min(point_box2(c, lo, hi));
    if near <= d2 {
        return Some(true);
    }
    let mut gap2 = 0.0;
    for k in 0..3 {
        let (tlo, thi) = (a[k].min(b[k]).min(c[k]), a[k].max(b[k]).max(c[k]));
        let g = fmax(lo[k] - thi, tlo - hi[k]);
        gap2 += if g > 0.0 { g * g } else { 0.0 };
    }
    if gap2 > d2 {
        return Some(false);
    }
    // Rounding margins keep every test on the safe side of `d`.
    let margin = 1e-9 * (d + (hi[0] - lo[0]));
    // Lower bounds first, the plane before the edge axes: most candidates
    // near a box beside the band are rejected, few accepted.
    let apart = d + margin;
    if crate::geometry::intersect::plane_apart(t, lo, hi, apart)
        || crate::geometry::intersect::edges_apart(t, lo, hi, apart)
    {
        return Some(false);
    }
    // Every point of the box grown by `d / sqrt 3` is within `d` of the
    // box, which it holds: overlapping it, the triangle is within `d`.
    let inner = (d / 3f64.sqrt() - margin).max(0.0);
    if triangle_box_overlap(t, lo.map(|x| x - inner), hi.map(|x| x + inner)) {
        return Some(true);
    }
    None
}

/// The exact part of [`box_within`]: the box's corners against the
/// triangle and its edges against the triangle's edges (the closest pair
/// of a box and a triangle that neither overlap nor have a vertex within
/// `d` of the other is one of these).
fn box_within_rest(t: &Triangle, lo: [f64; 3], hi: [f64; 3], d: f64) -> bool {
    let d2 = d * d;
    let [a, b, c] = t.v;
    let corner = |i: usize| -> [f64; 3] {
        std::array::from_fn(|k| if i >> k & 1 == 1 { hi[k] } else { lo[k] })
    };
    if (0..8).any(|i| {
        let p = corner(i);
        point_triangle2(p, a, b, c) <= d2
    }) {
        return true;
    }
    // The 12 edges: corner pairs differing in one bit.
    let edges = (0..8usize).flat_map(|i| {
        (0..3)
            .filter(move |k| i >> k & 1 == 0)
            .map(move |k| (i, i | 1 << k))
    });
    let tri_edges = [(a, b), (b, c), (c, a)];
    edges.into_iter().any(|(i, j)| {
        let (p, q) = (corner(i), corner(j));
        tri_edges
            .iter()
            .any(|&(u, v)| segment_segment2(p, q, u, v) <= d2)
    })
}

/// [`point_triangle2`] for eight triangles at once with AVX-512.
#[cfg(target_arch = "x86_64")]
pub(crate) mod wide {
    use std::arch::x86_64::*;

    /// Squared distances from `p` to eight triangles with corners
    /// `a`, `b`, `c` (coordinate `k` of lane `j`'s corner `a` is
    /// `a[k][j]`): lane `j` has the bits [`super::point_triangle2`] gives,
    /// except in the lanes of the mask returned (degenerate triangles,
    /// which the caller measures with it). Every region's point is
    /// computed with the scalar code's operations in its order, and the
    /// one the scalar code would pick is kept.
    ///
    /// # Safety
    /// The processor must have AVX-512F.
    #[target_feature(enable = "avx512f")]
    #[inline]
    pub(crate) unsafe fn point_triangle2(
        p: [f64; 3],
        a: &[[f64; 8]; 3],
        b: &[[f64; 8]; 3],
        c: &[[f64; 8]; 3],
    ) -> ([f64; 8], u8) {
        let (mul, add, sub, div) = (_mm512_mul_pd, _mm512_add_pd, _mm512_sub_pd, _mm512_div_pd);
        // SAFETY: loads of eight values from arrays of eight.
        let load = |v: &[f64; 8]| unsafe { _mm512_loadu_pd(v.as_ptr()) };
        let a = a.map(|v| load(&v));
        let b = b.map(|v| load(&v));
        let c = c.map(|v| load(&v));
        let p = p.map(|v| _mm512_set1_pd(v));
        let vsub =
            |x: [__m512d; 3], y: [__m512d; 3]| [sub(x[0], y[0]), sub(x[1], y[1]), sub(x[2], y[2])];
        let dot = |x: [__m512d; 3], y: [__m512d; 3]| {
            add(add(mul(x[0], y[0]), mul(x[1], y[1])), mul(x[2], y[2]))
        };
        let scaled = |x: [__m512d; 3], d: [__m512d; 3], t: __m512d| {
            [
                add(x[0], mul(t, d[0])),
                add(x[1], mul(t, d[1])),
                add(x[2], mul(t, d[2])),
            ]
        };
        let zero = _mm512_setzero_pd();
        let le = |x: __m512d, y: __m512d| _mm512_cmp_pd_mask::<_CMP_LE_OQ>(x, y);
        let ge = |x: __m512d, y: __m512d| _mm512_cmp_pd_mask::<_CMP_GE_OQ>(x, y);
        let (ab, ac, ap) = (vsub(b, a), vsub(c, a), vsub(p, a));
        let (d1, d2) = (dot(ab, ap), dot(ac, ap));
        let in_a = le(d1, zero) & le(d2, zero);
        let bp = vsub(p, b);
        let (d3, d4) = (dot(ab, bp), dot(ac, bp));
        let in_b = ge(d3, zero) & le(d4, d3);
        let vc = sub(mul(d1, d4), mul(d3, d2));
        let in_ab = le(vc, zero) & ge(d1, zero) & le(d3, zero);
        let cp = vsub(p, c);
        let (d5, d6) = (dot(ab, cp), dot(ac, cp));
        let in_c = ge(d6, zero) & le(d5, d6);
        let vb = sub(mul(d5, d2), mul(d1, d6));
        let in_ac = le(vb, zero) & ge(d2, zero) & le(d6, zero);
        let va = sub(mul(d3, d6), mul(d5, d4));
        let (e43, e56) = (sub(d4, d3), sub(d5, d6));
        let in_bc = le(va, zero) & ge(e43, zero) & ge(e56, zero);
        let denom = add(add(va, vb), vc);
        let inside = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(denom, zero);
        // The interior point, then the regions in the reverse of the
        // scalar code's order, each overriding the ones after it there.
        let mut q = scaled(scaled(a, ab, div(vb, denom)), ac, div(vc, denom));
        let mut pick = |m: __mmask8, r: [__m512d; 3]| {
            for k in 0..3 {
                q[k] = _mm512_mask_blend_pd(m, q[k], r[k]);
            }
        };
        pick(in_bc, scaled(b, vsub(c, b), div(e43, add(e43, e56))));
        pick(in_ac, scaled(a, ac, div(d2, sub(d2, d6))));
        pick(in_c, c);
        pick(in_ab, scaled(a, ab, div(d1, sub(d1, d3))));
        pick(in_b, b);
        pick(in_a, a);
        let regions = in_a | in_b | in_ab | in_c | in_ac | in_bc;
        let d = vsub(p, q);
        let mut out = [0.0; 8];
        // SAFETY: a store of eight values into an array of eight.
        unsafe { _mm512_storeu_pd(out.as_mut_ptr(), dot(d, d)) };
        (out, !regions & !inside)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Pseudo-random numbers in `[lo, hi)` from `seed` (a linear
    /// congruential generator: the same triangles on every run).
    fn uniform(mut seed: u64, lo: f64, hi: f64) -> impl FnMut() -> f64 {
        move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            lo + (hi - lo) * ((seed >> 11) as f64 / (1u64 << 53) as f64)
        }
    }

    #[test]
    #[cfg(target_arch = "x86_64")]
    fn eight_at_once_give_the_same_bits() {
        if !crate::parallel::cores::avx512() {
            eprintln!("skipped: this processor has no AVX-512F");
            return;
        }
        let mut r = uniform(7, -1.0, 1.0);
        let mut compared = 0;
        for round in 0..3000 {
            let mut v: [[[f64; 3]; 3]; 8] =
                std::array::from_fn(|_| std::array::from_fn(|_| [r(), r(), r()]));
            // Collinear, repeated and one-point triangles too.
            match round % 5 {
                0 => v[3][2] = v[3][0].map(|x| 2.0 * x),
                1 => v[5][1] = v[5][0],
                2 => v[6] = [v[6][0]; 3],
                _ => {}
            }
            if round % 5 == 0 {
                v[3][1] = v[3][0].map(|x| 1.5 * x);
            }
            let p = [3.0 * r(), 3.0 * r(), 3.0 * r()];
            let column = |c: usize| -> [[f64; 8]; 3] {
                std::array::from_fn(|k| std::array::from_fn(|j| v[j][c][k]))
            };
            // SAFETY: the processor has AVX-512F (checked above).
            let (d, mask) = unsafe { wide::point_triangle2(p, &column(0), &column(1), &column(2)) };
            for j in 0..8 {
                if mask >> j & 1 == 0 {
                    compared += 1;
                    let [a, b, c] = v[j];
                    assert_eq!(
                        d[j].to_bits(),
                        point_triangle2(p, a, b, c).to_bits(),
                        "{p:?} {:?}",
                        v[j]
                    );
                }
            }
        }
        // The degenerate lanes (left to the scalar code) are rare: the
        // region tests take most degenerate triangles.
        assert!(compared > 23_000, "{compared}");
    }

    /// Brute-force squared distance from the box to the triangle by dense
    /// sampling of both (an upper bound that converges).
    fn sampled(t: &Triangle, lo: [f64; 3], hi: [f64; 3]) -> f64 {
        let n = 24;
        let mut best = f64::INFINITY;
        for i in 0..=n {
            for j in 0..=(n - i) {
                let (u, v) = (i as f64 / n as f64, j as f64 / n as f64);
                let p: [f64; 3] = std::array::from_fn(|k| {
                    t.v[0][k] + u * (t.v[1][k] - t.v[0][k]) + v * (t.v[2][k] - t.v[0][k])
                });
                best = best.min(point_box2(p, lo, hi));
            }
        }
        best
    }

    #[test]
    fn box_distance_agrees_with_sampling() {
        let mut rnd = uniform(12345, -2.0, 2.0);
        let (lo, hi) = ([0.0, 0.0, 0.0], [1.0, 0.5, 0.25]);
        for _ in 0..300 {
            let t = Triangle::new(
                [rnd(), rnd(), rnd()],
                [rnd(), rnd(), rnd()],
                [rnd(), rnd(), rnd()],
            );
            let s = sampled(&t, lo, hi).sqrt();
            // Sampling only overestimates; the exact test must accept at the
            // sampled distance and, well below the true one, reject.
            assert!(box_within(&t, lo, hi, s + 1e-12), "{t:?}: sampled {s}");
            if s > 0.2 {
                assert!(!box_within(&t, lo, hi, 0.5 * s - 0.1), "{t:?}: sampled {s}");
            }
        }
    }

    /// Exact distance from the box to the triangle: zero when they overlap,
    /// else the least of the triangle's vertices to the box, the box's
    /// corners to the triangle and the edges of either to the other's.
    fn exact(t: &Triangle, lo: [f64; 3], hi: [f64; 3]) -> f64 {
        if triangle_box_overlap(t, lo, hi) {
            return 0.0;
        }
        let corner = |i: usize| -> [f64; 3] {
            std::array::from_fn(|k| if i >> k & 1 == 1 { hi[k] } else { lo[k] })
        };
        let [a, b, c] = t.v;
        let mut best =
            t.v.iter()
                .map(|&v| point_box2(v, lo, hi))
                .fold(f64::MAX, f64::min);
        for i in 0..8 {
            best = best.min(point_triangle2(corner(i), a, b, c));
            for k in 0..3 {
                if i >> k & 1 == 0 {
                    let (p, q) = (corner(i), corner(i | 1 << k));
                    for (u, v) in [(a, b), (b, c), (c, a)] {
                        best = best.min(segment_segment2(p, q, u, v));
                    }
                }
            }
        }
        best.sqrt()
    }

    /// Every cheap answer, the separating-axis lower bounds and the whole
    /// test agree with the exact distance on either side of it, for
    /// triangles near, across and beside a flat box.
    #[test]
    fn box_within_agrees_with_the_exact_distance() {
        let mut rnd = uniform(987654321, -1.0, 2.0);
        let (lo, hi) = ([0.0, 0.0, 0.0], [1.0, 0.5, 0.25]);
        let (mut near, mut apart) = (0, 0);
        for _ in 0..5000 {
            let t = Triangle::new(
                [rnd(), rnd(), rnd()],
                [rnd(), rnd(), rnd()],
                [rnd(), rnd(), rnd()],
            );
            let e = exact(&t, lo, hi);
            for (d, within) in [(e * (1.0 + 1e-6) + 1e-12, true), (e * (1.0 - 1e-6), false)] {
                if d <= 0.0 {
                    continue;
                }
                assert_eq!(box_within(&t, lo, hi, d), within, "{t:?} at {d}, exact {e}");
                if let Some(q) = box_within_quick(&t, lo, hi, d) {
                    assert_eq!(q, within, "{t:?} at {d}, exact {e}");
                }
                use crate::geometry::intersect::{edges_apart, plane_apart};
                if plane_apart(&t, lo, hi, d) || edges_apart(&t, lo, hi, d) {
                    assert!(!within, "{t:?} at {d}, exact {e}");
                    apart += 1;
                }
                near += within as usize;
            }
        }
        // Both sides were exercised, and the lower bounds decided some.
        assert!(near > 1000 && apart > 1000, "{near} within, {apart} apart");
    }

    #[test]
    fn segments_and_points() {
        assert_eq!(
            segment_segment2([0.0; 3], [1.0, 0.0, 0.0], [0.5, 1.0, 0.0], [0.5, 2.0, 0.0]),
            1.0
        );
        assert_eq!(
            segment_segment2([0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [3.0, 0.0, 0.0]),
            1.0
        );
        let (a, b, c) = ([0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        assert_eq!(point_triangle2([0.25, 0.25, 2.0], a, b, c), 4.0);
        assert_eq!(point_triangle2([-1.0, 0.0, 0.0], a, b, c), 1.0);
    }
}
