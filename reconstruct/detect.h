// Reference detectors of object returns in a gate-sweep count profile, and the 2D HDR inversion.
//
// A pixel's counts c_k over N binary frames at gate positions tau_k = start + k * step follow
// c_k ~ Binomial(N, 1 - exp(-lambda_k)), lambda_k the mean avalanches per frame (DESIGN.md). A return
// at time t raises lambda when the gate's end reaches t and lowers it when the gate's start passes t:
//   rising edge at tau:  t = tau + gate_delay + skew + length      (PixelTiming::rise_offset_s)
//   falling edge at tau: t = tau + gate_delay + skew                (PixelTiming::fall_offset_s)
// and its half path c (t - emission_delay) / 2, folded into [0, c T / 2) for the laser period T (a return
// of the pulse before arrives as one of this pulse: a camera of one period cannot tell), gives its range
// (Bistatic: the half path itself when the laser sits at the camera). Both detectors locate an edge at the half point of its
// step in the linearised domain lambda = -ln(1 - c / N) (the paper's eq. 5), where overlapping returns
// add, so a near-saturated profile does not put the edge early. docs/detection.md states each rule.
#pragma once
#include <string>
#include <vector>

namespace spadgen::reconstruct {

// One detected return.
struct Detection {
  double range_m = 0.0;    // camera centre to the return, along the pixel's ray
  double gate = 0.0;       // fractional gate index of the edge (the rising edge when there is one)
  double amplitude = 0.0;  // the step of lambda at the edge: detections per binary frame the return adds
  double score = 0.0;      // the step over its standard error under the binomial noise (z)
};

// c T / 2 for the laser period T: the ranges a camera of one period tells apart.
double ambiguity_range_m(double period_s);

// Where the laser sits against a pixel's ray. A surface at range r along the pixel-centre ray (unit d from
// the camera centre) returns after the path s = |r d - L| + r: from the laser at L (relative to the camera
// centre) to the surface and back to the camera. A return's time gives its half path h = s / 2 =
// c (t - emission_delay) / 2, which is its range only when the laser sits at the camera (L = 0); beside the
// lens, r = (s^2 - |L|^2) / (2 (s - L.d)), exactly (the surface in the air: a medium on the way lengthens s).
struct Bistatic {
  double along_m = 0.0;  // L . d
  double sq_m2 = 0.0;    // |L|^2; 0: the laser at the camera, range = half path
  // The pixel's ray from the camera centre (unit) and the laser's position from it, in one frame.
  static Bistatic of(const double ray[3], const double laser_m[3]);
  bool coaxial() const { return sq_m2 == 0.0; }
  double range_of_half_path(double h) const;  // for any h: below |L| / 2 (no surface can return), continued linearly
  double least_half_path() const;             // |L| / 2: a surface at the camera centre's
  double half_path_of_range(double r) const;  // (r + |r d - L|) / 2, for r >= 0
};

// When a pixel's gate opens and closes relative to the laser trigger, from the acquisition and the
// pixel's gate maps (sensor_maps.exr), and where its laser sits.
struct PixelTiming {
  double start_s = 0.0;        // gate position of k = 0
  double step_s = 0.0;         // gate step
  double rise_offset_s = 0.0;  // gate_delay + skew + length: a rising edge at tau means a return at tau + this
  double fall_offset_s = 0.0;  // gate_delay + skew: a falling edge at tau means a return at tau + this
  double emission_delay_s = 0.0;
  double period_s = 0.0;  // the laser's: a half path folds into one period, all a camera of one period tells; 0: none
  Bistatic bistatic;
  double range_of_rise(double k) const;  // the half path c (t - emission_delay) / 2, unfolded
  double range_of_fall(double k) const;
  double fold(double half_path_m) const;  // into [0, c period / 2)
  // A return's range from its unfolded half path: folded into [|L| / 2, |L| / 2 + c period / 2), then converted
  // through `bistatic`. No surface returns a half path below |L| / 2 (a surface at the camera centre's), so a fold
  // into [0, |L| / 2) is a return one period on (it was reported at a negative range, which evaluate refuses: an
  // object just beyond c period / 2 with the laser beside the lens). With a period (a run's always has one) the
  // range is >= 0; without one, the half path is converted unfolded.
  double range(double half_path_m) const;
};

// The paper's detector (section 4.D and 4.E): the profile smoothed by a moving average over
// 2 * half_width + 1 positions; a virtual window of `window` positions scanned without overlap (and again from
// half a window on: what that finds is kept where the first scan found nothing within half a window, so that an
// edge a few positions inside a window, whose first level then holds part of its step while the window before
// ends below it, is not missed by both); a window
// holds a rising edge when the linearised level of its last `plateau` positions exceeds that of its first
// `plateau` positions by min_score standard errors. The edge is then located on the whole profile (so
// that an edge straddling two windows is timed right): where the smoothed, linearised profile crosses
// the middle of the window's two levels, then, until it settles, where it crosses the middle of the
// levels measured `window / 6` positions either side of the last crossing; the step between those levels
// must hold min_score standard errors too. An edge named by two neighbouring windows counts once.
// The paper gives the moving average, the 60-position window without overlap and the rising edge; the
// average's width, `plateau`, min_score, the offset scan and the locating are spadgen's choices.
struct PaperDetector {
  int window = 60;
  int half_width = 2;
  int plateau = 6;
  double min_score = 5.0;
};

// The team's detector: a multi-scale step statistic on the linearised profile. At a boundary k and scale
// s in `scales`, the mean of lambda over [k, k + s) minus that over [k - s, k), over its standard error
// (the binomial variance p / (N (1 - p)) of each lambda estimate, delta method). Edges are taken
// strongest |z| first while |z| >= min_score: each claims its transition, `separation` positions either
// side, and later edges (and the windows of their statistic) must stay outside every claim, so that the
// foot or shoulder of an edge never passes for an edge of its own. reconstruct sets the separation from
// the run's gate (the slower of rise and fall plus the IRF's FWHM, in gate steps): returns closer than
// that merge, the camera's own limit (5-10 cm, the paper's section 4.E). z > 0: a rising edge, z < 0: a
// falling one. A rise and a fall that give the same return time within match_s are one return (two
// returns that close are not resolved anyway), timed and sized by the mean of the two weighted by z^2
// (an edge's timing variance falls as 1 / z^2); then a rise and a fall left unmatched whose times lie closer
// than `separation` positions are one return too, closest first (two returns that close make one rise and one
// fall; under background light the edges' timing noise exceeds match_s); an edge still unmatched is a return of
// its own (its partner lies outside the sweep or under another return's edge).
struct EdgeDetector {
  std::vector<int> scales{3, 6, 12, 24};
  double min_score = 6.0;
  int separation = 14;
  double match_s = 250e-12;
};

// Returns sorted by range. profile: K values of one pixel, its counts of N = frames binary frames, or with
// `rates` its noise-free rates lambda themselves (--noise-free: linear at any level, where expected counts
// within half a count of N would be clamped there; the noise is still that of counts of N frames).
std::vector<Detection> detect(const PaperDetector& d, const float* profile, int K, int frames, const PixelTiming& timing,
                              bool rates = false);
std::vector<Detection> detect(const EdgeDetector& d, const float* profile, int K, int frames, const PixelTiming& timing,
                              bool rates = false);

// Moving average over 2 h + 1 positions (fewer at the ends).
std::vector<double> moving_average(const std::vector<double>& p, int h);
// lambda = -ln(1 - c / N), c clamped to [0, N - 0.5] (a saturated count gives a large finite lambda).
double linearise(double counts, int frames);

// The 2D HDR inversion (the paper's eq. 5 single, eq. 6 dual with tau_L / tau_S = ratio, N_sat = frames):
// the incident detectable photons per N-frame image, its standard error from the binomial noise of the
// counts propagated through the inverse (delta method), and whether the counts were saturated (at or
// above N - 0.5: the estimate is then that of N - 0.5 counts, flagged rather than clamped silently).
struct HdrEstimate {
  double photons = 0.0;
  double standard_error = 0.0;
  bool saturated = false;
};
// counts: the image's summed counts (both exposures in dual mode).
HdrEstimate invert_hdr(double counts, int frames, bool dual, double ratio);
// The same from the noise-free rates (detections per frame of each exposure, lambda_k, K = 1 or 2): the
// photons exactly, N times their mean (linear at any level: not clamped at saturation, which it flags
// where the expected counts reach N - 0.5), with the standard error sampled counts would give.
HdrEstimate hdr_of_rates(const float* lambda, int frames, bool dual, double ratio);

}  // namespace spadgen::reconstruct
