// Small pictures a person opens first (previews/*.png): a depth map, an intensity image and gate
// profiles of a few pixels. Everything renders to plain RGB8 buffers; nothing here touches the disk
// except write_png(path, Rgb8Image).
#pragma once
#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace spadgen::writers {

// RGB, 3 bytes per pixel, row-major, top row first.
struct Rgb8Image {
  int width = 0, height = 0;
  std::vector<uint8_t> pixels;

  Rgb8Image() = default;
  Rgb8Image(int w, int h, std::array<uint8_t, 3> fill = {0, 0, 0});
  uint8_t* at(int x, int y) { return pixels.data() + (size_t(y) * size_t(width) + size_t(x)) * 3; }
  const uint8_t* at(int x, int y) const { return pixels.data() + (size_t(y) * size_t(width) + size_t(x)) * 3; }
};

// Atomic, like the other write_png.
void write_png(const std::string& path, const Rgb8Image& image);

// Viridis, matplotlib's perceptually uniform colour map (from its published 6th-order polynomial fit):
// dark blue-violet at t = 0, yellow at t = 1, luminance rising monotonically. t is clamped to [0, 1].
std::array<uint8_t, 3> viridis(double t);

// Depth as colour: range near_m maps to yellow (bright: near looks close), far_m to dark violet; values
// outside are clamped; a miss (+inf, NaN, or <= 0) is black. If !(far_m > near_m) the range is taken
// from the finite positive values. With `legend` (and width >= 48) a colour bar with the near, middle
// and far distances in metres is appended below, making the result kDepthLegendHeight rows taller, and
// kDepthLegendRow more where the near and far labels do not fit side by side (the far one goes below).
inline constexpr int kDepthLegendHeight = 24, kDepthLegendRow = 9;
Rgb8Image depth_preview(const float* range, int width, int height, float near_m, float far_m, bool legend = true);

// Intensity as gray: black at 0, white at the `white_percentile` percentile of the finite values (above
// it saturates), encoded with 1 / gamma so dark scenes stay readable. Non-finite values are black.
Rgb8Image gray_preview(const float* values, int width, int height, float gamma = 2.2f,
                       float white_percentile = 99.5f);

// Where profile_plot puts things. Pixel centres are at integer coordinates; px/py map data to them.
struct PlotLayout {
  int left = 0, top = 0, right = 0, bottom = 0;  // plot area, inclusive, axes drawn on left and bottom
  double x_min = 0, x_max = 1, y_min = 0, y_max = 1;
  std::vector<double> x_ticks, y_ticks;
  int tick_decimals_x = 0, tick_decimals_y = 0;
  double px(double x) const { return left + (x - x_min) / (x_max - x_min) * (right - left); }
  double py(double y) const { return bottom - (y - y_min) / (y_max - y_min) * (bottom - top); }
};

// Layout of a plot of curves[i][j] against x[j] in a width x height picture: the y axis starts at
// min(0, smallest value) and both axes end on a "nice" tick (1, 2 or 5 times a power of ten).
// Non-finite values are ignored. Throws spadgen::Error if a curve's length differs from x's.
PlotLayout profile_plot_layout(const std::vector<std::vector<float>>& curves, const std::vector<double>& x,
                               int width, int height, bool x_label = false, bool y_label = false);

// Gate profiles: each curve an anti-aliased 1.5 px line in plot_colour(i) on white, with axes, tick
// marks, numeric tick labels and optional axis labels in a built-in 5x7 font (digits, . - + ( ) / and
// the lower-case letters a-i, k-p, r-u, x, y; upper case is drawn as lower case, other characters as
// blanks). Breaks a line at non-finite values.
Rgb8Image profile_plot(const std::vector<std::vector<float>>& curves, const std::vector<double>& x, int width,
                       int height, const std::string& x_label = "", const std::string& y_label = "");

// The colour of curve i (a qualitative palette that cycles after 8 curves).
std::array<uint8_t, 3> plot_colour(size_t i);

// Text in the built-in 5x7 font (6 px advance), top-left corner at (x, y), clipped to the image.
void draw_text(Rgb8Image& image, int x, int y, const std::string& text, std::array<uint8_t, 3> colour);
int text_width(const std::string& text);

}  // namespace spadgen::writers
