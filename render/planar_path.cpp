#include "planar_path.h"

#include "rng_util.h"

#include <algorithm>
#include <cmath>

namespace spadgen::render {

namespace {

constexpr int kMaxUnknowns = 2 * kMaxPlanarFaces;

// Solves a x = b in place for `cols` right-hand sides (b row-major, n x cols), by Gaussian elimination with
// partial pivoting; false when a is singular to working precision. a is block tridiagonal in 2 x 2 blocks (the
// residual's Jacobian): row i's entries lie within 3 columns of i, and pivoting among the 3 rows below widens
// the band above to 6, so the loops skip what is zero (the same arithmetic as the dense elimination's).
bool solve_linear(double (*a)[kMaxUnknowns], double (*b)[2], int n, int cols) {
  constexpr int kBelow = 3, kAbove = 6;
  double scale = 0.0;
  for (int i = 0; i < n; ++i)
    for (int j = std::max(0, i - kBelow); j < std::min(n, i + kBelow + 1); ++j) scale = std::max(scale, std::fabs(a[i][j]));
  if (!(scale > 0.0)) return false;
  for (int c = 0; c < n; ++c) {
    const int last = std::min(n, c + kBelow + 1), right = std::min(n, c + kAbove + 1);
    int pivot = c;
    for (int i = c + 1; i < last; ++i)
      if (std::fabs(a[i][c]) > std::fabs(a[pivot][c])) pivot = i;
    if (!(std::fabs(a[pivot][c]) > 1e-14 * scale)) return false;
    if (pivot != c) {
      std::swap_ranges(a[c] + c, a[c] + right, a[pivot] + c);
      std::swap_ranges(b[c], b[c] + cols, b[pivot]);
    }
    for (int i = c + 1; i < last; ++i) {
      const double f = a[i][c] / a[c][c];
      if (f == 0.0) continue;
      for (int j = c; j < right; ++j) a[i][j] -= f * a[c][j];
      for (int j = 0; j < cols; ++j) b[i][j] -= f * b[c][j];
    }
  }
  for (int c = n - 1; c >= 0; --c)
    for (int j = 0; j < cols; ++j) {
      double s = b[c][j];
      for (int i = c + 1; i < std::min(n, c + kAbove + 1); ++i) s -= a[c][i] * b[i][j];
      b[c][j] = s / a[c][c];
    }
  return true;
}

// A face's unit shading normal at the current point, and the length of the interpolated one it normalises.
struct Shade {
  glm::dvec3 n{0.0};
  double m = 1.0;
};

struct Chain {
  const glm::dvec3 *x, *l;
  const PlanarFace* faces;
  const double* index;
  int k;
  glm::dvec3 t[kMaxPlanarFaces][2];  // each face's in-plane basis

  glm::dvec3 vertex(const glm::dvec3* y, int s) const { return s < 0 ? *x : s < k ? y[s] : *l; }

  // Segments' directions and lengths for points y, the shaded faces' normals there, and the residual: each face's
  // in-plane part of n_s d_s - n_{s+1} d_{s+1} (a shaded face's: of its part across the shading normal). Its
  // largest magnitude, or +inf where a segment is empty or an interpolated normal vanishes.
  double residual(const glm::dvec3* y, glm::dvec3* d, double* len, Shade* sh, double* c) const {
    for (int s = 0; s <= k; ++s) {
      const glm::dvec3 e = vertex(y, s) - vertex(y, s - 1);
      len[s] = glm::length(e);
      if (!(len[s] > 0.0)) return HUGE_VAL;
      d[s] = e / len[s];
    }
    double worst = 0.0;
    for (int j = 0; j < k; ++j) {
      const glm::dvec3 r = index[j] * d[j] - index[j + 1] * d[j + 1];
      const PlanarFace& f = faces[j];
      if (f.shaded) {
        const glm::dvec3 m = f.m + f.grad * (y[j] - f.p);
        sh[j].m = glm::length(m);
        if (!(sh[j].m > 1e-12)) return HUGE_VAL;
        sh[j].n = m / sh[j].m;
      }
      for (int a = 0; a < 2; ++a) {
        c[2 * j + a] = f.shaded ? glm::dot(t[j][a], r) - glm::dot(r, sh[j].n) * glm::dot(t[j][a], sh[j].n) : glm::dot(t[j][a], r);
        worst = std::max(worst, std::fabs(c[2 * j + a]));
      }
    }
    return worst;
  }

  // d(d_s) / d(end of segment s) applied to v: (v - d_s (d_s . v)) / len_s.
  static glm::dvec3 project(const glm::dvec3& d, double len, const glm::dvec3& v) { return (v - d * glm::dot(d, v)) / len; }

  // What face j's residual component a takes of a change m of n_s d_s - n_{s+1} d_{s+1}: its in-plane part, or
  // for a shaded face its part across the shading normal, then in-plane.
  glm::dvec3 across(int j, int a, const Shade* sh) const {
    return faces[j].shaded ? t[j][a] - glm::dot(t[j][a], sh[j].n) * sh[j].n : t[j][a];
  }

  // The residual's Jacobian in the points' in-plane coordinates (block tridiagonal). A shaded face's own block
  // also has the turn of its normal, dN = (I - N N^T) grad v / |m|.
  void jacobian(const glm::dvec3* d, const double* len, const Shade* sh, double (*jac)[kMaxUnknowns]) const {
    const int n = 2 * k;
    for (int i = 0; i < n; ++i) std::fill_n(jac[i] + std::max(0, i - 3), std::min(n, i + 7) - std::max(0, i - 3), 0.0);
    for (int j = 0; j < k; ++j)
      for (int i = std::max(0, j - 1); i <= std::min(k - 1, j + 1); ++i)
        for (int b = 0; b < 2; ++b) {
          const glm::dvec3& v = t[i][b];
          glm::dvec3 m(0.0);  // d r_j / d y_i applied to v
          if (i == j - 1) m = -index[j] * project(d[j], len[j], v);
          if (i == j) m = index[j] * project(d[j], len[j], v) + index[j + 1] * project(d[j + 1], len[j + 1], v);
          if (i == j + 1) m = -index[j + 1] * project(d[j + 1], len[j + 1], v);
          for (int a = 0; a < 2; ++a) {
            jac[2 * j + a][2 * i + b] = glm::dot(across(j, a, sh), m);
            if (i == j && faces[j].shaded) {
              const glm::dvec3& N = sh[j].n;
              const glm::dvec3 gv = faces[j].grad * v, dN = (gv - N * glm::dot(N, gv)) / sh[j].m;
              const glm::dvec3 r = index[j] * d[j] - index[j + 1] * d[j + 1];
              jac[2 * j + a][2 * i + b] -= glm::dot(r, dN) * glm::dot(t[j][a], N) + glm::dot(r, N) * glm::dot(t[j][a], dN);
            }
          }
        }
  }
};

}  // namespace

bool solve_planar_path(const glm::dvec3& x, const glm::dvec3& l, const PlanarFace* faces, const double* index, int k,
                       const glm::dvec3* start, PlanarPath* out, const bool* reflect, const FaceTracker* tracker) {
  if (k < 1 || k > kMaxPlanarFaces) return false;
  PlanarFace fc[kMaxPlanarFaces];
  std::copy_n(faces, k, fc);
  Chain ch{&x, &l, fc, index, k, {}};
  glm::dvec3 y[kMaxPlanarFaces], d[kMaxPlanarFaces + 1];
  double len[kMaxPlanarFaces + 1], c[kMaxUnknowns];
  Shade sh[kMaxPlanarFaces];
  for (int j = 0; j < k; ++j) {
    make_basis(fc[j].n, &ch.t[j][0], &ch.t[j][1]);
    y[j] = start[j] - fc[j].n * glm::dot(start[j] - fc[j].p, fc[j].n);  // onto its plane
  }
  const int n = 2 * k;
  double worst = ch.residual(y, d, len, sh, c);
  double jac[kMaxUnknowns][kMaxUnknowns], step[kMaxUnknowns][2];
  for (int it = 0;; ++it) {
    if (!std::isfinite(worst)) return false;
    if (worst <= 1e-12) break;
    if (it == 50) return false;
    ch.jacobian(d, len, sh, jac);
    for (int i = 0; i < n; ++i) step[i][0] = -c[i];
    if (!solve_linear(jac, step, n, 1)) return false;
    // Halve the step while it does not lower the residual (the points moved onto the tracked surfaces first).
    bool lowered = false;
    for (double f = 1.0; f > 1e-6 && !lowered; f *= 0.5) {
      glm::dvec3 trial[kMaxPlanarFaces], td[kMaxPlanarFaces + 1];
      double tl[kMaxPlanarFaces + 1], tc[kMaxUnknowns];
      Shade ts[kMaxPlanarFaces];
      for (int j = 0; j < k; ++j) trial[j] = y[j] + f * (step[2 * j][0] * ch.t[j][0] + step[2 * j + 1][0] * ch.t[j][1]);
      // The trial point taken where its residual w is lower.
      const auto take = [&](double w) {
        if (!(w < worst)) return false;
        lowered = true;
        worst = w;
        std::copy_n(trial, k, y), std::copy_n(td, k + 1, d), std::copy_n(tl, k + 1, len), std::copy_n(tc, n, c);
        std::copy_n(ts, k, sh);
        return true;
      };
      if (!tracker) {
        take(ch.residual(trial, td, tl, ts, tc));
        continue;
      }
      PlanarFace tf[kMaxPlanarFaces];
      std::copy_n(fc, k, tf);
      if (!tracker->track(x, trial, tf, k)) continue;
      Chain tch = ch;
      tch.faces = tf;
      for (int j = 0; j < k; ++j)
        if (tf[j].triangle != fc[j].triangle || tf[j].mesh != fc[j].mesh) make_basis(tf[j].n, &tch.t[j][0], &tch.t[j][1]);
      if (take(tch.residual(trial, td, tl, ts, tc))) {
        std::copy_n(tf, k, fc);
        ch = tch;
        ch.faces = fc;
      }
    }
    if (!lowered) return false;
  }
  // Each face crossed, or reflected off, as asked (a shaded face about its plane and its shading normal).
  for (int j = 0; j < k; ++j) {
    const bool off = reflect && reflect[j];
    const double sides = glm::dot(d[j], fc[j].n) * glm::dot(d[j + 1], fc[j].n);
    if (!(off ? sides < 0.0 : sides > 0.0)) return false;
    if (fc[j].shaded) {
      const double shaded_sides = glm::dot(d[j], sh[j].n) * glm::dot(d[j + 1], sh[j].n);
      if (!(off ? shaded_sides < 0.0 : shaded_sides > 0.0)) return false;
    }
  }
  // The spread: x moved by e across d[0] moves the points by du = -J^-1 (dC / dx) e (only face 0's residual
  // depends on x, through d[0]: d(d_0) / dx = -P_0), and l's direction d[k] by -P_k (dy_{k-1}).
  glm::dvec3 e0, e1;
  make_basis(d[0], &e0, &e1);
  ch.jacobian(d, len, sh, jac);
  for (int i = 0; i < n; ++i) step[i][0] = step[i][1] = 0.0;
  for (int a = 0; a < 2; ++a) {
    step[a][0] = index[0] * glm::dot(ch.across(0, a, sh), Chain::project(d[0], len[0], e0));
    step[a][1] = index[0] * glm::dot(ch.across(0, a, sh), Chain::project(d[0], len[0], e1));
  }
  if (!solve_linear(jac, step, n, 2)) return false;
  glm::dvec3 m[2];
  for (int b = 0; b < 2; ++b) {
    const glm::dvec3 dy = step[n - 2][b] * ch.t[k - 1][0] + step[n - 1][b] * ch.t[k - 1][1];
    m[b] = -Chain::project(d[k], len[k], dy);
  }
  out->k = k;
  for (int j = 0; j < k; ++j) out->n[j] = fc[j].n;
  std::copy_n(y, k, out->y), std::copy_n(d, k + 1, out->d), std::copy_n(len, k + 1, out->len);
  out->spread = glm::length(glm::cross(m[0], m[1]));
  return std::isfinite(out->spread) && out->spread > 0.0;
}

}  // namespace spadgen::render
