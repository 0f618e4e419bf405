// SPDX-License-Identifier: MIT
// Point readers (every real data set, with the counts SOURCES.md gives, and
// small hand-made files for each format and error), TetGen/VTK writers and
// reader, and check_mesh accepting valid meshes and rejecting broken ones.
#include <algorithm>
#include <array>
#include <bit>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <map>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include <fcntl.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include "common/io_test_util.hpp"
#include "common/point_sets.hpp"
#include "pdt/generate.hpp"
#include "pdt/io.hpp"
#include "pdt/triangulation.hpp"

using pdt_test::catch_error;
using pdt_test::same_bits;
using pdt_test::TempDir;
using pdt_test::write_file;

namespace {

std::string data_dir() {
#ifdef PDT_SHARED_DATA
  return PDT_SHARED_DATA;
#else
  return "";
#endif
}

// The shared data file, or "" (with a warning) when the data is absent.
std::string data_file(const std::string& rel) {
  const std::string p = data_dir() + "/" + rel;
  if (data_dir().empty() || !std::filesystem::exists(p)) {
    WARN("test data " << p << " not found; skipping");
    return "";
  }
  return p;
}

std::size_t distinct(std::vector<pdt::Point3> p) {
  auto key = [](const pdt::Point3& a) { return std::tie(a.x, a.y, a.z); };
  std::sort(p.begin(), p.end(), [&](const auto& a, const auto& b) { return key(a) < key(b); });
  return static_cast<std::size_t>(std::unique(p.begin(), p.end()) - p.begin());
}

void expect_bad_points(const std::string& path, const std::string& where, const std::string& what) {
  auto e = catch_error([&] { pdt::read_points(path); });
  REQUIRE(e);
  INFO(e->what());
  CHECK(e->code() == pdt::ErrorCode::bad_format);
  CHECK(std::string(e->what()).find(where) != std::string::npos);
  CHECK(std::string(e->what()).find(what) != std::string::npos);
}

std::string le_bytes(const void* p, std::size_t n) { return std::string(static_cast<const char*>(p), n); }
template <class T>
std::string le(T v) {  // the host is little-endian (x86-64, aarch64)
  return le_bytes(&v, sizeof v);
}
template <class T>
std::string be(T v) {
  std::string s = le(v);
  std::reverse(s.begin(), s.end());
  return s;
}

// Two tets abcd and abce sharing the triangle abc, apexes at height +-h over
// its centroid, or the same bipyramid split into three tets around edge de.
pdt::Mesh bipyramid(double h, bool three) {
  pdt::Mesh m;
  m.points = {{0, 0, 0}, {4, 0, 0}, {0, 4, 0}, {4.0 / 3, 4.0 / 3, h}, {4.0 / 3, 4.0 / 3, -h}};
  if (!three) {
    m.tets = {{0, 1, 2, 3}, {0, 2, 1, 4}};
  } else {
    m.tets = {{0, 1, 4, 3}, {1, 2, 4, 3}, {2, 0, 4, 3}};
  }
  return m;
}

// Swaps two vertices of each negatively oriented tet (exact for the small
// integer coordinates it is used with).
void orient_positively(pdt::Mesh& m) {
  for (auto& t : m.tets) {
    const auto& a = m.points[t[0]];
    auto d = [&](int i) {
      const auto& p = m.points[t[static_cast<std::size_t>(i)]];
      return std::array<double, 3>{p.x - a.x, p.y - a.y, p.z - a.z};
    };
    const auto u = d(1), v = d(2), w = d(3);
    const double det = u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0]) +
                       u[2] * (v[0] * w[1] - v[1] * w[0]);
    if (det < 0) std::swap(t[0], t[1]);
  }
}

pdt::Mesh delaunay_of(const std::vector<pdt::Point3>& pts) {
  pdt::Triangulation t;
  for (const auto& p : pts) t.insert(p);
  return pdt::extract_mesh(t);
}

std::vector<pdt::Point3> uniform_points(std::uint64_t n, std::uint64_t seed) {
  pdt::GenerateOptions o;
  o.points = n;
  o.seed = seed;
  std::vector<pdt::Point3> p;
  for (const auto& op : pdt::generate(o).ops) p.push_back(op.point);
  return p;
}

}  // namespace

// ---- the real data sets ------------------------------------------------------

TEST_CASE("read_points reads every shared data set with the documented counts", "[io][data]") {
  struct Case {
    const char* file;
    std::size_t points;
    std::size_t distinct;
  };
  const Case cases[] = {
      {"scans/stanford_bunny_bun000.ply", 40256, 40256},
      {"scans/stanford_bunny_bun_zipper.ply", 35947, 35947},
      {"scans/cgal_b9.ply", 22300, 22300},
      {"scans/pdal_autzen_trim.xyz.gz", 110000, 110000},
      {"scans/pcl_table_scene_mug_stereo_textured.xyz.gz", 209280, 209280},
      {"scans/pcl_isprs_CSite4_orig-utm.ply", 518056, 487208},
      {"medical/cgal_femur.off", 3897, 3897},
      {"degenerate/cgal_radar.xyz", 20950, 20950},
      {"degenerate/cgal_error_mesh-p_not_equal_0-min2.off", 19, 17},
  };
  for (const auto& c : cases) {
    const std::string p = data_file(c.file);
    if (p.empty()) continue;
    INFO(c.file);
    const auto pts = pdt::read_points(p);
    CHECK(pts.size() == c.points);
    CHECK(distinct(pts) == c.distinct);
  }
}

TEST_CASE("read_points gets the data sets' coordinates right", "[io][data]") {
  if (auto p = data_file("scans/pdal_autzen_trim.xyz.gz"); !p.empty()) {
    const auto pts = pdt::read_points(p);
    REQUIRE(!pts.empty());
    CHECK(same_bits(pts[0], pdt::Point3{637177.98, 849393.95, 411.19}));
    double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
    for (const auto& q : pts) {
      const double c[3] = {q.x, q.y, q.z};
      for (int i = 0; i < 3; ++i) lo[i] = std::min(lo[i], c[i]), hi[i] = std::max(hi[i], c[i]);
    }
    // Bounding box from SOURCES.md.
    CHECK(lo[0] == 636001.76);
    CHECK(hi[0] == 637179.22);
    CHECK(lo[1] == 848935.20);
    CHECK(hi[1] == 849497.90);
    CHECK(lo[2] == 406.26);
    CHECK(hi[2] == 520.51);
  }
  if (auto p = data_file("scans/pcl_isprs_CSite4_orig-utm.ply"); !p.empty()) {
    const auto pts = pdt::read_points(p);
    REQUIRE(pts.size() == 518056);
    // float32 values widened exactly.
    CHECK(pts.front() == pdt::Point3{513628.8125, 5403190.0, double(291.4f)});
    CHECK(pts.back() == pdt::Point3{513265.375, 5403759.5, double(304.47f)});
  }
  if (auto p = data_file("scans/stanford_bunny_bun000.ply"); !p.empty()) {
    const auto pts = pdt::read_points(p);
    REQUIRE(!pts.empty());
    CHECK(pts.front() == pdt::Point3{-0.06325, 0.0359793, 0.0420873});
  }
  if (auto p = data_file("scans/cgal_b9.ply"); !p.empty())
    CHECK(pdt::read_points(p).front() == pdt::Point3{45.375, 52.1094, -10.6268});
  if (auto p = data_file("degenerate/cgal_radar.xyz"); !p.empty()) {
    const auto pts = pdt::read_points(p);
    CHECK(pts.front() == pdt::Point3{-99.7385919424, 5.52386828797, -4.65834267608});
    for (const auto& q : pts) REQUIRE(std::sqrt(q.x * q.x + q.y * q.y + q.z * q.z) == Approx(100).epsilon(1e-12));
  }
  if (auto p = data_file("medical/cgal_femur.off"); !p.empty())
    CHECK(pdt::read_points(p).front() == pdt::Point3{0.0119284, -0.0448027, -0.465684});
}

TEST_CASE("read_points reads the TetGen .smesh test drafts", "[io][data]") {
  const std::string dir = data_dir() + "/degenerate/tetgen_testingdrafts";
  if (data_dir().empty() || !std::filesystem::exists(dir)) {
    WARN("test data " << dir << " not found; skipping");
    return;
  }
  std::size_t files = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    if (e.path().extension() != ".smesh") continue;
    const std::string name = e.path().filename().string();
    INFO(name);
    const auto pts = pdt::read_points(e.path().string());
    // wedge-*: 6 nodes; slit-*: 14; spike-a-b: b + 1.
    std::size_t expect = 0;
    if (name.rfind("wedge-", 0) == 0) expect = 6;
    else if (name.rfind("slit-", 0) == 0) expect = 14;
    else expect = std::stoul(name.substr(name.rfind('-') + 1)) + 1;
    CHECK(pts.size() == expect);
    if (name.rfind("spike-", 0) == 0) CHECK(pts.back() == pdt::Point3{0, 0, 1});  // the apex
    ++files;
  }
  CHECK(files == 19);
}

// ---- small files per format -----------------------------------------------------

TEST_CASE("xyz: extra columns, comments, blank lines; errors name the line", "[io]") {
  TempDir d;
  const std::string p = d.file("a.xyz");
  write_file(p, "# comment\n1 2 3\n\n  4.5\t5.5 6.5  255 0 0\r\n-1e-3 +2 3e2\n");
  const auto pts = pdt::read_points(p);
  REQUIRE(pts.size() == 3);
  CHECK(pts[1] == pdt::Point3{4.5, 5.5, 6.5});
  CHECK(pts[2] == pdt::Point3{-1e-3, 2, 300});
  write_file(p, "1 2 3\n4 5\n");
  expect_bad_points(p, p + ":2:", "expected 'x y z'");
  write_file(p, "1 2 3\n4 5 nan\n");
  expect_bad_points(p, p + ":2:", "not finite");
  write_file(p, "1 2 3\n\n4 5 1e400\n");
  expect_bad_points(p, p + ":3:", "out of the range");
  write_file(p, "1 2 3\n4 x 6\n");
  expect_bad_points(p, p + ":2:", "not a number");
}

TEST_CASE("ply ascii: vertex element after others, list properties skipped", "[io]") {
  TempDir d;
  const std::string p = d.file("a.ply");
  write_file(p,
             "ply\nformat ascii 1.0\ncomment made by hand\n"
             "element material 2\nproperty uchar r\nproperty list uchar int idx\n"
             "element vertex 3\nproperty float confidence\nproperty double x\nproperty double y\n"
             "property list uchar int extra\nproperty double z\n"
             "element face 1\nproperty list uchar int vertex_indices\n"
             "end_header\n"
             "1 3 7 8 9\n2 0\n"
             "0.5 1 2 2 10 11 3\n0.5 4 5 0 6\n0.5 7 8 1 99 9\n"
             "3 0 1 2\n");
  const auto pts = pdt::read_points(p);
  REQUIRE(pts.size() == 3);
  CHECK(pts[0] == pdt::Point3{1, 2, 3});
  CHECK(pts[1] == pdt::Point3{4, 5, 6});
  CHECK(pts[2] == pdt::Point3{7, 8, 9});
  write_file(p, "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n");
  expect_bad_points(p, p + ":", "file ends after 1 of 2 'vertex' elements");
  write_file(p, "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3 4\n");
  expect_bad_points(p, p + ":8:", "has 4 values");
  write_file(p, "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n");
  expect_bad_points(p, p + ":", "no scalar x, y and z");
  write_file(p, "PLY\n");
  expect_bad_points(p, p + ":1:", "not 'ply'");
  // A list announcing more values than its line holds (2^64 - 1 of them
  // wrapped the count round to the next token, read as x).
  for (const char* count : {"18446744073709551615", "3"}) {
    INFO(count);
    write_file(p, std::string("ply\nformat ascii 1.0\nelement vertex 1\nproperty list uchar int tag\n"
                              "property float x\nproperty float y\nproperty float z\nend_header\n") +
                      count + " 1 2\n");
    expect_bad_points(p, p + ":9:", "its list 'tag' announces");
  }
  // An integer property holds integers of its type's range, as a binary
  // file would: 0.25 for an int, -1 or 300 for a uchar are refused.
  for (const auto& [type, value, what] :
       {std::tuple{"int", "0.25", "'x' is an int (int32), an integer from -2147483648 to 2147483647"},
        std::tuple{"uchar", "-1", "'x' is a uchar (uint8), an integer from 0 to 255"},
        std::tuple{"uchar", "300", "'x' is a uchar (uint8)"}, std::tuple{"short", "1e9", "'x' is a short (int16)"}}) {
    INFO(type << " " << value);
    write_file(p, std::string("ply\nformat ascii 1.0\nelement vertex 1\nproperty ") + type +
                      " x\nproperty float y\nproperty float z\nend_header\n" + value + " 2 3\n");
    expect_bad_points(p, p + ":", what);
  }
  write_file(p, "ply\nformat ascii 1.0\nelement vertex 2\nproperty uchar x\nproperty int y\nproperty uint z\n"
                "end_header\n255 -2147483648 4294967295\n0 7.0 1e3\n");
  const auto ints = pdt::read_points(p);
  REQUIRE(ints.size() == 2);
  CHECK(ints[0] == pdt::Point3{255, -2147483648.0, 4294967295.0});
  CHECK(ints[1] == pdt::Point3{0, 7, 1000});
  // Two properties of one name: which one is x?
  write_file(p, "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float x\nproperty float y\n"
                "property float z\nend_header\n1 2 3 4\n");
  expect_bad_points(p, p + ":", "two properties named 'x'");
}

TEST_CASE("ply binary little and big endian, mixed types, lists in other elements", "[io]") {
  TempDir d;
  auto header = [](const char* fmt) {
    return std::string("ply\nformat ") + fmt +
           " 1.0\n"
           "element face 2\nproperty list uchar int vertex_indices\nproperty ushort flags\n"
           "element vertex 2\nproperty double x\nproperty uchar red\nproperty float y\nproperty int z\n"
           "element edge 1\nproperty int a\nproperty int b\n"
           "end_header\n";
  };
  const double x0 = 0.1, x1 = -1e300;
  const float y0 = 2.5f, y1 = 1.1f;
  for (bool big : {false, true}) {
    INFO((big ? "big" : "little") << " endian");
    auto enc = [&](auto v) { return big ? be(v) : le(v); };
    std::string body;
    body += enc(std::uint8_t{3}) + enc(std::int32_t{0}) + enc(std::int32_t{1}) + enc(std::int32_t{2}) + enc(std::uint16_t{7});
    body += enc(std::uint8_t{0}) + enc(std::uint16_t{9});  // an empty list
    body += enc(x0) + enc(std::uint8_t{255}) + enc(y0) + enc(std::int32_t{-7});
    body += enc(x1) + enc(std::uint8_t{0}) + enc(y1) + enc(std::int32_t{2000000000});
    body += enc(std::int32_t{0}) + enc(std::int32_t{1});
    const std::string p = d.file(big ? "b.ply" : "l.ply");
    write_file(p, header(big ? "binary_big_endian" : "binary_little_endian") + body);
    const auto pts = pdt::read_points(p);
    REQUIRE(pts.size() == 2);
    CHECK(same_bits(pts[0], pdt::Point3{x0, double(y0), -7}));
    CHECK(same_bits(pts[1], pdt::Point3{x1, double(y1), 2000000000}));
    // Truncated in the vertex data.
    write_file(p, header(big ? "binary_big_endian" : "binary_little_endian") + body.substr(0, body.size() - 20));
    expect_bad_points(p, p + ": 'vertex' element 1", "file ends");
  }
  // A list whose length the file does not hold: refused at the end of the
  // file, without first reserving what the length announces (2^32 - 1
  // doubles: 34 GB).
  {
    const std::string p = d.file("huge_list.ply");
    write_file(p, "ply\nformat binary_little_endian 1.0\nelement face 1\nproperty list uint double v\n"
                  "element vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n" +
                      le(std::uint32_t{0xFFFFFFFFu}) + le(1.0));
    expect_bad_points(p, p + ":", "file ends");
  }
  // A NaN coordinate in binary data.
  const std::string p = d.file("nan.ply");
  write_file(p, "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n" +
                    le(1.0f) + le(std::nanf("")) + le(1.0f));
  expect_bad_points(p, p + ": 'vertex' element 0", "NaN");
}

TEST_CASE("ply: counts that disagree with the data, empty elements, many properties", "[io]") {
  TempDir d;
  const std::string vertex3 = "element vertex 1\nproperty float x\nproperty float y\nproperty float z\n";
  const std::string one = le(1.0f) + le(2.0f) + le(3.0f);
  const std::string p = d.file("c.ply");
  // An element of no properties takes no bytes, whatever its count: skipped at
  // once (it was a loop of 10^18 empty reads).
  write_file(p, "ply\nformat binary_little_endian 1.0\nelement junk 1000000000000000000\n" + vertex3 +
                    "end_header\n" + one);
  CHECK(pdt::read_points(p) == std::vector<pdt::Point3>{{1, 2, 3}});
  // Fixed-size elements before the vertices are skipped whole; one the file
  // does not hold is refused.
  write_file(p, "ply\nformat binary_little_endian 1.0\nelement pad 3\nproperty short s\n" + vertex3 +
                    "end_header\n" + std::string(6, '\0') + one);
  CHECK(pdt::read_points(p) == std::vector<pdt::Point3>{{1, 2, 3}});
  write_file(p, "ply\nformat binary_little_endian 1.0\nelement pad 4000000000000000000\nproperty double s\n" +
                    vertex3 + "end_header\n" + one);
  expect_bad_points(p, p + ": 'pad' element 0", "file ends after 0 of 4000000000000000000 'pad' elements");
  // Data after the last element: a vertex count too low (binary and ascii),
  // here with a face element after the vertices.
  const std::string faces = "element face 1\nproperty list uchar int v\n";
  write_file(p, "ply\nformat binary_little_endian 1.0\n" + vertex3 + faces + "end_header\n" + one +
                    le(std::uint8_t{1}) + le(std::int32_t{0}) + one);
  expect_bad_points(p, p + ": bytes after the elements", "is a count in the header too low?");
  write_file(p, "ply\nformat binary_little_endian 1.0\n" + vertex3 + faces + "end_header\n" + one +
                    le(std::uint8_t{1}) + le(std::int32_t{0}));
  CHECK(pdt::read_points(p).size() == 1);
  write_file(p, "ply\nformat ascii 1.0\n" + vertex3 + faces + "end_header\n1 2 3\n1 0\n4 5 6\n");
  expect_bad_points(p, p + ":12:", "a line after the elements the header announces");
  write_file(p, "ply\nformat ascii 1.0\n" + vertex3 + faces + "end_header\n1 2 3\n1 0\n\n");
  CHECK(pdt::read_points(p).size() == 1);
  write_file(p, "ply\nformat ascii 1.0\n" + vertex3 + vertex3 + "end_header\n1 2 3\n4 5 6\n");
  expect_bad_points(p, p + ":", "two 'vertex' elements");
  // 60,000 properties (a 1 MB header, 480 kB a record): read in blocks of
  // about 1 MiB, not 4096 records (1.9 GB).
  {
    std::string head = "ply\nformat binary_little_endian 1.0\nelement vertex 2\n";
    for (int i = 0; i < 60000; ++i) head += "property double e" + std::to_string(i) + "\n";
    head += "property double x\nproperty double y\nproperty double z\nend_header\n";
    std::string body;
    for (double v : {1.0, 2.0}) body += std::string(60000 * 8, '\0') + le(v) + le(v) + le(v);
    write_file(p, head + body);
    auto peak_kib = [] {
      rusage u{};
      getrusage(RUSAGE_SELF, &u);
      return u.ru_maxrss;
    };
    const long before = peak_kib();
    CHECK(pdt::read_points(p) == std::vector<pdt::Point3>{{1, 1, 1}, {2, 2, 2}});
    INFO("peak before " << before << " KiB, after " << peak_kib() << " KiB");
    CHECK(peak_kib() - before < 256 * 1024);  // the header's names and a block: a few MiB
  }
  // A negative list length names the element and the byte.
  write_file(p, "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty list char int l\n"
                "property float x\nproperty float y\nproperty float z\nend_header\n" + le(std::int8_t{-5}) + one);
  expect_bad_points(p, p + ": 'vertex' element (byte ", "negative list length -5");
}

TEST_CASE("text readers: a carriage return inside a line (CR-only line ends) is refused", "[io]") {
  TempDir d;
  const std::string xyz = d.file("mac.xyz"), off = d.file("mac.off");
  write_file(xyz, "0 0 0\r1 0 0\r0 1 0\r0 0 1\r");
  expect_bad_points(xyz, xyz + ":1:", "a carriage return (\\r) inside the line");
  write_file(xyz, "0 0 0\r\n1 0 0\r\n");  // CR LF is fine
  CHECK(pdt::read_points(xyz).size() == 2);
  write_file(off, "OFF\r3 0 0\r");
  expect_bad_points(off, off + ":1:", "CR alone");
  // An empty file's error names the file without a line 0.
  write_file(off, "");
  expect_bad_points(off, off + ": empty file", "expected an 'OFF' header");
}

TEST_CASE("off, node and smesh", "[io]") {
  TempDir d;
  const std::string off = d.file("a.off");
  write_file(off, "OFF\n# comment\n3 1 0\n\n0 0 0\n1 0 0 \n0 1 0\n3 0 1 2\n");
  CHECK(pdt::read_points(off) == std::vector<pdt::Point3>{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
  write_file(off, "OFF 2 0 0\n1 2 3\n4 5 6\n");  // counts on the header line
  CHECK(pdt::read_points(off).size() == 2);
  write_file(off, "COFF\n2 0 0\n1 2 3 255 0 0 255\n4 5 6 0 0 0 255\n");  // colours
  CHECK(pdt::read_points(off)[1] == pdt::Point3{4, 5, 6});
  write_file(off, "OFF\n3 1 0\n0 0 0\n1 0 0\n");
  expect_bad_points(off, off + ":4:", "file ends after 2 of 3 vertices");
  write_file(off, "OFX\n");
  expect_bad_points(off, off + ":1:", "expected 'OFF'");
  // Lines after the faces the header counts: a vertex count too low.
  write_file(off, "OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n");
  expect_bad_points(off, off + ":6:", "a line after the 3 vertices and 0 faces its header announces");
  write_file(off, "OFF 0 0 0\n1 2 3\n");
  expect_bad_points(off, off + ":2:", "a line after the 0 vertices");
  write_file(off, "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n");
  expect_bad_points(off, off + ":5:", "file ends after 0 of 1 face");
  {
    auto e = catch_error([&] { pdt::read_points(off); });  // "1 face", not "1 faces"
    REQUIRE(e);
    CHECK(std::string(e->what()).find("faces") == std::string::npos);
  }
  write_file(off, "OFF\n1 0 0\n");
  expect_bad_points(off, off + ":2:", "file ends after 0 of 1 vertex");
  write_file(off, "OFF\n3\n0 0 0\n1 0 0\n0 1 0\nanything\n");  // no face count: the rest is not read
  CHECK(pdt::read_points(off).size() == 3);

  const std::string node = d.file("m.node");
  write_file(node, "# TetGen\n3 3 1 1\n1 0 0 0 7.5 1\n2 1 0 0 7.5 0\n3 0 1 0 7.5 1\n");  // 1-based, attribute, marker
  CHECK(pdt::read_points(node) == std::vector<pdt::Point3>{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
  write_file(node, "2 3 0 0\n0 0 0 0\n2 1 1 1\n");
  expect_bad_points(node, node + ":3:", "expected 1 (consecutive)");
  write_file(node, "2\n0 0 0 0\n1 1 1 1\n");  // the count alone: TetGen's defaults (3 dimensions)
  CHECK(pdt::read_points(node) == std::vector<pdt::Point3>{{0, 0, 0}, {1, 1, 1}});
  write_file(node, "2 2 0 0\n0 0 0\n1 1 1\n");
  expect_bad_points(node, node + ":1:", "dimension 2; expected 3");

  const std::string smesh = d.file("s.smesh");
  write_file(smesh, "# part 1\n2 3 0 0\n0 1 2 3\n1 4 5 6\n# part 2\n1 0\n3 0 1 0\n0\n0\n");
  CHECK(pdt::read_points(smesh) == std::vector<pdt::Point3>{{1, 2, 3}, {4, 5, 6}});
  // "0 3 0 0": the nodes are in the .node file beside it.
  write_file(smesh, "0 3 0 0\n1 0\n3 0 1 2\n");
  write_file(d.file("s.node"), "1 3 0 0\n0 9 8 7\n");
  CHECK(pdt::read_points(smesh) == std::vector<pdt::Point3>{{9, 8, 7}});

  expect_bad_points(d.file("x.txt"), "x.txt", "unknown point file type");
  auto e = catch_error([&] { pdt::read_points(d.file("missing.xyz")); });
  REQUIRE(e);
  CHECK(e->code() == pdt::ErrorCode::io_failure);
  CHECK(std::string(e->what()).find("missing.xyz") != std::string::npos);
}

// ---- writers and reader ------------------------------------------------------------

TEST_CASE("read_tetgen keeps a quadratic mesh's corners, and check_mesh checks them", "[io]") {
  // TetGen's -o2: 10 nodes a tetrahedron, the corners then the 6 edge nodes
  // (appended after the corners in the .node file, here some before them).
  TempDir d;
  const std::vector<pdt::Point3> corners = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {1, 1, 1}};
  std::vector<pdt::Point3> nodes;
  std::vector<int> corner_node(corners.size());
  auto mid = [&](int a, int b) {
    return pdt::Point3{(corners[a].x + corners[b].x) / 2, (corners[a].y + corners[b].y) / 2,
                       (corners[a].z + corners[b].z) / 2};
  };
  nodes.push_back(mid(0, 1));  // an edge node first
  for (std::size_t i = 0; i < corners.size(); ++i) {
    corner_node[i] = static_cast<int>(nodes.size());
    nodes.push_back(corners[i]);
  }
  // Two tets sharing the facet 1 2 3 (the hull of the 5 corners, Delaunay).
  const int tets[2][4] = {{0, 1, 2, 3}, {4, 2, 1, 3}};
  std::string ele = "2 10 0\n";
  std::map<std::pair<int, int>, int> edge_node{{{0, 1}, 0}};
  for (int t = 0; t < 2; ++t) {
    ele += std::to_string(t);
    for (int k = 0; k < 4; ++k) (ele += ' ') += std::to_string(corner_node[tets[t][k]]);
    const int e[6][2] = {{0, 1}, {1, 2}, {2, 0}, {0, 3}, {1, 3}, {2, 3}};
    for (const auto& ab : e) {
      const std::pair<int, int> key = std::minmax(tets[t][ab[0]], tets[t][ab[1]]);
      auto [it, added] = edge_node.emplace(key, static_cast<int>(nodes.size()));
      if (added) nodes.push_back(mid(key.first, key.second));
      (ele += ' ') += std::to_string(it->second);
    }
    ele += "\n";
  }
  std::string node = std::to_string(nodes.size()) + " 3 0 0\n";
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    std::ostringstream line;
    line.precision(17);
    line << i << " " << nodes[i].x << " " << nodes[i].y << " " << nodes[i].z << "\n";
    node += line.str();
  }
  write_file(d.file("q.node"), node);
  write_file(d.file("q.ele"), ele);
  const pdt::Mesh m = pdt::read_tetgen(d.file("q.node"));
  REQUIRE(m.points.size() == corners.size());
  for (std::size_t i = 0; i < corners.size(); ++i) CHECK(m.points[i] == corners[i]);
  REQUIRE(m.tets.size() == 2);
  CHECK(m.tets[0] == std::array<std::uint32_t, 4>{0, 1, 2, 3});
  CHECK(m.tets[1] == std::array<std::uint32_t, 4>{4, 2, 1, 3});
  const pdt::MeshCheck c = pdt::check_mesh(m);
  INFO(c.message);
  CHECK(c.valid);
  // A node no tetrahedron uses stays, and check_mesh says so.
  const std::string more_nodes =
      std::to_string(nodes.size() + 1) + node.substr(node.find(' ')) + std::to_string(nodes.size()) + " 5 5 5\n";
  write_file(d.file("q.node"), more_nodes);
  const pdt::Mesh stray = pdt::read_tetgen(d.file("q.node"));
  CHECK(stray.points.size() == corners.size() + 1);
  CHECK_FALSE(pdt::check_mesh(stray).valid);
  // An edge node past the nodes is refused, naming it.
  write_file(d.file("q.ele"), "1 10 0\n0 1 2 3 4 5 6 7 8 9 99\n");
  const auto e = catch_error([&] { pdt::read_tetgen(d.file("q.node")); });
  REQUIRE(e.has_value());
  CHECK(std::string(e->what()).find("node index 99 is not one of") != std::string::npos);
}

TEST_CASE("write_tetgen / read_tetgen round trip, with TetGen's headers", "[io]") {
  TempDir d;
  pdt::Mesh m;
  m.points = {{0.1, 0.2, 0.3}, {1e-310, 1, 0}, {0, 1.0 / 3, 1}, {1, 1, 1}, {-2, 3e300, 7}};
  m.tets = {{0, 1, 2, 3}, {1, 2, 3, 4}};
  for (const std::string name : {"mesh", "mesh.node", "mesh.ele"}) {
    const pdt::TetgenFiles files = pdt::tetgen_files(d.file(name));
    CHECK(files.node == d.file("mesh.node"));
    CHECK(files.ele == d.file("mesh.ele"));
    pdt::write_tetgen(d.file(name), m);
    const std::string node = pdt_test::read_file(d.file("mesh.node"));
    const std::string ele = pdt_test::read_file(d.file("mesh.ele"));
    CHECK(node.rfind("5 3 0 0\n0 0.10000000000000001 0.20000000000000001 0.29999999999999999\n", 0) == 0);
    CHECK(ele == "2 4 0\n0 0 1 2 3\n1 1 2 3 4\n");
    const pdt::Mesh r = pdt::read_tetgen(d.file(name));
    REQUIRE(r.points.size() == m.points.size());
    for (std::size_t i = 0; i < m.points.size(); ++i) CHECK(same_bits(r.points[i], m.points[i]));
    CHECK(r.tets == m.tets);
    CHECK(d.entries() == 2);
  }
  // The named file as named (any case), its partner in upper case if it is;
  // any other name gets both appended.
  CHECK(pdt::tetgen_files("a/B.NODE").node == "a/B.NODE");
  CHECK(pdt::tetgen_files("a/B.NODE").ele == "a/B.ELE");
  CHECK(pdt::tetgen_files("a/B.Ele").ele == "a/B.Ele");
  CHECK(pdt::tetgen_files("a/B.Ele").node == "a/B.node");
  CHECK(pdt::tetgen_files("m.vtu").node == "m.vtu.node");
  {
    pdt::write_tetgen(d.file("UP.NODE"), m);  // read back by the name it was written under
    CHECK(pdt::read_tetgen(d.file("UP.NODE")).tets == m.tets);
    CHECK(pdt_test::read_file(d.file("UP.ELE")) == "2 4 0\n0 0 1 2 3\n1 1 2 3 4\n");
    auto refused = catch_error([&] { pdt::write_tetgen(d.file(".NODE"), m); });
    REQUIRE(refused);
    CHECK(refused->code() == pdt::ErrorCode::invalid_argument);
  }
  // 1-based TetGen files (TetGen's default numbering) read back 0-based.
  write_file(d.file("one.node"), "4 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n");
  write_file(d.file("one.ele"), "# comment\n1 4 1\n1 1 2 3 4 5.0\n");
  const pdt::Mesh one = pdt::read_tetgen(d.file("one"));
  REQUIRE(one.tets.size() == 1);
  CHECK(one.tets[0] == std::array<std::uint32_t, 4>{0, 1, 2, 3});
  write_file(d.file("one.ele"), "1 4 0\n1 1 2 3 5\n");
  auto e = catch_error([&] { pdt::read_tetgen(d.file("one.node")); });
  REQUIRE(e);
  CHECK(e->code() == pdt::ErrorCode::bad_format);
  CHECK(std::string(e->what()).find("one.ele:2:") != std::string::npos);
  // A line that is not what the header says: a field more than its nodes and
  // attributes, an attribute count that is no number, an index out of turn.
  for (const auto& [ele, what] : {std::pair{"1 4 0\n1 1 2 3 4 9\n", "the header asks for 5"},
                                  std::pair{"1 4 xyz\n1 1 2 3 4\n", "attribute count 'xyz'"},
                                  std::pair{"2 4 0\n1 1 2 3 4\n1 1 2 4 3\n", "tetrahedron index 1; expected 2"},
                                  std::pair{"1 4 0 0\n1 1 2 3 4\n", "header has 4 fields"}}) {
    INFO(ele);
    write_file(d.file("one.ele"), ele);
    e = catch_error([&] { pdt::read_tetgen(d.file("one.node")); });
    REQUIRE(e);
    CHECK(e->code() == pdt::ErrorCode::bad_format);
    CHECK(std::string(e->what()).find(what) != std::string::npos);
  }
  // More rows than the header announces: a format error at the first extra
  // one (in either file); a trailing comment is fine.
  write_file(d.file("one.ele"), "1 4 0\n1 1 2 3 4\n# by TetGen\n2 1 2 3 4\n");
  e = catch_error([&] { pdt::read_tetgen(d.file("one.node")); });
  REQUIRE(e);
  CHECK(e->code() == pdt::ErrorCode::bad_format);
  CHECK(std::string(e->what()).find("one.ele:4: a line after the 1 tetrahedra its header announces") !=
        std::string::npos);
  write_file(d.file("one.ele"), "1 4 0\n1 1 2 3 4\n# by TetGen\n");
  write_file(d.file("one.node"), "4 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n5 1 1 1\n");
  e = catch_error([&] { pdt::read_tetgen(d.file("one.node")); });
  REQUIRE(e);
  CHECK(std::string(e->what()).find("one.node:6: a line after the 4 nodes") != std::string::npos);
  e = catch_error([&] { pdt::read_points(d.file("one.node")); });
  REQUIRE(e);
  CHECK(e->code() == pdt::ErrorCode::bad_format);
  // A directory where one of the two files goes: refused before either is
  // written, so an older pair stays a pair.
  pdt::write_tetgen(d.file("pair"), m);
  const std::string old_node = pdt_test::read_file(d.file("pair.node"));
  std::filesystem::remove(d.file("pair.ele"));
  std::filesystem::create_directory(d.file("pair.ele"));
  pdt::Mesh other = m;
  other.points[0].x = 0.5;
  e = catch_error([&] { pdt::write_tetgen(d.file("pair"), other); });
  REQUIRE(e);
  CHECK(e->code() == pdt::ErrorCode::io_failure);
  CHECK(std::string(e->what()).find("Is a directory") != std::string::npos);
  CHECK(pdt_test::read_file(d.file("pair.node")) == old_node);
  // Bad index in the writer's input.
  m.tets.push_back({0, 1, 2, 9});
  auto e2 = catch_error([&] { pdt::write_tetgen(d.file("bad"), m); });
  REQUIRE(e2);
  CHECK(e2->code() == pdt::ErrorCode::invalid_argument);
  CHECK(!std::filesystem::exists(d.file("bad.node")));
}

TEST_CASE("the mesh writers refuse points that are not finite and write nothing", "[io]") {
  TempDir d;
  pdt::Mesh m;
  m.points = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  m.tets = {{0, 1, 2, 3}};
  for (double bad : {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity(),
                     -std::numeric_limits<double>::infinity()}) {
    pdt::Mesh b = m;
    b.points[2].z = bad;
    auto e = catch_error([&] { pdt::write_tetgen(d.file("nan"), b); });
    REQUIRE(e);
    CHECK(e->code() == pdt::ErrorCode::invalid_argument);
    CHECK(std::string(e->what()).find("write_tetgen: point 2") != std::string::npos);
    CHECK(std::string(e->what()).find("not finite") != std::string::npos);
    e = catch_error([&] { pdt::write_vtu(d.file("nan.vtu"), b); });
    REQUIRE(e);
    CHECK(e->code() == pdt::ErrorCode::invalid_argument);
    CHECK(std::string(e->what()).find("write_vtu: point 2") != std::string::npos);
    CHECK(d.entries() == 0);
  }
  // A path that names no file ("", a folder, or TetGen's pair hidden as
  // ".node" / ".ele"): refused, nothing written.
  for (const std::string& nameless : {std::string(), d.path().string() + "/", d.file(".node"), d.file(".ELE")}) {
    INFO("'" << nameless << "'");
    auto e = catch_error([&] { pdt::write_tetgen(nameless, m); });
    REQUIRE(e);
    CHECK(e->code() == pdt::ErrorCode::invalid_argument);
    CHECK(std::string(e->what()).find("names no file") != std::string::npos);
  }
  for (const std::string& nameless : {std::string(), d.path().string() + "/"}) {
    auto e = catch_error([&] { pdt::write_vtu(nameless, m); });
    REQUIRE(e);
    CHECK(e->code() == pdt::ErrorCode::invalid_argument);
  }
  CHECK(d.entries() == 0);
  // The same mesh with finite points is written and reads back.
  pdt::write_tetgen(d.file("ok"), m);
  CHECK(pdt::read_tetgen(d.file("ok")).points.size() == 4);
}

TEST_CASE("write_vtu writes a VTK UnstructuredGrid of tetrahedra", "[io]") {
  TempDir d;
  pdt::Mesh m;
  m.points = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {1, 1, 1}};
  m.tets = {{0, 1, 2, 3}, {1, 2, 3, 4}};
  const std::string p = d.file("m.vtu");
  pdt::write_vtu(p, m, pdt::VtuEncoding::ascii);
  const std::string x = pdt_test::read_file(p);
  CHECK(x.rfind("<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\"", 0) == 0);
  CHECK(x.find("<Piece NumberOfPoints=\"5\" NumberOfCells=\"2\">") != std::string::npos);
  CHECK(x.find("Name=\"connectivity\" format=\"ascii\">\n          0 1 2 3\n          1 2 3 4\n") != std::string::npos);
  CHECK(x.find("Name=\"offsets\" format=\"ascii\">\n          4 8\n") != std::string::npos);
  CHECK(x.find("Name=\"types\" format=\"ascii\">\n          10 10\n") != std::string::npos);
  CHECK(x.size() > 5 * 3);
  CHECK(x.substr(x.size() - 11) == "</VTKFile>\n");
  CHECK(d.entries() == 1);

  // A field's name is an XML attribute: any characters, escaped.
  const std::vector<pdt::CellField> fields{{"quality \"<a&b>\" 'q'", {0.5, 0.25}}};
  pdt::write_vtu(p, m, pdt::VtuEncoding::ascii, fields);
  const std::string y = pdt_test::read_file(p);
  CHECK(y.find("Name=\"quality &quot;&lt;a&amp;b&gt;&quot; &apos;q&apos;\" format=\"ascii\">") != std::string::npos);
  CHECK(y.find("<a&b>") == std::string::npos);

  // Tab, newline and carriage return as character references (a parser
  // reads them as spaces otherwise); UTF-8 as it is.
  const std::vector<pdt::CellField> spaced{{"a\tb\nc\rd \xC3\xA9\xE2\x82\xAC\xF0\x9F\x98\x80", {0.5, 0.25}}};
  pdt::write_vtu(p, m, pdt::VtuEncoding::ascii, spaced);
  CHECK(pdt_test::read_file(p).find("Name=\"a&#9;b&#10;c&#13;d \xC3\xA9\xE2\x82\xAC\xF0\x9F\x98\x80\" format=\"ascii\">") !=
        std::string::npos);
}

TEST_CASE("write_vtu refuses cell fields VTK cannot read by name, and writes nothing", "[io]") {
  TempDir d;
  pdt::Mesh m;
  m.points = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  m.tets = {{0, 1, 2, 3}};
  const std::string p = d.file("m.vtu");
  pdt::write_vtu(p, m, pdt::VtuEncoding::ascii);
  const std::string before = pdt_test::read_file(p);
  struct Case {
    std::vector<pdt::CellField> fields;
    const char* says;
  };
  const std::vector<Case> cases = {
      {{{"", {1.0}}}, "cell field 0 has no name"},
      {{{"q", {1.0}}, {"r", {2.0}}, {"q", {3.0}}}, "cell field 2 is named 'q' as field 0 is; VTK needs distinct names"},
      {{{"q", {1.0}}, {"\xFF\xFE", {2.0}}}, "cell field 1's name has byte 0xFF at offset 0"},
      {{{"ab\x01", {1.0}}}, "byte 0x01 at offset 2"},
      {{{std::string("a\0b", 3), {1.0}}}, "byte 0x00 at offset 1"},
      {{{"\xC0\xAF", {1.0}}}, "byte 0xC0 at offset 0"},          // overlong '/'
      {{{"x\xED\xA0\x80", {1.0}}}, "byte 0xED at offset 1"},     // a surrogate
      {{{"\xEF\xBF\xBF", {1.0}}}, "byte 0xEF at offset 0"},      // U+FFFF
      {{{"\xF4\x90\x80\x80", {1.0}}}, "byte 0xF4 at offset 0"},  // past U+10FFFF
      {{{"\xE2\x82", {1.0}}}, "byte 0xE2 at offset 0"},          // cut short
  };
  for (const Case& c : cases)
    for (pdt::VtuEncoding enc : {pdt::VtuEncoding::zlib, pdt::VtuEncoding::raw, pdt::VtuEncoding::ascii}) {
      INFO(c.says);
      auto e = catch_error([&] { pdt::write_vtu(p, m, enc, c.fields); });
      REQUIRE(e);
      CHECK(e->code() == pdt::ErrorCode::invalid_argument);
      CHECK(std::string(e->what()).find(c.says) != std::string::npos);
      CHECK(pdt_test::read_file(p) == before);
      CHECK(d.entries() == 1);
    }
}

TEST_CASE("writers write through a symbolic link and into a FIFO, replacing neither", "[io]") {
  TempDir d;
  pdt::Mesh m;
  m.points = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  m.tets = {{0, 1, 2, 3}};
  std::filesystem::create_directory(d.path() / "real");
  const std::string target = d.file("real/mesh.vtu"), link = d.file("link.vtu");
  std::filesystem::create_symlink(target, link);
  pdt::write_vtu(link, m, pdt::VtuEncoding::ascii);
  CHECK(std::filesystem::is_symlink(link));
  CHECK(pdt_test::read_file(target).find("NumberOfCells=\"1\"") != std::string::npos);
  CHECK(std::distance(std::filesystem::directory_iterator(d.path() / "real"), {}) == 1);  // no temporary left

  // A FIFO is written in place (a rename would replace it with a file). The
  // reader end is opened first, without blocking, so the writer's open does
  // not wait; the file (under 2 KiB) fits the pipe's buffer.
  const std::string fifo = d.file("pipe.vtu");
  REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
  const int rd = ::open(fifo.c_str(), O_RDONLY | O_NONBLOCK);
  REQUIRE(rd >= 0);
  pdt::write_vtu(fifo, m, pdt::VtuEncoding::ascii);
  std::string got;
  char buf[4096];
  for (ssize_t n; (n = ::read(rd, buf, sizeof buf)) > 0;) got.append(buf, static_cast<std::size_t>(n));
  ::close(rd);
  CHECK(std::filesystem::is_fifo(fifo));
  REQUIRE(got.size() > 11);
  CHECK(got.find("NumberOfCells=\"1\"") != std::string::npos);
  CHECK(got.substr(got.size() - 11) == "</VTKFile>\n");
}

// Decodes one appended DataArray of a .vtu written by write_vtu (raw or zlib,
// UInt64 headers), as VTK's reader does.
std::string appended_array(const std::string& x, const std::string& name, bool zlib) {
  const std::size_t tag = x.find(name);
  REQUIRE(tag != std::string::npos);
  const std::size_t at = x.find("offset=\"", tag);
  const std::uint64_t offset = std::stoull(x.substr(at + 8));
  const std::size_t data = x.find("<AppendedData encoding=\"raw\">");
  REQUIRE(data != std::string::npos);
  const std::size_t base = x.find('_', data) + 1 + offset;
  auto u64 = [&](std::size_t pos) {
    std::uint64_t v = 0;
    for (int b = 7; b >= 0; --b) v = (v << 8) | static_cast<unsigned char>(x[pos + b]);
    return v;
  };
  if (!zlib) return x.substr(base + 8, u64(base));
  const std::uint64_t blocks = u64(base), block = u64(base + 8), last = u64(base + 16);
  std::string out;
  std::size_t pos = base + 24 + 8 * blocks;
  for (std::uint64_t b = 0; b < blocks; ++b) {
    const std::uint64_t packed = u64(base + 24 + 8 * b);
    std::string plain(b + 1 == blocks ? last : block, '\0');
    uLongf len = static_cast<uLongf>(plain.size());
    REQUIRE(uncompress(reinterpret_cast<Bytef*>(plain.data()), &len,
                       reinterpret_cast<const Bytef*>(x.data() + pos), static_cast<uLong>(packed)) == Z_OK);
    REQUIRE(len == plain.size());
    out += plain;
    pos += packed;
  }
  return out;
}

TEST_CASE("write_vtu's binary forms hold the mesh and its cell fields, raw and zlib-compressed", "[io]") {
  TempDir d;
  pdt::Mesh m;
  m.points = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {1, 1, 1}, {0.1, 0.2, 0.30000000000000004}};
  m.tets = {{0, 1, 2, 3}, {1, 2, 3, 4}, {5, 1, 2, 3}};
  const std::vector<pdt::CellField> fields{{"quality", {0.5, 0.25, 1e-300}}, {"label", {1, 2, 3}}};
  for (bool zlib : {false, true}) {
    INFO((zlib ? "zlib" : "raw"));
    const std::string p = d.file(zlib ? "z.vtu" : "r.vtu");
    pdt::write_vtu(p, m, zlib ? pdt::VtuEncoding::zlib : pdt::VtuEncoding::raw, fields);
    const std::string x = pdt_test::read_file(p);
    CHECK((x.find("compressor=\"vtkZLibDataCompressor\"") != std::string::npos) == zlib);
    CHECK(x.find("header_type=\"UInt64\"") != std::string::npos);
    const std::string xyz = appended_array(x, "NumberOfComponents=\"3\"", zlib);
    REQUIRE(xyz.size() == 3 * 8 * m.points.size());
    for (std::size_t i = 0; i < m.points.size(); ++i) {
      double c[3];
      std::memcpy(c, xyz.data() + 24 * i, 24);
      CHECK(pdt_test::same_bits(pdt::Point3{c[0], c[1], c[2]}, m.points[i]));
    }
    const std::string conn = appended_array(x, "Name=\"connectivity\"", zlib);
    REQUIRE(conn.size() == 4 * 8 * m.tets.size());
    for (std::size_t t = 0; t < m.tets.size(); ++t)
      for (int k = 0; k < 4; ++k) {
        std::int64_t v = 0;
        std::memcpy(&v, conn.data() + 8 * (4 * t + k), 8);
        CHECK(v == m.tets[t][k]);
      }
    const std::string types = appended_array(x, "Name=\"types\"", zlib);
    CHECK(types == std::string(m.tets.size(), '\x0a'));
    const std::string q = appended_array(x, "Name=\"quality\"", zlib);
    REQUIRE(q.size() == 3 * 8);
    double v[3];
    std::memcpy(v, q.data(), 24);
    CHECK(v[0] == 0.5);
    CHECK(v[2] == 1e-300);
  }
  // A field of the wrong length is refused, and nothing is written.
  const auto e = pdt_test::catch_error([&] {
    pdt::write_vtu(d.file("bad.vtu"), m, pdt::VtuEncoding::zlib, std::vector<pdt::CellField>{{"q", {1.0}}});
  });
  REQUIRE(e);
  CHECK(e->code() == pdt::ErrorCode::invalid_argument);
  CHECK_FALSE(std::filesystem::exists(d.file("bad.vtu")));
}

TEST_CASE("write_tetgen from a triangulation writes what extract_mesh gives", "[io]") {
  TempDir d;
  pdt::Triangulation t;
  for (const pdt::Point3& p : pdt_test::generated_points(pdt::Distribution::uniform, 500, 3)) t.insert(p);
  pdt::write_tetgen(d.file("a.node"), t);
  pdt::write_tetgen(d.file("b.node"), pdt::extract_mesh(t));
  CHECK(pdt_test::read_file(d.file("a.node")) == pdt_test::read_file(d.file("b.node")));
  CHECK(pdt_test::read_file(d.file("a.ele")).size() > 0);
  const pdt::Mesh back = pdt::read_tetgen(d.file("a.node"));
  CHECK(back.tets.size() == t.number_of_finite_cells());
  CHECK(pdt::check_mesh(back).valid);
}

// ---- check_mesh ----------------------------------------------------------------------

TEST_CASE("check_mesh accepts Delaunay tetrahedralizations", "[io]") {
  SECTION("bipyramid split around its axis") {
    const auto c = pdt::check_mesh(bipyramid(0.5, true));
    INFO(c.message);
    CHECK(c.valid);
    CHECK(c.tets == 3);
  }
  SECTION("tall bipyramid as two tets") { CHECK(pdt::check_mesh(bipyramid(10, false)).valid); }
  SECTION("all tets negatively oriented") {
    auto m = bipyramid(0.5, true);
    for (auto& t : m.tets) std::swap(t[2], t[3]);
    const auto c = pdt::check_mesh(m);
    CHECK(c.valid);
    CHECK(c.message.find("negatively") != std::string::npos);
  }
  SECTION("a cube: cospherical, both splittings are Delaunay") {
    pdt::Mesh m;
    for (int i = 0; i < 8; ++i) m.points.push_back({double(i & 1), double((i >> 1) & 1), double((i >> 2) & 1)});
    // Six tets around the diagonal 0-7, and the five-tet split (corner tets + a central one).
    const std::vector<std::array<std::uint32_t, 4>> six = {{0, 1, 3, 7}, {0, 1, 7, 5}, {0, 5, 7, 4},
                                                           {0, 3, 2, 7}, {0, 2, 6, 7}, {0, 6, 4, 7}};
    const std::vector<std::array<std::uint32_t, 4>> five = {{0, 1, 2, 4}, {1, 3, 2, 7}, {1, 4, 5, 7},
                                                            {2, 4, 6, 7}, {1, 2, 4, 7}};
    for (const auto& split : {six, five}) {
      m.tets = split;
      orient_positively(m);
      const auto c = pdt::check_mesh(m);
      INFO(c.message);
      CHECK(c.valid);
      CHECK(c.message.find("negatively") == std::string::npos);
    }
  }
  SECTION("near DBL_MAX the cover degree is still probed") {
    // A centroid's plain sum overflowed there, and the degree test was skipped.
    const double M = std::numeric_limits<double>::max();
    const pdt::Mesh m = delaunay_of({{0, 0, 0}, {M, 0, 0}, {0, M, 0}, {M / 4, M / 4, M / 8}, {M / 8, M / 4, -M / 2}});
    REQUIRE(m.tets.size() >= 2);
    const auto c = pdt::check_mesh(m);
    INFO(c.message);
    CHECK(c.valid);
    CHECK(c.message.find("not probed") == std::string::npos);
  }
  SECTION("coplanar points without tets") {
    pdt::Mesh m;
    m.points = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}};
    auto c = pdt::check_mesh(m);
    CHECK(c.valid);
    CHECK(c.message == "no tetrahedra; the 4 points are coplanar, so none is expected");
    m.points.push_back({0, 0, 1});
    CHECK_FALSE(pdt::check_mesh(m).valid);
    m.points = {{0, 0, 0}, {1, 1, 1}, {2, 2, 2}};
    c = pdt::check_mesh(m);
    CHECK(c.valid);
    CHECK(c.message == "no tetrahedra; the 3 points are collinear, so none is expected");
    m.points = {{5, 5, 5}};
    CHECK(pdt::check_mesh(m).message == "no tetrahedra; a single point, so none is expected");
  }
  SECTION("the kernel's triangulation of random points") {
    const pdt::Mesh m = delaunay_of(uniform_points(2000, 3));
    const auto c = pdt::check_mesh(m);
    INFO(c.message);
    CHECK(c.valid);
    CHECK(c.points == 2000);
    CHECK(c.tets > 2000);
  }
}

TEST_CASE("check_mesh rejects broken meshes", "[io]") {
  const pdt::Mesh good = delaunay_of(uniform_points(300, 5));
  REQUIRE(pdt::check_mesh(good).valid);
  auto expect_invalid = [](const pdt::Mesh& m, const char* why) {
    const auto c = pdt::check_mesh(m);
    INFO(c.message);
    CHECK_FALSE(c.valid);
    CHECK(c.message.find(why) != std::string::npos);
  };
  SECTION("a flipped tet") {
    pdt::Mesh m = good;
    std::swap(m.tets[17][0], m.tets[17][1]);
    expect_invalid(m, "tetrahedron 17 is negatively oriented");
  }
  SECTION("a dropped tet") {
    pdt::Mesh m = good;
    m.tets.erase(m.tets.begin() + 40);
    const auto c = pdt::check_mesh(m);
    INFO(c.message);
    CHECK_FALSE(c.valid);
  }
  SECTION("a duplicated tet") {
    pdt::Mesh m = good;
    m.tets.push_back(m.tets[3]);
    expect_invalid(m, "belongs to 3 tetrahedra");
  }
  SECTION("a non-Delaunay facet") { expect_invalid(bipyramid(0.5, false), "not Delaunay"); }
  SECTION("a point moved to break the Delaunay property") {
    // Move a vertex toward the far vertex of a neighbouring tet, by a fraction
    // small enough to keep every tet positively oriented.
    pdt::Mesh m = good;
    bool broken = false;
    for (std::size_t v = 0; v < m.points.size() && !broken; ++v) {
      for (double f : {0.3, 0.15, 0.05}) {
        pdt::Mesh t = m;
        // Toward the centroid of all points: an interior move.
        pdt::Point3 c{0.5, 0.5, 0.5};
        t.points[v] = {m.points[v].x + f * (c.x - m.points[v].x), m.points[v].y + f * (c.y - m.points[v].y),
                       m.points[v].z + f * (c.z - m.points[v].z)};
        const auto r = pdt::check_mesh(t);
        if (!r.valid && r.message.find("not Delaunay") != std::string::npos) {
          broken = true;
          break;
        }
      }
    }
    CHECK(broken);
  }
  SECTION("an unused point") {
    pdt::Mesh m = good;
    m.points.push_back({0.5, 0.5, 0.5000001});
    expect_invalid(m, "is not a vertex of any tetrahedron");
  }
  SECTION("a non-convex union") {
    pdt::Mesh m;
    m.points = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0.2, 0.2, 1}, {5, 5, -1}};
    m.tets = {{0, 1, 2, 3}, {0, 2, 1, 4}};
    expect_invalid(m, "not convex");
  }
  SECTION("index out of range") {
    pdt::Mesh m = good;
    m.tets[0][2] = static_cast<std::uint32_t>(m.points.size());
    expect_invalid(m, "but there are only");
  }
  SECTION("coinciding points") {
    pdt::Mesh m = good;
    m.points[1] = m.points[0];
    expect_invalid(m, "coincide");
  }
}

TEST_CASE("extract_mesh of a triangulation round-trips through TetGen files", "[io]") {
  TempDir d;
  pdt::Triangulation t;
  const auto pts = uniform_points(500, 8);
  std::vector<pdt::VertexId> ids;
  for (const auto& p : pts) ids.push_back(t.insert(p).vertex);
  for (std::size_t i = 0; i < 200; ++i) t.remove(ids[i]);
  const pdt::Mesh m = pdt::extract_mesh(t);
  CHECK(m.points.size() == 300);
  CHECK(m.tets.size() == t.number_of_finite_cells());
  pdt::write_tetgen(d.file("t"), m);
  const pdt::Mesh r = pdt::read_tetgen(d.file("t.node"));
  CHECK(r.tets == m.tets);
  REQUIRE(r.points.size() == m.points.size());
  for (std::size_t i = 0; i < m.points.size(); ++i) REQUIRE(same_bits(r.points[i], m.points[i]));
  const auto c = pdt::check_mesh(r);
  INFO(c.message);
  CHECK(c.valid);
  // Lower dimension: no tets, all points kept.
  pdt::Triangulation flat;
  flat.insert({0, 0, 0});
  flat.insert({1, 0, 0});
  flat.insert({0, 1, 0});
  const pdt::Mesh fm = pdt::extract_mesh(flat);
  CHECK(fm.points.size() == 3);
  CHECK(fm.tets.empty());
  CHECK(pdt::check_mesh(fm).valid);
}
