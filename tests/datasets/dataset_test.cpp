// The dataset file: its checks, the samples it describes (grid order, random draws against their
// distributions, independence of the index), and shards from the command line and the environment.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <map>
#include <string>
#include <vector>

#include "core/error.h"
#include "datasets/dataset.h"
#include "datasets/folder.h"

namespace spadgen::datasets {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;
namespace fs = std::filesystem;

const std::string kScenes = std::string(SPADGEN_SOURCE_DIR) + "/scenes/paper/";

// A dataset file over the flat target with the given body (after "scenes").
DatasetSpec parse(const std::string& body) {
  return parse_dataset_text("{\"scenes\": [\"" + kScenes + "flat_target.json\"]" + (body.empty() ? "" : ", " + body) + "}",
                            "test_dataset.json");
}

std::string error_of(const std::string& body) {
  try {
    parse(body);
  } catch (const Error& e) {
    return e.what();
  }
  return "no error";
}

// A mistake of the scene file itself is named as the scene file's, at /scenes/0, not at the first scene-file
// key the dataset sets (it said "/set/outputs.storage: ... /notes_for_me: unknown key"); a scene file that
// only the dataset's keys make valid is accepted.
TEST(DatasetFile, AMistakeOfTheSceneFileIsNamedAsItsOwn) {
  const fs::path dir = fs::temp_directory_path() / ("spadgen_dataset_scene_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  std::string scene;
  {
    std::ifstream in(kScenes + "flat_target.json");
    std::ostringstream t;
    t << in.rdbuf();
    scene = t.str();
  }
  const std::string gltf = "\"gltf\": \"" + kScenes + "flat_target.gltf\"";
  scene.replace(scene.find("\"gltf\": \"flat_target.gltf\""), std::string("\"gltf\": \"flat_target.gltf\"").size(), gltf);
  std::string broken = scene;
  broken.replace(broken.find(gltf), gltf.size(), gltf + ", \"notes_for_me\": 0");
  std::ofstream((dir / "broken.json").string()) << broken;
  std::string mended = scene;  // a crop outside the sensor, which the dataset widens
  mended.replace(mended.find("\"camera\": {"), 11, "\"camera\": {\"crop\": [1100, 0, 8, 8], ");
  std::ofstream((dir / "mended.json").string()) << mended;
  const auto error = [&](const std::string& text) {
    try {
      parse_dataset_text(text, (dir / "d.json").string());
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_THAT(error("{\"scenes\": [\"broken.json\"], \"set\": {\"outputs.storage\": \"zarr\"}}"),
              HasSubstr("d.json: /scenes/0: " + (dir / "broken.json").string() + ": /notes_for_me: unknown key"));
  EXPECT_EQ(error("{\"scenes\": [\"mended.json\"], \"set\": {\"camera.width_px\": 2048}}"), "no error");
  // once, whatever the keys checked with it (each key's check named it again, and the samples' probe too)
  EXPECT_EQ(error("{\"scenes\": [\"broken.json\"], \"set\": {\"render.samples_per_pixel\": 2}, "
                  "\"grid\": {\"laser.average_power_mW\": [1, 2], \"camera.f_number\": [2, 3]}}"),
            (dir / "d.json").string() + ": /scenes/0: " + (dir / "broken.json").string() +
                ": /notes_for_me: unknown key; the keys here are: gltf, gltf_scene, description, seed, seeds, camera, laser, "
                "ambient, sensor, acquisition, render, outputs, nodes, materials");
  fs::remove_all(dir);
}

// A grid of 16 keys of 16 values has 2^64 cells: the count wrapped to 0 (a dataset of 0 samples, exit 0),
// to -2^63 at 2^63 (internal error: vector::reserve), and with "samples" given the check looped for ever.
TEST(DatasetFile, AGridOfMoreCellsThanAnIntegerHoldsIsRefused) {
  const char* keys[] = {"camera.position_m[0]", "camera.position_m[1]", "camera.look_at_m[0]", "camera.look_at_m[1]",
                        "laser.offset_m[0]", "laser.offset_m[1]", "laser.offset_m[2]", "laser.average_power_mW",
                        "ambient.illuminance_lux", "camera.f_number", "render.samples_per_pixel", "render.max_bounces",
                        "camera.focal_length_mm", "laser.repetition_rate_MHz", "camera.look_at_m[2]", "camera.position_m[2]"};
  const auto grid = [&](int n_keys, const std::string& extra) {
    std::string g = "\"grid\": {";
    for (int k = 0; k < n_keys; ++k) {
      g += std::string(k ? ", " : "") + "\"" + keys[k] + "\": [";
      for (int v = 0; v < 16; ++v) g += (v ? ", " : "") + std::to_string(k == 14 ? -1 - v : 1 + v);
      g += "]";
    }
    return g + "}" + extra;
  };
  EXPECT_THAT(error_of(grid(16, "")), HasSubstr("/grid: has 1.84e+19 cells (the scene files times each key's values); expected at most 1e8"));
  EXPECT_THAT(error_of(grid(16, ", \"samples\": 5")), HasSubstr("/grid: has 1.84e+19 cells"));
  EXPECT_THAT(error_of(grid(15, "")), HasSubstr("/grid: has 1.15e+18 cells"));
  EXPECT_THAT(error_of(grid(7, "")), HasSubstr("/grid: has 268435456 cells (the scene files times each key's values); expected at most 1e8"));
}

TEST(DatasetFile, ErrorsNameTheKeyAndWhatWasExpected) {
  EXPECT_THAT(error_of("\"sampels\": 3"), HasSubstr("test_dataset.json: /sampels: unknown key; did you mean samples?"));
  EXPECT_THAT(error_of("\"samples\": 0"), HasSubstr("/samples: found 0, expected an integer in [1, 1e8] or null"));
  EXPECT_THAT(error_of("\"repeats\": 1.5"), HasSubstr("/repeats: found 1.5, expected an integer in [1, 1000]"));
  // Scene-file keys get the scene file's own checks, named at their place in the dataset file.
  const std::string typo = error_of("\"grid\": {\"laser.averge_power_mW\": [1, 2]}");
  EXPECT_THAT(typo, HasSubstr("/grid/laser.averge_power_mW/0"));
  EXPECT_THAT(typo, HasSubstr("did you mean /laser/average_power_mW?"));
  EXPECT_THAT(error_of("\"grid\": {\"laser.average_power_mW\": [1, -2]}"), HasSubstr("/grid/laser.average_power_mW/1"));
  EXPECT_THAT(error_of("\"grid\": {\"laser.average_power_mW\": []}"), HasSubstr("expected a non-empty array of values"));
  EXPECT_THAT(error_of("\"random\": {\"ambient.illuminance_lux\": {\"log_uniform\": [0, 10]}}"),
              HasSubstr("/random/ambient.illuminance_lux/log_uniform: found [0,10], expected 0 < a < b"));
  EXPECT_THAT(error_of("\"random\": {\"ambient.illuminance_lux\": {\"uniform\": [1, 2e6]}}"),
              HasSubstr("/random/ambient.illuminance_lux"));  // 2e6 lux is beyond the key's range
  EXPECT_THAT(error_of("\"random\": {\"ambient.illuminance_lux\": {\"gauss\": [1, 2]}}"),
              HasSubstr("/random/ambient.illuminance_lux/gauss: unknown key"));
  EXPECT_THAT(error_of("\"random\": {\"camera.f_number\": {\"normal\": [2, 0.1], \"min\": 5}}"),
              HasSubstr("of the normal distribution between min and max; expected at least 0.001"));
  EXPECT_THAT(error_of("\"random\": {\"camera.f_number\": {\"uniform\": [2, 3], \"min\": 2.5}}"),
              HasSubstr("is only for \"normal\""));
  EXPECT_THAT(error_of("\"set\": {\"seed\": 4}"), HasSubstr("/set/seed: the dataset sets every sample's seeds"));
  // a scene file twice, under two spellings (it doubled the grid)
  std::string twice = "no error";
  try {
    parse_dataset_text("{\"scenes\": [\"" + kScenes + "flat_target.json\", \"" + kScenes + "../paper/flat_target.json\"]}", "d.json");
  } catch (const Error& e) {
    twice = e.what();
  }
  EXPECT_THAT(twice, HasSubstr("d.json: /scenes/1: lists " + fs::path(kScenes).lexically_normal().string() +
                                   "flat_target.json twice (as /scenes/0 too); expected each scene file once"));
  EXPECT_THAT(error_of("\"grid\": {\"seeds.noise\": [1, 2]}"), HasSubstr("/grid/seeds.noise"));
  EXPECT_THAT(error_of("\"set\": {\"camera.f_number\": 2}, \"grid\": {\"camera.f_number\": [2, 4]}"),
              HasSubstr("varies camera.f_number a second time"));
  // one key under another spelling, or a whole [x, y, z] key and one of its components: one value twice (the
  // index listed the grid's and the sample rendered the random draw); two components are two values
  EXPECT_THAT(error_of("\"grid\": {\"camera.f_number\": [2, 4]}, \"random\": {\"\\\"camera\\\".f_number\": {\"uniform\": [2, 3]}}"),
              HasSubstr("/random/\"camera\".f_number: varies \"camera\".f_number, which camera.f_number varies too"));
  EXPECT_THAT(error_of("\"grid\": {\"camera.position_m\": [[0, 0, 1], [0, 0, 2]]}, \"random\": {\"camera.position_m[2]\": {\"uniform\": [1, 2]}}"),
              HasSubstr("varies camera.position_m[2], which camera.position_m varies too"));
  EXPECT_EQ(parse_dataset_text("{\"scenes\": [\"" + kScenes + "flat_target.json\"], \"grid\": {\"camera.position_m[0]\": [0, 0.1]}, "
                               "\"random\": {\"camera.position_m[2]\": {\"uniform\": [1, 2]}}}", "test_dataset.json").random.size(), 1u);
  EXPECT_THAT(error_of("\"repeats\": 2, \"set\": {\"\\\"outputs\\\".light\": false}"),
              HasSubstr("/set/\"outputs\".light: is false, but repeats 2"));
  EXPECT_THAT(error_of("\"seeds\": {\"chips\": 3}"), HasSubstr("/seeds/chips: unknown key; did you mean chip?"));
  // every wrong value of a seed names both what it takes (null, -1 and 1.5 left out "per_sample")
  for (const char* v : {"null", "-1", "1.5"})
    EXPECT_THAT(error_of(std::string("\"seeds\": {\"chip\": ") + v + "}"),
                HasSubstr("/seeds/chip: found " + std::string(v == std::string("null") ? "null" : v)) ) << v;
  EXPECT_THAT(error_of("\"seeds\": {\"chip\": null}"), HasSubstr("expected an integer in [0, 2^53] or \"per_sample\""));
  // repeats saves the light: outputs.light true may be said too (the shipped example says it), not false or varied
  EXPECT_THAT(error_of("\"repeats\": 2, \"set\": {\"outputs.light\": false}"),
              HasSubstr("/set/outputs.light: is false, but repeats 2 re-samples each sample's noise from its saved light, which it "
                        "saves: set it true, or remove it"));
  EXPECT_THAT(error_of("\"repeats\": 2, \"grid\": {\"outputs.light\": [true, false]}"),
              HasSubstr("/repeats: is 2, and outputs.light varies per sample (grid or random)"));
  EXPECT_EQ(parse_dataset_text("{\"scenes\": [\"" + kScenes + "flat_target.json\"], \"repeats\": 2, \"set\": {\"outputs.light\": true}}",
                               "test_dataset.json").repeats, 2);
  // a truncated normal whose bounds are the wrong way round says so (it said "keeps a fraction -0.84")
  EXPECT_THAT(error_of("\"random\": {\"camera.f_number\": {\"normal\": [2, 1], \"min\": 4, \"max\": 1.4}}"),
              HasSubstr("/random/camera.f_number: has min 4 and max 1.4; expected min < max"));
  // keys the scene file checks together (both ends of the time window) are taken together from `set` (each
  // was refused alone); one end alone is still refused, naming it
  EXPECT_EQ(error_of("\"set\": {\"render.window_start_ns\": 0, \"render.window_stop_ns\": 20}"), "no error");
  EXPECT_EQ(error_of("\"set\": {\"render.window_stop_ns\": 20, \"render.window_start_ns\": 0}"), "no error");
  EXPECT_THAT(error_of("\"set\": {\"render.window_stop_ns\": 20}"), HasSubstr("/set/render.window_stop_ns"));
  EXPECT_EQ(error_of("\"set\": {\"render.window_start_ns\": 0, \"render.window_stop_ns\": 20}, "
                     "\"grid\": {\"laser.average_power_mW\": [1, 2]}"), "no error");
  // an untruncated side of a normal on a key with a bound there (only the mean was checked: 7 of 20 samples
  // failed after the plan passed); a key without one (a position) takes it
  EXPECT_THAT(error_of("\"random\": {\"ambient.illuminance_lux\": {\"normal\": [1, 5]}}"),
              HasSubstr("/random/ambient.illuminance_lux: a normal without \"min\" can give any value below its mean, and the "
                        "key has a bound there"));
  EXPECT_THAT(error_of("\"random\": {\"ambient.illuminance_lux\": {\"normal\": [1, 5], \"min\": 0}}"), "no error");
  EXPECT_THAT(error_of("\"random\": {\"camera.position_m[2]\": {\"normal\": [1, 0.1]}}"), "no error");
  // realisation r's noise seed is seeds.noise + r: past 2^53 it failed every sample after rendering
  EXPECT_THAT(error_of("\"repeats\": 3, \"seeds\": {\"noise\": 9007199254740991}"),
              HasSubstr("/seeds/noise: found 9007199254740991, and realisation 2 (repeats 3) would use noise seed + 2, past 2^53; "
                        "expected at most 9007199254740990"));
  EXPECT_THAT(error_of("\"repeats\": 3, \"seeds\": {\"noise\": 9007199254740990}"), "no error");
  EXPECT_THAT(error_of("\"random\": {\"render.samples_per_pixel\": {\"uniform_int\": [1, 1e16]}}"),
              HasSubstr("expected integers a <= b (both included) within +-9e15"));
  // a continuous draw on an integer key, whose ends are integers: refused up front with the remedy (it passed,
  // and the dataset failed on its first samples; an auditor's find); a real key takes it
  for (const char* kind : {"uniform", "log_uniform"})
    EXPECT_THAT(error_of(std::string("\"random\": {\"camera.width_px\": {\"") + kind + "\": [600, 700]}}"),
                HasSubstr("/random/camera.width_px: with the scene file")) << kind;
  EXPECT_THAT(error_of("\"random\": {\"acquisition.frames\": {\"normal\": [255, 10], \"min\": 100, \"max\": 400}}"),
              HasSubstr("expected an integer in [1, 65535] (binary frames summed per gate position (gate_sweep) or per image "
                        "(intensity)); a continuous distribution draws fractions: for an integer key use {\"uniform_int\": [a, b]}"));
  EXPECT_THAT(error_of("\"random\": {\"laser.average_power_mW\": {\"uniform\": [1, 3]}}"), "no error");
}

// One reading names every mistake of the file, as a scene file's does (a new user's file of two mistakes
// took two plans): each top-level key and each key of set, grid and random on its own, then the glTF's names
// of the keys found right; one mistake reads as before.
TEST(DatasetFile, EveryMistakeIsNamedAtOnce) {
  const std::string e = error_of("\"sampels\": 3, \"repeats\": 0, "
                                 "\"random\": {\"ambient.illuminance_lux\": {\"log_uniform\": [0, 80]}, "
                                 "\"nodes.Target.translation_m[2]\": {\"uniform\": [1, 2]}}, "
                                 "\"grid\": {\"laser.average_power_mW\": [1, -2]}");
  EXPECT_THAT(e, HasSubstr("5 errors in the dataset file:\n"));
  for (const char* part : {"test_dataset.json: /sampels: unknown key; did you mean samples?",
                           "test_dataset.json: /repeats: found 0, expected an integer in [1, 1000]",
                           "test_dataset.json: /random/ambient.illuminance_lux/log_uniform: found [0,80], expected 0 < a < b",
                           "test_dataset.json: /grid/laser.average_power_mW/1: ",
                           "test_dataset.json: /random/nodes.Target.translation_m[2]: the nodes and materials the dataset varies"})
    EXPECT_THAT(e, HasSubstr(part));
  EXPECT_EQ(std::count(e.begin(), e.end(), '\n'), 5) << e;  // one line each (after the count's)
  EXPECT_EQ(error_of("\"repeats\": 0").find("errors in the dataset file"), std::string::npos);
  // a wrong value of set is named once: not again by the samples it fails, nor by the checks across keys
  for (const char* body : {"\"set\": {\"camera.f_number\": -3}", "\"repeats\": 2, \"set\": {\"outputs.light\": \"yes\"}"}) {
    const std::string one = error_of(body);
    EXPECT_EQ(one.find("errors in the dataset file"), std::string::npos) << one;
    EXPECT_EQ(one.find('\n'), std::string::npos) << one;
    EXPECT_THAT(one, HasSubstr("test_dataset.json: /set/")) << one;
  }
}

// [a, b) holds for ranges a few ulps wide (b itself was drawn: 51 of 200 at [130, 130 + 2 ulp]; a
// log-uniform fell below a).
TEST(DatasetFile, UniformDrawsStayInTheirHalfOpenRangeAtAnyWidth) {
  for (const char* range : {"[130, 130.00000000000006]", "[300, 300.0000000000002]", "[1, 1.0000000000000004]"}) {
    for (const char* kind : {"uniform", "log_uniform"}) {
      const DatasetSpec s = parse("\"samples\": 200, \"random\": {\"laser.average_power_mW\": {\"" + std::string(kind) + "\": " +
                                  range + "}}");
      const double a = s.random[0].dist.a, b = s.random[0].dist.b;
      for (int i = 0; i < 200; ++i) {
        const double x = make_sample(s, i).parameters["laser.average_power_mW"].get<double>();
        ASSERT_TRUE(x >= a && x < b) << kind << " " << range << ": " << x;
      }
    }
  }
}

TEST(DatasetFile, GltfNodesAndMaterialsAreCheckedAgainstTheGltf) {
  const auto multi = [](const std::string& body) {
    return parse_dataset_text("{\"scenes\": [\"" + kScenes + "multi_object.json\"], " + body + "}", "test_dataset.json");
  };
  const DatasetSpec ok = multi("\"samples\": 4, \"random\": {\"nodes.sphere.translation_m[2]\": {\"uniform\": [-1.2, -0.8]}, "
                               "\"materials.plastic_plate.roughness\": {\"uniform\": [0.05, 0.3]}}");
  const Sample s = make_sample(ok, 3);
  const double z = s.parameters["nodes.sphere.translation_m[2]"].get<double>();
  EXPECT_TRUE(z >= -1.2 && z < -0.8);
  EXPECT_THAT(s.overrides, ::testing::Contains("nodes.sphere.translation_m[2]=" + nlohmann::json(z).dump()));
  try {
    multi("\"random\": {\"nodes.sphre.translation_m[2]\": {\"uniform\": [-1.2, -0.8]}}");
    FAIL() << "a node the glTF does not have";
  } catch (const Error& e) {
    // the dataset's key is named (it named "scenes/0")
    EXPECT_THAT(std::string(e.what()), HasSubstr("test_dataset.json: /random/nodes.sphre.translation_m[2]: the nodes and materials the dataset varies"));
    EXPECT_THAT(std::string(e.what()), HasSubstr("sphre"));
    EXPECT_THAT(std::string(e.what()), HasSubstr("did you mean"));
  }
  try {
    multi("\"grid\": {\"materials.plastic_plate.roughness\": [0.1, 2]}");
    FAIL() << "a roughness above 1";
  } catch (const Error& e) {
    EXPECT_THAT(std::string(e.what()), HasSubstr("/grid/materials.plastic_plate.roughness/1"));
  }
}

TEST(DatasetFile, MissingSceneFilesAreNamed) {
  try {
    parse_dataset_text("{\"scenes\": [\"nowhere.json\"]}", "/tmp/d.json");
    FAIL();
  } catch (const Error& e) {
    EXPECT_THAT(std::string(e.what()), HasSubstr("/tmp/d.json: /scenes/0: the scene file /tmp/nowhere.json does not exist"));
  }
  // A NUL byte (\u0000 in JSON) ended the path the system opened: there.json was read for "there.json\0.old".
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / ("spadgen_dataset_nul_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  std::ofstream(dir / "there.json") << "{}";
  try {
    parse_dataset_text("{\"scenes\": [\"there.json\\u0000.old\"]}", (dir / "d.json").string());
    ADD_FAILURE() << "a scene file name holding a NUL byte was taken";
  } catch (const Error& e) {
    EXPECT_THAT(std::string(e.what()), HasSubstr("d.json: /scenes/0: found 'there.json\\x00.old', which holds a NUL byte"));
  }
  std::filesystem::remove_all(dir);
}

TEST(DatasetFile, TheGridIsEnumeratedWithTheLastKeyFastestAndRepeatsPastItsEnd) {
  const DatasetSpec s = parse(
      "\"samples\": 14, \"grid\": {\"laser.average_power_mW\": [1, 2], \"camera.f_number\": [1.4, 2, 2.8]}");
  EXPECT_EQ(s.grid_cells(), 6);
  EXPECT_EQ(s.count(), 14);
  for (int64_t i = 0; i < 14; ++i) {
    const Sample x = make_sample(s, i);
    const int64_t cell = i % 6;
    EXPECT_EQ(x.parameters["laser.average_power_mW"].get<double>(), std::vector<double>({1, 2})[size_t(cell / 3)]);
    EXPECT_EQ(x.parameters["camera.f_number"].get<double>(), std::vector<double>({1.4, 2, 2.8})[size_t(cell % 3)]);
  }
  EXPECT_EQ(parse("\"grid\": {\"camera.f_number\": [1.4, 2, 2.8]}").count(), 3);  // samples null: one per cell
}

TEST(DatasetFile, AddingSamplesOrAxesOrderLeavesEachSampleItsOwnDraws) {
  const std::string random = "\"random\": {\"laser.average_power_mW\": {\"uniform\": [1, 5]}, "
                             "\"camera.f_number\": {\"log_uniform\": [1, 8]}}";
  const DatasetSpec small = parse("\"seed\": 9, \"samples\": 10, " + random);
  const DatasetSpec large = parse("\"seed\": 9, \"samples\": 1000, " + random);
  const DatasetSpec other = parse("\"seed\": 10, \"samples\": 10, " + random);
  for (int64_t i = 0; i < 10; ++i) {
    const Sample a = make_sample(small, i), b = make_sample(large, i), c = make_sample(other, i);
    EXPECT_EQ(a.overrides, b.overrides);
    EXPECT_EQ(a.seed, b.seed);
    EXPECT_NE(a.parameters["laser.average_power_mW"], c.parameters["laser.average_power_mW"]);
    EXPECT_NE(a.seed, c.seed);
    EXPECT_LT(a.seed, uint64_t{1} << 53);
  }
  // A key's draws are keyed by its name: removing another key does not change them.
  const DatasetSpec one = parse("\"seed\": 9, \"samples\": 10, \"random\": {\"camera.f_number\": {\"log_uniform\": [1, 8]}}");
  for (int64_t i = 0; i < 10; ++i)
    EXPECT_EQ(make_sample(one, i).parameters["camera.f_number"], make_sample(small, i).parameters["camera.f_number"]);
  EXPECT_THROW(make_sample(small, 10), Error);
  // ... by its name, not its spelling: a name needlessly quoted draws as it does bare
  const DatasetSpec quoted = parse("\"seed\": 9, \"samples\": 10, \"random\": {\"camera.\\\"f_number\\\"\": {\"log_uniform\": [1, 8]}}");
  ASSERT_EQ(quoted.random.at(0).key, "camera.\"f_number\"");
  for (int64_t i = 0; i < 10; ++i)
    EXPECT_EQ(make_sample(quoted, i).parameters["camera.\"f_number\""], make_sample(one, i).parameters["camera.f_number"]);
}

// Kolmogorov-Smirnov distance of sorted values from a CDF.
double ks_distance(std::vector<double> v, const std::function<double(double)>& cdf) {
  std::sort(v.begin(), v.end());
  double d = 0.0;
  const double n = double(v.size());
  for (size_t i = 0; i < v.size(); ++i) d = std::max({d, std::fabs(cdf(v[i]) - double(i) / n), std::fabs(cdf(v[i]) - double(i + 1) / n)});
  return d;
}

TEST(DatasetFile, DrawsFollowTheirDistributions) {
  constexpr int n = 4000;
  const DatasetSpec s = parse(
      "\"seed\": 2, \"samples\": 4000, \"random\": {"
      "\"laser.average_power_mW\": {\"uniform\": [1, 5]},"
      "\"ambient.illuminance_lux\": {\"log_uniform\": [1, 1000]},"
      "\"camera.f_number\": {\"normal\": [2, 0.5], \"min\": 1.5, \"max\": 3.5},"
      "\"render.samples_per_pixel\": {\"uniform_int\": [1, 8]},"
      "\"sensor.preset\": {\"choice\": [\"pixel_A\", \"pixel_B\", \"full_chip\"]}}");
  std::vector<double> power, lux, fnum;
  std::map<int64_t, int> spp;
  std::map<std::string, int> preset;
  for (int i = 0; i < n; ++i) {
    const Sample x = make_sample(s, i);
    power.push_back(x.parameters["laser.average_power_mW"].get<double>());
    lux.push_back(x.parameters["ambient.illuminance_lux"].get<double>());
    fnum.push_back(x.parameters["camera.f_number"].get<double>());
    ASSERT_TRUE(x.parameters["render.samples_per_pixel"].is_number_integer());
    ++spp[x.parameters["render.samples_per_pixel"].get<int64_t>()];
    ++preset[x.parameters["sensor.preset"].get<std::string>()];
  }
  // KS at a false-alarm rate of 0.001 per test: D > 1.95 / sqrt(n).
  const double crit = 1.95 / std::sqrt(double(n));
  EXPECT_LT(ks_distance(power, [](double x) { return std::clamp((x - 1) / 4, 0.0, 1.0); }), crit);
  EXPECT_LT(ks_distance(lux, [](double x) { return std::clamp(std::log(x) / std::log(1000.0), 0.0, 1.0); }), crit);
  const auto phi = [](double z) { return 0.5 * std::erfc(-z / std::sqrt(2.0)); };
  const double lo = phi((1.5 - 2) / 0.5), hi = phi((3.5 - 2) / 0.5);
  EXPECT_LT(ks_distance(fnum, [&](double x) { return std::clamp((phi((x - 2) / 0.5) - lo) / (hi - lo), 0.0, 1.0); }), crit);
  EXPECT_GE(*std::min_element(fnum.begin(), fnum.end()), 1.5);
  EXPECT_LE(*std::max_element(fnum.begin(), fnum.end()), 3.5);
  // Chi-square at a false-alarm rate of 0.001: 24.32 for 7 degrees of freedom, 13.82 for 2.
  double chi = 0.0;
  ASSERT_EQ(spp.size(), 8u);
  for (const auto& [k, c] : spp) {
    EXPECT_TRUE(k >= 1 && k <= 8);
    chi += (c - n / 8.0) * (c - n / 8.0) / (n / 8.0);
  }
  EXPECT_LT(chi, 24.32);
  chi = 0.0;
  ASSERT_EQ(preset.size(), 3u);
  for (const auto& [k, c] : preset) chi += (c - n / 3.0) * (c - n / 3.0) / (n / 3.0);
  EXPECT_LT(chi, 13.82);
  // Two keys drawn independently: |correlation| < 3.29 / sqrt(n) (false-alarm rate 0.001).
  double mp = 0, ml = 0;
  for (int i = 0; i < n; ++i) mp += power[i] / n, ml += std::log(lux[i]) / n;
  double cov = 0, vp = 0, vl = 0;
  for (int i = 0; i < n; ++i) {
    const double a = power[i] - mp, b = std::log(lux[i]) - ml;
    cov += a * b, vp += a * a, vl += b * b;
  }
  EXPECT_LT(std::fabs(cov / std::sqrt(vp * vl)), 3.29 / std::sqrt(double(n)));
}

TEST(DatasetFile, SeedsArePerSampleOrFixed) {
  const DatasetSpec per = parse("\"samples\": 3");
  const DatasetSpec fixed = parse("\"samples\": 3, \"seeds\": {\"chip\": 7, \"noise\": \"per_sample\"}");
  const Sample a = make_sample(per, 1), b = make_sample(fixed, 1);
  EXPECT_EQ(a.seed, b.seed);
  EXPECT_EQ(a.chip_seed, a.seed);
  EXPECT_EQ(b.chip_seed, 7u);
  EXPECT_EQ(b.noise_seed, b.seed);
  EXPECT_THAT(b.overrides, ::testing::Contains("seeds.chip=7"));
  EXPECT_EQ(fixed.resolved["seeds"].dump(), "{\"light\":\"per_sample\",\"chip\":7,\"noise\":\"per_sample\"}");
  EXPECT_EQ(b.folder(), "samples/000001");
  EXPECT_EQ(b.repeat_folder(2), "samples/000001_r02");
  // Repeats need the saved light.
  EXPECT_THAT(make_sample(parse("\"samples\": 3, \"repeats\": 2"), 0).overrides, ::testing::Contains("outputs.light=true"));
}

TEST(Shards, FromTheCommandLine) {
  EXPECT_EQ(parse_shard("2/4").index, 2);
  EXPECT_EQ(parse_shard("2/4").count, 4);
  EXPECT_TRUE(parse_shard("0/3").owns(6));
  EXPECT_FALSE(parse_shard("1/3").owns(6));
  for (const char* bad : {"4/4", "1", "-1/2", "a/b", "1/0", "", "1/2/3"})
    EXPECT_THROW(parse_shard(bad), Error) << bad;
  // the bound on N said (0/4294967297 was refused as "expected I/N with 0 <= I < N")
  try {
    (void)parse_shard("0/4294967297");
    ADD_FAILURE() << "a 10-digit N was taken";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("expected I/N with 0 <= I < N <= 999999999"));
  }
}

TEST(Shards, FromSlurmJobArraysAndKubernetesIndexedJobs) {
  const auto clear = [] {
    for (const char* v : {"SLURM_ARRAY_TASK_ID", "SLURM_ARRAY_TASK_COUNT", "SLURM_ARRAY_TASK_MIN", "SLURM_ARRAY_TASK_STEP",
                          "SLURM_ARRAY_TASK_MAX", "JOB_COMPLETION_INDEX", "JOB_COMPLETIONS"})
      ::unsetenv(v);
  };
  clear();
  EXPECT_FALSE(shard_from_environment().has_value());
  ::setenv("SLURM_ARRAY_TASK_ID", "5", 1), ::setenv("SLURM_ARRAY_TASK_MIN", "2", 1), ::setenv("SLURM_ARRAY_TASK_COUNT", "4", 1);
  EXPECT_EQ(shard_from_environment()->text(), "3/4");
  ::setenv("SLURM_ARRAY_TASK_ID", "6", 1);
  EXPECT_THROW(shard_from_environment(), Error);  // beyond MIN + COUNT - 1
  ::unsetenv("SLURM_ARRAY_TASK_COUNT");
  EXPECT_THROW(shard_from_environment(), Error);
  // COUNT 0: said so (it suggested --array=0--1)
  ::setenv("SLURM_ARRAY_TASK_COUNT", "0", 1);
  try {
    (void)shard_from_environment();
    ADD_FAILURE() << "COUNT 0 was taken";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("SLURM_ARRAY_TASK_COUNT=0; expected a job array of at least one task"));
    EXPECT_THAT(e.what(), Not(HasSubstr("--1")));
  }
  clear();
  // --array=1-7:2, as Slurm 22.05 describes it: shards 0-3 of 4
  ::setenv("SLURM_ARRAY_TASK_MIN", "1", 1), ::setenv("SLURM_ARRAY_TASK_MAX", "7", 1), ::setenv("SLURM_ARRAY_TASK_STEP", "2", 1);
  ::setenv("SLURM_ARRAY_TASK_COUNT", "4", 1), ::setenv("SLURM_ARRAY_TASK_ID", "5", 1);
  EXPECT_EQ(shard_from_environment()->text(), "2/4");
  // --array=0,2,4 as it describes it (STEP 1, COUNT 3, MAX 4): task 2 would run shard 2 of 3 and task 4
  // none, shard 1 never; every task refuses, naming the array to use
  ::setenv("SLURM_ARRAY_TASK_MIN", "0", 1), ::setenv("SLURM_ARRAY_TASK_MAX", "4", 1), ::setenv("SLURM_ARRAY_TASK_STEP", "1", 1);
  ::setenv("SLURM_ARRAY_TASK_COUNT", "3", 1), ::setenv("SLURM_ARRAY_TASK_ID", "2", 1);
  try {
    (void)shard_from_environment();
    ADD_FAILURE() << "an uneven array was taken";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), HasSubstr("are not an evenly spaced array (--array=0,2,5, for example, is uneven), whose tasks would run some shards "
                                    "and never others: use --array=0-2, or START-END:STEP"));
  }
  clear();
  ::setenv("JOB_COMPLETION_INDEX", "1", 1);
  EXPECT_THROW(shard_from_environment(), Error);  // the Job's completions must be given
  ::setenv("JOB_COMPLETIONS", "3", 1);
  EXPECT_EQ(shard_from_environment()->text(), "1/3");
  ::setenv("JOB_COMPLETIONS", "x", 1);
  EXPECT_THROW(shard_from_environment(), Error);
  // the completions without an index (not an Indexed Job, or an empty index): refused (taken as 0 of 1)
  for (const bool empty : {true, false}) {
    clear();
    ::setenv("JOB_COMPLETIONS", "2", 1);
    if (empty) ::setenv("JOB_COMPLETION_INDEX", "", 1);
    try {
      (void)shard_from_environment();
      FAIL() << "no index";
    } catch (const Error& e) {
      EXPECT_THAT(e.what(), HasSubstr(std::string("JOB_COMPLETIONS is set but JOB_COMPLETION_INDEX is ") + (empty ? "empty" : "not") +
                                      ": run as a Kubernetes Indexed Job"));
    }
  }
  clear();
}

TEST(DatasetFile, TheDocsHoldTheGeneratedReference) {
  std::ifstream in(std::string(SPADGEN_SOURCE_DIR) + "/docs/datasets.md");
  ASSERT_TRUE(in) << "docs/datasets.md is missing";
  std::ostringstream text;
  text << in.rdbuf();
  EXPECT_THAT(text.str(), HasSubstr(dataset_reference_markdown()))
      << "docs/datasets.md is out of date: regenerate its key table with `spadgen dataset schema`";
  std::ifstream schema(std::string(SPADGEN_SOURCE_DIR) + "/docs/dataset-file.schema.json");
  ASSERT_TRUE(schema) << "docs/dataset-file.schema.json is missing";
  std::ostringstream json_text;
  json_text << schema.rdbuf();
  EXPECT_EQ(json_text.str(), dataset_schema_json())
      << "docs/dataset-file.schema.json is out of date: regenerate it with `spadgen dataset schema --json-schema`";
}

TEST(DatasetFile, RangesText) {
  EXPECT_EQ(ranges_text({}), "");
  EXPECT_EQ(ranges_text({3}), "3");
  EXPECT_EQ(ranges_text({1, 2, 3, 7, 9, 10}), "1-3, 7, 9-10");
}

}  // namespace
// The revision tests' common words: the GGX revision's change, and a sample's setting without dark counts (whose
// revision would join every other).
const std::string kGgxRevision = "glossy and metallic materials (GGX) render otherwise: a narrow lobe's peak was up to 7 % bright";
const std::string kNoDarkCounts = "\"sensor.dark_counts\": false";

// sample_hash's revisions of the renderer's rules: each applies where its rule changed what a sample renders
// (its samples rendered before are stale, with the change in words), and nowhere else (other samples keep their
// hashes): a gate sweep to a target error; an intensity run to a target error that keeps its laser return
// without laser_on; a scene rendering GGX lobes (a glossy or metallic material, in its glTF or by a sample's
// parameters); a colour under ambient light; a base colour texture through KHR_texture_transform. (Without dark
// counts, whose revision is the next test's.)
TEST(DatasetFolder, TheRenderRevisionsApplyWhereTheirRuleChangedTheSample) {
  const fs::path dir = fs::temp_directory_path() / ("spadgen_dataset_revisions_" + std::to_string(::getpid()));
  const auto resolved = [&](const std::string& set) {
    const DatasetSpec spec = parse("\"set\": {" + kNoDarkCounts + ", " + set + "}");
    return DatasetFolder(spec, dir).resolve(make_sample(spec, 0));
  };
  const std::string target = "\"render.target_relative_error\": 0.05, ";
  const std::string intensity = "\"acquisition.mode\": \"intensity\"";
  const std::string glint = "smooth (roughness below 0.032) mirrors and plates render otherwise: the laser's image in their "
                            "faces, a glint where it lands in view, is rendered as the camera sees it (it was missing)";
  const std::string light = "an intensity run's saved light (outputs.light, the dataset's repeats) no longer traces the laser, "
                            "which its counts do not see: no laser.exr, no laser channels in ground_truth.exr";
  struct Case {
    std::string set;
    std::string revisions;  // "" where none applies
  };
  for (const Case& c : std::vector<Case>{
           {"\"render.samples_per_pixel\": 4", ""},
           {target + "\"render.samples_per_pixel\": 4", "a gate sweep to render.target_relative_error holds the ambient light too"},
           {target + intensity, ""},
           // an intensity run's saved light no longer holds the laser's (it was traced for it, and held to the target)
           {target + intensity + ", \"outputs.light\": true", light},
           {target + intensity + ", \"outputs.transient\": true",
            "render.target_relative_error holds the laser return an intensity run keeps (outputs.transient, outputs.light with a time window)"},
           {target + intensity + ", \"outputs.light\": true, \"acquisition.intensity.laser_on\": true", ""},
           {intensity + ", \"outputs.light\": true", light},
           {intensity + ", \"outputs.light\": true, \"outputs.transient\": true", ""},
           {intensity + ", \"outputs.light\": true, \"render.window_start_ns\": 0, \"render.window_stop_ns\": 10", ""},
           // the flat target's paper is Lambertian: a GGX lobe only where a sample's parameters make it glossy
           {"\"materials.white_paper.roughness\": 0.5", kGgxRevision},
           {"\"materials.white_paper.roughness\": 1", ""},
           {"\"materials.white_paper.metallic\": 0.2", kGgxRevision},
           // a mirror (roughness below 0.032: Dirac lobes only) renders no GGX lobe, and the camera sees the laser's
           // image in it now
           {"\"materials.white_paper.metallic\": 1, \"materials.white_paper.roughness\": 0.01", glint},
           // a colour under ambient light reflects the band's photons (lambda-weighted): grey, or colour in the
           // dark, keeps its bits
           {"\"ambient.illuminance_lux\": 100", ""},
           {"\"materials.white_paper.base_color\": [0.8, 0.2, 0.2]", ""},
           {"\"ambient.illuminance_lux\": 100, \"materials.white_paper.base_color\": [0.8, 0.2, 0.2]",
            "coloured surfaces and lights render the ambient light otherwise: the band's colours are averaged over its photons "
            "(an equal-energy spectrum's, by lambda), not plainly over wavelength (up to about 15 %)"}}) {
    const DatasetFolder::Resolved r = resolved(c.set);
    EXPECT_EQ(r.revisions, c.revisions) << c.set;
    EXPECT_EQ(r.hash != r.hash_before_revisions, !c.revisions.empty()) << c.set;
  }
  // the multi-object scene's plates are glossy (roughness 0.05): every sample of it
  const DatasetSpec spec = parse_dataset_text("{\"scenes\": [\"" + kScenes + "multi_object.json\"], \"set\": {" + kNoDarkCounts + "}}",
                                              "test_dataset.json");
  const DatasetFolder::Resolved r = DatasetFolder(spec, dir).resolve(make_sample(spec, 0));
  EXPECT_EQ(r.revisions, kGgxRevision);
  EXPECT_NE(r.hash, r.hash_before_revisions);
  // made clear (smooth), its plate's echoes on the laser's side are rendered: those revisions and the glint's
  const DatasetSpec clear = parse_dataset_text("{\"scenes\": [\"" + kScenes + "multi_object.json\"], \"set\": "
                                               "{" + kNoDarkCounts + ", \"materials.plastic_plate.roughness\": 0}}", "test_dataset.json");
  const DatasetFolder::Resolved c = DatasetFolder(clear, dir).resolve(make_sample(clear, 0));
  EXPECT_EQ(c.revisions, glint + "; clear (smooth) refracting plates render otherwise: the laser's light reflected inside a plate "
                         "on its way in (half of the plate's delayed echo) was left out; clear (smooth) refracting plates render "
                         "otherwise: the laser's light reflected round inside a plate twice or more on its way in (part of the "
                         "plate's later echoes) was left out");
  EXPECT_NE(c.hash, c.hash_before_revisions);
  // a glTF point light, which the camera sees in view now, and in smooth faces: where it lights the scene
  // (ambient.gltf_lights)
  {
    fs::create_directories(dir);
    std::ifstream in(kScenes + "flat_target.gltf");
    nlohmann::json gltf = nlohmann::json::parse(in);
    gltf["extensionsUsed"].push_back("KHR_lights_punctual");
    gltf["extensions"]["KHR_lights_punctual"]["lights"] = {{{"name", "bulb"}, {"type", "point"}, {"intensity", 10.0}}};
    gltf["nodes"].push_back({{"name", "bulb"}, {"translation", {0.0, 0.0, 0.5}}, {"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}});
    gltf["scenes"][0]["nodes"].push_back(gltf["nodes"].size() - 1);
    std::ofstream(dir / "lamp.gltf") << gltf.dump();
    std::ofstream(dir / "lamp.json") << "{\"gltf\": \"lamp.gltf\", \"camera\": {\"position_m\": [0, 0, 1], \"look_at_m\": [0, 0, 0]}}";
    const std::string lamp = "glTF point and spot lights render otherwise: a lamp in view is rendered in the pixel it lands in (it was missing)";
    const std::string mirror = "\"materials.white_paper.metallic\": 1, \"materials.white_paper.roughness\": 0.01";
    for (const auto& [set, revisions] :
         {std::pair<std::string, std::string>{"", lamp},
          {"\"ambient.gltf_lights\": false", ""},
          // a mirror beside it: the lamp's image in it, and the laser's
          {mirror, lamp + "; glTF point and spot lights beside smooth (roughness below 0.032) mirrors and plates render "
                   "otherwise: a lamp's image in their faces is rendered in the pixel it lands in (it was missing); " + glint},
          {mirror + ", \"ambient.gltf_lights\": false", glint}}) {
      const DatasetSpec lit = parse_dataset_text("{\"scenes\": [\"" + (dir / "lamp.json").string() + "\"], \"set\": {" + kNoDarkCounts +
                                                     (set.empty() ? "" : ", ") + set + "}}",
                                                 "test_dataset.json");
      const DatasetFolder::Resolved l = DatasetFolder(lit, dir / "out").resolve(make_sample(lit, 0));
      EXPECT_EQ(l.revisions, revisions) << set;
    }
  }
  // a base colour texture through KHR_texture_transform, which maps its coordinates now (the test chart's
  // print; without the extension, no revision)
  {
    std::ifstream in(kScenes + "test_chart.gltf");
    nlohmann::json gltf = nlohmann::json::parse(in);
    std::ofstream(dir / "chart.gltf") << gltf.dump();
    gltf["extensionsUsed"] = {"KHR_texture_transform"};
    gltf["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["extensions"]["KHR_texture_transform"] = {{"scale", {2.0, 2.0}}};
    std::ofstream(dir / "chart_transformed.gltf") << gltf.dump();
    const std::string transform = "base colour textures with KHR_texture_transform render otherwise: the transform (offset, rotation, "
                                  "scale, texCoord) maps the coordinates they read (it was left out, with a warning)";
    for (const auto& [name, revisions] : {std::pair<std::string, std::string>{"chart", ""}, {"chart_transformed", transform}}) {
      std::ofstream(dir / (name + ".json")) << "{\"gltf\": \"" << name << ".gltf\", \"camera\": {\"position_m\": [0, 0, 1], \"look_at_m\": [0, 0, 0]}}";
      const DatasetSpec chart = parse_dataset_text("{\"scenes\": [\"" + (dir / (name + ".json")).string() + "\"], \"set\": {" + kNoDarkCounts + "}}",
                                                   "test_dataset.json");
      EXPECT_EQ(DatasetFolder(chart, dir / "out").resolve(make_sample(chart, 0)).revisions, revisions) << name;
    }
  }
  // the multi-object scene's sphere (81920 triangles shaded by vertex normals) made glass or a smooth mirror: the
  // laser's connections solved through it or off it take Fresnel at the solved normals now; not where it is
  // Lambertian, or no laser is traced (a 2D run); nor for the clear plate above (its normals are its faces')
  {
    const std::string curved = "glass meshes shaded by vertex normals and smooth curved mirrors render otherwise: the Fresnel "
                               "factors of the laser's connections through and off them are taken at the solved path's normals "
                               "(they were taken some 1e-5 m away: 3e-4 of the light through glass at 60 degrees' incidence)";
    const std::string glass = "\"materials.sphere_white.roughness\": 0, \"materials.sphere_white.transmission\": 1, "
                              "\"materials.sphere_white.thickness_mm\": 100, \"materials.sphere_white.ior\": 1.5";
    // (the plate made Lambertian; the glass sphere's revisions include its echoes', the scene's smooth faces the glint's)
    for (const auto& [set, applies] :
         {std::pair<std::string, bool>{glass, true},
          {"\"materials.sphere_white.roughness\": 0, \"materials.sphere_white.metallic\": 1", true},
          {glass + ", \"acquisition.mode\": \"intensity\"", false},
          {"\"materials.sphere_white.roughness\": 1", false}}) {
      const DatasetSpec sphere = parse_dataset_text("{\"scenes\": [\"" + kScenes + "multi_object.json\"], \"set\": {" + kNoDarkCounts +
                                                        ", \"materials.plastic_plate.roughness\": 1, \"materials.plastic_plate.transmission\": 0, " +
                                                        set + "}}",
                                                    "test_dataset.json");
      const DatasetFolder::Resolved v = DatasetFolder(sphere, dir).resolve(make_sample(sphere, 0));
      EXPECT_EQ(v.revisions.find(curved) != std::string::npos, applies) << set << ": " << v.revisions;
      if (set == "\"materials.sphere_white.roughness\": 1") {
        EXPECT_EQ(v.revisions, "");
      }
    }
  }
  // ... not where no echo is drawn: an ior of 1 (no refraction: the loader applies every edit, ior and thickness
  // too; its smooth faces are still taken to mirror the laser), or a 2D run that traces no laser (nor either)
  for (const auto& [set, revisions] : {std::pair<std::string, std::string>{"\"materials.plastic_plate.ior\": 1", glint},
                                       {"\"acquisition.mode\": \"intensity\"", ""}}) {
    const DatasetSpec none = parse_dataset_text("{\"scenes\": [\"" + kScenes + "multi_object.json\"], \"set\": "
                                                "{" + kNoDarkCounts + ", \"materials.plastic_plate.roughness\": 0, " + set + "}}", "test_dataset.json");
    const DatasetFolder::Resolved n = DatasetFolder(none, dir).resolve(make_sample(none, 0));
    EXPECT_EQ(n.revisions, revisions) << set;
    EXPECT_EQ(n.hash != n.hash_before_revisions, !revisions.empty()) << set;
  }
  fs::remove_all(dir);
}

// The sensor's revision: dcr_median_cps became the chip's median (hot pixels included), which moved every
// pixel's dark count rate where a pixel type the chip uses has hot pixels; its samples drawn before are stale.
// Not where no dark counts are drawn, no pixel in use is hot, or the median is 0.
TEST(DatasetFolder, TheDarkCountRevisionAppliesWhereTheChipsMedianMovedTheRates) {
  const fs::path dir = fs::temp_directory_path() / ("spadgen_dataset_dcr_revision_" + std::to_string(::getpid()));
  const std::string dcr = "the sensor's dark counts are drawn otherwise: sensor.pixel_A/B.dcr_median_cps is the chip's median, "
                          "hot pixels included (it was the main population's, and the chip's median 1.07 times it)";
  for (const auto& [set, applies] : std::vector<std::pair<std::string, bool>>{
           {"", true},  // the defaults: pixel A, 5 % hot pixels
           {"\"sensor.dark_counts\": false", false},
           {"\"sensor.pixel_A.hot_pixel_fraction\": 0", false},
           {"\"sensor.pixel_A.dcr_median_cps\": 0", false},
           // pixel B's hot pixels where the chip has no pixel B, and where it has
           {"\"sensor.pixel_A.hot_pixel_fraction\": 0, \"sensor.preset\": \"pixel_A\"", false},
           {"\"sensor.pixel_A.hot_pixel_fraction\": 0, \"sensor.preset\": \"full_chip\"", true},
           {"\"sensor.pixel_A.hot_pixel_fraction\": 0, \"sensor.preset\": \"pixel_B\"", true},
           {"\"sensor.pixel_A.hot_pixel_fraction\": 0, \"sensor.pixel_B.hot_pixel_fraction\": 0, \"sensor.preset\": \"full_chip\"", false},
           {"\"acquisition.mode\": \"intensity\"", true}}) {
    const DatasetSpec spec = parse("\"set\": {" + set + "}");
    const DatasetFolder::Resolved r = DatasetFolder(spec, dir).resolve(make_sample(spec, 0));
    EXPECT_EQ(r.revisions, applies ? dcr : std::string()) << set;
    EXPECT_EQ(r.hash != r.hash_before_revisions, applies) << set;
  }
}

// The revisions of rules that changed on 3 December: laser connections through rough refracting faces (a
// plate of roughness above 0.158, where the laser is traced), a sweep whose last position on the grid now
// counts, a measured gate table's own rise and fall times. Each where its rule applies, and nowhere else.
TEST(DatasetFolder, TheRoughPlateSweepAndGateTableRevisionsApplyWhereTheirRuleChangedTheSample) {
  const fs::path dir = fs::temp_directory_path() / ("spadgen_dataset_more_revisions_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const std::string rough = "rough refracting plates (roughness above 0.158) render otherwise: the laser's connections cross their "
                            "rough faces by drawn microfacet normals, also beside their shadow (they were crossed as smooth)";
  const std::string sweep = "this gate sweep has another number of positions: its last, on the step grid within the rounding of "
                            "start, stop and step, counts (it was left out)";
  const std::string table = "a measured gate table (sensor.gate.profile_csv) is described otherwise: metadata.json's gate rise_ps "
                            "and fall_ps are the table's own 10-90 % times (they were sensor.gate.rise_ps and fall_ps, unused)";
  std::ofstream(dir / "gate.csv") << "0,0\n400,1\n4200,1\n4600,0\n";
  const auto revisions = [&](const std::string& scene, const std::string& set) {
    const DatasetSpec spec = parse_dataset_text("{\"scenes\": [\"" + kScenes + scene + "\"], \"set\": {" + kNoDarkCounts + set + "}}",
                                                "test_dataset.json");
    return DatasetFolder(spec, dir / "out").resolve(make_sample(spec, 0)).revisions;
  };
  // the multi-object plate: glossy at 0.05 (crossed as smooth, as before), rough at 0.3; a 2D run traces no laser
  EXPECT_EQ(revisions("multi_object.json", ""), kGgxRevision);
  EXPECT_EQ(revisions("multi_object.json", ", \"materials.plastic_plate.roughness\": 0.15"), kGgxRevision);
  EXPECT_EQ(revisions("multi_object.json", ", \"materials.plastic_plate.roughness\": 0.3"), kGgxRevision + "; " + rough);
  EXPECT_EQ(revisions("multi_object.json", ", \"materials.plastic_plate.roughness\": 0.3, \"acquisition.mode\": \"intensity\""), kGgxRevision);
  // not refracting (ior 1): no crossing
  EXPECT_EQ(revisions("multi_object.json", ", \"materials.plastic_plate.roughness\": 0.3, \"materials.plastic_plate.ior\": 1"), kGgxRevision);
  // 5 to 5.00001 ns in 1e-6 ps steps: 10001 positions, 10000 before; the paper's sweep and one just off the grid as before
  const std::string grid = ", \"acquisition.gate_sweep.start_ns\": 5, \"acquisition.gate_sweep.step_ps\": 1e-6, \"acquisition.gate_sweep.stop_ns\": ";
  EXPECT_EQ(revisions("flat_target.json", grid + "5.00001"), sweep);
  EXPECT_EQ(revisions("flat_target.json", grid + "5.0000099999"), "");
  EXPECT_EQ(revisions("flat_target.json", ""), "");
  // a gate table
  EXPECT_EQ(revisions("flat_target.json", ", \"sensor.gate.profile_csv\": \"" + (dir / "gate.csv").string() + "\""), table);
  fs::remove_all(dir);
}

// The card's "Sensor and acquisition" row is each scene's first sample: a value the dataset varies reads
// "varies" (a new user read sample 0's preset and laser power as the dataset's), also one a preset sets (a
// reviewer's render.quality grid showed sample 0's paths), the others their value.
TEST(DatasetFolder, TheCardSaysWhichSettingsVary) {
  const fs::path dir = fs::temp_directory_path() / ("spadgen_dataset_card_" + std::to_string(::getpid()));
  const DatasetSpec spec = parse("\"grid\": {\"sensor.preset\": [\"pixel_A\", \"pixel_B\"], \"render.quality\": [\"draft\", \"standard\"]}, "
                                 "\"random\": {\"\\\"laser\\\".average_power_mW\": {\"uniform\": [1, 2]}, "
                                 "\"acquisition.gate_sweep.step_ps\": {\"uniform\": [30, 40]}}");
  const std::string card = dataset_card(DatasetFolder(spec, dir), CardTally{});
  const size_t at = card.find("flat_target.json` | 1024 x 500 | ", card.find("## Sensor and acquisition"));
  ASSERT_NE(at, std::string::npos) << card;
  const std::string row = card.substr(at, card.find('\n', at) - at);
  EXPECT_THAT(row, HasSubstr(" | varies | gate_sweep, "));  // the preset, by the grid
  EXPECT_THAT(row, HasSubstr(" ns in varies ps steps"));    // the sweep's step, by a random key
  // a quoted spelling; a preset that sets the paths (found by the values of the scene's first samples); what
  // nothing varies, as it is
  EXPECT_THAT(row, HasSubstr(" | 637 nm, 40 MHz, varies mW | varies paths per pixel |"));
  EXPECT_THAT(row, Not(HasSubstr("pixel_A")));
  // a 2D dataset varying the exposure and its length reads so (it read "varies exposure of varies us")
  const DatasetSpec two_d = parse("\"set\": {\"acquisition.mode\": \"intensity\"}, \"grid\": {\"acquisition.intensity.exposure\": "
                                  "[\"single\", \"dual\"]}, \"random\": {\"acquisition.intensity.exposure_us\": {\"uniform\": [5, 10]}}");
  const std::string card2 = dataset_card(DatasetFolder(two_d, dir), CardTally{});
  EXPECT_THAT(card2, HasSubstr("| intensity, 255 frames, exposure (single or dual) varies, its length varies |")) << card2;
  // its laser is off (the card listed its wavelength, rate and power, which say nothing of its data)
  EXPECT_THAT(card2, HasSubstr("varies | off (intensity mode without laser_on) | ")) << card2;
  const DatasetSpec lit = parse("\"set\": {\"acquisition.mode\": \"intensity\"}, \"grid\": {\"acquisition.intensity.laser_on\": [false, true]}");
  EXPECT_THAT(dataset_card(DatasetFolder(lit, dir), CardTally{}), HasSubstr(" nm, 40 MHz, 2 mW (laser_on varies) | "));
  const DatasetSpec single = parse("\"set\": {\"acquisition.mode\": \"intensity\", \"acquisition.intensity.exposure_us\": 10}");
  EXPECT_THAT(dataset_card(DatasetFolder(single, dir), CardTally{}), HasSubstr("| intensity, 255 frames, single exposure of 10 us |"));
  fs::remove_all(dir);
}

// A value that needs another of the dataset's keys is checked with them: one end of the time window in set, the
// other varied by the grid (both were refused, each alone, and the window's end could not be varied); a value
// wrong among them too is still named.
TEST(DatasetFile, AValueIsCheckedWithTheOtherKeysItNeeds) {
  const DatasetSpec spec = parse("\"set\": {\"render.window_start_ns\": 0}, \"grid\": {\"render.window_stop_ns\": [20, 60]}");
  EXPECT_EQ(spec.grid.size(), 1u);
  EXPECT_THAT(error_of("\"set\": {\"render.window_start_ns\": 0}, \"grid\": {\"render.window_stop_ns\": [20, -1]}"),
              HasSubstr("/grid/render.window_stop_ns/1: with the scene file "));
  EXPECT_THAT(error_of("\"grid\": {\"render.window_stop_ns\": [20, 60]}"), HasSubstr("/grid/render.window_stop_ns/0: "));
}

// "samples" fewer than the grid cells leaves the last cells out, and with the scenes outermost whole scene files:
// the plan and the run warn, and the card's scene table counts each scene's samples (it listed a scene no sample
// took).
TEST(DatasetFolder, WhatTheSamplesCoverIsSaid) {
  const fs::path dir = fs::temp_directory_path() / ("spadgen_dataset_cover_" + std::to_string(::getpid()));
  const auto two_scenes = [](const std::string& samples) {
    return parse_dataset_text("{\"scenes\": [\"" + kScenes + "flat_target.json\", \"" + kScenes + "multi_object.json\"], " +
                              "\"samples\": " + samples + ", \"grid\": {\"camera.f_number\": [1.4, 2, 2.8]}}", "cover.json");
  };
  const DatasetSpec three = two_scenes("3");
  EXPECT_EQ(three.coverage_warning(), three.file + ": samples (3) is fewer than the 6 grid cells (scenes outermost, the last grid key "
                                      "fastest): cells 3-5 make no sample, nor does the scene file " + kScenes +
                                      "multi_object.json; \"samples\": null makes one per cell, a multiple of 6 as many of each");
  std::string card = dataset_card(DatasetFolder(three, dir), CardTally{});
  EXPECT_THAT(card, HasSubstr("flat_target.json` | 3 | ")) << card;
  EXPECT_THAT(card, HasSubstr("multi_object.json` | 0 | ")) << card;
  EXPECT_THAT(card, HasSubstr("cells 3-5 make no sample"));
  const DatasetSpec five = two_scenes("5");  // the second scene takes two of its three cells
  EXPECT_THAT(five.coverage_warning(), HasSubstr("cell 5 make no sample; "));
  EXPECT_THAT(dataset_card(DatasetFolder(five, dir), CardTally{}), HasSubstr("multi_object.json` | 2 | "));
  // more samples than cells: each scene its share, and no warning (the cells repeat past the grid's end)
  const DatasetSpec eight = two_scenes("8");
  EXPECT_EQ(eight.coverage_warning(), "");
  card = dataset_card(DatasetFolder(eight, dir), CardTally{});
  EXPECT_THAT(card, HasSubstr("flat_target.json` | 5 | "));
  EXPECT_THAT(card, HasSubstr("multi_object.json` | 3 | "));
  EXPECT_EQ(two_scenes("null").coverage_warning(), "");
  fs::remove_all(dir);
}

// Warnings grouped by kind: numbers standing alone vary from sample to sample (values, exponents, signs), digits
// inside names tell kinds apart (offset_m[0] and [2], layer0 and layer1, pde_400nm.csv and pde_905nm.csv were
// one kind); at most kKindsShown kinds, then how many more.
TEST(DatasetFolder, WarningsAreGroupedByKindWithTheirNumbersLeftOut) {
  EXPECT_EQ(warning_kind("acquisition.cycles_per_frame: 1915 laser cycles last 47.875 us"),
            warning_kind("acquisition.cycles_per_frame: 2000 laser cycles last 50 us"));
  EXPECT_EQ(warning_kind("a rate of 1e+06 per s, -2.5 mm"), warning_kind("a rate of 100000 per s, 3 mm"));
  EXPECT_EQ(warning_kind("a rate of 1e+06 per s"), "a rate of # per s");
  EXPECT_EQ(warning_kind("expected a value in [0, 1]"), warning_kind("expected a value in [2, 5]"));  // a list's numbers
  for (const auto& [a, b] : {std::pair{"laser.offset_m[0]: far", "laser.offset_m[2]: far"}, {"layer0 too deep", "layer1 too deep"},
                             {"m[0][1]: far", "m[0][2]: far"},
                             {"pde_400nm.csv: short", "pde_905nm.csv: short"}})
    EXPECT_NE(warning_kind(a), warning_kind(b)) << a;
  WarningTally t;
  for (int64_t i = 0; i < 30; ++i) t.add(i, {"kind k" + std::string(1, char('a' + i % 26)) + "x: " + std::to_string(i) + " s"});
  const std::vector<std::string> lines = t.lines(" (more)");
  ASSERT_EQ(lines.size(), WarningTally::kKindsShown + 1);
  EXPECT_EQ(lines.front(), "2 samples (0, 26): kind kax: 0 s");  // the kinds most samples share first
  EXPECT_EQ(lines.back(), "and 6 more kinds of warning (more)");
  WarningTally once;
  once.add(3, {"x: 1 s", "x: 2 s"});  // a sample counts once per kind
  EXPECT_EQ(once.lines("").front(), "1 sample (3): x: 1 s");
}

}  // namespace spadgen::datasets
