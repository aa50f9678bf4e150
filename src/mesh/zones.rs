//! Zones: a name for every element of a mesh that keeps all the leaves, so
//! that one mesh holds several regions (a solid inside a fluid, say) and
//! the writers can tell them apart.
//!
//! # Which zone an element is in
//!
//! Zone 0 is [`INSIDE`] and zone 1 is [`OUTSIDE`]: the side of the surface
//! the element's centre lies on (the class bit the `center` cut rule keeps
//! by, so the inside zone holds exactly the elements `keep inside` keeps
//! and the outside zone those of `keep outside`). With the wall clean-up
//! ([`super::MeshOptions::clean_walls`], on for OpenFOAM cases) the
//! inside zone is what `keep inside` keeps cleaned, so that the interface
//! is manifold, and the outside zone the rest.
//! When the surface has two or more parts (the solids of an ASCII STL,
//! several `--surface` files) and each is closed
//! ([`crate::geometry::parts::Solids`]), the inside splits by solid:
//! zones 2, 3, ... are the solids, in part order, named after them, and
//! an inside element goes to the first solid whose winding number at its
//! centre is at least one half (`inside` keeps what none holds: nothing,
//! up to rounding). Then each refinement region that names a zone
//! ([`Region::zone`]) takes the elements whose centre it holds
//! ([`Region::contains`]), the later regions winning over the earlier
//! ones. Zones named by regions follow the two in the order their names
//! first appear; a region may name `inside`, `outside` or a zone of an
//! earlier region, which then grows.
//!
//! The zone of an element depends only on its class byte and its centre,
//! so the zones (and every file written from them) are the same on any
//! number of ranks; the halo's elements get theirs by the same rule.
//!
//! # For writers
//!
//! [`Zones::names`] gives the names by zone index, [`Zones::of_elements`]
//! the zone index of each local element (Morton order, as
//! [`Mesh::elements`]), [`Zones::of_halo`] that of each [`Mesh::halo`]
//! element, and [`Zones::counts`] the elements of each zone over all ranks.
//! [`Mesh::zones`] has them when the mesh was given zones
//! ([`Mesh::assign_zones`]).

use crate::classify::{Keep, CENTER_INSIDE};
use crate::error::{Error, Result};
use crate::geometry::parts::Solids;
use crate::octree::octant::Octant;
use crate::parallel::comm::{agree, Comm};
use crate::refine::regions::Region;

use super::Mesh;

/// Zone 0: the elements whose centre is inside the surface.
pub const INSIDE: &str = "inside";
/// Zone 1: the elements whose centre is outside the surface.
pub const OUTSIDE: &str = "outside";

/// The zone of every local and halo element. See the module
/// documentation.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Zones {
    names: Vec<String>,
    elements: Vec<u16>,
    halo: Vec<u16>,
    counts: Vec<u64>,
}

impl Zones {
    /// The zones' names, by zone index: `inside`, `outside`, then the
    /// regions' zones.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// The zone index of each local element.
    pub fn of_elements(&self) -> &[u16] {
        &self.elements
    }

    /// The zone index of each halo element ([`Mesh::halo`]).
    pub fn of_halo(&self) -> &[u16] {
        &self.halo
    }

    /// Elements of each zone over all ranks (the same on every rank).
    pub fn counts(&self) -> &[u64] {
        &self.counts
    }

    /// The names of `regions`' zones after `inside` and `outside`, each
    /// once, and the zone index of each region (`None` without a zone).
    fn names_of(solids: &[String], regions: &[Region]) -> (Vec<String>, Vec<Option<u16>>) {
        let mut names = vec![INSIDE.to_string(), OUTSIDE.to_string()];
        names.extend(solids.iter().cloned());
        let index = regions
            .iter()
            .map(|r| {
                let z = r.zone()?;
                Some(match names.iter().position(|n| n == z) {
                    Some(k) => k as u16,
                    None => {
                        names.push(z.to_string());
                        (names.len() - 1) as u16
                    }
                })
            })
            .collect();
        (names, index)
    }
}

impl Mesh {
    /// The zones, when [`Mesh::assign_zones`] gave them.
    pub fn zones(&self) -> Option<&Zones> {
        self.zones.as_ref()
    }

    /// Gives every element a zone by the rule of [`crate::mesh::zones`],
    /// with `regions`' zones (user units). `keep` is what the mesh was
    /// built keeping: zones need every leaf ([`Keep::All`]), so that the
    /// zones meet along internal faces. Collective; an error (on every
    /// rank) changes nothing.
    pub fn assign_zones(
        &mut self,
        comm: &dyn Comm,
        keep: Keep,
        regions: &[Region],
        solids: Option<&Solids>,
    ) -> Result<()> {
        let check = if keep != Keep::All {
            Err(Error::invalid(format!(
                "zones need a mesh keeping all leaves (this one keeps {}): \
                 the inside and the outside are zones of one mesh",
                keep.name()
            )))
        } else if let Some(r) = regions.iter().find_map(|r| r.validate().err()) {
            Err(Error::invalid(format!("a zone's region {r}")))
        } else {
            Ok(())
        };
        agree(comm, check)?;
        let solid_names = solids.map_or(&[][..], |s| s.names());
        let dup = (solid_names.iter().enumerate())
            .find(|(k, n)| *n == INSIDE || *n == OUTSIDE || solid_names[..*k].contains(n));
        if let Some((_, n)) = dup {
            return agree(
                comm,
                Err(Error::invalid(format!(
                    "the solid '{n}' cannot name a zone: its name is taken"
                ))),
            );
        }
        let (names, index) = Zones::names_of(solid_names, regions);
        if names.len() > u16::MAX as usize {
            return Err(Error::invalid("more than 65535 zones"));
        }
        let zoned: Vec<(&Region, u16)> = regions
            .iter()
            .zip(&index)
            .filter_map(|(r, z)| z.map(|z| (r, z)))
            .collect();
        let domain = self.domain;
        let zone_of = |o: &Octant, class: u8| -> u16 {
            let (c, h) = (o.coords(), o.side() as f64 / 2.0);
            let p = || domain.from_lattice(c.map(|x| x as f64 + h));
            let base = match (class & CENTER_INSIDE != 0, solids) {
                (false, _) => 1,
                (true, None) => 0,
                (true, Some(s)) => s.holding(p()).map_or(0, |k| 2 + k as u16),
            };
            if zoned.is_empty() {
                return base;
            }
            let p = p();
            zoned
                .iter()
                .rev()
                .find(|(r, _)| r.contains(p))
                .map_or(base, |&(_, z)| z)
        };
        let bits = &self.centre_inside;
        let class = |i: usize| match bits.get(i / 64) {
            Some(w) if w >> (i % 64) & 1 == 1 => CENTER_INSIDE,
            _ => 0,
        };
        let elements: Vec<u16> = (self.elements.iter().enumerate())
            .map(|(i, o)| zone_of(o, class(i)))
            .collect();
        let halo: Vec<u16> = (self.halo.leaves.iter().zip(&self.halo.classes))
            .map(|(o, &c)| zone_of(o, c))
            .collect();
        let mut counts = vec![0u64; names.len()];
        for &z in &elements {
            counts[z as usize] += 1;
        }
        comm.sum_u64(&mut counts);
        self.zones = Some(Zones {
            names,
            elements,
            halo,
            counts,
        });
        Ok(())
    }
}

/// The interfaces between zones: for each pair of zones `a < b` that
/// meet somewhere (on any rank), the pair. `pairs` lists the zone pairs
/// of this rank's faces, in any order and with repeats. Collective; the
/// same list, increasing, on every rank.
pub fn interfaces(
    comm: &dyn Comm,
    zones: usize,
    pairs: impl Iterator<Item = (u16, u16)>,
) -> Vec<(u16, u16)> {
    let index = |a: usize, b: usize| a * zones + b;
    let mut seen = vec![0u64; zones * zones];
    for (a, b) in pairs {
        let (a, b) = (a.min(b) as usize, a.max(b) as usize);
        if a != b {
            seen[index(a, b)] = 1;
        }
    }
    comm.sum_u64(&mut seen);
    let mut out = Vec::new();
    for a in 0..zones {
        for b in a + 1..zones {
            if seen[index(a, b)] > 0 {
                out.push((a as u16, b as u16));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use std::rc::Rc;

    use super::*;
    use crate::classify::CutRule;
    use crate::config::Config;
    use crate::octree::octant::Connectivity;
    use crate::parallel::comm::SerialComm;
    use crate::pipeline::Session;

    #[test]
    fn names_come_once_in_order_of_first_appearance() {
        let r = |s: &str| Region::parse(s).unwrap();
        let regions = [
            r("box:0,0,0,1,1,1:3:zone=a"),
            r("box:0,0,0,1,1,1:3"),
            r("sphere:0,0,0,1:3:zone=inside"),
            r("sphere:0,0,0,1:3:zone=b"),
            r("sphere:0,0,0,2:3:zone=a"),
        ];
        let (names, index) = Zones::names_of(&[], &regions);
        assert_eq!(names, ["inside", "outside", "a", "b"]);
        assert_eq!(index, [Some(2), None, Some(0), Some(3), Some(2)]);
    }

    #[test]
    fn the_inside_zone_is_what_keep_inside_keeps_and_later_regions_win() {
        let session = |keep: Keep, zones: bool, regions: &[Region]| {
            let mut c = Config::default();
            c.surface.file = "sphere".into();
            c.mesh.zones = zones;
            c.regions = regions.to_vec();
            let mut s = Session::new(Rc::new(SerialComm), c);
            s.load_surface().unwrap();
            s.refine_surface(4).unwrap();
            s.balance(Connectivity::Corner).unwrap();
            s.build_mesh(keep, CutRule::Center).map(|_| s)
        };
        let count = |keep| {
            session(keep, false, &[])
                .unwrap()
                .mesh()
                .unwrap()
                .counts()
                .elements
        };
        let (inside, outside) = (count(Keep::Inside), count(Keep::Outside));
        let s = session(Keep::All, true, &[]).unwrap();
        let z = s.mesh().unwrap().zones().unwrap();
        assert_eq!(z.counts(), [inside, outside]);
        // A box over the half x > 0 (refining nothing), then a ball at the
        // origin over it.
        let regions = [
            Region::parse("box:0,-9,-9,9,9,9:0:zone=east").unwrap(),
            Region::parse("sphere:0,0,0,0.5:0:zone=core").unwrap(),
        ];
        let s = session(Keep::All, true, &regions).unwrap();
        let mesh = s.mesh().unwrap();
        let z = mesh.zones().unwrap();
        assert_eq!(z.names(), ["inside", "outside", "east", "core"]);
        assert_eq!(z.counts().iter().sum::<u64>(), inside + outside);
        let plain = session(Keep::All, true, &[]).unwrap();
        let plain = plain
            .mesh()
            .unwrap()
            .zones()
            .unwrap()
            .of_elements()
            .to_vec();
        for (i, &k) in z.of_elements().iter().enumerate() {
            let c = mesh.element_centre(i);
            let r2: f64 = c.iter().map(|x| x * x).sum();
            let want = if r2 <= 0.25 {
                3
            } else if c[0] >= 0.0 {
                2
            } else {
                plain[i]
            };
            assert_eq!(k, want, "element {i} at {c:?}");
        }
        assert!(z.counts().iter().all(|&n| n > 0), "{:?}", z.counts());
        // Only a mesh of every leaf takes zones.
        let err = session(Keep::Inside, true, &[]).err().unwrap();
        assert!(err.message().contains("need keep all"), "{err}");
    }
}
