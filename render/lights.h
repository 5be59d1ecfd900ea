// The pulsed laser (a point emitter with uniform radiant intensity over a cone) and the steady ambient
// lights (uniform environment, glTF punctual lights), in photon units.
#pragma once
#include <glm/glm.hpp>

#include <vector>

#include "camera.h"
#include "core/config.h"
#include "scenes/scene.h"

namespace spadgen::render {

struct Laser {
  glm::dvec3 position{0.0};
  glm::dvec3 axis{0, 0, -1};    // unit, world
  double cos_half_angle = -1.0; // -1: every direction (a glTF point light)
  double intensity = 0.0;       // photons per pulse per steradian inside the cone

  // Radiant intensity (photons per pulse per sr) emitted along unit direction d (from the laser).
  double intensity_towards(const glm::dvec3& d) const {
    return glm::dot(d, axis) >= cos_half_angle ? intensity : 0.0;
  }
};

// laser.beam flood, cone or gltf_light. Throws spadgen::Error naming the key when the glTF light is missing
// or unusable (the scene file's values themselves were checked when it was read).
// *laser_light receives the index of the glTF light used as the laser (-1 if none).
Laser make_laser(const RenderStageConfig& config, const Camera& camera, const scenes::Scene& scene, int* laser_light);

struct PunctualLight {
  enum class Type { Point, Spot, Directional } type = Type::Point;
  glm::dvec3 position{0.0}, direction{0, 0, -1};  // direction the light travels (unit)
  double power = 0.0;  // photons/s/sr (point, spot) or photons/s/m^2 (directional), ambient band
  double cos_outer = -1.0, cos_inner = -1.0;

  // Photons/s/sr (point, spot) towards unit direction d from the light, with glTF's spot falloff.
  double intensity_towards(const glm::dvec3& d) const;
};

struct Ambient {
  double environment_radiance = 0.0;  // photons/s/m^2/sr seen by rays that escape the scene
  std::vector<PunctualLight> lights;
  bool any() const { return environment_radiance > 0.0 || !lights.empty(); }
};

// ambient.illuminance_lux and (when ambient.gltf_lights) the glTF lights other than the laser.
Ambient make_ambient(const RenderStageConfig& config, const scenes::Scene& scene, const glm::vec3& ambient_rgb_weights,
                     int laser_light);

}  // namespace spadgen::render
