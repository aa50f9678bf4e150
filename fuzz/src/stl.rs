//! Fuzz body `stl`: arbitrary bytes through the STL reader and everything
//! a loaded surface goes through (diagnostics, clean-up, the domain, the
//! surface index, the size estimate, a small refinement, classification,
//! balance and the mesh) on one process. Any input may fail with an error;
//! none may panic, and what loads must give a complete octree.

use std::rc::Rc;

use octmesh::internals::classify::{classify_leaves, CutRule, Keep};
use octmesh::internals::geometry::diagnostics::{clean, diagnose};
use octmesh::internals::geometry::stl::read_stl_bytes;
use octmesh::internals::mesh::{Mesh, MeshOptions};
use octmesh::internals::octree::domain::Domain;
use octmesh::internals::parallel::comm::{CommRef, SerialComm};
use octmesh::internals::refine::{build_from_surface, estimate_leaves, SurfaceIndex};
use octmesh::{Connectivity, ErrorKind};

/// Octant limit of the refinement and the balance, so that every input
/// runs in milliseconds.
pub const LIMIT: u64 = 20_000;

/// Runs one input.
pub fn run(data: &[u8]) {
    let surface = match read_stl_bytes(data) {
        Ok(s) => s,
        Err(e) => {
            assert!(!e.message().is_empty());
            return;
        }
    };
    let report = diagnose(&surface);
    assert_eq!(report.triangles, surface.len());
    assert!(report.boundary_edges <= 3 * report.triangles);
    if let Ok((cleaned, dropped)) = clean(&surface, true, true) {
        assert_eq!(cleaned.len() + dropped, surface.len());
    }
    let b = surface.bbox();
    let fit = [0.7, 1.0, 0.01][data.len() % 3];
    let Ok(domain) = Domain::around(b.min, b.max, fit) else {
        return;
    };
    let index = SurfaceIndex::new(&surface, &domain);
    // Small levels only; the low bits of the length pick one.
    let level = (data.len() / 3 % 4) as u8;
    let estimate = estimate_leaves(&index, level);
    assert!(estimate.refined >= 1 && estimate.balanced >= estimate.refined);
    let comm: CommRef = Rc::new(SerialComm);
    let mut tree = match build_from_surface(comm, &index, level, LIMIT) {
        Ok(t) => t,
        Err(e) => {
            assert_eq!(e.kind(), ErrorKind::Limit, "{e}");
            return;
        }
    };
    tree.check().expect("refined octree is complete");
    for &o in tree.leaves() {
        assert!(o.level() <= level);
    }
    let classes = classify_leaves(tree.leaves(), &index);
    assert_eq!(classes.len(), tree.local_len());
    match tree.balance_with_limit(Connectivity::Corner, LIMIT) {
        Ok(_) => {}
        Err(e) => {
            assert_eq!(e.kind(), ErrorKind::Limit, "{e}");
            return;
        }
    }
    tree.check().expect("balanced octree is complete");
    let classes = classify_leaves(tree.leaves(), &index);
    let keep = [Keep::All, Keep::Inside, Keep::Outside][data.len() % 3];
    let opts = MeshOptions {
        keep,
        cut_rule: CutRule::Center,
        clean_walls: data.len().is_multiple_of(2),
    };
    let mesh = Mesh::build(&tree, &domain, Some(&classes), &opts).expect("mesh");
    // Every element's faces close.
    let faces = mesh.faces().expect("faces");
    let mut sum = vec![[0f64; 3]; mesh.elements().len()];
    for f in faces.faces() {
        let (a, n) = (f.lattice_area(), f.unit_normal());
        for k in 0..3 {
            sum[f.owner() as usize][k] += a * n[k];
            if let octmesh::internals::mesh::Other::Element(j) = f.other() {
                sum[j as usize][k] -= a * n[k];
            }
        }
    }
    assert!(
        sum.iter().all(|s| *s == [0.0; 3]),
        "an element does not close"
    );
    let nodes = mesh.num_nodes() as u32;
    for e in mesh.connectivity() {
        assert!(e.iter().all(|&n| n < nodes));
    }
}
