// glTF files built by hand for the loader's tests (gltf_loader_test.cpp, scene_edits_test.cpp): each test
// states exactly the JSON and bytes it loads, written into a temporary folder of its own.
#pragma once
#include <gtest/gtest.h>
#include <unistd.h>

#include <nlohmann/json.hpp>

#include <glm/glm.hpp>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "core/error.h"
#include "scenes/scene.h"

namespace spadgen::test_gltf {

namespace fs = std::filesystem;
using nlohmann::json;
using spadgen::Error;
using spadgen::scenes::load_gltf;
using spadgen::scenes::Scene;

inline constexpr int kByte = 5120, kUByte = 5121, kShort = 5122, kUShort = 5123, kUInt = 5125, kFloat = 5126;
inline constexpr double kPi = 3.14159265358979323846;

// A 2x2 RGBA PNG: red, green / blue, white at alpha 128.
inline const char* kPng2x2 =
    "iVBORw0KGgoAAAANSUhEUgAAAAIAAAACCAYAAABytg0kAAAAE0lEQVR4nGP4z8DwHwyBNAg0AABJSQl4KKDbdwAAAABJRU5ErkJggg==";

inline std::string base64(const std::vector<uint8_t>& data) {
  static const char* t = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  for (size_t i = 0; i < data.size(); i += 3) {
    const uint32_t b = (uint32_t{data[i]} << 16) | (i + 1 < data.size() ? uint32_t{data[i + 1]} << 8 : 0u) |
                       (i + 2 < data.size() ? uint32_t{data[i + 2]} : 0u);
    out += t[(b >> 18) & 63];
    out += t[(b >> 12) & 63];
    out += i + 1 < data.size() ? t[(b >> 6) & 63] : '=';
    out += i + 2 < data.size() ? t[b & 63] : '=';
  }
  return out;
}

inline std::vector<uint8_t> unbase64(const std::string& s) {
  std::vector<uint8_t> out;
  uint32_t acc = 0;
  int bits = 0;
  for (char c : s) {
    int v;
    if (c >= 'A' && c <= 'Z') v = c - 'A';
    else if (c >= 'a' && c <= 'z') v = c - 'a' + 26;
    else if (c >= '0' && c <= '9') v = c - '0' + 52;
    else if (c == '+') v = 62;
    else if (c == '/') v = 63;
    else continue;
    acc = (acc << 6) | static_cast<uint32_t>(v);
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out.push_back(static_cast<uint8_t>((acc >> bits) & 0xff));
    }
  }
  return out;
}

// A temporary folder per test, removed when the test ends.
class TempDir {
 public:
  TempDir() {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    path_ = fs::temp_directory_path() /
            ("spadgen_gltf_" + std::string(info->test_suite_name()) + "_" + info->name() + "_" +
             std::to_string(::getpid()));
    fs::remove_all(path_);
    fs::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  const fs::path& path() const { return path_; }

 private:
  fs::path path_;
};

inline void write_file(const fs::path& p, const std::string& bytes) {
  std::ofstream f(p, std::ios::binary);
  f << bytes;
}

// Builds a glTF document and its binary buffer by hand, so each test states exactly the bytes it tests.
class Gltf {
 public:
  enum class Form { External, Embedded, Glb };

  Gltf() {
    doc = {{"asset", {{"version", "2.0"}, {"generator", "spadgen test"}}},
           {"scene", 0},
           {"scenes", json::array({{{"name", "main"}, {"nodes", json::array()}}})},
           {"nodes", json::array()},
           {"meshes", json::array()},
           {"accessors", json::array()},
           {"bufferViews", json::array()}};
  }

  template <class T>
  size_t append(const std::vector<T>& v) {
    while (bin.size() % 4) bin.push_back(0);
    const size_t offset = bin.size();
    const auto* p = reinterpret_cast<const uint8_t*>(v.data());
    bin.insert(bin.end(), p, p + v.size() * sizeof(T));
    return offset;
  }
  int view(size_t offset, size_t length, size_t stride = 0) {
    json v = {{"buffer", 0}, {"byteOffset", offset}, {"byteLength", length}};
    if (stride) v["byteStride"] = stride;
    doc["bufferViews"].push_back(v);
    return static_cast<int>(doc["bufferViews"].size()) - 1;
  }
  template <class T>
  int view_of(const std::vector<T>& v, size_t stride = 0) {
    const size_t offset = append(v);
    return view(offset, v.size() * sizeof(T), stride);
  }
  int accessor(int view_index, int component_type, const char* type, size_t count, size_t offset = 0,
               bool normalized = false) {
    json a = {{"componentType", component_type}, {"type", type}, {"count", count}};
    if (view_index >= 0) a["bufferView"] = view_index;
    if (offset) a["byteOffset"] = offset;
    if (normalized) a["normalized"] = true;
    doc["accessors"].push_back(a);
    return static_cast<int>(doc["accessors"].size()) - 1;
  }
  int positions(const std::vector<float>& xyz) {
    return accessor(view_of(xyz), kFloat, "VEC3", xyz.size() / 3);
  }
  template <class T>
  int indices(const std::vector<T>& idx, int component_type) {
    return accessor(view_of(idx), component_type, "SCALAR", idx.size());
  }
  int mesh(const json& primitives, const std::string& name = "") {
    json m = {{"primitives", primitives}};
    if (!name.empty()) m["name"] = name;
    doc["meshes"].push_back(m);
    return static_cast<int>(doc["meshes"].size()) - 1;
  }
  // Adds a node; a root of scene 0 unless `root` is false.
  int node(const json& n, bool root = true) {
    doc["nodes"].push_back(n);
    const int i = static_cast<int>(doc["nodes"].size()) - 1;
    if (root) doc["scenes"][0]["nodes"].push_back(i);
    return i;
  }
  // One triangle in the z = 0 plane facing +Z, with normals: the simplest mesh.
  int triangle_mesh(const std::string& name = "Tri") {
    const int pos = positions({0, 0, 0, 1, 0, 0, 0, 1, 0});
    const int nor = accessor(view_of(std::vector<float>{0, 0, 1, 0, 0, 1, 0, 0, 1}), kFloat, "VEC3", 3);
    const int idx = indices(std::vector<uint16_t>{0, 1, 2}, kUShort);
    return mesh(json::array({{{"attributes", {{"POSITION", pos}, {"NORMAL", nor}}}, {"indices", idx}}}), name);
  }

  std::string write(const fs::path& dir, const std::string& stem, Form form = Form::External) const {
    json d = doc;
    if (!bin.empty()) {
      json b = {{"byteLength", bin.size()}};
      if (form == Form::External) {
        b["uri"] = stem + ".bin";
        write_file(dir / (stem + ".bin"), std::string(bin.begin(), bin.end()));
      } else if (form == Form::Embedded) {
        b["uri"] = "data:application/octet-stream;base64," + base64(bin);
      }
      d["buffers"] = json::array({b});
    }
    if (form != Form::Glb) {
      const fs::path p = dir / (stem + ".gltf");
      write_file(p, d.dump(2));
      return p.string();
    }
    std::string js = d.dump();
    while (js.size() % 4) js += ' ';
    std::vector<uint8_t> b = bin;
    while (b.size() % 4) b.push_back(0);
    const auto u32 = [](uint32_t v) { return std::string(reinterpret_cast<const char*>(&v), 4); };
    std::string glb = "glTF" + u32(2) +
                      u32(static_cast<uint32_t>(12 + 8 + js.size() + (b.empty() ? 0 : 8 + b.size())));
    glb += u32(static_cast<uint32_t>(js.size())) + u32(0x4E4F534A) + js;
    if (!b.empty()) glb += u32(static_cast<uint32_t>(b.size())) + u32(0x004E4942) + std::string(b.begin(), b.end());
    const fs::path p = dir / (stem + ".glb");
    write_file(p, glb);
    return p.string();
  }

  json doc;
  std::vector<uint8_t> bin;
};

inline void expect_vec(const glm::vec3& got, const glm::dvec3& want, double tol = 1e-6) {
  EXPECT_NEAR(got.x, want.x, tol);
  EXPECT_NEAR(got.y, want.y, tol);
  EXPECT_NEAR(got.z, want.z, tol);
}

// Vertex v of m in the world: its float position plus the mesh's offset (scenes::Mesh::offset).
inline void expect_world(const spadgen::scenes::Mesh& m, size_t v, const glm::dvec3& want, double tol = 1e-6) {
  const glm::dvec3 got = glm::dvec3(m.positions[v]) + m.offset;
  EXPECT_NEAR(got.x, want.x, tol);
  EXPECT_NEAR(got.y, want.y, tol);
  EXPECT_NEAR(got.z, want.z, tol);
}

inline glm::dvec3 face_normal(const spadgen::scenes::Mesh& m, size_t t) {
  const glm::dvec3 a(m.positions[m.indices[3 * t]]), b(m.positions[m.indices[3 * t + 1]]),
      c(m.positions[m.indices[3 * t + 2]]);
  return glm::normalize(glm::cross(b - a, c - a));
}

inline std::string load_error(const std::string& path, const std::string& scene = "") {
  try {
    load_gltf(path, scene);
  } catch (const Error& e) {
    return e.what();
  }
  ADD_FAILURE() << "no spadgen::Error for " << path;
  return "";
}

inline bool has_warning(const Scene& s, const std::string& part) {
  for (const std::string& w : s.warnings)
    if (w.find(part) != std::string::npos) return true;
  return false;
}

}  // namespace spadgen::test_gltf
