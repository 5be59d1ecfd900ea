// Objects of the ground truth: glTF nodes with meshes, their slots along the pixel-centre ray, and the
// split of each pixel's laser light into the direct light of each object and the indirect rest.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <numeric>

#include "core/units.h"
#include "render/renderer.h"
#include "scene_builders.h"

namespace spadgen::render {
namespace {

using test::add_box;
using test::add_material;
using test::add_quad;
using test::add_sphere;
using test::test_config;

double sum_slots(const GroundTruthTile& gt, size_t i) {
  const auto L = size_t(gt.max_layers);
  double s = double(gt.direct_other_laser[i]) + double(gt.indirect_laser[i]);
  for (size_t j = 0; j < L; ++j) s += gt.object_laser[i * L + j];
  return s;
}

TEST(Objects, OneObjectPerGltfNodeInNodeOrderAndOnePerMeshWithoutNode) {
  scenes::Scene s;
  s.nodes.resize(4);
  s.nodes[1].name = "sphere";
  s.nodes[3].name = "plate";
  const int m = add_material(s, test::lambertian(0.5f));
  add_quad(s, {0, 0, -1}, {1, 0, 0}, {0, 1, 0}, m);  // plate, primitive 0
  add_quad(s, {0, 0, -2}, {1, 0, 0}, {0, 1, 0}, m);  // a mesh built without a node
  add_quad(s, {0, 0, -3}, {1, 0, 0}, {0, 1, 0}, m);  // sphere
  add_quad(s, {0, 0, -4}, {1, 0, 0}, {0, 1, 0}, m);  // plate, primitive 1
  s.meshes[0].gltf_node = 3, s.meshes[2].gltf_node = 1, s.meshes[3].gltf_node = 3;
  const scenes::Objects o = scenes::objects_of(s);
  ASSERT_EQ(o.list.size(), 3u);
  EXPECT_EQ(o.list[0].name, "sphere");
  EXPECT_EQ(o.list[0].node, 1);
  EXPECT_EQ(o.list[0].meshes, std::vector<int>{2});
  EXPECT_EQ(o.list[1].name, "plate");
  EXPECT_EQ(o.list[1].meshes, (std::vector<int>{0, 3}));
  EXPECT_EQ(o.list[2].node, -1);
  EXPECT_EQ(o.list[2].meshes, std::vector<int>{1});
  EXPECT_EQ(o.mesh_object, (std::vector<int>{1, 2, 0, 1}));
}

// A smooth 2 mm plate in front of a Lambertian sphere: three layers, two objects. The plate has no
// non-delta vertex, so it returns nothing directly; the sphere seen through it is direct.
TEST(Objects, SmoothPlateOverSphereIsTwoObjectsAtTheirFirstLayers) {
  scenes::Scene s;
  const int glass = add_material(s, test::glass(1.5f, 0.002f));
  add_box(s, {-0.1f, -0.1f, -0.452f}, {0.1f, 0.1f, -0.45f}, glass);
  add_sphere(s, {0, 0, -0.85f}, 0.1f, 96, 192, add_material(s, test::lambertian(0.6f)));
  RenderStageConfig c = test_config(16, 16, 12e-3);
  c.render.max_layers = 4;
  Renderer r(s, c);
  ASSERT_EQ(r.glint_pixels(), (std::vector<std::pair<int, int>>{{8, 8}}));
  const PixelRect rect{6, 6, 4, 4};
  GroundTruthTile gt = r.ground_truth(rect);
  const TimeAxis axis{0.0, 10e-12, 1000, 25e-9};
  const TransientTile t = r.transient(rect, rect, axis, nullptr, &gt);
  const size_t L = 4;
  for (size_t i = 0; i < size_t(rect.count()); ++i) {
    ASSERT_EQ(gt.layer_count[i], 3);
    ASSERT_EQ(gt.object_count[i], 2);
    EXPECT_EQ(gt.object_id[i], 0);
    EXPECT_EQ(gt.object_slot_id[i * L + 0], 0);
    EXPECT_EQ(gt.object_slot_id[i * L + 1], 1);
    EXPECT_EQ(gt.object_slot_id[i * L + 2], -1);
    EXPECT_EQ(gt.object_range[i * L + 0], gt.layer_range[i * L + 0]);
    EXPECT_EQ(gt.object_range[i * L + 1], gt.layer_range[i * L + 2]);  // the back face adds no object
    EXPECT_EQ(gt.object_transmittance[i * L + 1], gt.layer_transmittance[i * L + 2]);
    EXPECT_TRUE(std::isinf(gt.object_range[i * L + 2]));
    // (the plate's mirror image of the laser, on the axis in pixel (8, 8), is its own direct return there: a glint)
    if (rect.x0 + int(i) % rect.width == 8 && rect.y0 + int(i) / rect.width == 8) {
      EXPECT_GT(gt.object_laser[i * L + 0], 100.0f * gt.object_laser[i * L + 1]);
    } else {
      EXPECT_EQ(gt.object_laser[i * L + 0], 0.0f);
      EXPECT_GT(gt.object_laser[i * L + 1], 0.5f * float(t.laser_total[i]));
    }
    EXPECT_EQ(gt.object_laser[i * L + 2], 0.0f);
    EXPECT_NEAR(sum_slots(gt, i), t.laser_total[i], 1e-5 * t.laser_total[i]);
    // The returns' optical paths, the laser at the camera: the plate's front face 2 x its range; the
    // sphere 2 x its range and, both ways, (n - 1) x the straight line's chord through the plate.
    const double chord = double(gt.layer_range[i * L + 1]) - double(gt.layer_range[i * L + 0]);
    EXPECT_NEAR(gt.object_path[i * L + 0], 2.0 * gt.object_range[i * L + 0], 1e-6);
    EXPECT_NEAR(gt.object_path[i * L + 1], 2.0 * gt.object_range[i * L + 1] + 2.0 * 0.5 * chord, 1e-6);
    EXPECT_GT(chord, 0.002);  // the straight line's slant
    EXPECT_LT(chord, 0.00201);
    EXPECT_TRUE(std::isinf(gt.object_path[i * L + 2]));
  }
  // The laser 5 cm in front of the camera (laser.offset_m, camera coordinates): the front face at z =
  // -0.45 is range + |P - L| away, |P - L|^2 = range^2 - 2 P.L + L.L with P.L = 0.45 x 0.05.
  c.laser.offset_m = {0, 0, -0.05};
  const GroundTruthTile off = Renderer(s, c).ground_truth(rect);
  for (size_t i = 0; i < size_t(rect.count()); ++i) {
    const double range = off.object_range[i * L + 0];
    EXPECT_NEAR(off.object_path[i * L + 0], range + std::sqrt(range * range - 2 * 0.45 * 0.05 + 0.05 * 0.05), 1e-6);
  }
}

// A lone Lambertian plane: all its light is its own direct return, the camera equation's.
TEST(Objects, LambertianPlaneReturnsAllItsLightDirectly) {
  scenes::Scene s;
  add_quad(s, {0, 0, -1}, {5, 0, 0}, {0, 5, 0}, add_material(s, test::lambertian(0.6f)));
  RenderStageConfig c = test_config(8, 8, 12e-3);
  c.render.split_direct_indirect = true;
  Renderer r(s, c);
  const PixelRect rect{0, 0, 8, 8};
  GroundTruthTile gt = r.ground_truth(rect);
  const TimeAxis axis{0.0, 10e-12, 1000, 25e-9};
  const TransientTile t = r.transient(rect, rect, axis, nullptr, &gt);
  const auto L = size_t(gt.max_layers);
  // rho I p^2 FF T / (4 N^2 d^2) at d = 1 m, I the flood's intensity over its cone to the sensor's corner.
  const double alpha = std::atan(std::sqrt(2.0) * 4 * c.camera.pixel_pitch_m / c.camera.focal_length_m);
  const double intensity = r.photons_per_pulse() / (2 * kPi * (1 - std::cos(alpha)));
  const double on_axis = 0.6 * intensity * std::pow(c.camera.pixel_pitch_m, 2) * c.row_fill_factor[0] *
                         c.camera.optics_transmission / (4 * std::pow(c.camera.f_number, 2));
  for (size_t i = 0; i < size_t(rect.count()); ++i) {
    ASSERT_EQ(gt.object_count[i], 1);
    // The same contributions summed in the same order: the float of the same double.
    EXPECT_EQ(gt.object_laser[i * L], static_cast<float>(t.laser_total[i]));
    double direct = 0.0;
    for (int64_t b = 0; b < axis.bins; ++b)
      direct += double(t.transient[i * size_t(axis.bins) + size_t(b)]) - t.transient_indirect[i * size_t(axis.bins) + size_t(b)];
    EXPECT_NEAR(gt.object_laser[i * L], direct, 1e-6 * direct);
    EXPECT_EQ(gt.indirect_laser[i], 0.0f);
    EXPECT_EQ(gt.direct_other_laser[i], 0.0f);
    // Within the narrow field (0.16 degrees) the falloff is below 1e-5: the on-axis closed form.
    EXPECT_NEAR(gt.object_laser[i * L], on_axis, 1e-4 * on_axis);
  }
}

// An open corner: interreflections are indirect, and the direct light of every wall equals the
// max_bounces 1 render; at the walls' seams jittered samples see the neighbouring wall.
TEST(Objects, CornerSplitsIntoDirectPerWallOtherWallsAndIndirect) {
  scenes::Scene s;
  const int m = add_material(s, test::lambertian(0.7f));
  add_quad(s, {0.3f, 0.3f, -1.0f}, {0.3f, 0, 0}, {0, 0.3f, 0}, m);   // back wall, facing +z
  add_quad(s, {0, 0.3f, -0.7f}, {0, 0, 0.3f}, {0, 0.3f, 0}, m);      // left wall, facing +x
  add_quad(s, {0.3f, 0, -0.7f}, {0.3f, 0, 0}, {0, 0, -0.3f}, m);     // floor, facing +y
  RenderStageConfig c = test_config(16, 16, 2e-4);
  c.camera.position_m = {0.2, 0.2, 0};
  c.camera.look_at_m = {0.2, 0.2, -1};
  c.render.split_direct_indirect = true;
  const TimeAxis axis{0.0, 4e-12, 10000, 0.0};
  const PixelRect all{0, 0, 16, 16};
  Renderer r(s, c);
  GroundTruthTile gt = r.ground_truth(all);
  const TransientTile t = r.transient(all, all, axis, nullptr, &gt);
  RenderStageConfig c1 = c;
  c1.render.max_bounces = 1;
  const TransientTile one = Renderer(s, c1).transient(all, all, axis);
  // Another tile split gives the same bits.
  GroundTruthTile part = r.ground_truth({3, 5, 7, 6});
  r.transient({3, 5, 7, 6}, {3, 5, 7, 6}, axis, nullptr, &part);
  const auto L = size_t(gt.max_layers);
  int silhouettes = 0, with_indirect = 0;
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 16; ++x) {
      const auto i = size_t(all.index(x, y));
      double indirect = 0.0;
      for (int64_t b = 0; b < axis.bins; ++b) indirect += t.transient_indirect[i * size_t(axis.bins) + size_t(b)];
      EXPECT_NEAR(gt.indirect_laser[i], indirect, 1e-5 * t.laser_total[i]);
      with_indirect += gt.indirect_laser[i] > 0.0f;
      EXPECT_NEAR(gt.object_laser[i * L] + gt.direct_other_laser[i], one.laser_total[i], 1e-6 * t.laser_total[i]);
      EXPECT_NEAR(sum_slots(gt, i), t.laser_total[i], 1e-5 * t.laser_total[i]);
      silhouettes += gt.direct_other_laser[i] > 0.0f;
      if (x >= 3 && x < 10 && y >= 5 && y < 11) {
        const auto k = size_t(part.rect.index(x, y));
        for (size_t j = 0; j < L; ++j) EXPECT_EQ(part.object_laser[k * L + j], gt.object_laser[i * L + j]);
        EXPECT_EQ(part.direct_other_laser[k], gt.direct_other_laser[i]);
        EXPECT_EQ(part.indirect_laser[k], gt.indirect_laser[i]);
      }
    }
  EXPECT_GT(with_indirect, 200);  // 16 paths may all miss the other walls
  EXPECT_GT(silhouettes, 0);
  EXPECT_LT(silhouettes, 128);
}


// The renderer's copy of the scene (centred on its camera) shares the decoded texels with the loaded scene
// rather than copying them: a texture-heavy scene holds its textures once (the test chart's 2048 x 2048
// texture was held twice, 16.8 MB more at the run's peak).
TEST(Objects, TheRenderersCopyOfTheSceneSharesItsTexels) {
  scenes::Scene s;
  scenes::Material m = test::lambertian(0.5f);
  m.base_color_texture = 0;
  add_quad(s, {0, 0, -1}, {0.5f, 0, 0}, {0, 0.5f, 0}, add_material(s, m));
  scenes::Texture t;
  t.width = t.height = 2;
  t.texels = std::make_shared<const std::vector<uint8_t>>(16, uint8_t{200});
  s.textures.push_back(t);
  ASSERT_EQ(s.textures[0].texels.use_count(), 2);  // s and t
  {
    const Renderer r(s, test_config(8, 8, 12e-3));
    EXPECT_EQ(s.textures[0].texels.use_count(), 3);  // and the renderer's copy
  }
  EXPECT_EQ(s.textures[0].texels.use_count(), 2);
}

}  // namespace
}  // namespace spadgen::render
