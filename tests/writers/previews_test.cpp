#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "core/error.h"
#include "test_util.h"
#include "writers/previews.h"

namespace spadgen::writers {
namespace {

double luma(const uint8_t* p) { return 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]; }
double luma(std::array<uint8_t, 3> c) { return luma(c.data()); }

// CIE L* of an sRGB colour: the lightness viridis is designed to raise steadily.
double lightness(std::array<uint8_t, 3> c) {
  auto lin = [](uint8_t v) {
    const double s = v / 255.0;
    return s <= 0.04045 ? s / 12.92 : std::pow((s + 0.055) / 1.055, 2.4);
  };
  const double Y = 0.2126 * lin(c[0]) + 0.7152 * lin(c[1]) + 0.0722 * lin(c[2]);
  return Y > 216.0 / 24389.0 ? 116.0 * std::cbrt(Y) - 16.0 : Y * 24389.0 / 27.0;
}

TEST(Viridis, LightnessRisesMonotonicallyAndEndsMatchMatplotlib) {
  // Strictly rising over steps of 1/32; between neighbouring 8-bit entries only rounding may wobble.
  for (int i = 1; i <= 32; ++i) EXPECT_GT(lightness(viridis(i / 32.0)), lightness(viridis((i - 1) / 32.0)) + 1.0) << i;
  for (int i = 1; i <= 255; ++i) EXPECT_GT(lightness(viridis(i / 255.0)), lightness(viridis((i - 1) / 255.0)) - 0.3) << i;
  EXPECT_GT(luma(viridis(1.0)) - luma(viridis(0.0)), 150.0);
  // matplotlib's viridis: #440154 at 0, #fde725 at 1 (the fit is within a few levels).
  const auto lo = viridis(0.0), hi = viridis(1.0);
  EXPECT_NEAR(lo[0], 0x44, 6);
  EXPECT_NEAR(lo[1], 0x01, 6);
  EXPECT_NEAR(lo[2], 0x54, 6);
  EXPECT_NEAR(hi[0], 0xfd, 6);
  EXPECT_NEAR(hi[1], 0xe7, 6);
  EXPECT_NEAR(hi[2], 0x25, 12);
  EXPECT_EQ(viridis(-3.0), viridis(0.0));
  EXPECT_EQ(viridis(std::nan("")), viridis(0.0));
  EXPECT_EQ(viridis(7.0), viridis(1.0));
}

TEST(DepthPreview, NearIsBrightFarIsDarkAndMissesBlack) {
  const int w = 64, h = 4;
  const float inf = std::numeric_limits<float>::infinity();
  std::vector<float> r(size_t(w * h));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) r[size_t(y * w + x)] = 1.0f + float(x) / float(w - 1);  // 1 m .. 2 m
  r[size_t(1 * w + 5)] = inf;
  r[size_t(2 * w + 6)] = std::nanf("");
  r[size_t(3 * w + 7)] = 0.0f;
  const Rgb8Image im = depth_preview(r.data(), w, h, 1.0f, 2.0f);
  ASSERT_EQ(im.width, w);
  // 64 px hold "1.000 m" and "2.000 m" (41 px each) only one above the other: the far one a row lower
  ASSERT_EQ(im.height, h + kDepthLegendHeight + kDepthLegendRow);
  const auto white_in = [&](const Rgb8Image& m, int x0, int x1, int y0, int y1) {
    int n = 0;
    for (int y = y0; y < y1; ++y)
      for (int x = x0; x < x1; ++x) n += m.at(x, y)[0] == 255 && m.at(x, y)[1] == 255 && m.at(x, y)[2] == 255;
    return n;
  };
  EXPECT_GT(white_in(im, 0, 40, h + 15, h + 24), 20) << "the near label, left";
  EXPECT_EQ(white_in(im, 44, w, h + 15, h + 24), 0) << "nothing of the far label beside it";
  EXPECT_GT(white_in(im, w - 40, w, h + 24, h + 33), 20) << "the far label, right, a row lower";
  {  // wide enough for both on one row, and the middle one
    std::vector<float> wide(256 * 2, 1.5f);
    EXPECT_EQ(depth_preview(wide.data(), 256, 2, 1.0f, 2.0f).height, 2 + kDepthLegendHeight);
  }
  for (auto [x, y] : {std::pair{5, 1}, {6, 2}, {7, 3}}) {
    const uint8_t* p = im.at(x, y);
    EXPECT_EQ(p[0] + p[1] + p[2], 0) << x << "," << y;
  }
  // Row 0 has no misses: luminance must fall with range, strictly over every 4 pixels.
  for (int x = 4; x < w; ++x) {
    EXPECT_LE(luma(im.at(x, 0)), luma(im.at(x - 1, 0))) << x;
    EXPECT_LT(luma(im.at(x, 0)), luma(im.at(x - 4, 0))) << x;
  }
  const auto nearest = viridis(1.0), farthest = viridis(0.0);
  EXPECT_TRUE(std::equal(nearest.begin(), nearest.end(), im.at(0, 0)));
  EXPECT_TRUE(std::equal(farthest.begin(), farthest.end(), im.at(w - 1, 0)));
  // The legend's colour bar runs from near (left) to far (right).
  const int bar_y = h + 6;
  EXPECT_GT(luma(im.at(4, bar_y)), luma(im.at(w - 5, bar_y)) + 100);
}

TEST(DepthPreview, ClampsOutsideValuesAndFindsTheRangeItself) {
  std::vector<float> r = {0.5f, 3.0f, 1.0f, 2.0f};
  const Rgb8Image clamped = depth_preview(r.data(), 4, 1, 1.0f, 2.0f, false);
  ASSERT_EQ(clamped.height, 1);
  EXPECT_TRUE(std::equal(clamped.at(0, 0), clamped.at(0, 0) + 3, clamped.at(2, 0)));
  EXPECT_TRUE(std::equal(clamped.at(1, 0), clamped.at(1, 0) + 3, clamped.at(3, 0)));
  const Rgb8Image autorange = depth_preview(r.data(), 4, 1, 0.0f, 0.0f, false);
  const auto nearest = viridis(1.0), farthest = viridis(0.0);
  EXPECT_TRUE(std::equal(nearest.begin(), nearest.end(), autorange.at(0, 0)));
  EXPECT_TRUE(std::equal(farthest.begin(), farthest.end(), autorange.at(1, 0)));
  // A narrow picture gets no legend.
  EXPECT_EQ(depth_preview(r.data(), 4, 1, 1.0f, 2.0f, true).height, 1);
}

TEST(GrayPreview, PercentileWhitePointAndGamma) {
  std::vector<float> v(100);
  for (int i = 0; i < 100; ++i) v[size_t(i)] = float(i);
  v[50] = std::numeric_limits<float>::quiet_NaN();
  const Rgb8Image im = gray_preview(v.data(), 100, 1, 2.0f, 90.0f);
  // 99 finite values; the 90th percentile is element floor(0.9 * 98) = 88 of 0..99 without 50, i.e. 89.
  EXPECT_EQ(im.at(0, 0)[0], 0);
  EXPECT_EQ(im.at(50, 0)[0], 0);  // NaN
  EXPECT_EQ(im.at(89, 0)[0], 255);
  EXPECT_EQ(im.at(99, 0)[0], 255);
  EXPECT_LT(im.at(88, 0)[0], 255);
  // gamma 2: a quarter of white shows as half gray.
  EXPECT_NEAR(im.at(22, 0)[0], std::lround(255.0 * std::sqrt(22.0 / 89.0)), 1);
  EXPECT_EQ(im.at(22, 0)[0], im.at(22, 0)[1]);
  for (int x = 52; x < 100; ++x) EXPECT_GE(im.at(x, 0)[0], im.at(x - 1, 0)[0]);
  // All dark: stays black, no division by zero.
  std::vector<float> zeros(16, 0.0f);
  const Rgb8Image black = gray_preview(zeros.data(), 4, 4);
  for (uint8_t b : black.pixels) EXPECT_EQ(b, 0);
}

bool near_colour(const uint8_t* p, std::array<uint8_t, 3> c, int tol) {
  for (int k = 0; k < 3; ++k)
    if (std::abs(int(p[k]) - int(c[size_t(k)])) > tol) return false;
  return true;
}

TEST(ProfilePlot, DrawsKnownPointsAxesAndTicks) {
  // Two gate profiles over gate positions in ns.
  std::vector<double> x;
  std::vector<std::vector<float>> curves(2);
  for (int i = 0; i <= 100; ++i) {
    x.push_back(0.6 + 0.036 * i);
    curves[0].push_back(i < 40 ? 0.0f : 200.0f);
    curves[1].push_back(float(i));
  }
  const int w = 320, h = 200;
  const Rgb8Image im = profile_plot(curves, x, w, h, "gate position (ns)", "counts");
  const PlotLayout L = profile_plot_layout(curves, x, w, h, true, true);
  ASSERT_EQ(im.width, w);
  ASSERT_EQ(im.height, h);
  EXPECT_EQ(L.y_min, 0.0);
  EXPECT_GE(L.y_max, 200.0);
  EXPECT_DOUBLE_EQ(L.x_min, 0.6);
  EXPECT_DOUBLE_EQ(L.x_max, 0.6 + 3.6);

  // A point on the plateau of curve 0 and one on the ramp of curve 1 are drawn in their colours.
  const int ax = int(std::lround(L.px(x[70]))), ay = int(std::lround(L.py(200.0)));
  EXPECT_TRUE(near_colour(im.at(ax, ay), plot_colour(0), 40)) << int(im.at(ax, ay)[0]);
  const int bx = int(std::lround(L.px(x[30]))), by = int(std::lround(L.py(30.0)));
  EXPECT_TRUE(near_colour(im.at(bx, by), plot_colour(1), 40));
  // Away from the curves the background is white (or a light grid line).
  const uint8_t* empty = im.at(int(std::lround(L.px(x[10]))) + 1, int(std::lround(L.py(150.0))) + 1);
  EXPECT_GE(empty[0], 220);
  // Axes and tick marks are black.
  EXPECT_TRUE(near_colour(im.at(L.left, (L.top + L.bottom) / 2), {0, 0, 0}, 0));
  EXPECT_TRUE(near_colour(im.at((L.left + L.right) / 2, L.bottom), {0, 0, 0}, 0));
  ASSERT_GE(L.y_ticks.size(), 3u);
  for (double t : L.y_ticks) EXPECT_TRUE(near_colour(im.at(L.left - 2, int(std::lround(L.py(t)))), {0, 0, 0}, 0));
  ASSERT_GE(L.x_ticks.size(), 3u);
  for (double t : L.x_ticks) EXPECT_TRUE(near_colour(im.at(int(std::lround(L.px(t))), L.bottom + 2), {0, 0, 0}, 0));
  // Tick labels put dark pixels left of the y axis.
  int dark = 0;
  for (int y = L.top; y <= L.bottom; ++y)
    for (int xx = 0; xx < L.left - 4; ++xx) dark += im.at(xx, y)[0] < 128;
  EXPECT_GT(dark, 10);
}

TEST(ProfilePlot, HandlesGapsSinglePointsAndBadInput) {
  std::vector<double> x = {0, 1, 2, 3, 4};
  const float nan = std::nanf("");
  std::vector<std::vector<float>> c = {{1, nan, 3, nan, 2}};
  const Rgb8Image im = profile_plot(c, x, 120, 80);
  const PlotLayout L = profile_plot_layout(c, x, 120, 80);
  // The lone point at x = 2 still shows as a dot; nothing bridges the gaps.
  EXPECT_TRUE(near_colour(im.at(int(std::lround(L.px(2))), int(std::lround(L.py(3)))), plot_colour(0), 60));
  EXPECT_GE(im.at(int(std::lround(L.px(1.5))), int(std::lround(L.py(2)))) [0], 200);
  EXPECT_THROW(profile_plot({{1, 2}}, x, 120, 80), Error);
  EXPECT_THROW(profile_plot(c, x, 10, 10), Error);
  EXPECT_NO_THROW(profile_plot({}, {}, 120, 80));
}

TEST(Font, DrawsGlyphsAndSkipsUnknownCharacters) {
  Rgb8Image im(40, 9, {255, 255, 255});
  draw_text(im, 1, 1, "1.5 ns", {0, 0, 0});
  int dark = 0;
  for (size_t i = 0; i < im.pixels.size(); i += 3) dark += im.pixels[i] == 0;
  EXPECT_GT(dark, 20);
  EXPECT_EQ(text_width("1.5 ns"), 35);
  Rgb8Image blank(10, 9, {255, 255, 255});
  draw_text(blank, 0, 0, "~", {0, 0, 0});
  for (uint8_t b : blank.pixels) EXPECT_EQ(b, 255);
}

}  // namespace
}  // namespace spadgen::writers
