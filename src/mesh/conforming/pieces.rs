//! The templates as data: the hexahedra of a macro cell for a mark set, in
//! the macro's integer lattice (quarters of a fine cell, `[0, 16]^3`).
//!
//! A macro cell is meshed octant by octant when every octant's three macro
//! faces ask for one of these pieces (`piece`); the octant at macro
//! corner `c` gets
//!
//! - `c` unmarked: one box (the leaf itself);
//! - `c` marked, every face at `c` showing the corner quadrant (no marked
//!   edge at `c`, or the faces holding one are L faces): the corner piece,
//!   a fine cell at the corner and three frusta from its outer faces to
//!   the octant's (4 hexahedra, each octant face at the corner a unit
//!   square and two trapezoids, the three inner faces whole);
//! - `c` marked, the two faces holding the marked edge along `d` showing
//!   the half-edge quadrant and the third the corner quadrant: the
//!   half-edge piece, two fine
//!   cells along `d`, and over each of the two trapezoids of the corner
//!   piece's section half of the 2D pair template (4 segments to 2) swept
//!   across the trapezoid (8 hexahedra; the inner face across `d` shows the
//!   trapezoids split at their mid-lines, the same from both octants of
//!   the edge).
//!
//! ```text
//!   section across d (fine cells)      face along d, z = 0 (fine cells)
//!   2 +--------+                       2 +-------+      t0 ------ t1
//!     | B     /|                         |  \ p  |m     |  \  p---m
//!     |     /  |                         |   +---+      |   \ |   |
//!   1 +---+  A |                       1 +---+---+      b0--b1---b2
//!     | U | \  |                         | U | U |
//!   0 +---+---\+                       0 +---+---+
//!     0   1    2  (mid-lines of A, B:    0   1   2  along d
//!                  y = 1.5 / z = 1.5)
//! ```
//!
//! A macro cell with all eight corners marked is 4 x 4 x 4 fine cells.

use super::marks::{away, Marks, Symmetry};
use super::{Hex, Point, FINE, MACRO};
use crate::geometry::cells::VTK_TO_MORTON;

/// A hexahedron in an octant's own frame: fine cells from the macro corner
/// toward the centre (VTK order, possibly mirrored).
type LocalHex = [[f64; 3]; 8];

/// The hexahedra of the macro cell with these marks, in VTK order with a
/// positive volume, or `None` for a mark set without a template yet.
pub fn macro_template(marks: Marks) -> Option<Vec<Hex>> {
    if marks.0 == 0xff {
        return Some(grid(4));
    }
    if let Some(s) = Symmetry::all().find(|&s| Marks(0x0f).transform(s) == marks) {
        return Some(face_template().iter().map(|h| turn(s, h)).collect());
    }
    let pieces: Vec<Piece> = (0..8).map(|c| piece(marks, c)).collect::<Option<_>>()?;
    // Across the face between two octants the half-edge piece along the
    // axis shows its split trapezoids, every other piece one quadrilateral.
    for c in 0..8 {
        for a in 0..3 {
            let across = |p: Piece| p == Piece::HalfEdge(a);
            if across(pieces[c]) != across(pieces[c ^ 1 << a]) {
                return None;
            }
        }
    }
    let mut hexes = Vec::new();
    for (c, &p) in pieces.iter().enumerate() {
        let local = match p {
            Piece::Leaf => vec![boxed([0.0; 3], [2.0; 3])],
            Piece::Corner => corner_piece(),
            Piece::HalfEdge(d) => half_edge_piece(d),
        };
        hexes.extend(local.iter().map(|h| place(c, h)));
    }
    Some(hexes)
}

/// The octant pieces.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Piece {
    Leaf,
    Corner,
    /// Along the axis.
    HalfEdge(usize),
}

/// The piece whose three macro faces at corner `c` show what the faces'
/// patterns ask for there, if there is one: the leaf at an unmarked
/// corner; the corner piece where every face shows the corner quadrant;
/// the half-edge piece along `d` where the two faces holding the edge
/// along `d` show the half-edge quadrant along it and the third the corner
/// quadrant.
fn piece(marks: Marks, c: usize) -> Option<Piece> {
    use super::marks::FaceKind;
    if !marks.marked(c) {
        return Some(Piece::Leaf);
    }
    if (0..3).any(|a| marks.face_kind(a, c >> a & 1) == FaceKind::Full) {
        return None;
    }
    let edges = [0, 1, 2].map(|a| marks.face_edge(c, a));
    if edges.iter().all(Option::is_none) {
        return Some(Piece::Corner);
    }
    (0..3)
        .find(|&d| edges[d].is_none() && (0..3).all(|a| a == d || edges[a] == Some(d)))
        .map(Piece::HalfEdge)
}

/// The macro cell as `n^3` boxes.
fn grid(n: i32) -> Vec<Hex> {
    let s = MACRO / n;
    let mut out = Vec::new();
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                out.push(vtk_box([i * s, j * s, k * s], s));
            }
        }
    }
    out
}

/// A box at lattice point `a` with side `s`, in VTK order.
fn vtk_box(a: Point, s: i32) -> Hex {
    VTK_TO_MORTON.map(|c| [0, 1, 2].map(|k| a[k] + ((c >> k) & 1) as i32 * s))
}

/// The box `[lo, hi]` in an octant's frame.
fn boxed(lo: [f64; 3], hi: [f64; 3]) -> LocalHex {
    VTK_TO_MORTON.map(|c| [0, 1, 2].map(|k| if (c >> k) & 1 == 0 { lo[k] } else { hi[k] }))
}

/// Axis `d` of an octant-frame point becomes axis 0: `[p[d], p[d+1], p[d+2]]`
/// read back, so a piece built along x serves every axis.
fn rotate(h: &LocalHex, d: usize) -> LocalHex {
    h.map(|p| {
        let mut q = [0.0; 3];
        for (a, &value) in p.iter().enumerate() {
            q[(a + d) % 3] = value;
        }
        q
    })
}

/// The corner piece: a fine cell and three frusta.
fn corner_piece() -> Vec<LocalHex> {
    // The frustum over the fine cell's face x = 1: its section grows from
    // [0, 1]^2 at x = 1 to [0, 2]^2 at x = 2.
    let frustum = |x: usize, y: usize, z: usize| {
        let t = 1.0 + x as f64;
        [t, y as f64 * t, z as f64 * t]
    };
    let f: LocalHex = [
        frustum(0, 0, 0),
        frustum(0, 1, 0),
        frustum(0, 1, 1),
        frustum(0, 0, 1),
        frustum(1, 0, 0),
        frustum(1, 1, 0),
        frustum(1, 1, 1),
        frustum(1, 0, 1),
    ];
    vec![boxed([0.0; 3], [1.0; 3]), f, rotate(&f, 1), rotate(&f, 2)]
}

/// The half-edge piece along axis `d`.
fn half_edge_piece(d: usize) -> Vec<LocalHex> {
    // Half of the pair template in (x, w): x along the edge from the macro
    // corner, w across the trapezoid from the fine cells (w = 0) to the
    // coarse side (w = 1).
    const B0: [f64; 2] = [0.0, 0.0];
    const B1: [f64; 2] = [1.0, 0.0];
    const B2: [f64; 2] = [2.0, 0.0];
    const P: [f64; 2] = [1.0, 0.5];
    const M: [f64; 2] = [2.0, 0.5];
    const T0: [f64; 2] = [0.0, 1.0];
    const T1: [f64; 2] = [2.0, 1.0];
    let pair = [[B0, B1, P, T0], [B1, B2, M, P], [P, M, T1, T0]];
    // Trapezoid A: y = 1 + w, z = s (1 + w) for s in [0, 1]; B mirrors y, z.
    let a = |[x, w]: [f64; 2], s: f64| [x, 1.0 + w, s * (1.0 + w)];
    let b = |[x, w]: [f64; 2], s: f64| [x, s * (1.0 + w), 1.0 + w];
    let mut out = vec![
        boxed([0.0; 3], [1.0; 3]),
        boxed([1.0, 0.0, 0.0], [2.0, 1.0, 1.0]),
    ];
    for quad in pair {
        out.push(std::array::from_fn(|k| a(quad[k % 4], (k / 4) as f64)));
        out.push(std::array::from_fn(|k| b(quad[k % 4], (k / 4) as f64)));
    }
    out.iter().map(|h| rotate(h, d)).collect()
}

/// The face template: the four corners of the face z = 0 marked, nothing
/// else. Fine cells in `z` in [0, 1]; in [1, 2] the 2D pair template in
/// (x, z), whose four lower quadrilaterals each carry the pair template in
/// y swept across them (4 segments along y at their lower edge, 2 at their
/// upper), and whose two upper quadrilaterals are swept along y in 2
/// segments; leaves above; the mid-plane y = 2 lifted ([`lift`]). Every
/// side face shows fine cells, then the pair template, then leaves: the
/// canonical pattern of a face with one marked edge (48 hexahedra).
fn face_template() -> Vec<Hex> {
    // The pair template over [0, 4] with its lower side at 0 and its upper
    // at 1: nodes, then lower (from the lower edge) and upper quadrilaterals.
    const B: [[f64; 2]; 5] = [[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0], [4.0, 0.0]];
    const P: [f64; 2] = [1.0, 0.5];
    const M: [f64; 2] = [2.0, 0.5];
    const Q: [f64; 2] = [3.0, 0.5];
    const T: [[f64; 2]; 3] = [[0.0, 1.0], [2.0, 1.0], [4.0, 1.0]];
    let lower = [
        [B[0], B[1], P, T[0]],
        [B[1], B[2], M, P],
        [B[2], B[3], Q, M],
        [B[3], B[4], T[2], Q],
    ];
    let upper = [[P, M, T[1], T[0]], [M, Q, T[2], T[1]]];
    let mut local: Vec<LocalHex> = Vec::new();
    for j in 0..4 {
        for i in 0..4 {
            let (i, j) = (f64::from(i), f64::from(j));
            local.push(boxed([i, j, 0.0], [i + 1.0, j + 1.0, 1.0]));
        }
    }
    // (x, z) of a lower quadrilateral `c` at (s, w): s across it from its
    // left side to its right, w from its lower edge to its upper.
    let bilinear = |c: [[f64; 2]; 4], s: f64, w: f64| -> [f64; 2] {
        std::array::from_fn(|k| {
            (1.0 - s) * (1.0 - w) * c[0][k]
                + s * (1.0 - w) * c[1][k]
                + s * w * c[2][k]
                + (1.0 - s) * w * c[3][k]
        })
    };
    for c in lower {
        for y_quad in lower.iter().chain(upper.iter()) {
            local.push(std::array::from_fn(|k| {
                let [y, w] = y_quad[k % 4];
                let [x, z] = bilinear(c, (k / 4) as f64, w);
                [x, y, 1.0 + z]
            }));
        }
    }
    for c in upper {
        for y0 in [0.0, 2.0] {
            local.push(std::array::from_fn(|k| {
                let [x, z] = c[k % 4];
                [x, y0 + 2.0 * (k / 4) as f64, 1.0 + z]
            }));
        }
    }
    for j in 0..2 {
        for i in 0..2 {
            let (i, j) = (2.0 * f64::from(i), 2.0 * f64::from(j));
            local.push(boxed([i, j, 2.0], [i + 2.0, j + 2.0, 4.0]));
        }
    }
    local.iter().map(|h| place(0, &h.map(lift))).collect()
}

/// The face template's nodes on the mid-plane y = 2 inside the macro cell,
/// raised: the sweep alone leaves the pair template in y squeezed into half
/// a fine cell under the pair template in x (scaled Jacobian 0.22); lifted,
/// the inner U-turn arches over the outer one and every corner reaches 0.4
/// (found by maximising the smallest corner over the free nodes, then
/// rounded to half fine cells).
fn lift(p: [f64; 3]) -> [f64; 3] {
    const LIFTS: [([f64; 3], f64); 5] = [
        ([1.0, 2.0, 1.25], 1.5),
        ([1.0, 2.0, 1.5], 2.0),
        ([2.0, 2.0, 1.25], 1.5),
        ([2.0, 2.0, 1.5], 2.5),
        ([2.0, 2.0, 2.0], 3.0),
    ];
    let mirrored = [4.0 - p[0], p[1], p[2]];
    for (from, z) in LIFTS {
        if p == from || mirrored == from {
            return [p[0], p[1], z];
        }
    }
    p
}

/// A macro-lattice hexahedron under the symmetry `s`, turned to a positive
/// volume.
fn turn(s: Symmetry, h: &Hex) -> Hex {
    orient(h.map(|p| s.point(p)))
}

/// The hexahedron, its two faces swapped if its volume is negative.
fn orient(hex: Hex) -> Hex {
    if signed_volume(&hex) < 0 {
        [
            hex[4], hex[5], hex[6], hex[7], hex[0], hex[1], hex[2], hex[3],
        ]
    } else {
        hex
    }
}

/// An octant-frame hexahedron placed at macro corner `c`, in lattice units,
/// turned to a positive volume.
fn place(c: usize, h: &LocalHex) -> Hex {
    orient(h.map(|p| {
        std::array::from_fn(|a| {
            let quarters = p[a] * FINE as f64;
            debug_assert_eq!(quarters, quarters.round(), "off the lattice");
            away(c, a, quarters as i32)
        })
    }))
}

/// Six times the volume of the tetrahedra of a hexahedron's corner 0 (for
/// the orientation only: positive for a right-handed VTK order).
fn signed_volume(h: &Hex) -> i64 {
    let v = |i: usize| h[i].map(i64::from);
    let (p0, p1, p3, p4) = (v(0), v(1), v(3), v(4));
    let e = |p: [i64; 3]| [p[0] - p0[0], p[1] - p0[1], p[2] - p0[2]];
    let (a, b, c) = (e(p1), e(p3), e(p4));
    a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
        + a[2] * (b[0] * c[1] - b[1] * c[0])
}
