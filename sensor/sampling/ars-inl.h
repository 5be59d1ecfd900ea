// ARS-7 (sensor/ars.h) on whole Highway vectors: one 128-bit block per 128-bit part of a vector (four on
// AVX-512 with VAES), with Highway's AESRound / AESLastRound (AES-NI / VAES where the target has them, a
// software round otherwise; AVX2 and AVX3 without VAES: 128-bit AESENC on each block, ArsRoundsN),
// bit-identical to the scalar ars7. Included once per target from the
// translation units that use Highway's foreach_target (the per-target include guard below).
#if defined(SPADGEN_SENSOR_ARS_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef SPADGEN_SENSOR_ARS_INL_H_
#undef SPADGEN_SENSOR_ARS_INL_H_
#else
#define SPADGEN_SENSOR_ARS_INL_H_
#endif

#include <hwy/highway.h>

#include "sensor/sampling/ars.h"

HWY_BEFORE_NAMESPACE();
namespace spadgen::sensor {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

#if HWY_TARGET != HWY_SCALAR

// The round keys, each repeated in every 128-bit part of a u32 vector.
template <class D>
struct ArsKeysV {
  hn::Vec<D> k[kArsRounds + 1];
  ArsKeysV(D d, const ArsKeys& keys) {
    for (int r = 0; r <= kArsRounds; ++r) k[r] = hn::LoadDup128(d, keys.rk[r]);
  }
};

// Rounds 1..7 of ARS-7 on n vectors x[0 .. n) in place (each counter XOR k_0, one block per 128-bit part),
// round by round across the vectors so that their chains overlap.
//
// Without VAES, Highway's AVX2 and AVX3 targets split every AESRound of a 256- or 512-bit vector into 128-bit
// AESENC, moving the parts out and back in each round (AVX3: through two levels of halves). There each block
// instead takes its seven rounds in an xmm register, its vector's parts moved out once and back once: the same
// rounds, the same bits (the frame-bit sampler x 1.6 on AVX3, x 1.4 on AVX2 with each target forced on one
// thread; bench/README.md, "Binary frames on other instruction sets").
template <size_t n, class D, class KeysD>
HWY_INLINE void ArsRoundsN(D d, const ArsKeysV<KeysD>& k, hn::Vec<D>* x) {
#if HWY_ARCH_X86 && (HWY_TARGET == HWY_AVX3 || HWY_TARGET == HWY_AVX2)
  if constexpr (sizeof(hn::Vec<D>) == 64 || sizeof(hn::Vec<D>) == 32) {
    constexpr bool wide = sizeof(hn::Vec<D>) == 64;
    constexpr size_t parts = wide ? 4 : 2;
    // the vectors in pairs (AVX2) or one by one (AVX3): four chains in flight, within the 16 registers the
    // VEX-encoded AESENC can address beside the round keys
    constexpr size_t group = wide || n % 2 != 0 ? 1 : 2;
    __m128i rk[kArsRounds + 1];
#pragma GCC unroll 8
    for (int r = 1; r <= kArsRounds; ++r) {
      if constexpr (wide) rk[r] = hn::LowerHalf(hn::LowerHalf(k.k[r])).raw;  // (GCC 12's casts warn: Highway's do not)
      else rk[r] = hn::LowerHalf(k.k[r]).raw;
    }
#pragma GCC unroll 16
    for (size_t i = 0; i < n; i += group) {
      __m128i b[group * parts];
#pragma GCC unroll 4
      for (size_t g = 0; g < group; ++g) {
        if constexpr (wide) {
          const __m512i v = x[i + g].raw;
          b[g * parts] = hn::LowerHalf(hn::LowerHalf(x[i + g])).raw;
          // (the zero-masked form with every lane kept: GCC 12 warns of the plain form's undefined source)
          b[g * parts + 1] = _mm512_maskz_extracti32x4_epi32(0xF, v, 1);
          b[g * parts + 2] = _mm512_maskz_extracti32x4_epi32(0xF, v, 2);
          b[g * parts + 3] = _mm512_maskz_extracti32x4_epi32(0xF, v, 3);
        } else {
          const __m256i v = x[i + g].raw;
          b[g * parts] = hn::LowerHalf(x[i + g]).raw;
          b[g * parts + 1] = _mm256_extracti128_si256(v, 1);
        }
      }
#pragma GCC unroll 8
      for (int r = 1; r < kArsRounds; ++r)
#pragma GCC unroll 4
        for (size_t j = 0; j < group * parts; ++j) b[j] = _mm_aesenc_si128(b[j], rk[r]);
#pragma GCC unroll 4
      for (size_t j = 0; j < group * parts; ++j) b[j] = _mm_aesenclast_si128(b[j], rk[kArsRounds]);
#pragma GCC unroll 4
      for (size_t g = 0; g < group; ++g) {
        if constexpr (wide) {
          const __m512i lo = _mm512_inserti32x4(_mm512_zextsi128_si512(b[g * parts]), b[g * parts + 1], 1);
          x[i + g].raw = _mm512_inserti32x4(_mm512_inserti32x4(lo, b[g * parts + 2], 2), b[g * parts + 3], 3);
        } else {
          x[i + g].raw = _mm256_set_m128i(b[g * parts + 1], b[g * parts]);
        }
      }
    }
    return;
  }
#endif
  const hn::Repartition<uint8_t, D> d8;
#pragma GCC unroll 8
  for (int r = 1; r < kArsRounds; ++r) {
    const auto rk = hn::BitCast(d8, k.k[r]);
#pragma GCC unroll 16
    for (size_t i = 0; i < n; ++i) x[i] = hn::BitCast(d, hn::AESRound(hn::BitCast(d8, x[i]), rk));
  }
  const auto rk_last = hn::BitCast(d8, k.k[kArsRounds]);
#pragma GCC unroll 16
  for (size_t i = 0; i < n; ++i) x[i] = hn::BitCast(d, hn::AESLastRound(hn::BitCast(d8, x[i]), rk_last));
}

// 4 x 4 transpose of u32 inside every 128-bit part: afterwards word j of part l of a_i is what word i of
// part l of a_j was. Turns four vectors of blocks (part l of a_j: one block) into four vectors of words and
// back.
template <class D>
HWY_INLINE void Transpose4x4(D d, hn::Vec<D>& a0, hn::Vec<D>& a1, hn::Vec<D>& a2, hn::Vec<D>& a3) {
  const hn::Repartition<uint64_t, D> d64;
  const auto t0 = hn::BitCast(d64, hn::InterleaveLower(d, a0, a1));
  const auto t1 = hn::BitCast(d64, hn::InterleaveUpper(d, a0, a1));
  const auto t2 = hn::BitCast(d64, hn::InterleaveLower(d, a2, a3));
  const auto t3 = hn::BitCast(d64, hn::InterleaveUpper(d, a2, a3));
  a0 = hn::BitCast(d, hn::InterleaveLower(d64, t0, t2));
  a1 = hn::BitCast(d, hn::InterleaveUpper(d64, t0, t2));
  a2 = hn::BitCast(d, hn::InterleaveLower(d64, t1, t3));
  a3 = hn::BitCast(d, hn::InterleaveUpper(d64, t1, t3));
}

#endif  // HWY_TARGET != HWY_SCALAR

#if HWY_ARCH_X86 && HWY_TARGET == HWY_AVX2
// The AVX2 target plus VAES: functions with it are called only when the processor has VAES
// (avx2_vaes_flag), and are not inlined into the AVX2 code, which may not use it.
#define SPADGEN_AVX2_VAES __attribute__((target(HWY_TARGET_STR ",vaes")))

// ARS-7's round keys in both 128-bit parts.
SPADGEN_AVX2_VAES HWY_INLINE void ArsKeys256(const ArsKeys& keys, __m256i* rk) {
  for (int r = 0; r <= kArsRounds; ++r)
    rk[r] = _mm256_broadcastsi128_si256(_mm_load_si128(reinterpret_cast<const __m128i*>(keys.rk[r])));
}

// Transpose4x4 on four 256-bit vectors: a 4 x 4 transpose of u32 inside each 128-bit part.
SPADGEN_AVX2_VAES HWY_INLINE void Transpose4x4Parts(__m256i* a) {
  const __m256i t0 = _mm256_unpacklo_epi32(a[0], a[1]), t1 = _mm256_unpackhi_epi32(a[0], a[1]);
  const __m256i t2 = _mm256_unpacklo_epi32(a[2], a[3]), t3 = _mm256_unpackhi_epi32(a[2], a[3]);
  a[0] = _mm256_unpacklo_epi64(t0, t2);
  a[1] = _mm256_unpackhi_epi64(t0, t2);
  a[2] = _mm256_unpacklo_epi64(t1, t3);
  a[3] = _mm256_unpackhi_epi64(t1, t3);
}

// Rounds 1..7 of ARS-7 on n vectors of two blocks each (x: counters XOR k_0), interleaved so that the n
// chains overlap.
template <int n>
SPADGEN_AVX2_VAES HWY_INLINE void ArsRounds256(const __m256i* rk, __m256i* x) {
#pragma GCC unroll 8
  for (int r = 1; r < kArsRounds; ++r)
#pragma GCC unroll 8
    for (int j = 0; j < n; ++j) x[j] = _mm256_aesenc_epi128(x[j], rk[r]);
#pragma GCC unroll 8
  for (int j = 0; j < n; ++j) x[j] = _mm256_aesenclast_epi128(x[j], rk[kArsRounds]);
}

// Ars7Words on eight lanes with VAES.
SPADGEN_AVX2_VAES __attribute__((noinline)) inline void Ars7WordsVaes(const ArsKeys& keys, __m256i* x) {
  __m256i rk[kArsRounds + 1];
  ArsKeys256(keys, rk);
  __m256i v[4] = {x[0], x[1], x[2], x[3]};
  Transpose4x4Parts(v);  // part l of v_j: the block of lane 4 l + j
#pragma GCC unroll 4
  for (int j = 0; j < 4; ++j) v[j] = _mm256_xor_si256(v[j], rk[0]);
  ArsRounds256<4>(rk, v);
  Transpose4x4Parts(v);
  for (int j = 0; j < 4; ++j) x[j] = v[j];
}
#endif

// ARS-7 with the counters and outputs as words, like Philox10: lane i's block has counter
// (x0[i], x1[i], x2[i], x3[i]) and afterwards x0..x3 are its output words.
template <class D>
HWY_INLINE void Ars7Words(D d, const ArsKeys& keys, hn::Vec<D>& x0, hn::Vec<D>& x1, hn::Vec<D>& x2,
                          hn::Vec<D>& x3) {
#if HWY_ARCH_X86 && HWY_TARGET == HWY_AVX2
  if constexpr (sizeof(hn::Vec<D>) == 32) {
    if (avx2_vaes_flag().load(std::memory_order_relaxed)) {
      __m256i x[4] = {x0.raw, x1.raw, x2.raw, x3.raw};
      Ars7WordsVaes(keys, x);
      x0.raw = x[0];
      x1.raw = x[1];
      x2.raw = x[2];
      x3.raw = x[3];
      return;
    }
  }
#endif
#if HWY_TARGET == HWY_SCALAR
  const Block128 o = ars7({hn::GetLane(x0), hn::GetLane(x1), hn::GetLane(x2), hn::GetLane(x3)}, keys);
  x0 = hn::Set(d, o[0]);
  x1 = hn::Set(d, o[1]);
  x2 = hn::Set(d, o[2]);
  x3 = hn::Set(d, o[3]);
#else
  const ArsKeysV<D> k(d, keys);
  Transpose4x4(d, x0, x1, x2, x3);  // part l of x_j: the block of lane 4 l + j
  hn::Vec<D> x[4] = {hn::Xor(x0, k.k[0]), hn::Xor(x1, k.k[0]), hn::Xor(x2, k.k[0]), hn::Xor(x3, k.k[0])};
  ArsRoundsN<4>(d, k, x);
  x0 = x[0], x1 = x[1], x2 = x[2], x3 = x[3];
  Transpose4x4(d, x0, x1, x2, x3);
#endif
}

}  // namespace HWY_NAMESPACE
}  // namespace spadgen::sensor
HWY_AFTER_NAMESPACE();

#endif  // per-target include guard
