//! The part of a surface nearest a point: how a boundary face on the
//! surface finds the solid (patch) it belongs to; and the closed solids of
//! a surface, which contain the zones of a mesh with zones.

use super::bvh::Bvh;
use super::distance::point_triangle2;
use std::collections::HashMap;

use super::diagnostics::weld;
use super::winding::WindingTree;
use super::{Surface, Triangle};

/// Nearest-triangle look-ups for a surface of two or more parts. Kept
/// after the surface itself is released, only for such surfaces.
pub struct PartLocator {
    tris: Vec<Triangle>,
    of: Vec<u16>,
    bvh: Bvh,
    /// Half the diagonal of the surface's box: no search goes further.
    reach: f64,
}

impl PartLocator {
    /// The locator of `surface`, or `None` when it has fewer than two
    /// parts (every surface face is then on the one surface patch).
    pub fn new(surface: &Surface) -> Option<PartLocator> {
        let parts = surface.parts();
        if parts.names.len() < 2 || parts.of.len() != surface.len() {
            return None;
        }
        let tris = surface.triangles().to_vec();
        let bvh = Bvh::new(&tris);
        let e = surface.bbox().extent();
        let reach = (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt();
        Some(PartLocator {
            tris,
            of: parts.of.clone(),
            bvh,
            reach,
        })
    }

    /// The part of the triangle nearest `p` (ties: the lowest triangle
    /// index). `radius` is a first guess of the distance (a face's size):
    /// the search box doubles from there.
    pub fn nearest_part(&self, p: [f64; 3], radius: f64, scratch: &mut Vec<u32>) -> u16 {
        let mut r = radius.max(self.reach * 1e-9);
        loop {
            scratch.clear();
            let lo = [p[0] - r, p[1] - r, p[2] - r];
            let hi = [p[0] + r, p[1] + r, p[2] + r];
            self.bvh.query_candidates(lo, hi, scratch);
            let best = scratch
                .iter()
                .map(|&t| {
                    let [a, b, c] = self.tris[t as usize].v;
                    (point_triangle2(p, a, b, c), t)
                })
                .min_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
            // Within the box's inscribed ball, nothing outside is nearer.
            match best {
                Some((d2, t)) if d2 <= r * r || r > 4.0 * self.reach => return self.of[t as usize],
                None if r > 4.0 * self.reach + p.iter().map(|x| x.abs()).sum::<f64>() => return 0,
                _ => r *= 2.0,
            }
        }
    }
}

/// The closed solids of a surface of two or more parts, for zones: each
/// part whose triangles close up (every edge, its corners welded by
/// position, shared by an even number of the part's triangles) with its
/// winding-number tree. `None` unless the surface has two or more parts
/// and every one of them is closed (the halves of one body are not
/// solids of their own).
pub struct Solids {
    names: Vec<String>,
    trees: Vec<WindingTree>,
}

impl Solids {
    /// The solids of `surface`, see [`Solids`].
    pub fn new(surface: &Surface) -> Option<Solids> {
        let parts = surface.parts();
        if parts.names.len() < 2 || parts.of.len() != surface.len() {
            return None;
        }
        let mut trees = Vec::with_capacity(parts.names.len());
        for k in 0..parts.names.len() {
            let tris: Vec<Triangle> = (surface.triangles().iter().zip(&parts.of))
                .filter(|(_, &of)| of as usize == k)
                .map(|(t, _)| *t)
                .collect();
            if tris.is_empty() || !closed(&tris) {
                return None;
            }
            trees.push(WindingTree::new(&tris));
        }
        Some(Solids {
            names: parts.names.clone(),
            trees,
        })
    }

    /// The solids' names, in the surface's part order.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// The first solid (in part order) whose winding number at `p` is at
    /// least one half in size.
    pub fn holding(&self, p: [f64; 3]) -> Option<usize> {
        self.trees.iter().position(|t| t.eval(p).abs() >= 0.5)
    }
}

/// Whether every edge of `tris` (corners welded by position) is shared by
/// an even number of them.
fn closed(tris: &[Triangle]) -> bool {
    let (ids, _) = weld(tris);
    let mut edges: HashMap<(u64, u64), u32> = HashMap::new();
    for t in &ids {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *edges.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    edges.values().all(|n| n % 2 == 0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::shapes::default_sphere;
    use crate::geometry::Parts;

    #[test]
    fn halves_of_a_sphere() {
        let s = default_sphere();
        let of: Vec<u16> = s
            .triangles()
            .iter()
            .map(|t| u16::from(t.centroid()[2] > 0.0))
            .collect();
        let s = s
            .with_parts(Parts {
                names: vec!["bottom".into(), "top".into()],
                of,
            })
            .unwrap();
        let loc = PartLocator::new(&s).unwrap();
        let mut scratch = Vec::new();
        assert_eq!(loc.nearest_part([0.1, 0.2, 1.3], 0.01, &mut scratch), 1);
        assert_eq!(loc.nearest_part([0.0, 0.0, -5.0], 0.01, &mut scratch), 0);
        assert_eq!(loc.nearest_part([0.9, 0.0, 0.2], 1.0, &mut scratch), 1);
        assert!(PartLocator::new(&default_sphere()).is_none());
    }
}
