// SPDX-License-Identifier: MIT
#pragma once
// Reading point sets and writing / reading meshes.
#include <array>
#include <span>
#include <string>
#include <vector>

#include "pdt/geometry.hpp"
#include "pdt/triangulation.hpp"

namespace pdt {

// Reads the points of a point-set file, by extension: .xyz (x y z per line,
// extra columns ignored), .xyz.gz (gzip read as read_ops reads it), .ply
// (ascii, binary_little_endian or binary_big_endian; only the 'vertex'
// element's x y z), .off (vertices only), .node (TetGen),
// .smesh (TetGen PLC node section). Throws pdt::Error(bad_format) with file and
// line, or pdt::Error(io_failure). A header's counts must match the data: lines
// or bytes after the elements a .ply, .off (with its face count) or .node
// header announces are refused, as a count too low would otherwise drop points
// silently. Lines end in LF or CR LF; a CR inside a line (a file of CR-only
// line ends) is refused.
std::vector<Point3> read_points(const std::string& path);

// A tetrahedral mesh as plain arrays: what the writers take and check_mesh reads.
struct Mesh {
  std::vector<Point3> points;                    // index = node number (0-based)
  std::vector<std::array<std::uint32_t, 4>> tets;  // indices into points
};

// The finite part of a triangulation, vertices renumbered 0..n-1 in id order.
Mesh extract_mesh(const Triangulation& t);

// How write_vtu stores its arrays: VTK's XML UnstructuredGrid, as ParaView
// writes it, with the data appended after the XML in binary, zlib-compressed
// (the default) or raw, or inline as ASCII text.
enum class VtuEncoding { zlib, raw, ascii };

// A value per tetrahedron, written as VTK cell data (a quality, a label).
struct CellField {
  std::string name;
  std::vector<double> values;
};

// TetGen: path.node + path.ele (path given with or without extension),
// 0-based numbering. VTK: .vtu UnstructuredGrid ParaView opens, with
// optional cell fields, refused (invalid_argument) if one's size differs
// from the tetrahedra's, or its name is empty, given twice, or not UTF-8
// text XML can hold (controls other than tab, newline and carriage return
// excluded): VTK reads an array by its name. A tetrahedron naming a point that is not there, or a point
// with a NaN or infinite coordinate, is refused (invalid_argument) before
// anything is written, and so is a path that names no file ("", a folder
// "out/", or for TetGen ".node" alone). Writes go through a temporary file
// and a rename, except to what cannot be renamed onto (a device, a FIFO, a
// descriptor by name: /dev/stdout, /dev/fd/N), written in place; failure
// throws io_failure.
void write_tetgen(const std::string& path, const Mesh& mesh);
// The same straight from a triangulation, a line at a time, without copying
// the mesh first (for large meshes). Nodes numbered in vertex-id order.
void write_tetgen(const std::string& path, const Triangulation& t);
void write_vtu(const std::string& path, const Mesh& mesh, VtuEncoding encoding = VtuEncoding::zlib,
               std::span<const CellField> cell_fields = {});
// Reads .node and the .ele beside it. Of a quadratic mesh (10 nodes a
// tetrahedron) it keeps the corners: the nodes used only as edge nodes are
// left out of points, the others keep their order.
Mesh read_tetgen(const std::string& path);

// The two files write_tetgen writes and read_tetgen reads for `path`: a path
// ending in .node or .ele (any case) names one of them as it is, and the
// other gets the other extension, in upper case if the given one is
// ("m.NODE": "m.ELE"); any other path gets both appended.
struct TetgenFiles {
  std::string node, ele;
};
TetgenFiles tetgen_files(const std::string& path);

struct MeshCheck {
  bool valid = false;         // a Delaunay tetrahedralization of its points
  std::string message;        // what failed, or a summary
  std::size_t tets = 0, points = 0;
};
// Checks that the tets are positively oriented (or all negative), that every
// interior facet is shared by exactly two tets, that the boundary facets form the
// convex hull of the points, that every point is used, and that every interior facet is
// locally Delaunay (exact predicates).
MeshCheck check_mesh(const Mesh& mesh);

}  // namespace pdt
