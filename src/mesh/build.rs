//! The steps of [`Mesh::build`]: the inputs checked, the kept elements
//! selected, the ghost layer and the nodes extracted by the dual walk, the
//! hanging nodes counted, the independent nodes numbered, and the mesh
//! assembled.

use crate::classify::{keeps, Keep, LeafClass, VOID};
use crate::error::{Error, ErrorKind, Result};
use crate::octree::domain::Domain;
use crate::octree::ghost::build_ghost_layer;
use crate::octree::octant::Connectivity;
use crate::octree::LinearOctree;
use crate::parallel::comm::Comm;
use crate::run::report::PhaseTimer;

use std::sync::OnceLock;

use super::dual::{self, Merged, Ranks, CORNER, TAG, UNSET};
use super::hanging::{self, Hanging, GHOST};
use super::{
    manifold, numbering, prefetch, Elements, Halo, Mesh, MeshCounts, MeshOptions, VTK_TO_MORTON,
};

impl Mesh {
    /// Builds the mesh of `tree`, which must be balanced for edge or corner
    /// contacts. `classes` holds each local leaf's class byte (from
    /// [`crate::classify::classify_leaves`]); without it every leaf counts
    /// as outside and only [`Keep::All`] is allowed. Collective; any rank's
    /// error is returned on every rank.
    pub fn build(
        tree: &LinearOctree,
        domain: &Domain,
        classes: Option<&[u8]>,
        opts: &MeshOptions,
    ) -> Result<Mesh> {
        let comm: &dyn Comm = &**tree.comm();
        let check = check_inputs(tree, classes, opts);
        crate::parallel::comm::agree(comm, check)?;
        let mut timer = PhaseTimer::new();
        // Whatever earlier phases freed must not stay resident under the
        // mesh, which needs about 40 bytes per leaf: a free heap of more
        // than 4 bytes per leaf is given back.
        crate::run::report::trim_heap_above(
            crate::run::report::TRIM_MIN_FREE.min(4 * tree.local_len()),
        );
        // Leaves outside a box domain are never elements.
        let brick = domain.brick;
        let with_void: Vec<u8>;
        let any_void = !brick.is_cube() && tree.leaves().iter().any(|o| brick.is_void(*o));
        let local_class = match (classes, any_void) {
            // Without classes every leaf counts as outside: one byte for
            // all, not one per leaf.
            (None, false) => ClassBytes::Uniform(LeafClass::Outside as u8, tree.local_len()),
            (c, false) => ClassBytes::Slice(c.unwrap_or_default()),
            (c, true) => {
                let of = |i: usize| c.map_or(LeafClass::Outside as u8, |c| c[i]);
                with_void = (tree.leaves().iter().enumerate())
                    .map(|(i, &o)| of(i) | if brick.is_void(o) { VOID } else { 0 })
                    .collect();
                ClassBytes::Slice(&with_void)
            }
        };
        let keep =
            |bits: u8| bits & manifold::REMOVED == 0 && keeps(opts.keep, opts.cut_rule, bits);
        let mut cleaned_classes;
        let mut cleaned = 0;
        // The clean-up's ghost layer serves the mesh too: the same leaves,
        // new data.
        let mut clean_ghosts = None;
        let local_class = if opts.clean_walls && opts.keep != Keep::All {
            cleaned_classes = local_class.to_vec();
            cleaned = timer.time(comm, "clean", || {
                let mut ghosts = build_ghost_layer(tree, |i| cleaned_classes[i] as u64);
                let n = manifold::clean_walls(tree, &mut ghosts, &mut cleaned_classes, keep);
                clean_ghosts = Some(ghosts);
                n
            });
            ClassBytes::Slice(&cleaned_classes)
        } else {
            local_class
        };
        // A mesh of every leaf keeps them all; the clean-up then makes the
        // inside side of the zones' interface manifold instead, moving the
        // inside leaves it drops to the outside.
        let mut zone_classes = None;
        if let (true, Keep::All, ClassBytes::Slice(s)) = (opts.clean_walls, opts.keep, &local_class)
        {
            let mut c = s.to_vec();
            let inside = |bits: u8| {
                bits & manifold::REMOVED == 0 && keeps(Keep::Inside, opts.cut_rule, bits)
            };
            cleaned = timer.time(comm, "clean", || {
                let mut ghosts = build_ghost_layer(tree, |i| c[i] as u64);
                manifold::clean_walls(tree, &mut ghosts, &mut c, inside)
            });
            zone_classes = Some(c);
        }

        // Each leaf travels with its class and, when kept, its global
        // element number, so the halo of the finite-volume faces needs no
        // second exchange.
        // The kept leaves, numbered: a leaf's element number is the count
        // of kept leaves before it.
        // `keep` asked once per class byte, not once per leaf.
        let keeps_class: [bool; 256] = std::array::from_fn(|c| keep(c as u8));
        let kept = match local_class {
            ClassBytes::Slice(s) => Ranks::from_fn(s.len(), |i| keeps_class[s[i] as usize]),
            ClassBytes::Uniform(c, n) => Ranks::from_fn(n, |_| keeps_class[c as usize]),
        };
        let nkept = kept.count() as u64;
        let kept_counts = comm.allgather_u64(nkept);
        let first_element: u64 = kept_counts[..comm.rank()].iter().sum();
        let ghosts = timer.time(comm, "ghost", || {
            let data =
                |i: usize| local_class.get(i) as u64 | (first_element + kept.rank(i) as u64) << 8;
            match clean_ghosts {
                Some(mut g) => {
                    g.exchange_data(comm, data);
                    g
                }
                None => build_ghost_layer(tree, data),
            }
        });
        let halo = Halo::from_ghosts(&ghosts, keep);
        let num_ghosts = ghosts.len() as u64;
        drop(ghosts);

        let nodes = timer.time(comm, "nodes", || {
            let elements = kept_elements(tree, &local_class, &kept);
            // The walk goes over the elements and the halo elements only.
            let merged = halo.around(&elements.leaves);
            let (d, dual_tree) = dual::extract_nodes(merged)?;
            let counted = count_hanging(comm, tree.first_cells(), &d, merged);
            Ok((d, dual_tree, elements, counted))
        });
        let (d, dual_tree, elements, (face_hanging, edge_hanging)) =
            crate::parallel::comm::agree(comm, nodes)?;

        let numbering = timer.time(comm, "numbering", || {
            number_independent(comm, tree.first_cells(), &d, halo.around(&elements.leaves))
        });
        let numbering = crate::parallel::comm::agree(comm, numbering)?;

        let mesh = timer.time(comm, "connectivity", || {
            assemble(comm, domain, (d, dual_tree), elements, halo, numbering)
        });
        let mut mesh = crate::parallel::comm::agree(comm, mesh)?;
        // Zones split a mesh of every leaf by the centre's side, which the
        // element classes do not keep for cut leaves: one bit per element.
        if let (Keep::All, ClassBytes::Slice(s)) = (opts.keep, &local_class) {
            let s = zone_classes.as_deref().unwrap_or(s);
            let mut bits = Vec::with_capacity(mesh.elements.len());
            kept.select(s, &mut bits);
            let inside =
                |b: u8| b & manifold::REMOVED == 0 && b & crate::classify::CENTER_INSIDE != 0;
            mesh.centre_inside = bits
                .chunks(64)
                .map(|c| {
                    (c.iter().enumerate()).fold(0u64, |w, (k, &b)| w | u64::from(inside(b)) << k)
                })
                .collect();
        }
        mesh.first_element = first_element;
        mesh.first_cells = tree.first_cells().to_vec();
        let mut sums = [
            mesh.elements.len() as u64,
            face_hanging,
            edge_hanging,
            mesh.counts.elements_with_hanging,
            num_ghosts,
        ];
        comm.sum_u64(&mut sums);
        mesh.counts.elements = sums[0];
        mesh.counts.face_hanging_nodes = sums[1];
        mesh.counts.edge_hanging_nodes = sums[2];
        mesh.counts.elements_with_hanging = sums[3];
        mesh.counts.ghosts = sums[4];
        mesh.counts.cleaned = cleaned;
        mesh.timer = timer;
        Ok(mesh)
    }
}

/// The class byte of each local leaf: the caller's, or one for all.
enum ClassBytes<'a> {
    Slice(&'a [u8]),
    Uniform(u8, usize),
}

impl ClassBytes<'_> {
    #[inline]
    fn get(&self, i: usize) -> u8 {
        match self {
            ClassBytes::Slice(s) => s[i],
            ClassBytes::Uniform(c, _) => *c,
        }
    }

    fn len(&self) -> usize {
        match self {
            ClassBytes::Slice(s) => s.len(),
            ClassBytes::Uniform(_, n) => *n,
        }
    }

    fn iter(&self) -> impl Iterator<Item = u8> + '_ {
        (0..self.len()).map(|i| self.get(i))
    }

    fn to_vec(&self) -> Vec<u8> {
        self.iter().collect()
    }
}

fn check_inputs(tree: &LinearOctree, classes: Option<&[u8]>, opts: &MeshOptions) -> Result<()> {
    match tree.balanced() {
        Some(Connectivity::Edge) | Some(Connectivity::Corner) => {}
        other => {
            let what = other.map_or("not balanced", |c| c.name());
            return Err(Error::new(
                ErrorKind::State,
                format!(
                    "meshing needs an octree balanced for edge or corner contacts (this one is {what}): \
                     with face balance alone a hanging node may depend on another hanging node"
                ),
            ));
        }
    }
    match classes {
        Some(c) if c.len() != tree.local_len() => Err(Error::invalid(format!(
            "{} leaf classes for {} local leaves",
            c.len(),
            tree.local_len()
        ))),
        None if opts.keep != Keep::All => Err(Error::invalid(format!(
            "keeping {} elements needs a surface to classify the leaves",
            opts.keep.name()
        ))),
        _ => Ok(()),
    }
}

/// Face- and edge-hanging nodes found here whose directory is this rank,
/// so that each is counted once over all ranks (unused ones included).
fn count_hanging(
    comm: &dyn Comm,
    first_cell: &[u64],
    d: &dual::DualNodes,
    leaves: Merged,
) -> (u64, u64) {
    let (nf, ne) = (d.face.len() as u64, d.edge.len() as u64);
    if comm.size() == 1 {
        return (nf, ne);
    }
    // The walk counted the nodes whose directory cell is in a local leaf;
    // the others' directory is looked up from their points.
    let me = comm.rank();
    let count = |kind: usize, list: &dual::Entries| {
        let looked_up = d.directory_unknown[kind].iter().filter(|&&k| {
            let (q, mask, _) = list.get(k as usize);
            let x = dual::DualNodes::hanging_coords(leaves.get(q as usize), mask);
            numbering::directory_rank(first_cell, x) == me
        });
        d.directory_here[kind] + looked_up.count() as u64
    };
    (count(0, &d.face), count(1, &d.edge))
}

/// Owners and global numbers of the used independent nodes.
struct Independent {
    /// Used independent nodes this rank owns; local number = rank among
    /// them (traversal order), global number = `first_global` + that.
    owned: Ranks,
    /// The used independent nodes owned elsewhere, by global number:
    /// (global number, owner, node).
    others: Vec<(u64, u32, u32)>,
    /// Used boundary nodes, in traversal order.
    boundary: Vec<u32>,
    /// Their users (see [`numbering::Sharing`]).
    sharing: numbering::Sharing,
    first_global: u64,
    global_count: u64,
}

/// Numbers the used independent nodes: interior ones are this rank's alone;
/// only those on partition boundaries go through the directory. Collective.
fn number_independent(
    comm: &dyn Comm,
    first_cell: &[u64],
    d: &dual::DualNodes,
    leaves: Merged,
) -> Result<Independent> {
    let me = comm.rank() as u32;
    let on_boundary = |f: u8| f & dual::USED != 0 && f & dual::BOUNDARY != 0;
    let boundary: Vec<u32> = (0..d.flags.len() as u32)
        .filter(|&n| on_boundary(d.flags[n as usize]))
        .collect();
    // Points of boundary nodes: recorded by the traversal where a ghost is
    // around them, else (a dependency of such a hanging node) a corner of
    // the coarse leaf it hangs on.
    let mut bcoords = vec![[0u32; 3]; boundary.len()];
    let mut set = vec![false; boundary.len()];
    let mut put = |n: u32, x: [u32; 3]| {
        if let Ok(k) = boundary.binary_search(&n) {
            bcoords[k] = x;
            set[k] = true;
        }
    };
    for &(n, x) in &d.boundary_points {
        put(n, x);
    }
    for (q, mask, flags) in d.face.iter().chain(d.edge.iter()) {
        if flags & dual::BOUNDARY == 0 {
            continue;
        }
        let q = q as usize;
        for (n, x) in dual::entry_deps(leaves.get(q), &d.corners[q], mask) {
            put(n, x);
        }
    }
    if set.iter().any(|&s| !s) {
        return Err(Error::new(
            ErrorKind::Internal,
            "a node on a partition boundary has no known point",
        ));
    }
    drop(set);
    let sharing = numbering::find_users(comm, first_cell, &bcoords)?;

    let mut j = 0;
    let owned = Ranks::from_fn(d.flags.len(), |n| {
        let f = d.flags[n];
        if f & dual::USED == 0 {
            return false;
        }
        if f & dual::BOUNDARY == 0 {
            return true;
        }
        j += 1;
        sharing.owner[j - 1] == me
    });
    let all = comm.allgather_u64(owned.count() as u64);
    let first_global: u64 = all[..me as usize].iter().sum();
    let global_count: u64 = all.iter().sum();
    let mut bglobal: Vec<u64> = boundary
        .iter()
        .map(|&n| {
            if owned.contains(n as usize) {
                first_global + owned.rank(n as usize) as u64
            } else {
                u64::MAX
            }
        })
        .collect();
    numbering::exchange_numbers(comm, &bcoords, &sharing, &mut bglobal)?;
    let mut others = Vec::new();
    for (k, &n) in boundary.iter().enumerate() {
        if !owned.contains(n as usize) {
            if bglobal[k] == u64::MAX {
                return Err(Error::new(
                    ErrorKind::Internal,
                    "a shared node's owner sent no global number",
                ));
            }
            others.push((bglobal[k], sharing.owner[k], n));
        }
    }
    others.sort_unstable();
    Ok(Independent {
        owned,
        others,
        boundary,
        sharing,
        first_global,
        global_count,
    })
}

/// The kept local leaves, which become the elements, and their classes.
struct KeptElements {
    leaves: Elements,
    /// Class per element, or `None` when all leaves have `uniform`.
    class: Option<Vec<u8>>,
    uniform: u8,
}

/// Picks the local leaves in `kept`.
fn kept_elements(tree: &LinearOctree, local_class: &ClassBytes, kept: &Ranks) -> KeptElements {
    let nkept = kept.count() as usize;
    // One class for all is kept as one byte until asked for.
    let (class, uniform) = match local_class {
        ClassBytes::Uniform(c, _) => (None, LeafClass::from_bits(*c) as u8),
        ClassBytes::Slice(s) => {
            let mut class = Vec::with_capacity(nkept);
            kept.select(s, &mut class);
            class
                .iter_mut()
                .for_each(|c| *c = LeafClass::from_bits(*c) as u8);
            (Some(class), 0)
        }
    };
    let leaves = if nkept == tree.local_len() {
        Elements::Shared(tree.shared_leaves())
    } else {
        let mut own = Vec::with_capacity(nkept);
        kept.select(tree.leaves(), &mut own);
        Elements::Own(own)
    };
    KeptElements {
        leaves,
        class,
        uniform,
    }
}

/// Turns the traversal's output over the elements and the halo into the
/// mesh, in place where it can: the corner table becomes the connectivity,
/// the hanging-node entries their dependencies.
fn assemble(
    comm: &dyn Comm,
    domain: &Domain,
    (d, dual_tree): (dual::DualNodes, dual::DualTree),
    elements: KeptElements,
    halo: Halo,
    num: Independent,
) -> Result<Mesh> {
    let leaves = halo.around(&elements.leaves);
    let dual::DualNodes {
        flags,
        corners,
        mut face,
        mut edge,
        ..
    } = d;
    // Local order: owned (traversal order), others (by global number),
    // face-hanging, edge-hanging (each in traversal order).
    let num_owned = num.owned.count() as usize;
    let num_independent = num_owned + num.others.len();
    let mut other_of: Vec<(u32, u32)> = num
        .others
        .iter()
        .enumerate()
        .map(|(k, o)| (o.2, (num_owned + k) as u32))
        .collect();
    other_of.sort_unstable();
    let independent = |n: u32| -> u32 {
        if num.owned.contains(n as usize) {
            num.owned.rank(n as usize)
        } else {
            other_of
                .binary_search_by_key(&n, |o| o.0)
                .map_or(UNSET, |k| other_of[k].1)
        }
    };
    let used = |list: &dual::Entries, k: usize| list.get(k).2 & CORNER != 0;
    let face_used = Ranks::from_fn(face.len(), |k| used(&face, k));
    let edge_used = Ranks::from_fn(edge.len(), |k| used(&edge, k));
    let nf = face_used.count() as usize;
    let ne = edge_used.count() as usize;
    let total = num_independent + nf + ne;
    if total > i32::MAX as usize {
        return Err(Error::new(
            ErrorKind::Limit,
            format!("{total} nodes on rank {}: at most 2^31 - 1", comm.rank()),
        ));
    }
    // When every node found is used and owned here (one rank, or no
    // neighbour), a node's new number is the first of its kind plus its
    // index: no rank queries and no branch on its kind.
    let direct = num.owned.is_full() && face_used.is_full() && edge_used.is_full();
    // By the tag's two bits: independent, edge, face, none.
    let first_of_kind = [
        0,
        (num_independent + nf) as u32,
        num_independent as u32,
        UNSET,
    ];
    let of_kind = [&num.owned, &edge_used, &face_used];
    let new_of = |id: u32| -> u32 {
        let kind = (id >> 30) as usize;
        if direct {
            return first_of_kind[kind] + (id & !TAG) * (kind != 3) as u32;
        }
        if kind == 3 {
            return UNSET;
        }
        // No branch on the kind, which follows no pattern the processor
        // could predict; a node owned elsewhere is rare.
        let (rank, member) = of_kind[kind].rank_member((id & !TAG) as usize);
        if kind == 0 && !member {
            return independent(id);
        }
        first_of_kind[kind] + rank
    };

    // Each used hanging entry keeps its coarse leaf, and its code byte
    // becomes its dependency mask, in place; its dependencies are checked
    // and the ones no local element has as a corner keep their lattice
    // points.
    let mut dep_only = Vec::new();
    let mut compact = |list: &mut dual::Entries| -> Result<hanging::Refs> {
        let mut w = 0;
        for k in 0..list.len() {
            // The coarse leaves come in the walk's order, not in memory's.
            if let Some(&ahead) = list.leaf.get(k + 16) {
                prefetch(&corners, ahead as usize);
            }
            let (q, mask, entry_flags) = list.get(k);
            if entry_flags & CORNER == 0 {
                continue;
            }
            let row = &corners[q as usize];
            let mut rest = mask;
            while rest != 0 {
                let c = rest.trailing_zeros() as usize;
                rest &= rest - 1;
                let raw = row[c];
                let dep = if raw & TAG == 0 {
                    independent(raw)
                } else {
                    UNSET
                };
                if dep == UNSET || dep as usize >= num_independent {
                    return Err(Error::new(
                        ErrorKind::Internal,
                        "a hanging node depends on a node that is not independent",
                    ));
                }
                if flags[raw as usize] & CORNER == 0 {
                    // Rare (partition boundaries): the leaf is decoded
                    // only for these.
                    let o = leaves.get(q as usize);
                    dep_only.push((dep, dual::corner_coords(o.coords(), o.side(), c)));
                }
            }
            list.leaf[w] = q;
            list.code[w] = mask;
            w += 1;
        }
        let mut coarse = std::mem::take(&mut list.leaf);
        let mut mask = std::mem::take(&mut list.code);
        // Not shrunk: the unused capacity was never touched, so it is not
        // resident.
        coarse.truncate(w);
        mask.truncate(w);
        Ok(hanging::Refs { coarse, mask })
    };
    let mut face = compact(&mut face)?;
    let mut edge = compact(&mut edge)?;
    debug_assert_eq!((face.coarse.len(), edge.coarse.len()), (nf, ne));
    dep_only.sort_unstable();
    dep_only.dedup();
    drop(flags);

    // Coarse leaves of other ranks keep their row of independent nodes;
    // local ones become element indices.
    let local_range = leaves.local_range();
    let mut ghost_leaves: Vec<u32> = (face.coarse.iter().chain(&edge.coarse).copied())
        .filter(|&q| !local_range.contains(&(q as usize)))
        .collect();
    ghost_leaves.sort_unstable();
    ghost_leaves.dedup();
    let ghost_rows: Vec<[u32; 8]> = (ghost_leaves.iter())
        .map(|&q| corners[q as usize].map(|n| if n & TAG == 0 { independent(n) } else { UNSET }))
        .collect();
    for q in face.coarse.iter_mut().chain(edge.coarse.iter_mut()) {
        *q = match (*q as usize).checked_sub(local_range.start) {
            Some(j) if j < local_range.len() => j as u32,
            _ => GHOST | ghost_leaves.binary_search(q).unwrap_or(0) as u32,
        };
    }
    let hanging = Hanging::new(face, edge, ghost_rows);

    // The corner table becomes the connectivity in place: the elements'
    // rows move to the front (never past their own slot), renumbered.
    let mut connectivity = corners;
    let mut with_hanging = 0u64;
    for (w, i) in local_range.clone().enumerate() {
        let c = connectivity[i];
        with_hanging += (c.iter().fold(0, |a, &n| a | n) & TAG != 0) as u64;
        // A plain loop: `array::from_fn` left a call per corner here.
        let mut row = [UNSET; 8];
        for (v, slot) in row.iter_mut().enumerate() {
            *slot = new_of(c[VTK_TO_MORTON[v]]);
        }
        connectivity[w] = row;
    }
    connectivity.truncate(local_range.len());
    if connectivity.len() < connectivity.capacity() / 2 {
        connectivity.shrink_to_fit();
    }

    let sh = &num.sharing;
    let mut order: Vec<(u32, usize)> = sh
        .shared
        .iter()
        .enumerate()
        .map(|(s, &k)| (independent(num.boundary[k as usize]), s))
        .collect();
    order.sort_unstable();
    let mut shared_nodes = Vec::with_capacity(order.len());
    let mut shared_offsets = vec![0u32];
    let mut shared_ranks = Vec::with_capacity(sh.users.len());
    for (n, s) in order {
        shared_nodes.push(n);
        shared_ranks.extend_from_slice(sh.users_of(s));
        shared_offsets.push(shared_ranks.len() as u32);
    }
    Ok(Mesh {
        rank: comm.rank(),
        size: comm.size(),
        domain: *domain,
        element_class: match elements.class {
            Some(class) => OnceLock::from(class),
            None => OnceLock::new(),
        },
        uniform_class: elements.uniform,
        elements: elements.leaves,
        connectivity,
        num_owned,
        num_independent,
        other_global: num.others.iter().map(|o| o.0).collect(),
        other_owner: num.others.iter().map(|o| o.1).collect(),
        hanging,
        dep_only,
        shared_nodes,
        shared_offsets,
        shared_ranks,
        first_global: num.first_global,
        first_element: 0,
        first_cells: Vec::new(),
        halo,
        dual_tree,
        counts: MeshCounts {
            independent_nodes: num.global_count,
            // This rank's, summed by the caller.
            elements_with_hanging: with_hanging,
            ..MeshCounts::default()
        },
        timer: PhaseTimer::new(),
        moved: None,
        moved_lattice: None,
        zones: None,
        centre_inside: Vec::new(),
    })
}
