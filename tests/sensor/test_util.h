// Helpers shared by the sensor tests: configurations, tiles built from whole images, statistics.
#pragma once
#include <cmath>
#include <functional>
#include <limits>
#include <vector>

#include "core/config.h"
#include "core/tile.h"
#include "sensor/sensor.h"

namespace spadgen::sensor::testing {

// Two-sided z bound for a false-alarm rate of 1e-6 per check.
inline constexpr double kZ = 4.892;

inline PixelTypeConfig paper_pixel_B() { return PixelTypeConfig::paper_pixel_B(); }

inline SensorStageConfig sweep_config(int width = 48, int height = 24) {
  SensorStageConfig c;
  c.chip_seed = 12345;
  c.noise_seed = 12345;
  c.camera.width_px = width;
  c.camera.height_px = height;
  c.sensor.pixel_B = paper_pixel_B();
  c.acquisition.mode = AcquisitionMode::GateSweep;
  return c;
}

// A whole image of per-pixel transients/ambient/laser totals, cut into TransientTiles on demand.
struct Image {
  int width = 0, height = 0;
  TimeAxis axis;
  std::vector<float> transient;  // [(y * width + x) * bins + t]
  std::vector<float> ambient;    // photons per second
  std::vector<double> laser_total;

  Image(int w, int h, const TimeAxis& a)
      : width(w), height(h), axis(a),
        transient(static_cast<size_t>(w) * static_cast<size_t>(h) * static_cast<size_t>(a.bins), 0.0f),
        ambient(static_cast<size_t>(w) * static_cast<size_t>(h), 0.0f),
        laser_total(static_cast<size_t>(w) * static_cast<size_t>(h), 0.0) {}
  float* pixel(int x, int y) {
    return transient.data() + (static_cast<size_t>(y) * static_cast<size_t>(width) + static_cast<size_t>(x)) * static_cast<size_t>(axis.bins);
  }
  TransientTile tile(const PixelRect& r, int halo) const {
    TransientTile t;
    t.rect = r;
    t.data_rect = grow_clipped(r, halo, width, height);
    t.axis = axis;
    const auto bins = static_cast<size_t>(axis.bins);
    for (int y = t.data_rect.y0; y < t.data_rect.y1(); ++y)
      for (int x = t.data_rect.x0; x < t.data_rect.x1(); ++x) {
        const size_t i = static_cast<size_t>(y) * static_cast<size_t>(width) + static_cast<size_t>(x);
        t.transient.insert(t.transient.end(), transient.begin() + static_cast<std::ptrdiff_t>(i * bins),
                           transient.begin() + static_cast<std::ptrdiff_t>((i + 1) * bins));
        t.ambient_rate.push_back(ambient[i]);
        t.laser_total.push_back(laser_total[i]);
        t.out_of_window.push_back(0.0);
      }
    return t;
  }
};

// Regularised upper incomplete gamma Q(a, x) (Numerical Recipes' series / continued fraction).
inline double gamma_q(double a, double x) {
  if (x <= 0.0) return 1.0;
  const double gln = std::lgamma(a);
  if (x < a + 1.0) {
    double ap = a, sum = 1.0 / a, del = sum;
    for (int n = 0; n < 100000; ++n) {
      ap += 1.0;
      del *= x / ap;
      sum += del;
      if (std::abs(del) < std::abs(sum) * 1e-15) break;
    }
    return 1.0 - sum * std::exp(-x + a * std::log(x) - gln);
  }
  double b = x + 1.0 - a, c = 1.0 / 1e-300, d = 1.0 / b, h = d;
  for (int i = 1; i < 100000; ++i) {
    const double an = -i * (i - a);
    b += 2.0;
    d = an * d + b;
    if (std::abs(d) < 1e-300) d = 1e-300;
    c = b + an / c;
    if (std::abs(c) < 1e-300) c = 1e-300;
    d = 1.0 / d;
    const double del = d * c;
    h *= del;
    if (std::abs(del - 1.0) < 1e-15) break;
  }
  return std::exp(-x + a * std::log(x) - gln) * h;
}

// Chi-square goodness of fit of observed counts against expected probabilities; cells with expected
// counts below 5 are merged into their neighbour. Returns the p-value.
inline double chi_square_p(const std::vector<double>& observed, const std::vector<double>& prob, double total) {
  std::vector<double> o, e;
  double oa = 0.0, ea = 0.0;
  for (size_t i = 0; i < observed.size(); ++i) {
    oa += observed[i];
    ea += prob[i] * total;
    if (ea >= 5.0) {
      o.push_back(oa);
      e.push_back(ea);
      oa = ea = 0.0;
    }
  }
  if (!e.empty()) {
    o.back() += oa;
    e.back() += ea;
  }
  double chi2 = 0.0;
  for (size_t i = 0; i < o.size(); ++i) chi2 += (o[i] - e[i]) * (o[i] - e[i]) / e[i];
  const double df = static_cast<double>(o.size()) - 1.0;
  if (df < 1.0) return 1.0;
  return gamma_q(0.5 * df, 0.5 * chi2);
}

inline std::vector<double> binomial_pmf(int n, double p) {
  std::vector<double> pmf(static_cast<size_t>(n) + 1);
  for (int k = 0; k <= n; ++k)
    pmf[static_cast<size_t>(k)] = std::exp(std::lgamma(n + 1.0) - std::lgamma(k + 1.0) - std::lgamma(n - k + 1.0) +
                                           (k > 0 ? k * std::log(p) : 0.0) + (n - k > 0 ? (n - k) * std::log1p(-p) : 0.0));
  return pmf;
}

// Two-sided exact Poisson test: is x consistent with mean mu at false-alarm rate alpha?
inline bool poisson_consistent(double x, double mu, double alpha) {
  double cdf = 0.0, pmf = std::exp(-mu);
  double below = 0.0;  // P(X <= x)
  for (int k = 0; k <= static_cast<int>(x); ++k) {
    if (k > 0) pmf *= mu / k;
    cdf += pmf;
  }
  below = cdf;
  const double above = 1.0 - (cdf - pmf) ;  // P(X >= x)
  return below > alpha / 2 && above > alpha / 2;
}

// Two-sided exact binomial test: is the count x consistent with Binomial(n, p) at false-alarm rate alpha? The
// tail on x's side of the mean, summed from x outwards (where a z-test's normal tail is no bound: a hot pixel
// expecting 0.04 frames without a count that has 1 is 4.9 of its standard deviations off, 4 % of the time).
inline bool binomial_consistent(double x, double n, double p, double alpha) {
  if (!(p > 0.0)) return x == 0.0;
  if (!(p < 1.0)) return x == n;
  const double log_pmf = std::lgamma(n + 1.0) - std::lgamma(x + 1.0) - std::lgamma(n - x + 1.0) + x * std::log(p) + (n - x) * std::log1p(-p);
  const bool lower = x <= n * p;
  double term = std::exp(log_pmf), tail = 0.0;
  for (double k = x; k >= 0.0 && k <= n && term > 0.0; k += lower ? -1.0 : 1.0) {
    tail += term;
    if (term < tail * 1e-17) break;
    term *= lower ? k / (n - k + 1.0) * (1.0 - p) / p : (n - k) / (k + 1.0) * p / (1.0 - p);
  }
  return tail > alpha / 2;
}

}  // namespace spadgen::sensor::testing
