// Compiled once per target by Highway's foreach_target; see frames_tile.h. Compiled with
// -ffp-contract=off (sensor/CMakeLists.txt): the scalar crosstalk arithmetic must round as the
// reference's (sampling.cpp, baseline x86-64, no FMA) does.
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "sensor/sampling/frames_tile.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

#include <Random123/philox.h>

#include <algorithm>
#include <bit>
#include <cstring>

#include "sensor/sampling/frames_tile.h"
#include "sensor/sampling/philox-inl.h"

#ifndef SPADGEN_FRAMES_TILE_ONCE
#define SPADGEN_FRAMES_TILE_ONCE
namespace spadgen::sensor::frames_tile_detail {

// The sequential 32-bit words of a pixel's crosstalk stream Rng(seed, Crosstalk, pixel, k) from block 1
// on, with block 1 given (Rng's order: word 0 first; further blocks by scalar Philox).
class XtReader {
 public:
  XtReader(const uint32_t key[2], uint32_t k, uint32_t lo, uint32_t hi, const uint32_t block1[4])
      : key_{{key[0], key[1]}}, ctr_{{0u, k, lo, hi}} {
    std::memcpy(buf_, block1, sizeof(buf_));
  }
  uint32_t next_u32() {
    if (used_ == 4) {
      ctr_.v[0] = next_block_++;
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
  uint32_t next_block_ = 2;
  unsigned used_ = 0;
};

}  // namespace spadgen::sensor::frames_tile_detail
#endif

HWY_BEFORE_NAMESPACE();
namespace spadgen::sensor {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;
using frames_tile_detail::XtReader;

HWY_INLINE uint32_t PopcountWords(const uint64_t* w, size_t nw) {
  uint32_t c = 0;
  for (size_t i = 0; i < nw; ++i) c += static_cast<uint32_t>(std::popcount(w[i]));
  return c;
}

// The frame of set bit t (counted from frame 0) of words (t < their popcount).
HWY_INLINE uint32_t SelectBit(const uint64_t* words, size_t nw, uint32_t t) {
  for (size_t i = 0; i < nw; ++i) {
    uint64_t b = words[i];
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
    return static_cast<uint32_t>(64 * i) + static_cast<uint32_t>(std::countr_zero(b));
  }
  return 0;
}

// r and log1p(-r) of neighbour i of a pixel of law `law`.
HWY_INLINE void RateOf(const CrosstalkLaw& law, size_t i, const Prob* HWY_RESTRICT prob, FramesTileScratch& s,
                       double& r, double& lr) {
  if (law.single_avalanche) {
    r = law.xt;
    lr = s.b_lr;
    return;
  }
  if (s.stamp[i] != s.gen) {
    s.r[i] = crosstalk_rate(law, prob[i]);
    s.lr[i] = std::log1p(-s.r[i]);
    s.stamp[i] = s.gen;
  }
  r = s.r[i];
  lr = s.lr[i];
}

// crosstalk_reference's draws for one pixel (region index ri, grid index gi) whose block 0 is w and whose
// later words come from rd, for the directions in `dirs`: the frames added to extra (zero on entry), and
// their number. The neighbours' limits and rho come from the grid.
HWY_INLINE uint32_t CrosstalkPixel(const CrosstalkLaw& law, unsigned dirs, size_t ri, size_t region_width, size_t gi,
                                   size_t grid_width, const uint32_t w[4], XtReader& rd, const Prob* HWY_RESTRICT prob,
                                   const uint64_t* HWY_RESTRICT own, size_t nw, FramesTileScratch& s,
                                   uint64_t* HWY_RESTRICT extra) {
  uint64_t* HWY_RESTRICT cand = s.work.data();
  uint64_t* HWY_RESTRICT hits = s.work.data() + nw;
  const uint64_t* mine = own + ri * nw;
  const size_t nb_index[4] = {ri - 1, ri + 1, ri - region_width, ri + region_width};
  const size_t nb_grid[4] = {gi - 1, gi + 1, gi - grid_width, gi + grid_width};
  for (; dirs != 0; dirs &= dirs - 1) {
    const auto d = static_cast<size_t>(std::countr_zero(dirs));
    const uint32_t lim = s.lim[nb_grid[d]];
    if (!(w[d] < lim || lim == UINT32_MAX)) continue;
    const size_t i = nb_index[d];
    const uint64_t* theirs = own + i * nw;
    uint32_t c = 0;
    for (size_t q = 0; q < nw; ++q) {
      cand[q] = theirs[q] & ~mine[q];
      c += static_cast<uint32_t>(std::popcount(cand[q]));
    }
    if (c == 0) continue;
    const double rho = s.rho[nb_grid[d]];
    const bool per_candidate = crosstalk_per_candidate(s.n[i], rho);
    if (!per_candidate && !(w[d] < crosstalk_limit(c, rho))) continue;
    double r, lr;
    RateOf(law, i, prob, s, r, lr);
    if (per_candidate) {
      const uint64_t thr = probability_threshold(r);
      for (size_t q = 0; q < nw; ++q)
        for (uint64_t b = cand[q]; b != 0; b &= b - 1)
          if (rd.next_u64() < thr) extra[q] |= b & (~b + 1);
      continue;
    }
    const uint64_t U = (uint64_t{w[d]} << 32) | rd.next_u32();
    double S, P0;
    if (law.single_avalanche) {
      S = s.b_S[c];
      P0 = s.b_P0[c];
    } else {
      crosstalk_no_hit(c, lr, S, P0);
    }
    const uint32_t h = crosstalk_hits(U, c, r, S, P0);
    if (h == 0) continue;
    std::fill(hits, hits + nw, uint64_t{0});
    for (uint32_t j = c - h; j < c; ++j) {  // Floyd: a uniformly random h-subset of the candidates
      uint32_t f = SelectBit(cand, nw, uniform_below(rd, uint64_t{j} + 1));
      if ((hits[f / 64] >> (f % 64)) & 1u) f = SelectBit(cand, nw, j);
      hits[f / 64] |= uint64_t{1} << (f % 64);
    }
    for (size_t q = 0; q < nw; ++q) extra[q] |= hits[q];
  }
  return PopcountWords(extra, nw);  // extra holds candidates only: frames where this pixel was dark
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
    hn::Store(r, d, tl);
    std::memcpy(rho + i, tl, c * sizeof(double));
  }
}

// One stage of the 64 x 64 bit-matrix transpose (rows v[0..63], one matrix per lane): swaps the J x J
// blocks above and below the diagonal of every 2J x 2J block (bit c + J of row i with bit c of row i + J).
template <int J, class D>
HWY_INLINE void TransposeStage(D d, hn::Vec<D>* HWY_RESTRICT v, uint64_t low_halves) {
  const auto m = hn::Set(d, low_halves);
  for (int r = 0; r < 64; r += 2 * J)
    for (int i = r; i < r + J; ++i) {
      const auto a = v[i], b = v[i + J];
      const auto t = hn::And(hn::Xor(hn::ShiftRight<J>(a), b), m);
      v[i] = hn::Xor(a, hn::ShiftLeft<J>(t));
      v[i + J] = hn::Xor(b, t);
    }
}

// Packs the tile's words into frames: per word q of the pixels and per batch of as many 64-slot groups as
// a vector has 64-bit lanes, row r of lane b = word q of slot r of group b (gathered), transposed in place,
// so that row r is frame 64 q + r of those groups: one store per frame.
void PackTile(const uint64_t* HWY_RESTRICT own, const FramesTileShape& sh, uint8_t* HWY_RESTRICT frames) {
  const hn::ScalableTag<uint64_t> d;
  const hn::RebindToSigned<decltype(d)> di;
  const size_t L = hn::Lanes(d);
  const uint32_t N = sh.frames;
  const size_t nw = (static_cast<size_t>(N) + 63) / 64;
  const size_t fs = static_cast<size_t>(sh.height) * static_cast<size_t>((sh.width + 7) / 8);  // bytes per frame
  const size_t gp = sh.groups_padded;
  hn::Vec<decltype(d)> v[64];
  alignas(64) uint64_t tmp[hn::MaxLanes(hn::ScalableTag<uint64_t>())];
  for (size_t g0 = 0; g0 < sh.groups; g0 += L) {
    const size_t bytes = std::min(8 * L, fs - 8 * g0);
    for (size_t q = 0; q < nw; ++q) {
      const auto qv = hn::Set(di, static_cast<int64_t>(q));
      for (int r = 0; r < 64; ++r)
        v[r] = hn::GatherIndex(d, own, hn::Add(hn::LoadU(di, sh.slot_word.data() + static_cast<size_t>(r) * gp + g0), qv));
      TransposeStage<32>(d, v, 0x00000000FFFFFFFFull);
      TransposeStage<16>(d, v, 0x0000FFFF0000FFFFull);
      TransposeStage<8>(d, v, 0x00FF00FF00FF00FFull);
      TransposeStage<4>(d, v, 0x0F0F0F0F0F0F0F0Full);
      TransposeStage<2>(d, v, 0x3333333333333333ull);
      TransposeStage<1>(d, v, 0x5555555555555555ull);
      for (size_t r = 0; r < 64 && 64 * q + r < N; ++r) {
        uint8_t* dst = frames + (64 * q + r) * fs + 8 * g0;
        if (bytes == 8 * L) {
          hn::StoreU(v[r], d, reinterpret_cast<uint64_t*>(dst));  // unaligned: StoreU
        } else {
          hn::Store(v[r], d, tmp);
          std::memcpy(dst, tmp, bytes);
        }
      }
    }
  }
}

void FramesTile(const FramesTileShape& sh, const uint32_t key[2], uint32_t k, const Prob* HWY_RESTRICT prob,
                uint64_t* HWY_RESTRICT own, uint16_t* HWY_RESTRICT counts, uint8_t* HWY_RESTRICT frames,
                FramesTileScratch& s) {
  const size_t nw = (static_cast<size_t>(sh.frames) + 63) / 64;
  const int W = sh.width, H = sh.height;
  const size_t RW = static_cast<size_t>(sh.region_width), RH = static_cast<size_t>(sh.region_height);
  const size_t nreg = RW * RH;
  auto region_index = [&](int tx, int ty) {
    return static_cast<size_t>(sh.tile_y + ty) * RW + static_cast<size_t>(sh.tile_x + tx);
  };
  // Own avalanche frames of every region pixel: the counts before crosstalk, and the neighbours' n_i.
  s.n.resize(nreg);
  for (size_t i = 0; i < nreg; ++i) s.n[i] = PopcountWords(own + i * nw, nw);
  for (int ty = 0; ty < H; ++ty)
    for (int tx = 0; tx < W; ++tx) counts[ty * W + tx] = static_cast<uint16_t>(s.n[region_index(tx, ty)]);

  bool any = false;
  for (uint8_t dirs : sh.row_dirs) any |= dirs != 0;
  if (any) {
    const hn::CappedTag<uint32_t, 16> d32;
    const size_t L = hn::Lanes(d32);
    // Every region pixel's limit on a grid of the tile grown by one pixel (0 outside the region): the
    // neighbours of tile pixel (tx, ty) are at grid (tx, ty + 1), (tx + 2, ty + 1), (tx + 1, ty), (tx + 1, ty + 2).
    const size_t GW = static_cast<size_t>(W) + 2, GH = static_cast<size_t>(H) + 2;
    s.lim.assign(GW * GH + L, 0u);
    s.rho.resize(GW * GH);
    for (size_t gy = 0; gy < GH; ++gy) {
      const int ry = sh.tile_y - 1 + static_cast<int>(gy);
      if (ry < 0 || ry >= static_cast<int>(RH)) continue;
      const CrosstalkLaw& law = sh.region_row_law[static_cast<size_t>(ry)];
      if (!(law.xt > 0.0)) continue;
      const int rx0 = std::max(0, sh.tile_x - 1), rx1 = std::min(static_cast<int>(RW), sh.tile_x + W + 1);
      const size_t i0 = static_cast<size_t>(ry) * RW + static_cast<size_t>(rx0);
      const size_t g0 = gy * GW + static_cast<size_t>(rx0 - (sh.tile_x - 1));
      LimitsOfRow(law, s.n.data() + i0, prob + i0, static_cast<size_t>(rx1 - rx0), s.lim.data() + g0, s.rho.data() + g0);
    }
    // Block 0 of every tile pixel's stream against its neighbours' limits: the pixels where some direction
    // may hit (w_d <= limit, a superset of the reference's w_d < limit). Block 0 is kept per tile pixel,
    // the flagged pixels are listed (compressed in registers: a compressing store is slow).
    const size_t cap = static_cast<size_t>(W) * static_cast<size_t>(H) + L;
    s.flagged.resize(cap);
    s.code.resize(cap);
    s.blocks.resize(10 * cap);
    uint32_t* bw[10];
    for (size_t q = 0; q < 10; ++q) bw[q] = s.blocks.data() + q * cap;  // block 0 (per tile pixel), block 1, lo, hi
    size_t nf = 0;
    const auto iota = hn::Iota(d32, 0u);
    for (int ty = 0; ty < H; ++ty) {
      if (sh.row_dirs[static_cast<size_t>(ty)] == 0) continue;
      const uint32_t* gl = s.lim.data() + static_cast<size_t>(ty + 1) * GW;
      const uint32_t* gu = s.lim.data() + static_cast<size_t>(ty) * GW + 1;
      const uint32_t* gd = s.lim.data() + static_cast<size_t>(ty + 2) * GW + 1;
      for (int tx = 0; tx < W; tx += static_cast<int>(L)) {
        const auto vl = hn::LoadU(d32, gl + tx), vr = hn::LoadU(d32, gl + tx + 2);
        const auto vu = hn::LoadU(d32, gu + tx), vd = hn::LoadU(d32, gd + tx);
        if (hn::AllTrue(d32, hn::Eq(hn::Or(hn::Or(vl, vr), hn::Or(vu, vd)), hn::Zero(d32)))) continue;
        const size_t t0 = static_cast<size_t>(ty) * static_cast<size_t>(W) + static_cast<size_t>(tx);
        auto x0 = hn::Zero(d32), x1 = hn::Set(d32, k);
        auto x2 = hn::LoadU(d32, sh.pixel_lo.data() + t0), x3 = hn::LoadU(d32, sh.pixel_hi.data() + t0);
        Philox10(d32, key[0], key[1], x0, x1, x2, x3);
        const auto code = hn::Or(hn::Or(hn::IfThenElseZero(hn::Not(hn::Gt(x0, vl)), hn::Set(d32, 1u)),
                                        hn::IfThenElseZero(hn::Not(hn::Gt(x1, vr)), hn::Set(d32, 2u))),
                                 hn::Or(hn::IfThenElseZero(hn::Not(hn::Gt(x2, vu)), hn::Set(d32, 4u)),
                                        hn::IfThenElseZero(hn::Not(hn::Gt(x3, vd)), hn::Set(d32, 8u))));
        const auto flag = hn::And(hn::Ne(code, hn::Zero(d32)), hn::FirstN(d32, static_cast<size_t>(W - tx)));
        if (hn::AllFalse(d32, flag)) continue;
        hn::StoreU(code, d32, s.code.data() + t0);
        hn::StoreU(x0, d32, bw[0] + t0);
        hn::StoreU(x1, d32, bw[1] + t0);
        hn::StoreU(x2, d32, bw[2] + t0);
        hn::StoreU(x3, d32, bw[3] + t0);
        hn::StoreU(hn::Compress(hn::Add(iota, hn::Set(d32, static_cast<uint32_t>(t0))), flag), d32, s.flagged.data() + nf);
        nf += hn::CountTrue(d32, flag);
      }
    }
    // Block 1 of the flagged pixels' streams (ids gathered into bw[8], bw[9]), then their draws one by one.
    for (size_t j = 0; j < nf; ++j) {
      bw[8][j] = sh.pixel_lo[s.flagged[j]];
      bw[9][j] = sh.pixel_hi[s.flagged[j]];
    }
    for (size_t j = 0; j < nf; j += L) {
      auto x0 = hn::Set(d32, 1u), x1 = hn::Set(d32, k), x2 = hn::LoadU(d32, bw[8] + j), x3 = hn::LoadU(d32, bw[9] + j);
      Philox10(d32, key[0], key[1], x0, x1, x2, x3);
      hn::StoreU(x0, d32, bw[4] + j);
      hn::StoreU(x1, d32, bw[5] + j);
      hn::StoreU(x2, d32, bw[6] + j);
      hn::StoreU(x3, d32, bw[7] + j);
    }
    s.extra.assign(nf * nw, 0);
    s.work.resize(2 * nw);
    if (s.r.size() < nreg) {
      s.r.resize(nreg);
      s.lr.resize(nreg);
      s.stamp.assign(nreg, s.gen);
    }
    if (++s.gen == 0) std::fill(s.stamp.begin(), s.stamp.end(), s.gen++);
    for (size_t j = 0; j < nf; ++j) {
      const uint32_t t = s.flagged[j];
      const int ty = static_cast<int>(t / static_cast<uint32_t>(W)), tx = static_cast<int>(t % static_cast<uint32_t>(W));
      unsigned dirs = sh.row_dirs[static_cast<size_t>(ty)];
      if (tx == 0 && sh.left_edge) dirs &= ~1u;
      if (tx == W - 1 && sh.right_edge) dirs &= ~2u;
      const CrosstalkLaw& law = sh.region_row_law[static_cast<size_t>(sh.tile_y + ty)];
      if (law.single_avalanche && (law.xt != s.b_xt || sh.frames != s.b_frames)) {
        s.b_xt = law.xt;
        s.b_frames = sh.frames;
        s.b_lr = std::log1p(-law.xt);
        s.b_S.resize(sh.frames + 1);
        s.b_P0.resize(sh.frames + 1);
        for (uint32_t c = 0; c <= sh.frames; ++c) crosstalk_no_hit(c, s.b_lr, s.b_S[c], s.b_P0[c]);
      }
      dirs &= s.code[t];
      const uint32_t w[4] = {bw[0][t], bw[1][t], bw[2][t], bw[3][t]};
      const uint32_t b1[4] = {bw[4][j], bw[5][j], bw[6][j], bw[7][j]};
      XtReader rd(key, k, bw[8][j], bw[9][j], b1);
      const size_t gi = static_cast<size_t>(ty + 1) * GW + static_cast<size_t>(tx + 1);
      counts[t] = static_cast<uint16_t>(counts[t] + CrosstalkPixel(law, dirs, region_index(tx, ty), RW, gi, GW, w, rd,
                                                                    prob, own, nw, s, s.extra.data() + j * nw));
    }
    // Only now (every pixel's draws saw its neighbours' own avalanches): the hits into own.
    for (size_t j = 0; j < nf; ++j) {
      const uint32_t t = s.flagged[j];
      uint64_t* mine = own + region_index(static_cast<int>(t % static_cast<uint32_t>(W)), static_cast<int>(t / static_cast<uint32_t>(W))) * nw;
      for (size_t q = 0; q < nw; ++q) mine[q] |= s.extra[j * nw + q];
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
  // the kernel loads 16 ids at a time
  const size_t n = static_cast<size_t>(width) * static_cast<size_t>(height);
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
