// probability_threshold (sensor/sampling.h) on whole Highway vectors of doubles, for the counts and frames
// kernels. Included once per target from the translation units that use Highway's foreach_target (the
// per-target include guard below).
#if defined(SPADGEN_SENSOR_THRESHOLD_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef SPADGEN_SENSOR_THRESHOLD_INL_H_
#undef SPADGEN_SENSOR_THRESHOLD_INL_H_
#else
#define SPADGEN_SENSOR_THRESHOLD_INL_H_
#endif

#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace spadgen::sensor {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

// probability_threshold lane by lane for x >= 0 (a lane with x < 0 gets an unspecified value: callers mask
// it): floor(x 2^64), saturated at 2^64 - 1. t = x 2^64 is exact; below 2^63 the signed truncation is the
// floor; from 2^63 on t is an integer, so t - 2^63 converts exactly and 2^63 is added back. One conversion:
// this sits in the searches' inner loops.
template <class D>
HWY_INLINE hn::Vec<hn::RebindToUnsigned<D>> ProbabilityThreshold(D d, hn::Vec<D> x) {
  const hn::RebindToUnsigned<D> du;
  const hn::RebindToSigned<D> di;
  const auto two63 = hn::Set(d, 0x1p63);
  const auto t = hn::Mul(x, hn::Set(d, 0x1p64));
  const auto big = hn::Ge(t, two63);
  auto r = hn::BitCast(du, hn::ConvertTo(di, hn::IfThenElse(big, hn::Min(hn::Sub(t, two63), hn::Set(d, 0x1.fffffffffffffp62)), t)));
  r = hn::IfThenElse(hn::RebindMask(du, big), hn::Add(r, hn::Set(du, uint64_t{1} << 63)), r);
  return hn::IfThenElse(hn::RebindMask(du, hn::Ge(t, hn::Set(d, 0x1p64))), hn::Set(du, ~uint64_t{0}), r);
}

}  // namespace HWY_NAMESPACE
}  // namespace spadgen::sensor
HWY_AFTER_NAMESPACE();

#endif  // per-target include guard
