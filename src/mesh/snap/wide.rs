//! The element check and the nearest-triangle scan with AVX-512, chosen at
//! run time (the build targets x86-64-v2). Measured on the dragon at level
//! 10, one thread: a full check of its 1.83 million active elements in
//! about 0.15 s instead of 0.25 s, its 1.2 million nearest-point queries
//! 7 to 13 % faster.

use std::arch::x86_64::*;

use crate::geometry::cells::CORNER_EDGES;
use crate::geometry::distance::point_triangle2;
use crate::geometry::Triangle;

use super::measure::Measure;
use super::nearest::{Chunk, Nearest};

/// [`Measure::part`] compiled for AVX-512F, the corner test inlined.
///
/// # Safety
/// The processor must have AVX-512F.
#[target_feature(enable = "avx512f")]
pub unsafe fn measure(m: &Measure, part: &[u32]) -> Vec<(u32, u8)> {
    // SAFETY: this function runs only where AVX-512F is.
    m.run(part, |p, j2| unsafe { corner_verdict(p, j2) })
}

/// [`super::nearest::NearTriangles::nearest`]'s loop over the gathered
/// triangles, a chunk of eight at a time: their boxes' distances and,
/// where one is within `bound`, all eight triangles' distances
/// ([`crate::geometry::distance::wide::point_triangle2`], the same
/// bits); then the lanes in turn exactly as the scalar loop takes
/// them.
///
/// # Safety
/// The processor must have AVX-512F.
#[target_feature(enable = "avx512f")]
pub unsafe fn scan(chunks: &[Chunk], tris: &[Triangle], x: [f64; 3], near: &mut Nearest) {
    let xs = x.map(|v| _mm512_set1_pd(v));
    // SAFETY: loads of eight values from arrays of eight.
    let load = |v: &[f64; 8]| unsafe { _mm512_loadu_pd(v.as_ptr()) };
    let zero = _mm512_setzero_pd();
    for ch in chunks {
        // `point_box2`, lane by lane.
        let d: [__m512d; 3] = std::array::from_fn(|k| {
            let below = _mm512_max_pd(_mm512_sub_pd(load(&ch.lo[k]), xs[k]), zero);
            let dk = _mm512_max_pd(below, _mm512_sub_pd(xs[k], load(&ch.hi[k])));
            _mm512_mul_pd(dk, dk)
        });
        let box2 = _mm512_add_pd(_mm512_add_pd(d[0], d[1]), d[2]);
        let mut within = _mm512_cmp_pd_mask::<_CMP_LE_OQ>(box2, _mm512_set1_pd(near.bound)) as u32;
        if within == 0 {
            continue;
        }
        let mut boxes = [0.0; 8];
        // SAFETY: a store of eight values into an array of eight.
        unsafe { _mm512_storeu_pd(boxes.as_mut_ptr(), box2) };
        // SAFETY: the caller's processor has AVX-512F.
        let (dist, degenerate) =
            unsafe { crate::geometry::distance::wide::point_triangle2(x, &ch.a, &ch.b, &ch.c) };
        while within != 0 {
            let j = within.trailing_zeros() as usize;
            within &= within - 1;
            if boxes[j] > near.bound {
                continue;
            }
            let t = ch.ids[j];
            let d = if degenerate >> j & 1 == 1 {
                let [p, q, r] = tris[t as usize].v;
                point_triangle2(x, p, q, r)
            } else {
                dist[j]
            };
            near.offer(t, d);
        }
    }
}

/// Lane `k` holds `f(k)`.
#[inline(always)]
fn lanes(f: impl Fn(usize) -> i64) -> __m512i {
    let v: [i64; 8] = std::array::from_fn(f);
    // SAFETY: an unaligned load of 64 bytes from an array of 64.
    unsafe { _mm512_loadu_si512(v.as_ptr().cast()) }
}

/// [`super::measure::corner_verdict`], lane `k` for corner `k`.
///
/// # Safety
/// The processor must have AVX-512F.
#[target_feature(enable = "avx512f")]
#[inline]
pub unsafe fn corner_verdict(p: &[[f64; 3]; 8], j2: f64) -> (u8, f64) {
    // Each lane does the scalar code's operations in its order, with
    // no fused multiply-adds: the same roundings, the same bits.
    let column = |a: usize| {
        _mm512_set_pd(
            p[7][a], p[6][a], p[5][a], p[4][a], p[3][a], p[2][a], p[1][a], p[0][a],
        )
    };
    let (x, y, z) = (column(0), column(1), column(2));
    let edge = |c: __m512d, e: usize| {
        _mm512_sub_pd(
            _mm512_permutexvar_pd(lanes(|k| CORNER_EDGES[k][e] as i64), c),
            c,
        )
    };
    let (ax, ay, az) = (edge(x, 0), edge(y, 0), edge(z, 0));
    let (bx, by, bz) = (edge(x, 1), edge(y, 1), edge(z, 1));
    let (cx, cy, cz) = (edge(x, 2), edge(y, 2), edge(z, 2));
    let (mul, add, sub) = (_mm512_mul_pd, _mm512_add_pd, _mm512_sub_pd);
    let det = add(
        sub(
            mul(ax, sub(mul(by, cz), mul(bz, cy))),
            mul(ay, sub(mul(bx, cz), mul(bz, cx))),
        ),
        mul(az, sub(mul(bx, cy), mul(by, cx))),
    );
    let length = |u: __m512d, v: __m512d, w: __m512d| add(add(mul(u, u), mul(v, v)), mul(w, w));
    let product = mul(
        mul(length(ax, ay, az), length(bx, by, bz)),
        length(cx, cy, cz),
    );
    let zero = _mm512_setzero_pd();
    let positive = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(det, zero);
    let enough = _mm512_cmp_pd_mask::<_CMP_GE_OQ>(mul(det, det), mul(_mm512_set1_pd(j2), product));
    let failed = !(positive & enough);
    let flat_edge = _mm512_cmp_pd_mask::<_CMP_EQ_OQ>(product, zero);
    let figure = _mm512_div_pd(mul(det, _mm512_abs_pd(det)), product);
    let figure = _mm512_mask_blend_pd(flat_edge, figure, zero);
    (failed, _mm512_reduce_min_pd(figure))
}
