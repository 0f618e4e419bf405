// SPDX-License-Identifier: MIT
// pdt::read_points: point sets from .xyz, .xyz.gz, .ply, .off, .node, .smesh.
//
// Every reader returns the points in file order, coordinates converted exactly
// (text: correctly rounded decimal; binary float32/ints: exact widening to
// double). Every reader rejects NaN/Inf, missing numbers and truncated files
// with pdt::Error(bad_format) naming the file and the line (binary: the
// element index and byte offset), so no garbage point ever reaches a
// triangulation.
#include "point_readers.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <string>
#include <utility>
#include <vector>

#include "pdt/error.hpp"
#include "pdt/io.hpp"
#include "point_checks.hpp"

namespace pdt {
namespace detail {

namespace {

// Parses fields[0..2] as a point; fails naming the line.
Point3 parse_point(InputFile& f, const std::string_view* fields, const char* what) {
  double c[3];
  for (int i = 0; i < 3; ++i) {
    NumStatus s = parse_double(fields[i], c[i]);
    if (s != NumStatus::ok)
      f.fail(std::string(what) + " coordinate " + std::to_string(i + 1) + " " + quote(fields[i]) + " " +
             describe(s) + "; expected a finite decimal number");
  }
  return {c[0], c[1], c[2]};
}

// The next line with something other than blanks and comments, split; false at EOF.
bool next_content_line(InputFile& f, std::string_view* fields, std::size_t max, std::size_t& n) {
  std::string_view line;
  while (f.read_line(line)) {
    n = split_fields(strip_comment(line), fields, max);
    if (n > 0) return true;
  }
  return false;
}

std::uint64_t parse_count(InputFile& f, std::string_view tok, const char* what) {
  std::uint64_t v = 0;
  if (parse_u64(tok, v) != NumStatus::ok)
    f.fail(std::string(what) + " " + quote(tok) + " is not a non-negative integer");
  return v;
}

// Caps a reservation by a count read from a file, so a corrupt header cannot
// trigger a huge allocation before the data proves it.
std::size_t sane_reserve(std::uint64_t n) { return static_cast<std::size_t>(std::min<std::uint64_t>(n, 1u << 22)); }

// ---- .xyz ------------------------------------------------------------------

std::vector<Point3> read_xyz(InputFile& f) {
  std::vector<Point3> pts;
  std::string_view fields[3];
  std::string_view line;
  f.skip_utf8_bom();
  while (f.read_line(line)) {
    std::size_t n = split_fields(strip_comment(line), fields, 3);
    if (n == 0) continue;
    if (n < 3) f.fail("only " + std::to_string(n) + " field(s); expected 'x y z' (extra columns are ignored)");
    pts.push_back(parse_point(f, fields, "point"));
  }
  return pts;
}

// ---- .off ------------------------------------------------------------------

std::vector<Point3> read_off(InputFile& f) {
  std::string_view fields[4];
  std::size_t n = 0;
  if (!next_content_line(f, fields, 4, n)) f.fail("empty file; expected an 'OFF' header");
  std::string_view head = fields[0];
  // OFF with optional prefixes: C (colours), N (normals), ST (texture): the
  // vertex lines start with x y z in all of them.
  const bool ok_head = head.size() >= 3 && head.substr(head.size() - 3) == "OFF" &&
                       head.substr(0, head.size() - 3).find_first_not_of("CNST") == std::string_view::npos;
  if (!ok_head)
    f.fail("header " + quote(head) + "; expected 'OFF' (or COFF/NOFF/STOFF); 4OFF and nOFF are not supported");
  if (n >= 2 && fields[1] == "BINARY") f.fail("binary OFF is not supported; expected an ASCII OFF file");
  std::uint64_t nv = 0, nf = 0;
  bool have_nf = false;
  if (n >= 2) {  // counts on the header line: "OFF nv nf ne"
    nv = parse_count(f, fields[1], "vertex count");
    if ((have_nf = n >= 3)) nf = parse_count(f, fields[2], "face count");
  } else {
    if (!next_content_line(f, fields, 4, n)) f.fail("file ends before the counts line; expected 'nv nf ne'");
    nv = parse_count(f, fields[0], "vertex count");
    if ((have_nf = n >= 2)) nf = parse_count(f, fields[1], "face count");
  }
  std::vector<Point3> pts;
  pts.reserve(sane_reserve(nv));
  for (std::uint64_t i = 0; i < nv; ++i) {
    if (!next_content_line(f, fields, 3, n))
      f.fail("file ends after " + std::to_string(i) + " of " + detail::counted(nv, "vertex", "vertices"));
    if (n < 3) f.fail("vertex " + std::to_string(i) + " has " + std::to_string(n) + " field(s); expected 'x y z'");
    pts.push_back(parse_point(f, fields, "vertex"));
  }
  // The faces are not needed, but counted, a line each, and then the file must
  // end: a vertex count too low would leave vertex lines there. (Without a face
  // count, which OFF requires, nothing after the vertices is checked.)
  if (have_nf) {
    for (std::uint64_t i = 0; i < nf; ++i)
      if (!next_content_line(f, fields, 1, n))
        f.fail("file ends after " + std::to_string(i) + " of " + detail::counted(nf, "face", "faces"));
    require_end(f, "the " + detail::counted(nv, "vertex", "vertices") + " and " + detail::counted(nf, "face", "faces") +
                       " its header announces (is a count in the header too low?)");
  }
  return pts;
}

// ---- .ply ------------------------------------------------------------------

enum class PlyType { i8, u8, i16, u16, i32, u32, f32, f64 };

bool ply_type(std::string_view s, PlyType& t) {
  static const struct {
    const char* name;
    PlyType type;
  } names[] = {{"char", PlyType::i8},     {"int8", PlyType::i8},     {"uchar", PlyType::u8},
               {"uint8", PlyType::u8},    {"short", PlyType::i16},   {"int16", PlyType::i16},
               {"ushort", PlyType::u16},  {"uint16", PlyType::u16},  {"int", PlyType::i32},
               {"int32", PlyType::i32},   {"uint", PlyType::u32},    {"uint32", PlyType::u32},
               {"float", PlyType::f32},   {"float32", PlyType::f32}, {"double", PlyType::f64},
               {"float64", PlyType::f64}};
  for (const auto& n : names)
    if (s == n.name) {
      t = n.type;
      return true;
    }
  return false;
}

std::size_t ply_size(PlyType t) {
  switch (t) {
    case PlyType::i8:
    case PlyType::u8: return 1;
    case PlyType::i16:
    case PlyType::u16: return 2;
    case PlyType::i32:
    case PlyType::u32:
    case PlyType::f32: return 4;
    case PlyType::f64: return 8;
  }
  return 0;
}

// The value of a binary PLY scalar, exactly as a double.
// For an integer type: its range (true), else false (a float type takes any
// value a double holds).
bool ply_integer_range(PlyType t, double& lo, double& hi, const char*& name) {
  switch (t) {
    case PlyType::i8: lo = -128, hi = 127, name = "a char (int8)"; return true;
    case PlyType::u8: lo = 0, hi = 255, name = "a uchar (uint8)"; return true;
    case PlyType::i16: lo = -32768, hi = 32767, name = "a short (int16)"; return true;
    case PlyType::u16: lo = 0, hi = 65535, name = "a ushort (uint16)"; return true;
    case PlyType::i32: lo = -2147483648.0, hi = 2147483647.0, name = "an int (int32)"; return true;
    case PlyType::u32: lo = 0, hi = 4294967295.0, name = "a uint (uint32)"; return true;
    default: return false;
  }
}

double ply_value(PlyType t, const unsigned char* p, bool big_endian) {
  unsigned char b[8];
  const std::size_t n = ply_size(t);
  for (std::size_t i = 0; i < n; ++i) b[i] = big_endian ? p[n - 1 - i] : p[i];
  std::uint64_t u = 0;
  for (std::size_t i = n; i-- > 0;) u = (u << 8) | b[i];
  switch (t) {
    case PlyType::i8: return static_cast<std::int8_t>(u);
    case PlyType::u8: return static_cast<double>(u);
    case PlyType::i16: return static_cast<std::int16_t>(u);
    case PlyType::u16: return static_cast<double>(u);
    case PlyType::i32: return static_cast<std::int32_t>(u);
    case PlyType::u32: return static_cast<double>(u);
    case PlyType::f32: return std::bit_cast<float>(static_cast<std::uint32_t>(u));
    case PlyType::f64: return std::bit_cast<double>(u);
  }
  return 0;
}

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::f32;
  bool is_list = false;
  PlyType count_type = PlyType::u8;
};

struct PlyElement {
  std::string name;
  std::uint64_t count = 0;
  std::vector<PlyProperty> props;
  bool has_list() const {
    for (const auto& p : props)
      if (p.is_list) return true;
    return false;
  }
  std::size_t stride() const {  // bytes per instance when there is no list
    std::size_t s = 0;
    for (const auto& p : props) s += ply_size(p.type);
    return s;
  }
};

// Skips n bytes in pieces of at most 64 KiB: a length the file does not hold
// costs no more memory than that before the end of the file says so. False
// at end of file.
bool skip_bytes(InputFile& f, std::uint64_t n, std::vector<unsigned char>& scratch) {
  scratch.resize(std::size_t{1} << 16);
  while (n > 0) {
    const std::size_t part = static_cast<std::size_t>(std::min<std::uint64_t>(n, scratch.size()));
    if (f.read_bytes(scratch.data(), part) != part) return false;
    n -= part;
  }
  return true;
}

// Reads and checks one binary instance of an element into vals (one value per
// scalar property; lists are skipped). Returns false at end of file.
bool ply_binary_instance(InputFile& f, const PlyElement& e, bool big, std::vector<double>& vals,
                         std::vector<unsigned char>& scratch) {
  vals.clear();
  for (const auto& p : e.props) {
    if (p.is_list) {
      unsigned char cb[8];
      const std::size_t cs = ply_size(p.count_type);
      if (f.read_bytes(cb, cs) != cs) return false;
      const double count = ply_value(p.count_type, cb, big);
      if (count < 0)
        throw Error(ErrorCode::bad_format, f.path() + ": '" + e.name + "' element (byte " + std::to_string(f.offset()) +
                                               "): negative list length " + std::to_string(static_cast<long long>(count)));
      // Up to 2^32 - 1 items of 8 bytes.
      if (!skip_bytes(f, static_cast<std::uint64_t>(count) * ply_size(p.type), scratch)) return false;
      vals.push_back(0);  // placeholder, keeps indices aligned with props
    } else {
      unsigned char vb[8];
      const std::size_t s = ply_size(p.type);
      if (f.read_bytes(vb, s) != s) return false;
      vals.push_back(ply_value(p.type, vb, big));
    }
  }
  return true;
}

std::vector<Point3> read_ply(InputFile& f) {
  std::string_view line;
  std::string_view fields[8];
  if (!f.read_line(line) || line != "ply") f.fail("first line is not 'ply'; expected a PLY file");
  enum class Fmt { ascii, le, be } fmt = Fmt::ascii;
  bool have_format = false;
  std::vector<PlyElement> elements;
  bool ended = false;
  while (f.read_line(line)) {
    std::size_t n = split_fields(line, fields, 8);
    if (n == 0) continue;
    const std::string_view kw = fields[0];
    if (kw == "comment" || kw == "obj_info") continue;
    if (kw == "end_header") {
      ended = true;
      break;
    }
    if (kw == "format") {
      if (n != 3) f.fail("expected 'format ascii|binary_little_endian|binary_big_endian 1.0'");
      if (fields[1] == "ascii") fmt = Fmt::ascii;
      else if (fields[1] == "binary_little_endian") fmt = Fmt::le;
      else if (fields[1] == "binary_big_endian") fmt = Fmt::be;
      else f.fail("unknown PLY format '" + std::string(fields[1]) + "'; expected ascii, binary_little_endian or binary_big_endian");
      have_format = true;
    } else if (kw == "element") {
      if (n != 3) f.fail("expected 'element <name> <count>'");
      PlyElement e;
      e.name = std::string(fields[1]);
      e.count = parse_count(f, fields[2], "element count");
      elements.push_back(std::move(e));
    } else if (kw == "property") {
      if (elements.empty()) f.fail("'property' before any 'element'");
      PlyProperty p;
      if (n >= 2 && fields[1] == "list") {
        if (n != 5) f.fail("expected 'property list <count type> <item type> <name>'");
        if (!ply_type(fields[2], p.count_type) || !ply_type(fields[3], p.type))
          f.fail("unknown PLY type in list property");
        if (p.count_type == PlyType::f32 || p.count_type == PlyType::f64) f.fail("list count type must be an integer type");
        p.is_list = true;
        p.name = std::string(fields[4]);
      } else {
        if (n != 3) f.fail("expected 'property <type> <name>'");
        if (!ply_type(fields[1], p.type)) f.fail("unknown PLY type '" + std::string(fields[1]) + "'");
        p.name = std::string(fields[2]);
      }
      elements.back().props.push_back(std::move(p));
    } else {
      f.fail("unknown header keyword " + quote(kw));
    }
  }
  if (!ended) f.fail("file ends inside the header; expected 'end_header'");
  if (!have_format) f.fail("no 'format' line in the header");

  std::size_t vi = elements.size();
  for (std::size_t i = 0; i < elements.size(); ++i)
    if (elements[i].name == "vertex") {
      vi = i;
      break;
    }
  if (vi == elements.size()) f.fail("no 'vertex' element in the header");
  for (std::size_t i = vi + 1; i < elements.size(); ++i)
    if (elements[i].name == "vertex") f.fail("two 'vertex' elements in the header; expected one");
  const PlyElement& ve = elements[vi];
  int ix = -1, iy = -1, iz = -1;
  for (std::size_t i = 0; i < ve.props.size(); ++i) {
    const auto& p = ve.props[i];
    if (p.is_list) continue;
    for (auto [name, index] : {std::pair{"x", &ix}, std::pair{"y", &iy}, std::pair{"z", &iz}}) {
      if (p.name != name) continue;
      if (*index >= 0) f.fail(std::string("the vertex element has two properties named '") + name + "'");
      *index = static_cast<int>(i);
    }
  }
  if (ix < 0 || iy < 0 || iz < 0) f.fail("the vertex element has no scalar x, y and z properties");

  std::vector<Point3> pts;
  pts.reserve(sane_reserve(ve.count));
  auto check = [&](const Point3& p, std::uint64_t k) {
    if (!detail::is_finite(p))
      f.fail("vertex " + std::to_string(k) + " has a NaN or infinite coordinate");
  };

  if (fmt == Fmt::ascii) {
    // One instance per line (what every PLY writer does). The other elements
    // (before the vertices, and the faces after them) are skipped line by
    // line, and then the file must end: a vertex count too low would leave
    // vertex lines there.
    std::vector<std::string_view> tok(64);
    for (std::size_t e = 0; e < elements.size(); ++e) {
      const PlyElement& el = elements[e];
      for (std::uint64_t k = 0; k < el.count; ++k) {
        std::size_t n = 0;
        do {
          if (!f.read_line(line))
            f.fail("file ends after " + std::to_string(k) + " of " + std::to_string(el.count) + " '" + el.name +
                   "' elements");
          n = split_fields(line, tok.data(), tok.size());
        } while (n == 0);
        if (e != vi) continue;
        if (n > tok.size()) {
          tok.resize(n);
          split_fields(line, tok.data(), tok.size());
        }
        // Walk the properties over the tokens (lists: count, then items).
        std::size_t t = 0;
        double c[3] = {0, 0, 0};
        for (std::size_t pi = 0; pi < el.props.size(); ++pi) {
          const auto& p = el.props[pi];
          if (t >= n) f.fail("vertex " + std::to_string(k) + " has too few values for its " + std::to_string(el.props.size()) + " properties");
          if (p.is_list) {
            const std::uint64_t cnt = parse_count(f, tok[t], "list length");
            if (cnt > n - t - 1)
              f.fail("vertex " + std::to_string(k) + ": its list '" + p.name + "' announces " + std::to_string(cnt) +
                     " values, and the line has " + std::to_string(n - t - 1) + " after it");
            t += 1 + cnt;
            continue;
          }
          const int which = static_cast<int>(pi) == ix ? 0 : static_cast<int>(pi) == iy ? 1 : static_cast<int>(pi) == iz ? 2 : -1;
          if (which >= 0) {
            NumStatus s = parse_double(tok[t], c[which]);
            if (s != NumStatus::ok)
              f.fail("vertex " + std::to_string(k) + " coordinate " + quote(tok[t]) + " " + describe(s));
            // An integer property holds integers of its type's range (a
            // binary file cannot hold any other; text must not either).
            double lo = 0, hi = 0;
            const char* type_name = "";
            if (ply_integer_range(p.type, lo, hi, type_name) &&
                (c[which] != std::floor(c[which]) || c[which] < lo || c[which] > hi))
              f.fail("vertex " + std::to_string(k) + " coordinate " + quote(tok[t]) + " is not a value of its type: '" +
                     p.name + "' is " + type_name + ", an integer from " + std::to_string(static_cast<long long>(lo)) +
                     " to " + std::to_string(static_cast<long long>(hi)) + " (declare it float or double)");
          }
          ++t;
        }
        if (t != n)
          f.fail("vertex " + std::to_string(k) + " has " + std::to_string(n) + " values; its properties take " +
                 std::to_string(t));
        Point3 p{c[0], c[1], c[2]};
        check(p, k);
        pts.push_back(p);
      }
    }
    std::size_t n_after = 0;
    if (next_content_line(f, tok.data(), 1, n_after))
      f.fail("a line after the elements the header announces (" + detail::counted(ve.count, "vertex", "vertices") +
             "); expected the file to end there: is a count in the header too low?");
    return pts;
  }

  const bool big = fmt == Fmt::be;
  auto where = [&](const std::string& el, std::uint64_t k) {
    return f.path() + ": '" + el + "' element " + std::to_string(k) + " (byte " + std::to_string(f.offset()) + ")";
  };
  std::vector<double> vals;
  std::vector<unsigned char> scratch;
  // Skips element e's instances: fixed-size ones at once (a count of empty
  // instances is no loop), the others one at a time.
  auto skip_element = [&](std::size_t e) {
    const PlyElement& el = elements[e];
    if (!el.has_list()) {
      const std::uint64_t stride = el.stride();
      const std::uint64_t start = f.offset();
      if (stride != 0 && (el.count > UINT64_MAX / stride || !skip_bytes(f, el.count * stride, scratch)))
        throw Error(ErrorCode::bad_format, where(el.name, (f.offset() - start) / stride) + ": file ends after " +
                                               std::to_string((f.offset() - start) / stride) + " of " +
                                               std::to_string(el.count) + " '" + el.name + "' elements");
      return;
    }
    for (std::uint64_t k = 0; k < el.count; ++k)
      if (!ply_binary_instance(f, el, big, vals, scratch))
        throw Error(ErrorCode::bad_format, where(el.name, k) + ": file ends inside the element data");
  };
  for (std::size_t e = 0; e < vi; ++e) skip_element(e);  // the elements before the vertices
  if (!ve.has_list()) {
    // Fixed-size records: read in blocks.
    const std::size_t stride = ve.stride();
    std::size_t off[3] = {0, 0, 0};
    PlyType type[3] = {};
    {
      std::size_t o = 0;
      for (std::size_t i = 0; i < ve.props.size(); ++i) {
        const int idx = static_cast<int>(i);
        int w = idx == ix ? 0 : idx == iy ? 1 : idx == iz ? 2 : -1;
        if (w >= 0) {
          off[w] = o;
          type[w] = ve.props[i].type;
        }
        o += ply_size(ve.props[i].type);
      }
    }
    // Blocks of up to 4096 records and 1 MiB: a header of many properties
    // must not allocate by its own say-so.
    const std::size_t block = std::clamp<std::size_t>((std::size_t{1} << 20) / std::max<std::size_t>(stride, 1), 1, 4096);
    scratch.resize(block * stride);
    for (std::uint64_t k = 0; k < ve.count;) {
      const std::size_t take = static_cast<std::size_t>(std::min<std::uint64_t>(block, ve.count - k));
      const std::size_t got = f.read_bytes(scratch.data(), take * stride);
      if (got != take * stride)
        throw Error(ErrorCode::bad_format, where("vertex", k + got / stride) + ": file ends after " +
                                               std::to_string(k + got / stride) + " of " +
                                               detail::counted(ve.count, "vertex", "vertices"));
      for (std::size_t j = 0; j < take; ++j, ++k) {
        const unsigned char* r = scratch.data() + j * stride;
        Point3 p{ply_value(type[0], r + off[0], big), ply_value(type[1], r + off[1], big),
                 ply_value(type[2], r + off[2], big)};
        if (!detail::is_finite(p))
          throw Error(ErrorCode::bad_format, where("vertex", k) + ": NaN or infinite coordinate");
        pts.push_back(p);
      }
    }
  } else {
    for (std::uint64_t k = 0; k < ve.count; ++k) {
      if (!ply_binary_instance(f, ve, big, vals, scratch))
        throw Error(ErrorCode::bad_format, where("vertex", k) + ": file ends inside the vertex data");
      Point3 p{vals[static_cast<std::size_t>(ix)], vals[static_cast<std::size_t>(iy)], vals[static_cast<std::size_t>(iz)]};
      if (!detail::is_finite(p))
        throw Error(ErrorCode::bad_format, where("vertex", k) + ": NaN or infinite coordinate");
      pts.push_back(p);
    }
  }
  for (std::size_t e = vi + 1; e < elements.size(); ++e) skip_element(e);  // faces
  if (const std::string_view rest = f.peek(1); !rest.empty())
    throw Error(ErrorCode::bad_format, f.path() + ": bytes after the elements the header announces (at byte " +
                                           std::to_string(f.offset()) + ", after " +
                                           detail::counted(ve.count, "vertex", "vertices") + "); expected the file to end there: is a count in the header too low?");
  return pts;
}

// ---- TetGen ------------------------------------------------------------------

std::string strip_ext(const std::string& path, const char* ext) {
  return ends_with_nocase(path, ext) ? path.substr(0, path.size() - std::strlen(ext)) : path;
}

std::vector<Point3> read_smesh(InputFile& f) {
  std::uint64_t first = 0;
  std::vector<Point3> pts = read_node_section(f, &first);
  if (!pts.empty()) return pts;
  // "0 3 0 0": TetGen's convention for "the nodes are in the .node file beside".
  const std::string node = strip_ext(f.path(), ".smesh") + ".node";
  InputFile nf(node);
  pts = read_node_section(nf, &first);
  require_end(nf, "the " + std::to_string(pts.size()) + " nodes its header announces");
  return pts;
}

}  // namespace

void require_end(InputFile& f, const std::string& what) {
  std::string_view fields[1];
  std::size_t n = 0;
  if (next_content_line(f, fields, 1, n)) f.fail("a line after " + what + "; expected the file to end there");
}

std::vector<Point3> read_node_section(InputFile& f, std::uint64_t* first_index) {
  std::string_view fields[8];
  std::size_t n = 0;
  if (!next_content_line(f, fields, 8, n)) f.fail("file ends before the node header; expected 'N 3 nattr nmarker'");
  const std::uint64_t count = parse_count(f, fields[0], "node count");
  // TetGen reads a header of the count alone as dimension 3 (the other fields default).
  const std::uint64_t dim = n < 2 ? 3 : parse_count(f, fields[1], "dimension");
  if (dim != 3) f.fail("dimension " + std::to_string(dim) + "; expected 3");
  std::vector<Point3> pts;
  pts.reserve(sane_reserve(count));
  std::uint64_t first = 0;
  for (std::uint64_t i = 0; i < count; ++i) {
    if (!next_content_line(f, fields, 4, n))
      f.fail("file ends after " + std::to_string(i) + " of " + std::to_string(count) + " nodes");
    if (n < 4) f.fail("node line has " + std::to_string(n) + " field(s); expected 'index x y z'");
    const std::uint64_t idx = parse_count(f, fields[0], "node index");
    if (i == 0) {
      if (idx > 1) f.fail("first node index is " + std::to_string(idx) + "; expected 0 or 1");
      first = idx;
    } else if (idx != first + i) {
      f.fail("node index " + std::to_string(idx) + "; expected " + std::to_string(first + i) + " (consecutive)");
    }
    pts.push_back(parse_point(f, fields + 1, "node"));
  }
  if (first_index) *first_index = first;
  return pts;
}

}  // namespace detail

std::vector<Point3> read_points(const std::string& path) {
  using detail::ends_with_nocase;
  enum class Kind { xyz, ply, off, node, smesh } kind;
  if (ends_with_nocase(path, ".xyz") || ends_with_nocase(path, ".xyz.gz")) kind = Kind::xyz;
  else if (ends_with_nocase(path, ".ply")) kind = Kind::ply;
  else if (ends_with_nocase(path, ".off")) kind = Kind::off;
  else if (ends_with_nocase(path, ".node")) kind = Kind::node;
  else if (ends_with_nocase(path, ".smesh")) kind = Kind::smesh;
  else
    throw Error(ErrorCode::bad_format,
                path + ": unknown point file type; expected .xyz, .xyz.gz, .ply, .off, .node or .smesh");
  detail::InputFile f(path);
  switch (kind) {
    case Kind::xyz: return detail::read_xyz(f);
    case Kind::ply: return detail::read_ply(f);
    case Kind::off: return detail::read_off(f);
    case Kind::node: {
      std::vector<Point3> pts = detail::read_node_section(f, nullptr);
      detail::require_end(f, "the " + std::to_string(pts.size()) + " nodes its header announces");
      return pts;
    }
    case Kind::smesh: return detail::read_smesh(f);
  }
  return {};
}

}  // namespace pdt
