#!/usr/bin/python3
"""The wall layer (`--wall-layer`) on the shared models: checkMesh's verdict and figures, and how far the
written wall points lie from the surface, measured here from the STL (the built-in sphere: from the exact
unit sphere, which its triangles are inscribed in).

    tools/bench/wall_layer.py [--np 2] [--level 6] [--models sphere,bunny,...] [--keep outside,inside]

Prints a Markdown table. Each case is written in ASCII to target/bench/wall_layer/MODEL-KEEP and checked by
`checkMesh` (`-parallel` on several ranks) with OpenFOAM's environment from /usr/share/openfoam/etc/bashrc.
"""
import argparse
import os
import re
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
    a = ap.parse_args()
    work = ROOT / "target" / "bench" / "wall_layer"
    work.mkdir(parents=True, exist_ok=True)
    print("| model | keep | cells | wall points | on the surface (within %.0e of the size) | largest distance / size "
          "| max non-orthogonality | max skewness | checkMesh |" % a.tol)
    print("|:---|:---|---:|---:|---:|---:|---:|---:|:---|")
    for model in a.models.split(","):
        surface = model if model == "sphere" else str(DATA / (model + ".stl"))
        for keep in a.keep.split(","):
            case = work / ("%s-%s" % (model, keep))
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


if __name__ == "__main__":
    main()
