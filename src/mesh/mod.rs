//! The distributed trilinear hexahedral mesh of a balanced octree.
//!
//! [`Mesh::build`] follows the seed paper's Algorithm 4: exchange the ghost
//! layer ([`crate::octree::ghost`]), find the nodes and which of them hang
//! (`dual`), decide owners and global numbers (`numbering`), and write
//! the element connectivity.
//!
//! # Elements
//!
//! Each kept leaf is one element. Which leaves are kept is decided from each
//! leaf's class (inside, outside or cut, see [`crate::classify`]) by a
//! [`Keep`] selection and a [`CutRule`]; a leaf's class travels with it to
//! the ranks that hold it as a ghost, so every rank agrees.
//!
//! # Nodes
//!
//! Nodes are lattice points that are a corner of a kept element. A node
//! hangs when it lies inside a face (face-hanging) or an edge (edge-hanging)
//! of a coarser kept element; its value is then the mean of that face's 4
//! corners (weights 1/4) or that edge's 2 ends (weights 1/2), which are
//! always independent on an edge- or corner-balanced octree. Hanging is
//! decided among kept elements: a node on the face of a dropped coarse leaf
//! is independent, since no element there asks for continuity.
//!
//! Each rank numbers its nodes locally as
//! `[owned independent | other independent | face-hanging | edge-hanging]`.
//! Owned nodes have the global numbers `first_global..first_global +
//! num_owned`, in the order the dual traversal meets them (a space-filling
//! order, deterministic for a given partition); the other independent nodes
//! are sorted by global number; hanging nodes follow in traversal order,
//! face-hanging first. The owner of a node is the lowest rank using it
//! (directly or through a hanging dependency). Only nodes that a leaf of
//! another rank touches (or that such a hanging node depends on) can have
//! another user, so only those are exchanged.
//!
//! # Memory
//!
//! A mesh stores the connectivity (32 bytes per element), each hanging
//! node's coarse element and which of its corners it depends on (5 bytes,
//! see `hanging`; the explicit lists are made on request), a class byte
//! per element, and the numbers and sharers of the
//! nodes on partition boundaries. The elements are the octree's own leaves
//! when all are kept (shared, not copied). Node coordinates are not stored:
//! [`Mesh::node_lattice`] and [`Mesh::coordinates`] compute them from the
//! elements' corners. A snapped mesh ([`snap`]) stores its moved positions,
//! 24 bytes per local node.
//!
//! # Orderings and units
//!
//! Elements are in Morton order. [`Mesh::connectivity`] lists an element's 8
//! local nodes in VTK hexahedron order: the bottom face (lowest z)
//! counter-clockwise seen from above starting at the lowest corner, then the
//! top face in the same order. Coordinates are in the user's units (through
//! the [`Domain`]); lattice coordinates are also available.

pub mod boundary;
mod build;
pub mod conforming;
pub(crate) mod dual;
pub mod faces;
pub(crate) mod hanging;
pub mod hexahedra;
mod locate;
pub mod manifold;
pub(crate) mod numbering;
pub mod patches;
pub mod pieces;
pub mod points;
pub mod quality;
pub mod snap;
pub mod transfer;
pub mod zones;

use crate::classify::{CutRule, Keep};
use crate::octree::domain::Domain;
use crate::octree::octant::Octant;
use crate::parallel::comm::Traffic;
use crate::run::report::PhaseTimer;

use std::sync::Arc;
use std::sync::OnceLock;

pub use crate::geometry::cells::VTK_TO_MORTON;
pub use boundary::{Boundary, BoundaryFace};
pub use faces::{CellHalo, Face, Faces, Halo, Other, NUM_PATCHES, SIDE_PATCHES, SURFACE_PATCH};
pub use hanging::HangingDeps;
pub use locate::locate_elements;
pub use transfer::{transfer_elements, transfer_nodes, ElementMap};
pub use zones::Zones;

use hanging::Hanging;

/// What [`Mesh::build`] keeps.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MeshOptions {
    /// Which leaves become elements.
    pub keep: Keep,
    /// What happens to leaves touching the surface when keeping inside or
    /// outside.
    pub cut_rule: CutRule,
    /// Drop the kept leaves that make the walls non-manifold or have kept
    /// neighbours along fewer than three axes ([`manifold`]), as a
    /// finite-volume code wants. With [`Keep::All`] every leaf stays, and
    /// the clean-up applies to the inside side of the zones' interface
    /// instead ([`zones`]): the inside leaves it drops count as outside.
    pub clean_walls: bool,
}

impl Default for MeshOptions {
    fn default() -> Self {
        MeshOptions {
            keep: Keep::All,
            cut_rule: CutRule::Center,
            clean_walls: false,
        }
    }
}

/// The local elements: the octree's own leaves when every one is kept
/// (shared, not copied), else the kept ones.
#[derive(Debug)]
enum Elements {
    Shared(Arc<Vec<Octant>>),
    Own(Vec<Octant>),
}

impl std::ops::Deref for Elements {
    type Target = [Octant];
    fn deref(&self) -> &[Octant] {
        match self {
            Elements::Shared(v) => v,
            Elements::Own(v) => v,
        }
    }
}

/// Global sizes of a mesh, the same on every rank.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct MeshCounts {
    /// Elements over all ranks.
    pub elements: u64,
    /// Independent nodes over all ranks (each counted once).
    pub independent_nodes: u64,
    /// Face-hanging nodes over all ranks (each counted once).
    pub face_hanging_nodes: u64,
    /// Edge-hanging nodes over all ranks (each counted once).
    pub edge_hanging_nodes: u64,
    /// Elements with at least one hanging corner.
    pub elements_with_hanging: u64,
    /// Ghost leaves over all ranks.
    pub ghosts: u64,
    /// Leaves the selection kept but the wall clean-up dropped
    /// ([`MeshOptions::clean_walls`]; with [`Keep::All`], the inside leaves
    /// it moved to the outside).
    pub cleaned: u64,
}

/// One rank's part of the mesh. See the module documentation.
#[derive(Debug)]
pub struct Mesh {
    rank: usize,
    size: usize,
    domain: Domain,
    elements: Elements,
    /// Class of each element (made on first request when every element
    /// has `uniform_class`).
    element_class: OnceLock<Vec<u8>>,
    uniform_class: u8,
    connectivity: Vec<[u32; 8]>,
    num_owned: usize,
    num_independent: usize,
    /// Global numbers of the independent nodes this rank does not own
    /// (owned ones are `first_global + i`).
    other_global: Vec<u64>,
    /// Owners of the independent nodes this rank does not own.
    other_owner: Vec<u32>,
    /// The hanging nodes' dependencies, by their coarse elements.
    hanging: Hanging,
    // Independent nodes that are no local element's corner (only a
    // dependency of a hanging corner), with their lattice points, by node.
    dep_only: Vec<(u32, [u32; 3])>,
    shared_nodes: Vec<u32>,
    shared_offsets: Vec<u32>,
    shared_ranks: Vec<u32>,
    first_global: u64,
    /// Global number of local element 0.
    first_element: u64,
    /// The octree partition's first finest cell of each rank, with the
    /// total appended ([`LinearOctree::first_cells`]).
    first_cells: Vec<u64>,
    /// Kept elements of other ranks touching local ones.
    halo: Halo,
    /// The node walk's pointer tree over the elements and the halo, walked
    /// again for the faces.
    dual_tree: dual::DualTree,
    counts: MeshCounts,
    /// Time, traffic, time inside collectives and peak memory per phase.
    timer: PhaseTimer,
    /// Node positions in user units after [`Mesh::snap`], one per local
    /// node; `None` while the nodes are where the octree put them.
    moved: Option<Vec<[f64; 3]>>,
    /// The same in lattice units (what the midpoints of the faces' corners
    /// are computed from).
    moved_lattice: Option<Vec<[f64; 3]>>,
    /// The zone of each element, when assigned ([`zones`]).
    zones: Option<Zones>,
    /// Whether each element's centre is inside the surface, a bit per
    /// element (meshes of every leaf with classes; empty otherwise).
    centre_inside: Vec<u64>,
}

impl Mesh {
    /// This rank.
    pub fn rank(&self) -> usize {
        self.rank
    }

    /// Number of ranks.
    pub fn size(&self) -> usize {
        self.size
    }

    /// The cube the lattice maps to.
    pub fn domain(&self) -> &Domain {
        &self.domain
    }

    /// Global counts (the same on every rank).
    pub fn counts(&self) -> &MeshCounts {
        &self.counts
    }

    /// Seconds per phase (`ghost`, `nodes`, `numbering`, `connectivity`),
    /// each the maximum over ranks.
    pub fn timings(&self) -> &[(String, f64)] {
        self.timer.phases()
    }

    /// Bytes this rank exchanged with other ranks in each of the phases of
    /// [`Mesh::timings`] (rank-local, see [`crate::parallel::comm::Traffic`]).
    pub fn traffic(&self) -> &[(String, Traffic)] {
        self.timer.traffic()
    }

    /// Seconds this rank spent inside collectives in each of the phases of
    /// [`Mesh::timings`] (rank-local, see [`crate::parallel::comm::Comm::comm_seconds`]).
    pub fn comm_seconds(&self) -> &[(String, f64)] {
        self.timer.waits()
    }

    /// This rank's peak resident set size (bytes) at the end of each phase
    /// of [`Mesh::build`].
    pub fn peaks(&self) -> &[(String, u64)] {
        self.timer.peaks()
    }

    /// Everything [`Mesh::build`] measured, per phase, to merge into a
    /// caller's timer ([`PhaseTimer::append`]).
    pub fn phase_timer(&self) -> &PhaseTimer {
        &self.timer
    }

    /// The local elements, in Morton order.
    pub fn elements(&self) -> &[Octant] {
        &self.elements
    }

    /// Class of each local element ([`crate::classify::LeafClass`] as a byte).
    pub fn element_class(&self) -> &[u8] {
        self.element_class
            .get_or_init(|| vec![self.uniform_class; self.elements.len()])
    }

    /// The 8 local node indices of each local element, VTK hexahedron order.
    pub fn connectivity(&self) -> &[[u32; 8]] {
        &self.connectivity
    }

    /// Number of local nodes (independent and hanging).
    pub fn num_nodes(&self) -> usize {
        self.num_independent + self.num_hanging()
    }

    /// Local nodes `0..num_owned()` are owned by this rank.
    pub fn num_owned(&self) -> usize {
        self.num_owned
    }

    /// Local nodes `0..num_independent()` are independent, the rest hang.
    pub fn num_independent(&self) -> usize {
        self.num_independent
    }

    /// Global number of local node 0 (this rank's first owned node).
    pub fn first_global(&self) -> u64 {
        self.first_global
    }

    /// Global number of independent local node `i` (`i < num_independent()`).
    /// Owned nodes are numbered `first_global() + i`, so only the others'
    /// numbers are stored.
    pub fn global_id(&self, i: usize) -> u64 {
        if i < self.num_owned {
            self.first_global + i as u64
        } else {
            self.other_global[i - self.num_owned]
        }
    }

    /// Owner rank of independent local node `i` (`i < num_independent()`).
    pub fn owner(&self, i: usize) -> u32 {
        if i < self.num_owned {
            self.rank as u32
        } else {
            self.other_owner[i - self.num_owned]
        }
    }

    /// Global numbers of all independent local nodes (a new vector).
    pub fn global_ids(&self) -> Vec<u64> {
        (0..self.num_independent)
            .map(|i| self.global_id(i))
            .collect()
    }

    /// Owner ranks of all independent local nodes (a new vector).
    pub fn owners(&self) -> Vec<u32> {
        (0..self.num_independent).map(|i| self.owner(i)).collect()
    }

    /// Number of hanging local nodes: the face-hanging ones, then the
    /// edge-hanging ones.
    pub fn num_hanging(&self) -> usize {
        self.hanging.len()
    }

    /// Number of face-hanging local nodes (the first hanging ones).
    pub fn num_face_hanging(&self) -> usize {
        self.hanging.num_face()
    }

    /// Face-hanging nodes: entry `k` is local node `num_independent() + k`,
    /// the mean of the 4 independent local nodes given (weights 1/4). The
    /// mesh stores each hanging node by its coarse element; this list (16
    /// bytes per node) is made on the first call.
    pub fn face_hanging(&self) -> &[[u32; 4]] {
        self.hanging.face_lists(&self.connectivity)
    }

    /// Edge-hanging nodes: entry `k` is local node `num_independent() +
    /// num_face_hanging() + k`, the mean of the 2 independent local nodes
    /// given (weights 1/2). Made on the first call, like
    /// [`Mesh::face_hanging`].
    pub fn edge_hanging(&self) -> &[[u32; 2]] {
        self.hanging.edge_lists(&self.connectivity)
    }

    /// The independent local nodes hanging node `k` (local node
    /// `num_independent() + k`) is the mean of: 4 for a face-hanging node,
    /// 2 for an edge-hanging one, in the Morton order of the coarse
    /// element's corners. Read from the coarse element's connectivity, not
    /// stored.
    pub fn hanging_deps(&self, k: usize) -> HangingDeps {
        self.hanging.deps(k, &self.connectivity)
    }

    /// Lattice coordinates of each local node (a new vector: they are not
    /// stored, but recovered from the elements' corners).
    pub fn node_lattice(&self) -> Vec<[u32; 3]> {
        let mut out = vec![[0u32; 3]; self.num_nodes()];
        self.for_each_corner(|n, x| out[n as usize] = x);
        for &(n, x) in &self.dep_only {
            out[n as usize] = x;
        }
        out
    }

    /// The independent nodes that are no local element's corner, only a
    /// dependency of a hanging corner (at partition boundaries), in
    /// increasing order: no face of a local element has them.
    pub(crate) fn dependency_only_nodes(&self) -> impl Iterator<Item = u32> + '_ {
        self.dep_only.iter().map(|&(n, _)| n)
    }

    /// [`Mesh::hanging_deps`] of every hanging node, in order, the coarse
    /// elements' rows fetched ahead.
    pub(crate) fn all_hanging_deps(&self) -> impl Iterator<Item = HangingDeps> + '_ {
        self.hanging
            .deps_in(0..self.hanging.len(), &self.connectivity)
    }

    /// The hanging nodes found by the nodes they depend on (a new index).
    pub(crate) fn hanging_index(&self) -> hanging::DepsIndex {
        hanging::DepsIndex::new(&self.hanging, &self.connectivity, self.num_independent())
    }

    /// Calls `f(node, lattice point)` at every corner of every local
    /// element (a node once per element that has it; the nodes that are
    /// only a dependency never), each element's anchor decoded once.
    pub(crate) fn for_each_corner(&self, f: impl FnMut(u32, [u32; 3])) {
        self.for_each_corner_in(0..self.elements.len(), f);
    }

    /// [`Mesh::for_each_corner`] for the local elements of `range`.
    pub(crate) fn for_each_corner_in(
        &self,
        range: std::ops::Range<usize>,
        mut f: impl FnMut(u32, [u32; 3]),
    ) {
        for (e, c) in self.elements[range.clone()]
            .iter()
            .zip(&self.connectivity[range])
        {
            let (a, s) = (e.coords(), e.side());
            for (v, &n) in c.iter().enumerate() {
                f(n, dual::corner_coords(a, s, VTK_TO_MORTON[v]));
            }
        }
    }

    /// Coordinates of all local nodes in user units (a new vector): the
    /// moved positions after [`Mesh::snap`], else the lattice points.
    pub fn coordinates(&self) -> Vec<[f64; 3]> {
        if let Some(m) = &self.moved {
            return m.clone();
        }
        self.lattice_coordinates()
    }

    /// The moved node positions (user units, one per local node) when the
    /// mesh was snapped ([`Mesh::snap`]).
    pub fn moved(&self) -> Option<&[[f64; 3]]> {
        self.moved.as_deref()
    }

    /// Coordinates of all local nodes in user units where the octree puts
    /// them, whether or not the mesh was snapped (a new vector).
    pub fn lattice_coordinates(&self) -> Vec<[f64; 3]> {
        self.node_lattice()
            .into_iter()
            .map(|q| {
                self.domain
                    .from_lattice([q[0] as f64, q[1] as f64, q[2] as f64])
            })
            .collect()
    }

    /// The ranks using independent local node `i` (sorted, this rank
    /// included). A node is shared when there is more than one.
    pub fn sharers(&self, i: usize) -> Vec<u32> {
        match self.shared_nodes.binary_search(&(i as u32)) {
            Ok(k) => {
                let a = self.shared_offsets[k] as usize;
                let b = self.shared_offsets[k + 1] as usize;
                self.shared_ranks[a..b].to_vec()
            }
            Err(_) => vec![self.rank as u32],
        }
    }

    /// The independent local nodes used by more than one rank, increasing.
    pub fn shared_nodes(&self) -> &[u32] {
        &self.shared_nodes
    }

    /// For each other rank sharing nodes with this one, the shared local
    /// nodes ordered by global number: both ranks list the same nodes in
    /// the same order, ready for a halo exchange.
    pub fn exchange_lists(&self) -> Vec<(u32, Vec<u32>)> {
        let mut lists: Vec<Vec<u32>> = vec![Vec::new(); self.size];
        for (k, &n) in self.shared_nodes.iter().enumerate() {
            let a = self.shared_offsets[k] as usize;
            let b = self.shared_offsets[k + 1] as usize;
            for &r in &self.shared_ranks[a..b] {
                if r as usize != self.rank {
                    lists[r as usize].push(n);
                }
            }
        }
        lists
            .into_iter()
            .enumerate()
            .filter(|(_, l)| !l.is_empty())
            .map(|(r, mut l)| {
                l.sort_unstable_by_key(|&n| self.global_id(n as usize));
                (r as u32, l)
            })
            .collect()
    }

    /// Volume of the local elements in finest lattice cells (exact; the
    /// root is `8^19` cells).
    pub fn local_volume_cells(&self) -> u64 {
        self.elements.iter().map(|e| (e.side() as u64).pow(3)).sum()
    }

    /// A volume in finest lattice cells converted to user units.
    pub fn cells_to_volume(&self, cells: u64) -> f64 {
        let h = self.domain.side / crate::octree::octant::ROOT_LEN as f64;
        cells as f64 * h * h * h
    }
}

/// Asks the processor to bring `v[i]` into cache (a hint: no effect past
/// the end, nor on other targets). The mesh's passes over elements read
/// their nodes' and neighbours' entries all over arrays in another order.
#[inline(always)]
pub(crate) fn prefetch<T>(v: &[T], i: usize) {
    #[cfg(target_arch = "x86_64")]
    if i < v.len() {
        // SAFETY: the pointer is inside `v`; a prefetch reads nothing the
        // program sees and cannot fault.
        unsafe {
            use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            _mm_prefetch::<_MM_HINT_T0>(v.as_ptr().add(i).cast::<i8>());
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (v, i);
}
