#include "sphere_search.h"

#include <algorithm>
#include <cmath>

namespace spadgen::render {

SphereRay sphere_ray(double dl, double R, double n, double h) {
  SphereRay r;
  r.h = h;
  const double sin_t = h / dl, cos_t = std::sqrt(1.0 - sin_t * sin_t);
  const glm::dvec2 d(cos_t, sin_t), e = glm::dvec2(-dl, 0.0) + (dl * cos_t - std::sqrt(std::max(0.0, R * R - h * h))) * d, ne = e / R;
  const double ci = -glm::dot(d, ne);
  if (!(ci > 0.01)) return r;
  const double eta = 1.0 / n, k = 1.0 - eta * eta * (1.0 - ci * ci);
  if (!(k > 0.0)) return r;
  const glm::dvec2 d1 = glm::normalize(eta * d + (eta * ci - std::sqrt(k)) * ne);
  const glm::dvec2 q = e - 2.0 * glm::dot(e, d1) * d1, nq = q / R;
  const double co = glm::dot(d1, nq), k2 = 1.0 - n * n * (1.0 - co * co);
  if (!(co > 0.0) || !(k2 > 1e-4)) return r;  // (total reflection, or a grazing exit)
  r.ok = true, r.entry = e, r.exit = q, r.dir = n * d1 + (std::sqrt(k2) - n * co) * nq;
  return r;
}

SphereSearch::SphereSearch(double dl, double R, double n, int steps) : dl_(dl), R_(R), n_(n) {
  // (uniform in the angle of incidence, its sine h / R, up to 0.6 degrees from grazing)
  const double i_max = std::acos(0.0101);
  for (int i = 0; i <= steps; ++i) rays_.push_back(sphere_ray(dl, R, n, R * std::sin(i_max * (-1.0 + 2.0 * i / steps))));
}

int SphereSearch::seeds(const glm::dvec2& X, SphereRay* out, int max) const {
  int count = 0;
  // A ray's signed miss of X: the angle from its direction to X seen from its exit, in (-pi, pi] (continuous where
  // the exit passes X: a wall touching the sphere, the ray's exit beside X).
  const auto miss = [&](const SphereRay& r, double* m) {
    if (!r.ok) return false;
    const glm::dvec2 to_x = X - r.exit;
    *m = std::atan2(r.dir.x * to_x.y - r.dir.y * to_x.x, glm::dot(r.dir, to_x));
    return true;
  };
  // A root between misses a and b of opposite signs: the angle passes through 0, not through pi.
  const auto crosses = [](double a, double b) { return (a < 0.0) != (b < 0.0) && std::abs(a - b) < 3.141592653589793; };
  // The root bracketed by rays lo_r (miss lo_miss) and hi_r (the other sign), bisected 6 times in the angle of incidence.
  const auto root = [&](const SphereRay& lo_r, double lo_miss, const SphereRay& hi_r) {
    if (count >= max) return;
    double lo = std::asin(std::clamp(lo_r.h / R_, -1.0, 1.0)), hi = std::asin(std::clamp(hi_r.h / R_, -1.0, 1.0));  // (in the angle of incidence)
    SphereRay best = hi_r;
    for (int j = 0; j < 6; ++j) {
      const double mid = 0.5 * (lo + hi);
      const SphereRay r = sphere_ray(dl_, R_, n_, R_ * std::sin(mid));
      double at = 0.0;
      if (!miss(r, &at)) break;
      best = r;
      ((at < 0.0) == (lo_miss < 0.0) ? lo : hi) = mid;
    }
    out[count++] = best;
  };
  // Two roots between rays b and d about c, the least |miss| of one sign.
  const auto fold = [&](const SphereRay& rb, double mb, const SphereRay& rc, double mc, const SphereRay& rd, double md) {
    const double h0 = rb.h, h1 = rc.h, h2 = rd.h;
    const double d01 = (mc - mb) / (h1 - h0), d12 = (md - mc) / (h2 - h1), curv = (d12 - d01) / (h2 - h0);
    if (!(curv * mc > 0.0)) return;  // (the parabola opens away from zero)
    const double slope = d01 + curv * (h1 - h0), vertex = mc - slope * slope / (4.0 * curv);  // (its slope at h1)
    if (!(vertex / mc < 0.5)) return;
    const double g = 0.5 * (std::sqrt(5.0) - 1.0), s = mc < 0.0 ? -1.0 : 1.0;
    double lo = h0, hi = h2, p = hi - g * (hi - lo), q = lo + g * (hi - lo), fp = 0.0, fq = 0.0;
    SphereRay rp = sphere_ray(dl_, R_, n_, p), rq = sphere_ray(dl_, R_, n_, q);
    if (!miss(rp, &fp) || !miss(rq, &fq)) return;
    for (int j = 0; j < 16; ++j) {
      if (s * fp < 0.0 || s * fq < 0.0) {
        const bool at_p = s * fp < 0.0;
        const SphereRay& r = at_p ? rp : rq;
        const double f = at_p ? fp : fq;
        root(rb, mb, r);
        root(r, f, rd);
        return;
      }
      if (s * fp < s * fq) {
        hi = q, q = p, fq = fp, rq = rp, p = hi - g * (hi - lo), rp = sphere_ray(dl_, R_, n_, p);
        if (!miss(rp, &fp)) return;
      } else {
        lo = p, p = q, fp = fq, rp = rq, q = lo + g * (hi - lo), rq = sphere_ray(dl_, R_, n_, q);
        if (!miss(rq, &fq)) return;
      }
    }
  };
  double m_b = 0.0, m_c = 0.0, m_d = 0.0;
  bool ok_b = false, ok_c = !rays_.empty() && miss(rays_[0], &m_c);
  for (size_t i = 1; i < rays_.size() && count < max; ++i) {
    const bool ok_d = miss(rays_[i], &m_d);
    if (ok_c && ok_d && crosses(m_c, m_d))
      root(rays_[i - 1], m_c, rays_[i]);
    else if (ok_b && ok_c && ok_d && (m_b < 0.0) == (m_c < 0.0) && (m_c < 0.0) == (m_d < 0.0) &&
             std::abs(m_c) < std::abs(m_b) && std::abs(m_c) <= std::abs(m_d))
      fold(rays_[i - 2], m_b, rays_[i - 1], m_c, rays_[i], m_d);
    m_b = m_c, ok_b = ok_c, m_c = m_d, ok_c = ok_d;
  }
  return count;
}

}  // namespace spadgen::render
