#include "sensor/model/pixel_layout.h"

namespace spadgen::sensor {

PixelLayout::PixelLayout(PixelPreset preset, int height_px) : preset_(preset), height_(height_px) {
  const bool halves = preset == PixelPreset::FullChip && height_px >= 2;
  split_ = halves ? height_px / 2 : 0;
  sections_ = halves ? 2 : 1;
}

std::vector<int> PixelLayout::types() const {
  switch (preset_) {
    case PixelPreset::PixelA: return {0};
    case PixelPreset::PixelB: return {1};
    case PixelPreset::FullChip: return height_ >= 2 ? std::vector<int>{0, 1} : std::vector<int>{1};
  }
  return {};
}

std::vector<double> PixelLayout::row_fill_factor(const SensorConfig& sensor) const {
  std::vector<double> ff(static_cast<size_t>(height_));
  for (int y = 0; y < height_; ++y)
    ff[static_cast<size_t>(y)] = type_of_row(y) == 0 ? sensor.pixel_A.fill_factor : sensor.pixel_B.fill_factor;
  return ff;
}

}  // namespace spadgen::sensor
