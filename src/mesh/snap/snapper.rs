//! The state of one snap and its steps: the surface nodes' steps back
//! until every element is valid, the relaxation of the layers around them.

use crate::geometry::cells::{corner_coords, CORNER_EDGES, VTK_TO_MORTON};
use crate::mesh::dual::Bits;
use crate::octree::octant::Octant;
use crate::parallel::comm::Comm;

use super::features::Target;
use super::measure::Measure;
use super::nearest::NearTriangles;
use super::options::FIXED;
use super::{mean, SnapOptions, CHUNK, FRACTIONS, RELAX_TOLERANCE, SPLIT_AT, STEPS};

/// The hexahedra a snap moves the corners of.
#[derive(Clone, Copy)]
pub(super) struct Cells<'a> {
    /// Each element's nodes, VTK order.
    pub(super) conn: &'a [[u32; 8]],
    /// The nodes below this are the rank's own (the figures count them).
    pub(super) owned: usize,
    /// The hanging-node mesh's elements as octants, whose anchors and
    /// sides give their corners' lattice points without fetching them
    /// from all over memory; none for a mesh of other hexahedra (the
    /// corners' points are read).
    pub(super) octants: Option<&'a [Octant]>,
}

/// The state of one snap: positions in lattice units (or a fixed multiple
/// of them), per local node.
pub(super) struct Snapper<'a> {
    pub(super) cells: Cells<'a>,
    pub(super) comm: &'a dyn Comm,
    /// Whether a second thread may take pieces of the long passes
    /// ([`crate::parallel::cores::map_chunks`]).
    pub(super) spare: bool,
    /// The processor has AVX-512F ([`crate::parallel::cores::avx512`]).
    pub(super) wide: bool,
    pub(super) lists: Vec<(u32, Vec<u32>)>,
    pub(super) ni: usize,
    /// Lattice points of every local node.
    pub(super) lattice: Vec<[u32; 3]>,
    /// Hanging node `k`'s dependencies in the order of their lattice
    /// points (2 or 4).
    pub(super) deps: Vec<([u32; 4], u8)>,
    /// Current positions of every local node.
    pub(super) pos: Vec<[f64; 3]>,
    /// Independent surface nodes that move, with their targets and
    /// steps back (`STEPS`: unmoved).
    pub(super) snap: Vec<bool>,
    pub(super) target: Vec<[f64; 3]>,
    pub(super) step: Vec<u8>,
    /// Partly snapped nodes that still try to step up: a node whose step
    /// up was refused once stops (the next tries nearly all fail too).
    pub(super) climbing: Vec<bool>,
    /// Interior independent nodes that the relaxation moves.
    pub(super) layer: Vec<bool>,
    /// Elements touching a node that may move.
    pub(super) active: Vec<u32>,
    /// The active elements depending on each independent node: node `n`'s
    /// are `adj[adj_start[n]..adj_start[n + 1]]`.
    pub(super) adj_start: Vec<u32>,
    pub(super) adj: Vec<u32>,
    /// The finest element side at each independent node (lattice units).
    pub(super) side: Vec<u64>,
    /// The least scaled Jacobian allowed.
    pub(super) min_jacobian: f64,
    /// Scratch kept from one use to the next (fresh pages cost more than
    /// the work on them): per independent node, the check's flags (all
    /// zero between uses) and the relaxation's sums; one bit per element,
    /// whether it was seen (all clear between uses).
    pub(super) flags: Vec<u8>,
    pub(super) sums: Vec<u64>,
    pub(super) seen: Bits,
    /// Per element, the least figure of [`corner_verdict`] at its last
    /// measurement. Every move is followed by the measurement of the
    /// elements around, so for the active elements it is the current one.
    pub(super) least: Vec<f64>,
}

impl<'a> Snapper<'a> {
    /// A snap of `cells` whose nodes are at `lattice` (the first `ni`
    /// independent, the others the means of `deps`), nothing moved yet;
    /// `threads` is (`spare`, `wide`), `lists` the node exchange lists.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn new(
        cells: Cells<'a>,
        comm: &'a dyn Comm,
        (spare, wide): (bool, bool),
        lists: Vec<(u32, Vec<u32>)>,
        ni: usize,
        lattice: Vec<[u32; 3]>,
        deps: Vec<([u32; 4], u8)>,
        opts: &SnapOptions,
    ) -> Self {
        let elements = cells.conn.len();
        Snapper {
            cells,
            comm,
            spare,
            wide,
            lists,
            ni,
            pos: lattice.iter().map(|q| q.map(f64::from)).collect(),
            lattice,
            deps,
            snap: vec![false; ni],
            target: vec![[0.0; 3]; ni],
            step: vec![STEPS; ni],
            climbing: vec![true; ni],
            layer: vec![false; ni],
            active: Vec::new(),
            adj_start: Vec::new(),
            adj: Vec::new(),
            side: Vec::new(),
            min_jacobian: opts.min_jacobian,
            least: vec![f64::NAN; elements],
            flags: Vec::new(),
            sums: Vec::new(),
            seen: Bits::new(elements),
        }
    }

    /// The snap itself, once the nodes are known: the nodes `order` (the
    /// queried ones, in the order they are queried) go to their targets on
    /// `surface` where those are found, scaled back until every element is
    /// valid, then the layers are relaxed and the partly snapped nodes step
    /// up. `masks` are the nodes' patches, `side` the finest element side
    /// at each independent node; positions are `scale` times lattice units
    /// (the surface's). Returns per independent node whether it went to a
    /// feature and whether the relaxation moved it, and the relaxation's
    /// iterations. Collective.
    pub(super) fn run(
        &mut self,
        surface: Target,
        order: &[u32],
        masks: &[u64],
        side: Vec<u64>,
        opts: &SnapOptions,
        scale: f64,
    ) -> (Vec<bool>, Vec<bool>, u32) {
        let ni = self.ni;
        let queried = |n: usize| super::is_queried(masks[n], side[n]);
        let mut feature = vec![false; ni];
        // A node's target depends on nothing but its point: the pieces of
        // the order may go to two threads. The elements that may change
        // are found meanwhile, from the nodes queried (nearly all of them
        // find a target).
        let spare_here = self.spare && order.len() >= SPLIT_AT;
        let (wide, lattice) = (self.wide, &self.lattice);
        let query = |part: std::ops::Range<usize>| {
            let mut near_tris = NearTriangles {
                wide,
                ..NearTriangles::default()
            };
            order[part]
                .iter()
                .map(|&n| {
                    let n = n as usize;
                    let x = lattice[n].map(|c| f64::from(c) / scale);
                    surface
                        .of(x, side[n] as f64 / scale, &mut near_tris)
                        .map(|(t, f)| (t.map(|c| c * scale), f))
                })
                .collect::<Vec<_>>()
        };
        let this = &*self;
        let (targets, (layer, active, adj_start, adj)) =
            crate::parallel::cores::map_chunks_after(spare_here, order.len(), CHUNK, query, || {
                this.moving_elements(&queried, masks, opts)
            });
        for (&n, found) in order.iter().zip(targets.into_iter().flatten()) {
            let n = n as usize;
            if let Some((t, f)) = found {
                self.snap[n] = true;
                self.target[n] = t;
                self.step[n] = 0;
                feature[n] = f;
            }
        }
        drop(surface);
        self.layer = layer;
        self.active = active;
        self.adj_start = adj_start;
        self.adj = adj;
        self.side = side;

        self.scale_back();
        let mut relaxed = vec![false; ni];
        let mut iterations = 0;
        for _ in 0..opts.iterations {
            iterations += 1;
            let moved = self.relax();
            if moved == 0 {
                break;
            }
        }
        for (n, r) in relaxed.iter_mut().enumerate() {
            *r = self.layer[n] && self.pos[n] != self.lattice(n);
        }
        self.place_surface_nodes();
        self.update_hanging();
        (feature, relaxed, iterations)
    }

    /// The report's counts on this rank (`super::report` sums them):
    /// surface nodes, snapped, partly, not, to features, -, relaxed,
    /// reported elements, partly and not snapped by wall faces. `feature`
    /// and `relaxed` are [`Snapper::run`]'s. Collective (one exchange).
    pub(super) fn figures(&self, masks: &[u64], feature: &[bool], relaxed: &[bool]) -> [u64; 14] {
        let ni = self.ni;
        let on_surface = |n: usize| super::is_on_surface(masks[n]);
        // The most wall faces (faces whose four corners are on the surface
        // patch) of an element around each node, over the ranks: two or
        // three mark a convex corner of the staircase, which snapping
        // flattens.
        let mut walls = vec![0u8; ni];
        for c in self.cells.conn {
            let w = super::HEX_FACES
                .iter()
                .filter(|f| f.iter().all(|&v| on_surface(c[v] as usize)))
                .count()
                .min(3) as u8;
            for &n in c {
                if let Some(x) = walls.get_mut(n as usize) {
                    *x = (*x).max(w);
                }
            }
        }
        self.exchange(&mut walls, 1, |a, b| *a = (*a).max(b as u8));

        // Figures, each node once (by its owner).
        let mut counts = [0u64; 14];
        for n in 0..self.cells.owned {
            if on_surface(n) {
                counts[0] += 1;
                let w = walls[n].max(1) as usize - 1;
                match (self.snap[n], self.step[n]) {
                    (true, 0) => {
                        counts[1] += 1;
                        counts[4] += feature[n] as u64;
                    }
                    (true, k) if k < STEPS => {
                        counts[2] += 1;
                        counts[8 + w] += 1;
                    }
                    _ => {
                        counts[3] += 1;
                        counts[11 + w] += 1;
                    }
                }
            }
            counts[6] += relaxed[n] as u64;
        }
        for &e in &self.active {
            let mut reported = false;
            self.support(e as usize, |n| {
                reported |= on_surface(n) && self.step[n] > 0
            });
            counts[7] += reported as u64;
        }
        counts
    }

    /// The active elements that may hold the least scaled Jacobian: the
    /// lattice positions' figures (no roots), as last measured, pick them;
    /// the figures in user units differ from them by rounding only, far
    /// inside the margin.
    pub(super) fn near_least(&self) -> Vec<u32> {
        debug_assert!(self.active.iter().all(|&e| {
            let p = self.cells.conn[e as usize].map(|n| self.pos[n as usize]);
            super::measure::corner_verdict(&p, 0.0).1 == self.least[e as usize]
        }));
        let least = self
            .active
            .iter()
            .map(|&e| self.least[e as usize])
            .fold(f64::INFINITY, f64::min);
        let near = least + 1e-9 * least.abs() + 1e-12;
        self.active
            .iter()
            .copied()
            .filter(|&e| self.least[e as usize] <= near)
            .collect()
    }

    /// Calls `f` with each independent node element `e`'s corners depend
    /// on (hanging corners through their dependencies; repeats possible).
    pub(super) fn support(&self, e: usize, mut f: impl FnMut(usize)) {
        for &c in &self.cells.conn[e] {
            let c = c as usize;
            if c < self.ni {
                f(c);
            } else {
                let (d, n) = self.deps[c - self.ni];
                for &x in &d[..n as usize] {
                    f(x as usize);
                }
            }
        }
    }

    /// The independent nodes element `e`'s corners depend on, as
    /// [`Snapper::support`] gives them: the first `len` of the array.
    #[inline]
    pub(super) fn support_list(&self, e: usize) -> ([u32; 32], usize) {
        let mut nodes = [0u32; 32];
        let mut len = 0;
        self.support(e, |n| {
            nodes[len] = n as u32;
            len += 1;
        });
        (nodes, len)
    }

    /// In a pass over the elements `list`, now at `k`: fetches the corners'
    /// positions for the element a few places ahead. Nodes are numbered
    /// apart from elements, so an element's corners lie all over that
    /// array, and the passes wait on those loads otherwise.
    #[inline]
    pub(super) fn fetch_ahead(&self, list: &[u32], k: usize) {
        if let Some(&ahead) = list.get(k + 6) {
            for &n in &self.cells.conn[ahead as usize] {
                crate::mesh::prefetch(&self.pos, n as usize);
            }
        }
    }

    /// Node `n`'s lattice point.
    #[inline]
    pub(super) fn lattice(&self, n: usize) -> [f64; 3] {
        self.lattice[n].map(f64::from)
    }

    /// Flags the `eligible` nodes to blame for invalid element `e`: at
    /// each corner below the least scaled Jacobian the corner's node (through its
    /// dependencies when it hangs), else its three neighbours along the
    /// edges, else every eligible node of the element.
    /// Newly flagged nodes are appended to `flagged`.
    pub(super) fn blame(
        &self,
        e: usize,
        failed: u8,
        eligible: impl Fn(usize) -> bool,
        flags: &mut [u8],
        flagged: &mut Vec<u32>,
    ) {
        let c = &self.cells.conn[e];
        let mut any = false;
        let mut flag = |node: u32, any: &mut bool| {
            let node = node as usize;
            let mut visit = |n: usize| {
                if eligible(n) {
                    if flags[n] == 0 {
                        flags[n] = 1;
                        flagged.push(n as u32);
                    }
                    *any = true;
                }
            };
            if node < self.ni {
                visit(node);
            } else {
                let (d, k) = self.deps[node - self.ni];
                d[..k as usize].iter().for_each(|&x| visit(x as usize));
            }
        };
        for v in 0..8 {
            if failed >> v & 1 == 0 {
                continue;
            }
            // A hanging corner is where its face or edge puts it: moving
            // its dependencies back rarely helps, its neighbours do.
            let mut here = false;
            if (c[v] as usize) < self.ni {
                flag(c[v], &mut here);
            }
            if !here {
                for w in CORNER_EDGES[v] {
                    flag(c[w], &mut here);
                }
            }
            any |= here;
        }
        if !any {
            for &n in c {
                flag(n, &mut any);
            }
        }
    }

    /// Combines `words` values per independent node over the ranks sharing
    /// it: each rank's own values are sent, and `combine` folds in those
    /// received (it must be commutative and associative).
    pub(super) fn exchange<T: Copy + Into<u64>>(
        &self,
        vals: &mut [T],
        words: usize,
        combine: impl Fn(&mut T, u64),
    ) {
        if self.comm.size() == 1 {
            return;
        }
        let mut counts = vec![0usize; self.comm.size()];
        let mut send = Vec::new();
        for (r, nodes) in &self.lists {
            counts[*r as usize] = nodes.len() * words;
            for &n in nodes {
                let n = n as usize;
                send.extend(vals[n * words..(n + 1) * words].iter().map(|&v| v.into()));
            }
        }
        let (recv, got) = self.comm.alltoallv_u64(&send, &counts);
        let mut at = 0;
        for (r, &len) in got.iter().enumerate() {
            if let Ok(k) = self.lists.binary_search_by_key(&(r as u32), |l| l.0) {
                let nodes = &self.lists[k].1;
                for (j, &n) in nodes.iter().enumerate() {
                    let n = n as usize;
                    for w in 0..words {
                        combine(&mut vals[n * words + w], recv[at + j * words + w]);
                    }
                }
            }
            at += len;
        }
    }

    /// The position of surface node `n` after its steps back.
    pub(super) fn snapped_position(&self, n: usize) -> [f64; 3] {
        let (x, t, k) = (self.lattice(n), self.target[n], self.step[n]);
        match k {
            0 => t,
            STEPS => x,
            _ => {
                let s = FRACTIONS[k as usize];
                std::array::from_fn(|a| x[a] + (t[a] - x[a]) * s)
            }
        }
    }

    /// Hanging nodes from their dependencies.
    pub(super) fn update_hanging(&mut self) {
        for k in 0..self.deps.len() {
            self.pos[self.ni + k] = mean(&self.pos, self.deps[k]);
        }
    }

    pub(super) fn place_surface_nodes(&mut self) {
        for n in 0..self.ni {
            if self.snap[n] {
                self.pos[n] = self.snapped_position(n);
            }
        }
    }

    /// The elements a snap may change, from the surface nodes that may
    /// move (`surface`): the nodes the relaxation moves (interior nodes
    /// within `opts.layers` elements of those, off every patch), the
    /// active elements (those depending on either kind, in storage order)
    /// and the adjacency from the nodes to them (compressed rows: node
    /// `n`'s elements are `adj[start[n]..start[n + 1]]`, each once, in
    /// order). Collective.
    #[allow(clippy::type_complexity)]
    pub(super) fn moving_elements(
        &self,
        surface: &dyn Fn(usize) -> bool,
        masks: &[u64],
        opts: &SnapOptions,
    ) -> (Vec<bool>, Vec<u32>, Vec<u32>, Vec<u32>) {
        let (ni, elements) = (self.ni, self.cells.conn.len());
        // Byte flags: the passes look them up all over the nodes, and a
        // byte array stays in cache where a word array does not.
        let mut near: Vec<u8> = (0..ni).map(|n| surface(n) as u8).collect();
        for _ in 0..opts.layers {
            let mut next = near.clone();
            for e in 0..elements {
                let mut touch = false;
                self.support(e, |n| touch |= near[n] != 0);
                if touch {
                    self.support(e, |n| next[n] = 1);
                }
            }
            self.exchange(&mut next, 1, |a, b| *a |= b as u8);
            near = next;
        }
        let layer: Vec<bool> = (0..ni)
            .map(|n| near[n] != 0 && masks[n] == 0 && opts.iterations > 0)
            .collect();
        let moving: Vec<bool> = (0..ni).map(|n| surface(n) || layer[n]).collect();
        drop(near);
        // Each node once per element (a node several hanging corners
        // depend on comes up several times): `last` holds the element
        // that last counted it.
        let mut active = Vec::new();
        let mut start = vec![0u32; ni + 1];
        let mut last = vec![u32::MAX; ni];
        for e in 0..elements {
            let (nodes, len) = self.support_list(e);
            let nodes = &nodes[..len];
            if nodes.iter().any(|&n| moving[n as usize]) {
                active.push(e as u32);
                for &n in nodes {
                    let n = n as usize;
                    if last[n] != e as u32 {
                        last[n] = e as u32;
                        start[n + 1] += 1;
                    }
                }
            }
        }
        drop(last);
        for n in 0..ni {
            start[n + 1] += start[n];
        }
        let mut adj = vec![0u32; start[ni] as usize];
        let mut fill = start.clone();
        for &e in &active {
            self.support(e as usize, |n| {
                // The elements come in order: a repeat is the last one.
                let at = fill[n] as usize;
                if at == start[n] as usize || adj[at - 1] != e {
                    adj[at] = e;
                    fill[n] += 1;
                }
            });
        }
        debug_assert!((0..ni).all(|n| fill[n] == start[n + 1]));
        (layer, active, start, adj)
    }

    /// The elements of `cands` with a corner below the least scaled
    /// Jacobian, and those corners ([`corner_verdict`]); every element's
    /// figure is kept in `least`. Their hanging corners are placed from their dependencies
    /// first: every hanging node depending on a changed node is a corner of
    /// an element around it.
    pub(super) fn bad_among(&mut self, cands: &[u32]) -> Vec<(u32, u8)> {
        let conn = self.cells.conn;
        let j2 = self.min_jacobian * self.min_jacobian;
        let (ni, deps) = (self.ni, &self.deps);
        let (fixed, hanging) = self.pos.split_at_mut(ni);
        let fixed = &*fixed;
        // With a spare core two threads measure: they may place the same
        // hanging node (with the same bits), and each element's figure is
        // stored by the one that measures it.
        let hanging = crate::parallel::cores::shared_f64(hanging.as_flattened_mut());
        let least = crate::parallel::cores::shared_f64(&mut self.least);
        let m = Measure {
            conn,
            ni,
            deps,
            fixed,
            hanging,
            least,
            j2,
            wide: self.wide,
        };
        let measure = |part: std::ops::Range<usize>| m.part(&cands[part]);
        let spare = self.spare && cands.len() >= SPLIT_AT;
        crate::parallel::cores::map_chunks(spare, cands.len(), CHUNK, measure).concat()
    }

    /// The active elements depending on the nodes `nodes`, once each:
    /// only they can have changed.
    pub(super) fn around(&mut self, nodes: &[u32]) -> Vec<u32> {
        // One bit per element (a set that stays in the first cache
        // level), all zero from one call to the next; read out word by
        // word, the elements come in storage order without a sort, so
        // the measurements read the connectivity and the positions near
        // where they read last.
        let (mut lo, mut hi) = (usize::MAX, 0);
        for &n in nodes {
            let n = n as usize;
            let (a, b) = (self.adj_start[n] as usize, self.adj_start[n + 1] as usize);
            for &e in &self.adj[a..b] {
                self.seen.set(e as usize);
                lo = lo.min(e as usize);
                hi = hi.max(e as usize);
            }
        }
        let mut out = Vec::new();
        self.seen.drain_into(lo, hi, &mut out);
        out
    }

    /// Steps back the displacements of the surface nodes of invalid
    /// elements until every element is valid or those nodes are back.
    pub(super) fn scale_back(&mut self) {
        let cands = self.active.clone();
        // The hanging nodes follow in the first measurement: every one that
        // depends on a moving node is a corner of an active element.
        self.place_surface_nodes();
        self.settle(
            cands,
            |s, n| s.snap[n] && s.step[n] < STEPS,
            |s, n| {
                s.step[n] += 1;
                s.pos[n] = s.snapped_position(n);
            },
        );
    }

    /// Measures the elements `cands`; while some are invalid, the nodes
    /// they blame (among those `blamable` accepts) take one step back
    /// (`step_back`, on every rank holding them) and the elements around
    /// them are measured again. Collective.
    pub(super) fn settle(
        &mut self,
        mut cands: Vec<u32>,
        blamable: impl Fn(&Self, usize) -> bool,
        mut step_back: impl FnMut(&mut Self, usize),
    ) {
        // Kept from one call to the next and left all zero: fresh pages
        // cost more than the rounds after the first, which are small.
        let mut flags = std::mem::take(&mut self.flags);
        flags.resize(self.ni, 0);
        let mut flagged: Vec<u32> = Vec::new();
        loop {
            let bad = self.bad_among(&cands);
            flagged.clear();
            for (e, failed) in bad {
                self.blame(
                    e as usize,
                    failed,
                    |n| blamable(self, n),
                    &mut flags,
                    &mut flagged,
                );
            }
            // The owner of a flagged node has its flag after the exchange.
            self.exchange(&mut flags, 1, |a, b| *a |= b as u8);
            if self.comm.size() > 1 {
                // Flags other ranks set on shared nodes.
                for (_, nodes) in &self.lists {
                    flagged.extend(nodes.iter().filter(|&&n| flags[n as usize] != 0));
                }
                flagged.sort_unstable();
                flagged.dedup();
            }
            let owned = self.cells.owned as u32;
            let mut count = [flagged.iter().filter(|&&n| n < owned).count() as u64];
            self.comm.sum_u64(&mut count);
            if count[0] == 0 {
                for &n in &flagged {
                    flags[n as usize] = 0;
                }
                break;
            }
            for &n in &flagged {
                step_back(self, n as usize);
            }
            cands = self.around(&flagged);
            for &n in &flagged {
                flags[n as usize] = 0;
            }
        }
        debug_assert!(flags.iter().all(|&f| f == 0));
        self.flags = flags;
    }

    /// Undoes the moves of `moved` nodes (already made) in invalid
    /// elements (`undo` restores a node's position) until every element is
    /// valid or nothing is left to undo. Only elements around moved nodes
    /// are measured: the others were valid (or beyond help) before.
    pub(super) fn refuse_invalid(
        &mut self,
        moved: &mut [bool],
        mut undo: impl FnMut(&mut Self, usize),
    ) {
        let nodes: Vec<u32> = (0..self.ni as u32).filter(|&n| moved[n as usize]).collect();
        // When many nodes moved, nearly every active element is around one
        // (93 to 98 % on the dragon): measuring them all costs less than
        // finding which. The others change nothing: their positions did
        // not move, and they blame no node that moved.
        let cands = if nodes.len() * 8 > self.ni {
            self.active.clone()
        } else {
            self.around(&nodes)
        };
        let moved = std::cell::Cell::from_mut(moved).as_slice_of_cells();
        self.settle(
            cands,
            |_, n| moved[n].get(),
            |s, n| {
                moved[n].set(false);
                undo(s, n);
            },
        );
    }

    /// One relaxation step of the layer nodes, each moving only by more
    /// than [`RELAX_TOLERANCE`] of its cell, and one step up of every
    /// partly snapped node, the moves kept where the elements stay valid;
    /// returns how many moved (over all ranks, owned nodes).
    pub(super) fn relax(&mut self) -> u64 {
        // The hanging nodes are where their dependencies put them: the
        // measurements after every change placed those around it.
        let ni = self.ni;
        let conn = self.cells.conn;
        let mut sums = std::mem::take(&mut self.sums);
        sums.clear();
        sums.resize(4 * ni, 0);
        let octants = self.cells.octants;
        for (k, &e) in self.active.iter().enumerate() {
            self.fetch_ahead(&self.active, k);
            let c = &conn[e as usize];
            if !c
                .iter()
                .any(|&n| (n as usize) < ni && self.layer[n as usize])
            {
                continue;
            }
            // The corners' lattice points from the element's anchor and
            // side (the same numbers as the nodes' own, without fetching
            // eight of them from all over memory).
            let cube = octants.map(|o| (o[e as usize].coords(), o[e as usize].side()));
            let mut d = [0.0f64; 3];
            for (v, &n) in c.iter().enumerate() {
                let p = self.pos[n as usize];
                let x = match cube {
                    Some((anchor, side)) => corner_coords(anchor, side, VTK_TO_MORTON[v]),
                    None => self.lattice[n as usize],
                };
                debug_assert_eq!(x, self.lattice[n as usize]);
                for a in 0..3 {
                    d[a] += p[a] - f64::from(x[a]);
                }
            }
            let fixed = d.map(|v| ((v / 8.0) * FIXED).round() as i64 as u64);
            for &n in c {
                let n = n as usize;
                if n < ni && self.layer[n] {
                    for a in 0..3 {
                        sums[4 * n + a] = sums[4 * n + a].wrapping_add(fixed[a]);
                    }
                    sums[4 * n + 3] += 1;
                }
            }
        }
        self.exchange(&mut sums, 4, |a, b| *a = a.wrapping_add(b));
        let mut moved = vec![false; ni];
        let mut old = Vec::new();
        for n in 0..ni {
            let count = sums[4 * n + 3];
            if !self.layer[n] || count == 0 {
                continue;
            }
            let x = self.lattice(n);
            let p: [f64; 3] = std::array::from_fn(|a| {
                x[a] + (sums[4 * n + a] as i64 as f64 / FIXED) / count as f64
            });
            // Moves below the tolerance are not made: the elements around
            // need no new check, and the relaxation ends.
            let tol = RELAX_TOLERANCE * self.side[n] as f64;
            if (0..3).any(|a| (self.pos[n][a] - p[a]).abs() > tol) {
                old.push((n as u32, self.pos[n]));
                self.pos[n] = p;
                moved[n] = true;
            }
        }
        self.sums = sums;
        // The partly snapped nodes step up at the same time: one check of
        // the elements around serves both moves.
        for (n, m) in moved.iter_mut().enumerate() {
            if self.snap[n] && self.climbing[n] && self.step[n] > 0 {
                self.step[n] -= 1;
                self.pos[n] = self.snapped_position(n);
                *m = true;
            }
        }
        self.refuse_invalid(&mut moved, |s, n| {
            if s.snap[n] {
                s.climbing[n] = false;
                s.step[n] += 1;
                s.pos[n] = s.snapped_position(n);
            } else {
                let k = old.binary_search_by_key(&(n as u32), |o| o.0).unwrap_or(0);
                s.pos[n] = old[k].1;
            }
        });
        let mut count = [moved[..self.cells.owned].iter().filter(|&&m| m).count() as u64];
        self.comm.sum_u64(&mut count);
        count[0]
    }
}
