#!/usr/bin/env python3
"""Independent check of an octmesh mesh written as PVTU + VTU pieces.

Usage: check_vtu.py MESH.pvtu

Reads the PVTU with xml.etree, checks that it declares exactly the arrays
octmesh writes (its own, plus any caller point fields: Float64 point arrays
of one component), reads every piece with meshio (Debian's python3-meshio),
checks that each piece holds exactly the declared arrays with one finite
value per point for each field, and prints one JSON object:

  {"pieces": n, "cells": ..., "points": ... (summed over pieces),
   "volume": sum over hexahedra of the volume of their bounding box,
   "levels": {"level": count, ...}, "hanging_points": count of hanging > 0,
   "min_global_id": ..., "max_global_id": ... (over independent points),
   "fields": {"name": {"min": ..., "max": ..., "sum": ...}, ...}}

Field statistics run over every point of every piece (a node shared by two
pieces counts twice); min and max are null when there are no points.

Exits with status 1 and a message on stderr on any failure.

meshio (5.x to 7.x) cannot read a piece with no cells: vtk_cells_from_data
indexes types[0]. Such pieces (ranks that own nothing) are read instead by the
small raw reader below, which knows only this exact format.

If `python3` in PATH is not the system one (pyenv, venv), run this script with
/usr/bin/python3, which sees python3-meshio.
"""

import json
import os
import sys
import xml.etree.ElementTree as ET


def fail(msg):
    print(f"check_vtu: {msg}", file=sys.stderr)
    sys.exit(1)


try:
    import numpy as np
    import meshio
except ImportError as e:
    fail(
        f"{e} (interpreter {sys.executable}); install Debian's python3-meshio "
        "(apt-get install python3-meshio) and run with /usr/bin/python3"
    )

# What octmesh writes: name -> VTK type.
POINT_ARRAYS = {"global_id": "Int64", "hanging": "UInt8"}
CELL_ARRAYS = {"level": "UInt8", "rank": "Int32", "class": "UInt8"}
NUMPY = {
    "Float64": np.dtype("<f8"),
    "Int64": np.dtype("<i8"),
    "Int32": np.dtype("<i4"),
    "UInt8": np.dtype("u1"),
}


def declared(parent, tag):
    if parent is None:
        fail(f"missing <{tag}>")
    arrays = parent.findall("PDataArray")
    names = [a.get("Name") for a in arrays]
    if len(set(names)) != len(names) or any(not n for n in names):
        fail(f"<{tag}> declares an array twice or without a name: {names}")
    return {a.get("Name"): (a.get("type"), a.get("NumberOfComponents", "1")) for a in arrays}


def read_pvtu(path):
    """Checks the PVTU's declarations; returns its piece paths and the names
    of the caller point fields."""
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as e:
        fail(f"cannot parse '{path}': {e}")
    if root.tag != "VTKFile" or root.get("type") != "PUnstructuredGrid":
        fail(f"'{path}' is not a PUnstructuredGrid VTKFile")
    grid = root.find("PUnstructuredGrid")
    if grid is None:
        fail(f"'{path}' has no <PUnstructuredGrid>")
    point = declared(grid.find("PPointData"), "PPointData")
    if {n: point.get(n, (None,))[0] for n in POINT_ARRAYS} != POINT_ARRAYS:
        fail(f"'{path}': PPointData does not declare {POINT_ARRAYS}")
    fields = [n for n in point if n not in POINT_ARRAYS]
    for n in fields:
        if point[n] != ("Float64", "1"):
            fail(f"'{path}': point field {n!r} is {point[n]}, expected Float64 of 1 component")
    cell = {n: t for n, (t, _) in declared(grid.find("PCellData"), "PCellData").items()}
    if cell != CELL_ARRAYS:
        fail(f"'{path}': PCellData does not declare {CELL_ARRAYS}")
    pts = grid.find("PPoints")
    pa = [] if pts is None else pts.findall("PDataArray")
    if len(pa) != 1 or pa[0].get("type") != "Float64" or pa[0].get("NumberOfComponents") != "3":
        fail(f"'{path}': PPoints must declare one Float64 array of 3 components")
    sources = [p.get("Source") for p in grid.findall("Piece")]
    if not sources or any(not s for s in sources):
        fail(f"'{path}' lists no pieces, or a piece without Source")
    base = os.path.dirname(os.path.abspath(path))
    return [os.path.join(base, s) for s in sources], fields


def xml_head(raw, path):
    """The XML before the raw appended data, parsed, and where the data starts."""
    tag = b'<AppendedData encoding="raw">'
    at = raw.find(tag)
    if at < 0:
        fail(f"'{path}' has no raw AppendedData")
    try:
        root = ET.fromstring(raw[:at].decode("utf-8") + "</VTKFile>")
    except (UnicodeDecodeError, ET.ParseError) as e:
        fail(f"'{path}': bad XML header: {e}")
    underscore = raw.find(b"_", at + len(tag))
    if underscore < 0 or raw[at + len(tag) : underscore].strip():
        fail(f"'{path}': appended data does not start with '_'")
    return root, underscore + 1


def read_empty(raw, path, root, data):
    """Reads a piece with no cells without meshio (see the module docstring)."""
    piece = root.find("UnstructuredGrid/Piece")
    n_points = int(piece.get("NumberOfPoints"))
    if root.get("header_type") != "UInt64" or root.get("byte_order") != "LittleEndian":
        fail(f"'{path}': expected header_type UInt64, LittleEndian")
    arrays = {}
    for section in ("PointData", "CellData", "Points", "Cells"):
        for a in piece.findall(f"{section}/DataArray"):
            if a.get("format") != "appended":
                fail(f"'{path}': array {a.get('Name')} is not appended")
            off = data + int(a.get("offset"))
            if off + 8 > len(raw):
                fail(f"'{path}': array {a.get('Name')} starts past the end")
            n = int(np.frombuffer(raw[off : off + 8], "<u8")[0])
            if off + 8 + n > len(raw):
                fail(f"'{path}': array {a.get('Name')} runs past the end")
            dt = NUMPY.get(a.get("type"))
            if dt is None:
                fail(f"'{path}': unexpected type {a.get('type')}")
            arrays[(section, a.get("Name"))] = np.frombuffer(raw[off + 8 : off + 8 + n], dt)
    for name in ("connectivity", "offsets", "types"):
        if len(arrays.get(("Cells", name), [None])) != 0:
            fail(f"'{path}': NumberOfCells is 0 but {name} is not empty")
    pts = [v for (s, _), v in arrays.items() if s == "Points"]
    if len(pts) != 1 or len(pts[0]) != 3 * n_points:
        fail(f"'{path}': Points do not hold {n_points} points")
    point_data = {n: v for (s, n), v in arrays.items() if s == "PointData"}
    cell_data = {n: v for (s, n), v in arrays.items() if s == "CellData"}
    return pts[0].reshape(-1, 3), [], point_data, cell_data


def read_piece(path):
    """Returns (points, [hex connectivity blocks], point_data, cell_data)."""
    try:
        with open(path, "rb") as f:
            raw = f.read()
    except OSError as e:
        fail(f"cannot read piece '{path}': {e}")
    root, data = xml_head(raw, path)
    piece = root.find("UnstructuredGrid/Piece")
    if piece is None:
        fail(f"'{path}' has no UnstructuredGrid/Piece")
    if int(piece.get("NumberOfCells")) == 0:
        return read_empty(raw, path, root, data)
    try:
        mesh = meshio.read(path, file_format="vtu")
    except Exception as e:  # meshio raises many kinds
        fail(f"meshio cannot read '{path}': {type(e).__name__}: {e}")
    blocks = []
    for b in mesh.cells:
        if b.type != "hexahedron":
            fail(f"'{path}': cell block of type {b.type}, expected hexahedron")
        blocks.append(np.asarray(b.data))
    cell_data = {}
    for name, per_block in mesh.cell_data.items():
        cell_data[name] = np.concatenate([np.asarray(v).reshape(-1) for v in per_block])
    point_data = {n: np.asarray(v).reshape(-1) for n, v in mesh.point_data.items()}
    return np.asarray(mesh.points), blocks, point_data, cell_data


def check_arrays(path, got, want, count, what):
    if set(got) != set(want):
        fail(f"'{path}': {what} arrays {sorted(got)}, expected {sorted(want)}")
    for name, vtk_type in want.items():
        a = got[name]
        if a.dtype.newbyteorder("<") != NUMPY[vtk_type].newbyteorder("<"):
            fail(f"'{path}': {what} array {name} is {a.dtype}, expected {vtk_type}")
        if len(a) != count:
            fail(f"'{path}': {what} array {name} has {len(a)} values for {count}")


def main():
    if len(sys.argv) != 2:
        fail("usage: check_vtu.py MESH.pvtu")
    total = {"cells": 0, "points": 0, "volume": 0.0, "hanging": 0}
    levels = {}
    gid_min, gid_max = None, None
    pieces, fields = read_pvtu(sys.argv[1])
    point_arrays = dict(POINT_ARRAYS, **{f: "Float64" for f in fields})
    stats = {f: {"min": None, "max": None, "sum": 0.0} for f in fields}
    for path in pieces:
        points, blocks, pd, cd = read_piece(path)
        if points.ndim != 2 or points.shape[1] != 3 or points.dtype != np.float64:
            fail(f"'{path}': points are {points.dtype} {points.shape}, expected Float64 (n, 3)")
        n_cells = sum(len(b) for b in blocks)
        check_arrays(path, pd, point_arrays, len(points), "point")
        check_arrays(path, cd, CELL_ARRAYS, n_cells, "cell")
        for b in blocks:
            if b.ndim != 2 or b.shape[1] != 8:
                fail(f"'{path}': hexahedra with {b.shape[1:]} points")
            if b.size and (b.min() < 0 or b.max() >= len(points)):
                fail(f"'{path}': cell index out of range")
            corners = points[b]  # (n, 8, 3)
            extent = corners.max(axis=1) - corners.min(axis=1)
            total["volume"] += float(extent.prod(axis=1).sum())
        if n_cells and np.any(cd["rank"] != cd["rank"][0]):
            fail(f"'{path}': the rank array is not constant")
        hanging, gid = pd["hanging"], pd["global_id"]
        if np.any(hanging > 2):
            fail(f"'{path}': hanging values above 2")
        if np.any(gid[hanging > 0] != -1):
            fail(f"'{path}': a hanging point has a global id other than -1")
        independent = gid[hanging == 0]
        if np.any(independent < 0):
            fail(f"'{path}': an independent point has a negative global id")
        if len(independent):
            lo, hi = int(independent.min()), int(independent.max())
            gid_min = lo if gid_min is None else min(gid_min, lo)
            gid_max = hi if gid_max is None else max(gid_max, hi)
        for f in fields:
            v = pd[f]
            if not np.all(np.isfinite(v)):
                fail(f"'{path}': point field {f!r} has non-finite values")
            if len(v):
                st = stats[f]
                lo, hi = float(v.min()), float(v.max())
                st["min"] = lo if st["min"] is None else min(st["min"], lo)
                st["max"] = hi if st["max"] is None else max(st["max"], hi)
                st["sum"] += float(v.sum())
        for lv, c in zip(*np.unique(cd["level"], return_counts=True)):
            levels[int(lv)] = levels.get(int(lv), 0) + int(c)
        total["cells"] += n_cells
        total["points"] += len(points)
        total["hanging"] += int(np.count_nonzero(hanging))
    print(
        json.dumps(
            {
                "pieces": len(pieces),
                "cells": total["cells"],
                "points": total["points"],
                "volume": total["volume"],
                "levels": {str(k): levels[k] for k in sorted(levels)},
                "hanging_points": total["hanging"],
                "min_global_id": gid_min,
                "max_global_id": gid_max,
                "fields": stats,
            }
        )
    )


if __name__ == "__main__":
    try:
        main()
    except SystemExit:
        raise
    except Exception as e:  # anything unexpected is a failed check, not a traceback
        fail(f"{type(e).__name__}: {e}")
