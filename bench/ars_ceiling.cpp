// Compiled once per target by Highway's foreach_target, as sensor/sampling/frames_kernel.cpp is: eight
// independent vectors of counters per step (the dense kernel keeps as many in flight), each block's output
// folded into an accumulator by XOR so that nothing is stored and nothing can be left out.
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "ars_ceiling.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

#include "ars_ceiling.h"
#include "sensor/sampling/ars-inl.h"

HWY_BEFORE_NAMESPACE();
namespace spadgen::bench {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;
namespace sk = sensor::HWY_NAMESPACE;
using sensor::ArsKeys;
using sensor::Block128;
using sensor::kArsRounds;

#if HWY_ARCH_X86 && HWY_TARGET == HWY_AVX2
// The AVX2 kernel's rounds on a processor with VAES (ArsRounds256, two blocks per vector).
SPADGEN_AVX2_VAES __attribute__((noinline)) Block128 ArsXorVaes(const ArsKeys& keys, uint32_t c1, uint32_t c2,
                                                                uint32_t c3, uint32_t first, uint64_t count) {
  __m256i rk[kArsRounds + 1];
  sk::ArsKeys256(keys, rk);
  __m256i ctr[8], acc[8];
  for (int j = 0; j < 8; ++j) {
    const auto b = static_cast<int>(first + 2 * static_cast<uint32_t>(j));
    ctr[j] = _mm256_setr_epi32(b, static_cast<int>(c1), static_cast<int>(c2), static_cast<int>(c3), b + 1,
                               static_cast<int>(c1), static_cast<int>(c2), static_cast<int>(c3));
    acc[j] = _mm256_setzero_si256();
  }
  const __m256i step = _mm256_setr_epi32(16, 0, 0, 0, 16, 0, 0, 0);
  for (uint64_t i = 0; i < count; i += 16) {
    __m256i x[8];
#pragma GCC unroll 8
    for (int j = 0; j < 8; ++j) {
      x[j] = _mm256_xor_si256(ctr[j], rk[0]);
      ctr[j] = _mm256_add_epi32(ctr[j], step);
    }
    sk::ArsRounds256<8>(rk, x);
#pragma GCC unroll 8
    for (int j = 0; j < 8; ++j) acc[j] = _mm256_xor_si256(acc[j], x[j]);
  }
  for (int j = 1; j < 8; ++j) acc[0] = _mm256_xor_si256(acc[0], acc[j]);
  alignas(32) uint32_t w[8];
  _mm256_store_si256(reinterpret_cast<__m256i*>(w), acc[0]);
  return {w[0] ^ w[4], w[1] ^ w[5], w[2] ^ w[6], w[3] ^ w[7]};
}
#endif

Block128 ArsXor(const ArsKeys& keys, uint32_t c1, uint32_t c2, uint32_t c3, uint32_t first, uint64_t count) {
#if HWY_TARGET == HWY_SCALAR
  return ars7_xor_reference(keys, c1, c2, c3, first, count);
#else
#if HWY_ARCH_X86 && HWY_TARGET == HWY_AVX2
  if (sensor::avx2_vaes_flag().load(std::memory_order_relaxed)) return ArsXorVaes(keys, c1, c2, c3, first, count);
#endif
  const hn::ScalableTag<uint32_t> d;
  const size_t L = hn::Lanes(d), P = L / 4;  // P blocks per vector, one per 128-bit part
  const sk::ArsKeysV<hn::ScalableTag<uint32_t>> k(d, keys);
  alignas(64) uint32_t lane[64] = {}, inc[64] = {};
  for (size_t l = 0; l < P; ++l) {
    lane[4 * l] = first + static_cast<uint32_t>(l);
    lane[4 * l + 1] = c1;
    lane[4 * l + 2] = c2;
    lane[4 * l + 3] = c3;
    inc[4 * l] = static_cast<uint32_t>(P);
  }
  const auto step = hn::Load(d, inc);
  using V = hn::Vec<decltype(d)>;
  V ctr[8], acc[8], x[8];
  ctr[0] = hn::Load(d, lane);
  for (int j = 1; j < 8; ++j) ctr[j] = hn::Add(ctr[j - 1], step);
  for (int j = 0; j < 8; ++j) acc[j] = hn::Zero(d);
  const auto step8 = hn::ShiftLeft<3>(step);
  for (uint64_t i = 0; i < count; i += 8 * P) {
#pragma GCC unroll 8
    for (int j = 0; j < 8; ++j) {
      x[j] = hn::Xor(ctr[j], k.k[0]);
      ctr[j] = hn::Add(ctr[j], step8);
    }
    sk::ArsRoundsN<8>(d, k, x);
#pragma GCC unroll 8
    for (int j = 0; j < 8; ++j) acc[j] = hn::Xor(acc[j], x[j]);
  }
  for (int j = 1; j < 8; ++j) acc[0] = hn::Xor(acc[0], acc[j]);
  const auto a = acc[0];
  hn::Store(a, d, lane);
  Block128 out{};
  for (size_t l = 0; l < P; ++l)
    for (size_t w = 0; w < 4; ++w) out[w] ^= lane[4 * l + w];
  return out;
#endif
}

}  // namespace HWY_NAMESPACE
}  // namespace spadgen::bench
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace spadgen::bench {

HWY_EXPORT(ArsXor);

sensor::Block128 ars7_xor(const sensor::ArsKeys& keys, uint32_t c1, uint32_t c2, uint32_t c3, uint32_t first,
                          uint64_t count) {
  return HWY_DYNAMIC_DISPATCH(ArsXor)(keys, c1, c2, c3, first, count);
}

sensor::Block128 ars7_xor_reference(const sensor::ArsKeys& keys, uint32_t c1, uint32_t c2, uint32_t c3,
                                    uint32_t first, uint64_t count) {
  sensor::Block128 out{};
  for (uint64_t i = 0; i < count; ++i) {
    const sensor::Block128 b = sensor::ars7({first + static_cast<uint32_t>(i), c1, c2, c3}, keys);
    for (size_t w = 0; w < 4; ++w) out[w] ^= b[w];
  }
  return out;
}

}  // namespace spadgen::bench
#endif
