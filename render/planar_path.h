// The path of light between two fixed points through refracting planar interfaces of any orientation (the
// faces of plates that are not parallel, a wedge), and through the shaded triangles of smooth meshes (a glass
// sphere): the Integrator's laser connection where the straight walk to the laser crossed faces that are not all
// parallel (docs/render.md, "Refracted laser connections"). A manifold next-event estimation (Hanika et al. 2015),
// exact for planes; a smooth mesh's triangle is its plane with its corner normals interpolated.
#pragma once
#include <glm/glm.hpp>

#include <cstdint>

namespace spadgen::render {

// A plane: a point of it and its unit normal (either side). A shaded face (a triangle of a mesh with vertex
// normals) obeys Snell's law about its shading normal, m + grad (y - p) normalised at the point y of the plane
// (the corner normals interpolated, and extended beyond the triangle's edges as they are within it), not n.
// mesh, triangle and dual identify the triangle for a FaceTracker (dual: the barycentrics of a point y of the
// plane are dual[i] . (y - p), p its first corner).
struct PlanarFace {
  glm::dvec3 p, n;
  bool shaded = false;
  glm::dvec3 m{0.0};
  glm::dmat3 grad{0.0};
  glm::dvec3 dual[2] = {glm::dvec3(0.0), glm::dvec3(0.0)};
  uint32_t mesh = 0, triangle = 0;
};

// Moves the points of a Newton step onto the surfaces whose triangles the shaded faces are (the manifold walk's
// projection): a point that left its triangle onto the triangle of the same mesh the path meets there.
class FaceTracker {
 public:
  virtual ~FaceTracker() = default;
  // y[j] on the plane of faces[j], j = 0..k-1, the path from x through them in turn: each shaded face whose point
  // lies outside its triangle replaced, and its point moved onto the new face's plane; false where the path
  // leaves the surfaces.
  virtual bool track(const glm::dvec3& x, glm::dvec3* y, PlanarFace* faces, int k) const = 0;
};

constexpr int kMaxPlanarFaces = 24;  // a laser-side echo's chain through 8 faces: 8 + 2 * 7

// The path from x to l refracting at faces 0..k-1 in turn: y[j] on face j, d[s] the unit direction of segment s
// (s = 0..k, from x towards l; segment s ends at y[s], the last at l) and len[s] its length. spread is the
// solid angle at l of the path's bundle per unit area at x across d[0] (dOmega_l / dA_perp): a point light of
// intensity I at l gives x the irradiance I T spread across d[0], T the faces' transmittance (1 / r^2 without
// faces).
struct PlanarPath {
  int k = 0;
  glm::dvec3 y[kMaxPlanarFaces];
  glm::dvec3 n[kMaxPlanarFaces];  // the plane's normal of face j where y[j] lies (a tracked face: its triangle's)
  glm::dvec3 d[kMaxPlanarFaces + 1];
  double len[kMaxPlanarFaces + 1];
  double spread = 0.0;
};

// Solves Snell's law at every face, index[s] the refractive index along segment s, by Newton's method on the
// points' positions in their planes (reflect[j]: the path reflects off face j, index[j] = index[j + 1], the law
// of reflection being the same equation; null: it crosses every face) (Gaussian elimination on the 2k x 2k system, steps halved while they do
// not lower the residual), from start[j] (a point of face j: where the straight line from x to l crosses it).
// Converged when n_s d_s - n_{s+1} d_{s+1} is along face s's (shading) normal within 1e-12 for every face; false
// when it does not converge in 50 steps, a face is not crossed (or not reflected off) as asked, about its plane's
// normal and its shading normal, or a segment is empty.
// spread is then the implicit function theorem's: the points' derivatives with x, mapped to l's direction.
// tracker: each step's points moved onto the surfaces of shaded faces (null: the faces' planes are the surfaces).
bool solve_planar_path(const glm::dvec3& x, const glm::dvec3& l, const PlanarFace* faces, const double* index, int k,
                       const glm::dvec3* start, PlanarPath* out, const bool* reflect = nullptr,
                       const FaceTracker* tracker = nullptr);

}  // namespace spadgen::render
