// Which Acquisition the scene file's settings select. A new mode adds one line to kModes.
#include <optional>

#include "core/error.h"
#include "sensor/acquisition/acquisition.h"

namespace spadgen::sensor {

std::unique_ptr<Acquisition> make_gate_sweep(const SensorStageConfig&);
std::unique_ptr<Acquisition> make_intensity_single(const SensorStageConfig&);
std::unique_ptr<Acquisition> make_intensity_dual(const SensorStageConfig&);

namespace {

struct Mode {
  AcquisitionMode mode;
  std::optional<Exposure> exposure;  // for the 2D modes: acquisition.intensity.exposure
  std::unique_ptr<Acquisition> (*make)(const SensorStageConfig&);
};

const Mode kModes[] = {
    {AcquisitionMode::GateSweep, std::nullopt, make_gate_sweep},
    {AcquisitionMode::Intensity, Exposure::Single, make_intensity_single},
    {AcquisitionMode::Intensity, Exposure::Dual, make_intensity_dual},
};

}  // namespace

const std::vector<double>& Acquisition::gate_positions_s() const {
  static const std::vector<double> none;
  return none;
}
const std::vector<double>& Acquisition::exposures_s() const {
  static const std::vector<double> none;
  return none;
}
std::unique_ptr<Acquisition::TileSetup> Acquisition::setup(const TimeAxis&) const { return nullptr; }
std::unique_ptr<Acquisition::Scratch> Acquisition::scratch() const { return nullptr; }
void Acquisition::finish_tile(SensorTile&) const {}

std::unique_ptr<Acquisition> make_acquisition(const SensorStageConfig& c) {
  for (const Mode& m : kModes)
    if (m.mode == c.acquisition.mode && (!m.exposure || *m.exposure == c.acquisition.intensity.exposure))
      return m.make(c);
  throw Error("acquisition.mode: no acquisition implements \"" + to_string(c.acquisition.mode) + "\"");
}

}  // namespace spadgen::sensor
