//! The pieces of a mesh joined through faces: what a solver's stiffness
//! sees.
//!
//! Two elements are joined when they share a face or a piece of one (on a
//! 2:1-balanced mesh, a whole face or a quarter of the coarser element's):
//! exactly the internal and halo faces of [`Mesh::faces`]. Pieces touching
//! only along an edge or at a corner stay apart: such a joint is a hinge,
//! and the stiffness is singular unless every piece is held.
//!
//! Each rank joins its elements through its internal faces (union-find,
//! each piece named by its first element's global number) and sends rank 0
//! its pieces' sizes and, per halo face, its element, that element's piece
//! and the other rank's element. Rank 0 joins the pieces across ranks and
//! broadcasts the sizes. Only the partition boundary's faces travel.

use crate::geometry::hash::FoldMap;
use crate::parallel::comm::Comm;

use super::faces::{Faces, Other};
use super::Mesh;

/// The representative of `a`'s set; halves the path on the way.
fn root(parent: &mut [u32], mut a: u32) -> u32 {
    while parent[a as usize] != a {
        let up = parent[parent[a as usize] as usize];
        parent[a as usize] = up;
        a = up;
    }
    a
}

/// Joins the sets of `a` and `b`; the lower representative stays.
fn join(parent: &mut [u32], a: u32, b: u32) {
    let (a, b) = (root(parent, a), root(parent, b));
    parent[a.max(b) as usize] = a.min(b);
}

/// Sends `local` to rank 0; rank 0 gets every rank's in rank order.
fn to_root(comm: &dyn Comm, local: &[u64]) -> Vec<u64> {
    let mut counts = vec![0usize; comm.size()];
    counts[0] = local.len();
    comm.alltoallv_u64(local, &counts).0
}

/// The sizes (elements) of the pieces of `mesh` joined through faces,
/// largest first, the same on every rank. `faces` is this mesh's
/// [`Mesh::faces`]. Collective.
pub fn pieces(comm: &dyn Comm, mesh: &Mesh, faces: &Faces) -> Vec<u64> {
    let ne = mesh.elements().len();
    let first = mesh.first_element();
    let mut parent: Vec<u32> = (0..ne as u32).collect();
    for f in &faces.faces()[..faces.num_internal()] {
        if let Other::Element(j) = f.other() {
            join(&mut parent, f.owner(), j);
        }
    }
    // A piece's representative is its lowest element.
    let mut size = vec![0u32; ne];
    for e in 0..ne as u32 {
        let r = root(&mut parent, e);
        size[r as usize] += 1;
    }
    let mut local: Vec<u64> = Vec::new();
    for (e, &s) in size.iter().enumerate() {
        if s > 0 {
            local.extend([first + e as u64, u64::from(s)]);
        }
    }
    let sizes = to_root(comm, &local);
    local.clear();
    let global = &mesh.halo().global;
    for f in &faces.faces()[faces.halo_range()] {
        if let Other::Halo(h) = f.other() {
            let e = f.owner();
            let r = u64::from(root(&mut parent, e));
            local.extend([first + u64::from(e), first + r, global[h as usize]]);
        }
    }
    let across = to_root(comm, &local);
    drop(local);
    let mut out: Vec<u64> = Vec::new();
    if comm.rank() == 0 {
        // Join the ranks' pieces through the halo faces, each seen from
        // both sides.
        let index: FoldMap<u64, u32> = (sizes.chunks_exact(2).enumerate())
            .map(|(i, w)| (w[0], i as u32))
            .collect();
        let piece_of: FoldMap<u64, u64> = across.chunks_exact(3).map(|w| (w[0], w[1])).collect();
        let mut parent: Vec<u32> = (0..index.len() as u32).collect();
        for w in across.chunks_exact(3) {
            if let (Some(&a), Some(b)) = (index.get(&w[1]), piece_of.get(&w[2])) {
                if let Some(&b) = index.get(b) {
                    join(&mut parent, a, b);
                }
            }
        }
        let mut total = vec![0u64; parent.len()];
        for (i, w) in sizes.chunks_exact(2).enumerate() {
            total[root(&mut parent, i as u32) as usize] += w[1];
        }
        out = total.into_iter().filter(|&s| s > 0).collect();
        out.sort_unstable_by(|a, b| b.cmp(a));
    }
    let mut bytes: Vec<u8> = out.iter().flat_map(|s| s.to_le_bytes()).collect();
    comm.broadcast_bytes(0, &mut bytes);
    bytes
        .chunks_exact(8)
        .map(|b| u64::from_le_bytes(b.try_into().expect("8 bytes")))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::classify::{classify_leaves, CutRule, Keep};
    use crate::io::gathered::gather;
    use crate::mesh::MeshOptions;
    use crate::octree::domain::{Domain, DEFAULT_FIT};
    use crate::octree::octant::Connectivity;
    use crate::parallel::comm::{CommRef, SerialComm};
    use crate::refine::{build_from_surface, SurfaceIndex, NO_LIMIT};

    /// The pieces through the faces equal those the gathered mesh finds by
    /// its elements' face corners (hanging quarter faces by their coarse
    /// face), on solids without the wall clean-up and on cells chosen to
    /// touch along an edge only and across a 2:1 face.
    #[test]
    fn pieces_equal_those_of_the_gathered_mesh() {
        let comm: CommRef = std::rc::Rc::new(SerialComm);
        for (name, level) in [
            ("sphere", 3),
            ("sphere", 4),
            ("torus", 4),
            ("torus", 5),
            ("hull", 5),
        ] {
            let s = crate::geometry::load_surface(name).unwrap();
            let b = s.bbox();
            let domain = Domain::around(b.min, b.max, DEFAULT_FIT).unwrap();
            let index = SurfaceIndex::new(&s, &domain);
            let mut t = build_from_surface(comm.clone(), &index, level, NO_LIMIT).unwrap();
            t.balance(Connectivity::Corner).unwrap();
            let classes = classify_leaves(t.leaves(), &index);
            let opts = MeshOptions {
                keep: Keep::Inside,
                cut_rule: CutRule::Center,
                clean_walls: false,
            };
            let mesh = Mesh::build(&t, &domain, Some(&classes), &opts).unwrap();
            let faces = mesh.faces().unwrap();
            let boundary = mesh.boundary(&SerialComm, &faces, None).unwrap();
            let g = gather(&SerialComm, &mesh, &boundary).unwrap();
            let got = pieces(&SerialComm, &mesh, &faces);
            assert_eq!(got, g.pieces(), "{name} level {level}");
            assert_eq!(got.iter().sum::<u64>(), mesh.elements().len() as u64);
        }
        // Level-2 cells kept: A and C share a face; B touches A along an
        // edge only; D, split into 8, has a 2:1 face with B.
        let (a, c, b, d) = ([1u32, 1, 1], [1, 1, 2], [2, 2, 1], [3, 2, 1]);
        let mut t = crate::octree::LinearOctree::new_uniform(comm.clone(), 2).unwrap();
        let cell = |o: crate::octree::octant::Octant| o.coords().map(|x| x >> 17);
        t.refine_once(3, |o| cell(o) == d, u64::MAX).unwrap();
        t.balance(Connectivity::Corner).unwrap();
        let classes: Vec<u8> = (t.leaves().iter())
            .map(|&o| u8::from([a, c, b, d].contains(&cell(o))))
            .collect();
        let opts = MeshOptions {
            keep: Keep::Inside,
            cut_rule: CutRule::Center,
            clean_walls: false,
        };
        let domain = Domain::cube([0.0; 3], 1.0).unwrap();
        let mesh = Mesh::build(&t, &domain, Some(&classes), &opts).unwrap();
        let faces = mesh.faces().unwrap();
        let boundary = mesh.boundary(&SerialComm, &faces, None).unwrap();
        let g = gather(&SerialComm, &mesh, &boundary).unwrap();
        let got = pieces(&SerialComm, &mesh, &faces);
        assert_eq!(got, vec![9, 2]);
        assert_eq!(got, g.pieces());
    }
}
