//! The class of a leaf and the choices users make about classes: which
//! leaves a mesh keeps, what happens to cut leaves, how the inside is
//! decided.

use crate::geometry::diagnostics::SurfaceReport;

/// Bit set in a leaf's class byte when its centre is inside the surface.
pub const CENTER_INSIDE: u8 = 1;
/// Bit set when the leaf's closed box touches the surface.
pub const CUT: u8 = 2;
/// Bit set for a leaf outside a box domain (the void of [`crate::octree::brick`]):
/// never kept, never part of the leak search.
pub const VOID: u8 = 4;

/// The class of a leaf, from its class byte.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum LeafClass {
    /// Does not touch the surface, centre outside.
    Outside = 0,
    /// Does not touch the surface, centre inside.
    Inside = 1,
    /// Touches the surface (wherever its centre is).
    Cut = 2,
}

impl LeafClass {
    /// The class of a class byte ([`CUT`] wins over [`CENTER_INSIDE`]).
    pub fn from_bits(bits: u8) -> LeafClass {
        if bits & CUT != 0 {
            LeafClass::Cut
        } else if bits & CENTER_INSIDE != 0 {
            LeafClass::Inside
        } else {
            LeafClass::Outside
        }
    }

    /// The lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            LeafClass::Outside => "outside",
            LeafClass::Inside => "inside",
            LeafClass::Cut => "cut",
        }
    }
}

crate::named_enum! {
    /// Which elements a mesh keeps.
    pub enum Keep: "keep mode" {
        /// Every leaf.
        All = "all",
        /// Leaves inside the surface (cut leaves per the [`CutRule`]).
        Inside = "inside",
        /// Leaves outside the surface (cut leaves per the [`CutRule`]).
        Outside = "outside",
    }
}

crate::named_enum! {
    /// What to do with cut leaves (touching the surface) when keeping inside or
    /// outside.
    #[derive(Default)]
    pub enum CutRule: "cut rule" {
        /// Keep a cut leaf on the side of its centre (the default): inside and
        /// outside then partition the leaves.
        #[default]
        Center = "center",
        /// Keep every cut leaf (the kept part covers its side of the surface).
        All = "all",
        /// Drop every cut leaf (the kept part stays off the surface).
        None = "none",
    }
}

crate::named_enum! {
    /// How the centre of a leaf is found inside or outside the surface.
    #[derive(Default)]
    pub enum InsideRule: "inside rule" {
        /// Parity of surface crossings: exact for one closed surface (of any
        /// genus or orientation), the exclusive or of several overlapping ones,
        /// meaningless near holes.
        Parity = "parity",
        /// Generalized winding number above 1/2, after orienting every
        /// component: the union of overlapping parts, holes closed smoothly.
        Winding = "winding",
        /// Parity for one closed, consistently oriented component, winding
        /// number otherwise (the default).
        #[default]
        Auto = "auto",
    }
}

impl InsideRule {
    /// The rule [`InsideRule::Auto`] picks for a surface with this report,
    /// and why: parity for one closed (no boundary, non-manifold or
    /// inconsistently oriented edge, no degenerate facet), single component,
    /// winding otherwise, since parts may overlap and holes leak.
    pub fn auto_choice(report: &SurfaceReport) -> (InsideRule, String) {
        if report.closed && report.components == 1 {
            return (
                InsideRule::Parity,
                "one closed, consistently oriented component".to_string(),
            );
        }
        let mut why = Vec::new();
        if report.boundary_edges > 0 {
            why.push(format!("{} boundary edges", report.boundary_edges));
        }
        if report.non_manifold_edges > 0 {
            why.push(format!("{} non-manifold edges", report.non_manifold_edges));
        }
        if report.inconsistently_oriented_edges > 0 {
            why.push(format!(
                "{} inconsistently oriented edges",
                report.inconsistently_oriented_edges
            ));
        }
        if report.degenerate > 0 {
            why.push(format!("{} degenerate facets", report.degenerate));
        }
        if report.components != 1 {
            why.push(format!("{} components", report.components));
        }
        (InsideRule::Winding, why.join(", "))
    }

    /// The rule itself, or for [`InsideRule::Auto`] the choice of
    /// [`InsideRule::auto_choice`] (computed only then).
    pub fn resolve(self, report: impl FnOnce() -> SurfaceReport) -> InsideRule {
        match self {
            InsideRule::Auto => InsideRule::auto_choice(&report()).0,
            r => r,
        }
    }
}

/// What the winding-number rule did to the surface before classifying.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct WindingSummary {
    /// Components connected through manifold edges.
    pub components: usize,
    /// Facets reversed to orient the components consistently and outward.
    pub reversed_facets: usize,
    /// Manifold edges left inconsistent (non-orientable components).
    pub conflicting_edges: usize,
    /// Loops of the boundary (holes), each closed by a cap.
    pub boundary_loops: usize,
    /// Triangles of those caps.
    pub cap_triangles: usize,
}

/// Whether a leaf with class byte `bits` is kept. [`Keep::All`] keeps
/// everything; [`Keep::Inside`] keeps non-cut leaves whose centre is inside
/// and [`Keep::Outside`] those whose centre is outside; cut leaves follow
/// `rule` (with [`CutRule::Center`], the side of their centre).
pub fn keeps(keep: Keep, rule: CutRule, bits: u8) -> bool {
    if bits & VOID != 0 {
        return false;
    }
    let inside = bits & CENTER_INSIDE != 0;
    let want_inside = match keep {
        Keep::All => return true,
        Keep::Inside => true,
        Keep::Outside => false,
    };
    if bits & CUT == 0 {
        return inside == want_inside;
    }
    match rule {
        CutRule::Center => inside == want_inside,
        CutRule::All => true,
        CutRule::None => false,
    }
}
