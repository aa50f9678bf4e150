//! Stages for moving a solver's fields across an adaptation step: the mesh
//! before the step is kept (when asked) until the next one, and the element
//! map and transfers run between it and the current mesh (see
//! [`crate::mesh::transfer`]).

use super::{report, Session};
use crate::error::{Error, ErrorKind, Result};
use crate::mesh::{transfer_elements, transfer_nodes, ElementMap, Mesh};
use crate::parallel::comm::{agree, Comm};

/// The previous mesh and what was computed against it.
#[derive(Debug, Default)]
pub(super) struct Previous {
    /// Whether a replaced mesh is kept.
    keep: bool,
    mesh: Option<Mesh>,
    /// The element map to the mesh of a generation.
    map: Option<(u64, ElementMap)>,
}

impl Session {
    /// Keeps (`true`) or stops keeping the mesh that a change of the octree
    /// or a new mesh replaces, so that fields can be moved from it to the
    /// next mesh ([`Session::transfer_nodes`]). Off by default: the kept
    /// mesh costs about as much memory as the current one. Turning it off
    /// drops a kept mesh. Local (every rank should call it alike).
    pub fn keep_previous_mesh(&mut self, keep: bool) {
        self.previous.keep = keep;
        if !keep {
            self.previous = Default::default();
        }
    }

    /// The kept previous mesh, if any.
    pub fn previous_mesh(&self) -> Option<&Mesh> {
        self.previous.mesh.as_ref()
    }

    /// Drops the current mesh, keeping it as the previous one when asked.
    pub(super) fn drop_mesh(&mut self) {
        match self.mesh.take() {
            Some(m) if self.previous.keep => {
                self.previous.mesh = Some(m);
                self.previous.map = None;
            }
            _ => {}
        }
    }

    /// Runs `f` on the previous and the current mesh as phase `transfer`,
    /// or returns a state error on every rank.
    fn with_pair<T>(&mut self, f: impl FnOnce(&dyn Comm, &Mesh, &Mesh) -> Result<T>) -> Result<T> {
        let local = match (&self.previous.mesh, &self.mesh) {
            (Some(old), Some(new)) => Ok((old, new)),
            (None, _) if !self.previous.keep => Err(Error::new(
                ErrorKind::State,
                "no previous mesh: ask to keep it before the octree changes",
            )),
            (None, _) => Err(Error::new(
                ErrorKind::State,
                "no previous mesh: build a mesh, change the octree, then build the new mesh",
            )),
            (Some(_), None) => Err(Error::new(
                ErrorKind::State,
                "there is no mesh: build the new mesh first",
            )),
        };
        let (old, new) = agree(&*self.comm, local)?;
        let comm = self.comm.clone();
        let out = self
            .timer
            .time(&*comm, "transfer", || f(&*comm, old, new))?;
        report(&self.timer, &mut *self.observer, None);
        Ok(out)
    }

    /// Where each current element came from in the previous mesh (computed
    /// on first need). Collective. Phase `transfer`.
    pub fn element_map(&mut self) -> Result<&ElementMap> {
        let gen = self.mesh_generation;
        if self.previous.map.as_ref().map(|m| m.0) != Some(gen) {
            let map = self.with_pair(ElementMap::new)?;
            self.previous.map = Some((gen, map));
        }
        Ok(&self.previous.map.as_ref().expect("just computed").1)
    }

    /// An element field of the previous mesh (`ncomp` values per element)
    /// on the current mesh's elements ([`transfer_elements`]: copied on
    /// refinement, volume mean on coarsening). Collective. Phase `transfer`.
    pub fn transfer_elements(&mut self, ncomp: usize, values: &[f64]) -> Result<Vec<f64>> {
        self.with_pair(|comm, old, new| transfer_elements(comm, old, new, ncomp, values))
    }

    /// A trilinear nodal field of the previous mesh (`ncomp` values per
    /// local node) evaluated at the current mesh's nodes
    /// ([`transfer_nodes`]), with the number of nodes (over all ranks) that
    /// no previous element holds (their values are NaN). Collective. Phase
    /// `transfer`.
    pub fn transfer_nodes(&mut self, ncomp: usize, values: &[f64]) -> Result<(Vec<f64>, u64)> {
        self.with_pair(|comm, old, new| transfer_nodes(comm, old, new, ncomp, values))
    }
}
