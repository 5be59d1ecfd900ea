// Warnings about runs whose data would be useless although every key is valid: printed on stderr (even
// with -q) and recorded in metadata.json ("warnings"), with what the scene file's own checks warn about
// (settings that do nothing, scenes::ResolvedRun::warnings) and what loading the glTF warned about.
// docs/outputs.md, section metadata.json, lists them.
#pragma once
#include <string>
#include <vector>

#include "core/config.h"
#include "core/tile.h"
#include "app/metadata.h"
#include "render/camera.h"
#include "scenes/scene.h"
#include "sensor/sensor.h"

namespace spadgen::app {

// Laser light that arrives outside the time window, or from beyond the unambiguous range, above this
// fraction of all the laser light the image receives is warned about.
inline constexpr double kWarnLightFraction = 0.01;
// A glTF camera whose aspect ratio differs from the sensor's by more than this (relative) is warned about.
inline constexpr double kWarnAspectMismatch = 0.01;

// A gate tabulated more coarsely than this fraction of its open value (sensor.gate.knots_per_edge, grid_ps:
// the knots' error against the fine grid plus the fine grid's own) is warned about: at N frames the
// expected counts may move by up to N times it (docs/accuracy.md, "The sensor model's knobs").
inline constexpr double kWarnGateError = 2e-3;
// Every such warning starts with this.
inline constexpr const char* kGateWarning = "sensor.gate: the gate is tabulated";

// `sense`'s warning that the sensor's tables changed on disk since the run starts with this (a sensor
// warning: a sense of that sense compares its own tables).
inline constexpr const char* kTablesChangedWarning = "the sensor's tables (";

// Every sweep_edge_warnings warning holds this (a sense with another sweep says its own, not the run's).
inline constexpr const char* kSweepEdgeWarning = " of the objects' returns along the rays (";

// Every warning about a pixel type blind to the laser holds this.
inline constexpr const char* kPdpWarning = ": its photon detection probability at the laser's wavelength";

// The warning that sensor.gate.grid_ps was coarsened (the fine grid has at most 12000 steps over the gate's
// edges and the instrument response) starts with this.
inline constexpr const char* kGridWarning = "sensor.gate.grid_ps ";

// A warning on stderr: "spadgen: warning: ", the context (a dataset's "sample 3: "), the warning.
void print_warning(const std::string& warning);
// The context print_warning names while it lives (one at a time: a dataset generates one sample at a time);
// silent: print none (a dataset's further realisations repeat what their sample's run said; metadata.json
// records them all the same).
class WarningContext {
 public:
  explicit WarningContext(std::string context, bool silent = false);
  ~WarningContext();
  WarningContext(const WarningContext&) = delete;
  WarningContext& operator=(const WarningContext&) = delete;

 private:
  std::string previous_;
  bool previous_silent_;
};

// Before rendering (run, sense and info): the gate sweep's gate tabulated coarsely (above); a pixel type
// whose PDP at the laser's wavelength is 0 (the built-in curve ends short of a near-infrared laser); the fine
// grid coarser than sensor.gate.grid_ps asked (asked_grid_s, where it is not the default; kGridWarning).
std::vector<std::string> sensor_warnings(const sensor::SensorModel& sensor, double asked_grid_s);
// After the sensor stage: the gate's tabulation error (above) is of the open gate's rate, so a bright return
// (laser_open_rate: the largest laser rate of a pixel with the gate open, RunRecord::laser_open_rate) makes
// it that many times larger in the gate's tails; warned about when that exceeds kWarnGateError. Starts with
// kGateWarning.
std::vector<std::string> bright_gate_warnings(const sensor::SensorModel& sensor, double laser_open_rate);
// After the labels (run and sense, gate sweeps): more than kWarnLightFraction of the lit (pixel, object)
// pairs (RunRecord::label_edges) have no rising edge in the sweep: it begins on their return's plateau (their
// rise lies before the first gate position; the labels take the falling edge), or the plateau spans it (no
// edge at all). A new user's plate 0.8-1.2 m away rose before a sweep starting at 4 ns, silently.
std::vector<std::string> sweep_edge_warnings(const RunConfig& c, const RunRecord& r);
// One of sensor_warnings', bright_gate_warnings' or sweep_edge_warnings' (sense replaces a run's with its own
// sensor's and sweep's).
bool is_sensor_warning(const std::string& warning);

// Before rendering (run and info): a cone beam (laser.beam = cone) whose spot is smaller than a pixel's
// field of view (the camera's pitch over its focal length), so small that a pixel's camera paths land on it
// fewer than kWarnSpotPaths times on average: its light is found by chance (noisy, or absent from the image).
inline constexpr double kWarnSpotPaths = 16.0;
// With scene given: a mesh whose vertices lie this far or farther from the point they are measured from
// (scenes::Mesh::offset, the centre of its vertices: floats there are 0.12 mm apart or more), the float spacing there
// and what it does; and a transmissive surface this far from the camera or farther (kWarnTransmissiveFromCameraM).
// The renderer works in a frame centred on the camera and moves each path's next ray render::kOffsetUlps
// float ulps of its coordinates off the surface it leaves (render/embree_scene.h offset_ray_origin), 1.95
// mm at 64 m, which steps over the back face of a plate about as thin.
inline constexpr double kWarnCoarseVerticesM = 1024.0;
inline constexpr double kWarnTransmissiveFromCameraM = 64.0;
// With scene given: a used material bounding a curved refracting volume (vertex normals) this rough or rougher,
// whose faces the laser's connections cross as smooth ones (docs/render.md, "Refracted laser connections"): the
// error of so crossing a 3 mm plate's faces, +0.6 % to +3 % at this roughness.
inline constexpr float kWarnRoughRefractor = 0.2f;
std::vector<std::string> laser_warnings(const RunConfig& c, const render::Camera& camera,
                                        const scenes::Scene* scene = nullptr);

// Before rendering (run and info): a glTF camera (camera.gltf_camera) whose aspect ratio is not the
// sensor's, which keeps the vertical field of view and changes the horizontal one.
std::vector<std::string> camera_warnings(const RunConfig& c, const scenes::Scene& scene);

// After rendering, from the image's totals (r.rays summed over the tiles, r.laser_total, out_of_window_total,
// beyond_period_total, ground_truth_summary): nothing in view (no camera ray hits a surface), a surface
// through the camera's centre (a pixel's range at most kWarnRangeAtCameraM), no laser light returning, laser
// light from beyond the unambiguous range, laser light outside the time window.
inline constexpr double kWarnRangeAtCameraM = 1e-6;
// camera: as laser_warnings', which no laser light returning names as a cause when it applies.
std::vector<std::string> light_warnings(const RunConfig& c, const PixelRect& img, const RunRecord& r, const render::Camera& camera);

}  // namespace spadgen::app
