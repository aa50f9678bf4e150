//! The table the `octmesh` command prints while it runs: an [`Observer`]
//! writing each event of a [`super::Session`] as a line on stdout.

use std::io::Write;

use super::{Event, Observer};
use crate::config::{Command, Config};

/// Prints to stdout, ignoring a closed pipe (`octmesh ... | head -1`).
macro_rules! say {
    ($($t:tt)*) => {{ let _ = writeln!(std::io::stdout(), $($t)*); }};
}

/// Prints a run's table on stdout, as the `octmesh` command does on rank
/// 0: the surface, the domain, a line per phase with its time and count,
/// and what each stage found.
pub struct Table {
    command: Command,
    config: Config,
    ranks: usize,
}

impl Table {
    /// A table for `command` run with `config` on `ranks` ranks.
    pub fn new(command: Command, config: Config, ranks: usize) -> Table {
        Table {
            command,
            config,
            ranks,
        }
    }
}

impl Observer for Table {
    fn event(&mut self, e: &Event<'_>) {
        let c = &self.config;
        match e {
            Event::SurfaceLoaded {
                name,
                triangles,
                dropped,
                domain,
                estimate,
                inside,
            } => {
                let rule = inside.map(|(r, why)| format!("inside {r}{why}"));
                let what = match (self.command, rule) {
                    (Command::Octree, Some(r)) => format!("octree ({r})"),
                    (Command::Octree, None) => "octree".to_string(),
                    (Command::Mesh, r) => format!(
                        "mesh (keep {}, cut rule {}, {})",
                        c.mesh.keep,
                        c.mesh.cut_rule,
                        r.unwrap_or_default()
                    ),
                };
                // A loaded octree has the levels its file gives.
                let octree = match &c.octree.load {
                    Some(p) => format!("the octree of {}", p.display()),
                    None => format!(
                        "level {}, balance {}",
                        c.octree.level.unwrap_or(0),
                        c.octree.balance
                    ),
                };
                say!(
                    "octmesh {what}: {name} ({triangles} triangles), {octree}, {} rank(s)",
                    self.ranks
                );
                if let Some(n) = dropped {
                    say!("  dropped {n} facet(s) (degenerate or duplicate)");
                }
                let (o, s) = (domain.origin, domain.side);
                // A loaded octree brings its own domain: the configured one
                // is not shown.
                let shown = c.octree.load.is_none();
                if shown && domain.brick.is_cube() {
                    say!(
                        "  cube: origin ({:.6}, {:.6}, {:.6}), side {s:.6}",
                        o[0],
                        o[1],
                        o[2]
                    );
                } else if shown {
                    let (u, r) = (domain.upper(), domain.brick.roots());
                    say!(
                        "  box: ({:.6}, {:.6}, {:.6}) to ({:.6}, {:.6}, {:.6}), {}x{}x{} root cells \
                         of side {:.6}",
                        o[0],
                        o[1],
                        o[2],
                        u[0],
                        u[1],
                        u[2],
                        r[0],
                        r[1],
                        r[2],
                        domain.root_side()
                    );
                }
                if let Some(e) = estimate {
                    say!(
                        "  estimated octants: {} refined, {} balanced",
                        e.refined,
                        e.balanced
                    );
                }
                say!("  {:<12} {:>10} {:>14}", "phase", "time [s]", "count");
            }
            Event::Phase {
                name,
                seconds,
                count,
            } => {
                let n = count.map(|c| c.to_string()).unwrap_or_default();
                say!("  {name:<12} {seconds:>10.3} {n:>14}");
            }
            Event::Winding(w) => {
                say!(
                "  winding: {} component(s), {} facet(s) reversed, {} boundary loop(s) closed by \
                 {} cap triangle(s)",
                w.components, w.reversed_facets, w.boundary_loops, w.cap_triangles
            )
            }
            Event::LeafClasses([i, o, cut]) => {
                say!("  leaves inside {i} | outside {o} | cut {cut}")
            }
            Event::LeakChecked {
                point: p,
                path_octants: None,
                seconds,
                ..
            } => say!(
                "  leak check passed: the inside point ({}, {}, {}) is sealed off from the \
                 domain boundary ({seconds:.3} s)",
                p[0],
                p[1],
                p[2]
            ),
            Event::LeakChecked {
                path_octants: Some(n),
                written: Some(f),
                ..
            } => {
                say!("  wrote the leak path ({n} octants) to {}", f.display())
            }
            Event::Meshed { counts: m } => {
                say!(
                    "  elements {} | independent nodes {} | hanging nodes {} face, {} edge | \
                     ghosts {}",
                    m.elements,
                    m.independent_nodes,
                    m.face_hanging_nodes,
                    m.edge_hanging_nodes,
                    m.ghosts
                );
            }
            Event::Zones(z) => {
                let list: Vec<String> = z.iter().map(|(n, c)| format!("{n} {c}")).collect();
                say!("  zones: {}", list.join(" | "));
            }
            Event::KeptVolume {
                kept,
                expected,
                reference,
                snapped,
            } => {
                let what = match snapped {
                    true => "snapped volume",
                    false => "kept volume",
                };
                let rel = (kept - expected) / expected;
                say!(
                    "  {what} {kept:.6e} | {} {expected:.6e} | relative difference {rel:+.3e}",
                    reference.describe()
                );
            }
            Event::Quality(q) => {
                say!(
                    "  quality: scaled Jacobian min {:.4} ({} inverted) | non-orthogonality max {:.4} \
                     average {:.4} deg | skewness max {:.4}",
                    q.scaled_jacobian_min,
                    q.inverted_elements,
                    q.non_orthogonality_max,
                    q.non_orthogonality_average,
                    q.skewness_max
                );
                let h = &q.scaled_jacobian_histogram;
                let bins: Vec<String> = (0..h.counts.len())
                    .filter(|&k| h.counts[k] > 0)
                    .map(|k| {
                        // The last bin holds 1.
                        let close = if k + 1 == h.counts.len() { ']' } else { ')' };
                        let (a, b) = (h.edges[k], h.edges[k + 1]);
                        format!("[{a:.1}, {b:.1}{close} {}", h.counts[k])
                    })
                    .collect();
                say!("  scaled Jacobian histogram: {}", bins.join(" | "));
                say!(
                    "  checkMesh figures: skewness internal {:.4} boundary {:.4} | determinant min {:.4} \
                     | face weight min {:.4} | volume ratio min {:.4} | flatness min {:.4} | twist min {:.4}",
                    q.internal_skewness_max,
                    q.boundary_skewness_max,
                    q.determinant_min,
                    q.face_weight_min,
                    q.volume_ratio_min,
                    q.face_flatness_min,
                    q.face_twist_min
                );
                let l = &q.limits;
                if l.passed() {
                    say!("  meshQualityDict's default limits: passed");
                } else {
                    say!(
                        "  meshQualityDict's default limits: FAILED: non-orthogonal > 65: {} | skewness > 4 \
                         internal: {} | > 20 boundary: {} | determinant < 0.001: {} cells | weight < 0.05: {} \
                         | volume ratio < 0.01: {} | twist < 0.02: {}",
                        l.non_orthogonal_faces,
                        l.skewed_internal_faces,
                        l.skewed_boundary_faces,
                        l.low_determinant_cells,
                        l.low_weight_faces,
                        l.low_volume_ratio_faces,
                        l.twisted_faces
                    );
                }
            }
            Event::Snapped(r) => {
                say!(
                    "  snap: surface nodes {} | snapped {} ({} to features) | partly {} ({:?} at cells \
                     with <=1/2/3 wall faces) | not {} ({:?}) | relaxed {} | elements reported {} | \
                     scaled Jacobian min {:.4}",
                    r.surface_nodes,
                    r.snapped,
                    r.feature_nodes,
                    r.partial,
                    r.partial_by_wall_faces,
                    r.unsnapped,
                    r.unsnapped_by_wall_faces,
                    r.relaxed_nodes,
                    r.reported_elements,
                    r.min_scaled_jacobian
                );
            }
            Event::Layers(r) => {
                for p in &r.patches {
                    say!(
                        "  layers {}: {} layers on {} faces | coverage {:.2} % | mean layers {:.3} | \
                         thinned faces {} | first cell height mean {:.4e} min {:.4e} max {:.4e} | {:.3} s",
                        p.patch,
                        p.layers,
                        p.faces,
                        100.0 * p.coverage,
                        p.mean_layers,
                        p.thinned_faces,
                        p.first_height_mean,
                        p.first_height_min,
                        p.first_height_max,
                        r.seconds
                    );
                }
            }
            Event::Pieces(sizes) if sizes.len() > 1 => {
                let total: u64 = sizes.iter().sum();
                say!(
                    "  warning: the mesh is {} pieces joined through faces (the largest has {} of {total} \
                     elements; the others touch it at most along edges or corners, or not at all): a solver's \
                     stiffness is singular unless every piece is held; --clean-walls true joins them \
                     where they only touch",
                    sizes.len(),
                    sizes[0]
                );
            }
            Event::Conforming {
                hexahedra,
                elements,
                refined,
            } => {
                say!(
                    "  conforming: {hexahedra} hexahedra for {elements} elements (x{:.2})",
                    *hexahedra as f64 / (*elements).max(1) as f64
                );
                if *refined > 0 {
                    say!(
                        "  warning: {refined} macro cells had no refinement template (the concave edges and \
                         corners of a staircase) or children in different zones: they were split, so the \
                         conforming mesh is finer than the octree there (ARCHITECTURE.md, \"Conforming meshes\")"
                    );
                }
            }
            Event::Wrote(p) => say!("  wrote {}", p.display()),
            Event::Finished {
                seconds,
                peak_rss,
                bytes_per_leaf,
            } => {
                say!("  {:<12} {seconds:>10.3}", "total");
                let mib = *peak_rss as f64 / (1 << 20) as f64;
                say!("  peak RSS {mib:.1} MiB per rank (max over ranks), {bytes_per_leaf:.1} bytes per leaf");
            }
            _ => {}
        }
    }
}
