// The sensor stage: turns transient tiles (photons per pulse per time bin) into what the time-gated SPAD
// camera streams out. Depends on core/ only, never on the renderer. Pixel coordinates are full-sensor
// coordinates (camera.width_px x camera.height_px), so per-pixel maps and random streams do not change
// with the crop, the tile size or the thread count.
#pragma once
#include <nlohmann/json.hpp>

#include <memory>
#include <vector>

#include "core/config.h"
#include "core/tile.h"

namespace spadgen::sensor {

// The per-pixel maps actually used, for sensor_maps.exr: [rect.index(x, y)].
struct SensorMapsTile {
  PixelRect rect;
  std::vector<float> gate_skew_ps;    // gate position offset of the pixel, ps
  std::vector<float> gate_length_ps;  // gate length of the pixel, ps
  std::vector<float> dcr_cps;         // dark count rate at the set temperature, counts per second
  std::vector<float> pde;             // photon detection efficiency at the laser wavelength (PDP x FF x optics)
};

class SensorModel {
 public:
  explicit SensorModel(const RunConfig& config);
  ~SensorModel();
  SensorModel(const SensorModel&) = delete;
  SensorModel& operator=(const SensorModel&) = delete;

  // K: gate positions (gate sweep) or exposures (2D intensity: 1 single, 2 dual).
  int K() const;
  // Gate positions relative to the laser trigger, seconds (empty in 2D mode).
  const std::vector<double>& gate_positions_s() const;
  // The time window the renderer must cover: the union of every pixel's gate window at every position,
  // widened by the instrument response, on bins of bin_width_s. bins == 0 in 2D intensity mode.
  TimeAxis required_window(double bin_width_s) const;
  // Pixels of halo the sensor needs around a tile (1 when crosstalk is on, else 0).
  int halo() const;

  // Expected and sampled counts (and frames when asked) for the pixels of t.rect.
  SensorTile process(const TransientTile& t) const;
  SensorMapsTile maps(const PixelRect& rect) const;
  // What metadata.json records about the acquisition: gate positions, cycles per frame, N_sat, PDE, ...
  nlohmann::json describe() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace spadgen::sensor
