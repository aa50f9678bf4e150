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
//! The winding number needs consistent orientation. `orient` welds
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

use std::f64::consts::PI;

mod caps;
mod orient;
mod solid_angle;
mod tree;

#[cfg(test)]
mod tests;

pub use caps::*;
pub use orient::*;
pub use solid_angle::*;
pub use tree::*;

/// The accuracy parameter of [`WindingTree::eval`] by default: a node is
/// approximated when the query point is farther than `beta` times its radius
/// from its centre.
pub const DEFAULT_BETA: f64 = 2.0;

pub(crate) const FOUR_PI: f64 = 4.0 * PI;

/// Traversal stack size: the tree is balanced, so 33 entries suffice for
/// `u32` triangle indices.
pub(crate) const STACK: usize = 64;
