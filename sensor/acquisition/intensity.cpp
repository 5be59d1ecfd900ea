#include "sensor/acquisition/intensity.h"

#include <algorithm>
#include <cmath>

#include "core/units.h"
#include "sensor/model/pixel_maps.h"

namespace spadgen::sensor {

Intensity::Intensity(const SensorStageConfig& c, std::vector<double> exposures, uint32_t frames_per_k, bool dual)
    : exposures_(std::move(exposures)),
      frames_per_k_(frames_per_k),
      dual_(dual),
      dual_ratio_(c.acquisition.intensity.dual_ratio),
      frames_(c.acquisition.frames),
      laser_on_(c.acquisition.intensity.laser_on),
      repetition_rate_Hz_(c.laser.repetition_rate_Hz),
      nominal_length_s_(c.sensor.gate.length_s) {}

TimeAxis Intensity::required_window(const PixelMaps&, double bin_width_s, double period_s) const {
  TimeAxis axis;
  axis.bin_width_s = bin_width_s;
  axis.period_s = period_s;
  return axis;
}

void Intensity::rates(const PixelDetection& d, const PixelLight& in, const TileSetup*, Scratch*, double* out) const {
  const double laser = laser_on_ ? d.pdp_laser * in.laser_total * repetition_rate_Hz_ : 0.0;
  const double rate = d.pdp_ambient * in.ambient_rate + laser + d.params->dcr_cps;
  for (size_t k = 0; k < exposures_.size(); ++k) out[k] = rate * exposures_[k];
}

void Intensity::finish_tile(SensorTile& out) const {
  const size_t n = static_cast<size_t>(out.rect.count()), Ks = exposures_.size();
  out.intensity_counts.assign(n, 0.0f);
  out.intensity_photons.assign(n, 0.0f);
  for (size_t i = 0; i < n; ++i) {
    double c = 0.0;
    for (size_t k = 0; k < Ks; ++k) c += out.counts[k * n + i];
    out.intensity_counts[i] = static_cast<float>(c);
    out.intensity_photons[i] = static_cast<float>(linearise(c, static_cast<double>(frames_), dual_, dual_ratio_));
  }
}

std::vector<DeclaredOutput> Intensity::outputs() const {
  return {{"intensity.exr", "counts: summed binary frames; photons: linearised incident photons per image"}};
}

nlohmann::json Intensity::describe() const {
  nlohmann::json j;
  std::vector<double> us;
  for (double e : exposures_) us.push_back(times_ten_to(e, 6));  // (e / kUs: 10.000000000000002 for 10 us)
  j["exposures_us"] = us;
  j["laser_on"] = laser_on_;
  return j;
}

double linearise(double counts, double N, bool dual, double ratio) {
  const double c = std::min(counts, N - 0.5);
  if (c <= 0.0) return 0.0;
  if (!dual) return -N * std::log1p(-c / N);
  const double aL = 2.0 * ratio / (ratio + 1.0), aS = 2.0 / (ratio + 1.0);
  const double y = 2.0 * c / N;
  double x = 0.0;  // Newton from below on a concave increasing function converges monotonically
  for (int it = 0; it < 500; ++it) {
    const double eL = std::exp(-aL * x), eS = std::exp(-aS * x);
    const double f = (2.0 - eL - eS) - y;
    const double step = -f / (aL * eL + aS * eS);
    x += step;
    if (!(step > 1e-13 * x)) break;
  }
  return x * N;
}

}  // namespace spadgen::sensor
