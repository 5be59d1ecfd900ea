// Exact photon-count sampling: Bernoulli bits for binary frames and Binomial counts.
//
// Probabilities come in pairs (p, q = 1 - p), each computed accurately on its own (p = -expm1(-lambda),
// q = exp(-lambda)), and every draw works on the smaller of the two, so probabilities near 1 are as exact
// as probabilities near 0.
//
// Bernoulli: a bit is set when a 64-bit uniform integer U is below T = floor(a * 2^64) (a = min(p, q);
// the bit is inverted when a = q). U is built lazily: its top byte comes from the pixel's byte stream (ARS-7
// blocks, sensor/ars.h and sensor/frames_kernel.h) and
// decides the comparison unless it equals T's top byte (probability 1/256); only then are 56 more bits
// drawn. Expected random bytes per bit: 1 + 7/256 = 1.027 (1.004 blocks of 128 bits per 16 bits).
// When a <= 1/512 the bits are drawn sparsely instead: the number of set bits ~ Binomial(N, a), then their
// positions as a uniformly random subset (Floyd's algorithm); the joint law is the same i.i.d. Bernoulli.
// (Both ways are exact for any a; the bound picks the cheaper: see docs/sensor.md.)
//
// Binomial: inversion. Mean below 16: sequential search from 0 on the survival function, computed from
// -expm1 so that P(X >= 1) is exact even for a = 1e-15, compared with U as exact 64-bit thresholds.
// Otherwise: inversion in the order m, m-1, m+1, m-2, ... from the mode m, with the mode's probability
// from log-factorials; expected steps about 1.6 standard deviations.
#pragma once
#include <array>
#include <cstdint>
#include <vector>

#include "core/rng.h"

namespace spadgen::sensor {

// The sequential draws of an Rng stream (next_u32 / next_u64 in the same order as Rng's) when its block 0
// has already been computed, e.g. by a vectorised Philox for many streams at once.
class StreamReader {
 public:
  StreamReader(const Rng& stream, const std::array<uint32_t, 4>& block0) : stream_(stream), buf_(block0) {}
  uint32_t next_u32() {
    if (used_ == 4) {
      buf_ = stream_.block(next_block_++);
      used_ = 0;
    }
    return buf_[used_++];
  }
  uint64_t next_u64() {
    const uint64_t hi = next_u32();
    return (hi << 32) | next_u32();
  }

 private:
  const Rng& stream_;
  std::array<uint32_t, 4> buf_;
  uint32_t next_block_ = 1;
  unsigned used_ = 0;
};

// An unbiased integer in [0, range) from 32-bit draws (Lemire's multiply-and-reject); range <= 2^32.
template <class G>
uint32_t uniform_below(G& rng, uint64_t range) {
  for (;;) {
    const uint64_t m = static_cast<uint64_t>(rng.next_u32()) * range;
    const auto low = static_cast<uint32_t>(m);
    if (low >= static_cast<uint32_t>(range)) return static_cast<uint32_t>(m >> 32);
    const auto reject_below = static_cast<uint32_t>((uint64_t{1} << 32) % range);
    if (low >= reject_below) return static_cast<uint32_t>(m >> 32);
  }
}

// floor(a * 2^64) for a in [0, 1); saturates at 2^64 - 1.
uint64_t probability_threshold(double a);

// The sequential search of inversion from 0 for Binomial(n, a): X = the first x at which U >= floor(P(X > x)
// 2^64) (or n), with P(X > x) walked down from S = P(X > 0), pmf = P(X = 0) by the pmf recurrence
// pmf(x + 1) = pmf(x) (r ratio(x)), r = a / (1 - a), ratio(x) = (n - x) / (x + 1).
template <class Ratio>
uint32_t sequential_search(uint64_t U, uint32_t n, double r, double S, double pmf, Ratio ratio) {
  uint32_t x = 0;
  while (x < n && U < probability_threshold(S)) {
    pmf *= r * ratio(x);
    ++x;
    S -= pmf;  // P(X > x)
    if (!(S > 0.0)) break;
  }
  return x;
}

struct Prob {
  double p = 0.0, q = 1.0;
  double log_q = 1.0;  // log(q) when known exactly (-lambda); positive means "not known"
};
// p = 1 - exp(-lambda) and q = exp(-lambda), each to full relative precision.
Prob prob_from_lambda(double lambda);

class BinomialSampler {
 public:
  explicit BinomialSampler(uint32_t n);
  uint32_t n() const { return n_; }
  // Binomial(n, p); p = 0 gives 0 and q = 0 gives n exactly. Uses the stream's next 64-bit draw only.
  uint32_t sample(Rng& rng, const Prob& pr) const { return sample_u(rng.next_u64(), pr); }
  uint32_t sample(StreamReader& rng, const Prob& pr) const { return sample_u(rng.next_u64(), pr); }
  // The same from the 64-bit uniform U that sample() draws.
  uint32_t sample_u(uint64_t U, const Prob& pr) const;

  // The two halves of the inversion, for callers that computed the probabilities themselves (the
  // vectorised counts kernel). X counts the rarer outcome of probability a <= b = 1 - a.
  // Sequential search from 0 (used when n a < mode_search_from()): S0 = P(X > 0) = -expm1(n log b),
  // P0 = P(X = 0) (1 - S0 when S0 < 0.5, else exp(n log b)). X = 0 exactly when U >= floor(S0 2^64).
  uint32_t search_from_zero(uint64_t U, double a, double b, double S0, double P0) const;
  // Inversion from the mode m = min(n, floor((n + 1) a)) with pm = P(X = m), in the order m, m-1, m+1, ...
  uint32_t search_from_mode(uint64_t U, double a, double b, uint32_t m, double pm) const;
  static constexpr double mode_search_from() { return 16.0; }
  const std::vector<double>& log_factorials() const { return log_fact_; }
  // pmf ratios: up()[x] = (n - x) / (x + 1), down()[x] = x / (n - x + 1)
  const std::vector<double>& up() const { return up_; }
  const std::vector<double>& down() const { return down_; }

 private:
  uint32_t small_side(uint64_t U, double a, double b, double log_b) const;
  uint32_t n_;
  std::vector<double> log_fact_;
  // up_[x] = (n - x) / (x + 1), down_[x] = x / (n - x + 1): pmf ratios without a division per step
  std::vector<double> up_, down_;
};

// n = sampler.n() independent Bernoulli(p) bits: bit i of words[i / 64] is frame i; bits from n up to the
// end of the last word are zero. Draws from `stream` (copied; random access to its blocks).
void sample_bits(const Rng& stream, const BinomialSampler& sampler, const Prob& pr, uint64_t* words);

// The same for many streams at once: pixel i's bits come from the stream Rng(seed, Frames, pixels[i], k)
// and go to words[i * ceil(n / 64) ...], bit-identical to sample_bits. Groups of 256 pixels go through one
// vectorised kernel (frame_bits_group: classes, fills, block 0, the sparse first test, the dense pixels);
// only the sparse pixels with a rare outcome take the scalar sparse path here.
void sample_bits_batch(uint64_t seed, uint64_t k, const uint64_t* pixels, size_t count,
                       const BinomialSampler& sampler, const Prob* pr, uint64_t* words);

// Which path sample_bits takes (for tests).
bool bits_are_sparse(const Prob& pr);

// The 8 x 8 bit matrix transpose: bit c of byte r of the result is bit r of byte c of x.
inline uint64_t transpose8x8(uint64_t x) {
  uint64_t t = (x ^ (x >> 7)) & 0x00AA00AA00AA00AAull;
  x = x ^ t ^ (t << 7);
  t = (x ^ (x >> 14)) & 0x0000CCCC0000CCCCull;
  x = x ^ t ^ (t << 14);
  t = (x ^ (x >> 28)) & 0x00000000F0F0F0F0ull;
  return x ^ t ^ (t << 28);
}

// Writes the frames of one row of `width` pixels: masks[x * words_per_pixel ...] hold pixel x's n bits;
// out[i * frame_stride + x / 8] bit (x % 8) receives frame i of pixel x (bytes are overwritten).
void pack_frames_row(const uint64_t* masks, int width, uint32_t n, size_t words_per_pixel, uint8_t* out,
                     size_t frame_stride);

}  // namespace spadgen::sensor
