#!/usr/bin/env python3
"""octmesh against p4est on the same input, phase by phase, in one run.

For every case (surface, level, kept side) the script writes octmesh's refined
leaves once (`octmesh octree --write-refined`, not timed). Then, for every
rank count, it runs the whole octmesh pipeline K times (`octmesh mesh
--stats`) and the p4est reference program once on those refined leaves
(tools/p4est_ref/octmesh_p4est --nodes, which repeats its own pipeline K'
times in one process). Both codes go through the same phases:

  refine     octmesh: construction and refinement from the surface, then
             the partition of the refined leaves. p4est: p8est_new_ext,
             p8est_refine with a callback that looks the target leaves up in
             the file, p8est_partition. p4est's refine does less work (it
             never touches the surface), so this row favours p4est.
  balance    2:1 balance, corner (face, edge and corner neighbours).
  partition  the partition after balance.
  mesh       octmesh: ghost + nodes + numbering + connectivity (ghost layer,
             independent / face- / edge-hanging nodes, global numbering and
             owners, element connectivity with explicit hanging-node
             constraints). Compared with p4est's p8est_ghost_new +
             p8est_lnodes_new (degree 1; lists no constraints) and, in a
             second row, p8est_ghost_new + p8est_nodes_new (explicit hanging
             nodes, p4est's equivalent).
  total      refine + balance + partition + mesh, against p4est with lnodes.
octmesh's reading of the surface and its inside/outside classification have
no p4est counterpart and are shown apart. Every time is the maximum over the
ranks; octmesh times are medians over K runs, p4est's medians over K'
repeats. The ratio is octmesh / p4est; the bar is a ratio of at most 0.5.
Phases under 0.1 ms in both codes (a partition that moves nothing) are
shown but not rated.

Memory (peak RSS, maximum over ranks, per rank): octmesh's whole mesh run,
and the part after the surface was loaded (every rank holds the whole
surface and its search tree); p4est's run up to lnodes, and up to
p8est_nodes_new. Every p4est rank holds the whole refined leaf list for the
refine callback (16 B per refined leaf): that overhead is measured (the RSS
after reading the list minus the RSS before) and subtracted in its own
column. B/leaf = peak per rank x np / balanced leaves.

The script fails unless both codes reach the same refined and balanced leaf
counts; on full meshes (keep all) it also checks the element, independent,
face- and edge-hanging node counts and the elements with hanging nodes
against p8est_lnodes / p8est_nodes (p4est's hanging counts only up to 5 M
leaves). For solid or fluid meshes (keep inside / outside) octmesh meshes
the kept elements only while p4est meshes all leaves; then only the leaf
counts are compared.

    python3 tools/bench/compare_p4est.py --preset validation
    python3 tools/bench/compare_p4est.py --preset full --markdown target/bench/compare.md
    python3 tools/bench/compare_p4est.py --cases sphere:9-10,tangaroa:9:outside --np 1,2

Standard library only.
"""

import argparse
import json
import sys
from pathlib import Path

sys.dont_write_bytecode = True  # keep tools/bench free of __pycache__
sys.path.insert(0, str(Path(__file__).resolve().parent))
from benchlib import (  # noqa: E402
    GIB, P4EST, WORK, Progress, RunError, fmt_int, fmt_mib, fmt_s, header_line,
    markdown_table, median, mem_total_bytes, missing_note, mpi_env, mpirun, octmesh_stats,
    parse_cases, parse_nps, prepare, run, surface_arg, surface_name, text_table)

PRESETS = {
    # Small cases, a few minutes in all: checks that everything runs and agrees.
    "validation": "sphere:7-9,bunny:7-8,dragon:7,tangaroa:9:outside",
    # The comparison of the performance issue (hours; see BENCHMARKS.md).
    "full": ("sphere:8-11,bunny:8-11,armadillo:8-11,dragon:8-12,"
             "tangaroa:9:outside,tangaroa:10:outside,tangaroa:11:outside"),
}
BAR = 0.5
MIN_RATED = 1e-4  # seconds; faster phases are shown but not rated

# Rough peak memory per balanced leaf over all ranks (from earlier runs of
# this script at 20-30 M leaves), used to skip what cannot fit.
OCTMESH_B_PER_LEAF = 70
P4EST_LNODES_B_PER_LEAF = 120
P4EST_NODES_B_PER_LEAF = 180

PHASE_COLUMNS = [
    ("case", "case"), ("np", "np"), ("phase", "phase"),
    ("om", "octmesh [s]"), ("p4", "p4est [s]"), ("ratio", "octmesh/p4est"), ("bar", "<= 0.5"),
]
COUNT_COLUMNS = [
    ("case", "case"), ("refined", "refined leaves"), ("balanced", "balanced leaves"),
    ("elements", "elements"), ("indep", "independent nodes"),
    ("hanging", "hanging nodes (face + edge)"), ("agree", "p4est agrees on"),
]
MEM_COLUMNS = [
    ("case", "case"), ("np", "np"),
    ("om_peak", "octmesh peak MiB/rank"), ("om_bpl", "octmesh B/leaf"),
    ("om_surf", "octmesh surface MiB/rank"), ("om_nosurf_bpl", "octmesh B/leaf without surface"),
    ("p4_ln", "p4est lnodes peak MiB/rank"), ("p4_ln_bpl", "p4est lnodes B/leaf"),
    ("p4_list", "p4est leaf list MiB/rank"), ("p4_nolist_bpl", "p4est lnodes B/leaf without list"),
    ("p4_nd", "p4est p8est_nodes peak MiB/rank"), ("p4_nd_bpl", "p4est p8est_nodes B/leaf"),
]
EXTRA_COLUMNS = [
    ("case", "case"), ("np", "np"), ("read", "octmesh read [s]"),
    ("classify", "octmesh classify [s]"),
]


def case_label(name, level, keep):
    return "%s %d%s" % (name, level, "" if keep == "all" else " " + keep)


def octmesh_runs(src, level, keep, np_, args, env, stats_path):
    """K runs of `octmesh mesh`; per-phase medians and the counts."""
    runs, counts = [], set()
    for _ in range(args.repeat):
        s = octmesh_stats(np_, ["mesh", src, "--level", level, "--fit", args.fit,
                                "--balance", "corner", "--keep", keep], stats_path, env)
        t = s["timings"]
        parts = s["partition_timings"]
        r = {
            "read": t["read"],
            "refine": t["construct"] + t["refine"] + parts["refined"],
            "balance": t["balance"],
            "partition": parts["balanced"],
            "classify": t["classify"],
            "mesh": t["ghost"] + t["nodes"] + t["numbering"] + t["connectivity"],
            "peak": s["peak_rss_bytes"],
            "surface": s["rss_after_read_bytes"] - s["rss_start_bytes"],
        }
        r["total"] = r["refine"] + r["balance"] + r["partition"] + r["mesh"]
        runs.append(r)
        counts.add((s["octants_refined"], s["octants_balanced"], s["elements"],
                    s["independent_nodes"], s["face_hanging_nodes"], s["edge_hanging_nodes"],
                    s["elements_with_hanging"]))
    if len(counts) != 1:
        raise RunError("octmesh counts differ between repeats: %s" % sorted(counts))
    out = {k: median([r[k] for r in runs]) for k in runs[0]}
    keys = ("refined", "balanced", "elements", "indep", "face", "edge", "with_hanging")
    out.update(zip(keys, counts.pop()))
    return out


def p4est_run(refined_file, np_, lnodes_only, args, env, json_path):
    cmd = mpirun(np_) + [P4EST, "--in", refined_file, "--balance", "corner", "--nodes",
                         "--json", json_path, "--repeat", args.p4est_repeat]
    if lnodes_only:
        cmd.append("--lnodes-only")
    run(cmd, env)
    with open(json_path) as f:
        p = json.load(f)
    t = p["timings"]
    out = {
        "refine": t["refine"], "balance": t["balance"], "partition": t["partition"],
        "ghost": t["ghost"], "lnodes": t["lnodes"], "nodes": t.get("nodes"),
        "refined": p["leaves_in"], "balanced": p["leaves_balanced"],
        "lnodes_global": p["lnodes_global"], "lnodes_hanging": p["lnodes_hanging_elements"],
        "indep": p.get("indep_nodes"), "face": p.get("face_hanging_nodes"),
        "edge": p.get("edge_hanging_nodes"),
        "rss_start": p["rss_start_bytes"], "rss_read": p["rss_after_read_bytes"],
        "rss_lnodes": p["rss_lnodes_bytes"], "rss_nodes": p.get("rss_nodes_bytes"),
        "peak": p["peak_rss_bytes"], "version": p.get("version", "?"),
    }
    out["mesh_lnodes"] = out["ghost"] + out["lnodes"]
    out["mesh_nodes"] = out["ghost"] + out["nodes"] if out["nodes"] is not None else None
    out["total"] = out["refine"] + out["balance"] + out["partition"] + out["mesh_lnodes"]
    return out


def check_counts(keep, om, p4):
    """(what agreed, mismatch messages)."""
    agreed, bad = [], []

    def same(what, pairs):
        values = [v for _, v in pairs if v is not None]
        if len(values) < 2:
            return
        if len(set(values)) > 1:
            bad.append("%s: %s" % (what, ", ".join("%s %s" % (n, "-" if v is None else v)
                                                   for n, v in pairs)))
        else:
            agreed.append(what)

    same("refined", [("octmesh", om["refined"]), ("p4est", p4["refined"])])
    same("balanced", [("octmesh", om["balanced"]), ("p4est", p4["balanced"])])
    if keep == "all":
        same("elements", [("octmesh", om["elements"]), ("p4est balanced", p4["balanced"])])
        same("independent", [("octmesh", om["indep"]), ("p4est lnodes", p4["lnodes_global"]),
                             ("p4est nodes", p4["indep"])])
        same("face-hanging", [("octmesh", om["face"]), ("p4est", p4["face"])])
        same("edge-hanging", [("octmesh", om["edge"]), ("p4est", p4["edge"])])
        same("hanging elements", [("octmesh", om["with_hanging"]),
                                  ("p4est", p4["lnodes_hanging"])])
    return agreed, bad


def phase_rows(label, np_, om, p4):
    def row(phase, a, b):
        # Below a tenth of a millisecond (a partition with nothing to move)
        # the ratio is timer noise.
        ratio = a / b if a is not None and b and max(a, b) >= MIN_RATED else None
        return {"case": label, "np": str(np_), "phase": phase, "om": fmt_s(a), "p4": fmt_s(b),
                "ratio": "-" if ratio is None else "%.2f" % ratio,
                "bar": "-" if ratio is None else ("yes" if ratio <= BAR else "no")}

    return [
        row("refine (p4est: from the leaf list)", om["refine"], p4["refine"]),
        row("balance", om["balance"], p4["balance"]),
        row("partition", om["partition"], p4["partition"]),
        row("mesh vs ghost+lnodes", om["mesh"], p4["mesh_lnodes"]),
        row("mesh vs ghost+p8est_nodes", om["mesh"], p4["mesh_nodes"]),
        row("total (with lnodes)", om["total"], p4["total"]),
    ]


def mem_row(label, np_, om, p4):
    n = om["balanced"]

    def bpl(b):
        return "-" if b is None else "%.0f" % (b * np_ / n)

    leaf_list = p4["rss_read"] - p4["rss_start"]
    return {
        "case": label, "np": str(np_),
        "om_peak": fmt_mib(om["peak"]), "om_bpl": bpl(om["peak"]),
        "om_surf": fmt_mib(om["surface"]), "om_nosurf_bpl": bpl(om["peak"] - om["surface"]),
        "p4_ln": fmt_mib(p4["rss_lnodes"]), "p4_ln_bpl": bpl(p4["rss_lnodes"]),
        "p4_list": fmt_mib(leaf_list), "p4_nolist_bpl": bpl(p4["rss_lnodes"] - leaf_list),
        "p4_nd": fmt_mib(p4["rss_nodes"]), "p4_nd_bpl": bpl(p4["rss_nodes"]),
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="\n\n".join(__doc__.split("\n\n")[1:]))
    ap.add_argument("--preset", choices=sorted(PRESETS), default="validation",
                    help="case list when --cases is not given: %s" % "; ".join(
                        "%s = %s" % kv for kv in sorted(PRESETS.items())))
    ap.add_argument("--cases", help="comma-separated SURFACE:LEVEL[:KEEP] or "
                    "SURFACE:LO-HI[:KEEP]; SURFACE is sphere, torus, a model in "
                    "../shared/data or a .stl path; KEEP all (default), inside or outside")
    ap.add_argument("--np", default="1,2", help="rank counts, e.g. 1,2 (default)")
    ap.add_argument("--repeat", type=int, default=3, metavar="K",
                    help="octmesh runs per measurement; medians are reported (default 3)")
    ap.add_argument("--p4est-repeat", type=int, metavar="K",
                    help="repeats inside each p4est run (default: --repeat)")
    ap.add_argument("--no-p4est-nodes", action="store_true",
                    help="leave out p8est_nodes_new (slow from about 10 M leaves)")
    ap.add_argument("--fit", default="0.7", help="octmesh --fit (default 0.7)")
    ap.add_argument("--max-mem-gib", type=float,
                    help="skip what is estimated to need more (default 90%% of RAM)")
    ap.add_argument("--markdown", metavar="FILE", help="also write the tables as Markdown")
    ap.add_argument("--json", metavar="FILE", help="also write every measurement as JSON")
    ap.add_argument("--no-build", action="store_true",
                    help="do not run cargo build --release and make -C tools/p4est_ref first")
    args = ap.parse_args()
    if args.p4est_repeat is None:
        args.p4est_repeat = args.repeat
    if args.repeat < 1 or args.p4est_repeat < 1:
        ap.error("--repeat and --p4est-repeat must be at least 1")
    nps = parse_nps(ap, args.np)
    cases = parse_cases(args.cases or PRESETS[args.preset], keep_field=True)
    limit = (args.max_mem_gib * GIB if args.max_mem_gib else 0.9 * mem_total_bytes()) or None

    env = mpi_env()
    info = prepare(env, args.no_build, "octmesh against p4est, phase by phase")
    print("  octmesh: median of %d runs; p4est: median of %d repeats in one run; "
          "seconds, max over ranks; ratio = octmesh / p4est, bar <= %.1f"
          % (args.repeat, args.p4est_repeat, BAR), flush=True)

    WORK.mkdir(parents=True, exist_ok=True)
    progress = Progress(PHASE_COLUMNS)
    count_rows, mem_rows, extra_rows, records = [], [], [], []
    mismatches, failures, notes = [], [], []
    p4_version = "?"
    for surface, level, keep in cases:
        name = surface_name(surface)
        label = case_label(name, level, keep)
        src = surface_arg(surface)
        if src is None:
            notes.append("skipped %s (%s)" % (label, missing_note(surface)))
            print("note: " + notes[-1], flush=True)
            continue
        tag = "%s_L%d_%s" % (name, level, keep)
        refined_file = WORK / (tag + "_refined.bin")
        stats_path = WORK / (tag + "_stats.json")
        p4_json = WORK / (tag + "_p4est.json")
        try:
            s = octmesh_stats(1, ["octree", src, "--level", level, "--fit", args.fit,
                                  "--balance", "corner", "--write-refined", refined_file],
                              stats_path, env)
            n_ref, n_bal = s["octants_refined"], s["octants_balanced"]
            lnodes_only = args.no_p4est_nodes
            if limit:
                need_om = OCTMESH_B_PER_LEAF * n_bal
                need_ln = P4EST_LNODES_B_PER_LEAF * n_bal
                need_nd = P4EST_NODES_B_PER_LEAF * n_bal
                list_all = 16 * n_ref * max(nps)
                if max(need_om, need_ln + list_all) > limit:
                    notes.append("skipped %s: %s balanced leaves need an estimated %.1f GiB, "
                                 "above %.1f GiB" % (label, fmt_int(n_bal), max(
                                     need_om, need_ln + list_all) / GIB, limit / GIB))
                    print("note: " + notes[-1], flush=True)
                    continue
                if not lnodes_only and need_nd + list_all > limit:
                    lnodes_only = True
                    notes.append("%s: p8est_nodes_new left out (estimated %.1f GiB)"
                                 % (label, (need_nd + list_all) / GIB))
                    print("note: " + notes[-1], flush=True)
            agreed_all = None
            for np_ in nps:
                om = octmesh_runs(src, level, keep, np_, args, env, stats_path)
                p4 = p4est_run(refined_file, np_, lnodes_only, args, env, p4_json)
                p4_version = p4["version"]
                agreed, bad = check_counts(keep, om, p4)
                agreed_all = agreed if agreed_all is None else [
                    a for a in agreed_all if a in agreed]
                for msg in bad:
                    mismatches.append("%s np %d: %s" % (label, np_, msg))
                    print("*** MISMATCH " + mismatches[-1] + " ***", flush=True)
                for row in phase_rows(label, np_, om, p4):
                    progress.add(row)
                mem_rows.append(mem_row(label, np_, om, p4))
                extra_rows.append({"case": label, "np": str(np_), "read": fmt_s(om["read"]),
                                   "classify": fmt_s(om["classify"])})
                records.append({"surface": name, "level": level, "keep": keep, "np": np_,
                                "fit": float(args.fit), "octmesh": om, "p4est": p4,
                                "mismatches": bad})
            count_rows.append({
                "case": label, "refined": fmt_int(om["refined"]),
                "balanced": fmt_int(om["balanced"]), "elements": fmt_int(om["elements"]),
                "indep": fmt_int(om["indep"]),
                "hanging": "%s + %s" % (fmt_int(om["face"]), fmt_int(om["edge"])),
                "agree": ", ".join(agreed_all or []) or "-",
            })
        except (RunError, OSError, KeyError, ValueError) as e:
            failures.append("%s: %s" % (label, e))
            print("FAILED " + failures[-1], flush=True)
        finally:
            # Leaf files are 16 B per leaf; drop each once its case is done.
            for f in (refined_file, stats_path, p4_json):
                f.unlink(missing_ok=True)

    rows = progress.rows
    print()
    print(text_table(rows, PHASE_COLUMNS) if rows else "(no results)")
    if count_rows:
        print()
        print(text_table(count_rows, COUNT_COLUMNS))
        print()
        print(text_table(mem_rows, MEM_COLUMNS))
        print()
        print(text_table(extra_rows, EXTRA_COLUMNS))
    if rows:
        met = sum(r["bar"] == "yes" for r in rows)
        rated = sum(r["bar"] != "-" for r in rows)
        print("\n%d of %d phase comparisons meet the bar (octmesh/p4est <= %.1f)"
              % (met, rated, BAR))
    if args.markdown:
        with open(args.markdown, "w") as f:
            f.write(header_line(info, "p4est %s. octmesh --fit %s, balance corner; octmesh "
                                "times are medians of %d runs, p4est times medians of %d "
                                "repeats; seconds, max over ranks." % (
                                    p4_version, args.fit, args.repeat, args.p4est_repeat)))
            f.write("\n\n" + markdown_table(rows, PHASE_COLUMNS) + "\n")
            f.write("\nCounts (the same on every rank count):\n\n")
            f.write(markdown_table(count_rows, COUNT_COLUMNS) + "\n")
            f.write("\nMemory (peak RSS per rank, max over ranks; B/leaf = peak x np / "
                    "balanced leaves):\n\n")
            f.write(markdown_table(mem_rows, MEM_COLUMNS) + "\n")
            f.write("\noctmesh phases without a p4est counterpart:\n\n")
            f.write(markdown_table(extra_rows, EXTRA_COLUMNS) + "\n")
            for note in notes:
                f.write("\nNote: %s.\n" % note)
        print("markdown written to %s" % args.markdown)
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"info": info, "records": records, "notes": notes}, f, indent=1)
        print("json written to %s" % args.json)
    for note in notes:
        print("note: " + note)
    for msg in failures:
        print("FAILED " + msg)
    for msg in mismatches:
        print("*** MISMATCH " + msg + " ***")
    if mismatches or failures:
        sys.exit(1)


if __name__ == "__main__":
    main()
