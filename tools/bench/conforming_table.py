#!/usr/bin/env python3
"""The conforming meshes of the shared models: elements of the hanging-node mesh, hexahedra of the conforming
mesh, their ratio, the least scaled Jacobian (Knupp's, from the written .msh alone) and the time of the
`conforming` phase, as a Markdown table.

    python3 tools/bench/conforming_table.py [--cases sphere:5,bunny:6,...] [--keep inside] [--np 1]
"""

import argparse
import re
import subprocess
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import benchlib  # noqa: E402

DEFAULT = "sphere:5,bunny:5,bunny:6,armadillo:6,fandisk:6,flange:6,tangaroa:6"


def read_hexes(path):
    """Node coordinates and hexahedra (Gmsh order, which is VTK's) of an ASCII MSH 4.1 file."""
    lines = Path(path).read_text().split("\n")
    i = lines.index("$Nodes") + 1
    blocks = int(lines[i].split()[0])
    i += 1
    tags, coords = [], []
    for _ in range(blocks):
        n = int(lines[i].split()[3])
        i += 1
        tags.extend(int(t) for t in lines[i:i + n])
        coords.extend([float(x) for x in line.split()] for line in lines[i + n:i + 2 * n])
        i += 2 * n
    index = {t: k for k, t in enumerate(tags)}
    xyz = np.array(coords)
    i = lines.index("$Elements") + 1
    blocks = int(lines[i].split()[0])
    i += 1
    hexes = []
    for _ in range(blocks):
        dim, _, kind, n = (int(x) for x in lines[i].split())
        i += 1
        if kind == 5:
            hexes.extend([index[int(t)] for t in line.split()[1:]] for line in lines[i:i + n])
        i += n
    return xyz, np.array(hexes)


# Each corner's three neighbours in VTK order, right-handed.
CORNERS = [(0, 1, 3, 4), (1, 2, 0, 5), (2, 3, 1, 6), (3, 0, 2, 7),
           (4, 7, 5, 0), (5, 4, 6, 1), (6, 5, 7, 2), (7, 6, 4, 3)]


def least_scaled_jacobian(xyz, hexes):
    p = xyz[hexes]
    worst = np.inf
    for c, a, b, d in CORNERS:
        e = [p[:, k] - p[:, c] for k in (a, b, d)]
        e = [v / np.linalg.norm(v, axis=1)[:, None] for v in e]
        det = np.einsum("ij,ij->i", e[0], np.cross(e[1], e[2]))
        worst = min(worst, det.min())
    return worst


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", default=DEFAULT)
    ap.add_argument("--keep", default="inside")
    ap.add_argument("--np", type=int, default=1)
    args = ap.parse_args()
    out = benchlib.WORK / "conforming"
    out.mkdir(parents=True, exist_ok=True)
    print("| model | level | keep | elements | conforming hexahedra | ratio | least scaled Jacobian | conforming [s] |")
    print("|---|---:|---|---:|---:|---:|---:|---:|")
    for case in args.cases.split(","):
        name, level = case.split(":")
        model = name if name in benchlib.BUILTIN else str(benchlib.DATA / f"{name}.stl")
        msh = out / f"{name}{level}.msh"
        cmd = ["mpirun", "-np", str(args.np), str(benchlib.OCTMESH), "mesh", model, "--level", level,
               "--keep", args.keep, "--conforming", "--gmsh", str(msh)]
        text = subprocess.run(cmd, env=benchlib.mpi_env(), capture_output=True, text=True, check=True).stdout
        elements = int(re.search(r"elements (\d+) \|", text).group(1))
        m = re.search(r"^\s+conforming\s+([0-9.]+)\s+(\d+)", text, re.M)
        seconds, hexes = float(m.group(1)), int(m.group(2))
        xyz, h = read_hexes(msh)
        assert len(h) == hexes
        sj = least_scaled_jacobian(xyz, h)
        print(f"| {name} | {level} | {args.keep} | {elements:,} | {hexes:,} | {hexes / elements:.2f} | {sj:.3f} | "
              f"{seconds:.3f} |")


if __name__ == "__main__":
    main()
