//! Solid angles of triangles and the exact winding number of a soup.

use super::*;
use crate::geometry::vector::{add, cross, dot, norm, scale, sub};
use crate::geometry::Triangle;

/// The terms of Van Oosterom and Strackee's formula for triangle `t` seen
/// from `p`: numerator `a . (b x c)`, denominator, and `|a||b||c|`.
#[inline]
pub(crate) fn vo_terms(t: &Triangle, p: [f64; 3]) -> (f64, f64, f64) {
    let a = sub(t.v[0], p);
    let b = sub(t.v[1], p);
    let c = sub(t.v[2], p);
    let (la, lb, lc) = (norm(a), norm(b), norm(c));
    let det = dot(a, cross(b, c));
    let den = la * lb * lc + dot(a, b) * lc + dot(b, c) * la + dot(c, a) * lb;
    (det, den, la * lb * lc)
}

/// Signed solid angle of triangle `t` seen from `p`, in `[-2 pi, 2 pi]`:
/// positive when `p` is on the side the normal `(v1 - v0) x (v2 - v0)`
/// points away from (a point inside a closed outward surface sees each facet
/// with a positive angle).
pub fn solid_angle(t: &Triangle, p: [f64; 3]) -> f64 {
    let (det, den, _) = vo_terms(t, p);
    2.0 * det.atan2(den)
}

/// [`solid_angle`], with the sign of the numerator taken from `side(id)`
/// (true: positive) when it is too small to be trusted in floating point, so
/// that the jump of `2 pi` across the triangle is where an exact predicate
/// puts it. The numerator is within `16 eps |a||b||c|` of the exact value
/// when the differences `a, b, c` are exact.
#[inline]
pub(crate) fn solid_angle_sided(
    t: &Triangle,
    p: [f64; 3],
    id: u32,
    side: Option<&dyn Fn(u32) -> bool>,
) -> f64 {
    let (mut det, den, scale) = vo_terms(t, p);
    if let Some(f) = side {
        if det.abs() <= 16.0 * f64::EPSILON * scale {
            det = if f(id) { 0.0 } else { -0.0 };
        }
    }
    2.0 * det.atan2(den)
}

/// Distance from `p` to the closed triangle `t` (the closest point by the
/// Voronoi regions of the vertices, edges and face, as in Ericson,
/// "Real-Time Collision Detection", 5.1.5).
pub fn distance_to_triangle(p: [f64; 3], t: &Triangle) -> f64 {
    let [a, b, c] = t.v;
    let (ab, ac, ap) = (sub(b, a), sub(c, a), sub(p, a));
    let (d1, d2) = (dot(ab, ap), dot(ac, ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return norm(ap);
    }
    let bp = sub(p, b);
    let (d3, d4) = (dot(ab, bp), dot(ac, bp));
    if d3 >= 0.0 && d4 <= d3 {
        return norm(bp);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return norm(sub(ap, scale(ab, v)));
    }
    let cp = sub(p, c);
    let (d5, d6) = (dot(ab, cp), dot(ac, cp));
    if d6 >= 0.0 && d5 <= d6 {
        return norm(cp);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return norm(sub(ap, scale(ac, w)));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return norm(sub(bp, scale(sub(c, b), w)));
    }
    let denom = va + vb + vc;
    if denom == 0.0 {
        // Zero area: the nearest of the three edges.
        let seg = |u: [f64; 3], v: [f64; 3]| {
            let e = sub(v, u);
            let l = dot(e, e);
            let s = if l > 0.0 {
                (dot(sub(p, u), e) / l).clamp(0.0, 1.0)
            } else {
                0.0
            };
            norm(sub(p, add(u, scale(e, s))))
        };
        return seg(a, b).min(seg(b, c)).min(seg(c, a));
    }
    let (v, w) = (vb / denom, vc / denom);
    norm(sub(ap, add(scale(ab, v), scale(ac, w))))
}

/// The generalized winding number of `tris` at `p` by direct summation over
/// every triangle (the reference for [`WindingTree`]).
pub fn winding_number(tris: &[Triangle], p: [f64; 3]) -> f64 {
    tris.iter().map(|t| solid_angle(t, p)).sum::<f64>() / FOUR_PI
}
