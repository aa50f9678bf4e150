//! The marked corners of a macro cell, their 48 symmetries, and the
//! canonical pattern of a macro face: the quadrilaterals a face shows,
//! decided by the marks of its own four corners only, so the two macro
//! cells sharing a face build the same quadrilaterals on it.

use super::{Point, FINE};

/// The marked corners of a macro cell: bit `c` (Morton corner `c`: bit `a`
/// of `c` is the upper side along axis `a`) is set when a macro cell one
/// level finer touches that corner.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Marks(pub u8);

impl Marks {
    /// Whether corner `c` is marked.
    pub fn marked(self, c: usize) -> bool {
        self.0 >> c & 1 == 1
    }

    /// Whether the macro edge from corner `c` along `axis` has both ends
    /// marked (a marked edge).
    pub fn edge_marked(self, c: usize, axis: usize) -> bool {
        self.marked(c) && self.marked(c ^ 1 << axis)
    }

    /// The number of marked edges at corner `c`.
    pub fn degree(self, c: usize) -> usize {
        (0..3).filter(|&a| self.edge_marked(c, a)).count()
    }

    /// Whether no two marked edges share a corner.
    pub fn is_matching(self) -> bool {
        (0..8).all(|c| self.degree(c) <= 1)
    }

    /// What the macro face normal to `axis` on `side` is: by how many of
    /// its corners are marked and how.
    pub fn face_kind(self, axis: usize, side: usize) -> FaceKind {
        let (u, v) = face_axes(axis);
        let corners = (0..8).filter(|&c| c >> axis & 1 == side);
        if corners.clone().all(|c| self.marked(c)) {
            FaceKind::Full
        } else if corners
            .clone()
            .any(|c| self.edge_marked(c, u) && self.edge_marked(c, v))
        {
            FaceKind::L
        } else {
            FaceKind::Plain
        }
    }

    /// The edge along which the face normal to `axis` at corner `c` shows
    /// the half-edge quadrant, if any: a plain face with a marked edge at
    /// `c` ([`quadrant_pattern`]).
    pub fn face_edge(self, c: usize, axis: usize) -> Option<usize> {
        let (u, v) = face_axes(axis);
        (self.face_kind(axis, c >> axis & 1) == FaceKind::Plain)
            .then(|| [u, v].into_iter().find(|&a| self.edge_marked(c, a)))
            .flatten()
    }

    /// The marks after the symmetry `s` of the cube.
    pub fn transform(self, s: Symmetry) -> Marks {
        let mut out = 0u8;
        for c in (0..8).filter(|&c| self.marked(c)) {
            out |= 1 << s.corner(c);
        }
        Marks(out)
    }

    /// The smallest mark set among the 48 images of these marks: one
    /// representative per class of configurations.
    pub fn class(self) -> Marks {
        Symmetry::all()
            .map(|s| self.transform(s))
            .min()
            .expect("48 symmetries")
    }
}

/// A macro face by its corner marks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FaceKind {
    /// All four corners marked: fine cells.
    Full,
    /// Three corners marked, two marked edges meeting at one of them (an L
    /// of marks): the corner quadrant at each marked corner, the marked
    /// edges split by the quadrants' fine squares and trapezoids.
    L,
    /// Anything else: per quadrant, the leaf, the corner quadrant or the
    /// half-edge quadrant.
    Plain,
}

/// The two axes of a face normal to `axis`, increasing.
pub fn face_axes(axis: usize) -> (usize, usize) {
    let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
    (a.min(b), a.max(b))
}

/// A symmetry of the cube: output axis `a` is input axis `perm[a]`,
/// reflected when bit `a` of `flip` is set.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Symmetry {
    /// Which input axis each output axis reads.
    pub perm: [usize; 3],
    /// Reflections of the output axes.
    pub flip: u8,
}

impl Symmetry {
    /// The 48 symmetries (6 axis orders times 8 reflections).
    pub fn all() -> impl Iterator<Item = Symmetry> {
        const PERMS: [[usize; 3]; 6] = [
            [0, 1, 2],
            [0, 2, 1],
            [1, 0, 2],
            [1, 2, 0],
            [2, 0, 1],
            [2, 1, 0],
        ];
        PERMS
            .into_iter()
            .flat_map(|perm| (0..8u8).map(move |flip| Symmetry { perm, flip }))
    }

    /// The image of a lattice point of the macro cell.
    pub fn point(self, p: super::Point) -> super::Point {
        std::array::from_fn(|a| {
            let x = p[self.perm[a]];
            if self.flip >> a & 1 == 1 {
                super::MACRO - x
            } else {
                x
            }
        })
    }

    /// The image of Morton corner `c`.
    pub fn corner(self, c: usize) -> usize {
        (0..3)
            .map(|a| ((c >> self.perm[a] & 1) ^ (self.flip as usize >> a & 1)) << a)
            .sum()
    }
}

/// A quadrilateral in a face quadrant's own coordinates: fine cells from
/// the macro corner, along the face's two axes, in quarters of a fine cell.
type LocalQuad = [[i32; 2]; 4];

/// The quadrilaterals of the quadrant of a macro face at a macro corner, in
/// quarters of a fine cell measured from that corner along the face's
/// first (`u`) and second (`v`) axes. `marked`: the corner is; `eu`, `ev`:
/// the macro edges of the face at the corner along `u` and `v` are marked.
pub fn quadrant_pattern(marked: bool, eu: bool, ev: bool) -> Vec<LocalQuad> {
    const F: i32 = FINE;
    let q = |p: [[i32; 2]; 4]| p.map(|[u, v]| [u * F / 2, v * F / 2]);
    let swap = |p: LocalQuad| p.map(|[u, v]| [v, u]);
    if !marked {
        // One coarse quadrilateral.
        return vec![q([[0, 0], [4, 0], [4, 4], [0, 4]])];
    }
    match (eu, ev) {
        // A unit square at the corner and two trapezoids to the coarse
        // sides (in half fine cells).
        (false, false) => vec![
            q([[0, 0], [2, 0], [2, 2], [0, 2]]),
            q([[2, 0], [4, 0], [4, 4], [2, 2]]),
            q([[0, 2], [2, 2], [4, 4], [0, 4]]),
        ],
        // Fine cells along the marked edge, then half of the pair template
        // (4 segments to 2) in the second fine row.
        (true, false) => vec![
            q([[0, 0], [2, 0], [2, 2], [0, 2]]),
            q([[2, 0], [4, 0], [4, 2], [2, 2]]),
            q([[0, 2], [2, 2], [2, 3], [0, 4]]),
            q([[2, 2], [4, 2], [4, 3], [2, 3]]),
            q([[2, 3], [4, 3], [4, 4], [0, 4]]),
        ],
        (false, true) => quadrant_pattern(true, true, false)
            .into_iter()
            .map(|p| {
                let mut s = swap(p);
                s.reverse();
                s
            })
            .collect(),
        // A face whose four corners are marked: fine cells (what the finer
        // macro cells across it show).
        (true, true) => (0..2)
            .flat_map(|i| (0..2).map(move |j| (i, j)))
            .map(|(i, j)| {
                q([
                    [2 * i, 2 * j],
                    [2 * i + 2, 2 * j],
                    [2 * i + 2, 2 * j + 2],
                    [2 * i, 2 * j + 2],
                ])
            })
            .collect(),
    }
}

/// The canonical quadrilaterals of the macro face normal to `axis` on side
/// `side` (0 low, 1 high), in the macro's lattice units: per quadrant, by
/// the face's [`FaceKind`].
pub fn face_pattern(marks: Marks, axis: usize, side: usize) -> Option<Vec<[Point; 4]>> {
    let (u_axis, v_axis) = face_axes(axis);
    let corners: Vec<usize> = (0..8).filter(|&c| c >> axis & 1 == side).collect();
    let kind = marks.face_kind(axis, side);
    let mut quads = Vec::new();
    for &c in &corners {
        let (eu, ev) = match kind {
            FaceKind::Full => (true, true),
            FaceKind::L => (false, false),
            FaceKind::Plain => (marks.edge_marked(c, u_axis), marks.edge_marked(c, v_axis)),
        };
        for quad in quadrant_pattern(marks.marked(c), eu, ev) {
            quads.push(quad.map(|[u, v]| {
                let mut p = [0; 3];
                p[axis] = side as i32 * super::MACRO;
                p[u_axis] = away(c, u_axis, u);
                p[v_axis] = away(c, v_axis, v);
                p
            }));
        }
    }
    Some(quads)
}

/// The lattice coordinate along `axis` of a point `d` quarters of a fine
/// cell from macro corner `c` toward the macro's centre.
pub fn away(c: usize, axis: usize, d: i32) -> i32 {
    if c >> axis & 1 == 1 {
        super::MACRO - d
    } else {
        d
    }
}
