// Helpers for tests that run the spadgen program: run a command, read files, read NPY stacks with a
// small parser of our own (independent of writers/).
#pragma once
#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <cstring>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "core/utf8.h"
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace spadgen::testing {
namespace fs = std::filesystem;

inline const std::string kBin = std::string(SPADGEN_BINARY_DIR) + "/app/spadgen";
inline const std::string kScenes = std::string(SPADGEN_SOURCE_DIR) + "/scenes/paper/";
// A run of a few milliseconds: 8 x 8 pixels of the flat target, 1 path each, 29 gate positions, 28 of whose
// windows hold the target's return (4 + 6.7 ns): a sound run, which prints nothing with -q (no "outside the time
// window" warning).
inline const std::string kTiny = kScenes + "flat_target.json --set camera.crop=[508,246,8,8] --set render.samples_per_pixel=1 "
                                           "--set acquisition.gate_sweep.start_ns=6 --set acquisition.gate_sweep.stop_ns=7 "
                                           "--set outputs.previews=false";

struct Result {
  int code;
  std::string output;  // stdout and stderr
};
// Runs a shell command line; stdout and stderr together.
inline Result shell(const std::string& command_line) {
  const std::string cmd = command_line + " 2>&1";
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) return {-1, "popen failed for: " + command_line.substr(0, 200)};
  std::string out;
  std::array<char, 4096> buf{};
  while (size_t n = fread(buf.data(), 1, buf.size(), p)) out.append(buf.data(), n);
  const int status = pclose(p);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}
inline Result sh(const std::string& args) { return shell(kBin + " " + args); }
inline std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// A dataset run's presence on dataset folder `dir`, as a running `dataset run` holds it (a shared open-file-description
// lock on byte 0 of DIR/.dataset.runs), for as long as the returned descriptor is open (::close ends it); -1 when
// it could not be taken.
inline int hold_dataset_run_presence(const fs::path& dir) {
  const int fd = ::open((dir / ".dataset.runs").c_str(), O_RDWR | O_CLOEXEC);
  if (fd < 0) return -1;
  struct flock l {};
  l.l_type = F_RDLCK;
  l.l_whence = SEEK_SET;
  l.l_start = 0;
  l.l_len = 1;
  if (::fcntl(fd, F_OFD_SETLK, &l) != 0) return ::close(fd), -1;
  return fd;
}

// Whether process `pid` catches signal `sig` (a handler of its own): /proc/PID/status's SigCgt mask.
inline bool catches(pid_t pid, int sig) {
  std::ifstream status("/proc/" + std::to_string(pid) + "/status");
  for (std::string line; std::getline(status, line);)
    if (line.rfind("SigCgt:", 0) == 0) return (std::stoull(line.substr(7), nullptr, 16) >> (sig - 1)) & 1u;
  return false;
}

struct Signalled {
  int code = -1;             // the exit code; 128 + n: killed by signal n; 124: killed at the time limit
  std::string output;        // stdout and stderr
  bool caught = false;       // the signal was sent once the program caught it (else never: it ended first, or the
                             // time limit passed)
  double after_signal_s = 0; // from the signal to the program's end
};
// Runs `argv` (argv[0] the program's path) and sends it `sig` `delay_s` seconds after it first catches `sig`: a
// fixed time after the start is a race with the program's start-up (over 0.3 s for a sanitizer build, before
// main), where the signal's default action kills it. Killed (SIGKILL) after `limit_s` seconds.
inline Signalled signal_once_caught(std::vector<std::string> argv, int sig, double delay_s, double limit_s = 60.0) {
  using clock = std::chrono::steady_clock;
  Signalled s;
  const fs::path out = fs::temp_directory_path() / ("spadgen_signalled_" + std::to_string(::getpid()));
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 1, out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&actions, 1, 2);
  std::vector<char*> args;
  for (std::string& a : argv) args.push_back(a.data());
  args.push_back(nullptr);
  pid_t pid = 0;
  // posix_spawn returns once the program is executed (its dispositions are the program's, not this process's).
  const int spawned = posix_spawn(&pid, args[0], &actions, nullptr, args.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (spawned != 0) return s;
  const auto t0 = clock::now();
  const auto seconds_since = [](clock::time_point t) { return std::chrono::duration<double>(clock::now() - t).count(); };
  int status = 0;
  bool ended = false;
  while (!(s.caught = catches(pid, sig)) && seconds_since(t0) < limit_s) {
    if ((ended = ::waitpid(pid, &status, WNOHANG) == pid)) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  if (s.caught) {
    std::this_thread::sleep_for(std::chrono::duration<double>(delay_s));
    ::kill(pid, sig);
  }
  const auto signalled = clock::now();
  while (!ended && !(ended = ::waitpid(pid, &status, WNOHANG) == pid)) {
    if (seconds_since(t0) > limit_s) {
      ::kill(pid, SIGKILL);
      ::waitpid(pid, &status, 0);
      s.code = 124;
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  s.after_signal_s = seconds_since(signalled);
  if (s.code != 124) s.code = WIFEXITED(status) ? WEXITSTATUS(status) : WIFSIGNALED(status) ? 128 + WTERMSIG(status) : -1;
  s.output = slurp(out);
  fs::remove(out);
  return s;
}

// A small NPY reader, independent of the writer: header dict and raw data.
struct Npy {
  std::string descr;
  std::vector<int64_t> shape;
  std::string data;
};
inline Npy read_npy(const fs::path& p) {
  const std::string b = slurp(p);
  EXPECT_EQ(b.substr(0, 6), "\x93NUMPY");
  const size_t hlen = size_t(uint8_t(b[8])) | (size_t(uint8_t(b[9])) << 8);
  const std::string h = b.substr(10, hlen);
  Npy n;
  const size_t d = h.find("'descr': '") + 10;
  n.descr = h.substr(d, h.find('\'', d) - d);
  std::string s = h.substr(h.find('(') + 1, h.find(')') - h.find('(') - 1);
  std::stringstream ss(s);
  for (std::string tok; std::getline(ss, tok, ',');)
    if (tok.find_first_not_of(' ') != std::string::npos) n.shape.push_back(std::stoll(tok));
  n.data = b.substr(10 + hlen);
  return n;
}

// Values of a little-endian float32 or uint8 stack as doubles.
inline std::vector<double> values(const Npy& n) {
  std::vector<double> v;
  if (n.descr == "<f4") {
    v.resize(n.data.size() / 4);
    for (size_t i = 0; i < v.size(); ++i) {
      float f;
      std::memcpy(&f, n.data.data() + 4 * i, 4);
      v[i] = f;
    }
  } else if (n.descr == "|u1") {
    for (char c : n.data) v.push_back(uint8_t(c));
  } else if (n.descr == "<u2") {
    v.resize(n.data.size() / 2);
    for (size_t i = 0; i < v.size(); ++i) v[i] = double(uint8_t(n.data[2 * i]) | (uint8_t(n.data[2 * i + 1]) << 8));
  }
  return v;
}

// What is wrong with a run's stderr, or "" when it is the program's own: UTF-8 text, lines of "spadgen: ..." (the
// warnings, then with `failed` an error: "spadgen: error: ..." last) and no internal error.
inline std::string stderr_problem(const std::string& err, bool failed) {
  if (spadgen::invalid_utf8_at(err) != std::string::npos) return "not UTF-8 text";
  if (err.find("internal error") != std::string::npos) return "an internal error";
  std::vector<std::string> lines;
  for (std::istringstream in(err); std::getline(in, lines.emplace_back());) {
  }
  lines.pop_back();
  for (const std::string& line : lines)
    if (line.rfind("spadgen: ", 0) != 0) return "a line not of spadgen's: " + line;
  if (failed && (lines.empty() || lines.back().rfind("spadgen: error: ", 0) != 0)) return "no error last";
  return "";
}

// Damage for the soak tests: a fixed pseudo-random sequence (splitmix64), the same on every machine.
struct Splitmix {
  uint64_t state;
  uint64_t below(uint64_t n) {
    uint64_t z = (state += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return (z ^ (z >> 31)) % n;
  }
};

// Every place of a JSON document but its root, depth first.
inline std::vector<nlohmann::json::json_pointer> json_places(const nlohmann::json& doc) {
  std::vector<nlohmann::json::json_pointer> places;
  const auto walk = [&](const auto& self, const nlohmann::json& v, const nlohmann::json::json_pointer& at) -> void {
    if (!at.empty()) places.push_back(at);
    if (v.is_object())
      for (const auto& [k, e] : v.items()) self(self, e, at / k);
    else if (v.is_array())
      for (size_t i = 0; i < v.size(); ++i) self(self, v[i], at / i);
  };
  walk(walk, doc, nlohmann::json::json_pointer());
  return places;
}

// Damages doc (not a scalar) at one of its places, drawn from rng: a value of another type or out of range, or
// the key or element removed. Returns what it did ("/a/b = 1e+308", "/a/b removed").
inline std::string damage_json(nlohmann::json& doc, Splitmix& rng) {
  const std::vector<nlohmann::json::json_pointer> places = json_places(doc);
  const nlohmann::json values[] = {nullptr, true, "x", "", -1, 0, 1, 0.5, 1e308, -1e308, 1e-308, 9223372036854775807LL,
                                   18446744073709551615ULL, nlohmann::json::array(), nlohmann::json::object(),
                                   nlohmann::json::array({1, 2, 3}), nlohmann::json::object({{"a", 1}}), "\u00e9"};
  const nlohmann::json::json_pointer at = places.at(rng.below(places.size()));
  const size_t v = rng.below(std::size(values) + 2);  // the last two: remove it
  if (v < std::size(values)) {
    doc[at] = values[v];
    return at.to_string() + " = " + values[v].dump();
  }
  nlohmann::json& parent = doc[at.parent_pointer()];
  if (parent.is_object())
    parent.erase(at.back());
  else
    parent.erase(std::stoul(at.back()));
  return at.to_string() + " removed";
}

}  // namespace spadgen::testing
