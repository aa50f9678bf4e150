#!/usr/bin/env python3
"""snappyHexMesh's castellated stage and octmesh side by side on one specification (issue 21).

The specification: a surface (default the bunny) in a background box split into NX x NY x NZ
cubic cells, surface level L, a wake box at level LBOX (mode inside) and a distance band D at
level LBAND. Both tools get the same box, the same cubic background cells and the same levels
(octmesh's levels count from its root cells as snappyHexMesh's count from the background cells).

For each rank count (default 1 and 2), in a scratch directory under target/bench/snappy_side_by_side:

  snappyHexMesh  blockMesh, [decomposePar,] snappyHexMesh -overwrite [-parallel] (castellated
                 only: snap and addLayers false, nCellsBetweenLevels 1, resolveFeatureAngle 180);
  octmesh        [mpirun -np N] octmesh mesh SURFACE --box ... --roots ... --level L
                 --region box:...:LBOX --distance D:LBAND --keep outside --openfoam DIR
                 (alone on one rank, as snappyHexMesh runs serially)

and measures the wall time of the whole command (reading the STL to the written case; for
snappyHexMesh the sum of blockMesh, decomposePar and snappyHexMesh), the peak RSS and the user +
system CPU time of every rank (/usr/bin/time, one file per rank: the table gives the largest rank's
and the summed RSS, and the CPU time summed over ranks, steadier than wall time on a busy machine), the
cells (checkMesh's count for both, octmesh's stats 'elements' too) and checkMesh's verdict.
octmesh is run --octmesh-runs times (median), snappyHexMesh --snappy-runs times (median).

Both cases are binary (controlDict writeFormat binary for snappyHexMesh, octmesh's default).

Needs OpenFOAM (sourced from /usr/share/openfoam/etc/bashrc, or --foam-bashrc), Open MPI and
/usr/bin/time. Standard library only.

    python3 tools/bench/snappy_side_by_side.py --np 1,2 --markdown target/bench/snappy.md
"""

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import benchlib as bl

SCRATCH = bl.WORK / "snappy_side_by_side"
TIME = "/usr/bin/time"


def floats(ap, text, n, what):
    try:
        v = [float(x) for x in text.split(",")]
    except ValueError:
        v = []
    if len(v) != n:
        ap.error("%s expects %d comma-separated numbers" % (what, n))
    return v


def ints(ap, text, n, what):
    try:
        v = [int(x) for x in text.split(",")]
    except ValueError:
        v = []
    if len(v) != n or min(v) < 1:
        ap.error("%s expects %d comma-separated positive integers" % (what, n))
    return v


def foam_env(bashrc):
    """The environment after sourcing OpenFOAM's bashrc, with the MPI settings of benchlib."""
    p = subprocess.run(["bash", "-c", "set +u; source %s >/dev/null 2>&1; env -0" % bashrc],
                       capture_output=True)
    if p.returncode != 0:
        sys.exit("could not source %s" % bashrc)
    env = bl.mpi_env()
    for item in p.stdout.split(b"\0"):
        k, sep, v = item.decode(errors="replace").partition("=")
        if sep and k and not k.startswith("BASH_FUNC"):
            env[k] = v
    for k, v in bl.mpi_env().items():
        if k.startswith("OMPI_"):
            env[k] = v
    return env


def timed(cmd, env, cwd, log):
    """Runs cmd (stdout and stderr to log), returns its wall time; raises RunError on failure."""
    t0 = time.perf_counter()
    with open(log, "w") as f:
        p = subprocess.run([str(c) for c in cmd], env=env, cwd=cwd, stdout=f,
                           stderr=subprocess.STDOUT)
    t = time.perf_counter() - t0
    if p.returncode != 0:
        tail = Path(log).read_text(errors="replace").strip().splitlines()[-12:]
        raise bl.RunError("command failed (exit %d): %s\n    %s"
                          % (p.returncode, " ".join(map(str, cmd)), "\n    ".join(tail)))
    return t


def with_rss(np_, cmd, prefix):
    """cmd under mpirun -np np_ (np_ > 0) or alone (np_ == 0), each process under
    /usr/bin/time writing its peak RSS (KiB) and user and system CPU seconds to prefix.RANK."""
    if np_ == 0:
        return [TIME, "-f", "%M %U %S", "-o", "%s.0" % prefix] + list(cmd)
    wrap = 'exec %s -f "%%M %%U %%S" -o "$0.${OMPI_COMM_WORLD_RANK:-0}" "$@"' % TIME
    return bl.mpirun(np_) + ["sh", "-c", wrap, str(prefix)] + list(cmd)


def read_rss(prefix, np_):
    """(peak RSS in bytes, CPU seconds) per rank, read back from the /usr/bin/time files."""
    rss, cpu = [], []
    for r in range(max(np_, 1)):
        path = Path("%s.%d" % (prefix, r))
        got = None
        for line in path.read_text().splitlines():
            f = line.split()
            if len(f) == 3 and f[0].isdigit():
                got = (int(f[0]) * 1024, float(f[1]) + float(f[2]))
        if got is None:
            raise bl.RunError("no peak RSS in %s" % path)
        rss.append(got[0])
        cpu.append(got[1])
        path.unlink()
    return rss, cpu


def check_mesh(np_, case, env, log):
    """checkMesh (-parallel on several ranks): (cells, verdict) with the verdict as
    'Mesh OK, 1 region' or the failed checks."""
    cmd = ["checkMesh", "-case", case]
    if np_ > 1:
        cmd = bl.mpirun(np_) + cmd + ["-parallel"]
    t0 = time.perf_counter()
    with open(log, "w") as f:
        subprocess.run([str(c) for c in cmd], env=env, stdout=f, stderr=subprocess.STDOUT)
    text = Path(log).read_text(errors="replace")
    m = re.search(r"^\s*cells:\s+(\d+)", text, re.M)
    cells = int(m.group(1)) if m else None
    if "Mesh OK." in text:
        verdict = "Mesh OK"
    else:
        m = re.search(r"Failed (\d+) mesh checks", text)
        verdict = "failed %s checks" % m.group(1) if m else "no verdict (see %s)" % log
    m = re.search(r"Number of regions:\s+(\d+)", text)
    regions = int(m.group(1)) if m else None
    if regions is not None:
        verdict += ", %d region%s" % (regions, "" if regions == 1 else "s")
    return cells, verdict, time.perf_counter() - t0


# ---------------------------------------------------------------- the snappyHexMesh case

HEADER = "FoamFile { version 2.0; format ascii; class dictionary; object %s; }\n"


def vec(v):
    return "(%s)" % " ".join("%.9g" % x for x in v)


def write_snappy_case(case, spec, np_, snap=False):
    """The snappyHexMesh case of spec for np_ ranks: castellated only, or castellated and
    snapped with snap (addLayers false in both)."""
    if case.exists():
        shutil.rmtree(case)
    (case / "system").mkdir(parents=True)
    (case / "constant" / "triSurface").mkdir(parents=True)
    stl = case / "constant" / "triSurface" / (spec["name"] + ".stl")
    # A link, not a copy: the models stay in ../shared/data.
    os.symlink(os.path.abspath(spec["surface"]), stl)
    (x0, y0, z0), (x1, y1, z1) = spec["lo"], spec["hi"]
    pts = [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0),
           (x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)]
    nx, ny, nz = spec["roots"]
    sysd = case / "system"
    (sysd / "blockMeshDict").write_text(
        HEADER % "blockMeshDict"
        + "convertToMeters 1;\n"
        + "vertices ( %s );\n" % " ".join(vec(p) for p in pts)
        + "blocks ( hex (0 1 2 3 4 5 6 7) (%d %d %d) simpleGrading (1 1 1) );\n" % (nx, ny, nz)
        + "boundary ( xmin { type patch; faces ((0 4 7 3)); } xmax { type patch; faces ((1 2 6 5)); }\n"
        + " ymin { type patch; faces ((0 1 5 4)); } ymax { type patch; faces ((3 7 6 2)); }\n"
        + " zmin { type patch; faces ((0 3 2 1)); } zmax { type patch; faces ((4 5 6 7)); } );\n")
    (sysd / "controlDict").write_text(
        HEADER % "controlDict"
        + "application snappyHexMesh; startFrom startTime; startTime 0; stopAt endTime; endTime 1;\n"
        + "deltaT 1; writeControl timeStep; writeInterval 1; writeFormat binary;\n"
        + "writeCompression off; runTimeModifiable false;\n")
    (sysd / "fvSchemes").write_text(
        HEADER % "fvSchemes"
        + "ddtSchemes { default steadyState; } gradSchemes { default Gauss linear; }\n"
        + "divSchemes { default none; } laplacianSchemes { default Gauss linear corrected; }\n"
        + "interpolationSchemes { default linear; } snGradSchemes { default corrected; }\n")
    (sysd / "fvSolution").write_text(HEADER % "fvSolution" + "solvers { }\n")
    (sysd / "decomposeParDict").write_text(
        HEADER % "decomposeParDict"
        # Debian's OpenFOAM has only a stub of scotch; snappyHexMesh rebalances as it refines.
        + "numberOfSubdomains %d; method hierarchical;\n" % max(np_, 1)
        + "hierarchicalCoeffs { n (%d 1 1); order xyz; }\n" % max(np_, 1))
    name = spec["name"]
    (sysd / "snappyHexMeshDict").write_text(
        HEADER % "snappyHexMeshDict"
        + "castellatedMesh true; snap %s; addLayers false;\n" % ("true" if snap else "false")
        + "geometry {\n"
        + "  %s.stl { type triSurfaceMesh; name %s; }\n" % (name, name)
        + "  wake { type searchableBox; min %s; max %s; }\n" % (vec(spec["wake_lo"]), vec(spec["wake_hi"]))
        + "}\n"
        + "castellatedMeshControls {\n"
        + "  maxLocalCells 100000000; maxGlobalCells 2000000000; minRefinementCells 0;\n"
        + "  maxLoadUnbalance 0.10; nCellsBetweenLevels 1; features ();\n"
        + "  refinementSurfaces { %s { level (%d %d); } }\n" % (name, spec["level"], spec["level"])
        + "  resolveFeatureAngle 180;\n"
        + "  refinementRegions {\n"
        + "    wake { mode inside; levels ((1e15 %d)); }\n" % spec["wake_level"]
        + "    %s { mode distance; levels ((%.9g %d)); }\n" % (name, spec["band"], spec["band_level"])
        + "  }\n"
        + "  locationInMesh %s; allowFreeStandingZoneFaces true;\n" % vec(spec["location"])
        + "}\n"
        + "snapControls { nSmoothPatch 3; tolerance 2.0; nSolveIter 30; nRelaxIter 5; }\n"
        + "addLayersControls { relativeSizes true; layers {} expansionRatio 1.0; finalLayerThickness 0.3;\n"
        + "  minThickness 0.1; nGrow 0; featureAngle 60; nRelaxIter 3; nSmoothSurfaceNormals 1;\n"
        + "  nSmoothNormals 3; nSmoothThickness 10; maxFaceThicknessRatio 0.5;\n"
        + "  maxThicknessToMedialRatio 0.3; minMedianAxisAngle 90; nBufferCellsNoExtrude 0; nLayerIter 50; }\n"
        + "meshQualityControls { maxNonOrtho 65; maxBoundarySkewness 20; maxInternalSkewness 4;\n"
        + "  maxConcave 80; minVol 1e-13; minTetQuality 1e-30; minArea -1; minTwist 0.05;\n"
        + "  minDeterminant 0.001; minFaceWeight 0.05; minVolRatio 0.01; minTriangleTwist -1;\n"
        + "  nSmoothScale 4; errorReduction 0.75; }\n"
        + "mergeTolerance 1e-6;\n")


def snappy_commands(np_, case):
    """The commands of one snappyHexMesh run, as (label, command) pairs."""
    cmds = [("blockMesh", ["blockMesh", "-case", case])]
    if np_ > 1:
        cmds.append(("decomposePar", ["decomposePar", "-case", case, "-force"]))
        cmds.append(("snappyHexMesh", bl.mpirun(np_) + ["snappyHexMesh", "-case", case,
                                                         "-overwrite", "-parallel"]))
    else:
        cmds.append(("snappyHexMesh", ["snappyHexMesh", "-case", case, "-overwrite"]))
    return cmds


def run_snappy(np_, spec, runs, fenv, logs):
    case = SCRATCH / ("snappy_np%d" % np_)
    walls, parts, rss, cpus = [], [], [], []
    for i in range(runs):
        write_snappy_case(case, spec, np_)
        total, split, peak, cpu = 0.0, {}, [], 0.0
        for label, cmd in snappy_commands(np_, case):
            prefix = logs / ("rss_%s" % label)
            mpi = np_ if cmd[0] == "mpirun" else 0
            inner = cmd[3:] if mpi else cmd
            t = timed(with_rss(mpi, inner, prefix), fenv, SCRATCH,
                      logs / ("snappy_np%d_%s_%d.log" % (np_, label, i)))
            total += t
            split[label] = t
            r, c = read_rss(prefix, mpi)
            cpu += sum(c)
            if label == "snappyHexMesh":
                peak = r
        walls.append(total)
        cpus.append(cpu)
        split["load"] = os.getloadavg()[0]
        parts.append(split)
        rss.append(peak)
        print("    snappyHexMesh np %d run %d: %.2f s, CPU %.2f s (%s)" % (
            np_, i + 1, total, cpu, ", ".join("%s %.2f" % kv for kv in split.items())), flush=True)
    return case, walls, parts, rss, cpus


def octmesh_args(spec, case, stats):
    f = lambda v: ",".join("%.9g" % x for x in v)
    return ["mesh", spec["surface"], "--box", f(spec["lo"] + spec["hi"]),
            "--roots", ",".join(map(str, spec["roots"])), "--level", str(spec["level"]),
            "--region", "box:%s:%d" % (f(spec["wake_lo"] + spec["wake_hi"]), spec["wake_level"]),
            "--distance", "%.9g:%d" % (spec["band"], spec["band_level"]),
            "--keep", "outside", "--openfoam", str(case), "--stats", str(stats), "--quiet"]


def run_octmesh(np_, spec, runs, env, logs):
    case = SCRATCH / ("octmesh_np%d" % np_)
    stats_path = SCRATCH / ("octmesh_np%d.json" % np_)
    walls, rss, stats, loads, cpus = [], [], [], [], []
    for i in range(runs):
        if case.exists():
            shutil.rmtree(case)
        prefix = logs / "rss_octmesh"
        # One rank runs alone, as snappyHexMesh's serial run does (no mpirun,
        # and octmesh then does not start MPI).
        mpi = np_ if np_ > 1 else 0
        cmd = with_rss(mpi, [bl.OCTMESH] + octmesh_args(spec, case, stats_path), prefix)
        t = timed(cmd, env, bl.ROOT, logs / ("octmesh_np%d_%d.log" % (np_, i)))
        walls.append(t)
        loads.append(os.getloadavg()[0])
        r, c = read_rss(prefix, mpi)
        rss.append(r)
        cpus.append(sum(c))
        with open(stats_path) as fh:
            stats.append(json.load(fh))
        print("    octmesh np %d run %d: %.3f s, CPU %.3f s (load %.1f)"
              % (np_, i + 1, t, cpus[-1], loads[-1]), flush=True)
    return case, walls, rss, stats, loads, cpus


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--surface", default=str(bl.DATA / "bunny.stl"))
    ap.add_argument("--box", default="-1.5,-1,-1,2.5,1,1",
                    help="background box X0,Y0,Z0,X1,Y1,Z1 (default 4 x 2 x 2 bunny sizes)")
    ap.add_argument("--roots", default="16,8,8", help="background cells NX,NY,NZ (cubic)")
    ap.add_argument("--level", type=int, default=6, help="surface level L")
    ap.add_argument("--wake", default="0.5,-0.4,-0.4,2,0.4,0.4", help="wake box X0,...,Z1")
    ap.add_argument("--wake-level", type=int, help="default L-2")
    ap.add_argument("--band", type=float, default=0.05, help="distance band D (default 0.05)")
    ap.add_argument("--band-level", type=int, help="default L-1")
    ap.add_argument("--location", default="-1.2345,0.7123,0.6789",
                    help="snappyHexMesh's locationInMesh (outside the body)")
    ap.add_argument("--np", default="1,2", help="rank counts (default 1,2)")
    ap.add_argument("--octmesh-runs", type=int, default=5)
    ap.add_argument("--snappy-runs", type=int, default=1)
    ap.add_argument("--skip-snappy", action="store_true", help="octmesh only")
    ap.add_argument("--foam-bashrc", default="/usr/share/openfoam/etc/bashrc")
    ap.add_argument("--no-build", action="store_true")
    ap.add_argument("--markdown", help="write the table as Markdown to this file")
    ap.add_argument("--json", help="write every measurement to this file")
    a = ap.parse_args()

    lo_hi = floats(ap, a.box, 6, "--box")
    wake = floats(ap, a.wake, 6, "--wake")
    spec = {
        "surface": a.surface, "name": bl.surface_name(a.surface),
        "lo": lo_hi[:3], "hi": lo_hi[3:], "roots": ints(ap, a.roots, 3, "--roots"),
        "level": a.level, "wake_lo": wake[:3], "wake_hi": wake[3:],
        "wake_level": a.level - 2 if a.wake_level is None else a.wake_level,
        "band": a.band, "band_level": a.level - 1 if a.band_level is None else a.band_level,
        "location": floats(ap, a.location, 3, "--location"),
    }
    sides = [(spec["hi"][k] - spec["lo"][k]) / spec["roots"][k] for k in range(3)]
    if max(sides) - min(sides) > 1e-9 * max(sides):
        ap.error("background cells are not cubes: sides %s" % sides)
    if not os.path.isfile(a.surface):
        sys.exit("missing %s" % a.surface)
    if not os.access(TIME, os.X_OK):
        sys.exit("missing %s (apt-get install time)" % TIME)
    nps = bl.parse_nps(ap, a.np)

    env = bl.mpi_env()
    info = bl.prepare(env, a.no_build, "snappyHexMesh (castellated) and octmesh side by side",
                      need_p4est=False)
    fenv = foam_env(a.foam_bashrc)
    SCRATCH.mkdir(parents=True, exist_ok=True)
    logs = SCRATCH / "logs"
    logs.mkdir(exist_ok=True)
    print("  spec:    %s in box %s, %s background cells of side %.6g, level %d, wake box %s level %d,"
          " band %.6g level %d" % (spec["name"], a.box, "x".join(map(str, spec["roots"])), sides[0],
                                   spec["level"], a.wake, spec["wake_level"], spec["band"],
                                   spec["band_level"]), flush=True)
    print("  octmesh: [mpirun -np N] %s %s" % (bl.OCTMESH.relative_to(bl.ROOT), " ".join(
        octmesh_args(spec, "CASE", "STATS.json"))), flush=True)

    results = []
    for np_ in nps:
        row = {"np": np_}
        if not a.skip_snappy:
            case, walls, parts, rss, cpus = run_snappy(np_, spec, a.snappy_runs, fenv, logs)
            cells, verdict, _ = check_mesh(np_, case, fenv, logs / ("check_snappy_np%d.log" % np_))
            k = sorted(range(len(walls)), key=lambda j: walls[j])[(len(walls) - 1) // 2]
            results.append({"np": np_, "tool": "snappyHexMesh", "walls": walls, "parts": parts,
                            "wall": bl.median(walls), "rss": rss[k], "cells": cells,
                            "cpus": cpus, "cpu": bl.median(cpus),
                            "check": verdict})
        case, walls, rss, stats, loads, cpus = run_octmesh(np_, spec, a.octmesh_runs, env, logs)
        cells, verdict, _ = check_mesh(np_, case, fenv, logs / ("check_octmesh_np%d.log" % np_))
        k = sorted(range(len(walls)), key=lambda j: walls[j])[(len(walls) - 1) // 2]
        tim = stats[k].get("timings", {})
        results.append({"np": np_, "tool": "octmesh", "walls": walls, "wall": bl.median(walls),
                        "rss": rss[k], "cells": cells, "elements": stats[k].get("elements"),
                        "check": verdict, "timings": tim,
                        "stats_peak_rss": stats[k].get("peak_rss_bytes"), "loads": loads,
                        "cpus": cpus, "cpu": bl.median(cpus)})

    cols = [("np", "np"), ("tool", "tool"), ("cells", "cells"), ("wall", "wall s (median)"),
            ("runs", "runs"), ("cpu", "CPU s (median, sum of ranks)"), ("us", "us/cell"), ("rss", "peak RSS MiB max rank / sum"),
            ("check", "checkMesh"), ("ratio", "snappy / octmesh")]
    rows = []
    for r in results:
        snap = [s for s in results if s["np"] == r["np"] and s["tool"] == "snappyHexMesh"]
        ratio = ""
        if r["tool"] == "octmesh" and snap:
            ratio = "%.1fx (CPU %.1fx, per cell %.1fx)" % (
                snap[0]["wall"] / r["wall"], snap[0]["cpu"] / r["cpu"],
                (snap[0]["wall"] / snap[0]["cells"]) / (r["wall"] / r["cells"])
                if snap[0]["cells"] and r["cells"] else float("nan"))
        rows.append({
            "np": str(r["np"]), "tool": r["tool"], "cells": bl.fmt_int(r["cells"]),
            "wall": bl.fmt_s(r["wall"]),
            "runs": ", ".join(bl.fmt_s(w) for w in r["walls"]),
            "cpu": bl.fmt_s(r["cpu"]),
            "us": "%.2f" % (1e6 * r["wall"] / r["cells"]) if r["cells"] else "-",
            "rss": "%s / %s" % (bl.fmt_mib(max(r["rss"])), bl.fmt_mib(sum(r["rss"]))),
            "check": r["check"], "ratio": ratio})
    print()
    print(bl.text_table(rows, cols))
    for r in results:
        if r["tool"] == "octmesh":
            t = r["timings"]
            top = sorted(t.items(), key=lambda kv: -kv[1])
            print("  octmesh np %d phases (s, max over ranks): %s; sum %.2f s of %.2f s wall" % (
                r["np"], ", ".join("%s %.2f" % kv for kv in top if kv[1] >= 0.01),
                sum(t.values()), r["wall"]))
        else:
            print("  snappyHexMesh np %d: %s" % (r["np"], "; ".join(
                ", ".join("%s %.1f" % kv for kv in p.items()) for p in r["parts"])))
    if a.markdown:
        md = bl.header_line(info) + "\n\n" + bl.markdown_table(rows, cols, left=("tool", "check")) + "\n"
        Path(a.markdown).write_text(md)
        print("wrote %s" % a.markdown)
    if a.json:
        with open(a.json, "w") as fh:
            json.dump({"info": info, "spec": spec, "results": results}, fh, indent=1)
        print("wrote %s" % a.json)


if __name__ == "__main__":
    try:
        main()
    except bl.RunError as e:
        sys.exit(str(e))
