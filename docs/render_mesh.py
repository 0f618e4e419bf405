#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""Renders a .vtu written by `pdt refine --out` (or `pdt run --out`) to a PNG
with VTK: the mesh cut in half by a plane so that the inside shows, cells
coloured by a cell field (default radius_edge_ratio), edges drawn.

  xvfb-run -a /usr/bin/python3 docs/render_mesh.py mesh.vtu out.png [--field NAME] [--normal x,y,z]

Needs Debian's python3-vtk9 (and Xvfb for a machine without a display:
scripts/install-deps.sh --extras).
"""
import argparse
import sys

import vtk


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("vtu")
    ap.add_argument("png")
    ap.add_argument("--field", default="radius_edge_ratio")
    ap.add_argument("--normal", default="0,-1,0", help="normal of the cutting plane through the centre")
    ap.add_argument("--size", default="1200,800")
    ap.add_argument("--max", type=float, default=3.0,
                    help="top of the colour scale (higher values show in its top colour; default 3)")
    a = ap.parse_args()

    reader = vtk.vtkXMLUnstructuredGridReader()
    reader.SetFileName(a.vtu)
    reader.Update()
    grid = reader.GetOutput()
    if grid.GetNumberOfCells() == 0:
        sys.exit(f"render_mesh: {a.vtu} has no cells")
    field = grid.GetCellData().GetArray(a.field)
    if field is None:
        sys.exit(f"render_mesh: {a.vtu} has no cell field '{a.field}'")

    # Keep the cells on one side of the plane, whole (no cut cells): the
    # tetrahedra themselves show on the cut face.
    centre = grid.GetCenter()
    plane = vtk.vtkPlane()
    plane.SetOrigin(centre)
    plane.SetNormal(*[float(v) for v in a.normal.split(",")])
    clip = vtk.vtkExtractGeometry()
    clip.SetInputData(grid)
    clip.SetImplicitFunction(plane)
    clip.ExtractInsideOn()
    clip.ExtractBoundaryCellsOn()
    surface = vtk.vtkDataSetSurfaceFilter()
    surface.SetInputConnection(clip.GetOutputPort())

    lo, hi = field.GetRange()
    top = min(hi, a.max)
    lut = vtk.vtkLookupTable()
    lut.SetHueRange(0.62, 0.0)
    lut.SetTableRange(lo, top)
    lut.Build()
    mapper = vtk.vtkPolyDataMapper()
    mapper.SetInputConnection(surface.GetOutputPort())
    mapper.SetScalarModeToUseCellFieldData()
    mapper.SelectColorArray(a.field)
    mapper.SetLookupTable(lut)
    mapper.SetScalarRange(lo, top)
    actor = vtk.vtkActor()
    actor.SetMapper(mapper)
    actor.GetProperty().EdgeVisibilityOn()
    actor.GetProperty().SetEdgeColor(0.15, 0.15, 0.15)
    actor.GetProperty().SetLineWidth(0.5)

    bar = vtk.vtkScalarBarActor()
    bar.SetLookupTable(lut)
    bar.SetTitle(a.field.replace("_", " ") + (f" (max {hi:.1f})" if hi > top else ""))
    bar.SetNumberOfLabels(5)
    bar.SetWidth(0.08)
    bar.GetTitleTextProperty().SetColor(0, 0, 0)
    bar.GetLabelTextProperty().SetColor(0, 0, 0)

    ren = vtk.vtkRenderer()
    ren.SetBackground(1, 1, 1)
    ren.AddActor(actor)
    ren.AddActor2D(bar)
    cam = ren.GetActiveCamera()
    cam.SetFocalPoint(centre)
    cam.SetPosition(centre[0] + 0.6, centre[1] - 3.2, centre[2] + 2.4)
    cam.SetViewUp(0, 0, 1)
    ren.ResetCamera()
    cam.Zoom(1.35)
    w, h = (int(v) for v in a.size.split(","))
    win = vtk.vtkRenderWindow()
    win.SetOffScreenRendering(1)
    win.SetSize(w, h)
    win.AddRenderer(ren)
    win.Render()
    shot = vtk.vtkWindowToImageFilter()
    shot.SetInput(win)
    shot.Update()
    out = vtk.vtkPNGWriter()
    out.SetFileName(a.png)
    out.SetInputConnection(shot.GetOutputPort())
    out.Write()
    print(f"render_mesh: {a.png} ({grid.GetNumberOfCells():,} cells, {a.field} in [{lo:.3f}, {hi:.3f}])")


if __name__ == "__main__":
    main()
