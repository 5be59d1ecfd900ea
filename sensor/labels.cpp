#include "sensor/labels.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/error.h"
#include "core/units.h"

namespace spadgen::sensor {

ObjectLabelsTile object_labels(const SensorModel& sensor, const GroundTruthTile& gt, const SensorTile& s,
                               const TimeAxis& axis, double emission_delay_s) {
  const PixelRect& r = gt.rect;
  const auto n = static_cast<size_t>(r.count());
  const auto slots = static_cast<size_t>(gt.max_layers);
  const auto K = static_cast<size_t>(s.K);
  if (s.rect != r || s.rate.size() != n * K || gt.object_laser.size() != n * slots)
    throw Error("object_labels: expected the ground truth with its object slots and the sensor's rates of the same pixels");
  ObjectLabelsTile out;
  out.rect = r;
  out.slots = gt.max_layers;
  out.id.assign(n * slots, -1);
  out.edge_counts.assign(n * slots, 0.0f);
  out.edge_snr.assign(n * slots, 0.0f);
  out.detectable.assign(n * slots, 0);
  out.edge.assign(n * slots, kNoReturn);
  const double N = sensor.frames_per_k();
  // Every object of the tile with direct light, its rates computed in one call.
  std::vector<SensorModel::Return> returns;
  std::vector<size_t> slot;  // [return]: its element e = pixel * slots + j
  for (int y = r.y0; y < r.y1(); ++y)
    for (int x = r.x0; x < r.x1(); ++x) {
      const auto i = static_cast<size_t>(r.index(x, y));
      for (size_t j = 0; j < slots; ++j) {
        const size_t e = i * slots + j;
        out.id[e] = gt.object_slot_id[e];
        if (out.id[e] < 0 || !(gt.object_laser[e] > 0.0f) || K == 0) continue;
        // The direct return's arrival: its optical path (laser to the object, the object to the camera).
        const double path = gt.object_path.empty() ? 2.0 * double(gt.object_range[e]) : double(gt.object_path[e]);
        returns.push_back({x, y, emission_delay_s + path / kSpeedOfLight, gt.object_laser[e]});
        slot.push_back(e);
      }
    }
  // The returns' rates a block at a time, at most about 8 MB of them (each return's rates are its own): the
  // whole tile's at once took returns x K doubles, 82 MB per tile at 10,001 gate positions, which the
  // resource plan did not count (a run of 278 MB planned peaked at 594 MB).
  const size_t block = std::max<size_t>(1, (size_t{1} << 20) / std::max<size_t>(1, K));
  std::vector<double> rates;
  // Every pixel's least rate over the sweep (NaN never taken), computed for the whole tile when a return first
  // needs its pixel's (below): one contiguous pass, where a walk down each pixel's column of the rates, one
  // dependent minimum after another and a cache line per gate position, was 0.7 % of the default run.
  std::vector<float> least;
  for (size_t ri = 0; ri < returns.size(); ++ri) {
    if (ri % block == 0)
      rates = sensor.return_lambda({returns.begin() + ptrdiff_t(ri), returns.begin() + ptrdiff_t(std::min(returns.size(), ri + block))}, axis);
    const size_t e = slot[ri], i = e / slots;
    const double* own = rates.data() + (ri % block) * K;
    const double peak = *std::max_element(own, own + K);
    if (!(peak > 0.0)) continue;
    const auto on_plateau = [&](size_t j) { return own[j] >= kEdgeFraction * peak; };
    size_t k = 0;
    while (!on_plateau(k)) ++k;  // the peak is on it
    // The gate positions the sweep holds on either side of the edge, at most kEdgeGates each: the
    // object's side along its plateau, the other side to the sweep's end (a rise at k* = 3 has 3 positions
    // before it to average, not 12).
    size_t with = 0, other = 0;
    if (k == 0) {
      // The sweep begins on the object's plateau: its rise lies before the first gate position (it was
      // labelled by a step the counts do not hold). Its falling edge instead, from the last position on the
      // plateau; none when the plateau runs to the end too (no edge in the sweep at all).
      k = K - 1;
      while (!on_plateau(k)) --k;
      if (k == K - 1) {
        out.edge[e] = kNoEdgeInSweep;
        continue;
      }
      out.edge[e] = kFallingEdgeOnly;
      while (with <= k && with < size_t(kEdgeGates) && on_plateau(k - with)) ++with;
      other = std::min(K - 1 - k, size_t(kEdgeGates));
    } else {
      out.edge[e] = kRisingEdge;
      while (k + with < K && with < size_t(kEdgeGates) && on_plateau(k + with)) ++with;
      other = std::min(k, size_t(kEdgeGates));
    }
    const double lambda = s.rate[k * n + i];
    // The rate without the object, never below 0. Within what own[k] is known to (the neighbours' crosstalk is
    // theirs taken as this pixel's: their gate skew and PDP differ; lambda is float), the difference is noise: a
    // bright return's lambda is large, and a fraction of it left "without" at several avalanches per frame and no
    // edge at all (1e7 mW: none). There it is the pixel's background instead: its least rate over the sweep
    // (dark counts and ambient light, where no object is in the gate), at most that tolerance. (It was 0: a
    // saturating background under a bright return was dropped, and a step of N labelled where the counts are
    // N throughout: an auditor's find.)
    double without = std::max(0.0, lambda - own[k]);
    if (const double tolerance = (sensor.crosstalk_share(returns[ri].x, returns[ri].y) + 0x1p-22) * own[k]; without <= tolerance) {
      if (least.empty()) {
        least.assign(n, std::numeric_limits<float>::infinity());
        for (size_t j = 0; j < K; ++j) {
          const float* row = s.rate.data() + j * n;
          for (size_t p = 0; p < n; ++p) least[p] = std::min(least[p], row[p]);
        }
      }
      without = std::max(0.0, std::min(tolerance, double(least[i])));
    }
    // 1 - p as exp(-lambda), not 1 - (1 - exp(-lambda)), which is 0 from lambda = 37 on: a saturating background
    // (17,000 lux) gave noise 0 and an edge of 1e-17 counts an infinite SNR, detectable.
    const double q1 = std::exp(-lambda), q0 = std::exp(-without);
    const double p1 = -std::expm1(-lambda), p0 = -std::expm1(-without);
    const double edge = N * (q0 - q1);
    const double noise = std::sqrt(N * p1 * q1 / double(with) + N * p0 * q0 / double(other));
    // no noise either side (counts certain to be 0 and N): the step is certain, infinitely above the noise
    const double snr = noise > 0.0 ? edge / noise : edge > 0.0 ? std::numeric_limits<double>::infinity() : 0.0;
    out.edge_counts[e] = static_cast<float>(edge);
    out.edge_snr[e] = static_cast<float>(snr);
    out.detectable[e] = snr >= kDetectableSnr;
  }
  return out;
}

}  // namespace spadgen::sensor
