#include "app/run_parts.h"

#if defined(__SSE__)
#include <xmmintrin.h>
#endif

#include <algorithm>
#include <cmath>

#include "app/pipeline.h"
#include "core/error.h"
#include "scenes/scene_file.h"
#include "writers/writers.h"

namespace spadgen::app {

PixelRect image_rect(const RunConfig& c) {
  return c.camera.crop.value_or(PixelRect{0, 0, c.camera.width_px, c.camera.height_px});
}

TimeAxis time_axis(const RunConfig& c, const sensor::SensorModel& s) {
  TimeAxis a = s.required_window(c.render.time_bin_s);
  // (a window set where none is used rendered transients no output held: scenes::time_window_used)
  if (c.render.window_start_s && scenes::time_window_used(c)) {
    a.start_s = *c.render.window_start_s;
    a.bins = static_cast<int64_t>(std::ceil((*c.render.window_stop_s - a.start_s) / a.bin_width_s - 1e-9));
    return a;
  }
  if (a.bins == 0 && c.outputs.transient)
    // (a KeyError: run and info name it as given, the --set or the scene file's pointer; it named the file for a --set)
    throw KeyError("/outputs/transient", "found true in the intensity mode, which needs no time bins; set /render/window_start_ns "
                                         "and /render/window_stop_ns to say which window transient.npy should cover");
  return a;
}

SensorTables SensorTables::hashed(const RunConfig& c) {
  SensorTables t;
  t.hash = scenes::sensor_tables_hash(c, &t.tables);
  return t;
}

void SensorTables::check_unchanged(const RunConfig& c) const {
  const SensorTables now = hashed(c);
  if (now.hash == hash) return;
  std::string which;
  for (size_t i = 0; i < now.tables.size() && i < tables.size(); ++i)
    if (now.tables[i].hash != tables[i].hash) which += (which.empty() ? "" : ", ") + now.tables[i].key + " (" + now.tables[i].path + ")";
  throw Error(c.scene_file + ": " + (which.empty() ? std::string("a sensor table") : which) +
              " changed while the sensor read it; run again once it is written");
}

void SensorTables::check_expected(const RunConfig& c, const std::optional<std::string>& expected) const {
  if (!expected || *expected == hash) return;
  throw Error(c.scene_file + ": a sensor table it names (laser.pulse_shape_csv, sensor.gate.profile_csv, sensor.gate.maps_exr, a "
              "pdp_csv) changed since the dataset resolved this sample (the tables' hash " + *expected + " then, " + hash +
              " as the sensor read them): the sample is not generated from other tables than its hash holds; run the "
              "dataset again once they are as wanted");
}

void apply_user_maps(sensor::SensorModel& sensor, const RunConfig& c) {
  if (c.sensor.gate.maps_exr.empty()) return;
  // (a file that is no EXR was named without its key or scene file: an adversarial tester's find)
  const writers::ExrData maps = [&] {
    try {
      return writers::read_exr(c.sensor.gate.maps_exr);
    } catch (const Error& e) {
      throw Error(c.scene_file + ": sensor.gate.maps_exr: " + e.what() + "; expected an OpenEXR file of the gate's maps " +
                  "(gate_skew_ps and gate_length_ps channels over the whole sensor, as a run's sensor_maps.exr holds them)");
    }
  }();
  if (!maps.partial_window.empty())
    throw Error(c.sensor.gate.maps_exr + " (sensor.gate.maps_exr): its " + maps.partial_window +
                "; expected the whole sensor's pixels (a data window equal to the display window)");
  sensor.set_maps(maps.width, maps.height, maps.channels, c.sensor.gate.maps_exr);
}

void order_files(std::vector<std::string>& files) {
  std::sort(files.begin(), files.end(), [](const std::string& a, const std::string& b) {
    const bool ma = a == "metadata.json", mb = b == "metadata.json";
    return ma != mb ? mb : a < b;
  });
}

nlohmann::json file_bytes(const std::filesystem::path& dir, const std::vector<std::string>& files) {
  nlohmann::json bytes = nlohmann::json::object();
  for (const std::string& f : files)
    if (f != "metadata.json") bytes[f] = writers::bytes_on_disk((dir / f).string());
  return bytes;
}

void flush_denormals() {
#if defined(__SSE__)
  _mm_setcsr(_mm_getcsr() | 0x8040u);  // FTZ (bit 15) and DAZ (bit 6)
#endif
}

ThreadLimit::ThreadLimit(int threads) {
  // Before TBB starts (main() did it first): TBB's tasks run with the floating-point settings of the thread
  // that started it.
  flush_denormals();
  if (threads < 0 || threads > kMaxThreads)
    throw Error("--threads: expected 0 (every core) to " + std::to_string(kMaxThreads) + ", found " + std::to_string(threads));
  if (threads > 0) limit_ = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, size_t(threads));
  writers::set_exr_threads(int(tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism)));
}

ThreadLimit::~ThreadLimit() { writers::set_exr_threads(0); }

}  // namespace spadgen::app
