//! Tests of the winding number, its tree, orientation and caps.

use super::*;
use crate::geometry::diagnostics::diagnose;
use crate::geometry::diagnostics::weld;
use crate::geometry::shapes::{default_sphere, default_torus};
use crate::geometry::vector::{add, norm, scale, sub};
use crate::geometry::Surface;
use crate::geometry::Triangle;
use std::f64::consts::PI;

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
                let x = add(p, scale(d, rho * rng.unit() / norm(d)));
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
        (one.eval([30.0, -20.0, 10.0]) - winding_number(&[t], [30.0, -20.0, 10.0])).abs() < 1e-6
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
