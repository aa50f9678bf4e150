//! # octmesh
//!
//! Parallel 2:1-balanced linear octrees and trilinear hexahedral meshes from
//! triangulated surfaces.
//!
//! The pipeline, every step collective over the ranks of a [`parallel::comm::Comm`]:
//!
//! 1. read a [`geometry::Surface`] (STL or a built-in shape) and fit a
//!    [`octree::domain::Domain`] cube around it;
//! 2. build the [`octree::LinearOctree`] refined to the surface
//!    ([`refine::build_from_surface`]) or by a predicate
//!    ([`refine::build_from_callback`]);
//! 3. [`octree::LinearOctree::partition`], then
//!    [`octree::LinearOctree::balance`] for face, edge or corner
//!    [`octree::octant::Connectivity`], then partition again;
//! 4. optionally, for a fluid mesh, [`leak::find_leak`]: does the region
//!    outside the surface reach a point known to be inside the body?
//!
//! Octants live on a lattice of 2^19 points per side (see [`octree::octant`]); leaves
//! are kept in Morton order, each rank holding a contiguous run.

pub mod classify;
pub mod config;
pub mod error;
pub mod ffi;
pub mod geometry;
pub mod io;
pub mod leak;
pub mod mesh;
pub mod octree;
pub mod parallel;
pub mod pipeline;
pub mod refine;
pub mod run;

pub use error::{Error, ErrorKind, Result};
pub use octree::octant::{Connectivity, Octant, MAX_LEVEL};
pub use octree::LinearOctree;

#[cfg(test)]
mod testutil;
