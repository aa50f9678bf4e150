#!/usr/bin/env python3
"""Independent check of octmesh's boundary faces (NAME_boundary.pvtp).

Usage: check_vtp.py BOUNDARY.pvtp

Reads the PVTP and its pieces with VTK itself (Debian's python3-vtk9,
vtkXMLPPolyDataReader), checks that every cell is a quadrilateral with a
`patch` and an `element` value, and prints one JSON object:

  {"cells": n, "patches": {"id": {"faces": count, "area": summed area,
   "normal": summed area vector}}, "names": {"id": "name"}}

The names come from the comment octmesh writes at the top of the file.
Exits with status 1 and a message on stderr on any failure.
"""
import json
import re
import sys

try:
    import vtk
    from vtk.util.numpy_support import vtk_to_numpy
except ImportError as e:
    sys.exit(f"check_vtp.py: VTK's Python module is missing ({e}): apt-get install python3-vtk9")


def main():
    path = sys.argv[1]
    with open(path, encoding="utf-8") as f:
        head = f.read(4096)
    m = re.search(r"<!-- octmesh boundary faces: (.*?) -->", head)
    if not m:
        sys.exit("check_vtp.py: no patch list comment")
    names = dict(re.findall(r"patch (\d+) = (\S+?)(?:,|$)", m.group(1)))
    reader = vtk.vtkXMLPPolyDataReader()
    reader.SetFileName(path)
    reader.Update()
    data = reader.GetOutput()
    n = data.GetNumberOfCells()
    cd = data.GetCellData()
    patch_array, element_array = cd.GetArray("patch"), cd.GetArray("element")
    if n > 0 and (patch_array is None or element_array is None):
        sys.exit("check_vtp.py: missing cell data patch or element")
    patch = vtk_to_numpy(patch_array) if n else []
    pts = vtk_to_numpy(data.GetPoints().GetData()) if n else []
    out = {}
    for c in range(n):
        cell = data.GetCell(c)
        if cell.GetNumberOfPoints() != 4:
            sys.exit(f"check_vtp.py: cell {c} has {cell.GetNumberOfPoints()} points")
        ids = [cell.GetPointId(k) for k in range(4)]
        p = [pts[i] for i in ids]
        # Area vector of a planar quadrilateral: half the cross product of
        # its diagonals.
        d1 = [p[2][k] - p[0][k] for k in range(3)]
        d2 = [p[3][k] - p[1][k] for k in range(3)]
        a = [0.5 * (d1[1] * d2[2] - d1[2] * d2[1]),
             0.5 * (d1[2] * d2[0] - d1[0] * d2[2]),
             0.5 * (d1[0] * d2[1] - d1[1] * d2[0])]
        key = str(int(patch[c]))
        e = out.setdefault(key, {"faces": 0, "area": 0.0, "normal": [0.0, 0.0, 0.0]})
        e["faces"] += 1
        e["area"] += sum(x * x for x in a) ** 0.5
        for k in range(3):
            e["normal"][k] += a[k]
    print(json.dumps({"cells": n, "patches": out, "names": names}))


if __name__ == "__main__":
    main()
