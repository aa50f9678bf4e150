//! Stages: the mesh and its files.

use std::path::{Path, PathBuf};

use crate::classify::{CutRule, Keep};
use crate::error::{Error, ErrorKind, Result};
use crate::geometry::parts::PartLocator;
use crate::io::openfoam::{write_case, FoamCounts, FoamOptions, WallLayer};
use crate::io::vtp::write_boundary;
use crate::io::vtu::{write_gathered, write_mesh};
use crate::mesh::patches::PatchNames;
use crate::mesh::snap::{hexahedron_volume, SnapOptions, SnapReport};
use crate::mesh::{Boundary, Mesh, MeshOptions};
use crate::parallel::comm::agree;

use super::*;
use crate::geometry::parts::Solids;

impl Session {
    /// Builds the mesh of the leaves that `keep` selects, classified against
    /// the surface with the session's inside rule when there is a surface
    /// (without one only [`Keep::All`] is allowed). The octree must be
    /// balanced for edge or corner contacts. With `mesh.zones` every
    /// element gets a zone ([`crate::mesh::zones`], the regions' zones
    /// from the configuration), which needs [`Keep::All`]. Phases `ghost`,
    /// `nodes`, `numbering`, `connectivity` (and `zones`).
    pub fn build_mesh(&mut self, keep: Keep, cut_rule: CutRule) -> Result<()> {
        agree(&*self.comm, self.tree_or_state().map(|_| ()))?;
        let zones = self.config.mesh.zones;
        if zones && keep != Keep::All {
            return agree(
                &*self.comm,
                Err(Error::invalid(format!(
                    "zones (mesh.zones, --zones) need keep all, not keep {}: the inside and \
                     the outside are zones of one mesh",
                    keep.name()
                ))),
            );
        }
        // Classes made with another rule (or only the cut bits of a leak
        // check) are redone while the surface is there.
        let rule = self.inside.unwrap_or_default();
        if self.surface.is_some() {
            let wanted = agree(&*self.comm, self.resolve(rule))?;
            if self.classes.rule != Some(wanted) {
                self.classify(rule)?;
            }
        }
        let (tree, domain) = self.tree_or_state()?;
        let classes = self.classes.rule.map(|_| self.classes.bits.as_slice());
        let shown = self.progress("mesh", None);
        // A mesh of every leaf is cleaned only for its zones.
        let clean_walls = self
            .config
            .mesh
            .clean_walls
            .unwrap_or(self.config.writes_solver_mesh())
            && (keep != Keep::All || zones);
        let opts = MeshOptions {
            keep,
            cut_rule,
            clean_walls,
        };
        let mesh = Mesh::build(tree, domain, classes, &opts);
        drop(shown);
        let mut mesh = mesh?;
        self.timer.append(mesh.phase_timer());
        let c = *mesh.counts();
        for (name, seconds) in mesh.timings() {
            let count = match name.as_str() {
                "ghost" => Some(c.ghosts),
                "nodes" => Some(c.independent_nodes + c.face_hanging_nodes + c.edge_hanging_nodes),
                "connectivity" => Some(c.elements),
                "clean" => Some(c.cleaned),
                _ => None,
            };
            self.observer.event(&Event::Phase {
                name,
                seconds: *seconds,
                count,
            });
        }
        if zones {
            let comm = self.comm.clone();
            let regions = &self.config.regions;
            let surface = self.surface.as_ref();
            self.timer.time(&*comm, "zones", || {
                let solids = surface.and_then(|s| Solids::new(&s.surface));
                mesh.assign_zones(&*comm, keep, regions, solids.as_ref())
            })?;
            let n = mesh.zones().map(|z| z.names().len() as u64);
            self.report_phase(n);
        }
        self.observer.event(&Event::Meshed { counts: c });
        if let Some(z) = mesh.zones() {
            let counts = z.names().iter().cloned().zip(z.counts().iter().copied());
            self.observer
                .event(&Event::Zones(&counts.collect::<Vec<_>>()));
        }
        let e = self.volume_event(&mesh, keep, false);
        self.observer.event(&e);
        self.drop_mesh();
        self.mesh = Some(mesh);
        self.mesh_generation += 1;
        self.mesh_kept = Some((keep, cut_rule));
        Ok(())
    }

    /// Snaps the current mesh to the surface ([`crate::mesh::snap`]): the
    /// nodes on the surface patch move onto it where every element stays
    /// valid, the layers next to it are relaxed. Needs the mesh and the
    /// surface (a run keeps it for this stage). The derived views (faces,
    /// boundary, quality, the C arrays) are made again for the moved
    /// mesh. Phase `snap`.
    pub fn snap(&mut self, opts: &SnapOptions) -> Result<SnapReport> {
        self.mesh_or_state()?;
        agree(&*self.comm, crate::config::options::check_snap(opts))?;
        let surface = self.surface.as_ref().map(|_| ()).ok_or_else(|| {
            Error::new(
                ErrorKind::State,
                "snapping needs the surface: load it again (it was released after meshing)",
            )
        });
        agree(&*self.comm, surface)?;
        if self.config.mesh.conforming {
            return self.snap_conforming(opts);
        }
        let comm = self.comm.clone();
        let (mesh, surface) = (&mut self.mesh, &mut self.surface);
        let report = self.timer.time(&*comm, "snap", || match (mesh, surface) {
            (Some(m), Some(s)) if s.dist.is_some() => {
                super::distributed::snap_near(&comm, s, m, opts)
            }
            (Some(m), Some(s)) => {
                // The classification's index, if it was made for this cube.
                let index = (s.index_domain == *m.domain()).then_some(&s.index);
                m.snap_indexed(&*comm, &s.surface, index, opts)
                    .map(|r| (r, 0))
            }
            _ => Ok((SnapReport::default(), 0)),
        });
        let (report, held) = agree(&*comm, report)?;
        self.facts.held = self.facts.held.max(held);
        self.report_phase(Some(report.snapped));
        self.observer.event(&Event::Snapped(&report));
        if let Some(m) = &self.mesh {
            let e = self.volume_event(m, self.config.mesh.keep, true);
            self.observer.event(&e);
        }
        // Views of the mesh see that it changed.
        self.mesh_generation += 1;
        self.snapped = Some((self.mesh_generation, report.clone()));
        Ok(report)
    }

    /// [`Session::snap`] of a conforming run: the conforming mesh of the
    /// current mesh is built and snapped now ([`Session::gather_fe`]) and
    /// is what the single-file writers write; the hanging-node mesh keeps
    /// its lattice positions. Collective.
    fn snap_conforming(&mut self, opts: &SnapOptions) -> Result<SnapReport> {
        self.conforming_snap = Some((self.mesh_generation, *opts));
        self.gathered = None;
        self.gather_fe()?;
        Ok(self.current_snap().cloned().unwrap_or_default())
    }

    /// The report of the snap of the current mesh, if it was snapped (not
    /// collective).
    pub fn current_snap(&self) -> Option<&SnapReport> {
        self.snapped
            .as_ref()
            .filter(|s| s.0 == self.mesh_generation)
            .map(|s| &s.1)
    }

    /// The kept volume of `mesh` beside what a mesh keeping `keep` should
    /// fill, for the observer. Collective.
    fn volume_event(&self, mesh: &Mesh, keep: Keep, snapped: bool) -> Event<'static> {
        let kept = kept_volume(&*self.comm, mesh);
        self.volume_event_of(kept, mesh.domain(), keep, snapped)
    }

    /// The kept volume `kept` (of a mesh in `domain`) beside what a mesh
    /// keeping `keep` should fill, for the observer.
    pub(super) fn volume_event_of(
        &self,
        kept: f64,
        domain: &crate::octree::domain::Domain,
        keep: Keep,
        snapped: bool,
    ) -> Event<'static> {
        let reference = match self.surface_volume() {
            v if v > 0.0 => VolumeReference::of(keep),
            _ => VolumeReference::Domain,
        };
        let expected = reference.volume(domain.volume(), self.surface_volume());
        Event::KeptVolume {
            kept,
            expected,
            reference,
            snapped,
        }
    }

    pub(super) fn surface_volume(&self) -> f64 {
        match (&self.surface, &self.released) {
            (Some(s), _) => s.volume,
            (None, Some((_, v, _))) => *v,
            _ => 0.0,
        }
    }

    /// Writes the mesh as one binary VTU per rank and a PVTU, with the
    /// caller's point `fields` (name, one value per local node). Phase
    /// `write`.
    ///
    /// With `mesh.conforming` it writes the conforming mesh rank 0 builds
    /// ([`crate::mesh::conforming`], gathered as for the single-file writers):
    /// rank 0's piece holds all of it ([`write_gathered`]), the other
    /// pieces are empty; caller fields, given per node of the hanging-node
    /// mesh, are refused.
    pub fn write_vtu(&mut self, pvtu: &Path, fields: &[(&str, &[f64])]) -> Result<()> {
        self.mesh_or_state()?;
        let comm = self.comm.clone();
        if self.config.mesh.conforming {
            let refused = match fields {
                [] => Ok(()),
                _ => Err(Error::invalid(
                    "VTU point fields are given per node of the hanging-node mesh: \
                     the conforming mesh's VTU has none",
                )),
            };
            agree(&*comm, refused)?;
            self.gather_fe()?;
            let g = &self.gathered.as_ref().expect("gathered just now").1;
            self.timer
                .time(&*comm, "write", || write_gathered(&*comm, pvtu, g))?;
            self.report_phase(None);
            self.observer.event(&Event::Wrote(pvtu));
            return Ok(());
        }
        let mesh = &self.mesh;
        self.timer.time(&*comm, "write", || match mesh {
            Some(m) => write_mesh(&*comm, pvtu, m, fields).map(|_| ()),
            None => Ok(()),
        })?;
        self.report_phase(None);
        self.observer.event(&Event::Wrote(pvtu));
        Ok(())
    }

    /// The mesh, or a state error on every rank.
    pub(super) fn mesh_or_state(&self) -> Result<()> {
        let local = self
            .mesh
            .as_ref()
            .map(|_| ())
            .ok_or_else(|| Error::new(ErrorKind::State, "there is no mesh: build it first"));
        agree(&*self.comm, local)
    }

    /// The current mesh's finite-volume faces ([`crate::mesh::faces`]),
    /// extracted on first need. Phase `faces`.
    pub fn faces(&mut self) -> Result<&Faces> {
        self.mesh_or_state()?;
        let current = self.faces.as_ref().map(|f| f.0) == Some(self.mesh_generation);
        if !current {
            let comm = self.comm.clone();
            let mesh = self.mesh.as_ref();
            if self.locator.is_none() {
                if let Some(s) = &self.surface {
                    self.locator = PartLocator::new(&s.surface);
                }
            }
            let (locator, parts) = (&self.locator, self.parts.len());
            let spare = crate::parallel::cores::spare_core(&*comm);
            let faces = self.timer.time(&*comm, "faces", || match mesh {
                Some(m) => {
                    let mut f = m.faces_with(spare)?;
                    if let Some(loc) = locator {
                        let mut scratch = Vec::new();
                        f.split_surface(parts, |face| {
                            let r = m.face_area(face).sqrt();
                            loc.nearest_part(m.face_centre(face), r, &mut scratch)
                        });
                    }
                    Ok(f)
                }
                None => Ok(Faces::default()),
            });
            let faces = agree(&*comm, faces)?;
            let mut n = [faces.faces().len() as u64];
            self.comm.sum_u64(&mut n);
            self.report_phase(Some(n[0]));
            self.faces = Some((self.mesh_generation, faces));
        }
        Ok(&self.faces.as_ref().expect("faces were just made").1)
    }

    /// Writes the boundary faces with their patch ids beside the PVTU
    /// `pvtu` ([`crate::io::vtp`]): `NAME_boundary.pvtp` and a piece per
    /// rank. Phases `faces` (when not extracted yet) and `write boundary`.
    pub fn write_boundary_vtp(&mut self, pvtu: &Path) -> Result<PathBuf> {
        let patches = agree(&*self.comm, self.patch_names())?;
        self.faces()?;
        let comm = self.comm.clone();
        let (mesh, faces) = (&self.mesh, &self.faces);
        let path = self
            .timer
            .time(&*comm, "write boundary", || match (mesh, faces) {
                (Some(m), Some((_, f))) => write_boundary(&*comm, pvtu, m, f, &patches),
                _ => Ok(crate::io::vtp::boundary_path(pvtu)),
            })?;
        self.report_phase(None);
        self.observer.event(&Event::Wrote(&path));
        Ok(path)
    }

    /// The current mesh's faces if [`Session::faces`] made them (not
    /// collective).
    pub fn current_faces(&self) -> Option<&Faces> {
        self.faces
            .as_ref()
            .filter(|f| f.0 == self.mesh_generation)
            .map(|f| &f.1)
    }

    /// The current mesh's finite-element boundary
    /// ([`crate::mesh::boundary`]), made on first need with the faces.
    /// Collective. Phase `boundary`.
    pub fn boundary(&mut self) -> Result<&Boundary> {
        self.faces()?;
        let current = self.boundary.as_ref().map(|b| b.0) == Some(self.mesh_generation);
        if !current {
            let comm = self.comm.clone();
            let (mesh, faces, locator) = (&self.mesh, &self.faces, &self.locator);
            let boundary = self.timer.time(&*comm, "boundary", || match (mesh, faces) {
                (Some(m), Some((_, f))) => match locator {
                    Some(loc) => {
                        let scratch = std::cell::RefCell::new(Vec::new());
                        let part_at =
                            |p: [f64; 3]| loc.nearest_part(p, 0.0, &mut scratch.borrow_mut());
                        m.boundary(&*comm, f, Some(&part_at))
                    }
                    None => m.boundary(&*comm, f, None),
                },
                _ => Ok(Boundary::default()),
            });
            let boundary = agree(&*comm, boundary)?;
            self.report_phase(None);
            self.boundary = Some((self.mesh_generation, boundary));
        }
        Ok(&self
            .boundary
            .as_ref()
            .expect("the boundary was just made")
            .1)
    }

    /// The current mesh's boundary if [`Session::boundary`] made it (not
    /// collective).
    pub fn current_boundary(&self) -> Option<&Boundary> {
        self.boundary
            .as_ref()
            .filter(|b| b.0 == self.mesh_generation)
            .map(|b| &b.1)
    }

    /// Renames patch `from` (its current name) to `to` in the session's
    /// configuration (`mesh.patches`); a bad, unknown or duplicate name
    /// is an error and changes nothing. Not collective: every rank must
    /// make the same renames.
    pub fn rename_patch(&mut self, from: &str, to: &str) -> Result<()> {
        let now = self.patch_names()?;
        let id = now.id(from).ok_or_else(|| {
            Error::invalid(format!(
                "there is no patch '{from}' (patches: {})",
                now.names().join(" ")
            ))
        })?;
        let original = PatchNames::with_parts(self.surface_name(), &self.parts)
            .name(id)
            .to_string();
        let before = self.config.mesh.patches.clone();
        if original == to {
            self.config.mesh.patches.remove(&original);
        } else {
            self.config.mesh.patches.insert(original, to.to_string());
        }
        if let Err(e) = self.patch_names() {
            self.config.mesh.patches = before;
            return Err(e);
        }
        Ok(())
    }

    /// The name the surface patch is made from: the surface's file or
    /// built-in name.
    pub(super) fn surface_name(&self) -> &str {
        match (&self.surface, &self.released) {
            (Some(s), _) => s.name.as_str(),
            (None, Some((_, _, n))) => n.as_str(),
            _ => "surface",
        }
    }

    /// The patch names: the sides, the surface named after it, renamed by
    /// `mesh.patches`.
    pub fn patch_names(&self) -> Result<PatchNames> {
        self.config
            .patch_names_for(self.surface_name(), &self.parts)
    }

    /// Writes the mesh as an OpenFOAM case in `dir`
    /// ([`crate::io::openfoam`]) with `output.openfoam_format`,
    /// `output.overwrite` and the session's patch names. Phases `faces`
    /// (when not extracted yet) and `openfoam`.
    pub fn write_openfoam(&mut self, dir: &Path) -> Result<FoamCounts> {
        let patches = agree(&*self.comm, self.patch_names())?;
        if self.config.mesh.conforming {
            return self.write_conforming_openfoam(dir, &patches);
        }
        self.faces()?;
        let opts = FoamOptions {
            format: self.config.output.openfoam_format,
            overwrite: self.config.output.overwrite,
            patches,
        };
        let comm = self.comm.clone();
        let layer = self.config.wall_layer();
        let plan = agree(&*self.comm, self.config.layer_plan(&opts.patches))?;
        let surface = match (layer, &self.surface) {
            (false, _) => Ok(None),
            (true, Some(_)) if self.mesh.as_ref().is_some_and(|m| m.moved().is_some()) => {
                Err(Error::invalid(
                    "the wall layer needs the staircase kept off the surface, not a snapped mesh",
                ))
            }
            (true, _) if self.mesh_kept.is_some_and(|k| k.0 == Keep::All || k.1 != CutRule::None) => {
                Err(Error::invalid(
                    "the wall layer needs a mesh that keeps the inside or the outside with the cut \
                     rule none (the staircase kept off the surface)",
                ))
            }
            (true, Some(s)) => Ok(Some(&s.surface)),
            (true, None) => Err(Error::new(
                ErrorKind::State,
                "the wall layer needs the surface: load it again (it was released after meshing)",
            )),
        };
        let surface = agree(&*comm, surface)?;
        let (mesh, faces) = (&self.mesh, &self.faces);
        let wall = surface.map(|surface| WallLayer {
            surface,
            plan: plan.as_ref(),
        });
        let (counts, report) = self
            .timer
            .time(&*comm, "openfoam", || match (mesh, faces) {
                (Some(m), Some((_, f))) => write_case(&*comm, dir, (m, f), &opts, wall),
                _ => Ok((FoamCounts::default(), None)),
            })?;
        self.report_phase(None);
        if let Some(r) = &report {
            self.observer.event(&Event::Layers(r));
        }
        self.layer_report = report;
        self.observer.event(&Event::Wrote(dir));
        Ok(counts)
    }
}

impl Session {
    /// The conforming mesh as one serial case written by rank 0
    /// ([`crate::io::openfoam::write_gathered_case`]). Phases of the gather
    /// and `openfoam`.
    fn write_conforming_openfoam(
        &mut self,
        dir: &Path,
        patches: &PatchNames,
    ) -> Result<FoamCounts> {
        self.gather_fe()?;
        let comm = self.comm.clone();
        let overwrite = self.config.output.overwrite;
        let g = &self.gathered.as_ref().expect("gathered just now").1;
        let counts = self.timer.time(&*comm, "openfoam", || {
            let local = match comm.rank() {
                0 => crate::io::openfoam::write_gathered_case(dir, g, patches, overwrite),
                _ => Ok(FoamCounts::default()),
            };
            agree(&*comm, local)
        })?;
        self.report_phase(None);
        self.observer.event(&Event::Wrote(dir));
        Ok(counts)
    }
}

/// The volume of the kept elements over all ranks, user units: of the
/// moved elements when the mesh was snapped, else of the octree's cubes
/// (exact). A snapped element's volume is rounded to 2^-60 of the cube's
/// and summed as an integer, so the total has the same bits on any
/// number of ranks. Collective.
pub(super) fn kept_volume(comm: &dyn crate::parallel::comm::Comm, mesh: &Mesh) -> f64 {
    let Some(moved) = mesh.moved() else {
        let mut cells = [mesh.local_volume_cells()];
        comm.sum_u64(&mut cells);
        return mesh.cells_to_volume(cells[0]);
    };
    const FIXED: f64 = (1u64 << 60) as f64;
    let cube = mesh.domain().side.powi(3);
    let mut sum = [mesh
        .connectivity()
        .iter()
        .map(|c| {
            let p = c.map(|n| moved[n as usize]);
            (hexahedron_volume(&p) / cube * FIXED).round() as i64 as u64
        })
        .fold(0u64, u64::wrapping_add)];
    comm.sum_u64(&mut sum);
    sum[0] as i64 as f64 / FIXED * cube
}

#[cfg(test)]
mod tests {
    use std::cell::RefCell;
    use std::rc::Rc;

    use super::*;
    use crate::octree::octant::Connectivity;
    use crate::parallel::comm::SerialComm;

    /// One volume event: kept, expected, the reference, whether snapped.
    type Seen = (f64, f64, VolumeReference, bool);

    /// Keeps the volume events a session reports.
    struct Volumes(Rc<RefCell<Vec<Seen>>>);

    impl Observer for Volumes {
        fn event(&mut self, e: &Event<'_>) {
            if let Event::KeptVolume {
                kept,
                expected,
                reference,
                snapped,
            } = e
            {
                self.0
                    .borrow_mut()
                    .push((*kept, *expected, *reference, *snapped));
            }
        }
    }

    /// The sphere at level 4 meshed keeping `keep`, then snapped; the
    /// session's volume events.
    fn volumes(keep: Keep) -> Vec<Seen> {
        let seen = Rc::new(RefCell::new(Vec::new()));
        let mut config = Config::default();
        config.surface.file = "sphere".into();
        config.mesh.keep = keep;
        let mut s = Session::new(Rc::new(SerialComm), config);
        s.set_observer(Box::new(Volumes(seen.clone())));
        s.load_surface().unwrap();
        s.refine_surface(4).unwrap();
        s.balance(Connectivity::Corner).unwrap();
        s.build_mesh(keep, CutRule::Center).unwrap();
        s.snap(&SnapOptions::default()).unwrap();
        let v = seen.borrow().clone();
        v
    }

    #[test]
    fn a_run_compares_what_it_kept_with_what_it_should_fill() {
        let sphere = 4.0 / 3.0 * std::f64::consts::PI;
        let solid = volumes(Keep::Inside);
        let fluid = volumes(Keep::Outside);
        for (v, reference) in [
            (&solid, VolumeReference::Body),
            (&fluid, VolumeReference::DomainLessBody),
        ] {
            assert_eq!(v.len(), 2, "one event after meshing, one after snapping");
            assert!(v.iter().all(|e| e.2 == reference));
            assert_eq!((v[0].3, v[1].3), (false, true));
            // Within 3 % of what it should fill, and closer once snapped.
            for e in v {
                assert!(((e.0 - e.1) / e.1).abs() < 0.03, "{e:?}");
            }
            assert!((v[1].0 - v[1].1).abs() < (v[0].0 - v[0].1).abs(), "{v:?}");
        }
        // The body is the sphere's polyhedron (a little under the ball).
        assert!((solid[0].1 - sphere).abs() < 0.01 * sphere);
        // The solid and fluid staircases fill the domain together.
        let domain = fluid[0].1 + solid[0].1;
        assert!(((solid[0].0 + fluid[0].0) - domain).abs() < 1e-9 * domain);
    }

    /// A session writing conforming meshes snaps the conforming mesh (the
    /// C API's way): its report, every hexahedron valid, the snapped
    /// volume nearer the body's, the hanging-node mesh unmoved, and the
    /// conforming mesh's nodes moved where the report says (the same mesh
    /// built again without the snap for the comparison).
    #[test]
    fn a_conforming_session_snaps_the_conforming_mesh() {
        let seen = Rc::new(RefCell::new(Vec::new()));
        let mut config = Config::default();
        config.surface.file = "sphere".into();
        config.mesh.keep = Keep::Inside;
        config.mesh.conforming = true;
        let mut s = Session::new(Rc::new(SerialComm), config);
        s.set_observer(Box::new(Volumes(seen.clone())));
        s.load_surface().unwrap();
        s.refine_surface(4).unwrap();
        s.balance(Connectivity::Corner).unwrap();
        s.build_mesh(Keep::Inside, CutRule::Center).unwrap();
        let r = s.snap(&SnapOptions::default()).unwrap();
        assert!(r.surface_nodes > 100, "{r:?}");
        assert_eq!(r.snapped + r.partial + r.unsnapped, r.surface_nodes);
        assert!(r.snapped * 10 > r.surface_nodes * 9, "{r:?}");
        assert!(r.min_scaled_jacobian >= 0.99 * SnapOptions::default().min_jacobian);
        assert_eq!(s.current_snap(), Some(&r));
        assert!(s.mesh.as_ref().unwrap().moved().is_none());
        let v = seen.borrow().clone();
        assert_eq!(v.len(), 2, "{v:?}");
        assert_eq!((v[0].3, v[1].3), (false, true));
        assert!((v[1].0 - v[1].1).abs() < (v[0].0 - v[0].1).abs(), "{v:?}");
        let snapped = s.gathered.as_ref().unwrap().1.clone();
        for h in &snapped.elements {
            let p = h.map(|n| snapped.coordinates[n as usize]);
            let j = crate::geometry::cells::corner_scaled_jacobians(&p);
            assert!(j.iter().all(|&j| j > 0.0), "{j:?}");
        }
        s.conforming_snap = None;
        s.gathered = None;
        s.gather_fe().unwrap();
        let plain = &s.gathered.as_ref().unwrap().1;
        assert_eq!(plain.elements, snapped.elements);
        let moved = plain
            .coordinates
            .iter()
            .zip(&snapped.coordinates)
            .filter(|(a, b)| a != b)
            .count() as u64;
        assert!(moved >= r.snapped + r.partial, "{moved} {r:?}");
        assert!(moved <= r.surface_nodes + r.relaxed_nodes, "{moved} {r:?}");
    }
}
