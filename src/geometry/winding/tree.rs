//! The bounding-box tree with far-field expansions that evaluates winding
//! numbers fast, with guaranteed error bounds.

use super::*;
use crate::geometry::bvh::Bvh;
use crate::geometry::vector::{add, dot, norm, scale, sub};
use crate::geometry::Triangle;

/// Moments of one node of a [`WindingTree`].
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Node {
    /// Area-weighted centroid (the mean of the centroids if the area is 0).
    center: [f64; 3],
    /// Largest distance from `center` to a vertex of the node.
    radius: f64,
    /// Total area.
    area: f64,
    /// `sum A_t n_t`.
    normal: [f64; 3],
    /// `T[i][j] = sum A_t n_t[i] (c_t - center)[j]`.
    tensor: [[f64; 3]; 3],
    /// `C[i][j][k] = sum_t n_t[i] int_t (y - center)[j] (y - center)[k] dA`.
    third: [[[f64; 3]; 3]; 3],
    /// Leaf: first triangle; internal: left child (the right one follows).
    first: u32,
    /// Triangles in a leaf, 0 for an internal node.
    count: u32,
}

/// A tree over triangles for fast winding numbers (see the module
/// documentation).
#[derive(Clone, Debug)]
pub struct WindingTree {
    nodes: Vec<Node>,
    /// The triangles in leaf order.
    tris: Vec<Triangle>,
    /// Index of each in the slice the tree was built from.
    ids: Vec<u32>,
    beta: f64,
    order: u8,
}

/// `T += u v^T`.
pub(crate) fn add_outer(t: &mut [[f64; 3]; 3], u: [f64; 3], v: [f64; 3]) {
    for i in 0..3 {
        for j in 0..3 {
            t[i][j] += u[i] * v[j];
        }
    }
}

impl WindingTree {
    /// Builds the tree with [`DEFAULT_BETA`] and expansions to the third
    /// order.
    ///
    /// # Panics
    /// If there are more than `u32::MAX` triangles.
    pub fn new(tris: &[Triangle]) -> WindingTree {
        WindingTree::with_options(tris, DEFAULT_BETA, 3)
    }

    /// Builds the tree with accuracy parameter `beta` (> 1; larger is more
    /// accurate and slower) for [`WindingTree::eval`] and far-field
    /// expansions of `order` 1 (the dipole term alone), 2 (with the tensor
    /// `T`) or 3 (with the third moments `C`).
    ///
    /// # Panics
    /// If `beta <= 1`, `order` is not 1, 2 or 3, or there are more than
    /// `u32::MAX` triangles.
    pub fn with_options(tris: &[Triangle], beta: f64, order: u8) -> WindingTree {
        assert!(beta > 1.0, "beta must be above 1, got {beta}");
        assert!(
            (1..=3).contains(&order),
            "order must be 1, 2 or 3, got {order}"
        );
        let bvh = Bvh::new(tris);
        let ids = bvh.order().to_vec();
        let sorted: Vec<Triangle> = ids.iter().map(|&i| tris[i as usize]).collect();
        let n = bvh.node_count();
        let mut nodes = vec![Node::default(); n];
        // Slot range of every node: subtrees are contiguous in leaf order.
        let mut range = vec![(0usize, 0usize); n];
        // Children come after their parent, so a reverse sweep is bottom-up.
        for i in (0..n).rev() {
            let (first, count) = bvh.node_shape(i);
            let (f, c) = (first as usize, count as usize);
            let mut node = Node {
                first,
                count,
                ..Node::default()
            };
            if count > 0 {
                range[i] = (f, f + c);
                let mut weighted = [0.0; 3];
                let mut mean = [0.0; 3];
                for t in &sorted[f..f + c] {
                    let nt = scale(t.normal(), 0.5);
                    let at = norm(nt);
                    let ct = t.centroid();
                    node.area += at;
                    node.normal = add(node.normal, nt);
                    weighted = add(weighted, scale(ct, at));
                    mean = add(mean, ct);
                }
                node.center = if node.area > 0.0 {
                    scale(weighted, 1.0 / node.area)
                } else {
                    scale(mean, 1.0 / c as f64)
                };
                for t in &sorted[f..f + c] {
                    let nt = scale(t.normal(), 0.5);
                    let ct = t.centroid();
                    let d = sub(ct, node.center);
                    add_outer(&mut node.tensor, nt, d);
                    // int_t (y - m)(y - m)^T dA = A (d d^T + 1/12 sum_v (v - c)(v - c)^T).
                    let mut second = [[0.0; 3]; 3];
                    add_outer(&mut second, d, d);
                    for v in t.v {
                        let e = sub(v, ct);
                        add_outer(&mut second, scale(e, 1.0 / 12.0), e);
                    }
                    for (plane, &ni) in node.third.iter_mut().zip(&nt) {
                        for (row, srow) in plane.iter_mut().zip(&second) {
                            for (x, &s) in row.iter_mut().zip(srow) {
                                *x += ni * s;
                            }
                        }
                    }
                }
            } else {
                let (l, r) = (&nodes[f], &nodes[f + 1]);
                range[i] = (range[f].0, range[f + 1].1);
                node.area = l.area + r.area;
                node.center = if node.area > 0.0 {
                    scale(
                        add(scale(l.center, l.area), scale(r.center, r.area)),
                        1.0 / node.area,
                    )
                } else {
                    scale(add(l.center, r.center), 0.5)
                };
                node.normal = add(l.normal, r.normal);
                for ch in [l, r] {
                    // Moments about the child's centre, moved to this one:
                    // y - m = (y - m_c) + e.
                    let e = sub(ch.center, node.center);
                    for i in 0..3 {
                        for j in 0..3 {
                            node.tensor[i][j] += ch.tensor[i][j] + ch.normal[i] * e[j];
                            for k in 0..3 {
                                node.third[i][j][k] += ch.third[i][j][k]
                                    + ch.tensor[i][j] * e[k]
                                    + ch.tensor[i][k] * e[j]
                                    + ch.normal[i] * e[j] * e[k];
                            }
                        }
                    }
                }
            }
            let (lo, hi) = range[i];
            node.radius = sorted[lo..hi]
                .iter()
                .flat_map(|t| t.v)
                .map(|v| norm(sub(v, node.center)))
                .fold(0.0, f64::max);
            nodes[i] = node;
        }
        WindingTree {
            nodes,
            tris: sorted,
            ids,
            beta,
            order,
        }
    }

    /// Number of triangles.
    pub fn len(&self) -> usize {
        self.tris.len()
    }

    /// True if the tree holds no triangle (its winding number is 0).
    pub fn is_empty(&self) -> bool {
        self.tris.is_empty()
    }

    /// The accuracy parameter.
    pub fn beta(&self) -> f64 {
        self.beta
    }

    /// The node's solid angle at `p` by its expansion; `r = center - p`,
    /// `d2 = |r|^2`.
    #[inline]
    fn far(&self, n: &Node, r: [f64; 3], d2: f64) -> f64 {
        let inv3 = 1.0 / (d2 * d2.sqrt());
        let mut w = dot(n.normal, r) * inv3;
        if self.order >= 2 {
            // T : DK(r), DK_ij = delta_ij / |r|^3 - 3 r_i r_j / |r|^5.
            let t = &n.tensor;
            let trace = t[0][0] + t[1][1] + t[2][2];
            let mut rtr = 0.0;
            for i in 0..3 {
                rtr += r[i] * (t[i][0] * r[0] + t[i][1] * r[1] + t[i][2] * r[2]);
            }
            w += (trace - 3.0 * rtr / d2) * inv3;
        }
        if self.order >= 3 {
            // C : D^2K(r) / 2, with (D^2K)_ijk = -3 (delta_ij r_k + delta_ik r_j
            // + delta_jk r_i) / |r|^5 + 15 r_i r_j r_k / |r|^7 and C symmetric
            // in j, k.
            let c = &n.third;
            let (mut lin, mut cub) = (0.0, 0.0);
            for i in 0..3 {
                let ciik = c[i][i];
                let cijj = c[i][0][0] + c[i][1][1] + c[i][2][2];
                lin += 6.0 * (ciik[0] * r[0] + ciik[1] * r[1] + ciik[2] * r[2]) + 3.0 * cijj * r[i];
                let mut q = 0.0;
                for j in 0..3 {
                    q += r[j] * (c[i][j][0] * r[0] + c[i][j][1] * r[1] + c[i][j][2] * r[2]);
                }
                cub += r[i] * q;
            }
            w += 0.5 * (15.0 * cub / d2 - lin) * inv3 / d2;
        }
        w
    }

    /// The winding number at `p`, with far nodes approximated (accuracy
    /// parameter `beta`).
    pub fn eval(&self, p: [f64; 3]) -> f64 {
        if self.nodes.is_empty() {
            return 0.0;
        }
        let mut stack = [0u32; STACK];
        let mut sp = 1;
        let mut sum = 0.0;
        let b2 = self.beta * self.beta;
        while sp > 0 {
            sp -= 1;
            let n = &self.nodes[stack[sp] as usize];
            let r = sub(n.center, p);
            let d2 = dot(r, r);
            if d2 > b2 * n.radius * n.radius {
                sum += self.far(n, r, d2);
            } else if n.count > 0 {
                let f = n.first as usize;
                for t in &self.tris[f..f + n.count as usize] {
                    sum += solid_angle(t, p);
                }
            } else {
                stack[sp] = n.first + 1;
                stack[sp + 1] = n.first;
                sp += 2;
            }
        }
        sum / FOUR_PI
    }

    /// The winding number near `p` with a guaranteed error: returns `(v,
    /// e)` such that `|w(x) - v| <= e` for every `x` with `|x - p| <= rho`
    /// (up to floating-point rounding), or `None` when a triangle may come
    /// within `rho` of `p` (the winding number may jump in the ball), the
    /// bound exceeds `max_err`, or more than `max_work` nodes and triangles
    /// would be visited. A node is approximated when its part of the
    /// bound is at most `budget` times its share of the total area, so the
    /// approximations together err by at most `budget`; triangles of near
    /// leaves are summed exactly (over a ball, their variation adds to the
    /// bound).
    ///
    /// `side`, given the index of a triangle (in the slice the tree was
    /// built from), decides on which side of its plane `p` is (true: the
    /// numerator `a . (b x c)` is positive) when floating point cannot;
    /// with exact integer coordinates for `p` and the vertices, it lets an
    /// exact predicate place the jump across the triangle.
    pub fn eval_bounded(
        &self,
        p: [f64; 3],
        rho: f64,
        budget: f64,
        max_err: f64,
        max_work: usize,
        side: Option<&dyn Fn(u32) -> bool>,
    ) -> Option<(f64, f64)> {
        if self.nodes.is_empty() {
            return Some((0.0, 0.0));
        }
        let per_area = budget / self.nodes[0].area;
        let mut work = 0usize;
        let mut stack = [0u32; STACK];
        let mut sp = 1;
        let (mut sum, mut err) = (0.0, 0.0);
        while sp > 0 {
            sp -= 1;
            work += 1 + self.nodes[stack[sp] as usize].count as usize;
            if work > max_work {
                return None;
            }
            let n = &self.nodes[stack[sp] as usize];
            let r = sub(n.center, p);
            let d2 = dot(r, r);
            let gap = d2.sqrt() - n.radius;
            if gap > rho {
                // Remainder of the expansion of order k: (k + 1) A r^k / gap^(k + 2).
                let q = n.radius / gap;
                let qk = match self.order {
                    1 => q,
                    2 => q * q,
                    _ => q * q * q,
                };
                let approx = (self.order + 1) as f64 * n.area * qk / (gap * gap);
                let g = gap - rho;
                let e = (approx + 2.0 * n.area * rho / (g * g * g)) / FOUR_PI;
                if e <= per_area * n.area {
                    sum += self.far(n, r, d2);
                    err += e;
                    if err > max_err {
                        return None;
                    }
                    continue;
                }
            }
            if n.count > 0 {
                let f = n.first as usize;
                for slot in f..f + n.count as usize {
                    let t = &self.tris[slot];
                    if rho > 0.0 {
                        let g = distance_to_triangle(p, t) - rho;
                        if g <= 0.0 {
                            return None;
                        }
                        err += 2.0 * t.area() * rho / (g * g * g) / FOUR_PI;
                    }
                    sum += solid_angle_sided(t, p, self.ids[slot], side);
                }
                if err > max_err {
                    return None;
                }
            } else {
                stack[sp] = n.first + 1;
                stack[sp + 1] = n.first;
                sp += 2;
            }
        }
        // Rounding of the exact terms and of the sum.
        Some((sum / FOUR_PI, err + 1e-9))
    }

    /// The winding number at `p` summed exactly over every triangle, with
    /// `side` as in [`WindingTree::eval_bounded`].
    pub fn eval_exact(&self, p: [f64; 3], side: Option<&dyn Fn(u32) -> bool>) -> f64 {
        self.tris
            .iter()
            .zip(&self.ids)
            .map(|(t, &id)| solid_angle_sided(t, p, id, side))
            .sum::<f64>()
            / FOUR_PI
    }
}
