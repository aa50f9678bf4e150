//! Stages: the single-file finite-element meshes (Gmsh, Abaqus/CalculiX).

use std::path::Path;

use crate::io::gathered::{gather, Gathered};
use crate::mesh::patches::PatchNames;
use crate::parallel::comm::agree;

use super::*;

impl Session {
    /// The current mesh and its boundary gathered on rank 0
    /// ([`crate::io::gathered`]); empty on the other ranks. Phases `faces`
    /// and `boundary` (when not made yet) and `gather`.
    fn gathered(&mut self) -> Result<Gathered> {
        self.boundary()?;
        let comm = self.comm.clone();
        let (mesh, boundary) = (&self.mesh, &self.boundary);
        let g = self
            .timer
            .time(&*comm, "gather", || match (mesh, boundary) {
                (Some(m), Some((_, b))) => gather(&*comm, m, b),
                _ => Ok(Gathered::default()),
            });
        let g = agree(&*comm, g)?;
        self.report_phase(None);
        Ok(g)
    }

    /// Writes the mesh as one Gmsh MSH 4.1 file ([`crate::io::gmsh`]),
    /// gathered on rank 0, with the session's patch names. Phases `faces`,
    /// `boundary` (when not made yet), `gather` and `gmsh`.
    pub fn write_gmsh(&mut self, path: &Path) -> Result<()> {
        self.write_gathered(path, "gmsh", |g, patches| {
            crate::io::gmsh::write_gmsh(path, g, patches).map(|_| ())
        })
    }

    /// Writes the mesh as one Abaqus/CalculiX input file
    /// ([`crate::io::abaqus`]: nodes, C3D8 elements, sets and surfaces per
    /// patch, an `*EQUATION` per hanging node and degree of freedom),
    /// gathered on rank 0, with the session's patch names. Phases `faces`,
    /// `boundary` (when not made yet), `gather` and `abaqus`.
    pub fn write_abaqus(&mut self, path: &Path) -> Result<()> {
        self.write_gathered(path, "abaqus", |g, patches| {
            crate::io::abaqus::write_abaqus(path, g, patches)
        })
    }

    /// Gathers the mesh and has rank 0 `write` it as phase `phase`; every
    /// rank returns rank 0's result. Collective.
    fn write_gathered(
        &mut self,
        path: &Path,
        phase: &str,
        write: impl FnOnce(&Gathered, &PatchNames) -> Result<()>,
    ) -> Result<()> {
        let patches = agree(&*self.comm, self.patch_names())?;
        let g = self.gathered()?;
        let comm = self.comm.clone();
        self.timer.time(&*comm, phase, || {
            let local = match comm.rank() {
                0 => write(&g, &patches),
                _ => Ok(()),
            };
            agree(&*comm, local)
        })?;
        self.report_phase(None);
        self.observer.event(&Event::Wrote(path));
        Ok(())
    }
}
