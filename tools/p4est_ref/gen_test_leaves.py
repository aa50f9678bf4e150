#!/usr/bin/env python3
"""Write a valid, strongly unbalanced octree leaf file for octmesh_p4est.

Leaves are in p4est Morton order (child id bits: x = 1, y = 2, z = 4).
A cell is refined while below --base, or while it contains one of the
points and is below --level, or (with --random P) with probability P
below --level.  Output format follows the extension (.bin = binary).

  gen_test_leaves.py OUT [--level 8] [--point 0.3 0.3 0.3 ...]
                         [--base 0] [--random P --seed S]
"""

import argparse
import random
import struct
import sys

MAXLEVEL = 19  # P8EST_MAXLEVEL: the root has side 2^19
QMAXLEVEL = 18


def leaves(level_max, base, points, prob, rng):
    out = []
    root = 1 << MAXLEVEL
    # Points in lattice units; a cell [a, a+len) contains p if a <= p < a+len.
    pts = [tuple(min(int(c * root), root - 1) for c in p) for p in points]

    def rec(x, y, z, lev):
        h = 1 << (MAXLEVEL - lev)
        refine = lev < base
        if not refine and lev < level_max:
            refine = any(x <= px < x + h and y <= py < y + h and
                         z <= pz < z + h for px, py, pz in pts)
            if not refine and prob > 0.0:
                refine = rng.random() < prob
        if not refine:
            out.append((x, y, z, lev))
            return
        c = h >> 1
        for cid in range(8):  # z most significant, then y, then x
            rec(x + c * (cid & 1), y + c * ((cid >> 1) & 1),
                z + c * ((cid >> 2) & 1), lev + 1)

    rec(0, 0, 0, 0)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out")
    ap.add_argument("--level", type=int, default=8)
    ap.add_argument("--base", type=int, default=0)
    ap.add_argument("--point", type=float, nargs=3, action="append")
    ap.add_argument("--random", type=float, default=0.0)
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    if not 0 <= a.base <= a.level <= QMAXLEVEL:
        sys.exit("need 0 <= base <= level <= %d" % QMAXLEVEL)
    points = a.point if a.point else [(0.3, 0.3, 0.3)]
    ls = leaves(a.level, a.base, points, a.random, random.Random(a.seed))
    if a.out.endswith(".bin"):
        with open(a.out, "wb") as f:
            f.write(b"OCTLEAF1" + struct.pack("<Q", len(ls)))
            f.write(b"".join(struct.pack("<4i", *l) for l in ls))
    else:
        with open(a.out, "w") as f:
            f.write("# gen_test_leaves.py level %d base %d\n" % (a.level, a.base))
            f.write("# count %d\n" % len(ls))
            f.writelines("%d %d %d %d\n" % l for l in ls)
    print("%s: %d leaves" % (a.out, len(ls)))


if __name__ == "__main__":
    main()
