#!/usr/bin/env python3
"""Whether two OpenFOAM cases hold the same mesh, up to the numbering of their points.

Usage: same_foam_geometry.py CASE_A CASE_B

For every polyMesh under CASE_A (constant/polyMesh or processor*/constant/polyMesh):
- every file but `points` and `faces` is the same bytes in CASE_B;
- both have as many points and the same face sizes (offsets);
- each face, read as the sequence of its points' positions, is the same in both;
- every point of CASE_B is used by a face.

Reads binary (faceCompactList) and ASCII (faceList) cases as octmesh writes them. Meant for a
change to the writer that renumbers points: the faces, their order and their starting points
must not move. Prints one line per mesh; exits with status 1 on any difference.

If `python3` in PATH is not the system one (pyenv, venv), run this script with /usr/bin/python3,
which sees Debian's python3-numpy.
"""

import os
import re
import sys

import numpy as np


def body(data):
    """The bytes after the FoamFile header."""
    return data[data.index(b"}", data.index(b"FoamFile")) + 1:]


def binary_lists(data, dtype, width):
    """The top-level lists 'N (raw bytes)' of a binary file, in order."""
    out, b, pos = [], body(data), 0
    head = re.compile(rb"\s*(\d+) *\n\(")
    while True:
        m = head.match(b, pos)
        if not m:
            return out
        n, start = int(m.group(1)), m.end()
        size = np.dtype(dtype).itemsize * width
        out.append(np.frombuffer(b[start:start + n * size], dtype=dtype).reshape(n, width))
        pos = start + n * size + 1
        while pos < len(b) and b[pos:pos + 1] in b" \n)":
            pos += 1


def read_mesh(path):
    """(points, face offsets, face labels) of one polyMesh directory."""
    pts = open(os.path.join(path, "points"), "rb").read()
    fcs = open(os.path.join(path, "faces"), "rb").read()
    if b"format      binary" in pts[:800]:
        (p,) = binary_lists(pts, "<f8", 3)
        offsets, labels = binary_lists(fcs, "<i4", 1)
        return p, offsets.ravel(), labels.ravel()
    b = body(pts)
    m = re.search(rb"(\d+)\s*\(", b)
    p = np.array([[float(x) for x in v.split()] for v in re.findall(rb"\(([^()]*)\)", b[m.end():])])
    b = body(fcs)
    m = re.search(rb"(\d+)\s*\(", b)
    offsets, labels = [0], []
    for f in re.findall(rb"\d+\(([^()]*)\)", b[m.end():]):
        labels += [int(x) for x in f.split()]
        offsets.append(len(labels))
    return p, np.array(offsets), np.array(labels, dtype=np.int64)


def main():
    if len(sys.argv) != 3:
        print(__doc__.splitlines()[2], file=sys.stderr)
        return 2
    a, b = sys.argv[1], sys.argv[2]
    bad = meshes = 0
    for root, _, files in os.walk(a):
        other = os.path.join(b, os.path.relpath(root, a))
        for f in files:
            if f in ("points", "faces"):
                continue
            pb = os.path.join(other, f)
            if not os.path.exists(pb):
                print("missing", pb)
                bad += 1
            elif open(os.path.join(root, f), "rb").read() != open(pb, "rb").read():
                print("differs", pb)
                bad += 1
        if "points" not in files:
            continue
        meshes += 1
        pa, oa, la = read_mesh(root)
        pb, ob, lb = read_mesh(other)
        if len(pa) != len(pb) or not np.array_equal(oa, ob):
            print("different sizes", other, len(pa), len(pb))
            bad += 1
            continue
        if not np.array_equal(pa[la], pb[lb]):
            print("faces at other points", other)
            bad += 1
        if len(np.unique(lb)) != len(pb):
            print("points no face uses", other)
            bad += 1
        print("%s: %d points, %d faces" % (other, len(pb), len(ob) - 1))
    if meshes == 0:
        print("no polyMesh under", a)
        bad += 1
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
