// The pinhole camera: full-sensor pixel coordinates (row 0 at the top) to world rays, and the constant
// of the camera measurement equation.
#pragma once
#include <glm/glm.hpp>

#include "core/config.h"
#include "scenes/scene.h"

namespace spadgen::render {

class Camera {
 public:
  // From camera.gltf_camera (a node of `scene`) or from position_m / look_at_m / up. Throws
  // spadgen::Error naming the key when the camera is degenerate or the glTF camera does not exist.
  // origin: the world point position() is measured from (the renderer's frame, centred on the camera).
  Camera(const CameraConfig& config, const scenes::Scene& scene, const glm::dvec3& origin = glm::dvec3(0.0));

  int width() const { return width_; }
  int height() const { return height_; }
  double pitch_m() const { return pitch_; }
  double focal_length_m() const { return focal_; }
  const glm::dvec3& position() const { return position_; }
  const glm::dvec3& right() const { return right_; }
  const glm::dvec3& up() const { return up_; }
  const glm::dvec3& forward() const { return forward_; }
  double focal_length() const { return focal_; }  // metres
  double pitch() const { return pitch_; }         // metres

  // Unit world direction through the sensor-plane point of pixel coordinates (px, py), where pixel
  // (x, y) spans [x, x + 1) x [y, y + 1) and its centre is (x + 0.5, y + 0.5).
  glm::dvec3 direction(double px, double py) const;
  // The sensor pixel coordinates (px, py) where world direction d (from the camera centre) lands, as direction's
  // inverse; false when d points behind the camera or lands outside the sensor.
  bool pixel_of(const glm::dvec3& d, double* px, double* py) const;
  // Half-angle of the cone from the camera centre through the sensor's corners (the flood beam's).
  double corner_half_angle() const;

 private:
  int width_ = 0, height_ = 0;
  double pitch_ = 0, focal_ = 0;
  glm::dvec3 position_{0.0}, right_{1, 0, 0}, up_{0, 1, 0}, forward_{0, 0, -1};
};

}  // namespace spadgen::render
