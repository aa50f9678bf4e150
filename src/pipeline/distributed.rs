//! The distributed surface in the pipeline ([`crate::refine::distributed`]):
//! reading each rank's home share, the triangles near the chunk of the
//! construction for the octree stages, and those near the final partition
//! (with the classification walk's paths) for classification.

use std::cell::OnceCell;
use std::path::Path;

use crate::classify::{shared_counts, InsideRule, SharedCounts};
use crate::config::Command;
use crate::error::Result;
use crate::geometry::stl::{read_stl_share, shared::share};
use crate::geometry::{load_surfaces, Surface};
use crate::octree::domain::Domain;
use crate::parallel::comm::agree;
use crate::parallel::comm::CommRef;
use crate::refine::distributed::{plan_top, redistribute, sum_in_rank_order, HomeShare, TopPlan};
use crate::refine::{estimate_leaves, SurfaceIndex};
use crate::run::report::peak_rss_bytes;

use super::*;

/// The state of a distributed surface.
pub(super) struct Distributed {
    pub(super) home: HomeShare,
    /// The cell ranges (per rank, and `CELLS`) the index holds the
    /// triangles near, and whether with the classification's paths.
    pub(super) region: Option<(Vec<u64>, bool)>,
    /// The whole surface's projected area (the index's is its part's).
    pub(super) projected_area: f64,
    pub(super) shared: Option<SharedCounts>,
}

impl Session {
    /// Whether [`Session::run`] of `command` may distribute the surface: on
    /// several ranks when asked, for the parity rule (the winding rule
    /// orients the whole surface and `auto` diagnoses it), without
    /// zones (which read the whole surface near the nodes),
    /// clean-up (which compares facets anywhere) or checkpoints (which
    /// record the surface's hash). Several parts are found after reading.
    pub(super) fn may_distribute(&self, command: Command) -> bool {
        let c = &self.config;
        let rule = match self.inside {
            None => command == Command::Octree,
            Some(r) => r == InsideRule::Parity,
        };
        let mesh = command == Command::Mesh;
        c.surface.distributed
            && self.comm.size() > 1
            && rule
            && c.surface.others.is_empty()
            && !c.surface.drop_degenerate
            && !c.surface.drop_duplicates
            && c.octree.load.is_none()
            && c.output.save.is_none()
            && !(mesh && c.mesh.zones)
    }

    /// Reads this rank's home share of the configured surface (a binary STL
    /// file in shares; anything else whole, keeping the share) and indexes
    /// it. A surface of several parts is kept whole (patches need every
    /// triangle near a face). Phase `read`. Collective.
    pub(super) fn load_distributed(&mut self) -> Result<()> {
        let files = self.config.surface_files();
        let name = files.join(" + ");
        let comm = self.comm.clone();
        let (p, r) = (comm.size(), comm.rank());
        let domain_config = self.config.domain.clone();
        let mut whole = None;
        let loaded = self
            .timer
            .time(&*comm, "read", || -> Result<Option<SurfaceState>> {
                let share_read = read_stl_share(&*comm, Path::new(&files[0]));
                let (tris, first, names) = match share_read {
                    Some(s) => (s.triangles, s.first, Vec::new()),
                    None => {
                        let s = agree(&*comm, load_surfaces(&files))?;
                        if s.parts().names.len() >= 2 {
                            whole = Some(s);
                            return Ok(None);
                        }
                        let (lo, hi) = share(s.len() as u64, r, p);
                        let names = s.parts().names.clone();
                        (s.triangles()[lo as usize..hi as usize].to_vec(), lo, names)
                    }
                };
                let home = HomeShare::new(&*comm, tris, Vec::new(), first)?;
                let domain = domain_config.resolve(home.bbox.min, home.bbox.max);
                let domain = agree(&*comm, domain)?;
                let mut index = SurfaceIndex::of_triangles(&home.tris, &[], &domain);
                let projected_area = sum_in_rank_order(&*comm, index.projected_area);
                index.projected_area = projected_area;
                Ok(Some(SurfaceState {
                    name: name.clone(),
                    surface: Surface::stand_in(home.bbox, names),
                    index,
                    index_domain: domain,
                    dropped: None,
                    report: OnceCell::new(),
                    bbox: home.bbox,
                    volume: home.volume.abs(),
                    dist: Some(Distributed {
                        home,
                        region: None,
                        projected_area,
                        shared: None,
                    }),
                }))
            });
        let Some(state) = loaded? else {
            let s = whole.expect("read whole");
            return self.install_surface(&name, || Ok(s));
        };
        self.resolve_sizes(state.index_domain.root_side())?;
        self.facts.rss_read = peak_rss_bytes();
        let total = state.dist.as_ref().map_or(0, |d| d.home.total as usize);
        let k = state.index_domain.brick.level();
        let estimate = self
            .config
            .octree
            .level
            .map(|l| estimate_leaves(&state.index, l + k));
        self.observer.event(&Event::SurfaceLoaded {
            name: &state.name,
            triangles: total,
            dropped: None,
            domain: state.index_domain,
            estimate,
            inside: self.inside.map(|r| (r, "")),
        });
        self.facts.triangles = total;
        self.facts.dropped = None;
        self.facts.estimate = estimate;
        self.facts.report = None;
        self.facts.distributed = true;
        self.facts.held = self.facts.held.max(state.index.triangles().len());
        self.report_phase(None);
        self.parts = state.surface.parts().names.clone();
        self.surface_hash = None;
        self.locator = None;
        self.surface = Some(state);
        self.released = None;
        self.classes = Classes::default();
        Ok(())
    }
}

/// Re-indexes the distributed surface of `s` for the ranges of cells
/// `first_cells`: each rank then holds the triangles whose boxes come within
/// `halo` (lattice units) of its cells, and with `paths` those its
/// classification walk meets. Nothing to do when it already does, or for a
/// whole surface; returns the triangles held. Collective.
pub(super) fn hold_near(
    comm: &CommRef,
    s: &mut SurfaceState,
    first_cells: &[u64],
    halo: f64,
    paths: bool,
) -> usize {
    let Some(d) = s.dist.as_mut() else {
        return 0;
    };
    let same = d
        .region
        .as_ref()
        .is_some_and(|(f, p)| f == first_cells && *p == paths);
    if same && halo == 0.0 {
        return s.index.triangles().len();
    }
    let domain: Domain = s.index_domain;
    // The old index goes first: the new one reuses its memory.
    s.index = SurfaceIndex::of_triangles(&[], &[], &domain);
    let got = redistribute(&**comm, &d.home, &domain, first_cells, halo, paths);
    let mut index = SurfaceIndex::of_triangles(&got.tris, &got.part, &domain);
    index.projected_area = d.projected_area;
    s.index = index;
    d.region = Some((first_cells.to_vec(), paths));
    s.index.triangles().len()
}

/// For a distributed surface: the top of the refinement to `level`, with
/// the index of `s` made to hold what this rank's chunk reads (`halo`
/// for the distance bands). `None` for a whole surface. Collective.
pub(super) fn plan_near(
    comm: &CommRef,
    s: &mut SurfaceState,
    level: u8,
    halo: f64,
) -> Result<Option<(TopPlan, usize)>> {
    let Some(d) = s.dist.as_ref() else {
        return Ok(None);
    };
    // The index is the home share's until the first redistribution.
    let plan = if d.region.is_none() {
        plan_top(comm, s.index.triangles(), level)?
    } else {
        plan_top(comm, &d.home.lattice(&s.index_domain), level)?
    };
    let held = hold_near(comm, s, &plan.first_cells(), halo, false);
    Ok(Some((plan, held)))
}

/// For a distributed surface: the index of `s` made to hold what
/// classifying the leaves of `tree` reads, and the counts it needs from
/// the whole surface. `None` for a whole surface. Collective.
pub(super) fn classify_near(
    comm: &CommRef,
    s: &mut SurfaceState,
    tree: &crate::octree::LinearOctree,
) -> Option<(SharedCounts, usize)> {
    s.dist.as_ref()?;
    let held = hold_near(comm, s, tree.first_cells(), 0.0, true);
    let domain = s.index_domain;
    let d = s.dist.as_mut()?;
    if d.shared.is_none() {
        d.shared = Some(shared_counts(&**comm, &d.home.lattice(&domain)));
    }
    d.shared.map(|c| (c, held))
}

/// Snaps `mesh` to the distributed surface of `s`: the classification's
/// index goes, and each rank receives the triangles within the snap's
/// reach of its cells for the snap alone (see
/// [`crate::mesh::Mesh::snap_near`]); returns the report and the triangles
/// held. Collective.
pub(super) fn snap_near(
    comm: &CommRef,
    s: &mut SurfaceState,
    mesh: &mut crate::mesh::Mesh,
    opts: &crate::mesh::snap::SnapOptions,
) -> Result<(crate::mesh::snap::SnapReport, usize)> {
    let domain = s.index_domain;
    agree(
        &**comm,
        if *mesh.domain() == domain {
            Ok(())
        } else {
            Err(crate::error::Error::new(
                crate::error::ErrorKind::State,
                "the distributed surface is held for another cube than the mesh's",
            ))
        },
    )?;
    let Some(d) = s.dist.as_mut() else {
        return Ok(Default::default());
    };
    let mut held = 0;
    // The old index goes first: the new one reuses its memory.
    s.index = SurfaceIndex::of_triangles(&[], &[], &domain);
    let (home, projected_area) = (&d.home, d.projected_area);
    let mut fetch = |first_cells: &[u64], halo: f64| {
        let got = redistribute(&**comm, home, &domain, first_cells, halo, false);
        held = got.tris.len();
        let mut index = SurfaceIndex::of_triangles(&got.tris, &got.part, &domain);
        index.projected_area = projected_area;
        index
    };
    let report = mesh.snap_near(&**comm, &mut fetch, opts);
    // The snap's index went with it: held for no ranges, the next stage
    // that needs triangles receives them again.
    d.region = Some((Vec::new(), false));
    Ok((report?, held))
}
