// 2D intensity, single exposure: every frame is exposed for tau; one image of N frames, linearised by the
// inverse of the paper's eq. (5), -N log(1 - counts / N).
#include "sensor/acquisition/intensity.h"

namespace spadgen::sensor {
namespace {

class IntensitySingle final : public Intensity {
 public:
  explicit IntensitySingle(const SensorStageConfig& c)
      : Intensity(c, {c.acquisition.intensity.exposure_s}, static_cast<uint32_t>(c.acquisition.frames), false) {}
  std::string name() const override { return to_string(AcquisitionMode::Intensity) + " (single exposure)"; }
};

}  // namespace

std::unique_ptr<Acquisition> make_intensity_single(const SensorStageConfig& c) {
  return std::make_unique<IntensitySingle>(c);
}

}  // namespace spadgen::sensor
