//! Stages: saving the octree to a checkpoint and loading one
//! ([`crate::octree::checkpoint`]).

use std::path::Path;

use super::*;

impl Session {
    /// Saves the octree, its domain and the attached leaf data to the
    /// checkpoint `path`, one file written by all ranks, with the hash of
    /// the session's surface (0 without one). Collective. Phase `save`.
    pub fn save_octree(&mut self, path: &Path) -> Result<()> {
        agree(&*self.comm, self.tree_or_state().map(|_| ()))?;
        let comm = self.comm.clone();
        let hash = self.surface_hash.unwrap_or(0);
        let (tree, data) = (self.tree.as_ref(), self.data.as_ref());
        self.timer.time(&*comm, "save", || match tree {
            Some((t, d)) => t.save(path, d, data, hash),
            None => Ok(()),
        })?;
        let n = self.tree().map(|t| t.forest_len());
        self.report_phase(n);
        Ok(())
    }

    /// Replaces the octree by the one of the checkpoint `path`, in its
    /// domain and the equal-count partition, with its leaf data attached
    /// when it holds some. With a surface loaded, refuses a checkpoint
    /// saved from another surface ([`crate::Surface::hash`]). Collective.
    /// Phase `load`; on failure the session is as it was.
    pub fn load_octree(&mut self, path: &Path) -> Result<()> {
        let comm = self.comm.clone();
        let hash = self.surface.as_ref().and(self.surface_hash);
        let loaded = self.timer.time(&*comm, "load", || {
            crate::octree::LinearOctree::load(comm.clone(), path, hash)
        })?;
        self.set_tree(loaded.tree, loaded.info.domain);
        self.data = loaded.data;
        let n = self.tree().map_or(0, |t| t.forest_len());
        self.facts.octants_refined = n;
        self.facts.octants_balanced = n;
        self.report_phase(Some(n));
        Ok(())
    }
}
