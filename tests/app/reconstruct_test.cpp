// spadgen reconstruct, run as a user would: the HDR inversion of a 2D run against the sensor's own
// linearised image, the same detections from .npy and Zarr stacks, and clear refusals. (The detectors'
// accuracy on the paper's flat target: paper_test.cpp; the detectors themselves: tests/reconstruct.)
#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>
#include <unistd.h>

#include "run_util.h"
#include "writers/writers.h"

namespace {
using namespace spadgen::testing;

class Reconstruct : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("spadgen_reconstruct_" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()) +
                                        "_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

TEST_F(Reconstruct, HdrOfADualExposureRunIsTheSensorsLinearisedImageWithItsErrorAndSaturation) {
  // The test chart in dual exposure at 30 times its light, so that the brightest patches saturate.
  const fs::path run = dir_ / "run";
  Result r = sh("run " + kScenes + "test_chart_dual.json --set camera.crop=[400,200,64,64] -q -o " + run.string() +
                " --set acquisition.intensity.exposure_us=300");
  ASSERT_EQ(r.code, 0) << r.output;
  r = sh("reconstruct " + run.string() + " -q");
  ASSERT_EQ(r.code, 0) << r.output;
  const auto sensor = spadgen::writers::read_exr((run / "intensity.exr").string());
  const auto hdr = spadgen::writers::read_exr((run / "hdr.exr").string());
  const double N = nlohmann::json::parse(slurp(run / "metadata.json"))["acquisition"]["frames"];
  const double ratio = nlohmann::json::parse(slurp(run / "metadata.json"))["resolved_scene"]["acquisition"]["intensity"]["dual_ratio"];
  const double aL = 2 * ratio / (ratio + 1), aS = 2 / (ratio + 1);
  int saturated = 0, lit = 0;
  for (size_t i = 0; i < hdr.channels.at("photons").size(); ++i) {
    const double c = sensor.channels.at("counts")[i], x = hdr.channels.at("photons")[i], se = hdr.channels.at("photons_se")[i];
    EXPECT_EQ(hdr.channels.at("photons")[i], sensor.channels.at("photons")[i]);
    const bool sat = hdr.channels.at("saturated")[i] > 0.5f;
    EXPECT_EQ(sat, c >= N - 0.5) << "pixel " << i;
    saturated += sat;
    if (sat || c <= 0) continue;
    ++lit;
    // se: the binomial spread of the two halves' counts over the slope of eq. (6), recomputed here
    const double pL = -std::expm1(-aL * x / N), pS = -std::expm1(-aS * x / N);
    const double var = N / 2 * (pL * (1 - pL) + pS * (1 - pS)), slope = 0.5 * (aL * (1 - pL) + aS * (1 - pS));
    EXPECT_NEAR(se, std::sqrt(var) / slope, 1e-3 * se) << "pixel " << i;
  }
  EXPECT_GT(saturated, 0) << "the run should saturate somewhere";
  EXPECT_GT(lit, 1000);
}

TEST_F(Reconstruct, ZarrAndNpyRunsGiveTheSameDetections) {
  for (const char* storage : {"npy", "zarr"}) {
    const Result r = sh("run " + kScenes + "multi_object.json --set camera.crop=[480,242,32,8] --set render.samples_per_pixel=2 -q -o " +
                        (dir_ / storage).string() + " --set outputs.storage=" + storage);
    ASSERT_EQ(r.code, 0) << r.output;
    const Result rec = sh("reconstruct " + (dir_ / storage).string() + " -q --threads 1");
    ASSERT_EQ(rec.code, 0) << rec.output;
  }
  const auto a = spadgen::writers::read_exr((dir_ / "npy" / "detections_edges.exr").string());
  const auto b = spadgen::writers::read_exr((dir_ / "zarr" / "detections_edges.exr").string());
  ASSERT_EQ(a.channels.size(), b.channels.size());
  for (const auto& [name, v] : a.channels) {
    const auto& w = b.channels.at(name);
    for (size_t i = 0; i < v.size(); ++i)
      ASSERT_TRUE(v[i] == w[i] || (std::isnan(v[i]) && std::isnan(w[i]))) << name << " at " << i;
  }
  double found = 0;
  for (float c : a.channels.at("count")) found += c;
  EXPECT_GT(found, 256) << "the crop holds the plate and the sphere: more than one return per pixel on average";
}

TEST_F(Reconstruct, RefusesWhatItCannotReadNamingIt) {
  fs::create_directories(dir_);
  Result r = sh("reconstruct " + dir_.string());
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("not a run folder (no metadata.json)"), std::string::npos) << r.output;
  const fs::path run = dir_ / "run";
  r = sh("run " + kScenes + "flat_target.json --set camera.crop=[502,240,8,8] --set render.samples_per_pixel=1 -q -o " + run.string() +
         " --set outputs.counts=false");
  ASSERT_EQ(r.code, 0) << r.output;
  r = sh("reconstruct " + run.string() + " -q");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("no counts.npy or counts.zarr (outputs.counts)"), std::string::npos) << r.output;
  r = sh("reconstruct " + run.string() + " -q --noise-free");
  EXPECT_EQ(r.code, 0) << r.output;
  r = sh("reconstruct " + run.string() + " --detector median");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("--detector"), std::string::npos) << r.output;
  fs::remove(run / "sensor_maps.exr");
  r = sh("reconstruct " + run.string() + " -q --noise-free");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("no sensor_maps.exr"), std::string::npos) << r.output;
}

}  // namespace
