//! Exact integer predicates on fixed-point triangles: the orientation and
//! segment-crossing tests the inside/outside classification decides
//! with, free of rounding (products in `i128`).

/// `x.round() as i64` for `|x| < 2^52`, without the library call that
/// `round` is on x86-64 before SSE4.1: `x - trunc(x)` is exact there.
#[inline]
pub(crate) fn round_half_away(x: f64) -> i64 {
    let t = x as i64;
    let frac = x - t as f64;
    t + (frac >= 0.5) as i64 - (frac <= -0.5) as i64
}

/// A triangle rounded to fixed point.
#[derive(Clone, Copy)]
pub(crate) struct FixedTri {
    pub(crate) v: [[i64; 3]; 3],
    /// Sign of `n . t` for the perturbation `t` (+1 or -1): the sign of the
    /// first non-zero component of the normal; 0 for a triangle of zero
    /// area, which parity skips.
    pub(crate) nsign: i8,
}

impl FixedTri {
    pub(crate) fn new(v: [[i64; 3]; 3]) -> FixedTri {
        let n = normal(&v);
        let nsign = n.iter().find(|&&c| c != 0).map_or(0, |&c| c.signum() as i8);
        FixedTri { v, nsign }
    }

    /// Whether `p` (perturbed) is on the side the normal points to.
    #[inline]
    pub(crate) fn positive_side(&self, p: [i64; 3]) -> bool {
        let o = dot(normal(&self.v), sub(p, self.v[0]));
        if o != 0 {
            o > 0
        } else {
            self.nsign > 0
        }
    }
}

#[inline]
pub(crate) fn sub(a: [i64; 3], b: [i64; 3]) -> [i64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// Cross product of vectors below `2^41`: components below `2^83`.
#[inline]
pub(crate) fn cross(a: [i64; 3], b: [i64; 3]) -> [i128; 3] {
    let m = |x: i64, y: i64| x as i128 * y as i128;
    [
        m(a[1], b[2]) - m(a[2], b[1]),
        m(a[2], b[0]) - m(a[0], b[2]),
        m(a[0], b[1]) - m(a[1], b[0]),
    ]
}

/// `w . d` for `w` below `2^83` and `d` below `2^41`: below `2^126`.
#[inline]
pub(crate) fn dot(w: [i128; 3], d: [i64; 3]) -> i128 {
    w[0] * d[0] as i128 + w[1] * d[1] as i128 + w[2] * d[2] as i128
}

/// Unnormalised normal `(b - a) x (c - a)`.
#[inline]
pub(crate) fn normal(v: &[[i64; 3]; 3]) -> [i128; 3] {
    cross(sub(v[1], v[0]), sub(v[2], v[0]))
}

/// Sign of the first non-zero component (false for negative; true for
/// positive or all zero).
#[inline]
pub(crate) fn first_sign(m: [i128; 3]) -> bool {
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
pub(crate) fn edge_side(w: [i128; 3], d: [i64; 3], a: [i64; 3], b: [i64; 3]) -> bool {
    let o = dot(w, d);
    if o != 0 {
        return o > 0;
    }
    first_sign(cross(sub(a, b), d))
}

/// Whether segment `pq` crosses the triangle (perturbed, see the module
/// documentation). The triangle must have positive area.
pub(crate) fn crosses(p: [i64; 3], q: [i64; 3], t: &FixedTri) -> bool {
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
