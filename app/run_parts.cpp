#include "app/run_parts.h"

#include <tbb/task_scheduler_observer.h>
#if defined(__SSE__)
#include <xmmintrin.h>
#endif

#include <algorithm>
#include <cmath>

#include "app/pipeline.h"
#include "core/error.h"
#include "writers/writers.h"

namespace spadgen::app {

PixelRect image_rect(const RunConfig& c) {
  return c.camera.crop.value_or(PixelRect{0, 0, c.camera.width_px, c.camera.height_px});
}

TimeAxis time_axis(const RunConfig& c, const sensor::SensorModel& s) {
  TimeAxis a = s.required_window(c.render.time_bin_s);
  if (c.render.window_start_s) {
    a.start_s = *c.render.window_start_s;
    a.bins = static_cast<int64_t>(std::ceil((*c.render.window_stop_s - a.start_s) / a.bin_width_s - 1e-9));
    return a;
  }
  if (a.bins == 0 && c.outputs.transient)
    throw Error(c.scene_file + ": /outputs/transient: intensity mode needs no time bins; set /render/window_start_ns "
                "and /render/window_stop_ns to say which window transient.npy should cover");
  return a;
}

void apply_user_maps(sensor::SensorModel& sensor, const RunConfig& c) {
  if (c.sensor.gate.maps_exr.empty()) return;
  const writers::ExrData maps = writers::read_exr(c.sensor.gate.maps_exr);
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

namespace {
// Denormal floats flushed to zero and read as zero (FTZ and DAZ in MXCSR) on the calling thread.
void flush_denormals() {
#if defined(__SSE__)
  _mm_setcsr(_mm_getcsr() | 0x8040u);
#endif
}
// ... and on every TBB thread that works for the process.
class FlushDenormals : public tbb::task_scheduler_observer {
 public:
  FlushDenormals() { observe(true); }
  void on_scheduler_entry(bool) override { flush_denormals(); }
};
}  // namespace

ThreadLimit::ThreadLimit(int threads) {
  // Every command's floats flush denormals, as Embree sets its threads for the renderer: a sense (which
  // creates no Embree device) kept rates of 1e-40 that the run's sensor stage had flushed to 0.
  // The calling thread first: TBB's task contexts take the floating-point settings of the thread that
  // starts TBB (the observer's first use does), and apply them to every task they run.
  flush_denormals();
  static FlushDenormals flush;
  if (threads < 0 || threads > kMaxThreads)
    throw Error("--threads: expected 0 (every core) to " + std::to_string(kMaxThreads) + ", found " + std::to_string(threads));
  if (threads > 0) limit_ = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, size_t(threads));
  writers::set_exr_threads(int(tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism)));
}

ThreadLimit::~ThreadLimit() { writers::set_exr_threads(0); }

}  // namespace spadgen::app
