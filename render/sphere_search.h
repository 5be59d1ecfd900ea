// The search that seeds the laser's refracted paths through a smooth glass mesh (a glass sphere, an ellipsoid):
// every path of the laser's light through a sphere to a point, found in the plane of the laser, the sphere's
// centre and the point, where every such path lies (docs/render.md, "Refracted laser connections"). The
// Integrator solves each seed's path on the mesh's own triangles (render/planar_path.h).
#pragma once
#include <glm/glm.hpp>

#include <vector>

namespace spadgen::render {

// A ray of the laser through a sphere of radius R and index n about a centre at distance dl from the laser, in
// their plane (x along the axis from the laser through the centre, which is the origin; y towards the side the
// ray passes at signed distance h from the centre), refracted in and out: where it enters and leaves the sphere,
// and its direction after. ok: false where it meets the sphere within 0.6 degrees of grazing, or leaves it so.
struct SphereRay {
  bool ok = false;
  double h = 0.0;
  glm::dvec2 entry{0.0}, exit{0.0}, dir{0.0};
};
SphereRay sphere_ray(double dl, double R, double n, double h);

// The laser's rays through one sphere at `steps` + 1 angles of incidence, uniform from -89.4 to 89.4 degrees,
// made once per mesh and sphere; seeds() finds the rays whose exit passes through a point X of the plane.
class SphereSearch {
 public:
  SphereSearch(double dl, double R, double n, int steps);
  double radius() const { return R_; }

  // The rays through the point X = (along the axis, off it), each within 1 / 64 of a step of a ray that passes
  // through X exactly (its seed): a sign change of a ray's miss of X between two steps, bisected 6 times; and two
  // such roots within one step (a caustic's fold, where two paths merge), where the least |miss| of one sign
  // at step c between steps b and d, by the parabola through the three, falls to half of c's miss or past
  // zero: a golden-section search of [b, d] for the other sign, then each of its two brackets bisected. Writes
  // at most `max` seeds in the order of their steps; returns their number.
  int seeds(const glm::dvec2& X, SphereRay* out, int max) const;

 private:
  double dl_, R_, n_;
  std::vector<SphereRay> rays_;
};

}  // namespace spadgen::render
