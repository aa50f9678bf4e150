//! The generalized winding number of a triangle soup, its fast hierarchical
//! evaluation, and the two preparations it needs: consistent orientation and
//! caps over the boundary.
//!
//! # The winding number
//!
//! The generalized winding number (Jacobson, Kavan & Sorkine-Hornung 2013)
//! of triangles `T` at a point `p` is the sum of their signed solid angles
//! seen from `p`, over `4 pi`:
//!
//! ```text
//! w(p) = 1/(4 pi) sum_t Omega_t(p),    tan(Omega_t / 2) = a . (b x c) / (|a||b||c| + (a.b)|c| + (b.c)|a| + (c.a)|b|)
//! ```
//!
//! with `a, b, c` the triangle's vertices minus `p` (Van Oosterom & Strackee
//! 1983). For a closed, outward-oriented surface it is 1 inside and 0
//! outside (the number of times the surface wraps around `p`); for a surface
//! with holes it varies smoothly across the holes and is about 1/2 there;
//! overlapping closed parts add up. It is harmonic off the surface and jumps
//! by exactly 1 across it.
//!
//! # Fast evaluation
//!
//! [`WindingTree`] follows Barill, Dickson, Schmidt, Levin & Jacobson 2018
//! ("Fast winding numbers for soups and clouds"): the bounding-box tree of
//! [`super::bvh`] over the triangles, and for every node its area-weighted
//! centre `m`, the radius `r` of the ball around `m` holding its triangles,
//! the sum of area-weighted normals `N = sum A_t n_t` (the dipole term) and
//! the second-order tensor `T = sum A_t n_t (c_t - m)^T` (`c_t` the
//! triangle's centroid). With `K(x) = x / |x|^3` (the solid-angle kernel,
//! `Omega_t(p) = int_t n_t . K(y - p) dA`), the expansion of `K` about `m`
//! gives the node's solid angle at a far point
//!
//! ```text
//! Omega_node(p) ~ N . K(m - p) + sum_ij T_ij dK_i/dx_j(m - p),    dK_i/dx_j(x) = delta_ij / |x|^3 - 3 x_i x_j / |x|^5
//! ```
//!
//! [`WindingTree::eval`] uses it for a node when `|p - m| > beta r` (accuracy
//! parameter `beta`, [`DEFAULT_BETA`] = 2 as in the paper) and sums the
//! exact solid angles of the triangles of the near leaves.
//!
//! [`WindingTree::eval_bounded`] accepts a node by a rigorous bound on what
//! the approximation leaves out instead: the derivatives of `K` satisfy
//! `|D^k K(x)| <= (k + 1)! / |x|^(k + 2)`, so over a node of area `A` at
//! distance `d > r` the dipole term errs by at most `2 A r / (d - r)^3` and
//! the second-order expansion by at most `3 A r^2 / (d - r)^4`, and the
//! node's solid angle changes by at most `2 A rho / (d - r - rho)^3` over a
//! ball of radius `rho` around `p` (for a single triangle, `d - r` is its
//! exact distance to `p`). It returns the value with an error bound valid
//! over the whole ball, which lets a caller classify a region at once.
//!
//! # Orientation
//!
//! The winding number needs consistent orientation. [`orient`] welds
//! bit-identical vertices (as [`super::diagnostics`] does), walks each
//! component connected through manifold edges (exactly two facets) and
//! flips facets so that the two facets of each such edge traverse it in
//! opposite directions, then reverses a whole component when its signed
//! volume about its own centroid is negative (beyond rounding: a lone facet
//! or a flat patch keeps its orientation). Non-orientable components keep
//! the orientation the walk reached; the number of edges left inconsistent is
//! reported.
//!
//! # Caps
//!
//! The boundary of an oriented soup, as a chain, is the set of directed edges
//! whose two directions are not used equally often. It splits into closed
//! loops (every vertex has as many boundary edges in as out), and a fan from each loop's centroid over the
//! loop, oriented against it, closes the soup ([`close_boundary`]): the soup
//! plus its caps has no boundary, so its winding number is an integer
//! everywhere off it, and the soup's own is that integer minus the caps'.

use std::collections::HashMap;
use std::f64::consts::PI;

use super::bvh::Bvh;
use super::diagnostics::weld;
use super::{cross, dot, norm, sub, Triangle};

/// The accuracy parameter of [`WindingTree::eval`] by default: a node is
/// approximated when the query point is farther than `beta` times its radius
/// from its centre.
pub const DEFAULT_BETA: f64 = 2.0;

const FOUR_PI: f64 = 4.0 * PI;

/// Traversal stack size: the tree is balanced, so 33 entries suffice for
/// `u32` triangle indices.
const STACK: usize = 64;

/// The terms of Van Oosterom and Strackee's formula for triangle `t` seen
/// from `p`: numerator `a . (b x c)`, denominator, and `|a||b||c|`.
#[inline]
fn vo_terms(t: &Triangle, p: [f64; 3]) -> (f64, f64, f64) {
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
fn solid_angle_sided(
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
        return norm(sub(ap, scale(v, ab)));
    }
    let cp = sub(p, c);
    let (d5, d6) = (dot(ab, cp), dot(ac, cp));
    if d6 >= 0.0 && d5 <= d6 {
        return norm(cp);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return norm(sub(ap, scale(w, ac)));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return norm(sub(bp, scale(w, sub(c, b))));
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
            norm(sub(p, add(u, scale(s, e))))
        };
        return seg(a, b).min(seg(b, c)).min(seg(c, a));
    }
    let (v, w) = (vb / denom, vc / denom);
    norm(sub(ap, add(scale(v, ab), scale(w, ac))))
}

/// The generalized winding number of `tris` at `p` by direct summation over
/// every triangle (the reference for [`WindingTree`]).
pub fn winding_number(tris: &[Triangle], p: [f64; 3]) -> f64 {
    tris.iter().map(|t| solid_angle(t, p)).sum::<f64>() / FOUR_PI
}

/// Moments of one node of a [`WindingTree`].
#[derive(Clone, Copy, Debug, Default)]
struct Node {
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

fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

fn scale(s: f64, a: [f64; 3]) -> [f64; 3] {
    [s * a[0], s * a[1], s * a[2]]
}

/// `T += u v^T`.
fn add_outer(t: &mut [[f64; 3]; 3], u: [f64; 3], v: [f64; 3]) {
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
                    let nt = scale(0.5, t.normal());
                    let at = norm(nt);
                    let ct = t.centroid();
                    node.area += at;
                    node.normal = add(node.normal, nt);
                    weighted = add(weighted, scale(at, ct));
                    mean = add(mean, ct);
                }
                node.center = if node.area > 0.0 {
                    scale(1.0 / node.area, weighted)
                } else {
                    scale(1.0 / c as f64, mean)
                };
                for t in &sorted[f..f + c] {
                    let nt = scale(0.5, t.normal());
                    let ct = t.centroid();
                    let d = sub(ct, node.center);
                    add_outer(&mut node.tensor, nt, d);
                    // int_t (y - m)(y - m)^T dA = A (d d^T + 1/12 sum_v (v - c)(v - c)^T).
                    let mut second = [[0.0; 3]; 3];
                    add_outer(&mut second, d, d);
                    for v in t.v {
                        let e = sub(v, ct);
                        add_outer(&mut second, scale(1.0 / 12.0, e), e);
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
                        1.0 / node.area,
                        add(scale(l.area, l.center), scale(r.area, r.center)),
                    )
                } else {
                    scale(0.5, add(l.center, r.center))
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

/// How [`orient`] oriented a soup.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Orientation {
    /// Per facet, whether it is to be reversed.
    pub flipped: Vec<bool>,
    /// Components connected through manifold edges (facets with three
    /// distinct welded vertices only).
    pub components: usize,
    /// Facets reversed.
    pub reversed_facets: usize,
    /// Manifold edges still used twice in the same direction (the component
    /// is not orientable).
    pub conflicting_edges: usize,
}

impl Orientation {
    /// The facets with the reversed ones flipped (`v1` and `v2` swapped).
    pub fn apply(&self, tris: &[Triangle]) -> Vec<Triangle> {
        tris.iter()
            .zip(&self.flipped)
            .map(|(t, &f)| {
                if f {
                    Triangle::new(t.v[0], t.v[2], t.v[1])
                } else {
                    *t
                }
            })
            .collect()
    }
}

/// Orients every edge-connected component of `tris` consistently and
/// outward (see the module documentation).
pub fn orient(tris: &[Triangle]) -> Orientation {
    orient_welded(tris, &weld(tris).0)
}

/// [`orient`] with the welded vertex ids of the facets' corners.
pub(crate) fn orient_welded(tris: &[Triangle], ids: &[[u64; 3]]) -> Orientation {
    let n = tris.len();
    let proper = |f: &[u64; 3]| f[0] != f[1] && f[1] != f[2] && f[2] != f[0];
    // Half-edges (lower vertex, higher vertex, facet, traversed low to high).
    let mut half: Vec<(u64, u64, u32, bool)> = Vec::with_capacity(3 * n);
    for (i, f) in ids.iter().enumerate() {
        if proper(f) {
            for k in 0..3 {
                let (a, b) = (f[k], f[(k + 1) % 3]);
                half.push((a.min(b), a.max(b), i as u32, a < b));
            }
        }
    }
    half.sort_unstable_by_key(|h| (h.0, h.1, h.2));
    // Facet pairs across manifold edges, and whether they traverse it in
    // the same direction (then exactly one of them must be reversed).
    let mut links: Vec<(u32, u32, bool)> = Vec::new();
    let mut s = 0;
    while s < half.len() {
        let mut e = s + 1;
        while e < half.len() && (half[e].0, half[e].1) == (half[s].0, half[s].1) {
            e += 1;
        }
        if e - s == 2 {
            let (f, g) = (half[s], half[s + 1]);
            if f.2 != g.2 {
                links.push((f.2, g.2, f.3 == g.3));
                links.push((g.2, f.2, f.3 == g.3));
            }
        }
        s = e;
    }
    drop(half);
    links.sort_unstable();
    let mut start = vec![0usize; n + 1];
    for l in &links {
        start[l.0 as usize + 1] += 1;
    }
    for i in 0..n {
        start[i + 1] += start[i];
    }

    const NONE: u32 = u32::MAX;
    let mut comp = vec![NONE; n];
    let mut flipped = vec![false; n];
    let mut components = 0u32;
    let mut conflicts = 0usize;
    let mut stack = Vec::new();
    for seed in 0..n {
        if comp[seed] != NONE || !proper(&ids[seed]) {
            continue;
        }
        comp[seed] = components;
        stack.push(seed as u32);
        while let Some(f) = stack.pop() {
            let f = f as usize;
            for &(_, g, same) in &links[start[f]..start[f + 1]] {
                let want = flipped[f] ^ same;
                let g = g as usize;
                if comp[g] == NONE {
                    comp[g] = components;
                    flipped[g] = want;
                    stack.push(g as u32);
                } else if flipped[g] != want {
                    conflicts += 1;
                }
            }
        }
        components += 1;
    }

    // Signed volume of each component about its own centroid.
    let nc = components as usize;
    let mut weight = vec![(0.0f64, [0.0f64; 3]); nc];
    for (i, t) in tris.iter().enumerate() {
        if comp[i] != NONE {
            let a = t.area();
            let w = &mut weight[comp[i] as usize];
            w.0 += a;
            w.1 = add(w.1, scale(a, t.centroid()));
        }
    }
    let centroid: Vec<[f64; 3]> = weight
        .iter()
        .map(|(a, c)| {
            if *a > 0.0 {
                scale(1.0 / a, *c)
            } else {
                [0.0; 3]
            }
        })
        .collect();
    // The volume, and the sum of the magnitudes of its terms: a component
    // whose volume is zero up to rounding (a lone facet, a flat patch) says
    // nothing about its orientation and keeps it.
    let mut volume = vec![(0.0f64, 0.0f64); nc];
    for (i, t) in tris.iter().enumerate() {
        if comp[i] != NONE {
            let c = centroid[comp[i] as usize];
            let (a, mut b, mut d) = (sub(t.v[0], c), sub(t.v[1], c), sub(t.v[2], c));
            if flipped[i] {
                std::mem::swap(&mut b, &mut d);
            }
            let bd = cross(b, d);
            let v = &mut volume[comp[i] as usize];
            v.0 += dot(a, bd);
            v.1 += norm(a) * norm(bd);
        }
    }
    for i in 0..n {
        if comp[i] != NONE {
            let (v, magnitude) = volume[comp[i] as usize];
            if v < -1e-9 * magnitude {
                flipped[i] = !flipped[i];
            }
        }
    }
    let reversed_facets = flipped.iter().filter(|&&f| f).count();
    Orientation {
        flipped,
        components: nc,
        reversed_facets,
        // Each conflicting edge is seen from both of its facets.
        conflicting_edges: conflicts / 2,
    }
}

/// The boundary of the facets `ids` (welded corner ids; `flipped` facets
/// reversed) as closed loops of vertex ids: loop `[u0, u1, .., uk]` stands
/// for the directed edges `u0 -> u1 -> .. -> uk -> u0`. A directed edge is on
/// the boundary as many times as the facets use it more often in that
/// direction than in the other. Facets with a repeated vertex have no edges.
/// Deterministic: the loops depend on the ids only.
pub(crate) fn boundary_loops(ids: &[[u64; 3]], flipped: &[bool]) -> Vec<Vec<u64>> {
    let mut half: Vec<(u64, u64, i64)> = Vec::new();
    for (f, &rev) in ids.iter().zip(flipped) {
        if f[0] == f[1] || f[1] == f[2] || f[2] == f[0] {
            continue;
        }
        for k in 0..3 {
            let (mut a, mut b) = (f[k], f[(k + 1) % 3]);
            if rev {
                std::mem::swap(&mut a, &mut b);
            }
            half.push((a.min(b), a.max(b), if a < b { 1 } else { -1 }));
        }
    }
    half.sort_unstable();
    let mut edges: Vec<(u64, u64)> = Vec::new();
    let mut s = 0;
    while s < half.len() {
        let mut e = s;
        let mut net = 0i64;
        while e < half.len() && (half[e].0, half[e].1) == (half[s].0, half[s].1) {
            net += half[e].2;
            e += 1;
        }
        let (lo, hi) = (half[s].0, half[s].1);
        for _ in 0..net.unsigned_abs() {
            edges.push(if net > 0 { (lo, hi) } else { (hi, lo) });
        }
        s = e;
    }
    edges.sort_unstable();
    // Every vertex has as many boundary edges in as out (the boundary of a
    // sum of triangles is a sum of cycles), so a walk along unused edges
    // can only stop where it started.
    let m = edges.len();
    let mut used = vec![false; m];
    let mut cursor: HashMap<u64, usize> = HashMap::new();
    let mut loops = Vec::new();
    for i in 0..m {
        if used[i] {
            continue;
        }
        let first = edges[i].0;
        let mut lp = Vec::new();
        let mut cur = i;
        loop {
            used[cur] = true;
            lp.push(edges[cur].0);
            let v = edges[cur].1;
            if v == first {
                break;
            }
            let pos = cursor
                .entry(v)
                .or_insert_with(|| edges.partition_point(|e| e.0 < v));
            while *pos < m && edges[*pos].0 == v && used[*pos] {
                *pos += 1;
            }
            if *pos >= m || edges[*pos].0 != v {
                // Unreachable for a balanced boundary; end the loop here.
                break;
            }
            cur = *pos;
        }
        loops.push(lp);
    }
    loops
}

/// Caps closing the boundary of `tris` (taken as oriented): for every loop
/// `u_0 -> u_1 -> ..` of the boundary (see the module documentation), the
/// fan of triangles `(u_{i+1}, u_i, z)` with `z` the mean of the loop's
/// vertices. `tris` plus the caps has no boundary edge; empty when `tris`
/// has none.
pub fn close_boundary(tris: &[Triangle]) -> Vec<Triangle> {
    let (ids, nv) = weld(tris);
    let mut pos = vec![[0.0; 3]; nv];
    for (t, f) in tris.iter().zip(&ids) {
        for k in 0..3 {
            pos[f[k] as usize] = t.v[k];
        }
    }
    let mut caps = Vec::new();
    for lp in boundary_loops(&ids, &vec![false; tris.len()]) {
        let z = scale(
            1.0 / lp.len() as f64,
            lp.iter().fold([0.0; 3], |s, &u| add(s, pos[u as usize])),
        );
        for i in 0..lp.len() {
            let (u, v) = (pos[lp[i] as usize], pos[lp[(i + 1) % lp.len()] as usize]);
            caps.push(Triangle::new(v, u, z));
        }
    }
    caps
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::diagnostics::diagnose;
    use crate::geometry::shapes::{default_sphere, default_torus};
    use crate::geometry::Surface;

    use crate::testutil::Rng;

    /// The upper unit hemisphere `z >= 0` (open, outward): `rings` rings of
    /// `segments` vertices from the equator (exactly in `z = 0`) to the pole.
    fn hemisphere(rings: usize, segments: usize) -> Vec<Triangle> {
        let ring = |k: usize, j: usize| -> [f64; 3] {
            let th = 0.5 * PI * k as f64 / rings as f64;
            let ph = 2.0 * PI * j as f64 / segments as f64;
            let z = if k == 0 { 0.0 } else { th.sin() };
            [th.cos() * ph.cos(), th.cos() * ph.sin(), z]
        };
        let pole = [0.0, 0.0, 1.0];
        let mut t = Vec::new();
        for k in 0..rings - 1 {
            for j in 0..segments {
                let (a, b) = (ring(k, j), ring(k, (j + 1) % segments));
                let (c, d) = (ring(k + 1, j), ring(k + 1, (j + 1) % segments));
                t.push(Triangle::new(a, b, d));
                t.push(Triangle::new(a, d, c));
            }
        }
        for j in 0..segments {
            t.push(Triangle::new(
                ring(rings - 1, j),
                ring(rings - 1, (j + 1) % segments),
                pole,
            ));
        }
        t
    }

    #[test]
    fn solid_angle_of_an_octant() {
        // The triangle (e1, e2, e3) seen from the origin covers an eighth of
        // the sphere of directions.
        let t = Triangle::new([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
        assert!((solid_angle(&t, [0.0; 3]) - PI / 2.0).abs() < 1e-14);
        let flipped = Triangle::new(t.v[0], t.v[2], t.v[1]);
        assert!((solid_angle(&flipped, [0.0; 3]) + PI / 2.0).abs() < 1e-14);
        // From the far side of the plane, the sign changes.
        assert!(solid_angle(&t, [1.0; 3]) < 0.0);
        // In the plane, outside the triangle: no angle.
        assert!(solid_angle(&t, [2.0, 2.0, -3.0]).abs() < 1e-14);
    }

    fn closed_surface_points(s: &Surface, inside: impl Fn([f64; 3]) -> Option<bool>, seed: u64) {
        let tris = s.triangles();
        // The paper's setting (beta 2, third order) is within 1e-2 at these
        // points (5e-3 at worst on the sphere); beta 4 within 1e-3 (2.4e-4).
        let tree = WindingTree::new(tris);
        let fine = WindingTree::with_options(tris, 4.0, 3);
        let mut rng = Rng(seed);
        let (mut n_in, mut n_out) = (0, 0);
        for _ in 0..1500 {
            let p = rng.in_box(-2.0, 2.0);
            let Some(expect) = inside(p) else { continue };
            let want = if expect { 1.0 } else { 0.0 };
            let fast = tree.eval(p);
            assert!((fast - want).abs() < 1e-2, "{p:?}: {fast} (want {want})");
            let accurate = fine.eval(p);
            assert!(
                (accurate - want).abs() < 1e-3,
                "{p:?}: {accurate} (want {want})"
            );
            // The bounded evaluation meets its (pessimistic) bound.
            let (v, e) = tree
                .eval_bounded(p, 0.0, 1e-5, f64::INFINITY, usize::MAX, None)
                .unwrap();
            assert!((v - want).abs() <= e.min(1e-3), "{p:?}: {v} +- {e}");
            if n_in + n_out < 300 {
                let direct = winding_number(tris, p);
                assert!((direct - want).abs() < 1e-9, "{p:?}: {direct}");
            }
            if expect {
                n_in += 1;
            } else {
                n_out += 1;
            }
        }
        assert!(n_in > 50 && n_out > 50, "{n_in} {n_out}");
    }

    #[test]
    fn closed_sphere_is_one_inside_zero_outside() {
        // Points 2% inside or outside the unit sphere (the icosphere is
        // inscribed, within 0.1% of the radius).
        closed_surface_points(
            &default_sphere(),
            |p| {
                let r = norm(p);
                (!(0.98..=1.02).contains(&r)).then_some(r < 1.0)
            },
            1,
        );
    }

    #[test]
    fn closed_torus_is_one_inside_zero_outside() {
        closed_surface_points(
            &default_torus(),
            |p| {
                let q = ((p[0] * p[0] + p[1] * p[1]).sqrt() - 1.0).hypot(p[2]);
                (!(0.33..=0.37).contains(&q)).then_some(q < 0.35)
            },
            2,
        );
    }

    #[test]
    fn open_hemisphere_matches_the_analytic_values() {
        let tris = hemisphere(32, 128);
        let tree = WindingTree::new(&tris);
        // At the centre, in the plane of the (planar) boundary: exactly 1/2
        // for any cap over a polygon around the point.
        assert!((winding_number(&tris, [0.0; 3]) - 0.5).abs() < 1e-12);
        assert!((tree.eval([0.0; 3]) - 0.5).abs() < 1e-2);
        let fine = WindingTree::with_options(&tris, 4.0, 3);
        assert!((fine.eval([0.0; 3]) - 0.5).abs() < 1e-3);
        // On the axis below the dome (|z| < 1), the hemisphere is the closed
        // half ball minus its flat disk: w = (1 + z / sqrt(1 + z^2)) / 2;
        // above the pole w = (z / sqrt(1 + z^2) - 1) / 2. The polygonal
        // surface differs from the round one by about 1e-3 at most.
        for z in [-3.0, -0.7, -0.2, 0.25, 0.6, 0.9, 1.2, 4.0] {
            let s = z / f64::hypot(1.0, z);
            let exact = if z < 1.0 {
                0.5 * (1.0 + s)
            } else {
                0.5 * (s - 1.0)
            };
            let p = [0.0, 0.0, z];
            let direct = winding_number(&tris, p);
            assert!((direct - exact).abs() < 2e-3, "z {z}: {direct} vs {exact}");
            assert!((fine.eval(p) - direct).abs() < 1e-3, "z {z}");
        }
        // Across the opening, w is continuous: just above and below the
        // centre agree; across the dome it jumps by 1.
        let (a, b) = (fine.eval([0.0, 0.0, 1e-6]), fine.eval([0.0, 0.0, -1e-6]));
        assert!((a - b).abs() < 1e-5);
        let (c, d) = (
            winding_number(&tris, [0.0, 0.0, 0.99]),
            winding_number(&tris, [0.0, 0.0, 1.01]),
        );
        assert!((c - d - 1.0).abs() < 0.02, "{c} {d}");
    }

    /// Largest error of the tree against direct summation over random points
    /// of the surface's box (grown by half), and near the surface.
    fn max_error(tris: &[Triangle], tree: &WindingTree, seed: u64) -> f64 {
        let s = Surface::new(tris.to_vec()).unwrap();
        let b = s.bbox();
        let mut rng = Rng(seed);
        let mut worst = 0.0f64;
        for k in 0..400 {
            let p: [f64; 3] = if k % 2 == 0 {
                std::array::from_fn(|i| {
                    let e = b.max[i] - b.min[i];
                    b.min[i] - 0.5 * e + 2.0 * e * rng.unit()
                })
            } else {
                // Within 1% of the box size of a random facet.
                let t = &tris[(rng.next() % tris.len() as u64) as usize];
                let c = t.centroid();
                let h = 0.01 * b.longest_side();
                std::array::from_fn(|i| c[i] + h * (rng.unit() - 0.5))
            };
            worst = worst.max((tree.eval(p) - winding_number(tris, p)).abs());
        }
        worst
    }

    #[test]
    fn hierarchical_agrees_with_direct_summation() {
        // Tolerances, on closed and open surfaces, at points in and around
        // the box and within 1% of its size from a facet: 1e-2 with beta 2
        // and the third-order expansion (the default), 2e-3 with beta 4. The
        // third-order term pays: the dipole alone errs several times more.
        let sphere = default_sphere().triangles().to_vec();
        let hemi = hemisphere(24, 96);
        let torus = default_torus().triangles().to_vec();
        for (name, tris) in [
            ("sphere", &sphere),
            ("hemisphere", &hemi),
            ("torus", &torus),
        ] {
            let third = max_error(tris, &WindingTree::new(tris), 7);
            let second = max_error(tris, &WindingTree::with_options(tris, 2.0, 2), 7);
            let dipole = max_error(tris, &WindingTree::with_options(tris, 2.0, 1), 7);
            let fine = max_error(tris, &WindingTree::with_options(tris, 4.0, 3), 7);
            println!("{name}: max error dipole {dipole:.2e}, second order {second:.2e}, third {third:.2e}, beta 4 {fine:.2e}");
            assert!(third < 1e-2, "{name}: {third}");
            assert!(2.0 * third < dipole, "{name}: {third} vs {dipole}");
            assert!(fine < 2e-3 && fine < third, "{name}: {fine} vs {third}");
        }
    }

    #[test]
    fn bounded_evaluation_keeps_its_bound() {
        let tris = hemisphere(24, 96);
        let tree = WindingTree::new(&tris);
        let mut rng = Rng(11);
        let (mut balls, mut points) = (0, 0);
        for _ in 0..300 {
            let p = rng.in_box(-2.0, 2.0);
            let (v, e) = tree
                .eval_bounded(p, 0.0, 1e-3, f64::INFINITY, usize::MAX, None)
                .unwrap();
            assert!((v - winding_number(&tris, p)).abs() <= e, "{p:?}");
            points += 1;
            let rho = 0.2 * rng.unit();
            if let Some((v, e)) = tree.eval_bounded(p, rho, 1e-3, f64::INFINITY, usize::MAX, None) {
                balls += 1;
                for _ in 0..5 {
                    let d = rng.in_box(-1.0, 1.0);
                    let x = add(p, scale(rho * rng.unit() / norm(d), d));
                    let w = winding_number(&tris, x);
                    assert!(
                        (v - w).abs() <= e,
                        "{p:?} rho {rho}: {v} +- {e} vs {w} at {x:?}"
                    );
                }
            }
        }
        assert!(balls > 100 && points == 300, "{balls}");
        // A ball reaching the surface has no bound.
        assert!(tree
            .eval_bounded([0.0, 0.0, 0.95], 0.1, 1e-3, f64::INFINITY, usize::MAX, None)
            .is_none());
        assert!(tree
            .eval_bounded([0.0, 0.0, 0.5], 0.2, 1e-3, 1e-9, usize::MAX, None)
            .is_none());
        // Nor one that needs more work than allowed.
        assert!(tree
            .eval_bounded([0.0, 0.0, 0.5], 0.0, 1e-3, 1.0, 3, None)
            .is_none());
    }

    #[test]
    fn orientation_repairs_flipped_facets() {
        let s = default_sphere();
        let tris = s.triangles();
        let mut rng = Rng(3);
        let mut messy = tris.to_vec();
        let mut flips = 0;
        for t in messy.iter_mut() {
            if rng.next().is_multiple_of(2) {
                *t = Triangle::new(t.v[0], t.v[2], t.v[1]);
                flips += 1;
            }
        }
        assert!(diagnose(&Surface::new(messy.clone()).unwrap()).inconsistently_oriented_edges > 0);
        let o = orient(&messy);
        assert_eq!(o.components, 1);
        assert_eq!(o.conflicting_edges, 0);
        assert_eq!(o.reversed_facets, flips);
        assert_eq!(o.apply(&messy), tris);
        // All facets inward: the whole component is reversed.
        let inward: Vec<Triangle> = tris
            .iter()
            .map(|t| Triangle::new(t.v[0], t.v[2], t.v[1]))
            .collect();
        assert_eq!(orient(&inward).apply(&inward), tris);
        // Two components, one inward, one messy, far apart.
        let mut two = inward.clone();
        two.extend(messy.iter().map(|t| Triangle {
            v: t.v.map(|p| [p[0] + 5.0, p[1], p[2]]),
        }));
        let o = orient(&two);
        assert_eq!(o.components, 2);
        let fixed = o.apply(&two);
        let r = diagnose(&Surface::new(fixed.clone()).unwrap());
        assert!(r.closed && r.signed_volume.unwrap() > 0.0, "{r}");
        assert!((winding_number(&fixed, [5.0, 0.1, 0.0]) - 1.0).abs() < 1e-9);
        assert!((winding_number(&fixed, [0.0, 0.1, 0.0]) - 1.0).abs() < 1e-9);
    }

    #[test]
    fn flat_components_keep_their_orientation() {
        // Facets sharing no vertex, and a flat square of two facets, facing
        // either way: nothing to reverse.
        let s = default_sphere();
        let mut rng = Rng(8);
        let lone: Vec<Triangle> = s
            .triangles()
            .iter()
            .step_by(7)
            .enumerate()
            .map(|(i, t)| {
                let v = t.v.map(|p| [p[0] + 3.0 * i as f64, p[1], p[2]]);
                if rng.next().is_multiple_of(2) {
                    Triangle::new(v[0], v[2], v[1])
                } else {
                    Triangle { v }
                }
            })
            .collect();
        let o = orient(&lone);
        assert_eq!(o.reversed_facets, 0);
        let (p, q, r, u) = ([0.0; 3], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]);
        for square in [
            vec![Triangle::new(p, q, r), Triangle::new(p, r, u)],
            vec![Triangle::new(p, r, q), Triangle::new(p, u, r)],
        ] {
            let o = orient(&square);
            assert_eq!((o.components, o.reversed_facets), (1, 0));
        }
    }

    #[test]
    fn open_surface_orientation_follows_its_volume() {
        // The hemisphere's dome, reversed and half messed up, is turned back
        // outward: its volume about its centroid is positive.
        let tris = hemisphere(8, 32);
        let mut rng = Rng(5);
        let messy: Vec<Triangle> = tris
            .iter()
            .map(|t| {
                if !rng.next().is_multiple_of(3) {
                    Triangle::new(t.v[0], t.v[2], t.v[1])
                } else {
                    *t
                }
            })
            .collect();
        assert_eq!(orient(&messy).apply(&messy), tris);
    }

    #[test]
    fn caps_close_the_boundary() {
        // The hemisphere: one loop, the equator, closed by a fan.
        let tris = hemisphere(12, 40);
        let (ids, _) = weld(&tris);
        let loops = boundary_loops(&ids, &vec![false; tris.len()]);
        assert_eq!(loops.len(), 1);
        assert_eq!(loops[0].len(), 40);
        let caps = close_boundary(&tris);
        assert_eq!(caps.len(), 40);
        let mut closed = tris.clone();
        closed.extend(&caps);
        let r = diagnose(&Surface::new(closed.clone()).unwrap());
        assert_eq!((r.boundary_edges, r.inconsistently_oriented_edges), (0, 0));
        assert!(r.closed, "{r}");
        // The closed soup's winding number is an integer, and the open one's
        // is that integer minus the caps'.
        let mut rng = Rng(9);
        for _ in 0..200 {
            let p = rng.in_box(-1.5, 1.5);
            let wc = winding_number(&closed, p);
            assert!((wc - wc.round()).abs() < 1e-9, "{p:?}: {wc}");
            let ws = winding_number(&tris, p);
            assert!((ws - (wc - winding_number(&caps, p))).abs() < 1e-9);
        }

        // A sphere with three holes, one of them two facets wide, and a
        // facet counted twice in opposite directions (no boundary).
        let s = default_sphere().triangles().to_vec();
        let mut holed: Vec<Triangle> = s
            .iter()
            .enumerate()
            .filter(|(i, _)| ![10, 5000, 12000].contains(i))
            .map(|(_, t)| *t)
            .collect();
        let (ids, _) = weld(&holed);
        let loops = boundary_loops(&ids, &vec![false; holed.len()]);
        assert_eq!(loops.len(), 3);
        let t = holed[7];
        holed.push(t);
        holed.push(Triangle::new(t.v[0], t.v[2], t.v[1]));
        let caps = close_boundary(&holed);
        assert_eq!(caps.len(), 9);
        let mut closed = holed.clone();
        closed.extend(&caps);
        for _ in 0..100 {
            let p = rng.in_box(-1.5, 1.5);
            let wc = winding_number(&closed, p);
            assert!((wc - wc.round()).abs() < 1e-9, "{p:?}: {wc}");
        }
        // A closed surface needs no cap.
        assert!(close_boundary(&s).is_empty());
    }

    #[test]
    fn distance_to_triangle_by_sampling() {
        // Against the minimum over a fine barycentric grid (at most about
        // half a grid step above the true distance).
        let mut rng = Rng(21);
        for _ in 0..300 {
            let v: [[f64; 3]; 3] = std::array::from_fn(|_| rng.in_box(-1.0, 1.0));
            let t = Triangle { v };
            let p = rng.in_box(-2.0, 2.0);
            let d = distance_to_triangle(p, &t);
            let n = 200;
            let mut best = f64::INFINITY;
            for i in 0..=n {
                for j in 0..=n - i {
                    let (u, w) = (i as f64 / n as f64, j as f64 / n as f64);
                    let q: [f64; 3] = std::array::from_fn(|k| {
                        v[0][k] + u * (v[1][k] - v[0][k]) + w * (v[2][k] - v[0][k])
                    });
                    best = best.min(norm(sub(p, q)));
                }
            }
            assert!(d <= best + 1e-12 && best - d < 0.02, "{d} vs {best}");
        }
        // On the triangle, below it, and beyond a vertex.
        let t = Triangle::new([0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        assert_eq!(distance_to_triangle([0.25, 0.25, 0.0], &t), 0.0);
        assert_eq!(distance_to_triangle([0.25, 0.25, -2.0], &t), 2.0);
        assert_eq!(distance_to_triangle([-3.0, -4.0, 0.0], &t), 5.0);
        let flat = Triangle::new([0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]);
        assert!((distance_to_triangle([1.5, 1.0, 0.0], &flat) - 1.0).abs() < 1e-15);
    }

    #[test]
    fn empty_and_tiny_trees() {
        let empty = WindingTree::new(&[]);
        assert!(empty.is_empty());
        assert_eq!(empty.eval([0.0; 3]), 0.0);
        assert_eq!(
            empty.eval_bounded([0.0; 3], 1.0, 1e-3, 1.0, 0, None),
            Some((0.0, 0.0))
        );
        let t = Triangle::new([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
        let one = WindingTree::new(&[t]);
        assert_eq!(one.len(), 1);
        assert!((one.eval([0.0; 3]) - 0.125).abs() < 1e-12);
        assert!(
            (one.eval([30.0, -20.0, 10.0]) - winding_number(&[t], [30.0, -20.0, 10.0])).abs()
                < 1e-6
        );
        assert_eq!(one.beta(), DEFAULT_BETA);
        // The side callback decides for a point in the triangle's plane.
        let p = [1.0 / 3.0; 3];
        let up = one.eval_exact(p, Some(&|_| true));
        let down = one.eval_exact(p, Some(&|_| false));
        assert!(
            (up - 0.5).abs() < 1e-12 && (down + 0.5).abs() < 1e-12,
            "{up} {down}"
        );
    }
}
