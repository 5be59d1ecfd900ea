#include "lights.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "core/error.h"
#include "core/units.h"
#include "spectrum.h"

namespace spadgen::render {

Laser make_laser(const RenderStageConfig& config, const Camera& camera, const scenes::Scene& scene, int* laser_light) {
  const LaserConfig& c = config.laser;
  *laser_light = -1;
  const double n_p = photons_per_pulse(c.average_power_W, c.repetition_rate_Hz, c.wavelength_m);
  Laser laser;
  if (c.beam == Beam::Flood || c.beam == Beam::Cone) {
    laser.position = camera.position() + c.offset_m[0] * camera.right() + c.offset_m[1] * camera.up() -
                     c.offset_m[2] * camera.forward();
    laser.axis = camera.forward();
    double half = camera.corner_half_angle();
    if (c.beam == Beam::Cone) half = c.half_angle_rad;
    laser.cos_half_angle = std::cos(half);
  } else {  // Beam::GltfLight
    const scenes::Light* l = scene.find_light(c.gltf_light);
    if (!l) {
      std::string names;
      for (const scenes::Light& x : scene.lights) names += (names.empty() ? "'" : ", '") + x.name + "'";
      throw KeyError("/laser/gltf_light", "no KHR_lights_punctual light named '" + c.gltf_light + "' in " +
                  scene.source + " (lights: " + (names.empty() ? "none" : names) + ")" + scene.not_loaded_note(c.gltf_light));
    }
    if (l->type == scenes::Light::Type::Directional)
      throw KeyError("/laser/gltf_light", "light '" + c.gltf_light +
                  "' is directional; the laser must be a point or spot light");
    *laser_light = static_cast<int>(l - scene.lights.data());
    laser.position = l->position;
    laser.axis = glm::normalize(l->direction);
    laser.cos_half_angle = l->type == scenes::Light::Type::Spot ? std::cos(std::clamp(l->outer_cone_rad, 1e-6, kPi))
                                                                : -1.0;
  }
  // N_p spread uniformly over the cone's solid angle 2 pi (1 - cos alpha).
  laser.intensity = n_p / (2.0 * kPi * (1.0 - laser.cos_half_angle));
  return laser;
}

double PunctualLight::intensity_towards(const glm::dvec3& d) const {
  if (type != Type::Spot) return power;
  const double cd = glm::dot(d, direction);
  // glTF KHR_lights_punctual reference falloff.
  const double scale = 1.0 / std::max(0.001, cos_inner - cos_outer);
  const double a = std::clamp((cd - cos_outer) * scale, 0.0, 1.0);
  return power * a * a;
}

Ambient make_ambient(const RenderStageConfig& config, const scenes::Scene& scene, const glm::vec3& w, int laser_light) {
  const AmbientConfig& a = config.ambient;
  const double k = photons_per_second_per_photometric_unit(a.wavelength_m, a.bandwidth_m);
  Ambient amb;
  // ambient.spectral_irradiance_W_m2_nm, when set, replaces illuminance_lux: s W/m^2/nm of an equal-energy
  // spectrum is s * 683 lm/W * 106.857 nm lux (render/spectrum.h).
  const double lux = a.spectral_irradiance_W_m2_nm ? *a.spectral_irradiance_W_m2_nm * kLuminousEfficacy * kIntegralVLambdaNm
                                                   : a.illuminance_lux;
  // A uniform sky of radiance L gives illuminance pi L on any plane it fully covers.
  amb.environment_radiance = lux * k / kPi;
  if (!a.gltf_lights) return amb;
  for (size_t i = 0; i < scene.lights.size(); ++i) {
    if (static_cast<int>(i) == laser_light) continue;
    const scenes::Light& l = scene.lights[i];
    PunctualLight p;
    p.position = l.position;
    p.direction = glm::normalize(l.direction);
    p.power = l.intensity * k * static_cast<double>(glm::dot(l.color, w));
    switch (l.type) {
      case scenes::Light::Type::Point: p.type = PunctualLight::Type::Point; break;
      case scenes::Light::Type::Spot:
        p.type = PunctualLight::Type::Spot;
        p.cos_outer = std::cos(l.outer_cone_rad);
        p.cos_inner = std::cos(l.inner_cone_rad);
        break;
      case scenes::Light::Type::Directional: p.type = PunctualLight::Type::Directional; break;
    }
    if (p.power > 0.0) amb.lights.push_back(p);
  }
  return amb;
}

}  // namespace spadgen::render
