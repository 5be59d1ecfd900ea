// Photon detection probability of a SPAD as a function of wavelength.
#pragma once
#include <algorithm>
#include <string>
#include <vector>

#include "core/config.h"

namespace spadgen::sensor {

// A dotted key as the JSON pointer a KeyError names: "sensor.pixel_A" -> "/sensor/pixel_A".
std::string pointer_of(const std::string& dotted_key);

class PdpCurve {
 public:
  // The built-in curve shape scaled so that PDP(pdp_peak_wavelength) = pdp_peak, or the pdp_csv table
  // (wavelength_nm, PDP as a fraction) used as is. `key` names the pixel type in error messages.
  static PdpCurve from_config(const PixelTypeConfig& c, const std::string& key);
  // Linear interpolation between table points; 0 outside the table.
  double at(double wavelength_m) const;
  // The table's first and last wavelength, nm.
  double max() const { return *std::max_element(pdp_.begin(), pdp_.end()); }
  double first_nm() const { return nm_.front(); }
  double last_nm() const { return nm_.back(); }
  // Mean PDP over [centre - width/2, centre + width/2] for an equal-energy spectrum, i.e. weighted by the
  // photon flux per unit wavelength, which is proportional to the wavelength. width 0: at(centre).
  double band_average(double centre_m, double width_m) const;

  // The built-in relative shape: (wavelength_nm, PDP / PDP at 520 nm).
  static const std::vector<std::pair<double, double>>& builtin_shape();

 private:
  std::vector<double> nm_, pdp_;
};

}  // namespace spadgen::sensor
