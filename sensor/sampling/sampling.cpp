#include "sensor/sampling/sampling.h"

#include <algorithm>
#include <bit>
#include <cmath>

#include "sensor/sampling/batch_kernels.h"
#include "sensor/sampling/frames_kernel.h"
#include "sensor/streams.h"

namespace spadgen::sensor {
namespace {

constexpr double kTwo64 = 18446744073709551616.0;  // 2^64
constexpr double kSparseBelow = 1.0 / 512.0;
constexpr double kModeSearchFrom = BinomialSampler::mode_search_from();

}  // namespace

uint64_t probability_threshold(double a) {
  if (!(a > 0.0)) return 0;
  const double t = a * kTwo64;  // exact: scaling by a power of two
  if (t >= kTwo64) return ~uint64_t{0};
  return static_cast<uint64_t>(t);  // truncation = floor; exact for t >= 2^53, as t is then an integer
}

Prob prob_from_lambda(double lambda) {
  if (!(lambda > 0.0)) return {0.0, 1.0, 0.0};
  // Below 1e-3 the Taylor series of 1 - exp(-lambda) to degree 5 is exact to double precision (next term
  // lambda^6 / 720 < 1.4e-18 lambda); most pixels at most gate positions are here, where expm1 would
  // dominate the cost. q = 1 - p is then exact to an absolute 1e-16 (q is near 1).
  if (lambda < 1e-3) {
    const double l = lambda;
    const double p = l * (1.0 - l * (0.5 - l * (1.0 / 6.0 - l * (1.0 / 24.0 - l * (1.0 / 120.0)))));
    return {p, 1.0 - p, -lambda};
  }
  if (std::isinf(lambda)) return {1.0, 0.0, -lambda};
  return {-std::expm1(-lambda), std::exp(-lambda), -lambda};
}

bool bits_are_sparse(const Prob& pr) { return std::min(pr.p, pr.q) <= kSparseBelow; }

BinomialSampler::BinomialSampler(uint32_t n) : n_(n), log_fact_(n + 1), up_(n + 1), down_(n + 1) {
  for (uint32_t i = 0; i <= n; ++i) {
    log_fact_[i] = std::lgamma(static_cast<double>(i) + 1.0);
    up_[i] = static_cast<double>(n - i) / static_cast<double>(i + 1);
    down_[i] = static_cast<double>(i) / static_cast<double>(n - i + 1);
  }
}

uint32_t BinomialSampler::search_from_zero(uint64_t U, double a, double b, double S0, double P0) const {
  return sequential_search(U, n_, a / b, S0, P0, [this](uint32_t x) { return up_[x]; });
}

uint32_t BinomialSampler::search_from_mode(uint64_t U64, double a, double b, uint32_t m, double pm) const {
  double U = static_cast<double>(U64 >> 11) * 0x1.0p-53;
  U -= pm;
  if (U < 0.0) return m;
  const double r = a / b, r_inv = b / a;
  uint32_t lo = m, hi = m;
  double p_lo = pm, p_hi = pm;
  for (;;) {
    bool moved = false;
    if (lo > 0) {
      p_lo *= down_[lo] * r_inv;
      --lo;
      U -= p_lo;
      if (U < 0.0) return lo;
      moved = true;
    }
    if (hi < n_) {
      p_hi *= r * up_[hi];
      ++hi;
      U -= p_hi;
      if (U < 0.0) return hi;
      moved = true;
    }
    if (!moved) return m;  // U beyond the rounded total probability
  }
}

uint32_t BinomialSampler::small_side(uint64_t U, double a, double b, double log_b) const {
  // a <= b: the probability of the rarer outcome; X counts it.
  const double N = n_;
  const double mean = N * a;
  if (mean < kModeSearchFrom) {
    // P(X >= 1) = 1 - b^N <= N a: most draws end here without a transcendental function.
    if (mean < 1.0 && U >= probability_threshold(mean)) return 0;
    if (log_b > 0.0) log_b = std::log1p(-a);  // not log(b): b near 1 has lost a's digits
    const double S = -std::expm1(N * log_b);               // P(X > 0)
    const double P0 = S < 0.5 ? 1.0 - S : std::exp(N * log_b);  // P(X = 0), to an absolute 1e-16
    return search_from_zero(U, a, b, S, P0);
  }
  if (log_b > 0.0) log_b = std::log1p(-a);
  const double log_a = std::log(a);
  const auto m = static_cast<uint32_t>(std::min(N, std::floor((N + 1.0) * a)));
  const double pm = std::exp(log_fact_[n_] - log_fact_[m] - log_fact_[n_ - m] + m * log_a + (N - m) * log_b);
  return search_from_mode(U, a, b, m, pm);
}

uint32_t BinomialSampler::sample_u(uint64_t U, const Prob& pr) const {
  if (!(pr.p > 0.0) || n_ == 0) return 0;
  if (!(pr.q > 0.0)) return n_;
  // log of the likelier outcome's probability: log q is -lambda when known; log p is computed when needed
  if (pr.p <= pr.q) return small_side(U, pr.p, pr.q, pr.log_q <= 0.0 ? pr.log_q : 1.0);
  return n_ - small_side(U, pr.q, pr.p, 1.0);
}

namespace {

// The bits of one stream; rng draws the sparse path's numbers in the stream's order.
template <class G>
void bits_of_stream(const Rng& stream, G& rng, const BinomialSampler& sampler, const Prob& pr, uint64_t* words) {
  const uint32_t n = sampler.n();
  const size_t nw = (n + 63) / 64;
  std::fill(words, words + nw, uint64_t{0});
  const bool invert = pr.p > pr.q;
  const double a = invert ? pr.q : pr.p;
  if (a > 0.0) {
    if (a <= kSparseBelow) {
      const uint32_t hits = sampler.sample(rng, pr);
      const uint32_t c = invert ? n - hits : hits;  // the rarer outcome's count
      // Floyd: a uniformly random c-subset of [0, n)
      for (uint32_t j = n - c; j < n; ++j) {
        const uint32_t t = uniform_below(rng, uint64_t{j} + 1);
        const uint64_t bit_t = uint64_t{1} << (t % 64);
        if (words[t / 64] & bit_t)
          words[j / 64] |= uint64_t{1} << (j % 64);
        else
          words[t / 64] |= bit_t;
      }
    } else {
      dense_bits(stream, n, probability_threshold(a), words);
    }
  }
  if (invert) {
    for (size_t w = 0; w < nw; ++w) words[w] = ~words[w];
    if (n % 64 != 0) words[nw - 1] &= (uint64_t{1} << (n % 64)) - 1;
  }
}

}  // namespace

void sample_bits(const Rng& stream, const BinomialSampler& sampler, const Prob& pr, uint64_t* words) {
  Rng rng = stream;
  bits_of_stream(stream, rng, sampler, pr, words);
}

void sample_bits_batch(uint64_t seed, uint64_t k, const uint64_t* pixels, size_t count,
                       const BinomialSampler& sampler, const Prob* pr, uint64_t* words) {
  const uint32_t n = sampler.n();
  if (n == 0) return;  // no words (frame_bits_group writes each pixel's last word)
  const size_t nw = (n + 63) / 64;
  const Rng base = streams::frames(seed, 0, k);
  const uint32_t key[2] = {base.key().v[0], base.key().v[1]};
  uint32_t slow[kFrameGroup], block0[4 * kFrameGroup];
  for (size_t g = 0; g < count; g += kFrameGroup) {
    // Fills, dense pixels and the sparse pixels without a rare outcome, vectorised (frame_bits_group); the
    // remaining sparse pixels take bits_of_stream with their block 0 from there.
    const size_t c = std::min(kFrameGroup, count - g);
    const size_t ns = frame_bits_group(key, static_cast<uint32_t>(k), pixels + g, pr + g, c, n, kSparseBelow,
                                       words + g * nw, slow, block0);
    for (size_t j = 0; j < ns; ++j) {
      const size_t i = g + slow[j];
      const Rng stream = streams::frames(seed, pixels[i], k);
      StreamReader rng(stream, {block0[4 * j], block0[4 * j + 1], block0[4 * j + 2], block0[4 * j + 3]});
      bits_of_stream(stream, rng, sampler, pr[i], words + i * nw);
    }
  }
}

double crosstalk_rate(const CrosstalkLaw& law, const Prob& pr) {
  if (law.single_avalanche) return law.xt;
  return std::min(1.0, -std::expm1(-law.xt * -pr.log_q) / pr.p);
}

uint32_t crosstalk_hits_bounded(uint64_t U, uint32_t c, const CrosstalkLaw& law, const Prob& nb, double rho) {
  constexpr double up = 1.0 + 0x1p-40, down = 1.0 - 0x1p-40;
  double r_hi = law.xt, r_lo = law.xt;
  if (!law.single_avalanche) {
    r_hi = rho * up;
    const double y = law.xt * -nb.log_q;  // xt lambda: 1 - exp(-y) >= y - y^2 / 2
    r_lo = rho * (1.0 - 0.5 * y) * down;
  }
  const double cd = c;
  const double t1 = cd * r_hi * up;  // >= c r >= P(H > 0)
  if (U >= probability_threshold(t1)) return 0;
  const double pairs = 0.5 * cd * (cd - 1.0), triples = pairs * (cd - 2.0) / 3.0;
  const double p2_hi = pairs * r_hi * r_hi * up;                  // >= C(c, 2) r^2 >= P(H > 1)
  const double p2_lo = pairs * r_lo * r_lo * down;                // <= C(c, 2) r^2
  const double p3_hi = triples * r_hi * r_hi * r_hi * up * up;    // >= C(c, 3) r^3
  const double slack = t1 * 0x1p-45;
  const double s_hi = (t1 - p2_lo + p3_hi) * up + slack;          // >= P(H > 0)
  if (U >= probability_threshold(s_hi)) return 0;
  const double s_lo = (cd * r_lo * down - p2_hi) * down - slack;  // <= P(H > 0)
  if (U < probability_threshold(s_lo) && U >= probability_threshold(p2_hi)) return 1;
  return kCrosstalkUndecided;
}

void crosstalk_no_hit(uint32_t c, double lr, double& S, double& P0) {
  S = -std::expm1(static_cast<double>(c) * lr);
  P0 = S < 0.5 ? 1.0 - S : std::exp(static_cast<double>(c) * lr);
}

uint32_t crosstalk_hits_exact(uint64_t U, uint32_t c, double r, double S, double P0) {
  return sequential_search(U, c, r / (1.0 - r), S, P0,
                           [c](uint32_t x) { return static_cast<double>(c - x) / static_cast<double>(x + 1); });
}

uint32_t crosstalk_hits(uint64_t U, uint32_t c, const CrosstalkLaw& law, const Prob& nb, double rho) {
  const uint32_t h = crosstalk_hits_bounded(U, c, law, nb, rho);
  if (h != kCrosstalkUndecided) return h;
  const double r = crosstalk_rate(law, nb);
  double S, P0;
  crosstalk_no_hit(c, std::log1p(-r), S, P0);
  return crosstalk_hits_exact(U, c, r, S, P0);
}

namespace {

uint32_t popcount_words(const uint64_t* w, size_t nw) {
  uint32_t c = 0;
  for (size_t i = 0; i < nw; ++i) c += static_cast<uint32_t>(std::popcount(w[i]));
  return c;
}

// The frame of set bit t (counted from frame 0) of words.
uint32_t select_bit(const uint64_t* words, size_t nw, uint32_t t) {
  for (size_t i = 0; i < nw; ++i) {
    uint64_t b = words[i];
    const auto c = static_cast<uint32_t>(std::popcount(b));
    if (t >= c) {
      t -= c;
      continue;
    }
    for (; t > 0; --t) b &= b - 1;
    return static_cast<uint32_t>(64 * i) + static_cast<uint32_t>(std::countr_zero(b));
  }
  return ~0u;
}

}  // namespace

uint32_t crosstalk_reference(const Rng& stream, uint32_t n, const uint64_t* own, const CrosstalkNeighbour nb[4],
                             const CrosstalkLaw& law, uint64_t* extra) {
  const size_t nw = (n + 63) / 64;
  const std::array<uint32_t, 4> w = stream.block(0);
  std::vector<uint64_t> hits(nw);
  for (int d = 0; d < 4; ++d) {
    if (nb[d].bits == nullptr) continue;
    const uint64_t* theirs = nb[d].bits;
    const uint32_t ni = popcount_words(theirs, nw);
    const double rho = crosstalk_rate_bound(law, nb[d].prob);
    const uint32_t lim = crosstalk_limit(ni, rho);
    if (!(w[d] < lim || lim == UINT32_MAX)) continue;
    // Direction d's words of the crosstalk stream: blocks 1 + d, 5 + d, 9 + d, ...
    StreamReader rng(stream, 1 + static_cast<uint32_t>(d), 4);
    std::fill(hits.begin(), hits.end(), uint64_t{0});
    if (crosstalk_per_candidate(ni, rho)) {
      const uint64_t thr = probability_threshold(crosstalk_rate(law, nb[d].prob));
      for (size_t i = 0; i < nw; ++i)
        for (uint64_t b = theirs[i]; b != 0; b &= b - 1)
          if (rng.next_u64() < thr) hits[i] |= b & (~b + 1);
    } else {
      const uint64_t U = (uint64_t{w[d]} << 32) | rng.next_u32();
      const uint32_t h = crosstalk_hits(U, ni, law, nb[d].prob, rho);
      for (uint32_t j = ni - h; j < ni; ++j) {  // Floyd: a uniformly random h-subset of the neighbour's frames
        uint32_t f = select_bit(theirs, nw, uniform_below(rng, uint64_t{j} + 1));
        if ((hits[f / 64] >> (f % 64)) & 1u) f = select_bit(theirs, nw, j);
        hits[f / 64] |= uint64_t{1} << (f % 64);
      }
    }
    for (size_t i = 0; i < nw; ++i) extra[i] |= hits[i] & ~own[i];
  }
  uint32_t added = 0;
  for (size_t i = 0; i < nw; ++i) added += static_cast<uint32_t>(std::popcount(extra[i]));
  return added;
}

void pack_frames_row(const uint64_t* masks, int width, uint32_t n, size_t words_per_pixel, uint8_t* out,
                     size_t frame_stride) {
  for (int bx = 0; bx * 8 < width; ++bx) {
    const int npx = std::min(8, width - bx * 8);
    for (size_t w = 0; w < words_per_pixel; ++w) {
      uint64_t m[8] = {0, 0, 0, 0, 0, 0, 0, 0};
      for (int b = 0; b < npx; ++b) m[b] = masks[static_cast<size_t>(bx * 8 + b) * words_per_pixel + w];
      for (uint32_t j = 0; j < 8; ++j) {
        const uint32_t frame0 = static_cast<uint32_t>(w) * 64 + j * 8;
        if (frame0 >= n) break;
        uint64_t x = 0;
        for (int b = 0; b < 8; ++b) x |= ((m[b] >> (8 * j)) & 0xFFu) << (8 * b);
        x = transpose8x8(x);
        const uint32_t count = std::min<uint32_t>(8, n - frame0);
        for (uint32_t i = 0; i < count; ++i)
          out[(frame0 + i) * frame_stride + static_cast<size_t>(bx)] = static_cast<uint8_t>(x >> (8 * i));
      }
    }
  }
}

}  // namespace spadgen::sensor
