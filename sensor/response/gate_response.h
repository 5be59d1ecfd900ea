// The gate response h(tau) = integral g(t) f_eff(t - tau) dt of a binned transient for every gate position
// of a sweep, with f_eff the two edges of sensor/model/gate.h.
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
#include <vector>

#include "sensor/model/gate.h"

namespace spadgen::sensor {

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
