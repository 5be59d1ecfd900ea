// The renderer's state, shared by renderer.cpp and ground_truth.cpp. Member order is construction order.
#pragma once
#include <string>
#include <vector>

#include "camera.h"
#include "core/config.h"
#include "embree_scene.h"
#include "integrator.h"
#include "lights.h"
#include "renderer.h"
#include "scenes/scene.h"
#include "spectrum.h"
#include "surface.h"

namespace spadgen::render {

struct Renderer::Impl {
  Impl(const scenes::Scene& s, const RenderStageConfig& c);

  // Throws spadgen::Error unless rect is non-empty and inside the full sensor.
  void check_rect(const PixelRect& rect, const char* what) const;

  // The world point the renderer's frame is centred on: the camera's centre. Every position below (the
  // scene's vertices and lights, the camera, the laser) is measured from it, so that float coordinates
  // near the camera are fine however far the scene lies from the glTF's origin (a path's next ray steps
  // render::kOffsetUlps ulps of its coordinates off a surface: 30 um at 1 m from the camera, 1.95 mm at 64 m).
  glm::dvec3 origin;
  scenes::Scene scene;  // a copy, centred on origin: the renderer owns what Embree's shared buffers point into
  // Objects of the ground truth; mesh_object maps Embree's geometry ID (= mesh index) to its object.
  scenes::Objects objects;
  RenderStageConfig config;
  Camera camera;
  int laser_light = -1;
  Laser laser;
  glm::vec3 ambient_weights;
  Ambient ambient;
  EmbreeScene embree;
  Shading shading;
  Integrator integrator;
};

}  // namespace spadgen::render
