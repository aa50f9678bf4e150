#!/usr/bin/env python3
"""2:1 balance of octmesh against p4est on the same refined octree.

For every case (surface, level) and rank count, octmesh builds and balances
the surface-refined octree K times; its refined leaves are written once and
rebuilt by tools/p4est_ref/octmesh_p4est, which times p8est_balance K times.
Times are medians over the K runs of the per-run maximum over ranks.

    python3 tools/bench/balance_vs_p4est.py [--cases sphere:8,bunny:9]
        [--balance corner] [--repeat 3] [--np 1,2] [--markdown FILE]

Standard library only. Exits non-zero if a run fails or the two codes
disagree on the number of balanced leaves.
"""

import argparse
import datetime
import json
import os
import platform
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
OCTMESH = ROOT / "target" / "release" / "octmesh"
P4EST = ROOT / "tools" / "p4est_ref" / "octmesh_p4est"
DATA = ROOT.parent / "shared" / "data"
WORK = ROOT / "target" / "bench"
BUILTIN = ("sphere", "torus")
DEFAULT_CASES = [(s, lv) for s in ("sphere", "bunny") for lv in (8, 9, 10, 11)]
MIB = 1024.0 * 1024.0

COLUMNS = [
    ("surface", "surface"),
    ("level", "level"),
    ("np", "np"),
    ("refined", "refined leaves"),
    ("balanced", "balanced leaves"),
    ("om_bal", "octmesh balance s"),
    ("p4_bal", "p4est balance s"),
    ("ratio", "p4est/octmesh"),
    ("om_ref", "octmesh refine s"),
    ("p4_ref", "p4est refine s"),
    ("om_mib", "octmesh RSS MiB"),
    ("om_bpl", "octmesh B/leaf"),
    ("p4_mib", "p4est RSS MiB"),
    ("p4_bpl", "p4est B/leaf"),
]


class RunError(Exception):
    pass


def mpi_env():
    env = dict(os.environ)
    env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    # Only matters on machines with fewer cores than the largest np.
    env.setdefault("OMPI_MCA_rmaps_base_oversubscribe", "1")
    env["PATH"] = str(Path.home() / ".cargo" / "bin") + os.pathsep + env.get("PATH", "")
    return env


def run(cmd, env):
    p = subprocess.run(cmd, env=env, cwd=ROOT, capture_output=True, text=True)
    if p.returncode != 0:
        tail = (p.stderr or p.stdout).strip().splitlines()[-10:]
        raise RunError("command failed (exit %d): %s\n    %s"
                       % (p.returncode, " ".join(map(str, cmd)), "\n    ".join(tail)))
    return p.stdout


def parse_cases(text):
    cases = []
    for item in text.split(","):
        item = item.strip()
        if not item:
            continue
        surface, sep, level = item.rpartition(":")
        if not sep or not surface or not level.isdigit():
            sys.exit("bad case %r: expected SURFACE:LEVEL, e.g. sphere:8" % item)
        cases.append((surface, int(level)))
    return cases


def surface_arg(surface):
    """The octmesh argument for a case name, or None if the model is missing."""
    if surface in BUILTIN:
        return surface
    path = Path(surface) if surface.endswith(".stl") else DATA / (surface + ".stl")
    return str(path) if path.is_file() else None


def machine_info(env):
    cpu = "unknown"
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    mem = ""
    try:
        with open("/proc/meminfo") as f:
            kib = int(f.readline().split()[1])
            mem = ", %.0f GiB RAM" % (kib / MIB)
    except (OSError, ValueError, IndexError):
        pass

    def out(cmd):
        try:
            return subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True,
                                  text=True).stdout.strip()
        except OSError:
            return ""

    commit = out(["git", "rev-parse", "--short", "HEAD"]) or "unknown"
    if out(["git", "status", "--porcelain", "--untracked-files=no"]):
        commit += " (with uncommitted changes)"
    mpi = (out(["mpirun", "--version"]).splitlines() or ["unknown"])[0]
    return {
        "machine": "%d cores (nproc), %s%s, %s %s" % (
            len(os.sched_getaffinity(0)), cpu, mem, platform.system(), platform.release()),
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "commit": commit,
        "mpi": mpi,
    }


def fmt_s(t):
    return "%.4f" % t if t < 1 else "%.3f" % t if t < 10 else "%.2f" % t


def format_row(r):
    return {
        "surface": r["surface"],
        "level": str(r["level"]),
        "np": str(r["np"]),
        "refined": "{:,}".format(r["refined"]),
        "balanced": "{:,}".format(r["balanced"]),
        "om_bal": fmt_s(r["om_bal"]),
        "p4_bal": fmt_s(r["p4_bal"]),
        "ratio": "%.2f" % (r["p4_bal"] / r["om_bal"]) if r["om_bal"] > 0 else "-",
        "om_ref": fmt_s(r["om_ref"]),
        "p4_ref": fmt_s(r["p4_ref"]),
        "om_mib": "%.0f" % (r["om_rss"] / MIB),
        # Memory per leaf as if each rank held its share: peak (max over
        # ranks) times np over the balanced leaf count.
        "om_bpl": "%.0f" % (r["om_rss"] * r["np"] / r["balanced"]),
        "p4_mib": "%.0f" % (r["p4_rss"] / MIB),
        "p4_bpl": "%.0f" % (r["p4_rss"] * r["np"] / r["balanced"]),
    }


def text_table(rows):
    cells = [[h for _, h in COLUMNS]] + [[r[k] for k, _ in COLUMNS] for r in rows]
    widths = [max(len(c[i]) for c in cells) for i in range(len(COLUMNS))]
    lines = []
    for n, c in enumerate(cells):
        lines.append("  ".join(v.ljust(w) if i == 0 else v.rjust(w)
                               for i, (v, w) in enumerate(zip(c, widths))))
        if n == 0:
            lines.append("  ".join("-" * w for w in widths))
    return "\n".join(lines)


def markdown_table(rows):
    head = [h for _, h in COLUMNS]
    lines = ["| " + " | ".join(head) + " |",
             "|" + "|".join(":---" if i == 0 else "---:" for i in range(len(head))) + "|"]
    for r in rows:
        lines.append("| " + " | ".join(r[k] for k, _ in COLUMNS) + " |")
    return "\n".join(lines)


def parse_nps(ap, text):
    """Rank counts from '1,2', or an argparse error."""
    try:
        return [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        ap.error("--np expects integers, e.g. 1,2")


def prepare(env, no_build, title):
    """Builds both programs (unless no_build), checks they exist, prints the
    title and the machine lines, and returns the machine info."""
    if not no_build:
        # Builds are no-ops when up to date and make sure the measured
        # binaries match the sources.
        try:
            run(["cargo", "build", "--release", "--quiet"], env)
            run(["make", "-s", "-C", str(P4EST.parent)], env)
        except (RunError, OSError) as e:
            sys.exit("build failed: %s" % e)
    for exe in (OCTMESH, P4EST):
        if not os.access(exe, os.X_OK):
            sys.exit("missing %s (cargo build --release; make -C tools/p4est_ref)" % exe)
    info = machine_info(env)
    print(title, flush=True)
    print("  machine: %s" % info["machine"])
    print("  date:    %s" % info["date"])
    print("  commit:  %s" % info["commit"])
    print("  mpi:     %s" % info["mpi"])
    return info


def bench_case(surface, level, nps, args, env, files):
    """Yields one result dict per np; raises RunError on failure."""
    src = surface_arg(surface)
    name = Path(surface).stem if surface.endswith(".stl") else surface
    refined = WORK / ("%s_L%d.bin" % (name, level))
    stats = WORK / ("%s_L%d_stats.json" % (name, level))
    p4json = WORK / ("%s_L%d_p4est.json" % (name, level))
    files.extend([refined, stats, p4json])
    written = False
    for np_ in nps:
        mpirun = ["mpirun", "-np", str(np_)]
        refine_t, balance_t, rss, counts = [], [], [], set()
        for k in range(args.repeat):
            cmd = mpirun + [str(OCTMESH), "octree", src, "--level", str(level),
                            "--balance", args.balance, "--stats", str(stats), "--quiet"]
            if not written:
                cmd += ["--write-refined", str(refined)]
            run(cmd, env)
            written = True
            with open(stats) as f:
                s = json.load(f)
            t = s["timings"]
            refine_t.append(t["construct"] + t["refine"])
            balance_t.append(t["balance"])
            rss.append(s["peak_rss_bytes"])
            counts.add((s["octants_refined"], s["octants_balanced"]))
        if len(counts) != 1:
            raise RunError("octmesh leaf counts differ between repeats: %s" % sorted(counts))
        n_ref, n_bal = counts.pop()

        run(mpirun + [str(P4EST), "--in", str(refined), "--balance", args.balance,
                      "--json", str(p4json), "--repeat", str(args.repeat)], env)
        with open(p4json) as f:
            p = json.load(f)
        yield {
            "surface": name, "level": level, "np": np_,
            "refined": n_ref, "balanced": n_bal,
            "p4_in": p["leaves_in"], "p4_balanced": p["leaves_balanced"],
            "om_bal": statistics.median(balance_t),
            "om_ref": statistics.median(refine_t),
            "om_rss": max(rss),
            "p4_bal": p["timings"]["balance"],
            "p4_ref": p["timings"]["refine"],
            "p4_rss": p["peak_rss_bytes"],
            "p4_version": p.get("version", "?"),
        }


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", help="comma-separated SURFACE:LEVEL list, e.g. sphere:8,bunny:9 "
                    "(SURFACE: sphere, torus, a model name in ../shared/data or a .stl path)")
    ap.add_argument("--balance", default="corner", choices=["face", "edge", "corner"])
    ap.add_argument("--repeat", type=int, default=3, metavar="K",
                    help="runs per measurement; the median is reported (default 3)")
    ap.add_argument("--np", default="1,2", help="comma-separated rank counts (default 1,2)")
    ap.add_argument("--markdown", metavar="FILE", help="also write the table as Markdown")
    ap.add_argument("--no-build", action="store_true",
                    help="do not run cargo build --release and make -C tools/p4est_ref first")
    args = ap.parse_args()
    if args.repeat < 1:
        ap.error("--repeat must be at least 1")
    nps = parse_nps(ap, args.np)
    cases = parse_cases(args.cases) if args.cases else DEFAULT_CASES

    env = mpi_env()
    info = prepare(env, args.no_build, "octmesh 2:1 balance against p4est")
    print("  balance %s, median of %d runs, times in seconds (max over ranks)"
          % (args.balance, args.repeat), flush=True)

    WORK.mkdir(parents=True, exist_ok=True)
    rows, mismatches, failures, files, skipped = [], [], [], [], []
    p4_version = "?"
    try:
        for surface, level in cases:
            if surface_arg(surface) is None:
                note = "%s:%d (%s not found)" % (
                    surface, level, surface if surface.endswith(".stl")
                    else DATA / (surface + ".stl"))
                skipped.append(note)
                print("note: skipped " + note, flush=True)
                continue
            try:
                for r in bench_case(surface, level, nps, args, env, files):
                    p4_version = r["p4_version"]
                    row = format_row(r)
                    rows.append(row)
                    if len(rows) == 1:
                        print(text_table([row]).splitlines()[0])
                        print(text_table([row]).splitlines()[1])
                    print(text_table(rows).splitlines()[-1], flush=True)
                    if r["refined"] != r["p4_in"] or r["balanced"] != r["p4_balanced"]:
                        msg = ("MISMATCH %s level %d np %d: octmesh refined %d balanced %d, "
                               "p4est in %d balanced %d" % (
                                   r["surface"], level, r["np"], r["refined"], r["balanced"],
                                   r["p4_in"], r["p4_balanced"]))
                        mismatches.append(msg)
                        print("*** " + msg + " ***", flush=True)
            except (RunError, OSError, KeyError, ValueError) as e:
                failures.append("%s:%d: %s" % (surface, level, e))
                print("FAILED %s:%d: %s" % (surface, level, e), flush=True)
            finally:
                # Refined files are 16 B per leaf; drop each once its case is done.
                for f in files:
                    f.unlink(missing_ok=True)
                files.clear()
    finally:
        for f in files:
            f.unlink(missing_ok=True)

    print()
    print(text_table(rows) if rows else "(no results)")
    if args.markdown:
        with open(args.markdown, "w") as f:
            f.write("Machine: %s. Date: %s. Commit: %s. p4est %s, %s. "
                    "Balance %s; octmesh times are medians of %d runs, p4est times "
                    "medians of %d repeats; all times in seconds, max over ranks.\n\n"
                    % (info["machine"], info["date"], info["commit"], p4_version,
                       info["mpi"], args.balance, args.repeat, args.repeat))
            f.write(markdown_table(rows) + "\n")
            for note in skipped:
                f.write("\nSkipped %s.\n" % note)
        print("markdown written to %s" % args.markdown)
    for msg in failures:
        print("FAILED " + msg)
    for msg in mismatches:
        print("*** " + msg + " ***")
    if mismatches or failures:
        sys.exit(1)


if __name__ == "__main__":
    main()
