#!/usr/bin/env python3
"""Time and memory of the octree + mesh pipeline against the number of leaves.

Runs `octmesh mesh SURFACE --level L --stats` (corner balance, keep all) for
a range of levels, on the built-in sphere and one model (levels 7-12 give
about 1e5 to 1.2e8 balanced leaves on the sphere), and draws a log-log PNG
of the time per phase and the peak RSS against the balanced leaves, with a
linear reference line, plus the cost per leaf (ns per leaf and rank:
time x np / leaves; bytes per leaf: peak RSS per rank x np / leaves), so
that "flat within 1.5x from 1e5 to 1e8" can be read off. The table and the
verdict (largest / smallest total ns per leaf per surface) are printed and
can be written as Markdown.

The verdict is given twice: over the medians of each size's runs, and over
their means. On a machine whose speed changes from one spell to the next,
the two answer different questions for short runs: a 10 s run is itself an
average over the spells it spans, and so is the mean of many 60 ms runs,
while their median is the speed of whichever spell held in most of them.

Phases: refine = construct + refine + the partition after it; balance =
balance + the partition after it; mesh = ghost + nodes + numbering +
connectivity; classify (inside/outside) apart; total = refine + balance +
classify + mesh (reading the surface does not depend on the level and is
left out). Times are seconds, max over ranks, medians of --repeat runs, or
more for short cases (--min-seconds); the repeats are rounds over all the
cases, and each case's runs are spread evenly over the rounds (a case with
3 runs out of 15 rounds runs in rounds 1, 6 and 11), so that every size
samples the same stretch of time and a slow spell of the machine does not
fall on a few sizes only.

Before each level the peak memory is estimated from the level below (leaves
x 4.2); a level that would not fit in --max-mem-gib (default 90% of RAM)
ends that surface's series.

    python3 tools/bench/scaling_plot.py --cases sphere:7-12,bunny:7-12 --png docs/scaling.png
    python3 tools/bench/scaling_plot.py --from-json target/bench/scaling.json --png docs/scaling.png

Needs matplotlib for the PNG (Debian: apt-get install python3-matplotlib;
run with /usr/bin/python3); --no-plot runs without it.
"""

import argparse
import json
import math
import sys
from pathlib import Path

sys.dont_write_bytecode = True  # keep tools/bench free of __pycache__
sys.path.insert(0, str(Path(__file__).resolve().parent))
from benchlib import (  # noqa: E402
    GIB, WORK, Progress, RunError, fmt_int, fmt_mib, fmt_s, header_line, markdown_table,
    median, mem_total_bytes, missing_note, mpi_env, octmesh_stats, parse_cases, parse_nps,
    prepare, surface_arg, surface_name)

DEFAULT_CASES = "sphere:7-12,bunny:7-12"
PHASES = ("refine", "balance", "classify", "mesh", "total")
GROWTH = 4.2  # leaves per level, a little above the surface's 4
FLAT = 1.5

COLUMNS = [
    ("surface", "surface"), ("level", "level"), ("np", "np"), ("leaves", "balanced leaves"),
    ("refine", "refine [s]"), ("balance", "balance [s]"), ("classify", "classify [s]"),
    ("mesh", "mesh [s]"), ("total", "total [s]"), ("ns", "total ns/leaf"),
    ("mean", "mean ns/leaf"),
    ("runs", "runs"), ("range", "ns/leaf over runs"),
    ("peak", "peak MiB/rank"), ("bpl", "B/leaf"),
]


# Most runs of one short case (see --min-seconds).
MAX_RUNS = 15


def run_once(src, level, np_, fit, env, stats_path):
    """One run of the pipeline: phase times (s), peak RSS and leaves."""
    s = octmesh_stats(np_, ["mesh", src, "--level", level, "--fit", fit,
                            "--balance", "corner"], stats_path, env)
    t, parts = s["timings"], s["partition_timings"]
    r = {
        "refine": t["construct"] + t["refine"] + parts["refined"],
        "balance": t["balance"] + parts["balanced"],
        "classify": t["classify"],
        "mesh": t["ghost"] + t["nodes"] + t["numbering"] + t["connectivity"],
        "peak": s["peak_rss_bytes"],
        "base": s["rss_after_read_bytes"],
        "leaves": s["octants_balanced"],
    }
    r["total"] = r["refine"] + r["balance"] + r["classify"] + r["mesh"]
    return r


def summarize(runs):
    """Medians over the runs of one case (whose leaf counts must agree)."""
    leaves = {r["leaves"] for r in runs}
    if len(leaves) != 1:
        raise RunError("leaf counts differ between repeats: %s" % sorted(leaves))
    out = {k: median([r[k] for r in runs]) for k in runs[0] if k != "leaves"}
    out["leaves"] = leaves.pop()
    # The spread of the runs, to be read against the 1.5x band.
    out["runs"] = len(runs)
    out["total_min"] = min(r["total"] for r in runs)
    out["total_max"] = max(r["total"] for r in runs)
    # The mean too: a long run averages the machine's slow and fast spells
    # within itself, and only the mean of many short runs does the same.
    out["total_mean"] = sum(r["total"] for r in runs) / len(runs)
    out["totals"] = [r["total"] for r in runs]
    return out


def table_row(r):
    n, np_ = r["leaves"], r["np"]
    return {"surface": r["surface"], "level": str(r["level"]), "np": str(np_),
            "leaves": fmt_int(n), **{p: fmt_s(r[p]) for p in PHASES},
            "ns": "%.0f" % (r["total"] * np_ / n * 1e9),
            "mean": ("%.0f" % (r["total_mean"] * np_ / n * 1e9) if "total_mean" in r else "-"),
            "runs": str(r.get("runs", "-")),
            "range": ("%.0f to %.0f" % (r["total_min"] * np_ / n * 1e9,
                                        r["total_max"] * np_ / n * 1e9)
                      if "total_min" in r else "-"),
            "peak": fmt_mib(r["peak"]), "bpl": "%.0f" % (r["peak"] * np_ / n)}


def verdicts(records, lo=1e5):
    """Per (surface, np): spread of total ns per leaf over runs with at least lo leaves."""
    out = []
    groups = {}
    for r in records:
        if r["leaves"] >= lo:
            groups.setdefault((r["surface"], r["np"]), []).append(r)
    for (surface, np_), rs in sorted(groups.items()):
        ns = [r["total"] * np_ / r["leaves"] * 1e9 for r in rs]
        bpl = [r["peak"] * np_ / r["leaves"] for r in rs]
        spread = max(ns) / min(ns)
        line = ("%s np %d, %s to %s leaves: total %.0f to %.0f ns/leaf (medians, x%.2f, %s 1.5x)" % (
            surface, np_, fmt_int(min(r["leaves"] for r in rs)),
            fmt_int(max(r["leaves"] for r in rs)), min(ns), max(ns), spread,
            "within" if spread <= FLAT else "NOT within"))
        if all("total_mean" in r for r in rs):
            mean = [r["total_mean"] * np_ / r["leaves"] * 1e9 for r in rs]
            ms = max(mean) / min(mean)
            line += "; %.0f to %.0f (means, x%.2f, %s)" % (
                min(mean), max(mean), ms, "within" if ms <= FLAT else "NOT within")
        out.append(line + "; peak %.0f to %.0f B/leaf" % (min(bpl), max(bpl)))
    return out


def plot(records, png, title):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(2, 2, figsize=(11, 8))
    series = {}
    for r in records:
        series.setdefault((r["surface"], r["np"]), []).append(r)
    markers = "osd^v<>"
    colours = {"refine": "tab:blue", "balance": "tab:orange", "classify": "tab:purple",
               "mesh": "tab:green", "total": "black"}
    all_n = sorted(r["leaves"] for r in records)
    # The phases of the series reaching the most leaves go on the cost panel.
    detail = max(series, key=lambda k: max(r["leaves"] for r in series[k])) if series else None
    for i, ((surface, np_), rs) in enumerate(sorted(series.items())):
        rs = sorted(rs, key=lambda r: r["leaves"])
        n = [r["leaves"] for r in rs]
        m = markers[i % len(markers)]
        tag = "%s np %d" % (surface, np_)
        colour = "C%d" % i
        for p in PHASES:
            total = p == "total"
            ax[0][0].loglog(n, [r[p] for r in rs], "-" if total else "--", marker=m,
                            color=colours[p], linewidth=2 if total else 1, markersize=4,
                            label="%s %s" % (tag, p) if total or (surface, np_) == detail
                            else None)
        # Cost per leaf: every series' total, the phases of one.
        cost = [r["total"] * np_ / r["leaves"] * 1e9 for r in rs]
        ax[1][0].semilogx(n, cost, "-", marker=m, color=colour, linewidth=2,
                          label="%s total" % tag)
        big = [c for c, r in zip(cost, rs) if r["leaves"] >= 1e5]
        if big:
            ax[1][0].fill_between([min(n), max(n)], min(big), FLAT * min(big), color=colour,
                                  alpha=0.12, label="%s: 1.5x its smallest" % tag)
        if (surface, np_) == detail:
            for p in PHASES[:-1]:
                ax[1][0].semilogx(n, [r[p] * np_ / r["leaves"] * 1e9 for r in rs], "--",
                                  marker=m, color=colours[p], markersize=3, linewidth=1,
                                  label="%s %s" % (tag, p))
        ax[0][1].loglog(n, [r["peak"] / GIB for r in rs], "-", marker=m, color=colour,
                        label=tag)
        ax[1][1].semilogx(n, [r["peak"] * np_ / r["leaves"] for r in rs], "-", marker=m,
                          color=colour, label=tag)
    # Linear reference lines through the middle of the data.
    if all_n:
        lo, hi = all_n[0], all_n[-1]
        mid = [r for r in records if r["leaves"] == all_n[len(all_n) // 2]][0]
        for a, key, scale in ((ax[0][0], "total", 1.0), (ax[0][1], "peak", 1.0 / GIB)):
            k = mid[key] * scale / mid["leaves"]
            a.loglog([lo, hi], [k * lo, k * hi], ":", color="grey", label="linear")
    ax[0][0].set(title="time per phase", xlabel="balanced leaves", ylabel="seconds (max over ranks)")
    ax[0][1].set(title="peak RSS per rank", xlabel="balanced leaves", ylabel="GiB")
    ax[1][0].set(title="cost per leaf (time x np / leaves), band: flat within 1.5x", xlabel="balanced leaves",
                 ylabel="ns per leaf")
    ax[1][1].set(title="memory per leaf (peak x np / leaves)", xlabel="balanced leaves",
                 ylabel="bytes per leaf")
    ax[1][0].set_ylim(bottom=0)
    ax[1][1].set_ylim(bottom=0)
    for a in ax.flat:
        a.grid(True, which="both", alpha=0.3)
        a.legend(fontsize=7)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    Path(png).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=80)
    print("plot written to %s (%d bytes)" % (png, Path(png).stat().st_size))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="\n\n".join(__doc__.split("\n\n")[1:]))
    ap.add_argument("--cases", default=DEFAULT_CASES,
                    help="SURFACE:LO-HI list (default %s)" % DEFAULT_CASES)
    ap.add_argument("--np", default="1", help="rank counts (default 1)")
    ap.add_argument("--repeat", type=int, default=1, metavar="K",
                    help="runs per point, median reported (default 1)")
    ap.add_argument("--min-seconds", type=float, default=5.0, metavar="S",
                    help="give short cases more runs, up to S seconds of pipeline each "
                    "(at most %d runs; default 5)" % MAX_RUNS)
    ap.add_argument("--fit", default="0.7", help="octmesh --fit (default 0.7)")
    ap.add_argument("--max-mem-gib", type=float,
                    help="stop a series before a level estimated to need more "
                    "(default 90%% of RAM, over all ranks)")
    ap.add_argument("--png", default="target/bench/scaling.png", help="the plot")
    ap.add_argument("--title", default="", help="extra text for the plot title")
    ap.add_argument("--markdown", metavar="FILE", help="also write the table as Markdown")
    ap.add_argument("--json", metavar="FILE", help="also write the measurements as JSON")
    ap.add_argument("--from-json", metavar="FILE", help="plot earlier measurements, run nothing")
    ap.add_argument("--no-plot", action="store_true", help="no PNG (no matplotlib needed)")
    ap.add_argument("--no-build", action="store_true", help="do not run cargo build first")
    args = ap.parse_args()

    if args.from_json:
        with open(args.from_json) as f:
            saved = json.load(f)
        records, info = saved["records"], saved["info"]
    else:
        records, info = run_all(ap, args)
    rows = [table_row(r) for r in records]
    lines = verdicts(records)
    for line in lines:
        print(line)
    title = "octmesh mesh pipeline (corner balance, keep all), %s; commit %s, %s" % (
        info["machine"].split(",")[0], info["commit"].split()[0], info["date"][:10])
    if args.title:
        title += "\n" + args.title
    if args.markdown:
        with open(args.markdown, "w") as f:
            f.write(header_line(info, "octmesh --fit %s, corner balance, keep all; seconds, "
                                "max over ranks." % args.fit) + "\n\n")
            f.write(markdown_table(rows, COLUMNS) + "\n\n")
            for line in lines:
                f.write("- %s\n" % line)
        print("markdown written to %s" % args.markdown)
    if args.json and not args.from_json:
        with open(args.json, "w") as f:
            json.dump({"info": info, "records": records}, f, indent=1)
    if not args.no_plot and records:
        plot(records, args.png, title)


def run_all(ap, args):
    nps = parse_nps(ap, args.np)
    cases = parse_cases(args.cases)
    limit = args.max_mem_gib * GIB if args.max_mem_gib else 0.9 * mem_total_bytes()
    env = mpi_env()
    info = prepare(env, args.no_build, "octmesh pipeline scaling with the number of leaves",
                   need_p4est=False)
    WORK.mkdir(parents=True, exist_ok=True)
    stats_path = WORK / "scaling_stats.json"
    progress = Progress(COLUMNS)
    # Repeats go round all the cases, rather than one case at a time, so
    # that a slow spell of a shared machine spreads over every size instead
    # of tilting the cost per leaf of a few.
    runs, stopped = {}, set()
    try:
        print("round 1:", flush=True)
        for surface, level in cases:
            name = surface_name(surface)
            src = surface_arg(surface)
            if src is None:
                print("note: skipped %s level %d (%s)" % (name, level, missing_note(surface)))
                continue
            for np_ in nps:
                if (name, np_) in stopped:
                    continue
                prev = runs.get((name, level - 1, np_))
                if prev and limit:
                    p = prev[0][1]
                    need = np_ * (p["base"] + (p["peak"] - p["base"]) * GROWTH)
                    if need > limit:
                        print("note: %s np %d stops at level %d: level %d would need about "
                              "%.1f GiB (limit %.1f)" % (name, np_, level - 1, level,
                                                        need / GIB, limit / GIB), flush=True)
                        stopped.add((name, np_))
                        continue
                r = run_once(src, level, np_, args.fit, env, stats_path)
                runs[(name, level, np_)] = [(src, r)]
                progress.add(table_row({"surface": name, "level": level, "np": np_, **r}))
        # A short case gets more runs, up to --min-seconds of pipeline time
        # (at most MAX_RUNS): a single descheduling moves a 60 ms run by
        # more than the 1.5x band allows.
        want = {key: max(args.repeat, min(MAX_RUNS, math.ceil(
            args.min_seconds / max(done[0][1]["total"], 1e-3))))
            for key, done in runs.items()}
        rounds = max(want.values(), default=1)
        for k in range(1, rounds):
            print("round %d of %d" % (k + 1, rounds), flush=True)
            for key, done in runs.items():
                # Spread over all rounds, not packed into the first ones:
                # otherwise the short cases alone would sample the last
                # minutes of the machine.
                if len(done) < math.ceil((k + 1) * want[key] / rounds):
                    src = done[0][0]
                    name, level, np_ = key
                    done.append((src, run_once(src, level, np_, args.fit, env, stats_path)))
        records = []
        for (name, level, np_), done in runs.items():
            records.append({"surface": name, "level": level, "np": np_,
                            **summarize([r for _, r in done])})
        if rounds > 1:
            print("medians of %d to %d runs:" % (min(want.values()), rounds))
            final = Progress(COLUMNS)
            for r in records:
                final.add(table_row(r))
    except (RunError, OSError, KeyError, ValueError) as e:
        print("FAILED: %s" % e)
        sys.exit(1)
    finally:
        stats_path.unlink(missing_ok=True)
    return records, info


if __name__ == "__main__":
    main()
