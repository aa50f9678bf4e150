#!/usr/bin/env python3
"""The binary OpenFOAM case written against the disk's write speed (issue 19).

One case written by octmesh (phase 'openfoam' of --stats: the face polygons, the point positions
and every file of the case) and, right after each run, `dd` writing as many bytes to the same
file system in two ways: straight to the device (oflag=direct, what the device takes) and
through the page cache with a final fdatasync (conv=fdatasync, what an ordinary program gets to
the disk). Each write starts after `sync` and a pause, so none inherits the other's cached pages.

    python3 tools/bench/writer_speed.py --surface sphere --level 11 --np 1 2 --repeat 3

With --bind-to-none a lone rank may use the node's other core (the writer makes polygons on a
second thread when it has one).
"""

import argparse
import re
import shutil
import subprocess
import sys
import time

import benchlib as bl


def dir_bytes(path):
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file())


def dd(out, nbytes, flag):
    """Seconds dd takes to write nbytes (whole MiB) to `out`."""
    count = max(1, nbytes >> 20)
    r = subprocess.run(["dd", "if=/dev/zero", "of=%s" % out, "bs=1M", "count=%d" % count, flag],
                       capture_output=True, text=True, check=True)
    out.unlink()
    m = re.search(r"copied, ([0-9.]+) s", r.stderr)
    return (count << 20) / float(m.group(1)) if m else float("nan")


def settle():
    subprocess.run(["sync"], check=True)
    time.sleep(2)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--surface", default="sphere", help="model name or built-in (default sphere)")
    ap.add_argument("--level", type=int, default=11)
    ap.add_argument("--keep", default="inside")
    ap.add_argument("--np", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--bind-to-none", action="store_true",
                    help="run octmesh under `mpirun --bind-to none`: Open MPI binds each rank to one "
                         "core when there are at most two ranks, which leaves a lone rank no spare "
                         "core for the writer's second thread")
    started = bl.start_on_surface(ap, "OpenFOAM case against dd")
    if started is None:
        return 0
    args, env, surface, info = started
    bl.WORK.mkdir(parents=True, exist_ok=True)
    case = bl.WORK / "writer_case"
    scratch = bl.WORK / "writer_dd"
    for np_ in args.np:
        rows = []
        for i in range(args.repeat):
            shutil.rmtree(case, ignore_errors=True)
            settle()
            s = bl.octmesh_stats(np_, ["mesh", surface, "--level", str(args.level), "--keep",
                                       args.keep, "--openfoam", str(case)],
                                 bl.WORK / "writer.json", env,
                                 ["--bind-to", "none"] if args.bind_to_none else [])
            nbytes = dir_bytes(case)
            shutil.rmtree(case, ignore_errors=True)
            settle()
            direct = dd(scratch, nbytes, "oflag=direct")
            settle()
            synced = dd(scratch, nbytes, "conv=fdatasync")
            ours = nbytes / s["timings"]["openfoam"]
            rows.append((ours, direct, synced))
            print("  np %d run %d: %.2f GB in %.2f s: %.0f MB/s; dd direct %.0f MB/s, "
                  "dd fdatasync %.0f MB/s; ratio to direct %.2f"
                  % (np_, i + 1, nbytes / 1e9, s["timings"]["openfoam"], ours / 1e6,
                     direct / 1e6, synced / 1e6, ours / direct), flush=True)
        med = [bl.median([r[k] for r in rows]) for k in range(3)]
        print("np %d median: octmesh %.0f MB/s, dd direct %.0f MB/s, dd fdatasync %.0f MB/s"
              % ((np_,) + tuple(m / 1e6 for m in med)))
    print(bl.header_line(info))
    return 0


if __name__ == "__main__":
    sys.exit(main())
