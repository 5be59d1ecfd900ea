// Exact Binomial(n, a) draws from precomputed tables, for the counts of a gate sweep: n = frames per gate
// position (a few hundred), hundreds of millions of draws per run, a = min(p, 1 - p) <= 1/2.
//
// Thinning. With the grid point p_g = g / G <= a below a (g = floor(a G)) and delta = (a - p_g) / (1 - p_g)
// (formed as (a - p_g) times the rounded 1 / (1 - p_g): within 1.5 ulp, like p itself):
//   X = X1 + Y,   X1 ~ Binomial(n, p_g),   Y | X1 ~ Binomial(n - X1, delta)
// is exactly Binomial(n, a): each of the n frames fires in a first round with probability p_g, and a frame
// that did not gets a second chance with probability delta, so it fires with 1 - (1 - p_g)(1 - delta) = a,
// independently of the others.
//
// First round: inversion of the 64-bit uniform U1 against T_g(x) = floor(F_g(x) 2^64), F_g the CDF of
// Binomial(n, p_g) computed in long double from the exact pmf ratios with a compensated sum (absolute
// error below 1e-17): X1 = #{x < n : T_g(x) <= U1}. A guide on U1's top byte gives that count at the
// bucket's lower end, and the search goes up from there (a step or two). U1 = 2^64 - 1 is read as
// 2^64 - 2 (a 2^-64 change of one outcome), so T = 2^64 - 1 (F rounded to 1) is a sentinel no U1 reaches.
// Rows keep only x from the first T > 0 to the first T = 2^64 - 1 (at most 256 entries; the guide holds
// offsets in a byte). The vectorised kernel compares the top 16 bits of T and U1 (a copy of the rows in
// 16 bits: with the guide 1 MB at n = 255, so they stay in the core's L2 cache) and takes first_round for a lane
// whose top bits are equal (probability about 2^-16 per step), so it finds the same X1.
// Second round: inversion of U2 from 0 (the sequential search of BinomialSampler::search_from_zero): Y = 0
// when U2 >= floor(S0 2^64), S0 = P(Y > 0) = -expm1(n2 log1p(-delta)), n2 = n - X1; Y = 1 when U2 >=
// floor(S1 2^64), S1 = S0 - P(Y = 1); and so on. First U2 >= floor(n2 delta 2^64), an upper bound, ends
// most draws without S0 (all but about n / (2G) of them). delta < 1/G and n2 delta < 0.2 here, so log1p
// and expm1 are short series (Horner with fused multiply-adds, truncation below 1e-21 relative), the same
// operations in the kernel and in second_round.
//
// The vectorised kernel (batch_kernels.cpp) takes the same steps with the same floating-point operations
// and calls first_round / second_round for the lanes it does not settle, so it equals sample() draw for draw.
#pragma once
#include <cmath>
#include <cstdint>
#include <memory>
#include <vector>

namespace spadgen::sensor {

class BinomialTable {
 public:
  static constexpr uint32_t kGrid = 4096;  // G, a power of two: p_g = g / G is exact; rows g = 0 .. G / 2
  static constexpr int kGuideBits = 8;
  static constexpr uint32_t kGuide = 1u << kGuideBits;

  // The tables for n frames (built in parallel and shared), or nullptr when a row would hold more than 256
  // entries (n above 802). Built once per n while any holder keeps them, and the last kKeep built or asked
  // for are kept between runs: a dataset whose samples vary the frames (about 3 MB of tables each at 255
  // frames) holds a few, not one per value it met.
  static constexpr size_t kKeep = 4;
  static std::shared_ptr<const BinomialTable> get(uint32_t n);
  uint32_t n() const { return n_; }

  // X ~ Binomial(n, a), 0 <= a <= 1/2, from two 64-bit uniforms.
  uint32_t sample(uint64_t U1, uint64_t U2, double a) const {
    const uint32_t g = grid_index(a);
    const uint32_t x1 = first_round(U1, g);
    return x1 + second_round(U2, n_ - x1, delta(a, g));
  }

  static uint32_t grid_index(double a) { return static_cast<uint32_t>(a * kGrid); }  // floor, a >= 0
  static double grid_p(uint32_t g) { return static_cast<double>(g) * (1.0 / kGrid); }
  // (a - p_g) / (1 - p_g) as (a - p_g) times the rounded 1 / (1 - p_g) of row g (no division per draw; the
  // kernel gathers the same factor)
  double delta(double a, uint32_t g) const { return (a - grid_p(g)) * inv_one_minus_p_[g]; }
  const double* inv_one_minus_p() const { return inv_one_minus_p_.data(); }
  // r = delta / (1 - delta) = delta (1 + delta + ... + delta^4) for delta < 1/G (truncation below 1e-18)
  static double odds(double delta) {
    double t = 1.0 + delta;
    for (int i = 0; i < 3; ++i) t = std::fma(t, delta, 1.0);
    return delta * t;
  }
  uint32_t first_round(uint64_t U1, uint32_t g) const;
  uint32_t second_round(uint64_t U2, uint32_t n2, double delta) const;
  // Series coefficients: log1p(-d) = -d (1 + d / 2 + ... + d^5 / 6) and expm1(x) = x (1 + x / 2! + ...
  // + x^13 / 14!), highest first.
  static constexpr double kLog1pCoeff[6] = {1.0 / 6, 1.0 / 5, 1.0 / 4, 1.0 / 3, 1.0 / 2, 1.0};
  static constexpr double kExpm1Coeff[14] = {1.0 / 1307674368000.0, 1.0 / 87178291200.0, 1.0 / 6227020800.0,
                                             1.0 / 479001600.0, 1.0 / 39916800.0, 1.0 / 3628800.0, 1.0 / 362880.0,
                                             1.0 / 40320.0, 1.0 / 5040.0, 1.0 / 720.0, 1.0 / 120.0, 1.0 / 24.0,
                                             1.0 / 6.0, 1.0 / 2.0};
  // S0 = P(Y > 0) of Binomial(n2, delta) by those series (delta < 1/G, n2 <= 802).
  static double survival0(double n2, double delta);

  // Layout for the kernel. Row g: row()[g] = offset of its first entry | lo << 32 (lo = its first x);
  // entry i of the row is x = lo + i, thresholds64()[offset + i] its T, thresholds16() its top 16 bits;
  // guide()[g * kGuide + b] = X1 - lo at U1 = b 2^56.
  const int64_t* row() const { return row_.data(); }
  const uint64_t* thresholds64() const { return T64_.data(); }
  const uint16_t* thresholds16() const { return T16_.data(); }  // padded: 8-byte reads at any entry are valid
  const uint8_t* guide() const { return guide_.data(); }         // padded likewise

 private:
  explicit BinomialTable(uint32_t n) : n_(n) {}
  static std::unique_ptr<BinomialTable> build(uint32_t n);
  uint32_t n_;
  std::vector<int64_t> row_;
  std::vector<double> inv_one_minus_p_;
  std::vector<uint64_t> T64_;
  std::vector<uint16_t> T16_;
  std::vector<uint8_t> guide_;
};

}  // namespace spadgen::sensor
