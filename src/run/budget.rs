//! The memory budget: a run that would not fit in memory stops with a clear
//! error on every rank instead of being killed by the kernel.
//!
//! The budget is per rank: the caller's (`--memory-budget`, the C option
//! `memory_budget`), or else the memory available on the node (the smaller
//! of `MemAvailable` and the cgroup's limit less its usage) shared equally
//! among the ranks on that node. A run is expected to need, per rank,
//!
//! ```text
//!   BASE_BYTES + triangles x BYTES_PER_TRIANGLE            (process, MPI, surface, index)
//!   + octants / ranks x bytes per octant                   (BYTES_PER_OCTANT_OCTREE or _MESH)
//! ```
//!
//! with per-octant figures above the peaks measured on the benchmark
//! machine (sphere level 10 and bunny level 9 on 1 and 2 ranks: octree 8 to
//! 14 bytes per balanced octant over the memory after reading, mesh 19 to
//! 53). Before refining, the estimate of the octree's size is checked
//! against the budget; during the run the budget becomes an octant limit
//! ([`MemoryBudget::octant_limit`]) that refinement and balance check
//! before they allocate, so an underestimate ends in the same error.

use std::fmt;

use serde::{Deserialize, Serialize};

use crate::error::{Error, ErrorKind, Result};

/// Memory of the process, MPI and the surface's fixed part, per rank.
pub const BASE_BYTES: u64 = 64 << 20;
/// Memory per triangle of the surface (triangles, welded copy for the
/// diagnostics, lattice copy, bounding-box tree), on every rank.
pub const BYTES_PER_TRIANGLE: u64 = 512;
/// Peak memory per balanced octant for an octree alone.
pub const BYTES_PER_OCTANT_OCTREE: u64 = 24;
/// Peak memory per balanced octant when the mesh is built.
pub const BYTES_PER_OCTANT_MESH: u64 = 80;

/// A number of bytes, written with a binary unit (`50MiB`, `4 GiB`, `512k`)
/// or as a plain integer.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct ByteSize(pub u64);

impl ByteSize {
    /// Parses `123`, `64k`, `50MiB`, `1.5 G`, `2TB` (k, M, G, T are powers
    /// of 1024, with or without `i` and `B`).
    pub fn parse(s: &str) -> Result<ByteSize> {
        let t = s.trim();
        let split = t
            .find(|c: char| !(c.is_ascii_digit() || c == '.'))
            .unwrap_or(t.len());
        let (num, unit) = t.split_at(split);
        let shift = match unit.trim().to_ascii_lowercase().as_str() {
            "" | "b" => 0,
            "k" | "kb" | "kib" => 10,
            "m" | "mb" | "mib" => 20,
            "g" | "gb" | "gib" => 30,
            "t" | "tb" | "tib" => 40,
            _ => return Err(bad_size(s)),
        };
        let x: f64 = num.parse().map_err(|_| bad_size(s))?;
        let bytes = x * (1u64 << shift) as f64;
        if !(bytes.is_finite() && bytes >= 1.0 && bytes < u64::MAX as f64) {
            return Err(bad_size(s));
        }
        Ok(ByteSize(bytes as u64))
    }
}

fn bad_size(s: &str) -> Error {
    Error::invalid(format!(
        "expects a size in bytes such as 512MiB or 4GiB, got '{s}'"
    ))
}

impl std::str::FromStr for ByteSize {
    type Err = Error;
    fn from_str(s: &str) -> Result<ByteSize> {
        ByteSize::parse(s)
    }
}

impl fmt::Display for ByteSize {
    /// The size in the largest binary unit not above it, whole when exact,
    /// else with one decimal place (`50 MiB`, `1.5 GiB`, `600.5 GiB`).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let b = self.0;
        for (shift, unit) in [(40, "TiB"), (30, "GiB"), (20, "MiB"), (10, "KiB")] {
            if b >= 1 << shift {
                return if b.is_multiple_of(1 << shift) {
                    write!(f, "{} {unit}", b >> shift)
                } else {
                    write!(f, "{:.1} {unit}", b as f64 / (1u64 << shift) as f64)
                };
            }
        }
        write!(f, "{b} B")
    }
}

impl Serialize for ByteSize {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.serialize_str(&self.to_string())
    }
}

impl<'de> Deserialize<'de> for ByteSize {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<ByteSize, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Raw {
            Int(u64),
            Text(String),
        }
        match Raw::deserialize(d)? {
            Raw::Int(0) => Err(serde::de::Error::custom("must be at least 1 byte")),
            Raw::Int(n) => Ok(ByteSize(n)),
            Raw::Text(t) => ByteSize::parse(&t).map_err(|e| serde::de::Error::custom(e.message())),
        }
    }
}

/// Where a budget came from, for its messages.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BudgetSource {
    /// Given by the caller.
    Given,
    /// The node's available memory shared among its ranks.
    Available {
        /// Bytes available on the node.
        node: u64,
        /// Ranks of the run on the node.
        ranks_on_node: usize,
    },
}

/// Bytes one rank may use, and the run's figures to turn it into octants.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MemoryBudget {
    /// Bytes per rank.
    pub per_rank: u64,
    /// Where the figure came from.
    pub source: BudgetSource,
    /// Ranks of the run.
    pub ranks: usize,
    /// Memory per rank before any octant: [`BASE_BYTES`] and the surface.
    pub base: u64,
    /// Peak bytes per octant of the run's later phases.
    pub bytes_per_octant: u64,
}

impl MemoryBudget {
    /// The largest number of octants, over all ranks, that fits.
    pub fn octant_limit(&self) -> u64 {
        let room = self.per_rank.saturating_sub(self.base) as u128;
        (room * self.ranks as u128 / self.bytes_per_octant.max(1) as u128).min(u64::MAX as u128)
            as u64
    }

    /// The bytes per rank a run with `octants` octants over all ranks is
    /// expected to need.
    pub fn need(&self, octants: u64) -> u64 {
        let per_rank = octants as u128 * self.bytes_per_octant as u128 / self.ranks.max(1) as u128;
        (self.base as u128 + per_rank).min(u64::MAX as u128) as u64
    }

    /// Says where the budget came from.
    pub fn describe(&self) -> String {
        match self.source {
            BudgetSource::Given => format!("the budget of {} per rank", ByteSize(self.per_rank)),
            BudgetSource::Available {
                node,
                ranks_on_node,
            } => format!(
                "the budget of {} per rank (the node's available memory, {}, shared by its {} \
                 rank(s); raise it with --memory-budget)",
                ByteSize(self.per_rank),
                ByteSize(node),
                ranks_on_node
            ),
        }
    }

    /// The error of a run over budget. `what` says what was counted
    /// (`"about 16.1 G octants are estimated at level 16"`) and `fits` which
    /// level would fit.
    pub fn error(&self, octants: u64, what: &str, fits: &str) -> Error {
        Error::new(
            ErrorKind::Limit,
            format!(
                "memory budget: {what}, which needs about {} per rank ({} + {octants} octants x \
                 {} B / {} rank(s)), more than {}; {fits}; lower the level or raise \
                 --memory-budget",
                ByteSize(self.need(octants)),
                ByteSize(self.base),
                self.bytes_per_octant,
                self.ranks,
                self.describe()
            ),
        )
    }
}

/// Bytes of memory available to this process's node now: the smaller of
/// `MemAvailable` and, inside a memory-limited cgroup, its limit less its
/// usage. `None` when neither can be read.
pub fn available_on_node() -> Option<u64> {
    let meminfo = std::fs::read_to_string("/proc/meminfo").ok().and_then(|t| {
        t.lines()
            .find(|l| l.starts_with("MemAvailable:"))
            .and_then(|l| l.split_whitespace().nth(1)?.parse::<u64>().ok())
            .map(|kib| kib * 1024)
    });
    let read = |p: &str| -> Option<u64> { std::fs::read_to_string(p).ok()?.trim().parse().ok() };
    // cgroup v2, then v1; "max" (no limit) does not parse and is skipped.
    let cgroup = read("/sys/fs/cgroup/memory.max")
        .map(|max| max.saturating_sub(read("/sys/fs/cgroup/memory.current").unwrap_or(0)))
        .or_else(|| {
            let limit = read("/sys/fs/cgroup/memory/memory.limit_in_bytes")?;
            let used = read("/sys/fs/cgroup/memory/memory.usage_in_bytes").unwrap_or(0);
            // v1 reports "no limit" as a huge number.
            (limit < 1 << 60).then(|| limit.saturating_sub(used))
        });
    match (meminfo, cgroup) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_and_print() {
        assert_eq!(ByteSize::parse("50MiB").unwrap(), ByteSize(50 << 20));
        assert_eq!(ByteSize::parse("4 G").unwrap(), ByteSize(4 << 30));
        assert_eq!(ByteSize::parse("1.5GiB").unwrap(), ByteSize(3 << 29));
        assert_eq!(ByteSize::parse("4096").unwrap(), ByteSize(4096));
        assert!(ByteSize::parse("lots").is_err());
        assert!(ByteSize::parse("-1G").is_err());
        assert!(ByteSize::parse("0").is_err());
        assert_eq!(ByteSize(50 << 20).to_string(), "50 MiB");
        assert_eq!(ByteSize(3 << 29).to_string(), "1.5 GiB");
        assert_eq!(ByteSize(1000).to_string(), "1000 B");
        let t: toml::Table = toml::from_str("a = \"2GiB\"\nb = 1024").unwrap();
        let a: ByteSize = t["a"].clone().try_into().unwrap();
        let b: ByteSize = t["b"].clone().try_into().unwrap();
        assert_eq!((a, b), (ByteSize(2 << 30), ByteSize(1024)));
    }

    #[test]
    fn limit_and_need_agree() {
        let b = MemoryBudget {
            per_rank: 1 << 30,
            source: BudgetSource::Given,
            ranks: 2,
            base: 64 << 20,
            bytes_per_octant: 80,
        };
        let n = b.octant_limit();
        assert!(b.need(n) <= b.per_rank && b.need(n + 2) > b.per_rank);
        assert!(available_on_node().is_some_and(|a| a > 0));
        let e = b.error(n * 2, "about 2 octants", "level 3 would fit");
        assert!(
            e.message()
                .contains("more than the budget of 1 GiB per rank"),
            "{e}"
        );
    }
}
