// The fixture and the shared settings of the tests that run the program (app_test.cpp, sense_test.cpp).
#pragma once
#include <gtest/gtest.h>
#include <unistd.h>

#include <nlohmann/json.hpp>

#include "run_util.h"

namespace spadgen::testing {

// A fresh temporary folder per test, removed afterwards.
class App : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("spadgen_app_" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()) + "_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

// Two samples of an 8 x 8 crop of the flat target, 1 path each, a few gate positions: milliseconds per sample.
// more: further top-level entries (", \"random\": {...}").
inline std::string tiny_dataset(const std::string& more = "") {
  return "{\"seed\": 3, \"scenes\": [\"" + kScenes + "flat_target.json\"], \"samples\": 2, \"set\": {\"camera.crop\": [508, 246, 8, 8], "
         "\"render.samples_per_pixel\": 1, \"acquisition.gate_sweep.start_ns\": 6, \"acquisition.gate_sweep.stop_ns\": 7, "
         "\"outputs.previews\": false}" + more + "}";
}

// A quick version of the multi-object experiment: a crop where the plate covers the sphere's edge.
inline const std::string kSmallSettings =
    kScenes + "multi_object.json -q --set render.samples_per_pixel=2 --set acquisition.gate_sweep.stop_ns=4.2 "
              "--set outputs.frames=true --set outputs.transient=true";
inline const std::string kSmall = kSmallSettings + " --set camera.crop=[496,232,24,20]";

// Every output file byte for byte, the same set of files in both, except in metadata.json the "run"
// section (time taken, threads), the "sense" section (what `spadgen sense` read) and the tile size the
// runs were told to use.
inline void expect_same_outputs(const fs::path& a, const fs::path& b) {
  size_t compared = 0;
  for (const auto& e : fs::recursive_directory_iterator(a)) {
    if (!e.is_regular_file()) continue;
    const fs::path rel = fs::relative(e.path(), a);
    if (rel == "metadata.json") {
      auto ma = nlohmann::json::parse(slurp(e.path())), mb = nlohmann::json::parse(slurp(b / rel));
      for (const char* k : {"run", "sense"}) ma.erase(k), mb.erase(k);
      ma["resolved_scene"]["render"].erase("tile_size_px"), mb["resolved_scene"]["render"].erase("tile_size_px");
      EXPECT_EQ(ma, mb);
    } else {
      EXPECT_TRUE(slurp(e.path()) == slurp(b / rel)) << rel << " differs";
    }
    ++compared;
  }
  size_t in_b = 0;
  for (const auto& e : fs::recursive_directory_iterator(b)) in_b += e.is_regular_file();
  EXPECT_EQ(compared, in_b) << b << " holds files that " << a << " does not";
  EXPECT_GE(compared, 10u);
}


}  // namespace spadgen::testing
