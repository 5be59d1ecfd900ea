// The renderer: an Embree scene over the immutable Scene, camera rays, exact ground truth along primary
// rays, and a transient path tracer in absolute units. Pixel coordinates are full-sensor coordinates
// (camera.width_px x camera.height_px, row 0 at the top); a crop only selects which pixels are asked for.
//
// What a pixel receives (the camera measurement): photons per laser pulse arriving at the pixel's
// photosensitive area,
//   Phi = FF * optics_transmission * p^2 * pi / (4 N^2) * E_x[ L(omega_x) cos^4(theta_x) ]
// with x uniform over the pixel (jittered per sample), L the photon radiance along the ray through x and
// theta its angle to the optical axis. The output INCLUDES the fill factor (of the pixel's row, as
// RenderStageConfig::row_fill_factor gives it: the sensor's pixel layout decides) and the optics transmission; it EXCLUDES the PDP,
// which the sensor stage applies. A Lambertian plane of albedo rho at distance d on the axis, lit by
// radiant intensity I from the camera, gives rho I p^2 FF / (4 N^2 d^2) (DESIGN.md). The ambient rate
// uses the same measurement, in photons per second.
//
// Time: a path arrives at emission_delay + (optical path length) / c, the camera segment counted from the
// camera centre. Its contribution goes to the bin of every periodic image t + m * period inside the
// window (returns later than a period fold into the next one); with no image inside, to out_of_window.
// laser_total holds every contribution. The transient is rendered for a delta pulse: the pulse shape and
// the SPAD jitter are the sensor's convolution.
//
// The Renderer copies the Scene (Embree shares the copy's buffers), so the caller's Scene may go away.
// transient() and ground_truth() are const and may be called concurrently from TBB workers.
// See docs/render.md for the materials, lights, units and what is approximated.
#pragma once
#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

#include "core/config.h"
#include "core/tile.h"
#include "scenes/scene.h"

namespace spadgen::render {

// The rays a render traced, by what they were traced for. The first six are disjoint and sum to every ray;
// indirect overlaps them.
struct RayCounts {
  uint64_t camera = 0;     // camera rays: a path's first segment
  uint64_t bounce = 0;     // a path's further segments
  // straight connections to the laser, and their continuations across transmissive surfaces (with
  // refracting volumes, every laser connection's first walk: it finds the interfaces connect_laser_refracted crosses)
  uint64_t laser = 0;
  // the segments of connections to the laser refracted through them (connect_laser_refracted, connect_laser_planar)
  uint64_t refracted = 0;
  uint64_t mirror = 0;  // the segments of the laser's reflections off smooth planar faces (connect_laser_mirrors)
  // guided connections and ghost draws: their targets' search, their rays and the laser connections at their
  // ends
  uint64_t guided = 0;
  uint64_t ambient = 0;    // shadow rays to the glTF's punctual lights
  // of all the above, those a path traced after it left its first non-delta vertex through a non-Dirac lobe
  // (render.max_bounces > 1)
  uint64_t indirect = 0;
  uint64_t total() const { return camera + bounce + laser + refracted + mirror + guided + ambient; }
  RayCounts& operator+=(const RayCounts& o) {
    camera += o.camera, bounce += o.bounce, laser += o.laser, refracted += o.refracted, mirror += o.mirror,
        guided += o.guided, ambient += o.ambient, indirect += o.indirect;
    return *this;
  }
};

struct RenderStats {
  RayCounts rays;
  uint64_t camera_hits = 0;  // samples of the pixels of rect (the halo left out) whose camera ray hit a surface
};

class Renderer {
 public:
  // config: the renderer's part of the run (core/config.h), with the fill factor of every row from the
  // sensor's pixel layout.
  Renderer(const scenes::Scene& scene, const RenderStageConfig& config);
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  // Exact ground truth along the ray through each pixel centre of rect.
  GroundTruthTile ground_truth(const PixelRect& rect) const;

  // Laser transient (on `axis`; axis.bins == 0 renders only the time-integrated totals), laser totals,
  // out-of-window totals and the ambient photon rate for every pixel of data_rect (which contains rect).
  // Deterministic: depends only on the scene, the config, the seed and the pixel coordinates.
  // gt (null: not asked): the ground truth of rect, whose object_laser, direct_other_laser and
  // indirect_laser receive each pixel's laser_total split by the objects of its slots (docs/render.md).
  TransientTile transient(const PixelRect& rect, const PixelRect& data_rect, const TimeAxis& axis,
                          RenderStats* stats = nullptr, GroundTruthTile* gt = nullptr) const;

  // Photons per laser pulse emitted (N_p = P / (f_rep h c / lambda)).
  double photons_per_pulse() const;
  // Where the laser emits from (world): laser.offset_m from the camera centre, or the glTF light's position.
  glm::dvec3 laser_position() const;
  // The sensor pixels (x, y) in which the camera sees the laser's image in a smooth planar face (laser -> face ->
  // lens: docs/render.md, "The laser's image in smooth planar faces"), once each.
  std::vector<std::pair<int, int>> glint_pixels() const;

  // The pixels of a sensor row whose camera rays travel, and with a target error accumulate, together.
  static constexpr int kBlockPixels = 16;

  // The samples of a block whose camera rays are traced ahead at a time (as packets); the block's pixels
  // accumulate their bins side by side meanwhile.
  static constexpr int kSamplesAhead = 64;

  // Bytes each rendering thread holds for the camera rays traced ahead of samples_per_pixel (at most
  // kSamplesAhead) samples of a block (for the resource plan of a run, app/resources.h).
  static size_t bytes_per_thread(int samples_per_pixel);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace spadgen::render
