#include "sensor/model/pixel_maps.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/rng.h"
#include "core/units.h"
#include "sensor/streams.h"

namespace spadgen::sensor {
namespace {

constexpr double kTruncate = 5.0;
constexpr double kSkewPatternShare = 0.8;    // share of the skew variance in the smooth pattern
constexpr double kLengthPatternShare = 0.5;  // the length map is more uniform (paper Fig. 5(c))
constexpr double kActivationEv = 1.1;
constexpr double kRoomK = 298.15;
constexpr double kDiffusionShareAtRoom = 0.5;

double truncated_normal(Rng& rng) {
  for (;;) {
    const double u1 = 1.0 - rng.next_double();  // (0, 1]
    const double u2 = rng.next_double();
    const double z = std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * kPi * u2);
    if (std::abs(z) <= kTruncate) return z;
  }
}

// P(z <= x) of truncated_normal's z: the standard normal's, truncated at +-kTruncate.
double truncated_normal_cdf(double x) {
  if (x <= -kTruncate) return 0.0;
  if (x >= kTruncate) return 1.0;
  const double lo = 0.5 * std::erfc(kTruncate / std::sqrt(2.0));
  return (0.5 * std::erfc(-x / std::sqrt(2.0)) - lo) / (1.0 - 2.0 * lo);
}

double coord(int i, int n) { return n > 1 ? static_cast<double>(i) / (n - 1) : 0.5; }

}  // namespace

double PixelMaps::skew_pattern(double u, double v) {
  return v * v + 0.6 * std::pow(v, 6) * (u + 0.5 * std::sin(kPi * u));
}

double PixelMaps::length_pattern(double u, double v) { return v + 0.3 * u * v; }

double PixelMaps::temperature_factor(double temperature_C) {
  const double T = temperature_C + 273.15;
  const double arrhenius = std::exp(kActivationEv / kBoltzmannEv * (1.0 / kRoomK - 1.0 / T));
  return (1.0 - kDiffusionShareAtRoom) + kDiffusionShareAtRoom * arrhenius;
}

PixelMaps::PatternSums PixelMaps::pattern_sums(int width, int height) {
  // The patterns are products of a row's and a column's factors: the sine and the power are taken once per
  // column and row (per pixel they took 40 ms of every run and sense on the full chip), and each pixel's
  // value is the same expression as skew_pattern's and length_pattern's, the same bits (tested), summed in
  // the same order.
  std::vector<double> column_skew(static_cast<size_t>(width)), column_length(static_cast<size_t>(width));
  for (int x = 0; x < width; ++x) {
    const double u = coord(x, width);
    column_skew[size_t(x)] = u + 0.5 * std::sin(kPi * u);
    column_length[size_t(x)] = 0.3 * u;
  }
  PatternSums sums;
  for (int y = 0; y < height; ++y) {
    const double v = 1.0 - coord(y, height);
    const double v2 = v * v, v6 = 0.6 * std::pow(v, 6);
    for (int x = 0; x < width; ++x) {
      const double a = v2 + v6 * column_skew[size_t(x)], b = v + column_length[size_t(x)] * v;
      sums.skew += a;
      sums.skew_squared += a * a;
      sums.length += b;
      sums.length_squared += b * b;
    }
  }
  return sums;
}

double PixelMaps::dcr_main_median(const PixelTypeConfig& t) {
  const double m = t.dcr_median_cps, h = t.hot_pixel_fraction, s = t.dcr_log_sigma, lf = std::log(t.hot_pixel_factor);
  if (!(m > 0.0) || !(h > 0.0) || !(lf > 0.0)) return m;
  if (!(s > 0.0)) return h > 0.5 ? m / t.hot_pixel_factor : m;  // the median is a main pixel's, or a hot one's
  // u = ln(m / main median): the chip's share of pixels at or below m, (1 - h) P(z <= u / s) + h P(z <= (u - lf) / s),
  // rises with u from at most 0.5 at u = 0 to at least 0.5 at u = lf; bisected to where it is 0.5.
  const auto below = [&](double u) { return (1.0 - h) * truncated_normal_cdf(u / s) + h * truncated_normal_cdf((u - lf) / s); };
  double lo = 0.0, hi = lf;
  for (int i = 0; i < 200 && lo < hi; ++i) {
    const double mid = 0.5 * (lo + hi);
    if (mid <= lo || mid >= hi) break;
    (below(mid) < 0.5 ? lo : hi) = mid;
  }
  return m * std::exp(-0.5 * (lo + hi));
}

PixelMaps::PixelMaps(const SensorStageConfig& config, double nominal_length_s)
    : cfg_(config),
      nominal_length_s_(nominal_length_s),
      width_(config.camera.width_px),
      height_(config.camera.height_px),
      layout_(config.sensor.preset, config.camera.height_px) {
  for (int s = 0; s < layout_.sections(); ++s) sections_.push_back({layout_.section_begin(s), layout_.section_rows(s)});
  temp_factor_ = temperature_factor(config.sensor.temperature_C);
  main_dcr_cps_[0] = dcr_main_median(config.sensor.pixel_A);
  main_dcr_cps_[1] = dcr_main_median(config.sensor.pixel_B);
  if (!config.sensor.skew) return;

  const GateConfig& g = config.sensor.gate;
  const double skew_sigma = g.skew_fwhm_s / kFwhmPerSigma, len_sigma = g.length_fwhm_s / kFwhmPerSigma;
  skew_sigma_r_ = skew_sigma * std::sqrt(1.0 - kSkewPatternShare);
  len_sigma_r_ = len_sigma * std::sqrt(1.0 - kLengthPatternShare);
  double smin = 0, smax = 0, lmax = 0;
  bool first = true;
  for (SectionStats& s : sections_) {
    const PatternSums sums = pattern_sums(width_, s.height);
    const double s1 = sums.skew, s2 = sums.skew_squared, l1 = sums.length, l2 = sums.length_squared;
    const double n = static_cast<double>(s.height) * width_;
    s.skew_mean = s1 / n;
    s.len_mean = l1 / n;
    const double ssd = std::sqrt(std::max(0.0, s2 / n - s.skew_mean * s.skew_mean));
    const double lsd = std::sqrt(std::max(0.0, l2 / n - s.len_mean * s.len_mean));
    // A one-row or one-pixel section has no pattern: the random part then carries the whole spread.
    s.skew_scale = ssd > 1e-12 ? skew_sigma * std::sqrt(kSkewPatternShare) / ssd : 0.0;
    s.len_scale = lsd > 1e-12 ? len_sigma * std::sqrt(kLengthPatternShare) / lsd : 0.0;
    if (s.skew_scale == 0.0) skew_sigma_r_ = skew_sigma;
    if (s.len_scale == 0.0) len_sigma_r_ = len_sigma;
    // Bounds of the patterns over [0, 1]^2 from a 65 x 65 scan (they are smooth; 1 % slack is added below).
    double pmin = 1e300, pmax = -1e300, qmax = -1e300;
    for (int i = 0; i <= 64; ++i)
      for (int j = 0; j <= 64; ++j) {
        pmin = std::min(pmin, skew_pattern(i / 64.0, j / 64.0));
        pmax = std::max(pmax, skew_pattern(i / 64.0, j / 64.0));
        qmax = std::max(qmax, length_pattern(i / 64.0, j / 64.0));
      }
    const double lo = (pmin - s.skew_mean) * s.skew_scale, hi = (pmax - s.skew_mean) * s.skew_scale;
    const double lhi = (qmax - s.len_mean) * s.len_scale;
    smin = first ? lo : std::min(smin, lo);
    smax = first ? hi : std::max(smax, hi);
    lmax = first ? lhi : std::max(lmax, lhi);
    first = false;
  }
  // Slack of 1 % of the spread covers the coarse scan of the pattern's extremes.
  min_skew_ = smin - kTruncate * skew_sigma_r_ - 0.01 * skew_sigma;
  max_skew_ = smax + kTruncate * skew_sigma_r_ + 0.01 * skew_sigma;
  max_dL_ = std::max(0.0, lmax + kTruncate * len_sigma_r_ + 0.01 * len_sigma);
}


void PixelMaps::set_gate_maps(std::vector<float> skew_ps, std::vector<float> length_ps) {
  const size_t n = static_cast<size_t>(width_) * static_cast<size_t>(height_);
  if (skew_ps.size() != n || length_ps.size() != n)
    throw Error("sensor.gate.maps_exr: expected skew_ps and length_ps maps of " + std::to_string(width_) + " x " +
                std::to_string(height_) + " pixels, found " + std::to_string(skew_ps.size()) + " and " +
                std::to_string(length_ps.size()) + " values");
  double smin = 1e300, smax = -1e300, lmax = -1e300;
  for (size_t i = 0; i < n; ++i) {
    if (!std::isfinite(skew_ps[i]) || !(length_ps[i] > 0.0f))
      throw Error("sensor.gate.maps_exr: pixel " + std::to_string(i) +
                  ": expected a finite skew_ps and a positive length_ps");
    smin = std::min(smin, static_cast<double>(skew_ps[i]) * kPs);
    smax = std::max(smax, static_cast<double>(skew_ps[i]) * kPs);
    lmax = std::max(lmax, static_cast<double>(length_ps[i]) * kPs - nominal_length_s_);
  }
  user_skew_ps_ = std::move(skew_ps);
  user_length_ps_ = std::move(length_ps);
  if (cfg_.sensor.skew) {
    min_skew_ = smin;
    max_skew_ = smax;
    max_dL_ = std::max(0.0, lmax);
  }
}

PixelParams PixelMaps::at(int x, int y) const {
  PixelParams p;
  p.type = layout_.type_of_row(y);
  p.section = section_of_row(y);
  const PixelTypeConfig& tc = p.type == 0 ? cfg_.sensor.pixel_A : cfg_.sensor.pixel_B;
  const uint64_t idx = streams::pixel_index(x, y, width_);
  const uint64_t seed = cfg_.chip_seed;
  if (cfg_.sensor.skew) {
    if (!user_skew_ps_.empty()) {
      p.skew_s = static_cast<double>(user_skew_ps_[idx]) * kPs;
      p.dL_s = static_cast<double>(user_length_ps_[idx]) * kPs - nominal_length_s_;
    } else {
      const SectionStats& s = section(y);
      const double u = coord(x, width_), v = 1.0 - coord(y - s.y0, s.height);
      Rng rs = streams::chip_map(seed, idx, streams::Map::Skew), rl = streams::chip_map(seed, idx, streams::Map::Length);
      p.skew_s = (skew_pattern(u, v) - s.skew_mean) * s.skew_scale + skew_sigma_r_ * truncated_normal(rs);
      p.dL_s = (length_pattern(u, v) - s.len_mean) * s.len_scale + len_sigma_r_ * truncated_normal(rl);
    }
  }
  if (cfg_.sensor.dark_counts) {
    Rng rd = streams::chip_map(seed, idx, streams::Map::Dcr);
    const bool hot = rd.next_double() < tc.hot_pixel_fraction;
    const double z = truncated_normal(rd);
    p.dcr_cps = main_dcr_cps_[p.type == 0 ? 0 : 1] * (hot ? tc.hot_pixel_factor : 1.0) * std::exp(tc.dcr_log_sigma * z) *
                temp_factor_;
  }
  if (cfg_.sensor.pdp_nonuniformity) {
    Rng rp = streams::chip_map(seed, idx, streams::Map::Pdp);
    p.pdp_scale = std::max(0.0, 1.0 + tc.pdp_nonuniformity * truncated_normal(rp));
  }
  return p;
}

}  // namespace spadgen::sensor
