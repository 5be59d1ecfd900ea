// The spadgen program as a user runs it: commands, the output folder, determinism across threads and
// tiles, one-pixel replay through a crop, and what bad input does (and does not) write.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include "app_fixture.h"
#include "writers/writers.h"

namespace {
using namespace spadgen::testing;
using ::testing::HasSubstr;


TEST(AppCommands, HelpListsTheCommands) {
  const Result r = sh("--help");
  EXPECT_EQ(r.code, 0);
  EXPECT_THAT(r.output, HasSubstr("run"));
  EXPECT_THAT(r.output, HasSubstr("info"));
  EXPECT_THAT(r.output, HasSubstr("schema"));
  EXPECT_EQ(sh("run --help").code, 0);
  EXPECT_NE(sh("").code, 0);
}

TEST(AppCommands, InfoPrintsTheResolvedSceneAndTheGltf) {
  const Result r = sh("info " + kScenes + "multi_object.json --set laser.average_power_mW=5");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("\"average_power_mW\": 5"));
  EXPECT_THAT(r.output, HasSubstr("KHR_materials_transmission"));
  EXPECT_THAT(r.output, HasSubstr("time axis:"));
  // 1024 x 500 pixels x 351 gates: float32 detection rates 719 MB, uint8 counts 180 MB.
  EXPECT_THAT(r.output, HasSubstr("output sizes: detection_rate.npy 719 MB, counts.npy 180 MB\n"));
}

// The sizes list exactly the stacks the run writes.
TEST(AppCommands, InfoSizesTheStacksTheRunWrites) {
  const Result r = sh("info " + kScenes + "multi_object.json --set outputs.counts=false --set outputs.transient=true "
                      "--set render.split_direct_indirect=true --set camera.crop=[0,0,64,64] --set outputs.expected_counts=true");
  ASSERT_EQ(r.code, 0) << r.output;
  // 64 x 64 x 351 float32: 5.75 MB; 64 x 64 x 2394 bins float32: 39.2 MB each.
  EXPECT_THAT(r.output, HasSubstr("output sizes: expected_counts.npy 5.8 MB, detection_rate.npy 5.8 MB, transient.npy 39 MB, transient_indirect.npy 39 MB\n"));
  // 8 x 8 x 351 float32 and its 128-byte header: 89,984 bytes (it said 1 MB)
  const Result small = sh("info " + kScenes + "multi_object.json --set camera.crop=[0,0,8,8]");
  EXPECT_THAT(small.output, HasSubstr("output sizes: detection_rate.npy 90 kB, counts.npy 22 kB\n"));
}

// The keys the sensor checks against its curves (a PDP above 1, a peak wavelength where the built-in curve is
// zero) are named as every key is: the scene file and the key's pointer, or the --set (they said
// "sensor.pixel_A: ..." with no file, no override and not the key set; an auditor's find).
TEST_F(App, TheSensorsKeyErrorsNameTheFileOrTheOverride) {
  const fs::path scene = dir_ / "s.json";
  std::ofstream(scene) << R"({"gltf": ")" << kScenes << R"(flat_target.gltf", "sensor": {"pixel_A": {"pdp_peak": 1.0}}})";
  for (const std::string& command : std::vector<std::string>{"info " + scene.string(), "run " + scene.string() + " -o " + (dir_ / "out").string()}) {
    const Result r = sh(command);
    EXPECT_EQ(r.code, 1) << r.output;
    EXPECT_THAT(r.output, HasSubstr("spadgen: error: " + scene.string() + ": /sensor/pixel_A/pdp_peak: found 1: the PDP curve reaches 1, "
                                    "and sensor.pixel_A.pdp_nonuniformity 0.014 spreads it to 1.07")) << command;
    EXPECT_FALSE(fs::exists(dir_ / "out"));
  }
  const Result r = sh("info " + kScenes + "flat_target.json --set sensor.pixel_A.pdp_peak_wavelength_nm=200");
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("spadgen: error: --set sensor.pixel_A.pdp_peak_wavelength_nm: found 200 nm, where the built-in PDP "
                                  "curve is zero; expected a wavelength strictly between 300 and 1100 nm"));
  // and transient.npy in the intensity mode without a window (it named the scene file for two --set)
  const Result t = sh("run " + kScenes + "flat_target.json --set acquisition.mode=intensity --set outputs.transient=true -o " +
                      (dir_ / "out").string());
  EXPECT_EQ(t.code, 1) << t.output;
  EXPECT_THAT(t.output, HasSubstr("spadgen: error: --set outputs.transient: found true in the intensity mode, which needs no time bins"));
  EXPECT_FALSE(fs::exists(dir_ / "out"));
}

TEST(AppCommands, SchemaMatchesTheDocs) {
  const Result r = sh("schema");
  ASSERT_EQ(r.code, 0);
  EXPECT_THAT(slurp(std::string(SPADGEN_SOURCE_DIR) + "/docs/scene-file.md"), HasSubstr(r.output));
}

TEST_F(App, RunWritesEveryFileItListsWithConsistentShapes) {
  const Result r = sh("run " + kSmall + " --set outputs.expected_counts=true -o " + (dir_ / "out").string());
  ASSERT_EQ(r.code, 0) << r.output;
  const auto meta = nlohmann::json::parse(slurp(dir_ / "out/metadata.json"));
  for (const auto& f : meta["files"]) EXPECT_TRUE(fs::exists(dir_ / "out" / f.get<std::string>())) << f;
  // the unit of every quantity the files hold (the rates had none: a new user's find)
  EXPECT_THAT(meta.at("units").at("detection_rate").get<std::string>(), HasSubstr("mean avalanches per binary frame"));
  for (const char* f : {"ground_truth.exr", "laser.exr", "ambient.exr", "sensor_maps.exr", "counts.npy",
                        "expected_counts.npy", "detection_rate.npy", "frames.npy", "transient.npy", "previews/depth.png"})
    EXPECT_TRUE(fs::exists(dir_ / "out" / f)) << f;
  // No staging folder or temporary file is left behind.
  for (const auto& e : fs::recursive_directory_iterator(dir_ / "out"))
    EXPECT_THAT(e.path().filename().string(), ::testing::Not(HasSubstr("staging"))) << e.path();

  const int64_t K = meta["acquisition"]["K"];
  const Npy counts = read_npy(dir_ / "out/counts.npy");
  EXPECT_EQ(counts.descr, "|u1");
  EXPECT_EQ(counts.shape, (std::vector<int64_t>{K, 20, 24}));
  const Npy expected = read_npy(dir_ / "out/expected_counts.npy");
  EXPECT_EQ(expected.descr, "<f4");
  EXPECT_EQ(expected.shape, counts.shape);
  // The detection rate is the lossless form of the expectation: expected = N (1 - exp(-lambda)).
  const Npy rate = read_npy(dir_ / "out/detection_rate.npy");
  EXPECT_EQ(rate.descr, "<f4");
  ASSERT_EQ(rate.shape, counts.shape);
  const std::vector<double> e = values(expected), lam = values(rate);
  for (size_t i = 0; i < e.size(); ++i) ASSERT_NEAR(e[i], 255.0 * -std::expm1(-lam[i]), 2e-5 * 255.0) << i;
  const Npy frames = read_npy(dir_ / "out/frames.npy");
  EXPECT_EQ(frames.shape, (std::vector<int64_t>{K, 255, 20, 3}));
  const Npy transient = read_npy(dir_ / "out/transient.npy");
  EXPECT_EQ(transient.shape, (std::vector<int64_t>{20, 24, meta["time_axis"]["bins"].get<int64_t>()}));

  // Summed frames are the counts, pixel by pixel.
  for (int64_t k = 0; k < K; ++k)
    for (int y = 0; y < 20; ++y)
      for (int x = 0; x < 24; ++x) {
        int sum = 0;
        for (int n = 0; n < 255; ++n) sum += (uint8_t(frames.data[size_t(((k * 255 + n) * 20 + y) * 3 + x / 8)]) >> (x % 8)) & 1;
        ASSERT_EQ(sum, uint8_t(counts.data[size_t((k * 20 + y) * 24 + x)])) << k << " " << x << " " << y;
      }

  const spadgen::writers::ExrData gt = spadgen::writers::read_exr((dir_ / "out/ground_truth.exr").string());
  EXPECT_EQ(gt.width, 24);
  EXPECT_EQ(gt.height, 20);
  for (const char* c : {"range", "z", "normal.X", "normal.Y", "normal.Z", "mesh_id", "material_id", "layer_count", "layer0.range",
                        "layer0.transmittance"})
    EXPECT_TRUE(gt.channels.count(c)) << c;
  EXPECT_EQ(gt.attributes.at("spadgen_seed"), std::to_string(meta["seed"].get<uint64_t>()));
  EXPECT_EQ(gt.attributes.at("spadgen_scene_hash"), meta["scene_hash_fnv1a64"].get<std::string>());
}

TEST_F(App, IndirectTransientIsANonEmptyPartOfTheTotalInEveryBin) {
  ASSERT_EQ(sh("run " + kSmall + " --set render.split_direct_indirect=true --set outputs.transient_crop=[500,236,8,8] -o " +
               (dir_ / "out").string()).code, 0);
  const Npy total = read_npy(dir_ / "out/transient.npy"), indirect = read_npy(dir_ / "out/transient_indirect.npy");
  ASSERT_EQ(total.shape, indirect.shape);
  EXPECT_EQ(total.shape, (std::vector<int64_t>{8, 8, total.shape[2]}));
  const std::vector<double> t = values(total), i = values(indirect);
  double sum_t = 0, sum_i = 0;
  for (size_t k = 0; k < t.size(); ++k) {
    ASSERT_GE(i[k], 0.0);
    ASSERT_LE(i[k], t[k] * (1 + 1e-6) + 1e-30) << "the indirect part exceeds the total in bin " << k;
    sum_t += t[k], sum_i += i[k];
  }
  EXPECT_GT(sum_i, 0.0);
  EXPECT_LT(sum_i, sum_t);
}

TEST_F(App, OutputsAreBitIdenticalForAnyThreadCountAndTileSize) {
  ASSERT_EQ(sh("run " + kSmall + " --threads 1 --set render.tile_size_px=8 -o " + (dir_ / "a").string()).code, 0);
  ASSERT_EQ(sh("run " + kSmall + " --threads 2 --set render.tile_size_px=16 -o " + (dir_ / "b").string()).code, 0);
  expect_same_outputs(dir_ / "a", dir_ / "b");
}

// A render to a target error decides each pixel's paths from its own first round: the same bits for any
// thread count and tile size; laser.exr records every pixel's paths and standard error, and metadata.json
// their summary.
TEST_F(App, TargetErrorOutputsAreBitIdenticalForAnyThreadCountAndTileSize) {
  // (kSmall gives samples_per_pixel, which the preset then leaves: given back its value here. The target
  // error given too, above the preset's 0.02: the same test at a third of the paths, 221 s -> 90 s of
  // CI's sanitizer suite.)
  const std::string q = " --set render.quality=standard --set render.samples_per_pixel=32 --set render.target_relative_error=0.05 "
                        "--set render.split_direct_indirect=true -o ";
  ASSERT_EQ(sh("run " + kSmall + " --threads 1 --set render.tile_size_px=8" + q + (dir_ / "a").string()).code, 0);
  ASSERT_EQ(sh("run " + kSmall + " --threads 2 --set render.tile_size_px=16" + q + (dir_ / "b").string()).code, 0);
  expect_same_outputs(dir_ / "a", dir_ / "b");
  const auto laser = spadgen::writers::read_exr((dir_ / "a/laser.exr").string());
  const auto& se = laser.channels.at("standard_error");
  const auto& n = laser.channels.at("samples");
  const auto& l = laser.channels.at("photons_per_pulse");
  const auto meta = nlohmann::json::parse(slurp(dir_ / "a/metadata.json"));
  const auto& acc = meta.at("accuracy");
  EXPECT_EQ(acc.at("target_relative_error"), 0.05);
  const int first = meta["resolved_scene"]["render"]["samples_per_pixel"], most = meta["resolved_scene"]["render"]["max_samples_per_pixel"];
  double paths = 0;
  int over = 0, lit = 0;
  for (size_t i = 0; i < n.size(); ++i) {
    ASSERT_GE(n[i], float(first));
    ASSERT_LE(n[i], float(most));
    paths += n[i];
    if (l[i] > 0) ++lit, over += se[i] > 0.1f * l[i] && n[i] < float(most);
  }
  EXPECT_DOUBLE_EQ(acc.at("samples_per_pixel").at("mean").get<double>(), paths / double(n.size()));
  EXPECT_EQ(acc.at("laser_relative_standard_error").at("pixels_with_laser"), lit);
  EXPECT_LE(acc.at("laser_relative_standard_error").at("median").get<double>(), 0.05 * 1.25);
  EXPECT_LE(over, lit / 10);
  // metadata.json "model": what the scene and settings use, each with its reason.
  std::map<std::string, bool> model;
  for (const auto& e : meta.at("model")) {
    model[e.at("component").get<std::string>()] = e.at("active").get<bool>();
    EXPECT_FALSE(e.at("why").get<std::string>().empty());
  }
  EXPECT_TRUE(model.at("transmissive surfaces"));  // the plate
  EXPECT_FALSE(model.at("ambient light"));         // the paper's dark lab
  EXPECT_TRUE(model.at("guided connections"));     // the plate's roughness 0.05
  EXPECT_FALSE(model.at("laser mirrors"));         // nothing smooth
  EXPECT_TRUE(model.at("target error"));
  EXPECT_TRUE(model.at("binary frames"));          // kSmall writes them
  EXPECT_TRUE(model.at("crosstalk"));
  EXPECT_EQ(model.at("indirect light"), meta["resolved_scene"]["render"]["max_bounces"].get<int>() > 1);
}

// The sensor's components are active as the pixel designs the chip has set them: with pixel A alone and its
// DCR, crosstalk and PDP spread at 0, and no gate spreads, none is (each was listed active, with rates
// bit-identical to the component off; the hot pixels by the unused pixel B's fraction); a 2D run has no gate.
TEST_F(App, TheModelListsTheSensorsComponentsThePixelDesignsInUseHave) {
  const auto model_of = [&](const std::string& args) {
    const Result r = sh("run " + kScenes + "flat_target.json -q --set camera.crop=[508,246,8,8] --set render.samples_per_pixel=1 "
                        "--set outputs.previews=false --set sensor.preset=pixel_A " + args + " -o " + (dir_ / "m").string());
    EXPECT_EQ(r.code, 0) << r.output;
    std::map<std::string, bool> model;
    const nlohmann::json meta = nlohmann::json::parse(slurp(dir_ / "m/metadata.json"));
    for (const auto& e : meta.at("model")) model[e.at("component").get<std::string>()] = e.at("active").get<bool>();
    return model;
  };
  const auto on = model_of("");
  for (const char* c : {"dark counts", "hot pixels", "crosstalk", "per-pixel gate maps", "PDP non-uniformity"}) EXPECT_TRUE(on.at(c)) << c;
  const auto zero = model_of("--set sensor.pixel_A.dcr_median_cps=0 --set sensor.pixel_A.crosstalk_probability=0 "
                             "--set sensor.pixel_A.pdp_nonuniformity=0 --set sensor.gate.skew_fwhm_ps=0 --set sensor.gate.length_fwhm_ps=0");
  for (const char* c : {"dark counts", "hot pixels", "crosstalk", "per-pixel gate maps", "PDP non-uniformity"}) EXPECT_FALSE(zero.at(c)) << c;
  EXPECT_FALSE(model_of("--set sensor.pixel_A.hot_pixel_fraction=0").at("hot pixels"));
  EXPECT_FALSE(model_of("--set acquisition.mode=intensity").at("per-pixel gate maps"));
  // the laser's image in smooth planar faces: the target made a smooth mirror (2 triangles)
  EXPECT_FALSE(on.at("laser mirrors"));
  EXPECT_TRUE(model_of("--set materials.white_paper.roughness=0 --set materials.white_paper.metallic=1").at("laser mirrors"));
}

// metadata.json "run": the stages' shares of the run's wall time sum to 1, the rays' categories to their
// total, and each model component has a share of its own where it has one: 0 when the scene does not
// use it (the flat target has no transmissive surface, so no refracted connection; frames off: none sampled).
TEST_F(App, RunSaysWhereItsTimeWentAndAComponentNotUsedCostsNothing) {
  const auto run_of = [&](const std::string& name, const std::string& args) {
    const Result r = sh("run " + args + " -o " + (dir_ / name).string());
    EXPECT_EQ(r.code, 0) << r.output;
    return nlohmann::json::parse(slurp(dir_ / name / "metadata.json")).at("run");
  };
  const std::string flat = kScenes + "flat_target.json -q --set camera.crop=[496,234,32,32] --set render.samples_per_pixel=4";
  for (const auto& [name, run] : {std::pair{"small", run_of("small", kSmall)}, std::pair{"flat", run_of("flat", flat)},
                                  std::pair{"flat_frames", run_of("flat_frames", flat + " --set outputs.frames=true --set render.max_bounces=1")}}) {
    SCOPED_TRACE(name);
    double shares = 0, seconds = 0;
    for (const auto& st : run.at("stages")) {
      EXPECT_GE(st.at("share").get<double>(), 0.0);
      shares += st.at("share").get<double>(), seconds += st.at("seconds").get<double>();
    }
    EXPECT_NEAR(shares, 1.0, 1e-9);
    EXPECT_NEAR(seconds, run.at("wall_seconds").get<double>(), 1e-9);
    const auto& rays = run.at("rays");
    uint64_t sum = 0;
    for (const char* k : {"camera", "bounce", "laser", "refracted", "mirror", "guided", "ambient"}) sum += rays.at(k).get<uint64_t>();
    EXPECT_EQ(sum, rays.at("total").get<uint64_t>());
    EXPECT_GT(rays.at("camera").get<uint64_t>(), 0u);
    std::map<std::string, nlohmann::json> share;
    for (const auto& c : run.at("components")) share[c.at("component").get<std::string>()] = c.at("share");
    EXPECT_EQ(share.size(), 14u);
    EXPECT_GT(share.at("laser light").get<double>(), 0.0);  // its shadow rays
    if (std::string(name) == "small") {  // the plate: refracted connections; its roughness: guided ones
      EXPECT_GT(rays.at("refracted").get<uint64_t>(), 0u);
      EXPECT_GT(share.at("transmissive surfaces").get<double>(), 0.0);
      EXPECT_GT(share.at("guided connections").get<double>(), 0.0);
      EXPECT_GT(share.at("binary frames").get<double>(), 0.0);  // kSmall writes them
    } else {
      EXPECT_EQ(rays.at("refracted").get<uint64_t>(), 0u);
      EXPECT_EQ(rays.at("mirror").get<uint64_t>(), 0u);
      EXPECT_EQ(rays.at("guided").get<uint64_t>(), 0u);
      EXPECT_EQ(share.at("laser mirrors").get<double>(), 0.0);
      EXPECT_EQ(share.at("transmissive surfaces").get<double>(), 0.0);
      EXPECT_EQ(share.at("guided connections").get<double>(), 0.0);
      EXPECT_EQ(share.at("ambient light").get<double>(), 0.0);
      EXPECT_TRUE(share.at("crosstalk").is_null());  // inside the sensor's stages
      if (std::string(name) == "flat") {
        EXPECT_EQ(share.at("binary frames").get<double>(), 0.0);
      } else {
        EXPECT_GT(share.at("binary frames").get<double>(), 0.0);
        EXPECT_EQ(rays.at("indirect").get<uint64_t>(), 0u);  // render.max_bounces = 1
        EXPECT_EQ(share.at("indirect light").get<double>(), 0.0);
      }
    }
  }
}

// In a gate sweep render.target_relative_error holds the ambient light too (the counts' background: at 100
// lux the multi-object counts were 4.6-5.7 off at p99 at quality=standard), against its rate plus a floor the
// counts hardly see: a faint background takes the dark scene's paths (without the floor 1e-6 lux took 494
// paths per pixel against 290), a bright one more; bit-identical across threads and tiles.
TEST_F(App, TheTargetHoldsAGateSweepsAmbientLightWhereTheCountsSeeIt) {
  const std::string base = "run " + kScenes + "multi_object.json -q --set camera.crop=[480,230,32,16] --set render.quality=standard "
                           "--set outputs.previews=false -o ";
  const auto paths = [&](const std::string& lux, const std::string& extra = "") {
    const fs::path out = dir_ / ("lux_" + lux + (extra.empty() ? "" : "_again"));
    const Result r = sh(base + out.string() + " --set ambient.illuminance_lux=" + lux + extra);
    EXPECT_EQ(r.code, 0) << r.output;
    return spadgen::writers::read_exr((out / "laser.exr").string()).channels.at("samples");
  };
  const std::vector<float> dark = paths("0"), faint = paths("1e-6"), dim = paths("0.1"), bright = paths("100");
  EXPECT_EQ(faint, dark);
  EXPECT_EQ(dim, dark);
  double d = 0, b = 0;
  for (size_t i = 0; i < dark.size(); ++i) d += dark[i], b += bright[i];
  EXPECT_GT(b, 1.3 * d) << "the bright background holds more paths";
  // the same bits with one thread and other tiles
  paths("100", " --threads 1 --set render.tile_size_px=8");
  for (const char* f : {"counts.npy", "laser.exr", "ambient.exr"})
    EXPECT_EQ(slurp(dir_ / "lux_100" / f), slurp(dir_ / "lux_100_again" / f)) << f;
}

// One path per pixel has no spread to estimate an error from: every standard_error is 0, and metadata.json's
// summaries of them read 0 (exact) where the real error was 39 % rms behind the multi-object plate: null, and
// `meaning` says why. Two paths estimate it.
TEST_F(App, OnePathPerPixelReportsNoErrorSummary) {
  const std::string base = "run " + kScenes + "multi_object.json -q --set camera.crop=[440,234,16,8] --set ambient.illuminance_lux=10 "
                           "--set outputs.previews=false -o ";
  ASSERT_EQ(sh(base + (dir_ / "one").string() + " --set render.samples_per_pixel=1").code, 0);
  ASSERT_EQ(sh(base + (dir_ / "two").string() + " --set render.samples_per_pixel=2").code, 0);
  const nlohmann::json one = nlohmann::json::parse(slurp(dir_ / "one/metadata.json")).at("accuracy");
  const nlohmann::json two = nlohmann::json::parse(slurp(dir_ / "two/metadata.json")).at("accuracy");
  EXPECT_TRUE(one.at("laser_relative_standard_error").is_null()) << one.dump();
  EXPECT_TRUE(one.at("ambient_relative_standard_error").is_null()) << one.dump();
  EXPECT_EQ(one.at("meaning").get<std::string>().rfind("one path per pixel: no spread to estimate the error from", 0), 0u);
  EXPECT_GT(two.at("laser_relative_standard_error").at("median").get<double>(), 0.0);
  EXPECT_GT(two.at("ambient_relative_standard_error").at("median").get<double>(), 0.0);
  EXPECT_EQ(two.at("meaning").get<std::string>().find("one path"), std::string::npos);
}

// A 2D run without acquisition.intensity.laser_on models no laser (the test chart: 39 % of its rays were the
// laser's shadow rays): no laser.exr, no laser channels in ground_truth.exr, null laser figures in metadata.json,
// "laser light" skipped, no laser ray traced. The paths are drawn as when it is traced (outputs.transient keeps
// its light), so the ambient light and the counts are the same bits.
TEST_F(App, AnIntensityRunWithoutTheLaserTracesNone) {
  const std::string base = "run " + kScenes + "test_chart.json -q --set camera.crop=[480,480,32,16] "
                           "--set render.samples_per_pixel=2 --set outputs.previews=false -o ";
  Result r = sh(base + (dir_ / "off").string());
  ASSERT_EQ(r.code, 0) << r.output;
  r = sh(base + (dir_ / "kept").string() + " --set outputs.transient=true --set render.window_start_ns=0 --set render.window_stop_ns=20");
  ASSERT_EQ(r.code, 0) << r.output;
  const nlohmann::json off = nlohmann::json::parse(slurp(dir_ / "off/metadata.json"));
  const nlohmann::json kept = nlohmann::json::parse(slurp(dir_ / "kept/metadata.json"));
  EXPECT_FALSE(fs::exists(dir_ / "off/laser.exr"));
  for (const auto& f : off.at("files")) EXPECT_NE(f.get<std::string>(), "laser.exr");
  EXPECT_TRUE(fs::exists(dir_ / "kept/laser.exr"));
  EXPECT_TRUE(off.at("laser_photons_per_pulse").is_null());
  EXPECT_TRUE(off.at("accuracy").at("laser_relative_standard_error").is_null());
  EXPECT_GT(kept.at("laser_photons_per_pulse").at("total_all_pixels").get<double>(), 0.0);
  const auto model = [](const nlohmann::json& m) {
    for (const auto& e : m.at("model"))
      if (e.at("component") == "laser light") return e.at("active").get<bool>();
    ADD_FAILURE() << "no laser light in model";
    return false;
  };
  EXPECT_FALSE(model(off));
  EXPECT_TRUE(model(kept));
  EXPECT_EQ(off.at("run").at("rays").at("laser").get<uint64_t>(), 0u);
  EXPECT_GT(kept.at("run").at("rays").at("laser").get<uint64_t>(), 0u);
  EXPECT_LT(off.at("run").at("rays").at("total").get<uint64_t>(), kept.at("run").at("rays").at("total").get<uint64_t>());
  const auto gt_off = spadgen::writers::read_exr((dir_ / "off/ground_truth.exr").string());
  const auto gt_kept = spadgen::writers::read_exr((dir_ / "kept/ground_truth.exr").string());
  for (const char* c : {"direct_other_laser", "indirect_laser", "object0.laser"}) {
    EXPECT_FALSE(gt_off.channels.count(c)) << c;
    EXPECT_TRUE(gt_kept.channels.count(c)) << c;
  }
  EXPECT_EQ(gt_off.channels.at("range"), gt_kept.channels.at("range"));
  const auto amb_off = spadgen::writers::read_exr((dir_ / "off/ambient.exr").string());
  const auto amb_kept = spadgen::writers::read_exr((dir_ / "kept/ambient.exr").string());
  for (const char* c : {"photons_per_second", "standard_error"}) EXPECT_EQ(amb_off.channels.at(c), amb_kept.channels.at(c)) << c;
  EXPECT_EQ(slurp(dir_ / "off/counts.npy"), slurp(dir_ / "kept/counts.npy"));
  // ... also behind a clear plate, whose laser-side echoes are drawn where the laser is traced (a draw from the
  // path's stream moved its later draws: the counts and the ambient light differed; a reviewer's find)
  const std::string clear = "run " + kScenes + "multi_object.json -q --set acquisition.mode=intensity --set camera.crop=[384,200,64,24] "
                            "--set render.samples_per_pixel=2 --set ambient.illuminance_lux=100 --set materials.plastic_plate.roughness=0 "
                            "--set outputs.previews=false -o ";
  ASSERT_EQ(sh(clear + (dir_ / "clear_off").string()).code, 0);
  ASSERT_EQ(sh(clear + (dir_ / "clear_kept").string() + " --set outputs.transient=true --set render.window_start_ns=0 "
               "--set render.window_stop_ns=20").code, 0);
  EXPECT_EQ(slurp(dir_ / "clear_off/counts.npy"), slurp(dir_ / "clear_kept/counts.npy"));
  EXPECT_EQ(spadgen::writers::read_exr((dir_ / "clear_off/ambient.exr").string()).channels.at("photons_per_second"),
            spadgen::writers::read_exr((dir_ / "clear_kept/ambient.exr").string()).channels.at("photons_per_second"));
  // With a target error, each pixel's paths go to ambient.exr (laser.exr held them); the guided connections,
  // which draw towards the laser, are not modelled either (the multi-object scene's glossy plate).
  r = sh(base + (dir_ / "target").string() + " --set render.target_relative_error=0.2 --set render.max_samples_per_pixel=8");
  ASSERT_EQ(r.code, 0) << r.output;
  const auto samples = spadgen::writers::read_exr((dir_ / "target/ambient.exr").string()).channels.at("samples");
  EXPECT_GE(*std::min_element(samples.begin(), samples.end()), 2.0f);
  EXPECT_LE(*std::max_element(samples.begin(), samples.end()), 8.0f);
  EXPECT_FALSE(fs::exists(dir_ / "target/laser.exr"));
  r = sh("run " + kScenes + "multi_object.json -q --set acquisition.mode=intensity --set camera.crop=[480,230,16,8] "
         "--set render.samples_per_pixel=1 --set outputs.previews=false -o " + (dir_ / "glossy").string());
  ASSERT_EQ(r.code, 0) << r.output;
  const nlohmann::json glossy = nlohmann::json::parse(slurp(dir_ / "glossy/metadata.json"));
  for (const auto& e : glossy.at("model")) {
    if (e.at("component") == "guided connections") {
      EXPECT_FALSE(e.at("active").get<bool>()) << e;
    }
  }
  EXPECT_EQ(glossy.at("run").at("rays").at("guided").get<uint64_t>(), 0u);
}

// outputs.storage = zarr changes the container only: every stack of a Zarr run holds the .npy run's values
// element for element (the saved light, the transients and their indirect part included), frames stay a
// .npy, and every other file is the same bytes. Zarr stores are read here with writers::ZarrReader (itself
// checked against Blosc and zarr-python in tests/writers and tests/python).
TEST_F(App, ZarrRunHoldsTheNpyRunsValues) {
  const std::string run = "run " + kSmall + " --set render.split_direct_indirect=true --set outputs.expected_counts=true "
                          "--set outputs.light=true -o ";
  ASSERT_EQ(sh(run + (dir_ / "npy").string()).code, 0);
  const Result z = sh(run + (dir_ / "zarr").string() + " --set outputs.storage=zarr");
  ASSERT_EQ(z.code, 0) << z.output;
  auto mn = nlohmann::json::parse(slurp(dir_ / "npy/metadata.json")), mz = nlohmann::json::parse(slurp(dir_ / "zarr/metadata.json"));
  size_t stacks = 0;
  for (const auto& f : mn["files"]) {
    const std::string name = f.get<std::string>();
    if (name == "metadata.json") continue;
    if (!name.ends_with(".npy") || name == "frames.npy") {
      EXPECT_TRUE(slurp(dir_ / "npy" / name) == slurp(dir_ / "zarr" / name)) << name << " differs";
      continue;
    }
    const std::string zname = name.substr(0, name.size() - 4) + ".zarr";
    EXPECT_TRUE(std::find(mz["files"].begin(), mz["files"].end(), zname) != mz["files"].end()) << zname;
    const Npy n = read_npy(dir_ / "npy" / name);
    const spadgen::writers::ZarrReader r((dir_ / "zarr" / zname).string());
    EXPECT_EQ(n.descr, spadgen::writers::numpy_descr(r.dtype())) << name;
    EXPECT_EQ(n.shape, r.shape()) << name;
    std::string bytes(n.data.size(), '\0');
    ASSERT_EQ(r.elements() * spadgen::writers::element_bytes(r.dtype()), int64_t(bytes.size())) << name;
    r.read(0, r.elements(), bytes.data());
    EXPECT_TRUE(bytes == n.data) << name << " holds other values than " << zname;
    EXPECT_EQ(mz["storage"]["files"][zname]["format"], "zarr") << zname;
    EXPECT_EQ(mz["storage"]["files"][zname]["chunks"].size(), r.chunks().size()) << zname;
    ++stacks;
  }
  EXPECT_EQ(stacks, 14u);  // counts, detection rate, expected counts, transient and its indirect part, 9 of light
  EXPECT_EQ(mz["storage"]["stacks"], "zarr");
  EXPECT_EQ(mz["storage"]["files"]["frames.npy"]["format"], "npy");
  EXPECT_EQ(mn["storage"]["files"]["counts.npy"]["format"], "npy");
  for (auto* m : {&mn, &mz}) {
    for (const char* k : {"run", "storage", "files", "file_bytes"}) m->erase(k);
    (*m)["resolved_scene"]["outputs"].erase("storage");
  }
  EXPECT_EQ(mn, mz);
}

TEST_F(App, ZarrOutputsAreBitIdenticalForAnyThreadCountAndTileSize) {
  const std::string zarr = " --set outputs.storage=zarr --set outputs.light=true --set outputs.expected_counts=true";
  ASSERT_EQ(sh("run " + kSmall + zarr + " --threads 1 --set render.tile_size_px=8 -o " + (dir_ / "a").string()).code, 0);
  ASSERT_EQ(sh("run " + kSmall + zarr + " --threads 2 --set render.tile_size_px=16 -o " + (dir_ / "b").string()).code, 0);
  expect_same_outputs(dir_ / "a", dir_ / "b");
  EXPECT_TRUE(fs::is_regular_file(dir_ / "a/counts.zarr/0.0.0"));
}

// Every lossless EXR compression gives the same channels; metadata.json records the one used.
TEST_F(App, ExrCompressionKeepsEveryImageBitForBit) {
  ASSERT_EQ(sh("run " + kSmall + " -o " + (dir_ / "zip").string()).code, 0);
  for (const char* c : {"none", "rle", "zips"}) {
    const fs::path out = dir_ / c;
    ASSERT_EQ(sh("run " + kSmall + " --set outputs.exr_compression=" + c + " -o " + out.string()).code, 0) << c;
    EXPECT_EQ(nlohmann::json::parse(slurp(out / "metadata.json"))["storage"]["exr_compression"], c);
    for (const char* image : {"ground_truth.exr", "laser.exr", "ambient.exr", "sensor_maps.exr"}) {
      const auto a = spadgen::writers::read_exr((dir_ / "zip" / image).string()), b = spadgen::writers::read_exr((out / image).string());
      EXPECT_EQ(a.attributes, b.attributes) << c << " " << image;
      ASSERT_EQ(a.channels.size(), b.channels.size()) << c << " " << image;
      for (const auto& [name, v] : a.channels)
        EXPECT_EQ(std::memcmp(v.data(), b.channels.at(name).data(), v.size() * sizeof(float)), 0) << c << " " << image << " " << name;
    }
  }
  EXPECT_GT(fs::file_size(dir_ / "none/ground_truth.exr"), fs::file_size(dir_ / "zip/ground_truth.exr"));
}

// Each random stream changes only what it drives: seeds.noise the sampled counts and frames, seeds.chip
// the chip's maps (and so the expectations and the samples), seeds.light the rendered light (and all that
// follows from it). Setting every stream's seed to `seed` is the default, bit for bit.
TEST_F(App, EachSeedChangesOnlyWhatItDrives) {
  const std::string run = "run " + kSmall + " --seed 5 -o ";
  ASSERT_EQ(sh(run + (dir_ / "base").string()).code, 0);
  ASSERT_EQ(sh(run + (dir_ / "same").string() + " --set seeds.light=5 --set seeds.chip=5 --set seeds.noise=5").code, 0);
  ASSERT_EQ(sh(run + (dir_ / "noise").string() + " --set seeds.noise=6").code, 0);
  ASSERT_EQ(sh(run + (dir_ / "chip").string() + " --set seeds.chip=6").code, 0);
  ASSERT_EQ(sh(run + (dir_ / "light").string() + " --set seeds.light=6").code, 0);
  const auto same = [&](const std::string& variant, const std::string& file) {
    return slurp(dir_ / "base" / file) == slurp(dir_ / variant / file);
  };
  for (const char* f : {"laser.exr", "ambient.exr", "sensor_maps.exr", "ground_truth.exr", "transient.npy",
                        "detection_rate.npy", "counts.npy", "frames.npy"})
    EXPECT_TRUE(same("same", f)) << f;
  // The temporal noise: only the samples change.
  for (const char* f : {"laser.exr", "ambient.exr", "sensor_maps.exr", "transient.npy", "detection_rate.npy", "labels.exr"})
    EXPECT_TRUE(same("noise", f)) << "seeds.noise changed " << f;
  EXPECT_FALSE(same("noise", "counts.npy"));
  EXPECT_FALSE(same("noise", "frames.npy"));
  // The chip: its maps, hence the expectations and the samples; not the light.
  for (const char* f : {"laser.exr", "ambient.exr", "transient.npy", "ground_truth.exr"})
    EXPECT_TRUE(same("chip", f)) << "seeds.chip changed " << f;
  for (const char* f : {"sensor_maps.exr", "detection_rate.npy", "counts.npy", "labels.exr"}) EXPECT_FALSE(same("chip", f)) << f;
  // The light: the rendered light and what follows; not the chip, not the exact ground truth (but the
  // light each object returns, which ground_truth.exr holds too).
  EXPECT_TRUE(same("light", "sensor_maps.exr")) << "seeds.light changed sensor_maps.exr";
  for (const char* f : {"laser.exr", "transient.npy", "detection_rate.npy", "labels.exr"}) EXPECT_FALSE(same("light", f)) << f;
  const auto base_gt = spadgen::writers::read_exr((dir_ / "base/ground_truth.exr").string());
  const auto light_gt = spadgen::writers::read_exr((dir_ / "light/ground_truth.exr").string());
  ASSERT_EQ(base_gt.channels.size(), light_gt.channels.size());
  for (const auto& [name, values] : base_gt.channels) {
    if (!name.ends_with("laser")) {
      EXPECT_TRUE(values == light_gt.channels.at(name)) << "seeds.light changed ground_truth.exr " << name;
    }
  }
  // The plate's own light and the sphere's seen through the rough plate (indirect): other paths, other values.
  for (const char* c : {"object0.laser", "indirect_laser"}) EXPECT_FALSE(base_gt.channels.at(c) == light_gt.channels.at(c)) << c;
  const auto meta = nlohmann::json::parse(slurp(dir_ / "noise/metadata.json"));
  EXPECT_EQ(meta["seeds"], nlohmann::json({{"light", 5}, {"chip", 5}, {"noise", 6}}));
}

TEST_F(App, AOnePixelCropReplaysThatPixelOfALargerRun) {
  ASSERT_EQ(sh("run " + kSmall + " -o " + (dir_ / "full").string()).code, 0);
  const std::string one = kSmallSettings + " --set camera.crop=[509,241,1,1]";
  ASSERT_EQ(sh("run " + one + " -o " + (dir_ / "one").string()).code, 0);
  const Npy full = read_npy(dir_ / "full/counts.npy"), single = read_npy(dir_ / "one/counts.npy");
  const auto lf = spadgen::writers::read_exr((dir_ / "full/laser.exr").string());
  const auto ls = spadgen::writers::read_exr((dir_ / "one/laser.exr").string());
  EXPECT_EQ(lf.channels.at("photons_per_pulse")[size_t((241 - 232) * 24 + (509 - 496))], ls.channels.at("photons_per_pulse")[0]);
  const int64_t K = full.shape[0];
  for (int64_t k = 0; k < K; ++k)
    EXPECT_EQ(full.data[size_t((k * 20 + (241 - 232)) * 24 + (509 - 496))], single.data[size_t(k)]) << "gate " << k;
}

// The renderer (fill factor, in laser.exr) and the sensor (PDE, in sensor_maps.exr) must agree on which
// pixel design every row has, for odd heights, crops and full_chip. The same run with preset pixel_A gives
// the reference: the light transport is identical, so laser.exr's ratio per row is ff(row) / ff_A, and the
// PDE's ratio is pdp(row) ff(row) / (pdp_A ff_A). A row is pixel B for both, or for neither.
TEST_F(App, RendererAndSensorAgreeOnEveryRowsPixelDesign) {
  const double ff_a = 0.07, ff_b = 0.134, pdp_ratio = 0.267 / 0.105;  // the paper's pixels (Table 1)
  struct Case {
    int height;
    std::string crop;  // "" = the whole sensor
  };
  for (const Case& c : {Case{5, ""}, Case{7, ""}, Case{2, ""}, Case{1, ""}, Case{1000, "[0,496,8,7]"}, Case{9, "[0,3,8,4]"}}) {
    const std::string h = std::to_string(c.height);
    std::string base = kScenes;
    base += "flat_target.json -q --set camera.width_px=8 --set render.samples_per_pixel=2 --set outputs.previews=false"
            " --set sensor.pdp_nonuniformity=false";
    base += " --set camera.height_px=";
    base += h;
    if (!c.crop.empty()) base += " --set camera.crop=" + c.crop;
    const fs::path a = dir_ / "a" / h, f = dir_ / "f" / h;
    ASSERT_EQ(sh("run " + base + " --set sensor.preset=pixel_A -o " + a.string()).code, 0);
    ASSERT_EQ(sh("run " + base + " --set sensor.preset=full_chip -o " + f.string()).code, 0);
    const auto la = spadgen::writers::read_exr((a / "laser.exr").string()), lf = spadgen::writers::read_exr((f / "laser.exr").string());
    const auto ma = spadgen::writers::read_exr((a / "sensor_maps.exr").string()), mf = spadgen::writers::read_exr((f / "sensor_maps.exr").string());
    const int y0 = c.crop.empty() ? 0 : std::stoi(c.crop.substr(c.crop.find(',') + 1));
    const nlohmann::json meta_f = nlohmann::json::parse(slurp(f / "metadata.json"));
    int b_rows = 0;
    for (int y = 0; y < lf.height; ++y)
      for (int x = 0; x < lf.width; ++x) {
        const size_t i = size_t(y * lf.width + x);
        const double pa = la.channels.at("photons_per_pulse")[i], pf = lf.channels.at("photons_per_pulse")[i];
        ASSERT_GT(pa, 0.0) << "height " << c.height << " row " << y0 + y;
        const bool renderer_b = std::abs(pf / pa - ff_b / ff_a) < 1e-5 * ff_b / ff_a;
        ASSERT_TRUE(renderer_b || std::abs(pf / pa - 1.0) < 1e-5) << "height " << c.height << " row " << y0 + y << ": " << pf / pa;
        const double qa = ma.channels.at("pde")[i], qf = mf.channels.at("pde")[i];
        const bool sensor_b = std::abs(qf / qa - pdp_ratio * ff_b / ff_a) < 1e-5 * pdp_ratio * ff_b / ff_a;
        ASSERT_TRUE(sensor_b || std::abs(qf / qa - 1.0) < 1e-5) << "height " << c.height << " row " << y0 + y << ": " << qf / qa;
        EXPECT_EQ(renderer_b, sensor_b) << "height " << c.height << " row " << y0 + y << ": the renderer says pixel "
                                        << (renderer_b ? "B" : "A") << ", the sensor pixel " << (sensor_b ? "B" : "A");
        // Rows [H/2, H) are pixel B (docs/sensor.md): the middle row of an odd height is pixel B.
        EXPECT_EQ(sensor_b, y0 + y >= c.height / 2) << "height " << c.height << " row " << y0 + y;
        b_rows += sensor_b && x == 0;
        // the PDE of the ambient light: the same pixel, the ambient band's PDP in place of the laser's
        // (metadata.json's acquisition.pixel_types; a 2D image's photons divided by the laser's PDE were 52 %
        // high)
        for (const auto& type : meta_f["acquisition"]["pixel_types"]) {
          if (type["name"] != (sensor_b ? "pixel_B" : "pixel_A")) continue;
          EXPECT_NEAR(mf.channels.at("pde_ambient")[i] / qf,
                      type["pdp_ambient_band"].get<double>() / type["pdp_laser"].get<double>(), 1e-5);
        }
      }
    EXPECT_EQ(b_rows, std::max(0, y0 + lf.height - std::max(y0, c.height / 2))) << "height " << c.height;
  }
}

// An earlier run's metadata.json, alone in its folder: spadgen's (spadgen_version), listing itself.
const std::string kEarlier = R"({"spadgen_version": "earlier", "files": ["metadata.json"]})";

TEST_F(App, BadInputStopsBeforeWritingAndKeepsEarlierFiles) {
  fs::create_directories(dir_ / "out");
  std::ofstream(dir_ / "out/metadata.json") << kEarlier;  // (an earlier run's)
  const Result r = sh("run " + kScenes + "multi_object.json --set camera.f_numbr=2 -o " + (dir_ / "out").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("multi_object.json: --set camera.f_numbr: /camera/f_numbr: unknown key; did you mean /camera/f_number?"));
  EXPECT_EQ(slurp(dir_ / "out/metadata.json"), kEarlier);
  size_t entries = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir_ / "out")) ++entries;
  EXPECT_EQ(entries, 1u);

  const Result missing = sh("run " + (dir_ / "nope.json").string());
  EXPECT_NE(missing.code, 0);
  EXPECT_THAT(missing.output, HasSubstr("nope.json"));
}

TEST_F(App, AnInterruptedRunLeavesNothingBehind) {
  fs::create_directories(dir_ / "out");
  std::ofstream(dir_ / "out/metadata.json") << kEarlier;  // (an earlier run's)
  // The staging folder of a process that no longer exists (pids never reach 999999999) is removed.
  fs::create_directories(dir_ / "out/.spadgen-staging-999999999");
  std::ofstream(dir_ / "out/.spadgen-staging-999999999/counts.npy") << "partial";
  // The full default run takes far longer than 3 s; SIGINT arrives while tiles are rendering.
  const Signalled r = signal_once_caught({kBin, "run", kScenes + "multi_object.json", "-o", (dir_ / "out").string()}, SIGINT, 3.0);
  ASSERT_TRUE(r.caught) << r.code << r.output;
  EXPECT_EQ(r.code, 2) << r.output;  // the documented exit code of an interrupted run
  EXPECT_THAT(r.output, HasSubstr("interrupted by a signal"));
  EXPECT_EQ(slurp(dir_ / "out/metadata.json"), kEarlier);
  size_t entries = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir_ / "out")) ++entries;
  EXPECT_EQ(entries, 1u) << "only the earlier metadata.json may remain";
}

TEST_F(App, AnOutputPathThatCannotBeAFolderIsReported) {
  std::ofstream(dir_ / "a_file") << "x";
  for (const fs::path& out : {dir_ / "a_file", dir_ / "a_file" / "sub"}) {
    const Result r = sh("run " + kSmall + " -o " + out.string());
    EXPECT_EQ(r.code, 1) << r.output;
    EXPECT_THAT(r.output, HasSubstr("cannot use " + out.string() + " as the output folder (-o)"));
  }
  EXPECT_EQ(slurp(dir_ / "a_file"), "x");
}

TEST_F(App, ABrokenGltfIsReportedWithItsElement) {
  std::ofstream(dir_ / "broken.gltf") << R"({"asset": {"version": "2.0"}, "buffers": [{"uri": "missing.bin", "byteLength": 12}]})";
  std::ofstream(dir_ / "scene.json") << R"({"gltf": "broken.gltf"})";
  const Result r = sh("run " + (dir_ / "scene.json").string() + " -o " + (dir_ / "out").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("broken.gltf"));
  EXPECT_FALSE(fs::exists(dir_ / "out/metadata.json"));
}

// Runs whose data would be useless say so, on stderr (even with -q) and in metadata.json's "warnings"
// (app/warnings.h); a sound run of the same scene says nothing.
TEST_F(App, UselessRunsAreWarnedAboutOnStderrAndInTheMetadata) {
  const std::string run = "run " + kScenes + "flat_target.json -q --set camera.crop=[500,240,16,16] "
                          "--set render.samples_per_pixel=1 --set outputs.previews=false -o " + (dir_ / "out").string();
  struct Case {
    std::string set, warning;
  };
  const std::vector<Case> cases = {
      {"", ""},
      {"--set camera.look_at_m=[0,0,5]", "nothing in view: no camera ray of the 16 x 16 image hits a surface"},
      // the camera on the target's plane, looking through it: every pixel met it at range -0, without a word
      {"--set camera.position_m=[0,0,0] --set camera.look_at_m=[0,0,-1]",
       "a surface passes through the camera's centre: pixels of the 16 x 16 image meet it at range"},
      {"--set laser.beam=cone --set laser.half_angle_deg=0.01 --set laser.offset_m=[0.5,0,0]",
       "no laser light reaches the 16 x 16 image"},
      // a smooth mirror that sends the laser back where nothing in view is lit (the laser 5 cm beside the lens: its
      // image, a glint, lands at x = 645, outside the crop): named as a cause (only a black base colour was)
      {"--set materials.white_paper.roughness=0 --set materials.white_paper.metallic=1 --set laser.offset_m=[0.05,0,0]",
       "no laser light reaches the 16 x 16 image (laser.beam, half_angle_deg, offset_m, gltf_light; or what it lights reflects "
       "none of it: a black base colour, or a smooth mirror (roughness below 0.032, a Dirac lobe) that sends it where nothing in "
       "view is lit (the laser's image is rendered in planar faces of small meshes only"},
      // 40 MHz: 3.747 m; the target 5 m away folds into the window, so none of it is outside.
      {"--set camera.position_m=[0,0,5] --set camera.focal_length_mm=12",
       "100 % of the laser light comes from beyond the unambiguous range of 3.747 m"},
      // The return of the target 1 m away arrives at 4 + 6.7 ns, after the window the gates up to 1 ns need.
      {"--set acquisition.gate_sweep.stop_ns=1", "100 % of the laser light arrives outside the time window"},
      // The return rises at about 4 + 6.7 - 3.8 ns (the gate's length): a sweep from 8 ns begins on its plateau, and
      // the counts hold only its fall (a new user's plate rose before a sweep from 4 ns without a word)
      {"--set acquisition.gate_sweep.start_ns=8",
       "100 % of the objects' returns along the rays (256 of the 256 pairs (pixel, object) with laser light in labels.exr) rise "
       "before the gate sweep's first position (acquisition.gate_sweep.start_ns 8 ns; a pixel's gate opens at the position plus "
       "sensor.gate.delay_ns 0 ns and its skew): the counts hold no rising edge of them, only a fall (256 pairs, which "
       "labels.exr labels) or no edge at all (0 pairs: flat over the sweep); start the sweep earlier or lower sensor.gate.delay_ns"},
      {"--set camera.gltf_camera=spad_camera --set camera.height_px=1000 --set camera.crop=[500,490,16,16]",
       "camera.gltf_camera: the glTF camera 'spad_camera' has the aspect ratio 2.048, the 1024 x 1000 sensor 1.024: the "
       "vertical field of view (5.382 deg) is kept and the horizontal one is 5.511 deg instead of 11"},
      {"--set camera.gltf_camera=spad_camera", "camera.position_m: set to [0,0,1.0] but does nothing: camera.gltf_camera is \"spad_camera\""},
      {"--set acquisition.mode=intensity --set acquisition.gate_sweep.step_ps=50",
       "acquisition.gate_sweep.step_ps: set to 50 but does nothing: acquisition.mode is \"intensity\""},
      // a 2D run rendered the window's transients for nothing, and said 100 % of the laser light was outside it
      {"--set acquisition.mode=intensity --set render.window_start_ns=0 --set render.window_stop_ns=5",
       "render.window_start_ns: set to 0 but does nothing: acquisition.mode is \"intensity\" (no time bins) and outputs.transient "
       "and outputs.light are false"},
      // nor are the bins such a window would make refused (1e11 of them)
      {"--set acquisition.mode=intensity --set render.window_start_ns=0 --set render.window_stop_ns=100000 "
       "--set render.time_bin_ps=0.001",
       "render.window_start_ns: set to 0 but does nothing: acquisition.mode is \"intensity\" (no time bins) and outputs.transient "
       "and outputs.light are false"},
  };
  for (const Case& c : cases) {
    const Result r = sh(run + " " + c.set);
    ASSERT_EQ(r.code, 0) << c.set << ": " << r.output;
    const nlohmann::json meta = nlohmann::json::parse(slurp(dir_ / "out/metadata.json"));
    if (c.set.find("intensity") != std::string::npos) {
      EXPECT_EQ(meta["time_axis"]["bins"], 0) << c.set;
    }
    const nlohmann::json warnings = meta["warnings"];
    if (c.warning.empty()) {
      EXPECT_EQ(r.output, "") << c.set;
      EXPECT_EQ(warnings, nlohmann::json::array()) << c.set;
      continue;
    }
    EXPECT_THAT(r.output, HasSubstr("spadgen: warning: " + c.warning)) << c.set;
    bool recorded = false;
    for (const auto& w : warnings) recorded |= w.get<std::string>().find(c.warning) == 0;
    EXPECT_TRUE(recorded) << c.set << ": " << warnings.dump();
  }
  // sense warns of its own sweep's edges (a sound run's light, a sweep that starts too late)
  ASSERT_EQ(sh(run + " --set outputs.light=true").code, 0);
  const Result late = sh("sense " + (dir_ / "out").string() + " -q --set acquisition.gate_sweep.start_ns=8 -o " + (dir_ / "late").string());
  ASSERT_EQ(late.code, 0) << late.output;
  EXPECT_THAT(late.output, HasSubstr("spadgen: warning: 100 % of the objects' returns along the rays (256 of the 256 pairs"));
  EXPECT_THAT(nlohmann::json::parse(slurp(dir_ / "late/metadata.json"))["warnings"].dump(), HasSubstr("rise before the gate sweep's"));
  // ... and drops the run's when its own sweep holds the edges (it kept the run's as the scene's; a reviewer)
  ASSERT_EQ(sh(run + " --set outputs.light=true --set acquisition.gate_sweep.start_ns=8 --set render.window_start_ns=-2 "
               "--set render.window_stop_ns=25").code, 0);
  const Result early = sh("sense " + (dir_ / "out").string() + " -q --set acquisition.gate_sweep.start_ns=0.6 -o " +
                          (dir_ / "early").string());
  ASSERT_EQ(early.code, 0) << early.output;
  EXPECT_THAT(nlohmann::json::parse(slurp(dir_ / "out/metadata.json"))["warnings"].dump(), HasSubstr("rise before"));
  EXPECT_THAT(nlohmann::json::parse(slurp(dir_ / "early/metadata.json"))["warnings"].dump(), Not(HasSubstr("rise before")));
  // sense re-samples the same light: it records the run's warnings, once each.
  ASSERT_EQ(sh(run + " --set camera.look_at_m=[0,0,5] --set outputs.light=true").code, 0);
  const Result sensed = sh("sense " + (dir_ / "out").string() + " -q -o " + (dir_ / "sensed").string());
  ASSERT_EQ(sensed.code, 0) << sensed.output;
  EXPECT_EQ(nlohmann::json::parse(slurp(dir_ / "sensed/metadata.json"))["warnings"],
            nlohmann::json::parse(slurp(dir_ / "out/metadata.json"))["warnings"]);
}

// The plate's two faces fill render.max_layers 2 over the sphere: its slot was dropped without a word, its
// light moved to direct_other_laser and evaluate would score a detection of it as false.
TEST_F(App, AGroundTruthCutByMaxLayersIsWarned) {
  const std::string run = "run " + kScenes + "multi_object.json -q --set camera.crop=[504,242,8,8] "
                          "--set render.samples_per_pixel=1 --set outputs.previews=false -o " + (dir_ / "out").string();
  const std::string warning = "render.max_layers (2) cuts the ground truth of 64 pixels of the 8 x 8 image: their rays pass "
                              "2 transmissive surfaces and meet beyond them an object that gets no slot";
  const Result cut = sh(run + " --set render.max_layers=2");
  ASSERT_EQ(cut.code, 0) << cut.output;
  EXPECT_THAT(cut.output, HasSubstr("spadgen: warning: " + warning));
  EXPECT_THAT(nlohmann::json::parse(slurp(dir_ / "out/metadata.json"))["warnings"].dump(), HasSubstr(warning));
  const Result whole = sh(run);  // the default 8: plate, sphere and nothing cut
  ASSERT_EQ(whole.code, 0) << whole.output;
  EXPECT_THAT(whole.output, ::testing::Not(HasSubstr("max_layers")));
  EXPECT_EQ(nlohmann::json::parse(slurp(dir_ / "out/metadata.json"))["ground_truth_summary"]["max_object_count"], 2);
}

// One channel of an EXR a run wrote.
std::vector<float> exr_channel(const fs::path& file, const std::string& channel) {
  return spadgen::writers::read_exr(file.string()).channels.at(channel);
}

// A point's image (the laser's glint, a lamp) in pixel `at` of an image: 1000 times every other pixel.
void expect_one_point_at(const std::vector<float>& image, size_t at) {
  for (size_t i = 0; i < image.size(); ++i) {
    if (i == at) continue;
    EXPECT_GT(image[at], 1000.0f * image[i]) << i;
  }
}

// A smooth plate (a Dirac reflection) mirrors the laser 3 cm left of the lens into the lens: the camera sees a glint
// at the image's pixel, which no path finds (a verifier found 0 photons where roughness 0.033 gave the closed form).
// The image at (-0.03, 0, -0.9) m lands at x = 512 + 25 mm x (-0.03 / 0.9) / 9.4 um = 423.3, y = 250: laser.exr's
// pixel (3, 2) of the crop holds it, far above the plate's and the sphere's light in the others. The scene's own
// laser, 3 cm right of the lens, has its image off the plate (its reflection point at x > 0), where x = 600.7 sees none.
TEST_F(App, TheCameraSeesTheLasersImageInASmoothPlate) {
  const std::string run = "run " + kScenes + "multi_object.json -q --set render.samples_per_pixel=1 --set outputs.previews=false "
                          "--set acquisition.gate_sweep.step_ps=3600 --set materials.plastic_plate.roughness=0 -o ";
  const auto laser = [&](const std::string& dir) { return exr_channel(dir_ / dir / "laser.exr", "photons_per_pulse"); };
  Result r = sh(run + (dir_ / "glint").string() + " --set laser.offset_m=[-0.03,0,0] --set camera.crop=[420,248,8,4]");
  ASSERT_EQ(r.code, 0) << r.output;
  const std::vector<float> glint = laser("glint");
  ASSERT_EQ(glint.size(), 32u);
  expect_one_point_at(glint, 2 * 8 + 3);
  r = sh(run + (dir_ / "paper").string() + " --set laser.offset_m=[0.03,0,0] --set camera.crop=[596,248,8,4]");
  ASSERT_EQ(r.code, 0) << r.output;
  const std::vector<float> paper = laser("paper");
  EXPECT_LT(*std::max_element(paper.begin(), paper.end()), 1e-3f * glint[2 * 8 + 3]);
}

TEST(AppCommands, InfoWarnsAboutAGltfCameraOfAnotherAspectRatio) {
  const Result r = sh("info " + kScenes + "flat_target.json --set camera.gltf_camera=spad_camera --set camera.height_px=1000");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("warning: camera.gltf_camera: the glTF camera 'spad_camera' has the aspect ratio 2.048"));
  EXPECT_THAT(sh("info " + kScenes + "flat_target.json --set camera.gltf_camera=spad_camera").output,
              ::testing::Not(HasSubstr("warning: camera.gltf_camera")));
}

// info checks camera.gltf_camera as the run does (it printed its summary, and the run refused)
TEST(AppCommands, InfoRefusesACameraTheGltfDoesNotHave) {
  const Result r = sh("info " + kScenes + "flat_target.json --set camera.gltf_camera=zzz");
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("--set camera.gltf_camera: no perspective camera named 'zzz' in"));
  EXPECT_THAT(r.output, HasSubstr("(cameras: 'spad_camera')"));
}

// A transmissive surface 64 m or more from the camera is warned about: the renderer, in a frame centred on
// the camera, steps each path's next ray 256 float ulps of a surface's distance from the camera off it
// (1.95 mm from 64 m), and a 2 mm plate there loses the light behind its back face. The scene's distance
// from the glTF's origin no longer matters (tests/render: Transport.ASceneFarFromTheOriginRendersAsNearIt).
TEST(AppCommands, InfoWarnsAboutAThinPlateFarFromTheCamera) {
  const std::string info = "info " + kScenes + "multi_object.json";
  Result r = sh(info + " --set camera.position_m=[0,0,100] --set camera.look_at_m=[0,0,99]");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("m from the camera, where the renderer moves each path's next ray up to 1.953 mm"));
  EXPECT_THAT(r.output, HasSubstr("the transmissive mesh '"));
  r = sh(info);
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, Not(HasSubstr("next ray")));
  r = sh("info " + kScenes + "flat_target.json --set camera.position_m=[0,0,100]");  // nothing transmissive
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, Not(HasSubstr("next ray")));
}

// A curved refracting volume (vertex normals) of roughness 0.2 or more is warned about: the laser's connections
// cross its faces as smooth ones. A flat one's rough faces are crossed by their own estimate: no warning.
TEST(AppCommands, InfoWarnsAboutARoughCurvedRefractingVolume) {
  const std::string info = "info " + kScenes + "multi_object.json";
  const std::string glass_sphere = " --set materials.sphere_white.transmission=1 --set materials.sphere_white.ior=1.5 "
                                   "--set materials.sphere_white.thickness_mm=100";
  Result r = sh(info + glass_sphere + " --set materials.sphere_white.roughness=0.4");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("warning: the material 'sphere_white' (roughness 0.4) bounds a curved refracting volume (vertex "
                                  "normals) whose faces the laser's connections cross as smooth ones"));
  for (const std::string& fine : {glass_sphere + " --set materials.sphere_white.roughness=0.1",
                                  std::string(" --set materials.plastic_plate.roughness=0.4"),  // flat: crossed rough
                                  glass_sphere + " --set materials.sphere_white.roughness=0.4 --set materials.sphere_white.ior=1"}) {
    r = sh(info + fine);
    ASSERT_EQ(r.code, 0) << r.output;
    EXPECT_THAT(r.output, Not(HasSubstr("cross as smooth ones"))) << fine;
  }
}

// What the run refuses before rendering, info refuses too (it passed both): a laser.gltf_light the glTF
// does not have; gate maps of another size than the sensor; and a pixel design the preset does not use
// is not built (a wavelength its PDP curve refuses failed the run after the 'does nothing' warning).
// The resource plan counts the decoded textures once: the loaded scene and the renderer's copy of it share
// the texels (the test chart's 2048 x 2048 RGBA texture, 16.8 MB: 244 MB planned against a 254 MB peak; the
// texture was held twice, a 271 MB peak).
TEST_F(App, InfoPlansTheDecodedTextures) {
  const Result r = sh("info " + kScenes + "test_chart.json");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("baseColorTexture 'test_chart' (2048x2048, TEXCOORD_0)"));
  const int64_t bytes = int64_t{2048} * 2048 * 4;  // 16.8 MB
  EXPECT_EQ(bytes / 1000000, 16);
  EXPECT_THAT(r.output, HasSubstr("the scene's textures, decoded (1 texture) 17 MB"));
  const Result flat = sh("info " + kScenes + "flat_target.json");
  EXPECT_THAT(flat.output, Not(HasSubstr("textures, decoded")));
}

// The plan counts the sensor's working arrays over the tile and its halo (lambda, and the own avalanches'
// probabilities: 16 bytes per pixel and gate position with crosstalk): at 10,001 gate positions a 32 x 32
// crop peaked at 311 MB against 222 MB planned; the plan covers the peak now, within a factor 2. (Not under
// AddressSanitizer, whose shadow memory is not the program's.)
TEST_F(App, ThePlanCoversThePeakMemoryAtTenThousandGatePositions) {
#if defined(__SANITIZE_ADDRESS__)
  GTEST_SKIP() << "the resident set under AddressSanitizer is not the program's";
#else
  const std::vector<std::string> args = {"--set", "acquisition.gate_sweep.step_ps=1.26", "--set", "camera.crop=[496,236,32,32]",
                                         "--set", "render.samples_per_pixel=1"};
  std::string joined;
  for (const std::string& a : args) joined += " " + a;
  const Result info = sh("info " + kScenes + "multi_object.json" + joined);
  ASSERT_EQ(info.code, 0) << info.output;
  ASSERT_THAT(info.output, HasSubstr("K = 10001 gate positions"));
  const size_t at = info.output.find("memory: about ");
  ASSERT_NE(at, std::string::npos) << info.output;
  std::istringstream planned_text(info.output.substr(at + 14));  // "407 MB", or "1.2 GB"
  double planned_mb = 0.0;
  std::string unit;
  planned_text >> planned_mb >> unit;
  ASSERT_TRUE(unit == "MB" || unit == "GB") << info.output;
  if (unit == "GB") planned_mb *= 1000.0;
  const pid_t pid = ::fork();
  if (pid == 0) {
    std::vector<std::string> argv = {kBin, "run", kScenes + "multi_object.json", "-q", "-o", (dir_ / "k").string()};
    argv.insert(argv.end(), args.begin(), args.end());
    std::vector<char*> p;
    for (std::string& a : argv) p.push_back(a.data());
    p.push_back(nullptr);
    ::execv(kBin.c_str(), p.data());
    ::_exit(127);
  }
  int status = 0;
  struct rusage usage {};
  ASSERT_EQ(::wait4(pid, &status, 0, &usage), pid);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << status;
  const double peak_mb = static_cast<double>(usage.ru_maxrss) * 1024.0 / 1e6;  // ru_maxrss: kB
  EXPECT_GE(planned_mb, peak_mb) << planned_mb << " MB planned";
  EXPECT_LE(planned_mb, 2.0 * peak_mb) << peak_mb << " MB peak";
#endif
}

// A glTF light too bright for the scene's distances (a point light of 1e35 cd half a metre before the target) made
// ambient.exr infinite in every pixel and the rates infinite, exit 0: refused, naming the first pixel (sensor
// coordinates; the tile's own before its halo's) and the likely cause; 1e30 cd renders (finite).
TEST_F(App, ALightTooBrightForFloatOutputsIsRefused) {
  nlohmann::json gltf = nlohmann::json::parse(slurp(kScenes + "flat_target.gltf"));
  gltf["extensionsUsed"].push_back("KHR_lights_punctual");
  gltf["extensions"]["KHR_lights_punctual"]["lights"] = {{{"type", "point"}, {"intensity", 1e35}}};
  gltf["nodes"].push_back({{"name", "bulb"}, {"translation", {0.0, 0.0, 0.5}}, {"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}});
  gltf["scenes"][0]["nodes"].push_back(gltf["nodes"].size() - 1);
  std::ofstream(dir_ / "bright.gltf") << gltf.dump();
  std::string scene = slurp(kScenes + "flat_target.json");
  scene.replace(scene.find("\"flat_target.gltf\""), 18, "\"bright.gltf\"");
  std::ofstream(dir_ / "bright.json") << scene;
  const std::string run = "run " + (dir_ / "bright.json").string() + " -q --set camera.crop=[500,240,8,4] --set render.samples_per_pixel=1 -o ";
  Result r = sh(run + (dir_ / "o35").string());
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("render: sensor pixel (500, 240) receives more than 3.4e38 photons per second of ambient "
                                  "light, beyond what its float32 outputs hold: a glTF light (KHR_lights_punctual intensity)"));
  EXPECT_FALSE(fs::exists(dir_ / "o35"));
  gltf["extensions"]["KHR_lights_punctual"]["lights"][0]["intensity"] = 1e30;
  std::ofstream(dir_ / "bright.gltf") << gltf.dump();
  r = sh(run + (dir_ / "o30").string());
  EXPECT_EQ(r.code, 0) << r.output;
}

// A glTF point light in view is a lamp a real camera sees, which no camera ray meets (a verifier's 10 cd bulb at 1 m
// gave 0 photons): the run renders it in its pixel, (0.01, 0, 0.5) m seen from (0, 0, 1) through 50 mm landing at
// x = 512 + 50 mm x 0.02 / 9.4 um = 618.4, y = 250. A spot light facing away from the camera is not seen.
TEST_F(App, AGltfLampInViewIsSeenInItsPixel) {
  nlohmann::json gltf = nlohmann::json::parse(slurp(kScenes + "flat_target.gltf"));
  gltf["extensionsUsed"].push_back("KHR_lights_punctual");
  gltf["extensions"]["KHR_lights_punctual"]["lights"] = {{{"name", "bulb"}, {"type", "point"}, {"intensity", 10.0}},
                                                         {{"name", "away"}, {"type", "spot"}, {"intensity", 10.0}, {"spot", {{"outerConeAngle", 0.5}}}}};
  for (const auto& [name, x, light] : {std::tuple{"bulb_node", 0.01, 0}, std::tuple{"spot_node", -0.01, 1}}) {
    gltf["nodes"].push_back({{"name", name}, {"translation", {x, 0.0, 0.5}}, {"extensions", {{"KHR_lights_punctual", {{"light", light}}}}}});
    gltf["scenes"][0]["nodes"].push_back(gltf["nodes"].size() - 1);
  }
  std::ofstream(dir_ / "lamp.gltf") << gltf.dump();
  std::string scene = slurp(kScenes + "flat_target.json");
  scene.replace(scene.find("\"flat_target.gltf\""), 18, "\"lamp.gltf\"");
  std::ofstream(dir_ / "lamp.json") << scene;
  const std::string run = "run " + (dir_ / "lamp.json").string() + " -q --set render.samples_per_pixel=1 --set outputs.previews=false "
                          "--set acquisition.gate_sweep.step_ps=3600 -o ";
  const auto ambient = [&](const std::string& dir) { return exr_channel(dir_ / dir / "ambient.exr", "photons_per_second"); };
  // the lamp at the image's (2, 2) of a crop around it, far above the target it lights; the spot, at x = 405.6, nothing
  Result r = sh(run + (dir_ / "bulb").string() + " --set camera.crop=[616,248,4,4]");
  ASSERT_EQ(r.code, 0) << r.output;
  const std::vector<float> bulb = ambient("bulb");
  ASSERT_EQ(bulb.size(), 16u);
  expect_one_point_at(bulb, 2 * 4 + 2);
  r = sh(run + (dir_ / "spot").string() + " --set camera.crop=[403,248,4,4]");
  ASSERT_EQ(r.code, 0) << r.output;
  const std::vector<float> spot = ambient("spot");
  EXPECT_LT(*std::max_element(spot.begin(), spot.end()), 1e-3f * bulb[2 * 4 + 2]);
}

TEST_F(App, InfoRefusesWhatTheRunRefusesAndNotWhatItIgnores) {
  Result r = sh("info " + kScenes + "flat_target.json --set laser.beam=gltf_light --set laser.gltf_light=zzz");
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("--set laser.gltf_light: no KHR_lights_punctual light named 'zzz'"));
  // The keys that name elements of the glTF, given in a scene file: named with the scene file and their
  // pointer (the camera's and the light's named neither; gltf_scene's named only the glTF file).
  const std::string named = (dir_ / "named.json").string();
  const auto scene_file = [&](const std::string& keys) {
    std::ofstream(named) << "{\"gltf\": \"" + kScenes + "flat_target.gltf\", " + keys + "}";
    return sh("info " + named);
  };
  r = scene_file(R"("gltf_scene": "nope")");
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr(named + ": /gltf_scene: the glTF file " + kScenes + "flat_target.gltf has no scene named 'nope'; its scenes are: "));
  EXPECT_THAT(sh("info " + kScenes + "flat_target.json --set gltf_scene=nope").output, HasSubstr("--set gltf_scene: the glTF file "));
  r = scene_file(R"("camera": {"gltf_camera": "zzz"})");
  EXPECT_THAT(r.output, HasSubstr(named + ": /camera/gltf_camera: no perspective camera named 'zzz' in"));
  r = scene_file(R"("laser": {"beam": "gltf_light", "gltf_light": "zzz"})");
  EXPECT_THAT(r.output, HasSubstr(named + ": /laser/gltf_light: no KHR_lights_punctual light named 'zzz'"));
  ASSERT_EQ(sh("run " + kScenes + "flat_target.json -q --set camera.crop=[500,240,8,8] -o " + (dir_ / "crop").string()).code, 0);
  r = sh("info " + kScenes + "flat_target.json --set sensor.gate.maps_exr=" + (dir_ / "crop/sensor_maps.exr").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("expected the full sensor, 1024 x 500 pixels, found 8 x 8"));
  // a file that is no EXR: named with the key and the scene file (it named the file alone)
  std::ofstream(dir_ / "maps.csv") << "a,b\n";
  r = sh("info " + kScenes + "flat_target.json --set sensor.gate.maps_exr=" + (dir_ / "maps.csv").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr(kScenes + "flat_target.json: sensor.gate.maps_exr: cannot read EXR '" + (dir_ / "maps.csv").string()));
  EXPECT_THAT(r.output, HasSubstr("; expected an OpenEXR file of the gate's maps (gate_skew_ps and gate_length_ps channels"));
  r = sh("run " + kScenes + "flat_target.json -q --set camera.crop=[500,240,4,4] --set sensor.pixel_B.pdp_peak_wavelength_nm=250 -o " +
         (dir_ / "b").string());
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("sensor.pixel_B.pdp_peak_wavelength_nm: set to 250 but does nothing"));
}

}  // namespace

// detection_rate.npy keeps the flux where expected counts saturate: at 1000 times the power, lambda is
// 1000 times larger in every pixel and gate (the light and the chip are the same; with neither dark
// counts nor ambient light, and pixel A's crosstalk linear in its neighbours' rates, lambda is linear in
// the power), while expected_counts.npy reads exactly N = 255 wherever 1 - p rounds away in float32.
TEST_F(App, DetectionRateRecoversTheFluxOfASaturatedPixel) {
  const std::string run = "run " + kScenes + "flat_target.json -q --set camera.crop=[508,246,8,8] --set render.samples_per_pixel=1 "
                          "--set sensor.dark_counts=false --set outputs.expected_counts=true --set outputs.previews=false ";
  ASSERT_EQ(sh(run + "-o " + (dir_ / "low").string()).code, 0);
  ASSERT_EQ(sh(run + "--set laser.average_power_mW=2000 -o " + (dir_ / "high").string()).code, 0);
  const std::vector<double> low = values(read_npy(dir_ / "low/detection_rate.npy"));
  const std::vector<double> high = values(read_npy(dir_ / "high/detection_rate.npy"));
  const std::vector<double> high_expected = values(read_npy(dir_ / "high/expected_counts.npy"));
  ASSERT_EQ(low.size(), high.size());
  size_t lit = 0, saturated = 0;
  for (size_t i = 0; i < low.size(); ++i) {
    if (low[i] < 1e-3) continue;  // outside the return: rates of order 1e-30 carry no float32 information
    ++lit;
    ASSERT_NEAR(high[i] / low[i], 1000.0, 1000.0 * 1e-5) << i;
    if (high_expected[i] == 255.0) ++saturated;
  }
  EXPECT_GT(lit, 64u * 20);       // every pixel has a return over tens of gate positions
  EXPECT_GT(saturated, lit / 4);  // and where the expectation saturates, the rate still holds the flux
}
