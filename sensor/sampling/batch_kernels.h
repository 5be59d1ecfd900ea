// Vectorised per-pixel kernels of the sensor, compiled for several instruction sets (Highway
// foreach_target) and chosen at run time (HWY_DYNAMIC_DISPATCH):
//  - probabilities p = -expm1(-lambda), q = exp(-lambda) and crosstalk-corrected rates for all K gates of
//    a pixel, with Highway's Expm1 / Exp / Log1p (measured against long double: at most 2 ulp);
//  - Binomial(N, p) counts of all K gates of a pixel: by BinomialTable (gate sweeps, random words from
//    ARS-7), or by BinomialSampler's inversion (block 0 of the K streams Rng(seed, Counts, pixel, k) on 16
//    lanes of Philox, the decision X = 0 as one comparison of U with floor(P(X > 0) 2^64));
//  - a row of pixel-major results written k-major (transpose_rows).
// Every result depends on the pixel and k only: bit-identical for any tile size or thread count.
#pragma once
#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/rng.h"
#include "sensor/sampling/ars.h"
#include "sensor/sampling/binomial_table.h"
#include "sensor/sampling/sampling.h"

namespace spadgen::sensor {

// Working arrays of one thread (K rounded up to 16): the rates, p, q and counts of every k; the random
// words; and the table kernel's per-k stages (delta, grid row, U1, row entry, guide bound, scalar lanes).
struct KernelScratch {
  std::vector<double> lam, p, q, delta, grid;
  std::vector<uint64_t> U1;
  std::vector<uint32_t> hi, lo, hi2, lo2, x;
  std::vector<int64_t> row, idx, bound, scalar;
  void reserve(size_t K);
};

// p[k] = -expm1(-lam[k]), q[k] = exp(-lam[k]) for k < K (lam >= 0; +inf gives p = 1, q = 0); q may be
// nullptr when only p is needed.
void probabilities(const double* lam, size_t K, double* p, double* q);

// The same as Prob {p, q, -lam[k]} into out[k * stride] (the frames' per-gate input), and p alone into
// p[k] when p is not null.
void probabilities(const double* lam, size_t K, Prob* out, size_t stride, double* p = nullptr);

// Rates with crosstalk from nnb neighbours (arrays of K): pixel A (single_avalanche false)
// out = lam + xt * sum_i nb[i] with nb the neighbours' lambda; pixel B out = lam - sum_i log1p(-xt nb[i])
// with nb the neighbours' p (computed as -log of prod_i (1 - xt nb[i]) with one logarithm; within 8 ulp of
// the sum, test Sampling.CrosstalkRatesAreAccurate).
void crosstalk_rates(const double* lam, size_t K, const double* const* nb, int nnb, double xt,
                     bool single_avalanche, double* out);

// Counts of every k < K for one pixel: X_k ~ Binomial(N, p_k), p_k = -expm1(-lam[k]), from the stream
// Rng(seed, Counts, pixel, k) (key: Rng(seed, Counts, 0, 0).key(); k < 2^32). Results in s.x[0..K) and
// p_k in s.p[0..K). Equal to sampler.sample(Rng(seed, Counts, pixel, k), {p_k, q_k, -lam[k]}) up to the
// rounding of the vectorised exp / expm1 / log1p (a few ulp of the probabilities).
void binomial_counts(const double* lam, size_t K, const uint32_t key[2], uint64_t pixel,
                     const BinomialSampler& sampler, KernelScratch& s);

// The same counts by BinomialTable (table.n() = N): X_k = table.sample(U1, U2, min(p_k, q_k)) (or N minus
// that when q_k < p_k), U1 = words 0-1 and U2 = words 2-3 (high word first) of counts_block(key, pixel, k),
// the ARS-7 block of counter (0, k, pixel low, pixel high) with the key ars_key(key) (sensor/ars.h; key =
// Rng(seed, Counts, 0, 0).key()). p_k and q_k are left in s.p and s.q.
void binomial_counts(const double* lam, size_t K, const uint32_t key[2], uint64_t pixel, const BinomialTable& table,
                     KernelScratch& s);

// dst[k * dst_stride + x] = src[x * K + k] for x < width, k < K: a row of pixel-major results written
// k-major. The 16-bit version reads one element beyond src[width * K - 1] (it must be allocated).
void transpose_rows(const float* src, size_t width, size_t K, float* dst, size_t dst_stride);
void transpose_rows(const uint16_t* src, size_t width, size_t K, uint16_t* dst, size_t dst_stride);

// The tables' random block for (pixel, k): ARS-7, counter (0, k, pixel low, pixel high), key ars_key(key).
inline Block128 counts_block(const uint32_t key[2], uint64_t pixel, uint32_t k) {
  return ars7({0u, k, static_cast<uint32_t>(pixel), static_cast<uint32_t>(pixel >> 32)}, ars_round_keys(ars_key(key)));
}

}  // namespace spadgen::sensor
