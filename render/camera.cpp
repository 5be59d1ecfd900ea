#include "camera.h"

#include <cmath>
#include <string>

#include "core/error.h"
#include "core/units.h"

namespace spadgen::render {
namespace {

std::string vec_str(const glm::dvec3& v) {
  return "[" + std::to_string(v.x) + ", " + std::to_string(v.y) + ", " + std::to_string(v.z) + "]";
}

}  // namespace

Camera::Camera(const CameraConfig& c, const scenes::Scene& scene, const glm::dvec3& origin)
    : width_(c.width_px), height_(c.height_px), pitch_(c.pixel_pitch_m) {
  const double sensor_height = height_ * pitch_;

  std::optional<double> fov = c.vertical_fov_rad;
  if (!c.gltf_camera.empty()) {
    const scenes::Camera* gc = scene.find_camera(c.gltf_camera);
    if (!gc) {
      for (const std::string& o : scene.orthographic_cameras)
        if (o == c.gltf_camera)
          throw KeyError("/camera/gltf_camera", "camera '" + c.gltf_camera + "' in " + scene.source +
                      " is orthographic; spadgen models a lens (a perspective camera): choose a perspective one, or "
                      "place the camera with camera.position_m and camera.look_at_m");
      std::string names;
      for (const scenes::Camera& cam : scene.cameras) names += (names.empty() ? "'" : ", '") + cam.name + "'";
      throw KeyError("/camera/gltf_camera", "no perspective camera named '" + c.gltf_camera + "' in " + scene.source +
                  " (cameras: " + (names.empty() ? "none" : names) + ")" + scene.not_loaded_note(c.gltf_camera));
    }
    const glm::dmat4& m = gc->world_from_camera;
    position_ = glm::dvec3(m[3]);
    const glm::dvec3 x(m[0]), y(m[1]), z(m[2]);
    if (glm::length(x) < 1e-12 || glm::length(y) < 1e-12 || glm::length(z) < 1e-12)
      throw KeyError("/camera/gltf_camera", "the transform of camera '" + c.gltf_camera + "' is singular");
    forward_ = -glm::normalize(z);
    right_ = glm::normalize(glm::cross(forward_, y));
    up_ = glm::cross(right_, forward_);
    // The scene file's field of view, when given, overrides the glTF camera's.
    if (!fov) fov = gc->yfov_rad;
  } else {
    position_ = glm::dvec3(c.position_m[0], c.position_m[1], c.position_m[2]);
    const glm::dvec3 target(c.look_at_m[0], c.look_at_m[1], c.look_at_m[2]);
    const glm::dvec3 up(c.up[0], c.up[1], c.up[2]);
    const glm::dvec3 f = target - position_;
    if (glm::length(f) < 1e-12)
      throw Error("camera.look_at_m " + vec_str(target) + " equals camera.position_m: no viewing direction");
    forward_ = glm::normalize(f);
    const glm::dvec3 r = glm::cross(forward_, up);
    if (glm::length(r) < 1e-9 * std::max(1.0, glm::length(up)))
      throw Error("camera.up " + vec_str(up) + " is zero or parallel to the viewing direction " +
                  vec_str(forward_) + ": expected a vector across it");
    right_ = glm::normalize(r);
    up_ = glm::cross(right_, forward_);
  }
  if (fov) {
    if (!(*fov > 0.0 && *fov < kPi))
      throw Error("camera vertical field of view must lie in (0, 180) degrees, found " +
                  std::to_string(*fov * 180.0 / kPi));
    focal_ = 0.5 * sensor_height / std::tan(0.5 * *fov);
  } else {
    focal_ = c.focal_length_m;
  }
  if (!(focal_ > 0.0) || !std::isfinite(focal_))
    throw Error("camera.focal_length_mm must be positive, found " + std::to_string(focal_ * 1e3));
  position_ -= origin;
}

glm::dvec3 Camera::direction(double px, double py) const {
  const double sx = (px - 0.5 * width_) * pitch_;
  const double sy = (0.5 * height_ - py) * pitch_;
  return glm::normalize(sx * right_ + sy * up_ + focal_ * forward_);
}

bool Camera::pixel_of(const glm::dvec3& d, double* px, double* py) const {
  const double z = glm::dot(d, forward_);
  if (!(z > 0.0)) return false;
  *px = 0.5 * width_ + focal_ * glm::dot(d, right_) / (z * pitch_);
  *py = 0.5 * height_ - focal_ * glm::dot(d, up_) / (z * pitch_);
  return *px >= 0.0 && *px < double(width_) && *py >= 0.0 && *py < double(height_);
}

double Camera::corner_half_angle() const {
  const double half_diag = 0.5 * pitch_ * std::hypot(double(width_), double(height_));
  return std::atan2(half_diag, focal_);
}

}  // namespace spadgen::render
