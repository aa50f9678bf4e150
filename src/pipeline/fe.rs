//! Stages: the single-file finite-element meshes (Gmsh, Abaqus/CalculiX,
//! Exodus II, CGNS).

use std::path::Path;

use crate::io::gathered::{gather, Gathered};
use crate::mesh::patches::PatchNames;
use crate::mesh::pieces::pieces;
use crate::mesh::snap::{hexahedron_volume, SnapReport};
use crate::parallel::comm::agree;

use super::*;

impl Session {
    /// Gathers the current mesh and its boundary on rank 0
    /// ([`crate::io::gathered`]), once per mesh: every single-file writer
    /// of the same mesh uses the same copy. Reports the mesh's pieces
    /// ([`Event::Pieces`], [`crate::mesh::pieces`]). Phases `faces` and
    /// `boundary` (when not made yet) and `gather` (with the pieces).
    pub(super) fn gather_fe(&mut self) -> Result<()> {
        let key = (self.mesh_generation, self.config.mesh.conforming);
        if self.gathered.as_ref().map(|g| g.0) == Some(key) {
            return Ok(());
        }
        self.boundary()?;
        let comm = self.comm.clone();
        let (mesh, boundary, faces) = (&self.mesh, &self.boundary, &self.faces);
        let g = self
            .timer
            .time(&*comm, "gather", || match (mesh, boundary, faces) {
                (Some(m), Some((_, b)), Some((_, f))) => {
                    let g = gather(&*comm, m, b);
                    (g, pieces(&*comm, m, f))
                }
                _ => (Ok(Gathered::default()), Vec::new()),
            });
        let (g, sizes) = g;
        let g = agree(&*comm, g)?;
        self.report_phase(None);
        let g = match self.config.mesh.conforming {
            true => self.conforming(g)?,
            false => g,
        };
        self.observer.event(&Event::Pieces(&sizes));
        self.facts.pieces = Some(sizes);
        self.gathered = Some((key, g));
        Ok(())
    }

    /// The conforming mesh of the current mesh's octree and kept leaves
    /// in place of the gathered hanging-node mesh `g`
    /// ([`super::conforming`]), snapped when [`Session::snap`] asked for it
    /// on this mesh (rank 0 snaps it; the report is every rank's). Phases
    /// `conforming` and `snap`.
    fn conforming(&mut self, g: Gathered) -> Result<Gathered> {
        let comm = self.comm.clone();
        self.tree_or_state()?;
        let (Some((tree, domain)), Some(mesh)) = (&self.tree, &self.mesh) else {
            return Err(Error::new(
                ErrorKind::State,
                "there is no mesh yet: build it first",
            ));
        };
        let c = self.timer.time(&*comm, "conforming", || {
            super::conforming::conforming_gathered(
                &*comm,
                tree.leaves(),
                (mesh.elements(), mesh.element_class()),
                domain,
                &g,
            )
        });
        let domain = *domain;
        let (mut c, refined, built) = agree(&*comm, c)?;
        self.report_phase(Some(c.elements.len() as u64));
        // Rank 0 built it: its counts for every rank's observer.
        let mut n = [c.elements.len() as u64, g.elements.len() as u64, refined];
        comm.sum_u64(&mut n);
        self.observer.event(&Event::Conforming {
            hexahedra: n[0],
            elements: n[1],
            refined: n[2],
        });
        let snap = self.conforming_snap.filter(|s| s.0 == self.mesh_generation);
        if let Some((_, opts)) = snap {
            let surface = self.surface.as_ref().map(|_| ()).ok_or_else(|| {
                Error::new(
                    ErrorKind::State,
                    "snapping the conforming mesh needs the surface: load it again (it was \
                     released after meshing)",
                )
            });
            agree(&*comm, surface)?;
            let s = self.surface.as_ref().expect("agreed just now");
            let spare = crate::parallel::cores::spare_core(&*comm);
            let report = self.timer.time(&*comm, "snap", || {
                let local = match comm.rank() {
                    0 => {
                        // The classification's index, if it was made for this cube.
                        let index = (s.index_domain == domain).then_some(&s.index);
                        super::conforming::snap_gathered(
                            &mut c, &built, &domain, &s.surface, index, &opts, spare,
                        )
                    }
                    _ => Ok(SnapReport::default()),
                };
                agree(&*comm, local).map(|r| super::conforming::share_report(&*comm, r))
            })?;
            self.report_phase(Some(report.snapped));
            self.observer.event(&Event::Snapped(&report));
            // The snapped hexahedra's volume, rank 0's for every rank.
            let mut kept = [match comm.rank() {
                0 => c
                    .elements
                    .iter()
                    .map(|h| hexahedron_volume(&h.map(|n| c.coordinates[n as usize])))
                    .sum(),
                _ => f64::NEG_INFINITY,
            }];
            comm.max_f64(&mut kept);
            let e = self.volume_event_of(kept[0], &domain, self.config.mesh.keep, true);
            self.observer.event(&e);
            self.snapped = Some((self.mesh_generation, report));
        }
        Ok(c)
    }

    /// Writes the mesh as one Gmsh MSH 4.1 file ([`crate::io::gmsh`]),
    /// gathered on rank 0, with the session's patch names. Phases `faces`,
    /// `boundary` (when not made yet), `gather` and `gmsh`.
    pub fn write_gmsh(&mut self, path: &Path) -> Result<()> {
        self.write_fe_files(&[(FeFormat::Gmsh, path)])
    }

    /// Writes the mesh as one Abaqus/CalculiX input file
    /// ([`crate::io::abaqus`]: nodes, C3D8 elements, sets and surfaces per
    /// patch, an `*EQUATION` per hanging node and degree of freedom),
    /// gathered on rank 0, with the session's patch names. Phases `faces`,
    /// `boundary` (when not made yet), `gather` and `abaqus`.
    pub fn write_abaqus(&mut self, path: &Path) -> Result<()> {
        self.write_fe_files(&[(FeFormat::Abaqus, path)])
    }

    /// Writes the mesh as one Exodus II file ([`crate::io::exodus`]: element
    /// block `volume`, a side set and a node set per patch, the hanging
    /// nodes' constraints in the node set `hanging` and the variables
    /// `hanging_parents`, `hanging_weights`) through the netCDF library,
    /// gathered on rank 0, with the session's patch names. Phases `faces`,
    /// `boundary` (when not made yet), `gather` and `exodus`.
    pub fn write_exodus(&mut self, path: &Path) -> Result<()> {
        self.write_fe_files(&[(FeFormat::Exodus, path)])
    }

    /// Writes the mesh as one CGNS file ([`crate::io::cgns`]: an
    /// unstructured zone of HEXA_8 elements, per patch a QUAD_4 section, a
    /// boundary condition and a family, the hanging nodes' constraints as
    /// the zone's user data `HangingNodes`) through the CGNS library,
    /// gathered on rank 0, with the session's patch names. Phases `faces`,
    /// `boundary` (when not made yet), `gather` and `cgns`.
    pub fn write_cgns(&mut self, path: &Path) -> Result<()> {
        self.write_fe_files(&[(FeFormat::Cgns, path)])
    }

    /// Gathers the mesh once and has rank 0 write each of `files`, each as
    /// the phase named after its format; every rank returns rank 0's
    /// result. Stops at the first file that fails. Collective.
    pub(super) fn write_fe_files(&mut self, files: &[(FeFormat, &Path)]) -> Result<()> {
        if files.is_empty() {
            return Ok(());
        }
        let patches = agree(&*self.comm, self.patch_names())?;
        self.gather_fe()?;
        let comm = self.comm.clone();
        for &(format, path) in files {
            let g = &self.gathered.as_ref().expect("gathered just now").1;
            self.timer.time(&*comm, format.phase(), || {
                let local = match comm.rank() {
                    0 => format.write(path, g, &patches),
                    _ => Ok(()),
                };
                agree(&*comm, local)
            })?;
            self.report_phase(None);
            self.observer.event(&Event::Wrote(path));
        }
        Ok(())
    }
}

/// A single-file finite-element format written from the gathered mesh.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum FeFormat {
    Gmsh,
    Abaqus,
    Exodus,
    Cgns,
}

impl FeFormat {
    /// The phase that times the writer.
    fn phase(self) -> &'static str {
        match self {
            FeFormat::Gmsh => "gmsh",
            FeFormat::Abaqus => "abaqus",
            FeFormat::Exodus => "exodus",
            FeFormat::Cgns => "cgns",
        }
    }

    /// Writes `g` (rank 0's gathered mesh) to `path`.
    fn write(self, path: &Path, g: &Gathered, patches: &PatchNames) -> Result<()> {
        match self {
            FeFormat::Gmsh => crate::io::gmsh::write_gmsh(path, g, patches).map(|_| ()),
            FeFormat::Abaqus => crate::io::abaqus::write_abaqus(path, g, patches),
            FeFormat::Exodus => crate::io::exodus::write_exodus(path, g, patches).map(|_| ()),
            FeFormat::Cgns => crate::io::cgns::write_cgns(path, g, patches).map(|_| ()),
        }
    }
}
