// spadgen reconstruct, run as a user would: the HDR inversion of a 2D run against the sensor's own
// linearised image, the same detections from .npy and Zarr stacks, and clear refusals. (The detectors'
// accuracy on the paper's flat target: paper_test.cpp; the detectors themselves: tests/reconstruct.)
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfOutputFile.h>
#include <gmock/gmock.h>
#include <sys/wait.h>
#include <unistd.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <tuple>
#include <unistd.h>

#include "run_util.h"
#include "writers/writers.h"

namespace {
using namespace spadgen::testing;
using ::testing::HasSubstr;

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
  // --noise-free: the photons from the rates themselves, N times the mean of the two exposures' lambda, also
  // where the counts saturate (the expected counts, inverted, were clamped at N - 0.5)
  r = sh("reconstruct " + run.string() + " -q --noise-free");
  ASSERT_EQ(r.code, 0) << r.output;
  const auto exact = spadgen::writers::read_exr((run / "hdr_noise_free.exr").string());
  const Npy rates = read_npy(run / "detection_rate.npy");
  ASSERT_EQ(rates.shape.size(), 3u);
  const std::vector<double> lambda = values(rates);
  const size_t pixels = exact.channels.at("photons").size();
  ASSERT_EQ(lambda.size(), 2 * pixels);
  for (size_t i = 0; i < pixels; ++i) {
    const double truth = N * (lambda[i] + lambda[pixels + i]) / 2;
    EXPECT_NEAR(exact.channels.at("photons")[i], truth, 1e-6 * truth + 1e-9) << "pixel " << i;
    // its standard error: what one noisy image's inversion has at the true light (0 where 1 - p is 0 in double)
    const double pL = -std::expm1(-aL * truth / N), pS = -std::expm1(-aS * truth / N);
    const double var = N / 2 * (pL * (1 - pL) + pS * (1 - pS)), slope = 0.5 * (aL * (1 - pL) + aS * (1 - pS));
    const double want = slope > 0 ? std::sqrt(var) / slope : 0.0;
    EXPECT_NEAR(exact.channels.at("photons_se")[i], want, 1e-4 * want) << "pixel " << i;
    const double expected_counts = N / 2 * (-std::expm1(-double(lambda[i])) - std::expm1(-double(lambda[pixels + i])));
    EXPECT_EQ(exact.channels.at("saturated")[i] > 0.5f, expected_counts >= N - 0.5) << "pixel " << i;
  }
  // A 2D run has no gate profiles: the detectors' options are refused, not ignored, and nothing is written.
  for (const char* option : {"--detector paper", "--max-detections 2"}) {
    r = sh("reconstruct " + run.string() + " -q " + option + " -o " + (dir_ / "other.exr").string());
    EXPECT_EQ(r.code, 1) << option;
    EXPECT_THAT(r.output, HasSubstr(std::string(option).substr(0, std::string(option).find(' ')) + ": " + run.string() +
                                    " is a 2D run (an intensity image, no gate profiles to detect returns in)"));
    EXPECT_FALSE(fs::exists(dir_ / "other.exr")) << option;
  }
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
  EXPECT_THAT(r.output, Not(HasSubstr("dataset")));
  std::ofstream(dir_ / "dataset.json") << "{}";  // a dataset's folder: its samples are named
  r = sh("reconstruct " + dir_.string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("(this is a dataset's folder: its samples' run folders are in its samples/, e.g. " +
                                  (dir_ / "samples" / "000000").string() + ")"));
  fs::remove(dir_ / "dataset.json");
  const fs::path run = dir_ / "run";
  r = sh("run " + kScenes + "flat_target.json --set camera.crop=[502,240,8,8] --set render.samples_per_pixel=1 -q -o " + run.string() +
         " --set outputs.counts=false");
  ASSERT_EQ(r.code, 0) << r.output;
  r = sh("reconstruct " + run.string() + " -q");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("no counts.npy or counts.zarr (outputs.counts)"), std::string::npos) << r.output;
  // a run without the rates that saved the light (the README's dataset storage): the sense command named
  const fs::path light_run = dir_ / "light_run";
  r = sh("run " + kScenes + "flat_target.json --set camera.crop=[502,240,8,8] --set render.samples_per_pixel=1 -q -o " +
         light_run.string() + " --set outputs.detection_rate=false --set outputs.light=true --set outputs.previews=false");
  ASSERT_EQ(r.code, 0) << r.output;
  r = sh("reconstruct " + light_run.string() + " -q --noise-free");
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("no detection_rate.npy or .zarr (outputs.detection_rate); it saved the light, from which `spadgen sense " +
                                  light_run.string() + " --set outputs.detection_rate=true -o DIR` writes it without rendering"));
  r = sh("reconstruct " + run.string() + " -q --noise-free");
  EXPECT_EQ(r.code, 0) << r.output;
  // from the expected counts: a file of its own (it replaced the sampled counts' detections)
  EXPECT_TRUE(fs::exists(run / "detections_edges_noise_free.exr"));
  EXPECT_FALSE(fs::exists(run / "detections_edges.exr"));
  r = sh("reconstruct " + run.string() + " --detector median");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("--detector"), std::string::npos) << r.output;
  // evaluate's own options
  r = sh("evaluate " + run.string() + " --region 1,2,3");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("--region 1,2,3: expected X,Y,W,H"), std::string::npos) << r.output;
  r = sh("evaluate " + run.string() + " --region 0,0,1000,10");  // was scored as if it fitted
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("--region 0,0,1000,10: expected a rectangle inside " + run.string() + "'s "), std::string::npos)
      << r.output;
  // x0 + width beyond an int (it overflowed to a negative edge and passed, scoring 0 pixels, exit 0)
  for (const char* region : {"8,0,2147483647,8", "0,1,1,2147483647", "2147483647,2147483647,1,1"}) {
    r = sh("evaluate " + run.string() + " --region " + region + " -o " + (dir_ / "e_region").string());
    EXPECT_EQ(r.code, 1) << region << r.output;
    EXPECT_THAT(r.output, HasSubstr("expected a rectangle inside")) << region;
  }
  r = sh("evaluate " + run.string() + " --tolerance-m 0");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("--tolerance-m: expected a positive, finite number of metres"), std::string::npos) << r.output;
  r = sh("evaluate " + run.string() + " --min-score nan");  // was taken, and dropped every detection
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("--min-score: expected a finite number"), std::string::npos) << r.output;
  r = sh("evaluate " + run.string() + " --tolerance-m inf");  // was taken, and written as null
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("--tolerance-m: expected a positive, finite number of metres"), std::string::npos) << r.output;
  // errors are taken modulo c T / 2 (3.747 m at 40 MHz): a tolerance of c T / 4 or more matched a detection
  // 2.5 m too far as 1.247 m too near
  r = sh("evaluate " + run.string() + " --tolerance-m 1.9");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("--tolerance-m 1.9: expected less than half the range one laser period spans, c T / 4 = 1.8737 m"),
            std::string::npos) << r.output;
  r = sh("evaluate " + dir_.string());
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("neither a run folder (metadata.json) nor a dataset folder (dataset.json)"), std::string::npos) << r.output;
  fs::remove(run / "sensor_maps.exr");
  r = sh("reconstruct " + run.string() + " -q --noise-free");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("no sensor_maps.exr"), std::string::npos) << r.output;
}

// A count above the frames (a hand-edited or damaged counts.npy) or a rate below 0 or NaN is no camera's data:
// reconstruct and evaluate took them without a word, and detected and scored them.
TEST_F(Reconstruct, RefusesCountsAboveTheFramesAndRatesThatAreNoRates) {
  const fs::path run = dir_ / "run";
  Result r = sh("run " + kScenes + "flat_target.json --set camera.crop=[502,240,8,8] --set render.samples_per_pixel=1 -q -o " +
                run.string() + " --set acquisition.frames=100");
  ASSERT_EQ(r.code, 0) << r.output;
  // overwrite one element of a stack in place, after its header
  const auto poke = [](const fs::path& npy, size_t element, const std::string& bytes) {
    std::fstream f(npy, std::ios::in | std::ios::out | std::ios::binary);
    char h[10];
    f.read(h, 10);
    const size_t hlen = size_t(uint8_t(h[8])) | (size_t(uint8_t(h[9])) << 8);
    f.seekp(std::streamoff(10 + hlen + element * bytes.size()));
    f.write(bytes.data(), std::streamsize(bytes.size()));
  };
  const Npy counts = read_npy(run / "counts.npy");
  ASSERT_EQ(counts.descr, "|u1");
  const int64_t K = counts.shape[0];
  // element (k 1, y 2, x 3) of (K, 8, 8)
  poke(run / "counts.npy", size_t(1 * 64 + 2 * 8 + 3), std::string(1, char(101)));
  // evaluate first: it detects in memory when the run has no detections file
  for (const std::string& cmd : {"evaluate " + run.string() + " -q", "reconstruct " + run.string() + " -q"}) {
    r = sh(cmd);
    EXPECT_EQ(r.code, 1) << cmd << r.output;
    EXPECT_THAT(r.output, HasSubstr((run / "counts.npy").string() +
                                    ": count 101 at (k 1, y 2, x 3); expected 0 to 100 (/acquisition/frames_per_k of metadata.json)"))
        << cmd;
  }
  poke(run / "counts.npy", size_t(1 * 64 + 2 * 8 + 3), std::string(1, char(100)));  // N itself is a count
  EXPECT_EQ(sh("reconstruct " + run.string() + " -q").code, 0);
  for (const float bad : {-1.0f, std::numeric_limits<float>::quiet_NaN()}) {
    std::string b(4, '\0');
    std::memcpy(b.data(), &bad, 4);
    poke(run / "detection_rate.npy", size_t((K - 1) * 64 + 7 * 8 + 7), b);
    r = sh("reconstruct " + run.string() + " -q --noise-free");
    EXPECT_EQ(r.code, 1) << r.output;
    EXPECT_THAT(r.output, HasSubstr((run / "detection_rate.npy").string() + ": detection rate " + (bad < 0 ? "-1" : "nan") +
                                    " at (k " + std::to_string(K - 1) + ", y 7, x 7); expected a rate >= 0 (expected detections per frame)"));
  }
}

// evaluate reads ground_truth.exr and labels.exr as the run's: one of another size (replaced since, from
// another crop) was read past its end and scored (exit 0, object counts of garbage); a labels.exr with
// fewer object slots than the ground truth was an internal error (map::at). Each is named.
// metadata.json's integers and the timing's numbers out of range or of another type are named (a frames_per_k of
// -1 was blamed on counts.npy, "expected 0 to -1"; 1e308 overflowed the conversion to int).
TEST_F(Reconstruct, MetadataIntegersOutOfRangeAreNamed) {
  const fs::path run = dir_ / "run";
  ASSERT_EQ(sh("run " + kScenes + "flat_target.json --set render.samples_per_pixel=1 -q --set camera.crop=[502,240,4,4] -o " +
               run.string()).code, 0);
  const std::string meta = slurp(run / "metadata.json");
  for (const char* value : {"-1", "1e308", "9223372036854775808", "0", "\"255\"", "2.5"}) {
    nlohmann::ordered_json m = nlohmann::ordered_json::parse(meta);
    m["acquisition"]["frames_per_k"] = nlohmann::ordered_json::parse(value);
    std::ofstream(run / "metadata.json") << m.dump(2);
    const Result r = sh("reconstruct " + run.string() + " -q -o " + (dir_ / "d.exr").string());
    EXPECT_EQ(r.code, 1) << value << r.output;
    EXPECT_THAT(r.output, HasSubstr((run / "metadata.json").string() + ": /acquisition/frames_per_k is " + m["acquisition"]["frames_per_k"].dump() +
                                    ", not an integer in [1, 65535]")) << value;
  }
  // and its numbers out of their scene-file keys' ranges: an emission delay of 1e308 ns was taken (every
  // return's range negative), a repetition rate of 0 divided by zero
  for (const auto& [pointer, value, range] :
       std::vector<std::tuple<std::string, std::string, std::string>>{
           {"/resolved_scene/laser/emission_delay_ns", "1e308", "[-1e+06, 1e+06]"},
           {"/resolved_scene/laser/emission_delay_ns", "\"0\"", "[-1e+06, 1e+06]"},
           {"/resolved_scene/laser/repetition_rate_MHz", "0", "[1e-06, 100000]"},
           {"/acquisition/gate_step_ps", "-36", "[1e-06, 1e+09]"},
           {"/acquisition/gate/delay_ns", "-1e300", "[-1e+06, 1e+06]"},
           {"/acquisition/gate_positions_ns/0", "2e6", "[-1e+06, 1e+06]"},
           // intrinsics and the laser's position of 1e300 were taken
           {"/camera/intrinsics/0/0", "1e300", "[1e-06, 1e+12]"},
           {"/camera/intrinsics/1/2", "-1e300", "[-1e+12, 1e+12]"},
           {"/camera/laser_position_m/2", "1e300", "[-1e+09, 1e+09]"},
           // the gate's edge, which sets the edges detector's separation (an object here was an internal error)
           {"/acquisition/gate/rise_ps", "{}", "[0, 1e+09]"},
           {"/acquisition/gate/irf_fwhm_ps", "-5", "[0, 1e+09]"}}) {
    nlohmann::ordered_json m = nlohmann::ordered_json::parse(meta);
    m[nlohmann::ordered_json::json_pointer(pointer)] = 987654.25;  // then replaced by the value as written
    std::string text = m.dump(2);
    text.replace(text.find("987654.25"), 9, value);
    std::ofstream(run / "metadata.json") << text;
    const Result r = sh("reconstruct " + run.string() + " -q -o " + (dir_ / "d.exr").string());
    EXPECT_EQ(r.code, 1) << pointer << " " << value << r.output;
    EXPECT_THAT(r.output, HasSubstr((run / "metadata.json").string() + ": " + pointer + " is " +
                                    nlohmann::ordered_json::parse(value).dump() + ", not a number in " + range))
        << pointer << " " << value;
  }
  // and of another type than a run writes: what it is and what was expected (it was "has the wrong type")
  {
    nlohmann::ordered_json m = nlohmann::ordered_json::parse(meta);
    m["acquisition"]["gate_positions_ns"] = "0, 0.036";
    std::ofstream(run / "metadata.json") << m.dump(2);
    const Result r = sh("reconstruct " + run.string() + " -q -o " + (dir_ / "d.exr").string());
    EXPECT_EQ(r.code, 1) << r.output;
    EXPECT_THAT(r.output, HasSubstr((run / "metadata.json").string() + ": /acquisition/gate_positions_ns is \"0, 0.036\"; expected a "
                                    "list of numbers, as a run writes it"));
  }
  // and a mode no run writes (a gate sweep's planes were read as a 2D run's, and an hdr.exr written from them)
  {
    nlohmann::ordered_json m = nlohmann::ordered_json::parse(meta);
    m["acquisition"]["mode"] = "bogus";
    std::ofstream(run / "metadata.json") << m.dump(2);
    const Result r = sh("reconstruct " + run.string() + " -q -o " + (dir_ / "d.exr").string());
    EXPECT_EQ(r.code, 1) << r.output;
    EXPECT_THAT(r.output, HasSubstr((run / "metadata.json").string() + ": /acquisition/mode is \"bogus\", expected \"gate_sweep\" "
                                    "or \"intensity\""));
    EXPECT_FALSE(fs::exists(dir_ / "d.exr"));
  }
  std::ofstream(run / "metadata.json") << meta;
  EXPECT_EQ(sh("reconstruct " + run.string() + " -q -o " + (dir_ / "d.exr").string()).code, 0);
}

// So is one of the same size from another crop (its header's spadgen_crop): it was scored (recall 75 % for
// 99.97 %, an adversarial tester's), and reconstruct timed the edges with another crop's sensor maps.
TEST_F(Reconstruct, EvaluateRefusesLabelsOrGroundTruthThatAreNotTheRuns) {
  const std::string cmd = "run " + kScenes + "flat_target.json --set render.samples_per_pixel=1 -q --set camera.crop=";
  const fs::path run = dir_ / "run", other = dir_ / "other", shifted = dir_ / "shifted";
  ASSERT_EQ(sh(cmd + "[502,240,8,8] -o " + run.string()).code, 0);
  ASSERT_EQ(sh(cmd + "[502,240,4,4] -o " + other.string()).code, 0);
  ASSERT_EQ(sh(cmd + "[300,150,8,8] -o " + shifted.string()).code, 0);
  ASSERT_EQ(sh("reconstruct " + run.string() + " -q").code, 0);
  ASSERT_EQ(sh("evaluate " + run.string() + " -q").code, 0);
  for (const char* file : {"labels.exr", "ground_truth.exr", "sensor_maps.exr"}) {
    const fs::path kept = dir_ / "kept.exr";
    fs::copy_file(run / file, kept, fs::copy_options::overwrite_existing);
    fs::copy_file(other / file, run / file, fs::copy_options::overwrite_existing);
    const Result r = sh("evaluate " + run.string() + " -q");
    EXPECT_EQ(r.code, 1) << file << r.output;
    EXPECT_THAT(r.output, HasSubstr((run / file).string() + ": 4 x 4 pixels, and the run's image is 8 x 8 (metadata.json): a file "
                                    "of another run"));
    fs::copy_file(shifted / file, run / file, fs::copy_options::overwrite_existing);
    for (const char* command : {"evaluate ", "reconstruct "}) {
      if (std::string(command) == "reconstruct " && std::string(file) != "sensor_maps.exr") continue;  // (read by evaluate only)
      const Result s = sh(command + run.string() + " -q -o " + (dir_ / "out.exr").string());
      EXPECT_EQ(s.code, 1) << command << file << s.output;
      EXPECT_THAT(s.output, HasSubstr((run / file).string() + ": an image of the crop [300,150,8,8] (its spadgen_crop), and the "
                                      "run's is [502,240,8,8] (metadata.json image.crop_in_sensor): a file of another run"))
          << command << file;
    }
    fs::copy_file(kept, run / file, fs::copy_options::overwrite_existing);
  }
  // ... and the sensor maps and labels of another chip (a run of another seed, of the same scene and crop):
  // another chip's maps timed the edges 3 times worse (17.5 mm rms for 6.0) and were scored as the run's (an
  // adversarial tester's find). The ground truth, of the scene alone, is the same for any chip.
  const fs::path chip = dir_ / "chip";
  ASSERT_EQ(sh(cmd + "[502,240,8,8] --seed 7 -o " + chip.string()).code, 0);
  for (const char* file : {"labels.exr", "sensor_maps.exr", "ground_truth.exr"}) {
    const fs::path kept = dir_ / "kept.exr";
    fs::copy_file(run / file, kept, fs::copy_options::overwrite_existing);
    fs::copy_file(chip / file, run / file, fs::copy_options::overwrite_existing);
    for (const char* command : {"evaluate ", "reconstruct "}) {
      if (std::string(command) == "reconstruct " && std::string(file) != "sensor_maps.exr") continue;  // (read by evaluate only)
      const Result s = sh(command + run.string() + " -q -o " + (dir_ / "out.exr").string());
      if (std::string(file) == "ground_truth.exr") {
        EXPECT_EQ(s.code, 0) << command << file << s.output;
        continue;
      }
      EXPECT_EQ(s.code, 1) << command << file << s.output;
      EXPECT_THAT(s.output, HasSubstr((run / file).string() + ": made for the chip of seed 7 (its spadgen_chip_seed), and the run's is "
                                      "1 (metadata.json seeds.chip): a file of another run"))
          << command << file;
    }
    fs::copy_file(kept, run / file, fs::copy_options::overwrite_existing);
  }
  // ... and another image of the run in labels.exr's place (its ground truth: the same size, crop and chip)
  {
    const fs::path kept = dir_ / "kept.exr";
    fs::copy_file(run / "labels.exr", kept, fs::copy_options::overwrite_existing);
    fs::copy_file(run / "ground_truth.exr", run / "labels.exr", fs::copy_options::overwrite_existing);
    const Result s = sh("evaluate " + run.string() + " -q -o " + (dir_ / "e_swapped").string());
    EXPECT_EQ(s.code, 1) << s.output;
    EXPECT_THAT(s.output, HasSubstr((run / "labels.exr").string() + ": no channel object0.detectable; expected the labels a gate "
                                    "sweep writes"));
    fs::copy_file(kept, run / "labels.exr", fs::copy_options::overwrite_existing);
  }
  // metadata.json's objects (their names, for the metrics), damaged: named, not an internal error (value() of
  // a number, exit 3)
  const std::string meta = slurp(run / "metadata.json");
  for (const char* objects : {"[1, 2]", "\"x\"", "[{\"id\": \"0\", \"name\": \"a\"}]", "[{\"id\": 0, \"name\": 5}]"}) {
    nlohmann::ordered_json m = nlohmann::ordered_json::parse(meta);
    m["objects"] = nlohmann::ordered_json::parse(objects);
    std::ofstream(run / "metadata.json") << m.dump(2);
    const Result r = sh("evaluate " + run.string() + " -q -o " + (dir_ / "e").string());
    EXPECT_EQ(r.code, 1) << objects << r.output;
    EXPECT_THAT(r.output, HasSubstr((run / "metadata.json").string() + ": objects ")) << objects;
    EXPECT_THAT(r.output, HasSubstr("; expected a list of {\"id\": integer, \"name\": text, ...} as a run writes it")) << objects;
  }
  std::ofstream(run / "metadata.json") << meta;
  EXPECT_EQ(sh("evaluate " + run.string() + " -q -o " + (dir_ / "e").string()).code, 0);
}

// labels.exr's slot j must hold the ground truth's object j in every pixel: a labels file with its slots in
// another order (or another scene's of the same size) scored one object by another's edge, with exit 0.
TEST_F(Reconstruct, EvaluateRefusesLabelsWhoseObjectsAreNotTheGroundTruths) {
  const fs::path run = dir_ / "run";
  ASSERT_EQ(sh("run " + kScenes + "multi_object.json --set camera.crop=[480,242,64,12] --set render.samples_per_pixel=1 -q -o " +
               run.string()).code, 0);
  ASSERT_EQ(sh("reconstruct " + run.string() + " -q").code, 0);
  ASSERT_EQ(sh("evaluate " + run.string() + " -q").code, 0);
  // the same labels with slots 0 and 1 swapped
  const auto labels = spadgen::writers::read_exr((run / "labels.exr").string());
  spadgen::writers::ExrImage swapped(labels.width, labels.height);
  size_t both = 0;
  for (const auto& [name, values] : labels.channels) {
    std::string to = name;
    if (name.rfind("object0.", 0) == 0) to = "object1." + name.substr(8);
    if (name.rfind("object1.", 0) == 0) to = "object0." + name.substr(8);
    std::copy(values.begin(), values.end(), swapped.channel(to));
  }
  for (const auto& [key, value] : labels.attributes) swapped.set_attribute(key, value);
  for (size_t i = 0; i < labels.channels.at("object1.id").size(); ++i) both += labels.channels.at("object1.id")[i] >= 0.0f;
  ASSERT_GT(both, 0u) << "the crop has pixels that see the plate and the sphere";
  swapped.write((run / "labels.exr").string());
  const Result r = sh("evaluate " + run.string() + " -q");
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr((run / "labels.exr").string() + ": pixel ("));
  EXPECT_THAT(r.output, HasSubstr("in slot 0, " + (run / "ground_truth.exr").string() + " object id"));
  EXPECT_THAT(r.output, HasSubstr("the two files are not of one run"));
}

TEST_F(Reconstruct, ARunIntoTheFolderAgainReplacesWhatReconstructAndEvaluateDerivedFromIt) {
  const fs::path run = dir_ / "run";
  const std::string cmd = "run " + kScenes + "flat_target.json --set camera.crop=[502,240,8,8] --set render.samples_per_pixel=1 -q -o " + run.string();
  Result r = sh(cmd);
  ASSERT_EQ(r.code, 0) << r.output;
  ASSERT_EQ(sh("reconstruct " + run.string() + " -q").code, 0);
  ASSERT_EQ(sh("reconstruct " + run.string() + " -q --detector paper").code, 0);
  ASSERT_TRUE(fs::exists(run / "detections_edges.exr") && fs::exists(run / "detections_paper.exr"));
  r = sh(cmd + " --set seeds.noise=7");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_FALSE(fs::exists(run / "detections_edges.exr")) << "derived from the earlier run: replaced with it";
  EXPECT_FALSE(fs::exists(run / "detections_paper.exr"));
  // anything else that spadgen did not write is still refused
  std::ofstream(run / "notes.txt") << "mine";
  r = sh(cmd);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("notes.txt"), std::string::npos) << r.output;
}

// reconstruct -o at a run's top takes no other of its outputs' names (the noise-free edges detector written as
// detections_edges.exr was scored as the noisy one, recall 100 % against 95 %; the edges detector's as
// detections_paper.exr), and evaluate refuses a default file another detector wrote (a copy, an older -o).
TEST_F(Reconstruct, AnOutputAtTheRunsTopHasItsOwnNameAndEvaluateChecksIt) {
  const fs::path run = dir_ / "run";
  ASSERT_EQ(sh("run " + kScenes + "flat_target.json --set camera.crop=[502,240,8,8] --set render.samples_per_pixel=1 -q -o " +
               run.string()).code, 0);
  for (const auto& [args, name, own] : {std::tuple{" --noise-free", "detections_edges.exr", "detections_edges_noise_free.exr"},
                                        {"", "detections_paper.exr", "detections_edges.exr"},
                                        {" --detector paper", "hdr.exr", "detections_paper.exr"}}) {
    const Result r = sh("reconstruct " + run.string() + args + " -q -o " + (run / name).string());
    EXPECT_EQ(r.code, 1) << name;
    EXPECT_THAT(r.output, HasSubstr((run / name).string() + ": is the name of another of reconstruct's outputs at the top of the "
                                    "run folder " + run.string() + ", which evaluate and Python read as that output; this one's is " + own));
    EXPECT_FALSE(fs::exists(run / name)) << name;
  }
  // nor at another run's top (another run's detections were scored as that run's)
  const fs::path other = dir_ / "other";
  ASSERT_EQ(sh("run " + kScenes + "flat_target.json --set camera.crop=[502,240,8,8] --set render.samples_per_pixel=1 --set seed=7 -q -o " +
               other.string()).code, 0);
  {
    const Result o = sh("reconstruct " + run.string() + " -q -o " + (other / "detections_edges.exr").string());
    EXPECT_EQ(o.code, 1);
    EXPECT_THAT(o.output, HasSubstr(": lies in the run folder " + other.string() + ", which holds only what spadgen writes there"));
    EXPECT_FALSE(fs::exists(other / "detections_edges.exr"));
  }
  ASSERT_EQ(sh("reconstruct " + run.string() + " -q --noise-free -o " + (run / "detections_edges_noise_free.exr").string()).code, 0);
  fs::copy_file(run / "detections_edges_noise_free.exr", run / "detections_edges.exr");
  Result r = sh("evaluate " + run.string() + " -q");
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("detections_edges.exr: written by reconstruct's edges detector on the noise-free rates, not "
                                  "the edges detector its name stands for"));
  r = sh("evaluate " + run.string() + " -q --noise-free");  // the file of that name is that detector's: scored
  EXPECT_EQ(r.code, 0) << r.output;
  const auto m = nlohmann::json::parse(slurp(run / "evaluation" / "metrics.json"));
  EXPECT_EQ(m["detections_source"]["made_by"], nlohmann::json({{"detector", "edges"}, {"noise_free", true}}));
}

// reconstruct -o takes a name ending in .exr only: evaluate --detections reads a .npy name as a NumPy array (-o
// det.npy wrote an EXR there, exit 0, which evaluate refused); a 2D run's hdr.exr alike.
TEST_F(Reconstruct, AnOutputNotNamedExrIsRefused) {
  const fs::path run = dir_ / "run";
  ASSERT_EQ(sh("run " + kScenes + "flat_target.json --set camera.crop=[502,240,8,8] --set render.samples_per_pixel=1 -q -o " +
               run.string()).code, 0);
  for (const char* name : {"det.npy", "det", "det.EXR"}) {
    const Result r = sh("reconstruct " + run.string() + " -q -o " + (dir_ / name).string());
    EXPECT_EQ(r.code, 1) << name;
    EXPECT_THAT(r.output, HasSubstr((dir_ / name).string() + ": reconstruct writes an OpenEXR image, which evaluate --detections "
                                    "tells by its name (a .npy name is read as a NumPy array of detections); expected a name "
                                    "ending in .exr (-o)"));
    EXPECT_FALSE(fs::exists(dir_ / name)) << name;
  }
  const Result r = sh("reconstruct " + run.string() + " -q -o " + (dir_ / "det.exr").string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(sh("evaluate " + run.string() + " -q --detections " + (dir_ / "det.exr").string() + " -o " + (dir_ / "e").string()).code, 0);
}

// A dataset sample scored with detections made from another sample (other parameters: the same scene file and
// crop, so the scene hash and crop agreed and the source was reported checked) is refused; its own detections
// and a realisation's are scored.
TEST_F(Reconstruct, EvaluateRefusesAnotherDatasetSamplesDetections) {
  const fs::path out = dir_ / "ds";
  fs::create_directories(dir_);
  std::ofstream(dir_ / "d.json") << "{\"scenes\": [\"" + kScenes + "multi_object.json\"], \"seed\": 3, \"repeats\": 2,"
                                    "\"set\": {\"render.samples_per_pixel\": 2, \"camera.crop\": [480, 242, 16, 4]},"
                                    "\"grid\": {\"laser.average_power_mW\": [1, 3]}}";
  const Result made = sh("dataset run " + (dir_ / "d.json").string() + " -o " + out.string() + " -q");
  ASSERT_EQ(made.code, 0) << made.output;
  fs::create_directories(dir_ / "swapped");
  fs::create_directories(dir_ / "own");
  for (const auto& [from, to] : {std::pair{"000000", "000001"}, {"000001", "000000"}, {"000000_r01", "000001_r01"}, {"000001_r01", "000000_r01"}}) {
    ASSERT_EQ(sh("reconstruct " + (out / "samples" / from).string() + " -q -o " + (dir_ / "swapped" / (std::string(to) + ".exr")).string()).code, 0);
    // a realisation's own detections from its sample's folder: the same sample_hash, scored
    const std::string own_from = std::string(to).substr(0, 6);
    ASSERT_EQ(sh("reconstruct " + (out / "samples" / own_from).string() + " -q -o " + (dir_ / "own" / (std::string(to) + ".exr")).string()).code, 0);
  }
  Result r = sh("evaluate " + out.string() + " --detections " + (dir_ / "swapped" / "{sample}.exr").string() + " -o " + (dir_ / "e1").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("swapped/000000.exr: detections of a run of other settings than " +
                                  (out / "samples" / "000000").string() + " (made from "));
  EXPECT_FALSE(fs::exists(dir_ / "e1"));
  r = sh("evaluate " + out.string() + " --detections " + (dir_ / "own" / "{sample}.exr").string() + " -o " + (dir_ / "e2").string());
  EXPECT_EQ(r.code, 0) << r.output;
  const auto m = nlohmann::json::parse(slurp(dir_ / "e2" / "metrics.json"));
  ASSERT_EQ(m["samples"].size(), 4u);
  for (const auto& s : m["samples"])
    EXPECT_THAT(s["detections_source"]["source_checked"].get<std::string>(), HasSubstr("yes: made from")) << s["sample"];

  // Some samples only (a validation split): --samples, also from a file; the evaluation is of those, and
  // dataset status does not count the others as missing from it.
  r = sh("evaluate " + out.string() + " --samples 1");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("2 sample folders (realisations included)"));
  const auto sub = nlohmann::json::parse(slurp(out / "evaluation" / "metrics.json"));
  EXPECT_EQ(sub["selection"], nlohmann::json::parse("[[1, 1]]"));  // ranges, first and last
  ASSERT_EQ(sub["samples"].size(), 2u);
  EXPECT_EQ(sub["samples"][0]["sample"], "000001");
  EXPECT_EQ(sub["samples"][1]["sample"], "000001_r01");
  EXPECT_THAT(sh("dataset status " + out.string()).output, HasSubstr("evaluation/ is current, of some samples only: 1 (evaluate --samples)\n"));
  EXPECT_EQ(shell(kBin + " dataset run " + (dir_ / "d.json").string() + " -o " + out.string() + " -q 2>&1").output, "");  // (nothing out of date)
  std::ofstream(dir_ / "split.txt") << "0\n\n1\n";
  r = sh("evaluate " + out.string() + " --samples @" + (dir_ / "split.txt").string() + " -o " + (dir_ / "e3").string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(nlohmann::json::parse(slurp(dir_ / "e3" / "metrics.json"))["samples"].size(), 4u);
  std::ofstream(dir_ / "empty.txt") << "\n";
  // (a range of 10^8 samples is checked against the dataset at once: it was expanded first, 4.7 GB and 57 s)
  for (const auto& [list, says] : {std::pair<std::string, std::string>{"2", "sample 2 is not one of the dataset's 2 (index.jsonl: 0 to 1)"},
                                   {"0-100000000", "sample 100000000 is not one of the dataset's 2"},
                                   {"0-x", "found 'x', expected dataset indices and ranges such as 0,3,5-8"},
                                   {"1-0", "the range 1-0 is empty"},
                                   {"0,,1", "--samples 0,,1: an empty element between commas"},
                                   {"0,", "--samples 0,: an empty element between commas"},
                                   {",0", "--samples ,0: an empty element between commas"},
                                   {"\"\"", "selects no samples"},
                                   {"@" + (dir_ / "empty.txt").string(), "selects no samples"}}) {
    r = sh("evaluate " + out.string() + " --samples " + list + " -o " + (dir_ / "e4").string());
    EXPECT_EQ(r.code, 1) << list;
    EXPECT_THAT(r.output, HasSubstr(says)) << list;
  }
  r = sh("evaluate " + (out / "samples" / "000000").string() + " --samples 0 -o " + (dir_ / "e4").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("chooses samples of a dataset; "));
  EXPECT_FALSE(fs::exists(dir_ / "e4"));
  r = sh("evaluate " + out.string() + " --samples 1,1,0-1 -o " + (dir_ / "e5").string());  // overlapping: each once
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(nlohmann::json::parse(slurp(dir_ / "e5" / "metrics.json"))["selection"], nlohmann::json::parse("[[0, 1]]"));

  // Samples that differ in their seed only (no grid, no random keys): the same parameters, so one's detections
  // are scored on the other, as another seed's are (the sample's hash, which holds the seeds, refused them).
  std::ofstream(dir_ / "seeds.json") << "{\"scenes\": [\"" + kScenes + "multi_object.json\"], \"seed\": 3, \"samples\": 2,"
                                        "\"set\": {\"render.samples_per_pixel\": 2, \"camera.crop\": [480, 242, 16, 4]}}";
  ASSERT_EQ(sh("dataset run " + (dir_ / "seeds.json").string() + " -o " + (dir_ / "seeds").string() + " -q").code, 0);
  fs::create_directories(dir_ / "seed_swap");
  for (const auto& [from, to] : {std::pair{"000000", "000001"}, {"000001", "000000"}})
    ASSERT_EQ(sh("reconstruct " + (dir_ / "seeds" / "samples" / from).string() + " -q -o " +
                 (dir_ / "seed_swap" / (std::string(to) + ".exr")).string()).code, 0);
  r = sh("evaluate " + (dir_ / "seeds").string() + " --detections " + (dir_ / "seed_swap" / "{sample}.exr").string() + " -o " +
         (dir_ / "e6").string());
  ASSERT_EQ(r.code, 0) << r.output;
  const auto m6 = nlohmann::json::parse(slurp(dir_ / "e6" / "metrics.json"));  // (a temporary's member dangled)
  for (const auto& s : m6["samples"])
    EXPECT_THAT(s["detections_source"]["source_checked"].get<std::string>(), HasSubstr("yes: made from")) << s["sample"];
  // Plain runs: another --set value the scene hash does not see (the pulse) is refused, another path count or
  // seed is scored.
  const std::string run = "run " + kScenes + "multi_object.json --set camera.crop=[480,242,16,4] -q";
  ASSERT_EQ(sh(run + " --set render.samples_per_pixel=2 -o " + (dir_ / "p1").string()).code, 0);
  ASSERT_EQ(sh(run + " --set render.samples_per_pixel=4 --set seed=9 -o " + (dir_ / "p2").string()).code, 0);
  ASSERT_EQ(sh(run + " --set render.samples_per_pixel=2 --set laser.pulse_fwhm_ps=3000 -o " + (dir_ / "p3").string()).code, 0);
  ASSERT_EQ(sh("reconstruct " + (dir_ / "p1").string() + " -q -o " + (dir_ / "p1.exr").string()).code, 0);
  r = sh("evaluate " + (dir_ / "p2").string() + " --detections " + (dir_ / "p1.exr").string() + " -o " + (dir_ / "e7").string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(nlohmann::json::parse(slurp(dir_ / "e7" / "metrics.json"))["detections_source"]["source_checked"].get<std::string>(),
              HasSubstr("yes: made from " + (dir_ / "p1").string() + ", the same scene, settings and crop"));
  r = sh("evaluate " + (dir_ / "p3").string() + " --detections " + (dir_ / "p1.exr").string() + " -o " + (dir_ / "e8").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("p1.exr: detections of a run of other settings than " + (dir_ / "p3").string()));
}

// A plate over a sphere: a crop where both are seen, and the sphere alone on the right.
const std::string kMultiObjectCrop = " --set camera.crop=[480,242,64,12] --set render.samples_per_pixel=4 -q -o ";

TEST_F(Reconstruct, EvaluateScoresTheEdgeDetectorOnThePlateAndTheSphere) {
  const fs::path run = dir_ / "run";
  Result r = sh("run " + kScenes + "multi_object.json" + kMultiObjectCrop + run.string());
  ASSERT_EQ(r.code, 0) << r.output;
  r = sh("reconstruct " + run.string() + " -q");
  ASSERT_EQ(r.code, 0) << r.output;
  r = sh("evaluate " + run.string() + " --region 40,0,24,12");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("objects found:"), std::string::npos) << r.output;
  const auto m = nlohmann::json::parse(slurp(run / "evaluation" / "metrics.json"));
  EXPECT_EQ(m["detections_source"]["file"], (run / "detections_edges.exr").string());
  // the object labels: the plate and the sphere, by their glTF node names
  ASSERT_EQ(m["by_object"].size(), 2u) << m.dump(1);
  std::map<std::string, nlohmann::json> by_name;
  for (const auto& o : m["by_object"]) by_name[o["name"]] = o;
  ASSERT_TRUE(by_name.count("plate") && by_name.count("sphere")) << m.dump(1);
  EXPECT_GE(by_name["plate"]["recall"].get<double>(), 0.95);
  EXPECT_GE(by_name["sphere"]["recall"].get<double>(), 0.9);
  EXPECT_GE(m["objects_detectable"]["recall"].get<double>(), 0.95);
  EXPECT_GE(m["detections"]["precision"].get<double>(), 0.95);
  EXPECT_GT(m["objects_by_count_on_pixel"]["2"]["objects"].get<int>(), 100);
  EXPECT_LT(std::abs(m["range_error"]["bias_mm"].get<double>()), 10.0);
  EXPECT_EQ(m["region"]["count"].get<int>(), 24 * 12) << "the sphere alone, found on every pixel of the region";
  for (const char* png : {"range_error.png", "outcome.png"}) EXPECT_TRUE(fs::exists(run / "evaluation" / png)) << png;
}

// The multi-object scene's laser sits 3 cm right of the lens: on the right of the view the sphere's return
// travels 2.6 mm less than twice its range. The detectors convert a return's half path into range with
// the laser's position (metadata.json camera.laser_position_m): noise-free, the sphere there is found
// without that bias (c t / 2 gave -1.30 mm; the detector's own error is a few hundredths).
TEST_F(Reconstruct, TheLaserBesideTheLensIsNotADepthBias) {
  const fs::path run = dir_ / "run";
  Result r = sh("run " + kScenes + "multi_object.json -q --set camera.crop=[768,150,64,64] --set render.samples_per_pixel=4 -o " + run.string());
  ASSERT_EQ(r.code, 0) << r.output;
  const auto meta = nlohmann::json::parse(slurp(run / "metadata.json"));
  EXPECT_EQ(meta["camera"]["laser_position_m"], nlohmann::json::parse("[0.03, 0.0, 0.0]"));
  // The same point in the world's frame: camera_to_world applied to it.
  const auto& M = meta["camera"]["camera_to_world"];
  for (int i = 0; i < 3; ++i) {
    double w = M[i][3].get<double>();
    for (int j = 0; j < 3; ++j) w += M[i][j].get<double>() * meta["camera"]["laser_position_m"][j].get<double>();
    EXPECT_NEAR(meta["camera"]["laser_world_position_m"][i].get<double>(), w, 1e-12) << i;
  }
  r = sh("evaluate " + run.string() + " --noise-free --detector edges -q");
  ASSERT_EQ(r.code, 0) << r.output;
  const auto m = nlohmann::json::parse(slurp(run / "evaluation" / "metrics.json"));
  ASSERT_EQ(m["by_object"].size(), 1u) << m.dump(1);
  EXPECT_EQ(m["by_object"][0]["name"], "sphere");
  EXPECT_GT(m["by_object"][0]["recall"].get<double>(), 0.95);
  EXPECT_LT(std::abs(m["by_object"][0]["range_error"]["bias_mm"].get<double>()), 0.1) << m["by_object"][0].dump();
}

TEST_F(Reconstruct, EvaluateScoresADetectionsNpyAgainstTheLabelsExactly) {
  const fs::path run = dir_ / "run";
  Result r = sh("run " + kScenes + "multi_object.json" + kMultiObjectCrop + run.string());
  ASSERT_EQ(r.code, 0) << r.output;
  const auto gt = spadgen::writers::read_exr((run / "ground_truth.exr").string());
  const int W = gt.width, H = gt.height, M = 3;
  // A detector that returns every labelled object 1 cm too far, and a false return at 2 m on row 0.
  std::vector<float> ranges(size_t(W * H * M), std::nanf(""));
  int objects = 0;
  for (int i = 0; i < W * H; ++i)
    for (int j = 0; j < 2 && gt.channels.count("object" + std::to_string(j) + ".range"); ++j) {
      const float v = gt.channels.at("object" + std::to_string(j) + ".range")[size_t(i)];
      if (std::isfinite(v)) ranges[size_t(i * M + j)] = v + 0.01f, ++objects;
    }
  for (int x = 0; x < W; ++x) ranges[size_t(x * M + 2)] = 2.0f;
  {
    spadgen::writers::NpyWriter npy((dir_ / "mine.npy").string(), spadgen::writers::Dtype::F32, {H, W, M});
    npy.write(0, ranges.data(), int64_t(ranges.size()));
    npy.commit();
  }
  r = sh("evaluate " + run.string() + " --detections " + (dir_ / "mine.npy").string() + " -o " + (dir_ / "eval").string());
  ASSERT_EQ(r.code, 0) << r.output;
  const auto m = nlohmann::json::parse(slurp(dir_ / "eval" / "metrics.json"));
  EXPECT_EQ(m["objects"]["objects"], objects);
  EXPECT_EQ(m["objects"]["found"], objects);
  EXPECT_EQ(m["detections"]["false"], W);
  EXPECT_EQ(m["detections"]["total"], objects + W);
  EXPECT_NEAR(m["range_error"]["bias_mm"].get<double>(), 10.0, 0.01);  // float ranges: 1 cm to about 1e-7 m
  EXPECT_NEAR(m["range_error"]["std_mm"].get<double>(), 0.0, 0.01);
  EXPECT_THAT(r.output, Not(HasSubstr("matched across the laser period"))) << r.output;
  // The same a whole laser period's range further (c T / 2): matched, as the camera cannot tell them apart,
  // and the summary says that every match is across the period, asking whether the ranges are in metres (a
  // detector's millimetres scored a plausible recall and bias without a word).
  {
    const auto meta = nlohmann::json::parse(slurp(run / "metadata.json"));
    const double period_range = 299'792'458.0 / (2e6 * meta["resolved_scene"]["laser"]["repetition_rate_MHz"].get<double>());
    std::vector<float> folded(ranges);
    for (size_t i = 0; i < folded.size(); ++i)
      if (i % size_t(M) != 2) folded[i] += float(period_range);
    spadgen::writers::NpyWriter npy((dir_ / "folded.npy").string(), spadgen::writers::Dtype::F32, {H, W, M});
    npy.write(0, folded.data(), int64_t(folded.size()));
    npy.commit();
  }
  r = sh("evaluate " + run.string() + " --detections " + (dir_ / "folded.npy").string() + " -o " + (dir_ / "eval_folded").string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(nlohmann::json::parse(slurp(dir_ / "eval_folded" / "metrics.json"))["detections"]["matched_across_period"], objects);
  EXPECT_THAT(r.output, HasSubstr("matched across the laser period: " + std::to_string(objects) + " of the " +
                                  std::to_string(objects) + " matched detections lie a whole c T / 2")) << r.output;
  EXPECT_THAT(r.output, HasSubstr("are the detections' ranges in metres from the camera centre")) << r.output;
  // beyond a tolerance below the shift, nothing matches
  r = sh("evaluate " + run.string() + " --detections " + (dir_ / "mine.npy").string() + " -o " + (dir_ / "eval2").string() +
         " --tolerance-m 0.005");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(nlohmann::json::parse(slurp(dir_ / "eval2" / "metrics.json"))["objects"]["found"], 0);
  // a file of another size is refused, naming it
  {
    spadgen::writers::NpyWriter npy((dir_ / "wrong.npy").string(), spadgen::writers::Dtype::F32, {H + 1, W, M});
    npy.commit();
  }
  r = sh("evaluate " + run.string() + " --detections " + (dir_ / "wrong.npy").string() + " -o " + (dir_ / "eval3").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("wrong.npy: expected a float32 or float64 array (H, W, M)"), std::string::npos) << r.output;
  EXPECT_THAT(r.output, HasSubstr(", M) of ranges, found shape (" + std::to_string(H + 1) + ", " + std::to_string(W) + ", " +
                                  std::to_string(M) + ")"));
  EXPECT_FALSE(fs::exists(dir_ / "eval3")) << "a refused evaluation leaves no empty folder";
  // (M, H, W), as Python's Run.detections().range gives it, is named as such with the axis move
  {
    spadgen::writers::NpyWriter npy((dir_ / "mhw.npy").string(), spadgen::writers::Dtype::F32, {M, H, W});
    npy.commit();
  }
  r = sh("evaluate " + run.string() + " --detections " + (dir_ / "mhw.npy").string() + " -o " + (dir_ / "eval3").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr(": (M, H, W), as Python's Run.detections().range gives it; np.moveaxis(a, 0, -1) is (H, W, M)"));
  // the run's own counts stack is named as such (its (K, H, W) shape was said to be transposed detections), and
  // a uint8 (M, H, W) array elsewhere is refused for its dtype first (the axis advice led to a dtype error)
  r = sh("evaluate " + run.string() + " --detections " + (run / "counts.npy").string() + " -o " + (dir_ / "eval3").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("counts.npy: is the run's own counts.npy (" + run.string() +
                                  "/metadata.json lists it), not detections; expected a detector's output"));
  {
    spadgen::writers::NpyWriter npy((dir_ / "mhw_u8.npy").string(), spadgen::writers::Dtype::U8, {M, H, W});
    npy.commit();
  }
  r = sh("evaluate " + run.string() + " --detections " + (dir_ / "mhw_u8.npy").string() + " -o " + (dir_ / "eval3").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("mhw_u8.npy: its dtype is |u1; expected <f4 or <f8 ranges in metres"));
  EXPECT_THAT(r.output, Not(HasSubstr("moveaxis")));
  // -o the run folder itself: said to be the run (it was refused for files "spadgen did not write there"), and
  // the run is left as it was
  const auto listed_before = nlohmann::json::parse(slurp(run / "metadata.json"))["files"];
  r = sh("evaluate " + run.string() + " --detections " + (dir_ / "mine.npy").string() + " -o " + run.string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("-o " + run.string() + ": is a run folder (its metadata.json); an evaluation replaces the "
                                  "whole folder it writes, so it needs a folder of its own: leave -o out for " +
                                  (run / "evaluation").string()));
  EXPECT_EQ(nlohmann::json::parse(slurp(run / "metadata.json"))["files"], listed_before);
  for (const char* f : {"counts.npy", "labels.exr", "ground_truth.exr"}) EXPECT_TRUE(fs::exists(run / f)) << f;
  // a file that is not there: --detections named it (the message said to give --detections)
  r = sh("evaluate " + run.string() + " --detections " + (dir_ / "none.npy").string() + " -o " + (dir_ / "eval3").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("none.npy: no such file; expected the detections file --detections names"));
  EXPECT_THAT(r.output, Not(HasSubstr("or give --detections")));
  // the same ranges as float64 (NumPy's default dtype; it was refused): the same scores
  {
    spadgen::writers::NpyWriter npy((dir_ / "f8.npy").string(), spadgen::writers::Dtype::F64, {H, W, M});
    const std::vector<double> r64(ranges.begin(), ranges.end());
    npy.write(0, r64.data(), int64_t(r64.size()));
    npy.commit();
  }
  r = sh("evaluate " + run.string() + " --detections " + (dir_ / "f8.npy").string() + " -o " + (dir_ / "eval_f8").string());
  ASSERT_EQ(r.code, 0) << r.output;
  const auto m8 = nlohmann::json::parse(slurp(dir_ / "eval_f8" / "metrics.json"));
  EXPECT_EQ(m8["objects"], m["objects"]);
  EXPECT_EQ(m8["detections"], m["detections"]);
  EXPECT_EQ(m8["range_error"], m["range_error"]);
  // other dtypes: named, and the ones expected
  {
    spadgen::writers::NpyWriter npy((dir_ / "i4.npy").string(), spadgen::writers::Dtype::I32, {H, W, M});
    npy.commit();
  }
  r = sh("evaluate " + run.string() + " --detections " + (dir_ / "i4.npy").string() + " -o " + (dir_ / "eval3").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("i4.npy: its dtype is <i4; expected <f4 or <f8 ranges in metres"), std::string::npos) << r.output;
  // a float64 beyond float32's range is named (its conversion was undefined)
  {
    spadgen::writers::NpyWriter npy((dir_ / "huge.npy").string(), spadgen::writers::Dtype::F64, {H, W, M});
    std::vector<double> v(size_t(H * W * M), std::numeric_limits<double>::quiet_NaN());
    v[size_t(M) + 1] = 1e39;  // pixel (1, 0), detection 1
    npy.write(0, v.data(), int64_t(v.size()));
    npy.commit();
  }
  r = sh("evaluate " + run.string() + " --detections " + (dir_ / "huge.npy").string() + " -o " + (dir_ / "eval_huge").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("huge.npy: the range 1e+39 m at pixel (x 1, y 0), detection 1, is beyond float32's range"));
  // an infinite range is neither metres nor "none" (it was skipped as if nothing were there)
  {
    spadgen::writers::NpyWriter npy((dir_ / "inf.npy").string(), spadgen::writers::Dtype::F32, {H, W, M});
    std::vector<float> v(size_t(H * W * M), std::numeric_limits<float>::quiet_NaN());
    v[size_t(M) + 1] = std::numeric_limits<float>::infinity();  // pixel (1, 0), slot 1
    npy.write(0, v.data(), int64_t(v.size()));
    npy.commit();
  }
  r = sh("evaluate " + run.string() + " --detections " + (dir_ / "inf.npy").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("inf.npy: pixel (x 1, y 0) slot 1 holds an infinite range"), std::string::npos) << r.output;
  // nor is a negative one (a sentinel -1 for "none" was scored as a false detection)
  {
    spadgen::writers::NpyWriter npy((dir_ / "neg.npy").string(), spadgen::writers::Dtype::F32, {H, W, M});
    std::vector<float> v(size_t(H * W * M), std::numeric_limits<float>::quiet_NaN());
    v[size_t(2 * W * M) + 2] = -1.0f;  // pixel (0, 2), slot 2
    npy.write(0, v.data(), int64_t(v.size()));
    npy.commit();
  }
  r = sh("evaluate " + run.string() + " --detections " + (dir_ / "neg.npy").string() + " -o " + (dir_ / "eval").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("neg.npy: pixel (x 0, y 2) slot 2 holds a negative range (-1)"), std::string::npos) << r.output;
  // ... and the refused evaluation left the earlier one in eval/ as it was
  EXPECT_EQ(nlohmann::json::parse(slurp(dir_ / "eval" / "metrics.json"))["objects"]["found"], objects);
}

// evaluate writes its folder whole or not at all (app/staging.h): a run's evaluation (metrics and maps)
// replaced by a dataset's leaves no map behind, and evaluate does not write into a run folder or a folder
// of other files.
TEST_F(Reconstruct, EvaluateReplacesItsFolderWholeAndOnlyItsOwn) {
  const fs::path run = dir_ / "run";
  Result r = sh("run " + kScenes + "multi_object.json" + kMultiObjectCrop + run.string());
  ASSERT_EQ(r.code, 0) << r.output;
  const fs::path eval = dir_ / "eval";
  r = sh("evaluate " + run.string() + " -o " + eval.string());
  ASSERT_EQ(r.code, 0) << r.output;
  ASSERT_TRUE(fs::exists(eval / "outcome.png"));
  const std::string metrics = slurp(eval / "metrics.json");
  // a second evaluation with another tolerance replaces the first whole
  r = sh("evaluate " + run.string() + " -o " + eval.string() + " --tolerance-m 0.001");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(slurp(eval / "metrics.json"), metrics);
  EXPECT_EQ(nlohmann::json::parse(slurp(eval / "metrics.json"))["matching"]["tolerance_m"].get<double>(), 0.001);
  // the run folder itself, or a folder of someone else's files, is not replaced by an evaluation
  for (const fs::path& out : {run, dir_ / "mine"}) {
    fs::create_directories(out);
    std::ofstream(out / "notes.txt") << "mine";
    r = sh("evaluate " + run.string() + " -o " + out.string());
    EXPECT_EQ(r.code, 1) << out;
    EXPECT_NE(r.output.find(out == run ? ": is a run folder (its metadata.json)" : "holds files that spadgen did not write there"),
              std::string::npos) << r.output;
    EXPECT_EQ(slurp(out / "notes.txt"), "mine");
  }
  EXPECT_TRUE(fs::exists(run / "metadata.json"));
  EXPECT_TRUE(fs::exists(run / "ground_truth.exr"));
  // no staging folder or lock left beside the evaluation
  for (const fs::path& folder : {dir_, run})
    for (const auto& e : fs::directory_iterator(folder)) EXPECT_NE(e.path().filename().string()[0], '.') << e.path();
}

// The temporary file a reconstruct killed while it wrote left in the run folder (".detections_edges.exr.tmp-
// PID-N", a full-size EXR no later reconstruct, sense or status removed) goes with the next reconstruct of that
// file; a running process's stays.
TEST_F(Reconstruct, ADeadReconstructsTemporaryFileIsRemovedByTheNext) {
  const fs::path a = dir_ / "a";
  ASSERT_EQ(sh("run " + kScenes + "multi_object.json" + kMultiObjectCrop + a.string()).code, 0);
  const pid_t child = ::fork();
  if (child == 0) ::_exit(0);
  ASSERT_GT(child, 0);
  ASSERT_EQ(::waitpid(child, nullptr, 0), child);
  const fs::path dead = a / (".detections_edges.exr.tmp-" + std::to_string(child) + "-0");
  const fs::path live = a / ".detections_edges.exr.tmp-1-0";  // init's: running
  std::ofstream(dead) << "half an EXR";
  std::ofstream(live) << "another's";
  const Result r = sh("reconstruct " + a.string() + " -q");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_FALSE(fs::exists(dead));
  EXPECT_TRUE(fs::exists(live));
  EXPECT_TRUE(fs::exists(a / "detections_edges.exr"));
}

// reconstruct --help names the files --noise-free writes (it named the noisy ones only: a user looked for
// hdr.exr and found hdr_noise_free.exr).
TEST_F(Reconstruct, TheHelpNamesTheNoiseFreeFiles) {
  const Result r = sh("reconstruct --help");
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("detections_<detector>_noise_free.exr"));
  EXPECT_THAT(r.output, HasSubstr("hdr_noise_free.exr"));
}

// A run folder absent because a run replacing it was stopped in its swap (a file system without an atomic
// exchange) is named with the earlier set the run moved aside, by every command that reads a folder (they said
// only "Directory does not exist").
TEST_F(Reconstruct, AFolderLeftAsideInASwapIsNamed) {
  fs::create_directories(dir_ / ".t.spadgen-old-42");
  for (const char* cmd : {"reconstruct", "sense", "evaluate"}) {
    const Result r = sh(std::string(cmd) + " " + (dir_ / "t").string());
    EXPECT_EQ(r.code, 1) << cmd;
    EXPECT_THAT(r.output, HasSubstr("no such folder: " + (dir_ / "t").string() + "; a run replacing it was stopped during its "
                                    "swap and left its earlier files in " + (dir_ / ".t.spadgen-old-42").string() +
                                    ", which the next `spadgen run -o " + (dir_ / "t").string() + "` puts back and then "
                                    "replaces with its own files (to keep them, move it back yourself: mv " +
                                    (dir_ / ".t.spadgen-old-42").string() + " " + (dir_ / "t").string() + ")"))
        << cmd;
  }
  const Result r = sh("reconstruct " + (dir_ / "u").string());
  EXPECT_THAT(r.output, HasSubstr("no such folder: " + (dir_ / "u").string() + " "));
}

// evaluate holds the run folder's lock until its evaluation/ is published into it: a run into the folder
// meanwhile is refused (it let go after scoring, and a run replacing the folder then failed the publication,
// "No such file or directory", the work lost). Each of its renames (its two images', metrics.json's, the
// publication's) delayed 1 s by strace(1), the run started in the third (skipped without strace).
TEST_F(Reconstruct, EvaluateHoldsTheRunFolderUntilItsEvaluationIsPublished) {
  // (strace with syscall injection, on a machine with a rename syscall: not aarch64)
  if (shell("strace -f -o /dev/null -e trace=rename -e inject=rename:delay_enter=1 true 2> /dev/null").code != 0)
    GTEST_SKIP() << "strace cannot delay rename(2) here";
  const fs::path a = dir_ / "a";
  const std::string run_a = "run " + kScenes + "multi_object.json" + kMultiObjectCrop + a.string();
  ASSERT_EQ(sh(run_a).code, 0);
  ASSERT_EQ(sh("reconstruct " + a.string() + " -q").code, 0);
  // (LeakSanitizer cannot run under ptrace: off for the traced evaluate in a sanitizer build)
  const Result r = shell("(ASAN_OPTIONS=\"${ASAN_OPTIONS:-}:detect_leaks=0\" strace -f -o /dev/null -e trace=rename -e inject=rename:delay_enter=1000000 " + kBin + " evaluate " +
                         a.string() + " -q > " + (dir_ / "e.log").string() + " 2>&1; echo \"evaluate $?\" >> " +
                         (dir_ / "e.log").string() + ") & sleep 2.5; " + kBin + " " + run_a + " 2>&1; echo \"run $?\"; wait");
  const std::string e = slurp(dir_ / "e.log");
  EXPECT_THAT(e, HasSubstr("evaluate 0")) << e;
  EXPECT_THAT(r.output, HasSubstr("is being written or read by another spadgen process"));
  EXPECT_THAT(r.output, HasSubstr("run 1"));
  EXPECT_TRUE(fs::exists(a / "evaluation/metrics.json"));
}

// evaluate -o writes no folder into a run folder but the evaluated run's own evaluation/ (-o RUN/scores was
// written, exit 0, and the next run into RUN refused the folder for a foreign one), nor into another run's
// evaluation/, a dataset's own entries or a folder of sense --repeats' realisations.
TEST_F(Reconstruct, EvaluateWritesIntoNoRunOrDatasetButItsOwnEvaluation) {
  const fs::path a = dir_ / "a", b = dir_ / "b";
  const std::string run_a = "run " + kScenes + "multi_object.json" + kMultiObjectCrop + a.string();
  Result r = sh(run_a);
  ASSERT_EQ(r.code, 0) << r.output;
  r = sh("run " + kScenes + "multi_object.json" + kMultiObjectCrop + b.string());
  ASSERT_EQ(r.code, 0) << r.output;
  fs::create_directories(dir_ / "d");
  std::ofstream(dir_ / "d/dataset.json") << "{}";
  fs::create_directories(dir_ / "set/repeat_000");
  std::ofstream(dir_ / "set/repeat_000/metadata.json") << "{}";
  for (const auto& [out, says] : {std::pair{a / "scores", "lies in the run folder"}, {a / "evaluation/x", "lies in the run folder"},
                                  {b / "evaluation", "lies in the run folder"}, {dir_ / "d/samples/e", "lies in the dataset"},
                                  {dir_ / "d/evaluation", "is the dataset"}, {dir_ / "set/e", "sense --repeats"}}) {
    r = sh("evaluate " + a.string() + " -o " + out.string());
    EXPECT_EQ(r.code, 1) << out << r.output;
    EXPECT_THAT(r.output, HasSubstr(says)) << out;
    EXPECT_FALSE(fs::exists(out)) << out;
  }
  // its own evaluation/, named with a trailing separator before it exists (it was taken for another folder)
  r = sh("evaluate " + a.string() + " -o " + (a / "evaluation").string() + "/");
  EXPECT_EQ(r.code, 0) << r.output;
  r = sh(run_a);  // the run folder holds nothing foreign
  EXPECT_EQ(r.code, 0) << r.output;
  // A target neither a run nor a dataset is named as such, not by the default -o inside it.
  r = sh("evaluate " + (dir_ / "set").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("neither a run folder (metadata.json) nor a dataset folder (dataset.json)"));
  // a folder of sense --repeats' realisations is named as such, with its realisations' folders (reconstruct
  // said "not a run folder" only)
  EXPECT_THAT(r.output, HasSubstr("the folder of `spadgen sense --repeats`' realisations: evaluate each, " +
                                  (dir_ / "set" / "repeat_000").string()));
  r = sh("reconstruct " + (dir_ / "set").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("this is the folder of `spadgen sense --repeats`' realisations: each is a run folder, " +
                                  (dir_ / "set" / "repeat_000").string()));
}

// Detections evaluate would misread are refused, naming the file and what is wrong: detections of another
// scene or another crop (their header names where they were made; they were scored, precision 0 or recall
// 61 %, exit 0), slots after a gap (det0, det2: det2 was ignored), --min-score on detections without scores
// (every detection was dropped). Another run of the same scene and crop (another seed) is scored.
TEST_F(Reconstruct, EvaluateRefusesDetectionsOfAnotherSceneOrCropOrWithoutTheirSlots) {
  const std::string crop = " --set render.samples_per_pixel=2 --set camera.crop=";
  const fs::path a = dir_ / "a", flat = dir_ / "flat", other = dir_ / "other", seed = dir_ / "seed";
  ASSERT_EQ(sh("run " + kScenes + "multi_object.json -q -o " + a.string() + crop + "[480,242,32,4]").code, 0);
  ASSERT_EQ(sh("run " + kScenes + "flat_target.json -q -o " + flat.string() + crop + "[480,242,32,4]").code, 0);
  ASSERT_EQ(sh("run " + kScenes + "multi_object.json -q -o " + other.string() + crop + "[200,242,32,4]").code, 0);
  ASSERT_EQ(sh("run " + kScenes + "multi_object.json -q --seed 9 -o " + seed.string() + crop + "[480,242,32,4]").code, 0);
  for (const fs::path& run : {flat, other, seed}) ASSERT_EQ(sh("reconstruct -q " + run.string()).code, 0) << run;
  Result r = sh("evaluate " + a.string() + " --detections " + (flat / "detections_edges.exr").string() + " -o " + (dir_ / "e").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("flat/detections_edges.exr: detections of another scene (scene file and glTF hash) than "));
  EXPECT_THAT(r.output, HasSubstr("run spadgen reconstruct on " + a.string()));
  r = sh("evaluate " + a.string() + " --detections " + (other / "detections_edges.exr").string() + " -o " + (dir_ / "e").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("other/detections_edges.exr: detections of another crop of the sensor than "));
  EXPECT_THAT(r.output, HasSubstr("[200,242,32,4], this run: [480,242,32,4]"));
  EXPECT_FALSE(fs::exists(dir_ / "e"));
  r = sh("evaluate " + a.string() + " --detections " + (seed / "detections_edges.exr").string() + " -o " + (dir_ / "e").string());
  ASSERT_EQ(r.code, 0) << r.output;
  const auto m = nlohmann::json::parse(slurp(dir_ / "e" / "metrics.json"));
  EXPECT_EQ(m["detections_source"]["source_checked"], "yes: made from " + fs::absolute(seed).lexically_normal().string() +
                                                          ", the same scene, settings and crop");
  EXPECT_GT(m["objects"]["recall"].get<double>(), 0.5);

  // the seed run's detections, copied into slots 0 and 2 (no slot 1), and without scores
  const auto d = spadgen::writers::read_exr((seed / "detections_edges.exr").string());
  for (const bool gap : {true, false}) {
    spadgen::writers::ExrImage img(d.width, d.height);
    std::copy(d.channels.at("count").begin(), d.channels.at("count").end(), img.channel("count"));
    for (const char* slot : gap ? std::vector<const char*>{"det0", "det2"} : std::vector<const char*>{"det0", "det1"}) {
      const auto& range = d.channels.at(std::string(gap ? "det0" : slot) + ".range");
      std::copy(range.begin(), range.end(), img.channel(std::string(slot) + ".range"));
    }
    img.write((dir_ / (gap ? "gap.exr" : "unscored.exr")).string());
    if (gap) continue;
    // A header that names no scene, crop or settings: scored, and said unchecked (it said "yes: ... the same scene and crop");
    // its run not a text: taken as unnamed ("?"; it was an internal error).
    img.set_attribute("spadgen_source", "{\"run\": 5}");
    img.write((dir_ / "no_source.exr").string());
  }
  r = sh("evaluate " + a.string() + " --detections " + (dir_ / "no_source.exr").string() + " -o " + (dir_ / "e4").string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(nlohmann::json::parse(slurp(dir_ / "e4" / "metrics.json"))["detections_source"]["source_checked"],
            "no: its spadgen_source names no scene (scene file and glTF hash) and its crop of the sensor and its settings (--set "
            "values, dataset parameters; an earlier spadgen's file names none) (made from ?); taken on trust");
  // det0.range with its data window one row below the display window (scored one row off, exit 0)
  {
    const auto& range = d.channels.at("det0.range");
    Imf::Header h(Imath::Box2i({0, 0}, {d.width - 1, d.height - 1}), Imath::Box2i({0, 1}, {d.width - 1, d.height}));
    h.channels().insert("det0.range", Imf::Channel(Imf::FLOAT));
    Imf::FrameBuffer fb;
    fb.insert("det0.range", Imf::Slice::Make(Imf::FLOAT, range.data(), h.dataWindow()));
    Imf::OutputFile out((dir_ / "shifted.exr").c_str(), h);
    out.setFrameBuffer(fb);
    out.writePixels(d.height);
  }
  r = sh("evaluate " + a.string() + " --detections " + (dir_ / "shifted.exr").string() + " -o " + (dir_ / "e2").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("shifted.exr: its data window (0, 1)-(" + std::to_string(d.width - 1) + ", " + std::to_string(d.height) +
                                  ") is not its display window (0, 0)-("));
  EXPECT_FALSE(fs::exists(dir_ / "e2"));
  r = sh("evaluate " + a.string() + " --detections " + (dir_ / "gap.exr").string() + " -o " + (dir_ / "e2").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("gap.exr: channel det2.range after det0.range without det1.range"));
  // --detector and --noise-free choose the detector that runs without a file: refused beside one (ignored
  // without a word)
  for (const char* opt : {"--noise-free", "--detector paper"}) {
    r = sh("evaluate " + a.string() + " --detections " + (seed / "detections_edges.exr").string() + " " + opt + " -o " + (dir_ / "e2").string());
    EXPECT_EQ(r.code, 1) << opt;
    EXPECT_THAT(r.output, HasSubstr("--detections excludes --")) << opt;
  }
  r = sh("evaluate " + a.string() + " --detections " + (dir_ / "unscored.exr").string() + " -o " + (dir_ / "e2").string());
  ASSERT_EQ(r.code, 0) << r.output;  // no header: scored, and said unchecked
  EXPECT_THAT(nlohmann::json::parse(slurp(dir_ / "e2" / "metrics.json"))["detections_source"]["source_checked"].get<std::string>(),
              HasSubstr("no: the file names no run"));
  r = sh("evaluate " + a.string() + " --detections " + (dir_ / "unscored.exr").string() + " --min-score 1 -o " + (dir_ / "e3").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("unscored.exr: --min-score: slot 0 has no det0.score channel"));
  EXPECT_FALSE(fs::exists(dir_ / "e3"));

  // A NaN score where a slot holds a detection: refused under --min-score (it dropped the detection without a
  // word), scored without; a spadgen_source that is not JSON is said unreadable; a file that is not an EXR
  // says that only *.npy is read as NumPy.
  {
    spadgen::writers::ExrImage img(d.width, d.height);
    std::copy(d.channels.at("count").begin(), d.channels.at("count").end(), img.channel("count"));
    for (const char* slot : {"det0", "det1"}) {
      const auto& range = d.channels.at(std::string(slot) + ".range");
      std::copy(range.begin(), range.end(), img.channel(std::string(slot) + ".range"));
      std::fill_n(img.channel(std::string(slot) + ".score"), size_t(d.width) * size_t(d.height), 10.0f);
    }
    const auto& r0 = d.channels.at("det0.range");
    const size_t first = size_t(std::find_if(r0.begin(), r0.end(), [](float v) { return std::isfinite(v); }) - r0.begin());
    ASSERT_LT(first, r0.size());
    img.channel("det0.score")[first] = -std::numeric_limits<float>::infinity();
    img.write((dir_ / "inf_score.exr").string());
    img.channel("det0.score")[first] = std::numeric_limits<float>::quiet_NaN();
    img.set_attribute("spadgen_source", "not json");
    img.write((dir_ / "nan_score.exr").string());
  }
  // Scores count only under --min-score: a detection scoring -inf is scored as the unscored file's (it was
  // dropped, against a default threshold of -1e300)
  r = sh("evaluate " + a.string() + " --detections " + (dir_ / "inf_score.exr").string() + " -o " + (dir_ / "e7").string());
  ASSERT_EQ(r.code, 0) << r.output;
  const auto m7 = nlohmann::json::parse(slurp(dir_ / "e7" / "metrics.json"));
  const auto m2 = nlohmann::json::parse(slurp(dir_ / "e2" / "metrics.json"));
  EXPECT_EQ(m7["detections"], m2["detections"]);
  EXPECT_EQ(m7["objects"], m2["objects"]);
  EXPECT_FALSE(m7["matching"].contains("min_score"));
  r = sh("evaluate " + a.string() + " --detections " + (dir_ / "nan_score.exr").string() + " --min-score 5 -o " + (dir_ / "e5").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("nan_score.exr: --min-score: det0.score is NaN at pixel ("));
  EXPECT_FALSE(fs::exists(dir_ / "e5"));
  r = sh("evaluate " + a.string() + " --detections " + (dir_ / "nan_score.exr").string() + " -o " + (dir_ / "e5").string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(nlohmann::json::parse(slurp(dir_ / "e5" / "metrics.json"))["detections_source"]["source_checked"],
            "no: its spadgen_source is not a JSON object (unreadable); its scene and crop are taken on trust");
  std::ofstream(dir_ / "upper.NPY") << "\x93NUMPY";
  r = sh("evaluate " + a.string() + " --detections " + (dir_ / "upper.NPY").string() + " -o " + (dir_ / "e6").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("upper.NPY"));
  EXPECT_THAT(r.output, HasSubstr("the extension .npy selects the NumPy reader"));
}

TEST_F(Reconstruct, EvaluateOfADatasetSumsItsSamples) {
  const fs::path file = dir_ / "d.json", out = dir_ / "dataset";
  fs::create_directories(dir_);
  std::ofstream(file) << "{\"scenes\": [\"" + kScenes + "multi_object.json\"], \"samples\": 2, \"seed\": 5,"
                         "\"set\": {\"render.samples_per_pixel\": 2, \"camera.crop\": [496, 236, 24, 12]},"
                         "\"grid\": {\"laser.average_power_mW\": [1, 4]}}";
  Result r = sh("dataset run " + file.string() + " -o " + out.string() + " -q");
  ASSERT_EQ(r.code, 0) << r.output;
  r = sh("evaluate " + out.string());
  ASSERT_EQ(r.code, 0) << r.output;
  const auto m = nlohmann::json::parse(slurp(out / "evaluation" / "metrics.json"));
  ASSERT_EQ(m["samples"].size(), 2u);
  int objects = 0, found = 0, detections = 0;
  for (const auto& s : m["samples"]) {
    objects += s["metrics"]["objects"]["objects"].get<int>();
    found += s["metrics"]["objects"]["found"].get<int>();
    detections += s["metrics"]["detections"]["total"].get<int>();
  }
  EXPECT_EQ(m["objects"]["objects"], objects);
  EXPECT_EQ(m["objects"]["found"], found);
  EXPECT_EQ(m["detections"]["total"], detections);
  EXPECT_GT(objects, 2 * 24 * 12) << "the plate and the sphere on most pixels";
  const std::string csv = slurp(out / "evaluation" / "samples.csv");
  EXPECT_EQ(std::count(csv.begin(), csv.end(), '\n'), 3) << csv;
  // each sample's metrics, then its index, realisation and parameters as index.jsonl lists them (the grid's
  // power of each sample: 1 mW, then 4 mW)
  EXPECT_EQ(csv.rfind("sample,objects,found,recall,detectable,detectable_found,detections,false,bias_mm,rms_mm,index,repeat,scene,"
                      "laser.average_power_mW\n", 0), 0u) << csv;
  const std::string index_text = slurp(out / "index.jsonl");
  const std::vector<nlohmann::json> index_rows = {nlohmann::json::parse(index_text.substr(0, index_text.find('\n'))),
                                                  nlohmann::json::parse(index_text.substr(index_text.find('\n') + 1))};
  for (int i = 0; i < 2; ++i) {
    const std::string line = "\n00000" + std::to_string(i) + ",";
    const size_t at = csv.find(line);
    ASSERT_NE(at, std::string::npos) << csv;
    const std::string row = csv.substr(at + 1, csv.find('\n', at + 1) - at - 1);
    const std::string tail = "," + std::to_string(i) + ",0," + index_rows[size_t(i)]["parameters"]["scene"].get<std::string>() + "," +
                             index_rows[size_t(i)]["parameters"]["laser.average_power_mW"].dump();
    EXPECT_EQ(row.substr(row.size() - std::min(row.size(), tail.size())), tail) << row;
    EXPECT_EQ(m["samples"][size_t(i)]["index"], i);
    EXPECT_EQ(m["samples"][size_t(i)]["repeat"], 0);
    EXPECT_EQ(m["samples"][size_t(i)]["parameters"], index_rows[size_t(i)]["parameters"]);
  }
  EXPECT_EQ(m["samples"][0]["parameters"]["laser.average_power_mW"], 1);
  EXPECT_EQ(m["samples"][1]["parameters"]["laser.average_power_mW"], 4);
  // The index against the dataset's samples (dataset.json), as `dataset status` checks it: cut short, it was scored
  // as the rows left, without a word. While a dataset run is on the folder (this test holding a run's presence, a
  // shared lock on byte 0 of .dataset.runs, as a running `dataset run` does) the index is scored as it is, and said.
  std::ofstream(out / "index.jsonl") << index_text.substr(0, index_text.find('\n') + 1);
  r = sh("evaluate " + out.string() + " -o " + (dir_ / "e_cut").string());
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("index.jsonl has 1 row for the dataset's 2 samples (dataset.json): the index was cut short"));
  EXPECT_FALSE(fs::exists(dir_ / "e_cut"));
  {
    const int fd = hold_dataset_run_presence(out);
    ASSERT_GE(fd, 0);
    r = sh("evaluate " + out.string() + " -o " + (dir_ / "e_cut").string());
    ::close(fd);
    EXPECT_EQ(r.code, 0) << r.output;
    EXPECT_THAT(r.output, HasSubstr("note: " + (out / "index.jsonl").string() + " has 1 row for the dataset's 2 samples (dataset.json): "
                                    "a dataset run is on the folder"));
    EXPECT_THAT(r.output, HasSubstr("1 sample folder (realisations included)\n"));
    const nlohmann::json cut = nlohmann::json::parse(slurp(dir_ / "e_cut" / "metrics.json"));
    EXPECT_EQ(cut["samples"].size(), 1u);
    EXPECT_THAT(cut.value("index", ""), HasSubstr("scored as the index is now"));
  }
  std::ofstream(out / "index.jsonl") << index_text;

  // The done samples as index.jsonl lists them, not every folder under samples/ (sample 1, past a dataset
  // shrunk to 1 sample, was scored); a folder generated again since the index was written is refused.
  std::ofstream(dir_ / "d1.json") << "{\"scenes\": [\"" + kScenes + "multi_object.json\"], \"samples\": 1, \"seed\": 5,"
                                     "\"set\": {\"render.samples_per_pixel\": 2, \"camera.crop\": [496, 236, 24, 12]},"
                                     "\"grid\": {\"laser.average_power_mW\": [1, 4]}}";
  ASSERT_EQ(sh("dataset run " + (dir_ / "d1.json").string() + " -o " + out.string() + " -q").code, 0);
  ASSERT_TRUE(fs::exists(out / "samples/000001/metadata.json"));
  r = sh("evaluate " + out.string() + " -o " + (dir_ / "e_shrunk").string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("1 sample folder (realisations included)\n"));
  EXPECT_EQ(nlohmann::json::parse(slurp(dir_ / "e_shrunk" / "metrics.json"))["samples"].size(), 1u);
  // What was scored is at the top of metrics.json and the summary; an evaluation of another detector into the
  // folder says which it replaced (a dataset's named its detector per sample only, and was replaced unsaid)
  EXPECT_THAT(r.output, HasSubstr("scored: --detector edges\n"));
  EXPECT_THAT(r.output, HasSubstr("e_shrunk/metrics.json and samples.csv\n"));
  EXPECT_EQ(nlohmann::json::parse(slurp(dir_ / "e_shrunk" / "metrics.json"))["scored"],
            nlohmann::json::parse(R"({"detector": "edges", "noise_free": false})"));
  r = sh("evaluate " + out.string() + " --detector paper -o " + (dir_ / "e_shrunk").string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("scored: --detector paper\nreplaced the evaluation in " + (dir_ / "e_shrunk").string() +
                                  " of --detector edges (-o keeps each in its own folder)\n"));
  EXPECT_EQ(nlohmann::json::parse(slurp(dir_ / "e_shrunk" / "metrics.json"))["scored"]["detector"], "paper");
  r = sh("evaluate " + out.string() + " --detector paper -o " + (dir_ / "e_shrunk").string());
  EXPECT_THAT(r.output, Not(HasSubstr("replaced the evaluation")));  // the same detections again
  // an earlier metrics.json edited by hand ("scored" of other shapes was an internal error, exit 3, once the new
  // evaluation was published): what it scored is "?"
  for (const char* scored : {"5", R"({"detector": 7, "noise_free": "yes"})"}) {
    nlohmann::json edited = nlohmann::json::parse(slurp(dir_ / "e_shrunk" / "metrics.json"));
    edited["scored"] = nlohmann::json::parse(scored);
    std::ofstream(dir_ / "e_shrunk" / "metrics.json", std::ios::trunc) << edited.dump(2);
    r = sh("evaluate " + out.string() + " --detector paper -o " + (dir_ / "e_shrunk").string());
    EXPECT_EQ(r.code, 0) << scored << r.output;
    EXPECT_THAT(r.output, HasSubstr("replaced the evaluation in " + (dir_ / "e_shrunk").string() + " of " +
                                    (std::string(scored) == "5" ? "?" : "--detector ?") + " (-o keeps")) << scored;
  }
  std::string meta = slurp(out / "samples/000000/metadata.json");
  const std::string original_meta = meta;
  const size_t at = meta.find("\"sample_hash\": \"");
  ASSERT_NE(at, std::string::npos) << meta;
  meta[at + 16] = meta[at + 16] == '0' ? '1' : '0';
  std::ofstream(out / "samples/000000/metadata.json") << meta;
  r = sh("evaluate " + out.string() + " -o " + (dir_ / "e_changed").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("samples/000000: index.jsonl lists it done with hash "));
  EXPECT_THAT(r.output, HasSubstr(": the sample was removed or changed since the index was written"));
  EXPECT_FALSE(fs::exists(dir_ / "e_changed"));
  std::ofstream(out / "samples/000000/metadata.json") << original_meta;  // the sample as it was
  // A damaged index: a row copied (its sample was scored twice; as the next sample's, its folder twice), a
  // folder outside samples/ (scored too), a row removed (the rest was scored without a word).
  const std::string index = slurp(out / "index.jsonl");
  const std::string first_row = index.substr(0, index.find('\n') + 1);
  const auto rows_in = std::count(index.begin(), index.end(), '\n');
  ASSERT_GE(rows_in, 1);
  ASSERT_EQ(first_row.rfind("{\"index\":0,", 0), 0u) << first_row;
  const std::string next_row = "{\"index\":" + std::to_string(rows_in) + "," + first_row.substr(11);  // sample N's place
  std::string outside = next_row;  // (no std::regex: GCC 12 warns inside it under the sanitizers' -O1)
  ASSERT_NE(outside.find("\"samples/000000\""), std::string::npos) << first_row;
  outside.replace(outside.find("\"samples/000000\""), 16, "\"../../elsewhere\"");
  const std::string skipped = index + "{\"index\":" + std::to_string(rows_in + 1) + "," + first_row.substr(11);  // N left out
  for (const auto& [rows, says] : {std::pair{index + first_row, "row " + std::to_string(rows_in + 1) + ": lists sample 0 where sample " +
                                                                    std::to_string(rows_in) + " belongs (the index lists every sample in index order)"},
                                   {index + next_row, std::string("lists the folder samples/000000 again")},
                                   {index + outside, std::string("lists the folder ../../elsewhere, not a sample folder of the dataset")},
                                   {skipped, "index.jsonl row " + std::to_string(rows_in + 1) + ": lists sample " +
                                                 std::to_string(rows_in + 1) + " where sample " + std::to_string(rows_in) + " belongs"}}) {
    std::ofstream(out / "index.jsonl") << rows;
    r = sh("evaluate " + out.string() + " -o " + (dir_ / "e_index").string());
    EXPECT_EQ(r.code, 1) << r.output;
    EXPECT_THAT(r.output, HasSubstr(says));
  }
  std::ofstream(out / "index.jsonl") << index;
  // --detections: a name inside each sample's folder, not an empty one (ignored: the detector ran) nor one
  // leaving the folder (one file scored against every sample)
  for (const char* d : {"../../x.npy", "\"\""}) {
    r = sh("evaluate " + out.string() + " --detections " + d + " -o " + (dir_ / "e_det").string());
    EXPECT_EQ(r.code, 1) << d << r.output;
  }
  EXPECT_FALSE(fs::exists(dir_ / "e_index"));
  EXPECT_FALSE(fs::exists(dir_ / "e_det"));

  // Two scenes: objects are counted by name across the samples (flat_target's "target" has id 0, as the
  // multi-object scene's "plate" has: it was counted as the plate)
  const fs::path file2 = dir_ / "d2.json", out2 = dir_ / "dataset2";
  std::ofstream(file2) << "{\"scenes\": [\"" + kScenes + "multi_object.json\", \"" + kScenes + "flat_target.json\"], \"seed\": 3,"
                          "\"set\": {\"render.samples_per_pixel\": 2, \"camera.crop\": [480, 242, 32, 4]}}";
  ASSERT_EQ(sh("dataset run " + file2.string() + " -o " + out2.string() + " -q").code, 0);
  r = sh("evaluate " + out2.string());
  ASSERT_EQ(r.code, 0) << r.output;
  const auto m2 = nlohmann::json::parse(slurp(out2 / "evaluation" / "metrics.json"));
  std::map<std::string, int> total, in_samples;
  for (const auto& o : m2["by_object"]) total[o["name"].get<std::string>()] += o["objects"].get<int>();
  ASSERT_EQ(m2["samples"].size(), 2u);
  for (const auto& s : m2["samples"])
    for (const auto& o : s["metrics"]["by_object"]) in_samples[o.at("name").get<std::string>()] += o["objects"].get<int>();
  EXPECT_EQ(total, in_samples);
  EXPECT_EQ(total.size(), 3u);  // plate, sphere, target
  EXPECT_TRUE(total.count("target") && total.count("plate") && total.count("sphere"));
  for (const auto& s : m2["samples"]) EXPECT_EQ(s["detections_source"]["computed"], true);
  EXPECT_FALSE(m2.contains("labels"));

  // A sample whose labels.exr, which its metadata.json lists, is gone is damaged: refused, named (it was scored
  // as a sample without labels, every object detectable, exit 0: a new user's find).
  const fs::path first = out2 / "samples" / m2["samples"][0]["sample"].get<std::string>();
  fs::remove(first / "labels.exr");
  r = sh("evaluate " + out2.string() + " -o " + (dir_ / "e_damaged").string());
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr((first / "labels.exr").string() + ": listed in " + (first / "metadata.json").string() +
                                  " (files) but missing: the run folder is damaged"));
  EXPECT_FALSE(fs::exists(dir_ / "e_damaged"));
  // A sample without labels.exr (a run that wrote none: its metadata.json does not list it) is scored with every
  // object detectable, and the report says so (it was pooled silently); one detections file for every sample
  // (an absolute path) is refused.
  {
    nlohmann::ordered_json edited = nlohmann::ordered_json::parse(slurp(first / "metadata.json"));
    auto& files = edited["files"];
    files.erase(std::find(files.begin(), files.end(), "labels.exr"));
    edited["file_bytes"].erase("labels.exr");
    std::ofstream(first / "metadata.json") << edited.dump(2) << "\n";
  }
  r = sh("evaluate " + out2.string() + " -o " + (dir_ / "e_unlabelled").string());
  ASSERT_EQ(r.code, 0) << r.output;
  const auto m3 = nlohmann::json::parse(slurp(dir_ / "e_unlabelled" / "metrics.json"));
  EXPECT_THAT(m3["labels"].get<std::string>(), HasSubstr("1 of 2 samples without labels.exr"));
  EXPECT_TRUE(m3["samples"][0]["detections_source"].contains("labels"));
  EXPECT_FALSE(m3["samples"][1]["detections_source"].contains("labels"));
  r = sh("evaluate " + out2.string() + " --detections " + (first / "detections_edges.exr").string() + " -o " + (dir_ / "e_abs").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("for a dataset, expected a file name relative to each sample's folder"));

  // Detections kept outside the dataset: --detections with {sample}, the sample folder's name. The edges
  // detector's files written by reconstruct -o elsewhere score as the detector run in memory does; a missing
  // file is named before any sample is scored.
  fs::create_directories(dir_ / "preds");
  r = sh("evaluate " + out2.string() + " --detections " + (dir_ / "preds" / "{sample}.exr").string() + " -o " + (dir_ / "e_tpl").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("2 of 2 done sample folders have no detections file, first " + (dir_ / "preds").string() + "/0000"));
  EXPECT_FALSE(fs::exists(dir_ / "e_tpl"));
  for (const auto& s : m2["samples"]) {
    const std::string name = s["sample"].get<std::string>();
    ASSERT_EQ(sh("reconstruct " + (out2 / "samples" / name).string() + " -q -o " + (dir_ / "preds" / (name + ".exr")).string()).code, 0);
  }
  r = sh("evaluate " + out2.string() + " --detections " + (dir_ / "preds" / "{sample}.exr").string() + " -o " + (dir_ / "e_tpl").string());
  ASSERT_EQ(r.code, 0) << r.output;
  const auto mt = nlohmann::json::parse(slurp(dir_ / "e_tpl" / "metrics.json"));
  EXPECT_EQ(mt["objects"], m3["objects"]);  // (the first sample still without labels.exr, as for m3)
  EXPECT_EQ(mt["range_error"], m3["range_error"]);
  EXPECT_EQ(mt["detections"], m3["detections"]);
  EXPECT_GT(mt["objects"]["found"].get<int>(), 0);
  ASSERT_EQ(mt["samples"].size(), 2u);
  for (const auto& s : mt["samples"])
    EXPECT_EQ(s["detections_source"]["file"], (dir_ / "preds" / (s["sample"].get<std::string>() + ".exr")).string());
  // A dataset mixing 2D and gate-sweep scenes: the detector has no gate profiles in a 2D sample, which is
  // left out and named (it stopped the whole evaluation), and dataset status counts it as accounted for; a
  // dataset of 2D samples only needs detections given.
  const fs::path file3 = dir_ / "d3.json", out3 = dir_ / "dataset3";
  std::ofstream(file3) << "{\"scenes\": [\"" + kScenes + "multi_object.json\", \"" + kScenes + "test_chart.json\"], \"seed\": 3,"
                          "\"set\": {\"render.samples_per_pixel\": 2, \"camera.crop\": [480, 242, 16, 4]}}";
  ASSERT_EQ(sh("dataset run " + file3.string() + " -o " + out3.string() + " -q").code, 0);
  r = sh("evaluate " + out3.string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("1 sample folder (realisations included); not scored, 2D intensity runs (no gate profiles for the detector): 1\n"));
  const auto m4 = nlohmann::json::parse(slurp(out3 / "evaluation" / "metrics.json"));
  ASSERT_EQ(m4["not_scored_intensity"]["sample_folders"].size(), 1u);
  EXPECT_EQ(m4["not_scored_intensity"]["sample_folders"][0]["sample"], "000001");
  ASSERT_EQ(m4["samples"].size(), 1u);
  EXPECT_EQ(m4["samples"][0]["sample"], "000000");
  r = sh("dataset status " + out3.string());
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, Not(HasSubstr("out of date")));
  // the 2D sample generated again (its hash changed by hand, as a changed scene would): the evaluation is out
  // of date (it may be a gate sweep now; the left-out folder was accounted for by name alone)
  {
    const fs::path meta_2d = out3 / "samples/000001/metadata.json";
    const std::string original_2d = slurp(meta_2d);
    std::string text = original_2d;
    const size_t hash_at = text.find("\"sample_hash\": \"");
    ASSERT_NE(hash_at, std::string::npos);
    text[hash_at + 16] = text[hash_at + 16] == '0' ? '1' : '0';
    std::ofstream(meta_2d) << text;
    r = sh("dataset status " + out3.string());
    EXPECT_THAT(r.output, HasSubstr("evaluation/ is out of date: of the 2 sample folders it scored (or left out: 2D), 0 changed since "
                                    "(generated again with another sample_hash) and 1 are no longer done samples"));
    std::ofstream(meta_2d) << original_2d;  // (as generated)
  }
  // {sample} may not name one file for several samples (p/{sample}/../x.npy), nor a folder
  fs::create_directories(dir_ / "p" / "000000");
  fs::create_directories(dir_ / "p" / "000001");
  std::ofstream(dir_ / "p" / "x.npy") << "";
  r = sh("evaluate " + out2.string() + " --detections " + (dir_ / "p" / "{sample}" / ".." / "x.npy").string() + " -o " + (dir_ / "e_one").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("names one file, " + (dir_ / "p" / "000000" / ".." / "x.npy").string() + " and " +
                                  (dir_ / "p" / "000001" / ".." / "x.npy").string() + ", for the samples 000000 and 000001"));
  r = sh("evaluate " + out2.string() + " --detections " + (dir_ / "p" / "{sample}").string() + " -o " + (dir_ / "e_one").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("/p/000000 is not a regular file (a folder, a FIFO or a device)"));
  EXPECT_FALSE(fs::exists(dir_ / "e_one"));
  std::ofstream(dir_ / "d4.json") << "{\"scenes\": [\"" + kScenes + "test_chart.json\"], \"seed\": 3,"
                                     "\"set\": {\"render.samples_per_pixel\": 2, \"camera.crop\": [480, 242, 16, 4]}}";
  ASSERT_EQ(sh("dataset run " + (dir_ / "d4.json").string() + " -o " + (dir_ / "dataset4").string() + " -q").code, 0);
  r = sh("evaluate " + (dir_ / "dataset4").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("its 1 done sample folders are 2D intensity runs, without gate profiles for the detector"));
  // detections given for the gate-sweep sample only: the 2D one is left out as without --detections
  ASSERT_EQ(sh("reconstruct " + (out3 / "samples" / "000000").string() + " -q -o " + (dir_ / "mixed_000000.exr").string()).code, 0);
  r = sh("evaluate " + out3.string() + " --detections " + (dir_ / "mixed_{sample}.exr").string() + " -o " + (dir_ / "e_mixed").string());
  ASSERT_EQ(r.code, 0) << r.output;
  // (the summary says why: no file, not "no gate profiles", which --detections makes up for)
  EXPECT_THAT(r.output, HasSubstr("1 sample folder (realisations included); not scored, 2D intensity runs without a file of "
                                  "--detections: 1\n"));
  // a scored sample damaged since (a file gone; its metadata.json as it was): the evaluation is out of date as
  // dataset status finds the folders (index.jsonl still lists it done); a metrics.json of no dataset is named
  fs::remove(out3 / "samples/000000/counts.npy");
  r = sh("dataset status " + out3.string());
  EXPECT_THAT(r.output, HasSubstr("sample 0 damaged: "));
  EXPECT_THAT(r.output, HasSubstr("evaluation/ is out of date: of the 2 sample folders it scored (or left out: 2D), 0 changed "
                                  "since (generated again with another sample_hash) and 1 are no longer done samples"));
  std::ofstream(out3 / "evaluation/metrics.json") << "{}";
  r = sh("dataset status " + out3.string());
  EXPECT_THAT(r.output, HasSubstr("metrics.json does not read as spadgen evaluate's of a dataset"));
  // ... and one that is no file, said (a folder or a link to a device was passed over)
  fs::remove(out3 / "evaluation/metrics.json");
  fs::create_directories(out3 / "evaluation/metrics.json");
  r = sh("dataset status " + out3.string());
  EXPECT_THAT(r.output, HasSubstr("evaluation/: " + (out3 / "evaluation/metrics.json").string() + " is not a regular file (is a "
                                  "directory, expected a regular file): run `spadgen evaluate "));
  fs::remove(out3 / "evaluation/metrics.json");
  fs::create_symlink("/dev/zero", out3 / "evaluation/metrics.json");
  EXPECT_THAT(sh("dataset status " + out3.string()).output, HasSubstr("metrics.json is not a regular file (is a character device"));
  // {sample} names a dataset's samples: refused for a run
  r = sh("evaluate " + first.string() + " --detections " + (dir_ / "preds" / "{sample}.exr").string() + " -o " + (dir_ / "e_run").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("{sample} names each sample folder of a dataset; "));
  EXPECT_FALSE(fs::exists(dir_ / "e_run"));
}

}  // namespace
