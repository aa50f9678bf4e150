//! Leak check for fluid meshes: can the region outside the surface reach a
//! point the user knows to be inside the body?
//!
//! A fluid mesh keeps the leaves outside a body. When the surface has a gap
//! wider than the leaves near it, the outside region flows into the body and
//! the mesh silently fills it. snappyHexMesh users name a point in the fluid
//! (`locationInMesh`); here the user names a point *inside* the body, and
//! [`find_leak`] reports a path of leaves from the domain boundary to that
//! point when there is one.
//!
//! # The graph
//!
//! Nodes are the *open* leaves, those whose class lacks the
//! [`crate::classify::CUT`] bit (their closed box touches no triangle); edges
//! join open leaves sharing part of a face with positive area. Two such
//! leaves cannot be separated by the surface: the union of their closed
//! boxes is connected and touches no triangle. So a path of open leaves from
//! a leaf touching the cube's boundary to the point's leaf is a path that
//! avoids the surface, and for a closed surface inside the cube there is none
//! when the point is inside; an open surface leaks where a hole is wider than
//! the leaves around it.
//!
//! # Distances, in parallel
//!
//! Every open leaf gets its hop distance from the boundary leaves (breadth-first
//! search with several sources). Each rank sweeps its own leaves, in order of
//! distance, from the sources it knows; a face neighbour owned by another rank
//! (found in the ghost layer) gets a proposed distance, sent to its owner. The
//! owner lowers its leaf's distance if the proposal is better and sweeps
//! again from there. Rounds of (sweep, exchange) repeat until no rank proposes
//! anything; distances only decrease, so the result is the exact distance of
//! the whole graph, whatever the partition.
//!
//! # The path
//!
//! From the point's leaf at distance `d`, the walk steps to the face
//! neighbour at distance `d - 1` with the smallest Morton key, down to a
//! boundary leaf. Distances and keys are global facts, so the path is the
//! same on any number of ranks. The owner of the current leaf walks while the
//! steps stay on its rank, then broadcasts the steps and hands the walk to the
//! owner of the next leaf, which it knows from the ghost layer. Every rank
//! ends with the same path (or the same "no leak").
//!
//! Finding face neighbours: the leaves across face `f` of a leaf `o` are those
//! overlapping the same-size neighbour region `n` that either contain `n` or
//! lie inside it against the shared face. Local and ghost leaves are sorted in
//! Morton order, so they are a binary search and a short scan away. No 2:1
//! balance is assumed.

use crate::classify::CUT;
use crate::error::{Error, ErrorKind, Result};
use crate::geometry::Aabb;
use crate::octree::domain::Domain;
use crate::octree::ghost::build_ghost_layer;
use crate::octree::octant::Octant;
use crate::octree::{owner_of_cell, LeafIndex, LinearOctree};
use crate::parallel::comm::{agree, Comm};

mod path;
mod search;

pub use path::LeakPath;
use path::*;
use search::*;

/// Whether the open leaves (those without the [`CUT`] bit in `classes`, one
/// byte per local leaf as [`crate::classify::classify_leaves`] gives) connect
/// the boundary of the cube with the leaf holding `point` (user units of
/// `domain`, the cube the octree was built in) through shared faces.
/// Returns the path when they do, `None` when the point is sealed off.
/// Collective; every rank gets the same result, and the same for any number
/// of ranks.
///
/// Errors ([`ErrorKind::InvalidArgument`]): the point is outside the cube,
/// its leaf touches the surface (the point is on the surface at this
/// resolution), or `classes` has the wrong length.
pub fn find_leak(
    tree: &LinearOctree,
    classes: &[u8],
    domain: &Domain,
    point: [f64; 3],
) -> Result<Option<LeakPath>> {
    let comm: &dyn Comm = &**tree.comm();
    let local = if classes.len() != tree.local_len() {
        Err(Error::invalid(format!(
            "{} leaf classes for {} local leaves",
            classes.len(),
            tree.local_len()
        )))
    } else {
        point_cell(domain, point)
    };
    let cell = agree(comm, local)?;
    let me = comm.rank();
    // Outside a box domain nothing is open: the void counts as cut.
    let brick = domain.brick;
    let marked: Vec<u8>;
    let classes = if brick.is_cube() {
        classes
    } else {
        marked = classes
            .iter()
            .zip(tree.leaves())
            .map(|(&c, &o)| if brick.is_void(o) { c | CUT } else { c })
            .collect();
        &marked
    };
    let ghost = build_ghost_layer(tree, |i| classes[i] as u64);
    let ghost_class: Vec<u8> = ghost.data.iter().map(|&c| c as u8).collect();
    let leaves = tree.leaves();
    let (b, e) = tree.local_cells();
    let g = Graph {
        local: leaves,
        local_class: classes,
        index: LeafIndex::new(leaves, b, e),
        range: (b, e),
        ghosts: &ghost.leaves,
        ghost_class: &ghost_class,
    };
    let mut s = Search {
        g,
        comm,
        owners: &ghost.owners,
        dist: vec![UNREACHED; leaves.len()],
        proposed: vec![UNREACHED; ghost.len()],
        dirty: Vec::new(),
    };
    let mut seeds: Vec<(u32, u32)> = Vec::new();
    for (i, o) in leaves.iter().enumerate() {
        if classes[i] & CUT == 0 && brick.touches_boundary(*o) {
            s.dist[i] = 0;
            seeds.push((0, i as u32));
        }
    }
    loop {
        s.sweep(&mut seeds);
        if !s.exchange(&mut seeds) {
            break;
        }
    }

    // The point's leaf: its owner tells everyone its state.
    let owner = owner_of_cell(tree.first_cells(), cell);
    const SEALED: u64 = 0;
    const REACHED: u64 = 1;
    const ON_SURFACE: u64 = 2;
    let mut msg = Vec::new();
    if me == owner {
        let i = leaves.partition_point(|x| x.cell_begin() <= cell) - 1;
        let state = if classes[i] & CUT != 0 {
            ON_SURFACE
        } else if s.dist[i] == UNREACHED {
            SEALED
        } else {
            REACHED
        };
        put(&mut msg, state);
        put(&mut msg, leaves[i].key());
    }
    comm.broadcast_bytes(owner, &mut msg);
    let (state, start) = (get(&msg, 0), Octant::from_key(get(&msg, 1)));
    match state {
        SEALED => return Ok(None),
        ON_SURFACE => {
            let dec = decimals(domain);
            return Err(Error::invalid(format!(
                "the inside point {} lies in an octant touching the surface (centre {}, size \
                 {:.dec$}, level {}): at this resolution it is on the surface; choose a point \
                 farther from the surface",
                fmt_point(point, dec),
                fmt_point(centre(domain, start), dec),
                size(domain, start),
                start.level()
            )));
        }
        _ => {}
    }

    // Walk back from the point by decreasing distance.
    let ghost_dist = s.ghost_distances();
    let nl = leaves.len();
    let dist_of = |m: usize| {
        if m < nl {
            s.dist[m]
        } else {
            ghost_dist[m - nl]
        }
    };
    let mut path: Vec<Octant> = Vec::new();
    let (mut walker, mut at) = (owner, start);
    let mut nb = Vec::with_capacity(16);
    loop {
        // Message: [failed, next owner + 1 (0 when the walk is done), next
        // key, steps...], or [1, error text] on a broken invariant.
        let mut msg = Vec::new();
        if me == walker {
            let mut steps = Vec::new();
            let mut next: Option<(u64, u64)> = None;
            let mut x = s.g.local_index(at);
            let mut broken = None;
            while let Some(i) = x {
                steps.push(leaves[i].key());
                let d = s.dist[i];
                if d == 0 {
                    break;
                }
                s.g.open_neighbours(leaves[i], &mut nb);
                let best = nb
                    .iter()
                    .copied()
                    .filter(|&m| dist_of(m) == d - 1)
                    .min_by_key(|&m| s.g.key(m));
                x = match best {
                    Some(m) if m < nl => Some(m),
                    Some(m) => {
                        next = Some((ghost.owners[m - nl] as u64 + 1, s.g.key(m)));
                        None
                    }
                    None => {
                        broken = Some("no neighbour one step closer to the boundary");
                        None
                    }
                };
            }
            if x.is_none() && next.is_none() && broken.is_none() {
                broken = Some("the walk left its owner's leaves");
            }
            match broken {
                Some(why) => {
                    put(&mut msg, 1);
                    msg.extend_from_slice(format!("leak path: {why}").as_bytes());
                }
                None => {
                    let (r, k) = next.unwrap_or((0, 0));
                    for v in [0, r, k] {
                        put(&mut msg, v);
                    }
                    for k in steps {
                        put(&mut msg, k);
                    }
                }
            }
        }
        comm.broadcast_bytes(walker, &mut msg);
        if get(&msg, 0) != 0 {
            return Err(Error::new(
                ErrorKind::Internal,
                String::from_utf8_lossy(&msg[8..]).into_owned(),
            ));
        }
        path.extend((3..msg.len() / 8).map(|i| Octant::from_key(get(&msg, i))));
        let r = get(&msg, 1);
        if r == 0 {
            break;
        }
        walker = (r - 1) as usize;
        at = Octant::from_key(get(&msg, 2));
    }
    path.reverse();
    Ok(Some(LeakPath {
        point,
        octants: path,
    }))
}

/// [`find_leak`] as a check: `Ok(())` when the point is sealed off from the
/// boundary, else the [`ErrorKind::Leak`] error whose message
/// ([`LeakPath::message`]) describes the path, the same on every rank.
/// `surface_box` is the surface's bounding box in user units, for the report.
/// Collective.
pub fn check_leak(
    tree: &LinearOctree,
    classes: &[u8],
    domain: &Domain,
    point: [f64; 3],
    surface_box: Option<&Aabb>,
) -> Result<()> {
    match find_leak(tree, classes, domain, point)? {
        None => Ok(()),
        Some(p) => Err(p.to_error(domain, surface_box)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::parallel::comm::{CommRef, SerialComm};
    use std::rc::Rc;

    fn comm() -> CommRef {
        Rc::new(SerialComm)
    }

    /// Uniform tree at `level` with cut leaves where `cut(i, j, k)` holds.
    fn grid(level: u8, cut: impl Fn([u32; 3]) -> bool) -> (LinearOctree, Vec<u8>) {
        let t = LinearOctree::new_uniform(comm(), level).unwrap();
        let s = t.leaves()[0].side();
        let classes = t
            .leaves()
            .iter()
            .map(|o| {
                let c = o.coords().map(|v| v / s);
                if cut(c) {
                    CUT
                } else {
                    0
                }
            })
            .collect();
        (t, classes)
    }

    /// A hollow box of cut cells 4..=11 on a 16^3 grid, with `hole` open.
    fn shell(c: [u32; 3], hole: Option<[u32; 3]>) -> bool {
        let inside = c.iter().all(|&v| (4..=11).contains(&v));
        let wall = inside && c.iter().any(|&v| v == 4 || v == 11);
        wall && Some(c) != hole
    }

    fn unit() -> Domain {
        Domain::cube([0.0; 3], 1.0).unwrap()
    }

    #[test]
    fn sealed_shell_has_no_leak() {
        let (t, cl) = grid(4, |c| shell(c, None));
        let p = find_leak(&t, &cl, &unit(), [0.5; 3]).unwrap();
        assert!(p.is_none());
    }

    #[test]
    fn hole_gives_the_shortest_path() {
        // Hole in the +x wall at cell (11, 7, 7); the point is in cell
        // (8, 8, 8). Shortest: from the boundary cell (15, 7, 7) 4 steps to
        // the hole, then |11 - 8| + |7 - 8| + |7 - 8| = 5 steps: 10 cells.
        let (t, cl) = grid(4, |c| shell(c, Some([11, 7, 7])));
        let p = find_leak(&t, &cl, &unit(), [8.5 / 16.0; 3])
            .unwrap()
            .expect("leak");
        assert_eq!(p.len(), 10);
        let cells: Vec<[u32; 3]> = p
            .octants()
            .iter()
            .map(|o| o.coords().map(|v| v >> 15))
            .collect();
        assert_eq!(cells[0], [15, 7, 7]);
        assert_eq!(cells[4], [11, 7, 7]);
        assert_eq!(*cells.last().unwrap(), [8, 8, 8]);
        for w in cells.windows(2) {
            let d: u32 = (0..3).map(|k| w[0][k].abs_diff(w[1][k])).sum();
            assert_eq!(d, 1, "{w:?} are not face neighbours");
        }
        let msg = p.message(&unit(), None);
        assert!(msg.contains("a path of 10 face-adjacent"), "{msg}");
    }

    #[test]
    fn point_on_the_surface_and_outside_the_cube() {
        let (t, cl) = grid(4, |c| shell(c, None));
        let e = find_leak(&t, &cl, &unit(), [4.5 / 16.0, 0.5, 0.5]).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::InvalidArgument);
        assert!(e.message().contains("touching the surface"), "{e}");
        let e = find_leak(&t, &cl, &unit(), [1.5, 0.5, 0.5]).unwrap_err();
        assert!(e.message().contains("not in the cube"), "{e}");
        let e = find_leak(&t, &cl[1..], &unit(), [0.5; 3]).unwrap_err();
        assert!(e.message().contains("leaf classes"), "{e}");
    }

    #[test]
    fn coarse_and_fine_neighbours() {
        // Root split once, child 0 split again: a fine leaf sees a coarse
        // one across a face and the coarse one sees four fine ones.
        let mut leaves: Vec<Octant> = Octant::ROOT.child(0).children().to_vec();
        leaves.extend_from_slice(&Octant::ROOT.children()[1..]);
        let t = LinearOctree::from_local_leaves(comm(), leaves.clone()).unwrap();
        let cl = vec![0u8; leaves.len()];
        let (b, e) = t.local_cells();
        let g = Graph {
            local: t.leaves(),
            local_class: &cl,
            index: LeafIndex::new(t.leaves(), b, e),
            range: (b, e),
            ghosts: &[],
            ghost_class: &[],
        };
        let mut nb = Vec::new();
        // Coarse child 1 (+x of child 0): its -x face meets fine leaves
        // 1, 3, 5, 7 of child 0.
        let coarse = leaves.iter().position(|&o| o == Octant::ROOT.child(1));
        g.open_neighbours(Octant::ROOT.child(1), &mut nb);
        let fine: Vec<Octant> = nb
            .iter()
            .map(|&m| leaves[m])
            .filter(|o| o.level() == 2)
            .collect();
        assert_eq!(
            fine,
            [1, 3, 5, 7]
                .map(|c| Octant::ROOT.child(0).child(c))
                .to_vec()
        );
        // Fine leaf 1 of child 0 sees the coarse child 1 across +x.
        g.open_neighbours(Octant::ROOT.child(0).child(1), &mut nb);
        assert!(nb.contains(&coarse.unwrap()));
        for &m in &nb {
            assert_eq!(
                Octant::ROOT.child(0).child(1).contact(leaves[m]),
                Some(2),
                "{:?}",
                leaves[m]
            );
        }
    }
}
