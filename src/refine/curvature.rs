//! Refinement where the surface curves: a leaf touching the surface is
//! split, up to a maximum level, while the normals of the triangles touching
//! it differ by more than a feature angle. Each part of the surface (the
//! solids of an ASCII STL) may have its own range of levels: a leaf touching
//! a part is split while below the part's minimum, and up to the part's
//! maximum where the triangles of the parts it may still refine for turn.
//!
//! ```text
//!   flat: all normals within the angle       curved or sharp: two normals
//!   of each other -> the leaf stays           further apart -> split
//!        ^  ^  ^                                   ^     \
//!   -----+--+--+-----                          ----+      \ ->
//!                                                   `------
//! ```
//!
//! Triangles "touching" a leaf are those the surface refinement uses
//! (closed boxes, [`SurfaceIndex::touching`]); zero-area triangles have no
//! normal and are ignored. A surface with inconsistently oriented facets
//! counts a flipped facet as a 180-degree turn.

use crate::octree::octant::Octant;
use crate::refine::SurfaceIndex;

/// The curvature rule of one surface.
pub struct CurvatureRule<'a> {
    index: &'a SurfaceIndex,
    /// Unit normals of the index's triangles (zero for degenerate ones).
    normals: Vec<[f64; 3]>,
    /// Cosine of the feature angle.
    cos: f64,
    /// `(min, max)` levels of each part ([`SurfaceIndex::part_of`]).
    ranges: Vec<(u8, u8)>,
    max_level: u8,
}

impl<'a> CurvatureRule<'a> {
    /// The rule for `index`, splitting up to `max_level` where normals
    /// differ by more than `feature_angle` degrees.
    pub fn new(index: &'a SurfaceIndex, max_level: u8, feature_angle: f64) -> CurvatureRule<'a> {
        CurvatureRule::with_ranges(index, vec![(0, max_level)], feature_angle)
    }

    /// The rule with a `(min, max)` range of levels per part of `index`
    /// (one range for a surface of fewer than two parts).
    pub fn with_ranges(
        index: &'a SurfaceIndex,
        ranges: Vec<(u8, u8)>,
        feature_angle: f64,
    ) -> CurvatureRule<'a> {
        let normals = index
            .triangles()
            .iter()
            .map(|t| {
                let n = t.normal();
                let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
                if len > 0.0 && len.is_finite() {
                    [n[0] / len, n[1] / len, n[2] / len]
                } else {
                    [0.0; 3]
                }
            })
            .collect();
        let max_level = ranges.iter().map(|r| r.0.max(r.1)).max().unwrap_or(0);
        CurvatureRule {
            index,
            normals,
            cos: feature_angle.to_radians().cos(),
            ranges,
            max_level,
        }
    }

    /// The finest level the rule refines to.
    pub fn max_level(&self) -> u8 {
        self.max_level
    }

    /// Whether leaf `o` must be split; `buf` is scratch space.
    pub fn splits(&self, o: Octant, buf: &mut Vec<u32>) -> bool {
        if o.level() >= self.max_level {
            return false;
        }
        buf.clear();
        self.index.touching(o, buf);
        let l = o.level();
        let range = |t: u32| {
            let p = self.index.part_of(t);
            self.ranges
                .get(p)
                .or(self.ranges.first())
                .copied()
                .unwrap_or((0, 0))
        };
        if buf.iter().any(|&t| l < range(t).0) {
            return true;
        }
        let n: Vec<[f64; 3]> = buf
            .iter()
            .filter(|&&t| l < range(t).1)
            .map(|&t| self.normals[t as usize])
            .filter(|n| n != &[0.0; 3])
            .collect();
        n.iter().enumerate().any(|(i, a)| {
            n[i + 1..]
                .iter()
                .any(|b| a[0] * b[0] + a[1] * b[1] + a[2] * b[2] < self.cos)
        })
    }
}
