//! Refinement regions: boxes, spheres and cylinders in user units, each with
//! a level, refining where they are (or, with `outside`, where they are
//! not), and the minimum level everywhere.
//!
//! The rule, the same for every region and like the surface's: a leaf is
//! split while its level is below the region's level and its closed box
//! overlaps the closed region (for `outside`: is not inside the region's
//! interior). Applied after the surface refinement by splitting leaves
//! recursively, it gives the coarsest octree that satisfies the surface,
//! every region and the minimum level; balance comes after.
//!
//! ```text
//!   box            sphere           cylinder (start ── end, radius r)
//!   +------+         .-"-.           ___________________
//!   |      |        /     \         (___________________)
//!   +------+        \     /          start           end
//!   min..max         '-.-'
//! ```
//!
//! Tests against a leaf are exact for boxes and spheres; for a cylinder
//! the distance from the axis segment to the box is minimised over the
//! segment (a convex function of its parameter) to a relative 1e-12, which
//! may count a box just beyond a flat cap as overlapping (one more split,
//! never one less).

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::geometry::distance::any_box_within;
use crate::octree::brick::Brick;
use crate::octree::domain::Domain;
use crate::octree::octant::{Octant, MAX_LEVEL};
use crate::refine::{scatter_by_child, SurfaceIndex};

/// A refinement region with its level, user units.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "shape", rename_all = "lowercase", deny_unknown_fields)]
pub enum Region {
    /// The box `min..max`.
    Box {
        /// Lowest corner.
        min: [f64; 3],
        /// Highest corner.
        max: [f64; 3],
        /// Leaves overlapping it are refined to this level (counted from the
        /// root cells).
        #[serde(default)]
        level: u8,
        /// The level as a cell size in user units instead: the coarsest
        /// level whose cell is not larger (`size=S` on the command line).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        size: Option<f64>,
        /// Refine where the box is not, instead.
        #[serde(default)]
        outside: bool,
        /// With `mesh.zones`, the elements whose centre lies in the region
        /// (where it refines) belong to the zone of this name.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        zone: Option<String>,
    },
    /// The ball of `radius` around `center`.
    Sphere {
        /// Centre.
        center: [f64; 3],
        /// Radius (> 0).
        radius: f64,
        /// Leaves overlapping it are refined to this level (counted from the
        /// root cells).
        #[serde(default)]
        level: u8,
        /// The level as a cell size in user units instead: the coarsest
        /// level whose cell is not larger (`size=S` on the command line).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        size: Option<f64>,
        /// Refine where the ball is not, instead.
        #[serde(default)]
        outside: bool,
        /// With `mesh.zones`, the elements whose centre lies in the region
        /// (where it refines) belong to the zone of this name.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        zone: Option<String>,
    },
    /// The points within `radius` of the segment `start..end` whose
    /// projection falls on the segment (flat caps).
    Cylinder {
        /// One end of the axis.
        start: [f64; 3],
        /// The other end.
        end: [f64; 3],
        /// Radius (> 0).
        radius: f64,
        /// Leaves overlapping it are refined to this level (counted from the
        /// root cells).
        #[serde(default)]
        level: u8,
        /// The level as a cell size in user units instead: the coarsest
        /// level whose cell is not larger (`size=S` on the command line).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        size: Option<f64>,
        /// Refine where the cylinder is not, instead.
        #[serde(default)]
        outside: bool,
        /// With `mesh.zones`, the elements whose centre lies in the region
        /// (where it refines) belong to the zone of this name.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        zone: Option<String>,
    },
}

impl Region {
    /// The region's level.
    pub fn level(&self) -> u8 {
        match self {
            Region::Box { level, .. }
            | Region::Sphere { level, .. }
            | Region::Cylinder { level, .. } => *level,
        }
    }

    /// The region's level as a cell size, when given so (the level is
    /// then found once the domain is known, [`Region::sized`]).
    pub fn size(&self) -> Option<f64> {
        match self {
            Region::Box { size, .. }
            | Region::Sphere { size, .. }
            | Region::Cylinder { size, .. } => *size,
        }
    }

    /// The region with its size turned into a level for root cells of side
    /// `root_side` (unchanged without a size).
    pub fn sized(&self, root_side: f64) -> Result<Region> {
        let mut r = self.clone();
        if let Some(s) = self.size() {
            let l = level_for_size(root_side, s)?;
            match &mut r {
                Region::Box { level, size, .. }
                | Region::Sphere { level, size, .. }
                | Region::Cylinder { level, size, .. } => {
                    (*level, *size) = (l, None);
                }
            }
        }
        Ok(r)
    }

    /// Whether it refines outside its shape.
    pub fn outside(&self) -> bool {
        match self {
            Region::Box { outside, .. }
            | Region::Sphere { outside, .. }
            | Region::Cylinder { outside, .. } => *outside,
        }
    }

    /// The zone the region names (`mesh.zones`), if any.
    pub fn zone(&self) -> Option<&str> {
        match self {
            Region::Box { zone, .. }
            | Region::Sphere { zone, .. }
            | Region::Cylinder { zone, .. } => zone.as_deref(),
        }
    }

    /// Whether the point `p` (user units) is where the region refines: in
    /// the closed shape or, for `outside`, not in its open interior.
    pub fn contains(&self, p: [f64; 3]) -> bool {
        let shape = match *self {
            Region::Box { min, max, .. } => Lattice::Box(min, max),
            Region::Sphere { center, radius, .. } => Lattice::Sphere(center, radius),
            Region::Cylinder {
                start, end, radius, ..
            } => Lattice::Cylinder(start, end, radius),
        };
        match self.outside() {
            false => overlaps(shape, p, p),
            true => !inside_interior(shape, p, p),
        }
    }

    /// `box`, `sphere` or `cylinder`.
    pub fn shape(&self) -> &'static str {
        match self {
            Region::Box { .. } => "box",
            Region::Sphere { .. } => "sphere",
            Region::Cylinder { .. } => "cylinder",
        }
    }

    /// Checks the numbers: finite, positive radii, a box with min below
    /// max, a cylinder of positive length, a level at most 18. The message
    /// follows the region's name.
    pub fn validate(&self) -> std::result::Result<(), String> {
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        if self.level() > MAX_LEVEL {
            return Err(format!(
                "has level {}, above the maximum level {MAX_LEVEL}",
                self.level()
            ));
        }
        if let Some(z) = self.zone() {
            if let Err(e) = crate::geometry::names::check_word(z) {
                let why = e.message().replace("patch name", "zone name");
                return Err(format!("has a bad zone: {why}"));
            }
        }
        if let Some(s) = self.size() {
            if !(s.is_finite() && s > 0.0) {
                return Err(format!("needs a positive size, got {s}"));
            }
            if self.level() > 0 {
                return Err("gives both a level and a size: give one".to_string());
            }
        }
        match self {
            Region::Box { min, max, .. } => {
                if !finite(min) || !finite(max) || (0..3).any(|k| min[k] >= max[k]) {
                    return Err(format!(
                        "needs finite corners with min below max, got {min:?} and {max:?}"
                    ));
                }
            }
            Region::Sphere { center, radius, .. } => {
                if !(finite(center) && radius.is_finite() && *radius > 0.0) {
                    return Err(format!(
                        "needs a finite centre and a positive radius, got {center:?} and {radius}"
                    ));
                }
            }
            Region::Cylinder {
                start, end, radius, ..
            } => {
                if !(finite(start)
                    && finite(end)
                    && start != end
                    && radius.is_finite()
                    && *radius > 0.0)
                {
                    return Err(format!(
                        "needs two distinct finite ends and a positive radius, got {start:?}, {end:?} and {radius}"
                    ));
                }
            }
        }
        Ok(())
    }

    /// The region's bounding box, user units.
    pub fn bounding_box(&self) -> ([f64; 3], [f64; 3]) {
        match *self {
            Region::Box { min, max, .. } => (min, max),
            Region::Sphere { center, radius, .. } => {
                (center.map(|c| c - radius), center.map(|c| c + radius))
            }
            Region::Cylinder {
                start, end, radius, ..
            } => (
                std::array::from_fn(|a| start[a].min(end[a]) - radius),
                std::array::from_fn(|a| start[a].max(end[a]) + radius),
            ),
        }
    }

    /// A box inside the region (`None` for a cylinder): the box itself, or
    /// the cube inscribed in a sphere.
    pub fn inner_box(&self) -> Option<([f64; 3], [f64; 3])> {
        match *self {
            Region::Box { min, max, .. } => Some((min, max)),
            Region::Sphere { center, radius, .. } => {
                let h = radius / 3f64.sqrt();
                Some((center.map(|c| c - h), center.map(|c| c + h)))
            }
            Region::Cylinder { .. } => None,
        }
    }

    /// The region in the command line's form.
    pub fn describe(&self) -> String {
        let list = |v: &[f64]| {
            v.iter()
                .map(|x| x.to_string())
                .collect::<Vec<_>>()
                .join(",")
        };
        let numbers = match *self {
            Region::Box { min, max, .. } => list(&[min, max].concat()),
            Region::Sphere { center, radius, .. } => list(&[&center[..], &[radius]].concat()),
            Region::Cylinder {
                start, end, radius, ..
            } => list(&[&start[..], &end[..], &[radius]].concat()),
        };
        let outside = if self.outside() { ":outside" } else { "" };
        let level = match self.size() {
            Some(s) => format!("size={s}"),
            None => self.level().to_string(),
        };
        let zone = match self.zone() {
            Some(z) => format!(":zone={z}"),
            None => String::new(),
        };
        format!("{}:{numbers}:{level}{outside}{zone}", self.shape())
    }

    /// Parses the command line's form: `box:X0,Y0,Z0,X1,Y1,Z1:LEVEL`,
    /// `sphere:CX,CY,CZ,R:LEVEL` or `cylinder:X0,Y0,Z0,X1,Y1,Z1,R:LEVEL`,
    /// each optionally followed by `:outside`, then by `:zone=NAME`;
    /// `LEVEL` may be `size=S`, a cell size in user units.
    pub fn parse(s: &str) -> Result<Region> {
        let bad = |why: &str| {
            Error::invalid(format!(
                "expects box:X0,Y0,Z0,X1,Y1,Z1:LEVEL, sphere:CX,CY,CZ,R:LEVEL or \
                 cylinder:X0,Y0,Z0,X1,Y1,Z1,R:LEVEL (then :outside and :zone=NAME if wanted), \
                 got '{s}': {why}"
            ))
        };
        let mut parts: Vec<&str> = s.split(':').collect();
        let zone = match parts.last().and_then(|p| p.strip_prefix("zone=")) {
            Some(z) => {
                let z = z.to_string();
                parts.pop();
                Some(z)
            }
            None => None,
        };
        let (shape, numbers, level, outside) = match parts.as_slice() {
            [shape, n, l] => (*shape, *n, *l, false),
            [shape, n, l, "outside"] => (*shape, *n, *l, true),
            _ => return Err(bad("wrong number of ':' parts")),
        };
        let v: Vec<f64> = numbers
            .split(',')
            .map(|x| x.trim().parse::<f64>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| bad("not a list of numbers"))?;
        let (level, size) = match level.strip_prefix("size=") {
            Some(v) => (
                0,
                Some(
                    v.parse::<f64>()
                        .map_err(|_| bad("the size is not a number"))?,
                ),
            ),
            None => (
                level
                    .parse()
                    .map_err(|_| bad("the level is not an integer"))?,
                None,
            ),
        };
        let p = |i: usize| [v[i], v[i + 1], v[i + 2]];
        let r = match (shape, v.len()) {
            ("box", 6) => Region::Box {
                min: p(0),
                max: p(3),
                level,
                size,
                outside,
                zone: zone.clone(),
            },
            ("sphere", 4) => Region::Sphere {
                center: p(0),
                radius: v[3],
                level,
                size,
                outside,
                zone: zone.clone(),
            },
            ("cylinder", 7) => Region::Cylinder {
                start: p(0),
                end: p(3),
                radius: v[6],
                level,
                size,
                outside,
                zone: zone.clone(),
            },
            ("box" | "sphere" | "cylinder", n) => return Err(bad(&format!("{n} numbers"))),
            _ => return Err(bad("unknown shape")),
        };
        r.validate().map_err(|m| bad(&m))?;
        Ok(r)
    }
}

/// The regions mapped to the lattice of a domain, ready for octant tests.
pub struct RegionRules<'a> {
    min_level: u8,
    /// The domain's root cells: void octants never split, the others at
    /// least to the trees' level.
    brick: Brick,
    rules: Vec<(Lattice, u8, bool)>,
    /// Distance bands (lattice units, level), increasing distances, and the
    /// surface they measure from.
    bands: Vec<(f64, u8)>,
    surface: Option<&'a SurfaceIndex>,
    /// [`RegionRules::max_level`], and the deepest band's level (0 without
    /// bands), kept: the walks ask at every octant.
    max: u8,
    deepest: u8,
}

/// Scratch space of [`RegionRules::refine_leaf`]: the candidate stack.
#[derive(Default)]
pub struct BandScratch {
    stack: Vec<u32>,
    masks: Vec<u8>,
    /// Candidates the cheap tests left to the exact distances.
    undecided: Vec<u32>,
}

/// A region's shape in lattice units.
#[derive(Clone, Copy, Debug)]
enum Lattice {
    Box([f64; 3], [f64; 3]),
    Sphere([f64; 3], f64),
    Cylinder([f64; 3], [f64; 3], f64),
}

impl<'a> RegionRules<'a> {
    /// The rules of `regions` and `min_level` in the lattice of `domain`.
    /// Levels count from the domain's root cells.
    pub fn new(domain: &Domain, min_level: u8, regions: &[Region]) -> RegionRules<'a> {
        let k = domain.brick.level();
        let s = domain.scale();
        let rules = regions
            .iter()
            .map(|r| {
                let shape = match r {
                    Region::Box { min, max, .. } => {
                        Lattice::Box(domain.to_lattice(*min), domain.to_lattice(*max))
                    }
                    Region::Sphere { center, radius, .. } => {
                        Lattice::Sphere(domain.to_lattice(*center), radius * s)
                    }
                    Region::Cylinder {
                        start, end, radius, ..
                    } => Lattice::Cylinder(
                        domain.to_lattice(*start),
                        domain.to_lattice(*end),
                        radius * s,
                    ),
                };
                (shape, r.level() + k, r.outside())
            })
            .collect();
        let mut r = RegionRules {
            min_level: min_level + k,
            brick: domain.brick,
            rules,
            bands: Vec::new(),
            surface: None,
            max: 0,
            deepest: 0,
        };
        r.max = r.finest_rule();
        r
    }

    /// Adds distance bands `(distance in user units, level)` around
    /// `surface` (indexed in the lattice of `domain`): a leaf is split while
    /// its level is below a band's and its closed box comes within the
    /// band's distance of the surface.
    pub fn with_bands(
        mut self,
        domain: &Domain,
        bands: &[(f64, u8)],
        surface: &'a SurfaceIndex,
    ) -> RegionRules<'a> {
        self.bands = bands
            .iter()
            .map(|&(d, l)| (d * domain.scale(), l + domain.brick.level()))
            .collect();
        self.surface = Some(surface);
        self.deepest = self.bands.iter().map(|b| b.1).max().unwrap_or(0);
        self.max = self.finest_rule();
        self
    }

    /// Whether no rule asks for more than the root cells (which the
    /// octree's construction splits a box domain's cube into already).
    pub fn is_empty(&self) -> bool {
        let k = self.brick.level();
        self.min_level <= k
            && self.rules.iter().all(|r| r.1 <= k)
            && self.bands.iter().all(|b| b.1 <= k)
    }

    /// The finest level any rule asks for.
    pub fn max_level(&self) -> u8 {
        self.max
    }

    fn finest_rule(&self) -> u8 {
        let bands = self.bands.iter().map(|b| b.1);
        self.rules
            .iter()
            .map(|r| r.1)
            .chain(bands)
            .fold(self.min_level, u8::max)
    }

    /// Whether leaf `o` must be split; `buf` is scratch space.
    pub fn splits(&self, o: Octant, buf: &mut Vec<u32>) -> bool {
        if self.brick.is_void(o) {
            return false;
        }
        if let Some(s) = self.surface {
            let widest = self.widest(o.level());
            let (lo, hi) = o.bounds_f64();
            if widest >= 0.0 && s.box_within(lo, hi, widest, buf) {
                return true;
            }
        }
        self.shapes_split(o)
    }

    /// The widest band that still refines a leaf at `level` (lattice
    /// units), or -1 when none does: the narrower ones lie inside it, so it
    /// alone decides. Never grows with the level.
    fn widest(&self, level: u8) -> f64 {
        self.bands
            .iter()
            .filter(|b| level < b.1)
            .map(|b| b.0)
            .fold(-1.0, f64::max)
    }

    /// Appends to `out` the leaves that replace leaf `o` under every rule:
    /// [`RegionRules::splits`] applied recursively, but with the bands'
    /// candidate triangles found once for `o` and passed down, each child
    /// keeping those whose boxes come within its band's distance, rather
    /// than one search of the bounding-box tree per octant (as surface
    /// refinement passes its candidates down; sharing one search among
    /// neighbouring leaves was tried and was slower). Fails (the octant
    /// limit's error) once `out` holds more than `limit` leaves.
    pub fn refine_leaf(
        &self,
        o: Octant,
        out: &mut Vec<Octant>,
        scratch: &mut BandScratch,
        limit: u64,
    ) -> Result<()> {
        let w = self.widest(o.level());
        let (Some(s), true) = (self.surface, w >= 0.0 && !self.brick.is_void(o)) else {
            let buf = &mut scratch.stack;
            let max = self.max_level();
            return crate::refine::refine_rec(o, max, &mut |q| self.splits(q, buf), out, limit);
        };
        let (lo, hi) = o.bounds_f64();
        let stack = &mut scratch.stack;
        stack.clear();
        s.bvh
            .query_candidates(lo.map(|x| x - w), hi.map(|x| x + w), stack);
        let n = stack.len();
        self.walk(s, o, (0, n), out, scratch, limit)
    }

    /// Appends to `out` the leaves that replace `leaves` (this rank's, in
    /// Morton order) under every rule: [`RegionRules::refine_leaf`] for each,
    /// with the bands' candidates found by one walk down the octree the
    /// leaves belong to instead of one search of the bounding-box tree per
    /// leaf. From the common ancestor of the leaves down, each octant's
    /// candidates (triangles whose boxes come within its band's distance,
    /// per axis: a superset) are split among its eight children, as surface
    /// refinement splits its own; octants without candidates, or below the
    /// bands' levels, hand their leaves to the walk with none. Fails (the
    /// octant limit's error) once `out` holds more than `limit` leaves.
    pub fn refine_leaves(
        &self,
        leaves: &[Octant],
        out: &mut Vec<Octant>,
        scratch: &mut BandScratch,
        limit: u64,
    ) -> Result<()> {
        let (Some(s), Some(&first), Some(&last)) = (self.surface, leaves.first(), leaves.last())
        else {
            return leaves
                .iter()
                .try_for_each(|&o| self.refine_leaf(o, out, scratch, limit));
        };
        let top = first.nearest_common_ancestor(last);
        let top = if top.contains(first) {
            top
        } else {
            top.parent()
        };
        scratch.stack.clear();
        self.split_leaves(s, top, leaves, out, scratch, limit)
    }

    /// [`RegionRules::refine_leaves`] for the `leaves` inside `o`, above
    /// the level where the candidates are searched.
    fn split_leaves(
        &self,
        s: &SurfaceIndex,
        o: Octant,
        leaves: &[Octant],
        out: &mut Vec<Octant>,
        scratch: &mut BandScratch,
        limit: u64,
    ) -> Result<()> {
        if leaves.is_empty() {
            return Ok(());
        }
        if leaves[0] == o || o.level() + SEARCH_ABOVE >= self.max_level() {
            let w = self.widest(o.level());
            let stack = &mut scratch.stack;
            let a = stack.len();
            if w >= 0.0 {
                let (lo, hi) = o.bounds_f64();
                s.bvh
                    .query_candidates(lo.map(|x| x - w), hi.map(|x| x + w), stack);
            }
            let b = stack.len();
            self.descend(s, o, leaves, (a, b), out, scratch, limit)?;
            scratch.stack.truncate(a);
            return Ok(());
        }
        let slices = child_slices(o, leaves);
        for (c, mine) in o.children().into_iter().zip(slices) {
            self.split_leaves(s, c, mine, out, scratch, limit)?;
        }
        Ok(())
    }

    /// [`RegionRules::refine_leaves`] for the `leaves` inside `o`, whose
    /// candidates are `stack[a..b]`.
    #[allow(clippy::too_many_arguments)]
    fn descend(
        &self,
        s: &SurfaceIndex,
        o: Octant,
        leaves: &[Octant],
        (a, b): (usize, usize),
        out: &mut Vec<Octant>,
        scratch: &mut BandScratch,
        limit: u64,
    ) -> Result<()> {
        if leaves.is_empty() {
            return Ok(());
        }
        let w = self.widest(o.level() + 1);
        if leaves[0] == o || a == b || w < 0.0 {
            // A leaf, or no candidate for any leaf inside `o`: the
            // candidates (none, or `o`'s own when it is the leaf) are final.
            let range = if leaves[0] == o { (a, b) } else { (a, a) };
            for &l in leaves {
                if self.brick.is_void(l) {
                    out.push(l);
                    if out.len() as u64 > limit {
                        return Err(crate::refine::limit_error(limit, "refining"));
                    }
                } else {
                    self.walk(s, l, range, out, scratch, limit)?;
                }
            }
            return Ok(());
        }
        // The leaves of each child, and the children with a leaf some band
        // may split: only those get candidates.
        let children = o.children();
        let slices = child_slices(o, leaves);
        // Bands split leaves below the deepest band's level only.
        let deepest = self.deepest;
        let need = (0..8)
            .filter(|&i| slices[i].iter().any(|l| l.level() < deepest))
            .fold(0u8, |m, i| m | 1 << i);
        // Per axis, the children (bit set: high half) whose slab the
        // triangle's box grown by `w` meets.
        let (lo, hi) = o.bounds_f64();
        let mid: [f64; 3] = std::array::from_fn(|k| 0.5 * (lo[k] + hi[k]));
        let boxes = s.boxes();
        let child_mask = |t: u32| -> u8 {
            let bx = &boxes[t as usize];
            let mut m = need;
            for k in 0..3 {
                let (tl, th) = (bx.min[k] - w, bx.max[k] + w);
                let low = (tl <= mid[k]) & (th >= lo[k]);
                let high = (tl <= hi[k]) & (th >= mid[k]);
                m &= (low as u8).wrapping_neg() & LOW_HALF[k]
                    | (high as u8).wrapping_neg() & !LOW_HALF[k];
            }
            m
        };
        let BandScratch { stack, masks, .. } = scratch;
        let bounds = if need == 0 {
            [stack.len(); 9]
        } else {
            masks.clear();
            masks.extend(stack[a..b].iter().map(|&t| child_mask(t)));
            scatter_by_child(stack, a, b, |j| masks[j - a])
        };
        for (i, c) in children.into_iter().enumerate() {
            let range = (bounds[i], bounds[i + 1]);
            self.descend(s, c, slices[i], range, out, scratch, limit)?;
        }
        scratch.stack.truncate(bounds[0]);
        Ok(())
    }

    /// [`RegionRules::refine_leaf`] below `o`, whose candidates are
    /// `stack[a..b]`.
    fn walk(
        &self,
        s: &SurfaceIndex,
        o: Octant,
        (a, b): (usize, usize),
        out: &mut Vec<Octant>,
        scratch: &mut BandScratch,
        limit: u64,
    ) -> Result<()> {
        let level = o.level();
        let max = self.max_level();
        let split = level < max && {
            let w = self.widest(level);
            let (lo, hi) = o.bounds_f64();
            let ids = &scratch.stack[a..b];
            let undecided = &mut scratch.undecided;
            (w >= 0.0 && any_box_within(&s.tris, ids, lo, hi, w, undecided)) || self.shapes_split(o)
        };
        if !split {
            out.push(o);
            if out.len() as u64 > limit {
                return Err(crate::refine::limit_error(limit, "refining"));
            }
            return Ok(());
        }
        let w = self.widest(level + 1);
        // Children at the finest level are leaves: no candidates needed.
        if w < 0.0 || level + 1 >= max {
            for c in o.children() {
                self.walk(s, c, (0, 0), out, scratch, limit)?;
            }
            return Ok(());
        }
        let (lo, hi) = o.bounds_f64();
        let mid: [f64; 3] = std::array::from_fn(|k| 0.5 * (lo[k] + hi[k]));
        let (boxes, w2) = (s.boxes(), w * w);
        let BandScratch { stack, masks, .. } = scratch;
        masks.clear();
        masks.extend(
            stack[a..b]
                .iter()
                .map(|&t| child_gap_mask(&boxes[t as usize], lo, mid, hi, w2)),
        );
        let bounds = scatter_by_child(stack, a, b, |j| masks[j - a]);
        for (i, c) in o.children().into_iter().enumerate() {
            self.walk(s, c, (bounds[i], bounds[i + 1]), out, scratch, limit)?;
        }
        scratch.stack.truncate(bounds[0]);
        Ok(())
    }

    /// Whether the minimum level or a region asks to split `o` (not void).
    fn shapes_split(&self, o: Octant) -> bool {
        if o.level() < self.min_level {
            return true;
        }
        let (lo, hi) = o.bounds_f64();
        self.rules.iter().any(|&(shape, level, outside)| {
            o.level() < level
                && if outside {
                    !inside_interior(shape, lo, hi)
                } else {
                    overlaps(shape, lo, hi)
                }
        })
    }
}

/// The leaves (sorted, all inside `o`) inside each child of `o`.
fn child_slices(o: Octant, leaves: &[Octant]) -> [&[Octant]; 8] {
    // Each child's run found by galloping from its start: the probes stay
    // near the leaves the walk reads next, where bisecting the whole run
    // misses the cache.
    let mut rest = leaves;
    o.children().map(|c| {
        let last = c.cell_end() - 1;
        let k = crate::octree::sort::gallop_last_le(rest.len(), 0, last, |j| rest[j].cell_begin())
            .map_or(0, |j| j + 1);
        let (mine, after) = rest.split_at(k);
        rest = after;
        mine
    })
}

/// How many levels above the finest rule the band's candidates are
/// searched in the bounding-box tree (and split among children below): a
/// search per leaf costs more, and splitting from the root more still.
const SEARCH_ABOVE: u8 = 4;

/// The children in the low half along each axis (child bit `k` clear).
const LOW_HALF: [u8; 3] = [0b0101_0101, 0b0011_0011, 0b0000_1111];

/// The children of the octant `lo..hi` (halves split at `mid`; bit `k` of
/// a child set: the high half along `k`) whose closed boxes come within
/// `sqrt(w2)` of the box `b`, exactly: the squared gaps per axis to either
/// half, summed per child.
fn child_gap_mask(
    b: &crate::geometry::Aabb,
    lo: [f64; 3],
    mid: [f64; 3],
    hi: [f64; 3],
    w2: f64,
) -> u8 {
    let gap2 = |k: usize, l: f64, h: f64| {
        let g = (l - b.max[k]).max(0.0).max(b.min[k] - h);
        g * g
    };
    let low: [f64; 3] = std::array::from_fn(|k| gap2(k, lo[k], mid[k]));
    let high: [f64; 3] = std::array::from_fn(|k| gap2(k, mid[k], hi[k]));
    let mut m = 0u8;
    for c in 0..8 {
        let pick = |k: usize| if c >> k & 1 == 1 { high[k] } else { low[k] };
        m |= ((pick(0) + pick(1) + pick(2) <= w2) as u8) << c;
    }
    m
}

/// Squared distance from point `p` to the box `lo..hi`.
fn dist2_to_box(p: [f64; 3], lo: [f64; 3], hi: [f64; 3]) -> f64 {
    (0..3)
        .map(|k| {
            let d = (lo[k] - p[k]).max(0.0).max(p[k] - hi[k]);
            d * d
        })
        .sum()
}

/// The point at parameter `t` of the segment `a..b`.
fn along(a: [f64; 3], b: [f64; 3], t: f64) -> [f64; 3] {
    std::array::from_fn(|k| a[k] + t * (b[k] - a[k]))
}

/// Whether the closed shape meets the closed box `lo..hi`.
fn overlaps(shape: Lattice, lo: [f64; 3], hi: [f64; 3]) -> bool {
    match shape {
        Lattice::Box(a, b) => (0..3).all(|k| a[k] <= hi[k] && lo[k] <= b[k]),
        Lattice::Sphere(c, r) => dist2_to_box(c, lo, hi) <= r * r,
        Lattice::Cylinder(a, b, r) => cylinder_meets_box(a, b, r, lo, hi),
    }
}

/// Whether the closed box `lo..hi` lies in the shape's open interior.
fn inside_interior(shape: Lattice, lo: [f64; 3], hi: [f64; 3]) -> bool {
    let corners =
        (0..8).map(|c| std::array::from_fn(|k| if c >> k & 1 == 1 { hi[k] } else { lo[k] }));
    match shape {
        Lattice::Box(a, b) => (0..3).all(|k| a[k] < lo[k] && hi[k] < b[k]),
        // Both shapes are convex: the box is inside when its corners are.
        Lattice::Sphere(c, r) => corners
            .into_iter()
            .all(|q: [f64; 3]| (0..3).map(|k| (q[k] - c[k]).powi(2)).sum::<f64>() < r * r),
        Lattice::Cylinder(a, b, r) => corners.into_iter().all(|q: [f64; 3]| {
            let d: [f64; 3] = std::array::from_fn(|k| b[k] - a[k]);
            let len2: f64 = d.iter().map(|x| x * x).sum();
            let t = (0..3).map(|k| (q[k] - a[k]) * d[k]).sum::<f64>() / len2;
            let foot = along(a, b, t);
            t > 0.0 && t < 1.0 && (0..3).map(|k| (q[k] - foot[k]).powi(2)).sum::<f64>() < r * r
        }),
    }
}

/// Whether the closed cylinder meets the closed box: some point of the box
/// is within `r` of the axis segment with its projection on the segment.
/// The box is cut to the slab between the caps first (the slab and the box
/// are convex); then the distance from the segment to that part is a convex
/// function of the segment's parameter, minimised by golden sections.
fn cylinder_meets_box(a: [f64; 3], b: [f64; 3], r: f64, lo: [f64; 3], hi: [f64; 3]) -> bool {
    let d: [f64; 3] = std::array::from_fn(|k| b[k] - a[k]);
    // Parameter range of the box's projection on the axis.
    let len2: f64 = d.iter().map(|x| x * x).sum();
    let proj = |q: [f64; 3]| (0..3).map(|k| (q[k] - a[k]) * d[k]).sum::<f64>() / len2;
    let (mut t0, mut t1) = (f64::INFINITY, f64::NEG_INFINITY);
    for c in 0..8 {
        let q = std::array::from_fn(|k| if c >> k & 1 == 1 { hi[k] } else { lo[k] });
        let t = proj(q);
        t0 = t0.min(t);
        t1 = t1.max(t);
    }
    let (t0, t1) = (t0.max(0.0), t1.min(1.0));
    if t0 > t1 {
        return false;
    }
    // Over t in [t0, t1] the distance from the axis point to the box is
    // convex; at its minimum a box point within r projects inside [0, 1]
    // when the box reaches that far along the axis, which t0..t1 ensures
    // up to the slab's corners (a conservative answer there refines one
    // more leaf, never one less).
    let f = |t: f64| dist2_to_box(along(a, b, t), lo, hi);
    let (mut x0, mut x1) = (t0, t1);
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let mut c = x1 - g * (x1 - x0);
    let mut e = x0 + g * (x1 - x0);
    let (mut fc, mut fe) = (f(c), f(e));
    for _ in 0..80 {
        if fc <= fe {
            x1 = e;
            e = c;
            fe = fc;
            c = x1 - g * (x1 - x0);
            fc = f(c);
        } else {
            x0 = c;
            c = e;
            fc = fe;
            e = x0 + g * (x1 - x0);
            fe = f(e);
        }
    }
    [f(t0), f(t1), fc, fe]
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min)
        <= r * r * (1.0 + 1e-12)
}

/// The level whose cell is not larger than `size` (user units) in a cube of
/// side `side`: the smallest `l` with `side / 2^l <= size`.
pub fn level_for_size(side: f64, size: f64) -> Result<u8> {
    if !(size.is_finite() && size > 0.0) {
        return Err(Error::invalid(format!(
            "a cell size must be positive, got {size}"
        )));
    }
    let l = (side / size).log2().ceil().max(0.0);
    if l > MAX_LEVEL as f64 {
        return Err(Error::invalid(format!(
            "a cell of size {size} needs level {l}, above the maximum level {MAX_LEVEL} in a domain of side {side}"
        )));
    }
    Ok(l as u8)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_the_command_line_forms() {
        let r = Region::parse("box:0,0,0,1,2,3:7").unwrap();
        assert_eq!(
            r,
            Region::Box {
                min: [0.0; 3],
                max: [1.0, 2.0, 3.0],
                level: 7,
                size: None,
                outside: false,
                zone: None
            }
        );
        let r = Region::parse("sphere:0,0,0,0.5:6:zone=solid").unwrap();
        assert_eq!((r.zone(), r.outside()), (Some("solid"), false));
        assert_eq!(r.describe(), "sphere:0,0,0,0.5:6:zone=solid");
        assert!(r.contains([0.5, 0.0, 0.0]) && !r.contains([0.3, 0.3, 0.3]));
        let r = Region::parse("box:0,0,0,1,1,1:3:outside:zone=far").unwrap();
        assert!(r.contains([2.0, 0.5, 0.5]) && r.contains([1.0, 0.5, 0.5]));
        assert!(!r.contains([0.5, 0.5, 0.5]));
        assert!(Region::parse("box:0,0,0,1,1,1:3:zone=9lives").is_err());
        let r = Region::parse("box:0,0,0,1,2,3:size=0.1:outside").unwrap();
        assert_eq!((r.size(), r.level(), r.outside()), (Some(0.1), 0, true));
        assert_eq!(r.describe(), "box:0,0,0,1,2,3:size=0.1:outside");
        // Root cells of 1: 0.1 is level 4 (0.0625).
        assert_eq!(r.sized(1.0).unwrap().level(), 4);
        assert!(Region::parse("box:0,0,0,1,2,3:size=x").is_err());
        let r = Region::parse("sphere:0,0,0,0.5:6:outside").unwrap();
        assert!(r.outside() && r.level() == 6 && r.shape() == "sphere");
        let r = Region::parse("cylinder:0,0,0,1,0,0,0.25:5").unwrap();
        assert_eq!(r.shape(), "cylinder");
        for bad in [
            "box:0,0,0,1,1:3",
            "cone:0,0,0,1:3",
            "box:1,0,0,0,1,1:3",
            "sphere:0,0,0,-1:3",
            "box:0,0,0,1,1,1:19",
            "box:0,0,0,1,1,1:3:inside",
            "box:0,0,0,1,1,1:3:zone=a b",
        ] {
            assert!(Region::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn shapes_against_boxes() {
        let lo = [0.0; 3];
        let hi = [1.0; 3];
        assert!(
            overlaps(Lattice::Box([1.0; 3], [2.0; 3]), lo, hi),
            "touching counts"
        );
        assert!(!overlaps(Lattice::Box([1.5; 3], [2.0; 3]), lo, hi));
        assert!(overlaps(Lattice::Sphere([2.0, 0.5, 0.5], 1.0), lo, hi));
        assert!(!overlaps(Lattice::Sphere([2.0, 2.0, 2.0], 1.7), lo, hi));
        assert!(inside_interior(Lattice::Sphere([0.5; 3], 0.9), lo, hi));
        assert!(!inside_interior(Lattice::Sphere([0.5; 3], 0.8), lo, hi));
        // An axis along x at distance 1.5 from the box, radius 1.4 and 1.6.
        let (a, b) = ([-3.0, 2.5, 0.5], [3.0, 2.5, 0.5]);
        assert!(!cylinder_meets_box(a, b, 1.4, lo, hi));
        assert!(cylinder_meets_box(a, b, 1.6, lo, hi));
        // Its caps end before the box.
        assert!(!cylinder_meets_box(
            [-3.0, 0.5, 0.5],
            [-0.5, 0.5, 0.5],
            10.0,
            lo,
            hi
        ));
        assert!(cylinder_meets_box(
            [-3.0, 0.5, 0.5],
            [0.0, 0.5, 0.5],
            0.1,
            lo,
            hi
        ));
    }

    #[test]
    fn sizes_round_to_the_level_not_larger() {
        assert_eq!(level_for_size(1.0, 0.25).unwrap(), 2);
        assert_eq!(level_for_size(1.0, 0.2).unwrap(), 3);
        assert_eq!(level_for_size(1.0, 2.0).unwrap(), 0);
        assert!(level_for_size(1.0, 1e-9).is_err());
    }
}
