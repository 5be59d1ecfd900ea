// Provenance and metadata.json. Provenance (scene file and content hash, seed, crop, version) travels
// with every EXR as attributes, so that an image separated from its folder still says where it came from;
// metadata.json records it with the resolved scene file, the sensor's acquisition and what the run produced.
#pragma once
#include <nlohmann/json.hpp>

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/config.h"
#include "core/stage_clock.h"
#include "core/tile.h"
#include "core/time_axis.h"
#include "render/camera.h"
#include "render/renderer.h"
#include "scenes/scene.h"
#include "scenes/scene_file.h"
#include "sensor/sensor.h"
#include "writers/writers.h"

namespace spadgen::app {

struct Provenance {
  std::string scene_file;
  // FNV-1a 64 (hex) of the scene file, the glTF and every buffer and image beside it.
  std::string scene_hash;
  uint64_t seed = 0;
  PixelRect crop;  // the rendered pixels, in sensor coordinates
  uint64_t chip_seed = 0;  // the chip's fixed pattern (seeds.chip): sensor_maps.exr and labels.exr depend on it
  // The sensor's tables as the sensor read them (metadata.json's sensor_tables_fnv1a64 and sensor_table_fnv1a64;
  // scenes::sensor_tables_hash and its tables).
  std::string tables_hash;
  std::vector<scenes::SensorTable> tables;
};
// scene_hash: scenes::content_hash of the scene's files, as they were read; tables_hash and tables: the
// sensor's tables, as it read them.
Provenance provenance(const RunConfig& c, const PixelRect& img, const std::string& scene_hash, const std::string& tables_hash,
                      const std::vector<scenes::SensorTable>& tables);
// Sets the provenance attributes (spadgen_version, _seed, _scene_file, _scene_hash, _crop) of an EXR; the
// outputs add spadgen_chip_seed to those of the chip (sensor_maps.exr, labels.exr).
void stamp(writers::ExrImage& e, const Provenance& p);


// What a resolved scene (metadata.json's resolved_scene) sets that the scene hash does not see (--set values, a
// dataset sample's parameters and set), as FNV-1a 64 hex of it without what only draws another realisation
// of the same data (seed, seeds), what is only written (outputs), the Monte Carlo's settings (render) and
// the description: metadata.json's settings_hash_fnv1a64, which reconstruct's files record of their run
// (spadgen_source settings_hash) so that detections of another plate position are not scored on this one.
std::string settings_hash_of(const nlohmann::json& resolved_scene);

// The time axis as laser.exr (attribute spadgen_time_axis) and metadata.json record it.
nlohmann::json axis_json(const TimeAxis& a);

// The images' pinhole camera for metadata.json: OpenCV intrinsics (with the crop's offset), the
// camera-to-world pose, focal length and pitch, and where the laser emits from in the camera's frame.
nlohmann::json camera_json(const render::Camera& cam, const PixelRect& img, const glm::dvec3& laser_world);

// The scene's objects (scenes::objects_of) for metadata.json: id, the glTF node's name and index, the
// names of its meshes (Scene::meshes, the ground truth's mesh_id) and of their materials.
nlohmann::json objects_json(const scenes::Scene& scene);

// What of the physical model a run's scene and settings use, for metadata.json "model": one entry per
// component, {"component", "active", "why"}. The scene's part comes from the scene (null: a sense, which
// takes it from its source run's metadata.json, `from_run`). laser: whether the light holds the laser's
// (laser_traced(c) for a run; for a sense, whether its run's saved light does).
nlohmann::json model_components(const RunConfig& c, const scenes::Scene* scene, bool laser, const nlohmann::json& from_run = nullptr);

// What metadata.json reports that only the finished run knows.
// Where a run's time went: wall seconds before the tiles (scene, BVH, sensor maps, outputs opened), in
// the tiles and after them until metadata.json (images, previews); and the tiles' stages as StageClock
// measured them, summed over threads.
struct RunTimes {
  double setup_seconds = 0.0, tiles_seconds = 0.0, finish_seconds = 0.0;
  std::array<double, StageClock::kStageCount> stage_thread_seconds{};
  // The tiles' stages from the clock that timed them.
  void take_stages(const StageClock& clock) {
    for (int k = 0; k < StageClock::kStageCount; ++k) stage_thread_seconds[size_t(k)] = clock.seconds(StageClock::Stage(k));
  }
};

struct RunRecord {
  std::vector<std::string> files;  // as published, metadata.json last
  nlohmann::json file_bytes = nlohmann::json::object();  // each but metadata.json: writers::bytes_on_disk
  nlohmann::json camera;           // camera_json()
  double photons_per_pulse_emitted = 0.0;
  // The light holds the laser's (laser_traced of the run; for a sense, of the run whose light it read):
  // laser_photons_per_pulse is null without it.
  bool laser_traced = false;
  double laser_total = 0.0, out_of_window_total = 0.0;  // photons per pulse, summed over the image
  double beyond_period_total = 0.0;  // of laser_total, from beyond the unambiguous range (run only: app/warnings.h)
  int ground_truth_layers = 0;
  int64_t ground_truth_layers_cut = 0;  // pixels whose layers render.max_layers cut (run only: app/warnings.h)
  std::array<int64_t, 4> label_edges{};  // the labels' (pixel, object) pairs by EdgeInSweep (app/warnings.h)
  int ground_truth_objects = 0;   // the most objects along one ray (object<j> channels below it)
  nlohmann::json objects;         // objects_json(): the scene's objects, ids as in the images
  nlohmann::json model;                 // model_components()
  nlohmann::json accuracy;              // Outputs: the laser return's standard error and the paths per pixel
  nlohmann::json ground_truth_summary;  // Outputs: hit fraction, range span, meshes in view, deepest layer
  bool counts_u8 = true;
  double laser_open_rate = 0.0;   // SensorTile::laser_open_rate, of the image (avalanches per frame)
  PixelRect transient_crop;
  std::vector<std::pair<int, int>> profile_pixels;
  // Per stack written (relative path): its container, and a Zarr store's chunks and compressor.
  nlohmann::json storage = nlohmann::json::object();
  // outputs.light: the pixels it covers (sensor coordinates) and the size of its values.
  std::optional<PixelRect> light_region;
  int64_t light_values_bytes = 0;
  // The fill factor of each sensor row in that light (the renderer's; a sense with another pixel design
  // links the light as it is): metadata.json light.fill_factor, as runs of rows [first, count, value].
  std::vector<double> light_fill_factor;
  // spadgen sense: the run folder it read and which realisation of the temporal noise this is.
  std::optional<nlohmann::json> sense;
  // spadgen dataset: the dataset, the sample's index, parameters and hash (app/dataset.h).
  std::optional<nlohmann::json> dataset;
  // How the run went: not a function of the scene and the seed.
  int threads = 0;
  double seconds = 0.0;  // the tiles' wall time
  render::RenderStats render_stats;
  RunTimes times;
};

// metadata.json "run": threads, seconds, the stages' shares of the wall time, the rays by what they were
// traced for, and each model component's share where it has one of its own (docs/outputs.md).
nlohmann::json run_json(const RunRecord& r);

// The content of metadata.json.
// scene_warnings: what loading the glTF warned about.
nlohmann::json metadata(const scenes::ResolvedRun& resolved, const std::vector<std::string>& scene_warnings,
                        const sensor::SensorModel& sensor, const Provenance& p, const TimeAxis& axis, const RunRecord& r);

}  // namespace spadgen::app
