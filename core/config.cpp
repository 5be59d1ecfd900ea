#include "config.h"

namespace spadgen {

SensorStageConfig sensor_stage(const RunConfig& c) {
  SensorStageConfig s;
  s.camera = {c.camera.width_px, c.camera.height_px, c.camera.optics_transmission};
  s.laser = c.laser;
  s.ambient = {c.ambient.wavelength_m, c.ambient.bandwidth_m};
  s.sensor = c.sensor;
  s.acquisition = c.acquisition;
  s.outputs.frames = c.outputs.frames;
  // labels.exr (a gate sweep's, from the ground truth) compares each object's edge with the full rates.
  s.outputs.detection_rate = c.outputs.detection_rate ||
                             (c.outputs.ground_truth && c.acquisition.mode == AcquisitionMode::GateSweep);
  s.chip_seed = c.chip_seed();
  s.noise_seed = c.noise_seed();
  return s;
}

bool laser_traced(const RunConfig& c) {
  // (outputs.light in the intensity mode: what its counts see, and the laser's light only with a time window, which a
  // later spadgen sense may read as a gate sweep)
  return c.acquisition.mode != AcquisitionMode::Intensity || c.acquisition.intensity.laser_on || c.outputs.transient ||
         (c.outputs.light && c.render.window_start_s.has_value());
}

RenderStageConfig render_stage(const RunConfig& c, std::vector<double> row_fill_factor, std::vector<double> row_ambient_floor) {
  RenderStageConfig r{c.camera, c.laser, c.ambient, c.render, c.light_seed(), std::move(row_fill_factor)};
  // (a gate sweep's background only: in the intensity mode the ambient light is what the counts measure; and
  // not for light saved for a later spadgen sense, which may sense it in another mode or with another sensor)
  if (c.acquisition.mode == AcquisitionMode::GateSweep && !c.outputs.light) r.row_ambient_floor = std::move(row_ambient_floor);
  // The laser is held to the target wherever it is traced: what the counts see (a gate sweep, laser_on) and
  // what is kept of it (outputs.transient; outputs.light with a time window, which a later sense may read as a
  // gate sweep: an intensity run's saved laser return had the first round's paths only).
  r.trace_laser = laser_traced(c);
  r.target_laser = r.trace_laser;
  // The counts see the ambient light in every mode (a gate sweep's background): it is held to the target
  // as the laser is (a scene without it has none, and takes the laser's paths).
  r.target_ambient = true;
  return r;
}

}  // namespace spadgen
