// Philox4x32-10 (Random123's r123::Philox4x32, as core/rng.h uses it) on whole Highway vectors: one
// independent block per lane, bit-identical to the scalar generator. Included once per target from the
// translation units that use Highway's foreach_target (the per-target include guard below).
#if defined(SPADGEN_SENSOR_PHILOX_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef SPADGEN_SENSOR_PHILOX_INL_H_
#undef SPADGEN_SENSOR_PHILOX_INL_H_
#else
#define SPADGEN_SENSOR_PHILOX_INL_H_
#endif

#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace spadgen::sensor {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

// Philox4x32's multipliers and Weyl key increments (Random123).
inline constexpr uint32_t kPhiloxM0 = 0xD2511F53u, kPhiloxM1 = 0xCD9E8D57u;
inline constexpr uint32_t kPhiloxW0 = 0x9E3779B9u, kPhiloxW1 = 0xBB67AE85u;

// 32 x 32 -> 64-bit products of every lane: MulEven (vpmuludq) on the even lanes and on the odd lanes
// shifted down, recombined with OddEven; cheaper than widening to 64-bit multiplies.
template <class D>
HWY_INLINE void MulHiLoGeneric(D d, hn::Vec<D> a, hn::Vec<D> b, hn::Vec<D>& hi, hn::Vec<D>& lo) {
  const hn::Repartition<uint64_t, D> d64;
  const auto pe = hn::MulEven(a, b);
  const auto po = hn::MulEven(hn::BitCast(d, hn::ShiftRight<32>(hn::BitCast(d64, a))),
                              hn::BitCast(d, hn::ShiftRight<32>(hn::BitCast(d64, b))));
  hi = hn::OddEven(hn::BitCast(d, po), hn::BitCast(d, hn::ShiftRight<32>(pe)));
  lo = hn::OddEven(hn::BitCast(d, hn::ShiftLeft<32>(po)), hn::BitCast(d, pe));
}

// 32 x 32 -> 64-bit products of every lane: high and low halves.
template <class D>
HWY_INLINE void MulHiLo(D d, hn::Vec<D> a, hn::Vec<D> b, hn::Vec<D>& hi, hn::Vec<D>& lo) {
#if HWY_TARGET == HWY_SCALAR
  (void)d;
  const uint64_t p = uint64_t{hn::GetLane(a)} * hn::GetLane(b);
  hi = hn::Set(d, static_cast<uint32_t>(p >> 32));
  lo = hn::Set(d, static_cast<uint32_t>(p));
#elif HWY_TARGET <= HWY_AVX3
  if constexpr (sizeof(hn::Vec<D>) == 64) {
    // AVX-512: the odd lanes' product from a dword swap (vpshufd, not a shift on the multiplier's port),
    // and the halves recombined by masked dword swaps (one instruction each instead of shift + blend).
    const __m512i pe = hn::BitCast(d, hn::MulEven(a, b)).raw;
    const __m512i po = hn::BitCast(d, hn::MulEven(hn::Shuffle2301(a), hn::Shuffle2301(b))).raw;
    hi = hn::Vec<D>{_mm512_mask_shuffle_epi32(po, 0x5555, pe, _MM_PERM_CDAB)};
    lo = hn::Vec<D>{_mm512_mask_shuffle_epi32(pe, 0xAAAA, po, _MM_PERM_CDAB)};
  } else {
    MulHiLoGeneric(d, a, b, hi, lo);
  }
#else
  MulHiLoGeneric(d, a, b, hi, lo);
#endif
}

// `rounds` Philox rounds on (x0, x1, x2, x3), the first with round key (ka, kb).
template <class D>
HWY_INLINE void PhiloxRounds(D d, int rounds, uint32_t ka, uint32_t kb, hn::Vec<D>& x0, hn::Vec<D>& x1,
                             hn::Vec<D>& x2, hn::Vec<D>& x3) {
  const auto m0 = hn::Set(d, kPhiloxM0), m1 = hn::Set(d, kPhiloxM1);
  for (int round = 0; round < rounds; ++round) {
    hn::Vec<D> hi0, lo0, hi1, lo1;
    MulHiLo(d, x0, m0, hi0, lo0);
    MulHiLo(d, x2, m1, hi1, lo1);
    x0 = hn::Xor(hn::Xor(hi1, x1), hn::Set(d, ka));
    x2 = hn::Xor(hn::Xor(hi0, x3), hn::Set(d, kb));
    x1 = lo1;
    x3 = lo0;
    ka += kPhiloxW0;
    kb += kPhiloxW1;
  }
}

// Ten Philox rounds on (x0, x1, x2, x3) with key (k0, k1): afterwards x0..x3 are the block's words.
template <class D>
HWY_INLINE void Philox10(D d, uint32_t k0, uint32_t k1, hn::Vec<D>& x0, hn::Vec<D>& x1, hn::Vec<D>& x2,
                         hn::Vec<D>& x3) {
  PhiloxRounds(d, 10, k0, k1, x0, x1, x2, x3);
}

}  // namespace HWY_NAMESPACE
}  // namespace spadgen::sensor
HWY_AFTER_NAMESPACE();

#endif  // per-target include guard
