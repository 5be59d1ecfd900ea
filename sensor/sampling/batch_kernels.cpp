// Compiled once per target by Highway's foreach_target; see batch_kernels.h.
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "sensor/sampling/batch_kernels.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>
#include <hwy/contrib/math/math-inl.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>

#include "sensor/sampling/batch_kernels.h"
#include "sensor/sampling/ars-inl.h"
#include "sensor/sampling/philox-inl.h"
#include "sensor/sampling/threshold-inl.h"

HWY_BEFORE_NAMESPACE();
namespace spadgen::sensor {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

// Above this rate exp(-lambda) is 0 in double (e^-745 is below the smallest subnormal); clamping keeps
// the vector exp in its documented range.
constexpr double kMaxLambda = 800.0;

template <class D>
HWY_INLINE hn::Vec<D> ClampRate(D d, hn::Vec<D> lam) {
  return hn::Min(hn::Max(lam, hn::Zero(d)), hn::Set(d, kMaxLambda));
}

void Probabilities(const double* HWY_RESTRICT lam, size_t K, double* HWY_RESTRICT p, double* q) {
  const hn::ScalableTag<double> d;
  const size_t L = hn::Lanes(d);
  size_t k = 0;
  for (; k + L <= K; k += L) {
    const auto nl = hn::Neg(ClampRate(d, hn::LoadU(d, lam + k)));
    hn::StoreU(hn::Neg(hn::Expm1(d, nl)), d, p + k);
    if (q != nullptr) hn::StoreU(hn::Exp(d, nl), d, q + k);
  }
  if (k < K) {  // the tail through a padded copy
    alignas(64) double t[64] = {}, tp[64], tq[64];
    std::copy(lam + k, lam + K, t);
    Probabilities(t, L, tp, q != nullptr ? tq : nullptr);
    std::copy(tp, tp + (K - k), p + k);
    if (q != nullptr) std::copy(tq, tq + (K - k), q + k);
  }
}

void CrosstalkRates(const double* HWY_RESTRICT lam, size_t K, const double* const* nb, int nnb, double xt,
                    bool single_avalanche, double* HWY_RESTRICT out) {
  const hn::ScalableTag<double> d;
  const size_t L = hn::Lanes(d);
  const auto vxt = hn::Set(d, xt), one = hn::Set(d, 1.0), inf = hn::Set(d, HUGE_VAL);
  const auto half = hn::Set(d, 0.5);
  auto rate = [&](const double* l, const double* const* n, double* o, size_t count) {
    for (size_t k = 0; k < count; k += L) {
      auto v = hn::LoadU(d, l + k);
      if (!single_avalanche) {
        for (int i = 0; i < nnb; ++i) v = hn::MulAdd(vxt, hn::LoadU(d, n[i] + k), v);
        hn::StoreU(v, d, o + k);
        continue;
      }
      // Pixel B: a neighbour that avalanches at most once per frame fires this pixel with y_i = xt p_i, so
      // the rate gains -log prod_i (1 - y_i), with one logarithm for all neighbours: s = 1 - prod (1 - y_i)
      // by s <- s + y (1 - s) (all terms >= 0, a few ulp relative to s) and P = prod (1 - y_i) (1 - y is
      // exact for y >= 1/2). -log1p(-s) while s < 1/2, else -log(P) (P <= 1/2 then, so its relative error
      // is a small absolute error of the logarithm). Any y >= 1 gives infinity.
      auto sv = hn::Zero(d), P = one;
      auto sure = hn::Lt(one, hn::Zero(d));  // all false
      for (int i = 0; i < nnb; ++i) {
        const auto y = hn::Mul(vxt, hn::LoadU(d, n[i] + k));
        sure = hn::Or(sure, hn::Ge(y, one));
        sv = hn::MulAdd(y, hn::Sub(one, sv), sv);
        P = hn::Mul(P, hn::Sub(one, y));
      }
      hn::Vec<decltype(d)> t;
      if (hn::AllTrue(d, hn::Lt(sv, hn::Set(d, 1.0 / 32)))) {
        // the common case (xt p small for every neighbour): -log1p(-s) = s + s^2 / 2 + ... + s^13 / 13,
        // truncated below s^13 / 13 < 1e-19 s
        auto c = hn::Set(d, 1.0 / 13);
        for (int j = 12; j >= 1; --j) c = hn::MulAdd(c, sv, hn::Set(d, 1.0 / j));
        t = hn::Mul(c, sv);
      } else {
        const auto low = hn::Lt(sv, half);
        t = hn::Neg(hn::Log1p(d, hn::Neg(hn::IfThenElse(low, sv, hn::Zero(d)))));
        if (!hn::AllTrue(d, low)) t = hn::IfThenElse(low, t, hn::Neg(hn::Log(d, hn::IfThenElse(low, one, P))));
      }
      v = hn::Add(v, hn::IfThenElse(sure, inf, t));
      hn::StoreU(v, d, o + k);
    }
  };
  const size_t full = K / L * L;
  rate(lam, nb, out, full);
  if (full < K) {
    alignas(64) double tl[64] = {}, tn[4][64] = {}, to[64];
    const double* pn[4];
    std::copy(lam + full, lam + K, tl);
    for (int i = 0; i < nnb; ++i) {
      std::copy(nb[i] + full, nb[i] + K, tn[i]);
      pn[i] = tn[i];
    }
    rate(tl, pn, to, L);
    std::copy(to, to + (K - full), out + full);
  }
}

// The counts' random words of every k < K, counter (0, k, pixel low, pixel high), on the widest vectors:
// without ars (the walk from the mode) words 0 and 1 of Philox block 0 of the stream
// Rng(seed, Counts, pixel, k) into s.hi, s.lo; with ars (the tables) the four words of ARS-7 with the
// key ars_key(key) (sensor/ars.h) into s.hi, s.lo, s.hi2, s.lo2. Then the rates copied into s.lam, padded
// with zeros to whole vectors of doubles.
void CountsBlock0AndRates(const uint32_t key[2], size_t K, uint64_t pixel, bool ars, const double* lam_in,
                          KernelScratch& s) {
  const hn::ScalableTag<uint32_t> du;
  const size_t Lu = hn::Lanes(du);
  const auto plo = hn::Set(du, static_cast<uint32_t>(pixel)), phi = hn::Set(du, static_cast<uint32_t>(pixel >> 32));
  // Iota once: Highway 1.0's Iota stores the lanes one by one and reloads them as a vector (a stalled
  // store forwarding per call)
  const auto iota = hn::Iota(du, 0u);
  if (ars) {  // ARS-7 (the tables' draws), key ars_key(key)
    const ArsKeys keys = ars_round_keys(ars_key(key));
    for (size_t k = 0; k < K; k += Lu) {
      auto x0 = hn::Zero(du), x1 = hn::Add(iota, hn::Set(du, static_cast<uint32_t>(k))), x2 = plo, x3 = phi;
      Ars7Words(du, keys, x0, x1, x2, x3);
      hn::StoreU(x0, du, s.hi.data() + k);
      hn::StoreU(x1, du, s.lo.data() + k);
      hn::StoreU(x2, du, s.hi2.data() + k);
      hn::StoreU(x3, du, s.lo2.data() + k);
    }
  } else {  // Philox4x32-10: block 0 of the stream Rng(seed, Counts, pixel, k)
    for (size_t k = 0; k < K; k += Lu) {
      auto x0 = hn::Zero(du), x1 = hn::Add(iota, hn::Set(du, static_cast<uint32_t>(k))), x2 = plo, x3 = phi;
      Philox10(du, key[0], key[1], x0, x1, x2, x3);
      hn::StoreU(x0, du, s.hi.data() + k);
      hn::StoreU(x1, du, s.lo.data() + k);
    }
  }
  const size_t L = hn::Lanes(hn::ScalableTag<double>());
  std::copy(lam_in, lam_in + K, s.lam.data());
  std::fill(s.lam.begin() + static_cast<std::ptrdiff_t>(K), s.lam.begin() + static_cast<std::ptrdiff_t>((K + L - 1) / L * L), 0.0);
}

void BinomialCounts(const double* HWY_RESTRICT lam_in, size_t K, const uint32_t key[2], uint64_t pixel,
                    const BinomialSampler& sampler, KernelScratch& s) {
  const uint32_t N = sampler.n();
  CountsBlock0AndRates(key, K, pixel, /*ars=*/false, lam_in, s);  // U = word 0 << 32 | word 1
  const hn::ScalableTag<double> d;
  const size_t L = hn::Lanes(d);
  const hn::RebindToUnsigned<decltype(d)> d64;
  const hn::RebindToSigned<decltype(d)> di64;
  const hn::Rebind<uint32_t, decltype(d)> d32;
  const auto vN = hn::Set(d, static_cast<double>(N)), one = hn::Set(d, 1.0), half = hn::Set(d, 0.5);
  const hn::Rebind<int32_t, decltype(d)> di32;
  const auto two64 = hn::Set(d, 0x1p64), mode_from = hn::Set(d, BinomialSampler::mode_search_from());
  const double* lf = sampler.log_factorials().data();
  const auto lfN = hn::Set(d, lf[N]);
  const double* up = sampler.up().data();
  const double* down = sampler.down().data();
  for (size_t k = 0; k < K; k += L) {
    const auto lam = ClampRate(d, hn::LoadU(d, s.lam.data() + k));
    const auto nl = hn::Neg(lam);
    const auto p = hn::Neg(hn::Expm1(d, nl));
    hn::StoreU(p, d, s.p.data() + k);
    // q = 1 - p is exact to 1 ulp while p < 3/8; beyond, exp(-lambda) keeps q's relative precision
    const auto low_p = hn::Lt(p, hn::Set(d, 0.375));
    const auto q = hn::AllTrue(d, low_p) ? hn::Sub(one, p) : hn::IfThenElse(low_p, hn::Sub(one, p), hn::Exp(d, nl));
    const auto small = hn::Le(p, q);  // X counts detections (else misses, and the count is N - X)
    const auto a = hn::IfThenElse(small, p, q), b = hn::IfThenElse(small, q, p);
    const auto mean = hn::Mul(vN, a);
    const auto U = hn::Or(hn::ShiftLeft<32>(hn::PromoteTo(d64, hn::LoadU(d32, s.hi.data() + k))),
                          hn::PromoteTo(d64, hn::LoadU(d32, s.lo.data() + k)));
    // X = 0: no detection (small) or no miss
    hn::StoreU(hn::BitCast(d32, hn::DemoteTo(di32, hn::IfThenZeroElse(small, vN))), d32, s.x.data() + k);
    // P(X > 0) <= n a: where U >= floor(n a 2^64) (and n a < 1) X = 0 without computing P(X > 0)
    const auto below_one = hn::Lt(mean, one);
    const auto thr_mean = ProbabilityThreshold(d, hn::IfThenElseZero(below_one, mean));
    const auto mode = hn::Ge(mean, mode_from);
    const auto undecided = hn::Or(hn::Not(below_one), hn::RebindMask(d, hn::Lt(U, thr_mean)));
    if (hn::AllFalse(d, undecided)) continue;
    // log b: -lambda exactly when b = q; log1p(-q) when b = p (log(p) would lose q's digits)
    const auto log_b = hn::AllTrue(d, small) ? nl : hn::IfThenElse(small, nl, hn::Log1p(d, hn::Neg(a)));
    // P(X > 0) and P(X = 0) for the lanes that search from 0; not computed when every lane searches from
    // the mode.
    const bool all_mode = hn::AllTrue(d, mode);
    auto need = mode;
    auto S0 = hn::Zero(d), P0 = hn::Zero(d);
    if (!all_mode) {
      const auto nlb = hn::Mul(vN, log_b);
      S0 = hn::Neg(hn::Expm1(d, nlb));
      const auto x = hn::Mul(S0, two64);
      const auto thr = ProbabilityThreshold(d, S0);
      // S0 = 1 (saturated in double) is left to the scalar search, which uses the same threshold rule
      need = hn::Or(hn::Or(hn::RebindMask(d, hn::Lt(U, thr)), mode), hn::Ge(x, two64));
      if (HWY_LIKELY(hn::AllFalse(d, need))) continue;
      P0 = hn::IfThenElse(hn::Lt(S0, half), hn::Sub(one, S0), hn::Exp(d, nlb));
    }
    const auto r = hn::Div(a, b);
    auto xs = hn::Zero(d);  // the count of the rarer outcome, as BinomialSampler's searches find it
    // Sequential search from 0 (n a < 16), as BinomialSampler::search_from_zero, on all lanes at once. The
    // sums are updated on every lane (a finished lane's values are no longer read), so the only loop-carried
    // chains are pmf and S; `done` records where each lane's scalar loop would have stopped.
    if (!all_mode) {
      auto done = hn::Not(hn::AndNot(mode, need));
      auto S = S0, pmf = P0;
      for (uint32_t it = 0; !hn::AllTrue(d, done); ++it) {
        // every lane still searching is at x = it
        const auto cont = hn::AndNot(done, hn::And(hn::Lt(xs, vN), hn::RebindMask(d, hn::Lt(U, ProbabilityThreshold(d, S)))));
        pmf = hn::Mul(pmf, hn::Mul(r, hn::Set(d, up[std::min(it, N)])));
        S = hn::Sub(S, pmf);
        xs = hn::IfThenElse(cont, hn::Add(xs, one), xs);
        done = hn::Or(hn::Not(cont), hn::Or(done, hn::Not(hn::Gt(S, hn::Zero(d)))));
      }
    }
    // Inversion from the mode (n a >= 16) in the order m, m-1, m+1, ..., as search_from_mode. u decreases
    // step by step; a lane's result is where u first falls below 0 (or m when both sides are exhausted).
    if (!hn::AllFalse(d, mode)) {
      const auto m = hn::Min(hn::Floor(hn::Mul(hn::Add(vN, one), a)), vN);
      const auto mi = hn::ConvertTo(di64, m);
      const auto lfm = hn::GatherIndex(d, lf, mi), lfnm = hn::GatherIndex(d, lf, hn::Sub(hn::Set(di64, N), mi));
      // lanes with a = 0 are never in mode; their log is masked away
      const auto log_a = hn::Log(d, hn::IfThenElse(mode, a, one));
      const auto pm = hn::Exp(d, hn::Add(hn::Sub(hn::Sub(lfN, lfm), lfnm),
                                         hn::MulAdd(m, log_a, hn::Mul(hn::Sub(vN, m), log_b))));
      const auto r_inv = hn::Div(b, a);
      const auto zero = hn::Zero(d);
      const auto u0 = hn::Sub(hn::Mul(hn::ConvertTo(d, hn::BitCast(di64, hn::ShiftRight<11>(U))), hn::Set(d, 0x1p-53)), pm);
      // Fast walk while no lane can reach 0 or n (iteration i <= min(m, n - m) over the lanes; other lanes
      // index from n / 2): both sides move at every iteration, so the order of the terms is fixed and, as u
      // only decreases, the result follows from C = the number of terms after which u is still >= 0
      // (counting u0 = U - pm): C = 0 gives m, C odd m - (C + 1) / 2 (a lo step), C even m + C / 2 (a hi
      // step). The same products and differences as the exact walk below, without its per-step masks and
      // blends; a vector that runs past the bound is redone by the exact walk.
      bool fast_done = false;
      {
        const auto mm = hn::IfThenElse(mode, m, hn::Set(d, static_cast<double>(N / 2)));
        alignas(64) double bound[hn::MaxLanes(d)];
        hn::Store(hn::Min(mm, hn::Sub(vN, mm)), d, bound);
        double i_max = bound[0];
        for (size_t j = 1; j < L; ++j) i_max = std::min(i_max, bound[j]);
        auto fu = hn::IfThenElse(mode, u0, hn::Set(d, -1.0));
        const auto i_one = hn::Set(di64, 1);
        auto ge = hn::Ge(fu, zero);
        // C as 64-bit integers (a masked integer add per term: a short loop-carried chain)
        auto fc = hn::IfThenElseZero(hn::RebindMask(di64, ge), i_one);
        auto f_lo = pm, f_hi = pm;
        auto flo_i = hn::ConvertTo(di64, mm), fhi_i = flo_i;
        for (double i = 0.0; !hn::AllFalse(d, ge) && i < i_max; i += 1.0) {
          const auto dn = hn::GatherIndex(d, down, flo_i);
          const auto upx = hn::GatherIndex(d, up, fhi_i);
          flo_i = hn::Sub(flo_i, i_one);
          fhi_i = hn::Add(fhi_i, i_one);
          f_lo = hn::Mul(f_lo, hn::Mul(dn, r_inv));
          fu = hn::Sub(fu, f_lo);
          fc = hn::IfThenElse(hn::RebindMask(di64, hn::Ge(fu, zero)), hn::Add(fc, i_one), fc);
          f_hi = hn::Mul(f_hi, hn::Mul(r, upx));
          fu = hn::Sub(fu, f_hi);
          ge = hn::Ge(fu, zero);
          fc = hn::IfThenElse(hn::RebindMask(di64, ge), hn::Add(fc, i_one), fc);
        }
        if (hn::AllFalse(d, ge)) {
          const auto h = hn::ConvertTo(d, hn::ShiftRight<1>(hn::Add(fc, i_one)));  // floor((C + 1) / 2)
          const auto odd = hn::RebindMask(d, hn::Eq(hn::And(fc, i_one), i_one));
          xs = hn::IfThenElse(mode, hn::IfThenElse(odd, hn::Sub(m, h), hn::Add(m, h)), xs);
          fast_done = true;
        }
      }
      if (!fast_done) {
      auto u = u0;
      auto res = m, lo = m, hi = m, p_lo = pm, p_hi = pm;
      // indices max(m - i, 0) and min(m + i, n) at step i
      auto lo_i = mi, hi_i = mi;
      const auto i_one = hn::Set(di64, 1), i_zero = hn::Zero(di64), i_n = hn::Set(di64, N);
      auto open = hn::And(mode, hn::Ge(u, zero));  // lanes whose u has not fallen below 0 yet
      while (!hn::AllFalse(d, open)) {
        const auto can_lo = hn::Gt(lo, zero), can_hi = hn::Lt(hi, vN);
        const auto dn = hn::GatherIndex(d, down, lo_i);
        const auto upx = hn::GatherIndex(d, up, hi_i);
        lo_i = hn::Max(hn::Sub(lo_i, i_one), i_zero);
        hi_i = hn::Min(hn::Add(hi_i, i_one), i_n);
        p_lo = hn::IfThenElse(can_lo, hn::Mul(p_lo, hn::Mul(dn, r_inv)), p_lo);
        lo = hn::IfThenElse(can_lo, hn::Sub(lo, one), lo);
        u = hn::IfThenElse(can_lo, hn::Sub(u, p_lo), u);
        const auto hit_lo = hn::And(open, hn::Lt(u, zero));
        res = hn::IfThenElse(hit_lo, lo, res);
        open = hn::AndNot(hit_lo, open);
        p_hi = hn::IfThenElse(can_hi, hn::Mul(p_hi, hn::Mul(r, upx)), p_hi);
        hi = hn::IfThenElse(can_hi, hn::Add(hi, one), hi);
        u = hn::IfThenElse(can_hi, hn::Sub(u, p_hi), u);
        const auto hit_hi = hn::And(open, hn::Lt(u, zero));
        res = hn::IfThenElse(hit_hi, hi, res);
        open = hn::AndNot(hit_hi, open);
        // neither side can move: U beyond the rounded total probability, the mode
        open = hn::And(open, hn::Or(can_lo, can_hi));
      }
      xs = hn::IfThenElse(mode, res, xs);
      }
    }
    const auto count = hn::IfThenElse(small, xs, hn::Sub(vN, xs));
    hn::StoreU(hn::BitCast(d32, hn::DemoteTo(di32, count)), d32, s.x.data() + k);
  }
}

// Gathers of 64-bit lanes for the table sampler: on AVX2, four scalar loads (AMD's vpgatherqq, microcoded
// on Zen 1-3, was slower); elsewhere Highway's gathers. Offsets in bytes, indices in elements.
template <class D, typename T>
HWY_INLINE hn::Vec<D> Gather64Offset(D d, const T* HWY_RESTRICT base, hn::Vec<hn::RebindToSigned<D>> off) {
#if HWY_ARCH_X86 && HWY_TARGET == HWY_AVX2
  if constexpr (sizeof(hn::Vec<D>) == 32) {
    alignas(32) int64_t o[4];
    hn::Store(off, hn::RebindToSigned<D>(), o);
    const auto* b = reinterpret_cast<const char*>(base);
    alignas(32) hn::TFromD<D> v[4];
    for (int j = 0; j < 4; ++j) std::memcpy(&v[j], b + o[j], sizeof(v[j]));
    return hn::Load(d, v);
  }
#endif
  return hn::GatherOffset(d, base, off);
}
template <class D, typename T>
HWY_INLINE hn::Vec<D> Gather64Index(D d, const T* HWY_RESTRICT base, hn::Vec<hn::RebindToSigned<D>> idx) {
  static_assert(sizeof(T) == 8);
  return Gather64Offset(d, base, hn::ShiftLeft<3>(idx));
}

// Counts by the tables of BinomialTable (see binomial_table.h), all K gates of one pixel: the ARS-7 block
// with counter (0, k, pixel) gives U1 (words 0, 1) and U2 (words 2, 3). Per vector of gates: the
// grid row g = floor(a G); X1 from the guide and a step or two up the row, comparing the top 16 bits of T
// and U1 (gathers from tables that stay in cache); Y = 0 where U2 >= floor((n - X1) delta 2^64). Lanes with
// equal top bits take BinomialTable::first_round, lanes with a possible Y > 0 second_round.
void BinomialCountsTable(const double* HWY_RESTRICT lam_in, size_t K, const uint32_t key[2], uint64_t pixel,
                         const BinomialTable& table, KernelScratch& s) {
  const uint32_t N = table.n();
  CountsBlock0AndRates(key, K, pixel, /*ars=*/true, lam_in, s);
  const hn::ScalableTag<double> d;
  const size_t L = hn::Lanes(d);
  const hn::RebindToUnsigned<decltype(d)> d64;
  const hn::RebindToSigned<decltype(d)> di64;
  const hn::Rebind<uint32_t, decltype(d)> d32;
  const hn::Rebind<int32_t, decltype(d)> di32;
  const auto vN = hn::Set(d, static_cast<double>(N)), one = hn::Set(d, 1.0);
  const auto grid = hn::Set(d, static_cast<double>(BinomialTable::kGrid));
  const auto inv_grid = hn::Set(d, 1.0 / BinomialTable::kGrid);
  const auto u_cap = hn::Set(d64, ~uint64_t{0} - 1);
  const auto low32 = hn::Set(di64, 0xFFFFFFFF);
  const auto byte_mask = hn::Set(di64, 0xFF), u16_mask = hn::Set(di64, 0xFFFF);
  const int64_t* rows = table.row();
  const double* inv1m = table.inv_one_minus_p();
  const auto* t16 = reinterpret_cast<const int64_t*>(table.thresholds16());
  const auto* guide = reinterpret_cast<const int64_t*>(table.guide());
  // The gathers of one vector depend on each other (guide -> row entry -> next entry), so the vectors go
  // through each stage together: every stage's gathers are independent and their latencies overlap.
  double* delta_a = s.delta.data();  // per k: delta, the grid index g, U1 (capped), the row, the entry
  double* g_a = s.grid.data();
  uint64_t* U1_a = s.U1.data();
  int64_t* row_a = s.row.data();
  int64_t* i_a = s.idx.data();
  int64_t* scalar_a = s.scalar.data();  // lanes left to the scalar search
  int64_t* bound_a = s.bound.data();
  for (size_t k = 0; k < K; k += L) {  // stage 1: probabilities, grid row, guide
    const auto nl = hn::Neg(ClampRate(d, hn::LoadU(d, s.lam.data() + k)));
    const auto p = hn::Neg(hn::Expm1(d, nl));
    hn::StoreU(p, d, s.p.data() + k);
    // q = 1 - p is exact to 1 ulp while p < 3/8; beyond, exp(-lambda) keeps q's relative precision
    const auto low_p = hn::Lt(p, hn::Set(d, 0.375));
    const auto q = hn::AllTrue(d, low_p) ? hn::Sub(one, p) : hn::IfThenElse(low_p, hn::Sub(one, p), hn::Exp(d, nl));
    hn::StoreU(q, d, s.q.data() + k);
    const auto a = hn::Min(p, q);  // X counts the rarer outcome
    const auto g = hn::Floor(hn::Mul(a, grid));
    const auto pg = hn::Mul(g, inv_grid);
    const auto gi = hn::ConvertTo(di64, g);
    hn::StoreU(hn::Mul(hn::Sub(a, pg), Gather64Index(d, inv1m, gi)), d, delta_a + k);
    hn::StoreU(g, d, g_a + k);
    const auto U1 = hn::Min(hn::Or(hn::ShiftLeft<32>(hn::PromoteTo(d64, hn::LoadU(d32, s.hi.data() + k))),
                                   hn::PromoteTo(d64, hn::LoadU(d32, s.lo.data() + k))), u_cap);
    hn::StoreU(U1, d64, U1_a + k);
    hn::StoreU(Gather64Index(di64, rows, gi), di64, row_a + k);
    // bytes b and b + 1 of the row's guide: X1 - lo lies between them (bucket 255: below 256)
    const auto bucket = hn::BitCast(di64, hn::ShiftRight<64 - BinomialTable::kGuideBits>(U1));
    const auto gv = Gather64Offset(di64, guide, hn::Add(hn::ShiftLeft<BinomialTable::kGuideBits>(gi), bucket));
    hn::StoreU(hn::And(gv, byte_mask), di64, i_a + k);
    hn::StoreU(hn::IfThenElse(hn::Eq(bucket, byte_mask), byte_mask, hn::And(hn::ShiftRight<8>(gv), byte_mask)), di64, bound_a + k);
  }
  // stages 2 and 3: one step up the row each, where T(x) < U1 in the top 16 bits. After them a lane is
  // settled unless its top bits were equal to T's (a tie) or it stepped in stage 3 and is still below the
  // guide's bound (U1 in a bucket that several outcomes share: the tails); those take the scalar search.
  for (int stage = 0; stage < 2; ++stage)
    for (size_t k = 0; k < K; k += L) {
      const auto i = hn::LoadU(di64, i_a + k);
      const auto u_top = hn::BitCast(di64, hn::ShiftRight<48>(hn::LoadU(d64, U1_a + k)));
      const auto t = hn::And(Gather64Offset(di64, t16, hn::ShiftLeft<1>(hn::Add(hn::And(hn::LoadU(di64, row_a + k), low32), i))), u16_mask);
      const auto step = hn::VecFromMask(di64, hn::Lt(t, u_top));
      const auto i_next = hn::Sub(i, step);  // + 1 where T(x) < U1
      auto scalar = hn::VecFromMask(di64, hn::Eq(t, u_top));
      if (stage == 1)
        scalar = hn::Or(hn::Or(scalar, hn::LoadU(di64, scalar_a + k)),
                        hn::And(step, hn::VecFromMask(di64, hn::Lt(i_next, hn::LoadU(di64, bound_a + k)))));
      hn::StoreU(scalar, di64, scalar_a + k);
      hn::StoreU(i_next, di64, i_a + k);
    }
  for (size_t k = 0; k < K; k += L) {  // stage 4: the rest, and the second round
    const auto row = hn::LoadU(di64, row_a + k);
    auto i = hn::LoadU(di64, i_a + k);
    const auto scalar = hn::MaskFromVec(hn::LoadU(di64, scalar_a + k));
    auto x1 = hn::ConvertTo(d, hn::Add(hn::ShiftRight<32>(row), i));
    if (HWY_UNLIKELY(!hn::AllFalse(di64, scalar))) {
      alignas(64) double xa[hn::MaxLanes(d)];
      alignas(64) int64_t sa[hn::MaxLanes(d)];
      hn::Store(x1, d, xa);
      hn::Store(hn::VecFromMask(di64, scalar), di64, sa);
      for (size_t j = 0; j < L; ++j)
        if (sa[j] != 0) xa[j] = table.first_round(U1_a[k + j], static_cast<uint32_t>(g_a[k + j]));
      x1 = hn::Load(d, xa);
    }
    // second round: Y = 0 where U2 >= floor((N - X1) delta 2^64) ((N - X1) delta < 0.2 always)
    const auto delta = hn::LoadU(d, delta_a + k);
    const auto n2 = hn::Sub(vN, x1);
    const auto mean2 = hn::Mul(n2, delta);
    const auto U2 = hn::Or(hn::ShiftLeft<32>(hn::PromoteTo(d64, hn::LoadU(d32, s.hi2.data() + k))),
                           hn::PromoteTo(d64, hn::LoadU(d32, s.lo2.data() + k)));
    auto x = x1;
    const auto search = hn::RebindMask(d, hn::Lt(U2, ProbabilityThreshold(d, mean2)));
    if (HWY_UNLIKELY(!hn::AllFalse(d, search))) {
      // Y = 0 or 1 as second_round decides them: S0 = P(Y > 0) by the series, S1 = S0 - P(Y = 1)
      auto lp = hn::Set(d, BinomialTable::kLog1pCoeff[0]);
      for (int j = 1; j < 6; ++j) lp = hn::MulAdd(lp, delta, hn::Set(d, BinomialTable::kLog1pCoeff[j]));
      const auto lx = hn::Mul(n2, hn::Mul(hn::Neg(delta), lp));
      auto e = hn::Set(d, BinomialTable::kExpm1Coeff[0]);
      for (int j = 1; j < 14; ++j) e = hn::MulAdd(e, lx, hn::Set(d, BinomialTable::kExpm1Coeff[j]));
      e = hn::MulAdd(e, lx, one);
      const auto S0 = hn::Neg(hn::Mul(lx, e));
      auto r = hn::Add(one, delta);  // BinomialTable::odds: delta (1 + delta + ... + delta^4)
      for (int j = 0; j < 3; ++j) r = hn::MulAdd(r, delta, one);
      r = hn::Mul(delta, r);
      const auto S1 = hn::Sub(S0, hn::Mul(hn::Sub(one, S0), hn::Mul(r, n2)));
      const auto y1 = hn::And(search, hn::RebindMask(d, hn::Lt(U2, ProbabilityThreshold(d, S0))));  // Y >= 1
      const auto y2 = hn::And(y1, hn::And(hn::Gt(n2, one), hn::And(hn::Gt(S1, hn::Zero(d)),
                                                                    hn::RebindMask(d, hn::Lt(U2, ProbabilityThreshold(d, S1))))));
      x = hn::IfThenElse(y1, hn::Add(x1, one), x1);
      if (HWY_UNLIKELY(!hn::AllFalse(d, y2))) {  // Y >= 2: the whole search, lane by lane
        alignas(64) double xa[hn::MaxLanes(d)], n2a[hn::MaxLanes(d)];
        alignas(64) uint64_t u2a[hn::MaxLanes(d)];
        alignas(64) int64_t need[hn::MaxLanes(d)];
        hn::Store(x, d, xa);
        hn::Store(n2, d, n2a);
        hn::Store(U2, d64, u2a);
        hn::Store(hn::VecFromMask(di64, hn::RebindMask(di64, y2)), di64, need);
        for (size_t j = 0; j < L; ++j)
          if (need[j] != 0) xa[j] = (xa[j] - 1.0) + table.second_round(u2a[j], static_cast<uint32_t>(n2a[j]), delta_a[k + j]);
        x = hn::Load(d, xa);
      }
    }
    const auto p = hn::LoadU(d, s.p.data() + k), q = hn::LoadU(d, s.q.data() + k);
    const auto count = hn::IfThenElse(hn::Le(p, q), x, hn::Sub(vN, x));  // detections, or N - misses
    hn::StoreU(hn::BitCast(d32, hn::DemoteTo(di32, count)), d32, s.x.data() + k);
  }
}

// dst[k * dst_stride + x] = src[x * K + k]: one gather of a vector of pixels per k.
template <typename T>
void TransposeRowsImpl(const T* HWY_RESTRICT src, size_t width, size_t K, T* HWY_RESTRICT dst, size_t dst_stride) {
  const hn::ScalableTag<int32_t> di;
  const size_t L = hn::Lanes(di);
  size_t x0 = 0;
  if (K * width < (size_t{1} << 30)) {
    const auto stride = hn::Set(di, static_cast<int32_t>(K * sizeof(T)));
    const auto offs = hn::Mul(hn::Iota(di, 0), stride);
    for (; x0 + L <= width; x0 += L) {
      const auto* base = reinterpret_cast<const int32_t*>(src + x0 * K);
      for (size_t k = 0; k < K; ++k) {
        const auto v = hn::GatherOffset(di, reinterpret_cast<const int32_t*>(reinterpret_cast<const T*>(base) + k), offs);
        if constexpr (sizeof(T) == 4) {
          hn::StoreU(hn::BitCast(hn::Rebind<T, decltype(di)>(), v), hn::Rebind<T, decltype(di)>(), dst + k * dst_stride + x0);
        } else {  // 16-bit: the low half of each 4-byte read (src holds one more element)
          const hn::Rebind<uint16_t, decltype(di)> d16;
          hn::StoreU(hn::DemoteTo(d16, hn::And(v, hn::Set(di, 0xFFFF))), d16, reinterpret_cast<uint16_t*>(dst) + k * dst_stride + x0);
        }
      }
    }
  }
  for (size_t k = 0; k < K; ++k)
    for (size_t x = x0; x < width; ++x) dst[k * dst_stride + x] = src[x * K + k];
}

void TransposeRowsF(const float* src, size_t width, size_t K, float* dst, size_t dst_stride) {
  TransposeRowsImpl(src, width, K, dst, dst_stride);
}
void TransposeRowsU16(const uint16_t* src, size_t width, size_t K, uint16_t* dst, size_t dst_stride) {
  TransposeRowsImpl(src, width, K, dst, dst_stride);
}

// Prob {p, q, -lambda} of K rates: out[k * stride] (stride 1: one interleaved store per vector), and p
// alone into p_out[k] when p_out is not null. The same p and q as Probabilities.
void ProbsOfRates(const double* HWY_RESTRICT lam, size_t K, double* HWY_RESTRICT p_out, Prob* out, size_t stride) {
  const hn::ScalableTag<double> d;
  const size_t L = hn::Lanes(d);
  alignas(64) double tl[hn::MaxLanes(d)], tp[hn::MaxLanes(d)], tq[hn::MaxLanes(d)];
  for (size_t k = 0; k < K; k += L) {
    const size_t c = std::min(L, K - k);
    hn::Vec<decltype(d)> l;
    if (c == L) {
      l = hn::LoadU(d, lam + k);
    } else {
      std::fill(tl, tl + L, 0.0);
      std::copy(lam + k, lam + K, tl);
      l = hn::Load(d, tl);
    }
    const auto nl = hn::Neg(ClampRate(d, l));
    const auto p = hn::Neg(hn::Expm1(d, nl)), q = hn::Exp(d, nl);
    if (c == L && stride == 1) {
      hn::StoreInterleaved3(p, q, hn::Neg(l), d, reinterpret_cast<double*>(out + k));
      if (p_out != nullptr) hn::StoreU(p, d, p_out + k);
      continue;
    }
    hn::Store(p, d, tp);
    hn::Store(q, d, tq);
    for (size_t j = 0; j < c; ++j) {
      out[(k + j) * stride] = Prob{tp[j], tq[j], -lam[k + j]};
      if (p_out != nullptr) p_out[k + j] = tp[j];
    }
  }
}

const char* KernelTarget() { return hwy::TargetName(HWY_TARGET); }

}  // namespace HWY_NAMESPACE
}  // namespace spadgen::sensor
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace spadgen::sensor {

HWY_EXPORT(Probabilities);
HWY_EXPORT(ProbsOfRates);
HWY_EXPORT(CrosstalkRates);
HWY_EXPORT(BinomialCounts);
HWY_EXPORT(BinomialCountsTable);
HWY_EXPORT(TransposeRowsF);
HWY_EXPORT(TransposeRowsU16);

void KernelScratch::reserve(size_t K) {
  const size_t n = (K + 15) / 16 * 16 + 16;
  for (auto* v : {&lam, &p, &q, &delta, &grid}) v->resize(n);
  U1.resize(n);
  for (auto* v : {&hi, &lo, &hi2, &lo2, &x}) v->resize(n);
  for (auto* v : {&row, &idx, &bound, &scalar}) v->resize(n);
}

void probabilities(const double* lam, size_t K, double* p, double* q) {
  HWY_DYNAMIC_DISPATCH(Probabilities)(lam, K, p, q);
}

void probabilities(const double* lam, size_t K, Prob* out, size_t stride, double* p) {
  static_assert(sizeof(Prob) == 3 * sizeof(double), "Prob is three doubles, stored interleaved");
  HWY_DYNAMIC_DISPATCH(ProbsOfRates)(lam, K, p, out, stride);
}

void crosstalk_rates(const double* lam, size_t K, const double* const* nb, int nnb, double xt,
                     bool single_avalanche, double* out) {
  HWY_DYNAMIC_DISPATCH(CrosstalkRates)(lam, K, nb, nnb, xt, single_avalanche, out);
}

void binomial_counts(const double* lam, size_t K, const uint32_t key[2], uint64_t pixel,
                     const BinomialSampler& sampler, KernelScratch& s) {
  s.reserve(K);
  HWY_DYNAMIC_DISPATCH(BinomialCounts)(lam, K, key, pixel, sampler, s);
}

void binomial_counts(const double* lam, size_t K, const uint32_t key[2], uint64_t pixel, const BinomialTable& table,
                     KernelScratch& s) {
  s.reserve(K);
  HWY_DYNAMIC_DISPATCH(BinomialCountsTable)(lam, K, key, pixel, table, s);
}

void transpose_rows(const float* src, size_t width, size_t K, float* dst, size_t dst_stride) {
  HWY_DYNAMIC_DISPATCH(TransposeRowsF)(src, width, K, dst, dst_stride);
}
void transpose_rows(const uint16_t* src, size_t width, size_t K, uint16_t* dst, size_t dst_stride) {
  HWY_DYNAMIC_DISPATCH(TransposeRowsU16)(src, width, K, dst, dst_stride);
}

}  // namespace spadgen::sensor
#endif
