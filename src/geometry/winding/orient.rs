//! Consistent orientation of a soup's edge-connected components, outward,
//! and the loops of its boundary.

use std::collections::HashMap;

use crate::geometry::diagnostics::weld;
use crate::geometry::vector::{add, cross, dot, norm, scale, sub};
use crate::geometry::Triangle;

/// How `orient` oriented a soup.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Orientation {
    /// Per facet, whether it is to be reversed.
    pub flipped: Vec<bool>,
    /// Components connected through manifold edges (facets with three
    /// distinct welded vertices only).
    pub components: usize,
    /// Facets reversed.
    pub reversed_facets: usize,
    /// Manifold edges still used twice in the same direction (the component
    /// is not orientable).
    pub conflicting_edges: usize,
}

impl Orientation {
    /// The facets with the reversed ones flipped (`v1` and `v2` swapped).
    pub fn apply(&self, tris: &[Triangle]) -> Vec<Triangle> {
        tris.iter()
            .zip(&self.flipped)
            .map(|(t, &f)| {
                if f {
                    Triangle::new(t.v[0], t.v[2], t.v[1])
                } else {
                    *t
                }
            })
            .collect()
    }
}

/// Orients every edge-connected component of `tris` consistently and
/// outward (see the module documentation).
pub fn orient(tris: &[Triangle]) -> Orientation {
    orient_welded(tris, &weld(tris).0)
}

/// [`orient`] with the welded vertex ids of the facets' corners.
pub(crate) fn orient_welded(tris: &[Triangle], ids: &[[u64; 3]]) -> Orientation {
    let n = tris.len();
    let proper = |f: &[u64; 3]| f[0] != f[1] && f[1] != f[2] && f[2] != f[0];
    // Half-edges (lower vertex, higher vertex, facet, traversed low to high).
    let mut half: Vec<(u64, u64, u32, bool)> = Vec::with_capacity(3 * n);
    for (i, f) in ids.iter().enumerate() {
        if proper(f) {
            for k in 0..3 {
                let (a, b) = (f[k], f[(k + 1) % 3]);
                half.push((a.min(b), a.max(b), i as u32, a < b));
            }
        }
    }
    half.sort_unstable_by_key(|h| (h.0, h.1, h.2));
    // Facet pairs across manifold edges, and whether they traverse it in
    // the same direction (then exactly one of them must be reversed).
    let mut links: Vec<(u32, u32, bool)> = Vec::new();
    let mut s = 0;
    while s < half.len() {
        let mut e = s + 1;
        while e < half.len() && (half[e].0, half[e].1) == (half[s].0, half[s].1) {
            e += 1;
        }
        if e - s == 2 {
            let (f, g) = (half[s], half[s + 1]);
            if f.2 != g.2 {
                links.push((f.2, g.2, f.3 == g.3));
                links.push((g.2, f.2, f.3 == g.3));
            }
        }
        s = e;
    }
    drop(half);
    links.sort_unstable();
    let mut start = vec![0usize; n + 1];
    for l in &links {
        start[l.0 as usize + 1] += 1;
    }
    for i in 0..n {
        start[i + 1] += start[i];
    }

    const NONE: u32 = u32::MAX;
    let mut comp = vec![NONE; n];
    let mut flipped = vec![false; n];
    let mut components = 0u32;
    let mut conflicts = 0usize;
    let mut stack = Vec::new();
    for seed in 0..n {
        if comp[seed] != NONE || !proper(&ids[seed]) {
            continue;
        }
        comp[seed] = components;
        stack.push(seed as u32);
        while let Some(f) = stack.pop() {
            let f = f as usize;
            for &(_, g, same) in &links[start[f]..start[f + 1]] {
                let want = flipped[f] ^ same;
                let g = g as usize;
                if comp[g] == NONE {
                    comp[g] = components;
                    flipped[g] = want;
                    stack.push(g as u32);
                } else if flipped[g] != want {
                    conflicts += 1;
                }
            }
        }
        components += 1;
    }

    // Signed volume of each component about its own centroid.
    let nc = components as usize;
    let mut weight = vec![(0.0f64, [0.0f64; 3]); nc];
    for (i, t) in tris.iter().enumerate() {
        if comp[i] != NONE {
            let a = t.area();
            let w = &mut weight[comp[i] as usize];
            w.0 += a;
            w.1 = add(w.1, scale(t.centroid(), a));
        }
    }
    let centroid: Vec<[f64; 3]> = weight
        .iter()
        .map(|(a, c)| {
            if *a > 0.0 {
                scale(*c, 1.0 / a)
            } else {
                [0.0; 3]
            }
        })
        .collect();
    // The volume, and the sum of the magnitudes of its terms: a component
    // whose volume is zero up to rounding (a lone facet, a flat patch) says
    // nothing about its orientation and keeps it.
    let mut volume = vec![(0.0f64, 0.0f64); nc];
    for (i, t) in tris.iter().enumerate() {
        if comp[i] != NONE {
            let c = centroid[comp[i] as usize];
            let (a, mut b, mut d) = (sub(t.v[0], c), sub(t.v[1], c), sub(t.v[2], c));
            if flipped[i] {
                std::mem::swap(&mut b, &mut d);
            }
            let bd = cross(b, d);
            let v = &mut volume[comp[i] as usize];
            v.0 += dot(a, bd);
            v.1 += norm(a) * norm(bd);
        }
    }
    for i in 0..n {
        if comp[i] != NONE {
            let (v, magnitude) = volume[comp[i] as usize];
            if v < -1e-9 * magnitude {
                flipped[i] = !flipped[i];
            }
        }
    }
    let reversed_facets = flipped.iter().filter(|&&f| f).count();
    Orientation {
        flipped,
        components: nc,
        reversed_facets,
        // Each conflicting edge is seen from both of its facets.
        conflicting_edges: conflicts / 2,
    }
}

/// The boundary of the facets `ids` (welded corner ids; `flipped` facets
/// reversed) as closed loops of vertex ids: loop `[u0, u1, .., uk]` stands
/// for the directed edges `u0 -> u1 -> .. -> uk -> u0`. A directed edge is on
/// the boundary as many times as the facets use it more often in that
/// direction than in the other. Facets with a repeated vertex have no edges.
/// Deterministic: the loops depend on the ids only.
pub(crate) fn boundary_loops(ids: &[[u64; 3]], flipped: &[bool]) -> Vec<Vec<u64>> {
    let mut half: Vec<(u64, u64, i64)> = Vec::new();
    for (f, &rev) in ids.iter().zip(flipped) {
        if f[0] == f[1] || f[1] == f[2] || f[2] == f[0] {
            continue;
        }
        for k in 0..3 {
            let (mut a, mut b) = (f[k], f[(k + 1) % 3]);
            if rev {
                std::mem::swap(&mut a, &mut b);
            }
            half.push((a.min(b), a.max(b), if a < b { 1 } else { -1 }));
        }
    }
    half.sort_unstable();
    let mut edges: Vec<(u64, u64)> = Vec::new();
    let mut s = 0;
    while s < half.len() {
        let mut e = s;
        let mut net = 0i64;
        while e < half.len() && (half[e].0, half[e].1) == (half[s].0, half[s].1) {
            net += half[e].2;
            e += 1;
        }
        let (lo, hi) = (half[s].0, half[s].1);
        for _ in 0..net.unsigned_abs() {
            edges.push(if net > 0 { (lo, hi) } else { (hi, lo) });
        }
        s = e;
    }
    edges.sort_unstable();
    // Every vertex has as many boundary edges in as out (the boundary of a
    // sum of triangles is a sum of cycles), so a walk along unused edges
    // can only stop where it started.
    let m = edges.len();
    let mut used = vec![false; m];
    let mut cursor: HashMap<u64, usize> = HashMap::new();
    let mut loops = Vec::new();
    for i in 0..m {
        if used[i] {
            continue;
        }
        let first = edges[i].0;
        let mut lp = Vec::new();
        let mut cur = i;
        loop {
            used[cur] = true;
            lp.push(edges[cur].0);
            let v = edges[cur].1;
            if v == first {
                break;
            }
            let pos = cursor
                .entry(v)
                .or_insert_with(|| edges.partition_point(|e| e.0 < v));
            while *pos < m && edges[*pos].0 == v && used[*pos] {
                *pos += 1;
            }
            if *pos >= m || edges[*pos].0 != v {
                // Unreachable for a balanced boundary; end the loop here.
                break;
            }
            cur = *pos;
        }
        loops.push(lp);
    }
    loops
}
