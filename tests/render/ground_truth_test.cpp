// Ground truth against closed forms: planes, spheres, plate-and-sphere layers, misses.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "core/error.h"
#include "render/renderer.h"
#include "scene_builders.h"

namespace spadgen::render {
namespace {

using test::add_box;
using test::add_material;
using test::add_quad;
using test::add_sphere;
using test::test_config;

// Unit direction through the centre of pixel (x, y) of a camera at the origin looking down -z.
glm::dvec3 pixel_dir(const RenderStageConfig& c, int x, int y) {
  const double p = c.camera.pixel_pitch_m;
  return glm::normalize(glm::dvec3((x + 0.5 - c.camera.width_px / 2.0) * p, (c.camera.height_px / 2.0 - y - 0.5) * p,
                                   -c.camera.focal_length_m));
}

TEST(GroundTruth, PlaneRangeIsDistanceOverCosine) {
  scenes::Scene s;
  const int mat = add_material(s, test::lambertian(0.6f));
  add_quad(s, {0.2f, -0.1f, -1.3f}, {5, 0, 0}, {0, 5, 0}, mat);
  RenderStageConfig c = test_config(48, 40, 4e-3);  // wide: up to 5 degrees off axis
  Renderer r(s, c);
  const GroundTruthTile gt = r.ground_truth({0, 0, 48, 40});
  for (int y = 0; y < 40; ++y)
    for (int x = 0; x < 48; ++x) {
      const auto i = static_cast<size_t>(gt.rect.index(x, y));
      const double cos_t = -pixel_dir(c, x, y).z;
      EXPECT_NEAR(gt.range[i], 1.3 / cos_t, 2e-6);
      EXPECT_NEAR(gt.z[i], 1.3, 2e-6);
      EXPECT_FLOAT_EQ(gt.normal[3 * i + 2], 1.0f);
      EXPECT_EQ(gt.mesh_id[i], 0);
      EXPECT_EQ(gt.material_id[i], mat);
      ASSERT_EQ(gt.layer_count[i], 1);
      EXPECT_EQ(gt.layer_range[i * size_t(gt.max_layers)], gt.range[i]);
      EXPECT_EQ(gt.layer_transmittance[i * size_t(gt.max_layers)], 1.0f);
      EXPECT_TRUE(std::isinf(gt.layer_range[i * size_t(gt.max_layers) + 1]));
    }
}

TEST(GroundTruth, NormalFacesTheCameraAndMissesAreInfinite) {
  scenes::Scene s;
  // Back side towards the camera, double-sided: seen, normal flipped towards the camera.
  add_quad(s, {0, 0, -2}, {0, 0.001f, 0}, {0.001f, 0, 0}, add_material(s, test::lambertian(0.5f)));
  RenderStageConfig c = test_config(16, 16, 12e-3);
  Renderer r(s, c);
  const GroundTruthTile gt = r.ground_truth({0, 0, 16, 16});
  // The quad is 2 mm wide at 2 m: it covers only the central pixels (the footprint is 1.6 mm).
  const auto centre = static_cast<size_t>(gt.rect.index(8, 8));
  EXPECT_NEAR(gt.range[centre], 2.0, 1e-5);
  EXPECT_FLOAT_EQ(gt.normal[3 * centre + 2], 1.0f);
  const auto corner = static_cast<size_t>(gt.rect.index(0, 0));
  EXPECT_TRUE(std::isinf(gt.range[corner]) && gt.range[corner] > 0);
  EXPECT_TRUE(std::isinf(gt.z[corner]));
  EXPECT_EQ(gt.mesh_id[corner], -1);
  EXPECT_EQ(gt.material_id[corner], -1);
  EXPECT_EQ(gt.layer_count[corner], 0);
  EXPECT_EQ(gt.normal[3 * corner], 0.0f);
}

TEST(GroundTruth, SingleSidedBackFacesAreCulled) {
  scenes::Scene s;
  const int one_sided = add_material(s, test::lambertian(0.5f, /*double_sided=*/false));
  add_quad(s, {0, 0, -1}, {0, 1, 0}, {1, 0, 0}, one_sided);  // faces away from the camera
  add_quad(s, {0, 0, -3}, {1, 0, 0}, {0, 1, 0}, one_sided);  // faces the camera
  Renderer r(s, test_config(8, 8, 12e-3));
  const GroundTruthTile gt = r.ground_truth({0, 0, 8, 8});
  EXPECT_NEAR(gt.range[0], 3.0, 1e-4);
  EXPECT_EQ(gt.mesh_id[0], 1);
}

TEST(GroundTruth, SphereMatchesRaySphereIntersection) {
  scenes::Scene s;
  const float radius = 0.1f;
  const glm::dvec3 centre(0.02, -0.01, -0.6);
  const int rings = 128, segments = 256;
  add_sphere(s, glm::vec3(centre), radius, rings, segments, add_material(s, test::lambertian(0.5f)));
  RenderStageConfig c = test_config(64, 64, 2e-3);  // the sphere spans about 40 of the 64 pixels
  Renderer r(s, c);
  const GroundTruthTile gt = r.ground_truth({0, 0, 64, 64});
  // An inscribed polyhedron lies inside the sphere by at most the sagitta over half a cell diagonal.
  const double half_diag = std::sqrt(2.0) * 3.14159265358979 / segments;
  const double sagitta = radius * (1.0 - std::cos(half_diag));
  int hits = 0, misses = 0;
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) {
      const auto i = static_cast<size_t>(gt.rect.index(x, y));
      const glm::dvec3 d = pixel_dir(c, x, y);
      const double b = glm::dot(d, centre), disc = b * b - glm::dot(centre, centre) + double(radius) * radius;
      if (disc > 0.02 * radius * radius) {
        const double t = b - std::sqrt(disc);
        const glm::dvec3 n = glm::normalize(t * d - centre);
        const double cos_inc = -glm::dot(n, d);
        if (cos_inc < 0.3) continue;
        EXPECT_NEAR(gt.range[i], t, sagitta / cos_inc + 1e-6) << x << "," << y;
        EXPECT_NEAR(gt.z[i], -t * d.z, sagitta / cos_inc + 1e-6);
        // Interpolated vertex normals follow the sphere within the cell's angular size.
        const glm::dvec3 gn(gt.normal[3 * i], gt.normal[3 * i + 1], gt.normal[3 * i + 2]);
        EXPECT_GT(glm::dot(gn, n), std::cos(2 * half_diag));
        ++hits;
      } else if (disc < -0.02 * radius * radius) {
        EXPECT_TRUE(std::isinf(gt.range[i]));
        EXPECT_EQ(gt.layer_count[i], 0);
        ++misses;
      }
    }
  EXPECT_GT(hits, 500);
  EXPECT_GT(misses, 500);
}

struct PlateScene {
  scenes::Scene scene;
  float ior = 1.5f, front = 0.45f, thickness = 0.002f, sphere_near = 0.75f, radius = 0.1f;
};

PlateScene plate_and_sphere(float thickness_m, float attenuation_distance_m = std::numeric_limits<float>::infinity(),
                            float attenuation = 1.0f) {
  PlateScene p;
  scenes::Material g = test::glass(p.ior, thickness_m);
  g.attenuation_distance_m = attenuation_distance_m;
  g.attenuation_color = {attenuation, attenuation, attenuation};
  const int glass = add_material(p.scene, g);
  add_box(p.scene, {-0.1f, -0.1f, -p.front - p.thickness}, {0.1f, 0.1f, -p.front}, glass);
  add_sphere(p.scene, {0, 0, -(p.sphere_near + p.radius)}, p.radius, 96, 192, add_material(p.scene, test::lambertian(0.6f)));
  return p;
}

TEST(GroundTruth, PlateAndSphereLayersAtAnalyticDistancesAndTransmittances) {
  for (float thickness_attr : {0.002f, 0.0f}) {  // a volume, and a thin-walled box
    PlateScene p = plate_and_sphere(thickness_attr);
    RenderStageConfig c = test_config(16, 16, 12e-3);
    Renderer r(p.scene, c);
    const GroundTruthTile gt = r.ground_truth({7, 7, 2, 2});  // near the axis: normal incidence within 1e-3 rad
    const double rf = std::pow((p.ior - 1.0) / (p.ior + 1.0), 2.0);
    for (int y = 7; y < 9; ++y)
      for (int x = 7; x < 9; ++x) {
        const auto i = static_cast<size_t>(gt.rect.index(x, y));
        const size_t L = size_t(gt.max_layers);
        const double inv_cos = -1.0 / pixel_dir(c, x, y).z;
        ASSERT_EQ(gt.layer_count[i], 3) << "thickness attribute " << thickness_attr;
        EXPECT_NEAR(gt.layer_range[i * L + 0], p.front * inv_cos, 1e-6);
        EXPECT_NEAR(gt.layer_range[i * L + 1], (p.front + p.thickness) * inv_cos, 1e-6);
        // A vertex sits on the axis; the facets around it fall behind the sphere by at most their sagitta.
        EXPECT_NEAR(gt.layer_range[i * L + 2], p.sphere_near, 6e-5);
        EXPECT_NEAR(gt.layer_transmittance[i * L + 0], 1.0, 1e-7);
        EXPECT_NEAR(gt.layer_transmittance[i * L + 1], 1.0 - rf, 1e-6);
        EXPECT_NEAR(gt.layer_transmittance[i * L + 2], (1.0 - rf) * (1.0 - rf), 1e-6);
        EXPECT_EQ(gt.range[i], gt.layer_range[i * L]);
        EXPECT_EQ(gt.mesh_id[i], 0);
      }
  }
}

// A 2 mm plate seen at 50 degrees (past the critical angle of 41.8 at ior 1.5 for a straight ray leaving
// it), camera and scene 300 m from the origin, where a float's ulp is 31 um: the layers are the plate's two
// faces and the wall, at their distances along the ray, and the light through the plate's parallel faces
// is (1 - F(50 deg))^2 (the refracted light leaves at the angle it came in).
TEST(GroundTruth, TiltedPlateFarFromTheOriginKeepsBothFacesAndItsTransmittance) {
  const float far = -300.0f, front = 0.45f, thickness = 0.002f, wall = 1.0f, ior = 1.5f;
  scenes::Scene s;
  add_box(s, {-1, -1, far - front - thickness}, {1, 1, far - front}, add_material(s, test::glass(ior, thickness)));
  add_quad(s, {0, 0, far - wall}, {3, 0, 0}, {0, 3, 0}, add_material(s, test::lambertian(0.5f)));
  RenderStageConfig c = test_config(16, 16, 12e-3);
  const double angle = 50.0 * kPi / 180.0;
  c.camera.position_m = {0, 0, far};
  c.camera.look_at_m = {std::sin(angle), 0, far - std::cos(angle)};
  Renderer r(s, c);
  const GroundTruthTile gt = r.ground_truth({0, 0, 16, 16});
  int checked = 0;
  for (int y = 7; y < 9; ++y)
    for (int x = 7; x < 9; ++x) {
      const auto i = static_cast<size_t>(gt.rect.index(x, y));
      const size_t L = size_t(gt.max_layers);
      // The pixel's ray in the world: the camera turned by `angle` about +y.
      // The pixel's ray in the world: the camera's frame turned by `angle` about +y (right (cos, 0, sin),
      // forward (sin, 0, -cos)); the plate's normal is +z.
      const glm::dvec3 v = pixel_dir(c, x, y);
      const double cos_plate = -(v.x * std::sin(angle) + v.z * std::cos(angle));
      ASSERT_EQ(gt.layer_count[i], 3) << x << "," << y;
      // The faces where the scene's float coordinates put them (an ulp is 31 um here).
      const auto depth = [&](float z) { return (double(far) - double(z)) / cos_plate; };
      EXPECT_NEAR(gt.layer_range[i * L + 0], depth(far - front), 2e-6);
      EXPECT_NEAR(gt.layer_range[i * L + 1], depth(far - front - thickness), 2e-6);
      EXPECT_NEAR(gt.layer_range[i * L + 2], depth(far - wall), 2e-6);
      // Unpolarised Fresnel reflectance entering glass at that angle.
      const double st2 = (1.0 - cos_plate * cos_plate) / (ior * ior), ct = std::sqrt(1.0 - st2);
      const double rs = std::pow((cos_plate - ior * ct) / (cos_plate + ior * ct), 2.0);
      const double rp = std::pow((ior * cos_plate - ct) / (ior * cos_plate + ct), 2.0);
      const double T = 1.0 - 0.5 * (rs + rp);
      EXPECT_NEAR(gt.layer_transmittance[i * L + 1], T, 1e-5);
      EXPECT_NEAR(gt.layer_transmittance[i * L + 2], T * T, 1e-5);
      EXPECT_GT(gt.layer_transmittance[i * L + 2], 0.5);
      ++checked;
    }
  EXPECT_EQ(checked, 4);
}

TEST(GroundTruth, BeerLambertInsideTheVolumeAndLayerLimit) {
  // glTF: attenuationColor 0.5 after attenuationDistance 4 mm, so 2 mm of glass passes sqrt(0.5).
  PlateScene p = plate_and_sphere(0.002f, 0.004f, 0.5f);
  RenderStageConfig c = test_config(16, 16, 12e-3);
  c.render.max_layers = 2;
  Renderer r(p.scene, c);
  const GroundTruthTile gt = r.ground_truth({8, 8, 1, 1});
  const double rf = std::pow((p.ior - 1.0) / (p.ior + 1.0), 2.0);
  ASSERT_EQ(gt.max_layers, 2);
  EXPECT_EQ(gt.layer_count[0], 2);
  // 1e-5: the plate's 2 mm thickness is the difference of two float coordinates (1.5e-5 relative).
  EXPECT_NEAR(gt.layer_transmittance[1], (1.0 - rf) * std::sqrt(0.5), 1e-5);
  EXPECT_EQ(gt.layers_cut, 1);  // the sphere beyond the plate's two faces has no slot (warned by the app)

  c.render.max_layers = 8;
  Renderer r8(p.scene, c);
  const GroundTruthTile gt8 = r8.ground_truth({8, 8, 1, 1});
  EXPECT_EQ(gt8.layer_count[0], 3);
  EXPECT_NEAR(gt8.layer_transmittance[2], (1.0 - rf) * (1.0 - rf) * std::sqrt(0.5), 1e-5);
}

// Seen at 45 degrees through a 5 cm absorbing slab (attenuation 0.5 after 10 cm), the light crosses it at the
// refracted angle: Beer-Lambert over t / cos(theta_t), as the rendered light (the straight length t / cos(theta)
// gave 9 % less; an auditor's find). Through parallel faces the Fresnel factors are the entering angle's twice.
TEST(GroundTruth, AbsorptionInATiltedSlabFollowsTheRefractedPath) {
  const float thickness = 0.05f, ior = 1.5f;
  scenes::Scene s;
  scenes::Material g = test::glass(ior, thickness);
  g.attenuation_distance_m = 0.1f;
  g.attenuation_color = {0.5f, 0.5f, 0.5f};
  add_box(s, {-3, -3, -0.5f - thickness}, {3, 3, -0.5f}, add_material(s, g));
  add_quad(s, {0, 0, -1.5f}, {5, 0, 0}, {0, 5, 0}, add_material(s, test::lambertian(0.5f)));
  RenderStageConfig c = test_config(16, 16, 12e-3);
  const double angle = 45.0 * kPi / 180.0;
  c.camera.look_at_m = {std::sin(angle), 0, -std::cos(angle)};
  const GroundTruthTile gt = Renderer(s, c).ground_truth({7, 7, 2, 2});
  for (int y = 7; y < 9; ++y)
    for (int x = 7; x < 9; ++x) {
      const auto i = static_cast<size_t>(gt.rect.index(x, y));
      const size_t L = size_t(gt.max_layers);
      const glm::dvec3 v = pixel_dir(c, x, y);
      const double ci = -(v.x * std::sin(angle) + v.z * std::cos(angle));
      const double st2 = (1.0 - ci * ci) / (ior * ior), ct = std::sqrt(1.0 - st2);
      const double rs = std::pow((ci - ior * ct) / (ci + ior * ct), 2.0), rp = std::pow((ior * ci - ct) / (ior * ci + ct), 2.0);
      const double T = 1.0 - 0.5 * (rs + rp), absorbed = std::pow(0.5, double(thickness) / ct / 0.1);
      ASSERT_EQ(gt.layer_count[i], 3) << x << "," << y;
      EXPECT_NEAR(gt.layer_transmittance[i * L + 1] / (T * absorbed), 1.0, 2e-5) << x << "," << y;
      EXPECT_NEAR(gt.layer_transmittance[i * L + 2] / (T * T * absorbed), 1.0, 2e-5) << x << "," << y;
    }
}

// A ground truth is cut (GroundTruthTile::layers_cut) where an object beyond max_layers gets no slot; not where
// all that lies beyond is the back of an object that has one (a closed glass box alone: a false warning).
TEST(GroundTruth, LayersAreCutOnlyWhereAnObjectBeyondHasNoSlot) {
  for (const bool wall : {false, true}) {
    scenes::Scene s;
    add_box(s, {-1, -1, -0.6f}, {1, 1, -0.5f}, add_material(s, test::glass(1.5f, 0.1f)));
    if (wall) add_quad(s, {0, 0, -1}, {2, 0, 0}, {0, 2, 0}, add_material(s, test::lambertian(0.5f)));
    RenderStageConfig c = test_config(8, 8, 12e-3);
    c.render.max_layers = 1;
    const GroundTruthTile gt = Renderer(s, c).ground_truth({0, 0, 8, 8});
    EXPECT_EQ(gt.layers_cut, wall ? 64 : 0) << wall;
    c.render.max_layers = 3;  // the box's two faces and the wall: nothing cut
    EXPECT_EQ(Renderer(s, c).ground_truth({0, 0, 8, 8}).layers_cut, 0) << wall;
  }
}

TEST(GroundTruth, BadInputNamesTheKey) {
  scenes::Scene s;
  add_quad(s, {0, 0, -1}, {1, 0, 0}, {0, 1, 0}, add_material(s, test::lambertian(0.5f)));
  RenderStageConfig c = test_config(8, 8, 12e-3);
  c.camera.look_at_m = {0, 0, 0};
  try {
    Renderer r(s, c);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("camera.look_at_m"), std::string::npos) << e.what();
  }
  c = test_config(8, 8, 12e-3);
  c.camera.up = {0, 0, -2};
  EXPECT_THROW(Renderer(s, c), Error);
  c = test_config(8, 8, 12e-3);
  c.camera.gltf_camera = "nope";
  try {
    Renderer r(s, c);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("camera.gltf_camera"), std::string::npos) << e.what();
  }
  c = test_config(8, 8, 12e-3);
  c.laser.beam = Beam::GltfLight;
  c.laser.gltf_light = "spot";
  try {
    Renderer r(s, c);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("laser.gltf_light"), std::string::npos) << e.what();
  }
  Renderer ok(s, test_config(8, 8, 12e-3));
  EXPECT_THROW(ok.ground_truth({4, 4, 8, 8}), Error);
  // a camera or light whose node is in the file but not in the loaded glTF scene is said to be there (the
  // message listed "cameras: none" although the file had the node)
  scenes::Scene other = s;
  other.nodes.push_back({"C", -1, false, glm::dmat4(1.0)});
  other.nodes.push_back({"spot", -1, false, glm::dmat4(1.0)});
  for (const bool camera : {true, false}) {
    c = test_config(8, 8, 12e-3);
    if (camera) c.camera.gltf_camera = "C";
    else c.laser.beam = Beam::GltfLight, c.laser.gltf_light = "spot";
    try {
      Renderer r(other, c);
      FAIL() << "expected an error";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(std::string("; the file has a node '") + (camera ? "C" : "spot") +
                                           "', but it is not in the glTF scene loaded"),
                std::string::npos)
          << e.what();
    }
  }
}

TEST(GroundTruth, GltfCameraLooksDownItsLocalMinusZ) {
  scenes::Scene s;
  add_quad(s, {3, 0, 0}, {0, 0, 1}, {0, 1, 0}, add_material(s, test::lambertian(0.5f)));  // plane x = 3
  scenes::Camera cam;
  cam.name = "cam";
  // Rotated -90 degrees about +y: local -Z points to world +X.
  cam.world_from_camera = glm::dmat4(glm::dvec4(0, 0, 1, 0), glm::dvec4(0, 1, 0, 0), glm::dvec4(-1, 0, 0, 0),
                                     glm::dvec4(1, 0, 0, 1));
  cam.yfov_rad = 0.5;
  s.cameras.push_back(cam);
  RenderStageConfig c = test_config(10, 10, 12e-3);
  c.camera.gltf_camera = "cam";
  Renderer r(s, c);
  const GroundTruthTile gt = r.ground_truth({0, 0, 10, 10});
  // Camera at x = 1: the plane is 2 m ahead; yfov 0.5 rad over 10 rows gives the corner angle.
  const double f_px = 5.0 / std::tan(0.25);  // focal length in pixels
  EXPECT_NEAR(gt.z[0], 2.0, 1e-5);
  EXPECT_NEAR(gt.range[0], 2.0 * std::sqrt(f_px * f_px + 2 * 4.5 * 4.5) / f_px, 1e-5);
}

}  // namespace
}  // namespace spadgen::render
