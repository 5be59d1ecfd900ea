#include "app/preflight.h"

#include <cmath>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/units.h"
#include "scenes/scene_file.h"
#include "sensor/acquisition/acquisition.h"
#include "sensor/model/pixel_maps.h"

namespace spadgen::app {
namespace {

std::string g(double v) {
  std::ostringstream o;
  o << v;
  return o.str();
}

// The keys a derived time window depends on, for messages.
// A table replaces the keys of what it tabulates (a pulse table's span was blamed on laser.pulse_fwhm_ps).
std::string window_keys(const RunConfig& c) {
  if (c.render.window_start_s) return "render.window_start_ns and render.window_stop_ns";
  const bool gate_table = !c.sensor.gate.profile_csv.empty(), pulse_table = !c.laser.pulse_shape_csv.empty();
  return std::string("the gate sweep (acquisition.gate_sweep.start_ns, stop_ns), the gate (") +
         (gate_table ? "its table sensor.gate.profile_csv, " : "sensor.gate.length_ns, rise_ps, fall_ps, ") +
         "delay_ns, skew_fwhm_ps, length_fwhm_ps) and the instrument response (" +
         (pulse_table ? "the pulse's table laser.pulse_shape_csv" : "laser.pulse_fwhm_ps") + ", sensor.jitter_fwhm_ps)";
}

}  // namespace

void check_derived(const RunConfig& c, const sensor::SensorModel& sensor, const PixelRect& img, const TimeAxis& axis,
                   const std::map<std::string, std::string>& set_keys) {
  const std::string file = c.scene_file.empty() ? std::string("<scene>") : c.scene_file;
  // How a message starts: the first of the keys that drive it that `--set` gave ("--set KEY: "), else the
  // scene file and the first key's pointer.
  const auto where = [&](const std::vector<const char*>& pointers) {
    for (const char* p : pointers)
      if (const auto it = set_keys.find(p); it != set_keys.end()) return "--set " + it->second + ": ";
    return file + ": " + pointers.front() + ": ";
  };
  // The keys that set the time window (the window's ends, else the sweep, the gate and the IRF)
  // (the tables first when set: their span is what makes the window)
  std::vector<const char*> window = {"/render/window_stop_ns", "/render/window_start_ns"};
  if (!c.laser.pulse_shape_csv.empty()) window.push_back("/laser/pulse_shape_csv");
  if (!c.sensor.gate.profile_csv.empty()) window.push_back("/sensor/gate/profile_csv");
  for (const char* k : {"/acquisition/gate_sweep/start_ns", "/acquisition/gate_sweep/stop_ns"}) window.push_back(k);
  if (c.sensor.gate.profile_csv.empty())
    for (const char* k : {"/sensor/gate/length_ns", "/sensor/gate/rise_ps", "/sensor/gate/fall_ps"}) window.push_back(k);
  for (const char* k : {"/sensor/gate/delay_ns", "/sensor/gate/skew_fwhm_ps", "/sensor/gate/length_fwhm_ps"}) window.push_back(k);
  if (c.laser.pulse_shape_csv.empty()) window.push_back("/laser/pulse_fwhm_ps");
  window.push_back("/sensor/jitter_fwhm_ps");
  std::vector<const char*> bins_keys = {"/render/time_bin_ps"}, periods_keys = {"/laser/repetition_rate_MHz"};
  bins_keys.insert(bins_keys.end(), window.begin(), window.end());
  periods_keys.insert(periods_keys.end(), window.begin(), window.end());
  const double span = static_cast<double>(axis.bins) * axis.bin_width_s;
  if (axis.bins < 0 || axis.bins > scenes::kMaxTimeBins || !std::isfinite(span))
    throw Error(where(bins_keys) + "the time window that " + window_keys(c) + " set, " +
                (std::isfinite(axis.start_s) ? "from " + g(axis.start_s / kNs) + " ns on, " : "without a finite start, ") +
                "needs " + (axis.bins < 0 ? std::string("more than 2^63") : g(double(axis.bins))) + " bins of " +
                g(axis.bin_width_s / kPs) + " ps; expected at most " + std::to_string(scenes::kMaxTimeBins) +
                " bins: wider bins (render.time_bin_ps) or a shorter window");
  if (axis.bins > 0 && axis.period_s > 0 && span / axis.period_s > kMaxWindowPeriods)
    throw Error(where(periods_keys) + "the time window of " + g(span / kNs) + " ns spans " + g(span / axis.period_s) +
                " laser periods of " + g(axis.period_s / kPs) + " ps; expected at most " + g(kMaxWindowPeriods) + " (a lower repetition rate or a shorter window: " + window_keys(c) + ")");

  // A gate cannot be open for a negative time: with a length spread large against the gate length, the
  // Gaussian model of the spread stops being physical. Refused rather than clamped, so that the maps in
  // sensor_maps.exr are the ones the counts were computed with.
  // (In the intensity mode the gate does not shape the counts, but sensor_maps.exr still shows it.)
  if (!c.sensor.skew) return;
  const double nominal = sensor.acquisition().nominal_gate_length_s();
  // The generated deviations stay within a few FWHM of the nominal length (5 sigma of the random part plus
  // the smooth pattern's extremes): far inside that, no pixel needs looking at. Measured maps
  // (sensor.gate.maps_exr) are checked for positive lengths where they are read.
  if (!c.sensor.gate.maps_exr.empty() || nominal > 10.0 * c.sensor.gate.length_fwhm_s) return;
  for (int y = img.y0; y < img.y1(); ++y)
    for (int x = img.x0; x < img.x1(); ++x) {
      const double length = nominal + sensor.pixel(x, y).dL_s;
      if (length > 0.0) continue;
      throw Error(where({"/sensor/gate/length_fwhm_ps", "/sensor/gate/length_ns"}) + "a spread of " + g(c.sensor.gate.length_fwhm_s / kPs) +
                  " ps (FWHM) about a gate of " + g(nominal / kNs) +
                  " ns (sensor.gate.length_ns, or the gate profile's) gives pixel (" + std::to_string(x) + ", " +
                  std::to_string(y) + ") a gate " + g(length / kPs) +
                  " ps long; expected every gate length > 0: a spread below about half the gate length");
    }
}

}  // namespace spadgen::app
