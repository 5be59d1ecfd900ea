#include "sensor/response/gate_response.h"

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstring>

namespace spadgen::sensor {

EdgeBins edge_in_bins(const Edge& e, double bin_width_s) {
  EdgeBins b;
  const size_t m = e.u.size();
  b.u.resize(m);
  for (size_t j = 0; j < m; ++j) b.u[j] = e.u[j] / bin_width_s;
  b.c.assign(m, 0.0);
  double prev_slope = 0.0;
  for (size_t j = 0; j < m; ++j) {
    const double slope = j + 1 < m ? (e.y[j + 1] - e.y[j]) / (b.u[j + 1] - b.u[j]) : 0.0;
    b.c[j] = slope - prev_slope;
    prev_slope = slope;
  }
  b.C0.assign(m + 1, 0.0);
  b.C1.assign(m + 1, 0.0);
  for (size_t j = 0; j < m; ++j) {
    b.C0[j + 1] = b.C0[j] + b.c[j];
    b.C1[j + 1] = b.C1[j] + b.c[j] * b.u[j];
  }
  // Integer-step tables. Knot j with n_j = floor(u_j), r_j = u_j - n_j and f + r_j < 1 has argument
  // y + u_j = (d + n_j) + (f + r_j): Q is c_j (f + r_j)^2 / 2 at d = -n_j (entry t_j), 0 before,
  // c_j (d + u_j - 1/2 + f) after. The linear parts are summed from t_j + 1 on as t S0 + S1 with
  // S1 = sum c_j (u_j + d_lo - 1/2) (d + u_j = t + u_j + d_lo: small near the window's start, where W is).
  const int64_t n_first = static_cast<int64_t>(std::floor(b.u.front())), n_last = static_cast<int64_t>(std::floor(b.u.back()));
  b.d_lo = -(n_last + 1);
  b.L = n_last - n_first + 2;
  const auto L = static_cast<size_t>(b.L);
  std::vector<double> l0(L, 0.0), l1(L, 0.0);
  b.wa.assign(L, 0.0);
  b.wb.assign(L, 0.0);
  b.wc.assign(L, 0.0);
  std::vector<size_t> order(m);
  std::vector<double> r(m);
  std::vector<int64_t> t(m);
  for (size_t j = 0; j < m; ++j) {
    const double n = std::floor(b.u[j]);
    r[j] = b.u[j] - n;
    t[j] = n_last + 1 - static_cast<int64_t>(n);
    const auto tj = static_cast<size_t>(t[j]);
    const double c = b.c[j];
    b.wa[tj] += 0.5 * c * r[j] * r[j];
    b.wb[tj] += c * r[j];
    b.wc[tj] += 0.5 * c;
    if (tj + 1 < L) {
      l0[tj + 1] += c;
      l1[tj + 1] += c * (b.u[j] + static_cast<double>(b.d_lo) - 0.5);
    }
    order[j] = j;
  }
  double S0 = 0.0, S1 = 0.0;
  for (size_t k = 0; k < L; ++k) {
    S0 += l0[k];
    S1 += l1[k];
    b.wa[k] += static_cast<double>(k) * S0 + S1;
    b.wb[k] += S0;
  }
  std::stable_sort(order.begin(), order.end(), [&](size_t x, size_t y) { return r[x] > r[y]; });
  for (size_t j : order) {
    b.xr.push_back(r[j]);
    b.xc.push_back(b.c[j]);
    b.xt.push_back(t[j]);
  }
  static std::atomic<uint64_t> next_id{1};
  b.id = next_id.fetch_add(1, std::memory_order_relaxed);
  return b;
}

bool TransientPrefix::build(const float* g, int64_t T) {
  // Empty stretches shorter than this stay inside a run: a few extra knot evaluations are cheaper than
  // another run to walk at every gate position.
  constexpr int64_t kMergeGap = 4;
  runs_.clear();
  g_.clear();
  G1_.clear();
  G2_.clear();
  double G1 = 0.0, G2 = 0.0;
  int64_t cur = 0;
  int64_t i = 0;
  while (i < T) {
    // skip empty stretches 16 bins at a time (the reduction vectorises); -0.0f counts as empty
    while (i + 16 <= T) {
      uint32_t any = 0;
      for (int64_t j = 0; j < 16; ++j) any |= std::bit_cast<uint32_t>(g[i + j]) & 0x7FFFFFFFu;
      if (any != 0) break;
      i += 16;
    }
    while (i < T && g[i] == 0.0f) ++i;
    if (i == T) break;
    int64_t e = i + 1, last_nz = i;
    while (e < T && e - last_nz <= kMergeGap) {
      if (g[e] != 0.0f) last_nz = e;
      ++e;
    }
    e = last_nz + 1;
    G2 += G1 * static_cast<double>(i - cur);
    Run r;
    r.s = i;
    r.e = e;
    r.off = g_.size();
    for (int64_t b = i; b < e; ++b) {
      const double v = g[b];
      g_.push_back(v);
      G1_.push_back(G1);
      G2_.push_back(G2);
      G2 += G1 + 0.5 * v;
      G1 += v;
    }
    r.G1e = G1;
    r.G2e = G2;
    runs_.push_back(r);
    cur = e;
    i = e;
  }
  total_ = G1;
  return !runs_.empty();
}

bool TransientPrefix::build_bins(const float* g, int64_t T) { return build_bins(g, 0, T); }

bool TransientPrefix::build_bins(const float* g, int64_t lo, int64_t T) {
  runs_.clear();
  nz_i_.clear();
  nz_v_.clear();
  double G1 = 0.0;
  auto take = [&](int64_t b) {
    if (g[b] == 0.0f) return;
    const double v = g[b];
    nz_i_.push_back(b);
    nz_v_.push_back(v);
    G1 += v;
  };
  int64_t i = lo;
  // 32 bins at a time, OR-ed as four-lane vectors (GCC/Clang vector extension; the scalar loop compiled to
  // 16 scalar ORs per 16 bins); -0.0f counts as empty, as in build()
  using U4 = uint32_t __attribute__((vector_size(16)));
  for (; i + 32 <= T; i += 32) {
    __builtin_prefetch(g + i + 512);  // 2 KB ahead (a row's transients are one stream; 4 KB measured the same)
    __builtin_prefetch(g + i + 528);
    U4 acc{0, 0, 0, 0};
    for (int64_t j = 0; j < 8; ++j) {
      U4 x;
      std::memcpy(&x, g + i + 4 * j, sizeof x);
      acc |= x;
    }
    acc &= 0x7FFFFFFFu;
    uint64_t h[2];
    std::memcpy(h, &acc, sizeof h);
    if ((h[0] | h[1]) == 0) continue;
    for (int64_t j = 0; j < 32; ++j) take(i + j);
  }
  for (; i < T; ++i) take(i);
  total_ = G1;
  return !nz_i_.empty();
}

double TransientPrefix::G2_in_run(const Run& r, double a) const {
  auto b = static_cast<int64_t>(std::floor(a));
  b = std::clamp(b, r.s, r.e - 1);
  const double x = a - static_cast<double>(b);
  const size_t k = r.off + static_cast<size_t>(b - r.s);
  return G2_[k] + x * (G1_[k] + 0.5 * g_[k] * x);
}

void accumulate_edge_response(const TransientPrefix& p, const EdgeBins& e, double b0, double step, int K,
                              double sign, double* out) {
  const auto& runs = p.runs();
  const size_t R = runs.size(), M = e.u.size();
  if (R == 0) return;
  // ptr_s[r]: first knot with b + u_j >= s_r; ptr_e[r]: first with b + u_j >= e_r. Both only move down
  // as the gate position grows, so walking them costs O(M) per run over the whole sweep.
  std::vector<size_t> ptr_s(R), ptr_e(R);
  for (size_t r = 0; r < R; ++r) {
    ptr_s[r] = static_cast<size_t>(std::lower_bound(e.u.begin(), e.u.end(), static_cast<double>(runs[r].s) - b0) - e.u.begin());
    ptr_e[r] = static_cast<size_t>(std::lower_bound(e.u.begin(), e.u.end(), static_cast<double>(runs[r].e) - b0) - e.u.begin());
  }
  // Fast path: when no run overlaps the edge's support [b + u_0, b + u_M], every knot lies in one empty
  // stretch where G2 is linear with slope G1 (the mass before the stretch), and sum_j c_j G2(b + u_j) =
  // G1 sum_j c_j u_j (sum_j c_j = 0). rb: the first run that ends after b + u_0 (moves up with k).
  const double u_first = e.u.front(), u_last = e.u.back(), cu = e.C1[M];
  size_t rb = 0;
  for (int k = 0; k < K; ++k) {
    const double b = b0 + step * k;
    while (rb < R && static_cast<double>(runs[rb].e) <= b + u_first) ++rb;
    if (rb == R || static_cast<double>(runs[rb].s) >= b + u_last) {
      // The fast path holds, with the same rb, up to the first k' whose b' + u_M passes the start of run rb
      // (the same test, monotone in k'; before that b' + u_0 <= b' + u_M <= s < e, so rb stays): found by
      // bisection, then one constant added over the whole range.
      int k_end = K;
      if (rb < R) {
        const double s = static_cast<double>(runs[rb].s);
        int lo = k + 1, hi = K;  // every k' < lo passes; the first failing k' lies in [lo, hi]
        while (lo < hi) {
          const int mid = lo + (hi - lo) / 2;
          if (s >= b0 + step * mid + u_last) lo = mid + 1;
          else hi = mid;
        }
        k_end = lo;
      }
      const double v = sign * (rb > 0 ? runs[rb - 1].G1e * cu : 0.0);
      for (int j = k; j < k_end; ++j) out[j] += v;
      k = k_end - 1;
      continue;
    }
    // Runs before rb end before b + u_0: all their knot pointers are 0 and they add nothing, so the walk
    // starts at rb with the run before it as `prev` (the same sums in the same order as from run 0). It
    // stops after the first run that starts beyond b + u_M (every knot is then accounted for); the runs
    // it skips keep stale pointers, which only move down and are walked to the right place when read.
    double H = 0.0;
    size_t jprev = 0;
    const TransientPrefix::Run* prev = rb > 0 ? &runs[rb - 1] : nullptr;
    for (size_t r = rb; r < R; ++r) {
      const auto& run = runs[r];
      size_t& js = ptr_s[r];
      size_t& je = ptr_e[r];
      const double ts = static_cast<double>(run.s) - b, te = static_cast<double>(run.e) - b;
      while (js > 0 && e.u[js - 1] >= ts) --js;
      while (je > 0 && e.u[je - 1] >= te) --je;
      if (prev != nullptr && js > jprev) {
        const double sc = e.C0[js] - e.C0[jprev], scu = e.C1[js] - e.C1[jprev];
        H += prev->G2e * sc + prev->G1e * ((b - static_cast<double>(prev->e)) * sc + scu);
      }
      for (size_t j = js; j < je; ++j) H += e.c[j] * p.G2_in_run(run, b + e.u[j]);
      jprev = std::max(jprev, je);
      prev = &run;
      if (jprev == M) break;
    }
    if (jprev < M) {
      const double sc = e.C0[M] - e.C0[jprev], scu = e.C1[M] - e.C1[jprev];
      H += prev->G2e * sc + prev->G1e * ((b - static_cast<double>(prev->e)) * sc + scu);
    }
    out[k] += sign * H;
  }
}

int64_t integer_step(double step) {
  const double s = std::round(step);
  if (!(s >= 1.0 && s < 1e15)) return 0;
  return std::abs(step - s) <= 1e-14 * s ? static_cast<int64_t>(s) : 0;
}

// The integer-step loops (W by phase, the scatter, the plateau) are element-wise multiplies and adds, so an
// AVX2 clone (4 doubles per instruction, chosen at load time; no FMA, so the same roundings) gives the same
// bits as the baseline SSE2 build: 20 % less time for sparse transients, 37 % for dense ones (measured).
#if defined(__GNUC__) && defined(__x86_64__) && defined(__linux__)
#define SPADGEN_GATE_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define SPADGEN_GATE_CLONES
#endif

namespace {
int64_t floor_div(int64_t a, int64_t b) {  // b > 0
  const int64_t q = a / b;
  return (a % b != 0 && a < 0) ? q - 1 : q;
}
int64_t ceil_div(int64_t a, int64_t b) { return -floor_div(-a, b); }
}  // namespace

const TransientPrefix::StepTables& TransientPrefix::step_tables(const EdgeBins& e, int64_t s) {
  for (const StepTables& t : step_)
    if (t.id == e.id && t.s == s) return t;
  StepTables& t = step_[step_next_];
  step_next_ ^= 1;
  const int64_t L = e.L, qa = L / s, qb = L % s;
  const auto Ls = static_cast<size_t>(L);
  t.a.resize(Ls);
  t.b.resize(Ls);
  t.c.resize(Ls);
  t.pos.resize(Ls);
  for (int64_t k = 0; k < L; ++k) {
    const int64_t ph = k % s, at = ph * qa + std::min(ph, qb) + k / s;
    const auto i = static_cast<size_t>(at), ks = static_cast<size_t>(k);
    t.a[i] = e.wa[ks];
    t.b[i] = e.wb[ks];
    t.c[i] = e.wc[ks];
    t.pos[ks] = at;
  }
  t.a1 = t.a;
  t.b1 = t.b;
  t.c1 = t.c;
  t.crossing = 0;
  for (size_t q = 0; q < e.xr.size() && e.xr[q] > 0.0; ++q) {
    // + (-c w^2 / 2 at t_j, +c w^2 / 2 at t_j - 1), w = f + r_j - 1, as coefficients of 1, f, f^2
    const double c = e.xc[q], d = e.xr[q] - 1.0;
    const auto t0 = static_cast<size_t>(e.xt[q]);
    for (const auto& [at, sg] : {std::pair{t.pos[t0], -1.0}, std::pair{t.pos[t0 - 1], 1.0}}) {
      const auto i = static_cast<size_t>(at);
      t.a1[i] += sg * (0.5 * c * d * d);
      t.b1[i] += sg * (c * d);
      t.c1[i] += sg * (0.5 * c);
    }
    ++t.crossing;
  }
  t.id = e.id;
  t.s = s;
  return t;
}

SPADGEN_GATE_CLONES
void accumulate_edge_response_int(TransientPrefix& p, const EdgeBins& e, double b0, int64_t s, int K, double sign,
                                  double* out) {
  const std::vector<int64_t>& idx = p.bin_index();
  const std::vector<double>& val = p.bin_value();
  if (idx.empty() || K <= 0 || s < 1) return;
  const double Fd = std::floor(b0), f = b0 - Fd;  // exact
  const auto F = static_cast<int64_t>(Fd);
  const int64_t L = e.L, d_lo = e.d_lo, qa = L / s, qb = L % s;
  const auto Kl = static_cast<int64_t>(K);
  // Bin i reaches gate k at entry t = s k - (i - F + d_lo) of W: the window for k in [ka, kb), always in
  // phase t mod s = s ka - (i - F + d_lo); W = cu from kb on. Only the phases some bin uses are evaluated
  // (all of them when s > 64). (ka, ph) for ascending bins: one division, then steps (a division again
  // only after a long gap).
  struct Phase {
    int64_t s, base = 0, ka = 0, ph = 0;
    void to(int64_t b) {
      const int64_t delta = b - base;
      base = b;
      if (delta <= 8 * s) {
        ph -= delta;
        while (ph < 0) {
          ph += s;
          ++ka;
        }
      } else {
        ka = ceil_div(b, s);
        ph = s * ka - b;
      }
    }
  };
  const int64_t base0 = idx.front() - F + d_lo;
  const int64_t ka0 = ceil_div(base0, s);
  uint64_t phases = s > 64 ? ~uint64_t{0} : 0;
  if (s <= 64) {
    Phase walk{s, base0, ka0, s * ka0 - base0};
    for (const int64_t i : idx) {
      walk.to(i - F + d_lo);
      phases |= uint64_t{1} << static_cast<unsigned>(walk.ph);
    }
  }
  const TransientPrefix::StepTables& st = p.step_tables(e, s);
  std::vector<double>& work = p.scratch();
  const auto Ls = static_cast<size_t>(L);
  if (work.size() < Ls) work.resize(Ls);
  // The knots with r_j + f >= 1 come first in xr (descending): [0, nc) need the correction. With fewer of
  // them than the others (nc <= crossing - nc) the tables without corrections are used and those knots
  // corrected, else the tables with every correction and the knots [nc, crossing) have theirs taken out.
  const double* xr = e.xr.data();
  const size_t nc = static_cast<size_t>(std::partition_point(xr, xr + st.crossing, [f](double r) { return f + r >= 1.0; }) - xr);
  const bool all = nc > st.crossing - nc;
  const double *ta = all ? st.a1.data() : st.a.data(), *tb = all ? st.b1.data() : st.b.data(),
               *tc = all ? st.c1.data() : st.c.data();
  double* W = work.data();  // W by phase, laid out as the tables
  for (int64_t ph = 0; ph < std::min(s, L); ++ph) {
    if (ph < 64 && !(phases >> ph & 1)) continue;
    const auto o = static_cast<size_t>(ph * qa + std::min(ph, qb)), n = static_cast<size_t>(qa + (ph < qb ? 1 : 0));
    const double *a = ta + o, *b = tb + o, *c = tc + o;
    double* w = W + o;
    for (size_t q = 0; q < n; ++q) w[q] = a[q] + f * (b[q] + f * c[q]);
  }
  // entries of unused phases get junk, never read
  const double* xc = e.xc.data();
  const int64_t *xt = e.xt.data(), *pos = st.pos.data();
  const size_t q0 = all ? nc : 0, q1 = all ? st.crossing : nc;
  const double sg = all ? -1.0 : 1.0;
  for (size_t q = q0; q < q1; ++q) {
    const double w = (f + xr[q]) - 1.0, v = sg * (0.5 * xc[q] * w * w);
    const int64_t t = xt[q];
    W[pos[t]] -= v;
    W[pos[t - 1]] += v;
  }
  const double cu = e.C1[e.u.size()];
  double mass = 0.0;  // the content of the bins whose plateau has started at gate kc
  int64_t kc = 0;
  Phase walk{s, base0, ka0, s * ka0 - base0};
  for (size_t n = 0; n < idx.size(); ++n) {
    walk.to(idx[n] - F + d_lo);
    const int64_t ka = walk.ka, ph = walk.ph, kb = ka + qa + (ph < qb ? 1 : 0);  // ceil((base + L) / s)
    const int64_t ke = std::min(kb, Kl);
    if (ke > kc) {
      if (mass != 0.0) {
        const double v = sign * (mass * cu);
        for (int64_t k = kc; k < ke; ++k) out[k] += v;
      }
      kc = ke;
    }
    mass += val[n];
    const int64_t k0 = std::max<int64_t>(ka, 0);
    if (ke <= k0) continue;
    const double* Pp = W + (ph * qa + std::min(ph, qb)) + (k0 - ka);
    const double v = sign * val[n];
    double* o = out + k0;
    for (int64_t k = 0; k < ke - k0; ++k) o[k] += v * Pp[k];
  }
  if (kc < Kl && mass != 0.0) {
    const double v = sign * (mass * cu);
    for (int64_t k = kc; k < Kl; ++k) out[k] += v;
  }
}

}  // namespace spadgen::sensor
