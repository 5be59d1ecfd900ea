// The guided connections' targets: their draws have the densities their pdf() gives.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "core/rng.h"
#include "render/guide.h"

namespace spadgen::render {
namespace {

// A strip 1 m long and 2 mm wide, 0.5 m from the vertex and seen at a slant.
GlossyStrip strip() {
  GlossyStrip s;
  s.o = {-0.3, -0.5, -0.5};
  s.a = {0.0, 1.0, 0.0};
  s.b = {0.0, 0.0, -0.002};
  s.n = {1.0, 0.0, 0.0};
  s.area = 0.002;
  s.alpha = 0.0025f;
  return s;
}

// The density integrates to 1 over the strip (uniform points on it, pdf |cos| / r^2 times the area:
// 5 sigma), every draw lands on the strip with a positive density, and the draws' share below s = 0.3 is
// the truncated Cauchy law's about the centre 0.25 + 0.1 t, averaged over t uniform: the mean over t of
// (atan((0.3 - m) / c) + atan(m / c)) / (atan((1 - m) / c) + atan(m / c)), computed here (5 sigma).
TEST(Guide, StripDrawsHaveTheirDensity) {
  const GlossyStrip s = strip();
  GuideTargets g;
  g.origin = {0.0, 0.0, 0.0};
  g.n = 1;
  g.t[0].strip = true;
  g.t[0].part = &s;
  g.t[0].s0 = 0.25;
  g.t[0].s1 = 0.1;
  g.t[0].c = 0.05;
  Rng rng(21, RngKind::Test, 1);
  const int n = 200000;
  double integral = 0, sq = 0;
  for (int i = 0; i < n; ++i) {
    const glm::dvec3 p = s.o + double(rng.next_float()) * s.a + double(rng.next_float()) * s.b;
    const glm::dvec3 d = p - g.origin;
    const double r = glm::length(d);
    const glm::vec3 w(d / r);
    const double v = g.pdf(0, w) * std::fabs(glm::dot(glm::dvec3(w), s.n)) / (r * r) * s.area;
    integral += v / n, sq += v * v / n;
  }
  EXPECT_NEAR(integral, 1.0, 5 * std::sqrt((sq - integral * integral) / n) + 1e-6);
  int below = 0, lost = 0;
  for (int i = 0; i < n; ++i) {
    glm::vec3 w;
    ASSERT_TRUE(g.sample(0, rng.next_float(), rng.next_float(), &w));
    lost += !(g.pdf(0, w) > 0.0);
    // Where the draw meets the strip's plane, and its s there.
    const glm::dvec3 wd(w);
    const glm::dvec3 p = g.origin + (glm::dot(s.o - g.origin, s.n) / glm::dot(wd, s.n)) * wd;
    below += strip_coordinates(p, s.o, s.a, s.b).x < 0.3;
  }
  // A draw at the strip's edge whose float direction falls just off it has density 0 (its light is lost,
  // a bias of that share of the strip's guided light): measured 1 in 200,000.
  EXPECT_LE(lost, n / 10000) << lost;
  double expected = 0.0;
  const int steps = 10000;
  for (int k = 0; k < steps; ++k) {
    const double m = 0.25 + 0.1 * (k + 0.5) / steps, c = 0.05;
    expected += (std::atan((0.3 - m) / c) + std::atan(m / c)) / (std::atan((1 - m) / c) + std::atan(m / c)) / steps;
  }
  EXPECT_NEAR(double(below) / n, expected, 5 * std::sqrt(expected * (1 - expected) / n));
  EXPECT_DOUBLE_EQ(g.sum_pdf2(glm::vec3(0, 0, 1)), 0.0);  // a direction away from the strip
}

// The guided draw towards a glossy reflection of the laser has the density glossy_target_pdf gives: its
// integral over the sphere is the share of draws kept, and the mean of 1 / pdf over the kept draws is
// the solid angle they cover, which the integral of the indicator confirms.
TEST(Guide, GlossyTargetDensityIsItsDrawsDensity) {
  const GlossyTarget g{glm::vec3(0, 0, 1), glm::normalize(glm::vec3(0.4f, 0.1f, 1.0f)), 0.3f};
  Rng rng(14, RngKind::Test, 1);
  const int n = 400000;
  int kept = 0;
  for (int i = 0; i < n; ++i) {
    glm::vec3 w;
    if (!sample_glossy_target(g, rng.next_float(), rng.next_float(), &w)) continue;
    ++kept;
    ASSERT_NEAR(glm::length(w), 1.0f, 1e-5f);
    ASSERT_GT(glossy_target_pdf(g, w), 0.0f);
  }
  double integral = 0, sq = 0;
  const int m = 2000000;
  for (int i = 0; i < m; ++i) {
    const float z = 1.0f - 2.0f * rng.next_float(), phi = 6.2831853f * rng.next_float();
    const float r = std::sqrt(std::max(0.0f, 1.0f - z * z));
    const double v = glossy_target_pdf(g, {r * std::cos(phi), r * std::sin(phi), z}) * 4.0 * 3.14159265358979;
    integral += v / m, sq += v * v / m;
  }
  const double share = double(kept) / n;
  ASSERT_GT(share, 0.5);
  const double sigma = std::sqrt((sq - integral * integral) / m + share * (1 - share) / n);
  EXPECT_NEAR(integral, share, 5 * sigma);
}

// A ghost's lobe of directions: its draws have the density direction_lobe_pdf gives. The share of draws
// inside a cone of half-angle t about the axis is the integral of the density over that cone, computed
// here in closed form: the GGX draw of a microfacet normal puts tan^2(theta) = alpha^2 u / (1 - u), so
// the share is tan^2(t) / (alpha^2 + tan^2(t)) (5 sigma); every draw has a positive density, and the
// density integrates to 1 over the sphere (uniform directions, 5 sigma).
TEST(Guide, DirectionLobeDensityIsItsDrawsDensity) {
  const DirectionLobe g{glm::normalize(glm::vec3(0.3f, -0.2f, 1.0f)), 0.06f};
  Rng rng(22, RngKind::Test, 1);
  const int n = 400000;
  const double t = 0.05, tan2 = std::tan(t) * std::tan(t);
  int inside = 0;
  for (int i = 0; i < n; ++i) {
    glm::vec3 w;
    ASSERT_TRUE(sample_direction_lobe(g, rng.next_float(), rng.next_float(), &w));
    ASSERT_NEAR(glm::length(w), 1.0f, 1e-5f);
    ASSERT_GT(direction_lobe_pdf(g, w), 0.0f);
    inside += std::acos(std::min(1.0f, glm::dot(w, g.axis))) < t;
  }
  const double share = tan2 / (double(g.alpha) * g.alpha + tan2), got = double(inside) / n;
  EXPECT_NEAR(got, share, 5.0 * std::sqrt(share * (1.0 - share) / n));
  // The density over the sphere, sampled where it lives: half the points uniform over the sphere, half
  // uniform in the cone of 0.5 rad about the axis (a mixture density), each weighted by pdf / mixture.
  const double cone = 0.5, cone_sr = 2.0 * 3.14159265358979 * (1.0 - std::cos(cone));
  glm::vec3 tx, bx;
  make_basis(g.axis, &tx, &bx);
  double integral = 0, sq = 0;
  const int m = 1000000;
  for (int i = 0; i < m; ++i) {
    glm::vec3 w;
    if (i % 2 == 0) {
      const float z = 1.0f - 2.0f * rng.next_float(), phi = 6.2831853f * rng.next_float();
      const float r = std::sqrt(std::max(0.0f, 1.0f - z * z));
      w = {r * std::cos(phi), r * std::sin(phi), z};
    } else {
      const double cz = 1.0 - rng.next_double() * (1.0 - std::cos(cone)), phi = 6.283185307 * rng.next_double();
      const double r = std::sqrt(std::max(0.0, 1.0 - cz * cz));
      w = glm::normalize(float(r * std::cos(phi)) * tx + float(r * std::sin(phi)) * bx + float(cz) * g.axis);
    }
    const bool in_cone = glm::dot(w, g.axis) > std::cos(cone);
    const double mix = 0.5 / (4.0 * 3.14159265358979) + (in_cone ? 0.5 / cone_sr : 0.0);
    const double v = direction_lobe_pdf(g, w) / mix;
    integral += v / m, sq += v * v / m;
  }
  EXPECT_NEAR(integral, 1.0, 5.0 * std::sqrt((sq - integral * integral) / m));
}

}  // namespace
}  // namespace spadgen::render
