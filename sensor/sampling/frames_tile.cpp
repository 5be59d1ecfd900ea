// Compiled once per target by Highway's foreach_target; see frames_tile.h. Compiled with
// -ffp-contract=off (sensor/CMakeLists.txt): its scalar arithmetic must round as the reference's
// (sampling.cpp, baseline x86-64, no FMA) does.
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "sensor/sampling/frames_tile.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

#include <Random123/philox.h>

#include <algorithm>
#include <bit>
#include <cstring>

#include "sensor/sampling/frames_tile.h"
#include "sensor/sampling/compress-inl.h"
#include "sensor/sampling/philox-inl.h"
#include "sensor/sampling/threshold-inl.h"

#ifndef SPADGEN_FRAMES_TILE_ONCE
#define SPADGEN_FRAMES_TILE_ONCE
namespace spadgen::sensor::frames_tile_detail {

// Direction d's words of a pixel's crosstalk stream Rng(seed, Crosstalk, pixel, k), as crosstalk_reference
// reads them: blocks 1 + d, 5 + d, 9 + d, ..., word 0 first; the first block given, the others by scalar
// Philox.
class DirectionReader {
 public:
  DirectionReader(const uint32_t key[2], uint32_t d, uint32_t k, uint32_t lo, uint32_t hi, const uint32_t first[4])
      : key_{{key[0], key[1]}}, ctr_{{0u, k, lo, hi}}, next_block_(5 + d) {
    std::memcpy(buf_, first, sizeof(buf_));
  }
  uint32_t next_u32() {
    if (used_ == 4) {
      ctr_.v[0] = next_block_;
      next_block_ += 4;
      const auto r = r123::Philox4x32()(ctr_, key_);
      for (int i = 0; i < 4; ++i) buf_[i] = r.v[i];
      used_ = 0;
    }
    return buf_[used_++];
  }
  uint64_t next_u64() {
    const uint64_t hi = next_u32();
    return (hi << 32) | next_u32();
  }

 private:
  r123::Philox4x32::key_type key_;
  r123::Philox4x32::ctr_type ctr_;
  uint32_t buf_[4];
  uint32_t next_block_;
  unsigned used_ = 0;
};

}  // namespace spadgen::sensor::frames_tile_detail
#endif

HWY_BEFORE_NAMESPACE();
namespace spadgen::sensor {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;
using frames_tile_detail::DirectionReader;

HWY_INLINE uint32_t PopcountWords(const uint64_t* w, size_t nw) {
  uint32_t c = 0;
  for (size_t i = 0; i < nw; ++i) c += static_cast<uint32_t>(std::popcount(w[i]));
  return c;
}

// The frame of set bit t (counted from frame 0) of words (t < their popcount).
HWY_INLINE uint32_t SelectBit(const uint64_t* words, size_t nw, uint32_t t) {
  for (size_t q = 0; q < nw; ++q) {
    uint64_t b = words[q];
    const auto c = static_cast<uint32_t>(std::popcount(b));
    if (t >= c) {
      t -= c;
      continue;
    }
#if HWY_ARCH_X86 && HWY_TARGET <= HWY_AVX2  // BMI2: deposit 1 << t at the t-th set bit
    b = _pdep_u64(uint64_t{1} << t, b);
#else
    for (; t > 0; --t) b &= b - 1;
#endif
    return static_cast<uint32_t>(64 * q) + static_cast<uint32_t>(std::countr_zero(b));
  }
  return 0;
}

// S and P0 of crosstalk_no_hit for pixel B's r = xt and every c <= N, computed once per law and N.
HWY_INLINE void PixelBTable(const CrosstalkLaw& law, uint32_t N, FramesTileScratch& s) {
  if (law.xt == s.b_xt && N == s.b_frames) return;
  s.b_xt = law.xt;
  s.b_frames = N;
  const double lr = std::log1p(-law.xt), rr = law.xt / (1.0 - law.xt);
  s.b_S.resize(N + 1);
  s.b_P0.resize(N + 1);
  for (auto* t : {&s.b_T0, &s.b_T1, &s.b_T2}) t->assign(N + 1, 0);
  for (uint32_t c = 0; c <= N; ++c) {
    crosstalk_no_hit(c, lr, s.b_S[c], s.b_P0[c]);
    // crosstalk_hits_exact's thresholds floor(P(H > h) 2^64), h < 3, with sequential_search's operations
    // (0 where its search stops: h >= c, or P(H > h) <= 0)
    const auto ratio = [c](uint32_t x) { return static_cast<double>(c - x) / static_cast<double>(x + 1); };
    double S = s.b_S[c], pmf = s.b_P0[c];
    uint64_t* T[3] = {&s.b_T0[c], &s.b_T1[c], &s.b_T2[c]};
    for (uint32_t h = 0; h < 3 && h < c; ++h) {
      if (h > 0) {
        pmf *= rr * ratio(h - 1);
        S -= pmf;
        if (!(S > 0.0)) break;
      }
      *T[h] = probability_threshold(S);
    }
  }
}

// One direction's draws as crosstalk_reference makes them, once its limit let it through: neighbour
// `theirs` (n_i avalanche frames, probabilities nb, bound rho); its hits ORed into `hits` (zero on entry).
HWY_INLINE void CrosstalkDirection(const CrosstalkLaw& law, uint32_t n_i, const Prob& nb, double rho,
                                   const uint64_t* HWY_RESTRICT theirs, size_t nw, uint32_t w, DirectionReader& rd,
                                   FramesTileScratch& s, uint64_t* HWY_RESTRICT hits) {
  if (crosstalk_per_candidate(n_i, rho)) {
    const uint64_t thr = probability_threshold(crosstalk_rate(law, nb));
    for (size_t q = 0; q < nw; ++q)
      for (uint64_t b = theirs[q]; b != 0; b &= b - 1)
        if (rd.next_u64() < thr) hits[q] |= b & (~b + 1);
    return;
  }
  const uint64_t U = (uint64_t{w} << 32) | rd.next_u32();
  uint32_t h = crosstalk_hits_bounded(U, n_i, law, nb, rho);
  if (h == kCrosstalkUndecided) {  // crosstalk_hits' exact part (pixel B's S and P0 from the table)
    const double r = crosstalk_rate(law, nb);
    double S, P0;
    if (law.single_avalanche) {
      S = s.b_S[n_i];
      P0 = s.b_P0[n_i];
    } else {
      crosstalk_no_hit(n_i, std::log1p(-r), S, P0);
    }
    h = crosstalk_hits_exact(U, n_i, r, S, P0);
  }
  for (uint32_t j = n_i - h; j < n_i; ++j) {  // Floyd: a uniformly random h-subset of the neighbour's frames
    uint32_t f = SelectBit(theirs, nw, uniform_below(rd, uint64_t{j} + 1));
    if ((hits[f / 64] >> (f % 64)) & 1u) f = SelectBit(theirs, nw, j);
    hits[f / 64] |= uint64_t{1} << (f % 64);
  }
}

// crosstalk_limit and rho (crosstalk_rate_bound) of count region pixels of one row (law), vectorised with
// the same operations in the same order (the same bits).
HWY_INLINE void LimitsOfRow(const CrosstalkLaw& law, const uint32_t* HWY_RESTRICT n, const Prob* HWY_RESTRICT pr,
                            size_t count, uint32_t* HWY_RESTRICT lim, double* HWY_RESTRICT rho) {
  const hn::ScalableTag<double> d;
  const hn::Rebind<int32_t, decltype(d)> di32;
  const size_t L = hn::Lanes(d);
  constexpr size_t kMaxL = hn::MaxLanes(hn::ScalableTag<double>());
  alignas(64) double tp[3 * kMaxL], tl[kMaxL];
  alignas(64) int32_t tn[kMaxL];
  const auto xt = hn::Set(d, law.xt);
  for (size_t i = 0; i < count; i += L) {
    const size_t c = std::min(L, count - i);
    hn::Vec<decltype(d)> p, q, lq;
    if (c == L) {
      hn::LoadInterleaved3(d, &pr[i].p, p, q, lq);
      std::memcpy(tn, n + i, L * sizeof(uint32_t));
    } else {  // the tail through padded copies (n = 0: limit 0)
      for (size_t j = 0; j < L; ++j) {
        const Prob v = j < c ? pr[i + j] : Prob{1.0, 0.0, -1.0};
        tp[3 * j] = v.p;
        tp[3 * j + 1] = v.q;
        tp[3 * j + 2] = v.log_q;
        tn[j] = j < c ? static_cast<int32_t>(n[i + j]) : 0;
      }
      hn::LoadInterleaved3(d, tp, p, q, lq);
    }
    const auto nv = hn::PromoteTo(d, hn::Load(di32, tn));  // n <= N < 2^31
    const auto r = law.single_avalanche ? xt : hn::Div(hn::Mul(xt, hn::Neg(lq)), p);
    const auto nr = hn::Mul(nv, r);
    const auto x = hn::Mul(hn::Mul(nr, hn::Set(d, 0x1p32)), hn::Set(d, 1.0 + 0x1p-40));
    const auto per_candidate = hn::Or(hn::Not(hn::Lt(r, hn::Set(d, 0.5))), hn::Not(hn::Lt(nr, hn::Set(d, 16.0))));
    const auto max = hn::Or(per_candidate, hn::Ge(x, hn::Set(d, 4294967295.0)));
    const auto v = hn::IfThenElse(max, hn::Set(d, 4294967295.0), hn::Ceil(x));
    hn::Store(hn::IfThenZeroElse(hn::Eq(nv, hn::Zero(d)), v), d, tl);
    for (size_t j = 0; j < c; ++j) lim[i + j] = static_cast<uint32_t>(tl[j]);
    if (c == L) {
      hn::StoreU(r, d, rho + i);
    } else {  // (a variable-length memcpy here compiled to a slow rep movs)
      hn::Store(r, d, tl);
      for (size_t j = 0; j < c; ++j) rho[i + j] = tl[j];
    }
  }
}

// One stage of the 64 x 64 bit-matrix transpose (one matrix per lane) on R of its rows held in v: swaps bit
// c + S of row i with bit c of row i + J (the S x S blocks above and below the diagonal of every 2S x 2S
// block; J is the distance of those rows within v).
template <int S, size_t J, size_t R, class D>
HWY_INLINE void TransposeStage(D d, hn::Vec<D> (&v)[R], uint64_t low_halves) {
  const auto m = hn::Set(d, low_halves);
#pragma GCC unroll 16
  for (size_t r = 0; r < R; r += 2 * J)
#pragma GCC unroll 16
    for (size_t i = r; i < r + J; ++i) {
      const auto a = v[i], b = v[i + J];
      const auto t = hn::And(hn::Xor(hn::ShiftRight<S>(a), b), m);
      v[i] = hn::Xor(a, hn::ShiftLeft<S>(t));
      v[i + J] = hn::Xor(b, t);
    }
}

// Packs the tile's words into frames: per word q of the pixels and per batch of as many 64-slot groups as
// a vector has 64-bit lanes, row r of lane b = word q of slot r of group b (gathered), transposed in place,
// so that row r is frame 64 q + r of those groups: one store per frame. In registers: rows r0 + 16 j
// (j < 4) through the stages of 32 and 16, then quarters of 16 rows through the stages of 8, 4, 2, 1.
void PackTile(const uint64_t* HWY_RESTRICT own, const FramesTileShape& sh, uint8_t* HWY_RESTRICT frames) {
  const hn::ScalableTag<uint64_t> d;
  const hn::RebindToSigned<decltype(d)> di;
  using V = hn::Vec<decltype(d)>;
  const size_t L = hn::Lanes(d);
  const uint32_t N = sh.frames;
  const size_t nw = (static_cast<size_t>(N) + 63) / 64;
  const size_t fs = static_cast<size_t>(sh.height) * static_cast<size_t>((sh.width + 7) / 8);  // bytes per frame
  const size_t gp = sh.groups_padded;
  constexpr size_t kMaxL = hn::MaxLanes(hn::ScalableTag<uint64_t>());
  alignas(64) uint64_t half[64 * kMaxL];  // the rows after the first two stages
  alignas(64) uint64_t tmp[kMaxL];
  for (size_t g0 = 0; g0 < sh.groups; g0 += L) {
    const size_t bytes = std::min(8 * L, fs - 8 * g0);
    for (size_t q = 0; q < nw; ++q) {
      const auto qv = hn::Set(di, static_cast<int64_t>(q));
      const int64_t* slots = sh.slot_word.data() + g0;
#pragma GCC unroll 2
      for (size_t r0 = 0; r0 < 16; ++r0) {
        V v[4];
#pragma GCC unroll 4
        for (size_t j = 0; j < 4; ++j) v[j] = hn::GatherIndex(d, own, hn::Add(hn::LoadU(di, slots + (r0 + 16 * j) * gp), qv));
        TransposeStage<32, 2>(d, v, 0x00000000FFFFFFFFull);
        TransposeStage<16, 1>(d, v, 0x0000FFFF0000FFFFull);
#pragma GCC unroll 4
        for (size_t j = 0; j < 4; ++j) hn::Store(v[j], d, half + (r0 + 16 * j) * L);
      }
      for (size_t m = 0; m < 4; ++m) {
        V v[16];
#pragma GCC unroll 16
        for (size_t i = 0; i < 16; ++i) v[i] = hn::Load(d, half + (16 * m + i) * L);
        TransposeStage<8, 8>(d, v, 0x00FF00FF00FF00FFull);
        TransposeStage<4, 4>(d, v, 0x0F0F0F0F0F0F0F0Full);
        TransposeStage<2, 2>(d, v, 0x3333333333333333ull);
        TransposeStage<1, 1>(d, v, 0x5555555555555555ull);
#pragma GCC unroll 16
        for (size_t i = 0; i < 16; ++i) {
          const size_t f = 64 * q + 16 * m + i;
          if (f >= N) break;
          uint8_t* dst = frames + f * fs + 8 * g0;
          if (bytes == 8 * L) {
            hn::StoreU(v[i], d, reinterpret_cast<uint64_t*>(dst));  // unaligned: StoreU
          } else {
            hn::Store(v[i], d, tmp);
            std::memcpy(dst, tmp, bytes);
          }
        }
      }
    }
  }
}

// n[i] = the set bits of words[i * nw ...] for i < count; with four words per pixel also the bits of each
// word, one byte each (word q in byte q of pop[i]).
HWY_INLINE void Popcounts(const uint64_t* HWY_RESTRICT words, size_t nw, size_t count, uint32_t* HWY_RESTRICT n,
                          uint32_t* HWY_RESTRICT pop) {
  size_t i = 0;
#if HWY_TARGET != HWY_SCALAR
  if (nw == 4) {  // frames <= 256: eight pixels' four words per step
    const hn::ScalableTag<uint64_t> d;
    const size_t L = hn::Lanes(d);
    alignas(64) uint64_t t[hn::MaxLanes(hn::ScalableTag<uint64_t>())];
    for (; i + L <= count; i += L) {
      hn::Vec<decltype(d)> a, b, c, e;
      hn::LoadInterleaved4(d, words + 4 * i, a, b, c, e);
      a = hn::PopulationCount(a);
      b = hn::PopulationCount(b);
      c = hn::PopulationCount(c);
      e = hn::PopulationCount(e);
      const auto sum = hn::Add(hn::Add(a, b), hn::Add(c, e));
      const auto bytes = hn::Or(hn::Or(a, hn::ShiftLeft<8>(b)), hn::Or(hn::ShiftLeft<16>(c), hn::ShiftLeft<24>(e)));
      hn::Store(hn::Or(sum, hn::ShiftLeft<32>(bytes)), d, t);
      for (size_t j = 0; j < L; ++j) {
        n[i + j] = static_cast<uint32_t>(t[j]);
        pop[i + j] = static_cast<uint32_t>(t[j] >> 32);
      }
    }
  }
#endif
  for (; i < count; ++i) {
    n[i] = PopcountWords(words + i * nw, nw);
    pop[i] = 0;
    for (size_t q = 0; q < nw && q < 4; ++q) pop[i] |= static_cast<uint32_t>(std::popcount(words[i * nw + q])) << (8 * q);
  }
}

// The position (0..63) of set bit t of every lane's word (t < its popcount): a binary search on the popcounts
// of the lower halves.
template <class D>
HWY_INLINE hn::Vec<D> SelectInWord(D d, hn::Vec<D> word, hn::Vec<D> t) {
  auto pos = hn::Zero(d);
#define SPADGEN_SELECT_STEP(h)                                                                \
  {                                                                                           \
    const auto low = hn::PopulationCount(hn::And(word, hn::Set(d, (uint64_t{1} << h) - 1)));  \
    const auto go = hn::Not(hn::Lt(t, low));                                                           \
    t = hn::IfThenElse(go, hn::Sub(t, low), t);                                               \
    word = hn::IfThenElse(go, hn::ShiftRight<h>(word), word);                                 \
    pos = hn::IfThenElse(go, hn::Add(pos, hn::Set(d, uint64_t{h})), pos);                     \
  }
  SPADGEN_SELECT_STEP(32)
  SPADGEN_SELECT_STEP(16)
  SPADGEN_SELECT_STEP(8)
  SPADGEN_SELECT_STEP(4)
  SPADGEN_SELECT_STEP(2)
  SPADGEN_SELECT_STEP(1)
#undef SPADGEN_SELECT_STEP
  return pos;
}

// The draws of the listed (pixel, direction) pairs, eight (a vector of 64-bit lanes) at a time, exactly as
// CrosstalkDirection makes them: U, then crosstalk_hits' bounds (H = 0; H = 1, whose one frame comes from
// the direction's next word by uniform_below when its first multiply decides, found among the neighbour's
// four words from their popcounts). Hits go to (s.hit_t, s.hit_frame); the other pairs (per candidate, more
// than one hit, near a bound, a possible rejection) are listed in s.fallback for CrosstalkDirection.
// Frames <= 256 (four words per pixel).
HWY_INLINE void DecidePairs(const FramesTileShape& sh, size_t np, const uint64_t* HWY_RESTRICT own,
                            const Prob* HWY_RESTRICT prob, FramesTileScratch& s) {
  const hn::ScalableTag<uint64_t> du;
  const hn::RebindToSigned<decltype(du)> di;
  const hn::RebindToFloat<decltype(du)> dd;
  const hn::Rebind<uint32_t, decltype(du)> d32;  // the same lanes as 32-bit values
  const hn::Rebind<int32_t, decltype(du)> di32;
  const size_t L = hn::Lanes(du);
  constexpr double up = 1.0 + 0x1p-40, down = 1.0 - 0x1p-40;
  const auto iota = hn::Iota(du, uint64_t{0});
  const auto* log_q = reinterpret_cast<const double*>(prob) + 2;  // Prob = {p, q, log_q}
  const auto RW = static_cast<int32_t>(sh.region_width);
  const auto* t_region = reinterpret_cast<const int32_t*>(sh.tile_region.data());
  const auto* n_all = reinterpret_cast<const int32_t*>(s.n.data());
  const auto* pop_all = reinterpret_cast<const int32_t*>(s.pop.data());
  for (size_t j0 = 0; j0 < np; j0 += L) {
    const auto live = hn::RebindMask(du, hn::FirstN(di, np - j0));
    // lanes beyond the list: pair 0's pixel and direction (stale values would gather out of bounds)
    const auto live32 = hn::FirstN(di32, np - j0);
    const auto t = hn::IfThenElse(live32, hn::BitCast(di32, hn::LoadU(d32, s.p_t.data() + j0)), hn::Set(di32, static_cast<int32_t>(s.p_t[0])));
    const auto dir = hn::IfThenElse(live32, hn::BitCast(di32, hn::LoadU(d32, s.p_d.data() + j0)), hn::Set(di32, static_cast<int32_t>(s.p_d[0])));
    const auto ri = hn::GatherIndex(di32, t_region, t);
    const auto is = [&](int32_t v) { return hn::Eq(dir, hn::Set(di32, v)); };
    const auto off_r = hn::IfThenElse(is(0), hn::Set(di32, -1), hn::IfThenElse(is(1), hn::Set(di32, 1),
                                      hn::IfThenElse(is(2), hn::Set(di32, -RW), hn::Set(di32, RW))));
    const auto i32 = hn::Add(ri, off_r);
    const auto i = hn::PromoteTo(di, i32);
    const auto n_i32 = hn::GatherIndex(di32, n_all, i32);
    const auto n_u = hn::PromoteTo(du, hn::BitCast(d32, n_i32));
    const auto cd = hn::PromoteTo(dd, n_i32);
    const auto rho = hn::GatherIndex(dd, s.rho.data(), i);
    const auto row = hn::PromoteTo(di, hn::IfThenElse(live32, hn::BitCast(di32, hn::LoadU(d32, s.p_row.data() + j0)),
                                                      hn::Set(di32, static_cast<int32_t>(s.p_row[0]))));
    const auto xt = hn::GatherIndex(dd, sh.row_xt.data(), row);
    const auto single = hn::RebindMask(dd, hn::Ne(hn::GatherIndex(du, sh.row_single.data(), row), hn::Zero(du)));
    const auto per_candidate = hn::RebindMask(du, hn::Or(hn::Not(hn::Lt(rho, hn::Set(dd, 0.5))),
                                                         hn::Not(hn::Lt(hn::Mul(cd, rho), hn::Set(dd, 16.0)))));
    // U and the bounds of crosstalk_hits, with its operations in its order
    const auto U = hn::Or(hn::ShiftLeft<32>(hn::PromoteTo(du, hn::LoadU(d32, s.p_w.data() + j0))),
                          hn::PromoteTo(du, hn::LoadU(d32, s.p_b[0].data() + j0)));
    const auto y = hn::Mul(xt, hn::Neg(hn::GatherIndex(dd, log_q, hn::Mul(i, hn::Set(di, 3)))));
    const auto r_hi = hn::IfThenElse(single, xt, hn::Mul(rho, hn::Set(dd, up)));
    const auto r_lo = hn::IfThenElse(single, xt, hn::Mul(hn::Mul(rho, hn::Sub(hn::Set(dd, 1.0), hn::Mul(hn::Set(dd, 0.5), y))),
                                                         hn::Set(dd, down)));
    const auto vup = hn::Set(dd, up), vdown = hn::Set(dd, down);
    const auto t1 = hn::Mul(hn::Mul(cd, r_hi), vup);
    const auto pairs = hn::Mul(hn::Mul(hn::Set(dd, 0.5), cd), hn::Sub(cd, hn::Set(dd, 1.0)));
    const auto triples = hn::Div(hn::Mul(pairs, hn::Sub(cd, hn::Set(dd, 2.0))), hn::Set(dd, 3.0));
    const auto p2_hi = hn::Mul(hn::Mul(hn::Mul(pairs, r_hi), r_hi), vup);
    const auto p2_lo = hn::Mul(hn::Mul(hn::Mul(pairs, r_lo), r_lo), vdown);
    const auto p3_hi = hn::Mul(hn::Mul(hn::Mul(hn::Mul(hn::Mul(triples, r_hi), r_hi), r_hi), vup), vup);
    const auto slack = hn::Mul(t1, hn::Set(dd, 0x1p-45));
    const auto s_hi = hn::Add(hn::Mul(hn::Add(hn::Sub(t1, p2_lo), p3_hi), vup), slack);
    const auto none = hn::Or(hn::Not(hn::Lt(U, ProbabilityThreshold(dd, t1))),
                             hn::Not(hn::Lt(U, ProbabilityThreshold(dd, hn::Max(s_hi, hn::Zero(dd))))));
    const auto s_lo = hn::Sub(hn::Mul(hn::Sub(hn::Mul(hn::Mul(cd, r_lo), vdown), p2_hi), vdown), slack);
    const auto below_s = hn::And(hn::RebindMask(du, hn::Gt(s_lo, hn::Zero(dd))),
                                 hn::Lt(U, ProbabilityThreshold(dd, hn::Max(s_lo, hn::Zero(dd)))));
    const auto one = hn::AndNot(none, hn::And(below_s, hn::Not(hn::Lt(U, ProbabilityThreshold(dd, p2_hi)))));
    const auto regular = hn::AndNot(per_candidate, live);
    // Pixel B, undecided by the bounds: crosstalk_hits_exact's thresholds from the table (H < 3)
    auto h = hn::IfThenElseZero(one, hn::Set(du, 1));
    auto decided = hn::And(regular, hn::Or(none, one));
    const auto table = hn::AndNot(hn::Or(none, one), hn::And(regular, hn::RebindMask(du, single)));
    if (!hn::AllFalse(du, table) && s.b_frames == sh.frames) {
      const auto ci = hn::IfThenElseZero(hn::RebindMask(di, table), hn::BitCast(di, n_u));
      const auto below0 = hn::Lt(U, hn::GatherIndex(du, s.b_T0.data(), ci));
      const auto below1 = hn::Lt(U, hn::GatherIndex(du, s.b_T1.data(), ci));
      const auto below2 = hn::Lt(U, hn::GatherIndex(du, s.b_T2.data(), ci));
      const auto ht = hn::Add(hn::IfThenElseZero(below0, hn::Set(du, 1)), hn::IfThenElseZero(below1, hn::Set(du, 1)));
      h = hn::IfThenElse(table, ht, h);
      decided = hn::Or(decided, hn::AndNot(below2, table));
    }
    // Floyd for H = 1 (frame uniform_below(n_i) from the direction's next word) and H = 2 (uniform_below(n_i -
    // 1), then uniform_below(n_i), taken to be n_i - 1 when it repeats the first): decided when every
    // multiply's low half is at least its range (Lemire)
    const auto two = hn::Eq(h, hn::Set(du, 2));
    const auto range1 = hn::Sub(n_u, hn::IfThenElseZero(two, hn::Set(du, 1)));
    const auto m1 = hn::Mul(hn::PromoteTo(du, hn::LoadU(d32, s.p_b[1].data() + j0)), range1);  // < 2^41: exact
    const auto m2 = hn::Mul(hn::PromoteTo(du, hn::LoadU(d32, s.p_b[2].data() + j0)), n_u);
    const auto low = hn::Set(du, 0xFFFFFFFFull);
    const auto some_hit = hn::Ne(h, hn::Zero(du));
    const auto accept = hn::And(hn::Or(hn::Not(some_hit), hn::Not(hn::Lt(hn::And(m1, low), range1))),
                                hn::Or(hn::Not(two), hn::Not(hn::Lt(hn::And(m2, low), n_u))));
    const auto ok = hn::And(decided, accept);
    const auto hit = hn::And(ok, some_hit), hit2 = hn::And(ok, two);
    const auto fb = hn::And(live, hn::Or(per_candidate, hn::Not(ok)));
    if (!hn::AllFalse(du, hit)) {
      // the frame of rank k among the neighbour's, from its four words' popcounts
      const auto pop = hn::PromoteTo(du, hn::BitCast(d32, hn::GatherIndex(di32, pop_all, i32)));
      const auto byte = hn::Set(du, 0xFF);
      const auto p1 = hn::And(pop, byte);
      const auto p2 = hn::Add(p1, hn::And(hn::ShiftRight<8>(pop), byte));
      const auto p3 = hn::Add(p2, hn::And(hn::ShiftRight<16>(pop), byte));
      const auto frame_of = [&](hn::Vec<decltype(du)> k, hn::Mask<decltype(du)> lanes) HWY_ATTR {
        const auto ge1 = hn::Not(hn::Lt(k, p1)), ge2 = hn::Not(hn::Lt(k, p2)), ge3 = hn::Not(hn::Lt(k, p3));
        const auto q = hn::Add(hn::Add(hn::IfThenElseZero(ge1, hn::Set(du, 1)), hn::IfThenElseZero(ge2, hn::Set(du, 1))),
                               hn::IfThenElseZero(ge3, hn::Set(du, 1)));
        const auto base = hn::IfThenElse(ge3, p3, hn::IfThenElse(ge2, p2, hn::IfThenElseZero(ge1, p1)));
        const auto word_index = hn::IfThenElseZero(hn::RebindMask(di, lanes), hn::Add(hn::Mul(i, hn::Set(di, 4)), hn::BitCast(di, q)));
        const auto word = hn::GatherIndex(du, own, word_index);
        return hn::Add(hn::ShiftLeft<6>(q), SelectInWord(du, word, hn::Sub(k, base)));
      };
      const auto tv = hn::PromoteTo(du, hn::BitCast(d32, t));
      const auto rank1 = hn::ShiftRight<32>(m1);
      size_t nh = s.nhits;
      hn::StoreU(CompressLanes(du, tv, hit), du, s.hit_t.data() + nh);
      hn::StoreU(CompressLanes(du, frame_of(rank1, hit), hit), du, s.hit_frame.data() + nh);
      nh += hn::CountTrue(du, hit);
      if (!hn::AllFalse(du, hit2)) {
        auto rank2 = hn::ShiftRight<32>(m2);
        rank2 = hn::IfThenElse(hn::Eq(rank2, rank1), hn::Sub(n_u, hn::Set(du, 1)), rank2);
        hn::StoreU(CompressLanes(du, tv, hit2), du, s.hit_t.data() + nh);
        hn::StoreU(CompressLanes(du, frame_of(rank2, hit2), hit2), du, s.hit_frame.data() + nh);
        nh += hn::CountTrue(du, hit2);
      }
      s.nhits = nh;
    }
    if (!hn::AllFalse(du, fb)) {
      hn::StoreU(CompressLanes(du, hn::Add(iota, hn::Set(du, j0)), fb), du, s.fallback.data() + s.nfallback);
      s.nfallback += hn::CountTrue(du, fb);
    }
  }
}

void FramesTile(const FramesTileShape& sh, const uint32_t key[2], uint32_t k, const Prob* HWY_RESTRICT prob,
                uint64_t* HWY_RESTRICT own, uint16_t* HWY_RESTRICT counts, uint8_t* HWY_RESTRICT frames,
                FramesTileScratch& s) {
  const size_t nw = (static_cast<size_t>(sh.frames) + 63) / 64;
  const int W = sh.width, H = sh.height;
  const size_t RW = static_cast<size_t>(sh.region_width), RH = static_cast<size_t>(sh.region_height);
  const size_t nreg = RW * RH, ntile = static_cast<size_t>(W) * static_cast<size_t>(H);
  // Own avalanche frames of every region pixel: the counts before crosstalk, and the neighbours' n_i.
  s.n.resize(nreg + 16);
  s.pop.resize(nreg + 16);
  s.n_row.resize(static_cast<size_t>(W) + 16);
  s.pop_row.resize(static_cast<size_t>(W) + 16);
  Popcounts(own, nw, nreg, s.n.data(), s.pop.data());
  for (size_t t = 0; t < ntile; ++t) counts[t] = static_cast<uint16_t>(s.n[sh.tile_region[t]]);
  s.nhits = s.nfallback = 0;

  bool any = false;
  for (uint8_t dirs : sh.row_dirs) any |= dirs != 0;
  if (any) {
    const hn::CappedTag<uint32_t, 16> d32;
    const size_t L = hn::Lanes(d32);
    // Every region pixel's limit and rho on a grid of the tile grown by one pixel (limit 0 outside the
    // region): the neighbours of tile pixel (tx, ty) are at grid (tx, ty + 1), (tx + 2, ty + 1), (tx + 1, ty)
    // and (tx + 1, ty + 2).
    // Every region pixel's limit and rho (runs of rows of one law at a time), and the limits on a grid of
    // the tile grown by one pixel (0 outside the region): the neighbours of tile pixel (tx, ty) are at grid
    // (tx, ty + 1), (tx + 2, ty + 1), (tx + 1, ty) and (tx + 1, ty + 2).
    s.lim_r.assign(nreg, 0u);
    s.rho.assign(nreg, 0.0);
    for (size_t r0 = 0; r0 < RH;) {
      const CrosstalkLaw& law = sh.region_row_law[r0];
      size_t r1 = r0 + 1;
      while (r1 < RH && sh.region_row_law[r1].xt == law.xt && sh.region_row_law[r1].single_avalanche == law.single_avalanche) ++r1;
      if (law.xt > 0.0) LimitsOfRow(law, s.n.data() + r0 * RW, prob + r0 * RW, (r1 - r0) * RW, s.lim_r.data() + r0 * RW, s.rho.data() + r0 * RW);
      r0 = r1;
    }
    const size_t GW = static_cast<size_t>(W) + 2, GH = static_cast<size_t>(H) + 2;
    s.lim.assign(GW * GH + L, 0u);
    {
      const int rx0 = std::max(0, sh.tile_x - 1), rx1 = std::min(static_cast<int>(RW), sh.tile_x + W + 1);
      for (size_t gy = 0; gy < GH; ++gy) {
        const int ry = sh.tile_y - 1 + static_cast<int>(gy);
        if (ry < 0 || ry >= static_cast<int>(RH)) continue;
        std::memcpy(s.lim.data() + gy * GW + static_cast<size_t>(rx0 - (sh.tile_x - 1)),
                    s.lim_r.data() + static_cast<size_t>(ry) * RW + static_cast<size_t>(rx0),
                    static_cast<size_t>(rx1 - rx0) * sizeof(uint32_t));
      }
    }
    // Block 0 of every tile pixel's stream against its neighbours' limits (w_d < limit, or the limit is
    // UINT32_MAX), for the directions the pixel has: the (pixel, direction) pairs that draw, listed.
    const size_t cap = 4 * ntile + 2 * L;
    for (auto* v : {&s.p_t, &s.p_d, &s.p_w, &s.p_lo, &s.p_hi, &s.p_row, &s.p_b[0], &s.p_b[1], &s.p_b[2], &s.p_b[3]})
      v->resize(cap);
    size_t np = 0;
    const auto max = hn::Set(d32, UINT32_MAX);
    const auto iota = hn::Iota(d32, 0u);
    for (int ty = 0; ty < H; ++ty) {
      const unsigned row_dirs = sh.row_dirs[static_cast<size_t>(ty)];
      if (row_dirs == 0) continue;
      const auto row = hn::Set(d32, static_cast<uint32_t>(sh.tile_y + ty));
      const uint32_t* gl = s.lim.data() + static_cast<size_t>(ty + 1) * GW;
      const uint32_t* gu = s.lim.data() + static_cast<size_t>(ty) * GW + 1;
      const uint32_t* gd = s.lim.data() + static_cast<size_t>(ty + 2) * GW + 1;
      for (int tx = 0; tx < W; tx += static_cast<int>(L)) {
        const auto vl = hn::LoadU(d32, gl + tx), vr = hn::LoadU(d32, gl + tx + 2);
        const auto vu = hn::LoadU(d32, gu + tx), vd = hn::LoadU(d32, gd + tx);
        if (hn::AllTrue(d32, hn::Eq(hn::Or(hn::Or(vl, vr), hn::Or(vu, vd)), hn::Zero(d32)))) continue;
        const size_t t0 = static_cast<size_t>(ty) * static_cast<size_t>(W) + static_cast<size_t>(tx);
        const auto lo = hn::LoadU(d32, sh.pixel_lo.data() + t0), hi = hn::LoadU(d32, sh.pixel_hi.data() + t0);
        hn::Vec<decltype(d32)> x[4] = {hn::Zero(d32), hn::Set(d32, k), lo, hi};
        Philox10(d32, key[0], key[1], x[0], x[1], x[2], x[3]);
        const hn::Vec<decltype(d32)> lim[4] = {vl, vr, vu, vd};
        // the directions of these pixels: the row's, without left / right at the image's edges
        auto dirs = hn::Set(d32, row_dirs);
        if (tx == 0 && sh.left_edge) dirs = hn::IfThenElse(hn::FirstN(d32, 1), hn::Set(d32, row_dirs & ~1u), dirs);
        if (sh.right_edge) dirs = hn::IfThenElse(hn::Eq(iota, hn::Set(d32, static_cast<uint32_t>(W - 1 - tx))),
                                                 hn::Set(d32, row_dirs & ~2u), dirs);
        const auto inside = hn::FirstN(d32, static_cast<size_t>(W - tx));
        const auto tv = hn::Add(iota, hn::Set(d32, static_cast<uint32_t>(t0)));
        for (uint32_t d = 0; d < 4; ++d) {
          const auto m = hn::And(hn::And(inside, hn::Ne(hn::And(dirs, hn::Set(d32, 1u << d)), hn::Zero(d32))),
                                 hn::Or(hn::Lt(x[d], lim[d]), hn::Eq(lim[d], max)));
          if (hn::AllFalse(d32, m)) continue;
          const Compressor<decltype(d32)> compress(d32, m);
          hn::StoreU(compress(tv), d32, s.p_t.data() + np);
          hn::StoreU(compress(x[d]), d32, s.p_w.data() + np);
          hn::StoreU(compress(lo), d32, s.p_lo.data() + np);
          hn::StoreU(compress(hi), d32, s.p_hi.data() + np);
          hn::StoreU(hn::Set(d32, d), d32, s.p_d.data() + np);
          hn::StoreU(row, d32, s.p_row.data() + np);
          np += hn::CountTrue(d32, m);
        }
      }
    }
    // Block 1 + d of every pair's stream (its direction's first words), 16 pairs at a time.
    for (size_t j = 0; j < np; j += L) {
      auto x0 = hn::Add(hn::LoadU(d32, s.p_d.data() + j), hn::Set(d32, 1u)), x1 = hn::Set(d32, k);
      auto x2 = hn::LoadU(d32, s.p_lo.data() + j), x3 = hn::LoadU(d32, s.p_hi.data() + j);
      Philox10(d32, key[0], key[1], x0, x1, x2, x3);
      hn::StoreU(x0, d32, s.p_b[0].data() + j);
      hn::StoreU(x1, d32, s.p_b[1].data() + j);
      hn::StoreU(x2, d32, s.p_b[2].data() + j);
      hn::StoreU(x3, d32, s.p_b[3].data() + j);
    }
    s.hit_t.resize(2 * np + 16);
    s.hit_frame.resize(2 * np + 16);
    s.fallback.resize(np + 16);
    for (const CrosstalkLaw& law : sh.region_row_law)
      if (law.single_avalanche && law.xt > 0.0) PixelBTable(law, sh.frames, s);
    if (nw == 4) {
      DecidePairs(sh, np, own, prob, s);
    } else {
      for (size_t j = 0; j < np; ++j) s.fallback[s.nfallback++] = j;
    }
    // The other pairs one by one; their hits as (pair, word, bits).
    s.work.resize(nw);
    s.fb_bits.clear();
    for (size_t f = 0; f < s.nfallback; ++f) {
      const size_t j = s.fallback[f];
      const uint32_t d = s.p_d[j];
      const size_t ri = sh.tile_region[s.p_t[j]];
      const size_t i = d == 0 ? ri - 1 : d == 1 ? ri + 1 : d == 2 ? ri - RW : ri + RW;
      uint64_t* hits = s.work.data();
      std::fill(hits, hits + nw, uint64_t{0});
      const uint32_t first[4] = {s.p_b[0][j], s.p_b[1][j], s.p_b[2][j], s.p_b[3][j]};
      DirectionReader rd(key, d, k, s.p_lo[j], s.p_hi[j], first);
      const CrosstalkLaw& law = sh.region_row_law[s.p_row[j]];
      if (law.single_avalanche) PixelBTable(law, sh.frames, s);
      CrosstalkDirection(law, s.n[i], prob[i], s.rho[i], own + i * nw, nw, s.p_w[j], rd, s, hits);
      for (size_t q = 0; q < nw; ++q)
        if (hits[q] != 0) s.fb_bits.push_back({s.p_t[j], static_cast<uint32_t>(q), hits[q]});
    }
    // Only now (every pair's draws saw its neighbours' own avalanches): the hits into own, and the counts of
    // the pixels that received any.
    for (size_t h = 0; h < s.nhits; ++h)
      own[sh.tile_region[s.hit_t[h]] * nw + s.hit_frame[h] / 64] |= uint64_t{1} << (s.hit_frame[h] % 64);
    for (const auto& b : s.fb_bits) own[sh.tile_region[b.t] * nw + b.word] |= b.bits;
    if (s.nhits + s.fb_bits.size() > 0) {
      for (int ty = 0; ty < H; ++ty) {  // the counts again (a tile row at a time), for the pixels that received hits
        const size_t t0 = static_cast<size_t>(ty) * static_cast<size_t>(W);
        Popcounts(own + sh.tile_region[t0] * nw, nw, static_cast<size_t>(W), s.n_row.data(), s.pop_row.data());
        for (int tx = 0; tx < W; ++tx) counts[t0 + static_cast<size_t>(tx)] = static_cast<uint16_t>(s.n_row[static_cast<size_t>(tx)]);
      }
    }
  }
  PackTile(own, sh, frames);
}

void PackFramesTile(const uint64_t* own, const FramesTileShape& sh, uint8_t* frames) { PackTile(own, sh, frames); }

}  // namespace HWY_NAMESPACE
}  // namespace spadgen::sensor
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace spadgen::sensor {

HWY_EXPORT(FramesTile);
HWY_EXPORT(PackFramesTile);

void FramesTileShape::finish() {
  const size_t nw = (static_cast<size_t>(frames) + 63) / 64;
  const size_t RW = static_cast<size_t>(region_width);
  const auto zero = static_cast<int64_t>(RW * static_cast<size_t>(region_height) * nw);  // own's zero word
  const size_t slots_per_row = static_cast<size_t>((width + 7) / 8) * 8;
  const size_t P = slots_per_row * static_cast<size_t>(height);
  groups = (P + 63) / 64;
  groups_padded = (groups + 7) / 8 * 8;
  slot_word.assign(64 * groups_padded, zero);
  for (size_t s = 0; s < P; ++s) {
    const size_t ty = s / slots_per_row, tx = s % slots_per_row;
    if (tx >= static_cast<size_t>(width)) continue;
    const size_t ri = (static_cast<size_t>(tile_y) + ty) * RW + static_cast<size_t>(tile_x) + tx;
    slot_word[(s % 64) * groups_padded + s / 64] = static_cast<int64_t>(ri * nw);
  }
  // per tile pixel: region and grid index; per region row: the law as the kernel gathers it
  const size_t n = static_cast<size_t>(width) * static_cast<size_t>(height);
  tile_region.assign(n + 16, 0);
  tile_grid.assign(n + 16, 0);
  for (size_t ty = 0; ty < static_cast<size_t>(height); ++ty)
    for (size_t tx = 0; tx < static_cast<size_t>(width); ++tx) {
      tile_region[ty * static_cast<size_t>(width) + tx] =
          static_cast<uint32_t>((static_cast<size_t>(tile_y) + ty) * RW + static_cast<size_t>(tile_x) + tx);
      tile_grid[ty * static_cast<size_t>(width) + tx] = static_cast<uint32_t>((ty + 1) * (static_cast<size_t>(width) + 2) + tx + 1);
    }
  row_xt.clear();
  row_single.clear();
  for (const CrosstalkLaw& law : region_row_law) {
    row_xt.push_back(law.xt);
    row_single.push_back(law.single_avalanche ? 1 : 0);
  }
  // the kernel loads 16 ids at a time
  pixel_lo.resize(n + 16, 0);
  pixel_hi.resize(n + 16, 0);
}

void frames_tile(const FramesTileShape& shape, const uint32_t key[2], uint32_t k, const Prob* prob, uint64_t* own,
                 uint16_t* counts, uint8_t* frames, FramesTileScratch& scratch) {
  HWY_DYNAMIC_DISPATCH(FramesTile)(shape, key, k, prob, own, counts, frames, scratch);
}

void pack_frames_tile(const uint64_t* const* rows, int width, int height, uint32_t n, size_t words_per_pixel,
                      uint8_t* frames) {
  FramesTileShape sh;
  sh.width = sh.region_width = width;
  sh.height = sh.region_height = height;
  sh.frames = n;
  const size_t nw = (static_cast<size_t>(n) + 63) / 64;
  std::vector<uint64_t> own(static_cast<size_t>(width) * static_cast<size_t>(height) * nw + nw, 0);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x)
      for (size_t q = 0; q < nw && q < words_per_pixel; ++q)
        own[(static_cast<size_t>(y) * static_cast<size_t>(width) + static_cast<size_t>(x)) * nw + q] =
            rows[y][static_cast<size_t>(x) * words_per_pixel + q];
  sh.finish();
  HWY_DYNAMIC_DISPATCH(PackFramesTile)(own.data(), sh, frames);
}

}  // namespace spadgen::sensor
#endif
