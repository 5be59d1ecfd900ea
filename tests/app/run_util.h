// Helpers for tests that run the spadgen program: run a command, read files, read NPY stacks with a
// small parser of our own (independent of writers/).
#pragma once
#include <sys/wait.h>

#include <array>
#include <cstring>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <gtest/gtest.h>
#include <sstream>
#include <string>
#include <vector>

namespace spadgen::testing {
namespace fs = std::filesystem;

inline const std::string kBin = std::string(SPADGEN_BINARY_DIR) + "/app/spadgen";
inline const std::string kScenes = std::string(SPADGEN_SOURCE_DIR) + "/scenes/paper/";

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

}  // namespace spadgen::testing
