// Gate profile, instrument response and the O(T + K) gate response.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <unistd.h>
#include <vector>

#include "core/error.h"
#include "core/rng.h"
#include "core/units.h"
#include "sensor/model/gate.h"
#include "sensor/response/gate_response.h"
#include "sensor/model/pixel_maps.h"
#include "sensor/sensor.h"
#include "test_util.h"

namespace spadgen::sensor {
namespace {

using testing::sweep_config;

double Phi(double z) { return 0.5 * std::erfc(-z / std::sqrt(2.0)); }

// The closed form of a smooth (normal-CDF) gate convolved with a Gaussian instrument response.
double smooth_gate_closed_form(const GateConfig& g, const LaserConfig& l, double t, double dL) {
  const double s_irf2 = std::pow(l.pulse_fwhm_s / kFwhmPerSigma, 2) + std::pow(g.jitter_fwhm_s / kFwhmPerSigma, 2);
  const double sr = std::sqrt(std::pow(g.rise_s / 2.563103131, 2) + s_irf2);
  const double sf = std::sqrt(std::pow(g.fall_s / 2.563103131, 2) + s_irf2);
  return Phi(t / sr) - Phi((t - g.length_s - dL) / sf);
}

// Brute force O(T K): h(tau) = sum_i g_i / dt * integral over bin i of f(t - tau) dt, with f the piecewise-
// linear knot function integrated exactly (trapezoids between the knots that fall inside each bin).
std::vector<double> brute_force(const GateShape& gs, const std::vector<float>& g, const TimeAxis& ax,
                                const std::vector<double>& taus, double dL) {
  std::vector<double> h;
  for (double tau : taus) {
    double acc = 0.0;
    for (int64_t i = 0; i < ax.bins; ++i) {
      if (g[static_cast<size_t>(i)] == 0.0f) continue;
      const double a = ax.bin_start_s(i) - tau, b = a + ax.bin_width_s;
      std::vector<double> pts{a, b};
      for (double u : gs.rise.u)
        if (u > a && u < b) pts.push_back(u);
      for (double u : gs.fall.u)
        if (u + dL > a && u + dL < b) pts.push_back(u + dL);
      std::sort(pts.begin(), pts.end());
      double integral = 0.0;
      for (size_t j = 1; j < pts.size(); ++j)
        integral += 0.5 * (gs.value(pts[j - 1], dL) + gs.value(pts[j], dL)) * (pts[j] - pts[j - 1]);
      acc += g[static_cast<size_t>(i)] * integral / ax.bin_width_s;
    }
    h.push_back(acc);
  }
  return h;
}

std::vector<double> fast(const GateShape& gs, const std::vector<float>& g, const TimeAxis& ax,
                         const std::vector<double>& taus, double dL) {
  TransientPrefix p;
  std::vector<double> h(taus.size(), 0.0);
  if (!p.build(g.data(), ax.bins)) return h;
  const EdgeBins r = edge_in_bins(gs.rise, ax.bin_width_s), f = edge_in_bins(gs.fall, ax.bin_width_s);
  const double b0 = (taus[0] - ax.start_s) / ax.bin_width_s, step = (taus[1] - taus[0]) / ax.bin_width_s;
  const int K = static_cast<int>(taus.size());
  accumulate_edge_response(p, r, b0, step, K, 1.0, h.data());
  accumulate_edge_response(p, f, b0 + dL / ax.bin_width_s, step, K, -1.0, h.data());
  return h;
}

TEST(Gate, LinearEdgesWithoutInstrumentResponseAreExact) {
  GateConfig g;
  g.edge_shape = GateEdge::Linear;
  g.jitter_fwhm_s = 0.0;
  LaserConfig l;
  l.pulse_fwhm_s = 0.0;
  const GateShape s = build_gate_shape(g, l);
  EXPECT_TRUE(s.exact);
  EXPECT_EQ(s.knots_per_edge, 2);
  const double w = g.rise_s / 0.8;
  EXPECT_DOUBLE_EQ(s.value(0.0, 0.0), 0.5);
  EXPECT_NEAR(s.value(g.length_s, 0.0), 0.5, 1e-12);
  EXPECT_NEAR(s.value(0.25 * w, 0.0), 0.75, 1e-12);
  EXPECT_NEAR(s.value(-0.5 * g.rise_s, 0.0), 0.1, 1e-12);  // 10 % to 90 % takes rise_s
  EXPECT_NEAR(s.value(0.5 * g.rise_s, 0.0), 0.9, 1e-12);
  EXPECT_NEAR(s.open_time_s, g.length_s, 1e-18);
  EXPECT_NEAR(s.open_time(50e-12), g.length_s + 50e-12, 1e-18);
}

// The response engine is exact for any knot function; a linear-edge gate without IRF is exact itself.
TEST(Gate, FastResponseEqualsBruteForce) {
  for (const GateEdge shape : {GateEdge::Linear, GateEdge::Smooth}) {
    GateConfig g;
    g.edge_shape = shape;
    g.jitter_fwhm_s = shape == GateEdge::Linear ? 0.0 : 60e-12;
    LaserConfig l;
    l.pulse_fwhm_s = shape == GateEdge::Linear ? 0.0 : 80e-12;
    g.knots_per_edge = 48;
    const GateShape gs = build_gate_shape(g, l);
    TimeAxis ax{-1e-9, 9e-12, 2400, 25e-9};
    std::vector<float> tr(static_cast<size_t>(ax.bins), 0.0f);
    Rng rng(3, RngKind::Test, 1);
    // two narrow returns, a run with internal gaps, and a long dense low stretch (indirect light)
    tr[400] = 0.8f;
    tr[401] = 0.3f;
    tr[1100] = 0.5f;
    for (int i = 1500; i < 1530; i += 3) tr[static_cast<size_t>(i)] = 0.1f * rng.next_float();
    for (int i = 1800; i < 2300; ++i) tr[static_cast<size_t>(i)] = 0.01f * rng.next_float();
    std::vector<double> taus;
    for (int k = 0; k < 350; ++k) taus.push_back(-0.5e-9 + k * 36e-12);
    for (double dL : {0.0, 73e-12, -41e-12}) {
      const auto ref = brute_force(gs, tr, ax, taus, dL);
      const auto got = fast(gs, tr, ax, taus, dL);
      double peak = 0.0;
      for (double v : ref) peak = std::max(peak, std::abs(v));
      ASSERT_GT(peak, 0.5);
      for (size_t k = 0; k < taus.size(); ++k)
        ASSERT_NEAR(got[k], ref[k], 1e-9 * peak) << to_string(shape) << " k=" << k << " dL=" << dL;
    }
  }
}

// The integer-step path against the general one (the reference), edge by edge: random transients (sparse,
// dense, single bins at the array ends, huge and tiny contents), skews anywhere in a bin, length deviations,
// steps of 1 to 6 and 70 bins, the default gate (smooth edges and instrument response) and exact linear gates
// (one with edges of about a bin, shorter than the step).
// Both compute sum_i g_i W(b_k - i) exactly in real arithmetic, so they agree to rounding: 1e-12 of the
// plateau response |cu| x total (the old algorithm's own rounding, of G2 ~ total x T, is the larger part).
struct IntStepCase {
  const char* name;
  std::vector<float> g;
};

std::vector<IntStepCase> int_step_transients(int64_t T, Rng& rng) {
  std::vector<IntStepCase> cases;
  auto zero = [&] { return std::vector<float>(static_cast<size_t>(T), 0.0f); };
  {
    auto g = zero();  // one or two returns over two bins, as the benchmark's
    for (int r = 0; r < 2; ++r) {
      const auto b = static_cast<size_t>(rng.next_double() * static_cast<double>(T - 1));
      const double ph = std::pow(10.0, -4.0 + 2.0 * rng.next_double()), fr = rng.next_double();
      g[b] += static_cast<float>(ph * fr);
      g[b + 1] += static_cast<float>(ph * (1 - fr));
    }
    cases.push_back({"sparse", g});
  }
  {
    auto g = zero();  // every bin non-zero
    for (float& v : g) v = static_cast<float>(rng.next_double() + 1e-3);
    cases.push_back({"dense", g});
  }
  {
    auto g = zero();  // a peak, a run with gaps and a long dense low stretch (indirect light)
    g[static_cast<size_t>(T / 5)] = 0.8f;
    for (int64_t i = T / 3; i < T / 3 + 30; i += 3) g[static_cast<size_t>(i)] = 0.1f * rng.next_float();
    for (int64_t i = T / 2; i < T / 2 + T / 4; ++i) g[static_cast<size_t>(i)] = 0.01f * rng.next_float();
    cases.push_back({"mixed", g});
  }
  {
    auto g = zero();
    g.front() = 1.0f;
    cases.push_back({"first bin", g});
  }
  {
    auto g = zero();
    g.back() = 1.0f;
    cases.push_back({"last bin", g});
  }
  {
    auto g = zero();
    g.front() = 2.0f;
    g.back() = 3.0f;
    g[static_cast<size_t>(T / 2)] = -0.0f;  // counts as empty
    cases.push_back({"both ends", g});
  }
  cases.push_back({"zero", zero()});
  {
    auto g = zero();  // huge and tiny contents together (float range: 1e30 and a subnormal)
    g[static_cast<size_t>(T / 4)] = 1e30f;
    g[static_cast<size_t>(T / 4 + 1)] = 1e-30f;
    g[static_cast<size_t>(T / 2)] = 1e-40f;
    g[static_cast<size_t>(3 * T / 4)] = 7e29f;
    cases.push_back({"huge and tiny", g});
  }
  {
    auto g = zero();  // tiny only
    for (int i = 0; i < 20; ++i) g[static_cast<size_t>(rng.next_double() * static_cast<double>(T))] = 3e-38f * rng.next_float();
    cases.push_back({"tiny", g});
  }
  return cases;
}

TEST(Gate, IntegerStepPathEqualsGeneralPath) {
  GateConfig smooth;  // defaults: smooth 400 ps edges, 60 ps jitter, 80 ps pulse
  GateConfig linear;
  linear.edge_shape = GateEdge::Linear;
  linear.jitter_fwhm_s = 0.0;
  linear.rise_s = 150e-12;
  linear.fall_s = 250e-12;
  GateConfig steep = linear;  // edges of about one bin: the window is shorter than most steps
  steep.rise_s = steep.fall_s = 8e-12;
  LaserConfig with_irf, no_irf;
  no_irf.pulse_fwhm_s = 0.0;
  const GateShape shapes[3] = {build_gate_shape(smooth, with_irf), build_gate_shape(linear, no_irf),
                               build_gate_shape(steep, no_irf)};
  ASSERT_FALSE(shapes[0].exact);
  ASSERT_TRUE(shapes[1].exact);
  Rng rng(11, RngKind::Test, 4);
  double worst = 0.0;
  int compared = 0;
  TransientPrefix new_p;  // one for all sweeps, as per row in the sensor: its per-edge, per-step tables are reused
  for (const GateShape& gs : shapes)
    for (double dt : {9e-12, 4e-12}) {
      const EdgeBins edges[2] = {edge_in_bins(gs.rise, dt), edge_in_bins(gs.fall, dt)};
      const int64_t T = 1500;
      for (const IntStepCase& tc : int_step_transients(T, rng))
        for (const int64_t s : {1, 2, 3, 4, 5, 6, 70})  // 70: more phases than the evaluated-phase mask holds
          for (int rep = 0; rep < 3; ++rep)
            for (int which = 0; which < 2; ++which) {
              const EdgeBins& e = edges[which];
              const double sign = which == 0 ? 1.0 : -1.0;
              // gate positions from before the transient's first bin can see the edge to after its last,
              // with a random skew; rep 2 starts inside the transient and stops short of its end
              const double span = e.u.back() - e.u.front();
              double b0 = -e.u.back() - 3.0 - 5.0 * rng.next_double() + (which == 1 ? 37.3 * rng.next_double() : 0.0);
              int K = static_cast<int>((static_cast<double>(T) + span + 10.0) / static_cast<double>(s)) + 2;
              if (rep == 2) {
                b0 += 0.4 * static_cast<double>(T) + rng.next_double();
                K /= 3;
              }
              TransientPrefix old_p;
              std::vector<double> ref(static_cast<size_t>(K), 0.25), got(static_cast<size_t>(K), 0.25);
              const bool a = old_p.build(tc.g.data(), T), b = new_p.build_bins(tc.g.data(), T);
              ASSERT_EQ(a, b) << tc.name;
              EXPECT_EQ(old_p.total(), new_p.total()) << tc.name;
              if (a) {
                accumulate_edge_response(old_p, e, b0, static_cast<double>(s), K, sign, ref.data());
                accumulate_edge_response_int(new_p, e, b0, s, K, sign, got.data());
              }
              const double scale = std::abs(e.C1.back()) * new_p.total() + 1e-300;
              double diff = 0.0;
              for (int k = 0; k < K; ++k) diff = std::max(diff, std::abs(got[static_cast<size_t>(k)] - ref[static_cast<size_t>(k)]));
              worst = std::max(worst, diff / scale);
              ASSERT_LE(diff, 1e-12 * scale) << tc.name << " s=" << s << " dt=" << dt << " edge " << which << " b0=" << b0;
              ++compared;
            }
    }
  std::printf("integer-step path vs general path: %d sweeps, max |difference| / (|cu| total) = %.3g\n", compared, worst);
}

TEST(Gate, IntegerStepDetection) {
  EXPECT_EQ(integer_step(4.0), 4);
  EXPECT_EQ(integer_step(36e-12 / 9e-12), 4);
  EXPECT_EQ(integer_step(20e-12 / 4e-12), 5);
  EXPECT_EQ(integer_step(1.0 + 4e-16), 1);
  EXPECT_EQ(integer_step(4.0 + 1e-9), 0);  // a drift of 1e-9 bins per position is not rounding
  EXPECT_EQ(integer_step(4.5), 0);
  EXPECT_EQ(integer_step(0.0), 0);
  EXPECT_EQ(integer_step(0.25), 0);
}

// A non-integer step (36 ps over 7 ps bins) takes the general path: pixel_lambda equals it exactly; an
// integer step (36 ps over 9 ps bins) takes the integer-step path and equals the general one to rounding.
TEST(Gate, SensorTakesTheGeneralPathForNonIntegerSteps) {
  for (double dt : {7e-12, 9e-12}) {
    SensorStageConfig c = sweep_config(16, 8);
    c.sensor.dark_counts = false;
    c.sensor.crosstalk = false;
    c.acquisition.gate_sweep = {0.6e-9, 0.6e-9 + 99 * 36e-12, 36e-12};
    SensorModel model(c);
    const TimeAxis ax = model.required_window(dt);
    std::vector<float> g(static_cast<size_t>(ax.bins), 0.0f);
    const int64_t at2 = ax.bin_of(2.0e-9), at25 = ax.bin_of(2.5e-9);
    ASSERT_TRUE(at2 >= 0 && at25 >= 0 && at25 + 1 < ax.bins);
    g[static_cast<size_t>(at2)] = 0.7f;
    g[static_cast<size_t>(at25)] = 0.2f;
    g[static_cast<size_t>(at25) + 1] = 0.1f;
    const double step = 36e-12 / dt;
    EXPECT_EQ(integer_step(step) == 0, dt == 7e-12);
    for (auto [x, y] : {std::pair{3, 1}, std::pair{12, 6}}) {
      const PixelParams px = model.pixel(x, y);
      const auto lam = model.pixel_lambda(x, y, g.data(), ax, 0.0, 0.0);
      // the general path by hand, as SensorModel computes lambda from h
      TransientPrefix p;
      ASSERT_TRUE(p.build(g.data(), ax.bins));
      const EdgeBins r = edge_in_bins(model.gate().rise, dt), f = edge_in_bins(model.gate().fall, dt);
      const double b0 = (model.gate_positions_s()[0] + c.sensor.gate.delay_s + px.skew_s - ax.start_s) / dt;
      std::vector<double> h(lam.size(), 0.0);
      accumulate_edge_response(p, r, b0, step, model.K(), 1.0, h.data());
      accumulate_edge_response(p, f, b0 + px.dL_s / dt, step, model.K(), -1.0, h.data());
      const double C = static_cast<double>(c.acquisition.cycles_per_frame), pdp = model.pdp_laser(px.type) * px.pdp_scale;
      const double scale = C * pdp;
      for (size_t k = 0; k < lam.size(); ++k) {
        const double want = C * (pdp * std::max(h[k], 0.0) + 0.0);  // no dark counts, no ambient
        if (dt == 7e-12)
          ASSERT_EQ(lam[k], want) << "k " << k;
        else
          ASSERT_NEAR(lam[k], want, 1e-12 * scale * model.gate().plateau) << "k " << k;
      }
    }
  }
}

// A fine-grid edge with its constant tails.
double fine_value(const Sampled& s, double t, double v_end) {
  if (t <= s.x0) return 0.0;
  if (t >= s.x0 + s.dx * static_cast<double>(s.y.size() - 1)) return v_end;
  return s.at(t);
}

// Measured: the knot approximation of smooth edges against the closed form of a normal-CDF gate
// convolved with the Gaussian IRF. The fine grid is itself checked against the closed form.
TEST(Gate, SmoothKnotErrorAgainstClosedForm) {
  GateConfig g;  // defaults: smooth, 400 ps edges, 60 ps jitter
  LaserConfig l;  // 80 ps pulse
  double previous = 1.0;
  for (int m : {16, 32, 64, 128, 256}) {
    g.knots_per_edge = m;
    const GateShape gs = build_gate_shape(g, l);
    double err = 0.0, fine_err = 0.0;
    for (double t = -1.5e-9; t < g.length_s + 1.5e-9; t += 0.5e-12) {
      const double ref = smooth_gate_closed_form(g, l, t, 0.0);
      err = std::max(err, std::abs(gs.value(t, 0.0) - ref));
      const double fine = fine_value(gs.rise_fine, t, gs.plateau) - fine_value(gs.fall_fine, t, gs.plateau);
      fine_err = std::max(fine_err, std::abs(fine - ref));
    }
    std::printf("knots per edge %3d: max error vs closed form %.3g (recorded max_knot_error %.3g), fine grid %.3g\n",
                m, err, gs.max_knot_error, fine_err);
    EXPECT_LT(fine_err, 1e-7);
    EXPECT_LT(err, gs.max_knot_error + 1e-7);
    EXPECT_LT(err, previous);
    previous = err;
    if (m == 64) {
      EXPECT_LT(err, 3e-4);
    }
    if (m == 128) {
      EXPECT_LT(err, 6e-5);
    }
    if (m == 256) {  // the default
      EXPECT_LT(err, 1.5e-5);
    }
  }
}

// The fine grid's step (sensor.gate.grid_ps) against the closed form: the step used is the one asked for
// (unless the span needs a coarser one), the fine edges' error grows with its square, and the knots' error
// stays recorded against the grid they were fitted to.
TEST(Gate, FineGridStepIsTheSceneFilesAndItsErrorGrowsWithIt) {
  GateConfig g;
  LaserConfig l;
  double previous = 0.0;
  for (double step_ps : {0.25, 1.0, 4.0, 16.0, 40.0}) {
    g.grid_s = step_ps * 1e-12;
    g.knots_per_edge = 1024;
    const GateShape gs = build_gate_shape(g, l);
    // The default edge (16 sigma of a 400 ps 10-90 % rise) and instrument response (16 sigma of the 80 ps
    // pulse and 60 ps jitter) span 3.18 ns: 12000 steps of 0.265 ps, coarser than 0.25 ps.
    const double span = 16 * 400e-12 / 2.563103131 + 16 * std::hypot(80e-12, 60e-12) / 2.354820045;
    EXPECT_NEAR(gs.grid_s, step_ps < 0.3 ? span / 12000 : g.grid_s, 1e-6 * gs.grid_s);
    double fine_err = 0.0, err = 0.0;
    for (double t = -1.5e-9; t < g.length_s + 1.5e-9; t += 0.5e-12) {
      const double ref = smooth_gate_closed_form(g, l, t, 0.0);
      const double fine = fine_value(gs.rise_fine, t, gs.plateau) - fine_value(gs.fall_fine, t, gs.plateau);
      fine_err = std::max(fine_err, std::abs(fine - ref));
      err = std::max(err, std::abs(gs.value(t, 0.0) - ref));
    }
    std::printf("grid %5.2f ps: fine grid max error vs closed form %.3g (recorded estimate %.3g), 1024 knots %.3g\n",
                step_ps, fine_err, gs.max_grid_error, err);
    EXPECT_NEAR(gs.max_grid_error, fine_err, 0.02 * fine_err);  // the recorded estimate (measured within 1 %)
    EXPECT_GE(fine_err, previous);
    EXPECT_LT(fine_err, 1.5e-6 * step_ps * step_ps + 1e-7);  // second order in the step (measured 1.2e-6)
    previous = fine_err;
    EXPECT_LT(err, fine_err + gs.max_knot_error + 1e-9);
  }
  g.grid_s = 0.0;
  EXPECT_THROW(build_gate_shape(g, l), Error);
}

// A delta transient seen through the sweep reproduces the effective gate, shifted by the pixel's skew
// and stretched by its length deviation.
TEST(Gate, DeltaTransientReproducesGateShiftedBySkew) {
  SensorStageConfig c = sweep_config(64, 32);
  c.sensor.dark_counts = false;
  c.sensor.crosstalk = false;
  c.sensor.gate.delay_s = 0.7e-9;
  c.acquisition.gate_sweep = {-4e-9, 6e-9, 20e-12};
  SensorModel model(c);
  const double dt = 4e-12;
  const TimeAxis ax = model.required_window(dt);
  std::vector<float> g(static_cast<size_t>(ax.bins), 0.0f);
  const int64_t bin = ax.bin_of(3.0e-9);
  g[static_cast<size_t>(bin)] = 1.0f;
  const double t0 = ax.bin_start_s(bin);
  int tested = 0;
  for (auto [x, y] : {std::pair{3, 1}, std::pair{60, 2}, std::pair{30, 30}}) {
    const PixelParams px = model.pixel(x, y);
    const auto lam = model.pixel_lambda(x, y, g.data(), ax, 0.0, 0.0);
    const double scale = static_cast<double>(c.acquisition.cycles_per_frame) * model.pdp_laser(px.type) * px.pdp_scale;
    for (size_t k = 0; k < lam.size(); ++k) {
      const double tau = model.gate_positions_s()[k] + c.sensor.gate.delay_s + px.skew_s;
      double ref = 0.0;  // Simpson over the bin
      const int n = 64;
      for (int i = 0; i <= n; ++i) {
        const double w = (i == 0 || i == n) ? 1.0 : (i % 2 ? 4.0 : 2.0);
        ref += w * smooth_gate_closed_form(c.sensor.gate, c.laser, t0 + dt * i / n - tau, px.dL_s);
      }
      ref /= 3.0 * n;
      ASSERT_NEAR(lam[k] / scale, ref, model.gate().max_knot_error + 1e-6) << "pixel " << x << "," << y << " k " << k;
    }
    ++tested;
  }
  EXPECT_EQ(tested, 3);
  // the three pixels' skews differ, so the comparison above really tests the shift
  EXPECT_GT(std::abs(model.pixel(3, 1).skew_s - model.pixel(30, 30).skew_s), 50e-12);
}

// The files written by write_temp, removed when the test program exits.
struct TempFiles {
  std::vector<std::filesystem::path> paths;
  ~TempFiles() {
    for (const auto& p : paths) {
      std::error_code ec;
      std::filesystem::remove(p, ec);
    }
  }
};

std::string write_temp(const std::string& name, const std::string& text) {
  static TempFiles files;
  const auto p = std::filesystem::temp_directory_path() / ("spadgen_sensor_" + std::to_string(::getpid()) + "_" + name);
  std::ofstream(p) << text;
  files.paths.push_back(p);
  return p.string();
}

TEST(Gate, MeasuredTableProfile) {
  // a trapezoid: 0 at 0 ps, 1 from 400 to 4200 ps, 0 at 4600 ps -> 50 % points at 200 and 4400 ps
  const std::string path = write_temp("profile.csv", "time_ps,response\n0,0\n400,2\n4200,2\n4600,0\n");
  GateConfig g;
  g.profile_csv = path;
  g.jitter_fwhm_s = 0.0;
  LaserConfig l;
  l.pulse_fwhm_s = 0.0;
  const GateShape s = build_gate_shape(g, l);
  EXPECT_TRUE(s.exact);
  EXPECT_NEAR(s.nominal_length_s, 4.2e-9, 1e-18);
  EXPECT_NEAR(s.value(200e-12, 0.0), 0.5, 1e-12);
  EXPECT_NEAR(s.value(2000e-12, 0.0), 1.0, 1e-12);
  EXPECT_NEAR(s.value(4400e-12, 0.0), 0.5, 1e-12);
  // a longer pixel gate moves only the falling edge
  EXPECT_NEAR(s.value(4500e-12, 100e-12), 0.5, 1e-12);
  EXPECT_NEAR(s.value(200e-12, 100e-12), 0.5, 1e-12);
  EXPECT_NEAR(s.open_time_s, 4.2e-9, 1e-18);
  // its edges' 10-90 % times, for metadata.json's rise_ps and fall_ps (and the edges detector's separation):
  // the table's, not the ignored sensor.gate.rise_ps and fall_ps (400 ps)
  EXPECT_NEAR(s.rise_s, 0.8 * 400e-12, 1e-18);
  EXPECT_NEAR(s.fall_s, 0.8 * 400e-12, 1e-18);
}

// A gate of two humps, 0 at the middle of its 50 % crossings where it is split: its fit's errors are of the
// open gate (its peak, 1), finite. They were divided by the level at the split, 0: infinite errors, null in
// metadata.json and "within about inf %" in the warning (a helper's find). The edges' times are the first
// rise's and the last fall's.
TEST(Gate, ATableOfTwoHumpsHasFiniteErrors) {
  GateConfig g;
  g.profile_csv = write_temp("two_humps.csv", "0,0\n100,1\n200,0\n300,1\n400,0\n");
  LaserConfig l;
  const GateShape s = build_gate_shape(g, l);
  EXPECT_EQ(s.plateau, 0.0);
  EXPECT_TRUE(std::isfinite(s.max_knot_error));
  EXPECT_TRUE(std::isfinite(s.max_grid_error));
  EXPECT_GT(s.max_knot_error, 0.0);
  EXPECT_LT(s.max_knot_error, 0.05);
  EXPECT_NEAR(s.rise_s, 80e-12, 1e-18);
  EXPECT_NEAR(s.fall_s, 80e-12, 1e-18);
  // the response itself: its two peaks, 200 ps apart
  double first = 0.0, second = 0.0;
  for (double t = 0.0; t < 200e-12; t += 1e-12) first = std::max(first, s.value(t, 0.0));
  for (double t = 200e-12; t < 400e-12; t += 1e-12) second = std::max(second, s.value(t, 0.0));
  EXPECT_GT(first, 0.5);
  EXPECT_GT(second, 0.5);
}

TEST(Gate, BadTablesNameTheFileAndKey) {
  GateConfig g;
  LaserConfig l;
  const auto error_of = [&] {  // "" when the tables are taken
    try {
      build_gate_shape(g, l);
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  g.profile_csv = write_temp("bad_order.csv", "0,0\n400,1\n300,1\n");
  std::string what = error_of();
  EXPECT_NE(what.find("sensor.gate.profile_csv"), std::string::npos) << what;
  EXPECT_NE(what.find("bad_order.csv"), std::string::npos) << what;
  EXPECT_NE(what.find("strictly increasing"), std::string::npos) << what;
  g.profile_csv = "/nonexistent/profile.csv";
  EXPECT_THROW(build_gate_shape(g, l), Error);
  g.profile_csv = write_temp("bad_row.csv", "0,0\n400,abc\n");
  EXPECT_THROW(build_gate_shape(g, l), Error);
  // a first row that starts with a number is data, not a header: three columns are an error there too
  g.profile_csv = write_temp("three_columns.csv", "0,0,5\n400,1\n4200,1\n4600,0\n");
  what = error_of();
  EXPECT_NE(what.find("three_columns.csv' line 1: expected two numbers"), std::string::npos) << what;
  // decimal numbers only: hexadecimal (strtod read 0x10 as 16) and a NUL byte (it ended the line) are errors
  g.profile_csv = write_temp("hex.csv", "0,0\n0x190,1\n4200,1\n4600,0\n");
  what = error_of();
  EXPECT_NE(what.find("hex.csv' line 2: expected two numbers separated by a comma, found '0x190,1'"), std::string::npos) << what;
  g.profile_csv = write_temp("nul.csv", std::string("0,0\n400,1") + '\0' + "junk\n4200,1\n4600,0\n");
  what = error_of();
  EXPECT_NE(what.find("nul.csv' line 2: expected two numbers"), std::string::npos) << what;
  g.profile_csv = write_temp("with_header.csv", "time_ps,response\n0,0\n400,1\n4200,1\n4600,0\n");
  EXPECT_NO_THROW(build_gate_shape(g, l));
  g.profile_csv = write_temp("inf_header.csv", "infrared_ps,response\n0,0\n400,1\n4200,1\n4600,0\n");  // strtod reads "inf"
  EXPECT_NO_THROW(build_gate_shape(g, l));
  g.profile_csv.clear();
  l.pulse_shape_csv = write_temp("bad_pulse.csv", "0,1\n10,-1\n20,0\n");
  EXPECT_THROW(build_gate_shape(g, l), Error);
}

// A measured PDP table that stops short of the laser's wavelength would make the pixels blind to the laser
// (PDP 0 outside a table): refused, naming the key, the file and both wavelengths; a table that covers it,
// or one of a pixel type the layout does not use, is taken.
TEST(Gate, APdpTableThatMissesTheLasersWavelengthIsRefused) {
  SensorStageConfig c = sweep_config(16, 8);
  c.sensor.preset = PixelPreset::PixelA;
  c.laser.wavelength_m = 637e-9;
  c.sensor.pixel_A.pdp_csv = write_temp("pdp_700_800.csv", "700,0.1\n800,0.2\n");
  try {
    const sensor::SensorModel m(c);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("sensor.pixel_A.pdp_csv: '" + c.sensor.pixel_A.pdp_csv + "' covers 700 to 800 nm, not the laser's 637 nm"),
              std::string::npos) << what;
  }
  c.sensor.pixel_B.pdp_csv = c.sensor.pixel_A.pdp_csv;  // pixel_B is not in this layout
  c.sensor.pixel_A.pdp_csv = write_temp("pdp_600_800.csv", "600,0.1\n800,0.2\n");
  EXPECT_NO_THROW(const sensor::SensorModel m(c));
}

// A pulse table sampled from the Gaussian gives the same effective gate as the Gaussian pulse.
TEST(Gate, PulseTableMatchesGaussianPulse) {
  std::string csv = "time_ps,power\n";
  const double sigma_ps = 80.0 / kFwhmPerSigma;
  for (double t = -400; t <= 400; t += 2) csv += std::to_string(t + 1000.0) + "," + std::to_string(std::exp(-0.5 * t * t / (sigma_ps * sigma_ps))) + "\n";
  GateConfig g;
  LaserConfig gauss, table;
  table.pulse_shape_csv = write_temp("pulse.csv", csv);
  const GateShape a = build_gate_shape(g, gauss), b = build_gate_shape(g, table);
  EXPECT_NEAR(b.irf_fwhm_s, a.irf_fwhm_s, 1e-12);
  for (double t = -1e-9; t < 5e-9; t += 7e-12) ASSERT_NEAR(a.value(t, 0.0), b.value(t, 0.0), 2e-4) << t;
}

// The sweep's last position, stop_ns, counts when on the step grid, within the rounding of start, stop and
// step in seconds: 5 to 5.00001 ns in steps of 1e-6 ps is 10001 positions (an absolute 1e-9 of a step left
// the last out), the paper's sweep 351; a stop a tenth of a step short of the grid does not count.
TEST(Gate, TheSweepsLastPositionCountsWhenOnTheGrid) {
  struct Case {
    double start_ns, stop_ns, step_ps, positions;
  };
  for (const Case& t : {Case{0.6, 13.2, 36, 351}, Case{5, 5.00001, 1e-6, 10001}, Case{5, 5.0000099999, 1e-6, 10000},
                        Case{-3, 3, 1e-3, 6000001}, Case{1e5, 1e5 + 1e-3, 1, 2}}) {
    GateSweepConfig g;
    g.start_s = t.start_ns * kNs, g.stop_s = t.stop_ns * kNs, g.step_s = t.step_ps * kPs;
    EXPECT_EQ(g.positions(), t.positions) << t.start_ns << " to " << t.stop_ns << " ns in " << t.step_ps << " ps";
  }
  SensorStageConfig c = sweep_config(8, 8);
  c.acquisition.gate_sweep.start_s = 5 * kNs, c.acquisition.gate_sweep.stop_s = 5.00001 * kNs, c.acquisition.gate_sweep.step_s = 1e-6 * kPs;
  const SensorModel model(c);
  ASSERT_EQ(model.K(), 10001);
  EXPECT_NEAR(model.gate_positions_s().back(), 5.00001e-9, 1e-23);
}

TEST(Gate, RequiredWindowCoversEveryPixelGate) {
  SensorStageConfig c = sweep_config(96, 40);
  SensorModel model(c);
  const TimeAxis ax = model.required_window(9e-12);
  EXPECT_GT(ax.bins, 0);
  EXPECT_DOUBLE_EQ(ax.period_s, 25e-9);
  EXPECT_NEAR(std::remainder(ax.start_s, 9e-12), 0.0, 1e-18);
  const auto& taus = model.gate_positions_s();
  for (int y = 0; y < c.camera.height_px; ++y)
    for (int x = 0; x < c.camera.width_px; ++x) {
      const PixelParams p = model.pixel(x, y);
      const double open = taus.front() + p.skew_s + model.gate().support_begin();
      const double close = taus.back() + p.skew_s + model.gate().support_end(p.dL_s);
      ASSERT_GE(open, ax.start_s);
      ASSERT_LE(close, ax.end_s());
    }
  // and it is not much wider than needed: the paper's sweep (0.6 to 13.2 ns) plus a 3.8 ns gate
  EXPECT_LT(ax.end_s() - ax.start_s, (13.2 - 0.6 + 3.8 + 5.0) * 1e-9);
  // the sweep has K = 351 positions, 0.6 to 13.2 ns inclusive
  EXPECT_EQ(model.K(), 351);
  c.acquisition.mode = AcquisitionMode::Intensity;
  EXPECT_EQ(SensorModel(c).required_window(9e-12).bins, 0);
}

}  // namespace
}  // namespace spadgen::sensor
