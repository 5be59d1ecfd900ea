// Checks of what the scene file's keys imply together once the sensor has worked them out (the time
// axis, every pixel's gate), made before anything is rendered or written, so that a run that cannot
// produce meaningful data stops with the keys that drive it instead of producing NaN, negative gate
// lengths, or bins beyond what a tile can hold. `spadgen info` makes the same checks.
#pragma once
#include <map>
#include <string>

#include "core/config.h"
#include "core/tile.h"
#include "core/time_axis.h"
#include "sensor/sensor.h"

namespace spadgen::app {

// Periods of the laser one time window may span; every deposit of light visits each of them.
inline constexpr double kMaxWindowPeriods = 1e6;

// Throws spadgen::Error, naming the keys, when the time axis has more than scenes::kMaxTimeBins bins or
// spans more than kMaxWindowPeriods laser periods, or when a pixel of `img` would have a gate of zero or
// negative length (a gate length spread that is large against the gate length). set_keys: the keys `--set`
// gave (scenes::ResolvedRun::set_keys); a message names such a key's override ("--set render.time_bin_ps: ..."),
// not the scene file.
void check_derived(const RunConfig& c, const sensor::SensorModel& sensor, const PixelRect& img, const TimeAxis& axis,
                   const std::map<std::string, std::string>& set_keys);

}  // namespace spadgen::app
