//! Stages: the mesh and its files.

use std::path::Path;

use crate::classify::{CutRule, Keep};
use crate::comm::agree;
use crate::error::{Error, ErrorKind, Result};
use crate::io::vtu::write_mesh;
use crate::mesh::{Mesh, MeshOptions};

use super::*;

impl Session {
    /// Builds the mesh of the leaves that `keep` selects, classified against
    /// the surface with the session's inside rule when there is a surface
    /// (without one only [`Keep::All`] is allowed). The octree must be
    /// balanced for edge or corner contacts. Phases `ghost`, `nodes`,
    /// `numbering`, `connectivity`.
    pub fn build_mesh(&mut self, keep: Keep, cut_rule: CutRule) -> Result<()> {
        agree(&*self.comm, self.tree_or_state().map(|_| ()))?;
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
        let mesh = Mesh::build(tree, domain, classes, &MeshOptions { keep, cut_rule });
        drop(shown);
        let mesh = mesh?;
        self.timer.append(mesh.phase_timer());
        let c = *mesh.counts();
        for (name, seconds) in mesh.timings() {
            let count = match name.as_str() {
                "ghost" => Some(c.ghosts),
                "nodes" => Some(c.independent_nodes + c.face_hanging_nodes + c.edge_hanging_nodes),
                "connectivity" => Some(c.elements),
                _ => None,
            };
            self.observer.event(&Event::Phase {
                name,
                seconds: *seconds,
                count,
            });
        }
        let mut cells = [mesh.local_volume_cells()];
        self.comm.sum_u64(&mut cells);
        self.observer.event(&Event::Meshed {
            counts: c,
            kept_volume: mesh.cells_to_volume(cells[0]),
            surface_volume: self.surface_volume(),
        });
        self.mesh = Some(mesh);
        self.mesh_generation += 1;
        Ok(())
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
    pub fn write_vtu(&mut self, pvtu: &Path, fields: &[(&str, &[f64])]) -> Result<()> {
        let local = self
            .mesh
            .as_ref()
            .map(|_| ())
            .ok_or_else(|| Error::new(ErrorKind::State, "there is no mesh: build it first"));
        agree(&*self.comm, local)?;
        let comm = self.comm.clone();
        let mesh = &self.mesh;
        self.timer.time(&*comm, "write", || match mesh {
            Some(m) => write_mesh(&*comm, pvtu, m, fields).map(|_| ()),
            None => Ok(()),
        })?;
        self.report_phase(None);
        self.observer.event(&Event::Wrote(pvtu));
        Ok(())
    }
}
