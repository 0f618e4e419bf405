// Meshes: extraction from a triangulation, TetGen and VTK writers, TetGen
// reader. (check_mesh is in mesh_check.cpp, the point readers in
// point_readers.cpp.)
//
// Writers go through detail::OutputFile: a temporary file beside the target,
// every write checked, renamed into place only when complete. Coordinates are
// written with 17 significant digits, so reading a mesh back gives the same
// doubles.
#include <algorithm>
#include <array>
#include <cstring>
#include <string>
#include <vector>

#include "io_util.hpp"
#include "pdt/error.hpp"
#include "pdt/io.hpp"
#include "point_readers.hpp"

namespace pdt {

namespace {

// TetGen file base name: the path without a .node/.ele extension.
std::string tetgen_base(const std::string& path) {
  for (const char* ext : {".node", ".ele"})
    if (detail::ends_with_nocase(path, ext)) return path.substr(0, path.size() - std::strlen(ext));
  return path;
}

void check_indices(const Mesh& mesh, const char* who) {
  const std::size_t n = mesh.points.size();
  for (std::size_t t = 0; t < mesh.tets.size(); ++t)
    for (std::uint32_t v : mesh.tets[t])
      if (v >= n)
        throw Error(ErrorCode::invalid_argument, std::string(who) + ": tetrahedron " + std::to_string(t) +
                                                     " uses point " + std::to_string(v) + " but there are only " +
                                                     std::to_string(n) + " points");
}

}  // namespace

Mesh extract_mesh(const Triangulation& t) {
  Mesh m;
  const std::vector<VertexId> ids = t.vertices();  // increasing: node numbers follow id order
  std::vector<std::uint32_t> node_of(t.vertex_id_bound(), 0xFFFFFFFFu);
  m.points.reserve(ids.size());
  for (std::size_t i = 0; i < ids.size(); ++i) {
    node_of[ids[i]] = static_cast<std::uint32_t>(i);
    m.points.push_back(t.point(ids[i]));
  }
  const auto cells = t.finite_cells();  // positively oriented
  m.tets.reserve(cells.size());
  for (const auto& c : cells) m.tets.push_back({node_of[c[0]], node_of[c[1]], node_of[c[2]], node_of[c[3]]});
  return m;
}

void write_tetgen(const std::string& path, const Mesh& mesh) {
  check_indices(mesh, "write_tetgen");
  const std::string base = tetgen_base(path);
  detail::OutputFile node(base + ".node");
  detail::OutputFile ele(base + ".ele");
  std::string line;
  line.reserve(128);
  // .node: "<#points> <dimension> <#attributes> <boundary markers 0/1>", then
  // "<index> x y z", 0-based (TetGen takes the numbering from the first index).
  detail::append_uint(line, mesh.points.size());
  line += " 3 0 0\n";
  node.put(line);
  for (std::size_t i = 0; i < mesh.points.size(); ++i) {
    line.clear();
    detail::append_uint(line, i);
    for (double c : {mesh.points[i].x, mesh.points[i].y, mesh.points[i].z}) {
      line += ' ';
      detail::append_double(line, c);
    }
    line += '\n';
    node.put(line);
  }
  // .ele: "<#tetrahedra> <nodes per tetrahedron> <#attributes>", then
  // "<index> a b c d", positively oriented as given.
  line.clear();
  detail::append_uint(line, mesh.tets.size());
  line += " 4 0\n";
  ele.put(line);
  for (std::size_t i = 0; i < mesh.tets.size(); ++i) {
    line.clear();
    detail::append_uint(line, i);
    for (std::uint32_t v : mesh.tets[i]) {
      line += ' ';
      detail::append_uint(line, v);
    }
    line += '\n';
    ele.put(line);
  }
  // Both complete before either is renamed: a failure leaves neither file.
  node.finish();
  ele.finish();
  node.commit();
  ele.commit();
}

void write_vtu(const std::string& path, const Mesh& mesh) {
  check_indices(mesh, "write_vtu");
  detail::OutputFile out(path);
  std::string s;
  s.reserve(256);
  s = "<?xml version=\"1.0\"?>\n"
      "<VTKFile type=\"UnstructuredGrid\" version=\"0.1\" byte_order=\"LittleEndian\">\n"
      "  <UnstructuredGrid>\n"
      "    <Piece NumberOfPoints=\"";
  detail::append_uint(s, mesh.points.size());
  s += "\" NumberOfCells=\"";
  detail::append_uint(s, mesh.tets.size());
  s += "\">\n"
       "      <Points>\n"
       "        <DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">\n";
  out.put(s);
  for (const Point3& p : mesh.points) {
    s = "          ";
    detail::append_double(s, p.x);
    s += ' ';
    detail::append_double(s, p.y);
    s += ' ';
    detail::append_double(s, p.z);
    s += '\n';
    out.put(s);
  }
  out.put("        </DataArray>\n"
          "      </Points>\n"
          "      <Cells>\n"
          "        <DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">\n");
  for (const auto& t : mesh.tets) {
    s = "          ";
    for (int i = 0; i < 4; ++i) {
      if (i) s += ' ';
      detail::append_uint(s, t[i]);
    }
    s += '\n';
    out.put(s);
  }
  out.put("        </DataArray>\n"
          "        <DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n");
  // Offsets: the end of each cell's run in the connectivity array.
  for (std::size_t i = 0; i < mesh.tets.size(); i += 8) {
    s = "         ";
    for (std::size_t j = i; j < std::min(mesh.tets.size(), i + 8); ++j) {
      s += ' ';
      detail::append_uint(s, 4 * (j + 1));
    }
    s += '\n';
    out.put(s);
  }
  out.put("        </DataArray>\n"
          "        <DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n");
  // 10 = VTK_TETRA; its point order (0,1,2 counter-clockwise seen from 3) is
  // the positive orientation the mesh uses.
  for (std::size_t i = 0; i < mesh.tets.size(); i += 32) {
    s = "         ";
    for (std::size_t j = i; j < std::min(mesh.tets.size(), i + 32); ++j) s += " 10";
    s += '\n';
    out.put(s);
  }
  out.put("        </DataArray>\n"
          "      </Cells>\n"
          "    </Piece>\n"
          "  </UnstructuredGrid>\n"
          "</VTKFile>\n");
  out.commit();
}

Mesh read_tetgen(const std::string& path) {
  const std::string base = tetgen_base(path);
  Mesh m;
  std::uint64_t first = 0;
  {
    detail::InputFile nf(base + ".node");
    m.points = detail::read_node_section(nf, &first);
  }
  detail::InputFile f(base + ".ele");
  std::string_view fields[16];
  std::string_view line;
  auto next = [&](std::size_t& n) {
    while (f.read_line(line)) {
      n = detail::split_fields(detail::strip_comment(line), fields, 16);
      if (n > 0) return true;
    }
    return false;
  };
  auto count_field = [&](std::string_view tok, const char* what) {
    std::uint64_t v = 0;
    if (detail::parse_u64(tok, v) != detail::NumStatus::ok)
      f.fail(std::string(what) + " '" + std::string(tok) + "' is not a non-negative integer");
    return v;
  };
  std::size_t n = 0;
  if (!next(n)) f.fail("file ends before the header; expected '<#tetrahedra> 4 <#attributes>'");
  if (n < 2) f.fail("header has " + std::to_string(n) + " field(s); expected '<#tetrahedra> 4 <#attributes>'");
  const std::uint64_t count = count_field(fields[0], "tetrahedron count");
  const std::uint64_t per = count_field(fields[1], "nodes per tetrahedron");
  if (per != 4 && per != 10) f.fail("nodes per tetrahedron is " + std::to_string(per) + "; expected 4 (or 10)");
  m.tets.reserve(static_cast<std::size_t>(std::min<std::uint64_t>(count, 1u << 22)));
  for (std::uint64_t i = 0; i < count; ++i) {
    if (!next(n)) f.fail("file ends after " + std::to_string(i) + " of " + std::to_string(count) + " tetrahedra");
    if (n < 1 + per) f.fail("tetrahedron line has " + std::to_string(n) + " field(s); expected 'index a b c d'");
    std::array<std::uint32_t, 4> t{};
    for (int k = 0; k < 4; ++k) {  // the 4 corners; quadratic tets' edge nodes are ignored
      const std::uint64_t v = count_field(fields[1 + k], "node index");
      if (v < first || v - first >= m.points.size())
        f.fail("node index " + std::to_string(v) + " is not one of the " + std::to_string(m.points.size()) +
               " nodes (numbered from " + std::to_string(first) + ")");
      t[static_cast<std::size_t>(k)] = static_cast<std::uint32_t>(v - first);
    }
    m.tets.push_back(t);
  }
  return m;
}

}  // namespace pdt
