//! The root cube in the user's units and its map to the lattice.
//!
//! The octree lives on the integer lattice `[0, 2^19]^3`; the user's surface
//! lives in its own units (metres, millimetres, ...). A [`Domain`] is the
//! cube `origin + [0, side]^3` that the root octant stands for. Lattice
//! coordinate `q` is the point `origin + q * side / 2^19`.

use crate::error::{Error, Result};
use crate::octant::ROOT_LEN;

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
}

impl Domain {
    /// An explicit cube.
    pub fn cube(origin: [f64; 3], side: f64) -> Result<Domain> {
        if !(side.is_finite() && side > 0.0) || origin.iter().any(|c| !c.is_finite()) {
            return Err(Error::invalid(format!(
                "the domain cube needs a finite origin and a positive side (got origin {origin:?}, side {side})"
            )));
        }
        Ok(Domain { origin, side })
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

    /// Volume of the cube in user units.
    pub fn volume(&self) -> f64 {
        self.side * self.side * self.side
    }
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
}
