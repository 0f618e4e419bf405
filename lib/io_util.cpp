// SPDX-License-Identifier: MIT
// Internal I/O helpers; see io_util.hpp for the contracts.
#include "io_util.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <atomic>
#include <cassert>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iterator>
#include <memory>
#include <new>
#include <optional>
#include <string_view>

namespace pdt::detail {

// ---- numbers -------------------------------------------------------------

NumStatus parse_double(std::string_view token, double& out) {
  const char* first = token.data();
  const char* last = first + token.size();
  if (first != last && *first == '+') {
    ++first;
    // "+-1" or "+" alone is not a number.
    if (first == last || *first == '-' || *first == '+') return NumStatus::not_a_number;
  }
  if (first == last) return NumStatus::not_a_number;
  // from_chars is exact (correctly rounded) and ignores the locale, unlike
  // strtod under a locale with a decimal comma.
  double v = 0;
  auto [ptr, ec] = std::from_chars(first, last, v, std::chars_format::general);
  if (ec == std::errc::result_out_of_range) return NumStatus::out_of_range;
  if (ec != std::errc() || ptr != last) return NumStatus::not_a_number;
  if (!std::isfinite(v)) return NumStatus::non_finite;  // "nan", "inf", "infinity"
  out = v;
  return NumStatus::ok;
}

NumStatus parse_u64(std::string_view token, std::uint64_t& out) {
  if (token.empty() || token[0] < '0' || token[0] > '9') return NumStatus::not_a_number;
  std::uint64_t v = 0;
  auto [ptr, ec] = std::from_chars(token.data(), token.data() + token.size(), v, 10);
  if (ec == std::errc::result_out_of_range) return NumStatus::out_of_range;
  if (ec != std::errc() || ptr != token.data() + token.size()) return NumStatus::not_a_number;
  out = v;
  return NumStatus::ok;
}

const char* describe(NumStatus s) {
  switch (s) {
    case NumStatus::ok: return "is fine";
    case NumStatus::not_a_number: return "is not a number";
    case NumStatus::out_of_range: return "is out of the range of a double";
    case NumStatus::non_finite: return "is not finite (NaN or infinity)";
  }
  return "is invalid";
}

static inline bool is_blank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }

std::size_t split_fields(std::string_view line, std::string_view* out, std::size_t max) {
  std::size_t count = 0, i = 0, n = line.size();
  while (true) {
    while (i < n && is_blank(line[i])) ++i;
    if (i == n) break;
    std::size_t start = i;
    while (i < n && !is_blank(line[i])) ++i;
    if (count < max) out[count] = line.substr(start, i - start);
    ++count;
  }
  return count;
}

std::string_view strip_comment(std::string_view line) {
  auto p = line.find('#');
  return p == std::string_view::npos ? line : line.substr(0, p);
}

std::string quote(std::string_view s) {
  std::string out = "'";
  const std::size_t n = std::min<std::size_t>(s.size(), 40);
  for (std::size_t i = 0; i < n; ++i) {
    const auto c = static_cast<unsigned char>(s[i]);
    if (c >= 0x20 && c < 0x7F) {
      out += static_cast<char>(c);
    } else {
      static const char hex[] = "0123456789abcdef";
      out += "\\x";
      out += hex[c >> 4];
      out += hex[c & 15];
    }
  }
  if (n < s.size()) out += "...";
  out += "'";
  return out;
}

void append_double(std::string& out, double v) {
  char buf[40];
  // Same output as printf("%.17g"), without the locale's decimal point.
  auto [ptr, ec] = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::general, 17);
  (void)ec;  // 40 characters always suffice for 17 digits, sign and exponent
  out.append(buf, ptr);
}

std::string counted(std::uint64_t n, std::string_view one, std::string_view many) {
  std::string s = std::to_string(n);
  s += ' ';
  s += n == 1 ? one : many;
  return s;
}

void append_uint(std::string& out, std::uint64_t v) {
  char buf[24];
  auto [ptr, ec] = std::to_chars(buf, buf + sizeof buf, v);
  (void)ec;
  out.append(buf, ptr);
}

bool ends_with_nocase(std::string_view s, std::string_view suffix) {
  if (s.size() < suffix.size()) return false;
  s = s.substr(s.size() - suffix.size());
  for (std::size_t i = 0; i < s.size(); ++i) {
    char a = s[i], b = suffix[i];
    if (a >= 'A' && a <= 'Z') a = static_cast<char>(a - 'A' + 'a');
    if (b >= 'A' && b <= 'Z') b = static_cast<char>(b - 'A' + 'a');
    if (a != b) return false;
  }
  return true;
}

void throw_io_error(const std::string& what, const std::string& path, int err) {
  throw Error(ErrorCode::io_failure, what + " '" + path + "': " + std::strerror(err));
}

// ---- InputFile -----------------------------------------------------------

namespace {
constexpr std::size_t kReadChunk = 1 << 20;
// A text line longer than this is not a line of any format pdt reads: it is
// most likely binary data read as text, and growing the buffer without bound
// would only exhaust memory before reporting it.
constexpr std::size_t kMaxLine = 1 << 20;
}  // namespace

namespace {

// The descriptor of this process that a path names (/dev/stdin, /dev/stdout,
// /dev/stderr, /dev/fd/N, /proc/self/fd/N) when it is open; -1 for any other
// path.
int own_descriptor(const std::string& path) {
  int fd = -1;
  if (path == "/dev/stdin") fd = 0;
  else if (path == "/dev/stdout") fd = 1;
  else if (path == "/dev/stderr") fd = 2;
  else {
    std::string_view digits;
    for (std::string_view prefix : {"/dev/fd/", "/proc/self/fd/"})
      if (path.rfind(prefix, 0) == 0) digits = std::string_view(path).substr(prefix.size());
    // As the kernel spells them: no sign, no leading zero (/dev/fd/01 is no name).
    if (digits.empty() || (digits[0] == '0' && digits.size() > 1)) return -1;
    const auto [end, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), fd);
    if (ec != std::errc{} || end != digits.data() + digits.size()) return -1;
  }
  return ::fcntl(fd, F_GETFD) == -1 ? -1 : fd;
}

}  // namespace

// zlib's inflate state over gzip members. Invariant: in == [0, in.size()) is
// the raw read buffer; zs.next_in/avail_in the part of it not yet inflated;
// raw_read counts the file's bytes read so far, so raw_read - zs.avail_in is
// the file offset of the next byte to inflate. in_member: a member has begun
// (its header's first bytes seen) and not ended.
struct InputFile::Gunzip {
  z_stream zs{};
  std::vector<unsigned char> in = std::vector<unsigned char>(1 << 17);
  std::uint64_t raw_read = 0;
  bool in_member = false;
  Gunzip() {
    if (inflateInit2(&zs, 16 + MAX_WBITS) != Z_OK) throw std::bad_alloc();  // 16: gzip framing only
  }
  ~Gunzip() { inflateEnd(&zs); }
  Gunzip(const Gunzip&) = delete;
  Gunzip& operator=(const Gunzip&) = delete;
};

InputFile::InputFile(const std::string& path) : path_(path) {
  // A descriptor of this process (/dev/stdin) is opened anew, so a file
  // behind it reads from its start each time (a stream without a box is read
  // twice); one that cannot be read (open for writing only, or a bare O_PATH
  // place holder) is refused, as reading it would fail (opening the name
  // again would read whatever it names instead).
  if (const int own = own_descriptor(path); own >= 0) {
    const int flags = ::fcntl(own, F_GETFL);
    if ((flags & O_ACCMODE) == O_WRONLY || (flags & O_PATH) != 0)
      throw Error(ErrorCode::io_failure, "cannot read '" + path + "': the descriptor is not open for reading");
  }
  fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd_ < 0) throw_io_error("cannot open", path, errno);
  struct stat st;
  const int err = ::fstat(fd_, &st) != 0 ? errno : S_ISDIR(st.st_mode) ? EISDIR : 0;
  if (err != 0) {
    ::close(fd_);
    throw_io_error(err == EISDIR ? "cannot read" : "cannot open", path, err);
  }
  try {
    buf_.resize(kReadChunk);
  } catch (...) {
    ::close(fd_);
    throw;
  }
}

InputFile::~InputFile() {
  if (fd_ >= 0) ::close(fd_);
}

std::size_t InputFile::read_raw(char* dst, std::size_t n) {
  while (true) {
    const ssize_t got = ::read(fd_, dst, n);
    if (got >= 0) return static_cast<std::size_t>(got);
    if (errno != EINTR) throw_io_error("cannot read", path_, errno);
  }
}

std::size_t InputFile::inflate_into(char* dst, std::size_t n) {
  Gunzip& g = *gunzip_;
  z_stream& zs = g.zs;
  n = std::min<std::size_t>(n, 1u << 30);
  zs.next_out = reinterpret_cast<unsigned char*>(dst);
  zs.avail_out = static_cast<uInt>(n);
  // Reads more raw bytes behind the unconsumed ones; false at the end of the file.
  auto read_more = [&] {
    if (zs.avail_in > 0 && zs.next_in != g.in.data()) std::memmove(g.in.data(), zs.next_in, zs.avail_in);
    zs.next_in = g.in.data();
    const std::size_t got =
        read_raw(reinterpret_cast<char*>(g.in.data()) + zs.avail_in, g.in.size() - zs.avail_in);
    g.raw_read += got;
    zs.avail_in += static_cast<uInt>(got);
    return got > 0;
  };
  while (zs.avail_out == n) {
    if (!g.in_member) {
      // Between members: the end of the file, or the next member's magic.
      while (zs.avail_in < 2 && read_more()) {
      }
      if (zs.avail_in == 0) break;
      if (zs.avail_in < 2 || zs.next_in[0] != 0x1f || zs.next_in[1] != 0x8b)
        throw Error(ErrorCode::bad_format,
                    path_ + ": other data follows the gzip data (from byte " + std::to_string(g.raw_read - zs.avail_in) +
                        " of the file; was something appended to a .gz file?): decompress the file, or cut it after "
                        "the gzip data");
      if (inflateReset(&zs) != Z_OK) throw std::bad_alloc();
      g.in_member = true;
    }
    if (zs.avail_in == 0 && !read_more())
      throw Error(ErrorCode::bad_format, path_ + ": truncated compressed data (the gzip data ends early)");
    const int r = inflate(&zs, Z_NO_FLUSH);
    if (r == Z_STREAM_END) {
      g.in_member = false;
    } else if (r == Z_MEM_ERROR) {
      throw std::bad_alloc();
    } else if (r != Z_OK && !(r == Z_BUF_ERROR && zs.avail_in == 0)) {
      throw Error(ErrorCode::bad_format, path_ + ": corrupt compressed data (" +
                                             (zs.msg != nullptr ? std::string(zs.msg) : std::string("zlib error ") + std::to_string(r)) +
                                             ")");
    }
  }
  return n - zs.avail_out;
}

bool InputFile::fill() {
  if (eof_) return false;
  // Keep the unconsumed tail at the front; grow when the buffer is full of it.
  if (pos_ > 0) {
    std::memmove(buf_.data(), buf_.data() + pos_, end_ - pos_);
    end_ -= pos_;
    pos_ = 0;
  }
  if (end_ == buf_.size()) buf_.resize(buf_.size() * 2);
  if (!detected_) {
    // The first bytes say which: gzip's magic, or a plain file. The read goes
    // into the buffer, where a plain file's bytes stay; a gzip file's move to
    // the inflater's input.
    std::size_t got = 0;
    while (got < 2) {
      const std::size_t more = read_raw(buf_.data() + got, buf_.size() - got);
      if (more == 0) break;
      got += more;
    }
    detected_ = true;
    if (got >= 2 && static_cast<unsigned char>(buf_[0]) == 0x1f && static_cast<unsigned char>(buf_[1]) == 0x8b) {
      gunzip_ = std::make_unique<Gunzip>();
      Gunzip& g = *gunzip_;
      if (g.in.size() < got) g.in.resize(got);
      std::memcpy(g.in.data(), buf_.data(), got);
      g.zs.next_in = g.in.data();
      g.zs.avail_in = static_cast<uInt>(got);
      g.raw_read = got;
    } else {
      end_ = got;
      if (got == 0) eof_ = true;
      return got > 0;
    }
  }
  const std::size_t got = gunzip_ ? inflate_into(buf_.data() + end_, buf_.size() - end_)
                                  : read_raw(buf_.data() + end_, buf_.size() - end_);
  if (got == 0) {
    eof_ = true;
    return false;
  }
  end_ += got;
  return true;
}

// A CR that does not end its line: a file whose lines end in CR alone (classic
// Mac OS) reads as one long line, whose fields a reader that ignores extra
// columns (.xyz) would take for one point.
void InputFile::refuse_bare_cr(std::string_view line) const {
  if (std::memchr(line.data(), '\r', line.size()) != nullptr)
    fail("a carriage return (\\r) inside the line: pdt reads lines that end in LF or CR LF, and this "
         "file seems to end them in CR alone (classic Mac OS); convert it first, e.g. tr '\\r' '\\n'");
}

bool InputFile::read_line(std::string_view& line) {
  auto too_long = [&] {
    ++line_;
    fail("line longer than 1 MiB; this is not a text file of the expected format");
  };
  std::size_t scanned = pos_;
  while (true) {
    const char* base = buf_.data();
    const void* nl = std::memchr(base + scanned, '\n', end_ - scanned);
    if (nl != nullptr) {
      std::size_t e = static_cast<std::size_t>(static_cast<const char*>(nl) - base);
      std::size_t len = e - pos_;
      if (len > kMaxLine) too_long();  // found within the last fill, which may read past the limit
      if (len > 0 && base[e - 1] == '\r') --len;
      line = std::string_view(base + pos_, len);
      consumed_ += e + 1 - pos_;
      pos_ = e + 1;
      ++line_;
      refuse_bare_cr(line);
      return true;
    }
    std::size_t pending = end_ - pos_;
    if (pending > kMaxLine) too_long();
    if (!fill()) {
      if (end_ == pos_) return false;
      // Last line without a newline.
      std::size_t len = end_ - pos_;
      if (len > kMaxLine) too_long();
      if (buf_[end_ - 1] == '\r') --len;
      line = std::string_view(buf_.data() + pos_, len);
      consumed_ += end_ - pos_;
      pos_ = end_;
      ++line_;
      refuse_bare_cr(line);
      return true;
    }
    scanned = pos_ + pending;  // fill() moved the tail to the front
  }
}

std::size_t InputFile::read_bytes(void* dst, std::size_t n) {
  auto out = static_cast<char*>(dst);
  std::size_t done = 0;
  while (done < n) {
    if (pos_ == end_ && !fill()) break;
    std::size_t take = std::min(n - done, end_ - pos_);
    std::memcpy(out + done, buf_.data() + pos_, take);
    pos_ += take;
    done += take;
  }
  consumed_ += done;
  return done;
}

std::string_view InputFile::peek(std::size_t n) {
  while (end_ - pos_ < n && fill()) {
  }
  return std::string_view(buf_.data() + pos_, std::min(n, end_ - pos_));
}

void InputFile::skip_utf8_bom() {
  assert(consumed_ == 0 && line_ == 0);
  if (peek(3) == std::string_view("\xEF\xBB\xBF", 3)) {
    pos_ += 3;
    consumed_ += 3;
  }
}

void InputFile::fail(const std::string& what) const { fail_at_line(line_, what); }

void InputFile::fail_at_line(std::uint64_t line, const std::string& what) const {
  // Line 0: nothing was read (an empty file); the path alone says where.
  throw Error(ErrorCode::bad_format, path_ + (line == 0 ? std::string() : ":" + std::to_string(line)) + ": " + what);
}

bool names_no_file(std::string_view path) { return path.empty() || path.back() == '/'; }

void refuse_nameless(const std::string& path, const char* who, const char* example) {
  throw Error(ErrorCode::invalid_argument, std::string(who) + ": '" + path + "' names no file (give it a name such as " +
                                               example + "); nothing was written");
}

// ---- FdWriter ----------------------------------------------------------------

namespace {
constexpr std::size_t kWriteChunk = 1 << 20;
}

FdWriter::FdWriter(int fd, std::string name) : fd_(fd), name_(std::move(name)) { buf_.reserve(kWriteChunk); }

void FdWriter::put(std::string_view s) {
  if (buf_.size() + s.size() > kWriteChunk) {
    flush();
    if (s.size() > kWriteChunk) {  // large block: no point copying it through the buffer
      buf_.assign(s);
      flush();
      return;
    }
  }
  buf_.append(s);
}

void FdWriter::flush() {
  const char* p = buf_.data();
  std::size_t left = buf_.size();
  while (left > 0) {
    ssize_t w = ::write(fd_, p, left);
    if (w < 0) {
      if (errno == EINTR) continue;
      int err = errno;
      buf_.clear();
      throw_io_error("cannot write", name_, err);
    }
    if (w == 0) {  // should not happen for regular files; do not loop forever
      buf_.clear();
      throw_io_error("cannot write", name_, EIO);
    }
    p += w;
    left -= static_cast<std::size_t>(w);
  }
  buf_.clear();
}

// ---- OutputFile -------------------------------------------------------------

namespace {

// The temporaries unlink_temporaries() removes: a slot is free (0), being
// filled (1), holds a path (2), or is being read by unlink_temporaries (3,
// then it stays: the process is going). Only the OutputFile that filled a
// slot empties it (2 -> 0), after its temporary is renamed or unlinked, so a
// slot is never refilled while it is read.
struct TempSlot {
  std::atomic<int> state{0};
  char path[4096];
};
TempSlot temp_slots[16];

int track_temporary(const std::string& temp) noexcept {
  if (temp.size() >= sizeof temp_slots[0].path) return -1;
  for (int i = 0; i < static_cast<int>(std::size(temp_slots)); ++i) {
    int expected = 0;
    if (temp_slots[i].state.compare_exchange_strong(expected, 1, std::memory_order_acquire)) {
      std::memcpy(temp_slots[i].path, temp.c_str(), temp.size() + 1);
      temp_slots[i].state.store(2, std::memory_order_release);
      return i;
    }
  }
  return -1;  // not tracked: an interrupted run may leave this one
}

void untrack_temporary(int slot) noexcept {
  if (slot < 0) return;
  int expected = 2;
  temp_slots[slot].state.compare_exchange_strong(expected, 0, std::memory_order_release);
}

}  // namespace

void unlink_temporaries() noexcept {
  for (TempSlot& s : temp_slots) {
    int expected = 2;
    if (s.state.compare_exchange_strong(expected, 3, std::memory_order_acquire)) ::unlink(s.path);
  }
}

OutputFile::OutputFile(const std::string& path) : path_(path), target_(path) {
  // A descriptor this process holds (pdt gen --out /dev/stdout > file): its
  // copy writes where the descriptor stands, as the shell set it up (> has
  // truncated, >> appends). Opening the name again would start a second
  // file offset at 0 and truncate, so the stream and whatever else goes to
  // that descriptor would overwrite each other.
  if (const int own = own_descriptor(path); own >= 0) {
    // Refused now, before anything is written, as opening the name would be.
    struct stat st;
    if (::fstat(own, &st) == 0 && S_ISDIR(st.st_mode)) throw_io_error("cannot write", path, EISDIR);
    if (const int flags = ::fcntl(own, F_GETFL); (flags & O_ACCMODE) == O_RDONLY || (flags & O_PATH) != 0)
      throw Error(ErrorCode::io_failure, "cannot write '" + path + "': the descriptor is not open for writing");
    fd_ = ::fcntl(own, F_DUPFD_CLOEXEC, 0);
    if (fd_ < 0) throw_io_error("cannot open", path, errno);
    direct_ = true;
    try {
      writer_ = new FdWriter(fd_, path);
    } catch (...) {
      ::close(fd_);
      throw;
    }
    return;
  }
  // Other names under /proc and /dev/fd (another process's descriptor, or one
  // this process does not hold open): a rename would swap the file from under
  // its holder, so they are written in place.
  direct_ = path.rfind("/proc/", 0) == 0 || path.rfind("/dev/fd/", 0) == 0;
  struct stat st;
  if (!direct_ && ::lstat(path.c_str(), &st) == 0 && S_ISLNK(st.st_mode)) {
    std::string link(4096, '\0');
    const ssize_t n = ::readlink(path.c_str(), link.data(), link.size());
    link.resize(n > 0 ? static_cast<std::size_t>(n) : 0);
    // What the link names, a relative one from the link's folder.
    const std::string named = link.empty() || link[0] == '/' ? link : path.substr(0, path.find_last_of('/') + 1) + link;
    char* resolved = ::realpath(path.c_str(), nullptr);
    struct stat lt;
    if (link.rfind("/proc/", 0) == 0) {
      direct_ = true;  // /dev/stdout -> /proc/self/fd/1
    } else if (resolved) {
      target_ = resolved;
    } else if (!named.empty() && ::lstat(named.c_str(), &lt) != 0 && errno == ENOENT) {
      // A link to a file not there yet: made there, through a temporary
      // beside it and a rename, as any other (a temporary that cannot be
      // made there says why).
      target_ = named;
    } else {
      direct_ = true;  // a looping link, or one through another: open follows it, or says why not
    }
    std::free(resolved);
  }
  if (!direct_ && ::stat(target_.c_str(), &st) == 0 && !S_ISREG(st.st_mode)) {
    // A directory cannot be written or renamed onto: refused now, before
    // anything is written (of TetGen's two files, neither is replaced).
    if (S_ISDIR(st.st_mode)) throw_io_error("cannot write", path, EISDIR);
    direct_ = true;
  }
  if (direct_) {
    fd_ = ::open(target_.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
    if (fd_ < 0) throw_io_error("cannot open", path, errno);
    writer_ = new FdWriter(fd_, path);
    return;
  }
  // A file there already: replaced only if it could be written (a read-only
  // file is refused, as the shell's > would), and the new one keeps its
  // permissions (a private file stays private).
  std::optional<mode_t> keep_mode;
  if (::stat(target_.c_str(), &st) == 0) {
    if (::access(target_.c_str(), W_OK) != 0) throw_io_error("cannot write", path, errno);
    keep_mode = st.st_mode & 07777;
  }
  // Unique name in the target's directory: pid + per-process counter; O_EXCL
  // makes a collision with a stale file from another process retry.
  static std::atomic<unsigned> counter{0};
  for (int attempt = 0; attempt < 100; ++attempt) {
    temp_ = target_ + ".tmp." + std::to_string(::getpid()) + "." + std::to_string(counter.fetch_add(1));
    // 0666 & ~umask, as a plain fopen would create it (mkstemp would give 0600).
    fd_ = ::open(temp_.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
    if (fd_ >= 0) break;
    if (errno != EEXIST) throw_io_error("cannot create", path, errno);
  }
  if (fd_ < 0) throw_io_error("cannot create", path, EEXIST);
  temp_slot_ = track_temporary(temp_);
  if (keep_mode && ::fchmod(fd_, *keep_mode) != 0) {
    const int err = errno;
    discard();
    throw_io_error("cannot set the permissions of", path, err);
  }
  try {
    writer_ = new FdWriter(fd_, path);
  } catch (...) {
    discard();
    throw;
  }
}

OutputFile::~OutputFile() {
  if (!committed_) discard();
  delete writer_;
}

void OutputFile::discard() noexcept {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
  if (!temp_.empty()) ::unlink(temp_.c_str());
  temp_.clear();
  untrack_temporary(temp_slot_);
  temp_slot_ = -1;
}

void OutputFile::finish() {
  if (finished_) return;
  try {
    writer_->flush();
  } catch (...) {
    discard();
    throw;
  }
  // close() can report a delayed write error (NFS, quota): check it.
  int fd = fd_;
  fd_ = -1;
  if (::close(fd) != 0) {
    int err = errno;
    discard();
    throw_io_error("cannot write", path_, err);
  }
  finished_ = true;
}

bool OutputFile::seekable() const { return fd_ >= 0 && ::lseek(fd_, 0, SEEK_CUR) != -1; }

void OutputFile::overwrite(std::uint64_t at, const void* data, std::size_t n) {
  assert(!finished_);
  try {
    writer_->flush();
    const char* p = static_cast<const char*>(data);
    while (n > 0) {
      const ssize_t w = ::pwrite(fd_, p, n, static_cast<off_t>(at));
      if (w < 0 && errno == EINTR) continue;
      if (w <= 0) throw_io_error("cannot write", path_, w < 0 ? errno : EIO);
      p += w;
      at += static_cast<std::uint64_t>(w);
      n -= static_cast<std::size_t>(w);
    }
  } catch (...) {
    discard();
    throw;
  }
}

void OutputFile::commit() {
  if (committed_) return;
  finish();
  if (direct_) {
    committed_ = true;
    return;
  }
  if (::rename(temp_.c_str(), target_.c_str()) != 0) {
    int err = errno;
    discard();
    throw_io_error("cannot rename the temporary file onto", path_, err);
  }
  temp_.clear();
  untrack_temporary(temp_slot_);
  temp_slot_ = -1;
  committed_ = true;
}

}  // namespace pdt::detail
