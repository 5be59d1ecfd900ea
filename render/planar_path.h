// The path of light between two fixed points through refracting planar interfaces of any orientation (the
// faces of plates that are not parallel, a wedge): the Integrator's laser connection where the straight walk
// to the laser crossed flat faces that are not all parallel (docs/render.md, "Refracted laser connections").
// A manifold next-event estimation (Hanika et al. 2015) restricted to planes, where it is exact.
#pragma once
#include <glm/glm.hpp>

namespace spadgen::render {

// A plane: a point of it and its unit normal (either side).
struct PlanarFace {
  glm::dvec3 p, n;
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
  glm::dvec3 d[kMaxPlanarFaces + 1];
  double len[kMaxPlanarFaces + 1];
  double spread = 0.0;
};

// Solves Snell's law at every face, index[s] the refractive index along segment s, by Newton's method on the
// points' positions in their planes (reflect[j]: the path reflects off face j, index[j] = index[j + 1], the law
// of reflection being the same equation; null: it crosses every face) (Gaussian elimination on the 2k x 2k system, steps halved while they do
// not lower the residual), from start[j] (a point of face j: where the straight line from x to l crosses it).
// Converged when n_s d_s - n_{s+1} d_{s+1} is along face s's normal within 1e-12 for every face; false when it
// does not converge in 50 steps, a face is not crossed (or not reflected off) as asked, or a segment is empty.
// spread is then the implicit function theorem's: the points' derivatives with x, mapped to l's direction.
bool solve_planar_path(const glm::dvec3& x, const glm::dvec3& l, const PlanarFace* faces, const double* index, int k,
                       const glm::dvec3* start, PlanarPath* out, const bool* reflect = nullptr);

}  // namespace spadgen::render
