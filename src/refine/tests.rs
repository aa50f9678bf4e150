//! Tests of construction, surface and callback refinement, estimates.

use super::*;
use crate::error::ErrorKind;
use crate::geometry::{Surface, Triangle};
use crate::octree::domain::Domain;
use crate::parallel::comm::SerialComm;
use std::rc::Rc;

#[test]
fn callback_build_matches_recursive_definition() {
    // Refine towards the corner (0,0,0): leaves near it are finest.
    let comm: CommRef = Rc::new(SerialComm);
    let t = build_from_callback(comm, 8, |o| o.coords() == [0, 0, 0], NO_LIMIT).unwrap();
    t.check().unwrap();
    assert_eq!(t.global_len(), 1 + 7 * 8);
    assert!(t.leaves()[0].level() == 8);
}

/// Two triangles spanning the cube's cross-section at a height that is
/// no lattice plane: exactly `4^l` octants of each level touch them, the
/// plane-piece count, so the estimate is exact.
#[test]
fn estimate_of_a_plane_is_exact() {
    let z = 0.3;
    let tris = vec![
        Triangle::new([0.0, 0.0, z], [1.0, 0.0, z], [1.0, 1.0, z]),
        Triangle::new([0.0, 0.0, z], [1.0, 1.0, z], [0.0, 1.0, z]),
    ];
    let surface = Surface::new(tris).unwrap();
    let domain = Domain::cube([0.0; 3], 1.0).unwrap();
    let index = SurfaceIndex::new(&surface, &domain);
    for level in 0..=6u8 {
        let comm: CommRef = Rc::new(SerialComm);
        let t = build_from_surface(comm, &index, level, NO_LIMIT).unwrap();
        let cut: u64 = (0..level as u32).map(|l| 4u64.pow(l)).sum();
        assert_eq!(t.global_len(), 1 + 7 * cut);
        assert_eq!(estimate_leaves(&index, level).refined, t.global_len());
    }
    // Out of the cube, nothing is estimated beyond the root.
    let far = Domain::cube([5.0, 5.0, 5.0], 1.0).unwrap();
    let index = SurfaceIndex::new(&surface, &far);
    assert_eq!(index.projected_area(), 0.0);
    assert_eq!(estimate_leaves(&index, 9).refined, 1);
}

#[test]
fn estimate_far_above_the_limit_fails_before_refining() {
    let comm: CommRef = Rc::new(SerialComm);
    let surface = crate::geometry::shapes::default_sphere();
    let b = surface.bbox();
    let domain = Domain::around(b.min, b.max, 0.7).unwrap();
    let index = SurfaceIndex::new(&surface, &domain);
    let e = estimate_leaves(&index, 8);
    let limit = e.refined / 3;
    let err = check_estimate(&comm, &index, 8, limit).unwrap_err();
    assert_eq!(err.kind(), ErrorKind::Limit);
    let fits = (0..8)
        .rev()
        .find(|&l| estimate_leaves(&index, l).refined <= limit)
        .unwrap();
    assert!(
        err.message().contains(&format!("level {fits} would fit")),
        "{err}"
    );
    assert!(err.message().contains(&e.refined.to_string()), "{err}");
    // Within the margin it is left to the exact count.
    assert_eq!(
        check_estimate(&comm, &index, 8, e.refined / 2 + 1).unwrap(),
        e
    );
    let err = build_from_surface(comm, &index, 8, limit).unwrap_err();
    assert!(err.message().contains("estimated"), "{err}");
}

/// Refining from the top's candidate lists gives the leaves that
/// searching the bounding-box tree per leaf gives, at levels above,
/// at and below the top's depth, for surfaces partly outside the cube.
#[test]
fn refining_from_the_top_lists_matches_searching() {
    let comm: CommRef = Rc::new(SerialComm);
    let torus = crate::geometry::shapes::torus([0.55, 0.5, 0.45], 0.3, 0.1, 48, 24);
    let sphere = crate::geometry::shapes::sphere([0.4, 0.5, 0.5], 0.35, 3);
    let domain = Domain::cube([0.0; 3], 1.0).unwrap();
    let torus = SurfaceIndex::new(&torus, &domain);
    let sphere = SurfaceIndex::new(&sphere, &domain);
    for level in [0, 3, COARSE_LEVEL, COARSE_LEVEL + 1, COARSE_LEVEL + 2] {
        for s in [&torus, &sphere] {
            let mut searched = construct_for_surface(comm.clone(), s, level).unwrap();
            searched.refine_surface(s, level, NO_LIMIT).unwrap();
            let top = construct_top_for_surface(comm.clone(), s, level).unwrap();
            let listed = top.refine(NO_LIMIT).unwrap();
            listed.check().unwrap();
            assert_eq!(listed.leaves(), searched.leaves(), "level {level}");
            assert!(level < 3 || listed.local_len() > 8usize.pow(level as u32 / 2));
        }
    }
}

#[test]
fn limit_stops_early() {
    let comm: CommRef = Rc::new(SerialComm);
    let e = build_from_callback(comm, 5, |_| true, 1000).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Limit);
}
