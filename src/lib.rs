//! # octmesh
//!
//! Parallel 2:1-balanced linear octrees and hexahedral meshes from
//! triangulated surfaces (STL), for finite-element and finite-volume
//! solvers, on one process or over the ranks of an MPI communicator.
//!
//! # The pipeline
//!
//! A [`Session`] holds one run's state and has one method per stage. Every
//! stage is collective over the session's communicator; on one process a
//! [`SerialComm`] stands in for MPI, and an MPI program passes an
//! [`MpiComm`] built from its communicator.
//!
//! ```text
//!  load_surface ─► refine_surface ─► partition ─► balance ─► partition
//!      ─► classify ─► build_mesh ─► snap ─► faces / boundary / quality
//!      ─► write_vtu / write_openfoam
//! ```
//!
//! 1. **Surface.** [`Session::load_surface`] reads the STL file (or a
//!    built-in shape: `sphere`, `torus`, `hull`) named by the
//!    [`Config`] and fits the root cube around it.
//! 2. **Octree.** [`Session::refine_surface`] builds the distributed
//!    [`LinearOctree`], refined where leaves touch the surface;
//!    [`Session::partition`] spreads its leaves over the ranks in Morton
//!    order and [`Session::balance`] makes it 2:1 balanced across faces,
//!    edges or corners ([`Connectivity`]).
//! 3. **Inside and outside.** [`Session::classify`] marks each leaf as cut by
//!    the surface, inside it or outside it ([`InsideRule`]).
//! 4. **Mesh.** [`Session::build_mesh`] keeps the solid, the fluid or
//!    everything ([`Keep`]) and builds the [`Mesh`]: elements, independent
//!    and hanging nodes, global numbers and owners.
//!
//! ```
//! use std::rc::Rc;
//! use octmesh::{Config, Connectivity, CutRule, InsideRule, Keep, SerialComm, Session};
//!
//! # fn main() -> octmesh::Result<()> {
//! let mut config = Config::default();
//! config.surface.file = "sphere".into(); // radius 1 at the origin
//! let mut session = Session::new(Rc::new(SerialComm), config);
//! session.load_surface()?;
//! session.refine_surface(4)?;
//! session.partition()?;
//! session.balance(Connectivity::Corner)?;
//! session.partition()?;
//! session.classify(InsideRule::Parity)?;
//! session.build_mesh(Keep::Inside, CutRule::Center)?;
//!
//! let mesh = session.mesh().expect("built above");
//! let counts = mesh.counts();
//! assert_eq!(counts.elements as usize, mesh.elements().len()); // one rank
//! assert!(counts.face_hanging_nodes + counts.edge_hanging_nodes > 0);
//! // Eight corners per element, numbered locally.
//! assert!(mesh.connectivity().iter().flatten().all(|&n| (n as usize) < mesh.num_nodes()));
//! # Ok(())
//! # }
//! ```
//!
//! 5. **Outputs.** The mesh can be snapped to the surface
//!    ([`Session::snap`]), given finite-volume faces ([`Session::faces`]) and
//!    a boundary with patches ([`Session::boundary`]), judged
//!    ([`Session::quality`]) and written as VTU ([`Session::write_vtu`]) or
//!    as an OpenFOAM case ([`Session::write_openfoam`]).
//!
//! ```no_run
//! # use std::rc::Rc;
//! # use octmesh::{Config, Connectivity, CutRule, InsideRule, Keep, SerialComm, Session, SnapOptions};
//! # fn main() -> octmesh::Result<()> {
//! # let mut config = Config::default();
//! # config.surface.file = "sphere".into();
//! # let mut session = Session::new(Rc::new(SerialComm), config);
//! # session.load_surface()?;
//! # session.refine_surface(5)?;
//! # session.balance(Connectivity::Corner)?;
//! # session.classify(InsideRule::Parity)?;
//! session.build_mesh(Keep::Outside, CutRule::Center)?;
//! session.snap(&SnapOptions::default())?;
//! session.write_openfoam(std::path::Path::new("case"))?;
//! # Ok(())
//! # }
//! ```
//!
//! 6. **Checkpoints.** [`Session::save_octree`] writes the octree, its
//!    domain and the attached leaf data to one file, every rank its own
//!    leaves at their offset; [`Session::load_octree`] reads it back on any number
//!    of ranks, in equal shares, checking the file's checksums and that the
//!    session's surface is the one it was saved from. Without a session:
//!    [`LinearOctree::save`] and [`LinearOctree::load`] ([`Loaded`]).
//!
//! The `octmesh` command runs the whole sequence a [`Config`] asks for with
//! [`Session::run`]; the C API's handle calls the same stages.
//!
//! # Errors
//!
//! Every stage returns [`Result`]; an [`Error`] carries a stable
//! [`ErrorKind`] (the C API's status codes) and a message, and is the same
//! on every rank. A failed stage leaves the session as it was.
//!
//! # Units and orderings
//!
//! Coordinates are in the surface's units. Octants live on a lattice of
//! 2^19 points per side of each root cell ([`MAX_LEVEL`]); leaves are kept
//! in Morton order, each rank holding a contiguous run. An element's eight
//! nodes ([`Mesh::connectivity`]) are in VTK's hexahedron order: the lower
//! face counter-clockwise seen from above, then the upper face.

pub(crate) mod classify;
pub(crate) mod config;
pub mod error;
pub(crate) mod ffi;
pub(crate) mod geometry;
pub(crate) mod io;
pub(crate) mod leak;
pub(crate) mod mesh;
pub(crate) mod octree;
pub(crate) mod parallel;
pub(crate) mod pipeline;
pub(crate) mod refine;
pub(crate) mod run;

pub use classify::{CutRule, InsideRule, Keep};
pub use config::{Command, Config};
pub use error::{Error, ErrorKind, Result};
pub use geometry::Surface;
pub use mesh::quality::Quality;
pub use mesh::snap::{SnapOptions, SnapReport};
pub use mesh::{Boundary, Faces, Mesh, MeshCounts, Zones};
pub use octree::checkpoint::{CheckpointInfo, Loaded};
pub use octree::domain::Domain;
pub use octree::octant::{Connectivity, Octant, MAX_LEVEL};
pub use octree::LinearOctree;
pub use parallel::comm::{Comm, CommRef, MpiComm, SerialComm};
pub use pipeline::{Event, Observer, Session, Silent, Stats};

/// Every module of the crate, for octmesh's own tests, benchmarks and
/// command. Not part of the supported API: use the items at the crate root.
#[doc(hidden)]
pub mod internals {
    macro_rules! expose {
        ($($m:ident),*) => {$(
            pub mod $m {
                pub use crate::$m::*;
            }
        )*};
    }
    expose!(
        classify, config, ffi, geometry, io, leak, mesh, octree, parallel, pipeline, refine, run
    );
}

#[cfg(test)]
mod testutil;

/// The README's Rust example, compiled by `cargo test --doc`.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeExample;
