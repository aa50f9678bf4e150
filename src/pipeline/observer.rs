//! What a [`super::Session`] tells its caller while it runs: phases with
//! their times and counts, and facts as they become known. The command
//! prints them as a table; a library caller may log them or ignore them.

use std::path::Path;

use crate::classify::{InsideRule, WindingSummary};
use crate::mesh::quality::Quality;
use crate::mesh::MeshCounts;
use crate::octree::domain::Domain;
use crate::refine::LeafEstimate;

/// One thing that happened in a session. Every rank sees the same events
/// with the same (global) values, in the same order.
#[derive(Clone, Debug)]
pub enum Event<'a> {
    /// A surface is ready to refine against.
    SurfaceLoaded {
        /// Where it came from (a file, `sphere`, `torus`, or `triangles`).
        name: &'a str,
        /// Its triangles after clean-up.
        triangles: usize,
        /// Facets dropped by the clean-up, when one was asked for.
        dropped: Option<usize>,
        /// The cube the next octree is built in.
        domain: Domain,
        /// The size of the octree at the configured level, when one is set.
        estimate: Option<LeafEstimate>,
        /// The inside rule the run will classify with, and for `auto` why.
        inside: Option<(InsideRule, &'a str)>,
    },
    /// A phase ended: its name, seconds (maximum over ranks) and, where it
    /// has one, the global count of what it made.
    Phase {
        /// `read`, `construct`, `refine`, `partition`, `balance`,
        /// `coarsen`, `adapt`, `classify`, `leak_check`, `ghost`, `nodes`, `numbering`,
        /// `connectivity` or `write`.
        name: &'a str,
        /// Seconds, maximum over ranks.
        seconds: f64,
        /// Leaves, nodes or elements after the phase, over all ranks.
        count: Option<u64>,
    },
    /// The winding-number rule oriented and capped the surface.
    Winding(&'a WindingSummary),
    /// Leaves per class over all ranks: inside, outside, cut.
    LeafClasses([u64; 3]),
    /// The leak check ended.
    LeakChecked {
        /// The point given as inside.
        point: [f64; 3],
        /// The length of the leak's path, `None` when sealed off.
        path_octants: Option<usize>,
        /// Seconds of the check.
        seconds: f64,
        /// Where the path was written.
        written: Option<&'a Path>,
    },
    /// The mesh is built.
    Meshed {
        /// Global counts.
        counts: MeshCounts,
    },
    /// The mesh's zones ([`crate::mesh::zones`]): each name with its
    /// elements over all ranks, in zone order.
    Zones(&'a [(String, u64)]),
    /// The volume of the kept elements, after meshing and again after
    /// snapping, beside the volume they should fill.
    KeptVolume {
        /// Volume of the kept elements, user units: of the moved elements
        /// when `snapped`, else of the octree's cubes.
        kept: f64,
        /// What the kept elements should fill, user units.
        expected: f64,
        /// What `expected` is.
        reference: VolumeReference,
        /// Whether the mesh was snapped.
        snapped: bool,
    },
    /// The mesh's quality was measured.
    Quality(&'a Quality),
    /// The mesh was snapped to the surface.
    Snapped(&'a crate::mesh::snap::SnapReport),
    /// The OpenFOAM case got boundary layers: per wall patch, what they
    /// came to.
    Layers(&'a crate::io::openfoam::LayerReport),
    /// The mesh was gathered for a single-file writer: the sizes of its
    /// pieces joined through faces, largest first
    /// ([`crate::mesh::pieces`]). More than one piece
    /// leaves a finite-element solver's stiffness singular unless every
    /// piece is held.
    Pieces(&'a [u64]),
    /// The conforming mesh was built ([`crate::mesh::conforming`]).
    Conforming {
        /// Its hexahedra.
        hexahedra: u64,
        /// The hanging-node mesh's elements of the same region.
        elements: u64,
        /// Macro cells the closure split where no template fits: each
        /// makes the mesh finer than the octree there.
        refined: u64,
    },
    /// A file was written.
    Wrote(&'a Path),
    /// The run ended.
    Finished {
        /// Sum of the phases' seconds.
        seconds: f64,
        /// Peak resident memory, bytes, maximum over ranks.
        peak_rss: u64,
        /// Peak memory of all ranks per balanced leaf.
        bytes_per_leaf: f64,
    },
}

/// Receives a session's events.
pub trait Observer {
    /// Called on every rank for every event.
    fn event(&mut self, e: &Event<'_>);
}

/// An observer that ignores everything.
#[derive(Clone, Copy, Debug, Default)]
pub struct Silent;

impl Observer for Silent {
    fn event(&mut self, _: &Event<'_>) {}
}

/// What the kept elements of a mesh should fill, for the run's summary.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VolumeReference {
    /// A solid: the volume the surface encloses.
    Body,
    /// A fluid: the domain less the volume the surface encloses (exact for
    /// a body inside the domain).
    DomainLessBody,
    /// Every leaf kept: the domain's volume.
    Domain,
}

impl VolumeReference {
    /// The reference for a mesh that keeps `keep`.
    pub fn of(keep: crate::classify::Keep) -> VolumeReference {
        match keep {
            crate::classify::Keep::Inside => VolumeReference::Body,
            crate::classify::Keep::Outside => VolumeReference::DomainLessBody,
            crate::classify::Keep::All => VolumeReference::Domain,
        }
    }

    /// The expected volume from the domain's and the body's.
    pub fn volume(self, domain: f64, body: f64) -> f64 {
        match self {
            VolumeReference::Body => body,
            VolumeReference::DomainLessBody => domain - body,
            VolumeReference::Domain => domain,
        }
    }

    /// Words for the summary line.
    pub fn describe(self) -> &'static str {
        match self {
            VolumeReference::Body => "the body's volume",
            VolumeReference::DomainLessBody => "the domain less the body",
            VolumeReference::Domain => "the domain's volume",
        }
    }
}
