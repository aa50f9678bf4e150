//! The limits checked wherever octants are made (refinement, balance,
//! adaptation): the deepest level, and the number of octants a run may hold
//! over all ranks.

use crate::error::{Error, ErrorKind, Result};
use crate::octree::octant::MAX_LEVEL;
use crate::parallel::comm::CommRef;

/// No limit on the number of octants.
pub const NO_LIMIT: u64 = u64::MAX;

/// Fails unless `level` is at most [`MAX_LEVEL`].
pub fn check_level(level: u8) -> Result<()> {
    if level > MAX_LEVEL {
        return Err(Error::invalid(format!(
            "level {level} is above the maximum level {MAX_LEVEL}"
        )));
    }
    Ok(())
}

/// The error of an octant limit reached `during` a phase ("refining").
pub(crate) fn limit_error(limit: u64, during: &str) -> Error {
    Error::new(
        ErrorKind::Limit,
        format!(
            "the octree would exceed the limit of {limit} octants (stopped while {during}); \
             raise the limit or lower the level"
        ),
    )
}

/// Fails with [`limit_error`] when the ranks hold more than `limit` octants
/// together. Collective.
pub(crate) fn global_limit(comm: &CommRef, local: usize, limit: u64) -> Result<()> {
    let mut n = [local as u64];
    comm.sum_u64(&mut n);
    if n[0] > limit {
        return Err(limit_error(limit, "refining"));
    }
    Ok(())
}
