// The time axis of a transient: explicit start, bin width and bin count (as mitransient's film),
// plus the laser period used to fold late returns into the next period.
#pragma once
#include <cmath>
#include <cstdint>

namespace spadgen {

struct TimeAxis {
  double start_s = 0.0;      // left edge of bin 0, seconds after the laser trigger
  double bin_width_s = 0.0;  // width of every bin, seconds
  int64_t bins = 0;          // 0: no transient is kept (time-integrated quantities only)
  double period_s = 0.0;     // laser repetition period; 0 disables folding

  double end_s() const { return start_s + static_cast<double>(bins) * bin_width_s; }
  double bin_start_s(int64_t i) const { return start_s + static_cast<double>(i) * bin_width_s; }
  double bin_centre_s(int64_t i) const { return start_s + (static_cast<double>(i) + 0.5) * bin_width_s; }

  // Bin i covers the half-open interval [start + i w, start + (i + 1) w): a time exactly on an edge
  // belongs to the later bin. Returns -1 for a time outside [start, end).
  int64_t bin_of(double t_s) const {
    if (bins <= 0 || !(t_s >= start_s)) return -1;
    const double x = (t_s - start_s) / bin_width_s;
    auto i = static_cast<int64_t>(std::floor(x));
    // Guard the division's rounding so the edge rule holds exactly at bin_start_s(i).
    if (i < bins && t_s < bin_start_s(i)) --i;
    if (i + 1 <= bins && t_s >= bin_start_s(i + 1)) ++i;
    return (i >= 0 && i < bins) ? i : -1;
  }
};

}  // namespace spadgen
