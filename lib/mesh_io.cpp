// SPDX-License-Identifier: MIT
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
#include <cmath>
#include <cstring>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

#include <zlib.h>

#include "io_util.hpp"
#include "pdt/error.hpp"
#include "pdt/io.hpp"
#include "point_readers.hpp"

namespace pdt {

TetgenFiles tetgen_files(const std::string& path) {
  // The named file keeps its name; its partner's extension is upper case if
  // the named one's is ("mesh.NODE": "mesh.ELE").
  for (const char* ext : {".node", ".ele"}) {
    const std::size_t n = std::strlen(ext);
    if (!detail::ends_with_nocase(path, ext)) continue;
    const std::string base = path.substr(0, path.size() - n);
    const bool upper = std::all_of(path.end() - static_cast<std::ptrdiff_t>(n) + 1, path.end(),
                                   [](char c) { return c >= 'A' && c <= 'Z'; });
    const std::string node = upper ? ".NODE" : ".node", ele = upper ? ".ELE" : ".ele";
    return ext[1] == 'n' ? TetgenFiles{path, base + ele} : TetgenFiles{base + node, path};
  }
  return {path + ".node", path + ".ele"};
}

namespace {

// A path that names no file, refused before anything is written (io_util),
// and for TetGen's pair a name that is its extension alone (".node": the files
// would be hidden ".node" and ".ele"). A VTK file named ".vtu" is a (hidden)
// name like any other.
void refuse_mesh_path_naming_no_file(const std::string& path, const char* who, bool tetgen_pair) {
  const std::string name = path.substr(path.find_last_of('/') + 1);
  const std::string node = tetgen_files(name).node;
  if (detail::names_no_file(path) || (tetgen_pair && node.size() == 5 && detail::ends_with_nocase(node, ".node")))
    detail::refuse_nameless(path, who, tetgen_pair ? "mesh.node" : "mesh.vtu");
}

// What the writers refuse before writing anything: a tetrahedron naming a
// point that is not there, or a point that is not finite (the readers, pdt's
// and TetGen's, refuse it).
void refuse_unwritable(const Mesh& mesh, const char* who) {
  const std::size_t n = mesh.points.size();
  for (std::size_t i = 0; i < n; ++i) {
    const Point3& p = mesh.points[i];
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
      throw Error(ErrorCode::invalid_argument, std::string(who) + ": point " + std::to_string(i) + " (" +
                                                   std::to_string(p.x) + ", " + std::to_string(p.y) + ", " +
                                                   std::to_string(p.z) + ") is not finite; nothing was written");
  }
  for (std::size_t t = 0; t < mesh.tets.size(); ++t)
    for (std::uint32_t v : mesh.tets[t])
      if (v >= n)
        throw Error(ErrorCode::invalid_argument, std::string(who) + ": tetrahedron " + std::to_string(t) +
                                                     " uses point " + std::to_string(v) + " but there " +
                                                     (n == 1 ? "is only " : "are only ") +
                                                     detail::counted(n, "point", "points"));
}

// A field name as an XML attribute value: & < > " ' escaped, and tab,
// newline and carriage return as character references (a parser turns them
// into spaces otherwise), so that a name refuse_unreadable_names accepts gives
// a file XML parsers (ParaView's) read, and reads back as given.
std::string xml_attribute(const std::string& s) {
  std::string out;
  out.reserve(s.size());
  for (char c : s) switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      case '\'': out += "&apos;"; break;
      case '\t': out += "&#9;"; break;
      case '\n': out += "&#10;"; break;
      case '\r': out += "&#13;"; break;
      default: out += c;
    }
  return out;
}

// Where the name stops being text an XML 1.0 attribute can hold: the byte
// offset of the first byte that is not valid UTF-8 (an overlong form, a
// surrogate, past U+10FFFF) or starts a character XML excludes (controls
// other than tab, newline and carriage return; U+FFFE, U+FFFF); npos if none.
std::size_t first_non_xml_byte(const std::string& s) {
  const auto* b = reinterpret_cast<const unsigned char*>(s.data());
  const std::size_t n = s.size();
  for (std::size_t i = 0; i < n;) {
    const unsigned c = b[i];
    if (c < 0x80) {
      if (c < 0x20 && c != '\t' && c != '\n' && c != '\r') return i;
      ++i;
      continue;
    }
    std::size_t len = 0;
    unsigned lo = 0x80, hi = 0xBF;  // the second byte's range
    if (c >= 0xC2 && c <= 0xDF) len = 2;
    else if (c == 0xE0) len = 3, lo = 0xA0;
    else if ((c >= 0xE1 && c <= 0xEC) || c == 0xEE || c == 0xEF) len = 3;
    else if (c == 0xED) len = 3, hi = 0x9F;  // not a surrogate
    else if (c == 0xF0) len = 4, lo = 0x90;
    else if (c >= 0xF1 && c <= 0xF3) len = 4;
    else if (c == 0xF4) len = 4, hi = 0x8F;  // at most U+10FFFF
    if (len == 0 || i + len > n || b[i + 1] < lo || b[i + 1] > hi) return i;
    for (std::size_t k = 2; k < len; ++k)
      if (b[i + k] < 0x80 || b[i + k] > 0xBF) return i;
    if (c == 0xEF && b[i + 1] == 0xBF && b[i + 2] >= 0xBE) return i;  // U+FFFE, U+FFFF
    i += len;
  }
  return std::string::npos;
}

// A cell field VTK's reader (and so ParaView) cannot read back by its name:
// no name (the array would have none), a name given twice (the reader
// crashes), a name XML cannot hold.
void refuse_unreadable_names(std::span<const CellField> fields) {
  for (std::size_t k = 0; k < fields.size(); ++k) {
    const std::string& name = fields[k].name;
    const std::string which = "write_vtu: cell field " + std::to_string(k);
    if (name.empty()) throw Error(ErrorCode::invalid_argument, which + " has no name; VTK reads an array by its name");
    if (const std::size_t at = first_non_xml_byte(name); at != std::string::npos) {
      static const char hex[] = "0123456789ABCDEF";
      const auto byte = static_cast<unsigned char>(name[at]);
      throw Error(ErrorCode::invalid_argument, which + "'s name has byte 0x" + hex[byte >> 4] + hex[byte & 15] +
                                                   " at offset " + std::to_string(at) +
                                                   ", which is not UTF-8 text an XML file can hold");
    }
    for (std::size_t j = 0; j < k; ++j)
      if (fields[j].name == name)
        throw Error(ErrorCode::invalid_argument, which + " is named '" + name + "' as field " + std::to_string(j) +
                                                     " is; VTK needs distinct names");
  }
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

// Writes tetgen_files(path) a line at a time: each_point(emit) calls
// emit(p) for the points in their order, each_tet(emit) emit(a, b, c, d) with
// 0-based point numbers. Both files complete before either is renamed, so a
// failure leaves neither.
//   .node: "<#points> <dimension> <#attributes> <boundary markers 0/1>", then
//          "<index> x y z", 0-based (TetGen takes the numbering from the first index).
//   .ele:  "<#tetrahedra> <nodes per tetrahedron> <#attributes>", then
//          "<index> a b c d", positively oriented as given.
namespace {
template <class EachPoint, class EachTet>
void write_tetgen_files(const std::string& path, std::size_t points, EachPoint each_point, std::size_t tets,
                        EachTet each_tet) {
  refuse_mesh_path_naming_no_file(path, "write_tetgen", true);
  const TetgenFiles files = tetgen_files(path);
  detail::OutputFile node(files.node);
  detail::OutputFile ele(files.ele);
  std::string line;
  line.reserve(128);
  detail::append_uint(line, points);
  line += " 3 0 0\n";
  node.put(line);
  std::uint64_t k = 0;
  each_point([&](const Point3& p) {
    line.clear();
    detail::append_uint(line, k++);
    for (double c : {p.x, p.y, p.z}) {
      line += ' ';
      detail::append_double(line, c);
    }
    line += '\n';
    node.put(line);
  });
  line.clear();
  detail::append_uint(line, tets);
  line += " 4 0\n";
  ele.put(line);
  k = 0;
  each_tet([&](std::uint32_t a, std::uint32_t b, std::uint32_t c, std::uint32_t d) {
    line.clear();
    detail::append_uint(line, k++);
    for (std::uint32_t v : {a, b, c, d}) {
      line += ' ';
      detail::append_uint(line, v);
    }
    line += '\n';
    ele.put(line);
  });
  node.finish();
  ele.finish();
  node.commit();
  ele.commit();
}
}  // namespace

void write_tetgen(const std::string& path, const Mesh& mesh) {
  refuse_unwritable(mesh, "write_tetgen");
  write_tetgen_files(
      path, mesh.points.size(),
      [&](auto emit) {
        for (const Point3& p : mesh.points) emit(p);
      },
      mesh.tets.size(),
      [&](auto emit) {
        for (const auto& t : mesh.tets) emit(t[0], t[1], t[2], t[3]);
      });
}

namespace {

// One DataArray's bytes in the appended section, as VTK reads them: a UInt64
// byte count then the data (raw), or zlib blocks of 32 KiB with their header
// (count, block size, last block's size, compressed sizes), as ParaView writes.
std::string encode_appended(const void* data, std::size_t bytes, VtuEncoding encoding) {
  const auto* in = static_cast<const unsigned char*>(data);
  auto put_u64 = [](std::string& out, std::uint64_t v) {
    for (int b = 0; b < 8; ++b) out += static_cast<char>((v >> (8 * b)) & 0xFF);
  };
  std::string out;
  if (encoding == VtuEncoding::raw) {
    out.reserve(8 + bytes);
    put_u64(out, bytes);
    out.append(reinterpret_cast<const char*>(in), bytes);
    return out;
  }
  constexpr std::size_t block = 32768;
  const std::size_t blocks = bytes == 0 ? 0 : (bytes + block - 1) / block;
  std::vector<std::string> packed(blocks);
  std::vector<unsigned char> buf(compressBound(block));
  for (std::size_t b = 0; b < blocks; ++b) {
    const std::size_t n = std::min(block, bytes - b * block);
    uLongf len = static_cast<uLongf>(buf.size());
    if (compress2(buf.data(), &len, in + b * block, static_cast<uLong>(n), 6) != Z_OK)
      throw Error(ErrorCode::io_failure, "write_vtu: zlib failed to compress the data");
    packed[b].assign(reinterpret_cast<const char*>(buf.data()), len);
  }
  put_u64(out, blocks);
  put_u64(out, block);
  put_u64(out, blocks ? bytes - (blocks - 1) * block : 0);
  for (const std::string& p : packed) put_u64(out, p.size());
  for (const std::string& p : packed) out += p;
  return out;
}

// Numbers as text, per_line to a line (VTK's ASCII form).
template <class T>
void put_ascii(detail::OutputFile& out, const T* v, std::size_t n, std::size_t per_line) {
  std::string s;
  for (std::size_t i = 0; i < n; i += per_line) {
    s = "         ";
    for (std::size_t j = i; j < std::min(n, i + per_line); ++j) {
      s += ' ';
      if constexpr (std::is_floating_point_v<T>)
        detail::append_double(s, static_cast<double>(v[j]));
      else
        detail::append_uint(s, static_cast<std::uint64_t>(v[j]));
    }
    s += '\n';
    out.put(s);
  }
}

}  // namespace

void write_vtu(const std::string& path, const Mesh& mesh, VtuEncoding encoding, std::span<const CellField> cell_fields) {
  refuse_mesh_path_naming_no_file(path, "write_vtu", false);
  refuse_unwritable(mesh, "write_vtu");
  refuse_unreadable_names(cell_fields);
  for (const CellField& f : cell_fields)
    if (f.values.size() != mesh.tets.size())
      throw Error(ErrorCode::invalid_argument, "write_vtu: cell field '" + f.name + "' has " +
                                                   std::to_string(f.values.size()) + " values for " +
                                                   std::to_string(mesh.tets.size()) + " tetrahedra");
  // The arrays as VTK holds them (points as 3 doubles, connectivity and
  // offsets as Int64, types as UInt8: 10 = VTK_TETRA, whose point order
  // (0,1,2 counter-clockwise seen from 3) is the positive orientation the
  // mesh uses).
  std::vector<double> xyz;
  xyz.reserve(3 * mesh.points.size());
  for (const Point3& p : mesh.points) xyz.insert(xyz.end(), {p.x, p.y, p.z});
  std::vector<std::int64_t> conn, offsets;
  conn.reserve(4 * mesh.tets.size());
  offsets.reserve(mesh.tets.size());
  for (std::size_t i = 0; i < mesh.tets.size(); ++i) {
    for (std::uint32_t v : mesh.tets[i]) conn.push_back(v);
    offsets.push_back(static_cast<std::int64_t>(4 * (i + 1)));
  }
  const std::vector<std::uint8_t> types(mesh.tets.size(), 10);

  struct Array {
    const char* type;
    std::string name;  // empty: none
    int components;
    const void* data;
    std::size_t count;  // values
    std::size_t size;   // bytes per value
  };
  std::vector<Array> arrays = {{"Float64", "", 3, xyz.data(), xyz.size(), 8},
                               {"Int64", "connectivity", 1, conn.data(), conn.size(), 8},
                               {"Int64", "offsets", 1, offsets.data(), offsets.size(), 8},
                               {"UInt8", "types", 1, types.data(), types.size(), 1}};
  for (const CellField& f : cell_fields) arrays.push_back({"Float64", f.name, 1, f.values.data(), f.values.size(), 8});

  std::vector<std::string> encoded;
  std::vector<std::uint64_t> offset_of;
  if (encoding != VtuEncoding::ascii) {
    std::uint64_t at = 0;
    for (const Array& a : arrays) {
      encoded.push_back(encode_appended(a.data, a.count * a.size, encoding));
      offset_of.push_back(at);
      at += encoded.back().size();
    }
  }
  auto header = [&](std::size_t k) {
    const Array& a = arrays[k];
    std::string s = std::string("<DataArray type=\"") + a.type + "\"";
    if (!a.name.empty()) s += " Name=\"" + xml_attribute(a.name) + "\"";
    if (a.components != 1) s += " NumberOfComponents=\"" + std::to_string(a.components) + "\"";
    if (encoding == VtuEncoding::ascii) return s + " format=\"ascii\">\n";
    return s + " format=\"appended\" offset=\"" + std::to_string(offset_of[k]) + "\"/>\n";
  };
  auto body = [&](detail::OutputFile& out, std::size_t k) {
    if (encoding != VtuEncoding::ascii) return;
    const Array& a = arrays[k];
    if (std::string(a.type) == "Float64")
      put_ascii(out, static_cast<const double*>(a.data), a.count, a.components == 3 ? 3 : 6);
    else if (std::string(a.type) == "Int64")
      put_ascii(out, static_cast<const std::int64_t*>(a.data), a.count, k == 1 ? 4 : 8);
    else
      put_ascii(out, static_cast<const std::uint8_t*>(a.data), a.count, 32);
    out.put("        </DataArray>\n");
  };

  detail::OutputFile out(path);
  std::string s = "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\"";
  if (encoding == VtuEncoding::zlib) s += " compressor=\"vtkZLibDataCompressor\"";
  s += ">\n  <UnstructuredGrid>\n    <Piece NumberOfPoints=\"";
  detail::append_uint(s, mesh.points.size());
  s += "\" NumberOfCells=\"";
  detail::append_uint(s, mesh.tets.size());
  s += "\">\n      <Points>\n        " + header(0);
  out.put(s);
  body(out, 0);
  out.put("      </Points>\n      <Cells>\n");
  for (std::size_t k = 1; k <= 3; ++k) {
    out.put("        " + header(k));
    body(out, k);
  }
  out.put("      </Cells>\n");
  if (!cell_fields.empty()) {
    out.put("      <CellData Scalars=\"" + xml_attribute(cell_fields.front().name) + "\">\n");
    for (std::size_t k = 4; k < arrays.size(); ++k) {
      out.put("        " + header(k));
      body(out, k);
    }
    out.put("      </CellData>\n");
  }
  out.put("    </Piece>\n  </UnstructuredGrid>\n");
  if (encoding != VtuEncoding::ascii) {
    out.put("  <AppendedData encoding=\"raw\">\n   _");
    for (const std::string& e : encoded) out.put(e);
    out.put("\n  </AppendedData>\n");
  }
  out.put("</VTKFile>\n");
  out.commit();
}

void write_tetgen(const std::string& path, const Triangulation& t) {
  // Straight from the triangulation: no copy of the mesh, only its vertex
  // ids (vertices(), which skips the ids shrink_to_fit gave back).
  const std::vector<VertexId> ids = t.vertices();
  std::vector<std::uint32_t> node_of(t.vertex_id_bound(), 0xFFFFFFFFu);
  write_tetgen_files(
      path, ids.size(),
      [&](auto emit) {
        std::uint32_t next = 0;
        for (VertexId v : ids) {
          node_of[v] = next++;
          emit(t.point(v));
        }
      },
      t.number_of_finite_cells(),
      [&](auto emit) {
        for (CellId c = 0; c < t.cell_id_bound(); ++c)
          if (t.is_finite_cell(c))
            emit(node_of[t.cell_vertex(c, 0)], node_of[t.cell_vertex(c, 1)], node_of[t.cell_vertex(c, 2)],
                 node_of[t.cell_vertex(c, 3)]);
      });
}

namespace {
// A quadratic (second-order) mesh's nodes that are only edge nodes (its
// tets' nodes 5 to 10, at or near the edges' midpoints) are not vertices of
// the tetrahedralization its corners make: they leave m.points, which keeps
// the corners (and any node no tet uses, which check_mesh then reports), in
// their order.
void drop_edge_nodes(Mesh& m, const std::vector<std::uint32_t>& edge_nodes) {
  if (edge_nodes.empty()) return;
  constexpr std::uint8_t corner = 1, edge = 2;
  std::vector<std::uint8_t> role(m.points.size(), 0);
  for (const auto& t : m.tets)
    for (std::uint32_t v : t) role[v] |= corner;
  for (std::uint32_t v : edge_nodes) role[v] |= edge;
  std::vector<std::uint32_t> renumbered(m.points.size());
  std::size_t kept = 0;
  for (std::size_t i = 0; i < m.points.size(); ++i) {
    renumbered[i] = static_cast<std::uint32_t>(kept);
    if (role[i] != edge) m.points[kept++] = m.points[i];
  }
  m.points.resize(kept);
  for (auto& t : m.tets)
    for (std::uint32_t& v : t) v = renumbered[v];
}
}  // namespace

Mesh read_tetgen(const std::string& path) {
  const TetgenFiles files = tetgen_files(path);
  Mesh m;
  std::uint64_t first = 0;
  {
    detail::InputFile nf(files.node);
    m.points = detail::read_node_section(nf, &first);
    detail::require_end(nf, "the " + std::to_string(m.points.size()) + " nodes its header announces");
  }
  detail::InputFile f(files.ele);
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
  if (n > 3) f.fail("header has " + std::to_string(n) + " fields; expected '<#tetrahedra> 4 <#attributes>'");
  const std::uint64_t attributes = n == 3 ? count_field(fields[2], "attribute count") : 0;
  if (attributes > 1000) f.fail("attribute count " + std::to_string(attributes) + " is not plausible");
  // Every line: its index (the first numbered 0 or 1, then consecutive),
  // the nodes, the attributes; nothing more, nothing less.
  const std::uint64_t fields_per_line = 1 + per + attributes;
  std::vector<std::uint32_t> edge_nodes;  // quadratic tets' (per == 10)
  std::uint64_t first_index = 0;
  m.tets.reserve(static_cast<std::size_t>(std::min<std::uint64_t>(count, 1u << 22)));
  for (std::uint64_t i = 0; i < count; ++i) {
    if (!next(n)) f.fail("file ends after " + std::to_string(i) + " of " + std::to_string(count) + " tetrahedra");
    if (n != fields_per_line)
      f.fail("tetrahedron line has " + std::to_string(n) + " field(s); the header asks for " +
             std::to_string(fields_per_line) + " (index, " + std::to_string(per) + " nodes, " +
             std::to_string(attributes) + " attribute(s))");
    const std::uint64_t index = count_field(fields[0], "tetrahedron index");
    if (i == 0 && index > 1) f.fail("the first tetrahedron is numbered " + std::to_string(index) + "; expected 0 or 1");
    if (i == 0) first_index = index;
    if (index != first_index + i)
      f.fail("tetrahedron index " + std::to_string(index) + "; expected " + std::to_string(first_index + i) +
             " (consecutive)");
    std::array<std::uint32_t, 4> t{};
    for (std::uint64_t k = 0; k < per; ++k) {  // the 4 corners, then a quadratic tet's 6 edge nodes
      const std::uint64_t v = count_field(fields[1 + k], "node index");
      if (v < first || v - first >= m.points.size())
        f.fail("node index " + std::to_string(v) + " is not one of the " + std::to_string(m.points.size()) +
               " nodes (numbered from " + std::to_string(first) + ")");
      if (k < 4)
        t[static_cast<std::size_t>(k)] = static_cast<std::uint32_t>(v - first);
      else
        edge_nodes.push_back(static_cast<std::uint32_t>(v - first));
    }
    m.tets.push_back(t);
  }
  detail::require_end(f, "the " + std::to_string(count) + " tetrahedra its header announces");
  drop_edge_nodes(m, edge_nodes);
  return m;
}

}  // namespace pdt
