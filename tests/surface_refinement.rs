//! The surface refinement rule, checked by brute force over all triangles:
//! every leaf whose closed box touches a triangle is at the target level,
//! every coarser leaf touches none, and no leaf is finer than needed (its
//! parent touches the surface).

use std::rc::Rc;

use octmesh::internals::geometry::intersect::triangle_box_overlap;
use octmesh::internals::geometry::shapes;
use octmesh::internals::octree::domain::Domain;
use octmesh::internals::parallel::comm::{CommRef, SerialComm};
use octmesh::internals::refine::{build_from_surface, SurfaceIndex, NO_LIMIT};
use octmesh::Octant;

fn touches_brute_force(idx: &SurfaceIndex, o: Octant) -> bool {
    let (lo, hi) = o.bounds_f64();
    idx.triangles()
        .iter()
        .any(|t| triangle_box_overlap(t, lo, hi))
}

#[test]
fn touching_leaves_are_at_the_level_and_others_coarser() {
    let cases = [
        ("sphere", shapes::sphere([0.1, -0.2, 0.3], 1.0, 2), 5u8, 0.7),
        ("torus", shapes::torus([0.0; 3], 1.0, 0.3, 24, 12), 5, 0.9),
        // A fit of 1 puts the surface on the domain boundary.
        ("sphere-tight", shapes::sphere([0.0; 3], 1.0, 2), 4, 1.0),
    ];
    for (name, s, level, fit) in cases {
        let b = s.bbox();
        let d = Domain::around(b.min, b.max, fit).unwrap();
        let idx = SurfaceIndex::new(&s, &d);
        let comm: CommRef = Rc::new(SerialComm);
        let t = build_from_surface(comm, &idx, level, NO_LIMIT).unwrap();
        t.check().unwrap();
        let mut touching = 0;
        for &o in t.leaves() {
            if touches_brute_force(&idx, o) {
                touching += 1;
                assert_eq!(o.level(), level, "{name}: {o:?} touches the surface");
            }
            if o.level() > 0 {
                assert!(
                    touches_brute_force(&idx, o.parent()),
                    "{name}: {o:?} is finer than needed"
                );
            }
        }
        assert!(touching > 100, "{name}: only {touching} touching leaves");
    }
}

#[test]
fn level_above_maximum_is_an_error() {
    let s = shapes::default_sphere();
    let b = s.bbox();
    let d = Domain::around(b.min, b.max, 0.7).unwrap();
    let idx = SurfaceIndex::new(&s, &d);
    let comm: CommRef = Rc::new(SerialComm);
    let e = build_from_surface(comm, &idx, octmesh::MAX_LEVEL + 1, NO_LIMIT).unwrap_err();
    assert_eq!(e.kind(), octmesh::ErrorKind::InvalidArgument);
    assert!(e.message().contains("maximum level"));
}
