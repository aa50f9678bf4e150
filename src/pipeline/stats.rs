//! The statistics of a run (`--stats FILE.json`): counts, timings, memory
//! and traffic per phase, as one serde structure.
//!
//! Times are seconds, the maximum over ranks; memory is bytes, the maximum
//! over ranks; traffic is bytes (see each field). Optional parts are left
//! out when the run did not make them.

use serde::ser::SerializeMap;
use serde::{Serialize, Serializer};

use super::Session;
use crate::classify::{CutRule, InsideRule, Keep};
use crate::config::{Balance, Command};
use crate::geometry::diagnostics::SurfaceReport;
use crate::mesh::quality::Quality;
use crate::mesh::MeshCounts;
use crate::parallel::comm::Traffic;
use crate::run::report::peak_rss_bytes;

/// Values per phase, serialised as a JSON object in the order the phases
/// ran.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PerPhase<T>(pub Vec<(String, T)>);

impl<T: Serialize> Serialize for PerPhase<T> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut m = s.serialize_map(Some(self.0.len()))?;
        for (k, v) in &self.0 {
            m.serialize_entry(k, v)?;
        }
        m.end()
    }
}

/// The surface's diagnostics in the statistics, under `surface`.
#[derive(Clone, Debug, Serialize)]
pub struct SurfaceStats {
    /// Facets.
    pub triangles: u64,
    /// Edges used by one facet.
    pub boundary_edges: u64,
    /// Edges used by more than two facets.
    pub non_manifold_edges: u64,
    /// Edge-connected components.
    pub components: u64,
    /// Closed and consistently oriented.
    pub closed: bool,
}

impl From<&SurfaceReport> for SurfaceStats {
    fn from(r: &SurfaceReport) -> SurfaceStats {
        SurfaceStats {
            triangles: r.triangles as u64,
            boundary_edges: r.boundary_edges as u64,
            non_manifold_edges: r.non_manifold_edges as u64,
            components: r.components as u64,
            closed: r.closed,
        }
    }
}

/// The leak check, under `leak`.
#[derive(Clone, Debug, Default, Serialize)]
pub struct LeakStats {
    /// Whether a check ran.
    pub checked: bool,
    /// Whether the outside reached the inside point.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub found: Option<bool>,
    /// Octants on the leak's path (0 when none).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub path_octants: Option<u64>,
}

/// The mesh's counts (global), flattened into the statistics.
#[derive(Clone, Debug, Serialize)]
pub struct MeshStats {
    /// Elements, nodes of each kind, ghosts (see [`MeshCounts`]).
    #[serde(flatten)]
    pub counts: MeshCounts,
    /// Nodes over all ranks' pieces, shared nodes once per rank (what a VTU
    /// holds).
    pub points_written: u64,
    /// Volume of the kept elements, user units: of the moved elements
    /// after a snap, else of the octree's cubes.
    pub kept_volume: f64,
    /// The octree's cubes kept, in finest-lattice cells.
    pub kept_cells: u64,
    /// Which leaves were kept.
    pub keep: Keep,
    /// The rule for leaves touching the surface.
    pub cut_rule: CutRule,
    /// The zones with their elements, in zone order, when the mesh has
    /// zones ([`crate::mesh::zones`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub zones: Option<Vec<ZoneStats>>,
}

/// One zone of the mesh, under `zones`.
#[derive(Clone, Debug, Serialize)]
pub struct ZoneStats {
    /// Its name.
    pub name: String,
    /// Its elements over all ranks.
    pub elements: u64,
}

/// Bytes exchanged: sent and received over all ranks, under
/// `comm_bytes_sum`.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct TrafficSum {
    /// Bytes sent by all ranks.
    pub sent: u64,
    /// Bytes received by all ranks (equal when every message arrived).
    pub received: u64,
}

/// The two partitions of a run, under `partition_timings`.
pub type PartitionTimings = PerPhase<f64>;

/// The statistics of a run. The keys are stable: scripts read them.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Stats {
    /// `octree` or `mesh`.
    pub command: Option<Command>,
    /// The surface file as given.
    pub surface_file: String,
    /// The surface's diagnostics (when computed: always with `--stats`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub surface: Option<SurfaceStats>,
    /// MPI ranks.
    pub ranks: u64,
    /// Triangles after clean-up.
    pub triangles: u64,
    /// Whether each rank held only the triangles near its leaves
    /// (`--distributed-surface`).
    pub distributed_surface: bool,
    /// The most triangles a rank's surface index held (the largest over
    /// the ranks).
    pub triangles_held: u64,
    /// Level of the leaves touching the surface.
    pub level: u8,
    /// The balance applied.
    pub balance: Balance,
    /// Leaves after refinement.
    pub octants_refined: u64,
    /// Leaves after balance.
    pub octants_balanced: u64,
    /// The estimate of the final leaf count (balanced when balancing).
    pub estimated_octants: u64,
    /// The estimate of the refined leaf count.
    pub estimated_octants_refined: u64,
    /// The inside rule classified with, when one was asked for (for `auto`,
    /// its choice).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub inside_rule: Option<InsideRule>,
    /// Facets the winding rule reversed.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reversed_facets: Option<u64>,
    /// Holes the winding rule capped.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub boundary_loops: Option<u64>,
    /// Leaves inside, for octrees classified on request.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub inside_leaves: Option<u64>,
    /// Leaves outside.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub outside_leaves: Option<u64>,
    /// Leaves touching the surface.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cut_leaves: Option<u64>,
    /// The leak check.
    pub leak: LeakStats,
    /// The mesh, for meshes.
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    pub mesh: Option<MeshStats>,
    /// The mesh's quality, when measured (see [`crate::mesh::quality`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub quality: Option<Quality>,
    /// The sizes of the mesh's pieces joined through faces, largest
    /// first, when a single-file writer gathered it
    /// ([`crate::mesh::pieces`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pieces: Option<Vec<u64>>,
    /// What the snap did, when the mesh was snapped (see
    /// [`crate::mesh::snap`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub snap: Option<crate::mesh::snap::SnapReport>,
    /// The boundary layers of the OpenFOAM case, when it got them (see
    /// [`crate::io::openfoam::LayerReport`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub layers: Option<crate::io::openfoam::LayerReport>,
    /// Volume enclosed by the surface, user units.
    pub surface_volume: f64,
    /// Facets the clean-up dropped.
    pub dropped_facets: u64,
    /// Seconds per phase, maximum over ranks.
    pub timings: PerPhase<f64>,
    /// Seconds of the partition after refinement and after balance.
    pub partition_timings: PartitionTimings,
    /// Bytes sent plus received per phase, maximum over ranks.
    pub comm_bytes: PerPhase<u64>,
    /// Bytes sent per phase, maximum over ranks.
    pub comm_bytes_sent: PerPhase<u64>,
    /// Bytes received per phase, maximum over ranks.
    pub comm_bytes_received: PerPhase<u64>,
    /// Collective operations per phase, maximum over ranks (the same on
    /// every rank; see `Comm::collectives`).
    pub comm_calls: PerPhase<u64>,
    /// Bytes over all ranks.
    pub comm_bytes_sum: TrafficSum,
    /// Seconds inside collectives per phase, minimum over ranks.
    pub comm_seconds_min: PerPhase<f64>,
    /// Seconds inside collectives per phase, maximum over ranks.
    pub comm_seconds_max: PerPhase<f64>,
    /// Peak resident memory, bytes, maximum over ranks.
    pub peak_rss_bytes: u64,
    /// Peak resident memory at the end of each phase, maximum over ranks:
    /// the phase where it grows set the peak.
    pub peak_rss_after: PerPhase<u64>,
    /// Peak memory when the session started.
    pub rss_start_bytes: u64,
    /// Peak memory after reading the surface.
    pub rss_after_read_bytes: u64,
    /// With a distributed surface, the same after the triangles near each
    /// rank's chunk arrived and were indexed, before the octree is built
    /// (the surface's whole cost on a rank).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rss_after_distribute_bytes: Option<u64>,
    /// Side of the root cube, user units.
    pub domain_side: f64,
    /// The memory budget per rank, bytes, when one was known.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub memory_budget_bytes: Option<u64>,
    /// The octants that fit in it, over all ranks.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub memory_budget_octants: Option<u64>,
}

impl Session {
    /// The statistics of what this session ran for `command`. Collective
    /// (reductions over the ranks).
    pub fn stats(&self, command: Command) -> Stats {
        let comm = &*self.comm;
        let f = &self.facts;
        let meshed = self.mesh.as_ref();
        let ran = |name: &str| self.timer.phases().iter().any(|p| p.0 == name);
        let mut keys = vec!["read"];
        keys.extend(["distribute"].into_iter().filter(|k| ran(k)));
        keys.extend(["construct", "refine"]);
        keys.extend(["curvature", "regions"].into_iter().filter(|k| ran(k)));
        keys.extend(["partition", "balance"]);
        keys.extend(["load", "save"].into_iter().filter(|k| ran(k)));
        if self.classes.rule.is_some() || f.winding.is_some() {
            keys.push("classify");
        }
        if f.leak_checked {
            keys.push("leak_check");
        }
        if meshed.is_some() {
            keys.extend(["clean"].into_iter().filter(|k| ran(k)));
            keys.extend(["ghost", "nodes", "numbering", "connectivity"]);
            keys.extend(["zones"].into_iter().filter(|k| ran(k)));
            keys.extend(["snap"].into_iter().filter(|k| ran(k)));
            keys.push("write");
            keys.extend(
                ["faces", "openfoam", "quality"]
                    .into_iter()
                    .filter(|k| ran(k)),
            );
        }
        let keys_total: Vec<&str> = keys.iter().copied().chain(["total"]).collect();
        let t = &self.timer;
        // Traffic: per phase and in all, the maxima of sent + received and
        // of sent; then the sums over ranks.
        let total = t
            .traffic()
            .iter()
            .fold(Traffic::default(), |acc, p| acc + p.1);
        let per: Vec<Traffic> = keys
            .iter()
            .map(|k| t.traffic_of(k))
            .chain([total])
            .collect();
        let calls_total: u64 = t.calls().iter().map(|p| p.1).sum();
        let calls = keys.iter().map(|k| t.calls_of(k)).chain([calls_total]);
        let mut max: Vec<u64> = per
            .iter()
            .zip(calls)
            .flat_map(|(x, c)| [x.total(), x.sent, x.received, c])
            .collect();
        comm.max_u64(&mut max);
        let mut sums = [total.sent, total.received];
        comm.sum_u64(&mut sums);
        // Seconds inside collectives: maxima, and minima as maxima of the
        // negatives, in one reduction.
        let wait_total: f64 = t.waits().iter().map(|p| p.1).sum();
        let own: Vec<f64> = keys
            .iter()
            .map(|k| t.wait_of(k))
            .chain([wait_total])
            .collect();
        let mut w: Vec<f64> = own.iter().copied().chain(own.iter().map(|x| -x)).collect();
        comm.max_f64(&mut w);
        let n = own.len();
        // Peak memory at the end of each phase's last run.
        let mut after: Vec<u64> = keys
            .iter()
            .map(|k| {
                t.peaks()
                    .iter()
                    .rev()
                    .find(|p| p.0 == *k)
                    .map_or(0, |p| p.1)
            })
            .collect();
        comm.max_u64(&mut after);
        let mut held = [f.held as u64];
        comm.max_u64(&mut held);
        let mut rss = [peak_rss_bytes(), f.rss_start, f.rss_read, f.rss_distributed];
        comm.max_u64(&mut rss);
        let mesh = meshed.map(|m| {
            let c = m.counts();
            let mut v = [m.local_volume_cells(), m.num_nodes() as u64];
            comm.sum_u64(&mut v);
            MeshStats {
                counts: *c,
                points_written: v[1],
                kept_volume: super::mesh::kept_volume(comm, m),
                kept_cells: v[0],
                keep: self.config.mesh.keep,
                cut_rule: self.config.mesh.cut_rule,
                zones: m.zones().map(|z| {
                    (z.names().iter().zip(z.counts()))
                        .map(|(n, &c)| ZoneStats {
                            name: n.clone(),
                            elements: c,
                        })
                        .collect()
                }),
            }
        });
        let named = |v: Vec<(String, f64)>| PerPhase(v);
        let estimate = f.estimate;
        let balance = self.config.octree.balance;
        Stats {
            command: Some(command),
            surface_file: self.config.surface.file.clone(),
            surface: f.report.as_ref().map(SurfaceStats::from),
            ranks: comm.size() as u64,
            triangles: f.triangles as u64,
            distributed_surface: f.distributed,
            triangles_held: held[0],
            level: self.config.octree.level.unwrap_or(0),
            balance,
            octants_refined: f.octants_refined,
            octants_balanced: f.octants_balanced,
            estimated_octants: estimate.map_or(0, |e| match balance {
                Balance::None => e.refined,
                _ => e.balanced,
            }),
            estimated_octants_refined: estimate.map_or(0, |e| e.refined),
            inside_rule: self.inside.and(self.classes.rule),
            reversed_facets: f.winding.as_ref().map(|w| w.reversed_facets as u64),
            boundary_loops: f.winding.as_ref().map(|w| w.boundary_loops as u64),
            inside_leaves: f.leaf_classes.map(|c| c[0]),
            outside_leaves: f.leaf_classes.map(|c| c[1]),
            cut_leaves: f.leaf_classes.map(|c| c[2]),
            leak: LeakStats {
                checked: f.leak_checked,
                found: f.leak_checked.then_some(f.leak_path.is_some()),
                path_octants: f.leak_checked.then_some(f.leak_path.unwrap_or(0) as u64),
            },
            mesh,
            quality: self.current_quality().cloned(),
            pieces: f.pieces.clone(),
            snap: self.current_snap().cloned(),
            layers: self.layer_report.clone(),
            surface_volume: self.surface_volume(),
            dropped_facets: f.dropped.unwrap_or(0) as u64,
            timings: named(keys.iter().map(|k| (k.to_string(), t.get(k))).collect()),
            partition_timings: named(
                ["refined", "balanced"]
                    .iter()
                    .zip(t.phases().iter().filter(|p| p.0 == "partition"))
                    .map(|(k, p)| (k.to_string(), p.1))
                    .collect(),
            ),
            comm_bytes: PerPhase(
                keys_total
                    .iter()
                    .enumerate()
                    .map(|(i, k)| (k.to_string(), max[4 * i]))
                    .collect(),
            ),
            comm_bytes_sent: PerPhase(
                keys_total
                    .iter()
                    .enumerate()
                    .map(|(i, k)| (k.to_string(), max[4 * i + 1]))
                    .collect(),
            ),
            comm_bytes_received: PerPhase(
                keys_total
                    .iter()
                    .enumerate()
                    .map(|(i, k)| (k.to_string(), max[4 * i + 2]))
                    .collect(),
            ),
            comm_calls: PerPhase(
                keys_total
                    .iter()
                    .enumerate()
                    .map(|(i, k)| (k.to_string(), max[4 * i + 3]))
                    .collect(),
            ),
            comm_bytes_sum: TrafficSum {
                sent: sums[0],
                received: sums[1],
            },
            comm_seconds_min: named(
                keys_total
                    .iter()
                    .enumerate()
                    .map(|(i, k)| (k.to_string(), -w[n + i]))
                    .collect(),
            ),
            comm_seconds_max: named(
                keys_total
                    .iter()
                    .enumerate()
                    .map(|(i, k)| (k.to_string(), w[i]))
                    .collect(),
            ),
            peak_rss_bytes: rss[0],
            peak_rss_after: PerPhase(keys.iter().map(|k| k.to_string()).zip(after).collect()),
            rss_start_bytes: rss[1],
            rss_after_read_bytes: rss[2],
            rss_after_distribute_bytes: f.distributed.then_some(rss[3]),
            domain_side: self.domain().map_or(0.0, |d| d.side),
            memory_budget_bytes: f.budget.map(|b| b.per_rank),
            memory_budget_octants: f.budget.map(|b| b.octant_limit()),
        }
    }
}
