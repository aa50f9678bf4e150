#!/usr/bin/env python3
"""What a distance band costs against the plain surface refinement (issue 21).

The same surface and level twice, one run after the other and repeated: the plain surface
refinement (phases 'construct' + 'refine' of --stats) and the same command with one distance
band of one cell at that level on top (phase 'regions'). Balance is left out (--balance none)
so that only the refinement is measured. The issue's budget: the band costs at most twice the
plain refinement (the Dragon at level 10). One rank (under mpirun -np 1, as the other tools).

    python3 tools/bench/band_cost.py --surface dragon --level 10 --pairs 10
"""

import argparse
import sys

import benchlib as bl


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--surface", default="dragon", help="model name or built-in (default dragon)")
    ap.add_argument("--level", type=int, default=10)
    ap.add_argument("--pairs", type=int, default=10, help="alternating plain/band pairs")
    ap.add_argument("--distance", type=float,
                    help="band width in model units (default: one cell at the level)")
    started = bl.start_on_surface(ap, "distance band against surface refinement")
    if started is None:
        return 0
    args, env, surface, info = started
    base = ["octree", surface, "--level", str(args.level), "--balance", "none"]
    bl.WORK.mkdir(parents=True, exist_ok=True)
    cell = args.distance
    if cell is None:
        # One cell at the level: the domain's side (the default fit) over 2^level.
        stats = bl.octmesh_stats(1, base, bl.WORK / "band_plain.json", env)
        cell = stats["domain_side"] / 2 ** args.level
    band = base + ["--distance", "%r:%d" % (cell, args.level)]
    print("  band: --distance %r:%d" % (cell, args.level), flush=True)
    rows = []
    for i in range(args.pairs):
        p = bl.octmesh_stats(1, base, bl.WORK / "band_plain.json", env)["timings"]
        b = bl.octmesh_stats(1, band, bl.WORK / "band_band.json", env)["timings"]
        plain = p["construct"] + p["refine"]
        rows.append((plain, b["regions"], b["regions"] / plain))
        print("  pair %2d: plain %.4f s  band %.4f s  ratio %.3f" % ((i + 1,) + rows[-1]), flush=True)
    ratios = [r[2] for r in rows]
    print("median plain %.4f s, band %.4f s, ratio %.3f (%.3f-%.3f; budget 2)"
          % (bl.median([r[0] for r in rows]), bl.median([r[1] for r in rows]),
             bl.median(ratios), min(ratios), max(ratios)))
    print(bl.header_line(info))
    return 0


if __name__ == "__main__":
    sys.exit(main())
