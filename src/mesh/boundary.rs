//! Finite-element boundaries: the element faces on each patch and the
//! patches of each node.
//!
//! A finite-element code applies its boundary conditions on element faces
//! (Neumann, Robin) and on nodes (Dirichlet). [`Mesh::boundary`] lists
//!
//! - the **boundary element faces**: `(local element, local face, patch)`
//!   for every face of a local element that lies wholly or partly on the
//!   boundary, sorted by element then face. Local faces follow p4est's
//!   order:
//!
//!   ```text
//!              z
//!              |   3 (+y, back)
//!              |  /
//!         +----5----+            face  normal
//!        /|   /    /|             0     -x
//!       +---------+ |             1     +x
//!       | |       | 1 --- x       2     -y
//!       0 |       | |             3     +y
//!       | +------2--+             4     -z
//!       |/        |/              5     +z
//!       +----4----+
//!   ```
//!
//!   A face is partly on the boundary where some of the finer elements
//!   across it were dropped (the finite-volume faces, [`super::faces`],
//!   give the exact pieces and their areas);
//! - the **patches of each local node**, every node (independent or
//!   hanging) lying on a boundary face gets every patch it touches: a node
//!   on an edge of the domain is on two side patches, a node where the
//!   surface meets a side on both.
//!
//! A node's patches are found from the kept elements around it, not from
//! this rank's faces: the eight finest cells around the node are each kept
//! or not, and every kept/not-kept pair across a plane through the node
//! is a piece of boundary face holding the node, on a side patch when the
//! other cell is outside the domain and on the surface patch otherwise.
//! The halo holds every kept element touching a local one, so this is
//! exact at every corner of a local element. The other nodes (independent
//! nodes a hanging node depends on, corners of other ranks' elements) take
//! their patches from the ranks sharing them, in one exchange over the
//! node exchange lists; every rank holding a node then gives it the same
//! patches.

use crate::error::Result;
use crate::octree::octant::morton_encode;
use crate::parallel::comm::Comm;

use super::faces::{Faces, Kept, Other, SURFACE_PATCH};
use super::points::{face_polygon, point_key, PointIndex};
use super::{Mesh, VTK_TO_MORTON};

/// A local element's face on the boundary.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct BoundaryFace {
    /// The local element.
    pub element: u32,
    /// Its face, in p4est's order (`2 axis + 1` for the face on the
    /// positive side of `axis`).
    pub face: u8,
    /// The face's patch ([`super::faces`]: sides `0..6`, then the surface).
    pub patch: u16,
}

/// The finite-element boundary of one rank's part of the mesh; see the
/// module documentation.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Boundary {
    faces: Vec<BoundaryFace>,
    /// Node `n`'s patches are `node_patches[node_start[n]..node_start[n + 1]]`.
    node_start: Vec<u32>,
    node_patches: Vec<u16>,
}

impl Boundary {
    /// The boundary element faces, sorted by element, then face.
    pub fn faces(&self) -> &[BoundaryFace] {
        &self.faces
    }

    /// The patches of local node `n`, increasing (empty off the boundary).
    pub fn node_patches(&self, n: usize) -> &[u16] {
        &self.node_patches[self.node_start[n] as usize..self.node_start[n + 1] as usize]
    }

    /// Offsets into [`Boundary::patch_list`], one per local node and one
    /// past the end (compressed rows).
    pub fn node_offsets(&self) -> &[u32] {
        &self.node_start
    }

    /// Every node's patches, node after node.
    pub fn patch_list(&self) -> &[u16] {
        &self.node_patches
    }
}

/// The p4est face number of a finite-volume face's normal.
fn element_face(axis: usize, negative: bool) -> u8 {
    2 * axis as u8 + u8::from(!negative)
}

impl Mesh {
    /// This rank's finite-element boundary, from `faces` (this mesh's
    /// [`Mesh::faces`]). When `faces` has one surface patch per part
    /// ([`Faces::split_surface`]), a node on the surface gets the parts of
    /// the surface faces through it, or `part_at(its position)` when no
    /// local face passes through it. Collective: one exchange with the
    /// ranks sharing nodes.
    pub fn boundary(
        &self,
        comm: &dyn Comm,
        faces: &Faces,
        part_at: Option<&dyn Fn([f64; 3]) -> u16>,
    ) -> Result<Boundary> {
        let mut list: Vec<BoundaryFace> = faces.faces()
            [faces.num_internal()..faces.halo_range().start]
            .iter()
            .filter_map(|f| match f.other() {
                Other::Patch(p) => Some(BoundaryFace {
                    element: f.owner(),
                    face: element_face(f.axis(), f.negative()),
                    patch: p,
                }),
                _ => None,
            })
            .collect();
        list.sort_unstable();
        list.dedup();
        let masks = self.node_patch_masks(comm, faces, part_at);
        let mut node_start = Vec::with_capacity(masks.len() + 1);
        node_start.push(0u32);
        let mut node_patches: Vec<u16> = Vec::new();
        for mask in masks {
            node_patches.extend((0..64u16).filter(|&b| mask & 1 << b != 0));
            node_start.push(node_patches.len() as u32);
        }
        Ok(Boundary {
            faces: list,
            node_start,
            node_patches,
        })
    }

    /// Each local node's patches, bit `p` for patch `p`.
    fn node_patch_masks(
        &self,
        comm: &dyn Comm,
        faces: &Faces,
        part_at: Option<&dyn Fn([f64; 3]) -> u16>,
    ) -> Vec<u64> {
        let lattice = self.node_lattice();
        let mut masks = self.local_patch_masks(&lattice);
        if faces.num_patches() > SURFACE_PATCH as usize + 1 {
            self.surface_parts(&lattice, faces, part_at, &mut masks);
        }
        self.or_shared_masks(comm, &mut masks);
        masks
    }

    /// Each local node's patches with the surface as the one patch
    /// [`SURFACE_PATCH`] (bit `p` for patch `p`), the same on every rank
    /// holding the node: from the kept elements around it, and for nodes
    /// that are only a dependency from the sharing ranks. `lattice` is
    /// [`Mesh::node_lattice`]. Collective: one exchange with the ranks
    /// sharing nodes.
    pub(crate) fn plain_patch_masks(&self, comm: &dyn Comm, lattice: &[[u32; 3]]) -> Vec<u64> {
        let ni = self.num_independent;
        let mut masks = self.local_patch_masks(&lattice[..ni]);
        masks.resize(lattice.len(), 0);
        self.or_shared_masks(comm, &mut masks);
        // A hanging node can only be on the boundary where one of its
        // dependencies is: the others are not looked up.
        let kept = Kept::new(&self.elements, &self.halo);
        let hi = self.domain.brick.hi();
        let mut near = vec![u32::MAX; lattice.len() - ni];
        let mut covered = vec![0u8; lattice.len() - ni];
        for (e, c) in self.connectivity.iter().enumerate() {
            for (v, &n) in c.iter().enumerate() {
                if n as usize >= ni {
                    near[n as usize - ni] = e as u32;
                    covered[n as usize - ni] |= 1 << (7 - VTK_TO_MORTON[v]);
                }
            }
        }
        let nf = self.hanging.num_face();
        for k in 0..near.len() {
            // A face-hanging node whose four finer elements are kept and
            // whose coarse one is local is inside: every cell around it is
            // kept.
            let inside =
                k < nf && covered[k].count_ones() == 4 && self.hanging.coarse_element(k).is_some();
            if near[k] != u32::MAX
                && !inside
                && self.hanging_deps(k).iter().any(|&d| masks[d as usize] != 0)
            {
                let around = self.around_hanging(&kept, k, near[k] as usize);
                masks[ni + k] =
                    node_patch_mask(lattice[ni + k], hi, covered[k], |q| around.holds(q));
            }
        }
        masks
    }

    /// The patches of the local nodes seen from this rank's elements and
    /// halo; 0 for the nodes that are no local element's corner.
    fn local_patch_masks(&self, lattice: &[[u32; 3]]) -> Vec<u64> {
        let kept = Kept::new(&self.elements, &self.halo);
        let hi = self.domain.brick.hi();
        // A local element at each node, as the look-ups' starting point
        // (`lattice` may hold the independent nodes only).
        let mut near = vec![0u32; lattice.len()];
        let mut covered = vec![0u8; lattice.len()];
        for (e, c) in self.connectivity.iter().enumerate() {
            for (v, &n) in c.iter().enumerate() {
                if let Some(x) = near.get_mut(n as usize) {
                    *x = e as u32;
                    covered[n as usize] |= 1 << (7 - VTK_TO_MORTON[v]);
                }
            }
        }
        // The cells around a node that local elements cover with it as
        // their corner (bit b: the cell on the positive side of axis a
        // when bit a of b is set). A node all eight cover is inside: no
        // look-up needed.
        // No local element holds a cell around an independent node
        // without having the node as a corner (the node would hang on
        // it), so those cells are looked up in the halo only.
        let ni = self.num_independent;
        let hint = std::cell::Cell::new(0);
        let mut masks: Vec<u64> = lattice
            .iter()
            .zip(&near)
            .zip(&covered)
            .enumerate()
            .map(|(n, ((&p, &e), &c))| {
                if c == 0xff {
                    0
                } else {
                    if n < ni {
                        // Without a halo (one rank) nothing is looked up.
                        let holds = |q: [u32; 3]| {
                            !kept.halo.leaves.is_empty()
                                && kept.halo_holds(morton_encode(q[0], q[1], q[2]), &hint)
                        };
                        node_patch_mask(p, hi, c, holds)
                    } else {
                        let around = self.around_hanging(&kept, n - ni, e as usize);
                        node_patch_mask(p, hi, c, |q| around.holds(q))
                    }
                }
            })
            .collect();
        // Nodes no local element has as a corner: the halo may not reach
        // around them, so they take what the sharing ranks found.
        for &(n, _) in &self.dep_only {
            if let Some(m) = masks.get_mut(n as usize) {
                *m = 0;
            }
        }
        masks
    }

    /// The look-ups of the kept elements holding the cells around hanging
    /// node `k`, starting from local element `near`.
    fn around_hanging<'k>(&self, kept: &'k Kept<'k>, k: usize, near: usize) -> AroundHanging<'k> {
        let coarse = self.hanging.coarse_element(k).map(|c| self.elements[c]);
        AroundHanging {
            kept,
            near,
            last: std::cell::Cell::new(coarse.map(|o| (o.coords(), o.side()))),
        }
    }

    /// Ors each shared node's mask with those of the ranks sharing it.
    fn or_shared_masks(&self, comm: &dyn Comm, masks: &mut [u64]) {
        if comm.size() > 1 {
            let lists = self.exchange_lists();
            let mut counts = vec![0usize; comm.size()];
            let mut send = Vec::new();
            for (r, nodes) in &lists {
                counts[*r as usize] = nodes.len();
                send.extend(nodes.iter().map(|&n| masks[n as usize]));
            }
            let (recv, got) = comm.alltoallv_u64(&send, &counts);
            let mut at = 0;
            for (r, &n) in got.iter().enumerate() {
                if let Ok(k) = lists.binary_search_by_key(&(r as u32), |l| l.0) {
                    for (&node, &m) in lists[k].1.iter().zip(&recv[at..at + n]) {
                        masks[node as usize] |= m;
                    }
                }
                at += n;
            }
        }
    }

    /// Replaces the surface bit of each node on the surface by the bits of
    /// its parts' patches: those of the surface faces through it.
    fn surface_parts(
        &self,
        lattice: &[[u32; 3]],
        faces: &Faces,
        part_at: Option<&dyn Fn([f64; 3]) -> u16>,
        masks: &mut [u64],
    ) {
        let mut index = PointIndex::new(lattice.iter().map(|&p| point_key(p)).collect());
        let mut node_at = vec![0u32; index.len()];
        for (n, &p) in lattice.iter().enumerate() {
            if let Some(j) = index.find(point_key(p)) {
                node_at[j] = n as u32;
            }
        }
        let mut parts = vec![0u64; lattice.len()];
        let mut poly = Vec::with_capacity(8);
        let surface = SURFACE_PATCH as usize;
        for p in surface..faces.num_patches() {
            for f in &faces.faces()[faces.patch_range(p)] {
                poly.clear();
                face_polygon(
                    &f.corners(),
                    |_| true,
                    |k| index.find(k).is_some(),
                    &mut poly,
                );
                for &(k, _) in &poly {
                    if let Some(j) = index.find(k) {
                        parts[node_at[j] as usize] |= 1 << p;
                    }
                }
            }
        }
        for (n, mask) in masks.iter_mut().enumerate() {
            if *mask & 1 << surface == 0 {
                continue;
            }
            let mut found = parts[n];
            if found == 0 {
                let q = lattice[n].map(f64::from);
                let part = part_at.map_or(0, |f| f(self.domain.from_lattice(q)));
                found = 1 << (surface + part as usize);
            }
            *mask = (*mask & !(1 << surface)) | found;
        }
    }
}

/// Which kept elements hold the cells around a hanging node. The cells its
/// finer elements do not cover (see `covered`) lie mostly in the coarser
/// element it hangs on, which answers for them without a search, as does
/// the last element found.
struct AroundHanging<'k> {
    kept: &'k Kept<'k>,
    near: usize,
    /// The lowest corner and side of the last element found.
    last: std::cell::Cell<Option<([u32; 3], u32)>>,
}

impl AroundHanging<'_> {
    /// Whether a kept element holds the finest cell whose lowest corner is
    /// `q`.
    fn holds(&self, q: [u32; 3]) -> bool {
        if let Some((a, s)) = self.last.get() {
            if (0..3).all(|i| a[i] <= q[i] && q[i] - a[i] < s) {
                return true;
            }
        }
        let found = self
            .kept
            .holding_cell(morton_encode(q[0], q[1], q[2]), self.near);
        if let Some((_, o)) = found {
            self.last.set(Some((o.coords(), o.side())));
        }
        found.is_some()
    }
}

/// The patches (bit `p` for patch `p`) of the boundary faces holding
/// lattice point `p`.
/// `hi`: the upper lattice bounds of the domain (the cube's or a brick's);
/// `covered`: the cells known to be kept (bit `b` for cell `b`), which
/// need no look-up; `holds`: whether a kept element holds the finest cell
/// inside the domain whose lowest corner is the given lattice point.
fn node_patch_mask(
    p: [u32; 3],
    hi: [u32; 3],
    covered: u8,
    holds: impl Fn([u32; 3]) -> bool,
) -> u64 {
    // Cell `b` (bit `a` of `b` set: on the positive side of axis `a`),
    // kept or not; `outside[b]` when it leaves the domain.
    let mut inside = [false; 8];
    let mut outside = [false; 8];
    for b in 0..8 {
        let mut q = [0u32; 3];
        for a in 0..3 {
            let plus = b >> a & 1 == 1;
            if plus {
                outside[b] |= p[a] >= hi[a];
                q[a] = p[a];
            } else {
                outside[b] |= p[a] == 0;
                q[a] = p[a].wrapping_sub(1);
            }
        }
        if covered >> b & 1 == 1 {
            inside[b] = true;
        } else if !outside[b] {
            inside[b] = holds(q);
        }
    }
    let mut mask = 0u64;
    for b in 0..8 {
        if !inside[b] {
            continue;
        }
        for a in 0..3 {
            let c = b ^ (1 << a);
            if inside[c] {
                continue;
            }
            mask |= if outside[c] {
                // The side the missing cell lies beyond: xmin is patch 0.
                1 << (2 * a + (b >> a & 1 ^ 1))
            } else {
                1 << SURFACE_PATCH
            };
        }
    }
    mask
}
