#!/usr/bin/env python3
"""Ghost layer and mirrors of equal-count partitions of a leaf file, by ordering.

Reads a binary leaf file (`octmesh octree ... --write-leaves F.bin`: the magic
`OCTLEAF1`, a u64 count, then x y z level as little-endian i32 per leaf, on
the 2^19 lattice, in Morton order) and splits its leaves into P parts of equal
count (part q holds positions [ceil(q n / P), ceil((q + 1) n / P)) of the
order, as `octmesh`'s partition) in each of these orders:

- `morton`: the file's order, octmesh's partition;
- `hilbert`: the leaves sorted by the 3D Hilbert index of their centres on
  the finest lattice (Skilling's transform; every aligned cube is one run of
  a Hilbert curve, so this is a leaf order);
- `rcb`: recursive coordinate bisection of the leaf centres (split at the
  count's median across the widest extent), compact parts as a reference.

Per part it reports, as `octmesh`'s ghost layer counts them (contact across a
face, an edge or a corner):

- ghosts: distinct leaves of other parts touching the part (what a rank
  receives in the ghost exchange, 16 bytes each);
- mirror pairs: (own leaf, other part) pairs with a contact (what a rank
  sends, 16 bytes each); mirrors: distinct own leaves touching another part;
- neighbours: other parts touching the part.

Contacts. Each leaf probes the 26 lattice cells just outside its faces,
edges and corners at its own size (face and edge centres, corners), each
located by binary search on the Morton keys of the leaves. Every contact
with a leaf of the same size or larger is found from the smaller side, and
every pair of leaves in contact has a smaller-or-equal side, so the found
pairs, made symmetric, are all the contacts. One pass of probes serves every
order and every P.

    /usr/bin/python3 tools/bench/partition_boundary.py /tmp/pb/sphere_16.bin --parts 16
    /usr/bin/python3 tools/bench/partition_boundary.py F.bin --parts 2,4,8 --json out.json
    /usr/bin/python3 tools/bench/partition_boundary.py F.bin --parts 2 --orders morton --stats s.json

`--table rows.json` prints the rows as markdown: per surface (the file name
up to `_`) and P, the most ghosts and mirror pairs of a part in each order,
with the ratio to the same order's P = 2 value.
`--stats` checks the Morton counts against `octmesh mesh --stats` of the
same tree on P ranks: the ghosts over all ranks, and the ghost phase's most
bytes sent and received by a rank (16 per mirror pair and per ghost).

numpy only. `--self-test` checks the Hilbert order (consecutive cells are
face neighbours, aligned cubes are runs) and the contact pairs against brute
force on a small tree.
"""

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

LATTICE_BITS = 19
ROOT = 1 << LATTICE_BITS
ORDERS = ("morton", "hilbert", "rcb")


def read_leaves(path):
    """x, y, z, level arrays (int64) of a binary leaf file."""
    with open(path, "rb") as f:
        magic = f.read(8)
        if magic != b"OCTLEAF1":
            sys.exit(f"{path}: not a cube leaf file (magic {magic!r}, want OCTLEAF1)")
        n = int(np.frombuffer(f.read(8), dtype="<u8")[0])
        a = np.fromfile(f, dtype="<i4", count=4 * n)
    if a.size != 4 * n:
        sys.exit(f"{path}: truncated ({a.size // 4} of {n} leaves)")
    a = a.reshape(n, 4).astype(np.int64)
    return a[:, 0], a[:, 1], a[:, 2], a[:, 3]


def spread3(v):
    """Bit i of each value to bit 3 i (21 bits), as octmesh's `spread3`."""
    x = v.astype(np.uint64) & np.uint64(0x1F_FFFF)
    for shift, mask in (
        (32, 0x001F_0000_0000_FFFF),
        (16, 0x001F_0000_FF00_00FF),
        (8, 0x100F_00F0_0F00_F00F),
        (4, 0x10C3_0C30_C30C_30C3),
        (2, 0x1249_2492_4924_9249),
    ):
        x = (x | (x << np.uint64(shift))) & np.uint64(mask)
    return x


def morton(x, y, z):
    """Morton code with x in the lowest bit of each triple (octmesh's order)."""
    return spread3(x) | (spread3(y) << np.uint64(1)) | (spread3(z) << np.uint64(2))


def hilbert(x, y, z, bits=LATTICE_BITS):
    """3D Hilbert index of lattice points (Skilling 2004, axes to transpose)."""
    X = [np.asarray(c, dtype=np.int64).copy() for c in (x, y, z)]
    q = 1 << (bits - 1)
    while q > 1:
        p = q - 1
        for i in range(3):
            hit = (X[i] & q) != 0
            t = np.where(hit, 0, (X[0] ^ X[i]) & p)
            X[0] ^= np.where(hit, p, t)
            if i:
                X[i] ^= t
        q >>= 1
    X[1] ^= X[0]
    X[2] ^= X[1]
    t = np.zeros_like(X[0])
    q = 1 << (bits - 1)
    while q > 1:
        t ^= np.where((X[2] & q) != 0, q - 1, 0)
        q >>= 1
    for i in range(3):
        X[i] ^= t
    # Transposed form: X[0] holds the most significant bit of each triple.
    return spread3(X[2]) | (spread3(X[1]) << np.uint64(1)) | (spread3(X[0]) << np.uint64(2))


DIRECTIONS = np.array(
    [(a, b, c) for a in (-1, 0, 1) for b in (-1, 0, 1) for c in (-1, 0, 1) if (a, b, c) != (0, 0, 0)],
    dtype=np.int64,
)


def contacts(x, y, z, level, keys, chunk=150_000):
    """Every pair (i, j), i < j, of leaves in contact (see the module notes)."""
    n = x.size
    size = np.int64(1) << (LATTICE_BITS - level)
    found = []
    for lo in range(0, n, chunk):
        hi = min(n, lo + chunk)
        s = size[lo:hi]
        pairs = []
        anchor = [x[lo:hi], y[lo:hi], z[lo:hi]]
        for d in DIRECTIONS:
            p = [
                a - 1 if dk < 0 else (a + s if dk > 0 else a + s // 2)
                for a, dk in zip(anchor, d)
            ]
            ok = np.ones(hi - lo, dtype=bool)
            for c in p:
                ok &= (c >= 0) & (c < ROOT)
            idx = np.nonzero(ok)[0]
            k = morton(p[0][idx], p[1][idx], p[2][idx])
            j = np.searchsorted(keys, k, side="right") - 1
            i = idx + lo
            # One entry per unordered pair: (smaller index, larger index).
            pairs.append(np.minimum(i, j) * np.int64(n) + np.maximum(i, j))
        found.append(np.unique(np.concatenate(pairs)))
        pairs.clear()
    pair = np.unique(np.concatenate(found))
    return pair // n, pair % n


def starts(n, parts):
    """First position of each part, octmesh's split: ceil(q n / P)."""
    q = np.arange(parts + 1, dtype=np.int64)
    return -((-q * n) // parts)


def parts_of_order(order, parts):
    """Part of each leaf when the leaves in `order` are split in equal counts."""
    n = order.size
    pos = np.empty(n, dtype=np.int64)
    pos[order] = np.arange(n)
    return (np.searchsorted(starts(n, parts), pos, side="right") - 1).astype(np.int32)


def rcb(cx, cy, cz, parts):
    """Recursive coordinate bisection into parts with octmesh's counts."""
    n = cx.size
    counts = np.diff(starts(n, parts))
    out = np.empty(n, dtype=np.int32)
    coords = np.stack([cx, cy, cz])
    stack = [(np.arange(n), 0, parts)]
    while stack:
        idx, first, k = stack.pop()
        if k == 1:
            out[idx] = first
            continue
        k1 = k // 2
        n1 = int(counts[first:first + k1].sum())
        c = coords[:, idx]
        axis = int(np.argmax(c.max(axis=1) - c.min(axis=1)))
        sel = np.argpartition(c[axis], n1 - 1)
        stack.append((idx[sel[:n1]], first, k1))
        stack.append((idx[sel[n1:]], first + k1, k - k1))
    return out


def measure(part, pi, pj, parts):
    """Per-part ghosts, mirror pairs, mirrors and neighbour parts."""
    cross = part[pi] != part[pj]
    i, j = pi[cross], pj[cross]
    # Both directions: a leaf is a ghost of the other leaf's part.
    own = np.concatenate([i, j])
    other = np.concatenate([j, i])
    po, pt = part[own].astype(np.int64), part[other].astype(np.int64)
    n = part.size
    ghost = np.unique(po * n + other)  # (part, foreign leaf)
    ghosts = np.bincount(ghost // n, minlength=parts)
    mpair = np.unique(own * parts + pt)  # (own leaf, other part)
    mirror_pairs = np.bincount(part[mpair // parts], minlength=parts)
    mirrors = np.bincount(part[np.unique(own)], minlength=parts)
    adj = np.unique(po * parts + pt)
    neighbours = np.bincount(adj // parts, minlength=parts)
    return {
        "ghosts": ghosts.tolist(),
        "mirror_pairs": mirror_pairs.tolist(),
        "mirrors": mirrors.tolist(),
        "neighbours": neighbours.tolist(),
    }


def summary(per):
    g, mp, m, nb = (np.array(per[k]) for k in ("ghosts", "mirror_pairs", "mirrors", "neighbours"))
    return {
        "ghosts_max": int(g.max()),
        "ghosts_mean": float(g.mean()),
        "ghosts_total": int(g.sum()),
        "mirror_pairs_max": int(mp.max()),
        "mirrors_max": int(m.max()),
        "mirrors_mean": float(m.mean()),
        "neighbours_max": int(nb.max()),
        "neighbours_mean": float(nb.mean()),
        # The ghost exchange's payload: 16 bytes per (leaf, rank) pair.
        "ghost_kib_received_max": 16 * int(g.max()) / 1024,
        "ghost_kib_sent_max": 16 * int(mp.max()) / 1024,
    }


def analyse(path, parts_list, orders, log=print):
    t0 = time.time()
    x, y, z, level = read_leaves(path)
    n = x.size
    keys = morton(x, y, z)
    if n > 1 and not np.all(keys[1:] > keys[:-1]):
        sys.exit(f"{path}: leaves not in strictly increasing Morton order")
    size = np.int64(1) << (LATTICE_BITS - level)
    volume = sum(int(c) * 8 ** (LATTICE_BITS - lv) for lv, c in enumerate(np.bincount(level)))
    if volume != ROOT ** 3:
        sys.exit(f"{path}: the leaves do not cover the root cube")
    pi, pj = contacts(x, y, z, level, keys)
    log(f"{path}: {n} leaves, {pi.size} contacts ({time.time() - t0:.1f} s)")
    cx, cy, cz = x + size // 2, y + size // 2, z + size // 2
    hilbert_order = np.argsort(hilbert(cx, cy, cz), kind="stable") if "hilbert" in orders else None
    rows = []
    for parts in parts_list:
        for order in orders:
            if order == "morton":
                part = parts_of_order(np.arange(n), parts)
            elif order == "hilbert":
                part = parts_of_order(hilbert_order, parts)
            else:
                part = rcb(cx, cy, cz, parts)
            per = measure(part, pi, pj, parts)
            row = {"file": str(path), "leaves": n, "parts": parts, "order": order,
                   "leaves_per_part": n / parts}
            row.update(summary(per))
            row["per_part"] = per
            rows.append(row)
            log(
                f"  P={parts:3d} {order:8s} ghosts max {row['ghosts_max']:8d} mean "
                f"{row['ghosts_mean']:10.1f}  mirrors max {row['mirrors_max']:8d}  "
                f"mirror pairs max {row['mirror_pairs_max']:8d}  neighbours max "
                f"{row['neighbours_max']:3d} mean {row['neighbours_mean']:5.2f}"
            )
    return rows


def markdown(rows):
    """One line per surface and P: the most ghosts and mirror pairs of a part
    in each order, with the ratio to the same order's P = 2 value of the same
    surface (the file name up to its first `_`) in parentheses."""
    def surface(r):
        return Path(r["file"]).stem.split("_")[0]

    by = {(surface(r), r["parts"], r["order"]): r for r in rows}
    orders = [o for o in ORDERS if any(k[2] == o for k in by)]
    name = {"morton": "Morton", "hilbert": "Hilbert", "rcb": "RCB"}
    heads = [f"ghosts, {name[o]}" for o in orders] + [f"mirror pairs, {name[o]}" for o in orders]
    out = [
        "| surface | P | leaves per part | " + " | ".join(heads) + " |",
        "|:---|---:|---:|" + "---:|" * len(heads),
    ]
    surfaces = list(dict.fromkeys(surface(r) for r in rows))
    for surf, parts in sorted({(k[0], k[1]) for k in by}, key=lambda k: (surfaces.index(k[0]), k[1])):
        cells = []
        for key in ("ghosts_max", "mirror_pairs_max"):
            for o in orders:
                r, b = by.get((surf, parts, o)), by.get((surf, 2, o))
                if r is None:
                    cells.append("-")
                else:
                    ratio = f" ({r[key] / b[key]:.2f})" if b else ""
                    cells.append(f"{r[key]:,}{ratio}")
        any_row = next(by[(surf, parts, o)] for o in orders if (surf, parts, o) in by)
        out.append(f"| {surf} | {parts} | {any_row['leaves_per_part']:,.0f} | " + " | ".join(cells) + " |")
    return "\n".join(out)


def check_stats(stats_path, rows):
    """Compares the Morton rows with an `octmesh mesh --stats` run of the
    same tree: the total ghosts and the most ghost-phase bytes a rank sent
    and received (16 per leaf and rank). Returns whether all agree."""
    d = json.loads(Path(stats_path).read_text())
    p, n = d["ranks"], d["octants_balanced"]
    match = [r for r in rows if r["order"] == "morton" and r["parts"] == p and r["leaves"] == n]
    if not match:
        print(f"{stats_path}: no Morton row with P = {p} and {n} leaves")
        return False
    r = match[0]
    pairs = [
        ("ghosts over all ranks", d["ghosts"], r["ghosts_total"]),
        ("ghost bytes sent, max", d["comm_bytes_sent"]["ghost"], 16 * r["mirror_pairs_max"]),
        ("ghost bytes received, max", d["comm_bytes_received"]["ghost"], 16 * r["ghosts_max"]),
    ]
    ok = True
    for what, octmesh, tool in pairs:
        ok &= octmesh == tool
        print(f"{stats_path}: {what}: octmesh {octmesh}, this tool {tool}"
              f" {'(same)' if octmesh == tool else '(DIFFERENT)'}")
    return ok


def self_test():
    # Hilbert: consecutive cells of a 2^3 lattice are face neighbours.
    b = 3
    g = np.arange(1 << b)
    x, y, z = (a.ravel() for a in np.meshgrid(g, g, g, indexing="ij"))
    h = hilbert(x, y, z, bits=b)
    assert np.unique(h).size == h.size and int(h.max()) == (1 << 3 * b) - 1
    o = np.argsort(h)
    step = np.abs(np.diff(x[o])) + np.abs(np.diff(y[o])) + np.abs(np.diff(z[o]))
    assert np.all(step == 1), "Hilbert order not continuous"
    # Every aligned cube is one run of the curve, so sorting leaves by their
    # centres' indices is a leaf order.
    for side in (2, 4):
        cube = (x // side) * 64 + (y // side) * 8 + z // side
        for c in np.unique(cube):
            run = h[cube == c]
            assert int(run.max() - run.min()) + 1 == run.size, "aligned cube split"
    # Contacts against brute force on a random complete tree, 2:1 or not.
    rng = np.random.default_rng(7)
    leaves = [(0, 0, 0, 0)]
    for _ in range(60):
        k = int(rng.integers(len(leaves)))
        lx, ly, lz, lv = leaves.pop(k)
        if lv >= 5:
            leaves.append((lx, ly, lz, lv))
            continue
        h = 1 << (LATTICE_BITS - lv - 1)
        leaves += [(lx + h * (c & 1), ly + h * (c >> 1 & 1), lz + h * (c >> 2), lv + 1) for c in range(8)]
    a = np.array(leaves, dtype=np.int64)
    keys = morton(a[:, 0], a[:, 1], a[:, 2])
    o = np.argsort(keys)
    a, keys = a[o], keys[o]
    x, y, z, lv = a.T
    pi, pj = contacts(x, y, z, lv, keys, chunk=17)
    found = set(zip(pi.tolist(), pj.tolist()))
    s = 1 << (LATTICE_BITS - lv)
    want = set()
    for i in range(len(a)):
        for j in range(i + 1, len(a)):
            # Closed boxes meet, open boxes do not: a contact.
            if all(max(c[i], c[j]) <= min(c[i] + s[i], c[j] + s[j]) for c in (x, y, z)):
                want.add((i, j))
    assert found == want, (len(found), len(want))
    # Equal counts and RCB counts.
    assert starts(10, 4).tolist() == [0, 3, 5, 8, 10]
    part = rcb(x.astype(float), y.astype(float), z.astype(float), 3)
    assert sorted(np.bincount(part).tolist()) == sorted(np.diff(starts(len(a), 3)).tolist())
    print(f"self-test passed ({len(a)} leaves, {len(want)} contacts)")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("files", nargs="*", type=Path)
    ap.add_argument("--parts", default="2", help="comma-separated part counts P")
    ap.add_argument("--orders", default=",".join(ORDERS), help="of " + ",".join(ORDERS))
    ap.add_argument("--json", type=Path, help="append the rows (with per-part counts) here")
    ap.add_argument("--stats", type=Path, action="append", default=[],
                    help="an `octmesh mesh --stats` JSON of the same tree to check the Morton counts against")
    ap.add_argument("--table", type=Path,
                    help="print a markdown table of the rows in this JSON (from --json) and stop")
    ap.add_argument("--self-test", action="store_true")
    a = ap.parse_args()
    if a.self_test:
        self_test()
        return
    if a.table:
        print(markdown(json.loads(a.table.read_text())))
        return
    orders = [o for o in a.orders.split(",") if o]
    bad = set(orders) - set(ORDERS)
    if bad:
        sys.exit(f"unknown order(s): {', '.join(sorted(bad))}")
    parts_list = [int(p) for p in a.parts.split(",")]
    rows = []
    for f in a.files:
        rows += analyse(f, parts_list, orders)
    if a.json:
        old = json.loads(a.json.read_text()) if a.json.exists() else []
        a.json.write_text(json.dumps(old + rows, indent=1) + "\n")
    if a.stats and not all([check_stats(s, rows) for s in a.stats]):
        sys.exit(1)


if __name__ == "__main__":
    main()
