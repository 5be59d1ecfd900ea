// The refracted path through planar faces (render/planar_path.h) against closed forms and an independent
// forward trace.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "render/planar_path.h"

namespace spadgen::render {
namespace {

// The direction w refracted through a plane of normal n from index n1 into index n2 (vector form of Snell's
// law); false at total internal reflection.
bool refract(glm::dvec3 w, glm::dvec3 n, double n1, double n2, glm::dvec3* out) {
  if (glm::dot(n, w) > 0.0) n = -n;
  const double eta = n1 / n2, ci = -glm::dot(n, w), s2 = eta * eta * (1.0 - ci * ci);
  if (s2 >= 1.0) return false;
  *out = glm::normalize(eta * w + (eta * ci - std::sqrt(1.0 - s2)) * n);
  return true;
}

// The unit normal Snell's law takes at point y of face f: its plane's, or a shaded face's interpolated one.
glm::dvec3 normal_at(const PlanarFace& f, const glm::dvec3& y) {
  return f.shaded ? glm::normalize(f.m + f.grad * (y - f.p)) : f.n;
}

// From l along w (towards x), through the faces in reverse order (reflecting off those of `reflect`), to the
// plane through x across `across`: where the light lands there.
glm::dvec3 forward(const glm::dvec3& l, glm::dvec3 w, const std::vector<PlanarFace>& faces, const std::vector<double>& index,
                   const glm::dvec3& x, const glm::dvec3& across, const std::vector<bool>& reflect = {}) {
  glm::dvec3 o = l;
  for (int j = int(faces.size()) - 1; j >= 0; --j) {
    const PlanarFace& f = faces[size_t(j)];
    const double t = glm::dot(f.p - o, f.n) / glm::dot(w, f.n);
    o += t * w;
    const glm::dvec3 n = normal_at(f, o);
    if (!reflect.empty() && reflect[size_t(j)]) {
      w = w - 2.0 * glm::dot(w, n) * n;
      continue;
    }
    glm::dvec3 next(0.0);
    EXPECT_TRUE(refract(w, n, index[size_t(j) + 1], index[size_t(j)], &next));
    w = next;
  }
  return o + glm::dot(x - o, across) / glm::dot(w, across) * w;
}

// The solved path against the forward trace: the light leaving l along -d[k] lands on x (to 1e-10 m), and the
// spread is the inverse of the landing area per solid angle at l (central differences of the landing point
// along two directions across -d[k]).
void check_against_forward_trace(const glm::dvec3& x, const glm::dvec3& l, const std::vector<PlanarFace>& faces,
                                 const std::vector<double>& index, const PlanarPath& path,
                                 const std::vector<bool>& reflect = {}) {
  const int k = int(faces.size());
  const glm::dvec3 w0 = -path.d[k], across = path.d[0];
  EXPECT_LT(glm::length(forward(l, w0, faces, index, x, across, reflect) - x), 1e-10);
  const glm::dvec3 a = glm::normalize(glm::cross(w0, std::fabs(w0.x) < 0.9 ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0)));
  const glm::dvec3 b = glm::cross(w0, a);
  const double h = 1e-6;
  const auto land = [&](double s, double t) {
    return forward(l, glm::normalize(w0 + s * a + t * b), faces, index, x, across, reflect);
  };
  const glm::dvec3 da = (land(h, 0) - land(-h, 0)) / (2 * h), db = (land(0, h) - land(0, -h)) / (2 * h);
  const double area_per_sr = glm::length(glm::cross(da, db));
  EXPECT_NEAR(path.spread * area_per_sr, 1.0, 1e-6);
}

// Two parallel plates (2 cm and 5 mm, ior 1.5 and 1.7) between x and l, off the normal: the closed form of
// parallel layers, rho(a) = sum_j d_j tan(theta_j(a)) the lateral travel for the angle a at l, so that the
// irradiance across the plane is I sin a / (rho rho'(a)) and across d[0] that over cos theta_0.
TEST(PlanarPath, ParallelLayersMatchTheirClosedForm) {
  const glm::dvec3 n(0, 0, 1), x(0, 0, 0), l(0.3, 0.4, 1.0);
  const std::vector<PlanarFace> faces = {{{0, 0, 0.2}, n}, {{0, 0, 0.22}, n}, {{0, 0, 0.5}, n}, {{0, 0, 0.505}, n}};
  const std::vector<double> index = {1.0, 1.5, 1.0, 1.7, 1.0};
  const std::vector<double> depth = {0.2, 0.02, 0.28, 0.005, 0.495};
  std::vector<glm::dvec3> start;
  for (const PlanarFace& f : faces) start.push_back(x + (f.p.z / l.z) * l);
  PlanarPath path;
  ASSERT_TRUE(solve_planar_path(x, l, faces.data(), index.data(), 4, start.data(), &path));
  const auto rho = [&](double a) {
    double s = 0;
    for (size_t j = 0; j < depth.size(); ++j) s += depth[j] * std::tan(std::asin(std::sin(a) / index[j]));
    return s;
  };
  const double D = 0.5, a = std::acos(path.d[4].z);
  EXPECT_NEAR(rho(a), D, 1e-11);  // the path's angle at l is the closed form's
  const double h = 1e-6, drho = (rho(a + h) - rho(a - h)) / (2 * h);
  const double cos0 = path.d[0].z;
  EXPECT_NEAR(path.spread / (std::sin(a) / (rho(a) * drho * cos0)), 1.0, 1e-7);
  for (int j = 0; j < 4; ++j) EXPECT_NEAR(path.y[j].z, faces[size_t(j)].p.z, 1e-12);
  check_against_forward_trace(x, l, faces, index, path);
}

// Without refraction (every index 1) the path is the straight line and the spread 1 / r^2.
TEST(PlanarPath, FacesOfIndexOneLeaveTheStraightLine) {
  const glm::dvec3 x(0.1, -0.2, 0.0), l(0.5, 0.3, 1.2);
  const std::vector<PlanarFace> faces = {{{0, 0, 0.3}, glm::normalize(glm::dvec3(0.2, 0, 1))},
                                         {{0, 0, 0.6}, glm::normalize(glm::dvec3(0, -0.3, 1))}};
  const std::vector<double> index = {1.0, 1.0, 1.0};
  const glm::dvec3 start[2] = {{0, 0, 0.3}, {0, 0, 0.6}};
  PlanarPath path;
  ASSERT_TRUE(solve_planar_path(x, l, faces.data(), index.data(), 2, start, &path));
  const double r = glm::length(l - x);
  for (int s = 0; s < 3; ++s) EXPECT_LT(glm::length(path.d[s] - (l - x) / r), 1e-12);
  EXPECT_NEAR(path.spread * r * r, 1.0, 1e-10);
}

// Plates that are not parallel: a wedge (faces 3 degrees apart) inside which x lies, and a plate tilted 20
// degrees about another axis, both of ior 1.5, and two plates 0.1 degrees apart; the path and its spread
// against the forward trace.
TEST(PlanarPath, FacesAtAnyAngleMatchAForwardTrace) {
  const auto tilted = [](double deg_x, double deg_y) {
    const double a = deg_x * 3.14159265358979323846 / 180, b = deg_y * 3.14159265358979323846 / 180;
    return glm::normalize(glm::dvec3(std::sin(b), std::sin(a), std::cos(a) * std::cos(b)));
  };
  {
    const glm::dvec3 x(0.02, 0.01, 0.0), l(0.4, -0.2, 1.0);
    const std::vector<PlanarFace> faces = {{{0, 0, 0.03}, tilted(3, 0)}, {{0, 0, 0.5}, tilted(0, 20)}, {{0, 0, 0.54}, tilted(0, 20)}};
    const std::vector<double> index = {1.5, 1.0, 1.5, 1.0};
    std::vector<glm::dvec3> start;
    for (const PlanarFace& f : faces) start.push_back(f.p);
    PlanarPath path;
    ASSERT_TRUE(solve_planar_path(x, l, faces.data(), index.data(), 3, start.data(), &path));
    check_against_forward_trace(x, l, faces, index, path);
  }
  {
    const glm::dvec3 x(0.0, 0.0, 0.0), l(0.3, 0.0, 1.0);
    const std::vector<PlanarFace> faces = {{{0, 0, 0.5}, tilted(0, 0)}, {{0, 0, 0.52}, tilted(0, 0)},
                                           {{0, 0, 0.6}, tilted(0, 0.1)}, {{0, 0, 0.62}, tilted(0, 0.1)}};
    const std::vector<double> index = {1.0, 1.5, 1.0, 1.5, 1.0};
    std::vector<glm::dvec3> start;
    for (const PlanarFace& f : faces) start.push_back(f.p);
    PlanarPath path;
    ASSERT_TRUE(solve_planar_path(x, l, faces.data(), index.data(), 4, start.data(), &path));
    check_against_forward_trace(x, l, faces, index, path);
  }
}

// A shaded face: a plane whose normal is that of a sphere about c (m = p - c, grad the identity), as a smooth
// mesh's triangle interpolates its corner normals. A lens of two such faces (ior 1.5, centres on either side,
// off the axis), and a curved mirror (one face reflecting, with a flat plate after it), against the forward
// trace at the shading normals. The plane's normal alone (flat faces) lands elsewhere: 0.9 mm for the lens.
TEST(PlanarPath, ShadedFacesMatchAForwardTrace) {
  const auto shaded = [](glm::dvec3 p, glm::dvec3 n, glm::dvec3 centre) {
    PlanarFace f{p, glm::normalize(n)};
    f.shaded = true;
    f.m = p - centre;
    f.grad = glm::dmat3(1.0);
    return f;
  };
  {
    const glm::dvec3 x(0.0, 0.0, 0.0), l(0.05, 0.02, 1.0);
    const std::vector<PlanarFace> faces = {shaded({0, 0, 0.4}, {0, 0, 1}, {0.01, 0, 0.9}),
                                           shaded({0, 0, 0.45}, {0.05, 0, 1}, {0, 0.02, -0.1})};
    const std::vector<double> index = {1.0, 1.5, 1.0};
    std::vector<glm::dvec3> start;
    for (const PlanarFace& f : faces) start.push_back(f.p);
    PlanarPath path;
    ASSERT_TRUE(solve_planar_path(x, l, faces.data(), index.data(), 2, start.data(), &path));
    check_against_forward_trace(x, l, faces, index, path);
    std::vector<PlanarFace> flat = faces;
    for (PlanarFace& f : flat) f.shaded = false;
    PlanarPath straight;
    ASSERT_TRUE(solve_planar_path(x, l, flat.data(), index.data(), 2, start.data(), &straight));
    EXPECT_GT(glm::length(straight.y[0] - path.y[0]), 5e-4);
  }
  {
    const glm::dvec3 x(0.0, 0.0, 0.0), l(0.3, 0.05, 0.1);
    const std::vector<PlanarFace> faces = {shaded({0, 0, 0.5}, {0, 0, 1}, {0.15, 0, 1.5}), {{0.2, 0, 0.3}, {0, 0, 1}},
                                           {{0.2, 0, 0.25}, {0, 0, 1}}};
    const std::vector<double> index = {1.0, 1.0, 1.7, 1.0};
    const std::vector<bool> reflect = {true, false, false};
    const bool off[3] = {true, false, false};
    const glm::dvec3 start[3] = {{0.15, 0, 0.5}, {0.25, 0, 0.3}, {0.27, 0, 0.25}};
    PlanarPath path;
    ASSERT_TRUE(solve_planar_path(x, l, faces.data(), index.data(), 3, start, &path, off));
    check_against_forward_trace(x, l, faces, index, path, reflect);
  }
}

// No refracted path: l on x's side of the only face (the path would reflect off it), or an empty segment.
TEST(PlanarPath, NoPathWhereTheFacesAreNotCrossed) {
  const std::vector<PlanarFace> faces = {{{0, 0, 0.5}, {0, 0, 1}}};
  const std::vector<double> index = {1.0, 1.5};
  const glm::dvec3 start[1] = {{0, 0, 0.5}};
  PlanarPath path;
  EXPECT_FALSE(solve_planar_path({0, 0, 0}, {0.2, 0, 0.3}, faces.data(), index.data(), 1, start, &path));
  EXPECT_FALSE(solve_planar_path({0, 0, 0.5}, {0.2, 0, 1.0}, faces.data(), index.data(), 1, start, &path));
}

}  // namespace
}  // namespace spadgen::render
