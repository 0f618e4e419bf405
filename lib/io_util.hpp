// SPDX-License-Identifier: MIT
#pragma once
// Internal I/O helpers shared by the readers and writers (ops_io.cpp,
// mesh_io.cpp, the tool): exact number parsing, a buffered line/byte reader
// (plain or gzip files alike, through zlib), and a checked writer that goes
// through a temporary file and a rename so a failed write leaves nothing behind.
//
// Errors: every failure is a pdt::Error. Reading: io_failure for a file that
// cannot be opened or read, bad_format for content. Writing: io_failure whose
// message names the path and the system's reason (strerror), e.g.
// "cannot write 'out.ops': No space left on device".
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "pdt/error.hpp"

namespace pdt::detail {

// ---- numbers -------------------------------------------------------------

enum class NumStatus { ok, not_a_number, out_of_range, non_finite };

// Parses the whole token as a decimal double, exactly (correctly rounded, as
// strtod, but locale independent). A leading '+' is allowed. NaN and infinities
// are rejected (non_finite); so are values that overflow, and nonzero values
// that underflow to zero (out_of_range). Subnormals are accepted.
NumStatus parse_double(std::string_view token, double& out);
// Parses the whole token as an unsigned decimal integer (no sign, no fraction).
NumStatus parse_u64(std::string_view token, std::uint64_t& out);
const char* describe(NumStatus s);  // "is not a number", ...

// Splits a line into blank-separated tokens (space, tab, \r, \v, \f). Stores
// at most max of them in out and returns how many there are in all (so a
// caller can tell "too many fields" without storing them).
std::size_t split_fields(std::string_view line, std::string_view* out, std::size_t max);
// The part of line before the first '#'.
std::string_view strip_comment(std::string_view line);

// s in single quotes for an error message: non-printable bytes as \xNN, cut
// after 40 characters (a binary file read as text must not garble a terminal).
std::string quote(std::string_view s);

// Appends a double with 17 significant digits ("%.17g", but locale
// independent): reading it back with parse_double gives the same bits.
void append_double(std::string& out, double v);
void append_uint(std::string& out, std::uint64_t v);

// "1 vertex", "2 vertices": n and the noun that agrees with it, for messages.
std::string counted(std::uint64_t n, std::string_view one, std::string_view many);

// ---- reading ---------------------------------------------------------------

// Buffered sequential reader over a file, transparently gunzipping gzip data.
// A file that starts with gzip's magic bytes (1f 8b) is read as one or more
// gzip members back to back (what `cat a.gz b.gz` makes, as gzip -d reads
// it); anything else after a member's end (plain bytes appended to a gzip
// file) is refused as bad_format, as are a truncated member and corrupt data:
// what is read is the whole file or an error, never a silent prefix. Any
// other file is read as it is. Lines end at '\n'; a trailing '\r' is
// dropped, and any other '\r' in a line fails it (lines ended by CR alone).
// Line views stay valid until the next read call.
class InputFile {
 public:
  // Throws io_failure ("cannot open 'path': No such file or directory").
  explicit InputFile(const std::string& path);
  ~InputFile();
  InputFile(const InputFile&) = delete;
  InputFile& operator=(const InputFile&) = delete;

  // Next line, or false at end of file. Counts lines (see line()).
  bool read_line(std::string_view& line);
  // Up to n bytes into dst; returns how many (fewer only at end of file).
  std::size_t read_bytes(void* dst, std::size_t n);
  // Up to n bytes from the current position without consuming them.
  std::string_view peek(std::size_t n);
  // At the start of a text file: consumes a UTF-8 byte order mark (EF BB BF),
  // which some editors write, if there is one.
  void skip_utf8_bom();

  const std::string& path() const { return path_; }
  std::uint64_t line() const { return line_; }  // number of the last line read (1-based)
  std::uint64_t offset() const { return consumed_; }  // bytes (uncompressed) consumed
  // "path:line: " + what, as a bad_format error ("path: " + what before the first line).
  [[noreturn]] void fail(const std::string& what) const;
  [[noreturn]] void fail_at_line(std::uint64_t line, const std::string& what) const;

 private:
  bool fill();  // reads more into the buffer; false when nothing more
  void refuse_bare_cr(std::string_view line) const;  // fails the line if it holds a '\r'
  // Up to n raw (on-disk) bytes into dst; 0 only at the end of the file.
  std::size_t read_raw(char* dst, std::size_t n);
  std::size_t inflate_into(char* dst, std::size_t n);  // gzip: up to n decompressed bytes; 0 at the end
  struct Gunzip;                                       // zlib's state (io_util.cpp)
  int fd_ = -1;
  std::unique_ptr<Gunzip> gunzip_;  // null: a plain file
  std::string path_;
  std::vector<char> buf_;
  std::size_t pos_ = 0, end_ = 0;
  bool eof_ = false;
  bool detected_ = false;  // the first bytes were read: gunzip_ set for a gzip file
  std::uint64_t line_ = 0;
  std::uint64_t consumed_ = 0;
};

// ---- writing ---------------------------------------------------------------

// Buffered writer on a file descriptor that checks every write(2). The name is
// what error messages report. It does not own the descriptor.
class FdWriter {
 public:
  FdWriter(int fd, std::string name);
  FdWriter(const FdWriter&) = delete;
  FdWriter& operator=(const FdWriter&) = delete;
  void put(std::string_view s);
  void put(const void* data, std::size_t n) { put(std::string_view(static_cast<const char*>(data), n)); }
  // Writes out the buffer; throws io_failure ("cannot write 'name': <strerror>").
  void flush();
  const std::string& name() const { return name_; }

 private:
  int fd_;
  std::string name_;
  std::string buf_;
};

// A file written atomically: the data goes to a temporary file beside the
// target (same directory, so rename is atomic) and commit() renames it over the
// target. Until commit() succeeds nothing exists under the target name; if any
// step fails, or the object is destroyed without commit(), the temporary file
// is removed. Errors are io_failure naming the target path.
// The target is what the path names: through a symbolic link, the file it
// points to (the link stays), made there if it is not there yet; a device,
// FIFO or socket (/dev/null, a pipe), or a descriptor by name (/dev/stdout,
// /dev/fd/N, /proc/...), is written in place, since no rename could stand in
// for it, and so is the file behind a looping link or a chain of links to a
// missing file. Those direct writes cannot be undone. An existing target is
// replaced only if this process may write it, and the new file keeps its
// permissions. A descriptor of this
// process by name (/dev/stdout, /dev/fd/1) is written through a copy of it,
// from where it stands: after what the process wrote there before, without
// truncating it (the shell's > did, or >> appends).
class OutputFile {
 public:
  explicit OutputFile(const std::string& path);
  ~OutputFile();
  OutputFile(const OutputFile&) = delete;
  OutputFile& operator=(const OutputFile&) = delete;
  FdWriter& out() { return *writer_; }
  void put(std::string_view s) { writer_->put(s); }
  // Flushes and closes the temporary file, checked. Idempotent. Lets a writer
  // of several files (TetGen .node + .ele) finish all before renaming any.
  void finish();
  // finish(), then renames onto the target. After this the object is inert.
  void commit();
  // Whether overwrite() can go back in the file (a temporary or regular
  // file; not a FIFO, socket or terminal). Before finish().
  bool seekable() const;
  // Flushes, then writes n bytes at byte offset `at` of what was written
  // (a count patched into a header). Before finish(); io_failure on error.
  void overwrite(std::uint64_t at, const void* data, std::size_t n);
  const std::string& path() const { return path_; }

 private:
  void discard() noexcept;
  std::string path_, target_, temp_;  // target_: the file renamed onto (symbolic links resolved)
  bool direct_ = false;               // writing the target itself (not a regular file)
  int fd_ = -1;
  FdWriter* writer_ = nullptr;
  bool finished_ = false, committed_ = false;
  int temp_slot_ = -1;  // temp_'s slot for unlink_temporaries, or -1
};

[[noreturn]] void throw_io_error(const std::string& what, const std::string& path, int err);

// A path that names no file: "" or a folder ("out/"). Writers refuse it before
// writing anything, with refuse_nameless's invalid_argument (who: the function;
// example: a name to give instead).
bool names_no_file(std::string_view path);
[[noreturn]] void refuse_nameless(const std::string& path, const char* who, const char* example);

// Unlinks the temporary files of the OutputFiles alive now (up to 16 at a
// time are tracked). Async-signal-safe: the pdt tool calls it from its
// SIGINT / SIGTERM / SIGHUP handler, so that an interrupted run leaves no
// partial file behind (a library never installs signal handlers itself).
void unlink_temporaries() noexcept;

// Lowercase file name suffix tests.
bool ends_with_nocase(std::string_view s, std::string_view suffix);

}  // namespace pdt::detail
