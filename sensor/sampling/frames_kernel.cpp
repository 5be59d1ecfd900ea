// Compiled once per target by Highway's foreach_target; the code between HWY_BEFORE_NAMESPACE and
// HWY_AFTER_NAMESPACE carries that target's attributes: ARS-7 runs on 16 counters in its widest vectors
// (up to four 128-bit blocks per vector), and the byte comparisons use them too.
//
// AVX3_DL (AVX-512 with VAES: four AES rounds per instruction) is compiled too (HWY_WANT_AVX3_DL, set for
// the whole sensor library in sensor/CMakeLists.txt): on plain AVX3 each block takes its rounds as 128-bit
// AESENC (ArsRoundsN, sensor/sampling/ars-inl.h).
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "sensor/sampling/frames_kernel.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cstring>
#include <vector>

#include "sensor/sampling/frames_kernel.h"
#include "sensor/sampling/ars-inl.h"
#include "sensor/sampling/compress-inl.h"
#include "sensor/sampling/philox-inl.h"
#include "sensor/sampling/threshold-inl.h"
#include "sensor/sampling/sampling.h"

HWY_BEFORE_NAMESPACE();
namespace spadgen::sensor {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

// ARS-7 of 16 consecutive counters, structure of arrays: out holds word 0 of the 16 blocks, then word 1,
// word 2, word 3 (little endian), exactly as ars7 computes each block.
HWY_INLINE void Ars16(const ArsKeys& keys, const uint32_t ctr[4], uint32_t first, uint32_t* HWY_RESTRICT out) {
  const hn::CappedTag<uint32_t, 16> d;
  const size_t L = hn::Lanes(d);
  // Iota of a constant (a constant vector): Highway 1.0's Iota of a variable stores the lanes one by one and
  // reloads them as a vector, a stalled store forwarding (18 % of the sampler on AVX2 without VAES)
  const auto iota = hn::Iota(d, 0u);
  for (size_t g = 0; g < 16; g += L) {
    auto x0 = hn::Add(iota, hn::Set(d, first + static_cast<uint32_t>(g)));
    auto x1 = hn::Set(d, ctr[1]), x2 = hn::Set(d, ctr[2]), x3 = hn::Set(d, ctr[3]);
    Ars7Words(d, keys, x0, x1, x2, x3);
    hn::StoreU(x0, d, out + g);
    hn::StoreU(x1, d, out + 16 + g);
    hn::StoreU(x2, d, out + 32 + g);
    hn::StoreU(x3, d, out + 48 + g);
  }
}

// The bit of one frame given its top byte; refines a tie with the block `refine_block`.
HWY_INLINE bool dense_bit_from(const Rng& stream, const ArsKeys& keys, uint8_t top, uint64_t T,
                               uint32_t refine_block) {
  const auto tb = static_cast<uint8_t>(T >> 56);
  if (top != tb) return top < tb;
  const auto b = ars_block(stream, keys, refine_block);
  const uint64_t u = ((uint64_t{b[0]} << 32) | b[1]) & ((uint64_t{1} << 56) - 1);
  return u < (T & ((uint64_t{1} << 56) - 1));
}

// ties == nullptr: a tie is settled at once with a scalar ARS block. Otherwise its frame is appended to
// *ties and its bit left 0 (the caller settles many ties with one vectorised ARS).
HWY_INLINE void DenseBitsImpl(const Rng& stream, uint32_t n, uint64_t T, uint64_t* HWY_RESTRICT words,
                              std::vector<uint32_t>* ties) {
  const hn::ScalableTag<uint8_t> d8;
  const size_t L = hn::Lanes(d8);
  constexpr size_t kMaxEqBytes = (hn::MaxLanes(d8) + 63) / 64 * 8;
  const auto tb = hn::Set(d8, static_cast<uint8_t>(T >> 56));
  const uint64_t t_rest = T & ((uint64_t{1} << 56) - 1);
  const uint32_t chunks = (n + 255) / 256;
  const uint32_t refine_base = chunks * 16;
  const ArsKeys keys = ars_keys_of(stream);
  const auto& ctr = stream.counter();
  const uint32_t c[4] = {ctr.v[0], ctr.v[1], ctr.v[2], ctr.v[3]};
  alignas(64) uint32_t buf32[64];
  alignas(64) uint8_t mask[32 + 64];  // 256 bits, plus room for the last vector's store
  auto* dst = reinterpret_cast<uint8_t*>(words);
  const size_t total_bytes = (static_cast<size_t>(n) + 63) / 64 * 8;
  for (uint32_t ch = 0; ch < chunks; ++ch) {
    Ars16(keys, c, 16 * ch, buf32);
    const auto* bytes = reinterpret_cast<const uint8_t*>(buf32);
    if (L < 8) {  // a target narrower than one mask byte: plain comparisons
      std::memset(mask, 0, 32);
      for (size_t i = 0; i < 256; ++i)
        if (dense_bit_from(stream, keys, bytes[i], T, refine_base + ch * 256 + static_cast<uint32_t>(i)))
          mask[i / 8] = static_cast<uint8_t>(mask[i / 8] | (1u << (i % 8)));
      const size_t begin = static_cast<size_t>(ch) * 32;
      std::memcpy(dst + begin, mask, std::min<size_t>(32, total_bytes - begin));
      continue;
    }
    for (size_t off = 0; off < 256; off += L) {
      const auto v = hn::LoadU(d8, bytes + off);
      hn::StoreMaskBits(d8, hn::Lt(v, tb), mask + off / 8);
      const auto eq = hn::Eq(v, tb);
      if (HWY_UNLIKELY(!hn::AllFalse(d8, eq))) {
        // visit the tied lanes only: the mask bits, 64 lanes per word
        alignas(8) uint8_t eq_bits[kMaxEqBytes] = {};
        hn::StoreMaskBits(d8, eq, eq_bits);
        for (size_t wb = 0; wb < (L + 63) / 64; ++wb) {
          uint64_t m;
          std::memcpy(&m, eq_bits + 8 * wb, 8);
          for (; m != 0; m &= m - 1) {
            const size_t i = 64 * wb + static_cast<size_t>(std::countr_zero(m));
            const uint32_t f = ch * 256 + static_cast<uint32_t>(off + i);
            if (f >= n) continue;
            if (ties != nullptr) {
              ties->push_back(f);
              continue;
            }
            const auto b = ars_block(stream, keys, refine_base + f);
            const uint64_t u = ((uint64_t{b[0]} << 32) | b[1]) & ((uint64_t{1} << 56) - 1);
            if (u < t_rest) mask[(off + i) / 8] = static_cast<uint8_t>(mask[(off + i) / 8] | (1u << ((off + i) % 8)));
          }
        }
      }
    }
    const size_t begin = static_cast<size_t>(ch) * 32;
    std::memcpy(dst + begin, mask, std::min<size_t>(32, total_bytes - begin));
  }
  if (n % 64 != 0) words[(n - 1) / 64] &= (uint64_t{1} << (n % 64)) - 1;
}

void DenseBits(const Rng& stream, uint32_t n, uint64_t T, uint64_t* HWY_RESTRICT words) {
  DenseBitsImpl(stream, n, T, words, nullptr);
}


// Top-byte ties of DenseBitsBatch waiting to be settled: (slot, frame) pairs, each one 64-bit word (slot in
// the low half, frame in the high: one store per tie). A chunk appends at most 256, so the buffer is settled
// whenever it holds more than kCap.
struct TieBuffer {
  static constexpr size_t kCap = 512;
  uint64_t tie[kCap + 256 + 16];  // + 16: SettleTies pads the last vector
  size_t count = 0;
  static uint64_t pair(uint32_t slot, uint32_t frame) { return (uint64_t{frame} << 32) | slot; }
  uint32_t slot(size_t i) const { return static_cast<uint32_t>(tie[i]); }
  uint32_t frame(size_t i) const { return static_cast<uint32_t>(tie[i] >> 32); }
};

// Appends the ties of one output word (bit i of m: frame f0 + i is tied). About one word in five has one and
// few have more, so the first is written without a branch (a tie-dependent branch mispredicts about once per
// dense pixel; countr_zero(0) = 64 is written but not counted) and the others in a loop.
HWY_INLINE void AppendTies(TieBuffer& tb, uint32_t slot, uint32_t f0, uint64_t m) {
  size_t c = tb.count;
  tb.tie[c] = TieBuffer::pair(slot, f0 + static_cast<uint32_t>(std::countr_zero(m)));
  c += m != 0;
  m &= m - 1;
  for (; HWY_UNLIKELY(m != 0); m &= m - 1) tb.tie[c++] = TieBuffer::pair(slot, f0 + static_cast<uint32_t>(std::countr_zero(m)));
  tb.count = c;
}

// Settles the buffered ties, 16 per vectorised ARS-7: tie (slot s, frame f) takes the first 56 bits (word 0
// high, word 1 low) of ARS block refine_base + f of stream s, as dense_bits does, and its bit (left as the top
// byte's comparison gave it: 0, or 1 when inverted) is toggled when they are below T[s] mod 2^56, i.e. when
// U < T.
HWY_INLINE void SettleTies(const ArsKeys& keys, uint32_t c1, const uint64_t* HWY_RESTRICT pixels,
                           const uint64_t* HWY_RESTRICT T, uint32_t refine_base,
                           size_t nw, uint64_t* HWY_RESTRICT words, TieBuffer& tb) {
  const hn::CappedTag<uint32_t, 16> d;
  const size_t L = hn::Lanes(d);
  constexpr uint64_t kLow56 = (uint64_t{1} << 56) - 1;
  alignas(64) uint32_t a0[16], a2[16], a3[16], o0[16], o1[16];
#if HWY_TARGET != HWY_SCALAR && HWY_MAX_BYTES >= 64
  if (L == 16 && tb.count > 0) {
    // AVX-512: counters by vector loads and gathers (a slot's pixel id as two u32), the comparison with
    // T mod 2^56 on 64-bit lanes with T gathered, only the toggles in scalars; the last vector is padded
    // with copies of tie 0 (computed, not applied).
    const hn::RebindToSigned<decltype(d)> di;
    const hn::Half<decltype(d)> dh;
    const hn::Repartition<uint64_t, decltype(d)> d64;
    const hn::Repartition<int64_t, decltype(d)> di64;
    const hn::Half<decltype(di)> dih;
    const auto* px32 = reinterpret_cast<const uint32_t*>(pixels);  // little endian: low word first
    const auto low56 = hn::Set(d64, kLow56);
    for (size_t j = tb.count; j < tb.count + 16; ++j) tb.tie[j] = tb.tie[0];
    for (size_t t = 0; t < tb.count; t += 16) {
      hn::Vec<decltype(d)> sl, fr;
      hn::LoadInterleaved2(d, reinterpret_cast<const uint32_t*>(tb.tie + t), sl, fr);  // (little endian)
      const auto i2 = hn::BitCast(di, hn::Add(sl, sl));
      auto x0 = hn::Add(fr, hn::Set(d, refine_base)), x1 = hn::Set(d, c1);
      auto x2 = hn::GatherIndex(d, px32, i2), x3 = hn::GatherIndex(d, px32 + 1, i2);
      Ars7Words(d, keys, x0, x1, x2, x3);
      uint32_t below = 0;
      for (int h = 0; h < 2; ++h) {
        const auto w0 = hn::PromoteTo(d64, h == 0 ? hn::LowerHalf(dh, x0) : hn::UpperHalf(dh, x0));
        const auto w1 = hn::PromoteTo(d64, h == 0 ? hn::LowerHalf(dh, x1) : hn::UpperHalf(dh, x1));
        const auto si = hn::PromoteTo(di64, hn::BitCast(dih, h == 0 ? hn::LowerHalf(dh, sl) : hn::UpperHalf(dh, sl)));
        const auto u = hn::And(hn::Or(hn::ShiftLeft<32>(w0), w1), low56);
        const auto tr = hn::And(hn::GatherIndex(d64, T, si), low56);
        uint8_t mb[8] = {};
        hn::StoreMaskBits(d64, hn::Lt(u, tr), mb);
        below |= uint32_t{mb[0]} << (8 * h);
      }
      const size_t c = std::min<size_t>(16, tb.count - t);
      for (size_t j = 0; j < c; ++j) {
        const uint32_t s = tb.slot(t + j), f = tb.frame(t + j);
        words[s * nw + f / 64] ^= static_cast<uint64_t>((below >> j) & 1u) << (f % 64);
      }
    }
    tb.count = 0;
    return;
  }
#endif
  for (size_t t = 0; t < tb.count; t += L) {
    const size_t c = std::min(L, tb.count - t);
    for (size_t j = 0; j < L; ++j) {  // lanes beyond the last tie repeat it
      const size_t e = t + std::min(j, c - 1);
      const uint32_t s = tb.slot(e);
      a0[j] = refine_base + tb.frame(e);
      a2[j] = static_cast<uint32_t>(pixels[s]);
      a3[j] = static_cast<uint32_t>(pixels[s] >> 32);
    }
    auto x0 = hn::Load(d, a0), x1 = hn::Set(d, c1), x2 = hn::Load(d, a2), x3 = hn::Load(d, a3);
    Ars7Words(d, keys, x0, x1, x2, x3);
    hn::Store(x0, d, o0);
    hn::Store(x1, d, o1);
    for (size_t j = 0; j < c; ++j) {
      const uint32_t s = tb.slot(t + j), f = tb.frame(t + j);
      const uint64_t u = ((uint64_t{o0[j]} << 32) | o1[j]) & kLow56;
      words[s * nw + f / 64] ^= static_cast<uint64_t>(u < (T[s] & kLow56)) << (f % 64);
    }
  }
  tb.count = 0;
}

#if HWY_ARCH_X86 && HWY_TARGET == HWY_AVX2
// DenseBitsBatch on AVX2 processors that also have VAES (AMD Zen 3, Intel Alder Lake and later client
// chips): one vaesenc is one AES round on two blocks, where the AVX2 target runs two 128-bit AESENC (each
// block's rounds in an xmm register, ArsRoundsN). Compiled for the AVX2 target plus VAES,
// called only when the processor has it. Per pixel and chunk, the 16 blocks in eight vectors in registers:
// vector 4 g + j holds block 16 ch + 8 g + j + 4 l in its 128-bit part l; a 4 x 4 transpose inside the
// parts turns vectors 4 g .. 4 g + 3 into words 0..3 of blocks 8 g .. 8 g + 7, i.e. the bytes of frames
// 256 ch + 64 i + 32 g .. + 31 for word i, compared in registers (byte order as DenseBitsImpl's).
SPADGEN_AVX2_VAES __attribute__((noinline)) void DenseBitsBatchVaes(
    const ArsKeys& keys, uint32_t c1, const uint64_t* HWY_RESTRICT pixels, const uint64_t* HWY_RESTRICT T,
    const uint64_t* HWY_RESTRICT flips, const uint64_t* HWY_RESTRICT slots, size_t count, uint32_t n,
    uint64_t* HWY_RESTRICT words) {
  const uint32_t chunks = (n + 255) / 256;
  const uint32_t refine_base = chunks * 16;
  const size_t nw = (static_cast<size_t>(n) + 63) / 64;
  const uint64_t tail = n % 64 != 0 ? (uint64_t{1} << (n % 64)) - 1 : ~uint64_t{0};
  TieBuffer tb;
  __m256i rk[kArsRounds + 1];
  ArsKeys256(keys, rk);
  // (b, 0, 0, 0) in part l for b = 4 l: the block indices of vector 0 of a chunk's group 0
  const __m256i base_idx = _mm256_setr_epi32(0, 0, 0, 0, 4, 0, 0, 0);
  const __m256i sign = _mm256_set1_epi8(static_cast<char>(0x80));
  for (size_t j = 0; j < count; ++j) {
    const auto slot = static_cast<uint32_t>(slots[j]);
    const uint64_t px = pixels[slot];
    // (0, c1, pixel low, pixel high) XOR k_0 in both parts
    const __m256i ck = _mm256_xor_si256(
        _mm256_setr_epi32(0, static_cast<int>(c1), static_cast<int>(static_cast<uint32_t>(px)),
                          static_cast<int>(static_cast<uint32_t>(px >> 32)), 0, static_cast<int>(c1),
                          static_cast<int>(static_cast<uint32_t>(px)), static_cast<int>(static_cast<uint32_t>(px >> 32))),
        rk[0]);
    const auto tbyte = static_cast<char>(T[slot] >> 56);
    const __m256i tb8 = _mm256_set1_epi8(tbyte);
    const __m256i tbx = _mm256_xor_si256(tb8, sign);
    const uint64_t flip = flips[slot];
    uint64_t* w = words + static_cast<size_t>(slot) * nw;
    for (uint32_t ch = 0; ch < chunks; ++ch) {
      __m256i x[8];
#pragma GCC unroll 8
      for (int v = 0; v < 8; ++v)
        x[v] = _mm256_xor_si256(ck, _mm256_add_epi32(base_idx, _mm256_setr_epi32(static_cast<int>(16 * ch + 8 * (v / 4) + v % 4), 0, 0, 0,
                                                                                  static_cast<int>(16 * ch + 8 * (v / 4) + v % 4), 0, 0, 0)));
      ArsRounds256<8>(rk, x);
      Transpose4x4Parts(x);
      Transpose4x4Parts(x + 4);
      const size_t left = nw - 4 * static_cast<size_t>(ch);  // words of this chunk inside the pixel
      const size_t words_here = std::min<size_t>(4, left);
#pragma GCC unroll 4
      for (size_t i = 0; i < 4; ++i) {
        if (i >= words_here) break;
        const auto lo_lt = static_cast<uint32_t>(_mm256_movemask_epi8(_mm256_cmpgt_epi8(tbx, _mm256_xor_si256(x[i], sign))));
        const auto hi_lt = static_cast<uint32_t>(_mm256_movemask_epi8(_mm256_cmpgt_epi8(tbx, _mm256_xor_si256(x[4 + i], sign))));
        const auto lo_eq = static_cast<uint32_t>(_mm256_movemask_epi8(_mm256_cmpeq_epi8(x[i], tb8)));
        const auto hi_eq = static_cast<uint32_t>(_mm256_movemask_epi8(_mm256_cmpeq_epi8(x[4 + i], tb8)));
        const uint64_t bits = (uint64_t{hi_lt} << 32) | lo_lt;
        const uint64_t m = (uint64_t{hi_eq} << 32) | lo_eq;
        w[4 * ch + i] = bits ^ flip;
        AppendTies(tb, slot, 256 * ch + 64 * static_cast<uint32_t>(i), i + 1 == left ? m & tail : m);
      }
      if (HWY_UNLIKELY(tb.count > TieBuffer::kCap)) SettleTies(keys, c1, pixels, T, refine_base, nw, words, tb);
    }
    w[nw - 1] &= tail;
  }
  SettleTies(keys, c1, pixels, T, refine_base, nw, words, tb);
}
#endif

// Many dense pixels of one key in one call (from frame_bits_group): no per-pixel dispatch, Rng set-up or
// zero fill, the inversion folded into the store, the ties collected without branches and settled together.
HWY_INLINE void DenseBitsBatch(const ArsKeys& keys, uint32_t c1, const uint64_t* HWY_RESTRICT pixels,
                               const uint64_t* HWY_RESTRICT T, const uint64_t* HWY_RESTRICT flips,
                               const uint64_t* HWY_RESTRICT slots, size_t count, uint32_t n,
                               uint64_t* HWY_RESTRICT words) {
#if HWY_ARCH_X86 && HWY_TARGET == HWY_AVX2
  if (avx2_vaes_flag().load(std::memory_order_relaxed)) {
    DenseBitsBatchVaes(keys, c1, pixels, T, flips, slots, count, n, words);
    return;
  }
#endif
  const hn::ScalableTag<uint8_t> d8;
  const size_t L = hn::Lanes(d8);
  const uint32_t chunks = (n + 255) / 256;
  const uint32_t refine_base = chunks * 16;
  const size_t nw = (static_cast<size_t>(n) + 63) / 64;
  const uint64_t tail = n % 64 != 0 ? (uint64_t{1} << (n % 64)) - 1 : ~uint64_t{0};
  TieBuffer tb;
  // Vectors of 16 u32 (AVX-512): ARS word v of a chunk's 16 blocks is one vector, i.e. the chunk's
  // bytes 64 v .. 64 v + 63 (frames 256 ch + 64 v + i), compared in registers and stored as whole words
  // (no round trip through memory, whose narrow mask stores and wide reload stall store forwarding).
#if HWY_TARGET != HWY_SCALAR && HWY_MAX_BYTES >= 64
  const hn::CappedTag<uint32_t, 16> d32;
  const hn::Repartition<uint8_t, decltype(d32)> d8w;
  if (hn::Lanes(d32) == 16 && hn::Lanes(d8w) == 64) {
    // ARS on four blocks per vector: round keys in registers; words 1..3 of the counters XOR k_0 per pixel.
    const ArsKeysV<decltype(d32)> kv(d32, keys);
    alignas(16) static constexpr uint32_t kWord0[4] = {~0u, 0u, 0u, 0u};
    const auto word0 = hn::LoadDup128(d32, kWord0);
    const hn::Repartition<uint64_t, decltype(d32)> d64c;
    using V32 = hn::Vec<decltype(d32)>;
    // One output word (frames f0 .. f0 + 63) from one ARS word vector: below the threshold's top byte
    // (inverted by flip), and the ties (masked by keep) appended.
    const auto word = [&tb, d8w](V32 x, hn::Vec<decltype(d8w)> tb8, uint64_t flip, uint64_t keep, uint64_t* out,
                                 uint32_t slot, uint32_t f0) HWY_ATTR __attribute__((always_inline)) {
      const auto bytes = hn::BitCast(d8w, x);
      alignas(8) uint8_t lt[8], eqb[8];
      hn::StoreMaskBits(d8w, hn::Lt(bytes, tb8), lt);
      hn::StoreMaskBits(d8w, hn::Eq(bytes, tb8), eqb);
      uint64_t bits, m;
      std::memcpy(&bits, lt, 8);
      std::memcpy(&m, eqb, 8);
      *out = bits ^ flip;
      AppendTies(tb, slot, f0, m & keep);
    };
    // One pixel's words of chunk ch from the chunk's four ARS word vectors (by value: the chains stay
    // in registers).
    const auto emit = [&](uint32_t slot, uint32_t ch, V32 x0, V32 x1, V32 x2, V32 x3) HWY_ATTR __attribute__((always_inline)) {
      const auto tb8 = hn::Set(d8w, static_cast<uint8_t>(T[slot] >> 56));
      uint64_t* w = words + static_cast<size_t>(slot) * nw + 4 * static_cast<size_t>(ch);
      const uint64_t flip = flips[slot];
      const uint32_t f0 = 256 * ch;
      const size_t left = nw - 4 * static_cast<size_t>(ch);  // words of this chunk still inside the pixel
      if (HWY_LIKELY(left >= 4)) {  // whole chunk; the tail mask only on the pixel's last word
        word(x0, tb8, flip, ~uint64_t{0}, w, slot, f0);
        word(x1, tb8, flip, ~uint64_t{0}, w + 1, slot, f0 + 64);
        word(x2, tb8, flip, ~uint64_t{0}, w + 2, slot, f0 + 128);
        word(x3, tb8, flip, left == 4 ? tail : ~uint64_t{0}, w + 3, slot, f0 + 192);
      } else {
        word(x0, tb8, flip, left == 1 ? tail : ~uint64_t{0}, w, slot, f0);
        if (left > 1) word(x1, tb8, flip, left == 2 ? tail : ~uint64_t{0}, w + 1, slot, f0 + 64);
        if (left > 2) word(x2, tb8, flip, tail, w + 2, slot, f0 + 128);
      }
      if (HWY_UNLIKELY(tb.count > TieBuffer::kCap)) SettleTies(keys, c1, pixels, T, refine_base, nw, words, tb);
    };
    // Pixels in fours: their ARS chains interleaved (the last pixel is repeated to fill the four); four
    // vectors of blocks per pixel, v_j holding blocks 16 ch + j + 4 l in its 128-bit parts l, so that one
    // 4 x 4 transpose inside the parts gives the word vectors (lane i: block 16 ch + i).
    constexpr size_t K = 2;
    // Iota once: Highway 1.0's Iota stores the lanes one by one and reloads them (a stalled store forwarding)
    const auto iota32 = hn::Iota(d32, 0u);
    for (size_t j = 0; j < count; j += K) {
      uint32_t sl[K];
      V32 ck[K];  // (0, c1, c2, c3) XOR k_0 in every part, from two 64-bit broadcasts (not through memory)
      for (size_t s = 0; s < K; ++s) {
        sl[s] = static_cast<uint32_t>(slots[std::min(j + s, count - 1)]);
        const auto c = hn::OddEven(hn::Set(d64c, pixels[sl[s]]), hn::Set(d64c, uint64_t{c1} << 32));
        ck[s] = hn::Xor(hn::BitCast(d32, c), kv.k[0]);
      }
      const size_t live = std::min(K, count - j);
      for (uint32_t ch = 0; ch < chunks; ++ch) {
        V32 x[K][4];
#pragma GCC unroll 4
        for (size_t v = 0; v < 4; ++v) {
          const auto idx = hn::And(hn::Add(iota32, hn::Set(d32, 16 * ch + static_cast<uint32_t>(v))), word0);
#pragma GCC unroll 4
          for (size_t s = 0; s < K; ++s) x[s][v] = hn::Xor(ck[s], idx);
        }
        // fully unrolled (the chains must stay in registers)
        ArsRoundsN<K * 4>(d32, kv, &x[0][0]);
#pragma GCC unroll 4
        for (size_t s = 0; s < K; ++s) Transpose4x4(d32, x[s][0], x[s][1], x[s][2], x[s][3]);
        // constant indices into x only (a runtime index would keep the chains in memory)
        emit(sl[0], ch, x[0][0], x[0][1], x[0][2], x[0][3]);
        if (live > 1) emit(sl[1], ch, x[1][0], x[1][1], x[1][2], x[1][3]);
        if constexpr (K > 2) {
          if (live > 2) emit(sl[2], ch, x[2][0], x[2][1], x[2][2], x[2][3]);
          if (live > 3) emit(sl[3], ch, x[3][0], x[3][1], x[3][2], x[3][3]);
        }
      }
      for (size_t s = 0; s < live; ++s) words[static_cast<size_t>(sl[s]) * nw + nw - 1] &= tail;
    }
    SettleTies(keys, c1, pixels, T, refine_base, nw, words, tb);
    return;
  }
#endif
  alignas(64) uint32_t buf32[64];
  alignas(8) uint8_t lt[32 + 8], eq[32 + 8];  // a chunk's 256 comparisons each, as bits
  for (size_t j = 0; j < count; ++j) {
    const auto slot = static_cast<uint32_t>(slots[j]);
    const uint32_t c[4] = {0, c1, static_cast<uint32_t>(pixels[slot]), static_cast<uint32_t>(pixels[slot] >> 32)};
    const auto tbs = static_cast<uint8_t>(T[slot] >> 56);
    const auto tbv = hn::Set(d8, tbs);
    uint64_t* w = words + static_cast<size_t>(slot) * nw;
    const uint64_t flip = flips[slot];
    for (uint32_t ch = 0; ch < chunks; ++ch) {
      Ars16(keys, c, 16 * ch, buf32);
      const auto* bytes = reinterpret_cast<const uint8_t*>(buf32);
      if (L < 8) {  // a target narrower than one mask byte: plain comparisons
        std::memset(lt, 0, 32);
        std::memset(eq, 0, 32);
        for (uint32_t i = 0; i < 256; ++i) {
          lt[i / 8] = static_cast<uint8_t>(lt[i / 8] | (bytes[i] < tbs) << (i % 8));
          eq[i / 8] = static_cast<uint8_t>(eq[i / 8] | (bytes[i] == tbs) << (i % 8));
        }
      } else {
        for (size_t off = 0; off < 256; off += L) {
          const auto v = hn::LoadU(d8, bytes + off);
          hn::StoreMaskBits(d8, hn::Lt(v, tbv), lt + off / 8);
          hn::StoreMaskBits(d8, hn::Eq(v, tbv), eq + off / 8);
        }
      }
      for (uint32_t v = 0; v < 4; ++v) {
        const size_t wi = static_cast<size_t>(ch) * 4 + v;
        if (wi >= nw) break;
        uint64_t bits, m;
        std::memcpy(&bits, lt + 8 * v, 8);
        std::memcpy(&m, eq + 8 * v, 8);
        w[wi] = bits ^ flip;
        AppendTies(tb, slot, 64 * static_cast<uint32_t>(wi), wi + 1 == nw ? m & tail : m);
        if (HWY_UNLIKELY(tb.count > TieBuffer::kCap)) SettleTies(keys, c1, pixels, T, refine_base, nw, words, tb);
      }
    }
    w[nw - 1] &= tail;
  }
  SettleTies(keys, c1, pixels, T, refine_base, nw, words, tb);
}

// Philox on 64-bit lanes: each lane carries one block's 32-bit word in its low half; the high half is
// ignored (MulEven reads only the low halves; the outputs are the low halves), so the lanes line up with
// 64-bit data (doubles, thresholds). Bit-identical to Philox10 per block.
// The 64-bit products of the lanes' low halves with m.
template <class D64>
HWY_INLINE hn::Vec<D64> MulLow32(D64 d, hn::Vec<D64> a, uint32_t m) {
#if HWY_TARGET == HWY_SCALAR
  return hn::Set(d, (hn::GetLane(a) & 0xFFFFFFFFu) * m);
#else
  const hn::Repartition<uint32_t, D64> d32;
  return hn::MulEven(hn::BitCast(d32, a), hn::BitCast(d32, hn::Set(d, uint64_t{m})));
#endif
}

template <class D64>
HWY_INLINE void Philox10x64(D64 d, uint32_t ka, uint32_t kb, hn::Vec<D64>& x0, hn::Vec<D64>& x1, hn::Vec<D64>& x2,
                            hn::Vec<D64>& x3) {
  for (int round = 0; round < 10; ++round) {
    const auto p0 = MulLow32(d, x0, kPhiloxM0);  // (hi0, lo0) of x0 * M0
    const auto p1 = MulLow32(d, x2, kPhiloxM1);  // (hi1, lo1) of x2 * M1
    x0 = hn::Xor(hn::Xor(hn::ShiftRight<32>(p1), x1), hn::Set(d, uint64_t{ka}));
    x2 = hn::Xor(hn::Xor(hn::ShiftRight<32>(p0), x3), hn::Set(d, uint64_t{kb}));
    x1 = p1;
    x3 = p0;
    ka += kPhiloxW0;
    kb += kPhiloxW1;
  }
}

// One group of sample_bits_batch (see frame_bits_group), vectorised over pixels: a = min(p, q) as
// std::min gives it, the fills, the classes, the thresholds, block 0 of every stream (Philox on 64-bit
// lanes, aligned with the doubles) and the sparse pixels' first binomial test, with the lists compressed
// from masks (no branch on a pixel's class).
size_t FrameBitsGroup(const uint32_t key[2], uint32_t c1, const uint64_t* HWY_RESTRICT pixels,
                      const Prob* HWY_RESTRICT pr, size_t count, uint32_t n, double sparse_below,
                      uint64_t* HWY_RESTRICT words, uint32_t* HWY_RESTRICT slow, uint32_t* HWY_RESTRICT block0) {
  static_assert(sizeof(Prob) == 3 * sizeof(double), "Prob is read as interleaved doubles");
  const hn::ScalableTag<double> d;
  const hn::RebindToUnsigned<decltype(d)> du;
  const size_t L = hn::Lanes(d);
  constexpr size_t kMaxL = hn::MaxLanes(hn::ScalableTag<double>());
  const size_t nw = (static_cast<size_t>(n) + 63) / 64;
  const uint64_t tail = n % 64 != 0 ? (uint64_t{1} << (n % 64)) - 1 : ~uint64_t{0};
  alignas(64) uint64_t T[kFrameGroup + kMaxL], fill[kFrameGroup + kMaxL], b[4][kFrameGroup + kMaxL];
  alignas(64) uint64_t dense[kFrameGroup + kMaxL], slow_list[kFrameGroup + kMaxL];
  size_t nd = 0, ns = 0;
  const auto vn = hn::Set(d, static_cast<double>(n));
  const auto below = hn::Set(d, sparse_below);
  const auto low32 = hn::Set(du, uint64_t{0xFFFFFFFFu});
  const auto iota64 = hn::Iota(du, uint64_t{0});  // once: Highway 1.0's Iota goes through memory
  size_t filled = 0;  // pixels whose words were filled in the loop
  for (size_t i = 0; i < count; i += L) {
    hn::Vec<decltype(d)> vp, vq, vl;
    hn::Vec<decltype(du)> pix;
    if (i + L <= count) {
      hn::LoadInterleaved3(d, &pr[i].p, vp, vq, vl);
      pix = hn::LoadU(du, pixels + i);
    } else {  // the tail through padded copies: p = 0, q = 1 (a = 0: no list) beyond count
      alignas(64) double tp[3 * kMaxL];
      alignas(64) uint64_t tx[kMaxL] = {};
      for (size_t j = 0; j < L; ++j) {
        const Prob q = i + j < count ? pr[i + j] : Prob{0.0, 1.0, 0.0};
        tp[3 * j] = q.p;
        tp[3 * j + 1] = q.q;
        tp[3 * j + 2] = q.log_q;
        tx[j] = i + j < count ? pixels[i + j] : 0;
      }
      hn::LoadInterleaved3(d, tp, vp, vq, vl);
      pix = hn::Load(du, tx);
    }
    const auto a = hn::IfThenElse(hn::Lt(vq, vp), vq, vp);  // std::min(p, q)
    const auto inv = hn::Gt(vp, vq);
    const auto is_dense = hn::Gt(a, below);
    const auto is_sparse = hn::AndNot(is_dense, hn::Gt(a, hn::Zero(d)));
    hn::Store(ProbabilityThreshold(d, a), du, T + i);
    const auto fill_v = hn::BitCast(du, hn::VecFromMask(d, inv));
    hn::Store(fill_v, du, fill + i);
    if (nw == 4 && i + L <= count) {  // every pixel's words all equal first (see below), four at a time
      hn::StoreInterleaved4(fill_v, fill_v, fill_v, hn::And(fill_v, hn::Set(du, tail)), du, words + 4 * i);
      filled = i + L;
    }
    // block 0 of the streams (counter (0, c1, pixel low, pixel high)) for the sparse pixels' first binomial
    // test (BinomialSampler::small_side's, on U = (word 0, word 1)): no rare outcome when n a < 1 and
    // U >= floor(n a 2^64). Not computed for a vector without a sparse pixel.
    auto go_slow = hn::RebindMask(d, hn::Zero(du) != hn::Zero(du));
    if (!hn::AllFalse(d, is_sparse)) {
      auto x0 = hn::Zero(du), x1 = hn::Set(du, uint64_t{c1}), x2 = pix, x3 = hn::ShiftRight<32>(pix);
      Philox10x64(du, key[0], key[1], x0, x1, x2, x3);
      hn::Store(x0, du, b[0] + i);
      hn::Store(x1, du, b[1] + i);
      hn::Store(x2, du, b[2] + i);
      hn::Store(x3, du, b[3] + i);
      const auto U = hn::Or(hn::ShiftLeft<32>(x0), hn::And(x1, low32));
      const auto mean = hn::Mul(vn, a);
      const auto none = hn::And(hn::Lt(mean, hn::Set(d, 1.0)), hn::RebindMask(d, hn::Not(hn::Lt(U, ProbabilityThreshold(d, mean)))));
      go_slow = hn::AndNot(none, is_sparse);
    }
    const auto idx = hn::Add(iota64, hn::Set(du, uint64_t{i}));
    // compressed in registers and stored whole (a compressing store to memory is slow on AVX-512)
    hn::StoreU(CompressLanes(du, idx, hn::RebindMask(du, is_dense)), du, dense + nd);
    nd += hn::CountTrue(du, hn::RebindMask(du, is_dense));
    hn::StoreU(CompressLanes(du, idx, hn::RebindMask(du, go_slow)), du, slow_list + ns);
    ns += hn::CountTrue(du, hn::RebindMask(du, go_slow));
  }
  // every pixel's words all equal first (final for a = 0 and for sparse pixels without a rare outcome)
  for (size_t i = filled; i < count; ++i) {
    uint64_t* w = words + i * nw;
    for (size_t j = 0; j + 1 < nw; ++j) w[j] = fill[i];
    w[nw - 1] = fill[i] & tail;
  }
  if (nd > 0) DenseBitsBatch(ars_round_keys(ars_key(key)), c1, pixels, T, fill, dense, nd, n, words);
  for (size_t j = 0; j < ns; ++j) {
    const size_t i = slow_list[j];
    slow[j] = static_cast<uint32_t>(i);
    for (size_t v = 0; v < 4; ++v) block0[4 * j + v] = static_cast<uint32_t>(b[v][i]);
  }
  return ns;
}

void Ars7Blocks(const ArsKeys& keys, const uint32_t* HWY_RESTRICT ctr, size_t count, uint32_t* HWY_RESTRICT out) {
  const hn::CappedTag<uint32_t, 16> d;
  const size_t L = hn::Lanes(d);
  alignas(64) uint32_t x[4][16];
  for (size_t i = 0; i < count; i += L) {
    const size_t c = std::min(L, count - i);
    for (size_t j = 0; j < L; ++j)
      for (size_t w = 0; w < 4; ++w) x[w][j] = ctr[4 * (i + std::min(j, c - 1)) + w];
    auto x0 = hn::Load(d, x[0]), x1 = hn::Load(d, x[1]), x2 = hn::Load(d, x[2]), x3 = hn::Load(d, x[3]);
    Ars7Words(d, keys, x0, x1, x2, x3);
    hn::Store(x0, d, x[0]);
    hn::Store(x1, d, x[1]);
    hn::Store(x2, d, x[2]);
    hn::Store(x3, d, x[3]);
    for (size_t j = 0; j < c; ++j)
      for (size_t w = 0; w < 4; ++w) out[4 * (i + j) + w] = x[w][j];
  }
}

const char* TargetName() { return hwy::TargetName(HWY_TARGET); }

}  // namespace HWY_NAMESPACE
}  // namespace spadgen::sensor
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace spadgen::sensor {

HWY_EXPORT(DenseBits);
HWY_EXPORT(TargetName);
HWY_EXPORT(FrameBitsGroup);
HWY_EXPORT(Ars7Blocks);

void ars7_blocks(const ArsKeys& keys, const uint32_t* ctr, size_t count, uint32_t* out) {
  HWY_DYNAMIC_DISPATCH(Ars7Blocks)(keys, ctr, count, out);
}

size_t frame_bits_group(const uint32_t key[2], uint32_t c1, const uint64_t* pixels, const Prob* pr, size_t count,
                        uint32_t n, double sparse_below, uint64_t* words, uint32_t* slow, uint32_t* block0) {
  return HWY_DYNAMIC_DISPATCH(FrameBitsGroup)(key, c1, pixels, pr, count, n, sparse_below, words, slow, block0);
}

void dense_bits(const Rng& stream, uint32_t n, uint64_t T, uint64_t* words) {
  HWY_DYNAMIC_DISPATCH(DenseBits)(stream, n, T, words);
}


const char* dense_bits_target() {
  const char* name = HWY_DYNAMIC_DISPATCH(TargetName)();
  return std::strcmp(name, "AVX2") == 0 && avx2_vaes() ? "AVX2+VAES" : name;
}

bool avx2_vaes() { return avx2_vaes_flag().load(); }

bool set_avx2_vaes(bool on) { return avx2_vaes_flag().exchange(on && cpu_has_vaes()); }

bool dense_bit_reference(const Rng& stream, uint32_t n, uint64_t T, uint32_t frame) {
  const uint32_t chunks = (n + 255) / 256;
  const uint32_t ch = frame / 256, r = frame % 256;
  const ArsKeys keys = ars_keys_of(stream);
  const auto blk = ars_block(stream, keys, 16 * ch + (r % 64) / 4);
  const auto top = static_cast<uint8_t>(blk[r / 64] >> (8 * (r % 4)));
  const auto tb = static_cast<uint8_t>(T >> 56);
  if (top != tb) return top < tb;
  const auto b = ars_block(stream, keys, chunks * 16 + frame);
  const uint64_t u = ((uint64_t{b[0]} << 32) | b[1]) & ((uint64_t{1} << 56) - 1);
  return u < (T & ((uint64_t{1} << 56) - 1));
}

}  // namespace spadgen::sensor
#endif
