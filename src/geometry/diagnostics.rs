//! Surface diagnostics: topology and defect counts of a triangle soup, and
//! removal of degenerate and duplicate facets.
//!
//! # Definitions
//!
//! - **Welding**: corners whose three `f64` coordinates compare equal are one
//!   vertex (`-0.0` equals `0.0`). For STL input the coordinates are widened
//!   `f32` values, so this is the same as welding bit-identical `f32`
//!   coordinates (up to the sign of zero).
//! - **Degenerate** facet: zero (or non-finite) area, see
//!   [`Triangle::is_degenerate`].
//! - **Duplicate** facet: its three welded vertices are those of an earlier
//!   facet, in any order and either orientation. A group of `k` equal facets
//!   counts `k - 1` duplicates.
//! - **Edges** are the undirected pairs of welded vertices of the facets with
//!   three distinct welded vertices; facets with a repeated vertex have no
//!   edges. An edge is a *boundary* edge if one facet uses it and
//!   *non-manifold* if more than two do.
//! - **Inconsistently oriented** edge: used by exactly two facets that
//!   traverse it in the same direction (edges used more than twice are only
//!   counted as non-manifold). Flipping one facet of a closed surface makes
//!   its three edges inconsistent.
//! - **Components**: classes of facets connected through shared edges (edge
//!   connectivity, including non-manifold edges), counting only facets that
//!   have edges. Two pieces touching at a single vertex are two components.
//! - **Euler characteristic** `χ = V - E + F` with `V` the welded vertices,
//!   `E` the edges and `F` all facets.
//! - **Closed**: no boundary edge, no non-manifold edge, no inconsistently
//!   oriented edge and no degenerate facet. Pinched (non-manifold) vertices
//!   are not checked.
//! - **Genus** `(2 - χ) / 2`, given for a closed surface with one component.
//! - **Signed volume** ([`Surface::signed_volume`]), given for a closed
//!   surface.
//!
//! All counts are computed by sorting, in `O(n log n)` for `n` facets.

use std::fmt;

use super::{Aabb, Surface, Triangle};
use crate::error::Result;

/// Topology and defect counts of a surface (see the module documentation
/// for the definitions).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SurfaceReport {
    /// Number of facets.
    pub triangles: usize,
    /// Facets with zero area.
    pub degenerate: usize,
    /// Facets with the same welded vertices as an earlier facet.
    pub duplicate: usize,
    /// Vertices after welding equal coordinates.
    pub vertices: usize,
    /// Undirected edges.
    pub edges: usize,
    /// Edges used by one facet.
    pub boundary_edges: usize,
    /// Edges used by more than two facets.
    pub non_manifold_edges: usize,
    /// Edge-connected components of facets.
    pub components: usize,
    /// Edges used by two facets in the same direction.
    pub inconsistently_oriented_edges: usize,
    /// No boundary, non-manifold or inconsistently oriented edge and no
    /// degenerate facet.
    pub closed: bool,
    /// `V - E + F`.
    pub euler_characteristic: i64,
    /// `(2 - χ) / 2` when closed with one component.
    pub genus: Option<i64>,
    /// Enclosed volume when closed (positive for outward orientation).
    pub signed_volume: Option<f64>,
    /// Total facet area.
    pub area: f64,
    /// Bounding box of the vertices.
    #[serde(skip)]
    pub bbox: Aabb,
}

impl SurfaceReport {
    /// The report as a JSON object: the fields above, the box as
    /// `bbox_min` and `bbox_max`; an absent genus or volume and non-finite
    /// numbers are `null`.
    pub fn to_json_value(&self) -> serde_json::Value {
        let mut v = serde_json::to_value(self).unwrap_or_default();
        v["bbox_min"] = serde_json::json!(self.bbox.min);
        v["bbox_max"] = serde_json::json!(self.bbox.max);
        v
    }

    /// [`SurfaceReport::to_json_value`] as indented text.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(&self.to_json_value()).unwrap_or_default() + "\n"
    }
}

impl fmt::Display for SurfaceReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let b = &self.bbox;
        writeln!(
            f,
            "  triangles {} | degenerate {} | duplicate {}",
            self.triangles, self.degenerate, self.duplicate
        )?;
        writeln!(
            f,
            "  vertices {} (welded) | edges {} | boundary {} | non-manifold {} | \
             inconsistently oriented {}",
            self.vertices,
            self.edges,
            self.boundary_edges,
            self.non_manifold_edges,
            self.inconsistently_oriented_edges
        )?;
        let genus = self.genus.map_or("-".to_string(), |g| g.to_string());
        writeln!(
            f,
            "  components {} (edge-connected) | Euler characteristic {} | genus {genus}",
            self.components, self.euler_characteristic
        )?;
        let vol = self
            .signed_volume
            .map_or("n/a (not closed)".to_string(), |v| format!("{v:.9e}"));
        writeln!(
            f,
            "  closed {} | signed volume {vol} | area {:.9e}",
            if self.closed { "yes" } else { "no" },
            self.area
        )?;
        write!(
            f,
            "  bbox ({:.6}, {:.6}, {:.6}) to ({:.6}, {:.6}, {:.6})",
            b.min[0], b.min[1], b.min[2], b.max[0], b.max[1], b.max[2]
        )
    }
}

/// Welded vertex ids of every facet's corners, and the number of vertices.
/// Ids are assigned in the order of the coordinates' bits, so they depend on
/// the facets' vertices only.
pub(crate) fn weld(tris: &[Triangle]) -> (Vec<[u64; 3]>, usize) {
    // -0.0 and 0.0 are equal as f64 but differ in their bits.
    let bits = |c: f64| if c == 0.0 { 0 } else { c.to_bits() };
    let mut corners: Vec<([u64; 3], usize)> = Vec::with_capacity(3 * tris.len());
    for (i, t) in tris.iter().enumerate() {
        for (k, p) in t.v.iter().enumerate() {
            corners.push(([bits(p[0]), bits(p[1]), bits(p[2])], 3 * i + k));
        }
    }
    corners.sort_unstable_by_key(|c| c.0);
    let mut ids = vec![[0u64; 3]; tris.len()];
    let mut n = 0usize;
    for (j, (key, corner)) in corners.iter().enumerate() {
        if j > 0 && *key != corners[j - 1].0 {
            n += 1;
        }
        ids[corner / 3][corner % 3] = n as u64;
    }
    let vertices = if corners.is_empty() { 0 } else { n + 1 };
    (ids, vertices)
}

/// For every facet, true if it repeats the welded vertices of an earlier one.
fn duplicate_mask(ids: &[[u64; 3]]) -> Vec<bool> {
    let mut keyed: Vec<([u64; 3], u32)> = ids
        .iter()
        .enumerate()
        .map(|(i, f)| {
            let mut s = *f;
            s.sort_unstable();
            (s, i as u32)
        })
        .collect();
    keyed.sort_unstable();
    let mut dup = vec![false; ids.len()];
    for w in keyed.windows(2) {
        if w[0].0 == w[1].0 {
            dup[w[1].1 as usize] = true;
        }
    }
    dup
}

fn find(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        let p = parent[parent[x as usize] as usize];
        parent[x as usize] = p;
        x = p;
    }
    x
}

/// Computes the [`SurfaceReport`] of a surface.
pub fn diagnose(surface: &Surface) -> SurfaceReport {
    let tris = surface.triangles();
    let (ids, vertices) = weld(tris);
    let degenerate = tris.iter().filter(|t| t.is_degenerate()).count();
    let duplicate = duplicate_mask(&ids).iter().filter(|&&d| d).count();

    // Half-edges (lower vertex, higher vertex, facet, traversed low to high).
    let mut half: Vec<(u64, u64, u32, bool)> = Vec::with_capacity(3 * tris.len());
    for (i, f) in ids.iter().enumerate() {
        if f[0] == f[1] || f[1] == f[2] || f[2] == f[0] {
            continue;
        }
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            half.push((a.min(b), a.max(b), i as u32, a < b));
        }
    }
    half.sort_unstable_by_key(|h| (h.0, h.1));

    let mut parent: Vec<u32> = (0..tris.len() as u32).collect();
    let (mut edges, mut boundary, mut non_manifold, mut inconsistent) = (0, 0, 0, 0);
    let mut start = 0;
    while start < half.len() {
        let key = (half[start].0, half[start].1);
        let mut end = start + 1;
        while end < half.len() && (half[end].0, half[end].1) == key {
            end += 1;
        }
        let run = &half[start..end];
        edges += 1;
        match run.len() {
            1 => boundary += 1,
            2 if run[0].3 == run[1].3 => inconsistent += 1,
            2 => {}
            _ => non_manifold += 1,
        }
        let r0 = find(&mut parent, run[0].2);
        for h in &run[1..] {
            let r = find(&mut parent, h.2);
            if r != r0 {
                parent[r as usize] = r0;
            }
        }
        start = end;
    }
    let mut with_edges = vec![false; tris.len()];
    for h in &half {
        with_edges[h.2 as usize] = true;
    }
    let components = (0..tris.len() as u32)
        .filter(|&i| with_edges[i as usize] && find(&mut parent, i) == i)
        .count();

    let euler_characteristic = vertices as i64 - edges as i64 + tris.len() as i64;
    let closed = boundary == 0 && non_manifold == 0 && inconsistent == 0 && degenerate == 0;
    SurfaceReport {
        triangles: tris.len(),
        degenerate,
        duplicate,
        vertices,
        edges,
        boundary_edges: boundary,
        non_manifold_edges: non_manifold,
        components,
        inconsistently_oriented_edges: inconsistent,
        closed,
        euler_characteristic,
        genus: (closed && components == 1).then(|| (2 - euler_characteristic) / 2),
        signed_volume: closed.then(|| surface.signed_volume()),
        area: surface.area(),
        bbox: surface.bbox(),
    }
}

/// Removes degenerate facets (`drop_degenerate`) and duplicate facets
/// (`drop_duplicates`; the first facet of each group of equal facets is
/// kept). Returns the cleaned surface and the number of facets removed.
///
/// The remaining facets keep their order. Errors are those of
/// [`Surface::new`] on what remains.
pub fn clean(
    surface: &Surface,
    drop_degenerate: bool,
    drop_duplicates: bool,
) -> Result<(Surface, usize)> {
    let tris = surface.triangles();
    let dup = if drop_duplicates {
        duplicate_mask(&weld(tris).0)
    } else {
        vec![false; tris.len()]
    };
    let keep: Vec<bool> = tris
        .iter()
        .zip(&dup)
        .map(|(t, &d)| !(d || drop_degenerate && t.is_degenerate()))
        .collect();
    let kept: Vec<Triangle> = tris
        .iter()
        .zip(&keep)
        .filter(|(_, &k)| k)
        .map(|(t, _)| *t)
        .collect();
    let dropped = tris.len() - kept.len();
    let mut parts = surface.parts().clone();
    if !parts.of.is_empty() {
        parts.of = parts
            .of
            .iter()
            .zip(&keep)
            .filter(|(_, &k)| k)
            .map(|(&p, _)| p)
            .collect();
    }
    Ok((Surface::new(kept)?.with_parts(parts)?, dropped))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::shapes;

    /// The unit cube as 12 outward-oriented facets, two per face; facets
    /// `2k` and `2k + 1` make up face `k`.
    fn cube() -> Vec<Triangle> {
        let p = |i: usize| [(i & 1) as f64, ((i >> 1) & 1) as f64, ((i >> 2) & 1) as f64];
        // Faces as corner indices (bit 0 = x, bit 1 = y, bit 2 = z), each
        // counter-clockwise seen from outside.
        let quads = [
            [0, 2, 3, 1], // z = 0
            [4, 5, 7, 6], // z = 1
            [0, 1, 5, 4], // y = 0
            [2, 6, 7, 3], // y = 1
            [0, 4, 6, 2], // x = 0
            [1, 3, 7, 5], // x = 1
        ];
        let mut t = Vec::new();
        for q in quads {
            t.push(Triangle::new(p(q[0]), p(q[1]), p(q[2])));
            t.push(Triangle::new(p(q[0]), p(q[2]), p(q[3])));
        }
        t
    }

    fn report(tris: Vec<Triangle>) -> SurfaceReport {
        diagnose(&Surface::new(tris).unwrap())
    }

    #[test]
    fn closed_cube() {
        let r = report(cube());
        assert_eq!(r.triangles, 12);
        assert_eq!(r.vertices, 8);
        assert_eq!(r.edges, 18);
        assert_eq!(r.euler_characteristic, 2);
        assert_eq!(
            (r.boundary_edges, r.non_manifold_edges, r.components),
            (0, 0, 1)
        );
        assert_eq!(r.inconsistently_oriented_edges, 0);
        assert_eq!((r.degenerate, r.duplicate), (0, 0));
        assert!(r.closed);
        assert_eq!(r.genus, Some(0));
        assert!((r.signed_volume.unwrap() - 1.0).abs() < 1e-15);
        assert!((r.area - 6.0).abs() < 1e-15);
        assert_eq!(r.bbox.max, [1.0; 3]);
    }

    #[test]
    fn builtin_shapes_are_closed() {
        let s = report(shapes::default_sphere().triangles().to_vec());
        assert!(s.closed, "{s}");
        assert_eq!((s.genus, s.components), (Some(0), 1));
        assert_eq!(s.euler_characteristic, 2);
        assert!(s.signed_volume.unwrap() > 0.0);
        let t = report(shapes::default_torus().triangles().to_vec());
        assert!(t.closed, "{t}");
        assert_eq!((t.genus, t.components), (Some(1), 1));
        assert_eq!(t.euler_characteristic, 0);
        assert_eq!(t.boundary_edges + t.non_manifold_edges, 0);
        assert!(t.signed_volume.unwrap() > 0.0);
    }

    #[test]
    fn cube_with_missing_facets() {
        // One facet missing: its two cube edges and the face diagonal are
        // each left with one facet.
        let mut t = cube();
        t.remove(5);
        let r = report(t);
        assert_eq!(r.boundary_edges, 3);
        assert!(!r.closed);
        assert_eq!((r.genus, r.signed_volume), (None, None));
        assert_eq!(r.components, 1);
        assert_eq!(r.euler_characteristic, 1);
        // A whole face (both facets) missing: the 4 sides of the square.
        let mut t = cube();
        t.drain(4..6);
        let r = report(t);
        assert_eq!(r.boundary_edges, 4);
        assert_eq!(r.inconsistently_oriented_edges, 0);
        assert!(!r.closed);
    }

    #[test]
    fn cube_with_flipped_facet() {
        // The flipped facet traverses each of its 3 edges in the same
        // direction as its neighbour across that edge.
        let mut t = cube();
        t[7].v.swap(1, 2);
        let r = report(t);
        assert_eq!(r.inconsistently_oriented_edges, 3);
        assert_eq!((r.boundary_edges, r.non_manifold_edges), (0, 0));
        assert!(!r.closed);
        assert_eq!(r.genus, None);
    }

    #[test]
    fn two_cubes_are_two_components() {
        let mut t = cube();
        t.extend(cube().iter().map(|f| Triangle {
            v: f.v.map(|p| [p[0] + 3.0, p[1], p[2]]),
        }));
        let r = report(t);
        assert!(r.closed);
        assert_eq!(r.components, 2);
        assert_eq!(r.euler_characteristic, 4);
        assert_eq!(r.genus, None);
        assert!((r.signed_volume.unwrap() - 2.0).abs() < 1e-12);
    }

    #[test]
    fn duplicates_and_degenerates_are_counted_and_removed() {
        let mut t = cube();
        // A copy of facet 0 with rotated corners and flipped orientation,
        // and an exact copy of facet 3.
        let f = t[0].v;
        t.push(Triangle::new(f[1], f[0], f[2]));
        t.push(t[3]);
        // A zero-area facet (collinear corners on a cube edge) and one with
        // a repeated corner.
        t.push(Triangle::new([0.0; 3], [0.5, 0.0, 0.0], [1.0, 0.0, 0.0]));
        t.push(Triangle::new([0.0; 3], [0.0; 3], [1.0, 0.0, 0.0]));
        // -0.0 welds with 0.0.
        t[8].v[0] = [-0.0, 0.0, -0.0];
        let s = Surface::new(t).unwrap();
        let r = diagnose(&s);
        assert_eq!(r.triangles, 16);
        assert_eq!(r.duplicate, 2);
        assert_eq!(r.degenerate, 2);
        assert_eq!(r.vertices, 9); // the collinear facet adds (0.5, 0, 0)
        assert!(r.non_manifold_edges >= 3);
        assert!(!r.closed);

        let (c, dropped) = clean(&s, true, false).unwrap();
        assert_eq!(dropped, 2);
        let rc = diagnose(&c);
        assert_eq!((rc.degenerate, rc.duplicate), (0, 2));

        let (c, dropped) = clean(&s, false, true).unwrap();
        assert_eq!(dropped, 2);
        let rc = diagnose(&c);
        assert_eq!((rc.degenerate, rc.duplicate), (2, 0));
        // The first of each group is kept, so the cube's facets survive.
        assert_eq!(&c.triangles()[..12], &s.triangles()[..12]);

        let (c, dropped) = clean(&s, true, true).unwrap();
        assert_eq!(dropped, 4);
        let rc = diagnose(&c);
        assert_eq!(rc, report(s.triangles()[..12].to_vec()));
        assert!(rc.closed);

        let (c, dropped) = clean(&s, false, false).unwrap();
        assert_eq!((c.len(), dropped), (16, 0));
    }

    #[test]
    fn json_has_bools_and_nulls() {
        let mut t = cube();
        t.pop();
        let j = report(t).to_json();
        assert!(j.contains("\"closed\": false"), "{j}");
        assert!(j.contains("\"genus\": null"), "{j}");
        assert!(j.contains("\"boundary_edges\": 3"), "{j}");
        let j = report(cube()).to_json();
        assert!(
            j.contains("\"closed\": true") && j.contains("\"genus\": 0"),
            "{j}"
        );
    }
}
