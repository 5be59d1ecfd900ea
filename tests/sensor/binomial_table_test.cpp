// The table sampler of the counts path (sensor/binomial_table.h): its thresholds against an independent
// CDF, its draws against the exact pmf (chi-square, false-alarm rate 1e-6 each, fixed seeds), and the
// vectorised kernel against the scalar sampler, draw for draw.
#include <gtest/gtest.h>

#include <hwy/targets.h>

#include <cmath>
#include <cstdio>
#include <vector>

#include "core/rng.h"
#include "sensor/sampling/batch_kernels.h"
#include "sensor/sampling/binomial_table.h"
#include "test_util.h"

namespace spadgen::sensor {
namespace {

using testing::binomial_pmf;
using testing::chi_square_p;
constexpr double kAlpha = 1e-6;

const BinomialTable& table255() {
  static const std::shared_ptr<const BinomialTable> t = BinomialTable::get(255);
  return *t;
}

// Row g's thresholds are floor(F(x) 2^64) of Binomial(n, g / G): F from lgamma in double, independently
// of the table's long-double recurrence, agrees to 1e-13 absolute at every x; and X1 inverts them.
TEST(BinomialTable, ThresholdsAreTheBinomialCdf) {
  const BinomialTable& t = table255();
  ASSERT_EQ(t.n(), 255u);
  for (uint32_t g : {1u, 7u, 100u, 512u, 1000u, 2047u, 2048u}) {
    const double p = BinomialTable::grid_p(g);
    const std::vector<double> pmf = binomial_pmf(255, p);
    const int64_t row = t.row()[g];
    const auto off = static_cast<size_t>(row & 0xFFFFFFFF);
    const auto lo = static_cast<uint32_t>(row >> 32);
    double F = 0.0;
    uint64_t prev = 0;
    uint32_t x = 0;
    for (; x < lo; ++x) F += pmf[x];
    EXPECT_LT(F, 1e-18) << "below the row, F(x) < 2^-64: g=" << g;
    for (size_t i = 0;; ++i, ++x) {
      const uint64_t T = t.thresholds64()[off + i];
      EXPECT_EQ(t.thresholds16()[off + i], T >> 48);
      if (T == ~uint64_t{0}) {  // the row's end: F rounds to 1 from here on
        EXPECT_GT(F + (x < 255 ? pmf[x] : 1.0), 1.0 - 1e-13) << "g=" << g << " x=" << x;
        break;
      }
      F += pmf[x];
      EXPECT_NEAR(static_cast<double>(T) * 0x1p-64, F, 1e-13) << "g=" << g << " x=" << x;
      // U = T is the smallest U1 that counts x: X1 = x + 1 there and x just below (where the neighbours'
      // thresholds differ)
      if (prev < T && t.thresholds64()[off + i + 1] > T) {
        EXPECT_EQ(t.first_round(T, g), x + 1) << "g=" << g << " x=" << x;
        EXPECT_EQ(t.first_round(T - 1, g), x) << "g=" << g << " x=" << x;
      }
      prev = T;
    }
  }
  // p_g = 0: X1 = 0 for every U, including the largest
  EXPECT_EQ(t.first_round(~uint64_t{0}, 0), 0u);
  EXPECT_EQ(t.first_round(0, 0), 0u);
  // p_g = 1/2: U = 2^64 - 1 is read as 2^64 - 2, which lies in the top outcome's interval only if F(254)
  // < 1 - 2^-63; it does not here, so X1 is the last outcome whose threshold is below 2^64 - 1
  EXPECT_LE(t.first_round(~uint64_t{0}, 2048), 255u);
}

// sample(U1, U2, a) is Binomial(n, a): grid points, just below the next grid point (delta at its largest,
// so the second round often draws Y > 0), between them, tiny a (first round empty) and a = 1/2.
TEST(BinomialTable, SampleChiSquare) {
  const BinomialTable& t = table255();
  const double G = BinomialTable::kGrid;
  int seed = 70;
  for (double a : {1e-9, 1e-4, 1.0 / G - 1e-12, 1.0 / G, 3e-3, 0.0199, 0.25, 0.25 - 1e-12, 0.25 + 0.5 / G,
                   0.37 + 0.999 / G, 0.5 - 1e-15, 0.5}) {
    Rng rng(static_cast<uint64_t>(seed++), RngKind::Test, 3);
    const int draws = 300000;
    std::vector<double> hist(256, 0.0);
    for (int i = 0; i < draws; ++i) {
      const uint64_t U1 = rng.next_u64(), U2 = rng.next_u64();
      hist[t.sample(U1, U2, a)] += 1.0;
    }
    if (a < 1e-6) {  // mean 2.6e-4 per draw: the count of non-zero draws is Poisson
      EXPECT_TRUE(testing::poisson_consistent(draws - hist[0], draws * (1.0 - std::pow(1.0 - a, 255)), kAlpha))
          << "a=" << a;
      continue;
    }
    EXPECT_GT(chi_square_p(hist, binomial_pmf(255, a), draws), kAlpha) << "a=" << a;
  }
}

// Other n: small, odd, and the largest whose rows fit; far above, no table.
TEST(BinomialTable, OtherFrameCounts) {
  for (uint32_t n : {1u, 16u, 100u, 600u}) {
    const auto t = BinomialTable::get(n);
    ASSERT_NE(t, nullptr) << n;
    for (double a : {0.03, 0.31, 0.5}) {
      Rng rng(n * 7 + static_cast<uint64_t>(a * 100), RngKind::Test, 4);
      const int draws = 200000;
      std::vector<double> hist(n + 1, 0.0);
      for (int i = 0; i < draws; ++i) {
        const uint64_t U1 = rng.next_u64(), U2 = rng.next_u64();
        hist[t->sample(U1, U2, a)] += 1.0;
      }
      EXPECT_GT(chi_square_p(hist, binomial_pmf(static_cast<int>(n), a), draws), kAlpha) << "n=" << n << " a=" << a;
    }
  }
  EXPECT_EQ(BinomialTable::get(4080), nullptr);
  EXPECT_EQ(BinomialTable::get(255).get(), &table255());  // built once and shared
}

// The tables of the last kKeep frame counts asked for are kept, and those someone holds; the others are
// freed (a dataset planned with a random acquisition.frames kept one per value, 700 MB for 200 samples).
TEST(BinomialTable, KeepsTheLastFewAndTheHeldTablesNotEveryOne) {
  std::vector<uint32_t> draws;
  const auto draw_all = [](const BinomialTable& t) {
    Rng rng(3, RngKind::Test, 101);
    std::vector<uint32_t> d;
    for (int i = 0; i < 1000; ++i) {
      const uint64_t U1 = rng.next_u64(), U2 = rng.next_u64();
      d.push_back(t.sample(U1, U2, 0.5 * rng.next_double()));
    }
    return d;
  };
  std::weak_ptr<const BinomialTable> first = BinomialTable::get(101);
  ASSERT_FALSE(first.expired());  // among the last kKeep
  draws = draw_all(*first.lock());
  const std::shared_ptr<const BinomialTable> held = BinomialTable::get(102);
  for (uint32_t n = 103; n < 103 + BinomialTable::kKeep; ++n) ASSERT_NE(BinomialTable::get(n), nullptr);
  EXPECT_TRUE(first.expired());  // no holder, no longer among the last kKeep: freed
  EXPECT_EQ(BinomialTable::get(102).get(), held.get());  // held: the same table, not built again
  EXPECT_EQ(BinomialTable::get(255).get(), &table255());
  const std::shared_ptr<const BinomialTable> again = BinomialTable::get(101);  // built again: the same draws
  ASSERT_NE(again, nullptr);
  EXPECT_EQ(draw_all(*again), draws);
}

// The kernel equals the scalar sampler draw for draw: U1, U2 = the words of counts_block(key, pixel, k)
// (ARS-7 in software), a = min(p, q) with the kernel's own p and q. Lambdas cover zero, background,
// edges, plateaus, p = 1/2, p near 1 and infinity, in vectors that mix them; K not a multiple of 8.
TEST(BinomialTable, KernelEqualsScalarSampler) {
  const BinomialTable& t = table255();
  const uint64_t seed = 44;
  const Rng base(seed, RngKind::Counts, 0, 0);
  const uint32_t key[2] = {base.key().v[0], base.key().v[1]};
  KernelScratch s;
  Rng pick(9, RngKind::Test, 5);
  size_t mismatches = 0, draws = 0, scalar_first = 0, y1 = 0, y2 = 0;
  for (uint64_t pixel = 0; pixel < 2000; ++pixel) {
    const size_t K = pixel % 5 == 0 ? 1 + pixel % 37 : 350;
    std::vector<double> lam(K);
    for (size_t k = 0; k < K; ++k) {
      const double u = pick.next_double();
      lam[k] = u < 0.05   ? 0.0
               : u < 0.3  ? std::pow(10.0, -9.0 + 6.0 * pick.next_double())
               : u < 0.9  ? 3.0 * pick.next_double()
               : u < 0.95 ? std::log(2.0) * (1.0 + 1e-12 * (pick.next_double() - 0.5))
               : u < 0.99 ? 3.0 + 40.0 * pick.next_double()
                          : HUGE_VAL;
    }
    binomial_counts(lam.data(), K, key, pixel, t, s);
    for (size_t k = 0; k < K; ++k) {
      const Block128 b = counts_block(key, pixel, static_cast<uint32_t>(k));
      const uint64_t U1 = (uint64_t{b[0]} << 32) | b[1], U2 = (uint64_t{b[2]} << 32) | b[3];
      const double p = s.p[k], q = s.q[k];
      const double a = std::min(p, q);
      const uint32_t x = t.sample(U1, U2, a);
      // the second round's outcome: Y = 1 and Y >= 2 take different paths in the kernel
      const uint32_t g = BinomialTable::grid_index(a), x1 = t.first_round(U1, g);
      const uint32_t y = t.second_round(U2, 255 - x1, t.delta(a, g));
      y1 += y == 1;
      y2 += y >= 2;
      const uint32_t expect = p <= q ? x : 255 - x;
      mismatches += s.x[k] != expect;
      // U1 in a tail bucket: many outcomes share the guide's bucket, the kernel's lane takes the scalar search
      scalar_first += (U1 >> 56) == 0 || (U1 >> 56) == 255;
      ++draws;
    }
  }
  EXPECT_EQ(mismatches, 0u) << draws;
  EXPECT_GT(scalar_first, 1000u);
  EXPECT_GT(y1, 1000u);
  EXPECT_GT(y2, 20u);
}

// The same on every compiled target (the dispatcher's choice forced in turn), with the transposition.
TEST(BinomialTable, KernelEqualsScalarSamplerOnEveryTarget) {
  const BinomialTable& t = table255();
  const Rng base(45, RngKind::Counts, 0, 0);
  const uint32_t key[2] = {base.key().v[0], base.key().v[1]};
  int targets = 0;
  for (const int64_t target : hwy::SupportedAndGeneratedTargets()) {
    hwy::SetSupportedTargetsForTest(target);
    ++targets;
    KernelScratch s;
    Rng pick(10, RngKind::Test, 6);
    size_t mismatches = 0;
    for (uint64_t pixel = 0; pixel < 200; ++pixel) {
      const size_t K = 101 + pixel % 9;
      std::vector<double> lam(K);
      for (double& l : lam) l = pick.next_double() < 0.2 ? 1e-6 * pick.next_double() : 2.0 * pick.next_double();
      binomial_counts(lam.data(), K, key, pixel, t, s);
      for (size_t k = 0; k < K; ++k) {
        const Block128 b = counts_block(key, pixel, static_cast<uint32_t>(k));
        const uint64_t U1 = (uint64_t{b[0]} << 32) | b[1], U2 = (uint64_t{b[2]} << 32) | b[3];
        const uint32_t x = t.sample(U1, U2, std::min(s.p[k], s.q[k]));
        mismatches += s.x[k] != (s.p[k] <= s.q[k] ? x : 255 - x);
      }
    }
    EXPECT_EQ(mismatches, 0u) << hwy::TargetName(target);
    std::vector<uint16_t> src(9 * 13 + 1), dst(13 * 9);
    for (size_t i = 0; i < src.size(); ++i) src[i] = static_cast<uint16_t>(i);
    transpose_rows(src.data(), 9, 13, dst.data(), 9);
    for (size_t k = 0; k < 13; ++k)
      for (size_t x = 0; x < 9; ++x) ASSERT_EQ(dst[k * 9 + x], src[x * 13 + k]) << hwy::TargetName(target);
  }
  hwy::SetSupportedTargetsForTest(0);
  std::printf("counts kernel checked on %d targets\n", targets);
  EXPECT_GE(targets, 1);
}

// Through the kernel, on constant lambda: chi-square of the counts (mirrored too) against the pmf.
TEST(BinomialTable, KernelChiSquare) {
  const BinomialTable& t = table255();
  const Rng base(321, RngKind::Counts, 0, 0);
  const uint32_t key[2] = {base.key().v[0], base.key().v[1]};
  for (double lambda : {2e-3, 0.05, 0.3, 0.6931, 1.7, 4.0}) {
    KernelScratch s;
    const size_t K = 350;
    const std::vector<double> lam(K, lambda);
    std::vector<double> hist(256, 0.0);
    const int pixels = 600;
    for (int px = 0; px < pixels; ++px) {
      binomial_counts(lam.data(), K, key, static_cast<uint64_t>(px), t, s);
      for (size_t k = 0; k < K; ++k) hist[s.x[k]] += 1.0;
    }
    EXPECT_GT(chi_square_p(hist, binomial_pmf(255, -std::expm1(-lambda)), pixels * static_cast<double>(K)), kAlpha)
        << "lambda=" << lambda;
  }
}

// transpose_rows: pixel-major rows to k-major outputs, for widths below, at and above a vector's pixels.
TEST(CountsKernel, TransposeRows) {
  for (size_t width : {1u, 7u, 8u, 16u, 17u, 32u, 41u}) {
    const size_t K = 351, stride = width + 5;
    std::vector<float> f(width * K);
    std::vector<uint16_t> u(width * K + 1);
    for (size_t i = 0; i < width * K; ++i) {
      f[i] = static_cast<float>(i) * 0.5f;
      u[i] = static_cast<uint16_t>(i * 7919u);
    }
    std::vector<float> fo(K * stride, -1.0f);
    std::vector<uint16_t> uo(K * stride, 1);
    transpose_rows(f.data(), width, K, fo.data(), stride);
    transpose_rows(u.data(), width, K, uo.data(), stride);
    size_t bad = 0;
    for (size_t k = 0; k < K; ++k)
      for (size_t x = 0; x < stride; ++x) {
        const bool in = x < width;
        bad += fo[k * stride + x] != (in ? f[x * K + k] : -1.0f);
        bad += uo[k * stride + x] != (in ? u[x * K + k] : 1);
      }
    EXPECT_EQ(bad, 0u) << "width " << width;
  }
}

}  // namespace
}  // namespace spadgen::sensor
