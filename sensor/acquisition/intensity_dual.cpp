// 2D intensity, dual exposure: short (tau_S) and long (tau_L = dual_ratio tau_S) exposures interleaved,
// N / 2 frames each (scenes/ checks that N is even), two images; their sum is linearised by the inverse
// of the paper's eq. (6), which extends the dynamic range before saturation.
#include "sensor/acquisition/intensity.h"

namespace spadgen::sensor {
namespace {

class IntensityDual final : public Intensity {
 public:
  explicit IntensityDual(const SensorStageConfig& c)
      : Intensity(c, {c.acquisition.intensity.exposure_s, c.acquisition.intensity.exposure_s * c.acquisition.intensity.dual_ratio},
                  static_cast<uint32_t>(c.acquisition.frames / 2), true) {}
  std::string name() const override { return to_string(AcquisitionMode::Intensity) + " (dual exposure)"; }
};

}  // namespace

std::unique_ptr<Acquisition> make_intensity_dual(const SensorStageConfig& c) {
  return std::make_unique<IntensityDual>(c);
}

}  // namespace spadgen::sensor
