// The exceptions spadgen throws for what the user can act on. Their message is what the user sees: it
// names the file, the key or the glTF element, what was found and what was expected.
//
// Exit codes of the spadgen program (README.md, "Exit codes"): 0 success; 1 spadgen::Error (bad input, a
// file that cannot be read or written, an output folder in use, a run the machine cannot hold);
// 2 spadgen::Interrupted (SIGINT or SIGTERM; nothing was published); 3 an internal error (a bug).
#pragma once
#include <atomic>
#include <stdexcept>
#include <string>

#include "core/utf8.h"

namespace spadgen {

class Error : public std::runtime_error {
 public:
  // A NUL byte in the message (a name from a file, "fl\u0000at.json") is written \0: what() would end there;
  // a byte that is not part of well-formed UTF-8 (a damaged file's channel name a library echoes) \xNN: the
  // message is text, for a terminal, a script reading it, and the JSON it is recorded in (a dataset sample's
  // error with such a byte could not be recorded in its folder's index).
  explicit Error(const std::string& message) : std::runtime_error(escape_invalid_utf8(without_nul(message))) {}

 private:
  static std::string without_nul(const std::string& m) {
    if (m.find('\0') == std::string::npos) return m;
    std::string out;
    for (const char c : m) {
      if (c == '\0') out += "\\0";
      else out += c;
    }
    return out;
  }
};

// An Error of one scene-file key, found where the key is used (the renderer meeting no glTF camera of the name
// camera.gltf_camera gives): what() is "camera.gltf_camera: <reason>"; `pointer` ("/camera/gltf_camera") lets
// the program name the key as the user gave it (the --set key, else the scene file and the pointer).
class KeyError : public Error {
 public:
  KeyError(const std::string& key_pointer, const std::string& why)
      : Error(dotted(key_pointer) + ": " + why), pointer(escape_invalid_utf8(key_pointer)), reason(escape_invalid_utf8(why)) {}
  std::string pointer, reason;

 private:
  static std::string dotted(const std::string& p) {
    std::string d = p.empty() ? p : p.substr(1);
    for (char& c : d)
      if (c == '/') c = '.';
    return d;
  }
};

// The run was asked to stop (SIGINT, SIGTERM) and stopped without publishing anything.
class Interrupted : public Error {
 public:
  explicit Interrupted(const std::string& message) : Error(message) {}
};

// Set from a signal handler (app/interrupt.h) and polled by every long loop, so that no tile, pixel or
// table runs unbounded after a signal. A lock-free atomic is all a handler may touch.
inline std::atomic<bool> g_interrupt_flag{false};
inline std::atomic<bool>& interrupt_flag() { return g_interrupt_flag; }
static_assert(std::atomic<bool>::is_always_lock_free);

// Throws spadgen::Interrupted once a signal has arrived. Cheap (one relaxed load): call it per pixel.
inline void throw_if_interrupted() {
  if (interrupt_flag().load(std::memory_order_relaxed))
    throw Interrupted("interrupted by a signal: the run stopped and wrote nothing");
}

}  // namespace spadgen
