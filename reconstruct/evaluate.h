// Scoring detections against object labels (docs/detection.md).
//
// Per pixel, the true objects along the pixel-centre ray (ground_truth.exr object<j>.range, labels.exr
// object<j>.detectable) are matched one to one with the detections: pairs are taken in increasing
// |range error| while the error is within `tolerance_m`. A matched object is found; an unmatched
// detection is a false detection. Range errors are detection minus truth over the matched pairs, modulo
// the half path a laser period spans (a detector reports a farther object folded into it, as the camera
// sees it; with the laser beside the lens the fold is of the return's half path, not of its range).
#pragma once
#include <array>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <vector>

#include "core/tile.h"
#include "reconstruct/detect.h"

namespace spadgen::reconstruct {

struct TruthObject {
  int id = -1;            // the object's id (metadata.json objects[])
  double range_m = 0.0;
  bool detectable = true;
};

struct EvaluateOptions {
  double tolerance_m = 0.05;        // a detection further from every unmatched object is false
  double ambiguity_m = 0.0;         // c T / 2 of the laser period T: errors are taken modulo it; 0: none
  std::optional<double> min_score;  // detections scoring below are ignored; none: every score counts (-inf too)
  std::optional<PixelRect> region;  // image coordinates: accuracy and precision of the nearest object there
};

// What the scorer keeps per pixel, for the error maps.
struct PixelOutcome {
  int objects = 0, found = 0, false_detections = 0;
  float first_error_m = 0.0f;  // error of the nearest object when it was found, NaN otherwise
};

// Sums over pixels (and over a dataset's samples: merge()).
class Scores {
 public:
  explicit Scores(const EvaluateOptions& options) : options_(options) {}
  // One pixel. detections: ranges and scores, any order; bistatic: where the laser sits against the pixel's
  // ray (the folding is of half paths, detect.h).
  PixelOutcome add(int x, int y, std::vector<TruthObject> objects, const std::vector<std::pair<double, double>>& detections,
                   const Bistatic& bistatic = {});
  void merge(const Scores& other);
  // metrics.json's content; names: object id -> name, for the per-object table.
  nlohmann::json to_json(const std::map<int, std::string>& names = {}) const;

  struct Tally {
    int64_t total = 0, found = 0;
  };
  const Tally& all() const { return all_; }
  int64_t detections() const { return detections_; }
  int64_t false_detections() const { return false_; }
  const std::vector<double>& errors() const { return errors_; }

 private:
  EvaluateOptions options_;
  Tally all_, detectable_, undetectable_;
  std::array<Tally, 4> by_count_{};  // objects on the pixel: 1, 2, 3, 4 or more
  std::map<int, Tally> by_object_;
  std::map<int, std::vector<double>> errors_by_object_;
  std::vector<double> errors_, region_errors_;
  int64_t detections_ = 0, false_ = 0, pixels_ = 0, empty_pixels_with_detections_ = 0, empty_pixels_ = 0;
  int64_t across_period_ = 0;   // matched detections folded onto their object by one or more laser periods
  int64_t region_nearest_ = 0;  // pixels of the region with an object
};

// Statistics of range errors in metres, reported in mm: count, bias, rms, std, |error| percentiles 50/90/99.
nlohmann::json error_statistics(std::vector<double> errors);

}  // namespace spadgen::reconstruct
