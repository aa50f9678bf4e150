//! Body-fitted meshes: the nodes on the surface moved onto it.
//!
//! [`Mesh::snap`] moves every independent node on the surface patch (a
//! node of a kept element next to a dropped one, not on the domain's
//! sides) to the closest point of the surface, found by exact
//! point-triangle distance through a bounding-box tree. Sharp features are
//! kept: surface edges whose facets' normals differ by more than the
//! feature angle (and open or non-manifold edges) are *feature edges*,
//! their ends where not exactly two of them meet are *feature corners*; a
//! node within [`FEATURE_REACH`] cells of a corner goes to the corner,
//! else one that near a feature edge goes to the edge's closest point.
//! Hanging nodes stay the mean of their dependencies, so the constraint
//! stays exact.
//!
//! [`snap_conforming`] snaps a conforming mesh ([`crate::mesh::conforming`])
//! on one process by the same steps (the `Snapper`'s), which take the
//! hexahedra as connectivity alone.
//!
//! # Validity
//!
//! After the move every element touching a moved node is measured by its
//! corners' scaled Jacobians ([`crate::mesh::quality`]). At a corner below the
//! least scaled Jacobian allowed ([`SnapOptions::min_jacobian`]) the
//! corner's surface node is blamed (a hanging corner's neighbours along
//! the edges, as it follows its face or edge; else every surface node of
//! the element), and a blamed node moves a smaller fraction of its
//! displacement, down the steps of [`FRACTIONS`], until the element is
//! valid; after [`STEPS`] steps the node stays where the octree put it.
//! Only the elements around nodes that changed are measured again. The
//! nodes that end between are *partly snapped*, and the elements that
//! depend on them are reported. Then, up to `iterations` times, the
//! interior nodes within `layers` element layers of the surface nodes take
//! the mean displacement of the elements around them (the surface and
//! everything further in fixed), each move kept only where every element
//! around stays valid, and every partly snapped node tries a step up again
//! at the same time under the same rule (one check of the elements serves
//! both); the relaxed layers make room for it. A node whose step up is
//! refused stops trying: on the bunny's fluid mesh at level 5 over 95 % of
//! the later steps up that were kept came from nodes whose previous one
//! was, and the refused ones cost most of the relaxation's checks.
//!
//! # Limits
//!
//! The topology does not change. An element at a corner of the staircase
//! that is convex seen from the kept side has two or three faces on the
//! surface; where the surface bends away from the kept side (a fluid mesh
//! around a convex body, a saddle) moving all their nodes onto it flattens
//! or inverts the element, so some of those nodes stay partly snapped
//! (about half of a fluid sphere's); the report counts the partly and not
//! snapped nodes by the most wall faces of an element around them, and
//! nearly all have two or three. Hanging nodes on the surface cannot
//! reach it either: refining the leaves next to the surface to its level
//! (a distance band) keeps 2:1 steps off it.
//!
//! # Rank counts
//!
//! A node's target depends only on its lattice point and the surface, and
//! every rank holding a node computes it the same way. Every decision that
//! involves elements of several ranks (a step back, a refused move, the
//! layers) is a flag per node or-ed over the ranks sharing it through the
//! node exchange lists, and the smoothing's sums over the elements around
//! a node are fixed-point integers, exact in any order. So every rank
//! holding a node gives it the same bits, whatever the number of ranks.
//! Hanging nodes are the mean of their dependencies taken in the order of
//! their lattice points.

mod conforming;
mod features;
mod fv;
mod measure;
mod nearest;
mod options;
mod snapper;
#[cfg(target_arch = "x86_64")]
mod wide;

use crate::error::Result;
use crate::geometry::cells::corner_scaled_jacobians;
use crate::geometry::{Surface, Triangle};
use crate::mesh::faces::SURFACE_PATCH;
use crate::mesh::Mesh;
use crate::parallel::comm::Comm;
use crate::refine::SurfaceIndex;

pub use crate::geometry::cells::{hexahedron_volume, hexahedron_volume_centre, quad_area_centre};
pub use conforming::snap_conforming;
pub use fv::FvGeometry;
pub use options::{
    SnapOptions, SnapReport, DEFAULT_FEATURE_ANGLE, DEFAULT_ITERATIONS, DEFAULT_LAYERS,
    DEFAULT_MIN_JACOBIAN, FEATURE_REACH, FOAM_MIN_JACOBIAN, FRACTIONS, RELAX_TOLERANCE, STEPS,
    SURFACE_REACH,
};

use features::{features, Region, Target};
use options::{CHUNK, SPLIT_AT};
use snapper::{Cells, Snapper};

/// Collectively, the index of the triangles near this rank's cells (see
/// [`Mesh::snap_near`]).
pub(crate) type Fetch<'a> = &'a mut dyn FnMut(&[u64], f64) -> SurfaceIndex;

/// The surface a snap reads.
enum Source<'a> {
    /// The whole surface, with its index for the mesh's domain if there is
    /// one.
    Whole(&'a Surface, Option<&'a SurfaceIndex>),
    /// A surface each rank holds in part ([`Mesh::snap_near`]).
    Near(Fetch<'a>),
}

/// The corners of a hexahedron's faces, in VTK order.
const HEX_FACES: [[usize; 4]; 6] = [
    [0, 1, 2, 3],
    [4, 5, 6, 7],
    [0, 1, 5, 4],
    [1, 2, 6, 5],
    [2, 3, 7, 6],
    [3, 0, 4, 7],
];

/// Whether a node with patch mask `mask` is on the surface patch.
fn is_on_surface(mask: u64) -> bool {
    mask >> SURFACE_PATCH & 1 != 0
}

/// Whether a node with patch mask `mask` and finest element side `side`
/// (`u64::MAX`: no local element) is sent to the surface: on the surface
/// patch and on no side of the domain.
fn is_queried(mask: u64, side: u64) -> bool {
    is_on_surface(mask) && mask & ((1u64 << SURFACE_PATCH) - 1) == 0 && side != u64::MAX
}

/// The mean of the positions of a hanging node's dependencies, in the
/// order given (their lattice points'), pairwise.
#[inline]
fn mean(pos: &[[f64; 3]], (d, n): ([u32; 4], u8)) -> [f64; 3] {
    let p = |k: usize| pos[d[k] as usize];
    if n == 2 {
        let (a, b) = (p(0), p(1));
        std::array::from_fn(|k| (a[k] + b[k]) * 0.5)
    } else {
        let (a, b, c, e) = (p(0), p(1), p(2), p(3));
        std::array::from_fn(|k| ((a[k] + b[k]) + (c[k] + e[k])) * 0.25)
    }
}

impl Mesh {
    /// Snaps the mesh to `surface` (see the module documentation): moves
    /// the surface nodes onto it, scales back where an element would be
    /// invalid, relaxes the layers next to it, and stores the positions,
    /// which [`Mesh::coordinates`] and everything built on it then return.
    /// A snapped mesh is snapped again from the lattice. Collective; the
    /// positions are the same bits on any number of ranks.
    pub fn snap(
        &mut self,
        comm: &dyn Comm,
        surface: &Surface,
        opts: &SnapOptions,
    ) -> Result<SnapReport> {
        self.snap_indexed(comm, surface, None, opts)
    }

    /// [`Mesh::snap`] with the surface's index if there is one for this
    /// mesh's domain (the classification's): its triangles and tree are
    /// used instead of made again.
    pub(crate) fn snap_indexed(
        &mut self,
        comm: &dyn Comm,
        surface: &Surface,
        index: Option<&SurfaceIndex>,
        opts: &SnapOptions,
    ) -> Result<SnapReport> {
        let spare = crate::parallel::cores::spare_core(comm);
        self.snap_threads(
            comm,
            Source::Whole(surface, index),
            opts,
            spare,
            crate::parallel::cores::avx512(),
        )
    }

    /// [`Mesh::snap`] to a surface each rank holds only in part (the
    /// distributed surface): once the largest cell at a surface node is
    /// known, `fetch(first_cells, halo)` must return, collectively, the
    /// index (in the lattice units of the mesh's domain) of at least every
    /// triangle whose box comes within `halo` + [`crate::refine::distributed::MARGIN`]
    /// lattice units of this rank's cells (`first_cells` as
    /// [`crate::octree::LinearOctree::first_cells`]). Every closest point
    /// and every feature a node of the rank can reach lies there, so the
    /// positions are the bits [`Mesh::snap`] gives with the whole surface.
    pub(crate) fn snap_near(
        &mut self,
        comm: &dyn Comm,
        fetch: Fetch,
        opts: &SnapOptions,
    ) -> Result<SnapReport> {
        let spare = crate::parallel::cores::spare_core(comm);
        self.snap_threads(
            comm,
            Source::Near(fetch),
            opts,
            spare,
            crate::parallel::cores::avx512(),
        )
    }

    /// [`Mesh::snap_indexed`], with a second thread where `spare` allows
    /// and the kernels for AVX-512 where `wide` says the processor has it
    /// (the same bits either way).
    fn snap_threads(
        &mut self,
        comm: &dyn Comm,
        source: Source,
        opts: &SnapOptions,
        spare: bool,
        wide: bool,
    ) -> Result<SnapReport> {
        let empty;
        let (surface, index, near) = match source {
            Source::Whole(s, ix) => (s, ix.filter(|ix| ix.tris.len() == s.len()), None),
            Source::Near(fetch) => {
                empty = Surface::stand_in(crate::geometry::Aabb::empty(), Vec::new());
                (&empty, None, Some(fetch))
            }
        };
        self.moved = None;
        self.moved_lattice = None;
        // On a lone rank with a spare core, the surface's features (which
        // depend on the surface only) are found on a second thread while
        // this one finds the nodes to move; they are then cut to the
        // region those nodes give, as if found in it (see [`features`]).
        let early = match index {
            Some(ix) if spare && comm.size() == 1 && opts.feature_angle_deg < 180.0 => Some(ix),
            _ => None,
        };
        let (found, (masks, mut s, side, reach, mut region, largest_side)) =
            crate::parallel::cores::join(
                early.is_some(),
                || early.map(|ix| features(&ix.tris, opts.feature_angle_deg, |_| true)),
                || {
                    let lattice_u = self.node_lattice();
                    let masks = self.plain_patch_masks(comm, &lattice_u);
                    let ni = self.num_independent();
                    let deps: Vec<([u32; 4], u8)> = (0..self.num_hanging())
                        .map(|k| {
                            let mut d = [0u32; 4];
                            let h = self.hanging_deps(k);
                            d[..h.len()].copy_from_slice(&h);
                            d[..h.len()].sort_unstable_by_key(|&x| lattice_u[x as usize]);
                            (d, h.len() as u8)
                        })
                        .collect();
                    let lists = if comm.size() > 1 {
                        self.exchange_lists()
                    } else {
                        Vec::new()
                    };
                    let cells = Cells {
                        conn: self.connectivity(),
                        owned: self.num_owned(),
                        octants: Some(self.elements()),
                    };
                    let s =
                        Snapper::new(cells, comm, (spare, wide), lists, ni, lattice_u, deps, opts);
                    // The finest element side at each node, over the ranks.
                    let mut side = vec![u64::MAX; ni];
                    for (e, c) in self.elements().iter().zip(self.connectivity()) {
                        for &n in c {
                            let n = n as usize;
                            if n < ni {
                                side[n] = side[n].min(e.side() as u64);
                            }
                        }
                    }
                    s.exchange(&mut side, 1, |a, b| *a = (*a).min(b));
                    let queried = |n: usize| is_queried(masks[n], side[n]);
                    let largest = (0..ni).filter(|&n| queried(n)).map(|n| side[n]).max();
                    let reach = FEATURE_REACH * largest.unwrap_or(1) as f64;
                    let largest_side = largest.unwrap_or(1);
                    // The features that can attract a node lie within `reach` of
                    // it.
                    let region = Region::new(
                        (0..ni).filter(|&n| queried(n)).map(|n| s.lattice(n)),
                        largest.unwrap_or(1) as f64,
                        reach,
                    );
                    (masks, s, side, reach, region, largest_side)
                },
            );
        let found = found.map(|(edges, corners)| {
            let meets = |t: &Triangle| region.meets(&t.aabb());
            (
                edges.into_iter().filter(meets).collect(),
                corners.into_iter().filter(meets).collect(),
            )
        });
        // A partly held surface: the triangles within reach of this rank's
        // nodes, for the largest cell at a surface node of any rank (every
        // rank takes part in the exchange), and the features read only
        // from facets held with both neighbours of each of their edges.
        let fetched;
        let index = match near {
            Some(fetch) => {
                let mut l = [largest_side];
                comm.max_u64(&mut l);
                let halo = SURFACE_REACH * l[0] as f64 + 2.0;
                fetched = fetch(&self.first_cells, halo);
                region.held = Some((self.first_cells.clone(), comm.rank()));
                Some(&fetched)
            }
            None => index,
        };
        let target_surface = Target::new(
            surface,
            index,
            self.domain(),
            opts.feature_angle_deg,
            &region,
            reach,
            found,
        );
        // In the Morton order of their lattice points: each query's
        // neighbours come next, and the gathered triangles serve more.
        // (One node per lattice point: the keys are distinct.)
        let mut order: Vec<u32> = (0..s.ni as u32)
            .filter(|&n| is_queried(masks[n as usize], side[n as usize]))
            .collect();
        let mut keys: Vec<u64> = order
            .iter()
            .map(|&n| crate::mesh::numbering::node_key(s.lattice[n as usize]))
            .collect();
        crate::octree::sort::radix_sort_pairs_bits(&mut keys, &mut order, 0, 64);
        drop(keys);
        let (feature, relaxed, iterations) = s.run(target_surface, &order, &masks, side, opts, 1.0);
        let counts = s.figures(&masks, &feature, &relaxed);
        let domain = *self.domain();
        let near = s.near_least();
        let pos = std::mem::take(&mut s.pos);
        self.moved = Some(pos.iter().map(|&p| domain.from_lattice(p)).collect());
        self.moved_lattice = Some(pos);
        let min_j = near
            .iter()
            .flat_map(|&e| corner_scaled_jacobians(&self.element_corners(e as usize, None)))
            .fold(1.0f64, f64::min);
        Ok(report(comm, counts, min_j, iterations))
    }
}

/// The report from the figures of [`Snapper::figures`] (each rank's) and
/// each rank's least scaled Jacobian: sums and the minimum over the ranks.
/// Collective.
fn report(comm: &dyn Comm, mut counts: [u64; 14], min_j: f64, iterations: u32) -> SnapReport {
    comm.sum_u64(&mut counts);
    let mut worst = [-min_j];
    comm.max_f64(&mut worst);
    SnapReport {
        surface_nodes: counts[0],
        snapped: counts[1],
        partial: counts[2],
        unsnapped: counts[3],
        feature_nodes: counts[4],
        relaxed_nodes: counts[6],
        reported_elements: counts[7],
        partial_by_wall_faces: [counts[8], counts[9], counts[10]],
        unsnapped_by_wall_faces: [counts[11], counts[12], counts[13]],
        min_scaled_jacobian: -worst[0],
        iterations,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::classify::Keep;
    use crate::parallel::comm::SerialComm;
    use crate::testutil::mesh_of;

    #[test]
    fn a_second_thread_and_avx512_give_the_same_bits() {
        // Level 7: more surface nodes and active elements than SPLIT_AT,
        // so the passes are shared; outside, so nodes step back and up.
        let (mut m, s) = mesh_of("sphere", 7, Keep::Outside);
        let index = SurfaceIndex::new(&s, m.domain());
        let opts = SnapOptions {
            feature_angle_deg: 10.0,
            ..SnapOptions::default()
        };
        // A snapped mesh is snapped again from the lattice.
        let mut run = |spare: bool, wide: bool| {
            let r = m
                .snap_threads(
                    &SerialComm,
                    Source::Whole(&s, Some(&index)),
                    &opts,
                    spare,
                    wide,
                )
                .unwrap();
            (format!("{r:?}"), m.moved_lattice.clone().unwrap())
        };
        let one = run(false, false);
        assert!(one.1.len() > 2 * SPLIT_AT);
        // With AVX-512 (where the processor has it) too.
        let wide = crate::parallel::cores::avx512();
        for other in [run(true, false), run(false, wide), run(true, wide)] {
            assert_eq!(one.0, other.0);
            assert!(one
                .1
                .iter()
                .zip(&other.1)
                .all(|(a, b)| a.map(f64::to_bits) == b.map(f64::to_bits)));
        }
    }

    #[test]
    fn snapped_sphere_is_valid_and_on_the_surface() {
        for keep in [Keep::Inside, Keep::Outside] {
            let (mut m, s) = mesh_of("sphere", 5, keep);
            let r = m.snap(&SerialComm, &s, &SnapOptions::default()).unwrap();
            eprintln!("{keep:?} {r:?}");
            assert!(r.surface_nodes > 1000);
            assert_eq!(r.snapped + r.partial + r.unsnapped, r.surface_nodes);
            assert_eq!(r.partial_by_wall_faces.iter().sum::<u64>(), r.partial);
            assert_eq!(r.unsnapped_by_wall_faces.iter().sum::<u64>(), r.unsnapped);
            // Around the sphere the partly snapped nodes are at the
            // staircase's convex corners, every one.
            if keep == Keep::Outside {
                assert!(r.partial > 100, "{r:?}");
            }
            assert_eq!(r.partial_by_wall_faces[0], 0, "{r:?}");
            assert!(
                r.min_scaled_jacobian >= DEFAULT_MIN_JACOBIAN * 0.99,
                "{r:?}"
            );
            let x = m.coordinates();
            assert!(m.moved().is_some());
            let j = m.scaled_jacobians(None);
            assert!(j.iter().all(|&j| j > 0.0));
            let _ = x;
        }
    }
}
