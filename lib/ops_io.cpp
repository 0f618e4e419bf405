// SPDX-License-Identifier: MIT
// Reading and writing operation streams (.ops text, .opsb binary); the
// formats are documented in include/pdt/ops.hpp.
//
// Both readers enforce the same stream invariants, so whatever read_ops
// returns can be replayed without further checks:
//   - at most one box, before any operation, with lo <= hi per axis, finite;
//   - every coordinate finite; with a box, every inserted point inside it;
//   - 'r k' only for an insertion k made earlier and not yet undone.
// write_ops checks the same invariants (invalid_argument otherwise), so it
// never writes a file read_ops would reject.
#include <sys/stat.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <exception>
#include <string>
#include <vector>

#include "io_util.hpp"
#include "live_insertions.hpp"
#include "pdt/error.hpp"
#include "pdt/ops.hpp"
#include "point_checks.hpp"

namespace pdt {

std::size_t OpStream::insert_count() const {
  std::size_t n = 0;
  for (const auto& op : ops) n += op.kind == Operation::Kind::insert;
  return n;
}

std::size_t OpStream::remove_count() const { return ops.size() - insert_count(); }

namespace {

using detail::InputFile;
using detail::NumStatus;

constexpr char kMagic[8] = {'P', 'D', 'T', 'O', 'P', 'S', '1', '\0'};
constexpr const char* kExpectedForms = "expected 'i x y z', 'r k' or 'box x0 y0 z0 x1 y1 z1'";

using detail::box_problem;
using detail::is_finite;

using LiveSet = detail::LiveInsertions;

// Why 'r k' may not come here, in a reader's words.
const char* undo_problem(LiveSet::Undo u) {
  return u == LiveSet::Undo::not_made_yet ? "names an insertion that has not been made yet"
                                          : "names an insertion that was already undone";
}

std::uint64_t load_u64(const unsigned char* p) {
  std::uint64_t v = 0;
  for (int i = 7; i >= 0; --i) v = (v << 8) | p[i];
  return v;
}
double load_f64(const unsigned char* p) { return std::bit_cast<double>(load_u64(p)); }
void store_u64(unsigned char* p, std::uint64_t v) {
  for (int i = 0; i < 8; ++i) p[i] = static_cast<unsigned char>(v >> (8 * i));
}
void store_f64(unsigned char* p, double d) { store_u64(p, std::bit_cast<std::uint64_t>(d)); }

[[noreturn]] void fail_bin(const InputFile& f, const std::string& where, const std::string& what) {
  throw Error(ErrorCode::bad_format, f.path() + ": " + where + ": " + what);
}

void parse_coords(InputFile& f, const std::string_view* fields, std::size_t count, double* out, const char* what) {
  for (std::size_t i = 0; i < count; ++i) {
    NumStatus s = detail::parse_double(fields[i], out[i]);
    if (s != NumStatus::ok)
      f.fail(std::string(what) + " field " + std::to_string(i + 1) + " " + detail::quote(fields[i]) + " " +
             detail::describe(s) + "; expected a finite decimal number");
  }
}

}  // namespace

// ---------------------------------------------------------------------------
// OpReader: one operation at a time, checked as it is read
// ---------------------------------------------------------------------------
struct OpReader::State {
  explicit State(const std::string& path) : f(path) {}
  InputFile f;
  bool binary = false;
  std::optional<Box> box;
  std::optional<std::uint64_t> count;  // binary: announced
  std::uint64_t read = 0;              // operations returned
  std::uint64_t box_line = 0;          // text: where the box was
  std::optional<Operation> pending;    // text: the first operation, read while looking for a box
  bool done = false;
  // What the first failing read threw (a malformed record, a read error, no
  // memory). The file's position and the live set are then past a record
  // that was not returned, so every later next() throws it again rather
  // than read on from there. Invariant: set => no operation after it is
  // ever returned.
  std::exception_ptr failed;
  LiveSet live;

  // Text: the next operation, or false at the end of the file.
  bool next_text(Operation& op) {
    std::string_view line;
    std::string_view fields[8];
    while (f.read_line(line)) {
      std::size_t n = detail::split_fields(detail::strip_comment(line), fields, 8);
      if (n == 0) continue;  // blank or comment
      std::string_view verb = fields[0];
      if (verb == "i") {
        if (n != 4)
          f.fail("'i' with " + std::to_string(n - 1) + " field" + (n == 2 ? "" : "s") +
                 "; expected 'i x y z' (3 coordinates)");
        double c[3];
        parse_coords(f, fields + 1, 3, c, "insertion");
        op = Operation{};
        op.kind = Operation::Kind::insert;
        op.point = {c[0], c[1], c[2]};
        if (box && !box->contains(op.point))
          f.fail("point " + detail::format_point(op.point) + " is outside the box declared on line " +
                 std::to_string(box_line) + "; expected every inserted point inside the box");
        live.insert();
        return true;
      }
      if (verb == "r") {
        if (n != 2) f.fail("'r' with " + std::to_string(n - 1) + " fields; expected 'r k' (one insertion index)");
        std::uint64_t k = 0;
        NumStatus s = detail::parse_u64(fields[1], k);
        if (s != NumStatus::ok)
          f.fail("'r' index " + detail::quote(fields[1]) + " " +
                 (s == NumStatus::out_of_range ? "is too large" : "is not a non-negative integer") +
                 "; expected 'r k' with k the number (from 0) of an earlier 'i' line");
        const std::uint64_t made = live.made();
        if (const LiveSet::Undo u = live.remove(k); u != LiveSet::Undo::done)
          f.fail("'r " + std::to_string(k) + "' " + undo_problem(u) + " (" + std::to_string(made) +
                 " insertions so far); expected the index of an earlier, not yet undone 'i' line");
        op = Operation{};
        op.kind = Operation::Kind::remove;
        op.target = k;
        return true;
      }
      if (verb == "box") {
        if (box_line != 0)
          f.fail("second 'box' line (the first is line " + std::to_string(box_line) + "); expected at most one box");
        if (read != 0 || pending)
          f.fail("'box' after operations; expected the box before any 'i' or 'r' line");
        if (n != 7)
          f.fail("'box' with " + std::to_string(n - 1) + " fields; expected 'box x0 y0 z0 x1 y1 z1' (6 numbers)");
        double c[6];
        parse_coords(f, fields + 1, 6, c, "box");
        Box b{{c[0], c[1], c[2]}, {c[3], c[4], c[5]}};
        if (const char* why = box_problem(b))
          f.fail(std::string("the box ") + why + "; expected x0 <= x1, y0 <= y1, z0 <= z1");
        box = b;
        box_line = f.line();
        continue;
      }
      {
        // A number where a verb goes: most likely a point file (x y z per
        // line) under a name that does not say so.
        double x = 0;
        const bool number = detail::parse_double(verb, x) == detail::NumStatus::ok;
        f.fail("unknown verb " + detail::quote(verb) + "; " + kExpectedForms +
               (number ? " (a file of points, x y z per line, is read as one by its extension: .xyz, .xyz.gz, .ply, "
                         ".off, .node, .smesh)"
                       : ""));
      }
    }
    return false;
  }

  void read_binary_header() {
    unsigned char head[8 + 1 + 48 + 8];
    if (f.read_bytes(head, sizeof head) != sizeof head)
      fail_bin(f, "header", "file ends inside the header; expected magic, box flag, box and count (65 bytes)");
    const unsigned char has_box = head[8];
    if (has_box > 1) fail_bin(f, "header", "box flag is " + std::to_string(has_box) + "; expected 0 or 1");
    if (has_box) {
      Box b{{load_f64(head + 9), load_f64(head + 17), load_f64(head + 25)},
            {load_f64(head + 33), load_f64(head + 41), load_f64(head + 49)}};
      if (const char* why = box_problem(b)) fail_bin(f, "header", std::string("the box ") + why);
      box = b;
    }
    count = load_u64(head + 57);
  }

  bool next_binary(Operation& op) {
    const std::uint64_t i = read;
    if (i == *count) {
      if (!f.peek(1).empty())
        fail_bin(f, "byte " + std::to_string(f.offset()),
                 "extra data after the " + std::to_string(*count) + " operations the header announces");
      return false;
    }
    const std::uint64_t at = f.offset();  // where this operation's record starts
    auto where = [&] { return "operation " + std::to_string(i) + " (byte " + std::to_string(at) + ")"; };
    unsigned char kind = 0;
    unsigned char rec[24];
    if (f.read_bytes(&kind, 1) != 1)
      fail_bin(f, where(), "file ends after " + std::to_string(i) + " of the " + std::to_string(*count) +
                               " operations the header announces");
    op = Operation{};
    if (kind == 0) {
      if (f.read_bytes(rec, 24) != 24) fail_bin(f, where(), "file ends inside an insertion record (kind + 3 x f64)");
      op.kind = Operation::Kind::insert;
      op.point = {load_f64(rec), load_f64(rec + 8), load_f64(rec + 16)};
      if (!is_finite(op.point)) fail_bin(f, where(), "insertion of a point with a NaN or infinite coordinate");
      if (box && !box->contains(op.point))
        fail_bin(f, where(), "point " + detail::format_point(op.point) + " is outside the stream's box");
      live.insert();
    } else if (kind == 1) {
      if (f.read_bytes(rec, 8) != 8) fail_bin(f, where(), "file ends inside a removal record (kind + u64)");
      op.kind = Operation::Kind::remove;
      op.target = load_u64(rec);
      const std::uint64_t made = live.made();
      if (const LiveSet::Undo u = live.remove(op.target); u != LiveSet::Undo::done)
        fail_bin(f, where(), "removal of insertion " + std::to_string(op.target) + " " + undo_problem(u) + " (" +
                                 std::to_string(made) + " insertions so far)");
    } else {
      fail_bin(f, where(), "unknown operation kind " + std::to_string(kind) + "; expected 0 (insert) or 1 (remove)");
    }
    return true;
  }
};

OpReader::OpReader(const std::string& path) : state_(std::make_unique<State>(path)) {
  State& st = *state_;
  std::string_view head = st.f.peek(sizeof kMagic);
  st.binary = head.size() == sizeof kMagic && std::memcmp(head.data(), kMagic, sizeof kMagic) == 0;
  if (st.binary) {
    st.read_binary_header();
  } else {
    // "PDTOPS" and something else than "1\0": a binary stream of another
    // version, not text with an odd first word.
    if (head.substr(0, 6) == std::string_view(kMagic, 6))
      throw Error(ErrorCode::bad_format, st.f.path() + ": a binary operation stream of another version (magic " +
                                             detail::quote(head) + "); this pdt reads version 1 (magic 'PDTOPS1\\x00')");
    // The content decides, but a file named as binary must be binary: an empty or cut
    // .opsb (a copy that failed, a download cut short) is no empty text stream.
    if (detail::ends_with_nocase(path, ".opsb") || detail::ends_with_nocase(path, ".opsb.gz"))
      throw Error(ErrorCode::bad_format,
                  st.f.path() + ": not a binary operation stream: a .opsb file starts with the magic 'PDTOPS1\\x00', " +
                      (head.empty() ? std::string("and this one is empty")
                                    : "and this one starts with " + detail::quote(head)) +
                      "; a text stream goes under another name (.ops)");
    st.f.skip_utf8_bom();
    // The box, if any, comes before the first operation: read up to it.
    Operation first;
    if (st.next_text(first)) st.pending = first;
  }
}

OpReader::~OpReader() = default;
OpReader::OpReader(OpReader&&) noexcept = default;
OpReader& OpReader::operator=(OpReader&&) noexcept = default;

OpReader::State& OpReader::state_of(const std::unique_ptr<State>& s) {
  if (!s) throw Error(ErrorCode::invalid_argument, "OpReader: used after it was moved from");
  return *s;
}

const std::optional<Box>& OpReader::box() const { return state_of(state_).box; }
std::optional<std::uint64_t> OpReader::announced_count() const { return state_of(state_).count; }
std::uint64_t OpReader::operations_read() const { return state_of(state_).read; }
std::uint64_t OpReader::bytes_read() const { return state_of(state_).f.offset(); }
const std::string& OpReader::path() const { return state_of(state_).f.path(); }

bool OpReader::next(Operation& op) {
  State& st = state_of(state_);
  if (st.failed) std::rethrow_exception(st.failed);
  if (st.done) return false;
  // Read into a local: a call that throws leaves the caller's op as it was.
  Operation got_op;
  bool got = false;
  if (st.pending) {
    got_op = *st.pending;
    st.pending.reset();
    got = true;
  } else {
    try {
      got = st.binary ? st.next_binary(got_op) : st.next_text(got_op);
    } catch (...) {
      st.failed = std::current_exception();
      throw;
    }
  }
  if (!got) {
    st.done = true;
    return false;
  }
  op = got_op;
  ++st.read;
  return true;
}

namespace {

void validate_for_write(const OpStream& s) {
  auto bad = [](const std::string& what) { throw Error(ErrorCode::invalid_argument, "write_ops: " + what); };
  if (s.box)
    if (const char* why = box_problem(*s.box)) bad(std::string("the box ") + why);
  LiveSet live;
  for (std::size_t i = 0; i < s.ops.size(); ++i) {
    const Operation& op = s.ops[i];
    if (op.kind == Operation::Kind::insert) {
      if (!is_finite(op.point)) bad("operation " + std::to_string(i) + " inserts a point with a NaN or infinite coordinate");
      if (s.box && !s.box->contains(op.point))
        bad("operation " + std::to_string(i) + " inserts " + detail::format_point(op.point) + ", outside the box");
      live.insert();
    } else if (op.kind == Operation::Kind::remove) {
      if (const LiveSet::Undo u = live.remove(op.target); u != LiveSet::Undo::done)
        bad("operation " + std::to_string(i) + " (remove " + std::to_string(op.target) + ") " + undo_problem(u));
    } else {
      bad("operation " + std::to_string(i) + " has an unknown kind");
    }
  }
}

}  // namespace

OpStream read_ops(const std::string& path) {
  OpReader reader(path);
  OpStream st;
  st.box = reader.box();
  // Reserve by the announced count up to 2^20 operations (40 MiB), and let a
  // longer stream grow the vector as it proves its length: a corrupt count
  // must not make a large allocation (under a memory limit, a bad_alloc
  // instead of the bad_format the data gives).
  if (reader.announced_count())
    st.ops.reserve(static_cast<std::size_t>(std::min<std::uint64_t>(*reader.announced_count(), 1u << 20)));
  Operation op;
  while (reader.next(op)) st.ops.push_back(op);
  return st;
}

namespace {

// The binary header: magic, box flag, box, count (at kCountOffset).
constexpr std::size_t kHeadSize = 8 + 1 + 48 + 8, kCountOffset = 57;
void put_binary_head(detail::OutputFile& out, const std::optional<Box>& box, std::uint64_t count) {
  unsigned char head[kHeadSize] = {};
  std::memcpy(head, kMagic, 8);
  head[8] = box ? 1 : 0;
  if (box) {
    const double v[6] = {box->lo.x, box->lo.y, box->lo.z, box->hi.x, box->hi.y, box->hi.z};
    for (int i = 0; i < 6; ++i) store_f64(head + 9 + 8 * i, v[i]);
  }
  store_u64(head + kCountOffset, count);
  out.out().put(head, sizeof head);
}

void put_binary_op(detail::OutputFile& out, const Operation& op) {
  unsigned char rec[25];
  if (op.kind == Operation::Kind::insert) {
    rec[0] = 0;
    store_f64(rec + 1, op.point.x);
    store_f64(rec + 9, op.point.y);
    store_f64(rec + 17, op.point.z);
    out.out().put(rec, 25);
  } else {
    rec[0] = 1;
    store_u64(rec + 1, op.target);
    out.out().put(rec, 9);
  }
}

// `line` is scratch (its capacity reused).
void put_text_box(detail::OutputFile& out, const Box& b, std::string& line) {
  line = "box";
  for (double d : {b.lo.x, b.lo.y, b.lo.z, b.hi.x, b.hi.y, b.hi.z}) {
    line += ' ';
    detail::append_double(line, d);
  }
  line += '\n';
  out.put(line);
}

void put_text_op(detail::OutputFile& out, const Operation& op, std::string& line) {
  line.clear();
  if (op.kind == Operation::Kind::insert) {
    line += "i ";
    detail::append_double(line, op.point.x);
    line += ' ';
    detail::append_double(line, op.point.y);
    line += ' ';
    detail::append_double(line, op.point.z);
  } else {
    line += "r ";
    detail::append_uint(line, op.target);
  }
  line += '\n';
  out.put(line);
}

}  // namespace

void write_ops(const std::string& path, const OpStream& stream) {
  if (detail::names_no_file(path)) detail::refuse_nameless(path, "write_ops", "stream.ops");
  validate_for_write(stream);
  detail::OutputFile out(path);
  if (detail::ends_with_nocase(path, ".opsb")) {
    put_binary_head(out, stream.box, stream.ops.size());
    for (const Operation& op : stream.ops) put_binary_op(out, op);
  } else {
    std::string line;
    line.reserve(128);
    line = "# pdt operation stream: ";
    detail::append_uint(line, stream.insert_count());
    line += " insertions, ";
    detail::append_uint(line, stream.remove_count());
    line += " removals\n";
    out.put(line);
    if (stream.box) put_text_box(out, *stream.box, line);
    for (const Operation& op : stream.ops) put_text_op(out, op, line);
  }
  out.commit();
}

// ---- OpWriter ---------------------------------------------------------------
// Invariant: `live` holds exactly the insertions written and not undone, so
// every operation written passes read_ops's checks; the state is updated before the bytes are put, and `out` is null
// once closed (or after a failed write), when only destruction is allowed.
struct OpWriter::State {
  std::string path;
  std::optional<Box> box;
  bool binary = false;
  std::unique_ptr<detail::OutputFile> out;
  LiveSet live;  // insertion k of the stream is the k-th written
  std::uint64_t written = 0;
  std::string line;
  bool finished = false;  // finish() ran: everything is in the temporary, only close() is left

  detail::OutputFile& open(const char* call) {
    if (!out)
      throw Error(ErrorCode::invalid_argument,
                  std::string("OpWriter::") + call + ": '" + path + "' is closed (or a write to it failed)");
    return *out;
  }
  // open(), for a call that writes: refused after finish().
  detail::OutputFile& open_to_write(const char* call) {
    detail::OutputFile& o = open(call);
    if (finished)
      throw Error(ErrorCode::invalid_argument, std::string("OpWriter::") + call + ": '" + path +
                                                   "' is finished (finish() was called): only close() is left");
    return o;
  }
  // A write error discards the file (OutputFile did): the writer is closed.
  template <class F>
  void guarded(F&& f) {
    try {
      f();
    } catch (...) {
      out.reset();
      throw;
    }
  }
};

OpWriter::State& OpWriter::state_of(const std::unique_ptr<State>& s) {
  if (!s) throw Error(ErrorCode::invalid_argument, "OpWriter: used after it was moved from");
  return *s;
}

OpWriter::OpWriter(const std::string& path, const std::optional<Box>& box) : state_(std::make_unique<State>()) {
  if (detail::names_no_file(path)) detail::refuse_nameless(path, "OpWriter", "stream.ops");
  State& st = *state_;
  st.path = path;
  st.box = box;
  st.binary = detail::ends_with_nocase(path, ".opsb");
  if (box)
    if (const char* why = box_problem(*box))
      throw Error(ErrorCode::invalid_argument, "OpWriter: the box " + std::string(why));
  auto cannot_seek = [&] {
    return Error(ErrorCode::invalid_argument,
                 "OpWriter: '" + path + "' cannot be sought in, and the binary form (.opsb) patches its count into "
                 "its header when closed; write the text form (.ops) to a pipe or device");
  };
  // Before opening: opening a FIFO for writing waits for a reader.
  struct stat target;
  if (st.binary && ::stat(path.c_str(), &target) == 0 && !S_ISREG(target.st_mode) && !S_ISDIR(target.st_mode))
    throw cannot_seek();
  st.out = std::make_unique<detail::OutputFile>(path);
  if (st.binary && !st.out->seekable()) throw cannot_seek();
  st.line.reserve(128);
  st.guarded([&] {
    if (st.binary) {
      put_binary_head(*st.out, box, 0);
    } else {
      st.out->put("# pdt operation stream, written one operation at a time\n");
      if (box) put_text_box(*st.out, *box, st.line);
    }
  });
}

OpWriter::~OpWriter() = default;
OpWriter::OpWriter(OpWriter&&) noexcept = default;
OpWriter& OpWriter::operator=(OpWriter&&) noexcept = default;

void OpWriter::write(const Operation& op) {
  State& st = state_of(state_);
  detail::OutputFile& out = st.open_to_write("write");
  if (op.kind == Operation::Kind::insert) {
    if (!is_finite(op.point))
      throw Error(ErrorCode::invalid_argument, "OpWriter: insertion of a point with a NaN or infinite coordinate");
    if (st.box && !st.box->contains(op.point))
      throw Error(ErrorCode::invalid_argument,
                  "OpWriter: insertion of " + detail::format_point(op.point) + ", outside the box");
    st.live.insert();  // may throw bad_alloc: nothing changed yet
  } else if (op.kind == Operation::Kind::remove) {
    if (const LiveSet::Undo u = st.live.remove(op.target); u != LiveSet::Undo::done)
      throw Error(ErrorCode::invalid_argument,
                  "OpWriter: remove " + std::to_string(op.target) + " names an insertion that " +
                      (u == LiveSet::Undo::not_made_yet ? "has not been written yet" : "was already undone"));
  } else {
    throw Error(ErrorCode::invalid_argument, "OpWriter: an operation of unknown kind");
  }
  ++st.written;
  st.guarded([&] {  // a failure here closes the writer: the state above no longer matters
    if (st.binary)
      put_binary_op(out, op);
    else
      put_text_op(out, op, st.line);
  });
}

std::uint64_t OpWriter::insert(const Point3& p) {
  Operation op;
  op.kind = Operation::Kind::insert;
  op.point = p;
  write(op);
  return state_->live.made() - 1;
}

void OpWriter::remove(std::uint64_t k) {
  Operation op;
  op.kind = Operation::Kind::remove;
  op.target = k;
  write(op);
}

std::uint64_t OpWriter::operations_written() const { return state_of(state_).written; }
std::uint64_t OpWriter::insertions_written() const { return state_of(state_).live.made(); }
const std::string& OpWriter::path() const { return state_of(state_).path; }

void OpWriter::finish() {
  State& st = state_of(state_);
  detail::OutputFile& out = st.open_to_write("finish");
  st.guarded([&] {
    if (st.binary) {
      unsigned char count[8];
      store_u64(count, st.written);
      out.overwrite(kCountOffset, count, sizeof count);
    }
    out.finish();
  });
  st.finished = true;
}

void OpWriter::close() {
  State& st = state_of(state_);
  detail::OutputFile& out = st.open("close");
  if (!st.finished) finish();
  st.guarded([&] { out.commit(); });
  st.out.reset();
}

}  // namespace pdt
