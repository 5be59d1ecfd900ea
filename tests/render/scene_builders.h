// Scenes built in code for the renderer's tests and benchmark: quads, box plates, UV spheres.
#pragma once
#include <glm/glm.hpp>

#include <cmath>
#include <string>

#include "core/config.h"
#include "scenes/scene.h"

namespace spadgen::render::test {

inline int add_material(scenes::Scene& s, scenes::Material m) {
  s.materials.push_back(std::move(m));
  return static_cast<int>(s.materials.size()) - 1;
}

inline scenes::Material lambertian(float albedo, bool double_sided = true) {
  scenes::Material m;
  m.name = "lambert";
  m.base_color = {albedo, albedo, albedo, 1};
  m.metallic = 0.0f;
  m.roughness = 1.0f;
  m.double_sided = double_sided;
  return m;
}

inline scenes::Material glass(float ior, float thickness_m, float roughness = 0.0f) {
  scenes::Material m;
  m.name = "glass";
  m.metallic = 0.0f;
  m.roughness = roughness;
  m.transmission = 1.0f;
  m.ior = ior;
  m.thickness_m = thickness_m;
  m.double_sided = true;
  return m;
}

// A quad centred at c spanned by half-vectors a and b; front side (counter-clockwise) along a x b.
inline int add_quad(scenes::Scene& s, glm::vec3 c, glm::vec3 a, glm::vec3 b, int material) {
  scenes::Mesh m;
  m.name = "quad" + std::to_string(s.meshes.size());
  m.positions = {c - a - b, c + a - b, c + a + b, c - a + b};
  m.indices = {0, 1, 2, 0, 2, 3};
  m.material = material;
  s.meshes.push_back(std::move(m));
  return static_cast<int>(s.meshes.size()) - 1;
}

// An axis-aligned box [lo, hi] with outward (counter-clockwise) faces; with top_material, its top face (z = hi)
// is a mesh of its own of that material (a plate frosted on one side: one volume, two materials).
inline int add_box(scenes::Scene& s, glm::vec3 lo, glm::vec3 hi, int material, int top_material = -1) {
  scenes::Mesh m;
  m.name = "box" + std::to_string(s.meshes.size());
  for (int i = 0; i < 8; ++i) m.positions.push_back({(i & 1) ? hi.x : lo.x, (i & 2) ? hi.y : lo.y, (i & 4) ? hi.z : lo.z});
  // Each face as two triangles, wound so that (v1 - v0) x (v2 - v0) points out of the box.
  const uint32_t faces[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};
  for (const auto& f : faces) {
    if (top_material >= 0 && f[0] == 4) continue;
    m.indices.insert(m.indices.end(), {f[0], f[1], f[2], f[0], f[2], f[3]});
  }
  m.material = material;
  s.meshes.push_back(std::move(m));
  const int box = static_cast<int>(s.meshes.size()) - 1;
  if (top_material >= 0) {
    scenes::Mesh top;
    top.name = "box_top" + std::to_string(s.meshes.size());
    top.positions = {s.meshes[size_t(box)].positions[4], s.meshes[size_t(box)].positions[5], s.meshes[size_t(box)].positions[7],
                     s.meshes[size_t(box)].positions[6]};
    top.indices = {0, 1, 2, 0, 2, 3};
    top.material = top_material;
    s.meshes[size_t(box)].gltf_node = top.gltf_node = box;  // (one volume: the meshes of one node)
    s.meshes.push_back(std::move(top));
  }
  return box;
}

// A UV sphere with outward faces and vertex normals; inward = true flips winding and normals.
inline int add_sphere(scenes::Scene& s, glm::vec3 centre, float radius, int rings, int segments, int material,
                      bool inward = false) {
  scenes::Mesh m;
  m.name = "sphere" + std::to_string(s.meshes.size());
  const double pi = 3.14159265358979323846;
  for (int i = 0; i <= rings; ++i)
    for (int j = 0; j <= segments; ++j) {
      const double th = pi * i / rings, ph = 2 * pi * j / segments;
      const glm::dvec3 n(std::sin(th) * std::cos(ph), std::cos(th), -std::sin(th) * std::sin(ph));
      m.positions.push_back(centre + radius * glm::vec3(n));
      m.normals.push_back(glm::vec3(inward ? -n : n));
    }
  auto id = [&](int i, int j) { return static_cast<uint32_t>(i * (segments + 1) + j); };
  for (int i = 0; i < rings; ++i)
    for (int j = 0; j < segments; ++j) {
      uint32_t a = id(i, j), b = id(i + 1, j), c = id(i + 1, j + 1), d = id(i, j + 1);
      if (inward) std::swap(b, d);
      if (i != 0) m.indices.insert(m.indices.end(), {a, b, c});
      if (i != rings - 1) m.indices.insert(m.indices.end(), {a, c, d});
    }
  m.material = material;
  s.meshes.push_back(std::move(m));
  return static_cast<int>(s.meshes.size()) - 1;
}

// The paper's pixel A fill factor, which test_config gives every row.
inline constexpr double kTestFillFactor = 0.07;

// A small camera at the origin looking down -z, the paper's pixel, one fill factor.
inline RenderStageConfig test_config(int width, int height, double focal_length_m) {
  RenderStageConfig c;
  c.camera.width_px = width;
  c.camera.height_px = height;
  c.camera.position_m = {0, 0, 0};
  c.camera.look_at_m = {0, 0, -1};
  c.camera.up = {0, 1, 0};
  c.camera.focal_length_m = focal_length_m;
  c.camera.f_number = 1.4;
  c.row_fill_factor.assign(static_cast<size_t>(height), kTestFillFactor);
  c.laser.average_power_W = 2e-3;
  c.laser.repetition_rate_Hz = 40e6;
  c.laser.wavelength_m = 637e-9;
  c.ambient.illuminance_lux = 0.0;
  c.render.samples_per_pixel = 16;
  c.render.max_bounces = 4;
  c.light_seed = 7;
  return c;
}

}  // namespace spadgen::render::test
