//! Refinement to a surface: the redundant top of the tree with candidate
//! lists, then each rank refining its chunk top-down.

use super::*;
use crate::error::Result;
use crate::geometry::intersect::triangle_box_overlap;
#[cfg(target_arch = "x86_64")]
use crate::geometry::intersect::{wide, wide4};
use crate::geometry::{Aabb, Triangle};
use crate::octree::octant::Octant;
use crate::octree::LinearOctree;
use crate::parallel::comm::{agree, CommRef};

/// The top of a surface refinement on this rank ([`construct_for_surface`])
/// with, for each of its leaves, the triangles that may touch it. Refining
/// from it ([`SurfaceTop::refine`]) reuses those lists instead of searching
/// the bounding-box tree once per leaf.
pub struct SurfaceTop<'a> {
    pub(crate) tree: LinearOctree,
    pub(crate) lists: CoarseLists,
    /// The surface the lists index.
    pub(crate) surface: &'a SurfaceIndex,
    pub(crate) level: u8,
}

impl SurfaceTop<'_> {
    /// The octree of the top.
    pub fn tree(&self) -> &LinearOctree {
        &self.tree
    }

    /// The octree of the top, without the lists.
    pub fn into_tree(self) -> LinearOctree {
        self.tree
    }

    /// [`LinearOctree::refine_surface`] with the top's surface, to the level
    /// the top was built for. Collective.
    pub fn refine(self, limit: u64) -> Result<LinearOctree> {
        let mut tree = self.tree;
        tree.refine_surface_with(self.surface, self.level, limit, Some(&self.lists))?;
        Ok(tree)
    }
}

/// [`coarse_top`] for the surface rule, with the candidate triangles passed
/// down as in refinement rather than one search of the bounding-box tree
/// per octant (at small levels the top is most of the tree). At
/// `COARSE_LEVEL` refinement decides what splits, so the weight there only
/// needs a guess: some triangle's box meets the octant's box.
///
/// Also returns, for each coarse leaf, a superset of the triangles touching
/// it ([`CoarseLists`]): empty when it is known not to touch or is at
/// `max_level`, the triangles whose boxes meet its box otherwise.
pub(crate) fn surface_top(
    surface: &SurfaceIndex,
    max_level: u8,
    deep_weight: u64,
) -> (Vec<(Octant, u64)>, CoarseLists) {
    struct Top<'a> {
        surface: &'a SurfaceIndex,
        stop: u8,
        max_level: u8,
        deep_weight: u64,
        /// Stack of triangle lists; each octant's list is a suffix.
        buf: Vec<u32>,
        masks: Vec<u8>,
        out: Vec<(Octant, u64)>,
        lists: CoarseLists,
    }
    impl Top<'_> {
        /// `buf[lo..hi]`: the triangles whose boxes meet the box of `o`.
        fn visit(&mut self, o: Octant, lo: usize, hi: usize) {
            let (min, max) = o.bounds_f64();
            // The lists stay empty where refinement has nothing to do.
            let (weight, list) = if o.level() >= self.max_level {
                (Some(1), lo..lo)
            } else if o.level() == self.stop {
                (Some(if lo < hi { self.deep_weight } else { 1 }), lo..hi)
            } else if self.buf[lo..hi]
                .iter()
                .any(|&t| triangle_box_overlap(&self.surface.tris[t as usize], min, max))
            {
                (None, lo..lo)
            } else {
                (Some(1), lo..lo)
            };
            if let Some(w) = weight {
                self.out.push((o, w));
                self.lists.push(&self.buf[list]);
                return;
            }
            let b = split_candidates(
                self.surface.boxes(),
                &mut self.buf,
                &mut self.masks,
                lo,
                hi,
                o,
            );
            for i in 0..8 {
                self.visit(o.child(i as u32), b[i], b[i + 1]);
            }
            self.buf.truncate(b[0]);
        }
    }
    let mut top = Top {
        surface,
        stop: max_level.min(COARSE_LEVEL),
        max_level,
        deep_weight,
        buf: Vec::new(),
        masks: Vec::new(),
        out: Vec::new(),
        lists: CoarseLists::default(),
    };
    surface.candidates(Octant::ROOT, &mut top.buf);
    let n = top.buf.len();
    top.visit(Octant::ROOT, 0, n);
    (top.out, top.lists)
}

/// Candidate triangles of a run of coarse leaves, as the top's walk found
/// them: leaf `i` has `tris[offsets[i]..offsets[i + 1]]`, a superset of the
/// triangles touching it.
pub(crate) struct CoarseLists {
    pub(crate) offsets: Vec<usize>,
    pub(crate) tris: Vec<u32>,
}

impl Default for CoarseLists {
    fn default() -> CoarseLists {
        CoarseLists {
            offsets: vec![0],
            tris: Vec::new(),
        }
    }
}

impl CoarseLists {
    /// Appends the list of the next leaf.
    pub(crate) fn push(&mut self, tris: &[u32]) {
        self.tris.extend_from_slice(tris);
        self.offsets.push(self.tris.len());
    }

    /// The lists of leaves `range` only.
    pub(crate) fn slice(&self, range: std::ops::Range<usize>) -> CoarseLists {
        let first = self.offsets[range.start];
        CoarseLists {
            offsets: self.offsets[range.start..=range.end]
                .iter()
                .map(|&e| e - first)
                .collect(),
            tris: self.tris[first..self.offsets[range.end]].to_vec(),
        }
    }

    /// Candidates of leaf `i`.
    pub(crate) fn get(&self, i: usize) -> &[u32] {
        &self.tris[self.offsets[i]..self.offsets[i + 1]]
    }
}

/// Children of an octant with centre `c` whose closed boxes meet the
/// bounding box `b` of a triangle known to meet the octant's closed box:
/// bit `i` for child `i`. Along each axis the lower children meet it when
/// it starts at or below the centre, the upper ones when it ends at or
/// above it.
#[inline]
pub(crate) fn child_mask(b: &Aabb, c: [f64; 3]) -> u8 {
    // Children whose bit `k` is set.
    const UPPER: [u8; 3] = [0b1010_1010, 0b1100_1100, 0b1111_0000];
    let mut m = 0xffu8;
    for k in 0..3 {
        let lower = ((b.min[k] <= c[k]) as u8).wrapping_neg() & !UPPER[k];
        let upper = ((b.max[k] >= c[k]) as u8).wrapping_neg() & UPPER[k];
        m &= lower | upper;
    }
    m
}

/// [`child_mask`] of each triangle of `list` against the children of `o`,
/// into `masks`.
pub(crate) fn child_masks(boxes: &[Aabb], list: &[u32], o: Octant, masks: &mut Vec<u8>) {
    let (min, _) = o.bounds_f64();
    let half = (o.side() / 2) as f64;
    let c = min.map(|x| x + half);
    masks.clear();
    masks.extend(list.iter().map(|&t| child_mask(&boxes[t as usize], c)));
}

/// Appends to `buf` the candidate lists of the eight children of `o`, whose
/// list is `buf[lo..hi]` (triangles whose boxes meet its closed box): child
/// `i` gets `buf[b[i]..b[i + 1]]`. `masks` is scratch space.
pub(crate) fn split_candidates(
    boxes: &[Aabb],
    buf: &mut Vec<u32>,
    masks: &mut Vec<u8>,
    lo: usize,
    hi: usize,
    o: Octant,
) -> [usize; 9] {
    child_masks(boxes, &buf[lo..hi], o, masks);
    scatter_by_child(buf, lo, hi, |j| masks[j - lo])
}

/// Appends to `buf`, one after the other, the lists of the eight children
/// of an octant whose list is `buf[lo..hi]`, entry `j` going to the
/// children in `mask(j)` (bit `i` for child `i`), in two passes and without
/// allocating: child `i` gets `buf[b[i]..b[i + 1]]`.
pub(crate) fn scatter_by_child(
    buf: &mut Vec<u32>,
    lo: usize,
    hi: usize,
    mask: impl Fn(usize) -> u8,
) -> [usize; 9] {
    // Counted without branches: how many children an entry goes to is
    // hard to predict.
    let mut sizes = [0usize; 8];
    for j in lo..hi {
        let x = mask(j);
        for (i, s) in sizes.iter_mut().enumerate() {
            *s += (x >> i & 1) as usize;
        }
    }
    let mut b = [buf.len(); 9];
    for i in 0..8 {
        b[i + 1] = b[i] + sizes[i];
    }
    let mut fill: [usize; 8] = std::array::from_fn(|i| b[i]);
    buf.resize(b[8], 0);
    for j in lo..hi {
        let t = buf[j];
        let mut x = mask(j);
        while x != 0 {
            let i = x.trailing_zeros() as usize;
            buf[fill[i]] = t;
            fill[i] += 1;
            x &= x - 1;
        }
    }
    b
}

/// Builds the octree whose leaves touching `surface` are exactly at `level`
/// and whose other leaves are as coarse as possible. Fails with an
/// [`ErrorKind::Limit`](crate::ErrorKind::Limit) error when it would have more than `limit` leaves:
/// before refining when the estimate is far above the limit
/// ([`check_estimate`]), else as soon as the count exceeds it. Collective.
pub fn build_from_surface(
    comm: CommRef,
    surface: &SurfaceIndex,
    level: u8,
    limit: u64,
) -> Result<LinearOctree> {
    check_estimate(&comm, surface, level, limit)?;
    construct_top_for_surface(comm, surface, level)?.refine(limit)
}

impl LinearOctree {
    /// Refines every leaf whose closed box touches the surface until the
    /// touching leaves are at `level`. Collective.
    pub fn refine_surface(&mut self, surface: &SurfaceIndex, level: u8, limit: u64) -> Result<()> {
        self.refine_surface_with(surface, level, limit, None)
    }

    /// [`LinearOctree::refine_surface`], with the candidates of each leaf
    /// given by `lists` when present (else searched for).
    pub(crate) fn refine_surface_with(
        &mut self,
        surface: &SurfaceIndex,
        level: u8,
        limit: u64,
        lists: Option<&CoarseLists>,
    ) -> Result<()> {
        agree(&**self.comm(), check_level(level))?;
        let mut w = SurfaceWalker {
            tris: &surface.tris,
            boxes: surface.boxes(),
            level,
            buf: Vec::new(),
            masks: Vec::new(),
            out: Vec::with_capacity(self.local_len()),
            limit: limit.min(usize::MAX as u64) as usize,
            wide: crate::parallel::cores::avx512(),
            four: crate::parallel::cores::avx2(),
        };
        let mut result = Ok(());
        let leaves = self.leaves();
        let mut skip = 0;
        for (i, &o) in leaves.iter().enumerate() {
            if i % 4096 == 0 {
                crate::run::progress::set_done(w.out.len() as u64);
            }
            if skip > 0 {
                skip -= 1;
                continue;
            }
            if o.level() >= level {
                w.out.push(o);
                continue;
            }
            if let Some(lists) = lists {
                w.buf.clear();
                w.buf.extend_from_slice(lists.get(i));
            } else if o.level() + 1 == level
                && o.child_id() == 0
                && leaves.get(i + 7) == Some(&o.parent().child(7))
            {
                // A whole family (sorted and disjoint leaves: the eight in a
                // row are siblings): one search for the parent's candidates
                // serves all eight.
                let p = o.parent();
                w.buf.clear();
                surface.candidates(p, &mut w.buf);
                let n = w.buf.len();
                w.last_level(p, 0, n);
                if let Err(e) = w.check_limit() {
                    result = Err(e);
                    break;
                }
                skip = 7;
                continue;
            } else {
                w.buf.clear();
                surface.candidates(o, &mut w.buf);
            }
            if let Err(e) = w.leaf(o) {
                result = Err(e);
                break;
            }
        }
        let comm = self.comm().clone();
        // The sum is collective: a rank that stopped at the limit takes part
        // too, or the ranks would call different collectives.
        let global = global_limit(&comm, w.out.len(), limit);
        agree(&*comm, result.and(global))?;
        self.set_leaves(w.out);
        self.refresh()
    }
}

pub(crate) struct SurfaceWalker<'a> {
    pub(crate) tris: &'a [Triangle],
    pub(crate) boxes: &'a [Aabb],
    pub(crate) level: u8,
    /// Stack of triangle lists; each level's list is a suffix.
    pub(crate) buf: Vec<u32>,
    /// Scratch: child masks of one list.
    pub(crate) masks: Vec<u8>,
    pub(crate) out: Vec<Octant>,
    pub(crate) limit: usize,
    /// The processor has AVX-512F ([`crate::parallel::cores::avx512`]): a triangle
    /// is tested against eight children at once, with the same verdicts.
    pub(crate) wide: bool,
    /// Else, the processor has AVX2 ([`crate::parallel::cores::avx2`]): four
    /// children at a time, with the same verdicts.
    pub(crate) four: bool,
}

impl SurfaceWalker<'_> {
    /// Refines `o`, which touches the surface and is at least two levels
    /// above the target; `buf[lo..hi]` holds every triangle it touches, and
    /// maybe others whose boxes meet its box.
    pub(crate) fn walk(&mut self, o: Octant, lo: usize, hi: usize) -> Result<()> {
        if o.level() + 2 == self.level {
            self.last_level(o, lo, hi);
            return self.check_limit();
        }
        // The children's candidates by boxes; the exact test only has to
        // find one that touches.
        let b = split_candidates(self.boxes, &mut self.buf, &mut self.masks, lo, hi, o);
        // The lists were appended after `buf[lo..hi]`, which still holds
        // the octant's own, with their masks.
        let touched = self.touched(o, lo, hi);
        for i in 0..8u32 {
            let c = o.child(i);
            let (start, end) = (b[i as usize], b[i as usize + 1]);
            if touched & 1 << i != 0 {
                self.walk(c, start, end)?;
            } else {
                self.out.push(c);
            }
        }
        self.buf.truncate(b[0]);
        self.check_limit()
    }

    /// Refines leaf `o` (above the target), whose candidates are all of
    /// `buf`.
    pub(crate) fn leaf(&mut self, o: Octant) -> Result<()> {
        let (lo, hi) = o.bounds_f64();
        if !self
            .buf
            .iter()
            .any(|&t| triangle_box_overlap(&self.tris[t as usize], lo, hi))
        {
            self.out.push(o);
        } else if o.level() + 1 == self.level {
            // Only whether it touches matters: the first hit decided.
            self.out.extend_from_slice(&o.children());
        } else {
            return self.walk(o, 0, self.buf.len());
        }
        self.check_limit()
    }

    /// Splits each child of `o` (one level above the target) that touches
    /// the surface, given the candidates `buf[lo..hi]` of `o`: the
    /// children's children are leaves whatever they touch, so the first
    /// triangle touching a child decides.
    pub(crate) fn last_level(&mut self, o: Octant, lo: usize, hi: usize) {
        child_masks(self.boxes, &self.buf[lo..hi], o, &mut self.masks);
        let touched = self.touched(o, lo, hi);
        for i in 0..8u32 {
            let c = o.child(i);
            if touched & 1 << i != 0 {
                self.out.extend_from_slice(&c.children());
            } else {
                self.out.push(c);
            }
        }
    }

    /// The children of `o` that a triangle of `buf[lo..hi]` touches
    /// ([`triangle_box_overlap`]), given each one's box mask in `masks`.
    /// With AVX-512 or AVX2 a triangle is tested against its children at once;
    /// either way, the first triangle touching a child decides it.
    fn touched(&self, o: Octant, lo: usize, hi: usize) -> u8 {
        let list = &self.buf[lo..hi];
        #[cfg(target_arch = "x86_64")]
        if self.wide || self.four {
            let (mut cmin, mut cmax) = ([[0.0; 8]; 3], [[0.0; 8]; 3]);
            for i in 0..8 {
                let (a, b) = o.child(i as u32).bounds_f64();
                for k in 0..3 {
                    (cmin[k][i], cmax[k][i]) = (a[k], b[k]);
                }
            }
            let mut touched = 0u8;
            for (&t, &m) in list.iter().zip(&self.masks) {
                let want = m & !touched;
                if want != 0 {
                    let tri = &self.tris[t as usize];
                    // SAFETY: `wide` is set only where AVX-512F is, `four`
                    // only where AVX2 is.
                    touched |= unsafe {
                        if self.wide {
                            wide::triangle_boxes_overlap(tri, &cmin, &cmax, want)
                        } else {
                            wide4::triangle_boxes_overlap(tri, &cmin, &cmax, want)
                        }
                    };
                }
            }
            return touched;
        }
        let mut touched = 0u8;
        for i in 0..8u32 {
            let (cmin, cmax) = o.child(i).bounds_f64();
            let hit = list.iter().zip(&self.masks).any(|(&t, &m)| {
                m & 1 << i != 0 && triangle_box_overlap(&self.tris[t as usize], cmin, cmax)
            });
            touched |= (hit as u8) << i;
        }
        touched
    }

    pub(crate) fn check_limit(&self) -> Result<()> {
        if self.out.len() > self.limit {
            return Err(limit_error(self.limit as u64, "refining"));
        }
        Ok(())
    }
}
