// What the integrator and the ground truth need to know about a ray hit: position, normals and the
// material resolved there (texture lookups, spectral channels).
#pragma once
#include <glm/glm.hpp>

#include <vector>

#include "bsdf.h"
#include "core/config.h"
#include "embree_scene.h"
#include "planar_path.h"
#include "scenes/scene.h"

namespace spadgen::render {

struct Surface {
  glm::vec3 p{0.0f};   // on the triangle (from barycentrics, not origin + t dir)
  glm::vec3 ng{0.0f};  // unit geometric normal on the glTF front side (counter-clockwise)
  glm::vec3 ns{0.0f};  // unit shading normal (interpolated vertex normals, else ng)
  int mesh = -1;
  int material = -1;   // index into Scene::materials, -1: the glTF default material
};

// Per-material constants in the two channels (laser, ambient).
struct ResolvedMaterial {
  MaterialPoint point;          // factors (with a base colour texture or COLOR_0, point.base is recomputed per hit)
  glm::vec3 base_rgb{1.0f};     // baseColorFactor's RGB (linear), which the texture and COLOR_0 multiply
  int texture = -1, texcoord = 0;
  Spec sigma{0.0f};             // absorption coefficient inside the volume, 1/m
  bool absorbing = false;       // sigma > 0
  bool volume = false;          // transmissive with thickness > 0: bounds a medium of index ior
};

class Shading {
 public:
  // ambient_photometric: photons per second per nit (cd/m^2) in the ambient band, for emissive surfaces.
  Shading(const scenes::Scene& scene, double laser_wavelength_m, const glm::vec3& ambient_rgb_weights,
          double ambient_photometric);

  Surface surface(const RayHit& hit) const;
  // Position, geometric normal and material only (no shading normal): enough for shadow rays.
  Surface geometric(const RayHit& hit) const;
  MaterialPoint material_at(const Surface& s, const RayHit& hit) const;
  // Triangle `triangle` of mesh `mesh` as a face of a refracted path: its plane (corner 0, geometric normal),
  // shaded where the mesh has vertex normals (its corner normals interpolated over the plane), its identity and
  // barycentric dual basis; false where it is degenerate.
  bool face(uint32_t mesh, uint32_t triangle, PlanarFace* out) const;
  const ResolvedMaterial& material(int id) const { return id < 0 ? default_ : materials_[size_t(id)]; }
  bool has_emission() const { return has_emission_; }

 private:
  glm::vec3 texture_rgb(int texture, const glm::vec2& uv) const;

  const scenes::Scene& scene_;
  glm::vec3 w_laser_, w_ambient_;
  std::vector<ResolvedMaterial> materials_;
  // Per triangle, [mesh][triangle], gathered once so that a hit reads one or two cache lines instead of
  // an index triple, three positions and three normals spread over the mesh: the corners and the unit
  // geometric normal; the corner normals for meshes that have them (else empty).
  struct TriangleGeometry {
    glm::vec3 p0, p1, p2, ng;
  };
  struct TriangleNormals {
    glm::vec3 n0, n1, n2;
  };
  std::vector<std::vector<TriangleGeometry>> triangles_;
  std::vector<std::vector<TriangleNormals>> triangle_normals_;
  ResolvedMaterial default_;
  float srgb_[256];
  bool has_emission_ = false;
};

}  // namespace spadgen::render
