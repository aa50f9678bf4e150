//! A conformity checker for hexahedral meshes read from a Gmsh MSH 4.1
//! ASCII file, written without the library's structures: it sees only
//! the file's points, hexahedra and boundary quadrilaterals.
//!
//! A mesh is conforming when
//! - no point lies inside an edge or a face of an element it is not a
//!   corner of (a hanging node does: it is a corner of the fine elements
//!   and lies on the coarse element's edge or face);
//! - every quadrilateral face is in exactly two elements, or in one and
//!   then listed as a boundary quadrilateral.
//!
//! Both sides of a 2:1 interface leave faces used once (the coarse face,
//! the four fine quarters), so counting faces alone would miss them only
//! if they were listed as boundary; the point test finds them anyway.
//! The volume is the sum of the hexahedra's (2-point Gauss quadrature of
//! the trilinear map's Jacobian, exact for trilinear hexahedra).

use std::collections::{HashMap, HashSet};
use std::path::Path;

/// What the checker found.
#[derive(Debug, Default)]
pub struct Conformity {
    /// Points (file tags) strictly inside an element edge.
    pub in_edges: HashSet<u64>,
    /// Points strictly inside an element face (off its edges).
    pub in_faces: HashSet<u64>,
    /// Faces in one element and not listed as boundary.
    pub unmatched_faces: usize,
    /// Faces in more than two elements.
    pub crowded_faces: usize,
    /// Boundary quadrilaterals that are no element's face used once.
    pub stray_boundary: usize,
    /// Faces in one element (listed or not).
    pub faces_used_once: usize,
    /// The hexahedra.
    pub elements: usize,
    /// The sum of the hexahedra's volumes.
    pub volume: f64,
    /// The smallest Jacobian determinant at the 8 corners over all
    /// hexahedra, scaled by the edge lengths (1 for a cube).
    pub min_scaled_jacobian: f64,
}

impl Conformity {
    /// Whether the mesh passed every check.
    pub fn conforming(&self) -> bool {
        self.in_edges.is_empty()
            && self.in_faces.is_empty()
            && self.unmatched_faces == 0
            && self.crowded_faces == 0
            && self.stray_boundary == 0
    }
}

/// The points, hexahedra (Gmsh type 5) and quadrilaterals (type 3) of an
/// MSH 4.1 ASCII file.
pub struct Msh {
    pub points: HashMap<u64, [f64; 3]>,
    pub hexes: Vec<[u64; 8]>,
    pub quads: Vec<[u64; 4]>,
}

/// Reads `path` (MSH 4.1 ASCII).
pub fn read_msh(path: &Path) -> Msh {
    let text = std::fs::read_to_string(path).unwrap();
    let mut msh = Msh {
        points: HashMap::new(),
        hexes: Vec::new(),
        quads: Vec::new(),
    };
    let section = |name: &str| -> Vec<&str> {
        let start = format!("${name}\n");
        let body = text
            .split(&start)
            .nth(1)
            .unwrap_or_else(|| panic!("no ${name}"));
        let end = format!("$End{name}");
        body.split(&end).next().unwrap().lines().collect()
    };
    let nums = |l: &str| -> Vec<f64> { l.split_whitespace().map(|x| x.parse().unwrap()).collect() };
    let nodes = section("Nodes");
    let blocks = nums(nodes[0])[0] as usize;
    let mut i = 1;
    for _ in 0..blocks {
        let n = nums(nodes[i])[3] as usize;
        let tags: Vec<u64> = (0..n).map(|k| nums(nodes[i + 1 + k])[0] as u64).collect();
        for (k, t) in tags.iter().enumerate() {
            let c = nums(nodes[i + 1 + n + k]);
            msh.points.insert(*t, [c[0], c[1], c[2]]);
        }
        i += 1 + 2 * n;
    }
    let elements = section("Elements");
    let blocks = nums(elements[0])[0] as usize;
    let mut i = 1;
    for _ in 0..blocks {
        let h = nums(elements[i]);
        let (kind, n) = (h[2] as u32, h[3] as usize);
        for k in 0..n {
            let v: Vec<u64> = elements[i + 1 + k]
                .split_whitespace()
                .map(|x| x.parse().unwrap())
                .collect();
            match kind {
                5 => msh.hexes.push(v[1..9].try_into().unwrap()),
                3 => msh.quads.push(v[1..5].try_into().unwrap()),
                _ => {}
            }
        }
        i += 1 + n;
    }
    msh
}

/// The faces of a hexahedron in Gmsh's (= VTK's) corner order.
const FACES: [[usize; 4]; 6] = [
    [0, 3, 2, 1],
    [4, 5, 6, 7],
    [0, 1, 5, 4],
    [1, 2, 6, 5],
    [2, 3, 7, 6],
    [3, 0, 4, 7],
];
const EDGES: [[usize; 2]; 12] = [
    [0, 1],
    [1, 2],
    [2, 3],
    [3, 0],
    [4, 5],
    [5, 6],
    [6, 7],
    [7, 4],
    [0, 4],
    [1, 5],
    [2, 6],
    [3, 7],
];

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

/// A uniform grid of the points, for the queries by box.
struct Grid {
    cell: f64,
    cells: HashMap<[i64; 3], Vec<u64>>,
}

impl Grid {
    fn new(points: &HashMap<u64, [f64; 3]>, cell: f64) -> Grid {
        let mut cells: HashMap<[i64; 3], Vec<u64>> = HashMap::new();
        for (&t, p) in points {
            cells
                .entry(p.map(|x| (x / cell).floor() as i64))
                .or_default()
                .push(t);
        }
        Grid { cell, cells }
    }

    /// The points in the box `lo..hi` (and some around it).
    fn near(&self, lo: [f64; 3], hi: [f64; 3], out: &mut Vec<u64>) {
        out.clear();
        let a = lo.map(|x| (x / self.cell).floor() as i64);
        let b = hi.map(|x| (x / self.cell).floor() as i64);
        for i in a[0]..=b[0] {
            for j in a[1]..=b[1] {
                for k in a[2]..=b[2] {
                    if let Some(v) = self.cells.get(&[i, j, k]) {
                        out.extend(v);
                    }
                }
            }
        }
    }
}

/// Whether `p` lies in triangle `a b c` within `tol` of its plane, with
/// barycentric coordinates at least `-eps`.
fn in_triangle(p: [f64; 3], a: [f64; 3], b: [f64; 3], c: [f64; 3], tol: f64) -> bool {
    let n = cross(sub(b, a), sub(c, a));
    let area2 = norm(n);
    if area2 == 0.0 || (dot(sub(p, a), n) / area2).abs() > tol {
        return false;
    }
    let eps = 1e-9;
    let w = |u: [f64; 3], v: [f64; 3]| dot(cross(sub(v, u), sub(p, u)), n) / (area2 * area2);
    w(b, c) >= -eps && w(c, a) >= -eps && w(a, b) >= -eps
}

/// The scaled Jacobian at the 8 corners of hexahedron `x` (VTK order):
/// the smallest over the corners of the triple product of the three
/// edges leaving the corner, divided by their lengths.
fn min_corner_jacobian(x: &[[f64; 3]; 8]) -> f64 {
    // The three neighbours of each corner, in right-handed order.
    const AROUND: [[usize; 3]; 8] = [
        [1, 3, 4],
        [2, 0, 5],
        [3, 1, 6],
        [0, 2, 7],
        [7, 5, 0],
        [4, 6, 1],
        [5, 7, 2],
        [6, 4, 3],
    ];
    let mut worst = f64::MAX;
    for (c, n) in AROUND.iter().enumerate() {
        let e = n.map(|k| sub(x[k], x[c]));
        let l = norm(e[0]) * norm(e[1]) * norm(e[2]);
        worst = worst.min(dot(cross(e[0], e[1]), e[2]) / l);
    }
    worst
}

/// The volume of the trilinear hexahedron `x` (VTK order).
fn volume(x: &[[f64; 3]; 8]) -> f64 {
    let g = 0.5 / 3f64.sqrt();
    let mut v = 0.0;
    for &r in &[0.5 - g, 0.5 + g] {
        for &s in &[0.5 - g, 0.5 + g] {
            for &t in &[0.5 - g, 0.5 + g] {
                // Derivatives of the map at (r, s, t) in [0,1]^3.
                let corner =
                    |i: usize, j: usize, k: usize| x[[0, 1, 3, 2, 4, 5, 7, 6][i + 2 * j + 4 * k]];
                let mut d = [[0.0f64; 3]; 3];
                for i in 0..2 {
                    for j in 0..2 {
                        for k in 0..2 {
                            let p = corner(i, j, k);
                            let (wr, ws, wt) = (
                                if i == 1 { r } else { 1.0 - r },
                                if j == 1 { s } else { 1.0 - s },
                                if k == 1 { t } else { 1.0 - t },
                            );
                            let sr = if i == 1 { 1.0 } else { -1.0 };
                            let ss = if j == 1 { 1.0 } else { -1.0 };
                            let st = if k == 1 { 1.0 } else { -1.0 };
                            for m in 0..3 {
                                d[0][m] += sr * ws * wt * p[m];
                                d[1][m] += wr * ss * wt * p[m];
                                d[2][m] += wr * ws * st * p[m];
                            }
                        }
                    }
                }
                v += dot(cross(d[0], d[1]), d[2]) / 8.0;
            }
        }
    }
    v
}

/// Checks the mesh of `path`.
pub fn check(path: &Path) -> Conformity {
    let msh = read_msh(path);
    let p = &msh.points;
    let mut out = Conformity {
        elements: msh.hexes.len(),
        min_scaled_jacobian: f64::MAX,
        ..Conformity::default()
    };
    let mut faces: HashMap<[u64; 4], (usize, [u64; 4])> = HashMap::new();
    let mut edges: HashSet<[u64; 2]> = HashSet::new();
    let mut shortest = f64::MAX;
    for h in &msh.hexes {
        let x = h.map(|t| p[&t]);
        out.volume += volume(&x);
        out.min_scaled_jacobian = out.min_scaled_jacobian.min(min_corner_jacobian(&x));
        for f in &FACES {
            let corners = f.map(|k| h[k]);
            let mut key = corners;
            key.sort_unstable();
            faces.entry(key).or_insert((0, corners)).0 += 1;
        }
        for e in &EDGES {
            let mut key = [h[e[0]], h[e[1]]];
            key.sort_unstable();
            shortest = shortest.min(norm(sub(x[e[0]], x[e[1]])));
            edges.insert(key);
        }
    }
    let boundary: HashSet<[u64; 4]> = msh
        .quads
        .iter()
        .map(|q| {
            let mut k = *q;
            k.sort_unstable();
            k
        })
        .collect();
    for (key, (n, _)) in &faces {
        match n {
            1 => {
                out.faces_used_once += 1;
                if !boundary.contains(key) {
                    out.unmatched_faces += 1;
                }
            }
            2 => {}
            _ => out.crowded_faces += 1,
        }
    }
    out.stray_boundary = boundary
        .iter()
        .filter(|k| faces.get(*k).map(|f| f.0) != Some(1))
        .count();
    let grid = Grid::new(p, shortest.max(1e-300) * 2.0);
    let mut near = Vec::new();
    for e in &edges {
        let (a, b) = (p[&e[0]], p[&e[1]]);
        let d = sub(b, a);
        let len2 = dot(d, d);
        let tol = 1e-9 * len2.sqrt();
        let lo = [0, 1, 2].map(|k| a[k].min(b[k]) - tol);
        let hi = [0, 1, 2].map(|k| a[k].max(b[k]) + tol);
        grid.near(lo, hi, &mut near);
        for &t in &near {
            if t == e[0] || t == e[1] {
                continue;
            }
            let q = sub(p[&t], a);
            let s = dot(q, d) / len2;
            if s > 1e-9 && s < 1.0 - 1e-9 && norm(sub(q, d.map(|x| x * s))) <= tol {
                out.in_edges.insert(t);
            }
        }
    }
    for (_, corners) in faces.values() {
        let x = corners.map(|t| p[&t]);
        let size = norm(sub(x[2], x[0])).max(norm(sub(x[3], x[1])));
        let tol = 1e-9 * size;
        let lo = [0, 1, 2].map(|k| x.iter().fold(f64::MAX, |m, q| m.min(q[k])) - tol);
        let hi = [0, 1, 2].map(|k| x.iter().fold(f64::MIN, |m, q| m.max(q[k])) + tol);
        grid.near(lo, hi, &mut near);
        for &t in &near {
            if corners.contains(&t) || out.in_edges.contains(&t) {
                continue;
            }
            let q = p[&t];
            if in_triangle(q, x[0], x[1], x[2], tol) || in_triangle(q, x[0], x[2], x[3], tol) {
                out.in_faces.insert(t);
            }
        }
    }
    out
}
