// Exactness and distribution of the Bernoulli and binomial samplers. Every statistical check uses a fixed
// seed and a false-alarm rate of 1e-6 (p-value or z bound), so a failure means a real defect.
#include <gtest/gtest.h>
#include <hwy/targets.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <string>

#include "core/rng.h"
#include "sensor/sampling/batch_kernels.h"
#include "sensor/sampling/frames_kernel.h"
#include "sensor/sampling/sampling.h"
#include "test_util.h"

namespace spadgen::sensor {
namespace {

using testing::binomial_pmf;
using testing::chi_square_p;
using testing::poisson_consistent;
constexpr double kAlpha = 1e-6;

TEST(Sampling, ThresholdIsExact) {
  EXPECT_EQ(probability_threshold(0.0), 0u);
  EXPECT_EQ(probability_threshold(0.5), uint64_t{1} << 63);
  EXPECT_EQ(probability_threshold(0x1p-64), 1u);
  // p = 1e-15: floor(p 2^64) computed independently in long double (64-bit mantissa)
  const long double exact = std::floor(static_cast<long double>(1e-15) * 18446744073709551616.0L);
  EXPECT_EQ(probability_threshold(1e-15), static_cast<uint64_t>(exact));
  EXPECT_EQ(probability_threshold(1e-15), 18446u);
  // 1 - p near 1: the sampler works on q, whose threshold is exact as well
  const Prob pr = prob_from_lambda(-std::log(1e-15));
  EXPECT_NEAR(pr.q, 1e-15, 1e-29);
  EXPECT_EQ(probability_threshold(1.0), ~uint64_t{0});
  // P(X >= 1) of Binomial(255, 1e-15) keeps its relative precision
  const Prob tiny = prob_from_lambda(1e-15);
  EXPECT_NEAR(tiny.p, 1e-15, 1e-30);
  // P(X >= 1) of Binomial(255, 1e-15) as the sampler computes it, against the series N p - C(N, 2) p^2
  const double s0 = 255e-15 - 32385e-30;
  EXPECT_NEAR(-std::expm1(255.0 * std::log1p(-tiny.p)), s0, 1e-15 * s0);
  EXPECT_EQ(probability_threshold(-std::expm1(255.0 * std::log1p(-tiny.p))), 4703919u);  // floor(s0 2^64)
}

TEST(Sampling, ExactZeroAndOne) {
  BinomialSampler s(255);
  Rng rng(1, RngKind::Test, 0);
  uint64_t w[4];
  for (int i = 0; i < 1000; ++i) {
    EXPECT_EQ(s.sample(rng, {0.0, 1.0}), 0u);
    EXPECT_EQ(s.sample(rng, {1.0, 0.0}), 255u);
  }
  sample_bits(Rng(1, RngKind::Test, 5), s, {0.0, 1.0}, w);
  EXPECT_EQ(w[0] | w[1] | w[2] | w[3], 0u);
  sample_bits(Rng(1, RngKind::Test, 5), s, {1.0, 0.0}, w);
  EXPECT_EQ(std::popcount(w[0]) + std::popcount(w[1]) + std::popcount(w[2]) + std::popcount(w[3]), 255);
  EXPECT_EQ(w[3] >> 63, 0u);  // bits past n stay zero
}

TEST(Sampling, DenseKernelMatchesScalarReference) {
  for (uint32_t n : {1u, 100u, 255u, 256u, 300u, 4080u}) {
    for (double p : {0.3, 0.5, 0.0039, 0.99}) {
      const uint64_t T = probability_threshold(p);
      for (uint64_t s = 0; s < 20; ++s) {
        const Rng stream(77, RngKind::Frames, s, n);
        std::vector<uint64_t> w((n + 63) / 64 + 1, 0xDEADBEEFull);
        dense_bits(stream, n, T, w.data());
        for (uint32_t f = 0; f < n; ++f)
          ASSERT_EQ(((w[f / 64] >> (f % 64)) & 1u) != 0, dense_bit_reference(stream, n, T, f)) << n << " " << p << " " << f;
        if (n % 64) {
          ASSERT_EQ(w[(n - 1) / 64] >> (n % 64), 0u);
        }
        ASSERT_EQ(w.back(), 0xDEADBEEFull);  // nothing written past the last word
      }
    }
  }
  // ties on the top byte: T's top byte 0x80 and its refinement, checked frame by frame above; here the
  // tie rate itself is 1/256
  std::printf("dense kernel target: %s\n", dense_bits_target());
}

// Bits: count per stream ~ Binomial(n, p) (chi-square), and every frame position set with probability p
// (chi-square over positions), for the sparse and dense paths and p near 1.
void check_bits(double p, double q, uint32_t n, int streams, uint64_t seed) {
  BinomialSampler s(n);
  std::vector<double> hist(n + 1, 0.0), pos(n, 0.0);
  std::vector<uint64_t> w((n + 63) / 64);
  double ones = 0.0;
  for (int i = 0; i < streams; ++i) {
    sample_bits(Rng(seed, RngKind::Frames, static_cast<uint64_t>(i), 0), s, {p, q}, w.data());
    int c = 0;
    for (uint32_t f = 0; f < n; ++f)
      if ((w[f / 64] >> (f % 64)) & 1u) {
        ++c;
        pos[f] += 1.0;
      }
    hist[static_cast<size_t>(c)] += 1.0;
    ones += c;
  }
  const double total_bits = static_cast<double>(n) * streams;
  if (q < 1e-4) {  // zeros are rare: their total is Poisson
    EXPECT_TRUE(poisson_consistent(total_bits - ones, total_bits * q, kAlpha)) << total_bits - ones << " zeros, expected " << total_bits * q;
    return;
  }
  const std::vector<double> pmf = binomial_pmf(static_cast<int>(n), p);
  EXPECT_GT(chi_square_p(hist, pmf, streams), kAlpha) << "counts, p=" << p;
  // positions: each frame's share of the ones is 1/n
  EXPECT_GT(chi_square_p(pos, std::vector<double>(n, 1.0 / n), ones), kAlpha) << "positions, p=" << p;
}

TEST(Sampling, BernoulliBitsChiSquare) {
  check_bits(1e-3, 1.0 - 1e-3, 255, 200000, 11);   // sparse path
  check_bits(0.5, 0.5, 255, 20000, 12);            // dense path
  check_bits(0.2, 0.8, 300, 20000, 13);            // dense, n not a multiple of 64
  check_bits(0.9985, 0.0015, 255, 50000, 14);      // sparse on the zeros
  check_bits(0.003, 0.997, 255, 50000, 16);        // dense, a just above the sparse bound
  check_bits(1.0 - 1e-6, 1e-6, 255, 200000, 15);   // p near 1
  EXPECT_TRUE(bits_are_sparse({1e-3, 1.0 - 1e-3}));
  EXPECT_TRUE(bits_are_sparse({0.9985, 0.0015}));
  EXPECT_FALSE(bits_are_sparse({0.5, 0.5}));
  EXPECT_FALSE(bits_are_sparse({0.003, 0.997}));
}

// p = 1e-9: 2^20 streams of 65535 frames (6.9e10 Bernoulli trials, 68.7 expected ones).
TEST(Sampling, BernoulliAtOneInABillion) {
  const uint32_t n = 65535;
  BinomialSampler s(n);
  std::vector<uint64_t> w((n + 63) / 64);
  double ones = 0.0, bit_draws = 0.0;
  const int streams = 1 << 20;
  const Prob pr{1e-9, 1.0 - 1e-9};
  for (int i = 0; i < streams; ++i) {
    Rng rng(21, RngKind::Counts, static_cast<uint64_t>(i), 0);
    ones += s.sample(rng, pr);
  }
  const double mu = 1e-9 * n * streams;
  EXPECT_TRUE(poisson_consistent(ones, mu, kAlpha)) << ones << " vs " << mu;
  for (int i = 0; i < streams / 16; ++i) {
    sample_bits(Rng(22, RngKind::Frames, static_cast<uint64_t>(i), 0), s, pr, w.data());
    for (uint64_t v : w) bit_draws += std::popcount(v);
  }
  EXPECT_TRUE(poisson_consistent(bit_draws, mu / 16, kAlpha)) << bit_draws << " vs " << mu / 16;
}

void check_binomial(uint32_t n, double p, double q, int draws, uint64_t seed) {
  BinomialSampler s(n);
  std::vector<double> hist(n + 1, 0.0);
  Rng rng(seed, RngKind::Counts, 0, 0);
  for (int i = 0; i < draws; ++i) hist[s.sample(rng, {p, q})] += 1.0;
  if (q < 1e-4) {
    double misses = 0.0;
    for (uint32_t k = 0; k <= n; ++k) misses += hist[k] * (n - k);
    EXPECT_TRUE(poisson_consistent(misses, static_cast<double>(n) * draws * q, kAlpha)) << misses;
    return;
  }
  EXPECT_GT(chi_square_p(hist, binomial_pmf(static_cast<int>(n), p), draws), kAlpha) << "n=" << n << " p=" << p;
}

TEST(Sampling, BinomialChiSquare) {
  check_binomial(255, 1e-3, 1.0 - 1e-3, 400000, 31);  // sequential search
  check_binomial(255, 0.03, 0.97, 200000, 32);        // sequential, mean 7.7
  check_binomial(255, 0.5, 0.5, 200000, 33);          // from the mode
  check_binomial(4080, 0.01, 0.99, 200000, 34);       // from the mode, mean 40.8
  check_binomial(255, 0.9, 0.1, 200000, 35);          // mirrored
  check_binomial(255, 1.0 - 1e-6, 1e-6, 400000, 36);  // p near 1: misses are Poisson
  check_binomial(65535, 0.3, 0.7, 20000, 37);         // large n
}

// The vectorised counts kernel against the scalar sampler on the same streams: identical except where a
// 64-bit uniform falls within the last few ulp of a probability (vector exp/expm1/log vs libm), i.e. never
// in practice. Rates cover both searches, the mirrored side, the X = 0 fast path, 0, saturation and tails
// (K = 37: a partial vector at the end).
TEST(Sampling, CountsKernelMatchesScalarSampler) {
  const std::vector<double> rates = {0.0, 1e-15, 1e-9, 1e-6, 1e-4, 2e-3, 0.004, 0.02, 0.062, 0.07, 0.3, 0.6931,
                                     0.6932, 1.0, 2.5, 5.0, 9.0, 20.0, 40.0, 745.0, 900.0, HUGE_VAL};
  const uint64_t seed = 99;
  const Rng base(seed, RngKind::Counts, 0, 0);
  const uint32_t key[2] = {base.key().v[0], base.key().v[1]};
  for (uint32_t n : {1u, 255u, 4080u}) {
    const BinomialSampler sampler(n);
    KernelScratch s;
    size_t mismatches = 0, draws = 0;
    for (uint64_t pixel = 0; pixel < 400; ++pixel) {
      std::vector<double> lam(37);
      for (size_t k = 0; k < lam.size(); ++k) lam[k] = rates[(pixel * 7 + k) % rates.size()];
      std::vector<double> p(lam.size()), q(lam.size());
      probabilities(lam.data(), lam.size(), p.data(), q.data());
      binomial_counts(lam.data(), lam.size(), key, pixel * 1000003, sampler, s);
      for (size_t k = 0; k < lam.size(); ++k) {
        ASSERT_EQ(s.p[k], p[k]);
        Rng rng(seed, RngKind::Counts, pixel * 1000003, k);
        const uint32_t want = sampler.sample(rng, {p[k], q[k], -lam[k]});
        ++draws;
        if (s.x[k] != want) ++mismatches;
        if (lam[k] == 0.0) {
          ASSERT_EQ(s.x[k], 0u);
        }
        if (lam[k] >= 745.0) {
          ASSERT_EQ(s.x[k], n);
        }
        ASSERT_LE(s.x[k], n);
      }
    }
    EXPECT_LE(mismatches, draws / 100000) << "n=" << n;
    std::printf("n = %u: %zu of %zu draws differ from the scalar sampler\n", n, mismatches, draws);
  }
}

// The kernel's counts are Binomial(n, p): chi-square where the X = 0 decision (one comparison of U with
// floor(P(X > 0) 2^64)) carries the distribution (n p from 0.05 to 3), through both searches and mirrored.
// Whole vectors of gates that all search from the mode (the kernel then skips P(X > 0) and P(X = 0)), and
// vectors that mix both searches: the kernel equals the scalar sampler draw for draw.
TEST(Sampling, CountsKernelAllModeVectorsMatchScalarSampler) {
  const uint64_t seed = 41;
  const Rng base(seed, RngKind::Counts, 0, 0);
  const uint32_t key[2] = {base.key().v[0], base.key().v[1]};
  const BinomialSampler sampler(255);
  KernelScratch s;
  size_t mismatches = 0, draws = 0;
  for (uint64_t pixel = 0; pixel < 300; ++pixel) {
    std::vector<double> lam(64);
    for (size_t k = 0; k < lam.size(); ++k)  // N p from 17 to 230 for k < 48, then down to N p ~ 1
      lam[k] = k < 48 ? 0.07 + 0.05 * static_cast<double>((k + pixel) % 48) : 0.004 * static_cast<double>(k - 47);
    std::vector<double> p(lam.size()), q(lam.size());
    probabilities(lam.data(), lam.size(), p.data(), q.data());
    binomial_counts(lam.data(), lam.size(), key, pixel, sampler, s);
    for (size_t k = 0; k < lam.size(); ++k) {
      Rng rng(seed, RngKind::Counts, pixel, k);
      mismatches += s.x[k] != sampler.sample(rng, {p[k], q[k], -lam[k]});
      ++draws;
    }
  }
  EXPECT_EQ(mismatches, 0u) << draws;
}

TEST(Sampling, CountsKernelChiSquare) {
  const Rng base(123, RngKind::Counts, 0, 0);
  const uint32_t key[2] = {base.key().v[0], base.key().v[1]};
  for (const auto& [n, lambda] : std::vector<std::pair<uint32_t, double>>{
           {255, 2e-4}, {255, 2e-3}, {255, 1.2e-2}, {255, 0.05}, {255, 0.5}, {255, 2.3}, {4080, 0.01}}) {
    const BinomialSampler sampler(n);
    KernelScratch s;
    const size_t K = 350;
    const std::vector<double> lam(K, lambda);
    std::vector<double> hist(n + 1, 0.0);
    const int pixels = 600;
    for (int px = 0; px < pixels; ++px) {
      binomial_counts(lam.data(), K, key, static_cast<uint64_t>(px), sampler, s);
      for (size_t k = 0; k < K; ++k) hist[s.x[k]] += 1.0;
    }
    const double p = -std::expm1(-lambda);
    EXPECT_GT(chi_square_p(hist, binomial_pmf(static_cast<int>(n), p), static_cast<double>(pixels) * K), kAlpha)
        << "n=" << n << " lambda=" << lambda;
  }
}

// Inversion from the mode (n min(p, q) >= 16): chi-square against the exact pmf (false-alarm rate 1e-6 each)
// and the sample mean against n p within the z bound of 1e-6, for the scalar sampler (one stream) and for
// the vectorised counts kernel (a stream per gate), at n p from the threshold 16 to n / 2, mirrored
// (p > 1/2: X counts misses), and at n = 4080.
TEST(Sampling, ModeSearchChiSquareAndMean) {
  const Rng base(77, RngKind::Counts, 0, 0);
  const uint32_t key[2] = {base.key().v[0], base.key().v[1]};
  for (const auto& [n, p] : std::vector<std::pair<uint32_t, double>>{
           {255, 16.0 / 255.0}, {255, 0.07}, {255, 0.2}, {255, 0.5}, {255, 0.8}, {255, 0.93}, {4080, 0.01}}) {
    const BinomialSampler sampler(n);
    const double q = 1.0 - p, lambda = -std::log1p(-p);
    const Prob pr = prob_from_lambda(lambda);
    ASSERT_GE(static_cast<double>(n) * std::min(pr.p, pr.q), BinomialSampler::mode_search_from()) << n << " " << p;
    const std::vector<double> pmf = binomial_pmf(static_cast<int>(n), pr.p);
    const double mean = static_cast<double>(n) * pr.p;
    // scalar: one stream
    {
      std::vector<double> hist(n + 1, 0.0);
      Rng rng(78, RngKind::Counts, n, static_cast<uint64_t>(p * 1e6));
      const int draws = 200000;
      double sum = 0.0;
      for (int i = 0; i < draws; ++i) {
        const uint32_t x = sampler.sample(rng, pr);
        ASSERT_LE(x, n);
        hist[x] += 1.0;
        sum += x;
      }
      EXPECT_GT(chi_square_p(hist, pmf, draws), kAlpha) << "scalar n=" << n << " p=" << p;
      EXPECT_LE(std::abs(sum / draws - mean), testing::kZ * std::sqrt(mean * q / draws)) << "scalar n=" << n << " p=" << p;
    }
    // kernel: 600 pixels x 350 gates
    {
      KernelScratch s;
      const size_t K = 350;
      const std::vector<double> lam(K, lambda);
      std::vector<double> hist(n + 1, 0.0);
      const int pixels = 600;
      double sum = 0.0;
      for (int px = 0; px < pixels; ++px) {
        binomial_counts(lam.data(), K, key, static_cast<uint64_t>(px), sampler, s);
        for (size_t k = 0; k < K; ++k) {
          ASSERT_LE(s.x[k], n);
          hist[s.x[k]] += 1.0;
          sum += s.x[k];
        }
      }
      const double draws = static_cast<double>(pixels) * K;
      EXPECT_GT(chi_square_p(hist, pmf, draws), kAlpha) << "kernel n=" << n << " p=" << p;
      EXPECT_LE(std::abs(sum / draws - mean), testing::kZ * std::sqrt(mean * q / draws)) << "kernel n=" << n << " p=" << p;
    }
  }
}

// Exactness at the X = 0 threshold: U just below floor(P(X > 0) 2^64) gives X >= 1, U at it gives 0.
TEST(Sampling, ZeroDecisionAtTheThreshold) {
  const uint32_t n = 255;
  const BinomialSampler sampler(n);
  for (double lambda : {1e-15, 1e-9, 1e-4, 3e-3, 0.02}) {
    const double S0 = -std::expm1(-static_cast<double>(n) * lambda);
    const double P0 = S0 < 0.5 ? 1.0 - S0 : std::exp(-static_cast<double>(n) * lambda);
    const double p = -std::expm1(-lambda), q = std::exp(-lambda);
    const uint64_t T = probability_threshold(S0);
    ASSERT_GT(T, 0u);
    EXPECT_EQ(sampler.search_from_zero(T, p, q, S0, P0), 0u);
    EXPECT_GE(sampler.search_from_zero(T - 1, p, q, S0, P0), 1u);
    EXPECT_EQ(sampler.sample_u(T, {p, q, -lambda}), 0u);
    EXPECT_GE(sampler.sample_u(T - 1, {p, q, -lambda}), 1u);
    EXPECT_EQ(sampler.sample_u(~uint64_t{0}, {p, q, -lambda}), 0u);
    EXPECT_GE(sampler.sample_u(0, {p, q, -lambda}), 1u);
  }
}

// sample_bits_batch (block 0 of the sparse streams from the vectorised Philox, the dense bytes from ARS-7, branch-free classification,
// groups of 256) equals sample_bits per stream; n = 2000 also has sparse pixels with n a >= 1.
TEST(Sampling, BatchBitsEqualPerStreamBits) {
  for (const uint32_t n : {255u, 2000u}) {
    const BinomialSampler sampler(n);
    const size_t count = 603, nw = (n + 63) / 64;
    std::vector<uint64_t> ids(count);
    std::vector<Prob> pr(count);
    const std::vector<double> rates = {0.0, 1e-7, 1e-4, 1e-3, 1.9e-3, 3e-3, 0.03, 0.07, 0.5, 1.0, 3.0, 5.4, 8.0, 30.0, HUGE_VAL};
    for (size_t i = 0; i < count; ++i) {
      ids[i] = (uint64_t{1} << 32) - 50 + i * 3;  // crosses 2^32: both counter words vary
      const double l = rates[i % rates.size()];
      pr[i] = prob_from_lambda(l);
    }
    std::vector<uint64_t> batch(count * nw), one(nw);
    sample_bits_batch(7, 11, ids.data(), count, sampler, pr.data(), batch.data());
    for (size_t i = 0; i < count; ++i) {
      sample_bits(Rng(7, RngKind::Frames, ids[i], 11), sampler, pr[i], one.data());
      for (size_t w = 0; w < nw; ++w) ASSERT_EQ(batch[nw * i + w], one[w]) << "n " << n << " pixel " << i;
    }
  }
}

// n = 0 frames: no words, nothing written (the batch's kernel writes each pixel's last word otherwise).
TEST(Sampling, BatchBitsWithNoFramesWriteNothing) {
  const BinomialSampler sampler(0);
  const std::vector<uint64_t> ids = {1, 2, 3};
  const std::vector<Prob> pr = {prob_from_lambda(0.0), prob_from_lambda(1e-4), prob_from_lambda(1.0)};
  std::vector<uint64_t> guard(4, 0x5555555555555555ull);
  sample_bits_batch(3, 1, ids.data(), ids.size(), sampler, pr.data(), guard.data() + 2);
  for (uint64_t g : guard) EXPECT_EQ(g, 0x5555555555555555ull);
}

// Where sample_bits_batch's words (pixels ids, probabilities pr, n frames) differ from dense_bit_reference of
// the streams Rng(seed, Frames, ids[i], k), each pixel inverted where p > q, or hold a bit past n: the first
// such place, "" when none. ties (if given) counts the frames whose top byte equals the threshold's.
std::string batch_mismatch(const std::vector<uint64_t>& batch, uint64_t seed, uint64_t k, const std::vector<uint64_t>& ids,
                           const std::vector<Prob>& pr, uint32_t n, size_t* ties = nullptr) {
  const size_t nw = (n + 63) / 64;
  for (size_t i = 0; i < ids.size(); ++i) {
    if (bits_are_sparse(pr[i])) return "pixel " + std::to_string(i) + " is sparse";
    const Rng stream(seed, RngKind::Frames, ids[i], k);
    const bool invert = pr[i].p > pr[i].q;
    const uint64_t T = probability_threshold(invert ? pr[i].q : pr[i].p);
    for (uint32_t f = 0; f < n; ++f) {
      if ((((batch[i * nw + f / 64] >> (f % 64)) & 1) != 0) != (dense_bit_reference(stream, n, T, f) != invert))
        return "pixel " + std::to_string(i) + " frame " + std::to_string(f);
      if (ties != nullptr) {
        const uint32_t r = f % 256;
        const auto blk = ars_block(stream, ars_keys_of(stream), 16 * (f / 256) + (r % 64) / 4);
        *ties += static_cast<uint8_t>(blk[r / 64] >> (8 * (r % 4))) == static_cast<uint8_t>(T >> 56);
      }
    }
    for (uint32_t f = n; f < nw * 64; ++f)
      if ((batch[i * nw + f / 64] >> (f % 64)) & 1) return "pixel " + std::to_string(i) + " bit " + std::to_string(f) + " past n";
  }
  return "";
}

// The batch settles the dense pixels' top-byte ties with one vectorised ARS-7 per 16: every frame equals
// dense_bit_reference (one scalar ars_block per tie), for frame counts that are not multiples of 64 or 256
// (several chunks) and both sides (a = p and a = q); the test counts the ties it covered.
TEST(Sampling, BatchSettlesTiesLikeTheReference) {
  for (const uint32_t n : {100u, 300u, 1000u}) {
    const BinomialSampler sampler(n);
    const size_t nw = (n + 63) / 64, count = 150;
    std::vector<uint64_t> ids(count);
    std::vector<Prob> pr(count);
    for (size_t i = 0; i < count; ++i) {
      ids[i] = 1000003 * i + 17;
      pr[i] = prob_from_lambda(0.07 + 0.0175 * static_cast<double>(i));  // p from 0.068 to 0.93: dense
    }
    std::vector<uint64_t> batch(count * nw);
    sample_bits_batch(9, 5, ids.data(), count, sampler, pr.data(), batch.data());
    size_t ties = 0;
    ASSERT_EQ(batch_mismatch(batch, 9, 5, ids, pr, n, &ties), "") << "n " << n;
    EXPECT_GT(ties, count * n / 512);  // about count n / 256 ties were settled
  }
}

// Every instruction set compiled into the dense kernels (the dispatcher's choice forced in turn) gives the
// bits of dense_bit_reference in sample_bits_batch, both sides, frame counts over several chunks and not
// multiples of 64, and enough pixels (150 at n = 1000: about 590 ties) that ties are settled mid-stream.
// AVX2 twice where the processor has VAES: its 256-bit AES rounds, and Highway's split ones.
TEST(Sampling, BatchBitsEqualReferenceOnEveryTarget) {
  struct RestoreVaes {  // also when an assertion returns early
    bool on = avx2_vaes();
    ~RestoreVaes() {
      set_avx2_vaes(on);
      hwy::SetSupportedTargetsForTest(0);
    }
  } restore;
  int passes = 0;
  // the list once: it follows SetSupportedTargetsForTest (taken again after a pass, it held the last target alone)
  const std::vector<int64_t> targets = hwy::SupportedAndGeneratedTargets();
  for (const uint32_t n : {100u, 300u, 1000u}) {
    const BinomialSampler sampler(n);
    const size_t nw = (n + 63) / 64, count = 150;
    std::vector<uint64_t> ids(count);
    std::vector<Prob> pr(count);
    for (size_t i = 0; i < count; ++i) {
      ids[i] = 7919 * i + 3;
      pr[i] = prob_from_lambda(0.07 + 0.0175 * static_cast<double>(i));  // p from 0.068 to 0.93: dense
    }
    for (const int64_t target : targets) {
      hwy::SetSupportedTargetsForTest(target);
      for (const bool use_vaes : {false, true}) {
        if (use_vaes && (!restore.on || target != HWY_AVX2)) continue;
        set_avx2_vaes(use_vaes);
        ++passes;
        std::vector<uint64_t> batch(count * nw + 1, 0x5A5A5A5A5A5A5A5Aull);  // + a guard word
        sample_bits_batch(4, 2, ids.data(), count, sampler, pr.data(), batch.data());
        const std::string where = std::string(hwy::TargetName(target)) + (use_vaes ? "+VAES" : "") + " n " + std::to_string(n);
        ASSERT_EQ(batch_mismatch(batch, 4, 2, ids, pr, n), "") << where;
        ASSERT_EQ(batch.back(), 0x5A5A5A5A5A5A5A5Aull) << where;
      }
    }
  }
  std::printf("dense batch checked in %d passes (3 frame counts x %zu targets%s)\n", passes, targets.size(),
              restore.on ? "; AVX2 twice: with and without VAES" : "");
  const bool avx2 = std::find(targets.begin(), targets.end(), HWY_AVX2) != targets.end();
  EXPECT_EQ(passes, 3 * static_cast<int>(targets.size() + (restore.on && avx2 ? 1 : 0)));
}

// Pixel B's crosstalk-corrected rate takes one logarithm for all neighbours (-log of prod (1 - xt p_i));
// against the sum of the four -log1p(-xt p_i) in long double it stays within 8 ulp, from p = 1e-17 to
// p = 1 and xt up to 1 (xt p = 1 gives infinity); pixel A's is lam + xt sum_i lambda_i.
TEST(Sampling, CrosstalkRatesAreAccurate) {
  std::vector<double> ps;
  for (double e = -17.0; e <= 0.0; e += 0.37) ps.push_back(std::pow(10.0, e));
  ps.push_back(0.5);
  ps.push_back(0.999);
  ps.push_back(1.0);
  const size_t K = ps.size() * 3;  // not a multiple of the vector length: the tail path as well
  double worst = 0.0;
  for (const double xt : {0.0039, 0.3, 1.0})
    for (int nnb = 1; nnb <= 4; ++nnb) {
      std::vector<double> lam(K), out(K), nb[4];
      for (int i = 0; i < 4; ++i) {
        nb[i].resize(K);
        for (size_t k = 0; k < K; ++k) nb[i][k] = ps[(k * (2 * i + 1) + static_cast<size_t>(i)) % ps.size()];
      }
      for (size_t k = 0; k < K; ++k) lam[k] = 1e-3 * static_cast<double>(k % 5);
      const double* nbp[4] = {nb[0].data(), nb[1].data(), nb[2].data(), nb[3].data()};
      crosstalk_rates(lam.data(), K, nbp, nnb, xt, true, out.data());
      for (size_t k = 0; k < K; ++k) {
        long double ref = lam[k];
        bool infinite = false;
        for (int i = 0; i < nnb; ++i) {
          const double y = xt * nb[i][k];  // the product as the kernel forms it
          if (y >= 1.0) infinite = true;
          else ref -= std::log1p(-static_cast<long double>(y));
        }
        if (infinite) {
          ASSERT_TRUE(std::isinf(out[k])) << k;
          continue;
        }
        const double r = static_cast<double>(ref);
        const double ulp = std::nextafter(r, HUGE_VAL) - r;
        worst = std::max(worst, static_cast<double>(std::fabs(static_cast<long double>(out[k]) - ref)) / ulp);
      }
      crosstalk_rates(lam.data(), K, nbp, nnb, xt, false, out.data());
      for (size_t k = 0; k < K; ++k) {
        double ref = lam[k];
        for (int i = 0; i < nnb; ++i) ref = std::fma(xt, nb[i][k], ref);
        ASSERT_LE(std::fabs(out[k] - ref), 2.0 * (std::nextafter(ref, HUGE_VAL) - ref)) << k;  // FMA or not
      }
    }
  EXPECT_LE(worst, 8.0);
  std::printf("pixel B crosstalk rates: within %.2f ulp\n", worst);
}

// Vector exp / expm1 / log1p are within a few ulp: p and q from probabilities() against long double.
TEST(Sampling, VectorProbabilitiesAreAccurate) {
  std::vector<double> lam;
  for (double e = -17.0; e < 2.8; e += 0.013) lam.push_back(std::pow(10.0, e));
  std::vector<double> p(lam.size()), q(lam.size());
  probabilities(lam.data(), lam.size(), p.data(), q.data());
  auto ulps = [](double v, long double ref) {
    const double r = static_cast<double>(ref);
    return static_cast<double>(std::fabs(static_cast<long double>(v) - ref)) / (std::nextafter(r, HUGE_VAL) - r);
  };
  double worst_p = 0, worst_q = 0;
  for (size_t i = 0; i < lam.size(); ++i) {
    worst_p = std::max(worst_p, ulps(p[i], -std::expm1(-static_cast<long double>(lam[i]))));
    worst_q = std::max(worst_q, ulps(q[i], std::exp(-static_cast<long double>(lam[i]))));
  }
  EXPECT_LE(worst_p, 4.0);
  EXPECT_LE(worst_q, 4.0);
  std::printf("vector probabilities: p within %.2f ulp, q within %.2f ulp\n", worst_p, worst_q);
}

TEST(Sampling, FramePackingTransposes) {
  Rng rng(5, RngKind::Test, 0);
  for (int i = 0; i < 100; ++i) {
    const uint64_t x = rng.next_u64();
    const uint64_t t = transpose8x8(x);
    for (int r = 0; r < 8; ++r)
      for (int c = 0; c < 8; ++c) ASSERT_EQ((t >> (8 * r + c)) & 1u, (x >> (8 * c + r)) & 1u);
  }
  const int width = 13;
  const uint32_t n = 70;
  const size_t wpp = 2;
  std::vector<uint64_t> masks(width * wpp);
  for (auto& m : masks) m = rng.next_u64();
  for (int x = 0; x < width; ++x) masks[static_cast<size_t>(x) * wpp + 1] &= (uint64_t{1} << (n - 64)) - 1;
  const size_t bpr = 2;
  std::vector<uint8_t> out(n * bpr, 0xFF);
  pack_frames_row(masks.data(), width, n, wpp, out.data(), bpr);
  for (uint32_t f = 0; f < n; ++f)
    for (int x = 0; x < 16; ++x) {
      const bool bit = (out[f * bpr + static_cast<size_t>(x / 8)] >> (x % 8)) & 1u;
      const bool want = x < width && ((masks[static_cast<size_t>(x) * wpp + f / 64] >> (f % 64)) & 1u);
      ASSERT_EQ(bit, want) << f << " " << x;
    }
}

}  // namespace
}  // namespace spadgen::sensor
