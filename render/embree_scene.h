// Every Embree call of spadgen lives in embree_scene.cpp, so that a port to Embree 4 touches one file.
// One Embree scene over all meshes of a scenes::Scene, in world space, with geometry ID = mesh index (the
// renderer maps a mesh on to its ground-truth object with scenes::Objects::mesh_object).
#pragma once
#include <embree3/rtcore.h>

#include <glm/glm.hpp>

#include <cstdint>
#include <limits>
#include <vector>

#include "scenes/scene.h"

namespace spadgen::render {

// The bit of a ray's id that marks it as going towards a light (every occluded ray; intersect's toward_light).
inline constexpr unsigned kTowardLight = 1u << 31;

struct RayHit {
  float t = std::numeric_limits<float>::infinity();
  uint32_t mesh = 0, triangle = 0;
  float u = 0, v = 0;  // barycentrics of vertices 1 and 2
};

class EmbreeScene {
 public:
  // Keeps pointers into `scene`'s index buffers (shared with Embree): `scene` must outlive this object.
  explicit EmbreeScene(const scenes::Scene& scene);
  ~EmbreeScene();
  EmbreeScene(const EmbreeScene&) = delete;
  EmbreeScene& operator=(const EmbreeScene&) = delete;

  // Closest hit on (tnear, tfar) along origin + t dir (dir need not be unit; t is in units of |dir|).
  // toward_light: the ray goes from a point towards a light (the laser), and a single-sided surface is
  // culled as the light sees it, from the other side (occluded and occluded_packet always are).
  bool intersect(const glm::vec3& origin, const glm::vec3& dir, float tnear, float tfar, RayHit* hit,
                 bool toward_light = false) const;
  // kPacket rays at once (rtcIntersect16: the coherent camera rays of 16 pixels). Lanes with valid[i]
  // false are not traced; found[i] tells whether lane i hit anything, hit[i] where.
  static constexpr int kPacket = 16;
  void intersect_packet(const bool* valid, const glm::vec3& origin, const glm::vec3* dirs, float tnear, float tfar,
                        RayHit* hit, bool* found) const;
  // The same with one origin and tfar per lane (the shadow rays of 16 first hits towards the laser);
  // occluded_packet sets blocked[i] when anything lies on lane i's (tnear, tfar[i]).
  void intersect_packet(const bool* valid, const glm::vec3* origins, const glm::vec3* dirs, float tnear,
                        const float* tfar, RayHit* hit, bool* found, bool toward_light = false) const;
  void occluded_packet(const bool* valid, const glm::vec3* origins, const glm::vec3* dirs, float tnear,
                       const float* tfar, bool* blocked) const;
  // Whether anything lies on (tnear, tfar).
  bool occluded(const glm::vec3& origin, const glm::vec3& dir, float tnear, float tfar) const;

  // For the benchmark, which replays the integrator's rays through raw rtcIntersect1/rtcOccluded1 on the
  // same BVH and back-face filters.
  RTCScene handle() const { return scene_; }

 private:
  RTCDevice device_ = nullptr;
  RTCScene scene_ = nullptr;
  // Embree reads vertex buffers 16 bytes at a time, so each mesh's positions are copied with padding.
  std::vector<std::vector<float>> vertices_;
};

// Moves a point off the surface it lies on, along the geometric normal n towards the side the next ray
// leaves to, by kOffsetUlps ulps of its own coordinates (times n's component; Waechter and Binder, Ray
// Tracing Gems ch. 6), so that the next ray neither re-hits that surface nor skips a nearby one (a 2 mm
// plate within about 100 m of the scene's origin: farther, the step is longer than the plate is thick).
inline constexpr float kOffsetUlps = 256.0f;
glm::vec3 offset_ray_origin(const glm::vec3& p, const glm::vec3& n, const glm::vec3& dir);

}  // namespace spadgen::render
