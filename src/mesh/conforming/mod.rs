//! Conforming all-hexahedral meshes by refinement templates: the scheme,
//! its configurations and the templates proven so far. [`build::build`]
//! meshes a whole octree's kept leaves (`--conforming`); where a kept macro
//! cell is in one of the eight classes of configurations that have no
//! template yet, it splits the cell and balances again until none is left
//! ([`build::close`]).
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
//! marks of its four corners ([`marks::face_pattern`]): fine cells on a
//! full face (four marks), the corner quadrant at each marked corner on an
//! L face (three marks, two marked edges meeting at one), and per quadrant
//! the leaf, the corner quadrant or the half-edge quadrant on any other.
//! Across a face, a macro cell sees either
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
//! whose octants each see corner quadrants on their three faces, or the
//! half-edge quadrant along one marked edge on the two faces holding it, is
//! meshed octant by octant (corner and half-edge pieces, see [`pieces`]);
//! one whole marked face has the face template (the pair template in x
//! whose lower quadrilaterals each carry the pair template in y, its
//! mid-plane lifted); all eight marked is 4 x 4 x 4 fine cells. Every
//! template is checked by brute force in the unit tests: volumes add up to
//! the macro cell's, every corner's scaled Jacobian at least 0.3 (the
//! templates reach 0.400), every inner face in exactly two hexahedra, no
//! node inside another hexahedron's edge, the boundary equal to the
//! canonical pattern of each face. That covers 14 of the 22 classes (104 of
//! the 256 mark sets). [`assemble::assemble`] places the templates of a
//! whole macro tree in one lattice, checked globally in the unit tests on
//! octrees whose macro cells all have covered classes.
//!
//! # Configurations without a template
//!
//! Eight classes have none: those with an octant whose plain face shows the
//! half-edge quadrant along an edge that an L face beside it holds too
//! (`00000111`, `00011011`, `00011110`, `00111101`), and those with a full
//! face beside a plain or L face at one corner (`00011111`, the concave
//! edge `00111111`, `01101111`, the concave corner `01111111`). No
//! octant-by-octant template exists for an octant on a full face whose
//! other two faces show half-edge quadrants: it would have 1 + 5 + 5 + 5 +
//! 5 + 4 = 25 boundary quadrilaterals, and a hexahedral mesh of a ball has
//! an even number. [`configurations`] lists the classes with their
//! coverage; on the sphere at level 5 the open ones are the concave edge
//! and corner, 72 of 1,408 macro cells. The closure splits them, and the
//! staircases make it refine every coarser region bounded by finer cells
//! to the finest level.

pub mod assemble;
pub mod build;
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
