//! Tests of the classification: rules, parity, winding numbers, caps,
//! rank-count invariance.

use super::masks::*;
use super::walk::*;
use super::*;
use crate::geometry::diagnostics::diagnose;
use crate::geometry::intersect::triangle_box_overlap;
use crate::geometry::predicates::*;
use crate::geometry::shapes::{default_sphere, default_torus, sphere};
use crate::geometry::winding::winding_number;
use crate::geometry::{Surface, Triangle};
use crate::octree::domain::{Domain, DEFAULT_FIT};
use crate::octree::octant::CELLS;
use crate::octree::octant::{Octant, MAX_LEVEL, ROOT_LEN};
use crate::parallel::comm::{CommRef, SerialComm};
use crate::refine::SurfaceIndex;

fn norm(p: [f64; 3]) -> f64 {
    f_dot(p, p).sqrt()
}
use crate::refine::{build_from_surface, NO_LIMIT};
use crate::Connectivity;
use std::rc::Rc;

use crate::testutil::Rng;

fn fitted(surface: &Surface) -> (Domain, SurfaceIndex) {
    let b = surface.bbox();
    let d = Domain::around(b.min, b.max, DEFAULT_FIT).unwrap();
    let index = SurfaceIndex::new(surface, &d);
    (d, index)
}

/// The surface-refined tree at `level`, optionally 2:1 balanced.
fn leaves_of(index: &SurfaceIndex, level: u8, balance: bool) -> Vec<Octant> {
    let comm: CommRef = Rc::new(SerialComm);
    let mut t = build_from_surface(comm, index, level, NO_LIMIT).unwrap();
    if balance {
        t.balance(Connectivity::Corner).unwrap();
    }
    t.leaves().to_vec()
}

fn f_sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn f_cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn f_dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Classic ray parity in plain floating point (Moller-Trumbore against
/// every triangle); `None` when some hit is too close to call.
fn ray_inside(p: [f64; 3], tris: &[Triangle]) -> Option<bool> {
    let dir = [0.356_123_7, 0.581_774_1, 0.731_229_5];
    let mut inside = false;
    for t in tris {
        let [a, b, c] = t.v;
        let (e1, e2) = (f_sub(b, a), f_sub(c, a));
        let pv = f_cross(dir, e2);
        let det = f_dot(e1, pv);
        let n = f_cross(e1, e2);
        let nn = f_dot(n, n).sqrt();
        if nn == 0.0 {
            continue;
        }
        let w = f_sub(p, a);
        if det.abs() <= 1e-12 * nn {
            // Ray parallel to the plane: only a centre in it is a problem.
            if (f_dot(n, w) / nn).abs() < 1e-6 {
                return None;
            }
            continue;
        }
        let inv = 1.0 / det;
        let u = f_dot(w, pv) * inv;
        let qv = f_cross(w, e1);
        let v = f_dot(dir, qv) * inv;
        let s = f_dot(e2, qv) * inv;
        let eps = 1e-9;
        if u < -eps || v < -eps || u + v > 1.0 + eps || s < -1e-6 {
            continue;
        }
        if u < eps || v < eps || u + v > 1.0 - eps || s < 1e-6 {
            return None;
        }
        inside = !inside;
    }
    Some(inside)
}

fn center_f64(o: Octant) -> [f64; 3] {
    let (lo, hi) = o.bounds_f64();
    [
        0.5 * (lo[0] + hi[0]),
        0.5 * (lo[1] + hi[1]),
        0.5 * (lo[2] + hi[2]),
    ]
}

/// Compares every leaf with brute force over all triangles; returns
/// (leaves compared, ambiguous ray tests).
fn check_brute_force(leaves: &[Octant], index: &SurfaceIndex, bits: &[u8]) -> (usize, usize) {
    let tris = index.triangles();
    let mut skipped = 0;
    for (l, &b) in leaves.iter().zip(bits) {
        let (lo, hi) = l.bounds_f64();
        let cut = tris.iter().any(|t| triangle_box_overlap(t, lo, hi));
        assert_eq!(b & CUT != 0, cut, "CUT of {l:?}");
        match ray_inside(center_f64(*l), tris) {
            Some(inside) => assert_eq!(b & CENTER_INSIDE != 0, inside, "centre of {l:?}"),
            None => skipped += 1,
        }
    }
    (leaves.len(), skipped)
}

fn brute_force_surface(surface: &Surface, level: u8) {
    let (_, index) = fitted(surface);
    let leaves = leaves_of(&index, level, true);
    let bits = classify_leaves(&leaves, &index);
    let (n, skipped) = check_brute_force(&leaves, &index, &bits);
    assert!(skipped * 1000 <= n, "{skipped} ambiguous of {n}");
    for class in [LeafClass::Outside, LeafClass::Inside, LeafClass::Cut] {
        let count = bits
            .iter()
            .filter(|&&b| LeafClass::from_bits(b) == class)
            .count();
        assert!(
            count > n / 20,
            "only {count} {} leaves of {n}",
            class.name()
        );
    }
    // Cut leaves have their centres on both sides.
    let cut_in = bits.iter().filter(|&&b| b == CUT | CENTER_INSIDE).count();
    let cut_out = bits.iter().filter(|&&b| b == CUT).count();
    assert!(cut_in > 0 && cut_out > 0, "{cut_in} / {cut_out}");
}

#[test]
fn classify_sphere_matches_brute_force() {
    brute_force_surface(&default_sphere(), 5);
}

#[test]
fn classify_torus_matches_brute_force() {
    brute_force_surface(&default_torus(), 5);
}

/// Random octants at every level, near and on the surface, classified
/// together and some of them alone (so through their own chain of
/// ancestors only).
fn random_octants(surface: &Surface, seed: u64, count: usize) {
    let (_, index) = fitted(surface);
    let tris = index.triangles();
    let mut rng = Rng(seed);
    let mut octants = Vec::new();
    for k in 0..count {
        let t = &tris[(rng.next() % tris.len() as u64) as usize];
        let (mut u, mut v) = (rng.unit(), rng.unit());
        if u + v > 1.0 {
            (u, v) = (1.0 - u, 1.0 - v);
        }
        let level = (1 + rng.next() % MAX_LEVEL as u64) as u8;
        let side = (ROOT_LEN >> level) as f64;
        let jitter = if k % 2 == 0 { 0.0 } else { 2.0 * side };
        let p: [f64; 3] = std::array::from_fn(|i| {
            let q = t.v[0][i] + u * (t.v[1][i] - t.v[0][i]) + v * (t.v[2][i] - t.v[0][i]);
            q + jitter * (rng.unit() - 0.5)
        });
        let c: [u32; 3] = std::array::from_fn(|i| {
            let x = p[i].clamp(0.0, ROOT_LEN as f64 - 1.0) as u32;
            x & !((ROOT_LEN >> level) - 1)
        });
        octants.push(Octant::new(c[0], c[1], c[2], level).unwrap());
    }
    // One call per level: octants of one level are disjoint once sorted
    // and deduplicated.
    let (mut n, mut skipped, mut cut) = (0, 0, 0);
    for level in 1..=MAX_LEVEL {
        let mut run: Vec<Octant> = octants
            .iter()
            .copied()
            .filter(|o| o.level() == level)
            .collect();
        run.sort_unstable();
        run.dedup();
        let bits = classify_leaves(&run, &index);
        for (k, (&o, &b)) in run.iter().zip(&bits).enumerate() {
            assert_eq!(b & CUT != 0, index.touches(o), "CUT of {o:?}");
            cut += (b & CUT != 0) as usize;
            match ray_inside(center_f64(o), tris) {
                Some(inside) => {
                    assert_eq!(b & CENTER_INSIDE != 0, inside, "centre of {o:?}")
                }
                None => skipped += 1,
            }
            if k % 25 == 0 {
                assert_eq!(classify_leaves(&[o], &index), [b], "{o:?} alone");
            }
        }
        n += run.len();
    }
    assert!(n > count / 2, "{n} of {count}");
    assert!(skipped * 100 <= n, "{skipped} ambiguous of {n}");
    assert!(cut > n / 4 && cut < n, "{cut} cut of {n}");
}

#[test]
fn classify_random_octants_sphere() {
    random_octants(&default_sphere(), 0x5eed_0001, 3000);
}

#[test]
fn classify_random_octants_torus() {
    random_octants(&default_torus(), 0x5eed_0002, 3000);
}

/// Volume of the kept leaves, in finest cells.
fn kept_cells(leaves: &[Octant], bits: &[u8], keep: Keep, rule: CutRule) -> u64 {
    leaves
        .iter()
        .zip(bits)
        .filter(|(_, &b)| keeps(keep, rule, b))
        .map(|(l, _)| l.cell_end() - l.cell_begin())
        .sum()
}

fn volume_converges(surface: &Surface) {
    let (d, index) = fitted(surface);
    // The enclosed volume in finest cells (the lattice has 2^19 points
    // per side and 8^19 cells).
    let cell = d.side / ROOT_LEN as f64;
    let exact = surface.signed_volume().abs() / (cell * cell * cell);
    let mut last_err = f64::INFINITY;
    let mut last_band = u64::MAX;
    for level in 4..=7 {
        let leaves = leaves_of(&index, level, false);
        let bits = classify_leaves(&leaves, &index);
        let inside = kept_cells(&leaves, &bits, Keep::Inside, CutRule::Center);
        let outside = kept_cells(&leaves, &bits, Keep::Outside, CutRule::Center);
        assert_eq!(inside + outside, CELLS, "level {level}");
        assert_eq!(kept_cells(&leaves, &bits, Keep::All, CutRule::None), CELLS);
        for &b in &bits {
            assert!(
                keeps(Keep::Inside, CutRule::Center, b) != keeps(Keep::Outside, CutRule::Center, b)
            );
        }
        // Off the surface the classification is exact, so the solid lies
        // between the inside leaves without the cut ones and with them.
        let inner = kept_cells(&leaves, &bits, Keep::Inside, CutRule::None);
        let outer = kept_cells(&leaves, &bits, Keep::Inside, CutRule::All);
        assert!(
            (inner as f64) < exact && exact < outer as f64,
            "level {level}"
        );
        assert!(outer - inner < last_band, "level {level}");
        last_band = outer - inner;
        let err = (inside as f64 - exact).abs() / exact;
        assert!(
            err < last_err.max(2e-3),
            "level {level}: {err} after {last_err}"
        );
        last_err = err;
    }
    assert!(last_err < 0.01, "{last_err}");
}

#[test]
fn classify_sphere_volume_converges() {
    volume_converges(&default_sphere());
}

#[test]
fn classify_torus_volume_converges() {
    volume_converges(&default_torus());
}

/// The 12 triangles of the box `lo..hi`, outward (`flip`: inward).
fn box_surface(lo: [f64; 3], hi: [f64; 3], flip: bool) -> Surface {
    let p = |i: usize| {
        [
            if i & 1 != 0 { hi[0] } else { lo[0] },
            if i & 2 != 0 { hi[1] } else { lo[1] },
            if i & 4 != 0 { hi[2] } else { lo[2] },
        ]
    };
    // Faces as corner quads, counter-clockwise seen from outside.
    let quads = [
        [0, 4, 6, 2], // -x
        [1, 3, 7, 5], // +x
        [0, 1, 5, 4], // -y
        [2, 6, 7, 3], // +y
        [0, 2, 3, 1], // -z
        [4, 5, 7, 6], // +z
    ];
    let mut tris = Vec::new();
    for q in quads {
        for t in [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] {
            let t = if flip { [t[0], t[2], t[1]] } else { t };
            tris.push(Triangle::new(p(t[0]), p(t[1]), p(t[2])));
        }
    }
    Surface::new(tris).unwrap()
}

#[test]
fn classify_lattice_aligned_boxes() {
    // Lattice units are user units; box faces on level-5 boundaries.
    let d = Domain::cube([0.0; 3], ROOT_LEN as f64).unwrap();
    let u = (ROOT_LEN >> 5) as i64;
    let mid = (ROOT_LEN / 2) as i64;
    let boxes: [([i64; 3], [i64; 3]); 4] = [
        // The root's centre on a corner, an edge, a face, and inside.
        ([mid, mid, mid], [mid + 3 * u, mid + 5 * u, mid + 2 * u]),
        (
            [mid - 2 * u, mid, mid],
            [mid + 3 * u, mid + 4 * u, mid + 2 * u],
        ),
        (
            [mid - 3 * u, mid - 2 * u, mid],
            [mid + 4 * u, mid + u, mid + 6 * u],
        ),
        (
            [mid - 5 * u, mid - 3 * u, mid - 4 * u],
            [mid + 2 * u, mid + 6 * u, mid + u],
        ),
    ];
    for (bi, (lo, hi)) in boxes.into_iter().enumerate() {
        for flip in [false, true] {
            let f = |p: [i64; 3]| p.map(|c| c as f64);
            let s = box_surface(f(lo), f(hi), flip);
            let index = SurfaceIndex::new(&s, &d);
            for level in [5u8, 7] {
                let leaves = leaves_of(&index, level, level == 7);
                let bits = classify_leaves(&leaves, &index);
                let h = (ROOT_LEN >> level) as i64;
                let vol = |grow: i64| -> u64 {
                    // In finest cells, which are lattice units cubed.
                    (0..3)
                        .map(|k| (hi[k] - lo[k] + 2 * grow) as u64)
                        .product::<u64>()
                };
                let what = format!("box {bi} flip {flip} level {level}");
                assert_eq!(
                    kept_cells(&leaves, &bits, Keep::Inside, CutRule::Center),
                    vol(0),
                    "{what}"
                );
                assert_eq!(
                    kept_cells(&leaves, &bits, Keep::Inside, CutRule::None),
                    vol(-h),
                    "{what}"
                );
                assert_eq!(
                    kept_cells(&leaves, &bits, Keep::Inside, CutRule::All),
                    vol(h),
                    "{what}"
                );
                assert_eq!(
                    kept_cells(&leaves, &bits, Keep::Outside, CutRule::Center),
                    CELLS - vol(0),
                    "{what}"
                );
                // A slice is classified as in the whole run.
                let (a, b) = (leaves.len() / 3, 2 * leaves.len() / 3 + 1);
                assert_eq!(classify_leaves(&leaves[a..b], &index), bits[a..b], "{what}");
                let (_, bf_skipped) = check_brute_force(&leaves, &index, &bits);
                // Centres on faces are ambiguous for the float ray test.
                assert!(bf_skipped < leaves.len() / 4, "{what}: {bf_skipped}");
            }
        }
    }
}

#[test]
fn classify_slices_match_whole_run() {
    for s in [default_sphere(), default_torus()] {
        let (_, index) = fitted(&s);
        let leaves = leaves_of(&index, 6, true);
        let whole = classify_leaves(&leaves, &index);
        let n = leaves.len();
        let cuts = [0, n / 7, n / 2 + 3, n];
        let mut joined = Vec::new();
        for w in cuts.windows(2) {
            joined.extend(classify_leaves(&leaves[w[0]..w[1]], &index));
        }
        assert_eq!(joined, whole);
        // Every other leaf (a run with gaps) too.
        let sparse: Vec<Octant> = leaves.iter().copied().step_by(2).collect();
        let expect: Vec<u8> = whole.iter().copied().step_by(2).collect();
        assert_eq!(classify_leaves(&sparse, &index), expect);
        assert!(classify_leaves(&[], &index).is_empty());
    }
}

#[test]
fn classify_ignores_orientation() {
    let s = default_torus();
    let flipped = Surface::new(
        s.triangles()
            .iter()
            .map(|t| Triangle::new(t.v[0], t.v[2], t.v[1]))
            .collect(),
    )
    .unwrap();
    let (_, index) = fitted(&s);
    let (_, index_flipped) = fitted(&flipped);
    let leaves = leaves_of(&index, 6, false);
    assert_eq!(
        classify_leaves(&leaves, &index),
        classify_leaves(&leaves, &index_flipped)
    );
}

/// Segments through shared vertices and edges of a closed octahedron,
/// exactly: each leaves the solid, so it must cross an odd number of
/// triangles; segments inside or outside cross an even number.
#[test]
fn classify_crossings_through_vertices_and_edges() {
    let r = 1000i64;
    let v = [
        [r, 0, 0],
        [-r, 0, 0],
        [0, r, 0],
        [0, -r, 0],
        [0, 0, r],
        [0, 0, -r],
    ];
    let mut tris = Vec::new();
    for (x, y, z) in [
        (0, 2, 4),
        (2, 1, 4),
        (1, 3, 4),
        (3, 0, 4),
        (2, 0, 5),
        (1, 2, 5),
        (3, 1, 5),
        (0, 3, 5),
    ] {
        let t = [v[x], v[y], v[z]];
        let n = normal(&t);
        let nsign = n.iter().find(|&&c| c != 0).map_or(0, |&c| c.signum() as i8);
        tris.push(FixedTri { v: t, nsign });
    }
    let count = |p: [i64; 3], q: [i64; 3]| tris.iter().filter(|t| crosses(p, q, t)).count();
    let origin = [0, 0, 0];
    // Through every vertex, every edge midpoint, every face centre.
    let mut targets: Vec<[i64; 3]> = v.to_vec();
    for a in 0..6 {
        for b in 0..6 {
            if a / 2 != b / 2 {
                targets.push(std::array::from_fn(|k| (v[a][k] + v[b][k]) / 2));
            }
        }
    }
    for sx in [-1, 1] {
        for sy in [-1, 1] {
            for sz in [-1, 1] {
                targets.push([sx * r / 3, sy * r / 3, sz * r / 3]);
            }
        }
    }
    for t in &targets {
        let far = t.map(|c| 3 * c);
        assert_eq!(count(origin, far) % 2, 1, "origin to {far:?}");
        assert_eq!(count(far, origin) % 2, 1, "{far:?} to origin");
        // Ending exactly on the surface: the perturbation puts the end
        // on one side, consistently for both directions.
        let a = count(origin, *t) % 2;
        let b = count(*t, far) % 2;
        assert_eq!((a + b) % 2, 1, "split at {t:?}");
        // Outside to outside along the surface's own plane or edge.
        let beyond = t.map(|c| 2 * c);
        assert_eq!(count(beyond, far) % 2, 0, "{beyond:?} to {far:?}");
    }
    // Along an edge line from vertex to vertex, outside the solid.
    assert_eq!(count([2 * r, -r, 0], [-r, 2 * r, 0]) % 2, 0);
    // And from the centre of each child octant to the origin, which the
    // top-down walk does with the batched test.
    for i in 0..8u32 {
        let s = [
            if i & 1 != 0 { 1 } else { -1 },
            if i & 2 != 0 { 1 } else { -1 },
            if i & 4 != 0 { 1 } else { -1 },
        ];
        for h in [r / 3, r / 2, r, 2 * r] {
            let q = s.map(|c| c * h);
            let direct = tris.iter().filter(|t| crosses(origin, q, t)).count() % 2;
            let batched = tris
                .iter()
                .filter(|t| crossings_from_center(origin, h, t, 1 << i).0 != 0)
                .count()
                % 2;
            assert_eq!(direct, batched, "child {i} at {h}");
            // (r/3)(1,1,1) is on a face: inside for this perturbation or
            // not, but 2r(1,1,1) is outside.
            if h == 2 * r {
                assert_eq!(direct, 1);
            }
            if h == r / 2 || h == r {
                // (r/2)(1,1,1) and r(1,1,1) are outside (|x|+|y|+|z| > r).
                assert_eq!(direct, 1, "child {i} at {h}");
            }
        }
    }
}

/// The batched per-child box test against `triangle_box_overlap` on
/// each child, for triangles that touch or nearly touch a child box at
/// a corner, an edge or a face with non-dyadic coordinates, where the
/// floating-point verdicts are closest to a tie.
#[test]
fn classify_batched_box_test_agrees() {
    let mut rng = Rng(0xb0c5_7e57);
    let d = Domain::cube([0.0; 3], ROOT_LEN as f64).unwrap();
    let (mut sure, mut unsure, mut touching, mut crossing) = (0usize, 0usize, 0usize, 0usize);
    let mut wide_cases = 0;
    for case in 0..4000 {
        let level = (1 + rng.next() % (MAX_LEVEL as u64 - 1)) as u8;
        let side = ROOT_LEN >> level;
        let cells = (ROOT_LEN / side) as u64;
        let c: [u32; 3] = std::array::from_fn(|_| (rng.next() % cells) as u32 * side);
        let o = Octant::new(c[0], c[1], c[2], level).unwrap();
        let half = (side / 2) as f64;
        let center = c.map(|x| x as f64 + half);
        let scale = [0.01 * half, half, 3.0 * half, 65536.0][case % 4];
        let mut v;
        if case % 5 == 4 {
            // A triangle around a point of a segment from the centre to a
            // child's centre (the parity test's segments).
            let i = rng.next() % 8;
            let tau = [0.0, 1.0, rng.unit()][(rng.next() % 3) as usize];
            let p: [f64; 3] = std::array::from_fn(|k| {
                let s = if i >> k & 1 != 0 { 0.5 } else { -0.5 };
                center[k] + tau * s * half + 1e-7 * half * (rng.unit() - 0.5)
            });
            let a: [f64; 3] = std::array::from_fn(|_| scale * (rng.unit() - 0.5));
            let b: [f64; 3] = std::array::from_fn(|_| scale * (rng.unit() - 0.5));
            v = [
                std::array::from_fn(|k| p[k] + a[k]),
                std::array::from_fn(|k| p[k] + b[k]),
                std::array::from_fn(|k| p[k] - a[k] - b[k]),
            ];
        } else {
            // A point on a child's boundary: a corner, an edge or a face.
            let mut p: [f64; 3] =
                std::array::from_fn(|k| c[k] as f64 + half * (rng.next() % 3) as f64);
            for x in p.iter_mut().take(case % 3) {
                *x += half * rng.unit();
            }
            // Two more vertices, nearly all on one side of that point.
            let dir: [f64; 3] = std::array::from_fn(|_| rng.unit() - 0.5);
            v = [p; 3];
            for vi in v.iter_mut().skip(1) {
                for k in 0..3 {
                    let away = if dir[k] > 0.0 { 1.0 } else { -1.0 };
                    vi[k] = p[k] + scale * (away * rng.unit() + 0.3 * (rng.unit() - 0.5)) / 3.0;
                }
            }
        }
        let tri = Triangle::new(v[0], v[1], v[2]);
        let s = match Surface::new(vec![tri]) {
            Ok(s) => s,
            Err(_) => continue,
        };
        let index = SurfaceIndex::new(&s, &d);
        let cl = Classifier::new(&index, false);
        let t = &cl.tris[0];
        let m = cl.child_masks(0, center, half, 0xff, 0xff);
        if cl.wide {
            // The AVX-512 lanes give the scalar code's verdicts, for any
            // children wanted.
            let mut scalar = Classifier::new(&index, false);
            scalar.wide = false;
            for (want, leafy) in [(0xff, 0xff), (rng.next() as u8, rng.next() as u8)] {
                assert_eq!(
                    cl.child_masks(0, center, half, want, leafy),
                    scalar.child_masks(0, center, half, want, leafy),
                    "case {case}, want {want:#x}, leafy {leafy:#x}"
                );
            }
            wide_cases += 1;
        }
        let pc = cl.center(o);
        let h = cl.to_fixed((side / 4) as u64);
        for i in 0..8u32 {
            let (lo, hi) = o.child(i).bounds_f64();
            let exact = triangle_box_overlap(t, lo, hi);
            let bit = 1u8 << i;
            if m.unsure & bit != 0 {
                unsure += 1;
            } else {
                sure += 1;
                assert_eq!(m.touch & bit != 0, exact, "case {case} child {i}");
            }
            touching += exact as usize;
            if exact {
                assert!(m.near & bit != 0, "case {case} child {i}");
            }
            // A crossing needs the triangle near the child and its plane
            // between the two centres.
            let ft = &cl.fixed[0];
            if ft.nsign != 0 && cl.crossings(o, pc, h, ft, bit).0 != 0 {
                crossing += 1;
                assert!(m.near & m.plane & bit != 0, "case {case} child {i}");
            }
        }
    }
    assert!(
        touching > 2000 && sure > 5 * unsure && unsure > 100 && crossing > 300,
        "{touching} {sure} {unsure} {crossing}"
    );
    if crate::parallel::cores::avx512() {
        assert!(wide_cases > 3000, "{wide_cases}");
    } else {
        println!("no AVX-512F here: the child masks' lanes were not compared");
    }
}

/// The whole classification with and without the AVX-512 lanes: the same
/// bytes, on a closed surface (parity) and an open one (winding, caps).
#[test]
fn classify_wide_lanes_give_the_same_bytes() {
    if !crate::parallel::cores::avx512() {
        println!("no AVX-512F here: nothing to compare");
        return;
    }
    for (surface, rule) in [
        (default_torus(), InsideRule::Parity),
        (holed_sphere(0.8), InsideRule::Winding),
    ] {
        let (_, index) = fitted(&surface);
        let leaves = leaves_of(&index, 7, true);
        let mut c = InsideClassifier::new(&index, rule);
        assert!(c.c.wide);
        let wide = c.classify(&leaves);
        c.c.wide = false;
        let scalar = c.classify(&leaves);
        assert_eq!(wide, scalar, "{rule:?}");
        assert!(wide.iter().any(|&b| b & CUT != 0) && wide.contains(&CENTER_INSIDE));
    }
}

#[test]
fn round_half_away_matches_round() {
    let mut x = 0x2545_f491_4f6c_dd1du64;
    let mut values = vec![
        0.0,
        -0.0,
        0.5,
        -0.5,
        1.5,
        -2.5,
        0.499_999_999_999_999_94,
        -0.499_999_999_999_999_94,
        4_503_599_627_370_495.5,
        -4_503_599_627_370_495.5,
        (1u64 << 39) as f64 + 0.5,
    ];
    for _ in 0..10_000 {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        let v = (x >> 11) as f64 / (1u64 << 53) as f64;
        values.push((v - 0.5) * (1u64 << 41) as f64);
        values.push((v - 0.5) * 8.0);
    }
    for v in values {
        assert_eq!(round_half_away(v), v.round() as i64, "{v}");
    }
}

#[test]
fn classify_names_and_rules() {
    assert_eq!(Keep::parse("inside").unwrap(), Keep::Inside);
    assert_eq!(Keep::parse("outside").unwrap().name(), "outside");
    assert_eq!(Keep::parse("all").unwrap(), Keep::All);
    assert!(Keep::parse("in").is_err());
    assert_eq!(CutRule::parse("none").unwrap(), CutRule::None);
    assert_eq!(CutRule::parse("all").unwrap().name(), "all");
    assert_eq!(CutRule::default(), CutRule::Center);
    assert!(CutRule::parse("centre").is_err());
    assert_eq!(LeafClass::from_bits(0), LeafClass::Outside);
    assert_eq!(LeafClass::from_bits(CENTER_INSIDE), LeafClass::Inside);
    assert_eq!(LeafClass::from_bits(CUT).name(), "cut");
    assert_eq!(LeafClass::from_bits(CUT | CENTER_INSIDE), LeafClass::Cut);
    for bits in 0..4u8 {
        let inside = bits & CENTER_INSIDE != 0;
        let cut = bits & CUT != 0;
        assert!(keeps(Keep::All, CutRule::None, bits));
        assert_eq!(keeps(Keep::Inside, CutRule::Center, bits), inside);
        assert_eq!(keeps(Keep::Outside, CutRule::Center, bits), !inside);
        assert_eq!(keeps(Keep::Inside, CutRule::None, bits), inside && !cut);
        assert_eq!(keeps(Keep::Outside, CutRule::None, bits), !inside && !cut);
        assert_eq!(keeps(Keep::Inside, CutRule::All, bits), inside || cut);
        assert_eq!(keeps(Keep::Outside, CutRule::All, bits), !inside || cut);
    }
}

/// The surface with the facets `which` reversed.
fn reversed_where(s: &Surface, which: impl Fn(usize) -> bool) -> Surface {
    let t = s
        .triangles()
        .iter()
        .enumerate()
        .map(|(i, t)| {
            if which(i) {
                Triangle::new(t.v[0], t.v[2], t.v[1])
            } else {
                *t
            }
        })
        .collect();
    Surface::new(t).unwrap()
}

/// A coarse unit sphere (1280 facets) without the facets whose centroid
/// is above `z`: one hole around the pole.
fn holed_sphere(z: f64) -> Surface {
    let s = sphere([0.0; 3], 1.0, 3);
    Surface::new(
        s.triangles()
            .iter()
            .filter(|t| t.centroid()[2] < z)
            .copied()
            .collect(),
    )
    .unwrap()
}

#[test]
fn inside_rule_names_and_auto_choice() {
    assert_eq!(InsideRule::parse("parity").unwrap(), InsideRule::Parity);
    assert_eq!(InsideRule::parse("winding").unwrap().name(), "winding");
    assert_eq!(InsideRule::parse("auto").unwrap(), InsideRule::default());
    assert!(InsideRule::parse("wind").is_err());
    let report = |s: &Surface| diagnose(s);
    let (r, why) = InsideRule::auto_choice(&report(&default_torus()));
    assert_eq!(r, InsideRule::Parity, "{why}");
    let (r, why) = InsideRule::auto_choice(&report(&holed_sphere(0.8)));
    assert_eq!(r, InsideRule::Winding);
    assert!(why.contains("boundary edges"), "{why}");
    let s = default_sphere();
    let (r, why) = InsideRule::auto_choice(&report(&reversed_where(&s, |i| i == 3)));
    assert_eq!(r, InsideRule::Winding);
    assert!(why.contains("3 inconsistently oriented edges"), "{why}");
    let mut two = s.triangles().to_vec();
    two.extend(sphere([3.0, 0.0, 0.0], 1.0, 2).triangles());
    let (r, why) = InsideRule::auto_choice(&report(&Surface::new(two).unwrap()));
    assert_eq!((r, why.as_str()), (InsideRule::Winding, "2 components"));
    assert_eq!(
        InsideRule::Parity.resolve(|| unreachable!()),
        InsideRule::Parity
    );
    assert_eq!(InsideRule::Auto.resolve(|| report(&s)), InsideRule::Parity);
}

#[test]
fn winding_equals_parity_on_one_closed_surface() {
    // One closed, outward surface: the winding number is 0 or 1, the
    // parity of the crossings.
    for s in [default_sphere(), default_torus()] {
        let (_, index) = fitted(&s);
        let leaves = leaves_of(&index, 6, true);
        let parity = classify_leaves(&leaves, &index);
        let w = InsideClassifier::new(&index, InsideRule::Winding);
        assert_eq!(w.rule(), InsideRule::Winding);
        let sum = w.summary().unwrap();
        assert_eq!(
            (sum.components, sum.reversed_facets, sum.cap_triangles),
            (1, 0, 0)
        );
        assert_eq!(w.classify(&leaves), parity);
        let auto = InsideClassifier::new(&index, InsideRule::Auto);
        assert_eq!(auto.rule(), InsideRule::Parity);
        assert!(auto.summary().is_none());
    }
}

#[test]
fn winding_ignores_reversed_facets() {
    // Half the facets at random, or all of them, reversed: classified
    // like the clean sphere, leaf by leaf.
    let s = default_sphere();
    let mut rng = Rng(77);
    let coin: Vec<bool> = (0..s.len()).map(|_| rng.next().is_multiple_of(2)).collect();
    let (_, clean) = fitted(&s);
    let leaves = leaves_of(&clean, 6, true);
    let expect = classify_leaves(&leaves, &clean);
    for (name, messy) in [
        ("half", reversed_where(&s, |i| coin[i])),
        ("all", reversed_where(&s, |_| true)),
    ] {
        let (_, index) = fitted(&messy);
        // Auto: an inward but consistent sphere is closed, for parity.
        let auto = InsideClassifier::new(&index, InsideRule::Auto).rule();
        let want = if name == "all" {
            InsideRule::Parity
        } else {
            InsideRule::Winding
        };
        assert_eq!(auto, want, "{name}");
        let c = InsideClassifier::new(&index, InsideRule::Winding);
        let reversed = c.summary().unwrap().reversed_facets;
        let want = if name == "all" {
            s.len()
        } else {
            coin.iter().filter(|&&b| b).count()
        };
        assert_eq!(reversed, want, "{name}");
        assert_eq!(c.classify(&leaves), expect, "{name}");
    }
}

/// Every leaf's centre bit against the winding number summed directly
/// over the (outward) surface; returns the number of leaves whose
/// winding number is away from 0 and 1 (where holes matter). Centres are
/// moved by `(1e-3, 1e-6, 1e-9)` lattice units, which is what the
/// classification's infinitesimal perturbation does to centres on the
/// surface.
fn check_against_direct_winding(index: &SurfaceIndex, leaves: &[Octant], bits: &[u8]) -> usize {
    let tris = index.triangles();
    let parity = classify_leaves(leaves, index);
    let (mut mid, mut ties) = (0, 0);
    for (i, (&l, &b)) in leaves.iter().zip(bits).enumerate() {
        assert_eq!(b & CUT, parity[i] & CUT, "{l:?}: cut differs");
        let c = center_f64(l);
        let w = winding_number(tris, [c[0] + 1e-3, c[1] + 1e-6, c[2] + 1e-9]);
        if (w - 0.5).abs() < 1e-6 {
            ties += 1;
            continue;
        }
        assert_eq!(b & CENTER_INSIDE != 0, w > 0.5, "{l:?}: w = {w}");
        mid += (0.02..0.98).contains(&w) as usize;
    }
    assert!(ties * 100 < leaves.len(), "{ties} ties");
    mid
}

#[test]
fn winding_on_open_surfaces_matches_direct_summation() {
    for (name, s) in [
        ("small hole", holed_sphere(0.9)),
        ("large hole", holed_sphere(0.3)),
        ("bowl", holed_sphere(-0.2)),
    ] {
        let (_, index) = fitted(&s);
        let leaves = leaves_of(&index, 6, true);
        let c = InsideClassifier::new(&index, InsideRule::Auto);
        assert_eq!(c.rule(), InsideRule::Winding);
        let sum = c.summary().unwrap();
        assert_eq!(sum.boundary_loops, 1, "{name}");
        let bits = c.classify(&leaves);
        let mid = check_against_direct_winding(&index, &leaves, &bits);
        assert!(mid > 100, "{name}: {mid}");
        // Parity is wrong somewhere near the hole.
        let parity = classify_leaves(&leaves, &index);
        assert_ne!(parity, bits, "{name}");
    }
}

#[test]
fn winding_on_an_open_lattice_aligned_box() {
    // A box on level-5 planes without its top face: centres of coarser
    // leaves lie in the plane of the opening (ties, w = 1/2) and the cap
    // is a fan in that plane.
    let d = Domain::cube([0.0; 3], ROOT_LEN as f64).unwrap();
    let u = (ROOT_LEN >> 5) as f64;
    let m = (ROOT_LEN / 2) as f64;
    let b = box_surface(
        [m - 5.0 * u, m - 3.0 * u, m - 4.0 * u],
        [m + 2.0 * u, m + 6.0 * u, m + 6.0 * u],
        false,
    );
    // Faces are facets 2k, 2k + 1 of -x, +x, -y, +y, -z, +z: drop +z.
    let open = Surface::new(b.triangles()[..10].to_vec()).unwrap();
    let index = SurfaceIndex::new(&open, &d);
    let c = InsideClassifier::new(&index, InsideRule::Winding);
    assert_eq!(c.summary().unwrap().cap_triangles, 4);
    for level in [4u8, 6] {
        let leaves = leaves_of(&index, level, true);
        let bits = c.classify(&leaves);
        check_against_direct_winding(&index, &leaves, &bits);
    }
}

#[test]
fn winding_gives_the_union_of_overlapping_parts() {
    // Two unit spheres with centres 1 apart, as one soup: the winding
    // number is 2 where they overlap, which parity calls outside.
    let a = sphere([0.0; 3], 1.0, 3);
    let b = sphere([1.0, 0.0, 0.0], 1.0, 3);
    let mut t = a.triangles().to_vec();
    t.extend(b.triangles());
    let s = Surface::new(t).unwrap();
    let (d, index) = fitted(&s);
    let leaves = leaves_of(&index, 6, false);
    let c = InsideClassifier::new(&index, InsideRule::Auto);
    assert_eq!(c.rule(), InsideRule::Winding);
    let wb = c.classify(&leaves);
    let pb = classify_leaves(&leaves, &index);
    let (mut both, mut one) = (0, 0);
    for (i, &l) in leaves.iter().enumerate() {
        if wb[i] & CUT != 0 {
            assert_eq!(pb[i] & CUT, CUT, "{l:?}");
            continue;
        }
        // Uncut centres are at least half a leaf from the facets, far
        // more than the facets are from the spheres.
        let p = d.from_lattice(center_f64(l));
        let ina = norm(p) < 1.0;
        let inb = norm([p[0] - 1.0, p[1], p[2]]) < 1.0;
        assert_eq!(wb[i] & CENTER_INSIDE != 0, ina || inb, "{l:?}");
        assert_eq!(pb[i] & CENTER_INSIDE != 0, ina != inb, "{l:?}");
        both += (ina && inb) as usize;
        one += (ina != inb) as usize;
    }
    assert!(both > 50 && one > 50, "{both} {one}");
}

#[test]
fn winding_slices_match_whole_run() {
    let s = holed_sphere(0.5);
    let (_, index) = fitted(&s);
    let leaves = leaves_of(&index, 7, true);
    let c = InsideClassifier::new(&index, InsideRule::Winding);
    let whole = c.classify(&leaves);
    let n = leaves.len();
    for parts in [2, 3, 7] {
        let mut joined = Vec::new();
        for k in 0..parts {
            joined.extend(c.classify(&leaves[k * n / parts..(k + 1) * n / parts]));
        }
        assert_eq!(joined, whole, "{parts} parts");
    }
    let sparse: Vec<Octant> = leaves.iter().copied().step_by(3).collect();
    let expect: Vec<u8> = whole.iter().copied().step_by(3).collect();
    assert_eq!(c.classify(&sparse), expect);
    // Alone, through its own chain of ancestors.
    for k in (0..n).step_by(97) {
        assert_eq!(c.classify(&leaves[k..k + 1]), [whole[k]], "{:?}", leaves[k]);
    }
}

#[test]
fn winding_on_an_unwelded_soup() {
    // A sphere whose facets share no vertex (each corner moved by up to
    // 1e-6): every facet is a component with its own boundary, capped
    // by a fan of three, and keeps its (outward) orientation. The
    // cracks are far below the leaves, so the classes are parity's.
    let s = sphere([0.0; 3], 1.0, 3);
    let mut k = 0u64;
    let soup: Vec<Triangle> = s
        .triangles()
        .iter()
        .map(|t| Triangle {
            v: t.v.map(|p| {
                p.map(|c| {
                    k += 1;
                    c + 1e-9 * ((k * 2_654_435_761) % 1000) as f64
                })
            }),
        })
        .collect();
    let soup = Surface::new(soup).unwrap();
    let (_, index) = fitted(&soup);
    let leaves = leaves_of(&index, 6, true);
    let c = InsideClassifier::new(&index, InsideRule::Auto);
    assert_eq!(c.rule(), InsideRule::Winding);
    let sum = c.summary().unwrap();
    assert_eq!((sum.components, sum.reversed_facets), (s.len(), 0));
    assert_eq!(sum.cap_triangles, 3 * s.len());
    assert_eq!(c.classify(&leaves), classify_leaves(&leaves, &index));
}

/// Two threads (each half of the leaves walked from the root) give the
/// same bytes as one, under both rules, on a surface with holes (caps for
/// the winding rule) and a closed one.
#[test]
fn classify_on_two_threads_is_the_same() {
    for (surface, rule) in [
        (default_torus(), InsideRule::Parity),
        (default_torus(), InsideRule::Winding),
        (holed_sphere(0.8), InsideRule::Winding),
    ] {
        let (_, index) = fitted(&surface);
        let leaves = leaves_of(&index, 8, true);
        assert!(
            leaves.len() >= SPARE_MIN_LEAVES,
            "{} leaves: one thread",
            leaves.len()
        );
        let c = InsideClassifier::new(&index, rule);
        let one = c.classify(&leaves);
        assert_eq!(c.classify_spare(&leaves, true), one, "{rule:?}");
        assert!(one.iter().any(|&b| b & CUT != 0) && one.iter().any(|&b| b & CENTER_INSIDE != 0));
        // An odd length, and runs too short to split.
        assert_eq!(c.classify_spare(&leaves[1..], true), one[1..]);
        assert_eq!(c.classify_spare(&leaves[..1], true), one[..1]);
        assert!(c.classify_spare(&[], true).is_empty());
    }
}
