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

use std::collections::VecDeque;
use std::path::Path;

use crate::classify::CUT;
use crate::comm::{agree, Comm};
use crate::domain::Domain;
use crate::error::{Error, ErrorKind, Result};
use crate::geometry::Aabb;
use crate::ghost::build_ghost_layer;
use crate::octant::{morton_encode, Octant, ROOT_LEN};
use crate::octree::{owner_of_cell, LeafIndex, LinearOctree};

/// Distance of a leaf the search has not reached.
const UNREACHED: u32 = u32::MAX;

/// A path of face-adjacent open leaves from the domain boundary to the leaf
/// holding the inside point: the evidence of a leak.
#[derive(Clone, Debug, PartialEq)]
pub struct LeakPath {
    point: [f64; 3],
    octants: Vec<Octant>,
}

impl LeakPath {
    /// The inside point the outside region reaches, in user units.
    pub fn point(&self) -> [f64; 3] {
        self.point
    }

    /// The leaves of the path: the first touches the boundary of the cube,
    /// the last holds the point, consecutive leaves share part of a face,
    /// and none touches the surface. It is a shortest such path (in leaves);
    /// among those, each step back from the point goes to the neighbour with
    /// the smallest Morton key.
    pub fn octants(&self) -> &[Octant] {
        &self.octants
    }

    /// Number of leaves on the path.
    pub fn len(&self) -> usize {
        self.octants.len()
    }

    /// Whether the path is empty (never so for a path [`find_leak`] returns).
    pub fn is_empty(&self) -> bool {
        self.octants.is_empty()
    }

    /// Centres of the path's leaves in user units.
    pub fn centres(&self, domain: &Domain) -> Vec<[f64; 3]> {
        self.octants.iter().map(|&o| centre(domain, o)).collect()
    }

    /// Side lengths of the path's leaves in user units.
    pub fn sizes(&self, domain: &Domain) -> Vec<f64> {
        self.octants.iter().map(|&o| size(domain, o)).collect()
    }

    /// The report of the leak: the point, the number of leaves, the centres
    /// and sizes of the first and last few, and where the path enters the
    /// surface's bounding box `surface_box` (user units), if given.
    pub fn message(&self, domain: &Domain, surface_box: Option<&Aabb>) -> String {
        let dec = decimals(domain);
        let n = self.octants.len();
        let c = self.centres(domain);
        let s = self.sizes(domain);
        let item = |i: usize| {
            format!(
                "#{} {} size {:.dec$} (level {})",
                i + 1,
                fmt_point(c[i], dec),
                s[i],
                self.octants[i].level()
            )
        };
        let mut m = format!(
            "leak: the outside region reaches the inside point {}: a path of {n} face-adjacent \
             octant(s) that touch no triangle leads from the domain boundary to the point's octant",
            fmt_point(self.point, dec)
        );
        const FEW: usize = 3;
        if n <= 2 * FEW {
            m.push_str("\n  path: ");
            m.push_str(&(0..n).map(item).collect::<Vec<_>>().join("; "));
        } else {
            m.push_str("\n  from the boundary: ");
            m.push_str(&(0..FEW).map(item).collect::<Vec<_>>().join("; "));
            m.push_str("\n  to the point: ");
            m.push_str(&(n - FEW..n).map(item).collect::<Vec<_>>().join("; "));
        }
        if let Some(b) = surface_box {
            m.push_str("\n  ");
            m.push_str(&box_crossing(&c, b, dec));
        }
        m.push_str(
            "\n  close the surface's gaps near the path, raise the level until the leaves are \
             smaller than the gaps, or check the inside point",
        );
        m
    }

    /// The [`ErrorKind::Leak`] error carrying [`LeakPath::message`].
    pub fn to_error(&self, domain: &Domain, surface_box: Option<&Aabb>) -> Error {
        Error::new(ErrorKind::Leak, self.message(domain, surface_box))
    }

    /// Writes the path for ParaView: for `.vtk`, a legacy VTK unstructured
    /// grid holding the polyline through the centres as one line cell per
    /// step, with point data `size`, `level` and `step`; for any other
    /// extension a CSV table `step,x,y,z,size,level`. User units. Not
    /// collective.
    pub fn write(&self, path: &Path, domain: &Domain) -> Result<()> {
        crate::io::leak_path::write_leak_path(
            path,
            &self.centres(domain),
            &self.sizes(domain),
            &self.octants,
        )
    }
}

/// Centre of `o` in user units.
fn centre(domain: &Domain, o: Octant) -> [f64; 3] {
    let c = o.coords();
    let h = 0.5 * o.side() as f64;
    domain.from_lattice([c[0] as f64 + h, c[1] as f64 + h, c[2] as f64 + h])
}

/// Side of `o` in user units.
fn size(domain: &Domain, o: Octant) -> f64 {
    o.side() as f64 * domain.side / ROOT_LEN as f64
}

/// Decimals that give about six significant digits at the cube's scale.
fn decimals(domain: &Domain) -> usize {
    (6 - domain.side.log10().floor() as i64).clamp(0, 15) as usize
}

fn fmt_point(p: [f64; 3], dec: usize) -> String {
    format!("({:.dec$}, {:.dec$}, {:.dec$})", p[0], p[1], p[2])
}

fn in_box(p: [f64; 3], b: &Aabb) -> bool {
    (0..3).all(|k| b.min[k] <= p[k] && p[k] <= b.max[k])
}

/// Where the polyline through `c` last enters the closed box `b`: the
/// entry point of the segment between the last centre outside and the next
/// one (slab clipping).
fn box_crossing(c: &[[f64; 3]], b: &Aabb, dec: usize) -> String {
    let what = format!(
        "surface's bounding box {}-{}",
        fmt_point(b.min, dec),
        fmt_point(b.max, dec)
    );
    let n = c.len();
    let Some(last_out) = (0..n).rev().find(|&i| !in_box(c[i], b)) else {
        return format!(
            "the whole path lies inside the {what}: the cube is hardly larger than the surface"
        );
    };
    if last_out == n - 1 {
        return format!("the inside point's octant lies outside the {what}");
    }
    let (p, q) = (c[last_out], c[last_out + 1]);
    // Largest entry parameter over the three slabs.
    let mut t = 0.0f64;
    for k in 0..3 {
        let d = q[k] - p[k];
        if d != 0.0 {
            let t0 = (b.min[k] - p[k]) / d;
            let t1 = (b.max[k] - p[k]) / d;
            t = t.max(t0.min(t1));
        }
    }
    let t = t.clamp(0.0, 1.0);
    let x = std::array::from_fn(|k| p[k] + t * (q[k] - p[k]));
    format!(
        "the path enters the {what} at {} between octants #{} and #{} of {n} (and stays inside)",
        fmt_point(x, dec),
        last_out + 1,
        last_out + 2
    )
}

/// Local and ghost leaves with their classes: the graph of open leaves.
/// Node `i < local.len()` is local leaf `i`, node `local.len() + j` ghost `j`.
struct Graph<'a> {
    local: &'a [Octant],
    local_class: &'a [u8],
    index: LeafIndex,
    range: (u64, u64),
    ghosts: &'a [Octant],
    ghost_class: &'a [u8],
}

impl Graph<'_> {
    fn key(&self, node: usize) -> u64 {
        let nl = self.local.len();
        if node < nl {
            self.local[node].key()
        } else {
            self.ghosts[node - nl].key()
        }
    }

    /// The open leaves sharing part of a face with `leaf` (a local leaf),
    /// as nodes, into `out` (cleared first).
    fn open_neighbours(&self, leaf: Octant, out: &mut Vec<usize>) {
        out.clear();
        let c = leaf.coords();
        let side = leaf.side();
        for (f, n) in leaf.face_neighbors().into_iter().enumerate() {
            let Some(n) = n else {
                continue; // the cube's boundary
            };
            let axis = f / 2;
            let plus = f % 2 == 1;
            let plane = if plus { c[axis] + side } else { c[axis] };
            // A leaf overlapping `n` touches the face if it contains `n` or
            // lies against the face plane inside it.
            let faces = |m: Octant| {
                m.level() <= n.level()
                    || if plus {
                        m.coords()[axis] == plane
                    } else {
                        m.coords()[axis] + m.side() == plane
                    }
            };
            let (b, e) = (n.cell_begin(), n.cell_end());
            if b >= self.range.0 && e <= self.range.1 {
                let mut j = self.index.find(self.local, b);
                while j < self.local.len() && self.local[j].cell_begin() < e {
                    if faces(self.local[j]) && self.local_class[j] & CUT == 0 {
                        out.push(j);
                    }
                    j += 1;
                }
            } else {
                let nl = self.local.len();
                for (arr, class, base) in [
                    (self.local, self.local_class, 0),
                    (self.ghosts, self.ghost_class, nl),
                ] {
                    let mut j = arr.partition_point(|x| x.cell_begin() <= b);
                    if j > 0 && arr[j - 1].cell_end() > b {
                        j -= 1;
                    }
                    while j < arr.len() && arr[j].cell_begin() < e {
                        if faces(arr[j]) && class[j] & CUT == 0 {
                            out.push(base + j);
                        }
                        j += 1;
                    }
                }
            }
        }
    }

    /// Index of the local leaf `o` (which must be local).
    fn local_index(&self, o: Octant) -> Option<usize> {
        let (b, e) = self.range;
        if o.cell_begin() < b || o.cell_begin() >= e {
            return None;
        }
        let i = self.index.find(self.local, o.cell_begin());
        (self.local[i] == o).then_some(i)
    }
}

/// Hop distances from the boundary leaves, computed collectively.
struct Search<'a> {
    g: Graph<'a>,
    comm: &'a dyn Comm,
    owners: &'a [u32],
    /// Distance of each local leaf.
    dist: Vec<u32>,
    /// Smallest distance proposed to each ghost's owner so far.
    proposed: Vec<u32>,
    /// Ghosts whose proposal changed since the last exchange.
    dirty: Vec<u32>,
}

impl Search<'_> {
    /// Sweeps the local leaves in order of distance from `seeds` (pairs of
    /// distance and local index, distances already set), recording
    /// proposals for ghosts.
    fn sweep(&mut self, seeds: &mut Vec<(u32, u32)>) {
        seeds.sort_unstable();
        let nl = self.g.local.len();
        let mut queue: VecDeque<(u32, u32)> = VecDeque::new();
        let mut nb = Vec::with_capacity(16);
        let mut s = 0;
        loop {
            // Merge the sorted seeds with the queue (whose distances never
            // decrease): leaves leave in order of distance, as in Dijkstra.
            let take_seed = match (seeds.get(s), queue.front()) {
                (None, None) => break,
                (Some(_), None) => true,
                (None, Some(_)) => false,
                (Some(a), Some(b)) => a.0 <= b.0,
            };
            let (d, i) = if take_seed {
                s += 1;
                seeds[s - 1]
            } else {
                queue.pop_front().unwrap_or_default()
            };
            let i = i as usize;
            if self.dist[i] != d {
                continue; // superseded by a shorter distance
            }
            self.g.open_neighbours(self.g.local[i], &mut nb);
            let next = d + 1;
            for &m in &nb {
                if m < nl {
                    if self.dist[m] > next {
                        self.dist[m] = next;
                        queue.push_back((next, m as u32));
                    }
                } else {
                    let j = m - nl;
                    if self.proposed[j] > next {
                        self.proposed[j] = next;
                        self.dirty.push(j as u32);
                    }
                }
            }
        }
        seeds.clear();
    }

    /// Sends the proposals; returns whether any rank sent one, and fills
    /// `seeds` with the local leaves whose distance dropped.
    fn exchange(&mut self, seeds: &mut Vec<(u32, u32)>) -> bool {
        self.dirty.sort_unstable();
        self.dirty.dedup();
        let mut total = [self.dirty.len() as u64];
        self.comm.sum_u64(&mut total);
        if total[0] == 0 {
            return false;
        }
        let p = self.comm.size();
        let mut counts = vec![0usize; p];
        // Ghosts are sorted by owner, so this is grouped by rank.
        let mut send = Vec::with_capacity(2 * self.dirty.len());
        for &j in &self.dirty {
            let j = j as usize;
            counts[self.owners[j] as usize] += 2;
            send.push(self.g.ghosts[j].key());
            send.push(self.proposed[j] as u64);
        }
        self.dirty.clear();
        let (recv, _) = self.comm.alltoallv_u64(&send, &counts);
        for pair in recv.chunks_exact(2) {
            let (o, d) = (Octant::from_key(pair[0]), pair[1] as u32);
            if let Some(i) = self.g.local_index(o) {
                if self.dist[i] > d {
                    self.dist[i] = d;
                    seeds.push((d, i as u32));
                }
            }
        }
        true
    }

    /// The exact distances of all ghosts, asked from their owners.
    fn ghost_distances(&self) -> Vec<u32> {
        let p = self.comm.size();
        let mut counts = vec![0usize; p];
        for &r in self.owners {
            counts[r as usize] += 1;
        }
        let keys: Vec<u64> = self.g.ghosts.iter().map(|o| o.key()).collect();
        let (asked, asked_counts) = self.comm.alltoallv_u64(&keys, &counts);
        let answers: Vec<u64> = asked
            .iter()
            .map(|&k| {
                self.g
                    .local_index(Octant::from_key(k))
                    .map_or(UNREACHED as u64, |i| self.dist[i] as u64)
            })
            .collect();
        let (got, _) = self.comm.alltoallv_u64(&answers, &asked_counts);
        got.into_iter().map(|d| d as u32).collect()
    }
}

/// The finest lattice cell holding `point` (user units), or an error if it
/// is outside the cube.
fn point_cell(domain: &Domain, point: [f64; 3]) -> Result<u64> {
    let q = domain.to_lattice(point);
    let len = ROOT_LEN as f64;
    if !q.iter().all(|&v| (0.0..=len).contains(&v)) {
        return Err(Error::invalid(format!(
            "the inside point ({}, {}, {}) is not in the cube (origin ({}, {}, {}), side {})",
            point[0],
            point[1],
            point[2],
            domain.origin[0],
            domain.origin[1],
            domain.origin[2],
            domain.side
        )));
    }
    let i = q.map(|v| (v.floor() as u32).min(ROOT_LEN - 1));
    Ok(morton_encode(i[0], i[1], i[2]))
}

fn put(b: &mut Vec<u8>, v: u64) {
    b.extend_from_slice(&v.to_le_bytes());
}

fn get(b: &[u8], i: usize) -> u64 {
    let mut a = [0u8; 8];
    a.copy_from_slice(&b[8 * i..8 * i + 8]);
    u64::from_le_bytes(a)
}

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
    let ghost = build_ghost_layer(tree, classes);
    let leaves = tree.leaves();
    let (b, e) = tree.local_cells();
    let g = Graph {
        local: leaves,
        local_class: classes,
        index: LeafIndex::new(leaves, b, e),
        range: (b, e),
        ghosts: &ghost.leaves,
        ghost_class: &ghost.data,
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
        if classes[i] & CUT == 0 && o.touches_domain_boundary() {
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
    use crate::comm::{CommRef, SerialComm};
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
