//! Leaf classes carried across a local change of the leaves (refinement,
//! coarsening, adaptation, balance), so that a new mesh after an
//! adaptation step classifies only what the step changed near the surface.
//!
//! A leaf that is not cut has a closed box no triangle touches, so every
//! point of it is on one side of the surface (the parity, or a closed
//! surface's winding number, is constant there):
//!
//! - an unchanged leaf keeps its class;
//! - a leaf inside an old leaf that was not cut takes its class (its box
//!   is inside the old box);
//! - a leaf made of old leaves none of which was cut, all on one side,
//!   takes their class (its box is their union, connected, and touches no
//!   triangle);
//! - every other new leaf (inside a cut leaf, or over a cut one) is
//!   classified again.
//!
//! With the winding number of an open surface (closed by caps) the inside
//! bit varies continuously away from the surface, so only unchanged leaves
//! keep their class then (`inherit` false).

use super::rules::CUT;
use crate::octree::octant::Octant;

/// The class bytes of `new` from those of `old` (both sorted and covering
/// the same cells, as a local refinement, coarsening or balance leaves
/// them), and the indices of the new leaves that must be classified again
/// (their bytes are 0). `inherit`: whether non-cut classes pass to
/// descendants and ancestors (see the module documentation).
pub fn carry_classes(
    old: &[Octant],
    old_bits: &[u8],
    new: &[Octant],
    inherit: bool,
) -> (Vec<u8>, Vec<usize>) {
    debug_assert_eq!(old.len(), old_bits.len());
    let mut bits = vec![0u8; new.len()];
    let mut pending = Vec::new();
    let (mut i, mut j) = (0, 0);
    while j < new.len() {
        let n = new[j];
        // Old leaves before `n` cannot occur when both cover the same
        // cells; skip them defensively.
        while i < old.len() && old[i].cell_end() <= n.cell_begin() {
            i += 1;
        }
        let Some(&o) = old.get(i) else {
            pending.push(j);
            j += 1;
            continue;
        };
        if o == n {
            bits[j] = old_bits[i];
            i += 1;
            j += 1;
        } else if o.is_ancestor_of(n) {
            // Refined: every new leaf inside `o`.
            let keep = inherit && old_bits[i] & CUT == 0;
            while j < new.len() && o.is_ancestor_of(new[j]) {
                if keep {
                    bits[j] = old_bits[i];
                } else {
                    pending.push(j);
                }
                j += 1;
            }
            i += 1;
        } else {
            // Coarsened: the old leaves inside `n`.
            let first = old_bits[i];
            let mut same = inherit && first & CUT == 0;
            while i < old.len() && n.is_ancestor_of(old[i]) {
                same &= old_bits[i] == first;
                i += 1;
            }
            if same {
                bits[j] = first;
            } else {
                pending.push(j);
            }
            j += 1;
        }
    }
    (bits, pending)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unchanged_refined_and_coarsened_leaves() {
        let root = Octant::ROOT;
        let c = root.children();
        // Old: child 0 split (its children cut except 7), children 1..8.
        let mut old: Vec<Octant> = c[0].children().to_vec();
        old.extend_from_slice(&c[1..]);
        let mut old_bits = vec![CUT; 7];
        old_bits.push(1);
        old_bits.extend_from_slice(&[1, CUT, 0, 0, 0, 0, 1]);
        // New: child 0 coarsened, child 1 split, child 2 split, rest same.
        let mut new = vec![c[0]];
        new.extend_from_slice(&c[1].children());
        new.extend_from_slice(&c[2].children());
        new.extend_from_slice(&c[3..]);
        let (bits, pending) = carry_classes(&old, &old_bits, &new, true);
        // c[0] over cut leaves, c[2]'s children inside a cut leaf.
        let want_pending: Vec<usize> = std::iter::once(0).chain(9..17).collect();
        assert_eq!(pending, want_pending);
        assert!(bits[1..9].iter().all(|&b| b == 1));
        assert_eq!(&bits[17..], &[0, 0, 0, 0, 1]);
        // Without inheritance only the unchanged leaves keep their class.
        let (_, pending) = carry_classes(&old, &old_bits, &new, false);
        assert_eq!(pending, (0..17).collect::<Vec<_>>());
    }
}
