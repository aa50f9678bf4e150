#!/usr/bin/env python3
"""Hexahedral mesh construction of octmesh against p4est on the same octree.

For every case (surface, level) and rank count, `octmesh mesh` refines,
balances and meshes the surface-refined octree K times; its balanced leaves
are written once and rebuilt by tools/p4est_ref/octmesh_p4est, which times
p8est_ghost_new, p8est_nodes_new and p8est_lnodes_new (degree 1).

    python3 tools/bench/mesh_vs_p4est.py [--cases sphere:9,bunny:10]
        [--np 1,2] [--repeat 3] [--p4est-repeat K] [--no-p4est-nodes]
        [--markdown FILE]

What is summed:
  octmesh ghost+nodes = ghost + nodes + numbering + connectivity from
      `--stats`: ghost layer, node extraction with hanging-node detection,
      global numbering of the owned independent nodes, and the element
      connectivity with explicit hanging constraints. Summed per run; the
      median over the K runs is reported.
  p4est ghost+lnodes  = ghost + lnodes medians (p8est_ghost_new,
      p8est_lnodes_new with degree 1).
  p4est ghost+nodes   = ghost + nodes medians (p8est_ghost_new,
      p8est_nodes_new). --no-p4est-nodes leaves p8est_nodes_new out (the
      reference tool gets --balance edge, a no-op on corner-balanced leaves).
Every time is the maximum over the ranks. Peak RSS is the maximum over the
ranks; for p4est it is the whole process, so it includes p8est_nodes_new's
memory whenever that runs, and the input leaf list every rank holds.

Standard library only. Exits non-zero if a run fails or the two codes
disagree on the element, independent-node or hanging-node counts.
"""

import argparse
import json
import statistics
import sys
from pathlib import Path

sys.dont_write_bytecode = True  # keep tools/bench free of __pycache__
sys.path.insert(0, str(Path(__file__).resolve().parent))
from balance_vs_p4est import (  # noqa: E402  (shared helpers)
    DATA, MIB, OCTMESH, P4EST, WORK, RunError, fmt_s, mpi_env, parse_cases,
    parse_nps, prepare, run, surface_arg)

DEFAULT_CASES = [("sphere", 9), ("sphere", 10), ("sphere", 11), ("bunny", 10)]
OCTMESH_PHASES = ("ghost", "nodes", "numbering", "connectivity")

# (key, header); the Markdown table has exactly these columns.
COLUMNS = [
    ("surface", "surface"),
    ("level", "level"),
    ("np", "np"),
    ("elements", "elements"),
    ("indep", "independent nodes"),
    ("hanging", "hanging nodes (face+edge)"),
    ("om_mesh", "octmesh ghost+nodes [s]"),
    ("p4_ln", "p4est ghost+lnodes [s]"),
    ("ratio_ln", "ratio"),
    ("p4_nd", "p4est ghost+nodes (p8est_nodes) [s]"),
    ("ratio_nd", "ratio"),
    ("om_mib", "octmesh peak RSS MiB"),
    ("p4_mib", "p4est peak RSS MiB"),
]
# The text table also shows the ghost layers on their own.
TEXT_COLUMNS = COLUMNS[:7] + [("om_ghost", "octmesh ghost [s]"),
                              ("p4_ghost", "p4est ghost [s]")] + COLUMNS[7:]


def format_row(r):
    def ratio(p4, om):
        return "%.2f" % (p4 / om) if p4 is not None and om > 0 else "-"

    hang = "-"
    if r["face_hanging"] is not None:
        hang = "{:,} + {:,}".format(r["face_hanging"], r["edge_hanging"])
    return {
        "surface": r["surface"],
        "level": str(r["level"]),
        "np": str(r["np"]),
        "elements": "{:,}".format(r["elements"]),
        "indep": "{:,}".format(r["indep"]),
        "hanging": hang,
        "om_mesh": fmt_s(r["om_mesh"]),
        "om_ghost": fmt_s(r["om_ghost"]),
        "p4_ghost": fmt_s(r["p4_ghost"]),
        "p4_ln": fmt_s(r["p4_ln"]),
        "ratio_ln": ratio(r["p4_ln"], r["om_mesh"]),
        "p4_nd": fmt_s(r["p4_nd"]) if r["p4_nd"] is not None else "-",
        "ratio_nd": ratio(r["p4_nd"], r["om_mesh"]),
        "om_mib": "%.0f" % (r["om_rss"] / MIB),
        "p4_mib": "%.0f" % (r["p4_rss"] / MIB),
    }


def text_table(rows, columns):
    cells = [[h for _, h in columns]] + [[r[k] for k, _ in columns] for r in rows]
    widths = [max(len(c[i]) for c in cells) for i in range(len(columns))]
    lines = []
    for n, c in enumerate(cells):
        lines.append("  ".join(v.ljust(w) if i == 0 else v.rjust(w)
                               for i, (v, w) in enumerate(zip(c, widths))))
        if n == 0:
            lines.append("  ".join("-" * w for w in widths))
    return "\n".join(lines)


def markdown_table(rows, columns):
    head = [h for _, h in columns]
    lines = ["| " + " | ".join(head) + " |",
             "|" + "|".join(":---" if i == 0 else "---:" for i in range(len(head))) + "|"]
    for r in rows:
        lines.append("| " + " | ".join(r[k] for k, _ in columns) + " |")
    return "\n".join(lines)


def check_counts(r):
    """Messages for every count on which octmesh and p4est disagree."""
    bad = []

    def same(what, pairs):
        values = [v for _, v in pairs if v is not None]
        if len(set(values)) > 1:
            bad.append("%s: %s" % (what, ", ".join(
                "%s %s" % (n, "-" if v is None else v) for n, v in pairs)))

    same("elements", [("octmesh balanced", r["balanced"]),
                      ("octmesh elements", r["elements"]),
                      ("p4est in", r["p4_in"]),
                      ("p4est balanced", r["p4_balanced"])])
    same("independent nodes", [("octmesh", r["indep"]),
                               ("p4est lnodes_global", r["p4_lnodes"]),
                               ("p4est indep_nodes", r["p4_indep"])])
    same("face hanging nodes", [("octmesh", r["face_hanging"]),
                                ("p4est", r["p4_face"])])
    same("edge hanging nodes", [("octmesh", r["edge_hanging"]),
                                ("p4est", r["p4_edge"])])
    same("elements with hanging nodes", [("octmesh", r["with_hanging"]),
                                         ("p4est", r["p4_with_hanging"])])
    return bad


def bench_case(surface, level, nps, args, env, files):
    """Yields one result dict per np; raises RunError on failure."""
    src = surface_arg(surface)
    name = Path(surface).stem if surface.endswith(".stl") else surface
    leaves = WORK / ("%s_L%d_mesh_leaves.bin" % (name, level))
    stats = WORK / ("%s_L%d_mesh_stats.json" % (name, level))
    p4json = WORK / ("%s_L%d_mesh_p4est.json" % (name, level))
    files.extend([leaves, stats, p4json])
    # With --no-p4est-nodes the reference tool gets --balance edge: on leaves
    # that are already corner-balanced that balance changes nothing (the leaf
    # count is checked), and the tool then runs p8est_ghost_new (full) and
    # p8est_lnodes_new but not p8est_nodes_new, which needs corner balance.
    p4_balance = "edge" if args.no_p4est_nodes else args.balance
    written = False
    for np_ in nps:
        mpirun = ["mpirun", "-np", str(np_)]
        ghost_t, mesh_t, rss, counts = [], [], [], set()
        for k in range(args.repeat):
            cmd = mpirun + [str(OCTMESH), "mesh", src, "--level", str(level),
                            "--balance", args.balance, "--quiet", "--stats", str(stats)]
            if not written:
                cmd += ["--write-leaves", str(leaves)]
            run(cmd, env)
            written = True
            with open(stats) as f:
                s = json.load(f)
            t = s["timings"]
            ghost_t.append(t["ghost"])
            mesh_t.append(sum(t[p] for p in OCTMESH_PHASES))
            rss.append(s["peak_rss_bytes"])
            counts.add((s["octants_balanced"], s["elements"], s["independent_nodes"],
                        s["face_hanging_nodes"], s["edge_hanging_nodes"],
                        s["elements_with_hanging"]))
        if len(counts) != 1:
            raise RunError("octmesh counts differ between repeats: %s" % sorted(counts))
        n_bal, n_el, n_ind, n_face, n_edge, n_with = counts.pop()

        run(mpirun + [str(P4EST), "--in", str(leaves), "--balance", p4_balance,
                      "--nodes", "--json", str(p4json),
                      "--repeat", str(args.p4est_repeat)], env)
        with open(p4json) as f:
            p = json.load(f)
        pt = p["timings"]
        nodes_t = pt.get("nodes")
        yield {
            "surface": name, "level": level, "np": np_,
            "balanced": n_bal, "elements": n_el, "indep": n_ind,
            "face_hanging": n_face, "edge_hanging": n_edge, "with_hanging": n_with,
            "om_ghost": statistics.median(ghost_t),
            "om_mesh": statistics.median(mesh_t),
            "om_rss": statistics.median(rss),
            "p4_in": p["leaves_in"], "p4_balanced": p["leaves_balanced"],
            "p4_lnodes": p["lnodes_global"], "p4_indep": p.get("indep_nodes"),
            # p4est de-duplicates hanging nodes only up to 5 M leaves.
            "p4_face": p.get("face_hanging_nodes"),
            "p4_edge": p.get("edge_hanging_nodes"),
            "p4_with_hanging": p.get("lnodes_hanging_elements"),
            "p4_ghost": pt["ghost"],
            "p4_ln": pt["ghost"] + pt["lnodes"],
            "p4_nd": pt["ghost"] + nodes_t if nodes_t is not None else None,
            "p4_rss": p["peak_rss_bytes"],
            "p4_version": p.get("version", "?"),
        }


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", help="comma-separated SURFACE:LEVEL list, default "
                    "sphere:9,sphere:10,sphere:11,bunny:10 (SURFACE: sphere, torus, "
                    "a model name in ../shared/data or a .stl path)")
    ap.add_argument("--balance", default="corner", choices=["edge", "corner"],
                    help="balance kind (default corner; p8est_nodes_new needs corner)")
    ap.add_argument("--repeat", type=int, default=3, metavar="K",
                    help="octmesh runs per measurement; the median is reported (default 3)")
    ap.add_argument("--p4est-repeat", type=int, metavar="K",
                    help="repeats inside the p4est run (default: --repeat)")
    ap.add_argument("--no-p4est-nodes", action="store_true",
                    help="do not run p8est_nodes_new (slow at level 11); its "
                    "column shows '-'")
    ap.add_argument("--np", default="1,2", help="comma-separated rank counts (default 1,2)")
    ap.add_argument("--markdown", metavar="FILE", help="also write the table as Markdown")
    ap.add_argument("--no-build", action="store_true",
                    help="do not run cargo build --release and make -C tools/p4est_ref first")
    args = ap.parse_args()
    if args.p4est_repeat is None:
        args.p4est_repeat = args.repeat
    if args.repeat < 1 or args.p4est_repeat < 1:
        ap.error("--repeat and --p4est-repeat must be at least 1")
    nps = parse_nps(ap, args.np)
    cases = parse_cases(args.cases) if args.cases else DEFAULT_CASES

    env = mpi_env()
    info = prepare(env, args.no_build, "octmesh hexahedral mesh against p4est")
    print("  balance %s; octmesh median of %d runs, p4est median of %d repeats; "
          "times in seconds (max over ranks)" % (args.balance, args.repeat, args.p4est_repeat))
    print("  octmesh ghost+nodes = ghost + nodes + numbering + connectivity", flush=True)

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
                    lines = text_table(rows, TEXT_COLUMNS).splitlines()
                    if len(rows) == 1:
                        print(lines[0])
                        print(lines[1])
                    print(lines[-1], flush=True)
                    for msg in check_counts(r):
                        msg = "MISMATCH %s level %d np %d: %s" % (
                            r["surface"], level, r["np"], msg)
                        mismatches.append(msg)
                        print("*** " + msg + " ***", flush=True)
            except (RunError, OSError, KeyError, ValueError) as e:
                failures.append("%s:%d: %s" % (surface, level, e))
                print("FAILED %s:%d: %s" % (surface, level, e), flush=True)
            finally:
                # Leaf files are 16 B per leaf; drop each once its case is done.
                for f in files:
                    f.unlink(missing_ok=True)
                files.clear()
    finally:
        for f in files:
            f.unlink(missing_ok=True)

    print()
    print(text_table(rows, TEXT_COLUMNS) if rows else "(no results)")
    if args.markdown:
        with open(args.markdown, "w") as f:
            p4_times = ("medians of %d repeats" % args.p4est_repeat
                        if args.p4est_repeat > 1 else "from one run")
            f.write("Machine: %s. Date: %s. Commit: %s. p4est %s, %s. "
                    "Balance %s; octmesh times are medians of %d runs, p4est times "
                    "%s; all times in seconds, max over ranks. "
                    "octmesh ghost+nodes = ghost + nodes + numbering + connectivity. "
                    "Each ratio is the p4est time to its left over octmesh ghost+nodes. "
                    "p4est peak RSS includes p8est_nodes_new when it runs%s.\n\n"
                    % (info["machine"], info["date"], info["commit"], p4_version,
                       info["mpi"], args.balance, args.repeat, p4_times,
                       " (not run here: --no-p4est-nodes)" if args.no_p4est_nodes else ""))
            f.write(markdown_table(rows, COLUMNS) + "\n")
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
