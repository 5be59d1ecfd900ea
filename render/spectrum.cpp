#include "spectrum.h"

#include <algorithm>

#include "core/units.h"

namespace spadgen::render {

glm::vec3 rgb_weights_at(double wavelength_m) {
  const double nm = wavelength_m * 1e9;
  constexpr double kB = 465.0, kG = 540.0, kR = 610.0;
  if (nm <= kB) return {0, 0, 1};
  if (nm >= kR) return {1, 0, 0};
  if (nm <= kG) {
    const auto t = static_cast<float>((nm - kB) / (kG - kB));
    return {0, t, 1 - t};
  }
  const auto t = static_cast<float>((nm - kG) / (kR - kG));
  return {t, 1 - t, 0};
}

glm::vec3 rgb_weights_over(double centre_m, double width_m) {
  if (!(width_m > 0.0)) return rgb_weights_at(centre_m);
  // Weighted by the photons of the band's equal-energy spectrum, whose photon flux grows as lambda: a colour
  // reflects the mean of its reflectance over those photons (the plain mean over wavelength gave a blue-green
  // colour 9 % more ambient photons over 400-700 nm; a verifier's find). Grey stays grey.
  constexpr int kSteps = 256;
  glm::dvec3 sum(0.0);
  double photons = 0.0;
  for (int i = 0; i < kSteps; ++i) {
    const double lambda = centre_m + width_m * ((i + 0.5) / kSteps - 0.5);
    sum += lambda * glm::dvec3(rgb_weights_at(lambda)), photons += lambda;
  }
  return glm::vec3(sum / photons);
}

double photons_per_second_per_photometric_unit(double wavelength_m, double bandwidth_m) {
  const double watts_per_nm = 1.0 / (kLuminousEfficacy * kIntegralVLambdaNm);
  return watts_per_nm * (bandwidth_m * 1e9) / photon_energy_J(wavelength_m);
}

}  // namespace spadgen::render
