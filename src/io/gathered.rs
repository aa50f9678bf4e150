//! The whole mesh on rank 0, numbered the same way on any number of ranks,
//! for the single-file finite-element writers ([`super::gmsh`],
//! [`super::abaqus`]).
//!
//! Every rank sends rank 0 its elements (the 8 corners of each as lattice
//! point keys, in global element order), its nodes (lattice key, position,
//! the keys of a hanging node's dependencies, the node's patches) and its
//! boundary faces, as plain integer buffers. Rank 0 merges the nodes by
//! lattice point and numbers them by first use: the independent nodes in
//! the order the elements, in global (Morton) element order, first list
//! them, then the hanging nodes the same way. Global element order and
//! lattice points do not depend on the partition, and neither do snapped
//! positions ([`crate::mesh::snap`]), so the numbering and every written
//! byte are the same on any number of ranks. (The mesh's own global node
//! numbers do depend on the partition: an owner numbers its nodes in its
//! own traversal order.)
//!
//! Rank 0 holds the whole mesh: about 150 bytes per node and 40 per
//! element. That bounds the size of meshes these files suit.

use crate::error::{Error, Result};
use crate::geometry::hash::FoldMap;
use crate::mesh::points::point_key;
use crate::mesh::{Boundary, Mesh};
use crate::parallel::comm::Comm;

/// The corners of p4est face `f` (`2 axis + side`) as Abaqus lists them:
/// [`ABAQUS_FACE`]`[f]` is the face's label `S1..S6` less one, and
/// [`ABAQUS_FACE_NODES`] its 4 VTK corners in Abaqus's order.
pub const ABAQUS_FACE: [u8; 6] = [5, 3, 2, 4, 0, 1];

/// The VTK (= Abaqus C3D8 = Gmsh) corners of the hexahedron's faces
/// `S1..S6`: S1 = 1-2-3-4, S2 = 5-8-7-6, S3 = 1-5-6-2, S4 = 2-6-7-3,
/// S5 = 3-7-8-4, S6 = 4-8-5-1 (1-based in Abaqus's manual). Each runs
/// clockwise seen from outside, so its right-hand normal points into the
/// element.
pub const ABAQUS_FACE_NODES: [[usize; 4]; 6] = [
    [0, 1, 2, 3],
    [4, 7, 6, 5],
    [0, 4, 5, 1],
    [1, 5, 6, 2],
    [2, 6, 7, 3],
    [3, 7, 4, 0],
];

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
    pub dependencies: Vec<Vec<u32>>,
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
}

impl Gathered {
    /// The patches that have boundary faces, increasing.
    pub fn used_patches(&self) -> Vec<u16> {
        let mut p: Vec<u16> = self.faces.iter().map(|f| f.patch).collect();
        p.dedup();
        p
    }
}

impl Gathered {
    /// The sizes (elements) of the mesh's pieces joined through faces,
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

/// Gathers `mesh` with its `boundary` (this mesh's) on rank 0. Collective;
/// the result is empty on the other ranks.
pub fn gather(comm: &dyn Comm, mesh: &Mesh, boundary: &Boundary) -> Result<Gathered> {
    let lattice = mesh.node_lattice();
    let keys: Vec<u64> = lattice.iter().map(|&p| point_key(p)).collect();
    let coords = mesh.coordinates();
    let ni = mesh.num_independent();
    // Elements: 8 keys each.
    let mut buf: Vec<u64> = Vec::with_capacity(mesh.connectivity().len() * 8);
    for c in mesh.connectivity() {
        buf.extend(c.iter().map(|&n| keys[n as usize]));
    }
    let elements = to_root(comm, &buf);
    // Nodes: key, x, y, z, deps, dep keys, patches, patch ids.
    buf.clear();
    for n in 0..mesh.num_nodes() {
        buf.push(keys[n]);
        buf.extend(coords[n].iter().map(|x| x.to_bits()));
        if n < ni {
            buf.push(0);
        } else {
            let d = mesh.hanging_deps(n - ni);
            buf.push(d.len() as u64);
            buf.extend(d.iter().map(|&m| keys[m as usize]));
        }
        let p = boundary.node_patches(n);
        buf.push(p.len() as u64);
        buf.extend(p.iter().map(|&x| x as u64));
    }
    let nodes = to_root(comm, &buf);
    // Faces: global element, label, patch.
    buf.clear();
    let first = mesh.first_element();
    for f in boundary.faces() {
        buf.push(first + f.element as u64);
        buf.push(ABAQUS_FACE[f.face as usize] as u64);
        buf.push(f.patch as u64);
    }
    let faces = to_root(comm, &buf);
    let zones = mesh.zones().map(|z| {
        let local: Vec<u64> = z.of_elements().iter().map(|&k| u64::from(k)).collect();
        (z.names().to_vec(), to_root(comm, &local))
    });
    if comm.rank() != 0 {
        return Ok(Gathered::default());
    }
    let mut out = assemble(&elements, &nodes, &faces)?;
    if let Some((names, of)) = zones {
        out.zone_names = names;
        out.element_zones = of.into_iter().map(|k| k as u16).collect();
    }
    Ok(out)
}

/// One node as the ranks sent it, merged over the ranks: its position and
/// the keys of its dependencies (`deps[..count]`, none when independent).
/// Fixed size, so that a million nodes cost no allocation each.
struct NodeRecord {
    position: [f64; 3],
    deps: [u64; 4],
    count: u8,
}

impl NodeRecord {
    fn deps(&self) -> &[u64] {
        &self.deps[..self.count as usize]
    }
}

/// No number yet.
const NONE: u32 = u32::MAX;

/// Rank 0's half of [`gather`].
fn assemble(elements: &[u64], nodes: &[u64], faces: &[u64]) -> Result<Gathered> {
    let corrupt = || Error::io("the gathered mesh is inconsistent (an internal error)");
    // Each node's slot in `records`. Fixed fast hash: the map's order never
    // shows (numbers follow the elements' order). The element corners are
    // looked up once; the numbering then runs on plain arrays.
    // A node's record is at least 6 words: room for all, no rehashing.
    let most = nodes.len() / 6;
    let mut slot: FoldMap<u64, u32> = FoldMap::with_capacity_and_hasher(most, Default::default());
    let mut records: Vec<NodeRecord> = Vec::with_capacity(most);
    // (node key, patch), every rank's.
    let mut on_patch: Vec<(u64, u16)> = Vec::new();
    let mut i = 0;
    let take = |i: &mut usize| -> Result<u64> {
        let v = *nodes.get(*i).ok_or_else(corrupt)?;
        *i += 1;
        Ok(v)
    };
    while i < nodes.len() {
        let key = take(&mut i)?;
        let mut position = [0.0f64; 3];
        for x in &mut position {
            *x = f64::from_bits(take(&mut i)?);
        }
        let nd = take(&mut i)? as usize;
        if nd > 4 {
            return Err(corrupt());
        }
        let mut deps = [0u64; 4];
        for d in deps.iter_mut().take(nd) {
            *d = take(&mut i)?;
        }
        let np = take(&mut i)? as usize;
        for _ in 0..np {
            on_patch.push((key, take(&mut i)? as u16));
        }
        let next = records.len() as u32;
        let at = *slot.entry(key).or_insert(next);
        if at == next {
            records.push(NodeRecord {
                position,
                deps,
                count: nd as u8,
            });
        } else {
            let r = &mut records[at as usize];
            if r.count == 0 && nd > 0 {
                (r.deps, r.count) = (deps, nd as u8);
            }
        }
    }
    let corners: Vec<u32> = elements
        .iter()
        .map(|k| slot.get(k).copied().ok_or_else(corrupt))
        .collect::<Result<_>>()?;
    // Number the nodes by first use: independent ones, then hanging ones.
    let mut number = vec![NONE; records.len()];
    let mut order: Vec<u32> = Vec::with_capacity(records.len());
    for hanging in [false, true] {
        for &c in &corners {
            if (records[c as usize].count == 0) != hanging && number[c as usize] == NONE {
                number[c as usize] = order.len() as u32;
                order.push(c);
            }
        }
    }
    let number_of = |k: &u64| -> Option<u32> {
        slot.get(k)
            .map(|&c| number[c as usize])
            .filter(|&n| n != NONE)
    };
    let mut out = Gathered {
        num_independent: order
            .iter()
            .take_while(|&&c| records[c as usize].count == 0)
            .count(),
        ..Gathered::default()
    };
    out.elements = corners
        .chunks_exact(8)
        .map(|c| std::array::from_fn(|v| number[c[v] as usize]))
        .collect();
    for &c in &order {
        let r = &records[c as usize];
        out.coordinates.push(r.position);
        if r.count > 0 {
            let d = r
                .deps()
                .iter()
                .map(|k| number_of(k).ok_or_else(corrupt))
                .collect::<Result<Vec<u32>>>()?;
            if d.iter().any(|&m| m as usize >= out.num_independent) {
                return Err(corrupt());
            }
            out.dependencies.push(d);
        }
    }
    for (k, p) in on_patch {
        let p = p as usize;
        if out.patch_nodes.len() <= p {
            out.patch_nodes.resize(p + 1, Vec::new());
        }
        // A node no element uses has no number (and is on no face).
        if let Some(n) = number_of(&k) {
            out.patch_nodes[p].push(n);
        }
    }
    for l in &mut out.patch_nodes {
        l.sort_unstable();
        l.dedup();
    }
    out.faces = faces
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
