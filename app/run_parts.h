// What `run` and `sense` share: the image they cover, the time axis the sensor needs, the order of the
// files metadata.json lists. Internal to app/.
#pragma once
#include <nlohmann/json.hpp>
#include <tbb/global_control.h>

#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/config.h"
#include "core/tile.h"
#include "core/time_axis.h"
#include "scenes/scene_file.h"
#include "sensor/sensor.h"

namespace spadgen::app {

// The pixel rectangle the run renders (the crop, or the whole sensor).
PixelRect image_rect(const RunConfig& c);

// The arrival times the renderer covers. The sensor knows the window its acquisition needs and the laser
// period that folds late arrivals; a window set in the scene file replaces only the start and the length.
TimeAxis time_axis(const RunConfig& c, const sensor::SensorModel& s);

// The files in the order metadata.json lists them and the staging folder publishes them: by name,
// metadata.json last.
void order_files(std::vector<std::string>& files);

// The bytes of each file of the staging folder `dir` but metadata.json (writers::bytes_on_disk), for
// metadata.json's file_bytes: written once every other file is complete.
nlohmann::json file_bytes(const std::filesystem::path& dir, const std::vector<std::string>& files);

// The user's gate maps (sensor.gate.maps_exr), when the scene file names them, into the sensor: run,
// sense and info read them alike (throws spadgen::Error naming the file when they do not fit the sensor).
void apply_user_maps(sensor::SensorModel& sensor, const RunConfig& c);

// The sensor's tables (scenes::sensor_tables) hashed before the sensor reads them, and checked after: a run
// or sense records them as it read them (metadata.json recorded them when it was written, so a table edited
// while a run rendered was recorded as if read, and a later sense took the run's noise-free files for its own).
struct SensorTables {
  std::string hash;
  std::vector<scenes::SensorTable> tables;
  static SensorTables hashed(const RunConfig& c);
  // Throws spadgen::Error naming the scene file when the tables differ now from these.
  void check_unchanged(const RunConfig& c) const;
  // Throws spadgen::Error naming the scene file when these are not the tables of `expected` (a dataset sample's
  // hash, taken when it was resolved: null, nothing to compare).
  void check_expected(const RunConfig& c, const std::optional<std::string>& expected) const;
};

// Denormal floats flushed to zero and read as zero (FTZ, DAZ) on the calling thread. main() calls it
// first, before TBB starts: TBB's tasks run with the floating-point settings of the thread that started
// it, and threads inherit their creator's. Whether a run's sensor tasks flushed depended on whether
// Embree (which sets them) had run before TBB's first use, and a sense (no Embree) never did: with every
// command's threads flushing, run and sense agree bit for bit.
void flush_denormals();

// The command's worker threads while it lives: TBB's (all cores when threads <= 0) and OpenEXR's pool,
// which compresses and decompresses the images with as many (and flush_denormals on the calling thread).
class ThreadLimit {
 public:
  explicit ThreadLimit(int threads);
  ~ThreadLimit();
  ThreadLimit(const ThreadLimit&) = delete;
  ThreadLimit& operator=(const ThreadLimit&) = delete;

 private:
  std::unique_ptr<tbb::global_control> limit_;
};

}  // namespace spadgen::app
