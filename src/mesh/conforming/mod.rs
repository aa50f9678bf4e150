//! Conforming all-hexahedral meshes by refinement templates: the scheme,
//! its configurations and the templates proven so far (issue 57). Not yet
//! a stage of the pipeline: no option builds a conforming mesh.
//!
//! # Macro cells and marks
//!
//! The octree must come in whole families: every leaf's seven siblings are
//! leaves. The parents of the leaves then tile the domain: they are the
//! leaves of the *macro tree*, which must be 2:1 balanced across corners.
//! A macro corner is *marked* when a macro cell one level finer touches it.
//! By the corner balance the macro cells around a corner span two levels,
//! so the marks are a property of the corner, and the macro cells of the
//! finer level never see a mark there.
//!
//! Each macro cell is meshed by a template chosen by its eight marks (256
//! configurations, 22 up to the 48 symmetries of the cube). Near a marked
//! corner the template has *fine cells*, a quarter of the macro cell's side:
//! the size of the leaves of the finer macro cells across.
//!
//! # Why faces match
//!
//! A macro face shows a pattern of quadrilaterals that depends only on the
//! marks of its four corners ([`marks::face_pattern`]). Across a face, a
//! macro cell sees either
//!
//! - one macro cell of its level: the same four corners, the same marks,
//!   the same pattern;
//! - one coarser macro cell, whose face holds this face as a quarter: the
//!   corners are touched by the coarser cell, so by the balance none is
//!   marked here (pattern: 2 x 2 leaves), and the coarser face has all four
//!   corners marked (pattern: 4 x 4 of its fine cells), which is the same
//!   quadrilaterals on that quarter;
//! - four finer macro cells: all four corners marked (4 x 4 fine cells),
//!   each finer face unmarked (its 2 x 2 leaves).
//!
//! A face whose marks are neither all nor none only ever meets a face of
//! its own level. A macro edge's subdivision depends on its two end marks
//! (none: 2 segments; one: 1, 1, 2 fine cells from the marked end; both: 4),
//! so the faces around an edge agree along it; and the macro edge of a
//! coarser cell is met only along a whole half by a finer cell, which
//! touches that half's end (a cell of half the size aligned to its own
//! size cannot touch an edge at its midpoint alone).
//!
//! # Templates
//!
//! [`pieces::macro_template`]: unmarked corners keep their leaf; a macro cell
//! whose marked edges share no corner is meshed octant by octant (corner and
//! half-edge pieces, see [`pieces`]); all eight marked is 4 x 4 x 4 fine
//! cells. Every template is checked by brute force in the unit tests:
//! volumes add up to the macro cell's, every corner's scaled Jacobian at
//! least 0.3 (the templates reach 0.400), every inner face in exactly two
//! hexahedra, the boundary equal to the canonical pattern of each face.
//!
//! # Configurations without a template
//!
//! A corner with two or more marked edges (a face transition, an L of
//! marked edges, a concave corner) has none yet, and no octant-by-octant
//! template can exist for it with these face patterns: a hexahedral mesh of
//! a ball has an even number of boundary quadrilaterals, and the octant at a
//! corner with marked edges along x and y has 1 (whole face to the unmarked
//! z side) + 5 + 5 (its inner faces across x and y) + 5 + 5 (its outer
//! faces along x and along y) + 4 (its outer face in the x-y plane, fine
//! cells, since the four finer macro cells across a fully marked face
//! force them) = 25. Those configurations need whole-macro templates whose
//! inner structure crosses the octants; [`configurations`] lists what is
//! covered and what is not.

pub mod conditions;
pub mod marks;
pub mod pieces;

#[cfg(test)]
mod tests;

pub use marks::{face_pattern, Marks, Symmetry};
pub use pieces::macro_template;

/// A point of a macro cell's lattice: quarters of a fine cell.
pub type Point = [i32; 3];

/// A hexahedron: eight lattice points in VTK order.
pub type Hex = [Point; 8];

/// Lattice units per fine cell (a quarter of the macro cell's side).
pub const FINE: i32 = 4;

/// Lattice units per macro cell side.
pub const MACRO: i32 = 4 * FINE;

/// One class of mark sets under the cube's symmetries.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Class {
    /// The smallest mark set of the class.
    pub representative: Marks,
    /// How many of the 256 mark sets it holds.
    pub members: usize,
    /// Whether [`macro_template`] meshes it.
    pub covered: bool,
}

/// Every configuration a macro cell can see, by class: its eight corner
/// marks (the whole state its template and faces depend on), each class
/// with whether it has a template.
pub fn configurations() -> Vec<Class> {
    let mut classes: Vec<Class> = Vec::new();
    for m in 0..=255u8 {
        let rep = Marks(m).class();
        match classes.iter_mut().find(|c| c.representative == rep) {
            Some(c) => c.members += 1,
            None => classes.push(Class {
                representative: rep,
                members: 1,
                covered: macro_template(rep).is_some(),
            }),
        }
    }
    classes.sort_by_key(|c| (c.representative.0.count_ones(), c.representative));
    classes
}
