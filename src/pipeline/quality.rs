//! Stage: the mesh's quality ([`crate::mesh::quality`]), measured only when
//! a run asks for it (`--stats`, `--quality-out`).

use crate::error::Result;
use crate::io::vtu::write_worst_vtu;
use crate::mesh::quality::{hexahedra_quality, worst_hexahedra, Quality};
use crate::parallel::comm::agree;

use super::*;

impl Session {
    /// Measures the current mesh's quality: the scaled Jacobian of each
    /// element from its nodes, and `checkMesh`'s non-orthogonality and
    /// skewness over the faces (measured as they are made, not stored; on
    /// a snapped mesh, on the moved points);
    /// with `output.quality_out` also writes the worst elements
    /// there (rank 0). Collective; the figures are the same on every rank.
    /// Phase `quality`.
    ///
    /// With `mesh.conforming` it measures the conforming mesh rank 0
    /// builds ([`crate::mesh::conforming`]), gathered as for the single-file
    /// writers (phases `gather` and `conforming` when not made yet), by
    /// [`hexahedra_quality`]: the same figures on any number of ranks.
    pub fn quality(&mut self) -> Result<Quality> {
        self.mesh_or_state()?;
        if self.config.mesh.conforming {
            self.gather_fe()?;
        }
        let comm = self.comm.clone();
        let out = self.config.output.quality_out.clone();
        let worst = self.config.output.quality_worst() as usize;
        let mesh = &self.mesh;
        let conforming = match (&self.gathered, self.config.mesh.conforming) {
            (Some((_, g)), true) => Some(g),
            _ => None,
        };
        let measured = self.timer.time(&*comm, "quality", || {
            if let Some(g) = conforming {
                let (q, jac) = hexahedra_quality(&*comm, &g.coordinates, &g.elements);
                if let Some(path) = &out {
                    let wrote = if comm.rank() == 0 {
                        let cells = (&g.element_level[..], &g.element_class[..]);
                        let list = worst_hexahedra(&g.coordinates, &g.elements, &jac, cells, worst);
                        write_worst_vtu(path, &list)
                    } else {
                        Ok(())
                    };
                    agree(&*comm, wrote)?;
                }
                return Ok(q);
            }
            let Some(m) = mesh else {
                return Ok(Quality::default());
            };
            // The nodes are where the octree put them (corners from the
            // elements, no node array) or, on a snapped mesh, where the
            // snap moved them.
            let (q, jac) = m.quality(&*comm, None)?;
            if let Some(path) = &out {
                let list = m.worst_elements(&*comm, None, &jac, worst);
                let wrote = if comm.rank() == 0 {
                    write_worst_vtu(path, &list)
                } else {
                    Ok(())
                };
                agree(&*comm, wrote)?;
            }
            Ok(q)
        });
        let q = agree(&*comm, measured)?;
        self.report_phase(Some(q.elements));
        self.observer.event(&Event::Quality(&q));
        if let Some(path) = &out {
            self.observer.event(&Event::Wrote(path));
        }
        self.quality = Some((self.mesh_generation, q.clone()));
        Ok(q)
    }

    /// The current mesh's quality if [`Session::quality`] measured it (not
    /// collective).
    pub fn current_quality(&self) -> Option<&Quality> {
        self.quality
            .as_ref()
            .filter(|q| q.0 == self.mesh_generation)
            .map(|q| &q.1)
    }
}
