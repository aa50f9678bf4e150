//! Files octmesh writes and reads: leaf lists, VTK XML meshes (`vtu`), JSON
//! statistics and reports (`json`), and (in `geometry::stl`) STL.

pub mod json;
pub mod leaves;
pub mod vtu;
