# SPDX-License-Identifier: MIT
"""Reads .vtu files that pdt wrote with VTK's own reader (python3-vtk9) and
checks them against the TetGen mesh of the same run.

    check_vtu.py MESH.node FILE.vtu[:field,field...] ...

Exit status: 0 all read and agree, 1 a file disagrees, 77 VTK is not
installed (the test is then reported as skipped, with this message).
"""
import sys

try:
    import vtk
    from vtk.util.numpy_support import vtk_to_numpy
except ImportError as e:
    # Debian 12's python3-vtk9 does not depend on numpy, which vtk.util needs.
    print("SKIPPED: %s: VTK's Python bindings or numpy are not installed "
          "(Debian: apt-get install python3-vtk9 python3-numpy, or scripts/install-deps.sh); "
          ".vtu files not read with VTK" % e)
    sys.exit(77)


def read_tetgen(base):
    with open(base + ".node") as f:
        lines = [l.split() for l in f if l.strip() and not l.startswith("#")]
    points = [tuple(float(v) for v in l[1:4]) for l in lines[1:]]
    with open(base + ".ele") as f:
        lines = [l.split() for l in f if l.strip() and not l.startswith("#")]
    tets = [tuple(int(v) for v in l[1:5]) for l in lines[1:]]
    return points, tets


def main():
    base = sys.argv[1][:-len(".node")]
    points, tets = read_tetgen(base)
    bad = 0
    for arg in sys.argv[2:]:
        path, _, fields = arg.partition(":")
        reader = vtk.vtkXMLUnstructuredGridReader()
        reader.SetFileName(path)
        reader.Update()
        grid = reader.GetOutput()
        n_points, n_cells = grid.GetNumberOfPoints(), grid.GetNumberOfCells()
        problems = []
        if reader.GetErrorCode() != 0:
            problems.append("reader error %d" % reader.GetErrorCode())
        if fields:
            # A refined mesh: its own tetrahedra; check they are tetrahedra with the fields.
            for name in fields.split(","):
                arr = grid.GetCellData().GetArray(name)
                if arr is None or arr.GetNumberOfTuples() != n_cells:
                    problems.append("cell field %s missing or of the wrong size" % name)
            if n_cells == 0:
                problems.append("no cells")
        else:
            if (n_points, n_cells) != (len(points), len(tets)):
                problems.append("%d points and %d cells, the .node/.ele have %d and %d"
                                % (n_points, n_cells, len(points), len(tets)))
            else:
                # The same tetrahedra, as sets of points (runs may number vertices differently).
                xyz = [tuple(float(c) for c in p) for p in vtk_to_numpy(grid.GetPoints().GetData())]
                conn = vtk_to_numpy(grid.GetCells().GetConnectivityArray())
                theirs = sorted(tuple(sorted(xyz[conn[4 * i + k]] for k in range(4))) for i in range(n_cells))
                ours = sorted(tuple(sorted(points[v] for v in t)) for t in tets)
                if theirs != ours:
                    problems.append("tetrahedra (as point sets) differ from the .node/.ele")
        types = {grid.GetCellType(i) for i in range(n_cells)}
        if types and types != {vtk.VTK_TETRA}:
            problems.append("cell types %s, expected only VTK_TETRA" % sorted(types))
        if problems:
            bad += 1
            print("%s: %s" % (path, "; ".join(problems)))
        else:
            print("%s: read by VTK %s: %d points, %d tetrahedra%s"
                  % (path, vtk.vtkVersion.GetVTKVersion(), n_points, n_cells,
                     (", fields " + fields) if fields else ", as in the .node/.ele"))
    sys.exit(1 if bad else 0)


main()
