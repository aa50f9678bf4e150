#!/usr/bin/env python3
"""A large surface for scaling runs: a binary STL file with every triangle
cut into four by its edge midpoints, LEVELS times over (4**LEVELS times the
triangles).

  python3 tools/bench/subdivide_stl.py ../shared/data/dragon.stl /tmp/dragon16.stl
  python3 tools/bench/subdivide_stl.py IN.stl OUT.stl --levels 3

The default, two levels, makes the dragon's 871,306 triangles 13,940,896
(697 MB). The new triangles keep the orientation of the old one; a midpoint
is computed from the edge's two float32 ends the same way in both triangles
that share the edge, so a closed surface stays closed (bit-identical shared
vertices). Normals are the unit normals of the new triangles. The input is
read and written in chunks: memory stays near 100 MB whatever the size.
Needs numpy.
"""

import argparse
import struct
import sys

import numpy as np

RECORD = np.dtype(
    [("normal", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")]
)
CHUNK = 1 << 16


def split4(v):
    """(n, 3, 3) float32 corners -> (4 n, 3, 3): the midpoint subdivision."""
    a, b, c = v[:, 0], v[:, 1], v[:, 2]
    # float64 sums of float32 values are exact; one rounding to float32,
    # identical from both sides of an edge.
    mid = lambda p, q: ((p.astype(np.float64) + q) * 0.5).astype(np.float32)
    ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
    out = np.empty((len(v), 4, 3, 3), dtype=np.float32)
    out[:, 0] = np.stack([a, ab, ca], axis=1)
    out[:, 1] = np.stack([ab, b, bc], axis=1)
    out[:, 2] = np.stack([ca, bc, c], axis=1)
    out[:, 3] = np.stack([ab, bc, ca], axis=1)
    return out.reshape(-1, 3, 3)


def records(v):
    rec = np.zeros(len(v), dtype=RECORD)
    d = v.astype(np.float64)
    n = np.cross(d[:, 1] - d[:, 0], d[:, 2] - d[:, 0])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    rec["normal"] = np.divide(n, length, out=np.zeros_like(n), where=length > 0)
    rec["v"] = v
    return rec


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("input", help="a binary STL file")
    ap.add_argument("output", help="the binary STL file to write")
    ap.add_argument("--levels", type=int, default=2, help="subdivisions (default 2)")
    args = ap.parse_args()
    with open(args.input, "rb") as f:
        head = f.read(84)
        if len(head) < 84:
            sys.exit(f"{args.input}: too short for a binary STL")
        (n,) = struct.unpack("<I", head[80:84])
        f.seek(0, 2)
        if f.tell() != 84 + 50 * n:
            sys.exit(f"{args.input}: not a binary STL of {n} triangles (ASCII?)")
        total = n * 4**args.levels
        if total >= 2**32:
            sys.exit(f"{total} triangles: more than a binary STL can count")
        f.seek(84)
        with open(args.output, "wb") as out:
            header = f"{args.input} subdivided {args.levels} times".encode()[:80]
            out.write(header.ljust(80, b" "))
            out.write(struct.pack("<I", total))
            done = 0
            while done < n:
                k = min(CHUNK, n - done)
                v = np.frombuffer(f.read(50 * k), dtype=RECORD)["v"].copy()
                for _ in range(args.levels):
                    v = split4(v)
                records(v).tofile(out)
                done += k
    print(f"{args.output}: {total} triangles ({84 + 50 * total} bytes)")


if __name__ == "__main__":
    main()
