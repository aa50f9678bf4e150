//! The distributed trilinear hexahedral mesh of a balanced octree.
//!
//! [`Mesh::build`] follows the seed paper's Algorithm 4: exchange the ghost
//! layer ([`crate::ghost`]), find the nodes and which of them hang
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
//! `[owned independent | other independent | hanging]`. Owned nodes have the
//! global numbers `first_global..first_global + num_owned`, in the order the
//! dual traversal meets them (a space-filling order, deterministic for a
//! given partition); the other independent nodes are sorted by global
//! number; hanging nodes follow in traversal order. The owner of a node is
//! the lowest rank using it (directly or through a hanging dependency).
//!
//! # Orderings and units
//!
//! Elements are in Morton order. [`Mesh::connectivity`] lists an element's 8
//! local nodes in VTK hexahedron order: the bottom face (lowest z)
//! counter-clockwise seen from above starting at the lowest corner, then the
//! top face in the same order. Coordinates are in the user's units (through
//! the [`Domain`]); lattice coordinates are also available.

pub(crate) mod dual;
pub(crate) mod numbering;

use crate::classify::{keeps, CutRule, Keep, LeafClass};
use crate::comm::{Comm, Traffic};
use crate::domain::Domain;
use crate::error::{Error, ErrorKind, Result};
use crate::ghost::{build_ghost_layer, GhostLayer};
use crate::octant::{Connectivity, Octant};
use crate::octree::LinearOctree;
use crate::report::PhaseTimer;

use dual::UNSET;

/// VTK hexahedron corner `v` is Morton corner `VTK_TO_MORTON[v]`
/// (Morton corner bits: x, y, z).
pub const VTK_TO_MORTON: [usize; 8] = [0, 1, 3, 2, 4, 5, 7, 6];

/// What [`Mesh::build`] keeps.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MeshOptions {
    /// Which leaves become elements.
    pub keep: Keep,
    /// What happens to leaves touching the surface when keeping inside or
    /// outside.
    pub cut_rule: CutRule,
}

impl Default for MeshOptions {
    fn default() -> Self {
        MeshOptions {
            keep: Keep::All,
            cut_rule: CutRule::Center,
        }
    }
}

/// A node constrained by 2 or 4 independent nodes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HangingNode {
    /// Local indices of the independent nodes it depends on; an
    /// edge-hanging node has only two, and `u32::MAX` in the last two
    /// entries (16 bytes per node instead of 20 with a separate count).
    deps: [u32; 4],
}

impl HangingNode {
    /// A constraint on the given 2 or 4 independent nodes.
    pub fn new(deps: &[u32]) -> HangingNode {
        assert!(deps.len() == 2 || deps.len() == 4, "2 or 4 dependencies");
        let mut d = [u32::MAX; 4];
        d[..deps.len()].copy_from_slice(deps);
        HangingNode { deps: d }
    }

    /// 2 for an edge-hanging node (weights 1/2), 4 for a face-hanging one
    /// (weights 1/4).
    pub fn count(&self) -> usize {
        if self.deps[2] == u32::MAX {
            2
        } else {
            4
        }
    }

    /// The nodes it depends on.
    pub fn deps(&self) -> &[u32] {
        &self.deps[..self.count()]
    }

    /// The weight of each dependency.
    pub fn weight(&self) -> f64 {
        1.0 / self.count() as f64
    }
}

/// Global sizes of a mesh, the same on every rank.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
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
}

/// One rank's part of the mesh. See the module documentation.
#[derive(Debug)]
pub struct Mesh {
    rank: usize,
    size: usize,
    domain: Domain,
    elements: Vec<Octant>,
    element_class: Vec<u8>,
    connectivity: Vec<[u32; 8]>,
    node_lattice: Vec<[u32; 3]>,
    num_owned: usize,
    num_independent: usize,
    /// Global numbers of the independent nodes this rank does not own
    /// (owned ones are `first_global + i`).
    other_global: Vec<u64>,
    /// Owners of the independent nodes this rank does not own.
    other_owner: Vec<u32>,
    hanging: Vec<HangingNode>,
    shared_nodes: Vec<u32>,
    shared_offsets: Vec<u32>,
    shared_ranks: Vec<u32>,
    first_global: u64,
    counts: MeshCounts,
    timings: Vec<(String, f64)>,
    traffic: Vec<(String, Traffic)>,
}

impl Mesh {
    /// Builds the mesh of `tree`, which must be balanced for edge or corner
    /// contacts. `classes` holds each local leaf's class byte (from
    /// [`crate::classify::classify_leaves`]); without it every leaf counts
    /// as outside and only [`Keep::All`] is allowed. Collective; any rank's
    /// error is returned on every rank.
    pub fn build(
        tree: &LinearOctree,
        domain: &Domain,
        classes: Option<&[u8]>,
        opts: &MeshOptions,
    ) -> Result<Mesh> {
        let comm: &dyn Comm = &**tree.comm();
        let check = check_inputs(tree, classes, opts);
        crate::comm::agree(comm, check)?;
        let mut timer = PhaseTimer::new();
        let unclassified;
        let local_class: &[u8] = match classes {
            Some(c) => c,
            None => {
                unclassified = vec![LeafClass::Outside as u8; tree.local_len()];
                &unclassified
            }
        };
        let keep = |bits: u8| keeps(opts.keep, opts.cut_rule, bits);

        let ghosts = timer.time(comm, "ghost", || build_ghost_layer(tree, local_class));

        let nodes_phase = timer.time(comm, "nodes", || {
            // Merged run: ghosts of lower ranks, local leaves, the rest.
            let local = tree.leaves();
            let nl = local.len();
            let b = ghosts.before;
            let mut merged = Vec::with_capacity(nl + ghosts.len());
            merged.extend_from_slice(&ghosts.leaves[..b]);
            merged.extend_from_slice(local);
            merged.extend_from_slice(&ghosts.leaves[b..]);
            let mut kept = Vec::with_capacity(merged.len());
            kept.extend(ghosts.data[..b].iter().map(|&c| keep(c)));
            kept.extend(local_class.iter().map(|&c| keep(c)));
            kept.extend(ghosts.data[b..].iter().map(|&c| keep(c)));
            let d = dual::extract_nodes(&merged, &kept);
            let local_range = b..b + nl;
            let counted = count_hanging(comm, tree.first_cells(), &d, &merged);
            (d, local_range, kept, counted)
        });
        let (d, local_range, kept, (face_hanging, edge_hanging)) = nodes_phase;
        let leaf_at = |i: usize| merged_leaf(&ghosts, tree.leaves(), i);

        let (used, slot, numbering) = timer.time(comm, "numbering", || {
            let used = used_nodes(&d, &local_range, &kept);
            // slot[n]: the index of used independent node n among them.
            let mut slot = vec![UNSET; d.num_nodes()];
            let mut ni = 0u32;
            for (n, s) in slot.iter_mut().enumerate() {
                if used[n] && d.kind[n] == 0 {
                    *s = ni;
                    ni += 1;
                }
            }
            let mut icoords = vec![[0u32; 3]; ni as usize];
            d.scatter_coords(leaf_at, &kept, &slot, &mut icoords);
            let numbering = numbering::number_nodes(comm, tree.first_cells(), &icoords);
            (used, slot, numbering)
        });
        let numbering = crate::comm::agree(comm, numbering)?;

        let mesh = timer.time(comm, "connectivity", || {
            assemble(
                tree,
                domain,
                d,
                leaf_at,
                &local_range,
                &kept,
                local_class,
                used,
                slot,
                numbering,
            )
        });
        let mut mesh = crate::comm::agree(comm, mesh)?;
        let with_hanging = mesh
            .connectivity
            .iter()
            .filter(|c| c.iter().any(|&n| n as usize >= mesh.num_independent))
            .count();
        let mut sums = [
            mesh.elements.len() as u64,
            face_hanging,
            edge_hanging,
            with_hanging as u64,
            ghosts.len() as u64,
        ];
        comm.sum_u64(&mut sums);
        mesh.counts.elements = sums[0];
        mesh.counts.face_hanging_nodes = sums[1];
        mesh.counts.edge_hanging_nodes = sums[2];
        mesh.counts.elements_with_hanging = sums[3];
        mesh.counts.ghosts = sums[4];
        mesh.timings = timer.phases().to_vec();
        mesh.traffic = timer.traffic().to_vec();
        Ok(mesh)
    }

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
        &self.timings
    }

    /// Bytes this rank exchanged with other ranks in each of the phases of
    /// [`Mesh::timings`] (rank-local, see [`crate::comm::Traffic`]).
    pub fn traffic(&self) -> &[(String, Traffic)] {
        &self.traffic
    }

    /// The local elements, in Morton order.
    pub fn elements(&self) -> &[Octant] {
        &self.elements
    }

    /// Class of each local element ([`LeafClass`] as a byte).
    pub fn element_class(&self) -> &[u8] {
        &self.element_class
    }

    /// The 8 local node indices of each local element, VTK hexahedron order.
    pub fn connectivity(&self) -> &[[u32; 8]] {
        &self.connectivity
    }

    /// Number of local nodes (independent and hanging).
    pub fn num_nodes(&self) -> usize {
        self.node_lattice.len()
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

    /// Hanging nodes: entry `k` is local node `num_independent() + k`.
    pub fn hanging(&self) -> &[HangingNode] {
        &self.hanging
    }

    /// Lattice coordinates of each local node.
    pub fn node_lattice(&self) -> &[[u32; 3]] {
        &self.node_lattice
    }

    /// Coordinates of local node `i` in user units.
    pub fn node_coordinates(&self, i: usize) -> [f64; 3] {
        let q = self.node_lattice[i];
        self.domain
            .from_lattice([q[0] as f64, q[1] as f64, q[2] as f64])
    }

    /// Coordinates of all local nodes in user units.
    pub fn coordinates(&self) -> Vec<[f64; 3]> {
        (0..self.num_nodes())
            .map(|i| self.node_coordinates(i))
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
        let h = self.domain.side / crate::octant::ROOT_LEN as f64;
        cells as f64 * h * h * h
    }
}

fn check_inputs(tree: &LinearOctree, classes: Option<&[u8]>, opts: &MeshOptions) -> Result<()> {
    match tree.balanced() {
        Some(Connectivity::Edge) | Some(Connectivity::Corner) => {}
        other => {
            let what = other.map_or("not balanced", |c| c.name());
            return Err(Error::new(
                ErrorKind::State,
                format!(
                    "meshing needs an octree balanced for edge or corner contacts (this one is {what}): \
                     with face balance alone a hanging node may depend on another hanging node"
                ),
            ));
        }
    }
    match classes {
        Some(c) if c.len() != tree.local_len() => Err(Error::invalid(format!(
            "{} leaf classes for {} local leaves",
            c.len(),
            tree.local_len()
        ))),
        None if opts.keep != Keep::All => Err(Error::invalid(format!(
            "keeping {} elements needs a surface to classify the leaves",
            opts.keep.name()
        ))),
        _ => Ok(()),
    }
}

/// This rank's share of the face- and edge-hanging nodes: each node is
/// counted by its directory rank, which sees every leaf around it.
fn count_hanging(
    comm: &dyn Comm,
    first_cell: &[u64],
    d: &dual::DualNodes,
    leaves: &[Octant],
) -> (u64, u64) {
    let me = comm.rank();
    let mut c = [0u64; 2];
    for &(n, q, mask) in &d.hanging {
        let x = dual::DualNodes::hanging_coords(leaves[q as usize], mask);
        if numbering::directory_rank(first_cell, x) == me {
            c[if d.kind[n as usize] == 2 { 0 } else { 1 }] += 1;
        }
    }
    (c[0], c[1])
}

/// Nodes this rank uses: corners of its kept elements and what their
/// hanging corners depend on.
fn used_nodes(d: &dual::DualNodes, local: &std::ops::Range<usize>, kept: &[bool]) -> Vec<bool> {
    let mut used = vec![false; d.num_nodes()];
    for i in local.clone() {
        if kept[i] {
            for &n in &d.corners[i] {
                used[n as usize] = true;
            }
        }
    }
    for &(n, q, mask) in &d.hanging {
        if used[n as usize] {
            for c in 0..8 {
                if mask >> c & 1 == 1 {
                    let dep = d.corners[q as usize][c];
                    debug_assert_ne!(dep, UNSET);
                    used[dep as usize] = true;
                }
            }
        }
    }
    used
}

/// Leaf `i` of the merged run (lower ghosts, local leaves, upper ghosts).
fn merged_leaf(ghosts: &GhostLayer, local: &[Octant], i: usize) -> Octant {
    let b = ghosts.before;
    if i < b {
        ghosts.leaves[i]
    } else if i < b + local.len() {
        local[i - b]
    } else {
        ghosts.leaves[i - local.len()]
    }
}

#[allow(clippy::too_many_arguments)]
fn assemble(
    tree: &LinearOctree,
    domain: &Domain,
    mut d: dual::DualNodes,
    leaf_at: impl Fn(usize) -> Octant,
    local_range: &std::ops::Range<usize>,
    kept: &[bool],
    local_class: &[u8],
    used: Vec<bool>,
    slot: Vec<u32>,
    num: numbering::Numbering,
) -> Result<Mesh> {
    let comm: &dyn Comm = &**tree.comm();
    let me = comm.rank() as u32;
    let ni = num.owner.len();
    // Final local order: owned (by global number), other independent (by
    // global number), hanging (in traversal order). Owned nodes are already
    // in global order; the others are few.
    let mut pos = vec![UNSET; ni];
    let mut others: Vec<(u64, u32, u32)> = Vec::new();
    let mut next = 0u32;
    for (k, p) in pos.iter_mut().enumerate() {
        if num.owner[k] == me {
            // Owned numbers are contiguous from first_global, so they are
            // not stored.
            if num.global[k] != num.first_global + next as u64 {
                return Err(Error::new(
                    ErrorKind::Internal,
                    "owned node numbers are not contiguous",
                ));
            }
            *p = next;
            next += 1;
        } else {
            others.push((num.global[k], num.owner[k], k as u32));
        }
    }
    let num_owned = next as usize;
    drop(num.global);
    drop(num.owner);
    others.sort_unstable();
    let mut other_global = Vec::with_capacity(others.len());
    let mut other_owner = Vec::with_capacity(others.len());
    for &(g, o, k) in &others {
        pos[k as usize] = next;
        other_global.push(g);
        other_owner.push(o);
        next += 1;
    }
    drop(others);
    let num_independent = next as usize;

    // slot becomes the new local number of every used node, in place.
    let mut new_of = slot;
    for s in new_of.iter_mut() {
        if *s != UNSET {
            *s = pos[*s as usize];
        }
    }
    let used_hanging = d.hanging.iter().filter(|h| used[h.0 as usize]).count();
    for &(n, _, _) in &d.hanging {
        if used[n as usize] {
            new_of[n as usize] = next;
            next += 1;
        }
    }
    drop(used);
    d.kind = Vec::new();
    // The constraints first: the traversal's list is released before the
    // coordinates are allocated.
    let mut hanging = Vec::with_capacity(used_hanging);
    for &(n, q, mask) in &d.hanging {
        if new_of[n as usize] == UNSET {
            continue;
        }
        let mut deps = [0u32; 4];
        let mut count = 0u8;
        for c in 0..8 {
            if mask >> c & 1 == 1 {
                let dep = new_of[d.corners[q as usize][c] as usize];
                if dep == UNSET || dep as usize >= num_independent {
                    return Err(Error::new(
                        ErrorKind::Internal,
                        "a hanging node depends on a node that is not independent",
                    ));
                }
                deps[count as usize] = dep;
                count += 1;
            }
        }
        hanging.push(HangingNode::new(&deps[..count as usize]));
    }
    d.hanging = Vec::new();
    let mut node_lattice = vec![[0u32; 3]; next as usize];
    d.scatter_coords(&leaf_at, kept, &new_of, &mut node_lattice);

    // The corner table becomes the connectivity in place: local kept leaves
    // move to the front (never past their own slot), renumbered.
    let nkept = kept[local_range.clone()].iter().filter(|&&k| k).count();
    let mut elements = Vec::with_capacity(nkept);
    let mut element_class = Vec::with_capacity(nkept);
    let mut connectivity = d.corners;
    let mut w = 0;
    for (j, i) in local_range.clone().enumerate() {
        if !kept[i] {
            continue;
        }
        elements.push(tree.leaves()[j]);
        element_class.push(LeafClass::from_bits(local_class[j]) as u8);
        let c = connectivity[i];
        connectivity[w] = std::array::from_fn(|v| new_of[c[VTK_TO_MORTON[v]] as usize]);
        w += 1;
    }
    connectivity.truncate(w);
    if w < connectivity.capacity() / 2 {
        connectivity.shrink_to_fit();
    }

    let mut shared_nodes = Vec::with_capacity(num.shared.len());
    let mut order: Vec<(u32, usize)> = num
        .shared
        .iter()
        .enumerate()
        .map(|(s, &k)| (pos[k as usize], s))
        .collect();
    order.sort_unstable();
    let mut shared_offsets = vec![0u32];
    let mut shared_ranks = Vec::with_capacity(num.users.len());
    for (n, s) in order {
        shared_nodes.push(n);
        let a = num.user_offsets[s] as usize;
        let b = num.user_offsets[s + 1] as usize;
        shared_ranks.extend_from_slice(&num.users[a..b]);
        shared_offsets.push(shared_ranks.len() as u32);
    }
    Ok(Mesh {
        rank: comm.rank(),
        size: comm.size(),
        domain: *domain,
        elements,
        element_class,
        connectivity,
        node_lattice,
        num_owned,
        num_independent,
        other_global,
        other_owner,
        hanging,
        shared_nodes,
        shared_offsets,
        shared_ranks,
        first_global: num.first_global,
        counts: MeshCounts {
            independent_nodes: num.global_count,
            ..MeshCounts::default()
        },
        timings: Vec::new(),
        traffic: Vec::new(),
    })
}
