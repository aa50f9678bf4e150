//! The faces of a hexahedron given by its 8 corners in VTK order (= Gmsh =
//! Abaqus C3D8), and the matching of faces between such hexahedra, shared by
//! the conforming mesh's measurements and the single-file writers.
//!
//! ```text
//!        7-------6        VTK corners: 0-1-2-3 the bottom (z low),
//!       /|      /|        4-5-6-7 the top, each counter-clockwise
//!      4-------5 |        seen from above.
//!      | 3-----|-2
//!      |/      |/
//!      0-------1
//! ```

use crate::geometry::hash::FoldMap;

/// The corners of p4est face `f` (`2 axis + side`) as Abaqus lists them:
/// [`ABAQUS_FACE`]`[f]` is the face's label `S1..S6` less one, and
/// [`ABAQUS_FACE_NODES`] its 4 VTK corners in Abaqus's order.
pub const ABAQUS_FACE: [u8; 6] = [5, 3, 2, 4, 0, 1];

/// The VTK (= Abaqus C3D8 = Gmsh) corners of the hexahedron's faces
/// `S1..S6`: S1 = 1-2-3-4, S2 = 5-8-7-6, S3 = 1-5-6-2, S4 = 2-6-7-3,
/// S5 = 3-7-8-4, S6 = 4-8-5-1 (1-based in Abaqus's manual). Each runs
/// clockwise seen from outside, so its right-hand normal points into the
/// element.
pub const ABAQUS_FACE_NODES: [[usize; 4]; 6] = [
    [0, 1, 2, 3],
    [4, 7, 6, 5],
    [0, 4, 5, 1],
    [1, 5, 6, 2],
    [2, 6, 7, 3],
    [3, 7, 4, 0],
];

/// Faces of elements as (element, Abaqus label less one): those two
/// elements share as (first, its label, second), then those of one only.
pub type MatchedFaces = (Vec<(u32, u8, u32)>, Vec<(u32, u8)>);

/// The faces of conforming hexahedra (VTK order) by their Abaqus labels,
/// matched by their sorted corners: each face two elements have, as
/// (first element, its label, second element), and each face only one
/// element has, as (element, label), in no particular order.
pub fn match_faces(elements: &[[u32; 8]]) -> MatchedFaces {
    let mut open: FoldMap<[u32; 4], (u32, u8)> = FoldMap::default();
    let mut pairs = Vec::with_capacity(3 * elements.len());
    for (h, hex) in elements.iter().enumerate() {
        for (label, corners) in ABAQUS_FACE_NODES.iter().enumerate() {
            let mut key = corners.map(|c| hex[c]);
            key.sort_unstable();
            match open.remove(&key) {
                Some((o, l)) => pairs.push((o, l, h as u32)),
                None => {
                    open.insert(key, (h as u32, label as u8));
                }
            }
        }
    }
    (pairs, open.into_values().collect())
}
