// libFuzzer harness of the glTF loader: the input is a .gltf (JSON) or .glb file's bytes, loaded as if it
// lay in a folder holding one buffer file (buffer.bin) and one image (image.png) it may reference. Every
// input must end in a Scene or a spadgen::Error; any other exception, a crash, a sanitizer report or a
// Scene that breaks the loader's promises (indices inside their mesh, finite bounded coordinates,
// attributes one per vertex, materials and textures that exist) is a finding.
#include <unistd.h>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "fuzz_common.h"
#include "scenes/scene.h"

namespace {

namespace fs = std::filesystem;
using spadgen::fuzz::broken;
using spadgen::scenes::Scene;

fs::path g_dir;

// A 2x2 RGBA PNG.
const unsigned char kPng[] = {
    0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a, 0x00, 0x00, 0x00, 0x0d, 0x49, 0x48, 0x44, 0x52, 0x00, 0x00, 0x00,
    0x02, 0x00, 0x00, 0x00, 0x02, 0x08, 0x06, 0x00, 0x00, 0x00, 0x72, 0xb6, 0x0d, 0x24, 0x00, 0x00, 0x00, 0x13, 0x49,
    0x44, 0x41, 0x54, 0x78, 0x9c, 0x63, 0xf8, 0xcf, 0xc0, 0xf0, 0x1f, 0x0c, 0x81, 0x34, 0x08, 0x34, 0x00, 0x00, 0x49,
    0x49, 0x09, 0x78, 0x28, 0xa0, 0xdb, 0x77, 0x00, 0x00, 0x00, 0x00, 0x49, 0x45, 0x4e, 0x44, 0xae, 0x42, 0x60, 0x82};

void remove_dir() {
  std::error_code ec;
  fs::remove_all(g_dir, ec);
}

// A world point (the loader checks every vertex within +-1e9 m; positions are measured from the mesh's
// offset, within half its 64 m grid of the node's place).
bool finite_bounded(const glm::dvec3& p) {
  for (int i = 0; i < 3; ++i)
    if (!std::isfinite(p[i]) || std::fabs(p[i]) > 1e9 + 64.0) return false;
  return true;
}

void check(const Scene& s) {
  for (const spadgen::scenes::Mesh& m : s.meshes) {
    const size_t n = m.positions.size();
    if (m.indices.size() % 3 != 0) broken(m.name + ": indices not a multiple of 3");
    for (uint32_t i : m.indices)
      if (i >= n) broken(m.name + ": index past the vertices");
    for (const glm::vec3& p : m.positions)
      if (!finite_bounded(glm::dvec3(p) + m.offset)) broken(m.name + ": a vertex not finite or beyond 1e9 m");
    if (!m.normals.empty() && m.normals.size() != n) broken(m.name + ": normals not one per vertex");
    for (const glm::vec3& v : m.normals)
      if (!std::isfinite(v.x) || !std::isfinite(v.y) || !std::isfinite(v.z)) broken(m.name + ": a normal not finite");
    for (const auto* t : {&m.texcoords0, &m.texcoords1}) {
      if (!t->empty() && t->size() != n) broken(m.name + ": texture coordinates not one per vertex");
      for (const glm::vec2& uv : *t)
        if (!(std::fabs(uv.x) <= 4096.0f) || !(std::fabs(uv.y) <= 4096.0f)) broken(m.name + ": texture coordinates beyond 4096");
    }
    if (m.material < -1 || m.material >= static_cast<int>(s.materials.size())) broken(m.name + ": no such material");
  }
  for (const spadgen::scenes::Material& m : s.materials) {
    if (m.base_color_texture < -1 || m.base_color_texture >= static_cast<int>(s.textures.size()))
      broken(m.name + ": no such texture");
    for (float v : {m.base_color.r, m.base_color.g, m.base_color.b, m.base_color.a, m.metallic, m.roughness, m.transmission,
                    m.ior, m.thickness_m, m.emissive.r, m.emissive.g, m.emissive.b})
      if (!std::isfinite(v)) broken(m.name + ": a material parameter not finite");
  }
  for (const spadgen::scenes::Texture& t : s.textures)
    if (t.width <= 0 || t.height <= 0 || t.rgba().size() != size_t(t.width) * size_t(t.height) * 4)
      broken(t.name + ": texel count does not match the size");
  for (const spadgen::scenes::Camera& c : s.cameras) {
    if (!(c.yfov_rad > 0.0 && c.yfov_rad < 3.1416)) broken(c.name + ": camera field of view out of (0, pi)");
    if (!std::isfinite(c.aspect_ratio) || c.aspect_ratio < 0.0) broken(c.name + ": camera aspect ratio not finite");
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j)
        if (!std::isfinite(c.world_from_camera[i][j])) broken(c.name + ": camera transform not finite");
  }
  for (const spadgen::scenes::Light& l : s.lights) {
    if (!std::isfinite(l.intensity) || !std::isfinite(l.direction.x) || !std::isfinite(l.direction.y) ||
        !std::isfinite(l.direction.z))
      broken(l.name + ": light parameters not finite");
    // A directional light has no position.
    if (l.type != spadgen::scenes::Light::Type::Directional &&
        !(std::fabs(l.position.x) <= 1e9 && std::fabs(l.position.y) <= 1e9 && std::fabs(l.position.z) <= 1e9))
      broken(l.name + ": light position not finite or beyond 1e9 m");
  }
  (void)spadgen::scenes::summarize(s);
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  g_dir = fs::temp_directory_path() / ("spadgen_fuzz_gltf_" + std::to_string(::getpid()));
  fs::create_directories(g_dir);
  std::atexit(remove_dir);
  // A triangle (3 float VEC3) and its indices (3 UNSIGNED_SHORT), as buffers may hold them.
  const float tri[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  const uint16_t idx[4] = {0, 1, 2, 0};
  std::ofstream bin(g_dir / "buffer.bin", std::ios::binary);
  bin.write(reinterpret_cast<const char*>(tri), sizeof tri);
  bin.write(reinterpret_cast<const char*>(idx), sizeof idx);
  std::ofstream png(g_dir / "image.png", std::ios::binary);
  png.write(reinterpret_cast<const char*>(kPng), sizeof kPng);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  try {
    check(spadgen::scenes::parse_gltf(bytes, (g_dir / "input.gltf").string()));
  } catch (const spadgen::Error& e) {
    spadgen::fuzz::refused(e);
  }
  return 0;
}
