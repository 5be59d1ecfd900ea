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
#include <cmath>
#include <cstdint>
#include <vector>

#include "core/rng.h"

namespace spadgen::sensor {

// Sequential draws (next_u32 / next_u64, word 0 of a block first) from blocks first, first + stride,
// first + 2 stride, ... of an Rng stream. With block 0 given (computed already, e.g. by a vectorised
// Philox for many streams at once), the draws of the whole stream in Rng's own order.
class StreamReader {
 public:
  StreamReader(const Rng& stream, uint32_t first_block, uint32_t stride)
      : stream_(stream), next_block_(first_block), stride_(stride), used_(4) {}
  StreamReader(const Rng& stream, const std::array<uint32_t, 4>& block0) : stream_(stream), buf_(block0) {}
  uint32_t next_u32() {
    if (used_ == 4) {
      buf_ = stream_.block(next_block_);
      next_block_ += stride_;
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
  std::array<uint32_t, 4> buf_{};
  uint32_t next_block_ = 1;
  uint32_t stride_ = 1;
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

// Crosstalk between sampled binary frames (docs/sensor.md, "Crosstalk"). Every frame in which a neighbour
// avalanched and this pixel did not (a candidate) becomes a crosstalk detection of this pixel with
// probability r, independently: r = xt for pixel B (one avalanche per frame), r = (1 - exp(-xt lambda)) / p
// for pixel A (lambda, p: the neighbour's), so that the marginal matches the thinned Poisson process of
// the counts path. Only the neighbours' own avalanches fire (second-order crosstalk is neglected).
struct CrosstalkLaw {
  double xt = 0.0;                // crosstalk probability per avalanche (A) or per avalanche frame (B)
  bool single_avalanche = false;  // pixel B
};

// r of a neighbour with probabilities pr (pr.log_q must be -lambda, as probabilities() gives it).
double crosstalk_rate(const CrosstalkLaw& law, const Prob& pr);

// rho >= r without a transcendental function: xt (B), xt lambda / p (A; 1 - exp(-x) <= x).
inline double crosstalk_rate_bound(const CrosstalkLaw& law, const Prob& pr) {
  return law.single_avalanche ? law.xt : law.xt * -pr.log_q / pr.p;
}

// A neighbour with n avalanche frames and bound rho: each candidate is drawn on its own (one 64-bit
// uniform each) when rho >= 1/2 or n rho >= 16 (then the binomial inversion would be long or underflow).
inline bool crosstalk_per_candidate(uint32_t n, double rho) {
  return !(rho < 0.5) || !(static_cast<double>(n) * rho < 16.0);
}

// The limit L of the draw's top 32 bits w for a neighbour with n avalanche frames: when w >= L (and
// L != UINT32_MAX) no hit is possible, because U >= w 2^32 >= n rho 2^64 >= c r 2^64 >= P(hits > 0) 2^64
// (c <= n candidates). L = ceil(n rho 2^32 (1 + 2^-40)), saturated at UINT32_MAX; 0 when n = 0, UINT32_MAX
// when per candidate. Only products: the vector kernel forms the same bits.
inline uint32_t crosstalk_limit(uint32_t n, double rho) {
  if (n == 0) return 0;
  if (crosstalk_per_candidate(n, rho)) return UINT32_MAX;
  const double x = static_cast<double>(n) * rho * 0x1p32 * (1.0 + 0x1p-40);
  return x >= 4294967295.0 ? UINT32_MAX : static_cast<uint32_t>(std::ceil(x));
}

// The number of hits H ~ Binomial(c, r) among the c avalanche frames of a neighbour (r of a neighbour with
// probabilities nb and bound rho = crosstalk_rate_bound; rho < 1/2, c rho < 16) by inversion of the 64-bit
// uniform U: H = the first h with U >= floor(P(H > h) 2^64).
uint32_t crosstalk_hits(uint64_t U, uint32_t c, const CrosstalkLaw& law, const Prob& nb, double rho);

// crosstalk_hits' first part: most draws are decided from bounds, without a transcendental function. With
// r_lo <= r <= r_hi (r itself for pixel B; rho (1 - xt lambda / 2) and rho for pixel A): H = 0 when U >=
// floor(c r_hi 2^64) or U >= floor(S_hi 2^64); H = 1 when U < floor(S_lo 2^64) and U >= floor(P2_hi 2^64),
// where S_lo = c r_lo - C(c, 2) r_hi^2 <= P(H > 0) <= S_hi = c r_hi - C(c, 2) r_lo^2 + C(c, 3) r_hi^3
// (Bonferroni) and P2_hi = C(c, 2) r_hi^2 >= P(H > 1); relative margins of 2^-40 and absolute ones of
// 2^-45 c r_hi cover the rounding. Otherwise kCrosstalkUndecided.
inline constexpr uint32_t kCrosstalkUndecided = ~0u;
uint32_t crosstalk_hits_bounded(uint64_t U, uint32_t c, const CrosstalkLaw& law, const Prob& nb, double rho);

// The rest: S = P(H > 0) = -expm1(c lr) and P0 = P(H = 0) (1 - S while S < 1/2, else exp(c lr)) for lr =
// log1p(-r), then the sequential search from 0 on P(H > h).
void crosstalk_no_hit(uint32_t c, double lr, double& S, double& P0);
uint32_t crosstalk_hits_exact(uint64_t U, uint32_t c, double r, double S, double P0);

// One neighbour of a pixel in crosstalk_reference: its own avalanche frames (nullptr: no neighbour in
// that direction: outside the image or in another array section) and probabilities.
struct CrosstalkNeighbour {
  const uint64_t* bits = nullptr;
  Prob prob;
};

// The scalar reference of the frames' crosstalk (the kernel, frames_tile, gives the same bits): the frames
// in which this pixel (own bits `own`, n frames) is fired by its neighbours nb[0..3] (left, right, up,
// down), from the pixel's stream Rng(seed, Crosstalk, pixel, k). Each of the n_i avalanche frames of a
// neighbour fires the pixel with probability r, independently (a frame where the pixel avalanched itself
// stays as it was: the same law as drawing only in the frames where it did not):
//  - block 0: word d is the top 32 bits w_d of direction d's uniform U_d;
//  - direction d reads its other words from its own blocks 1 + d, 5 + d, 9 + d, ... (word 0 first), so
//    that the directions are independent of each other's draws;
//  - a direction whose neighbour allows a hit (n_i > 0 and w_d < crosstalk_limit(n_i, rho), or that limit
//    is UINT32_MAX) draws: per avalanche frame (crosstalk_per_candidate(n_i, rho)) one 64-bit uniform each
//    (high word first), a hit when below floor(r 2^64); otherwise U_d's low 32 bits, H =
//    crosstalk_hits(U_d, n_i, ...) and H of the n_i frames as a uniformly random subset (Floyd: for j = n_i
//    - H .. n_i - 1, t = uniform_below(j + 1), frame t, or frame j if t is taken; frames counted in order).
// The hits in frames where the pixel did not avalanche are ORed into extra[0 .. ceil(n / 64)) (zero on
// entry); returns their number.
uint32_t crosstalk_reference(const Rng& stream, uint32_t n, const uint64_t* own, const CrosstalkNeighbour nb[4],
                             const CrosstalkLaw& law, uint64_t* extra);

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
