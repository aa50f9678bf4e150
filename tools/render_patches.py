#!/usr/bin/env python3
"""Renders an octmesh fluid mesh cut open, its boundary patches coloured.

Usage: xvfb-run -a python3 tools/render_patches.py NAME.pvtu OUT.png

Reads NAME.pvtu (the hexahedra) and NAME_boundary.pvtp (the boundary faces
with their patch ids) written by `octmesh mesh ... --out NAME.pvtu`, with
VTK (Debian's python3-vtk9). Shows the elements behind the plane y = centre
as a grey wireframe-on-surface cut (whole cells: the staircase of the mesh),
the surface patch behind the plane in colour, and the inlet and outlet
sides (xmin, xmax) by patch. Needs an X display for OpenGL: xvfb-run gives one.
"""
import sys

import vtk

pvtu, png = sys.argv[1], sys.argv[2]
pvtp = pvtu[: -len(".pvtu")] + "_boundary.pvtp"

mesh = vtk.vtkXMLPUnstructuredGridReader()
mesh.SetFileName(pvtu)
mesh.Update()
faces = vtk.vtkXMLPPolyDataReader()
faces.SetFileName(pvtp)
faces.Update()
b = mesh.GetOutput().GetBounds()
centre = [(b[0] + b[1]) / 2, (b[2] + b[3]) / 2, (b[4] + b[5]) / 2]

# Whole cells behind the plane y = centre (crinkle cut).
plane = vtk.vtkPlane()
plane.SetOrigin(centre)
plane.SetNormal(0, -1, 0)
cut = vtk.vtkExtractGeometry()
cut.SetInputConnection(mesh.GetOutputPort())
cut.SetImplicitFunction(plane)
cut.ExtractInsideOn()
cut.ExtractBoundaryCellsOff()
surface = vtk.vtkDataSetSurfaceFilter()
surface.SetInputConnection(cut.GetOutputPort())
cells = vtk.vtkPolyDataMapper()
cells.SetInputConnection(surface.GetOutputPort())
cells.ScalarVisibilityOff()
cell_actor = vtk.vtkActor()
cell_actor.SetMapper(cells)
cell_actor.GetProperty().SetColor(0.85, 0.85, 0.85)
cell_actor.GetProperty().EdgeVisibilityOn()
cell_actor.GetProperty().SetEdgeColor(0.35, 0.35, 0.35)
cell_actor.GetProperty().SetLineWidth(0.5)

# Patches, coloured by id: the surface's (6 and up) and the inlet and
# outlet sides (xmin, xmax), each behind the cut.
def patches_behind(low, high):
    """The boundary faces of patches low..high behind the cutting plane."""
    keep = vtk.vtkThreshold()
    keep.SetInputConnection(faces.GetOutputPort())
    keep.SetInputArrayToProcess(0, 0, 0, vtk.vtkDataObject.FIELD_ASSOCIATION_CELLS, "patch")
    keep.SetLowerThreshold(low)
    keep.SetUpperThreshold(high)
    keep.SetThresholdFunction(vtk.vtkThreshold.THRESHOLD_BETWEEN)
    behind = vtk.vtkExtractGeometry()
    behind.SetInputConnection(keep.GetOutputPort())
    behind.SetImplicitFunction(plane)
    behind.ExtractInsideOn()
    polygons = vtk.vtkGeometryFilter()
    polygons.SetInputConnection(behind.GetOutputPort())
    return polygons


geometry = patches_behind(6, 1000)
lut = vtk.vtkLookupTable()
lut.SetNumberOfTableValues(7)
colours = [(0.2, 0.4, 0.9), (0.9, 0.3, 0.2), (0.5, 0.5, 0.5), (0.5, 0.5, 0.5),
           (0.4, 0.7, 0.4), (0.5, 0.5, 0.5), (0.95, 0.7, 0.1)]
for k, c in enumerate(colours):
    lut.SetTableValue(k, c[0], c[1], c[2], 1.0)
lut.SetTableRange(0, 6)
lut.Build()
patch_mapper = vtk.vtkPolyDataMapper()
patch_mapper.SetInputConnection(geometry.GetOutputPort())
patch_mapper.SetScalarModeToUseCellFieldData()
patch_mapper.SelectColorArray("patch")
patch_mapper.SetLookupTable(lut)
patch_mapper.SetScalarRange(0, 6)
patch_actor = vtk.vtkActor()
patch_actor.SetMapper(patch_mapper)

side_geometry = patches_behind(0, 1)
side_mapper = vtk.vtkPolyDataMapper()
side_mapper.SetInputConnection(side_geometry.GetOutputPort())
side_mapper.SetScalarModeToUseCellFieldData()
side_mapper.SelectColorArray("patch")
side_mapper.SetLookupTable(lut)
side_mapper.SetScalarRange(0, 6)
side_actor = vtk.vtkActor()
side_actor.SetMapper(side_mapper)
side_actor.GetProperty().EdgeVisibilityOn()
side_actor.GetProperty().SetEdgeColor(0.2, 0.2, 0.2)

renderer = vtk.vtkRenderer()
renderer.SetBackground(1, 1, 1)
for a in (cell_actor, patch_actor, side_actor):
    renderer.AddActor(a)
camera = renderer.GetActiveCamera()
camera.SetFocalPoint(centre)
size = max(b[1] - b[0], b[3] - b[2], b[5] - b[4])
camera.SetPosition(centre[0] - 0.55 * size, centre[1] - 1.6 * size, centre[2] + 0.7 * size)
camera.SetViewUp(0, 0, 1)
renderer.ResetCamera()
camera.Zoom(1.35)
window = vtk.vtkRenderWindow()
window.SetOffScreenRendering(1)
window.AddRenderer(renderer)
window.SetSize(800, 600)
window.SetMultiSamples(4)
window.Render()
grab = vtk.vtkWindowToImageFilter()
grab.SetInput(window)
grab.Update()
writer = vtk.vtkPNGWriter()
writer.SetFileName(png)
writer.SetInputConnection(grab.GetOutputPort())
writer.Write()
print(f"wrote {png}")
