#pragma once
// Reading point sets and writing / reading meshes.
#include <array>
#include <string>
#include <vector>

#include "pdt/geometry.hpp"
#include "pdt/triangulation.hpp"

namespace pdt {

// Reads the points of a point-set file, by extension: .xyz (x y z per line,
// extra columns ignored), .xyz.gz, .ply (ascii or binary_little_endian; only
// the 'vertex' element's x y z), .off (vertices only), .node (TetGen),
// .smesh (TetGen PLC node section). Throws pdt::Error(bad_format) with file and
// line, or pdt::Error(io_failure).
std::vector<Point3> read_points(const std::string& path);

// A tetrahedral mesh as plain arrays: what the writers take and check_mesh reads.
struct Mesh {
  std::vector<Point3> points;                    // index = node number (0-based)
  std::vector<std::array<std::uint32_t, 4>> tets;  // indices into points
};

// The finite part of a triangulation, vertices renumbered 0..n-1 in id order.
Mesh extract_mesh(const Triangulation& t);

// TetGen: path.node + path.ele (path given with or without extension),
// 0-based numbering. VTK: .vtu UnstructuredGrid (ASCII) ParaView opens.
// Writes go through a temporary file and a rename; failure throws io_failure.
void write_tetgen(const std::string& path, const Mesh& mesh);
void write_vtu(const std::string& path, const Mesh& mesh);
Mesh read_tetgen(const std::string& path);  // reads .node and the .ele beside it

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
