//! The validity test of the snapped elements: each corner's scaled
//! Jacobian against the least allowed, squared (no roots or divisions).

use std::sync::atomic::{AtomicU64, Ordering};

use crate::geometry::cells::CORNER_EDGES;

use super::mean;

/// Per corner of the hexahedron `p` (VTK order), the determinant of its
/// three edges ([`CORNER_EDGES`]) and the product of their squared
/// lengths. Computed across the corners (one array per coordinate), so
/// each step is one operation on all eight: the compiler packs them.
#[inline(always)]
pub(super) fn corner_terms(p: &[[f64; 3]; 8]) -> ([f64; 8], [f64; 8]) {
    let column = |a: usize| -> [f64; 8] { std::array::from_fn(|k| p[k][a]) };
    let (x, y, z) = (column(0), column(1), column(2));
    let edge = |c: &[f64; 8], e: usize| -> [f64; 8] {
        std::array::from_fn(|k| c[CORNER_EDGES[k][e]] - c[k])
    };
    let (ax, ay, az) = (edge(&x, 0), edge(&y, 0), edge(&z, 0));
    let (bx, by, bz) = (edge(&x, 1), edge(&y, 1), edge(&z, 1));
    let (cx, cy, cz) = (edge(&x, 2), edge(&y, 2), edge(&z, 2));
    let det = std::array::from_fn(|k| {
        ax[k] * (by[k] * cz[k] - bz[k] * cy[k]) - ay[k] * (bx[k] * cz[k] - bz[k] * cx[k])
            + az[k] * (bx[k] * cy[k] - by[k] * cx[k])
    });
    let product = std::array::from_fn(|k| {
        (ax[k] * ax[k] + ay[k] * ay[k] + az[k] * az[k])
            * (bx[k] * bx[k] + by[k] * by[k] + bz[k] * bz[k])
            * (cx[k] * cx[k] + cy[k] * cy[k] + cz[k] * cz[k])
    });
    (det, product)
}

/// The corners of the hexahedron `p` (VTK order) whose scaled Jacobian is
/// below `sqrt(j2)` or not positive, as bits (bit `k`: corner `k`; 0 when
/// the element is valid), tested as `det >= j |e0| |e1| |e2|` squared
/// without roots or divisions; and the least over the corners of the
/// scaled Jacobian times its absolute value (0 where an edge has no
/// length), which orders the elements as their least scaled Jacobians do.
#[inline(always)]
pub(super) fn corner_verdict(p: &[[f64; 3]; 8], j2: f64) -> (u8, f64) {
    let (det, product) = corner_terms(p);
    let mut failed = 0u8;
    for k in 0..8 {
        let pass = det[k] > 0.0 && det[k] * det[k] >= j2 * product[k];
        failed |= (!pass as u8) << k;
    }
    let figure: [f64; 8] = std::array::from_fn(|k| {
        if product[k] == 0.0 {
            0.0
        } else {
            det[k] * det[k].abs() / product[k]
        }
    });
    (failed, figure.iter().fold(f64::INFINITY, |l, &f| l.min(f)))
}

/// What [`super::snapper::Snapper::bad_among`] measures with, shared by its threads.
pub(super) struct Measure<'a> {
    pub(super) conn: &'a [[u32; 8]],
    pub(super) ni: usize,
    pub(super) deps: &'a [([u32; 4], u8)],
    pub(super) fixed: &'a [[f64; 3]],
    /// The hanging nodes' positions, placed as they are met (two threads
    /// may place the same one, with the same bits).
    pub(super) hanging: &'a [AtomicU64],
    /// Per element, its least figure, stored by the thread measuring it.
    pub(super) least: &'a [AtomicU64],
    pub(super) j2: f64,
    /// The processor has AVX-512F.
    pub(super) wide: bool,
}

impl Measure<'_> {
    /// The elements of `part` with a corner below the least scaled
    /// Jacobian, and those corners; with AVX-512 where the processor has
    /// it ([`super::wide`]): the same verdicts and figures. (A least figure of
    /// zero may come with the other sign.)
    #[inline]
    pub(super) fn part(&self, part: &[u32]) -> Vec<(u32, u8)> {
        #[cfg(target_arch = "x86_64")]
        if self.wide {
            // SAFETY: `wide` says the processor has AVX-512F.
            return unsafe { super::wide::measure(self, part) };
        }
        self.run(part, corner_verdict)
    }

    /// [`Measure::part`] with the corner test `verdict`.
    #[inline(always)]
    pub(super) fn run(
        &self,
        part: &[u32],
        verdict: impl Fn(&[[f64; 3]; 8], f64) -> (u8, f64),
    ) -> Vec<(u32, u8)> {
        let (conn, ni, deps, fixed) = (self.conn, self.ni, self.deps, self.fixed);
        let mut bad = Vec::new();
        for (k, &e) in part.iter().enumerate() {
            if let Some(&ahead) = part.get(k + 6) {
                for &n in &conn[ahead as usize] {
                    let n = n as usize;
                    if n < ni {
                        crate::mesh::prefetch(fixed, n);
                    } else {
                        crate::mesh::prefetch(self.hanging, 3 * (n - ni));
                    }
                }
            }
            let mut p = [[0.0; 3]; 8];
            for (q, &n) in p.iter_mut().zip(&conn[e as usize]) {
                let n = n as usize;
                *q = if n < ni {
                    fixed[n]
                } else {
                    let m = mean(fixed, deps[n - ni]);
                    for (w, v) in self.hanging[3 * (n - ni)..][..3].iter().zip(m) {
                        w.store(v.to_bits(), Ordering::Relaxed);
                    }
                    m
                };
            }
            let (failed, figure) = verdict(&p, self.j2);
            self.least[e as usize].store(figure.to_bits(), Ordering::Relaxed);
            if failed != 0 {
                bad.push((e, failed));
            }
        }
        bad
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::cells::{corner_scaled_jacobians, VTK_TO_MORTON};

    /// Numbers in `[-0.5, 0.5)` from `seed` (xorshift: the same on
    /// every run).
    fn uniform(mut x: u64) -> impl FnMut() -> f64 {
        move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        }
    }

    #[test]
    fn the_squared_test_agrees_with_the_scaled_jacobians() {
        let mut next = uniform(0x9e37_79b9_7f4a_7c15);
        let mut agree = 0;
        for _ in 0..2000 {
            let p: [[f64; 3]; 8] = std::array::from_fn(|v| {
                let m = VTK_TO_MORTON[v];
                [0, 1, 2].map(|a| (m >> a & 1) as f64 + 0.6 * next())
            });
            let j = corner_scaled_jacobians(&p);
            for t in [0.001, 0.1, 0.3] {
                let slow = j.iter().all(|&v| v >= t);
                let near = j.iter().any(|&v| (v - t).abs() < 1e-12);
                if !near {
                    let (failed, least) = corner_verdict(&p, t * t);
                    assert_eq!(failed == 0, slow, "{p:?} {t}");
                    assert_eq!(least >= t * t, slow, "{p:?} {t}");
                    agree += slow as usize;
                }
            }
        }
        assert!(agree > 500, "{agree}");
    }

    #[test]
    #[cfg(target_arch = "x86_64")]
    fn the_wide_test_gives_the_same_bits() {
        if !crate::parallel::cores::avx512() {
            eprintln!("skipped: this processor has no AVX-512F");
            return;
        }
        let mut next = uniform(0x2545_f491_4f6c_dd1d);
        let mut failing = 0;
        for round in 0..4000 {
            let mut p: [[f64; 3]; 8] = std::array::from_fn(|v| {
                let m = VTK_TO_MORTON[v];
                [0, 1, 2].map(|a| (m >> a & 1) as f64 * 1024.0 + 700.0 * next())
            });
            // Flat and collapsed elements too: an edge of no length, two
            // corners in one plane.
            if round % 7 == 0 {
                p[6] = p[5];
            }
            if round % 11 == 0 {
                p[3][2] = p[0][2];
            }
            for j in [0.0, 0.001, 0.1, 0.5] {
                let scalar = corner_verdict(&p, j * j);
                // SAFETY: the processor has AVX-512F (checked above).
                let wide = unsafe { super::super::wide::corner_verdict(&p, j * j) };
                assert_eq!(scalar.0, wide.0, "{p:?} {j}");
                // The same number; a zero may come with either sign.
                assert!(scalar.1 == wide.1, "{p:?} {j}: {scalar:?} {wide:?}");
                assert_eq!(scalar.1.to_bits() | 1 << 63, wide.1.to_bits() | 1 << 63);
                failing += (scalar.0 != 0) as usize;
            }
        }
        assert!(failing > 1000, "{failing}");
    }
}
