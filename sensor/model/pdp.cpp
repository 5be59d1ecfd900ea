#include "sensor/model/pdp.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "core/error.h"
#include "core/units.h"
#include "sensor/model/csv.h"

namespace spadgen::sensor {

// Relative PDP of a front-side illuminated p+/n-well SPAD at about 3.3 V excess bias. An approximation that
// follows the shape of the paper's Fig. 4(c): a peak at 520 nm, about half of it at 400 nm, falling in the red
// as absorption moves below the shallow junction (0.45 at 637 nm, 0.30 at 785 nm), and nearly nothing in the
// near infrared. Not a measurement; give sensor.pixel_X.pdp_csv for a measured curve.
const std::vector<std::pair<double, double>>& PdpCurve::builtin_shape() {
  static const std::vector<std::pair<double, double>> shape = {
      {300, 0.00}, {350, 0.22}, {400, 0.50}, {450, 0.80}, {500, 0.97}, {520, 1.00}, {550, 0.93},
      {600, 0.64}, {637, 0.45}, {700, 0.37}, {785, 0.30}, {850, 0.20}, {900, 0.13}, {950, 0.07},
      {1000, 0.03}, {1100, 0.00}};
  return shape;
}

std::string pointer_of(const std::string& dotted_key) {
  std::string p = "/" + dotted_key;
  std::replace(p.begin(), p.end(), '.', '/');
  return p;
}

PdpCurve PdpCurve::from_config(const PixelTypeConfig& c, const std::string& key) {
  PdpCurve curve;
  if (!c.pdp_csv.empty()) {
    const Table2 t = read_table_csv(c.pdp_csv, key + ".pdp_csv");
    for (size_t i = 0; i < t.y.size(); ++i)
      if (!(t.y[i] >= 0.0 && t.y[i] <= 1.0)) {
        std::ostringstream m;
        m << "'" << c.pdp_csv << "' row " << i + 1 << ": PDP must be a fraction in [0, 1], found " << t.y[i];
        throw KeyError(pointer_of(key) + "/pdp_csv", m.str());
      }
    curve.nm_ = t.x;
    curve.pdp_ = t.y;
    return curve;
  }
  for (const auto& [nm, rel] : builtin_shape()) {
    curve.nm_.push_back(nm);
    curve.pdp_.push_back(rel);
  }
  const double at_peak = curve.at(c.pdp_peak_wavelength_m);
  if (!(at_peak > 0.0)) {
    std::ostringstream m;
    m << "found " << c.pdp_peak_wavelength_m / kNm << " nm, where the built-in PDP curve is zero"
      << "; expected a wavelength strictly between 300 and 1100 nm (the curve is zero at and beyond both ends) or a pdp_csv table";
    throw KeyError(pointer_of(key) + "/pdp_peak_wavelength_nm", m.str());
  }
  for (double& v : curve.pdp_) v *= c.pdp_peak / at_peak;
  return curve;
}

double PdpCurve::at(double wavelength_m) const {
  const double nm = wavelength_m / kNm;
  if (!(nm >= nm_.front() && nm <= nm_.back())) return 0.0;
  const auto it = std::upper_bound(nm_.begin(), nm_.end(), nm);
  if (it == nm_.end()) return pdp_.back();
  const size_t i = static_cast<size_t>(it - nm_.begin());
  const double w = (nm - nm_[i - 1]) / (nm_[i] - nm_[i - 1]);
  return pdp_[i - 1] + w * (pdp_[i] - pdp_[i - 1]);
}

double PdpCurve::band_average(double centre_m, double width_m) const {
  if (!(width_m > 0.0)) return at(centre_m);
  // The curve is piecewise linear; 2000 midpoint samples make the quadrature error far below the
  // accuracy of any PDP curve.
  constexpr int n = 2000;
  double num = 0.0, den = 0.0;
  for (int i = 0; i < n; ++i) {
    const double lambda = centre_m - 0.5 * width_m + (i + 0.5) * width_m / n;
    num += lambda * at(lambda);
    den += lambda;
  }
  return num / den;
}

}  // namespace spadgen::sensor
