#!/usr/bin/env python3
"""The seed paper's Tables 1-4, measured with octmesh.

Camata & Coutinho ("Parallel linear octree meshing with immersed surfaces")
report per model and level: octants before and after 2:1 balance, elements,
independent and hanging nodes, and the time of surface detection
(refinement), balance and meshing. This script runs the whole octmesh
pipeline (`octmesh mesh --stats`, corner balance) on 1 and 2 ranks for

  Armadillo  solid (keep inside), octmesh levels 7-11
  Dragon     solid (keep inside), octmesh levels 7-11
  Tangaroa   fluid (keep outside), octmesh levels 9-11

and writes one counts table and one times table per model as Markdown.

Level mapping. octmesh's level counts from the cube around the model (side =
longest bounding-box side / --fit). The only figure of the seed at hand
(../shared/GUIDE.md) is its level-9 Armadillo with about 31 M balanced
octants; octmesh reaches 31 M for the Armadillo at level 11 with --fit 1,
so the tables use --fit 1 and seed level = octmesh level - 2 for every
model. The seed column holds that figure where it applies; the paper's other
figures were not available here.

Times: seconds, maximum over ranks, median over --repeat runs. refine =
construct + refine + the partition after it; balance = balance + the
partition after it; mesh = classify (inside / outside) + ghost + nodes +
numbering + connectivity; total = all of these plus reading the surface.

    python3 tools/bench/seed_tables.py --markdown target/bench/seed_tables.md
    python3 tools/bench/seed_tables.py --cases armadillo:7-8,dragon:7,tangaroa:9 --np 1,2

Standard library only.
"""

import argparse
import json
import sys
from pathlib import Path

sys.dont_write_bytecode = True  # keep tools/bench free of __pycache__
sys.path.insert(0, str(Path(__file__).resolve().parent))
from benchlib import (  # noqa: E402
    WORK, Progress, RunError, fmt_int, fmt_mib, fmt_s, header_line, markdown_table, median,
    missing_note, mpi_env, octmesh_stats, parse_cases, parse_nps, prepare, surface_arg,
    surface_name, text_table)

DEFAULT_CASES = "armadillo:7-11,dragon:7-11,tangaroa:9-11"
KEEP = {"armadillo": "inside", "dragon": "inside", "tangaroa": "outside"}
LEVEL_OFFSET = 2  # seed level = octmesh level - LEVEL_OFFSET at --fit 1
# The seed's figures known here (../shared/GUIDE.md, section 3).
SEED = {("armadillo", 9): "~31 M balanced octants; ~126 s on 64 cores "
                          "(detect 13 + balance 60 + mesh 53)"}
BAR_SECONDS = 60.0  # GUIDE.md: Armadillo at the seed's level 9 under 60 s on 2 cores

COUNT_COLUMNS = [
    ("level", "octmesh level"), ("seed_level", "seed level"),
    ("refined", "octants (unbalanced)"), ("balanced", "octants (balanced)"),
    ("elements", "elements"), ("indep", "independent nodes"),
    ("hanging", "hanging nodes (face + edge)"), ("seed", "seed"),
]
TIME_COLUMNS = [
    ("level", "octmesh level"), ("seed_level", "seed level"), ("np", "np"),
    ("read", "read [s]"), ("refine", "refine [s]"), ("balance", "balance [s]"),
    ("mesh", "mesh [s]"), ("total", "total [s]"), ("peak", "peak MiB/rank"),
]
PROGRESS_COLUMNS = [("model", "model")] + TIME_COLUMNS + [("balanced", "balanced octants")]


def measure(src, level, keep, np_, args, env, stats_path):
    runs, counts = [], set()
    for _ in range(args.repeat):
        s = octmesh_stats(np_, ["mesh", src, "--level", level, "--fit", args.fit,
                                "--balance", "corner", "--keep", keep], stats_path, env)
        t, parts = s["timings"], s["partition_timings"]
        r = {
            "read": t["read"],
            "refine": t["construct"] + t["refine"] + parts["refined"],
            "balance": t["balance"] + parts["balanced"],
            "mesh": t["classify"] + t["ghost"] + t["nodes"] + t["numbering"]
            + t["connectivity"],
            "peak": s["peak_rss_bytes"],
        }
        r["total"] = r["read"] + r["refine"] + r["balance"] + r["mesh"]
        runs.append(r)
        counts.add((s["octants_refined"], s["octants_balanced"], s["elements"],
                    s["independent_nodes"], s["face_hanging_nodes"], s["edge_hanging_nodes"]))
    if len(counts) != 1:
        raise RunError("counts differ between repeats: %s" % sorted(counts))
    out = {k: median([r[k] for r in runs]) for k in runs[0]}
    out.update(zip(("refined", "balanced", "elements", "indep", "face", "edge"), counts.pop()))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="\n\n".join(__doc__.split("\n\n")[1:]))
    ap.add_argument("--cases", default=DEFAULT_CASES,
                    help="MODEL:LEVEL or MODEL:LO-HI list (default %s)" % DEFAULT_CASES)
    ap.add_argument("--np", default="1,2", help="rank counts (default 1,2)")
    ap.add_argument("--repeat", type=int, default=1, metavar="K",
                    help="runs per measurement, median reported (default 1)")
    ap.add_argument("--fit", default="1", help="octmesh --fit (default 1, see the mapping)")
    ap.add_argument("--markdown", metavar="FILE", help="also write the tables as Markdown")
    ap.add_argument("--json", metavar="FILE", help="also write every measurement as JSON")
    ap.add_argument("--no-build", action="store_true", help="do not run cargo build first")
    args = ap.parse_args()
    if args.repeat < 1:
        ap.error("--repeat must be at least 1")
    nps = parse_nps(ap, args.np)
    cases = parse_cases(args.cases)

    env = mpi_env()
    info = prepare(env, args.no_build, "the seed paper's tables, measured with octmesh",
                   need_p4est=False)
    print("  --fit %s, seed level = octmesh level - %d; median of %d run(s); seconds, "
          "max over ranks" % (args.fit, LEVEL_OFFSET, args.repeat), flush=True)
    WORK.mkdir(parents=True, exist_ok=True)
    stats_path = WORK / "seed_tables_stats.json"
    progress = Progress(PROGRESS_COLUMNS)
    tables, records, failures, notes = {}, [], [], []
    for surface, level in cases:
        name = surface_name(surface)
        keep = KEEP.get(name, "inside")
        src = surface_arg(surface)
        if src is None:
            notes.append("skipped %s level %d (%s)" % (name, level, missing_note(surface)))
            print("note: " + notes[-1], flush=True)
            continue
        counts_rows, time_rows = tables.setdefault((name, keep), ([], []))
        seed_level = level - LEVEL_OFFSET
        try:
            for np_ in nps:
                m = measure(src, level, keep, np_, args, env, stats_path)
                row = {"model": name, "level": str(level), "seed_level": str(seed_level),
                       "np": str(np_), "read": fmt_s(m["read"]), "refine": fmt_s(m["refine"]),
                       "balance": fmt_s(m["balance"]), "mesh": fmt_s(m["mesh"]),
                       "total": fmt_s(m["total"]), "peak": fmt_mib(m["peak"]),
                       "balanced": fmt_int(m["balanced"])}
                time_rows.append(row)
                progress.add(row)
                records.append({"model": name, "keep": keep, "level": level, "np": np_,
                                "fit": float(args.fit), **m})
            counts_rows.append({
                "level": str(level), "seed_level": str(seed_level),
                "refined": fmt_int(m["refined"]), "balanced": fmt_int(m["balanced"]),
                "elements": fmt_int(m["elements"]), "indep": fmt_int(m["indep"]),
                "hanging": "%s + %s" % (fmt_int(m["face"]), fmt_int(m["edge"])),
                "seed": SEED.get((name, seed_level), "not available"),
            })
            if (name, seed_level) == ("armadillo", 9):
                for rec in records[-len(nps):]:
                    print("  bar: Armadillo seed level 9, np %d: %.1f s %s %.0f s"
                          % (rec["np"], rec["total"],
                             "<=" if rec["total"] <= BAR_SECONDS else ">", BAR_SECONDS))
        except (RunError, OSError, KeyError, ValueError) as e:
            failures.append("%s level %d: %s" % (name, level, e))
            print("FAILED " + failures[-1], flush=True)
    stats_path.unlink(missing_ok=True)

    out = []
    for (name, keep), (counts_rows, time_rows) in tables.items():
        if not time_rows:
            continue
        title = "%s (%s, keep %s)" % (name, "solid" if keep == "inside" else "fluid", keep)
        out.append(("%s: counts" % title, markdown_table(counts_rows, COUNT_COLUMNS),
                    text_table(counts_rows, COUNT_COLUMNS)))
        out.append(("%s: times" % title, markdown_table(time_rows, TIME_COLUMNS),
                    text_table(time_rows, TIME_COLUMNS)))
    for title, _, text in out:
        print("\n" + title + "\n" + text)
    if args.markdown:
        with open(args.markdown, "w") as f:
            f.write(header_line(info, "octmesh --fit %s, balance corner, cut rule center; "
                                "seed level = octmesh level - %d; times are medians of %d "
                                "run(s), seconds, max over ranks." % (
                                    args.fit, LEVEL_OFFSET, args.repeat)) + "\n")
            for title, md, _ in out:
                f.write("\n%s:\n\n%s\n" % (title, md))
            for note in notes:
                f.write("\nNote: %s.\n" % note)
        print("markdown written to %s" % args.markdown)
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"info": info, "records": records, "notes": notes}, f, indent=1)
    for msg in failures:
        print("FAILED " + msg)
    if failures:
        sys.exit(1)


if __name__ == "__main__":
    main()
