// The renderer: an Embree scene over the immutable Scene, camera rays, exact ground truth along primary
// rays, and a transient path tracer in absolute units (photons per laser pulse reaching each pixel's
// SPAD, after optics and fill factor, before PDP). Pixel coordinates are full-sensor coordinates
// (camera.width_px x camera.height_px); a crop only selects which pixels are asked for.
#pragma once
#include <cstdint>
#include <memory>

#include "core/config.h"
#include "core/tile.h"
#include "scenes/scene.h"

namespace spadgen::render {

struct RenderStats {
  uint64_t camera_rays = 0, shadow_rays = 0;
};

class Renderer {
 public:
  Renderer(const scenes::Scene& scene, const RunConfig& config);
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  // Exact ground truth along the ray through each pixel centre of rect.
  GroundTruthTile ground_truth(const PixelRect& rect) const;

  // Laser transient (on `axis`; axis.bins == 0 renders only the time-integrated totals), laser totals,
  // out-of-window totals and the ambient photon rate for every pixel of data_rect (which contains rect).
  // Deterministic: depends only on the scene, the config, the seed and the pixel coordinates.
  TransientTile transient(const PixelRect& rect, const PixelRect& data_rect, const TimeAxis& axis,
                          RenderStats* stats = nullptr) const;

  // Photons per laser pulse emitted (N_p = P / (f_rep h c / lambda)).
  double photons_per_pulse() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace spadgen::render
