#!/usr/bin/env python3
"""Volume of the solid mesh against the volume the surface encloses.

For each surface and level, runs `octmesh mesh SURFACE --level L --keep
inside` (cut rule center, corner balance) and compares the kept volume with
the surface's own volume (divergence theorem on its triangles). Prints a
markdown table.

    python3 tools/bench/volume_convergence.py [--cases sphere:4-9,dragon:5-10]
        [--np 2]

Standard library only.
"""

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
OCTMESH = ROOT / "target" / "release" / "octmesh"
DATA = ROOT.parent / "shared" / "data"
WORK = ROOT / "target" / "bench"
DEFAULT = "sphere:4-9,torus:4-9,bunny:5-10,dragon:5-10"


def surface_arg(name):
    if name in ("sphere", "torus"):
        return name
    p = DATA / f"{name}.stl"
    return str(p) if p.is_file() else None


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=DEFAULT)
    ap.add_argument("--np", type=int, default=2)
    a = ap.parse_args()
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMPI_MCA_rmaps_base_oversubscribe="1")
    WORK.mkdir(parents=True, exist_ok=True)
    print("| surface | level | solid elements | solid volume | enclosed volume | relative error |")
    print("|---|---:|---:|---:|---:|---:|")
    for case in a.cases.split(","):
        name, levels = case.split(":")
        lo, hi = (int(x) for x in levels.split("-"))
        surf = surface_arg(name)
        if surf is None:
            print(f"SKIP {name}: not in {DATA}", file=sys.stderr)
            continue
        for level in range(lo, hi + 1):
            stats = WORK / f"volume_{name}_{level}.json"
            cmd = ["mpirun", "--oversubscribe", "-np", str(a.np), str(OCTMESH), "mesh", surf,
                   "--level", str(level), "--keep", "inside", "--quiet", "--stats", str(stats)]
            r = subprocess.run(cmd, env=env, capture_output=True, text=True)
            if r.returncode != 0:
                sys.exit(f"failed: {' '.join(cmd)}\n{r.stderr}")
            s = json.loads(stats.read_text())
            v, want = s["kept_volume"], s["surface_volume"]
            print(f"| {name} | {level} | {s['elements']:,} | {v:.6g} | {want:.6g} | "
                  f"{(v - want) / want:+.2e} |", flush=True)


if __name__ == "__main__":
    main()
