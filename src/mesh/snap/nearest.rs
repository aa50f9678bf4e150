//! The nearest triangle to a surface node: the triangles gathered around
//! a recent node, which prove the answer for the nodes near it.

use crate::geometry::bvh::Bvh;
use crate::geometry::distance::{point_box2, point_triangle2};
use crate::geometry::{Aabb, Triangle};

/// The half side (in cells of the node's finest element) of the cube
/// around a node whose triangles [`NearTriangles`] gathers.
pub(super) const NEAR_REACH: f64 = 2.0;

/// The triangles whose bounding boxes meet a cube around a recent surface
/// node: the nearest of them to a point `x` well inside the cube is the
/// nearest of all when it is nearer than the cube's side from `x` (every
/// other triangle lies outside the cube).
#[derive(Default)]
pub(super) struct NearTriangles {
    pub(super) centre: [f64; 3],
    pub(super) half: f64,
    /// The triangles and their bounding boxes.
    pub(super) found: Vec<(u32, Aabb)>,
    /// With `wide` (the processor has AVX-512F), the same eight to a
    /// chunk, as columns.
    pub(super) wide: bool,
    pub(super) chunks: Vec<Chunk>,
    /// The last answer, a first bound for the tree.
    pub(super) last: Option<u32>,
}

/// Eight gathered triangles (the last chunk padded with boxes at
/// infinity), coordinate `k` of lane `j` at `[k][j]`.
#[derive(Clone, Copy)]
pub(super) struct Chunk {
    pub(super) ids: [u32; 8],
    pub(super) lo: [[f64; 8]; 3],
    pub(super) hi: [[f64; 8]; 3],
    pub(super) a: [[f64; 8]; 3],
    pub(super) b: [[f64; 8]; 3],
    pub(super) c: [[f64; 8]; 3],
}

impl Chunk {
    const EMPTY: Chunk = Chunk {
        ids: [u32::MAX; 8],
        lo: [[f64::INFINITY; 8]; 3],
        hi: [[f64::INFINITY; 8]; 3],
        a: [[0.0; 8]; 3],
        b: [[0.0; 8]; 3],
        c: [[0.0; 8]; 3],
    };
}

impl NearTriangles {
    /// Gathers the triangles around the cube of half side `half` at `x`.
    #[inline]
    pub(super) fn gather(&mut self, bvh: &Bvh, tris: &[Triangle], x: [f64; 3], half: f64) {
        self.centre = x;
        self.half = half;
        self.found.clear();
        bvh.query_candidate_boxes(x.map(|v| v - half), x.map(|v| v + half), &mut self.found);
        self.chunks.clear();
        if self.wide {
            for piece in self.found.chunks(8) {
                self.chunks.push(Chunk::EMPTY);
                let ch = self.chunks.last_mut().expect("a chunk was pushed");
                for (j, &(t, b)) in piece.iter().enumerate() {
                    let [p, q, r] = tris[t as usize].v;
                    ch.ids[j] = t;
                    for k in 0..3 {
                        ch.lo[k][j] = b.min[k];
                        ch.hi[k][j] = b.max[k];
                        ch.a[k][j] = p[k];
                        ch.b[k][j] = q[k];
                        ch.c[k][j] = r[k];
                    }
                }
            }
        }
    }

    /// The triangle nearest `x` (ties to the lowest index) if the gathered
    /// ones prove it: nearer than any point outside the cube, with a
    /// margin for rounding.
    #[inline]
    pub(super) fn nearest(&self, tris: &[Triangle], x: [f64; 3]) -> Option<u32> {
        let dx = (0..3)
            .map(|a| (x[a] - self.centre[a]).abs())
            .fold(0.0, f64::max);
        let room = self.half - dx;
        if room <= 0.0 {
            return None;
        }
        let mut near = Nearest {
            best: None,
            bound: 0.98 * room * room,
        };
        // The last answer first: usually near, it prunes the rest.
        if let Some(t) = self.last {
            let [p, q, r] = tris[t as usize].v;
            near.offer(t, point_triangle2(x, p, q, r));
        }
        #[cfg(target_arch = "x86_64")]
        if self.wide {
            // SAFETY: `wide` says the processor has AVX-512F.
            unsafe { super::wide::scan(&self.chunks, tris, x, &mut near) };
            return near.best.map(|b| b.0);
        }
        for &(t, b) in &self.found {
            if point_box2(x, b.min, b.max) > near.bound {
                continue;
            }
            let [p, q, r] = tris[t as usize].v;
            near.offer(t, point_triangle2(x, p, q, r));
        }
        near.best.map(|b| b.0)
    }
}

/// The nearest triangle so far and its squared distance, and the bound a
/// nearer one must beat (the distance limit until one is found).
pub(super) struct Nearest {
    pub(super) best: Option<(u32, f64)>,
    pub(super) bound: f64,
}

impl Nearest {
    /// Triangle `t` at squared distance `d`: kept if nearer, or as near
    /// with a lower index (so the answer does not depend on the order).
    #[inline(always)]
    pub(super) fn offer(&mut self, t: u32, d: f64) {
        let better = match self.best {
            None => d < self.bound,
            Some((bt, bd)) => d < bd || (d == bd && t < bt),
        };
        if better {
            self.best = Some((t, d));
            self.bound = d;
        }
    }
}
