//! The root cube in the user's units and its map to the lattice.
//!
//! The octree lives on the integer lattice `[0, 2^19]^3`; the user's surface
//! lives in its own units (metres, millimetres, ...). A [`Domain`] is the
//! cube `origin + [0, side]^3` that the root octant stands for. Lattice
//! coordinate `q` is the point `origin + q * side / 2^19`.
//!
//! A box domain ([`Domain::brick`]) is a brick of cubic root cells placed at
//! the cube's lowest corner (see [`crate::octree::brick`]): the cube is then the
//! smallest power-of-two block of root cells holding the box.

use crate::error::{Error, Result};
use crate::octree::brick::Brick;
use crate::octree::octant::ROOT_LEN;

/// Default ratio of the surface's longest bounding-box side to the cube's
/// side when the cube is fitted around a surface.
pub const DEFAULT_FIT: f64 = 0.7;

/// The root cube in user units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Domain {
    /// Lowest corner.
    pub origin: [f64; 3],
    /// Side length (> 0).
    pub side: f64,
    /// The root cells of a box domain ([`Brick::CUBE`] for a cube).
    pub brick: Brick,
}

impl Domain {
    /// An explicit cube.
    pub fn cube(origin: [f64; 3], side: f64) -> Result<Domain> {
        if !(side.is_finite() && side > 0.0) || origin.iter().any(|c| !c.is_finite()) {
            return Err(Error::invalid(format!(
                "the domain cube needs a finite origin and a positive side (got origin {origin:?}, side {side})"
            )));
        }
        Ok(Domain {
            origin,
            side,
            brick: Brick::CUBE,
        })
    }

    /// The box `lo..hi` split into `roots` cubic root cells: the box's
    /// sides divided by the root counts must agree (to a relative 1e-9),
    /// else the error names the boxes of the same root counts whose cells
    /// are cubes, one per axis's cell size.
    pub fn brick(lo: [f64; 3], hi: [f64; 3], roots: [u32; 3]) -> Result<Domain> {
        let brick = Brick::new(roots)?;
        let extent: [f64; 3] = std::array::from_fn(|k| hi[k] - lo[k]);
        if lo.iter().chain(&hi).any(|c| !c.is_finite()) || extent.iter().any(|&e| e <= 0.0) {
            return Err(Error::invalid(format!(
                "the box needs finite corners with the lowest below the highest on every axis \
                 (got {lo:?} to {hi:?})"
            )));
        }
        let cell: [f64; 3] = std::array::from_fn(|k| extent[k] / roots[k] as f64);
        let (small, large) = cell
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(a, b), &c| (a.min(c), b.max(c)));
        if large - small > 1e-9 * large {
            let mut boxes: Vec<String> = Vec::new();
            for a in 0..3 {
                let s = cell[a];
                let text = format!(
                    "{} x {} x {} (cells of {} as along {})",
                    short(s * roots[0] as f64),
                    short(s * roots[1] as f64),
                    short(s * roots[2] as f64),
                    short(s),
                    ["x", "y", "z"][a]
                );
                // Axes with the same cell size suggest the same box.
                if !boxes.iter().any(|b| {
                    b[..b.find(" as").unwrap_or(0)] == text[..text.find(" as").unwrap_or(0)]
                }) {
                    boxes.push(text);
                }
            }
            return Err(Error::invalid(format!(
                "the box {} x {} x {} does not divide into {}x{}x{} cubic root cells (cells of \
                 {} x {} x {}); boxes that do: {}",
                short(extent[0]),
                short(extent[1]),
                short(extent[2]),
                roots[0],
                roots[1],
                roots[2],
                short(cell[0]),
                short(cell[1]),
                short(cell[2]),
                boxes.join(", or ")
            )));
        }
        let side = cell[0] * (1u64 << brick.level()) as f64;
        let mut d = Domain::cube(lo, side)?;
        d.brick = brick;
        Ok(d)
    }

    /// Side of a root cell (the cube's side for a cube).
    pub fn root_side(&self) -> f64 {
        self.side / (1u64 << self.brick.level()) as f64
    }

    /// The highest corner of the domain (of the box for a brick).
    pub fn upper(&self) -> [f64; 3] {
        let r = self.brick.roots();
        std::array::from_fn(|k| self.origin[k] + r[k] as f64 * self.root_side())
    }

    /// The cube centred on the box `min..max` whose side is the box's
    /// longest side divided by `fit` (0 < fit <= 1).
    pub fn around(min: [f64; 3], max: [f64; 3], fit: f64) -> Result<Domain> {
        if !(fit > 0.0 && fit <= 1.0) {
            return Err(Error::invalid(format!(
                "--fit must be in (0, 1], got {fit}"
            )));
        }
        let longest = (0..3).map(|k| max[k] - min[k]).fold(0.0, f64::max);
        if !(longest.is_finite() && longest > 0.0) {
            return Err(Error::geometry(
                "the surface has no extent: its bounding box is a point",
            ));
        }
        let side = longest / fit;
        let origin = std::array::from_fn(|k| 0.5 * (min[k] + max[k]) - 0.5 * side);
        Domain::cube(origin, side)
    }

    /// Lattice units per user unit.
    pub fn scale(&self) -> f64 {
        ROOT_LEN as f64 / self.side
    }

    /// User point to lattice coordinates (not rounded).
    #[inline]
    pub fn to_lattice(&self, p: [f64; 3]) -> [f64; 3] {
        let s = self.scale();
        std::array::from_fn(|k| (p[k] - self.origin[k]) * s)
    }

    /// Lattice coordinates to a user point.
    #[inline]
    pub fn from_lattice(&self, q: [f64; 3]) -> [f64; 3] {
        let h = self.side / ROOT_LEN as f64;
        std::array::from_fn(|k| self.origin[k] + q[k] * h)
    }

    /// Volume of the domain (the cube, or the brick's box) in user units.
    pub fn volume(&self) -> f64 {
        let s = self.root_side();
        self.brick.trees() as f64 * s * s * s
    }
}

/// A length for messages: at most 10 significant digits, no trailing
/// zeros (3.6, not 3.5999999999999996).
fn short(v: f64) -> String {
    let t = format!("{v:.10e}");
    let parsed: f64 = t.parse().unwrap_or(v);
    format!("{parsed}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fit_centres_and_scales() {
        let d = Domain::around([0.0, 0.0, 0.0], [2.0, 1.0, 1.0], 0.5).unwrap();
        assert_eq!(d.side, 4.0);
        assert_eq!(d.origin, [-1.0, -1.5, -1.5]);
        let q = d.to_lattice([1.0, 0.5, 0.5]);
        assert_eq!(q, [ROOT_LEN as f64 / 2.0; 3]);
        assert_eq!(d.from_lattice(q), [1.0, 0.5, 0.5]);
        assert!(Domain::around([0.0; 3], [0.0; 3], 0.5).is_err());
        assert!(Domain::around([0.0; 3], [1.0; 3], 1.5).is_err());
        assert!(Domain::cube([0.0; 3], f64::NAN).is_err());
    }

    #[test]
    fn bricks_need_cubic_cells() {
        let d = Domain::brick([0.0, -1.0, -0.5], [6.0, 1.0, 0.5], [6, 2, 1]).unwrap();
        assert_eq!(d.brick.level(), 3);
        assert_eq!(d.side, 8.0);
        assert_eq!(d.origin, [0.0, -1.0, -0.5]);
        assert_eq!(d.upper(), [6.0, 1.0, 0.5]);
        assert_eq!(d.volume(), 12.0);
        let e = Domain::brick([0.0; 3], [6.0, 2.0, 1.1], [6, 2, 1]).unwrap_err();
        let m = e.message();
        assert!(m.contains("does not divide"), "{m}");
        assert!(m.contains("6 x 2 x 1 (cells of 1 as along x)"), "{m}");
        assert!(m.contains("(cells of 1.1 as along z)"), "{m}");
        assert!(Domain::brick([0.0; 3], [-1.0, 1.0, 1.0], [1, 1, 1]).is_err());
    }
}
