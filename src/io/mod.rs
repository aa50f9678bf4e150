//! Files octmesh writes and reads: leaf lists, and (in `geometry::stl`) STL.

pub mod leaves;
