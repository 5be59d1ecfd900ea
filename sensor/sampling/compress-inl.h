// Compressing lanes (the selected lanes first, in order; the rest unspecified) without Highway 1.0's
// Compress on x86: it looks the lanes' order up in a constant table declared inside the function, which
// GCC copies onto the stack on every call (512 bytes to 2 KB; on AVX2 the copies took 45 % of the frames'
// crosstalk kernel and 12 % of the frame-bit sampler). AVX-512: vpcompressd / vpcompressq in registers;
// AVX2: one vpermd with indices from a static table; other targets: Highway's Compress. A Compressor is
// built once per mask and applied to several vectors. Included once per target (the guard below).
#if defined(SPADGEN_SENSOR_COMPRESS_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef SPADGEN_SENSOR_COMPRESS_INL_H_
#undef SPADGEN_SENSOR_COMPRESS_INL_H_
#else
#define SPADGEN_SENSOR_COMPRESS_INL_H_
#endif

#include <hwy/highway.h>

#include <cstdint>
#include <type_traits>

HWY_BEFORE_NAMESPACE();
namespace spadgen::sensor {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

#if HWY_ARCH_X86 && HWY_TARGET == HWY_AVX2
// vpermd indices of the compressed order: 32-bit lanes (8 byte indices per mask of 8 lanes) and 64-bit
// lanes (pairs of 32-bit indices per mask of 4 lanes).
struct CompressTables {
  uint64_t lanes32[256] = {};
  alignas(32) uint32_t lanes64[16][8] = {};
  constexpr CompressTables() {
    for (unsigned m = 0; m < 256; ++m) {
      unsigned o = 0;
      for (unsigned i = 0; i < 8; ++i)
        if ((m >> i) & 1u) lanes32[m] |= uint64_t{i} << (8 * o++);
    }
    for (unsigned m = 0; m < 16; ++m) {
      unsigned o = 0;
      for (unsigned i = 0; i < 4; ++i)
        if ((m >> i) & 1u) {
          lanes64[m][2 * o] = 2 * i;
          lanes64[m][2 * o + 1] = 2 * i + 1;
          ++o;
        }
    }
  }
};
inline constexpr CompressTables kCompressTables;
#endif

template <class D>
class Compressor {
 public:
  Compressor(D /*d*/, hn::Mask<D> m) : m_(m) {
#if HWY_ARCH_X86 && HWY_TARGET == HWY_AVX2
    if constexpr (sizeof(hn::Vec<D>) == 32 && std::is_integral_v<hn::TFromD<D>> && sizeof(hn::TFromD<D>) == 4) {
      const int bits = _mm256_movemask_ps(_mm256_castsi256_ps(m.raw));
      idx_ = _mm256_cvtepu8_epi32(_mm_cvtsi64_si128(static_cast<long long>(kCompressTables.lanes32[bits])));
    } else if constexpr (sizeof(hn::Vec<D>) == 32 && std::is_integral_v<hn::TFromD<D>> && sizeof(hn::TFromD<D>) == 8) {
      const int bits = _mm256_movemask_pd(_mm256_castsi256_pd(m.raw));
      idx_ = _mm256_load_si256(reinterpret_cast<const __m256i*>(kCompressTables.lanes64[bits]));
    }
#endif
  }
  hn::Vec<D> operator()(hn::Vec<D> v) const {
#if HWY_ARCH_X86 && HWY_TARGET <= HWY_AVX3
    if constexpr (sizeof(hn::Vec<D>) == 64 && std::is_integral_v<hn::TFromD<D>> && sizeof(hn::TFromD<D>) == 8)
      return hn::Vec<D>{_mm512_maskz_compress_epi64(m_.raw, v.raw)};
    if constexpr (sizeof(hn::Vec<D>) == 64 && std::is_integral_v<hn::TFromD<D>> && sizeof(hn::TFromD<D>) == 4)
      return hn::Vec<D>{_mm512_maskz_compress_epi32(m_.raw, v.raw)};
#endif
#if HWY_ARCH_X86 && HWY_TARGET == HWY_AVX2
    if constexpr (sizeof(hn::Vec<D>) == 32 && std::is_integral_v<hn::TFromD<D>> &&
                  (sizeof(hn::TFromD<D>) == 4 || sizeof(hn::TFromD<D>) == 8))
      return hn::Vec<D>{_mm256_permutevar8x32_epi32(v.raw, idx_)};
#endif
    return hn::Compress(v, m_);
  }

 private:
  hn::Mask<D> m_;
#if HWY_ARCH_X86 && HWY_TARGET == HWY_AVX2
  __m256i idx_{};
#endif
};

// One vector compressed by its mask.
template <class D>
HWY_INLINE hn::Vec<D> CompressLanes(D d, hn::Vec<D> v, hn::Mask<D> m) {
  return Compressor<D>(d, m)(v);
}

}  // namespace HWY_NAMESPACE
}  // namespace spadgen::sensor
HWY_AFTER_NAMESPACE();

#endif  // per-target include guard
