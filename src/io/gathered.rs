//! The whole mesh on rank 0, numbered the same way on any number of ranks,
//! for the single-file finite-element writers ([`super::gmsh`],
//! [`super::abaqus`], [`super::exodus`], [`super::cgns`]).
//!
//! Nodes are numbered by first use: the independent nodes in the order the
//! elements, in global (Morton) element order, first list them, then the
//! hanging nodes the same way. Global element order and lattice points do
//! not depend on the partition, and neither do snapped positions
//! ([`crate::mesh::snap`]), so the numbering and every written byte are
//! the same on any number of ranks. (The mesh's own global node numbers do
//! depend on the partition: an owner numbers its nodes in its own
//! traversal order.)
//!
//! The ranks number the nodes in parallel ([`gather`]): each numbers the
//! nodes whose first use is one of its elements, and sends rank 0 its
//! elements' corners in the final numbers, those nodes' positions and
//! dependencies, and its boundary faces, as plain integer buffers. Rank 0
//! only copies them into place.
//!
//! Rank 0 holds the whole mesh: about 100 bytes per node and 70 per
//! element with the buffers it receives. That bounds the size of meshes
//! these files suit.

use crate::error::{Error, Result};
use crate::geometry::hash::FoldMap;
pub use crate::mesh::hexahedra::{match_faces, MatchedFaces, ABAQUS_FACE, ABAQUS_FACE_NODES};
use crate::mesh::points::{halo_corners, point_key};
use crate::mesh::{Boundary, Mesh};
use crate::parallel::comm::Comm;

/// A boundary face of the gathered mesh.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct GatheredFace {
    /// The patch.
    pub patch: u16,
    /// The element (0-based global number).
    pub element: u64,
    /// The face's Abaqus label less one (`0..6` for `S1..S6`).
    pub label: u8,
}

/// The nodes a hanging node of a [`Gathered`] mesh is the mean of: 4 for a
/// face-hanging node, 2 for an edge-hanging one. Fixed size, so that a
/// million hanging nodes cost no allocation each.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Parents {
    count: u8,
    nodes: [u32; 4],
}

impl Parents {
    /// The parents `nodes` (at most 4; more are dropped).
    pub fn new(nodes: &[u32]) -> Parents {
        let mut p = Parents::default();
        for (&n, to) in nodes.iter().zip(&mut p.nodes) {
            *to = n;
            p.count += 1;
        }
        p
    }
}

impl std::ops::Deref for Parents {
    type Target = [u32];
    fn deref(&self) -> &[u32] {
        &self.nodes[..self.count as usize]
    }
}

impl<'a> IntoIterator for &'a Parents {
    type Item = &'a u32;
    type IntoIter = std::slice::Iter<'a, u32>;
    fn into_iter(self) -> Self::IntoIter {
        self.iter()
    }
}

/// The whole mesh, on rank 0 (empty elsewhere). Nodes are 0-based: the
/// independent ones `0..num_independent`, then the hanging ones.
#[derive(Clone, Debug, Default)]
pub struct Gathered {
    /// Node positions, user units.
    pub coordinates: Vec<[f64; 3]>,
    /// Nodes below this are independent.
    pub num_independent: usize,
    /// Each element's 8 nodes, VTK hexahedron order, global element order.
    pub elements: Vec<[u32; 8]>,
    /// Hanging node `num_independent + k` is the mean of the nodes
    /// `dependencies[k]` (4 for a face-hanging node, 2 for an edge-hanging
    /// one).
    pub dependencies: Vec<Parents>,
    /// Each patch's nodes (independent and hanging), increasing; one entry
    /// per patch id up to the highest used.
    pub patch_nodes: Vec<Vec<u32>>,
    /// The boundary faces, by patch, element, label.
    pub faces: Vec<GatheredFace>,
    /// The zones' names when the mesh has zones ([`crate::mesh::zones`]),
    /// else empty.
    pub zone_names: Vec<String>,
    /// Each element's zone index, global element order (empty without
    /// zones).
    pub element_zones: Vec<u16>,
    /// The conforming mesh's ([`crate::mesh::conforming`]): per
    /// hexahedron, the octree level (from the root cells) and the class
    /// ([`crate::classify::LeafClass`] as a byte) of the kept leaf its
    /// centre lies in. Empty for the hanging-node mesh.
    pub element_level: Vec<u8>,
    /// See [`Gathered::element_level`].
    pub element_class: Vec<u8>,
}

impl Gathered {
    /// The patches that have boundary faces, increasing.
    pub fn used_patches(&self) -> Vec<u16> {
        let mut p: Vec<u16> = self.faces.iter().map(|f| f.patch).collect();
        p.dedup();
        p
    }
}

#[cfg(test)]
impl Gathered {
    /// The reference for [`crate::mesh::pieces`], counted here on the
    /// gathered mesh: the sizes (elements) of its pieces joined through faces,
    /// largest first: what a solver's stiffness sees. Two elements are
    /// joined when they share a whole face, or when one's face is a
    /// quarter of the other's (a face-hanging node's four dependencies
    /// are the coarse face's corners). Pieces touching only along an edge
    /// or at a corner stay apart: such a joint is a hinge, and the
    /// stiffness is singular unless every piece is held.
    pub fn pieces(&self) -> Vec<u64> {
        let ni = self.num_independent;
        let mut parent: Vec<u32> = (0..self.elements.len() as u32).collect();
        fn root(parent: &mut [u32], mut a: u32) -> u32 {
            while parent[a as usize] != a {
                let up = parent[parent[a as usize] as usize];
                parent[a as usize] = up;
                a = up;
            }
            a
        }
        let mut first: FoldMap<[u32; 4], u32> = FoldMap::default();
        for (e, nodes) in self.elements.iter().enumerate() {
            for face in &ABAQUS_FACE_NODES {
                let corners = face.map(|k| nodes[k]);
                // A quarter of a coarse face: its face-hanging corner
                // names the coarse face.
                let coarse = corners.iter().find_map(|&n| {
                    let d = n.checked_sub(ni as u32)?;
                    let deps = &self.dependencies[d as usize];
                    (deps.len() == 4).then(|| [deps[0], deps[1], deps[2], deps[3]])
                });
                let mut key = coarse.unwrap_or(corners);
                key.sort_unstable();
                match first.get(&key) {
                    Some(&other) => {
                        let (a, b) = (root(&mut parent, other), root(&mut parent, e as u32));
                        parent[a.max(b) as usize] = a.min(b);
                    }
                    None => {
                        first.insert(key, e as u32);
                    }
                }
            }
        }
        let mut size: FoldMap<u32, u64> = FoldMap::default();
        for e in 0..parent.len() as u32 {
            *size.entry(root(&mut parent, e)).or_default() += 1;
        }
        let mut sizes: Vec<u64> = size.into_values().collect();
        sizes.sort_unstable_by(|a, b| b.cmp(a));
        sizes
    }
}

/// The volumes of a gathered mesh as blocks of elements, for the formats
/// that number a block's elements after the previous block's (Exodus II
/// element blocks, CGNS sections): one per zone with elements (ID `zone
/// index + 1`, the zone's name, as the Gmsh file's physical volumes) on a
/// mesh with zones, else one, `volume` with ID 1. The elements are listed
/// block after block, each block in global element order.
pub struct Blocks<'a> {
    /// ID, name and element count of each block.
    pub blocks: Vec<(i32, &'a str, usize)>,
    /// The gathered elements in file order.
    pub order: Vec<u32>,
    /// The file's number (1-based) of each gathered element.
    pub number: Vec<i32>,
}

impl<'a> Blocks<'a> {
    /// The blocks of `g`.
    pub fn of(g: &'a Gathered) -> Blocks<'a> {
        let ne = g.elements.len();
        let zoned = !g.zone_names.is_empty() && g.element_zones.len() == ne;
        if !zoned {
            return Blocks {
                blocks: vec![(1, "volume", ne)],
                order: (0..ne as u32).collect(),
                number: (1..=ne as i32).collect(),
            };
        }
        let mut count = vec![0usize; g.zone_names.len()];
        for &z in &g.element_zones {
            count[z as usize] += 1;
        }
        let mut order: Vec<u32> = (0..ne as u32).collect();
        // Stable: each zone keeps the global element order.
        order.sort_by_key(|&e| g.element_zones[e as usize]);
        let mut number = vec![0i32; ne];
        for (k, &e) in order.iter().enumerate() {
            number[e as usize] = k as i32 + 1;
        }
        let blocks = (g.zone_names.iter().zip(&count).enumerate())
            .filter(|(_, (_, &n))| n > 0)
            .map(|(z, (name, &n))| (z as i32 + 1, name.as_str(), n))
            .collect();
        Blocks {
            blocks,
            order,
            number,
        }
    }
}

/// Sends `local` to rank 0; rank 0 gets every rank's in rank order.
fn to_root(comm: &dyn Comm, local: &[u64]) -> Vec<u64> {
    let mut counts = vec![0usize; comm.size()];
    counts[0] = local.len();
    comm.alltoallv_u64(local, &counts).0
}

/// No number yet.
const NONE: u32 = u32::MAX;
/// Numbered by a lower rank: the number arrives in [`gather`]'s exchange.
const REMOTE: u32 = u32::MAX - 1;

/// Words of [`gather`]'s halo-corner filter (2^20 bits).
const FILTER_WORDS: usize = 1 << 14;

/// The filter bit of point key `k`.
#[inline]
fn filter_bit(k: u64) -> usize {
    (k.wrapping_mul(0x9e37_79b9_7f4a_7c15) >> 44) as usize
}

/// Gathers `mesh` with its `boundary` (this mesh's) on rank 0. Collective;
/// the result is empty on the other ranks.
///
/// Each node is numbered by its *first user*, the lowest rank with an
/// element that has it as a corner (an element of a lower rank with the
/// node as a corner touches the local element there, so it is in the
/// halo). The first user numbers its nodes in the order its elements list
/// them; an exclusive scan of the counts places the independent nodes of
/// every rank before all the hanging ones. The first user sends each
/// number on a partition boundary to the ranks that hold the node: those
/// of the halo elements with it as a corner and, for an independent node,
/// its sharers (which include the ranks that use it only as a hanging
/// node's dependency). Rank 0 then receives the connectivity in the final
/// numbers and each node's position once, from its first user, in order.
pub fn gather(comm: &dyn Comm, mesh: &Mesh, boundary: &Boundary) -> Result<Gathered> {
    let me = comm.rank() as u32;
    let p = comm.size();
    let lattice = mesh.node_lattice();
    let key = |n: usize| point_key(lattice[n]);
    let ni = mesh.num_independent();
    let halo = mesh.halo();
    // The halo elements' corners with their ranks, sorted: a key's first
    // entry has the lowest rank.
    let mut halo_corners: Vec<(u64, u32)> = halo_corners(mesh)
        .enumerate()
        .map(|(i, x)| (point_key(x), halo.owners[i / 8]))
        .collect();
    halo_corners.sort_unstable();
    halo_corners.dedup();
    let mut first: FoldMap<u64, u32> =
        FoldMap::with_capacity_and_hasher(halo_corners.len(), Default::default());
    // A bit per hashed key in front of the map: most nodes are no halo
    // element's corner, and the bits stay in cache.
    let mut filter = vec![0u64; FILTER_WORDS];
    for (i, &(k, _)) in halo_corners.iter().enumerate().rev() {
        first.insert(k, i as u32);
        let b = filter_bit(k);
        filter[b / 64] |= 1 << (b % 64);
    }
    // Number the nodes this rank uses first, in the order its elements
    // list them: independent and hanging ones apart.
    let mut num = vec![NONE; mesh.num_nodes()];
    let mut order: [Vec<u32>; 2] = [Vec::new(), Vec::new()];
    // The nodes numbered here that other ranks hold as corners.
    let mut border: Vec<u32> = Vec::new();
    for c in mesh.connectivity() {
        for &n in c {
            let n = n as usize;
            if num[n] != NONE {
                continue;
            }
            let k = key(n);
            let b = filter_bit(k);
            if filter[b / 64] & 1 << (b % 64) != 0 {
                if let Some(&i) = first.get(&k) {
                    if halo_corners[i as usize].1 < me {
                        num[n] = REMOTE;
                        continue;
                    }
                    border.push(n as u32);
                }
            }
            let list = &mut order[usize::from(n >= ni)];
            num[n] = list.len() as u32;
            list.push(n as u32);
        }
    }
    let counts = [0, 1].map(|h| comm.allgather_u64(order[h].len() as u64));
    let before = |h: usize| counts[h][..me as usize].iter().sum::<u64>();
    let total_independent: u64 = counts[0].iter().sum();
    let total = total_independent + counts[1].iter().sum::<u64>();
    let mut bad = total >= u64::from(REMOTE);
    let offset = [before(0), total_independent + before(1)];
    for h in [0, 1] {
        for &n in &order[h] {
            num[n as usize] += offset[h] as u32;
        }
    }
    // Send the numbers on partition boundaries to the ranks holding them.
    let mut out: Vec<Vec<u64>> = vec![Vec::new(); p];
    for &n in &border {
        let k = key(n as usize);
        let i = first[&k] as usize;
        for &(_, r) in halo_corners[i..].iter().take_while(|e| e.0 == k) {
            out[r as usize].extend([k, u64::from(num[n as usize])]);
        }
    }
    for &n in mesh.shared_nodes() {
        let v = num[n as usize];
        if v < REMOTE {
            let k = key(n as usize);
            for r in mesh.sharers(n as usize) {
                if r != me {
                    out[r as usize].extend([k, u64::from(v)]);
                }
            }
        }
    }
    let sizes: Vec<usize> = out.iter().map(Vec::len).collect();
    let (got, _) = comm.alltoallv_u64(&out.concat(), &sizes);
    drop(out);
    if !got.is_empty() {
        let mut given: FoldMap<u64, u32> =
            FoldMap::with_capacity_and_hasher(got.len() / 2, Default::default());
        for w in got.chunks_exact(2) {
            given.insert(w[0], w[1] as u32);
        }
        for (n, v) in num.iter_mut().enumerate() {
            if *v >= REMOTE {
                match given.get(&key(n)) {
                    Some(&g) => *v = g,
                    // Only a dependency here, and of no node numbered here.
                    None => bad |= *v == REMOTE,
                }
            }
        }
    }
    drop(first);
    drop(halo_corners);
    let number = |n: u32, bad: &mut bool| -> u64 {
        let v = num[n as usize];
        *bad |= u64::from(v) >= total;
        u64::from(v)
    };
    // Elements: 8 numbers in 4 words.
    let mut buf: Vec<u64> = Vec::with_capacity(mesh.connectivity().len() * 4);
    for c in mesh.connectivity() {
        for pair in c.chunks_exact(2) {
            buf.push(number(pair[0], &mut bad) | number(pair[1], &mut bad) << 32);
        }
    }
    let elements = to_root(comm, &buf);
    // The positions of the nodes numbered here, in their order.
    buf.clear();
    let domain = mesh.domain();
    let position = |n: usize| match mesh.moved() {
        Some(m) => m[n],
        None => domain.from_lattice(lattice[n].map(f64::from)),
    };
    for &n in order.iter().flatten() {
        buf.extend(position(n as usize).map(f64::to_bits));
    }
    let positions = to_root(comm, &buf);
    // The hanging nodes' dependencies, 4 numbers in 2 words (NONE after
    // an edge-hanging node's 2).
    buf.clear();
    buf.resize(2 * order[1].len(), 0);
    let hanging_offset = offset[1] as u32;
    for (k, d) in mesh.all_hanging_deps().enumerate() {
        // Only the hanging nodes numbered here are sent, at their places.
        let Some(at) = num[ni + k].checked_sub(hanging_offset) else {
            continue;
        };
        let Some(slot) = buf.get_mut(2 * at as usize..2 * at as usize + 2) else {
            continue;
        };
        let mut w = [u64::from(NONE); 4];
        for (w, &m) in w.iter_mut().zip(d.iter()) {
            *w = number(m, &mut bad);
            bad |= *w >= total_independent;
        }
        slot.copy_from_slice(&[w[0] | w[1] << 32, w[2] | w[3] << 32]);
    }
    let dependencies = to_root(comm, &buf);
    // Patches: (number, patch) of the nodes numbered here, in their order
    // (every rank holding a node gives it the same patches).
    buf.clear();
    for &n in order.iter().flatten() {
        let v = u64::from(num[n as usize]);
        buf.extend(
            boundary
                .node_patches(n as usize)
                .iter()
                .map(|&q| v << 16 | u64::from(q)),
        );
    }
    let patches = to_root(comm, &buf);
    // Faces: global element, label, patch.
    buf.clear();
    let first_element = mesh.first_element();
    for f in boundary.faces() {
        buf.push(first_element + f.element as u64);
        buf.push(ABAQUS_FACE[f.face as usize] as u64);
        buf.push(f.patch as u64);
    }
    let faces = to_root(comm, &buf);
    let zones = mesh.zones().map(|z| {
        let local: Vec<u64> = z.of_elements().iter().map(|&k| u64::from(k)).collect();
        (z.names().to_vec(), to_root(comm, &local))
    });
    if bad {
        return Err(corrupt());
    }
    if comm.rank() != 0 {
        return Ok(Gathered::default());
    }
    let parts = Parts {
        counts: &counts,
        elements: &elements,
        positions: &positions,
        dependencies: &dependencies,
        patches: &patches,
        faces: &faces,
    };
    let mut out = parts.assemble()?;
    if let Some((names, of)) = zones {
        out.zone_names = names;
        out.element_zones = of.into_iter().map(|k| k as u16).collect();
    }
    Ok(out)
}

/// The error of a gather whose pieces do not fit together.
fn corrupt() -> Error {
    Error::io("the gathered mesh is inconsistent (an internal error)")
}

/// What rank 0 received in [`gather`].
struct Parts<'a> {
    /// Independent and hanging nodes numbered by each rank.
    counts: &'a [Vec<u64>; 2],
    elements: &'a [u64],
    positions: &'a [u64],
    dependencies: &'a [u64],
    patches: &'a [u64],
    faces: &'a [u64],
}

impl Parts<'_> {
    /// Rank 0's half of [`gather`]: copies the pieces into place.
    fn assemble(&self) -> Result<Gathered> {
        let [independent, hanging] = self.counts;
        let ni: u64 = independent.iter().sum();
        let nh: u64 = hanging.iter().sum();
        let total = (ni + nh) as usize;
        if self.positions.len() != 3 * total
            || self.dependencies.len() as u64 != 2 * nh
            || !self.elements.len().is_multiple_of(4)
        {
            return Err(corrupt());
        }
        let mut out = Gathered {
            num_independent: ni as usize,
            ..Gathered::default()
        };
        out.elements = self
            .elements
            .chunks_exact(4)
            .map(|w| std::array::from_fn(|v| (w[v / 2] >> (32 * (v % 2))) as u32))
            .collect();
        // Each rank sent its independent nodes' positions, then its
        // hanging ones'.
        out.coordinates = vec![[0.0; 3]; total];
        let (mut at, mut to) = (0, [0, ni as usize]);
        for r in 0..independent.len() {
            for h in [0, 1] {
                let n = self.counts[h][r] as usize;
                let from = &self.positions[3 * at..3 * (at + n)];
                for (x, w) in out.coordinates[to[h]..to[h] + n]
                    .iter_mut()
                    .zip(from.chunks_exact(3))
                {
                    *x = [0, 1, 2].map(|k| f64::from_bits(w[k]));
                }
                at += n;
                to[h] += n;
            }
        }
        out.dependencies = self
            .dependencies
            .chunks_exact(2)
            .map(|w| {
                let d = [
                    w[0] as u32,
                    (w[0] >> 32) as u32,
                    w[1] as u32,
                    (w[1] >> 32) as u32,
                ];
                Parents::new(&d[..if d[2] == NONE { 2 } else { 4 }])
            })
            .collect();
        // The independent nodes of every rank come before the hanging
        // ones: two passes keep each patch's list increasing.
        for hanging in [false, true] {
            for &w in self.patches {
                let (n, q) = ((w >> 16) as u32, (w & 0xffff) as usize);
                if (u64::from(n) >= ni) == hanging {
                    if out.patch_nodes.len() <= q {
                        out.patch_nodes.resize(q + 1, Vec::new());
                    }
                    out.patch_nodes[q].push(n);
                }
            }
        }
        out.faces = self
            .faces
            .chunks_exact(3)
            .map(|f| GatheredFace {
                patch: f[2] as u16,
                element: f[0],
                label: f[1] as u8,
            })
            .collect();
        out.faces.sort_unstable();
        out.faces.dedup();
        Ok(out)
    }
}
