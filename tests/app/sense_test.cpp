// spadgen sense: the sensor stage alone from a run's saved light, as a user runs it.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cmath>
#include <fstream>
#include <limits>
#include <set>
#include <string>
#include <tuple>
#include <vector>
#include <nlohmann/json.hpp>

#include "app_fixture.h"
#include "writers/writers.h"

namespace {
using namespace spadgen::testing;
using ::testing::HasSubstr;
using ::testing::Not;

// kSmall with the light saved, and an 8-pixel-wide crop at the sensor's left edge with crosstalk's ring.
const std::string kLit = kSmall + " --set outputs.light=true";

TEST_F(App, SenseWritesWhatTheRunWroteBitForBit) {
  ASSERT_EQ(sh("run " + kLit + " -o " + (dir_ / "run").string()).code, 0);
  const Result r = sh("sense " + (dir_ / "run").string() + " -q -o " + (dir_ / "sense").string());
  ASSERT_EQ(r.code, 0) << r.output;
  expect_same_outputs(dir_ / "run", dir_ / "sense");
  const auto meta = nlohmann::json::parse(slurp(dir_ / "sense/metadata.json"));
  EXPECT_EQ(meta["sense"]["from"], (dir_ / "run").string());
}

// ... its warnings too: the run's that its sweep starts after the returns rise. With the run's own sensor
// labels.exr is linked from the run, not labelled again, and the warning counted from the labels was dropped.
TEST_F(App, SenseKeepsTheRunsWarningOfItsSweepsEdges) {
  ASSERT_EQ(sh("run " + kScenes + "flat_target.json -q --set camera.crop=[500,240,16,16] --set render.samples_per_pixel=1 "
               "--set outputs.light=true --set acquisition.gate_sweep.start_ns=8 -o " + (dir_ / "run").string()).code, 0);
  const auto run_meta = nlohmann::json::parse(slurp(dir_ / "run/metadata.json"));
  ASSERT_THAT(run_meta["warnings"].dump(), HasSubstr("rise before the gate sweep's first position"));
  const Result r = sh("sense " + (dir_ / "run").string() + " -o " + (dir_ / "sense").string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("rise before the gate sweep's first position"));
  expect_same_outputs(dir_ / "run", dir_ / "sense");
  EXPECT_EQ(nlohmann::json::parse(slurp(dir_ / "sense/metadata.json"))["warnings"], run_meta["warnings"]);
}

// Light saved before the ambient light's standard error (no light/ambient_se) is sensed as before: the
// ambient image without its standard_error, metadata.json's accuracy without the ambient summary.
TEST_F(App, SenseReadsLightSavedBeforeTheAmbientStandardError) {
  ASSERT_EQ(sh("run " + kLit + " -o " + (dir_ / "run").string()).code, 0);
  nlohmann::ordered_json meta = nlohmann::ordered_json::parse(slurp(dir_ / "run/metadata.json"));
  fs::remove(dir_ / "run/light/ambient_se.npy");
  auto& files = meta["files"];
  files.erase(std::find(files.begin(), files.end(), "light/ambient_se.npy"));
  meta["file_bytes"].erase("light/ambient_se.npy");
  std::ofstream(dir_ / "run/metadata.json") << meta.dump(2);
  const Result r = sh("sense " + (dir_ / "run").string() + " -q --set seeds.chip=5 -o " + (dir_ / "sense").string());
  ASSERT_EQ(r.code, 0) << r.output;
  const auto ambient = spadgen::writers::read_exr((dir_ / "sense/ambient.exr").string());
  EXPECT_TRUE(ambient.channels.count("photons_per_second"));
  EXPECT_FALSE(ambient.channels.count("standard_error"));
  const auto sensed = nlohmann::json::parse(slurp(dir_ / "sense/metadata.json"));
  EXPECT_TRUE(sensed["accuracy"].contains("laser_relative_standard_error"));
  EXPECT_FALSE(sensed["accuracy"].contains("ambient_relative_standard_error"));
}

// sense reads the saved light and the sensor's tables, not the scene's geometry: a run whose glTF (and its
// buffers) are gone since, as in an archive of runs, is re-sampled as before (it was refused: "the glTF file
// ... does not exist").
TEST_F(App, SenseNeedsNoGltf) {
  fs::create_directories(dir_ / "scene");
  for (const char* f : {"multi_object.json", "multi_object.gltf", "multi_object.bin"})
    fs::copy_file(fs::path(kScenes) / f, dir_ / "scene" / f);
  const std::string settings = kLit.substr(kLit.find(" -q"));
  ASSERT_EQ(sh("run " + (dir_ / "scene/multi_object.json").string() + settings + " -o " + (dir_ / "run").string()).code, 0);
  fs::remove(dir_ / "scene/multi_object.gltf");
  fs::remove(dir_ / "scene/multi_object.bin");
  const Result r = sh("sense " + (dir_ / "run").string() + " -q -o " + (dir_ / "sense").string());
  ASSERT_EQ(r.code, 0) << r.output;
  expect_same_outputs(dir_ / "run", dir_ / "sense");
  // The run itself needs it.
  const Result again = sh("run " + (dir_ / "scene/multi_object.json").string() + settings + " -o " + (dir_ / "again").string());
  EXPECT_EQ(again.code, 1);
  EXPECT_THAT(again.output, HasSubstr("does not exist"));
}

// A new noise realisation of the run's own sensor: the files that do not depend on the noise are the
// run's, linked (one file system here), and the counts and frames are drawn anew. Another chip, or a
// sensor table whose contents changed since the run, makes sense compute and write them all again.
TEST_F(App, SenseLinksTheRunsNoiseFreeFilesOnlyForTheRunsOwnSensor) {
  const fs::path pdp = dir_ / "pdp.csv";
  const auto write_pdp = [&](double peak) {
    std::ofstream(pdp) << "wavelength_nm,pdp\n400," << peak << "\n1000," << peak << "\n";
  };
  write_pdp(0.1);
  ASSERT_EQ(sh("run " + kLit + " --set sensor.pixel_A.pdp_csv=" + pdp.string() + " -o " + (dir_ / "run").string()).code, 0);
  const auto linked = [&](const fs::path& d, const char* f) { return fs::equivalent(dir_ / "run" / f, d / f); };
  const char* noise_free[] = {"detection_rate.npy", "laser.exr", "ambient.exr", "sensor_maps.exr", "labels.exr",
                              "previews/intensity.png"};

  Result r = sh("sense " + (dir_ / "run").string() + " -q --noise-seed 11 -o " + (dir_ / "noise").string());
  ASSERT_EQ(r.code, 0) << r.output;
  for (const char* f : noise_free) EXPECT_TRUE(linked(dir_ / "noise", f)) << f;
  for (const char* f : {"counts.npy", "frames.npy"}) EXPECT_FALSE(linked(dir_ / "noise", f)) << f;
  ASSERT_EQ(sh("run " + kLit + " --set sensor.pixel_A.pdp_csv=" + pdp.string() + " --set seeds.noise=11 -o " +
               (dir_ / "run11").string()).code, 0);
  expect_same_outputs(dir_ / "run11", dir_ / "noise");

  r = sh("sense " + (dir_ / "run").string() + " -q --set seeds.chip=5 -o " + (dir_ / "chip").string());
  ASSERT_EQ(r.code, 0) << r.output;
  for (const char* f : {"detection_rate.npy", "sensor_maps.exr", "labels.exr"}) EXPECT_FALSE(linked(dir_ / "chip", f)) << f;
  EXPECT_NE(slurp(dir_ / "run/sensor_maps.exr"), slurp(dir_ / "chip/sensor_maps.exr"));

  write_pdp(0.2);  // the table the run read has changed: its rates are no longer this sensor's
  r = sh("sense " + (dir_ / "run").string() + " -q -o " + (dir_ / "table").string());
  ASSERT_EQ(r.code, 0) << r.output;
  for (const char* f : noise_free) EXPECT_FALSE(linked(dir_ / "table", f)) << f;
  const std::vector<double> was = values(read_npy(dir_ / "run/detection_rate.npy"));
  const std::vector<double> now = values(read_npy(dir_ / "table/detection_rate.npy"));
  ASSERT_EQ(was.size(), now.size());
  size_t higher = 0;
  for (size_t i = 0; i < was.size(); ++i) higher += now[i] > was[i];
  EXPECT_GT(higher, was.size() / 2);  // twice the PDP: more avalanches wherever light arrives
  // said on stderr (-q keeps warnings) and kept in metadata.json's warnings (it was on stderr only), and not
  // carried into a sense of that sense, whose tables are its own
  EXPECT_THAT(r.output, HasSubstr("have changed on disk since the run"));
  const auto warned = [](const fs::path& d) {
    return nlohmann::json::parse(slurp(d / "metadata.json")).at("warnings").dump().find("have changed on disk") != std::string::npos;
  };
  EXPECT_TRUE(warned(dir_ / "table"));
  ASSERT_EQ(sh("sense " + (dir_ / "table").string() + " -q --noise-seed 3 -o " + (dir_ / "table2").string()).code, 0);
  EXPECT_FALSE(warned(dir_ / "table2"));

  // The disk a sense needs: the files linked from the run take none, each further realisation writes its
  // counts and frames again (100,000 realisations of this run's frames: hundreds of GB, refused before
  // any work).
  write_pdp(0.1);  // the run's table again: the run's own sensor
  r = sh("sense " + (dir_ / "run").string() + " -q --repeats 100000 --set sensor.pixel_A.pdp_csv=" + pdp.string() +
         " -o " + (dir_ / "many").string());
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("frames.npy x 99999 more realisations (--repeats)"));
  // and the memory of the realisations sampled together, each with its counts and frames (8 with frames
  // peaked at 945 MB against 301 MB planned for one): both refusals said at once
  EXPECT_THAT(r.output, HasSubstr("the counts and frames of 100000 realisations (--repeats)) "));
  EXPECT_THAT(r.output, HasSubstr("; and it writes "));
  // Sense is named, and what it holds: no camera paths (it traces none), transient tiles rebuilt from the
  // saved light (the message had said "the run needs" and listed the renderer's paths).
  EXPECT_THAT(r.output, HasSubstr("spadgen: error: sense " + (dir_ / "run").string() + " needs about "));
  EXPECT_THAT(r.output, Not(HasSubstr("the run needs")));
  EXPECT_THAT(r.output, Not(HasSubstr("camera paths")));
  EXPECT_THAT(r.output, HasSubstr("transient tiles rebuilt from the saved light (render.tile_size_px"));
  EXPECT_THAT(r.output, Not(HasSubstr("detection_rate.npy")));  // the run's own sensor: linked
  EXPECT_FALSE(fs::exists(dir_ / "many"));
  // The files the realisations hold open, against the process's limit: refused up front, not on the
  // file that exceeds it with folders half made (ulimit -n 256: 100 realisations hold about 400, and the
  // process the 4 it has open and 5 to read the run). Under bash, the descriptors this test inherited closed
  // first (the child counts what it has open).
  const auto limited = [&](int limit, int repeats) {
    return shell("bash -c 'for fd in $(ls /proc/$$/fd); do [ $fd -gt 2 ] && eval \"exec $fd>&-\"; done; ulimit -n " +
                 std::to_string(limit) + " && exec " + kBin + " sense " + (dir_ / "run").string() + " -q --repeats " +
                 std::to_string(repeats) + " --set sensor.pixel_A.pdp_csv=" + pdp.string() + " -o " + (dir_ / "many").string() + "'");
  };
  r = limited(256, 100);
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("--repeats 100: the realisations hold about 400 files open"));
  EXPECT_THAT(r.output, HasSubstr("ask for at most 61 realisations per call"));  // (256 - 4 open - 5) / 4
  EXPECT_FALSE(fs::exists(dir_ / "many"));
  // A limit below what one realisation needs: said so (not "ask for at most 1 realisations").
  r = limited(11, 1);
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("and this process may open 11 (ulimit -n): raise the limit"));
  EXPECT_FALSE(fs::exists(dir_ / "many"));
}

// A sensor table moved since the run: a --set gives it in its new place (sense needed it where the run read
// it too, for the run's own scene), the same table by its contents, so the run's noise-free files are linked;
// without the --set the missing table is the run's mistake, named in its metadata.json.
TEST_F(App, SenseTakesATableMovedSinceTheRunFromSet) {
  fs::create_directories(dir_ / "was");
  fs::create_directories(dir_ / "now");
  std::ofstream(dir_ / "was/pdp.csv") << "wavelength_nm,pdp\n400,0.1\n1000,0.1\n";
  Result r = sh("run " + kLit + " --set sensor.pixel_A.pdp_csv=" + (dir_ / "was/pdp.csv").string() + " -o " + (dir_ / "run").string());
  ASSERT_EQ(r.code, 0) << r.output;
  fs::rename(dir_ / "was/pdp.csv", dir_ / "now/pdp.csv");
  r = sh("sense " + (dir_ / "run").string() + " -q -o " + (dir_ / "missing").string());
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr((dir_ / "run/metadata.json").string() + ": resolved_scene"));
  EXPECT_THAT(r.output, HasSubstr((dir_ / "was/pdp.csv").string() + " does not exist"));
  r = sh("sense " + (dir_ / "run").string() + " -q --noise-seed 11 --set sensor.pixel_A.pdp_csv=" + (dir_ / "now/pdp.csv").string() +
         " -o " + (dir_ / "moved").string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, Not(HasSubstr("have changed on disk")));
  for (const char* f : {"detection_rate.npy", "sensor_maps.exr", "labels.exr"})
    EXPECT_TRUE(fs::equivalent(dir_ / "run" / f, dir_ / "moved" / f)) << f;
  // description is free text: taken, the same sensor (it was refused as a key that "shapes the rendered light")
  r = sh("sense " + (dir_ / "run").string() + " -q --set description=resampled --set sensor.pixel_A.pdp_csv=" +
         (dir_ / "now/pdp.csv").string() + " -o " + (dir_ / "described").string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_TRUE(fs::equivalent(dir_ / "run/detection_rate.npy", dir_ / "described/detection_rate.npy"));
  EXPECT_THAT(slurp(dir_ / "described/metadata.json"), HasSubstr("\"description\": \"resampled\""));

  // Two tables (pixel A's and B's PDP). Both moved, one given anew: the other is named, not the one given.
  const auto pdp = [](const fs::path& p, double v) { std::ofstream(p) << "wavelength_nm,pdp\n400," << v << "\n1000," << v << "\n"; };
  pdp(dir_ / "was/a.csv", 0.1);
  pdp(dir_ / "was/b.csv", 0.2);
  const std::string tables = " --set sensor.pixel_A.pdp_csv=" + (dir_ / "was/a.csv").string() + " --set sensor.pixel_B.pdp_csv=" +
                             (dir_ / "was/b.csv").string();
  r = sh("run " + kLit + tables + " -o " + (dir_ / "two").string());
  ASSERT_EQ(r.code, 0) << r.output;
  fs::rename(dir_ / "was/a.csv", dir_ / "now/a.csv");
  fs::rename(dir_ / "was/b.csv", dir_ / "now/b.csv");
  const std::string a_anew = " --set sensor.pixel_A.pdp_csv=" + (dir_ / "now/a.csv").string();
  r = sh("sense " + (dir_ / "two").string() + " -q" + a_anew + " -o " + (dir_ / "one_given").string());
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr((dir_ / "was/b.csv").string() + " does not exist"));
  EXPECT_THAT(r.output, Not(HasSubstr((dir_ / "was/a.csv").string())));
  // A given anew, B back where the run read it but changed: B is said to have changed (it was not: one flag
  // for all the tables, A's gone)
  pdp(dir_ / "was/b.csv", 0.3);
  r = sh("sense " + (dir_ / "two").string() + " -q" + a_anew + " -o " + (dir_ / "b_changed").string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("the sensor's tables (sensor.pixel_B.pdp_csv) have changed on disk since the run"));
  // Both given anew (B of other contents): this call reads none of the run's, so nothing changed under it
  // (it said the run's had changed, B being changed where the run read it)
  pdp(dir_ / "now/b.csv", 0.4);
  r = sh("sense " + (dir_ / "two").string() + " -q" + a_anew + " --set sensor.pixel_B.pdp_csv=" + (dir_ / "now/b.csv").string() +
         " -o " + (dir_ / "both_given").string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, Not(HasSubstr("have changed on disk")));

  // The laser's pulse table (the sensor convolves with it; it sized the window the run rendered): given moved,
  // it is taken (it was refused as a key that "shapes the rendered light", the docs saying a --set gives a
  // moved table); another pulse is refused naming both contents' hashes.
  std::ofstream(dir_ / "was/pulse.csv") << "time_ps,power\n-100,0\n0,1\n100,0\n";
  r = sh("run " + kLit + " --set laser.pulse_shape_csv=" + (dir_ / "was/pulse.csv").string() + " -o " + (dir_ / "pulsed").string());
  ASSERT_EQ(r.code, 0) << r.output;
  fs::rename(dir_ / "was/pulse.csv", dir_ / "now/pulse.csv");
  r = sh("sense " + (dir_ / "pulsed").string() + " -q --set laser.pulse_shape_csv=" + (dir_ / "now/pulse.csv").string() + " -o " +
         (dir_ / "pulse_moved").string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, Not(HasSubstr("have changed on disk")));
  for (const char* f : {"detection_rate.npy", "counts.npy"})
    EXPECT_TRUE(slurp(dir_ / "pulsed" / f) == slurp(dir_ / "pulse_moved" / f)) << f;
  std::ofstream(dir_ / "now/other.csv") << "time_ps,power\n-200,0\n0,1\n200,0\n";
  r = sh("sense " + (dir_ / "pulsed").string() + " -q --set laser.pulse_shape_csv=" + (dir_ / "now/other.csv").string() + " -o " +
         (dir_ / "pulse_other").string());
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("--set laser.pulse_shape_csv: " + (dir_ / "now/other.csv").string() +
                                  " is not the pulse the run rendered with (its contents hash to "));
  EXPECT_THAT(r.output, HasSubstr("so sense takes the run's table moved, not another: use spadgen run for another pulse"));
  EXPECT_FALSE(fs::exists(dir_ / "pulse_other"));
}

// A run stored as Zarr: sense reads its light from the Zarr stores and writes what the run wrote, bit for
// bit; asked for .npy stacks, it writes the .npy run's files.
TEST_F(App, SenseReadsAZarrRunsLightAndWritesEitherStorage) {
  ASSERT_EQ(sh("run " + kLit + " --set outputs.storage=zarr -o " + (dir_ / "run").string()).code, 0);
  ASSERT_EQ(sh("run " + kLit + " -o " + (dir_ / "npy").string()).code, 0);
  Result r = sh("sense " + (dir_ / "run").string() + " -q -o " + (dir_ / "sense").string());
  ASSERT_EQ(r.code, 0) << r.output;
  expect_same_outputs(dir_ / "run", dir_ / "sense");
  r = sh("sense " + (dir_ / "run").string() + " -q --set outputs.storage=npy -o " + (dir_ / "sense_npy").string());
  ASSERT_EQ(r.code, 0) << r.output;
  for (const char* f : {"counts.npy", "detection_rate.npy", "frames.npy", "laser.exr", "sensor_maps.exr"})
    EXPECT_TRUE(slurp(dir_ / "npy" / f) == slurp(dir_ / "sense_npy" / f)) << f;
  // The light and the transients are the run's Zarr stores, linked.
  const auto meta = nlohmann::json::parse(slurp(dir_ / "sense_npy/metadata.json"));
  EXPECT_EQ(meta["storage"]["files"]["light/values.zarr"]["format"], "zarr");
  EXPECT_EQ(meta["storage"]["files"]["counts.npy"]["format"], "npy");
  EXPECT_TRUE(slurp(dir_ / "run/transient.zarr/0.0.0") == slurp(dir_ / "sense_npy/transient.zarr/0.0.0"));
  // ... so the folder is a Zarr group of them, as the run's is (it had light/.zgroup only)
  EXPECT_EQ(slurp(dir_ / "sense_npy/.zgroup"), slurp(dir_ / "run/.zgroup"));
  EXPECT_NE(std::find(meta["files"].begin(), meta["files"].end(), ".zgroup"), meta["files"].end());
  // A sense of that sense reads the light in the format it is stored in (Zarr), not the folder's own stacks'
  // (.npy): the same files again; and the other way, a .npy run's light in a folder of Zarr stacks.
  r = sh("sense " + (dir_ / "sense_npy").string() + " -q -o " + (dir_ / "again").string());
  ASSERT_EQ(r.code, 0) << r.output;
  for (const char* f : {"counts.npy", "detection_rate.npy", "frames.npy"})
    EXPECT_TRUE(slurp(dir_ / "npy" / f) == slurp(dir_ / "again" / f)) << f;
  r = sh("sense " + (dir_ / "npy").string() + " -q --set outputs.storage=zarr -o " + (dir_ / "sense_zarr").string());
  ASSERT_EQ(r.code, 0) << r.output;
  r = sh("sense " + (dir_ / "sense_zarr").string() + " -q --set outputs.storage=npy -o " + (dir_ / "back").string());
  ASSERT_EQ(r.code, 0) << r.output;
  for (const char* f : {"counts.npy", "detection_rate.npy", "frames.npy"})
    EXPECT_TRUE(slurp(dir_ / "npy" / f) == slurp(dir_ / "back" / f)) << f;
}

// The dataset sample docs/outputs.md recommends (Zarr, the saved light, no detection rate) gives the
// detection rate back through sense, bit for bit the one a run writes.
TEST_F(App, TheRecommendedSampleGivesTheDetectionRateBackBitForBit) {
  ASSERT_EQ(sh("run " + kSmall + " -o " + (dir_ / "run").string()).code, 0);
  ASSERT_EQ(sh("run " + kSmall + " --set outputs.storage=zarr --set outputs.light=true --set outputs.detection_rate=false -o " +
               (dir_ / "sample").string()).code, 0);
  EXPECT_FALSE(fs::exists(dir_ / "sample/detection_rate.zarr"));
  const Result r = sh("sense " + (dir_ / "sample").string() + " -q --set outputs.detection_rate=true --set outputs.counts=false "
                      "--set outputs.storage=npy -o " + (dir_ / "rates").string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_TRUE(slurp(dir_ / "run/detection_rate.npy") == slurp(dir_ / "rates/detection_rate.npy"));
  EXPECT_FALSE(fs::exists(dir_ / "rates/counts.npy"));
}

// The light's ring around a crop lets sense switch crosstalk on although the run had it off, and the
// result is what a run with crosstalk writes; the same for another gate step and frame count.
TEST_F(App, SenseWithOtherSensorSettingsWritesWhatARunWithThemWrites) {
  const std::string base = kLit + " --set sensor.crosstalk=false";
  ASSERT_EQ(sh("run " + base + " -o " + (dir_ / "run").string()).code, 0);
  for (const std::string& change : {std::string("--set sensor.crosstalk=true"),
                                    std::string("--set acquisition.gate_sweep.step_ps=72 --set acquisition.frames=100 "
                                                "--set seeds.chip=4")}) {
    SCOPED_TRACE(change);
    fs::remove_all(dir_ / "other"), fs::remove_all(dir_ / "sensed");
    ASSERT_EQ(sh("run " + base + " " + change + " -o " + (dir_ / "other").string()).code, 0);
    const Result r = sh("sense " + (dir_ / "run").string() + " -q " + change + " -o " + (dir_ / "sensed").string());
    ASSERT_EQ(r.code, 0) << r.output;
    expect_same_outputs(dir_ / "other", dir_ / "sensed");
  }
}

// Another pixel design has another fill factor, which the renderer applied: sense rescales the saved
// light row by row. The result is a run with that design up to the float32 rounding of the rescaling.
TEST_F(App, SenseWithAnotherPixelDesignRescalesTheLight) {
  ASSERT_EQ(sh("run " + kLit + " -o " + (dir_ / "run").string()).code, 0);
  const std::string change = " --set sensor.preset=pixel_B";
  ASSERT_EQ(sh("run " + kLit + change + " -o " + (dir_ / "other").string()).code, 0);
  const Result r = sh("sense " + (dir_ / "run").string() + " -q" + change + " -o " + (dir_ / "sensed").string());
  ASSERT_EQ(r.code, 0) << r.output;
  const std::vector<double> want = values(read_npy(dir_ / "other/detection_rate.npy"));
  const std::vector<double> got = values(read_npy(dir_ / "sensed/detection_rate.npy"));
  ASSERT_EQ(want.size(), got.size());
  for (size_t i = 0; i < want.size(); ++i) ASSERT_NEAR(got[i], want[i], 1e-6 * want[i] + 1e-30) << i;
  const std::vector<double> cw = values(read_npy(dir_ / "other/counts.npy")), cg = values(read_npy(dir_ / "sensed/counts.npy"));
  size_t same = 0;
  for (size_t i = 0; i < cw.size(); ++i) same += cw[i] == cg[i];
  // The same noise draws against probabilities 1e-7 apart: a count differs when a draw falls between.
  EXPECT_GE(double(same), 0.999 * double(cw.size()));
  const auto lw = spadgen::writers::read_exr((dir_ / "other/laser.exr").string());
  const auto lg = spadgen::writers::read_exr((dir_ / "sensed/laser.exr").string());
  const auto& a = lw.channels.at("photons_per_pulse");
  const auto& b = lg.channels.at("photons_per_pulse");
  for (size_t i = 0; i < a.size(); ++i) ASSERT_NEAR(b[i], a[i], 1e-6 * a[i]) << i;
  // The files of photons it keeps from the run are the design's too (they were linked at the run's:
  // labels from them were half a run's), and the labels computed from them.
  const auto near_all = [&](const fs::path& want_file, const fs::path& got_file, const std::vector<std::string>& channels) {
    const auto w = spadgen::writers::read_exr(want_file.string()), g = spadgen::writers::read_exr(got_file.string());
    for (const std::string& c : channels) {
      SCOPED_TRACE(want_file.filename().string() + " " + c);
      const auto &x = w.channels.at(c), &y = g.channels.at(c);
      ASSERT_EQ(x.size(), y.size());
      for (size_t i = 0; i < x.size(); ++i) ASSERT_NEAR(y[i], x[i], 1e-6 * std::fabs(x[i]) + 1e-30) << i;
    }
  };
  near_all(dir_ / "other/ground_truth.exr", dir_ / "sensed/ground_truth.exr",
           {"object0.laser", "direct_other_laser", "indirect_laser", "range", "object0.path"});
  near_all(dir_ / "other/labels.exr", dir_ / "sensed/labels.exr", {"object0.edge_counts", "object0.detectable"});
  const std::vector<double> tw = values(read_npy(dir_ / "other/transient.npy")), tg = values(read_npy(dir_ / "sensed/transient.npy"));
  ASSERT_EQ(tw.size(), tg.size());
  for (size_t i = 0; i < tw.size(); ++i) ASSERT_NEAR(tg[i], tw[i], 1e-6 * tw[i] + 1e-30) << i;
  // A sense of that sense back to the run's design reads the light as it was saved: the run's rates, exactly.
  ASSERT_EQ(sh("sense " + (dir_ / "sensed").string() + " -q --set sensor.preset=pixel_A -o " + (dir_ / "back").string()).code, 0);
  EXPECT_EQ(slurp(dir_ / "run/detection_rate.npy"), slurp(dir_ / "back/detection_rate.npy"));
  near_all(dir_ / "run/ground_truth.exr", dir_ / "back/ground_truth.exr", {"object0.laser", "indirect_laser"});
}

// Rates so small they are float denormals (a PDP of 1e-36): the run's sensor stage flushed them to 0 on
// the threads Embree had set up, a sense (no Embree) kept them; every command flushes them now.
TEST_F(App, SenseFlushesDenormalsAsTheRunDoes) {
  const std::string dim = " --set sensor.pixel_A.pdp_peak=1e-36 --set sensor.dark_counts=false --set sensor.crosstalk=false";
  ASSERT_EQ(sh("run " + kLit + " -o " + (dir_ / "run").string()).code, 0);
  ASSERT_EQ(sh("run " + kLit + dim + " -o " + (dir_ / "dim").string()).code, 0);
  const Result r = sh("sense " + (dir_ / "run").string() + " -q" + dim + " -o " + (dir_ / "sensed").string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(slurp(dir_ / "dim/detection_rate.npy"), slurp(dir_ / "sensed/detection_rate.npy"));
  // ... flushed, both: TBB's tasks run with the settings of the thread that started TBB, which the run once
  // left without them in some settings (outputs.frames off) and not in others
  size_t nonzero = 0;
  for (const double v : values(read_npy(dir_ / "sensed/detection_rate.npy"))) {
    ASSERT_TRUE(v == 0.0 || std::fabs(v) >= double(std::numeric_limits<float>::min())) << v;
    nonzero += v != 0.0;
  }
  EXPECT_GT(nonzero, 0u);
  ASSERT_EQ(sh("run " + kLit + dim + " --set outputs.frames=false -o " + (dir_ / "dim2").string()).code, 0);
  for (const double v : values(read_npy(dir_ / "dim2/detection_rate.npy")))
    ASSERT_TRUE(v == 0.0 || std::fabs(v) >= double(std::numeric_limits<float>::min())) << v;
}

// What a sense keeps from the run follows its own settings: an intensity-mode sense of a gate sweep writes
// no labels and its summary says nothing of them (it kept the run's); without previews it links none; a seed
// given twice is refused (the option silently won).
TEST_F(App, SenseKeepsOnlyWhatItsSettingsAskFor) {
  ASSERT_EQ(sh("run " + kLit + " --set outputs.transient=false -o " + (dir_ / "run").string()).code, 0);
  const std::string sense = "sense " + (dir_ / "run").string() + " -q ";
  ASSERT_EQ(sh(sense + "--set acquisition.mode=intensity -o " + (dir_ / "int").string()).code, 0);
  const auto meta = nlohmann::json::parse(slurp(dir_ / "int/metadata.json"));
  EXPECT_FALSE(fs::exists(dir_ / "int/labels.exr"));
  EXPECT_TRUE(meta["ground_truth_summary"].contains("hit_fraction"));
  EXPECT_FALSE(meta["ground_truth_summary"].contains("objects_detectable"));
  EXPECT_FALSE(meta["ground_truth_summary"].contains("detectable_fraction"));
  // The saved light holds the laser's (outputs.light has the run trace it): a 2D sense without laser_on still
  // writes laser.exr and its figures (it wrote none, and listed the laser light as skipped).
  EXPECT_TRUE(fs::exists(dir_ / "int/laser.exr"));
  EXPECT_GT(meta.at("laser_photons_per_pulse").at("total_all_pixels").get<double>(), 0.0);
  EXPECT_FALSE(meta.at("accuracy").at("laser_relative_standard_error").is_null());
  for (const auto& e : meta.at("model")) {
    if (e.at("component") == "laser light") {
      EXPECT_TRUE(e.at("active").get<bool>()) << e;
    }
  }
  // A run that kept its transients too: its transient.npy is linked, whatever the mode (sense refused it
  // as "intensity mode needs no time bins", naming keys sense does not take), and the 2D rates are the same.
  ASSERT_EQ(sh("run " + kLit + " --set outputs.transient=true -o " + (dir_ / "run_t").string()).code, 0);
  Result t = sh("sense " + (dir_ / "run_t").string() + " -q --set acquisition.mode=intensity -o " + (dir_ / "int_t").string());
  ASSERT_EQ(t.code, 0) << t.output;
  EXPECT_EQ(slurp(dir_ / "int_t/detection_rate.npy"), slurp(dir_ / "int/detection_rate.npy"));
  EXPECT_EQ(slurp(dir_ / "int_t/transient.npy"), slurp(dir_ / "run_t/transient.npy"));
  ASSERT_EQ(sh(sense + "--set outputs.previews=false -o " + (dir_ / "np").string()).code, 0);
  EXPECT_FALSE(fs::exists(dir_ / "np/previews"));
  const Result r = sh(sense + "--noise-seed 30 --set seeds.noise=31 -o " + (dir_ / "two").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("--set seeds.noise and --noise-seed both give the seed"));
  // also when the key is written with quotes (the option won silently: the keys were compared as written)
  const Result quoted = sh(sense + "--noise-seed 30 --set '\"seeds\".\"noise\"=31' -o " + (dir_ / "two").string());
  EXPECT_EQ(quoted.code, 1);
  EXPECT_THAT(quoted.output, HasSubstr("--set seeds.noise and --noise-seed both give the seed"));
  // A bad value names the --set that gave it, not the run's scene file (which sense does not read)
  const Result bad = sh(sense + "--set acquisition.frames=0 -o " + (dir_ / "bad").string());
  EXPECT_EQ(bad.code, 1);
  EXPECT_THAT(bad.output, HasSubstr("spadgen: error: --set acquisition.frames: found 0"));
  EXPECT_FALSE(fs::exists(dir_ / "bad"));
}

// An intensity run without laser_on keeps in its saved light what its counts see: it traces no laser for it (a
// dataset's 2D samples with repeats traced the laser for 40 % of their rays, and wrote laser images no one
// reads), its counts are those of the run without the light, and its sense in the intensity mode writes what
// the run wrote; a sense that images the laser (laser_on) is refused, naming what the light lacks.
TEST_F(App, AnIntensityRunsSavedLightHoldsNoLaser) {
  const std::string chart = "run " + kScenes + "test_chart.json -q --set camera.crop=[500,500,16,8] --set render.samples_per_pixel=2 ";
  ASSERT_EQ(sh(chart + "--set outputs.light=true -o " + (dir_ / "run").string()).code, 0);
  ASSERT_EQ(sh(chart + "-o " + (dir_ / "bare").string()).code, 0);
  const auto meta = nlohmann::json::parse(slurp(dir_ / "run/metadata.json"));
  EXPECT_EQ(meta.at("run").at("rays").at("laser"), 0);
  EXPECT_TRUE(meta.at("laser_photons_per_pulse").is_null());
  EXPECT_FALSE(fs::exists(dir_ / "run/laser.exr"));
  for (const char* f : {"counts.npy", "detection_rate.npy", "ambient.exr", "intensity.exr", "ground_truth.exr"})
    EXPECT_EQ(slurp(dir_ / "run" / f), slurp(dir_ / "bare" / f)) << f;
  for (const auto& e : meta.at("model"))
    if (e.at("component") == "laser light") {
      EXPECT_FALSE(e.at("active").get<bool>()) << e;
      EXPECT_THAT(e.at("why").get<std::string>(), HasSubstr("the saved light holds none"));
    }
  const Result r = sh("sense " + (dir_ / "run").string() + " -q -o " + (dir_ / "sense").string());
  ASSERT_EQ(r.code, 0) << r.output;
  expect_same_outputs(dir_ / "run", dir_ / "sense");
  EXPECT_FALSE(fs::exists(dir_ / "sense/laser.exr"));
  const Result on = sh("sense " + (dir_ / "run").string() + " -q --set acquisition.intensity.laser_on=true -o " + (dir_ / "on").string());
  EXPECT_EQ(on.code, 1);
  EXPECT_THAT(on.output, HasSubstr((dir_ / "run").string() + ": the run traced no laser (the intensity mode without "
                                   "acquisition.intensity.laser_on), so its saved light holds none, and "
                                   "acquisition.intensity.laser_on images the laser's light; run the scene again"));
  EXPECT_FALSE(fs::exists(dir_ / "on"));
  // With a time window the light keeps the laser's, for a later sense as a gate sweep.
  ASSERT_EQ(sh(chart + "--set outputs.light=true --set render.window_start_ns=0 --set render.window_stop_ns=20 -o " +
               (dir_ / "windowed").string()).code, 0);
  EXPECT_GT(nlohmann::json::parse(slurp(dir_ / "windowed/metadata.json")).at("run").at("rays").at("laser").get<int64_t>(), 0);
  EXPECT_TRUE(fs::exists(dir_ / "windowed/laser.exr"));
}

// A sense holds the run folder's lock, shared: while a run replaces the folder (its lock exclusive) a
// sense refuses rather than read light of one run and link files of the next; senses of one run share it.
TEST_F(App, SenseRefusesARunFolderBeingReplaced) {
  ASSERT_EQ(sh("run " + kLit + " -o " + (dir_ / "run").string()).code, 0);
  const std::string lock = (dir_ / ".run.spadgen-lock").string();
  const int fd = ::open(lock.c_str(), O_RDWR | O_CREAT, 0644);
  ASSERT_GE(fd, 0);
  ASSERT_EQ(::flock(fd, LOCK_EX | LOCK_NB), 0);
  Result r = sh("sense " + (dir_ / "run").string() + " -q -o " + (dir_ / "s1").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("the run folder " + (dir_ / "run").string() + " is being written, or may be written into, by another spadgen process"));
  EXPECT_FALSE(fs::exists(dir_ / "s1"));
  // Another reader's shared lock does not stop it.
  ASSERT_EQ(::flock(fd, LOCK_SH | LOCK_NB), 0);
  r = sh("sense " + (dir_ / "run").string() + " -q -o " + (dir_ / "s1").string());
  EXPECT_EQ(r.code, 0) << r.output;
  // ... and the sense leaves the lock file to the reader still holding it
  EXPECT_TRUE(fs::exists(lock));
  ::close(fd);
  // The last reader removes it (every sense left one beside the run folder).
  r = sh("sense " + (dir_ / "run").string() + " -q -o " + (dir_ / "s2").string());
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_FALSE(fs::exists(lock));
  r = sh("sense " + (dir_ / "run").string() + " -q --set acquisition.frames=0 -o " + (dir_ / "s3").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_FALSE(fs::exists(lock)) << "nor after an error";
}

// Realisation r of --repeats R with --noise-seed S is the run with seeds.noise = S + r: same files (the
// counts and frames differ from one realisation to the next, the rates do not).
TEST_F(App, SenseRepeatsAreTheRunsWithConsecutiveNoiseSeeds) {
  ASSERT_EQ(sh("run " + kLit + " -o " + (dir_ / "run").string()).code, 0);
  const Result r = sh("sense " + (dir_ / "run").string() + " -q --noise-seed 7 --repeats 3 -o " + (dir_ / "rep").string());
  ASSERT_EQ(r.code, 0) << r.output;
  ASSERT_EQ(sh("run " + kLit + " --set seeds.noise=9 -o " + (dir_ / "seed9").string()).code, 0);
  expect_same_outputs(dir_ / "seed9", dir_ / "rep/repeat_002");
  EXPECT_EQ(slurp(dir_ / "rep/repeat_000/detection_rate.npy"), slurp(dir_ / "rep/repeat_001/detection_rate.npy"));
  // What does not depend on the noise is written once and linked (one file system here).
  for (const char* f : {"detection_rate.npy", "laser.exr", "sensor_maps.exr", "previews/intensity.png"})
    EXPECT_TRUE(fs::equivalent(dir_ / "rep/repeat_000" / f, dir_ / "rep/repeat_002" / f)) << f;
  EXPECT_NE(slurp(dir_ / "rep/repeat_000/counts.npy"), slurp(dir_ / "rep/repeat_001/counts.npy"));
  EXPECT_NE(slurp(dir_ / "rep/repeat_000/frames.npy"), slurp(dir_ / "rep/repeat_001/frames.npy"));
  const auto meta = nlohmann::json::parse(slurp(dir_ / "rep/repeat_001/metadata.json"));
  EXPECT_EQ(meta["seeds"]["noise"], 8);
  EXPECT_EQ(meta["sense"]["repeat"], 1);
  // The scene is resolved once and each realisation takes its seed (the last is resolved in full): the
  // resolved scenes differ in seeds.noise alone, in the same key order.
  auto last = nlohmann::ordered_json::parse(slurp(dir_ / "rep/repeat_002/metadata.json"))["resolved_scene"];
  const auto middle = nlohmann::ordered_json::parse(slurp(dir_ / "rep/repeat_001/metadata.json"))["resolved_scene"];
  EXPECT_EQ(last["seeds"]["noise"], 9);
  last["seeds"]["noise"] = 8;
  EXPECT_EQ(last.dump(), middle.dump());
  // The realisations are one folder, replaced whole: two realisations into it leave no third from before
  // (repeat_002 stayed beside the new ones, with the old seed), ...
  const Result two = sh("sense " + (dir_ / "run").string() + " -q --noise-seed 20 --repeats 2 -o " + (dir_ / "rep").string());
  ASSERT_EQ(two.code, 0) << two.output;
  std::set<std::string> folders;
  for (const auto& e : fs::directory_iterator(dir_ / "rep")) folders.insert(e.path().filename().string());
  EXPECT_EQ(folders, (std::set<std::string>{"repeat_000", "repeat_001"}));
  EXPECT_EQ(nlohmann::json::parse(slurp(dir_ / "rep/repeat_001/metadata.json"))["seeds"]["noise"], 21);
  // ... and a folder with other files in it is not replaced
  std::ofstream(dir_ / "rep/notes.txt") << "mine";
  const Result foreign = sh("sense " + (dir_ / "run").string() + " -q --repeats 2 -o " + (dir_ / "rep").string());
  EXPECT_EQ(foreign.code, 1);
  EXPECT_THAT(foreign.output, HasSubstr("holds files that spadgen did not write there (notes.txt"));
  EXPECT_TRUE(fs::exists(dir_ / "rep/repeat_001/counts.npy"));
  // Seeds past the key's range: said in terms of --noise-seed and --repeats (it named a --set the user
  // never gave, with a seed they never wrote)
  const Result past = sh("sense " + (dir_ / "run").string() + " -q --noise-seed 9007199254740992 --repeats 2 -o " +
                         (dir_ / "past").string());
  EXPECT_EQ(past.code, 1);
  EXPECT_THAT(past.output, HasSubstr("spadgen: error: --repeats 2: the realisations' noise seeds would run from "
                                     "9007199254740992 (--noise-seed) to 9007199254740993; expected seeds of at most "
                                     "9007199254740992: a smaller first seed or fewer repeats\n"));
  EXPECT_THAT(past.output, Not(HasSubstr("seeds.noise:")));
  EXPECT_FALSE(fs::exists(dir_ / "past"));
}

// A sense of one realisation and one of several (--repeats, a folder of repeat_NNN run folders) replace
// each other in one output folder (each refused the other's files as "not written by spadgen"); a run folder
// of another name inside stays someone's.
TEST_F(App, OneRealisationAndSeveralReplaceEachOther) {
  ASSERT_EQ(sh("run " + kLit + " -o " + (dir_ / "run").string()).code, 0);
  const std::string sense = "sense " + (dir_ / "run").string() + " -q -o " + (dir_ / "s").string();
  ASSERT_EQ(sh(sense + " --repeats 2").code, 0);
  Result r = sh(sense);
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_TRUE(fs::exists(dir_ / "s/metadata.json"));
  EXPECT_FALSE(fs::exists(dir_ / "s/repeat_000"));
  r = sh(sense + " --repeats 2");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_TRUE(fs::exists(dir_ / "s/repeat_001/metadata.json"));
  EXPECT_FALSE(fs::exists(dir_ / "s/metadata.json"));
  // A user's file inside a realisation's folder is not spadgen's (it was removed with the folder).
  std::ofstream(dir_ / "s/repeat_000/notes.txt") << "mine";
  for (const std::string& call : {sense, sense + " --repeats 2"}) {
    r = sh(call);
    EXPECT_EQ(r.code, 1) << call;
    EXPECT_THAT(r.output, HasSubstr("holds files that spadgen did not write there (repeat_000/notes.txt")) << call;
    EXPECT_TRUE(fs::exists(dir_ / "s/repeat_000/notes.txt"));
  }
  fs::remove(dir_ / "s/repeat_000/notes.txt");
  fs::copy(dir_ / "run", dir_ / "s/mine", fs::copy_options::recursive);
  r = sh(sense);
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("holds files that spadgen did not write there (mine/"));
  // Neither is a folder of runs of other names, for realisations (they removed every run folder in it).
  r = sh(sense + " --repeats 2");
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("holds files that spadgen did not write there (mine/"));
  EXPECT_TRUE(fs::exists(dir_ / "s/mine/metadata.json"));
}

// A realisation's folder is part of its set: a sense into repeat_001 of a set (it mixed two calls in one
// set, exit 0), and a sense of repeat_001 into the set's folder (its swap removed the run it read, exit 0),
// are refused; so are realisations that would hold the same files (no counts, no frames), and a folder
// inside one another spadgen process is writing (its swap replaced this one's files when it ended).
TEST_F(App, SenseKeepsARealisationSetWhole) {
  ASSERT_EQ(sh("run " + kLit + " -o " + (dir_ / "run").string()).code, 0);
  ASSERT_EQ(sh("sense " + (dir_ / "run").string() + " -q --repeats 2 -o " + (dir_ / "set").string()).code, 0);
  const std::string before = slurp(dir_ / "set/repeat_001/counts.npy");
  Result r = sh("sense " + (dir_ / "run").string() + " -q --noise-seed 77 -o " + (dir_ / "set/repeat_001").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("it lies in " + fs::canonical(dir_ / "set").string() +
                                  ", the 2 realisations that one `spadgen sense --repeats` wrote together"));
  for (const char* o : {"set/repeat_001", "set/repeat_002"}) {
    r = sh("run " + kLit + " -o " + (dir_ / o).string());
    EXPECT_EQ(r.code, 1) << o;
    EXPECT_THAT(r.output, HasSubstr("the 2 realisations that one `spadgen sense --repeats` wrote together")) << o;
  }
  EXPECT_FALSE(fs::exists(dir_ / "set/repeat_002"));
  r = sh("sense " + (dir_ / "set/repeat_001").string() + " -q -o " + (dir_ / "set").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("it holds the run " + fs::canonical(dir_ / "set/repeat_001").string() + ", which sense reads"));
  EXPECT_EQ(slurp(dir_ / "set/repeat_001/counts.npy"), before);
  EXPECT_TRUE(fs::exists(dir_ / "set/repeat_000/metadata.json"));
  // a set's realisation can still be read: sensed beside the set
  EXPECT_EQ(sh("sense " + (dir_ / "set/repeat_001").string() + " -q -o " + (dir_ / "again").string()).code, 0);

  // a set's realisation sensed without -o: beside the set (it went inside it, set/repeat_000-sense, and the
  // set could not be written again)
  ASSERT_EQ(sh("sense " + (dir_ / "set/repeat_000").string() + " -q --noise-seed 9").code, 0);
  EXPECT_TRUE(fs::exists(dir_ / "set-repeat_000-sense/counts.npy"));
  EXPECT_FALSE(fs::exists(dir_ / "set/repeat_000-sense"));
  // any folder in the set is refused (a sense --repeats into set/repeat_001 wrote a set inside the set), and
  // the set can be written again whole
  for (const std::string extra : {"", " --repeats 2"}) {
    r = sh("sense " + (dir_ / "run").string() + " -q" + extra + " -o " + (dir_ / "set/repeat_001").string());
    EXPECT_EQ(r.code, 1) << extra;
    EXPECT_THAT(r.output, HasSubstr("the 2 realisations that one `spadgen sense --repeats` wrote together")) << extra;
  }
  r = sh("sense " + (dir_ / "run").string() + " -q -o " + (dir_ / "set/mine").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_FALSE(fs::exists(dir_ / "set/mine"));
  EXPECT_EQ(sh("sense " + (dir_ / "run").string() + " -q --repeats 2 --noise-seed 5 -o " + (dir_ / "set").string()).code, 0);

  // realisations without counts, frames or previews (of the counts) would be the same files
  r = sh("sense " + (dir_ / "run").string() + " -q --repeats 3 --set outputs.counts=false --set outputs.frames=false "
         "--set outputs.previews=false -o " + (dir_ / "same").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("--repeats 3: the realisations differ in their counts, frames and the previews of the counts only"));
  EXPECT_FALSE(fs::exists(dir_ / "same"));
  EXPECT_EQ(sh("sense " + (dir_ / "run").string() + " -q --repeats 2 --set outputs.counts=false --set outputs.frames=false -o " +
               (dir_ / "previews").string()).code, 0);

  // another process holding a folder as its output (its lock, as a sense --repeats holds its set's): a run
  // folder inside it is refused while it writes
  fs::create_directories(dir_ / "new_set");
  const fs::path lock = dir_ / ".new_set.spadgen-lock";
  const int fd = ::open(lock.c_str(), O_RDWR | O_CREAT, 0644);
  ASSERT_GE(fd, 0);
  ASSERT_EQ(::flock(fd, LOCK_EX), 0);
  ASSERT_EQ(::pwrite(fd, "pid 4242\n", 9, 0), 9);
  r = sh("sense " + (dir_ / "run").string() + " -q -o " + (dir_ / "new_set/repeat_001").string());
  ::close(fd);
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("the folder holding it, " + fs::canonical(dir_ / "new_set").string() +
                                  ", is held by another spadgen process (pid 4242) that writes it"));
  EXPECT_FALSE(fs::exists(dir_ / "new_set/repeat_001"));
  // once it is gone, a folder inside is the user's to choose
  EXPECT_EQ(sh("sense " + (dir_ / "run").string() + " -q -o " + (dir_ / "new_set/repeat_001").string()).code, 0);

  // a reader of one realisation (reconstruct, evaluate: its lock, set/.repeat_001.spadgen-lock) keeps the set
  // from being replaced, by a set or a run (the set was replaced under a reconstruct, whose file was lost)
  const std::string counts = slurp(dir_ / "set/repeat_001/counts.npy");
  const fs::path reader = dir_ / "set/.repeat_001.spadgen-lock";
  const int held = ::open(reader.c_str(), O_RDWR | O_CREAT, 0644);
  ASSERT_GE(held, 0);
  ASSERT_EQ(::flock(held, LOCK_EX), 0);
  ASSERT_EQ(::pwrite(held, "pid 4343\n", 9, 0), 9);
  for (const std::string& cmd : {"sense " + (dir_ / "run").string() + " -q --repeats 2 --noise-seed 6 -o " + (dir_ / "set").string(),
                                 "run " + kLit + " -q -o " + (dir_ / "set").string()}) {
    r = sh(cmd);
    EXPECT_EQ(r.code, 1) << cmd << r.output;
    EXPECT_THAT(r.output, HasSubstr("the run folder " + fs::canonical(dir_ / "set").string() + "/repeat_001 is being written or read "
                                    "by another spadgen process (pid 4343)")) << cmd;
  }
  ::close(held);
  EXPECT_EQ(slurp(dir_ / "set/repeat_001/counts.npy"), counts);
  EXPECT_EQ(sh("sense " + (dir_ / "run").string() + " -q --repeats 2 --noise-seed 6 -o " + (dir_ / "set").string()).code, 0);
  EXPECT_FALSE(fs::exists(dir_ / "set/.repeat_001.spadgen-lock"));
}

// A cone beam whose spot is far smaller than a pixel (0.001 deg against a pixel's 0.01077 deg: 9.4 um at
// 50 mm) is found by chance by the camera paths: warned about before rendering, with the spot's size and
// the paths that land on it; a spot of a pixel or more, or one enough paths land on, is not.
TEST_F(App, AConeNarrowerThanAPixelIsWarnedAbout) {
  const std::string info = "info " + kScenes + "flat_target.json --set laser.beam=cone ";
  Result r = sh(info + "--set laser.half_angle_deg=0.001 --set render.samples_per_pixel=16");
  EXPECT_THAT(r.output, HasSubstr("warning: laser.half_angle_deg: a cone of 0.001 deg lights a spot of about 0.02708 pixels "
                                  "(a pixel spans 0.01077 deg)"));
  EXPECT_THAT(r.output, HasSubstr("about 0.4332 of its 16 paths"));  // 16 pi (0.001 / 0.01077)^2
  // 0.005 deg: 0.677 pixels, 10.8 of 16 paths (warned), 43 of 64 (not); 0.1 deg: 271 pixels
  EXPECT_THAT(sh(info + "--set laser.half_angle_deg=0.005 --set render.samples_per_pixel=16").output, HasSubstr("about 10.83 of its 16 paths"));
  EXPECT_THAT(sh(info + "--set laser.half_angle_deg=0.005 --set render.samples_per_pixel=64").output, Not(HasSubstr("lights a spot")));
  EXPECT_THAT(sh(info + "--set laser.half_angle_deg=0.1 --set render.samples_per_pixel=1").output, Not(HasSubstr("lights a spot")));
}

// The glTF's positions are measured from each mesh's centre (scenes::Mesh::offset) and the renderer's from
// the camera: a camera and scene 1e5 m from the origin are not warned about. A mesh whose own vertices lie
// 1024 m or more from its centre is, with the float spacing there (the target, its corners 2 m out, scaled by 3000:
// vertices 6000 m out, floats 0.49 mm apart).
TEST_F(App, AMeshWithCoarseVerticesIsWarnedAbout) {
  const std::string info = "info " + kScenes + "flat_target.json ";
  Result r = sh(info + "--set camera.position_m=[100000,0,1] --set camera.look_at_m=[100000,0,0] "
                       "--set nodes.target.translation_m=[100000,0,0]");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, Not(HasSubstr("floats are")));
  r = sh(info + "--set nodes.target.scale=[3000,3000,1]");
  EXPECT_THAT(r.output, HasSubstr("warning: the mesh 'target/target/0' has vertices 6000 m from its centre, where floats are "
                                  "0.4883 mm apart"));
  r = sh(info + "--set nodes.target.scale=[300,300,1]");  // 600 m
  EXPECT_THAT(r.output, Not(HasSubstr("floats are")));
}

// A laser the pixels cannot detect (1550 nm: beyond the built-in PDP curve) is warned about, naming the
// pixel type, by run, info and sense (once: sense replaces the run's sensor warnings with its own); the
// laser adds nothing to the detection rate.
TEST_F(App, ALaserThePixelsCannotDetectIsWarnedAbout) {
  const std::string warning = "warning: sensor.pixel_A: its photon detection probability at the laser's wavelength "
                              "(laser.wavelength_nm) is 0";
  Result r = sh("run " + kLit + " --set laser.wavelength_nm=1550 -o " + (dir_ / "blind").string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr(warning));
  r = sh("info " + kScenes + "flat_target.json --set laser.wavelength_nm=1550");
  EXPECT_THAT(r.output, HasSubstr(warning));
  r = sh("info " + kScenes + "flat_target.json");
  EXPECT_THAT(r.output, Not(HasSubstr("photon detection probability")));
  r = sh("sense " + (dir_ / "blind").string() + " -q -o " + (dir_ / "sensed").string());
  ASSERT_EQ(r.code, 0) << r.output;
  for (const char* d : {"blind", "sensed"}) {
    const nlohmann::json meta = nlohmann::json::parse(slurp(dir_ / d / "metadata.json"));
    int n = 0;
    for (const auto& w : meta["warnings"]) n += w.get<std::string>().find("photon detection probability") != std::string::npos;
    EXPECT_EQ(n, 1) << d << ": " << meta["warnings"].dump();
  }
  // the same rates as without the laser
  ASSERT_EQ(sh("run " + kLit + " --set laser.average_power_mW=0 -o " + (dir_ / "dark").string()).code, 0);
  EXPECT_TRUE(slurp(dir_ / "blind/detection_rate.npy") == slurp(dir_ / "dark/detection_rate.npy"));
}

// The gate's tabulation error is of the open gate's rate: where a bright return's pixel sees little through
// the gate's edge, its counts are off by N x error x lambda, not N x error (the flat target at 10 cm, lambda
// about 16: up to 0.9 of 255 counts against 64 x more knots, while the warning before the render, which
// knows no rate, stays silent below 0.2 % and promised 0.06). The run warns with the brightest rate and a
// bound the counts keep; at 1 m (lambda about 0.2) it does not, nor does a sense with 1024 knots. With 64 knots
// (the default 256 keeps this return's error below the warning's 0.2 %).
TEST_F(App, ABrightReturnsGateTabulationErrorIsWarnedAboutWithItsRate) {
  const std::string base = kScenes + "flat_target.json -q --set camera.crop=[504,244,8,8] --set render.samples_per_pixel=4 "
                           "--set outputs.light=true --set outputs.detection_rate=true --set outputs.expected_counts=true "
                           "--set sensor.gate.knots_per_edge=64";
  Result r = sh("run " + base + " --set camera.position_m=[0,0,0.1] -o " + (dir_ / "near").string());
  ASSERT_EQ(r.code, 0) << r.output;
  const std::string key = "the brightest return's, ";
  const size_t at = r.output.find(key);
  ASSERT_NE(at, std::string::npos) << r.output;
  const double lambda = std::stod(r.output.substr(at + key.size()));
  // The laser's rate with the gate open: the rates' plateau at the target (its light in the gate whole), less
  // the rate without laser light (dark counts).
  const std::vector<double> rate = values(read_npy(dir_ / "near/detection_rate.npy"));
  ASSERT_EQ(sh("run " + base + " --set camera.position_m=[0,0,0.1] --set laser.average_power_mW=0 -o " + (dir_ / "unlit").string()).code, 0);
  const std::vector<double> unlit = values(read_npy(dir_ / "unlit/detection_rate.npy"));
  double plateau = 0.0;
  for (size_t i = 0; i < rate.size(); ++i) plateau = std::max(plateau, rate[i] - unlit[i]);
  // (the plateau holds the neighbours' crosstalk too, 0.7 % for pixel A)
  EXPECT_NEAR(lambda, plateau, 1e-2 * plateau);
  const std::string bound_key = "may be off by up to about ";
  const size_t b = r.output.find(bound_key);
  ASSERT_NE(b, std::string::npos);
  const double bound = std::stod(r.output.substr(b + bound_key.size()));
  // The same light through a finely tabulated gate.
  r = sh("sense " + (dir_ / "near").string() + " -q --set sensor.gate.knots_per_edge=4096 -o " + (dir_ / "fine").string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, Not(HasSubstr("sensor.gate")));
  const std::vector<double> e = values(read_npy(dir_ / "near/expected_counts.npy"));
  const std::vector<double> f = values(read_npy(dir_ / "fine/expected_counts.npy"));
  ASSERT_EQ(e.size(), f.size());
  double worst = 0.0;
  for (size_t i = 0; i < e.size(); ++i) worst = std::max(worst, std::fabs(e[i] - f[i]));
  EXPECT_LE(worst, bound) << "the warning's bound";
  EXPECT_GE(worst, 0.25 * bound) << "the warning's bound is far above what the counts move";
  r = sh("run " + base + " -o " + (dir_ / "far").string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, Not(HasSubstr("sensor.gate")));
  // One gate position in the return's tail (where the 351-position sweep's error was largest): the same error,
  // and the same warning (the rate's swing over the sweep, which was tried first, is 0 there).
  r = sh("run " + base + " --set camera.position_m=[0,0,0.1] --set acquisition.gate_sweep.start_ns=5.352 "
         "--set acquisition.gate_sweep.stop_ns=5.352 -o " + (dir_ / "one").string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr(key));
  // Bright ambient light (lambda about 70 at every gate position) is not a return: its rate is the gate's
  // integral, which the edges' error barely moves.
  r = sh("run " + base + " --set ambient.illuminance_lux=30000 -o " + (dir_ / "sunny").string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, Not(HasSubstr("sensor.gate")));
  const std::vector<double> sunny = values(read_npy(dir_ / "sunny/detection_rate.npy"));
  EXPECT_GT(*std::min_element(sunny.begin(), sunny.end()), 20.0);
}

// A coarsely tabulated gate (sensor.gate.knots_per_edge, grid_ps) is warned about, by run, info and sense,
// each for its own sensor: a sense with the default gate drops the run's warning, one with a coarse grid
// gives its own. A grid finer than the fine grid goes (at most 12000 steps over the edges and the instrument
// response) is warned about with the step used, where grid_ps is not the default (0.25 ps, "or coarser").
TEST_F(App, ACoarselyTabulatedGateIsWarnedAboutForTheSensorThatUsesIt) {
  const auto gate_warnings = [](const fs::path& dir) {
    std::vector<std::string> out;
    const nlohmann::json meta = nlohmann::json::parse(slurp(dir / "metadata.json"));
    for (const auto& w : meta["warnings"])
      if (w.get<std::string>().rfind("sensor.gate: the gate is tabulated", 0) == 0) out.push_back(w.get<std::string>());
    return out;
  };
  // A window wide enough for the coarse grid's wider gate support (below).
  Result r = sh("run " + kLit + " --set sensor.gate.knots_per_edge=8 --set render.window_start_ns=-3 --set "
                "render.window_stop_ns=12 -o " + (dir_ / "run").string());
  ASSERT_EQ(r.code, 0) << r.output;
  // 8 knots: 2.2 % of the open gate (docs/sensor.md), up to 5.7 of 255 frames' counts.
  EXPECT_THAT(r.output, HasSubstr("spadgen: warning: sensor.gate: the gate is tabulated to within about 2.2"));
  ASSERT_EQ(gate_warnings(dir_ / "run").size(), 1u);
  EXPECT_THAT(gate_warnings(dir_ / "run")[0], HasSubstr("knots_per_edge 8"));
  r = sh("info " + kScenes + "multi_object.json --set sensor.gate.knots_per_edge=8");
  EXPECT_THAT(r.output, HasSubstr("warning: sensor.gate: the gate is tabulated"));
  r = sh("info " + kScenes + "multi_object.json");
  EXPECT_THAT(r.output, Not(HasSubstr("sensor.gate: the gate is tabulated")));
  EXPECT_THAT(r.output, Not(HasSubstr("sensor.gate.grid_ps")));  // (its 0.25 ps default is 0.29 ps there)
  r = sh("info " + kScenes + "multi_object.json --set sensor.gate.grid_ps=0.1");
  EXPECT_THAT(r.output, HasSubstr("warning: sensor.gate.grid_ps 0.1 is finer than the fine grid goes: its step is 0.2892 ps"));
  r = sh("info " + kScenes + "multi_object.json --set sensor.gate.grid_ps=0.3");
  EXPECT_THAT(r.output, Not(HasSubstr("sensor.gate.grid_ps")));

  r = sh("sense " + (dir_ / "run").string() + " -q --set sensor.gate.knots_per_edge=64 -o " + (dir_ / "fine").string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, Not(HasSubstr("sensor.gate")));
  EXPECT_TRUE(gate_warnings(dir_ / "fine").empty());
  r = sh("sense " + (dir_ / "run").string() + " -q --set sensor.gate.knots_per_edge=64 --set sensor.gate.grid_ps=0.01 -o " +
         (dir_ / "finest").string());
  ASSERT_EQ(r.code, 0) << r.output;
  const nlohmann::json finest = nlohmann::json::parse(slurp(dir_ / "finest" / "metadata.json"));
  const double used = finest["acquisition"]["gate"]["grid_ps"].get<double>();
  EXPECT_GT(used, 0.01);
  EXPECT_THAT(finest["warnings"].dump(), HasSubstr("sensor.gate.grid_ps 0.01 is finer than the fine grid goes: its step is "));
  // A 40 ps grid (0.17 % of the open gate from the grid alone, docs/sensor.md) with 16 knots.
  r = sh("sense " + (dir_ / "run").string() + " -q --set sensor.gate.knots_per_edge=16 --set sensor.gate.grid_ps=40 -o " +
         (dir_ / "coarse").string());
  ASSERT_EQ(r.code, 0) << r.output;
  ASSERT_EQ(gate_warnings(dir_ / "coarse").size(), 1u);
  EXPECT_THAT(gate_warnings(dir_ / "coarse")[0], HasSubstr("knots_per_edge 16"));
  EXPECT_THAT(gate_warnings(dir_ / "coarse")[0], HasSubstr("grid_ps 40"));
}

TEST_F(App, SenseRefusesWhatItCannotDo) {
  ASSERT_EQ(sh("run " + kSmall + " -o " + (dir_ / "dark").string()).code, 0);
  Result r = sh("sense " + (dir_ / "dark").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("saved no light; run it again with --set outputs.light=true"));

  ASSERT_EQ(sh("run " + kLit + " -o " + (dir_ / "run").string()).code, 0);
  r = sh("sense " + (dir_ / "run").string() + " --set laser.average_power_mW=5");
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("--set laser.average_power_mW: sense re-samples the sensor only"));
  EXPECT_THAT(r.output, HasSubstr("laser.average_power_mW shapes the rendered light: use spadgen run"));
  // The tile edge changes no output: said so (it was called a key that shapes the light: a new user's find).
  r = sh("sense " + (dir_ / "run").string() + " --set render.tile_size_px=64");
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("render.tile_size_px is the renderer's tile edge, on which no output depends: leave it out"));
  // The glTF's nodes and materials shape the light too.
  r = sh("sense " + (dir_ / "run").string() + " --set nodes.sphere.scale=[1,1,1]");
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("--set nodes.sphere.scale: sense re-samples the sensor only"));
  r = sh("sense " + (dir_ / "run").string() + " --set 'materials.\"a=b\".ior=1.2'");
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("--set materials.\"a=b\".ior: sense re-samples the sensor only"));
  // A key the scene file does not have is a typo, named as the schema names it (sense called it a key of
  // the rendered light; a key that began as a sensor key did pass its check: "seeds.noiseX").
  r = sh("sense " + (dir_ / "run").string() + " --set lazer.power=1");
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("--set lazer.power: /lazer/power: unknown key: there is no section /lazer; did you mean /laser?"));
  r = sh("sense " + (dir_ / "run").string() + " --set seeds.noiseX=1");
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("--set seeds.noiseX: /seeds/noiseX: unknown key; did you mean /seeds/noise?"));
  // Without -o, a default output name too long for the file system says it is the default (it said "(-o)")
  const fs::path long_run = dir_ / std::string(238, 'r');
  fs::rename(dir_ / "run", long_run);
  r = sh("sense " + long_run.string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr(long_run.string() + "-sense as the output folder (sense's default without -o, the run's name and "
                                  "'-sense' beside it; name another with -o): its name is 244 bytes long"));
  EXPECT_EQ(sh("sense " + long_run.string() + " -o " + (dir_ / "short").string() + " -q").code, 0);
  fs::remove_all(dir_ / "short");
  fs::rename(long_run, dir_ / "run");
  r = sh("sense " + (dir_ / "run").string() + " --set seeds.light=3");
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("--set seeds.light: sense re-samples the sensor only"));
  // A sweep beyond the rendered window (the run stopped at 4.2 ns).
  r = sh("sense " + (dir_ / "run").string() + " --set acquisition.gate_sweep.stop_ns=9");
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("but the run saved light from"));
  r = sh("sense " + dir_.string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("no metadata.json"));
  EXPECT_FALSE(fs::exists(dir_ / "run-sense")) << "a refused sense leaves nothing behind";

  // Into the run's folder: refused however the folder is named (the default of RUN/, as a shell completes
  // it, is RUN-sense beside it, not RUN/-sense inside).
  for (const std::string& o : {(dir_ / "run" / "sub").string(), (dir_ / "run" / ".").string()}) {
    r = sh("sense " + (dir_ / "run").string() + " -o " + o);
    EXPECT_EQ(r.code, 1) << o;
    EXPECT_THAT(r.output, HasSubstr("sense writes a new folder beside the run, not into it")) << o;
  }
  EXPECT_FALSE(fs::exists(dir_ / "run" / "sub"));
  r = sh("sense " + (dir_ / "run").string() + "/ -q");
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_TRUE(fs::exists(dir_ / "run-sense" / "counts.npy"));
  EXPECT_FALSE(fs::exists(dir_ / "run" / "-sense"));

  // A file of the run that sense links, removed: named before any work, not an internal error.
  fs::remove(dir_ / "run" / "ground_truth.exr");
  r = sh("sense " + (dir_ / "run").string() + " -o " + (dir_ / "again").string());
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("ground_truth.exr: listed in"));
  EXPECT_THAT(r.output, HasSubstr("(files) but missing"));
  EXPECT_FALSE(fs::exists(dir_ / "again"));

  // A damaged saved light (a NaN among the values: its last bin) is refused, not sensed into NaN outputs.
  ASSERT_EQ(sh("run " + kLit + " -o " + (dir_ / "nan").string()).code, 0);
  {
    std::fstream f(dir_ / "nan" / "light" / "values.npy", std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(-4, std::ios::end);
    const float nan = std::numeric_limits<float>::quiet_NaN();
    f.write(reinterpret_cast<const char*>(&nan), 4);
  }
  r = sh("sense " + (dir_ / "nan").string() + " --set seeds.chip=4 -o " + (dir_ / "nan_sensed").string());
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("/light: pixel ("));
  EXPECT_THAT(r.output, HasSubstr("the saved light is damaged"));
  EXPECT_FALSE(fs::exists(dir_ / "nan_sensed"));
  // ... and so is one in the light's other arrays, named (a NaN in out_of_window or laser_se reached
  // metadata.json as null, -4 samples its minimum; an adversarial tester's finds)
  ASSERT_EQ(sh("run " + kLit + " -o " + (dir_ / "whole").string()).code, 0);
  const auto damage_last = [&](const std::string& file, const std::string& value_bytes) {
    fs::remove_all(dir_ / "damaged");
    fs::copy(dir_ / "whole", dir_ / "damaged", fs::copy_options::recursive);
    std::fstream f(dir_ / "damaged" / "light" / file, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(-static_cast<std::streamoff>(value_bytes.size()), std::ios::end);
    f.write(value_bytes.data(), static_cast<std::streamsize>(value_bytes.size()));
  };
  const auto bytes_of = [](auto v) { return std::string(reinterpret_cast<const char*>(&v), sizeof v); };
  for (const auto& [file, bytes, name, what] :
       std::vector<std::tuple<std::string, std::string, std::string, std::string>>{
           {"out_of_window.npy", bytes_of(std::numeric_limits<double>::quiet_NaN()), "out_of_window", "a finite number >= 0"},
           {"out_of_window.npy", bytes_of(-1.0), "out_of_window", "a finite number >= 0"},
           {"laser_se.npy", bytes_of(std::numeric_limits<float>::quiet_NaN()), "laser_se", "a finite number >= 0"},
           {"samples.npy", bytes_of(int32_t{-4}), "samples", "a count >= 0"}}) {
    damage_last(file, bytes);
    r = sh("sense " + (dir_ / "damaged").string() + " --set seeds.chip=4 -o " + (dir_ / "damaged_sensed").string());
    EXPECT_EQ(r.code, 1) << file << r.output;
    EXPECT_THAT(r.output, HasSubstr("/light: pixel (")) << file;
    EXPECT_THAT(r.output, HasSubstr(") holds a value that is not " + what + " (in " + name + "); the saved light is damaged")) << file;
    EXPECT_FALSE(fs::exists(dir_ / "damaged_sensed"));
  }
  // ... and finite values the pixel's totals deny (3e38 photons in a bin wrote +inf rates, exit 0: an
  // adversarial tester's find): the bins sum to laser_total less out_of_window
  damage_last("values.npy", bytes_of(3e38f));
  r = sh("sense " + (dir_ / "damaged").string() + " --set seeds.chip=4 -o " + (dir_ / "damaged_sensed").string());
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("'s values sum to 3e+38 photons per pulse, and its laser_total less out_of_window is "));
  EXPECT_THAT(r.output, HasSubstr("(the light inside the window, which the values hold); the saved light is damaged"));
  EXPECT_FALSE(fs::exists(dir_ / "damaged_sensed"));

  // A bad value in the run's resolved scene is named there: sense reads it from metadata.json (it was
  // reported against the scene file, which held a good one).
  {
    nlohmann::ordered_json meta = nlohmann::ordered_json::parse(slurp(dir_ / "nan" / "metadata.json"));
    meta["resolved_scene"]["camera"]["width_px"] = "abc";
    std::ofstream(dir_ / "nan" / "metadata.json") << meta.dump(2);
  }
  r = sh("sense " + (dir_ / "nan").string() + " -o " + (dir_ / "bad_meta").string());
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr((dir_ / "nan" / "metadata.json").string() + ": resolved_scene (the run's scene file as it resolved"));
  EXPECT_THAT(r.output, HasSubstr("/camera/width_px"));
  EXPECT_FALSE(fs::exists(dir_ / "bad_meta"));
  // nor is an emptied list of the run's files taken for a run without them (sense wrote a folder without
  // the run's ground truth, labels and depth preview, exit 0)
  {
    nlohmann::ordered_json meta = nlohmann::ordered_json::parse(slurp(dir_ / "run" / "metadata.json"));
    meta["files"] = nlohmann::ordered_json::array();
    std::ofstream(dir_ / "run" / "metadata.json") << meta.dump(2);
  }
  r = sh("sense " + (dir_ / "run").string() + " -o " + (dir_ / "no_files").string());
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("metadata.json: files does not list metadata.json, as every run's list does"));
  EXPECT_FALSE(fs::exists(dir_ / "no_files"));
  // A run of a later spadgen, which may lay out its light otherwise, is named rather than read on a guess (it
  // was sensed); an earlier version's is read while its keys are there; a version that is no version is named.
  const std::string ours = nlohmann::json::parse(slurp(dir_ / "nan" / "metadata.json"))["spadgen_version"];
  const std::string later = std::to_string(std::stoi(ours.substr(0, ours.find('.'))) + 1) + ".0.0";
  // ("0.1.0.0" is this 0.1.0, not a later one: it was refused as later)
  for (const std::string& version : {later, std::string("0.0.1"), ours + ".0", std::string("x.1")}) {
    ASSERT_EQ(sh("run " + kLit + " -o " + (dir_ / "versioned").string()).code, 0);
    {
      nlohmann::ordered_json meta = nlohmann::ordered_json::parse(slurp(dir_ / "versioned" / "metadata.json"));
      meta["spadgen_version"] = version;
      std::ofstream(dir_ / "versioned" / "metadata.json") << meta.dump(2);
    }
    const fs::path out = dir_ / ("v_" + version);
    r = sh("sense " + (dir_ / "versioned").string() + " -q -o " + out.string());
    if (version == "0.0.1" || version == ours + ".0") {
      EXPECT_EQ(r.code, 0) << r.output;
      continue;
    }
    EXPECT_EQ(r.code, 1) << version << r.output;
    EXPECT_THAT(r.output, HasSubstr((dir_ / "versioned" / "metadata.json").string() +
                                    (version == later ? ": written by spadgen " + later + ", later than this spadgen " + ours +
                                                            ", whose sense may read its light otherwise: use spadgen " + later + " or later"
                                                      : ": spadgen_version \"x.1\"; expected a version such as \"" + ours + "\"")));
    EXPECT_FALSE(fs::exists(out));
  }
}

// metadata.json's fields of another type than a run writes are named with the file and the key (each was an
// internal error, exit 3: "type must be number, but is string"; an adversarial tester's), and so is a file
// that is no JSON object ("the run saved no light").
TEST_F(App, SenseNamesMetadataFieldsOfTheWrongType) {
  ASSERT_EQ(sh("run " + kLit + " -o " + (dir_ / "run").string()).code, 0);
  const fs::path meta = dir_ / "run" / "metadata.json";
  const std::string kept = slurp(meta);
  const struct {
    const char* pointer;
    const char* value;
    const char* expected;
  } cases[] = {{"/light/time_axis_s/start", "\"x\"", "a number"},
               {"/light/time_axis_s/bins", "\"12\"", "an integer >= 0"},
               {"/light/time_axis_s/bin_width", "true", "a number > 0"},
               {"/light/crop_in_sensor", "[1, 2, 3]", "[x, y, width, height] in pixels"},
               {"/sensor_tables_fnv1a64", "5", "text"},
               {"/files", "[5]", "a list of file names"},
               {"/warnings", "5", "a list of texts"},
               // the scene's components, which sense carries over (an entry of another shape was an internal error)
               {"/model/0/active", "\"x\"", "a list of {component: text, active: true or false, why: text}"},
               {"/model/1", "null", "a list of {component: text, active: true or false, why: text}"}};
  // sense of the run with metadata.json's value at `pointer` replaced by the JSON `value`
  const auto sensed_with = [&](const char* pointer, const char* value) {
    nlohmann::ordered_json m = nlohmann::ordered_json::parse(kept);
    m[nlohmann::ordered_json::json_pointer(pointer)] = nlohmann::ordered_json::parse(value);
    std::ofstream(meta, std::ios::trunc) << m.dump(2);
    return sh("sense " + (dir_ / "run").string() + " -o " + (dir_ / "s").string());
  };
  for (const auto& c : cases) {
    const Result r = sensed_with(c.pointer, c.value);
    EXPECT_EQ(r.code, 1) << c.pointer << r.output;
    // the key checked is the field (for the model, its list: the message shows the list's start)
    const std::string key = std::string(c.pointer).starts_with("/model/") ? "/model" : c.pointer;
    const std::string shown = key == c.pointer ? nlohmann::json::parse(c.value).dump() : "[";
    EXPECT_THAT(r.output, HasSubstr(meta.string() + ": " + key + " is " + shown)) << c.pointer << r.output;
    EXPECT_THAT(r.output, HasSubstr("; expected " + std::string(c.expected) + ", as a run writes it")) << c.pointer;
  }
  // ... and its time axis as the run computed it from its scene: an axis of 2^62 bins crashed sense (a
  // segmentation fault), one of 0.5 s bins drew counts from rates on another axis than the detection_rate.npy
  // it linked, and a resolved scene whose laser no longer gives the axis's period was taken (an adversarial
  // tester's finds)
  const struct {
    const char* pointer;
    const char* value;
    const char* says;
  } axes[] = {{"/light/time_axis_s/bins", "4611686018427387904", "light.time_axis_s.bins is 4611686018427387904; expected at most 1000000"},
              {"/light/time_axis_s/bins", "18446744073709551615", "light.time_axis_s.bins is 18446744073709551615; expected at most"},
              {"/light/time_axis_s/bin_width", "0.5", "light.time_axis_s.bin_width is 0.5 s, but the run's render.time_bin_ps gives "},
              {"/light/time_axis_s/laser_period", "1e300", "light.time_axis_s.laser_period is 1e+300 s, but the run's laser.repetition_rate_MHz"},
              {"/resolved_scene/laser/repetition_rate_MHz", "0.5", "light.time_axis_s.laser_period is "},
              {"/light/time_axis_s/start", "-1e300", "light.time_axis_s.start is -1e+300 s; expected within +-0.01 s"}};
  for (const auto& c : axes) {
    const Result r = sensed_with(c.pointer, c.value);
    EXPECT_EQ(r.code, 1) << c.pointer << r.output;
    EXPECT_THAT(r.output, HasSubstr(meta.string() + ": " + c.says)) << c.pointer;
    EXPECT_FALSE(fs::exists(dir_ / "s"));
  }
  // a kept transient without its crop (sense rescales the transient to it: an internal error)
  {
    nlohmann::ordered_json m = nlohmann::ordered_json::parse(kept);
    ASSERT_TRUE(m.contains("transient")) << "the run keeps its transient";
    m["transient"].erase("crop_in_sensor");
    std::ofstream(meta, std::ios::trunc) << m.dump(2);
    const Result r = sh("sense " + (dir_ / "run").string() + " -o " + (dir_ / "s").string());
    EXPECT_EQ(r.code, 1) << r.output;
    EXPECT_THAT(r.output, HasSubstr(meta.string() + ": transient has no crop_in_sensor; expected [x, y, width, height] in pixels"));
  }
  std::ofstream(meta, std::ios::trunc) << "[[[]]]";
  EXPECT_THAT(sh("sense " + (dir_ / "run").string() + " -o " + (dir_ / "s").string()).output,
              HasSubstr(meta.string() + ": not a JSON object; expected a run's metadata.json"));
  std::ofstream(meta, std::ios::trunc) << kept;
  EXPECT_EQ(sh("sense " + (dir_ / "run").string() + " -o " + (dir_ / "s").string() + " -q").code, 0);
  EXPECT_FALSE(fs::exists(dir_ / "run-sense"));
}

// The saved light holds every rendered bin of every pixel (the transient, compactly), and its own
// description (metadata.json's light section) agrees with its files.
TEST_F(App, SavedLightIsTheTransientOverEachPixelsLitBins) {
  ASSERT_EQ(sh("run " + kLit + " -o " + (dir_ / "run").string()).code, 0);
  const fs::path d = dir_ / "run";
  const auto meta = nlohmann::json::parse(slurp(d / "metadata.json"));
  EXPECT_EQ(meta["light"]["crop_in_sensor"], nlohmann::json({495, 231, 26, 22}));  // the crop and its ring
  const Npy ranges = read_npy(d / "light/ranges.npy"), offsets = read_npy(d / "light/offsets.npy");
  const Npy vals = read_npy(d / "light/values.npy"), transient = read_npy(d / "transient.npy");
  const Npy laser = read_npy(d / "light/laser_total.npy");
  ASSERT_EQ(ranges.shape, (std::vector<int64_t>{22, 26, 2}));
  ASSERT_EQ(offsets.shape, (std::vector<int64_t>{22 * 26 + 1}));
  EXPECT_EQ(laser.descr, "<f8");
  const int64_t T = transient.shape[2];
  const auto i32 = [&](const Npy& n, size_t i) { int32_t v; std::memcpy(&v, n.data.data() + 4 * i, 4); return v; };
  const auto i64 = [&](const Npy& n, size_t i) { int64_t v; std::memcpy(&v, n.data.data() + 8 * i, 8); return v; };
  const std::vector<double> v = values(vals), t = values(transient);
  EXPECT_EQ(int64_t(v.size()), i64(offsets, 22 * 26));
  EXPECT_EQ(meta["light"]["values_bytes"], 4 * v.size());
  // Inside the crop, the transient rebuilt from the light is transient.npy, bin for bin.
  size_t lit_bins = 0;
  for (int y = 0; y < 20; ++y)
    for (int x = 0; x < 24; ++x) {
      const size_t i = size_t((y + 1) * 26 + (x + 1));
      const int32_t lo = i32(ranges, 2 * i), hi = i32(ranges, 2 * i + 1);
      ASSERT_EQ(i64(offsets, i + 1) - i64(offsets, i), hi - lo);
      for (int64_t b = 0; b < T; ++b) {
        const double expect = t[size_t((y * 24 + x) * T + b)];
        const double got = b >= lo && b < hi ? v[size_t(i64(offsets, i) + b - lo)] : 0.0;
        ASSERT_EQ(got, expect) << x << " " << y << " " << b;
      }
      lit_bins += size_t(hi - lo);
    }
  // Compact: the multi-object transient spans a small part of the window.
  EXPECT_LT(lit_bins, size_t(24 * 20 * T) / 4);
  // Offsets that disagree with the ranges name both files (the ranges alone were named).
  const size_t at = size_t(21 * 26 + 25);  // a pixel of the ring's last row; its offset moved by one bin
  std::string bytes = slurp(d / "light/offsets.npy");
  const std::string offsets_kept = bytes;
  const size_t data = bytes.size() - 8 * (22 * 26 + 1);
  int64_t o;
  std::memcpy(&o, bytes.data() + data + 8 * at, 8);
  ++o;
  std::memcpy(bytes.data() + data + 8 * at, &o, 8);
  std::ofstream(d / "light/offsets.npy", std::ios::binary) << bytes;
  const Result r = sh("sense " + d.string() + " -q -o " + (dir_ / "damaged").string());
  EXPECT_EQ(r.code, 1);
  EXPECT_THAT(r.output, HasSubstr("light/ranges.npy' and '"));
  // (the pixel by its sensor coordinates in the light's crop [495, 231, 26, 22]; it was the index into the file)
  EXPECT_THAT(r.output, HasSubstr("light/offsets.npy' disagree at pixel (" + std::to_string(495 + (at - 1) % 26) + ", " +
                                  std::to_string(231 + (at - 1) / 26) + "): its range ["));
  // Values of another length (another run's) name the values with the offsets (the offsets alone were named).
  std::ofstream(d / "light/offsets.npy", std::ios::binary) << offsets_kept;
  std::string values_npy = slurp(d / "light/values.npy");
  const std::string count = std::to_string(v.size()), fewer = std::to_string(v.size() - 1);
  ASSERT_EQ(count.size(), fewer.size());
  const size_t shape = values_npy.find("(" + count + ",)");
  ASSERT_NE(shape, std::string::npos);
  values_npy.replace(shape + 1, count.size(), fewer);
  values_npy.resize(values_npy.size() - 4);
  std::ofstream(d / "light/values.npy", std::ios::binary) << values_npy;
  const Result swapped = sh("sense " + d.string() + " -q -o " + (dir_ / "damaged").string());
  EXPECT_EQ(swapped.code, 1);
  EXPECT_THAT(swapped.output, HasSubstr("light/offsets.npy' and '"));
  EXPECT_THAT(swapped.output, HasSubstr("light/values.npy' disagree: the offsets run from 0 to " + count + " and the values hold " +
                                        fewer + " (one of them damaged, or of another run)"));
}

}  // namespace
