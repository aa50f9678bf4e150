#!/usr/bin/env python3
"""Steady laminar flow past a sphere at Re = 100: the drag coefficient with simpleFoam.

  /usr/bin/python3 tools/bench/sphere_drag.py --np 2 --level 8 --mesh="--wall-layer --cut-rule none"

The built-in sphere (radius 1, D = 2) in the box [-16, 48] x [-16, 16]^2 (8 D
upstream and to the sides, 24 D downstream; 4 x 2 x 2 root cells of side 16);
U = (1 0 0) at `xmin`, p = 0 at `xmax`,
slip on the four other sides, noSlip on the sphere; nu = U D / Re. Second-order
schemes (linearUpwind for the convection, linear gradients, corrected
Laplacians), SIMPLE with consistent = yes, run until the residuals fall below
1e-5 or --iterations. The drag coefficient is the `forceCoeffs` function
object's Cd (reference area pi r^2, speed 1) at the last iteration; the run
also prints the mean of the last 50 iterations and their spread, which tells
whether the run converged.

Johnson & Patel (1999): Cd = 1.087 at Re = 100.

`--mesh` passes options to `octmesh mesh` (the wall treatment: `--snap`,
`--wall-layer --cut-rule none`, `--layers 3 ...`); `--snappy` meshes the same
box with blockMesh + snappyHexMesh (castellation to the same wall level,
snapping, and `--snappy-layers N` layers) instead. `--grow G` multiplies the
domain's extent (the wall level is kept by adding the levels the larger roots
need). Each case is written under --work, and one line of JSON per case to
stdout.
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

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BIN = os.path.join(ROOT, "target", "release", "octmesh")
FOAM = "source /usr/share/openfoam/etc/bashrc >/dev/null 2>&1 || true; "
MPI_ROOT = {"OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"}

HEAD = "FoamFile {{ version 2.0; format ascii; class {cls}; object {obj}; }}\n"


def foam(cmd, cwd, log):
    env = dict(os.environ, **MPI_ROOT)
    with open(os.path.join(cwd, log), "w") as f:
        r = subprocess.run(["bash", "-c", FOAM + cmd], cwd=cwd, stdout=f, stderr=subprocess.STDOUT, env=env)
    if r.returncode != 0:
        sys.exit(f"{cmd} failed in {cwd}, see {log}")


def write(path, text):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as f:
        f.write(text)


def geometry(grow):
    """Box (lo, hi), roots and root side: the sphere at the origin, 8 D * grow upstream and to the sides,
    24 D * grow downstream, in root cells of side 16 * grow."""
    side = 16.0 * grow
    lo = [-side, -side, -side]
    hi = [3 * side, side, side]
    return lo, hi, (4, 2, 2), side


def case_files(case, nu, iterations, np_):
    sides = "(ymin|ymax|zmin|zmax)"
    write(os.path.join(case, "0/U"), HEAD.format(cls="volVectorField", obj="U") + f"""
dimensions [0 1 -1 0 0 0 0];
internalField uniform (1 0 0);
boundaryField
{{
    xmin {{ type fixedValue; value uniform (1 0 0); }}
    xmax {{ type inletOutlet; inletValue uniform (0 0 0); value uniform (1 0 0); }}
    "{sides}" {{ type slip; }}
    sphere {{ type noSlip; }}
    "proc.*" {{ type processor; }}
}}
""")
    write(os.path.join(case, "0/p"), HEAD.format(cls="volScalarField", obj="p") + f"""
dimensions [0 2 -2 0 0 0 0];
internalField uniform 0;
boundaryField
{{
    xmin {{ type zeroGradient; }}
    xmax {{ type fixedValue; value uniform 0; }}
    "{sides}" {{ type slip; }}
    sphere {{ type zeroGradient; }}
    "proc.*" {{ type processor; }}
}}
""")
    write(os.path.join(case, "constant/transportProperties"),
          HEAD.format(cls="dictionary", obj="transportProperties") + f"transportModel Newtonian;\nnu {nu};\n")
    write(os.path.join(case, "constant/turbulenceProperties"),
          HEAD.format(cls="dictionary", obj="turbulenceProperties") + "simulationType laminar;\n")
    write(os.path.join(case, "system/controlDict"), HEAD.format(cls="dictionary", obj="controlDict") + f"""
application simpleFoam;
startFrom startTime; startTime 0; stopAt endTime; endTime {iterations}; deltaT 1;
writeControl timeStep; writeInterval {iterations}; purgeWrite 0; writeFormat binary; writePrecision 10;
writeCompression off; timeFormat general; timePrecision 6; runTimeModifiable false;
functions
{{
    forceCoeffs1
    {{
        type forceCoeffs; libs ("libforces.so"); writeControl timeStep; writeInterval 1;
        patches (sphere); rho rhoInf; rhoInf 1; CofR (0 0 0); liftDir (0 1 0); dragDir (1 0 0);
        pitchAxis (0 0 1); magUInf 1; lRef 2; Aref {math.pi};
    }}
}}
""")
    write(os.path.join(case, "system/fvSchemes"), HEAD.format(cls="dictionary", obj="fvSchemes") + """
ddtSchemes { default steadyState; }
gradSchemes { default Gauss linear; }
divSchemes { default none; div(phi,U) bounded Gauss linearUpwind grad(U);
             div((nuEff*dev2(T(grad(U))))) Gauss linear; }
laplacianSchemes { default Gauss linear limited corrected 0.5; }
interpolationSchemes { default linear; }
snGradSchemes { default limited corrected 0.5; }
""")
    write(os.path.join(case, "system/fvSolution"), HEAD.format(cls="dictionary", obj="fvSolution") + """
solvers
{
    p { solver GAMG; smoother GaussSeidel; tolerance 1e-7; relTol 0.05; }
    U { solver smoothSolver; smoother GaussSeidel; tolerance 1e-8; relTol 0.1; }
}
SIMPLE { nNonOrthogonalCorrectors 1; consistent yes; residualControl { p 1e-5; U 1e-6; } }
relaxationFactors { equations { U 0.9; ".*" 0.9; } fields { p 1; } }
""")
    write(os.path.join(case, "system/decomposeParDict"), HEAD.format(cls="dictionary", obj="decomposeParDict") +
          f"numberOfSubdomains {np_};\nmethod scotch;\n")


def icosphere(path, subdivisions):
    """An icosahedron's faces split in four `subdivisions` times, points pushed onto the unit sphere (20 * 4^5 =
    20,480 triangles for 5, as the built-in sphere), ASCII STL."""
    t = (1 + 5 ** 0.5) / 2
    pts = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
           (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    tris = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
            (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11),
            (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    unit = lambda p: tuple(c / math.sqrt(sum(x * x for x in p)) for c in p)
    pts = [unit(p) for p in pts]
    for _ in range(subdivisions):
        mid, out = {}, []

        def m(a, b):
            k = (min(a, b), max(a, b))
            if k not in mid:
                mid[k] = len(pts)
                pts.append(unit(tuple((pts[a][i] + pts[b][i]) / 2 for i in range(3))))
            return mid[k]
        for a, b, c in tris:
            ab, bc, ca = m(a, b), m(b, c), m(c, a)
            out += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        tris = out
    with open(path, "w") as f:
        f.write("solid sphere\n")
        for tri in tris:
            f.write("facet normal 0 0 0\nouter loop\n")
            for i in tri:
                f.write("vertex %.17g %.17g %.17g\n" % pts[i])
            f.write("endloop\nendfacet\n")
        f.write("endsolid sphere\n")


def octmesh_case(case, args, level, grow):
    lo, hi, roots, side = geometry(grow)
    extra = int(round(math.log2(grow)))
    cmd = ([args.bin] if args.np == 1 else ["mpirun", "--oversubscribe", "-np", str(args.np), args.bin])
    cmd += ["mesh", "sphere", "--box", ",".join(str(v) for v in lo + hi), "--roots", ",".join(map(str, roots)),
            "--level", str(level + extra), "--keep", "outside", "--openfoam", case, "--overwrite", "--quiet"]
    # Distance bands: the wall level within 0.25 D, then one level less per doubling.
    bands = [f"{0.5 * 2 ** k}:{level + extra - 1 - k}" for k in range(3) if level - 1 - k > 2]
    if bands:
        cmd += ["--distance", ",".join(bands)]
    # The near wake, two levels below the wall's.
    cmd += ["--region", f"box:0,-1.5,-1.5,8,1.5,1.5:{level + extra - 2}"]
    cmd += args.mesh.split()
    env = dict(os.environ, **MPI_ROOT)
    t = time.time()
    subprocess.run(cmd, check=True, env=env)
    return time.time() - t


def snappy_case(case, args, level, grow):
    lo, hi, roots, side = geometry(grow)
    extra = int(round(math.log2(grow)))
    base = 3  # background cells of side 2 * grow: roots of side 16 * grow split 8 times
    n = [r * 2 ** base for r in roots]
    # A background cell's centre at (-0.5, -0.5, -0.5): snappyHexMesh finds the surface by the segments between
    # cell centres, and a sphere of radius 1 around a vertex of cells of side 2 or 4 (or around the centre of a
    # cell of side 4) crosses none of them.
    shift = side / 2 ** base / 2 - 0.5
    lo, hi = [v + shift for v in lo], [v + shift for v in hi]
    surf = level + extra - base
    os.makedirs(os.path.join(case, "constant/triSurface"), exist_ok=True)
    icosphere(os.path.join(case, "constant/triSurface/sphere.stl"), 5)
    write(os.path.join(case, "system/blockMeshDict"), HEAD.format(cls="dictionary", obj="blockMeshDict") + f"""
convertToMeters 1;
vertices ( ({lo[0]} {lo[1]} {lo[2]}) ({hi[0]} {lo[1]} {lo[2]}) ({hi[0]} {hi[1]} {lo[2]}) ({lo[0]} {hi[1]} {lo[2]})
           ({lo[0]} {lo[1]} {hi[2]}) ({hi[0]} {lo[1]} {hi[2]}) ({hi[0]} {hi[1]} {hi[2]}) ({lo[0]} {hi[1]} {hi[2]}) );
blocks ( hex (0 1 2 3 4 5 6 7) ({n[0]} {n[1]} {n[2]}) simpleGrading (1 1 1) );
boundary
(
    xmin {{ type patch; faces ((0 4 7 3)); }}
    xmax {{ type patch; faces ((1 2 6 5)); }}
    ymin {{ type patch; faces ((0 1 5 4)); }}
    ymax {{ type patch; faces ((3 7 6 2)); }}
    zmin {{ type patch; faces ((0 3 2 1)); }}
    zmax {{ type patch; faces ((4 5 6 7)); }}
);
""")
    layers = args.snappy_layers
    dist = [(0.5 * 2 ** k, surf - 1 - k) for k in range(3) if surf - 1 - k > 0]
    levels = " ".join(f"({d} {lv})" for d, lv in dist)
    write(os.path.join(case, "system/snappyHexMeshDict"), HEAD.format(cls="dictionary", obj="snappyHexMeshDict") + f"""
castellatedMesh true; snap true; addLayers {'true' if layers else 'false'};
geometry {{ sphere.stl {{ type triSurfaceMesh; name sphere; }}
           wake {{ type searchableBox; min (0 -1.5 -1.5); max (8 1.5 1.5); }}
           near {{ type searchableBox; min (-3 -3 -3); max (3 3 3); }} }}
castellatedMeshControls
{{
    maxLocalCells 10000000; maxGlobalCells 100000000; minRefinementCells 0; nCellsBetweenLevels 1;
    maxLoadUnbalance 0.1; resolveFeatureAngle 30; allowFreeStandingZoneFaces true;
    features ();
    refinementSurfaces {{ sphere {{ level ({surf} {surf}); patchInfo {{ type wall; }} }} }}
    refinementRegions {{ sphere {{ mode distance; levels ({levels}); }}
                        wake {{ mode inside; levels ((1e15 {surf - 2})); }}
                        near {{ mode inside; levels ((1e15 {max(1, surf - 3)})); }} }}
    locationInMesh (-3.1 0.1 0.1);
}}
snapControls {{ nSmoothPatch 3; tolerance 2.0; nSolveIter 100; nRelaxIter 5; nFeatureSnapIter 10;
               implicitFeatureSnap false; explicitFeatureSnap false; multiRegionFeatureSnap false; }}
addLayersControls
{{
    relativeSizes true; layers {{ sphere {{ nSurfaceLayers {layers or 1}; }} }}
    expansionRatio {args.snappy_expansion}; finalLayerThickness 0.5; minThickness 0.1; nGrow 0;
    featureAngle 60; slipFeatureAngle 30; nRelaxIter 3; nSmoothSurfaceNormals 1; nSmoothNormals 3;
    nSmoothThickness 10; maxFaceThicknessRatio 0.5; maxThicknessToMedialRatio 0.3; minMedialAxisAngle 90;
    nBufferCellsNoExtrude 0; nLayerIter 50;
}}
meshQualityControls {{ #includeEtc "caseDicts/meshQualityDict" nSmoothScale 4; errorReduction 0.75; }}
mergeTolerance 1e-6;
""")
    t = time.time()
    foam("blockMesh", case, "log.blockMesh")
    foam("snappyHexMesh -overwrite", case, "log.snappyHexMesh")
    return time.time() - t


def run_case(args, label, level, grow):
    case = os.path.join(args.work, label)
    shutil.rmtree(case, ignore_errors=True)
    os.makedirs(case)
    case_files(case, 2.0 / args.re, args.iterations, args.np)
    mesh_s = (snappy_case if args.snappy else octmesh_case)(case, args, level, grow)
    foam("checkMesh", case, "log.checkMesh")
    check = open(os.path.join(case, "log.checkMesh")).read()
    cells = int(re.search(r"cells:\s+(\d+)", check).group(1))
    ok = "Mesh OK." in check
    if args.snappy and args.np > 1:
        foam("decomposePar -force", case, "log.decomposePar")
    par = f"mpirun --oversubscribe -np {args.np} simpleFoam -parallel" if args.np > 1 else "simpleFoam"
    t = time.time()
    foam(par, case, "log.simpleFoam")
    solve_s = time.time() - t
    log = open(os.path.join(case, "log.simpleFoam")).read()
    iters = len(re.findall(r"^Time = ", log, re.M))
    cds = [float(x) for x in re.findall(r"^\s+Cd\s+[:=]\s+([-0-9.eE+]+)", log, re.M)]
    if not cds:
        sys.exit(f"no Cd in {case}/log.simpleFoam")
    tail = cds[-50:]
    out = {"case": label, "level": level, "grow": grow, "cells": cells, "mesh_ok": ok,
           "iterations": iters, "cd": cds[-1], "cd_tail_mean": sum(tail) / len(tail),
           "cd_tail_spread": max(tail) - min(tail), "mesh_s": round(mesh_s, 2), "solve_s": round(solve_s, 1),
           "error_pct": round(100 * (cds[-1] - 1.087) / 1.087, 2)}
    print(json.dumps(out), flush=True)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], allow_abbrev=False)
    ap.add_argument("--np", type=int, default=2)
    ap.add_argument("--level", default="8", help="wall levels (root side 16: level 8 is D/32), comma separated")
    ap.add_argument("--grow", default="1", help="domain factors (powers of two), comma separated")
    ap.add_argument("--mesh", default="--snap", help="octmesh options for the wall")
    ap.add_argument("--snappy", action="store_true", help="mesh with blockMesh + snappyHexMesh instead")
    ap.add_argument("--snappy-layers", type=int, default=0)
    ap.add_argument("--snappy-expansion", type=float, default=1.2)
    ap.add_argument("--re", type=float, default=100.0)
    ap.add_argument("--iterations", type=int, default=2000)
    ap.add_argument("--work", default="/tmp/sphere_drag")
    ap.add_argument("--bin", default=BIN, help="the octmesh to run")
    ap.add_argument("--name", default="octmesh")
    args = ap.parse_args()
    for grow in [float(g) for g in args.grow.split(",")]:
        for level in [int(v) for v in args.level.split(",")]:
            run_case(args, f"{args.name}_l{level}_g{grow:g}", level, grow)


if __name__ == "__main__":
    main()
