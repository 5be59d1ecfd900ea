// The run: scene file -> Scene -> renderer -> sensor -> writers, streamed tile by tile. Everything is
// written into a staging folder beside the output folder, which replaces the output folder as one unit
// only when the whole run has succeeded (app/staging.h): a failed or interrupted run never leaves a
// half-written, mixed or wrong file behind.
#pragma once
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace spadgen::app {

struct RunOptions {
  std::string scene_file;
  std::string out_dir;                  // "" = out/<scene file stem>
  std::vector<std::string> overrides;   // "key.path=value"
  std::optional<uint64_t> seed;         // replaces the scene file's seed
  int threads = 0;                      // 0 = all cores
  bool progress = true;                 // progress and the summary lines on stderr (-q: off)
};

struct RunResult {
  std::string out_dir;
  std::vector<std::string> files;       // relative to out_dir, as listed in metadata.json
};

// Runs the whole pipeline; throws spadgen::Error with a message for the user on bad input.
RunResult run(const RunOptions& options);

// `spadgen info`: the resolved scene file, a summary of the glTF and what a run would produce.
std::string info(const std::string& scene_file, const std::vector<std::string>& overrides);

}  // namespace spadgen::app
