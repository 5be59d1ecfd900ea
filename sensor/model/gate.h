// The gate: its time profile f(t) and the instrument response (laser pulse, SPAD jitter) it is convolved
// with, as two piecewise-linear edges. The gate response engine (sensor/response/gate_response.h) turns
// them into h(tau) for every gate position of a sweep.
//
// Representation. f_eff = f convolved with the instrument response is written as the difference of two
// edges, f_eff(t) = rise(t - s) - fall(t - s - dL), where s is the pixel's gate skew, dL its gate length
// minus the nominal length, and both edges are piecewise-linear functions that are 0 before their first
// knot and `v_end` after their last. For a piecewise-linear gate (linear edges or a measured table) with no
// instrument response the knots are exact; otherwise the edges are tabulated on a fine grid (step
// gate.grid_s, 0.25 ps by default; a direct discrete convolution) and gate.knots_per_edge knots are placed where the curvature is, and the
// largest difference between the knots' interpolation and the fine grid is recorded in max_knot_error.
//
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "core/config.h"

namespace spadgen::sensor {

// A piecewise-linear function of time: 0 before u.front(), v_end after u.back(), linear between knots.
struct Edge {
  std::vector<double> u;  // knot times, seconds, relative to the gate opening of a pixel with no skew
  std::vector<double> y;  // values at the knots (y.front() = 0, y.back() = v_end)
  double v_end = 1.0;
  double value(double t) const;
  double integral() const;  // over [u.front(), u.back()]
};

// A function sampled on a uniform grid x0 + i * dx.
struct Sampled {
  double x0 = 0.0, dx = 0.0;
  std::vector<double> y;
  double at(double x) const;  // linear interpolation; 0 outside
};

struct GateShape {
  Edge rise, fall;  // f_eff(t) = rise(t - s) - fall(t - s - dL)
  double nominal_length_s = 0.0;  // 50 %-50 % length of the parametric gate or of the measured table
  double plateau = 1.0;           // the open-gate response (1, or the table's value at its middle)
  double open_time_s = 0.0;       // integral of f over time for dL = 0 (the effective gate length)
  int knots_per_edge = 0;         // knots actually used, per edge
  bool exact = false;             // the knots are the exact response (piecewise-linear gate, no IRF)
  double max_knot_error = 0.0;    // max |knots - fine grid| over both edges, of the open gate (its peak, 1)
  double rise_s = 0.0, fall_s = 0.0;  // 10-90 % and 90-10 % times: the parametric gate's, or the table's edges'
                                      // (their first and last crossings of 10 and 90 % of its peak)
  double grid_s = 0.0;            // the fine grid's step (gate.grid_s, or coarser for a long span)
  // The fine grid's own error against the exact effective gate, estimated as the linear interpolation's
  // error between its points, max |y[i-1] - 2 y[i] + y[i+1]| / 8 over both edges, of the open gate (1)
  // (0 when exact). Measured within 1 % of the closed form's error from 0.25 to 40 ps (gate_test).
  double max_grid_error = 0.0;
  double irf_fwhm_s = 0.0;        // FWHM of the instrument response (0: none)
  Sampled rise_fine, fall_fine;   // the fine reference of each edge (empty when exact)

  double value(double t, double dL) const { return rise.value(t) - fall.value(t - dL); }
  double open_time(double dL) const { return open_time_s + plateau * dL; }
  double support_begin() const { return rise.u.front(); }
  double support_end(double dL) const { return fall.u.back() + dL; }
};

// Builds the effective gate (profile convolved with laser pulse and SPAD jitter), with gate.knots_per_edge
// knots per tabulated edge on a fine grid of step gate.grid_s. Reads
// gate.profile_csv and laser.pulse_shape_csv when given; throws spadgen::Error on bad tables.
GateShape build_gate_shape(const GateConfig& gate, const LaserConfig& laser);

// The instrument response as weights on a grid of spacing dx (sum 1): a photon the renderer places at t is
// detected at t + u with probability weight at u. Empty y: a delta (no pulse width, no jitter).
Sampled build_irf(const GateConfig& gate, const LaserConfig& laser, double dx);

}  // namespace spadgen::sensor
