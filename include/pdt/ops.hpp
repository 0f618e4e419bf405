// SPDX-License-Identifier: MIT
#pragma once
// Operation streams: the sequence of insertions and removals a refiner makes.
//
// Text form (.ops), one item per line:
//   # comment                      (also blank lines)
//   box x0 y0 z0 x1 y1 z1          optional, at most once, before any i/r line: the domain
//   i x y z                        insert a point; the k-th 'i' line (from 0) is insertion k
//   r k                            undo insertion k (k < number of 'i' lines before it)
// Coordinates are parsed exactly (strtod); write them with 17 significant digits
// (as write_ops does) and they round-trip bit for bit.
//
// Binary form (.opsb), little-endian: magic "PDTOPS1\0", u8 has_box, 6 x f64 box,
// u64 count, then per operation: u8 kind (0 insert, 1 remove) followed by 3 x f64
// (insert) or u64 k (remove).
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "pdt/geometry.hpp"

namespace pdt {

struct Operation {
  enum class Kind : std::uint8_t { insert, remove } kind = Kind::insert;
  Point3 point;              // insert: the point
  std::uint64_t target = 0;  // remove: the insertion index undone
};

struct OpStream {
  std::optional<Box> box;
  std::vector<Operation> ops;
  std::size_t insert_count() const;
  std::size_t remove_count() const;
};

// Reads a stream one operation at a time, with the checks read_ops makes, so
// that a long stream can be replayed without holding it in memory (what it
// keeps grows with the live insertions, not with the stream). The format is
// chosen by content; throws as read_ops does, from the constructor (a bad
// header or box) or from next(). A next() that throws leaves its argument
// as it was and stops the reader there: every later next() throws the same
// error again (the file is read no further). A moved-from reader refuses
// every call (Error invalid_argument).
class OpReader {
 public:
  explicit OpReader(const std::string& path);
  ~OpReader();
  OpReader(OpReader&&) noexcept;
  OpReader& operator=(OpReader&&) noexcept;
  // The stream's box, if it declares one (known once constructed).
  const std::optional<Box>& box() const;
  // The number of operations the binary form announces; nothing for text.
  std::optional<std::uint64_t> announced_count() const;
  // The next operation, or false at the end of the stream.
  bool next(Operation& op);
  std::uint64_t operations_read() const;
  std::uint64_t bytes_read() const;  // uncompressed bytes consumed so far
  const std::string& path() const;

 private:
  struct State;
  static State& state_of(const std::unique_ptr<State>& s);  // refuses a moved-from reader
  std::unique_ptr<State> state_;
};

// Reads a stream; the format is chosen by content (binary magic) not by name,
// except that a file named *.opsb (or *.opsb.gz) without the magic, an empty
// one included, is bad_format (either form may also be gzip-compressed: one member or several back to
// back; a truncated or damaged member, or other bytes after the gzip data,
// are bad_format). Throws pdt::Error(bad_format)
// naming file and line (binary: operation index) for a malformed stream:
// unknown verb, missing or extra field, NaN/Inf or out-of-range number, box
// after operations or twice, a box with lo > hi, an inserted point outside the
// box, 'r k' naming an insertion that does not exist yet or was already undone;
// pdt::Error(io_failure) for a missing or unreadable file. So a stream it
// returns can be replayed without further checks.
OpStream read_ops(const std::string& path);
// Writes text (or binary when path ends with ".opsb"). Writes to a temporary
// file and renames, so a failure (disk full) leaves no partial file behind;
// throws pdt::Error(io_failure) with the path and the reason. A stream that
// read_ops would reject (non-finite point, point outside the box, bad 'r k')
// is refused with pdt::Error(invalid_argument) before anything is written.
void write_ops(const std::string& path, const OpStream& stream);

// Writes a stream one operation at a time, as a refiner records what it does
// while it does it, without holding the stream (write_ops writes a whole
// OpStream). Text, or binary when the path ends with ".opsb". The data goes to
// a temporary file beside the path, renamed onto it by close(): a writer
// destroyed without close() (an exception, a failed run) leaves no partial
// stream and an older file of that name as it was. A path that is not a
// regular file (a FIFO, /dev/stdout) is written in place, as every pdt writer
// does: a descriptor of this process by name (/dev/stdout, /dev/fd/N) from
// where it stands, after what was written there before and without
// truncating it (a descriptor open for reading only is refused, io_failure);
// the binary form announces its count in its header, patched by
// close(), so it is refused (invalid_argument) for a path it cannot seek in.
// Each operation is checked as read_ops would check it (finite, inside the
// box, 'remove k' of an insertion written and not undone yet) and refused
// with pdt::Error(invalid_argument), nothing written, so every file it closes
// reads back. Write errors throw io_failure (the file is then discarded). Not
// thread-safe: writers from several threads hold a mutex around each call.
class OpWriter {
 public:
  explicit OpWriter(const std::string& path, const std::optional<Box>& box = std::nullopt);
  ~OpWriter();
  OpWriter(OpWriter&&) noexcept;
  OpWriter& operator=(OpWriter&&) noexcept;  // the file this writer had open is discarded
  // Writes an insertion; returns its index k (0, 1, ... in writing order),
  // which remove(k) names.
  std::uint64_t insert(const Point3& p);
  void remove(std::uint64_t k);  // undoes insertion k
  void write(const Operation& op);
  std::uint64_t operations_written() const;
  std::uint64_t insertions_written() const;
  // Writes out what is buffered, patches the count (binary) and closes the
  // temporary file, checked, without putting it in place: what can fail is
  // done, and close() only renames. For a program with several outputs that
  // should all appear or none (a trace and a mesh): finish() each, then put
  // them in place. Writing after it is refused with invalid_argument.
  void finish();
  // finish() if not done, then renames onto the path. After close() (or a
  // failed one) every call but the destructor is refused with
  // invalid_argument.
  void close();
  const std::string& path() const;

 private:
  struct State;
  static State& state_of(const std::unique_ptr<State>& s);  // refuses a moved-from writer
  std::unique_ptr<State> state_;
};

}  // namespace pdt
