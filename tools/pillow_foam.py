#!/usr/bin/python3
"""Pillow the wall of an octmesh OpenFOAM case (a measurement of the design, not the product).

Reads an ASCII polyMesh that octmesh wrote from the staircase kept off the surface (`--cut-rule none`) and
writes a new case where every wall face has one more hexahedron between it and the surface:

- each wall vertex (a wall point, or one fan of wall faces at a pinched point) gets a twin on the surface,
  which becomes the wall's point: the first hit of a ray along the mean normal of its faces within CAST
  cells, else of rays along its faces' normals and between, else its closest point;
- the twins spread along the surface by SMOOTH rounds of neighbour means projected back, a round kept per
  point only where its twin stays ahead of its faces;
- the wall point itself moves into the kept region along its mean normal until its twin is DEPTH cells
  ahead of each of its faces (at most REACH cells), so no pillow cell starts flat;
- each wall face becomes an internal face between its cell and its pillow cell; the pillow cells meet across
  the wall's edges (hanging points included: the polygons carry them), and their outer faces are the wall.

No old cell keeps a face on the wall, so a staircase corner cell with two or three wall faces is not
flattened, and every wall point is on the surface. Usage:

    pillow_foam.py CASE SURFACE OUT [--patch NAME]

SURFACE is a binary STL or `sphere` (the unit sphere, exactly). Prints counts as JSON; PILLOW_DEPTH,
PILLOW_REACH, PILLOW_CAST and PILLOW_SMOOTH override the constants, PILLOW_DEBUG=1 lists the points whose
twin stays too near.
"""
import json
import os
import re
import shutil
import struct
import sys

import numpy as np
from scipy.spatial import cKDTree

DEPTH = float(os.environ.get("PILLOW_DEPTH", "0.2"))
REACH = float(os.environ.get("PILLOW_REACH", "0.6"))
CAST = float(os.environ.get("PILLOW_CAST", "3"))
SMOOTH = int(os.environ.get("PILLOW_SMOOTH", "10"))


def read_foam_list(path):
    text = open(path).read()
    body = text[text.index("}") + 1:] if "FoamFile" in text else text
    m = re.search(r"\n(\d+)\s*\n?\(", body)
    n = int(m.group(1))
    start = m.end()
    return n, body[start:], text[: text.index("}") + 1] if "FoamFile" in text else ""


def read_points(path):
    n, rest, _ = read_foam_list(path)
    nums = re.findall(r"\(([^()]*)\)", rest[: rest.rindex(")")])
    pts = np.array([[float(x) for x in s.split()] for s in nums[:n]])
    assert len(pts) == n
    return pts


def read_faces(path):
    n, rest, _ = read_foam_list(path)
    faces = [[int(x) for x in s.split()] for s in re.findall(r"\d+\(([^()]*)\)", rest)[:n]]
    assert len(faces) == n
    return faces


def read_labels(path):
    n, rest, _ = read_foam_list(path)
    body = rest[: rest.index(")")]
    labels = np.array([int(x) for x in body.split()], dtype=np.int64)
    assert len(labels) == n, (path, len(labels), n)
    return labels


def read_boundary(path):
    text = open(path).read()
    text = text[text.index("}") + 1:]
    patches = []
    for m in re.finditer(r"(\w+)\s*\{([^{}]*)\}", text):
        d = dict(re.findall(r"(\w+)\s+([^;]+);", m.group(2)))
        patches.append((m.group(1), d))
    return patches


def header(cls, obj, note=""):
    return (
        "FoamFile\n{\n    version 2.0;\n    format ascii;\n    class %s;\n%s    location \"constant/polyMesh\";\n"
        "    object %s;\n}\n" % (cls, note, obj)
    )


def write_list(path, cls, obj, items, fmt, note=""):
    with open(path, "w") as f:
        f.write(header(cls, obj, note))
        f.write("%d\n(\n" % len(items))
        f.write("\n".join(fmt(x) for x in items))
        f.write("\n)\n")


def read_stl(path):
    data = open(path, "rb").read()
    n = struct.unpack_from("<I", data, 80)[0]
    rec = np.frombuffer(data, dtype=np.uint8, count=n * 50, offset=84).reshape(n, 50)
    tri = rec[:, 12:48].copy().view("<f4").reshape(n, 3, 3).astype(np.float64)
    return tri


def closest_on_triangles(p, a, b, c):
    """Closest points of the triangles (a, b, c) to the points p, row by row (Ericson's regions)."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = np.einsum("ij,ij->i", ab, ap), np.einsum("ij,ij->i", ac, ap)
    bp = p - b
    d3, d4 = np.einsum("ij,ij->i", ab, bp), np.einsum("ij,ij->i", ac, bp)
    cp = p - c
    d5, d6 = np.einsum("ij,ij->i", ab, cp), np.einsum("ij,ij->i", ac, cp)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        v = vb / denom
        w = vc / denom
        out = a + ab * v[:, None] + ac * w[:, None]
        # Edge regions, then vertex regions (later assignments win).
        t = d1 / (d1 - d3)
        m = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
        out[m] = (a + ab * t[:, None])[m]
        t = d2 / (d2 - d6)
        m = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
        out[m] = (a + ac * t[:, None])[m]
        t = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        m = (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0)
        out[m] = (b + (c - b) * t[:, None])[m]
    m = (d1 <= 0) & (d2 <= 0)
    out[m] = a[m]
    m = (d3 >= 0) & (d4 <= d3)
    out[m] = b[m]
    m = (d6 >= 0) & (d5 <= d6)
    out[m] = c[m]
    return out


def closest_points(tri, pts, k=48):
    """The closest surface point of each point: exact over the k triangles with the nearest centres and
    every triangle within reach of the best found (checked by the bound of each triangle's radius)."""
    cen = tri.mean(axis=1)
    rad = np.max(np.linalg.norm(tri - cen[:, None, :], axis=2), axis=1)
    tree = cKDTree(cen)
    k = min(k, len(tri))
    _, idx = tree.query(pts, k=k)
    best = np.full(len(pts), np.inf)
    out = np.zeros_like(pts)
    for j in range(k):
        t = idx[:, j]
        q = closest_on_triangles(pts, tri[t, 0], tri[t, 1], tri[t, 2])
        d = np.linalg.norm(q - pts, axis=1)
        m = d < best
        best[m], out[m] = d[m], q[m]
    # Any triangle whose centre lies within best + its radius could be nearer.
    rmax = rad.max()
    for i in np.nonzero(best > 0)[0]:
        cand = tree.query_ball_point(pts[i], best[i] + rmax)
        cand = [t for t in cand if np.linalg.norm(cen[t] - pts[i]) - rad[t] < best[i]]
        if len(cand) > k:
            cand = np.array(cand)
            q = closest_on_triangles(np.repeat(pts[i][None], len(cand), 0), tri[cand, 0], tri[cand, 1], tri[cand, 2])
            d = np.linalg.norm(q - pts[i], axis=1)
            j = np.argmin(d)
            if d[j] < best[i]:
                best[i], out[i] = d[j], q[j]
    return out, best


def ray_hits(tri, tree, rmax, pts, dirs, tmax):
    """The first t >= 0 where pts + t dirs meets a triangle, inf when none within tmax (per point;
    Moller-Trumbore over the triangles whose centres lie within rmax of sample points along the ray)."""
    out = np.full(len(pts), np.inf)
    cen_step = 0.5
    for i in range(len(pts)):
        n = max(2, int(np.ceil(tmax[i] / (cen_step * tmax[i] / 6))))
        samples = pts[i] + np.linspace(0, tmax[i], n)[:, None] * dirs[i]
        r = rmax + tmax[i] / n
        cand = sorted({t for l in tree.query_ball_point(samples, r) for t in l})
        if not cand:
            continue
        t3 = tri[cand]
        e1, e2 = t3[:, 1] - t3[:, 0], t3[:, 2] - t3[:, 0]
        pv = np.cross(dirs[i], e2)
        det = np.einsum("ij,ij->i", e1, pv)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            tv = pts[i] - t3[:, 0]
            u = np.einsum("ij,ij->i", tv, pv) * inv
            qv = np.cross(tv, e1)
            v = (qv @ dirs[i]) * inv
            t = np.einsum("ij,ij->i", e2, qv) * inv
        ok = (np.abs(det) > 1e-30) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t >= 0) & (t <= tmax[i])
        if ok.any():
            out[i] = t[ok].min()
    return out


def face_normal_area(pts, f):
    p = pts[f]
    c = p.mean(axis=0)
    a = np.zeros(3)
    for i in range(len(f)):
        a += np.cross(p[i] - c, p[(i + 1) % len(f)] - c)
    return a / 2


def main():
    args = sys.argv[1:]
    patch = None
    if "--patch" in args:
        i = args.index("--patch")
        patch = args[i + 1]
        del args[i : i + 2]
    case, surface, out = args
    pm = os.path.join(case, "constant", "polyMesh")
    pts = read_points(os.path.join(pm, "points"))
    faces = read_faces(os.path.join(pm, "faces"))
    owner = read_labels(os.path.join(pm, "owner"))
    neigh = read_labels(os.path.join(pm, "neighbour"))
    bnd = read_boundary(os.path.join(pm, "boundary"))
    ncells = int(owner.max()) + 1
    nint = len(neigh)
    if patch is None:
        walls = [p for p, d in bnd if d.get("type", "").strip() == "wall"]
        patch = walls[0]
    pd = dict(bnd)[patch]
    ws, wn = int(pd["startFace"]), int(pd["nFaces"])
    wall = list(range(ws, ws + wn))

    # Wall points, their outward normals and sizes.
    # Wall vertices: a point with the fan of wall faces around it joined through wall edges (a point
    # where two fans touch, a pinch, has a vertex per fan and a twin per fan).
    edge_face = {}
    for f in wall:
        fv = faces[f]
        for i in range(len(fv)):
            edge_face[(fv[i], fv[(i + 1) % len(fv)])] = f
    parent = {(v, f): (v, f) for f in wall for v in faces[f]}

    def root(k):
        while parent[k] != k:
            parent[k] = parent[parent[k]]
            k = parent[k]
        return k
    for (a, b), f in edge_face.items():
        g = edge_face.get((b, a))
        if g is None:
            sys.exit("wall edge %d-%d has one wall face: the wall is open" % (a, b))
        for v in (a, b):
            ra, rb = root((v, f)), root((v, g))
            if ra != rb:
                parent[max(ra, rb)] = min(ra, rb)
    roots = sorted({root(k) for k in parent})
    ridx = {r: i for i, r in enumerate(roots)}
    widx = {k: ridx[root(k)] for k in parent}
    wpts = [v for v, _ in roots]
    pinched = np.bincount(wpts)[wpts] > 1
    # The staircase's faces are axis-aligned: a point's distinct normals (at most 3 on a manifold wall).
    dirs = [set() for _ in wpts]
    size = np.full(len(wpts), np.inf)
    for f in wall:
        fa = face_normal_area(pts, faces[f])
        area = np.linalg.norm(fa)
        h = np.sqrt(area)
        axis = tuple(np.rint(fa / area).astype(int))
        for v in faces[f]:
            dirs[widx[(v, f)]].add(axis)
            size[widx[(v, f)]] = min(size[widx[(v, f)]], h)
    dirs = [np.array(sorted(d), dtype=float) for d in dirs]
    normal = np.array([d.sum(axis=0) for d in dirs])
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    p = pts[wpts]
    if surface == "sphere":
        def project(x):
            return x / np.linalg.norm(x, axis=1)[:, None]

        def cast(x, d, tmax):
            # |x + t d| = 1, the root ahead.
            b = np.einsum("ij,ij->i", x, d)
            c = np.einsum("ij,ij->i", x, x) - 1
            disc = b * b - c
            with np.errstate(invalid="ignore"):
                r = np.sqrt(disc)
            t = np.where(-b - r >= 0, -b - r, -b + r)
            return np.where((disc >= 0) & (t >= 0) & (t <= tmax), t, np.inf)
    else:
        tri = read_stl(surface)
        tcen = tri.mean(axis=1)
        trad = np.max(np.linalg.norm(tri - tcen[:, None, :], axis=2), axis=1)
        ttree = cKDTree(tcen)

        def project(x):
            return closest_points(tri, x)[0]

        def cast(x, d, tmax):
            return ray_hits(tri, ttree, trad.max(), x, d, tmax)
    near = project(p)
    before = np.linalg.norm(near - p, axis=1)
    # The target lies ahead of every face of the point: along the mean normal (the closest point of a
    # staircase corner is often beside it, over one of its faces), the closest point where no hit is near.
    t = cast(p, normal, CAST * size)
    s = np.where(np.isfinite(t)[:, None], p + normal * np.where(np.isfinite(t), t, 0)[:, None], near)
    # Where that ray finds nothing near, the nearest hit of rays along the faces' normals and between.
    miss = np.nonzero(~np.isfinite(t))[0]
    if len(miss):
        best = np.full(len(miss), np.inf)
        for k in range(7):
            dk = []
            for i in miss:
                d = dirs[i]
                v = d[k] if k < len(d) else (d[k - 3] + normal[i] if 3 <= k < 3 + len(d) else normal[i])
                dk.append(v / np.linalg.norm(v))
            dk = np.array(dk)
            tk = cast(p[miss], dk, CAST * size[miss])
            better = tk < best
            best[better] = tk[better]
            s[miss[better]] = p[miss[better]] + dk[better] * tk[better, None]

    def margin(x):
        return np.array([np.min(d @ (x[i] - p[i])) for i, d in enumerate(dirs)])
    # The closest points crowd where the staircase meets the surface at a steep angle (a riser's points
    # all go near one point): spread them along the surface by relaxing each to the mean of its wall
    # neighbours, projected back.
    nbr = [[] for _ in wpts]
    for f in wall:
        fv = faces[f]
        for i in range(len(fv)):
            a, b = widx[(fv[i], f)], widx[(fv[(i + 1) % len(fv)], f)]
            nbr[a].append(b)
            nbr[b].append(a)
    nbr_a = np.array([i for i, l in enumerate(nbr) for _ in l])
    nbr_b = np.array([j for l in nbr for j in l])
    deg = np.bincount(nbr_a, minlength=len(wpts))[:, None]
    for _ in range(SMOOTH):
        m = np.zeros_like(s)
        np.add.at(m, nbr_a, s[nbr_b])
        x = project(0.5 * s + 0.5 * m / deg)
        # Kept where the point stays as far ahead of its faces (or DEPTH cells).
        ok = margin(x) >= np.minimum(margin(s), DEPTH * size)
        s[ok] = x[ok]
    # How far s lies beyond p along each of its faces' normals: p moves in along n until it is DEPTH
    # cells beyond every one (each pillow cell then has its outer face in front of its inner one).
    with np.errstate(divide="ignore", invalid="ignore"):
        need = np.array([np.max((DEPTH * size[i] - d @ (s[i] - p[i])) / (d @ normal[i])) for i, d in enumerate(dirs)])
    with np.errstate(divide="ignore", invalid="ignore"):
        shift = np.clip(need, 0.0, REACH * size)
    short = need > REACH * size
    if os.environ.get("PILLOW_DEBUG"):
        opposite = np.array([len(d) > 1 and np.min(d @ d.T) < -0.5 for d in dirs])
        print("short", int(short.sum()), "opposite", int(opposite.sum()), "short&opposite",
              int((short & opposite).sum()), file=sys.stderr)
        print("opposite points", sorted({wpts[i] for i in np.nonzero(opposite)[0]}), file=sys.stderr)
        for i in np.nonzero(short)[0][:10]:
            print(" ", wpts[i], p[i], s[i], dirs[i].tolist(), need[i] / size[i], np.linalg.norm(s[i] - p[i]) / size[i],
                  file=sys.stderr)
    pts = pts.copy()
    # A pinched point stays: its fans would pull it apart.
    shift[pinched] = 0
    pts[wpts] = p - normal * shift[:, None]
    outer = len(pts) + np.arange(len(wpts))
    pts = np.vstack([pts, s])

    # Pillow cells: one per wall face, numbered after the old cells.
    cell_of = {f: ncells + k for k, f in enumerate(wall)}
    internal = [(faces[f], int(owner[f]), int(neigh[f])) for f in range(nint)]
    internal += [(faces[f], int(owner[f]), cell_of[f]) for f in wall]
    for (a, b), f in edge_face.items():
        g = edge_face[(b, a)]
        if cell_of[f] < cell_of[g]:
            tw = [int(outer[widx[(v, f)]]) for v in (a, b)]
            internal.append(([a, b, tw[1], tw[0]], cell_of[f], cell_of[g]))
    internal.sort(key=lambda t: (t[1], t[2]))
    new_faces = [t[0] for t in internal]
    new_owner = [t[1] for t in internal]
    new_neigh = [t[2] for t in internal]
    patches = []
    for name, d in bnd:
        st, n = int(d["startFace"]), int(d["nFaces"])
        start = len(new_faces)
        for f in range(st, st + n):
            if name == patch:
                new_faces.append([int(outer[widx[(v, f)]]) for v in faces[f]])
                new_owner.append(cell_of[f])
            else:
                new_faces.append(faces[f])
                new_owner.append(int(owner[f]))
        patches.append((name, d, start, n))

    opm = os.path.join(out, "constant", "polyMesh")
    if os.path.exists(out):
        shutil.rmtree(out)
    os.makedirs(opm)
    shutil.copytree(os.path.join(case, "system"), os.path.join(out, "system"))
    nc = ncells + len(wall)
    note = '    note "nPoints:%d nCells:%d nFaces:%d nInternalFaces:%d";\n' % (
        len(pts), nc, len(new_faces), len(new_neigh))
    write_list(os.path.join(opm, "points"), "vectorField", "points", pts,
               lambda x: "(%.17g %.17g %.17g)" % tuple(x))
    write_list(os.path.join(opm, "faces"), "faceList", "faces", new_faces,
               lambda f: "%d(%s)" % (len(f), " ".join(map(str, f))))
    write_list(os.path.join(opm, "owner"), "labelList", "owner", new_owner, str, note)
    write_list(os.path.join(opm, "neighbour"), "labelList", "neighbour", new_neigh, str, note)
    with open(os.path.join(opm, "boundary"), "w") as f:
        f.write(header("polyBoundaryMesh", "boundary"))
        f.write("%d\n(\n" % len(patches))
        for name, d, start, n in patches:
            f.write("    %s\n    {\n        type %s;\n" % (name, d["type"].strip()))
            if "inGroups" in d:
                f.write("        inGroups %s;\n" % d["inGroups"].strip())
            f.write("        nFaces %d;\n        startFace %d;\n    }\n" % (n, start))
        f.write(")\n")
    print(json.dumps({
        "cells": nc, "pillow_cells": len(wall), "wall_points": len(set(wpts)), "pinched_points": int(len(set(np.array(wpts)[pinched]))),
        "before_max_distance": float(before.max()),
        "moved_in_max_cells": float((shift / size).max()),
        "moved_in_points": int((shift > 0).sum()),
    }))


if __name__ == "__main__":
    main()
