// The sensor stage end to end: eq. (5)/(6), dark counts, saturation, crosstalk, maps, determinism.
#include <gtest/gtest.h>
#include <hwy/targets.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdio>
#include <string>

#include "core/error.h"
#include "core/rng.h"
#include "core/units.h"
#include "sensor/model/gate.h"
#include "sensor/model/pixel_maps.h"
#include "sensor/sampling/sampling.h"
#include "sensor/sensor.h"
#include "test_util.h"

namespace spadgen::sensor {
namespace {

using testing::Image;
using testing::kZ;
using testing::sweep_config;

SensorStageConfig quiet(SensorStageConfig c) {
  c.sensor.dark_counts = false;
  c.sensor.crosstalk = false;
  c.sensor.pdp_nonuniformity = false;
  c.sensor.skew = false;
  return c;
}

SensorStageConfig intensity_config(int w, int h, Exposure exposure, int frames) {
  SensorStageConfig c = quiet(sweep_config(w, h));
  c.acquisition.mode = AcquisitionMode::Intensity;
  c.acquisition.intensity.exposure = exposure;
  c.acquisition.frames = frames;
  return c;
}

// Eq. (5) and (6): mean sampled output against the formulas, incident photons 1 to 1e6 per 4080 frames.
TEST(Sensor, Equations5And6) {
  const int levels = 25, per_level = 64;
  for (const Exposure mode : {Exposure::Single, Exposure::Dual}) {
    SensorStageConfig c = intensity_config(per_level, levels, mode, 4080);
    SensorModel model(c);
    const double N = 4080.0, pdp = model.pdp_ambient(0);
    const double tS = c.acquisition.intensity.exposure_s, tL = tS * c.acquisition.intensity.dual_ratio;
    Image img(per_level, levels, TimeAxis{});
    std::vector<double> n_in(levels);
    for (int l = 0; l < levels; ++l) {
      n_in[static_cast<size_t>(l)] = std::pow(10.0, 6.0 * l / (levels - 1));
      // N_in = detectable photons per N-frame image = N * PDP * rate * tau (single), (N/2) PDP rate (tS + tL) (dual)
      const double rate = mode == Exposure::Single ? n_in[static_cast<size_t>(l)] / (N * pdp * tS)
                                           : n_in[static_cast<size_t>(l)] / (0.5 * N * pdp * (tS + tL));
      for (int x = 0; x < per_level; ++x) img.ambient[static_cast<size_t>(l * per_level + x)] = static_cast<float>(rate);
    }
    const SensorTile out = model.process(img.tile({0, 0, per_level, levels}, 0));
    ASSERT_EQ(out.intensity_counts.size(), static_cast<size_t>(levels * per_level));
    for (int l = 0; l < levels; ++l) {
      const double x = n_in[static_cast<size_t>(l)] / N;
      double want = 0.0, var = 0.0;
      if (mode == Exposure::Single) {
        want = N * (1.0 - std::exp(-x));  // eq. (5)
        var = want * std::exp(-x);
      } else {
        const double pL = 1.0 - std::exp(-2.0 * tL / (tL + tS) * x), pS = 1.0 - std::exp(-2.0 * tS / (tL + tS) * x);
        want = N / 2 * (pL + pS);  // eq. (6)
        var = N / 2 * (pL * (1 - pL) + pS * (1 - pS));
      }
      double mean = 0.0, mean_expected = 0.0;
      for (int px = 0; px < per_level; ++px) {
        const size_t i = static_cast<size_t>(l * per_level + px);
        mean += out.intensity_counts[i];
        mean_expected += out.expected[i] + (mode == Exposure::Dual ? out.expected[out.intensity_counts.size() + i] : 0.0f);
      }
      mean /= per_level;
      mean_expected /= per_level;
      EXPECT_NEAR(mean_expected, want, 2e-6 * want + 1e-9) << to_string(mode) << " N_in=" << n_in[static_cast<size_t>(l)];
      const double sd = std::sqrt(var / per_level);
      if (sd > 0.0) {
        EXPECT_LT(std::abs(mean - want), kZ * sd) << to_string(mode) << " N_in=" << n_in[static_cast<size_t>(l)];
      } else {
        EXPECT_EQ(mean, want);
      }
      // the linearised estimate inverts the formula
      if (want < N - 1.0) {
        EXPECT_NEAR(linearise_counts(want, 4080, mode == Exposure::Dual, 8.0), n_in[static_cast<size_t>(l)], 1e-6 * n_in[static_cast<size_t>(l)]);
      }
    }
    // saturation is clamped to a finite estimate
    EXPECT_TRUE(std::isfinite(linearise_counts(N, 4080, mode == Exposure::Dual, 8.0)));
  }
}

// Dark pixels count at their own DCR, in the counts path and in the frames path: each pixel's sum over the
// sweep is Binomial(K N, p) (every position's counts Binomial(N, p), p = 1 - exp(-lambda)), tested exactly at a
// false-alarm rate of 1e-6 (a z-test failed at 1 of 60 seeds: a hot pixel expecting 0.04 frames without a count
// had one, 4.9 of its standard deviations off).
TEST(Sensor, DarkPixelCountsAtItsDcr) {
  SensorStageConfig c = sweep_config(16, 8);
  c.sensor.crosstalk = false;
  c.sensor.pixel_A.dcr_median_cps = 3e4;  // enough counts per pixel for a sharp test
  c.acquisition.gate_sweep = {0.6e-9, 4.2e-9, 36e-12};
  for (bool frames : {false, true}) {
    c.outputs.frames = frames;
    SensorModel model(c);
    const TimeAxis ax = model.required_window(20e-12);
    Image img(16, 8, ax);
    const SensorTile out = model.process(img.tile({0, 0, 16, 8}, model.halo()));
    const size_t n = 16 * 8;
    for (int y = 0; y < 8; ++y)
      for (int x = 0; x < 16; ++x) {
        const PixelParams p = model.pixel(x, y);
        const double lambda = static_cast<double>(c.acquisition.cycles_per_frame) * p.dcr_cps * model.gate().open_time(p.dL_s);
        const double pr = -std::expm1(-lambda), N = 255.0;
        double sum = 0.0;
        for (int k = 0; k < model.K(); ++k) {
          sum += out.counts[static_cast<size_t>(k) * n + static_cast<size_t>(y * 16 + x)];
          ASSERT_NEAR(out.expected[static_cast<size_t>(k) * n + static_cast<size_t>(y * 16 + x)], N * pr, 1e-5 * N * pr);
        }
        EXPECT_TRUE(testing::binomial_consistent(sum, model.K() * N, pr, 1e-6))
            << x << "," << y << " frames=" << frames << ": " << sum << " counts against " << model.K() * N * pr;
      }
  }
}

TEST(Sensor, DcrMapsAndTemperature) {
  SensorStageConfig c = sweep_config(256, 200);
  SensorModel model(c);
  int below = 0, hot = 0;
  for (int y = 0; y < 200; ++y)
    for (int x = 0; x < 256; ++x) {
      const double d = model.pixel(x, y).dcr_cps;
      below += d < 0.4;
      hot += d > 0.4 * 10.0;  // hot pixels (x100) are above 10 x median unless 2.3 sigma low; main ones rarely
    }
  const double n = 256.0 * 200.0;
  // dcr_median_cps (0.4) is the chip's median, main and hot pixels together, as the paper's Fig. 4(a) gives it (it
  // was the main population's, and the chip's median 0.429): half the pixels below it. The main population's
  // median mu solves 0.95 Phi(ln(0.4 / mu)) + 0.05 Phi(ln(0.4 / (100 mu))) = 0.5 (Phi's truncation at 5 sigma
  // changes it by 1e-7): 0.4 exp(-u), u found here by Newton's method on the untruncated Phi.
  const auto Phi = [](double x) { return 0.5 * std::erfc(-x / std::sqrt(2.0)); };
  const auto phi = [](double x) { return std::exp(-0.5 * x * x) / std::sqrt(2.0 * kPi); };
  double u = 0.0;
  for (int i = 0; i < 50; ++i)
    u -= (0.95 * Phi(u) + 0.05 * Phi(u - std::log(100.0)) - 0.5) / (0.95 * phi(u) + 0.05 * phi(u - std::log(100.0)));
  const double mu = 0.4 * std::exp(-u);
  EXPECT_NEAR(mu / 0.4, 0.936, 0.001);
  EXPECT_NEAR(PixelMaps::dcr_main_median(c.sensor.pixel_A), mu, 1e-6 * mu);
  const double pb = 0.5;
  // P(> 4 cps) = 0.95 P(z > ln(4 / mu)) + 0.05 P(z > ln(4 / (100 mu)))
  const double ph = 0.95 * (1 - Phi(std::log(4.0 / mu))) + 0.05 * (1 - Phi(std::log(4.0 / (100 * mu))));
  EXPECT_LT(std::abs(below - n * pb), kZ * std::sqrt(n * pb * (1 - pb)));
  EXPECT_LT(std::abs(hot - n * ph), kZ * std::sqrt(n * ph * (1 - ph)));
  // without hot pixels, the main population's median is the key's; with all pixels hot, a hundredth of it
  PixelTypeConfig t = c.sensor.pixel_A;
  t.hot_pixel_fraction = 0.0;
  EXPECT_EQ(PixelMaps::dcr_main_median(t), 0.4);
  t.hot_pixel_fraction = 1.0;
  EXPECT_NEAR(PixelMaps::dcr_main_median(t), 0.004, 1e-12);
  t.hot_pixel_fraction = 0.05, t.dcr_log_sigma = 0.0;  // no spread: the median is a main pixel's
  EXPECT_EQ(PixelMaps::dcr_main_median(t), 0.4);
  EXPECT_DOUBLE_EQ(PixelMaps::temperature_factor(25.0), 1.0);
  EXPECT_NEAR(PixelMaps::temperature_factor(0.0) / PixelMaps::temperature_factor(10.0), 1.0, 0.1);  // flat below 10 C
  const double arrhenius = std::exp(1.1 / kBoltzmannEv * (1 / 323.15 - 1 / 333.15));
  EXPECT_NEAR(PixelMaps::temperature_factor(60.0) / PixelMaps::temperature_factor(50.0), arrhenius, 0.05 * arrhenius);
  c.sensor.temperature_C = 50.0;
  EXPECT_NEAR(SensorModel(c).pixel(5, 5).dcr_cps / model.pixel(5, 5).dcr_cps, PixelMaps::temperature_factor(50.0), 1e-9);
  c.sensor.dark_counts = false;
  EXPECT_EQ(SensorModel(c).pixel(5, 5).dcr_cps, 0.0);
}

TEST(Sensor, SaturationGivesExactlyN) {
  SensorStageConfig c = quiet(sweep_config(16, 8));
  c.acquisition.gate_sweep = {2e-9, 3e-9, 100e-12};
  for (bool frames : {false, true}) {
    c.outputs.frames = frames;
    SensorModel model(c);
    const TimeAxis ax = model.required_window(10e-12);
    Image img(16, 8, ax);
    for (int y = 0; y < 8; ++y)
      for (int x = 0; x < 16; ++x) img.pixel(x, y)[ax.bin_of(5e-9)] = 1e6f;  // inside every gate
    const SensorTile out = model.process(img.tile({0, 0, 16, 8}, 0));
    for (size_t i = 0; i < out.counts.size(); ++i) {
      ASSERT_EQ(out.counts[i], 255);
      ASSERT_EQ(out.expected[i], 255.0f);
    }
    if (frames) {
      for (uint8_t b : out.frames) ASSERT_EQ(b, 0xFF);
    }
  }
}

// Bright pixels on a 4-pixel lattice, dark elsewhere: each dark 4-neighbour of a bright pixel fires by
// crosstalk only, at the marginal rate; counts and frames paths both match it.
TEST(Sensor, CrosstalkRates) {
  for (int type = 0; type < 2; ++type) {
    SensorStageConfig c = intensity_config(64, 64, Exposure::Single, 2000);
    c.sensor.crosstalk = true;
    c.sensor.preset = type == 0 ? PixelPreset::PixelA : PixelPreset::PixelB;
    PixelTypeConfig& tc = type == 0 ? c.sensor.pixel_A : c.sensor.pixel_B;
    tc.crosstalk_probability = 0.02;  // large, for statistical power
    const double lam_bright = 1.5;
    for (bool frames : {false, true}) {
      c.outputs.frames = frames;
      SensorModel model(c);
      ASSERT_EQ(model.halo(), 1);
      Image img(64, 64, TimeAxis{});
      const double rate = lam_bright / (model.pdp_ambient(type) * c.acquisition.intensity.exposure_s);
      for (int y = 1; y < 64; y += 4)
        for (int x = 1; x < 64; x += 4) img.ambient[static_cast<size_t>(y * 64 + x)] = static_cast<float>(rate);
      const SensorTile out = model.process(img.tile({0, 0, 64, 64}, 1));
      const double q = 0.02;
      const double p_x = type == 0 ? -std::expm1(-q * lam_bright) : q * -std::expm1(-lam_bright);
      double sum = 0.0, far = 0.0;
      int nx = 0;
      for (int y = 0; y < 64; ++y)
        for (int x = 0; x < 64; ++x) {
          const int dx = (x + 3) % 4, dy = (y + 3) % 4;  // position relative to the bright lattice
          const bool neighbour = (dx == 0 && (dy == 1 || dy == 3)) || (dy == 0 && (dx == 1 || dx == 3));
          const size_t i = static_cast<size_t>(y * 64 + x);
          if (neighbour) {
            sum += out.counts[i];
            ASSERT_NEAR(out.expected[i], 2000.0 * p_x, 1e-4 * 2000.0 * p_x);
            ++nx;
          } else if (dx != 0 || dy != 0) {
            far += out.counts[i];
          }
        }
      const double mean = nx * 2000.0 * p_x, sd = std::sqrt(mean * (1 - p_x));
      EXPECT_LT(std::abs(sum - mean), kZ * sd) << "type " << type << " frames " << frames;
      EXPECT_EQ(far, 0.0);
    }
  }
}

TEST(Sensor, CrosstalkOffCostsNoHalo) {
  SensorStageConfig c = sweep_config();
  c.sensor.crosstalk = false;
  EXPECT_EQ(SensorModel(c).halo(), 0);
  c.sensor.crosstalk = true;
  EXPECT_EQ(SensorModel(c).halo(), 1);
}

// The paper's spreads and Fig. 5 pattern on the full 1024 x 500 pixel-A array.
TEST(Sensor, GateMapsSpreadAndPattern) {
  SensorStageConfig c = sweep_config(1024, 500);
  SensorModel model(c);
  const SensorMapsTile m = model.maps({0, 0, 1024, 500});
  double s1 = 0, s2 = 0, l1 = 0, l2 = 0, top = 0, bottom = 0, top_left = 0, top_right = 0;
  for (int y = 0; y < 500; ++y)
    for (int x = 0; x < 1024; ++x) {
      const size_t i = static_cast<size_t>(y * 1024 + x);
      const double s = m.gate_skew_ps[i], l = m.gate_length_ps[i];
      s1 += s;
      s2 += s * s;
      l1 += l;
      l2 += l * l;
      if (y < 50) top += s;
      if (y >= 450) bottom += s;
      if (y < 50 && x < 200) top_left += s;
      if (y < 50 && x >= 824) top_right += s;
    }
  const double n = 1024.0 * 500.0;
  const double skew_fwhm = kFwhmPerSigma * std::sqrt(s2 / n - (s1 / n) * (s1 / n));
  const double len_fwhm = kFwhmPerSigma * std::sqrt(l2 / n - (l1 / n) * (l1 / n));
  EXPECT_NEAR(skew_fwhm, 410.0, 0.01 * 410.0);
  EXPECT_NEAR(len_fwhm, 120.0, 0.01 * 120.0);
  EXPECT_NEAR(l1 / n, 3800.0, 1.0);
  EXPECT_NEAR(s1 / n, 0.0, 1.0);
  EXPECT_GT(top / (50 * 1024) - bottom / (50 * 1024), 200.0);  // later at the top
  EXPECT_GT(top_right / (50 * 200) - top_left / (50 * 200), 50.0);  // asymmetric across the top
  // user maps replace them
  std::vector<float> skew(1024 * 500, 12.5f), len(1024 * 500, 3900.0f);
  model.set_gate_maps(skew, len);
  EXPECT_NEAR(model.pixel(7, 9).skew_s, 12.5e-12, 1e-18);
  EXPECT_NEAR(model.pixel(7, 9).dL_s, 100e-12, 1e-16);
  EXPECT_THROW(model.set_gate_maps(std::vector<float>(10), std::vector<float>(10)), Error);
  // from EXR channels, e.g. a previous run's sensor_maps.exr
  model.set_maps(1024, 500, {{"gate_skew_ps", std::vector<float>(1024 * 500, -3.0f)}, {"gate_length_ps", len}}, "maps.exr");
  EXPECT_NEAR(model.pixel(1, 2).skew_s, -3e-12, 1e-18);
  EXPECT_THROW(model.set_maps(1024, 500, {{"skew_ps", skew}}, "maps.exr"), Error);
  EXPECT_THROW(model.set_maps(512, 500, {{"skew_ps", skew}, {"length_ps", len}}, "maps.exr"), Error);
}

// The gate maps' pattern statistics, summed from a row's and a column's factors, are the same bits as the
// patterns evaluated at every pixel (the maps of every run depend on them).
TEST(Sensor, GatePatternSumsEqualThePixelByPixelSums) {
  for (const auto& [w, h] : {std::pair{1024, 500}, std::pair{1024, 1000}, std::pair{37, 3}, std::pair{1, 1}, std::pair{2, 1}}) {
    double s1 = 0, s2 = 0, l1 = 0, l2 = 0;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const double u = w > 1 ? double(x) / (w - 1) : 0.5, v = 1.0 - (h > 1 ? double(y) / (h - 1) : 0.5);
        const double a = PixelMaps::skew_pattern(u, v), b = PixelMaps::length_pattern(u, v);
        s1 += a, s2 += a * a, l1 += b, l2 += b * b;
      }
    const PixelMaps::PatternSums sums = PixelMaps::pattern_sums(w, h);
    EXPECT_EQ(sums.skew, s1) << w << " x " << h;
    EXPECT_EQ(sums.skew_squared, s2) << w << " x " << h;
    EXPECT_EQ(sums.length, l1) << w << " x " << h;
    EXPECT_EQ(sums.length_squared, l2) << w << " x " << h;
  }
}

TEST(Sensor, FullChipPresetUsesBothPixels) {
  SensorStageConfig c = sweep_config(32, 20);
  c.sensor.preset = PixelPreset::FullChip;
  SensorModel model(c);
  EXPECT_EQ(model.pixel(3, 9).type, 0);
  EXPECT_EQ(model.pixel(3, 10).type, 1);
  EXPECT_NEAR(model.pdp_laser(1) / model.pdp_laser(0), 0.267 / 0.105, 1e-9);
  EXPECT_NEAR(model.pdp_laser(0), 0.105 * 0.45, 1e-12);  // 637 nm: 0.45 of the peak
  const auto j = model.describe();
  EXPECT_EQ(j["pixel_types"].size(), 2u);
  EXPECT_EQ(j["K"], model.K());
  EXPECT_TRUE(j["gate"].contains("knot_max_error"));
  EXPECT_GT(j["gate"]["grid_ps"].get<double>(), 0.25);  // span / 12000 for the default gate: 0.265 ps
  EXPECT_EQ(j["gate"]["knots_per_edge"], 256);
  // The gate model's knobs (sensor.gate.knots_per_edge, grid_ps) reach the gate, and metadata says so.
  c.sensor.gate.knots_per_edge = 16;
  c.sensor.gate.grid_s = 4e-12;
  const auto j16 = SensorModel(c).describe();
  EXPECT_EQ(j16["gate"]["knots_per_edge"], 16);
  EXPECT_DOUBLE_EQ(j16["gate"]["grid_ps"].get<double>(), 4.0);
  EXPECT_GT(j16["gate"]["knot_max_error"].get<double>(), 10 * j["gate"]["knot_max_error"].get<double>());
}

// metadata.json's exposures in microseconds are the scene file's decimals (10 us read 10.000000000000002,
// 2.2222 us 2.2222000000000004: the seconds divided by 1e-6), the dual's long one that of its seconds.
TEST(Sensor, ExposuresAreDescribedInTheirDecimals) {
  SensorStageConfig c = intensity_config(4, 4, Exposure::Single, 100);
  c.acquisition.intensity.exposure_s = 1e-5;  // as the scene file's 10 us reads
  EXPECT_EQ(SensorModel(c).describe()["exposures_us"], nlohmann::json::array({10.0}));
  c = intensity_config(4, 4, Exposure::Dual, 100);
  c.acquisition.intensity.exposure_s = 2.2222e-6;
  c.acquisition.intensity.dual_ratio = 8;
  EXPECT_EQ(SensorModel(c).describe()["exposures_us"], nlohmann::json::array({2.2222, 17.7776}));
}

// Bit-identical results for one tile or tiles of 8, 16, 32, with 1 or 2 threads, counts and frames.
TEST(Sensor, DeterministicAcrossTilesAndThreads) {
  const int W = 40, H = 24;
  SensorStageConfig c = sweep_config(W, H);
  c.acquisition.gate_sweep = {0.6e-9, 6e-9, 72e-12};
  for (bool frames : {false, true}) {
    c.outputs.frames = frames;
    c.sensor.pixel_A.crosstalk_probability = 0.05;
    SensorModel model(c);
    const TimeAxis ax = model.required_window(9e-12);
    Image img(W, H, ax);
    Rng rng(99, RngKind::Test, 0);
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        float* g = img.pixel(x, y);
        const auto b = static_cast<int64_t>(rng.next_double() * static_cast<double>(ax.bins - 20));
        g[b] = 0.05f * rng.next_float();
        g[b + 3] = 0.02f * rng.next_float();
        if (x % 3 == 0) g[ax.bins / 2] = 0.5f;
        img.ambient[static_cast<size_t>(y * W + x)] = 1e4f * rng.next_float();
      }
    auto run = [&](int tile, int threads) {
      tbb::global_control gc(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(threads));
      const std::vector<PixelRect> tiles = tile > 0 ? make_tiles(W, H, tile) : std::vector<PixelRect>{{0, 0, W, H}};
      const auto K = static_cast<size_t>(model.K());
      const uint32_t N = static_cast<uint32_t>(model.frames_per_k());
      const size_t bpr = (W + 7) / 8;
      std::vector<uint16_t> counts(K * W * H);
      std::vector<float> expected(K * W * H);
      std::vector<uint8_t> fr(frames ? K * N * H * bpr : 0);
      for (const PixelRect& r : tiles) {
        const SensorTile t = model.process(img.tile(r, model.halo()));
        const size_t tb = static_cast<size_t>((r.width + 7) / 8);
        for (size_t k = 0; k < K; ++k)
          for (int y = r.y0; y < r.y1(); ++y)
            for (int x = r.x0; x < r.x1(); ++x) {
              const size_t i = k * static_cast<size_t>(r.count()) + static_cast<size_t>(r.index(x, y));
              counts[k * W * H + static_cast<size_t>(y * W + x)] = t.counts[i];
              expected[k * W * H + static_cast<size_t>(y * W + x)] = t.expected[i];
              if (frames) {
                int c_bits = 0;
                for (uint32_t f = 0; f < N; ++f) {
                  const size_t src = ((k * N + f) * static_cast<size_t>(r.height) + static_cast<size_t>(y - r.y0)) * tb + static_cast<size_t>((x - r.x0) / 8);
                  const bool bit = (t.frames[src] >> ((x - r.x0) % 8)) & 1u;
                  c_bits += bit;
                  const size_t dst = ((k * N + f) * H + static_cast<size_t>(y)) * bpr + static_cast<size_t>(x / 8);
                  if (bit) fr[dst] = static_cast<uint8_t>(fr[dst] | (1u << (x % 8)));
                }
                EXPECT_EQ(c_bits, t.counts[i]);
              }
            }
      }
      return std::tuple{counts, expected, fr};
    };
    const auto ref = run(0, 2);
    double total = 0;
    for (uint16_t v : std::get<0>(ref)) total += v;
    EXPECT_GT(total, 1000.0);
    for (int tile : {8, 16, 32})
      for (int threads : {1, 2}) {
        const auto got = run(tile, threads);
        EXPECT_TRUE(std::get<0>(got) == std::get<0>(ref)) << "counts tile " << tile << " threads " << threads;
        EXPECT_TRUE(std::get<1>(got) == std::get<1>(ref)) << "expected tile " << tile << " threads " << threads;
        EXPECT_TRUE(std::get<2>(got) == std::get<2>(ref)) << "frames tile " << tile << " threads " << threads;
      }
  }
}

// The renderer's range of non-zero bins (TransientTile::bin_lo / bin_hi) only saves reading empty bins:
// with exact ranges, with wider ones and without any, counts and expectations are bit-identical; a range
// of the wrong size is an error.
TEST(Sensor, BinRangesChangeNothing) {
  const int W = 24, H = 16;
  SensorStageConfig c = sweep_config(W, H);
  c.acquisition.gate_sweep = {0.6e-9, 6e-9, 36e-12};
  SensorModel model(c);
  const TimeAxis ax = model.required_window(9e-12);
  Image img(W, H, ax);
  Rng rng(77, RngKind::Test, 0);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      float* g = img.pixel(x, y);
      if ((x + y) % 5 == 0) continue;  // no light in the window
      const auto b = static_cast<int64_t>(rng.next_double() * static_cast<double>(ax.bins - 40));
      for (int i = 0; i < 1 + (x % 4) * 10; ++i) g[b + i] = 0.01f * rng.next_float();
      if (x % 7 == 0) g[ax.bins - 1] = 0.2f;  // the window's last bin
      if (y % 6 == 0) g[0] = 0.3f;            // and its first
      img.ambient[static_cast<size_t>(y * W + x)] = 1e5f * rng.next_float();
    }
  const PixelRect r{8, 0, 8, 16};
  const TransientTile plain = img.tile(r, model.halo());
  ASSERT_TRUE(plain.bin_lo.empty());
  TransientTile exact = plain;
  exact.set_bin_ranges_from_data();
  TransientTile wide = exact;
  const auto n = static_cast<size_t>(plain.data_rect.count());
  size_t dark = 0;
  for (size_t i = 0; i < n; ++i) {
    // the ranges hold the light: checked independently of set_bin_ranges_from_data
    const float* g = plain.transient.data() + i * static_cast<size_t>(ax.bins);
    for (int64_t b = 0; b < ax.bins; ++b)
      if (g[b] != 0.0f) {
        ASSERT_TRUE(b >= exact.bin_lo[i] && b < exact.bin_hi[i]) << i << " " << b;
      }
    dark += exact.bin_lo[i] >= exact.bin_hi[i];
    wide.bin_lo[i] = std::max(0, exact.bin_lo[i] - 37);
    wide.bin_hi[i] = std::min(static_cast<int32_t>(ax.bins), exact.bin_hi[i] + 100);
  }
  EXPECT_GT(dark, 0u);  // some pixels have no light in the window: empty ranges
  const SensorTile a = model.process(plain), b = model.process(exact), w = model.process(wide);
  EXPECT_TRUE(a.counts == b.counts && a.expected == b.expected);
  EXPECT_TRUE(a.counts == w.counts && a.expected == w.expected);
  double total = 0;
  for (uint16_t v : a.counts) total += v;
  EXPECT_GT(total, 1000.0);
  TransientTile bad = exact;
  bad.bin_hi.pop_back();
  EXPECT_THROW(model.process(bad), Error);
}

// Each pixel's PDP is the curve times 1 + pdp_nonuniformity z (z truncated at 5): a design whose pixels
// could pass a PDP of 1 is refused (a pdp_peak of 1 gave half the pixels a PDP above 1, up to 1.05 at the
// default spread; a peak wavelength off the built-in curve's peak scaled the curve past 1 at 520 nm).
TEST(Sensor, APdpAboveOneIsRefused) {
  const auto message = [](const SensorStageConfig& c) {
    try {
      SensorModel m(c);
      return std::string();
    } catch (const Error& e) {
      return std::string(e.what());
    }
  };
  SensorStageConfig c = sweep_config(8, 8);
  c.sensor.pixel_A.pdp_peak = 1.0;
  c.sensor.pixel_A.pdp_nonuniformity = 0.014;
  const auto says = [&](const std::string& what) { return message(c).find(what) != std::string::npos; };
  // named by the key that sets the curve's most (a KeyError, which the program names as the user gave it)
  EXPECT_TRUE(says("sensor.pixel_A.pdp_peak: found 1: the PDP curve reaches 1, and sensor.pixel_A.pdp_nonuniformity 0.014 "
                   "spreads it to 1.07 (times 1 + 5 sigma); expected a photon detection probability of at most 1")) << message(c);
  c.sensor.pdp_nonuniformity = false;  // no spread: a PDP of 1 is a probability
  EXPECT_EQ(message(c), "");
  const SensorModel ideal(c);
  const SensorMapsTile maps = ideal.maps({0, 0, 8, 8});
  for (float pde : maps.pde) EXPECT_LE(pde, 1.0f);
  c.sensor.pdp_nonuniformity = true;
  c.sensor.pixel_A.pdp_peak = 0.9, c.sensor.pixel_A.pdp_nonuniformity = 0.02;  // 0.9 x 1.1 = 0.99
  EXPECT_EQ(message(c), "");
  c.sensor.pixel_A.pdp_peak = 0.3, c.sensor.pixel_A.pdp_peak_wavelength_m = 350e-9;  // 0.22 of the curve's peak there
  EXPECT_TRUE(says("sensor.pixel_A.pdp_peak_wavelength_nm: found 350 nm, off the built-in curve's own peak (520 nm): scaled "
                   "so that PDP there is sensor.pixel_A.pdp_peak 0.3, the curve reaches 1.36")) << message(c);
}

TEST(Sensor, TileWithoutHaloIsRejected) {
  SensorStageConfig c = sweep_config(16, 16);
  SensorModel model(c);
  const TimeAxis ax = model.required_window(20e-12);
  Image img(16, 16, ax);
  EXPECT_THROW(model.process(img.tile({0, 0, 8, 8}, 0)), Error);
  EXPECT_NO_THROW(model.process(img.tile({0, 0, 8, 8}, 1)));
}

// The sensor's outputs pinned, bit for bit, so that a change of its rules is seen here and comes with a
// revision of the datasets' sample hash (DatasetFolder::revisions_of, datasets/folder.cpp), which makes the
// samples drawn by the old rule stale: a dataset resumed with a new build kept them as done beside samples of
// the new rule (the chip's DCR median, e3f0a42, had no revision). A chip with both pixel designs, dark counts,
// hot pixels, crosstalk, gate maps and PDP spread; a return whose time and strength vary across the image, and
// ambient light on its lower half; counts, expected counts and binary frames of a gate sweep, and a dual
// exposure's 2D counts. The bits are the same on every instruction set the kernels dispatch to.
TEST(Sensor, OutputsArePinnedSoThatARuleChangeComesWithADatasetRevision) {
  const auto fnv = [](uint64_t h, const void* data, size_t bytes) {
    const auto* b = static_cast<const unsigned char*>(data);
    for (size_t i = 0; i < bytes; ++i) h = (h ^ b[i]) * 1099511628211ull;
    return h;
  };
  const auto image_of = [](const SensorModel& model, int w, int h) {
    Image img(w, h, model.required_window(20e-12));
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const float photons = 2e-4f * float(1 + (x * 7 + y * 3) % 11);
        if (img.axis.bins > 0)  // (a 2D run's window holds no bins)
          img.pixel(x, y)[std::min<int64_t>(img.axis.bins - 1, 40 + 7 * x)] = photons;
        img.laser_total[size_t(y * w + x)] = photons;
        img.ambient[size_t(y * w + x)] = y >= h / 2 ? 3e5f : 0.0f;
      }
    return img;
  };
  constexpr int kW = 32, kH = 16;
  const auto outputs_hash = [&]() -> uint64_t {
    SensorStageConfig c = sweep_config(kW, kH);
    c.sensor.preset = PixelPreset::FullChip;
    c.acquisition.gate_sweep = {0.6e-9, 4.2e-9, 36e-12};
    c.outputs.frames = true;
    const SensorModel sweep(c);
    const SensorTile s = sweep.process(image_of(sweep, kW, kH).tile({0, 0, kW, kH}, sweep.halo()));
    EXPECT_EQ(s.counts.size(), size_t(sweep.K()) * kW * kH);
    EXPECT_EQ(s.frames.size(), size_t(sweep.K()) * 255 * kH * (kW / 8));
    EXPECT_GT(*std::max_element(s.counts.begin(), s.counts.end()), 0);
    uint64_t h = 14695981039346656037ull;
    h = fnv(h, s.counts.data(), s.counts.size() * sizeof(uint16_t));
    h = fnv(h, s.expected.data(), s.expected.size() * sizeof(float));
    h = fnv(h, s.frames.data(), s.frames.size());
    SensorStageConfig d = c;
    d.acquisition.mode = AcquisitionMode::Intensity;
    d.acquisition.intensity.exposure = Exposure::Dual;
    d.acquisition.frames = 1020;
    d.outputs.frames = false;
    const SensorModel two_d(d);
    const SensorTile t = two_d.process(image_of(two_d, kW, kH).tile({0, 0, kW, kH}, two_d.halo()));
    EXPECT_EQ(t.intensity_counts.size(), size_t(kW) * kH);
    h = fnv(h, t.intensity_counts.data(), t.intensity_counts.size() * sizeof(float));
    return fnv(h, t.intensity_photons.data(), t.intensity_photons.size() * sizeof(float));
  };
  // on every instruction set the kernels are compiled for that this processor runs
  for (const int64_t target : hwy::SupportedAndGeneratedTargets()) {
    hwy::SetSupportedTargetsForTest(target);
    const uint64_t h = outputs_hash();
    char hex[17];
    std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(h));
    EXPECT_EQ(std::string(hex), "4affb0f15e7baa10")
        << hwy::TargetName(target) << ": the sensor's outputs changed. A change of its rules (not a refactoring, which "
           "keeps these bits) changes what datasets' samples hold: add a revision for it to DatasetFolder::revisions_of "
           "(datasets/folder.cpp), where it applies, so that samples drawn by the old rule are stale; then pin the new "
           "value here";
  }
  hwy::SetSupportedTargetsForTest(0);
}

}  // namespace
}  // namespace spadgen::sensor
