#include "render_setup.h"

#include <benchmark/benchmark.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <vector>

#include "core/units.h"
#include "scenes/scene_file.h"
#include "sensor/model/pixel_layout.h"

namespace spadgen::bench {
namespace {

// The equivalent of scenes/paper/multi_object.json when the shipped file is not there: a 2 mm plate of
// ior 1.5, front face at 0.45 m, covering the left half, in front of a sphere whose nearest point is 0.75 m.
Setup build_in_code() {
  Setup s;
  s.source = "built in code";
  scenes::Material plate;
  plate.name = "plastic_plate";
  plate.metallic = 0;
  plate.roughness = 0.1f;
  plate.transmission = 1;
  plate.ior = 1.5f;
  plate.thickness_m = 0.002f;
  s.scene.materials.push_back(plate);
  scenes::Material white;
  white.base_color = {0.8f, 0.8f, 0.8f, 1};
  white.metallic = 0;
  s.scene.materials.push_back(white);
  scenes::Mesh box;
  const glm::vec3 lo(-0.35f, -0.2f, -0.452f), hi(0.0f, 0.2f, -0.45f);
  for (int i = 0; i < 8; ++i) box.positions.push_back({(i & 1) ? hi.x : lo.x, (i & 2) ? hi.y : lo.y, (i & 4) ? hi.z : lo.z});
  const uint32_t f[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};
  for (const auto& q : f) box.indices.insert(box.indices.end(), {q[0], q[1], q[2], q[0], q[2], q[3]});
  box.material = 0;
  s.scene.meshes.push_back(box);
  scenes::Mesh sphere;
  const int rings = 128, segs = 256;
  for (int i = 0; i <= rings; ++i)
    for (int j = 0; j <= segs; ++j) {
      const double th = kPi * i / rings, ph = 2 * kPi * j / segs;
      const glm::vec3 n(float(std::sin(th) * std::cos(ph)), float(std::cos(th)), float(-std::sin(th) * std::sin(ph)));
      sphere.positions.push_back(glm::vec3(0, 0, -0.85f) + 0.1f * n);
      sphere.normals.push_back(n);
    }
  for (int i = 0; i < rings; ++i)
    for (int j = 0; j < segs; ++j) {
      const auto a = uint32_t(i * (segs + 1) + j), b = a + uint32_t(segs + 1);
      sphere.indices.insert(sphere.indices.end(), {a, b, b + 1, a, b + 1, a + 1});
    }
  sphere.material = 1;
  s.scene.meshes.push_back(sphere);
  s.config.camera.height_px = 1000;
  s.config.laser.wavelength_m = 510e-9;
  s.config.render.max_bounces = 8;
  return s;
}

}  // namespace

Setup& setup() {
  static Setup s = [] {
    const std::string json = std::string(SPADGEN_SOURCE_DIR) + "/scenes/paper/multi_object.json";
    if (std::filesystem::exists(json)) {
      try {
        Setup r;
        r.config = scenes::load_scene_file(json, {"camera.height_px=1000"}).config;
        r.scene = scenes::load_gltf(r.config.gltf_path, r.config.gltf_scene, r.config.edits);
        r.source = json;
        return r;
      } catch (const std::exception& e) {
        std::fprintf(stderr, "could not load %s (%s); building the scene in code\n", json.c_str(), e.what());
      }
    }
    return build_in_code();
  }();
  return s;
}

RenderStageConfig stage(const RunConfig& c) {
  return render_stage(c, sensor::PixelLayout(c.sensor.preset, c.camera.height_px).row_fill_factor(c.sensor));
}

render::RenderStats render_image(const render::Renderer& r, const RunConfig& c, const TimeAxis& axis,
                                 const PixelRect& region) {
  std::vector<PixelRect> tiles;
  for (int y = region.y0; y < region.y1(); y += 32)
    for (int x = region.x0; x < region.x1(); x += 32)
      tiles.push_back({x, y, std::min(32, region.x1() - x), std::min(32, region.y1() - y)});
  std::vector<render::RenderStats> stats(tiles.size());
  tbb::parallel_for(size_t(0), tiles.size(), [&](size_t i) {
    const TransientTile t = r.transient(tiles[i], tiles[i], axis, &stats[i]);
    benchmark::DoNotOptimize(t.laser_total.data());
  });
  (void)c;
  render::RenderStats total;
  for (const auto& s : stats) {
    total.rays += s.rays;
  }
  return total;
}

}  // namespace spadgen::bench
