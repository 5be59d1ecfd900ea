#include "guide.h"

#include <algorithm>
#include <cmath>

namespace spadgen::render {

namespace {

double sqr(double x) { return x * x; }

}  // namespace

bool sample_glossy_target(const GlossyTarget& g, float u, float v, glm::vec3* w) {
  glm::vec3 t, b;
  make_basis(g.n, &t, &b);
  const glm::vec3 ml = sample_ggx(g.alpha, u, v);
  const glm::vec3 m = ml.x * t + ml.y * b + ml.z * g.n;
  const glm::vec3 out = 2.0f * glm::dot(g.wl, m) * m - g.wl;  // the reflection towards the vertex
  if (!(glm::dot(out, g.n) > 0.0f) || !(glm::dot(g.wl, m) > 0.0f)) return false;
  *w = -glm::normalize(out);
  return true;
}

float glossy_target_pdf(const GlossyTarget& g, const glm::vec3& w) {
  const glm::vec3 out = -w;
  if (!(glm::dot(out, g.n) > 0.0f)) return 0.0f;
  const glm::vec3 m = glm::normalize(out + g.wl);
  const float c = glm::dot(out, m), cm = glm::dot(m, g.n);
  if (!(c > 0.0f) || !(cm > 0.0f)) return 0.0f;
  return ggx_d(g.alpha, cm, glm::dot(glm::cross(m, g.n), glm::cross(m, g.n))) * cm / (4.0f * c);
}

bool sample_direction_lobe(const DirectionLobe& g, float u, float v, glm::vec3* w) {
  glm::vec3 t, b;
  make_basis(g.axis, &t, &b);
  const glm::vec3 m = sample_ggx(g.alpha, u, v);
  const glm::vec3 out = m.x * t + m.y * b + m.z * g.axis;
  if (!(glm::dot(out, g.axis) > 0.0f)) return false;
  *w = glm::normalize(out);
  return true;
}

float direction_lobe_pdf(const DirectionLobe& g, const glm::vec3& w) {
  const float c = glm::dot(w, g.axis);
  if (!(c > 0.0f)) return 0.0f;
  const glm::vec3 s = glm::cross(w, g.axis);
  return ggx_d(g.alpha, c, glm::dot(s, s)) * c;
}

glm::dvec2 strip_coordinates(const glm::dvec3& p, const glm::dvec3& o, const glm::dvec3& a, const glm::dvec3& b) {
  const glm::dvec3 d = p - o;
  const double aa = glm::dot(a, a), ab = glm::dot(a, b), bb = glm::dot(b, b);
  const double da = glm::dot(d, a), db = glm::dot(d, b), det = aa * bb - ab * ab;
  return {(da * bb - db * ab) / det, (db * aa - da * ab) / det};
}

double distance_to_triangle(const glm::dvec3& p, const glm::dvec3& p0, const glm::dvec3& e1, const glm::dvec3& e2) {
  const glm::dvec2 st = strip_coordinates(p, p0, e1, e2);
  if (st.x >= 0.0 && st.y >= 0.0 && st.x + st.y <= 1.0) return 0.0;
  const glm::dvec3 q = p0 + st.x * e1 + st.y * e2;  // p projected on the plane
  const auto to_segment = [&](const glm::dvec3& a, const glm::dvec3& e) {
    const double t = std::clamp(glm::dot(q - a, e) / glm::dot(e, e), 0.0, 1.0);
    return glm::length(q - (a + t * e));
  };
  return std::min({to_segment(p0, e1), to_segment(p0, e2), to_segment(p0 + e1, e2 - e1)});
}

bool GuideTargets::sample(int i, float u, float v, glm::vec3* w) const {
  const GuideTarget& g = t[i];
  if (!g.strip) return sample_glossy_target(g.lobe, u, v, w);
  const GlossyStrip& p = *g.part;
  const double tt = v, s0 = g.s0 + g.s1 * tt;
  const double a0 = std::atan(-s0 / g.c), a1 = std::atan((1.0 - s0) / g.c);
  const double s = std::clamp(s0 + g.c * std::tan(a0 + double(u) * (a1 - a0)), 0.0, 1.0);
  const glm::dvec3 d = p.o + s * p.a + tt * p.b - origin;
  const double len = glm::length(d);
  if (!(len > 0.0)) return false;
  *w = glm::vec3(d / len);
  return true;
}

double GuideTargets::pdf(int i, const glm::vec3& wf) const {
  const GuideTarget& g = t[i];
  if (!g.strip) return glossy_target_pdf(g.lobe, wf);
  // Where the ray from the vertex along w meets the strip: the density of (s, t) over the strip's area,
  // times r^2 / |cos|.
  const GlossyStrip& p = *g.part;
  const glm::dvec3 w(wf);
  const double wn = glm::dot(w, p.n);
  if (wn == 0.0) return 0.0;
  const double dist = glm::dot(p.o - origin, p.n) / wn;
  if (!(dist > 0.0)) return 0.0;
  const glm::dvec2 st = strip_coordinates(origin + dist * w, p.o, p.a, p.b);
  if (!(st.x >= 0.0 && st.x <= 1.0 && st.y >= 0.0 && st.y <= 1.0)) return 0.0;
  const double s0 = g.s0 + g.s1 * st.y;
  const double a0 = std::atan(-s0 / g.c), a1 = std::atan((1.0 - s0) / g.c);
  const double x = (st.x - s0) / g.c;
  const double ps = 1.0 / (g.c * (1.0 + x * x) * (a1 - a0));
  return ps / p.area * dist * dist / std::fabs(wn);
}

double GuideTargets::sum_pdf2(const glm::vec3& w) const {
  double s = 0.0;
  for (int i = 0; i < n; ++i) s += sqr(pdf(i, w));
  return s;
}

}  // namespace spadgen::render
