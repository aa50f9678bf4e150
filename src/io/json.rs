//! JSON files: statistics and surface reports, written by rank 0 through
//! serde.

use std::path::Path;

use serde::Serialize;

use crate::error::{Error, Result};
use crate::parallel::comm::{agree, Comm};

/// Writes `value` as pretty JSON to `path` on rank 0; a failure there is
/// reported on every rank. Collective.
pub fn write_json(comm: &dyn Comm, path: &Path, value: &impl Serialize) -> Result<()> {
    let written = if comm.rank() == 0 {
        serde_json::to_string_pretty(value)
            .map_err(|e| Error::new(crate::ErrorKind::Internal, format!("JSON: {e}")))
            .and_then(|text| {
                std::fs::write(path, text + "\n")
                    .map_err(|e| Error::io(format!("cannot write '{}': {e}", path.display())))
            })
    } else {
        Ok(())
    };
    agree(comm, written)
}
