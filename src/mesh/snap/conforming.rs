//! The snap of a conforming mesh ([`crate::mesh::conforming`]), made on one
//! process: the same targets, steps back and relaxation as the
//! hanging-node mesh's (the [`Snapper`]), on hexahedra that need not be
//! cubes and nodes in the conforming mesh's lattice, [`MACRO`] times finer
//! than the octree's. There are no hanging nodes and no other ranks.

use crate::error::{Error, ErrorKind, Result};
use crate::geometry::cells::corner_scaled_jacobians;
use crate::geometry::Surface;
use crate::mesh::conforming::build::Conforming;
use crate::mesh::conforming::MACRO;
use crate::octree::domain::Domain;
use crate::octree::octant::morton_encode;
use crate::parallel::comm::SerialComm;
use crate::refine::SurfaceIndex;

use super::features::{Region, Target};
use super::snapper::{Cells, Snapper};
use super::{is_queried, report, SnapOptions, SnapReport, FEATURE_REACH};

/// Snaps the conforming mesh `mesh` (a whole mesh, on this process) to
/// `surface` as [`crate::mesh::Mesh::snap`] snaps the hanging-node mesh:
/// the nodes on the surface patch and on no side go onto the surface,
/// every hexahedron stays valid at its eight corners by
/// [`SnapOptions::min_jacobian`], the layers behind are relaxed. `masks`
/// holds each node's patches (bit `p` for side `p`, bit
/// [`crate::mesh::faces::SURFACE_PATCH`] for the surface); `index`, if
/// given, is `surface` in `domain`'s lattice units; `spare`: a second
/// thread may take pieces of the long passes (the same bits either way).
/// Returns the nodes' positions in user units and the report. A node's
/// "cell" (the reach of its features and of its surface) is the least
/// over its hexahedra of the longest side of their boxes: the leaf's side
/// where the hexahedra are the octree's leaves, as at the surface.
pub fn snap_conforming(
    mesh: &Conforming,
    surface: &Surface,
    index: Option<&SurfaceIndex>,
    domain: &Domain,
    masks: &[u64],
    opts: &SnapOptions,
    spare: bool,
) -> Result<(Vec<[f64; 3]>, SnapReport)> {
    let unit = MACRO as f64;
    let index = index.filter(|ix| ix.tris.len() == surface.len());
    let lattice = mesh
        .points
        .iter()
        .map(|p| {
            let c = p.map(u32::try_from);
            match c {
                [Ok(x), Ok(y), Ok(z)] => Ok([x, y, z]),
                _ => Err(Error::new(
                    ErrorKind::Internal,
                    "a node of the conforming mesh lies outside the lattice",
                )),
            }
        })
        .collect::<Result<Vec<[u32; 3]>>>()?;
    let ni = lattice.len();
    if masks.len() != ni {
        return Err(Error::new(
            ErrorKind::Internal,
            "the conforming mesh's patch masks do not match its nodes",
        ));
    }
    let mut side = vec![u64::MAX; ni];
    for h in &mesh.hexes {
        let longest = (0..3)
            .map(|a| {
                let c = h.iter().map(|&n| lattice[n as usize][a]);
                c.clone().max().unwrap_or(0) - c.min().unwrap_or(0)
            })
            .max()
            .unwrap_or(0) as u64;
        for &n in h {
            side[n as usize] = side[n as usize].min(longest);
        }
    }
    let queried = |n: usize| is_queried(masks[n], side[n]);
    let largest = (0..ni).filter(|&n| queried(n)).map(|n| side[n]).max();
    let largest = largest.map_or(1.0, |s| s as f64 / unit);
    let reach = FEATURE_REACH * largest;
    let region = Region::new(
        (0..ni)
            .filter(|&n| queried(n))
            .map(|n| lattice[n].map(|c| f64::from(c) / unit)),
        largest,
        reach,
    );
    let target = Target::new(
        surface,
        index,
        domain,
        opts.feature_angle_deg,
        &region,
        reach,
        None,
    );
    // Queried in the Morton order of their leaf-lattice points (nearby
    // queries share gathered triangles), ties by number.
    let mut order: Vec<u32> = (0..ni as u32).filter(|&n| queried(n as usize)).collect();
    order.sort_by_cached_key(|&n| {
        let [x, y, z] = lattice[n as usize].map(|c| c / MACRO as u32);
        (morton_encode(x, y, z), n)
    });
    let comm = SerialComm;
    let cells = Cells {
        conn: &mesh.hexes,
        owned: ni,
        octants: None,
    };
    let wide = crate::parallel::cores::avx512();
    let mut s = Snapper::new(
        cells,
        &comm,
        (spare, wide),
        Vec::new(),
        ni,
        lattice,
        Vec::new(),
        opts,
    );
    let (feature, relaxed, iterations) = s.run(target, &order, masks, side, opts, unit);
    let counts = s.figures(masks, &feature, &relaxed);
    let near = s.near_least();
    let pos: Vec<[f64; 3]> = s
        .pos
        .iter()
        .map(|p| domain.from_lattice(p.map(|c| c / unit)))
        .collect();
    let min_j = near
        .iter()
        .flat_map(|&e| corner_scaled_jacobians(&mesh.hexes[e as usize].map(|n| pos[n as usize])))
        .fold(1.0f64, f64::min);
    Ok((pos, report(&comm, counts, min_j, iterations)))
}
