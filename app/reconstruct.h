// `spadgen reconstruct RUN_DIR` (reference detectors, the 2D HDR inversion) and `spadgen evaluate
// RUN_DIR|DATASET_DIR` (detections scored against the object labels). docs/detection.md.
#pragma once
#include <filesystem>
#include <nlohmann/json.hpp>

#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/tile.h"

namespace spadgen::app {

struct ReconstructOptions {
  std::string run_dir;
  std::string detector = "edges";  // "edges" (the team's) or "paper"
  std::string out;                 // default RUN_DIR/detections_<detector>.exr (2D runs: RUN_DIR/hdr.exr)
  bool noise_free = false;         // from the noise-free expected counts (detection_rate) instead of counts
  int max_detections = 4;          // slots per pixel in the file; a pixel keeps its highest-scoring ones
  int threads = 0;
  bool progress = true;
  // The options the user gave (a 2D run, which has no gate profiles to detect in, refuses the detectors').
  bool detector_given = false, max_detections_given = false;
};
// Returns the path written.
std::string reconstruct(const ReconstructOptions& options);

// The dataset indices `evaluate --samples` chooses, as sorted, disjoint, inclusive ranges (a range of 10^8
// samples is two numbers, not 10^8: it was expanded into a set, 4.7 GB, before it was checked against the
// dataset). metrics.json records it as `selection`, which dataset status reads back.
class SampleSelection {
 public:
  // "0,3,5-8", or @FILE with the list in a file (commas or whitespace between items: a long selection exceeds
  // what one command-line argument may hold, 128 kB). Error naming the token otherwise, or when it selects none.
  explicit SampleSelection(const std::string& given);
  // metrics.json's [[first, last], ...]; none when it holds no well-formed range.
  static std::optional<SampleSelection> from_json(const nlohmann::json& ranges);
  bool contains(int64_t index) const;
  int64_t last() const { return ranges_.back().second; }
  nlohmann::json json() const;
  // As --samples takes it ("0-3,7"), ",..." once past `most` characters.
  std::string text(size_t most) const;

 private:
  SampleSelection() = default;
  void add_sorted_merged(std::vector<std::pair<int64_t, int64_t>> parts);
  std::vector<std::pair<int64_t, int64_t>> ranges_;
};

struct EvaluateCommand {
  std::string target;              // a run folder or a dataset folder
  std::string detections;          // a file (run), or a file name inside each sample (dataset);
                                   // default: detections_<detector>.exr, computed in memory when absent
  std::string detector = "edges";
  std::string out_dir;             // default TARGET/evaluation
  double tolerance_m = 0.05;
  std::optional<double> min_score;
  std::optional<PixelRect> region; // image coordinates
  bool noise_free = false;
  std::optional<std::string> samples;  // a dataset's samples to score ("0,3,5-8", "@FILE"); none = every one
  int threads = 0;
};
// Writes metrics.json (and error maps for a run, samples.csv for a dataset); returns a short summary.
std::string evaluate(const EvaluateCommand& command);

// What reconstruct and evaluate write into a run folder by default (detections_<detector>.exr, hdr.exr,
// evaluation/): derived from that run, so a later run into the folder replaces them with the rest rather
// than refusing them as someone else's files. rel: a name directly inside the run folder.
bool is_derived_output(const std::string& rel);
// Whether the entry `path` (named rel inside a run folder) is such an output of spadgen's, by its content: an
// OpenEXR file that records its spadgen_source, or an evaluation/ folder holding evaluate's files only, its
// metrics.json evaluate's. A user's file of such a name (notes in evaluation/, an hdr.exr of their own) is not
// (a run into the folder deleted it: a verifier's find).
bool is_spadgen_derived_output(const std::filesystem::path& path, const std::string& rel);
// Whether a metrics.json is evaluate's: a JSON object with its spadgen_version and scored (or, written before it
// had spadgen_version, scored and the run or dataset scored).
bool is_evaluation_metrics(const std::filesystem::path& metrics);

}  // namespace spadgen::app
