#!/usr/bin/env python3
"""Reading an STL file on 1 and more ranks, page cache warm and cold.

  python3 tools/bench/read_split.py ../shared/data/dragon.stl --np 1,2 --repeat 5

For each round and rank count (alternating), two runs of the release build:
`octmesh check FILE`, whose `read` is the file read and the exchange
of the triangles (rank 0's time, the last to finish the exchange), and
`octmesh octree FILE --level 5 --stats`, whose `read` phase (the maximum
over ranks) adds the surface's diagnostics and bounding-box tree, made on
every rank. "cold" runs first drop the file from the page cache
(posix_fadvise DONTNEED on the file alone). `--base BIN` alternates every
run with another build (an earlier commit's `octmesh`). Prints medians and
ranges.
"""

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BIN = os.path.join(ROOT, "target", "release", "octmesh")


def drop(path):
    fd = os.open(path, os.O_RDONLY)
    os.posix_fadvise(fd, 0, 0, os.POSIX_FADV_DONTNEED)
    os.close(fd)


def run(bin_, np_, args):
    cmd = ([bin_] if np_ == 1 else ["mpirun", "--oversubscribe", "-np", str(np_), bin_]) + args
    out = subprocess.run(cmd, capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed:\n{out.stdout}\n{out.stderr}")
    return out.stdout


def check_read(bin_, np_, path, _stats):
    m = re.search(r"read ([0-9.]+) s", run(bin_, np_, ["check", path]))
    return float(m.group(1))


def phase_read(bin_, np_, path, stats):
    run(bin_, np_, ["octree", path, "--level", "5", "--stats", stats, "--quiet"])
    with open(stats) as f:
        return json.load(f)["timings"]["read"]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("file")
    ap.add_argument("--np", default="1,2")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--base", help="another octmesh build to alternate with")
    args = ap.parse_args()
    bins = [("this", BIN)] + ([("base", args.base)] if args.base else [])
    nps = [int(x) for x in args.np.split(",")]
    stats = os.path.join(tempfile.mkdtemp(), "stats.json")
    got = {}
    for _ in range(args.repeat):
        for cache in ("warm", "cold"):
            for np_ in nps:
                for what, f in (("check read", check_read), ("read phase", phase_read)):
                    for label, bin_ in bins:
                        if cache == "cold":
                            drop(args.file)
                        t = f(bin_, np_, args.file, stats)
                        got.setdefault((what, label, cache, np_), []).append(t)
    heads = " | ".join(f"{n} rank{'s' if n > 1 else ''}" for n in nps)
    print(f"| measure | build | cache | {heads} |")
    print("|:---|:---|:---|" + "---:|" * len(nps))
    for what in ("check read", "read phase"):
        for label, _ in bins:
            for cache in ("warm", "cold"):
                cells = []
                for n in nps:
                    v = got[(what, label, cache, n)]
                    cells.append(f"{statistics.median(v):.3f} ({min(v):.3f}-{max(v):.3f})")
                print(f"| {what} | {label} | {cache} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
