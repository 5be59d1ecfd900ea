#include "sensor/model/gate.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <sstream>

#include "core/error.h"
#include "core/units.h"
#include "sensor/model/csv.h"

namespace spadgen::sensor {
namespace {

// Gaussian tails are cut where the CDF is below 1e-15: far below any knot error.
constexpr double kTailSigmas = 8.0;
// A linear edge never becomes a true step: a zero rise time with no instrument response would make the
// slope changes infinite. 0.1 ps is far below any time bin.
constexpr double kMinRampWidth = 0.1e-12;
// The fine grid has at most this many points: its step is gate.grid_s (sensor.gate.grid_ps), or
// span / kMaxFinePoints where that is coarser.
constexpr double kMaxFinePoints = 12000.0;
// Fraction of the 10-90 % interval of a standard normal CDF: 2 * 1.2815515655 sigma.
constexpr double kTenNinetySigmas = 2.563103131;

double normal_cdf(double z) { return 0.5 * std::erfc(-z / std::sqrt(2.0)); }

// One edge of the gate before the instrument response: a normal CDF (smooth), or piecewise linear.
struct BaseEdge {
  bool smooth = false;
  double centre = 0.0, sigma = 0.0;  // smooth
  Edge pwl;                          // linear or table
  double begin() const { return smooth ? centre - kTailSigmas * sigma : pwl.u.front(); }
  double end() const { return smooth ? centre + kTailSigmas * sigma : pwl.u.back(); }
  double v_end() const { return smooth ? 1.0 : pwl.v_end; }
  double eval(double t) const { return smooth ? normal_cdf((t - centre) / sigma) : pwl.value(t); }
};

BaseEdge parametric_edge(GateEdge shape, double centre, double ten_ninety_s) {
  BaseEdge e;
  if (shape == GateEdge::Smooth && ten_ninety_s > 0.0) {
    e.smooth = true;
    e.centre = centre;
    e.sigma = ten_ninety_s / kTenNinetySigmas;
    return e;
  }
  // linear: 10 % to 90 % in ten_ninety_s means 0 to 100 % in ten_ninety_s / 0.8
  const double w = std::max(ten_ninety_s / 0.8, kMinRampWidth);
  e.pwl.u = {centre - 0.5 * w, centre + 0.5 * w};
  e.pwl.y = {0.0, 1.0};
  e.pwl.v_end = 1.0;
  return e;
}

double interp(const std::vector<double>& x, const std::vector<double>& y, double t) {
  if (t <= x.front()) return y.front();
  if (t >= x.back()) return y.back();
  const size_t i = static_cast<size_t>(std::upper_bound(x.begin(), x.end(), t) - x.begin());
  const double w = (t - x[i - 1]) / (x[i] - x[i - 1]);
  return y[i - 1] + w * (y[i] - y[i - 1]);
}

struct TableGate {
  BaseEdge rise, fall;
  double length_s = 0.0;
  double rise_s = 0.0, fall_s = 0.0;  // 10-90 % of the peak, first crossings; 90-10 %, last ones
};

// A measured gate profile: normalised to its maximum, extended to 0 over one sample interval at each end when
// it does not start or end at 0, and split at the middle of its 50 % crossings into a rising part and a
// falling ("drop") part, so that the falling part can be moved by the pixel's length deviation.
TableGate table_gate(const std::string& path) {
  const std::string key = "sensor.gate.profile_csv";
  Table2 t = read_table_csv(path, key);
  double peak = 0.0;
  for (size_t i = 0; i < t.y.size(); ++i) {
    if (!(t.y[i] >= 0.0))
      throw Error(key + ": '" + path + "' row " + std::to_string(i + 1) + ": the response must be >= 0");
    peak = std::max(peak, t.y[i]);
  }
  if (!(peak > 0.0)) throw Error(key + ": '" + path + "': the response is zero everywhere; expected a gate profile");
  std::vector<double> x, y;
  const double step0 = t.x[1] - t.x[0], step1 = t.x[t.x.size() - 1] - t.x[t.x.size() - 2];
  if (t.y.front() != 0.0) {
    x.push_back((t.x.front() - step0) * kPs);
    y.push_back(0.0);
  }
  for (size_t i = 0; i < t.x.size(); ++i) {
    x.push_back(t.x[i] * kPs);
    y.push_back(t.y[i] / peak);
  }
  if (t.y.back() != 0.0) {
    x.push_back((t.x.back() + step1) * kPs);
    y.push_back(0.0);
  }
  size_t first = 0, last = y.size() - 1;
  while (y[first] < 0.5) ++first;
  while (y[last] < 0.5) --last;
  const double t_r = x[first - 1] + (0.5 - y[first - 1]) / (y[first] - y[first - 1]) * (x[first] - x[first - 1]);
  const double t_f = x[last] + (y[last] - 0.5) / (y[last] - y[last + 1]) * (x[last + 1] - x[last]);
  // where y first reaches `level` going up (rising), or last leaves it going down
  const auto crossing_at = [&](double level, bool rising) {
    if (rising) {
      size_t i = 0;
      while (y[i] < level) ++i;
      return x[i - 1] + (level - y[i - 1]) / (y[i] - y[i - 1]) * (x[i] - x[i - 1]);
    }
    size_t i = y.size() - 1;
    while (y[i] < level) --i;
    return x[i] + (y[i] - level) / (y[i] - y[i + 1]) * (x[i + 1] - x[i]);
  };
  const double t_mid = 0.5 * (t_r + t_f);
  const double f_mid = interp(x, y, t_mid);
  TableGate g;
  g.length_s = t_f - t_r;
  g.rise_s = crossing_at(0.9, true) - crossing_at(0.1, true);
  g.fall_s = crossing_at(0.1, false) - crossing_at(0.9, false);
  Edge& r = g.rise.pwl;
  Edge& d = g.fall.pwl;
  for (size_t i = 0; i < x.size() && x[i] < t_mid; ++i) {
    r.u.push_back(x[i]);
    r.y.push_back(y[i]);
  }
  r.u.push_back(t_mid);
  r.y.push_back(f_mid);
  d.u.push_back(t_mid);
  d.y.push_back(0.0);
  for (size_t i = 0; i < x.size(); ++i)
    if (x[i] > t_mid) {
      d.u.push_back(x[i]);
      d.y.push_back(f_mid - y[i]);
    }
  r.v_end = d.v_end = f_mid;
  return g;
}

// The IRF support, to size the fine grid before the IRF itself is built.
double irf_span(const GateConfig& gate, const LaserConfig& laser) {
  const double sj = gate.jitter_fwhm_s / kFwhmPerSigma;
  if (laser.pulse_shape_csv.empty()) return 2.0 * kTailSigmas * std::hypot(laser.pulse_fwhm_s / kFwhmPerSigma, sj);
  const Table2 t = read_table_csv(laser.pulse_shape_csv, "laser.pulse_shape_csv");
  return (t.x.back() - t.x.front()) * kPs + 2.0 * kTailSigmas * sj;
}

std::vector<double> gaussian_weights(double sigma, double dx, int64_t& k0) {
  const auto half = static_cast<int64_t>(std::ceil(kTailSigmas * sigma / dx));
  k0 = -half;
  std::vector<double> w(static_cast<size_t>(2 * half + 1));
  double sum = 0.0;
  for (int64_t k = -half; k <= half; ++k) {
    const double u = static_cast<double>(k) * dx / sigma;
    sum += w[static_cast<size_t>(k + half)] = std::exp(-0.5 * u * u);
  }
  for (double& v : w) v /= sum;
  return w;
}

// The fine reference of an edge: y_i = sum_k w_k E(x_i + u_k) on the lattice x = i dx.
Sampled convolve_edge(const BaseEdge& e, const Sampled& irf) {
  const double dx = irf.dx;
  const auto k0 = static_cast<int64_t>(std::llround(irf.x0 / dx));
  const auto nk = static_cast<int64_t>(irf.y.size());
  const double u_lo = irf.x0, u_hi = irf.x0 + static_cast<double>(nk - 1) * dx;
  const auto i_first = static_cast<int64_t>(std::floor((e.begin() - u_hi) / dx)) - 2;
  const auto i_last = static_cast<int64_t>(std::ceil((e.end() - u_lo) / dx)) + 2;
  const int64_t n = i_last - i_first + 1;
  std::vector<double> samples(static_cast<size_t>(n + nk - 1));
  for (int64_t m = 0; m < n + nk - 1; ++m)
    samples[static_cast<size_t>(m)] = e.eval(static_cast<double>(i_first + k0 + m) * dx);
  Sampled out;
  out.x0 = static_cast<double>(i_first) * dx;
  out.dx = dx;
  out.y.assign(static_cast<size_t>(n), 0.0);
  // Eight outputs at a time, each its own sum in the order of k (the same operations as one output at a
  // time, so the same bits: this file is compiled without FMA contraction, sensor/CMakeLists.txt), which the
  // compiler vectorises across the eight; blocks of them in parallel (each output independent of the others).
  constexpr int64_t kBlock = 8;
  const int64_t blocks = n / kBlock;
  tbb::parallel_for(tbb::blocked_range<int64_t>(0, blocks, 32), [&](const tbb::blocked_range<int64_t>& r) {
    for (int64_t b = r.begin(); b < r.end(); ++b) {
      const double* s = samples.data() + b * kBlock;
      double acc[kBlock] = {};
      for (int64_t k = 0; k < nk; ++k) {
        const double w = irf.y[static_cast<size_t>(k)];
        for (int64_t j = 0; j < kBlock; ++j) acc[j] += w * s[k + j];
      }
      for (int64_t j = 0; j < kBlock; ++j) out.y[static_cast<size_t>(b * kBlock + j)] = acc[j];
    }
  });
  for (int64_t i = blocks * kBlock; i < n; ++i) {
    const double* s = samples.data() + i;
    double acc = 0.0;
    for (int64_t k = 0; k < nk; ++k) acc += irf.y[static_cast<size_t>(k)] * s[k];
    out.y[static_cast<size_t>(i)] = acc;
  }
  out.y.front() = 0.0;
  out.y.back() = e.v_end();
  return out;
}

// Places m knots on the fine grid with density proportional to sqrt|f''| (which equalises the linear
// interpolation error h^2 |f''| / 8 between knots), plus a small floor so tails are not left bare.
// Returns the edge and its max interpolation error against the fine grid.
Edge fit_knots(const Sampled& f, double v_end, int m, double& max_err) {
  const size_t n = f.y.size();
  std::vector<double> w(n, 0.0);
  double wmax = 0.0;
  for (size_t i = 1; i + 1 < n; ++i) {
    w[i] = std::sqrt(std::abs(f.y[i + 1] - 2.0 * f.y[i] + f.y[i - 1]));
    wmax = std::max(wmax, w[i]);
  }
  const double floor_w = 1e-3 * wmax;
  std::vector<double> cum(n, 0.0);
  for (size_t i = 1; i < n; ++i) cum[i] = cum[i - 1] + 0.5 * (w[i - 1] + w[i]) + floor_w;
  std::vector<size_t> idx{0};
  const int count = std::max(2, std::min<int>(m, static_cast<int>(n)));
  size_t i = 0;
  for (int j = 1; j < count - 1; ++j) {
    const double target = cum.back() * j / (count - 1);
    while (i + 1 < n && cum[i] < target) ++i;
    if (i > idx.back() && i < n - 1) idx.push_back(i);
  }
  idx.push_back(n - 1);
  Edge e;
  e.v_end = v_end;
  for (size_t k : idx) {
    e.u.push_back(f.x0 + static_cast<double>(k) * f.dx);
    e.y.push_back(f.y[k]);
  }
  e.y.front() = 0.0;
  e.y.back() = v_end;
  max_err = 0.0;
  for (size_t k = 0; k + 1 < idx.size(); ++k)
    for (size_t q = idx[k]; q <= idx[k + 1]; ++q) {
      const double t = static_cast<double>(q - idx[k]) / static_cast<double>(idx[k + 1] - idx[k]);
      max_err = std::max(max_err, std::abs(e.y[k] + t * (e.y[k + 1] - e.y[k]) - f.y[q]));
    }
  return e;
}

double fwhm_of(const Sampled& s) {
  if (s.y.empty()) return 0.0;
  const auto it = std::max_element(s.y.begin(), s.y.end());
  const double half = 0.5 * *it;
  size_t a = static_cast<size_t>(it - s.y.begin()), b = a;
  while (a > 0 && s.y[a - 1] >= half) --a;
  while (b + 1 < s.y.size() && s.y[b + 1] >= half) ++b;
  double left = static_cast<double>(a), right = static_cast<double>(b);
  if (a > 0) left -= (s.y[a] - half) / (s.y[a] - s.y[a - 1]);
  if (b + 1 < s.y.size()) right += (s.y[b] - half) / (s.y[b] - s.y[b + 1]);
  return (right - left) * s.dx;
}

}  // namespace

double Edge::value(double t) const {
  if (t <= u.front()) return 0.0;
  if (t >= u.back()) return v_end;
  return interp(u, y, t);
}

double Edge::integral() const {
  double s = 0.0;
  for (size_t i = 1; i < u.size(); ++i) s += 0.5 * (y[i] + y[i - 1]) * (u[i] - u[i - 1]);
  return s;
}

double Sampled::at(double x) const {
  if (y.empty()) return 0.0;
  const double f = (x - x0) / dx;
  if (f < 0.0 || f > static_cast<double>(y.size() - 1)) return 0.0;
  const auto i = std::min(static_cast<size_t>(f), y.size() - 2);
  const double w = f - static_cast<double>(i);
  return y[i] + w * (y[i + 1] - y[i]);
}

Sampled build_irf(const GateConfig& gate, const LaserConfig& laser, double dx) {
  const double sj = gate.jitter_fwhm_s / kFwhmPerSigma;
  Sampled irf;
  irf.dx = dx;
  int64_t k0 = 0;
  if (laser.pulse_shape_csv.empty()) {
    const double s = std::hypot(laser.pulse_fwhm_s / kFwhmPerSigma, sj);
    if (s > 0.0) irf.y = gaussian_weights(s, dx, k0);
    irf.x0 = static_cast<double>(k0) * dx;
    return irf;
  }
  const std::string key = "laser.pulse_shape_csv";
  Table2 t = read_table_csv(laser.pulse_shape_csv, key);
  for (size_t i = 0; i < t.y.size(); ++i)
    if (!(t.y[i] >= 0.0))
      throw Error(key + ": '" + laser.pulse_shape_csv + "' row " + std::to_string(i + 1) + ": power must be >= 0");
  // A laser pulse lasts at most a microsecond: a table spanning 1e300 ps overflowed its centroid below
  // (an infinite centre, then a signed overflow: undefined behaviour, found by the sanitizers).
  if (const double span = t.x.back() - t.x.front(); !(span <= 1e6)) {
    std::ostringstream o;
    o << span;
    throw Error(key + ": '" + laser.pulse_shape_csv + "': the pulse spans " + o.str() + " ps; expected at most 1e+06 ps (1 us)");
  }
  for (double& v : t.x) v *= kPs;
  // Centroid of the piecewise-linear table, so that the pulse's mean arrival is the emission instant the
  // renderer uses (as for the Gaussian pulse).
  double m0 = 0.0, m1 = 0.0;
  for (size_t i = 1; i < t.x.size(); ++i) {
    const double h = t.x[i] - t.x[i - 1], a = t.y[i - 1], b = t.y[i];
    m0 += 0.5 * h * (a + b);
    m1 += h * (a * (2.0 * t.x[i - 1] + t.x[i]) + b * (t.x[i - 1] + 2.0 * t.x[i])) / 6.0;
  }
  if (!(m0 > 0.0)) throw Error(key + ": '" + laser.pulse_shape_csv + "': the pulse has zero energy");
  const double c = m1 / m0;
  const auto lo = static_cast<int64_t>(std::floor((t.x.front() - c) / dx));
  const auto hi = static_cast<int64_t>(std::ceil((t.x.back() - c) / dx));
  std::vector<double> p;
  for (int64_t k = lo; k <= hi; ++k) {
    const double u = static_cast<double>(k) * dx + c;
    p.push_back(u < t.x.front() || u > t.x.back() ? 0.0 : interp(t.x, t.y, u));
  }
  if (sj > 0.0) {
    int64_t g0 = 0;
    const std::vector<double> g = gaussian_weights(sj, dx, g0);
    std::vector<double> q(p.size() + g.size() - 1, 0.0);
    for (size_t i = 0; i < p.size(); ++i)
      for (size_t j = 0; j < g.size(); ++j) q[i + j] += p[i] * g[j];
    p.swap(q);
    k0 = lo + g0;
  } else {
    k0 = lo;
  }
  double sum = 0.0;
  for (double v : p) sum += v;
  for (double& v : p) v /= sum;
  irf.y = std::move(p);
  irf.x0 = static_cast<double>(k0) * dx;
  return irf;
}

GateShape build_gate_shape(const GateConfig& gate, const LaserConfig& laser) {
  const int knots_per_edge = gate.knots_per_edge;
  if (knots_per_edge < 2) throw Error("sensor: the gate needs at least 2 knots per edge, found " + std::to_string(knots_per_edge));
  BaseEdge rise, fall;
  GateShape g;
  if (!gate.profile_csv.empty()) {
    TableGate tg = table_gate(gate.profile_csv);
    rise = tg.rise;
    fall = tg.fall;
    g.nominal_length_s = tg.length_s;
    g.rise_s = tg.rise_s, g.fall_s = tg.fall_s;
  } else {
    rise = parametric_edge(gate.edge_shape, 0.0, gate.rise_s);
    fall = parametric_edge(gate.edge_shape, gate.length_s, gate.fall_s);
    g.nominal_length_s = gate.length_s;
    g.rise_s = gate.rise_s, g.fall_s = gate.fall_s;
  }
  g.plateau = rise.v_end();
  if (!(gate.grid_s > 0.0)) throw Error("sensor.gate.grid_ps: the fine grid's step must be > 0");

  const double span = std::max(rise.end() - rise.begin(), fall.end() - fall.begin()) + irf_span(gate, laser);
  const double dx = std::max(gate.grid_s, span / kMaxFinePoints);
  g.grid_s = dx;
  Sampled irf = build_irf(gate, laser, dx);
  g.irf_fwhm_s = irf.y.empty() ? 0.0 : fwhm_of(irf);
  if (laser.pulse_shape_csv.empty())  // exact for the Gaussian (the sampled width is within dx of it)
    g.irf_fwhm_s = kFwhmPerSigma * std::hypot(laser.pulse_fwhm_s / kFwhmPerSigma, gate.jitter_fwhm_s / kFwhmPerSigma);

  if (irf.y.empty() && !rise.smooth && !fall.smooth) {
    g.rise = rise.pwl;
    g.fall = fall.pwl;
    g.exact = true;
    g.knots_per_edge = static_cast<int>(std::max(g.rise.u.size(), g.fall.u.size()));
  } else {
    if (irf.y.empty()) irf.y = {1.0};  // a delta on the lattice
    double e1 = 0.0, e2 = 0.0;
    g.rise_fine = convolve_edge(rise, irf);
    g.fall_fine = convolve_edge(fall, irf);
    g.rise = fit_knots(g.rise_fine, g.plateau, knots_per_edge, e1);
    g.fall = fit_knots(g.fall_fine, g.plateau, knots_per_edge, e2);
    // (of the open gate, the peak 1 the table is normalised to: its middle's level, which divided them, is
    // 0 in a gate of two humps, and the errors were infinite)
    g.max_knot_error = std::max(e1, e2);
    double curvature = 0.0;
    for (const Sampled* f : {&g.rise_fine, &g.fall_fine})
      for (size_t i = 1; i + 1 < f->y.size(); ++i)
        curvature = std::max(curvature, std::fabs(f->y[i - 1] - 2.0 * f->y[i] + f->y[i + 1]));
    g.max_grid_error = curvature / 8.0;
    g.knots_per_edge = static_cast<int>(std::max(g.rise.u.size(), g.fall.u.size()));
  }
  // integral over all t of rise(t) - fall(t), both constant v_end after their last knot
  g.open_time_s = g.rise.integral() - g.fall.integral() + g.plateau * (g.fall.u.back() - g.rise.u.back());
  return g;
}

}  // namespace spadgen::sensor
