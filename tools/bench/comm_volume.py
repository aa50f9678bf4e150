#!/usr/bin/env python3
"""Bytes each rank exchanges per phase, against a surface-to-volume estimate.

For each fixed case (default: sphere level 9 and bunny level 9) the script
runs `octmesh mesh --stats` on np = 1..8 ranks (oversubscribed on small
machines) and reads `comm_bytes`: per phase, the maximum over ranks of the
bytes a rank sent to and received from other ranks (the payload octmesh hands
to MPI; see `comm::Traffic`). It checks that nothing is exchanged on one rank
and that, summed over the ranks, sent equals received.

Model. With N balanced leaves on p ranks, a rank holds n = N / p leaves in a
contiguous Morton range; the leaves on the boundary of such a range number
about c * n^(2/3) for a compact region, and the ghost layer, the balance
probes and the shared nodes all scale with them. For each phase, c is
fitted once by least squares over all p >= 2 (bytes = c * n^(2/3)); the
table shows the measured bytes per rank and their ratio to the fitted
estimate. Ratios near 1 at every p mean the phase's communication follows
the boundary of the partition; a ratio growing with p means a part that
does not shrink with n (for example reductions, or a surface that crosses
many ranks' ranges). The exponent a of the best power law bytes ~ n^a over
p >= 2 is printed too (2/3 for the model; a surface-refined octree has its
leaves on a thin shell, where a range's boundary may behave otherwise).

Time. Each row also gives the pipeline's time (the phases from construct to
connectivity, each the maximum over ranks) and the seconds a rank spent
inside collectives over those phases (`comm_seconds_min` / `_max`: the
least and the most over ranks). The most is mostly waiting for the slowest
rank; the least bounds what overlapping work with communication could hide.

    python3 tools/bench/comm_volume.py --np 1-8 --markdown target/bench/comm.md

Standard library only.
"""

import argparse
import json
import math
import sys
from pathlib import Path

sys.dont_write_bytecode = True  # keep tools/bench free of __pycache__
sys.path.insert(0, str(Path(__file__).resolve().parent))
from benchlib import (  # noqa: E402
    WORK, RunError, fmt_int, header_line, markdown_table, missing_note, mpi_env,
    octmesh_stats, parse_cases, parse_nps, prepare, surface_arg, surface_name, text_table)

DEFAULT_CASES = "sphere:9,bunny:9"
# Phases that exchange data; "other" adds up the rest (read, classify,
# nodes, connectivity, write: reductions only, or nothing).
PHASES = ("construct", "refine", "partition", "balance", "ghost", "numbering")
MODELLED = ("balance", "ghost", "numbering", "boundary")


def fit_exponent(points):
    """Least-squares slope a of log(bytes) = a log(n) + b over (n, bytes) points."""
    pts = [(math.log(n), math.log(b)) for n, b in points if n > 0 and b > 0]
    if len(pts) < 2:
        return None
    mx = sum(x for x, _ in pts) / len(pts)
    my = sum(y for _, y in pts) / len(pts)
    sxx = sum((x - mx) ** 2 for x, _ in pts)
    return sum((x - mx) * (y - my) for x, y in pts) / sxx if sxx else None


def fit_c(points):
    """Least-squares c for bytes = c * x over (x, bytes) points."""
    sxx = sum(x * x for x, _ in points)
    return sum(x * b for x, b in points) / sxx if sxx else 0.0


def fmt_bytes(b):
    if b >= 10 * 1024 * 1024:
        return "%.1f MiB" % (b / 1024.0 / 1024.0)
    if b >= 10 * 1024:
        return "%.1f KiB" % (b / 1024.0)
    return "%d B" % b


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="\n\n".join(__doc__.split("\n\n")[1:]))
    ap.add_argument("--cases", default=DEFAULT_CASES,
                    help="SURFACE:LEVEL list (default %s)" % DEFAULT_CASES)
    ap.add_argument("--np", default="1-8", help="rank counts (default 1-8)")
    ap.add_argument("--fit", default="0.7", help="octmesh --fit (default 0.7)")
    ap.add_argument("--markdown", metavar="FILE", help="also write the tables as Markdown")
    ap.add_argument("--json", metavar="FILE", help="also write the measurements as JSON")
    ap.add_argument("--no-build", action="store_true", help="do not run cargo build first")
    args = ap.parse_args()
    nps = parse_nps(ap, args.np)
    cases = parse_cases(args.cases)

    env = mpi_env()
    info = prepare(env, args.no_build, "octmesh communication volume per rank and phase",
                   need_p4est=False)
    WORK.mkdir(parents=True, exist_ok=True)
    stats_path = WORK / "comm_volume_stats.json"
    problems, notes, records, tables = [], [], [], []
    for surface, level in cases:
        name = surface_name(surface)
        src = surface_arg(surface)
        if src is None:
            notes.append("skipped %s level %d (%s)" % (name, level, missing_note(surface)))
            print("note: " + notes[-1])
            continue
        runs = []
        try:
            for np_ in nps:
                s = octmesh_stats(np_, ["mesh", src, "--level", level, "--fit", args.fit,
                                        "--balance", "corner"], stats_path, env)
                b = s["comm_bytes"]
                r = {"np": np_, "leaves": s["octants_balanced"],
                     "total": b["total"], "sent_sum": s["comm_bytes_sum"]["sent"],
                     "received_sum": s["comm_bytes_sum"]["received"]}
                for p in PHASES:
                    r[p] = b[p]
                timed = [k for k in s["timings"] if k not in ("read", "write")]
                r["time"] = sum(s["timings"][k] for k in timed)
                r["wait_min"] = sum(s["comm_seconds_min"][k] for k in timed)
                r["wait_max"] = sum(s["comm_seconds_max"][k] for k in timed)
                # The phases that move only boundary data, together.
                r["boundary"] = b["balance"] + b["ghost"] + b["numbering"]
                r["other"] = sum(v for k, v in b.items() if k not in PHASES + ("total",))
                runs.append(r)
                if r["sent_sum"] != r["received_sum"]:
                    problems.append("%s %d np %d: sent %d != received %d" % (
                        name, level, np_, r["sent_sum"], r["received_sum"]))
                if (np_ == 1) != (r["total"] == 0):
                    problems.append("%s %d np %d: total %d bytes" % (name, level, np_,
                                                                     r["total"]))
                print("%s %d np %d: %s per rank (max), %s in all; %.3f s, %.4f to %.4f s "
                      "inside collectives" % (
                          name, level, np_, fmt_bytes(r["total"]), fmt_bytes(r["sent_sum"]),
                          r["time"], r["wait_min"], r["wait_max"]), flush=True)
        except (RunError, OSError, KeyError, ValueError) as e:
            problems.append("%s %d: %s" % (name, level, e))
            print("FAILED " + problems[-1])
            continue
        multi = [r for r in runs if r["np"] > 1]
        cs = {}
        for p in MODELLED:
            cs[p] = fit_c([((r["leaves"] / r["np"]) ** (2.0 / 3.0), r[p]) for r in multi])
        columns = [("np", "np"), ("n", "leaves per rank n"), ("n23", "n^(2/3)")]
        for p in PHASES + ("other", "total"):
            columns.append((p, p))
        columns.append(("per_leaf", "total B per local leaf"))
        for p in MODELLED:
            columns.append(("ratio_" + p, "%s / (c n^(2/3))" % p))
        columns += [("time", "pipeline [s]"), ("wait", "in collectives [s], min to max"),
                    ("share", "share, min to max")]
        rows = []
        for r in runs:
            n = r["leaves"] / r["np"]
            x = n ** (2.0 / 3.0)
            row = {"np": str(r["np"]), "n": fmt_int(round(n)), "n23": "%.0f" % x}
            for p in PHASES + ("other", "total"):
                row[p] = fmt_bytes(r[p])
            row["per_leaf"] = "%.2f" % (r["total"] / n)
            row["time"] = "%.3f" % r["time"]
            row["wait"] = "%.4f to %.4f" % (r["wait_min"], r["wait_max"])
            row["share"] = "%.1f%% to %.1f%%" % (100 * r["wait_min"] / r["time"],
                                                  100 * r["wait_max"] / r["time"])
            for p in MODELLED:
                row["ratio_" + p] = "%.2f" % (r[p] / (cs[p] * x)) if r["np"] > 1 and cs[p] else "-"
            rows.append(row)
        alpha = fit_exponent([(r["leaves"] / r["np"], r["boundary"]) for r in multi])
        title = ("%s level %d (%s balanced leaves): bytes per rank (max over ranks) and "
                 "the ratio to c n^(2/3), c fitted over np >= 2: %s; best power law for "
                 "boundary: n^%s" % (
                     name, level, fmt_int(runs[0]["leaves"]),
                     ", ".join("c_%s = %.1f B" % (p, cs[p]) for p in MODELLED),
                     "-" if alpha is None else "%.2f" % alpha))
        tables.append((title, rows, columns))
        print("\n" + title + "\n" + text_table(rows, columns) + "\n")
        records.append({"surface": name, "level": level, "runs": runs, "c": cs,
                        "boundary_exponent": alpha})
    stats_path.unlink(missing_ok=True)
    if args.markdown:
        with open(args.markdown, "w") as f:
            f.write(header_line(info, "octmesh mesh, --fit %s, corner balance, keep all. "
                                "Each phase's figure is the maximum over ranks of the "
                                "bytes one rank sent plus received; total is the maximum "
                                "of the per-rank totals (not the sum of the column maxima). "
                                "boundary = balance + ghost + numbering; other = the "
                                "remaining phases (reductions only)." % args.fit) + "\n")
            for title, rows, columns in tables:
                f.write("\n%s.\n\n%s\n" % (title, markdown_table(rows, columns)))
            for note in notes:
                f.write("\nNote: %s.\n" % note)
        print("markdown written to %s" % args.markdown)
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"info": info, "records": records}, f, indent=1)
    for msg in problems:
        print("PROBLEM " + msg)
    if problems:
        sys.exit(1)


if __name__ == "__main__":
    main()
