// The targets of the integrator's guided connections (docs/render.md, "Guided connections"): the
// narrow glossy reflections of the laser and the slivers of glossy plates a path vertex aims extra
// direction draws at, each with the exact density of its draws, for MIS against the vertex's BSDF.
#pragma once
#include <glm/glm.hpp>

#include "bsdf.h"

namespace spadgen::render {

// A glossy reflection of the laser at a surface ahead of a path vertex (Integrator's guided connection):
// the surface's normal n (unit, on the vertex's side), the laser's direction wl seen from it (unit, on
// n's side) and a GGX alpha. sample_glossy_target draws a direction w from the vertex towards the surface
// whose half-vector at the surface, normalize(-w + wl), follows GGX(alpha) (density D(m) m.n); false
// when the draw reflects below the surface. glossy_target_pdf is that draw's density of w, per steradian.
struct GlossyTarget {
  glm::vec3 n{0.0f}, wl{0.0f};
  float alpha = 0.0f;
};
bool sample_glossy_target(const GlossyTarget& g, float u, float v, glm::vec3* w);
float glossy_target_pdf(const GlossyTarget& g, const glm::vec3& w);

// A GGX lobe of directions around a unit axis: sample_direction_lobe draws w with density
// D_alpha(w . axis) (w . axis) per steradian (direction_lobe_pdf), a microfacet normal drawn about the axis;
// false when the draw falls behind the axis's plane (never for alpha < 1).
struct DirectionLobe {
  glm::vec3 axis{0.0f, 0.0f, 1.0f};
  float alpha = 0.0f;
};
bool sample_direction_lobe(const DirectionLobe& g, float u, float v, glm::vec3* w);
float direction_lobe_pdf(const DirectionLobe& g, const glm::vec3& w);

// A glossy plate's two parallel faces, for the ghost of the laser that a non-delta vertex behind the
// plate sees through it (Integrator::ghost_targets): planes n . x = lo and n . x = hi (hi - lo the
// thickness, n unit), of the plate's volume material.
struct GlossySlab {
  glm::dvec3 n;
  double lo, hi;
  double ior;
  float alpha;
  int material;
};

// A part of a glossy plate (one triangle): Lambertian vertices aim at its reflection of the laser, unless it
// is half of a sliver (a GlossyStrip, aimed at along its length instead).
struct GlossyPart {
  glm::dvec3 p0, e1, e2, n;  // corner, edges, unit normal
  float alpha;
  bool sliver = false;
  int plane = 0;  // the same for the parts of one plane (a face of several triangles)
};
// A sliver of a glossy plate (its thin edge: a parallelogram o + s a + t b, s, t in [0, 1], |b| < |a| / 20),
// which Lambertian vertices also aim at over its length.
struct GlossyStrip {
  glm::dvec3 o, a, b, n;     // corner, long side, short side, unit normal
  double area;               // |a x b|
  float alpha;
  int slab = -1;             // the plate (GlossySlab) whose edge it is, across its thickness, lit by the laser; -1: none
  // An edge's plane (out of the plate) and the distance into the plate over which the laser's light
  // entering through it climbs one thickness, at least (Integrator::edge_entry).
  glm::dvec3 out{0.0};
  double offset = 0.0, per_reflection = 0.0;
  // Its two triangles (GlossyPart indices, and their triangles in mesh `mesh`), for the base colour's texture
  // and COLOR_0 where the laser's light enters through it.
  int mesh = -1;
  size_t part[2] = {0, 0};
  uint32_t triangle[2] = {0, 0};
};
// The affine coordinates (s, t) of point p (projected on the plane) in o + s a + t b.
glm::dvec2 strip_coordinates(const glm::dvec3& p, const glm::dvec3& o, const glm::dvec3& a, const glm::dvec3& b);
// The distance from p, projected on the plane of the triangle p0, p0 + e1, p0 + e2, to the triangle: 0 inside.
double distance_to_triangle(const glm::dvec3& p, const glm::dvec3& p0, const glm::dvec3& e1, const glm::dvec3& e2);

// A plate's reflection of the laser is aimed at while its mirror point (or, for a ghost, its entry point)
// lies within this many of the lobe's widths (alpha over the mirror point's turn per metre) of the part:
// a rough face's lobe reaches across its edge, and the BSDF's draws alone, which find that light, would
// weight it in full (at 8 widths GGX's density is below 1 / 4000 of its peak).
constexpr double kGuideEdgeWidths = 8.0;

// What a vertex's guided connections aim at: a glossy reflection of the laser (draws from
// sample_glossy_target), or a strip (t uniform; s from a Cauchy law of scale c around s0 + s1 t, truncated
// to [0, 1], in units of the long side).
struct GuideTarget {
  bool strip = false;
  GlossyTarget lobe;
  const GlossyStrip* part = nullptr;
  double s0 = 0.0, s1 = 0.0, c = 1.0;
};

constexpr int kMaxGuideTargets = 4;
struct GuideTargets {
  GuideTarget t[kMaxGuideTargets];
  glm::dvec3 origin{0.0};  // the vertex
  int n = 0;
  bool sample(int i, float u, float v, glm::vec3* w) const;
  double pdf(int i, const glm::vec3& w) const;  // per steradian
  double sum_pdf2(const glm::vec3& w) const;    // sum over the targets of pdf^2
};

}  // namespace spadgen::render
