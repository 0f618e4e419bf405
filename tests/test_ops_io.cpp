// SPDX-License-Identifier: MIT
// Operation stream I/O: round trips (text and binary, bit-exact), every
// malformed-stream case with its line, missing files, and write failures
// (disk full via /dev/full and a file size limit) leaving nothing behind.
#include <fcntl.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include <catch2/catch.hpp>
#include <cfloat>
#include <cmath>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <functional>
#include <limits>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "common/io_test_util.hpp"
#include "io_util.hpp"
#include "live_insertions.hpp"  // the readers' and the writer's live set, tested alone
#include "pdt/io.hpp"
#include "pdt/ops.hpp"

using pdt_test::catch_error;
using pdt_test::same_bits;
using pdt_test::TempDir;
using pdt_test::write_file;

namespace {

pdt::Operation ins(double x, double y, double z) {
  pdt::Operation op;
  op.kind = pdt::Operation::Kind::insert;
  op.point = {x, y, z};
  return op;
}
pdt::Operation rem(std::uint64_t k) {
  pdt::Operation op;
  op.kind = pdt::Operation::Kind::remove;
  op.target = k;
  return op;
}

// Values chosen to break any writer that loses digits or any reader that is
// not correctly rounded: subnormals, extremes, non-terminating binary
// fractions, negative zero, halfway-like decimals.
pdt::OpStream tricky_stream() {
  pdt::OpStream s;
  s.box = pdt::Box{{-1.7976931348623157e308, -1e308, -DBL_MAX}, {DBL_MAX, 1e308, 1.7976931348623157e308}};
  const double denorm_min = std::numeric_limits<double>::denorm_min();
  s.ops = {ins(denorm_min, -denorm_min, 2.2250738585072009e-308),  // smallest subnormal; largest subnormal
           ins(1e308, -1e308, DBL_MAX),
           ins(0.1, 1.0 / 3.0, -0.0),
           ins(std::nextafter(1.0, 2.0), std::nextafter(1.0, 0.0), 9007199254740993.0),
           rem(1),
           ins(123456789.123456789, -2.5e-300, 5e-324),
           rem(0),
           ins(0.1, 1.0 / 3.0, -0.0),  // a duplicate point: allowed in a stream
           rem(3)};
  return s;
}

void require_same(const pdt::OpStream& a, const pdt::OpStream& b) {
  REQUIRE(a.box.has_value() == b.box.has_value());
  if (a.box) {
    CHECK(same_bits(a.box->lo, b.box->lo));
    CHECK(same_bits(a.box->hi, b.box->hi));
  }
  REQUIRE(a.ops.size() == b.ops.size());
  for (std::size_t i = 0; i < a.ops.size(); ++i) {
    INFO("operation " << i);
    REQUIRE(a.ops[i].kind == b.ops[i].kind);
    if (a.ops[i].kind == pdt::Operation::Kind::insert) CHECK(same_bits(a.ops[i].point, b.ops[i].point));
    else CHECK(a.ops[i].target == b.ops[i].target);
  }
}

// The error read_ops gives for `content`, which must be bad_format naming
// `file:line:` and containing `what`.
void expect_bad(const std::string& content, int line, const std::string& what) {
  TempDir d;
  const std::string p = d.file("bad.ops");
  write_file(p, content);
  INFO("stream:\n" << content);
  auto e = catch_error([&] { pdt::read_ops(p); });
  REQUIRE(e);
  INFO("message: " << e->what());
  CHECK(e->code() == pdt::ErrorCode::bad_format);
  CHECK(std::string(e->what()).find(p + ":" + std::to_string(line) + ": ") == 0);
  CHECK(std::string(e->what()).find(what) != std::string::npos);
}

}  // namespace

TEST_CASE("ops text round trip is bit-exact", "[io]") {
  TempDir d;
  const pdt::OpStream s = tricky_stream();
  const std::string p = d.file("s.ops");
  pdt::write_ops(p, s);
  const std::string text = pdt_test::read_file(p);
  // 17 significant digits, as documented.
  CHECK(text.find("i 0.10000000000000001 0.33333333333333331 -0\n") != std::string::npos);
  CHECK(text.find("\nr 1\n") != std::string::npos);
  CHECK(text.find("\nbox ") != std::string::npos);
  require_same(s, pdt::read_ops(p));
  CHECK(d.entries() == 1);  // no temporary file left over
}

TEST_CASE("ops binary round trip is bit-exact and has the documented layout", "[io]") {
  TempDir d;
  const pdt::OpStream s = tricky_stream();
  const std::string p = d.file("s.opsb");
  pdt::write_ops(p, s);
  const std::string bytes = pdt_test::read_file(p);
  // magic 8 + has_box 1 + box 48 + count 8, then 6 inserts x 25 + 3 removes x 9.
  REQUIRE(bytes.size() == 65 + 6 * 25 + 3 * 9);
  CHECK(std::memcmp(bytes.data(), "PDTOPS1\0", 8) == 0);
  CHECK(bytes[8] == 1);
  CHECK(static_cast<unsigned char>(bytes[57]) == 9);  // count, little-endian
  CHECK(bytes[65] == 0);                              // first op: insert
  require_same(s, pdt::read_ops(p));
}

TEST_CASE("ops format is chosen by content, not by name", "[io]") {
  TempDir d;
  const pdt::OpStream s = tricky_stream();
  pdt::write_ops(d.file("a.opsb"), s);
  std::filesystem::rename(d.file("a.opsb"), d.file("a.ops"));  // binary under a text name
  require_same(s, pdt::read_ops(d.file("a.ops")));
}

TEST_CASE("ops: a file named .opsb must be binary, an empty one included", "[io]") {
  TempDir d;
  pdt::write_ops(d.file("a.opsb"), tricky_stream());
  const std::string bytes = pdt_test::read_file(d.file("a.opsb"));
  const std::pair<std::string, std::string> cases[] = {
      {"", "and this one is empty"},
      {bytes.substr(0, 5), "starts with 'PDTOP'"},
      {"i 1 2 3\n", "starts with 'i 1 2 3"},
  };
  for (const auto& [content, what] : cases) {
    for (const char* name : {"b.opsb", "b.OPSB"}) {
      write_file(d.file(name), content);
      auto e = catch_error([&] { pdt::read_ops(d.file(name)); });
      REQUIRE(e);
      INFO(e->what());
      CHECK(e->code() == pdt::ErrorCode::bad_format);
      CHECK(std::string(e->what()).find(d.file(name) + ": not a binary operation stream") == 0);
      CHECK(std::string(e->what()).find(what) != std::string::npos);
      std::filesystem::remove(d.file(name));
    }
  }
  // Under a text name the same text reads as text.
  write_file(d.file("b.ops"), "i 1 2 3\n");
  CHECK(pdt::read_ops(d.file("b.ops")).ops.size() == 1);
}

TEST_CASE("ops writers refuse a path that names no file before writing", "[io]") {
  TempDir d;
  const std::filesystem::path cwd = std::filesystem::current_path();
  std::filesystem::current_path(d.path());
  for (const std::string& path : {std::string(), d.file("sub") + "/"}) {
    INFO("path '" << path << "'");
    auto e = catch_error([&] { pdt::write_ops(path, tricky_stream()); });
    REQUIRE(e);
    CHECK(e->code() == pdt::ErrorCode::invalid_argument);
    CHECK(std::string(e->what()).find("write_ops: '" + path + "' names no file") == 0);
    e = catch_error([&] { pdt::OpWriter w(path); });
    REQUIRE(e);
    CHECK(e->code() == pdt::ErrorCode::invalid_argument);
    CHECK(std::string(e->what()).find("OpWriter: '" + path + "' names no file") == 0);
  }
  std::filesystem::current_path(cwd);
  CHECK(d.entries() == 0);  // no temporary left behind
}

TEST_CASE("ops without a box, empty streams, counts", "[io]") {
  TempDir d;
  pdt::OpStream s;
  s.ops = {ins(1, 2, 3), ins(4, 5, 6), rem(0), ins(7, 8, 9)};
  CHECK(s.insert_count() == 3);
  CHECK(s.remove_count() == 1);
  for (const char* name : {"n.ops", "n.opsb"}) {
    pdt::write_ops(d.file(name), s);
    const pdt::OpStream r = pdt::read_ops(d.file(name));
    CHECK_FALSE(r.box.has_value());
    require_same(s, r);
  }
  pdt::OpStream empty;
  pdt::write_ops(d.file("e.ops"), empty);
  pdt::write_ops(d.file("e.opsb"), empty);
  CHECK(pdt::read_ops(d.file("e.ops")).ops.empty());
  CHECK(pdt::read_ops(d.file("e.opsb")).ops.empty());
}

TEST_CASE("ops text accepts comments, blank lines, CRLF, '+' signs and exponents", "[io]") {
  TempDir d;
  const std::string p = d.file("ok.ops");
  write_file(p,
             "# header comment\r\n"
             "\r\n"
             "   box  0 0 0   1 1 1   # the domain\r\n"
             "i\t+0.5 1e-1 .25\r\n"
             "i 1 1 1\n"
             "r 0 # undo\n"
             "i 0 0 0");  // no final newline
  const pdt::OpStream s = pdt::read_ops(p);
  REQUIRE(s.ops.size() == 4);
  CHECK(s.ops[0].point == pdt::Point3{0.5, 0.1, 0.25});
  CHECK(s.ops[2].kind == pdt::Operation::Kind::remove);
  CHECK(s.ops[2].target == 0);
  CHECK(s.ops[3].point == pdt::Point3{0, 0, 0});
}

TEST_CASE("malformed text streams are rejected with file and line", "[io]") {
  SECTION("unknown verb") { expect_bad("i 1 2 3\nx 1 2 3\n", 2, "unknown verb 'x'"); }
  SECTION("verbs are case-sensitive") { expect_bad("I 1 2 3\n", 1, "unknown verb 'I'"); }
  SECTION("a point file under a stream's name") {
    expect_bad("0.1 0.2 0.3\n0.4 0.5 0.6\n", 1, "unknown verb '0.1'");
    expect_bad("0.1 0.2 0.3\n", 1, "is read as one by its extension: .xyz");
  }
  SECTION("missing coordinate") { expect_bad("i 1 2\n", 1, "expected 'i x y z'"); }
  SECTION("extra coordinate") { expect_bad("i 0 0 0\ni 1 2 3 4\n", 2, "expected 'i x y z'"); }
  SECTION("NaN") { expect_bad("i 0 0 0\ni nan 0 0\n", 2, "not finite"); }
  SECTION("NaN spelled otherwise") { expect_bad("i 0 NaN 0\n", 1, "not finite"); }
  SECTION("infinity") { expect_bad("i 0 0 inf\n", 1, "not finite"); }
  SECTION("negative infinity") { expect_bad("i -infinity 0 0\n", 1, "not finite"); }
  SECTION("overflow") { expect_bad("# c\ni 1e309 0 0\n", 2, "out of the range"); }
  SECTION("negative overflow") { expect_bad("i 0 -2e308 0\n", 1, "out of the range"); }
  SECTION("underflow to zero") { expect_bad("i 0 0 1e-400\n", 1, "out of the range"); }
  SECTION("decimal comma") { expect_bad("i 1,5 0 0\n", 1, "not a number"); }
  SECTION("hex float") { expect_bad("i 0x10 0 0\n", 1, "not a number"); }
  SECTION("trailing garbage") { expect_bad("i 1.0abc 0 0\n", 1, "not a number"); }
  SECTION("double sign") { expect_bad("i +-1 0 0\n", 1, "not a number"); }
  SECTION("box after operations") { expect_bad("# c\n\ni 0 0 0\nbox 0 0 0 1 1 1\n", 4, "'box' after operations"); }
  SECTION("second box") { expect_bad("box 0 0 0 1 1 1\nbox 0 0 0 1 1 1\n", 2, "second 'box'"); }
  SECTION("box with 5 numbers") { expect_bad("box 0 0 0 1 1\n", 1, "expected 'box x0 y0 z0 x1 y1 z1'"); }
  SECTION("box with 7 numbers") { expect_bad("box 0 0 0 1 1 1 1\n", 1, "expected 'box x0 y0 z0 x1 y1 z1'"); }
  SECTION("inverted box") { expect_bad("box 1 0 0 0 1 1\n", 1, "lower corner above"); }
  SECTION("box with NaN") { expect_bad("box 0 0 0 1 nan 1\n", 1, "not finite"); }
  SECTION("point outside the box") { expect_bad("box 0 0 0 1 1 1\ni 0.5 0.5 0.5\ni 0.5 1.0000000000000002 0.5\n", 3, "outside the box declared on line 1"); }
  SECTION("r of an insertion not made yet") { expect_bad("i 0 0 0\nr 1\n", 2, "not been made yet"); }
  SECTION("r before any insertion") { expect_bad("r 0\n", 1, "not been made yet"); }
  SECTION("r of an insertion already undone") { expect_bad("i 0 0 0\ni 1 1 1\nr 0\nr 0\n", 4, "already undone"); }
  SECTION("r with a negative index") { expect_bad("i 0 0 0\nr -1\n", 2, "not a non-negative integer"); }
  SECTION("r with a fractional index") { expect_bad("i 0 0 0\nr 0.0\n", 2, "not a non-negative integer"); }
  SECTION("r with a huge index") { expect_bad("i 0 0 0\nr 99999999999999999999999\n", 2, "too large"); }
  SECTION("r without index") { expect_bad("i 0 0 0\nr\n", 2, "expected 'r k'"); }
  SECTION("r with two indices") { expect_bad("i 0 0 0\nr 0 0\n", 2, "expected 'r k'"); }
  SECTION("binary garbage") { expect_bad(std::string("i 0 0 0\n\x01\x02\x03 4\n", 13), 2, "unknown verb '\\x01\\x02\\x03'"); }
}

TEST_CASE("malformed binary streams are rejected", "[io]") {
  TempDir d;
  pdt::OpStream s;
  s.box = pdt::Box{{0, 0, 0}, {1, 1, 1}};
  s.ops = {ins(0.5, 0.5, 0.5), ins(0.25, 0.25, 0.25), rem(0)};
  const std::string good = d.file("good.opsb");
  pdt::write_ops(good, s);
  const std::string bytes = pdt_test::read_file(good);
  REQUIRE(bytes.size() == 65 + 2 * 25 + 9);
  auto expect = [&](std::string b, const std::string& what) {
    const std::string p = d.file("bad.opsb");
    write_file(p, b);
    auto e = catch_error([&] { pdt::read_ops(p); });
    REQUIRE(e);
    INFO(e->what());
    CHECK(e->code() == pdt::ErrorCode::bad_format);
    CHECK(std::string(e->what()).find(p + ": ") == 0);
    CHECK(std::string(e->what()).find(what) != std::string::npos);
  };
  SECTION("truncated header") { expect(bytes.substr(0, 40), "ends inside the header"); }
  SECTION("bad box flag") {
    std::string b = bytes;
    b[8] = 2;
    expect(b, "box flag");
  }
  SECTION("count larger than the data") {
    std::string b = bytes;
    b[57] = 4;
    expect(b, "file ends after 3 of the 4 operations");
  }
  SECTION("count smaller than the data") {
    std::string b = bytes;
    b[57] = 2;
    expect(b, "extra data");
  }
  SECTION("unknown kind") {
    std::string b = bytes;
    b[65 + 25] = 7;
    expect(b, "operation 1 (byte 90): unknown operation kind 7");
  }
  SECTION("truncated record") { expect(bytes.substr(0, 65 + 25 + 10), "ends inside an insertion record"); }
  SECTION("NaN coordinate") {
    std::string b = bytes;
    const double nan = std::numeric_limits<double>::quiet_NaN();
    std::memcpy(&b[65 + 1 + 8], &nan, 8);  // host is little-endian (x86-64, aarch64)
    expect(b, "NaN or infinite");
  }
  SECTION("point outside the box") {
    std::string b = bytes;
    const double two = 2.0;
    std::memcpy(&b[65 + 25 + 1], &two, 8);
    expect(b, "outside the stream's box");
  }
  SECTION("removal of an insertion not made") {
    std::string b = bytes;
    b[65 + 50 + 1] = 5;
    expect(b, "not been made yet");
  }
}

TEST_CASE("an OpReader whose next() threw stops there: the same error again, nothing past it, op untouched",
          "[io]") {
  TempDir d;
  auto drain_after_error = [](pdt::OpReader& r, std::uint64_t good_before) {
    pdt::Operation op;
    for (std::uint64_t k = 0; k < good_before; ++k) REQUIRE(r.next(op));
    const pdt::Operation marker = ins(-7, -8, -9);
    std::string first_message;
    for (int attempt = 0; attempt < 3; ++attempt) {
      op = marker;
      auto e = catch_error([&] { r.next(op); });
      REQUIRE(e);  // never an operation from past the bad record, never a quiet end
      CHECK(e->code() == pdt::ErrorCode::bad_format);
      if (attempt == 0) first_message = e->what();
      CHECK(std::string(e->what()) == first_message);
      CHECK(same_bits(op.point, marker.point));  // the caller's op as it was
      CHECK(r.operations_read() == good_before);
    }
  };
  SECTION("binary: a record of an unknown kind, then a good insertion") {
    pdt::OpStream s;
    s.ops = {ins(1, 2, 3), ins(4, 5, 6), ins(7, 8, 9)};
    const std::string good = d.file("good.opsb");
    pdt::write_ops(good, s);
    std::string b = pdt_test::read_file(good);
    b[65 + 25] = 7;  // operation 1's kind
    const std::string p = d.file("bad.opsb");
    write_file(p, b);
    pdt::OpReader r(p);
    drain_after_error(r, 1);
  }
  SECTION("text: a bad line between good ones") {
    const std::string p = d.file("bad.ops");
    write_file(p, "i 1 2 3\ni 4 5 6\nx 1\ni 7 8 9\nr 0\n");
    pdt::OpReader r(p);
    drain_after_error(r, 2);
  }
  SECTION("text: an undo of an insertion not made yet") {
    const std::string p = d.file("bad.ops");
    write_file(p, "i 1 2 3\nr 5\ni 4 5 6\n");
    pdt::OpReader r(p);
    drain_after_error(r, 1);
  }
}

TEST_CASE("missing or unreadable ops files give io_failure", "[io]") {
  TempDir d;
  auto e = catch_error([&] { pdt::read_ops(d.file("nope.ops")); });
  REQUIRE(e);
  CHECK(e->code() == pdt::ErrorCode::io_failure);
  CHECK(std::string(e->what()).find(d.file("nope.ops")) != std::string::npos);
  CHECK(std::string(e->what()).find("No such file or directory") != std::string::npos);
  auto e2 = catch_error([&] { pdt::read_ops(d.path().string()); });  // a directory
  REQUIRE(e2);
  CHECK(e2->code() == pdt::ErrorCode::io_failure);
  CHECK(std::string(e2->what()).find("Is a directory") != std::string::npos);
}

namespace {
// data as one gzip member (zlib's deflate with gzip framing).
std::string gzip_member(const std::string& data) {
  z_stream zs{};
  REQUIRE(deflateInit2(&zs, 6, Z_DEFLATED, 16 + MAX_WBITS, 8, Z_DEFAULT_STRATEGY) == Z_OK);
  std::string out(deflateBound(&zs, data.size()) + 32, '\0');
  zs.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(data.data()));
  zs.avail_in = static_cast<uInt>(data.size());
  zs.next_out = reinterpret_cast<Bytef*>(out.data());
  zs.avail_out = static_cast<uInt>(out.size());
  REQUIRE(deflate(&zs, Z_FINISH) == Z_STREAM_END);
  out.resize(zs.total_out);
  deflateEnd(&zs);
  return out;
}
}  // namespace

TEST_CASE("gzipped streams: members back to back are read whole; appended bytes, truncation, corruption refused",
          "[io]") {
  TempDir d;
  std::string text = "box 0 0 0 1 1 1\n";
  for (int k = 0; k < 3000; ++k) text += "i 0." + std::to_string(100000 + 7 * k) + " 0.5 0.25\nr " + std::to_string(k) + "\n";
  const pdt::OpStream plain = [&] {
    write_file(d.file("plain.ops"), text);
    return pdt::read_ops(d.file("plain.ops"));
  }();
  REQUIRE(plain.ops.size() == 6000);
  const std::string gz = gzip_member(text);
  auto read = [&](const std::string& name, const std::string& bytes) {
    write_file(d.file(name), bytes);
    return pdt::read_ops(d.file(name));
  };
  auto refused = [&](const std::string& name, const std::string& bytes, const std::string& says) {
    write_file(d.file(name), bytes);
    auto e = catch_error([&] { pdt::read_ops(d.file(name)); });
    REQUIRE(e);
    CHECK(e->code() == pdt::ErrorCode::bad_format);
    INFO(e->what());
    CHECK(std::string(e->what()).find(says) != std::string::npos);
  };
  SECTION("one member, and the same text split into members (what cat a.gz b.gz makes)") {
    CHECK(read("one.ops.gz", gz).ops.size() == plain.ops.size());
    const std::size_t cut = text.find('\n', text.size() / 2) + 1;
    const auto two = read("two.ops.gz", gzip_member(text.substr(0, cut)) + gzip_member("") + gzip_member(text.substr(cut)));
    REQUIRE(two.ops.size() == plain.ops.size());
    CHECK(two.ops.back().target == plain.ops.back().target);
  }
  SECTION("plain bytes appended to the gzip data: refused, with the offset where they start") {
    refused("app.ops.gz", gz + "i 0.5 0.5 0.5\n", "other data follows the gzip data (from byte " + std::to_string(gz.size()));
    refused("one-byte.ops.gz", gz + "\x1f", "from byte " + std::to_string(gz.size()));
    refused("zeros.ops.gz", gz + std::string(512, '\0'), "other data follows the gzip data");
  }
  SECTION("a member cut short or damaged") {
    for (std::size_t keep : {std::size_t{2}, std::size_t{10}, gz.size() / 2, gz.size() - 1})
      refused("cut.ops.gz", gz.substr(0, keep), "truncated compressed data");
    std::string bad = gz;
    for (std::size_t i = 40; i < 48; ++i) bad[i] = static_cast<char>(bad[i] ^ 0x5a);
    refused("bad.ops.gz", bad, "corrupt compressed data");
  }
  SECTION("a plain file that starts like gzip's magic but is not one is read as text") {
    refused("magic1.ops", "\x1f", "unknown verb");
    CHECK(read("empty.ops", "").ops.empty());
  }
}

TEST_CASE("a UTF-8 byte order mark before a text stream is skipped; a binary stream of another version is named",
          "[io]") {
  TempDir d;
  write_file(d.file("bom.ops"), "\xEF\xBB\xBF" "box 0 0 0 1 1 1\ni 0.5 0.5 0.5\nr 0\n");
  const auto s = pdt::read_ops(d.file("bom.ops"));
  REQUIRE(s.box);
  CHECK(s.ops.size() == 2);
  write_file(d.file("bom.xyz"), "\xEF\xBB\xBF" "0 0 0\n1 0 0\n");
  CHECK(pdt::read_points(d.file("bom.xyz")).size() == 2);
  write_file(d.file("half.ops"), "\xEF\xBB" "i 0 0 0\n");  // not a byte order mark: bytes of a verb
  auto e = catch_error([&] { pdt::read_ops(d.file("half.ops")); });
  REQUIRE(e);
  CHECK(std::string(e->what()).find("half.ops:1: unknown verb") != std::string::npos);
  write_file(d.file("v2.opsb"), std::string("PDTOPS2\0", 8) + std::string(80, '\0'));
  e = catch_error([&] { pdt::read_ops(d.file("v2.opsb")); });
  REQUIRE(e);
  CHECK(e->code() == pdt::ErrorCode::bad_format);
  CHECK(std::string(e->what()).find("a binary operation stream of another version (magic 'PDTOPS2\\x00')") !=
        std::string::npos);
}

TEST_CASE("write_ops refuses streams read_ops would reject, writing nothing", "[io]") {
  TempDir d;
  pdt::OpStream s;
  s.ops = {ins(0, std::numeric_limits<double>::quiet_NaN(), 0)};
  auto e = catch_error([&] { pdt::write_ops(d.file("x.ops"), s); });
  REQUIRE(e);
  CHECK(e->code() == pdt::ErrorCode::invalid_argument);
  s.ops = {ins(0, 0, 0), rem(1)};
  auto e2 = catch_error([&] { pdt::write_ops(d.file("x.ops"), s); });
  REQUIRE(e2);
  CHECK(e2->code() == pdt::ErrorCode::invalid_argument);
  s.box = pdt::Box{{1, 1, 1}, {2, 2, 2}};
  s.ops = {ins(0, 0, 0)};
  auto e3 = catch_error([&] { pdt::write_ops(d.file("x.opsb"), s); });
  REQUIRE(e3);
  CHECK(e3->code() == pdt::ErrorCode::invalid_argument);
  CHECK(d.entries() == 0);
}

TEST_CASE("write_ops into a missing directory names the path", "[io]") {
  TempDir d;
  const std::string p = d.file("no/such/dir/x.ops");
  auto e = catch_error([&] { pdt::write_ops(p, pdt::OpStream{}); });
  REQUIRE(e);
  CHECK(e->code() == pdt::ErrorCode::io_failure);
  CHECK(std::string(e->what()).find(p) != std::string::npos);
  CHECK(std::string(e->what()).find("No such file or directory") != std::string::npos);
}

TEST_CASE("write_ops replaces an existing file atomically", "[io]") {
  TempDir d;
  const std::string p = d.file("x.ops");
  write_file(p, "old content that is not a stream\n");
  pdt::OpStream s;
  s.ops = {ins(1, 2, 3)};
  pdt::write_ops(p, s);
  CHECK(pdt::read_ops(p).ops.size() == 1);
  CHECK(d.entries() == 1);
}

TEST_CASE("a full disk gives io_failure 'No space left on device'", "[io]") {
  // The checked writer every pdt writer goes through, on /dev/full (every
  // write fails with ENOSPC). The public writers cannot target /dev/full
  // themselves: they create a temporary file beside the target.
  const int fd = ::open("/dev/full", O_WRONLY | O_CLOEXEC);
  if (fd < 0) {
    WARN("/dev/full not available; skipping");
    return;
  }
  auto e = catch_error([&] {
    pdt::detail::FdWriter w(fd, "/dev/full");
    const std::string chunk(4096, 'x');
    for (int i = 0; i < 1024; ++i) w.put(chunk);  // 4 MiB: more than the buffer holds
    w.flush();
  });
  ::close(fd);
  REQUIRE(e);
  CHECK(e->code() == pdt::ErrorCode::io_failure);
  CHECK(std::string(e->what()) == "cannot write '/dev/full': No space left on device");
}

TEST_CASE("a write failure in write_ops leaves no file behind", "[io]") {
  // A file-size limit makes write(2) fail (EFBIG) part way through, through
  // the public writer: it must throw io_failure and remove its temporary file.
  TempDir d;
  pdt::OpStream s;
  for (int i = 0; i < 200000; ++i) s.ops.push_back(ins(i * 0.1, i * 0.2, i * 0.3));
  struct rlimit old {};
  REQUIRE(::getrlimit(RLIMIT_FSIZE, &old) == 0);
  auto old_handler = std::signal(SIGXFSZ, SIG_IGN);  // fail with EFBIG instead of killing us
  struct rlimit lim = old;
  lim.rlim_cur = 64 * 1024;
  REQUIRE(::setrlimit(RLIMIT_FSIZE, &lim) == 0);
  auto e1 = catch_error([&] { pdt::write_ops(d.file("big.ops"), s); });
  auto e2 = catch_error([&] { pdt::write_ops(d.file("big.opsb"), s); });
  ::setrlimit(RLIMIT_FSIZE, &old);
  std::signal(SIGXFSZ, old_handler);
  for (auto* e : {&e1, &e2}) {
    REQUIRE(*e);
    INFO((*e)->what());
    CHECK((*e)->code() == pdt::ErrorCode::io_failure);
    CHECK(std::string((*e)->what()).find("File too large") != std::string::npos);
  }
  CHECK(std::string(e1->what()).find(d.file("big.ops")) != std::string::npos);
  CHECK(d.entries() == 0);  // neither the target nor a temporary file
}

TEST_CASE("number parsing helpers are exact and strict", "[io]") {
  using pdt::detail::NumStatus;
  double v = 0;
  CHECK(pdt::detail::parse_double("4.9406564584124654e-324", v) == NumStatus::ok);
  CHECK(same_bits(v, std::numeric_limits<double>::denorm_min()));
  CHECK(pdt::detail::parse_double("0.1", v) == NumStatus::ok);
  CHECK(same_bits(v, 0.1));
  CHECK(pdt::detail::parse_double("1.7976931348623157e308", v) == NumStatus::ok);
  CHECK(v == DBL_MAX);
  CHECK(pdt::detail::parse_double("1.7976931348623159e308", v) == NumStatus::out_of_range);
  CHECK(pdt::detail::parse_double("", v) == NumStatus::not_a_number);
  CHECK(pdt::detail::parse_double("+", v) == NumStatus::not_a_number);
  CHECK(pdt::detail::parse_double("1e", v) == NumStatus::not_a_number);
  std::uint64_t k = 0;
  CHECK(pdt::detail::parse_u64("18446744073709551615", k) == NumStatus::ok);
  CHECK(k == 18446744073709551615ull);
  CHECK(pdt::detail::parse_u64("18446744073709551616", k) == NumStatus::out_of_range);
  CHECK(pdt::detail::parse_u64("+1", k) == NumStatus::not_a_number);
  std::string s;
  pdt::detail::append_double(s, 0.1);
  CHECK(s == "0.10000000000000001");
  s.clear();
  pdt::detail::append_double(s, 1e308);
  CHECK(s == "1e+308");
}

TEST_CASE("OpWriter writes a stream one operation at a time, text and binary, bit-exact", "[io]") {
  const pdt::OpStream s = tricky_stream();
  for (const char* name : {"w.ops", "w.opsb"}) {
    INFO(name);
    TempDir d;
    const std::string p = d.file(name);
    pdt::OpWriter w(p, s.box);
    CHECK_FALSE(std::filesystem::exists(p));  // written to a temporary file until close()
    std::uint64_t inserted = 0;
    for (const pdt::Operation& op : s.ops) {
      if (op.kind == pdt::Operation::Kind::insert)
        CHECK(w.insert(op.point) == inserted++);  // its index, as 'r k' names it
      else
        w.remove(op.target);
    }
    CHECK(w.operations_written() == s.ops.size());
    CHECK(w.insertions_written() == inserted);
    w.close();
    require_same(s, pdt::read_ops(p));
    CHECK(d.entries() == 1);  // no temporary file left over
    const std::string bytes = pdt_test::read_file(p);
    if (std::string(name) == "w.opsb") {
      CHECK(std::memcmp(bytes.data(), "PDTOPS1\0", 8) == 0);
      CHECK(static_cast<unsigned char>(bytes[57]) == s.ops.size());  // the count, patched at close()
    } else {
      CHECK(bytes.rfind("# pdt operation stream", 0) == 0);
    }
    auto e = catch_error([&] { w.insert({0, 0, 0}); });  // closed
    REQUIRE(e);
    CHECK(e->code() == pdt::ErrorCode::invalid_argument);
    CHECK(std::string(e->what()).find("closed") != std::string::npos);
  }
}

TEST_CASE("OpWriter::finish writes everything out without putting the file in place; close then renames", "[io]") {
  TempDir d;
  for (const char* name : {"f.ops", "f.opsb"}) {
    INFO(name);
    const std::string path = d.file(name);
    write_file(path, "older\n");
    pdt::OpWriter w(path, pdt::Box{{0, 0, 0}, {1, 1, 1}});
    const std::uint64_t k = w.insert({0.5, 0.5, 0.5});
    w.insert({0.25, 0.5, 0.5});
    w.remove(k);
    w.finish();
    CHECK(pdt_test::read_file(path) == "older\n");  // not in place yet
    auto e = catch_error([&] { w.insert({0.1, 0.1, 0.1}); });
    REQUIRE(e);
    CHECK(e->code() == pdt::ErrorCode::invalid_argument);
    CHECK(std::string(e->what()).find("finish() was called") != std::string::npos);
    CHECK(catch_error([&] { w.finish(); }).has_value());  // a second finish is refused too
    w.close();
    const pdt::OpStream s = pdt::read_ops(path);
    CHECK(s.ops.size() == 3);  // the binary count was patched by finish()
    CHECK(s.insert_count() == 2);
  }
  // A writer finished and dropped without close(): nothing is put in place.
  {
    pdt::OpWriter w(d.file("dropped.ops"));
    w.insert({1, 2, 3});
    w.finish();
  }
  CHECK_FALSE(std::filesystem::exists(d.file("dropped.ops")));
}

TEST_CASE("OpWriter refuses what read_ops would reject and writes nothing for it", "[io]") {
  TempDir d;
  const std::string p = d.file("w.ops");
  pdt::OpWriter w(p, pdt::Box{{0, 0, 0}, {1, 1, 1}});
  w.insert({0.5, 0.5, 0.5});
  w.insert({0.25, 0.5, 0.5});
  w.remove(0);
  auto refused = [&](auto&& call, const char* what) {
    auto e = catch_error(call);
    REQUIRE(e);
    INFO(e->what());
    CHECK(e->code() == pdt::ErrorCode::invalid_argument);
    CHECK(std::string(e->what()).find(what) != std::string::npos);
  };
  refused([&] { w.insert({2, 0, 0}); }, "outside the box");
  refused([&] { w.insert({std::nan(""), 0, 0}); }, "NaN or infinite");
  refused([&] { w.remove(0); }, "already undone");
  refused([&] { w.remove(2); }, "not been written yet");
  CHECK(w.operations_written() == 3);
  w.remove(1);
  w.close();
  const pdt::OpStream back = pdt::read_ops(p);
  REQUIRE(back.ops.size() == 4);
  CHECK(back.insert_count() == 2);
  auto e = catch_error([&] { pdt::OpWriter bad(d.file("b.ops"), pdt::Box{{1, 0, 0}, {0, 1, 1}}); });
  REQUIRE(e);
  CHECK(e->code() == pdt::ErrorCode::invalid_argument);
  CHECK_FALSE(std::filesystem::exists(d.file("b.ops")));
}

TEST_CASE("OpWriter not closed leaves no file and an older one as it was; binary needs a seekable file", "[io]") {
  TempDir d;
  const std::string p = d.file("w.opsb");
  write_file(p, "older");
  {
    pdt::OpWriter w(p);
    w.insert({1, 2, 3});
  }  // destroyed without close(): a failed run
  CHECK(pdt_test::read_file(p) == "older");
  CHECK(d.entries() == 1);
  // Moved: the new owner closes it.
  pdt::OpWriter a(d.file("m.ops"));
  a.insert({1, 2, 3});
  pdt::OpWriter b = std::move(a);
  b.remove(0);
  b.close();
  CHECK(pdt::read_ops(d.file("m.ops")).ops.size() == 2);
  auto moved = catch_error([&] { a.insert({0, 0, 0}); });  // NOLINT: use after move, on purpose
  REQUIRE(moved);
  CHECK(std::string(moved->what()).find("moved from") != std::string::npos);
  // A moved-from reader refuses every call the same way; the new owner reads on.
  {
    pdt::OpReader r(d.file("m.ops"));
    pdt::Operation op;
    REQUIRE(r.next(op));
    pdt::OpReader r2 = std::move(r);
    const std::vector<std::function<void()>> calls = {  // NOLINT below: use after move, on purpose
        [&] { r.next(op); },              // NOLINT
        [&] { (void)r.box(); },           // NOLINT
        [&] { (void)r.announced_count(); },  // NOLINT
        [&] { (void)r.operations_read(); },  // NOLINT
        [&] { (void)r.bytes_read(); },    // NOLINT
        [&] { (void)r.path(); }};         // NOLINT
    for (const auto& call : calls) {
      auto e = catch_error(call);
      REQUIRE(e);
      CHECK(e->code() == pdt::ErrorCode::invalid_argument);
      CHECK(std::string(e->what()).find("OpReader: used after it was moved from") != std::string::npos);
    }
    CHECK(r2.operations_read() == 1);
    REQUIRE(r2.next(op));
    CHECK(op.kind == pdt::Operation::Kind::remove);
    CHECK(!r2.next(op));
  }

  // A FIFO: text is written in place; binary, whose count is patched at
  // close(), is refused before anything is opened (with no reader, opening
  // would wait for one).
  const std::string fifo = d.file("pipe.opsb");
  REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
  auto e = catch_error([&] { pdt::OpWriter w(fifo); });
  REQUIRE(e);
  CHECK(e->code() == pdt::ErrorCode::invalid_argument);
  CHECK(std::string(e->what()).find("text form") != std::string::npos);
  const std::string text_fifo = d.file("pipe.ops");
  REQUIRE(::mkfifo(text_fifo.c_str(), 0600) == 0);
  const int rd2 = ::open(text_fifo.c_str(), O_RDONLY | O_NONBLOCK);
  REQUIRE(rd2 >= 0);
  {
    pdt::OpWriter w(text_fifo);
    w.insert({1, 2, 3});
    w.close();
  }
  std::string got;
  char buf[4096];
  for (ssize_t n; (n = ::read(rd2, buf, sizeof buf)) > 0;) got.append(buf, static_cast<std::size_t>(n));
  ::close(rd2);
  CHECK(std::filesystem::is_fifo(text_fifo));
  CHECK(got.find("\ni 1 2 3\n") != std::string::npos);
}

TEST_CASE("a line over 1 MiB is refused, as the message says, wherever the buffer ends", "[io]") {
  // 1.5 MiB (found within one buffer fill past the limit) and 3 MiB.
  for (std::size_t len : {std::size_t{3} << 19, std::size_t{3} << 20}) {
    INFO(len << " bytes");
    expect_bad("i 0 0 0\n# " + std::string(len, 'x') + "\ni 1 1 1\n", 2, "line longer than 1 MiB");
  }
  // Just under the limit: a comment like any other.
  TempDir d;
  write_file(d.file("ok.ops"), "# " + std::string((std::size_t{1} << 20) - 8, 'x') + "\ni 1 1 1\n");
  CHECK(pdt::read_ops(d.file("ok.ops")).ops.size() == 1);
}

TEST_CASE("LiveInsertions agrees with a reference set and stays as small as the live insertions", "[io]") {
  using Undo = pdt::detail::LiveInsertions::Undo;
  pdt::detail::LiveInsertions live;
  std::set<std::uint64_t> ref;
  std::mt19937_64 rng(7);
  CHECK(live.remove(0) == Undo::not_made_yet);
  for (int step = 0; step < 400000; ++step) {
    const auto dice = rng() % 100;
    // Few live at a time (a refiner's stream: most insertions are undone
    // soon), with bursts that grow and shrink the set.
    const bool grow_phase = (step / 50000) % 2 == 0;
    if (ref.empty() || dice < (grow_phase ? 60u : 40u)) {
      ref.insert(live.made());
      live.insert();
    } else {
      // A live one (often the newest), an undone one, or one not made yet.
      const auto pick = rng() % 10;
      std::uint64_t k;
      if (pick < 7) {
        auto it = ref.lower_bound(rng() % live.made());
        if (it == ref.end()) it = std::prev(ref.end());
        k = *it;
      } else if (pick < 9) {
        k = rng() % live.made();
      } else {
        k = live.made() + rng() % 3;
      }
      const Undo want = k >= live.made() ? Undo::not_made_yet : ref.count(k) ? Undo::done : Undo::already_undone;
      REQUIRE(live.remove(k) == want);
      if (want == Undo::done) ref.erase(k);
    }
    REQUIRE(live.live() == ref.size());
  }
  for (std::uint64_t k = 0; k < live.made(); ++k) REQUIRE(live.is_live(k) == (ref.count(k) == 1));
  // Undo everything: nothing is live, and nothing can be undone twice.
  for (std::uint64_t k : ref) REQUIRE(live.remove(k) == Undo::done);
  CHECK(live.live() == 0);
  CHECK(live.remove(0) == Undo::already_undone);
}

TEST_CASE("reading an endless refiner-like stream keeps memory to the live insertions", "[io]") {
  // 2M insertions, each undone right after the next one: at most 2 live. The
  // set of live indices must not grow with the stream (a bit or a node per
  // insertion made would be 250 KB or 64 MB here).
  pdt::detail::LiveInsertions live;
  for (std::uint64_t k = 0; k < 2000000; ++k) {
    live.insert();
    if (k > 0) REQUIRE(live.remove(k - 1) == pdt::detail::LiveInsertions::Undo::done);
  }
  CHECK(live.live() == 1);
  CHECK(live.made() == 2000000);
  CHECK(live.table_bytes() <= 16 * sizeof(std::uint64_t));
}
