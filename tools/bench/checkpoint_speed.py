#!/usr/bin/env python3
"""Octree checkpoints saved and loaded against the disk's speed (issue 59).

One run per repeat: `octmesh octree SURFACE --level L --fit 1 --save FILE` to a new file and
again over it (phase 'save' of --stats: the block checksums, the open, the ranks' positioned
writes and the close, which does not sync), then `dd` writing as many bytes to the same file
system through the page cache without a sync to a new file and over it (conv=notrunc), the
same to compare with, and straight to the device (oflag=direct) and through the page cache
with a final fdatasync, the disk's speed; then `octmesh octree SURFACE --fit 1 --load FILE`
(phase 'load': the reads, the checksums, the octree's checks) against `dd` reading the file
(iflag=direct, and through the page cache). Before each read the page cache is dropped when the
host allows it (`/proc/sys/vm/drop_caches`); the output says whether it did (if not, the load
reads from the cache, and compares with the cached `dd`).

    python3 tools/bench/checkpoint_speed.py --surface armadillo --level 11 --np 2 --repeat 3
"""

import argparse
import re
import subprocess
import sys
import time

import benchlib as bl


def dd(args, nbytes):
    """Bytes per second dd reports for `args` (whole MiB of nbytes)."""
    count = max(1, nbytes >> 20)
    r = subprocess.run(["dd", "bs=1M", "count=%d" % count] + args,
                       capture_output=True, text=True, check=True)
    m = re.search(r"copied, ([0-9.]+) s", r.stderr)
    return (count << 20) / float(m.group(1)) if m else float("nan")


def settle():
    subprocess.run(["sync"], check=True)
    time.sleep(2)


def drop_caches():
    """Empties the page cache; False when the host does not allow it."""
    settle()
    try:
        with open("/proc/sys/vm/drop_caches", "w") as f:
            f.write("3\n")
        return True
    except OSError:
        return False


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--surface", default="armadillo", help="model name or built-in")
    ap.add_argument("--level", type=int, default=11)
    ap.add_argument("--np", type=int, nargs="+", default=[2])
    ap.add_argument("--repeat", type=int, default=3)
    started = bl.start_on_surface(ap, "octree checkpoints against dd")
    if started is None:
        return 0
    args, env, surface, info = started
    bl.WORK.mkdir(parents=True, exist_ok=True)
    ckpt = bl.WORK / "speed.ckpt"
    scratch = bl.WORK / "speed_dd"
    for np_ in args.np:
        for i in range(args.repeat):
            saves = []
            for fresh in (True, False):
                if fresh and ckpt.exists():
                    ckpt.unlink()
                settle()
                s = bl.octmesh_stats(np_, ["octree", surface, "--level", str(args.level), "--fit",
                                           "1", "--save", str(ckpt)], bl.WORK / "save.json", env)
                saves.append(s["timings"]["save"])
            nbytes = ckpt.stat().st_size
            settle()
            c_new = dd(["if=/dev/zero", "of=%s" % scratch], nbytes)
            c_over = dd(["if=/dev/zero", "of=%s" % scratch, "conv=notrunc"], nbytes)
            scratch.unlink()
            settle()
            w_direct = dd(["if=/dev/zero", "of=%s" % scratch, "oflag=direct"], nbytes)
            scratch.unlink()
            settle()
            w_synced = dd(["if=/dev/zero", "of=%s" % scratch, "conv=fdatasync"], nbytes)
            dropped = drop_caches()
            r_direct = dd(["if=%s" % scratch, "of=/dev/null", "iflag=direct"], nbytes)
            drop_caches()
            r_cached = dd(["if=%s" % scratch, "of=/dev/null"], nbytes)
            scratch.unlink()
            drop_caches()
            s = bl.octmesh_stats(np_, ["octree", surface, "--fit", "1", "--load", str(ckpt)],
                                 bl.WORK / "load.json", env)
            t_load = s["timings"]["load"]
            print("  np %d run %d: %s octants, %.3f GB; save to a new file %.3f s = %.0f MB/s, over "
                  "it %.3f s = %.0f MB/s (dd through the cache, no sync: new file %.0f, over it %.0f; "
                  "dd direct %.0f, dd fdatasync %.0f MB/s); load %.3f s = %.0f MB/s (dd direct %.0f, "
                  "dd cached %.0f MB/s); caches dropped: %s"
                  % (np_, i + 1, bl.fmt_int(s["octants_balanced"]), nbytes / 1e9, saves[0],
                     nbytes / saves[0] / 1e6, saves[1], nbytes / saves[1] / 1e6, c_new / 1e6,
                     c_over / 1e6, w_direct / 1e6, w_synced / 1e6, t_load, nbytes / t_load / 1e6,
                     r_direct / 1e6, r_cached / 1e6, "yes" if dropped else "no"), flush=True)
    ckpt.unlink()
    print(bl.header_line(info))
    return 0


if __name__ == "__main__":
    sys.exit(main())
