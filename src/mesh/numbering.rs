//! Owners, sharers and global numbers of independent nodes.
//!
//! Every node has a *directory* rank: the owner of the finest cell whose
//! lowest corner is the node (clamped into the domain). That rank owns the
//! leaf with the node as its lowest corner, so it sees every leaf around the
//! node in its ghost layer. Ranks tell each node's directory that they use
//! it; the directory answers with the full list of users. The owner is the
//! lowest-numbered user (p4est's rule: the rank of the first element in
//! Morton order touching the node). Owners number their nodes in the order
//! given (the mesh's traversal order, deterministic for a given partition),
//! after the owned nodes of lower ranks, and send the numbers to the other
//! users. Three all-to-all exchanges, each carrying only
//! nodes on partition boundaries.

use crate::error::{Error, ErrorKind, Result};
use crate::octree::octant::{morton_encode, ROOT_LEN};
use crate::octree::owner_of_cell;
use crate::parallel::comm::Comm;

/// Morton key of a lattice point (20 bits per coordinate: the upper domain
/// boundary `ROOT_LEN` is a valid coordinate).
#[inline]
pub(crate) fn node_key(x: [u32; 3]) -> u64 {
    morton_encode(x[0], x[1], x[2])
}

/// The finest cell whose lowest corner is `x`, moved inside the domain.
#[inline]
fn directory_cell(x: [u32; 3]) -> u64 {
    let c = |v: u32| v.min(ROOT_LEN - 1);
    morton_encode(c(x[0]), c(x[1]), c(x[2]))
}

/// The rank that counts and arbitrates node `x`.
#[inline]
pub(crate) fn directory_rank(first_cell: &[u64], x: [u32; 3]) -> usize {
    owner_of_cell(first_cell, directory_cell(x))
}

/// Result of [`find_users`], indexed like its input.
pub(crate) struct Sharing {
    /// Owner rank of each node.
    pub owner: Vec<u32>,
    /// Nodes used by more than one rank (input indices, increasing), with
    /// their users: `users[user_offsets[k]..user_offsets[k + 1]]`, sorted.
    pub shared: Vec<u32>,
    /// See `shared`.
    pub user_offsets: Vec<u32>,
    /// See `shared`.
    pub users: Vec<u32>,
}

impl Sharing {
    /// The users of shared node `k` (of `shared`).
    pub fn users_of(&self, k: usize) -> &[u32] {
        &self.users[self.user_offsets[k] as usize..self.user_offsets[k + 1] as usize]
    }
}

/// Finds the users and the owner of each node `coords` used on this rank
/// that other ranks may use too. Collective.
pub(crate) fn find_users(
    comm: &dyn Comm,
    first_cell: &[u64],
    coords: &[[u32; 3]],
) -> Result<Sharing> {
    let p = comm.size();
    let me = comm.rank();
    let n = coords.len();
    let dir: Vec<u32> = coords
        .iter()
        .map(|&x| directory_rank(first_cell, x) as u32)
        .collect();

    // 1. Tell each directory which of its nodes this rank uses.
    let mut asked: Vec<Vec<u32>> = vec![Vec::new(); p];
    for (i, &d) in dir.iter().enumerate() {
        if d as usize != me {
            asked[d as usize].push(i as u32);
        }
    }
    let counts: Vec<usize> = asked.iter().map(|v| v.len()).collect();
    let send: Vec<u64> = asked
        .iter()
        .flat_map(|v| v.iter().map(|&i| node_key(coords[i as usize])))
        .collect();
    let (recv, rcounts) = comm.alltoallv_u64(&send, &counts);

    // 2. As a directory: gather the users of each asked-about node.
    // (key, src, position in src's request)
    let mut reqs: Vec<(u64, u32, u32)> = Vec::with_capacity(recv.len());
    let mut at = 0;
    for (src, &c) in rcounts.iter().enumerate() {
        for (k, &key) in recv[at..at + c].iter().enumerate() {
            reqs.push((key, src as u32, k as u32));
        }
        at += c;
    }
    reqs.sort_unstable();
    // Which of the asked-about keys this rank uses too. Only the asked keys
    // (a partition-boundary set) go into the table; every used node probes it.
    let table = KeyTable::new(reqs.iter().map(|r| r.0));
    let mut local_of = vec![u32::MAX; table.slots()];
    for (i, &x) in coords.iter().enumerate() {
        if dir[i] as usize == me {
            if let Some(slot) = table.find(node_key(x)) {
                local_of[slot] = i as u32;
            }
        }
    }

    let mut owner = vec![me as u32; n];
    let mut users_of: Vec<(u32, Vec<u32>)> = Vec::new(); // (node, users) for shared nodes
                                                         // Per source rank, for each of its requests, the user list (group id).
    let mut reply_group: Vec<Vec<u32>> = rcounts.iter().map(|&c| vec![0; c]).collect();
    let mut groups: Vec<Vec<u32>> = Vec::new();
    let mut k = 0;
    while k < reqs.len() {
        let key = reqs[k].0;
        let mut e = k;
        while e < reqs.len() && reqs[e].0 == key {
            e += 1;
        }
        let local = table
            .find(key)
            .map(|slot| local_of[slot])
            .filter(|&i| i != u32::MAX);
        let mut users: Vec<u32> = reqs[k..e].iter().map(|r| r.1).collect();
        if local.is_some() {
            users.push(me as u32);
        }
        users.sort_unstable();
        users.dedup();
        let g = groups.len() as u32;
        for r in &reqs[k..e] {
            reply_group[r.1 as usize][r.2 as usize] = g;
        }
        if let Some(i) = local {
            owner[i as usize] = users[0];
            users_of.push((i, users.clone()));
        }
        groups.push(users);
        k = e;
    }
    let mut reply_counts = vec![0usize; p];
    let mut reply = Vec::new();
    for (src, gs) in reply_group.iter().enumerate() {
        let start = reply.len();
        for &g in gs {
            let u = &groups[g as usize];
            reply.push(u.len() as u64);
            reply.extend(u.iter().map(|&r| r as u64));
        }
        reply_counts[src] = reply.len() - start;
    }
    drop(groups);
    let (answers, acounts) = comm.alltoallv_u64(&reply, &reply_counts);
    drop(reply);

    // 3. Read the answers about the nodes this rank asked for.
    let mut at = 0;
    for (d, &c) in acounts.iter().enumerate() {
        let mut r = at;
        for &i in &asked[d] {
            let len = answers[r] as usize;
            let users: Vec<u32> = answers[r + 1..r + 1 + len]
                .iter()
                .map(|&u| u as u32)
                .collect();
            r += 1 + len;
            if !users.contains(&(me as u32)) {
                return Err(Error::new(
                    ErrorKind::Internal,
                    format!("node directory on rank {d} does not list rank {me} as a user"),
                ));
            }
            owner[i as usize] = users[0];
            users_of.push((i, users));
        }
        if r != at + c {
            return Err(Error::new(
                ErrorKind::Internal,
                "node directory answer has the wrong length",
            ));
        }
        at += c;
    }
    users_of.sort_unstable_by_key(|u| u.0);
    // A node used only here is not shared.
    users_of.retain(|u| u.1.len() > 1);

    let mut shared = Vec::with_capacity(users_of.len());
    let mut user_offsets = Vec::with_capacity(users_of.len() + 1);
    let mut users = Vec::new();
    user_offsets.push(0);
    for (i, u) in users_of {
        shared.push(i);
        users.extend_from_slice(&u);
        user_offsets.push(users.len() as u32);
    }
    Ok(Sharing {
        owner,
        shared,
        user_offsets,
        users,
    })
}

/// Sends the global numbers of the owned shared nodes to their other users
/// and fills in `global` for the shared nodes owned elsewhere; `global` has
/// the owned nodes' numbers on entry. Collective.
pub(crate) fn exchange_numbers(
    comm: &dyn Comm,
    coords: &[[u32; 3]],
    sharing: &Sharing,
    global: &mut [u64],
) -> Result<()> {
    let p = comm.size();
    let me = comm.rank();
    let owner = &sharing.owner;
    // 5. Owners send the numbers to the other users, in Morton order of
    // the (few) shared nodes, which both sides can reproduce.
    let mut owned_shared: Vec<(u64, usize)> = sharing
        .shared
        .iter()
        .enumerate()
        .filter(|&(_, &i)| owner[i as usize] as usize == me)
        .map(|(k, &i)| (node_key(coords[i as usize]), k))
        .collect();
    owned_shared.sort_unstable();
    let mut out: Vec<Vec<u64>> = vec![Vec::new(); p];
    for &(_, k) in &owned_shared {
        let i = sharing.shared[k];
        for &r in sharing.users_of(k) {
            if r as usize != me {
                out[r as usize].push(global[i as usize]);
            }
        }
    }
    let counts: Vec<usize> = out.iter().map(|v| v.len()).collect();
    let send: Vec<u64> = out.concat();
    let (ids, icounts) = comm.alltoallv_u64(&send, &counts);
    let mut from: Vec<Vec<(u64, u32)>> = vec![Vec::new(); p];
    for &i in &sharing.shared {
        let o = owner[i as usize] as usize;
        if o != me {
            from[o].push((node_key(coords[i as usize]), i));
        }
    }
    let mut at = 0;
    for (o, list) in from.iter_mut().enumerate() {
        list.sort_unstable();
        if list.len() != icounts[o] {
            return Err(Error::new(
                ErrorKind::Internal,
                format!(
                    "rank {o} sent {} node numbers, {} expected",
                    icounts[o],
                    list.len()
                ),
            ));
        }
        for (k, &(_, i)) in list.iter().enumerate() {
            global[i as usize] = ids[at + k];
        }
        at += icounts[o];
    }
    Ok(())
}

/// A small open-addressing set of keys, each with a slot number.
struct KeyTable {
    keys: Vec<u64>,
    mask: usize,
    shift: u32,
}

impl KeyTable {
    const EMPTY: u64 = u64::MAX;

    fn new(keys: impl ExactSizeIterator<Item = u64>) -> KeyTable {
        let cap = (keys.len() * 2).next_power_of_two().max(16);
        let mut t = KeyTable {
            keys: vec![Self::EMPTY; cap],
            mask: cap - 1,
            shift: 64 - cap.trailing_zeros(),
        };
        for k in keys {
            let mut s = t.home(k);
            while t.keys[s] != Self::EMPTY && t.keys[s] != k {
                s = (s + 1) & t.mask;
            }
            t.keys[s] = k;
        }
        t
    }

    fn slots(&self) -> usize {
        self.keys.len()
    }

    #[inline]
    fn home(&self, k: u64) -> usize {
        (k.wrapping_mul(0x9e37_79b9_7f4a_7c15) >> self.shift) as usize
    }

    #[inline]
    fn find(&self, k: u64) -> Option<usize> {
        let mut s = self.home(k);
        loop {
            let v = self.keys[s];
            if v == k {
                return Some(s);
            }
            if v == Self::EMPTY {
                return None;
            }
            s = (s + 1) & self.mask;
        }
    }
}
