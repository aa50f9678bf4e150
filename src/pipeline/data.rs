//! User data per leaf in a session (see [`crate::octree::leaf_data`]): attached
//! with a size, kept by the adaptation stages, balance and partition,
//! detached by the stages that build or refine the octree otherwise.

use super::Session;
use crate::error::{Error, ErrorKind, Result};
use crate::octree::leaf_data::{LeafData, ReplaceFn};
use crate::octree::LinearOctree;
use crate::parallel::comm::agree;

impl Session {
    /// Attaches `size` bytes of zeroed data to every local leaf; 0 detaches
    /// it. The same size again keeps the data as it is; another size while
    /// data is attached is an [`ErrorKind::State`] error (detach first).
    /// Needs an octree. Collective.
    pub fn set_leaf_data_size(&mut self, size: usize) -> Result<()> {
        let checked = self.tree_or_state().and_then(|(t, _)| match &self.data {
            Some(d) if d.size() != size && size != 0 => Err(Error::new(
                ErrorKind::State,
                format!(
                    "leaf data of {} bytes per leaf is attached; detach it (size 0) \
                         before attaching {size} bytes",
                    d.size()
                ),
            )),
            _ => Ok(t.local_len()),
        });
        let n = agree(&*self.comm, checked)?;
        match (&self.data, size) {
            (_, 0) => self.data = None,
            (Some(_), _) => {}
            (None, _) => self.data = Some(LeafData::new(size, n)),
        }
        Ok(())
    }

    /// The attached leaf data, one entry per local leaf in Morton order.
    pub fn leaf_data(&self) -> Option<&LeafData> {
        self.data.as_ref()
    }

    /// The attached leaf data, to write.
    pub fn leaf_data_mut(&mut self) -> Option<&mut LeafData> {
        self.data.as_mut()
    }
}

/// Runs `op` (leaves change in place) keeping `data` through `replace`
/// when either is there; without both, just `op`.
pub(super) fn changing<T>(
    tree: &mut LinearOctree,
    data: &mut Option<LeafData>,
    replace: Option<ReplaceFn>,
    op: impl FnOnce(&mut LinearOctree) -> Result<T>,
) -> Result<T> {
    let mut zero = |_: crate::octree::leaf_data::Replace<'_>| Ok(());
    match (data, replace) {
        (None, None) => op(tree),
        (Some(d), r) => tree.change_with_data(d, r.unwrap_or(&mut zero), op),
        (None, Some(r)) => tree.change_with_data(&mut LeafData::for_tree(tree, 0), r, op),
    }
}

/// Runs `op` (leaves move between ranks) moving `data` with them.
pub(super) fn moving<T>(
    tree: &mut LinearOctree,
    data: &mut Option<LeafData>,
    op: impl FnOnce(&mut LinearOctree) -> Result<T>,
) -> Result<T> {
    match data {
        None => op(tree),
        Some(d) => tree.move_with_data(d, op),
    }
}
