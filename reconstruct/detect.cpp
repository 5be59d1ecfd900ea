#include "detect.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <tuple>
#include <vector>

#include "core/units.h"
#include "sensor/sensor.h"

namespace spadgen::reconstruct {
namespace {

// The binomial variance of one count, from a smoothed estimate of its p (a raw count of 0 or N would
// claim no noise at all): N p (1 - p), p kept half a count inside (0, 1).
double count_variance(double smoothed_counts, int frames) {
  const double N = frames;
  const double p = std::clamp(smoothed_counts / N, 0.5 / N, 1.0 - 0.5 / N);
  return N * p * (1.0 - p);
}

// A pixel's counts: the profile itself, or the expected counts N (1 - exp(-lambda)) of its rates (for the
// noise model only: the rates are linearised already).
std::vector<double> counts_of(const float* profile, int K, int frames, bool rates) {
  std::vector<double> c(profile, profile + K);
  if (rates)
    for (double& v : c) v = frames * -std::expm1(-v);
  return c;
}

// d lambda / d c at a count level (lambda = -ln(1 - c / N)).
double lambda_slope(double counts, int frames) {
  const double N = frames;
  return 1.0 / (N - std::min(counts, N - 0.5));
}

// Fractional index in [lo, hi) where v first crosses `level` in the direction `up`, nearest to `near`.
double crossing(const std::vector<double>& v, int lo, int hi, double level, bool up, double near) {
  lo = std::max(lo, 1);
  hi = std::min(hi, int(v.size()));
  double best = std::nan(""), best_d = 1e300;
  for (int k = lo; k < hi; ++k) {
    const double a = v[size_t(k - 1)], b = v[size_t(k)];
    const bool crosses = up ? (a < level && b >= level) : (a > level && b <= level);
    if (!crosses) continue;
    const double x = double(k - 1) + (level - a) / (b - a);
    if (std::abs(x - near) < best_d) best = x, best_d = std::abs(x - near);
  }
  return best;
}

// The detections' half paths folded by the laser period (edges are paired unfolded: a rise and its fall
// may straddle a period's end) and turned into ranges, in increasing range. A sweep longer than the period sees
// each return once per period: detections from different periods (unfolded half paths half a period or more
// apart) whose folded half paths lie closer than the detector resolves (`resolved` gate positions) are one
// return, reported once, by the detection of the highest score (each copy was a false detection: a sweep of
// 12.6 ns at 100 MHz scored the multi-object scene's precision 71 %; an auditor's find).
std::vector<Detection> folded(std::vector<Detection> out, const PixelTiming& timing, double resolved) {
  if (timing.period_s > 0.0 && out.size() > 1) {
    const double ambiguity = ambiguity_range_m(timing.period_s), near = resolved * std::abs(timing.step_s) * kSpeedOfLight / 2.0;
    std::vector<size_t> order(out.size());
    for (size_t i = 0; i < order.size(); ++i) order[i] = i;
    std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return out[a].score > out[b].score; });
    std::vector<Detection> kept;
    for (const size_t i : order) {
      const bool copy = std::any_of(kept.begin(), kept.end(), [&](const Detection& k) {
        const double dh = out[i].range_m - k.range_m;  // (unfolded half paths)
        return std::abs(dh) >= 0.5 * ambiguity && std::abs(std::remainder(dh, ambiguity)) < near;
      });
      if (!copy) kept.push_back(out[i]);
    }
    out = std::move(kept);
  }
  for (Detection& d : out) d.range_m = timing.range(d.range_m);
  std::stable_sort(out.begin(), out.end(), [](const Detection& a, const Detection& b) { return a.range_m < b.range_m; });
  return out;
}

}  // namespace

Bistatic Bistatic::of(const double ray[3], const double laser_m[3]) {
  return {ray[0] * laser_m[0] + ray[1] * laser_m[1] + ray[2] * laser_m[2],
          laser_m[0] * laser_m[0] + laser_m[1] * laser_m[1] + laser_m[2] * laser_m[2]};
}

double Bistatic::range_of_half_path(double h) const {
  if (coaxial()) return h;
  const double s = 2.0 * h, baseline = std::sqrt(sq_m2);
  if (!(s > baseline)) return 0.5 * (s - baseline);  // r(|L|) = 0, where the formula's r starts
  // (s^2 - |L|^2) / (2 (s - L.d)), written so that it stays finite as the ray points at the laser (L.d -> |L|)
  return 0.5 * (s + along_m) + 0.5 * (along_m * along_m - sq_m2) / (s - along_m);
}

double Bistatic::least_half_path() const { return 0.5 * std::sqrt(sq_m2); }

double Bistatic::half_path_of_range(double r) const {
  if (coaxial()) return r;
  return 0.5 * (r + std::sqrt(std::max(0.0, r * r - 2.0 * r * along_m + sq_m2)));
}

double PixelTiming::range_of_rise(double k) const {
  return (start_s + k * step_s + rise_offset_s - emission_delay_s) * kSpeedOfLight / 2.0;
}
double PixelTiming::range_of_fall(double k) const {
  return (start_s + k * step_s + fall_offset_s - emission_delay_s) * kSpeedOfLight / 2.0;
}

double ambiguity_range_m(double period_s) { return period_s * kSpeedOfLight / 2.0; }

double PixelTiming::fold(double half_path_m) const {
  if (!(period_s > 0.0)) return half_path_m;
  const double ambiguity = ambiguity_range_m(period_s);
  double r = std::fmod(half_path_m, ambiguity);
  if (r < 0.0) r += ambiguity;
  return r < ambiguity ? r : 0.0;  // -1e-300 + ambiguity rounds to it
}

double PixelTiming::range(double half_path_m) const {
  double h = fold(half_path_m);
  const double least = bistatic.least_half_path();
  if (period_s > 0.0 && h < least) {  // the return one or more periods on (|L| may exceed c period / 2)
    const double ambiguity = ambiguity_range_m(period_s);
    h += ambiguity * std::ceil((least - h) / ambiguity);
  }
  return bistatic.range_of_half_path(h);
}

std::vector<double> moving_average(const std::vector<double>& p, int h) {
  std::vector<double> s(p.size());
  const auto n = int64_t(p.size());
  for (int64_t k = 0; k < n; ++k) {
    double sum = 0.0;
    int count = 0;
    for (int64_t j = std::max<int64_t>(0, k - h); j <= std::min<int64_t>(n - 1, k + h); ++j) sum += p[size_t(j)], ++count;
    s[size_t(k)] = sum / count;
  }
  return s;
}

double linearise(double counts, int frames) {
  const double N = frames;
  return -std::log1p(-std::clamp(counts, 0.0, N - 0.5) / N);
}

std::vector<Detection> detect(const PaperDetector& d, const float* profile, int K, int frames, const PixelTiming& timing,
                              bool rates) {
  const std::vector<double> c = counts_of(profile, K, frames, rates);
  const std::vector<double> s = moving_average(c, d.half_width);
  // linearised after the smoothing, as the paper does; the rates, linear already, smoothed as they are
  std::vector<double> lam(static_cast<size_t>(K));
  if (rates)
    lam = moving_average(std::vector<double>(profile, profile + K), d.half_width);
  else
    for (int k = 0; k < K; ++k) lam[size_t(k)] = linearise(s[size_t(k)], frames);
  // The variance of the mean linearised level over smoothed positions [a, b): by the delta method, each raw
  // count j enters with the weight sum over k of (1 / (b - a)) (1 / n_k) dlambda/dc(s_k), n_k the positions
  // averaged at k.
  // Only counts [a - half_width, b + half_width) enter, so the weights cover just that span.
  std::vector<double> w;
  const auto level = [&](int a, int b, double* variance) {
    const int lo = std::max(0, a - d.half_width), hi = std::min(K, b + d.half_width);
    w.assign(size_t(hi - lo), 0.0);
    double mean = 0.0;
    for (int k = a; k < b; ++k) {
      mean += lam[size_t(k)] / (b - a);
      const int j0 = std::max(0, k - d.half_width), j1 = std::min(K - 1, k + d.half_width);
      const double g = lambda_slope(s[size_t(k)], frames) / (b - a) / (j1 - j0 + 1);
      for (int j = j0; j <= j1; ++j) w[size_t(j - lo)] += g;
    }
    *variance = 0.0;
    for (int j = lo; j < hi; ++j)
      if (w[size_t(j - lo)] != 0.0) *variance += w[size_t(j - lo)] * w[size_t(j - lo)] * count_variance(s[size_t(j)], frames);
    return mean;
  };
  // Each window that holds a significant rise names an edge; the edge itself is located on the whole
  // profile (below), so that one straddling two windows is timed right. The windows from `from` on.
  const int guard = d.window / 6;
  const auto scan = [&](int from) {
    std::vector<Detection> found;
    for (int a = from; a < K; a += d.window) {
      const int b = std::min(K, a + d.window);
      if (b - a < 2 * d.plateau + 2) break;  // a last partial window too short to hold two levels
      double var_lo = 0.0, var_hi = 0.0;
      double lo = level(a, a + d.plateau, &var_lo), hi = level(b - d.plateau, b, &var_hi);
      double se = std::sqrt(var_lo + var_hi);
      const double z = se > 0.0 ? (hi - lo) / se : 0.0;
      if (!(z >= d.min_score)) continue;
      // The edge's centre: where the profile crosses the window's middle level (nearest the window's centre),
      // then, until it settles (a window holding only the foot of an edge first finds it early), where it
      // crosses the middle of the levels `guard` positions either side of the last centre.
      double k = crossing(lam, a + 1, b, 0.5 * (lo + hi), true, 0.5 * (a + b));
      if (std::isnan(k)) k = 0.5 * (a + b);
      for (int iteration = 0; iteration < 8; ++iteration) {
        const int c0 = int(std::lround(k));
        const int l0 = c0 - guard - d.plateau, h1 = c0 + guard + d.plateau;
        if (l0 < 0 || h1 > K) break;
        lo = level(l0, l0 + d.plateau, &var_lo);
        hi = level(h1 - d.plateau, h1, &var_hi);
        se = std::sqrt(var_lo + var_hi);
        const double next = crossing(lam, l0 + d.plateau, h1 - d.plateau + 1, 0.5 * (lo + hi), true, k);
        if (std::isnan(next)) break;
        const bool settled = std::abs(next - k) < 0.5;
        k = next;
        if (settled) break;
      }
      // The step where the edge settled must hold up too (a window holding the shoulder of an edge that the
      // previous window found settles on the plateau beyond it).
      const double z_located = se > 0.0 ? (hi - lo) / se : 0.0;
      if (!(z_located >= d.min_score)) continue;
      // Two windows that both hold part of one edge name it once.
      if (!found.empty() && std::abs(found.back().gate - k) < guard) {
        if (found.back().score >= z_located) continue;
        found.pop_back();
      }
      found.push_back({timing.range_of_rise(k), k, hi - lo, z_located});
    }
    return found;
  };
  // The paper's scan, windows without overlap, misses an edge a few positions inside a window (the window's
  // first level holds part of its step, and the window before ends below it). The windows offset by half a
  // window see it in their middle; what they find is kept where the paper's scan found nothing within half a
  // window (elsewhere it is that edge again, or its shoulder: a window whose first level lies on an edge's
  // rise settles 10-12 positions past it, with a score near the threshold).
  std::vector<Detection> out = scan(0);
  const size_t paper = out.size();
  for (const Detection& e : scan(d.window / 2))
    if (std::none_of(out.begin(), out.begin() + long(paper), [&](const Detection& m) { return std::abs(m.gate - e.gate) < 0.5 * d.window; }))
      out.push_back(e);
  return folded(std::move(out), timing, 0.5 * d.window);
}

std::vector<Detection> detect(const EdgeDetector& d, const float* profile, int K, int frames, const PixelTiming& timing,
                              bool rates) {
  const std::vector<double> c = counts_of(profile, K, frames, rates);
  const std::vector<double> cs = moving_average(c, 2);
  std::vector<double> lam(static_cast<size_t>(K)), var(static_cast<size_t>(K));
  // Prefix sums of lambda and of its variance p / (N (1 - p)) = var(c) (dlambda/dc)^2.
  std::vector<double> sum_l(size_t(K) + 1, 0.0), sum_v(size_t(K) + 1, 0.0);
  for (int k = 0; k < K; ++k) {
    lam[size_t(k)] = rates ? double(profile[k]) : linearise(c[size_t(k)], frames);
    const double g = lambda_slope(cs[size_t(k)], frames);
    var[size_t(k)] = count_variance(cs[size_t(k)], frames) * g * g;
    sum_l[size_t(k) + 1] = sum_l[size_t(k)] + lam[size_t(k)];
    sum_v[size_t(k) + 1] = sum_v[size_t(k)] + var[size_t(k)];
  }
  struct Edge {
    int k = 0, scale = 0;
    double z = 0.0, step = 0.0, lo = 0.0, hi = 0.0;
    int claim_lo = 0, claim_hi = 0;  // the positions [claim_lo, claim_hi) of its transition
  };
  // z of the step at boundary k over `s` positions either side.
  const auto z_at = [&](int k, int s) {
    const double left = (sum_l[size_t(k)] - sum_l[size_t(k - s)]) / s, right = (sum_l[size_t(k + s)] - sum_l[size_t(k)]) / s;
    const double v = (sum_v[size_t(k + s)] - sum_v[size_t(k - s)]) / (double(s) * s);
    return v > 0.0 ? (right - left) / std::sqrt(v) : 0.0;
  };
  // Edges are taken strongest first. Each taken edge claims its transition: `separation` positions
  // either side of it, and beyond while the profile still steps the edge's way by min_score standard
  // errors over the finest scale (a bright return's foot and shoulder stand out of the noise far from its
  // centre); a later edge must lie outside every claim, and only the scales whose windows stay outside
  // every claim count for it (a window reaching into a stronger edge's transition would see that edge's
  // foot or shoulder as a step of its own). z at boundary k (between positions k - 1 and k), the best
  // allowed scale, recomputed after each take; at most 64 edges.
  std::vector<Edge> taken;
  const auto allowed = [&](int lo, int hi) {  // positions [lo, hi) touch no claim
    return std::none_of(taken.begin(), taken.end(), [&](const Edge& t) { return lo < t.claim_hi && hi > t.claim_lo; });
  };
  const int fine = d.scales.front();
  const auto claim = [&](Edge e) {
    const double sign = e.z > 0.0 ? 1.0 : -1.0;
    int lo = e.k - d.separation, hi = e.k + d.separation;
    while (lo - fine >= 0 && lo + fine <= K && sign * z_at(lo, fine) >= d.min_score) --lo;
    while (hi - fine >= 0 && hi + fine <= K && sign * z_at(hi, fine) >= d.min_score) ++hi;
    e.claim_lo = lo, e.claim_hi = hi;
    return e;
  };
  // Only statistics at or above min_score can be taken: list them once (in k, then scale order, which
  // breaks ties as a full scan would), then take from the list.
  std::vector<Edge> candidates;
  for (int k = 1; k < K; ++k)
    for (int s : d.scales) {
      if (k - s < 0 || k + s > K) continue;
      const double z = z_at(k, s);
      const double left = (sum_l[size_t(k)] - sum_l[size_t(k - s)]) / s, right = (sum_l[size_t(k + s)] - sum_l[size_t(k)]) / s;
      if (std::abs(z) >= d.min_score) candidates.push_back({k, s, z, right - left, left, right});
    }
  while (taken.size() < 64) {
    const Edge* top = nullptr;
    for (const Edge& e : candidates)
      if ((!top || std::abs(e.z) > std::abs(top->z)) && allowed(e.k, e.k) && allowed(e.k - e.scale, e.k + e.scale)) top = &e;
    if (!top) break;
    taken.push_back(claim(*top));
  }
  // Position k saturated: its count within half a count of N, or (rates) a rate that would make it so.
  const double clip = linearise(frames, frames);  // ln(2 N)
  const auto saturated = [&](int k) { return rates ? lam[size_t(k)] >= clip : c[size_t(k)] >= frames - 0.5; };
  const std::vector<double> lam_s = moving_average(lam, 1);
  // The level of positions [a, b): the rates' mean, or the linearised mean count (the mean of linearised
  // counts near N is biased by their clipping).
  constexpr int kPlateau = 12;
  constexpr int kMinPlateau = 4;
  constexpr double kPlateauFlatness = 0.1;
  constexpr double kPartOfStep = 0.5;
  constexpr double kBrightLevel = 2.0;  // lambda: the noise of the linearised level has grown e^2 - 1 = 6.4 times over the foot's
  const auto level_of = [&](int a, int b) {
    double sum = 0.0;
    for (int k = a; k < b; ++k) sum += rates ? lam[size_t(k)] : c[size_t(k)];
    return rates ? sum / (b - a) : linearise(sum / (b - a), frames);
  };
  // Each edge at the half point of its step on the lightly smoothed profile, nearest its boundary.
  const auto pick = [&](bool rising) {
    std::vector<std::pair<Edge, double>> located;  // the edge and its fractional position
    std::vector<bool> was_clipped;                 // [j]: located[j] runs into saturated counts
    std::vector<double> whole_x;                   // [j]: located[j]'s half point between the plateaus (NaN: none)
    std::vector<bool> cut;                         // [j]: its dark side cut short by the sweep's end (below)
    for (const Edge& e : taken) {
      if ((e.z > 0.0) != rising) continue;
      // An edge into a saturated plateau: the bright level is clipped at ln(2 N), and the edge's z, largest
      // in the unclipped foot where the noise is least, may have named it by its foot; its half point is
      // then taken between the dark side and the clip, over the window, the claim and up to the plateau.
      double left = e.lo, right = e.hi;
      double x = crossing(lam_s, e.k - e.scale + 1, e.k + e.scale, 0.5 * (left + right), rising, e.k - 0.5);
      if (std::isnan(x)) x = e.k - 0.5;
      int span_lo = std::min(e.k - e.scale, e.claim_lo) - fine, span_hi = std::max(e.k + e.scale, e.claim_hi) + fine;
      // the first saturated position on the bright side: within the window and claim, or up the transition
      // from the edge found while the profile climbs on (at most 4 claims)
      const int dir = rising ? 1 : -1;
      int first = -1;
      for (int j = rising ? e.k : e.k - 1; rising ? j < span_hi : j >= span_lo; j += dir)
        if (j >= 0 && j < K && saturated(j)) {
          first = j;
          break;
        }
      for (int j = rising ? int(std::ceil(x)) : int(std::floor(x)), n = 0; first < 0 && j >= 0 && j < K && n < 4 * d.separation; j += dir, ++n) {
        if (saturated(j)) first = j;
        else if (j + dir < 0 || j + dir >= K || lam_s[size_t(j + dir)] < lam_s[size_t(j)]) break;
      }
      // clipped when the plateau it begins is: half or more of the claim's width of positions from it saturated
      // (counts near N on a plateau reach N now and then by chance, which clips nothing)
      bool clipped = false;
      if (first >= 0) {
        int n = 0, sat = 0;
        for (int j = first; j >= 0 && j < K && n < d.separation; j += dir, ++n) sat += saturated(j);
        clipped = 2 * sat >= n;
        if (clipped) (rising ? span_hi : span_lo) = rising ? std::max(span_hi, first + fine) : std::min(span_lo, first - fine);
      }
      if (clipped) {
        // the bright level: the clip; for rates, which are not clipped, the highest over the span
        double bright = clip;
        if (rates)
          for (int k = std::max(0, span_lo); k < std::min(K, span_hi); ++k) bright = std::max(bright, lam_s[size_t(k)]);
        (rising ? right : left) = bright;
        x = crossing(lam_s, span_lo + 1, span_hi, 0.5 * (left + right), rising, e.k - 0.5);
        if (std::isnan(x)) x = e.k - 0.5;
      } else if (e.claim_lo - kPlateau >= 0 && e.claim_hi + kPlateau <= K) {
        // A bright edge (a bright side of lambda kBrightLevel or more, where the linearised noise has grown
        // many times over its foot's) may be named by its foot too, by windows that hold part of its step only: its half
        // point is then taken between the levels either side of its whole claimed transition (the bright one
        // from the mean count, which a plateau near N keeps unbiased).
        const double before = level_of(e.claim_lo - kPlateau, e.claim_lo), after = level_of(e.claim_hi, e.claim_hi + kPlateau);
        const double whole = rising ? after - before : before - after, seen = rising ? e.hi - e.lo : e.lo - e.hi;
        if (whole > 0.0 && seen < kPartOfStep * whole && std::max(before, after) >= kBrightLevel) {
          x = crossing(lam_s, e.claim_lo + 1, e.claim_hi, 0.5 * (before + after), rising, e.k - 0.5);
          if (std::isnan(x)) x = e.k - 0.5;
        }
      }
      // The half point between the plateaus either side of the whole claimed transition, for an edge left
      // unpaired (below): the windows of the statistic that named it are not centred on its half point (its
      // z peaks towards the foot, where the noise is least), which places a rise early and a fall late by
      // the same time, about 25 ps (3.5 mm) on the default gate; a pair's two shifts cancel, a lone edge's
      // (its partner outside the sweep) did not.
      // The plateaus end where another edge's claim begins (a lone edge's partner is often under another
      // return's edge) or the sweep ends; at least kMinPlateau positions each, else the statistic's timing
      // stays.
      double xw = std::numeric_limits<double>::quiet_NaN();
      int p0 = std::max(0, e.claim_lo - kPlateau), p1 = std::min(K, e.claim_hi + kPlateau);
      for (const Edge& t : taken) {
        if (t.claim_hi <= e.claim_lo) p0 = std::max(p0, t.claim_hi);
        if (t.claim_lo >= e.claim_hi) p1 = std::min(p1, t.claim_lo);
      }
      // Cut by the sweep: fewer than kPlateau positions of its dark side (before a rise, after a fall) lie in
      // the sweep, whose end bounds them.
      const bool cut_short = rising ? p0 == 0 && e.claim_lo - p0 < kPlateau : p1 == K && p1 - e.claim_hi < kPlateau;
      if (!clipped && e.claim_lo - p0 >= kMinPlateau && p1 - e.claim_hi >= kMinPlateau) {
        const double before = level_of(p0, e.claim_lo), after = level_of(e.claim_hi, p1);
        // plateaus indeed: each window's halves within a tenth of the step of each other, beyond two
        // standard errors of their noise (the foot of another return's edge just past the claim is not one)
        const auto flat = [&](int a, int b) {
          const int m = (a + b) / 2;
          // the halves' difference and its standard error (the noise of lambda's means over them)
          const double se = std::sqrt((sum_v[size_t(m)] - sum_v[size_t(a)]) / double((m - a) * (m - a)) +
                                      (sum_v[size_t(b)] - sum_v[size_t(m)]) / double((b - m) * (b - m)));
          return std::abs(level_of(a, m) - level_of(m, b)) <= kPlateauFlatness * std::abs(after - before) + 2.0 * se;
        };
        if ((after - before > 0.0) == rising && flat(p0, e.claim_lo) && flat(e.claim_hi, p1))
          xw = crossing(lam_s, e.claim_lo + 1, e.claim_hi, 0.5 * (before + after), rising, x);
      }
      // The whole step, from plateaus just outside the edge's transition when the profile has them (the
      // statistic's windows may reach into the transition and see part of it).
      const int lo0 = int(std::floor(x)) - d.separation - 4, hi1 = int(std::ceil(x)) + d.separation + 4;
      Edge located_edge = e;
      if (lo0 >= 0 && hi1 <= K)
        located_edge.step = (sum_l[size_t(hi1)] - sum_l[size_t(hi1 - 4)]) / 4.0 - (sum_l[size_t(lo0 + 4)] - sum_l[size_t(lo0)]) / 4.0;
      // Two edges of one clipped transition (its foot and its shoulder can both stand out) are one: the
      // stronger is kept.
      bool merged = false;
      for (size_t j = 0; j < located.size() && !merged; ++j) {
        auto& [other, ox] = located[j];
        if ((clipped || was_clipped[j]) && std::abs(ox - x) < d.separation) {
          if (std::abs(located_edge.z) > std::abs(other.z))
            other = located_edge, ox = x, was_clipped[j] = clipped, whole_x[j] = xw, cut[j] = cut_short;
          merged = true;
        }
      }
      if (merged) continue;
      located.emplace_back(located_edge, x);
      was_clipped.push_back(clipped);
      whole_x.push_back(xw);
      cut.push_back(cut_short);
    }
    return std::make_tuple(located, whole_x, cut);
  };
  const auto [rises, rise_whole_x, rise_cut] = pick(true);
  const auto [falls, fall_whole_x, fall_cut] = pick(false);
  const auto lone = [](double x, double whole) { return std::isnan(whole) ? x : whole; };
  // Counts saturated (within half a count of N) at nine in ten or more of the positions strictly between
  // fractional positions a < b, at least one: the level there is clipped at ln(2 N), so the edges either
  // side are located on the clipped step, early for a rise and late for a fall by the same time.
  const auto saturated_between = [&](double a, double b) {
    const int k0 = std::max(0, int(std::floor(a)) + 1), k1 = std::min(K - 1, int(std::ceil(b)) - 1);
    if (rates || k0 > k1) return false;
    int n = 0;
    for (int k = k0; k <= k1; ++k) n += saturated(k);
    return 10 * n >= 9 * (k1 - k0 + 1);
  };
  // Pair each rise with the fall that gives the closest return time, within match_s; or with the fall
  // that ends the saturated stretch the rise begins (one return whose plateau saturates, both edges moved
  // out by the clipping: their plain mean times it).
  std::vector<bool> fall_used(falls.size(), false);
  std::vector<Detection> out;
  const auto rise_time = [&](size_t ri) { return timing.start_s + rises[ri].second * timing.step_s + timing.rise_offset_s; };
  const auto fall_time = [&](size_t fi) { return timing.start_s + falls[fi].second * timing.step_s + timing.fall_offset_s; };
  const auto pair = [&](size_t ri, size_t fi, bool clipped) {
    fall_used[fi] = true;
    const auto& [r, xr] = rises[ri];
    const auto& [f, xf] = falls[fi];
    // One edge cut short by the sweep's end: located on a step whose dark level the sweep does not reach, it
    // is off by up to 6 mm; the other times the return alone, as a lone edge (a pair of two cut edges keeps both).
    if (!clipped && rise_cut[ri] != fall_cut[fi]) {
      const bool by_rise = fall_cut[fi];
      const double x = by_rise ? lone(xr, rise_whole_x[ri]) : lone(xf, fall_whole_x[fi]);
      out.push_back({by_rise ? timing.range_of_rise(x) : timing.range_of_fall(x), by_rise ? x : xr, by_rise ? r.step : -f.step,
                     std::hypot(r.z, f.z)});
      return;
    }
    // weighted by z^2: the timing variance of an edge falls as its z grows (clipped: equally, so that the
    // two shifts cancel)
    const double wr = clipped ? 1.0 : r.z * r.z, wf = clipped ? 1.0 : f.z * f.z;
    const double range = (wr * timing.range_of_rise(xr) + wf * timing.range_of_fall(xf)) / (wr + wf);
    out.push_back({range, xr, (wr * r.step - wf * f.step) / (wr + wf), std::hypot(r.z, f.z)});
  };
  std::vector<size_t> lone_rises;
  for (size_t ri = 0; ri < rises.size(); ++ri) {
    const double xr = rises[ri].second, tr = rise_time(ri);
    int partner = -1;
    bool clipped = false;
    double best_dt = d.match_s;
    for (size_t i = 0; i < falls.size(); ++i) {
      if (fall_used[i]) continue;
      const double tf = fall_time(i);
      if (std::abs(tf - tr) <= best_dt) best_dt = std::abs(tf - tr), partner = int(i), clipped = false;
      else if (partner < 0 && falls[i].second > xr && saturated_between(xr, falls[i].second)) partner = int(i), clipped = true;
    }
    if (partner < 0) lone_rises.push_back(ri);
    else pair(ri, size_t(partner), clipped);
  }
  // A rise and a fall left alone whose return times lie closer than the detector resolves (two returns that
  // close make one rise and one fall: their edges' claims merge them) are one return whose two edges' timing
  // errors exceed match_s (under background light, where each edge's noise grows: at 200 lux 3.7 % of a flat
  // target's profiles gave two detections 4 cm apart, each 2 cm off): paired, closest first.
  const double resolved_s = d.separation * timing.step_s;
  std::vector<std::tuple<double, size_t, size_t>> close;
  for (const size_t ri : lone_rises)
    for (size_t i = 0; i < falls.size(); ++i)
      if (!fall_used[i] && std::abs(fall_time(i) - rise_time(ri)) < resolved_s) close.emplace_back(std::abs(fall_time(i) - rise_time(ri)), ri, i);
  std::sort(close.begin(), close.end());
  std::vector<bool> rise_used(rises.size(), false);
  for (const auto& [dt, ri, fi] : close)
    if (!rise_used[ri] && !fall_used[fi]) rise_used[ri] = true, pair(ri, fi, false);
  for (const size_t ri : lone_rises)
    if (!rise_used[ri]) {
      const auto& [r, xr] = rises[ri];
      const double x = lone(xr, rise_whole_x[ri]);
      out.push_back({timing.range_of_rise(x), x, r.step, r.z});
    }
  for (size_t i = 0; i < falls.size(); ++i)
    if (!fall_used[i]) {
      const auto& [f, xf] = falls[i];
      const double x = lone(xf, fall_whole_x[i]);
      out.push_back({timing.range_of_fall(x), x, -f.step, -f.z});
    }
  return folded(std::move(out), timing, d.separation);
}

namespace {
// The standard error of e.photons from N frames at x photons per frame (delta method): sqrt(var(c)) over
// dc / dphotons, written so that it grows to +inf past saturation instead of dividing two underflows (it was
// 0 beyond about 745 photons per frame, where exp(-x) is 0, and +inf in float32 from about 180, while the
// documents said 0: the counts then tell nothing of the light, and the error is unbounded).
void set_standard_error(HdrEstimate& e, int frames, bool dual, double ratio) {
  const double N = frames;
  const double x = e.photons / N;  // photons per frame
  if (!(x > 0.0)) {
    e.standard_error = 0.0;  // no light, no counts: their variance is 0
    return;
  }
  if (!dual) {
    // var(c) = N p q, slope = q: var / slope^2 = N p / q = N (e^x - 1) (expm1: exact for faint light)
    e.standard_error = std::sqrt(N * std::expm1(x));
  } else {
    // both halves' terms over the short exposure's q_S = exp(-a_S x): var / slope^2 =
    // 2 N (p_L r + p_S) e^{a_S x} / (a_L r + a_S)^2, r = q_L / q_S = exp(-(a_L - a_S) x)
    const double aL = 2.0 * ratio / (ratio + 1.0), aS = 2.0 / (ratio + 1.0);
    const double pL = -std::expm1(-aL * x), pS = -std::expm1(-aS * x), r = aL > aS ? std::exp(-(aL - aS) * x) : 1.0;
    const double w = aL * r + aS;
    e.standard_error = std::sqrt(2.0 * N * (pL * r + pS) / (w * w)) * std::exp(0.5 * aS * x);
  }
  // beyond a float's range it is written as +inf (a double's own overflow gives +inf too)
  if (e.standard_error > double(std::numeric_limits<float>::max())) e.standard_error = std::numeric_limits<double>::infinity();
}
}  // namespace

HdrEstimate invert_hdr(double counts, int frames, bool dual, double ratio) {
  HdrEstimate e;
  e.saturated = counts >= frames - 0.5;
  e.photons = sensor::linearise_counts(counts, frames, dual, ratio);
  set_standard_error(e, frames, dual, ratio);
  return e;
}

HdrEstimate hdr_of_rates(const float* lambda, int frames, bool dual, double ratio) {
  HdrEstimate e;
  const int K = dual ? 2 : 1;
  double mean = 0.0, counts = 0.0;
  for (int k = 0; k < K; ++k) {
    mean += double(lambda[k]) / K;
    counts += double(frames) / K * -std::expm1(-double(lambda[k]));
  }
  e.photons = frames * mean;
  e.saturated = counts >= frames - 0.5;
  set_standard_error(e, frames, dual, ratio);
  return e;
}

}  // namespace spadgen::reconstruct
