//! The snap's options, its report and the constants that tune it.

use serde::Serialize;

/// Default feature angle, degrees: surface edges whose facets' normals
/// differ by more are kept as features.
pub const DEFAULT_FEATURE_ANGLE: f64 = 30.0;
/// Default element layers around the surface nodes that are relaxed.
pub const DEFAULT_LAYERS: u32 = 2;
/// Default relaxation iterations.
pub const DEFAULT_ITERATIONS: u32 = 3;
/// The least scaled Jacobian a corner of a snapped element may have by
/// default: valid elements, as close to the surface as they go.
pub const DEFAULT_MIN_JACOBIAN: f64 = 0.001;
/// The least scaled Jacobian for a finite-volume mesh (an OpenFOAM case):
/// flatter cells put their centres so far from their faces that
/// `checkMesh` finds faces skewer than 4.
pub const FOAM_MIN_JACOBIAN: f64 = 0.1;
/// The fractions of its displacement a surface node may move, in the order
/// they are tried: the first steps back little, as the curvature of a
/// smooth surface only asks for a back-off of the order of the cell size
/// squared over the radius of curvature.
pub const FRACTIONS: [f64; 8] = [1.0, 0.96875, 0.9375, 0.875, 0.75, 0.5, 0.25, 0.0];
/// Steps back of a surface node's displacement before it is left unmoved.
pub const STEPS: u8 = (FRACTIONS.len() - 1) as u8;
/// How near a feature corner or edge (in cells of the node's finest
/// element) a surface node must be to be attracted to it.
pub const FEATURE_REACH: f64 = 0.6;
/// Surface nodes further than this (in cells of the node's finest element)
/// from the surface are not moved.
pub const SURFACE_REACH: f64 = 4.0;
/// A relaxation move shorter than this fraction of the node's cell is
/// not made; the relaxation stops when no node moves.
pub const RELAX_TOLERANCE: f64 = 1e-3;
/// Fixed-point scale of the smoothing's sums: 2^32 per lattice unit.
pub(super) const FIXED: f64 = 4294967296.0;
/// Passes over at least this many nodes or elements are shared with a
/// second thread when the rank has a spare core: below it a thread's
/// start costs more than it saves.
pub(super) const SPLIT_AT: usize = 1 << 15;
/// The pieces such a pass is cut into ([`crate::parallel::cores::map_chunks`]).
pub(super) const CHUNK: usize = 1 << 13;

/// How [`Mesh::snap`](crate::mesh::Mesh::snap) moves the nodes.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SnapOptions {
    /// Surface edges whose facets' normals differ by more than this
    /// (degrees, 0 to 180) are features; 180 keeps none.
    pub feature_angle_deg: f64,
    /// Element layers around the surface nodes whose interior nodes are
    /// relaxed (0: none).
    pub layers: u32,
    /// Relaxation iterations (0: the surface nodes alone, scaled back).
    pub iterations: u32,
    /// The least scaled Jacobian a corner of an element may have after
    /// the snap, in (0, 0.5].
    pub min_jacobian: f64,
}

impl Default for SnapOptions {
    fn default() -> Self {
        SnapOptions {
            feature_angle_deg: DEFAULT_FEATURE_ANGLE,
            layers: DEFAULT_LAYERS,
            iterations: DEFAULT_ITERATIONS,
            min_jacobian: DEFAULT_MIN_JACOBIAN,
        }
    }
}

/// What [`Mesh::snap`](crate::mesh::Mesh::snap) did, over all ranks (each
/// node counted once, by its owner), the same on every rank.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct SnapReport {
    /// Independent nodes on the surface patch.
    pub surface_nodes: u64,
    /// Of those, the ones moved onto the surface.
    pub snapped: u64,
    /// Moved part of the way (a valid position nearer was not found).
    pub partial: u64,
    /// Not moved: no valid position, also on a side of the domain, or no
    /// surface within reach.
    pub unsnapped: u64,
    /// Snapped nodes that went to a feature edge or corner.
    pub feature_nodes: u64,
    /// Interior nodes the relaxation moved.
    pub relaxed_nodes: u64,
    /// Elements that depend on a partly or not snapped surface node.
    pub reported_elements: u64,
    /// The partly snapped nodes by the most wall faces (faces with four
    /// corners on the surface patch) of an element around them: at most
    /// one, two, three or more. Two or three are the staircase's convex
    /// corners.
    pub partial_by_wall_faces: [u64; 3],
    /// The same for the nodes not moved.
    pub unsnapped_by_wall_faces: [u64; 3],
    /// Smallest scaled Jacobian over all elements afterwards.
    pub min_scaled_jacobian: f64,
    /// Relaxation iterations run (they stop early when nothing moves).
    pub iterations: u32,
}
