// render.split_direct_indirect, and the renderer at the extremes of scale: a plane at 1 km (folding by the
// laser period), a plane at 5 mm, and a return of 1e-9 photons per pulse. Tolerances: 6 sigma of the
// Monte Carlo error (false-alarm rate 2e-9 per comparison, fixed seeds) plus the stated float rounding.
#include <gtest/gtest.h>

#include <cmath>
#include <numeric>
#include <vector>

#include "core/units.h"
#include "render/renderer.h"
#include "scene_builders.h"

namespace spadgen::render {
namespace {

using test::add_material;
using test::add_quad;
using test::test_config;

constexpr double kC = kSpeedOfLight;

double flood_intensity(const RenderStageConfig& c) {
  const double half_diag = 0.5 * c.camera.pixel_pitch_m * std::hypot(c.camera.width_px, c.camera.height_px);
  const double alpha = std::atan2(half_diag, c.camera.focal_length_m);
  const double np = photons_per_pulse(c.laser.average_power_W, c.laser.repetition_rate_Hz, c.laser.wavelength_m);
  return np / (2 * kPi * (1 - std::cos(alpha)));
}

// rho I p^2 FF / (4 N^2 d^2): a Lambertian plane at distance d on the axis, lit from the camera.
double on_axis_photons(const RenderStageConfig& c, double rho, double d) {
  return rho * flood_intensity(c) * std::pow(c.camera.pixel_pitch_m, 2) * c.row_fill_factor[0] /
         (4 * std::pow(c.camera.f_number, 2) * d * d);
}

// Mean over pixel (x, y) (16 x 16 midpoint grid) of g(unit ray direction).
template <class G>
double pixel_mean(const RenderStageConfig& c, int x, int y, G g) {
  const double p = c.camera.pixel_pitch_m;
  double s = 0;
  for (int j = 0; j < 16; ++j)
    for (int i = 0; i < 16; ++i)
      s += g(glm::normalize(glm::dvec3((x + (i + 0.5) / 16 - c.camera.width_px / 2.0) * p,
                                       (c.camera.height_px / 2.0 - y - (j + 0.5) / 16) * p, -c.camera.focal_length_m)));
  return s / 256;
}

double mean_time(const float* g, const TimeAxis& axis) {
  double m0 = 0, m1 = 0;
  for (int64_t b = 0; b < axis.bins; ++b) {
    m0 += g[b];
    m1 += double(g[b]) * axis.bin_centre_s(b);
  }
  return m1 / m0;
}

scenes::Scene plane_at(double d, float rho, float half_size) {
  scenes::Scene s;
  add_quad(s, {0, 0, float(-d)}, {half_size, 0, 0}, {0, half_size, 0}, add_material(s, test::lambertian(rho)));
  return s;
}

// ---------------------------------------------------------------------------------------------------
// Direct and indirect transients.

TEST(Split, OffByDefaultAndALonePlaneHasNoIndirectLight) {
  RenderStageConfig c = test_config(8, 8, 12e-3);
  c.render.samples_per_pixel = 4;
  const TimeAxis axis{6e-9, 5e-12, 200, 25e-9};
  {
    Renderer r(plane_at(1.0, 0.6f, 5.0f), c);
    EXPECT_TRUE(r.transient({0, 0, 8, 8}, {0, 0, 8, 8}, axis).transient_indirect.empty());
  }
  c.render.split_direct_indirect = true;
  Renderer r(plane_at(1.0, 0.6f, 5.0f), c);
  const TransientTile t = r.transient({0, 0, 8, 8}, {0, 0, 8, 8}, axis);
  ASSERT_EQ(t.transient_indirect.size(), t.transient.size());
  EXPECT_GT(std::accumulate(t.transient.begin(), t.transient.end(), 0.0), 0.0);
  for (float v : t.transient_indirect) ASSERT_EQ(v, 0.0f);
  // No transient asked: nothing to split.
  EXPECT_TRUE(r.transient({0, 0, 8, 8}, {0, 0, 8, 8}, TimeAxis{}).transient_indirect.empty());
}

// Three perpendicular Lambertian walls meeting in the corner (0, 0, -1), open towards the camera at
// (0.2, 0.2, 0): back wall z = -1, left wall x = 0, floor y = 0, each 0.6 m wide.
scenes::Scene open_corner() {
  scenes::Scene s;
  const int m = add_material(s, test::lambertian(0.7f));
  add_quad(s, {0.3f, 0.3f, -1.0f}, {0.3f, 0, 0}, {0, 0.3f, 0}, m);   // back wall, facing +z
  add_quad(s, {0, 0.3f, -0.7f}, {0, 0, 0.3f}, {0, 0.3f, 0}, m);      // left wall, facing +x
  add_quad(s, {0.3f, 0, -0.7f}, {0.3f, 0, 0}, {0, 0, -0.3f}, m);     // floor, facing +y
  return s;
}

TEST(Split, CornerIndirectLightArrivesAfterTheDirectReturnAndDirectIsTheOneBounceRender) {
  RenderStageConfig c = test_config(16, 16, 2e-4);  // 20.6 degrees half field: the walls fill the view
  c.camera.position_m = {0.2, 0.2, 0};
  c.camera.look_at_m = {0.2, 0.2, -1};
  c.render.samples_per_pixel = 16;
  c.render.max_bounces = 4;
  c.render.split_direct_indirect = true;
  // 40 ns, no folding: every path of up to 4 bounces (at most 5 segments of 1.2 m) fits.
  const TimeAxis axis{0.0, 4e-12, 10000, 0.0};
  const PixelRect all{0, 0, 16, 16};
  Renderer r(open_corner(), c);
  const TransientTile t = r.transient(all, all, axis);
  RenderStageConfig c1 = c;
  c1.render.max_bounces = 1;
  Renderer r1(open_corner(), c1);
  const TransientTile one = r1.transient(all, all, axis);
  int lit = 0;
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 16; ++x) {
      const auto i = static_cast<size_t>(all.index(x, y));
      const float* g = t.pixel_transient(x, y);
      const float* ind = t.transient_indirect.data() + i * size_t(axis.bins);
      int64_t first_direct = -1, first_indirect = -1;
      double direct = 0, indirect = 0;
      for (int64_t b = 0; b < axis.bins; ++b) {
        // A bin with indirect light only holds the same double sum twice: direct is exactly 0 there.
        ASSERT_LE(ind[b], g[b]);
        if (g[b] != ind[b] && first_direct < 0) first_direct = b;
        if (ind[b] > 0 && first_indirect < 0) first_indirect = b;
        direct += double(g[b]) - double(ind[b]);
        indirect += ind[b];
      }
      if (t.laser_total[i] == 0.0) continue;
      ++lit;
      // Camera -> x1 -> x2 -> ... -> laser at the camera is at least twice the range of x1 (triangle
      // inequality), and some sample's x1 is the pixel's earliest direct return.
      ASSERT_GE(first_direct, 0);
      if (first_indirect >= 0) {
        EXPECT_GE(first_indirect, first_direct) << x << "," << y;
      }
      // Direct part = the max_bounces 1 render (same random draws: the first NEE uses only the jitter), up
      // to float storage of the two transients.
      EXPECT_NEAR(direct, one.laser_total[i], 1e-6 * t.laser_total[i]) << x << "," << y;
      EXPECT_NEAR(direct + indirect, t.laser_total[i], 1e-6 * t.laser_total[i]);
      EXPECT_EQ(t.out_of_window[i], 0.0);
    }
  EXPECT_EQ(lit, 256);
  // Interreflections are really there: near the corner (bottom left of the image) a 0.7-albedo corner
  // adds several per cent; in total across the image more than 1 %.
  double ind_total = 0, total = 0;
  for (float v : t.transient_indirect) ind_total += v;
  for (double v : t.laser_total) total += v;
  EXPECT_GT(ind_total, 0.01 * total);
  EXPECT_LT(ind_total, total);
}

// Camera rays travel in packets of 16 pixels fixed by the sensor: a 37-pixel row has blocks of 16, 16 and
// 5, and tiles of 8 or 13 cut them anywhere; every pixel must come out bit-identical to the whole image.
TEST(Split, PacketBlocksDoNotDependOnTheTiling) {
  RenderStageConfig c = test_config(37, 9, 4e-4);
  c.camera.position_m = {0.2, 0.2, 0};
  c.camera.look_at_m = {0.2, 0.2, -1};
  c.render.samples_per_pixel = 3;
  c.render.split_direct_indirect = true;
  Renderer r(open_corner(), c);
  const TimeAxis axis{0.0, 20e-12, 2000, 25e-9};
  const PixelRect all{0, 0, 37, 9};
  const TransientTile whole = r.transient(all, all, axis);
  for (int tile : {8, 13}) {
    for (int y0 = 0; y0 < 9; y0 += tile)
      for (int x0 = 0; x0 < 37; x0 += tile) {
        const PixelRect rect{x0, y0, std::min(tile, 37 - x0), std::min(tile, 9 - y0)};
        const PixelRect data = grow_clipped(rect, 1, 37, 9);
        const TransientTile t = r.transient(rect, data, axis);
        for (int y = data.y0; y < data.y1(); ++y)
          for (int x = data.x0; x < data.x1(); ++x) {
            const size_t i = size_t(data.index(x, y)), j = size_t(all.index(x, y));
            ASSERT_EQ(t.laser_total[i], whole.laser_total[j]) << x << "," << y;
            for (int64_t b = 0; b < axis.bins; ++b) {
              ASSERT_EQ(t.transient[i * size_t(axis.bins) + size_t(b)], whole.transient[j * size_t(axis.bins) + size_t(b)]);
              ASSERT_EQ(t.transient_indirect[i * size_t(axis.bins) + size_t(b)],
                        whole.transient_indirect[j * size_t(axis.bins) + size_t(b)]);
            }
          }
      }
  }
  EXPECT_GT(std::accumulate(whole.laser_total.begin(), whole.laser_total.end(), 0.0), 0.0);
}

// ---------------------------------------------------------------------------------------------------
// Extremes of scale.

TEST(Extremes, PlaneAtOneKilometreFoldsToTimeModuloThePeriod) {
  const double d = 1000.0;
  RenderStageConfig c = test_config(8, 8, 0.1);  // 94 urad pixels: ranges in a pixel differ by < 2e-5 m
  c.render.samples_per_pixel = 16;
  c.laser.emission_delay_s = 3e-9;
  Renderer r(plane_at(d, 0.5f, 10.0f), c);
  const TimeAxis folded{0.0, 1e-12, 25000, 25e-9};  // one whole 40 MHz period in 1 ps bins
  const TransientTile t = r.transient({3, 3, 2, 2}, {3, 3, 2, 2}, folded);
  TimeAxis unfolded = folded;
  unfolded.period_s = 0.0;
  const TransientTile u = r.transient({3, 3, 2, 2}, {3, 3, 2, 2}, unfolded);
  // Float positions at 1 km: one ulp of 1000 m is 6.1e-5 m; the hit point from barycentrics carries a few
  // ulps, so the round trip is known to 2 * 8 ulps / c = 3.3 ps. Binning moves the mean by < 0.5 ps.
  const double position_ps = 2 * 8 * 6.1e-5 / kC;
  for (int y = 3; y < 5; ++y)
    for (int x = 3; x < 5; ++x) {
      const auto i = static_cast<size_t>(t.data_rect.index(x, y));
      const double range = pixel_mean(c, x, y, [&](const glm::dvec3& v) { return d / -v.z; });
      const double t_abs = c.laser.emission_delay_s + 2 * range / kC;  // 6.674 us: 266 periods late
      const double expected = std::fmod(t_abs, folded.period_s);
      EXPECT_GT(t_abs, 200 * folded.period_s);
      EXPECT_NEAR(mean_time(t.pixel_transient(x, y), folded), expected, 0.5e-12 + position_ps) << x << "," << y;
      // Photons: the camera equation at 1 km (cos^7 is 1 to 1e-8 here), to float rounding.
      EXPECT_NEAR(t.laser_total[i], on_axis_photons(c, 0.5, d), 1e-5 * on_axis_photons(c, 0.5, d));
      const float* g = t.pixel_transient(x, y);
      EXPECT_NEAR(std::accumulate(g, g + folded.bins, 0.0), t.laser_total[i], 1e-6 * t.laser_total[i]);
      EXPECT_EQ(t.out_of_window[i], 0.0);
      // Without folding the same window sees nothing and reports all of it.
      EXPECT_EQ(u.out_of_window[i], u.laser_total[i]);
      EXPECT_EQ(u.laser_total[i], t.laser_total[i]);
    }
}

TEST(Extremes, PlaneAtFiveMillimetres) {
  const double d = 0.005;
  RenderStageConfig c = test_config(8, 8, 12e-3);  // the 8 x 8 pixels see 25 um of the plane
  c.render.samples_per_pixel = 16;
  c.laser.emission_delay_s = 1e-9;
  Renderer r(plane_at(d, 0.6f, 0.01f), c);
  const TimeAxis axis{1e-9, 0.25e-12, 400, 25e-9};  // 1.0 to 1.1 ns in 0.25 ps bins
  const TransientTile t = r.transient({0, 0, 8, 8}, {0, 0, 8, 8}, axis);
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 8; ++x) {
      const auto i = static_cast<size_t>(t.data_rect.index(x, y));
      // The falloff cos^7 over this 0.2 degree view is 1 - 2e-5 at most: the on-axis closed form to 1e-4.
      EXPECT_NEAR(t.laser_total[i], on_axis_photons(c, 0.6, d), 1e-4 * on_axis_photons(c, 0.6, d)) << x << "," << y;
      const double range = pixel_mean(c, x, y, [&](const glm::dvec3& v) { return d / -v.z; });
      // 33.36 ps round trip; float positions at 5 mm are exact to 1e-9 m (0.007 ps).
      EXPECT_NEAR(mean_time(t.pixel_transient(x, y), axis), c.laser.emission_delay_s + 2 * range / kC, 0.13e-12);
      EXPECT_EQ(t.out_of_window[i], 0.0);
    }
}

TEST(Extremes, ABillionthOfAPhotonPerPulseIsBinnedWithoutLoss) {
  RenderStageConfig c = test_config(8, 8, 12e-3);
  c.render.samples_per_pixel = 4;
  const double scale = 1e-9 / on_axis_photons(c, 0.5, 1.0);
  c.laser.average_power_W *= scale;  // 1e-9 photons per pulse on the axis
  Renderer r(plane_at(1.0, 0.5f, 5.0f), c);
  const TimeAxis axis{6e-9, 1e-12, 1000, 25e-9};
  const TransientTile t = r.transient({0, 0, 8, 8}, {0, 0, 8, 8}, axis);
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 8; ++x) {
      const auto i = static_cast<size_t>(t.data_rect.index(x, y));
      EXPECT_NEAR(t.laser_total[i], 1e-9, 1e-4 * 1e-9);  // cos^7 over 0.3 degrees: 1 - 6e-5
      const float* g = t.pixel_transient(x, y);
      // The whole return lies in one or two 1 ps bins (ranges in a pixel differ by < 0.1 mm), each a
      // normal float: the bins hold it to float rounding.
      EXPECT_NEAR(std::accumulate(g, g + axis.bins, 0.0), t.laser_total[i], 1e-6 * t.laser_total[i]);
      EXPECT_GT(*std::max_element(g, g + axis.bins), 0.4e-9f);
      EXPECT_EQ(t.out_of_window[i], 0.0);
    }
}

}  // namespace
}  // namespace spadgen::render
