// The gate: its time profile f(t), the instrument response it is convolved with, and the gate response
// h(tau) = integral g(t) f_eff(t - tau) dt of a binned transient for every gate position of a sweep.
//
// Representation. f_eff = f convolved with the instrument response is written as the difference of two
// edges, f_eff(t) = rise(t - s) - fall(t - s - dL), where s is the pixel's gate skew, dL its gate length
// minus the nominal length, and both edges are piecewise-linear functions that are 0 before their first
// knot and `v_end` after their last. For a piecewise-linear gate (linear edges or a measured table) with no
// instrument response the knots are exact; otherwise the edges are tabulated on a fine grid (about 0.4 ps,
// a direct discrete convolution) and `knots_per_edge` knots are placed where the curvature is, and the
// largest difference between the knots' interpolation and the fine grid is recorded in max_knot_error.
//
// Response. With G1 the running integral of the binned transient g and G2 the running integral of G1,
// an edge E(t) = sum_j c_j (t - u_j)_+ with final slope 0 contributes sum_j c_j G2(tau + u_j) (plus a
// constant that cancels between the two edges). G2 is piecewise quadratic over non-empty bins and linear
// over empty stretches, so knots that fall in an empty stretch are summed in O(1) with prefix sums over the
// knots; only knots inside non-empty bins are evaluated one by one. The cost per pixel is
// O(T + K * runs + knot passes through occupied bins), at most O(T + K * M).
//
// Integer step (accumulate_edge_response_int, the sweep's usual case). With Q(y) = 0 (y <= 0), y^2 / 2
// (0 < y < 1), y - 1/2 (y >= 1), G2(x) = sum_i g_i Q(x - i), so the edge contributes
// sum_i g_i W(b - i) with W(y) = sum_j c_j Q(y + u_j): 0 for y + u_M <= 0, cu = sum_j c_j u_j once every
// y + u_j >= 1, varying only over a window of about u_M - u_0 + 2 bins. When the step is a whole number
// s of bins, b_k - i = f + d with f = b_0 - floor(b_0) fixed for the pixel and d an integer: W is
// tabulated once per pixel and edge at y = f + d over the window (a quadratic in f per entry, tabulated per
// edge, plus a correction at two entries for each knot with frac(u_j) + f >= 1, or the reverse from a
// table with every correction when most knots are past that point), every non-zero bin adds g_i W to the
// gates whose window holds it (about (u_M - u_0) / s of them, contiguous per phase of d mod s; only the
// phases in use are evaluated) and g_i cu to every later gate. Cost per pixel and edge
// O(T / 32 + window + M + nnz * window / s + K); no running integrals. Equal to the general algorithm to
// rounding (both compute the same sum exactly in real arithmetic).
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
  double max_knot_error = 0.0;    // max |knots - fine grid| over both edges, in units of the plateau
  double irf_fwhm_s = 0.0;        // FWHM of the instrument response (0: none)
  Sampled rise_fine, fall_fine;   // the fine reference of each edge (empty when exact)

  double value(double t, double dL) const { return rise.value(t) - fall.value(t - dL); }
  double open_time(double dL) const { return open_time_s + plateau * dL; }
  double support_begin() const { return rise.u.front(); }
  double support_end(double dL) const { return fall.u.back() + dL; }
};

// Builds the effective gate (profile convolved with laser pulse and SPAD jitter). Reads
// gate.profile_csv and laser.pulse_shape_csv when given; throws spadgen::Error on bad tables.
GateShape build_gate_shape(const GateConfig& gate, const LaserConfig& laser, int knots_per_edge);

// The instrument response as weights on a grid of spacing dx (sum 1): a photon the renderer places at t is
// detected at t + u with probability weight at u. Empty y: a delta (no pulse width, no jitter).
Sampled build_irf(const GateConfig& gate, const LaserConfig& laser, double dx);

// An edge in the units of a transient's time axis: knot positions in bins, slope changes per bin, and
// prefix sums C0[j] = sum_{i<j} c_i, C1[j] = sum_{i<j} c_i u_i.
struct EdgeBins {
  std::vector<double> u, c, C0, C1;
  // For the integer-step path: W(f + d) (see the header comment) for f in [0, 1) and d in [d_lo, d_lo + L)
  // is wa[t] + f (wb[t] + f wc[t]) at t = d - d_lo, the value for f below every frac(-u_j), corrected for
  // each knot with r_j + f >= 1 (r_j = u_j - floor(u_j)): -c_j w^2 / 2 at t_j and +c_j w^2 / 2 at t_j - 1,
  // w = r_j + f - 1, t_j the entry of d = -floor(u_j). Those knots come first in xr (r_j descending), xc
  // (c_j), xt (t_j). W is 0 below the window and C1[M] above it.
  int64_t d_lo = 0, L = 0;
  std::vector<double> wa, wb, wc, xr, xc;
  std::vector<int64_t> xt;
  uint64_t id = 0;  // distinct for every edge_in_bins() result (keys TransientPrefix's per-step copies)
};
EdgeBins edge_in_bins(const Edge& e, double bin_width_s);

// The running integrals of one pixel's transient, kept only over runs of non-empty bins.
class TransientPrefix {
 public:
  // g: photons per bin, T bins. Returns false (and keeps nothing) when every bin is zero.
  bool build(const float* g, int64_t T);
  // For the integer-step path: only the non-zero bins (index, content), ascending; no running integrals
  // (runs() is left empty). Returns false when every bin is zero.
  bool build_bins(const float* g, int64_t T);
  // The same when every non-zero bin lies in [lo, hi) (0 <= lo, hi <= the transient's length): only those
  // bins are read.
  bool build_bins(const float* g, int64_t lo, int64_t hi);
  double total() const { return total_; }
  const std::vector<int64_t>& bin_index() const { return nz_i_; }
  const std::vector<double>& bin_value() const { return nz_v_; }
  // Scratch for accumulate_edge_response_int: W of one edge, and per edge and step the tables wa, wb, wc
  // split by phase (entry t at pos[t] = (t mod s) a + min(t mod s, b) + t / s, L = a s + b), so that each
  // phase is contiguous; a1, b1, c1 the same with every knot's correction (r_j > 0: the first `crossing`
  // knots of xr) included as a polynomial in f, so that a pixel corrects whichever set of knots is smaller.
  // Built on first use for an edge's id and step; two edges are kept.
  struct StepTables {
    uint64_t id = 0;
    int64_t s = 0;
    std::vector<double> a, b, c, a1, b1, c1;
    std::vector<int64_t> pos;
    size_t crossing = 0;
  };
  const StepTables& step_tables(const EdgeBins& e, int64_t s);
  std::vector<double>& scratch() { return work_; }

  struct Run {
    int64_t s = 0, e = 0;  // bins [s, e)
    size_t off = 0;        // index of bin s in g_, G1_, G2_
    double G1e = 0, G2e = 0;  // G1 and G2 at the run's end edge
  };
  const std::vector<Run>& runs() const { return runs_; }
  // G2 at a point a (in bins) that lies inside run r.
  double G2_in_run(const Run& r, double a) const;

 private:
  std::vector<Run> runs_;
  std::vector<double> g_, G1_, G2_;  // per bin of every run: content, and G1, G2 at the bin's start edge
  std::vector<int64_t> nz_i_;        // build_bins: the non-zero bins and their contents
  std::vector<double> nz_v_;
  std::vector<double> work_;
  StepTables step_[2];
  int step_next_ = 0;
  double total_ = 0.0;
};

// out[k] += sign * sum_j c_j G2(b0 + k * step + u_j) for k = 0 .. K-1 (b0, step in bins).
void accumulate_edge_response(const TransientPrefix& p, const EdgeBins& e, double b0, double step, int K,
                              double sign, double* out);

// The step as a whole number of bins when it is one (to 1e-14 relative: the positions then differ from
// b0 + step * k by less than K * 1e-14 * step bins), else 0.
int64_t integer_step(double step);

// The same sum for an integer step s >= 1 (bins), from build_bins(); the result equals
// accumulate_edge_response's to rounding.
void accumulate_edge_response_int(TransientPrefix& p, const EdgeBins& e, double b0, int64_t s, int K, double sign,
                                  double* out);

}  // namespace spadgen::sensor
