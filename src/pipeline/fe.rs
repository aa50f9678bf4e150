//! Stages: the single-file finite-element meshes (Gmsh, Abaqus/CalculiX).

use std::path::Path;

use crate::io::gathered::{gather, Gathered};
use crate::mesh::patches::PatchNames;
use crate::parallel::comm::agree;

use super::*;

impl Session {
    /// Gathers the current mesh and its boundary on rank 0
    /// ([`crate::io::gathered`]), once per mesh: every single-file writer
    /// of the same mesh uses the same copy. Reports the mesh's pieces
    /// ([`Event::Pieces`]). Phases `faces` and `boundary` (when not made
    /// yet) and `gather`.
    fn gather(&mut self) -> Result<()> {
        if self.gathered.as_ref().map(|g| g.0) == Some(self.mesh_generation) {
            return Ok(());
        }
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
        // Rank 0 has the mesh: it counts the pieces and tells the others.
        let mut sizes = g.pieces();
        let mut n = [sizes.len() as u64];
        comm.max_u64(&mut n);
        sizes.resize(n[0] as usize, 0);
        comm.max_u64(&mut sizes);
        self.observer.event(&Event::Pieces(&sizes));
        self.facts.pieces = Some(sizes);
        self.gathered = Some((self.mesh_generation, g));
        Ok(())
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
        self.gather()?;
        let comm = self.comm.clone();
        let g = &self.gathered.as_ref().expect("gathered just now").1;
        self.timer.time(&*comm, phase, || {
            let local = match comm.rank() {
                0 => write(g, &patches),
                _ => Ok(()),
            };
            agree(&*comm, local)
        })?;
        self.report_phase(None);
        self.observer.event(&Event::Wrote(path));
        Ok(())
    }
}
