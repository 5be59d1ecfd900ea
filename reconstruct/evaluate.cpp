#include "evaluate.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace spadgen::reconstruct {
namespace {

nlohmann::json rate(const Scores::Tally& t) {
  nlohmann::json j = {{"objects", t.total}, {"found", t.found}};
  j["recall"] = t.total > 0 ? nlohmann::json(double(t.found) / double(t.total)) : nlohmann::json(nullptr);
  return j;
}

}  // namespace

PixelOutcome Scores::add(int x, int y, std::vector<TruthObject> objects,
                         const std::vector<std::pair<double, double>>& detections, const Bistatic& bistatic) {
  PixelOutcome o;
  o.first_error_m = std::numeric_limits<float>::quiet_NaN();
  std::vector<double> dets;
  for (const auto& [range, score] : detections)
    if (std::isfinite(range) && (!options_.min_score || score >= *options_.min_score)) dets.push_back(range);
  std::sort(objects.begin(), objects.end(), [](const TruthObject& a, const TruthObject& b) { return a.range_m < b.range_m; });
  // Candidate pairs within the tolerance, taken in increasing |error|, each object and detection once; of
  // equal |error|, the nearer object first, then the detection given first (stable: objects in range order).
  struct Pair {
    double error;
    size_t object, detection;
    bool folded;  // matched to the object across one or more laser periods
  };
  std::vector<Pair> pairs;
  // The error of a detection folded by the laser period: folded as the return's half path is (which is
  // its range only with the laser at the camera), then that half path's range against the object's. A
  // detection the fold leaves in place is compared by its range as given (the round trip through the half path
  // rounds: a detection exactly the tolerance away was matched in some pixels and not in others).
  const auto error = [&](double det, double object) -> std::pair<double, bool> {
    const double direct = det - object;
    if (options_.ambiguity_m <= 0.0) return {direct, false};
    if (bistatic.coaxial()) {
      const double e = std::remainder(direct, options_.ambiguity_m);
      return e == direct ? std::pair{direct, false} : std::pair{e, true};
    }
    const double h = bistatic.half_path_of_range(object);
    const double e = bistatic.half_path_of_range(det) - h;
    const double f = std::remainder(e, options_.ambiguity_m);
    if (f == e) return {direct, false};
    return {bistatic.range_of_half_path(h + f) - object, true};
  };
  for (size_t i = 0; i < objects.size(); ++i)
    for (size_t j = 0; j < dets.size(); ++j) {
      const auto [e, folded] = error(dets[j], objects[i].range_m);
      if (std::abs(e) <= options_.tolerance_m) pairs.push_back({e, i, j, folded});
    }
  std::stable_sort(pairs.begin(), pairs.end(), [](const Pair& a, const Pair& b) { return std::abs(a.error) < std::abs(b.error); });
  std::vector<bool> object_used(objects.size(), false), det_used(dets.size(), false);
  std::vector<double> error_of(objects.size(), std::nan(""));
  for (const Pair& p : pairs) {
    if (object_used[p.object] || det_used[p.detection]) continue;
    object_used[p.object] = det_used[p.detection] = true;
    error_of[p.object] = p.error;
    across_period_ += p.folded;
  }
  ++pixels_;
  o.objects = int(objects.size());
  const size_t count_slot = std::min<size_t>(objects.size(), 4);
  for (size_t i = 0; i < objects.size(); ++i) {
    const bool found = object_used[i];
    o.found += found;
    for (Tally* t : {&all_, objects[i].detectable ? &detectable_ : &undetectable_, &by_count_[count_slot - 1], &by_object_[objects[i].id]})
      ++t->total, t->found += found;
    if (found) {
      errors_.push_back(error_of[i]);
      errors_by_object_[objects[i].id].push_back(error_of[i]);
    }
  }
  const auto& r = options_.region;
  const bool in_region = r && x >= r->x0 && x < r->x1() && y >= r->y0 && y < r->y1();
  region_nearest_ += in_region && !objects.empty();
  if (!objects.empty() && object_used[0]) {
    o.first_error_m = static_cast<float>(error_of[0]);
    if (in_region) region_errors_.push_back(error_of[0]);
  }
  detections_ += int64_t(dets.size());
  for (bool used : det_used) o.false_detections += !used;
  false_ += o.false_detections;
  if (objects.empty()) {
    ++empty_pixels_;
    empty_pixels_with_detections_ += !dets.empty();
  }
  return o;
}

void Scores::merge(const Scores& s) {
  const auto add = [](Tally& a, const Tally& b) { a.total += b.total, a.found += b.found; };
  add(all_, s.all_), add(detectable_, s.detectable_), add(undetectable_, s.undetectable_);
  for (size_t i = 0; i < by_count_.size(); ++i) add(by_count_[i], s.by_count_[i]);
  for (const auto& [id, t] : s.by_object_) add(by_object_[id], t);
  for (const auto& [id, e] : s.errors_by_object_) errors_by_object_[id].insert(errors_by_object_[id].end(), e.begin(), e.end());
  errors_.insert(errors_.end(), s.errors_.begin(), s.errors_.end());
  region_errors_.insert(region_errors_.end(), s.region_errors_.begin(), s.region_errors_.end());
  detections_ += s.detections_, false_ += s.false_, pixels_ += s.pixels_, across_period_ += s.across_period_;
  region_nearest_ += s.region_nearest_;
  empty_pixels_ += s.empty_pixels_, empty_pixels_with_detections_ += s.empty_pixels_with_detections_;
}

nlohmann::json error_statistics(std::vector<double> e) {
  nlohmann::json j = {{"count", e.size()}};
  if (e.empty()) {  // the same keys, null (a reader of bias_mm met a missing key where nothing matched)
    for (const char* k : {"bias_mm", "rms_mm", "std_mm", "abs_p50_mm", "abs_p90_mm", "abs_p99_mm"}) j[k] = nullptr;
    return j;
  }
  double sum = 0, sq = 0;
  for (double v : e) sum += v, sq += v * v;
  const double n = double(e.size()), mean = sum / n;
  double var = 0;
  for (double v : e) var += (v - mean) * (v - mean);
  for (double& v : e) v = std::abs(v);
  std::sort(e.begin(), e.end());
  // Nearest-rank percentiles of |error|.
  const auto pct = [&](double q) { return e[std::min(e.size() - 1, size_t(std::max(0.0, std::ceil(q * n) - 1.0)))] * 1e3; };
  j["bias_mm"] = mean * 1e3;
  j["rms_mm"] = std::sqrt(sq / n) * 1e3;
  j["std_mm"] = e.size() > 1 ? nlohmann::json(std::sqrt(var / (n - 1)) * 1e3) : nlohmann::json(nullptr);  // undefined for one
  j["abs_p50_mm"] = pct(0.50);
  j["abs_p90_mm"] = pct(0.90);
  j["abs_p99_mm"] = pct(0.99);
  return j;
}

nlohmann::json Scores::to_json(const std::map<int, std::string>& names) const {
  nlohmann::json j;
  j["matching"] = {{"tolerance_m", options_.tolerance_m},
                   {"rule", "per pixel, object-detection pairs in increasing |range error| within the tolerance (|error| <= tolerance_m), each once; of equal |error|, the nearer object first, then the detection given first (the lower slot)"},
                   {"range_error", "detection minus object range, the detection folded onto the object by c T / 2 of half path (laser to object to camera, over 2) for the run's laser period T"}};
  if (options_.min_score) j["matching"]["min_score"] = *options_.min_score;
  j["pixels"] = pixels_;
  j["objects"] = rate(all_);
  j["objects_detectable"] = rate(detectable_);
  j["objects_not_detectable"] = rate(undetectable_);
  nlohmann::json by_count = nlohmann::json::object();
  for (size_t i = 0; i < by_count_.size(); ++i)
    if (by_count_[i].total > 0) by_count[i + 1 < by_count_.size() ? std::to_string(i + 1) : std::to_string(i + 1) + "+"] = rate(by_count_[i]);
  j["objects_by_count_on_pixel"] = by_count;
  j["detections"] = {{"total", detections_},
                     {"matched", detections_ - false_},
                     {"matched_across_period", across_period_},
                     {"false", false_},
                     {"precision", detections_ > 0 ? nlohmann::json(double(detections_ - false_) / double(detections_)) : nlohmann::json(nullptr)},
                     {"pixels_without_objects", empty_pixels_},
                     {"pixels_without_objects_with_detections", empty_pixels_with_detections_}};
  j["range_error"] = error_statistics(errors_);
  nlohmann::json per = nlohmann::json::array();
  for (const auto& [id, t] : by_object_) {
    nlohmann::json o = rate(t);
    o["id"] = id;
    if (names.count(id)) o["name"] = names.at(id);
    const auto it = errors_by_object_.find(id);
    o["range_error"] = error_statistics(it == errors_by_object_.end() ? std::vector<double>{} : it->second);
    per.push_back(o);
  }
  j["by_object"] = per;
  if (options_.region) {
    const PixelRect& r = *options_.region;
    nlohmann::json reg = error_statistics(region_errors_);
    reg["rect"] = {r.x0, r.y0, r.width, r.height};
    // how many of the region's nearest objects the errors cover (a detector that misses half of them is not
    // precise there because its few matches are)
    reg["objects"] = region_nearest_;
    reg["found"] = region_errors_.size();
    reg["recall"] = region_nearest_ > 0 ? nlohmann::json(double(region_errors_.size()) / double(region_nearest_)) : nlohmann::json(nullptr);
    reg["what"] = "the nearest object of each pixel of the region where it was found: accuracy = bias, precision = std; "
                  "objects: the region's pixels with an object, found: those whose nearest object was found";
    j["region"] = reg;
  }
  return j;
}

}  // namespace spadgen::reconstruct
