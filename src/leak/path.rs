//! A leak's path: the octants from the boundary to the inside point, and
//! the report that describes it.

use crate::error::{Error, ErrorKind};
use crate::geometry::Aabb;
use crate::octree::domain::Domain;
use crate::octree::octant::{Octant, ROOT_LEN};

/// A path of face-adjacent open leaves from the domain boundary to the leaf
/// holding the inside point: the evidence of a leak.
#[derive(Clone, Debug, PartialEq)]
pub struct LeakPath {
    pub(crate) point: [f64; 3],
    pub(crate) octants: Vec<Octant>,
}

impl LeakPath {
    /// The inside point the outside region reaches, in user units.
    pub fn point(&self) -> [f64; 3] {
        self.point
    }

    /// The leaves of the path: the first touches the boundary of the cube,
    /// the last holds the point, consecutive leaves share part of a face,
    /// and none touches the surface. It is a shortest such path (in leaves);
    /// among those, each step back from the point goes to the neighbour with
    /// the smallest Morton key.
    pub fn octants(&self) -> &[Octant] {
        &self.octants
    }

    /// Number of leaves on the path.
    pub fn len(&self) -> usize {
        self.octants.len()
    }

    /// Whether the path is empty (never so for a path [`find_leak`](super::find_leak) returns).
    pub fn is_empty(&self) -> bool {
        self.octants.is_empty()
    }

    /// Centres of the path's leaves in user units.
    pub fn centres(&self, domain: &Domain) -> Vec<[f64; 3]> {
        self.octants.iter().map(|&o| centre(domain, o)).collect()
    }

    /// Side lengths of the path's leaves in user units.
    pub fn sizes(&self, domain: &Domain) -> Vec<f64> {
        self.octants.iter().map(|&o| size(domain, o)).collect()
    }

    /// The report of the leak: the point, the number of leaves, the centres
    /// and sizes of the first and last few, and where the path enters the
    /// surface's bounding box `surface_box` (user units), if given.
    pub fn message(&self, domain: &Domain, surface_box: Option<&Aabb>) -> String {
        let dec = decimals(domain);
        let n = self.octants.len();
        let c = self.centres(domain);
        let s = self.sizes(domain);
        let item = |i: usize| {
            format!(
                "#{} {} size {:.dec$} (level {})",
                i + 1,
                fmt_point(c[i], dec),
                s[i],
                self.octants[i].level()
            )
        };
        let mut m = format!(
            "leak: the outside region reaches the inside point {}: a path of {n} face-adjacent \
             octant(s) that touch no triangle leads from the domain boundary to the point's octant",
            fmt_point(self.point, dec)
        );
        const FEW: usize = 3;
        if n <= 2 * FEW {
            m.push_str("\n  path: ");
            m.push_str(&(0..n).map(item).collect::<Vec<_>>().join("; "));
        } else {
            m.push_str("\n  from the boundary: ");
            m.push_str(&(0..FEW).map(item).collect::<Vec<_>>().join("; "));
            m.push_str("\n  to the point: ");
            m.push_str(&(n - FEW..n).map(item).collect::<Vec<_>>().join("; "));
        }
        if let Some(b) = surface_box {
            m.push_str("\n  ");
            m.push_str(&box_crossing(&c, b, dec));
        }
        m.push_str(
            "\n  close the surface's gaps near the path, raise the level until the leaves are \
             smaller than the gaps, or check the inside point",
        );
        m
    }

    /// The [`ErrorKind::Leak`] error carrying [`LeakPath::message`].
    pub fn to_error(&self, domain: &Domain, surface_box: Option<&Aabb>) -> Error {
        Error::new(ErrorKind::Leak, self.message(domain, surface_box))
    }
}

/// Centre of `o` in user units.
pub(crate) fn centre(domain: &Domain, o: Octant) -> [f64; 3] {
    let c = o.coords();
    let h = 0.5 * o.side() as f64;
    domain.from_lattice([c[0] as f64 + h, c[1] as f64 + h, c[2] as f64 + h])
}

/// Side of `o` in user units.
pub(crate) fn size(domain: &Domain, o: Octant) -> f64 {
    o.side() as f64 * domain.side / ROOT_LEN as f64
}

/// Decimals that give about six significant digits at the cube's scale.
pub(crate) fn decimals(domain: &Domain) -> usize {
    (6 - domain.side.log10().floor() as i64).clamp(0, 15) as usize
}

pub(crate) fn fmt_point(p: [f64; 3], dec: usize) -> String {
    format!("({:.dec$}, {:.dec$}, {:.dec$})", p[0], p[1], p[2])
}

pub(crate) fn in_box(p: [f64; 3], b: &Aabb) -> bool {
    (0..3).all(|k| b.min[k] <= p[k] && p[k] <= b.max[k])
}

/// Where the polyline through `c` last enters the closed box `b`: the
/// entry point of the segment between the last centre outside and the next
/// one (slab clipping).
pub(crate) fn box_crossing(c: &[[f64; 3]], b: &Aabb, dec: usize) -> String {
    let what = format!(
        "surface's bounding box {}-{}",
        fmt_point(b.min, dec),
        fmt_point(b.max, dec)
    );
    let n = c.len();
    let Some(last_out) = (0..n).rev().find(|&i| !in_box(c[i], b)) else {
        return format!(
            "the whole path lies inside the {what}: the cube is hardly larger than the surface"
        );
    };
    if last_out == n - 1 {
        return format!("the inside point's octant lies outside the {what}");
    }
    let (p, q) = (c[last_out], c[last_out + 1]);
    // Largest entry parameter over the three slabs.
    let mut t = 0.0f64;
    for k in 0..3 {
        let d = q[k] - p[k];
        if d != 0.0 {
            let t0 = (b.min[k] - p[k]) / d;
            let t1 = (b.max[k] - p[k]) / d;
            t = t.max(t0.min(t1));
        }
    }
    let t = t.clamp(0.0, 1.0);
    let x = std::array::from_fn(|k| p[k] + t * (q[k] - p[k]));
    format!(
        "the path enters the {what} at {} between octants #{} and #{} of {n} (and stays inside)",
        fmt_point(x, dec),
        last_out + 1,
        last_out + 2
    )
}
