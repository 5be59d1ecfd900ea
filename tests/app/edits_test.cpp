// The scene file's edits of the glTF's nodes and materials, end to end: what the program writes when a node
// moves or a material changes, against the geometry and the light transport; the resolved scene of
// metadata.json reproducing an edited run; the names `spadgen info` lists; what sense refuses.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "app_fixture.h"
#include "writers/writers.h"

namespace {
using namespace spadgen::testing;
using ::testing::HasSubstr;

// The paper's flat target (a Lambertian plane at z = 0 facing the camera at z = 1 m, laser at the camera)
// on a 16 x 16 crop around the optical axis, with the gate sweep around its return.
const std::string kFlat = kScenes +
                          "flat_target.json -q --set camera.crop=[504,242,16,16] --set render.samples_per_pixel=2 "
                          "--set acquisition.gate_sweep.start_ns=6.5 --set acquisition.gate_sweep.stop_ns=8 "
                          "--set outputs.previews=false";

spadgen::writers::ExrData exr(const fs::path& p) { return spadgen::writers::read_exr(p.string()); }

// Moving the target 0.1 m towards the camera (its node's translation, z from the glTF's 0 to 0.1) moves its
// depth z from 1 m to 0.9 m, and shortens each pixel's ray to it by 0.1 m over the cosine of the ray's angle
// to the axis, z / range. The laser light follows: the flood's irradiance, and so what a pixel receives,
// goes as 1 / d^2.
TEST_F(App, MovingANodeMovesTheGroundTruthByTheGeometrysAmount) {
  ASSERT_EQ(sh("run " + kFlat + " -o " + (dir_ / "a").string()).code, 0);
  const Result r = sh("run " + kFlat + " --set nodes.target.translation_m[2]=0.1 -o " + (dir_ / "b").string());
  ASSERT_EQ(r.code, 0) << r.output;
  const auto a = exr(dir_ / "a/ground_truth.exr"), b = exr(dir_ / "b/ground_truth.exr");
  const auto &range_a = a.channels.at("range"), &range_b = b.channels.at("range");
  const auto &z_a = a.channels.at("z"), &z_b = b.channels.at("z");
  const auto laser_a = exr(dir_ / "a/laser.exr").channels.at("photons_per_pulse");
  const auto laser_b = exr(dir_ / "b/laser.exr").channels.at("photons_per_pulse");
  ASSERT_EQ(range_a.size(), 256u);
  for (size_t i = 0; i < range_a.size(); ++i) {
    ASSERT_NEAR(z_a[i], 1.0, 1e-6) << i;
    EXPECT_NEAR(z_b[i], 0.9, 1e-6) << i;
    EXPECT_NEAR(range_b[i], range_a[i] - 0.1 * range_a[i] / z_a[i], 1e-6) << i;
    EXPECT_NEAR(laser_b[i] / laser_a[i], 1.0 / (0.9 * 0.9), 1e-3) << i;
  }
  const auto meta = nlohmann::json::parse(slurp(dir_ / "b/metadata.json"));
  EXPECT_EQ(meta["resolved_scene"]["nodes"]["target"]["translation_m"].dump(), "[null,null,0.1]");
  // the sweep (6.5-8 ns, around the return at 1 m) begins on the plateau of the nearer target's return in some
  // pixels (it rises at about 6.2 ns, moved by each pixel's gate skew): said, and nothing else
  ASSERT_EQ(meta["warnings"].size(), 1u) << meta["warnings"].dump();
  EXPECT_THAT(meta["warnings"][0].get<std::string>(), HasSubstr("of the objects' returns along the rays"));
  EXPECT_TRUE(nlohmann::json::parse(slurp(dir_ / "a/metadata.json"))["warnings"].empty());
}

// An edit of a glTF name holding a newline that the glTF does not have is named on one line, the newline
// escaped (the message broke in two; a reviewer).
TEST_F(App, AnEditOfANameWithANewlineIsNamedOnOneLine) {
  const Result r = sh("run " + kFlat + " --set 'materials.\"no\nsuch\".roughness=0.5' -o " + (dir_ / "a").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_EQ(r.output, "spadgen: error: --set materials.\"no\\nsuch\".roughness: the glTF file " + kScenes +
                          "flat_target.gltf has no material named \"no\\nsuch\" (its materials: \"white_paper\")\n");
}

// Half the albedo of a Lambertian target lit directly gives half the laser light, bit for bit up to float
// rounding: the paths sampled do not depend on the albedo (the plane's only lobe is the diffuse one; the
// path continues by cosine sampling whatever its weight, and with max_bounces 2 Russian roulette never
// starts), so the same seed draws the same paths and each one's contribution is scaled by exactly 0.5.
TEST_F(App, HalvingABaseColourHalvesTheLaserLight) {
  ASSERT_EQ(sh("run " + kFlat + " -o " + (dir_ / "a").string()).code, 0);
  const Result r = sh("run " + kFlat + " --set materials.white_paper.base_color=[0.3,0.3,0.3] -o " + (dir_ / "b").string());
  ASSERT_EQ(r.code, 0) << r.output;
  const auto a = exr(dir_ / "a/laser.exr").channels.at("photons_per_pulse");
  const auto b = exr(dir_ / "b/laser.exr").channels.at("photons_per_pulse");
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i) {
    ASSERT_GT(a[i], 0.0f) << i;
    EXPECT_EQ(b[i], 0.5f * a[i]) << i;
  }
}

// metadata.json's resolved scene reproduces an edited run: the same data, bit for bit (the EXR files differ
// only in their provenance attributes, which name the scene file).
TEST_F(App, TheResolvedSceneOfAnEditedRunReproducesIt) {
  const std::string edits = " --set nodes.target.rotation_deg[0]=5 --set nodes.target.translation_m=[0.01,0,0.05]"
                            " --set materials.white_paper.roughness=0.5 --set materials.white_paper.base_color[1]=0.4";
  ASSERT_EQ(sh("run " + kFlat + edits + " -o " + (dir_ / "a").string()).code, 0);
  auto scene = nlohmann::json::parse(slurp(dir_ / "a/metadata.json"))["resolved_scene"];
  EXPECT_EQ(scene["nodes"], nlohmann::json::parse(R"({"target": {"translation_m": [0.01, 0, 0.05], "rotation_deg": [5, null, null]}})"));
  EXPECT_EQ(scene["materials"], nlohmann::json::parse(R"({"white_paper": {"base_color": [null, 0.4, null], "roughness": 0.5}})"));
  scene["gltf"] = kScenes + "flat_target.gltf";
  std::ofstream(dir_ / "resolved.json") << scene.dump(2);
  const Result r = sh("run " + (dir_ / "resolved.json").string() + " -q -o " + (dir_ / "b").string());
  ASSERT_EQ(r.code, 0) << r.output;
  for (const char* file : {"detection_rate.npy", "counts.npy"})
    EXPECT_TRUE(slurp(dir_ / "a" / file) == slurp(dir_ / "b" / file)) << file << " differs";
  for (const char* file : {"ground_truth.exr", "laser.exr", "ambient.exr", "sensor_maps.exr"})
    EXPECT_TRUE(exr(dir_ / "a" / file).channels == exr(dir_ / "b" / file).channels) << file << " differs";
  EXPECT_EQ(nlohmann::json::parse(slurp(dir_ / "b/metadata.json"))["resolved_scene"], scene);
  // The edits changed the data: the same run without them differs.
  ASSERT_EQ(sh("run " + kFlat + " -o " + (dir_ / "c").string()).code, 0);
  EXPECT_FALSE(exr(dir_ / "a/laser.exr").channels == exr(dir_ / "c/laser.exr").channels);
  EXPECT_FALSE(exr(dir_ / "a/ground_truth.exr").channels == exr(dir_ / "c/ground_truth.exr").channels);
}

// A name the glTF does not have stops the run before anything is written, with the names it has, named as
// the user gave it: the --set key, else the scene file and its key (it was "/nodes/targte" alone).
TEST_F(App, AnUnknownNodeStopsTheRunWithTheGltfsNames) {
  Result r = sh("run " + kFlat + " --set nodes.targte.scale=[1,1,1] -o " + (dir_ / "a").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("spadgen: error: --set nodes.targte.scale: the glTF file " + kScenes + "flat_target.gltf has no node named "
                                  "\"targte\"; did you mean \"target\"? (its nodes: \"spad_camera\", \"target\")"));
  EXPECT_FALSE(fs::exists(dir_ / "a"));
  fs::create_directories(dir_);
  for (const char* f : {"flat_target.gltf"}) fs::copy_file(kScenes + f, dir_ / f);
  std::string scene = slurp(kScenes + "flat_target.json");
  scene.replace(scene.rfind('}'), 1, ", \"materials\": {\"papr\": {\"roughness\": 0.5}}}");
  std::ofstream(dir_ / "edited.json") << scene;
  r = sh("info " + (dir_ / "edited.json").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("spadgen: error: " + (dir_ / "edited.json").string() + ": /materials/papr: the glTF file "));
}

// info lists every node and material by name, the names the scene file's sections take.
TEST(AppCommands, InfoListsTheNodeAndMaterialNames) {
  const Result r = sh("info " + kScenes + "multi_object.json --set nodes.sphere.translation_m[0]=0.05");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("nodes: 3\n  0 'plate', at (-0.175, 0, -0.45)\n  1 'sphere', at (0.05, 0, -0.85)\n"
                                  "  2 'spad_camera', at (0, 0, 0)\n"));
  EXPECT_THAT(r.output, HasSubstr("0 'plastic_plate': "));
  EXPECT_THAT(r.output, HasSubstr("1 'sphere_white': "));
  // and the ground truth's objects by the ids ground_truth.exr and evaluate give them (the camera has no mesh)
  EXPECT_THAT(r.output, HasSubstr("objects (ground-truth ids): 2\n  0 'plate', 1 mesh\n  1 'sphere', 1 mesh\n"));
}

}  // namespace
