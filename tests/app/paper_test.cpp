// The paper's experiments reproduced by the whole pipeline (scenes/paper/*.json through the spadgen
// program), checked against the geometry's ground truth:
//  - flat target (paper section 4.D, Fig. 9): depth from the rising edge of the smoothed gate profile,
//    skew compensated (spadgen reconstruct --detector paper), is accurate to better than 1 cm with a precision better than 7.8 mm rms over the
//    central 20 x 20 pixels, at 0.2, 0.8 and 1.6 m;
//  - multi-object (section 4.E, Fig. 10): where the plate covers the sphere, the profile rises twice,
//    at the gate positions the plate's and the sphere's distances predict, about 55 steps apart.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <numeric>
#include <unistd.h>

#include "run_util.h"
#include "writers/writers.h"

namespace {
using namespace spadgen::testing;
constexpr double kC = 299792458.0;

struct SceneRun {
  nlohmann::json meta;
  std::vector<double> counts, expected;  // [k][y][x]
  int64_t K = 0, H = 0, W = 0;
  spadgen::writers::ExrData gt, maps;
  double start_ns = 0, step_ns = 0, emission_delay_ns = 0, gate_delay_ns = 0;

  double at(const std::vector<double>& v, int64_t k, int64_t x, int64_t y) const { return v[size_t((k * H + y) * W + x)]; }
  size_t pixel(int64_t x, int64_t y) const { return size_t(y * W + x); }
};

SceneRun run_scene(const std::string& args, const fs::path& out) {
  const Result r = sh("run " + args + " -q -o " + out.string());
  EXPECT_EQ(r.code, 0) << r.output;
  SceneRun run;
  run.meta = nlohmann::json::parse(slurp(out / "metadata.json"));
  const Npy c = read_npy(out / "counts.npy"), rate = read_npy(out / "detection_rate.npy");
  run.K = c.shape[0], run.H = c.shape[1], run.W = c.shape[2];
  run.counts = values(c), run.expected = values(rate);
  // expected counts N (1 - exp(-lambda)) from the detection rate lambda
  const double N = run.meta["acquisition"]["frames_per_k"];
  for (double& v : run.expected) v = N * -std::expm1(-v);
  run.gt = spadgen::writers::read_exr((out / "ground_truth.exr").string());
  run.maps = spadgen::writers::read_exr((out / "sensor_maps.exr").string());
  const auto& s = run.meta["resolved_scene"];
  run.start_ns = s["acquisition"]["gate_sweep"]["start_ns"];
  run.step_ns = s["acquisition"]["gate_sweep"]["step_ps"].get<double>() / 1000.0;
  run.emission_delay_ns = s["laser"]["emission_delay_ns"];
  run.gate_delay_ns = s["sensor"]["gate"]["delay_ns"];
  return run;
}

double edge_index_for_range(const SceneRun& r, double range_m, size_t px) {
  const double t = r.emission_delay_ns + 2.0 * range_m / kC * 1e9;
  return (t - r.gate_delay_ns - r.maps.channels.at("gate_skew_ps")[px] / 1000.0 -
          r.maps.channels.at("gate_length_ps")[px] / 1000.0 - r.start_ns) / r.step_ns;
}

class Paper : public ::testing::Test {
 protected:
  void SetUp() override {
    // a parameterised test's name holds a '/' ("Name/0"): one folder, not a subfolder that leaves its parent
    std::string name = ::testing::UnitTest::GetInstance()->current_test_info()->name();
    std::replace(name.begin(), name.end(), '/', '_');
    dir_ = fs::temp_directory_path() / ("spadgen_paper_" + name + "_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

class FlatTarget : public Paper, public ::testing::WithParamInterface<double> {};

TEST_P(FlatTarget, RisingEdgeDepthMeetsThePapersAccuracyAndPrecision) {
  const double d = GetParam();
  // The central 20 x 20 pixels of the pixel-A half, through `spadgen reconstruct --detector paper` (the
  // paper's rising edge, skew and length compensated, on the linearised profile: docs/detection.md).
  const SceneRun r = run_scene(kScenes + "flat_target.json --set camera.position_m=[0,0," + std::to_string(d) +
                              "] --set camera.crop=[502,240,20,20] --set render.samples_per_pixel=4",
                          dir_);
  for (const std::string& extra : {std::string("--noise-free"), std::string()}) {  // (their own names in the run)
    const Result rec = sh("reconstruct " + dir_.string() + " --detector paper -q " + extra);
    ASSERT_EQ(rec.code, 0) << rec.output;
  }
  const auto depth_errors = [&](const fs::path& file) {
    const spadgen::writers::ExrData det = spadgen::writers::read_exr(file.string());
    std::vector<double> err;
    for (int64_t y = 0; y < r.H; ++y)
      for (int64_t x = 0; x < r.W; ++x) {
        const size_t px = r.pixel(x, y);
        EXPECT_EQ(det.channels.at("count")[px], 1.0f) << "one return at pixel " << x << ", " << y;
        err.push_back(det.channels.at("det0.range")[px] - r.gt.channels.at("range")[px]);
      }
    return err;
  };
  // Noise-free profiles: the timing chain (emission delay, time of flight, gate delay, skew, length,
  // edges, instrument response) must agree with the geometry to within 3 mm (0.55 gate steps).
  for (double e : depth_errors(dir_ / "detections_paper_noise_free.exr")) ASSERT_LT(std::abs(e), 3e-3) << "noise-free depth error at " << d << " m";
  const std::vector<double> err_sampled = depth_errors(dir_ / "detections_paper.exr");
  const double n = double(err_sampled.size());
  const double mean = std::accumulate(err_sampled.begin(), err_sampled.end(), 0.0) / n;
  double var = 0;
  for (double e : err_sampled) var += (e - mean) * (e - mean);
  const double rms = std::sqrt(var / (n - 1));
  RecordProperty("accuracy_mm", std::to_string(mean * 1e3));
  RecordProperty("precision_mm", std::to_string(rms * 1e3));
  EXPECT_LT(std::abs(mean), 0.01) << "accuracy at " << d << " m";
  EXPECT_LT(rms, 0.0078) << "precision at " << d << " m";
}

INSTANTIATE_TEST_SUITE_P(PaperDistances, FlatTarget, ::testing::Values(0.2, 0.8, 1.6));

TEST_F(Paper, MultiObjectProfilesRiseAtThePlateAndAtTheSphere) {
  // A band across the image centre: left of column 512 the plate covers the sphere.
  const SceneRun r = run_scene(kScenes + "multi_object.json --set camera.crop=[448,242,128,16] --set render.samples_per_pixel=8 "
                                    "--set acquisition.gate_sweep.stop_ns=9",
                          dir_);
  const auto& layers = r.gt.channels.at("layer_count");
  int both = 0, both_found = 0, sphere_only = 0, sphere_only_single = 0;
  std::vector<double> separations;
  for (int64_t y = 0; y < r.H; ++y)
    for (int64_t x = 0; x < r.W; ++x) {
      const size_t px = r.pixel(x, y);
      std::vector<double> p(size_t(r.K));
      for (int64_t k = 0; k < r.K; ++k) p[size_t(k)] = r.at(r.expected, k, x, y);
      // Rising edges: local maxima of the profile's slope above 5 % of its largest rise per step.
      std::vector<double> slope(p.size(), 0.0);
      for (size_t k = 1; k + 1 < p.size(); ++k) slope[k] = (p[k + 1] - p[k - 1]) / 2;
      const double top = *std::max_element(slope.begin(), slope.end());
      std::vector<double> edges;
      for (size_t k = 2; k + 2 < p.size(); ++k)
        if (slope[k] > 0.05 * top && slope[k] >= slope[k - 1] && slope[k] > slope[k + 1] && slope[k] >= slope[k - 2] && slope[k] > slope[k + 2])
          edges.push_back(double(k));
      const int L = int(layers[px]);
      if (L >= 3) {
        ++both;
        const double plate = edge_index_for_range(r, r.gt.channels.at("layer0.range")[px], px);
        const double sphere = edge_index_for_range(r, r.gt.channels.at("layer" + std::to_string(L - 1) + ".range")[px], px);
        const auto near = [&](double k0) {
          return std::any_of(edges.begin(), edges.end(), [&](double e) { return std::abs(e - k0) <= 2.0; });
        };
        if (near(plate) && near(sphere)) ++both_found, separations.push_back(sphere - plate);
      } else if (L == 1) {
        ++sphere_only;
        if (edges.size() == 1) ++sphere_only_single;
      }
    }
  ASSERT_GT(both, 100) << "the crop should contain pixels where the plate covers the sphere";
  ASSERT_GT(sphere_only, 100) << "the crop should contain pixels that see the sphere alone";
  EXPECT_GE(both_found, int(0.95 * both)) << "two rising edges where the plate covers the sphere";
  EXPECT_GE(sphere_only_single, int(0.95 * sphere_only)) << "one rising edge where the sphere is seen alone";
  // The paper: edges "around gate positions 40 and 100", i.e. 0.30 m of extra range = 55.6 steps of 36 ps.
  for (double s : separations) EXPECT_NEAR(s, 55.6, 4.0);
}

}  // namespace
