// Which pixel design each sensor row has, and which array section (own gate tree, no crosstalk across)
// it belongs to. The one place that decides it: the sensor's maps and rates, and the renderer's fill
// factor (through SensorModel::row_fill_factor), all ask this class.
//
// pixel_A / pixel_B: every row has that design, one section. full_chip: rows [0, H/2) are pixel A and
// rows [H/2, H) pixel B (H/2 rounded down, so an odd middle row is pixel B), each half its own section;
// a one-row full_chip sensor is its pixel B row.
#pragma once
#include <vector>

#include "core/config.h"

namespace spadgen::sensor {

class PixelLayout {
 public:
  PixelLayout(PixelPreset preset, int height_px);

  // 0: sensor.pixel_A's settings, 1: sensor.pixel_B's.
  int type_of_row(int y) const { return preset_ == PixelPreset::PixelA ? 0 : preset_ == PixelPreset::PixelB ? 1 : (y < split_ ? 0 : 1); }
  int section_of_row(int y) const { return y < split_ ? 0 : sections_ - 1; }
  int sections() const { return sections_; }
  // First row and row count of a section.
  int section_begin(int s) const { return s == 0 ? 0 : split_; }
  int section_rows(int s) const { return sections_ == 1 ? height_ : (s == 0 ? split_ : height_ - split_); }
  // The pixel designs that occur, in type order (0 and/or 1).
  std::vector<int> types() const;
  // The fill factor of every row (the renderer applies it: RenderStageConfig::row_fill_factor).
  std::vector<double> row_fill_factor(const SensorConfig& sensor) const;

 private:
  PixelPreset preset_;
  int height_;
  int split_;     // first pixel B row of full_chip (0 when one section)
  int sections_;  // 1 or 2
};

}  // namespace spadgen::sensor
