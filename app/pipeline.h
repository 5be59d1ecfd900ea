// The run: scene file -> Scene -> renderer -> sensor -> writers, streamed tile by tile. Everything is
// written into a staging folder beside the output folder, which replaces the output folder as one unit
// only when the whole run has succeeded (app/staging.h): a failed or interrupted run never leaves a
// half-written, mixed or wrong file behind.
#pragma once
#include <nlohmann/json.hpp>

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace spadgen::app {

// --threads above this is refused: the system runs out of threads long before (100000 failed in TBB).
inline constexpr int kMaxThreads = 1024;

struct RunOptions {
  std::string scene_file;
  std::string out_dir;                  // "" = out/<scene file stem>
  std::vector<std::string> overrides;   // "key.path=value"
  std::optional<uint64_t> seed;         // replaces the scene file's seed
  int threads = 0;                      // 0 = all cores
  bool progress = true;                 // progress and the summary lines on stderr (-q: off)
  std::optional<nlohmann::json> dataset;  // spadgen dataset: recorded as metadata.json's "dataset"
  // spadgen dataset: the sensor tables' hash the sample's hash holds; a run whose sensor reads other tables (edited
  // since the sample was resolved) is refused, not recorded done under the hash of the others
  std::optional<std::string> tables_hash;
};

struct RunResult {
  std::string out_dir;
  std::vector<std::string> files;       // relative to out_dir, as listed in metadata.json
};

// Runs the whole pipeline; throws spadgen::Error with a message for the user on bad input.
RunResult run(const RunOptions& options);

struct SenseOptions {
  std::string run_dir;                  // a run folder written with outputs.light
  std::string out_dir;                  // "" = <run_dir>-sense
  std::vector<std::string> overrides;   // "key.path=value": sensor.*, acquisition.*, seeds.chip, seeds.noise, outputs.*
  std::optional<uint64_t> noise_seed;   // replaces seeds.noise
  std::optional<uint64_t> chip_seed;    // replaces seeds.chip
  int repeats = 1;                      // realisations of the temporal noise: noise seeds S, S + 1, ...
  int threads = 0;
  bool progress = true;
  std::optional<nlohmann::json> dataset;  // spadgen dataset: recorded as metadata.json's "dataset"
  std::optional<std::string> tables_hash;  // spadgen dataset: as RunOptions::tables_hash
};

// `spadgen sense`: the sensor stage alone, from the light a run saved (light/). With the run's settings
// and seeds it writes the same files as the run, bit for bit. With repeats > 1, realisation r (noise
// seed S + r) goes to <out_dir>/repeat_<r>. Returns the folders written.
std::vector<RunResult> sense(const SenseOptions& options);

// `spadgen info`: the resolved scene file, a summary of the glTF and what a run would produce.
std::string info(const std::string& scene_file, const std::vector<std::string>& overrides);

}  // namespace spadgen::app
