// Reading what the user hands spadgen, within stated limits: files are read only when they are regular
// files no larger than a stated size (a directory, FIFO or /dev/zero is named as what it is, never read
// without bound), and JSON is parsed without recursion, to a stated nesting depth, with duplicate keys and
// numbers beyond the range of a double reported at their key and line:column.
#pragma once
#include <nlohmann/json.hpp>

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "core/error.h"

namespace spadgen::scenes {

// Size limits of the files a scene names (docs/scene-file.md, "Limits").
inline constexpr uint64_t kMaxSceneFileBytes = uint64_t{4} << 20;    // a scene file
inline constexpr uint64_t kMaxTableFileBytes = uint64_t{64} << 20;   // a CSV table
inline constexpr uint64_t kMaxImageFileBytes = uint64_t{1} << 30;    // sensor.gate.maps_exr, a glTF image
inline constexpr uint64_t kMaxGltfFileBytes = uint64_t{2} << 30;     // a .gltf / .glb and each buffer file
// Arrays and objects inside one another, in a scene file, a --set value and a glTF file's JSON (its
// extras included). A scene file needs 4; glTF exporters write fewer than 20.
inline constexpr int kMaxJsonDepth = 64;

// "" when `path` names a regular file of at most max_bytes; else why not, e.g. "is a directory",
// "is a FIFO (named pipe)", "is a character device (/dev/zero?)", "does not exist",
// "is 3.1 GB, larger than the 2 GB spadgen reads".
std::string file_problem(const std::string& path, uint64_t max_bytes);

// `path` made absolute with "." and "X/.." taken out, as the system resolves it: ".." after a symbolic link
// is the parent of the link's target ("DIR/LINK/../f" is the f beside LINK's target, which lexically_normal
// made DIR/f). Other links stay as spelt. Scene and dataset files' paths, and those relative to them.
std::string normal_path(const std::string& path);

// The whole file, after file_problem; throws spadgen::Error "<what> <path>: <problem>".
std::string read_file_bounded(const std::string& path, uint64_t max_bytes, const std::string& what);

// "4 MB", "2 GB": a limit as the messages and the docs state it.
std::string size_text(uint64_t bytes);

struct JsonOptions {
  bool comments = true;         // // and /* */ comments (scene files are JSONC)
  bool reject_duplicates = true;  // the same key twice in one object is an error
  // Without reject_duplicates: where the first key repeated in its object is, with its path (the later value
  // is kept), or "" when none is ("file:3:5: /materials appears twice in one object").
  std::string* first_duplicate = nullptr;
  bool positions = true;  // errors name the line:column (a --set value, one short line, names only its key)
};

// What parse_json throws for a text whose syntax is JSON's but which it refuses: a number beyond the range of a
// double or below the smallest one, nesting deeper than kMaxJsonDepth, a key twice in one object. A --set value
// that fails so was meant as JSON (a plain string never does), where one that is not JSON at all is a string.
class JsonLimitError : public Error {
 public:
  using Error::Error;
};

// Parses JSON without recursion. Throws spadgen::Error naming `where` (a file, or "--set key") with
// line:column for a syntax error, a number beyond the double range (with its key path), nesting deeper
// than kMaxJsonDepth, and (when asked) a key that appears twice in one object (with its path).
nlohmann::json parse_json(const std::string& text, const std::string& where, const JsonOptions& options = {});

// The offset of the first byte of `text` that is not part of well-formed UTF-8 (core/utf8.h).
using spadgen::invalid_utf8_at;

// `text` for a message: bytes outside printable ASCII shown as \xHH.
std::string printable(const std::string& text);
// The text on one line: control bytes (a newline, a tab, ...) as \n, \t or \xNN, bytes that are not part of
// well-formed UTF-8 as \xNN, the rest (UTF-8 included, and NUL, which spadgen::Error shows as \0) as it is: for
// a user's key or name in a one-line message.
std::string one_line(const std::string& text);

// The candidate closest to `word` by edit distance when it is close enough to be a likely typo (at most a
// third of the word's length, and at least 2 edits allowed), else "": for "did you mean" messages.
std::string closest(const std::string& word, const std::vector<std::string>& candidates);

// FNV-1a 64 (16 hex digits) of a scene file, its glTF file and the files the glTF reads (its buffers and
// images, gltf_external_files, each by name and content): a stable content hash for provenance, not for
// security. Files that cannot be read, and any but regular files of at most kMaxGltfFileBytes (a device, a FIFO),
// count as empty; files are hashed in pieces, not held.
std::string content_hash(const std::string& scene_file, const std::string& gltf_path);

// FNV-1a 64 of bytes, continuing from `h`, and as 16 hex digits.
uint64_t fnv1a64(std::string_view bytes, uint64_t h = 0xcbf29ce484222325ull);
std::string hex64(uint64_t h);

// A file's bytes; "" when it cannot be read or is not a regular file of at most kMaxGltfFileBytes (for content
// hashes: a device or a FIFO is not read).
std::string file_bytes(const std::string& path);

// Levenshtein distance (insertions, deletions, substitutions), for the "did you mean" of messages.
size_t edit_distance(const std::string& a, const std::string& b);

// "line:column" (both from 1) of byte `offset` of `text`.
std::string line_column(const std::string& text, size_t offset);

}  // namespace spadgen::scenes
