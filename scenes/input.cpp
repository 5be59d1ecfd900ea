#include "scenes/input.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <fstream>
#include <sstream>
#include <set>
#include <vector>

#include "core/error.h"
#include "scenes/scene.h"

namespace spadgen::scenes {
namespace {

using json = nlohmann::json;

std::string kind_of(mode_t mode) {
  if (S_ISDIR(mode)) return "is a directory";
  if (S_ISFIFO(mode)) return "is a FIFO (named pipe)";
  if (S_ISCHR(mode)) return "is a character device";
  if (S_ISBLK(mode)) return "is a block device";
  if (S_ISSOCK(mode)) return "is a socket";
  return "is not a regular file";
}

std::string stat_problem(const struct stat& st, uint64_t max_bytes) {
  if (!S_ISREG(st.st_mode)) return kind_of(st.st_mode) + ", expected a regular file";
  if (static_cast<uint64_t>(st.st_size) > max_bytes)
    return "is " + size_text(static_cast<uint64_t>(st.st_size)) + ", larger than the " + size_text(max_bytes) +
           " spadgen reads";
  return "";
}

// Where the string or comment that begins at text[i] ends (its last character), i when none begins there,
// or npos for a block comment never closed.
size_t skip_string_or_comment(const std::string& text, size_t i) {
  if (text[i] == '"') {
    for (++i; i < text.size() && text[i] != '"'; ++i)
      if (text[i] == '\\') ++i;
    return i;
  }
  if (text[i] != '/' || i + 1 >= text.size()) return i;
  if (text[i + 1] == '/') {
    while (i < text.size() && text[i] != '\n') ++i;
    return i;
  }
  if (text[i + 1] == '*') {
    const size_t end = text.find("*/", i + 2);
    return end == std::string::npos ? std::string::npos : end + 1;
  }
  return i;
}

// The offset at which arrays and objects nest deeper than `limit`, or npos. Strings and comments are
// skipped, so a brace inside them does not count; anything malformed is left to the parser.
size_t depth_exceeded_at(const std::string& text, int limit) {
  int depth = 0;
  for (size_t i = 0; i < text.size(); ++i) {
    if (const size_t e = skip_string_or_comment(text, i); e != i) {
      if (e == std::string::npos) return std::string::npos;
      i = e;
    } else if (text[i] == '[' || text[i] == '{') {
      if (++depth > limit) return i;
    } else if (text[i] == ']' || text[i] == '}') {
      --depth;
    }
  }
  return std::string::npos;
}

// The offset of the first number written as `token` outside strings and comments, or npos. The parse stops
// at the first number too small for a double, so an earlier one written alike would have stopped it.
size_t number_offset(const std::string& text, const std::string& token) {
  const auto in_number = [](char c) { return (c >= '0' && c <= '9') || c == '-' || c == '+' || c == '.' || c == 'e' || c == 'E'; };
  for (size_t i = 0; i < text.size(); ++i) {
    if (const size_t e = skip_string_or_comment(text, i); e != i) {
      if (e == std::string::npos) return std::string::npos;
      i = e;
    } else if (text[i] == '-' || (text[i] >= '0' && text[i] <= '9')) {
      size_t end = i;
      while (end < text.size() && in_number(text[end])) ++end;
      if (end - i == token.size() && text.compare(i, end - i, token) == 0) return i;
      i = end - 1;
    }
  }
  return std::string::npos;
}

// Builds the document through nlohmann's own DOM builder, keeping the path of the value being read so
// that an error can name it, and refusing duplicate keys and excessive nesting as they are met.
class CheckedSax {
 public:
  CheckedSax(json& root, const JsonOptions& options) : dom_(root, /*allow_exceptions=*/false), options_(options) {}

  bool null() { return value() && dom_.null(); }
  bool boolean(bool v) { return value() && dom_.boolean(v); }
  bool number_integer(json::number_integer_t v) { return value() && dom_.number_integer(v); }
  bool number_unsigned(json::number_unsigned_t v) { return value() && dom_.number_unsigned(v); }
  bool number_float(json::number_float_t v, const json::string_t& s) {
    // A number too small for a double is read as 0 (1e-400: a bin width of it was "found 0.0"), and so is a
    // subnormal one where the program flushes subnormals to zero (app::flush_denormals; 1e-320 was refused as
    // "below the smallest double (about 4.9e-324)"): named as written, at the smallest normal double.
    if ((v == 0.0 && s.find_first_of("123456789") < s.find_first_of("eE")) ||
        (v != 0.0 && std::abs(v) < std::numeric_limits<double>::min())) {
      problem = (levels_.empty() ? std::string() : path(/*pending=*/true) + ": ") + "the number " + s +
                " is below the smallest normal double (about 2.2e-308), which spadgen computes with (smaller ones "
                "are flushed to 0); write 0 for zero";
      limit = true;
      tiny_number = s;  // (the SAX interface gives no position: found again in the text)
      return false;
    }
    return value() && dom_.number_float(v, s);
  }
  bool string(json::string_t& v) { return value() && dom_.string(v); }
  bool binary(json::binary_t& v) { return value() && dom_.binary(v); }
  bool start_object(std::size_t n) {
    if (!value() || !open()) return false;
    levels_.push_back({true, "", 0, {}});
    return dom_.start_object(n);
  }
  bool key(json::string_t& k) {
    Level& l = levels_.back();
    ++keys_seen;
    if ((options_.reject_duplicates || (options_.first_duplicate && duplicate_key == 0)) && !l.keys.insert(k).second) {
      duplicate_key = keys_seen;
      l.key = k;
      if (!options_.reject_duplicates) {  // noted, and read on: the later value is kept
        duplicate_path = path();
        return dom_.key(k);
      }
      problem = path() + ": appears twice in one object; expected each key once (JSON readers keep one of them "
                         "silently)";
      limit = true;
      return false;
    }
    l.key = k;
    return dom_.key(k);
  }
  bool end_object() {
    levels_.pop_back();
    return dom_.end_object();
  }
  bool start_array(std::size_t n) {
    if (!value() || !open()) return false;
    levels_.push_back({false, "", 0, {}});
    return dom_.start_array(n);
  }
  bool end_array() {
    levels_.pop_back();
    return dom_.end_array();
  }
  bool parse_error(std::size_t position, const std::string& token, const nlohmann::detail::exception& e) {
    offset = position;
    if (e.id == 406) {  // out_of_range.406: a number beyond the range of a double, reported at its end
      if (position >= token.size()) offset = position - token.size() + 1;
      problem = (levels_.empty() ? std::string() : path(/*pending=*/true) + ": ") + "the number " + token +
                " is beyond the range of a double (about 1.8e308)";
      limit = true;
    } else {
      std::string what = e.what();
      if (const size_t pos = what.find("syntax error"); pos != std::string::npos) what = what.substr(pos);
      problem = "not valid JSON: " + what;
    }
    syntax = true;
    return false;
  }

  std::string problem;  // why the parse stopped ("" = it did not)
  std::string tiny_number;  // the number below the smallest normal double it stopped at, as written
  size_t offset = 0;    // where, for syntax errors and overflowing numbers
  bool syntax = false;  // the problem has an offset
  bool limit = false;   // the problem is one of JsonLimitError's (the text's syntax is JSON's)
  size_t keys_seen = 0;      // object keys read so far
  size_t duplicate_key = 0;  // which of them (from 1) repeated a key of its object; 0 = none
  std::string duplicate_path;  // its path, when it was only noted

 private:
  struct Level {
    bool object;
    std::string key;    // the key being read (objects)
    size_t count;       // elements started so far (arrays)
    std::set<std::string> keys;
  };
  // A value starts: in an array it is the next element.
  bool value() {
    if (!levels_.empty() && !levels_.back().object) ++levels_.back().count;
    return true;
  }
  bool open() {
    if (static_cast<int>(levels_.size()) >= kMaxJsonDepth) {
      problem = "arrays and objects nested deeper than " + std::to_string(kMaxJsonDepth) + " levels";
      limit = true;
      return false;
    }
    return true;
  }
  // The JSON pointer of the value being read; `pending` when its own value() has not run yet.
  std::string path(bool pending = false) const {
    std::string p;
    for (const Level& l : levels_)
      p += "/" + (l.object ? l.key : std::to_string(pending && &l == &levels_.back() ? l.count : l.count - 1));
    return p.empty() ? "/" : p;
  }

  nlohmann::detail::json_sax_dom_parser<json> dom_;
  JsonOptions options_;
  std::vector<Level> levels_;
};

}  // namespace

std::string size_text(uint64_t bytes) {
  const char* units[] = {"bytes", "KiB", "MiB", "GiB", "TiB"};
  double v = static_cast<double>(bytes);
  int u = 0;
  while (v >= 1024.0 && u < 4) v /= 1024.0, ++u;
  char buf[32];
  std::snprintf(buf, sizeof buf, v == static_cast<double>(static_cast<uint64_t>(v)) ? "%.0f %s" : "%.1f %s", v, units[u]);
  return buf;
}

std::string normal_path(const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  fs::path abs = fs::absolute(path, ec);
  if (ec) abs = path;
  fs::path out;
  for (const fs::path& part : abs) {
    if (part.empty() || part == ".") continue;
    if (part != "..") {
      out /= part;
      continue;
    }
    if (fs::is_symlink(out, ec))
      if (fs::path real = fs::canonical(out, ec); !ec) {
        out = real.parent_path();
        continue;
      }
    if (out.has_relative_path()) out = out.parent_path();  // (the root's parent is the root)
  }
  return out.string();
}

std::string file_problem(const std::string& path, uint64_t max_bytes) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0)
    return errno == ENOENT ? std::string("does not exist") : std::string("cannot be read: ") + std::strerror(errno);
  return stat_problem(st, max_bytes);
}

std::string read_file_bounded(const std::string& path, uint64_t max_bytes, const std::string& what) {
  const auto fail = [&](const std::string& problem) { return Error(what + " " + path + ": " + problem); };
  // O_NONBLOCK: a FIFO put in place after a check must not block the open; fstat then decides.
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) throw fail(errno == ENOENT ? std::string("does not exist") : std::string("cannot be opened: ") + std::strerror(errno));
  struct stat st {};
  std::string problem = ::fstat(fd, &st) != 0 ? std::string("cannot be read: ") + std::strerror(errno) : stat_problem(st, max_bytes);
  std::string out;
  if (problem.empty()) {
    out.resize(static_cast<size_t>(st.st_size));
    size_t got = 0;
    // A file that grows while it is read is cut at the size it had: the read never runs unbounded.
    while (got < out.size()) {
      const ssize_t n = ::read(fd, out.data() + got, out.size() - got);
      if (n < 0 && errno == EINTR) continue;
      if (n < 0) {
        problem = std::string("cannot be read: ") + std::strerror(errno);
        break;
      }
      if (n == 0) break;
      got += static_cast<size_t>(n);
    }
    out.resize(got);
  }
  ::close(fd);
  if (!problem.empty()) throw fail(problem);
  return out;
}

std::string printable(const std::string& text) {
  std::string out;
  for (const char ch : text) {
    const auto c = static_cast<unsigned char>(ch);
    if (c >= 32 && c < 127) {
      out += ch;
    } else {
      char hex[8];
      std::snprintf(hex, sizeof hex, "\\x%02X", c);
      out += hex;
    }
  }
  return out;
}

std::string one_line(const std::string& text) {
  std::string out;
  // Bytes that are not part of well-formed UTF-8 (a damaged file's name echoed by a library) first, as \xNN:
  // every message is valid UTF-8 (a script decoding stderr as text failed on it); then the control bytes.
  for (const char ch : escape_invalid_utf8(text)) {
    const auto c = static_cast<unsigned char>(ch);
    if (c == '\n') {
      out += "\\n";
    } else if (c == '\t') {
      out += "\\t";
    } else if ((c < 32 && c != 0) || c == 127) {  // (a NUL byte: spadgen::Error shows it as \0)
      char hex[8];
      std::snprintf(hex, sizeof hex, "\\x%02X", c);
      out += hex;
    } else {
      out += ch;
    }
  }
  return out;
}

std::string line_column(const std::string& text, size_t offset) {
  size_t line = 1, col = 1;
  for (size_t i = 0; i < offset && i < text.size(); ++i) {
    if (text[i] == '\n') ++line, col = 1;
    else ++col;
  }
  return std::to_string(line) + ":" + std::to_string(col);
}

namespace {

// The offset of the opening quote of the n-th object key (from 1) of well-formed JSON text up to that key:
// a string followed, after blanks and comments, by ':'. npos when there is no such key.
size_t nth_key_offset(const std::string& text, size_t n) {
  size_t i = 0, count = 0;
  const auto skip_blank = [&](size_t j) {
    while (j < text.size()) {
      if (std::isspace(static_cast<unsigned char>(text[j]))) ++j;
      else if (text.compare(j, 2, "//") == 0) j = std::min(text.size(), text.find('\n', j) == std::string::npos ? text.size() : text.find('\n', j));
      else if (text.compare(j, 2, "/*") == 0) j = text.find("*/", j + 2) == std::string::npos ? text.size() : text.find("*/", j + 2) + 2;
      else break;
    }
    return j;
  };
  while ((i = skip_blank(i)) < text.size()) {
    if (text[i] != '"') {
      ++i;
      continue;
    }
    const size_t start = i++;
    while (i < text.size() && text[i] != '"') i += text[i] == '\\' ? 2 : 1;
    ++i;
    const size_t after = skip_blank(i);
    if (after < text.size() && text[after] == ':' && ++count == n) return start;
  }
  return std::string::npos;
}

}  // namespace

json parse_json(const std::string& text, const std::string& where, const JsonOptions& options) {
  // No JSON text holds a raw NUL byte (the parser took one for the end of the input: a file led by one was
  // "unexpected end of input", one after the text went unsaid).
  // ":line:column" of an offset (nothing for a --set value, one short line)
  const auto place = [&](size_t at) {
    std::string s;
    if (options.positions) s.append(":").append(line_column(text, at));
    return s;
  };
  if (text.size() >= 2 && (text.compare(0, 2, "\xff\xfe") == 0 || text.compare(0, 2, "\xfe\xff") == 0))
    throw Error(where + place(0) + ": starts with a UTF-16 byte order mark; expected JSON text in UTF-8");
  if (const size_t at = text.find('\0'); at != std::string::npos)
    throw Error(where + place(at) + ": a NUL byte (0x00), which no JSON text holds; expected JSON text in " +
                "UTF-8 (is this a binary file, or UTF-16 text?)");
  if (const size_t at = depth_exceeded_at(text, kMaxJsonDepth); at != std::string::npos)
    throw JsonLimitError(where + place(at) + ": arrays and objects nested deeper than " +
                std::to_string(kMaxJsonDepth) + " levels; spadgen reads at most " + std::to_string(kMaxJsonDepth));
  json root;
  CheckedSax sax(root, options);
  const bool ok = json::sax_parse(text, &sax, json::input_format_t::json, /*strict=*/true, options.comments);
  if (sax.duplicate_key > 0 && !options.reject_duplicates) {
    if (ok && sax.problem.empty() && options.first_duplicate) {
      const size_t at = nth_key_offset(text, sax.duplicate_key);
      *options.first_duplicate = where + (at == std::string::npos ? std::string() : place(at)) + ": " +
                                 sax.duplicate_path + " appears twice in one object";
    }
  } else if (sax.duplicate_key > 0) {
    // The SAX interface gives no positions: the repeated key is found again by counting keys in the text.
    const size_t at = nth_key_offset(text, sax.duplicate_key);
    throw JsonLimitError(where + (at == std::string::npos ? std::string() : place(at)) + ": " + sax.problem);
  }
  if (!ok || !sax.problem.empty()) {
    const std::string problem = sax.problem.empty() ? std::string("not valid JSON") : sax.problem;
    // nlohmann reports the offset one past the character it stopped at.
    std::string message = where;
    if (!sax.tiny_number.empty())
      if (const size_t at = number_offset(text, sax.tiny_number); at != std::string::npos) sax.syntax = true, sax.offset = at + 1;
    if (sax.syntax) message.append(place(sax.offset > 0 ? sax.offset - 1 : 0));
    message.append(": ").append(problem);
    if (sax.limit) throw JsonLimitError(message);
    throw Error(message);
  }
  return root;
}

std::string closest(const std::string& word, const std::vector<std::string>& candidates) {
  std::string best;
  size_t best_d = std::max<size_t>(2, word.size() / 3) + 1;
  for (const std::string& c : candidates)
    if (const size_t d = edit_distance(word, c); d < best_d) best_d = d, best = c;
  return best;
}

uint64_t fnv1a64(std::string_view bytes, uint64_t h) {
  for (unsigned char c : bytes) h = (h ^ c) * 0x100000001b3ull;
  return h;
}

std::string hex64(uint64_t h) {
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(h));
  return buf;
}

std::string file_bytes(const std::string& path) {
  std::string out;
  try {
    out = read_file_bounded(path, kMaxGltfFileBytes, "file");  // (a device or a FIFO: not read)
  } catch (const Error&) {
  }
  return out;
}

// FNV-1a 64 of a file's bytes continuing from h, read in pieces (a 2 GiB buffer is not held to hash it); a file
// that is not a regular one of at most kMaxGltfFileBytes (a device, a FIFO, a link to one: a verifier's buffer
// uri "/dev/zero" read on until memory ran out, a FIFO blocked for ever), or cannot be read, counts as empty:
// the loader refuses it with the reason. Opened without blocking: fstat decides before a byte is read.
uint64_t hash_file(const std::string& path, uint64_t h) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) return h;
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !stat_problem(st, kMaxGltfFileBytes).empty()) {
    ::close(fd);
    return h;
  }
  std::string piece(size_t{1} << 20, '\0');
  // (cut at the size it had: a file that grows while it is hashed never runs the read unbounded)
  for (uint64_t left = static_cast<uint64_t>(st.st_size); left > 0;) {
    const ssize_t n = ::read(fd, piece.data(), static_cast<size_t>(std::min<uint64_t>(left, piece.size())));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    h = fnv1a64(std::string_view(piece.data(), static_cast<size_t>(n)), h);
    left -= static_cast<uint64_t>(n);
  }
  ::close(fd);
  return h;
}

std::string content_hash(const std::string& scene_file, const std::string& gltf_path) {
  namespace fs = std::filesystem;
  uint64_t h = hash_file(scene_file, 0xcbf29ce484222325ull);
  h = hash_file(gltf_path, h);
  std::vector<std::string> referenced;
  try {
    referenced = gltf_external_files(gltf_path);
  } catch (const Error&) {
  }  // not a glTF file: loading it fails with the reason; its bytes are hashed above
  // each file's name (relative to the glTF's folder) and its bytes, so that a swap of two names counts
  for (const std::string& f : referenced)
    h = hash_file(f, fnv1a64(fs::path(f).lexically_relative(fs::path(gltf_path).parent_path()).string(), h));
  return hex64(h);
}

size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<size_t> row(b.size() + 1);
  for (size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (size_t i = 1; i <= a.size(); ++i) {
    size_t diag = row[0];
    row[0] = i;
    for (size_t j = 1; j <= b.size(); ++j) {
      const size_t up = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diag + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diag = up;
    }
  }
  return row[b.size()];
}

}  // namespace spadgen::scenes
