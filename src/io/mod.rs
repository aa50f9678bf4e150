//! Files octmesh writes and reads: leaf lists, VTK XML meshes (`vtu`), and (in
//! `geometry::stl`) STL.

pub mod leaves;
pub mod vtu;
