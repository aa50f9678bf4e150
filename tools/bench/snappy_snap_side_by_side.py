#!/usr/bin/env python3
"""snappyHexMesh's snap stage and octmesh's snap side by side on one specification (issue 24).

The specification is the one of snappy_side_by_side.py (a surface in a background box of cubic
cells, a surface level, a wake box and a distance band; the fluid outside kept). For each rank
count, in target/bench/snappy_snap_side_by_side:

  snappyHexMesh  blockMesh, [decomposePar,] snappyHexMesh -overwrite [-parallel] with
                 castellatedMesh true, snap true, addLayers false (the snapControls and
                 meshQualityControls of snappy_side_by_side.py); the stage times are read from
                 its log ("Mesh refined in", "Mesh snapped in");
  octmesh        mpirun -np N octmesh mesh ... --snap --quality --openfoam DIR; the phase
                 'snap' of --stats is the snap stage (surface nodes, scale-back, relaxation).

Then checkMesh -allGeometry on both (maximum non-orthogonality, maximum skewness, the failed
checks), and, on the 1-rank cases, the scaled Jacobian of every cell corner computed here from
the polyMesh (the meshes are converted to ASCII with foamFormatConvert after the timed runs),
over the cells that are hexahedra there (six quadrilateral faces, eight vertices; the cells at
2:1 steps have split faces in both tools and are left out): at each of the eight corners the
triple product of the three unit edge vectors, signed so that a corner of a valid convex cell
is positive (Knupp's definition, which octmesh's --quality uses on all its elements, hanging
ones included). Both meshes are measured by the same code; octmesh's own figure from --stats
is printed beside it.

Timings: the whole command (wall, and user + system CPU summed over ranks) as in
snappy_side_by_side.py, and the snap stage alone: snappyHexMesh's own "Mesh snapped in" against
octmesh's phase 'snap' (max over ranks). The ratio of the stage times is the issue's measure
(at least 20 times faster).

    python3 tools/bench/snappy_snap_side_by_side.py --level 5 --np 1,2 --markdown target/bench/snap.md

Standard library only; needs OpenFOAM, Open MPI and /usr/bin/time like snappy_side_by_side.py.
"""

import argparse
import json
import math
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import benchlib as bl
import snappy_side_by_side as sbs

SCRATCH = bl.WORK / "snappy_snap_side_by_side"


def check_mesh_geometry(np_, case, env, log):
    """checkMesh -allGeometry: cells, max non-orthogonality, max skewness and the verdict
    ('Mesh OK' or the failed checks' names)."""
    cmd = ["checkMesh", "-case", case, "-allGeometry"]
    if np_ > 1:
        cmd = bl.mpirun(np_) + cmd + ["-parallel"]
    with open(log, "w") as f:
        subprocess.run([str(c) for c in cmd], env=env, stdout=f, stderr=subprocess.STDOUT)
    text = Path(log).read_text(errors="replace")
    num = lambda pat: (lambda m: float(m.group(1)) if m else None)(re.search(pat, text, re.M))
    cells = num(r"^\s*cells:\s+(\d+)")
    failed = [re.sub(r"\s+", " ", l.strip(" *")).split(",")[0].split(" found")[0]
              for l in text.splitlines() if l.lstrip().startswith("***")]
    verdict = "Mesh OK" if "Mesh OK." in text else "failed: " + "; ".join(failed)
    return {"cells": int(cells) if cells is not None else None,
            "non_ortho_max": num(r"non-orthogonality Max:\s+([-\d.eE+]+)"),
            "skewness_max": num(r"Max skewness = ([-\d.eE+]+)"),
            "check": verdict}


# ---------------------------------------------------------------- scaled Jacobians of a polyMesh

def _list_body(path):
    """The entries of an ASCII OpenFOAM list file (points, faces, owner, neighbour)."""
    text = Path(path).read_text()
    text = text[text.index("}", text.index("FoamFile")) + 1:]
    at = text.index("\n(")
    n = int(text[:at].split()[-1])
    return text[at + 3:].split("\n")[:n]


def polymesh_scaled_jacobians(mesh_dir):
    """(min, histogram in tenths over [0, 1] with a bin for <= 0, corners, hexahedra) of the
    corner scaled Jacobians of the hexahedral cells of the ASCII polyMesh in mesh_dir."""
    pts = [tuple(map(float, l.strip("()").split())) for l in _list_body(mesh_dir / "points")]
    faces = [list(map(int, l[l.index("(") + 1:-1].split())) for l in _list_body(mesh_dir / "faces")]
    owner = list(map(int, _list_body(mesh_dir / "owner")))
    neigh = list(map(int, _list_body(mesh_dir / "neighbour")))
    ncells = max(max(owner), max(neigh) if neigh else 0) + 1
    # Each cell's faces, ordered so that the normal points out of the cell.
    cell_faces = [[] for _ in range(ncells)]
    for f, o in enumerate(owner):
        cell_faces[o].append(faces[f])
    for f, n in enumerate(neigh):
        cell_faces[n].append(faces[f][::-1])
    sub = lambda a, b: (a[0] - b[0], a[1] - b[1], a[2] - b[2])
    norm = lambda a: math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    cross = lambda a, b: (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])
    dot = lambda a, b: a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    worst, corners = 1.0, 0
    hist = [0] * 11
    hexes = 0
    for fl in cell_faces:
        # Hexahedra only (six quadrilaterals, eight vertices): at the split faces of a 2:1
        # step a vertex's three edges are not found from the cell's faces alone.
        if len(fl) != 6 or any(len(f) != 4 for f in fl) or len({v for f in fl for v in f}) != 8:
            continue
        hexes += 1
        # Outgoing edges of each vertex within the cell, and one outward face loop through it.
        nbrs, loop = {}, {}
        for face in fl:
            k = len(face)
            for i, v in enumerate(face):
                nxt, prv = face[(i + 1) % k], face[i - 1]
                nbrs.setdefault(v, set()).update((nxt, prv))
                loop.setdefault(v, (nxt, prv))
        for v, ns in nbrs.items():
            if len(ns) != 3:
                continue
            p = pts[v]
            e = {u: sub(pts[u], p) for u in ns}
            ln = {u: norm(e[u]) for u in ns}
            if min(ln.values()) == 0.0:
                j = 0.0
            else:
                nxt, prv = loop[v]
                third = [u for u in ns if u != nxt and u != prv]
                if len(third) != 1:
                    continue
                t = third[0]
                # Outward face loop: (next - v) x (prev - v) points out, the third edge in.
                j = -dot(cross(e[nxt], e[prv]), e[t]) / (ln[nxt] * ln[prv] * ln[t])
            corners += 1
            worst = min(worst, j)
            hist[0 if j <= 0 else min(10, 1 + int(j * 10))] += 1
    return worst, hist, corners, hexes


def convert_to_ascii(case, env, log):
    """Rewrites case's polyMesh in ASCII (controlDict writeFormat ascii, foamFormatConvert)."""
    cd = case / "system" / "controlDict"
    text = cd.read_text() if cd.exists() else ""
    if "writeFormat" in text:
        text = re.sub(r"writeFormat\s+\w+;", "writeFormat ascii;", text)
    else:
        text = (sbs.HEADER % "controlDict"
                + "application none; startFrom startTime; startTime 0; stopAt endTime; endTime 1;\n"
                + "deltaT 1; writeControl timeStep; writeInterval 1; writeFormat ascii;\n")
    if "writePrecision" not in text:
        text += "writePrecision 17;\n"
    cd.write_text(text)
    sbs.timed(["foamFormatConvert", "-case", case, "-constant"], env, SCRATCH, log)


# ---------------------------------------------------------------- the runs

def stage_times(log):
    """snappyHexMesh's stage times from its log: {'refine': s, 'snap': s, 'total': s}."""
    text = Path(log).read_text(errors="replace")
    out = {}
    for key, label in (("refine", "Mesh refined in"), ("snap", "Mesh snapped in"),
                       ("total", "Finished meshing in")):
        m = re.search(label + r"\s*=\s*([\d.eE+-]+)", text)
        if m:
            out[key] = float(m.group(1))
    return out


def run_snappy(np_, spec, runs, fenv, logs):
    case = SCRATCH / ("snappy_np%d" % np_)
    results = []
    for i in range(runs):
        sbs.write_snappy_case(case, spec, np_, snap=True)
        total, cpu, peak = 0.0, 0.0, []
        stages = {}
        for label, cmd in sbs.snappy_commands(np_, case):
            prefix = logs / ("rss_%s" % label)
            mpi = np_ if cmd[0] == "mpirun" else 0
            inner = cmd[3:] if mpi else cmd
            log = logs / ("snappy_np%d_%s_%d.log" % (np_, label, i))
            total += sbs.timed(sbs.with_rss(mpi, inner, prefix), fenv, SCRATCH, log)
            r, c = sbs.read_rss(prefix, mpi)
            cpu += sum(c)
            if label == "snappyHexMesh":
                peak = r
                stages = stage_times(log)
        results.append({"wall": total, "cpu": cpu, "rss": peak, "stages": stages,
                        "load": os.getloadavg()[0]})
        print("    snappyHexMesh np %d run %d: %.2f s, CPU %.2f s, stages %s (load %.1f)" % (
            np_, i + 1, total, cpu, ", ".join("%s %.2f" % kv for kv in stages.items()),
            results[-1]["load"]), flush=True)
    return case, results


def run_octmesh(np_, spec, runs, env, logs):
    case = SCRATCH / ("octmesh_np%d" % np_)
    stats_path = SCRATCH / ("octmesh_np%d.json" % np_)
    args = sbs.octmesh_args(spec, case, stats_path) + ["--snap", "--quality"]
    results = []
    for i in range(runs):
        if case.exists():
            shutil.rmtree(case)
        prefix = logs / "rss_octmesh"
        cmd = sbs.with_rss(np_, [bl.OCTMESH] + args, prefix)
        t = sbs.timed(cmd, env, bl.ROOT, logs / ("octmesh_np%d_%d.log" % (np_, i)))
        r, c = sbs.read_rss(prefix, np_)
        with open(stats_path) as fh:
            stats = json.load(fh)
        results.append({"wall": t, "cpu": sum(c), "rss": r, "stats": stats,
                        "load": os.getloadavg()[0]})
        tim = stats.get("timings", {})
        print("    octmesh np %d run %d: %.3f s, CPU %.3f s, snap %.3f s (load %.1f)" % (
            np_, i + 1, t, sum(c), tim.get("snap", float("nan")), results[-1]["load"]), flush=True)
    return case, args, results


def median_run(results, key):
    order = sorted(range(len(results)), key=lambda j: key(results[j]))
    return results[order[(len(order) - 1) // 2]]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--surface", default=str(bl.DATA / "bunny.stl"))
    ap.add_argument("--box", default="-1.5,-1,-1,2.5,1,1")
    ap.add_argument("--roots", default="16,8,8")
    ap.add_argument("--level", type=int, default=5, help="surface level L (default 5)")
    ap.add_argument("--wake", default="0.5,-0.4,-0.4,2,0.4,0.4")
    ap.add_argument("--wake-level", type=int, help="default L-2")
    ap.add_argument("--band", type=float, default=0.05)
    ap.add_argument("--band-level", type=int, help="default L-1")
    ap.add_argument("--location", default="-1.2345,0.7123,0.6789")
    ap.add_argument("--np", default="1,2")
    ap.add_argument("--octmesh-runs", type=int, default=3)
    ap.add_argument("--snappy-runs", type=int, default=1)
    ap.add_argument("--no-jacobian", action="store_true",
                    help="skip the scaled Jacobians computed from the polyMeshes")
    ap.add_argument("--foam-bashrc", default="/usr/share/openfoam/etc/bashrc")
    ap.add_argument("--no-build", action="store_true")
    ap.add_argument("--markdown")
    ap.add_argument("--json")
    a = ap.parse_args()

    lo_hi = sbs.floats(ap, a.box, 6, "--box")
    wake = sbs.floats(ap, a.wake, 6, "--wake")
    spec = {
        "surface": a.surface, "name": bl.surface_name(a.surface),
        "lo": lo_hi[:3], "hi": lo_hi[3:], "roots": sbs.ints(ap, a.roots, 3, "--roots"),
        "level": a.level, "wake_lo": wake[:3], "wake_hi": wake[3:],
        "wake_level": a.level - 2 if a.wake_level is None else a.wake_level,
        "band": a.band, "band_level": a.level - 1 if a.band_level is None else a.band_level,
        "location": sbs.floats(ap, a.location, 3, "--location"),
    }
    if not os.path.isfile(a.surface):
        sys.exit("missing %s" % a.surface)
    nps = bl.parse_nps(ap, a.np)
    env = bl.mpi_env()
    info = bl.prepare(env, a.no_build, "snappyHexMesh (castellated + snap) and octmesh --snap",
                      need_p4est=False)
    fenv = sbs.foam_env(a.foam_bashrc)
    sbs.SCRATCH = SCRATCH  # the helpers run their commands from here
    SCRATCH.mkdir(parents=True, exist_ok=True)
    logs = SCRATCH / "logs"
    logs.mkdir(exist_ok=True)

    rows, records = [], []
    for np_ in nps:
        scase, sres = run_snappy(np_, spec, a.snappy_runs, fenv, logs)
        ocase, oargs, ores = run_octmesh(np_, spec, a.octmesh_runs, env, logs)
        print("  octmesh: mpirun -np %d %s %s" % (np_, bl.OCTMESH.relative_to(bl.ROOT),
                                                  " ".join(map(str, oargs))), flush=True)
        sq = check_mesh_geometry(np_, scase, fenv, logs / ("check_snappy_np%d.log" % np_))
        oq = check_mesh_geometry(np_, ocase, fenv, logs / ("check_octmesh_np%d.log" % np_))
        sj = oj = None
        if np_ == 1 and not a.no_jacobian:
            convert_to_ascii(scase, fenv, logs / "convert_snappy.log")
            convert_to_ascii(ocase, fenv, logs / "convert_octmesh.log")
            sj = polymesh_scaled_jacobians(scase / "constant" / "polyMesh")
            oj = polymesh_scaled_jacobians(ocase / "constant" / "polyMesh")
        sm = median_run(sres, lambda r: r["stages"].get("snap", r["wall"]))
        om = median_run(ores, lambda r: r["stats"]["timings"].get("snap", 0.0))
        s_snap = sm["stages"].get("snap")
        o_snap = om["stats"]["timings"].get("snap")
        o_q = om["stats"].get("quality", {})
        snap_report = om["stats"].get("snap", {})
        rec = {"np": np_, "snappy": {"runs": sres, "check": sq, "jacobian": sj},
               "octmesh": {"runs": [{k: v for k, v in r.items() if k != "stats"} for r in ores],
                           "timings": om["stats"].get("timings"), "quality": o_q,
                           "snap": snap_report, "check": oq, "jacobian": oj}}
        records.append(rec)
        fmt = lambda x, f="%.3g": "-" if x is None else f % x
        jac = lambda j: "-" if j is None else "%.3f (%s hexahedra; %s of %s corners <= 0.1)" % (
            j[0], bl.fmt_int(j[3]), bl.fmt_int(j[1][0] + j[1][1]), bl.fmt_int(j[2]))
        rows.append({"np": str(np_), "tool": "snappyHexMesh", "cells": bl.fmt_int(sq["cells"]),
                     "snap": fmt(s_snap, "%.2f"), "rest": fmt(sm["stages"].get("refine"), "%.2f"),
                     "wall": "%.2f" % sm["wall"], "cpu": "%.2f" % sm["cpu"],
                     "jac": jac(sj), "own": "-",
                     "nonortho": fmt(sq["non_ortho_max"], "%.1f"),
                     "skew": fmt(sq["skewness_max"], "%.2f"), "check": sq["check"], "ratio": ""})
        ratio = ""
        if s_snap and o_snap:
            ratio = "%.1fx" % (s_snap / o_snap)
        rows.append({"np": str(np_), "tool": "octmesh", "cells": bl.fmt_int(oq["cells"]),
                     "snap": fmt(o_snap, "%.3f"),
                     "rest": "%.2f" % (sum(om["stats"]["timings"].values()) - (o_snap or 0.0)),
                     "wall": "%.2f" % om["wall"], "cpu": "%.2f" % om["cpu"],
                     "jac": jac(oj), "own": fmt(o_q.get("scaled_jacobian_min"), "%.3f"),
                     "nonortho": fmt(oq["non_ortho_max"], "%.1f"),
                     "skew": fmt(oq["skewness_max"], "%.2f"), "check": oq["check"], "ratio": ratio})

    cols = [("np", "np"), ("tool", "tool"), ("cells", "cells"),
            ("snap", "snap stage s"), ("rest", "rest s (snappy: castellation)"),
            ("wall", "wall s"), ("cpu", "CPU s"),
            ("jac", "min scaled Jacobian (polyMesh hexahedra)"), ("own", "octmesh --quality min"),
            ("nonortho", "max non-ortho (checkMesh)"), ("skew", "max skewness (checkMesh)"),
            ("check", "checkMesh -allGeometry"), ("ratio", "snap stage snappy / octmesh")]
    print()
    print(bl.text_table(rows, cols))
    for r in records:
        print("  np %d: octmesh phases %s; snap report %s" % (
            r["np"], ", ".join("%s %.2f" % kv for kv in sorted(
                r["octmesh"]["timings"].items(), key=lambda kv: -kv[1]) if kv[1] >= 0.01),
            r["octmesh"]["snap"]))
        for tool in ("snappy", "octmesh"):
            j = r[tool]["jacobian"]
            if j:
                print("  np %d %s corner scaled Jacobian histogram (<=0, then tenths of (0, 1]): %s"
                      % (r["np"], tool, j[1]))
    if a.markdown:
        md = bl.header_line(info) + "\n\n" + bl.markdown_table(rows, cols, left=("tool", "check", "jac")) + "\n"
        Path(a.markdown).write_text(md)
        print("wrote %s" % a.markdown)
    if a.json:
        with open(a.json, "w") as fh:
            json.dump({"info": info, "spec": spec, "results": records}, fh, indent=1)
        print("wrote %s" % a.json)


if __name__ == "__main__":
    try:
        main()
    except bl.RunError as e:
        sys.exit(str(e))
