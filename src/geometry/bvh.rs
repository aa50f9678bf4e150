//! Bounding-volume hierarchy over triangles for axis-aligned box queries.
//!
//! A binary tree stored flat in a `Vec`: each internal node is split at the
//! median of its triangles' centroids along the longest axis of the centroid
//! bounds, which keeps the tree balanced (depth at most 32 for `u32`
//! indices) whatever the triangle distribution. Leaves hold at most
//! [`LEAF_SIZE`] triangles. The two children of a node are stored next to
//! each other, so one index per node suffices.
//!
//! The tree keeps its own copy of the triangle bounding boxes (in leaf
//! order) so candidate queries do not need the triangles; exact queries take
//! the triangle slice the tree was built from.

use super::distance::{point_box2, point_triangle2};
use super::intersect::triangle_box_overlap;
use super::{Aabb, Triangle};

/// Maximum number of triangles in a leaf.
pub const LEAF_SIZE: usize = 4;

/// Traversal stack size; a balanced tree over `u32` indices needs at most
/// 33 entries.
const STACK: usize = 64;

#[derive(Clone, Copy, Debug)]
struct Node {
    bbox: Aabb,
    /// Leaf: first slot in `order`. Internal: index of the left child (the
    /// right child follows it).
    first: u32,
    /// Number of triangles in a leaf, 0 for an internal node.
    count: u32,
}

/// A bounding-box tree over a triangle slice.
#[derive(Clone, Debug)]
pub struct Bvh {
    nodes: Vec<Node>,
    /// Triangle indices in leaf order.
    order: Vec<u32>,
    /// Bounding box of `order[i]`, at slot `i`.
    boxes: Vec<Aabb>,
}

impl Bvh {
    /// Builds the tree over `tris`; indices returned by queries refer to
    /// this slice.
    ///
    /// # Panics
    /// If there are more than `u32::MAX` triangles.
    pub fn new(tris: &[Triangle]) -> Bvh {
        let n = tris.len();
        assert!(n <= u32::MAX as usize, "too many triangles for a Bvh");
        if n == 0 {
            return Bvh {
                nodes: Vec::new(),
                order: Vec::new(),
                boxes: Vec::new(),
            };
        }
        let boxes: Vec<Aabb> = tris.iter().map(Triangle::aabb).collect();
        // Each triangle's centroid travels with its number: the splits
        // compare and move contiguous items instead of looking centroids
        // up through the numbers (a third less time on the dragon; the
        // comparisons, hence the tree, are the same).
        let mut items: Vec<([f64; 3], u32)> = tris
            .iter()
            .enumerate()
            .map(|(i, t)| (t.centroid(), i as u32))
            .collect();

        let placeholder = Node {
            bbox: Aabb::empty(),
            first: 0,
            count: 0,
        };
        let mut nodes = Vec::with_capacity(2 * n.div_ceil(LEAF_SIZE));
        nodes.push(placeholder);
        let mut work = vec![(0usize, 0usize, n)];
        while let Some((ni, start, end)) = work.pop() {
            let range = &mut items[start..end];
            if range.len() <= LEAF_SIZE {
                let bbox = range
                    .iter()
                    .fold(Aabb::empty(), |b, it| b.union(&boxes[it.1 as usize]));
                nodes[ni] = Node {
                    bbox,
                    first: start as u32,
                    count: range.len() as u32,
                };
                continue;
            }
            let cb = Aabb::from_points(range.iter().map(|it| it.0));
            let e = cb.extent();
            let axis = if e[0] >= e[1] && e[0] >= e[2] {
                0
            } else if e[1] >= e[2] {
                1
            } else {
                2
            };
            let half = range.len() / 2;
            range.select_nth_unstable_by(half, |a, b| a.0[axis].total_cmp(&b.0[axis]));
            let left = nodes.len();
            nodes.push(placeholder);
            nodes.push(placeholder);
            nodes[ni] = Node {
                bbox: Aabb::empty(),
                first: left as u32,
                count: 0,
            };
            work.push((left, start, start + half));
            work.push((left + 1, start + half, end));
        }
        let order: Vec<u32> = items.iter().map(|it| it.1).collect();
        // Internal boxes bottom-up (children come after their parent): one
        // union per node instead of one per triangle on every level.
        for i in (0..nodes.len()).rev() {
            let Node { first, count, .. } = nodes[i];
            if count == 0 {
                let (l, r) = (first as usize, first as usize + 1);
                nodes[i].bbox = nodes[l].bbox.union(&nodes[r].bbox);
            }
        }
        let boxes = order.iter().map(|&i| boxes[i as usize]).collect();
        Bvh {
            nodes,
            order,
            boxes,
        }
    }

    /// Number of nodes (0 for an empty tree; node 0 is the root).
    pub(crate) fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Shape of node `i`, for trees that carry more per node: `(first, 0)`
    /// for an internal node whose children are `first` and `first + 1`
    /// (always after `i`), `(first, count)` for a leaf holding the
    /// triangles `order()[first..first + count]`.
    pub(crate) fn node_shape(&self, i: usize) -> (u32, u32) {
        (self.nodes[i].first, self.nodes[i].count)
    }

    /// Bounding box of the triangle in each slot of [`Bvh::order`]; after
    /// [`Bvh::renumber`], of triangle `i` at `i`.
    pub(crate) fn slot_boxes(&self) -> &[Aabb] {
        &self.boxes
    }

    /// Triangle indices in leaf order.
    pub(crate) fn order(&self) -> &[u32] {
        &self.order
    }

    /// Renumbers the triangles in leaf order: returns the old order (new
    /// index `i` is old index `order[i]`) and makes the tree refer to the
    /// triangles by their new indices. The caller must permute its
    /// triangles the same way.
    pub(crate) fn renumber(&mut self) -> Vec<u32> {
        let identity = (0..self.order.len() as u32).collect();
        std::mem::replace(&mut self.order, identity)
    }

    /// Bounding box of all triangles (empty for an empty tree).
    pub fn bbox(&self) -> Aabb {
        self.nodes.first().map_or(Aabb::empty(), |n| n.bbox)
    }

    /// Appends to `out` the indices of the triangles that overlap the closed
    /// box `[box_min, box_max]` by [`triangle_box_overlap`] (touching counts).
    /// `tris` must be the slice the tree was built from. Indices come in tree
    /// order, not sorted.
    pub fn query_box(
        &self,
        tris: &[Triangle],
        box_min: [f64; 3],
        box_max: [f64; 3],
        out: &mut Vec<u32>,
    ) {
        debug_assert_eq!(tris.len(), self.order.len());
        self.visit(box_min, box_max, |ti, _| {
            if triangle_box_overlap(&tris[ti as usize], box_min, box_max) {
                out.push(ti);
            }
            false
        });
    }

    /// True if some triangle overlaps the closed box; stops at the first
    /// hit. `tris` must be the slice the tree was built from.
    pub fn any_overlap(&self, tris: &[Triangle], box_min: [f64; 3], box_max: [f64; 3]) -> bool {
        debug_assert_eq!(tris.len(), self.order.len());
        self.visit(box_min, box_max, |ti, _| {
            triangle_box_overlap(&tris[ti as usize], box_min, box_max)
        })
    }

    /// Appends to `out` the indices of the triangles whose bounding box
    /// overlaps the closed box (a superset of [`Bvh::query_box`]).
    pub fn query_candidates(&self, box_min: [f64; 3], box_max: [f64; 3], out: &mut Vec<u32>) {
        self.visit(box_min, box_max, |ti, _| {
            out.push(ti);
            false
        });
    }

    /// [`Bvh::query_candidates`] with each triangle's bounding box, as
    /// the tree holds it.
    pub fn query_candidate_boxes(
        &self,
        box_min: [f64; 3],
        box_max: [f64; 3],
        out: &mut Vec<(u32, Aabb)>,
    ) {
        self.visit(box_min, box_max, |ti, b| {
            out.push((ti, *b));
            false
        });
    }

    /// The triangle nearest `p` by exact point-triangle distance, with its
    /// squared distance, among those closer than `sqrt(limit2)` (`None`
    /// when there is none, or no triangle). Equally near triangles go to
    /// the lowest index, so the answer depends on `p` and the triangles
    /// only. `tris` must be the slice the tree was built from.
    pub fn nearest(&self, tris: &[Triangle], p: [f64; 3], limit2: f64) -> Option<(u32, f64)> {
        self.nearest_from(tris, p, limit2, None)
    }

    /// [`Bvh::nearest`] with a guess: triangle `hint` (if any) is measured
    /// first, and its distance bounds the search from the start. A guess
    /// near the answer (the previous query's, for a nearby point) prunes
    /// most of the tree; the answer is the same with any guess or none.
    pub fn nearest_from(
        &self,
        tris: &[Triangle],
        p: [f64; 3],
        limit2: f64,
        hint: Option<u32>,
    ) -> Option<(u32, f64)> {
        debug_assert_eq!(tris.len(), self.order.len());
        if self.nodes.is_empty() {
            return None;
        }
        let mut best: Option<(u32, f64)> = None;
        let mut bound = limit2;
        if let Some(t) = hint.filter(|&t| (t as usize) < tris.len()) {
            let [a, b, c] = tris[t as usize].v;
            let d = point_triangle2(p, a, b, c);
            if d <= bound {
                best = Some((t, d));
                bound = d;
            }
        }
        let node_d2 = |i: u32| {
            let b = &self.nodes[i as usize].bbox;
            point_box2(p, b.min, b.max)
        };
        // (node, its box's squared distance); the nearer child is visited
        // first so the bound shrinks early.
        let mut stack = [(0u32, 0.0f64); STACK];
        let mut sp = 0;
        let root = node_d2(0);
        if root <= bound {
            stack[0] = (0, root);
            sp = 1;
        }
        while sp > 0 {
            sp -= 1;
            let (ni, d2) = stack[sp];
            if d2 > bound {
                continue;
            }
            let node = &self.nodes[ni as usize];
            if node.count == 0 {
                debug_assert!(sp + 2 <= STACK);
                let (l, r) = (node.first, node.first + 1);
                let (dl, dr) = (node_d2(l), node_d2(r));
                let (near, far) = if dl <= dr {
                    ((l, dl), (r, dr))
                } else {
                    ((r, dr), (l, dl))
                };
                if far.1 <= bound {
                    stack[sp] = far;
                    sp += 1;
                }
                if near.1 <= bound {
                    stack[sp] = near;
                    sp += 1;
                }
                continue;
            }
            let first = node.first as usize;
            for slot in first..first + node.count as usize {
                let b = &self.boxes[slot];
                if point_box2(p, b.min, b.max) > bound {
                    continue;
                }
                let ti = self.order[slot];
                let [a, bb, c] = tris[ti as usize].v;
                let d = point_triangle2(p, a, bb, c);
                let better = match best {
                    None => d <= bound,
                    Some((bi, bd)) => d < bd || (d == bd && ti < bi),
                };
                if better {
                    best = Some((ti, d));
                    bound = d;
                }
            }
        }
        best
    }

    /// The least `t` in `[0, tmax]` where the segment `o + t d` meets a
    /// triangle (Möller and Trumbore's test over the triangles whose boxes
    /// meet the segment's box), if any. The answer is a minimum over the
    /// triangles, so it does not depend on the order they are visited in.
    pub fn first_hit(&self, tris: &[Triangle], o: [f64; 3], d: [f64; 3], tmax: f64) -> Option<f64> {
        let end: [f64; 3] = std::array::from_fn(|k| o[k] + tmax * d[k]);
        let lo: [f64; 3] = std::array::from_fn(|k| o[k].min(end[k]));
        let hi: [f64; 3] = std::array::from_fn(|k| o[k].max(end[k]));
        let mut best: Option<f64> = None;
        self.visit(lo, hi, |ti, _| {
            if let Some(t) = ray_triangle(o, d, &tris[ti as usize]) {
                if t <= tmax && best.is_none_or(|b| t < b) {
                    best = Some(t);
                }
            }
            false
        });
        best
    }

    /// Calls `hit` for each triangle whose box overlaps the query box, until
    /// `hit` returns true; returns whether it did.
    #[inline]
    fn visit(
        &self,
        box_min: [f64; 3],
        box_max: [f64; 3],
        mut hit: impl FnMut(u32, &Aabb) -> bool,
    ) -> bool {
        if self.nodes.is_empty() {
            return false;
        }
        let query = Aabb {
            min: box_min,
            max: box_max,
        };
        if !self.nodes[0].bbox.overlaps(&query) {
            return false;
        }
        // Only nodes whose box overlaps the query go on the stack: children
        // are tested before they are pushed.
        let mut stack = [0u32; STACK];
        let mut sp = 1;
        while sp > 0 {
            sp -= 1;
            let node = &self.nodes[stack[sp] as usize];
            if node.count == 0 {
                debug_assert!(sp + 2 <= STACK);
                let l = node.first;
                let right = self.nodes[l as usize + 1].bbox.overlaps(&query);
                let left = self.nodes[l as usize].bbox.overlaps(&query);
                stack[sp] = l + 1;
                sp += right as usize;
                stack[sp] = l;
                sp += left as usize;
                continue;
            }
            let first = node.first as usize;
            for slot in first..first + node.count as usize {
                let b = &self.boxes[slot];
                if b.overlaps(&query) && hit(self.order[slot], b) {
                    return true;
                }
            }
        }
        false
    }
}

/// Where the ray `o + t d`, `t >= 0`, meets the closed triangle `tri`
/// (Möller and Trumbore), if it does and is not parallel to it.
pub fn ray_triangle(o: [f64; 3], d: [f64; 3], tri: &Triangle) -> Option<f64> {
    use super::vector::{cross, dot, sub};
    let [a, b, c] = tri.v;
    let (e1, e2) = (sub(b, a), sub(c, a));
    let pv = cross(d, e2);
    let det = dot(e1, pv);
    if det.abs() < 1e-300 {
        return None;
    }
    let inv = 1.0 / det;
    let tv = sub(o, a);
    let u = dot(tv, pv) * inv;
    let qv = cross(tv, e1);
    let v = dot(d, qv) * inv;
    let t = dot(e2, qv) * inv;
    (u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t >= 0.0).then_some(t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::shapes::{default_sphere, default_torus, sphere};
    use crate::geometry::Surface;

    struct Rng(u64);
    impl Rng {
        fn next_f64(&mut self) -> f64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }
        fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
            lo + (hi - lo) * self.next_f64()
        }
    }

    fn check_structure(bvh: &Bvh, n: usize) {
        let mut seen = vec![false; n];
        for &i in &bvh.order {
            assert!(!seen[i as usize]);
            seen[i as usize] = true;
        }
        assert!(seen.iter().all(|&s| s));
        for node in &bvh.nodes {
            if node.count == 0 {
                for c in [node.first, node.first + 1] {
                    let child = bvh.nodes[c as usize].bbox;
                    assert_eq!(node.bbox.union(&child), node.bbox);
                }
            } else {
                assert!(node.count as usize <= LEAF_SIZE);
                let f = node.first as usize;
                for b in &bvh.boxes[f..f + node.count as usize] {
                    assert_eq!(node.bbox.union(b), node.bbox);
                }
            }
        }
    }

    fn compare_with_brute_force(s: &Surface, seed: u64, queries: usize) {
        let tris = s.triangles();
        let bvh = Bvh::new(tris);
        check_structure(&bvh, tris.len());
        assert_eq!(bvh.bbox(), s.bbox());
        let sb = s.bbox();
        let mut rng = Rng(seed);
        let (mut out, mut cand) = (Vec::new(), Vec::new());
        let mut nonempty = 0;
        for q in 0..queries {
            let size = [0.0, 0.01, 0.05, 0.2, 1.0][q % 5] * sb.longest_side();
            let mut lo = [0.0; 3];
            let mut hi = [0.0; 3];
            if q % 3 == 0 {
                // Boxes with a corner on a vertex exercise exact touching.
                let t = &tris[(rng.next_f64() * tris.len() as f64) as usize];
                lo = t.v[q % 3];
                for k in 0..3 {
                    hi[k] = lo[k] + size * rng.next_f64();
                }
            } else {
                for k in 0..3 {
                    lo[k] = rng.uniform(sb.min[k] - 0.1, sb.max[k] + 0.1);
                    hi[k] = lo[k] + size * rng.next_f64();
                }
            }
            out.clear();
            cand.clear();
            bvh.query_box(tris, lo, hi, &mut out);
            bvh.query_candidates(lo, hi, &mut cand);
            out.sort_unstable();
            cand.sort_unstable();
            let query = Aabb { min: lo, max: hi };
            let brute_cand: Vec<u32> = (0..tris.len() as u32)
                .filter(|&i| tris[i as usize].aabb().overlaps(&query))
                .collect();
            let brute: Vec<u32> = brute_cand
                .iter()
                .copied()
                .filter(|&i| triangle_box_overlap(&tris[i as usize], lo, hi))
                .collect();
            assert_eq!(out, brute, "query {q}");
            assert_eq!(cand, brute_cand, "query {q}");
            assert_eq!(bvh.any_overlap(tris, lo, hi), !brute.is_empty());
            if !brute.is_empty() {
                nonempty += 1;
            }
        }
        assert!(nonempty > queries / 10, "{nonempty}");
    }

    #[test]
    fn sphere_matches_brute_force() {
        compare_with_brute_force(&default_sphere(), 0x1234_5678_9abc_def1, 600);
    }

    #[test]
    fn torus_matches_brute_force() {
        compare_with_brute_force(&default_torus(), 0x0fed_cba9_8765_4321, 600);
    }

    #[test]
    fn nearest_matches_brute_force() {
        for s in [default_sphere(), default_torus()] {
            let tris = s.triangles();
            let bvh = Bvh::new(tris);
            let sb = s.bbox();
            let mut rng = Rng(0x5eed_1234_abcd_0001);
            for _ in 0..300 {
                let p: [f64; 3] =
                    std::array::from_fn(|k| rng.uniform(sb.min[k] - 0.2, sb.max[k] + 0.2));
                let brute = (0..tris.len() as u32)
                    .map(|i| {
                        let [a, b, c] = tris[i as usize].v;
                        (point_triangle2(p, a, b, c), i)
                    })
                    .min_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)))
                    .unwrap();
                let got = bvh.nearest(tris, p, f64::INFINITY).unwrap();
                assert_eq!((got.1, got.0), brute);
                // Any guess, near or far, gives the same answer; one past
                // the limit is ignored.
                let n = tris.len() as u32;
                for hint in [got.0, (got.0 + 1) % n, rng.next_f64().to_bits() as u32 % n] {
                    let from = bvh.nearest_from(tris, p, f64::INFINITY, Some(hint));
                    assert_eq!(from, Some(got));
                    let limited = bvh.nearest_from(tris, p, 0.5 * brute.0, Some(hint));
                    assert!(limited.is_none() || brute.0 == 0.0);
                }
                // A limit below the distance finds nothing.
                assert!(bvh.nearest(tris, p, 0.5 * brute.0).is_none() || brute.0 == 0.0);
            }
        }
        assert!(Bvh::new(&[])
            .nearest(&[], [0.0; 3], f64::INFINITY)
            .is_none());
    }

    #[test]
    fn small_and_empty_trees() {
        let empty = Bvh::new(&[]);
        let mut out = Vec::new();
        empty.query_candidates([-1e9; 3], [1e9; 3], &mut out);
        assert!(out.is_empty());
        assert!(!empty.any_overlap(&[], [-1e9; 3], [1e9; 3]));
        assert!(empty.bbox().is_empty());

        let s = sphere([0.0; 3], 1.0, 0);
        let few = &s.triangles()[..3];
        let bvh = Bvh::new(few);
        check_structure(&bvh, 3);
        bvh.query_box(few, [-2.0; 3], [2.0; 3], &mut out);
        out.sort_unstable();
        assert_eq!(out, vec![0, 1, 2]);
    }

    #[test]
    fn identical_centroids_still_split() {
        let t = Triangle::new([0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        let tris = vec![t; 37];
        let bvh = Bvh::new(&tris);
        check_structure(&bvh, 37);
        let mut out = Vec::new();
        bvh.query_box(&tris, [1.0, 0.0, 0.0], [2.0, 1.0, 1.0], &mut out);
        assert_eq!(out.len(), 37);
    }
}
