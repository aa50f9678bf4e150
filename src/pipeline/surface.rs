//! Stage: the surface (reading, cleaning, indexing for the domain).

use std::cell::OnceCell;

use crate::classify::InsideRule;
use crate::error::{Error, ErrorKind, Result};
use crate::geometry::diagnostics::{clean, diagnose};
use crate::geometry::{load_surfaces, Surface};
use crate::octree::domain::Domain;
use crate::parallel::comm::agree;
use crate::refine::{estimate_leaves, SurfaceIndex};
use crate::run::report::peak_rss_bytes;

use super::*;
use crate::geometry::parts::PartLocator;

/// Triangles below which the surface's report stays on this thread:
/// about 6 ms of work here, against tens of microseconds to start one.
const SPARE_MIN_TRIANGLES: usize = 8192;

impl Session {
    /// Reads the configured surface (`surface.file`: an STL file, `sphere`,
    /// `torus` or `hull`, and the `surface.others` meshed with it, each a
    /// part), cleans it as configured, and indexes it for the cube the next
    /// octree will use. Phase `read`. Every rank reads the whole file: while
    /// every rank holds the whole surface this is faster than the split read
    /// ([`crate::geometry::stl::read_stl_file_on`]) and its exchange.
    /// Collective: a failure on any rank (a file missing on one node) fails
    /// on every rank.
    pub fn load_surface(&mut self) -> Result<()> {
        if self.distribute {
            return self.load_distributed();
        }
        let files = self.config.surface_files();
        let name = files.join(" + ");
        self.install_surface(&name, || load_surfaces(&files))
    }

    /// Installs `surface` (read by the caller on every rank) under `name`,
    /// as [`Session::load_surface`] does with a file.
    pub fn set_surface(&mut self, name: &str, surface: Result<Surface>) -> Result<()> {
        self.install_surface(name, || surface)
    }

    pub(super) fn install_surface(
        &mut self,
        name: &str,
        get: impl FnOnce() -> Result<Surface>,
    ) -> Result<()> {
        let (drop_degenerate, drop_duplicates) = (
            self.config.surface.drop_degenerate,
            self.config.surface.drop_duplicates,
        );
        let want_report =
            self.config.output.stats.is_some() || self.inside == Some(InsideRule::Auto);
        let comm = self.comm.clone();
        let (tree_domain, domain_config) = (self.tree.as_ref().map(|t| t.1), &self.config.domain);
        let spare = crate::parallel::cores::spare_core(&*comm);
        let loaded = self.timer.time(&*comm, "read", || -> Result<SurfaceState> {
            let mut surface = get()?;
            let mut dropped = None;
            if drop_degenerate || drop_duplicates {
                let (cleaned, n) = clean(&surface, drop_degenerate, drop_duplicates)?;
                surface = cleaned;
                dropped = Some(n);
            }
            let bbox = surface.bbox();
            let domain = match tree_domain {
                Some(d) => d,
                None => domain_config.resolve(bbox.min, bbox.max)?,
            };
            // The report and the index read the surface alone: a spare core
            // makes them side by side.
            let (found, index) = crate::parallel::cores::join(
                spare && want_report && surface.len() >= SPARE_MIN_TRIANGLES,
                || want_report.then(|| diagnose(&surface)),
                || SurfaceIndex::new(&surface, &domain),
            );
            let report = OnceCell::new();
            if let Some(r) = found {
                let _ = report.set(r);
            }
            Ok(SurfaceState {
                name: name.to_string(),
                index,
                index_domain: domain,
                volume: surface.signed_volume().abs(),
                bbox,
                surface,
                dropped,
                report,
                dist: None,
            })
        });
        let state = agree(&*self.comm, loaded)?;
        // Sizes count from the root cells, as levels do.
        self.resolve_sizes(state.index_domain.root_side())?;
        self.facts.rss_read = peak_rss_bytes();
        self.facts.held = self.facts.held.max(state.index.triangles().len());
        let level = self.config.octree.level;
        // Levels count from the root cells.
        let k = state.index_domain.brick.level();
        let estimate = level.map(|l| estimate_leaves(&state.index, l + k));
        let inside = self.inside.map(|r| match r {
            InsideRule::Auto => {
                let (rule, why) = InsideRule::auto_choice(state.report());
                (rule, format!(" (auto: {why})"))
            }
            r => (r, String::new()),
        });
        self.observer.event(&Event::SurfaceLoaded {
            name: &state.name,
            triangles: state.surface.len(),
            dropped: state.dropped,
            domain: state.index_domain,
            estimate,
            inside: inside.as_ref().map(|(r, why)| (*r, why.as_str())),
        });
        self.facts.triangles = state.surface.len();
        self.facts.dropped = state.dropped;
        self.facts.estimate = estimate;
        self.facts.report = state.report.get().cloned();
        // The phase's row comes after the facts it found.
        self.report_phase(None);
        self.parts = state.surface.parts().names.clone();
        self.surface_hash = Some(state.surface.hash());
        self.locator = None;
        self.surface = Some(state);
        self.released = None;
        self.classes = Classes::default();
        Ok(())
    }

    /// Turns the configuration's cell sizes (`octree.size`, `max_size`,
    /// `min_size`) into levels for a domain of side `side`, and checks the
    /// levels they give. Nothing to do without sizes.
    pub(super) fn resolve_sizes(&mut self, side: f64) -> Result<()> {
        if !self.config.has_sizes() {
            return Ok(());
        }
        let resolved = self.config.with_sizes(side).and_then(|c| {
            c.validate(self.plan)
                .map_err(|e| Error::invalid(e.render(|k| k.to_string())))?;
            Ok(c)
        });
        self.config = agree(&*self.comm, resolved)?;
        Ok(())
    }

    /// Frees the surface (its triangles and index) once no stage needs it:
    /// meshing does not, and its memory then goes before the mesh's.
    pub fn release_surface(&mut self) {
        if let Some(s) = self.surface.take() {
            if self.locator.is_none() {
                // Faces on the surface still need their part.
                self.locator = PartLocator::new(&s.surface);
            }
            self.released = Some((s.bbox, s.volume, s.name));
        }
    }

    /// The surface index mapped to the cube `domain` (re-mapped if the
    /// surface was indexed for another cube).
    pub(super) fn index_for(&mut self, domain: Domain) -> Result<&SurfaceIndex> {
        let s = self
            .surface
            .as_mut()
            .ok_or_else(|| Error::new(ErrorKind::State, "there is no surface: load one first"))?;
        if s.index_domain != domain && s.dist.is_none() {
            s.index = SurfaceIndex::new(&s.surface, &domain);
            s.index_domain = domain;
        }
        Ok(&s.index)
    }
}
