// Per-pixel parameters: pixel type, gate skew and length deviation, dark count rate, PDP scale.
//
// Every value is drawn from a counter-based stream keyed by (seed, SensorMaps, pixel index, map id), so a
// pixel's parameters never depend on the tile, the crop or the thread that asks for them.
//
// Gate skew and length: a smooth spatial pattern (the paper's Fig. 5(b): the gate arrives later towards
// the top of the array, and across the top rows the skew is asymmetric, later towards the right) plus an
// independent per-pixel Gaussian part truncated at 5 sigma. The pattern is normalised over the array
// section so that pattern and random part together have the standard deviation of a Gaussian with the
// requested FWHM (FWHM = 2.3548 sigma); the skew pattern carries 80 % of the variance, the length pattern
// 50 %. Both have zero mean over the section. With preset full_chip each half (pixel A rows, pixel B rows)
// is a separate section with its own gate tree, so each half gets the pattern (sections: pixel_layout.h).
//
// DCR: log-normal main population (log sigma dcr_log_sigma) and a hot-pixel tail (hot_pixel_fraction of
// pixels, hot_pixel_factor times the main population's median, same log sigma), times the temperature factor
// of temperature_factor(). dcr_median_cps is the chip's median, main and hot pixels together, as the paper
// gives it (Fig. 4(a): 0.4 and 2.0 cps); the main population's median is below it (dcr_main_median).
#pragma once
#include <cstdint>
#include <vector>

#include "core/config.h"
#include "sensor/model/pixel_layout.h"

namespace spadgen::sensor {

struct PixelParams {
  int type = 0;           // 0: sensor.pixel_A settings, 1: sensor.pixel_B settings
  int section = 0;        // array section (crosstalk does not cross sections)
  double skew_s = 0.0;    // gate position offset
  double dL_s = 0.0;      // gate length minus the nominal length
  double dcr_cps = 0.0;   // at the set temperature (0 when dark counts are off)
  double pdp_scale = 1.0; // per-pixel PDP non-uniformity factor
};

class PixelMaps {
 public:
  PixelMaps(const SensorStageConfig& config, double nominal_length_s);

  PixelParams at(int x, int y) const;
  const PixelLayout& layout() const { return layout_; }
  int section_of_row(int y) const { return layout_.section_of_row(y); }

  // Measured maps, full-sensor row-major arrays (width * height): gate skew in ps and absolute gate length
  // (50 %-50 %) in ps. Replace the generated skew and length maps. Throws spadgen::Error on a size mismatch
  // or a non-finite value.
  void set_gate_maps(std::vector<float> skew_ps, std::vector<float> length_ps);
  bool has_user_maps() const { return !user_skew_ps_.empty(); }

  // Bounds over every pixel of the sensor, for the render window.
  double min_skew_s() const { return min_skew_; }
  double max_skew_s() const { return max_skew_; }
  double max_dL_s() const { return max_dL_; }

  // The smooth patterns at (u, v): u = x / (W - 1) from left to right, v = 1 at the top row of the section,
  // 0 at its bottom row; unnormalised.
  static double skew_pattern(double u, double v);
  static double length_pattern(double u, double v);
  // The patterns' sums over a section of width x height pixels (u = x / (width - 1), v = 1 - y / (height - 1),
  // row by row), for their exact mean and spread.
  struct PatternSums {
    double skew = 0, skew_squared = 0, length = 0, length_squared = 0;
  };
  static PatternSums pattern_sums(int width, int height);

  // DCR(T) / DCR(25 C). Two components, tunnelling (flat in temperature) and diffusion (Arrhenius with
  // 1.1 eV), each half of the DCR at 25 C: below about 10 C the tunnelling part dominates and the factor is
  // flat (0.51 at 0 C, 0.55 at 10 C); above about 30 C the diffusion part dominates and the factor rises
  // with 1.1 eV (1.5 at 30 C, 4.4 at 40 C, 14 at 50 C). The sum is the interpolation between the regimes.
  static double temperature_factor(double temperature_C);

  // The main population's median DCR at 25 C that puts the chip's median (main and hot pixels together) at
  // t.dcr_median_cps: 0.936 of it at the defaults (5 % hot pixels at 100 times, log sigma 1), t.dcr_median_cps
  // itself without hot pixels.
  static double dcr_main_median(const PixelTypeConfig& t);

 private:
  struct SectionStats {
    int y0 = 0, height = 0;
    double skew_mean = 0, skew_scale = 0, len_mean = 0, len_scale = 0;
  };
  const SectionStats& section(int y) const { return sections_[static_cast<size_t>(section_of_row(y))]; }

  const SensorStageConfig& cfg_;
  double nominal_length_s_;
  int width_, height_;
  PixelLayout layout_;
  std::vector<SectionStats> sections_;
  double skew_sigma_r_ = 0, len_sigma_r_ = 0;  // random parts, seconds
  double temp_factor_ = 1.0;
  double main_dcr_cps_[2] = {0.0, 0.0};  // dcr_main_median of pixel A and pixel B
  double min_skew_ = 0, max_skew_ = 0, max_dL_ = 0;
  std::vector<float> user_skew_ps_, user_length_ps_;
};

}  // namespace spadgen::sensor
