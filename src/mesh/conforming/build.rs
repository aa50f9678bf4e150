//! A conforming mesh of the kept leaves of a whole octree: the conditions,
//! the marks, the closure ([`close`]) and every kept macro cell's template,
//! with nodes numbered by first use in Morton order of the macro cells, so
//! the result depends on the leaves alone.
//!
//! The kept region and the zones do not change: each leaf has a tag (0:
//! dropped, else kept, in zone `tag - 1`); a macro cell keeps its eight
//! children's tags, and the closure splits one whose tags differ wherever
//! it has marks (without marks its template is its leaves, each with its
//! tag); the refinement the conditions add inherits the tag of the leaf
//! it refines. Dropped macro cells still mark corners, which only makes a
//! kept cell's pattern finer where it meets them.

use super::assemble::GlobalPoint;
use super::{conditions, macro_template, Marks, MACRO};
use crate::error::Result;
use crate::geometry::hash::FoldMap;
use crate::octree::octant::{Connectivity, Octant};
use crate::octree::LinearOctree;
use crate::parallel::comm::CommRef;

/// A conforming all-hexahedral mesh in the octree's lattice refined
/// [`MACRO`] times.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Conforming {
    /// Node positions, numbered by first use.
    pub points: Vec<GlobalPoint>,
    /// Hexahedra, VTK corner order, positive volume.
    pub hexes: Vec<[u32; 8]>,
    /// Each hexahedron's tag (that of its macro cell, never 0).
    pub tags: Vec<u32>,
    /// Kept macro cells (parents of the conditioned octree's families).
    pub macro_cells: usize,
    /// Kept macro cells the closure split ([`close`]).
    pub refined: usize,
    /// Rounds of the closure.
    pub rounds: usize,
}

/// Builds the conforming mesh of `leaves` (a complete, sorted octree of one
/// process) keeping those with a tag other than 0. `comm` must be a
/// communicator of one rank: the conditions run through
/// [`LinearOctree::balance`]. The macro tree is closed first ([`close`]),
/// so every kept macro cell has a template.
pub fn build(comm: CommRef, leaves: &[Octant], tags: &[u32]) -> Result<Conforming> {
    debug_assert_eq!(leaves.len(), tags.len());
    let templates: Vec<_> = (0..=255u8).map(|m| macro_template(Marks(m))).collect();
    let (macros, children) = conditions::families(leaves, tags);
    let closed = close(comm, macros, children, |m| {
        templates[m.0 as usize].is_some()
    })?;
    let mut out = Conforming {
        refined: closed.refined,
        rounds: closed.rounds,
        ..Conforming::default()
    };
    let mut index: FoldMap<GlobalPoint, u32> = FoldMap::default();
    for ((&o, &m), t) in closed.cells.iter().zip(&closed.marks).zip(&closed.tags) {
        if t.iter().all(|&t| t == 0) {
            continue;
        }
        out.macro_cells += 1;
        let template = templates[m.0 as usize]
            .as_ref()
            .expect("the closure leaves no kept cell without a template");
        let (a, s) = (o.coords(), u64::from(o.side()));
        let place = |p: [i32; 3]| -> GlobalPoint {
            std::array::from_fn(|d| u64::from(a[d]) * MACRO as u64 + p[d] as u64 * s)
        };
        for h in template.iter() {
            // A cell of mixed tags has no marks (the closure): its
            // template is its eight leaves, each in one octant.
            let tag = t[octant(h)];
            if tag == 0 {
                continue;
            }
            let hex = h.map(|p| {
                let g = place(p);
                let next = out.points.len() as u32;
                *index.entry(g).or_insert_with(|| {
                    out.points.push(g);
                    next
                })
            });
            out.hexes.push(hex);
            out.tags.push(tag);
        }
    }
    Ok(out)
}

/// The octant of the macro cell (Morton child number) holding a template
/// hexahedron's centre.
fn octant(h: &[[i32; 3]; 8]) -> usize {
    (0..3)
        .map(|d| usize::from(h.iter().map(|p| p[d]).sum::<i32>() > 4 * MACRO) << d)
        .sum()
}

/// A corner-balanced macro tree whose kept cells all have templates.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Closed {
    /// The macro cells, sorted.
    pub cells: Vec<Octant>,
    /// The tags of each cell's eight children (0: dropped).
    pub tags: Vec<[u32; 8]>,
    /// Their marks.
    pub marks: Vec<Marks>,
    /// Macro cells split because their marks had no template or their
    /// children's tags differ under marks.
    pub refined: usize,
    /// Rounds of splitting and balancing.
    pub rounds: usize,
}

/// The closure of the macro cells `macros` (sorted, complete, with their
/// children's tags): balanced across corners, then every cell with a kept
/// child that either has marks without a template (`covered`) or has
/// marks and children of different tags split into its eight children
/// (macro cells of their own, each with its tag), and the tree balanced
/// again, until none is left. It ends: a cell with a mark touches a finer
/// macro cell, so it is not of the finest level, and neither splitting
/// nor the balance makes a cell finer than the finest one present; a cell
/// of the finest level has no marks, and its template (its eight leaves)
/// takes any tags.
pub fn close(
    comm: CommRef,
    mut macros: Vec<Octant>,
    mut tags: Vec<[u32; 8]>,
    covered: impl Fn(Marks) -> bool,
) -> Result<Closed> {
    let mut refined = 0;
    let mut rounds = 0;
    loop {
        let mut tree = LinearOctree::from_local_leaves(comm.clone(), macros.clone())?;
        tree.balance(Connectivity::Corner)?;
        let balanced = tree.leaves();
        // Balance only refines: each balanced cell is a macro cell or lies
        // in one child of one, whose tag it takes.
        let mut keep = Vec::with_capacity(balanced.len());
        let mut j = 0;
        for &b in balanced {
            while !macros[j].contains(b) {
                j += 1;
            }
            keep.push(if b == macros[j] {
                tags[j]
            } else {
                let child = b.ancestor(macros[j].level() + 1).child_id() as usize;
                [tags[j][child]; 8]
            });
        }
        let marks = conditions::marks(balanced);
        let open = |i: usize| {
            let t = &keep[i];
            t.iter().any(|&t| t != 0)
                && marks[i].0 != 0
                && (!covered(marks[i]) || t.iter().any(|&x| x != t[0]))
        };
        if !(0..balanced.len()).any(open) {
            return Ok(Closed {
                cells: balanced.to_vec(),
                tags: keep,
                marks,
                refined,
                rounds,
            });
        }
        rounds += 1;
        let (mut next, mut next_tags) = (Vec::new(), Vec::new());
        for (i, &o) in balanced.iter().enumerate() {
            if open(i) {
                refined += 1;
                next.extend(o.children());
                next_tags.extend(keep[i].map(|t| [t; 8]));
            } else {
                next.push(o);
                next_tags.push(keep[i]);
            }
        }
        (macros, tags) = (next, next_tags);
    }
}
