#!/usr/bin/python3
"""The wall layer (`--wall-layer`) on the shared models: checkMesh's verdict and figures, and how far the
written wall points lie from the surface, measured here from the STL (the built-in sphere: from the exact
unit sphere, which its triangles are inscribed in).

    tools/bench/wall_layer.py [--np 2] [--level 6] [--models sphere,bunny,...] [--keep outside,inside]
                              [--layers N --expansion R --first F]

With --layers: N boundary layers (`--layers N --layer-expansion R --first-layer F*size`, size the model's
largest extent) and the coverage measured from the written polyMesh: the wall area whose faces lead through N
cells (each entered through the face opposite the last, sharing no point with it) whose heights (distances
between the faces' point means) are the first layer's within [0.5, 1] and grow by R within 1 %; the seconds of
the layer step (the wall layer's points and cells) beside the OpenFOAM writer's, from --stats.

Prints a Markdown table. Each case is written in ASCII to target/bench/wall_layer/MODEL-KEEP and checked by
`checkMesh` (`-parallel` on several ranks) with OpenFOAM's environment from /usr/share/openfoam/etc/bashrc.
"""
import argparse
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import pillow_foam as pf  # noqa: E402
from benchlib import DATA, OCTMESH, ROOT, mpi_env  # noqa: E402

MODELS = ["sphere", "bunny", "armadillo", "fandisk", "flange", "tangaroa"]
RC = "/usr/share/openfoam/etc/bashrc"


def wall_points(case):
    """The positions of the points of every wall face of every mesh of the case."""
    dirs = sorted(case.glob("processor*/constant/polyMesh")) or [case / "constant" / "polyMesh"]
    out = []
    for d in dirs:
        pts = pf.read_points(d / "points")
        faces = pf.read_faces(d / "faces")
        used = set()
        for _, p in pf.read_boundary(d / "boundary"):
            if p.get("type", "").strip() == "wall":
                s, n = int(p["startFace"]), int(p["nFaces"])
                for f in faces[s:s + n]:
                    used.update(f)
        out.append(pts[sorted(used)])
    return np.unique(np.vstack(out), axis=0)


def distances(model, pts):
    if model == "sphere":
        return np.abs(np.linalg.norm(pts, axis=1) - 1.0)
    tri = pf.read_stl(DATA / (model + ".stl"))
    d = pf.closest_points(tri, pts)[1]
    # The tree search of pillow_foam can miss the nearest triangle: the points it puts off the surface are
    # measured again against every triangle.
    for i in np.nonzero(d > 1e-12)[0]:
        p = np.repeat(pts[i][None], len(tri), 0)
        d[i] = np.linalg.norm(pf.closest_on_triangles(p, tri[:, 0], tri[:, 1], tri[:, 2]) - p, axis=1).min()
    return d


def coverage(case, n, first, r):
    """The wall area fraction whose faces carry n layer cells of the asked heights (see the module)."""
    dirs = sorted(case.glob("processor*/constant/polyMesh")) or [case / "constant" / "polyMesh"]
    total = covered = 0.0
    for d in dirs:
        pts = pf.read_points(d / "points")
        faces = pf.read_faces(d / "faces")
        own = pf.read_labels(d / "owner")
        nei = pf.read_labels(d / "neighbour")
        cells = [[] for _ in range(int(max(own)) + 1)]
        for f, c in enumerate(own):
            cells[c].append(f)
        for f, c in enumerate(nei):
            cells[c].append(f)
        for _, p in pf.read_boundary(d / "boundary"):
            if p.get("type", "").strip() != "wall":
                continue
            s, m = int(p["startFace"]), int(p["nFaces"])
            for f in range(s, s + m):
                cur, c, hs = f, own[f], []
                for _ in range(n):
                    here = set(faces[cur])
                    opp = [g for g in cells[c] if g != cur and not here & set(faces[g])]
                    if len(opp) != 1:
                        break
                    g = opp[0]
                    hs.append(float(np.linalg.norm(pts[faces[g]].mean(0) - pts[faces[cur]].mean(0))))
                    if g >= len(nei):
                        break
                    c = nei[g] if own[g] == c else own[g]
                    cur = g
                a = polygon_area(pts[faces[f]])
                total += a
                ok = len(hs) == n and 0.5 * first <= hs[0] <= first * (1 + 1e-6) and all(
                    abs(hs[k + 1] / hs[k] / r - 1) < 0.01 for k in range(n - 1))
                covered += a if ok else 0.0
    return covered / total


def polygon_area(p):
    c = p.mean(0)
    return 0.5 * float(np.linalg.norm(sum(np.cross(p[i] - c, p[(i + 1) % len(p)] - c) for i in range(len(p)))))


def checkmesh(case, np_, extra=""):
    par = "mpirun -np %d checkMesh -parallel %s" % (np_, extra) if np_ > 1 else "checkMesh " + extra
    script = "set +u; source %s >/dev/null 2>&1; cd '%s' && %s" % (RC, case, par)
    return subprocess.run(["bash", "-c", script], env=mpi_env(), capture_output=True, text=True).stdout


def figure(pattern, text):
    m = re.search(pattern, text)
    return float(m.group(1)) if m else float("nan")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--np", type=int, default=2)
    ap.add_argument("--level", type=int, default=6)
    ap.add_argument("--models", default=",".join(MODELS))
    ap.add_argument("--keep", default="outside,inside")
    ap.add_argument("--tol", type=float, default=1e-6, help="relative to the model's size")
    ap.add_argument("--layers", type=int, default=0)
    ap.add_argument("--expansion", type=float, default=1.2)
    ap.add_argument("--first", type=float, default=5e-4, help="the first layer, relative to the model's size")
    a = ap.parse_args()
    work = ROOT / "target" / "bench" / "wall_layer"
    work.mkdir(parents=True, exist_ok=True)
    if a.layers:
        return layers_table(a, work)
    print("| model | keep | cells | wall points | on the surface (within %.0e of the size) | largest distance / size "
          "| max non-orthogonality | max skewness | checkMesh |" % a.tol)
    print("|:---|:---|---:|---:|---:|---:|---:|---:|:---|")
    for model in a.models.split(","):
        surface = model if model == "sphere" else str(DATA / (model + ".stl"))
        for keep in a.keep.split(","):
            case = work / ("%s-%s" % (model, keep))
            # A serial run after a parallel one would leave the old processor folders, which the readers prefer.
            shutil.rmtree(case, ignore_errors=True)
            cmd = ["mpirun", "-np", str(a.np)] if a.np > 1 else []
            cmd += [str(OCTMESH), "mesh", surface, "--level", str(a.level), "--keep", keep, "--cut-rule", "none",
                    "--wall-layer", "--openfoam", str(case), "--openfoam-format", "ascii", "--overwrite", "--quiet"]
            p = subprocess.run(cmd, env=mpi_env(), capture_output=True, text=True)
            if p.returncode != 0:
                print("| %s | %s | failed: %s |" % (model, keep, (p.stderr or p.stdout).strip().splitlines()[-1]))
                continue
            text = checkmesh(case, a.np)
            pts = wall_points(case)
            lo, hi = pts.min(axis=0), pts.max(axis=0)
            size = float(np.max(hi - lo))
            d = distances(model, pts)
            on = int(np.sum(d <= a.tol * size))
            verdict = "Mesh OK" if "Mesh OK." in text else "failed: " + "; ".join(
                s.strip(" *") for s in re.findall(r"\*\*\*[^\n]*", text))
            print("| %s | %s | %d | %d | %d | %.1e | %.2f | %.3f | %s |" % (
                model, keep, figure(r"cells:\s+(\d+)", text), len(pts), on, float(d.max()) / size,
                figure(r"non-orthogonality Max: ([\d.eE+-]+)", text), figure(r"Max skewness = ([\d.eE+-]+)", text),
                verdict), flush=True)


def model_size(model):
    if model == "sphere":
        return 2.0
    tri = pf.read_stl(DATA / (model + ".stl")).reshape(-1, 3)
    return float(np.max(tri.max(0) - tri.min(0)))


def layers_table(a, work):
    print("| model | keep | cells | first layer | checkMesh | max non-orthogonality | max skewness | coverage "
          "(polyMesh) | coverage (octmesh) | layer step s | writer s |")
    print("|:---|:---|---:|---:|:---|---:|---:|---:|---:|---:|---:|")
    for model in a.models.split(","):
        surface = model if model == "sphere" else str(DATA / (model + ".stl"))
        first = a.first * model_size(model)
        for keep in a.keep.split(","):
            case = work / ("%s-%s-layers" % (model, keep))
            stats = work / ("%s-%s-layers.json" % (model, keep))
            shutil.rmtree(case, ignore_errors=True)
            cmd = ["mpirun", "-np", str(a.np)] if a.np > 1 else []
            cmd += [str(OCTMESH), "mesh", surface, "--level", str(a.level), "--keep", keep, "--cut-rule", "none",
                    "--layers", str(a.layers), "--layer-expansion", str(a.expansion), "--first-layer", repr(first),
                    "--openfoam", str(case), "--openfoam-format", "ascii", "--overwrite", "--quiet",
                    "--stats", str(stats)]
            p = subprocess.run(cmd, env=mpi_env(), capture_output=True, text=True)
            if p.returncode != 0:
                print("| %s | %s | failed: %s |" % (model, keep, (p.stderr or p.stdout).strip().splitlines()[-1]))
                continue
            text = checkmesh(case, a.np)
            st = json.loads(stats.read_text())
            rep = st["layers"]["patches"]
            own = sum(x["coverage"] * x["faces"] for x in rep) / max(1, sum(x["faces"] for x in rep))
            verdict = "Mesh OK" if "Mesh OK." in text else "failed: " + "; ".join(
                s.strip(" *") for s in re.findall(r"\*\*\*[^\n]*", text))
            print("| %s | %s | %d | %.2e | %s | %.2f | %.3f | %.2f %% | %.2f %% | %.3f | %.3f |" % (
                model, keep, figure(r"cells:\s+(\d+)", text), first, verdict,
                figure(r"non-orthogonality Max: ([\d.eE+-]+)", text), figure(r"Max skewness = ([\d.eE+-]+)", text),
                100 * coverage(case, a.layers, first, a.expansion), 100 * own, st["layers"]["seconds"],
                st["timings"]["openfoam"]), flush=True)


if __name__ == "__main__":
    main()
