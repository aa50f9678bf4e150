#!/usr/bin/env python3
"""One adaptive cycle of the moving-sphere loop, octmesh against p4est (issue 23).

Both programs grow the same octree with the same warm-up (not timed) and then
time one cycle, each phase between barriers, maximum over ranks:

  octmesh (tools/bench/adapt_cycle_octmesh.c, the C API):
    adapt      octmesh_octree_adapt_ext (or, with --split, a second octmesh
               run timing _refine_once_ext and _coarsen_ext separately)
    balance    octmesh_octree_balance_ext (corner)
    partition  octmesh_octree_partition_for_coarsening (data moves along)
    mesh       octmesh_mesh_build (keep all): ghost, nodes with hanging
               constraints, numbering, connectivity
  p4est 2.2 (tools/p4est_ref/p4est_adapt_cycle.c):
    refine + coarsen   p8est_refine_ext, p8est_coarsen_ext (replace_fn)
    balance            p8est_balance_ext (corner, replace_fn)
    partition          p8est_partition_ext (for coarsening; data moves along)
    ghost + lnodes     p8est_ghost_new (corner), p8est_lnodes_new (degree 1)

16 bytes of data per leaf in both (a double copied on splits and averaged on
coarsening, the level). The geometry is the oracle's
(tools/p4est_ref/octmesh_p4est_adapt.c): a sphere of radius 1/4 whose centre
moves along x; leaves its surface cuts are refined up to the maximum level,
families it does not cut are coarsened. The oracle moves the centre 20972
lattice units per step for a maximum level of 5 (1.28 finest cells); here the
step is scaled to the same 1.28 finest cells by default (--dx), so that the
fine shell follows the sphere as in a CFL-limited simulation. The warm-up is a
uniform octree at --level and --warmup steps of the loop; the cycle is the
next step. With the centre at mid-height (the oracle's; --z) the octree is
symmetric about the plane z = 1/2, where two ranks split it, so the partition
on 2 ranks moves nothing; a centre off the middle makes it move leaves and
their data.

The script runs both programs --rounds times per rank count, alternating
which goes first, and prints medians (and the range), the ratio octmesh / p4est
(bar: at most 0.5), the peak RSS per rank during the cycle (VmHWM reset just before it) and
before it, and the leaf counts. It fails unless both codes have the same
leaves before and after the cycle, the same leaves per rank, the same
independent node count (octmesh's against p8est_lnodes') and the same
integral of the data, in every run.

    python3 tools/bench/adapt_cycle.py                       # 1 and 2 ranks, 3 rounds
    python3 tools/bench/adapt_cycle.py --max-level 9 --rounds 1   # quick check
    python3 tools/bench/adapt_cycle.py --markdown target/bench/adapt_cycle.md
    python3 tools/bench/adapt_cycle.py --from-json a.json b.json --markdown table.md

Standard library only.
"""

import argparse
import json
import shutil
import sys
from pathlib import Path

sys.dont_write_bytecode = True  # keep tools/bench free of __pycache__
sys.path.insert(0, str(Path(__file__).resolve().parent))
from benchlib import (  # noqa: E402
    MIB, ROOT, WORK, RunError, fmt_int, fmt_s, header_line, machine_info, markdown_table,
    median, mpi_env, mpirun, parse_nps, run, text_table)

BAR = 0.5
MIN_RATED = 1e-4  # seconds; faster phases are shown but not rated
ORACLE_DX, ORACLE_MAX_LEVEL, ORACLE_Z = 20972, 5, 262144
P4EST_DIR = ROOT / "tools" / "p4est_ref"
P4EST_CYCLE = P4EST_DIR / "p4est_adapt_cycle"
SOURCE = ROOT / "tools" / "bench" / "adapt_cycle_octmesh.c"
OUT = WORK / "adapt_cycle"
OCTMESH_CYCLE = OUT / "adapt_cycle_octmesh"
LIB = OUT / "lib"

# octmesh phases the table knows; any other phase the program reports (a
# transfer timed after the mesh build) gets a row of its own.
KNOWN = ("adapt", "refine", "coarsen", "balance", "partition", "mesh")
CHECKED = ("leaves_before", "refined", "coarsened", "leaves_after", "per_rank_before_partition",
           "per_rank", "nodes", "integral")

PHASE_COLUMNS = [("np", "np"), ("phase", "phase"), ("om", "octmesh [s]"),
                 ("p4", "p4est [s]"), ("ratio", "octmesh/p4est"), ("bar", "<= 0.5"),
                 ("om_range", "octmesh min-max"), ("p4_range", "p4est min-max")]
MEM_COLUMNS = [("np", "np"), ("om_before", "octmesh before cycle"),
               ("om_peak", "octmesh cycle peak"), ("om_bpl", "octmesh B/leaf"),
               ("p4_before", "p4est before cycle"), ("p4_peak", "p4est cycle peak"),
               ("p4_bpl", "p4est B/leaf"), ("ratio", "peak octmesh/p4est"),
               ("bar", "<= 0.5"), ("om_warm", "octmesh warm-up peak"),
               ("p4_warm", "p4est warm-up peak")]
HWM_COLUMNS = [("np", "np"), ("code", "code"),
               ("hwm", "peak RSS so far after each phase, MiB per rank")]
COUNT_COLUMNS = [("np", "np"), ("before", "leaves before"),
                 ("changed", "refined / coarsened families"), ("after", "leaves after"),
                 ("per_rank", "leaves per rank"), ("moved", "moved by the partition"), ("nodes", "independent nodes"),
                 ("hanging", "hanging nodes (face + edge, octmesh)"),
                 ("ghosts", "p4est ghosts"), ("integral", "integral of the data")]


def build(env, no_build):
    """cargo build, make -C tools/p4est_ref, and mpicc of the octmesh program
    against include/octmesh.h and a copy of the cdylib under its SONAME."""
    try:
        if not no_build:
            run(["cargo", "build", "--release", "--quiet"], env)
        run(["make", "-s", "-C", P4EST_DIR], env)
        so = ROOT / "target" / "release" / "liboctmesh.so"
        if not so.is_file():
            sys.exit("missing %s (cargo build --release)" % so)
        LIB.mkdir(parents=True, exist_ok=True)
        for name in ("liboctmesh.so", "liboctmesh.so.0"):
            shutil.copyfile(so, LIB / name)
        run(["mpicc", "-O2", "-std=c11", "-Wall", "-Wextra", "-Werror",
             "-I", ROOT / "include", "-I", P4EST_DIR, SOURCE, "-o", OCTMESH_CYCLE,
             "-L", LIB, "-Wl,-rpath,%s" % LIB, "-loctmesh", "-lm"], env)
    except (RunError, OSError) as e:
        sys.exit("build failed: %s" % e)


def result(stdout):
    for line in stdout.splitlines():
        if line.startswith("RESULT "):
            return json.loads(line[len("RESULT "):])
    raise RunError("no RESULT line in:\n" + stdout[-2000:])


def run_one(tool, np_, args, env):
    common = ["--level", args.level, "--max-level", args.max_level, "--dx", args.dx,
              "--z", args.z, "--warmup", args.warmup]
    if tool == "p4est":
        cmd = mpirun(np_) + [P4EST_CYCLE] + common
    else:
        cmd = mpirun(np_) + [OCTMESH_CYCLE] + common + (["--split"] if tool == "split" else [])
    r = result(run(cmd, env))
    t = r["times"]
    if tool == "p4est":
        r["phase"] = {"adapt": t["refine"] + t["coarsen"], "refine": t["refine"],
                      "coarsen": t["coarsen"], "balance": t["balance"],
                      "partition": t["partition"], "mesh": t["ghost"] + t["lnodes"],
                      "ghost": t["ghost"], "lnodes": t["lnodes"]}
    else:
        r["phase"] = dict(t)
    r["phase"]["total"] = r["total_of_max"]
    return r


def med(runs, key):
    values = [r["phase"].get(key) for r in runs]
    return median(values) if values and None not in values else None


def spread(runs, key):
    values = [r["phase"].get(key) for r in (runs or [])]
    if not values or None in values:
        return "-"
    return "%s-%s" % (fmt_s(min(values)), fmt_s(max(values)))


def med_mem(runs, key):
    return median([r[key] for r in runs])


def phase_rows(np_, om, p4, split):
    def row(phase, a_runs, b_runs, a_key, b_key=None):
        b_key = b_key or a_key
        a = med(a_runs, a_key) if a_runs else None
        b = med(b_runs, b_key) if b_runs else None
        ratio = a / b if a is not None and b and max(a, b) >= MIN_RATED else None
        return {"np": str(np_), "phase": phase, "om": fmt_s(a), "p4": fmt_s(b),
                "ratio": "-" if ratio is None else "%.2f" % ratio,
                "bar": "-" if ratio is None else ("yes" if ratio <= BAR else "no"),
                "om_range": spread(a_runs, a_key), "p4_range": spread(b_runs, b_key)}

    rows = [row("adapt (p4est: refine + coarsen)", om, p4, "adapt")]
    if split:
        rows.append(row("refine (octmesh --split run)", split, p4, "refine"))
        rows.append(row("coarsen (octmesh --split run)", split, p4, "coarsen"))
    rows += [row("balance", om, p4, "balance"),
             row("partition for coarsening", om, p4, "partition"),
             row("mesh (p4est: ghost + lnodes)", om, p4, "mesh"),
             row("- p4est ghost", None, p4, "ghost"),
             row("- p4est lnodes", None, p4, "lnodes")]
    extra = [k for k in om[0]["phase"] if k not in KNOWN and k != "total"]
    for k in extra:
        rows.append(row("%s (octmesh only)" % k, om, None, k))
    rows.append(row("total" + (" (octmesh with %s)" % ", ".join(extra) if extra else ""),
                    om, p4, "total"))
    return rows


def mem_row(np_, om, p4):
    n = om[0]["leaves_after"]

    def mib(b):
        return "%.0f MiB" % (b / MIB)

    def bpl(b):
        return "%.0f" % (b * np_ / n)

    a, b = med_mem(om, "peak_cycle"), med_mem(p4, "peak_cycle")
    return {"np": str(np_),
            "om_before": mib(med_mem(om, "rss_before_cycle")), "om_peak": mib(a),
            "om_bpl": bpl(a), "p4_before": mib(med_mem(p4, "rss_before_cycle")),
            "p4_peak": mib(b), "p4_bpl": bpl(b), "ratio": "%.2f" % (a / b),
            "bar": "yes" if a / b <= BAR else "no",
            "om_warm": mib(med_mem(om, "peak_warmup")),
            "p4_warm": mib(med_mem(p4, "peak_warmup"))}


def hwm_rows(np_, om, p4):
    def row(code, runs):
        keys = list(runs[0]["peak_after"])
        return {"np": str(np_), "code": code, "hwm": ", ".join(
            "%s %.0f" % (k, median([r["peak_after"][k] for r in runs]) / MIB) for k in keys)}

    return [row("octmesh", om), row("p4est", p4)]


def check(np_, runs):
    """Mismatch messages: every run of every tool must agree on CHECKED."""
    bad = []
    ref = runs["p4est"][0]
    for tool, rs in runs.items():
        for i, r in enumerate(rs):
            for k in CHECKED:
                if r.get(k) != ref.get(k):
                    bad.append("np %d %s run %d: %s %s, p4est %s" % (np_, tool, i + 1, k,
                                                                    r[k], ref[k]))
            if not r["hwm_reset"]:
                bad.append("np %d %s: VmHWM could not be reset; its peak is the run's"
                           % (np_, tool))
    return bad


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="\n\n".join(__doc__.split("\n\n")[1:]))
    ap.add_argument("--level", type=int, default=4, help="uniform start level (default 4)")
    ap.add_argument("--max-level", type=int, default=11,
                    help="finest level (default 11: about 15 M leaves)")
    ap.add_argument("--dx", type=int,
                    help="the centre's step in lattice units (default: the oracle's 20972 "
                    "scaled to the max level, round(20972 / 2^(max level - 5)))")
    ap.add_argument("--z", type=int, default=ORACLE_Z,
                    help="the centre's z in lattice units (default %d, the middle: the "
                    "octree is then symmetric about the plane that splits it between 2 "
                    "ranks, and a partition on 2 ranks moves nothing)" % ORACLE_Z)
    ap.add_argument("--warmup", type=int, default=8,
                    help="warm-up steps; the timed cycle is the next (default 8)")
    ap.add_argument("--np", default="1,2", help="rank counts (default 1,2)")
    ap.add_argument("--rounds", type=int, default=3,
                    help="runs of each program per rank count, alternating (default 3)")
    ap.add_argument("--split", action="store_true",
                    help="also run octmesh with refine_once_ext + coarsen_ext timed apart")
    ap.add_argument("--markdown", metavar="FILE", help="also write the tables as Markdown")
    ap.add_argument("--json", metavar="FILE", help="also write every run as JSON")
    ap.add_argument("--no-build", action="store_true", help="do not run cargo build first "
                    "(make and mpicc still run)")
    ap.add_argument("--from-json", metavar="FILE", nargs="+",
                    help="run nothing: print (and --markdown) the tables of saved --json "
                    "files (several: their runs together; the first file's machine line)")
    args = ap.parse_args()
    if args.from_json:
        report(*merge_saved(args.from_json), markdown=args.markdown)
        return
    if args.dx is None:
        args.dx = int(round(ORACLE_DX / 2.0 ** (args.max_level - ORACLE_MAX_LEVEL)))
    if args.rounds < 1:
        ap.error("--rounds must be at least 1")
    nps = parse_nps(ap, args.np)

    env = mpi_env()
    build(env, args.no_build)
    info = machine_info(env)
    print("One adaptive cycle, octmesh against p4est (issue 23)")
    for k in ("machine", "date", "commit", "mpi"):
        print("  %-8s %s" % (k + ":", info[k]))
    print("  warm-up: uniform level %d, %d steps, max level %d, dx %d, z %d; %d rounds, "
          "alternating" % (args.level, args.warmup, args.max_level, args.dx, args.z,
                           args.rounds), flush=True)

    tools = ["octmesh", "p4est"] + (["split"] if args.split else [])
    records = []
    try:
        for np_ in nps:
            runs = {t: [] for t in tools}
            for k in range(args.rounds):
                order = tools if k % 2 == 0 else tools[::-1]
                for tool in order:
                    r = run_one(tool, np_, args, env)
                    runs[tool].append(r)
                    print("  np %d round %d %-7s total %s s, cycle peak %.0f MiB/rank, "
                          "leaves %s" % (np_, k + 1, tool, fmt_s(r["phase"]["total"]),
                                         r["peak_cycle"] / MIB, fmt_int(r["leaves_after"])),
                          flush=True)
            records.append({"np": np_, "runs": runs})
    except (RunError, OSError, KeyError, ValueError) as e:
        sys.exit("FAILED: %s" % e)
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"info": info, "args": vars(args), "records": records}, f, indent=1)
        print("json written to %s" % args.json)
    report(info, vars(args), records, args.markdown)


def moved(old, new):
    """Leaves that change rank when the counts per rank go from old to new
    (both partitions cut one Morton order into consecutive pieces)."""
    if old is None:
        return None
    stay, a, b = 0, 0, 0
    for n_old, n_new in zip(old, new):
        stay += max(0, min(a + n_old, b + n_new) - max(a, b))
        a, b = a + n_old, b + n_new
    return sum(new) - stay


def merge_saved(paths):
    """(info, params, records) of saved --json files, runs of equal np together."""
    info = params = None
    by_np = {}
    for path in paths:
        with open(path) as f:
            saved = json.load(f)
        if info is None:
            info, params = saved["info"], dict(saved["args"])
            params["rounds"] = 0
        elif any(saved["args"].get(k, ORACLE_Z) != params.get(k, ORACLE_Z)
                 for k in ("level", "max_level", "dx", "z", "warmup")):
            sys.exit("%s: another octree than %s" % (path, paths[0]))
        params["rounds"] += saved["args"]["rounds"]
        for rec in saved["records"]:
            runs = by_np.setdefault(rec["np"], {})
            for tool, rs in rec["runs"].items():
                runs.setdefault(tool, []).extend(rs)
    return info, params, [{"np": n, "runs": by_np[n]} for n in sorted(by_np)]


def report(info, params, records, markdown):
    """Prints the tables (and writes them as Markdown); exits 1 on a mismatch."""
    phase_rows_all, mem_rows, hwm_rows_all, count_rows, mismatches = [], [], [], [], []
    for rec in records:
        np_, runs = rec["np"], rec["runs"]
        mismatches += check(np_, runs)
        om, p4 = runs["octmesh"], runs["p4est"]
        phase_rows_all += phase_rows(np_, om, p4, runs.get("split"))
        mem_rows.append(mem_row(np_, om, p4))
        hwm_rows_all += hwm_rows(np_, om, p4)
        c = om[0]
        count_rows.append({
            "np": str(np_), "before": fmt_int(c["leaves_before"]),
            "changed": "%s / %s" % (fmt_int(c["refined"]), fmt_int(c["coarsened"])),
            "after": fmt_int(c["leaves_after"]),
            "per_rank": " + ".join(fmt_int(n) for n in c["per_rank"]),
            "moved": fmt_int(moved(c.get("per_rank_before_partition"), c["per_rank"])),
            "nodes": fmt_int(c["nodes"]),
            "hanging": "%s + %s" % (fmt_int(c["face_hanging"]), fmt_int(c["edge_hanging"])),
            "ghosts": fmt_int(p4[0]["ghosts"]), "integral": "%.15g" % c["integral"]})

    print()
    print(text_table(phase_rows_all, PHASE_COLUMNS))
    print()
    print(text_table(mem_rows, MEM_COLUMNS))
    print()
    print(text_table(hwm_rows_all, HWM_COLUMNS))
    print()
    print(text_table(count_rows, COUNT_COLUMNS))
    if markdown:
        with open(markdown, "w") as f:
            f.write(header_line(info, "p4est %s. Uniform level %d, %d warm-up steps, max "
                                "level %d, dx %d, z %d; medians of %d alternating rounds; "
                                "seconds, max over ranks." % (
                                    records[0]["runs"]["p4est"][0]["version"], params["level"],
                                    params["warmup"], params["max_level"], params["dx"],
                                    params.get("z", ORACLE_Z), params["rounds"])))
            f.write("\n\n" + markdown_table(phase_rows_all, PHASE_COLUMNS,
                                            left=("phase",)) + "\n")
            f.write("\nMemory (RSS per rank, max over ranks; the cycle's peak with VmHWM reset "
                    "before it; B/leaf = cycle peak x np / leaves after):\n\n")
            f.write(markdown_table(mem_rows, MEM_COLUMNS, left=()) + "\n")
            f.write("\nWhere the peak is reached (VmHWM after each phase, medians):\n\n")
            f.write(markdown_table(hwm_rows_all, HWM_COLUMNS, left=("code", "hwm")) + "\n")
            f.write("\nCounts (equal in both codes and every run):\n\n")
            f.write(markdown_table(count_rows, COUNT_COLUMNS, left=()) + "\n")
        print("markdown written to %s" % markdown)
    for msg in mismatches:
        print("*** MISMATCH " + msg + " ***")
    if mismatches:
        sys.exit(1)


if __name__ == "__main__":
    main()
