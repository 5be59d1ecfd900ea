// The search for the laser's paths through a glass sphere (render/sphere_search.h) against an independent trace
// of the sphere in the plane: every path a fine scan finds, found.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "render/sphere_search.h"

namespace spadgen::render {
namespace {

constexpr double kPi = 3.141592653589793;

// The laser at (-dl, 0) (the sphere's centre at the origin, radius R, index n), its ray in direction angle t
// from the axis, refracted in and out by Snell's law in vector form: where it leaves and its direction after;
// false where it misses the sphere or is totally reflected.
bool trace(double dl, double R, double n, double t, glm::dvec2* exit, glm::dvec2* dir) {
  const auto refract = [](glm::dvec2 w, glm::dvec2 nn, double eta, glm::dvec2* out) {
    if (glm::dot(w, nn) > 0.0) nn = -nn;
    const double ci = -glm::dot(w, nn), s2 = eta * eta * (1.0 - ci * ci);
    if (s2 >= 1.0) return false;
    *out = glm::normalize(eta * w + (eta * ci - std::sqrt(1.0 - s2)) * nn);
    return true;
  };
  const glm::dvec2 o(-dl, 0.0), w(std::cos(t), std::sin(t));
  const double b = glm::dot(o, w), disc = b * b - (glm::dot(o, o) - R * R);
  if (disc <= 0.0) return false;
  const glm::dvec2 e = o + (-b - std::sqrt(disc)) * w;
  glm::dvec2 w1;
  if (!refract(w, e / R, 1.0 / n, &w1)) return false;
  const glm::dvec2 q = e + (-2.0 * glm::dot(e, w1)) * w1;  // (the chord's other end)
  return refract(w1, q / R, n, dir) && (*exit = q, true);
}

// The rays through the point X, by a scan of 40,000 angles of incidence up to 0.6 degrees from grazing (as the
// search's): the sines of incidence h / R where X passes from one side of the exit ray to the other ahead of its
// exit (the angle from the ray to X passing through 0, not through pi).
std::vector<double> scan_roots(double dl, double R, double n, const glm::dvec2& X) {
  std::vector<double> roots;
  const double i_max = std::acos(0.0101);
  double prev = NAN, prev_s = NAN;
  for (int i = 0; i <= 40000; ++i) {
    const double s = std::sin(i_max * (-1.0 + 2.0 * i / 40000));
    glm::dvec2 q, d;
    double f = NAN;
    if (trace(dl, R, n, std::asin(s * R / dl), &q, &d)) f = std::atan2(d.x * (X - q).y - d.y * (X - q).x, glm::dot(d, X - q));
    if (std::isfinite(prev) && std::isfinite(f) && (prev < 0.0) != (f < 0.0) && std::abs(f - prev) < kPi)
      roots.push_back(0.5 * (prev_s + s));
    prev = f, prev_s = s;
  }
  return roots;
}

TEST(SphereSearch, SphereRayIsSnellsLaw) {
  const double dl = 0.5, R = 0.1, n = 1.5;
  for (const double s : {-0.9, -0.3, 0.0, 0.2, 0.7}) {
    const SphereRay r = sphere_ray(dl, R, n, s * R);
    glm::dvec2 q, d;
    ASSERT_TRUE(r.ok && trace(dl, R, n, std::asin(s * R / dl), &q, &d)) << s;
    EXPECT_NEAR(glm::length(r.exit - q), 0.0, 1e-12) << s;
    EXPECT_NEAR(glm::length(glm::normalize(r.dir) - d), 0.0, 1e-12) << s;
  }
}

// Walls behind an ior 1.5 sphere (radius 0.1 m, the laser 0.5 m from its centre) at 0.1 to 0.3 m from its centre
// (the first touching it, as a floor a ball rests on: near the contact a path's exit passes beside the point, and
// a miss defined only ahead of the exit lost the path there):
// around the focus (0.15 m) and beyond it, up to three paths reach a point, two of them merging at the caustic's
// fold (the ring where the light's landing turns back). On 200 points of each wall up to 32 mm off the axis, and on
// 60 within 40 um inside each fold's ring (where both merging paths lie within one of the search's 64 steps at
// 0.615 and 0.645 m), the search's seeds against the scan's paths: as many, each within 1 / 32 of a step (of 2.8
// degrees of incidence). Without the fold's search, 2 paths of 3 are missed on the rings.
TEST(SphereSearch, EveryPathAScanFindsIsSeeded) {
  const double dl = 0.5, R = 0.1, n = 1.5;
  const int steps = 64;
  const SphereSearch search(dl, R, n, steps);
  const double step = 2.0 * std::acos(0.0101) / steps;
  int points = 0, fold_points = 0;
  for (const double A : {0.1, 0.115, 0.13, 0.145, 0.16, 0.2, 0.3}) {
    // The fold's ring on this wall: the farthest landing of the rays on the side of positive h.
    double ring = 0.0;
    for (int i = 1; i < 20000; ++i) {
      glm::dvec2 q, d;
      if (trace(dl, R, n, std::asin(R / dl) * i / 20000, &q, &d) && d.x > 0.0) ring = std::max(ring, q.y + (A - q.x) / d.x * d.y);
    }
    std::vector<double> rhos;
    for (int i = 0; i < 200; ++i) rhos.push_back(0.032 * (i + 0.5) / 200);
    for (int i = 0; i < 60; ++i) rhos.push_back(ring - 40e-6 * (i + 0.5) / 60);
    for (const double rho : rhos) {
      const glm::dvec2 X(A, rho);
      const std::vector<double> roots = scan_roots(dl, R, n, X);
      SphereRay seeds[16];
      const int k = search.seeds(X, seeds, 16);
      ASSERT_EQ(size_t(k), roots.size()) << "wall " << A << ", " << rho * 1e3 << " mm off the axis (ring " << ring * 1e3 << " mm)";
      for (size_t j = 0; j < roots.size(); ++j) {
        const double incidence = std::asin(roots[j]), seeded = std::asin(seeds[j].h / R);
        EXPECT_LT(std::abs(seeded - incidence), step / 32) << "wall " << A << ", " << rho * 1e3 << " mm, path " << j;
      }
      ++points;
      if (rho < ring && roots.size() == 3 && std::abs(roots[2] - roots[1]) < std::sin(step)) ++fold_points;
    }
  }
  EXPECT_EQ(points, 7 * 260);
  EXPECT_GE(fold_points, 150);  // (the fold's points where both merging paths are within one step)
}

}  // namespace
}  // namespace spadgen::render
