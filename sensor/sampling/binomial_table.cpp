#include "sensor/sampling/binomial_table.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <deque>
#include <map>
#include <mutex>
#include <set>

#include "sensor/sampling/sampling.h"

namespace spadgen::sensor {
namespace {
constexpr uint64_t kMax = ~uint64_t{0};
}

std::shared_ptr<const BinomialTable> BinomialTable::get(uint32_t n) {
  static std::mutex mu;
  static std::map<uint32_t, std::weak_ptr<const BinomialTable>> live;  // every table someone holds
  static std::deque<std::pair<uint32_t, std::shared_ptr<const BinomialTable>>> recent;  // the last kKeep asked for
  static std::set<uint32_t> too_long;  // frame counts without tables (a failed build takes seconds at 65,535)
  const std::lock_guard<std::mutex> lock(mu);
  if (too_long.count(n) != 0) return nullptr;
  std::shared_ptr<const BinomialTable> t;  // recent holds it, or someone does, or it is built
  if (const auto it = live.find(n); it != live.end()) t = it->second.lock();
  if (t == nullptr) {
    t = std::shared_ptr<const BinomialTable>(build(n));
    std::erase_if(live, [](const auto& e) { return e.second.expired(); });
    if (t == nullptr) {
      too_long.insert(n);
      return nullptr;
    }
    live[n] = t;
  }
  std::erase_if(recent, [n](const auto& e) { return e.first == n; });
  recent.emplace_front(n, t);
  if (recent.size() > kKeep) recent.pop_back();
  return t;
}

std::unique_ptr<BinomialTable> BinomialTable::build(uint32_t n) {
  const uint32_t rows = kGrid / 2 + 1;
  // (n - x) / (x + 1), exact to long double
  std::vector<long double> up(n + 1);
  for (uint32_t x = 0; x <= n; ++x) up[x] = static_cast<long double>(n - x) / static_cast<long double>(x + 1);
  // Each row's entries x in [lo, hi] (T(hi) = 2^64 - 1) and its guide, rows in parallel
  struct Row {
    uint32_t lo = 0;
    std::vector<uint64_t> T;
    std::array<uint8_t, kGuide> guide{};
  };
  std::vector<Row> R(rows);
  std::atomic<bool> too_long{false};
  tbb::parallel_for(tbb::blocked_range<uint32_t>(0, rows), [&](const tbb::blocked_range<uint32_t>& range) {
    const long double two64 = 18446744073709551616.0L;
    std::vector<uint64_t> T(n + 1);
    std::vector<long double> pmf(n + 1), S(n + 1);
    for (uint32_t g = range.begin(); g < range.end(); ++g) {
      std::fill(T.begin(), T.end(), kMax);
      if (g > 0) {  // row 0 (p_g = 0): F = 1 everywhere, X1 = 0
        const long double p = static_cast<long double>(g) / kGrid;
        const long double ratio = p / (1.0L - p);
        pmf[0] = std::exp(static_cast<long double>(n) * std::log1p(-p));  // P(X = 0)
        for (uint32_t x = 0; x < n; ++x) pmf[x + 1] = pmf[x] * ratio * up[x];
        // S[x] = P(X > x) summed from the top, so that the upper tail keeps its relative precision
        long double acc = 0.0L, c = 0.0L;
        for (uint32_t x = n; x-- > 0;) {
          const long double y = pmf[x + 1] - c, t = acc + y;
          c = (t - acc) - y;
          acc = t;
          S[x] = acc;
        }
        // floor(F 2^64): from F summed from the bottom while F <= 1/2, else 2^64 - ceil(S 2^64)
        long double F = 0.0L;
        c = 0.0L;
        for (uint32_t x = 0; x < n; ++x) {
          const long double y = pmf[x] - c, t = F + y;
          c = (t - F) - y;
          F = t;
          if (F <= 0.5L) {
            T[x] = static_cast<uint64_t>(F * two64);  // truncation = floor; F 2^64 is exact
          } else {
            const long double up_s = std::ceil(S[x] * two64);
            T[x] = up_s <= 1.0L ? kMax : static_cast<uint64_t>(two64 - up_s);  // 2^64 - 1 from here on
          }
          if (x > 0 && T[x] < T[x - 1]) T[x] = T[x - 1];  // the two sums may differ by a unit where they meet
        }
      }
      uint32_t lo = 0, hi = 0;
      while (T[lo] == 0) ++lo;  // T[n] = kMax
      for (hi = lo; T[hi] != kMax;) ++hi;
      if (hi - lo + 1 > 256) {
        too_long = true;
        continue;
      }
      Row& row = R[g];
      row.lo = lo;
      row.T.assign(T.begin() + lo, T.begin() + hi + 1);
      // guide[b] = #{x < n : T(x) <= b 2^56} - lo, the count at the bucket's smallest U1
      uint32_t x = lo;
      for (uint32_t b = 0; b < kGuide; ++b) {
        const uint64_t u = static_cast<uint64_t>(b) << (64 - kGuideBits);
        while (T[x] <= u) ++x;
        row.guide[b] = static_cast<uint8_t>(x - lo);
      }
    }
  });
  if (too_long) return nullptr;
  std::unique_ptr<BinomialTable> t(new BinomialTable(n));
  t->row_.resize(rows);
  t->inv_one_minus_p_.resize(rows);
  for (uint32_t g = 0; g < rows; ++g) t->inv_one_minus_p_[g] = 1.0 / (1.0 - grid_p(g));
  t->guide_.reserve(static_cast<size_t>(rows) * kGuide + 8);
  for (uint32_t g = 0; g < rows; ++g) {
    t->row_[g] = static_cast<int64_t>(t->T64_.size()) | (static_cast<int64_t>(R[g].lo) << 32);
    for (uint64_t v : R[g].T) {
      t->T64_.push_back(v);
      t->T16_.push_back(static_cast<uint16_t>(v >> 48));
    }
    t->guide_.insert(t->guide_.end(), R[g].guide.begin(), R[g].guide.end());
  }
  t->guide_.resize(t->guide_.size() + 8, 0);           // padded for 8-byte gathers
  t->T16_.resize(t->T16_.size() + 4, 0xFFFF);           // padded likewise
  return t;
}

uint32_t BinomialTable::first_round(uint64_t U1, uint32_t g) const {
  const uint64_t u = U1 == kMax ? kMax - 1 : U1;
  const auto off = static_cast<size_t>(row_[g] & 0xFFFFFFFF);
  const auto lo = static_cast<uint32_t>(row_[g] >> 32);
  const uint64_t* T = T64_.data() + off;
  uint32_t i = guide_[static_cast<size_t>(g) * kGuide + (u >> (64 - kGuideBits))];
  // the first entry above u: a few steps from the guide, else a binary search up to the row's end (its
  // last entry is 2^64 - 1, above every u)
  for (int step = 0; step < 4; ++step, ++i)
    if (T[i] > u) return lo + i;
  const size_t end = g + 1 < row_.size() ? static_cast<size_t>(row_[g + 1] & 0xFFFFFFFF) - off : T64_.size() - off;
  return lo + static_cast<uint32_t>(std::upper_bound(T + i, T + end, u) - T);
}

double BinomialTable::survival0(double n2, double delta) {
  double t = kLog1pCoeff[0];
  for (int i = 1; i < 6; ++i) t = std::fma(t, delta, kLog1pCoeff[i]);
  const double x = n2 * (-delta * t);  // n2 log1p(-delta)
  double e = kExpm1Coeff[0];
  for (int i = 1; i < 14; ++i) e = std::fma(e, x, kExpm1Coeff[i]);
  e = std::fma(e, x, 1.0);
  return -(x * e);
}

uint32_t BinomialTable::second_round(uint64_t U2, uint32_t n2, double delta) const {
  if (!(delta > 0.0) || n2 == 0) return 0;
  const double N = n2;
  const double mean = N * delta;  // >= P(Y > 0)
  if (U2 >= probability_threshold(mean)) return 0;  // mean < 1 here
  // the sequential search from 0, as BinomialSampler::search_from_zero
  const double S0 = survival0(N, delta);  // P(Y > 0) < 0.2
  return sequential_search(U2, n2, odds(delta), S0, 1.0 - S0,
                           [n2](uint32_t y) { return static_cast<double>(n2 - y) / static_cast<double>(y + 1); });
}

}  // namespace spadgen::sensor
